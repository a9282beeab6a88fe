"""Reading and writing leaf presets as TOML (``schema = 1``) or JSON with the same structure.

Errors are :class:`~leafview.model.params.ParamError` naming the file and either ``line:col``
(syntax) or the dotted field path (content).
"""

from __future__ import annotations

import json
import os
import tomllib
from pathlib import Path
from typing import Any

import tomli_w

from ..atomic import atomic_output
from .params import LeafParams, ParamError, parse_params

__all__ = ["load_params", "save_params", "dumps_toml", "read_document"]

_FORMATS = {".toml": "toml", ".json": "json"}


def _format_of(path: Path) -> str:
    fmt = _FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise ParamError("", f"unknown preset format {path.suffix!r} (use .toml or .json)", str(path))
    return fmt


def read_document(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Parse a preset file into a dict, reporting syntax errors with ``file:line:col``."""
    p = Path(path)
    fmt = _format_of(p)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ParamError("", "no such file", str(p)) from None
    except IsADirectoryError:
        raise ParamError("", "is a directory, expected a preset file", str(p)) from None
    except UnicodeDecodeError as exc:
        raise ParamError("", f"not UTF-8 text ({exc.reason} at byte {exc.start})", str(p)) from None
    except OSError as exc:
        raise ParamError("", f"cannot read: {exc.strerror}", str(p)) from None
    if not text.strip():
        raise ParamError("", "empty file: expected 'schema' and a [shape] table", str(p))
    if fmt == "toml":
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            line, col = _toml_position(str(exc))
            msg = str(exc).split(" (at ")[0]
            raise ParamError("", f"TOML syntax error: {msg}", f"{p}:{line}:{col}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ParamError("", f"JSON syntax error: {exc.msg}", f"{p}:{exc.lineno}:{exc.colno}") from None
    return data


def _toml_position(message: str) -> tuple[int, int]:
    # tomllib reports "... (at line L, column C)" or "(at end of document)"
    import re

    m = re.search(r"line (\d+), column (\d+)", message)
    return (int(m.group(1)), int(m.group(2))) if m else (0, 0)


def load_params(path: str | os.PathLike[str]) -> LeafParams:
    """Load and validate a preset; the file name becomes ``name`` when the file has none."""
    p = Path(path)
    data = read_document(p)
    try:
        params = parse_params(data)
    except ParamError as exc:
        raise exc.with_source(str(p)) from None
    if not params.name:
        params = params.replace(name=p.stem)
    return params


def dumps_toml(params: LeafParams) -> str:
    return tomli_w.dumps(params.to_dict())


def save_params(params: LeafParams, path: str | os.PathLike[str]) -> None:
    """Write ``params`` to ``path`` (.toml or .json) atomically."""
    p = Path(path)
    fmt = _format_of(p)
    text = dumps_toml(params) if fmt == "toml" else json.dumps(params.to_dict(), indent=2) + "\n"
    with atomic_output(p) as tmp:
        tmp.write_text(text, encoding="utf-8")
