"""The Light uniform block of a canopy frame (:data:`~leafview.gpu.layout.LIGHT_BLOCK`): sun, sky,
ground, ambient spherical harmonics and camera response, filled from a
:class:`~leafview.scene.lighting.LightSettings` through :func:`leafview.scene.sky.sky_model`.

Irradiances are folded (divided by π, see :mod:`leafview.scene.sky`): ``sun.w`` is the settings'
sun intensity, ``sky_sh`` the convolved coefficients Â_l L_lm / π, so that ``sh_irradiance(n)`` of
``sky_model.glsl`` is what an albedo multiplies.
"""

from __future__ import annotations

import math
from typing import Self

import moderngl
import numpy as np
from numpy.typing import ArrayLike

from leafview.errors import ParamError
from leafview.gpu.layout import LIGHT_BINDING, LIGHT_BLOCK
from leafview.scene.lighting import LightSettings
from leafview.scene.sky import GROUND_ALBEDO, HORIZON_HAZE, SH_BANDS, SkyModel, sky_model

__all__ = ["LightUniforms", "fill_light"]


def fill_light(record: np.ndarray, light: LightSettings, model: SkyModel, *, ground_height: float = 0.0) -> None:
    """Fill a LIGHT_BLOCK ``record`` from ``light`` and its sky ``model`` (the numpy side of
    ``sky_model.glsl`` and ``tonemap.glsl``)."""
    record["sun"] = (*model.sun, model.sun_irradiance)
    record["sun_colour"] = (*model.sun_colour, 0.0)
    record["sky_zenith"] = (*model.zenith, float(light.sky))
    record["sky_horizon"] = (*model.horizon, float(light.ground))
    a, b, c, d, e = model.perez
    record["sky_perez"] = ((a, b, c, d), (e, model.inv_f0, HORIZON_HAZE, 0.0))
    record["ground"] = (*model.ground_albedo, float(ground_height))
    record["ground_radiance"] = (*model.ground_radiance, 0.0)
    sh = np.zeros((9, 4))
    sh[:, :3] = SH_BANDS[:, None] * model.sh / math.pi
    record["sky_sh"] = sh
    record["tone"] = (2.0 ** float(light.exposure), 1.0 if light.tone == "filmic" else 0.0,
                      float(light.transmission), float(light.gloss))
    record["flags"] = (int(light.shadows), int(light.ssao), int(light.alpha_to_coverage), 0)


class LightUniforms:
    """One Light uniform block: :meth:`set` fills it from a :class:`LightSettings`, :meth:`bind`
    binds it at ``LIGHT_BINDING``. ``model`` is the last :class:`SkyModel` (the numpy twin of what
    the shaders see)."""

    def __init__(self, ctx: moderngl.Context, ground_albedo: ArrayLike = GROUND_ALBEDO) -> None:
        self.ctx = ctx
        self.record = LIGHT_BLOCK.zeros()
        self.buffer = ctx.buffer(reserve=LIGHT_BLOCK.nbytes)
        self.ground_albedo = np.asarray(ground_albedo, np.float64)
        self.ground_z = 0.0
        self.light = LightSettings()
        self.model = sky_model(self.light, self.ground_albedo)
        self._write()

    def set(self, light: LightSettings) -> None:
        """Fill the block from ``light`` (checked: a bad value raises ParamError, nothing written)."""
        same_sky = (light.sun, light.sun_intensity) == (self.light.sun, self.light.sun_intensity)
        model = self.model if same_sky else sky_model(light, self.ground_albedo)   # exposure etc.: no new sky
        light.check()
        self.light, self.model = light, model
        self._write()

    def set_ground_height(self, z: float) -> None:
        """The ground's height (world z; e.g. :func:`leafview.scene.sky.ground_height` of the scene)."""
        if not math.isfinite(float(z)):
            raise ParamError("light.ground_height", f"must be a finite number, got {z!r}")
        self.ground_z = float(z)
        self._write()

    def _write(self) -> None:
        fill_light(self.record, self.light, self.model, ground_height=self.ground_z)
        self.buffer.write(self.record.tobytes())

    def bind(self) -> None:
        self.buffer.bind_to_uniform_block(LIGHT_BINDING)

    def release(self) -> None:
        """Release the buffer (idempotent)."""
        self.buffer.release()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
