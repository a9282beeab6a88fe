"""The JSON Schema of a scene file, and the published copies of every leafview schema.

:func:`scene_schema` describes a scene recipe (:mod:`leafview.scene.spec`) whose species are
compact or full leaf tables (the schemas of :mod:`leafview.core.schema`) and whose ``[plant]``
bounds come from :data:`~leafview.scene.plants.PLANT_RANGES`. The settings tables (``[light]``,
``[wind]``, each species' ``variety``) are generated from their classes' field specs
(:func:`settings_schema`), so a field added there appears here; the ``[[edits]]`` list from the
constants of :mod:`leafview.scene.scene_edits`. It cannot say that ``leaves = 10.0`` is refused
(the loader wants whole numbers), that a variety range must not be reversed, or what a settings
class checks between its fields (the sun's elevation range).

The published copies are ``assets/schema/{leaf,leaf-compact,scene}.schema.json`` (shipped in
the wheel under ``leafview/assets/schema/``). Regenerate them after a parameter change with
``python -m leafview.scene.schema --write``; ``--check`` exits 1 when a file is stale.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from collections.abc import Callable
from dataclasses import MISSING, Field, fields
from pathlib import Path
from typing import Any

from leafview.atomic import atomic_output
from leafview.core.fieldspec import FieldSpec
from leafview.core.limits import MAX_NAME_CHARS, MAX_PLANTS
from leafview.core.schema import DIALECT, compact_leaf_schema, compact_schema, doc_line, leaf_schema
from leafview.core.settings import field_specs
from leafview.deform.wind import WindSettings
from leafview.resources import asset_dir
from leafview.scene import scene_edits as E
from leafview.scene import spec as S
from leafview.scene.lighting import LightSettings
from leafview.scene.plants import PHYLLOTAXIS, PLANT_RANGES, PlantSpec
from leafview.scene.variety import Variety

__all__ = ["SCHEMAS", "main", "published_path", "scene_schema", "schema_text", "settings_schema", "edits_schema"]


def _bounded(entry: dict[str, Any], spec: FieldSpec) -> dict[str, Any]:
    """``entry`` with the hard range of ``spec`` (exclusive 0 when it must be positive)."""
    lo, hi = spec.hard_range
    if spec.positive and (lo is None or lo <= 0):
        entry["exclusiveMinimum"] = 0
    elif lo is not None:
        entry["minimum"] = lo
    if hi is not None:
        entry["maximum"] = hi
    return entry


def _field_schema(spec: FieldSpec, default: Any) -> dict[str, Any]:
    """The JSON Schema of one settings field from its :class:`~leafview.core.fieldspec.FieldSpec`."""
    entry: dict[str, Any]
    if spec.kind == "bool":
        entry = {"type": "boolean"}
    elif spec.kind == "choice":
        entry = {"enum": list(spec.choices)}
    elif spec.kind == "int":
        entry = _bounded({"type": "integer"}, spec)
    elif spec.kind == "pair":
        entry = {"type": "array", "items": _bounded({"type": "number"}, spec), "minItems": 2, "maxItems": 2}
    elif spec.kind == "float":
        entry = _bounded({"type": "number"}, spec)
    else:
        raise ValueError(f"no schema for a settings field of kind {spec.kind!r}")
    entry["default"] = list(default) if isinstance(default, tuple) else default
    entry["description"] = spec.label
    return entry


def _default(f: Field[Any]) -> Any:
    """A dataclass field's default value (made by its factory when it has one)."""
    if f.default is not MISSING:
        return f.default
    factory: Callable[[], Any] = f.default_factory   # type: ignore[assignment]
    return factory()


def settings_schema(cls: type) -> dict[str, Any]:
    """The JSON Schema of a settings table (:class:`~leafview.core.settings.SettingsTable`), from
    its fields' specs: every key optional, unknown keys refused."""
    defaults = {f.name: _default(f) for f in fields(cls)}
    props = {name: _field_schema(spec, defaults[name]) for name, spec in field_specs(cls).items()}
    return {"type": "object", "description": doc_line(cls), "properties": props, "additionalProperties": False}


