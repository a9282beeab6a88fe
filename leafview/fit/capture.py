"""Dense foliage from RGB-D views to an editable leaf set (Chaurasia & Beardsley 2017, secs 4-5).

:func:`capture` runs the whole pipeline:

1. **Candidates** from each view on its own (sec. 4.1, eqs 7-8): superpixels, a RANSAC plane per
   superpixel, the affinity graph and its connected components, each scored by the share of its
   enclosing ellipse it covers (:mod:`leafview.fit.segment`).
2. **Refinement** across the whole scene (sec. 4.2): the scale-invariant template ellipse aligned
   to each candidate by ICP, taking the scene's points near it (:mod:`leafview.fit.refine`).
3. **Fitting** Ω and a placement to each leaf's points (sec. 5, eqs 9-11,
   :func:`leafview.fit.cloud.fit_cloud`). A leaf whose fit does not explain its points, or with
   fewer than ``min_points`` points, is reported in :attr:`CaptureResult.rejected` with the
   reason, never silently kept; leaves that are pieces of one leaf are then joined (see below).
   In a capture a leaf is *explained* when its median distance to the fit is at most
   :data:`CAPTURE_LIMIT` (1.2 %) of its length plus the estimated depth noise (:func:`depth_noise`;
   points scattered by the sensor lie off any surface by about 0.67 σ). That is stricter than a
   single cloud's 3 % (:data:`~leafview.fit.cloud.EXPLAINED_LIMIT`): a capture's pieces of two
   leaves or of a leaf and its neighbour's edge fit to 1.3-3.3 %, its true leaves to 0.28 %
   (median; 95th percentile 0.7 %), measured on 8 views of a 200-leaf plant.

Choices, each tested:

* **δ_plane by default.** The paper uses 2 cm for plants a metre or so from a Kinect, about
  twelve times the footprint of a pixel there. Scenes here come in any unit, so the default is
  :data:`DELTA_FACTOR` times the median pixel footprint (depth over focal length) of all depth
  pixels of all views. Eq. 8 needs it about that large: two adjacent superpixels of one leaf are
  one footprint apart, and with σ = 0.2 they join (affinity 0.85) only while that gap is below
  0.114 δ_plane. Noisy depth needs more: RANSAC must keep a superpixel's points within δ_plane
  of its plane, and a noisy superpixel's normal wanders, so δ_plane is at least
  :data:`NOISE_FACTOR` times the depth noise estimated from the views (:func:`depth_noise`; the
  paper's 2 cm is 7-10 times a Kinect's noise at a metre). On the synthetic scenes with noise of
  1.8 footprints (2.7 % of a leaf's length) this raised precision from 0.59 to 0.87.
* **Which side is up.** A point cloud does not say which face of a leaf is its upper side; each
  captured leaf is turned (:func:`face_camera`) so that its upper side (+z of leaf space, the side
  :func:`leafview.deform.surface.normals` points to) faces the camera of the view whose candidate
  it came from, as the side a camera sees of a leaf it photographs is usually the upper one.
* **Size.** A plant's leaves differ in size by tens of per cent, not by factors: a refined leaf
  whose template is shorter than 0.45 or longer than 1.8 times the median of all refined leaves
  (:data:`SIZE_RANGE`) is a fragment left over by an earlier leaf or several leaves joined in one
  plane, and is reported as such instead of fitted. On the 200-leaf plant of ``leafview bench
  capture`` this raised precision from 0.59 to 0.70 (see docs/capture.md).
* **Colour** (``leaf_colour="green"``, the default). Stems and bark give flat, plane-like pieces
  too, and a leaf's template otherwise takes in the stem at its base. Pixels whose green is not
  the largest of their three channels are left out of everything (their depth is ignored):
  on the 8 views of the benchmark plant this keeps 99.9 % of leaf pixels and 11-13 % of stem
  pixels (excess green, 2G - R - B > 0, kept 97 % of the brown stems). ``leaf_colour=None``
  keeps every pixel, for autumn leaves.
* **Pieces of one leaf are joined.** The refinement claims each scene point once, so a leaf whose
  first template did not cover all of it (a view saw only part of it) comes out in pieces, each
  fitted as a leaf: on the 200-leaf plant of ``leafview bench capture`` most captured leaves that
  matched no truth leaf were such pieces, of leaves captured whole or of none. Two kept leaves
  (or fragments) are tried as one when eqs 7-8 would join them were they superpixels (their
  planes agree and their points touch, :func:`leafview.fit.refine.touching`) and their union is
  no longer than the size rule allows with the template's proportions; the union is fitted, and
  it is one leaf when its fit is explained and its median distance is at most
  :data:`JOIN_RATIO` (1.25) times that of the pieces' own fits (weighted by their points).
  Measured on two benchmark plants (seeds 7 and 11): unions of pieces of one leaf 0.75-1.12, of
  two neighbouring leaves 1.37-1.62. A limit from the depth noise σ alone does not separate them:
  a single leaf's median distance runs from 0.3 σ to 0.7 σ with the angle between its normal and
  the views, a wrongly joined pair's from 1.0 σ to 1.4 σ. Joins are taken the cheapest first, in
  rounds, so a leaf in three pieces is put together in two; the later piece is reported as
  :data:`JOINED`. On those plants this raised precision from 0.85 to 0.96 and 0.95, and recall
  from 0.845 to 0.88 and from 0.835 to 0.86 (leaves no piece of which matched are now found).
* **Fitting in parallel.** The fits (sec. 5) are independent: with more than 16 leaves per CPU
  they run in spawned worker processes (``workers``), each with one BLAS thread; the leaves come
  out the same, in the same order.
* **Material.** Each leaf's front material is the median colour of its pixels (sRGB decoded to
  linear), the back a lighter shade of it.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from multiprocessing import get_context
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.core.colour import srgb_to_linear
from leafview.core.params import LeafParams, Material, Shape, Transform
from leafview.deform.surface import normals
from leafview.errors import ParamError
from leafview.fit.blas import single_threaded
from leafview.fit.cloud import FitResult, fit_cloud
from leafview.fit.refine import SPREAD, Refined, ScenePoints, icp_refine, joined, template, touching
from leafview.fit.segment import Candidate, segment_view
from leafview.fit.views import View, check_views

__all__ = ["CaptureResult", "capture", "default_delta", "depth_noise", "face_camera", "NOISE_FACTOR", "DELTA_FACTOR",
           "FIT_POINTS", "CAPTURE_LIMIT", "FIT_FAILED", "UNEXPLAINED", "FRAGMENT", "CONJOINED", "SIZE_RANGE", "JOINED",
           "JOIN_RATIO", "JOIN_ROUNDS", "leaf_coloured"]

FIT_FAILED = "the fit failed"
UNEXPLAINED = "the fit cannot explain its points"
DELTA_FACTOR = 12.0     # default δ_plane in median pixel footprints
NOISE_FACTOR = 8.0      # ... or in estimated depth noise (standard deviation), when that is larger
CAPTURE_LIMIT = 0.012   # a captured leaf's median distance to its fit, in lengths (plus the depth noise)
FIT_POINTS = 1500       # a leaf's points are subsampled to at most this many for the fit
FRAGMENT = "a fragment: much shorter than the scene's typical leaf"
CONJOINED = "conjoined: much longer than the scene's typical leaf"
PARALLEL_MIN_PER_WORKER = 16   # leaves per worker process below which the fits run in this process
SIZE_RANGE = (0.45, 1.8)   # kept leaves' template lengths, relative to the median of all refined leaves
JOINED = "a piece of an earlier leaf: joined to it"
JOIN_RATIO = 1.25          # a union's median distance to its fit over its pieces': at most this for one leaf
JOIN_ROUNDS = 3            # rounds of joining pieces (a leaf in three or four pieces needs two or three)

Progress = Callable[[str, int, int], object]


@dataclass
class CaptureResult:
    """What :func:`capture` found.

    ``leaves`` are the retained leaves (``leaf_000``, ``leaf_001``, ...) and ``fits`` their fits;
    ``points_of[i]`` is ``(view indices, flat pixel indices)`` of the points leaf ``i`` was fitted
    to; ``rejected`` lists ``(reason, info)`` for every candidate or leaf that was not kept
    (``info``: its view, number of points, centre, confidence); ``candidates`` are all candidates
    of all views; ``timings`` the seconds spent in each stage (``segment``, ``refine``, ``fit``,
    ``total``); ``delta_plane`` the δ_plane used, ``ratio`` the template's major/minor ratio,
    ``refined`` the refined point sets of the kept leaves and ``noise`` the estimated depth noise
    (:func:`depth_noise`)."""

    leaves: list[LeafParams]
    fits: list[FitResult]
    rejected: list[tuple[str, dict[str, Any]]]
    candidates: list[Candidate]
    points_of: list[tuple[NDArray[np.int64], NDArray[np.int64]]]
    timings: dict[str, float]
    delta_plane: float
    ratio: float = 1.0
    refined: list[Refined] = field(default_factory=list, repr=False)
    noise: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready summary: δ_plane, the template's ratio, timings, per leaf its name, points,
        views and fit (median distance in lengths, iterations), every rejection with its reason,
        and the candidates (view, points, confidence, length, width)."""
        leaves = []
        for leaf, fit, (vi, _) in zip(self.leaves, self.fits, self.points_of, strict=True):
            leaves.append({"name": leaf.name, "points": int(len(vi)), "views": sorted(int(v) for v in np.unique(vi)),
                           "median": round(float(fit.median), 6), "iterations": int(fit.iterations)})
        return {"delta_plane": self.delta_plane, "template_ratio": round(self.ratio, 6), "depth_noise": self.noise,
                "timings": {k: round(v, 3) for k, v in self.timings.items()},
                "counts": {"candidates": len(self.candidates), "leaves": len(self.leaves),
                           "rejected": len(self.rejected)},
                "leaves": leaves,
                "rejected": [{"reason": reason, **info} for reason, info in self.rejected],
                "candidates": [_info(c) | {"width": round(float(c.width), 6)} for c in self.candidates]}


