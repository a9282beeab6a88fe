"""Tracing the vein tree in vein space (Hong 2005, ch. 6.1): the secondaries' law (angle to the
parent, curving towards the apex, the basal ones opening up), pinnate, palmate and parallel
skeletons, loops and the tertiary network. :mod:`leafview.botany.venation` holds the public tree
(:func:`~leafview.botany.venation.vein_tree`) and the edits; this module builds the skeleton it
caches."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leafview.botany.vein_space import halfwidth_at, halfwidth_table
from leafview.core.params import LeafParams, Shape
from leafview.core.venation import Venation

__all__ = ["SECONDARY_V_RANGE", "BASAL_ANGLE", "EPS", "basal_lift", "arc_length", "Space", "Tree", "build_tree"]

Arr = NDArray[np.float64]

_STEP = 0.0025             # tracing step in vein space (leaf lengths)
_MAX_LENGTH = 2.0          # no vein is traced further than this
_SPACING = 0.02            # point spacing of the stored polylines
_MAX_POINTS = 64
SECONDARY_V_RANGE = (0.03, 0.9)     # where pinnate secondaries leave the midrib
BASAL_ANGLE = 90.0         # degrees: secondaries leaving the midrib low down open up towards it (basal_lift)
_BASAL_V = 0.3             # ... below this v
_BASAL_SPREAD = 0.7
EPS = 1e-9


def basal_lift(v0: NDArray[np.floating] | float) -> NDArray[np.float64]:
    """How far (0..1) a secondary leaving the midrib at v = ``v0`` turns from the venation's angle
    towards :data:`BASAL_ANGLE`: 0 above v = 0.3, rising as (1 - v0 / 0.3)^1.5 · 0.7 below, so the
    basal secondaries fill the base of the blade. Broadcasts."""
    return np.asarray(_BASAL_SPREAD * np.clip(1.0 - np.asarray(v0, np.float64) / _BASAL_V, 0.0, 1.0) ** 1.5,
                      np.float64)


# -- vein space --------------------------------------------------------------------------------
class Space:
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
        u = np.where(w > EPS, q[..., 0] / np.maximum(w, EPS), 0.0)
        return np.stack([np.clip(u, -1.0, 1.0), np.clip(q[..., 1], 0.0, 1.0)], axis=-1)

    def to_q(self, uv: Arr) -> Arr:
        return np.stack([uv[..., 0] * self.w(uv[..., 1]), uv[..., 1]], axis=-1)


# -- tracing -----------------------------------------------------------------------------------
def _trace(space: Space, origin: Arr, base: Arr, theta: Arr, curvature: float, ell: Arr | None,
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


def _trace_steps(space: Space, origin: Arr, base: Arr, theta: Arr, curvature: float, ell: Arr | None,
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
    f[:, 0] = np.minimum(f[:, 0], -EPS)       # the origin counts as inside
    margin_f = f.copy()
    if stop is not None and stop[1] >= 0:
        f = np.maximum(f, stop[0].beyond(pos, stop[1]))
        f[:, 0] = np.minimum(f[:, 0], -EPS)
    left: NDArray[np.bool_] = np.asarray((f > 0.0).any(axis=1))
    return left, np.asarray(pos, np.float64), f, margin_f


def arc_length(p: Arr) -> Arr:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def _at_length(p: Arr, s: Arr | float) -> Arr:
    """Points of polyline ``p`` at arc lengths ``s``."""
    arc = arc_length(p)
    ss = np.asarray(s, np.float64)
    return np.stack([np.interp(ss, arc, p[:, 0]), np.interp(ss, arc, p[:, 1])], axis=-1)


def _cut(p: Arr, s: float) -> Arr:
    """``p`` up to arc length ``s``."""
    arc = arc_length(p)
    j = int(np.searchsorted(arc, s))
    return np.concatenate([p[:j], _at_length(p, s)[None]], axis=0)


def _along3(c: Arr, f: Arr) -> Arr:
    """Points at fractions ``f`` (K,) of the arc length of the 3-point polylines ``c`` (K, 3, 2)."""
    l1 = np.linalg.norm(c[:, 1] - c[:, 0], axis=1)
    l2 = np.linalg.norm(c[:, 2] - c[:, 1], axis=1)
    s = f * (l1 + l2)
    t1 = np.clip(s / np.maximum(l1, EPS), 0.0, 1.0)[:, None]
    t2 = np.clip((s - l1) / np.maximum(l2, EPS), 0.0, 1.0)[:, None]
    first = (s <= l1)[:, None]
    return np.where(first, c[:, 0] + t1 * (c[:, 1] - c[:, 0]), c[:, 1] + t2 * (c[:, 2] - c[:, 1]))


def _rest(p: Arr, s: float) -> Arr:
    """``p`` from arc length ``s`` on."""
    arc = arc_length(p)
    j = int(np.searchsorted(arc, s, side="right"))
    return np.concatenate([_at_length(p, s)[None], p[j:]], axis=0)


def _resample(p: Arr) -> Arr:
    """``p`` with points about :data:`_SPACING` apart (at least 2, at most :data:`_MAX_POINTS`)."""
    arc = arc_length(p)
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
class Tree:
    uv: tuple[Arr, ...]
    order: tuple[int, ...]
    parent: tuple[int, ...]
    width: tuple[float, ...]
    slots: dict[int, tuple[int, ...]]     # side -> indices of the veins edits address
    table: Arr


class _Builder:
    def __init__(self, shape: Shape, ven: Venation) -> None:
        self.ven = ven
        self.space = Space(shape)
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
        ahead = _at_length(path, np.minimum(at + 1e-3, arc_length(path)[-1]))
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
        d = d / max(float(np.linalg.norm(d)), EPS)
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
                la, lb = arc_length(a)[-1], arc_length(b)[-1]
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

    def build(self) -> Tree:
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
        return Tree(tuple(uv), tuple(v.order for v in self.veins), tuple(v.parent for v in self.veins), widths,
                     {s: tuple(ix) for s, ix in self.slots.items()}, self.space.table)


@functools.lru_cache(maxsize=64)
def build_tree(shape: Shape, venation: Venation) -> Tree:
    return _Builder(shape, venation).build()
