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

Two more schemas are generated from the same specs: :func:`compact_schema`, the compact form of
:mod:`leafview.model.compact` (Ω typed entry by entry for each accepted length), and
:func:`scene_schema`, a scene recipe (:mod:`leafview.model.scene`) whose species are compact or
full leaf tables and whose ``[plant]`` bounds come from
:data:`~leafview.model.plants.PLANT_RANGES`. The scene schema cannot say that ``leaves = 10.0``
is refused (the loader wants whole numbers).

The published copies are ``assets/schema/{leaf,leaf-compact,scene}.schema.json`` (shipped in
the wheel under ``leafview/assets/schema/``). Regenerate them after a parameter change with
``python -m leafview.schema --write``; ``--check`` exits 1 when a file is stale.
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

__all__ = ["SCHEMA_ID", "SCHEMAS", "compact_schema", "leaf_schema", "main", "published_path", "scene_schema",
           "schema_text"]

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


def _omega_schema() -> dict[str, Any]:
    """Ω as the compact form writes it: one alternative per accepted length, each entry typed and
    bounded as its shape field is (v̄ inside (0, 1), tilts within ±90°)."""

    specs = P.field_specs()
    vbar = {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1}
    plain = {"type": "number"}
    tilt = _number(specs["shape.tilt"])
    alternatives = []
    for size, n in P.omega_sizes().items():
        items = [plain] * 6
        for _ in range(n):
            items += [vbar, plain, plain]
        items += [plain] * (2 * n)
        tilted = size != P.OMEGA_SIZE
        if tilted:
            items += [tilt] * n
        what = f"{n} silhouette rows" + (" with tilts" if tilted else " (the paper's quartic)")
        alternatives.append({"description": f"{size} numbers: {what}", "prefixItems": items,
                             "minItems": size, "maxItems": size})
    return {"type": "array", "title": "Ω",
            "description": ("The shape vector Ω: a1 (3), a2 (3), the silhouette rows (v̄, x̄s, z̄s) × N, "
                            "z̄f × N, z̄g × N and, for an extended silhouette, the row tilts × N (degrees)."),
            "items": {"type": "number"}, "anyOf": alternatives}


def _compact_leaf(version: str) -> dict[str, Any]:
    """The compact leaf object; ``version``: "required", "optional" or "absent" (the leafview key)."""
    from .model.compact import COMPACT_VERSION, OPTIONAL_GROUPS

    full = leaf_schema()["properties"]
    specs = P.field_specs()
    props: dict[str, Any] = {}
    if version != "absent":
        props["leafview"] = {"const": COMPACT_VERSION, "description": "compact format version"}
    props["name"] = full["name"]
    props["omega"] = {"$ref": "#/$defs/omega"}
    props["half"] = {"title": specs["shape.half"].label, **_field(specs["shape.half"]),
                     "description": "only for a one-sided leaf; absent means both halves (0)"}
    for group in OPTIONAL_GROUPS:
        g = copy.deepcopy(full[group])
        g.pop("required", None)
        g["description"] = g.get("description", "") + " Only the fields that differ from their defaults."
        props[group] = g
    required = ["leafview", "omega"] if version == "required" else ["omega"]
    return {"type": "object", "properties": props, "required": required, "additionalProperties": False}


def compact_schema() -> dict[str, Any]:
    """The JSON Schema of the compact form (one leaf, or a leaf set): see
    :mod:`leafview.model.compact`."""
    from .model.compact import COMPACT_VERSION

    return {
        "$schema": _DIALECT,
        "$id": f"urn:leafview:schema:leaf-compact:{COMPACT_VERSION}",
        "title": "leafview compact leaf",
        "description": ("One parametric leaf in the compact form: Ω as one list (seed 004 eqs 3-4) and only the "
                        "settings that differ from their defaults (the defaults are the 'default' values in "
                        "leaf.schema.json); or a leaf set {\"leafview\": 1, \"leaves\": [...]}. Numbers are "
                        "the shortest decimals that read back to the same float64."),
        "oneOf": [{"$ref": "#/$defs/leafDocument"}, {"$ref": "#/$defs/leafSet"}],
        "$defs": {
            "omega": _omega_schema(),
            "leafDocument": _compact_leaf("required"),
            "leaf": _compact_leaf("absent"),
            "leafSet": {"type": "object",
                        "properties": {"leafview": {"const": COMPACT_VERSION},
                                       "leaves": {"type": "array", "minItems": 1, "items": {"$ref": "#/$defs/leaf"}}},
                        "required": ["leafview", "leaves"], "additionalProperties": False},
        },
    }


def _plant_schema() -> dict[str, Any]:
    from .model.plants import PHYLLOTAXIS, PLANT_RANGES, PlantSpec

    default = PlantSpec()
    props: dict[str, Any] = {
        "phyllotaxis": {"enum": list(PHYLLOTAXIS), "default": default.phyllotaxis},
        "light": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3,
                  "not": {"items": {"const": 0}}, "default": list(default.light),
                  "description": "direction towards the light (normalised on load), not the zero vector"},
    }
    for name, (lo, hi, open_lo, integer) in PLANT_RANGES.items():
        entry: dict[str, Any] = {"type": "integer" if integer else "number"}
        if lo is not None:
            entry["exclusiveMinimum" if open_lo else "minimum"] = lo
        if hi is not None:
            entry["maximum"] = hi
        entry["default"] = getattr(default, name)
        props[name] = entry
    return {"type": "object", "description": _doc_line(PlantSpec), "properties": props,
            "additionalProperties": False}


