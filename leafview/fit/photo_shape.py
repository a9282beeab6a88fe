"""The shape of a leaf mask: one leaf or two, petiole, base, apex and a smoothed outline (used by
:func:`leafview.fit.photo_outline.leaf_outline`; x right, y down, pixel centres at integers).

* **Two touching leaves** (:func:`split_shares`). The mask's distance transform (on a copy at most
  :data:`SPLIT_SIDE` pixels across) is cut by a watershed into one basin per peak (local maxima
  of at least a third of the largest); two basins are one leaf when the saddle between them is
  at least :data:`NECK_RATIO` of the lower of their peaks, i.e. when the neck between the parts
  is at least 70 % as wide as the narrower part's widest inscribed circle. Lobes, teeth and a
  petiole stay with the blade (wide necks, or no peak of their own); two leaves touching at a
  point or along a short stretch part. The two largest parts must also meet at a pinch: the
  line between them is at most :data:`NECK_LENGTH` times the smaller part's inscribed radius
  long, and one of its ends lies at least :data:`NECK_NOTCH` of that radius inside the mask's
  convex hull (the gap between two leaves). The teeth of one long serrated leaf can pull the
  distance transform's saddle down, but the line across such a leaf is its whole width. Limits: leaves overlapping widely, or touching
  along most of their length, pass (:func:`two_blades` and the fit's error catch many of them);
  a leaf with a waist narrower than 70 % of its narrower end (a fiddle-shaped leaf) looks like two.
* **Two touching leaves without a neck** (:func:`two_blades`). On the traced outline, the sinuses
  (runs of outline points inside the convex hull) at least :data:`BLADES_SINUS` of the hull's
  diameter deep are paired; the straight cut between two sinuses' deepest points splits the
  region in two. Two leaves touching along an edge or overlapping widely part there into two
  convex blades; the lobes of one leaf do not (the piece holding the base keeps the other
  lobes' sinuses), nor does a leaf's cut from a notched apex to a cordate base (most of its
  length). The region is two leaves when some cut no longer than :data:`BLADES_CUT` of the
  diameter leaves two pieces of at least :data:`BLADES_SHARE` of the area, each at least
  :data:`BLADES_SOLIDITY` convex (area ÷ convex hull's area). Limit: a two-lobed leaf cleft so
  deep, with a cordate base so deep, that less than :data:`BLADES_CUT` of it stays between the
  two sinuses looks like two leaves.
* **Petiole.** The working mask is opened with a disc of :data:`PETIOLE_RADIUS` times its
  largest inscribed radius (through two distance transforms); what lies outside the opened blade
  at full resolution and touches it is a candidate: teeth, the apex tip, a narrow base and the
  petiole. A candidate's centre line is the longest path through its skeleton; it is the
  petiole when it is long (:data:`PETIOLE_MIN_LENGTH` of the leaf's extent and eight times its
  half-width, at least), not a hair (half-width :data:`PETIOLE_MIN_RADIUS` px at least) and of
  even width (its free third at least :data:`PETIOLE_EVENNESS` as wide as its middle: an apex tip
  tapers to nothing); the longest such candidate wins. A petiole whose free end lies more than
  :data:`PETIOLE_TURN` degrees off the line from the base it gives to the apex found from there
  (seen from that base) is none (a tooth on a shoulder, a sliver along the edge, or a narrow second
  leaf against the blade's side): base and apex are then found as for a blade without one.
* **Base with a petiole.** Walking the petiole's centre line from its free end (cut where it
  leaves the even petiole), then straight on into the blade, the mask's chord across the walk is
  measured; the blade starts where the half-chord first exceeds twice the petiole's half-width.
  (Where straight on leaves the mask before that, the petiole curves: the walk aims instead at
  where the whole centre line meets the blade, if that way crosses less than half as much
  background.) The growth of the chord past that point is
  extrapolated back (by :data:`BASE_EXTRAPOLATION` of the way to zero width: all of it), which
  finds the tip of a wedge-shaped (cuneate) base hidden in the petiole's width: the growth just
  past the point (back at most four petiole half-widths), and the mean growth until the
  half-chord reaches four times the petiole's half-width (over at most :data:`BASE_RUN` of the
  extent, back at most :data:`BASE_BACK`: a long narrow wedge), whichever reaches farther; but
  not back past a neck, where the walk narrows below :data:`BASE_NECK` of the petiole's median
  half-chord behind it, within :data:`NECK_REACH` petiole half-widths before the widening point
  (a petiole joined to the blade at a narrow neck, not hiding a wedge: the extrapolation from
  the blade's concave growth overshot such a joint by 23 px, 6.7 % of the length). A
  rounded or cordate base widens at once (more than a petiole half-width within three pixels) and
  stays put, unless the walk ran between two lobes before it (:func:`_flanked`): then the petiole
  may run on in a sinus narrower than itself, whose walls meet over it beyond where the mask
  shows, and where the photo's colours are known its end is followed by its colour
  (:func:`_hidden_base`).
* **Base without a petiole.** The blade's principal axis (through its centroid) meets the
  outline at two ends; on a blade wider than long the midrib runs across that axis, which the
  veins tell (:func:`_vein_sense` clear across it and :data:`VEIN_TURN` times clearer than
  along it), and the axis is turned by 90°. Only a blade not much longer than wide (principal
  standard deviations within :data:`VEIN_TURN_ELONGATION`) is turned: on a narrow one the teeth
  and the edges' shading can outweigh the veins (a narrow serrated leaf, 15 times longer than
  wide in these terms, had its base found mid-blade, 36 % of its length off). The base end is,
  in order: the end opposite a given apex; the end the secondary veins open away from (when
  clear: an emarginate apex has a notch too; on a blade less than :data:`VEIN_WEAK_ELONGATION`
  times longer than wide a weaker sense, from :data:`VEIN_WEAK`, is clear enough: on the
  synthetic photos its sign told the apex's end in every one of 55 such blades between
  :data:`VEIN_WEAK` and :data:`VEIN_SENSE`, against 2 of 6 wrong on narrower ones, whose short,
  nearly axial veins are outweighed by the edges' shading); the end with a notch (a crossing more than
  :data:`NOTCH_DEPTH` of the length inside the outline's convex hull: a cordate base); the
  blunter end (wider by 15 % at a tenth of the length from it: apices are usually acute); the end
  that is a stalk where the other tapers (:func:`_stalk_end`: a petiole too wide to be found as
  one), with a warning; else the end nearer the widest part (most leaves are widest below the
  middle), with a warning.
  A roundish blade (principal standard deviations within :data:`SINUS_ROUND`) with one sinus
  deeper than :data:`SINUS_DEEP` of its extent inside its convex hull, none half as deep a quarter
  of the extent away (:func:`_lone_sinus`), has its base there, wherever its principal axis runs
  (a round cordate blade's axis is a guess; it was found across the sinus).
  The base itself is the notch's sinus; else the outline point farthest from the apex, unless that
  lies more than :data:`SHOULDER` of the width off the axis (a shoulder of a truncate base), where
  the axis' crossing is used, or more than that off the line from the apex through the
  centroid while that line leaves the blade nearly as far from the apex (at least
  :data:`OBLIQUE_REACH` of the way: a corner of an oblique truncate base), where that line's exit
  is used; a petiole stub too short to be found as a petiole (or the part of a petiole darker
  than the blade that the segmentation kept) is walked back to where the blade widens it: where
  the width profile from the end breaks from a narrow, nearly even run into the blade's growth
  (:func:`_stub_root`, :func:`_hinge`); a pointed base is followed on along its
  taper as the apex is (:func:`_taper_tip`). A nearly round blade (principal axes within 15 %)
  gets a warning: its axis, so its ends, are a guess.
* **Apex** (:func:`_midrib_end`): the midrib's end, seen from the base along the line through the
  blade's centroid (the principal axis misleads on a blade wider than long). Where that line
  leaves the outline in a notch (an emarginate or two-lobed apex) it is the notch's sinus; else
  the outline point farthest from the base within 45° of the line, or, on a blunt apex (many
  points nearly as far, spread across the line), the one of those nearest the line (:func:`_apex`;
  the base opposite an apex is found the same way). A thin tip loses its last pixels in the
  segmentation (the blurred threshold drops parts a few pixels wide), so the tip's width profile
  behind that point, where it is wide enough to trust, is extended as a straight line to zero
  width (:func:`_taper_tip`); a blunt apex widens too fast to be moved.
* **Outline** (:func:`fit_closed_bspline`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import NDArray
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import ConvexHull, cKDTree
from shapely.geometry import Polygon
from skimage.measure import approximate_polygon, find_contours
from skimage.morphology import convex_hull_image, skeletonize
from skimage.segmentation import watershed

__all__ = ["Shape", "leaf_shape", "split_shares", "two_blades", "TwoBlades", "fit_closed_bspline",
           "eval_closed_bspline"]

SPLIT_SIDE = 200              # px: the two-leaves test runs on a mask at most this wide
NECK_RATIO = 0.7              # saddle / lower peak of the distance transform at which two parts join
NECK_NOTCH = 0.75             # depth in the convex hull of the neck's ends / the smaller part's peak, at least
NECK_LENGTH = 1.8             # pixels along the neck / the smaller part's peak, at most
# Two leaves without a neck. Measured on the seeded synthetic photos (64 touching pairs at
# 500-600 px, 18 maple, oak and two-lobed leaves, 128 single leaves): of the 28 pairs the neck test
# lets through, the best cut leaves both pieces at least 0.946 convex in 12 (cuts 16-40 % of the
# diameter long, smaller pieces 22-47 % of the area), the others 0.71-0.91 or one deep sinus;
# lobed leaves reach at most 0.86 (oak), a two-lobed leaf has one deep sinus, and one of the 128
# single leaves has two deep sinuses, cutting off 6 % of it.
BLADES_SINUS = 0.06           # sinus depth / the convex hull's diameter, at least (as lobes count)
BLADES_SOLIDITY = 0.93        # each piece's area / its convex hull's area, at least
BLADES_SHARE = 0.15           # the smaller piece's share of the area, at least
BLADES_CUT = 0.45             # cut length / the convex hull's diameter, at most
PETIOLE_RADIUS = 0.25         # opening radius / largest inscribed radius of the mask
PETIOLE_MIN_LENGTH = 0.04     # petiole length / extent of the leaf, at least
PETIOLE_MIN_RADIUS = 1.0      # px: a thinner strand is an apex tip or noise
PETIOLE_EVENNESS = 0.7        # width of the free third / width of the middle third, at least
PETIOLE_END = 0.5            # a petiole joins the blade in this outer share of the base's half, where the veins show which
PETIOLE_TURN = 60.0           # degrees: a petiole running more off the base-apex line is none
BASE_EXTRAPOLATION = 1.0      # of the distance back to zero width at the blade's first slope
BASE_RUN = 0.1               # the mean growth is read from twice to four times the petiole's half-width, over at most this of the extent
BASE_BACK = 0.25             # the extrapolation reaches back at most this of the extent
BASE_NECK = 0.55             # ... and not past a neck of the walk narrower than this of the petiole's median half-chord behind
NECK_REACH = 8.0             # ... lying within this many petiole half-widths before the blade widens the walk
SLIT_FLANKED = 0.5           # a petiole between lobes: the mask met again on each side at this share of the walk before the blade
SLIT_REACH = 0.1             # its colour followed at most this far (of the extent) into the sinus
SLIT_CONTRAST = 1.5          # the petiole's colour differs from the blade's by more than this of the blade's median deviation
SLIT_BLUR = 0.5              # px: the Gaussian blur of the colours compared there (the thin end of the strip not lost to it)
TIP_REACH = 0.06             # the tip's width is read this far (of the length) behind the apex
TIP_BLUR = 3.0               # working pixels: narrower parts of the tip are not measured
TIP_SLOPE = 0.8              # a tip widening faster than this (width per length) is blunt: it stays
TIP_MIN_SLOPE = 0.15         # ... and one widening slower is a stalk (a short petiole, a drip tip): it stays too
TIP_MAX = 0.04               # the tip moves on at most this (of the length)
STUB_MAX = 0.1               # a stub (a petiole too short to be found as one) is at most this long (of the length)
STUB_REACH = 0.15            # ... looked for this far (of the length) from the end
STUB_WIDTH = 0.08            # ... and at most this wide (of the blade's widest width)
STUB_MIN = 1.5               # ... running at least this many of its widths
STUB_GROWTH = 0.3            # ... and growing along them less than this of the blade's growth just past it
VEIN_SENSE = 0.03             # |vein sense| from which the veins tell the apex's end
VEIN_WEAK = 0.006             # ... and on a blade not too narrow (below) from this
VEIN_WEAK_ELONGATION = 6.0    # principal standard deviations' ratio below which the weaker sense counts
VEIN_TURN = 2.0               # the veins' sense across the principal axis / along it, from which the midrib runs across
VEIN_TURN_ELONGATION = 2.0    # ... on a blade whose principal standard deviations differ less than this (wider than long)
STALK_NEAR, STALK_FAR = 0.03, 0.09  # of the extent from an end: where a stalk's width is compared
STALK_EVEN = 0.75             # a stalk's near width / its far width, at least
SHOULDER = 1 / 3              # farthest point off the axis by this much of the width: a truncate base
OBLIQUE_REACH = 0.96          # the line from the apex through the centroid leaves a truncate base this far, at least (of the corner's distance)
SINUS_ROUND = 1.3             # a blade whose principal standard deviations differ less than this ...
SINUS_DEEP = 0.06             # ... with one sinus this deep (of its extent) inside its convex hull: that is the base
ROUND_BLADE = 1.15            # principal standard deviations closer than this: a round blade
NOTCH_DEPTH = 0.02            # of the blade's length
BLUNT_DISTANCE = 0.01         # outline points this close (of the distance) to the farthest from the base ...
BLUNT_SPREAD = 0.2            # ... spread across the midrib by more than this (of the distance): a blunt apex
OUTLINE_POINTS = 512
OUTLINE_TOLERANCE = 0.0025    # Hausdorff distance of the spline to the traced contour / length
OUTLINE_WARN = 0.005
_EIGHT = np.ones((3, 3), bool)
Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Shape:
    """What :func:`leaf_shape` finds: ``blade`` mask; ``outline`` (M, 2), ``base`` and ``apex``
    (2,), ``petiole`` (K, 2) from free end to base, in (x, y) pixels; ``warnings``."""

    blade: NDArray[np.bool_]
    outline: Array
    base: Array
    apex: Array
    petiole: Array
    warnings: tuple[str, ...]


# -- two leaves ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TwoBlades:
    """The cut of :func:`two_blades`: the pieces' shares of the area (larger first), the less
    convex piece's solidity and the cut's length ÷ the convex hull's diameter."""

    shares: tuple[float, float]
    solidity: float
    cut: float


