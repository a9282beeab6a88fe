"""Wind: a time-varying turbulent load on every leaf (the ``[wind]`` table of a scene file,
``--wind SPEED --time T`` on the command line).

Conventions: the wind blows *towards* ``direction`` (degrees counter-clockwise from +x, in the
ground plane), ``speed`` in scene units per second, ``time`` in seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leafview.core.fieldspec import spec_field
from leafview.core.settings import SettingsTable

__all__ = ["WindSettings"]

_G = "wind"


@dataclass(frozen=True)
class WindSettings(SettingsTable):
    """The wind of a frame: speed, direction, time and the turbulence of its load."""

    TABLE = "wind"

    speed: float = spec_field("wind speed", _G, 0.0, 20.0, 0.1, hard=(0.0, 60.0), default=0.0)
    direction: float = spec_field("wind direction (degrees)", _G, -180.0, 180.0, 1.0, hard=(-360.0, 360.0),
                                  default=0.0)
    time: float = spec_field("time (s)", _G, 0.0, 60.0, 0.01, hard=(0.0, 1e6), default=0.0)
    gust: float = spec_field("gustiness λ (eq. 5)", _G, 0.0, 1.0, 0.01, hard=(0.0, 2.0), default=0.5)
    flutter: float = spec_field("blade flutter", _G, 0.0, 2.0, 0.01, hard=(0.0, 4.0), default=1.0)
    seed: int = spec_field("seed", _G, 0, 9999, 1, hard=(0, 2**31 - 1), kind="int", default=0)

    @property
    def active(self) -> bool:
        return self.speed > 0.0

    @property
    def heading(self) -> NDArray[np.float64]:
        """Unit vector the wind blows towards (world, z = 0)."""
        a = math.radians(self.direction)
        return np.array([math.cos(a), math.sin(a), 0.0])
