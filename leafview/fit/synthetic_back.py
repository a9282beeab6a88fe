"""A synthetic photo of a leaf's back: the leaf of a :class:`~leafview.fit.synthetic_photos.SyntheticPhoto`
turned over about its midrib and photographed again, for the back texture's tests.
The whole leaf stays inside the picture (its length chosen from its reach around the blade's middle).

:func:`synthetic_back` takes the front photo's primary leaf (its mask, with the petiole, and its
base and apex) and draws it mirrored (leaf x → -x in the canonical frame of
:func:`leafview.fit.photo.canonical_frame`, base at (0, 0), apex at (0, 1)) at another rotation,
length and position, on another paper, with the paler colour of an underside. The colour is a
known function of the place on the leaf (:func:`back_colour`, in the front photo's leaf frame): a
gradient across the blade (redder towards the front's x > 0 side) and along it, and one dark spot
on the x > 0 side, so a test can tell whether the back photo landed on the right side of the
midrib. The camera is a light blur and Gaussian noise (no JPEG), seeded like the rest.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from leafview.errors import ParamError
from leafview.fit.photo import canonical_frame
from leafview.fit.synthetic_photos import SyntheticPhoto
from leafview.fit.synthetic_surfaces import BACKGROUNDS, paper_surface

__all__ = ["synthetic_back", "back_colour", "BACK_BASE_RGB", "SPOT_RGB"]

BACK_BASE_RGB = (0.56, 0.74, 0.48)     # the underside's colour on the midrib, halfway up (sRGB)
SPOT_RGB = (0.30, 0.40, 0.16)          # the dark spot on the front's x > 0 side
_ACROSS = 0.3                          # red added per leaf length of x (front leaf frame)
_ALONG = 0.12                          # green added per leaf length of y - 0.5

F64 = NDArray[np.float64]


def back_colour(x: ArrayLike, y: ArrayLike, truth: dict[str, Any]) -> F64:
    """The back's colour (..., 3), sRGB in [0, 1], at the leaf point (x, y) of the front photo's
    canonical frame (before the blur and the noise)."""
    xx, yy = np.asarray(x, np.float64), np.asarray(y, np.float64)
    rgb = np.empty(xx.shape + (3,))
    rgb[..., 0] = BACK_BASE_RGB[0] + _ACROSS * xx
    rgb[..., 1] = BACK_BASE_RGB[1] + _ALONG * (yy - 0.5)
    rgb[..., 2] = BACK_BASE_RGB[2]
    sx, sy = truth["spot_leaf"]
    inside = np.hypot(xx - sx, yy - sy) <= truth["spot_radius"]
    rgb[inside] = SPOT_RGB
    return np.clip(rgb, 0.0, 1.0)


def _half_width(front: SyntheticPhoto, frame: F64) -> float:
    """The blade's half-width on its x > 0 side near y = 0.5 (leaf lengths, front frame)."""
    pts = front.outline @ frame[:2, :2].T + frame[:2, 2]
    near = np.abs(pts[:, 1] - 0.5) < 0.08
    right = pts[near & (pts[:, 0] > 0.0), 0]
    return float(right.max()) if right.size else 0.1


