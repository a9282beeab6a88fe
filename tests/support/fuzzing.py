"""Hypothesis strategies and run helpers for the fuzz tests (``tests/fuzz/``, issue 14 §2).

What is generated:

* **documents** of every input kind leafview reads: full presets, compact leaves, leaf sets,
  scene recipes, multilobed leaves and landmark leaves. Each starts valid (the built-in files,
  random values inside each field's range, or an instance of the published JSON Schema drawn by
  hypothesis-jsonschema) and is then mutated zero or more times: wrong types, NaN/Inf, huge and
  tiny numbers, 5,000-digit integers, nesting 10..10⁵ deep, unknown and missing keys, edge-case
  strings (path separators, NUL, 300-byte and 10⁵-character names, lone surrogates), shortened
  and lengthened lists;
* **files** from those documents: TOML or JSON text (sometimes the wrong suffix), then sometimes
  byte mutations (truncation, bytes that are not UTF-8, UTF-16, a BOM, NUL bytes, garbage), or a
  special file in its place (FIFO, directory, dangling or looping link, a link to /dev/null);
* **argument lists** for every sub-command (:mod:`tests.fuzz.test_cli` builds them).

Names and paths that would point outside the sandbox are confined: leaf names climb at most one
folder (``../escaped``, which the sandbox sees) and absolute names point into the sandbox's
``trap/`` folder (the placeholder ``@TRAP@``), so a failing run never writes elsewhere on the
machine.

The profiles (``LEAFVIEW_FUZZ_PROFILE``): ``ci`` (the default: derandomized, the budgets of
:func:`budget`), ``long`` (random seeds, the long budgets: see docs/reliability.md) and ``dev``
(a twentieth of ``ci``, for a quick look).
"""

from __future__ import annotations

import atexit
import collections
import contextlib
import copy
import functools
import io
import json
import math
import os
import re
import shutil
import signal
import sys
import tempfile
import time
import tomllib
import traceback
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir
from hypothesis.errors import HypothesisSideeffectWarning

from leafview.botany.catalogue import landmark_leaf
from leafview.botany.shapes import shape_names
from leafview.cli import main as cli_main
from leafview.core import compact
from leafview.core.params import LeafParams, field_specs
from leafview.resources import asset_dir

# Hypothesis keeps its Unicode table (and patches of failing examples) in a storage folder: not in
# the working tree. hypothesis-jsonschema builds that table on import, which Hypothesis flags when
# it happens while conftest files load, as here; it is a one-off cost.
set_hypothesis_home_dir(Path(tempfile.gettempdir()) / "leafview-hypothesis")
with warnings.catch_warnings():
    warnings.simplefilter("ignore", HypothesisSideeffectWarning)
    from hypothesis_jsonschema import from_schema

__all__ = ["PROFILE", "COUNTS", "budget", "tally", "Sandbox", "sandbox", "InputFile", "input_files",
           "documents", "to_compact", "CliRun", "run_main", "deadline", "Hang", "NAMES", "HOSTILE_NAMES",
           "CATALOGUE", "PRESETS", "LOBED", "safe_tail", "shared_sandbox", "SECRET", "ESCAPING_PRESETS",
           "BUDGETS", "schema_docs", "schema_instances", "seed_mutants", "SEED_TEXTS", "any_input"]

# -- profiles and budgets ---------------------------------------------------------------------------
PROFILE = os.environ.get("LEAFVIEW_FUZZ_PROFILE", "ci")
_COMMON: dict[str, Any] = {"deadline": None, "database": None, "print_blob": True,
                           "suppress_health_check": list(HealthCheck)}
settings.register_profile("ci", derandomize=True, **_COMMON)
settings.register_profile("long", derandomize=False, **_COMMON)
settings.register_profile("dev", derandomize=False, **_COMMON)
if PROFILE not in ("ci", "long", "dev"):
    raise RuntimeError(f"LEAFVIEW_FUZZ_PROFILE={PROFILE!r}: use ci, long or dev")

LONG_SCALE = float(os.environ.get("LEAFVIEW_FUZZ_LONG_SCALE", "1"))   # tools/fuzz_long.py sizes its rounds
COUNTS: collections.Counter[str] = collections.Counter()   # examples run, per property
BUDGETS: dict[str, tuple[int, int]] = {}                     # property -> (ci, long) max_examples


