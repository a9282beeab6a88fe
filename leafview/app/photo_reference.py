"""The reference photo: a leaf photograph shown in the leaf's plane, behind the leaf, so the
handles can be dragged against it and "Fit" can fit the leaf to it.

This follows the interactive workflow of Garg & Leow 2011 (Fig. 1): the user lays the model's
outline over a photograph and adjusts its control points until they agree; here the photo can
also be fitted automatically (:func:`leafview.fit.photo.fit_image`).

**Placement.** A photo pixel (x right, y down, pixel centres at integers) goes to leaf space by a
similarity ``leaf_from_pixel`` (3 × 3, homogeneous), then to world space by the leaf's transform;
the photo lies in the plane z = 0 of leaf space. Before a fit, ``leaf_from_pixel`` takes the
photo's base and apex, found by :func:`leafview.fit.photo_outline.leaf_outline`, to the leaf's
base (0, 0) and apex (0, 1), without mirroring the picture as seen from above (+z)
(:func:`leafview.fit.photo.canonical_frame`, the fit's own frame). After a fit it is the fit's own. Moving the base/apex markers
changes only the points handed to the fit (``base=`` / ``apex=``), never the placement.

**Drawing.** :class:`PhotoLayer` draws the photo as one textured quad (``shaders/
photo_reference.vert`` / ``.frag``) blended over what is behind it with alpha = opacity, with no
depth test, before the leaf: the leaf is always drawn over it. Photos with a side over
:data:`MAX_DISPLAY_SIDE` pixels are reduced for display by block means (the quad still covers
the photo's full extent, so the placement is unchanged). The base/apex markers are round points
drawn with the overlay program.

Every failure (an unreadable file, an image without a leaf, a fit that fails) becomes
``state.error`` and changes nothing.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import moderngl
import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.app.state import ReferencePhoto, ViewerState
from leafview.core.params import LeafParams, ParamError
from leafview.gpu.layout import ATLAS_UNIT
from leafview.gpu.shaders import build_program

if TYPE_CHECKING:
    from types import ModuleType


def _fit(module: str) -> ModuleType:
    """``leafview.fit.<module>``, loaded when a photo is first opened or fitted: the photo fit
    pulls in scipy and scikit-image (about a second), which a viewer or a ``leafview scene`` run
    without photos never needs."""
    return importlib.import_module(f"leafview.fit.{module}")

__all__ = ["PHOTO_SUFFIXES", "MAX_DISPLAY_SIDE", "MARKERS", "is_photo_path", "display_image",
           "world_from_pixel", "pixel_of_world", "marker_world", "plane_normal", "open_photo", "close_photo",
           "move_marker", "fit_reference", "report_line", "PhotoLayer"]

PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff")
MAX_DISPLAY_SIDE = 2048              # longest side of the texture shown (larger photos are reduced)
MARKERS = ("photo:base", "photo:apex")
MARKER_COLORS = {"photo:base": (1.0, 0.55, 0.1, 1.0), "photo:apex": (0.2, 0.85, 1.0, 1.0)}
HOT_SIZE, MARKER_SIZE = 15.0, 11.0
FIT_TEXTURE_SIZE = 64                # the fit's texture is not drawn by the viewer
_CORNERS = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]], dtype="f4")   # a triangle strip
_POINT = np.dtype([("pos", "f4", 3), ("color", "f4", 4)])                          # the overlay's vertex


def is_photo_path(path: str | Path) -> bool:
    """Whether ``path`` names an image file (by its suffix) rather than a leaf preset."""
    return Path(path).suffix.lower() in PHOTO_SUFFIXES


def display_image(rgb: NDArray[np.floating], max_side: int = MAX_DISPLAY_SIDE) -> tuple[NDArray[np.uint8], int]:
    """(RGBA uint8 texture pixels, reduction factor f): ``rgb`` (h, w, 3) in [0, 1], reduced by
    the smallest integer f that brings both sides to ``max_side`` or less (block means of f × f
    pixels, the last row and column repeated to fill whole blocks). Texel (i, j) covers photo
    pixels [f i - 1/2, f (i + 1) - 1/2)."""
    h, w = rgb.shape[:2]
    f = max(1, math.ceil(max(h, w) / max_side))
    px = np.asarray(rgb, np.float32)
    if f > 1:
        th, tw = -(-h // f), -(-w // f)
        px = np.pad(px, ((0, th * f - h), (0, tw * f - w), (0, 0)), mode="edge")
        px = px.reshape(th, f, tw, f, 3).mean(axis=(1, 3))
    out = np.empty((*px.shape[:2], 4), np.uint8)
    out[..., :3] = np.clip(np.rint(px * 255.0), 0, 255).astype(np.uint8)
    out[..., 3] = 255
    return out, f


def world_from_pixel(leaf_from_pixel: ArrayLike, params: LeafParams) -> NDArray[np.float64]:
    """4 × 4: photo pixel (x, y, 0, 1) to world space, through leaf space (z = 0) and the
    leaf's transform."""
    lfp = np.asarray(leaf_from_pixel, np.float64)
    m = np.eye(4)
    m[:2, :2], m[:2, 3] = lfp[:2, :2], lfp[:2, 2]
    return params.transform.matrix() @ m


