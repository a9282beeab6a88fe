"""A leaf from a photograph or scan: Ω in the canonical frame, its scale and its front texture.

:func:`fit_image` is the whole path (Mündermann et al. 2003, sec. 3.1 and 3.4; Hong 2005, ch. 5):

1. **The leaf in the photo** (:func:`leafview.fit.photo_outline.leaf_outline`): mask, smoothed
   blade outline, base, apex and petiole, in pixels (x right, y down).
2. **The canonical frame**: the similarity ``leaf_from_pixel`` taking the base to (0, 0) and the
   apex to (0, 1), one leaf length to 1. Pixel y runs down and leaf y up, so the map flips y before
   it turns: the leaf keeps the handedness the camera saw, and a leaf photographed face up from
   above comes out face up, its left and right sides where the photo shows them.
   **Face down** (:func:`leafview.fit.photo_face.detect_face` with ``face="auto"``, or
   ``face="down"``): the photo shows the leaf's back, which is the leaf mirrored about its
   midrib, so the frame gets the mirror diag(-1, 1) after the similarity (``leaf_from_pixel =
   MIRROR · frame``, the convention of :mod:`leafview.fit.photo_back`): the outline, its sides,
   the halves of an asymmetric fit (the photo's left side becomes the leaf's right), the texture
   (resampled through the mirrored map, so a texel at (u, v) shows the photo where the leaf point
   (u, v) lies) and the measures all follow from it, and the leaf comes out with the real leaf's
   handedness. The photo's pixels then show the back: they become ``back_texture`` (the layout of
   :func:`leafview.core.texture.texture_st`, as :func:`leafview.fit.photo_back.back_fit` makes it),
   and the front texture holds the same pixels, the only view of the leaf there is. Where the
   detector cannot tell (``unknown``), the leaf is taken as face up.
3. **Ω** (Chaurasia & Beardsley 2017, sec. 3): the outline is split at base and apex into the
   right (x > 0) and left sides; the symmetric model and two one-sided halves (Garg & Leow 2011,
   Fig. 6, as :mod:`leafview.botany.asymmetric` draws them) are fitted together by the batched fit
   of :mod:`leafview.botany.quick_fit`, each with the fewest silhouette rows (3 = the paper's
   quartic, up to 7 extended rows) whose Hausdorff error meets ``target``. The halves replace the
   symmetric leaf only where its error is above the target and they cover the traced blade
   clearly better: the area between fitted margin and outline (their mean distance times the
   outline's length), as a share of the blade's area, is :data:`HALVES_AREA_GAIN` smaller
   (about that much more IoU). A leaf whose sides differ by the outline's noise or a slightly
   misplaced landmark stays one leaf; a narrow leaf whose sides differ by 1 % of its length does
   not. (The batched fit gives the same model as
   :func:`~leafview.botany.outline_fit.fit_outline` in a fraction of the time when the target
   lies below the outline's noise, where ``fit_outline`` polishes every row count.)

   Two touching leaves are refused at four points. The neck test of
   :mod:`leafview.fit.photo_outline` refuses pairs meeting at a narrow neck. Before the fit, a
   region that parts between two notches into two convex blades
   (:func:`leafview.fit.photo_shape.two_blades`) is refused, and so is one that looks lobed or is
   notched twice (:func:`leafview.fit.photo_lobed.two_notches`) but is not mirror-symmetric
   (``lobed="auto"``, landmarks found): its IoU with its mirror image in its best axis
   (:func:`leafview.fit.photo_lobed.symmetry_axis`) is below
   :data:`~leafview.fit.photo_lobed.LOBED_MIN_MIRROR` or
   :data:`~leafview.fit.photo_lobed.NOTCHED_MIN_MIRROR` (two blades in a V, a T or an X). After it, a region that even the
   better of the two fits misses by more than :data:`TOUCHING_FIT_ERROR` leaf lengths is refused,
   unless its outline looks lobed (``lobed="off"`` on a lobed leaf: Ω misses its lobes). Such a
   region is not one leaf with these landmarks: two leaves touching along an edge or overlapping
   widely, or a base and apex found wrongly, which ``base=``/``apex=`` mend.
4. **Petiole and scale**: the petiole's length in leaf lengths becomes ``bending.petiole_length``;
   the photo's dots per inch (from the file, or ``dpi=``) give ``transform.scale``, the leaf's
   length in metres. Without a resolution the leaf is 1 unit long, with a warning.
5. **Texture** (:func:`leafview.fit.photo_texture.leaf_texture`).
6. **Veins** (:func:`leafview.fit.photo_veins.detect_veins`): where the texture shows a pinnate
   vein tree, its secondaries' angle, curvature, count, spacing and loops become the leaf's
   ``venation`` (enabled); where it does not, the venation stays off and the report says why.

The report measures the fit against the traced leaf: the IoU of the fitted top view with the
blade mask, the Hausdorff distance between fitted margin and outline, and per silhouette row the
RMS distance of the outline points nearest that row's stretch of the margin.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from leafview.botany.asymmetric import LEFT_HALF, RIGHT_HALF, with_half
from leafview.botany.lobe_sweep import sweep_table
from leafview.botany.outline_fit import hausdorff, margin
from leafview.botany.quick_fit import quick_fit_outlines
from leafview.core.bspline import sample_closed
from leafview.core.params import SCALE_RANGE, Bending, LeafParams, Transform
from leafview.errors import ParamError
from leafview.fit.blas import single_threaded
from leafview.fit.photo_face import FACES, FaceEstimate, detect_face
from leafview.fit.photo_lobed import (
    LOBED_MIN_MIRROR,
    LOBED_MODES,
    NOTCHED_MIN_MIRROR,
    LobeMeasures,
    fit_lobed_margin,
    lobe_measures,
    lobed_landmarks,
    lobed_leaf,
    looks_lobed,
    symmetry_axis,
    two_notches,
)
from leafview.fit.photo_outline import LeafOutline, Photo, as_photo, leaf_outline
from leafview.fit.photo_shape import BLADES_SOLIDITY, two_blades
from leafview.fit.photo_texture import leaf_texture, lobed_texture
from leafview.fit.photo_veins import VeinEstimate, detect_veins, with_veins

__all__ = ["ImageFit", "fit_image", "canonical_frame", "outline_sides", "margin_pixels", "polygon_mask",
           "top_view_iou", "PHOTO_FIT_TARGET", "HALVES_AREA_GAIN", "TOUCHING_FIT_ERROR", "METRES_PER_INCH",
           "MIN_LENGTH_PX", "DPI_RANGE", "MIRROR"]

PHOTO_FIT_TARGET = 0.01    # Hausdorff error ÷ leaf length accepted when choosing the rows
HALVES_AREA_GAIN = 0.01    # two halves must miss this much less of the blade's area than one symmetric leaf
# The better of the symmetric and the two one-sided fits off the traced outline by more than this
# (÷ leaf length): not one leaf, refused. Measured on the seeded synthetic photos: of 128 single
# leaves (all kinds, faces, petioles, 500-1000 px; the fit bench's 24 among them) 127 fit within
# 2.3 %, one round leaf wider than long, its axis found across it, 8.0 %; the 10 of 64 touching
# pairs that neither the neck nor the two-blades test refuses: 2.7, 4.5, 7.7, 8.5, 11, 12, 16, 19,
# 19 and 20 %. 10 % refuses four of them and leaves the misplaced axis (which --base/--apex mend).
TOUCHING_FIT_ERROR = 0.10
METRES_PER_INCH = 0.0254
MIN_LENGTH_PX = 8.0        # a blade shorter than this (base to apex, in pixels) cannot be fitted
DPI_RANGE = (1.0, 1e6)
MIRROR = np.diag([-1.0, 1.0, 1.0])     # the leaf turned over about its midrib: x -> -x
_SIDE_SAMPLES = 160        # points per side handed to the fit
_MARGIN_SAMPLES = 513      # margin samples for the measures

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ImageFit:
    """What :func:`fit_image` found.

    Attributes
    ----------
    parts
        One leaf, or the right (``shape.half = -1``) and left (``+1``) halves of an asymmetric one;
        canonical frame, ``transform.scale`` the length in metres (1 without a resolution). No
        ``texture`` is set: the texture is an array here, a file only once written.
    texture
        (T, T, 4) float32 RGBA, sRGB colours in [0, 1], laid out as
        :func:`leafview.core.texture.texture_st` says; alpha from the leaf mask.
    outline
        The leaf traced in the photo.
    leaf_from_pixel
        3 × 3: homogeneous photo pixels (x right, y down) to leaf space (x, y).
    report
        JSON-able measures (see :func:`fit_image`).
    warnings
        One line each: cut border, no resolution, clamped petiole, differing sides.
    photo
        The photo the fit was made from.
    back_texture
        Face down (``report["face"] == "down"``): the photo shows the leaf's back, so its texture
        (the same array as ``texture``) is the back texture too; None face up.
    """

    parts: tuple[LeafParams, ...]
    texture: NDArray[np.float32]
    outline: LeafOutline
    leaf_from_pixel: F64
    report: dict[str, Any]
    warnings: tuple[str, ...]
    photo: Photo
    back_texture: NDArray[np.float32] | None = None

    @property
    def asymmetric(self) -> bool:
        """Whether the leaf is drawn as two one-sided halves."""
        return len(self.parts) == 2

    @property
    def pixel_from_leaf(self) -> F64:
        """3 × 3: leaf space (x, y) to photo pixels."""
        return np.asarray(np.linalg.inv(self.leaf_from_pixel), np.float64)

    def margin_pixels(self, n: int = _MARGIN_SAMPLES) -> F64:
        """The fitted margin as a closed polygon (2n - 1, 2) in photo pixels."""
        return margin_pixels(self.parts, self.pixel_from_leaf, n)


# -- the frame ---------------------------------------------------------------------------------------
def canonical_frame(base: ArrayLike, apex: ArrayLike) -> F64:
    """The 3 × 3 similarity taking photo pixels (x right, y down) to leaf space: ``base`` to
    (0, 0), ``apex`` to (0, 1), with y flipped so that the leaf keeps the handedness seen in the
    photo (a rotation of the flipped pixels, never a mirror of what the camera saw)."""
    b = np.asarray(base, np.float64)
    d = np.asarray(apex, np.float64) - b
    length = float(np.hypot(*d))
    if not (np.isfinite(length) and length > 0.0):
        raise ParamError("apex", "base and apex coincide: the leaf has no length")
    flip = np.diag([1.0, -1.0])
    dx, dy = flip @ d
    turn = math.pi / 2.0 - math.atan2(dy, dx)           # the flipped base→apex direction onto +y
    c, s = math.cos(turn), math.sin(turn)
    lin = np.array([[c, -s], [s, c]]) @ flip / length
    m = np.eye(3)
    m[:2, :2] = lin
    m[:2, 2] = -lin @ b
    return m


def _apply(m: F64, points: ArrayLike) -> F64:
    p = np.asarray(points, np.float64)
    return np.asarray(p @ m[:2, :2].T + m[:2, 2], np.float64)


def outline_sides(outline_leaf: ArrayLike) -> tuple[F64, F64]:
    """The closed outline (leaf space) split at the points nearest the base and the apex into
    ``(right, left)``, each running from (0, 0) to (0, 1), the right side the one reached going
    counter-clockwise from the base (x > 0 for a leaf of the canonical frame)."""
    pts = np.asarray(outline_leaf, np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 8:
        raise ParamError("outline", f"expected a closed polyline of at least 8 points, got shape {pts.shape}")
    if np.allclose(pts[0], pts[-1]):
        pts = pts[:-1]
    area = 0.5 * float(np.sum(pts[:, 0] * np.roll(pts[:, 1], -1) - np.roll(pts[:, 0], -1) * pts[:, 1]))
    if area < 0.0:
        pts = pts[::-1]
    ib = int(np.argmin(np.hypot(pts[:, 0], pts[:, 1])))
    pts = np.roll(pts, -ib, axis=0)
    ia = int(np.argmin(np.hypot(pts[:, 0], pts[:, 1] - 1.0)))
    if ia < 2 or len(pts) - ia < 2:
        raise ParamError("outline", "base and apex are too close together on the outline to split it into sides")
    ends = (np.zeros((1, 2)), np.array([[0.0, 1.0]]))
    right = np.vstack([ends[0], pts[1:ia], ends[1]])
    left = np.vstack([ends[0], pts[ia + 1:][::-1], ends[1]])
    return right, left


def _resample(points: F64, n: int) -> F64:
    d = np.r_[0.0, np.cumsum(np.hypot(*np.diff(points, axis=0).T))]
    t = np.linspace(0.0, d[-1], n)
    return np.stack([np.interp(t, d, points[:, 0]), np.interp(t, d, points[:, 1])], axis=-1)


# -- the fitted margin in pixels and the measures -----------------------------------------------------
def _margins(parts: tuple[LeafParams, ...], n: int) -> tuple[F64, F64]:
    """(right, left) margins in leaf space, base to apex: the right from the leaf drawing u < 0."""
    if len(parts) == 1:
        return margin(parts[0], n)
    by_half = {p.shape.half: p for p in parts}
    return margin(by_half[RIGHT_HALF], n)[0], margin(by_half[LEFT_HALF], n)[1]


def margin_pixels(parts: tuple[LeafParams, ...], pixel_from_leaf: ArrayLike, n: int = _MARGIN_SAMPLES) -> F64:
    """The top view's boundary (right margin up, left margin down; a lobed leaf's closed margin from
    its base, clockwise) as a polygon in photo pixels."""
    if parts[0].lobes.enabled:
        ctrl = np.asarray(parts[0].lobes.outline, np.float64)
        return _apply(np.asarray(pixel_from_leaf, np.float64), sample_closed(ctrl, max(2 * n - 2, 4 * len(ctrl))))
    right, left = _margins(parts, n)
    return _apply(np.asarray(pixel_from_leaf, np.float64), np.vstack([right, left[-2:0:-1]]))


def polygon_mask(polygon_px: ArrayLike, shape: tuple[int, int]) -> NDArray[np.bool_]:
    """The pixels whose centres (at integers) lie inside the closed polygon (x, y pixels, any
    orientation; non-zero winding), an (h, w) mask. A scanline fill: each edge adds its winding
    at the first pixel centre right of where it crosses a row, and a running sum along the rows
    gives every pixel's winding number, so the cost follows the crossings, not pixels × edges."""
    p = np.asarray(polygon_px, np.float64)
    h, w = shape
    out = np.zeros(shape, bool)
    if len(p) < 3 or not np.all(np.isfinite(p)):
        return out
    r_lo, r_hi = max(int(np.ceil(p[:, 1].min())), 0), min(int(np.floor(p[:, 1].max())) + 1, h)
    c_lo, c_hi = max(int(np.ceil(p[:, 0].min())), 0), min(int(np.floor(p[:, 0].max())) + 1, w)
    if r_hi <= r_lo or c_hi <= c_lo:
        return out
    a, b = p, np.roll(p, -1, axis=0)
    lo, hi = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    first = np.clip(np.ceil(lo), r_lo, r_hi).astype(np.int64)       # rows y with lo <= y < hi
    last = np.clip(np.ceil(hi), r_lo, r_hi).astype(np.int64)
    counts = last - first
    edge = np.repeat(np.arange(len(p)), counts)
    row = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts) + first[edge]
    t = (row - a[edge, 1]) / (b[edge, 1] - a[edge, 1])
    x = a[edge, 0] + t * (b[edge, 0] - a[edge, 0])
    col = np.clip(np.ceil(x), c_lo, c_hi).astype(np.int64) - c_lo
    sign = np.where(b[edge, 1] > a[edge, 1], 1, -1)
    nc = c_hi - c_lo + 1
    acc = np.bincount((row - r_lo) * nc + col, sign, (r_hi - r_lo) * nc).reshape(r_hi - r_lo, nc)
    out[r_lo:r_hi, c_lo:c_hi] = np.cumsum(acc[:, :-1], axis=1) != 0
    return out


