"""One closed margin for a multilobed leaf (Garg & Leow 2011, sec. 5): the union of the parts of a
compound spec (:mod:`leafview.botany.lobes`) joined by valley curves and fitted by a closed cubic
B-spline (:mod:`leafview.core.bspline`), the ``outline`` of :class:`leafview.core.lobes.Lobes`.

Steps.

1. The margin of every part (lateral and terminal lobes, web) in the leaf frame, their union
   (shapely). The union must be one polygon without holes; a part detached from it ("a lobe
   outside the blade") is an error naming the field that places it.
2. Corners. Walking the union's boundary, each vertex lies on one part's margin; where the walk
   switches from one part to another with a concave turn sharper than :data:`CORNER_ANGLE`, two
   margins cross: a sharp valley. Between two consecutive runs of different lobes lies a *gap*;
   its default valley point is the crossing (sec. 5: "the intersections of adjacent margins form
   the valleys") or, where a web run lies between them, the web's point nearest the primary vein
   (sec. 5's "default valley points placed at a predefined distance from the primary vein": the
   web's margin sets that distance). A user valley point (``valleys`` of the compound file)
   replaces the default of the gap of its nearest corner.
3. Valley curves. Around each corner the boundary over :data:`BLEND` leaf lengths either side is
   replaced by two cubic Bézier segments through the valley point, tangent to the margin at both
   ends, with the tangent at the valley point parallel to the chord of the span (sec. 5: "adjacent
   lobes are combined by fitting additional B-spline curves at the valley points"). Spans that
   overlap are merged into one curve.
4. The smoothed boundary is oriented clockwise seen from +z, started at the point nearest the
   base (0, 0), resampled evenly by arc length and fitted by :func:`fit_closed`; ``controls``
   grows until the Hausdorff distance to the union is within :data:`HAUSDORFF_GOAL` of the leaf
   length (the union's y-extent) or :data:`MAX_CONTROLS` is reached.

Lengths stay in the compound spec's units (the primary vein is 1), so the margin covers the same
ground as the compound leaf drawn part by part.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import LinearRing, LineString, Polygon
from shapely.geometry.polygon import orient
from shapely.ops import unary_union

from leafview.botany.lobes import LobedLeaf, LobePlacement, ShapeSource, lobe_outlines, lobed_from_dict
from leafview.core.bspline import MAX_CONTROLS, basis, fit_closed, sample_closed, signed_area
from leafview.core.io import register_document_reader
from leafview.core.lobes import Lobes
from leafview.core.params import LeafParams
from leafview.errors import ParamError

__all__ = ["compound_document", "HAUSDORFF_GOAL", "BLEND", "CORNER_ANGLE", "USER_VALLEY_OFF", "VALLEY_REACH", "LobedMargin",
           "parts_union", "lobed_margin", "lobed_outline", "lobed_outline_params", "margin_params", "hausdorff"]

HAUSDORFF_GOAL = 0.005   # fitted margin vs the union, in units of the leaf length (y-extent)
BLEND = 0.03             # half span of a valley curve, in leaf lengths
CORNER_ANGLE = 12.0      # degrees: a sharper concave turn where the margin switches part is a corner
USER_VALLEY_OFF = 0.02   # leaf lengths a user valley point may lie off the union's boundary
VALLEY_REACH = 0.12      # leaf lengths from a user valley point to the corner it replaces
VALLEY_HANDLE = 0.12     # handle of a valley curve at its valley point, times the chord (a tight turn)
HOLE_AREA = 1e-5         # square leaf lengths: smaller uncovered pockets are slivers, filled
_PART_RING = 257         # margin samples per side of each part
_LOOK = 0.006            # leaf lengths either side of a vertex for its turn
_STEP_CONTROLS = 32


@dataclass(frozen=True)
class LobedMargin:
    """The fitted margin of a lobed leaf and how well it fits.

    Attributes
    ----------
    outline
        (controls, 2) control points of the closed B-spline, clockwise, C(0) at the base.
    valleys
        (k, 2) valley points used, in the order the margin meets them from the base.
    ring
        The smoothed boundary that was fitted (dense, evenly spaced, starting at the base).
    union
        The union of the parts (shapely Polygon).
    length
        The leaf length: the union's y-extent.
    hausdorff
        Hausdorff distance between the fitted curve and the union's boundary (leaf-frame units).
    area_error
        |area(margin) - area(union)| / area(union).
    """

    outline: NDArray[np.float64]
    valleys: NDArray[np.float64]
    ring: NDArray[np.float64]
    union: Polygon
    length: float
    hausdorff: float
    area_error: float

    @property
    def controls(self) -> int:
        return len(self.outline)

    @property
    def hausdorff_fraction(self) -> float:
        """The Hausdorff distance as a fraction of the leaf length."""
        return self.hausdorff / self.length


# -- the union of the parts ------------------------------------------------------------------------
def _part_field(leaf: LobedLeaf, parts: list[LobePlacement], k: int) -> tuple[str, str]:
    """The compound-spec field that places part ``k`` and a description of the part."""
    p = parts[k]
    if p.role == "web":
        return "web_length", f"the web ({p.shape})"
    if p.role == "terminal":
        return "terminal_base", f"the terminal lobe ({p.shape})"
    lateral = [j for j, q in enumerate(parts) if q.role == "lateral"]
    n = len(lateral) // 2
    i = n - 1 - lateral.index(k) // 2            # place_lobes lists the specs outermost first
    side = "left" if p.angle > 0 else "right"
    what = (f"lateral lobe {i + 1} on the {side} (r = {p.base[1]:.3g}, θ = {abs(p.angle):.3g}°, "
            f"l = {p.length:.3g})")
    if leaf.positions:
        return f"positions[{i}]", what
    return ("r1" if p.base[1] > 0.0 else "theta"), what


def parts_union(leaf: LobedLeaf, shape_source: ShapeSource | None = None
                ) -> tuple[Polygon, list[NDArray[np.float64]], list[LobePlacement]]:
    """The union of the parts' margins (one polygon, no holes), each part's closed margin and
    the parts; a part detached from the blade or a hole in it raises :class:`ParamError`."""
    parts = leaf.lobes()
    rings = lobe_outlines(leaf, shape_source, _PART_RING)
    polys = [Polygon(r).buffer(0) for r in rings]
    union = unary_union(polys)
    if union.geom_type != "Polygon":
        comps = sorted(union.geoms, key=lambda g: g.area, reverse=True)
        main = comps[0]
        for g in comps:
            if g.distance(shapely.Point(0.0, 0.0)) < 1e-9 and g.area > 0.1 * main.area:
                main = g
                break
        for k, poly in enumerate(polys):
            if poly.intersection(main).area < 1e-9 * max(poly.area, 1e-12):
                path, what = _part_field(leaf, parts, k)
                raise ParamError(path, f"{what} lies outside the blade: it does not overlap the other "
                                       "parts (move it onto the primary vein's blade, or widen the web)")
        raise ParamError("web", f"the parts form {len(comps)} separate pieces, not one blade")
    holes = [h for h in union.interiors if Polygon(h).area > HOLE_AREA]
    if holes:
        c = Polygon(holes[0]).representative_point()
        raise ParamError("web", f"the lobes enclose {len(holes)} uncovered pocket(s), the first at "
                                f"({c.x:.3f}, {c.y:.3f}): a lobed margin has no holes (add or widen the web)")
    return Polygon(union.exterior), rings, parts


# -- walking the boundary -------------------------------------------------------------------------
def _arc(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cumulative arc length of the closed polyline ``p`` at each vertex (s[0] = 0), and the
    perimeter appended."""
    seg = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def _at(p: NDArray[np.float64], s: NDArray[np.float64], x: float) -> NDArray[np.float64]:
    """The point at arc length ``x`` (modulo the perimeter) of the closed polyline."""
    per = s[-1]
    x = x % per
    q = np.vstack([p, p[:1]])
    return np.array([np.interp(x, s, q[:, 0]), np.interp(x, s, q[:, 1])])


