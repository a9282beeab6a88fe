"""Viewport handles of a lobed leaf (``LeafParams.lobes``): its lobe tips, its valleys and its
skeleton, and what dragging them does to the margin's control points.

The margin is a closed uniform cubic B-spline (:mod:`leafview.core.bspline`): control point j
peaks at t = j / m and moves the curve only over t in ((j - 2) / m, (j + 2) / m). Handles:

* ``tip:i``, the i-th lobe tip clockwise from the base (``Skeleton.terminals``), shown at its tip
  anchor on the margin (where the skeleton's tangent at the tip meets it, Mündermann et al. 2003,
  sec. 3.3). Dragging it moves the control points between the two neighbouring valleys (or the
  base) with a smoothstep falloff that is 1 at the tip and 0 within two spans of each valley, so
  the curve at a valley and at the base does not move at all; the weights are divided by the
  curve's own response at the tip, so the margin point under the handle moves by exactly the
  drag. The valleys stay.
* ``valley:i``, the point ``lobes.valleys[i]``: dragging it sets the valley to the new point and
  moves the control points between the neighbouring tips, valleys and base the same way, so that
  the margin passes exactly through the new valley (it stays on the margin).
* ``anchor:i``, only when there are no valley points: the sweep's junction anchors (where a
  junction's ties reach the margin, ``leafview.botany.lobe_sweep.anchors``), one per gap
  between consecutive tips (:func:`gap_anchors`). Dragging one moves
  the margin like a valley; the sweep then recomputes its anchor (the margin point nearest the
  junction), so the handle may settle slightly off the cursor.
* junctions and the root are display-only (:attr:`LobeHandles.fixed`): a junction lies on the
  medial axis, which follows from the margin; no single edit of the margin moves it predictably.

Every drag is checked like a file (:func:`leafview.core.params.parse_params`: a simple closed
margin, valleys on it) and the skeleton and sweep must build; otherwise :func:`drag_lobe_handle`
raises :class:`ParamError` saying why and the caller keeps the leaf as it was. numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.botany.lobe_skeleton import Skeleton, skeleton
from leafview.botany.lobe_sweep import anchors, sweep_table, tour
from leafview.core.bspline import evaluate_closed
from leafview.core.lobes import Lobes
from leafview.core.params import LeafParams, ParamError, parse_params
from leafview.deform.sweep import SweepTable

__all__ = ["LobeHandles", "lobe_handles", "gap_anchors", "junction_anchors", "handle_flat", "drag_lobe_handle", "falloff", "lift_margin", "lift_flat",
           "skeleton_lines", "margin_offsets", "GUARD", "MIN_RESPONSE"]

GUARD = 2.0          # control spans around a fixed margin point that a drag leaves untouched
MIN_RESPONSE = 0.25  # refuse a drag whose weighted controls move the handle's point less than this


@dataclass(frozen=True)
class LobeHandles:
    """The handles of one lobed leaf, in the flat leaf plane (x, y in leaf lengths).

    ``names``/``points`` (N, 2)/``w`` (N,): the draggable handles, their flat positions and
    their margin arc-length fractions; ``fixed``/``fixed_points`` (K, 2): display-only points
    (``root``, ``junction:k``)."""

    names: tuple[str, ...]
    points: NDArray[np.float64]
    w: NDArray[np.float64]
    fixed: tuple[str, ...]
    fixed_points: NDArray[np.float64]


def _t_of_w(sk: Skeleton, w: ArrayLike) -> NDArray[np.float64]:
    """B-spline parameters of margin arc-length fractions."""
    return np.interp(np.asarray(w, dtype=np.float64), sk.margin.w, sk.margin.t)


def junction_anchors(sk: Skeleton, valleys: tuple[tuple[float, float], ...] = ()) -> NDArray[np.float64]:
    """Margin fractions of the sweep's anchors at junction visits (sorted, unique)."""
    trips = tour(sk)
    w = anchors(sk, trips, valleys)
    out = []
    for k, (e, d) in enumerate(trips):
        node = sk.edges[e].start if d > 0 else sk.edges[e].end
        if k > 0 and node != sk.root and not np.isfinite(sk.tip_w[node]):
            out.append(float(w[k]))
    return np.unique(np.round(np.array(out, dtype=np.float64), 12))


def gap_anchors(sk: Skeleton) -> NDArray[np.float64]:
    """One junction anchor per gap between consecutive lobe tips (the one nearest the gap's
    middle): where the valleys would be. The gaps next to the base have none (the base is
    fixed), and several junction visits can share a gap (their anchors a few samples apart)."""
    tips = np.sort(sk.tip_w[list(sk.terminals)])
    ws = junction_anchors(sk)
    out = []
    for a, b in zip(tips[:-1], tips[1:]):
        inside = ws[(ws > a) & (ws < b)]
        if len(inside):
            out.append(float(inside[np.argmin(np.abs(inside - 0.5 * (a + b)))]))
    return np.array(out, dtype=np.float64)


