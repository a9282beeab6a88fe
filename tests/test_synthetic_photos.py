"""The seeded synthetic leaf photographs (leafview.fit.synthetic_photos) that the photo fit's tests
and benchmark measure against: deterministic, their truth agrees with their pixels, leaves are
green and the paper and debris are not, the camera's JPEG is really applied, files carry the DPI,
and the bad-input variants (touching, empty, cut) are what they say.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from numpy.typing import NDArray
from scipy import ndimage
from skimage.draw import polygon

from leafview.errors import ImageWriteError, ParamError
from leafview.fit.synthetic_photos import (
    BACKGROUNDS,
    KINDS,
    SyntheticPhoto,
    coverage,
    synthetic_photo,
    write_photo,
    write_photo_set,
)

SIZE = (320, 288)          # (width, height): not square, so that a swapped axis shows


def _photo(seed: int, **options: object) -> SyntheticPhoto:
    return synthetic_photo(seed, size=SIZE, **options)  # type: ignore[arg-type]


def _excess_green(image: NDArray[np.uint8]) -> NDArray[np.float64]:
    """2g - r - b of the chromaticities (r = R / (R + G + B), ...): brightness does not count."""
    rgb = image.astype(np.float64) + 1.0
    rgb /= rgb.sum(axis=-1, keepdims=True)
    return 2.0 * rgb[..., 1] - rgb[..., 0] - rgb[..., 2]


def _raster(outline: NDArray[np.float64], shape: tuple[int, int]) -> NDArray[np.bool_]:
    """Pixels whose centres lie inside ``outline`` (x right, y down), by scikit-image."""
    out = np.zeros(shape, bool)
    rr, cc = polygon(outline[:, 1], outline[:, 0], shape)
    out[rr, cc] = True
    return out


def _iou(a: NDArray[np.bool_], b: NDArray[np.bool_]) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def _read(path: Path) -> tuple[NDArray[np.uint8], oiio.ImageSpec]:
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    pixels = inp.read_image("uint8")
    inp.close()
    return np.asarray(pixels), spec


# -- determinism -----------------------------------------------------------------------------------

def test_same_seed_same_bytes_other_seed_other_photo() -> None:
    a, b, c = _photo(11), _photo(11), _photo(12)
    assert a.image.shape == (SIZE[1], SIZE[0], 3) and a.image.dtype == np.uint8
    assert a.image.tobytes() == b.image.tobytes()
    assert np.array_equal(a.mask, b.mask) and np.array_equal(a.outline, b.outline)
    assert a.truth == b.truth
    assert a.image.tobytes() != c.image.tobytes()
    assert not np.array_equal(a.mask, c.mask)


def test_truth_is_json_and_names_the_drawn_leaf() -> None:
    for seed, kind in enumerate(KINDS):
        photo = _photo(20 + seed, kind=kind)
        truth = json.loads(json.dumps(photo.truth))
        assert truth["seed"] == 20 + seed and truth["kind"] == kind and truth["size"] == list(SIZE)
        assert truth["background"] in BACKGROUNDS and 70 <= truth["jpeg_quality"] <= 85
        assert truth["dpi"] == photo.dpi and photo.dpi == round(photo.dpi) > 0
        assert truth["face_down"] == photo.face_down
        short = min(SIZE)
        assert 0.35 * short - 1e-6 <= photo.length_px <= 0.8 * short + 1e-6


# -- the truth agrees with the pixels --------------------------------------------------------------

@pytest.mark.parametrize("kind", KINDS)
def test_blade_mask_matches_the_outline(kind: str) -> None:
    """The antialiased fill (thresholded at half coverage) and scikit-image's centre-sampled
    polygon of the true outline are the same region."""
    for seed in (1, 2):
        photo = _photo(seed, kind=kind)
        assert _iou(photo.blade, _raster(photo.outline, photo.blade.shape)) >= 0.98
        assert not np.any(photo.blade & ~photo.mask)


def test_coverage_is_the_exact_area() -> None:
    """A polygon's coverage sums to its area, whatever its orientation and position."""
    rng = np.random.default_rng(0)
    for _ in range(5):
        angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, 9))
        radius = rng.uniform(10.0, 30.0, 9)
        poly = np.stack([50.0 + radius * np.cos(angle), 40.0 + radius * np.sin(angle)], axis=1)
        area = 0.5 * abs(np.dot(poly[:, 0], np.roll(poly[:, 1], -1)) - np.dot(poly[:, 1], np.roll(poly[:, 0], -1)))
        for p in (poly, poly[::-1]):
            _, _, cov = coverage(p, 100, 100, sub=16)
            assert abs(float(cov.sum()) - area) < 0.002 * area
    r0, c0, cov = coverage(np.array([[-0.5, -0.5], [1.5, -0.5], [1.5, 0.5], [-0.5, 0.5]]), 10, 10)
    assert (r0, c0) == (0, 0) and np.allclose(cov, 1.0)          # pixel (0, 0) and (0, 1) exactly


