"""The compact parametric form of a leaf: Ω as one list and only the settings that differ from
their defaults, about 100-200 bytes of JSON per leaf.

A compact leaf document (``*.leaf.json``)::

    {"leafview":1,"name":"ovate","omega":[0,0.3333333333333333,0,0,0.6666666666666666,0,
     0.12,0.52,0,0.4,0.46,0,0.75,0.16,0,0.01,0.015,0.01,0.015,0.02,0.01]}

* ``leafview`` is the format version (:data:`COMPACT_VERSION`); it is also how loaders tell
  this form from the full one (which starts with ``schema``).
* ``omega`` is Ω in the order of :meth:`LeafParams.to_vector <leafview.core.params.LeafParams.to_vector>`:
  21 numbers for the paper's quartic (Chaurasia & Beardsley 2017, eqs 3-4), 6 + 6N for an extended silhouette of N
  rows with tilts.
* ``half`` (-1 or 1) appears only for a one-sided leaf (:attr:`Shape.half`).
* ``jitter``, ``material``, ``transform``, ``ripple``, ``bending`` and ``venation`` hold only
  the fields that differ from the defaults, with the same names and units as the full form; a
  group with no such field is left out (``venation.edits``, when present, is the whole list).

Numbers are written in the shortest decimal that reads back to the same float64
(``repr``), with a trailing ``.0`` dropped, so ``loads(dumps(x)) == x`` holds bit for bit.
``digits=N`` rounds every float to N significant digits first (a lossy, smaller file);
that rounding is idempotent: a leaf read from such a file is written back to the same text.

A leaf *set* (``*.leaves.json``) holds many leaves: ``{"leafview":1,"leaves":[leaf, ...]}``,
each entry a compact leaf without the ``leafview`` key. It is what a baked scene's leaves
look like as parameters (see ``leafview export SCENE -o x.leaves.json``).

Validation reuses the full form's parser, so every rule and error message is the same; a bad
Ω entry is named both ways, e.g. ``omega[7] (shape.silhouette[0][1])``.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

from leafview.core.limits import BYTES_PER_LEAF_PARAMS, MAX_LEAVES, check_count, check_memory
from leafview.core.lobes import Lobes, lobes_dict
from leafview.core.params import (
    SCHEMA_VERSION,
    LeafParams,
    ParamError,
    parse_params,
    split_omega,
)
from leafview.core.venation import Venation, venation_dict
from leafview.inputs import parse_json

__all__ = ["COMPACT_VERSION", "OPTIONAL_GROUPS", "compact_dict", "dumps", "dumps_leaves", "is_compact",
           "loads", "omega_path", "parse_compact", "parse_leaves", "round_params"]

COMPACT_VERSION = 1
OPTIONAL_GROUPS = ("jitter", "material", "transform", "ripple", "bending", "venation", "lobes")
_LEAF_KEYS = ("name", "omega", "half", *OPTIONAL_GROUPS, "texture", "margin")


# -- numbers ------------------------------------------------------------------------------
def _round(x: float, digits: int | None) -> float:
    if digits is None or x == 0.0 or not math.isfinite(x):
        return x
    return float(f"{x:.{digits - 1}e}")


def _num(x: Any) -> str:
    """Shortest JSON text of a number that reads back to the same value."""
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, int):
        return str(x)
    text = repr(float(x))
    if text.endswith(".0") and text != "-0.0":
        text = text[:-2]
    return text


def _text(value: Any) -> str:
    """Minified JSON with :func:`_num` numbers (``json.dumps`` writes ``36.0`` for 36.0)."""
    if isinstance(value, Mapping):
        return "{" + ",".join(f"{json.dumps(k)}:{_text(v)}" for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_text(v) for v in value) + "]"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    return _num(value)


def _map_floats(value: Any, digits: int | None) -> Any:
    if isinstance(value, int):      # bools and ints stay as they are
        return value
    if isinstance(value, float):
        return _round(value, digits)
    if isinstance(value, (list, tuple)):
        return [_map_floats(v, digits) for v in value]
    if isinstance(value, Mapping):
        return {k: _map_floats(v, digits) for k, v in value.items()}
    return value


# -- writing ------------------------------------------------------------------------------
def compact_dict(params: LeafParams, *, digits: int | None = None, version: bool = True) -> dict[str, Any]:
    """The compact document of ``params`` as a plain dict (see the module docstring).
    ``digits`` rounds floats to that many significant digits; ``version=False`` leaves out
    the ``leafview`` key (entries of a leaf set)."""
    if digits is not None and not (isinstance(digits, int) and 1 <= digits <= 17):
        raise ParamError("digits", f"must be a whole number in 1..17, got {digits!r}")
    full = params.to_dict()
    default = LeafParams().to_dict()
    default["venation"] = venation_dict(Venation(), keep_empty_edits=True)
    default["lobes"] = lobes_dict(Lobes())
    out: dict[str, Any] = {"leafview": COMPACT_VERSION} if version else {}
    if params.name:
        out["name"] = params.name
    out["omega"] = [_round(float(x), digits) for x in params.to_vector()]
    if params.shape.half:
        out["half"] = int(params.shape.half)
    for group in OPTIONAL_GROUPS:
        kept = {k: _map_floats(v, digits) for k, v in full.get(group, {}).items() if v != default[group][k]}
        if kept:
            out[group] = kept
    if params.texture is not None:
        out["texture"] = params.texture.to_dict()
    if params.margin is not None:
        out["margin"] = _map_floats(params.margin.to_dict(), digits)
    return out


def dumps(params: LeafParams, *, digits: int | None = None) -> str:
    """The compact JSON text of one leaf (no whitespace, no final newline)."""
    return _text(compact_dict(params, digits=digits))


def dumps_leaves(leaves: Sequence[LeafParams], *, digits: int | None = None) -> str:
    """A leaf set: ``{"leafview":1,"leaves":[...]}`` with one compact entry per line."""
    body = ",\n".join(_text(compact_dict(p, digits=digits, version=False)) for p in leaves)
    return f'{{"leafview":{COMPACT_VERSION},"leaves":[\n{body}\n]}}'


def round_params(params: LeafParams, digits: int) -> LeafParams:
    """``params`` as a file written with ``digits`` significant digits reads back."""
    return parse_compact(compact_dict(params, digits=digits))


# -- reading ------------------------------------------------------------------------------
def is_compact(doc: Any) -> bool:
    """Whether a parsed JSON document is in the compact form (it has the ``leafview`` key)."""
    return isinstance(doc, Mapping) and "leafview" in doc


_SHAPE_PATH = re.compile(r"shape\.(a1|a2|silhouette|zf|zg|tilt)\[(\d+)\](?:\[(\d+)\])?")


def omega_path(shape_path: str, rows: int, extended: bool) -> str | None:
    """The Ω index (``omega[k]``) of a dotted shape path such as ``shape.silhouette[1][0]``."""
    m = _SHAPE_PATH.match(shape_path)
    if not m:
        return None
    name, i, j = m.group(1), int(m.group(2)), m.group(3)
    e = 6 + 3 * rows
    if name in ("a1", "a2"):
        k = (0 if name == "a1" else 3) + i
    elif name == "silhouette":
        if j is None:
            return f"omega[{6 + 3 * i}:{9 + 3 * i}]"
        k = 6 + 3 * i + int(j)
    elif name == "tilt" and not extended:
        return None
    else:
        k = e + {"zf": 0, "zg": rows, "tilt": 2 * rows}[name] + i
    return f"omega[{k}]"


def _check_version(value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParamError("leafview", f"expected the format version {COMPACT_VERSION}, got {value!r}")
    if value != COMPACT_VERSION:
        raise ParamError("leafview", f"unsupported compact format version {value} "
                                     f"(this leafview reads {COMPACT_VERSION})")


def _shape_table(omega: Any) -> dict[str, Any]:
    if not isinstance(omega, list):
        raise ParamError("omega", f"expected a list of numbers (Ω), got {type(omega).__name__}")
    for k, x in enumerate(omega):
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise ParamError(f"omega[{k}]", f"expected a number, got {type(x).__name__} {x!r}")
    return split_omega([float(x) for x in omega])


def parse_compact(doc: Any, *, where: str = "", version: bool = True) -> LeafParams:
    """Validate a compact leaf document into :class:`LeafParams`; raises :class:`ParamError`
    naming the compact path (``omega[7]``, ``jitter.seed``), prefixed by ``where``."""
    pre = f"{where}." if where else ""
    try:
        if not isinstance(doc, Mapping):
            raise ParamError("", f"expected a JSON object, got {type(doc).__name__}")
        known = ("leafview", *_LEAF_KEYS) if version else _LEAF_KEYS
        for key in doc:
            if key not in known:
                raise ParamError(str(key), f"unknown key (known: {', '.join(known)})")
        if version:
            if "leafview" not in doc:
                raise ParamError("leafview", f"missing field (this version writes \"leafview\": {COMPACT_VERSION})")
            _check_version(doc["leafview"])
        if "omega" not in doc:
            raise ParamError("omega", "missing field: the shape vector Ω")
        shape = _shape_table(doc["omega"])
        if "half" in doc:
            shape["half"] = doc["half"]
        full: dict[str, Any] = {"schema": SCHEMA_VERSION, "shape": shape}
        if "name" in doc:
            full["name"] = doc["name"]
        for group in (*OPTIONAL_GROUPS, "texture", "margin"):
            if group in doc:
                full[group] = doc[group]
        try:
            return parse_params(full)
        except ParamError as exc:
            path = exc.path
            if path == "shape.half":
                path = "half"
            elif path.startswith("shape."):
                rows = len(shape["silhouette"])
                k = omega_path(path, rows, "tilt" in shape)
                path = f"{k} ({path})" if k else "omega"
            raise ParamError(path, exc.message) from None
    except ParamError as exc:
        raise ParamError(f"{pre}{exc.path}".rstrip("."), exc.message) from None


def loads(text: str) -> LeafParams:
    """Read one compact leaf from JSON text."""
    return parse_compact(parse_json(text, "<compact leaf text>"))


def parse_leaves(doc: Any) -> list[LeafParams]:
    """Validate a leaf set (``{"leafview":1,"leaves":[...]}``); errors name ``leaves[i].…``."""
    if not isinstance(doc, Mapping):
        raise ParamError("", f"expected a JSON object, got {type(doc).__name__}")
    for key in doc:
        if key not in ("leafview", "leaves"):
            raise ParamError(str(key), "unknown key (known: leafview, leaves)")
    if "leafview" not in doc:
        raise ParamError("leafview", f"missing field (this version writes \"leafview\": {COMPACT_VERSION})")
    _check_version(doc["leafview"])
    leaves = doc.get("leaves")
    if not isinstance(leaves, list) or not leaves:
        raise ParamError("leaves", "expected a non-empty list of compact leaves")
    check_count("leaves", len(leaves), 1, MAX_LEAVES)
    check_memory("leaves", len(leaves) * BYTES_PER_LEAF_PARAMS, f"a leaf set of {len(leaves):,} leaves")
    return [parse_compact(item, where=f"leaves[{i}]", version=False) for i, item in enumerate(leaves)]