def top_view_iou(polygon_px: ArrayLike, mask: NDArray[np.bool_]) -> float:
    """Intersection over union of the polygon (photo pixels) and ``mask``."""
    fitted = polygon_mask(polygon_px, mask.shape)
    union = int(np.count_nonzero(fitted | mask))
    return float(np.count_nonzero(fitted & mask)) / union if union else 0.0


def _row_residuals(part: LeafParams, sides: list[tuple[F64, F64]]) -> list[float]:
    """Per silhouette row of ``part``: the RMS distance (% of the length) from the outline points
    whose nearest margin point lies in that row's stretch of v (between the midpoints of its foot
    and its neighbours') to the margin. ``sides``: (outline points, margin polyline at even v)."""
    feet = np.array([row[0] for row in part.shape.silhouette])
    edges = np.r_[0.0, 0.5 * (feet[1:] + feet[:-1]), 1.0]
    total = np.zeros(len(feet))
    count = np.zeros(len(feet))
    for points, curve in sides:
        dist, idx = cKDTree(curve).query(points)
        v = idx / (len(curve) - 1)
        row = np.clip(np.searchsorted(edges, v, side="right") - 1, 0, len(feet) - 1)
        total += np.bincount(row, dist ** 2, len(feet))
        count += np.bincount(row, None, len(feet))
    rms = np.sqrt(total / np.maximum(count, 1.0))
    return [round(100.0 * float(r), 4) if c else 0.0 for r, c in zip(rms, count)]


