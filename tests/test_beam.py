"""The cantilever beam (Geng, Hu & Zhang 2014, sec. 4, eq. 4) and the midrib bend built on it."""

import numpy as np
import pytest

from leafview.core.params import Bending, LeafParams, ParamError, parse_params
from leafview.deform.beam import bend_profile, residual, sample_clamped, solve_bending
from leafview.deform.surface import evaluate, normals
from tests.conftest import random_params


def test_newton_residual_below_1e_10_and_bracketed():
    rng = np.random.default_rng(0)
    ds, th = rng.uniform(0.001, 0.5, 20000), rng.uniform(0, np.pi, 20000)
    load, ei = rng.uniform(0, 1e3, 20000), rng.uniform(1e-3, 1e2, 20000)
    phi = solve_bending(ds, th, load, ei)
    assert np.abs(residual(phi, ds, th, load, ei)).max() <= 1e-10
    assert np.all(phi >= 0) and np.all(phi <= th)


def test_small_load_matches_the_linearised_beam():
    phi = solve_bending(0.1, np.pi / 2, 1e-3, 1.0)
    assert phi == pytest.approx(0.1**2 * 1e-3 / 1.0, rel=1e-6)


@pytest.mark.parametrize("bad", [dict(ds=0.0), dict(theta0=4.0), dict(load=-1.0), dict(EI=0.0), dict(EI=np.nan)])
def test_solver_rejects_bad_input(bad):
    args = dict(ds=0.1, theta0=1.0, load=1.0, EI=1.0) | bad
    with pytest.raises(ValueError, match=next(iter(bad))):
        solve_bending(**args)


def _tip_drop(params):
    return -evaluate(params, 0.0, 1.0)[0, 2]


def test_zero_load_gives_no_bend():
    p = LeafParams.load("assets/presets/lanceolate.toml")
    assert bend_profile(p.replace(bending=Bending(load=0.0))).identity
    u, v = np.linspace(-1, 1, 9), np.linspace(0, 1, 9)
    np.testing.assert_array_equal(evaluate(p.replace(bending=Bending(load=0.0, stiffness=3.0)), u, v), evaluate(p, u, v))


def test_droop_grows_with_load_and_shrinks_with_stiffness():
    p = LeafParams.load("assets/presets/lanceolate.toml")
    drops = [_tip_drop(p.replace(bending=Bending(load=x))) for x in (1, 4, 10, 20)]
    assert drops[0] > 0 and np.all(np.diff(drops) > 0)
    stiff = [_tip_drop(p.replace(bending=Bending(load=10, stiffness=s))) for s in (0.5, 1, 2, 4)]
    assert np.all(np.diff(stiff) < 0)
    # the midrib keeps its length (inextensible beam): arc length within 1 %
    v = np.linspace(0, 1, 400)
    bent = evaluate(p.replace(bending=Bending(load=20)), np.zeros_like(v), v)
    straight = evaluate(p, np.zeros_like(v), v)
    length = lambda pts: np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()  # noqa: E731
    assert length(bent) == pytest.approx(length(straight), rel=0.01)


def test_load_direction_is_in_world_space():
    from leafview.core.params import Transform

    p = LeafParams.load("assets/presets/lanceolate.toml").replace(bending=Bending(load=10))
    tip = evaluate(p, 0.0, 1.0)[0]
    assert tip[2] < -0.1                                            # gravity -z: droops down
    flipped = p.replace(transform=Transform(rotation=(180.0, 0.0, 0.0)))   # upside down in the world
    assert evaluate(flipped, 0.0, 1.0)[0][2] > 0.1                  # now it sags towards leaf +z
    along = p.replace(bending=Bending(load=10, direction=(0.0, 1.0, 0.0)))
    assert bend_profile(along).identity                             # pulled along its axis: no bend


def test_petiole_moves_the_base():
    p = LeafParams.load("assets/presets/ovate.toml")
    base = evaluate(p.replace(bending=Bending(load=5, petiole_length=0.2)), 0.0, 0.0)[0]
    assert base[1] < 0 and base[2] < -0.01  # the blade hangs from a bent petiole
    np.testing.assert_allclose(evaluate(p.replace(bending=Bending(load=5)), 0.0, 0.0)[0], 0.0, atol=1e-12)


@pytest.mark.parametrize("alpha", [30.0, -75.0, 120.0])
def test_twist_rotates_the_cross_section_by_alpha_at_the_tip(alpha):
    p = LeafParams.load("assets/presets/oblong.toml")
    twisted = p.replace(bending=Bending(twist=alpha))
    for v in (0.5, 0.95, 0.999):
        a, b = evaluate(p, [-0.5, 0.5], [v, v]), evaluate(twisted, [-0.5, 0.5], [v, v])
        d0, d1 = a[1] - a[0], b[1] - b[0]
        angle = np.degrees(np.arctan2(d1[2], d1[0]) - np.arctan2(d0[2], d0[0]))
        angle = (angle + 180) % 360 - 180
        assert angle == pytest.approx(-alpha * v, abs=1e-6)  # about +y: x turns towards -z
    assert normals(twisted, 0.0, 0.0)[0] @ normals(p, 0.0, 0.0)[0] == pytest.approx(1.0)


def test_bend_samples_interpolate_smoothly():
    vals = np.array([0.0, 0.1, 0.3, 0.6, 0.7, 0.75, 0.77, 0.78])
    v = np.linspace(0, 1, 8)
    np.testing.assert_allclose(sample_clamped(vals, v)[0], vals, atol=1e-12)
    x = np.linspace(0.001, 0.999, 300)
    h = 1e-7
    fd = (sample_clamped(vals, x + h)[0] - sample_clamped(vals, x - h)[0]) / (2 * h)
    np.testing.assert_allclose(sample_clamped(vals, x)[1], fd, atol=1e-5)


@pytest.mark.parametrize("group, key, value, words", [
    ("ripple", "beta", 0.0, "greater than 0"),
    ("ripple", "beta", -1.0, "greater than 0"),
    ("bending", "stiffness", 0.0, "greater than 0"),
    ("bending", "petiole_stiffness", -2.0, "greater than 0"),
    ("bending", "load", float("nan"), "NaN"),
    ("ripple", "amplitude", [0.01, -0.01], "below the minimum"),
    ("ripple", "fluctuation", [0.5, 1.5], "above the maximum"),
    ("ripple", "fluctuation", [-0.1, 0.5], "below the minimum"),
    ("bending", "load", -1.0, "below the minimum"),
    ("bending", "direction", [0, 0, 0], "zero vector"),
    ("ripple", "veins", 0, "greater than 0"),
])
def test_invalid_ripple_and_bend_values_name_the_field(group, key, value, words):
    d = LeafParams().to_dict()
    d[group][key] = value
    with pytest.raises(ParamError, match=words) as info:
        parse_params(d)
    assert info.value.path.startswith(f"{group}.{key}")


def test_random_leaves_bend_without_nans():
    rng = np.random.default_rng(4)
    for _ in range(20):
        p = random_params(rng).replace(bending=Bending(load=rng.uniform(0, 40), twist=rng.uniform(-90, 90),
                                                       petiole_length=rng.uniform(0, 0.3)))
        u, v = rng.uniform(-1, 1, 200), rng.uniform(0, 1, 200)
        assert np.isfinite(evaluate(p, u, v)).all() and np.isfinite(normals(p, u, v)).all()
