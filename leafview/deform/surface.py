"""The whole leaf surface in float64: the blade (Chaurasia & Beardsley 2017, eqs 1-6) with
jitter, the vein-driven displacement (Hong 2005, ch. 7.2), rippled margins (Geng, Hu & Zhang
2014, eq. 5) and the bent, twisted midrib (Geng, Hu & Zhang 2014, sec. 5.2.2), in that order.
This is the numpy twin of ``shaders/leaf_eval.glsl``.

The vein-driven part is optional: :func:`partials`, :func:`evaluate`, :func:`normals` and
:func:`tessellate` take ``vein_grid``, the (nv, nu, 4) grid of
:func:`leafview.botany.vein_shape.vein_grid` (xyz: the blade's displacement by its edited veins;
w: the ripple coordinate, the v at which the secondary vein through the point leaves its parent),
read by :func:`sample_vein_grid`. Without it the results are those of a leaf without veins.

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
from leafview.core.texture import texture_st, uv_of_st
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
    "vein_grid_uv",
    "sample_vein_grid",
]

Arr = NDArray[np.float64]


def partials(params: LeafParams, u: ArrayLike, v: ArrayLike, *, bend: BendProfile | None = None,
             vein_grid: ArrayLike | None = None) -> Partials:
    """L, ∂L/∂u, ∂L/∂v and ∂²L/∂u∂v of the whole leaf: the blade (with jitter when enabled),
    then the vein-driven displacement (with ``vein_grid``), the rippled margin, then the bent and
    twisted midrib. ``bend`` replaces the leaf's own bend profile (a scene bends every leaf of a
    species by the species' profile)."""
    p, s, sigma, vv, A, dA = blade_partials(params, u, v)
    L, Lu, Lv, Luv = p.L, p.Lu, p.Lv, p.Luv
    ripple_w = None
    if vein_grid is not None:
        g, gu, gv, guv = sample_vein_grid(vein_grid, sigma * s, vv)
        L, Lu, Lv, Luv = L + g[:, :3], Lu + gu[:, :3], Lv + gv[:, :3], Luv + guv[:, :3]
        ripple_w = (g[:, 3], gu[:, 3], gv[:, 3], guv[:, 3])
    if params.ripple.enabled:
        L, Lu, Lv, Luv = _add_ripple(params, s, sigma, vv, L, Lu, Lv, Luv, ripple_w)
    if bend is None and params.bending.active:
        bend = bend_profile(params)
    if bend is not None:
        L, Lu, Lv, Luv = _bend(bend, vv, A, dA, L, Lu, Lv, Luv)
    return Partials(L, Lu, Lv, Luv)


def vein_grid_uv(nu: int, nv: int) -> tuple[Arr, Arr]:
    """(u, v) of the texel centres of a (nv, nu) vein grid, each (nv, nu): texel (i, j) sits at
    ``(s, t) = ((i + 0.5) / nu, (j + 0.5) / nv)`` of :func:`leafview.core.texture.texture_st`,
    like the image textures (row 0 at the apex, column 0 at u = +1)."""
    if nu < 2 or nv < 2:
        raise ValueError(f"a vein grid needs at least 2×2 texels, got {nu}×{nv}")
    uu, vv = uv_of_st((np.arange(nu) + 0.5)[None, :] / nu, (np.arange(nv) + 0.5)[:, None] / nv)
    return np.broadcast_to(uu, (nv, nu)).copy(), np.broadcast_to(vv, (nv, nu)).copy()


_APEX_TEXEL = np.array([0.0, 0.0, 0.0, 1.0])   # pinned rows past the texel centres: no displacement,
_BASE_TEXEL = np.zeros(4)                        # w = v, so the pinched base and apex stay closed


def sample_vein_grid(grid: ArrayLike, u: ArrayLike, v: ArrayLike) -> tuple[Arr, Arr, Arr, Arr]:
    """The vein grid at (u, v) and its partials: value, ∂/∂u, ∂/∂v and ∂²/∂u∂v, each (N, 4).

    Bilinear between texel centres (:func:`vein_grid_uv`), clamped across u (the margin) and
    pinned along v: past the first and last row of centres the grid runs linearly to
    ``(0, 0, 0, 1)`` at the apex and ``(0, 0, 0, 0)`` at the base, so that the displacement
    vanishes where the blade is pinched (as it does at the midrib's ends, which are held) and every
    u keeps the same base and apex. The twin of ``vein_grid_eval`` in ``shaders/leaf_eval.glsl``
    (texel fetches, no filtering hardware: exact weights and exact partials)."""
    g = np.asarray(grid, np.float64)
    if g.ndim != 3 or g.shape[2] != 4 or g.shape[0] < 2 or g.shape[1] < 2:
        raise ValueError(f"a vein grid is (nv, nu, 4) with nu, nv >= 2, got {g.shape}")
    nv, nu = g.shape[:2]
    st_s, st_t = texture_st(u, v)
    x = np.ravel(st_s) * nu - 0.5
    wx = ((x > 0.0) & (x < nu - 1)).astype(np.float64)[:, None]   # ∂x/∂x: 0 where clamped
    x = np.clip(x, 0.0, nu - 1)
    i0 = np.minimum(np.floor(x), nu - 2).astype(np.int64)
    fx = (x - i0)[:, None]
    y = np.ravel(st_t) * nv - 0.5                                  # -0.5 (apex) .. nv - 0.5 (base)
    j = np.clip(np.floor(y), -1, nv - 1).astype(np.int64)
    y0 = np.maximum(j, -0.5)
    y1 = np.minimum(j + 1, nv - 0.5)

    def row(k: NDArray[np.int64]) -> tuple[Arr, Arr]:
        kc = np.clip(k, 0, nv - 1)
        a, b = g[kc, i0], g[kc, i0 + 1]
        r, rx = a + (b - a) * fx, (b - a) * wx
        r = np.where((k < 0)[:, None], _APEX_TEXEL, np.where((k >= nv)[:, None], _BASE_TEXEL, r))
        rx = np.where(((k < 0) | (k >= nv))[:, None], 0.0, rx)
        return r, rx

    r0, r0x = row(j)
    r1, r1x = row(j + 1)
    h = (1.0 / (y1 - y0))[:, None]
    fy = (y - y0)[:, None] * h
    value = r0 + (r1 - r0) * fy
    gx = r0x + (r1x - r0x) * fy
    return (value, gx * (-0.5 * nu), (r1 - r0) * (h * -float(nv)),
            (r1x - r0x) * (h * (0.5 * nu * nv)))


