"""A lobed leaf (maple, oak, a two-lobed leaf) from its traced outline: whether the photo shows
one, and its closed margin (:class:`leafview.core.lobes.Lobes`).

* **Detection** (:func:`lobe_measures`, :func:`looks_lobed`). In the canonical frame (base (0, 0),
  apex (0, 1), one leaf length 1) the traced outline's *solidity* (its area over its convex
  hull's) and its *deepest sinus* (the largest distance of an outline point inside the convex hull
  from the hull's boundary, in leaf lengths) are measured. Teeth, a cordate base and an emarginate
  apex cut little area and few deep sinuses; lobes cut both. The leaf is lobed when the solidity is
  below :data:`LOBED_SOLIDITY`, or the solidity is below :data:`NOTCHED_SOLIDITY` and at least two
  sinuses are :data:`SINUS_DEPTH` deep. The thresholds were set on the synthetic photos of
  :mod:`leafview.fit.synthetic_photos` (unilobed kinds and ``kind="lobed"``).
* **Margin** (:func:`fit_lobed_margin`). The traced outline (a smoothed closed curve, leaf frame)
  is resampled evenly by arc length, started at its point nearest the base, made clockwise and
  fitted by the closed uniform cubic B-spline of :func:`leafview.core.bspline.fit_closed`
  (Mündermann et al. 2003, sec. 3.1) with :data:`START_CONTROLS` control points, raised by
  :data:`STEP_CONTROLS` until the Hausdorff distance to the outline is within ``target`` leaf
  lengths (as :mod:`leafview.botany.lobe_outline` grows its margins). The valleys are the fitted
  margin's points deepest inside the convex hull between lobes (each on the margin), at most
  :data:`MAX_FIT_VALLEYS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray
from shapely.geometry import LinearRing, Polygon

from leafview.core.bspline import MAX_CONTROLS, fit_closed, sample_closed, signed_area
from leafview.core.lobes import Lobes, self_intersections
from leafview.core.params import LeafParams
from leafview.errors import ParamError

__all__ = ["LobeMeasures", "LobedMargin", "lobe_measures", "looks_lobed", "fit_lobed_margin", "lobed_leaf",
           "LOBED_SOLIDITY", "NOTCHED_SOLIDITY", "SINUS_DEPTH", "START_CONTROLS", "STEP_CONTROLS", "LOBED_MODES",
           "LOBED_MIN_MIRROR", "NOTCHED_MIN_MIRROR", "symmetry_axis", "two_notches"]

LOBED_MODES = ("auto", "on", "off")
LOBED_SOLIDITY = 0.72     # solidity below this: lobed
NOTCHED_SOLIDITY = 0.92   # below this, with two sinuses SINUS_DEPTH deep: lobed
SINUS_DEPTH = 0.06        # outline diameters inside the convex hull
DEEP_NOTCH = 0.2          # one sinus this deep (outline diameters): lobed
# A region that looks lobed, or is notched twice (two_notches), but is not mirror-symmetric is two
# touching leaves (a V, a T or an X of two blades): the IoU of the outline with its mirror image in
# its best axis (symmetry_axis) is at least LOBED_MIN_MIRROR for one lobed leaf, NOTCHED_MIN_MIRROR
# for one notched twice. Measured on the seeded synthetic photos: 18 maple, oak and two-lobed
# leaves 0.983-0.998, the 6 touching pairs of 64 taken for lobed 0.686-0.855; an asymmetric leaf
# with a drip tip between two sinuses 0.890, touching pairs so notched 0.65-0.74.
LOBED_MIN_MIRROR = 0.9
NOTCHED_MIN_MIRROR = 0.8
START_CONTROLS = 32
STEP_CONTROLS = 32
MAX_FIT_VALLEYS = 16
_SAMPLES = 2048           # outline samples handed to the spline fit
_CHECK = 8                # curve samples per control point for the Hausdorff check

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class LobeMeasures:
    """Solidity (area ÷ convex-hull area), the deepest sinus and the depths of the separate sinuses
    (leaf lengths, deepest first) of a closed outline in the canonical frame."""

    solidity: float
    deepest: float
    sinuses: tuple[float, ...]

    def report(self) -> dict[str, object]:
        return {"solidity": round(self.solidity, 4), "deepest_sinus": round(self.deepest, 4),
                "sinuses": [round(s, 4) for s in self.sinuses[:8]]}


@dataclass(frozen=True)
class LobedMargin:
    """A fitted lobed margin: control points (clockwise, C(0) at the base), valleys on it, and the
    Hausdorff distance to the traced outline (leaf lengths)."""

    outline: F64
    valleys: F64
    hausdorff: float


def _ring(points: ArrayLike) -> F64:
    p = np.asarray(points, np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 8 or not np.all(np.isfinite(p)):
        raise ParamError("outline", f"expected a closed polyline of at least 8 finite points, got shape {p.shape}")
    if np.allclose(p[0], p[-1]):
        p = p[:-1]
    return p


def _depths(ring: F64, hull: Polygon) -> F64:
    """Each point's distance inside the convex hull's boundary (0 on it)."""
    return np.asarray(shapely.distance(shapely.points(ring), hull.exterior), np.float64)


def _sinuses(depth: F64, floor: float) -> list[tuple[float, int]]:
    """(depth, index) of the deepest point of each run of the closed sequence ``depth`` above
    ``floor`` (a run: one sinus between two hull contacts), deepest first."""
    inside = depth > floor
    if not inside.any():
        return []
    if inside.all():
        k = int(np.argmax(depth))
        return [(float(depth[k]), k)]
    start = int(np.argmin(inside))                 # a point on the hull: runs do not wrap
    order = np.roll(np.arange(len(depth)), -start)
    runs: list[tuple[float, int]] = []
    best, at = -1.0, -1
    for i in order:
        if inside[i]:
            if depth[i] > best:
                best, at = float(depth[i]), int(i)
        elif at >= 0:
            runs.append((best, at))
            best, at = -1.0, -1
    if at >= 0:
        runs.append((best, at))
    return sorted(runs, reverse=True)


def _diameter(hull: Polygon) -> float:
    h = np.asarray(hull.exterior.coords)
    return float(np.max(np.hypot(*(h[:, None, :] - h[None, :, :]).transpose(2, 0, 1))))


def lobe_measures(outline: ArrayLike) -> LobeMeasures:
    """:class:`LobeMeasures` of the closed ``outline`` (any frame: depths are divided by the
    outline's diameter, its convex hull's widest span, so the landmarks play no part)."""
    ring = _ring(outline)
    poly = Polygon(ring).buffer(0)
    hull = poly.convex_hull
    if not hull.area > 0.0:
        raise ParamError("outline", "the outline encloses no area")
    depth = _depths(ring, hull) / _diameter(hull)
    runs = _sinuses(depth, 0.01)
    return LobeMeasures(float(poly.area / hull.area), float(depth.max()), tuple(d for d, _ in runs))


def two_notches(m: LobeMeasures) -> bool:
    """Whether the outline is notched twice (at least two sinuses :data:`SINUS_DEPTH` deep, solidity
    below :data:`NOTCHED_SOLIDITY`) without looking lobed: one leaf so notched is mirror-symmetric
    (a three-lobed leaf with shallow lobes), two blades crossing are not."""
    return (not looks_lobed(m) and m.solidity < NOTCHED_SOLIDITY
            and sum(1 for s in m.sinuses if s >= SINUS_DEPTH) >= 2)


def looks_lobed(m: LobeMeasures) -> bool:
    """Whether the measures say lobed (see the module docstring)."""
    deep = sum(1 for s in m.sinuses if s >= SINUS_DEPTH)
    return m.solidity < LOBED_SOLIDITY or (m.solidity < NOTCHED_SOLIDITY and deep >= 3) or m.deepest >= DEEP_NOTCH


def _resample(ring: F64, n: int) -> F64:
    closed = np.vstack([ring, ring[:1]])
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(closed, axis=0).T))]
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    return np.stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])], axis=1)


def _hausdorff(curve: F64, ring: F64) -> float:
    a, b = LinearRing(curve), LinearRing(ring)
    return max(float(np.max(shapely.distance(shapely.points(curve), b))),
               float(np.max(shapely.distance(shapely.points(ring), a))))


def _valleys(curve: F64, hull_of: F64) -> F64:
    """The deepest point of each sinus of ``curve`` (a curve sample: on the margin) that reaches
    :data:`SINUS_DEPTH` / 2 inside the convex hull of ``hull_of``, in the curve's order."""
    hull = Polygon(hull_of).convex_hull
    runs = _sinuses(_depths(curve, hull), 0.5 * SINUS_DEPTH)[:MAX_FIT_VALLEYS]
    idx = sorted(i for _, i in runs)
    return curve[idx] if idx else np.zeros((0, 2))