def depth_noise(views: Sequence[View]) -> float:
    """The depth noise of ``views`` (a standard deviation along the optical axis, in world units),
    estimated from second differences of depth along rows and columns, ``z[i-1] - 2 z[i] + z[i+1]``
    over three pixels that all have depth: for a smooth surface they are nearly 0, for
    independent noise of deviation σ their deviation is σ√6. Robust: σ = 1.4826 · median |Δ²z| /
    √6, so the steps at the edges of leaves (fewer than half the triples) do not count. 0 for
    noiseless depth."""
    found: list[NDArray[np.float64]] = []
    for v in views:
        d = v.depth.astype(np.float64)
        for a, b, c in ((d[:, :-2], d[:, 1:-1], d[:, 2:]), (d[:-2], d[1:-1], d[2:])):
            ok = (a > 0) & (b > 0) & (c > 0)
            found.append(np.abs(a[ok] - 2.0 * b[ok] + c[ok]))
    diffs = np.concatenate(found) if found else np.zeros(0)
    return 1.4826 * float(np.median(diffs)) / math.sqrt(6.0) if len(diffs) else 0.0


def default_delta(views: Sequence[View], factor: float = DELTA_FACTOR, noise_factor: float = NOISE_FACTOR) -> float:
    """The default δ_plane (see the module docstring): ``factor`` times the median pixel footprint
    (depth / √(fx fy)) over every depth pixel of ``views``, or ``noise_factor`` times their
    :func:`depth_noise` when that is larger."""
    feet = [v.depth[v.depth > 0].astype(np.float64) / math.sqrt(v.k[0, 0] * v.k[1, 1]) for v in views]
    allf = np.concatenate(feet) if feet else np.zeros(0)
    if not len(allf):
        raise ParamError("views", "no view has any depth: nothing to capture")
    return max(factor * float(np.median(allf)), noise_factor * depth_noise(views))


