"""The published schemas of the compact leaf form and of scene files: equal to the generated ones;
they accept what leafview writes, and reject what the loaders reject."""

from __future__ import annotations

import copy
import json

import jsonschema
import numpy as np
import pytest

from leafview.core import compact as C
from leafview.core.params import LeafParams, ParamError, Transform
from leafview.resources import builtin_presets
from leafview.scene.schema import SCHEMAS, main, published_path, schema_text
from leafview.scene.spec import SceneSpec
from tests.conftest import random_params
from tests.test_schema import _DELETE, _set


def _validator(name: str) -> jsonschema.Draft202012Validator:
    schema = json.loads(published_path(name).read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


@pytest.fixture(scope="module")
def compact_v():
    return _validator("leaf-compact.schema.json")


@pytest.fixture(scope="module")
def scene_v():
    return _validator("scene.schema.json")


def _errors(validator, doc) -> list[str]:
    return [e.message for e in validator.iter_errors(json.loads(json.dumps(doc)))]


def test_published_files_equal_the_generated_schemas(capsys):
    for name in SCHEMAS:
        assert published_path(name).read_text(encoding="utf-8") == schema_text(name), \
            f"assets/schema/{name} is stale: run python -m leafview.scene.schema --write"
    assert main(["--check"]) == 0
    assert "scene.schema.json is up to date" in capsys.readouterr().out


def _extended() -> list[LeafParams]:
    from tests.test_compact import _extended as ext

    return ext()


def test_compact_schema_accepts_what_leafview_writes(compact_v):
    leaves = [LeafParams.load(p) for p in builtin_presets().values()] + _extended()
    rng = np.random.default_rng(3)
    leaves += [random_params(rng, jitter=True) for _ in range(20)]
    for leaf in leaves:
        assert _errors(compact_v, json.loads(C.dumps(leaf))) == [], leaf.name
        assert _errors(compact_v, json.loads(C.dumps(leaf, digits=4))) == [], leaf.name
    assert _errors(compact_v, json.loads(C.dumps_leaves(leaves))) == []


def _doc() -> dict:
    return json.loads(C.dumps(LeafParams.load(builtin_presets()["maize"])))


def _with(path: tuple, value) -> dict:
    return _set(_doc(), path, value)


BAD_COMPACT = [
    (("leafview",), 2), (("leafview",), _DELETE), (("omega",), _DELETE), (("omega",), [0.1] * 22),
    (("omega", 6), 0.0), (("omega", 6), 1.0), (("omega", 7), "0.1"), (("half",), 2), (("half",), 0.5),
    (("name",), 1), (("shape",), {}), (("schema",), 1), (("jitter",), {"seed": -1}),
    (("jitter",), {"teeth": 3}), (("material",), {"front": [0, 0, 2]}), (("ripple", "veins"), 0),
    (("bending", "load"), -1), (("bending",), {"direction": [0, 0, 0]}), (("transform",), {"scale": 0}),
    (("leaves",), []),
]


@pytest.mark.parametrize("path, value", BAD_COMPACT,
                         ids=[".".join(map(str, p)) + ("=del" if v is _DELETE else f"={v!r}"[:20]) for p, v in BAD_COMPACT])
def test_compact_schema_and_loader_reject_the_same_documents(compact_v, path, value):
    doc = _with(path, value)
    assert _errors(compact_v, doc), "the schema accepted it"
    with pytest.raises(ParamError):
        C.parse_compact(doc)


def test_extended_omega_tilt_bounds_in_both(compact_v):
    leaf = _extended()[-1]
    doc = json.loads(C.dumps(leaf))
    assert _errors(compact_v, doc) == []
    doc["omega"][-1] = 95.0
    assert _errors(compact_v, doc)
    with pytest.raises(ParamError, match="tilt"):
        C.parse_compact(doc)


def test_bad_leaf_set_entries_are_rejected_by_both(compact_v):
    good = json.loads(C.dumps_leaves([LeafParams(), LeafParams().replace(transform=Transform(scale=2.0))]))
    assert _errors(compact_v, good) == []
    for change in ({"leafview": 1}, {"omega": [0.0] * 21}, {"extra": 1}):
        doc = copy.deepcopy(good)
        doc["leaves"][1].update(change)
        assert _errors(compact_v, doc), change
        with pytest.raises(ParamError):
            C.parse_leaves(doc)


def _scene() -> SceneSpec:
    presets = builtin_presets()
    return SceneSpec(species=(LeafParams.load(presets["beech"]), LeafParams.load(presets["maize"])),
                     weights=(2.0, 1.0), layout="plant", leaves=800, seed=4,
                     plant={"phyllotaxis": "whorled", "whorl": 4, "light": [0.0, 0.0, 1.0], "twigs": 3})


def test_scene_schema_accepts_saved_scenes_and_old_full_tables(scene_v):
    spec = _scene()
    assert _errors(scene_v, spec.to_dict()) == []
    assert _errors(scene_v, SceneSpec(species=(LeafParams(),)).to_dict()) == []
    old = spec.to_dict()
    full = LeafParams.load(builtin_presets()["beech"]).to_dict()
    del full["schema"], full["transform"]
    old["species"][0]["leaf"] = full
    assert _errors(scene_v, old) == []
    assert SceneSpec.from_dict(old).species[0] == spec.species[0]
    preset = {"schema": 1, "species": [{"preset": "ovate", "weight": 3}]}
    assert _errors(scene_v, preset) == []
    SceneSpec.from_dict(preset)


BAD_SCENE = [
    ("schema", 2), ("scene.leaves", 0), ("scene.layout", "forest"), ("scene.variation", 0.7),
    ("scene.stems", "yes"), ("scene.zoom", 1), ("species", []), ("species.0.weight", 0),
    ("species.0.weight", "2"), ("species.0.preset", "ovate"), ("species.0.leaf.omega.6", 1.5),
    ("species.0.leaf.jitter", {"seed": -2}), ("plant.whorl", 20), ("plant.phyllotaxis", "spiral"),
    ("plant.light", [0, 0, 0]), ("plant.colour", 1), ("plant.crown_base", 0.99), ("trees", {}),
]


@pytest.mark.parametrize("path, value", BAD_SCENE, ids=[f"{p}={v!r}"[:30] for p, v in BAD_SCENE])
def test_scene_schema_and_loader_reject_the_same_documents(scene_v, path, value):
    doc = json.loads(json.dumps(_scene().to_dict()))
    keys = [int(k) if k.isdigit() else k for k in path.split(".")]
    node = doc
    for key in keys[:-1]:
        node = node[key]
    node[keys[-1]] = value
    assert _errors(scene_v, doc), "the schema accepted it"
    with pytest.raises(ParamError):
        SceneSpec.from_dict(doc)
