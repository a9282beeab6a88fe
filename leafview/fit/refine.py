"""Scale-invariant refinement of candidate leaves across the whole scene (Chaurasia & Beardsley
2017, sec. 4.2).

The *template* is an ellipse whose major/minor ratio is the median length/width ratio of the 50
most confident candidates (:func:`template`). Each candidate in turn (25 bins of confidence,
highest first; within a bin the largest first) gets the template laid along its major axis in its
plane, aligned to its points by rigid ICP (point-to-point, correspondences up to δ_plane, at most
300 iterations, :func:`icp`), and then takes the not yet claimed points of the *whole scene* (all
views merged) near the aligned template: those are the leaf's points, free of the candidate's
spurious geometry and filled in by what the other views saw (:func:`icp_refine`).

Choices where the paper leaves room, each measured on the cluttered synthetic scenes of the tests
(recall and precision of leaves, see ``tests/test_capture.py``):

* **Template size.** The template is the largest ellipse of the template's ratio inside the
  candidate's enclosing ellipse: length ``min(L, ratio · W)`` for a candidate of length L and
  width W. A well-segmented leaf gets a template of its own length; two leaves conjoined end to
  end (twice as long, one leaf wide) or side by side (one leaf long, twice as wide) get a
  template of one leaf.
* **Where ICP starts.** On the candidate's centre and, when the template is smaller than the
  candidate's ellipse, also pushed to either end of its major and minor axes; the alignment
  whose template samples find the most candidate points within δ_plane wins. A template started
  on the middle of two conjoined leaves would otherwise stay there, half on each.
* **Order.** The bins are of the candidate's confidence times its *similarity of proportions*
  to the template, ``min(r, R) / max(r, R)`` for its ratio r and the template's R (the paper
  "computes their similarity with a scale-invariant template"). A fragment of a leaf (a few
  superpixels cut off by an occluder or a failed edge) fills its own small ellipse as well as a
  whole leaf does, and processed first it would claim that fragment as a leaf.
* **Near the template** is within δ_plane of its plane and inside the template ellipse grown by
  :data:`MARGIN` · δ_plane in the plane (the paper's "within δ_plane" grows it by δ_plane, which
  lets a leaf take a strip of each coplanar neighbour, and all of a neighbour less than δ_plane
  wide; the template, an enclosing ellipse, needs little growth to hold its leaf), and connected to
  the candidate's own points through points less than about :data:`CONNECT` · δ_plane apart
  (:func:`_connected`): a leaf lying below or above within δ_plane of the plane but not touching
  the candidate is not taken with it.
* **Claimed points are not taken twice**, so a leaf seen by several views is extracted once, by
  its first candidate; the later candidates of the same leaf find their points taken. A
  candidate that lost some of its points to earlier leaves is measured again (plane, ellipse,
  confidence) on what is left before its template is placed.
* **Pieces of one leaf are merged.** When what a candidate's template takes together with the
  earlier leaf that holds most of the candidate's points still looks like one leaf (their
  enclosing ellipse covered at least :data:`MERGE_CONFIDENCE`, its ratio within a factor
  :data:`SPREAD` of the template's), it is added to that leaf rather than made a new one: the
  rest of a leaf that an earlier, smaller template did not cover.
* **What is left over.** The points of a candidate that its template did not take (the other
  leaf of a conjoined pair) form a new candidate, queued by its own confidence and size, when
  they are at least ``min_points``.

After the refinement, :func:`touching` finds the refined leaves that would join under eqs 7-8
if they were superpixels (their planes agree and their points touch), and :func:`joined` makes
one leaf of two: :func:`leafview.fit.capture.capture` uses them to put back together a leaf that
the templates of several views took in pieces.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from leafview.errors import ParamError
from leafview.fit.segment import SIGMA, THRESHOLD, Candidate, affinity, measure
from leafview.fit.views import View

__all__ = ["ScenePoints", "Refined", "template", "similarity", "ellipse_samples", "icp", "icp_refine", "touching",
           "joined", "TOP", "BINS",
           "ICP_ITERATIONS", "ICP_TARGET_POINTS", "MARGIN", "CONNECT", "MERGE_CONFIDENCE", "SPREAD", "DUPLICATE",
           "NOT_PLANE", "TOO_FEW"]

TOP = 50                   # candidates that define the template's ratio
BINS = 25                  # confidence bins of the processing order
ICP_ITERATIONS = 300
ICP_TARGET_POINTS = 1500   # a candidate's points are subsampled to at most this many for ICP
MARGIN = 0.25              # in-plane growth of the template for the extraction, in δ_plane
CONNECT = 0.25             # connection distance of a leaf's points, in δ_plane (voxels of half of it)
MERGE_CONFIDENCE = 0.85    # a piece joins an earlier leaf when their union covers its ellipse this well
SPREAD = 1.5               # ... and the union's ratio is within this factor of the template's
LEFTOVER_GENERATIONS = 3   # what a template left of a candidate is queued again at most this deep
DUPLICATE = "duplicate: its points were taken by earlier leaves"
NOT_PLANE = "what earlier leaves left of it is not a plane"
TOO_FEW = "too few points near its aligned template"
TEMPLATE_RINGS = 8         # the template's filled-ellipse sampling: rings of samples

Arr = NDArray[np.float64]
Idx = NDArray[np.int64]


class ScenePoints:
    """Every point of every view with depth, merged: ``points`` (N, 3), and for each the view
    index ``view`` and the flat pixel index ``pixel`` it came from; :meth:`index_of` maps
    (view, pixels) back to rows."""

    def __init__(self, views: Sequence[View]) -> None:
        parts, vids, pix = [], [], []
        self._lookup: list[Idx] = []
        start = 0
        for i, v in enumerate(views):
            p, flat = v.points()
            parts.append(p)
            vids.append(np.full(len(p), i, np.int64))
            pix.append(flat)
            table = np.full(v.depth.size, -1, np.int64)
            table[flat] = start + np.arange(len(p))
            self._lookup.append(table)
            start += len(p)
        self.points: Arr = np.concatenate(parts) if parts else np.zeros((0, 3))
        self.view: Idx = np.concatenate(vids) if vids else np.zeros(0, np.int64)
        self.pixel: Idx = np.concatenate(pix) if pix else np.zeros(0, np.int64)
        self.eyes: Arr = np.array([v.eye for v in views]) if views else np.zeros((0, 3))
        self._tree: cKDTree | None = None

    def __len__(self) -> int:
        return len(self.points)

    @property
    def tree(self) -> cKDTree:
        if self._tree is None:
            self._tree = cKDTree(self.points)
        return self._tree

    def index_of(self, view: int, pixels: Idx) -> Idx:
        """Rows of the points seen at ``pixels`` (flat indices) of ``view`` (-1 where none)."""
        return self._lookup[view][pixels]


@dataclass
class Refined:
    """One leaf after refinement: the scene rows it took (``indices``; ``points``, ``view`` and
    ``pixel`` of each), the aligned template (``centre``, in-plane unit ``major`` and ``minor``,
    ``normal`` towards the camera ``eye`` of the candidate's view ``source_view``, semi-axes ``a``
    and ``b``; after a merge, the enclosing ellipse of the merged points), the index of the
    candidate it came from (``candidate``; what a template left of a candidate keeps its index)
    with its ``confidence``, and how ICP went (``coverage``: the share of template samples with a
    candidate point within δ_plane; ``iterations``)."""

    indices: Idx
    points: Arr
    view: Idx
    pixel: Idx
    centre: Arr
    major: Arr
    minor: Arr
    normal: Arr
    a: float
    b: float
    eye: Arr
    source_view: int
    candidate: int
    confidence: float
    coverage: float
    iterations: int


def template(cands: Sequence[Candidate], top: int = TOP) -> float:
    """The scale-invariant template's major/minor ratio (Chaurasia & Beardsley 2017, sec. 4.2):
    the median length/width of the ``top`` most confident candidates (ties: the larger first)."""
    if not cands:
        raise ParamError("candidates", "no candidate leaves to build the template from")
    best = sorted(cands, key=lambda c: (-c.confidence, -c.area))[:max(int(top), 1)]
    ratios = [c.length / c.width for c in best if c.width > 0]
    return float(np.median(ratios)) if ratios else 1.0


def ellipse_samples(a: float, b: float, rings: int = TEMPLATE_RINGS) -> Arr:
    """Points filling the ellipse of semi-axes ``a`` (x) and ``b`` (y) about the origin, (K, 2):
    the centre and ``rings`` concentric rings, about evenly spread."""
    pts = [np.zeros((1, 2))]
    for r in range(1, rings + 1):
        t = r / rings
        n = 6 * r
        ang = (np.arange(n) + 0.5 * (r % 2)) * (2 * np.pi / n)
        pts.append(np.stack([a * t * np.cos(ang), b * t * np.sin(ang)], axis=1))
    return np.concatenate(pts)


def _kabsch(src: Arr, dst: Arr) -> tuple[Arr, Arr]:
    """The rotation R and translation t minimising ``|R src + t - dst|²``."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    h = (src - cs).T @ (dst - cd)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, cd - r @ cs