def budget(name: str, ci: int, long: int | None = None, *, shrink: bool = True) -> settings:
    """The settings of property ``name``: ``ci`` examples in the ci profile, ``long`` (default:
    ``ci``) in the long one, ``ci // 20`` in dev. ``shrink=False`` skips shrinking (for properties
    whose failing examples may hang: each shrink step would wait for the time-out again)."""
    BUDGETS[name] = (ci, ci if long is None else long)
    scaled = max(1, round((ci if long is None else long) * LONG_SCALE))
    n = {"ci": ci, "long": scaled, "dev": max(2, ci // 20)}[PROFILE]
    phases = tuple(Phase) if shrink else tuple(p for p in Phase if p != Phase.shrink)
    return settings(settings.get_profile(PROFILE), max_examples=n, phases=phases)


def tally(name: str) -> None:
    """Count one example of property ``name`` (reported at the end of the session)."""
    COUNTS[name] += 1


# -- time-outs ------------------------------------------------------------------------------------
class Hang(BaseException):
    """Raised by :func:`deadline` in the main thread when a call runs past its time."""


@contextlib.contextmanager
def deadline(seconds: float) -> Iterator[None]:
    """Raise :class:`Hang` if the block runs longer than ``seconds`` (SIGALRM; main thread only;
    a blocking ``open()`` of a FIFO is interrupted too)."""
    def expire(signum: int, frame: Any) -> None:
        raise Hang(f"no answer in {seconds:g} s")

    old = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


# -- seed documents -------------------------------------------------------------------------------
ASSETS = asset_dir()
SCHEMA_DIR = ASSETS / "schema"


def _toml(path: Path) -> dict[str, Any]:
    return tomllib.loads(path.read_text(encoding="utf-8"))


PRESETS = sorted(p.stem for p in (ASSETS / "presets").glob("*.toml"))
LOBED = sorted(p.stem for p in (ASSETS / "compound").glob("*.toml"))
CATALOGUE = shape_names()
FULL_SEEDS = [_toml(p) for p in sorted((ASSETS / "presets").glob("*.toml"))] + \
             [_toml(p) for p in sorted((ASSETS / "shapes").glob("*.toml"))]
LOBED_SEEDS = [_toml(p) for p in sorted((ASSETS / "compound").glob("*.toml"))]
LANDMARK_SEEDS = [_toml(p) for p in sorted((ASSETS / "landmarks").glob("*.toml"))] + \
                 [landmark_leaf(n).to_dict() for n in CATALOGUE[::6]]
SPECS = {k: v for k, v in field_specs().items() if not k.startswith("shape.")}


def _draft7(node: Any) -> Any:
    """A published draft 2020-12 schema in the draft-07 terms hypothesis-jsonschema reads
    (``prefixItems`` → ``items`` as a list)."""
    if isinstance(node, dict):
        out = {k: _draft7(v) for k, v in node.items() if k not in ("$schema", "$id")}
        if "prefixItems" in out:
            prefix = out.pop("prefixItems")
            if "items" in out:
                out["additionalItems"] = out.pop("items")
            out["items"] = prefix
        return out
    if isinstance(node, list):
        return [_draft7(v) for v in node]
    return node


def _schema(name: str, ref: str | None = None) -> dict[str, Any]:
    doc = _draft7(json.loads((SCHEMA_DIR / name).read_text(encoding="utf-8")))
    doc["$schema"] = "http://json-schema.org/draft-07/schema#"
    if ref:
        doc = {"$schema": doc["$schema"], "$defs": doc["$defs"], "$ref": f"#/$defs/{ref}"}
    return doc


@functools.cache
def _from_schema(name: str, ref: str | None = None, prop: str | None = None) -> st.SearchStrategy[Any]:
    """Instances of a published schema (of its ``$defs`` entry ``ref``, or of its top-level
    property ``prop``) drawn by hypothesis-jsonschema: thorough but slow (tens to hundreds of
    milliseconds a draw), so only :func:`schema_instances` uses it."""
    schema = _schema(name, ref)
    if prop:
        schema = {"$schema": schema["$schema"], **schema["properties"][prop]}
    return from_schema(schema)


def _merge(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


class _Schema:
    """A fast translation of the published schemas into strategies: the keywords they use
    (``$ref``, ``type``, ``properties``, ``required``, ``items``/``prefixItems``, ``min/maxItems``,
    bounds, ``const``, ``enum``, ``anyOf``/``oneOf`` merged into their parent; ``not`` is
    ignored). Optional properties appear in half of the draws."""

    def __init__(self, root: dict[str, Any]) -> None:
        self.root = root

    def resolve(self, node: dict[str, Any]) -> dict[str, Any]:
        while "$ref" in node:
            target: Any = self.root
            for part in node["$ref"].lstrip("#/").split("/"):
                target = target[part]
            node = _merge({k: v for k, v in node.items() if k != "$ref"}, target)
        return node

    def strategy(self, node: Any) -> st.SearchStrategy[Any]:
        if not isinstance(node, dict):
            return st.none()
        node = self.resolve(node)
        for key in ("anyOf", "oneOf"):
            if key in node:
                base = {k: v for k, v in node.items() if k != key}
                return st.one_of(*[self.strategy(_merge(base, self.resolve(alt))) for alt in node[key]])
        if "const" in node:
            return st.just(node["const"])
        if "enum" in node:
            return st.sampled_from(node["enum"])
        kind = node.get("type")
        if isinstance(kind, list):
            return st.one_of(*[self.strategy({**node, "type": k}) for k in kind])
        if kind == "object" or "properties" in node:
            return self._object(node)
        if kind == "array":
            return self._array(node)
        if kind == "integer":
            lo, hi = node.get("minimum", -1000), node.get("maximum", 1000)
            return st.integers(int(lo), int(hi))
        if kind == "number":
            lo = node.get("minimum", node.get("exclusiveMinimum", -1e3))
            hi = node.get("maximum", node.get("exclusiveMaximum", 1e3))
            return st.floats(lo, hi, allow_nan=False, allow_infinity=False,
                             exclude_min="exclusiveMinimum" in node and "minimum" not in node,
                             exclude_max="exclusiveMaximum" in node and "maximum" not in node)
        if kind == "string":
            return st.text(min_size=node.get("minLength", 0), max_size=max(node.get("minLength", 0), 12))
        if kind == "boolean":
            return st.booleans()
        return st.one_of(st.integers(), st.text(max_size=4), st.booleans())

    def _object(self, node: dict[str, Any]) -> st.SearchStrategy[Any]:
        props = node.get("properties", {})
        required = set(node.get("required", ()))
        fields = {k: self.strategy(v) for k, v in props.items()}

        @st.composite
        def build(draw: Any) -> dict[str, Any]:
            return {k: draw(s) for k, s in fields.items() if k in required or draw(st.booleans())}
        return build()

    def _array(self, node: dict[str, Any]) -> st.SearchStrategy[Any]:
        prefix = node.get("prefixItems")
        if prefix is None and isinstance(node.get("items"), list):
            prefix = node["items"]
        if prefix is not None:
            return st.tuples(*[self.strategy(p) for p in prefix]).map(list)
        item = self.strategy(node.get("items", {}))
        lo = node.get("minItems", 0)
        return st.lists(item, min_size=lo, max_size=node.get("maxItems", lo + 4))


@functools.cache
def schema_docs(name: str, ref: str | None = None) -> st.SearchStrategy[Any]:
    """Instances of a published schema (``$defs`` entry ``ref``), by the fast translation."""
    raw = json.loads((SCHEMA_DIR / name).read_text(encoding="utf-8"))
    node = {"$ref": f"#/$defs/{ref}"} if ref else raw
    return _Schema(raw).strategy(node)


@st.composite
def _leaf_with_schema_group(draw: Any) -> dict[str, Any]:
    doc = copy.deepcopy(draw(st.sampled_from(FULL_SEEDS)))
    group = draw(st.sampled_from(["shape", "jitter", "material", "transform", "ripple", "bending"]))
    doc[group] = draw(_from_schema("leaf.schema.json", None, group))
    return doc


def schema_instances(kind: str) -> st.SearchStrategy[Any]:
    """Documents of ``kind`` (preset, compact, set, scene) in which one group is an instance of
    its published JSON Schema as hypothesis-jsonschema draws it (a group at a time: a whole
    document takes seconds a draw): a built-in leaf with a schema-drawn ``shape``, ``jitter``,
    ``material``, ``transform``, ``ripple`` or ``bending``; a scene with schema-drawn ``scene``
    settings and ``plant`` (counts then capped so that it stays small)."""
    if kind == "preset":
        return _leaf_with_schema_group()
    if kind == "compact":
        return _leaf_with_schema_group().map(to_compact)
    if kind == "set":
        return st.lists(_leaf_with_schema_group().map(lambda d: to_compact(d, version=False)),
                        min_size=1, max_size=3).map(lambda leaves: {"leafview": 1, "leaves": leaves})
    return st.builds(lambda settings_, plant: _small_scene({"schema": 1, "scene": settings_, "plant": plant,
                                                            "species": [{"preset": "ovate"}]}),
                     _from_schema("scene.schema.json", None, "scene"), _from_schema("scene.schema.json", None, "plant"))


# -- names ----------------------------------------------------------------------------------------
HOSTILE_NAMES = ["../escaped", "@TRAP@/absolute", "a/b", "a/../../escaped-b", "", ".", "..", "...", " ",
                 "-rf", "--help", "a\x00b", "line\nbreak", "tab\tname", "back\\slash", "x" * 300,
                 "é" * 150, "\u202eevil", "CON", ".hidden", "dup", "dup", "名前", "ovate", "x" * 100_000]
NAMES = st.deferred(lambda: st.one_of(
    st.sampled_from(HOSTILE_NAMES),
    st.text(st.characters(exclude_categories=("Cs",), exclude_characters="/"), max_size=24),
    st.text(st.characters(categories=("Cs",)), min_size=1, max_size=3),   # lone surrogates
))


def _confine_name(name: str) -> str:
    """Names that climb more than one folder up, or start at /, would write outside the
    sandbox when a run fails to sanitise them: map them to names the sandbox sees."""
    if name.startswith("/"):
        return "@TRAP@" + name
    if os.path.normpath(os.path.join("a/b", name)).startswith(".."):
        return "../escaped-" + str(len(name))
    return name


# -- valid-ish documents --------------------------------------------------------------------------
def _value(draw: Any, spec: Any, edge: bool) -> Any:
    lo, hi = spec.soft_range
    hard_lo, hard_hi = spec.hard_range
    if edge:
        lo = hard_lo if hard_lo is not None else lo
        hi = hard_hi if hard_hi is not None else hi
    if spec.kind == "bool":
        return draw(st.booleans())
    if spec.kind == "choice":
        return draw(st.sampled_from(spec.choices))
    if spec.kind == "edits":   # venation.edits: a few vein edits with their fields in range
        return draw(st.lists(st.fixed_dictionaries({
            "vein": st.integers(0, 12), "side": st.sampled_from([-1, 1]),
            "angle": st.floats(-30.0, 30.0), "bulge": st.floats(-0.05, 0.05)}),
            max_size=3, unique_by=lambda e: (e["vein"], e["side"])))
    if spec.kind == "int":
        return draw(st.integers(int(math.ceil(lo)), int(math.floor(hi))))
    number = st.floats(lo, hi, allow_nan=False, allow_infinity=False,
                       exclude_min=bool(spec.positive and lo <= 0.0))
    if spec.positive and lo <= 0.0:
        number = number.filter(lambda x: x > 0.0)
    if spec.kind in ("vec3", "color"):
        return draw(st.lists(number, min_size=3, max_size=3))
    if spec.kind == "pair":
        return sorted(draw(st.lists(number, min_size=2, max_size=2)))
    return draw(number)


@st.composite
def full_docs(draw: Any) -> dict[str, Any]:
    """A full preset document: a built-in or catalogue file with groups changed within each
    field's soft range (or at its hard limits), its Ω scaled a little, and maybe renamed."""
    doc = copy.deepcopy(draw(st.sampled_from(FULL_SEEDS)))
    for key in draw(st.lists(st.sampled_from(sorted(SPECS)), max_size=5, unique=True)):
        group, name = key.split(".")
        doc.setdefault(group, {})[name] = _value(draw, SPECS[key], draw(st.booleans()))
        if group in ("jitter", "ripple") and draw(st.booleans()):
            doc[group]["enabled"] = True
    if draw(st.integers(0, 3)) == 0:
        factor = draw(st.floats(0.5, 1.5))
        shape = doc["shape"]
        shape["zf"] = [x * factor for x in shape["zf"]]
        shape["silhouette"] = [[r[0], r[1] * factor, r[2]] for r in shape["silhouette"]]
    if draw(st.booleans()):
        doc["name"] = _confine_name(draw(NAMES))
    return doc


def to_compact(doc: Any, *, version: bool = True) -> Any:
    """The compact form of a full document, built without validating it (so mutated documents
    turn into mutated compact ones)."""
    if not isinstance(doc, dict) or not isinstance(doc.get("shape"), dict):
        return doc
    shape = doc["shape"]
    omega: list[Any] = []
    for key in ("a1", "a2"):
        omega += shape.get(key, []) if isinstance(shape.get(key), list) else [shape.get(key)]
    for row in shape.get("silhouette", []) if isinstance(shape.get("silhouette"), list) else []:
        omega += row if isinstance(row, list) else [row]
    for key in ("zf", "zg", "tilt"):
        if key in shape:
            omega += shape[key] if isinstance(shape[key], list) else [shape[key]]
    out: dict[str, Any] = {"leafview": 1} if version else {}
    if "name" in doc:
        out["name"] = doc["name"]
    out["omega"] = omega
    if shape.get("half"):
        out["half"] = shape["half"]
    for key, value in doc.items():
        if key not in ("schema", "name", "shape"):
            out[key] = value
    return out


@st.composite
def _transforms(draw: Any) -> dict[str, Any]:
    big = st.sampled_from([1e308, -1e308, 1e30, 1e16, 1e-300, 0.0, -0.0])
    small = st.floats(-5, 5, allow_nan=False)
    out: dict[str, Any] = {}
    if draw(st.booleans()):
        out["translation"] = draw(st.lists(st.one_of(small, big) if draw(st.booleans()) else small,
                                           min_size=3, max_size=3))
    if draw(st.booleans()):
        out["rotation"] = draw(st.lists(st.floats(-720, 720, allow_nan=False), min_size=3, max_size=3))
    if draw(st.booleans()):
        out["scale"] = draw(st.one_of(st.floats(0.05, 5), st.sampled_from([1e-300, 1e300, 1e30, 0.0, -1.0])))
    return out


@st.composite
def leaf_set_docs(draw: Any) -> dict[str, Any]:
    leaves = []
    for _ in range(draw(st.integers(1, 4))):
        leaf = to_compact(draw(full_docs()), version=False)
        if draw(st.booleans()):
            leaf["transform"] = draw(_transforms())
        leaves.append(leaf)
    return {"leafview": 1, "leaves": leaves}


SCENE_PRESETS = ["ovate", "maize", "holly", "sub/ok.toml", "../trap/secret.toml", "@TRAP@/secret.toml",
                 "missing.toml", "", "sub", "ok.toml", "sub/../sub/ok.toml", "sub/bad.toml"]
ESCAPING_PRESETS = ("../trap/secret.toml", "@TRAP@/secret.toml")


@st.composite
def scene_docs(draw: Any, *, small: bool = True) -> dict[str, Any]:
    """A scene recipe: schema-drawn settings and plant, a few species (inline full or compact
    leaves, or preset names and paths, some of which leave the scene's folder). ``small``
    bounds the leaf and plant counts so that a run takes a fraction of a second."""
    doc: dict[str, Any] = {"schema": 1}
    scene = dict(draw(_SCENE_SETTINGS) if draw(st.integers(0, 3)) == 0 else {})
    if small:
        scene["leaves"] = draw(st.integers(1, 40))
        scene.pop("plants", None)
        if draw(st.booleans()):
            scene["plants"] = draw(st.integers(0, 3))
    if draw(st.booleans()):
        scene["layout"] = draw(st.sampled_from(["plant", "field", "hedge"]))
    doc["scene"] = scene
    species = []
    for _ in range(draw(st.integers(1, 3))):
        choice = draw(st.integers(0, 3))
        if choice == 0:
            item: dict[str, Any] = {"preset": draw(st.sampled_from(SCENE_PRESETS))}
        elif choice == 1:
            full = draw(full_docs())
            full.pop("schema", None)
            item = {"leaf": full}
        else:
            item = {"leaf": to_compact(draw(full_docs()), version=choice == 3)}
        if draw(st.booleans()):
            item["weight"] = draw(st.sampled_from([1, 0.5, 3, 0, -1, 1e308]))
        species.append(item)
    doc["species"] = species
    if draw(st.booleans()):
        plant = dict(draw(_PLANT))
        if small:
            for key, cap in (("branches", 6), ("twigs", 4), ("height", 20.0)):
                if key in plant and plant[key] > cap:
                    plant[key] = cap
        doc["plant"] = plant
    return doc


_PLANT = st.deferred(lambda: schema_docs("scene.schema.json").map(lambda d: d.get("plant", {})))
_SCENE_SETTINGS = st.deferred(lambda: schema_docs("scene.schema.json").map(lambda d: d.get("scene", {})))


@st.composite
def lobed_docs(draw: Any) -> dict[str, Any]:
    doc = copy.deepcopy(draw(st.sampled_from(LOBED_SEEDS)))
    if draw(st.booleans()):
        doc["half"] = draw(st.integers(1, 12))
    if draw(st.booleans()):
        doc["shape"] = draw(st.sampled_from(CATALOGUE))
    if draw(st.integers(0, 3)) == 0:
        doc["positions"] = [[draw(st.floats(0, 1)), draw(st.floats(-170, 170)), draw(st.floats(0.05, 1.5))]
                            for _ in range(draw(st.integers(1, 8)))]
    if draw(st.booleans()):
        doc["name"] = _confine_name(draw(NAMES))
    return doc


@st.composite
def landmark_docs(draw: Any) -> dict[str, Any]:
    doc = copy.deepcopy(draw(st.sampled_from(LANDMARK_SEEDS)))
    side = doc["right"]
    for key in ("theta_b", "theta_a"):
        if draw(st.integers(0, 3)) == 0:
            side[key] = draw(st.floats(0, 180))
    if draw(st.integers(0, 3)) == 0:
        side["waist"] = [draw(st.floats(0.05, 0.95)), draw(st.floats(0.05, 1.5))]
    return doc


def _schema_docs(kind: str) -> st.SearchStrategy[Any]:
    if kind == "preset":
        return schema_docs("leaf.schema.json")
    if kind == "compact":
        return schema_docs("leaf-compact.schema.json", "leafDocument")
    if kind == "set":
        return schema_docs("leaf-compact.schema.json", "leafSet")
    return schema_docs("scene.schema.json").map(_small_scene)


def _small_scene(doc: dict[str, Any]) -> dict[str, Any]:
    scene = doc.setdefault("scene", {})
    scene["leaves"] = min(int(scene.get("leaves", 10) or 1), 40)
    scene["plants"] = min(int(scene.get("plants", 0) or 0), 3)
    for item in doc.get("species", []):
        if isinstance(item, dict) and "preset" in item:
            item["preset"] = "ovate"
    plant = doc.get("plant", {})
    for key, cap in (("branches", 6), ("twigs", 4)):
        if key in plant and plant[key] > cap:
            plant[key] = cap
    return doc


def _names_confined(doc: Any) -> Any:
    if isinstance(doc, dict):
        return {k: (_confine_name(v) if k == "name" and isinstance(v, str) else _names_confined(v))
                for k, v in doc.items()}
    if isinstance(doc, list):
        return [_names_confined(v) for v in doc]
    return doc


@functools.cache
def _base_documents(kind: str) -> st.SearchStrategy[Any]:
    return base_documents(kind)


def base_documents(kind: str) -> st.SearchStrategy[Any]:
    """Unmutated documents of ``kind``: preset, compact, set, scene, lobed, landmark."""
    made: dict[str, st.SearchStrategy[Any]] = {
        "preset": full_docs(),
        "compact": full_docs().map(to_compact),
        "set": leaf_set_docs(),
        "scene": scene_docs(),
        "lobed": lobed_docs(),
        "landmark": landmark_docs(),
    }
    if kind in ("preset", "compact", "set", "scene"):
        return st.one_of(made[kind], made[kind], made[kind], _schema_docs(kind).map(_names_confined))
    return made[kind]


# -- mutations ------------------------------------------------------------------------------------
RAW_CHOICES = [
    ("deep-list", None), ("deep-table", None), ("bigint", "9" * 5000), ("bigint", "-" + "1" * 4400),
    ("overflow", "1e400"), ("overflow", "-1e400"), ("hexint", "0x7fffffffffffffffffff"), ("underscore", "1_000"),
    ("tiny", "1e-400"),
]
WRONG_VALUES: list[Any] = ["text", "", [], {}, True, False, None, 1, 2.5, [1, 2, 3], {"a": 1}, [[]], [None],
                           ["1", "2", "3"], [0.0] * 1000, "1e3", "NaN"]
EDGE_NUMBERS: list[Any] = [math.nan, math.inf, -math.inf, 1e308, -1e308, 1e300, 1e30, -1e30, 1e16, 5e-324,
                           -0.0, 2 ** 31, 2 ** 63, 2 ** 64, -(2 ** 63) - 1, 10 ** 30, 0, -1, 1e-12]
EDGE_KEYS = ["unknown", "", " ", "SHAPE", "__proto__", "shape ", "名前", "a.b", "leafview", "schema", "x" * 300]


def _paths(doc: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [prefix]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:50]):
            out += _paths(v, (*prefix, i))
    return out


def _get(doc: Any, path: tuple[Any, ...]) -> Any:
    for key in path:
        doc = doc[key]
    return doc


def _set(doc: Any, path: tuple[Any, ...], value: Any) -> Any:
    if not path:
        return value
    _get(doc, path[:-1])[path[-1]] = value
    return doc


@st.composite
def _mutate_once(draw: Any, doc: Any, raws: dict[str, tuple[str, str]]) -> Any:
    doc = copy.deepcopy(doc)
    paths = _paths(doc)
    path = draw(st.sampled_from(paths))
    target = _get(doc, path)
    op = draw(st.sampled_from(["type", "number", "number", "raw", "key", "delete", "length", "string", "top"]))
    if op == "type":
        return _set(doc, path, copy.deepcopy(draw(st.sampled_from(WRONG_VALUES))))
    if op == "number":
        return _set(doc, path, draw(st.sampled_from(EDGE_NUMBERS)))
    if op == "raw":
        kind, text = draw(st.sampled_from(RAW_CHOICES))
        token = f"@RAW{len(raws)}@"
        if kind in ("deep-list", "deep-table"):
            depth = draw(st.sampled_from([10, 100, 500, 990, 1000, 3000, 100_000]))
            if kind == "deep-list":
                raws[token] = ("[" * depth + "1" + "]" * depth,) * 2
            else:
                raws[token] = ('{"a":' * depth + "1" + "}" * depth, "{a = " * depth + "1" + "}" * depth)
        else:
            assert text is not None
            raws[token] = (text, text)
        return _set(doc, path, token)
    if op == "key" and isinstance(target, dict):
        target[draw(st.one_of(st.sampled_from(EDGE_KEYS), st.text(max_size=10)))] = \
            draw(st.sampled_from([1, "x", [], {}, 0.5]))
        return doc
    if op == "delete" and path:
        parent = _get(doc, path[:-1])
        del parent[path[-1]]
        return doc
    if op == "length" and isinstance(target, list):
        if target and draw(st.booleans()):
            target.pop(draw(st.integers(0, len(target) - 1)))
        else:
            target.extend(copy.deepcopy(target[:1]) * draw(st.sampled_from([1, 2, 5, 1000])) or [0])
        return doc
    if op == "string":
        return _set(doc, path, _confine_name(draw(NAMES)))
    if op == "top":
        return draw(st.sampled_from([[doc], "text", 1, None, [], {}]))
    return _set(doc, path, draw(st.sampled_from(EDGE_NUMBERS)))


@st.composite
def documents(draw: Any, kind: str) -> tuple[Any, dict[str, tuple[str, str]]]:
    """(document, raw substitutions): a ``kind`` document, mutated 0-3 times (0 in about a
    third of the draws). Raw substitutions replace ``"@RAWn@"`` in the encoded text with text no
    encoder writes (10⁵-deep nesting, 5,000-digit integers, 1e400)."""
    doc = draw(_base_documents(kind))
    raws: dict[str, tuple[str, str]] = {}
    for _ in range(draw(st.sampled_from([0, 0, 1, 1, 1, 2, 3]))):
        doc = draw(_mutate_once(doc, raws))
    return doc, raws


_DOCUMENTS = {k: documents(k) for k in ("preset", "compact", "set", "scene", "lobed", "landmark")}


# -- files ----------------------------------------------------------------------------------------
class InputFile:
    """A file to put in the sandbox's ``in/`` folder: ``data`` bytes, or a ``special`` file
    (fifo, dir, dangling, loop, devnull, outside). A plain class, so that failure reports
    show its short ``repr`` rather than every byte."""

    __slots__ = ("name", "data", "special", "kind", "doc")

    def __init__(self, name: str, data: bytes = b"", special: str = "", kind: str = "", doc: Any = None) -> None:
        self.name, self.data, self.special, self.kind, self.doc = name, data, special, kind, doc

    def __repr__(self) -> str:
        body = self.special or f"{len(self.data):,} bytes {self.data[:400]!r}{'...' if len(self.data) > 400 else ''}"
        return f"InputFile({self.name!r}, {body})"


def _encode(doc: Any, raws: dict[str, tuple[str, str]], fmt: str, ascii_only: bool) -> bytes:
    text: str | None = None
    if fmt == "toml" and isinstance(doc, dict):
        with contextlib.suppress(Exception):
            text = tomli_w.dumps(doc)
    if text is None:
        fmt = "json"
        try:
            text = json.dumps(doc, allow_nan=True, ensure_ascii=ascii_only)
        except (TypeError, ValueError):   # a 5,000-digit int written by hand below
            text = json.dumps(doc, allow_nan=True, ensure_ascii=ascii_only, default=str)
    for token, (json_text, toml_text) in raws.items():
        text = text.replace(f'"{token}"', json_text if fmt == "json" else toml_text)
    return text.encode("utf-8", errors="surrogatepass")


@st.composite
def _byte_mutation(draw: Any, data: bytes) -> bytes:
    op = draw(st.sampled_from(["truncate", "invalid", "utf16", "bom", "latin1", "nul", "flip", "garbage", "empty",
                               "space", "crlf"]))
    at = draw(st.integers(0, len(data)))
    if op == "truncate":
        return data[:at]
    if op == "invalid":
        return data[:at] + draw(st.sampled_from([b"\xff", b"\xfe\xff", b"\xc3(", b"\xed\xa0\x80", b"\x80"])) + data[at:]
    if op == "utf16":
        return data.decode("utf-8", "replace").encode("utf-16")
    if op == "bom":
        return b"\xef\xbb\xbf" + data
    if op == "latin1":
        return data.decode("utf-8", "replace").replace('"', '"é', 1).encode("latin-1", "replace")
    if op == "nul":
        return data[:at] + b"\x00" + data[at:]
    if op == "flip" and data:
        i = min(at, len(data) - 1)
        return data[:i] + bytes([data[i] ^ draw(st.integers(1, 255))]) + data[i + 1:]
    if op == "garbage":
        return data + draw(st.binary(min_size=1, max_size=64))
    if op == "empty":
        return b""
    if op == "space":
        return b" \n\t\r\n"
    return data.replace(b"\n", b"\r\n")


SUFFIXES = {"preset": [".toml", ".json"], "compact": [".leaf.json", ".json"], "set": [".leaves.json", ".json"],
            "scene": [".toml", ".json"], "lobed": [".toml"], "landmark": [".toml", ".json"]}
SPECIALS = ["fifo", "dir", "dangling", "loop", "devnull", "outside"]


@functools.cache
def input_files(kind: str, *, specials: bool = True, stem: str = "input") -> st.SearchStrategy[InputFile]:
    """A file of ``kind`` as a user (or an attacker) might hand it to leafview."""
    return _input_files(kind, specials=specials, stem=stem)


@st.composite
def _input_files(draw: Any, kind: str, *, specials: bool, stem: str) -> InputFile:
    suffix = draw(st.sampled_from(SUFFIXES[kind]))
    if draw(st.integers(0, 40)) == 0:
        suffix = draw(st.sampled_from([".txt", "", ".TOML", ".JSON", ".yaml", ".toml.json"]))
    name = stem + suffix
    if specials and draw(st.integers(0, 60)) == 0:
        return InputFile(name, special=draw(st.sampled_from(SPECIALS)), kind=kind)
    doc, raws = draw(_DOCUMENTS[kind])
    fmt = "toml" if suffix.lower().endswith(".toml") else "json"
    if draw(st.integers(0, 20)) == 0:
        fmt = "json" if fmt == "toml" else "toml"
    data = _encode(doc, raws, fmt, draw(st.booleans()))
    if draw(st.integers(0, 7)) == 0:
        data = draw(_byte_mutation(data))
    return InputFile(name, data, kind=kind, doc=doc)


# -- mutants of the seed files (cheap: a few draws an example) ----------------------------------------
def _seed_texts() -> dict[str, list[tuple[str, bytes]]]:
    full = list(FULL_SEEDS)
    leaves = [LeafParams.from_dict(d) for d in full]
    entries = [compact.compact_dict(leaf, version=False) for leaf in leaves[:18]]
    for i, e in enumerate(entries):
        e["transform"] = {"translation": [0.3 * i, 0.1 * i, 0.0], "rotation": [0.0, 5.0 * i, 10.0], "scale": 1 + i / 10}
    sets = [{"leafview": 1, "leaves": entries[i:i + 3]} for i in range(0, len(entries), 3)]
    maize = {k: v for k, v in full[PRESETS.index("maize")].items() if k != "schema"}
    scenes = [{"schema": 1, "scene": {"layout": "plant", "leaves": 30, "seed": 3}, "species": [{"preset": "ovate"}]},
              {"schema": 1, "scene": {"layout": "field", "leaves": 20, "plants": 2, "variation": 0.3},
               "species": [{"leaf": entries[0], "weight": 2}, {"preset": "sub/ok.toml"}],
               "plant": {"phyllotaxis": "whorled", "whorl": 4, "branches": 3}},
              {"schema": 1, "scene": {"layout": "hedge", "leaves": 15, "stems": False}, "species": [{"leaf": maize}]}]

    def both(docs: list[Any], toml_suffix: str, json_suffix: str) -> list[tuple[str, bytes]]:
        return [(toml_suffix, tomli_w.dumps(d).encode()) for d in docs] + \
               [(json_suffix, json.dumps(d).encode()) for d in docs]
    return {"preset": both(full, ".toml", ".json"),
            "compact": [(".leaf.json", compact.dumps(leaf).encode()) for leaf in leaves],
            "set": [(".leaves.json", compact.dumps_leaves(leaves[i:i + 3]).encode()) for i in range(0, 18, 3)]
            + [(".leaves.json", json.dumps(d).encode()) for d in sets],
            "scene": both(scenes, ".toml", ".json"),
            "lobed": [(".toml", tomli_w.dumps(d).encode()) for d in LOBED_SEEDS],
            "landmark": both(LANDMARK_SEEDS, ".toml", ".json")}


SEED_TEXTS = _seed_texts()
_NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
TOKENS = [b"nan", b"inf", b"-inf", b"NaN", b"Infinity", b"1e400", b"-1e400", b"1e308", b"9" * 5000, b"-0", b"0x10",
          b"1_0", b'"x"', b"true", b"[]", b"{}", b"null", b"[1, 2]", b"1e-400", b"18446744073709551616",
          b"[" * 1000 + b"1" + b"]" * 1000, b"[" * 100_000 + b"]" * 100_000, b'"' + b"x" * 300 + b'"']


@st.composite
def _token_mutation(draw: Any, data: bytes) -> bytes:
    op = draw(st.integers(0, 9))
    if op <= 3:                                  # a number becomes something else
        spans = [m.span() for m in _NUMBER.finditer(data)]
        if spans:
            a, b = spans[draw(st.integers(0, len(spans) - 1))]
            return data[:a] + draw(st.sampled_from(TOKENS)) + data[b:]
    lines = data.split(b"\n")
    if op == 4 and len(lines) > 1:              # a line goes
        del lines[draw(st.integers(0, len(lines) - 1))]
        return b"\n".join(lines)
    if op == 5 and lines:                       # a line doubles
        i = draw(st.integers(0, len(lines) - 1))
        return b"\n".join(lines[:i + 1] + lines[i:])
    if op == 6:                                 # a key is renamed
        keys = [m.span() for m in re.finditer(rb"[A-Za-z_]+", data)]
        if keys:
            a, b = keys[draw(st.integers(0, len(keys) - 1))]
            return data[:a] + draw(st.sampled_from([b"X", b"", b"schema", b"leafview", b"omega", b"SECRET_x"])) + data[b:]
    return draw(_byte_mutation(data))


@functools.cache
def any_input(kind: str) -> st.SearchStrategy[InputFile]:
    """A structured document file or a seed mutant of ``kind`` (no special files): what the
    command-line properties hand to a command."""
    return st.one_of(input_files(kind, specials=False), seed_mutants(kind))


@functools.cache
def seed_mutants(kind: str) -> st.SearchStrategy[InputFile]:
    """A built-in or seed file of ``kind`` with one to three token or byte mutations."""
    return _seed_mutants(kind)


@st.composite
def _seed_mutants(draw: Any, kind: str) -> InputFile:
    suffix, data = draw(st.sampled_from(SEED_TEXTS[kind]))
    for _ in range(draw(st.integers(1, 3))):
        data = draw(_token_mutation(data))
    return InputFile("input" + suffix, data, kind=kind)


# -- the sandbox ----------------------------------------------------------------------------------
SECRET = "SECRET_d41d8cd98f"
_BASE: list[Path] = []


def _base() -> Path:
    if not _BASE:
        shm = "/dev/shm" if os.access("/dev/shm", os.W_OK) else None   # a tmpfs: file churn is cheap there
        root = Path(tempfile.mkdtemp(prefix="leafview-fuzz-", dir=shm))
        atexit.register(shutil.rmtree, root, ignore_errors=True)
        _BASE.append(root)
    return _BASE[0]


@dataclass
class Sandbox:
    """A folder ``root`` with ``in/`` (inputs, ``in/sub/ok.toml``: a preset a scene may name),
    ``out/`` (the only place a run may write) and ``trap/`` (``secret.toml``: a file no input may
    reach)."""

    root: Path
    made: list[Path] = field(default_factory=list)

    @property
    def trap(self) -> Path:
        return self.root / "trap"

    def put(self, item: InputFile, folder: str = "in") -> Path:
        """Write ``item`` (placeholders ``@TRAP@`` resolved) and return its path."""
        path = self.root / folder / item.name
        path.parent.mkdir(parents=True, exist_ok=True)
        special = item.special
        if special == "fifo":
            os.mkfifo(path)
        elif special == "dir":
            path.mkdir()
        elif special == "dangling":
            path.symlink_to(self.trap / "missing.toml")
        elif special == "loop":
            path.symlink_to(path.name)
        elif special == "devnull":
            path.symlink_to("/dev/null")
        elif special == "outside":
            path.symlink_to(self.trap / "secret.toml")
        else:
            path.write_bytes(item.data.replace(b"@TRAP@", str(self.trap).encode()))
        self.made.append(path)
        return path

    def clean(self) -> None:
        """Remove what :meth:`put` made and whatever a run wrote to ``out/`` (a reused sandbox)."""
        for path in self.made:
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)
        self.made.clear()
        out = self.root / "out"
        if not out.is_dir() or any(os.scandir(out)):
            shutil.rmtree(out, ignore_errors=True)
            out.mkdir()

    def state(self) -> list[tuple[str, str, int, int]]:
        """A cheap fingerprint of the sandbox's folders (names, sizes, mtimes; not recursive):
        enough to see that a loader wrote nothing."""
        out = []
        for folder in ("", "in", "in/sub", "out", "trap"):
            with contextlib.suppress(OSError), os.scandir(self.root / folder) as it:
                for e in it:
                    st_ = e.stat(follow_symlinks=False)
                    out.append((folder, e.name, st_.st_size, st_.st_mtime_ns))
        return sorted(out)


def _fill(root: Path) -> None:
    for folder in ("in/sub", "out", "trap"):
        (root / folder).mkdir(parents=True)
    ovate = (ASSETS / "presets" / "ovate.toml").read_text(encoding="utf-8")
    (root / "in/sub/ok.toml").write_text(ovate, encoding="utf-8")
    (root / "in/sub/bad.toml").write_text(ovate + f"\n{SECRET}_BAD = 1\n", encoding="utf-8")
    (root / "trap/secret.toml").write_text(f"{SECRET} = 1\n" + ovate, encoding="utf-8")


@contextlib.contextmanager
def sandbox() -> Iterator[Sandbox]:
    """A fresh :class:`Sandbox`, removed afterwards."""
    root = Path(tempfile.mkdtemp(prefix="sb-", dir=_base()))
    try:
        _fill(root)
        yield Sandbox(root)
    finally:
        shutil.rmtree(root, ignore_errors=True)


_SHARED: list[Sandbox] = []


def shared_sandbox() -> Sandbox:
    """One :class:`Sandbox` for the whole session (parse-level properties: faster than a new
    folder per example; :meth:`Sandbox.clean` after each)."""
    if not _SHARED:
        root = Path(tempfile.mkdtemp(prefix="shared-", dir=_base()))
        _fill(root)
        _SHARED.append(Sandbox(root))
    return _SHARED[0]


# -- running the command in this process ----------------------------------------------------------
@dataclass
class CliRun:
    """One in-process ``leafview`` run: exit code (None for an escaped exception or a hang)."""

    argv: list[str]
    code: int | None
    stdout: str
    stderr: str
    error: str = ""                 # the traceback of an exception that escaped main()
    hung: bool = False
    seconds: float = 0.0
    warnings: list[str] = field(default_factory=list)

    def describe(self) -> str:
        err = self.stderr.strip().splitlines()
        return (f"leafview {' '.join(safe_tail(a, 80) for a in self.argv)} -> exit {self.code}"
                f"{' (hang)' if self.hung else ''}; stderr: {' | '.join(s[:200] for s in err[-3:]) or '-'}"
                f"{chr(10) + self.error[-3000:] if self.error else ''}")


def safe_tail(text: str, n: int) -> str:
    text = repr(text)[1:-1]
    return text if len(text) <= n else text[: n // 2] + "…" + text[-n // 2:]


def run_main(argv: Sequence[str], cwd: Path, *, timeout: float = 60.0,
             main: Callable[[list[str]], int] | None = None) -> CliRun:
    """``leafview.cli.main(argv)`` in ``cwd`` with stdout/stderr as a terminal-less process has
    them (UTF-8; stdout strict, stderr backslashreplace), warnings recorded, a time-out."""
    main = main or cli_main
    out_b, err_b = io.BytesIO(), io.BytesIO()
    out = io.TextIOWrapper(out_b, encoding="utf-8", errors="strict", write_through=True)
    err = io.TextIOWrapper(err_b, encoding="utf-8", errors="backslashreplace", write_through=True)
    saved = sys.stdout, sys.stderr, os.getcwd()
    run = CliRun(list(argv), None, "", "")
    started = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        sys.stdout, sys.stderr = out, err
        os.chdir(cwd)
        try:
            with deadline(timeout):
                run.code = main(list(argv))
        except SystemExit as exc:
            if exc.code is None or isinstance(exc.code, int):
                run.code = exc.code or 0
            else:
                print(exc.code, file=err)
                run.code = 1
        except Hang:
            run.hung = True
        except BaseException:   # whatever escapes main() is the finding
            run.error = traceback.format_exc()
        finally:
            with contextlib.suppress(Exception):
                out.flush()
                err.flush()
            sys.stdout, sys.stderr = saved[0], saved[1]
            os.chdir(saved[2])
        run.warnings = [f"{w.category.__name__}: {w.message}" for w in caught]
    run.seconds = time.perf_counter() - started
    run.stdout = out_b.getvalue().decode("utf-8", "replace")
    run.stderr = err_b.getvalue().decode("utf-8", "replace")
    return run
