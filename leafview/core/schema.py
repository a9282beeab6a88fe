"""The JSON Schema of the leaf parameter file, generated from the parameter dataclasses.

A leaf file (TOML or JSON, see :mod:`leafview.core.io`) holds ``schema``, an optional
``name`` and the groups of :class:`~leafview.core.params.LeafParams` (``shape`` is Ω of Chaurasia & Beardsley 2017,
sec. 3, eqs 3-4; ``jitter`` sec. 6; ``ripple`` and ``bending`` Geng, Hu & Zhang 2014, eqs 4-5; ``material``;
``transform``). :func:`leaf_schema` builds a JSON Schema (draft 2020-12) of that document from
:func:`~leafview.core.params.field_specs` and the dataclass defaults, so it follows the code:

* each field's type from its ``kind`` (number, integer, boolean, fixed-length vectors, the
  silhouette rows and the per-row lists), ``hard_range`` as minimum/maximum and ``positive`` as
  an exclusive minimum of 0; its label as ``title`` and its default as ``default``;
* which keys are required is measured, not declared: a key is required when
  :func:`~leafview.core.params.parse_params` rejects the default document without it;
* the per-row lists (``zf``, ``zg``, ``tilt``) have as many entries as ``silhouette`` has rows,
  written as one alternative per row count;
* two rules of ``_check_shape`` / ``_parse_group`` are added by hand, and a test checks that the
  parser agrees: v̄ lies strictly inside (0, 1) and the bending direction is not zero.

What the schema cannot say: that v̄ increases from row to row, and that integer fields reject
``1.0`` (JSON Schema counts 1.0 as an integer). The loader checks both.

One more schema is generated from the same specs here: :func:`compact_schema`, the compact form
of :mod:`leafview.core.compact` (Ω typed entry by entry for each accepted length). The scene
schema, and the published copies of all three, live in :mod:`leafview.scene.schema`.
"""

from __future__ import annotations

import copy
from dataclasses import MISSING, fields
from typing import Any

from leafview.core import params as P
from leafview.core.bspline import MAX_CONTROLS, MIN_CONTROLS
from leafview.core.compact import COMPACT_VERSION, OPTIONAL_GROUPS
from leafview.core.limits import MAX_NAME_CHARS
from leafview.core.lobes import (
    MAX_BRANCHES,
    MAX_VALLEYS,
    OUTLINE_LIMIT,
    TURTLE_KNOTS,
    BranchTurtle,
    Lobes,
    lobes_dict,
    turtle_specs,
)
from leafview.core.margin import MARGIN_LIMIT, MAX_GAPS
from leafview.core.texture import MAX_TEXTURE_PATH
from leafview.core.venation import MAX_EDITS, VeinEdit, Venation, edit_specs, venation_dict

__all__ = ["SCHEMA_ID", "DIALECT", "compact_schema", "compact_leaf_schema", "doc_line", "leaf_schema"]

SCHEMA_ID = f"urn:leafview:schema:leaf:{P.SCHEMA_VERSION}"
DIALECT = "https://json-schema.org/draft/2020-12/schema"


def _groups() -> dict[str, type]:
    """Group name -> dataclass, in LeafParams field order."""
    out: dict[str, type] = {}
    for f in fields(P.LeafParams):
        if f.name not in ("name", "texture", "margin"):
            if f.default_factory is MISSING:
                raise TypeError(f"LeafParams.{f.name} is a group without a default factory")
            out[f.name] = type(f.default_factory())
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


def _name_schema(description: str) -> dict[str, Any]:
    """A name: at most MAX_NAME_CHARS characters, no control characters (:func:`leafview.core.limits.check_name`)."""
    return {"type": "string", "maxLength": MAX_NAME_CHARS, "pattern": "^[^\\u0000-\\u001f\\u007f-\\u009f]*$",
            "description": description}


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
                               {**_number(spec), "description": "x̄s: half-width offset along the axis normal"},
                               {**_number(spec), "description": "z̄s: height"}]}
        return _array(row, 3, _max_rows())
    if kind == "per_row":
        return _array(_number(spec), 3, _max_rows())
    if kind == "choice":
        return {"type": "string", "enum": list(spec.choices)}
    if kind == "edits":
        return _edits_schema()
    if kind in ("outline", "points"):
        lo, hi = (MIN_CONTROLS, MAX_CONTROLS) if kind == "outline" else (0, MAX_VALLEYS)
        point = {"type": "array", "items": {"type": "number", "minimum": -OUTLINE_LIMIT, "maximum": OUTLINE_LIMIT},
                 "minItems": 2, "maxItems": 2}
        out = {"type": "array", "items": point, "maxItems": hi}
        if kind == "outline":   # empty (not lobed) or a closed B-spline's control points
            out["anyOf"] = [{"maxItems": 0}, {"minItems": lo}]
        return out
    if kind == "knots":
        return _array(_number(spec), TURTLE_KNOTS)
    if kind == "turtle":
        return _turtle_schema()
    raise ValueError(f"leafview.core.schema does not know the field kind {kind!r}: extend _field()")


