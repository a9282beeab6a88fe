"""One leaf's Ω and placement from its point cloud (Chaurasia & Beardsley 2017, sec. 5 and 5.1, eqs 9-11).

The paper alternates a UV mapping P_A of the points with a Levenberg-Marquardt solve of eq. 11 for
the 21 numbers of its quartic model (:mod:`leafview.fit.quartic`). The steps, with the decisions
the paper leaves open (*Decision*):

1. **Frame.** The cloud is centred; its SVD gives the leaf plane (the two largest singular
   directions) and normal (the smallest), made right-handed.
2. **Ellipse, base and apex.** The minimum-volume enclosing ellipse of the in-plane points
   (:func:`leafview.fit.mvee.mvee`) gives the leaf's axis, its major axis. The paper puts base and
   apex at its major-axis extremities (sec. 5.1). *Decision:* on the built-in presets those lie
   well beyond a blunt end (7 % below the base and 8 % above the apex of "ovate", 17 % below the
   base of "acuminate": the enclosing ellipse of an ovate blade is longer than the blade), and
   nothing pulls a tip back from where no point lies. So base and apex are put at the cloud's two
   ends along the major axis (there along the axis; across it and in height the mean of the
   points within :data:`TIP_SLAB` of the length of each end). A tip hidden by an occluder is not
   extrapolated; the ellipse still weights the scanlines (eq. 10) and shapes the initial Ω.
3. **Placement.** A similarity maps base to (0, 0, 0) and apex to (0, 1, 0), z along the plane
   normal; it is the leaf's :class:`~leafview.core.params.Transform` (with the cloud's frame).
   Base and apex are fixed from here on; the leaf may roll about the line through them (step 6).
4. **UV mapping P_A.** The paper draws scanlines across the axis and gives each point the
   scanline's v and its distance from the axis, normalised, as u. *Decision:* every point takes
   the (u, v) of its closest point on the current model (the model's own cross-section through
   it: the paper's scanline, neither quantised in v nor assuming the cross-section perpendicular
   to the axis). Points are binned to the nearest of ``scanlines`` values of v and a side; the
   farthest point of each bin is the scanline's margin sample (the paper's ``x_{v,s}``) and maps
   to ``u = ±n / (n + 1)`` for n points in the bin (the farthest of n evenly spread samples falls
   1 / (n + 1) short of the margin on average), unless its side reaches less than
   :data:`COMPLETE` of the other side's reach: a side cut short by an occluder says nothing about
   the margin, and the mirror-symmetric model takes it from the other side. ``u >= 0`` is the
   ``+n`` side of the axis, as in :mod:`leafview.core.blade`.
5. **Weights (eq. 10).** ``x_{v,s}`` is a bin's farthest distance from the axis along its
   scanline and ``x_{v,e}`` the rest of the way to the ellipse; every point of the bin carries
   ``w_v = x_{v,s} / (x_{v,s} + x_{v,e})`` (floored at :data:`MIN_WEIGHT`). Eq. 11 weights squared
   distances, so each residual is multiplied by ``sqrt(w_v)``. The enclosing ellipse of a cloud
   with part of one side missing hugs the cut, so these weights lower a cut side only a little
   (measured: a mean of 0.72 against 0.79 on the whole side); the margin-sample rule of step 4
   does most of the occlusion handling.
6. **Solve (eq. 11).** Start: straight axis, rows at v̄ = 1/4, 1/2, 3/4 whose x̄s fit the
   ellipse's half-width, z̄ = 0. Each alternation minimises ``Σ w_v |F (L_Ω(u, v) - P(u, v))|²``
   with :func:`scipy.optimize.least_squares` ``method="lm"`` (MINPACK's Levenberg-Marquardt, the
   paper's method; unbounded, which the softmax parameterisation of v̄ allows) over Ω and the roll.
   *Decision:* F measures each residual in the point's frame (normal, across the cross-section,
   along v) with weight 1 along the normal and, for margin samples, across the cross-section, and
   :data:`TANGENTIAL` otherwise. With full tangential weight the mapping of step 4 pins the
   model's own parameterisation: the rows' v̄ cannot move and the silhouette stays where the
   ellipse put it (measured on a clean flat ovate leaf: margin off by 1.4 % of the length on
   average and 3.8 % at worst; 0.25 % and 0.8 % with this weighting). With (u, v) fixed the residuals are linear in the 63 control coordinates, so
   the 3N residuals reduce exactly to 63 before the LM runs (:func:`_reduce`).
   *Decision:* the roll about the base-apex line is solved with Ω: the SVD plane of a curved leaf
   with part of one side missing is tilted, which the mirror-symmetric model cannot absorb.
7. **Stop.** *Decision:* when the solve changes the points' residuals by less than ``tol`` (RMS,
   in lengths), or after ``max_iterations``. Ω itself is a poor measure: some of its directions
   barely move the surface where the points are (the axis where one side is unseen), and the
   alternation creeps along them by about 10⁻³ per step.
8. **Orientation.** The model is closed under swapping base and apex
   (:func:`leafview.fit.quartic.reversed_omega`), so the data cannot say which end is the base.
   *Rule:* the base is the broader end (the half of the blade next to it holds more area): right
   for ovate, lanceolate and acuminate leaves, wrong for obovate and oblanceolate ones, which come
   out reversed; elliptic leaves come out either way.
9. **Report.** Each LM solve uses at most :data:`MAX_FIT_POINTS` points (a seeded subsample);
   residuals (exact distances to the model), (u, v) and weights are computed for every point. The
   fit explains the cloud when the median residual is at most :data:`EXPLAINED_LIMIT` of the
   length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import solve_triangular
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from leafview.core.bezier import bernstein
from leafview.core.blade import grid_indices, grid_uv
from leafview.core.limits import check_name
from leafview.core.params import OMEGA_LIMIT, LeafParams, ParamError, Transform
from leafview.deform.surface import evaluate, partials
from leafview.fit import quartic as qm
from leafview.fit.blas import single_threaded
from leafview.fit.cloud_io import check_cloud
from leafview.fit.mvee import Ellipse, mvee

__all__ = ["FitResult", "fit_cloud", "surface_distance", "sample_leaf", "EXPLAINED_LIMIT", "MAX_FIT_POINTS",
           "TIP_SLAB", "COMPLETE", "TANGENTIAL", "MIN_WEIGHT", "SCANLINE_POINTS"]

EXPLAINED_LIMIT = 0.03      # median residual / length at most this: the fit explains the cloud
MAX_FIT_POINTS = 1500       # points per LM solve (a seeded subsample of larger clouds)
TIP_SLAB = 0.01             # base and apex: the points this close to each end (in lengths) place them
COMPLETE = 0.8              # a scanline side reaching less than this share of the other is cut short
TANGENTIAL = 0.1            # weight of the tangential residuals of points that are not margin samples
SCANLINE_POINTS = 30        # points per scanline at least (fewer scanlines for small clouds)
MIN_WEIGHT = 0.05           # floor of the scanline weights w_v (eq. 10)
_RIDGE = 1e-6               # pull of each control point towards its place before the solve (see _reduce)
_MAX_NFEV = 60              # residual evaluations per LM solve
_WARM_STEPS = 2             # Gauss-Newton steps of the projection from the previous alternation's (u, v)

Arr = NDArray[np.float64]


@dataclass(frozen=True)
class FitResult:
    """A fitted leaf and how well it explains its cloud.

    Attributes
    ----------
    params
        The leaf: canonical shape (base at the origin, apex at +y, length 1) and a transform with
        ``params.transform.matrix() @ evaluate(params, u, v)`` on the cloud.
    iterations
        Alternations of (LM solve, UV update).
    lm_evaluations
        Residual evaluations of all LM solves together.
    residuals
        (N,) distance of each input point to the fitted surface, in cloud units.
    uv
        (N, 2) the (u, v) of each point's closest point on the fitted leaf.
    weights
        (N,) the scanline confidence ``w_v`` (eq. 10) of each point's scanline in the final fit.
    ellipse
        The minimum-volume enclosing ellipse of the points in the plane of their SVD frame.
    length
        Base-apex distance in cloud units (the transform's scale).
    rms, median
        Of ``residuals / length``.
    explained
        ``median <= EXPLAINED_LIMIT``.
    """

    params: LeafParams
    iterations: int
    lm_evaluations: int
    residuals: Arr
    uv: Arr
    weights: Arr
    ellipse: Ellipse
    length: float
    rms: float
    median: float
    explained: bool


# -- the UV mapping P_A ---------------------------------------------------------------------------
def _groups(uv: Arr, scanlines: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(nearest scanline j, bin 2j for u >= 0 and 2j + 1 for u < 0) of each point."""
    j = np.rint(uv[:, 1] * (scanlines - 1)).astype(np.int64)
    return j, 2 * j + (uv[:, 0] < 0.0)


def _map_uv(x: Arr, q: Arr, scanlines: int, start: Arr | None = None) -> tuple[Arr, Arr, Arr, Arr]:
    """P_A (sec. 5) and the directions its residuals are measured in.

    Every point takes the (u, v) of its closest point on the current model (the model's own
    cross-section through it). The farthest point of each scanline and side is the scanline's
    margin sample (the paper's ``x_{v,s}``): it moves to ``u = ±n / (n + 1)`` (n points in the
    bin: the farthest of n evenly spread samples falls 1 / (n + 1) short of the end), unless the
    bin reaches less than :data:`COMPLETE` of the other side's reach (a side cut short by an
    occluder: it says nothing about where the margin is).

    Residuals are measured in each point's frame (normal, across the cross-section, along v):
    full weight along the normal, and across the cross-section for margin samples;
    :data:`TANGENTIAL` for the rest, whose tangential position only restates the current
    parameterisation.

    Returns (u, v) (N, 2), frames (N, 3, 3), distances to the model (N,), closest (u, v) (N, 2)."""
    if start is None:
        raw, dist, free = qm.project(x, q)
    else:                       # from the previous alternation's (u, v): a few steps, no restarts
        raw, dist, free = qm.project(x, q, start, _WARM_STEPS, cross=False)
    uv = raw.copy()
    j, group = _groups(raw, scanlines)
    size = np.abs(free)
    order = np.lexsort((size, group))
    last = np.flatnonzero(np.r_[group[order][1:] != group[order][:-1], True])
    far = order[last]                                   # the farthest point of each occupied bin
    reach = np.zeros(2 * scanlines)
    reach[group[far]] = size[far]
    count = np.bincount(group, minlength=2 * scanlines)
    other = reach[group[far] ^ 1]
    margin = far[size[far] >= COMPLETE * np.maximum(size[far], other)]
    n = count[group[margin]]
    uv[margin, 0] = np.where(raw[margin, 0] >= 0.0, 1.0, -1.0) * n / (n + 1.0)
    frames = _frames(x, uv, TANGENTIAL)
    frames[margin, 1] /= TANGENTIAL
    return uv, frames, dist, raw


def _frames(x: Arr, uv: Arr, tangential: float) -> Arr:
    """(N, 3, 3) rows: the unit normal, ``tangential`` × the unit direction across the
    cross-section (normal × along), ``tangential`` × the unit direction along v."""
    _, wu, wv = qm.weights_all(uv[:, 0], uv[:, 1])
    c = qm.controls(x)
    lu, lv = qm.mm(wu, c), qm.mm(wv, c)
    n = np.cross(lv, lu)
    size = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(size > 1e-12, n / np.maximum(size, 1e-300), qm.Z)       # pinched base and apex: the leaf's z
    along = lv - np.sum(lv * n, 1, keepdims=True) * n
    size = np.linalg.norm(along, axis=1, keepdims=True)
    along = np.where(size > 1e-12, along / np.maximum(size, 1e-300), qm.APEX)
    return np.stack([n, tangential * np.cross(n, along), tangential * along], axis=1)


def _scan_weights(q: Arr, uv: Arr, x: Arr, scanlines: int, ellipse: Ellipse, frame_from_leaf: Arr) -> Arr:
    """w_v of eq. 10 for each point: points are binned by nearest scanline and side; ``x_{v,s}``
    is the bin's largest distance from the axis along the scanline, ``x_{v,e}`` the rest of the
    way to the ellipse. Floored at :data:`MIN_WEIGHT` so that no bin drops out of the solve; 1
    where the scanline does not meet the ellipse."""
    j, group = _groups(uv, scanlines)
    sign = np.where(uv[:, 0] >= 0.0, 1.0, -1.0)
    vj = np.linspace(0.0, 1.0, scanlines)
    a, n = qm.axis(x, vj)
    dist = np.einsum("nd,nd->n", q - a[j], n[j]) * sign
    reach = np.zeros(2 * scanlines)
    np.maximum.at(reach, group, np.maximum(dist, 0.0))
    lin, shift = frame_from_leaf[:3, :3], frame_from_leaf[:3, 3]
    origins = (a @ lin.T + shift)[:, :2]
    exits = np.stack([ellipse.ray_exit(origins, (s * n @ lin.T)[:, :2]) for s in (1.0, -1.0)], axis=1).ravel()
    gap = np.maximum(exits - reach, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(np.isfinite(exits) & (reach + gap > 0.0), reach / (reach + gap), 1.0)
    return np.maximum(w, MIN_WEIGHT)[group]


# -- eq. 11 by Levenberg-Marquardt ----------------------------------------------------------------
def _roll(angle: float) -> Arr:
    """Rotation by ``angle`` about the leaf's y axis (through base and apex)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _reduce(w: Arr, q: Arr, frames: Arr, current: Arr) -> tuple[Arr, Arr]:
    """The residuals of eq. 11 with (u, v) and frames fixed are linear in the 63 control
    coordinates c' = vec(C Rᵀ): ``r_i = F_i (W_i C' - q_i)``. Their squared sum is
    ``c'ᵀ H c' - 2 gᵀ c' + const``; with ``H = L Lᵀ`` (Cholesky) the 63 numbers ``Lᵀ c' - L⁻¹ g``
    have the same sum of squares up to a constant, so the LM runs on 63 residuals instead of 3N.
    A ridge of :data:`_RIDGE` × the mean diagonal of H holds control points that no point sees
    at their ``current`` place. Returns (Lᵀ, L⁻¹ g)."""
    gram = np.matmul(frames.transpose(0, 2, 1), frames)                 # F_iᵀ F_i, (N, 3, 3)
    h = np.empty((21, 3, 21, 3))
    for d in range(3):
        for f in range(3):
            h[:, d, :, f] = qm.gram(w * gram[:, d, f, None], w)
    hm = h.reshape(63, 63)
    ridge = _RIDGE * np.trace(hm) / 63.0 + 1e-300
    g = qm.gram(w, np.einsum("nij,nj->ni", gram, q)).ravel() + ridge * current
    low = np.linalg.cholesky(hm + ridge * np.eye(63))
    return low.T, solve_triangular(low, g, lower=True)


def _solve(x: Arr, w: Arr, q: Arr, frames: Arr) -> tuple[Arr, float, int]:
    """Eq. 11 with (u, v) fixed, each point's residual measured in its (weighted) frame, over Ω'
    and a roll of the leaf about its base-apex line, by MINPACK's Levenberg-Marquardt
    (:func:`scipy.optimize.least_squares`, ``method="lm"``) on the reduced residuals of
    :func:`_reduce` with their analytic Jacobian (central differences only inside the 21×3
    control points). Returns (Ω', roll angle, residual evaluations)."""
    upper, target = _reduce(w, q, frames, qm.controls(x).ravel())
    last: dict[bytes, Arr] = {}

    def placed(p: Arr) -> Arr:             # C Rᵀ, kept for the jac call at the point fun saw last
        key = p.tobytes()
        if key not in last:
            last.clear()
            last[key] = qm.controls(p[:21]) @ _roll(p[21]).T
        return last[key]

    def fun(p: Arr) -> Arr:
        return upper @ placed(p).ravel() - target

    def jac(p: Arr) -> Arr:
        rot = _roll(p[21])
        d_rot = np.array([[-rot[0, 2], 0.0, rot[0, 0]], [0.0, 0.0, 0.0], [-rot[0, 0], 0.0, -rot[0, 2]]])
        d_ctrl = np.einsum("ij,cjk->cik", rot, qm.controls_jacobian(p[:21])).reshape(63, 21)
        d_roll = (placed(p) @ rot @ d_rot.T).reshape(63, 1)
        return upper @ np.hstack([d_ctrl, d_roll])

    res = least_squares(fun, np.append(x, 0.0), jac=jac, method="lm", max_nfev=_MAX_NFEV, xtol=1e-10, ftol=1e-10)
    return res.x[:21], float(res.x[21]), int(res.nfev)


# -- the fit ---------------------------------------------------------------------------------------
def _frame(points: Arr) -> tuple[Arr, Arr]:
    """(world_from_frame 4×4, frame coordinates (N, 3)): centred, SVD axes, right-handed."""
    centre = points.mean(axis=0)
    rel = points - centre
    _, vecs = np.linalg.eigh(qm.gram(rel, rel))             # the SVD's right singular vectors
    axes = vecs[:, ::-1].copy()                             # largest spread first, the normal last
    if np.linalg.det(axes) < 0.0:
        axes[:, 2] = -axes[:, 2]
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = axes, centre
    return m, qm.mm(rel, axes)


def _initial_placement(frame: Arr, ellipse: Ellipse) -> Arr:
    """frame_from_leaf (4×4): base and apex at the two ends of the cloud along the ellipse's major
    axis (there along the axis; across it and in height the mean of the points within
    :data:`TIP_SLAB` of the length from each end), leaf z along the plane normal, x = y × z."""
    _, vecs = ellipse.axes
    t = qm.mm(frame[:, :2], vecs[:, :1])[:, 0]
    span = float(t.max() - t.min())
    e = np.append(vecs[:, 0], 0.0)
    base = frame[t <= t.min() + TIP_SLAB * span].mean(axis=0)
    apex = frame[t >= t.max() - TIP_SLAB * span].mean(axis=0)
    base += (t.min() - base @ e) * e             # at the extreme along the axis, not the slab's mean
    apex += (t.max() - apex @ e) * e
    length = float(np.linalg.norm(apex - base))
    if not length > 1e-9 * span:
        raise ParamError("points", "the cloud has no length along its enclosing ellipse")
    ydir = (apex - base) / length
    zdir = np.array([0.0, 0.0, 1.0]) - ydir[2] * ydir
    zdir /= np.linalg.norm(zdir)
    m = np.eye(4)
    m[:3, :3] = length * np.stack([np.cross(ydir, zdir), ydir, zdir], axis=1)
    m[:3, 3] = base
    return m


def _initial_omega(ellipse: Ellipse, frame_from_leaf: Arr) -> Arr:
    """Ω' of the enclosing ellipse (sec. 5.1): straight axis, rows at v̄ = 1/4, 1/2, 3/4 (θ = 0)
    whose x̄s fit the ellipse's half-width across the base-apex line (the mean of both sides), z̄ = 0."""
    v = np.linspace(0.02, 0.98, 49)
    lin, shift = frame_from_leaf[:3, :3], frame_from_leaf[:3, 3]
    origins = (np.stack([np.zeros_like(v), v, np.zeros_like(v)], axis=1) @ lin.T + shift)[:, :2]
    side = lin[:2, 0]
    reach = [ellipse.ray_exit(origins, np.broadcast_to(s * side, origins.shape)) for s in (1.0, -1.0)]
    half = np.nan_to_num(0.5 * (reach[0] + reach[1]))
    xs = np.linalg.lstsq(bernstein(4, v)[:, 1:4], half, rcond=None)[0]
    return np.concatenate([[0.0, 1 / 3, 0.0, 0.0, 2 / 3, 0.0], np.zeros(3), xs, np.zeros(9)])


def _to_leaf(frame_from_leaf: Arr, frame: Arr) -> Arr:
    inv = np.asarray(np.linalg.inv(frame_from_leaf), dtype=np.float64)
    return qm.mm(frame, inv[:3, :3].T) + inv[:3, 3]


def _base_is_narrow(x: Arr) -> bool:
    """Whether the half of the blade next to the apex holds more area than the half next to the
    base (the orientation rule of the module docstring), from a coarse tessellation."""
    nu, nv = qm.PROJECT_GRID
    _, w_grid = qm.grid_weights(nu, nv)
    verts = w_grid @ qm.controls(x)
    tri = grid_indices(nu, nv)
    a, b, c = verts[tri[:, 0]], verts[tri[:, 1]], verts[tri[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    upper = (a[:, 1] + b[:, 1] + c[:, 1]) / 3.0 > 0.5
    return bool(area[upper].sum() > area[~upper].sum() * (1.0 + 1e-9))


def _count(field: str, value: object, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= int(value) <= hi:
        raise ParamError(field, f"expected a whole number in {lo}..{hi}, got {value!r}")
    return int(value)


@single_threaded
def fit_cloud(points: ArrayLike, *, scanlines: int = 24, max_iterations: int = 15, tol: float = 1e-4,
              name: str = "", seed: int = 0) -> FitResult:
    """Fit the paper's quartic leaf (Ω, 21 numbers) and its placement to one leaf's ``points``
    (N, 3) by the alternation of Chaurasia & Beardsley 2017, sec. 5 (see the module docstring).

    Parameters
    ----------
    points
        One leaf's points in any unit (the unit becomes the transform's scale); checked by
        :func:`leafview.fit.cloud_io.check_cloud` (ParamError for bad input).
    scanlines
        Scanlines of the UV mapping and the weights of eq. 10 (at least 4); fewer, one per
        :data:`SCANLINE_POINTS` points of the solve, when the cloud is small.
    max_iterations
        Most alternations of LM solve and UV update.
    tol
        Stop when an LM solve changes the points' residuals by less than this (RMS, in leaf
        lengths).
    name
        The leaf's name.
    seed
        Seed of the subsample used by the LM solves.
    """
    p = check_cloud(points)
    name = check_name(name)
    scanlines = _count("scanlines", scanlines, 4, 4096)
    max_iterations = _count("max_iterations", max_iterations, 1, 1000)
    if isinstance(tol, bool) or not isinstance(tol, (int, float, np.number)) or not (math.isfinite(tol) and tol > 0.0):
        raise ParamError("tol", f"{tol!r} must be a positive number")
    world_from_frame, frame = _frame(p)
    ellipse = mvee(frame[:, :2])
    placement = _initial_placement(frame, ellipse)
    x = _initial_omega(ellipse, placement)
    x0, placement0 = x.copy(), placement.copy()
    rng = np.random.default_rng(seed)
    pick = np.sort(rng.choice(len(p), MAX_FIT_POINTS, replace=False)) if len(p) > MAX_FIT_POINTS else np.arange(len(p))
    sub = frame[pick]
    scanlines = min(int(scanlines), max(4, len(sub) // SCANLINE_POINTS))
    evaluations = iterations = 0
    q = _to_leaf(placement, sub)
    uv, frames, _, raw = _map_uv(x, q, scanlines)
    for _ in range(max_iterations):
        iterations += 1
        sw = np.sqrt(_scan_weights(q, uv, x, scanlines, ellipse, placement))
        w = qm.weights(uv[:, 0], uv[:, 1])
        frames *= sw[:, None, None]
        before = np.linalg.norm(np.einsum("nij,nj->ni", frames, qm.mm(w, qm.controls(x)) - q), axis=1)
        x, roll, nfev = _solve(x, w, q, frames)
        x[6:9] = qm.theta(qm.vbar(x[6:9]))
        evaluations += nfev
        after = np.linalg.norm(np.einsum("nij,nj->ni", frames, qm.mm(w, qm.controls(x) @ _roll(roll).T) - q), axis=1)
        correction = np.eye(4)
        correction[:3, :3] = _roll(roll)
        placement = placement @ correction
        q = _to_leaf(placement, sub)
        uv, frames, _, raw = _map_uv(x, q, scanlines, raw)
        moved = float(np.sqrt(np.mean((after - before) ** 2)))
        if moved < tol:
            break
    try:
        x, placement, params = _finish(x, placement, world_from_frame, name)
    except ParamError:
        # the solve ran into a shape the model cannot draw (an axis with no in-plane direction at
        # a silhouette row, found on two stacked leaves): keep the drawable start, the enclosing
        # ellipse, and let its residuals say how little it explains
        x, placement, params = _finish(x0, placement0, world_from_frame, name)
    q_all = _to_leaf(placement, frame)
    uv_all, dist_all, _ = qm.project(x, q_all)
    weights = _scan_weights(q_all, uv_all, x, scanlines, ellipse, placement)
    length = float(params.transform.scale)
    median = float(np.median(dist_all))                    # leaf space: fractions of the length
    return FitResult(params=params, iterations=iterations, lm_evaluations=evaluations, residuals=dist_all * length,
                     uv=uv_all, weights=weights, ellipse=ellipse, length=length,
                     rms=float(np.sqrt(np.mean(dist_all * dist_all))), median=median,
                     explained=median <= EXPLAINED_LIMIT)


def _finish(x: Arr, placement: Arr, world_from_frame: Arr, name: str) -> tuple[Arr, Arr, LeafParams]:
    """The solved ``x`` as a leaf: the sign and base-end conventions of :func:`fit_cloud` applied,
    Ω clipped to its limits, placed in the cloud's frame. Raises ParamError for a shape
    :class:`LeafParams` refuses."""
    omega = qm.to_omega(x)
    if omega[9:12].sum() < 0.0:             # the same surface with the sides' names swapped
        omega[9:12] = -omega[9:12]
    if _base_is_narrow(qm.from_omega(omega)):
        omega, placement = qm.reversed_omega(omega), placement @ qm.REVERSE
    x = qm.from_omega(np.clip(omega, -OMEGA_LIMIT, OMEGA_LIMIT))
    world = world_from_frame @ placement
    params = LeafParams.from_vector(qm.to_omega(x)).replace(transform=Transform.from_matrix(world), name=name)
    return x, placement, params


# -- distances and samples -------------------------------------------------------------------------
_ADJACENT: dict[tuple[int, int], NDArray[np.int64]] = {}


def _adjacent_triangles(nu: int, nv: int) -> NDArray[np.int64]:
    """(V, 6) the triangles of :func:`grid_indices` around each grid vertex (-1 padded)."""
    key = (nu, nv)
    if key not in _ADJACENT:
        tri = grid_indices(nu, nv).astype(np.int64)
        owner = np.repeat(np.arange(len(tri)), 3)
        vert = tri.ravel()
        order = np.argsort(vert, kind="stable")
        vert, owner = vert[order], owner[order]
        slot = np.arange(len(vert)) - np.searchsorted(vert, vert)
        table = np.full((nu * nv, 6), -1, dtype=np.int64)
        table[vert, slot] = owner
        _ADJACENT[key] = table
    return _ADJACENT[key]


def closest_on_triangles(p: Arr, a: Arr, b: Arr, c: Arr) -> Arr:
    """The closest point of each triangle (a, b, c) to p, all (M, 3) (Ericson's region tests;
    degenerate triangles are safe)."""
    dot = lambda x, y: np.einsum("nd,nd->n", x, y)  # noqa: E731

    def ratio(num: Arr, den: Arr) -> Arr:
        return np.divide(num, den, out=np.zeros_like(num), where=np.abs(den) > 1e-300)

    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c
    d1, d2, d3, d4, d5, d6 = dot(ab, ap), dot(ac, ap), dot(ab, bp), dot(ac, bp), dot(ab, cp), dot(ac, cp)
    vc, vb, va = d1 * d4 - d3 * d2, d5 * d2 - d1 * d6, d3 * d6 - d5 * d4
    total = va + vb + vc
    inside = a + ab * ratio(vb, total)[:, None] + ac * ratio(vc, total)[:, None]
    cases = [
        (d1 <= 0) & (d2 <= 0), (d3 >= 0) & (d4 <= d3), (vc <= 0) & (d1 >= 0) & (d3 <= 0),
        (d6 >= 0) & (d5 <= d6), (vb <= 0) & (d2 >= 0) & (d6 <= 0),
        (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
    ]
    choices = [a, b, a + ab * ratio(d1, d1 - d3)[:, None], c, a + ac * ratio(d2, d2 - d6)[:, None],
               b + (c - b) * ratio(d4 - d3, (d4 - d3) + (d5 - d6))[:, None]]
    out = inside
    for case, choice in zip(reversed(cases), reversed(choices)):
        out = np.where(case[:, None], choice, out)
    return out


def surface_distance(points: ArrayLike, params: LeafParams, *, grid: tuple[int, int] = (65, 257),
                     neighbours: int = 3) -> Arr:
    """Distance of each world point (N, 3) to the placed leaf surface (``params.transform`` applied
    to :func:`leafview.deform.surface.evaluate`, ripples and bending included).

    The surface is tessellated on the (nu, nv) ``grid``; each point is projected onto the triangles
    around its ``neighbours`` nearest vertices (:class:`scipy.spatial.cKDTree`). With the default
    grid the error against the exact surface is about 10⁻⁴ of the leaf length (measured in the tests)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not len(p):
        return np.zeros(0)
    nu, nv = grid
    uv = grid_uv(nu, nv).astype(np.float64)
    m = params.transform.matrix()
    verts = evaluate(params, uv[:, 0], uv[:, 1]) @ m[:3, :3].T + m[:3, 3]
    k = max(1, min(int(neighbours), len(verts)))
    _, near = cKDTree(verts).query(p, k=k)
    cand = _adjacent_triangles(nu, nv)[np.asarray(near).reshape(len(p), k)].reshape(len(p), -1)
    tri = grid_indices(nu, nv).astype(np.int64)
    rows = np.repeat(np.arange(len(p)), cand.shape[1])
    flat = cand.ravel()
    valid = flat >= 0
    rows, flat = rows[valid], flat[valid]
    t = tri[flat]
    closest = closest_on_triangles(p[rows], verts[t[:, 0]], verts[t[:, 1]], verts[t[:, 2]])
    dist = np.linalg.norm(closest - p[rows], axis=1)
    out = np.full(len(p), np.inf)
    np.minimum.at(out, rows, dist)
    return out


def sample_leaf(params: LeafParams, n: int, seed: int = 0) -> tuple[Arr, Arr]:
    """``n`` points spread uniformly by area over the placed leaf (``params.transform`` applied),
    and their (u, v): cells of a 64 × 256 parameter grid are drawn in proportion to their area
    ``|∂L/∂u × ∂L/∂v| du dv`` (at the cell centre) and a point is drawn uniformly in (u, v) inside
    each. Returns ((n, 3) world points, (n, 2) (u, v))."""
    if int(n) < 1:
        raise ParamError("n", f"{n} points: at least 1")
    rng = np.random.default_rng(seed)
    nu, nv = 64, 256
    cu = (np.arange(nu) + 0.5) / nu * 2.0 - 1.0
    cv = (np.arange(nv) + 0.5) / nv
    gu, gv = np.meshgrid(cu, cv)
    d = partials(params, gu.ravel(), gv.ravel())
    area = np.linalg.norm(np.cross(d.Lu, d.Lv), axis=1)
    if not area.sum() > 0.0:
        raise ParamError("shape", "the leaf has no area to sample")
    cell = rng.choice(len(area), size=int(n), p=area / area.sum())
    u = np.clip(gu.ravel()[cell] + (rng.random(int(n)) - 0.5) * (2.0 / nu), -1.0, 1.0)
    v = np.clip(gv.ravel()[cell] + (rng.random(int(n)) - 0.5) / nv, 0.0, 1.0)
    m = params.transform.matrix()
    return evaluate(params, u, v) @ m[:3, :3].T + m[:3, 3], np.stack([u, v], axis=1)
