"""LeafParams: Ω order, validation with field paths, TOML/JSON round trips."""

import dataclasses
import json
import math
import re

import numpy as np
import pytest

from leafview.core.lobes import Lobes
from leafview.core.params import (
    OMEGA_SIZE,
    SCHEMA_VERSION,
    Jitter,
    LeafParams,
    ParamError,
    Venation,
    field_specs,
    parse_params,
)
from tests.conftest import random_params


def test_vector_order_is_the_papers():
    omega = np.arange(1, 22) / 100.0
    omega[6], omega[9], omega[12] = 0.2, 0.5, 0.8  # v̄ strictly increasing
    p = LeafParams.from_vector(omega)
    s = p.shape
    assert s.a1 == tuple(omega[0:3]) and s.a2 == tuple(omega[3:6])
    assert s.silhouette == (tuple(omega[6:9]), tuple(omega[9:12]), tuple(omega[12:15]))
    assert s.zf == tuple(omega[15:18]) and s.zg == tuple(omega[18:21])
    np.testing.assert_array_equal(p.to_vector(), omega)
    assert p.to_vector().shape == (OMEGA_SIZE,)


def test_from_vector_leaves_jitter_off_and_defaults():
    p = LeafParams.from_vector(LeafParams().to_vector())
    assert p.jitter.enabled is False
    assert p == LeafParams()


@pytest.mark.parametrize("bad", [np.zeros(20), np.zeros((3, 7)), np.zeros(22)])
def test_from_vector_rejects_wrong_length(bad):
    with pytest.raises(ParamError, match="omega"):
        LeafParams.from_vector(bad)


def test_from_vector_rejects_non_finite():
    omega = LeafParams().to_vector()
    omega[4] = np.nan
    with pytest.raises(ParamError, match=r"shape\.a2\[1\].*NaN"):
        LeafParams.from_vector(omega)


def _doc(**shape_changes):
    d = LeafParams().to_dict()
    d["shape"].update(shape_changes)
    return d


@pytest.mark.parametrize("mutate, path, words", [
    (lambda d: d["shape"].update(a1=[0, "x", 0]), r"shape\.a1\[1\]", "expected a number"),
    (lambda d: d["shape"].update(a1=[0, True, 0]), r"shape\.a1\[1\]", "expected a number"),
    (lambda d: d["shape"].update(a1=[0, 0.3]), r"shape\.a1", "expected 3 numbers"),
    (lambda d: d["shape"].update(zf=[0, math.nan, 0]), r"shape\.zf\[1\]", "NaN"),
    (lambda d: d["shape"].update(zg=[0, 0, -math.inf]), r"shape\.zg\[2\]", "Inf"),
    (lambda d: d["shape"].update(extra=1), r"shape\.extra", "unknown key"),
    (lambda d: d.update(colour=1), r"colour", "unknown key"),
    (lambda d: d["shape"].pop("zg"), r"shape\.zg", "missing field"),
    (lambda d: d.pop("shape"), r"shape", "missing"),
    (lambda d: d.pop("schema"), r"schema", "missing"),
    (lambda d: d.update(schema=99), r"schema", "unsupported schema version 99"),
    (lambda d: d["shape"]["silhouette"][1].__setitem__(0, 0.1), r"shape\.silhouette\[1\]\[0\]", "increasing"),
    (lambda d: d["shape"]["silhouette"][0].__setitem__(0, 0.0), r"shape\.silhouette\[0\]\[0\]", r"inside \(0, 1\)"),
    (lambda d: d["shape"]["silhouette"][2].__setitem__(0, 1.0), r"shape\.silhouette\[2\]\[0\]", r"inside \(0, 1\)"),
    (lambda d: d["jitter"].update(seed=1.5), r"jitter\.seed", "integer"),
    (lambda d: d["jitter"].update(enabled=1), r"jitter\.enabled", "true or false"),
    (lambda d: d["jitter"].update(amplitude=-0.1), r"jitter\.amplitude", "below the minimum"),
    (lambda d: d["material"].update(front=[0.1, 2.0, 0.1]), r"material\.front\[1\]", "above the maximum"),
    (lambda d: d["transform"].update(scale=0), r"transform\.scale", "below the minimum"),
    (lambda d: d.update(name=3), r"name", "string"),
])
def test_validation_names_the_field(mutate, path, words):
    d = LeafParams().to_dict()
    mutate(d)
    with pytest.raises(ParamError, match=path) as info:
        parse_params(d)
    assert re.search(words, str(info.value)), str(info.value)
    assert re.fullmatch(path + r".*", info.value.path), info.value.path


def test_messages_show_plain_numbers():
    d = LeafParams().to_dict()
    d["shape"]["silhouette"][1][0] = 0.1
    with pytest.raises(ParamError) as info:
        parse_params(d)
    assert "np." not in str(info.value) and "0.25 then 0.1" in str(info.value)


