"""The sun's cascaded shadow maps on the GPU: :class:`ShadowPass` draws a scene's depth from the
sun into one atlas depth texture (a tile per cascade, :mod:`leafview.scene.sun`) and binds it,
with the Shadow uniform block, for ``shaders/leaf_shadow.glsl``'s ``sun_visibility``.

Each cascade is drawn by :meth:`SceneRenderer.draw <leafview.gpu.scene.SceneRenderer.draw>` with
the ``LEAF_DEPTH`` variant after :meth:`~leafview.gpu.scene.SceneRenderer.set_camera` with the
cascade's orthographic sun camera: culling tests the sun's frustum (which reaches from the
receivers up to the top of the scene, so leaves outside the view still cast their shadows), and
the level of detail is chosen at the shadow map's texel scale, coarse
(:data:`SHADOW_LOD_TEXELS`: the depth bias covers the outline error). Leaves are two-sided thin
sheets: nothing is culled by facing; acne is kept away on the receiver side (normal offset and
depth bias in texels, :mod:`leafview.scene.sun`), not by polygon offset, so the map holds the
surfaces' own depths.
"""

from __future__ import annotations

from collections.abc import Mapping

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.gpu.layout import SHADOW_BINDING, SHADOW_BLOCK, SHADOW_UNIT
from leafview.gpu.limits import context_alive, ensure_alive
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.scene.camera import Camera
from leafview.scene.lighting import LightSettings
from leafview.scene.sun import (
    DEPTH_BIAS,
    MAX_CASCADES,
    NORMAL_OFFSET,
    Cascades,
    atlas_layout,
    shadow_cascades,
    tile_origin,
)

__all__ = ["ShadowPass", "SHADOW_LOD_TEXELS", "shadow_record"]

SHADOW_LOD_TEXELS = 2.0
"""Largest outline error (shadow texels) the shadow pass's level of detail may add; the receiver's
offset from its surface, at least the depth bias (:data:`leafview.scene.sun.DEPTH_BIAS`, 2 texels)
along the normal, covers it. (1 texel drew most of a 10⁵-leaf field's casters at the middle grid,
64 triangles; 2 draws them at the coarsest, 16: the pass of the ground camera's four cascades
went from 1.5 s to 1.0 s on llvmpipe.)"""


def shadow_record(cascades: Cascades | None, depth_bias: float = DEPTH_BIAS,
                  normal_offset: float = NORMAL_OFFSET) -> NDArray[np.void]:
    """The SHADOW_BLOCK record of ``cascades`` (None: shadows off, ``params.x = 0``): matrices
    column-major, unused cascades repeating the last, splits, (count, depth bias, normal offset,
    1 / tile size)."""
    rec = SHADOW_BLOCK.zeros()
    if cascades is None or cascades.count == 0:
        rec["matrices"] = np.eye(4)
        rec["params"] = (0.0, depth_bias, normal_offset, 1.0)
        return rec
    n = cascades.count
    mats = np.array([cascades.matrices[min(k, n - 1)].T for k in range(MAX_CASCADES)])
    rec["matrices"] = mats
    splits = np.full(MAX_CASCADES, cascades.splits[-1])
    splits[:n] = cascades.splits
    rec["splits"] = splits
    rec["params"] = (float(n), depth_bias, normal_offset, 1.0 / cascades.tile)
    return rec