def face_camera(leaf: LeafParams, eye: NDArray[np.float64]) -> LeafParams:
    """``leaf`` with its upper side facing ``eye``: unchanged when the upper normal at the blade's
    middle already points towards the eye, else the same surface turned over. Turning over is a
    half turn about the midrib: x and z of the axis controls and the z̄ offsets are negated
    (and the drawn half swapped) while the placement gains the same half turn, so every point of
    the surface stays where it was and the normals reverse."""
    m = leaf.transform.matrix()
    mid = np.array([0.0, 0.5, 0.0])
    n = normals(leaf, [0.0], [0.5])[0] @ m[:3, :3].T
    if float(n @ (eye - (m[:3, :3] @ mid + m[:3, 3]))) >= 0.0:
        return leaf
    s = leaf.shape

    def neg(p: tuple[float, float, float]) -> tuple[float, float, float]:
        return (-p[0], p[1], -p[2])

    shape = Shape(a1=neg(s.a1), a2=neg(s.a2), silhouette=tuple((r[0], r[1], -r[2]) for r in s.silhouette),
                  zf=tuple(-z for z in s.zf), zg=tuple(-z for z in s.zg), tilt=s.tilt, half=-s.half)
    turned = Transform.from_matrix(m @ np.diag([-1.0, 1.0, -1.0, 1.0]))
    return replace(leaf, shape=shape, transform=turned)


