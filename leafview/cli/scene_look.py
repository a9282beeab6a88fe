"""The light options of ``leafview scene``: ``--shadows on|off``, ``--sun AZ,EL``, ``--sky on|off``,
``--ground on|off``, ``--exposure EV``, ``--ssao on|off``, ``--tone filmic|linear``,
``--shadow-filter soft|fast``.

Each option overrides the scene file's ``[light]`` table (:class:`~leafview.scene.lighting.LightSettings`),
whose defaults apply to the rest. Values are checked while the command line is parsed, by the
settings' own rules (one source for the ranges and the messages, which name ``light.sun[1]`` and
so on): argparse reports a bad one and exits 2 before anything is built or rendered.

Examples::

    leafview scene --layout plant --leaves 3000 -o tree.png --sun 220,25 --exposure 0.5
    leafview scene tree.toml -o flat.png --shadows off --sky off --ground off --tone linear
    leafview scene --leaves 100000 --camera ground --shadow-filter fast -o field.png
"""

from __future__ import annotations

import argparse
from typing import Any

from leafview.cli.args import checked_setting, numbers, setting_option
from leafview.scene.lighting import SHADOW_FILTERS, TONE_MAPS, LightSettings

__all__ = ["add_light_arguments", "light_from_args", "sun_angles", "exposure", "LIGHT_SWITCHES", "ON_OFF"]

ON_OFF = ("on", "off")
LIGHT_SWITCHES = ("shadows", "sky", "ground", "ssao")   # on|off options, named as LightSettings' fields


def sun_angles(text: str) -> tuple[float, float]:
    """``--sun AZ,EL``: azimuth (degrees counter-clockwise from +x) and elevation (degrees above the
    horizon), checked as ``light.sun``."""
    sun: tuple[float, float] = checked_setting(
        LightSettings, "sun", numbers(text, 2, "AZ,EL (two numbers in degrees, e.g. 135,50)"))
    return sun


exposure = setting_option(LightSettings, "exposure", "a number of stops")
"""``--exposure EV``: stops (the image is scaled by 2^EV), checked as ``light.exposure``."""


def add_light_arguments(p: argparse.ArgumentParser) -> None:
    """The light options (an argument group); each defaults to None: the scene file's or the
    default light."""
    g = p.add_argument_group("light", "the canopy look (each overrides the scene file's [light] table)")
    default = LightSettings()
    g.add_argument("--shadows", choices=ON_OFF, help=f"sun shadows (default {_word(default.shadows)})")
    g.add_argument("--sun", type=sun_angles, metavar="AZ,EL",
                   help="sun azimuth (degrees counter-clockwise from +x) and elevation (0-90 degrees above the "
                        f"horizon) (default {default.sun[0]:g},{default.sun[1]:g})")
    g.add_argument("--sky", choices=ON_OFF, help=f"analytic sky behind the scene (default {_word(default.sky)})")
    g.add_argument("--ground", choices=ON_OFF, help=f"ground plane under the scene (default {_word(default.ground)})")
    g.add_argument("--exposure", type=exposure, metavar="EV",
                   help=f"exposure in stops, the image scaled by 2^EV before tone mapping (default {default.exposure:g})")
    g.add_argument("--ssao", choices=ON_OFF, help=f"screen-space ambient occlusion (default {_word(default.ssao)})")
    g.add_argument("--tone", choices=TONE_MAPS, help=f"tone mapping (default {default.tone})")
    g.add_argument("--shadow-filter", dest="shadow_filter", choices=SHADOW_FILTERS,
                   help="filter of the shadow maps: soft (3 × 3 percentage-closer) or fast (one bilinear tap, "
                        f"about half the lookup cost on a CPU rasteriser) (default {default.shadow_filter})")


def _word(flag: bool) -> str:
    return ON_OFF[0] if flag else ON_OFF[1]


def light_from_args(args: argparse.Namespace, base: LightSettings | None = None) -> LightSettings:
    """``base`` (the scene file's light; None: the defaults) with the options given on the command
    line; raises :class:`ParamError` naming the field when a combination is refused."""
    light = base if base is not None else LightSettings()
    changes: dict[str, Any] = {}
    for name in LIGHT_SWITCHES:
        value = getattr(args, name, None)
        if value is not None:
            changes[name] = value == ON_OFF[0]
    for name in ("sun", "exposure", "tone", "shadow_filter"):
        value = getattr(args, name, None)
        if value is not None:
            changes[name] = value
    return light.replace(**changes) if changes else light