def plane_normal(params: LeafParams) -> NDArray[np.float64]:
    """World normal of the photo's plane (leaf space z = 0 after the leaf's transform)."""
    n = params.transform.matrix()[:3, 2]
    return n / np.linalg.norm(n)


def pixel_of_world(leaf_from_pixel: ArrayLike, params: LeafParams, points: ArrayLike) -> NDArray[np.float64]:
    """Photo pixel coordinates (N, 2) of world ``points`` (N, 3) lying in the photo's plane (the
    inverse of :func:`world_from_pixel` there)."""
    inv = np.linalg.inv(params.transform.matrix())
    p = np.asarray(points, np.float64).reshape(-1, 3)
    leaf = p @ inv[:3, :3].T + inv[:3, 3]
    pfl = np.linalg.inv(np.asarray(leaf_from_pixel, np.float64))
    return leaf[:, :2] @ pfl[:2, :2].T + pfl[:2, 2]


def marker_world(ref: ReferencePhoto, params: LeafParams) -> dict[str, NDArray[np.float64]]:
    """World positions of the base and apex markers (empty without a placed photo)."""
    if ref.leaf_from_pixel is None or ref.base_px is None or ref.apex_px is None:
        return {}
    m = world_from_pixel(ref.leaf_from_pixel, params)
    return {name: (m @ np.array([p[0], p[1], 0.0, 1.0]))[:3]
            for name, p in zip(MARKERS, (ref.base_px, ref.apex_px), strict=True)}


def move_marker(state: ViewerState, name: str, world: ArrayLike) -> bool:
    """Put marker ``name`` (``photo:base`` / ``photo:apex``) at the world point ``world`` of the
    photo's plane; returns whether it moved (a point off the photo is kept, clamped to it)."""
    ref = state.reference
    if name not in MARKERS or ref.leaf_from_pixel is None:
        return False
    px = pixel_of_world(ref.leaf_from_pixel, state.params, world)[0]
    if not np.all(np.isfinite(px)):
        return False
    w, h = ref.size
    point = (float(np.clip(px[0], 0.0, w - 1.0)), float(np.clip(px[1], 0.0, h - 1.0)))
    setattr(ref, "base_px" if name == "photo:base" else "apex_px", point)
    return True


def open_photo(state: ViewerState, path: str | Path) -> bool:
    """Make the image file ``path`` the reference photo, placed by its detected base and apex on
    the current leaf (which is kept). On any error ``state.error`` says why and nothing changes."""
    p = Path(path).expanduser()
    try:
        outlines = _fit("photo_outline")
        photo = outlines.read_photo(p)
        outline = outlines.leaf_outline(photo)
        placement = _fit("photo").canonical_frame(outline.base, outline.apex)
    except (ParamError, ValueError) as exc:
        state.error = f"reference photo: {exc}"
        return False
    except OSError as exc:  # read_photo reports files as ParamError; anything else the OS says
        state.error = f"{p}: cannot read: {exc.strerror or exc}"
        return False
    image, factor = display_image(photo.rgb)
    ref = state.reference
    state.reference = replace(
        ref, path=p, image=image, factor=factor, size=photo.size, dpi=photo.dpi,
        base_px=(float(outline.base[0]), float(outline.base[1])),
        apex_px=(float(outline.apex[0]), float(outline.apex[1])),
        leaf_from_pixel=placement, fitted=False, report={}, warnings=tuple(outline.warnings),
        revision=ref.revision + 1)
    state.error = None
    h, w = photo.rgb.shape[:2]
    state.message = f"reference photo {p.name} ({w}×{h} px); drag the leaf's handles over it, or Fit"
    return True


def close_photo(state: ViewerState) -> None:
    """Remove the reference photo (the leaf stays)."""
    state.reference = ReferencePhoto(opacity=state.reference.opacity, revision=state.reference.revision + 1)


def report_line(report: Mapping[str, Any]) -> str:
    """One line of a fit's report: the IoU of the fitted top view against the traced mask and the
    Hausdorff distance of the margins in % of the leaf's length."""
    parts = []
    if isinstance(report.get("iou"), (int, float)):
        parts.append(f"IoU {float(report['iou']):.3f}")
    if isinstance(report.get("hausdorff_pct"), (int, float)):
        parts.append(f"Hausdorff {float(report['hausdorff_pct']):.2f} % of the length")
    return ", ".join(parts) or "fitted"


