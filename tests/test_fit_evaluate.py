"""A capture scored against its truth (leafview.fit.evaluate): identity scores perfectly, known
perturbations give the errors they should, missing and spurious leaves move recall and precision
exactly, visibility sees occlusion, IoU matching is one-to-one across views.

Instance images come from the numpy splat rasteriser of tests/support/rasterize.py, cameras from
leafview.scene.camera (look_at + intrinsics): no GL.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import ndimage
from scipy.spatial.transform import Rotation
from support.rasterize import splat

from leafview.core.params import LeafParams, Shape, Transform
from leafview.deform.surface import evaluate
from leafview.errors import ParamError
from leafview.fit.evaluate import (
    VISIBILITY_BINS,
    Match,
    chamfer,
    evaluate_capture,
    leaf_measures,
    match_leaves,
    visibility,
)
from leafview.resources import builtin_presets
from leafview.scene.camera import intrinsics, look_at

SIZE = (200, 150)
EYES = ((0.3, -2.5, 3.0), (-2.0, 1.5, 2.5))


def _preset(name: str, transform: Transform) -> LeafParams:
    return LeafParams.load(builtin_presets()[name]).replace(transform=transform)


def _scene() -> list[LeafParams]:
    """Four leaves of different shapes side by side in the ground plane, each fully in view."""
    names = ("ovate", "lanceolate", "curled", "holly")
    return [_preset(n, Transform(translation=(-0.6 + 1.2 * (i % 2), -1.1 + 1.2 * (i // 2), 0.02 * i),
                                 rotation=(0.0, 0.0, 10.0 * i), scale=1.0)) for i, n in enumerate(names)]


def _cameras(eyes: tuple[tuple[float, float, float], ...] = EYES, target: tuple[float, float, float] = (0, 0, 0),
             size: tuple[int, int] = SIZE) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    return [intrinsics(look_at(eye, target, size[0] / size[1], 0.1, 20.0), size) for eye in eyes]


def _views(truth: list[LeafParams], cameras: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
           size: tuple[int, int] = SIZE) -> list[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.uint32]]]:
    return [(k, m, splat(truth, k, m, size)[0]) for k, m in cameras]


def _predicted(captured: list[LeafParams], cameras: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
               size: tuple[int, int] = SIZE) -> list[NDArray[np.uint32]]:
    return [splat(captured, k, m, size)[0] for k, m in cameras]


def _pair(truth: LeafParams, captured: LeafParams) -> Match:
    """The Match of one truth and one captured leaf whose masks coincide (a 4×4 image of ones):
    its errors come from the geometry alone."""
    ones = np.ones((4, 4), dtype=np.uint32)
    result = evaluate_capture([truth], [captured], [(np.eye(3), np.eye(4), ones)], [ones])
    assert len(result.matches) == 1
    return result.matches[0]


def _moved(leaf: LeafParams, world: NDArray[np.float64]) -> LeafParams:
    """``leaf`` after the world-space motion ``world`` (4×4)."""
    return leaf.replace(transform=Transform.from_matrix(world @ leaf.transform.matrix()))


def _about(axis: NDArray[np.float64], degrees: float, point: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation by ``degrees`` about the line through ``point`` along ``axis``."""
    m = np.eye(4)
    m[:3, :3] = Rotation.from_rotvec(np.radians(degrees) * axis).as_matrix()
    m[:3, 3] = point - m[:3, :3] @ point
    return m


PLACED = Transform(translation=(0.3, 0.2, 0.1), rotation=(20.0, -10.0, 35.0), scale=2.0)


# -- identity and known perturbations ------------------------------------------------------------
def test_identity_scores_perfectly() -> None:
    truth = _scene()
    cameras = _cameras()
    views = _views(truth, cameras)
    # the captured leaves carry transforms recovered from matrices, as a fit would give them
    captured = [p.replace(transform=Transform.from_matrix(p.transform.matrix())) for p in truth]
    result = evaluate_capture(truth, captured, views, _predicted(captured, cameras))
    assert result.precision == 1.0 and result.recall == 1.0 and result.recall_visible_50 == 1.0
    assert [(m.truth, m.captured) for m in result.matches] == [(i, i) for i in range(4)]
    assert all(m.iou > 0.99 for m in result.matches)
    assert np.all(result.visibility > 0.95)
    for m in result.matches:
        assert m.chamfer < 0.2
        assert max(abs(m.length_error), abs(m.width_error), m.orientation_error, m.normal_error) < 1e-6
    assert result.by_bin[-1]["truth"] == 4 and result.by_bin[-1]["recall"] == 1.0
    assert result.median_chamfer < 0.2