def _size_info(r: Refined, typical: float) -> dict[str, Any]:
    return {"view": r.source_view, "points": int(len(r.points)), "length": round(2.0 * r.a, 6),
            "relative_length": round(2.0 * r.a / typical, 3)}


def _info(c: Candidate) -> dict[str, Any]:
    return {"view": c.view, "points": int(len(c.points)), "centre": [round(float(x), 6) for x in c.centre],
            "confidence": round(float(c.confidence), 4), "length": round(float(c.length), 6)}


def _median_colour(views: Sequence[View], r: Refined) -> NDArray[np.float64]:
    """The median sRGB colour (0-255) of the pixels a refined leaf's points came from."""
    cols = np.concatenate([views[v].color.reshape(-1, 3)[r.pixel[r.view == v]] for v in np.unique(r.view)])
    return np.median(cols, axis=0).astype(np.float64)


def leaf_coloured(view: View) -> View:
    """``view`` with the depth of every pixel whose green is not its largest channel set to 0
    (no data): what ``leaf_colour="green"`` captures from."""
    c = view.color.astype(np.int16)
    green = (c[..., 1] > c[..., 0]) & (c[..., 1] > c[..., 2])
    return replace(view, depth=np.where(green, view.depth, np.float32(0.0)).astype(np.float32))


def _fit_one(job: tuple[int, NDArray[np.float64], int]) -> FitResult | str:
    k, pts, seed = job
    try:
        return fit_cloud(pts, name=f"refined_{k}", seed=seed)
    except ParamError as exc:
        return str(exc)