def _turtle_schema() -> dict[str, Any]:
    """``lobes.branches``: turtle edits per skeleton branch (:class:`~leafview.core.lobes.BranchTurtle`),
    each branch at most once (which the loader checks; the schema cannot)."""
    props = {name: {"title": spec.label, **_field(spec)} for name, spec in turtle_specs().items()}
    item = {"type": "object", "description": doc_line(BranchTurtle), "properties": props,
            "required": ["branch"], "additionalProperties": False}
    return {"type": "array", "items": item, "maxItems": MAX_BRANCHES}


def _edits_schema() -> dict[str, Any]:
    """``venation.edits``: a list of vein edits (:class:`~leafview.core.venation.VeinEdit`), each
    (vein, side) at most once (which the loader checks; the schema cannot)."""
    props: dict[str, Any] = {}
    for name, spec in edit_specs().items():
        props[name] = {"title": spec.label, **_field(spec)}
    props["side"]["enum"] = [-1, 1]
    for name in ("angle", "bulge"):
        props[name]["default"] = 0.0
    item = {"type": "object", "description": doc_line(VeinEdit), "properties": props,
            "required": ["vein", "side"], "additionalProperties": False}
    return {"type": "array", "items": item, "maxItems": MAX_EDITS}


def _default_document() -> dict[str, Any]:
    """The default leaf as a document with every group written out (the venation group, which
    a default leaf leaves out of its file, with an empty ``edits`` list)."""
    doc = P.LeafParams().to_dict()
    doc["venation"] = venation_dict(Venation(), keep_empty_edits=True)
    doc["lobes"] = lobes_dict(Lobes())
    return doc


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


def doc_line(cls: type) -> str:
    text = (cls.__doc__ or "").strip().split("\n\n")[0]
    return " ".join(text.split())


def _texture_schema() -> dict[str, Any]:
    """The ``texture`` table (:mod:`leafview.core.texture`): relative image paths."""
    path = {"type": "string", "minLength": 1, "maxLength": MAX_TEXTURE_PATH,
            "pattern": r"^(?!/)(?![A-Za-z]:)(?!.*\\)(?!(.*/)?\.{1,2}(/|$))(?!.*//)[^\x00-\x1f\x7f]+"
                       r"\.([Pp][Nn][Gg]|[Jj][Pp][Ee]?[Gg]|[Tt][Ii][Ff][Ff]?|[Ee][Xx][Rr])$"}
    return {"type": "object",
            "description": ("Image textures addressed by the leaf's (u, v): paths relative to the leaf file's "
                            "folder, which they may not leave (PNG, JPEG, TIFF, OpenEXR)."),
            "properties": {"front": {**path, "description": "the front (upper side) image"},
                           "back": {**path, "description": "the back (lower side) image; the front one when absent"}},
            "required": ["front"], "additionalProperties": False}


def _margin_schema() -> dict[str, Any]:
    """The ``margin`` table (:mod:`leafview.core.margin`): a landmark margin in place of Ω's silhouette."""
    xy = {"type": "array", "items": {"type": "number", "minimum": -MARGIN_LIMIT, "maximum": MARGIN_LIMIT},
          "minItems": 2, "maxItems": 2}
    side = {"type": "object",
            "description": ("one side in its own frame (x across the blade, y along the midrib): N knots "
                            "from 0 to 1 and 3N - 2 points p0, a0, b0, p1, ..., from [0, 0] to [0, 1]"),
            "properties": {"knots": {"type": "array", "items": {"type": "number", "minimum": 0, "maximum": 1},
                                     "minItems": 2, "maxItems": MAX_GAPS + 1},
                           "points": {"type": "array", "items": xy, "minItems": 4, "maxItems": 3 * MAX_GAPS + 1}},
            "required": ["knots", "points"], "additionalProperties": False}
    return {"type": "object",
            "description": ("A landmark margin (quadratic B-spline through landmarks, Garg & Leow 2011, eqs 2-6) "
                            "drawn in place of the silhouette rows; left copies right when absent."),
            "properties": {"right": side, "left": side}, "required": ["right"], "additionalProperties": False}


