"""Fit Ω to a batch of leaf margins in a few array passes: the fast path of
:mod:`leafview.botany.batch_fit`, for random instances by the hundred (Garg & Leow 2011, Fig. 8).

The model is the same as :func:`~leafview.botany.batch_fit.fit_outlines` fits: the right-side
silhouette of Chaurasia & Beardsley 2017, eq. 1, a Bézier of degree N + 1 from the base (0, 0) to
the apex (0, 1) on a straight axis, its N inner control points turned into tilted rows (eq. 3).
What makes it fast:

1. **Fixed start.** Each (mean) side is resampled at ``_SAMPLES`` points evenly spaced in arc
   length and given the parameters ``t_j = j / (S - 1)``, the same for every leaf, so the
   least-squares inner control points are one precomputed matrix (the pseudo-inverse of the
   Bernstein matrix, factored once per N) times the samples: one matrix product for the batch.
2. **Few Gauss-Newton rounds** (``_ROUNDS``), each with a per-leaf Levenberg-Marquardt safeguard:
   the tangent-distance model of ``batch_fit`` (the normal residual at each sample's foot point
   counts fully, the tangential one with a small weight), without the fold penalty. Curves are
   evaluated in the power basis (``[1, t, …, t^n] · Z · c``, Chaurasia & Beardsley 2017, eq. 1)
   by Horner's rule on one (B, S) plane per coordinate, so a foot-point Newton step costs a few
   dozen array operations for the whole batch.
3. **Rows by batch**, as ``fit_outlines``: the leaves that miss the target with N rows go on with
   N + 1, started from the degree elevation of their N-row fit (the same curve). Only leaves whose
   samples all lie within the target are measured (step 4). Where a measured fit meets the target
   but its blade folds (eq. 6's in-plane Jacobian, :func:`~leafview.botany.batch_fit.jacobian_grids`),
   it is refitted from the same start with ``batch_fit``'s fold penalty (``_FOLD_ROUNDS`` rounds);
   with ``max_rows``, every leaf still missing gets ``_FINAL_ROUNDS`` such rounds. Each leaf keeps
   its best fit (no fold first, then the smaller error).
4. **A bound instead of the Hausdorff measure.** Each target side point's distance to its foot on
   the fitted margin, and the distance of margin points (midway between consecutive feet, and at
   ``_BOUND_SAMPLES`` even parameters) to the target segment between the feet that enclose them,
   are distances to *some* point of the other curve, hence never below the true ones; their
   largest value is the symmetric Hausdorff distance ÷ leaf length from above, up to the sampling
   of the margin. :func:`~leafview.botany.batch_fit.outline_errors` measures vertex to vertex on
   polylines densified to 1e-3, so it may read up to half that step above this bound.

Nothing here falls back to the slow fits: leaves that miss the target at ``max_rows`` keep their
best fit and are counted (:attr:`~leafview.botany.batch_fit.BatchFit.n_missed`);
:func:`leafview.botany.shapes.fit_instances` refits those with ``fit_outlines``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from functools import lru_cache
from math import comb

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.botany.batch_fit import (
    DEFAULT_BATCH_TARGET,
    BatchFit,
    _as_batch,
    _fold_cost,
    _jacobian_parts,
    _resample,
    _with_ends,
    elevate,
    fit_inputs,
    jacobian_grids,
)
from leafview.botany.outline_fit import _FOLD_MARGIN, _FOLD_WEIGHT, _JAC_S, params_from_controls
from leafview.core.bezier import bernstein_matrix
from leafview.core.params import MAX_SILHOUETTE_ROWS, LeafParams, ParamError

__all__ = ["quick_fit_outlines", "quick_fit_sides", "error_bound"]

_SAMPLES = 32            # samples of the (mean) side in the fit
_ROUNDS = 5              # Gauss-Newton rounds per row count
_NEWTON = 1              # foot-point Newton steps per Gauss-Newton round
_START_NEWTON = 3        # foot-point Newton steps before the first round and in the error bound
_FOLD_ROUNDS = 6         # rounds with the fold penalty for leaves whose blade folds
_FINAL_ROUNDS = 16       # rounds from the start for leaves that miss the target with max_rows
_BOUND_SAMPLES = 33      # even margin parameters in the error bound (besides the midpoints)
_TANGENT_WEIGHT = 1e-3   # weight of the tangential residual (as batch_fit)
_STEP_LIMIT = 0.05       # largest parameter change of one Newton step


# -- curves in power form, one (B, K) plane per coordinate -------------------------------------------
@lru_cache(maxsize=16)
def _z(n: int) -> NDArray[np.float64]:
    return bernstein_matrix(n)


@lru_cache(maxsize=16)
def _binomials(n: int) -> NDArray[np.float64]:
    return np.array([comb(n, i) for i in range(n + 1)], dtype=np.float64)[:, None, None]


def _horner(a: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B, K): Σ_k a[:, k] t^k for coefficients (B, d + 1) and parameters (B, K)."""
    v = a[:, -1:] * t
    for k in range(a.shape[1] - 2, 0, -1):
        v += a[:, k:k + 1]
        v *= t
    v += a[:, :1]
    return v