def _tangent(p: NDArray[np.float64], s: NDArray[np.float64], x: float, h: float) -> NDArray[np.float64]:
    d = _at(p, s, x + h) - _at(p, s, x - h)
    return d / max(float(np.linalg.norm(d)), 1e-300)


@dataclass(frozen=True)
class _Corner:
    s: float                  # arc position on the union's boundary
    point: NDArray[np.float64]
    parts: tuple[int, int]    # the part before and after
    handle: float = 0.0       # handle of a valley curve through it, times the chord (0: VALLEY_HANDLE)


@dataclass(frozen=True)
class _Gap:
    start: float              # arc positions (end of one lobe run, start of the next), start <= end
    end: float
    valley: NDArray[np.float64]
    s_valley: float
    parts: tuple[int, int]
    corner: int = -1          # index of the corner that is its valley (lobes crossing), -1: a web point


def _labels(ex: NDArray[np.float64], rings: list[NDArray[np.float64]], tol: float
            ) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Per boundary vertex: the part whose margin it lies on, and whether it lies on two (a
    crossing)."""
    pts = shapely.points(ex)
    d = np.stack([shapely.distance(pts, LinearRing(r)) for r in rings], axis=1)
    return np.argmin(d, axis=1), np.sum(d < tol, axis=1) >= 2


def _corners(ex: NDArray[np.float64], s: NDArray[np.float64], label: NDArray[np.int64],
             multi: NDArray[np.bool_], look: float) -> list[_Corner]:
    """Concave switches from one part to another on the clockwise boundary ``ex``."""
    plain = np.nonzero(~multi)[0]
    out = []
    for i in np.nonzero(multi)[0]:
        k = np.searchsorted(plain, i)
        before, after = label[plain[(k - 1) % len(plain)]], label[plain[k % len(plain)]]
        if before == after:
            continue
        a = ex[i] - _at(ex, s, s[i] - look)
        b = _at(ex, s, s[i] + look) - ex[i]
        turn = np.degrees(np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b))
        if turn > CORNER_ANGLE:       # a left turn on a clockwise walk: concave
            out.append(_Corner(float(s[i]), ex[i].copy(), (int(before), int(after))))
    return out


def _vein_distance(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance from points to the primary vein, the segment (0, 0)-(0, 1)."""
    y = np.clip(p[:, 1], 0.0, 1.0)
    return np.hypot(p[:, 0], p[:, 1] - y)


