"""Fit the shader model Ω to many leaf margins at once, vectorised over the batch.

:func:`leafview.botany.outline_fit.fit_outline` fits one outline in about 0.2 s (least-squares
polish) or 0.025 s (linear least squares with parameter correction, up to 3.5 % off). Random
instances of the catalogue (Garg & Leow 2011, Fig. 8) come by the hundred, so this module fits the same
model, the right-side silhouette S of Chaurasia & Beardsley 2017, eq. 1 (a Bézier of degree N + 1 from the base
(0, 0) to the apex (0, 1), straight axis, eq. 3 with tilt for the rows), to a whole batch with
stacked arrays:

1. **Samples.** Each side is resampled evenly in arc length (batched interpolation); the symmetric
   model follows the mean of the right side and the mirrored left side, as in ``fit_outline``.
2. **Linear start.** Chord-length parameters, then a few rounds of batched linear least squares
   (normal equations of the stacked Bernstein matrices, one ``np.linalg.solve`` for all leaves)
   alternating with batched Newton projection of the samples onto the curve (Hoschek's parameter
   correction).
3. **Tangent-distance Gauss-Newton.** The squared distance of a sample to the curve is linearised
   at its foot point: the residual along the curve normal counts fully, the one along the tangent
   with a small weight (the squared-distance minimisation of Wang, Pottmann & Liu 2006, without
   curvature terms). This is Gauss-Newton on the control points with the parameters eliminated,
   which converges much faster than step 2 alone; a per-leaf Levenberg-Marquardt damping accepts
   a step only where it lowers that leaf's sum of squared distances.
   The fold penalty of ``fit_outline``'s polish (eq. 6's in-plane Jacobian determinant kept above
   a margin on a grid) enters the same normal equations with its analytic gradient.
4. **Rows by batch.** All leaves are fitted with N = ``min_rows`` silhouette rows; those whose
   outline error exceeds ``target`` or whose blade folds are refitted with N + 1 rows (started
   both afresh and from the degree-elevated N-row fit, the better kept), and so on up to
   ``max_rows``. The leaves still missing then get a few rounds of Lawson's reweighting towards the
   smallest largest distance (:func:`minimax_sides`), and whatever still misses falls back to
   ``fit_outline`` (counted in :attr:`BatchFit.fallback`).
5. **Error.** The same measure as :func:`~leafview.botany.outline_fit.outline_error`: the symmetric
   Hausdorff distance between the margin (1025 samples of S, both polylines densified to 1e-3)
   and each target side, ÷ the leaf length (1). It is batched by placing every leaf's points far
   apart in one k-d tree, so one query answers all leaves; the side → margin distances start
   from the nearest of 1025 margin samples (found the same way) and are refined by Newton steps.

Control points become silhouette rows through
:func:`~leafview.botany.outline_fit.rows_from_controls` and the fold check is
:func:`~leafview.botany.outline_fit._jacobian_grid` (eq. 6's in-plane Jacobian), so a leaf from
here has exactly the form of one from ``fit_outline``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from leafview.botany.landmarks import LandmarkLeaf, outlines
from leafview.botany.outline_fit import (
    _FOLD_MARGIN,
    _FOLD_WEIGHT,
    _FOOT_GAP,
    _JAC_S,
    _JAC_V,
    _densify,
    _feet_rows,
    fit_outline,
    params_from_controls,
)
from leafview.botany.outline_fit import _project as _project_feet  # one foot-point Newton for one curve or a batch
from leafview.core.bezier import bernstein, derivative_points
from leafview.core.defaults import INSTANCE_FIT_TARGET
from leafview.core.params import MAX_SILHOUETTE_ROWS, LeafParams, ParamError

__all__ = ["BatchFit", "fit_outlines", "fit_landmark_leaves", "fit_sides", "minimax_sides", "elevate",
           "controls_from_params", "outline_errors", "jacobian_grids", "min_jacobians", "split_outlines", "fit_inputs",
           "DEFAULT_BATCH_TARGET"]

DEFAULT_BATCH_TARGET = INSTANCE_FIT_TARGET
_SAMPLES = 80                 # samples per side in the fit (as fit_outline)
_MEAN_SAMPLES = 257           # resolution of the mean side (as fit_outline)
_LINEAR_ROUNDS = 6            # linear solve + projection rounds before Gauss-Newton
_GN_ROUNDS = 14               # tangent-distance Gauss-Newton rounds
_TANGENT_WEIGHT = 1e-3        # weight of the tangential residual in the Gauss-Newton model
_MINIMAX_ROUNDS = 6           # Lawson reweighting rounds for leaves that miss the target at max_rows
_MINIMAX_GN_ROUNDS = 4        # weighted Gauss-Newton rounds in each
_PROJECT_STEPS = 3            # Newton steps of each parameter correction
_MARGIN_SAMPLES = 1025        # samples of the fitted margin in the error (as outline_fit.margin)
_ERROR_STEP = 1e-3            # target sides densified to this for the margin -> side distance (as hausdorff)
_SPREAD = 16.0                # sides are this far apart in the shared k-d tree (leaf space: ~2 wide)
_TARGET_PARTS = 2             # target segments cut into this many pieces for the side -> margin distance
_CURVE_SEEDS = 1025           # start parameters of the projection onto the fitted margin
_CURVE_NEWTON = 4             # Newton steps of that projection


@dataclass(frozen=True)
class BatchFit:
    """The fitted leaves of a batch and how well each follows its outline.

    Attributes
    ----------
    params
        One :class:`LeafParams` per input outline (straight axis, flat blade, N rows), in order.
    errors
        (B,) Hausdorff distance between each margin and its outline ÷ leaf length (both sides).
    error_sides
        (B, 2) the same for the right and the left side.
    rows
        (B,) silhouette rows N of each leaf.
    min_jacobian
        (B,) smallest normalised in-plane Jacobian determinant on the fit grid (> 0: no fold).
    fallback
        (B,) True where the leaf was fitted by :func:`~leafview.botany.outline_fit.fit_outline`
        because no batched fit with ``min_rows..max_rows`` rows met the target without folding.
    attempts
        ``{N: leaves fitted in the batch with N rows}``.
    seconds
        Wall time, and ``fallback_seconds`` the part of it spent in the fallback fits.
    """

    params: list[LeafParams]
    errors: NDArray[np.float64]
    error_sides: NDArray[np.float64]
    rows: NDArray[np.int64]
    min_jacobian: NDArray[np.float64]
    fallback: NDArray[np.bool_]
    attempts: dict[int, int] = field(default_factory=dict)
    seconds: float = 0.0
    fallback_seconds: float = 0.0
    target: float = DEFAULT_BATCH_TARGET

    def __len__(self) -> int:
        return len(self.params)

    @property
    def n_fallback(self) -> int:
        """How many leaves were fitted one by one by ``fit_outline``."""
        return int(self.fallback.sum())

    @property
    def n_missed(self) -> int:
        """How many leaves still miss the target (or fold) after everything."""
        return int(np.sum((self.errors > self.target) | (self.min_jacobian <= 0.0)))

    def summary(self) -> dict[str, Any]:
        """JSON-able figures: count, error median / 95th percentile / max, rows histogram,
        fallbacks, misses, seconds per leaf."""
        e = self.errors
        return {"leaves": len(self), "error_median": float(np.median(e)), "error_p95": float(np.percentile(e, 95)),
                "error_max": float(e.max()), "rows": {int(n): int(np.sum(self.rows == n)) for n in np.unique(self.rows)},
                "fallback": self.n_fallback, "missed": self.n_missed, "attempts": dict(self.attempts),
                "seconds_per_leaf": self.seconds / max(len(self), 1),
                "fallback_seconds": self.fallback_seconds}


# -- input checks -------------------------------------------------------------------------------
def _as_batch(value: ArrayLike, name: str, min_points: int) -> NDArray[np.float64]:
    """``value`` as a finite (B, K, 2) float array, else a ParamError naming ``name``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ParamError(name, f"expected a (B, K, 2) array of numbers (all outlines the same length): {exc}") from None
    if arr.ndim == 2 and arr.shape[-1] == 2:
        raise ParamError(name, f"expected a batch (B, K, 2), got one polyline {arr.shape}: wrap it in a list")
    if arr.ndim != 3 or arr.shape[2] != 2 or arr.shape[0] < 1 or arr.shape[1] < min_points:
        raise ParamError(name, f"expected shape (B >= 1, K >= {min_points}, 2), got {arr.shape}")
    bad = ~np.isfinite(arr).all(axis=(1, 2))
    if bad.any():
        raise ParamError(name, f"outline {int(np.argmax(bad))} holds NaN or infinite values")
    return arr


