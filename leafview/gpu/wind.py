"""The Wind uniform block (``WIND_BLOCK`` at ``WIND_BINDING``): what ``shaders/leaf_wind.glsl``
reads to move every leaf of a ``LEAF_WIND`` draw, and the culling pass's padding for it.

The wind's fBm signal (Geng, Hu & Zhang 2014, eqs 1-2) is a ripple signal
(:func:`leafview.deform.fbm.ripple_signal`, the same spectral synthesis, cached per (seed, β)) carried
in the block itself: a uniform read costs the vertex stage less than a
storage-buffer gather on llvmpipe, and the scene's ripple rows stay the species' own. The
time-dependent phases are reduced modulo the signal's period in float64
(:func:`leafview.deform.wind.wind_frame`), so a frame at t = 10⁶ s is as exact as one at t = 0.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import moderngl
import numpy as np

from leafview.deform.wind import SIGNAL_SAMPLES, WindFrame, WindSettings, cull_bounds, wind_frame
from leafview.gpu.layout import WIND_BINDING, WIND_BLOCK

if TYPE_CHECKING:
    from leafview.gpu.scene import SceneRenderer

__all__ = ["WindUniforms", "wind_defines", "fill_wind", "set_cull_padding", "WIND_PAD_UNIFORM"]

WIND_PAD_UNIFORM = "wind_pad"
"""``vec3`` uniform of ``scene_cull.comp``: :func:`leafview.deform.wind.cull_bounds` of the wind
drawn (zero: no padding, the culling of a still scene)."""


def wind_defines(wind: WindSettings) -> dict[str, int]:
    """``{"LEAF_WIND": 1}`` when the wind blows, else ``{}`` (still leaves draw the plain program)."""
    return {"LEAF_WIND": 1} if wind.active else {}


def fill_wind(record: np.ndarray, wind: WindSettings | WindFrame) -> WindFrame:
    """Fill a WIND_BLOCK record from ``wind``; returns the frame it was made from."""
    f = wind if isinstance(wind, WindFrame) else wind_frame(wind)
    assert f.signal.size == SIGNAL_SAMPLES == 4 * record["signal"].shape[0]
    record["wind"] = (f.heading[0], f.heading[1], f.speed, f.time)
    record["gust"] = (f.load, f.gust, f.inv_length, f.gust_phase)
    record["flutter"] = (f.sway_phase, f.flutter_phase, f.flutter, 0.0)
    record["ids"] = (np.int32(np.uint32(f.seed).view(np.int32)), 0, 0, 0)
    record["signal"] = f.signal.reshape(-1, 4)
    return f


def set_cull_padding(scene: SceneRenderer, wind: WindSettings | WindFrame | None) -> None:
    """Make ``scene``'s culling pass pad every leaf's bounding sphere by the farthest the wind can
    move it (None or a still wind: no padding). The cull program is shared by the renderers of one
    :class:`~leafview.gpu.resources.GpuResources`: set it before each draw."""
    pad = (0.0, 0.0, 0.0) if wind is None else cull_bounds(wind)
    uniform = scene.cull.get(WIND_PAD_UNIFORM, None)
    if isinstance(uniform, moderngl.Uniform):
        uniform.value = tuple(float(x) for x in pad)


class WindUniforms:
    """One Wind uniform block: :meth:`set` writes it, :meth:`bind` binds it at ``WIND_BINDING``
    (and, given the scene renderer, sets its culling padding)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.record = WIND_BLOCK.zeros()
        self.buffer = ctx.buffer(reserve=WIND_BLOCK.nbytes)
        self.frame: WindFrame | None = None
        self.wind = WindSettings()
        self.buffer.write(self.record.tobytes())

    def set(self, wind: WindSettings) -> None:
        """Write the block for ``wind`` (its time included; the signal of a (seed, β) is cached)."""
        self.wind = wind
        self.frame = fill_wind(self.record, wind)
        self.buffer.write(self.record.tobytes())

    def bind(self, scene: SceneRenderer | None = None) -> None:
        self.buffer.bind_to_uniform_block(WIND_BINDING)
        if scene is not None:
            set_cull_padding(scene, self.frame if self.wind.active else None)

    def release(self) -> None:
        self.buffer.release()

