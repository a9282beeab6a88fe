"""Fit the shader model Ω to a leaf margin (a closed outline polyline) by least squares.

The target is an outline in leaf space, base at (0, 0) and apex at (0, 1), as written by
:func:`leafview.botany.landmarks.outline` (Garg & Leow 2011, eqs 2-6): the right side (x > 0) from the
base up to the apex, then the left side back down. The result is a :class:`LeafParams` whose
margin (the ``u = ±1`` curves of :func:`leafview.deform.surface.evaluate`, Chaurasia & Beardsley 2017, eqs 3-6) follows
that outline, so every catalogue shape renders through the shader path.

How (Chaurasia & Beardsley 2017, sec. 3; the fit itself is ours):

1. The axis A stays straight, ``a1 = (0, 1/3, 0)``, ``a2 = (0, 2/3, 0)``, so ``A(v) = (0, v, 0)``
   and ``n = -x`` (eq. 2). The model is mirror-symmetric about the axis; an asymmetric outline is
   fitted through the mean of its right side and its mirrored left side, and its error is measured
   against both sides as they are (so asymmetry shows up in the reported error, never hidden).
2. The margin of the right half is the silhouette S_σ=-1, a Bézier of degree N + 1 (eq. 1) with
   base (0, 0), apex (0, 1) and N inner control points ``c_i``. For N = 3 .. N_max, the ``c_i``
   come from linear least squares with chord-length parameters, refined by Newton projection of
   the samples onto the curve (Hoschek's parameter correction) and then by
   :func:`scipy.optimize.least_squares` over the control points and the sample parameters jointly,
   with a penalty that keeps the blade from folding (below).
3. Each control point becomes a silhouette row (eq. 3 with the tilt of
   :mod:`leafview.core.params`): its foot ``v̄_i`` is its height clamped into (0, 1) and kept
   strictly increasing; if the point lies off the foot's normal line (below the base: cordate
   lobes; above the apex: emarginate shoulders), the row is tilted, ``x̄s_i cos φ_i = c_x``,
   ``-x̄s_i sin φ_i = c_y - v̄_i``. With N = 3 and no tilt the result is the paper's 21-number Ω.
4. Folding: in the leaf plane, eq. 6 maps (|u|, v) to ``L = B0(s) A(v) + (1 - B0(s)) P(v) +
   s (S(v) - P(v))`` (P the curve through the feet). Its Jacobian determinant must keep one sign
   over the blade, otherwise the surface doubles back and a top view is not bounded by the margin
   (for example the sinus of a cordate leaf filled in). It is sampled on a grid, penalised in the
   fit and reported (:attr:`OutlineFit.min_jacobian`).
5. The error is the symmetric Hausdorff distance between the evaluated margin (both sides) and the
   target outline, divided by the leaf length (base to apex: 1 in leaf space). The smallest N whose
   error is within ``target`` (and which does not fold) is kept, else the best one found.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from leafview.core.bezier import bernstein, derivative_points
from leafview.core.defaults import OUTLINE_FIT_TARGET
from leafview.core.params import MAX_SILHOUETTE_ROWS, LeafParams, ParamError, Shape
from leafview.deform.surface import control_polygons, evaluate, partials

__all__ = ["OutlineFit", "fit_outline", "fit_side", "split_outline", "margin", "hausdorff",
           "outline_error", "rows_from_controls", "params_from_controls", "jacobian_min", "DEFAULT_TARGET"]

DEFAULT_TARGET = OUTLINE_FIT_TARGET   # accept the smallest N whose error is below this
_FOOT_GAP = 1e-3            # smallest spacing of the feet v̄_i (they must increase strictly)
_SAMPLES = 80               # target samples per side in the fit
_FOLD_WEIGHT = 0.5          # weight of the fold penalty residuals
_FOLD_MARGIN = 0.01         # normalised Jacobian below which the penalty starts
_QUICK_STEP = 2e-3         # polyline spacing of the error estimate while choosing N
_QUICK_SAMPLES = 257
_JAC_S = np.linspace(0.05, 1.0, 8)
_JAC_V = np.linspace(0.01, 0.99, 49)


@dataclass(frozen=True)
class OutlineFit:
    """The fitted Ω and how well it follows the outline.

    Attributes
    ----------
    params
        The leaf (straight axis, flat blade, N silhouette rows).
    error
        Hausdorff distance between the evaluated margin and the outline ÷ leaf length.
    error_sides
        The same for the right (x > 0) and the left side separately.
    rows
        N, the number of silhouette rows (degree N + 1); 3 with no tilt is the paper's quartic.
    min_jacobian
        Smallest normalised Jacobian determinant of the in-plane map over the blade (> 0: no fold).
    tried
        ``{N: error}`` for every N tried.
    seconds
        Wall time of the fit.
    """

    params: LeafParams
    error: float
    error_sides: tuple[float, float]
    rows: int
    min_jacobian: float
    tried: dict[int, float]
    seconds: float

    @property
    def quartic(self) -> bool:
        """True when the result is the paper's 21-number model (3 rows, no tilt)."""
        return not self.params.shape.extended

    @property
    def folded(self) -> bool:
        return self.min_jacobian <= 0.0