def fit_lobed_margin(outline: ArrayLike, target: float = 0.01, *, start: int = START_CONTROLS) -> LobedMargin:
    """The closed B-spline margin of the traced ``outline`` (leaf frame: base (0, 0), apex (0, 1);
    any orientation; see the module docstring), within ``target`` leaf lengths where
    :data:`~leafview.core.bspline.MAX_CONTROLS` control points allow."""
    ring = _ring(outline)
    pts = _resample(ring, _SAMPLES)
    if signed_area(pts) > 0.0:                     # clockwise seen from +z, as Lobes wants it
        pts = pts[::-1]
    k = int(np.argmin(np.hypot(pts[:, 0], pts[:, 1])))
    pts = np.roll(pts, -k, axis=0)
    m = int(start)
    while True:
        ctrl = fit_closed(pts, m)
        curve = sample_closed(ctrl, _CHECK * m)
        h = _hausdorff(curve, ring)
        if (h <= target and not self_intersections(curve)) or m >= MAX_CONTROLS:
            break
        m = min(MAX_CONTROLS, m + STEP_CONTROLS)
    return LobedMargin(ctrl, _valleys(curve, ring), h)


def lobed_leaf(margin: LobedMargin, name: str) -> LeafParams:
    """A lobed :class:`LeafParams` with ``margin`` (everything else at its default), validated as
    a leaf file is."""
    lobes = Lobes(outline=tuple((float(x), float(y)) for x, y in margin.outline),
                  valleys=tuple((float(x), float(y)) for x, y in margin.valleys))
    return LeafParams.from_dict(LeafParams(lobes=lobes, name=name).to_dict())