@pytest.mark.parametrize("seed", [3, 4, 5, 6])
def test_base_and_apex_end_the_leaf_axis(seed: int) -> None:
    photo = _photo(seed, petiole=seed % 2 == 0)
    assert abs(np.hypot(*(photo.apex - photo.base)) - photo.length_px) < 1e-9
    # both lie on the outline (the outline runs base -> one side -> apex -> other side)
    for point in (photo.apex, photo.base):
        assert np.min(np.hypot(*(photo.outline - point).T)) < 1.0
    # the base is on the blade's boundary: blade pixels and background pixels within 2 px of it
    y, x = np.round(photo.base[::-1]).astype(int)
    window = photo.blade[y - 2:y + 3, x - 2:x + 3]
    assert window.any() and not window.all()
    if photo.petiole_px > 0:
        stalk = np.argwhere(photo.mask & ~photo.blade)[:, ::-1]
        assert len(stalk) > 0
        # the petiole starts at the base, and its far end lies petiole_px away from it, opposite the apex
        near = np.min(np.hypot(*(stalk - photo.base).T))
        assert near < 3.0
        far = stalk[np.argmax(np.hypot(*(stalk - photo.base).T))]
        assert abs(np.hypot(*(far - photo.base)) - photo.petiole_px) < 0.05 * photo.petiole_px + 3.0
        axis = (photo.apex - photo.base) / photo.length_px
        assert np.dot(far - photo.base, axis) < 0.0
    else:
        assert not np.any(photo.mask & ~photo.blade)


# -- colours -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("background", sorted(BACKGROUNDS))
def test_leaf_is_greener_than_the_paper(background: str) -> None:
    photo = _photo(30 + len(background), background=background)
    exg = _excess_green(photo.image)
    leaf = ndimage.binary_erosion(photo.blade, iterations=3)
    paper = ~ndimage.binary_dilation(photo.all_leaves, iterations=25)
    assert exg[leaf].mean() > exg[paper].mean() + 0.15
    r, g, b = photo.image[paper].mean(axis=0)
    assert g <= max(r, b) + 1.0                      # never green paper (cream is yellow: red > green)


def test_debris_are_not_green() -> None:
    """Dark specks off the leaves (debris: the paper's own grain is faint) are not green (green
    is never their largest channel) and far from the leaf's excess green."""
    found = 0
    for seed in range(40, 46):
        photo = _photo(seed)
        if sum(photo.truth["debris"].values()) == 0:
            continue
        exg = _excess_green(photo.image)
        lum = photo.image.astype(np.float64).mean(axis=2) / 255.0
        paper = ~ndimage.binary_dilation(photo.all_leaves, iterations=25)
        dark = paper & (lum < np.median(lum[paper]) - 0.3)
        if not dark.any():
            continue
        found += 1
        r, g, b = photo.image[dark].astype(np.float64).mean(axis=0)
        assert g <= max(r, b) + 2.0
        assert exg[dark].mean() < exg[ndimage.binary_erosion(photo.blade, iterations=3)].mean() - 0.15
    assert found >= 3


def test_face_down_is_paler() -> None:
    """Underside leaves (face_down) are lighter on average than upper sides."""
    up: list[float] = []
    down: list[float] = []
    for seed in range(60, 80):
        photo = synthetic_photo(seed, size=(160, 160), kind="preset")
        lum = float(photo.image[ndimage.binary_erosion(photo.blade, iterations=3)].mean())
        (down if photo.face_down else up).append(lum)
    assert up and down and np.mean(down) > np.mean(up) + 10.0


# -- the camera --------------------------------------------------------------------------------------

def test_jpeg_round_trip_is_applied_at_the_quality_asked() -> None:
    """Quality 0 skips the JPEG; any other quality gives exactly the raw photo encoded at that
    quality and decoded, further from the raw photo the lower the quality."""
    raw = _photo(7, jpeg_quality=0)
    assert raw.truth["jpeg_quality"] is None
    errors = {}
    for q in (60, 80, 95):
        photo = _photo(7, jpeg_quality=q)
        assert photo.truth["jpeg_quality"] == q
        assert np.array_equal(photo.mask, raw.mask)
        errors[q] = float(np.abs(photo.image.astype(int) - raw.image.astype(int)).mean())
        assert errors[q] > 0.0
    assert errors[60] > errors[80] > errors[95]
    by_default = _photo(7)
    assert 70 <= by_default.truth["jpeg_quality"] <= 85
    assert by_default.image.tobytes() == _photo(7, jpeg_quality=by_default.truth["jpeg_quality"]).image.tobytes()


# -- files ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("suffix", [".png", ".tif", ".jpg"])
def test_written_photo_carries_the_dpi(tmp_path: Path, suffix: str) -> None:
    photo = _photo(8)
    path = write_photo(photo, tmp_path / f"leaf{suffix}")
    pixels, spec = _read(path)
    assert spec.getattribute("XResolution") == pytest.approx(photo.dpi, rel=1e-3)
    assert spec.getattribute("YResolution") == pytest.approx(photo.dpi, rel=1e-3)
    assert str(spec.getattribute("ResolutionUnit")) in ("in", "inch")
    if suffix == ".jpg":    # encoded again at the photo's own quality: close to, not equal to, the image
        assert np.abs(pixels.astype(int) - photo.image.astype(int)).mean() < 3.0
    else:
        assert np.array_equal(pixels, photo.image)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]      # no temporary file left


