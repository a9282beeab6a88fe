"""Eq. 1: the Bernstein/power-basis form and its derivatives."""

import numpy as np

from leafview.core.bezier import bernstein, bernstein_matrix, derivative_points, evaluate_curve


def test_cubic_matrix_is_the_one_of_eq_6():
    expected = np.array([[1, 0, 0, 0], [-3, 3, 0, 0], [3, -6, 3, 0], [-1, 3, -3, 1]])
    np.testing.assert_array_equal(bernstein_matrix(3), expected)


def test_power_basis_form_equals_bernstein_form():
    t = np.linspace(0, 1, 17)
    for n in (2, 3, 4, 5):
        powers = t[:, None] ** np.arange(n + 1)
        np.testing.assert_allclose(powers @ bernstein_matrix(n), bernstein(n, t), atol=1e-12)


def test_partition_of_unity_and_end_interpolation():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(5, 3))
    np.testing.assert_allclose(bernstein(4, rng.uniform(size=50)).sum(-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(evaluate_curve(pts, 0.0), pts[0], atol=1e-12)
    np.testing.assert_allclose(evaluate_curve(pts, 1.0), pts[-1], atol=1e-12)


def test_de_casteljau_agrees():
    rng = np.random.default_rng(4)
    pts = rng.normal(size=(5, 2))
    for t in rng.uniform(size=10):
        p = pts.copy()
        while len(p) > 1:
            p = (1 - t) * p[:-1] + t * p[1:]
        np.testing.assert_allclose(evaluate_curve(pts, t), p[0], atol=1e-12)


def test_hodograph_matches_finite_differences():
    rng = np.random.default_rng(5)
    pts = rng.normal(size=(4, 3))
    t = rng.uniform(0.01, 0.99, 20)
    h = 1e-6
    fd = (evaluate_curve(pts, t + h) - evaluate_curve(pts, t - h)) / (2 * h)
    np.testing.assert_allclose(evaluate_curve(derivative_points(pts), t), fd, atol=1e-7)