# -- the fit -------------------------------------------------------------------------------------------
def _check_dpi(dpi: float | None, photo: Photo) -> float | None:
    if dpi is None:
        return photo.dpi
    if isinstance(dpi, bool) or not isinstance(dpi, (int, float)) or not DPI_RANGE[0] <= dpi <= DPI_RANGE[1]:
        raise ParamError("dpi", f"must be a number of dots per inch in {DPI_RANGE[0]:g}..{DPI_RANGE[1]:g}, got {dpi!r}")
    return float(dpi)


def _area_miss(fits: tuple[LeafParams, ...], right: F64, left: F64) -> float:
    """The area between the fitted margin and the outline ÷ the outline's area, estimated as the
    mean distance of the outline's points to the margin times the outline's length: about the
    IoU the fit loses. ``fits``: one leaf, or the right side's and the (mirrored) left side's."""
    mr = margin(fits[0], 257)[0]
    ml = margin(fits[-1], 257)[0] * [-1.0, 1.0] if len(fits) == 2 else margin(fits[0], 257)[1]
    total, count, perimeter = 0.0, 0, 0.0
    for side, curve in ((right, mr), (left, ml)):
        dense = _resample(side, 200)
        total += float(cKDTree(curve).query(dense)[0].sum())
        count += len(dense)
        perimeter += float(np.sum(np.hypot(*np.diff(side, axis=0).T)))
    ring = np.vstack([right, left[-2:0:-1]])
    area = 0.5 * abs(float(np.sum(ring[:, 0] * np.roll(ring[:, 1], -1) - np.roll(ring[:, 0], -1) * ring[:, 1])))
    return total / count * perimeter / max(area, 1e-9)


