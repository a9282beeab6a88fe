"""Screen-space ambient occlusion of a scene's frame: :class:`SsaoPass`.

One :meth:`SsaoPass.run` makes the frame's occlusion texture in three draws:

1. the scene's **label pass** (``leaf.vert`` + ``leaf.frag`` with ``LEAF_AOV``, the caller's extra
   defines merged in, e.g. ``LEAF_WIND``, so the occlusion moves with the leaves) into a
   single-sample framebuffer laid out as :data:`~leafview.gpu.layout.AOV_OUTPUTS`, whose depth
   (view-space, along the optical axis) and normal attachments are textures;
2. ``ssao.vert`` + ``ssao.frag``: a full-screen triangle estimating the occlusion of every pixel
   from its depth and normal with a seeded hemisphere kernel (steps 1-4 of
   :mod:`leafview.scene.ssao`, the numpy reference);
3. ``ssao.vert`` + ``ssao_blur.frag``: the surface-aware 4 × 4 blur (step 5).

The result, R16F with 1 = unoccluded and exactly the frame's size (one texel per pixel of the final,
resolved frame, which ``leaf.frag`` reads with ``texelFetch(ambient_occlusion,
ivec2(gl_FragCoord.xy), 0)`` under ``LEAF_SSAO``), is left bound at
:data:`~leafview.gpu.layout.SSAO_UNIT`. The depth and normal inputs are bound at
:data:`~leafview.gpu.layout.SSAO_DEPTH_UNIT` and :data:`~leafview.gpu.layout.SSAO_NORMAL_UNIT`
while the pass runs. Textures and framebuffers belong to the pass (remade when the size changes,
released by :meth:`SsaoPass.release`); the programs belong to the scene's program cache.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.gpu.context import check_error
from leafview.gpu.layout import AOV_OUTPUTS, SSAO_DEPTH_UNIT, SSAO_NORMAL_UNIT, SSAO_UNIT
from leafview.gpu.limits import ContextLimits, check_image, check_memory, context_alive, ensure_alive
from leafview.gpu.owner import GLObjects
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.scene.camera import Camera
from leafview.scene.ssao import BLUR_PLANE, MAX_SAMPLES, OBSCURANCE_EPS, SsaoSettings, default_radius, ssao_kernel

__all__ = ["SsaoPass", "SsaoSettings"]

_PROGRAM_DEFINES = {"SSAO_MAX_SAMPLES": MAX_SAMPLES, "SSAO_EPS": f"{OBSCURANCE_EPS:.6e}"}
_LABEL_DEFINES = {"LEAF_AOV": 1}
_DEFAULT_CULL = CullSettings()   # frozen: a shared default is safe
_NO_DEFINES: Mapping[str, object] = {}
_DEFAULT_SETTINGS = SsaoSettings()   # frozen: a shared default is safe


def _write(prog: moderngl.Program, name: str, data: bytes) -> None:
    """Write raw bytes (an array or a matrix) to uniform ``name`` of ``prog``."""
    member = prog[name]
    assert isinstance(member, moderngl.Uniform), name
    member.write(data)


class _Images:
    """The pass's textures and framebuffers at one size (one owner, released together)."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        self.size = size
        w, h = size
        check_image(ContextLimits.of(ctx), size, 0, linear=True, copies=0)
        per_pixel = sum(o.nbytes for o in AOV_OUTPUTS) + 4 + 4 + 2   # labels, depth buffer, raw AO, AO
        check_memory(w * h * per_pixel, "size", f"the {w}×{h} ambient occlusion images")
        self.objects = GLObjects()
        try:
            attachments: list[Any] = []
            for o in AOV_OUTPUTS:
                if o.name in ("depth", "normal"):
                    tex = self.objects.own(ctx.texture(size, o.components, dtype=o.dtype))
                    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
                    setattr(self, o.name, tex)
                    attachments.append(tex)
                else:
                    attachments.append(self.objects.own(ctx.renderbuffer(size, o.components, dtype=o.dtype)))
            self.depth: moderngl.Texture
            self.normal: moderngl.Texture
            zbuffer = self.objects.own(ctx.depth_renderbuffer(size))
            self.labels = self.objects.own(ctx.framebuffer(attachments, zbuffer))
            self.raw = self.objects.own(ctx.texture(size, 1, dtype="f4"))
            self.ao = self.objects.own(ctx.texture(size, 1, dtype="f2"))
            for tex in (self.raw, self.ao):
                tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self.raw_fbo = self.objects.own(ctx.framebuffer([self.raw]))
            self.ao_fbo = self.objects.own(ctx.framebuffer([self.ao]))
        except BaseException:
            self.release(ctx)
            raise

    def release(self, ctx: moderngl.Context) -> None:
        if len(self.objects) and context_alive(ctx):
            ctx.detect_framebuffer(0).use()   # never delete the current framebuffer (see targets.py)
        self.objects.release()


