"""One closed margin for the multilobed leaves (Garg & Leow 2011, sec. 5): the union of the parts
joined by valley curves and fitted by a closed B-spline (leafview.botany.lobe_outline), and the
maple, oak and bilobed presets generated from it (tools/make_lobed_presets.py)."""

from __future__ import annotations

import importlib.util
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import shapely
from shapely.geometry import LinearRing, Polygon

from leafview.botany.lobe_outline import (
    HAUSDORFF_GOAL,
    hausdorff,
    lobed_margin,
    lobed_outline,
    lobed_outline_params,
    parts_union,
)
from leafview.botany.lobes import LobedLeaf, builtin_lobed, load_lobed_leaf, lobed_from_dict
from leafview.core.bspline import evaluate_closed, sample_closed, signed_area
from leafview.core.lobes import VALLEY_TOLERANCE, outline_samples, self_intersections
from leafview.core.params import LeafParams, ParamError
from leafview.resources import builtin_presets

NAMES = ("maple", "oak", "bilobed")
ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("make_lobed_presets", ROOT / "tools" / "make_lobed_presets.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def presets() -> dict[str, LeafParams]:
    return {n: LeafParams.load(builtin_presets()[n]) for n in NAMES}


@pytest.fixture(scope="module")
def margins(presets):
    """Each built-in's margin refitted with the preset's number of control points."""
    return {n: lobed_margin(load_lobed_leaf(n), controls=len(presets[n].lobes.outline), grow=False) for n in NAMES}


@pytest.mark.parametrize("name", NAMES)
def test_margin_is_one_simple_clockwise_curve_from_the_base(name, margins):
    mg = margins[name]
    ring = outline_samples(mg.outline)
    assert self_intersections(ring) == []
    assert signed_area(ring) < 0.0                          # clockwise seen from +z
    c0 = evaluate_closed(mg.outline, 0.0)
    dense = sample_closed(mg.outline, 4096)
    nearest = dense[np.argmin(np.linalg.norm(dense, axis=1))]
    assert np.linalg.norm(c0 - nearest) < 0.01 * mg.length  # C(0): the margin point nearest (0, 0)
    assert evaluate_closed(mg.outline, 0.02)[0] < c0[0]     # the sweep leaves the base towards -x


@pytest.mark.parametrize("name", NAMES)
def test_fit_is_close_to_the_union_of_the_parts(name, margins):
    mg = margins[name]
    union, _, _ = parts_union(load_lobed_leaf(name))
    target = np.asarray(union.exterior.coords)[:-1]
    curve = sample_closed(mg.outline, 8192)
    length = float(np.ptp(target[:, 1]))
    h = hausdorff(curve, target)
    assert h <= HAUSDORFF_GOAL * length, f"{name}: Hausdorff {100 * h / length:.3f} % of the length"
    area = abs(signed_area(curve))
    assert abs(area - union.area) <= 0.01 * union.area


@pytest.mark.parametrize("name", NAMES)
def test_valleys_lie_on_the_margin_between_lobes(name, margins):
    mg = margins[name]
    expected = {"maple": 4, "oak": 8, "bilobed": 1}[name]
    assert len(mg.valleys) == expected
    ring = LinearRing(sample_closed(mg.outline, 8192))
    assert np.all(shapely.distance(shapely.points(mg.valleys), ring) <= VALLEY_TOLERANCE)
    # a valley is a concave place: the margin's hull leaves it well outside
    hull = Polygon(ring).convex_hull.exterior
    assert np.all(shapely.distance(shapely.points(mg.valleys), hull) > 0.02 * mg.length)


@pytest.mark.parametrize("name", NAMES)
def test_committed_presets_equal_what_the_tool_writes(name, presets, margins):
    tool = _tool()
    leaf = load_lobed_leaf(builtin_lobed()[name])
    fresh = lobed_outline_params(leaf, controls=len(presets[name].lobes.outline), grow=False)
    text = (ROOT / "assets" / "presets" / f"{name}.toml").read_text()
    assert text.startswith(tool.header(name))
    np.testing.assert_allclose(np.asarray(fresh.lobes.outline), np.asarray(presets[name].lobes.outline),
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(fresh.lobes.valleys), np.asarray(presets[name].lobes.valleys),
                               rtol=0, atol=1e-9)
    assert presets[name].material == leaf.material and presets[name].name == name


@pytest.mark.parametrize("name", NAMES)
def test_presets_round_trip_and_are_listed(name, presets):
    assert name in builtin_presets()
    p = presets[name]
    assert p.lobes.enabled and len(p.lobes.valleys) >= 1
    assert LeafParams.from_dict(p.to_dict()) == p


def test_controls_grow_until_the_goal_is_met():
    leaf = load_lobed_leaf("maple")
    coarse = lobed_margin(leaf, controls=16, grow=False)
    assert coarse.hausdorff_fraction > HAUSDORFF_GOAL            # too few control points ...
    grown = lobed_margin(leaf, controls=16)
    assert grown.controls > 16 and grown.hausdorff_fraction <= HAUSDORFF_GOAL   # ... so it grows
    assert lobed_outline(leaf, controls=16).shape == (grown.controls, 2)


# -- bad input -------------------------------------------------------------------------------------
def _oak(**changes) -> LobedLeaf:
    return replace(load_lobed_leaf("oak"), **changes)


def test_a_lobe_outside_the_blade_names_its_position():
    leaf = _oak(positions=((0.15, 72.0, 0.26), (0.31, 64.0, 0.3), (2.5, 60.0, 0.3)))
    with pytest.raises(ParamError) as e:
        lobed_outline(leaf)
    assert e.value.path == "positions[2]" and "outside the blade" in str(e.value)


def test_a_lobe_outside_the_blade_by_eqs_7_9_names_r1():
    leaf = _oak(r1=0.9, spacing=0.0, half=2, web_length=0.3, terminal_base=0.0, terminal_length=0.3)
    with pytest.raises(ParamError) as e:
        lobed_outline(leaf)
    assert e.value.path in ("r1", "theta", "length") and "outside the blade" in str(e.value)


def test_valley_points_off_the_margin_name_the_point():
    leaf = replace(load_lobed_leaf("bilobed"), valleys=((0.0, 0.472), (0.3, 0.3)))
    with pytest.raises(ParamError) as e:
        lobed_outline(leaf)
    assert e.value.path == "valleys[1]"
    far = replace(load_lobed_leaf("bilobed"), valleys=((-0.62, 0.58),))   # on the margin, no valley near
    with pytest.raises(ParamError) as e:
        lobed_outline(far)
    assert e.value.path == "valleys[0]"


def test_a_valley_curve_that_crosses_the_margin_is_refused():
    # a point just off the margin but on the far side of the opposite lobe's edge: its curve crosses
    leaf = replace(load_lobed_leaf("maple"), valleys=((0.2, 0.367),))
    lobed_outline(leaf)                                        # on the valley: fine
    bad = replace(load_lobed_leaf("bilobed"), valleys=((0.0, 0.4535),))
    with pytest.raises(ParamError) as e:
        lobed_margin(bad, controls=96)
    assert e.value.path.startswith("valleys")


def test_user_valley_points_are_honoured():
    base = lobed_margin(load_lobed_leaf("maple"), controls=128, grow=False)
    v = base.valleys[0] + np.array([0.006, 0.004])
    leaf = replace(load_lobed_leaf("maple"), valleys=(tuple(v),))
    mg = lobed_margin(leaf, controls=128)
    curve = LinearRing(sample_closed(mg.outline, 16384))
    assert curve.distance(shapely.Point(*v)) <= 1e-3
    assert any(np.allclose(p, v) for p in mg.valleys)
    assert len(mg.valleys) == len(base.valleys)                # it replaced one valley, not added one


def test_compound_files_read_valleys_and_name_bad_ones():
    doc = {"lobed": 1, "kind": "bilobed", "half": 1, "terminal": "", "valleys": [[0.0, 0.47]]}
    assert lobed_from_dict(doc).valleys == ((0.0, 0.47),)
    for bad, path in (([[0.0]], "valleys[0]"), ([[0.0, float("nan")]], "valleys[0][1]"),
                      ("x", "valleys"), ([[0.0, 1e9]], "valleys[0][1]")):
        with pytest.raises(ParamError) as e:
            lobed_from_dict({**doc, "valleys": bad})
        assert e.value.path == path
