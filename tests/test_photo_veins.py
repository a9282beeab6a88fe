"""Secondary veins read from a photographed leaf (:mod:`leafview.fit.photo_veins`), on seeded
synthetic photos whose veins are drawn from a known vein tree (``synthetic_photo(veins="tree")``).

**The truth.** A Venation's angle and curvature are laid out in the leaf's own vein space
q = (u · w(v), v), and the fitted leaf's (u, v) is not the true leaf's: the same veins make other
angles in the fitted leaf's q. What the fit must find is the Venation that puts the fitted leaf's
veins where the photo's are, so the truth here is the true secondaries (the drawn polylines)
carried into the fitted leaf's vein space through the texture's own map
(:func:`leafview.fit.photo_texture.pixel_positions`) and fitted by the same family
(:func:`~leafview.fit.vein_family.family_misfit`) over a full grid; the count is the tree's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from leafview.botany.vein_space import halfwidth_table, vein_space, vein_space_of
from leafview.botany.venation import check_veins, vein_tree
from leafview.core.io import load_params
from leafview.core.venation import Venation
from leafview.errors import ParamError
from leafview.fit import ImageFit, fit_image
from leafview.fit.photo_texture import pixel_positions
from leafview.fit.photo_veins import MAX_MISFIT, NOT_VISIBLE, detect_veins, family_misfit, ridge_maps, vein_image
from leafview.fit.synthetic_photos import SyntheticPhoto, synthetic_photo
from leafview.fit.vein_family import reach
from leafview.fit.vein_search import RIDGE_ROWS, side_parts
from leafview.resources import builtin_presets

SIZE = (1000, 1000)
TREE_SEEDS = range(5, 17)           # 12 photos; 9 show their veins clearly enough (see the report)
PLAIN_SEEDS = (100, 101, 102, 103)
ANGLE_TOL = 8.0                     # degrees
COUNT_TOL = 2                       # secondaries per side


def _row_w(table: np.ndarray, rows: int = RIDGE_ROWS) -> np.ndarray:
    y = (np.arange(rows) + 0.5) / rows
    return vein_space_of(table, np.stack([np.ones(rows), y], axis=1))[:, 0]


def truth_in_fitted_space(sp: SyntheticPhoto, fit: ImageFit) -> dict[int, tuple[float, float, float]]:
    """Per side: (θ degrees, c, RMS misfit) of the family fitted to the true secondaries carried
    into the fitted leaf's vein space (the nearest texel of a 384² grid of the texture's map)."""
    n = 384
    u, v = np.linspace(-1.0, 1.0, n), np.linspace(0.0, 1.0, n)
    x, y = pixel_positions(fit.parts, fit.pixel_from_leaf, u, v)
    tree = cKDTree(np.stack([x.ravel(), y.ravel()], axis=1))
    neg, pos = side_parts(fit.parts)
    tables = {-1: halfwidth_table(neg), 1: halfwidth_table(pos)}
    lines: dict[int, list[np.ndarray]] = {-1: [], 1: []}
    for line, side in zip(sp.secondaries, sp.secondary_sides, strict=True):
        _, i = tree.query(line)
        q = vein_space_of(tables[side], np.stack([np.tile(u, n)[i], np.repeat(v, n)[i]], axis=1))
        lines[side].append(q * [side, 1.0])
    thetas, curvs = np.radians(np.arange(10.0, 85.1, 1.0)), np.arange(0.0, 1.001, 0.05)
    out = {}
    for side in (-1, 1):
        m = family_misfit(lines[side], _row_w(tables[side]), thetas, curvs)
        a, b = np.unravel_index(int(np.argmin(m)), m.shape)
        out[side] = (math.degrees(thetas[a]), float(curvs[b]), float(m[a, b]))
    return out


@pytest.fixture(scope="module")
def tree_fits() -> list[tuple[SyntheticPhoto, ImageFit]]:
    out = []
    for seed in TREE_SEEDS:
        sp = synthetic_photo(seed, size=SIZE, veins="tree")
        out.append((sp, fit_image(sp.image, dpi=sp.dpi, face="up")))   # the generator's frame, unmirrored
    return out


# -- the family of curves is H1's vein tree --------------------------------------------------------------
def test_the_family_is_the_vein_trees_secondaries():
    """The closed-form secondaries (:mod:`leafview.fit.vein_family`) lie on the traced
    ones of :func:`leafview.botany.venation.vein_tree` (irregularity 0): the misfit at the true
    (θ, c) is a small fraction of the length, and the best of a grid is the true one."""
    base = load_params(builtin_presets()["elliptic"])
    for angle, curvature in ((50.0, 0.4), (35.0, 0.0), (65.0, 0.7)):
        params = base.replace(venation=Venation(enabled=True, angle=angle, curvature=curvature, irregularity=0.0,
                                                loop=0.0, tertiary=0.0, secondaries=8))
        veins = [v for v in vein_tree(params) if v.order == 2 and v.parent == 0]
        w = _row_w(halfwidth_table(params))
        for side in (-1, 1):
            lines = [vein_space(params, v.uv) * [side, 1.0] for v in veins if np.sign(v.uv[-1, 0]) == side]
            at_truth = family_misfit(lines, w, np.radians([angle]), np.array([curvature]))[0, 0]
            assert at_truth < 2e-3
            thetas, curvs = np.radians(np.arange(20.0, 80.1, 1.0)), np.arange(0.0, 1.001, 0.05)
            m = family_misfit(lines, w, thetas, curvs)
            a, b = np.unravel_index(int(np.argmin(m)), m.shape)
            assert abs(math.degrees(thetas[a]) - angle) <= 2.0 and abs(curvs[b] - curvature) <= 0.1


def test_reach_is_the_straight_veins_length_to_the_margin():
    w = np.full(RIDGE_ROWS, 0.3)                    # a strip 0.3 wide each side
    ell = reach(w, np.array([0.2, 0.3, 0.7]), np.radians([30.0, 90.0 - 1e-9]))
    np.testing.assert_allclose(ell[0], [0.6, 0.6, 0.3 / math.cos(math.radians(30.0))], atol=0.02)   # margin, v = 1
    np.testing.assert_allclose(ell[1], [0.3, 0.3, 0.3], atol=0.02)


# -- photos with veins ------------------------------------------------------------------------------------
def test_secondaries_recovered_from_tree_photos(tree_fits):
    """On 12 seeded photos, at least 8 show their veins; on every one that does, the angle is
    within 8° of the truth (both sides) and the count per side within 2 of the tree's."""
    visible = 0
    errors = []
    for sp, fit in tree_fits:
        est = fit.report["veins"]
        if est["status"] == NOT_VISIBLE:
            assert not fit.parts[0].venation.enabled and est["reason"]
            continue
        visible += 1
        truth = truth_in_fitted_space(sp, fit)
        counts = sp.truth["veins"]["secondaries_per_side"]
        for side in (-1, 1):
            got = est["sides"][f"{side:+d}"]
            errors.append(abs(got["angle"] - truth[side][0]))
            assert abs(got["angle"] - truth[side][0]) <= ANGLE_TOL, (sp.truth["seed"], side, got, truth[side])
            assert abs(got["secondaries"] - counts[f"{side:+d}"]) <= COUNT_TOL, (sp.truth["seed"], side, got)
        ven = fit.parts[0].venation
        assert ven.enabled and ven.pattern == "pinnate" and ven.tertiary == 0.0
        assert abs(ven.angle - np.mean([truth[s][0] for s in (-1, 1)])) <= ANGLE_TOL
        check_veins(fit.parts[0])
        assert len(vein_tree(fit.parts[0])) > 2 * ven.secondaries
    assert visible >= 8
    assert np.median(errors) <= 3.0