def fit_reference(state: ViewerState) -> bool:
    """Fit the leaf to the reference photo with the current base and apex markers and replace
    the leaf by the fit (one undoable edit); the photo then takes the fit's placement. An error
    goes to ``state.error`` and changes nothing."""
    ref = state.reference
    if ref.path is None:
        state.error = "Fit: open a photo first (Open… accepts PNG, JPEG and TIFF)"
        return False
    try:  # one symmetric leaf (the viewer edits one); the texture is not shown here, so keep it small
        fit = _fit("photo").fit_image(ref.path, base=ref.base_px, apex=ref.apex_px, name=state.params.name or ref.path.stem,
                        texture_size=FIT_TEXTURE_SIZE, halves=False)
    except (ParamError, ValueError) as exc:
        state.error = f"Fit: {exc}"
        return False
    except OSError as exc:
        state.error = f"Fit: {ref.path}: cannot read: {exc.strerror or exc}"
        return False
    leaf = fit.parts[0]
    placement = np.asarray(fit.leaf_from_pixel, np.float64)
    if placement.shape != (3, 3) or not np.all(np.isfinite(placement)):
        state.error = "Fit: the fit returned no usable placement of the photo"
        return False
    changed = state.apply(lambda _: leaf)
    if state.error:
        return False
    line = report_line(fit.report)
    state.reference = replace(ref, leaf_from_pixel=placement, fitted=True, report=dict(fit.report),
                              warnings=tuple(fit.warnings), fits=ref.fits + 1)
    state.message = f"fitted to {ref.path.name}: {line}" + ("" if changed else " (the leaf was already this fit)")
    return True


def _uniform(program: moderngl.Program, name: str) -> moderngl.Uniform:
    member = program[name]
    assert isinstance(member, moderngl.Uniform), f"{name} is not a plain uniform"
    return member


class PhotoLayer:
    """GL objects of the reference photo for one context: the textured quad and the markers.
    :meth:`release` frees them."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.program = build_program(ctx, "photo_reference.vert", "photo_reference.frag")
        self.points = build_program(ctx, "overlay.vert", "overlay.frag")
        self.quad = ctx.buffer(_CORNERS.tobytes())
        self.vao = ctx.vertex_array(self.program, [(self.quad, "2f", "in_corner")])
        self.marker_vbo = ctx.buffer(reserve=4 * _POINT.itemsize, dynamic=True)
        self.marker_vao = ctx.vertex_array(self.points, [(self.marker_vbo, "3f 4f", "in_pos", "in_color")])
        self.texture: moderngl.Texture | None = None
        self._revision = -1

    def _upload(self, ref: ReferencePhoto) -> moderngl.Texture | None:
        """The photo's texture, (re)created when the reference changed."""
        if ref.revision != self._revision:
            self._revision = ref.revision
            if self.texture is not None:
                self.texture.release()
                self.texture = None
            if ref.image is not None:
                h, w = ref.image.shape[:2]
                tex = self.ctx.texture((w, h), 4, np.ascontiguousarray(ref.image).tobytes())
                tex.repeat_x = tex.repeat_y = False
                tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
                tex.build_mipmaps()
                self.texture = tex
        return self.texture

    def draw_photo(self, view_proj: NDArray[np.float64], ref: ReferencePhoto, params: LeafParams) -> bool:
        """The photo quad, blended with alpha = opacity, no depth test; returns whether it drew."""
        tex = self._upload(ref)
        if tex is None or ref.leaf_from_pixel is None or not ref.visible or ref.opacity <= 0.0:
            return False
        h, w = tex.height, tex.width
        world = world_from_pixel(ref.leaf_from_pixel, params)
        _uniform(self.program, "view_proj").write(view_proj.T.astype("f4").tobytes())
        _uniform(self.program, "world_from_pixel").write(world.T.astype("f4").tobytes())
        _uniform(self.program, "photo_size").value = (float(w * ref.factor), float(h * ref.factor))
        _uniform(self.program, "opacity").value = float(min(max(ref.opacity, 0.0), 1.0))
        ctx = self.ctx
        ctx.disable(moderngl.DEPTH_TEST)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        try:
            tex.use(location=ATLAS_UNIT)
            self.vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        finally:
            ctx.disable(moderngl.BLEND)
        return True

    def draw_markers(self, view_proj: NDArray[np.float64], ref: ReferencePhoto, params: LeafParams,
                     hot: str | None = None, *, show: bool = True) -> None:
        """The base and apex markers (round points; the one under the mouse larger)."""
        if not (ref.visible and show):
            return
        where = marker_world(ref, params)
        if not where:
            return
        pts = np.zeros(len(where), _POINT)
        pts["pos"] = list(where.values())
        pts["color"] = [MARKER_COLORS[name] for name in where]
        ctx = self.ctx
        ctx.disable(moderngl.DEPTH_TEST)
        ctx.enable(moderngl.BLEND | moderngl.PROGRAM_POINT_SIZE)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        _uniform(self.points, "view_proj").write(view_proj.T.astype("f4").tobytes())
        _uniform(self.points, "round_points").value = True
        try:
            for name, pt in zip(where, pts, strict=True):
                _uniform(self.points, "point_size").value = HOT_SIZE if name == hot else MARKER_SIZE
                self.marker_vbo.write(pt.tobytes())
                self.marker_vao.render(moderngl.POINTS, vertices=1)
        finally:
            ctx.disable(moderngl.BLEND | moderngl.PROGRAM_POINT_SIZE)

    def release(self) -> None:
        for obj in (self.texture, self.vao, self.quad, self.marker_vao, self.marker_vbo, self.program, self.points):
            if obj is not None:
                obj.release()
        self.texture = None
