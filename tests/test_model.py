"""The numpy reference (eqs 2-6, jitter, normals, tessellation) checked against independent
constructions: boundary curves, symmetry, finite differences, winding."""

import subprocess
import sys

import numpy as np
import pytest

from leafview.core.bezier import derivative_points, evaluate_curve
from leafview.core.params import Jitter, LeafParams
from leafview.deform.surface import evaluate, grid_indices, grid_uv, jitter_table, normals, partials, tessellate
from tests.conftest import random_params


def _axis_normal(params, v):
    d = evaluate_curve(derivative_points(params.shape.axis_points()), v)
    m = np.array([-d[1], d[0], 0.0])
    return m / np.linalg.norm(m)


def _silhouette(params, sigma, v, frac=1.0, zkey="zs"):
    """S (or F, G with frac 1/3, 2/3) built directly from eqs 3-4."""
    s = params.shape
    pa = s.axis_points()
    z = {"zs": s.zs, "zf": np.array(s.zf), "zg": np.array(s.zg)}[zkey]
    pts = [np.zeros(3)]
    for i in range(3):
        vb = s.vbar[i]
        pts.append(evaluate_curve(pa, vb) + sigma * frac * s.xs[i] * _axis_normal(params, vb) + [0, 0, z[i]])
    pts.append(np.array([0.0, 1.0, 0.0]))
    return evaluate_curve(np.array(pts), v)


def test_midrib_silhouettes_and_tips():
    rng = np.random.default_rng(0)
    for _ in range(20):
        p = random_params(rng)
        v = rng.uniform(0, 1, 15)
        np.testing.assert_allclose(evaluate(p, 0.0, v), evaluate_curve(p.shape.axis_points(), v), atol=1e-12)
        for sigma in (1.0, -1.0):
            expected = np.array([_silhouette(p, sigma, vi) for vi in v])
            np.testing.assert_allclose(evaluate(p, sigma, v), expected, atol=1e-12)
        u = rng.uniform(-1, 1, 15)
        np.testing.assert_allclose(evaluate(p, u, 0.0), 0.0, atol=1e-12)
        np.testing.assert_allclose(evaluate(p, u, 1.0), np.tile([0, 1, 0], (15, 1)), atol=1e-12)


def test_cross_section_control_points_are_eq_5():
    rng = np.random.default_rng(1)
    p = random_params(rng)
    for v in (0.1, 0.37, 0.8):
        for sigma in (1.0, -1.0):
            c = np.array([evaluate_curve(p.shape.axis_points(), v), _silhouette(p, sigma, v, 1 / 3, "zf"),
                          _silhouette(p, sigma, v, 2 / 3, "zg"), _silhouette(p, sigma, v)])
            s = np.linspace(0, 1, 7)
            np.testing.assert_allclose(evaluate(p, sigma * s, v), evaluate_curve(c, s), atol=1e-12)


def test_straight_axis_normal_points_minus_x_and_leaf_is_mirror_symmetric():
    p = LeafParams()
    np.testing.assert_allclose(_axis_normal(p, 0.5), [-1, 0, 0], atol=1e-12)
    u = np.linspace(0, 1, 9)
    v = np.linspace(0, 1, 9)
    right, left = evaluate(p, u, v), evaluate(p, -u, v)
    np.testing.assert_allclose(right * [-1, 1, 1], left, atol=1e-12)
    assert np.all(right[1:-1, 0] < 0)  # u > 0 lies on the -x side (eq. 2)


def test_partials_match_finite_differences_with_jitter():
    rng = np.random.default_rng(2)
    h = 1e-6
    for jit in (False, True):
        p = random_params(rng, jitter=jit)
        u = rng.uniform(-0.99, 0.99, 300)
        u = np.where(np.abs(u) < 2 * h, 0.5, u)
        v = rng.uniform(0.01, 0.99, 300)
        d = partials(p, u, v)
        fu = (evaluate(p, u + h, v) - evaluate(p, u - h, v)) / (2 * h)
        fv = (evaluate(p, u, v + h) - evaluate(p, u, v - h)) / (2 * h)
        fuv = (partials(p, u, v + h).Lu - partials(p, u, v - h).Lu) / (2 * h)
        # jitter's table is piecewise linear: skip points within h of a kink
        t = v * p.jitter.density
        smooth = np.abs(t - np.round(t)) > 1e-4 if jit else np.ones_like(v, bool)
        np.testing.assert_allclose(d.Lu, fu, atol=2e-6)
        np.testing.assert_allclose(d.Lv[smooth], fv[smooth], atol=2e-6)
        np.testing.assert_allclose(d.Luv[smooth], fuv[smooth], atol=5e-5)


