"""The venation parameters of a leaf (``LeafParams.venation``, the ``[venation]`` table).

A leaf's veins form a hierarchical tree (Hong 2005, ch. 6.1): the midrib (order 1), the
secondaries that leave it (order 2) and a reticulate network of tertiaries between them (order
3 and finer). :class:`Venation` holds the numbers that describe such a tree; the tree itself is
built by :mod:`leafview.botany.venation`. Three patterns:

* ``pinnate``: ``secondaries`` veins per side leave the midrib at ``angle`` degrees, curving
  towards the apex by ``curvature``, spaced along the midrib with ``irregularity`` jitter and
  shifted between the two sides by ``alternate`` (0 opposite, 1 alternate); they run to the
  margin (``loop = 0``, craspedodromous) or, at that fraction of the way, bend to join the next
  one (brochidodromous).
* ``palmate``: ``primaries`` lateral primary veins per side fan out from the base beside the
  midrib, each with its own secondaries.
* ``parallel``: ``secondaries`` veins per side run from base to apex beside the midrib
  (grasses).

``tertiary`` is the density of the tertiary network (cross-veins per leaf length along a
secondary; 0: none). ``midrib_width`` is the midrib's width in leaf lengths; each order is
``width_ratio`` times as wide as the one above it. ``contrast`` and ``relief`` say how strongly
the veins show in colour and as a bump in the shading.

``edits`` reshape single veins (Hong 2005, ch. 7.1): a :class:`VeinEdit` turns vein ``vein`` of
side ``side`` about its hinge (the point where it leaves its parent) by ``angle`` degrees
(positive towards the apex) and bows it sideways by ``bulge`` leaf lengths at its middle
(positive towards the apex); see :func:`leafview.botany.venation.edited_uv`.

A leaf whose venation is the default (``Venation()``, disabled) writes no ``[venation]`` table,
so files from before venation existed read and write back unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from leafview.core.fieldspec import FieldSpec, check_range, check_table, integer, number, parse_list, spec_field
from leafview.errors import ParamError

__all__ = ["PATTERNS", "MAX_EDITS", "MAX_SECONDARIES", "Venation", "VeinEdit", "edit_specs", "parse_edits",
           "venation_dict", "edit_dict"]

PATTERNS = ("pinnate", "palmate", "parallel")
MAX_EDITS = 64            # vein edits per leaf
MAX_SECONDARIES = 64      # secondaries (parallel veins) per side
_G = "venation"


@dataclass(frozen=True)
class VeinEdit:
    """One vein reshaped (Hong 2005, ch. 7.1): vein ``vein`` (counted from the base among the
    veins that leave the midrib on ``side``: -1 the u < 0 half, +1 the u > 0 half) turned about
    its hinge by ``angle`` degrees and bowed by ``bulge`` leaf lengths (both positive towards
    the apex)."""

    vein: int = spec_field("vein (from the base)", "venation.edits", 0, 30, 1, hard=(0, 4 * MAX_SECONDARIES),
                           kind="int", default=0)
    side: int = spec_field("side (-1 u < 0, +1 u > 0)", "venation.edits", -1, 1, 2, hard=(-1, 1), kind="int",
                           default=1)
    angle: float = spec_field("hinge angle (degrees, + towards the apex)", "venation.edits", -30.0, 30.0, 0.5,
                              hard=(-90.0, 90.0), default=0.0)
    bulge: float = spec_field("bulge (leaf lengths, + towards the apex)", "venation.edits", -0.1, 0.1, 0.001,
                              hard=(-0.5, 0.5), default=0.0)


def _no_edits() -> tuple[VeinEdit, ...]:
    return ()


@dataclass(frozen=True)
class Venation:
    """The vein tree of the leaf (Hong 2005, ch. 6.1): pattern, secondaries, tertiary network,
    widths, how strongly the veins show, and vein edits (Hong 2005, ch. 7.1)."""

    enabled: bool = spec_field("veins on", _G, 0, 1, 1, kind="bool", default=False)
    pattern: str = spec_field("pattern", _G, 0, 2, 1, kind="choice", choices=PATTERNS, default="pinnate")
    seed: int = spec_field("seed", _G, 0, 9999, 1, hard=(0, 2**31 - 1), kind="int", default=0)
    secondaries: int = spec_field("secondaries per side", _G, 2, 30, 1, hard=(1, MAX_SECONDARIES), kind="int",
                                  default=8)
    angle: float = spec_field("secondary angle (degrees from the midrib)", _G, 10.0, 85.0, 0.5, hard=(2.0, 88.0),
                              default=50.0)
    curvature: float = spec_field("curvature towards the apex", _G, 0.0, 1.0, 0.01, hard=(0.0, 1.0), default=0.4)
    irregularity: float = spec_field("spacing irregularity", _G, 0.0, 1.0, 0.01, hard=(0.0, 1.0), default=0.2)
    alternate: float = spec_field("alternate (0 opposite, 1 alternate)", _G, 0.0, 1.0, 0.01, hard=(0.0, 1.0),
                                  default=0.5)
    loop: float = spec_field("loop (0 to the margin, else where it loops)", _G, 0.0, 0.95, 0.01,
                             hard=(0.0, 0.95), default=0.0)
    primaries: int = spec_field("lateral primaries per side (palmate)", _G, 1, 4, 1, hard=(1, 6), kind="int",
                                default=2)
    tertiary: float = spec_field("tertiary density (per leaf length, 0 off)", _G, 0.0, 60.0, 0.5,
                                 hard=(0.0, 200.0), default=20.0)
    midrib_width: float = spec_field("midrib width (leaf lengths)", _G, 0.002, 0.04, 0.0005, hard=(1e-4, 0.1),
                                     positive=True, default=0.012)
    width_ratio: float = spec_field("width ratio per order", _G, 0.2, 0.9, 0.01, hard=(0.05, 1.0), default=0.5)
    contrast: float = spec_field("colour contrast", _G, 0.0, 1.0, 0.01, hard=(0.0, 1.0), default=0.5)
    relief: float = spec_field("relief (bump strength)", _G, 0.0, 1.0, 0.01, hard=(0.0, 4.0), default=0.5)
    edits: tuple[VeinEdit, ...] = spec_field("vein edits", _G, 0, MAX_EDITS, 1, kind="edits",
                                             default_factory=_no_edits)


def edit_specs() -> dict[str, FieldSpec]:
    """The :class:`FieldSpec` of each :class:`VeinEdit` field by name."""
    return {f.name: f.metadata["spec"] for f in fields(VeinEdit)}


def _edit(value: Any, path: str) -> VeinEdit:
    specs = edit_specs()
    check_table(value, path, specs, ("vein", "side"), "vein, side, angle and bulge")
    out: dict[str, Any] = {}
    for name, spec in specs.items():
        if name not in value:
            continue
        where = f"{path}.{name}"
        if spec.kind == "int":
            out[name] = integer(value[name], spec, where)
            if name == "side" and out[name] == 0:
                raise ParamError(where, "0 is not a side: -1 (the u < 0 half) or +1 (the u > 0 half)")
        else:
            out[name] = number(value[name], where)
            check_range(out[name], spec, where)
    return VeinEdit(**out)


def parse_edits(value: Any, path: str = "venation.edits") -> tuple[VeinEdit, ...]:
    """Validate the ``edits`` list (``[[venation.edits]]`` tables); errors name
    ``venation.edits[i].field``. Each (vein, side) may be edited once."""
    edits = parse_list(value, path, VeinEdit, edit_dict, _edit, MAX_EDITS, "edit")
    seen: dict[tuple[int, int], int] = {}
    for i, e in enumerate(edits):
        key = (e.vein, e.side)
        if key in seen:
            raise ParamError(f"{path}[{i}]", f"vein {e.vein} of side {e.side:+d} is already edited by "
                                             f"{path}[{seen[key]}]: merge the two edits")
        seen[key] = i
    return edits


def edit_dict(edit: VeinEdit) -> dict[str, Any]:
    """One edit as a plain table."""
    return {f.name: getattr(edit, f.name) for f in fields(edit)}


def venation_dict(venation: Venation, *, keep_empty_edits: bool = False) -> dict[str, Any]:
    """The ``[venation]`` table of ``venation`` (plain values; ``edits`` as a list of tables,
    left out when empty unless ``keep_empty_edits``)."""
    out: dict[str, Any] = {}
    for f in fields(venation):
        value = getattr(venation, f.name)
        if f.name == "edits":
            if value or keep_empty_edits:
                out["edits"] = [edit_dict(e) for e in value]
        else:
            out[f.name] = value
    return out
