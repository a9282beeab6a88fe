"""Base and apex on the bench's hard photos (issue 15): a petiole running into a long narrow
wedge-shaped base, and thin tips that the segmentation cuts short. Each seed below missed 2 % of
the length before the base was extrapolated along the blade's width profile and the tip along its
taper (measured 2026-12-03: seed 1513 base 2.06 %, 3001 base 9.66 % and apex 2.26 %, 3004 apex
2.83 %, 3019 base 5.06 %); and a petiole stub too short to be found as a petiole, whose end was
taken for the base before its root was looked for (seed 3003: base 3.06 %, now 0.61 %), and a
long concave drip tip whose last pixels are fainter than the threshold, now followed along its
faint trace (seed 1520: apex 3.53 %, now 1.64 %; the narrow leaf 3013's apex 2.14 %, now 0.33 %,
its base still 2.08 %). A petiole lying in a narrow cordate sinus whose walls meet over it beyond
where the mask shows, followed by its colour to its end (seed 1501: base 5.20 %, now 0.93 %; 3005:
6.19 %, now 1.55 %); an oblique truncate base whose corner lies farthest from the apex (seed 10067
of the touching sweep's single leaves, 700 × 700: base 30.1 %, now 2.79 %); and a round blade whose
one deep sinus lies off both principal axes (3007: base 43.7 %, now 3.84 %; apex 36.4 %, now 7.88 %)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from leafview.bench.fit_photo import SIZE, _options
from leafview.fit.photo_io import as_photo
from leafview.fit.photo_outline import _Channels, _faint_tip, leaf_outline
from leafview.fit.photo_shape import TIP_MAX, _lone_sinus, _ray_exit, _stub_root, _taper_tip, leaf_shape
from leafview.fit.synthetic_photos import synthetic_photo, write_photo

# seed: the photo's place in its bench set (the bench's kinds, papers and petioles go by it)
HARD = {1513: 13, 1520: 20, 3001: 1, 3003: 3, 3004: 4, 3019: 19}


@pytest.mark.parametrize("seed", sorted(HARD))
def test_hard_landmarks_are_found_within_two_percent(seed, tmp_path) -> None:
    sp = synthetic_photo(seed, size=SIZE, **_options(HARD[seed]))
    outline = leaf_outline(write_photo(sp, tmp_path / "leaf.jpg"))    # the bench's JPEG round trip
    base = 100 * float(np.hypot(*(outline.base - sp.base))) / sp.length_px
    apex = 100 * float(np.hypot(*(outline.apex - sp.apex))) / sp.length_px
    assert base <= 2.0 and apex <= 2.0, (base, apex)


def test_the_narrow_leaf_s_apex_is_found_within_two_percent(tmp_path) -> None:
    sp = synthetic_photo(3013, size=SIZE, **_options(13))
    outline = leaf_outline(write_photo(sp, tmp_path / "leaf.jpg"))
    assert 100 * float(np.hypot(*(outline.apex - sp.apex))) / sp.length_px <= 2.0


def _errors(sp, tmp_path) -> tuple[float, float]:
    """The base's and the apex's distance from the truth (% of the length), traced from the JPEG."""
    outline = leaf_outline(write_photo(sp, tmp_path / "leaf.jpg"))
    return (100 * float(np.hypot(*(outline.base - sp.base))) / sp.length_px,
            100 * float(np.hypot(*(outline.apex - sp.apex))) / sp.length_px)


def test_a_petiole_hidden_in_a_narrow_cordate_sinus_is_followed_to_its_end(tmp_path) -> None:
    # the lobes close over the petiole's last 5-6 % of the length: the mask ends where they touch it
    base, apex = _errors(synthetic_photo(1501, size=SIZE, **_options(1)), tmp_path)
    assert base <= 2.0 and apex <= 2.0, (base, apex)
    base, apex = _errors(synthetic_photo(3005, size=SIZE, **_options(5)), tmp_path)
    assert base <= 2.0 and apex <= 2.0, (base, apex)


def _sinus_leaf(petiole_rgb: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """(mask, RGB) of a disc blade (radius 100 round (150, 170)) with a narrow V-shaped sinus from its
    top down to (150, 130), and a petiole 7 px wide along x = 150 from y = 10 to 140 drawn under the
    blade: the sinus is narrower than the petiole from y = 107.5 on, so the mask shows no notch there."""
    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[:300, :300].astype(float)
    blade = (np.hypot(xx - 150, yy - 170) <= 100) & ~((yy < 130) & (np.abs(xx - 150) < 8 * (130 - yy) / 60))
    petiole = (np.abs(xx - 150) <= 3) & (yy >= 10) & (yy <= 140)
    rgb = np.full((300, 300, 3), 0.9)
    rgb[petiole] = petiole_rgb
    rgb[blade] = np.array([0.2, 0.5, 0.2]) * (1 + 0.15 * rng.standard_normal((int(blade.sum()), 1)))
    return blade | petiole, rgb


def test_a_petiole_s_colour_is_followed_into_the_sinus_only_where_it_differs_from_the_blade() -> None:
    mask, rgb = _sinus_leaf((0.35, 0.25, 0.1))
    assert leaf_shape(mask).base[1] < 110                      # the mask alone: where the lobes touch it
    base = leaf_shape(mask, colour=rgb).base
    assert abs(base[0] - 150) <= 2 and 124 <= base[1] <= 131, base
    mask, rgb = _sinus_leaf((0.2, 0.5, 0.2))                   # a petiole of the blade's colour: not followed
    assert leaf_shape(mask, colour=rgb).base[1] < 110


def test_an_oblique_truncate_base_is_the_midribs_end_not_its_corner(tmp_path) -> None:
    # an asymmetric blade whose truncate base runs obliquely to the midrib, its faint petiole not traced
    base, apex = _errors(synthetic_photo(10067, size=(700, 700)), tmp_path)
    assert base <= 3.0 and apex <= 2.0, (base, apex)


def test_a_round_blade_s_one_deep_sinus_is_its_base(tmp_path) -> None:
    # a round blade (principal standard deviations within 16 %) with a cordate sinus off both
    # principal axes and a petiole too faint to be traced: the axis ran across it (base 43.7 %,
    # apex 36.4 % off); the sinus is the base now, the apex the midrib's end seen from it (a blunt
    # end, so only within 10 %)
    base, apex = _errors(synthetic_photo(3007, size=SIZE, **_options(7)), tmp_path)
    assert base <= 5.0 and apex <= 10.0, (base, apex)


def test_one_sinus_is_found_and_lobes_or_a_shallow_notch_are_not() -> None:
    t = np.linspace(0.0, 2 * math.pi, 720, endpoint=False)
    disc = np.stack([100 * np.cos(t), 100 * np.sin(t)], axis=1)

    def notched(at: list[float], depth: float) -> np.ndarray:
        r = np.ones_like(t)
        for a in at:
            gap = np.abs(np.angle(np.exp(1j * (t - a))))
            r -= depth * np.clip(1 - gap / 0.3, 0, None)             # a V-shaped notch 0.6 rad wide
        return disc * r[:, None]

    one = notched([1.0], 0.3)
    sinus = _lone_sinus(one, ConvexHull(one).equations, 200.0)
    assert sinus is not None and np.allclose(sinus, [70 * math.cos(1.0), 70 * math.sin(1.0)], atol=1.0), sinus
    two = notched([1.0, 1.0 + math.pi], 0.3)                         # lobes, not one sinus
    assert _lone_sinus(two, ConvexHull(two).equations, 200.0) is None
    shallow = notched([1.0], 0.05)
    assert _lone_sinus(shallow, ConvexHull(shallow).equations, 200.0) is None


def test_the_ray_leaves_the_contour_at_its_far_crossing() -> None:
    square = _ring([(0.0, 0.0), (100.0, 0.0), (100.0, 100.0), (0.0, 100.0)])
    exit_ = _ray_exit(square, np.array([50.0, 50.0]), np.array([0.6, 0.8]))
    assert np.allclose(exit_, [50.0 + 37.5, 100.0], atol=0.3), exit_


def _tip_photo(trace: float, wedge: bool) -> tuple[object, np.ndarray, np.ndarray]:
    """A white photo with a green leaf ending at (160, 100): a narrow wedge from x = 0 (60 px wide
    there) or a disc of radius 60 round (100, 100); where ``trace`` > 0, a line 1 px wide of that
    excess green runs on from the tip (x 160 to 180). The leaf's outline and its apex."""
    rgb = np.ones((200, 260, 3), np.float32)
    yy, xx = np.mgrid[:200, :260]
    if wedge:
        rgb[(xx <= 160) & (np.abs(yy - 100) <= 30 * (160 - xx) / 160)] = (0.2, 0.5, 0.2)
        outline = _ring([(0.0, 70.0), (160.0, 100.0), (0.0, 130.0)])
    else:
        rgb[(xx - 100) ** 2 + (yy - 100) ** 2 <= 60 ** 2] = (0.2, 0.5, 0.2)
        t = np.linspace(0, 2 * math.pi, 720, endpoint=False)
        outline = np.stack([100 + 60 * np.cos(t), 100 + 60 * np.sin(t)], axis=1)
    rgb[100, 160:181] = (1.0 - trace / 2, 1.0, 1.0 - trace / 2)      # 2G - R - B = trace
    return as_photo(rgb), outline, np.array([160.0, 100.0])


