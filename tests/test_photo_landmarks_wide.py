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
from leafview.fit.photo_shape import _hinge, _stub_root
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
