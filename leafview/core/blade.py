"""Reference evaluation of the leaf surface L_Ω(u, v) (Chaurasia & Beardsley 2017, sec. 3, eqs 1-6) in float64.

Conventions (the GLSL in ``shaders/leaf_eval.glsl`` follows them line for line):

* ``u ∈ [-1, 1]``, ``v ∈ [0, 1]``. ``σ = +1`` for ``u >= 0`` (the half built with ``+x̄s``),
  ``σ = -1`` for ``u < 0`` (built with ``-x̄s``); ``s = |u|`` is the cross-section parameter.
* In-plane axis normal (eq. 2): ``n(v) = normalize((-A'_y, A'_x, 0))``. For a straight axis along
  +y this is -x, so the ``u >= 0`` half lies on the -x side and u runs from +x (u = -1) to -x
  (u = +1): one continuous parameterisation across the midrib.
* Control points (eqs 3-4) for side σ: ``s_i = A(v̄_i) + σ x̄_i n(v̄_i) + z̄s_i ẑ``,
  ``f_i`` and ``g_i`` the same with ``σ x̄_i / 3``, ``2 σ x̄_i / 3`` and ``z̄f_i``, ``z̄g_i``; S, F, G
  are quartics with base (0,0,0) and apex (0,1,0).
* Extended silhouettes (:mod:`leafview.core.params`): N rows give S, F and G of degree N + 1
  (eq. 1 with n = N + 1). A row tilted by φ_i displaces its control point along the normal turned
  towards the base: ``s_i = A(v̄_i) + x̄_i (σ cos φ_i n(v̄_i) - sin φ_i t(v̄_i)) + z̄s_i ẑ`` with
  ``t`` the unit axis tangent; F and G take 1/3 and 2/3 of the same displacement. The tilt part
  does not depend on σ, so the blade stays mirror-symmetric about the axis, and the rulings near
  the margin point from the feet ``A(v̄_i)`` to the margin: a basal lobe hangs from the base
  instead of being swept by lines parallel to n (which would fill the sinus of a cordate leaf).
  With N = 3 and φ = 0 this is exactly the paper's quartic.
* Cross-section (eqs 5-6): ``L = Σ_k B³_k(s) c_k(v)`` with ``c = (A, F_σ, G_σ, S_σ)``.
* Jitter (sec. 6), when enabled: ``D = amp · j(v) · s² · τ(v) · σ n(v)`` with ``j`` the periodic
  piecewise-linear table read at ``v · density``, ``τ(v) = 1 - (2v - 1)⁴`` (zero at base and
  apex) and ``s²`` fading it to zero at the midrib with zero slope, so the blade stays whole.
* Normals: ``N = normalize(∂L/∂v × ∂L/∂u)`` = −(∂L/∂u × ∂L/∂v), the upper (+z for a flat leaf,
  adaxial, "front") side. At the pinched base and apex ∂L/∂u vanishes; there the limit direction
  ``±∂²L/∂u∂v`` replaces it (``+`` at v = 0, ``-`` at v = 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.bezier import bernstein, derivative_points, in_plane_normal
from leafview.core.limits import MAX_GRID
from leafview.core.margin import margin_frame
from leafview.core.params import Jitter, LeafParams
from leafview.errors import ParamError

__all__ = [
    "JITTER_TABLE_SIZE",
    "axis_frames",
    "tilt_offsets",
    "control_polygons",
    "jitter_table",
    "Partials",
    "blade_partials",
    "normal_from",
    "tip_taper",
    "uv_arrays",
    "drawn_uv",
    "Mesh",
    "grid_uv",
    "grid_indices",
]

JITTER_TABLE_SIZE = 256
BASE = np.zeros(3)                # fixed base and apex of every leaf (Chaurasia & Beardsley 2017, sec. 3)
APEX = np.array([0.0, 1.0, 0.0])


def jitter_table(jitter: Jitter, size: int = JITTER_TABLE_SIZE) -> NDArray[np.float32]:
    """The jitter values for ``jitter.seed``: ``size`` uniform numbers in [0, 1], float32 (the
    exact values uploaded to the GPU texture, so both sides read identical data)."""
    rng = np.random.default_rng(int(jitter.seed))
    return rng.random(size).astype(np.float32)


def _basis(n: int, t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Bernstein basis at ``t``, computed once per distinct value (grids repeat each u and v)."""
    values, inverse = np.unique(t, return_inverse=True)
    if values.size * 4 > t.size:
        return bernstein(n, t)
    return bernstein(n, values)[inverse.ravel()]