def lobe_handles(lobes: Lobes) -> LobeHandles:
    """Tips, valleys (or junction anchors) and the display-only junctions of ``lobes``."""
    sk = skeleton(lobes)
    names: list[str] = []
    ws: list[float] = []
    for i, k in enumerate(sk.terminals):
        names.append(f"tip:{i}")
        ws.append(float(sk.tip_w[k]))
    points = [sk.margin.at(w) for w in ws]
    if lobes.valleys:
        for i, v in enumerate(lobes.valleys):
            names.append(f"valley:{i}")
            ws.append(sk.margin.nearest(v))
            points.append(np.asarray(v, dtype=np.float64))
    else:
        for i, w in enumerate(gap_anchors(sk)):
            names.append(f"anchor:{i}")
            ws.append(float(w))
            points.append(sk.margin.at(w))
    fixed = ["root"] + [f"junction:{k}" for k in range(len(sk.nodes))
                        if k != sk.root and not np.isfinite(sk.tip_w[k])]
    fixed_pts = np.array([sk.nodes[sk.root] if n == "root" else sk.nodes[int(n.split(":")[1])] for n in fixed])
    return LobeHandles(tuple(names), np.array(points, dtype=np.float64).reshape(-1, 2),
                       np.array(ws, dtype=np.float64), tuple(fixed), fixed_pts.reshape(-1, 2))


def handle_flat(lobes: Lobes, name: str) -> NDArray[np.float64]:
    """The flat margin point (2,) that dragging handle ``name`` moves (where the tip anchor or
    valley meets the margin); a drag's target is this point plus the cursor's displacement."""
    h = lobe_handles(lobes)
    if name not in h.names:
        raise ParamError(name, "unknown lobe handle")
    sk = skeleton(lobes)
    return np.asarray(evaluate_closed(np.asarray(lobes.outline, dtype=np.float64),
                                      float(_t_of_w(sk, h.w[h.names.index(name)]))), dtype=np.float64)


def falloff(m: int, center: float, lo: float, hi: float, guard: float = GUARD) -> NDArray[np.float64]:
    """Weights (m,) of the control points for a drag at index position ``center`` (m · t) between
    the fixed positions ``lo`` < ``center`` < ``hi`` (unwrapped, ``hi - lo <= m``): 1 at the
    centre, smoothstep down to 0 at ``guard`` spans from each fixed position, 0 beyond. Control
    points within ``guard`` (< 2 would leave the curve at a fixed point moving) get 0."""
    j = np.arange(int(np.floor(lo)) - 1, int(np.ceil(hi)) + 2, dtype=np.float64)
    a, b = lo + guard, hi - guard
    x = np.zeros_like(j)
    left = j < center
    with np.errstate(divide="ignore", invalid="ignore"):
        x[left] = (j[left] - a) / (center - a) if center > a else 0.0
        x[~left] = (b - j[~left]) / (b - center) if b > center else 0.0
    x = np.clip(np.nan_to_num(x), 0.0, 1.0)
    weight = x * x * (3.0 - 2.0 * x)
    out = np.zeros(m)
    inside = (j > lo) & (j < hi)
    np.add.at(out, j[inside].astype(np.int64) % m, weight[inside])
    return np.minimum(out, 1.0)


def _between(x: float, fixed: NDArray[np.float64], m: int) -> tuple[float, float]:
    """The fixed index positions just below and above ``x`` (cyclic, unwrapped around x)."""
    f = np.sort(np.mod(fixed, m))
    below = f[f < x - 1e-9]
    above = f[f > x + 1e-9]
    lo = float(below[-1]) if len(below) else float(f[-1]) - m
    hi = float(above[0]) if len(above) else float(f[0]) + m
    return lo, hi


def _moved(ctrl: NDArray[np.float64], t: float, weights: NDArray[np.float64], delta: NDArray[np.float64],
           name: str) -> NDArray[np.float64]:
    """``ctrl`` with ``weights`` · ``delta`` scaled so the curve at ``t`` moves by ``delta`` exactly."""
    response = float(evaluate_closed(weights[:, None], t)[0])
    if response < MIN_RESPONSE:
        raise ParamError("lobes.outline", f"{name}: too few control points between its neighbours to drag "
                                          f"(response {response:.2f})")
    return ctrl + weights[:, None] * (delta / response)[None, :]


def _rebuilt(params: LeafParams, outline: NDArray[np.float64], valleys: tuple[tuple[float, float], ...],
             name: str) -> LeafParams:
    """``params`` with a new margin and valleys, validated like a file; its sweep must build."""
    data = params.to_dict()
    lobes = dict(data["lobes"])
    lobes["outline"] = [[float(x), float(y)] for x, y in outline]
    lobes["valleys"] = [[float(x), float(y)] for x, y in valleys]
    data["lobes"] = lobes
    try:
        new = parse_params(data)
        sweep_table(new.lobes)
    except ParamError as exc:
        raise ParamError(exc.path, f"{name} refused: {exc.message}") from None
    except (ValueError, IndexError) as exc:   # a degenerate skeleton (scipy, empty arrays)
        raise ParamError("lobes.outline", f"{name} refused: no skeleton for this margin ({exc})") from None
    return new


