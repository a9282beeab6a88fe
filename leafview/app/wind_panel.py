"""The viewers' wind controls: a play/pause checkbox and sliders for the wind's speed, direction,
gustiness and flutter (:class:`~leafview.deform.wind.WindSettings`, the turbulent load of Geng, Hu &
Zhang 2014, eq. 5), and the clock that plays it live.

While playing, the wind's ``time`` advances by each frame's wall-clock interval
(:func:`advance_wind`): only the Wind uniform block changes from one frame to the next
(:class:`~leafview.gpu.wind.WindUniforms`), nothing is rebuilt. A wind of speed 0 is still: the
leaves are drawn with the plain program, bit for bit the frame without wind.
"""

from __future__ import annotations

import math

from imgui_bundle import imgui

from leafview.app.settings_panel import widget_value
from leafview.core.settings import field_specs
from leafview.deform.wind import WindSettings
from leafview.errors import ParamError

__all__ = ["advance_wind", "wind_widgets", "WIND_FIELDS", "TIME_WRAP"]

WIND_FIELDS = ("speed", "direction", "gust", "flutter")   # the sliders, in this order
TIME_WRAP = 1e6   # seconds: the wind's time wraps here (WindSettings.time's hard range)


def advance_wind(wind: WindSettings, playing: bool, dt: float) -> WindSettings:
    """``wind`` ``dt`` seconds later when ``playing`` and blowing, else ``wind`` itself."""
    if not playing or not wind.active or dt <= 0.0:
        return wind
    return wind.replace(time=math.fmod(wind.time + float(dt), TIME_WRAP))


def wind_widgets(wind: WindSettings, playing: bool, suffix: str) -> tuple[WindSettings, bool, str | None]:
    """Draw the wind's controls (labels end ``##suffix-name``); returns (wind, playing, the message
    of a value the settings refused, else None)."""
    _, playing = imgui.checkbox(f"play wind##{suffix}-play", playing)
    imgui.same_line()
    imgui.text(f"t = {wind.time:.2f} s")
    specs = field_specs(WindSettings)
    values = {}
    for name in WIND_FIELDS:
        changed, new = widget_value(f"{specs[name].label}##{suffix}-{name}", getattr(wind, name), specs[name])
        if changed:
            values[name] = new
    if not values:
        return wind, bool(playing), None
    try:
        return wind.replace(**values), bool(playing), None
    except ParamError as exc:
        return wind, bool(playing), str(exc)