class ShadowPass:
    """The sun's shadow maps of one context: :meth:`render` draws them for a scene and a camera and
    binds them (the Shadow block at ``SHADOW_BINDING``, the atlas at ``SHADOW_UNIT``);
    :meth:`bind` binds them again; :meth:`read_depth` reads the atlas back (tests)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.buffer = ctx.buffer(reserve=SHADOW_BLOCK.nbytes)
        self.record = shadow_record(None)
        self.buffer.write(self.record.tobytes())
        self.cascades: Cascades | None = None
        self.depth_bias, self.normal_offset = DEPTH_BIAS, NORMAL_OFFSET
        # culling and level of detail of the shadow pass (max_error_px in shadow texels)
        self.settings = CullSettings(max_error_px=SHADOW_LOD_TEXELS)
        self.texture: moderngl.Texture = self._depth_texture((1, 1))
        self.fbo: moderngl.Framebuffer | None = None

    def _depth_texture(self, size: tuple[int, int]) -> moderngl.Texture:
        tex = self.ctx.depth_texture(size)
        tex.repeat_x = tex.repeat_y = False
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        tex.compare_func = "<="
        return tex

    def _atlas(self, size: tuple[int, int]) -> moderngl.Framebuffer:
        if self.fbo is None or self.texture.size != size:
            if self.fbo is not None:
                self.fbo.release()
            self.texture.release()
            self.texture = self._depth_texture(size)
            self.fbo = self.ctx.framebuffer(depth_attachment=self.texture)
        return self.fbo

    def render(self, scene: SceneRenderer, camera: Camera, size: tuple[int, int], light: LightSettings,
               defines: Mapping[str, object] = {}) -> None:
        """Draw the cascades of ``camera`` (the view the shadows are for; ``size`` its image) for
        ``light``'s sun (``light.shadows`` off: no cascade, every fragment lit), then bind. The
        scene's camera is the last cascade's afterwards: the caller sets its own again. The bound
        framebuffer and viewport are restored."""
        ensure_alive(self.ctx, "drawing the shadow maps")
        if not light.shadows:
            self.cascades = None
            self.record = shadow_record(None, self.depth_bias, self.normal_offset)
            self.buffer.write(self.record.tobytes())
            self.bind()
            return
        tile = int(light.shadow_size)
        count = light.cascades
        limit = int(self.ctx.info["GL_MAX_TEXTURE_SIZE"])
        tile = min(tile, limit // 2) if count != 1 else min(tile, limit)
        cascades = shadow_cascades(camera, scene.bounds, light.direction, tile, count)
        fbo = self._atlas(cascades.atlas_size)
        previous, viewport = self.ctx.fbo, self.ctx.viewport
        try:
            fbo.use()
            self.ctx.viewport = (0, 0, *cascades.atlas_size)
            fbo.clear(depth=1.0)
            variant = {"LEAF_DEPTH": 1, **defines}
            for k, cam in enumerate(cascades.cameras):
                col, row = tile_origin(k)
                self.ctx.viewport = (col * tile, row * tile, tile, tile)
                scene.set_camera(cam, (tile, tile))
                scene.draw(self.settings, defines=variant)
        finally:
            # the framebuffer bound before, unless released since (then the default one)
            alive = previous is not None and type(previous.mglo).__name__ != "InvalidObject"
            (previous if alive and previous is not None else self.ctx.detect_framebuffer(0)).use()
            self.ctx.viewport = viewport
        self.cascades = cascades
        self.record = shadow_record(cascades, self.depth_bias, self.normal_offset)
        self.buffer.write(self.record.tobytes())
        self.bind()

    def bind(self) -> None:
        """Bind the Shadow block at ``SHADOW_BINDING`` and the atlas at ``SHADOW_UNIT``."""
        self.buffer.bind_to_uniform_block(SHADOW_BINDING)
        self.texture.use(SHADOW_UNIT)

    def read_depth(self) -> NDArray[np.float32]:
        """The atlas's depths, (H, W) float32, row 0 at texture v = 0 (the bottom)."""
        w, h = self.texture.size
        return np.frombuffer(self.texture.read(), np.float32).reshape(h, w).copy()

    @property
    def layout(self) -> tuple[int, int]:
        """(columns, rows) of tiles of the current atlas."""
        return atlas_layout(self.cascades.count if self.cascades is not None else 1)

    def release(self) -> None:
        """Release the GL objects (idempotent)."""
        if self.fbo is not None:
            if context_alive(self.ctx):   # never delete the current framebuffer (see targets.py)
                self.ctx.detect_framebuffer(0).use()
            self.fbo.release()
            self.fbo = None
        self.texture.release()
        self.buffer.release()