def test_normals_unit_upper_side_and_limits_at_tips():
    p = LeafParams()
    n = normals(p, np.linspace(-1, 1, 11), np.linspace(0, 1, 11))
    np.testing.assert_allclose(n, np.tile([0, 0, 1], (11, 1)), atol=1e-12)
    rng = np.random.default_rng(3)
    q = random_params(rng)
    u = rng.uniform(-1, 1, 40)
    for v_tip, v_near in ((0.0, 1e-5), (1.0, 1 - 1e-5)):
        tip, near = normals(q, u, v_tip), normals(q, u, v_near)
        np.testing.assert_allclose(np.linalg.norm(tip, axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(tip, near, atol=1e-3)  # the limit direction, continuous


def test_normals_are_minus_du_cross_dv():
    rng = np.random.default_rng(4)
    p = random_params(rng, jitter=True)
    u, v = rng.uniform(-1, 1, 50), rng.uniform(0.05, 0.95, 50)
    d = partials(p, u, v)
    n = -np.cross(d.Lu, d.Lv)
    np.testing.assert_allclose(normals(p, u, v), n / np.linalg.norm(n, axis=1, keepdims=True), atol=1e-12)


def test_tessellate_layout_and_winding():
    mesh = tessellate(LeafParams(), 9, 15)
    assert mesh.vertices.shape == (135, 3) and mesh.normals.shape == (135, 3) and mesh.uv.shape == (135, 2)
    assert mesh.indices.shape == (2 * 8 * 14, 3) and mesh.indices.max() == 134
    a, b, c = (mesh.vertices[mesh.indices[:, k]] for k in range(3))
    cross_z = np.cross(b - a, c - a)[:, 2]
    nondegenerate = np.abs(cross_z) > 1e-12
    assert np.all(cross_z[nondegenerate] > 0)  # counter-clockwise seen from +z
    np.testing.assert_array_equal(grid_indices(9, 15), mesh.indices)
    assert grid_uv(9, 15)[4].tolist() == [0.0, 0.0]  # odd nu: a column on the midrib
    with pytest.raises(ValueError):
        grid_uv(1, 5)


def test_jitter_off_changes_nothing_and_on_moves_only_outward_in_plane():
    rng = np.random.default_rng(5)
    base = random_params(rng)
    u, v = rng.uniform(-1, 1, 500), rng.uniform(0, 1, 500)
    off = base.replace(jitter=Jitter(enabled=False, amplitude=0.07, density=13))
    np.testing.assert_array_equal(evaluate(off, u, v), evaluate(base, u, v))
    on = base.replace(jitter=Jitter(enabled=True, amplitude=0.07, density=13, seed=3))
    delta = evaluate(on, u, v) - evaluate(base, u, v)
    np.testing.assert_allclose(delta[:, 2], 0.0, atol=1e-15)  # in the leaf plane
    n = np.array([_axis_normal(base, vi) for vi in v])
    outward = np.sum(delta * n, axis=1) * np.sign(np.where(u >= 0, 1, -1))
    assert np.all(outward >= -1e-15) and outward.max() > 0.01
    np.testing.assert_allclose(evaluate(on, 0.0, v), evaluate(base, 0.0, v), atol=1e-15)  # axis untouched
    np.testing.assert_allclose(evaluate(on, u, 0.0), evaluate(base, u, 0.0), atol=1e-15)  # tips untouched
    np.testing.assert_allclose(evaluate(on, u, 1.0), evaluate(base, u, 1.0), atol=1e-15)


def test_jitter_table_is_seeded():
    a, b = jitter_table(Jitter(seed=1)), jitter_table(Jitter(seed=1))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, jitter_table(Jitter(seed=2)))
    assert a.dtype == np.float32 and a.min() >= 0 and a.max() <= 1


def test_evaluate_rejects_out_of_domain():
    with pytest.raises(ValueError):
        evaluate(LeafParams(), 1.5, 0.5)
    with pytest.raises(ValueError):
        evaluate(LeafParams(), 0.5, np.nan)


def test_model_never_imports_gl():
    code = ("import sys, leafview, leafview.core, leafview.deform.surface, leafview.botany.shapes, leafview.scene.spec, leafview.core.edits, leafview.core.io, leafview.landmarks, leafview.shapes; "
            "bad = [m for m in ('moderngl', 'glfw', 'imgui_bundle', 'glcontext') if m in sys.modules]; "
            "print(bad); sys.exit(1 if bad else 0)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_control_polygons_are_the_curves_control_points():
    from leafview.deform.surface import control_polygons

    rng = np.random.default_rng(8)
    p = random_params(rng)
    polys = control_polygons(p)
    assert set(polys) == {"A", "S+", "F+", "G+", "S-", "F-", "G-"}
    v = np.linspace(0, 1, 11)
    np.testing.assert_allclose(evaluate_curve(polys["A"], v), evaluate(p, 0.0, v), atol=1e-12)
    np.testing.assert_allclose(evaluate_curve(polys["S+"], v), evaluate(p, 1.0, v), atol=1e-12)
    np.testing.assert_allclose(evaluate_curve(polys["S-"], v), evaluate(p, -1.0, v), atol=1e-12)
    np.testing.assert_allclose(polys["F+"][1:4], _frac_points(p, 1 / 3, p.shape.zf), atol=1e-12)  # eq. 4a
    np.testing.assert_allclose(polys["G-"][1:4], _frac_points(p, -2 / 3, p.shape.zg), atol=1e-12)  # eq. 4b


def _frac_points(p, frac, z):
    from leafview.deform.surface import axis_frames

    a, q = axis_frames(p)
    return a + frac * q + np.c_[np.zeros(3), np.zeros(3), z]
