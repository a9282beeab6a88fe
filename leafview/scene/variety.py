"""Per-leaf variety within a species (Geng, Hu & Zhang 2014, sec. 6: many different leaves from
one set of parameters): each leaf draws its ripple phase, ripple amplitude and bend load from
ranges set per species (``[[species]] variety = {...}`` in a scene file).
"""

from __future__ import annotations

from dataclasses import dataclass

from leafview.core.fieldspec import spec_field
from leafview.core.settings import SettingsTable
from leafview.errors import ParamError

__all__ = ["Variety"]

_G = "variety"


@dataclass(frozen=True)
class Variety(SettingsTable):
    """Ranges a species' leaves draw from (uniformly, seeded by the scene): a ripple phase offset
    (added to θ of eq. 5, in units of the signal's samples), factors on the ripple amplitude P and
    on the bend load. The defaults give every leaf its species' values."""

    TABLE = "variety"

    ripple_phase: tuple[float, float] = spec_field("ripple phase offset (samples)", _G, 0.0, 64.0, 0.5,
                                                   hard=(0.0, 1e4), kind="pair", default=(0.0, 0.0))
    ripple_amplitude: tuple[float, float] = spec_field("ripple amplitude factor", _G, 0.0, 2.0, 0.01,
                                                       hard=(0.0, 10.0), kind="pair", default=(1.0, 1.0))
    bend_load: tuple[float, float] = spec_field("bend load factor", _G, 0.0, 2.0, 0.01, hard=(0.0, 10.0),
                                                kind="pair", default=(1.0, 1.0))

    def check(self) -> None:
        for name in ("ripple_phase", "ripple_amplitude", "bend_load"):
            lo, hi = getattr(self, name)
            if lo > hi:
                raise ParamError(f"variety.{name}", f"range [{lo}, {hi}] is empty: the first number must not exceed "
                                 "the second")

    @property
    def active(self) -> bool:
        return self != Variety()