def _middle(ex: NDArray[np.float64], s: NDArray[np.float64], idx: NDArray[np.int64]) -> int:
    """The vertex of the run ``idx`` (consecutive, may wrap) halfway along it."""
    sr = s[idx] + np.where(idx < idx[0], s[-1], 0.0)
    return int(idx[int(np.argmin(np.abs(sr - 0.5 * (sr[0] + sr[-1]))))])


def _gaps(ex: NDArray[np.float64], s: NDArray[np.float64], label: NDArray[np.int64], multi: NDArray[np.bool_],
          web: set[int], corners: list[_Corner]) -> list[_Gap]:
    """The stretches between consecutive runs of different lobes (web vertices belong to the
    gap they lie in) and each one's default valley point. ``ex`` starts inside a lobe run."""
    n = len(ex)
    lobe = [(i, int(label[i])) for i in range(n) if not multi[i] and int(label[i]) not in web]
    out = []
    for (i, a), (j, b) in zip(lobe, lobe[1:] + lobe[:1]):
        if a == b:
            continue
        idx = np.arange(i, j + 1) if j > i else np.concatenate([np.arange(i, n), np.arange(0, j + 1)])
        start, end = float(s[i]), float(s[j] if j > i else s[j] + s[-1])
        webs = [m for m in idx if not multi[m] and int(label[m]) in web]
        inside = [k for k, c in enumerate(corners) if start <= c.s <= end or start <= c.s + s[-1] <= end]
        if webs or not inside:
            m = _middle(ex, s, np.array(webs) if webs else idx)
            sv = float(s[m]) if s[m] >= start else float(s[m] + s[-1])
            out.append(_Gap(start, end, ex[m].copy(), sv, (a, b)))
        else:
            k = min(inside, key=lambda k: float(_vein_distance(corners[k].point[None])[0]))
            out.append(_Gap(start, end, corners[k].point, corners[k].s, (a, b), k))
    return out