# -- base and apex of a lobed blade ------------------------------------------------------------------------
def _mirror_score(poly: Polygon, centre: F64, angle: float) -> float:
    """IoU of ``poly`` and its mirror image in the line through ``centre`` at ``angle``."""
    d = np.array([np.cos(angle), np.sin(angle)])
    p = np.asarray(poly.exterior.coords) - centre
    q = 2.0 * np.outer(p @ d, d) - p + centre
    other = Polygon(q).buffer(0)
    inter = poly.intersection(other).area
    return float(inter / max(poly.union(other).area, 1e-12))


def symmetry_axis(outline: ArrayLike) -> tuple[F64, F64, float]:
    """The mirror axis of the closed ``outline`` (pixels): (a point on it, its unit direction, the
    IoU of the outline with its mirror image), searched through the centroid every 3° and refined
    by golden sections."""
    ring = _ring(outline)
    poly = Polygon(_resample(ring, 400)).buffer(0)
    c = np.asarray(poly.centroid.coords[0])
    angles = np.radians(np.arange(0.0, 180.0, 3.0))
    scores = [_mirror_score(poly, c, a) for a in angles]
    best = float(angles[int(np.argmax(scores))])
    lo, hi = best - np.radians(3.0), best + np.radians(3.0)
    g = 0.5 * (np.sqrt(5.0) - 1.0)
    for _ in range(12):
        a, b = hi - g * (hi - lo), lo + g * (hi - lo)
        if _mirror_score(poly, c, a) > _mirror_score(poly, c, b):
            hi = b
        else:
            lo = a
    angle = 0.5 * (lo + hi)
    return c, np.array([np.cos(angle), np.sin(angle)]), _mirror_score(poly, c, angle)


def _axis_ends(ring: F64, c: F64, d: F64) -> tuple[F64, F64]:
    """The ends of the longest stretch of the line through ``c`` along ``d`` that lies inside the
    closed polyline ``ring``: (the end towards +d, the end towards -d)."""
    a, b = ring, np.roll(ring, -1, axis=0)
    n = np.array([-d[1], d[0]])
    sa, sb = (a - c) @ n, (b - c) @ n
    hit = (sa * sb <= 0.0) & (sa != sb)
    f = sa[hit] / (sa[hit] - sb[hit])
    pts = a[hit] + f[:, None] * (b[hit] - a[hit])
    if len(pts) < 2:
        raise ParamError("outline", "the leaf's mirror axis does not cross its outline")
    t = np.sort((pts - c) @ d)
    pairs = t[: len(t) // 2 * 2].reshape(-1, 2)
    lo, hi = pairs[int(np.argmax(pairs[:, 1] - pairs[:, 0]))]
    return c + hi * d, c + lo * d


def lobed_landmarks(outline: ArrayLike, petiole: ArrayLike, measures: LobeMeasures,
                    axis: tuple[F64, F64, float] | None = None) -> tuple[F64, F64]:
    """Base and apex (pixels) of a lobed blade: the ends of the longest stretch of its mirror axis
    (:func:`symmetry_axis`) inside the outline; an end more than :data:`SINUS_DEPTH` diameters
    inside the convex hull is a notch. The base is the end the petiole joins;
    without one, a single deep sinus on the axis is the apex (a bilobed leaf), a notch on the axis
    of a leaf of several lobes is the base (a palmate leaf's basal sinus), and else the base is the
    end where the blade is narrower 15 % of the way in (a lobed blade broadest towards its apex).
    ``axis``: :func:`symmetry_axis` of ``outline``, where already known."""
    ring = _ring(outline)
    c, d, _ = symmetry_axis(ring) if axis is None else axis
    p1, p2 = _axis_ends(ring, c, d)
    hull = Polygon(ring).buffer(0).convex_hull
    sinus = SINUS_DEPTH * _diameter(hull)
    notch1, notch2 = (float(hull.exterior.distance(shapely.Point(*p))) > sinus for p in (p1, p2))
    pet = np.asarray(petiole, np.float64)
    if len(pet) > 1:
        first_is_base = np.hypot(*(p1 - pet[-1])) < np.hypot(*(p2 - pet[-1]))
    elif notch1 != notch2:
        single = sum(1 for s in measures.sinuses if s >= SINUS_DEPTH) <= 2
        first_is_base = notch2 if single else notch1
    else:
        poly = Polygon(ring).buffer(0)
        n = np.array([-d[1], d[0]]) * 4.0 * _diameter(hull)

        def width(end: F64, other: F64) -> float:
            at = end + 0.15 * (other - end)
            return float(poly.intersection(shapely.LineString([at - n, at + n])).length)

        first_is_base = width(p1, p2) < width(p2, p1)
    return (p1, p2) if first_is_base else (p2, p1)
