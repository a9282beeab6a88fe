"""The swept surface of a lobed leaf (Mündermann et al. 2003, secs 3.3-4): railroad ties between a
branching skeleton and one closed margin, carried by turtle frames. This is the numpy twin of
the lobed branch of ``shaders/leaf_eval.glsl``; a readback test compares the two.

A :class:`SweepTable` holds ``N`` railroad ties T_j in the order the sweep visits them: clockwise
around the margin from the base (base → left side → apex → right side → base), which is the
skeleton's tour, each skeleton edge once distally and once basally (Mündermann et al. 2003,
sec. 3.3). Tie j runs from its foot k_j on the skeleton to s_j on the margin. Per tie the table
stores, already deformed by the turtle (Mündermann et al. 2003, sec. 4, eqs 2-3, and the
per-branch bend, twist and turn):

* ``origin``  X_j: the foot in leaf space;
* ``rim``     the tie's end, X_j + R_j (s_j - k_j, 0) with R_j the turtle's rotation at the foot;
* ``up``      R_j ẑ, the turtle's up axis (the direction of cupping and ripples);
* ``length``  ℓ_j = |s_j - k_j|;
* ``flat``    (k_j, s_j) of the flat leaf, the shading coordinates (Mündermann et al. 2003, eq. 1);
* ``margin``  w_j, the margin's arc length from the base to s_j over the whole margin (0 ≤ w < 1).

The surface is evaluated on the grid the other leaves use: u in [-1, 1] runs along the tie,
t = (u + 1) / 2 (0 on the skeleton, 1 on the margin); v in [0, 1] runs along the tour, x = v N.
Between ties each stored quantity q is the periodic Catmull-Rom spline through q_j (at grid rows,
x is an integer and q(x) = q_j exactly, so the two sides of a skeleton edge, whose feet the
table pairs, meet without a crack):

    P(t, x) = O(x) + t (E(x) - O(x)) + cup ℓ(x) t² U(x)

O, E, U, ℓ the splines of origin, rim, up and length; ``cup`` cups the ties (0: the straight
generating line). The upper-side normal is normalize(∂P/∂v × ∂P/∂u), or U where the tie has no
extent (at a skeleton tip, where the foot turns back).

Ripples along the lobes' margins (Geng, Hu & Zhang 2014, eq. 5, as for unilobed leaves in
:func:`leafview.deform.surface.evaluate`): with the leaf's ripple on, each tie is a cantilever from
the skeleton loaded at the margin, D = r(w) c(t) U(x) with r = P [λ + (1 - λ) N(k · veins · w + θ)]
(the left-side (u >= 0) settings, N the leaf's fBm signal), c(t) = t² (3 - t) / 2, w the margin
coordinate along the tour (unwrapped: it gains 1 per turn), tapered by ρ(ℓ) = ℓ² / (ℓ² + ℓ0²) on
short ties (ℓ0 = :data:`RIPPLE_TIE`).

A lobed leaf is drawn on :func:`lobed_grid` of the grid asked for: the same ties-per-tie count
u, and every 1st, 2nd or 4th tie along v, so that paired feet stay on grid rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.params import Ripple
from leafview.deform.fbm import catmull_rom, ripple_signal, sample_periodic

__all__ = ["SWEEP_ROWS", "RIPPLE_TIE", "ROW_STEPS", "SweepTable", "SweepEval", "sweep_eval", "catmull_rom_periodic",
           "table_texels", "lobed_grid", "texture_window", "texture_uv", "flat_of_uv"]

RIPPLE_TIE = 0.05    # leaf lengths: ties shorter than this ripple less (ρ(ℓ) of _add_margin_ripple)
SWEEP_ROWS = 256     # ties per table: a multiple of 4, so grids of N/2 and N/4 rows keep the pairing
ROW_STEPS = (1, 2, 4)   # ties between the rows of a lobed grid
MAX_TIE_SAMPLES = 9     # samples along a tie, at most


def lobed_grid(grid: tuple[int, int], ties: int = SWEEP_ROWS) -> tuple[int, int]:
    """The grid a lobed leaf is drawn on when ``grid`` (nu, nv) is asked for, with about as many
    vertices: ``ties / step + 1`` rows along the tour for a step of :data:`ROW_STEPS` (so rows land
    on ties) and 2 to min(nu, :data:`MAX_TIE_SAMPLES`) samples along each tie (a tie is straight
    unless cupped, rippled or turned, so the margin gets the vertices). The nearest count wins, the
    finer tour on a tie."""
    nu, nv = int(grid[0]), int(grid[1])
    want = nu * nv
    best: tuple[int, int] | None = None
    for step in ROW_STEPS:
        rows = ties // step + 1
        nt = int(min(max(round(want / rows), 2), max(min(nu, MAX_TIE_SAMPLES), 2)))
        if best is None or abs(nt * rows - want) < abs(best[0] * best[1] - want):
            best = (nt, rows)
    assert best is not None
    return best


@dataclass(frozen=True)
class SweepTable:
    """Railroad ties of a lobed leaf (see the module docstring); arrays of N rows, float64."""

    origin: NDArray[np.float64]   # (N, 3)
    rim: NDArray[np.float64]      # (N, 3)
    up: NDArray[np.float64]       # (N, 3)
    length: NDArray[np.float64]   # (N,)
    flat: NDArray[np.float64]     # (N, 4): k_x, k_y, s_x, s_y
    margin: NDArray[np.float64]   # (N,): w_j in [0, 1), increasing
    cup: float = 0.0

    @property
    def rows(self) -> int:
        return len(self.origin)

    @property
    def window(self) -> tuple[float, float, float, float]:
        """The texture window (x_c, w, y_0, h): the flat margin's bounding box (centre x, half
        width, bottom, height), which :func:`texture_uv` maps onto u in [-1, 1], v in [0, 1]."""
        return texture_window(self.flat[:, 2:])


@dataclass(frozen=True)
class SweepEval:
    """Positions ``L``, partials ``Lu``, ``Lv``, upper-side normals ``normal`` (n, 3), the flat
    position ``flat`` (n, 2), the margin coordinate ``w`` (n,) and the texture coordinates ``uv``
    (n, 2) at the evaluated (u, v)."""

    L: NDArray[np.float64]
    Lu: NDArray[np.float64]
    Lv: NDArray[np.float64]
    normal: NDArray[np.float64]
    flat: NDArray[np.float64]
    w: NDArray[np.float64]
    uv: NDArray[np.float64]      # the texture coordinates: ``flat`` in the table's window (texture_uv)


def texture_window(rim_flat: ArrayLike) -> tuple[float, float, float, float]:
    """(x_c, w, y_0, h) of the bounding box of the flat margin points ``rim_flat`` (n, 2)."""
    p = np.asarray(rim_flat, dtype=np.float64)
    x0, y0 = p.min(axis=0)
    x1, y1 = p.max(axis=0)
    return float(0.5 * (x0 + x1)), float(max(0.5 * (x1 - x0), 1e-9)), float(y0), float(max(y1 - y0, 1e-9))


def texture_uv(flat: ArrayLike, window: tuple[float, float, float, float]) -> NDArray[np.float64]:
    """A lobed leaf's texture coordinates: its flat position (Mündermann et al. 2003, eq. 1) in
    the ``window`` (x_c, w, y_0, h), u = (x - x_c) / w in [-1, 1] and v = (y - y_0) / h in [0, 1],
    the (u, v) every leaf's image texture is addressed by (:func:`leafview.core.texture.texture_st`)."""
    f = np.asarray(flat, dtype=np.float64)
    xc, hw, y0, h = window
    return np.stack([(f[..., 0] - xc) / hw, (f[..., 1] - y0) / h], axis=-1)


