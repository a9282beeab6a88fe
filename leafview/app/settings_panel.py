"""Widgets for a settings table (:class:`~leafview.core.settings.SettingsTable`): one widget per
field, chosen by its :class:`~leafview.core.fieldspec.FieldSpec` (checkbox, slider, combo, a pair of
sliders), so the scene viewer's light and wind panels follow the settings' declarations.
"""

from __future__ import annotations

from typing import Any, TypeVar

from imgui_bundle import imgui

from leafview.core.fieldspec import FieldSpec
from leafview.core.settings import SettingsTable, field_specs
from leafview.errors import ParamError

__all__ = ["settings_widgets", "widget_value"]

S = TypeVar("S", bound=SettingsTable)


def _decimals(step: float) -> int:
    text = f"{step:g}"
    return len(text.split(".")[1]) if "." in text else 0


def widget_value(label: str, value: Any, spec: FieldSpec, ranges: Any = None) -> tuple[bool, Any]:
    """Draw one widget for ``value`` (``label`` unique in the window); (changed, new value).
    ``ranges``: per-component (lo, hi) of a pair (else the spec's soft range for both)."""
    lo, hi = (float(x) for x in spec.soft_range)
    fmt = f"%.{_decimals(spec.step)}f"
    if spec.kind == "bool":
        return imgui.checkbox(label, bool(value))
    if spec.kind == "choice":
        current = spec.choices.index(value) if value in spec.choices else 0
        changed, index = imgui.combo(label, current, list(spec.choices))
        return changed, spec.choices[index]
    if spec.kind == "int":
        return imgui.slider_int(label, int(value), int(lo), int(hi))
    if spec.kind == "pair":
        parts = ranges or ((lo, hi), (lo, hi))
        new = list(value)
        changed = False
        for i, (a, b) in enumerate(parts):
            c, new[i] = imgui.slider_float(f"{label.split('##')[0]} [{i}]##{label}{i}", float(value[i]), float(a),
                                           float(b), fmt)
            changed = changed or c
        return changed, tuple(float(x) for x in new)
    return imgui.slider_float(label, float(value), lo, hi, fmt)


def settings_widgets(settings: S, suffix: str, pair_ranges: dict[str, Any] | None = None) -> tuple[S, str | None]:
    """Draw every field of ``settings``; returns (the settings, changed or not, and the message of
    a value the settings refused, else None). Widgets are labelled ``label##suffix-name``."""
    values: dict[str, Any] = {}
    for name, spec in field_specs(type(settings)).items():
        changed, new = widget_value(f"{spec.label}##{suffix}-{name}", getattr(settings, name), spec,
                                    (pair_ranges or {}).get(name))
        if changed:
            values[name] = new
    if not values:
        return settings, None
    try:
        return settings.replace(**values), None
    except ParamError as exc:   # a slider outside a rule between fields: keep the old settings
        return settings, str(exc)