def edits_schema() -> dict[str, Any]:
    """The JSON Schema of the ``[[edits]]`` list (:class:`leafview.scene.scene_edits.SceneEdit`):
    each op's value range, a ``leaves`` target with at least one leaf."""
    limits = E._LIMITS
    index = {"type": "integer", "minimum": 0}
    edit = {
        "type": "object",
        "description": doc_line(E.SceneEdit),
        "properties": {
            "op": {"enum": list(E.EDIT_OPS)},
            "value": {"type": "number", "minimum": min(lo for lo, _ in limits.values()),
                      "maximum": max(hi for _, hi in limits.values())},
            "target": {"enum": list(E.EDIT_TARGETS), "default": "all"},
            "species": {**index, "default": 0, "description": "the species index of a 'species' target"},
            "leaves": {"type": "array", "items": index, "description": "the leaf indices of a 'leaves' target"},
            "row": {"type": "integer", "minimum": 0, "maximum": E.SIL_ROWS - 1, "default": 0,
                    "description": "the silhouette row of a 'silhouette' edit"},
            "v": {"type": "number", "minimum": -E._V_LIMIT, "maximum": E._V_LIMIT, "default": 0.0,
                  "description": "the shift of a 'silhouette' edit's foot along v"},
            "curve": {"enum": list(E.CURVES), "default": "axis", "description": "the curve of a 'curvature' edit"},
        },
        "required": ["op", "value"],
        "additionalProperties": False,
        "allOf": [{"if": {"properties": {"op": {"const": op}}, "required": ["op"]},
                   "then": {"properties": {"value": {"minimum": lo, "maximum": hi}}}}
                  for op, (lo, hi) in limits.items()]
        + [{"if": {"properties": {"target": {"const": "leaves"}}, "required": ["target"]},
            "then": {"required": ["leaves"], "properties": {"leaves": {"minItems": 1}}}}],
    }
    return {"type": "array", "items": edit, "description": "scene-wide edits, applied in order (leafview.scene.scene_edits)"}


def _plant_schema() -> dict[str, Any]:

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
    return {"type": "object", "description": doc_line(PlantSpec), "properties": props,
            "additionalProperties": False}


def scene_schema() -> dict[str, Any]:
    """The JSON Schema of a scene file (:class:`leafview.scene.spec.SceneSpec`)."""

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
        "plants": {"type": "integer", "minimum": 0, "maximum": MAX_PLANTS, "default": spec_fields["plants"].default,
                   "description": "0: chosen from the leaf count (leaves and plants together must also fit "
                                  "in half of the machine's memory)"},
        "variation": {"type": "number", "minimum": 0, "maximum": 0.5, "default": spec_fields["variation"].default,
                      "description": "± fraction of each Ω component per leaf"},
        "colour_variation": {"type": "number", "minimum": 0, "maximum": 0.5,
                             "default": spec_fields["colour_variation"].default},
        "stems": {"type": "boolean", "default": spec_fields["stems"].default},
        "name": {"type": "string", "maxLength": MAX_NAME_CHARS, "pattern": "^[^\\u0000-\\u001f\\u007f-\\u009f]*$"},
    }
    species = {
        "type": "object",
        "properties": {
            "weight": {"type": "number", "exclusiveMinimum": 0, "default": 1.0,
                       "description": "relative frequency per plant"},
            "leaf": {"anyOf": [{"$ref": "#/$defs/compactLeaf"}, {"$ref": "#/$defs/fullLeaf"}]},
            "preset": {"type": "string", "minLength": 1,
                       "description": "a built-in preset name or a path relative to the scene file, inside "
                                      "its folder (absolute paths and '..' need --allow-outside-presets)"},
            "variety": settings_schema(Variety),
        },
        "oneOf": [{"required": ["leaf"]}, {"required": ["preset"]}],
        "additionalProperties": False,
    }
    return {
        "$schema": DIALECT,
        "$id": f"urn:leafview:schema:scene:{S.SCENE_SCHEMA}",
        "title": "leafview scene",
        "description": ("A scene recipe: layout, leaf count, seed and species with weights; leafview expands it "
                        "deterministically into per-leaf parameters and placements (leafview.scene.spec). "
                        "Stored as TOML or JSON."),
        "type": "object",
        "properties": {
            "schema": {"const": S.SCENE_SCHEMA, "description": "file format version"},
            "scene": {"type": "object", "properties": scene_props, "additionalProperties": False},
            "species": {"type": "array", "minItems": 1, "items": {"$ref": "#/$defs/species"}},
            "plant": _plant_schema(),
            "light": settings_schema(LightSettings),
            "wind": settings_schema(WindSettings),
            "edits": edits_schema(),
        },
        "required": ["schema", "species"],
        "additionalProperties": False,
        "$defs": {
            "species": species,
            "compactLeaf": compact_leaf_schema("optional"),
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

    return asset_dir() / "schema" / name


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m leafview.scene.schema",
                                     description="Print, check or rewrite the published JSON Schemas "
                                                 f"({', '.join(SCHEMAS)}).")
    parser.add_argument("name", nargs="?", choices=tuple(SCHEMAS), default="leaf.schema.json",
                        help="the schema to print (default leaf.schema.json)")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--write", action="store_true", help="rewrite every file in assets/schema/")
    group.add_argument("--check", action="store_true", help="exit 1 if a published file is stale")
    args = parser.parse_args(argv)
    if args.write:

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
                print(f"{path} is stale: run python -m leafview.scene.schema --write", file=sys.stderr)
                stale += 1
            else:
                print(f"{path} is up to date")
        return 1 if stale else 0
    sys.stdout.write(schema_text(args.name))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