def _choose(right: F64, left: F64, target: float) -> tuple[tuple[LeafParams, LeafParams, LeafParams],
                                                            tuple[float, float, float]]:
    """The symmetric fit and the two one-sided fits (right, left mirrored) as plain leaves, fitted
    as one batch, and their errors (estimates from above, ÷ leaf length)."""
    r, lt = _resample(right, _SIDE_SAMPLES), _resample(left, _SIDE_SAMPLES)
    mirror = np.array([-1.0, 1.0])
    fit = quick_fit_outlines(right=np.stack([r, r, lt * mirror]), left=np.stack([lt, r * mirror, lt]), target=target)
    e = [float(x) for x in fit.errors]
    return (fit.params[0], fit.params[1], fit.params[2]), (e[0], e[1], e[2])


@single_threaded      # many small matrix products: BLAS threads only hand off work on a busy machine
def fit_image(image_or_path: Photo | str | os.PathLike[str] | NDArray[Any], *, base: ArrayLike | None = None,
              apex: ArrayLike | None = None, dpi: float | None = None, name: str = "", texture_size: int = 512,
              target: float = PHOTO_FIT_TARGET, halves: bool = True, lobed: str = "auto",
              face: str = "auto") -> ImageFit:
    """Fit the leaf model to the leaf in a photo or scan (see the module docstring).

    Parameters
    ----------
    image_or_path
        An image file (PNG, JPEG, TIFF), a :class:`Photo` or an (h, w[, 3|4]) array.
    base, apex
        (x, y) in the photo's pixels, replacing the detected landmarks.
    dpi
        Dots per inch, replacing the file's resolution.
    name
        The leaf's name (default: the file's stem, or ``leaf``); halves get `` (right)`` / `` (left)``.
    texture_size
        Side of the square texture in texels.
    target
        Hausdorff error ÷ leaf length accepted when choosing the number of silhouette rows.
    halves
        Allow two one-sided halves where the sides differ. Off: always one symmetric leaf, and a
        warning when two halves would have followed the photo better.
    lobed
        ``auto``: a lobed leaf when the traced outline looks lobed
        (:func:`leafview.fit.photo_lobed.looks_lobed`); ``on``: always a lobed leaf (its closed
        margin, ``lobes.outline``); ``off``: always Ω (the unilobed fit).
    face
        Which side of the leaf faces the camera: ``auto`` (:func:`leafview.fit.photo_face.detect_face`;
        face up where it cannot tell), ``up`` or ``down`` (the leaf fitted mirrored, see the
        module docstring).

    Returns
    -------
    ImageFit
        ``report`` holds ``iou`` (fitted top view against the traced blade mask),
        ``hausdorff_pct`` (fitted margin against the traced outline, % of the length), ``base_px``,
        ``apex_px``, ``length_px``, ``rows`` and ``row_residuals`` (per part, per silhouette
        row: RMS % of the length), ``asymmetric`` (two halves), ``sides_differ`` (two halves
        would follow the photo clearly better), ``symmetric_error_pct``,
        ``halves_error_pct``, ``petiole_length``, ``dpi``, ``scale``, ``cut_sides``, ``method``,
        ``warnings``, ``veins`` (:meth:`leafview.fit.photo_veins.VeinEstimate.report`: ``status``
        ``pinnate`` with the numbers given to ``venation``, or ``not visible`` and the
        ``reason``), ``face`` (``up`` or ``down``: what the fit took), ``face_detected``
        (``up``, ``down`` or ``unknown``: what the detector found, run whatever ``face`` says),
        ``face_score`` and ``face_evidence`` (:meth:`leafview.fit.photo_face.FaceEstimate.report`),
        ``seconds`` and ``stage_seconds`` (read, outline, fit, texture, veins, measures).

    Raises
    ------
    ParamError
        Naming the file: no leaf, two touching leaves, an unreadable or too small image; or naming
        the argument.
    """
    t0 = time.perf_counter()
    if not (isinstance(target, (int, float)) and math.isfinite(target) and target > 0.0):
        raise ParamError("target", f"must be a positive number, got {target!r}")
    if lobed not in LOBED_MODES:
        raise ParamError("lobed", f"must be one of {', '.join(LOBED_MODES)}, got {lobed!r}")
    if face not in FACES:
        raise ParamError("face", f"must be one of {', '.join(FACES)}, got {face!r}")
    photo = as_photo(image_or_path)
    source = photo.path or None
    dots = _check_dpi(dpi, photo)
    t1 = time.perf_counter()
    traced = leaf_outline(photo, base=base, apex=apex)
    blades = two_blades(traced.outline)
    if blades is not None:
        raise ParamError("" if source else "image",
                         f"two touching leaves? the leaf-coloured region parts along a line between two notches into "
                         f"two convex blades of {100 * blades.shares[0]:.0f} % and {100 * blades.shares[1]:.0f} % of "
                         f"it (each fills ≥ {100 * blades.solidity:.0f} % of its convex hull; one leaf's lobes "
                         f"< {100 * BLADES_SOLIDITY:.0f} %); photograph one leaf at a time, apart from others", source)
    measures = lobe_measures(traced.outline)
    looks = looks_lobed(measures)
    is_lobed = lobed == "on" or (lobed == "auto" and looks)
    axis = None
    if lobed == "auto" and base is None and apex is None and (looks or two_notches(measures)):
        axis = symmetry_axis(traced.outline)
        least = LOBED_MIN_MIRROR if looks else NOTCHED_MIN_MIRROR
        if axis[2] < least:
            raise ParamError("" if source else "image",
                             f"two touching leaves? the leaf-coloured region "
                             f"{'looks lobed' if looks else 'is notched twice'}, but its mirror image in its "
                             f"best axis covers only {100 * axis[2]:.0f} % of it (one leaf ≥ {100 * least:.0f} %); "
                             f"photograph one leaf at a time, apart from others, or give --lobed "
                             f"{'on' if looks else 'off'}", source)
    if is_lobed and base is None and apex is None:
        traced = _lobed_landmarks(traced, measures, axis)
    t2 = time.perf_counter()
    length_px = float(np.hypot(*(traced.apex - traced.base)))
    if not length_px >= MIN_LENGTH_PX:
        raise ParamError("", f"the leaf is {length_px:.1f} px from base to apex; at least {MIN_LENGTH_PX:g} px are "
                             "needed to fit it", source)
    name = name or (Path(photo.path).stem if photo.path else "leaf")
    warnings = list(traced.warnings)
    frame = canonical_frame(traced.base, traced.apex)
    estimate = detect_face(photo.rgb, traced.blade, frame)
    down = face == "down" or (face == "auto" and estimate.face == "down")
    if down:
        frame = MIRROR @ frame
        warnings.append(f"the leaf is {'judged' if face == 'auto' else 'given as'} face down (score "
                        f"{estimate.score:.0f}: light/dark pairs across the veins): fitted mirrored about its midrib, "
                        "the photo as its back texture; give --face up if it lies face up")
    if is_lobed:
        fit = _fit_lobed(photo, traced, frame, _apply(frame, traced.outline), measures, name, dots, warnings,
                         target, texture_size, (t0, t1, t2))
        return _with_face(fit, face, down, estimate)
    outline = _apply(frame, traced.outline)
    try:
        right, left = outline_sides(outline)
    except ParamError as exc:
        raise exc.with_source(photo.path) if photo.path else exc from None

    (sym, fit_r, fit_l), (e_sym, e_r, e_l) = _choose(right, left, target)
    e_halves = max(e_r, e_l)
    e_best = min(e_sym, e_halves)     # the halves judge even when halves=False: an asymmetric leaf is one leaf
    if e_best > TOUCHING_FIT_ERROR and not looks:    # a lobed leaf fitted by Ω (lobed="off") misses its lobes
        raise ParamError("" if source else "image",
                         f"two touching leaves? the fitted leaf misses the outline of the leaf-coloured region by "
                         f"{100 * e_best:.1f} % of its length (one leaf fits within {100 * TOUCHING_FIT_ERROR:g} %); "
                         "photograph one leaf at a time, apart from others, or give --base and --apex", source)
    gain = _area_miss((sym,), right, left) - _area_miss((fit_r, fit_l), right, left)
    differ = e_sym > target and gain > HALVES_AREA_GAIN
    if differ and halves:
        parts: tuple[LeafParams, ...] = (with_half(fit_r, RIGHT_HALF, f"{name} (right)"),
                                         with_half(fit_l, LEFT_HALF, f"{name} (left)"))
    else:
        parts = (sym.replace(name=name),)
        if differ:
            warnings.append(f"the two sides differ: the symmetric fit is off by {100 * e_sym:.1f} % of the length, "
                            f"two one-sided halves by {100 * e_halves:.1f} %")

    petiole_px = float(np.sum(np.hypot(*np.diff(traced.petiole, axis=0).T))) if len(traced.petiole) > 1 else 0.0
    petiole = petiole_px / length_px
    lo, hi = 0.0, 10.0
    if petiole > hi:
        warnings.append(f"the petiole is {petiole:.1f} leaf lengths long; clamped to {hi:g}")
        petiole = hi
    if dots is None:
        scale = 1.0
        warnings.append("the photo has no resolution (dots per inch): the leaf is 1 unit long; give --dpi for metres")
    else:
        scale = float(np.clip(length_px / dots * METRES_PER_INCH, *SCALE_RANGE))
    parts = tuple(p.replace(bending=replace(Bending(), petiole_length=max(lo, petiole)), transform=Transform(scale=scale))
                  for p in parts)

    pixel_from_leaf = np.asarray(np.linalg.inv(frame), np.float64)
    t3 = time.perf_counter()
    texture = leaf_texture(photo.rgb, traced.mask, parts, pixel_from_leaf, texture_size)
    t4 = time.perf_counter()
    veins = detect_veins(texture, parts)
    parts = with_veins(parts, veins)
    t_veins = time.perf_counter()

    m_right, m_left = _margins(parts, _MARGIN_SAMPLES)
    fitted_outline = np.vstack([m_right, m_left[-2:0:-1], m_right[:1]])
    polygon = _apply(pixel_from_leaf, fitted_outline[:-1])
    hd = hausdorff(fitted_outline, np.vstack([outline, outline[:1]]))
    if len(parts) == 1:
        residuals = [_row_residuals(parts[0], [(right, m_right), (left, m_left)])]
    else:
        residuals = [_row_residuals(parts[0], [(right, m_right)]), _row_residuals(parts[1], [(left, m_left)])]
    report: dict[str, Any] = {
        "iou": round(top_view_iou(polygon, traced.blade), 5),
        "hausdorff_pct": round(100.0 * hd, 4),
        "base_px": [round(float(c), 3) for c in traced.base],
        "apex_px": [round(float(c), 3) for c in traced.apex],
        "length_px": round(length_px, 3),
        "rows": [p.shape.rows for p in parts],
        "row_residuals": residuals,
        "asymmetric": len(parts) == 2,
        "sides_differ": differ,
        "halves_area_gain": round(gain, 5),
        "symmetric_error_pct": round(100.0 * e_sym, 4),
        "halves_error_pct": round(100.0 * e_halves, 4),
        "petiole_length": round(petiole, 5),
        "dpi": dots,
        "scale": scale,
        "cut_sides": list(traced.cut_sides),
        "method": traced.method,
        "warnings": warnings,
        "veins": veins.report(),
        "lobed": False,
        "lobedness": measures.report(),
        "seconds": 0.0,
    }
    t5 = time.perf_counter()
    report["seconds"] = round(t5 - t0, 4)
    report["stage_seconds"] = {"read": round(t1 - t0, 4), "outline": round(t2 - t1, 4), "fit": round(t3 - t2, 4),
                               "texture": round(t4 - t3, 4), "veins": round(t_veins - t4, 4),
                               "measures": round(t5 - t_veins, 4)}
    return _with_face(ImageFit(parts, texture, traced, frame, report, tuple(warnings), photo), face, down, estimate)