def _bernstein_planes(t: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """(n + 1, B, K): the Bernstein basis B_{i,n}(t), one plane per i."""
    pt = np.empty((n + 1,) + t.shape)
    qt = np.empty_like(pt)
    pt[0] = 1.0
    qt[0] = 1.0
    s = 1.0 - t
    for k in range(1, n + 1):
        np.multiply(pt[k - 1], t, out=pt[k])
        np.multiply(qt[k - 1], s, out=qt[k])
    pt *= qt[::-1]
    pt *= _binomials(n)
    return pt


class _Curves:
    """A batch of Bézier curves (B, n + 1, 2) in power form (``[1, t, …, t^n] · Z · c``), with the
    coefficients of their first two derivatives, x and y apart."""

    def __init__(self, ctrl: NDArray[np.float64]) -> None:
        n = ctrl.shape[1] - 1
        self.n = n
        a = np.einsum("ki,bid->dbk", _z(n), ctrl)                     # (2, B, n + 1)
        k = np.arange(n + 1, dtype=np.float64)
        self.a = a
        self.a1 = a[:, :, 1:] * k[1:]
        self.a2 = a[:, :, 2:] * (k[2:] * (k[2:] - 1.0))

    def at(self, t: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return _horner(self.a[0], t), _horner(self.a[1], t)

    def tangent(self, t: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return _horner(self.a1[0], t), _horner(self.a1[1], t)

    def feet(self, px: NDArray[np.float64], py: NDArray[np.float64], t: NDArray[np.float64], steps: int
             ) -> NDArray[np.float64]:
        """Newton steps moving each parameter towards the foot of its point on the curve; the first
        and last stay at 0 and 1 and the order is kept (as ``outline_fit._project``)."""
        for _ in range(steps):
            rx, ry = self.at(t)
            rx -= px
            ry -= py
            sx, sy = self.tangent(t)
            num = rx * sx + ry * sy
            den = sx * sx + sy * sy + rx * _horner(self.a2[0], t) + ry * _horner(self.a2[1], t)
            step = num / np.where(np.abs(den) > 1e-12, den, 1e-12)
            t = np.clip(t - np.clip(step, -_STEP_LIMIT, _STEP_LIMIT), 0.0, 1.0)
            t[:, 0], t[:, -1] = 0.0, 1.0
            t = np.maximum.accumulate(t, axis=1)
        return t

    def sq_distances(self, px: NDArray[np.float64], py: NDArray[np.float64], t: NDArray[np.float64]
                     ) -> NDArray[np.float64]:
        """(B, K) squared distances of the points to the curves at ``t``."""
        x, y = self.at(t)
        x -= px
        y -= py
        return np.asarray(x * x + y * y)


@lru_cache(maxsize=16)
def _start_operator(n: int, k: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The least-squares operator of module step 1 for degree n and k uniform parameters:
    ``inner = P @ (samples - B_n(t) ⊗ apex)``, P the pseudo-inverse of the inner Bernstein columns."""
    basis = _bernstein_planes(np.linspace(0.0, 1.0, k)[None], n)[:, 0].T
    return np.asarray(np.linalg.pinv(basis[:, 1:n]), np.float64), basis[:, n].copy()


def _fold_system(inner: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The fold penalty of ``batch_fit._fold_terms`` linearised at ``inner`` (B, n - 1, 2), summed
    into normal equations: ``(G^T G (B, m, m), G^T (G x0 - d) (B, m))`` over the grid points where
    the normalised Jacobian determinant d lies below the margin, unknowns in blocked order (all x,
    then all y). The gradient G is built at those points only (few, on a blade that nearly
    folds), which is what makes the penalised rounds affordable."""
    b, n1 = inner.shape[:2]
    m = 2 * n1
    q = _jacobian_parts(_with_ends(inner))
    scale = q["scale"]
    norm = q["det"] / scale[:, None, None]
    leaf, si, vi = np.nonzero(norm < _FOLD_MARGIN)
    lhs, rhs = np.zeros((b, m, m)), np.zeros((b, m))
    if leaf.size == 0:
        return lhs, rhs
    n = n1 + 1
    bv = q["bn"][vi, 1:n]                                                # (A, n - 1) inner basis at the points
    dv = n * (q["bd"][vi, :n - 1] - q["bd"][vi, 1:n])                    # hodograph of a unit bump
    pb = np.einsum("ai,aij->aj", bv, q["dfeet"][leaf])                   # d P_y / d y_j
    pd = np.einsum("ai,aij->aj", dv, q["dfeet"][leaf])
    s = _JAC_S[si][:, None]
    b0, db0 = (1.0 - s) ** 3, -3.0 * (1.0 - s) ** 2
    ls, lv = q["Ls"][leaf, si, vi], q["Lv"][leaf, si, vi]               # (A, 2)
    d_x = bv * lv[:, 1:] - ls[:, 1:] * s * dv
    d_y = ls[:, :1] * ((1.0 - b0) * pd + s * (dv - pd)) - (bv - pb * (1.0 + db0)) * lv[:, :1]
    g = np.concatenate([d_x, d_y], axis=1) / scale[leaf][:, None]
    x = inner[..., 0]
    top = np.argmax(np.abs(x), axis=1)                                   # d scale / d x at the widest row
    widest = np.take_along_axis(x, top[:, None], axis=1)[:, 0]
    sign = np.sign(widest) * (np.abs(widest) > 1e-3)
    point = norm[leaf, si, vi]
    g[np.arange(leaf.size), top[leaf]] -= point / scale[leaf] * sign[leaf]
    x0 = _blocked(inner)[leaf]
    first = np.flatnonzero(np.r_[True, leaf[1:] != leaf[:-1]])         # leaf is sorted: one segment each
    owners = leaf[first]
    lhs[owners] = np.add.reduceat(g[:, :, None] * g[:, None, :], first, axis=0)
    rhs[owners] = np.add.reduceat(g * (np.sum(g * x0, axis=1) - (point - _FOLD_MARGIN))[:, None], first, axis=0)
    return lhs, rhs


def _blocked(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B, n - 1, 2) points -> (B, 2 (n - 1)): all x, then all y."""
    return np.concatenate([x[:, :, 0], x[:, :, 1]], axis=1)


def _gauss_newton(px: NDArray[np.float64], py: NDArray[np.float64], inner: NDArray[np.float64],
                  t: NDArray[np.float64], rounds: int, fold: bool = False
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Module step 2 on inner control points (B, n - 1, 2) and sample parameters (B, K); with
    ``fold``, the fold penalty of ``batch_fit`` (eq. 6's in-plane Jacobian kept above a margin)
    enters the normal equations and the cost, as in ``fit_outline``'s polish. Returns the inner
    points, the parameters and each leaf's largest sample distance (B,)."""
    b = len(px)
    n = inner.shape[1] + 1
    m = 2 * (n - 1)
    curves = _Curves(_with_ends(inner))
    t = curves.feet(px, py, t, _START_NEWTON)
    d2 = curves.sq_distances(px, py, t)
    cost = d2.sum(axis=1) + (_fold_cost(inner) if fold else 0.0)
    worst = d2.max(axis=1)
    mu = np.full(b, 1e-6)
    eye = np.eye(m)
    for _ in range(rounds):
        basis = _bernstein_planes(t, n)
        tx, ty = curves.tangent(t)
        norm = np.maximum(np.sqrt(tx * tx + ty * ty), 1e-12)
        tx /= norm
        ty /= norm
        qy = py - basis[n]                                               # what the inner points must reach
        inner_basis = basis[1:n]
        # unknowns ordered (x_1 .. x_{n-1}, y_1 .. y_{n-1}); normal = (-ty, tx)
        an = np.concatenate([inner_basis * -ty, inner_basis * tx]).transpose(1, 0, 2)     # (B, m, K)
        at = np.concatenate([inner_basis * tx, inner_basis * ty]).transpose(1, 0, 2)
        rn = (tx * qy - ty * px)[..., None]
        rt = (tx * px + ty * qy)[..., None]
        lhs = an @ an.transpose(0, 2, 1) + _TANGENT_WEIGHT * (at @ at.transpose(0, 2, 1))
        rhs = an @ rn + _TANGENT_WEIGHT * (at @ rt)
        x0 = _blocked(inner)[..., None]
        if fold:
            fold_lhs, fold_rhs = _fold_system(inner)
            lhs = lhs + _FOLD_WEIGHT ** 2 * fold_lhs
            rhs = rhs + _FOLD_WEIGHT ** 2 * fold_rhs[..., None]
        damp = (mu * np.trace(lhs, axis1=1, axis2=2) / m)[:, None, None]
        x = np.linalg.solve(lhs + damp * eye, rhs + damp * x0)[..., 0]
        trial = np.stack([x[:, :n - 1], x[:, n - 1:]], axis=-1)
        trial_curves = _Curves(_with_ends(trial))
        trial_t = trial_curves.feet(px, py, t, _NEWTON)
        d2 = trial_curves.sq_distances(px, py, trial_t)
        trial_cost = d2.sum(axis=1) + (_fold_cost(trial) if fold else 0.0)
        ok = trial_cost <= cost
        inner = np.where(ok[:, None, None], trial, inner)
        t = np.where(ok[:, None], trial_t, t)
        cost = np.where(ok, trial_cost, cost)
        worst = np.where(ok, d2.max(axis=1), worst)
        keep = ok[None, :, None]
        curves.a = np.where(keep, trial_curves.a, curves.a)
        curves.a1 = np.where(keep, trial_curves.a1, curves.a1)
        curves.a2 = np.where(keep, trial_curves.a2, curves.a2)
        mu = np.where(ok, np.maximum(mu * 0.3, 1e-9), mu * 10.0)
    return inner, t, np.sqrt(worst)


def _start(points: NDArray[np.float64], rows: int, start: NDArray[np.float64] | None
           ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Samples (x and y planes, (B, S) each), start inner points and parameters of module step 1."""
    pts = _resample(points, _SAMPLES)
    n = rows + 1
    if start is None:
        op, last = _start_operator(n, _SAMPLES)
        inner = np.einsum("ik,bkd->bid", op, pts - last[:, None] * np.array([0.0, 1.0]))
    else:
        if start.shape != (len(pts), n, 2):
            raise ParamError("start", f"expected shape {(len(pts), n, 2)}, got {start.shape}")
        inner = elevate(start)[:, 1:-1]
    t = np.broadcast_to(np.linspace(0.0, 1.0, _SAMPLES), (len(pts), _SAMPLES)).copy()
    return np.ascontiguousarray(pts[..., 0]), np.ascontiguousarray(pts[..., 1]), inner, t


def quick_fit_sides(points: ArrayLike, rows: int, *, start: NDArray[np.float64] | None = None,
                    rounds: int = _ROUNDS, fold_rounds: int = _FOLD_ROUNDS
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Control points (B, rows + 2, 2) of degree rows + 1 Béziers from (0, 0) to (0, 1) fitted to
    a batch of sides (B, K, 2) from base to apex (module steps 1-2), and the parameters (B, S) of
    the fit's S evenly spaced samples. ``start`` (B, rows + 1, 2): fits with one row fewer, whose
    degree elevation replaces the fixed start. Leaves whose blade folds get ``fold_rounds`` more
    rounds with the fold penalty. Each leaf is fitted on its own."""
    if not 3 <= rows <= MAX_SILHOUETTE_ROWS:
        raise ParamError("rows", f"must be in 3..{MAX_SILHOUETTE_ROWS}, got {rows}")
    px, py, inner, t = _start(_as_batch(points, "points", 3), rows, start)
    inner, t, _ = _gauss_newton(px, py, inner, t, rounds)
    folded = np.flatnonzero(jacobian_grids(_with_ends(inner)).min(axis=(1, 2)) <= 0.0)
    if folded.size and fold_rounds > 0:
        inner[folded], t[folded], _ = _gauss_newton(px[folded], py[folded], inner[folded], t[folded], fold_rounds,
                                                    fold=True)
    return _with_ends(inner), t


# -- the error bound -------------------------------------------------------------------------------
def _arc_fraction(side: NDArray[np.float64]) -> NDArray[np.float64]:
    d = np.concatenate([np.zeros((len(side), 1)), np.cumsum(np.linalg.norm(np.diff(side, axis=1), axis=2), axis=1)],
                       axis=1)
    return d / np.where(d[:, -1:] > 0.0, d[:, -1:], 1.0)


def _to_segments(cx: NDArray[np.float64], cy: NDArray[np.float64], px: NDArray[np.float64],
                 py: NDArray[np.float64], seg: NDArray[np.int64]) -> NDArray[np.float64]:
    """(B, M): distance of the points (cx, cy) to segment ``seg`` (B, M) of the polylines
    (px, py) (B, P): never below the distance to the whole polyline."""
    b, p = px.shape
    flat_x, flat_y = px.ravel(), py.ravel()
    i = np.clip(seg, 0, p - 2) + (p * np.arange(b))[:, None]
    ax, ay = flat_x[i], flat_y[i]
    sx, sy = flat_x[i + 1] - ax, flat_y[i + 1] - ay
    dx, dy = cx - ax, cy - ay
    h = np.clip((dx * sx + dy * sy) / np.maximum(sx * sx + sy * sy, 1e-30), 0.0, 1.0)
    return np.asarray(np.sqrt((dx - h * sx) ** 2 + (dy - h * sy) ** 2))


def _side_bound(curves: _Curves, side: NDArray[np.float64], t_fit: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B,) module step 4 for one target side (B, P, 2), starting its feet from the fit's sample
    parameters ``t_fit`` (B, S) at the same arc-length fractions.

    Side → margin: each side point's distance to its foot. Margin → side: the margin at the
    parameters midway between consecutive feet and at ``_BOUND_SAMPLES`` even parameters, each
    measured to the side segment between the two feet that enclose its parameter (feet are kept in
    order, so every margin parameter lies between two). All are distances to some point of the
    other curve, so none is below the true one."""
    b, s = t_fit.shape
    x = _arc_fraction(side) * (s - 1)
    j = np.minimum(x.astype(np.int64), s - 2)
    w = x - j
    flat = (j + (s * np.arange(b))[:, None]).ravel()
    t = (t_fit.ravel()[flat] * (1.0 - w.ravel()) + t_fit.ravel()[flat + 1] * w.ravel()).reshape(w.shape)
    px, py = np.ascontiguousarray(side[..., 0]), np.ascontiguousarray(side[..., 1])
    t = curves.feet(px, py, t, _START_NEWTON)
    cx, cy = curves.at(t)
    on = np.sqrt(np.max((cx - px) ** 2 + (cy - py) ** 2, axis=1))
    p = px.shape[1]
    tau = np.concatenate([0.5 * (t[:, 1:] + t[:, :-1]),
                          np.broadcast_to(np.linspace(0.0, 1.0, _BOUND_SAMPLES), (b, _BOUND_SAMPLES))], axis=1)
    lane = 2.0 * np.arange(b)[:, None]                      # one global search: row k lives in [2k, 2k + 1]
    seg = np.searchsorted((t + lane).ravel(), (tau + lane).ravel(), side="right").reshape(tau.shape)
    seg = seg - p * np.arange(b)[:, None] - 1
    seg[:, :p - 1] = np.arange(p - 1)                       # the midpoints: their own segment
    mx, my = curves.at(tau)
    off = _to_segments(mx, my, px, py, seg).max(axis=1)
    return np.asarray(np.maximum(on, off))


def error_bound(ctrl: NDArray[np.float64], right: ArrayLike, left: ArrayLike | None = None,
                t_fit: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """(B, 3): the estimate from above of module step 4 (whole, right, left ÷ leaf length) for
    the margins with control points ``ctrl`` (B, n + 1, 2) against the target sides (B, P, 2),
    base to apex; ``left`` defaults to the mirrored right side. ``t_fit``: the parameters of
    evenly spaced samples along the side (default: their arc-length fractions)."""
    r = _as_batch(right, "right", 3)
    lt = r * [-1.0, 1.0] if left is None else _as_batch(left, "left", 3)
    c = np.asarray(ctrl, np.float64)
    if lt.shape != r.shape or c.ndim != 3 or len(c) != len(r):
        raise ParamError("ctrl", f"expected {len(r)} control polygons and left sides like {r.shape}")
    if t_fit is None:
        t_fit = np.broadcast_to(np.linspace(0.0, 1.0, _SAMPLES), (len(r), _SAMPLES))
    return _bound(c, r, lt, t_fit)


def _bound(ctrl: NDArray[np.float64], r: NDArray[np.float64], lt: NDArray[np.float64], t_fit: NDArray[np.float64]
           ) -> NDArray[np.float64]:
    if len(ctrl) == 0:
        return np.zeros((0, 3))
    er = _side_bound(_Curves(ctrl), r, t_fit)
    mirrored = lt * [-1.0, 1.0]
    asym = ~np.all(np.abs(mirrored - r) <= 1e-12, axis=(1, 2))
    el = er.copy()
    if asym.any():
        el[asym] = _side_bound(_Curves(ctrl[asym]), mirrored[asym], t_fit[asym])
    return np.c_[np.maximum(er, el), er, el]


def _better(err: NDArray[np.float64], jmin: NDArray[np.float64], err0: NDArray[np.float64],
            jmin0: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Where a fit (error, smallest Jacobian) beats another: no fold first, then the smaller error."""
    return np.asarray(((jmin > 0.0) > (jmin0 > 0.0)) | (((jmin > 0.0) == (jmin0 > 0.0)) & (err < err0)))


def _jmin(ctrl: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B,) smallest fold-grid Jacobian determinant of each margin (eq. 6)."""
    return jacobian_grids(ctrl).min(axis=(1, 2)) if len(ctrl) else np.zeros(0)


# -- the batch ---------------------------------------------------------------------------------------
def _stage(px: NDArray[np.float64], py: NDArray[np.float64], start: NDArray[np.float64], t_start: NDArray[np.float64],
           sides: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]], target: float, rounds: int,
           final: bool) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """One row count for a batch (module steps 2-4): control points, error bounds (B, 3) and
    smallest Jacobians (B,); leaves left unmeasured (their samples already miss the target) get
    an infinite error. ``sides``: right sides, left sides and which leaves are symmetric."""
    r, lt, sym = sides
    inner, t, worst = _gauss_newton(px, py, start, t_start, rounds)
    # measured: the leaves whose samples all lie within the target (their margin may pass),
    # the asymmetric ones (fitted to the mean side) and, with the last row count, all
    judged = np.flatnonzero((worst <= target) | ~sym | final)
    ctrl = _with_ends(inner)
    err = np.full((len(px), 3), np.inf)
    jmin = np.full(len(px), -np.inf)
    err[judged] = _bound(ctrl[judged], r[judged], lt[judged], t[judged])
    jmin[judged] = _jmin(ctrl[judged])
    # refit from the start with the fold penalty where the blade folds though the margin is close
    # enough (with the last row count: wherever the fit misses), measure again, keep the better fit
    meets = err[:, 0] <= target
    redo = np.flatnonzero(np.isfinite(err[:, 0]) & (~(meets & (jmin > 0.0)) if final else (meets & (jmin <= 0.0))))
    if redo.size:
        inner_k, t_k, _ = _gauss_newton(px[redo], py[redo], start[redo], t_start[redo],
                                        _FINAL_ROUNDS if final else _FOLD_ROUNDS, fold=True)
        ctrl_k = _with_ends(inner_k)
        err_k, jmin_k = _bound(ctrl_k, r[redo], lt[redo], t_k), _jmin(ctrl_k)
        won = _better(err_k[:, 0], jmin_k, err[redo, 0], jmin[redo])
        ctrl[redo[won]], err[redo[won]], jmin[redo[won]] = ctrl_k[won], err_k[won], jmin_k[won]
    return ctrl, err, jmin


def quick_fit_outlines(outlines: ArrayLike | None = None, *, right: ArrayLike | None = None,
                       left: ArrayLike | None = None, target: float = DEFAULT_BATCH_TARGET, min_rows: int = 3,
                       max_rows: int = MAX_SILHOUETTE_ROWS, names: Sequence[str] | None = None,
                       rounds: int = _ROUNDS) -> BatchFit:
    """Fit Ω to a batch of closed outlines (or right and left sides) by the fast path of the module
    docstring; the arguments are those of :func:`~leafview.botany.batch_fit.fit_outlines`.

    Returns
    -------
    BatchFit
        ``errors`` and ``error_sides`` hold the estimates from above of module step 4 (not the
        measure of :func:`~leafview.botany.batch_fit.outline_errors`, which costs more than the fit;
        call it to check); ``fallback`` is all False.
    """
    t0 = time.perf_counter()
    r, lt, names = fit_inputs(outlines, right, left, target, min_rows, max_rows, names, same_shape=True)
    b = len(r)

    mirrored = lt * [-1.0, 1.0]
    sym = np.all(np.abs(mirrored - r) <= 1e-12, axis=(1, 2))
    mean = r.copy()
    if not sym.all():
        mean[~sym] = 0.5 * (_resample(r[~sym], r.shape[1]) + _resample(mirrored[~sym], r.shape[1]))
    best: list[NDArray[np.float64] | None] = [None] * b
    errors = np.full((b, 3), np.inf)
    jac = np.full(b, -np.inf)
    rows = np.zeros(b, dtype=np.int64)
    attempts: dict[int, int] = {}

    def offer(leaves: NDArray[np.int64], ctrl: NDArray[np.float64], err: NDArray[np.float64],
              jmin: NDArray[np.float64], n_rows: int) -> NDArray[np.bool_]:
        """Keep each leaf's better fit; True where this one meets the target."""
        better = _better(err[:, 0], jmin, errors[leaves, 0], jac[leaves])
        for k in np.flatnonzero(better):
            best[leaves[k]] = ctrl[k]
        errors[leaves[better]], jac[leaves[better]], rows[leaves[better]] = err[better], jmin[better], n_rows
        return np.asarray((err[:, 0] <= target) & (jmin > 0.0))

    todo = np.arange(b)
    last_fit: NDArray[np.float64] | None = None
    for n_rows in range(min_rows, max_rows + 1):
        if todo.size == 0:
            break
        attempts[n_rows] = int(todo.size)
        px, py, start, t_start = _start(mean[todo], n_rows, last_fit)
        ctrl, err, jmin = _stage(px, py, start, t_start, (r[todo], lt[todo], sym[todo]), target, rounds,
                                 n_rows == max_rows)
        judged = np.isfinite(err[:, 0])
        done = np.zeros(todo.size, dtype=bool)
        done[judged] = offer(todo[judged], ctrl[judged], err[judged], jmin[judged], n_rows)
        todo, last_fit = todo[~done], ctrl[~done]
    fitted: dict[int, LeafParams] = {}
    for n_rows in np.unique(rows):
        same = [int(i) for i in np.flatnonzero(rows == n_rows)]
        ctrl = np.stack([c for c in (best[i] for i in same) if c is not None])
        fitted.update(zip(same, params_from_controls(ctrl, [names[i] for i in same])))
    return BatchFit([fitted[i] for i in range(b)], errors[:, 0].copy(), errors[:, 1:].copy(), rows, jac,
                    np.zeros(b, dtype=bool), attempts, time.perf_counter() - t0, 0.0, float(target))