def test_write_photo_refuses_an_unknown_type(tmp_path: Path) -> None:
    with pytest.raises(ImageWriteError, match=r"leaf\.bmp"):
        write_photo(_photo(8), tmp_path / "leaf.bmp")
    assert list(tmp_path.iterdir()) == []


def test_photo_set_writes_photos_and_truth(tmp_path: Path) -> None:
    paths = write_photo_set(tmp_path / "set", 3, 5, size=(200, 180), kind="serrated")
    assert [p.name for p in paths] == ["photo_0000.png", "photo_0001.png", "photo_0002.png"]
    doc = json.loads((tmp_path / "set" / "truth.json").read_text())
    assert [r["file"] for r in doc["photos"]] == [p.name for p in paths]
    for path, record in zip(paths, doc["photos"], strict=True):
        again = synthetic_photo(record["seed"], size=(200, 180), kind="serrated")
        pixels, spec = _read(path)
        assert np.array_equal(pixels, again.image)
        assert spec.getattribute("XResolution") == pytest.approx(record["dpi"])
        assert np.allclose(record["outline"], again.outline, atol=1e-3)
        assert record["base"] == pytest.approx(again.base, abs=1e-4)
        assert record["apex"] == pytest.approx(again.apex, abs=1e-4)
        assert record["length_px"] == again.length_px and record["petiole_px"] == again.petiole_px
        assert record["truth"]["kind"] == "serrated" and record["truth"]["serration"] is not None


def test_photo_set_with_a_bad_option_writes_nothing(tmp_path: Path) -> None:
    with pytest.raises(ParamError, match="kind"):
        write_photo_set(tmp_path / "set", 2, 0, kind="fern")
    assert not (tmp_path / "set").exists() or list((tmp_path / "set").iterdir()) == []


# -- the bad-input variants ----------------------------------------------------------------------------

def test_touching_leaves_overlap_a_little() -> None:
    for seed in (1, 2, 3):
        photo = _photo(seed, touching=True)
        (other,) = photo.truth["others"]
        second = _raster(np.array(other["outline"]), photo.blade.shape)
        shared = (photo.blade & second).sum()
        assert 0 < shared <= 0.06 * min(photo.blade.sum(), second.sum())
        # the two make one connected region of leaf pixels
        labels, count = ndimage.label(photo.blade | second)
        assert count == 1
        assert ((photo.blade | second) & ~photo.all_leaves).sum() <= 0.02 * second.sum()


def test_other_leaves_are_apart_and_smaller() -> None:
    photo = _photo(9, leaves=3, petiole=False)
    labels, count = ndimage.label(photo.all_leaves, np.ones((3, 3)))
    assert count == 3
    sizes = sorted(np.bincount(labels.ravel())[1:])
    assert photo.mask.sum() == sizes[-1]


def test_empty_page_has_paper_and_debris_only() -> None:
    photo = _photo(10, empty=True)
    assert not photo.mask.any() and not photo.blade.any() and not photo.all_leaves.any()
    assert photo.outline.shape == (0, 2) and np.all(np.isnan(photo.base)) and np.all(np.isnan(photo.apex))
    assert photo.truth["shadow"] is None
    smooth = ndimage.uniform_filter(_excess_green(photo.image), 9)
    assert smooth.max() < 0.08


@pytest.mark.parametrize("cut", ["left", "right", "top", "bottom"])
def test_cut_leaf_runs_off_its_border(cut: str) -> None:
    photo = _photo(12, cut=cut)
    w, h = SIZE
    axis = 0 if cut in ("left", "right") else 1
    border = {"left": photo.mask[:, 0], "right": photo.mask[:, -1], "top": photo.mask[0], "bottom": photo.mask[-1]}
    opposite = {"left": "right", "right": "left", "top": "bottom", "bottom": "top"}[cut]
    assert border[cut].any() and not border[opposite].any()
    coord = photo.outline[:, axis]
    beyond = -0.5 - coord.min() if cut in ("left", "top") else coord.max() - ((w, h)[axis] - 0.5)
    assert 0.1 * photo.length_px - 1e-6 <= beyond <= 0.25 * photo.length_px + 1e-6
    assert photo.truth["cut"] == cut


@pytest.mark.parametrize(("options", "field"), [
    ({"kind": "fern"}, "kind"), ({"background": "green"}, "background"), ({"jpeg_quality": 101}, "jpeg_quality"),
    ({"size": (8, 8)}, "size"), ({"leaves": 0}, "leaves"), ({"cut": "middle"}, "cut"),
    ({"touching": True, "cut": "left"}, "cut"), ({"empty": True, "touching": True}, "empty")])
def test_bad_options_name_the_field(options: dict[str, object], field: str) -> None:
    with pytest.raises(ParamError) as info:
        synthetic_photo(0, **options)  # type: ignore[arg-type]
    assert info.value.path == field
    with pytest.raises(ParamError, match="seed"):
        synthetic_photo(-1)
