"""The sky and ground behind and under a canopy: :class:`SkyPass` (a full-screen analytic sky, drawn
first, no depth) and :class:`GroundPass` (the ground plane with the sun's shadow, contact shadows and
the sky's ambient, depth written). Both read the Light block (:class:`~leafview.gpu.light.LightUniforms`,
bound by the caller at ``LIGHT_BINDING``) and tone map like the leaves (``tonemap.glsl``); each owns
a Frame block for its camera. Numpy twins: :mod:`leafview.scene.sky`.

Both are full-screen triangles whose fragments cast the pixel's view ray, the points of the pixel
on the near and far planes unprojected by ``inverse(proj · view)`` (:func:`view_rays`), so one code
path serves perspective and orthographic cameras and the ground needs no mesh: it reaches as far as
the view does and fades into the sky's hazy ground radiance far from the scene.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Self

import moderngl
import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.errors import ParamError
from leafview.gpu.frame import FrameUniforms
from leafview.gpu.layout import shadow_defines
from leafview.gpu.owner import GLObjects
from leafview.gpu.programs import ProgramCache
from leafview.scene.camera import Camera
from leafview.scene.sky import CONTACT_CELLS, CONTACT_ITEMS, CONTACT_REACH, MAX_CONTACTS, contact_grid

__all__ = ["SkyPass", "GroundPass", "view_rays", "pixel_ndc", "CONTACT_STRENGTH", "FADE_START", "FADE_END"]

CONTACT_STRENGTH = 0.55  # k of the contact occlusion (leafview.scene.sky.contact_occlusion)
FADE_START, FADE_END = 3.0, 12.0   # the ground's fade into the haze, in scene radii from its centre


def pixel_ndc(size: tuple[int, int]) -> NDArray[np.float64]:
    """(h, w, 2) normalised device x, y of the pixel centres, row 0 at the top (as readbacks)."""
    w, h = int(size[0]), int(size[1])
    x = (np.arange(w) + 0.5) / w * 2.0 - 1.0
    y = 1.0 - (np.arange(h) + 0.5) / h * 2.0
    xx, yy = np.meshgrid(x, y)
    return np.stack([xx, yy], axis=-1)


def _uniform(program: moderngl.Program, name: str) -> moderngl.Uniform:
    member = program[name]
    assert isinstance(member, moderngl.Uniform), name
    return member


def _inverse(camera: Camera) -> NDArray[np.float64]:
    m = np.asarray(camera.proj, np.float64) @ np.asarray(camera.view, np.float64)
    return np.asarray(np.linalg.inv(m), np.float64)


def view_rays(camera: Camera, size: tuple[int, int]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(origins, directions), each (h, w, 3): the pixel centres' points on the near plane and the
    unit directions to their points on the far plane (the twin of sky.frag / ground.frag)."""
    ndc = pixel_ndc(size)
    inv = _inverse(camera)

    def unproject(z: float) -> NDArray[np.float64]:
        p = np.concatenate([ndc, np.full(ndc.shape[:2] + (1,), z), np.ones(ndc.shape[:2] + (1,))], axis=-1) @ inv.T
        out: NDArray[np.float64] = p[..., :3] / p[..., 3:]
        return out

    near, far = unproject(-1.0), unproject(1.0)
    d = far - near
    return near, d / np.linalg.norm(d, axis=-1, keepdims=True)


class _FullScreen:
    """A full-screen triangle program of ``sky.vert`` + ``fragment`` and its Frame block."""

    def __init__(self, ctx: moderngl.Context, fragment: str, defines: dict[str, object],
                 programs: ProgramCache | None) -> None:
        self.ctx = ctx
        self._objects = GLObjects()
        try:
            self.programs = programs if programs is not None else self._objects.own(ProgramCache(ctx))
            vertex = "ground.vert" if fragment == "ground.frag" else "sky.vert"
            self.program = self.programs.program(vertex, fragment, defines=defines)
            self.vao = self._objects.own(ctx.vertex_array(self.program, []))
            self.frame = self._objects.own(FrameUniforms(ctx))
        except BaseException:
            self._objects.release()
            raise

    def _prepare(self, camera: Camera, size: tuple[int, int], srgb: bool) -> None:
        self.frame.set_camera(camera, srgb=srgb, size=size)
        self.frame.bind()
        _uniform(self.program, "inv_view_proj").write(_inverse(camera).T.astype("f4").tobytes())

    def release(self) -> None:
        """Release what this pass created (idempotent); a shared program cache stays its owner's."""
        self._objects.release()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


