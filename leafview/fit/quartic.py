"""The paper's quartic blade (Chaurasia & Beardsley 2017, eqs 1-6, N = 3 rows, no tilt) as a linear
map of 21 control points, for the cloud fit (:mod:`leafview.fit.cloud`).

With (u, v) fixed the undeformed blade is linear in the control points of its curves:
``L(u, v) = W(u, v) @ C(Ω)``, W (N, 21) Bernstein products, C (21, 3) the rows

* 0 the apex (0, 1, 0), 1 ``a1``, 2 ``a2`` (the base is the origin and adds nothing),
* 3-5 F, 6-8 G, 9-11 S: the inner control points of the u >= 0 half,
* 12-20 the same for the u < 0 half,

so a least-squares step over Ω costs two small matrix products, and ∂L/∂Ω = W ∂C/∂Ω with the
(21, 3, 21) Jacobian of the 21 control points only. :func:`weights` and :func:`blade` reproduce
:func:`leafview.deform.surface.partials` (L, ∂L/∂u, ∂L/∂v) of a leaf without jitter, ripple or
bending to rounding (the tests compare them); :func:`project` finds each point's closest point on
the blade.

The fit works on Ω' = ``[a1, a2, θ, x̄s, z̄s, z̄f, z̄g]``: the rows' v̄ are the cumulative
softmax of ``(θ1, θ2, θ3, 0)``, so any Ω' has ``0 < v̄1 < v̄2 < v̄3 < 1`` and an unbounded
Levenberg-Marquardt can run on it.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from leafview.core.bezier import bernstein
from leafview.core.blade import grid_uv

__all__ = ["MIN_GAP", "REVERSE", "mm", "gram", "weights", "weights_all", "blade", "controls", "controls_jacobian", "to_omega",
           "from_omega", "vbar", "theta", "axis", "project", "reversed_omega"]

MIN_GAP = 0.02              # smallest spacing of the rows' v̄ (and from base and apex) that theta() keeps
PROJECT_GRID = (17, 65)     # (u, v) grid of the closest-point look-up before the Gauss-Newton steps
PROJECT_STEPS = 4           # Gauss-Newton steps of project() after the look-up
_MIDRIB = 0.05              # project(): points this close to u = 0 also try the other side of the midrib
APEX = np.array([0.0, 1.0, 0.0])
Z = np.array([0.0, 0.0, 1.0])
# the leaf turned by 180° about z through (0, 1/2, 0): base and apex swap (see reversed_omega)
REVERSE = np.array([[-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])

Arr = NDArray[np.float64]
# OpenBLAS runs a matrix product on several threads above about 2.6e5 multiply-adds. On a loaded
# machine the waiting threads made one (1500 × 21) · (21 × 63) product 45 times slower (11.5 ms
# instead of 0.25 ms, measured), so the tall products of the fit are taken in row blocks below it.
BLAS_BLOCK = 200_000


def mm(a: Arr, b: Arr) -> Arr:
    """``a @ b`` for a tall ``a`` (N, k) and a small ``b`` (k, m), in row blocks of at most
    :data:`BLAS_BLOCK` multiply-adds (one BLAS thread each)."""
    rows = max(1, BLAS_BLOCK // max(1, a.shape[1] * b.shape[1]))
    if len(a) <= rows:
        return np.asarray(a @ b)
    return np.concatenate([a[i:i + rows] @ b for i in range(0, len(a), rows)])


def gram(a: Arr, b: Arr) -> Arr:
    """``aᵀ b`` for tall ``a`` (N, k) and ``b`` (N, m), summed over row blocks of at most
    :data:`BLAS_BLOCK` multiply-adds (one BLAS thread each)."""
    rows = max(1, BLAS_BLOCK // max(1, a.shape[1] * b.shape[1]))
    out = np.zeros((a.shape[1], b.shape[1]))
    for i in range(0, len(a), rows):
        out += a[i:i + rows].T @ b[i:i + rows]
    return out


def _bern(n: int, t: Arr) -> Arr:
    """The degree-n Bernstein basis at ``t`` (N,), (N, n + 1): :func:`leafview.core.bezier.bernstein`
    by products instead of powers (this is the fit's inner loop)."""
    s = 1.0 - t
    tp, sp = [np.ones_like(t), t], [np.ones_like(t), s]
    for _ in range(n - 1):
        tp.append(tp[-1] * t)
        sp.append(sp[-1] * s)
    return np.stack([math.comb(n, i) * tp[i] * sp[n - i] for i in range(n + 1)], axis=-1)


def _dbern(n: int, t: Arr) -> Arr:
    """Derivatives of the degree-n Bernstein basis, (N, n + 1)."""
    low = _bern(n - 1, t)
    out = np.zeros(t.shape + (n + 1,))
    out[..., 1:] += n * low
    out[..., :-1] -= n * low
    return out


def _assemble(b: Arr, ba: Arr, b4: Arr, plus: NDArray[np.bool_]) -> Arr:
    """W from the cross-section basis ``b`` (N, 4) over (A, F, G, S) (eq. 5), the axis basis ``ba``
    (N, 4) and the quartic basis ``b4`` (N, 5), or their derivatives."""
    w = np.empty((len(b), 21))
    w[:, 0] = b[:, 0] * ba[:, 3] + (b[:, 1] + b[:, 2] + b[:, 3]) * b4[:, 4]
    w[:, 1] = b[:, 0] * ba[:, 1]
    w[:, 2] = b[:, 0] * ba[:, 2]
    block = (b[:, 1:4, None] * b4[:, None, 1:4]).reshape(-1, 9)
    side = plus[:, None]
    w[:, 3:12] = np.where(side, block, 0.0)
    w[:, 12:21] = np.where(side, 0.0, block)
    return w


def weights(u: Arr, v: Arr, derivative: str = "") -> Arr:
    """W (N, 21) with ``L(u, v) = W @ C``; ``derivative`` "u" or "v" gives ∂W/∂u or ∂W/∂v."""
    s = np.abs(u)
    plus = u >= 0.0
    b = _dbern(3, s) * np.where(plus, 1.0, -1.0)[:, None] if derivative == "u" else _bern(3, s)
    ba = _dbern(3, v) if derivative == "v" else _bern(3, v)
    b4 = _dbern(4, v) if derivative == "v" else _bern(4, v)
    return _assemble(b, ba, b4, plus)


def weights_all(u: Arr, v: Arr) -> tuple[Arr, Arr, Arr]:
    """(W, ∂W/∂u, ∂W/∂v), sharing their Bernstein values."""
    s = np.abs(u)
    plus = u >= 0.0
    b, db = _bern(3, s), _dbern(3, s) * np.where(plus, 1.0, -1.0)[:, None]
    ba, dba, b4, db4 = _bern(3, v), _dbern(3, v), _bern(4, v), _dbern(4, v)
    return _assemble(b, ba, b4, plus), _assemble(db, ba, b4, plus), _assemble(b, dba, db4, plus)


def vbar(th: Arr) -> Arr:
    """v̄ (..., 3) of θ (..., 3): the cumulative softmax of ``(θ, 0)``."""
    t = np.concatenate([th, np.zeros(th.shape[:-1] + (1,))], axis=-1)
    e = np.exp(t - t.max(axis=-1, keepdims=True))
    return np.cumsum(e / e.sum(axis=-1, keepdims=True), axis=-1)[..., :3]


def theta(vb: Arr) -> Arr:
    """θ of v̄ (the inverse of :func:`vbar`), every gap of ``0, v̄1, v̄2, v̄3, 1`` raised to at least
    :data:`MIN_GAP` first (rows may not merge or reach base and apex)."""
    gaps = np.maximum(np.diff(np.concatenate([[0.0], vb, [1.0]])), MIN_GAP)
    return np.log(gaps[:3] / gaps[3])


def to_omega(x: Arr) -> Arr:
    """The paper's Ω (21 numbers in :meth:`LeafParams.to_vector` order) of Ω'."""
    rows = np.stack([vbar(x[6:9]), x[9:12], x[12:15]], axis=1).ravel()
    return np.concatenate([x[0:6], rows, x[15:21]])


def from_omega(omega: Arr) -> Arr:
    """Ω' of the paper's Ω (the inverse of :func:`to_omega`, up to :data:`MIN_GAP`)."""
    rows = omega[6:15].reshape(3, 3)
    return np.concatenate([omega[0:6], theta(rows[:, 0]), rows[:, 1], rows[:, 2], omega[15:21]])


def controls(x: Arr) -> Arr:
    """C (..., 21, 3) of Ω' (..., 21): eq. 2 for the normals, eqs 3-4 for the control points."""
    a1, a2 = x[..., 0:3], x[..., 3:6]
    vb = vbar(x[..., 6:9])
    xs, zs, zf, zg = x[..., 9:12], x[..., 12:15], x[..., 15:18], x[..., 18:21]
    apex = np.broadcast_to(APEX, a1.shape)
    pa = np.stack([np.zeros_like(a1), a1, a2, apex], axis=-2)                       # (..., 4, 3)
    a = bernstein(3, vb) @ pa                                                       # A(v̄_i), (..., 3, 3)
    d = bernstein(2, vb) @ (3.0 * np.diff(pa, axis=-2))
    n = np.stack([-d[..., 1], d[..., 0], np.zeros_like(d[..., 0])], axis=-1)
    q = xs[..., None] * n / np.linalg.norm(n, axis=-1, keepdims=True)
    rows = [apex[..., None, :], a1[..., None, :], a2[..., None, :]]
    for sigma in (1.0, -1.0):
        for frac, zz in ((1 / 3, zf), (2 / 3, zg), (1.0, zs)):
            rows.append(a + (sigma * frac) * q + zz[..., None] * Z)
    return np.concatenate(rows, axis=-2)


def controls_jacobian(x: Arr, h: float = 1e-6) -> Arr:
    """∂C/∂Ω' (21, 3, 21) by central differences, the 42 evaluations in one batch."""
    steps = np.eye(21) * h
    c = controls(np.concatenate([x + steps, x - steps]))
    return np.moveaxis((c[:21] - c[21:]) / (2.0 * h), 0, -1)


def axis(x: Arr, v: Arr) -> tuple[Arr, Arr]:
    """The axis A(v) and its in-plane unit normal n(v) (eq. 2), each (len(v), 3)."""
    pa = np.stack([np.zeros(3), x[0:3], x[3:6], APEX])
    d = bernstein(2, v) @ (3.0 * np.diff(pa, axis=0))
    n = np.stack([-d[:, 1], d[:, 0], np.zeros(len(v))], axis=-1)
    return bernstein(3, v) @ pa, n / np.linalg.norm(n, axis=-1, keepdims=True)


_GRID: dict[tuple[int, int], tuple[Arr, Arr]] = {}


def grid_weights(nu: int, nv: int) -> tuple[Arr, Arr]:
    """The (u, v) of :func:`leafview.core.blade.grid_uv` (float64) and their W, cached."""
    if (nu, nv) not in _GRID:
        uv = grid_uv(nu, nv).astype(np.float64)
        _GRID[nu, nv] = uv, weights(uv[:, 0], uv[:, 1])
    return _GRID[nu, nv]


def blade(c: Arr, u: Arr, v: Arr) -> tuple[Arr, Arr, Arr]:
    """(L, ∂L/∂u, ∂L/∂v), each (N, 3), of the blade with control points ``c`` (21, 3): the same
    as ``weights_all(u, v)`` times ``c``, without the (N, 21) matrices (eqs 5-6 directly)."""
    s = np.abs(u)
    sigma = np.where(u >= 0.0, 1.0, -1.0)[:, None]
    pa = np.stack([np.zeros(3), c[1], c[2], c[0]])
    a, da = mm(_bern(3, v), pa), mm(_dbern(3, v), pa)
    b4, db4 = _bern(4, v), _dbern(4, v)
    plus = (u >= 0.0)[:, None]
    curves = []
    for rows in ((3, 4, 5), (6, 7, 8), (9, 10, 11)):               # F, G, S: the u >= 0 and u < 0 rows
        both = []
        for off in (0, 9):
            ctrl = np.vstack([np.zeros(3), c[[r + off for r in rows]], c[0]])
            both.append((mm(b4, ctrl), mm(db4, ctrl)))
        curves.append((np.where(plus, both[0][0], both[1][0]), np.where(plus, both[0][1], both[1][1])))
    b, db = _bern(3, s), _dbern(3, s)
    pos = [a] + [p for p, _ in curves]
    der = [da] + [d for _, d in curves]
    big_l = sum(b[:, k:k + 1] * pos[k] for k in range(4))
    big_lu = sigma * sum(db[:, k:k + 1] * pos[k] for k in range(4))
    big_lv = sum(b[:, k:k + 1] * der[k] for k in range(4))
    return np.asarray(big_l), np.asarray(big_lu), np.asarray(big_lv)


def project(x: Arr, q: Arr, start: Arr | None = None, steps: int = PROJECT_STEPS,
            cross: bool = True) -> tuple[Arr, Arr, Arr]:
    """Each point's closest point on the blade of Ω': its (u, v) (N, 2), the distance (N,), and u
    continued past the margin (N,) (a last Newton step along u, unclamped: how far beyond the
    margin a point lies, in u).

    Starts from ``start`` (N, 2) or from the nearest vertex of a coarse grid, then takes ``steps``
    Levenberg-Marquardt steps clamped to the domain, each kept only where it brings the point
    closer (and the damping raised where it does not). With ``cross``, points that end within
    :data:`_MIDRIB` of the midrib (u = 0, a crease when z̄f or z̄g is not zero) are also started on
    its other side, and points that end within :data:`_MIDRIB` of the pinched base or apex (where
    u is nearly undetermined) from both margins; each keeps the nearest result."""
    c = controls(x)
    if start is None:
        grid, w_grid = grid_weights(*PROJECT_GRID)
        _, idx = cKDTree(w_grid @ c).query(q)
        u, v = grid[idx, 0].copy(), grid[idx, 1].copy()
    else:
        u, v = start[:, 0].copy(), start[:, 1].copy()
    pos, lu, lv = blade(c, u, v)
    r = pos - q
    dist = np.linalg.norm(r, axis=1)
    damp = np.full(len(q), 1e-6)
    for _ in range(steps):
        a, b, cc = np.sum(lu * lu, 1), np.sum(lu * lv, 1), np.sum(lv * lv, 1)
        gu, gv = np.sum(lu * r, 1), np.sum(lv * r, 1)
        mu = 1e-12 + damp * (a + cc)
        det = (a + mu) * (cc + mu) - b * b
        du, dv = -((cc + mu) * gu - b * gv) / det, -((a + mu) * gv - b * gu) / det
        # at a bound with the step pointing out of the domain: step along the boundary only
        out_u = (np.abs(u) >= 1.0) & (du * u > 0.0)
        out_v = ((v <= 0.0) & (dv < 0.0)) | ((v >= 1.0) & (dv > 0.0))
        dv = np.where(out_u & ~out_v, -gv / (cc + mu), np.where(out_v, 0.0, dv))
        du = np.where(out_v & ~out_u, -gu / (a + mu), np.where(out_u, 0.0, du))
        un, vn = np.clip(u + du, -1.0, 1.0), np.clip(v + dv, 0.0, 1.0)
        pos, lun, lvn = blade(c, un, vn)
        rn = pos - q
        dn = np.linalg.norm(rn, axis=1)
        ok = dn < dist
        col = ok[:, None]
        u, v, dist = np.where(ok, un, u), np.where(ok, vn, v), np.where(ok, dn, dist)
        r, lu, lv = np.where(col, rn, r), np.where(col, lun, lu), np.where(col, lvn, lv)
        damp = np.where(ok, np.maximum(damp / 10.0, 1e-9), damp * 100.0)      # Levenberg-Marquardt per point
    slide = np.sum(lu * r, 1) / np.maximum(np.sum(lu * lu, 1), 1e-300)
    uv, free = np.stack([u, v], axis=1), u - slide
    if not cross:
        return uv, dist, free
    # the midrib may be a crease (try its other side), and at the pinched base and apex u is
    # undetermined (try both margins next to them)
    near = np.flatnonzero(np.abs(u) < _MIDRIB)
    tips = np.flatnonzero((v <= _MIDRIB) | (v >= 1.0 - _MIDRIB))
    inward = np.clip(v[tips], _MIDRIB, 1.0 - _MIDRIB)
    for idx, other in ((near, np.stack([np.where(u[near] >= 0.0, -_MIDRIB, _MIDRIB), v[near]], axis=1)),
                       (tips, np.stack([np.ones(len(tips)), inward], axis=1)),
                       (tips, np.stack([-np.ones(len(tips)), inward], axis=1))):
        if not len(idx):
            continue
        uv2, dist2, free2 = project(x, q[idx], other, steps, cross=False)
        better = dist2 < dist[idx]
        pick = idx[better]
        uv[pick], dist[pick], free[pick] = uv2[better], dist2[better], free2[better]
    return uv, dist, free


def reversed_omega(omega: Arr) -> Arr:
    """Ω of the same surface with base and apex swapped: placed by ``M @ REVERSE`` instead of
    ``M``, the leaf turned by 180° about z through (0, 1/2, 0), with ``L'(u, v) = R L(-u, 1 - v)``
    (the rows in reverse order at ``1 - v̄``, ``a1' = R a2``, ``a2' = R a1``)."""
    flip = lambda p: np.array([-p[0], 1.0 - p[1], p[2]])  # noqa: E731
    rows = omega[6:15].reshape(3, 3)[::-1].copy()
    rows[:, 0] = 1.0 - rows[:, 0]
    return np.concatenate([flip(omega[3:6]), flip(omega[0:3]), rows.ravel(), omega[17:14:-1], omega[20:17:-1]])