def icp(source: Arr, target_tree: cKDTree, max_distance: float, iterations: int = ICP_ITERATIONS,
        tol: float = 1e-6) -> tuple[Arr, Arr, float, int]:
    """Rigid point-to-point ICP of ``source`` (K, 3) onto the points of ``target_tree``, pairs
    farther than ``max_distance`` ignored, until the motion of a step moves no point more than
    ``tol · max_distance`` or after ``iterations`` steps. Returns ``(R, t, coverage,
    iterations)``: the motion (``R @ x + t``) and the share of moved source points with a
    target point within ``max_distance``."""
    r_tot, t_tot = np.eye(3), np.zeros(3)
    cur = source.copy()
    radius = float(np.max(np.linalg.norm(source - source.mean(axis=0), axis=1))) or 1.0
    done = 0
    while done < iterations:
        done += 1
        dist, idx = target_tree.query(cur, distance_upper_bound=max_distance)
        hit = np.isfinite(dist)
        if hit.sum() < 3:
            break
        r, t = _kabsch(cur[hit], target_tree.data[idx[hit]])
        cur = cur @ r.T + t
        r_tot, t_tot = r @ r_tot, r @ t_tot + t
        angle = math.acos(max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0)))
        if angle * radius + float(np.linalg.norm(t)) <= tol * max_distance:
            break
    dist, _ = target_tree.query(cur, distance_upper_bound=max_distance)
    return r_tot, t_tot, float(np.isfinite(dist).mean()), done