def test_polarity_and_loops_are_read(tree_fits):
    """Darker veins are found as darker, lighter ones as lighter; looping veins report a loop
    near where they turn and veins that reach the margin report none (most photos)."""
    right_loop = total = 0
    for sp, fit in tree_fits:
        est = fit.report["veins"]
        if est["status"] == NOT_VISIBLE:
            continue
        assert est["polarity"] == ("darker" if sp.truth["veins"]["dark"] else "lighter")
        loop = sp.truth["veins"]["venation"]["loop"]
        total += 1
        right_loop += (abs(est["loop"] - loop) <= 0.15) if loop > 0.0 else (est["loop"] == 0.0)
    assert right_loop >= 0.75 * total


def test_a_plain_blade_shows_no_veins():
    for seed in PLAIN_SEEDS:
        sp = synthetic_photo(seed, size=SIZE, veins="none")
        fit = fit_image(sp.image, dpi=sp.dpi)
        assert all(not p.venation.enabled for p in fit.parts)
        assert fit.report["veins"]["status"] == NOT_VISIBLE and fit.report["veins"]["reason"]


def test_veins_that_follow_no_tree_are_not_invented():
    """Random ridges (noise on a plain blade) never make a vein tree."""
    rng = np.random.default_rng(5)
    texture = np.ones((256, 256, 4), np.float32)
    texture[..., :3] = 0.3 + 0.05 * rng.standard_normal((256, 256, 3)).astype(np.float32)
    est = detect_veins(texture, (load_params(builtin_presets()["ovate"]),))
    assert not est.visible and est.venation().enabled is False
    assert est.report()["status"] == NOT_VISIBLE


