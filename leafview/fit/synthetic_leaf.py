"""The leaves of the synthetic photos (:mod:`leafview.fit.synthetic_photos`): each leaf's top view
in leaf space, where it lies on the page, and the exact pixel coverage of a polygon.

A top view is a margin pair from base (0, 0) to apex (0, 1) with its midrib: a built-in preset
pressed flat (its margin ``evaluate(params, ±1, v)``; Chaurasia & Beardsley 2017, eq. 6, with the
preset's jitter of sec. 6) or a random catalogue shape (Garg & Leow 2011, Fig. 8; asymmetric ones
from two shapes' sides, Fig. 6), optionally toothed, with an optional petiole. :func:`arrange`
draws the leaves of one photo and places them on the page: the primary one (optionally running off
a border), a second one overlapping it when asked, and the others in free spots. :func:`tree_veins`
draws a known vein tree (:func:`leafview.botany.venation.vein_tree`) over a preset leaf's pixels.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.spatial import cKDTree

from leafview.botany.catalogue import catalogue, catalogue_names, combine_sides, landmark_leaf, random_instance
from leafview.botany.landmarks import LandmarkLeaf, check_margin, outline_sides
from leafview.botany.venation import Vein
from leafview.core.io import load_params
from leafview.core.params import Jitter, LeafParams
from leafview.deform.surface import evaluate
from leafview.errors import ParamError
from leafview.fit.synthetic_lobed import LOBED_PRESETS, lobed_sides
from leafview.resources import builtin_presets

Arr = NDArray[np.float64]
F32 = NDArray[np.float32]

KINDS = ("preset", "landmark", "serrated", "asymmetric")
LOBED = "lobed"              # a further kind, never drawn at random: a varied lobed preset (synthetic_lobed)
SUPERSAMPLE = 4              # sub-rows per pixel row in :func:`coverage` (the x extent is exact)
_MARGIN = 0.04               # free border kept round a leaf that is not cut, in shorter sides
_NAMED = tuple(e.name for e in catalogue() if e.named)
VEINED_PRESETS = ("acuminate", "beech", "elliptic", "lanceolate", "oblanceolate", "oblong", "obovate", "ovate",
                  "rhomboidal", "serrate")   # broad pinnate blades for photos with a known vein tree
_SHAPES = ("elliptic", "lanceolate", "oblanceolate", "rhomboidal", "oval", "ovate", "obovate", "oblong", "deltoid")


# ---------------------------------------------------------------------------------------------
# the leaf's top view in leaf space (base (0, 0), apex (0, 1))
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class TopView:
    """One leaf seen from above in leaf space (base (0, 0), apex (0, 1)); ``info`` is its truth."""

    right: Arr          # (n, 2) one margin, base to apex
    left: Arr           # (n, 2) the other margin, base to apex
    axis: Arr           # (k, 2) the midrib, base to apex
    info: dict[str, Any]
    params: LeafParams | None = None    # the flattened preset whose top view this is (preset views only)

    @property
    def outline(self) -> Arr:
        return np.concatenate([self.right, self.left[-2:0:-1]])


@cache
def _preset(name: str) -> LeafParams:
    return load_params(builtin_presets()[name])


def _flattened(p: LeafParams) -> LeafParams:
    """``p`` pressed flat: every out-of-plane number zero, no ripples, no bending, both halves."""
    s = p.shape
    rows = s.rows
    shape = replace(s, a1=(s.a1[0], s.a1[1], 0.0), a2=(s.a2[0], s.a2[1], 0.0), zf=(0.0,) * rows, zg=(0.0,) * rows,
                    silhouette=tuple((r[0], r[1], 0.0) for r in s.silhouette), half=0)
    return p.replace(shape=shape, ripple=replace(p.ripple, enabled=False),
                     bending=replace(p.bending, load=0.0, twist=0.0, petiole_length=0.0))


def _preset_view(rng: np.random.Generator, name: str, serrate: bool) -> TopView:
    p = _flattened(_preset(name))
    info: dict[str, Any] = {"name": name, "serration": None}
    if serrate:
        p = p.replace(jitter=Jitter(enabled=True, amplitude=float(rng.uniform(0.012, 0.03)),
                                    density=float(rng.uniform(25.0, 70.0)), seed=int(rng.integers(0, 10_000))))
    if p.jitter.enabled:
        info["serration"] = {"model": "jitter", "amplitude": p.jitter.amplitude, "density": p.jitter.density,
                             "seed": p.jitter.seed}
    n = int(max(400, 14 * p.jitter.density)) if p.jitter.enabled else 400
    v = np.linspace(0.0, 1.0, n)
    right, left = evaluate(p, 1.0, v)[:, :2], evaluate(p, -1.0, v)[:, :2]
    axis = evaluate(p, 0.0, np.linspace(0.0, 1.0, 65))[:, :2]
    return TopView(right, left, axis, info, p)


def _landmark_leaf(rng: np.random.Generator, asymmetric: bool) -> tuple[LandmarkLeaf, str]:
    for _ in range(20):
        if asymmetric and rng.random() < 0.5:
            a, b = rng.choice(_SHAPES, 2, replace=False)
            leaf, name = combine_sides(str(a), str(b)), f"{a}|{b}"
        else:
            names = _NAMED if rng.random() < 0.6 else catalogue_names()
            name = str(rng.choice(names))
            leaf = landmark_leaf(name)
        # the oblong's straight sides are extra landmarks that random_instance leaves in place
        amount = 0.0 if "oblong" in name else 0.2 if asymmetric else 0.15
        try:
            leaf = random_instance(leaf, int(rng.integers(0, 2**31 - 1)), amount, independent_sides=asymmetric)
            check_margin(leaf)
            return leaf, name
        except ParamError:
            continue
    return random_instance("elliptic", 0, 0.0), "elliptic"


def _teeth(side: Arr, rng_teeth: tuple[float, float, float], sign: float) -> Arr:
    """``side`` (base to apex, even in arc length) with apically pointing teeth: the margin
    leaves it slowly outward and drops back sharply, ``count`` teeth of ``depth`` leaf lengths,
    tapered to nothing at base and apex."""
    count, depth, rise = rng_teeth
    seg = np.diff(side, axis=0)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
    s /= s[-1]
    t = np.gradient(side, axis=0)
    t /= np.maximum(np.hypot(t[:, 0], t[:, 1]), 1e-12)[:, None]
    normal = sign * np.stack([t[:, 1], -t[:, 0]], axis=1)
    f = (s * count) % 1.0
    tooth = np.where(f < rise, f / rise, (1.0 - f) / (1.0 - rise)) ** 1.3
    taper = np.sin(np.pi * s) ** 0.7
    return side + (depth * taper * tooth)[:, None] * normal


def _landmark_view(rng: np.random.Generator, asymmetric: bool, serrate: bool) -> TopView:
    leaf, name = _landmark_leaf(rng, asymmetric)
    info: dict[str, Any] = {"name": name, "serration": None}
    teeth = (float(rng.uniform(12, 45)), float(rng.uniform(0.008, 0.022)), float(rng.uniform(0.6, 0.85)))
    n = int(16 * teeth[0]) if serrate else 300
    right, left = outline_sides(leaf, n)
    if serrate:
        # the right side runs counter-clockwise round the blade, the left one clockwise
        right, left = _teeth(right, teeth, 1.0), _teeth(left, teeth, -1.0)
        info["serration"] = {"model": "teeth", "count": teeth[0], "depth": teeth[1], "rise": teeth[2]}
    axis = np.stack([np.zeros(33), np.linspace(0.0, 1.0, 33)], axis=1)
    return TopView(right, left, axis, info)


def _top_view(rng: np.random.Generator, kind: str, veined: bool = False, lobed_preset: str | None = None) -> TopView:
    """A random top view of ``kind``; ``veined``: a preset's (serrated or not, as ``kind`` says) of
    :data:`VEINED_PRESETS` at its own width, so that the preset's vein tree lies on it exactly;
    kind :data:`LOBED`: a varied lobed preset (``lobed_preset``, or one at random)."""
    # the unilobed presets (a lobed one's top view is drawn by kind LOBED, from its own margin)
    presets = sorted(name for name in builtin_presets() if name not in LOBED_PRESETS)
    if kind == LOBED:
        view = TopView(*lobed_sides(rng, lobed_preset))
    elif veined:
        view = _preset_view(rng, str(rng.choice(VEINED_PRESETS)), kind == "serrated")
    elif kind == "preset":
        view = _preset_view(rng, str(rng.choice(presets)), False)
    elif kind == "landmark":
        view = _landmark_view(rng, False, False)
    elif kind == "asymmetric":
        view = (_preset_view(rng, "asymmetric", False) if rng.random() < 0.2 else _landmark_view(rng, True, False))
    else:
        view = (_preset_view(rng, str(rng.choice(presets)), True) if rng.random() < 0.5
                else _landmark_view(rng, bool(rng.random() < 0.3), True))
    width = float(rng.uniform(0.8, 1.2))          # x only: base and apex stay where they are
    if veined:
        width = 1.0
    k = np.array([width, 1.0])
    return TopView(view.right * k, view.left * k, view.axis * k, {**view.info, "kind": kind, "width_factor": width},
                   view.params)


def _petiole(rng: np.random.Generator) -> tuple[Arr, float]:
    """The petiole's outline in leaf space (a tapering, slightly curved band from just inside the
    base down along -y) and its length in leaf lengths."""
    length = float(rng.uniform(0.05, 0.25))
    width = float(rng.uniform(0.01, 0.02))
    bend = float(rng.uniform(-0.25, 0.25))
    t = np.linspace(0.0, 1.0, 24)
    centre = np.stack([bend * length * t**2, -length * t], axis=1)
    centre[0, 1] = 0.03                           # start inside the blade: no gap at the base
    d = np.gradient(centre, axis=0)
    d /= np.hypot(d[:, 0], d[:, 1])[:, None]
    n = np.stack([-d[:, 1], d[:, 0]], axis=1) * (0.5 * width * (1.0 - 0.3 * t))[:, None]
    return np.concatenate([centre + n, (centre - n)[::-1]]), length


# ---------------------------------------------------------------------------------------------
# rasterising
# ---------------------------------------------------------------------------------------------

def coverage(poly: Arr, height: int, width: int, sub: int = SUPERSAMPLE) -> tuple[int, int, F32]:
    """The fraction of each pixel inside the closed polygon ``poly`` ((n, 2) pixel coordinates,
    centres at integers; any orientation, self-overlaps count once): ``(row0, col0, crop)`` with
    ``crop`` the coverage over the polygon's bounding box clipped to the image.

    A scanline fill: ``sub`` sub-rows per pixel row, and along each sub-row the exact length
    inside, from the signed crossings of the edges (non-zero winding, accumulated with one
    ``bincount``), so the cost follows the crossings, not pixels × vertices."""
    p = np.asarray(poly, dtype=np.float64) + 0.5            # pixel j spans [j, j + 1]
    lo_xy, hi_xy = p.min(axis=0), p.max(axis=0)
    c0, c1 = max(int(math.floor(lo_xy[0])), 0), min(int(math.ceil(hi_xy[0])), width)
    r0, r1 = max(int(math.floor(lo_xy[1])), 0), min(int(math.ceil(hi_xy[1])), height)
    if c1 <= c0 or r1 <= r0:
        return 0, 0, np.zeros((0, 0), np.float32)
    nr, nc, ns = r1 - r0, c1 - c0, (r1 - r0) * sub
    a, b = p, np.roll(p, -1, axis=0)
    ya, yb = a[:, 1], b[:, 1]
    k0 = np.clip(np.ceil((np.minimum(ya, yb) - r0) * sub - 0.5), 0, ns).astype(np.int64)
    k1 = np.clip(np.ceil((np.maximum(ya, yb) - r0) * sub - 0.5), 0, ns).astype(np.int64)
    counts = k1 - k0
    edge = np.repeat(np.arange(len(p)), counts)
    k = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts) + k0[edge]
    y = r0 + (k + 0.5) / sub
    x = a[edge, 0] + (y - ya[edge]) * (b[edge, 0] - a[edge, 0]) / (yb[edge] - ya[edge])
    sign = np.where(yb[edge] > ya[edge], 1.0, -1.0)
    xr = np.clip(x - c0, 0.0, float(nc))
    i = np.floor(xr).astype(np.int64)
    f = xr - i
    flat = k * (nc + 2) + i
    size = ns * (nc + 2)
    acc = np.bincount(np.concatenate([flat, flat + 1]), np.concatenate([sign * (1.0 - f), sign * f]),
                      size).astype(np.float32)
    cov = np.cumsum(acc.reshape(ns, nc + 2), axis=1)[:, :nc]
    cov = np.minimum(np.abs(cov, out=cov), 1.0, out=cov)
    return r0, c0, np.asarray(cov.reshape(nr, sub, nc).mean(axis=1, dtype=np.float32), dtype=np.float32)


def tree_veins(leaf: Placed, crop: tuple[int, int, F32], veins: Sequence[Vein],
               strength: tuple[float, float, float] = (1.0, 0.85, 0.3)) -> F32:
    """The veins of a known vein tree drawn over the blade's ``crop`` (row0, col0, coverage): per
    crop pixel 0..1, a Gaussian across each vein (its half-width from ``Vein.width``, at least
    0.8 px, its strength cut in proportion below that) times ``strength`` of its order (midrib,
    secondaries, tertiaries), the strongest vein winning. ``veins`` are in the (u, v) of
    ``leaf.view.params`` (:func:`leafview.botany.venation.vein_tree`), placed on its flat top
    view (:func:`leafview.deform.surface.evaluate`) and in the photo by ``leaf.px``."""
    params = leaf.view.params
    r0, c0, cov = crop
    out = np.zeros(cov.shape, np.float32)
    if params is None or not veins or not cov.size:
        return out
    rows, cols = np.nonzero(cov > 0.0)
    pixels = np.stack([cols + c0, rows + r0], axis=1).astype(np.float64)
    flat = out.reshape(-1)
    at_pixel = rows * cov.shape[1] + cols
    for order in (1, 2, 3):                       # one tree per order: a fine vein never hides a coarse one
        points, half = [], []
        for vein in veins:
            if min(max(vein.order, 1), 3) != order:
                continue
            px = leaf.px(evaluate(params, vein.uv[:, 0], vein.uv[:, 1])[:, :2])
            arc = np.r_[0.0, np.cumsum(np.hypot(*np.diff(px, axis=0).T))]
            at = np.linspace(0.0, arc[-1], max(int(arc[-1] / 0.3) + 2, 2))   # a point every 0.3 px at most
            points.append(np.stack([np.interp(at, arc, px[:, 0]), np.interp(at, arc, px[:, 1])], axis=1))
            half.append(np.full(len(at), 0.5 * vein.width * leaf.length))
        if not points:
            continue
        hw = np.concatenate(half)
        d, i = cKDTree(np.concatenate(points)).query(pixels, distance_upper_bound=3.0 * max(float(hw.max()), 0.8))
        near = np.isfinite(d)
        w = hw[i[near]]
        eff = np.maximum(w, 0.8)
        s = (np.exp(-(d[near] / eff) ** 2) * (w / eff) * strength[order - 1]).astype(np.float32)
        hit = at_pixel[near]                      # distinct pixels: a plain gather and scatter
        flat[hit] = np.maximum(flat[hit], s)
    return out


def paste(crop: tuple[int, int, F32], height: int, width: int) -> F32:
    out = np.zeros((height, width), np.float32)
    r0, c0, c = crop
    out[r0:r0 + c.shape[0], c0:c0 + c.shape[1]] = c
    return out


# ---------------------------------------------------------------------------------------------
# placing leaves on the page
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Placed:
    """A leaf on the page: pixel = ``t + length · M(theta) · leaf``, where ``M`` turns leaf space
    (y up) by ``theta`` into image space (y down); at theta = 0 the apex points up."""

    view: TopView
    petiole: Arr | None
    petiole_len: float
    theta: float
    length: float
    t: Arr

    @property
    def m(self) -> Arr:
        return _frame(self.theta)

    def px(self, q: Arr) -> Arr:
        return self.t + self.length * (np.asarray(q) @ self.m.T)

    def polygons(self) -> list[Arr]:
        return [self.px(self.view.outline)] + ([] if self.petiole is None else [self.px(self.petiole)])


def _frame(theta: float) -> Arr:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, s], [s, -c]])          # a rotation after the flip y -> -y (its own inverse)


def _points(view: TopView, petiole: Arr | None) -> Arr:
    return view.outline if petiole is None else np.concatenate([view.outline, petiole])


def _area(poly: Arr) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _length_range(lo: float, hi: float, fit: float, rng: np.random.Generator) -> float:
    hi = min(hi, fit)
    return float(rng.uniform(lo, hi)) if hi > lo else hi


def _place_primary(rng: np.random.Generator, view: TopView, petiole: Arr | None, size: tuple[int, int],
                   frac: tuple[float, float], cut: str | None) -> tuple[float, float, Arr, float]:
    """Rotation, length and translation of the first leaf, and how far it runs off a cut border
    (in leaf lengths, 0 when not cut)."""
    w, h = size
    short, m = min(w, h), _MARGIN * min(w, h)
    over = 0.0
    if cut is None:
        theta = float(rng.uniform(0.0, 2.0 * math.pi))
    else:
        out = {"left": math.pi, "right": 0.0, "top": -0.5 * math.pi, "bottom": 0.5 * math.pi}[cut]
        out += float(rng.uniform(-0.7, 0.7)) + (math.pi if rng.random() < 0.5 else 0.0)   # apex or base runs off
        theta = out + 0.5 * math.pi              # the image direction of the leaf axis is theta - pi/2
        over = float(rng.uniform(0.10, 0.25))
    unit = _points(view, petiole) @ _frame(theta).T
    lo_xy, hi_xy = unit.min(axis=0), unit.max(axis=0)
    blade = view.outline @ _frame(theta).T
    ext = hi_xy - lo_xy
    room = np.array([w - 2 * m, h - 2 * m])
    if cut is not None:                          # the blade runs off by `over`; the rest stays clear of the far border
        ax = 0 if cut in ("left", "right") else 1
        room[ax] += m
        inner = hi_xy[ax] - blade[:, ax].min() if cut in ("left", "top") else blade[:, ax].max() - lo_xy[ax]
        ext[ax] = max(inner - over, 1e-6)
    length = _length_range(frac[0] * short, frac[1] * short, float(np.min(room / ext)), rng)
    t = np.empty(2)
    for ax, n in ((0, w), (1, h)):
        lo_t, hi_t = m - 0.5 - lo_xy[ax] * length, n - 0.5 - m - hi_xy[ax] * length
        t[ax] = rng.uniform(lo_t, hi_t) if hi_t > lo_t else 0.5 * (lo_t + hi_t)
    if cut in ("left", "top"):
        ax = 0 if cut == "left" else 1
        t[ax] = -0.5 - (over + blade[:, ax].min()) * length
    elif cut in ("right", "bottom"):
        ax = 0 if cut == "right" else 1
        t[ax] = (w, h)[ax] - 0.5 + (over - blade[:, ax].max()) * length
    return theta, length, t, over


def area_mask(polys: list[Arr], scale: float, shape: tuple[int, int]) -> F32:
    out = np.zeros(shape, np.float32)
    for poly in polys:
        out = np.maximum(out, paste(coverage(poly * scale, shape[0], shape[1], 2), *shape))
    return out


def _touching(rng: np.random.Generator, a: Placed, b: Placed, size: tuple[int, int]) -> tuple[Placed, Placed, float]:
    """Put ``b`` against ``a`` so that their blades overlap by 0.5-3 % of the smaller blade
    (bisection on the distance between their centres along a random direction), then scale and
    move the pair into the page. Returns the pair and the overlap reached at the search grid."""
    target = float(rng.uniform(0.005, 0.03))
    phi = float(rng.uniform(0.0, 2.0 * math.pi))
    direction = np.array([math.cos(phi), math.sin(phi)])
    ca, cb = a.px(a.view.outline).mean(axis=0), b.px(b.view.outline).mean(axis=0)
    base_t = b.t + (ca - cb)
    scale = 200.0 / a.length                    # the search grid: the first leaf 200 cells long
    pa = a.px(a.view.outline)
    reach = float(np.ptp(pa, axis=0).max() + np.ptp(b.px(b.view.outline), axis=0).max())
    lo_d, hi_d, got = 0.0, reach, 0.0

    def overlap(d: float) -> float:
        pb = b.px(b.view.outline) - b.t + base_t + d * direction
        pts = np.concatenate([pa, pb])
        origin = pts.min(axis=0) - 2.0
        shape = tuple(int(v) for v in np.ceil((pts.max(axis=0) - origin) * scale) + 4)
        ma = area_mask([pa - origin], scale, (shape[1], shape[0]))
        mb = area_mask([pb - origin], scale, (shape[1], shape[0]))
        return float(np.minimum(ma, mb).sum() / max(min(ma.sum(), mb.sum()), 1e-9))

    for _ in range(12):
        mid = 0.5 * (lo_d + hi_d)
        g = overlap(mid)
        if g > target:
            lo_d = mid
        else:
            hi_d, got = mid, g
    if got <= 0.0:
        hi_d, got = lo_d, overlap(lo_d)
    b = replace(b, t=base_t + hi_d * direction)
    pts = np.concatenate([np.concatenate(p.polygons()) for p in (a, b)])
    w, h = size
    m = _MARGIN * min(w, h)
    ext = np.ptp(pts, axis=0)
    shrink = min(1.0, float(np.min((np.array([w, h]) - 2 * m) / ext)))
    centre = pts.min(axis=0) + 0.5 * ext
    room = np.maximum(np.array([w, h]) - 2 * m - ext * shrink, 0.0)
    new_centre = m - 0.5 + 0.5 * ext * shrink + rng.uniform(0.0, 1.0, 2) * room
    moved = [replace(p, length=p.length * shrink, t=new_centre + (p.t - centre) * shrink) for p in (a, b)]
    return moved[0], moved[1], got


def _free_spot(rng: np.random.Generator, leaf: Placed, occupied: NDArray[np.bool_], size: tuple[int, int],
               cell: int) -> Placed | None:
    """``leaf`` at a random rotation and position whose pixels stay clear of ``occupied`` (a
    grid of ``cell`` pixels), shrinking it when no place is found."""
    w, h = size
    m = _MARGIN * min(w, h)
    for attempt in range(60):
        length = leaf.length * (0.8 ** (attempt // 15))
        theta = float(rng.uniform(0.0, 2.0 * math.pi))
        unit = _points(leaf.view, leaf.petiole) @ _frame(theta).T * length
        lo_xy, hi_xy = unit.min(axis=0), unit.max(axis=0)
        lo_t, hi_t = m - 0.5 - lo_xy, np.array([w, h]) - 0.5 - m - hi_xy
        if np.any(hi_t <= lo_t):
            continue
        cand = replace(leaf, theta=theta, length=length, t=rng.uniform(lo_t, hi_t))
        grid = area_mask(cand.polygons(), 1.0 / cell, occupied.shape) > 0.0
        if not np.any(grid & occupied):
            return cand
    return None


def arrange(rng: np.random.Generator, n: int, kind: str, petiole: bool | None, size: tuple[int, int],
             touching: bool, cut: str | None, veined: bool = False,
             lobed_preset: str | None = None) -> tuple[list[Placed], dict[str, Any]]:
    """Draw ``n`` leaves (the first of ``kind``, the others of any kind) and place them on a page of
    ``size`` (width, height): the primary leaf (running off the ``cut`` border, if any), with
    ``touching`` a second one overlapping it, the rest clear of each other. Returns them and the
    layout's truth (cut, how far it runs off, touching, overlap). ``veined``: the primary leaf is
    a preset's top view that a vein tree can be drawn on (see :func:`_top_view`); ``lobed_preset``:
    the lobed preset of a primary leaf of kind :data:`LOBED`."""
    leaves: list[Placed] = []
    for i in range(n):
        view = (_top_view(rng, kind, veined, lobed_preset) if i == 0
                else _top_view(rng, str(rng.choice(KINDS)), False))
        has_petiole = bool(rng.random() < 0.5) if petiole is None else petiole
        pet, plen = _petiole(rng) if has_petiole else (None, 0.0)
        leaves.append(Placed(view, pet, plen, 0.0, 1.0, np.zeros(2)))
    frac = (0.35, 0.8) if n == 1 else (0.3, 0.45) if touching else (0.35, 0.55)
    theta, length, t, over = _place_primary(rng, leaves[0].view, leaves[0].petiole, size, frac, cut)
    leaves[0] = replace(leaves[0], theta=theta, length=length, t=t)
    info: dict[str, Any] = {"cut": cut, "cut_fraction": over, "touching": touching, "overlap": 0.0}
    placed = 1
    if touching:
        second = replace(leaves[1], theta=float(rng.uniform(0.0, 2.0 * math.pi)),
                         length=length * float(rng.uniform(0.75, 1.0)), t=t.copy())
        leaves[0], leaves[1], info["overlap"] = _touching(rng, leaves[0], second, size)
        placed = 2
    w, h = size
    cell = max(1, min(8, min(w, h) // 64))      # the occupancy grid, and a gap of about 3 % between leaves
    grid = (-(-h // cell), -(-w // cell))
    gap = max(1, round(0.03 * min(w, h) / cell))
    for i in range(placed, n):
        occupied = np.zeros(grid, bool)
        for leaf in leaves[:i]:
            occupied |= area_mask(leaf.polygons(), 1.0 / cell, grid) > 0.0
        occupied = ndimage.binary_dilation(occupied, iterations=gap)
        # shorter than the first leaf and at most 60 % of its area
        ratio = math.sqrt(0.6 * _area(leaves[0].view.outline) / _area(leaves[i].view.outline))
        length = leaves[0].length * min(float(rng.uniform(0.45, 0.8)), ratio)
        spot = _free_spot(rng, replace(leaves[i], length=length), occupied, size, cell)
        if spot is None:
            raise ParamError("leaves", f"{n} leaves do not fit on a {w}×{h} page")
        leaves[i] = spot
    return leaves, info