def test_a_faint_trace_beyond_a_thin_tip_is_followed() -> None:
    ch = _Channels("exg", 0.3, {}, 0.02)
    base = np.array([-140.0, 100.0])
    photo, outline, apex = _tip_photo(0.3, wedge=True)   # its box mean over 3 px: 0.1, above 0.02
    moved = _faint_tip(photo, ch, 1, apex, outline, base)
    assert 170.0 <= moved[0] <= 181.0 and abs(moved[1] - 100.0) < 1.0, moved
    photo, outline, apex = _tip_photo(0.0, wedge=True)   # no trace: the tip's blurred end only
    assert np.allclose(_faint_tip(photo, ch, 1, apex, outline, base), apex)
    photo, outline, apex = _tip_photo(0.3, wedge=False)  # a round end shows where it ends: not followed
    assert np.allclose(_faint_tip(photo, ch, 1, apex, outline, base), apex)


def _ring(points: list[tuple[float, float]], step: float = 0.5) -> np.ndarray:
    """A closed polygon densified to ``step`` spacing."""
    p = np.asarray(points + points[:1], np.float64)
    out = []
    for a, b in zip(p[:-1], p[1:]):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / step))
        out.append(a + np.arange(n)[:, None] / n * (b - a))
    return np.vstack(out)