def scene_schema() -> dict[str, Any]:
    """The JSON Schema of a scene file (:class:`leafview.model.scene.SceneSpec`)."""
    from .model import scene as S

    spec_fields = S.SceneSpec.__dataclass_fields__
    full_leaf = copy.deepcopy(leaf_schema())
    for key in ("$schema", "$id", "title"):
        full_leaf.pop(key)
    full_leaf["required"] = [k for k in full_leaf["required"] if k != "schema"]
    full_leaf["description"] = "the full leaf parameter table (schema may be left out; transform is ignored)"
    compact = compact_schema()["$defs"]
    scene_props = {
        "layout": {"enum": list(S.LAYOUTS), "default": spec_fields["layout"].default},
        "leaves": {"type": "integer", "minimum": 1, "maximum": S.MAX_LEAVES, "default": spec_fields["leaves"].default},
        "seed": {"type": "integer", "minimum": 0, "maximum": 2**63 - 1, "default": spec_fields["seed"].default},
        "plants": {"type": "integer", "minimum": 0, "maximum": 1_000_000, "default": spec_fields["plants"].default,
                   "description": "0: chosen from the leaf count"},
        "variation": {"type": "number", "minimum": 0, "maximum": 0.5, "default": spec_fields["variation"].default,
                      "description": "± fraction of each Ω component per leaf"},
        "colour_variation": {"type": "number", "minimum": 0, "maximum": 0.5,
                             "default": spec_fields["colour_variation"].default},
        "stems": {"type": "boolean", "default": spec_fields["stems"].default},
        "name": {"type": "string"},
    }
    species = {
        "type": "object",
        "properties": {
            "weight": {"type": "number", "exclusiveMinimum": 0, "default": 1.0,
                       "description": "relative frequency per plant"},
            "leaf": {"anyOf": [{"$ref": "#/$defs/compactLeaf"}, {"$ref": "#/$defs/fullLeaf"}]},
            "preset": {"type": "string", "minLength": 1,
                       "description": "a built-in preset name or a path relative to the scene file"},
        },
        "oneOf": [{"required": ["leaf"]}, {"required": ["preset"]}],
        "additionalProperties": False,
    }
    return {
        "$schema": _DIALECT,
        "$id": f"urn:leafview:schema:scene:{S.SCENE_SCHEMA}",
        "title": "leafview scene",
        "description": ("A scene recipe: layout, leaf count, seed and species with weights; leafview expands it "
                        "deterministically into per-leaf parameters and placements (leafview.model.scene). "
                        "Stored as TOML or JSON."),
        "type": "object",
        "properties": {
            "schema": {"const": S.SCENE_SCHEMA, "description": "file format version"},
            "scene": {"type": "object", "properties": scene_props, "additionalProperties": False},
            "species": {"type": "array", "minItems": 1, "items": {"$ref": "#/$defs/species"}},
            "plant": _plant_schema(),
        },
        "required": ["schema", "species"],
        "additionalProperties": False,
        "$defs": {
            "species": species,
            "compactLeaf": _compact_leaf("optional"),
            "omega": compact["omega"],
            "fullLeaf": full_leaf,
        },
    }


# published file name -> generator
SCHEMAS = {"leaf.schema.json": leaf_schema, "leaf-compact.schema.json": compact_schema,
           "scene.schema.json": scene_schema}


def schema_text(name: str = "leaf.schema.json") -> str:
    """A schema as the published file holds it (2-space JSON, UTF-8, final newline)."""
    return json.dumps(SCHEMAS[name](), indent=2, ensure_ascii=False) + "\n"


def published_path(name: str = "leaf.schema.json") -> Path:
    """``assets/schema/<name>`` (in the checkout, or inside the installed wheel)."""
    from .resources import asset_dir

    return asset_dir() / "schema" / name


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m leafview.schema",
                                     description="Print, check or rewrite the published JSON Schemas "
                                                 f"({', '.join(SCHEMAS)}).")
    parser.add_argument("name", nargs="?", choices=tuple(SCHEMAS), default="leaf.schema.json",
                        help="the schema to print (default leaf.schema.json)")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--write", action="store_true", help="rewrite every file in assets/schema/")
    group.add_argument("--check", action="store_true", help="exit 1 if a published file is stale")
    args = parser.parse_args(argv)
    if args.write:
        from .atomic import atomic_output

        for name in SCHEMAS:
            path = published_path(name)
            with atomic_output(path) as tmp:
                tmp.write_text(schema_text(name), encoding="utf-8")
            print(f"wrote {path}")
        return 0
    if args.check:
        stale = 0
        for name in SCHEMAS:
            path = published_path(name)
            current = path.read_text(encoding="utf-8") if path.exists() else ""
            if current != schema_text(name):
                print(f"{path} is stale: run python -m leafview.schema --write", file=sys.stderr)
                stale += 1
            else:
                print(f"{path} is up to date")
        return 1 if stale else 0
    sys.stdout.write(schema_text(args.name))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
