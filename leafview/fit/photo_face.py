"""Which side of a leaf faces the camera: raised veins lit from one side, or flat ones.

A leaf's underside carries its veins raised; under light from one side each raised vein shows a
lighter flank towards the light and a darker one away from it, an odd (light/dark) profile
across the vein, the same way round on every vein of the leaf because there is one light. Its
upper side carries the veins flat (or nearly so): a vein differs from the blade by its pigment,
an even profile (a lighter or darker line) with no such pair.

The cue is separated from the vein's own colour by the pigment's chromaticity: shading multiplies
the three channels alike and leaves log chromaticity (log R/G, log B/G) unchanged, while the
vein's pigment changes it. So, on the blade's band-passed log images (a difference of Gaussians,
:data:`SIGMA_FINE` and :data:`SIGMA_COARSE` pixels), the log luminance ``l`` is regressed on

* the even terms: the two log chromaticities ``c1``, ``c2`` (a flat vein: lightness that follows
  the pigment), then
* the odd terms: their gradients ``∂c/∂x``, ``∂c/∂y`` (a raised vein under one light direction
  L: shading ``∇(vein) · L`` follows the derivative of the pigment pattern, one L for the leaf).

``odd`` is the share of ``l``'s energy the odd terms explain beyond the even ones; ``even`` the
share the even terms explain. A four-parameter fit over n pixels explains about 4/n_eff of pure
noise, so the score is ``odd × n`` (n the blade pixels used): about the χ² of the odd terms times
the pixels per independent sample. ``score ≥`` :data:`DOWN_SCORE`: face down; ``≤``
:data:`UP_SCORE`: face up; between: ``unknown`` (the fit then assumes face up). Paleness is not
used, not even as a secondary cue (but see the limits: an additive pale tint can mimic the cue).

Cost: the blade, less a rim of 2 % of the leaf's length (the margin's darker rim, the shadow), is
cut into tiles of :data:`TILE` pixels (with a halo), at most :data:`MAX_TILES` of them spread over
the blade (about 24 000 pixels read), so the cost stays bounded on a large photo: about 7 ms of
CPU a photo (4 % of the fit). A verdict of ``unknown`` is looked at once more over up to
:data:`MAX_TILES_AGAIN` tiles (a weak pair is a matter of sample size: the score grows with the
pixels where there is relief and stays put where there is none): 8-10 ms a photo on average.

Limits: a shift between the chromaticity and the luminance of the photo (JPEG's 4:2:0 chroma,
a lens's lateral chromatic aberration) is modelled by the odd terms exactly as a light direction
is; an additive pale tint over a face-up leaf (pixel = 0.45 rgb + 0.5 paper-like colour) made
it read as face down on 5 of 7 JPEG photos (scores 81-253; a multiplicative, desaturating paling
gave 1-43). Real upper sides with sunken (impressed) veins also give a light/dark pair, of the other
sign relative to the light; without the light's direction (the sign of L is not known here) they
would read as face down. Under diffuse light, raised veins give no pair and the answer is
``up`` or ``unknown``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

__all__ = ["FaceEstimate", "detect_face", "FACES", "DOWN_SCORE", "UP_SCORE", "SIGMA_FINE", "SIGMA_COARSE",
           "TILE", "MAX_TILES", "MAX_TILES_AGAIN", "MIN_PIXELS"]

FACES = ("auto", "up", "down")
SIGMA_FINE = 2.0        # px: the difference of Gaussians keeps veins of a few pixels
SIGMA_COARSE = 4.0
TILE = 32               # px: tiles of the blade analysed (plus a halo of _HALO px each side)
MAX_TILES = 24
MAX_TILES_AGAIN = 96    # an unknown verdict is looked at again over up to this many tiles
_HALO = 10
_STEP = 4               # px: the mask is eroded on every _STEP-th pixel
# Thresholds on odd × n, measured on seeded synthetic photos, landmarks found by the fit.
# synthetic_photo(seed, size=(700, 700)), seeds 10000-10127: face up (91) scored 0-108 (three above
# 70), face down (37) 0-904 over 24 tiles; with these thresholds and the second look over up to 96
# tiles, face up 75 right, 1 wrong, 15 unknown, face down 17 right, 3 wrong (called up), 17
# unknown; held out, seeds 10128-10255: up 73 / 2 / 14, down 19 / 6 / 14. The fit bench's 24
# photos: see `leafview bench fit`.
DOWN_SCORE = 90.0
UP_SCORE = 17.0
MIN_PIXELS = 2000       # fewer blade pixels read: unknown

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class FaceEstimate:
    """What :func:`detect_face` found: ``face`` ('up', 'down' or 'unknown'), ``score`` (odd × n),
    ``odd`` and ``even`` (shares of the band-passed log luminance's energy explained by the odd
    and the even terms), ``pixels`` (n), ``light_deg`` (the fitted light direction in photo
    pixels, x right, y down; meaningful only face down) and ``reason`` (why unknown)."""

    face: str
    score: float
    odd: float
    even: float
    pixels: int
    light_deg: float | None
    reason: str = ""

    def report(self) -> dict[str, Any]:
        return {"face": self.face, "score": round(self.score, 3), "odd": float(f"{self.odd:.4g}"),
                "even": round(self.even, 5), "pixels": self.pixels,
                "light_deg": None if self.light_deg is None else round(self.light_deg, 1),
                **({"reason": self.reason} if self.reason else {})}


def _tiles(inner: NDArray[np.bool_], limit: int) -> list[tuple[int, int]]:
    """Top-left corners of the tiles whose centre lies in ``inner``, at most ``limit`` of them,
    spread evenly over the blade."""
    h, w = inner.shape
    corners = [(r, c) for r in range(_HALO, max(h - _HALO - TILE, _HALO) + 1, TILE)
               for c in range(_HALO, max(w - _HALO - TILE, _HALO) + 1, TILE)
               if inner[min(r + TILE // 2, h - 1), min(c + TILE // 2, w - 1)]]
    if len(corners) > limit:
        pick = np.round(np.linspace(0, len(corners) - 1, limit)).astype(int)
        corners = [corners[i] for i in pick]
    return corners


def detect_face(rgb: NDArray[np.floating], blade: NDArray[np.bool_], leaf_from_pixel: ArrayLike) -> FaceEstimate:
    """Which side of the leaf faces the camera (see the module docstring). ``rgb`` (h, w, 3)
    float sRGB in [0, 1]; ``blade`` (h, w) the blade's mask; ``leaf_from_pixel`` the fit's 3 × 3
    canonical frame (its scale gives the leaf's length in pixels, which sets how far from the
    margin the blade is read)."""
    m = np.asarray(leaf_from_pixel, np.float64)
    length_px = 1.0 / max(float(np.hypot(m[0, 0], m[1, 0])), 1e-12)
    coarse = blade[::_STEP, ::_STEP]                  # the bounding box and the inner blade on every 4th pixel
    rows, cols = np.flatnonzero(coarse.any(axis=1)), np.flatnonzero(coarse.any(axis=0))
    if len(rows) == 0:
        return FaceEstimate("unknown", 0.0, 0.0, 0.0, 0, None, "no blade")
    r0, r1 = max(int(rows[0]) * _STEP - _HALO - _STEP, 0), min(int(rows[-1]) * _STEP + _HALO + _STEP + 1, blade.shape[0])
    c0, c1 = max(int(cols[0]) * _STEP - _HALO - _STEP, 0), min(int(cols[-1]) * _STEP + _HALO + _STEP + 1, blade.shape[1])
    keep = max(1, int(math.ceil(0.02 * length_px / _STEP)))   # the margin's rim and shadow left out
    small = ndimage.minimum_filter(coarse.view(np.uint8), size=2 * keep + 1).astype(bool)
    lo_r, lo_c = r0 // _STEP, c0 // _STEP
    block = small[lo_r:(r1 - 1) // _STEP + 1, lo_c:(c1 - 1) // _STEP + 1]
    up = np.repeat(np.repeat(block, _STEP, axis=0), _STEP, axis=1)
    inner = up[r0 - lo_r * _STEP:r1 - lo_r * _STEP, c0 - lo_c * _STEP:c1 - lo_c * _STEP] & blade[r0:r1, c0:c1]
    corners = _tiles(inner, MAX_TILES)
    if not corners:
        return FaceEstimate("unknown", 0.0, 0.0, 0.0, 0, None, "the blade is too small to read its veins")
    crop = rgb[r0:r1, c0:c1]
    estimate = _estimate(crop, inner, corners)
    if estimate.face == "unknown" and estimate.pixels >= MIN_PIXELS:
        more = _tiles(inner, MAX_TILES_AGAIN)       # a weak pair over more of the blade: a larger sample
        if len(more) > len(corners):
            estimate = _estimate(crop, inner, more)
    return estimate


def _estimate(crop: NDArray[np.floating], inner: NDArray[np.bool_], corners: list[tuple[int, int]]) -> FaceEstimate:
    """The verdict from the tiles at ``corners`` of ``crop`` (the blade's bounding box), their
    pixels inside ``inner``: the even and odd fits of the module docstring."""
    side = TILE + 2 * _HALO
    stack = np.empty((len(corners), side, side, 3), np.float32)
    inside = np.zeros((len(corners), side, side), bool)
    for k, (r, c) in enumerate(corners):
        tile = crop[r - _HALO:r + TILE + _HALO, c - _HALO:c + TILE + _HALO]
        stack[k, :tile.shape[0], :tile.shape[1]] = tile
        stack[k, tile.shape[0]:], stack[k, :, tile.shape[1]:] = 0.5, 0.5
        inside[k, _HALO:_HALO + TILE, _HALO:_HALO + TILE] = inner[r:r + TILE, c:c + TILE]
    logs = np.log(np.maximum(stack, np.float32(1.0 / 255.0)))
    planes = np.stack([logs.sum(axis=-1), logs[..., 0] - logs[..., 1], logs[..., 2] - logs[..., 1]])
    fine = ndimage.gaussian_filter(planes, (0.0, 0.0, SIGMA_FINE, SIGMA_FINE), truncate=2.5)
    s = math.sqrt(SIGMA_COARSE ** 2 - SIGMA_FINE ** 2)
    band = fine - ndimage.gaussian_filter(fine, (0.0, 0.0, s, s), truncate=2.5)
    gy1, gx1 = np.gradient(band[1], axis=(1, 2))
    gy2, gx2 = np.gradient(band[2], axis=(1, 2))
    x = np.stack([band[1][inside], band[2][inside], gx1[inside], gy1[inside], gx2[inside], gy2[inside],
                  band[0][inside]], axis=1).astype(np.float64)
    n = len(x)
    if n < MIN_PIXELS:
        return FaceEstimate("unknown", 0.0, 0.0, 0.0, n, None, "the blade is too small to read its veins")
    g = x.T @ x
    total = float(g[6, 6])
    if not total > 0.0:
        return FaceEstimate("unknown", 0.0, 0.0, 0.0, n, None, "the blade shows no texture")
    eye = 1e-12 * total * np.eye(6)
    c_even = np.linalg.solve(g[:2, :2] + eye[:2, :2], g[:2, 6])
    c_full = np.linalg.solve(g[:6, :6] + eye, g[:6, 6])
    even = float(c_even @ g[:2, 6]) / total
    odd = max(float(c_full @ g[:6, 6]) / total - even, 0.0)
    score = odd * n
    # the light: the odd terms' direction weighted by the even terms' (one vector per chromaticity)
    light = c_full[2:4] * np.sign(c_full[0] or 1.0) + c_full[4:6] * np.sign(c_full[1] or 1.0)
    light_deg = math.degrees(math.atan2(float(light[1]), float(light[0])))
    if score >= DOWN_SCORE:
        return FaceEstimate("down", score, odd, even, n, light_deg)
    if score <= UP_SCORE:
        return FaceEstimate("up", score, odd, even, n, None)
    return FaceEstimate("unknown", score, odd, even, n, None,
                        f"the light/dark pairs across the veins are weak ({score:.1f}: up ≤ {UP_SCORE:g}, "
                        f"down ≥ {DOWN_SCORE:g})")
