"""A leaf's back texture from a second photo of the same leaf, turned over.

:func:`back_texture` traces the back photo as :func:`leafview.fit.photo.fit_image` traces the
front (:func:`leafview.fit.photo_outline.leaf_outline`: mask, outline, base and apex, which
``base`` / ``apex`` replace; a lobed leaf's landmarks from
:func:`leafview.fit.photo_lobed.lobed_landmarks`) and takes its canonical frame
(:func:`leafview.fit.photo.canonical_frame`: base to (0, 0), apex to (0, 1)); where neither
landmark is given, the frame with base and apex swapped is tried too, and so is the front fit's
outline laid onto the back's blade without landmarks (centroid on centroid, the scale from the
areas, the turn of best IoU); the frame whose mirrored outline matches the back's blade best (IoU,
below) is kept, and base and apex are where it puts them. A leaf turned over
about its midrib shows its sides swapped: the leaf point (x, y) of the front fit lies at (-x, y)
of the back photo's canonical frame. So the back photo's ``pixel_from_leaf`` is the inverse of its
frame after the mirror diag(-1, 1), and the texture is resampled through the front fit's own
surface exactly as the front's is (:func:`leafview.fit.photo_texture.leaf_texture`, or
:func:`~leafview.fit.photo_texture.lobed_texture` for a lobed leaf).

The renderer's back face reads its layer at the same (u, v) as the front face
(``shaders/leaf_texture.glsl``: :func:`leafview.core.texture.texture_st` for both), so texel
(s, t) of the back texture shows the back photo at the leaf point (u, v) = ``uv_of_st(s, t)``:
the texture is stored in the front's layout, not mirrored; the mirror lives in the pixel map.

**Refusal.** The back photo must show the same leaf: the front fit's margin, mapped into the back
photo through that map, must cover the back photo's traced blade with an IoU of at least
:data:`BACK_MIN_IOU`; else a :class:`~leafview.errors.ParamError` names the back photo.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from shapely.geometry import Polygon

from leafview.botany.lobe_sweep import sweep_table
from leafview.errors import ParamError
from leafview.fit.photo import MIN_LENGTH_PX, MIRROR, ImageFit, canonical_frame, margin_pixels, top_view_iou
from leafview.fit.photo_io import Photo, as_photo
from leafview.fit.photo_lobed import lobe_measures, lobed_landmarks
from leafview.fit.photo_outline import LeafOutline, leaf_outline
from leafview.fit.photo_texture import leaf_texture, lobed_texture

__all__ = ["BackFit", "back_fit", "back_texture", "BACK_MIN_IOU"]

# The front fit's margin against the back photo's traced blade. Measured on seeded synthetic pairs
# (fit_image on synthetic_photo with the true landmarks; the back from leafview.fit.synthetic_back,
# 500 px, JPEG, its landmarks found here): 18 backs of the same 6 leaves (preset, asymmetric,
# landmark, serrated) reach 0.947 (serrated: teeth the model leaves out) to 0.994, 6 backs of 3
# lobed leaves 0.968 to 0.986; the backs of the 30 other pairings at most 0.86. 0.9 lies about
# halfway: 0.047 below the worst match and 0.04 above the best mismatch.
BACK_MIN_IOU = 0.9
_TURN_STEP = 4.0                       # degrees between the turns tried when registering the outline

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class BackFit:
    """What :func:`back_fit` found: ``texture`` (T, T, 4) float32 RGBA in the front's layout,
    ``outline`` the leaf traced in the back photo, ``pixel_from_leaf`` (3 × 3, front leaf frame to
    back photo pixels, the mirror included), ``iou`` (the front fit's margin against the back
    photo's blade) and ``photo``."""

    texture: NDArray[np.float32]
    outline: LeafOutline
    pixel_from_leaf: F64
    iou: float
    photo: Photo

    def report(self) -> dict[str, Any]:
        return {"photo": os.path.basename(self.photo.path) if self.photo.path else None,
                "iou": round(self.iou, 5), "base_px": [round(float(c), 3) for c in self.outline.base],
                "apex_px": [round(float(c), 3) for c in self.outline.apex]}


def _similarity(scale: float, angle: float, leaf_point: F64, pixel: F64) -> F64:
    """3 × 3: leaf space to pixels, the mirror first, then a turn by ``angle`` and ``scale`` with
    y flipped (pixels run down), taking ``leaf_point`` to ``pixel``."""
    c, s = math.cos(angle), math.sin(angle)
    lin = scale * np.array([[c, -s], [s, c]]) @ np.diag([1.0, -1.0]) @ MIRROR[:2, :2]
    m = np.eye(3)
    m[:2, :2] = lin
    m[:2, 2] = pixel - lin @ leaf_point
    return m


def _registered(fit: ImageFit, traced: LeafOutline) -> tuple[float, F64, LeafOutline]:
    """The front fit's outline laid onto the back photo's blade without landmarks: centroid on
    centroid, the scale from the two areas, the turn that gives the best IoU (every
    :data:`_TURN_STEP` degrees, then to a tenth of that); the landmarks are where base and apex
    land. For a back photo whose base or apex was found in the wrong place."""
    ring = margin_pixels(fit.parts, np.eye(3))                     # the fitted outline in leaf space
    outline = Polygon(ring)
    area = float(outline.area)
    if not area > 0.0 or not traced.blade.any():
        return 0.0, np.eye(3), traced
    centre = np.array(outline.centroid.coords[0], np.float64)
    rows, cols = np.nonzero(traced.blade)
    target = np.array([cols.mean(), rows.mean()])
    scale = math.sqrt(len(rows) / area)

    def score(angle: float) -> tuple[float, F64]:
        m = _similarity(scale, angle, centre, target)
        return top_view_iou(ring @ m[:2, :2].T + m[:2, 2], traced.blade), m

    step = math.radians(_TURN_STEP)
    best = max((score(a) + (a,) for a in np.arange(0.0, 2.0 * math.pi, step)), key=lambda item: item[0])
    best = max((score(a) + (a,) for a in best[2] + np.linspace(-step, step, 21)), key=lambda item: item[0])
    m = best[1]
    base, apex = m[:2, 2].copy(), m[:2, 2] + m[:2, 1]   # the leaf points (0, 0) and (0, 1)
    placed = replace(traced, base=base, apex=apex)
    frame_m = np.asarray(np.linalg.inv(canonical_frame(base, apex)) @ MIRROR, np.float64)
    return top_view_iou(margin_pixels(fit.parts, frame_m), traced.blade), frame_m, placed


def back_fit(fit: ImageFit, back_photo: Photo | str | os.PathLike[str] | NDArray[Any], *,
             base: ArrayLike | None = None, apex: ArrayLike | None = None,
             texture_size: int | None = None) -> BackFit:
    """The back texture of ``fit``'s leaf from ``back_photo`` and the measures behind it (see the
    module docstring). ``texture_size`` defaults to the front texture's side."""
    size = int(fit.texture.shape[0]) if texture_size is None else texture_size
    photo = as_photo(back_photo)
    source = photo.path or None
    where = "" if source else "back_photo"
    traced = leaf_outline(photo, base=base, apex=apex)
    leaf = fit.parts[0]
    if leaf.lobes.enabled and base is None and apex is None:
        b, a = lobed_landmarks(traced.outline, traced.petiole, lobe_measures(traced.outline))
        traced = replace(traced, base=np.asarray(b, np.float64), apex=np.asarray(a, np.float64))
    length_px = float(np.hypot(*(traced.apex - traced.base)))
    if not length_px >= MIN_LENGTH_PX:
        raise ParamError(where, f"the back's leaf is {length_px:.1f} px from base to apex; at least "
                                f"{MIN_LENGTH_PX:g} px are needed", source)
    # without given landmarks, base and apex are also tried the other way round: a blade without a
    # petiole can show its base and apex alike, and the front fit's outline tells them apart
    tries = [traced] if base is not None or apex is not None else [traced, replace(traced, base=traced.apex,
                                                                                   apex=traced.base)]
    scored = []
    for t in tries:
        m = np.asarray(np.linalg.inv(canonical_frame(t.base, t.apex)) @ MIRROR, np.float64)
        scored.append((top_view_iou(margin_pixels(fit.parts, m), t.blade), m, t))
    if len(tries) == 2:
        scored.append(_registered(fit, traced))
    iou, pixel_from_leaf, traced = max(scored, key=lambda item: item[0])
    if iou < BACK_MIN_IOU:
        raise ParamError(where, f"the back photo does not show the fitted leaf turned over: the front's outline, "
                                f"mirrored about its midrib, covers the leaf traced here with an IoU of {iou:.2f} "
                                f"(at least {BACK_MIN_IOU:g} is accepted); photograph the same leaf face down, or "
                                "give its base and apex (--back-base, --back-apex)", source)
    if leaf.lobes.enabled:
        texture = lobed_texture(photo.rgb, traced.mask, pixel_from_leaf, sweep_table(leaf.lobes).window, size)
    else:
        texture = leaf_texture(photo.rgb, traced.mask, fit.parts, pixel_from_leaf, size)
    return BackFit(texture, traced, pixel_from_leaf, iou, photo)


def back_texture(fit: ImageFit, back_photo: Photo | str | os.PathLike[str] | NDArray[Any], *,
                 base: ArrayLike | None = None, apex: ArrayLike | None = None,
                 texture_size: int | None = None) -> NDArray[np.float32]:
    """The back texture (T, T, 4) float32 RGBA (sRGB colours, alpha from the back photo's mask) of
    ``fit``'s leaf, resampled from ``back_photo``, a photo of the same leaf turned over about its
    midrib; ``base`` / ``apex`` ((x, y) back photo pixels) replace the landmarks found there.
    Raises :class:`~leafview.errors.ParamError` naming the back photo when it shows another leaf
    (:data:`BACK_MIN_IOU`)."""
    return back_fit(fit, back_photo, base=base, apex=apex, texture_size=texture_size).texture
