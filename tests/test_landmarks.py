"""Garg & Leow 2011, eqs 1-6: the quadratic B-spline through landmarks with tangents, its condition number,
the closed form at singular parameters, and the leaf-space outline."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from leafview.botany.catalogue import catalogue, catalogue_names, landmark_leaf, random_instance
from leafview.botany.hermite import margin_pieces
from leafview.botany.landmarks import (
    LandmarkLeaf,
    SideLandmarks,
    chord_parameters,
    fit_margin,
    fit_margin_report,
    hermite_knots,
    outline,
    outline_sides,
    outlines,
    side_fit,
)
from leafview.core.params import ParamError


def _angle_between(a: np.ndarray, b: np.ndarray) -> float:
    return abs(math.atan2(a[0] * b[1] - a[1] * b[0], a @ b))


def _random_landmarks(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    pts = np.cumsum(rng.uniform(0.05, 0.5, (n, 2)) * rng.choice([-1, 1], (n, 2)), axis=0)
    ang = rng.uniform(-math.pi, math.pi, n)
    return pts, np.c_[np.cos(ang), np.sin(ang)] * rng.uniform(0.5, 3.0, (n, 1))  # any length: direction only


def _assert_interpolates(points: np.ndarray, tangents: np.ndarray, report) -> None:
    spline = report.spline
    np.testing.assert_allclose(spline(report.u), points, atol=1e-9, rtol=0)
    for u, t in zip(report.u, tangents):
        d = spline(u, nu=1)
        assert d @ t > 0, "tangent points backwards"
        assert _angle_between(d, t) <= 1e-6


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_random_landmarks_are_interpolated_with_their_tangents(n):
    rng = np.random.default_rng(100 + n)
    for _ in range(20):
        pts, tan = _random_landmarks(rng, n)
        report = fit_margin_report(pts, tan)
        assert report.spline.k == 2 and report.spline.c.shape == (2 * n, 2)   # 2N control points
        _assert_interpolates(pts, tan, report)
        # eq. 4: the derivative is α_i t_i with α = the total chord length D (eq. 5) by default
        d = report.spline(report.u, nu=1)
        np.testing.assert_allclose(np.linalg.norm(d, axis=1), report.alpha, rtol=1e-9)
        np.testing.assert_allclose(report.alpha, np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())


def test_every_catalogue_side_is_interpolated():
    for e in catalogue():
        leaf = landmark_leaf(e)
        pts, tan = leaf.right.landmarks()
        report = side_fit(leaf.right)
        assert report.method == "solve" and report.condition < 1e4, e.name
        _assert_interpolates(pts, tan, report)


def test_chord_length_parameters_of_eqs_5_and_6():
    pts = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 5.0], [3.0, 9.0]])   # chords 5, 1, 4: D = 10
    u, d = chord_parameters(pts)
    assert d == 10.0
    np.testing.assert_allclose(u, [0.0, 0.5, 0.6, 1.0])
    # quadratic Hermite knots: clamped ends, every landmark and every midpoint (2N + 3 knots)
    np.testing.assert_allclose(hermite_knots(u), [0, 0, 0, 0.25, 0.5, 0.55, 0.6, 0.8, 1, 1, 1])


def test_closed_form_equals_the_linear_solve():
    rng = np.random.default_rng(7)
    for n in (2, 3, 4, 5):
        for _ in range(10):
            pts, tan = _random_landmarks(rng, n)
            a = fit_margin_report(pts, tan, method="solve")
            b = fit_margin_report(pts, tan, method="closed-form")
            assert a.method == "solve" and b.method == "closed-form"
            np.testing.assert_allclose(a.spline.c, b.spline.c, atol=1e-9 * max(1.0, a.condition * 1e-3))


def _three_landmarks(u2: float) -> tuple[np.ndarray, np.ndarray]:
    """Base, waist, apex with the waist at chord parameter u2 along a bent path."""
    base, apex = np.array([0.0, 0.0]), np.array([0.0, 1.0])
    # waist on the circle through base and apex whose chords split as u2 : 1 - u2
    ang = math.pi * u2
    waist = np.array([0.5 * math.sin(ang), 0.5 - 0.5 * math.cos(ang)])
    return np.array([base, waist, apex]), np.array([[1.0, 0.3], [0.0, 1.0], [-1.0, 0.3]])


def test_condition_number_is_small_inside_and_grows_towards_the_ends():
    """Fig. 3(a): small for interior u_2, unbounded as u_2 → 0 or 1."""
    conds = {}
    for x in (1e-6, 1e-4, 1e-2, 0.2, 0.5, 0.8, 1 - 1e-2, 1 - 1e-4, 1 - 1e-6):
        pts, tan = _three_landmarks(x)
        conds[x] = fit_margin_report(pts, tan).condition
    assert max(conds[0.2], conds[0.5], conds[0.8]) < 50
    assert conds[1e-6] > conds[1e-4] > conds[1e-2] > conds[0.2]
    assert conds[1 - 1e-6] > conds[1 - 1e-4] > conds[1 - 1e-2] > conds[0.8]
    assert conds[1e-6] > 1e5


def test_coincident_landmarks_use_the_closed_form_and_leave_a_corner():
    """u_i = u_{i-1}: the system of eqs 3-4 is singular; the closed form still interpolates and the
    margin turns from one landmark's tangent to the other's."""
    pts = np.array([[0.0, 0.0], [0.0, 0.0], [0.3, 0.5], [0.0, 1.0]])
    tan = np.array([[0.0, 1.0], [1.0, 0.0], [0.0, 1.0], [-0.6, 0.8]])
    report = fit_margin_report(pts, tan)
    assert report.method == "closed-form" and report.condition == math.inf
    assert report.u[0] == report.u[1] == 0.0
    np.testing.assert_allclose(report.spline(report.u), pts, atol=1e-12)
    # one-sided tangents: leaving the coincident pair along the second landmark's tangent
    d = report.spline(1e-9, nu=1)
    assert _angle_between(d, tan[1]) < 1e-6
    for i in (2, 3):
        assert _angle_between(report.spline(report.u[i], nu=1), tan[i]) < 1e-6
    with pytest.raises(ParamError, match="singular"):
        fit_margin_report(pts, tan, method="solve")


def test_closed_form_is_the_limit_of_nearly_singular_fits():
    """Nearly coincident landmarks: the solve approaches the singular closed form continuously."""
    tan = np.array([[0.0, 1.0], [1.0, 0.0], [0.0, 1.0], [-0.6, 0.8]])
    singular = fit_margin_report(np.array([[0, 0], [0, 0], [0.3, 0.5], [0, 1.0]]), tan)
    previous = math.inf
    for eps in (1e-2, 1e-4, 1e-6):
        near = fit_margin_report(np.array([[0, 0], [eps, -eps], [0.3, 0.5], [0, 1.0]]), tan)
        gap = np.abs(near.spline.c - singular.spline.c).max()
        assert gap < previous and gap < 10 * eps
        previous = gap


def test_waist_at_the_base_is_singular_but_fits():
    pts = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    tan = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    report = fit_margin_report(pts, tan)
    assert report.method == "closed-form"
    np.testing.assert_allclose(report.spline(report.u), pts, atol=1e-12)


@pytest.mark.parametrize("points, tangents, field", [
    (np.zeros((3, 3)), np.zeros((3, 3)), "points"),
    (np.zeros((1, 2)), np.ones((1, 2)), "points"),
    (np.array([[0, 0], [1, 1.0]]), np.array([[1, 0.0]]), "tangents"),
    (np.array([[0, 0], [np.nan, 1.0]]), np.ones((2, 2)), "points"),
    (np.array([[0, 0], [1, 1.0]]), np.array([[1, 0], [0, 0.0]]), "tangents[1]"),
    (np.array([[0, 0], [0, 0.0]]), np.ones((2, 2)), "points"),
])
def test_bad_landmarks_are_named(points, tangents, field):
    with pytest.raises(ParamError) as err:
        fit_margin(points, tangents)
    assert err.value.path == field


def test_side_validation_names_the_field():
    good = SideLandmarks(0.5, 0.5, (0.25, 0.5))
    with pytest.raises(ParamError) as err:
        good.replace(waist=(0.25, 1.2))
    assert err.value.path == "waist[1]"
    with pytest.raises(ParamError) as err:
        good.replace(theta_b=4.0)
    assert err.value.path == "theta_b"
    with pytest.raises(ParamError) as err:
        good.replace(waist=(0.0, 0.5))
    assert err.value.path == "waist[0]"
    with pytest.raises(ParamError) as err:
        good.replace(tail=("a", 0.1))
    assert err.value.path == "tail"
    with pytest.raises(ParamError) as err:
        LandmarkLeaf.from_dict({"landmarks": 1, "right": {"theta_b": 30, "theta_a": 30, "waist": [0.2, 0.5],
                                                          "wiast": 1}})
    assert err.value.path == "right.wiast"
    with pytest.raises(ParamError) as err:
        LandmarkLeaf.from_dict({"landmarks": 1, "right": {"theta_b": 30, "theta_a": 30, "waist": [0.2, 0.5]},
                                "left": {"theta_b": 30, "theta_a": 300, "waist": [0.2, 0.5]}})
    assert err.value.path == "left.theta_a"


def test_eq1_landmarks_and_tangents():
    side = SideLandmarks(math.radians(120), math.radians(150), (0.3, 0.4), tail=(0.1, -0.1), shoulder=(0.1, 1.1))
    pts, tan = side.landmarks()
    np.testing.assert_allclose(pts, [[0, 0], [0.1, -0.1], [0.3, 0.4], [0.1, 1.1], [0, 1]])
    s, c = math.sin, math.cos
    np.testing.assert_allclose(tan, [[s(math.radians(120)), c(math.radians(120))], [1, 0], [0, 1], [-1, 0],
                                     [-s(math.radians(150)), c(math.radians(150))]], atol=1e-15)
    assert side.waist_index == 2


def test_dict_round_trip_keeps_every_field():
    leaf = landmark_leaf("cordate", left_waist=(0.3, 0.4), left_tail_angle=0.2)
    again = LandmarkLeaf.from_dict(leaf.to_dict())
    for a, b in zip((again.right, again.left), (leaf.right, leaf.left)):
        for name in ("theta_b", "theta_a", "tail_angle", "shoulder_angle"):
            assert getattr(a, name) == pytest.approx(getattr(b, name), abs=1e-12)
        assert a.waist == b.waist and a.tail == b.tail and a.shoulder == b.shoulder
    assert "left" not in landmark_leaf("ovate").to_dict()    # symmetric: one side written


def test_outline_layout_in_leaf_space():
    n = 50
    for name in ("ovate", "cordate", "obcordate", "linear"):
        leaf = landmark_leaf(name)
        poly = outline(leaf, n)
        assert poly.shape == (2 * n - 2, 2)
        np.testing.assert_array_equal(poly[0], [0.0, 0.0])
        np.testing.assert_array_equal(poly[n - 1], [0.0, 1.0])
        assert np.all(poly[1:n - 1, 0] > 0) and np.all(poly[n:, 0] < 0)   # right side first, then left
        x, y = poly[:, 0], poly[:, 1]
        area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
        assert area > 0                                                     # counter-clockwise
        right, left = outline_sides(leaf, n)
        np.testing.assert_allclose(left, right * [-1, 1], atol=1e-15)       # symmetric leaf
        seg = np.linalg.norm(np.diff(right, axis=0), axis=1)
        assert seg.max() / seg.min() < 1.05                                 # even arc-length spacing
    assert outline(landmark_leaf("cordate"), n)[:, 1].min() < -0.05         # the tail reaches below the base
    assert outline(landmark_leaf("obcordate"), n)[:, 1].max() > 1.05        # the shoulder above the apex


def test_asymmetric_outline_uses_each_side():
    leaf = landmark_leaf("elliptic", left_waist=(0.15, 0.6))
    right, left = outline_sides(leaf, 400)
    assert right[:, 0].max() == pytest.approx(0.25, abs=1e-5)
    assert -left[:, 0].min() == pytest.approx(0.15, abs=1e-5)
    assert left[np.argmin(left[:, 0]), 1] == pytest.approx(0.6, abs=5e-3)


def test_landmark_modules_never_import_gl():
    code = ("import sys, leafview.botany.hermite, leafview.botany.landmarks, leafview.botany.catalogue, leafview.botany.morph; "
            "bad = [m for m in ('moderngl', 'glfw', 'imgui_bundle', 'glcontext') if m in sys.modules]; "
            "print(bad); sys.exit(1 if bad else 0)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stdout + result.stderr


# -- many margins at once ---------------------------------------------------------------------------
@pytest.mark.parametrize("n", [2, 3, 5, 6])
def test_margin_pieces_equal_the_fitted_spline(n):
    """The closed form as quadratic Bézier pieces (batched) against the solved B-spline of eqs 3-4,
    random landmarks, a coincident pair (the singular case) included."""
    rng = np.random.default_rng(300 + n)
    sets = [_random_landmarks(rng, n) for _ in range(12)]
    pts, tan = np.stack([p for p, _ in sets]), np.stack([t for _, t in sets])
    if n >= 3:
        pts[0, 1] = pts[0, 0]                      # singular: closed form on both sides
    u = np.linspace(0.0, 1.0, 257)
    got = margin_pieces(pts, tan)(u)
    for k in range(len(sets)):
        np.testing.assert_allclose(got[k], fit_margin(pts[k], tan[k])(u), atol=1e-9)
    per_leaf_u = np.sort(rng.uniform(0, 1, (len(sets), 33)), axis=1)
    for k, row in enumerate(margin_pieces(pts, tan)(per_leaf_u)):
        np.testing.assert_allclose(row, fit_margin(pts[k], tan[k])(per_leaf_u[k]), atol=1e-9)


def test_margin_pieces_bad_input_is_named():
    for pts, tan, field in ((np.zeros((2, 3)), np.zeros((2, 3)), "points"),
                            (np.zeros((1, 3, 2)), np.ones((1, 2, 2)), "tangents"),
                            (np.zeros((1, 3, 2)), np.zeros((1, 3, 2)), "tangents"),
                            (np.zeros((1, 3, 2)), np.ones((1, 3, 2)), "points")):
        with pytest.raises(ParamError) as err:
            margin_pieces(pts, tan)
        assert err.value.path == field


def test_outlines_equal_outline_leaf_by_leaf():
    names = catalogue_names()
    leaves = [random_instance(landmark_leaf(names[k % 62]), k, independent_sides=k % 3 == 0) for k in range(70)]
    for spacing, n in (("arclength", 128), ("parameter", 40), ("arclength", 7)):
        batch = outlines(leaves, n, spacing=spacing)
        assert batch.shape == (70, 2 * n - 2, 2)
        for k, leaf in enumerate(leaves):
            np.testing.assert_allclose(batch[k], outline(leaf, n, spacing=spacing), atol=1e-12)
    with pytest.raises(ParamError) as err:
        outlines([leaves[0], "ovate"])
    assert err.value.path == "leaves[1]"
    with pytest.raises(ValueError):
        outlines(leaves, 1)