def _curve(points: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    return bernstein(points.shape[-2] - 1, t) @ points


def _axis_normal(d: NDArray[np.float64]) -> NDArray[np.float64]:
    """Eq. 2: the axis tangent rotated by +90° in xy, z dropped, normalised."""
    m = np.stack([-d[..., 1], d[..., 0], np.zeros_like(d[..., 0])], axis=-1)
    return m / np.linalg.norm(m, axis=-1, keepdims=True)


def axis_frames(params: LeafParams) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The per-leaf constants of eqs 3-4: ``A(v̄_i)`` and ``x̄s_i cos φ_i · n(v̄_i)``, each (N, 3)
    (N = 3 rows and φ = 0 for the paper's model: ``x̄s_i · n(v̄_i)``).

    The GPU computes the same two arrays once per leaf (``shaders/leaf_prepare.comp``).
    """
    sh = params.shape
    pa = sh.axis_points()
    a = _curve(pa, sh.vbar)
    n = _axis_normal(_curve(derivative_points(pa), sh.vbar))
    xs = sh.xs if not sh.extended else sh.xs * np.cos(sh.phi)
    return a, xs[:, None] * n


def tilt_offsets(params: LeafParams) -> NDArray[np.float64]:
    """The side-independent part of each tilted row's displacement, ``-x̄s_i sin φ_i t(v̄_i)``
    with ``t`` the unit in-plane axis tangent, (N, 3); zero for untilted rows. The GPU's prepare
    pass writes the same numbers (``tilt`` rows of the leaf record)."""
    sh = params.shape
    pa = sh.axis_points()
    d = _curve(derivative_points(pa), sh.vbar)
    t = np.stack([d[:, 0], d[:, 1], np.zeros(len(d))], axis=-1)
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    return (-sh.xs * np.sin(sh.phi))[:, None] * t


def _side_controls(params: LeafParams) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Control points of S, F and G (eqs 3, 4a, 4b) for both sides.

    Returns ``(plus, minus)``, each (N + 2, 9): columns 0-2 are S, 3-5 F, 6-8 G, rows the control
    points base, N inner (N = 3 for the paper's quartic), apex.
    """
    sh = params.shape
    a, q = axis_frames(params)
    tq = tilt_offsets(params) if sh.extended else np.zeros_like(q)
    z = np.array([0.0, 0.0, 1.0])
    out = []
    for sigma in (1.0, -1.0):
        cols = []
        for frac, zz in ((1.0, sh.zs), (1 / 3, np.asarray(sh.zf)), (2 / 3, np.asarray(sh.zg))):
            mid = a + (sigma * frac) * q + frac * tq + np.asarray(zz)[:, None] * z
            cols.append(np.vstack([BASE, mid, APEX]))
        out.append(np.hstack(cols))
    return out[0], out[1]


def control_polygons(params: LeafParams) -> dict[str, NDArray[np.float64]]:
    """Control points of the curves of eqs 3-4 in leaf space, for drawing control polygons:
    ``"A"`` (4, 3); ``"S+"``, ``"F+"``, ``"G+"`` (the u >= 0 half) and ``"S-"``, ``"F-"``,
    ``"G-"`` (N + 2, 3) each (5 for the paper's quartic)."""
    plus, minus = _side_controls(params)
    out = {"A": params.shape.axis_points()}
    for sign, ctrl in (("+", plus), ("-", minus)):
        for k, name in enumerate("SFG"):
            out[name + sign] = ctrl[:, 3 * k:3 * k + 3].copy()
    return out


@dataclass(frozen=True)
class Partials:
    """``L`` and its partial derivatives at N points, each (N, 3) float64."""

    L: NDArray[np.float64]
    Lu: NDArray[np.float64]
    Lv: NDArray[np.float64]
    Luv: NDArray[np.float64]


def uv_arrays(u: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Flattened float64 (u, v) arrays, checked: finite, u in [-1, 1], v in [0, 1]."""
    uu, vv = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
    uu, vv = uu.ravel(), vv.ravel()
    if np.any(~np.isfinite(uu)) or np.any(~np.isfinite(vv)):
        raise ValueError("u and v must be finite")
    if np.any(np.abs(uu) > 1.0) or np.any((vv < 0.0) | (vv > 1.0)):
        raise ValueError("u must lie in [-1, 1] and v in [0, 1]")
    return uu, vv


Arr = NDArray[np.float64]


def blade_partials(params: LeafParams, u: ArrayLike, v: ArrayLike) -> tuple[Partials, Arr, Arr, Arr, Arr, Arr]:
    """The undeformed blade: L, ∂L/∂u, ∂L/∂v and ∂²L/∂u∂v (Chaurasia & Beardsley 2017, eqs 1-6)
    with the jitter of sec. 6 when enabled, but no ripple or bending.

    Returns the partials and what the deformations need: ``s = |u|``, ``σ``, ``v`` (flattened),
    the axis ``A(v)`` and ``A'(v)``."""
    uu, vv = uv_arrays(u, v)
    sigma = np.where(uu >= 0.0, 1.0, -1.0)
    s = np.abs(uu)
    pa = params.shape.axis_points()
    pa_d = derivative_points(pa)

    # longitudinal curves c_k(v) = (A, F_σ, G_σ, S_σ) and their v-derivatives (eq. 5)
    deg = params.shape.rows + 1  # 4: the paper's quartic
    b4, db4, b3 = _basis(deg, vv), _basis(deg - 1, vv), _basis(3, vv)
    c = np.empty((4,) + vv.shape + (3,))
    dc = np.empty_like(c)
    c[0], dc[0] = b3 @ pa, _basis(2, vv) @ pa_d
    plus, minus = _side_controls(params)
    right = sigma > 0
    for mask, ctrl in ((right, plus), (~right, minus)):
        if not mask.any():
            continue
        pos = (b4[mask] @ ctrl).reshape(-1, 3, 3)  # (n, curve S/F/G, xyz)
        der = (db4[mask] @ (float(deg) * (ctrl[1:] - ctrl[:-1]))).reshape(-1, 3, 3)
        c[3][mask], c[1][mask], c[2][mask] = pos[:, 0], pos[:, 1], pos[:, 2]
        dc[3][mask], dc[1][mask], dc[2][mask] = der[:, 0], der[:, 1], der[:, 2]

    if params.margin is not None:
        _margin_curves(params, sigma, vv, b4, db4, c, dc)

    b = _basis(3, s)  # (N, 4)
    db = _basis(2, s) @ np.array([[-3, 3, 0, 0], [0, -3, 3, 0], [0, 0, -3, 3]], dtype=np.float64)
    L = np.einsum("nk,knd->nd", b, c)
    Lu = sigma[:, None] * np.einsum("nk,knd->nd", db, c)
    Lv = np.einsum("nk,knd->nd", b, dc)
    Luv = sigma[:, None] * np.einsum("nk,knd->nd", db, dc)

    jit = params.jitter
    if jit.enabled and jit.amplitude > 0.0:
        L, Lu, Lv, Luv = _add_jitter(params, s, sigma, vv, pa_d, L, Lu, Lv, Luv)
    return Partials(L, Lu, Lv, Luv), s, sigma, vv, c[0], dc[0]


def _margin_curves(params: LeafParams, sigma: Arr, vv: Arr, b4: Arr, db4: Arr, c: Arr, dc: Arr) -> None:
    """A leaf with a landmark margin (:mod:`leafview.core.margin`): S, F and G of each side become
    ``P + σ Q k + z ẑ`` (k = 1, 1/3, 2/3) with P = A(y(v)) and Q = x(v) n(y(v)) from the side's
    quadratic B-spline (Garg & Leow 2011, eqs 2-6), the heights z the paper's quartics (eqs 3-4)."""
    margin = params.margin
    assert margin is not None
    sh = params.shape
    axis = sh.axis_points()
    for sg in (1.0, -1.0):
        mask = sigma == sg
        if not mask.any():
            continue
        side = margin.side(sg)
        xy, dxy = side.evaluate(vv[mask])
        P, Q, dP, dQ = margin_frame(xy[0], dxy[0], axis)
        for k, (frac, zz) in zip((3, 1, 2), ((1.0, sh.zs), (1 / 3, sh.zf), (2 / 3, sh.zg))):
            zc = np.r_[0.0, np.asarray(zz, np.float64), 0.0]
            z = b4[mask] @ zc
            dz = db4[mask] @ (4.0 * np.diff(zc))
            c[k][mask] = P + (sg * frac) * Q
            c[k][mask, 2] += z
            dc[k][mask] = dP + (sg * frac) * dQ
            dc[k][mask, 2] += dz


def tip_taper(vv: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """τ(v) = 1 - (2v - 1)⁴ and its derivative: zero at base and apex, flat in the middle."""
    w = 2.0 * vv - 1.0
    return 1.0 - w**4, -8.0 * w**3


def _add_jitter(params: LeafParams, s: Arr, sigma: Arr, vv: Arr, pa_d: Arr,
                L: Arr, Lu: Arr, Lv: Arr, Luv: Arr) -> tuple[Arr, Arr, Arr, Arr]:
    jit = params.jitter
    table = jitter_table(jit).astype(np.float64)
    size = table.shape[0]
    t = vv * jit.density
    i0 = np.floor(t)
    frac = t - i0
    i0 = i0.astype(np.int64) % size
    i1 = (i0 + 1) % size
    j = table[i0] + (table[i1] - table[i0]) * frac
    dj = (table[i1] - table[i0]) * jit.density
    tau, dtau = tip_taper(vv)

    d1 = _curve(pa_d, vv)
    d2 = _curve(derivative_points(pa_d), vv)
    n, dn = in_plane_normal(d1, d2, vv)

    amp = jit.amplitude
    g = (j * tau)[:, None] * n                               # j τ n
    dg = (dj * tau + j * dtau)[:, None] * n + (j * tau)[:, None] * dn
    L = L + (amp * s**2 * sigma)[:, None] * g
    Lu = Lu + (amp * 2.0 * s)[:, None] * g
    Lv = Lv + (amp * s**2 * sigma)[:, None] * dg
    Luv = Luv + (amp * 2.0 * s)[:, None] * dg
    return L, Lu, Lv, Luv


def normal_from(p: Partials, vv: NDArray[np.float64]) -> NDArray[np.float64]:
    lu = np.where((vv <= 0.0)[:, None], p.Luv, np.where((vv >= 1.0)[:, None], -p.Luv, p.Lu))
    n = np.cross(p.Lv, lu)
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    return n / np.where(length > 0.0, length, 1.0)


def grid_uv(nu: int, nv: int) -> NDArray[np.float32]:
    """The fixed (u, v) grid, (nu·nv, 2) float32, u fastest: ``u = linspace(-1, 1, nu)``,
    ``v = linspace(0, 1, nv)``. An odd ``nu`` puts a column on the midrib."""
    if nu < 2 or nv < 2:
        raise ValueError(f"grid needs at least 2×2 samples, got {nu}×{nv}")
    if nu > MAX_GRID or nv > MAX_GRID:   # before allocating: 10⁶ × 10⁶ would ask for terabytes
        raise ParamError("grid", f"at most {MAX_GRID}×{MAX_GRID} samples, got {nu}×{nv}")
    u = np.linspace(-1.0, 1.0, nu)
    v = np.linspace(0.0, 1.0, nv)
    uu, vv = np.meshgrid(u, v)
    return np.stack([uu.ravel(), vv.ravel()], axis=-1).astype(np.float32)


def grid_indices(nu: int, nv: int) -> NDArray[np.uint32]:
    """Triangles of the grid, (2(nu-1)(nv-1), 3) uint32, counter-clockwise seen from +z."""
    i = np.arange(nu - 1)
    j = np.arange(nv - 1)
    ii, jj = np.meshgrid(i, j)
    p00 = (jj * nu + ii).ravel()
    p10, p01 = p00 + 1, p00 + nu
    p11 = p01 + 1
    tris = np.concatenate([np.stack([p00, p01, p10], -1), np.stack([p10, p01, p11], -1)])
    return tris.astype(np.uint32)


@dataclass(frozen=True)
class Mesh:
    """A baked leaf: ``vertices`` and ``normals`` (V, 3) float64, ``uv`` (V, 2), ``indices`` (T, 3)."""

    vertices: NDArray[np.float64]
    normals: NDArray[np.float64]
    uv: NDArray[np.float64]
    indices: NDArray[np.uint32]


def drawn_uv(params: LeafParams, uv: ArrayLike) -> NDArray[np.float64]:
    """The surface parameters the vertex shader evaluates for grid parameters ``uv`` (N, 2): the
    grid itself, or with ``shape.half = ±1`` (one side of the midrib only) the grid's u ∈ [-1, 1]
    spread over that half, ``u' = (u + half) / 2`` (increasing with u, so triangles keep their
    winding and the upper side stays the front face)."""
    out = np.array(uv, dtype=np.float64, copy=True).reshape(-1, 2)
    half = params.shape.half
    if half:
        out[:, 0] = 0.5 * (out[:, 0] + half)
    return out