def similarity(c: Candidate, ratio: float) -> float:
    """How much candidate ``c`` looks like the template: its confidence (the share of its
    enclosing ellipse it covers) times ``min(r, R) / max(r, R)`` for its length/width ``r`` and the
    template's ratio ``R``. A fragment of a leaf can fill its own ellipse as well as a whole leaf
    does, but rarely has a leaf's proportions."""
    r = c.length / max(c.width, 1e-300)
    return c.confidence * min(r, ratio) / max(r, ratio)


def _order_key(conf: float, area: float, edges: Arr) -> tuple[int, float]:
    """Heap key: confidence bin (highest first), then size (largest first)."""
    b = int(np.clip(np.searchsorted(edges, conf, side="right") - 1, 0, len(edges) - 2))
    return -b, -area


def _place(c: Candidate, ratio: float, delta: float, target: Arr,
           iterations: int) -> tuple[Arr, Arr, Arr, Arr, float, float, float, int]:
    """The template on candidate ``c`` aligned by ICP to ``target``: (centre, major, minor, normal,
    a, b, coverage, iterations), the best-covered of the starts (see the module docstring)."""
    length = min(c.length, ratio * c.width)
    a, b = length / 2.0, length / (2.0 * ratio)
    flat = ellipse_samples(a, b)
    tree = cKDTree(target)
    shift_a, shift_b = c.length / 2.0 - a, c.width / 2.0 - b
    starts = [(0.0, 0.0)]
    if shift_a > 0.5 * delta:
        starts += [(shift_a, 0.0), (-shift_a, 0.0)]
    if shift_b > 0.5 * delta:
        starts += [(0.0, shift_b), (0.0, -shift_b)]
    best: tuple[Arr, Arr, Arr, Arr, float, float, float, int] | None = None
    for sx, sy in starts:
        centre = c.centre + sx * c.major + sy * c.minor
        src = centre + flat[:, :1] * c.major + flat[:, 1:] * c.minor
        r, t, cov, its = icp(src, tree, delta, iterations)
        if best is None or cov > best[6] + 1e-9:
            major, minor = r @ c.major, r @ c.minor
            best = (r @ centre + t, major, minor, np.cross(major, minor), a, b, cov, its)
    assert best is not None
    return best


