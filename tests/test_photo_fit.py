"""``leafview.fit.fit_image``: Ω, frame, scale and texture from synthetic leaf photos with a known
truth (:mod:`leafview.fit.synthetic_photos`).

Most fits here are given the true base and apex (``base=``, ``apex=``), so that they measure this
module's part (the frame, Ω, the texture) and not the landmark detection, which has tests of its own.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from skimage.draw import polygon as sk_polygon

from leafview.core.texture import texture_st, uv_of_st
from leafview.deform.surface import evaluate
from leafview.errors import ParamError
from leafview.fit import ImageFit, fit_image
from leafview.fit.photo import METRES_PER_INCH, canonical_frame, outline_sides, polygon_mask, top_view_iou
from leafview.fit.photo_texture import flat_top_view
from leafview.fit.synthetic_photos import SyntheticPhoto, synthetic_photo, write_photo

SIZE = (600, 600)
CASES = {"preset": (3, "preset", True), "asymmetric": (2, "asymmetric", False), "serrated": (5, "serrated", False)}
TEXTURE = 128


@pytest.fixture(scope="module")
def photos() -> dict[str, SyntheticPhoto]:
    return {name: synthetic_photo(seed, size=SIZE, kind=kind, petiole=petiole)
            for name, (seed, kind, petiole) in CASES.items()}


@pytest.fixture(scope="module")
def fits(photos: dict[str, SyntheticPhoto]) -> dict[str, ImageFit]:
    """Each photo fitted with its true base and apex."""
    return {name: fit_image(sp.image, base=sp.base, apex=sp.apex, dpi=sp.dpi, texture_size=TEXTURE, name=name)
            for name, sp in photos.items()}


def _truth_iou(fit: ImageFit, sp: SyntheticPhoto) -> float:
    return top_view_iou(fit.margin_pixels(), polygon_mask(sp.outline, sp.blade.shape))


# -- the outline and the frame ------------------------------------------------------------------------
@pytest.mark.parametrize("name, least", [("preset", 0.97), ("asymmetric", 0.97), ("serrated", 0.93)])
def test_the_fitted_top_view_covers_the_true_leaf(photos, fits, name, least):
    fit, sp = fits[name], photos[name]
    assert _truth_iou(fit, sp) >= least
    assert fit.report["iou"] >= least                      # against the traced mask, as the report says
    assert 0.0 < fit.report["hausdorff_pct"] < 8.0


def test_the_landmarks_given_make_the_canonical_frame(photos, fits):
    fit, sp = fits["preset"], photos["preset"]
    np.testing.assert_allclose(fit.report["base_px"], sp.base, atol=1e-3)
    np.testing.assert_allclose(fit.report["apex_px"], sp.apex, atol=1e-3)
    m = fit.leaf_from_pixel
    np.testing.assert_allclose(m[:2, :2] @ sp.base + m[:2, 2], [0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(m[:2, :2] @ sp.apex + m[:2, 2], [0.0, 1.0], atol=1e-9)
    assert fit.report["length_px"] == pytest.approx(sp.length_px, rel=1e-6)


def test_the_frame_keeps_left_and_right_as_the_camera_saw_them():
    """On screen (pixel y down), the side of the midrib to the right of someone walking from base to
    apex is the direction (-d_y, d_x): it must come out at x > 0, as seen from above (the frame
    flips pixel y, it does not mirror the leaf)."""
    for base, apex in (((100.0, 500.0), (100.0, 100.0)), ((0.0, 0.0), (300.0, 400.0)), ((50.0, 20.0), (-10.0, 5.0))):
        b, a = np.array(base), np.array(apex)
        d = a - b
        right = np.array([-d[1], d[0]])
        m = canonical_frame(b, a)
        np.testing.assert_allclose(m @ [*(b + 0.5 * d + 0.2 * right), 1.0], [0.2, 0.5, 1.0], atol=1e-12)
        assert np.linalg.det(m[:2, :2]) < 0.0      # a reflection of pixel coordinates: y runs down in them


def test_outline_sides_run_from_base_to_apex():
    t = np.linspace(0.0, 2.0 * np.pi, 200, endpoint=False)
    ring = np.stack([0.3 * np.sin(t), 0.5 - 0.5 * np.cos(t)], axis=1)     # counter-clockwise from the base
    for pts in (ring, ring[::-1]):
        right, left = outline_sides(pts)
        for side in (right, left):
            np.testing.assert_allclose(side[0], [0.0, 0.0])
            np.testing.assert_allclose(side[-1], [0.0, 1.0])
        assert right[1:-1, 0].min() > 0.0 and left[1:-1, 0].max() < 0.0


# -- symmetric or two halves ---------------------------------------------------------------------------
def test_an_asymmetric_leaf_gets_two_one_sided_halves(photos, fits):
    fit = fits["asymmetric"]
    assert fit.asymmetric and fit.report["asymmetric"] and fit.report["sides_differ"]
    assert [p.shape.half for p in fit.parts] == [-1, 1]
    assert [p.name for p in fit.parts] == ["asymmetric (right)", "asymmetric (left)"]
    assert fit.report["halves_error_pct"] < fit.report["symmetric_error_pct"]
    one = fit_image(photos["asymmetric"].image, base=photos["asymmetric"].base, apex=photos["asymmetric"].apex,
                    texture_size=16, halves=False)
    assert len(one.parts) == 1 and one.parts[0].shape.half == 0 and one.report["sides_differ"]
    assert any("sides differ" in w for w in one.warnings)
    assert _truth_iou(one, photos["asymmetric"]) < _truth_iou(fit, photos["asymmetric"])


def test_a_symmetric_leaf_stays_one_leaf(fits):
    fit = fits["preset"]
    assert len(fit.parts) == 1 and not fit.report["sides_differ"] and fit.parts[0].shape.half == 0


def test_row_residuals_are_per_silhouette_row(fits):
    for fit in fits.values():
        assert fit.report["rows"] == [p.shape.rows for p in fit.parts]
        for part, residuals in zip(fit.parts, fit.report["row_residuals"]):
            assert len(residuals) == part.shape.rows
            assert all(0.0 <= r <= fit.report["hausdorff_pct"] for r in residuals)
            assert max(residuals) > 0.0


# -- petiole and scale ---------------------------------------------------------------------------------------
def test_the_petiole_becomes_the_petiole_length(fits):
    for fit in fits.values():
        pet = fit.outline.petiole
        expected = float(np.sum(np.hypot(*np.diff(pet, axis=0).T))) / fit.report["length_px"] if len(pet) > 1 else 0.0
        for part in fit.parts:
            assert part.bending.petiole_length == pytest.approx(expected, abs=1e-4)
            assert part.bending.load == 0.0 and part.bending.twist == 0.0


def test_the_scale_is_the_length_in_metres_from_the_files_resolution(photos, tmp_path):
    sp = photos["preset"]
    path = write_photo(sp, tmp_path / "leaf.png")
    fit = fit_image(path, base=sp.base, apex=sp.apex, texture_size=16)
    assert fit.report["dpi"] == pytest.approx(sp.dpi)
    assert fit.parts[0].transform.scale == pytest.approx(sp.length_px / sp.dpi * METRES_PER_INCH, rel=1e-6)
    assert fit.parts[0].transform.scale == pytest.approx(sp.truth["leaf_cm"] / 100.0, rel=1e-3)
    assert fit.parts[0].name == "leaf"                              # the file's stem
    given = fit_image(path, base=sp.base, apex=sp.apex, dpi=300, texture_size=16)
    assert given.parts[0].transform.scale == pytest.approx(sp.length_px / 300 * METRES_PER_INCH, rel=1e-6)
    bare = fit_image(sp.image, base=sp.base, apex=sp.apex, texture_size=16)   # an array: no resolution
    assert bare.parts[0].transform.scale == 1.0 and bare.report["dpi"] is None
    assert any("resolution" in w for w in bare.warnings)


# -- the texture ----------------------------------------------------------------------------------------------
def _texel_pixels(fit: ImageFit, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Photo pixels (x, y) of texel centres, computed here from the convention and the surface."""
    t = fit.texture.shape[0]
    s, tt = (cols + 0.5) / t, (rows + 0.5) / t
    u, v = uv_of_st(s, tt)
    np.testing.assert_allclose(np.stack(texture_st(u, v)), np.stack([s, tt]), atol=1e-12)
    xy = np.empty((len(u), 2))
    for part in fit.parts:
        side = np.ones(len(u), bool) if part.shape.half == 0 else (u < 0) if part.shape.half < 0 else (u >= 0)
        xy[side] = evaluate(flat_top_view(part), u[side], v[side])[:, :2]
    px = xy @ fit.pixel_from_leaf[:2, :2].T + fit.pixel_from_leaf[:2, 2]
    return px[:, 0], px[:, 1]


