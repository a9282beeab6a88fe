"""The Laplace solver of leafview.botany.laplace (Hong 2005, ch. 7.2, App. B) against analytic
harmonic functions with mixed Dirichlet / Neumann conditions, and its exact reproduction of a
rigid translation."""

from __future__ import annotations

import numpy as np
import pytest

from leafview.botany.laplace import grid_mesh, signed_areas, solve_dirichlet, stiffness


def _solve(points: np.ndarray, exact: np.ndarray, fixed_rows: list[int]) -> float:
    """Max error of the solution with Dirichlet data ``exact`` on ``fixed_rows`` (Neumann elsewhere)."""
    mesh = grid_mesh(points)
    fixed = np.zeros(mesh.size, bool)
    for j in fixed_rows:
        fixed[mesh.index[j]] = True
    values = np.zeros(mesh.size)
    values[mesh.index.ravel()] = exact.ravel()
    x = solve_dirichlet(stiffness(mesh), fixed, values)
    return float(np.abs(x[mesh.index] - exact).max() / np.abs(exact).max())


def _rectangle(n: int) -> float:
    # d = cos(πx) cosh(πy): ∂d/∂x = 0 on x = 0 and x = 1 (Neumann), Dirichlet on y = 0, 0.7
    x, y = np.meshgrid(np.linspace(0.0, 1.0, n), np.linspace(0.0, 0.7, n))
    return _solve(np.stack([x, y], -1), np.cos(np.pi * x) * np.cosh(np.pi * y), [0, n - 1])


def _annulus(n: int, r0: float = 0.5, r1: float = 1.0, k: int = 2) -> float:
    # d = (r^k + r1^2k r^-k) cos kθ on the sector θ ∈ [0, π/k]: ∂d/∂n = 0 on the outer arc and
    # both radial sides (Neumann on three sides, on curved boundaries), Dirichlet on the inner arc
    th, r = np.meshgrid(np.linspace(0.0, np.pi / k, n), np.linspace(r0, r1, n))
    pts = np.stack([r * np.cos(th), r * np.sin(th)], -1)
    return _solve(pts, (r**k + r1 ** (2 * k) * r ** (-k)) * np.cos(k * th), [0])


def _pinched(n: int, k: int = 2) -> float:
    # d = r^k cos kθ on the sector r ≤ 1, θ ∈ [0, π/k]: row 0 (r = 0) collapses to one node, like
    # a blade's base; Neumann on the radial sides, Dirichlet on the arc
    th, r = np.meshgrid(np.linspace(0.0, np.pi / k, n), np.linspace(0.0, 1.0, n))
    pts = np.stack([r * np.cos(th), r * np.sin(th)], -1)
    return _solve(pts, r**k * np.cos(k * th) + 1.0, [n - 1])


@pytest.mark.parametrize("case, tol33", [(_rectangle, 3e-4), (_annulus, 1.2e-3), (_pinched, 1e-4)])
def test_converges_quadratically(case, tol33):
    errors = [case(n) for n in (17, 33, 65)]
    assert errors[1] < tol33
    # linear elements: the error falls about fourfold per halving of h
    assert errors[0] / errors[1] > 3.5 and errors[1] / errors[2] > 3.5, errors


def test_rigid_translation_is_exact():
    # a blade-like domain in vein space, pinched at both ends: constant Dirichlet data on a
    # "midrib" and two "veins" moves every node by the same vector
    n = 33
    u, v = np.meshgrid(np.linspace(-1.0, 1.0, n), np.linspace(0.0, 1.0, n))
    w = 0.4 * np.sin(np.pi * v)
    mesh = grid_mesh(np.stack([u * w, v], -1))
    assert mesh.size == n * (n - 2) + 2
    fixed = np.zeros(mesh.size, bool)
    fixed[mesh.index[:, n // 2]] = True
    fixed[mesh.index[10, n // 2:]] = True
    fixed[mesh.index[20, : n // 2]] = True
    values = np.tile([0.3, -0.2, 0.05], (mesh.size, 1))
    values[~fixed] = 0.0
    x = solve_dirichlet(stiffness(mesh), fixed, values)
    np.testing.assert_allclose(x, np.tile([0.3, -0.2, 0.05], (mesh.size, 1)), atol=1e-12)


def test_mesh_orientation_and_errors():
    u, v = np.meshgrid(np.linspace(0.0, 1.0, 4), np.linspace(0.0, 1.0, 3))
    mesh = grid_mesh(np.stack([u, v], -1))
    areas = signed_areas(mesh.nodes, mesh.triangles)
    assert np.all(areas < 0) and np.isclose(areas.sum(), -1.0)   # grid_indices' winding, y up
    with pytest.raises(ValueError, match="no Dirichlet"):
        solve_dirichlet(stiffness(mesh), np.zeros(mesh.size, bool), np.zeros(mesh.size))
    with pytest.raises(ValueError, match="grid points"):
        grid_mesh(np.zeros((3, 3)))