def icp_refine(cands: Sequence[Candidate], scene: ScenePoints, *, ratio: float, delta_plane: float,
               iterations: int = ICP_ITERATIONS, bins: int = BINS, min_points: int = 60, seed: int = 0,
               skipped: list[tuple[str, Candidate]] | None = None,
               progress: Callable[[str, int, int], object] | None = None) -> list[Refined]:
    """Sec. 4.2 over all candidates of all views (see the module docstring): the leaves, in the
    order they were extracted. ``skipped`` (when given) receives ``(reason, candidate)`` for
    every candidate that yielded no leaf."""
    if not ratio >= 1.0 or not math.isfinite(ratio):
        raise ParamError("ratio", f"the template's major/minor ratio must be at least 1, got {ratio!r}")
    if not delta_plane > 0 or not math.isfinite(delta_plane):
        raise ParamError("delta_plane", f"must be a positive distance, got {delta_plane!r}")
    rng = np.random.default_rng(seed)
    conf = np.array([similarity(c, ratio) for c in cands])
    edges = np.histogram_bin_edges(conf, bins=bins) if len(conf) else np.array([0.0, 1.0])
    heap: list[tuple[int, float, int, int, Candidate, int]] = []
    for i, c in enumerate(cands):
        heapq.heappush(heap, (*_order_key(similarity(c, ratio), c.area, edges), i, i, c, 0))
    counter = len(cands)
    claimed = np.zeros(len(scene), bool)
    owner = np.full(len(scene), -1, np.int64)
    out: list[Refined] = []
    done = 0
    while heap:
        _, _, _, origin, c, generation = heapq.heappop(heap)
        done += 1
        if progress is not None:
            progress("refine", done, done + len(heap))
        own = scene.index_of(c.view, c.pixels)
        own = own[own >= 0]
        free = own[~claimed[own]]
        if len(free) < min_points:
            _note(skipped, DUPLICATE, c)
            continue
        eye = scene.eyes[c.view]
        if len(free) < len(own):
            geo = measure(scene.points[free], eye)
            if geo is None:
                _note(skipped, NOT_PLANE, c)
                continue
            n_, ce, ma, mi, ln, wd, cf = geo
            c = Candidate(c.view, scene.pixel[free], scene.points[free], n_, cf, ln, wd, ce, ma, mi, c.superpixels)
        target = scene.points[free]
        if len(target) > ICP_TARGET_POINTS:
            target = target[rng.choice(len(target), ICP_TARGET_POINTS, replace=False)]
        centre, major, minor, normal, a, b, cov, its = _place(c, ratio, delta_plane, target, iterations)
        if float(normal @ (eye - centre)) < 0:
            normal, minor = -normal, -minor
        take = _extract(scene, claimed, centre, major, minor, normal, a, b, delta_plane)
        take = _connected(scene, take, free, CONNECT * delta_plane)
        if len(take) < min_points:
            _note(skipped, TOO_FEW, c)
            continue
        holder = _holder(owner, own, len(out))
        if holder >= 0 and _merge(out[holder], take, scene, ratio):
            owner[take] = holder
            claimed[take] = True
        else:
            owner[take] = len(out)
            claimed[take] = True
            out.append(Refined(take, scene.points[take], scene.view[take], scene.pixel[take], centre, major, minor,
                               normal, a, b, eye, c.view, origin, c.confidence, cov, its))
        rest = free[~claimed[free]]
        took_own = len(free) - len(rest)
        if len(rest) >= min_points and took_own >= min_points // 2 and generation < LEFTOVER_GENERATIONS:
            geo = measure(scene.points[rest], eye)
            if geo is not None:
                n_, ce, ma, mi, ln, wd, cf = geo
                left = Candidate(c.view, scene.pixel[rest], scene.points[rest], n_, cf, ln, wd, ce, ma, mi, 0)
                heapq.heappush(heap, (*_order_key(similarity(left, ratio), left.area, edges), counter, origin, left,
                                      generation + 1))
                counter += 1
    return out


