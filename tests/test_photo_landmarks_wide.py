"""Base and apex on single leaves of the touching sweep (seeds 10000-10127 at 700 × 700, issue 15),
a wider set than the bench's, where three causes of misses were mended (measured 2026-12-03, the
JPEG round trip; each seed below missed 2 % of the length before):

* base and apex swapped on a blade without a petiole whose ends are alike, where the veins'
  sense was weaker than the clear level but its sign right (10072: base 99.5 %, now 0.38 %; 10078:
  101 %, now 0.58 %; 10118: 99.5 %, now 1.12 %);
* a petiole darker than the blade, of which the segmentation kept only a stub too long or too
  slowly joined by a narrow wedge base for the stub rule, whose end was taken for the base (10026:
  base 4.29 %, now 0.96 %; 10044: 6.24 %, now 1.15 %; 10089: 4.35 %, now 1.01 %);
* a petiole found as one whose width extrapolated back along the blade overshot a neck where the
  petiole joins the blade (10082: base 6.71 %, now 0.17 %)."""

from __future__ import annotations

import numpy as np
import pytest

from leafview.fit.photo_outline import leaf_outline
from leafview.fit.photo_shape import _against_veins, _hinge, _moments, _Petiole, _stub_root, _vein_sense
from leafview.fit.synthetic_photos import synthetic_photo, write_photo

SIZE = (700, 700)
SWAPPED = (10072, 10078, 10118)
STUB = (10026, 10044, 10089)
NECK = (10082,)


def _errors(seed: int, tmp_path) -> tuple[float, float]:
    """Base and apex distance from the truth (% of the length), traced from the photo's JPEG."""
    sp = synthetic_photo(seed, size=SIZE)
    outline = leaf_outline(write_photo(sp, tmp_path / "leaf.jpg"))
    return (100 * float(np.hypot(*(outline.base - sp.base))) / sp.length_px,
            100 * float(np.hypot(*(outline.apex - sp.apex))) / sp.length_px)


@pytest.mark.parametrize("seed", SWAPPED + STUB + NECK)
def test_wide_set_landmarks_are_found_within_two_percent(seed: int, tmp_path) -> None:
    base, apex = _errors(seed, tmp_path)
    assert base <= 2.0 and apex <= 2.0, (base, apex)


def test_the_hinge_splits_a_stub_from_the_blade() -> None:
    t = np.arange(0.0, 40.0, 0.5)
    w = np.where(t < 15.0, 3.0 + 0.02 * t, 3.3 + 0.8 * (t - 15.0))
    k, stub, blade = _hinge(t, w)
    assert abs(t[k] - 15.0) <= 1.0 and stub < 0.1 and abs(blade - 0.8) < 0.05, (t[k], stub, blade)


def _ring(corners: list[tuple[float, float]], step: float = 0.5) -> np.ndarray:
    pts = np.asarray(corners + corners[:1], float)
    out = [np.linspace(a, b, max(2, int(np.hypot(*(b - a)) / step)), endpoint=False) for a, b in zip(pts[:-1], pts[1:])]
    return np.vstack(out)


def test_a_stub_joined_by_a_slowly_widening_wedge_is_found() -> None:
    # a 3 px stub 30 px long, then a narrow wedge widening 0.6 px a px: the stub's end is not the base
    contour = _ring([(-30.0, -1.5), (0.0, -1.5), (100.0, -31.5), (300.0, -60.0), (500.0, 0.0),
                     (300.0, 60.0), (100.0, 31.5), (0.0, 1.5), (-30.0, 1.5)])
    root = _stub_root(contour, np.array([500.0, 0.0]), np.array([-30.0, 0.0]), 120.0, 1.0)
    assert root is not None and abs(root[0]) <= 3.0 and abs(root[1]) < 1.0, root


# A thin piece taken for a petiole where the veins clearly show the base lies elsewhere (a tooth or a
# sliver of shadow on the blade's side, the apex's own thin tip): base and apex were found across
# the blade or swapped (measured 2026-12-03, JPEG round trip: 10042 base 58.6 %, apex 57.8 %, now
# 1.0/1.0 %; 10063 base 46.7 %, now 3.1 % (still a miss, but at the right end); 10122 base 96.4 %,
# apex 99.3 %, now 0.7/0.5 %).
AGAINST_VEINS = (10042, 10122)


@pytest.mark.parametrize("seed", AGAINST_VEINS)
def test_a_petiole_against_the_veins_is_not_taken(seed: int, tmp_path) -> None:
    base, apex = _errors(seed, tmp_path)
    assert base <= 2.0 and apex <= 2.0, (base, apex)


def test_the_base_end_is_told_by_the_veins_where_a_petiole_lies_elsewhere(tmp_path) -> None:
    sp = synthetic_photo(10063, size=SIZE)
    outline = leaf_outline(write_photo(sp, tmp_path / "leaf.jpg"))
    assert float(np.hypot(*(outline.base - sp.base))) < 0.1 * sp.length_px
    assert float(np.hypot(*(outline.apex - sp.apex))) < 0.02 * sp.length_px


def _chevron_blade() -> tuple[np.ndarray, np.ndarray]:
    """An elliptic blade along x with chevron veins x = c + 0.8 |y - 60| (opening towards +x: the apex
    at the right)."""
    yy, xx = np.mgrid[:120, :240].astype(float)
    mask = ((xx - 120) / 100) ** 2 + ((yy - 60) / 40) ** 2 <= 1
    grey = (0.5 + 0.1 * np.cos(2 * np.pi * (xx - 0.8 * np.abs(yy - 60)) / 12)).astype(np.float32)
    return mask, grey


def _stalk(mask: np.ndarray, joint_x: float, outward: float) -> _Petiole:
    path = np.array([[joint_x + outward * (1 - t), 60.0] for t in np.linspace(0, 1, 11)])
    return _Petiole(path, np.ones(11), np.zeros_like(mask), 1.0, 10.0)


def test_a_petiole_is_checked_against_the_veins_sense() -> None:
    mask, grey = _chevron_blade()
    centre, axis, _ = _moments(mask)
    sense = _vein_sense(grey, mask, centre, axis)[0] * float(np.sign(axis[0]))
    assert sense > 0.1                                               # the apex lies at +x
    assert not _against_veins(_stalk(mask, 22.0, -10.0), mask, 1, grey)   # at the base's end
    assert _against_veins(_stalk(mask, 218.0, 10.0), mask, 1, grey)       # at the apex's end
    assert _against_veins(_stalk(mask, 120.0, 0.0), mask, 1, grey)        # mid-blade, on its side
    assert not _against_veins(_stalk(mask, 218.0, 10.0), mask, 1, None)   # no photo: no veins to go by