@pytest.mark.parametrize("name", ["preset", "asymmetric"])
def test_texture_alpha_is_the_mask_where_the_texel_falls(fits, name):
    fit = fits[name]
    rng = np.random.default_rng(1)
    rows, cols = rng.integers(0, TEXTURE, 4000), rng.integers(0, TEXTURE, 4000)
    x, y = _texel_pixels(fit, rows, cols)
    mask = fit.outline.mask
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    inside = (x0 >= 0) & (y0 >= 0) & (x0 + 1 < mask.shape[1]) & (y0 + 1 < mask.shape[0])
    x0, y0, rows, cols = x0[inside], y0[inside], rows[inside], cols[inside]
    inside = (x0 >= 1) & (y0 >= 1) & (x0 + 2 < mask.shape[1]) & (y0 + 2 < mask.shape[0])
    x0, y0, rows, cols = x0[inside], y0[inside], rows[inside], cols[inside]
    # the texel's pixel position is interpolated from a coarse grid of the surface (within a tenth
    # of a pixel): the pixels a bilinear sample may read, with that slack, are the 4 × 4 around it
    block = np.stack([mask[y0 + dy, x0 + dx] for dy in (-1, 0, 1, 2) for dx in (-1, 0, 1, 2)])
    uniform = block.all(axis=0) | ~block.any(axis=0)
    alpha = fit.texture[rows, cols, 3][uniform]
    expected = block[5][uniform].astype(np.float32)
    np.testing.assert_allclose(alpha, expected, atol=1e-5)
    assert (expected == 1.0).sum() > 1000 and (expected == 0.0).sum() >= 5   # both the leaf and cut-out margins


