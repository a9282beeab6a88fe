"""The whole leaf surface in float64: the blade (Chaurasia & Beardsley 2017, eqs 1-6) with
jitter, rippled margins (Geng, Hu & Zhang 2014, eq. 5) and the bent, twisted midrib (Geng, Hu &
Zhang 2014, sec. 5.2.2), in that order. This is the numpy twin of ``shaders/leaf_eval.glsl``.

The undeformed blade and the grids live in :mod:`leafview.core.blade`; they are re-exported here
so that one import gives every evaluation function.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.blade import (
    JITTER_TABLE_SIZE,
    Mesh,
    Partials,
    axis_frames,
    blade_partials,
    control_polygons,
    drawn_uv,
    grid_indices,
    grid_uv,
    jitter_table,
    normal_from,
    tilt_offsets,
    tip_taper,
    uv_arrays,
)
from leafview.core.defaults import DEFAULT_GRID
from leafview.core.params import LeafParams
from leafview.deform.beam import BendProfile, bend_profile, rotation, sample_clamped
from leafview.deform.fbm import ripple_signal, sample_periodic

__all__ = [
    "JITTER_TABLE_SIZE",
    "axis_frames",
    "tilt_offsets",
    "control_polygons",
    "jitter_table",
    "Partials",
    "partials",
    "evaluate",
    "normals",
    "tessellate",
    "Mesh",
    "drawn_uv",
    "grid_uv",
    "grid_indices",
]

Arr = NDArray[np.float64]


def partials(params: LeafParams, u: ArrayLike, v: ArrayLike, *, bend: BendProfile | None = None) -> Partials:
    """L, ∂L/∂u, ∂L/∂v and ∂²L/∂u∂v of the whole leaf: the blade (with jitter when enabled),
    then the rippled margin, then the bent and twisted midrib. ``bend`` replaces the leaf's own
    bend profile (a scene bends every leaf of a species by the species' profile)."""
    p, s, sigma, vv, A, dA = blade_partials(params, u, v)
    L, Lu, Lv, Luv = p.L, p.Lu, p.Lv, p.Luv
    if params.ripple.enabled:
        L, Lu, Lv, Luv = _add_ripple(params, s, sigma, vv, L, Lu, Lv, Luv)
    if bend is None and params.bending.active:
        bend = bend_profile(params)
    if bend is not None:
        L, Lu, Lv, Luv = _bend(bend, vv, A, dA, L, Lu, Lv, Luv)
    return Partials(L, Lu, Lv, Luv)


def _add_ripple(params: LeafParams, s: Arr, sigma: Arr, vv: Arr,
                L: Arr, Lu: Arr, Lv: Arr, Luv: Arr) -> tuple[Arr, Arr, Arr, Arr]:
    """Rippled margin (Geng, Hu & Zhang 2014, eq. 5): each cross-section is a secondary vein, a cantilever from
    the midrib under the turbulent load ``r = P [λ + (1 - λ) N(k · veins · v + θ)]``. In the
    small-deflection limit of eq. 4 a tip-loaded cantilever deflects as ``c(s) = s² (3 - s) / 2``
    (zero with zero slope at the midrib, 1 at the margin), so ``D = τ(v) r(v) c(|u|) ẑ``: out of
    the leaf plane (+z in leaf space, before bending), tapered to zero at base and apex."""
    rip = params.ripple
    signal = ripple_signal(rip.beta, rip.seed)
    side = np.where(sigma > 0, 0, 1)  # pairs are [left (u >= 0), right (u < 0)]
    amp, lam, k, theta = (np.asarray(getattr(rip, name))[side]
                          for name in ("amplitude", "fluctuation", "interval", "phase"))
    n_val, n_slope = sample_periodic(signal, k * rip.veins * vv + theta)
    r = amp * (lam + (1.0 - lam) * n_val)
    dr = amp * (1.0 - lam) * n_slope * k * rip.veins
    tau, dtau = tip_taper(vv)
    c = 0.5 * s * s * (3.0 - s)
    dc = 3.0 * s - 1.5 * s * s
    g = dtau * r + tau * dr
    z = np.array([0.0, 0.0, 1.0])
    return (L + (tau * r * c)[:, None] * z, Lu + (sigma * tau * r * dc)[:, None] * z,
            Lv + (c * g)[:, None] * z, Luv + (sigma * dc * g)[:, None] * z)


def _bend(bp: BendProfile, vv: Arr, A: Arr, dA: Arr,
          L: Arr, Lu: Arr, Lv: Arr, Luv: Arr) -> tuple[Arr, Arr, Arr, Arr]:
    """Apply the midrib bend and twist (Geng, Hu & Zhang 2014, sec. 5.2.2) to L and its partials.

    ``p' = A(v) + Δ(v) + R(v) (p - A(v))`` with ``R = R_N(Φ(v)) R_y(α v)``: the cross-section at
    v is twisted about the straight midrib's direction (y) through A(v), then turned with the
    bent midrib; Φ and Δ are the Catmull-Rom splines through the bend samples
    (:func:`leafview.deform.beam.sample_clamped`)."""
    phi, dphi = sample_clamped(bp.phi, vv)
    delta, ddelta = sample_clamped(bp.delta, vv)
    rn = rotation(bp.axis, phi)                         # (N, 3, 3)
    ry = rotation([0.0, 1.0, 0.0], bp.twist * vv)
    r = rn @ ry
    kn = _cross_matrix(bp.axis)
    ky = _cross_matrix([0.0, 1.0, 0.0])
    dr = dphi[:, None, None] * (kn @ r) + bp.twist * (rn @ (ky @ ry))
    rel = L - A
    apply = lambda m, x: np.einsum("nij,nj->ni", m, x)  # noqa: E731
    return (A + delta + apply(r, rel), apply(r, Lu),
            dA + ddelta + apply(dr, rel) + apply(r, Lv - dA), apply(dr, Lu) + apply(r, Luv))


def _cross_matrix(a: Sequence[float] | NDArray[np.float64]) -> NDArray[np.float64]:
    x, y, z = a
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def evaluate(params: LeafParams, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """Points L_Ω(u, v) of eq. 6 in leaf space (no world transform), shape (N, 3) float64."""
    return partials(params, u, v).L


def normals(params: LeafParams, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """Unit upper-side normals ``normalize(∂L/∂v × ∂L/∂u)`` (see the module docstring), (N, 3)."""
    uu, vv = uv_arrays(u, v)
    p = partials(params, uu, vv)
    return normal_from(p, vv)


def tessellate(params: LeafParams, nu: int = DEFAULT_GRID[0], nv: int = DEFAULT_GRID[1]) -> Mesh:
    """Bake the leaf on the (nu × nv) grid of :func:`grid_uv` (leaf space, no world transform),
    as drawn (:func:`drawn_uv`)."""
    uv = drawn_uv(params, grid_uv(nu, nv))
    p = partials(params, uv[:, 0], uv[:, 1])
    return Mesh(p.L, normal_from(p, uv[:, 1]), uv, grid_indices(nu, nv))