def _sinus_points(ring: Array, hull: Polygon, floor: float) -> list[int]:
    """Index of the deepest point of each run of ``ring`` deeper than ``floor`` inside ``hull``."""
    depth = np.asarray(shapely.distance(shapely.points(ring), hull.exterior), np.float64)
    inside = depth > floor
    if not inside.any() or inside.all():
        return []
    order = np.roll(np.arange(len(ring)), -int(np.argmin(inside)))     # start on the hull: no run wraps
    found: list[int] = []
    at = -1
    for i in order:
        if inside[i]:
            at = int(i) if at < 0 or depth[i] > depth[at] else at
        elif at >= 0:
            found.append(at)
            at = -1
    return found + ([at] if at >= 0 else [])


def two_blades(outline: Array) -> TwoBlades | None:
    """The cut that parts the closed ``outline`` ((M, 2), any frame) into two convex blades, or
    None for one leaf (see the module docstring)."""
    ring = np.asarray(outline, np.float64)
    region = Polygon(ring).buffer(0)
    hull = region.convex_hull
    if not (region.area > 0.0 and len(ring) >= 8):
        return None
    corners = np.asarray(hull.exterior.coords)
    diameter = float(np.max(np.hypot(*(corners[:, None, :] - corners[None, :, :]).transpose(2, 0, 1))))
    sinuses = sorted(_sinus_points(ring, hull, BLADES_SINUS * diameter))
    best: TwoBlades | None = None
    for k, i in enumerate(sinuses):
        for j in sinuses[k + 1:]:
            cut = float(np.hypot(*(ring[i] - ring[j]))) / diameter
            pieces = [Polygon(ring[i:j + 1]).buffer(0), Polygon(np.vstack([ring[j:], ring[:i + 1]])).buffer(0)]
            if cut > BLADES_CUT or min(p.area for p in pieces) <= 0.0:
                continue
            shares = sorted((p.area / region.area for p in pieces), reverse=True)
            solidity = min(p.area / p.convex_hull.area for p in pieces)
            if shares[1] >= BLADES_SHARE and solidity >= BLADES_SOLIDITY and (best is None or solidity > best.solidity):
                best = TwoBlades((shares[0], shares[1]), solidity, cut)
    return best


