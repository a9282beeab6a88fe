"""The metadata of one leaf parameter (:class:`FieldSpec`) and the checks every parameter group
shares: a finite number, inside its hard range. Kept apart from :mod:`leafview.core.params` so
that groups defined in their own modules (:mod:`leafview.core.venation`) can use them without
importing the whole parameter set.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from leafview.errors import ParamError

__all__ = ["FieldSpec", "spec_field", "number", "check_range", "check_choice"]


@dataclass(frozen=True)
class FieldSpec:
    """UI and validation metadata of one parameter (used by the viewer panel and the checks).
    ``choices`` lists the accepted strings of a ``choice`` field (the panel shows a combo box,
    the schema an enum)."""

    label: str
    group: str
    soft_range: tuple[float, float]
    step: float
    hard_range: tuple[float | None, float | None] = (None, None)
    kind: str = "float"  # float | int | bool | color | vec3 | pair | rows | per_row | choice | edits
    positive: bool = False  # strictly greater than zero
    choices: tuple[str, ...] = ()


def spec_field(label: str, group: str, lo: float, hi: float, step: float, *,
               hard: tuple[float | None, float | None] = (None, None),
               kind: str = "float", positive: bool = False, choices: tuple[str, ...] = (),
               default: Any = None, default_factory: Any = None) -> Any:
    """A dataclass field carrying its :class:`FieldSpec` in ``metadata["spec"]``."""
    spec = FieldSpec(label, group, (lo, hi), step, hard, kind, positive, choices)
    if default_factory is not None:
        return field(default_factory=default_factory, metadata={"spec": spec})
    return field(default=default, metadata={"spec": spec})


def number(value: Any, path: str) -> float:
    """``value`` as a finite float, else a :class:`ParamError` naming ``path``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParamError(path, f"expected a number, got {type(value).__name__} {value!r}")
    x = float(value)
    if math.isnan(x):
        raise ParamError(path, "is NaN; every parameter must be a finite number")
    if math.isinf(x):
        raise ParamError(path, f"is {'+' if x > 0 else '-'}Inf; every parameter must be a finite number")
    return x


def check_range(x: float, spec: FieldSpec, path: str) -> None:
    """Raise :class:`ParamError` unless ``x`` lies in ``spec``'s hard range (and is > 0 when
    ``spec.positive``)."""
    if spec.positive and not x > 0.0:
        raise ParamError(path, f"{x!r} must be greater than 0")
    lo, hi = spec.hard_range
    if lo is not None and x < lo:
        raise ParamError(path, f"{x!r} is below the minimum {lo}")
    if hi is not None and x > hi:
        raise ParamError(path, f"{x!r} is above the maximum {hi}")


def check_choice(value: Any, spec: FieldSpec, path: str) -> str:
    """``value`` when it is one of ``spec.choices``, else a :class:`ParamError` naming ``path``."""
    if not isinstance(value, str):
        raise ParamError(path, f"expected one of {', '.join(spec.choices)}, got {type(value).__name__} {value!r}")
    if value not in spec.choices:
        raise ParamError(path, f"{value!r} is not one of {', '.join(spec.choices)}")
    return value