class _Fitter:
    """:func:`fit_cloud` of batches of jobs, each batch's results in order: in this process, or in
    ``workers`` spawned processes when the capture has enough leaves (``expected``) to pay for
    starting them (a fit takes 0.1-0.5 s, a process about 2 s to import numpy, scipy and leafview).
    The processes start with the first batch and serve every later one. ``progress(stage, done,
    total)`` counts each stage's fits."""

    def __init__(self, workers: int | None, expected: int, progress: Progress | None) -> None:
        n = min(os.cpu_count() or 1, 8) if workers is None else int(workers)
        if n < 1:
            raise ParamError("workers", f"must be at least 1, got {workers}")
        self._n = n if n > 1 and expected >= PARALLEL_MIN_PER_WORKER * n else 1
        self._pool: ProcessPoolExecutor | None = None
        self._progress = progress
        self._done: dict[str, int] = {}

    def __enter__(self) -> _Fitter:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def map(self, jobs: list[tuple[int, NDArray[np.float64], int]], stage: str = "fit") -> list[FitResult | str]:
        if self._n > 1 and self._pool is None and jobs:
            self._pool = ProcessPoolExecutor(max_workers=self._n, mp_context=get_context("spawn"))
        results = (map(_fit_one, jobs) if self._pool is None
                   else self._pool.map(_fit_one, jobs, chunksize=max(1, min(4, len(jobs) // (2 * self._n)))))
        start = self._done.get(stage, 0)
        out: list[FitResult | str] = []
        for result in results:
            out.append(result)
            self._done[stage] = start + len(out)
            if self._progress is not None:
                self._progress(stage, start + len(out), start + len(jobs))
        return out


def _subsample(points: NDArray[np.float64], seed: int, k: int) -> NDArray[np.float64]:
    """At most :data:`FIT_POINTS` of ``points``, drawn without replacement (seeded by ``seed``
    and the leaf's index ``k``), in their order."""
    if len(points) <= FIT_POINTS:
        return points
    pick = np.random.default_rng([seed, k]).choice(len(points), FIT_POINTS, replace=False)
    return points[np.sort(pick)]


def _join_pieces(pieces: list[Refined | None], fitted: dict[int, FitResult], fitter: _Fitter, *, typical: float,
                 ratio: float, delta: float, noise: float, seed: int, fragments: set[int],
                 rejected: list[tuple[str, dict[str, Any]]]) -> None:
    """Put together the leaves that the refinement took in pieces (see the module docstring).

    The pieces are the explained fits in ``fitted`` and the ``fragments`` (not fitted yet). In
    rounds (at most :data:`JOIN_ROUNDS`), the pairs of them that eqs 7-8 would join
    (:func:`leafview.fit.refine.touching`) and whose union (:func:`leafview.fit.refine.joined`) is
    no longer than :data:`SIZE_RANGE` allows and has the template's proportions (within
    :data:`~leafview.fit.refine.SPREAD`) are fitted as one leaf, with the fragments among them.
    A union is one leaf when its fit is explained (:func:`_explained`) and its median distance is
    at most :data:`JOIN_RATIO` times its pieces' (:func:`_join_cost`). Those are taken, the
    cheapest first and each piece once a round: the union replaces the earlier piece (its fit goes
    in ``fitted``) and the later one is reported as :data:`JOINED`. The next round looks only at
    pairs holding a new union."""
    if not typical > 0.0:
        return
    hi = SIZE_RANGE[1] * typical
    among = {k for k, fit in fitted.items() if _explained(fit, noise)} | set(fragments)
    changed: set[int] | None = None
    for _ in range(JOIN_ROUNDS):
        trials: list[tuple[int, int, Refined]] = []
        for i, j in touching(pieces, delta, among, changed):
            a, b = pieces[i], pieces[j]
            assert a is not None and b is not None
            u = joined(a, b)
            if u is not None and 2.0 * u.a <= hi and ratio / SPREAD <= u.a / max(u.b, 1e-300) <= ratio * SPREAD:
                trials.append((i, j, u))
        if not trials:
            return
        alone = sorted({k for i, j, _ in trials for k in (i, j) if k not in fitted})
        jobs = [(k, _subsample(_piece(pieces, k).points, seed, k), seed + k) for k in alone]
        jobs += [(i, _subsample(u.points, seed, i), seed + i) for i, _, u in trials]
        outcomes = fitter.map(jobs, stage="join")
        for k, outcome in zip(alone, outcomes[:len(alone)], strict=True):
            if isinstance(outcome, str) or not _explained(outcome, noise):
                among.discard(k)         # a fragment without a leaf's fit joins nothing
            else:
                fitted[k] = outcome
        good = []
        for (i, j, u), fit in zip(trials, outcomes[len(alone):], strict=True):
            if i in among and j in among and not isinstance(fit, str) and _explained(fit, noise):
                cost = _join_cost(fit, (fitted[i], len(_piece(pieces, i).points)),
                                  (fitted[j], len(_piece(pieces, j).points)))
                if cost <= JOIN_RATIO:
                    good.append((cost, i, j, u, fit))
        changed = set()
        for cost, i, j, u, fit in sorted(good, key=lambda g: (g[0], g[1], g[2])):
            gone = pieces[j]
            if i in changed or j in changed or pieces[i] is None or gone is None:
                continue
            rejected.append((JOINED, {"view": gone.source_view, "points": int(len(gone.points)),
                                      "centre": [round(float(x), 6) for x in gone.centre],
                                      "length": round(2.0 * gone.a, 6), "joined_to": int(i),
                                      "cost": round(float(cost), 3)}))
            pieces[i], pieces[j] = u, None
            fitted[i] = fit
            fitted.pop(j, None)
            among.discard(j)
            changed.add(i)
        if not changed:
            return


def _piece(pieces: list[Refined | None], k: int) -> Refined:
    r = pieces[k]
    assert r is not None
    return r


def _explained(fit: FitResult, noise: float) -> bool:
    """Whether a captured leaf's fit explains its points: median distance at most
    :data:`CAPTURE_LIMIT` of its length plus the depth ``noise``."""
    return bool(fit.median * fit.length <= CAPTURE_LIMIT * fit.length + noise)


def _join_cost(union: FitResult, *pieces: tuple[FitResult, int]) -> float:
    """A union's median distance to its fit over its pieces' (each piece's median distance to its
    own fit, weighted by its number of points): about 1 when one surface explains the union as
    well as two explained the pieces."""
    total = sum(n for _, n in pieces)
    before = sum(fit.median * fit.length * n for fit, n in pieces) / max(total, 1)
    after = union.median * union.length
    return float(after / before) if before > 0.0 else (1.0 if after <= 0.0 else math.inf)


def _material(views: Sequence[View], r: Refined) -> Material:
    srgb = _median_colour(views, r) / 255.0
    lin = srgb_to_linear(srgb)
    f = np.clip(lin, 0.0, 1.0)
    b = np.clip(lin * 1.6 + 0.02, 0.0, 1.0)
    return Material(front=(float(f[0]), float(f[1]), float(f[2])), back=(float(b[0]), float(b[1]), float(b[2])))


@single_threaded
def capture(views: Sequence[View], *, delta_plane: float | None = None, n_segments: int | None = None,
            min_points: int = 60, progress: Progress | None = None, seed: int = 0,
            leaf_colour: str | None = "green", workers: int | None = None) -> CaptureResult:
    """The leaves of ``views`` (see the module docstring). ``delta_plane`` overrides the default
    (:func:`default_delta`), ``n_segments`` the superpixels per view (default
    :func:`leafview.fit.segment.default_segments`); ``progress(stage, done, total)`` is called as
    the work advances (stages ``segment``, ``refine``, ``fit`` and, when pieces of a leaf are tried
    as one, ``join``). ``leaf_colour``: "green" uses only the pixels whose green is their largest
    channel (:func:`leaf_coloured`); None uses every pixel. ``workers``: processes that fit leaves
    side by side (default: the CPUs, at most 8; 1 fits in this process); the result does not depend
    on it."""
    if leaf_colour not in ("green", None):
        raise ParamError("leaf_colour", f"expected 'green' or None, got {leaf_colour!r}")
    check_views(views)
    if not any(bool((v.depth > 0).any()) for v in views):
        raise ParamError("views", "no view has any depth: nothing to capture")
    if leaf_colour == "green":
        views = [leaf_coloured(v) for v in views]
        if not any(bool((v.depth > 0).any()) for v in views):
            raise ParamError("views", "no pixel with depth is leaf-coloured (green its largest channel); "
                                      "capture every colour with leaf_colour=None (leafview capture --any-colour)")
    t0 = time.perf_counter()
    if min_points < 4:
        raise ParamError("min_points", f"must be at least 4, got {min_points}")
    delta = default_delta(views) if delta_plane is None else float(delta_plane)
    if not (delta > 0 and math.isfinite(delta)):
        raise ParamError("delta_plane", f"must be a positive distance, got {delta_plane!r}")
    timings: dict[str, float] = {}
    cands: list[Candidate] = []
    for i, v in enumerate(views):
        cands += segment_view(v, i, delta_plane=delta, n_segments=n_segments, min_points=min_points,
                              seed=seed).candidates
        if progress is not None:
            progress("segment", i + 1, len(views))
    t1 = time.perf_counter()
    timings["segment"] = t1 - t0
    rejected: list[tuple[str, dict[str, Any]]] = []
    if not cands:
        timings.update(refine=0.0, fit=0.0, total=t1 - t0)
        return CaptureResult([], [], [], [], [], timings, delta)
    ratio = template(cands)
    scene = ScenePoints(views)
    skipped: list[tuple[str, Candidate]] = []
    refined = icp_refine(cands, scene, ratio=ratio, delta_plane=delta, min_points=min_points, seed=seed,
                         skipped=skipped, progress=progress)
    rejected += [(reason, _info(c)) for reason, c in skipped]
    t2 = time.perf_counter()
    timings["refine"] = t2 - t1
    noise = depth_noise(views)
    leaves: list[LeafParams] = []
    fits: list[FitResult] = []
    points_of: list[tuple[NDArray[np.int64], NDArray[np.int64]]] = []
    kept: list[Refined] = []
    typical = float(np.median([2.0 * r.a for r in refined])) if refined else 0.0
    pieces: list[Refined | None] = list(refined)
    fitted: dict[int, FitResult] = {}
    failed: dict[int, str] = {}
    fragments: set[int] = set()
    lo, hi = SIZE_RANGE[0] * typical, SIZE_RANGE[1] * typical
    jobs: list[tuple[int, NDArray[np.float64], int]] = []
    for k, r in enumerate(refined):
        if typical > 0.0 and 2.0 * r.a > hi:
            rejected.append((CONJOINED, _size_info(r, typical)))
        elif typical > 0.0 and 2.0 * r.a < lo:
            fragments.add(k)     # fitted only when it is tried as part of a leaf
        else:
            jobs.append((k, _subsample(r.points, seed, k), seed + k))
    with _Fitter(workers, len(jobs), progress) as fitter:
        for (k, _, _), outcome in zip(jobs, fitter.map(jobs), strict=True):
            if isinstance(outcome, str):
                failed[k] = outcome
            else:
                fitted[k] = outcome
        _join_pieces(pieces, fitted, fitter, typical=typical, ratio=ratio, delta=delta, noise=noise, seed=seed,
                     fragments=fragments, rejected=rejected)
    for k, piece in enumerate(pieces):
        if piece is None or k not in fitted and k not in failed and k not in fragments:
            continue
        if typical > 0.0 and 2.0 * piece.a < lo:
            rejected.append((FRAGMENT, _size_info(piece, typical)))
            continue
        info = {"view": piece.source_view, "points": int(len(piece.points)),
                "centre": [round(float(x), 6) for x in piece.centre], "confidence": round(float(piece.confidence), 4),
                "length": round(2.0 * piece.a, 6)}
        if k in failed or k not in fitted:
            rejected.append((FIT_FAILED, {**info, "detail": failed.get(k, "no fit")}))
            continue
        fit = fitted[k]
        if not _explained(fit, noise):
            rejected.append((UNEXPLAINED, {**info, "median": round(float(fit.median), 6),
                                           "detail": f"median distance {100 * fit.median:.1f} % of its length"}))
            continue
        leaf = face_camera(fit.params, piece.eye)
        leaf = replace(leaf, name=f"leaf_{len(leaves):03d}", material=_material(views, piece))
        leaves.append(leaf)
        fits.append(fit)
        points_of.append((piece.view.copy(), piece.pixel.copy()))
        kept.append(piece)
    t3 = time.perf_counter()
    timings.update(fit=t3 - t2, total=t3 - t0)
    return CaptureResult(leaves, fits, rejected, cands, points_of, timings, delta, ratio, kept, noise)
