"""A captured leaf set scored against the truth its RGB-D views were rendered from.

Chaurasia & Beardsley 2017 (sec. 8) leave "quantitative evaluation using synthetically generated
foliage" to future work; this module is that evaluation. The truth is a leaf set placed in world
coordinates; views of it were rendered (colour, depth and a truth *instance* image: leaf index + 1
per pixel, 0 for the background); the capture pipeline fitted a leaf set to the views; the
captured leaves are rendered again from the same cameras to give *predicted* instance images.

* :func:`visibility`: the fraction of each truth leaf's surface seen in at least one view.
* :func:`match_leaves`: one-to-one truth/captured pairs by mask IoU in the best view.
* :func:`chamfer` and :func:`leaf_measures`: the geometric errors of a matched pair.
* :func:`evaluate_capture`: all of it, with precision, recall and the errors binned by visibility
  (:data:`VISIBILITY_BINS`), in a :class:`CaptureEvaluation` that writes JSON and a Markdown table.

Cameras follow the OpenCV pinhole convention of :func:`leafview.scene.camera.intrinsics`: a
camera point ``X`` lands at pixel ``(K @ X)[:2] / X[2]``, pixel centres at integer coordinates,
x right, y down, z forward; ``world_from_camera`` (4×4) maps camera to world coordinates.

Choices where a careful reading leaves room:

* Surfaces are sampled on a regular (u, v) grid as drawn (:func:`leafview.core.blade.drawn_uv`,
  so a one-sided leaf is sampled on its drawn half) and every sample carries its area weight
  ``|∂L/∂u × ∂L/∂v|`` times the trapezoid weights of the grid: means over samples are means over
  the surface, not over the parameter grid (which crowds samples at base and apex).
* Visibility cannot see self-occlusion: the views give instance images, not the depth of the
  truth leaf behind its own fold, so a sample is visible when a pixel near its projection shows
  its leaf (see :func:`visibility`).
* Length is the base-to-apex distance (a bent leaf is shorter than its midrib), and Chamfer
  distances are in % of the truth leaf's length so measured.
* The normal angle is unsigned (0-90°): a point cloud does not say which side of a leaf is up.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from leafview.core.blade import drawn_uv, normal_from
from leafview.core.params import LeafParams
from leafview.deform.surface import partials
from leafview.errors import ParamError
from leafview.fit.cloud import closest_on_triangles

__all__ = ["VISIBILITY_BINS", "MIN_IOU", "VISIBILITY_SAMPLES", "CHAMFER_SAMPLES", "Match", "CaptureEvaluation",
           "LeafMeasures", "visibility", "match_leaves", "chamfer", "leaf_measures", "evaluate_capture"]

VISIBILITY_BINS = ((0.0, 0.25), (0.25, 0.5), (0.5, 0.75), (0.75, 1.0001))
"""Half-open visibility intervals ``[lo, hi)``; the last one holds fully visible leaves."""
MIN_IOU = 0.5                   # a truth and a captured leaf match when their masks' IoU reaches this
VISIBILITY_SAMPLES = (17, 33)   # (u, v) grid of the visibility test
CHAMFER_SAMPLES = (33, 65)      # (u, v) grid of the Chamfer distance and of the mean normal
NEAREST_VERTICES = 1            # the cells around this many nearest vertices hold the nearest surface point
MARGIN_SAMPLES = 257            # samples along each margin for the width

Arr = NDArray[np.float64]
View = tuple[ArrayLike, ArrayLike, ArrayLike]   # (K, world_from_camera, truth instance image)


# -- surfaces and measures -----------------------------------------------------------------------
class _Surface(NamedTuple):
    points: Arr     # (N, 3) world, on a (nu, nv) grid, u fastest
    weights: Arr    # (N,) area weights, summing to 1
    normals: Arr    # (N, 3) unit world normals (upper side)
    grid: tuple[int, int]


def _trapezoid(n: int) -> Arr:
    w = np.ones(n)
    w[[0, -1]] = 0.5
    return w


def _grid(samples: tuple[int, int]) -> tuple[int, int, Arr]:
    nu, nv = (int(s) for s in samples)
    if nu < 2 or nv < 2 or nu * nv > 4_000_000:
        raise ParamError("samples", f"expected a (u, v) grid of at least 2×2 and at most 4·10⁶ samples, got {samples}")
    uu, vv = np.meshgrid(np.linspace(-1.0, 1.0, nu), np.linspace(0.0, 1.0, nv))
    return nu, nv, np.stack([uu.ravel(), vv.ravel()], axis=-1)


def _rotation(p: LeafParams) -> Arr:
    m = p.transform.matrix()[:3, :3]
    return np.asarray(m / p.transform.scale, dtype=np.float64)


def _surface(p: LeafParams, samples: tuple[int, int]) -> _Surface:
    """Area-weighted world-space samples of ``p`` on the drawn (u, v) grid (u fastest)."""
    nu, nv, grid = _grid(samples)
    uv = drawn_uv(p, grid)
    part = partials(p, uv[:, 0], uv[:, 1])
    m = p.transform.matrix()
    points = part.L @ m[:3, :3].T + m[:3, 3]
    area = np.linalg.norm(np.cross(part.Lu, part.Lv), axis=-1) * np.outer(_trapezoid(nv), _trapezoid(nu)).ravel()
    total = float(area.sum())
    weights = area / total if total > 0.0 and math.isfinite(total) else np.full(len(area), 1.0 / len(area))
    normals = normal_from(part, uv[:, 1])
    crease = np.flatnonzero(uv[:, 0] == 0.0)
    if len(crease):     # the midrib is a crease (u ≥ 0 and u < 0 have their own ∂L/∂u): average both sides
        left = partials(p, np.full(len(crease), -1e-9), uv[crease, 1])
        both = normals[crease] + normal_from(left, uv[crease, 1])
        normals[crease] = both / np.maximum(np.linalg.norm(both, axis=-1, keepdims=True), 1e-300)
    return _Surface(points, weights, normals @ _rotation(p).T, (nu, nv))


class LeafMeasures(NamedTuple):
    """What :func:`leaf_measures` gives: world-space size and orientation of one leaf."""

    length: float       # base-to-apex distance
    width: float        # largest margin-to-margin extent across the midrib, in the leaf plane
    direction: Arr      # unit midrib direction, base to apex
    normal: Arr         # unit upper-side normal, perpendicular to ``direction``


def _unit(v: Arr) -> Arr | None:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 and math.isfinite(n) else None


def _measures(p: LeafParams, surface: _Surface) -> LeafMeasures:
    m = p.transform.matrix()
    ends = partials(p, [0.0, 0.0], [0.0, 1.0]).L @ m[:3, :3].T + m[:3, 3]
    rot = _rotation(p)
    length = float(np.linalg.norm(ends[1] - ends[0]))
    direction = _unit(ends[1] - ends[0])
    if direction is None:       # a leaf bent until its apex touches its base: fall back to the placement
        direction = rot[:, 1]
    mean_normal = surface.weights @ surface.normals
    normal = _unit(mean_normal - (mean_normal @ direction) * direction)
    if normal is None:          # normals cancel out (a leaf rolled into a tube)
        normal = _unit(rot[:, 2] - (rot[:, 2] @ direction) * direction)
    if normal is None:
        normal = _unit(np.cross(direction, rot[:, 0]))
    assert normal is not None
    v = np.linspace(0.0, 1.0, MARGIN_SAMPLES)
    margin_uv = drawn_uv(p, np.stack([np.repeat([-1.0, 1.0], len(v)), np.tile(v, 2)], axis=-1))
    margin = partials(p, margin_uv[:, 0], margin_uv[:, 1]).L @ m[:3, :3].T
    across = np.cross(normal, direction)
    width = float(np.ptp(margin @ across))
    return LeafMeasures(length, width, direction, normal)


def leaf_measures(p: LeafParams, samples: tuple[int, int] = CHAMFER_SAMPLES) -> LeafMeasures:
    """Length, width, midrib direction and normal of a placed leaf, in world units.

    * ``length``: the distance from the base ``L(0, 0)`` to the apex ``L(0, 1)`` (Chaurasia &
      Beardsley 2017, eq. 6) after the world transform, so it includes the scale and a bent leaf
      measures shorter than its midrib.
    * ``direction``: the unit vector from base to apex.
    * ``normal``: the area-weighted mean of the upper-side surface normals, made perpendicular to
      ``direction`` (the leaf plane is the plane through the midrib with this normal).
    * ``width``: the extent of the margin (the surface at u = ±1, as drawn) along
      ``normal × direction``, i.e. perpendicular to the midrib within the leaf plane.

    ``samples`` is the (u, v) grid of the mean normal, the one :func:`evaluate_capture` uses by
    default; the margin is sampled at :data:`MARGIN_SAMPLES` values of v.
    """
    return _measures(p, _surface(p, samples))


def _angle(a: Arr, b: Arr, *, unsigned: bool = False) -> float:
    dot = float(a @ b)
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), abs(dot) if unsigned else dot))


def _directed(a: _Surface, b: _Surface, tree_b: cKDTree) -> float:
    """Area-weighted mean distance from ``a``'s samples to ``b``'s triangulated grid: each sample
    is measured against the two triangles of every grid cell around its nearest vertices."""
    nu, nv = b.grid
    k = min(NEAREST_VERTICES, len(b.points))
    _, near = tree_b.query(a.points, k=k)
    near = near.reshape(len(a.points), k)
    i = np.clip((near % nu)[..., None] + np.array([-1, 0, -1, 0]), 0, nu - 2)
    j = np.clip((near // nu)[..., None] + np.array([-1, -1, 0, 0]), 0, nv - 2)
    p00 = (j * nu + i).reshape(len(a.points), -1)
    corners = np.concatenate([np.stack([p00, p00 + nu, p00 + 1], axis=-1),
                              np.stack([p00 + 1, p00 + nu, p00 + nu + 1], axis=-1)], axis=1)
    v = b.points
    tri = [v[corners[..., k]].reshape(-1, 3) for k in range(3)]
    p = np.repeat(a.points, corners.shape[1], axis=0)
    distance = np.linalg.norm(closest_on_triangles(p, *tri) - p, axis=1).reshape(corners.shape[:2])
    return float(a.weights @ distance.min(axis=1))


def _chamfer(a: _Surface, b: _Surface, length: float) -> float:
    if not length > 0.0:
        raise ParamError("transform.scale", "the truth leaf has zero length: no Chamfer distance in % of it")
    return 100.0 * 0.5 * (_directed(a, b, cKDTree(b.points)) + _directed(b, a, cKDTree(a.points))) / length


def chamfer(a: LeafParams, b: LeafParams, samples: tuple[int, int] = CHAMFER_SAMPLES) -> float:
    """Mean symmetric Chamfer distance between the surfaces of ``a`` (the truth) and ``b``, in %
    of ``a``'s length (base to apex, :func:`leaf_measures`).

    Each surface is sampled on a ``samples`` = (nu, nv) grid of (u, v) and triangulated on that
    grid. The directed distance from ``a`` to ``b`` is the area-weighted mean, over ``a``'s
    samples, of the distance to ``b``'s triangles (those of the four grid cells around the
    nearest vertex, found with a k-d tree); the result is the mean of the two directed distances.
    Distances to triangles rather than to ``b``'s samples: sample-to-sample distances have a floor
    of about a third of the sample spacing, so that two leaves sliding 1 % of their length within
    their common plane (a true Chamfer distance of about 0.03 %) scored 0.3-0.7 %; to the
    triangles they score 0.03 % at any grid from 17 × 33 up. Two identical leaves give 0 and a
    flat leaf moved by d along its normal gives d.
    """
    sa, sb = _surface(a, samples), _surface(b, samples)
    return _chamfer(sa, sb, _measures(a, sa).length)


# -- visibility and matching ---------------------------------------------------------------------
def _check_views(views: Sequence[View]) -> list[tuple[Arr, Arr, NDArray[np.int64]]]:
    out = []
    for i, view in enumerate(views):
        if len(view) != 3:
            raise ParamError(f"views[{i}]", "expected (K, world_from_camera, truth instance image)")
        k = np.asarray(view[0], dtype=np.float64)
        m = np.asarray(view[1], dtype=np.float64)
        if k.shape != (3, 3) or not np.all(np.isfinite(k)):
            raise ParamError(f"views[{i}].K", f"expected a finite 3×3 matrix, got shape {k.shape}")
        if m.shape != (4, 4) or not np.all(np.isfinite(m)) or abs(np.linalg.det(m[:3, :3])) < 1e-12:
            raise ParamError(f"views[{i}].world_from_camera", f"expected an invertible finite 4×4 matrix, "
                                                              f"got shape {m.shape}")
        out.append((k, m, _instance(view[2], f"views[{i}].instance")))
    return out


def _instance(image: ArrayLike, where: str) -> NDArray[np.int64]:
    a = np.asarray(image)
    if a.ndim != 2 or a.size == 0 or not np.issubdtype(a.dtype, np.integer):
        raise ParamError(where, f"expected a non-empty 2-D integer image, got {a.dtype} of shape {a.shape}")
    if a.min() < 0:
        raise ParamError(where, f"negative instance id {int(a.min())}")
    return a.astype(np.int64, copy=False)


def _project(points: Arr, k: Arr, world_from_camera: Arr, shape: tuple[int, ...]) -> tuple[NDArray[np.bool_],
                                                                                               NDArray[np.int64],
                                                                                               NDArray[np.int64]]:
    """Pixel (column, row) of each world point and whether it lies in front of the camera and in
    the image (pixel ``i`` covers ``[i - 0.5, i + 0.5)``)."""
    camera_from_world = np.linalg.inv(world_from_camera)
    x = points @ camera_from_world[:3, :3].T + camera_from_world[:3, 3]
    h, w = shape
    z = x[:, 2]
    front = z > 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        px = np.floor((x @ k[0]) / z + 0.5)
        py = np.floor((x @ k[1]) / z + 0.5)
    inside = front & (px >= 0) & (px < w) & (py >= 0) & (py < h)
    col = np.where(inside, px, 0).astype(np.int64)
    row = np.where(inside, py, 0).astype(np.int64)
    return inside, col, row


def visibility(truth: Sequence[LeafParams], views: Sequence[View],
               samples: tuple[int, int] = VISIBILITY_SAMPLES) -> Arr:
    """Fraction of each truth leaf's surface visible in at least one view, in [0, 1], shape
    (len(truth),).

    Each leaf is sampled on a ``samples`` = (nu, nv) grid of (u, v) with area weights (see the
    module docstring). A sample is visible in a view when it lies in front of the camera, projects
    into the image, and the truth instance image shows the leaf's id (index + 1) in the 3×3 pixel
    neighbourhood of the pixel it lands in: the tolerance keeps samples on a leaf's silhouette,
    whose pixel centres may fall just outside the rasterised mask, and costs at most a one-pixel
    rim of an occluded part. The result is the summed weight of the samples visible in any view.
    """
    checked = _check_views(views)
    if not truth:
        return np.zeros(0)
    surfaces = [_surface(p, samples) for p in truth]
    points = np.concatenate([s.points for s in surfaces])
    weights = np.concatenate([s.weights for s in surfaces])
    ids = np.repeat(np.arange(1, len(truth) + 1), [len(s.points) for s in surfaces])
    seen = np.zeros(len(points), dtype=bool)
    for k, m, image in checked:
        inside, col, row = _project(points, k, m, image.shape)
        h, w = image.shape
        hit = np.zeros(len(points), dtype=bool)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                hit |= image[np.clip(row + dr, 0, h - 1), np.clip(col + dc, 0, w - 1)] == ids
        seen |= inside & hit
    return np.asarray(np.bincount(ids - 1, weights=weights * seen, minlength=len(truth)), dtype=np.float64)


def _view_pairs(truth: NDArray[np.int64], predicted: NDArray[np.int64], nt: int,
                nc: int) -> tuple[NDArray[np.int64], NDArray[np.int64], Arr]:
    """(truth index, captured index, IoU) of every pair of masks that overlap in one view: the
    areas from ``bincount`` of the ids, the intersections from the counts of the pair codes
    ``truth_id · (nc + 1) + captured_id`` on the pixels both images cover."""
    area_t = np.bincount(truth.ravel(), minlength=nt + 1)
    area_c = np.bincount(predicted.ravel(), minlength=nc + 1)
    both = (truth > 0) & (predicted > 0)
    codes, inter = np.unique(truth[both] * (nc + 1) + predicted[both], return_counts=True)
    t, c = np.divmod(codes, nc + 1)
    return t - 1, c - 1, inter / (area_t[t] + area_c[c] - inter)


def _assign(t: NDArray[np.int64], c: NDArray[np.int64], score: Arr, nt: int, nc: int) -> list[tuple[int, int]]:
    """A one-to-one choice among the candidate pairs with the most pairs, then the largest summed
    score: the Hungarian method on each connected component of the candidate graph (small: a
    truth leaf has at most one candidate per view)."""
    graph = coo_matrix((np.ones(len(t)), (t, nt + c)), shape=(nt + nc, nt + nc))
    _, component = connected_components(graph, directed=False)
    out = []
    for label in np.unique(component[t]):
        edges = np.flatnonzero(component[t] == label)
        rows, r_of = np.unique(t[edges], return_inverse=True)
        cols, c_of = np.unique(c[edges], return_inverse=True)
        gain = np.zeros((len(rows), len(cols)))
        gain[r_of, c_of] = 1.0 + score[edges]
        for a, b in zip(*linear_sum_assignment(gain, maximize=True), strict=True):
            if gain[a, b] > 0.0:
                out.append((int(rows[a]), int(cols[b])))
    return out


def match_leaves(truth_instances: Sequence[ArrayLike], predicted_instances: Sequence[ArrayLike], *,
                 truth_count: int | None = None, captured_count: int | None = None,
                 min_iou: float = MIN_IOU) -> list[tuple[int, int, float, int]]:
    """One-to-one pairs ``(truth index, captured index, IoU, view)`` sorted by truth index.

    In each view the IoU of every pair of overlapping truth and predicted masks comes from the
    pixel counts of the pair codes ``truth_id · (captured_count + 1) + captured_id``. A pair's
    score is its best IoU over the views, and ``view`` is the first view that reaches it. Pairs
    scoring at least ``min_iou`` are candidates; within one view an IoU above 0.5 is unique, but
    across views a leaf can have several. They are assigned one-to-one with the most pairs and,
    among those, the largest summed IoU (the Hungarian method,
    :func:`scipy.optimize.linear_sum_assignment`): a truth leaf whose best partner is taken by
    another truth leaf in a different view keeps its second-best partner, where a greedy choice
    could lose both.

    ``truth_count`` and ``captured_count`` default to the largest ids in the images; ids above
    them raise :class:`ParamError`.
    """
    if len(truth_instances) != len(predicted_instances):
        raise ParamError("predicted_instances", f"{len(predicted_instances)} predicted instance images for "
                                                f"{len(truth_instances)} views")
    images = []
    for i, (t, c) in enumerate(zip(truth_instances, predicted_instances, strict=True)):
        ti, ci = _instance(t, f"views[{i}].instance"), _instance(c, f"predicted_instances[{i}]")
        if ti.shape != ci.shape:
            raise ParamError(f"predicted_instances[{i}]", f"shape {ci.shape} differs from the truth image's {ti.shape}")
        images.append((ti, ci))
    nt = max((int(t.max()) for t, _ in images), default=0) if truth_count is None else int(truth_count)
    nc = max((int(c.max()) for _, c in images), default=0) if captured_count is None else int(captured_count)
    found: list[tuple[NDArray[np.int64], NDArray[np.int64], Arr, NDArray[np.int64]]] = []
    for i, (t, c) in enumerate(images):
        if int(t.max()) > nt:
            raise ParamError(f"views[{i}].instance", f"instance id {int(t.max())} but only {nt} truth leaves")
        if int(c.max()) > nc:
            raise ParamError(f"predicted_instances[{i}]", f"instance id {int(c.max())} but only {nc} captured leaves")
        pt, pc, iou = _view_pairs(t, c, nt, nc)
        keep = iou >= min_iou
        found.append((pt[keep], pc[keep], iou[keep], np.full(int(keep.sum()), i)))
    if not found or not any(len(f[0]) for f in found):
        return []
    pt, pc, iou, view = (np.concatenate(parts) for parts in zip(*found, strict=True))
    code = pt * max(nc, 1) + pc
    order = np.lexsort((view, -iou, code))          # per pair: best IoU first, then the first view
    first = order[np.r_[True, code[order][1:] != code[order][:-1]]]
    pt, pc, iou, view = pt[first], pc[first], iou[first], view[first]
    best = {(int(a), int(b)): (float(s), int(v)) for a, b, s, v in zip(pt, pc, iou, view, strict=True)}
    return sorted((a, b, *best[a, b]) for a, b in _assign(pt, pc, iou, nt, nc))


# -- the evaluation ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Match:
    """One truth/captured pair and its errors. Errors are signed, captured minus truth, in % of
    the truth value (length, width); Chamfer is in % of the truth length; angles in degrees."""

    truth: int
    captured: int
    iou: float
    view: int
    chamfer: float
    length_error: float
    width_error: float
    orientation_error: float    # angle between the midrib directions, base to apex (0-180°)
    normal_error: float         # angle between the leaf planes' normals, sign ignored (0-90°)


_ERRORS = ("chamfer", "length_error", "width_error", "orientation_error", "normal_error")


def _median(values: list[float]) -> float:
    return float(np.median(np.abs(values))) if values else math.nan


def _summary(label: str, members: NDArray[np.bool_], matches: Sequence[Match]) -> dict[str, Any]:
    chosen = [m for m in matches if members[m.truth]]
    n = int(members.sum())
    row: dict[str, Any] = {"bin": label, "truth": n, "matched": len(chosen),
                           "recall": len(chosen) / n if n else math.nan}
    for name in _ERRORS:
        row[f"median_{name}"] = _median([getattr(m, name) for m in chosen])
    return row


def _bin_label(lo: float, hi: float) -> str:
    return f"{round(100 * lo)}–{min(100, round(100 * hi))} %"


def _json(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json(v) for v in value]
    return value


def _cell(value: float, digits: int) -> str:
    return "—" if not math.isfinite(value) else f"{value:.{digits}f}"


@dataclass(frozen=True, eq=False)
class CaptureEvaluation:
    """The scores of a capture. ``by_bin`` has one summary per :data:`VISIBILITY_BINS` interval
    and ``overall`` the same over every truth leaf: truth count, matched count, recall and the
    medians of the absolute match errors (NaN where there is nothing to count)."""

    matches: tuple[Match, ...]
    truth_count: int
    captured_count: int
    visibility: Arr
    precision: float            # matched captured leaves / captured leaves
    recall: float               # matched truth leaves / truth leaves
    recall_visible_50: float    # the same over the truth leaves at least half visible
    by_bin: list[dict[str, Any]]
    overall: dict[str, Any]
    median_chamfer: float

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict (NaN written as None)."""
        return _json({
            "truth_count": self.truth_count, "captured_count": self.captured_count,
            "precision": self.precision, "recall": self.recall, "recall_visible_50": self.recall_visible_50,
            "median_chamfer": self.median_chamfer, "min_iou": MIN_IOU,
            "visibility_bins": [list(b) for b in VISIBILITY_BINS],
            "by_bin": self.by_bin, "overall": self.overall,
            "visibility": [float(v) for v in self.visibility],
            "matches": [asdict(m) for m in self.matches],
        })

    def table(self) -> str:
        """A Markdown table, one row per visibility bin and one for all leaves, then a line with
        precision and recall."""
        head = ("| visible | truth | matched | recall | Chamfer (% length) | length error (%) | width error (%) "
                "| midrib angle (°) | normal angle (°) |")
        lines = [head, "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for row in [*self.by_bin, self.overall]:
            lines.append(f"| {row['bin']} | {row['truth']} | {row['matched']} | {_cell(row['recall'], 2)} | "
                         f"{_cell(row['median_chamfer'], 2)} | {_cell(row['median_length_error'], 1)} | "
                         f"{_cell(row['median_width_error'], 1)} | {_cell(row['median_orientation_error'], 1)} | "
                         f"{_cell(row['median_normal_error'], 1)} |")
        lines += ["", f"Precision {_cell(self.precision, 3)} ({len(self.matches)} of {self.captured_count} captured "
                      f"leaves matched), recall {_cell(self.recall, 3)}, recall over leaves at least half visible "
                      f"{_cell(self.recall_visible_50, 3)}; errors are medians of absolute values over the matches."]
        return "\n".join(lines) + "\n"


def evaluate_capture(truth: Sequence[LeafParams], captured: Sequence[LeafParams], views: Sequence[View],
                     predicted_instances: Sequence[ArrayLike], *, min_iou: float = MIN_IOU,
                     visibility_samples: tuple[int, int] = VISIBILITY_SAMPLES,
                     chamfer_samples: tuple[int, int] = CHAMFER_SAMPLES) -> CaptureEvaluation:
    """Score ``captured`` against ``truth`` from the ``views`` = (K, world_from_camera, truth
    instance image) the capture was made from and the instance images of ``captured`` rendered
    from the same cameras (``predicted_instances``, captured index + 1).

    Pairs come from :func:`match_leaves`; each pair gets :func:`chamfer`, the length and width
    errors and the angles between midribs and normals (:func:`leaf_measures`). Precision is
    matched captured leaves over captured leaves, recall matched truth leaves over truth leaves;
    a truth leaf no view shows cannot be matched, which the visibility bins make plain.
    """
    checked = _check_views(views)
    if len(predicted_instances) != len(checked):
        raise ParamError("predicted_instances", f"{len(predicted_instances)} predicted instance images for "
                                                f"{len(checked)} views")
    vis = visibility(truth, views, visibility_samples)
    pairs = match_leaves([image for _, _, image in checked], predicted_instances, truth_count=len(truth),
                         captured_count=len(captured), min_iou=min_iou)
    matches = []
    for t, c, iou, view in pairs:
        st, sc = _surface(truth[t], chamfer_samples), _surface(captured[c], chamfer_samples)
        mt, mc = _measures(truth[t], st), _measures(captured[c], sc)
        if not (mt.length > 0.0 and mt.width > 0.0):
            raise ParamError(f"truth[{t}]", "a leaf of zero length or width cannot be scored")
        matches.append(Match(
            truth=t, captured=c, iou=iou, view=view,
            chamfer=_chamfer(st, sc, mt.length),
            length_error=100.0 * (mc.length - mt.length) / mt.length,
            width_error=100.0 * (mc.width - mt.width) / mt.width,
            orientation_error=_angle(mt.direction, mc.direction),
            normal_error=_angle(mt.normal, mc.normal, unsigned=True)))
    nt, nc = len(truth), len(captured)
    visible_50 = vis >= 0.5
    matched_truth = np.zeros(nt, dtype=bool)
    matched_truth[[m.truth for m in matches]] = True
    return CaptureEvaluation(
        matches=tuple(matches), truth_count=nt, captured_count=nc, visibility=vis,
        precision=len(matches) / nc if nc else math.nan,
        recall=len(matches) / nt if nt else math.nan,
        recall_visible_50=float(matched_truth[visible_50].sum() / visible_50.sum()) if visible_50.any() else math.nan,
        by_bin=[_summary(_bin_label(lo, hi), (vis >= lo) & (vis < hi), matches) for lo, hi in VISIBILITY_BINS],
        overall=_summary("all", np.ones(nt, dtype=bool), matches),
        median_chamfer=_median([m.chamfer for m in matches]))
