"""Vein edits on the flat blade (Hong 2005, ch. 7.1): where every vein goes.

The edits are ``LeafParams.venation.edits`` (:class:`leafview.core.venation.VeinEdit`). Where an
edited vein goes is :func:`leafview.botany.venation.edited_uv`: turned about its hinge
(the point where it leaves its parent) by ``angle`` in vein space, i.e. in the leaf plane, and
bowed by spline control, ``bulge · 4 t (1 - t)`` along its chord's normal (the offset of the
quadratic Bézier curve whose middle control point is lifted by ``2 · bulge``: zero at both ends).
Here the edited (u, v) are mapped onto the flat blade (no jitter, ripple or bending; leaf space),
so the vein's material points (its original (u, v)) move by ``new - old``.

Children move with their parent: a child vein of order ≤ 2 (the secondaries of a palmate primary)
rides rigidly on its parent's local frame at its junction (the parent's displacement there and the
turn of its tangent in the leaf plane); a vein of order ≤ 2 whose end joins another vein (the arch
of a looping secondary, a palmate secondary ending on a primary) stays joined when either moves:
its end goes to the joined vein's new point, the rest of it following by a smoothstep of its arc
length. Tertiaries are not constrained: they are material lines of the blade and follow it
(:func:`leafview.botany.vein_shape.veins` evaluates every vein on the final surface).

:mod:`leafview.botany.vein_shape` turns these moves into the blade's displacement.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from leafview.botany.venation import Vein, edited_uv
from leafview.core.blade import blade_partials
from leafview.core.params import Jitter, LeafParams
from leafview.core.venation import VeinEdit

__all__ = ["flat_blade", "edited_points"]

_JOIN_TOL = 1e-3     # (u, v) distance within which a vein's end lies on another vein

Arr = NDArray[np.float64]


def flat_blade(params: LeafParams) -> LeafParams:
    """The leaf whose blade the veins are edited on: without jitter (and, in
    :func:`leafview.core.blade.blade_partials`, without ripple or bending); the vein grid depends on
    the shape and the venation only."""
    return params.replace(jitter=Jitter())


def _flat_points(params: LeafParams, uv: Arr) -> Arr:
    """Leaf-space points of the flat blade at ``uv`` (N, 2)."""
    return blade_partials(flat_blade(params), uv[:, 0], uv[:, 1])[0].L


def _rot(angle: float) -> Arr:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _junction(parent: Arr, point: Arr) -> tuple[int, float]:
    """Segment k and fraction f of the point of polyline ``parent`` nearest ``point`` (xy)."""
    a, b = parent[:-1, :2], parent[1:, :2]
    d = b - a
    dd = np.maximum(np.sum(d * d, axis=1), 1e-300)
    f = np.clip(np.sum((point[:2] - a) * d, axis=1) / dd, 0.0, 1.0)
    dist = np.linalg.norm(a + f[:, None] * d - point[:2], axis=1)
    k = int(np.argmin(dist))
    return k, float(f[k])


def _carry(old_parent: Arr, new_parent: Arr, points: Arr) -> Arr:
    """``points`` of a child carried by its parent's motion at the junction: the parent's
    displacement there and the turn of its tangent (in the leaf plane)."""
    k, f = _junction(old_parent, points[0])
    o = old_parent[k] + f * (old_parent[k + 1] - old_parent[k])
    n = new_parent[k] + f * (new_parent[k + 1] - new_parent[k])
    to, tn = old_parent[k + 1] - old_parent[k], new_parent[k + 1] - new_parent[k]
    turn = np.arctan2(tn[1], tn[0]) - np.arctan2(to[1], to[0])
    return n + (points - o) @ _rot(turn).T


def edited_points(params: LeafParams, tree: Sequence[Vein],
                  edits: Sequence[VeinEdit] | None = None) -> tuple[list[Arr], list[Arr], NDArray[np.bool_]]:
    """Flat-blade points (leaf space) of every vein of ``tree`` before and after the ``edits``
    (default: the leaf's), and which veins moved: the edited veins
    (:func:`leafview.botany.venation.edited_uv`, which refuses edits of veins that do not exist or
    that leave the blade) and the children of order ≤ 2 they carry."""
    if edits is not None:
        params = params.replace(venation=replace(params.venation, edits=tuple(edits)))
    old = _split(_flat_points(params, np.concatenate([vein.uv for vein in tree])), [len(vein.uv) for vein in tree])
    new = [p.copy() for p in old]
    moved = np.zeros(len(tree), bool)
    if not params.venation.edits:
        return old, new, moved
    uv_after = [np.asarray(uv, np.float64) for uv in edited_uv(params)]
    edited = [k for k, vein in enumerate(tree) if not np.array_equal(uv_after[k], vein.uv)]
    edited_set = set(edited)
    if edited:
        uv = np.concatenate([uv_after[k] for k in edited])
        uv = np.stack([np.clip(uv[:, 0], -1.0, 1.0), np.clip(uv[:, 1], 0.0, 1.0)], -1)
        for k, pts in zip(edited, _split(_flat_points(params, uv), [len(uv_after[k]) for k in edited])):
            new[k] = pts
    for k in _topological(tree):
        vein = tree[k]
        pts = new[k]
        carried = vein.parent >= 0 and bool(moved[vein.parent]) and vein.order <= 2
        if carried:
            pts = _carry(old[vein.parent], new[vein.parent], pts)
        new[k] = pts
        moved[k] = carried or k in edited_set
    joins = _joins(tree)
    done: set[int] = set()

    def follow(k: int) -> None:   # a vein whose end joins a moved vein (or that moved) stays joined
        if k in done:
            return
        done.add(k)
        j = joins[k]
        if j in joins:
            follow(j)
        if moved[j] or moved[k]:
            seg, f = _junction(old[j], old[k][-1])
            target = (1.0 - f) * new[j][seg] + f * new[j][seg + 1]
            arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(new[k], axis=0), axis=1))])
            t = arc / max(arc[-1], 1e-300)
            new[k] = new[k] + (t * t * (3.0 - 2.0 * t))[:, None] * (target - new[k][-1])
            moved[k] = True

    for k in joins:
        follow(k)
    return old, new, moved


def _joins(tree: Sequence[Vein]) -> dict[int, int]:
    """Veins of order ≤ 2 whose last point lies on another one (not their parent), as {vein: the
    vein it joins}: a looping secondary's arch joins the next one up, a palmate leaf's secondary
    joins the next primary out."""
    major = [k for k, vein in enumerate(tree) if vein.order <= 2]
    a = np.concatenate([tree[k].uv[:-1] for k in major])
    d = np.concatenate([tree[k].uv[1:] for k in major]) - a
    owner = np.repeat(major, [len(tree[k].uv) - 1 for k in major])
    dd = np.maximum(np.sum(d * d, axis=1), 1e-300)
    out: dict[int, int] = {}
    for k in major:
        end = tree[k].uv[-1]
        f = np.clip(np.sum((end - a) * d, axis=1) / dd, 0.0, 1.0)
        dist = np.linalg.norm(a + f[:, None] * d - end, axis=1)
        dist[(owner == k) | (owner == tree[k].parent)] = np.inf
        best = int(np.argmin(dist))
        if dist[best] <= _JOIN_TOL:
            out[k] = int(owner[best])
    return out


def _split(points: Arr, sizes: Sequence[int]) -> list[Arr]:
    return np.split(points, np.cumsum(sizes)[:-1])


def _topological(tree: Sequence[Vein]) -> list[int]:
    depth = [0] * len(tree)
    for k in range(len(tree)):
        p, d = tree[k].parent, 0
        while p >= 0 and d <= len(tree):
            p, d = tree[p].parent, d + 1
        depth[k] = d
    return sorted(range(len(tree)), key=lambda k: (depth[k], k))