def test_empty_document():
    with pytest.raises(ParamError, match="empty"):
        parse_params({})


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_file_round_trip_is_exact(tmp_path, suffix):
    rng = np.random.default_rng(11)
    for i in range(10):
        p = random_params(rng, jitter=bool(i % 2)).replace(name=f"leaf{i}")
        path = tmp_path / f"leaf{i}{suffix}"
        p.save(path)
        q = LeafParams.load(path)
        assert q == p
        np.testing.assert_array_equal(q.to_vector(), p.to_vector())


def test_saved_toml_carries_schema_version(tmp_path):
    LeafParams().save(tmp_path / "a.toml")
    assert f"schema = {SCHEMA_VERSION}" in (tmp_path / "a.toml").read_text()


def test_load_names_file_and_line_for_syntax_errors(tmp_path):
    f = tmp_path / "broken.toml"
    f.write_text("schema = 1\n[shape]\na1 = [0, 0.3,\n")
    with pytest.raises(ParamError) as info:
        LeafParams.load(f)
    assert f"{f}:" in str(info.value) and "syntax" in str(info.value)
    g = tmp_path / "broken.json"
    g.write_text('{"schema": 1,\n "shape": {,}}')
    with pytest.raises(ParamError, match=r"broken\.json:2:\d+: JSON syntax error"):
        LeafParams.load(g)


def test_load_names_file_and_field(tmp_path):
    d = LeafParams().to_dict()
    d["shape"]["a2"][0] = "wide"
    f = tmp_path / "typed.json"
    f.write_text(json.dumps(d))
    with pytest.raises(ParamError, match=r"typed\.json: shape\.a2\[0\]: expected a number"):
        LeafParams.load(f)


def test_load_missing_and_empty_and_unknown_format(tmp_path):
    with pytest.raises(ParamError, match="no such file"):
        LeafParams.load(tmp_path / "nope.toml")
    (tmp_path / "empty.toml").write_text("  \n")
    with pytest.raises(ParamError, match="empty file"):
        LeafParams.load(tmp_path / "empty.toml")
    with pytest.raises(ParamError, match="unknown preset format"):
        LeafParams.load(tmp_path / "leaf.yaml")


def test_failed_save_leaves_no_file(tmp_path):
    with pytest.raises(ParamError):
        LeafParams().save(tmp_path / "leaf.txt")
    assert list(tmp_path.iterdir()) == []


def test_field_specs_cover_every_field_with_sane_ranges():
    specs = field_specs()
    d = LeafParams().to_dict()
    expected = {f"{g}.{k}" for g in ("shape", "jitter", "material", "transform", "ripple", "bending") for k in d[g]}
    # the venation group is left out of a default leaf's file (leafview.core.venation): its fields
    expected |= {f"venation.{f.name}" for f in dataclasses.fields(Venation)}
    expected |= {f"lobes.{f.name}" for f in dataclasses.fields(Lobes)}   # the same for lobed leaves
    assert set(specs) == expected
    for path, spec in specs.items():
        assert spec.soft_range[0] < spec.soft_range[1], path
        assert spec.step > 0, path
        assert spec.label and spec.group, path


def test_jitter_defaults_are_valid_and_off():
    assert Jitter().enabled is False
    parse_params({**LeafParams().to_dict(), "jitter": {"enabled": True}})


def test_transform_matrix():
    from leafview.core.params import Transform

    m = Transform(translation=(1, 2, 3), rotation=(0, 0, 90), scale=2).matrix()
    np.testing.assert_allclose(m @ [1, 0, 0, 1], [1, 4, 3, 1], atol=1e-12)


def test_a_row_where_the_axis_has_no_direction_is_refused():
    """Found by the long fuzz run: a1 = a0 makes A'(v̄) = 3 v̄² ĵ, which is 0 in float64 at
    v̄ = 5e-324; the normal of eq. 2 was then 0/0, the blade NaN and the bend solve raised a bare
    ValueError. Validation now names the row."""
    from leafview.core.compact import parse_compact
    from leafview.deform.beam import bend_profile
    from leafview.deform.surface import evaluate

    omega = [0.0] * 6 + [5e-324, 0.0, 0.0, 0.25, 0.0, 0.0, 0.5, 0.0, 0.0] + [0.0] * 6
    doc = {"leafview": 1, "omega": omega, "bending": {"load": 1.0, "petiole_length": 1.0}}
    with pytest.raises(ParamError, match=r"omega\[6\].*no in-plane direction"):
        parse_compact(doc)
    # near the cusp but with a direction: accepted, and the blade and its bend are finite
    ok = parse_compact({**doc, "omega": [0.0] * 6 + [0.01, 0.2, 0.0, 0.25, 0.3, 0.0, 0.5, 0.2, 0.0] + [0.0] * 6})
    assert np.all(np.isfinite(evaluate(ok, np.linspace(-1, 1, 9), np.linspace(0, 1, 9))))
    assert np.all(np.isfinite(bend_profile(ok).delta))
