"""The light of a canopy frame: sun, sky, ground, tone mapping (the ``[light]`` table of a scene
file, ``--shadows``/``--sun``/``--sky``/``--ground``/``--exposure`` on the command line, the light
panel of the scene viewer).

Conventions: world +z is up. The sun's azimuth is in degrees counter-clockwise from +x towards +y,
its elevation in degrees above the horizon; :func:`sun_direction` is the unit vector *towards* the
sun. Exposure is in stops (the image is scaled by 2^exposure before tone mapping).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leafview.core.fieldspec import spec_field
from leafview.core.settings import SettingsTable
from leafview.errors import ParamError

__all__ = ["LightSettings", "sun_direction", "TONE_MAPS", "SHADOW_FILTERS"]

_G = "light"
TONE_MAPS = ("filmic", "linear")
# the shadow maps' filter (leafview.scene.sun.visibility): "soft" the 3 × 3 percentage-closer
# filter, "fast" one bilinear depth-compare tap (2 × 2 texels; about half the lookup's cost on a CPU
# rasteriser), "auto" soft on a GPU and fast on a CPU rasteriser (Mesa llvmpipe)
SHADOW_FILTERS = ("auto", "soft", "fast")


@dataclass(frozen=True)
class LightSettings(SettingsTable):
    """Sun, sky, ground and camera response of a canopy frame."""

    TABLE = "light"

    shadows: bool = spec_field("sun shadows", _G, 0, 1, 1, kind="bool", default=True)
    sun: tuple[float, float] = spec_field("sun azimuth, elevation (degrees)", _G, -180.0, 360.0, 1.0,
                                          hard=(-360.0, 360.0), kind="pair", default=(135.0, 50.0))
    sun_intensity: float = spec_field("sun intensity", _G, 0.0, 4.0, 0.05, hard=(0.0, 100.0), default=1.6)
    sky: bool = spec_field("sky", _G, 0, 1, 1, kind="bool", default=True)
    ground: bool = spec_field("ground plane", _G, 0, 1, 1, kind="bool", default=True)
    exposure: float = spec_field("exposure (stops)", _G, -4.0, 4.0, 0.1, hard=(-10.0, 10.0), default=0.0)
    tone: str = spec_field("tone mapping", _G, 0, 1, 1, kind="choice", choices=TONE_MAPS, default="filmic")
    transmission: float = spec_field("leaf transmission", _G, 0.0, 2.0, 0.05, hard=(0.0, 4.0), default=1.0)
    gloss: float = spec_field("cuticle gloss", _G, 0.0, 2.0, 0.05, hard=(0.0, 4.0), default=1.0)
    ssao: bool = spec_field("ambient occlusion (SSAO)", _G, 0, 1, 1, kind="bool", default=False)
    alpha_to_coverage: bool = spec_field("alpha to coverage", _G, 0, 1, 1, kind="bool", default=True)
    shadow_size: int = spec_field("shadow map size (texels)", _G, 512, 4096, 256, hard=(256, 8192), kind="int",
                                  default=2048)
    cascades: int = spec_field("shadow cascades (0: automatic)", _G, 0, 4, 1, hard=(0, 4), kind="int", default=0)
    shadow_filter: str = spec_field("shadow filter", _G, 0, 1, 1, kind="choice", choices=SHADOW_FILTERS,
                                    default="auto")

    def check(self) -> None:
        az, el = self.sun
        if not -180.0 <= az <= 360.0:
            raise ParamError("light.sun[0]", f"azimuth {az!r} must lie in [-180, 360] degrees")
        if not 0.0 <= el <= 90.0:
            raise ParamError("light.sun[1]", f"elevation {el!r} must lie in [0, 90] degrees (0: on the horizon)")

    @property
    def direction(self) -> NDArray[np.float64]:
        """Unit vector towards the sun (world)."""
        return sun_direction(*self.sun)


def sun_direction(azimuth: float, elevation: float) -> NDArray[np.float64]:
    """Unit vector towards a sun at ``azimuth`` (degrees counter-clockwise from +x) and
    ``elevation`` (degrees above the horizon), +z up."""
    a, e = math.radians(azimuth), math.radians(elevation)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
