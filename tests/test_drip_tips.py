"""Drip tips (Garg & Leow 2011, sec. 3.1 and Fig. 7): an apex "initially concave and then convex"
ending in a long slender tip, as a landmark recipe, catalogue shapes and shader-model fits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from leafview.botany.catalogue import catalogue, landmark_leaf, random_instance
from leafview.botany.landmarks import check_margin, drip_tip, outline_sides, side_fit
from leafview.botany.morph import morph_path
from leafview.botany.outline_fit import margin
from leafview.botany.shapes import fit_info, shape_names, shapes_params
from leafview.core.params import ParamError

DRIP = [e for e in catalogue() if e.apex == "drip"]


def _curvature_above_waist(side, n=6001):
    """(y, signed curvature) of the right margin from the waist to the apex (> 0 turns left,
    i.e. convex walking up the right side)."""
    fit = side_fit(side)
    u = np.linspace(fit.u[side.waist_index], 1.0, n)[1:-1]
    d1, d2 = np.asarray(fit.spline(u, nu=1)), np.asarray(fit.spline(u, nu=2))
    k = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.linalg.norm(d1, axis=1) ** 3
    return np.asarray(fit.spline(u))[:, 1], k


def _half_width_at(right: np.ndarray, y: float) -> float:
    top = right[right[:, 1] > 0.5]
    order = np.argsort(top[:, 1])
    return float(np.interp(y, top[order, 1], top[order, 0]))


def test_two_drip_shapes_in_the_catalogue():
    assert {e.name for e in DRIP} >= {"ovate-drip", "elliptic-drip"}
    assert all(e.figure.startswith("Fig. 7") and not e.table1 and not e.named for e in DRIP)
    for e in catalogue():
        leaf = landmark_leaf(e)
        assert leaf.right.drip_tip == (e.apex == "drip"), e.name


@pytest.mark.parametrize("e", DRIP, ids=lambda e: e.name)
def test_apex_is_concave_then_convex(e):
    leaf = landmark_leaf(e)
    check_margin(leaf)
    y, k = _curvature_above_waist(leaf.right)
    concave = np.flatnonzero(k < -1e-3)
    assert concave.size, "no concave stretch between waist and apex"
    # the concave stretch lies between the waist and the foot of the tip; after it, convex to the apex
    foot = 1.0 - e.drip
    assert y[concave].min() > e.waist_y and y[concave].max() <= foot + 0.02
    after = k[concave.max() + 1:]
    assert after.size and np.all(after > 0.0)
    # and the change of sign happens once there: concave, then convex
    signs = np.sign(k[concave.min():])
    assert np.count_nonzero(np.diff(signs) > 0) == 1 and np.count_nonzero(np.diff(signs) < 0) == 0


@pytest.mark.parametrize("e", DRIP, ids=lambda e: e.name)
def test_tip_is_long_and_slender(e):
    right, left = outline_sides(landmark_leaf(e), 4001)
    widest = right[:, 0].max()
    w95 = _half_width_at(right, 0.95)
    assert 0.0 < w95 < 0.02 and w95 / widest < 0.1
    # the tip is slender over its whole length: at its middle still under a tenth of the blade
    mid = _half_width_at(right, 1.0 - e.drip / 2.0)
    assert mid / widest < 0.12
    np.testing.assert_allclose(left[:, 0], -right[:, 0], atol=1e-12)


def test_an_ordinary_acuminate_apex_has_no_concave_then_convex_tip():
    """The test above can fail: a plain concave apex is concave up to the apex point."""
    y, k = _curvature_above_waist(landmark_leaf("ovate-convex-concave").right)
    assert np.all(k[y > 0.9] < 0.0)
    right, _ = outline_sides(landmark_leaf("ovate-convex-convex"), 4001)
    assert _half_width_at(right, 0.95) / right[:, 0].max() > 0.1


@pytest.mark.parametrize("e", DRIP, ids=lambda e: e.name)
def test_shader_fit_keeps_the_tip(e):
    assert e.name in shape_names()
    info = fit_info(e.name)
    assert info.error <= 0.01 and info.min_jacobian > 0.0 and info.apex == "drip"
    right, left = margin(shapes_params(e.name))
    assert _half_width_at(right, 0.95) < 0.025
    assert abs(float(right[-1, 1]) - 1.0) < 0.01


def test_drip_recipe_overrides_and_bad_values():
    leaf = landmark_leaf("ovate-drip", drip=0.35, tip_width=0.02)
    assert leaf.right.shoulder == pytest.approx((0.02, 0.65))
    (xs, ys), angle, theta_a = drip_tip(0.3, 0.03, (0.3, 0.34))
    assert (xs, ys) == pytest.approx((0.03, 0.7))
    gamma = math.atan2(0.03, 0.3)
    assert math.pi / 2 < angle < math.pi / 2 + gamma < math.pi / 2 + theta_a
    for kw, field in (({"drip": 0.8}, "drip"), ({"drip": 0.0}, "drip"), ({"tip_width": 0.2}, "tip_width"),
                      ({"tip_width": float("nan")}, "tip_width")):
        with pytest.raises(ParamError) as err:
            landmark_leaf("ovate-drip", **kw)
        assert err.value.path == field


def test_random_instances_and_morphs_stay_valid():
    for seed in range(6):
        leaf = random_instance("elliptic-drip", seed)
        check_margin(leaf)
        y, k = _curvature_above_waist(leaf.right)
        assert (k < 0).any() and k[-1] > 0
    path = morph_path("ovate-drip", "cordate")
    for frame in path.frames(5):
        check_margin(frame)
    assert path.frames(5)[0] == landmark_leaf("ovate-drip")
