"""The leaf in a photograph (leafview.fit.photo_io, photo_outline, photo_shape): files read with
their DPI or refused cleanly, the leaf segmented from white and coloured paper with shadows and
debris, its outline smoothed faithfully, base, apex and petiole found, overrides honoured, a leaf
cut by the border warned about, and the bad inputs (no leaf, two touching leaves, an 8 × 8 px
image, a truncated file) refused naming the file.

The photos are the seeded synthetic ones of :mod:`leafview.fit.synthetic_photos` (1000 × 1000 px,
so segmented at half resolution), each made and traced once per session.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from leafview.errors import ParamError
from leafview.fit.photo_io import MAX_PHOTO_PIXELS, Photo, as_photo, read_photo
from leafview.fit.photo_outline import LeafOutline, _downscale, leaf_outline
from leafview.fit.photo_shape import eval_closed_bspline, fit_closed_bspline, split_shares
from leafview.fit.synthetic_photos import SyntheticPhoto, synthetic_photo

# (seed, background, kind, petiole): every paper but green, shadows and debris in all of them
Case = tuple[int, str | None, str | None, bool | None]
PETIOLED: list[Case] = [(0, "white", "landmark", True), (0, "white", "serrated", True), (1, "white", "serrated", True),
            (0, "pink", "preset", True), (1, "cream", "preset", True), (0, "blue", "serrated", True)]
BARE: list[Case] = [(14, None, None, None), (16, None, None, None)]       # no petiole: pink paper, blue paper


@cache
def _photo(seed: int, background: str | None, kind: str | None, petiole: bool | None) -> SyntheticPhoto:
    return synthetic_photo(seed, background=background, kind=kind, petiole=petiole)


@cache
def _traced(case: Case) -> LeafOutline:
    return leaf_outline(as_photo(_photo(*case).image))


def _iou(a: NDArray[np.bool_], b: NDArray[np.bool_]) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def _write(path: Path, pixels: NDArray[np.generic], **attributes: object) -> Path:
    h, w = pixels.shape[:2]
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    spec = oiio.ImageSpec(w, h, channels, "uint16" if pixels.dtype == np.uint16 else "uint8")
    for name, value in attributes.items():
        spec.attribute(name, value)
    data = np.ascontiguousarray(pixels.reshape(h, w, channels))   # OIIO 3.2 misreads a 2-D array
    out = oiio.ImageOutput.create(str(path))
    assert out is not None and out.open(str(path), spec) and out.write_image(data)
    assert out.close()
    return path


def _leaf_image(size: tuple[int, int] = (300, 400), centre: tuple[float, float] = (200, 150),
                radii: tuple[float, float] = (120, 50)) -> NDArray[np.uint8]:
    """A green ellipse on white paper (h, w, 3): a minimal leaf photo."""
    h, w = size
    yy, xx = np.mgrid[0:h, 0:w]
    inside = ((xx - centre[0]) / radii[0]) ** 2 + ((yy - centre[1]) / radii[1]) ** 2 <= 1
    img = np.full((h, w, 3), (235, 233, 228), np.uint8)
    img[inside] = (60, 120, 40)
    return img


# -- segmentation ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("case", PETIOLED + BARE)
def test_segments_the_leaf_from_paper_shadow_and_debris(case: Case) -> None:
    photo = _photo(*case)
    assert photo.truth["shadow"] and photo.truth["debris"], "the photo should carry a shadow and debris"
    traced = _traced(case)
    assert _iou(traced.mask, photo.mask) >= 0.97, (case, _iou(traced.mask, photo.mask))
    assert traced.method in ("exg-otsu", "lab-a-otsu")
    assert traced.cut_sides == ()


def test_yellow_paper_is_segmented_by_lab_a_and_an_autumn_leaf_by_excess_green() -> None:
    leaf = _leaf_image()
    truth = (leaf == (60, 120, 40)).all(axis=2)
    yellow = leaf.copy()
    yellow[~truth] = (245, 230, 100)                 # 2G-R-B 0.45: greener than the leaf's 0.43 ...
    yellow[truth] = (50, 110, 60)                    # ... but a* -10 against the leaf's -31
    on_yellow = leaf_outline(as_photo(yellow))
    assert on_yellow.method == "lab-a-otsu"
    autumn = leaf.copy()
    autumn[truth] = (205, 175, 50)                   # a yellow autumn leaf: a* > 0, 2G-R-B 0.37
    on_white = leaf_outline(as_photo(autumn))
    assert on_white.method == "exg-otsu"
    assert _iou(on_yellow.mask, truth) > 0.99 and _iou(on_white.mask, truth) > 0.99


# -- outline, base, apex, petiole -------------------------------------------------------------------------
@pytest.mark.parametrize("case", PETIOLED + BARE)
def test_base_and_apex_within_two_percent_of_the_length(case: Case) -> None:
    photo, traced = _photo(*case), _traced(case)
    length = photo.length_px
    assert np.hypot(*(traced.base - photo.base)) <= 0.02 * length, (traced.base, photo.base)
    assert np.hypot(*(traced.apex - photo.apex)) <= 0.02 * length, (traced.apex, photo.apex)


# leaves whose apex is not simply the farthest point along the principal axis: wider than long with
# a blunt apex (1501, 1517), an emarginate apex in a notch (1507), a notched apex and a petiole cut off
# by the border (1503: the veins, not the notch, tell the base), round and wider than long (3006, 3022)
AWKWARD: list[Case] = [(1501, "cream", "landmark", True), (1517, "blue", "landmark", True),
                       (1507, "blue", "asymmetric", True), (1503, "grey", "asymmetric", True),
                       (3006, "cream", "serrated", False), (3022, "blue", "serrated", False)]


@pytest.mark.parametrize("case", AWKWARD)
def test_the_apex_is_the_midribs_end_on_wide_notched_and_blunt_leaves(case: Case) -> None:
    photo, traced = _photo(*case), _traced(case)
    length = photo.length_px
    assert np.hypot(*(traced.apex - photo.apex)) <= 0.02 * length, (traced.apex, photo.apex)
    # the base at least on the right end (a petiole in a cordate notch can hide a few % of it)
    assert np.hypot(*(traced.base - photo.base)) <= 0.06 * length, (traced.base, photo.base)


@pytest.mark.parametrize("case", PETIOLED[:4])
def test_petiole_found_with_its_length(case: Case) -> None:
    photo, traced = _photo(*case), _traced(case)
    assert photo.petiole_px > 0
    assert len(traced.petiole) >= 2
    found = float(np.hypot(*np.diff(traced.petiole, axis=0).T).sum())
    assert abs(found / photo.petiole_px - 1) <= 0.10, (found, photo.petiole_px)
    assert np.allclose(traced.petiole[-1], traced.base)
    # the blade is the mask less the petiole
    assert not (traced.blade & ~traced.mask).any()
    assert _iou(traced.blade, photo.blade) >= 0.97


@pytest.mark.parametrize("case", BARE)
def test_no_petiole_is_reported_for_a_bare_blade(case: Case) -> None:
    assert _photo(*case).petiole_px == 0
    assert _traced(case).petiole.shape == (0, 2)


@pytest.mark.parametrize("case", [PETIOLED[0], PETIOLED[1], BARE[0]])
def test_outline_is_smooth_faithful_counter_clockwise_and_starts_at_the_base(
        case: Case) -> None:
    photo, traced = _photo(*case), _traced(case)
    outline = traced.outline
    assert 400 <= len(outline) <= 800 and np.isfinite(outline).all()
    x, y = outline.T
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) < 0      # counter-clockwise on screen (y down)
    assert np.hypot(*(outline[0] - traced.base)) <= 0.02 * photo.length_px
    dense_truth = np.vstack([np.linspace(a, b, 8, endpoint=False)
                             for a, b in zip(photo.outline, np.roll(photo.outline, -1, axis=0), strict=True)])
    hausdorff = max(cKDTree(dense_truth).query(outline)[0].max(), cKDTree(outline).query(dense_truth)[0].max())
    # the truth is sharper than the blurred photo: teeth and the tip are where the two part
    assert hausdorff <= 0.02 * photo.length_px, hausdorff / photo.length_px


def test_bspline_fit_is_within_tolerance_and_smooth() -> None:
    t = np.linspace(0, 2 * np.pi, 2000, endpoint=False)
    wobble = np.stack([300 * np.cos(t) + 4 * np.cos(9 * t), 120 * np.sin(t)], axis=1)
    controls, hausdorff = fit_closed_bspline(wobble, 0.5)
    assert hausdorff <= 0.5
    curve = eval_closed_bspline(controls, np.linspace(0, 1, 4000, endpoint=False))
    assert cKDTree(wobble).query(curve)[0].max() <= 0.6
    assert len(controls) < 400                                            # a control polygon, not the samples


# -- overrides -------------------------------------------------------------------------------------------
def test_base_and_apex_overrides_are_honoured() -> None:
    photo = as_photo(_leaf_image())
    traced = leaf_outline(photo, base=(90, 150), apex=(310.5, 152))
    assert np.array_equal(traced.base, [90, 150]) and np.array_equal(traced.apex, [310.5, 152])
    assert np.hypot(*(traced.outline[0] - traced.base)) < 15
    found = leaf_outline(photo)                       # a symmetric ellipse: either end, near the axis
    ends = sorted([found.base[0], found.apex[0]])
    assert abs(ends[0] - 80) < 3 and abs(ends[1] - 320) < 3
    assert abs(found.base[1] - 150) < 0.025 * 240 and abs(found.apex[1] - 150) < 0.025 * 240


@pytest.mark.parametrize(("field", "value"), [("--base", (400, 10)), ("--apex", (-3, 5)), ("--base", (1, np.nan)),
                                              ("--apex", (1, 2, 3))])
def test_an_override_outside_the_image_names_its_field(field: str, value: tuple[float, ...]) -> None:
    kwargs = {"base" if field == "--base" else "apex": value}
    with pytest.raises(ParamError) as err:
        leaf_outline(as_photo(_leaf_image()), **kwargs)
    assert err.value.path == field


# -- borders and bad input --------------------------------------------------------------------------------
@pytest.mark.parametrize(("seed", "side"), [(0, "left"), (2, "top")])
def test_a_leaf_cut_by_the_border_is_fitted_with_a_warning_naming_the_side(seed: int, side: str) -> None:
    photo = synthetic_photo(seed, cut=side, size=(640, 480))
    traced = leaf_outline(as_photo(photo.image))
    assert traced.cut_sides == (side,)
    assert any(side in w for w in traced.warnings)
    assert _iou(traced.mask, photo.mask) >= 0.97


def test_a_photo_with_no_leaf_is_refused_naming_the_file(tmp_path: Path) -> None:
    path = _write(tmp_path / "paper.png", synthetic_photo(3, empty=True, size=(640, 480)).image)
    with pytest.raises(ParamError, match="no leaf found") as err:
        leaf_outline(path)
    assert str(path) in str(err.value)
    speck = _leaf_image(radii=(6, 4))                 # far below 0.2 % of the image
    with pytest.raises(ParamError, match="no leaf found"):
        leaf_outline(as_photo(speck))


def test_two_touching_leaves_are_refused_naming_the_file(tmp_path: Path) -> None:
    path = _write(tmp_path / "two.jpg", synthetic_photo(0, touching=True).image)
    with pytest.raises(ParamError, match="two touching leaves") as err:
        leaf_outline(path)
    assert str(path) in str(err.value)


def test_lobed_serrated_and_petioled_single_leaves_are_not_taken_for_two() -> None:
    for case in PETIOLED + BARE:
        shares = split_shares(_traced(case).mask[::2, ::2])
        assert len(shares) == 1 or shares[1] < 0.25, (case, shares)
    yy, xx = np.mgrid[0:300, 0:300]
    r, a = np.hypot(xx - 150, yy - 150), np.arctan2(yy - 150, xx - 150)
    lobed = r < 90 + 30 * np.cos(5 * a)               # five deep lobes
    assert split_shares(lobed) == [1.0]
    pair = (np.hypot(xx - 90, yy - 150) < 60) | (np.hypot(xx - 205, yy - 150) < 56)   # two discs that just touch
    shares = split_shares(pair)
    assert len(shares) == 2 and shares[1] >= 0.4


def test_an_8_by_8_image_is_refused_naming_the_file(tmp_path: Path) -> None:
    path = _write(tmp_path / "tiny.png", np.full((8, 8, 3), 90, np.uint8))
    with pytest.raises(ParamError, match="8×8 px") as err:
        read_photo(path)
    assert str(path) in str(err.value)
    with pytest.raises(ParamError, match="image: .*8×8 px"):
        as_photo(np.zeros((8, 8, 3), np.uint8))


@pytest.mark.parametrize("suffix", [".png", ".jpg", ".tif"])
def test_a_truncated_file_is_refused_naming_the_file(tmp_path: Path, suffix: str) -> None:
    whole = _write(tmp_path / f"whole{suffix}", _leaf_image())
    data = whole.read_bytes()
    cut = tmp_path / f"cut{suffix}"
    cut.write_bytes(data[:len(data) // 2])
    with pytest.raises(ParamError, match="cannot be read in full") as err:
        read_photo(cut)
    assert str(cut) in str(err.value)


def test_files_that_are_not_photos_are_refused(tmp_path: Path) -> None:
    (tmp_path / "junk.png").write_bytes(b"not an image at all")
    for path, message in [(tmp_path / "junk.png", "not an image"), (tmp_path / "missing.png", "no such file"),
                          (tmp_path, "not a regular file")]:
        with pytest.raises(ParamError, match=message) as err:
            read_photo(path)
        assert str(path) in str(err.value)


# -- files and arrays -------------------------------------------------------------------------------------
def test_dpi_is_read_back_from_tiff_and_png(tmp_path: Path) -> None:
    img = _leaf_image()
    tif = _write(tmp_path / "scan.tif", img, XResolution=118.11, YResolution=118.11, ResolutionUnit="cm")
    png = _write(tmp_path / "photo.png", img, XResolution=300.0, YResolution=300.0, ResolutionUnit="in")
    bare = _write(tmp_path / "bare.png", img)
    assert read_photo(tif).dpi == pytest.approx(300.0, rel=1e-4)
    assert read_photo(png).dpi == pytest.approx(300.0, rel=1e-4)
    assert read_photo(bare).dpi is None
    photo = read_photo(png)
    assert photo.path == str(png) and photo.rgb.dtype == np.float32 and photo.rgb.shape == (300, 400, 3)
    assert np.allclose(photo.rgb[150, 200], np.array([60, 120, 40]) / 255, atol=1e-6)


def test_16_bit_grey_and_rgba_files_and_arrays_become_srgb_floats(tmp_path: Path) -> None:
    img = _leaf_image()
    wide = img.astype(np.uint16) * 257
    assert np.allclose(read_photo(_write(tmp_path / "deep.tif", wide)).rgb, img / 255, atol=1e-6)
    grey = read_photo(_write(tmp_path / "grey.png", img[:, :, 1])).rgb
    assert np.array_equal(grey[..., 0], grey[..., 2]) and np.allclose(grey[..., 1], img[:, :, 1] / 255)
    rgba = np.dstack([img, np.zeros(img.shape[:2], np.uint8)])
    rgba[100:200, 100:300, 3] = 255
    over_white = as_photo(rgba).rgb                          # transparent: white paper
    assert np.allclose(over_white[0, 0], 1.0) and np.allclose(over_white[150, 200], img[150, 200] / 255)
    assert np.allclose(as_photo(img.astype(np.float64) / 255).rgb, img / 255, atol=1e-6)
    assert as_photo(img).dpi is None and as_photo(img).path == ""
    same = Photo(rgb=over_white, dpi=72.0, path="x.png")
    assert as_photo(same) is same
    for bad in (img.astype(np.int32), img.astype(bool), img[:, :, :2], img.astype(np.float32) * 1.0):
        if bad.dtype == np.float32:
            with pytest.raises(ParamError, match="must lie in \\[0, 1\\]"):
                as_photo(bad)
        else:
            with pytest.raises(ParamError):
                as_photo(bad)


def test_photos_above_the_pixel_limit_are_refused_before_reading(tmp_path: Path) -> None:
    side = int(np.sqrt(MAX_PHOTO_PIXELS)) + 16
    spec = oiio.ImageSpec(side, side, 1, "uint8")
    path = tmp_path / "huge.tif"
    out = oiio.ImageOutput.create(str(path))
    spec.attribute("Compression", "zip")
    assert out is not None and out.open(str(path), spec)
    assert out.write_image(np.zeros((side, side, 1), np.uint8)) and out.close()
    with pytest.raises(ParamError, match="larger than the 50 MP") as err:
        read_photo(path)
    assert str(path) in str(err.value)


def test_downscale_is_area_averaging_including_partial_blocks() -> None:
    rng = np.random.default_rng(1)
    rgb = rng.random((23, 31, 3)).astype(np.float32)
    for f in (2, 3, 7):
        small = _downscale(rgb, f)
        assert small.shape == (-(-23 // f), -(-31 // f), 3)
        for i, j in ((0, 0), (small.shape[0] - 1, small.shape[1] - 1), (1, small.shape[1] - 1)):
            block = rgb[i * f:(i + 1) * f, j * f:(j + 1) * f].reshape(-1, 3)
            assert np.allclose(small[i, j], block.mean(axis=0), atol=1e-6)


def test_a_large_photo_is_traced_in_full_resolution_pixels() -> None:
    photo = synthetic_photo(0, kind="landmark", petiole=True, size=(2400, 1800))    # 4.3 MP: segmented at 1/4
    traced = leaf_outline(as_photo(photo.image))
    assert traced.mask.shape == (1800, 2400)
    assert _iou(traced.mask, photo.mask) >= 0.97
    assert np.hypot(*(traced.base - photo.base)) <= 0.02 * photo.length_px
    assert np.hypot(*(traced.apex - photo.apex)) <= 0.02 * photo.length_px