def _add_ripple(params: LeafParams, s: Arr, sigma: Arr, vv: Arr, L: Arr, Lu: Arr, Lv: Arr, Luv: Arr,
                ripple_w: tuple[Arr, Arr, Arr, Arr] | None = None) -> tuple[Arr, Arr, Arr, Arr]:
    """Rippled margin (Geng, Hu & Zhang 2014, eq. 5): each cross-section is a secondary vein, a cantilever from
    the midrib under the turbulent load ``r = P [λ + (1 - λ) N(k · veins · v + θ)]``. In the
    small-deflection limit of eq. 4 a tip-loaded cantilever deflects as ``c(s) = s² (3 - s) / 2``
    (zero with zero slope at the midrib, 1 at the margin), so ``D = τ(v) r(v) c(|u|) ẑ``: out of
    the leaf plane (+z in leaf space, before bending), tapered to zero at base and apex.

    With a vein grid the load indexes the secondary veins themselves: ``ripple_w`` is the ripple
    coordinate w(u, v) and its partials (w, ∂w/∂u, ∂w/∂v, ∂²w/∂u∂v), and ``v`` in the load becomes
    w, constant along each secondary (the veins are the load-bearing beams). ∂²L/∂u∂v then leaves
    out ``τ r''(w) w_u w_v c``: it vanishes at the base and apex (τ = 0), the only places where
    ∂²L/∂u∂v is used (the normal of the pinched ends)."""
    rip = params.ripple
    signal = ripple_signal(rip.beta, rip.seed)
    side = np.where(sigma > 0, 0, 1)  # pairs are [left (u >= 0), right (u < 0)]
    amp, lam, k, theta = (np.asarray(getattr(rip, name))[side]
                          for name in ("amplitude", "fluctuation", "interval", "phase"))
    w = vv if ripple_w is None else ripple_w[0]
    n_val, n_slope = sample_periodic(signal, k * rip.veins * w + theta)
    r = amp * (lam + (1.0 - lam) * n_val)
    dr = amp * (1.0 - lam) * n_slope * k * rip.veins
    tau, dtau = tip_taper(vv)
    c = 0.5 * s * s * (3.0 - s)
    dc = 3.0 * s - 1.5 * s * s
    z = np.array([0.0, 0.0, 1.0])
    if ripple_w is None:
        g = dtau * r + tau * dr
        return (L + (tau * r * c)[:, None] * z, Lu + (sigma * tau * r * dc)[:, None] * z,
                Lv + (c * g)[:, None] * z, Luv + (sigma * dc * g)[:, None] * z)
    _, wu, wv, wuv = ripple_w
    ru = dr * wu
    g = dtau * r + tau * (dr * wv)                               # ∂(τ r)/∂v
    return (L + (tau * r * c)[:, None] * z, Lu + (sigma * tau * r * dc + tau * ru * c)[:, None] * z,
            Lv + (c * g)[:, None] * z,
            Luv + (sigma * dc * g + c * (dtau * ru + tau * dr * wuv))[:, None] * z)


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


def evaluate(params: LeafParams, u: ArrayLike, v: ArrayLike, *,
             vein_grid: ArrayLike | None = None) -> NDArray[np.float64]:
    """Points L_Ω(u, v) of eq. 6 in leaf space (no world transform), shape (N, 3) float64;
    ``vein_grid`` as in :func:`partials`."""
    return partials(params, u, v, vein_grid=vein_grid).L


def normals(params: LeafParams, u: ArrayLike, v: ArrayLike, *,
            vein_grid: ArrayLike | None = None) -> NDArray[np.float64]:
    """Unit upper-side normals ``normalize(∂L/∂v × ∂L/∂u)`` (see the module docstring), (N, 3)."""
    uu, vv = uv_arrays(u, v)
    p = partials(params, uu, vv, vein_grid=vein_grid)
    return normal_from(p, vv)


def tessellate(params: LeafParams, nu: int = DEFAULT_GRID[0], nv: int = DEFAULT_GRID[1], *,
               vein_grid: ArrayLike | None = None) -> Mesh:
    """Bake the leaf on the (nu × nv) grid of :func:`grid_uv` (leaf space, no world transform),
    as drawn (:func:`drawn_uv`)."""
    uv = drawn_uv(params, grid_uv(nu, nv))
    p = partials(params, uv[:, 0], uv[:, 1], vein_grid=vein_grid)
    return Mesh(p.L, normal_from(p, uv[:, 1]), uv, grid_indices(nu, nv))
