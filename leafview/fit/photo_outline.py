"""The leaf in a photograph: its mask, smoothed outline, base, apex and petiole (the image side of
Mündermann et al. 2003, sec. 3.1, and Hong 2005, ch. 5).

Steps, all in :func:`leaf_outline`:

1. **Working resolution.** The segmentation runs on the photo reduced by an integer factor
   f = round(√(pixels / :data:`WORK_PIXELS`)) with area averaging (block means): a 1 MP photo is
   segmented at 500 × 500. Every coordinate returned is in the full photo's pixels (pixel (i, j)'s
   centre at x = i, y = j, y down); the full-resolution ``mask`` is the working one enlarged with
   the pixels along its edge thresholded again from the photo's own pixels, and the petiole is
   measured at full resolution (:mod:`leafview.fit.photo_shape`).
2. **Threshold chosen automatically.** Two candidate "greenness" channels: excess green
   2G - R - B, and -a* of CIELAB (D65) / 100. Each is clipped below at neutral, so grey, white,
   brown, red and pink are all "not green": non-green debris and shadows fall into the paper's
   class whatever their colour. Each is split by Otsu's threshold on a subsample. A channel is
   admissible when its leaf class is green enough (mean ≥ :data:`MIN_GREEN`), stands
   :data:`MIN_SEPARATION` standard deviations of the paper above it, and covers less than half of
   the image border (on yellow paper the paper is greener than the leaf in excess green: only a*
   finds the leaf there); of the admissible ones the one with the larger Otsu separation
   (between-class over total variance) is used, on the working image smoothed by a 3 × 3 box.
   Yellowish (autumn) leaves are found by excess green; red and brown ones are not.
3. **Morphology.** The largest 8-connected component above the threshold is the blade
   (:data:`MIN_LEAF_FRACTION` of the image at least, else "no leaf"); its holes smaller than
   :data:`HOLE_FRACTION` of it are filled, larger ones (insect damage) stay holes. No opening or
   closing: the 3 × 3 box mean already quiets the noise, and either would eat thin petioles and
   sharp tips or fill narrow sinuses.
   A petiole paler than the blade is added back by a hysteresis (:func:`_segment`).
4. **One leaf, not two** (:func:`leafview.fit.photo_shape.split_shares`), and no second leaf too
   dark or olive to be traced lying against it (:func:`_unlike_paper`: a region whose chroma is
   not the paper's, at least :data:`UNLIKE_SHARE` of the leaf's area and :data:`UNLIKE_THICK` of
   its thickness).
5. **Petiole, base, apex, outline** (:func:`leafview.fit.photo_shape.leaf_shape`); the apex then
   followed on along a tip's faint trace, below the threshold but above the paper's noise
   (:func:`_faint_tip`).

A leaf touching the image border is fitted as it shows, with a warning naming the side.
Errors are :class:`~leafview.errors.ParamError` naming the file (or ``image`` for an array).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from skimage.filters import threshold_otsu

from leafview.core.colour import srgb_to_linear
from leafview.errors import ParamError
from leafview.fit.photo_io import Photo, as_photo, read_photo
from leafview.fit.photo_shape import TIP_MAX, Shape, leaf_shape, split_shares

__all__ = ["LeafOutline", "leaf_outline", "Photo", "read_photo", "as_photo", "greenness", "WORK_PIXELS"]

WORK_PIXELS = 300_000          # segmentation resolution (pixels) for larger photos
MIN_LEAF_FRACTION = 0.002      # the leaf covers at least this share of the image
HOLE_FRACTION = 0.001          # holes smaller than this share of the leaf are filled
TWO_LEAVES_SHARE = 0.25        # a second part of at least this share of the leaf means two leaves
UNLIKE_PAPER = 8.0             # CIELAB chroma distance (a*, b*) from the paper's median that is not paper, at least ...
UNLIKE_SPREAD = 5.0            # ... and this many times the paper's median distance from it
UNLIKE_SHARE = 0.25            # a region unlike the paper touching the leaf, of this share of its area, ...
UNLIKE_THICK = 0.35            # ... and this thick (its largest inscribed radius / the leaf's): a second leaf
MIN_GREEN = {"exg": 0.05, "lab-a": 0.05}   # leaf class mean: excess green, or -a*/100
MIN_SEPARATION = 5.0           # leaf class mean above the paper's, in standard deviations of the paper
MAX_BORDER_SHARE = 0.5         # the leaf class covers less than this share of the image border
LOW_FRACTION = 0.3             # pale thin parts (petioles): at least this share of the way from the paper to Otsu's
PALE_REACH = 0.3               # pale parts are looked for this far (of the blade's size) beyond its box
FAINT_FRACTION = 0.05          # a faint tip's trace: at least this share of the way from the paper to Otsu's
FAINT_RUN = 3                  # ... followed for at least this many working pixels (more than an edge's blur)
FAINT_THIN, FAINT_THIN_AT = 8.0, 0.02   # ... beyond a tip at most this many working pixels wide this far (of the length) behind it
_MIN_THIN_PIXELS = 6           # a pale part beyond the blade's edge has at least this many working pixels
_SAMPLE_PIXELS = 40_000        # pixels used to choose the channel and its threshold
_UNLIKE_PIXELS = 25_000        # pixels (about) in which a region unlike the paper is looked for
_CROSS = ndimage.generate_binary_structure(2, 1)
_EIGHT = ndimage.generate_binary_structure(2, 2)


@dataclass(frozen=True, eq=False)
class LeafOutline:
    """The leaf found in a photo, in its pixels (x right, y down, pixel (i, j) centred at (i, j)).

    * ``mask`` (h, w): the leaf with its petiole; ``blade`` the mask without the petiole.
    * ``outline`` (M, 2): the blade's closed outline, smoothed (a periodic cubic B-spline, see
      :func:`leafview.fit.photo_shape.fit_closed_bspline`), counter-clockwise as seen on screen
      (its shoelace area in these y-down coordinates is negative), starting at the point nearest
      ``base``; the last point is not repeated.
    * ``base``: where the blade starts, on its midline (the leaf's v = 0); ``apex``: its tip (v = 1).
    * ``petiole`` (K, 2): the petiole's centre line from its free end to ``base`` ((0, 2) if none).
    * ``cut_sides``: the image borders the leaf touches; ``method``: the threshold used
      (``'exg-otsu'`` or ``'lab-a-otsu'``); ``warnings``: one line each.
    """

    mask: NDArray[np.bool_]
    blade: NDArray[np.bool_]
    outline: NDArray[np.float64]
    base: NDArray[np.float64]
    apex: NDArray[np.float64]
    petiole: NDArray[np.float64]
    cut_sides: tuple[str, ...]
    method: str
    warnings: tuple[str, ...]

    @property
    def length(self) -> float:
        """The blade's length in pixels: from base to apex."""
        return float(np.hypot(*(self.apex - self.base)))


# -- colour ------------------------------------------------------------------------------------------
_LUT = np.linspace(0.0, 1.0, 4096, dtype=np.float64)
_LINEAR = srgb_to_linear(_LUT).astype(np.float32)   # a look-up table: the photo's pixels decoded fast


def _lab_f(t: NDArray[np.float32]) -> NDArray[np.float32]:
    eps = (6 / 29) ** 3
    return np.where(t > eps, np.cbrt(np.maximum(t, eps)), t * np.float32(1 / (3 * (6 / 29) ** 2)) + np.float32(4 / 29))


def greenness(rgb: NDArray[np.float32], channel: str) -> NDArray[np.float32]:
    """The candidate channel ``'exg'`` (excess green 2G - R - B) or ``'lab-a'`` (-a*/100 of
    CIELAB, D65 white) of sRGB pixels (..., 3) in [0, 1], clipped below at 0 (neutral): the
    greener, the higher."""
    if channel == "exg":
        g = 2 * rgb[..., 1] - rgb[..., 0] - rgb[..., 2]
    else:
        lin = _LINEAR[np.clip(rgb * 4095 + 0.5, 0, 4095).astype(np.int32)]
        r, gr, b = lin[..., 0], lin[..., 1], lin[..., 2]
        x = (0.4124564 * r + 0.3575761 * gr + 0.1804375 * b) * np.float32(1 / 0.95047)
        y = 0.2126729 * r + 0.7151522 * gr + 0.0721750 * b
        g = -5.0 * (_lab_f(x) - _lab_f(y))        # -a*/100
    return np.maximum(g, 0).astype(np.float32)


def _block_means(rgb: NDArray[np.float32], f: int) -> NDArray[np.float32]:
    """Means of the whole ``f`` × ``f`` blocks of ``rgb`` (strided sums for small ``f``, reshaped
    sums for large: both the fastest numpy has for their case)."""
    hm, wm = rgb.shape[0] // f, rgb.shape[1] // f
    if hm == 0 or wm == 0:
        return np.zeros((hm, wm, 3), np.float32)
    if f <= 4:
        acc = np.zeros((hm, wm, 3), np.float32)
        for i in range(f):
            rows = rgb[i:hm * f:f]
            for j in range(f):
                acc += rows[:, j:wm * f:f]
    else:
        acc = rgb[:hm * f].reshape(hm, f, rgb.shape[1], 3).sum(axis=1, dtype=np.float32)
        acc = acc[:, :wm * f].reshape(hm, wm, f, 3).sum(axis=2, dtype=np.float32)
    return acc * np.float32(1 / (f * f))


def _downscale(rgb: NDArray[np.float32], f: int) -> NDArray[np.float32]:
    """Area averaging by ``f``: each working pixel is the mean of an ``f`` × ``f`` block of the
    photo; the last row and column of blocks, where the photo's size is not a multiple of ``f``,
    average the pixels there are."""
    if f == 1:
        return rgb
    h, w = rgb.shape[:2]
    hm, wm = h // f, w // f
    out = np.empty((-(-h // f), -(-w // f), 3), np.float32)
    out[:hm, :wm] = _block_means(rgb, f)
    if h > hm * f:
        out[hm, :wm] = rgb[hm * f:, :wm * f].mean(axis=0).reshape(wm, f, 3).mean(axis=1) if wm else 0
    if w > wm * f:
        out[:hm, wm] = rgb[:hm * f, wm * f:].mean(axis=1).reshape(hm, f, 3).mean(axis=1) if hm else 0
    if h > hm * f and w > wm * f:
        out[hm, wm] = rgb[hm * f:, wm * f:].reshape(-1, 3).mean(axis=0)
    return out


@dataclass(frozen=True)
class _Channels:
    channel: str                 # the channel the blade is thresholded in
    threshold: float             # its Otsu threshold
    pale: dict[str, float]       # channel -> threshold for pale thin parts, for channels whose paper is quiet
    faint: float = 0.0           # the chosen channel just above the paper's noise (a faint tip's trace)


def _choose_channel(work: NDArray[np.float32], source: str) -> _Channels:
    """The channel (``'exg'`` or ``'lab-a'``) and its Otsu threshold, and thresholds for pale
    thin parts just above the paper's noise, chosen on a subsample (module docstring)."""
    step = max(1, int(math.sqrt(work.shape[0] * work.shape[1] / _SAMPLE_PIXELS)))
    sample = work[::step, ::step]
    border = np.zeros(sample.shape[:2], bool)
    border[[0, -1], :] = border[:, [0, -1]] = True
    best: tuple[float, str, float] | None = None
    seen: list[str] = []
    values: dict[str, NDArray[np.float32]] = {}
    for channel in ("exg", "lab-a"):
        g = values[channel] = greenness(sample, channel)
        if float(g.max()) - float(g.min()) < 1e-3:
            seen.append(f"{channel}: flat")
            continue
        t = float(threshold_otsu(g))
        hi = g > t
        w1 = float(hi.mean())
        mean_hi, mean_lo = float(g[hi].mean()), float(g[~hi].mean())
        eta = w1 * (1 - w1) * (mean_hi - mean_lo) ** 2 / max(float(g.var()), 1e-12)
        border_share = float(hi[border].mean())
        seen.append(f"{channel}: leaf class {mean_hi:.3f}, border {border_share:.0%}, "
                    f"separation {(mean_hi - mean_lo) / max(float(g[~hi].std()), 1e-3):.1f}")
        spread = float(g[~hi].std())
        if (mean_hi >= MIN_GREEN[channel] and border_share < MAX_BORDER_SHARE
                and mean_hi - mean_lo >= MIN_SEPARATION * max(spread, 1e-3) and (best is None or eta > best[0])):
            best = (eta, channel, t)
    if best is None:
        raise _no_leaf(source, "nothing in the photo is green enough to be a leaf (" + "; ".join(seen) + ")")
    _, channel, t = best
    paper = values[channel] <= t
    # Otsu's criterion is flat between two well separated classes (and skimage takes the low end):
    # the midpoint of the class medians puts the edge where a blurred step is half leaf
    t = 0.5 * (float(np.median(values[channel][~paper])) + float(np.median(values[channel][paper])))
    paper = values[channel] <= t
    pale: dict[str, float] = {}
    faint = t
    for name, g in values.items():
        q50, q95 = (float(q) for q in np.percentile(g[paper], [50, 95]))
        floor = LOW_FRACTION * (t - q50) if name == channel else 0.5 * MIN_GREEN[name]
        low = max(q95 + 2 * (q95 - q50), q50 + floor)
        if name == channel or float((g[border] > low).mean()) < 0.02:
            pale[name] = min(low, t) if name == channel else low
        if name == channel:
            faint = min(max(q95 + 2 * (q95 - q50), q50 + FAINT_FRACTION * (t - q50)), t)
    return _Channels(channel, t, pale, faint)


def _no_leaf(source: str, why: str) -> ParamError:
    return ParamError("" if source else "image", f"no leaf found: {why}", source or None)


# -- mask ----------------------------------------------------------------------------------------------
def _padded(op: Any, mask: NDArray[np.bool_], structure: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """A binary morphology ``op`` with the image edge replicated (a leaf cut by the border keeps
    its border pixels)."""
    p = np.pad(mask, 2, mode="edge")
    return np.asarray(op(p, structure=structure)[2:-2, 2:-2], bool)


def _largest(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    lab, n = ndimage.label(mask, structure=_EIGHT)
    if n == 0:
        return np.zeros_like(mask)
    counts = np.bincount(lab.ravel())
    counts[0] = 0
    return np.asarray(lab == int(np.argmax(counts)), bool)


def _fill_small_holes(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """``mask`` with its holes smaller than :data:`HOLE_FRACTION` of its area filled."""
    holes = ndimage.binary_fill_holes(mask) & ~mask
    if not holes.any():
        return mask
    lab, n = ndimage.label(holes, structure=_CROSS)
    sizes = np.bincount(lab.ravel())
    small = sizes < max(HOLE_FRACTION * float(mask.sum()), 4.0)
    small[0] = False
    return np.asarray(mask | small[lab], bool)


@dataclass(frozen=True)
class _Segmentation:
    channels: _Channels
    crop: NDArray[np.bool_]          # the leaf (working resolution) in its bounding box and a margin
    pale: NDArray[np.bool_]          # where (in the crop) the pale-part thresholds apply
    corner: tuple[int, int]          # (row, column) of the crop's first pixel in the working image


def _pale_mask(rgb: NDArray[np.float32], ch: _Channels) -> NDArray[np.bool_]:
    """Pixels above the pale-part threshold in any quiet channel (3 × 3 box means)."""
    out = np.zeros(rgb.shape[:2], bool)
    for name, low in ch.pale.items():
        out |= ndimage.uniform_filter(greenness(rgb, name), 3, mode="nearest") > low
    return out


def _segment(work: NDArray[np.float32], source: str) -> _Segmentation:
    """The leaf at working resolution.

    The blade is the largest component above the threshold, its small holes filled. Pale thin
    parts joined to it (a petiole paler than the blade) come from a hysteresis: take the component
    above the pale-part thresholds (in either channel where the paper is quiet) that holds the
    blade, less a one-pixel ring round the blade (where the blur of its edge lies between the
    thresholds); keep its pieces beyond that ring that have a few pixels and meet the ring at a
    point (at most a quarter of their pixels touch it: a stalk, not a fringe along the edge), and
    bridge them back to the blade across the ring. The search reaches :data:`PALE_REACH` of the
    blade's size beyond its box."""
    ch = _choose_channel(work, source)
    g = ndimage.uniform_filter(greenness(work, ch.channel), 3, mode="nearest")
    hi, nh = ndimage.label(g > ch.threshold, structure=_EIGHT)
    if nh == 0:
        raise _no_leaf(source, "no pixel is greener than the threshold")
    counts = np.bincount(hi.ravel())
    counts[0] = 0
    k = int(np.argmax(counts))
    rs, cs = ndimage.find_objects(hi, max_label=k)[k - 1]
    if counts[k] < MIN_LEAF_FRACTION * hi.size:
        raise _no_leaf(source, f"the largest leaf-coloured region ({int(counts[k]):,} px) is below "
                               f"{MIN_LEAF_FRACTION:.1%} of the image")
    reach = int(PALE_REACH * max(rs.stop - rs.start, cs.stop - cs.start)) + 2
    y0, x0 = max(rs.start - reach, 0), max(cs.start - reach, 0)
    window = np.s_[y0:rs.stop + reach, x0:cs.stop + reach]
    blade = hi[window] == k
    low, _ = ndimage.label(_pale_mask(work[window], ch) | blade, structure=_EIGHT)
    joined = low == int(low.ravel()[int(np.argmax(blade.ravel()))])
    core = _fill_small_holes(_largest(blade))
    ring = _padded(ndimage.binary_dilation, core, _EIGHT)
    beyond, n = ndimage.label(joined & ~ring, structure=_EIGHT)
    pale = np.zeros(core.shape, bool)
    if n:
        sizes = np.bincount(beyond.ravel(), minlength=n + 1)
        touching = np.bincount(beyond[_padded(ndimage.binary_dilation, ring, _EIGHT)], minlength=n + 1)
        keep = (sizes >= _MIN_THIN_PIXELS) & (touching <= np.maximum(3, 0.25 * sizes))   # joined at a point,
        keep[0] = False                                                               # not along the edge
        thin = keep[beyond]
        thin |= ring & ~core & joined & ndimage.binary_dilation(thin, _EIGHT)
        core = core | thin
        pale = ndimage.binary_dilation(thin, _EIGHT, iterations=2)
    rows, cols = np.nonzero(core)
    r0, r1, c0, c1 = max(rows.min() - 2, 0), rows.max() + 3, max(cols.min() - 2, 0), cols.max() + 3
    return _Segmentation(ch, core[r0:r1, c0:c1], pale[r0:r1, c0:c1], (y0 + r0, x0 + c0))


def _chroma(rgb: NDArray[np.float32]) -> NDArray[np.float32]:
    """CIELAB (a*, b*) (D65 white) of sRGB pixels (..., 3) in [0, 1], as (..., 2)."""
    lin = _LINEAR[np.clip(rgb * 4095 + 0.5, 0, 4095).astype(np.int32)]
    r, g, b = lin[..., 0], lin[..., 1], lin[..., 2]
    fx = _lab_f((0.4124564 * r + 0.3575761 * g + 0.1804375 * b) * np.float32(1 / 0.95047))
    fy = _lab_f(0.2126729 * r + 0.7151522 * g + 0.0721750 * b)
    fz = _lab_f((0.0193339 * r + 0.1191920 * g + 0.9503041 * b) * np.float32(1 / 1.08883))
    return np.stack([500 * (fx - fy), 200 * (fy - fz)], axis=-1).astype(np.float32)


def _unlike_paper(work: NDArray[np.float32], seg: _Segmentation) -> tuple[float, float]:
    """The largest region beside the leaf whose colour is not the paper's (a second leaf too dark
    or too olive for the leaf's threshold): (its area / the leaf's, its largest inscribed radius /
    the leaf's), or (0, 0). Looked for within :data:`PALE_REACH` of the leaf's size around its box,
    on 3 × 3 box means: a pixel is unlike the paper where its chroma (CIELAB a*, b*) lies more than
    :data:`UNLIKE_PAPER` and :data:`UNLIKE_SPREAD` times the paper's median spread from the paper's
    median chroma (shadows darken the paper but keep its chroma), the paper being what lies more
    than 6 pixels from the leaf. The leaf's own pixels (with the holes it encloses) and a 2-pixel
    ring round it (one more per k) are left out; the region must reach that ring. Every k-th row
    and column of the window is looked at (about :data:`_UNLIKE_PIXELS` pixels in all)."""
    core = seg.crop
    cy, cx = seg.corner
    reach = int(PALE_REACH * max(core.shape)) + 2
    y0, x0 = max(cy - reach, 0), max(cx - reach, 0)
    win = work[y0:cy + core.shape[0] + reach, x0:cx + core.shape[1] + reach]
    leaf = np.zeros(win.shape[:2], bool)
    leaf[cy - y0:cy - y0 + core.shape[0], cx - x0:cx - x0 + core.shape[1]] = core
    k = max(1, round(math.sqrt(leaf.size / _UNLIKE_PIXELS)))     # every k-th pixel is enough for a leaf-sized region
    win, leaf = win[::k, ::k], ndimage.binary_fill_holes(leaf[::k, ::k])
    away = ndimage.distance_transform_edt(~leaf) * k
    near, paper = away <= 1.5 + k, away > 6
    if not paper.any():
        return 0.0, 0.0
    chroma = _chroma(ndimage.uniform_filter(win, (3, 3, 1), mode="nearest"))
    d = np.hypot(*(chroma - np.median(chroma[paper], axis=0)).transpose(2, 0, 1))
    other = (d > max(UNLIKE_PAPER, UNLIKE_SPREAD * float(np.median(d[paper])))) & ~near
    lab, n = ndimage.label(other, structure=_EIGHT)
    touch = np.unique(lab[(away <= 1.5 + 3 * k) & other])
    touch = touch[touch > 0]
    if not len(touch):
        return 0.0, 0.0
    sizes = np.bincount(lab.ravel())
    j = int(touch[np.argmax(sizes[touch])])
    share = float(sizes[j]) / float(leaf.sum())
    if share < UNLIKE_SHARE:
        return share, 0.0
    inner = float(ndimage.distance_transform_edt(np.pad(leaf, 1))[1:-1, 1:-1].max())
    return share, float(ndimage.distance_transform_edt(np.pad(lab == j, 1))[1:-1, 1:-1].max()) / max(inner, 1.0)


def _faint_tip(photo: Photo, ch: _Channels, f: int, apex: NDArray[np.float64], outline: NDArray[np.float64],
               base: NDArray[np.float64]) -> NDArray[np.float64]:
    """The apex moved on along a tip's faint trace beyond it: the thin end of an acuminate or drip
    tip, below the threshold but above the paper's noise (:data:`FAINT_FRACTION`). From the apex, in
    the direction from the outline's points within 3 % of the length of it, the greenness (box
    means over 3 working pixels, as the threshold's) is followed one pixel a step along its ridge
    (the best of five offsets up to half a pixel across, the direction turning slowly towards it)
    while it stays above that level and below the threshold (not back into the blade), goes on
    away from ``base``, and keeps leaving the outline (at least 0.7 pixels from it per step: not
    along the blur of a blunt apex's edge), for at most
    :data:`~leafview.fit.photo_shape.TIP_MAX` of the length. A run shorter than :data:`FAINT_RUN`
    working pixels is the edge's blur: the apex stays. Only a thin tip is followed, at most
    :data:`FAINT_THIN` working pixels wide :data:`FAINT_THIN_AT` of the length behind the apex
    (wider tips end where they show; followed, their blur and shadows took the single leaves of a
    sweep with both ends within 2 % from 150 to 144 of 232)."""
    length = float(np.hypot(*(apex - base)))
    near = outline[np.hypot(*(outline - apex).T) <= 0.03 * length]
    if len(near) < 3 or not length > 0:
        return apex
    d = apex - near.mean(axis=0)
    ahead = (apex - base) / length
    rel = outline - apex
    along, side = rel @ ahead, rel @ np.array([-ahead[1], ahead[0]])
    band = np.abs(along + FAINT_THIN_AT * length) <= 2.0
    if not float(d @ ahead) > 0 or band.sum() < 2 or float(np.ptp(side[band])) > FAINT_THIN * f:
        return apex                                 # not a thin tip: its end shows
    d = d / float(np.hypot(*d))
    reach = int(TIP_MAX * length)
    r = reach + 3 * f + 2
    y0, x0 = max(int(apex[1]) - r, 0), max(int(apex[0]) - r, 0)
    win = photo.rgb[y0:int(apex[1]) + r + 1, x0:int(apex[0]) + r + 1]
    if win.shape[0] < 3 or win.shape[1] < 3:
        return apex
    g = ndimage.uniform_filter(greenness(win, ch.channel), 3 * f, mode="nearest")
    p = apex - (x0, y0)
    ring = outline - (x0, y0)
    across = np.linspace(-0.5, 0.5, 5)
    run = 0
    for _ in range(reach):
        n = np.array([-d[1], d[0]])
        q = p + d + across[:, None] * n
        v = ndimage.map_coordinates(g, [q[:, 1], q[:, 0]], order=1, mode="nearest")
        k = int(np.argmax(v))
        if (not ch.faint < v[k] < ch.threshold or float((q[k] - p) @ ahead) <= 0
                or float(np.min(np.hypot(*(ring - q[k]).T))) < 0.7 * (run + 1)):
            break                                   # the paper or the blade, or along the edge's blur instead of away
        step = q[k] - p
        d = 0.8 * d + 0.2 * step / float(np.hypot(*step))
        d = d / float(np.hypot(*d))
        p, run = q[k], run + 1
    if run < FAINT_RUN * f:
        return apex
    return np.asarray(p + (x0, y0), np.float64)


def _band_greenness(rgb: NDArray[np.float32], rows: NDArray[np.intp], cols: NDArray[np.intp],
                    channel: str) -> NDArray[np.float32]:
    """The 3 × 3 box mean of the photo around each pixel (rows, cols), as greenness."""
    h, w = rgb.shape[:2]
    acc = np.zeros((len(rows), 3), np.float32)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            acc += rgb[np.clip(rows + dr, 0, h - 1), np.clip(cols + dc, 0, w - 1)]
    return greenness(acc * np.float32(1 / 9), channel)


def _fine_crop(photo: Photo, f: int, seg: _Segmentation) -> tuple[NDArray[np.bool_], tuple[int, int]]:
    """The leaf's crop at the photo's resolution and its (row, column) there: the working crop
    enlarged, the pixels along its edge thresholded again from the photo's own pixels (same
    channel and threshold, on their 3 × 3 box means)."""
    h, w = photo.rgb.shape[:2]
    crop = seg.crop
    y0, x0 = seg.corner[0] * f, seg.corner[1] * f
    if f == 1:
        return crop, (y0, x0)
    shape = (min(crop.shape[0] * f, h - y0), min(crop.shape[1] * f, w - x0))

    def up(m: NDArray[np.bool_]) -> NDArray[np.bool_]:
        return np.asarray(np.repeat(np.repeat(m, f, axis=0), f, axis=1)[:shape[0], :shape[1]], bool)

    band = up(_padded(ndimage.binary_dilation, crop, _EIGHT) & ~_padded(ndimage.binary_erosion, crop, _EIGHT))
    fine = up(crop)
    rows, cols = np.nonzero(band)
    ch = seg.channels
    on_pale = seg.pale[rows // f, cols // f]
    fine[rows, cols] = _band_greenness(photo.rgb, rows + y0, cols + x0, ch.channel) > ch.threshold
    for name, low in ch.pale.items():
        fine[rows[on_pale], cols[on_pale]] |= _band_greenness(photo.rgb, rows[on_pale] + y0, cols[on_pale] + x0,
                                                              name) > low
    return fine, (y0, x0)


def _cut_sides(mask: NDArray[np.bool_], blade: NDArray[np.bool_]) -> tuple[tuple[str, ...], list[str]]:
    sides: list[str] = []
    notes: list[str] = []
    for side, edge, bedge in (("left", mask[:, 0], blade[:, 0]), ("right", mask[:, -1], blade[:, -1]),
                              ("top", mask[0], blade[0]), ("bottom", mask[-1], blade[-1])):
        if edge.any():
            sides.append(side)
            what = "blade" if bedge.any() else "petiole"
            notes.append(f"the leaf's {what} is cut by the image's {side} border: it is fitted as far as it shows")
    return tuple(sides), notes


# -- the whole --------------------------------------------------------------------------------------------
def _point(value: ArrayLike | None, field: str, size: tuple[int, int], source: str) -> NDArray[np.float64] | None:
    """An (x, y) override in pixels, checked to lie in the image."""
    if value is None:
        return None
    try:
        p = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ParamError(field, f"expected two numbers X,Y in pixels, got {value!r}", source or None) from None
    if p.shape != (2,) or not np.all(np.isfinite(p)):
        raise ParamError(field, f"expected two finite numbers X,Y in pixels, got {value!r}", source or None)
    w, h = size
    if not (-0.5 <= p[0] <= w - 0.5 and -0.5 <= p[1] <= h - 0.5):
        raise ParamError(field, f"({p[0]:g}, {p[1]:g}) lies outside the {w}×{h} px image", source or None)
    return p


def leaf_outline(photo: Photo | Any, *, base: ArrayLike | None = None, apex: ArrayLike | None = None) -> LeafOutline:
    """The leaf in ``photo`` (a :class:`Photo`, a path or an array, see :func:`as_photo`): see the
    module docstring. ``base`` and ``apex`` ((x, y) in the photo's pixels) replace the detected
    ones; they must lie in the image (else a :class:`ParamError` naming ``--base`` or ``--apex``)."""
    photo = as_photo(photo)
    source = photo.path
    h, w = photo.rgb.shape[:2]
    base_px = _point(base, "--base", (w, h), source)
    apex_px = _point(apex, "--apex", (w, h), source)
    f = max(1, round(math.sqrt(h * w / WORK_PIXELS)))
    work = _downscale(photo.rgb, f)
    seg = _segment(work, source)
    shares = split_shares(seg.crop)
    if len(shares) > 1 and shares[1] >= TWO_LEAVES_SHARE:
        raise ParamError("" if source else "image",
                         f"two touching leaves found: the leaf-coloured region parts at a narrow neck into pieces of "
                         f"{shares[0]:.0%} and {shares[1]:.0%} of it; photograph one leaf at a time, apart from others",
                         source or None)
    other, thick = _unlike_paper(work, seg)
    if other >= UNLIKE_SHARE and thick >= UNLIKE_THICK:
        raise ParamError("" if source else "image",
                         f"two touching leaves? a region of {other:.0%} of the leaf's area, unlike the paper but not "
                         f"green enough to be traced, lies against it (a second, darker or olive leaf?); photograph "
                         f"one leaf at a time, apart from others", source or None)
    fine, (y0, x0) = _fine_crop(photo, f, seg)
    corner = np.array([x0, y0], np.float64)

    def to_crop(p: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
        return None if p is None else p - corner

    def to_full(p: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(p + corner, np.float64)

    cy, cx = seg.corner
    grey = work[cy:cy + seg.crop.shape[0], cx:cx + seg.crop.shape[1]] @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    colour = photo.rgb[y0:y0 + fine.shape[0], x0:x0 + fine.shape[1]]
    shape: Shape = leaf_shape(seg.crop, fine=fine, f=f, grey=grey, base=to_crop(base_px), apex=to_crop(apex_px),
                              colour=colour)
    mask, blade = np.zeros((h, w), bool), np.zeros((h, w), bool)
    window = np.s_[y0:y0 + fine.shape[0], x0:x0 + fine.shape[1]]
    mask[window], blade[window] = fine, shape.blade
    sides, notes = _cut_sides(mask, blade)
    outline, found_base = to_full(shape.outline), to_full(shape.base)
    found_apex = to_full(shape.apex)
    if apex_px is None:
        found_apex = _faint_tip(photo, seg.channels, f, found_apex, outline, found_base)
    return LeafOutline(
        mask=mask, blade=blade, outline=outline,
        base=base_px if base_px is not None else found_base,
        apex=apex_px if apex_px is not None else found_apex,
        petiole=to_full(shape.petiole), cut_sides=sides, method=f"{seg.channels.channel}-otsu",
        warnings=tuple(notes) + shape.warnings)