def leaf_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a leaf parameter document."""
    specs = P.field_specs()
    default = _default_document()
    props: dict[str, Any] = {
        "schema": {"const": P.SCHEMA_VERSION, "description": "file format version"},
        "name": _name_schema("the leaf's name (the file name when absent)"),
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
        gschema: dict[str, Any] = {"type": "object", "description": doc_line(cls), "properties": gprops,
                                   "additionalProperties": False}
        required = [k for k in gprops if _required(default, (group, k))]
        if required:
            gschema["required"] = required
        if group == "shape" and per_row:
            gschema["anyOf"] = [{"properties": {"silhouette": {"minItems": n, "maxItems": n},
                                                **{k: {"minItems": n, "maxItems": n} for k in per_row}}}
                                for n in range(3, _max_rows() + 1)]
        props[group] = gschema
    props["texture"] = _texture_schema()
    props["margin"] = _margin_schema()
    return {
        "$schema": DIALECT,
        "$id": SCHEMA_ID,
        "title": "leafview leaf parameters",
        "description": ("One parametric leaf (leafview): the Bézier shape vector Ω "
                        "(Chaurasia & Beardsley 2017, eqs 3-4), jitter, ripples and bending (Geng, Hu & Zhang 2014, eqs 4-5), material and "
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
    vbar: dict[str, Any] = {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1}
    plain: dict[str, Any] = {"type": "number", "minimum": -P.OMEGA_LIMIT, "maximum": P.OMEGA_LIMIT}
    tilt = _number(specs["shape.tilt"])
    alternatives: list[dict[str, Any]] = []
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


def compact_leaf_schema(version: str) -> dict[str, Any]:
    """The compact leaf object; ``version``: "required", "optional" or "absent" (the leafview key)."""

    full = leaf_schema()["properties"]
    specs = P.field_specs()
    props: dict[str, Any] = {}
    if version != "absent":
        props["leafview"] = {"const": COMPACT_VERSION, "description": "compact format version"}
    props["name"] = full["name"]
    props["omega"] = {"$ref": "#/$defs/omega"}
    props["half"] = {"title": specs["shape.half"].label, **_field(specs["shape.half"]),
                     "description": "only for a one-sided leaf; absent means both halves (0)"}
    props["texture"] = full["texture"]
    props["margin"] = full["margin"]
    for group in OPTIONAL_GROUPS:
        g = copy.deepcopy(full[group])
        g.pop("required", None)
        g["description"] = g.get("description", "") + " Only the fields that differ from their defaults."
        props[group] = g
    required = ["leafview", "omega"] if version == "required" else ["omega"]
    return {"type": "object", "properties": props, "required": required, "additionalProperties": False}


def compact_schema() -> dict[str, Any]:
    """The JSON Schema of the compact form (one leaf, or a leaf set): see
    :mod:`leafview.core.compact`."""

    return {
        "$schema": DIALECT,
        "$id": f"urn:leafview:schema:leaf-compact:{COMPACT_VERSION}",
        "title": "leafview compact leaf",
        "description": ("One parametric leaf in the compact form: Ω as one list (Chaurasia & Beardsley 2017, eqs 3-4) and only the "
                        "settings that differ from their defaults (the defaults are the 'default' values in "
                        "leaf.schema.json); or a leaf set {\"leafview\": 1, \"leaves\": [...]}. Numbers are "
                        "the shortest decimals that read back to the same float64."),
        "oneOf": [{"$ref": "#/$defs/leafDocument"}, {"$ref": "#/$defs/leafSet"}],
        "$defs": {
            "omega": _omega_schema(),
            "leafDocument": compact_leaf_schema("required"),
            "leaf": compact_leaf_schema("absent"),
            "leafSet": {"type": "object",
                        "properties": {"leafview": {"const": COMPACT_VERSION},
                                       "leaves": {"type": "array", "minItems": 1, "items": {"$ref": "#/$defs/leaf"}}},
                        "required": ["leafview", "leaves"], "additionalProperties": False},
        },
    }