def drag_lobe_handle(params: LeafParams, name: str, target: ArrayLike) -> LeafParams:
    """New parameters with handle ``name`` of the lobed leaf ``params`` (the leaf as it was when
    the drag started) moved to the flat leaf-plane point ``target`` (x, y; a z is ignored).
    Raises :class:`ParamError` when the handle is display-only or unknown, or the result would be
    invalid (the margin crossing itself, a valley off the margin, no skeleton)."""
    lobes = params.lobes
    if not lobes.enabled:
        raise ParamError("lobes.outline", "not a lobed leaf: it has no lobe handles")
    p = np.asarray(target, dtype=np.float64).reshape(-1)[:2]
    if len(p) != 2 or not np.all(np.isfinite(p)):
        raise ParamError(name, "the handle left the view (no finite position)")
    handles = lobe_handles(lobes)
    if name not in handles.names:
        why = "display-only (it follows from the margin)" if name in handles.fixed else "unknown handle"
        raise ParamError(name, why)
    sk = skeleton(lobes)
    ctrl = np.asarray(lobes.outline, dtype=np.float64)
    m = len(ctrl)
    i = handles.names.index(name)
    kind = name.split(":")[0]
    t = float(_t_of_w(sk, handles.w[i]))
    x = m * t
    tips = m * _t_of_w(sk, handles.w[[n.startswith("tip:") for n in handles.names]])
    bounds = m * _t_of_w(sk, handles.w[[not n.startswith("tip:") for n in handles.names]])
    every = np.concatenate([tips, bounds])
    fixed = np.concatenate([every[np.abs(every - x) > 1e-9], [0.0]])
    lo, hi = _between(x, fixed, m)
    weights = falloff(m, x, lo, hi)
    start = evaluate_closed(ctrl, t)
    delta = p - start
    new_ctrl = _moved(ctrl, t, weights, delta, name)
    valleys = lobes.valleys
    if kind == "valley":
        k = int(name.split(":")[1])
        valleys = tuple((float(p[0]), float(p[1])) if j == k else v for j, v in enumerate(valleys))
    return _rebuilt(params, new_ctrl, valleys, name)


def _table(params: LeafParams) -> SweepTable:
    return sweep_table(params.lobes)


def lift_margin(params: LeafParams, w: ArrayLike) -> NDArray[np.float64]:
    """Leaf-space points (n, 3) of the drawn surface's rim at margin fractions ``w`` (the ties'
    rims, turtle edits and cupping included; ripples left out)."""
    table = _table(params)
    w = np.mod(np.atleast_1d(np.asarray(w, dtype=np.float64)), 1.0)
    rim = table.rim + (table.cup * table.length)[:, None] * table.up
    return np.stack([np.interp(w, table.margin, rim[:, k], period=1.0) for k in range(3)], axis=-1)


def lift_flat(params: LeafParams, points: ArrayLike) -> NDArray[np.float64]:
    """Leaf-space points (n, 3) for flat skeleton points (n, 2): moved like the nearest tie foot
    (turtle edits), z = 0 on an unedited leaf."""
    table = _table(params)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    feet = table.flat[:, :2]
    d2 = np.sum((p[:, None, :] - feet[None, :, :]) ** 2, axis=2)
    near = np.argmin(d2, axis=1)
    out = np.zeros((len(p), 3))
    out[:, :2] = p
    offset = table.origin[near].copy()
    offset[:, :2] -= feet[near]
    return out + offset


def margin_offsets(params: LeafParams) -> NDArray[np.float64]:
    """(m, 3): how far the drawn rim lies from the flat margin at each control point's own curve
    point t = j / m (zero on an unedited, uncupped leaf); added to the control polygon."""
    ctrl = np.asarray(params.lobes.outline, dtype=np.float64)
    sk = skeleton(params.lobes)
    t = np.arange(len(ctrl)) / len(ctrl)
    w = np.interp(t, sk.margin.t, sk.margin.w)
    flat = np.zeros((len(ctrl), 3))
    flat[:, :2] = evaluate_closed(ctrl, t)
    return lift_margin(params, w) - flat


def skeleton_lines(params: LeafParams) -> list[NDArray[np.float64]]:
    """Leaf-space polylines (m, 3) of the skeleton's edges, each tip extended to its anchor."""
    sk = skeleton(params.lobes)
    lines = []
    for edge in sk.edges:
        pts = np.asarray(edge.points, dtype=np.float64)
        line = lift_flat(params, pts)
        if np.isfinite(sk.tip_w[edge.end]):
            line = np.vstack([line, lift_margin(params, [sk.tip_w[edge.end]])])
        lines.append(line)
    return lines
