"""The venation parameter group (leafview.core.venation): defaults that leave older files
unchanged, round trips through TOML, JSON, the compact form and the JSON Schemas, and errors
that name the field (``venation.angle``, ``venation.edits[1].angle``)."""

from __future__ import annotations

import json
import tomllib
from dataclasses import fields, replace
from pathlib import Path

import jsonschema
import pytest

from leafview.core import compact as C
from leafview.core.io import dumps_toml
from leafview.core.params import LeafParams, ParamError, VeinEdit, Venation, field_specs, parse_params
from leafview.core.schema import compact_schema, leaf_schema
from leafview.core.venation import MAX_EDITS, PATTERNS
from leafview.resources import builtin_presets

EDITED = Venation(enabled=True, pattern="palmate", seed=7, secondaries=6, angle=42.5, loop=0.6, primaries=3,
                  tertiary=12.0, edits=(VeinEdit(2, -1, 7.5, 0.01), VeinEdit(0, 1, -3.0, 0.0)))


@pytest.fixture(scope="module")
def leaf_validator() -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(leaf_schema())


@pytest.fixture(scope="module")
def compact_validator() -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(compact_schema())


def _doc(**venation: object) -> dict:
    return {**LeafParams().to_dict(), "venation": venation}


def test_default_is_off_and_a_leaf_without_veins_writes_no_table():
    p = LeafParams()
    assert p.venation == Venation() and p.venation.enabled is False and p.venation.edits == ()
    assert "venation" not in p.to_dict()
    assert "venation" not in dumps_toml(p)
    assert "venation" not in C.dumps(p)
    # a file without the table reads as the default
    assert parse_params({k: v for k, v in p.to_dict().items()}).venation == Venation()


def test_field_specs_cover_the_group_with_ranges_inside_the_hard_ranges():
    specs = {k: v for k, v in field_specs().items() if k.startswith("venation.")}
    assert set(specs) == {f"venation.{f.name}" for f in fields(Venation)}
    for path, spec in specs.items():
        assert spec.label and spec.group == "venation" and spec.step > 0, path
        lo, hi = spec.hard_range
        if spec.kind in ("float", "int"):
            assert (lo is None or lo <= spec.soft_range[0]) and (hi is None or spec.soft_range[1] <= hi), path
    assert specs["venation.pattern"].kind == "choice" and specs["venation.pattern"].choices == PATTERNS
    assert specs["venation.edits"].kind == "edits"


@pytest.mark.parametrize("suffix", [".toml", ".json", ".leaf.json"])
def test_round_trip_through_files(tmp_path: Path, suffix: str):
    p = LeafParams.load(builtin_presets()["ovate"]).replace(venation=EDITED, name="v")
    path = tmp_path / f"v{suffix}"
    p.save(path)
    assert LeafParams.load(path) == p


def test_toml_has_the_table_and_its_edits():
    p = LeafParams(venation=EDITED)
    data = tomllib.loads(dumps_toml(p))
    assert data["venation"]["pattern"] == "palmate"
    assert data["venation"]["edits"] == [{"vein": 2, "side": -1, "angle": 7.5, "bulge": 0.01},
                                         {"vein": 0, "side": 1, "angle": -3.0, "bulge": 0.0}]
    assert parse_params(data) == p
    # [[venation.edits]] array-of-tables syntax reads the same
    text = dumps_toml(LeafParams(venation=replace(EDITED, edits=()))).replace("edits = []\n", "") + (
        "\n[[venation.edits]]\nvein = 2\nside = -1\nangle = 7.5\nbulge = 0.01\n"
        "\n[[venation.edits]]\nvein = 0\nside = 1\nangle = -3.0\n")
    assert parse_params(tomllib.loads(text)) == p


def test_compact_form_keeps_only_what_differs():
    p = LeafParams(venation=Venation(enabled=True, angle=30.0))
    doc = C.compact_dict(p)
    assert doc["venation"] == {"enabled": True, "angle": 30}
    assert C.loads(C.dumps(p)) == p
    q = LeafParams(venation=EDITED)
    assert C.loads(C.dumps(q)) == q
    assert C.round_params(q, 3).venation.edits[0].bulge == 0.01


def test_presets_validate_against_both_schemas(leaf_validator, compact_validator):
    for name, path in builtin_presets().items():
        p = LeafParams.load(path)
        assert p.venation.enabled or p.lobes.enabled, name   # lobed leaves are swept, their venation off
        leaf_validator.validate(json.loads(json.dumps(p.to_dict())))
        compact_validator.validate(json.loads(C.dumps(p)))
    leaf_validator.validate(json.loads(json.dumps(LeafParams(venation=EDITED).to_dict())))
    compact_validator.validate(json.loads(C.dumps(LeafParams(venation=EDITED))))