# -- valley curves --------------------------------------------------------------------------------
def _bezier(p0: NDArray[np.float64], t0: NDArray[np.float64], p1: NDArray[np.float64], t1: NDArray[np.float64],
            step: float, k0: float = 1.0 / 3.0, k1: float = 1.0 / 3.0) -> NDArray[np.float64]:
    """A cubic from ``p0`` (leaving along ``t0``) to ``p1`` (arriving along ``t1``), handles
    ``k0`` and ``k1`` times the chord, sampled about every ``step`` (``p1`` excluded)."""
    a = float(np.linalg.norm(p1 - p0))
    c = np.array([p0, p0 + k0 * a * t0, p1 - k1 * a * t1, p1])
    n = max(4, int(np.ceil(a / step)))
    u = np.arange(n)[:, None] / n
    w = np.hstack([(1 - u) ** 3, 3 * u * (1 - u) ** 2, 3 * u ** 2 * (1 - u), u ** 3])
    return w @ c


@dataclass
class _Span:
    lo: float
    hi: float
    corners: list[_Corner]
    user: list[int]           # indices of user valley points in it
    gaps: set[int]
    passes: list[_Corner]     # the corners that are valleys (the curve passes through them)


def _valley_curve(ex: NDArray[np.float64], s: NDArray[np.float64], span: _Span,
                  through: list[tuple[NDArray[np.float64], float, float]], step: float, look: float) -> NDArray[np.float64]:
    """Cubic Bézier segments from the span's start to its end through the points ``through``
    (point, arc position), tangent to the margin at both ends; at an inner point the tangent
    bisects the margin's directions just before and after it, so the curve is G1 throughout."""
    h = 0.25 * look
    pts = [_at(ex, s, span.lo), *(p for p, _, _ in through), _at(ex, s, span.hi)]
    tan = [_tangent(ex, s, span.lo, h)]
    for p, sp, _ in through:
        a = p - _at(ex, s, sp - look)
        b = _at(ex, s, sp + look) - p
        t = a / max(float(np.linalg.norm(a)), 1e-300) + b / max(float(np.linalg.norm(b)), 1e-300)
        if not np.linalg.norm(t) > 1e-9:          # a cusp: fall back on the chord of the span
            t = pts[-1] - pts[0]
        tan.append(t / float(np.linalg.norm(t)))
    tan.append(_tangent(ex, s, span.hi, h))
    k = [1.0 / 3.0] + [h for _, _, h in through] + [1.0 / 3.0]
    return np.vstack([_bezier(pts[i], tan[i], pts[i + 1], tan[i + 1], step, k[i], k[i + 1])
                      for i in range(len(pts) - 1)])


def _merge(spans: list[_Span]) -> list[_Span]:
    spans = sorted(spans, key=lambda sp: sp.lo)
    out: list[_Span] = []
    for sp in spans:
        if out and sp.lo <= out[-1].hi:
            last = out[-1]
            last.hi = max(last.hi, sp.hi)
            last.corners += sp.corners
            last.user += sp.user
            last.gaps |= sp.gaps
            last.passes += sp.passes
        else:
            out.append(sp)
    return out