def split_shares(mask: NDArray[np.bool_]) -> list[float]:
    """Shares of the mask's area (largest first) of the parts it falls into at narrow necks (see
    the module docstring); ``[1.0]`` for one leaf."""
    rows, cols = np.nonzero(mask)
    crop = mask[rows.min():rows.max() + 1, cols.min():cols.max() + 1]
    g = max(1, math.ceil(max(crop.shape) / SPLIT_SIDE))
    if g > 1:
        h, w = -(-crop.shape[0] // g) * g, -(-crop.shape[1] // g) * g
        crop = np.pad(crop, ((0, h - crop.shape[0]), (0, w - crop.shape[1])))
        crop = crop.reshape(h // g, g, w // g, g).mean(axis=(1, 3)) >= 0.5
    crop = np.pad(crop, 1)
    d = ndimage.distance_transform_edt(crop)
    top = float(d.max())
    if top < 2:
        return [1.0]
    peaks = (d == ndimage.maximum_filter(d, size=max(3, 2 * int(0.3 * top) + 1))) & (d >= top / 3)
    markers, n = ndimage.label(peaks, structure=_EIGHT)
    if n < 2:
        return [1.0]
    basins = watershed(-d, markers, mask=crop)
    peak = np.asarray(ndimage.maximum(d, basins, np.arange(1, n + 1)), np.float64)
    saddle = np.zeros((n + 1, n + 1))
    for a, b, da, db in ((basins[:, :-1], basins[:, 1:], d[:, :-1], d[:, 1:]),
                         (basins[:-1], basins[1:], d[:-1], d[1:])):
        edge = (a != b) & (a > 0) & (b > 0)
        np.maximum.at(saddle, (a[edge], b[edge]), np.minimum(da[edge], db[edge]))
    saddle = np.maximum(saddle, saddle.T)
    parent = list(range(n + 1))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in zip(*np.nonzero(np.triu(saddle))):
        if saddle[i, j] >= NECK_RATIO * min(peak[i - 1], peak[j - 1]):
            parent[root(int(i))] = root(int(j))
    areas = np.bincount(basins.ravel(), minlength=n + 1).astype(np.float64)
    groups: dict[int, float] = {}
    for i in range(1, n + 1):
        groups[root(i)] = groups.get(root(i), 0.0) + areas[i]
    total = sum(groups.values())
    if len(groups) > 1:
        (a, _), (b, _) = sorted(groups.items(), key=lambda kv: -kv[1])[:2]
        owner = np.array([0] + [root(i) for i in range(1, n + 1)])[basins]
        part_a, part_b = owner == a, owner == b
        neck = part_a & ndimage.binary_dilation(part_b, _EIGHT)
        ends = neck & ndimage.binary_dilation(~crop, _EIGHT)
        hull = ndimage.distance_transform_edt(convex_hull_image(crop))
        depth = float(hull[ends].max()) if ends.any() else 0.0
        peak_b = float(d[part_b].max())
        if depth < NECK_NOTCH * peak_b or neck.sum() > NECK_LENGTH * peak_b:   # no pinch where they meet: one leaf
            groups[a] += groups.pop(b)
    return sorted((v / total for v in groups.values()), reverse=True)


# -- B-spline outline ---------------------------------------------------------------------------------------
def _basis(u: Array) -> Array:
    """Uniform cubic B-spline weights (len(u), 4) of control points j .. j+3 in span j."""
    u2, u3 = u * u, u * u * u
    return np.stack([(1 - u) ** 3, 3 * u3 - 6 * u2 + 4, -3 * u3 + 3 * u2 + 3 * u + 1, u3], axis=1) / 6


def _resample(points: Array, count: int) -> Array:
    """``count`` points evenly spaced by arc length along the closed polygon ``points``."""
    closed = np.vstack([points, points[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])
    t = np.arange(count) * (s[-1] / count)
    return np.stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])], axis=1)


def _lsq_controls(samples: Array, n: int, smooth: float = 1e-4) -> Array:
    """Control points (n, 2) of the periodic uniform cubic B-spline closest in least squares to
    ``samples`` (n·k, 2) taken at parameters i / (n·k). With k samples per span the normal
    matrix is circulant, so it is solved exactly with FFTs; a small second-difference penalty on
    the control polygon (``smooth`` × k) keeps it well posed."""
    k = len(samples) // n
    w = _basis(np.arange(k) / k)                         # (k, 4)
    gram = w.T @ w
    kernel = np.zeros(n)
    for a in range(4):
        for b in range(4):
            kernel[(b - a) % n] += gram[a, b]
    kernel[[0, 1, 2, -1, -2]] += smooth * k * np.array([6.0, -4.0, 1.0, -4.0, 1.0])
    per_span = np.einsum("ua,jud->jad", w, samples.reshape(n, k, 2))   # (n, 4, 2)
    rhs = np.sum([np.roll(per_span[:, a], a, axis=0) for a in range(4)], axis=0)
    return np.real(np.fft.ifft(np.fft.fft(rhs, axis=0) / np.fft.fft(kernel)[:, None], axis=0))


def eval_closed_bspline(controls: Array, t: Array) -> Array:
    """Points of the periodic uniform cubic B-spline with ``controls`` (n, 2) at parameters ``t``
    (period 1)."""
    n = len(controls)
    x = np.mod(t, 1.0) * n
    j = np.minimum(np.floor(x).astype(np.int64), n - 1)
    w = _basis(x - j)
    return np.asarray(np.einsum("ka,kad->kd", w, controls[(j[:, None] + np.arange(4)) % n]), np.float64)


def fit_closed_bspline(contour: Array, tolerance: float, spacing: float = 0.5) -> tuple[Array, float]:
    """A smooth closed curve through a traced contour (N, 2): ``(controls, hausdorff)``.

    This is the inverse subdivision of Mündermann et al. (2003, sec. 3.1) done in one step: they
    coarsen the traced polygon by repeatedly undoing a B-spline subdivision step, which leaves a
    control polygon whose B-spline approximates the contour. Here the contour (one vertex per
    pixel edge it crosses) is simplified to samples evenly spaced by arc length, at most
    ``spacing`` apart, and the periodic uniform cubic B-spline with n control points that is closest to them in
    least squares is solved for directly (:func:`_lsq_controls`), for n = 64, 128, ... until the
    symmetric Hausdorff distance to the samples is within ``tolerance`` (or n reaches 1024, or a
    span would be shorter than six samples)."""
    simple = contour
    perimeter = float(np.hypot(*np.diff(np.vstack([simple, simple[:1]]), axis=0).T).sum())
    n, best = 64, None
    while True:
        k = max(4, math.ceil(perimeter / (n * spacing)))
        dense = _resample(simple, n * k)
        controls = _lsq_controls(dense, n)
        curve = eval_closed_bspline(controls, np.arange(n * k) / (n * k))
        dist = max(float(cKDTree(curve).query(dense)[0].max()), float(cKDTree(dense).query(curve)[0].max()))
        if best is None or dist < best[1]:
            best = (controls, dist)
        if dist <= tolerance or n >= 1024 or 12 * n * spacing > perimeter:
            return best
        n *= 2


def _contour(blade: NDArray[np.bool_]) -> Array:
    """The blade's outer boundary (N, 2) in (x, y), traced by marching squares at 0.5 on the
    filled mask smoothed by a Gaussian of 0.7 px."""
    rows, cols = np.nonzero(blade)
    y0, x0 = int(rows.min()) - 3, int(cols.min()) - 3
    crop = np.pad(blade, 3)[y0 + 3:int(rows.max()) + 7, x0 + 3:int(cols.max()) + 7]
    smooth = ndimage.gaussian_filter(ndimage.binary_fill_holes(crop).astype(np.float32), 0.7)
    contours = find_contours(smooth, 0.5)
    c = max(contours, key=len)
    return np.stack([c[:, 1] + x0, c[:, 0] + y0], axis=1)[:-1]


# -- petiole ----------------------------------------------------------------------------------------------
def _skeleton_path(piece: NDArray[np.bool_]) -> Array:
    """The longest path (K, 2) in (row, col) through the skeleton of ``piece``."""
    sk = skeletonize(piece)
    rc = np.argwhere(sk)
    if len(rc) < 2:
        return rc.astype(np.float64)
    index = -np.ones(sk.shape, np.int64)
    index[rc[:, 0], rc[:, 1]] = np.arange(len(rc))
    src, dst, wt = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        r2, c2 = rc[:, 0] + dr, rc[:, 1] + dc
        ok = (r2 < sk.shape[0]) & (c2 >= 0) & (c2 < sk.shape[1])
        nb = np.full(len(rc), -1)
        nb[ok] = index[r2[ok], c2[ok]]
        has = nb >= 0
        src.append(np.nonzero(has)[0])
        dst.append(nb[has])
        wt.append(np.full(int(has.sum()), math.hypot(dr, dc)))
    graph = coo_matrix((np.concatenate(wt), (np.concatenate(src), np.concatenate(dst))), shape=(len(rc),) * 2)
    d0 = dijkstra(graph, directed=False, indices=0)
    a = int(np.argmax(np.where(np.isfinite(d0), d0, -1)))
    da, pred = dijkstra(graph, directed=False, indices=a, return_predecessors=True)
    b = int(np.argmax(np.where(np.isfinite(da), da, -1)))
    path = [b]
    while path[-1] != a:
        path.append(int(pred[path[-1]]))
    return rc[path].astype(np.float64)


