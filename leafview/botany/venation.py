"""The vein tree of a leaf (Hong 2005, ch. 6.1): the midrib, the secondaries and the reticulate
tertiary network, built from :class:`~leafview.core.venation.Venation` in the blade's own (u, v).

**Where veins live.** Every vein is a polyline in the surface parameters (u, v) (u ∈ [-1, 1]
across, v ∈ [0, 1] base → apex; :mod:`leafview.core.blade`), so it follows every shape, ripple
and bend of the leaf; :attr:`Vein.points` is the surface (:func:`leafview.deform.surface.evaluate`)
at those parameters. Angles and lengths are laid out in *vein space* q(u, v) = (u · w(v), v), w(v)
the half-width of the flat blade (:mod:`leafview.botany.vein_field`), where a step has about the
same length on the leaf in either direction: a secondary at ``angle`` leaves the midrib at that
angle in q. The margin is |q_x| = w(q_y); veins are traced until they reach it.

**Patterns** (Hong 2005, ch. 6.1: a hierarchy of vein orders, each branching from the one above):

* *pinnate*: ``secondaries`` veins per side leave the midrib at v_k, evenly spaced in
  [0.03, 0.9] with a jitter of ``irregularity`` × 0.35 spacing, the two sides shifted by
  ``alternate`` × ½ spacing. A secondary leaves at ``angle`` (± 6° × ``irregularity``) from its
  parent; those leaving the midrib below v = 0.3 open up towards 90° (by 0.7 (1 - v / 0.3)^1.5 of
  the difference) and fill the base of the blade. It turns towards its parent's direction: at
  arc length s its heading is α₀ (1 - ``curvature`` · min(s / ℓ, 1)) from the parent, ℓ the
  length of the straight vein to the margin. It ends at the margin (``loop`` = 0,
  craspedodromous) or, when ``loop`` > 0, at that fraction of its length, from where an arch (a
  quadratic Bézier leaving in the vein's direction) joins it to the same point of the next
  secondary up (brochidodromous); the last one runs to the margin.
* *palmate*: ``primaries`` lateral primaries per side fan out from the base at
  φ_j = φ_max j / (n + ½), φ_max the widest direction in which a straight vein from the base
  still runs ⅓ as far as the longest one, turning towards the apex by ½ ``curvature``.
  Secondaries leave the midrib as in a pinnate leaf (from v = 0.12) and each primary on its
  outer side; a secondary that meets the next primary out ends there (joins it).
* *parallel*: ``secondaries`` veins per side run from base to apex at fixed
  u_k = (k ± 0.35 ``irregularity``) / (n + 1), as in grasses.

**Tertiaries** (order 3): about ``tertiary`` percurrent cross-veins per leaf length of the
shorter of two neighbouring secondaries (same parent, same side) join them, from evenly spaced
points of the lower one to the nearest point of the upper one, bowed a little at random; in each
cell between two cross-veins a veinlet of order 4 joins random points of the two (a seeded,
Voronoi-like mesh). In a parallel leaf, round(``tertiary``) short transverse veins at random
heights join each pair of neighbouring parallel veins (the midrib included).

**Widths** taper by order: ``midrib_width`` · ``width_ratio`` ** (order - 1).

**Edits** (Hong 2005, ch. 7.1; :func:`edited_uv`): vein ``vein`` of side ``side`` is one of
the veins that leave the midrib on that side, counted from the base (palmate: the lateral
primaries first, innermost first, then the midrib's secondaries; parallel: from the midrib
outwards). In vein space it is turned about its hinge (its first point) by ``angle`` (positive
towards the apex) and, when it ended on the margin, stretched or shrunk along itself so that it
ends on the margin again; then every point moves by ``bulge`` · 4t(1 - t) along the normal of its
chord (positive towards the apex), t its fraction of the vein's arc length. An edit that takes a
vein out of the blade or across the midrib is refused by :func:`check_veins`, naming
``venation.edits[i].angle`` or ``.bulge`` (refused, not clamped: the message says where).

The tree depends only on the shape and the venation, and is deterministic for a seed.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import NamedTuple, NoReturn

import numpy as np
from numpy.typing import NDArray

from leafview.botany.vein_space import halfwidth_at, halfwidth_table
from leafview.core.params import LeafParams, Shape
from leafview.core.venation import Venation
from leafview.deform.surface import evaluate
from leafview.errors import ParamError

__all__ = ["Vein", "VeinSegments", "vein_tree", "vein_segments", "check_veins", "edited_uv", "edit_slots", "basal_lift",
           "BASAL_ANGLE", "SECONDARY_V_RANGE"]

Arr = NDArray[np.float64]

_STEP = 0.0025             # tracing step in vein space (leaf lengths)
_MAX_LENGTH = 2.0          # no vein is traced further than this
_SPACING = 0.02            # point spacing of the stored polylines
_MAX_POINTS = 64
SECONDARY_V_RANGE = (0.03, 0.9)     # where pinnate secondaries leave the midrib
BASAL_ANGLE = 90.0         # degrees: secondaries leaving the midrib low down open up towards it (basal_lift)
_BASAL_V = 0.3             # ... below this v
_BASAL_SPREAD = 0.7
_EPS = 1e-9


@dataclass(frozen=True)
class Vein:
    """One vein: ``points`` (N, 3) in leaf space on the (unedited) surface, ``uv`` (N, 2) its
    surface parameters, ``order`` (1 midrib and primaries, 2 secondaries, 3 tertiaries, 4 the
    finer mesh), ``parent`` (index in the list, -1 for the midrib) and ``width`` (leaf lengths)."""

    points: Arr
    uv: Arr
    order: int
    parent: int
    width: float


class VeinSegments(NamedTuple):
    """Every vein as straight segments in (u, v): ``uv0``/``uv1`` (M, 2) float64, the vein's
    ``order`` (M,) int32 and ``width`` (M,) float32, and ``vein`` (M,) int32 its index in
    :func:`vein_tree`."""

    uv0: Arr
    uv1: Arr
    order: NDArray[np.int32]
    width: NDArray[np.float32]
    vein: NDArray[np.int32]


def basal_lift(v0: NDArray[np.floating] | float) -> NDArray[np.float64]:
    """How far (0..1) a secondary leaving the midrib at v = ``v0`` turns from the venation's angle
    towards :data:`BASAL_ANGLE`: 0 above v = 0.3, rising as (1 - v0 / 0.3)^1.5 · 0.7 below, so the
    basal secondaries fill the base of the blade. Broadcasts."""
    return np.asarray(_BASAL_SPREAD * np.clip(1.0 - np.asarray(v0, np.float64) / _BASAL_V, 0.0, 1.0) ** 1.5,
                      np.float64)


# -- vein space --------------------------------------------------------------------------------
class _Space:
    """q(u, v) = (u w(v), v) of one blade; w from the same table as the vein field."""

    def __init__(self, shape: Shape) -> None:
        self.table = halfwidth_table(LeafParams(shape=shape)).astype(np.float64)

    def w(self, y: Arr) -> Arr:
        return halfwidth_at(self.table, y)

    def outside(self, q: Arr) -> Arr:
        """How far ``q`` (..., 2; x ≥ 0 on the side traced) lies outside the blade (> 0 outside)."""
        x, y = q[..., 0], q[..., 1]
        return np.maximum(np.maximum(np.abs(x) - self.w(y), y - 1.0), -y)

    def to_uv(self, q: Arr) -> Arr:
        w = self.w(q[..., 1])
        u = np.where(w > _EPS, q[..., 0] / np.maximum(w, _EPS), 0.0)
        return np.stack([np.clip(u, -1.0, 1.0), np.clip(q[..., 1], 0.0, 1.0)], axis=-1)

    def to_q(self, uv: Arr) -> Arr:
        return np.stack([uv[..., 0] * self.w(uv[..., 1]), uv[..., 1]], axis=-1)


# -- tracing -----------------------------------------------------------------------------------
def _trace(space: _Space, origin: Arr, base: Arr, theta: Arr, curvature: float, ell: Arr | None,
           stop: tuple[_Fan, int] | None = None, want_paths: bool = True) -> tuple[list[Arr], Arr, NDArray[np.bool_]]:
    """Trace veins in the side frame (x ≥ 0 outwards) from ``origin`` (K, 2): heading
    ``base + theta (1 - curvature min(s / ell, 1))`` (radians from +y towards +x) until the
    margin or, with ``stop``, the next primary. Returns the dense polylines, their lengths and
    whether each ended on the margin (no polylines unless ``want_paths``)."""
    k = len(origin)
    n_max = int(math.ceil(min(_MAX_LENGTH, 1.05 + 2.0 * float(space.table.max())) / _STEP))
    n = min(128, n_max)
    while True:   # most veins are short: trace 128 steps, then twice as many until every vein has ended
        out = _trace_steps(space, origin, base, theta, curvature, ell, stop, n)
        if n >= n_max or out[0].all():
            break
        n = min(2 * n, n_max)
    left, pos, f, margin_f = out
    rows = np.arange(k)
    first = np.where(left, (f > 0.0).argmax(axis=1), n)      # never left within the length: keep it all
    j = np.maximum(first, 1)
    jc = np.minimum(j, n)
    f0, f1 = f[rows, jc - 1], f[rows, jc]
    t = np.where(left, np.clip(f0 / np.where(f1 != f0, f0 - f1, -1.0), 0.0, 1.0), 1.0)
    lengths = (jc - 1 + t) * _STEP                   # every step is _STEP long
    on_margin = left & (margin_f[rows, jc] >= f[rows, jc] - 1e-12)
    paths: list[Arr] = []
    if want_paths:
        for i in range(k):
            end = pos[i, jc[i] - 1] + t[i] * (pos[i, jc[i]] - pos[i, jc[i] - 1])
            paths.append(np.concatenate([pos[i, :jc[i]], end[None]], axis=0))
    return paths, lengths, on_margin


def _trace_steps(space: _Space, origin: Arr, base: Arr, theta: Arr, curvature: float, ell: Arr | None,
                 stop: tuple[_Fan, int] | None, n: int) -> tuple[NDArray[np.bool_], Arr, Arr, Arr]:
    """``n`` steps of :func:`_trace`: whether each vein left, the positions (K, n + 1, 2), the
    outside measure with and without the stop."""
    k = len(origin)
    s = np.arange(1, n + 1) * _STEP
    if ell is None or curvature == 0.0:
        alpha = np.broadcast_to((base + theta)[:, None], (k, n))
    else:
        frac = np.minimum(s[None, :] / np.maximum(ell, _STEP)[:, None], 1.0)
        alpha = base[:, None] + theta[:, None] * (1.0 - curvature * frac)
    steps = _STEP * np.stack([np.sin(alpha), np.cos(alpha)], axis=-1)
    pos = np.concatenate([origin[:, None, :], origin[:, None, :] + np.cumsum(steps, axis=1)], axis=1)
    f = space.outside(pos)
    f[:, 0] = np.minimum(f[:, 0], -_EPS)       # the origin counts as inside
    margin_f = f.copy()
    if stop is not None and stop[1] >= 0:
        f = np.maximum(f, stop[0].beyond(pos, stop[1]))
        f[:, 0] = np.minimum(f[:, 0], -_EPS)
    left: NDArray[np.bool_] = np.asarray((f > 0.0).any(axis=1))
    return left, np.asarray(pos, np.float64), f, margin_f


def _arc_length(p: Arr) -> Arr:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def _at_length(p: Arr, s: Arr | float) -> Arr:
    """Points of polyline ``p`` at arc lengths ``s``."""
    arc = _arc_length(p)
    ss = np.asarray(s, np.float64)
    return np.stack([np.interp(ss, arc, p[:, 0]), np.interp(ss, arc, p[:, 1])], axis=-1)


def _cut(p: Arr, s: float) -> Arr:
    """``p`` up to arc length ``s``."""
    arc = _arc_length(p)
    j = int(np.searchsorted(arc, s))
    return np.concatenate([p[:j], _at_length(p, s)[None]], axis=0)


def _along3(c: Arr, f: Arr) -> Arr:
    """Points at fractions ``f`` (K,) of the arc length of the 3-point polylines ``c`` (K, 3, 2)."""
    l1 = np.linalg.norm(c[:, 1] - c[:, 0], axis=1)
    l2 = np.linalg.norm(c[:, 2] - c[:, 1], axis=1)
    s = f * (l1 + l2)
    t1 = np.clip(s / np.maximum(l1, _EPS), 0.0, 1.0)[:, None]
    t2 = np.clip((s - l1) / np.maximum(l2, _EPS), 0.0, 1.0)[:, None]
    first = (s <= l1)[:, None]
    return np.where(first, c[:, 0] + t1 * (c[:, 1] - c[:, 0]), c[:, 1] + t2 * (c[:, 2] - c[:, 1]))


def _rest(p: Arr, s: float) -> Arr:
    """``p`` from arc length ``s`` on."""
    arc = _arc_length(p)
    j = int(np.searchsorted(arc, s, side="right"))
    return np.concatenate([_at_length(p, s)[None], p[j:]], axis=0)


def _resample(p: Arr) -> Arr:
    """``p`` with points about :data:`_SPACING` apart (at least 2, at most :data:`_MAX_POINTS`)."""
    arc = _arc_length(p)
    m = int(np.clip(math.ceil(arc[-1] / _SPACING) + 1, 2, _MAX_POINTS))
    return _at_length(p, np.linspace(0.0, arc[-1], m))


class _Fan:
    """The lateral primaries of one side as polar angles Φ_j(r) about the base: a point is beyond
    primary j when its polar angle exceeds Φ_j at its distance from the base."""

    def __init__(self, paths: list[Arr]) -> None:
        self.curves = []
        for p in paths:
            r = np.linalg.norm(p, axis=1)
            phi = np.arctan2(p[:, 0], p[:, 1])
            keep = np.concatenate([[True], np.diff(np.maximum.accumulate(r)) > 0])
            self.curves.append((np.maximum.accumulate(r)[keep], phi[keep]))

    def beyond(self, pos: Arr, j: int) -> Arr:
        """(K, n) > 0 where the traced points ``pos`` (K, n, 2) lie beyond primary ``j``."""
        rr, phi = self.curves[j]
        r = np.linalg.norm(pos, axis=-1)
        return np.arctan2(pos[..., 0], pos[..., 1]) - np.interp(r, rr, phi)


# -- the skeleton: veins in vein space ----------------------------------------------------------
@dataclass
class _Skel:
    q: Arr              # (n, 2) polyline in vein space (x signed)
    order: int
    parent: int
    side: int           # -1, +1, 0 for the midrib
    margin: bool = False  # ends on the margin (its last point gets |u| = 1 exactly)
    final: bool = False   # q already holds the stored points (no resampling)
    uv: Arr | None = None  # the stored (u, v) when the vein was laid out in (u, v)


@dataclass(frozen=True)
class _Tree:
    uv: tuple[Arr, ...]
    order: tuple[int, ...]
    parent: tuple[int, ...]
    width: tuple[float, ...]
    slots: dict[int, tuple[int, ...]]     # side -> indices of the veins edits address
    table: Arr


class _Builder:
    def __init__(self, shape: Shape, ven: Venation) -> None:
        self.ven = ven
        self.space = _Space(shape)
        self.rng = np.random.default_rng(int(ven.seed))
        self.veins: list[_Skel] = [_Skel(np.stack([np.zeros(33), np.linspace(0.0, 1.0, 33)], axis=1), 1, -1, 0)]
        self.slots: dict[int, list[int]] = {-1: [], 1: []}
        # per (parent, side): the secondaries' bodies (the part before any loop), base to apex
        self.groups: dict[tuple[int, int], list[tuple[int, Arr]]] = {}

    def add(self, q: Arr, order: int, parent: int, side: int, *, slot: bool = False, margin: bool = False,
            final: bool = False, uv: Arr | None = None) -> int:
        self.veins.append(_Skel(q, order, parent, side, margin, final, uv))
        i = len(self.veins) - 1
        if slot:
            self.slots[side].append(i)
        return i

    # secondaries leaving a parent polyline (side frame) at arc lengths ``at``
    def secondaries(self, side: int, parent: int, path: Arr, at: Arr, *, fan: _Fan | None = None,
                    obstacle: int = -1) -> None:
        ven = self.ven
        k = len(at)
        if k == 0:
            return
        origin = _at_length(path, at)
        ahead = _at_length(path, np.minimum(at + 1e-3, _arc_length(path)[-1]))
        d = ahead - origin
        base = np.arctan2(d[:, 0], d[:, 1])
        deg = ven.angle + 6.0 * ven.irregularity * self.rng.uniform(-1.0, 1.0, k)
        if parent == 0:   # basal secondaries open up towards 90° (they fill the base of the blade)
            deg = deg + (BASAL_ANGLE - ven.angle) * basal_lift(origin[:, 1])
        theta = np.radians(deg)
        theta = np.clip(theta, math.radians(1.0), math.radians(89.0))
        stop = None if fan is None else (fan, obstacle)
        _, ell, _ = _trace(self.space, origin, base, theta, 0.0, None, stop, want_paths=False)
        paths, lengths, on_margin = _trace(self.space, origin, base, theta, ven.curvature, ell, stop)
        kept = [i for i in range(k) if lengths[i] > 4 * _STEP]
        loop = ven.loop
        bodies = [paths[i] if loop == 0.0 or not on_margin[i] else _cut(paths[i], loop * lengths[i]) for i in kept]
        group = self.groups.setdefault((parent, side), [])
        for n, i in enumerate(kept):
            looped = loop > 0.0 and bool(on_margin[i]) and n + 1 < len(kept) and bool(on_margin[kept[n + 1]])
            if looped:   # the junction with the next one stays a vertex of both
                body = bodies[n]
                q = np.concatenate([_resample(body), self._arch(body, bodies[n + 1][-1])[1:]], axis=0)
            elif loop > 0.0 and on_margin[i]:   # keep the point where the one below joins it a vertex
                body = paths[i]
                q = np.concatenate([_resample(bodies[n]), _resample(_rest(body, loop * lengths[i]))[1:]], axis=0)
            else:
                body = paths[i]
                q = _resample(body)
            idx = self.add(q * [side, 1.0], 2, parent, side, slot=(parent == 0),
                           margin=bool(on_margin[i]) and not looped, final=True)
            group.append((idx, body * [side, 1.0]))

    def _arch(self, body: Arr, target: Arr) -> Arr:
        """A quadratic Bézier from the end of ``body`` (leaving in its direction) to ``target``,
        pulled in until it lies inside the blade."""
        start = body[-1]
        d = body[-1] - body[-2]
        d = d / max(float(np.linalg.norm(d)), _EPS)
        reach = 0.5 * float(np.linalg.norm(target - start))
        t = np.linspace(0.0, 1.0, 12)[:, None]
        for _ in range(8):
            c = start + reach * d
            arch = (1 - t) ** 2 * start + 2 * t * (1 - t) * c + t**2 * target
            if (self.space.outside(arch) <= 0.0).all():
                return arch
            reach *= 0.5
        return (1 - t) * start + t * target

    def pinnate(self, side: int, *, v_range: tuple[float, float] = SECONDARY_V_RANGE, fan: _Fan | None = None) -> None:
        ven = self.ven
        n = ven.secondaries
        lo, hi = v_range
        spacing = (hi - lo) / n
        shift = 0.25 * ven.alternate * side
        jitter = 0.35 * ven.irregularity * self.rng.uniform(-1.0, 1.0, n)
        at = lo + (np.arange(n) + 0.5 + shift + jitter) * spacing
        midrib = np.stack([np.zeros(2), [0.0, 1.0]], axis=1)
        self.secondaries(side, 0, midrib, np.clip(at, 0.0, 1.0), fan=fan, obstacle=0)

    def palmate(self, side: int) -> None:
        ven = self.ven
        n = ven.primaries
        phis = np.radians(np.linspace(4.0, 88.0, 22))
        _, reach, _ = _trace(self.space, np.zeros((len(phis), 2)), phis, np.zeros(len(phis)), 0.0, None,
                             want_paths=False)
        ok = reach >= reach.max() / 3.0
        phi_max = float(phis[ok].max())
        phi = phi_max * np.arange(1, n + 1, dtype=np.float64) / (n + 0.5)
        origin = np.zeros((n, 2))
        _, ell, _ = _trace(self.space, origin, np.zeros(n), phi, 0.0, None, want_paths=False)
        paths, lengths, _ = _trace(self.space, origin, np.zeros(n), phi, 0.5 * ven.curvature, ell)
        fan = _Fan(paths)
        primaries = [self.add(_resample(p) * [side, 1.0], 1, 0, side, slot=True, margin=True, final=True)
                     for p in paths]
        # the midrib's secondaries stop at the innermost primary, each primary's at the next one out
        self.pinnate(side, v_range=(0.12, 0.9), fan=fan)
        for j, (idx, p) in enumerate(zip(primaries, paths)):
            count = max(1, int(round(ven.secondaries * lengths[j] * 0.8)))
            at = (0.15 + 0.75 * (np.arange(count) + 0.5 + 0.35 * ven.irregularity
                                 * self.rng.uniform(-1.0, 1.0, count)) / count) * lengths[j]
            self.secondaries(side, idx, p, at, fan=fan, obstacle=j + 1 if j + 1 < n else -1)

    def parallel(self, side: int) -> None:
        ven = self.ven
        n = ven.secondaries
        jitter = 0.35 * ven.irregularity * self.rng.uniform(-1.0, 1.0, n)
        us = (np.arange(1, n + 1) + jitter) / (n + 1)
        v = np.linspace(0.0, 1.0, 33)
        for u in us:
            uv = np.stack([np.full_like(v, side * u), v], axis=1)
            self.add(self.space.to_q(uv), 2, 0, side, slot=True, uv=uv)
        # transverse veins between neighbours (the midrib first)
        count = int(round(ven.tertiary))
        if count == 0:
            return
        ring = [0.0, *us]
        for a, b in zip(ring[:-1], ring[1:]):
            vs = np.sort(self.rng.uniform(0.03, 0.97, count))
            for vv in vs:
                uv = np.array([[side * a, vv], [side * b, vv]])
                self.add(self.space.to_q(uv), 3, 0, side, uv=uv)

    def tertiaries(self) -> None:
        ven = self.ven
        if ven.tertiary == 0.0:
            return
        rng = self.rng
        for (_, side), group in self.groups.items():
            for (ia, a), (_, b) in zip(group[:-1], group[1:]):
                la, lb = _arc_length(a)[-1], _arc_length(b)[-1]
                count = int(math.floor(ven.tertiary * min(la, lb)))
                if count < 1:
                    continue
                f = (np.arange(count) + 0.5 + 0.3 * ven.irregularity * rng.uniform(-1, 1, count)) / count
                f = np.clip(f, 0.05, 0.95)
                p0 = _at_length(a, f * la)
                p1 = b[np.argmin(((p0[:, None, :] - b[None, :, :]) ** 2).sum(axis=-1), axis=1)]   # nearest: percurrent
                d = p1 - p0
                bow = 0.15 * (0.3 + ven.irregularity) * rng.normal(size=count)
                mid = 0.5 * (p0 + p1) + bow[:, None] * np.stack([-d[:, 1], d[:, 0]], axis=1)
                out = self.space.outside(mid * [side, 1.0]) > 0.0
                mid[out] = 0.5 * (p0[out] + p1[out])
                cross = np.stack([p0, mid, p1], axis=1)                       # (count, 3, 2)
                first = len(self.veins)
                for c in cross:
                    self.add(c, 3, ia, side)
                if count < 2:
                    continue
                # the finer mesh: a veinlet between random points of neighbouring cross-veins
                s = rng.uniform(0.25, 0.75, (count - 1, 2))
                q0 = _along3(cross[:-1], s[:, 0])
                q1 = _along3(cross[1:], s[:, 1])
                for j in range(count - 1):
                    self.add(np.stack([q0[j], 0.5 * (q0[j] + q1[j]), q1[j]]), 4, first + j, side)

    def build(self) -> _Tree:
        ven = self.ven
        for side in (-1, 1):
            getattr(self, ven.pattern)(side)
        if ven.pattern != "parallel":
            self.tertiaries()
        qs = [v.q if v.final or len(v.q) <= 3 or v.parent == -1 else _resample(v.q) for v in self.veins]
        sizes = np.cumsum([len(q) for q in qs])[:-1]
        uv = np.split(self.space.to_uv(np.concatenate(qs, axis=0)), sizes)
        for i, vein in enumerate(self.veins):
            if vein.uv is not None:
                uv[i] = vein.uv.copy()
            if vein.margin:
                uv[i][-1, 0] = float(vein.side)
            uv[i].setflags(write=False)
        widths = tuple(float(ven.midrib_width * ven.width_ratio ** (v.order - 1)) for v in self.veins)
        return _Tree(tuple(uv), tuple(v.order for v in self.veins), tuple(v.parent for v in self.veins), widths,
                     {s: tuple(ix) for s, ix in self.slots.items()}, self.space.table)


@functools.lru_cache(maxsize=64)
def _tree(shape: Shape, venation: Venation) -> _Tree:
    return _Builder(shape, venation).build()


# -- public API ----------------------------------------------------------------------------------
def vein_tree(params: LeafParams) -> list[Vein]:
    """The veins of ``params`` (no edits applied): the midrib first (index 0, parent -1), then
    the primaries and secondaries, then the tertiaries; see the module docstring. Built whether
    or not ``params.venation.enabled`` (which only says whether renderers show them)."""
    tree = _tree(params.shape, _unedited(params.venation))
    sizes = [len(p) for p in tree.uv]
    uv = np.concatenate(tree.uv, axis=0)
    pts = evaluate(params, uv[:, 0], uv[:, 1])
    out = []
    start = 0
    for i, n in enumerate(sizes):
        p = pts[start:start + n]
        p.setflags(write=False)
        out.append(Vein(p, tree.uv[i], tree.order[i], tree.parent[i], tree.width[i]))
        start += n
    return out


def _unedited(venation: Venation) -> Venation:
    """The venation without its edits (the tree does not depend on them; the cache key)."""
    return replace(venation, edits=()) if venation.edits else venation


def vein_segments(params: LeafParams) -> VeinSegments:
    """Every vein of :func:`vein_tree` as straight (u, v) segments between consecutive points."""
    tree = _tree(params.shape, _unedited(params.venation))
    uv0 = np.concatenate([p[:-1] for p in tree.uv], axis=0)
    uv1 = np.concatenate([p[1:] for p in tree.uv], axis=0)
    counts = np.array([len(p) - 1 for p in tree.uv])
    vein = np.repeat(np.arange(len(tree.uv), dtype=np.int32), counts)
    order = np.asarray(tree.order, np.int32)[vein]
    width = np.asarray(tree.width, np.float32)[vein]
    return VeinSegments(uv0, uv1, order, width, vein)


def edit_slots(params: LeafParams) -> dict[int, tuple[int, ...]]:
    """For each side (-1, +1), the indices in :func:`vein_tree` of the veins that edits address,
    in the order of :attr:`VeinEdit.vein <leafview.core.venation.VeinEdit.vein>`."""
    return dict(_tree(params.shape, _unedited(params.venation)).slots)


def _rotate_scale(space: _Space, q: Arr, side: int, angle: float, to_margin: bool) -> Arr:
    """Turn the side-frame polyline ``q`` about its first point by ``angle`` (radians, towards
    the apex) and, when it ended on the margin, scale it about that point to end there again."""
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])            # counter-clockwise in (x outwards, y up): towards +y
    hinge = q[0]
    r = (q - hinge) @ rot.T
    if to_margin:
        end = r[-1]
        lam = np.linspace(0.0, 4.0, 4001)[1:]
        f = space.outside(hinge + lam[:, None] * end[None, :])
        hit = np.flatnonzero(f > 0.0)
        if len(hit) and hit[0] > 0:
            j = hit[0]
            t = f[j - 1] / (f[j - 1] - f[j])
            r = r * (lam[j - 1] + t * (lam[j] - lam[j - 1]))
    return hinge + r


def edited_uv(params: LeafParams) -> list[Arr]:
    """The (u, v) of every vein of :func:`vein_tree` after ``params.venation.edits`` (Hong 2005,
    ch. 7.1; see the module docstring): the position in the flat blade each point of an edited
    vein moves to. Unedited veins keep theirs. Points may lie outside the blade (|u| > 1, v
    outside [0, 1]) when an edit takes them there: :func:`check_veins` refuses such edits."""
    return [uv for uv, _ in _edit(params)]


def _edit(params: LeafParams) -> list[tuple[Arr, str | None]]:
    ven = params.venation
    tree = _tree(params.shape, _unedited(ven))
    space = _Space.__new__(_Space)
    space.table = tree.table
    out: list[tuple[Arr, str | None]] = [(uv, None) for uv in tree.uv]
    for i, e in enumerate(ven.edits):
        where = f"venation.edits[{i}]"
        slots = tree.slots[e.side]
        if e.vein >= len(slots):
            raise ParamError(f"{where}.vein", f"side {e.side:+d} of this {ven.pattern} leaf has {len(slots)} "
                                              f"editable veins (0..{len(slots) - 1}), not {e.vein}")
        idx = slots[e.vein]
        uv = tree.uv[idx]
        q = space.to_q(uv) * [e.side, 1.0]
        end = uv[-1]
        to_margin = abs(abs(end[0]) - 1.0) < 1e-9 or end[1] >= 1.0 - 1e-9
        q = _rotate_scale(space, q, e.side, math.radians(e.angle), to_margin)
        cause = "angle"
        if e.bulge:
            bad = _out(space, q)
            if bad.any():
                _fail(where, "angle", space, q)
            arc = _arc_length(q)
            t = arc / max(arc[-1], _EPS)
            chord = q[-1] - q[0]
            normal = np.array([-chord[1], chord[0]]) / max(float(np.linalg.norm(chord)), _EPS)
            q = q + e.bulge * (4.0 * t * (1.0 - t))[:, None] * normal
            cause = "bulge"
        bad = _out(space, q)
        if bad.any():
            _fail(where, cause, space, q)
        qs = q * [e.side, 1.0]
        w = space.w(qs[:, 1])
        u = np.where(w > _EPS, qs[:, 0] / np.maximum(w, _EPS), 0.0)
        out[idx] = (np.stack([np.clip(u, -1.0, 1.0), qs[:, 1]], axis=1), None)
    return out


def _out(space: _Space, q: Arr) -> NDArray[np.bool_]:
    """Which points of the side-frame polyline ``q`` lie outside the blade or across the midrib
    (the hinge itself, on its parent, never counts)."""
    bad = (space.outside(q) > 1e-9) | (q[:, 0] < -1e-9)
    bad[0] = False
    return bad


def _fail(where: str, cause: str, space: _Space, q: Arr) -> NoReturn:
    bad = _out(space, q)
    x, y = q[int(np.argmax(bad))]
    what = "across the midrib" if x < 0.0 else "out of the blade"
    raise ParamError(f"{where}.{cause}", f"takes the vein {what} (at vein-space point ({abs(x):.3f}, {y:.3f})): "
                                         f"use a smaller {cause}")


def check_veins(params: LeafParams) -> None:
    """Raise :class:`ParamError` naming the field when a vein of ``params`` leaves the blade:
    an edit of a vein that does not exist (``venation.edits[i].vein``), or that turns or bows a
    vein out of the blade (``venation.edits[i].angle`` / ``.bulge``); or, as a safeguard, a
    generated vein outside |u| ≤ 1, 0 ≤ v ≤ 1 (named after the pattern's shaping field)."""
    tree = _tree(params.shape, _unedited(params.venation))
    for i, uv in enumerate(tree.uv):
        if not (np.isfinite(uv).all() and (np.abs(uv[:, 0]) <= 1.0).all()
                and (uv[:, 1] >= 0.0).all() and (uv[:, 1] <= 1.0).all()):
            field = "venation.curvature" if tree.order[i] <= 2 else "venation.tertiary"
            raise ParamError(field, f"vein {i} (order {tree.order[i]}) leaves the blade")
    _edit(params)