def _with_face(fit: ImageFit, face: str, down: bool, estimate: FaceEstimate) -> ImageFit:
    """``fit`` with the face in its report (after ``warnings``, before the timings) and, face
    down, its texture as the back texture."""
    report = dict(fit.report)
    timings = {k: report.pop(k) for k in ("seconds", "stage_seconds")}
    report.update(face="down" if down else "up", face_given=face, face_detected=estimate.face,
                  face_score=round(estimate.score, 3), face_evidence=estimate.report(), **timings)
    return replace(fit, report=report, back_texture=fit.texture if down else None)


# -- a lobed leaf ----------------------------------------------------------------------------------------
def _lobed_landmarks(traced: LeafOutline, measures: LobeMeasures,
                     axis: tuple[F64, F64, float] | None = None) -> LeafOutline:
    """``traced`` with the base and apex of a lobed blade (:func:`lobed_landmarks`), the outline
    starting at the point nearest the base."""
    b, a = lobed_landmarks(traced.outline, traced.petiole, measures, axis)
    k = int(np.argmin(np.hypot(*(traced.outline - b).T)))
    return replace(traced, base=np.asarray(b, np.float64), apex=np.asarray(a, np.float64),
                   outline=np.roll(traced.outline, -k, axis=0))


def _scale_and_petiole(traced: LeafOutline, length_px: float, dots: float | None,
                       warnings: list[str]) -> tuple[float, float]:
    petiole_px = float(np.sum(np.hypot(*np.diff(traced.petiole, axis=0).T))) if len(traced.petiole) > 1 else 0.0
    petiole = petiole_px / length_px
    if petiole > 10.0:
        warnings.append(f"the petiole is {petiole:.1f} leaf lengths long; clamped to 10")
        petiole = 10.0
    if dots is None:
        warnings.append("the photo has no resolution (dots per inch): the leaf is 1 unit long; give --dpi for metres")
        return petiole, 1.0
    return petiole, float(np.clip(length_px / dots * METRES_PER_INCH, *SCALE_RANGE))