# -- geometry helpers ---------------------------------------------------------------------------
def _resample(points: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """``n`` points evenly spaced in arc length along the polyline ``points``."""
    d = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))]
    t = np.linspace(0.0, d[-1], n)
    return np.stack([np.interp(t, d, points[:, 0]), np.interp(t, d, points[:, 1])], axis=-1)


def _densify(points: NDArray[np.float64], step: float = 1e-3) -> NDArray[np.float64]:
    """The polyline with every segment split into pieces no longer than ``step`` (vertices kept)."""
    seg = np.diff(points, axis=0)
    k = np.maximum(np.ceil(np.linalg.norm(seg, axis=1) / step).astype(int), 1)
    idx = np.repeat(np.arange(len(seg)), k)
    start = np.repeat(np.cumsum(k) - k, k)
    frac = (np.arange(idx.size) - start) / k[idx]
    return np.vstack([points[idx] + frac[:, None] * seg[idx], points[-1:]])


class _Side:
    """A target side, densified, with its k-d tree (built once per fit)."""

    def __init__(self, points: NDArray[np.float64], step: float) -> None:
        self.points = _densify(points, step)
        self.tree = cKDTree(self.points)

    def distance(self, curve: NDArray[np.float64], step: float) -> float:
        """Hausdorff distance between this side and the polyline ``curve``."""
        dense = _densify(curve, step)
        return float(max(self.tree.query(dense)[0].max(), cKDTree(dense).query(self.points)[0].max()))


def hausdorff(a: ArrayLike, b: ArrayLike) -> float:
    """Symmetric Hausdorff distance between two polylines (densified to 1e-3 spacing)."""
    pa, pb = _densify(np.asarray(a, np.float64)), _densify(np.asarray(b, np.float64))
    return float(max(cKDTree(pb).query(pa)[0].max(), cKDTree(pa).query(pb)[0].max()))