def test_a_cut_wedge_tip_is_followed_to_its_point() -> None:
    # a narrow wedge along +x, 400 px long, 80 px wide at its base, cut off where it is 4 px wide
    # (the last 20 px): the tip is followed on towards where its sides meet, as far as TIP_MAX allows
    cut = 380.0
    half = 40.0 * (400.0 - cut) / 400.0
    contour = _ring([(0.0, -40.0), (cut, -half), (cut, half), (0.0, 40.0)])
    apex = np.array([cut, 0.0])
    tip = _taper_tip(contour, np.array([0.0, 0.0]), apex, 1.0)
    assert tip[0] > cut + 0.8 * min(20.0, TIP_MAX * cut) and abs(tip[1]) < 1.0, tip


def test_a_stalk_stays() -> None:
    # a blade ending in a stalk of even width (a short petiole, not a taper): not extended
    contour = _ring([(0.0, -40.0), (300.0, -4.0), (380.0, -3.0), (380.0, 3.0), (300.0, 4.0), (0.0, 40.0)])
    apex = np.array([380.0, 0.0])
    assert np.allclose(_taper_tip(contour, np.array([0.0, 0.0]), apex, 1.0), apex)


def test_a_rounded_apex_stays() -> None:
    t = np.linspace(-math.pi / 2, math.pi / 2, 400)
    contour = np.vstack([np.stack([100 + 40 * np.cos(t), 40 * np.sin(t)], axis=1), [[0.0, 40.0], [0.0, -40.0]]])
    apex = np.array([140.0, 0.0])
    assert np.allclose(_taper_tip(_ring([tuple(p) for p in contour]), np.array([0.0, 0.0]), apex, 1.0), apex)


def test_a_stub_is_walked_back_to_the_blade() -> None:
    # a wedge-based blade along +x from its root at x = 0 to its apex at x = 400, 160 px wide at most,
    # with a 4 px wide stub from x = -16 to 0: the base is the stub's root, not its end
    contour = _ring([(-16.0, -2.0), (0.0, -2.0), (60.0, -60.0), (200.0, -80.0), (400.0, 0.0),
                     (200.0, 80.0), (60.0, 60.0), (0.0, 2.0), (-16.0, 2.0)])
    root = _stub_root(contour, np.array([400.0, 0.0]), np.array([-16.0, 0.0]), 160.0, 1.0)
    assert root is not None and abs(root[0]) <= 2.0 and abs(root[1]) < 1.0, root


def test_a_wedge_base_has_no_stub() -> None:
    # a narrow wedge base (width growing evenly from its point) and a stub wider than a stub may be
    contour = _ring([(0.0, 0.0), (200.0, -40.0), (400.0, 0.0), (200.0, 40.0)])
    assert _stub_root(contour, np.array([400.0, 0.0]), np.array([0.0, 0.0]), 80.0, 1.0) is None
    wide = _ring([(-16.0, -10.0), (0.0, -10.0), (60.0, -60.0), (400.0, 0.0), (60.0, 60.0), (0.0, 10.0), (-16.0, 10.0)])
    assert _stub_root(wide, np.array([400.0, 0.0]), np.array([-16.0, 0.0]), 120.0, 1.0) is None
