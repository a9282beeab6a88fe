"""Every parser and loader on generated and mutated input (issue 14 §2, parse level).

The property: a loader returns, or raises a :class:`~leafview.errors.LeafviewError` whose
message is one line, at most ``MAX_ERROR_LINE`` characters, naming the file. Nothing else
escapes (no RecursionError, MemoryError, ValueError, UnicodeDecodeError...), nothing hangs
(a FIFO is refused, not waited on), nothing is written, and a file read through a scene never
comes from outside the scene's folder nor shows up in an error. What a loader accepts must
survive what comes next: the numpy bake (bending and ripples included), the expansion of a
small scene, the placement of lobes, a landmark outline.
"""

from __future__ import annotations

import json
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from support.fuzzing import (
    ESCAPING_PRESETS,
    SECRET,
    Hang,
    InputFile,
    base_documents,
    budget,
    deadline,
    documents,
    input_files,
    schema_instances,
    seed_mutants,
    shared_sandbox,
    tally,
)
from support.promise import MAX_ERROR_LINE

from leafview.botany.catalogue import load_landmark_leaf
from leafview.botany.landmarks import LandmarkLeaf, outline
from leafview.botany.lobes import load_lobed_leaf, lobed_from_dict
from leafview.core import compact
from leafview.core.io import load_leaves
from leafview.core.params import LeafParams, parse_params
from leafview.errors import LeafviewError
from leafview.export.mesh import bake
from leafview.gpu.morph import load_morph_leaf
from leafview.scene.spec import SceneSpec, build_scene, load_scene

PARSE_TIMEOUT = 10.0    # seconds; a parse takes milliseconds
DEEPER_LEAVES = 4       # leaves of a set baked after loading


def _bake_all(leaves: list[LeafParams]) -> None:
    for leaf in leaves[:DEEPER_LEAVES]:
        bake(leaf, (3, 5), backend="numpy")


def _scene_deeper(spec: SceneSpec) -> None:
    if spec.leaves <= 200 and spec.plants <= 10:
        scene = build_scene(spec)
        if not np.isfinite(scene.matrices).all():
            raise AssertionError("a validated scene expanded into non-finite leaf matrices")


def _lobes_deeper(leaf: Any) -> None:
    for lobe in leaf.lobes():
        if not np.isfinite(np.asarray([v for v in vars(lobe).values() if isinstance(v, float)])).all():
            raise AssertionError(f"a validated multilobed leaf placed a lobe at non-finite values: {lobe}")


def _landmark_deeper(leaf: LandmarkLeaf) -> None:
    if not np.isfinite(outline(leaf, 32)).all():
        raise AssertionError("a validated landmark leaf has a non-finite outline")


# kind -> (the loader a command uses, what is done next with what it returns)
LOADERS: dict[str, tuple[Callable[[Path], Any], Callable[[Any], None]]] = {
    "preset": (load_leaves, _bake_all),
    "compact": (load_leaves, _bake_all),
    "set": (load_leaves, _bake_all),
    "scene": (load_scene, _scene_deeper),
    "lobed": (load_lobed_leaf, _lobes_deeper),
    "landmark": (load_landmark_leaf, _landmark_deeper),
}


def _walk_presets(doc: Any) -> list[str]:
    if isinstance(doc, dict):
        found = [v for k, v in doc.items() if k == "preset" and isinstance(v, str)]
        return found + [p for v in doc.values() for p in _walk_presets(v)]
    if isinstance(doc, list):
        return [p for v in doc for p in _walk_presets(v)]
    return []


def message_problems(message: str, names: tuple[str, ...], *, secret: bool) -> list[str]:
    """What a LeafviewError's message breaks: one line, bounded, naming one of ``names``, and
    (``secret``) not repeating the content of a file that an input named."""
    problems = []
    if "\n" in message.strip():
        problems.append(f"a {message.count(chr(10)) + 1}-line message: {message[:300]!r}")
    if len(message) > MAX_ERROR_LINE:
        problems.append(f"a message of {len(message):,} characters")
    if names and not any(n in message for n in names):
        problems.append(f"the message names none of {names}: {message[:300]!r}")
    if secret and SECRET in message:
        problems.append(f"the message repeats another file's content: {message[:300]!r}")
    return problems


def check_load(kind: str, item: InputFile, load: Callable[[Path], Any] | None = None) -> None:
    """The parse-level property for one file of ``kind``."""
    loader, deeper = LOADERS[kind]
    load = load or loader
    sb = shared_sandbox()
    try:
        path = sb.put(item)
        before = sb.state()
        problems: list[str] = []
        result = None
        try:
            with deadline(PARSE_TIMEOUT):
                result = load(path)
        except Hang as exc:
            problems.append(f"hang: {exc}")
        except LeafviewError as exc:
            problems += message_problems(str(exc), (path.name,),
                                         secret=kind == "scene" and item.special != "outside")
        except BaseException:   # whatever else escapes is the finding
            problems.append("an exception that is not a LeafviewError:\n" + traceback.format_exc(limit=-6))
        if result is not None:
            if kind == "scene" and item.special != "outside" \
                    and any(p in ESCAPING_PRESETS or p.startswith("@TRAP@") for p in _walk_presets(item.doc)):
                problems.append("a scene read a species preset outside its folder")
            try:
                with deadline(PARSE_TIMEOUT * 3):
                    deeper(result)
            except Hang as exc:
                problems.append(f"accepted, then a hang in what comes next: {exc}")
            except LeafviewError:
                pass
            except BaseException:
                problems.append("accepted by validation, then failed deeper:\n" + traceback.format_exc(limit=-6))
        if sb.state() != before:
            changed = sorted(set(sb.state()) ^ set(before))
            problems.append(f"a loader changed the sandbox: {changed[:4]}")
        assert not problems, f"{kind} file {item!r}:\n" + "\n".join(problems)
    finally:
        sb.clean()


