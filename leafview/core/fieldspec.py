"""The metadata of one leaf parameter (:class:`FieldSpec`) and the checks every parameter group
shares: a finite number, inside its hard range. Kept apart from :mod:`leafview.core.params` so
that groups defined in their own modules (:mod:`leafview.core.venation`) can use them without
importing the whole parameter set.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

from leafview.errors import ParamError

__all__ = ["FieldSpec", "spec_field", "number", "integer", "check_range", "check_choice", "check_table", "parse_list"]


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


def integer(value: Any, spec: FieldSpec, path: str) -> int:
    """``value`` as an int inside ``spec``'s hard range, else a :class:`ParamError` naming ``path``."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParamError(path, f"expected an integer, got {type(value).__name__} {value!r}")
    check_range(float(value), spec, path)
    return int(value)


def check_table(value: Any, path: str, specs: Mapping[str, FieldSpec], required: tuple[str, ...], what: str) -> None:
    """``value`` must be a table (``what`` says of which fields) with only the keys of ``specs``
    and every key of ``required``; errors name ``path`` or ``path.key``."""
    if not isinstance(value, Mapping):
        raise ParamError(path, f"expected a table with {what}, got {type(value).__name__}")
    for key in value:
        if key not in specs:
            raise ParamError(f"{path}.{key}", f"unknown key (known: {', '.join(specs)})")
    for key in required:
        if key not in value:
            raise ParamError(f"{path}.{key}", "missing field")


T = TypeVar("T")


def parse_list(value: Any, path: str, kind: type[T], as_table: Callable[[T], dict[str, Any]],
               parse_item: Callable[[Any, str], T], most: int, noun: str) -> tuple[T, ...]:
    """A list of tables (``[[path]]``), each parsed by ``parse_item(table, "path[i]")``: at most
    ``most`` of them (``noun`` names them in the error). A tuple of ``kind`` objects is accepted
    as it is written back (``as_table``), so validated values round-trip."""
    if isinstance(value, tuple) and all(isinstance(item, kind) for item in value):
        value = [as_table(item) for item in value]
    if not isinstance(value, (list, tuple)):
        raise ParamError(path, f"expected a list of {noun} tables, got {type(value).__name__}")
    if len(value) > most:
        raise ParamError(path, f"{len(value)} {noun}s; at most {most} are accepted")
    return tuple(parse_item(item, f"{path}[{i}]") for i, item in enumerate(value))