def split_outline(outline: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Split a closed outline (right side up from the base, then left side down, as
    :func:`leafview.botany.landmarks.outline` writes it) at the apex: ``(right, left)``, each from
    the base (0, 0) to the apex (0, 1). Raises :class:`ParamError` if base or apex are missing."""
    pts = np.asarray(outline, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 6 or not np.all(np.isfinite(pts)):
        raise ParamError("outline", f"expected a finite (M >= 6, 2) polyline, got shape {pts.shape}")
    if np.linalg.norm(pts[0]) > 1e-9:
        raise ParamError("outline", f"must start at the base (0, 0), starts at {pts[0].tolist()}")
    k = int(np.argmin(np.linalg.norm(pts - [0.0, 1.0], axis=1)))
    if np.linalg.norm(pts[k] - [0.0, 1.0]) > 1e-9:
        raise ParamError("outline", "must pass through the apex (0, 1)")
    right = pts[:k + 1]
    left = np.vstack([pts[k:], pts[:1]])[::-1]
    return right, left


def margin(params: LeafParams, n: int = 1025) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The leaf's margin as two polylines from base to apex, ``(right, left)``: the ``u = -1``
    (+x for a straight axis) and ``u = +1`` curves of eq. 6, xy only."""
    v = np.linspace(0.0, 1.0, n)
    right = evaluate(params, -np.ones(n), v)[:, :2]
    left = evaluate(params, np.ones(n), v)[:, :2]
    return right, left


def outline_error(params: LeafParams, right: ArrayLike, left: ArrayLike | None = None
                  ) -> tuple[float, float, float]:
    """(whole, right, left) Hausdorff distances between the margin of ``params`` and the target
    sides ÷ leaf length (1). ``left`` defaults to the mirror image of ``right``."""
    r = np.asarray(right, np.float64)
    lt = r * [-1.0, 1.0] if left is None else np.asarray(left, np.float64)
    mr, ml = margin(params)
    er, el = hausdorff(mr, r), hausdorff(ml, lt)
    return max(er, el), er, el


# -- the Bézier fit of one side --------------------------------------------------------------
def _controls(inner: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.vstack([[0.0, 0.0], inner, [0.0, 1.0]])


def _project(ctrl: NDArray[np.float64], pts: NDArray[np.float64], t: NDArray[np.float64],
             steps: int = 3) -> NDArray[np.float64]:
    """Newton steps moving each parameter to the foot of its sample on the curve, the first and
    last parameters pinned to 0 and 1 and the order kept. Works on one curve (``ctrl`` (n+1, 2),
    ``pts`` (P, 2), ``t`` (P,)) or a batch (leading axis B on all three)."""
    n = ctrl.shape[-2] - 1
    d1 = derivative_points(ctrl)
    d2 = derivative_points(d1)
    for _ in range(steps):
        r = bernstein(n, t) @ ctrl - pts
        s1 = bernstein(n - 1, t) @ d1
        s2 = bernstein(n - 2, t) @ d2
        num = np.sum(r * s1, axis=-1)
        den = np.sum(s1 * s1, axis=-1) + np.sum(r * s2, axis=-1)
        step = num / np.where(np.abs(den) > 1e-12, den, 1e-12)
        t = np.clip(t - np.clip(step, -0.05, 0.05), 0.0, 1.0)
        t[..., 0], t[..., -1] = 0.0, 1.0
        t = np.maximum.accumulate(t, axis=-1)
    return t


def _linear_fit(pts: NDArray[np.float64], t: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """Inner control points of the degree-n Bézier with fixed ends minimising Σ|B(t_j) - p_j|²."""
    b = bernstein(n, t)
    rhs = pts - np.outer(b[:, n], [0.0, 1.0])
    inner = np.linalg.lstsq(b[:, 1:n], rhs, rcond=None)[0]
    return np.asarray(inner, dtype=np.float64)


def fit_side(points: ArrayLike, rows: int, *, iterations: int = 12, polish: bool = True
             ) -> NDArray[np.float64]:
    """Control points (rows + 2, 2) of the degree rows + 1 Bézier from (0, 0) to (0, 1) fitted
    to one side (base to apex) by least squares with parameter correction, then (``polish``)
    :func:`scipy.optimize.least_squares` over control points and parameters with the fold
    penalty of the module docstring."""
    pts = _resample(np.asarray(points, np.float64), _SAMPLES)
    n = rows + 1
    d = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]
    t = d / d[-1]
    for _ in range(iterations):
        inner = _linear_fit(pts, t, n)
        t = _project(_controls(inner), pts, t)
    inner = _linear_fit(pts, t, n)
    if not polish:
        return _controls(inner)
    return _controls(_polish(pts, t, inner, n))


def _polish(pts: NDArray[np.float64], t: NDArray[np.float64], inner: NDArray[np.float64], n: int
            ) -> NDArray[np.float64]:
    """Joint refinement of the inner control points and the sample parameters (each sample's
    parameter is its own variable in [0, 1], so the Jacobian is sparse: finite differences need
    one column group per control coordinate plus one for all the parameters)."""
    k = len(pts)
    nc = 2 * (n - 1)

    def unpack(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return x[:nc].reshape(n - 1, 2), np.r_[0.0, x[nc:], 1.0]

    def residuals(x: NDArray[np.float64]) -> NDArray[np.float64]:
        c, tt = unpack(x)
        ctrl = _controls(c)
        fit = (bernstein(n, tt) @ ctrl - pts).ravel()
        det = _jacobian_grid(ctrl)
        fold = _FOLD_WEIGHT * np.minimum(det - _FOLD_MARGIN, 0.0).ravel()  # only where it nearly folds
        return np.r_[fit, fold]

    x0 = np.r_[inner.ravel(), t[1:-1]]
    sparsity = np.zeros((2 * k + _JAC_S.size * _JAC_V.size, x0.size), dtype=bool)
    sparsity[:, :nc] = True
    rows = np.arange(1, k - 1)
    sparsity[2 * rows, nc + rows - 1] = True
    sparsity[2 * rows + 1, nc + rows - 1] = True
    lo = np.r_[np.full(nc, -np.inf), np.zeros(k - 2)]
    hi = np.r_[np.full(nc, np.inf), np.ones(k - 2)]
    res = least_squares(residuals, np.clip(x0, lo, hi), jac_sparsity=sparsity, bounds=(lo, hi), method="trf",
                        x_scale="jac", max_nfev=60, xtol=1e-10, ftol=1e-10)
    return unpack(res.x)[0]


# -- control points to silhouette rows ----------------------------------------------------
def _feet_rows(y: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B, N) feet v̄_i of B leaves' rows from the heights y (B, N) of their control points:
    clamped into (0, 1) and kept increasing by at least ``_FOOT_GAP`` (a running maximum)."""
    n = y.shape[1]
    step = _FOOT_GAP * np.arange(n)
    lo = _FOOT_GAP * np.arange(1, n + 1)
    hi = 1.0 - _FOOT_GAP * np.arange(n, 0, -1)
    return np.minimum(np.maximum.accumulate(np.clip(y, lo, hi) - step, axis=1) + step, hi)


def _feet(y: NDArray[np.float64]) -> NDArray[np.float64]:
    return _feet_rows(np.asarray(y, np.float64)[None])[0]


def _rows_arrays(ctrl: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Feet v̄, x̄s and tilts φ (degrees), each (B, N), of the inner control points
    ``ctrl[:, 1:-1]`` (B, N + 2, 2) of B right sides (eq. 3 with tilt)."""
    c = ctrl[:, 1:-1]
    feet = _feet_rows(c[..., 1])
    dy = c[..., 1] - feet
    r = np.hypot(c[..., 0], dy)
    xs = np.where(c[..., 0] >= 0.0, r, -r)
    safe = np.where(xs != 0.0, xs, 1.0)
    phi = np.where(np.abs(dy) > 0.0, np.degrees(np.arctan2(-dy / safe, c[..., 0] / safe)), 0.0)
    return feet, xs, np.clip(phi, -90.0, 90.0)


def rows_from_controls(ctrl: ArrayLike) -> tuple[tuple[tuple[float, float, float], ...], tuple[float, ...]]:
    """Silhouette rows ``(v̄, x̄s, 0)`` and tilts (degrees) placing the inner control points
    ``ctrl[1:-1]`` of the right side (x > 0) on a straight axis (eq. 3 with tilt)."""
    feet, xs, phi = (a[0].tolist() for a in _rows_arrays(np.asarray(ctrl, np.float64)[None]))
    return tuple((f, x, 0.0) for f, x in zip(feet, xs)), tuple(phi)


def _leaf_from_rows(feet: list[float], xs: list[float], phi: list[float], name: str) -> LeafParams:
    n = len(feet)
    shape = Shape(a1=(0.0, 1.0 / 3.0, 0.0), a2=(0.0, 2.0 / 3.0, 0.0), silhouette=tuple((f, x, 0.0) for f, x in zip(feet, xs)),
                  zf=(0.0,) * n, zg=(0.0,) * n, tilt=tuple(phi))
    return LeafParams(shape=shape, name=name)


def _params_from_controls(ctrl: NDArray[np.float64], name: str = "") -> LeafParams:
    return params_from_controls(np.asarray(ctrl, np.float64)[None], [name])[0]


def params_from_controls(ctrl: NDArray[np.float64], names: Sequence[str]) -> list[LeafParams]:
    """Straight-axis flat leaves (B of them, named ``names``) whose right margin has the control
    points ``ctrl`` (B, N + 2, 2): rows and tilts of :func:`rows_from_controls`, for the batch at once."""
    feet, xs, phi = (a.tolist() for a in _rows_arrays(np.asarray(ctrl, np.float64)))
    return [_leaf_from_rows(f, x, p, name) for f, x, p, name in zip(feet, xs, phi, names)]


# -- folding --------------------------------------------------------------------------------
def _jacobian_grid(ctrl: NDArray[np.float64]) -> NDArray[np.float64]:
    """Jacobian determinant of the in-plane map (s, v) -> L of the right half for a straight axis,
    normalised by the blade's scale, on the (_JAC_S × _JAC_V) grid."""
    n = len(ctrl) - 1
    feet = _feet(ctrl[1:-1, 1])
    pctrl = np.zeros_like(ctrl)
    pctrl[1:-1, 1] = feet
    pctrl[-1] = (0.0, 1.0)
    v = _JAC_V
    bn, bd = bernstein(n, v), bernstein(n - 1, v)
    S, dS = bn @ ctrl, bd @ derivative_points(ctrl)
    P, dP = bn @ pctrl, bd @ derivative_points(pctrl)
    A = np.stack([np.zeros_like(v), v], axis=-1)
    dA = np.tile([0.0, 1.0], (len(v), 1))
    s = _JAC_S[:, None, None]
    b0, db0 = (1.0 - s) ** 3, -3.0 * (1.0 - s) ** 2
    Ls = db0 * (A - P) + (S - P)
    Lv = b0 * dA + (1.0 - b0) * dP + s * (dS - dP)
    det = Ls[..., 0] * Lv[..., 1] - Ls[..., 1] * Lv[..., 0]
    scale = max(float(np.abs(ctrl[:, 0]).max()), 1e-3)
    return det / scale


def jacobian_min(params: LeafParams, ns: int = 12, nv: int = 97) -> float:
    """Smallest Jacobian determinant of the in-plane map (|u|, v) -> L_xy over both halves of the
    blade, normalised by the leaf's half-width; positive means the blade does not fold. Uses the
    numpy reference partials (any axis)."""

    s = np.linspace(0.05, 1.0, ns)
    v = np.linspace(0.01, 0.99, nv)
    ss, vv = np.meshgrid(s, v)
    worst = np.inf
    for sigma in (-1.0, 1.0):
        p = partials(params, sigma * ss.ravel(), vv.ravel())
        lu = sigma * p.Lu[:, :2]            # d/ds, s = |u|
        det = lu[:, 0] * p.Lv[:, 1] - lu[:, 1] * p.Lv[:, 0]
        det = -det if sigma > 0 else det    # the u >= 0 half runs towards -x
        worst = min(worst, float(det.min()))
    width = float(np.abs(margin(params, 257)[0][:, 0]).max())
    return worst / max(width, 1e-3)


# -- the fit ------------------------------------------------------------------------------------
def fit_outline(outline: ArrayLike | None = None, *, right: ArrayLike | None = None,
                left: ArrayLike | None = None, target: float = DEFAULT_TARGET,
                max_rows: int = MAX_SILHOUETTE_ROWS, min_rows: int = 3, polish: bool = True,
                name: str = "") -> OutlineFit:
    """Fit Ω to a closed ``outline`` (or to its ``right`` and ``left`` sides, each from base to
    apex; ``left`` defaults to the mirrored right side).

    Parameters
    ----------
    outline
        (M, 2) closed polyline, right side up then left side down (see :func:`split_outline`).
    target
        Accept the smallest number of silhouette rows whose Hausdorff error ÷ leaf length is at
        most this and whose blade does not fold.
    max_rows, min_rows
        Range of silhouette rows N tried (degree N + 1).
    polish
        Run the joint least-squares refinement (slower, better); off: linear least squares with
        parameter correction only.

    Returns
    -------
    OutlineFit
    """
    t0 = time.perf_counter()
    if outline is not None:
        right, left = split_outline(outline)
    if right is None:
        raise ParamError("outline", "give an outline or its right side")
    r = np.asarray(right, np.float64)
    lt = r * [-1.0, 1.0] if left is None else np.asarray(left, np.float64)
    if not 3 <= min_rows <= max_rows <= MAX_SILHOUETTE_ROWS:
        raise ParamError("max_rows", f"rows must satisfy 3 <= {min_rows} <= {max_rows} <= {MAX_SILHOUETTE_ROWS}")
    # the symmetric model follows the mean of the right side and the mirrored left side
    mean = 0.5 * (_resample(r, 257) + _resample(lt * [-1.0, 1.0], 257))
    step = min(_QUICK_STEP, max(target / 2.0, 2e-5))   # fine enough to tell errors near the target
    sides = (_Side(r, step), _Side(lt * [-1.0, 1.0], step))
    vq = np.linspace(0.0, 1.0, _QUICK_SAMPLES)
    best: tuple[float, LeafParams, tuple[float, float], float] | None = None
    tried: dict[int, float] = {}
    for rows in range(min_rows, max_rows + 1):
        ctrl = fit_side(mean, rows, polish=False)           # linear least squares first
        for stage in ("linear", "polish"):
            if stage == "polish":
                if not polish:
                    break
                ctrl = fit_side(mean, rows, polish=True)
            params = _params_from_controls(ctrl, name)
            curve = bernstein(rows + 1, vq) @ _controls_of(params)     # the right margin, exactly
            er, el = (side.distance(curve, step) for side in sides)
            err = max(er, el)
            jac = float(_jacobian_grid(ctrl).min())
            tried[rows] = min(err, tried.get(rows, np.inf))
            if best is None or (jac > 0.0, -err) > (best[3] > 0.0, -best[0]):
                best = (err, params, (er, el), jac)
            if err <= target and jac > 0.0:
                break
        assert best is not None     # the linear stage of every row count sets it
        if best[0] <= target and best[3] > 0.0:
            break
    assert best is not None
    params = best[1]
    err, er, el = outline_error(params, r, lt)   # the reported error: the evaluated margin, fine steps
    return OutlineFit(params, err, (er, el), params.shape.rows, jacobian_min(params), tried,
                      time.perf_counter() - t0)


def _controls_of(params: LeafParams) -> NDArray[np.float64]:
    """The right side's silhouette control points in the plane (straight axis, eq. 3 with tilt)."""

    return control_polygons(params)["S-"][:, :2]
