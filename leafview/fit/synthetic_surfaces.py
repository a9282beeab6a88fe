"""The surfaces of the synthetic photos (:mod:`leafview.fit.synthetic_photos`): smooth random
fields, the leaf's colours and texture (gradient, mottling, midrib, secondary and tertiary veins,
spots; an underside paler with embossed veins), and the paper under it (albedo, grain, uneven
light, a soft drop shadow and non-green debris).

Images here are float32 and planar, (3, h, w) or one row per channel, so that every operation
runs along the pixels.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from skimage.draw import line_aa

from leafview.fit.synthetic_leaf import F32, Arr, Placed

BACKGROUNDS: dict[str, tuple[float, float, float]] = {   # paper albedo, sRGB in [0, 1]; none of them green
    "white": (0.94, 0.94, 0.93), "cream": (0.95, 0.91, 0.79), "blue": (0.79, 0.86, 0.95),
    "grey": (0.73, 0.73, 0.72), "pink": (0.96, 0.83, 0.86)}


# ---------------------------------------------------------------------------------------------
# smooth random fields
# ---------------------------------------------------------------------------------------------

def _field(rng: np.random.Generator, height: int, width: int, *octaves: tuple[float, float]) -> F32:
    """A smooth random field: the sum over ``octaves`` of (cell, amplitude) of Gaussian random
    fields of standard deviation ``amplitude`` with features about ``cell`` pixels across. Each is
    a random grid interpolated by separable Gaussian weights; all octaves are one matrix product
    each way (the grids sit on a block diagonal)."""
    def weights(n: int, cell: float) -> F32:
        m = int(n / cell) + 4
        centres = (np.arange(m) - 1.5) * cell
        w = np.exp(-0.5 * ((np.arange(n)[:, None] - centres[None, :]) / (0.8 * cell)) ** 2)
        return (w / np.sqrt((w * w).sum(axis=1, keepdims=True))).astype(np.float32)
    wy = [weights(height, c) for c, _ in octaves]
    wx = [weights(width, c) for c, _ in octaves]
    grid = np.zeros((sum(a.shape[1] for a in wy), sum(a.shape[1] for a in wx)), np.float32)
    i = j = 0
    for (_, amp), a, b in zip(octaves, wy, wx, strict=True):
        grid[i:i + a.shape[1], j:j + b.shape[1]] = amp * rng.standard_normal((a.shape[1], b.shape[1]), dtype=np.float32)
        i, j = i + a.shape[1], j + b.shape[1]
    return np.asarray((np.concatenate(wy, axis=1) @ grid) @ np.concatenate(wx, axis=1).T, dtype=np.float32)


def _upsample(small: F32, f: int, height: int, width: int) -> F32:
    """Bilinear upsampling by the integer factor ``f`` (pixel centres aligned), cut to size."""
    def axis(n_out: int, n_in: int) -> tuple[NDArray[np.intp], NDArray[np.intp], F32]:
        pos = np.clip((np.arange(n_out) + 0.5) / f - 0.5, 0.0, n_in - 1.0)
        i0 = np.floor(pos).astype(np.intp)
        return i0, np.minimum(i0 + 1, n_in - 1), (pos - i0).astype(np.float32)
    r0, r1, wr = axis(height, small.shape[0])
    rows = small[r0] * (1.0 - wr)[:, None] + small[r1] * wr[:, None]
    c0, c1, wc = axis(width, small.shape[1])
    return np.asarray(rows[:, c0] * (1.0 - wc) + rows[:, c1] * wc, dtype=np.float32)


# ---------------------------------------------------------------------------------------------
# the leaf's colours and texture
# ---------------------------------------------------------------------------------------------

def _hsv(h: float, s: float, v: float) -> Arr:
    """HSV (hue in degrees) to RGB."""
    k = (np.array([5.0, 3.0, 1.0]) + h / 60.0) % 6.0
    return v - v * s * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)


def _palette(rng: np.random.Generator, face_down: bool) -> dict[str, Arr]:
    hue = float(rng.uniform(72.0, 130.0))
    sat, val = float(rng.uniform(0.5, 0.85)), float(rng.uniform(0.26, 0.52))
    base = _hsv(hue + rng.uniform(-14.0, 4.0), sat * rng.uniform(0.85, 1.05), min(val * rng.uniform(1.0, 1.3), 0.7))
    apex = _hsv(hue + rng.uniform(-6.0, 10.0), sat * rng.uniform(0.9, 1.1), val * rng.uniform(0.8, 1.05))
    vein = _hsv(float(rng.uniform(62.0, 88.0)), float(rng.uniform(0.35, 0.6)), min(val * rng.uniform(1.4, 1.9), 0.85))
    if face_down:
        pale = _hsv(hue - 10.0, 0.25, 0.68)
        mix = float(rng.uniform(0.35, 0.55))
        base, apex = base + (pale - base) * mix, apex + (pale - apex) * mix
        vein = vein + (np.array([0.85, 0.88, 0.7]) - vein) * 0.4
    petiole = base * rng.uniform(0.7, 0.95) + (np.array([0.35, 0.38, 0.12]) - base) * rng.uniform(0.1, 0.35)
    return {"base": base, "apex": apex, "vein": vein, "petiole": petiole}


def _col(rgb: Arr) -> F32:
    """An RGB colour as a float32 column (3, 1), to scale planar pixels."""
    return np.asarray(rgb, np.float32).reshape(3, 1)


def _ramp(x: F32, lo: float, hi: float) -> F32:
    """0 below ``lo``, 1 above ``hi``, linear between."""
    out = (x - np.float32(lo)) * np.float32(1.0 / (hi - lo))
    return np.clip(out, 0.0, 1.0, out=out)


def leaf_rgb(rng: np.random.Generator, leaf: Placed, crop: tuple[int, int, F32], face_down: bool, *,
             veins_drawn: F32 | None = None, dark_veins: bool = False) -> tuple[F32, NDArray[np.intp], Arr]:
    """The blade's colour (3, k) at the k pixels of its crop that it covers (their flat indices
    into the crop, in order): gradient, mottling, veins, spots; and the petiole's colour. Colours
    are planar (one row per channel) so that every operation runs along the pixels.

    ``veins_drawn`` (the crop's shape, 0..1) replaces the procedural veins by given ones (a known
    vein tree, :func:`leafview.fit.synthetic_leaf.tree_veins`; zeros: no veins), drawn darker than
    the blade with ``dark_veins``; the random numbers drawn stay the same."""
    r0, c0, cov = crop
    h, w = cov.shape
    pal = _palette(rng, face_down)
    big = leaf.length
    idx = np.flatnonzero(cov > 0.0)
    rows, cols = np.divmod(idx, w)
    ys = (rows + r0).astype(np.float32) - np.float32(leaf.t[1])
    xs = (cols + c0).astype(np.float32) - np.float32(leaf.t[0])
    mm = leaf.m.astype(np.float32) / np.float32(big)
    xl, yl = mm[0, 0] * xs + mm[0, 1] * ys, mm[1, 0] * xs + mm[1, 1] * ys
    axis = leaf.view.axis
    xr = xl - np.interp(yl, axis[:, 1], axis[:, 0]).astype(np.float32) if np.any(axis[:, 0]) else xl
    v = np.clip(yl, 0.0, 1.0)
    grad = v ** np.float32(rng.uniform(0.6, 1.6))
    rgb = _col(pal["base"]) + _col(pal["apex"] - pal["base"]) * grad
    mottle = _field(rng, h, w, (big / 6.0, 0.07), (big / 22.0, 0.035)).ravel()[idx]

    # distance to the margin (px), coarsely: veins fade before it, the rim is a little darker
    step = 3
    coarse = ndimage.distance_transform_edt(cov[::step, ::step] > 0.5).astype(np.float32) * step
    edge = coarse.ravel()[(rows // step) * coarse.shape[1] + cols // step]

    a = np.abs(xr)
    # vein widths (px) are kept at 0.8 px or more, their strength cut in proportion below that
    mid_true = big * (0.007 * (1.0 - v) + 0.0016 * v)
    mid_w = np.maximum(mid_true, 0.8)
    q = a * big / mid_w
    vm = np.exp(-q * q) * _ramp(1.0 - yl, 0.0, 0.06) * (mid_true / mid_w)
    n_sec, k, c = float(rng.uniform(6.0, 13.0)), float(rng.uniform(0.45, 1.2)), float(rng.uniform(0.5, 3.0))
    wobble = _field(rng, h, w, (big / 5.0, 0.25)).ravel()[idx]           # in vein spacings
    phase = (yl - (k + c * a) * a) * np.float32(n_sec) + wobble
    phase[xr <= 0] += np.float32(rng.uniform())
    slope = k + 2.0 * c * a
    q = np.abs(phase - np.round(phase)) * np.float32(big / n_sec) / np.sqrt(1.0 + slope * slope)
    sec_true = big * 0.0024 * (1.0 - 0.6 * np.minimum(a / 0.45, 1.0))
    sec_w = np.maximum(sec_true, 0.8)
    q /= sec_w
    vs = np.exp(-q * q) * _ramp(v, 0.02, 0.1) * _ramp(edge, 0.0, 0.05 * big) * (sec_true / sec_w)
    q = _field(rng, h, w, (max(big / 70.0, 3.0), 1.0 / 0.12)).ravel()[idx]
    vt = np.exp(-q * q) * _ramp(edge, 0.0, 0.02 * big)
    veins = np.maximum(np.maximum(vm, 0.85 * vs), 0.22 * vt)
    # the blade between two secondaries bulges a little: lighter in the middle of each band
    bands = 1.0 + np.float32(rng.uniform(0.0, 0.06)) * np.cos(np.float32(2.0 * math.pi) * phase)
    if veins_drawn is not None:
        veins, bands = veins_drawn.ravel()[idx], np.ones_like(bands)
    vein_rgb = _col(pal["base"] * 0.45 if dark_veins else pal["vein"])
    rim = (1.0 - 0.15 * (1.0 - _ramp(edge, 0.0, 2.5))) * bands

    if face_down:
        contrast = float(rng.uniform(0.55, 0.85))
        rgb *= (1.0 + 0.6 * mottle) * rim
        plane = np.zeros(h * w, np.float32)
        plane[idx] = veins
        gy, gx = np.gradient(plane.reshape(h, w))
        light = float(rng.uniform(0.0, 2.0 * math.pi))
        emboss = 1.0 + 0.35 * (gx.ravel()[idx] * math.cos(light) + gy.ravel()[idx] * math.sin(light))
        rgb += (vein_rgb - rgb) * (contrast * veins)
        rgb *= emboss
    else:
        contrast = float(rng.uniform(0.3, 0.6))
        rgb *= (1.0 + mottle) * rim
        rgb += (vein_rgb - rgb) * (contrast * veins)
        gloss = np.clip(_field(rng, h, w, (big / 3.0, 1.0)).ravel()[idx], 0.0, None) ** 2
        rgb += float(rng.uniform(0.0, 0.06)) * gloss
    if rng.random() < 0.3:                       # a few brown spots (the leaf stays the leaf)
        spot = _col(np.array([0.42, 0.33, 0.14]))
        for _ in range(int(rng.integers(1, 5))):
            cy, cx = rng.uniform(0.0, h), rng.uniform(0.0, w)
            rad = big * float(rng.uniform(0.006, 0.02))
            near = slice(*np.searchsorted(rows, (cy - rad, cy + rad)))       # rows come sorted
            d = np.hypot(rows[near] - cy, cols[near] - cx).astype(np.float32)
            s = (1.0 - _ramp(d, 0.6 * rad, rad)) * (edge[near] > rad)
            rgb[:, near] += (spot - rgb[:, near]) * (0.8 * s)
    return np.clip(rgb, 0.0, 1.0, out=rgb), idx, pal["petiole"]


# ---------------------------------------------------------------------------------------------
# paper, light, shadow, debris
# ---------------------------------------------------------------------------------------------

def paper_surface(rng: np.random.Generator, h: int, w: int, background: str) -> tuple[Arr, F32, dict[str, Any]]:
    """The paper's albedo (RGB) and its grain (a factor about 1): low-frequency cloudiness and
    per-pixel fibre noise (the camera's blur softens it)."""
    albedo = np.array(BACKGROUNDS[background]) * rng.uniform(0.97, 1.03, 3)
    albedo[1] = min(albedo[1], max(albedo[0], albedo[2]))       # never greenish
    short = min(h, w)
    grain = _field(rng, h, w, (short / 5.0, 0.02), (short / 14.0, 0.01))
    fibre = np.float32(rng.uniform(0.006, 0.02) * math.sqrt(12.0))     # uniform noise of that deviation
    grain += 1.0 + fibre * (rng.random((h, w), dtype=np.float32) - np.float32(0.5))
    return albedo, grain, {"background": background, "paper_rgb": [round(float(x), 4) for x in albedo]}


def illumination(rng: np.random.Generator, h: int, w: int) -> tuple[F32, Arr, dict[str, Any]]:
    """Uneven light: a gain, vignetting, a linear gradient and a faint cloud (a factor per pixel),
    and a warm/cool colour cast that leaves green alone."""
    gain, vig = float(rng.uniform(0.9, 1.04)), float(rng.uniform(0.0, 0.25))
    g = rng.uniform(-0.08, 0.08, 2)
    cast = float(rng.uniform(-0.03, 0.03))
    y = (np.arange(h, dtype=np.float32) / h - 0.5)[:, None]
    x = (np.arange(w, dtype=np.float32) / w - 0.5)[None, :]
    light = ((1.0 - vig * 2.0 * y * y) * (1.0 + g[1] * y)) * (gain * (1.0 - vig * 2.0 * x * x) * (1.0 + g[0] * x))
    light *= 1.0 + _field(rng, h, w, (min(h, w) / 2.0, 0.03))
    return light, np.array([1.0 + cast, 1.0, 1.0 - cast]), {"gain": gain, "vignetting": vig,
                                                               "gradient": g.tolist(), "cast": cast}


def drop_shadow(rng: np.random.Generator, alpha: F32,
            box: tuple[int, int, int, int]) -> tuple[tuple[int, int, F32], dict[str, Any]]:
    """A soft drop shadow (0 none, 1 black): the leaves' coverage, offset, blurred and scaled,
    computed at a quarter of the resolution (it is smooth) over the leaves' bounding ``box``
    (rows r0:r1, columns c0:c1) grown by the offset and the blur. Returns (row0, col0, crop)."""
    h, w = alpha.shape
    f = 4
    short = min(h, w)
    angle = float(rng.uniform(0.0, 2.0 * math.pi))
    dist, sigma, strength = (float(rng.uniform(0.005, 0.025)) * short, float(rng.uniform(0.004, 0.02)) * short,
                             float(rng.uniform(0.2, 0.5)))
    pad = int(dist + 3.0 * sigma) + 2 * f
    r0, r1 = max(box[0] - pad, 0) // f * f, min(box[1] + pad, h)
    c0, c1 = max(box[2] - pad, 0) // f * f, min(box[3] + pad, w)
    hp, wp = -(-(r1 - r0) // f) * f, -(-(c1 - c0) // f) * f
    part = np.zeros((hp, wp), np.float32)
    part[:r1 - r0, :c1 - c0] = alpha[r0:r1, c0:c1]
    small = part.reshape(hp // f, f, wp // f, f).mean(axis=(1, 3))
    small = ndimage.shift(small, (dist * math.sin(angle) / f, dist * math.cos(angle) / f), order=1)
    small = ndimage.gaussian_filter(np.clip(small, 0.0, 1.0) * strength, sigma / f)
    info = {"offset_px": [dist * math.cos(angle), dist * math.sin(angle)], "blur_px": sigma, "strength": strength}
    return (r0, c0, _upsample(small.astype(np.float32), f, r1 - r0, c1 - c0)), info


def _debris_colour(rng: np.random.Generator) -> Arr:
    if rng.random() < 0.55:                      # browns: red > green > blue
        r = float(rng.uniform(0.22, 0.55))
        return np.array([r, r * rng.uniform(0.62, 0.8), r * rng.uniform(0.35, 0.6)])
    grey = float(rng.uniform(0.04, 0.5))      # greys and blacks, green a little below red and blue
    return grey * np.array([rng.uniform(1.0, 1.04), rng.uniform(0.94, 0.98), rng.uniform(0.98, 1.04)])


def scatter_debris(rng: np.random.Generator, paper: F32, keepout: NDArray[np.bool_], cell: int, light: F32,
            cast: Arr) -> dict[str, int]:
    """Specks, crumbs and hairs painted onto the lit, planar (3, h, w) ``paper`` (in place; their colours lit by
    ``light`` and ``cast``), none on a ``keepout`` cell."""
    h, w = paper.shape[1:]
    counts = {"speck": 0, "crumb": 0, "hair": 0}
    wanted = int(rng.integers(0, 31))
    for _ in range(wanted * 3):
        if sum(counts.values()) >= wanted:
            break
        kind = str(rng.choice(["speck", "speck", "crumb", "hair"]))
        colour = _debris_colour(rng).astype(np.float32)
        if kind == "hair":
            n = int(rng.integers(6, 14))
            length = float(rng.uniform(15.0, 0.15 * min(h, w) + 15.0))
            start = rng.uniform((0.0, 0.0), (w, h))
            heading = float(rng.uniform(0.0, 2.0 * math.pi)) + np.cumsum(rng.normal(0.0, 0.25, n))
            pts = start + np.cumsum(np.stack([np.cos(heading), np.sin(heading)], 1) * length / n, axis=0)
        else:
            rad = float(rng.uniform(0.5, 1.8)) if kind == "speck" else float(rng.uniform(1.5, 4.5))
            centre = rng.uniform((0.0, 0.0), (w, h))
            lumps = 1 if kind == "speck" else int(rng.integers(4, 12))
            pts = centre + rng.normal(0.0, 0.5 * rad, (lumps, 2))
        if np.any((pts < 8) | (pts > (w - 9, h - 9))):
            continue
        cells = (pts // cell).astype(np.int64)
        if np.any(keepout[cells[:, 1], cells[:, 0]]):
            continue
        colour = (colour * cast * light[int(pts[0, 1]), int(pts[0, 0])]).astype(np.float32)
        if kind == "hair":
            opacity = float(rng.uniform(0.5, 0.95))
            for (xa, ya), (xb, yb) in zip(pts[:-1], pts[1:], strict=True):
                rr, cc, val = line_aa(int(round(ya)), int(round(xa)), int(round(yb)), int(round(xb)))
                a = (opacity * val).astype(np.float32)
                paper[:, rr, cc] = paper[:, rr, cc] * (1.0 - a) + _col(colour) * a
        else:
            for cx, cy in pts:
                r = rad * float(rng.uniform(0.25, 0.7)) if lumps > 1 else rad
                y0, y1, x0, x1 = int(cy - r - 2), int(cy + r + 3), int(cx - r - 2), int(cx + r + 3)
                d = np.hypot(np.arange(y0, y1)[:, None] - cy, np.arange(x0, x1)[None, :] - cx)
                a = np.clip(r + 0.5 - d, 0.0, 1.0).astype(np.float32) * np.float32(rng.uniform(0.7, 1.0))
                lump = colour[:, None, None] * np.float32(rng.uniform(0.8, 1.15))
                paper[:, y0:y1, x0:x1] = paper[:, y0:y1, x0:x1] * (1.0 - a) + lump * a
        counts[kind] += 1
    return counts
