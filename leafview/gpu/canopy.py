"""A canopy frame: sun and shadows, sky and ground, ambient occlusion and wind around a
:class:`~leafview.gpu.scene.SceneRenderer`'s leaves.

One frame runs, in order:

1. the wind's uniforms (:class:`~leafview.gpu.wind.WindUniforms`) when the wind blows: every draw
   of the scene below (shadow maps and occlusion too) displaces the leaves the same way
   (:func:`~leafview.gpu.wind.wind_defines`);
2. the sun's shadow maps (:class:`~leafview.gpu.shadow.ShadowPass`) when ``light.shadows``;
3. the screen-space ambient occlusion (:class:`~leafview.gpu.ssao.SsaoPass`) when ``light.ssao``;
4. the frame: cleared, the sky (:class:`~leafview.gpu.sky.SkyPass`; without it the clear colour
   stays), the ground (:class:`~leafview.gpu.sky.GroundPass`), then the leaves and stems with
   ``leaf.frag``'s ``LEAF_CANOPY`` variant (+ ``LEAF_SHADOWS``, ``LEAF_SSAO``): their shading is
   :mod:`leafview.scene.leaf_light`'s.

Alpha to coverage: a textured leaf's margin (teeth and holes of its image) is written as a sample
mask from its alpha (``leaf.frag``'s ``coverage_mask``: moderngl 5 offers no
``SAMPLE_ALPHA_TO_COVERAGE`` switch, its ``enable`` flags being BLEND, DEPTH_TEST, CULL_FACE,
RASTERIZER_DISCARD and PROGRAM_POINT_SIZE); it is on for multisampled targets only (the Light
block's ``flags.z``), a single-sample one keeps the alpha test at 0.5.
"""

from __future__ import annotations

from collections.abc import Callable

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.deform.wind import WindSettings
from leafview.errors import GLUnavailable
from leafview.gpu.context import check_error, is_software
from leafview.gpu.layout import shadow_defines
from leafview.gpu.light import LightUniforms
from leafview.gpu.limits import ensure_alive
from leafview.gpu.owner import GLObjects
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.gpu.shadow import ShadowPass
from leafview.gpu.sky import GroundPass, SkyPass
from leafview.gpu.ssao import SsaoPass
from leafview.gpu.wind import WindUniforms, wind_defines
from leafview.scene.camera import Camera
from leafview.scene.lighting import LightSettings
from leafview.scene.sky import contacts_of, ground_height

__all__ = ["CanopyRenderer", "canopy_defines", "resolve_shadow_filter", "MIN_GL_VERSION", "BACKGROUND"]

MIN_GL_VERSION = 450   # sample masks, depth-compare samplers, multisampled targets
BACKGROUND = (0.0, 0.0, 0.0, 0.0)   # without a sky: transparent, as SceneRenderer.render
_LIGHT, _WIND, _CULL = LightSettings(), WindSettings(), CullSettings()   # the defaults


def resolve_shadow_filter(shadow_filter: str, gl_renderer: str) -> str:
    """The shadow filter a renderer named ``gl_renderer`` uses for the setting ``shadow_filter``:
    ``"auto"`` is ``"soft"`` on a GPU and ``"fast"`` on a CPU rasteriser (the 3 × 3 filter's four
    gathers cost llvmpipe about as much again as the shadow maps: ``leafview bench canopy``)."""
    if shadow_filter != "auto":
        return shadow_filter
    return "fast" if is_software(gl_renderer) else "soft"


def canopy_defines(light: LightSettings, wind: WindSettings, gl_renderer: str = "") -> dict[str, object]:
    """The program defines of the leaves' draw for ``light`` and ``wind`` on ``gl_renderer`` (which
    resolves an ``"auto"`` shadow filter; empty: a GPU's)."""
    shadow_filter = resolve_shadow_filter(light.shadow_filter, gl_renderer)
    defines: dict[str, object] = {"LEAF_CANOPY": 1, **shadow_defines(light.shadows, shadow_filter)}
    if light.ssao:
        defines["LEAF_SSAO"] = 1
    defines.update(wind_defines(wind))
    return defines


