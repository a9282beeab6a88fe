"""Reading and writing leaf presets as TOML (``schema = 1``) or JSON with the same structure,
and the compact JSON form (:mod:`leafview.core.compact`): ``*.leaf.json`` files are written
compact, and any JSON file whose top level has the ``leafview`` key is read as compact.

Errors are :class:`~leafview.core.params.ParamError` naming the file and either ``line:col``
(syntax) or the dotted field path (content).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import tomli_w

from leafview.atomic import write_text
from leafview.core import compact
from leafview.core.params import LeafParams, ParamError, parse_params, register_file_io
from leafview.core.texture import with_folder
from leafview.inputs import parse_json, parse_toml, read_text

__all__ = ["register_document_reader", "load_params", "save_params", "dumps_toml", "read_document", "load_leaves", "save_leaves",
           "leaves_from_document", "is_compact_path"]

_FORMATS = {".toml": "toml", ".json": "json"}


def _format_of(path: Path) -> str:
    fmt = _FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise ParamError("", f"unknown preset format {path.suffix!r} (use .toml or .json)", str(path))
    return fmt


def read_document(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Parse a preset file into a dict through :mod:`leafview.inputs` (regular files only, size,
    nesting and number limits), reporting syntax errors with ``file:line:col``."""
    p = Path(path)
    fmt = _format_of(p)
    text = read_text(p)
    if not text.strip():
        raise ParamError("", "empty file: expected 'schema' and a [shape] table", str(p))
    data: dict[str, Any] = parse_toml(text, str(p)) if fmt == "toml" else parse_json(text, str(p))
    return data


def _stem(p: Path) -> str:
    name = p.name
    for suffix in (".leaf.json", ".leaves.json"):
        if name.lower().endswith(suffix):
            return name[: -len(suffix)]
    return p.stem


def is_compact_path(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` names a compact leaf file (``*.leaf.json``), which :func:`save_params`
    writes in the compact form."""
    return Path(path).name.lower().endswith(".leaf.json")


def load_params(path: str | os.PathLike[str]) -> LeafParams:
    """Load and validate a preset (full TOML/JSON or compact JSON); the file name becomes
    ``name`` when the file has none."""
    p = Path(path)
    data = read_document(p)
    if _is_leaf_set(data):
        n = len(data["leaves"]) if isinstance(data["leaves"], list) else "?"
        raise ParamError("leaves", f"a leaf set of {n} leaves, not one leaf: read it with "
                                   "leafview.core.io.load_leaves (or leafview render)", str(p))
    return leaves_from_document(data, p)[0]


def _is_leaf_set(data: Any) -> bool:
    return compact.is_compact(data) and "leaves" in data


DocumentReader = Callable[[Any], LeafParams | None]
_READERS: list[DocumentReader] = []


def register_document_reader(reader: DocumentReader) -> None:
    """Let ``reader`` turn documents of a kind this module does not know into a leaf (it returns
    None for the others; its ParamErrors name the field). :mod:`leafview.botany.lobe_outline`
    registers the compound lobed-leaf files (``lobed = 1``) when it is imported, which every
    command line tool does."""
    if reader not in _READERS:
        _READERS.append(reader)


def leaves_from_document(data: Any, path: str | os.PathLike[str]) -> list[LeafParams]:
    """The validated leaves of a parsed leaf file (full, compact, leaf set, or a kind a registered
    reader knows) read from ``path`` (named in errors; its stem names unnamed leaves: ``<stem>``,
    or ``<stem>-<i>`` in a set)."""
    p = Path(path)
    try:
        for reader in _READERS:
            leaf = reader(data)
            if leaf is not None:
                return [_in_folder(leaf if leaf.name else leaf.replace(name=_stem(p)), p.parent)]
        if isinstance(data, Mapping) and "lobed" in data:
            raise ParamError("lobed", "a compound lobed-leaf file (Garg & Leow's lobes, eqs 7-9): read it with "
                                      "leafview.botany.lobe_outline (imported by the command line tools), "
                                      "e.g. lobed_outline_params(load_lobed_leaf(path))")
        if _is_leaf_set(data):
            leaves = compact.parse_leaves(data)
            named = [leaf if leaf.name else leaf.replace(name=f"{_stem(p)}-{i}") for i, leaf in enumerate(leaves)]
        else:
            params = compact.parse_compact(data) if compact.is_compact(data) else parse_params(data)
            named = [params if params.name else params.replace(name=_stem(p))]
        return [_in_folder(leaf, p.parent) for leaf in named]
    except ParamError as exc:
        raise exc.with_source(str(p)) from None


def _in_folder(leaf: LeafParams, folder: Path) -> LeafParams:
    """``leaf`` with its texture paths resolving against ``folder`` (the leaf file's), checked not
    to leave it once symbolic links are followed."""
    if leaf.texture is None:
        return leaf
    texture = with_folder(leaf.texture, folder)
    assert texture is not None
    texture.paths()
    return leaf.replace(texture=texture)


def load_leaves(path: str | os.PathLike[str]) -> list[LeafParams]:
    """The leaves of a file: every leaf of a leaf set (``{"leafview":1,"leaves":[...]}``), or the
    one leaf of any other leaf file."""
    return leaves_from_document(read_document(path), path)


def save_leaves(leaves: list[LeafParams], path: str | os.PathLike[str], *, digits: int | None = None) -> None:
    """Write a compact leaf set (``.json``, conventionally ``*.leaves.json``) atomically."""
    p = Path(path)
    if p.suffix.lower() != ".json":
        raise ParamError("", f"a leaf set is JSON: expected a .leaves.json file name, got {p.suffix!r}", str(p))
    if not leaves:
        raise ParamError("leaves", "nothing to write: the leaf set is empty", str(p))
    text = compact.dumps_leaves(leaves, digits=digits) + "\n"
    write_text(p, text)   # checked target, atomic rename, every byte on the disk


def dumps_toml(params: LeafParams) -> str:
    return tomli_w.dumps(params.to_dict())


def save_params(params: LeafParams, path: str | os.PathLike[str], *, digits: int | None = None) -> None:
    """Write ``params`` to ``path`` atomically: ``.toml``, ``.json`` (the full form) or
    ``.leaf.json`` (the compact form; ``digits`` rounds its floats, see
    :mod:`leafview.core.compact`)."""
    p = Path(path)
    fmt = _format_of(p)
    if is_compact_path(p):
        text = compact.dumps(params, digits=digits) + "\n"
    elif digits is not None:
        raise ParamError("digits", f"only the compact form (.leaf.json) rounds numbers, not {p.name}", str(p))
    else:
        text = dumps_toml(params) if fmt == "toml" else json.dumps(params.to_dict(), indent=2) + "\n"
    write_text(p, text)   # checked target, atomic rename, every byte on the disk


class _LeafFiles:
    """The file reader and writer behind :meth:`LeafParams.load` and :meth:`LeafParams.save`."""

    def load(self, path: str | os.PathLike[str]) -> LeafParams:
        return load_params(path)

    def save(self, params: LeafParams, path: str | os.PathLike[str], *, digits: int | None = None) -> None:
        save_params(params, path, digits=digits)


register_file_io(_LeafFiles())