class SsaoPass:
    """The screen-space ambient occlusion of a scene's frame (see the module docstring).

    Parameters
    ----------
    ctx: the context the scenes are drawn in.
    settings: kernel, radius and strength (:class:`~leafview.scene.ssao.SsaoSettings`); with
        ``radius`` None, ρ is 0.5 × the median leaf length of the scene drawn.
    """

    def __init__(self, ctx: moderngl.Context, settings: SsaoSettings = _DEFAULT_SETTINGS) -> None:
        if not isinstance(settings, SsaoSettings):
            raise TypeError(f"settings must be SsaoSettings, got {type(settings).__name__}")
        self.ctx, self.settings = ctx, settings
        kernel, rotations = ssao_kernel(settings.samples, settings.seed)
        padded = np.zeros((MAX_SAMPLES, 3), np.float32)
        padded[:len(kernel)] = kernel
        self._kernel, self._rotations = padded.tobytes(), rotations.astype(np.float32).tobytes()
        self._images: _Images | None = None
        self._vaos: dict[int, tuple[moderngl.Program, moderngl.VertexArray]] = {}
        self._radius: tuple[object, float] | None = None
        self.radius: float | None = None
        """ρ (world units) of the last :meth:`run`."""

    # -- the pass ------------------------------------------------------------------------------
    def radius_for(self, scene: SceneRenderer) -> float:
        """ρ for ``scene``: the settings' radius, else 0.5 × its median leaf length (computed once
        per scene)."""
        if self.settings.radius is not None:
            return float(self.settings.radius)
        if self._radius is None or self._radius[0] is not scene.scene:
            self._radius = (scene.scene, default_radius(scene.scene.matrices))
        return self._radius[1]

    def _vao(self, prog: moderngl.Program) -> moderngl.VertexArray:
        found = self._vaos.get(id(prog))
        if found is None or found[0] is not prog:
            found = self._vaos[id(prog)] = (prog, self.ctx.vertex_array(prog, []))
        return found[1]

    def run(self, scene: SceneRenderer, camera: Camera, size: tuple[int, int],
            defines: Mapping[str, object] = _NO_DEFINES, *, cull: CullSettings = _DEFAULT_CULL) -> None:
        """Draw ``scene``'s labels from ``camera`` at ``size`` = (w, h) (the frame's size) with the
        extra program ``defines`` and ``cull`` settings (those of the frame, so that the occlusion
        sees the frame's geometry), estimate and blur the occlusion, and bind the result at
        :data:`~leafview.gpu.layout.SSAO_UNIT`.

        Calls ``scene.set_camera(camera, size)``. The framebuffer and viewport bound before the
        call are bound again after it; depth testing is left off.

        Raises :class:`~leafview.errors.GpuLimitError` for a size the context cannot hold and
        :class:`~leafview.errors.GLContextLost` for a released context."""
        ctx = self.ctx
        size = (int(size[0]), int(size[1]))
        ensure_alive(ctx, "the ambient occlusion pass")
        # the bound framebuffer (moderngl tracks it once some framebuffer's use() ran)
        previous = ctx.fbo if ctx.fbo is not None else ctx.detect_framebuffer()
        viewport = ctx.viewport
        if self._images is None or self._images.size != size:
            if self._images is not None:
                self._images.release(ctx)
                self._images = None
            self._images = _Images(ctx, size)
        img = self._images
        rho = self.radius = self.radius_for(scene)
        s = self.settings
        programs = scene.resources.programs
        occlusion = programs.program("ssao.vert", "ssao.frag", defines=_PROGRAM_DEFINES)
        blur = programs.program("ssao.vert", "ssao_blur.frag", defines=_PROGRAM_DEFINES)
        try:
            # 1. labels: depth along the optical axis and the visible side's world normal
            img.labels.use()
            ctx.viewport = (0, 0, *size)
            img.labels.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            scene.set_camera(camera, size)
            scene.draw(cull, defines={**_LABEL_DEFINES, **dict(defines)})
            # 2. raw occlusion
            ctx.enable_only(moderngl.NOTHING)
            img.depth.use(location=SSAO_DEPTH_UNIT)
            img.normal.use(location=SSAO_NORMAL_UNIT)
            p = np.asarray(camera.proj, np.float64)
            shift = (p[0, 2], p[1, 2]) if camera.perspective else (p[0, 3], p[1, 3])
            rotation = np.asarray(camera.view, np.float64)[:3, :3].T.astype("f4").tobytes()
            for prog in (occlusion, blur):
                _write(prog, "view_rotation", rotation)
                prog["proj_terms"] = (float(p[0, 0]), float(p[1, 1]), float(shift[0]), float(shift[1]))
                prog["perspective"] = bool(camera.perspective)
            occlusion["radius"] = rho
            occlusion["bias"] = s.bias * rho
            occlusion["strength"] = float(s.strength)
            occlusion["samples"] = int(s.samples)
            _write(occlusion, "kernel", self._kernel)
            _write(occlusion, "rotations", self._rotations)
            img.raw_fbo.use()
            self._vao(occlusion).render(moderngl.TRIANGLES, vertices=3)
            # 3. blur; the raw AO is read at SSAO_UNIT, the result bound there after
            img.raw.use(location=SSAO_UNIT)
            blur["plane_tolerance"] = BLUR_PLANE * rho
            img.ao_fbo.use()
            self._vao(blur).render(moderngl.TRIANGLES, vertices=3)
            img.ao.use(location=SSAO_UNIT)
        finally:
            if context_alive(ctx):
                previous.use()
                ctx.viewport = viewport
        check_error(ctx, "the ambient occlusion pass")

    def bind(self) -> None:
        """Bind the last result at :data:`~leafview.gpu.layout.SSAO_UNIT` again (another pass may
        have used the unit since). Raises RuntimeError before the first :meth:`run`."""
        self._require().ao.use(location=SSAO_UNIT)

    # -- readback (tests, debugging) -------------------------------------------------------------
    def _require(self) -> _Images:
        if self._images is None:
            raise RuntimeError("SsaoPass: nothing was run yet (or it was released)")
        return self._images

    @property
    def texture(self) -> moderngl.Texture | None:
        """The last occlusion texture (R16F, the frame's size), or None before :meth:`run`."""
        return None if self._images is None else self._images.ao

    def _read(self, tex: moderngl.Texture, components: int, dtype: str) -> NDArray[np.float32]:
        w, h = tex.size
        data = np.frombuffer(tex.read(alignment=1), np.float16 if dtype == "f2" else np.float32)
        image = data.reshape(h, w, components) if components > 1 else data.reshape(h, w)
        return np.ascontiguousarray(image[::-1]).astype(np.float32)

    def read(self) -> NDArray[np.float32]:
        """The last occlusion, (h, w) float32, 1 = unoccluded, row 0 at the top."""
        return self._read(self._require().ao, 1, "f2")

    def read_raw(self) -> NDArray[np.float32]:
        """The last unblurred occlusion, (h, w) float32, row 0 at the top."""
        return self._read(self._require().raw, 1, "f4")

    def read_depth(self) -> NDArray[np.float32]:
        """The depth the last run used: (h, w) float32, along the optical axis, 0 background."""
        return self._read(self._require().depth, 1, "f4")

    def read_normal(self) -> NDArray[np.float32]:
        """The world normals the last run used: (h, w, 3) float32, 0 background."""
        return np.ascontiguousarray(self._read(self._require().normal, 4, "f4")[..., :3])

    def release(self) -> None:
        """Release the textures, framebuffers and vertex arrays (idempotent)."""
        if self._images is not None:
            self._images.release(self.ctx)
            self._images = None
        while self._vaos:
            _, (_, vao) = self._vaos.popitem()
            vao.release()
        self._radius = None

    def __enter__(self) -> SsaoPass:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