@pytest.mark.parametrize("name", ["ovate", "lanceolate"])
def test_shift_along_the_normal_is_the_chamfer_distance(name: str) -> None:
    truth = _preset(name, PLACED)
    measures = leaf_measures(truth)
    shift = np.eye(4)
    shift[:3, 3] = 0.02 * measures.length * measures.normal
    match = _pair(truth, _moved(truth, shift))
    assert match.chamfer == pytest.approx(2.0, abs=0.05)
    assert chamfer(truth, _moved(truth, shift)) == pytest.approx(match.chamfer, rel=1e-9)
    assert abs(match.length_error) < 1e-6 and match.orientation_error < 1e-6 and match.normal_error < 1e-6


def test_scaling_by_1_1_is_a_10_percent_length_and_width_error() -> None:
    truth = _preset("ovate", PLACED)
    t = truth.transform
    captured = truth.replace(transform=Transform(t.translation, t.rotation, t.scale * 1.1))
    match = _pair(truth, captured)
    assert match.length_error == pytest.approx(10.0, abs=1e-6)
    assert match.width_error == pytest.approx(10.0, abs=1e-6)
    assert match.orientation_error < 1e-6
    assert match.chamfer > 0.3          # in-plane growth: only the rim is off the other surface
    shrunk = _pair(truth, truth.replace(transform=Transform(t.translation, t.rotation, t.scale * 0.8)))
    assert shrunk.length_error == pytest.approx(-20.0, abs=1e-6)    # signed: captured minus truth


def test_rotations_about_the_normal_and_the_midrib() -> None:
    truth = _preset("ovate", PLACED)
    measures = leaf_measures(truth)
    base = np.asarray(truth.transform.translation)
    turned = _pair(truth, _moved(truth, _about(measures.normal, 20.0, base)))
    assert turned.orientation_error == pytest.approx(20.0, abs=1e-6)
    assert turned.normal_error < 1e-6
    assert abs(turned.length_error) < 1e-6 and abs(turned.width_error) < 1e-6
    rolled = _pair(truth, _moved(truth, _about(measures.direction, 15.0, base)))
    assert rolled.orientation_error < 1e-6
    assert rolled.normal_error == pytest.approx(15.0, abs=0.1)
    flipped = _pair(truth, _moved(truth, _about(measures.direction, 180.0, base)))
    assert flipped.normal_error < 0.5      # upside down is the same plane


def test_width_is_the_margin_extent_across_the_midrib() -> None:
    shape = Shape()     # the paper's default: flat, symmetric about the midrib
    leaf = LeafParams(shape=shape, transform=Transform((1.0, -2.0, 0.5), (30.0, 40.0, -60.0), 2.5))
    v = np.linspace(0.0, 1.0, 4001)
    half_width = float(np.abs(evaluate(LeafParams(shape=shape), np.ones_like(v), v)[:, 0]).max())
    measures = leaf_measures(leaf)
    assert measures.width == pytest.approx(2.0 * half_width * 2.5, rel=1e-4)
    assert measures.length == pytest.approx(2.5, rel=1e-12)
    rot = leaf.transform.matrix()[:3, :3] / 2.5
    assert np.allclose(measures.direction, rot[:, 1]) and np.allclose(measures.normal, rot[:, 2])


# -- recall, precision and visibility ------------------------------------------------------------
def test_a_missing_leaf_lowers_recall_exactly() -> None:
    truth = _scene()
    cameras = _cameras()
    captured = truth[:2] + truth[3:]
    result = evaluate_capture(truth, captured, _views(truth, cameras), _predicted(captured, cameras))
    assert result.recall == 3 / 4 and result.precision == 1.0
    assert [(m.truth, m.captured) for m in result.matches] == [(0, 0), (1, 1), (3, 2)]
    assert result.overall["matched"] == 3 and result.captured_count == 3


def test_a_spurious_leaf_lowers_precision_exactly() -> None:
    truth = _scene()
    cameras = _cameras()
    extra = _preset("beech", Transform(translation=(1.6, 0.5, 0.0), rotation=(0.0, 0.0, -20.0), scale=0.6))
    captured = [*truth, extra]
    predicted = _predicted(captured, cameras)
    assert any(np.any(image == 5) for image in predicted)   # the extra leaf is in view
    result = evaluate_capture(truth, captured, _views(truth, cameras), predicted)
    assert result.precision == 4 / 5 and result.recall == 1.0
    assert all(m.captured != 4 for m in result.matches)


