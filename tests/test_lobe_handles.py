"""The viewport handles of a lobed leaf without GL (leafview.app.lobe_handles): which handles there
are, and that dragging them keeps the margin valid, moves what it should and nothing else, and is
refused (leaf unchanged, the reason named) when the margin would cross itself."""

from __future__ import annotations

import numpy as np
import pytest

from leafview.app.lobe_handles import (
    GUARD,
    drag_lobe_handle,
    falloff,
    gap_anchors,
    handle_flat,
    lobe_handles,
    skeleton_lines,
)
from leafview.app.state import ViewerState
from leafview.botany.lobe_skeleton import skeleton
from leafview.core.bspline import evaluate_closed
from leafview.core.lobes import Lobes, parse_outline, parse_valleys
from leafview.core.params import LeafParams, ParamError


@pytest.fixture(scope="module")
def maple(presets) -> LeafParams:
    return presets["maple"]


def _valid(params: LeafParams) -> None:
    lobes = params.lobes
    assert parse_outline(lobes.outline) == lobes.outline
    assert parse_valleys(lobes.valleys, lobes.outline) == lobes.valleys


def _margin_distance(params: LeafParams, point) -> float:
    """Distance from ``point`` to the margin (dense samples, then refined around the nearest)."""
    ctrl, p, n = np.asarray(params.lobes.outline), np.asarray(point, dtype=np.float64), 20000
    t0 = np.argmin(np.linalg.norm(evaluate_closed(ctrl, np.arange(n) / n) - p, axis=1)) / n
    fine = evaluate_closed(ctrl, t0 + np.linspace(-1.0, 1.0, 4001) / n)
    return float(np.min(np.linalg.norm(fine - p, axis=1)))


def test_handles_are_the_tips_and_valleys(maple):
    h = lobe_handles(maple.lobes)
    sk = skeleton(maple.lobes)
    tips = [n for n in h.names if n.startswith("tip:")]
    valleys = [n for n in h.names if n.startswith("valley:")]
    assert len(tips) == len(sk.terminals) == 5
    assert len(valleys) == len(maple.lobes.valleys)
    junctions = [n for n in h.fixed if n.startswith("junction:")]
    assert len(junctions) == sum(1 for k in range(len(sk.nodes)) if sk.degree(k) > 1 and k != sk.root)
    for name, p in zip(h.names, h.points):   # every draggable handle sits on the margin
        assert _margin_distance(maple, p) < 0.011, name
    lines = skeleton_lines(maple)
    assert len(lines) == len(sk.edges) and all(line.shape[1] == 3 for line in lines)


def test_no_valleys_gives_junction_anchor_handles(maple):
    bare = LeafParams.from_dict({**maple.to_dict(), "lobes": {**maple.to_dict()["lobes"], "valleys": []}})
    h = lobe_handles(bare.lobes)
    anchors = [n for n in h.names if n.startswith("anchor:")]
    assert len(anchors) == len(gap_anchors(skeleton(bare.lobes))) == len(maple.lobes.valleys)
    # where the valleys would be: each anchor near one of the preset's valley points
    points = np.array([h.points[h.names.index(n)] for n in anchors])
    assert np.max(np.min(np.linalg.norm(points[:, None] - np.array(maple.lobes.valleys)[None], axis=2), axis=1)) < 0.1
    name = anchors[1]
    target = handle_flat(bare.lobes, name) + np.array([0.02, -0.03])
    moved = drag_lobe_handle(bare, name, target)
    _valid(moved)
    assert moved.lobes.valleys == () and _margin_distance(moved, target) < 1e-6


def test_falloff_is_zero_near_fixed_points_and_one_at_the_centre():
    w = falloff(64, 20.0, 10.3, 31.7)
    assert w[20] == 1.0
    assert np.all(w[:13] == 0.0) and np.all(w[30:] == 0.0)   # within GUARD spans of 10.3 and 31.7
    assert np.all(np.diff(w[12:21]) >= 0) and np.all(np.diff(w[20:31]) <= 0)
    wrapped = falloff(64, 2.0, -10.0, 12.0)                  # across the closing point
    assert wrapped[2] == 1.0 and wrapped[60] > 0.0 and wrapped[63] > wrapped[60]