def _fit_lobed(photo: Photo, traced: LeafOutline, frame: F64, outline: F64, measures: LobeMeasures, name: str,
               dots: float | None, warnings: list[str], target: float, texture_size: int,
               times: tuple[float, float, float]) -> ImageFit:
    """The lobed branch of :func:`fit_image`: the closed margin (:func:`fit_lobed_margin`), scale
    and petiole as for Ω, the texture addressed by the flat position (:func:`lobed_texture`)."""
    t0, t1, t2 = times
    length_px = float(np.hypot(*(traced.apex - traced.base)))
    fitted = fit_lobed_margin(outline, target)
    petiole, scale = _scale_and_petiole(traced, length_px, dots, warnings)
    leaf = lobed_leaf(fitted, name)
    parts = (leaf.replace(bending=replace(Bending(), petiole_length=petiole), transform=Transform(scale=scale)),)
    pixel_from_leaf = np.asarray(np.linalg.inv(frame), np.float64)
    t3 = time.perf_counter()
    texture = lobed_texture(photo.rgb, traced.mask, pixel_from_leaf, sweep_table(leaf.lobes).window, texture_size)
    t4 = time.perf_counter()
    polygon = margin_pixels(parts, pixel_from_leaf)
    curve = _apply(frame, polygon)
    hd = hausdorff(np.vstack([curve, curve[:1]]), np.vstack([outline, outline[:1]]))
    report: dict[str, Any] = {
        "iou": round(top_view_iou(polygon, traced.blade), 5), "hausdorff_pct": round(100.0 * hd, 4),
        "base_px": [round(float(c), 3) for c in traced.base], "apex_px": [round(float(c), 3) for c in traced.apex],
        "length_px": round(length_px, 3), "rows": [], "row_residuals": [], "asymmetric": False,
        "sides_differ": False, "halves_area_gain": 0.0, "symmetric_error_pct": None, "halves_error_pct": None,
        "petiole_length": round(petiole, 5), "dpi": dots, "scale": scale, "cut_sides": list(traced.cut_sides),
        "method": traced.method, "warnings": warnings,
        "veins": VeinEstimate(False, "a lobed leaf: its veins are not traced").report(),
        "lobed": True, "lobedness": measures.report(), "controls": len(fitted.outline),
        "valleys": len(fitted.valleys), "seconds": 0.0}
    t5 = time.perf_counter()
    report["seconds"] = round(t5 - t0, 4)
    report["stage_seconds"] = {"read": round(t1 - t0, 4), "outline": round(t2 - t1, 4), "fit": round(t3 - t2, 4),
                               "texture": round(t4 - t3, 4), "veins": 0.0, "measures": round(t5 - t4, 4)}
    return ImageFit(parts, texture, traced, frame, report, tuple(warnings), photo)
