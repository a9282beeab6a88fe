"""Laplace interpolation on a mapped grid (Hong 2005, ch. 7.2 and App. B).

Hong deforms a leaf blade by interpolating the displacements of its edited veins over the rest
of the blade: each displacement component ``d`` solves ``Δd = 0`` on the blade, with the veins as
Dirichlet conditions (``d`` prescribed) and the margin as a Neumann condition (``∂d/∂n = 0``: the
margin is free). This module is that solver, independent of leaves:

* the domain is a structured ``(nv, nu)`` grid of points mapped into the plane (for a leaf the
  flat blade in vein space, :mod:`leafview.botany.vein_shape`); a grid row whose points all
  coincide (the pinched base and apex of a blade) becomes one node;
* each grid cell is split into two triangles and the Laplacian is discretised with linear finite
  elements (the cotangent stiffness matrix). The Neumann condition on the free boundary is the
  natural condition of that weak form, so it needs no stencil of its own, and the operator is the
  Laplacian of the plane the points are mapped into, not of the grid's parameters;
* the Dirichlet nodes are eliminated and the rest solved with a sparse LU factorisation
  (``scipy.sparse.linalg.splu``), several right-hand sides at once.

Linear elements reproduce constants exactly (a rigid translation of every vein moves the whole
blade) and converge as ``O(h²)`` for smooth solutions (``tests/test_laplace.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.linalg import splu

__all__ = ["GridMesh", "grid_mesh", "stiffness", "solve_dirichlet", "signed_areas"]

PINCH_TOL = 1e-12   # a grid row whose points lie within this (relative to the grid's extent) is one node


@dataclass(frozen=True)
class GridMesh:
    """A structured grid mapped into the plane, as a triangle mesh.

    ``points`` (nv, nu, 2) the grid's positions; ``index`` (nv, nu) the node of each grid point
    (pinched rows share one node); ``nodes`` (n, 2) the node positions; ``triangles`` (T, 3) node
    indices of the non-degenerate triangles, two per cell (the diagonal from (i + 1, j) to
    (i, j + 1), as :func:`leafview.core.blade.grid_indices`)."""

    points: NDArray[np.float64]
    index: NDArray[np.int64]
    nodes: NDArray[np.float64]
    triangles: NDArray[np.int64]

    @property
    def size(self) -> int:
        """Number of nodes."""
        return int(self.nodes.shape[0])


def grid_mesh(points: ArrayLike) -> GridMesh:
    """The triangle mesh of the mapped grid ``points`` (nv, nu, 2); see :class:`GridMesh`."""
    pts = np.asarray(points, np.float64)
    if pts.ndim != 3 or pts.shape[2] != 2 or pts.shape[0] < 2 or pts.shape[1] < 2:
        raise ValueError(f"expected (nv, nu, 2) grid points with nv, nu >= 2, got {pts.shape}")
    nv, nu = pts.shape[:2]
    extent = float(np.ptp(pts.reshape(-1, 2), axis=0).max()) or 1.0
    spread = np.ptp(pts, axis=1).max(axis=1)                     # (nv,) extent of each row
    pinched = spread <= PINCH_TOL * extent
    index = np.empty((nv, nu), np.int64)
    nodes: list[NDArray[np.float64]] = []
    count = 0
    for j in range(nv):
        if pinched[j]:
            index[j] = count
            nodes.append(pts[j, :1].mean(axis=0, keepdims=True))
            count += 1
        else:
            index[j] = count + np.arange(nu)
            nodes.append(pts[j])
            count += nu
    i = np.arange(nu - 1)
    jj, ii = np.meshgrid(np.arange(nv - 1), i, indexing="ij")
    p00 = index[jj, ii].ravel()
    p10 = index[jj, ii + 1].ravel()
    p01 = index[jj + 1, ii].ravel()
    p11 = index[jj + 1, ii + 1].ravel()
    tris = np.concatenate([np.stack([p00, p01, p10], -1), np.stack([p10, p01, p11], -1)])
    keep = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
    return GridMesh(pts, index, np.concatenate(nodes), tris[keep])


def signed_areas(nodes: ArrayLike, triangles: NDArray[np.int64]) -> NDArray[np.float64]:
    """Signed areas (T,) of ``triangles`` over planar ``nodes`` (n, 2) (positive counter-clockwise)."""
    p = np.asarray(nodes, np.float64)[triangles]
    e1 = p[:, 1] - p[:, 0]
    e2 = p[:, 2] - p[:, 0]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def stiffness(mesh: GridMesh) -> sp.csr_matrix:
    """The P1 stiffness matrix ``K_ij = ∫ ∇φ_i · ∇φ_j`` (n, n) of the mesh (the cotangent
    Laplacian): ``K d = 0`` at a free node is the discrete ``Δd = 0`` with zero normal flux through
    the free boundary."""
    tri = mesh.triangles
    p = mesh.nodes[tri]                                    # (T, 3, 2)
    area = np.abs(signed_areas(mesh.nodes, tri))
    # edge opposite each corner: e_k = p_{k+2} - p_{k+1}; ∇φ_k · ∇φ_l = e_k · e_l / (4 A²)
    e = np.roll(p, -2, axis=1) - np.roll(p, -1, axis=1)    # (T, 3, 2)
    local = np.einsum("tkd,tld->tkl", e, e) / (4.0 * area)[:, None, None]
    rows = np.repeat(tri, 3, axis=1).ravel()
    cols = np.tile(tri, (1, 3)).ravel()
    n = mesh.size
    return sp.coo_matrix((local.ravel(), (rows, cols)), shape=(n, n)).tocsr()


def solve_dirichlet(matrix: sp.csr_matrix, fixed: ArrayLike, values: ArrayLike) -> NDArray[np.float64]:
    """Solve ``K x = 0`` at the free nodes with ``x = values`` at the ``fixed`` ones.

    ``matrix`` (n, n) from :func:`stiffness`; ``fixed`` (n,) bool; ``values`` (n,) or (n, k) (only
    the fixed rows are read). Returns x with the shape of ``values``. Every connected part of the
    mesh needs a fixed node (a pure Neumann problem has no unique solution): ``ValueError``
    otherwise."""
    fix = np.asarray(fixed, bool)
    vals = np.asarray(values, np.float64)
    x = np.array(vals, dtype=np.float64, copy=True)
    if not fix.any():
        raise ValueError("no Dirichlet node: the Laplace problem has no unique solution")
    free = ~fix
    if not free.any():
        return x
    k_ff = matrix[free][:, free].tocsc()
    rhs = -(matrix[free][:, fix] @ vals[fix])
    try:
        lu = splu(k_ff)
    except RuntimeError as exc:  # exactly singular: a free part with no fixed node
        raise ValueError("a part of the domain touches no Dirichlet node") from exc
    sol = lu.solve(np.asarray(rhs, np.float64))
    if not np.all(np.isfinite(sol)):
        raise ValueError("a part of the domain touches no Dirichlet node")
    x[free] = sol
    return x
