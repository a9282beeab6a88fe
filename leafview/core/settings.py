"""Settings tables: frozen dataclasses whose fields carry a :class:`~leafview.core.fieldspec.FieldSpec`
(made with :func:`~leafview.core.fieldspec.spec_field`), checked on construction, read from and
written to a TOML/JSON table.

The light, wind and per-leaf variety settings of a scene (``[light]``, ``[wind]``,
``[[species]] variety``) are such tables; so the checks, the error paths (``light.sun``), the file
form and the viewer's sliders come from one declaration per setting.

Field kinds understood here: ``float``, ``int``, ``bool``, ``choice`` and ``pair`` (two numbers, each
inside the hard range; a ``pair`` with ``ordered`` in its group name is not checked for order here:
a class checks what its pairs mean in its own ``check``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields, replace
from typing import Any, TypeVar

from leafview.core.fieldspec import FieldSpec
from leafview.core.params import parse_field
from leafview.errors import ParamError

__all__ = ["SettingsTable", "field_specs"]

S = TypeVar("S", bound="SettingsTable")


def field_specs(cls: Any) -> dict[str, FieldSpec]:
    """``{name: FieldSpec}`` of a settings class's fields, in declaration order."""
    return {f.name: f.metadata["spec"] for f in fields(cls) if "spec" in f.metadata}


class SettingsTable:
    """Mixin of a frozen dataclass of spec fields. ``TABLE`` is the table's name in a file (the
    prefix of every error path). Subclasses may override :meth:`check` for rules between fields
    (called after every field passed its own check)."""

    TABLE = ""

    def __post_init__(self) -> None:
        for name, spec in field_specs(type(self)).items():
            object.__setattr__(self, name, parse_field(getattr(self, name), spec, f"{self.TABLE}.{name}"))
        self.check()

    def check(self) -> None:
        """Rules between fields (raise ParamError naming the field)."""

    @classmethod
    def from_dict(cls: type[S], data: Any, path: str | None = None) -> S:
        """The settings of a table (missing keys take their defaults); unknown keys and bad values
        raise :class:`ParamError` naming ``path.key`` (``path`` defaults to :attr:`TABLE`)."""
        where = cls.TABLE if path is None else path
        if not isinstance(data, Mapping):
            raise ParamError(where, f"expected a table, got {type(data).__name__}")
        specs = field_specs(cls)
        for key in data:
            if key not in specs:
                raise ParamError(f"{where}.{key}", f"unknown setting (known: {', '.join(specs)})")
        values = {k: parse_field(v, specs[k], f"{where}.{k}") for k, v in data.items()}
        try:
            return cls(**values)
        except ParamError as exc:
            if where != cls.TABLE and exc.path.startswith(cls.TABLE):
                raise ParamError(where + exc.path[len(cls.TABLE):], exc.message) from None
            raise

    def to_dict(self, *, changed_only: bool = True) -> dict[str, Any]:
        """The file form: every setting that differs from its default (all with ``changed_only``
        False); pairs as lists."""
        default = type(self)()
        out: dict[str, Any] = {}
        for name in field_specs(type(self)):
            v = getattr(self, name)
            if changed_only and v == getattr(default, name):
                continue
            out[name] = list(v) if isinstance(v, tuple) else v
        return out

    def replace(self: S, **changes: Any) -> S:
        return replace(self, **changes)  # type: ignore[type-var]