def _extract(scene: ScenePoints, claimed: NDArray[np.bool_], centre: Arr, major: Arr, minor: Arr, normal: Arr,
             a: float, b: float, delta: float) -> Idx:
    """Unclaimed scene rows within ``delta`` of the template (see the module docstring)."""
    near = np.asarray(scene.tree.query_ball_point(centre, math.hypot(a + delta, delta)), np.int64)
    if len(near) == 0:
        return near
    near = near[~claimed[near]]
    rel = scene.points[near] - centre
    x, y, z = rel @ major, rel @ minor, rel @ normal
    m = MARGIN * delta
    inside = (np.abs(z) <= delta) & ((x / (a + m)) ** 2 + (y / (b + m)) ** 2 <= 1.0)
    return np.sort(near[inside])


def _holder(owner: Idx, own: Idx, n_leaves: int) -> int:
    """The earlier leaf holding most of a candidate's own points (-1: none holds any)."""
    held = owner[own]
    held = held[held >= 0]
    if len(held) == 0:
        return -1
    return int(np.argmax(np.bincount(held, minlength=n_leaves)))


def _merge(leaf: Refined, take: Idx, scene: ScenePoints, ratio: float) -> bool:
    """Add ``take`` to ``leaf`` when the two together still look like one leaf: their points'
    enclosing ellipse is covered at least :data:`MERGE_CONFIDENCE` and its ratio within
    :data:`SPREAD` of the template's. Updates ``leaf`` in place; True when merged."""
    union = np.concatenate([leaf.indices, take])
    geo = measure(scene.points[union], leaf.eye)
    if geo is None:
        return False
    normal, centre, major, minor, length, width, conf = geo
    if conf < MERGE_CONFIDENCE or not ratio / SPREAD <= length / max(width, 1e-300) <= ratio * SPREAD:
        return False
    union = np.sort(union)
    leaf.indices, leaf.points, leaf.view, leaf.pixel = union, scene.points[union], scene.view[union], scene.pixel[union]
    leaf.centre, leaf.major, leaf.minor, leaf.normal = centre, major, minor, normal
    leaf.a, leaf.b = length / 2.0, width / 2.0
    return True


def _connected(scene: ScenePoints, take: Idx, seeds: Idx, radius: float) -> Idx:
    """The rows of ``take`` connected to the candidate's own points ``seeds`` through occupied
    voxels of side ``radius / 2`` that touch (26-neighbourhood: points of touching voxels are at
    most 1.7 ``radius`` apart): the components holding at least a fifth as many seeds as the best
    one."""
    if len(take) == 0:
        return take
    cell = np.floor(scene.points[take] / (0.5 * radius)).astype(np.int64)
    cell -= cell.min(axis=0)
    dims = cell.max(axis=0) + 3
    key = ((cell[:, 0] + 1) * dims[1] + cell[:, 1] + 1) * dims[2] + cell[:, 2] + 1
    voxels, which = np.unique(key, return_inverse=True)
    rows, cols = [], []
    for dx, dy, dz in _HALF_NEIGHBOURS:
        other = voxels + (dx * dims[1] + dy) * dims[2] + dz
        pos = np.minimum(np.searchsorted(voxels, other), len(voxels) - 1)
        hit = voxels[pos] == other
        rows.append(np.flatnonzero(hit))
        cols.append(pos[hit])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r)), (r, c)), shape=(len(voxels), len(voxels)))
    _, comp_v = connected_components(graph, directed=False)
    comp = comp_v[which]
    is_seed = np.isin(take, seeds, assume_unique=True)
    counts = np.bincount(comp[is_seed], minlength=int(comp.max()) + 1)
    if counts.max() == 0:
        return take[:0]
    keep = counts >= max(0.2 * counts.max(), 1)
    return take[keep[comp]]