@pytest.mark.parametrize("tip", [1, 2, 3])
def test_tip_drag_moves_the_tip_by_the_drag_and_leaves_far_points(maple, tip):
    name = f"tip:{tip}"
    start = handle_flat(maple.lobes, name)
    delta = np.array([0.06, 0.04])
    moved = drag_lobe_handle(maple, name, start + delta)
    _valid(moved)
    old, new = np.asarray(maple.lobes.outline), np.asarray(moved.lobes.outline)
    # the margin point under the handle moved by exactly the drag (same curve parameter)
    h = lobe_handles(maple.lobes)
    t = np.interp(h.w[h.names.index(name)], skeleton(maple.lobes).margin.w, skeleton(maple.lobes).margin.t)
    assert np.allclose(evaluate_closed(new, t) - evaluate_closed(old, t), delta, atol=1e-12)
    # the recomputed tip anchor follows (it is where the skeleton's tangent meets the margin)
    assert np.linalg.norm(lobe_handles(moved.lobes).points[tip] - (start + delta)) < 0.02
    # valleys stay, and stay on the margin; far control points are untouched
    assert moved.lobes.valleys == maple.lobes.valleys
    changed = np.nonzero(np.any(new != old, axis=1))[0]
    assert 0 < len(changed) < len(old) // 3
    far = np.abs(((np.arange(len(old)) - len(old) * t) + len(old) / 2) % len(old) - len(old) / 2) > len(old) / 4
    assert np.array_equal(new[far], old[far])


def test_tip_drag_keeps_the_base_and_every_valley_exactly(maple):
    moved = drag_lobe_handle(maple, "tip:2", handle_flat(maple.lobes, "tip:2") + [0.1, 0.1])
    base_old = evaluate_closed(np.asarray(maple.lobes.outline), 0.0)
    assert np.array_equal(evaluate_closed(np.asarray(moved.lobes.outline), 0.0), base_old)
    sk = skeleton(maple.lobes)
    for v in maple.lobes.valleys:
        t = np.interp(sk.margin.nearest(v), sk.margin.w, sk.margin.t)
        assert np.allclose(evaluate_closed(np.asarray(moved.lobes.outline), t),
                           evaluate_closed(np.asarray(maple.lobes.outline), t), atol=1e-14)


@pytest.mark.parametrize("valley", [0, 1, 2, 3])
def test_valley_drag_keeps_the_margin_through_the_valley(maple, valley):
    name = f"valley:{valley}"
    target = handle_flat(maple.lobes, name) + np.array([0.03, -0.05])
    moved = drag_lobe_handle(maple, name, target)
    _valid(moved)
    assert np.allclose(moved.lobes.valleys[valley], target)
    assert _margin_distance(moved, target) < 1e-6
    others = [i for i in range(len(maple.lobes.valleys)) if i != valley]
    assert all(moved.lobes.valleys[i] == maple.lobes.valleys[i] for i in others)
    assert lobe_handles(moved.lobes).names.count(name) == 1


def test_a_crossing_drag_is_refused_and_leaves_the_leaf(maple):
    state = ViewerState(maple)
    name = "tip:4"
    before, revision = state.params, state.revision
    target = handle_flat(maple.lobes, name) + np.array([-0.6, 0.2])   # across the neighbouring lobe
    with pytest.raises(ParamError, match="crosses itself"):
        drag_lobe_handle(maple, name, target)
    assert not state.apply(lambda p: drag_lobe_handle(p, name, target), gesture=f"lobe:{name}")
    assert state.params is before and state.revision == revision and not state.can_undo
    assert "tip:4 refused" in (state.error or "") and "crosses itself" in state.error


def test_display_only_unknown_and_non_finite_handles_are_refused(maple, presets):
    h = lobe_handles(maple.lobes)
    with pytest.raises(ParamError, match="display-only"):
        drag_lobe_handle(maple, h.fixed[1], h.fixed_points[1] + 0.01)
    with pytest.raises(ParamError, match="unknown"):
        drag_lobe_handle(maple, "tip:99", [0.0, 0.5])
    with pytest.raises(ParamError, match="finite"):
        drag_lobe_handle(maple, "tip:0", [np.nan, 0.5])
    with pytest.raises(ParamError, match="not a lobed leaf"):
        drag_lobe_handle(presets["ovate"], "tip:0", [0.0, 0.5])


def test_a_drag_is_one_undo_step(maple):
    state = ViewerState(maple)
    start = handle_flat(maple.lobes, "tip:2")
    for k in range(1, 5):   # a drag: every move from the leaf at the start of the drag
        target = start + np.array([0.0, 0.02 * k])
        assert state.apply(lambda p, t=target: drag_lobe_handle(maple, "tip:2", t), gesture="lobe:tip:2")
    state.end_gesture()
    assert state.params.lobes.outline != maple.lobes.outline
    assert state.undo() and state.params == maple and not state.can_undo
    assert isinstance(state.params.lobes, Lobes)


@pytest.mark.parametrize("name", ["oak", "bilobed"])
def test_every_handle_of_the_other_presets_drags_validly(presets, name):
    params = presets[name]
    h = lobe_handles(params.lobes)
    for handle in h.names:
        moved = drag_lobe_handle(params, handle, handle_flat(params.lobes, handle) + np.array([0.01, 0.015]))
        _valid(moved)
        assert moved != params
    assert GUARD >= 2.0   # a cubic B-spline point depends on the controls within 2 spans