class SkyPass(_FullScreen):
    """The analytic sky (``sky.frag``) over the whole bound framebuffer, alpha 1, depth untouched;
    draw it first. The Light block must be bound (:meth:`LightUniforms.bind`)."""

    def __init__(self, ctx: moderngl.Context, *, programs: ProgramCache | None = None) -> None:
        super().__init__(ctx, "sky.frag", {}, programs)

    def draw(self, camera: Camera, size: tuple[int, int], *, srgb: bool = True) -> None:
        """Draw the sky seen by ``camera`` into the bound framebuffer of ``size`` (w, h); ``srgb``:
        encode sRGB (an 8-bit target) or leave the tone-mapped values linear (a float target)."""
        self._prepare(camera, size, srgb)
        self.ctx.enable_only(moderngl.NOTHING)
        self.vao.render(moderngl.TRIANGLES, vertices=3)


class GroundPass(_FullScreen):
    """The ground plane (``ground.frag``), lit by the Light block's sun and sky, with contact
    shadows at :meth:`set_contacts`'s points, and with ``shadows`` the sun's shadow maps
    (``leaf_shadow.glsl``, bound by :class:`leafview.gpu.shadow.ShadowPass`). Writes colour (alpha 1)
    and depth; draw it after the sky and before the leaves. ``shadow_filter``: as the leaves'
    (:data:`leafview.scene.lighting.SHADOW_FILTERS`)."""

    def __init__(self, ctx: moderngl.Context, *, shadows: bool = False, shadow_filter: str = "soft",
                 programs: ProgramCache | None = None) -> None:
        defines: dict[str, object] = {"GROUND_MAX_CONTACTS": MAX_CONTACTS, "GROUND_CONTACT_CELLS": CONTACT_CELLS,
                                      "GROUND_CONTACT_ITEMS": CONTACT_ITEMS, "GROUND_CONTACT_REACH": repr(float(CONTACT_REACH)),
                                      **shadow_defines(shadows, shadow_filter)}
        super().__init__(ctx, "ground.frag", defines, programs)
        self.shadows = bool(shadows)
        self.contacts = np.zeros((0, 3))
        self.radii = np.zeros(0)
        self.set_contacts(self.contacts, self.radii)
        self.program["contact_strength"] = CONTACT_STRENGTH

    def set_contacts(self, contacts: ArrayLike, radii: ArrayLike | float) -> None:
        """Contact points (M, 3) (plant bases; :func:`leafview.scene.sky.contacts_of`) and their
        radii (M,) or one radius: at most :data:`~leafview.scene.sky.MAX_CONTACTS`, the first ones
        kept (contacts_of sorts the largest plants first), binned on a grid
        (:func:`~leafview.scene.sky.contact_grid`, which may drop more where its lists fill up);
        ``contacts`` and ``radii`` are those drawn."""
        pts = np.asarray(contacts, np.float64).reshape(-1, 3)
        rad = np.broadcast_to(np.asarray(radii, np.float64), (len(pts),))
        if not (np.isfinite(pts).all() and np.isfinite(rad).all() and (rad > 0).all()):
            raise ParamError("ground.contacts", "contact points and radii must be finite, radii positive")
        pts, rad = pts[:MAX_CONTACTS], rad[:MAX_CONTACTS]
        grid = contact_grid(pts, rad)
        self.contacts, self.radii = pts[grid.kept], np.array(rad[grid.kept])
        data = np.zeros((MAX_CONTACTS, 4), np.float32)
        data[: len(pts), :3] = pts
        data[: len(pts), 3] = rad
        _uniform(self.program, "contacts").write(data.tobytes())
        self.program["contact_grid"] = (*grid.origin, *grid.inv_cell)
        _uniform(self.program, "contact_cells").write(np.stack([grid.start, grid.count], axis=1).astype("i4").tobytes())
        _uniform(self.program, "contact_items").write(grid.packed().tobytes())

    def draw(self, camera: Camera, bounds: Sequence[ArrayLike], *, size: tuple[int, int] | None = None,
             height: float | None = None, srgb: bool = True) -> None:
        """Draw the ground seen by ``camera`` into the bound framebuffer: the plane z = ``height``
        (default the bottom of ``bounds`` = (lo, hi), the scene's world box), fading into the haze
        from :data:`FADE_START` to :data:`FADE_END` scene radii around the box's centre."""
        lo, hi = (np.asarray(b, np.float64).reshape(3) for b in bounds)
        z = float(lo[2]) if height is None else float(height)
        if not np.isfinite(z) or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
            raise ParamError("ground.bounds", f"must be finite, got {bounds!r} (height {height!r})")
        centre = (lo + hi) / 2.0
        radius = max(0.5 * float(np.linalg.norm((hi - lo)[:2])), 0.25 * float(hi[2] - lo[2]), 1e-3)
        _, _, vw, vh = self.ctx.viewport
        self._prepare(camera, size if size is not None else (int(vw), int(vh)), srgb)
        self.program["ground_z"] = z
        self.program["ground_fade"] = (float(centre[0]), float(centre[1]), FADE_START * radius, FADE_END * radius)
        self.ctx.enable_only(moderngl.DEPTH_TEST)
        self.ctx.depth_func = "<="
        try:
            self.vao.render(moderngl.TRIANGLES, vertices=3)
        finally:
            self.ctx.depth_func = "<"