def _half_chords(mask: NDArray[np.bool_], points: Array, normals: Array, reach: float) -> Array:
    """Half the length of the mask's chord through each point (x, y) along its normal."""
    ts = np.arange(-reach, reach + 0.25, 0.5)
    c = len(ts) // 2
    xy = points[:, None, :] + ts[None, :, None] * normals[:, None, :]
    inside = ndimage.map_coordinates(mask, [xy[..., 1], xy[..., 0]], order=0, mode="constant", cval=0).astype(bool)
    right = np.where(inside[:, c:].all(axis=1), len(ts) - c, np.argmin(inside[:, c:], axis=1))
    left = np.where(inside[:, c::-1].all(axis=1), c + 1, np.argmin(inside[:, c::-1], axis=1))
    return np.where(inside[:, c], (right + left - 1) * 0.25, 0.0)


def _walk(path: Array, axis: Array, extra: float) -> tuple[Array, Array]:
    """Points at 1 px spacing along ``path`` (K, 2) then straight on along ``axis`` for ``extra``
    px, with their unit tangents."""
    seg = np.hypot(*np.diff(path, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.arange(0.0, s[-1], 1.0)
    pts = np.stack([np.interp(t, s, path[:, 0]), np.interp(t, s, path[:, 1])], axis=1)
    pts = np.vstack([pts, path[-1] + np.arange(0.0, extra, 1.0)[:, None] * axis])
    tan = np.gradient(ndimage.uniform_filter1d(pts, 7, axis=0, mode="nearest"), axis=0)
    tan /= np.maximum(np.hypot(*tan.T), 1e-9)[:, None]
    return pts, tan


@dataclass(frozen=True)
class _Petiole:
    path: Array                 # (K, 2) x, y along the skeleton, from the free end to the blade
    radii: Array                # (K,) the mask's distance transform along it
    pixels: NDArray[np.bool_]   # the piece the opening removed (petiole and whatever blade tip came with it)
    radius: float               # median half-width of its middle third
    length: float


def _opened(mask: NDArray[np.bool_], edt: Array) -> NDArray[np.bool_]:
    """The largest component of ``mask`` opened by a disc of :data:`PETIOLE_RADIUS` times its
    largest inscribed radius (an erosion and a dilation, each a threshold of a distance transform)."""
    r = max(1.5, PETIOLE_RADIUS * float(edt.max()))
    opened = ndimage.distance_transform_edt(edt <= r) <= r
    lab, n = ndimage.label(opened, structure=_EIGHT)
    if n == 0:
        return opened
    return np.asarray(lab == int(np.argmax(np.bincount(lab.ravel())[1:]) + 1), bool)


def _find_petiole(fine: NDArray[np.bool_], core: NDArray[np.bool_], extent: float) -> _Petiole | None:
    """The petiole among the pieces of ``fine`` outside ``core`` (the opened blade, at the same
    resolution), or None (module docstring). Each piece is measured in a window of its own."""
    thin, _ = ndimage.label(fine & ~core, structure=_EIGHT)
    best: _Petiole | None = None
    for i, sl in enumerate(ndimage.find_objects(thin), start=1):
        if sl is None or math.hypot(sl[0].stop - sl[0].start, sl[1].stop - sl[1].start) < PETIOLE_MIN_LENGTH * extent:
            continue
        m = 4
        r0, c0 = max(sl[0].start - m, 0), max(sl[1].start - m, 0)
        win = np.s_[r0:sl[0].stop + m, c0:sl[1].stop + m]
        piece = thin[win] == i
        touch = np.argwhere(piece & ndimage.binary_dilation(core[win], _EIGHT))
        if len(touch) == 0:
            continue
        rc = _skeleton_path(piece)
        if len(rc) < 6:
            continue
        if np.hypot(*(rc[0] - touch.mean(0))) < np.hypot(*(rc[-1] - touch.mean(0))):
            rc = rc[::-1]                                          # free end first
        edt = ndimage.distance_transform_edt(np.pad(fine[win], 1, mode="edge"))[1:-1, 1:-1]
        radii = edt[rc[:, 0].astype(int), rc[:, 1].astype(int)]
        third = len(rc) // 3
        rho = float(np.median(radii[third:2 * third]))
        length = float(np.hypot(*np.diff(rc, axis=0).T).sum()) + rho
        if (rho < PETIOLE_MIN_RADIUS or length < PETIOLE_MIN_LENGTH * extent or length < 8 * rho
                or float(np.median(radii[:third])) < PETIOLE_EVENNESS * rho):
            continue
        if best is None or length > best.length:
            pixels = np.zeros_like(fine)
            pixels[win] = piece
            best = _Petiole((rc + (r0, c0))[:, ::-1].copy(), radii, pixels, rho, length)
    return best


def _extend_free_end(mask: NDArray[np.bool_], path: Array) -> Array:
    """``path`` with its first point moved on, in the direction it ends in, to the mask's edge."""
    d = path[0] - path[min(5, len(path) - 1)]
    d /= max(float(np.hypot(*d)), 1e-9)
    steps = path[0] + np.arange(0.5, 4 * len(path), 0.5)[:, None] * d
    ij = np.rint(steps[:, ::-1]).astype(int)
    ok = (ij >= 0).all(1) & (ij[:, 0] < mask.shape[0]) & (ij[:, 1] < mask.shape[1])
    inside = ok.copy()
    inside[ok] = mask[ij[ok, 0], ij[ok, 1]]
    run = int(np.argmin(inside)) if not inside.all() else len(inside)
    return path if run == 0 else np.vstack([steps[run - 1], path])


def _first_wide(half: Array, begin: int, rho: float) -> int | None:
    """The first index from ``begin`` where the half-chord exceeds twice the petiole's half-width
    and stays above it for the next few pixels (not one noisy sample), or None."""
    over = half[begin:] > 2 * rho + 0.5
    n = max(3, int(round(rho)))
    if len(over) < n:
        return None
    held = np.nonzero(np.convolve(over, np.ones(n), "valid") >= n)[0]
    return begin + int(held[0]) if len(held) else None


def _gap(half: Array, begin: int, rho: float) -> int:
    """How many steps of the walk from index ``begin`` lie outside the mask before the blade
    widens it past twice the petiole's half-width."""
    wide = _first_wide(half, begin, rho)
    return int(np.count_nonzero(half[begin:len(half) if wide is None else wide] == 0))


def _flanked(mask: NDArray[np.bool_], pts: Array, tan: Array, reach: float) -> bool:
    """Whether, at most of the walk's ``pts`` (x, y; ``tan`` their unit tangents), the mask is
    left on both sides and met again within ``reach``: a petiole running between two lobes."""
    ts = np.arange(0.0, reach + 0.25, 0.5)
    normals = np.stack([-tan[:, 1], tan[:, 0]], axis=1)
    for sign in (1.0, -1.0):
        xy = pts[:, None, :] + sign * ts[None, :, None] * normals[:, None, :]
        inside = ndimage.map_coordinates(mask, [xy[..., 1], xy[..., 0]], order=0, mode="constant", cval=0).astype(bool)
        left = np.argmin(inside, axis=1)
        again = (inside & (np.arange(len(ts))[None, :] > left[:, None])).any(axis=1) & ~inside.all(axis=1)
        if again.mean() < SLIT_FLANKED:
            return False
    return True


def _hidden_base(colour: NDArray[np.floating], mask: NDArray[np.bool_], pts: Array, tan: Array, i: int,
                 start: int, rho: float, extent: float) -> Array | None:
    """Where a petiole lying in a narrow cordate sinus ends, the sinus' walls meeting over it
    beyond where the mask shows (the walk ``pts`` first widens at index ``i``; ``start`` is where
    its even part begins), or None: the farthest pixel ahead of the petiole's colour (closer to
    its median colour along the walk than to the blade's median round it, after a Gaussian blur of
    :data:`SLIT_BLUR` px), connected to the walk at ``i`` within a corridor widening at 1:2 from
    the petiole's width, at most :data:`SLIT_REACH` of the extent ahead. None too where the two
    colours differ by less than :data:`SLIT_CONTRAST` times the blade's median deviation from its own."""
    reach = int(SLIT_REACH * extent + 4 * rho) + 2
    cx, cy = (int(round(v)) for v in pts[i])
    y0, x0 = max(cy - reach, 0), max(cx - reach, 0)
    win = np.s_[y0:cy + reach + 1, x0:cx + reach + 1]
    m = mask[win]
    rgb = np.stack([ndimage.gaussian_filter(np.asarray(colour[win + (c,)], np.float32), SLIT_BLUR) for c in range(3)],
                   axis=-1)
    along = np.rint(pts[start:max(start + 1, i - int(rho) - 2)] - (x0, y0)).astype(int)
    ok = (along >= 0).all(1) & (along[:, 0] < m.shape[1]) & (along[:, 1] < m.shape[0])
    if ok.sum() < 3:
        return None
    own = np.median(rgb[along[ok, 1], along[ok, 0]], axis=0)
    yy, xx = np.mgrid[:m.shape[0], :m.shape[1]]
    d = tan[i]
    rx, ry = xx + x0 - pts[i][0], yy + y0 - pts[i][1]
    ahead, lat = rx * d[0] + ry * d[1], ry * d[0] - rx * d[1]
    ring = m & (np.hypot(ahead, lat) > 4 * rho + 2) & (ahead > 0)
    if ring.sum() < 10:
        return None
    blade = np.median(rgb[ring], axis=0)
    spread = float(np.median(np.linalg.norm(rgb[ring] - blade, axis=-1)))
    if float(np.linalg.norm(own - blade)) <= SLIT_CONTRAST * spread:
        return None                       # the petiole's colour is not told from the blade's
    like = (m & (np.linalg.norm(rgb - own, axis=-1) < np.linalg.norm(rgb - blade, axis=-1))
            & (np.abs(lat) <= rho + 2 + 0.5 * np.maximum(ahead, 0)) & (ahead > -2 * rho - 2)
            & (ahead <= SLIT_REACH * extent))
    lab, _ = ndimage.label(like)
    r, c = (int(round(v)) for v in pts[i - 1][::-1] - (y0, x0))
    if not (0 <= r < m.shape[0] and 0 <= c < m.shape[1]) or lab[r, c] == 0:
        return None
    k = int(np.argmax(np.where(lab == lab[r, c], ahead, -np.inf)))
    if ahead.flat[k] <= 0:
        return None
    return np.array([xx.flat[k] + x0, yy.flat[k] + y0], np.float64)


def _petiole_base(mask: NDArray[np.bool_], pet: _Petiole, extent: float, base: Array | None,
                  colour: NDArray[np.floating] | None = None) -> tuple[Array, Array, Array]:
    """(base, petiole polyline from its free end to the base, unit direction into the blade).
    ``colour`` (the photo aligned with ``mask``, RGB), where given, finds a petiole's end hidden in a
    narrow cordate sinus (:func:`_hidden_base`)."""
    rho = max(pet.radius, 0.75)
    odd = np.nonzero((pet.radii > 1.5 * rho + 0.5) | (pet.radii < min(0.75 * rho, rho - 1)))[0]
    odd = odd[odd >= len(pet.radii) // 3]          # where the centre line leaves the even petiole
    path = _extend_free_end(mask, pet.path[:int(odd[0])] if len(odd) else pet.path)
    back = path[-min(len(path), int(3 * rho) + 4)]
    direction = path[-1] - back
    direction /= max(float(np.hypot(*direction)), 1e-9)
    pts, tan = _walk(path, direction, 0.4 * extent)
    if base is None:
        half = _half_chords(mask, pts, np.stack([-tan[:, 1], tan[:, 0]], axis=1), 8 * rho + 4)
        joint = pet.path[-1] - path[-1]            # where the whole centre line meets the blade
        gap = _gap(half, len(path), rho)
        if gap > 0 and float(np.hypot(*joint)) > 2 * rho:
            # a curved petiole: straight on along its last tangent leaves the mask, so aim at the
            # joint instead, where that way lies outside the mask for less than half as long
            pts2, tan2 = _walk(path, joint / float(np.hypot(*joint)), 0.4 * extent)
            half2 = _half_chords(mask, pts2, np.stack([-tan2[:, 1], tan2[:, 0]], axis=1), 8 * rho + 4)
            if 2 * _gap(half2, len(path), rho) < gap:
                pts, tan, half = pts2, tan2, half2
        start = int(np.hypot(*np.diff(path, axis=0).T).sum()) // 3     # not at the free end
        wide_at = _first_wide(half, start, rho)
        i = wide_at if wide_at is not None else len(path) - 1
        wide = np.nonzero(half[i:] > 4 * rho + 1)[0]
        end = i + min(max(int(wide[0]) + 1 if len(wide) else len(half), 3), int(BASE_RUN * extent) + 1)
        back_px = 0.0
        for run, cap in ((half[i:i + int(3 * rho) + 3], 4 * rho + 2), (half[i:end], BASE_BACK * extent)):
            slope = float(np.polyfit(np.arange(len(run)), run, 1)[0]) if len(run) >= 3 else 0.0
            if i > 0 and (cap < 4 * rho + 3 or half[i] - half[max(i - 3, 0)] > rho):
                # a jump (rounded or cordate base) is not extrapolated
                slope = max(slope, half[i] - half[i - 1], (half[min(i + 1, len(half) - 1)] - half[i - 1]) / 2)
            if slope > 0:
                back_px = max(back_px, min(BASE_EXTRAPOLATION * half[i] / slope, cap))
        k = max(0, i - int(round(back_px)))
        behind = half[start:k][half[start:k] > 0]        # the petiole walked before the extrapolated base
        near = max(k, i - int(round(NECK_REACH * rho)))
        neck = (np.nonzero((half[near:i] > 0) & (half[near:i] < BASE_NECK * float(np.median(behind))))[0]
                if len(behind) >= 3 else np.zeros(0, np.intp))
        if len(neck):
            k = near + int(neck[-1])                # not back past a neck where the petiole joins the blade
        flank = pts[max(i - int(3 * rho) - 3, 0):i], tan[max(i - int(3 * rho) - 3, 0):i]
        if (colour is not None and wide_at is not None and i > 3 and half[i] - half[i - 3] > rho
                and len(flank[0]) >= 3 and _flanked(mask, *flank, 8 * rho + 4)):
            hidden = _hidden_base(colour, mask, pts, tan, i, start, rho, extent)
            if hidden is not None:        # the petiole's end in a narrow cordate sinus
                line = np.vstack([approximate_polygon(pts[:k + 1], tolerance=0.3), hidden[None]])
                return hidden, line, tan[k]
    else:
        k = int(np.argmin(np.hypot(*(pts - base).T)))
    found = pts[k] if base is None else base
    line = np.vstack([approximate_polygon(pts[:k + 1], tolerance=0.3), found[None]])
    return found, line, tan[k]


# -- base and apex without a petiole ---------------------------------------------------------------------------
def _axis(blade: NDArray[np.bool_]) -> tuple[Array, Array]:
    """(centroid, unit principal axis) of the mask's pixels, in (x, y)."""
    c, vec, _ = _moments(blade)
    return c, vec


def _moments(blade: NDArray[np.bool_]) -> tuple[Array, Array, float]:
    """(centroid, unit principal axis, ratio of the principal standard deviations ≥ 1)."""
    yx = np.argwhere(blade).astype(np.float64)
    c = yx.mean(axis=0)
    values, vectors = np.linalg.eigh(np.cov((yx - c).T))
    return c[::-1].copy(), vectors[:, -1][::-1].copy(), float(np.sqrt(values[-1] / max(values[0], 1e-12)))


def _frame(contour: Array, centre: Array, axis: Array) -> tuple[Array, Array]:
    """Projections of the contour on the axis and across it."""
    rel = contour - centre
    return rel @ axis, rel @ np.array([-axis[1], axis[0]])


def _width_at(s: Array, lat: Array, at: float, step: float) -> float:
    """The contour's extent across the axis within ``step`` of projection ``at``."""
    band = np.abs(s - at) <= step
    return float(lat[band].max() - lat[band].min()) if band.sum() >= 2 else 0.0


def _sign_changes(lat: Array) -> NDArray[np.intp]:
    """Indices of the closed contour's edges (point i to i + 1) whose ends lie on either side of
    the line ``lat`` = 0."""
    return np.nonzero(np.sign(lat) != np.sign(np.roll(lat, -1)))[0]


def _crossing_points(contour: Array, s: Array, lat: Array, cross: NDArray[np.intp]) -> tuple[Array, Array]:
    """Where the contour's edges ``cross`` meet the line ``lat`` = 0: their positions along it
    (``s``, linearly interpolated) and the points themselves."""
    nxt = (cross + 1) % len(contour)
    w = lat[cross] / np.where(lat[cross] == lat[nxt], 1.0, lat[cross] - lat[nxt])
    return s[cross] + w * (s[nxt] - s[cross]), contour[cross] + w[:, None] * (contour[nxt] - contour[cross])


def _end_point(contour: Array, s: Array, lat: Array, low: bool, hull: Array) -> tuple[Array, float]:
    """One end of the blade along its axis: the point where the axis line crosses the contour
    there, and how deep that point lies inside the contour's convex hull (``hull``: its facet
    equations). A deep one is a notch, and the point becomes the deepest contour point near it (a
    cordate base's sinus)."""
    cross = _sign_changes(lat)
    if len(cross) == 0:
        cross = np.array([int(np.argmin(np.abs(lat)))])
    sc, points = _crossing_points(contour, s, lat, cross)
    point = points[int(np.argmin(sc)) if low else int(np.argmax(sc))]
    depth = float(-np.max(hull[:, :2] @ point + hull[:, 2]))
    extent = float(s.max() - s.min())
    if depth > NOTCH_DEPTH * extent:
        inside = -np.max(contour @ hull[:, :2].T + hull[:, 2], axis=1)
        near = np.hypot(*(contour - point).T) <= max(2 * depth, 0.05 * extent)
        k = int(np.argmax(np.where(near, inside, -np.inf)))
        point, depth = contour[k], float(inside[k])
    return np.asarray(point, np.float64).copy(), depth


def _vein_sense(grey: NDArray[np.float32] | None, blade: NDArray[np.bool_], centre: Array,
                axis: Array) -> tuple[float, float]:
    """Which way the secondary veins point along the axis, from -1 (towards -axis) to 1, and the
    same along the axis turned by +90° (x right, y down: (-axis_y, axis_x)).

    Pinnate secondary veins leave the midrib at an acute angle opening towards the apex, a
    chevron. Across a vein the brightness gradient (g_s, g_l) in the axis frame (along, across)
    is perpendicular to the vein, so a vein at angle φ to the axis has g_s·g_l ∝ -sin φ cos φ,
    whose sign flips between the two sides of the midrib. The gradient products summed over each
    side of the axis (the blade's edge excluded), differenced and normalised by the gradient
    energy, give the sense; ~0 when no veins show. Along the turned axis the halves are the base's
    and the apex's, where both sides of the midrib agree, so the sums cancel unless the midrib runs
    across the first axis (a blade wider than long): then that one is the clear one."""
    if grey is None:
        return 0.0, 0.0
    inner = ndimage.binary_erosion(blade, _EIGHT, iterations=3)
    if inner.sum() < 50:
        return 0.0, 0.0
    gy, gx = ndimage.sobel(grey, axis=0), ndimage.sobel(grey, axis=1)
    yx = np.argwhere(inner)
    gxs, gys = gx[inner], gy[inner]
    g_s, g_l = gxs * axis[0] + gys * axis[1], -gxs * axis[1] + gys * axis[0]
    rel = yx[:, ::-1] - centre
    side, ahead = np.sign(rel @ np.array([-axis[1], axis[0]])), np.sign(rel @ axis)
    energy = float(np.sum(g_s * g_s + g_l * g_l))
    if energy <= 0:
        return 0.0, 0.0
    return float(-np.sum(side * g_s * g_l) / energy), float(-np.sum(ahead * g_s * g_l) / energy)


def _stalk_end(s: Array, lat: Array, extent: float, step: float) -> int | None:
    """0 (the low end along the axis) or 1 where one end of the blade is a stalk and the other
    tapers, else None. A stalk (a petiole too wide or too short to be found as one) keeps its
    width from :data:`STALK_NEAR` to :data:`STALK_FAR` of the extent in (the near width at least
    :data:`STALK_EVEN` of the far one); a tapering end narrows towards its end."""
    even = []
    for end, sense in ((float(s.min()), 1.0), (float(s.max()), -1.0)):
        near, far = (_width_at(s, lat, end + sense * k * extent, step) for k in (STALK_NEAR, STALK_FAR))
        if far <= 0.0:
            return None
        even.append(near >= STALK_EVEN * far)
    return None if even[0] == even[1] else (0 if even[0] else 1)


def _lone_sinus(contour: Array, hull: Array, extent: float) -> Array | None:
    """The deepest contour point inside the convex hull (``hull``: its facet equations) where it
    lies deeper than :data:`SINUS_DEEP` of ``extent`` and no point farther than a quarter of
    ``extent`` from it lies half as deep (one sinus, not lobes), else None."""
    inside = -np.max(contour @ hull[:, :2].T + hull[:, 2], axis=1)
    k = int(np.argmax(inside))
    if inside[k] <= SINUS_DEEP * extent:
        return None
    away = np.hypot(*(contour - contour[k]).T) > 0.25 * extent
    if away.any() and float(inside[away].max()) >= 0.5 * float(inside[k]):
        return None
    return np.asarray(contour[k], np.float64).copy()


def _base_without_petiole(contour: Array, centre: Array, axis: Array, apex: Array | None, step: float,
                          veins: float, elongation: float = np.inf) -> tuple[Array, str | None]:
    """The base of a blade with no petiole (module docstring) and a warning when it is a guess.
    ``veins`` is :func:`_vein_sense` (positive: the apex lies towards +axis); ``elongation`` the
    ratio of the blade's principal standard deviations."""
    s, lat = _frame(contour, centre, axis)
    extent = float(s.max() - s.min())
    hull = ConvexHull(contour).equations
    if apex is None and elongation < SINUS_ROUND and (sinus := _lone_sinus(contour, hull, extent)) is not None:
        return sinus, None                            # a roundish blade's one deep sinus, wherever its axis runs
    (lo, dlo), (hi, dhi) = _end_point(contour, s, lat, True, hull), _end_point(contour, s, lat, False, hull)
    ends, notch = [lo, hi], [dlo, dhi]
    near = [_width_at(s, lat, float(s.min()) + 0.1 * extent, step), _width_at(s, lat, float(s.max()) - 0.1 * extent, step)]
    note = None
    if apex is not None:
        b = int(np.argmax([np.hypot(*(e - apex)) for e in ends]))
    elif abs(veins) >= (VEIN_SENSE if elongation >= VEIN_WEAK_ELONGATION else VEIN_WEAK):
        b = 0 if veins > 0 else 1
    elif max(notch) > NOTCH_DEPTH * extent and min(notch) < 0.5 * NOTCH_DEPTH * extent:
        b = int(np.argmax(notch))
    elif max(near) > 1.15 * max(min(near), 1e-9):
        b = int(np.argmax(near))
    elif (stalk := _stalk_end(s, lat, extent, step)) is not None:
        b = stalk
        note = ("the base was told from the apex by a stalk at one end only (a petiole not found as one): "
                "check it, or give --base and --apex")
    else:
        ss = np.linspace(float(s.min()), float(s.max()), 41)[1:-1]
        widest = float(ss[int(np.argmax([_width_at(s, lat, x, step) for x in ss]))])
        b = 0 if widest - s.min() < s.max() - widest else 1
        note = ("the base was told from the apex by the widest part of the blade only (the two ends are alike): "
                "check it, or give --base and --apex")
    if notch[b] > NOTCH_DEPTH * extent:
        return ends[b], note                          # a cordate base's sinus
    towards = axis if b == 1 else -axis              # from the centre to the base end
    tip = apex if apex is not None else _apex(contour, ends[b], -towards)
    far = _apex(contour, tip, towards, 60.0)         # a pointed or rounded base: farthest from the apex
    widest = max(_width_at(s, lat, x, step) for x in np.linspace(s.min(), s.max(), 21)[1:-1])
    if abs(float((far - centre) @ np.array([-axis[1], axis[0]]))) > SHOULDER * widest:
        return ends[b], note                          # that is a shoulder of a truncate base: its middle
    ray = centre - tip
    ray /= max(float(np.hypot(*ray)), 1e-9)
    if abs(float((far - tip) @ np.array([-ray[1], ray[0]]))) > SHOULDER * widest:
        mid = _ray_exit(contour, tip, ray)
        if float(np.hypot(*(mid - tip))) >= OBLIQUE_REACH * float(np.hypot(*(far - tip))):
            return mid, note                          # a corner of an oblique truncate base: the midrib's end
    stub = _stub_root(contour, tip, far, widest, step)
    if stub is not None:
        return stub, note                             # a petiole stub too short to be found as a petiole
    return _taper_tip(contour, tip, far, step), note  # a wedge's point thinner than the segmentation resolves


def _ray_exit(contour: Array, origin: Array, ray: Array) -> Array:
    """The farthest point where the line from ``origin`` along the unit ``ray`` crosses the contour."""
    s, lat = _frame(contour, origin, ray)
    cross = _sign_changes(lat)
    cross = cross[s[cross] > 0]
    if len(cross) == 0:
        return contour[int(np.argmax(np.where(s > 0, s - np.abs(lat), -np.inf)))].copy()
    sc, points = _crossing_points(contour, s, lat, cross)
    return np.asarray(points[int(np.argmax(sc))], np.float64)


def _hinge(t: Array, w: Array) -> tuple[int, float, float]:
    """The index k splitting ``w(t)`` into two straight pieces, [0, k) and [k, n), with the least
    squared error, and the two pieces' slopes (cumulative sums: one pass for every k)."""
    n = len(t)
    def sums(x: Array, y: Array) -> tuple[Array, ...]:
        z = np.zeros(1)
        return tuple(np.concatenate([z, np.cumsum(v)]) for v in (np.ones_like(x), x, y, x * x, x * y, y * y))
    def fit(c: tuple[Array, ...], a: NDArray[np.intp], b: NDArray[np.intp]) -> tuple[Array, Array]:
        m, sx, sy, sxx, sxy, syy = (v[b] - v[a] for v in c)
        vx = np.maximum(sxx - sx * sx / m, 1e-12)
        cxy = sxy - sx * sy / m
        return cxy / vx, np.maximum(syy - sy * sy / m - cxy * cxy / vx, 0.0)
    c = sums(t, w)
    k = np.arange(4, n - 3)
    left, e_left = fit(c, np.zeros_like(k), k)
    right, e_right = fit(c, k, np.full_like(k, n))
    best = int(np.argmin(e_left + e_right))
    return int(k[best]), float(left[best]), float(right[best])


def _stub_root(contour: Array, apex: Array, end: Array, widest: float, f: float) -> Array | None:
    """Where a petiole stub at the blade's ``end`` (too short to be found as a petiole, or the part
    of a darker petiole the segmentation kept) meets the blade, or None where there is no stub.
    Walking from ``end`` towards ``apex`` until the contour's width across the line passes
    :data:`STUB_WIDTH` of ``widest`` (at most :data:`STUB_REACH` of the length), the width is split
    into two straight pieces (:func:`_hinge`); the first is a stub where it is narrow (its mean at
    most :data:`STUB_WIDTH` of ``widest``), runs at least :data:`STUB_MIN` of its widths and at
    most :data:`STUB_MAX` of the length, and grows less than :data:`STUB_GROWTH` of the second's
    growth (a wedge-shaped base grows evenly, or faster towards its point's blur); the blade past
    it must reach twice the stub's width. The base is the hinge."""
    length = float(np.hypot(*(apex - end)))
    if length <= 0:
        return None
    d = (end - apex) / length                       # the frame of _side_profile: the end ahead
    s, lat = _frame(contour, end, d)
    i0 = int(np.argmin(np.hypot(*(contour - end).T)))
    reach = STUB_REACH * length
    t = np.arange(0.0, reach, 0.5)
    a, b = _side_profile(s, lat, i0, 1, reach, t), _side_profile(s, lat, i0, -1, reach, t)
    width, mid = np.abs(a - b), 0.5 * (a + b)
    start = int(np.argmax(width >= 1.5 * f))        # past the blurred end
    past = np.nonzero(width[start:] > STUB_WIDTH * widest)[0]
    stop = start + int(past[0]) + 1 if len(past) else len(t)
    if stop - start < 16:
        return None
    k, stub_slope, blade_slope = _hinge(t[start:stop], width[start:stop])
    k += start
    w0 = float(np.mean(width[start:k]))
    if (w0 <= 0 or w0 > STUB_WIDTH * widest or t[k] - t[start] < STUB_MIN * w0 or t[k] > STUB_MAX * length
            or float(width[stop - 1]) < 2 * w0 + f or blade_slope <= 0 or stub_slope >= STUB_GROWTH * blade_slope):
        return None
    return np.asarray(end - t[k] * d + mid[k] * np.array([-d[1], d[0]]), np.float64)


def _apex(contour: Array, base: Array, axis: Array, cone_deg: float = 45.0) -> Array:
    """The contour point farthest from ``base`` within ``cone_deg`` of ``axis``; on a blunt end
    (the points within :data:`BLUNT_DISTANCE` of that distance spread more than
    :data:`BLUNT_SPREAD` of it across the axis, where the farthest one is a matter of noise), the
    one of those nearest the axis line."""
    s, lat = _frame(contour, base, axis)
    dist = np.hypot(s, lat)
    cone = s >= math.cos(math.radians(cone_deg)) * dist
    top = float(dist[cone].max())
    near = cone & (dist >= (1 - BLUNT_DISTANCE) * top)
    if float(np.ptp(lat[near])) > BLUNT_SPREAD * top:
        return contour[int(np.argmin(np.where(near, np.abs(lat), np.inf)))].copy()
    return contour[int(np.argmax(np.where(cone, dist, -1.0)))].copy()


def _side_profile(s: Array, lat: Array, start: int, step: int, reach: float, t: Array) -> Array:
    """The lateral offset at distances ``t`` behind the apex of one side of the contour, walked
    from index ``start`` in direction ``step`` until it lies ``reach`` behind the apex."""
    order = np.roll(np.arange(len(s)), -start)[::step] if step > 0 else np.roll(np.arange(len(s))[::-1], start + 1)
    back = -s[order]
    stop = int(np.argmax(back > reach)) if (back > reach).any() else len(back)
    back, side = np.maximum.accumulate(back[:max(stop + 1, 2)]), lat[order][:max(stop + 1, 2)]
    return np.interp(t, back, side)


def _taper_tip(contour: Array, base: Array, apex: Array, f: float) -> Array:
    """The apex moved on to where the tip's sides meet, when the tip tapers to a point narrower
    than the segmentation resolves (a thin acuminate tip's last pixels are lighter than the
    threshold). The width of the blade across its midline is read over :data:`TIP_REACH` of the
    length behind the apex, where it is at least :data:`TIP_BLUR` working pixels (narrower parts
    are thinned by the blur); a straight line fitted to it (and one to the midline, which turns
    the frame to the tip's own direction) is followed to zero width. A blunt or rounded apex
    widens faster than :data:`TIP_SLOPE`, a stalk (a petiole too short to be found as one, a drip
    tip) slower than :data:`TIP_MIN_SLOPE`: both stay. The move is at most :data:`TIP_MAX` of the
    length."""
    length = float(np.hypot(*(apex - base)))
    if length <= 0:
        return apex
    d = (apex - base) / length
    reach = TIP_REACH * length
    i0 = int(np.argmin(np.hypot(*(contour - apex).T)))
    t = np.arange(0.0, reach, 0.5)
    tip = apex
    for _ in range(2):
        s, lat = _frame(contour, apex, d)
        a, b = _side_profile(s, lat, i0, 1, reach, t), _side_profile(s, lat, i0, -1, reach, t)
        width, mid = np.abs(a - b), 0.5 * (a + b)
        use = width >= TIP_BLUR * f
        if use.sum() < 5:
            return apex
        slope, icpt = np.polyfit(t[use], width[use], 1)
        turn, offset = np.polyfit(t[use], mid[use], 1)
        if slope <= 0:
            return apex
        t0 = -icpt / slope                          # where the width reaches zero (negative: beyond the apex)
        normal = np.array([-d[1], d[0]])
        reached = max(t0, -TIP_MAX * length)
        tip = apex - reached * d + (offset + turn * reached) * normal
        d = d - turn * normal                       # the tip's own direction, for the second pass
        d /= max(float(np.hypot(*d)), 1e-9)
    if t0 >= 0 or not TIP_MIN_SLOPE < slope < TIP_SLOPE:
        return apex
    return np.asarray(tip, np.float64)


def _midrib_end(contour: Array, base: Array, centre: Array) -> tuple[Array, bool]:
    """The apex seen from ``base``: the contour point farthest from it within 45° of the line from
    it through the blade's centroid, unless that line's far crossing of the contour lies in a notch
    (deeper than :data:`NOTCH_DEPTH` of the length inside the convex hull: an emarginate or
    two-lobed apex), where the notch's sinus is the midrib's end (and True: notched)."""
    away = centre - base
    away = away / max(float(np.hypot(*away)), 1e-9)
    s, lat = _frame(contour, base, away)
    end, depth = _end_point(contour, s, lat, False, ConvexHull(contour).equations)
    if depth > NOTCH_DEPTH * float(s.max() - s.min()):
        return end, True
    return _apex(contour, base, away), False


# -- the whole -------------------------------------------------------------------------------------------------
def _block_any(mask: NDArray[np.bool_], f: int, shape: tuple[int, int]) -> NDArray[np.bool_]:
    """Which ``f`` × ``f`` blocks of ``mask`` hold a true pixel, as an array of ``shape``."""
    h, w = shape
    padded = np.zeros((h * f, w * f), bool)
    padded[:mask.shape[0], :mask.shape[1]] = mask[:h * f, :w * f]
    return np.asarray(padded.reshape(h, f, w, f).any(axis=(1, 3)), bool)


def _up(mask: NDArray[np.bool_], f: int, shape: tuple[int, int]) -> NDArray[np.bool_]:
    if f == 1:
        return mask
    return np.asarray(np.repeat(np.repeat(mask, f, axis=0), f, axis=1)[:shape[0], :shape[1]], bool)


def _landmarks(mask: NDArray[np.bool_], fine: NDArray[np.bool_], f: int, grey: NDArray[np.float32] | None,
               pet: _Petiole | None, extent: float, base: Array | None, apex: Array | None,
               colour: NDArray[np.floating] | None = None) -> tuple[NDArray[np.bool_], Array, Array, Array, Array,
                                                                    list[str]]:
    """(blade at ``fine``'s resolution, petiole line, contour, base, apex, warnings) of the leaf
    ``mask`` with the petiole ``pet`` (or none), as :func:`leaf_shape` finds them."""
    def to_fine(p: Array) -> Array:
        return np.asarray((p + 0.5) * f - 0.5, np.float64)

    warnings: list[str] = []
    blade, blade_w = fine, mask
    petiole = np.zeros((0, 2))
    if pet is not None:
        base, petiole, direction = _petiole_base(fine, pet, extent, base, colour)
        yx = np.argwhere(pet.pixels)
        behind = (yx[:, ::-1] - base) @ direction < 0
        cut = np.zeros_like(fine)
        cut[yx[behind, 0], yx[behind, 1]] = True
        blade = fine & ~cut
        lab, n = ndimage.label(mask & ~(_block_any(cut, f, mask.shape) if f > 1 else cut), structure=_EIGHT)
        if n:
            blade_w = lab == int(np.argmax(np.bincount(lab.ravel())[1:]) + 1)
    contour = to_fine(_contour(blade_w))
    centre_w, axis, elongation = _moments(blade_w)
    centre = to_fine(centre_w)
    if base is None and apex is None and elongation < ROUND_BLADE and pet is None:
        warnings.append("the blade is nearly round, so which way its axis runs is a guess: check the base and apex, "
                        "or give --base and --apex")
    if base is None:
        axis, veins = _midrib_axis(grey, blade_w, centre_w, axis, elongation)
        base, note = _base_without_petiole(contour, centre, axis, apex, float(f), veins, elongation)
        if note:
            warnings.append(note)
    if apex is None:
        apex, notched = _midrib_end(contour, base, centre)
        if not notched:
            apex = _taper_tip(contour, base, apex, float(f))
    return blade, petiole, contour, base, apex, warnings


def _off_axis(pet: _Petiole, found: tuple[NDArray[np.bool_], Array, Array, Array, Array, list[str]]) -> bool:
    """Whether the petiole ``pet`` runs more than :data:`PETIOLE_TURN` degrees off the line from the
    base to the apex ``found`` with it, from its free end to that base (its centre line's own end
    forks where it flares into the blade): a tooth on a shoulder, a sliver along the blade's edge,
    or a second, narrow leaf lying against the blade's side, not a petiole."""
    _, _, _, base, apex, _ = found
    into, ahead = base - pet.path[0], apex - base
    norm = float(np.hypot(*into)) * float(np.hypot(*ahead))
    return norm > 0 and float(into @ ahead) < math.cos(math.radians(PETIOLE_TURN)) * norm


def _midrib_axis(grey: NDArray[np.float32] | None, blade: NDArray[np.bool_], centre: Array, axis: Array,
                 elongation: float) -> tuple[Array, float]:
    """The axis the midrib runs along and the veins' sense along it (:func:`_vein_sense`): the
    principal ``axis``, or the axis across it where the veins' sense across is clear (at least
    :data:`VEIN_SENSE`), :data:`VEIN_TURN` times the sense along and the blade less than
    :data:`VEIN_TURN_ELONGATION` times longer than wide."""
    veins, across = _vein_sense(grey, blade, centre, axis)
    if abs(across) >= VEIN_SENSE and abs(across) > VEIN_TURN * abs(veins) and elongation < VEIN_TURN_ELONGATION:
        return np.array([-axis[1], axis[0]]), across
    return axis, veins


def _against_veins(pet: _Petiole, mask: NDArray[np.bool_], f: int, grey: NDArray[np.float32] | None) -> bool:
    """Whether the secondary veins, where they show clearly (:func:`_vein_sense` at least
    :data:`VEIN_SENSE`, along the midrib's axis, :func:`_midrib_axis`), put
    the base away from the petiole ``pet``: its joint with the blade does not lie in the outer
    :data:`PETIOLE_END` of the base's half of the blade along the midrib (it lies on the apex's half,
    a thin apex tip, or on the blade's side, a tooth or a sliver of shadow along the margin)."""
    if grey is None:
        return False
    centre, axis, elongation = _moments(mask)
    axis, veins = _midrib_axis(grey, mask, centre, axis, elongation)
    if abs(veins) < VEIN_SENSE:
        return False
    s = (np.argwhere(mask)[:, ::-1] - centre) @ axis
    joint = (pet.path[-1] + 0.5) / f - 0.5
    towards_base = -math.copysign(1.0, veins)
    half = float(s.max() if towards_base > 0 else -s.min())
    return float((joint - centre) @ axis) * towards_base < PETIOLE_END * half


def leaf_shape(mask: NDArray[np.bool_], *, fine: NDArray[np.bool_] | None = None, f: int = 1,
               grey: NDArray[np.float32] | None = None, base: Array | None = None,
               apex: Array | None = None, colour: NDArray[np.floating] | None = None) -> Shape:
    """Blade, outline, base, apex and petiole of the leaf ``mask`` (module docstring).

    ``mask`` is the leaf at working resolution; ``fine`` the same leaf ``f`` times finer (pixel
    (i, j) of ``mask`` covers rows i·f .. i·f + f - 1 and columns j·f .. j·f + f - 1 of ``fine``),
    or None when they are one; ``grey`` the photo's brightness aligned with ``mask`` (for the
    veins), if known; ``colour`` the photo's RGB aligned with ``fine``, if known (a petiole hidden in
    a narrow cordate sinus). Blade-scale work (distance transform, opening, outline) is done on
    ``mask``, the thin petiole on ``fine``; everything returned is in ``fine``'s pixels. ``base``
    and ``apex`` ((x, y) in ``fine``'s pixels), where given, are kept."""
    fine = mask if fine is None else fine
    warnings: list[str] = []
    edt = ndimage.distance_transform_edt(np.pad(mask, 1, mode="edge"))[1:-1, 1:-1]
    centre, axis = _axis(mask)
    extent = float(np.ptp((np.argwhere(mask)[:, ::-1] - centre) @ axis)) * f
    opened = _opened(mask, edt)
    core = _up(ndimage.binary_dilation(opened, _EIGHT) if f > 1 else opened, f, fine.shape)
    pet = _find_petiole(fine, core, extent)
    given = base
    if pet is not None and given is None and apex is None and _against_veins(pet, mask, f, grey):
        pet = None                  # a tooth, a sliver or the apex's own tip at the end the veins point to
    found = _landmarks(mask, fine, f, grey, pet, extent, given, apex, colour)
    if pet is not None and given is None and _off_axis(pet, found):
        found = _landmarks(mask, fine, f, grey, None, extent, given, apex)    # a tooth or a second leaf, not a petiole
    blade, petiole, contour, base, apex, notes = found
    warnings += notes
    length = max(float(np.hypot(*(apex - base))), 1.0)
    controls, hausdorff = fit_closed_bspline(contour, max(0.5 * f, OUTLINE_TOLERANCE * length), 0.5 * f)
    if hausdorff > max(0.75 * f, OUTLINE_WARN * length):
        warnings.append(f"the smoothed outline departs up to {hausdorff / length:.1%} of the length from the traced "
                        f"one (a very ragged margin?)")
    return Shape(blade=np.asarray(blade, bool), outline=_ordered_outline(controls, base),
                 base=np.asarray(base, np.float64), apex=np.asarray(apex, np.float64), petiole=petiole,
                 warnings=tuple(warnings))


def _ordered_outline(controls: Array, base: Array) -> Array:
    """:data:`OUTLINE_POINTS` points of the spline, counter-clockwise on screen (negative shoelace
    area with y down), the first nearest ``base``."""
    dense_t = np.arange(16 * len(controls)) / (16 * len(controls))
    dense = eval_closed_bspline(controls, dense_t)
    x, y = dense.T
    area = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    t0 = float(dense_t[int(np.argmin(np.hypot(*(dense - base).T)))])
    sign = 1.0 if area < 0 else -1.0
    return eval_closed_bspline(controls, t0 + sign * np.arange(OUTLINE_POINTS) / OUTLINE_POINTS)