def flat_of_uv(u: ArrayLike, v: ArrayLike, window: tuple[float, float, float, float]
               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The inverse of :func:`texture_uv`: the flat position (x, y) of texture coordinates (u, v)."""
    xc, hw, y0, h = window
    return xc + np.asarray(u, np.float64) * hw, y0 + np.asarray(v, np.float64) * h


def table_texels(table: SweepTable) -> NDArray[np.float32]:
    """The table as the (4, N, 4) float32 texels the shader reads (row r of the texture, tie j):
    r0 (origin, w), r1 (rim, ℓ), r2 (up, and in w: tie 0 the cup, ties 1-4 the texture window
    x_c, w, y_0, h), r3 (k, s)."""
    n = table.rows
    out = np.zeros((4, n, 4), np.float32)
    out[0, :, :3], out[0, :, 3] = table.origin, table.margin
    out[1, :, :3], out[1, :, 3] = table.rim, table.length
    out[2, :, :3] = table.up
    out[2, 0, 3] = table.cup
    out[2, 1:5, 3] = table.window
    out[3] = table.flat
    return out


def catmull_rom_periodic(q: ArrayLike, x: ArrayLike, *, period_offset: ArrayLike | None = None
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The periodic Catmull-Rom spline through rows ``q`` (N, ...) at positions ``x`` (rows, any
    real) and its derivative d/dx. ``period_offset``: what a row gains per wrap past N (the
    margin coordinate gains 1), zero by default."""
    q = np.asarray(q, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    n = len(q)
    fl = np.floor(x)
    f = (x - fl)[(...,) + (None,) * (q.ndim - 1)]
    j = fl.astype(np.int64)
    pts = []
    for k in (-1, 0, 1, 2):
        idx = j + k
        wraps = np.floor_divide(idx, n)
        val = q[np.mod(idx, n)]
        if period_offset is not None:
            val = val + wraps[(...,) + (None,) * (q.ndim - 1)] * np.asarray(period_offset, dtype=np.float64)
        pts.append(val)
    p0, p1, p2, p3 = pts
    return catmull_rom(p0, p1, p2, p3, f)


def sweep_eval(table: SweepTable, uv: ArrayLike, ripple: Ripple | None = None) -> SweepEval:
    """The lobed surface at grid coordinates ``uv`` (n, 2): t = (u + 1) / 2 along the tie, x = v N
    along the tour (see the module docstring); ``ripple`` (the leaf's, when enabled) ripples the
    margins."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    n = table.rows
    t = 0.5 * (uv[:, 0] + 1.0)
    x = uv[:, 1] * n
    o, do = catmull_rom_periodic(table.origin, x)
    e, de = catmull_rom_periodic(table.rim, x)
    up, dup = catmull_rom_periodic(table.up, x)
    ln, dln = catmull_rom_periodic(table.length, x)
    fl, _ = catmull_rom_periodic(table.flat, x)
    w, dw = catmull_rom_periodic(table.margin, x, period_offset=1.0)
    tt = t[:, None]
    cup = table.cup
    L = o + tt * (e - o) + (cup * ln * t * t)[:, None] * up
    dt = (e - o) + (2.0 * cup * ln * t)[:, None] * up
    dx = do + tt * (de - do) + (cup * t * t)[:, None] * (dln[:, None] * up + ln[:, None] * dup)
    Lu = 0.5 * dt
    Lv = n * dx
    if ripple is not None and ripple.enabled:
        L, Lu, Lv = _add_margin_ripple(ripple, t, w, dw, up, dup, ln, dln, n, L, Lu, Lv)
    nrm = np.cross(Lv, Lu)
    size = np.linalg.norm(nrm, axis=1)
    scale = np.maximum(np.linalg.norm(Lu, axis=1) * np.linalg.norm(Lv, axis=1), 1e-30)
    upn = up / np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-30)
    ok = size > 1e-6 * scale
    normal = np.where(ok[:, None], nrm / np.where(ok, size, 1.0)[:, None], upn)
    flat = fl[:, :2] + tt * (fl[:, 2:] - fl[:, :2])
    xc, hw, y0, h = (float(np.float32(x)) for x in table.window)   # as the shader reads them (float32)
    return SweepEval(L, Lu, Lv, normal, flat, np.mod(w, 1.0), texture_uv(flat, (xc, hw, y0, h)))


def _add_margin_ripple(rip: Ripple, t: NDArray[np.float64], w: NDArray[np.float64], dw: NDArray[np.float64],
                       up: NDArray[np.float64], dup: NDArray[np.float64], ln: NDArray[np.float64],
                       dln: NDArray[np.float64], n: int, L: NDArray[np.float64],
                       Lu: NDArray[np.float64], Lv: NDArray[np.float64]
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """D = r(w) c(t) ρ(ℓ) U(x) (see the module docstring), ρ(ℓ) = ℓ² / (ℓ² + ℓ0²) with ℓ0 =
    :data:`RIPPLE_TIE` (short ties ripple less; the base's zero-length tie not at all, so the tour
    closes without a seam), added to L and its partials; ``w``, ``dw`` the
    unwrapped margin coordinate and dw/dx, ``up``, ``dup`` U and dU/dx. The twin of the lobed
    branch's ripple in ``shaders/leaf_eval.glsl`` (the signal sampled as ``add_ripple`` does)."""
    amp, lam, k, theta = (float(getattr(rip, name)[0]) for name in ("amplitude", "fluctuation", "interval", "phase"))
    n_val, n_slope = sample_periodic(ripple_signal(rip.beta, rip.seed), k * rip.veins * w + theta)
    r = amp * (lam + (1.0 - lam) * n_val)
    dr = amp * (1.0 - lam) * n_slope * k * rip.veins          # dr/dw
    den = ln * ln + RIPPLE_TIE**2
    rho = ln * ln / den                                      # short ties ripple less, the base's not at all
    drho = 2.0 * ln * RIPPLE_TIE**2 / (den * den) * dln      # d rho / dx
    c = 0.5 * t * t * (3.0 - t)
    dc = 3.0 * t - 1.5 * t * t
    return (L + (r * c * rho)[:, None] * up, Lu + (0.5 * r * dc * rho)[:, None] * up,
            Lv + n * ((dr * dw * c * rho + r * c * drho)[:, None] * up + (r * c * rho)[:, None] * dup))
