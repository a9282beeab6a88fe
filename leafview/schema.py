"""The JSON Schema of the leaf parameter file, generated from the parameter dataclasses.

A leaf file (TOML or JSON, see :mod:`leafview.model.io`) holds ``schema``, an optional
``name`` and the groups of :class:`~leafview.model.params.LeafParams` (``shape`` is Ω of seed 004
sec. 3, eqs 3-4; ``jitter`` sec. 6; ``ripple`` and ``bending`` seed 002 eqs 4-5; ``material``;
``transform``). :func:`leaf_schema` builds a JSON Schema (draft 2020-12) of that document from
:func:`~leafview.model.params.field_specs` and the dataclass defaults, so it follows the code:

* each field's type from its ``kind`` (number, integer, boolean, fixed-length vectors, the
  silhouette rows and the per-row lists), ``hard_range`` as minimum/maximum and ``positive`` as
  an exclusive minimum of 0; its label as ``title`` and its default as ``default``;
* which keys are required is measured, not declared: a key is required when
  :func:`~leafview.model.params.parse_params` rejects the default document without it;
* the per-row lists (``zf``, ``zg``, ``tilt``) have as many entries as ``silhouette`` has rows,
  written as one alternative per row count;
* two rules of ``_check_shape`` / ``_parse_group`` are added by hand, and a test checks that the
  parser agrees: v̄ lies strictly inside (0, 1) and the bending direction is not zero.

What the schema cannot say: that v̄ increases from row to row, and that integer fields reject
``1.0`` (JSON Schema counts 1.0 as an integer). The loader checks both.

The published copy is ``assets/schema/leaf.schema.json`` (shipped in the wheel as
``leafview/assets/schema/leaf.schema.json``). Regenerate it after a parameter change with
``python -m leafview.schema --write``; ``--check`` exits 1 when the file is stale.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from dataclasses import fields
from pathlib import Path
from typing import Any

from .model import params as P

__all__ = ["SCHEMA_ID", "leaf_schema", "main", "published_path", "schema_text"]

SCHEMA_ID = f"urn:leafview:schema:leaf:{P.SCHEMA_VERSION}"
_DIALECT = "https://json-schema.org/draft/2020-12/schema"


def _groups() -> dict[str, type]:
    """Group name -> dataclass, in LeafParams field order."""
    out = {}
    for f in fields(P.LeafParams):
        if f.name != "name":
            out[f.name] = type(f.default_factory())  # type: ignore[misc]
    return out


def _max_rows() -> int:
    return int(getattr(P, "MAX_SILHOUETTE_ROWS", 3))


def _number(spec: P.FieldSpec, integer: bool = False) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "integer" if integer else "number"}
    lo, hi = spec.hard_range
    if lo is not None:
        out["minimum"] = lo
    if hi is not None:
        out["maximum"] = hi
    if spec.positive:
        out["exclusiveMinimum"] = 0
    return out


def _array(items: dict[str, Any], n_min: int, n_max: int | None = None) -> dict[str, Any]:
    return {"type": "array", "items": items, "minItems": n_min, "maxItems": n_min if n_max is None else n_max}


def _field(spec: P.FieldSpec) -> dict[str, Any]:
    kind = spec.kind
    if kind == "bool":
        return {"type": "boolean"}
    if kind == "int":
        return _number(spec, integer=True)
    if kind == "float":
        return _number(spec)
    if kind in ("vec3", "color"):
        return _array(_number(spec), 3)
    if kind == "pair":
        return _array(_number(spec), 2)
    if kind == "rows":
        row = {"type": "array", "minItems": 3, "maxItems": 3,
               "prefixItems": [{"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1,
                                "description": "v̄: where the row's foot sits on the axis, strictly inside (0, 1) "
                                               "and increasing from row to row"},
                               {"type": "number", "description": "x̄s: half-width offset along the axis normal"},
                               {"type": "number", "description": "z̄s: height"}]}
        return _array(row, 3, _max_rows())
    if kind == "per_row":
        return _array(_number(spec), 3, _max_rows())
    raise ValueError(f"leafview.schema does not know the field kind {kind!r}: extend _field()")


def _required(doc: dict[str, Any], path: tuple[str, ...]) -> bool:
    """Whether the parser rejects ``doc`` without the key at ``path``."""
    trial = copy.deepcopy(doc)
    node = trial
    for key in path[:-1]:
        node = node[key]
    del node[path[-1]]
    try:
        P.parse_params(trial)
    except P.ParamError:
        return True
    return False


def _doc_line(cls: type) -> str:
    text = (cls.__doc__ or "").strip().split("\n\n")[0]
    return " ".join(text.split())


def leaf_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a leaf parameter document."""
    specs = P.field_specs()
    default = P.LeafParams().to_dict()
    props: dict[str, Any] = {
        "schema": {"const": P.SCHEMA_VERSION, "description": "file format version"},
        "name": {"type": "string", "description": "the leaf's name (the file name when absent)"},
    }
    per_row: list[str] = []
    for group, cls in _groups().items():
        gprops: dict[str, Any] = {}
        for f in fields(cls):
            spec = specs[f"{group}.{f.name}"]
            entry = {"title": spec.label, **_field(spec), "default": default[group][f.name]}
            if spec.kind == "per_row":
                per_row.append(f.name)
            gprops[f.name] = entry
        if group == "bending" and "direction" in gprops:
            gprops["direction"]["not"] = {"const": [0, 0, 0]}
        gschema: dict[str, Any] = {"type": "object", "description": _doc_line(cls), "properties": gprops,
                                   "additionalProperties": False}
        required = [k for k in gprops if _required(default, (group, k))]
        if required:
            gschema["required"] = required
        if group == "shape" and per_row:
            gschema["anyOf"] = [{"properties": {"silhouette": {"minItems": n, "maxItems": n},
                                                **{k: {"minItems": n, "maxItems": n} for k in per_row}}}
                                for n in range(3, _max_rows() + 1)]
        props[group] = gschema
    return {
        "$schema": _DIALECT,
        "$id": SCHEMA_ID,
        "title": "leafview leaf parameters",
        "description": ("One parametric leaf (leafview): the Bézier shape vector Ω of Chaurasia & Beardsley "
                        "(seed 004, eqs 3-4), jitter, ripples and bending (seed 002, eqs 4-5), material and "
                        "placement. Stored as TOML or JSON. Lengths are in leaf lengths (base (0,0,0), apex "
                        "(0,1,0)); angles in degrees; colours linear RGB."),
        "type": "object",
        "properties": props,
        "required": [k for k in ("schema", *_groups()) if k in default and _required(default, (k,))],
        "additionalProperties": False,
    }


def schema_text() -> str:
    """The schema as the published file holds it (2-space JSON, UTF-8, final newline)."""
    return json.dumps(leaf_schema(), indent=2, ensure_ascii=False) + "\n"


def published_path() -> Path:
    """``assets/schema/leaf.schema.json`` (in the checkout, or inside the installed wheel)."""
    from .resources import asset_dir

    return asset_dir() / "schema" / "leaf.schema.json"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m leafview.schema",
                                     description="Print, check or rewrite the leaf file's JSON Schema.")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--write", action="store_true", help="rewrite assets/schema/leaf.schema.json")
    group.add_argument("--check", action="store_true", help="exit 1 if the published file is stale")
    args = parser.parse_args(argv)
    text = schema_text()
    path = published_path()
    if args.write:
        from .atomic import atomic_output

        with atomic_output(path) as tmp:
            tmp.write_text(text, encoding="utf-8")
        print(f"wrote {path}")
        return 0
    if args.check:
        current = path.read_text(encoding="utf-8") if path.exists() else ""
        if current != text:
            print(f"{path} is stale: run python -m leafview.schema --write", file=sys.stderr)
            return 1
        print(f"{path} is up to date")
        return 0
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