def _occluded_scene() -> tuple[list[LeafParams], list[tuple[NDArray[np.float64], NDArray[np.float64]]]]:
    """Leaf 0 (the default leaf, midrib along +y in the ground plane) half covered by leaf 1, a
    large one-sided leaf above it whose straight midrib lies in the plane x = 0 with the camera:
    its edge projects onto leaf 0's midrib. Leaf 2, small, lies under leaf 1 and is hidden."""
    target = LeafParams()
    occluder = LeafParams(shape=Shape(half=1), transform=Transform(translation=(0.0, -1.0, 0.3), scale=3.0))
    hidden = LeafParams(transform=Transform(translation=(-0.15, 0.3, 0.1), rotation=(0.0, 0.0, 20.0), scale=0.3))
    cameras = _cameras(eyes=((0.0, -2.0, 3.0),), target=(0.0, 0.5, 0.0), size=(240, 180))
    return [target, occluder, hidden], cameras


def test_a_leaf_half_hidden_behind_another_is_half_visible() -> None:
    truth, cameras = _occluded_scene()
    views = _views(truth, cameras, size=(240, 180))
    image = views[0][2]
    assert np.count_nonzero(image == 1) > 1000 and not np.any(image == 3)   # big enough; leaf 2 hidden
    vis = visibility(truth, views)
    assert vis[0] == pytest.approx(0.5, abs=0.05)
    assert vis[2] < 0.05
    # the same leaf seen alone is fully visible, and seen from behind a wall not at all
    alone = _views(truth[:1], cameras, size=(240, 180))
    assert visibility(truth[:1], alone)[0] > 0.97
    blank = [(k, m, np.zeros_like(image)) for k, m, _ in views]
    assert visibility(truth, blank).tolist() == [0.0, 0.0, 0.0]


def test_a_hidden_leaf_cannot_be_matched_and_the_bins_show_it() -> None:
    truth, cameras = _occluded_scene()
    views = _views(truth, cameras, size=(240, 180))
    result = evaluate_capture(truth, truth, views, _predicted(truth, cameras, size=(240, 180)))
    assert {m.truth for m in result.matches} == {0, 1}
    assert result.recall == 2 / 3 and result.precision == 2 / 3
    low = result.by_bin[0]
    assert (low["truth"], low["matched"], low["recall"]) == (1, 0, 0.0)
    assert math.isnan(low["median_chamfer"])
    assert sum(row["truth"] for row in result.by_bin) == 3
    half = [row for (lo, hi), row in zip(VISIBILITY_BINS, result.by_bin, strict=True) if lo <= result.visibility[0] < hi]
    assert half[0]["matched"] == 1


# -- IoU matching --------------------------------------------------------------------------------
def _masks(shape: tuple[int, int], regions: dict[int, tuple[slice, slice]]) -> NDArray[np.uint32]:
    image = np.zeros(shape, dtype=np.uint32)
    for label, (rows, cols) in regions.items():
        image[rows, cols] = label
    return image


def test_masks_that_swap_between_views_still_match_one_to_one() -> None:
    # truth: leaf 1 on the left block, leaf 2 on the right, in both views
    truth = _masks((10, 40), {1: (slice(0, 10), slice(0, 20)), 2: (slice(0, 10), slice(20, 40))})
    # view 0: captured 1 on truth 1 (IoU 0.9), captured 2 on truth 2 (IoU 0.9)
    view0 = _masks((10, 40), {1: (slice(0, 9), slice(0, 20)), 2: (slice(0, 9), slice(20, 40))})
    # view 1: the labels swap: captured 1 covers truth 2 better than it covered truth 1 in view 0
    view1 = _masks((10, 40), {2: (slice(0, 6), slice(0, 20)), 1: (slice(0, 10), slice(20, 39))})
    pairs = match_leaves([truth, truth], [view0, view1])
    # the largest summed IoU: 0.9 + 0.9 (view 0), not 0.95 (t2-c1, view 1) + 0.6 (t1-c2, view 1)
    assert [(t, c, v) for t, c, _, v in pairs] == [(0, 0, 0), (1, 1, 0)]
    assert [iou for _, _, iou, _ in pairs] == pytest.approx([0.9, 0.9])
    assert len({c for _, c, _, _ in pairs}) == len(pairs)
    # with view 0 gone, the swapped labels match the other way round
    assert [(t, c) for t, c, _, _ in match_leaves([truth], [view1])] == [(0, 1), (1, 0)]


