"""The published JSON Schema of the leaf file: equal to the generated one, accepts every preset
and what the loader accepts, rejects what the loader rejects; load(save(x)) == x exactly."""

from __future__ import annotations

import copy
import json
import tomllib

import jsonschema
import numpy as np
import pytest

from leafview.core.params import LeafParams, ParamError, parse_params
from leafview.core.schema import leaf_schema
from leafview.resources import builtin_presets
from leafview.scene.schema import main, published_path, schema_text
from tests.conftest import random_params


@pytest.fixture(scope="module")
def validator() -> jsonschema.Draft202012Validator:
    schema = json.loads(published_path().read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def test_published_file_equals_generated_schema():
    assert published_path().read_text(encoding="utf-8") == schema_text(), \
        "assets/schema/leaf.schema.json is stale: run python -m leafview.scene.schema --write"
    assert main(["--check"]) == 0


def test_every_builtin_preset_validates(validator):
    for name, path in builtin_presets().items():
        raw = tomllib.loads(path.read_text(encoding="utf-8"))           # the file as written
        assert list(validator.iter_errors(json.loads(json.dumps(raw)))) == [], name
        full = LeafParams.load(path).to_dict()                           # every field spelled out
        assert list(validator.iter_errors(json.loads(json.dumps(full)))) == [], name


def test_random_parameters_validate_and_round_trip_exactly(validator, tmp_path):
    rng = np.random.default_rng(11)
    for i in range(20):
        params = random_params(rng, jitter=bool(i % 2)).replace(name=f"r{i}")
        assert list(validator.iter_errors(json.loads(json.dumps(params.to_dict())))) == []
        for suffix in (".json", ".toml"):
            path = tmp_path / f"r{i}{suffix}"
            params.save(path)
            assert LeafParams.load(path) == params                       # bit-exact floats


def _doc() -> dict:
    return json.loads(json.dumps(LeafParams.load(builtin_presets()["beech"]).to_dict()))


def _set(doc: dict, path: tuple, value) -> dict:
    doc = copy.deepcopy(doc)
    node = doc
    for key in path[:-1]:
        node = node[key]
    if value is _DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return doc


_DELETE = object()
BAD = [
    (("schema",), 2),
    (("schema",), _DELETE),
    (("shape",), _DELETE),
    (("shape", "a1"), _DELETE),
    (("shape", "a1"), [0.0, 0.3]),
    (("shape", "a1"), [0.0, "0.3", 0.0]),
    (("shape", "silhouette"), [[0.2, 0.3, 0.0], [0.5, 0.3, 0.0]]),
    (("shape", "silhouette", 0, 0), 0.0),
    (("shape", "silhouette", 2, 0), 1.0),
    (("shape", "silhouette", 1), [0.5, 0.3]),
    (("shape", "zf"), [0.0, 0.0]),
    (("shape", "colour"), 1),
    (("jitter", "amplitude"), 1.5),
    (("jitter", "seed"), -1),
    (("jitter", "enabled"), 1),
    (("material", "front"), [0.1, 0.2, 1.2]),
    (("material", "translucency"), -0.1),
    (("ripple", "beta"), 0.0),
    (("ripple", "amplitude"), [0.1]),
    (("bending", "direction"), [0, 0, 0]),
    (("bending", "stiffness"), 0),
    (("transform", "scale"), 0.0),
    (("name",), 5),
    (("name",), "x" * 257),                          # the limits of leafview.core.limits and the
    (("name",), "nul\u0000"),                       # physical ranges of the field specs
    (("shape", "zf"), [11.0, 0.0, 0.0]),
    (("shape", "a2"), [0.0, -1e300, 0.0]),
    (("shape", "silhouette", 1, 1), 1e9),
    (("transform", "translation"), [1e308, 0.0, 0.0]),
    (("transform", "scale"), 1e7),
    (("bending", "stiffness"), 1e-9),
    (("ripple", "phase"), [0.0, 1e5]),
    (("extra",), {}),
]


@pytest.mark.parametrize("path, value", BAD, ids=[".".join(map(str, p)) + ("=del" if v is _DELETE else "")
                                                  for p, v in BAD])
def test_schema_and_loader_reject_the_same_bad_documents(validator, path, value):
    doc = _set(_doc(), path, value)
    assert list(validator.iter_errors(doc)), "the schema accepted it"
    with pytest.raises(ParamError):
        parse_params(doc)


def test_optional_groups_and_fields_are_optional_in_both(validator):
    doc = _doc()
    for group in ("jitter", "material", "transform", "ripple", "bending", "name"):
        trimmed = _set(doc, (group,), _DELETE)
        assert list(validator.iter_errors(trimmed)) == []
        parse_params(trimmed)
    trimmed = _set(doc, ("jitter", "density"), _DELETE)
    assert list(validator.iter_errors(trimmed)) == []
    parse_params(trimmed)


def test_schema_follows_the_field_specs():
    from leafview.core.params import field_specs

    schema = leaf_schema()
    specs = field_specs()
    listed = {f"{g}.{k}" for g, s in schema["properties"].items() if "properties" in s for k in s["properties"]}
    # the texture table holds file paths and the margin table curve points, not numbers with
    # ranges the panels edit: they have no field specs
    assert listed == set(specs) | {"texture.front", "texture.back", "margin.right", "margin.left"}
    amp = schema["properties"]["jitter"]["properties"]["amplitude"]
    assert (amp["minimum"], amp["maximum"]) == specs["jitter.amplitude"].hard_range
    assert amp["title"] == specs["jitter.amplitude"].label
