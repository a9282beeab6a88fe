"""Garg & Leow 2011, Table 1, Figs 4-6 and 8: the catalogue of unilobed shapes, their waist, base and apex
types measured on the drawn margins, asymmetric leaves and random instances."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from leafview.botany.catalogue import (
    MARGIN_TYPES,
    catalogue,
    catalogue_names,
    combine_sides,
    entry,
    landmark_leaf,
    load_landmark_leaf,
    random_instance,
    save_landmark_leaf,
)
from leafview.botany.landmarks import (
    LandmarkLeaf,
    SideLandmarks,
    check_margin,
    outline,
    outline_sides,
    side_fit,
)
from leafview.core.params import ParamError

FIG5 = ["elliptic", "lanceolate", "oblanceolate", "rhomboidal", "deltoid", "linear", "oval", "ovate", "obovate",
        "orbicular", "oblong", "cordate", "obcordate", "reniform"]
ENTRIES = catalogue()


def test_table1_has_fifty_types_and_fig5_fourteen_names():
    names = catalogue_names()
    assert len(names) == len(set(names)) == 64          # + the two drip-tip shapes of Fig. 7
    table1 = [e for e in ENTRIES if e.table1]
    assert len(table1) == 50
    combos = [(e.waist, e.base, e.apex) for e in table1 if e.waist in ("elliptic", "ovate", "obovate")]
    assert sorted(combos) == sorted(itertools.product(("elliptic", "ovate", "obovate"), MARGIN_TYPES, MARGIN_TYPES))
    assert {(e.name, e.waist, e.base, e.apex) for e in table1 if e.waist in ("oblong", "linear")} == {
        ("oblong", "oblong", "convex", "convex"), ("linear", "linear", "straight", "straight")}
    assert [e.name for e in ENTRIES if e.named] == FIG5
    assert all(e.unilobed for e in ENTRIES)


def _widest(leaf: LandmarkLeaf) -> tuple[float, float]:
    """(half-width, y) of the widest point of the right margin, from a dense polyline."""
    right, _ = outline_sides(leaf, 4001)
    i = int(np.argmax(right[:, 0]))
    return float(right[i, 0]), float(right[i, 1])


@pytest.mark.parametrize("e", ENTRIES, ids=lambda e: e.name)
def test_widest_point_matches_the_waist_type(e):
    leaf = landmark_leaf(e)
    width, y = _widest(leaf)
    # the waist landmark is the widest point of the drawn margin (nothing bulges past it)
    assert width == pytest.approx(leaf.right.waist[0], abs=1e-6)
    if e.waist == "elliptic":
        assert 0.4 <= y <= 0.6
    elif e.waist == "ovate":
        assert y < 0.4
    elif e.waist == "obovate":
        assert y > 0.6
    elif e.waist == "linear":
        assert 2 * width < 0.1                          # narrower than a tenth of the length
    elif e.waist == "oblong":
        right, _ = outline_sides(leaf, 4001)
        middle = right[(right[:, 1] > 0.32) & (right[:, 1] < 0.68)]
        assert np.ptp(middle[:, 0]) < 1e-9              # opposite sides parallel in the middle
    else:
        pytest.fail(f"unknown waist type {e.waist}")


def _end_bulge(side: SideLandmarks, end: str, fraction: float = 0.25) -> float:
    """Signed deviation of the margin from its chord over the first ``fraction`` of the arc from the
    base (or apex) towards the waist, divided by the chord length squared: > 0 means the margin
    lies outside the chord (convex), < 0 inside (concave)."""
    fit = side_fit(side)
    k = side.waist_index
    u = np.linspace(0.0, fit.u[k], 4001) if end == "base" else np.linspace(1.0, fit.u[k], 4001)
    p = fit.spline(u)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    q = p[s <= fraction * s[-1]]
    chord, mid = q[-1] - q[0], q[len(q) // 2] - q[0]
    cross = chord[0] * mid[1] - chord[1] * mid[0]
    sign = -1.0 if end == "base" else 1.0   # walking up the right side, outside is clockwise
    return sign * cross / (chord @ chord)


def _first_span_turn(side: SideLandmarks, end: str) -> float:
    """Sign of the curvature on the first / last B-spline span from its control polygon."""
    q = side_fit(side).control_points
    a, b, c = (q[0], q[1], q[2]) if end == "base" else (q[-3], q[-2], q[-1])
    (x1, y1), (x2, y2) = b - a, c - b
    return float(x1 * y2 - y1 * x2)


@pytest.mark.parametrize("e", ENTRIES, ids=lambda e: e.name)
def test_base_and_apex_curvature_have_the_right_sign(e):
    leaf = landmark_leaf(e)
    right, _ = outline_sides(leaf, 801)
    for end, kind in (("base", e.base), ("apex", e.apex)):
        bulge = _end_bulge(leaf.right, end)
        turn = _first_span_turn(leaf.right, end)
        if kind == "convex":
            assert bulge > 1e-3 and turn > 0, (end, bulge, turn)
        elif kind == "concave":
            assert bulge < -1e-3 and turn < 0, (end, bulge, turn)
        elif kind == "straight":
            assert abs(bulge) < 1e-9 and abs(turn) < 1e-12, (end, bulge, turn)
        elif kind == "drip":   # the slender tip closes convexly onto the apex (tests/test_drip_tips.py)
            assert end == "apex" and turn > 0 and leaf.right.drip_tip, (end, turn)
        else:  # extended: the margin leaves the base downwards / enters the apex from above
            if end == "base":
                assert leaf.has_basal_extension and right[:, 1].min() < -0.05 and right[1, 1] < 0
            else:
                assert leaf.has_apical_extension and right[:, 1].max() > 1.05 and right[-2, 1] > 1
        if kind != "extended":
            assert (right[:, 1].min() >= 0.0) if end == "base" else (right[:, 1].max() <= 1.0)


def test_named_shapes_keep_their_botanical_proportions():
    def ratio(name: str) -> float:           # length / full width
        return 1.0 / (2.0 * _widest(landmark_leaf(name))[0])

    assert ratio("lanceolate") >= 3.0 and ratio("oblanceolate") >= 3.0
    assert ratio("orbicular") == pytest.approx(1.0, abs=0.05)
    assert ratio("reniform") < 1.0                                 # kidney: wider than long
    assert ratio("oval") < ratio("elliptic")                       # oval: broadly elliptic
    poly = outline(landmark_leaf("orbicular"), 400)
    radius = np.linalg.norm(poly - [0.0, 0.5], axis=1)
    assert np.ptp(radius) < 0.05                                   # close to a circle


def test_overrides_and_asymmetry():
    base = landmark_leaf("ovate")
    assert base.is_symmetric and base.name == "ovate"
    asym = landmark_leaf("ovate", left_waist=(0.2, 0.5))
    assert not asym.is_symmetric and asym.right == base.right and asym.left.waist == (0.2, 0.5)
    mixed = landmark_leaf("ovate", left="elliptic")                 # Fig. 6: other type on one side
    assert mixed.left == landmark_leaf("elliptic").left and mixed.right == base.right
    assert combine_sides("ovate", "elliptic").left == mixed.left
    right, left = outline_sides(mixed, 400)
    assert not np.allclose(right * [-1, 1], left)
    # a recipe override rebuilds the angles: a straight base stays straight at another width
    wide = landmark_leaf("rhomboidal", half_width=0.4)
    assert wide.right.waist[0] == 0.4 and abs(_first_span_turn(wide.right, "base")) < 1e-12
    with pytest.raises(ParamError) as err:
        landmark_leaf("ovate", wasit=(0.2, 0.5))
    assert err.value.path == "wasit"
    with pytest.raises(ParamError) as err:
        landmark_leaf("ovate", left_waist=(0.2, 1.5))
    assert err.value.path == "left.waist[1]"
    with pytest.raises(ParamError, match="ovate-convex-convex"):
        entry("ovate-convex")


def test_random_instances_stay_within_the_perturbation():
    ref = landmark_leaf("cordate")
    a, b = random_instance(ref, seed=1), random_instance(ref, seed=1)
    assert a == b                                                    # seeded
    assert random_instance(ref, seed=2) != a
    assert a.is_symmetric and not random_instance(ref, seed=1, independent_sides=True).is_symmetric
    for seed in range(30):
        inst = random_instance(ref, seed=seed, amount=0.2)
        for got, want in ((inst.right.theta_b, ref.right.theta_b), (inst.right.theta_a, ref.right.theta_a),
                          (inst.right.waist[0], ref.right.waist[0]), (inst.right.waist[1], ref.right.waist[1]),
                          (inst.right.tail[0], ref.right.tail[0]), (inst.right.tail[1], ref.right.tail[1])):
            assert abs(got / want - 1.0) <= 0.2 + 1e-12
        assert inst.right.tail[1] < 0                                # still cordate
    zero = random_instance(ref, seed=5, amount=0.0)
    assert zero.right == ref.right
    spread = [random_instance("obcordate", seed=s).right.shoulder[1] for s in range(30)]
    assert min(spread) > 1.0 and max(spread) - min(spread) > 0.01      # the apical extension varies, stays above
    with pytest.raises(ParamError):
        random_instance(ref, seed=0, amount=1.5)


def test_landmark_files_round_trip_and_report_errors(tmp_path):
    leaf = landmark_leaf("reniform", left_waist=(0.55, 0.5))
    path = tmp_path / "kidney.toml"
    save_landmark_leaf(leaf, path)
    back = load_landmark_leaf(path)
    np.testing.assert_allclose(outline(back, 64), outline(leaf, 64), atol=1e-12)
    assert load_landmark_leaf("cordate") == landmark_leaf("cordate")
    bad = tmp_path / "bad.toml"
    bad.write_text("landmarks = 1\n[right]\ntheta_b = 30\ntheta_a = 40\nwaist = [0.3, 1.4]\n")
    with pytest.raises(ParamError) as err:
        load_landmark_leaf(bad)
    assert err.value.path == "right.waist[1]" and err.value.source == str(bad)
    with pytest.raises(ParamError) as err:
        load_landmark_leaf(tmp_path / "missing.toml")
    assert "no such file" in str(err.value)


def test_margins_that_loop_or_cross_the_midrib_are_rejected(tmp_path):
    for e in ENTRIES:
        check_margin(landmark_leaf(e))                                   # every catalogue shape is simple
    for seed in range(10):
        check_margin(random_instance("cordate", seed, independent_sides=True))
    with pytest.raises(ParamError) as err:
        check_margin(landmark_leaf("cordate", left_tail_angle=3.0))     # tail tangent pointing back
    assert err.value.path == "left" and "crosses itself" in str(err.value)
    with pytest.raises(ParamError) as err:
        check_margin(landmark_leaf("cordate", right_tail=(0.02, -0.2), right_tail_angle=-2.5))
    assert err.value.path == "right" and "midrib" in str(err.value)
    bad = tmp_path / "loop.toml"
    save_landmark_leaf(landmark_leaf("cordate", tail_angle=3.0), bad)
    with pytest.raises(ParamError) as err:
        load_landmark_leaf(bad)
    assert err.value.source == str(bad)