def _splice(ex: NDArray[np.float64], s: NDArray[np.float64], spans: list[_Span],
            curves: list[NDArray[np.float64]]) -> tuple[NDArray[np.float64], list[tuple[int, int]]]:
    """``ex`` with each span's stretch replaced by its curve; the index range of each curve."""
    pieces, where, pos, cursor = [], [], 0, -np.inf
    for sp, cv in zip(spans, curves):
        keep = ex[(s[:-1] > cursor) & (s[:-1] < sp.lo)]
        pieces += [keep, cv]
        where.append((pos + len(keep), pos + len(keep) + len(cv)))
        pos += len(keep) + len(cv)
        cursor = sp.hi
    pieces.append(ex[s[:-1] > cursor])
    return np.vstack(pieces), where


def _resample(p: NDArray[np.float64], n: int, start: NDArray[np.float64]) -> NDArray[np.float64]:
    """``n`` points evenly spaced by arc length round the closed polyline, the first at its point
    nearest ``start``."""
    s = _arc(p)
    s0 = float(LineString(np.vstack([p, p[:1]])).project(shapely.Point(*start)))
    return np.array([_at(p, s, s0 + k * s[-1] / n) for k in range(n)])


def hausdorff(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Hausdorff distance between two closed polylines (vertex-to-polyline, both ways)."""
    ra, rb = LinearRing(a), LinearRing(b)
    return max(float(np.max(shapely.distance(shapely.points(a), rb))),
               float(np.max(shapely.distance(shapely.points(b), ra))))


# -- the margin -----------------------------------------------------------------------------------
def _smoothed(leaf: LobedLeaf, shape_source: ShapeSource | None
              ) -> tuple[NDArray[np.float64], NDArray[np.float64], Polygon, float]:
    """The union's boundary with valley curves (clockwise, starting at the base), the valley
    points, the union and the leaf length."""
    union, rings, parts = parts_union(leaf, shape_source)
    union = orient(union, sign=-1.0)                       # clockwise exterior
    ex = np.asarray(union.exterior.coords)[:-1]
    y0, y1 = float(ex[:, 1].min()), float(ex[:, 1].max())
    length = y1 - y0
    tol = 1e-9 * max(1.0, length)
    web = {k for k, p in enumerate(parts) if p.role == "web"}
    label, multi = _labels(ex, rings, 1e3 * tol)
    # start the walk inside a lobe run so that no gap wraps around index 0
    lobe_idx = np.nonzero(~multi & ~np.isin(label, list(web)))[0]
    if len(lobe_idx) == 0:
        raise ParamError("half", "the leaf has no lobes outside the web")
    s = _arc(ex)
    corners0 = _corners(ex, s, label, multi, _LOOK * length)
    far = _far_index(s, [c.s for c in corners0], lobe_idx)
    ex, label, multi = np.roll(ex, -far, axis=0), np.roll(label, -far), np.roll(multi, -far)
    s = _arc(ex)
    corners = _corners(ex, s, label, multi, _LOOK * length)
    gaps = _gaps(ex, s, label, multi, web, corners)
    per = float(s[-1])
    base_s = float(LineString(np.vstack([ex, ex[:1]])).project(shapely.Point(0.0, 0.0)))
    base_gap = next((g for g, gp in enumerate(gaps) if gp.start <= base_s <= gp.end
                     or gp.start <= base_s + per <= gp.end), -1)
    d = BLEND * length
    spans = []
    for c in corners:
        g = next((g for g, gp in enumerate(gaps) if gp.start - 1e-12 <= c.s <= gp.end + 1e-12
                  or gp.start <= c.s + per <= gp.end), -1)
        spans.append(_Span(c.s - d, c.s + d, [c], [], {g} if g >= 0 else set(), []))
    user = _user_valleys(leaf, ex, s, corners, spans, length)
    for i, (sv, g) in user.items():
        spans.append(_Span(sv - d, sv + d, [], [i], {g}, []))
    spans = _merge(spans)
    webs = [gp for g, gp in enumerate(gaps) if gp.corner < 0 and g != base_gap]
    for sp in spans:
        if sp.user or sp.lo <= base_s <= sp.hi or sp.lo <= base_s - per <= sp.hi:
            continue            # through the user's point only; the petiole's sinus is simply rounded
        sp.passes = _collapse(sp.corners, 0.2 * d)
        for gp in webs:         # a web valley inside the span: the curve follows the web through it
            sv = gp.s_valley if gp.s_valley < per else gp.s_valley - per
            if sp.lo < sv < sp.hi and all(abs(c.s - sv) > 0.2 * d for c in sp.passes):
                sp.passes.append(_Corner(sv, gp.valley, gp.parts, 1.0 / 3.0))
    if spans and (spans[0].lo < 0.0 or spans[-1].hi > per or any(sp.hi - sp.lo > 0.5 * per for sp in spans)):
        raise ParamError("valleys", "the valley curves cover the whole margin: the lobes are too small "
                                    "for their valleys")
    step = per / max(len(ex), 2048)
    curves = []
    for sp in spans:
        through = _through(sp, user, leaf)
        curves.append(_valley_curve(ex, s, sp, through, step, _LOOK * length))
    smooth, where = _splice(ex, s, spans, curves)
    _check_simple(smooth, where, spans, parts, leaf)
    # the valley points: user ones, then the defaults of the other gaps (not the base's sinus)
    used = {g for _, g in user.values()}
    vals = [np.asarray(leaf.valleys[i], dtype=np.float64) for i in user]
    ring = LineString(np.vstack([smooth, smooth[:1]]))
    for g, gp in enumerate(gaps):
        if g in used or g == base_gap:
            continue
        p = ring.interpolate(ring.project(shapely.Point(*gp.valley)))
        vals.append(np.array([p.x, p.y]))
    return smooth, np.array(vals).reshape(-1, 2), union, length


def _collapse(corners: list[_Corner], gap: float) -> list[_Corner]:
    """The corners in order along the margin, those closer than ``gap`` to the previous counting
    once (the one nearest the primary vein)."""
    groups: list[list[_Corner]] = []
    for c in sorted(corners, key=lambda c: c.s):
        if groups and c.s - groups[-1][-1].s < gap:
            groups[-1].append(c)
        else:
            groups.append([c])
    return [min(g, key=lambda c: float(_vein_distance(c.point[None])[0])) for g in groups]


def _far_index(s: NDArray[np.float64], at: list[float], candidates: NDArray[np.int64]) -> int:
    """The candidate vertex farthest (along the boundary) from every position in ``at``."""
    if not at:
        return int(candidates[0])
    per = s[-1]
    sc = s[candidates][:, None]
    d = np.abs(sc - np.asarray(at)[None, :])
    d = np.minimum(d, per - d).min(axis=1)
    return int(candidates[int(np.argmax(d))])


def _user_valleys(leaf: LobedLeaf, ex: NDArray[np.float64], s: NDArray[np.float64], corners: list[_Corner],
                  spans: list[_Span], length: float) -> dict[int, tuple[float, int]]:
    """Each user valley point's arc position and gap; ParamError ``valleys[i]`` for a point off
    the boundary, away from every corner, or a second point for the same valley."""
    out: dict[int, tuple[float, int]] = {}
    if not leaf.valleys:
        return out
    ring = LineString(np.vstack([ex, ex[:1]]))
    taken: dict[int, int] = {}
    for i, v in enumerate(leaf.valleys):
        pt = shapely.Point(*v)
        off = float(ring.distance(pt))
        if off > USER_VALLEY_OFF * length:
            raise ParamError(f"valleys[{i}]", f"({v[0]:.4g}, {v[1]:.4g}) is {off:.4f} off the joined margin "
                                              f"(at most {USER_VALLEY_OFF * length:.3g})")
        if not corners:
            raise ParamError(f"valleys[{i}]", "the lobes' margins meet nowhere: there is no valley to place")
        dist = [float(np.hypot(*(np.asarray(v) - c.point))) for c in corners]
        k = int(np.argmin(dist))
        if dist[k] > VALLEY_REACH * length:
            raise ParamError(f"valleys[{i}]", f"({v[0]:.4g}, {v[1]:.4g}) is {dist[k]:.3f} from the nearest "
                                              f"valley corner ({corners[k].point[0]:.3f}, {corners[k].point[1]:.3f}); "
                                              f"a valley point lies within {VALLEY_REACH * length:.3g} of one")
        g = next(iter(spans[k].gaps), -1)
        if g in taken:
            raise ParamError(f"valleys[{i}]", f"the valley near ({corners[k].point[0]:.3f}, "
                                              f"{corners[k].point[1]:.3f}) already has valleys[{taken[g]}]")
        taken[g] = i
        sv = float(ring.project(pt))
        cs = corners[k].s
        if abs(sv - cs) > 0.5 * s[-1]:
            sv += s[-1] if sv < cs else -s[-1]
        out[i] = (sv, g)
    return out


def _through(sp: _Span, user: dict[int, tuple[float, int]], leaf: LobedLeaf
             ) -> list[tuple[NDArray[np.float64], float, float]]:
    """The points a merged span's valley curve passes through: its user valley point, else the
    crossings in it that are the valleys of their gaps (lobes meeting without a web between);
    none (a fillet: one cubic across the span) where the span only rounds a lobe into the web."""
    if len(sp.user) > 1:
        i, j = sorted(sp.user)[:2]
        raise ParamError(f"valleys[{j}]", f"its valley curve overlaps that of valleys[{i}]: the points are "
                                          f"closer than {2 * BLEND:g} leaf lengths along the margin")
    if sp.user:
        return [(np.asarray(leaf.valleys[sp.user[0]], dtype=np.float64), user[sp.user[0]][0], VALLEY_HANDLE)]
    return [(c.point, c.s, c.handle or VALLEY_HANDLE) for c in sorted(sp.passes, key=lambda c: c.s)]


def _check_simple(smooth: NDArray[np.float64], where: list[tuple[int, int]], spans: list[_Span],
                  parts: list[LobePlacement], leaf: LobedLeaf) -> None:
    if LinearRing(smooth).is_simple:
        return
    for (a, b), sp in zip(where, spans):
        curve = LineString(smooth[max(a - 1, 0):b + 1])
        rest = np.vstack([smooth[b + 2:], smooth[:max(a - 2, 0)]])
        if len(rest) > 1 and curve.intersects(LineString(rest)) or not curve.is_simple:
            if sp.user:
                raise ParamError(f"valleys[{sp.user[0]}]", "the valley curve through this point crosses the "
                                                           "margin: move it onto the margin between the lobes")
            names = [_part_field(leaf, parts, k)[1] for c in sp.corners for k in c.parts]
            raise ParamError("valleys", f"the valley curve between {' and '.join(dict.fromkeys(names))} "
                                        "crosses the margin: the lobes meet too steeply")
    raise ParamError("valleys", "the joined margin crosses itself after the valley curves")


def _pin(ctrl: NDArray[np.float64], points: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """``ctrl`` nudged so that the curve passes through each of ``points`` (the valleys): at the
    parameter t of the curve point nearest it, the four control points that shape C(t) move by
    the least-norm change that puts C(t) on the point (a few rounds, for valleys sharing them)."""
    ctrl = ctrl.copy()
    m = len(ctrl)
    for _ in range(3):
        dense = sample_closed(ctrl, n)
        for v in points:
            x = int(np.argmin(np.linalg.norm(dense - v, axis=1))) / n * m
            i = int(np.floor(x))
            w = basis(x - i)
            idx = (i + np.arange(-1, 3)) % m
            ctrl[idx] += np.outer(w, v - w @ ctrl[idx]) / float(w @ w)
    return ctrl


def lobed_margin(leaf: LobedLeaf, *, controls: int = 96, shape_source: ShapeSource | None = None,
                 goal: float = HAUSDORFF_GOAL, grow: bool = True) -> LobedMargin:
    """The closed margin of ``leaf`` and its fit figures (see the module docstring).

    Parameters
    ----------
    controls
        Control points to start with (``MIN_CONTROLS`` to ``MAX_CONTROLS``).
    goal
        Hausdorff distance to the union, as a fraction of the leaf length, to reach.
    grow
        Raise ``controls`` in steps of 32 (at most ``MAX_CONTROLS``) until ``goal`` is met.
    """
    smooth, vals, union, length = _smoothed(leaf, shape_source)
    base = np.array([0.0, 0.0])
    target = np.asarray(union.exterior.coords)[:-1]
    m = int(controls)
    while True:
        n = max(4096, 8 * m)
        pts = _resample(smooth, n, base)
        if signed_area(pts) > 0.0:
            pts = np.vstack([pts[:1], pts[:0:-1]])
        ctrl = _pin(fit_closed(pts, m), vals, n)
        curve = sample_closed(ctrl, n)
        h = hausdorff(curve, target)
        if not grow or h <= goal * length or m >= MAX_CONTROLS:
            break
        m = min(MAX_CONTROLS, m + _STEP_CONTROLS)
    area = abs(signed_area(curve))
    ring = LineString(np.vstack([curve, curve[:1]]))
    order = np.argsort([ring.project(shapely.Point(*v)) for v in vals]) if len(vals) else np.arange(0)
    return LobedMargin(ctrl, vals[order], pts, union, length, h, abs(area - union.area) / union.area)


def lobed_outline(leaf: LobedLeaf, *, controls: int = 96, shape_source: ShapeSource | None = None,
                  grow: bool = True) -> NDArray[np.float64]:
    """The (controls', 2) control points of the closed margin of ``leaf``: clockwise seen from +z,
    C(0) at the base; with ``grow``, ``controls`` rises (to at most MAX_CONTROLS) until the fit is
    within :data:`HAUSDORFF_GOAL` of the leaf length. :func:`lobed_margin` also gives the figures."""
    return lobed_margin(leaf, controls=controls, shape_source=shape_source, grow=grow).outline


def margin_params(leaf: LobedLeaf, margin: LobedMargin) -> LeafParams:
    """The lobed :class:`LeafParams` of a fitted margin (validated like a file)."""
    lobes = Lobes(outline=tuple((float(x), float(y)) for x, y in margin.outline),
                  valleys=tuple((float(x), float(y)) for x, y in margin.valleys))
    return LeafParams.from_dict(LeafParams(lobes=lobes, material=leaf.material, name=leaf.name).to_dict())


def lobed_outline_params(leaf: LobedLeaf, *, controls: int = 96, shape_source: ShapeSource | None = None,
                         grow: bool = True) -> LeafParams:
    """A lobed :class:`LeafParams`: ``lobes`` with the margin and its valleys, the compound
    spec's material and name; everything else at its default."""
    return margin_params(leaf, lobed_margin(leaf, controls=controls, shape_source=shape_source, grow=grow))


def compound_document(data: Any) -> LeafParams | None:
    """The lobed leaf of a parsed compound file (``lobed = 1``: Garg & Leow's lobes, eqs 7-9,
    joined into one margin by :func:`lobed_outline_params`), or None for any other document.
    Registered with :func:`leafview.core.io.register_document_reader` when this module is
    imported, so compound files load wherever leaf files do."""
    if not (isinstance(data, Mapping) and "lobed" in data):
        return None
    return lobed_outline_params(lobed_from_dict(data))


register_document_reader(compound_document)