# -- files ------------------------------------------------------------------------------------------
@budget("parse.preset", ci=500, long=20_000)
@given(item=input_files("preset"))
def test_preset_files(item: InputFile) -> None:
    tally("parse.preset")
    check_load("preset", item)


@budget("parse.compact", ci=500, long=20_000)
@given(item=input_files("compact"))
def test_compact_files(item: InputFile) -> None:
    tally("parse.compact")
    check_load("compact", item)


@budget("parse.leaf_set", ci=400, long=6_000)
@given(item=input_files("set"))
def test_leaf_set_files(item: InputFile) -> None:
    tally("parse.leaf_set")
    check_load("set", item)


@budget("parse.scene", ci=400, long=6_000)
@given(item=input_files("scene"))
def test_scene_files(item: InputFile) -> None:
    tally("parse.scene")
    check_load("scene", item)


@budget("parse.lobed", ci=700, long=30_000)
@given(item=input_files("lobed"))
def test_lobed_files(item: InputFile) -> None:
    tally("parse.lobed")
    check_load("lobed", item)


@budget("parse.landmark", ci=700, long=6_000)
@given(item=input_files("landmark"))
def test_landmark_files(item: InputFile) -> None:
    tally("parse.landmark")
    check_load("landmark", item, load=lambda p: load_morph_leaf(str(p), "A"))


KINDS = ["preset", "compact", "set", "scene", "lobed", "landmark"]


@budget("parse.seed_mutants", ci=1_500, long=50_000)
@given(item=st.sampled_from(KINDS).flatmap(seed_mutants))
def test_seed_mutants(item: InputFile) -> None:
    """The built-in files of every kind with one to three token or byte mutations (a number
    becomes NaN, 1e400, a 5,000-digit integer, 10⁵-deep brackets, a string, a list; a line goes
    or doubles; a key is renamed; bytes are cut, flipped or made invalid UTF-8): the cheapest
    property, so most of the long run's examples."""
    tally("parse.seed_mutants")
    check_load(item.kind, item)


@budget("parse.schema_instances", ci=60, long=1_000)
@given(kind_doc=st.sampled_from(["preset", "compact", "set", "scene"]).flatmap(
    lambda k: st.tuples(st.just(k), schema_instances(k))))
def test_schema_instances(kind_doc: tuple[str, Any]) -> None:
    """Documents with groups drawn from the published JSON Schemas by hypothesis-jsonschema
    (slow: tens of milliseconds a draw), written as JSON: accepted, or refused in one line."""
    tally("parse.schema_instances")
    kind, doc = kind_doc
    name = {"compact": "input.leaf.json", "set": "input.leaves.json"}.get(kind, "input.json")
    check_load(kind, InputFile(name, json.dumps(doc).encode(), kind=kind, doc=doc))


@budget("parse.bytes", ci=3_000, long=820_000)
@given(kind=st.sampled_from(KINDS), data=st.binary(max_size=2048), suffix=st.sampled_from([".toml", ".json"]))
def test_random_bytes(kind: str, data: bytes, suffix: str) -> None:
    """Any bytes at all, under any loader."""
    tally("parse.bytes")
    name = {"compact": "input.leaf.json", "set": "input.leaves.json"}.get(kind, "input" + suffix)
    check_load(kind, InputFile(name, data, kind=kind))


# -- documents already parsed (the Python API) ------------------------------------------------------
def _parse_set(doc: Any) -> Any:
    return compact.parse_leaves(doc)


DICT_PARSERS: dict[str, Callable[[Any], Any]] = {
    "preset": parse_params,
    "compact": compact.parse_compact,
    "set": _parse_set,
    "scene": SceneSpec.from_dict,
    "lobed": lobed_from_dict,
    "landmark": LandmarkLeaf.from_dict,
}


@budget("parse.dict", ci=800, long=6_000)
@given(kind_doc=st.sampled_from(KINDS).flatmap(lambda k: st.tuples(st.just(k), documents(k))))
def test_dict_parsers(kind_doc: tuple[str, tuple[Any, Any]]) -> None:
    """``parse_params``, ``parse_compact``, ``parse_leaves``, ``SceneSpec.from_dict``,
    ``lobed_from_dict`` and ``LandmarkLeaf.from_dict`` on mutated documents (raw text
    substitutions stay as the placeholder strings they are): a value or a ParamError with a
    one-line, bounded message."""
    tally("parse.dict")
    kind, (doc, _) = kind_doc
    try:
        with deadline(PARSE_TIMEOUT):
            DICT_PARSERS[kind](doc)
    except LeafviewError as exc:
        problems = message_problems(str(exc), (), secret=False)
        assert not problems, f"{kind} {doc!r:.2000}: " + "; ".join(problems)


@budget("parse.compact_text", ci=1_000, long=40_000)
@given(doc=base_documents("compact"), cut=st.integers(0, 400), extra=st.text(max_size=8))
def test_compact_loads(doc: Any, cut: int, extra: str) -> None:
    """``compact.loads(text)`` on compact text, truncated and with text appended."""
    tally("parse.compact_text")
    text = compact.dumps(LeafParams()) if not isinstance(doc, dict) else _json_text(doc)
    for candidate in (text, text[:cut], text + extra):
        try:
            with deadline(PARSE_TIMEOUT):
                compact.loads(candidate)
        except LeafviewError as exc:
            problems = message_problems(str(exc), (), secret=False)
            assert not problems, f"{candidate!r:.2000}: " + "; ".join(problems)


def _json_text(doc: Any) -> str:
    return json.dumps(doc, allow_nan=True)