@pytest.mark.parametrize(("venation", "path", "text"), [
    ({"pattern": "reticulate"}, "venation.pattern", "not one of pinnate, palmate, parallel"),
    ({"pattern": 1}, "venation.pattern", "expected one of"),
    ({"angle": 95.0}, "venation.angle", "above the maximum 88.0"),
    ({"angle": float("nan")}, "venation.angle", "NaN"),
    ({"secondaries": 0}, "venation.secondaries", "below the minimum"),
    ({"secondaries": 3.5}, "venation.secondaries", "integer"),
    ({"loop": 0.99}, "venation.loop", "above the maximum"),
    ({"midrib_width": 0.0}, "venation.midrib_width", "greater than 0"),
    ({"enabled": 1}, "venation.enabled", "true or false"),
    ({"colour": 1}, "venation.colour", "unknown key"),
    ({"edits": {"vein": 1}}, "venation.edits", "list of edit tables"),
    ({"edits": [{"vein": 1, "side": 1}, 3]}, "venation.edits[1]", "expected a table"),
    ({"edits": [{"vein": 1}]}, "venation.edits[0].side", "missing field"),
    ({"edits": [{"side": 1}]}, "venation.edits[0].vein", "missing field"),
    ({"edits": [{"vein": 1, "side": 0}]}, "venation.edits[0].side", "not a side"),
    ({"edits": [{"vein": 1, "side": 2}]}, "venation.edits[0].side", "above the maximum"),
    ({"edits": [{"vein": 1, "side": 1}, {"vein": 2, "side": -1, "angle": 100.0}]}, "venation.edits[1].angle",
     "above the maximum 90.0"),
    ({"edits": [{"vein": 1, "side": 1, "bulge": "big"}]}, "venation.edits[0].bulge", "expected a number"),
    ({"edits": [{"vein": 1, "side": 1, "hinge": 3.0}]}, "venation.edits[0].hinge", "unknown key"),
    ({"edits": [{"vein": 1, "side": 1}, {"vein": 1, "side": 1}]}, "venation.edits[1]", "already edited"),
    ({"edits": [{"vein": i, "side": 1} for i in range(MAX_EDITS + 1)]}, "venation.edits", "at most"),
])
def test_bad_values_name_the_field(venation, path, text, leaf_validator):
    doc = _doc(**venation)
    with pytest.raises(ParamError) as err:
        parse_params(doc)
    assert err.value.path == path and text in err.value.message
    # the schema refuses them too (except what it cannot say: NaN, 3.5 as an integer, duplicates)
    if path not in ("venation.angle", "venation.secondaries", "venation.edits[1]") or "maximum" in text \
            or "minimum" in text:
        assert not leaf_validator.is_valid(json.loads(json.dumps(doc)))


def test_compact_errors_name_the_field_too():
    doc = json.loads(C.dumps(LeafParams(venation=Venation(enabled=True))))
    doc["venation"]["edits"] = [{"vein": 0, "side": 1, "angle": -91}]
    with pytest.raises(ParamError) as err:
        C.parse_compact(doc)
    assert err.value.path == "venation.edits[0].angle"


@pytest.mark.parametrize("edit, field", [(VeinEdit(99, -1, 5.0, 0.0), "venation.edits[0].vein"),
                                         (VeinEdit(0, 1, 20.0, 0.0), "venation.edits[0].angle")])
@pytest.mark.parametrize("command", [["export", "-o", "out.glb", "--backend", "numpy"], ["render", "-o", "out.png"]])
def test_a_bad_vein_edit_names_the_file_and_writes_nothing(command, edit, field, tmp_path, monkeypatch, capsys):
    """A vein edit is only checkable against the vein tree and the solved blade, after parsing: the
    command line checks it before drawing, and the refusal names the input file as well as the
    field (a missing vein; a turn that folds the blade)."""
    from leafview.cli import main
    monkeypatch.chdir(tmp_path)
    leaf = LeafParams.load(builtin_presets()["acuminate"])
    leaf = replace(leaf, venation=replace(leaf.venation, enabled=True, edits=(edit,)))
    Path("in.toml").write_text(dumps_toml(leaf))
    assert main([command[0], "in.toml", *command[1:]]) == 2
    err = capsys.readouterr().err
    assert "in.toml" in err and field in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.toml"]
