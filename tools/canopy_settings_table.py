"""The scene-file tables of docs/canopy.md (``[light]``, ``[wind]``, ``variety = {...}``,
``[[edits]]``) written from the code: each settings class's field specs (label, kind, default,
hard range, slider range) and :mod:`leafview.scene.scene_edits`' limits.

    python tools/canopy_settings_table.py            # print the tables
    python tools/canopy_settings_table.py --write    # replace them in docs/canopy.md
    python tools/canopy_settings_table.py --check    # exit 1 when docs/canopy.md is out of date

In docs/canopy.md each table sits between ``<!-- settings:NAME -->`` and ``<!-- /settings -->``
(NAME: light, wind, variety, edits).
"""

from __future__ import annotations

import re
import sys
from collections.abc import Callable, Sequence
from dataclasses import MISSING, fields
from pathlib import Path
from typing import Any

from leafview.core.settings import field_specs
from leafview.deform.wind import WindSettings
from leafview.scene import scene_edits
from leafview.scene.lighting import LightSettings
from leafview.scene.variety import Variety

DOC = Path("docs/canopy.md")
CLASSES: dict[str, Any] = {"light": LightSettings, "wind": WindSettings, "variety": Variety}


def _number(x: Any) -> str:
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, float):
        return f"{x:g}" if abs(x) < 1e5 or x == 0 else f"{x:.0e}".replace("e+0", "e").replace("e+", "e")
    if isinstance(x, int) and x > 2**20:
        return "2³¹ − 1" if x == 2**31 - 1 else str(x)
    return str(x)


def _value(x: Any) -> str:
    if isinstance(x, tuple):
        return "[" + ", ".join(_number(v) for v in x) + "]"
    if isinstance(x, str):
        return f'"{x}"'
    return _number(x)


# rules of a class's own check() beyond each field's range (LightSettings.check, Variety.check)
RULES = {("light", "sun"): "azimuth -180 … 360, elevation 0 … 90",
         **{("variety", name): "each {}, first ≤ second" for name in ("ripple_phase", "ripple_amplitude", "bend_load")}}


def _range(table: str, name: str, spec: Any) -> str:
    if spec.kind == "bool":
        return "true / false"
    if spec.kind == "choice":
        return " / ".join(f'"{c}"' for c in spec.choices)
    lo, hi = spec.hard_range
    if lo is not None and hi is not None:
        text = f"{_number(lo)} … {_number(hi)}"
    else:
        text = f"≥ {_number(lo)}" if lo is not None else f"≤ {_number(hi)}"
    if spec.positive and (lo is None or lo <= 0):
        text += ", > 0"
    rule = RULES.get((table, name))
    if rule is not None:
        return rule.format(text)
    return ("each " + text) if spec.kind == "pair" else text


def settings_table(cls: Any) -> str:
    """A Markdown table of a settings class: key, meaning, default, accepted range, slider range."""
    default = cls()
    rows = ["| key | meaning | default | accepted | slider |", "|---|---|---|---|---|"]
    for name, spec in field_specs(cls).items():
        soft = "" if spec.kind in ("bool", "choice") else f"{_number(spec.soft_range[0])} … {_number(spec.soft_range[1])}"
        rows.append(f"| `{name}` | {spec.label} | `{_value(getattr(default, name))}` | {_range(cls.TABLE, name, spec)} | {soft} |")
    return "\n".join(rows)


def edits_table() -> str:
    """A Markdown table of the keys of one ``[[edits]]`` entry (:class:`~leafview.scene.scene_edits.SceneEdit`)."""
    defaults = {f.name: f.default for f in fields(scene_edits.SceneEdit)}
    limits = scene_edits._LIMITS
    values = "; ".join(f"{op}: {_number(lo)} … {_number(hi)}" for op, (lo, hi) in limits.items())
    meaning = {
        "op": ("the edit", " / ".join(f'"{o}"' for o in scene_edits.EDIT_OPS)),
        "value": ("width: a factor; the others: a displacement in leaf lengths", values),
        "target": ("which leaves", " / ".join(f'"{t}"' for t in scene_edits.EDIT_TARGETS)),
        "species": ("the species' index, with target = \"species\"", "0 … species − 1"),
        "leaves": ("leaf indices, with target = \"leaves\"", "0 … leaves − 1, at least one"),
        "row": ("silhouette row of a silhouette edit", f"0 … {scene_edits.SIL_ROWS - 1}"),
        "v": ("the row's shift along the midrib (silhouette)", f"{-scene_edits._V_LIMIT:g} … {scene_edits._V_LIMIT:g}"),
        "curve": ("what a curvature edit lifts", " / ".join(f'"{c}"' for c in scene_edits.CURVES)),
    }
    rows = ["| key | meaning | default | accepted |", "|---|---|---|---|"]
    for name in scene_edits._KEYS:
        d = defaults[name]
        text = "required" if d is MISSING else f"`{_value(d) if d != () else '[]'}`"
        rows.append(f"| `{name}` | {meaning[name][0]} | {text} | {meaning[name][1]} |")
    return "\n".join(rows)


def tables() -> dict[str, str]:
    out = {name: settings_table(cls) for name, cls in CLASSES.items()}
    out["edits"] = edits_table()
    return out


def _filler(table: str) -> Callable[[re.Match[str]], str]:
    def fill(m: re.Match[str]) -> str:
        return m.group(1) + table + "\n" + m.group(2)
    return fill


def _replaced(text: str, made: dict[str, str]) -> str:
    for name, table in made.items():
        pattern = re.compile(rf"(<!-- settings:{name} -->\n)(?:(?:(?!<!-- ).)*?\n)?(<!-- /settings -->)", re.S)
        if not pattern.search(text):
            raise SystemExit(f"{DOC}: no <!-- settings:{name} --> ... <!-- /settings --> block")
        text = pattern.sub(_filler(table), text)
    return text


def main(argv: Sequence[str]) -> int:
    made = tables()
    if not argv:
        for name, table in made.items():
            print(f"## {name}\n\n{table}\n")
        return 0
    text = DOC.read_text(encoding="utf-8")
    new = _replaced(text, made)
    if argv[0] == "--check":
        if new != text:
            print(f"{DOC}: the settings tables differ from the code (run {Path(__file__).name} --write)")
            return 1
        return 0
    if argv[0] == "--write":
        DOC.write_text(new, encoding="utf-8")
        print(f"wrote {DOC}")
        return 0
    print(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