def test_ridge_detection_at_the_texture_size_is_repeatable(tree_fits):
    """At the fit's texture size (512²) the detection gives the same estimate every time (its
    speed is a figure of ``leafview bench fit``, the ``veins`` stage, not asserted here)."""
    sp, fit = tree_fits[0]
    first = detect_veins(fit.texture, fit.parts)
    again = detect_veins(fit.texture, fit.parts)
    assert fit.texture.shape[0] == 512 and first.seconds > 0.0
    assert {k: v for k, v in first.report().items() if k != "seconds"} == \
        {k: v for k, v in again.report().items() if k != "seconds"}


def test_vein_image_and_ridges(tree_fits):
    sp, fit = tree_fits[0]
    image = vein_image(fit.texture, fit.parts)
    assert image.grey.shape == image.alpha.shape and image.rows == RIDGE_ROWS
    lighter, darker, inside = ridge_maps(image)
    assert lighter.shape == image.grey.shape and (lighter >= 0).all() and (darker >= 0).all()
    assert not lighter[~inside].any() and not darker[~inside].any()
    assert MAX_MISFIT > 0.0


def test_bad_input_names_the_field():
    with pytest.raises(ParamError, match="texture"):
        detect_veins(np.zeros((8, 8, 3), np.float32), (load_params(builtin_presets()["ovate"]),))
    with pytest.raises(ParamError, match="veins"):
        synthetic_photo(1, size=(200, 200), veins="bogus")
    with pytest.raises(ParamError, match="veins"):
        synthetic_photo(1, size=(200, 200), veins="tree", kind="landmark")


# -- the synthetic photos ----------------------------------------------------------------------------------
def test_tree_photos_are_seeded_and_carry_their_truth():
    a = synthetic_photo(7, size=(400, 400), veins="tree")
    b = synthetic_photo(7, size=(400, 400), veins="tree")
    assert np.array_equal(a.image, b.image)
    truth = a.truth["veins"]
    assert truth["mode"] == "tree" and truth["venation"]["pattern"] == "pinnate"
    assert len(a.secondaries) == sum(truth["secondaries_per_side"].values()) == len(a.secondary_sides)
    assert a.truth["width_factor"] == 1.0 and a.truth["kind"] in ("preset", "serrated")


def test_the_default_photos_are_unchanged_by_the_vein_option():
    """``veins="procedural"`` (the default, what ``leafview bench fit`` draws) gives the same bytes
    as before the option existed, and a plain blade differs only on the blade."""
    default = synthetic_photo(1503, size=(400, 400))
    same = synthetic_photo(1503, size=(400, 400), veins="procedural")
    plain = synthetic_photo(1503, size=(400, 400), veins="none")
    assert np.array_equal(default.image, same.image) and default.truth["veins"] == {"mode": "procedural"}
    assert np.array_equal(default.mask, plain.mask)
    assert not np.array_equal(default.image, plain.image)