def synthetic_back(front: SyntheticPhoto, seed: int, *, size: tuple[int, int] | None = None,
                   background: str | None = None) -> SyntheticPhoto:
    """The back of ``front``'s primary leaf, turned over about its midrib, as a second seeded photo
    (see the module docstring). ``truth`` holds ``back_pixel_from_front_leaf`` (3 × 3: front
    leaf frame to this photo's pixels, the mirror included), ``spot_leaf`` and ``spot_radius``
    (front leaf frame), ``rotation_deg``, ``length_px`` and ``background``."""
    if not np.all(np.isfinite(front.base)) or not front.mask.any():
        raise ParamError("front", "the front photo has no leaf to turn over")
    rng = np.random.default_rng([int(seed), 29])
    w, h = size or (int(front.image.shape[1]), int(front.image.shape[0]))
    background = background or str(rng.choice([b for b in BACKGROUNDS if b != front.truth.get("background")]))
    theta = float(rng.uniform(0.0, 2.0 * math.pi))
    frame = canonical_frame(front.base, front.apex)          # front pixels -> front leaf
    rows, cols = np.nonzero(front.mask)
    reach = float(np.max(np.hypot(frame[0, 0] * cols + frame[0, 1] * rows + frame[0, 2],
                                  frame[1, 0] * cols + frame[1, 1] * rows + frame[1, 2] - 0.5)))
    length = float(rng.uniform(0.75, 0.92)) * 0.42 * min(w, h) / max(reach, 0.5)   # the whole leaf in the picture
    centre = np.array([w / 2.0, h / 2.0]) + rng.uniform(-0.04, 0.04, 2) * min(w, h)
    c, s = math.cos(theta), math.sin(theta)
    # front leaf (x, y) -> back leaf (-x, y) -> back pixels: centre + length · R(θ) · (xb, 0.5 - yb)
    lin = length * np.array([[c, -s], [s, c]]) @ np.diag([1.0, -1.0]) @ np.diag([-1.0, 1.0])
    m = np.eye(3)
    m[:2, :2] = lin
    m[:2, 2] = centre - lin @ np.array([0.0, 0.5])
    front_px_from_back_px = np.linalg.inv(frame) @ np.linalg.inv(m)

    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    fx = front_px_from_back_px[0, 0] * xs + front_px_from_back_px[0, 1] * ys + front_px_from_back_px[0, 2]
    fy = front_px_from_back_px[1, 0] * xs + front_px_from_back_px[1, 1] * ys + front_px_from_back_px[1, 2]
    alpha = ndimage.map_coordinates(front.mask.astype(np.float32), [fy, fx], order=1, cval=0.0)
    blade = ndimage.map_coordinates(front.blade.astype(np.float32), [fy, fx], order=1, cval=0.0) >= 0.5
    leaf_from_back_px = np.linalg.inv(m)
    lx = leaf_from_back_px[0, 0] * xs + leaf_from_back_px[0, 1] * ys + leaf_from_back_px[0, 2]
    ly = leaf_from_back_px[1, 0] * xs + leaf_from_back_px[1, 1] * ys + leaf_from_back_px[1, 2]

    half = _half_width(front, frame)
    truth: dict[str, Any] = {"seed": int(seed), "front_seed": front.truth.get("seed"), "size": [w, h],
                             "background": background, "rotation_deg": math.degrees(theta), "length_px": length,
                             "spot_leaf": [0.5 * half, 0.5], "spot_radius": 0.25 * half,
                             "back_pixel_from_front_leaf": m.tolist(), "face_down": True}
    albedo, grain, _ = paper_surface(rng, h, w, background)
    tilt = rng.uniform(-0.05, 0.05, 2)
    light = 1.0 + tilt[0] * (xs / w - 0.5) + tilt[1] * (ys / h - 0.5)
    paper = (grain * light)[..., None] * albedo[None, None, :]
    leaf = back_colour(lx, ly, truth) * light[..., None]
    img = paper + (leaf - paper) * alpha[..., None]
    img = ndimage.gaussian_filter(img, (0.8, 0.8, 0.0), truncate=2.5)
    img += 0.008 * rng.standard_normal(img.shape)
    image = np.asarray(np.clip(np.rint(img * 255.0), 0, 255), np.uint8)

    outline = (np.c_[front.outline, np.ones(len(front.outline))] @ (m @ frame).T)[:, :2]
    base, apex = m[:2, 2].copy(), m[:2, :2] @ np.array([0.0, 1.0]) + m[:2, 2]
    scale = length / front.length_px
    return SyntheticPhoto(image, alpha >= 0.5, blade, outline, base, apex, length, front.petiole_px * scale,
                          float(max(round(front.dpi * scale), 20)), True, truth, alpha >= 0.5)
