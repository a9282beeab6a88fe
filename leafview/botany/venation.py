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

import math
from dataclasses import dataclass, replace
from typing import NamedTuple, NoReturn

import numpy as np
from numpy.typing import NDArray

from leafview.botany.vein_trace import (
    BASAL_ANGLE,
    EPS,
    SECONDARY_V_RANGE,
    Space,
    arc_length,
    basal_lift,
    build_tree,
)
from leafview.core.params import LeafParams
from leafview.core.venation import Venation
from leafview.deform.surface import evaluate
from leafview.errors import ParamError

__all__ = ["Vein", "VeinSegments", "vein_tree", "vein_segments", "check_veins", "edited_uv", "edit_slots", "basal_lift",
           "BASAL_ANGLE", "SECONDARY_V_RANGE"]

Arr = NDArray[np.float64]



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


# -- public API ----------------------------------------------------------------------------------
def vein_tree(params: LeafParams) -> list[Vein]:
    """The veins of ``params`` (no edits applied): the midrib first (index 0, parent -1), then
    the primaries and secondaries, then the tertiaries; see the module docstring. Built whether
    or not ``params.venation.enabled`` (which only says whether renderers show them)."""
    tree = build_tree(params.shape, _unedited(params.venation))
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
    tree = build_tree(params.shape, _unedited(params.venation))
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
    return dict(build_tree(params.shape, _unedited(params.venation)).slots)


def _rotate_scale(space: Space, q: Arr, side: int, angle: float, to_margin: bool) -> Arr:
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
    tree = build_tree(params.shape, _unedited(ven))
    space = Space.__new__(Space)
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
            arc = arc_length(q)
            t = arc / max(arc[-1], EPS)
            chord = q[-1] - q[0]
            normal = np.array([-chord[1], chord[0]]) / max(float(np.linalg.norm(chord)), EPS)
            q = q + e.bulge * (4.0 * t * (1.0 - t))[:, None] * normal
            cause = "bulge"
        bad = _out(space, q)
        if bad.any():
            _fail(where, cause, space, q)
        qs = q * [e.side, 1.0]
        w = space.w(qs[:, 1])
        u = np.where(w > EPS, qs[:, 0] / np.maximum(w, EPS), 0.0)
        out[idx] = (np.stack([np.clip(u, -1.0, 1.0), qs[:, 1]], axis=1), None)
    return out


def _out(space: Space, q: Arr) -> NDArray[np.bool_]:
    """Which points of the side-frame polyline ``q`` lie outside the blade or across the midrib
    (the hinge itself, on its parent, never counts)."""
    bad = (space.outside(q) > 1e-9) | (q[:, 0] < -1e-9)
    bad[0] = False
    return bad


def _fail(where: str, cause: str, space: Space, q: Arr) -> NoReturn:
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
    tree = build_tree(params.shape, _unedited(params.venation))
    for i, uv in enumerate(tree.uv):
        if not (np.isfinite(uv).all() and (np.abs(uv[:, 0]) <= 1.0).all()
                and (uv[:, 1] >= 0.0).all() and (uv[:, 1] <= 1.0).all()):
            field = "venation.curvature" if tree.order[i] <= 2 else "venation.tertiary"
            raise ParamError(field, f"vein {i} (order {tree.order[i]}) leaves the blade")
    _edit(params)