def test_matching_prefers_more_pairs_to_one_perfect_pair() -> None:
    a, b = (slice(0, 10), slice(0, 10)), (slice(0, 10), slice(10, 20))
    truth = _masks((10, 20), {1: a, 2: b})
    exact = _masks((10, 20), {1: a})                                                # t0-c0: IoU 1
    halves = _masks((10, 20), {2: (slice(0, 5), slice(0, 10)), 1: (slice(0, 5), slice(10, 20))})  # 0.5 each
    pairs = match_leaves([truth, truth], [exact, halves])
    assert pairs == [(0, 1, 0.5, 1), (1, 0, 0.5, 1)]


def test_iou_below_one_half_does_not_match() -> None:
    truth = _masks((10, 10), {1: (slice(0, 10), slice(0, 10))})
    half = _masks((10, 10), {1: (slice(0, 5), slice(0, 10))})           # IoU exactly 0.5
    less = _masks((10, 10), {1: (slice(0, 5), slice(0, 9))})            # IoU 0.45
    assert match_leaves([truth], [half]) == [(0, 0, 0.5, 0)]
    assert match_leaves([truth], [less]) == []
    assert match_leaves([truth, truth], [less, half]) == [(0, 0, 0.5, 1)]
    assert match_leaves([truth], [np.zeros_like(truth)], captured_count=0) == []


def test_bad_input_names_the_view() -> None:
    truth = _masks((10, 10), {1: (slice(0, 10), slice(0, 10))})
    with pytest.raises(ParamError, match=r"predicted_instances\[1\]"):
        match_leaves([truth, truth], [truth, truth[:5]])
    with pytest.raises(ParamError, match=r"views\[0\]\.instance.*2 but only 1"):
        match_leaves([truth * 2], [truth], truth_count=1)
    with pytest.raises(ParamError, match=r"views\[0\]\.instance"):
        match_leaves([truth.astype(np.float32)], [truth])
    with pytest.raises(ParamError, match=r"views\[0\]\.K"):
        visibility([LeafParams()], [(np.eye(2), np.eye(4), truth)])
    with pytest.raises(ParamError, match="predicted_instances"):
        evaluate_capture([LeafParams()], [LeafParams()], [(np.eye(3), np.eye(4), truth)], [])


# -- output --------------------------------------------------------------------------------------
def test_to_dict_is_json_and_the_table_has_a_row_per_bin() -> None:
    truth, cameras = _occluded_scene()
    result = evaluate_capture(truth, truth[:2], _views(truth, cameras, size=(240, 180)),
                              _predicted(truth[:2], cameras, size=(240, 180)))
    data = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    assert data["truth_count"] == 3 and data["captured_count"] == 2 and data["precision"] == 1.0
    assert len(data["by_bin"]) == len(VISIBILITY_BINS) and len(data["matches"]) == 2
    assert data["by_bin"][0]["median_chamfer"] is None      # the hidden leaf's bin has no match
    assert data["visibility"] == pytest.approx(result.visibility.tolist())
    rows = [line for line in result.table().splitlines() if line.startswith("|")]
    assert len(rows) == 2 + len(VISIBILITY_BINS) + 1        # header, rule, one per bin, all
    for (lo, hi), row in zip(VISIBILITY_BINS, rows[2:-1], strict=True):
        assert row.startswith(f"| {round(100 * lo)}–{min(100, round(100 * hi))} % |")
    assert rows[-1].startswith("| all | 3 | 2 | 0.67 |")
    assert "Precision 1.000 (2 of 2" in result.table()
    empty = evaluate_capture([], [], [(np.eye(3), np.eye(4), np.zeros((4, 4), np.uint32))], [np.zeros((4, 4), np.uint32)])
    data = json.loads(json.dumps(empty.to_dict(), allow_nan=False))
    assert data["precision"] is None and data["recall"] is None and data["matches"] == []
    assert "| all | 0 | 0 | — |" in empty.table()


def test_the_splat_rasteriser_leaves_no_holes() -> None:
    """The instance images the other tests use: every leaf's mask is one piece without holes, and
    a finer splat changes it only at the silhouettes."""
    truth = _scene()
    for k, m in _cameras():
        image = splat(truth, k, m, SIZE)[0]
        for label in range(1, len(truth) + 1):
            mask = image == label
            assert mask.sum() > 500
            assert ndimage.label(mask)[1] == 1
            assert np.array_equal(ndimage.binary_fill_holes(mask), mask)
        finer = splat(truth, k, m, SIZE, per_pixel=3.0)[0]
        assert np.count_nonzero(finer != image) < 0.01 * np.count_nonzero(image)