_HALF_NEIGHBOURS = [(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
                    if (dx, dy, dz) > (0, 0, 0)]


def _note(skipped: list[tuple[str, Candidate]] | None, reason: str, c: Candidate) -> None:
    if skipped is not None:
        skipped.append((reason, c))


def touching(leaves: Sequence[Refined | None], delta_plane: float, among: Collection[int],
             changed: Collection[int] | None = None) -> list[tuple[int, int]]:
    """Pairs ``(i, j)``, ``i < j``, of the leaves indexed by ``among`` (None entries skipped) that
    eqs 7-8 would join were they two superpixels: ``d_n = 1 - |n̂_i · n̂_j|`` of their planes (the
    normals may face different cameras, hence the absolute value) and ``d_p`` the smallest
    distance between a point of one and a point of the other over ``delta_plane``, with affinity
    at least :data:`~leafview.fit.segment.THRESHOLD`. With ``changed``, only pairs holding at least
    one of those leaves (the others were looked at before)."""
    got: dict[int, Refined] = {}
    for k in sorted(set(among)):
        r = leaves[k]
        if r is not None:
            got[k] = r
    reach = delta_plane * math.sqrt(-2.0 * SIGMA * SIGMA * math.log(THRESHOLD))    # d_p beyond this cannot join
    radius = {k: float(np.max(np.linalg.norm(r.points - r.centre, axis=1))) for k, r in got.items()}
    trees: dict[int, cKDTree] = {}
    fresh = None if changed is None else set(changed)
    keys = list(got)
    out = []
    for a, i in enumerate(keys):
        for j in keys[a + 1:]:
            if fresh is not None and i not in fresh and j not in fresh:
                continue
            ri, rj = got[i], got[j]
            if float(np.linalg.norm(ri.centre - rj.centre)) > radius[i] + radius[j] + reach:
                continue
            d_n = 1.0 - abs(float(ri.normal @ rj.normal))
            if float(affinity(d_n, 0.0)) < THRESHOLD:
                continue
            big, small = (j, i) if len(ri.points) <= len(rj.points) else (i, j)
            if big not in trees:
                trees[big] = cKDTree(got[big].points)
            dist, _ = trees[big].query(got[small].points, distance_upper_bound=reach)
            gap = float(dist.min())
            if math.isfinite(gap) and float(affinity(d_n, gap / delta_plane)) >= THRESHOLD:
                out.append((i, j))
    return out


def joined(a: Refined, b: Refined) -> Refined | None:
    """One leaf of the points of ``a`` and ``b`` (disjoint scene rows): its plane and enclosing
    ellipse measured again (:func:`leafview.fit.segment.measure`; ``confidence`` is the union's
    coverage of it), and the camera, view and candidate of the one with more points. None when the
    union spans no plane."""
    big = a if len(a.indices) >= len(b.indices) else b
    rows = np.concatenate([a.indices, b.indices])
    order = np.argsort(rows, kind="stable")
    points = np.concatenate([a.points, b.points])[order]
    geo = measure(points, big.eye)
    if geo is None:
        return None
    normal, centre, major, minor, length, width, conf = geo
    return Refined(rows[order], points, np.concatenate([a.view, b.view])[order],
                   np.concatenate([a.pixel, b.pixel])[order], centre, major, minor, normal, length / 2.0, width / 2.0,
                   big.eye, big.source_view, big.candidate, conf, big.coverage, big.iterations)