class CanopyRenderer:
    """Draws a scene's canopy look (see the module).

    Parameters
    ----------
    scene_renderer: the scene's renderer (not owned: the caller releases it after this one).
    light: sun, sky, ground and camera response (``set_light`` changes it between frames).
    wind: the wind (``set_wind``, or ``render(wind=...)`` for one frame of an animation).

    Raises :class:`~leafview.errors.GLUnavailable` when the context is older than OpenGL 4.5.
    """

    def __init__(self, scene_renderer: SceneRenderer, light: LightSettings = _LIGHT,
                 wind: WindSettings = _WIND) -> None:
        self.scene = scene_renderer
        self.ctx: moderngl.Context = scene_renderer.ctx
        ensure_alive(self.ctx, "setting up a canopy frame")
        version = int(self.ctx.version_code)
        if version < MIN_GL_VERSION:
            raise GLUnavailable(f"canopy frames need OpenGL {MIN_GL_VERSION // 100}.{MIN_GL_VERSION % 100 // 10} "
                                f"(sample masks, shadow samplers); this context is {version // 100}.{version % 100 // 10}")
        self._objects = GLObjects()
        self.ssao: SsaoPass | None = None
        self._grounds: dict[tuple[bool, str], GroundPass] = {}   # without and with the shadow maps (per filter)
        self.gl_renderer = str(self.ctx.info.get("GL_RENDERER", ""))
        try:
            self.light_uniforms = self._objects.own(LightUniforms(self.ctx))
            self.shadow = self._objects.own(ShadowPass(self.ctx))
            self.sky = self._objects.own(SkyPass(self.ctx, programs=scene_renderer.resources.programs))
            self.wind_uniforms = self._objects.own(WindUniforms(self.ctx))
            self.ground_z = ground_height(scene_renderer.scene)
            self.light_uniforms.set_ground_height(self.ground_z)
        except BaseException:
            self._objects.release()
            raise
        self.light = light
        self.wind = wind
        self._samples = 0
        self.set_light(light)
        self.set_wind(wind)

    # -- settings ----------------------------------------------------------------------------
    def set_light(self, light: LightSettings) -> None:
        """Use ``light`` from the next frame (the viewer's panel); the occlusion pass is made on
        first use and kept."""
        self.light = light
        if light.ssao and self.ssao is None:
            self.ssao = self._objects.own(SsaoPass(self.ctx))
        self._write_light(self._samples)

    def set_wind(self, wind: WindSettings) -> None:
        """Use ``wind`` (its time included) from the next frame."""
        self.wind = wind
        self.wind_uniforms.set(wind)

    def _write_light(self, samples: int) -> None:
        # alpha to coverage only where there are samples to cover (else the alpha test)
        light = self.light
        if light.alpha_to_coverage and samples <= 1:
            light = light.replace(alpha_to_coverage=False)
        self.light_uniforms.set(light)
        self._samples = samples

    # -- frames ------------------------------------------------------------------------------
    def render(self, camera: Camera, size: tuple[int, int], settings: CullSettings = _CULL, *,
               samples: int = 4, wind: WindSettings | None = None,
               background: tuple[float, float, float, float] = BACKGROUND) -> NDArray[np.uint8]:
        """One frame offscreen: (h, w, 4) uint8 RGBA (sRGB, tone mapped), row 0 at the top, in a
        render target of the scene's shared resources (multisampled with ``samples`` > 0, at most
        the context's). ``wind``: this frame's wind (kept for the next ones); ``background``: the
        clear colour where no sky is drawn."""
        ctx = self.ctx
        size = (int(size[0]), int(size[1]))
        ensure_alive(ctx, "rendering a canopy frame")
        samples = min(max(int(samples), 0), int(ctx.max_samples))
        if wind is not None:
            self.set_wind(wind)
        target = self.scene.resources.target(size, samples)
        self._frame(camera, size, settings, target.fbo.use, target.clear, background, samples)
        image: NDArray[np.uint8] = target.read()
        check_error(ctx, "canopy frame")
        return image

    def draw(self, camera: Camera, size: tuple[int, int], settings: CullSettings = _CULL, *,
             framebuffer: moderngl.Framebuffer | None = None,
             background: tuple[float, float, float, float] = BACKGROUND) -> None:
        """One frame into ``framebuffer`` (None: the one bound now, e.g. the viewer's window),
        cleared first, its viewport ``(0, 0, *size)``."""
        ensure_alive(self.ctx, "drawing a canopy frame")
        fbo = framebuffer if framebuffer is not None else self.ctx.detect_framebuffer()
        samples = int(getattr(fbo, "samples", 0) or 0)

        def clear(rgba: tuple[float, float, float, float]) -> None:
            r, g, b, a = (float(x) for x in rgba)
            fbo.clear(r, g, b, a, depth=1.0)

        self._frame(camera, (int(size[0]), int(size[1])), settings, fbo.use, clear, background, samples)

    def _frame(self, camera: Camera, size: tuple[int, int], settings: CullSettings, bind: Callable[[], None],
               clear: Callable[[tuple[float, float, float, float]], None],
               background: tuple[float, float, float, float], samples: int) -> None:
        ctx, scene, light = self.ctx, self.scene, self.light
        if samples != self._samples:
            self._write_light(samples)
        wind = wind_defines(self.wind)
        # the block, and the culling pass's padding of every leaf by the farthest the wind moves it
        # (zero when still: the cull program is shared)
        self.wind_uniforms.bind(scene)
        if light.shadows:
            self.shadow.render(scene, camera, size, light, defines=wind)
        scene.set_camera(camera, size)
        if light.ssao:
            assert self.ssao is not None
            self.ssao.run(scene, camera, size, defines=wind, cull=settings)
            scene.set_camera(camera, size)
        bind()
        ctx.viewport = (0, 0, *size)
        self.light_uniforms.bind()
        clear((0.0, 0.0, 0.0, 1.0) if light.sky else background)
        if light.sky:
            self.sky.draw(camera, size)
        if light.ground:
            ground = self.ground(light.shadows, light.shadow_filter)
            ground.draw(camera, scene.bounds, size=size, height=self.ground_z)
        # the passes above may have used the units and bindings since: bind everything again
        self.light_uniforms.bind()
        if light.shadows:
            self.shadow.bind()
        if light.ssao:
            assert self.ssao is not None
            self.ssao.bind()
        self.wind_uniforms.bind(scene)
        scene.draw(settings, defines=canopy_defines(light, self.wind, self.gl_renderer))

    def ground(self, shadows: bool, shadow_filter: str = "auto") -> GroundPass:
        """The ground pass with or without the sun's shadow maps, read with ``shadow_filter``
        (``"auto"`` resolved for this context, as the leaves' by :func:`canopy_defines`; made on
        first use, with the scene's contact points)."""
        shadow_filter = resolve_shadow_filter(shadow_filter, self.gl_renderer)
        key = (bool(shadows), shadow_filter if shadows else "")
        found = self._grounds.get(key)
        if found is None:
            found = self._objects.own(GroundPass(self.ctx, shadows=shadows, shadow_filter=shadow_filter,
                                                 programs=self.scene.resources.programs))
            found.set_contacts(*contacts_of(self.scene.scene))
            self._grounds[key] = found
        return found

    def release(self) -> None:
        """Release the passes (idempotent); the scene renderer stays the caller's."""
        self.ssao = None
        self._grounds.clear()
        self._objects.release()

    def __enter__(self) -> CanopyRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