@pytest.mark.parametrize("name", ["preset", "asymmetric"])
def test_texture_colour_is_the_photo_at_the_mapped_pixel(fits, name):
    fit = fits[name]
    rows, cols = np.nonzero(fit.texture[..., 3] >= 1.0)
    pick = np.random.default_rng(2).choice(len(rows), 500, replace=False)
    rows, cols = rows[pick], cols[pick]
    x, y = _texel_pixels(fit, rows, cols)

    def photo_at(dx: float) -> np.ndarray:
        return np.stack([ndimage.map_coordinates(fit.photo.rgb[..., c], [y, x + dx], order=1) for c in range(3)], -1)

    # the texture's pixel positions are interpolated from a coarse grid of the surface (within a
    # tenth of a pixel here): equal up to that, and far closer than the photo one pixel aside
    error = np.abs(fit.texture[rows, cols, :3] - photo_at(0.0))
    aside = np.abs(fit.texture[rows, cols, :3] - photo_at(1.0))
    assert np.median(error) < 5e-4 and error.max() < 0.02
    assert np.median(aside) > 10 * np.median(error)


def test_transparent_texels_take_leaf_colours_not_the_papers(fits, photos):
    fit = fits["serrated"]
    tex = fit.texture
    solid = tex[..., 3] >= 1.0 - 1e-4
    assert solid.any() and (~solid).any()
    known = {tuple(c) for c in tex[solid][:, :3].round(6)}
    assert all(tuple(c) in known for c in tex[~solid][:, :3].round(6))
    paper = np.median(photos["serrated"].image.reshape(-1, 3), axis=0) / 255.0
    far = tex[~solid][:, :3]
    assert np.abs(far - paper).sum(axis=1).min() > 0.1


# -- bad input -------------------------------------------------------------------------------------------------
def test_a_photo_without_a_leaf_is_refused():
    with pytest.raises(ParamError, match="no leaf"):
        fit_image(synthetic_photo(1, size=SIZE, empty=True).image)


def test_two_touching_leaves_are_refused():
    with pytest.raises(ParamError, match="two touching"):
        fit_image(synthetic_photo(4, size=(500, 500), touching=True).image)


@pytest.mark.parametrize("kwargs, field", [({"texture_size": 8}, "texture_size"), ({"dpi": 0.0}, "dpi"),
                                           ({"target": -1.0}, "target"), ({"base": (10, 10), "apex": (10, 10)}, "apex")])
def test_bad_arguments_name_the_argument(photos, kwargs, field):
    with pytest.raises(ParamError, match=field):
        fit_image(photos["preset"].image, **kwargs)


def test_a_tiny_image_is_refused():
    with pytest.raises(ParamError):
        fit_image(np.zeros((8, 8, 3), np.uint8))


# -- the rasteriser --------------------------------------------------------------------------------------------
def test_polygon_mask_fills_the_pixel_centres_inside():
    rng = np.random.default_rng(3)
    for k in range(25):
        n = int(rng.integers(3, 50))
        angle = np.sort(rng.uniform(0, 2 * np.pi, n))
        radius = rng.uniform(3, 45, n)
        poly = np.stack([50 + radius * np.cos(angle) + rng.uniform(-30, 30), 40 + radius * np.sin(angle)], axis=1)
        poly = poly[::-1] if k % 2 else poly
        ref = np.zeros((80, 100), bool)
        rr, cc = sk_polygon(poly[:, 1], poly[:, 0], ref.shape)
        ref[rr, cc] = True
        assert np.array_equal(polygon_mask(poly, ref.shape), ref)
