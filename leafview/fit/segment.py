"""Candidate leaves from one RGB-D view (Chaurasia & Beardsley 2017, sec. 4.1, eqs 7-8).

The view is over-segmented into SLIC superpixels where there is depth; a plane is fitted to each
superpixel's 3D points by RANSAC with threshold δ_plane; superpixels sharing an image boundary
are joined when their planes agree and their points touch (eqs 7-8, affinity at least 0.85);
each connected component is a *candidate leaf*, scored by the share of its minimum-volume
enclosing ellipse it covers (the "leaf confidence", :func:`leafview.fit.mvee.occupancy`).

Choices where the paper leaves room, each tested and measured on the cluttered synthetic scenes
of ``tests/test_capture.py``:

* **RGB-D superpixels.** SLIC runs on CIELAB colour plus the depth, scaled so that one pixel
  footprint of depth counts like :data:`DEPTH_WEIGHT` CIELAB units (``depth_weight=0`` gives the
  paper's colour-only superpixels). Two similarly green leaves one behind the other are then
  rarely in one superpixel. SLIC runs on the bounding box of the pixels with depth, without
  skimage's mask (whose k-means seeding took most of the time); pixels without depth get the
  nearest depth, are cut out afterwards, and a superpixel the cut splits becomes one per piece.
* **Normals face the camera.** Eq. 7's ``d_n = 1 - n̂_i · n̂_j`` depends on the sign of the
  normals, which a plane fit does not give: every superpixel's normal is turned towards the eye of
  the view that saw it, so two coplanar superpixels have ``d_n = 0``.
* **One surface per superpixel.** Before the plane fit, a superpixel keeps only its largest
  piece of *continuous* surface: pixels 4-adjacent in the image whose points are less than
  :data:`CONTINUITY` · δ_plane apart (:func:`_surface_pieces`). A superpixel reaching over the
  edge of a leaf onto one just behind it (closer than δ_plane, so RANSAC would keep both) would
  otherwise tie the two leaves together through eq. 7's minimum distance.
* **Points far from the mean.** After RANSAC keeps the points within δ_plane of the plane, points
  farther from the inliers' mean than three times their median distance from it (and than
  δ_plane) are dropped too.
* **"Very few points"** is fewer than ``min_superpixel_points`` (default 8); **no valid plane**
  is fewer than half the points within δ_plane of the best of the RANSAC planes.
* **The minimum distance of eq. 7 is computed exactly where it can matter.** With ``d_n = 0``
  the affinity reaches the threshold ``t`` only for ``d_p <= sqrt(-2 σ² ln t)`` (0.114 for the
  paper's σ = 0.2, t = 0.85), so point pairs are searched (:class:`scipy.spatial.cKDTree`) up to
  that distance times δ_plane; an adjacent pair with no points that close has ``d_p`` = ∞ and
  affinity 0 (it could not have passed the threshold).
* **Boundary** means 4-connected pixel adjacency in the superpixel label image.
* **A candidate's plane** is the least-squares plane of all its points (normal towards the eye);
  its length and width are the diameters of the enclosing ellipse of the points in that plane
  (Khachiyan's iteration stopped after :data:`MVEE_ITERATIONS` steps, then grown to enclose), and
  its confidence is measured on cells of :data:`CELL` times the 90th percentile of the distances
  between nearest points in that plane, so that a leaf seen obliquely, or by several views with
  uneven density, is not counted as porous.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from skimage.color import rgb2lab
from skimage.measure import label as measure_label
from skimage.segmentation import slic

from leafview.errors import ParamError
from leafview.fit.mvee import mvee, occupancy
from leafview.fit.views import View

__all__ = ["Candidate", "ViewSegmentation", "superpixels", "default_segments", "plane_ransac", "affinity",
           "pair_affinity", "measure", "segment_view", "candidates", "SIGMA", "THRESHOLD"]

SIGMA = 0.2               # eq. 8's kernel width (Chaurasia & Beardsley 2017, sec. 4.1)
THRESHOLD = 0.85          # affinity at which superpixels join
PIXELS_PER_SUPERPIXEL = 120   # default superpixel size: n_segments = depth pixels / this
DEPTH_WEIGHT = 2.0        # CIELAB units per pixel footprint of depth in the superpixels' features
CELL = 2.0                # occupancy cells, in 90th percentiles of the nearest-point distance
CONTINUITY = 0.25         # continuous surface within a superpixel: neighbours closer than this × δ_plane
MVEE_ITERATIONS = 100     # Khachiyan steps for a candidate's ellipse (enough for the confidence; then grown to enclose)

Arr = NDArray[np.float64]
Idx = NDArray[np.int64]


@dataclass
class Candidate:
    """One candidate leaf: the points of connected superpixels of view ``view``.

    ``pixels`` are flat pixel indices in that view, ``points`` (M, 3) their world points; the
    plane through them has unit ``normal`` (towards the camera) and passes through ``centre``;
    ``major`` and ``minor`` are the in-plane unit directions of the enclosing ellipse, whose
    diameters are ``length`` and ``width``; ``confidence`` is the share of that ellipse the
    points cover (Chaurasia & Beardsley 2017, sec. 4.1, Fig. 3)."""

    view: int
    pixels: Idx
    points: Arr
    normal: Arr
    confidence: float
    length: float
    width: float
    centre: Arr = field(default_factory=lambda: np.zeros(3))
    major: Arr = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    minor: Arr = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    superpixels: int = 1

    @property
    def area(self) -> float:
        """The enclosing ellipse's area, π · length · width / 4: the candidate's size."""
        return math.pi * self.length * self.width / 4.0


@dataclass
class ViewSegmentation:
    """Everything :func:`segment_view` computed, for inspection: the label image (-1: no depth
    or dropped), per superpixel its unit normal (NaN where dropped), the graph's edges (pairs of
    superpixel labels sharing a boundary) with their ``d_n``, ``d_p`` and affinity, and the
    candidates."""

    labels: NDArray[np.int64]
    normals: Arr
    edges: Idx
    d_n: Arr
    d_p: Arr
    affinity: Arr
    candidates: list[Candidate]


def default_segments(view: View) -> int:
    """The number of superpixels when none is given: one per :data:`PIXELS_PER_SUPERPIXEL`
    pixels with depth (at least 16)."""
    return max(16, int(np.count_nonzero(view.depth > 0)) // PIXELS_PER_SUPERPIXEL)


def superpixels(view: View, *, n_segments: int | None = None, compactness: float = 10.0,
                depth_weight: float = DEPTH_WEIGHT) -> NDArray[np.int64]:
    """SLIC superpixels (Achanta et al. 2012) of the view where it has depth: an (h, w) label
    image numbered 0, 1, ... and -1 where there is no depth.

    The features are the colour in CIELAB and, unless ``depth_weight`` is 0 (colour only, as
    Chaurasia & Beardsley 2017 have it), the depth in units of the view's median pixel footprint
    (depth / focal length) times ``depth_weight``: a step of one footprint in depth counts like
    ``depth_weight`` CIELAB units of colour, so superpixels do not straddle two similarly green
    leaves at different depths (the RGB-D superpixels of Jebari & Filliat 2012, which the paper
    cites)."""
    mask = view.depth > 0
    if not mask.any():
        return np.full(mask.shape, -1, np.int64)
    n = default_segments(view) if n_segments is None else int(n_segments)
    if n < 1:
        raise ParamError("n_segments", f"must be at least 1, got {n}")
    if not depth_weight >= 0:
        raise ParamError("depth_weight", f"must be zero or positive, got {depth_weight!r}")
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
    inside = mask[box]
    image = rgb2lab(view.color[box])
    if depth_weight > 0:
        depth = view.depth[box].astype(np.float64)
        z0 = float(np.median(depth[inside]))
        footprint = z0 / float(np.sqrt(view.k[0, 0] * view.k[1, 1]))
        if not inside.all():          # no depth: the nearest depth, so that only colour tells it apart
            nearest = ndimage.distance_transform_edt(~inside, return_distances=False, return_indices=True)
            depth = depth[tuple(nearest)]
        image = np.concatenate([image, ((depth - z0) * (depth_weight / footprint))[:, :, None]], axis=2)
    # slic rescales the features to [0, 1] by their range; dividing the compactness by that range
    # keeps it in CIELAB units, as in slic's own colour conversion
    span = float(np.ptp(image)) or 1.0
    n_box = max(1, round(n * inside.size / max(int(inside.sum()), 1)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        lab = slic(image, n_segments=n_box, compactness=compactness / span, start_label=1, channel_axis=-1,
                   convert2lab=False)
    lab = np.where(inside, np.asarray(lab, np.int64), 0)
    pieces = measure_label(lab, background=0, connectivity=1)   # a superpixel cut by the mask: one per piece
    out = np.full(mask.shape, -1, np.int64)
    out[box] = np.asarray(pieces, np.int64) - 1
    return out


def plane_ransac(points: ArrayLike, delta: float, rng: np.random.Generator, iterations: int = 64,
                 min_inliers: float = 0.5) -> tuple[Arr, float, NDArray[np.bool_]] | None:
    """A plane ``n · x + d = 0`` through ``points`` (M, 3) by RANSAC: ``iterations`` planes through
    three random points, the one with most points within ``delta`` kept and refitted to its inliers
    by least squares (twice). Returns ``(unit normal, d, inlier mask)``, or None when fewer than
    three points, or fewer than ``min_inliers`` of them, lie within ``delta`` of the best plane."""
    p = np.asarray(points, np.float64)
    m = len(p)
    if m < 3:
        return None
    idx = rng.integers(0, m, (iterations, 3))
    a, b, c = p[idx[:, 0]], p[idx[:, 1]], p[idx[:, 2]]
    nrm = np.cross(b - a, c - a)
    length = np.linalg.norm(nrm, axis=1)
    ok = length > 1e-12 * max(float(np.ptp(p, axis=0).max()) ** 2, 1e-300)
    if not ok.any():
        return None
    nrm = nrm[ok] / length[ok, None]
    d = -np.sum(nrm * a[ok], axis=1)
    counts = (np.abs(p @ nrm.T + d) <= delta).sum(axis=0)
    best = int(np.argmax(counts))
    normal, offset = nrm[best], float(d[best])
    inliers = np.abs(p @ normal + offset) <= delta
    for _ in range(2):
        if inliers.sum() < 3:
            return None
        q = p[inliers]
        centre = q.mean(axis=0)
        _, _, vt = np.linalg.svd(q - centre, full_matrices=False)
        normal = vt[-1]
        offset = -float(normal @ centre)
        inliers = np.abs(p @ normal + offset) <= delta
    if inliers.sum() < max(3, min_inliers * m):
        return None
    return normal, offset, inliers


def affinity(d_n: ArrayLike, d_p: ArrayLike, sigma: float = SIGMA) -> Arr:
    """Eq. 8: ``D = exp(-(d_n² + d_p²) / (2 σ²))``."""
    dn, dp = np.asarray(d_n, np.float64), np.asarray(d_p, np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.exp(-(dn * dn + dp * dp) / (2.0 * sigma * sigma))
    return np.nan_to_num(out, nan=0.0)


def pair_affinity(points_i: ArrayLike, normal_i: ArrayLike, points_j: ArrayLike, normal_j: ArrayLike,
                  delta_plane: float, sigma: float = SIGMA) -> tuple[float, float, float]:
    """Eqs 7-8 for two superpixels given their points and (consistently oriented) unit normals:
    ``(d_n, d_p, D)`` with ``d_n = 1 - n̂_i · n̂_j`` and ``d_p`` the smallest distance between a
    point of one and a point of the other, over ``delta_plane``."""
    d_n = 1.0 - float(np.dot(normal_i, normal_j))
    dist, _ = cKDTree(np.asarray(points_j, np.float64)).query(np.asarray(points_i, np.float64))
    d_p = float(np.min(dist)) / delta_plane
    return d_n, d_p, float(affinity(d_n, d_p, sigma))


def measure(points: Arr, eye: Arr) -> tuple[Arr, Arr, Arr, Arr, float, float, float] | None:
    """The plane and enclosing ellipse of a candidate's ``points``: ``(normal, centre, major,
    minor, length, width, confidence)`` with the normal towards ``eye``; None when the points do
    not span a plane (fewer than 4, or all on a line)."""
    if len(points) < 4:
        return None
    mean = points.mean(axis=0)
    _, sv, vt = np.linalg.svd(points - mean, full_matrices=False)
    if not sv[1] > 1e-9 * max(sv[0], 1e-300):
        return None
    normal = vt[2] if float(vt[2] @ (eye - mean)) >= 0 else -vt[2]
    e1, e2 = vt[0], np.cross(normal, vt[0])
    flat = np.stack([(points - mean) @ e1, (points - mean) @ e2], axis=1)
    try:
        ell = mvee(flat, tol=1e-3, max_iter=MVEE_ITERATIONS)
        gaps, _ = cKDTree(flat).query(flat, k=2)
        conf = occupancy(flat, ell, cell=CELL * float(np.percentile(gaps[:, 1], 90)))
    except ParamError:
        return None
    radii, vecs = ell.axes
    major = vecs[0, 0] * e1 + vecs[1, 0] * e2
    minor = np.cross(normal, major)
    centre = mean + ell.center[0] * e1 + ell.center[1] * e2
    return normal, centre, major, minor, 2.0 * float(radii[0]), 2.0 * float(radii[1]), float(conf)


def _surface_pieces(labels: NDArray[np.int64], pts: Arr, flat: Idx, radius: float) -> Idx:
    """A piece id per point: points of 4-adjacent pixels in the same superpixel whose 3D distance
    is below ``radius`` are in one piece (connected components over the whole image)."""
    h, w = labels.shape
    where = np.full(h * w, -1, np.int64)
    where[flat] = np.arange(len(flat))
    grid = where.reshape(h, w)
    rows, cols = [], []
    for a, b in ((grid[:, :-1], grid[:, 1:]), (grid[:-1, :], grid[1:, :])):
        sel = (a >= 0) & (b >= 0)
        ia, ib = a[sel], b[sel]
        same = labels.reshape(-1)[flat[ia]] == labels.reshape(-1)[flat[ib]]
        ia, ib = ia[same], ib[same]
        close = np.sum((pts[ia] - pts[ib]) ** 2, axis=1) < radius * radius
        rows.append(ia[close])
        cols.append(ib[close])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r)), (r, c)), shape=(len(pts), len(pts)))
    _, comp = connected_components(graph, directed=False)
    return np.asarray(comp, np.int64)


def _adjacent_pairs(labels: NDArray[np.int64]) -> Idx:
    """Unique label pairs (a < b) of 4-adjacent pixels with different labels, both >= 0."""
    pairs = []
    for a, b in ((labels[:, :-1], labels[:, 1:]), (labels[:-1, :], labels[1:, :])):
        sel = (a != b) & (a >= 0) & (b >= 0)
        pairs.append(np.stack([np.minimum(a[sel], b[sel]), np.maximum(a[sel], b[sel])], axis=1))
    allp = np.concatenate(pairs)
    return np.unique(allp, axis=0) if len(allp) else np.zeros((0, 2), np.int64)


def segment_view(view: View, view_index: int, *, delta_plane: float, sigma: float = SIGMA,
                 threshold: float = THRESHOLD, n_segments: int | None = None, compactness: float = 10.0,
                 depth_weight: float = DEPTH_WEIGHT, min_points: int = 60, min_superpixel_points: int = 8,
                 seed: int = 0) -> ViewSegmentation:
    """Sec. 4.1 on one view: superpixels, a RANSAC plane per superpixel, the graph of eqs 7-8
    thresholded at ``threshold``, its connected components as candidates of at least
    ``min_points`` points (see the module docstring for the choices)."""
    if not delta_plane > 0 or not math.isfinite(delta_plane):
        raise ParamError("delta_plane", f"must be a positive distance, got {delta_plane!r}")
    if not 0.0 < threshold < 1.0:
        raise ParamError("threshold", f"must lie strictly between 0 and 1, got {threshold!r}")
    if not sigma > 0:
        raise ParamError("sigma", f"must be positive, got {sigma!r}")
    rng = np.random.default_rng([seed, view_index])
    labels = superpixels(view, n_segments=n_segments, compactness=compactness, depth_weight=depth_weight)
    n_sp = int(labels.max()) + 1
    if n_sp == 0:
        return ViewSegmentation(labels, np.zeros((0, 3)), np.zeros((0, 2), np.int64), np.zeros(0), np.zeros(0),
                                np.zeros(0), [])
    pts, flat = view.points(labels >= 0)
    lab = labels.reshape(-1)[flat]
    order = np.argsort(lab, kind="stable")
    starts = np.searchsorted(lab[order], np.arange(n_sp + 1))
    keep = np.zeros(len(pts), bool)
    normals = np.full((n_sp, 3), np.nan)
    eye = view.eye
    piece = _surface_pieces(labels, pts, flat, CONTINUITY * delta_plane)
    for s in range(n_sp):
        sel = order[starts[s]:starts[s + 1]]
        if len(sel) < min_superpixel_points:
            continue
        ids, counts = np.unique(piece[sel], return_counts=True)
        sel = sel[piece[sel] == ids[np.argmax(counts)]]
        if len(sel) < min_superpixel_points:
            continue
        fit = plane_ransac(pts[sel], delta_plane, rng)
        if fit is None:
            continue
        normal, _, inl = fit
        q = pts[sel[inl]]
        r = np.linalg.norm(q - q.mean(axis=0), axis=1)
        near = r <= max(3.0 * float(np.median(r)), delta_plane)
        if near.sum() < min_superpixel_points:
            continue
        keep[sel[inl][near]] = True
        normals[s] = normal if float(normal @ (eye - q.mean(axis=0))) >= 0 else -normal
    valid = ~np.isnan(normals[:, 0])
    lab_img = labels.copy()
    lab_img[lab_img >= 0] = np.where(valid[lab_img[lab_img >= 0]], lab_img[lab_img >= 0], -1)
    edges = _adjacent_pairs(lab_img)
    # eq. 7's d_p: nearest points of the two superpixels, searched up to the distance that could pass
    kpts, klab = pts[keep], lab[keep]
    reach = delta_plane * math.sqrt(-2.0 * sigma * sigma * math.log(threshold))
    d_min = np.full(len(edges), np.inf)
    if len(edges) and len(kpts):
        pairs = cKDTree(kpts).query_pairs(reach, output_type="ndarray")
        la, lb = klab[pairs[:, 0]], klab[pairs[:, 1]]
        cross = la != lb
        if cross.any():
            lo, hi = np.minimum(la[cross], lb[cross]), np.maximum(la[cross], lb[cross])
            dist = np.linalg.norm(kpts[pairs[cross, 0]] - kpts[pairs[cross, 1]], axis=1)
            key = lo * n_sp + hi
            ekey = edges[:, 0] * n_sp + edges[:, 1]
            uk, inv = np.unique(key, return_inverse=True)
            best = np.full(len(uk), np.inf)
            np.minimum.at(best, inv, dist)
            pos = np.searchsorted(uk, ekey)
            hit = (pos < len(uk)) & (uk[np.minimum(pos, len(uk) - 1)] == ekey)
            d_min[hit] = best[pos[hit]]
    d_n = 1.0 - np.sum(normals[edges[:, 0]] * normals[edges[:, 1]], axis=1) if len(edges) else np.zeros(0)
    d_p = d_min / delta_plane
    aff = affinity(d_n, d_p, sigma)
    strong = edges[aff >= threshold]
    graph = coo_matrix((np.ones(len(strong)), (strong[:, 0], strong[:, 1])), shape=(n_sp, n_sp))
    _, comp = connected_components(graph, directed=False)
    cands: list[Candidate] = []
    if len(kpts):
        kflat = flat[keep]
        kcomp = comp[klab]
        corder = np.argsort(kcomp, kind="stable")
        cstarts = np.searchsorted(kcomp[corder], np.arange(comp.max() + 2))
        for c in range(comp.max() + 1):
            sel = corder[cstarts[c]:cstarts[c + 1]]
            if len(sel) < min_points:
                continue
            geo = measure(kpts[sel], eye)
            if geo is None:
                continue
            normal, centre, major, minor, length, width, conf = geo
            n_members = int(np.unique(klab[sel]).size)
            cands.append(Candidate(view_index, kflat[sel], kpts[sel], normal, conf, length, width, centre, major,
                                   minor, n_members))
    return ViewSegmentation(lab_img, normals, edges, d_n, d_p, aff, cands)


def candidates(view: View, view_index: int, *, delta_plane: float, sigma: float = SIGMA,
               threshold: float = THRESHOLD, n_segments: int | None = None, compactness: float = 10.0,
               depth_weight: float = DEPTH_WEIGHT, min_points: int = 60, seed: int = 0) -> list[Candidate]:
    """The candidate leaves of one view (Chaurasia & Beardsley 2017, sec. 4.1): see
    :func:`segment_view`."""
    return segment_view(view, view_index, delta_plane=delta_plane, sigma=sigma, threshold=threshold,
                        n_segments=n_segments, compactness=compactness, depth_weight=depth_weight,
                        min_points=min_points, seed=seed).candidates