def _check_ends(side: NDArray[np.float64], name: str) -> None:
    for which, row, want in (("start at the base", 0, (0.0, 0.0)), ("end at the apex", -1, (0.0, 1.0))):
        off = np.linalg.norm(side[:, row] - want, axis=1) > 1e-9
        if off.any():
            k = int(np.argmax(off))
            raise ParamError(name, f"side {k} must {which} {want}, got {side[k, row].tolist()}")


def _split_batch(outlines: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(right, left) sides of closed outlines written as :func:`~leafview.botany.landmarks.outline`
    does: M = 2n - 2 rows, the base at row 0 and the apex at row n - 1 = M / 2."""
    m = outlines.shape[1]
    if m % 2:
        raise ParamError("outlines", f"expected an even number of rows (2n - 2, apex at row n - 1), got {m}")
    h = m // 2
    if np.any(np.linalg.norm(outlines[:, 0], axis=1) > 1e-9):
        k = int(np.argmax(np.linalg.norm(outlines[:, 0], axis=1) > 1e-9))
        raise ParamError("outlines", f"outline {k} must start at the base (0, 0), starts at {outlines[k, 0].tolist()}")
    off = np.linalg.norm(outlines[:, h] - [0.0, 1.0], axis=1) > 1e-9
    if off.any():
        raise ParamError("outlines", f"outline {int(np.argmax(off))} must have the apex (0, 1) at row {h}")
    right = outlines[:, :h + 1]
    left = np.concatenate([outlines[:, h:], outlines[:, :1]], axis=1)[:, ::-1]
    return right, np.ascontiguousarray(left)


def split_outlines(outlines: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(right, left) sides (B, n, 2), base to apex, of closed outlines (B, 2n - 2, 2) as
    :func:`~leafview.botany.landmarks.outlines` writes them (the batched
    :func:`~leafview.botany.outline_fit.split_outline`)."""
    return _split_batch(_as_batch(outlines, "outlines", 6))


# -- batched geometry -----------------------------------------------------------------------------
def _chord(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B, K): chord-length parameters of the (B, K, 2) polylines, 0 at the first point and 1 at
    the last (0 throughout for a polyline of zero length)."""
    d = np.concatenate([np.zeros((len(points), 1)),
                        np.cumsum(np.linalg.norm(np.diff(points, axis=1), axis=2), axis=1)], axis=1)
    return d / np.where(d[:, -1:] > 0.0, d[:, -1:], 1.0)


def _resample(points: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """(B, n, 2): every polyline of the (B, K, 2) batch resampled evenly in arc length."""
    b = len(points)
    d = _chord(points)
    lane = 2.0 * np.arange(b)[:, None]          # row b lives in [2b, 2b + 1]: one global interpolation
    xp = (d + lane).ravel()
    x = (np.linspace(0.0, 1.0, n)[None, :] + lane).ravel()
    out = np.stack([np.interp(x, xp, points[..., k].ravel()) for k in (0, 1)], axis=-1)
    return out.reshape(b, n, 2)


def _with_ends(inner: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B, n + 1, 2) control points: base (0, 0), the inner points, apex (0, 1)."""
    b = len(inner)
    base = np.zeros((b, 1, 2))
    apex = np.broadcast_to(np.array([[[0.0, 1.0]]]), (b, 1, 2))
    return np.concatenate([base, inner, apex], axis=1)


def _project(ctrl: NDArray[np.float64], pts: NDArray[np.float64], t: NDArray[np.float64],
             steps: int | None = None) -> NDArray[np.float64]:
    """Newton steps moving each sample's parameter to its foot on its leaf's curve (batched)."""
    return _project_feet(ctrl, pts, t, _PROJECT_STEPS if steps is None else steps)


def _linear_solve(pts: NDArray[np.float64], t: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """(B, n - 1, 2) inner control points minimising Σ|B(t_j) - p_j|² for every leaf: the normal
    equations of the stacked Bernstein matrices, one batched solve."""
    basis = bernstein(n, t)
    a = basis[:, :, 1:n]
    rhs = pts - basis[:, :, n:] * np.array([0.0, 1.0])
    lhs = np.swapaxes(a, 1, 2) @ a
    lhs += 1e-12 * np.eye(n - 1)
    return np.linalg.solve(lhs, np.swapaxes(a, 1, 2) @ rhs)


def _sq_distance(ctrl: NDArray[np.float64], pts: NDArray[np.float64], t: NDArray[np.float64],
                 weights: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """(B,) Σ_j w_j |C(t_j) - p_j|² (w = 1 by default)."""
    r = bernstein(ctrl.shape[1] - 1, t) @ ctrl - pts
    r2 = np.sum(r * r, axis=2)
    return np.sum(r2 if weights is None else weights * r2, axis=1)


def _feet_batch(y: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(B, N) feet v̄_i of the rows: heights clamped into (0, 1) and kept increasing by
    ``_FOOT_GAP`` (:func:`leafview.botany.outline_fit._feet` for a batch, as a running maximum),
    and (B, N, N) their derivatives ∂v̄_k/∂y_j (0 or 1: which height each foot follows)."""
    b, n = y.shape
    step = _FOOT_GAP * np.arange(n)
    lo = _FOOT_GAP * np.arange(1, n + 1)
    hi = 1.0 - _FOOT_GAP * np.arange(n, 0, -1)
    g = np.clip(y, lo, hi) - step
    acc = np.maximum.accumulate(g, axis=1)
    feet = _feet_rows(y)
    idx = np.where(g >= acc, np.arange(n), 0)
    source = np.maximum.accumulate(idx, axis=1)                          # the row each foot follows
    follows = (y > lo) & (y < hi)
    live = (acc + step < hi) & np.take_along_axis(follows, source, axis=1)
    d = np.zeros((b, n, n))
    d[np.arange(b)[:, None], np.arange(n)[None, :], source] = live
    return feet, d


@lru_cache(maxsize=16)
def _fold_bases(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Bernstein bases of degrees n and n - 1 on the fold grid's v samples (fixed: computed once)."""
    return bernstein(n, _JAC_V), bernstein(n - 1, _JAC_V)


def _jacobian_parts(ctrl: NDArray[np.float64]) -> dict[str, Any]:
    """Pieces of eq. 6's in-plane map on the fold grid for a batch of control polygons."""
    n = ctrl.shape[1] - 1
    pctrl = np.zeros_like(ctrl)
    pctrl[:, 1:-1, 1], dfeet = _feet_batch(ctrl[:, 1:-1, 1])
    pctrl[:, -1, 1] = 1.0
    bn, bd = _fold_bases(n)
    S, dS = bn @ ctrl, bd @ derivative_points(ctrl)
    P, dP = bn @ pctrl, bd @ derivative_points(pctrl)
    A = np.stack([np.zeros_like(_JAC_V), _JAC_V], axis=-1)
    s = _JAC_S[None, :, None, None]
    b0, db0 = (1.0 - s) ** 3, -3.0 * (1.0 - s) ** 2
    Ls = db0 * (A - P)[:, None] + (S - P)[:, None]
    Lv = b0 * np.array([0.0, 1.0]) + (1.0 - b0) * dP[:, None] + s * (dS - dP)[:, None]
    det = Ls[..., 0] * Lv[..., 1] - Ls[..., 1] * Lv[..., 0]
    scale = np.maximum(np.abs(ctrl[..., 0]).max(axis=1), 1e-3)
    return dict(n=n, bn=bn, bd=bd, Ls=Ls, Lv=Lv, det=det, scale=scale, dfeet=dfeet)


def jacobian_grids(ctrl: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B, 8, 49): the normalised in-plane Jacobian determinant of eq. 6 for a batch of control
    polygons (B, n + 1, 2), on the grid of :func:`leafview.botany.outline_fit._jacobian_grid`
    (which it equals leaf by leaf); used for the fold penalty inside the Gauss-Newton rounds."""
    parts = _jacobian_parts(ctrl)
    return parts["det"] / parts["scale"][:, None, None]


def min_jacobians(ctrl: Sequence[NDArray[np.float64]] | NDArray[np.float64]) -> NDArray[np.float64]:
    """(B,) the smallest normalised Jacobian determinant of eq. 6 over the fold grid of each
    control polygon (each (n + 1, 2); the polygons may differ in n): > 0 where the blade does not
    fold. The one fold measure of the fits and the benchmarks."""
    out = np.empty(len(ctrl), dtype=np.float64)
    sizes = np.array([len(c) for c in ctrl], dtype=np.int64)
    for n in np.unique(sizes):
        which = np.flatnonzero(sizes == n)
        out[which] = jacobian_grids(np.stack([np.asarray(ctrl[int(i)], np.float64) for i in which])).min(axis=(1, 2))
    return out


def _fold_terms(inner: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Fold penalty of every leaf, linearised: ``(value (B, G), gradient (B, G, m))`` of
    ``det / scale - margin`` on the grid, m = 2 (n - 1) inner coordinates in ``inner``'s order.

    Analytic: det = Ls × Lv is bilinear in the map's partials, which are linear in the control
    points (S) and in the feet (P, which follow a row's height where it is not clamped)."""
    ctrl = _with_ends(inner)
    q = _jacobian_parts(ctrl)
    n, Ls, Lv, det, scale = q["n"], q["Ls"], q["Lv"], q["det"], q["scale"]
    B = q["bn"][:, 1:n]                                                    # (V, n-1)
    D = n * (q["bd"][:, :n - 1] - q["bd"][:, 1:n])                         # hodograph of a unit bump
    s = _JAC_S[:, None, None]
    b0, db0 = (1.0 - s) ** 3, -3.0 * (1.0 - s) ** 2
    PB = (B @ q["dfeet"])[:, None]                                         # d P_y / d y_j: (B, 1, V, n-1)
    PD = (D @ q["dfeet"])[:, None]
    lsx, lsy = Ls[..., 0][..., None], Ls[..., 1][..., None]                # (B, S, V, 1)
    lvx, lvy = Lv[..., 0][..., None], Lv[..., 1][..., None]
    d_x = B * lvy - lsy * s * D                                            # d det / d x_i
    d_y = lsx * ((1.0 - b0) * PD + s * (D - PD)) - (B - PB * (1.0 + db0)) * lvx
    grad = np.stack([d_x, d_y], axis=-1) / scale[:, None, None, None, None]
    x = inner[..., 0]
    top = np.argmax(np.abs(x), axis=1)                                     # d scale / d x at the widest row
    widest = np.abs(x[np.arange(len(x)), top]) > 1e-3
    norm = det / scale[:, None, None]
    sign = np.sign(x[np.arange(len(x)), top]) * widest
    grad[np.arange(len(x)), ..., top, 0] -= (norm / scale[:, None, None] * sign[:, None, None])
    b = len(inner)
    return (norm - _FOLD_MARGIN).reshape(b, -1), grad.reshape(b, det.shape[1] * det.shape[2], -1)


def _fold_cost(inner: NDArray[np.float64]) -> NDArray[np.float64]:
    det = jacobian_grids(_with_ends(inner)).reshape(len(inner), -1) - _FOLD_MARGIN
    return _FOLD_WEIGHT ** 2 * np.sum(np.minimum(det, 0.0) ** 2, axis=1)


def _gauss_newton(pts: NDArray[np.float64], t: NDArray[np.float64], inner: NDArray[np.float64], n: int,
                  rounds: int, weights: NDArray[np.float64] | None = None
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Tangent-distance Gauss-Newton with the fold penalty and per-leaf Levenberg-Marquardt
    damping (module step 3). Minimises, per leaf, Σ_j |C(t_j) - p_j|² (t_j the feet) plus
    ``_FOLD_WEIGHT²`` Σ min(det - ``_FOLD_MARGIN``, 0)² over the Jacobian grid, the objective of
    ``fit_outline``'s polish. ``weights`` (B, S) weigh the samples (the minimax rounds)."""
    b = len(pts)
    m = 2 * (n - 1)
    w = np.ones(pts.shape[:2]) if weights is None else weights
    ctrl = _with_ends(inner)
    t = _project(ctrl, pts, t)
    cost = _sq_distance(ctrl, pts, t, w) + _fold_cost(inner)
    mu = np.full(b, 1e-6)
    eye = np.eye(m)
    for _ in range(rounds):
        basis = bernstein(n, t)
        tangent = bernstein(n - 1, t) @ derivative_points(ctrl)
        tangent /= np.maximum(np.linalg.norm(tangent, axis=2, keepdims=True), 1e-12)
        normal = np.stack([-tangent[..., 1], tangent[..., 0]], axis=-1)
        q = pts - basis[:, :, n:] * np.array([0.0, 1.0])             # what the inner points must reach
        inner_basis = basis[:, :, 1:n, None]
        an = (inner_basis * normal[:, :, None, :]).reshape(b, -1, m)  # d(ν·C)/d(inner), flattened (i, xy)
        at = (inner_basis * tangent[:, :, None, :]).reshape(b, -1, m)
        rn = np.sum(normal * q, axis=2)
        rt = np.sum(tangent * q, axis=2)
        ant, att = np.swapaxes(an * w[..., None], 1, 2), np.swapaxes(at * w[..., None], 1, 2)
        x0 = inner.reshape(b, m, 1)
        lhs = ant @ an + _TANGENT_WEIGHT * (att @ at)
        rhs = ant @ rn[..., None] + _TANGENT_WEIGHT * (att @ rt[..., None])
        # fold penalty rows where the blade (nearly) folds: w (det0 + G (x - x0)) -> 0
        det, grad = _fold_terms(inner)
        active = det < 0.0
        if active.any():
            g = grad * active[..., None]
            gt = np.swapaxes(g, 1, 2)
            lhs = lhs + _FOLD_WEIGHT ** 2 * (gt @ g)
            rhs = rhs + _FOLD_WEIGHT ** 2 * (gt @ (g @ x0 - (det * active)[..., None]))
        scale = np.trace(lhs, axis1=1, axis2=2)[:, None, None] / m
        damp = mu[:, None, None] * scale
        x = np.linalg.solve(lhs + damp * eye, rhs + damp * x0)
        trial_inner = x.reshape(b, n - 1, 2)
        trial_ctrl = _with_ends(trial_inner)
        trial_t = _project(trial_ctrl, pts, t)
        trial_cost = _sq_distance(trial_ctrl, pts, trial_t, w) + _fold_cost(trial_inner)
        ok = trial_cost <= cost
        inner = np.where(ok[:, None, None], trial_inner, inner)
        ctrl = _with_ends(inner)
        t = np.where(ok[:, None], trial_t, t)
        cost = np.where(ok, trial_cost, cost)
        mu = np.where(ok, np.maximum(mu * 0.3, 1e-9), mu * 10.0)
    return inner, t


def elevate(ctrl: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B, n + 2, 2): the same Bézier curves one degree higher (Farin, eq. of degree elevation:
    c'_i = i/(n+1) c_{i-1} + (1 - i/(n+1)) c_i)."""
    n = ctrl.shape[1] - 1
    a = (np.arange(1, n + 1) / (n + 1))[None, :, None]
    inner = a * ctrl[:, :-1] + (1.0 - a) * ctrl[:, 1:]
    return np.concatenate([ctrl[:, :1], inner, ctrl[:, -1:]], axis=1)


def fit_sides(points: ArrayLike, rows: int, *, start: NDArray[np.float64] | None = None,
              linear_rounds: int | None = None, gn_rounds: int | None = None) -> NDArray[np.float64]:
    """Control points (B, rows + 2, 2) of the degree rows + 1 Béziers from (0, 0) to (0, 1) fitted
    to a batch of sides (B, K, 2), each from base to apex (module steps 1-3).

    ``start`` (B, rows + 1, 2): fits with one row fewer; their degree elevation (the same curves)
    is a second start for the Gauss-Newton rounds, and each leaf keeps the better of the two, so
    a leaf never fits worse with more rows.

    Every leaf is fitted on its own (no coupling through the batch): the result for a batch equals
    the results for its leaves one at a time, to rounding.
    """
    if not 3 <= rows <= MAX_SILHOUETTE_ROWS:
        raise ParamError("rows", f"must be in 3..{MAX_SILHOUETTE_ROWS}, got {rows}")
    linear_rounds = _LINEAR_ROUNDS if linear_rounds is None else linear_rounds
    gn_rounds = _GN_ROUNDS if gn_rounds is None else gn_rounds
    pts = _resample(_as_batch(points, "points", 3), _SAMPLES)
    n = rows + 1
    t = _chord(pts)
    for _ in range(linear_rounds):
        inner = _linear_solve(pts, t, n)
        t = _project(_with_ends(inner), pts, t)
    inner = _linear_solve(pts, t, n)
    if gn_rounds > 0:
        inner, t = _gauss_newton(pts, t, inner, n, gn_rounds)
    if start is not None:
        if start.shape != (len(pts), n, 2):
            raise ParamError("start", f"expected shape {(len(pts), n, 2)}, got {start.shape}")
        other, t2 = _gauss_newton(pts, t, elevate(start)[:, 1:-1], n, gn_rounds)
        mine = _sq_distance(_with_ends(inner), pts, t) + _fold_cost(inner)
        theirs = _sq_distance(_with_ends(other), pts, t2) + _fold_cost(other)
        inner = np.where((theirs < mine)[:, None, None], other, inner)
    return _with_ends(inner)


def minimax_sides(points: ArrayLike, ctrl: NDArray[np.float64], rounds: int = _MINIMAX_ROUNDS) -> NDArray[np.float64]:
    """Refine fitted control points (B, n + 1, 2) towards the smallest *largest* sample distance
    (what the Hausdorff error measures) by Lawson's iteration: each round weighs every sample by
    its distance times its previous weight, then runs weighted Gauss-Newton rounds. Each leaf keeps
    its iterate with the smallest largest distance (possibly the input)."""
    pts = _resample(_as_batch(points, "points", 3), _SAMPLES)
    n = ctrl.shape[1] - 1
    inner = ctrl[:, 1:-1].copy()
    t = _project(ctrl, pts, _chord(pts), steps=3 * _PROJECT_STEPS)
    def worst(c: NDArray[np.float64], tt: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.linalg.norm(bernstein(n, tt) @ c - pts, axis=2)

    dist = worst(ctrl, t)
    best, best_max = inner.copy(), dist.max(axis=1)
    w = np.ones(pts.shape[:2])
    for _ in range(rounds):
        w = w * np.maximum(dist, 1e-9)
        w = np.maximum(w / w.mean(axis=1, keepdims=True), 1e-3)
        inner, t = _gauss_newton(pts, t, inner, n, _MINIMAX_GN_ROUNDS, w)
        c = _with_ends(inner)
        dist = worst(c, t)
        better = (dist.max(axis=1) < best_max) & (jacobian_grids(c).min(axis=(1, 2)) > 0.0)
        best[better], best_max[better] = inner[better], dist.max(axis=1)[better]
    return _with_ends(best)


# -- rows and the error -----------------------------------------------------------------------------
def controls_from_params(params: Sequence[LeafParams]) -> list[NDArray[np.float64]]:
    """The right margin's control points of straight-axis leaves, from their rows and tilts
    (eq. 3 with tilt: ``c = (x̄s cos φ, v̄ - x̄s sin φ)``); what the shader draws for them."""
    out = []
    for p in params:
        sh = p.shape
        xs, phi = np.asarray(sh.xs, np.float64), np.asarray(sh.phi, np.float64)
        inner = np.stack([xs * np.cos(phi), np.asarray(sh.vbar, np.float64) - xs * np.sin(phi)], axis=-1)
        out.append(np.vstack([[0.0, 0.0], inner, [0.0, 1.0]]))
    return out


def _subdivide(lines: NDArray[np.float64], parts: int) -> NDArray[np.float64]:
    """(B, (K - 1) parts + 1, 2): every segment of the (B, K, 2) polylines cut into ``parts``."""
    f = (np.arange(parts) / parts)[None, None, :, None]
    inner = lines[:, :-1, None] + f * (lines[:, 1:, None] - lines[:, :-1, None])
    return np.concatenate([inner.reshape(len(lines), -1, 2), lines[:, -1:]], axis=1)


def _to_curve(points: NDArray[np.float64], ctrl: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B, P) distance of each point to its leaf's Bézier (B, n + 1, 2): the nearest of
    ``_CURVE_SEEDS`` even parameters (one k-d tree for the batch, leaves kept apart as in
    :class:`_SideTree`), then Newton projection within that parameter step (never below the true
    distance)."""
    seeds = np.linspace(0.0, 1.0, _CURVE_SEEDS)
    b, p = points.shape[:2]
    on = bernstein(ctrl.shape[1] - 1, seeds) @ ctrl                        # (B, seeds, 2)
    shift = np.c_[_SPREAD * np.repeat(np.arange(b, dtype=np.float64), _CURVE_SEEDS), np.zeros(b * _CURVE_SEEDS)]
    tree = cKDTree(on.reshape(-1, 2) + shift)
    lanes = np.c_[_SPREAD * np.repeat(np.arange(b, dtype=np.float64), p), np.zeros(b * p)]
    hit = tree.query(points.reshape(-1, 2) + lanes)[1]
    if np.any(hit // _CURVE_SEEDS != np.repeat(np.arange(b), p)):
        raise RuntimeError("batched Hausdorff: a nearest point belongs to another leaf (margin far off?)")
    t = seeds[hit % _CURVE_SEEDS].reshape(b, p)
    n = ctrl.shape[1] - 1
    d1 = derivative_points(ctrl)
    dd = derivative_points(d1)
    for _ in range(_CURVE_NEWTON):
        r = bernstein(n, t) @ ctrl - points
        s1 = bernstein(n - 1, t) @ d1
        s2 = bernstein(n - 2, t) @ dd
        num = np.sum(r * s1, axis=2)
        den = np.sum(s1 * s1, axis=2) + np.sum(r * s2, axis=2)
        step = np.where(den > 1e-12, num / np.where(den > 1e-12, den, 1.0), 0.0)
        t = np.clip(t - np.clip(step, -1.0 / _CURVE_SEEDS, 1.0 / _CURVE_SEEDS), 0.0, 1.0)
    return np.linalg.norm(bernstein(n, t) @ ctrl - points, axis=2)


class _SideTree:
    """Target sides (B, K, 2) densified to ``_ERROR_STEP`` (as :func:`~leafview.botany.outline_fit.hausdorff`)
    in one k-d tree, side b shifted by ``b · _SPREAD`` along x, so one query finds every point's
    nearest target point on its own leaf's side."""

    def __init__(self, sides: NDArray[np.float64]) -> None:
        dense = [_densify(s, _ERROR_STEP) for s in sides]
        owner = np.repeat(np.arange(len(sides)), [len(d) for d in dense])
        self.tree = cKDTree(np.concatenate(dense) + np.c_[_SPREAD * owner, np.zeros(len(owner))])
        self.owner = owner

    def farthest(self, points: NDArray[np.float64], leaves: NDArray[np.int64]) -> NDArray[np.float64]:
        """(len(leaves),): the largest distance from ``points[i]`` (P, 2) to side ``leaves[i]``."""
        p = points.shape[1]
        shift = np.repeat(_SPREAD * leaves.astype(np.float64), p)
        dist, hit = self.tree.query(points.reshape(-1, 2) + np.c_[shift, np.zeros(len(shift))])
        if np.any(self.owner[hit] != np.repeat(leaves, p)):
            raise RuntimeError("batched Hausdorff: a nearest point belongs to another leaf (margin far off?)")
        return dist.reshape(len(leaves), p).max(axis=1)


class _ErrorMeter:
    """The outline error (module step 5) against fixed target sides for margins given by their
    control points. The margin → side distance uses the sides' k-d tree (built once per batch),
    the side → margin distance projects the side's points onto the Bézier (batched Newton)."""

    def __init__(self, right: NDArray[np.float64], left: NDArray[np.float64]) -> None:
        mirrored = left * [-1.0, 1.0]
        if mirrored.shape == right.shape:
            self.asym = ~np.all(np.abs(mirrored - right) <= 1e-12, axis=(1, 2))
        else:
            self.asym = np.ones(len(right), dtype=bool)
        self.sides = (right, mirrored)
        self.trees: list[_SideTree | None] = [_SideTree(right), _SideTree(mirrored) if self.asym.any() else None]
        self.sources = tuple(_subdivide(s, _TARGET_PARTS) for s in self.sides)

    def __call__(self, ctrl: Sequence[NDArray[np.float64]], which: NDArray[np.int64]) -> NDArray[np.float64]:
        """(len(which), 3): whole, right, left error of the margins ``ctrl`` of leaves ``which``."""
        out = np.zeros((len(which), 2))
        v = np.linspace(0.0, 1.0, _MARGIN_SAMPLES)
        by_degree: dict[int, list[int]] = {}
        for i, c in enumerate(ctrl):
            by_degree.setdefault(len(c) - 1, []).append(i)
        for n, rows in by_degree.items():
            rows_a = np.asarray(rows)
            c = np.stack([np.asarray(ctrl[i], np.float64) for i in rows])
            leaves = which[rows_a]
            curve = bernstein(n, v) @ c
            for s, tree in enumerate(self.trees):
                sel = np.ones(len(rows), bool) if s == 0 else self.asym[leaves]
                if tree is None or not sel.any():
                    continue
                there = tree.farthest(curve[sel], leaves[sel])
                back = _to_curve(self.sources[s][leaves[sel]], c[sel]).max(axis=1)
                out[rows_a[sel], s] = np.maximum(there, back)
        sym = ~self.asym[which]
        out[sym, 1] = out[sym, 0]
        return np.c_[out.max(axis=1), out]


def outline_errors(ctrl: Sequence[NDArray[np.float64]] | NDArray[np.float64], right: ArrayLike,
                   left: ArrayLike | None = None) -> NDArray[np.float64]:
    """(B, 3): whole, right and left Hausdorff distance ÷ leaf length between the margins of
    straight-axis leaves (their right control points, (n + 1, 2) each; the left margin is the
    mirror image) and the target sides (B, K, 2), base to apex. The batched
    :func:`~leafview.botany.outline_fit.outline_error` (module step 5); ``left`` defaults to the
    mirrored right side."""
    r = _as_batch(right, "right", 2)
    lt = r * [-1.0, 1.0] if left is None else _as_batch(left, "left", 2)
    if len(ctrl) != len(r) or len(lt) != len(r):
        raise ParamError("ctrl", f"expected {len(r)} control polygons and left sides, got {len(ctrl)} and {len(lt)}")
    return _ErrorMeter(r, lt)(list(ctrl), np.arange(len(r)))


# -- the batch fit ----------------------------------------------------------------------------------
def fit_inputs(outlines: ArrayLike | None, right: ArrayLike | None, left: ArrayLike | None, target: float,
               min_rows: int, max_rows: int, names: Sequence[str] | None, *, same_shape: bool = False
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], list[str]]:
    """The checked arguments of a batch fit (:func:`fit_outlines` and the quick fit): right and
    left sides (B, K, 2) and B names. ``same_shape``: the left sides must have the right sides'
    shape (not only their count). Raises :class:`ParamError` naming the argument."""
    if outlines is not None:
        if right is not None or left is not None:
            raise ParamError("outlines", "give outlines or right/left sides, not both")
        r, lt = _split_batch(_as_batch(outlines, "outlines", 6))
    elif right is not None:
        r = _as_batch(right, "right", 3)
        lt = r * [-1.0, 1.0] if left is None else _as_batch(left, "left", 3)
        if same_shape and lt.shape != r.shape:
            raise ParamError("left", f"expected {r.shape} like the right sides, got {lt.shape}")
        if len(lt) != len(r):
            raise ParamError("left", f"expected {len(r)} left sides, got {len(lt)}")
        _check_ends(r, "right")
        _check_ends(lt, "left")
    else:
        raise ParamError("outlines", "give outlines or their right sides")
    if not (isinstance(target, (int, float)) and np.isfinite(target) and target > 0.0):
        raise ParamError("target", f"must be a positive number, got {target!r}")
    if not 3 <= min_rows <= max_rows <= MAX_SILHOUETTE_ROWS:
        raise ParamError("max_rows", f"rows must satisfy 3 <= {min_rows} <= {max_rows} <= {MAX_SILHOUETTE_ROWS}")
    if names is None:
        names = [""] * len(r)
    elif len(names) != len(r):
        raise ParamError("names", f"expected {len(r)} names, got {len(names)}")
    return r, lt, list(names)



def fit_outlines(outlines: ArrayLike | None = None, *, right: ArrayLike | None = None, left: ArrayLike | None = None,
                 target: float = DEFAULT_BATCH_TARGET, min_rows: int = 3, max_rows: int = MAX_SILHOUETTE_ROWS,
                 fallback: bool = True, names: Sequence[str] | None = None) -> BatchFit:
    """Fit Ω to a batch of closed outlines (or of right and left sides), vectorised over the batch.

    Parameters
    ----------
    outlines
        (B, M, 2) closed polylines as :func:`~leafview.botany.landmarks.outline` writes them (base at
        row 0, apex at row M / 2), all of the same length.
    right, left
        Instead of ``outlines``: (B, K, 2) sides from the base (0, 0) to the apex (0, 1); ``left``
        (x < 0) defaults to the mirrored right side.
    target
        Accept the smallest row count N whose error (Hausdorff ÷ leaf length) is at most this and
        whose blade does not fold.
    min_rows, max_rows
        Range of silhouette rows tried, batch by batch.
    fallback
        Fit the leaves that miss ``target`` (or fold) at every N with
        :func:`~leafview.botany.outline_fit.fit_outline` (least-squares polish, slow); off: keep the
        best batched fit (no fold first, then the smallest error).
    names
        One leaf name per outline (default "").

    Returns
    -------
    BatchFit
    """
    t0 = time.perf_counter()
    r, lt, names = fit_inputs(outlines, right, left, target, min_rows, max_rows, names)
    b = len(r)

    meter = _ErrorMeter(r, lt)
    mean = 0.5 * (_resample(r, _MEAN_SAMPLES) + _resample(lt * [-1.0, 1.0], _MEAN_SAMPLES))
    params: list[LeafParams | None] = [None] * b
    errors = np.full((b, 3), np.inf)
    jac = np.full(b, -np.inf)
    rows = np.zeros(b, dtype=np.int64)
    attempts: dict[int, int] = {}
    todo = np.arange(b)

    def keep_better(ctrl: NDArray[np.float64], n_rows: int) -> NDArray[np.bool_]:
        """Measure the fits ``ctrl`` of the leaves ``todo``, keep each where it beats the leaf's
        best so far (no fold first, then the smaller error); True where it meets the target."""
        fitted = params_from_controls(ctrl, [names[int(i)] for i in todo])
        err = meter(controls_from_params(fitted), todo)
        jmin = min_jacobians(ctrl)
        for k, i in enumerate(todo):
            if params[i] is None or (jmin[k] > 0.0, -err[k, 0]) > (jac[i] > 0.0, -errors[i, 0]):
                params[i], errors[i], jac[i], rows[i] = fitted[k], err[k], jmin[k], n_rows
        return (err[:, 0] <= target) & (jmin > 0.0)

    last: NDArray[np.float64] | None = None   # previous round's fits of the leaves still to do
    keep = np.ones(b, dtype=bool)
    for n_rows in range(min_rows, max_rows + 1):
        if todo.size == 0:
            break
        attempts[n_rows] = int(todo.size)
        ctrl = fit_sides(mean[todo], n_rows, start=None if last is None else last[keep])
        done = keep_better(ctrl, n_rows)
        todo, last, keep = todo[~done], ctrl, ~done

    if todo.size and last is not None and last.shape[1] == max_rows + 2:
        # the leaves still missing at max_rows: minimise the largest distance instead of the sum
        attempts[-1] = int(todo.size)
        todo = todo[~keep_better(minimax_sides(mean[todo], last[keep]), max_rows)]

    used = np.zeros(b, dtype=bool)
    t_fb = time.perf_counter()
    if fallback:
        for i in todo:
            fit = fit_outline(right=r[i], left=lt[i], target=target, min_rows=min_rows, max_rows=max_rows, name=names[int(i)])
            c = controls_from_params([fit.params])[0]
            j = float(min_jacobians([c])[0])
            if (j > 0.0, -fit.error) > (jac[i] > 0.0, -errors[i, 0]):
                params[i], errors[i], jac[i], rows[i] = fit.params, (fit.error, *fit.error_sides), j, fit.rows
            used[i] = True
    fb_seconds = time.perf_counter() - t_fb
    return BatchFit([p for p in params if p is not None], errors[:, 0].copy(), errors[:, 1:].copy(), rows, jac, used,
                    attempts, time.perf_counter() - t0, fb_seconds, float(target))


def fit_landmark_leaves(leaves: Sequence[LandmarkLeaf], *, n: int = 128, **options: Any) -> BatchFit:
    """Fit Ω to a batch of :class:`~leafview.botany.landmarks.LandmarkLeaf` (their margins sampled
    with :func:`~leafview.botany.landmarks.outline`, ``n`` points per side); ``options`` go to
    :func:`fit_outlines`. Leaf names carry over."""

    for k, leaf in enumerate(leaves):
        if not isinstance(leaf, LandmarkLeaf):
            raise ParamError(f"leaves[{k}]", f"expected a LandmarkLeaf, got {type(leaf).__name__}")
    if len(leaves) == 0:
        raise ParamError("leaves", "expected at least one leaf")
    rings = outlines(leaves, n)
    options.setdefault("names", [leaf.name or "" for leaf in leaves])
    return fit_outlines(rings, **options)

