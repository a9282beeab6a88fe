"""The compact parametric form (leafview.core.compact): exact round trips over presets, catalogue
shapes, extended and one-sided leaves and random parameters; sizes; rounding; errors that name
the Ω entry; leaf sets; compact species in scene files; Transform.from_matrix; the CLI."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from leafview.cli import main
from leafview.core import compact as C
from leafview.core.io import load_leaves, save_leaves
from leafview.core.params import Bending, Jitter, LeafParams, ParamError, Ripple, Transform, Venation
from leafview.resources import builtin_presets
from tests.conftest import random_params


def _presets() -> dict[str, LeafParams]:
    return {k: LeafParams.load(p) for k, p in builtin_presets().items()}


def _extended() -> list[LeafParams]:
    from leafview.shapes import shapes_params

    out = [shapes_params(n, polish=False) for n in ("elliptic-concave-extended", "obovate-extended-concave",
                                                    "elliptic-convex-concave")]
    base = LeafParams()
    tilted = replace(base.shape, tilt=(10.0, 0.0, -25.5))
    one_sided = replace(base.shape, half=-1)
    four_rows = replace(base.shape, silhouette=((0.2, 0.3, 0.01), (0.4, 0.45, 0.0), (0.6, 0.4, -0.02),
                                                (0.85, 0.2, 0.0)),
                        zf=(0.0, 0.01, 0.02, 0.0), zg=(0.0, -0.01, 0.0, 0.003), tilt=(5.0, 0.0, 0.0, -3.0), half=1)
    return out + [base.replace(shape=s) for s in (tilted, one_sided, four_rows)]


def test_presets_round_trip_exactly_in_memory_and_on_disk(tmp_path):
    for name, leaf in _presets().items():
        text = C.dumps(leaf)
        assert C.loads(text) == leaf, name
        path = tmp_path / f"{name}.leaf.json"
        leaf.save(path)
        assert path.read_text(encoding="utf-8") == text + "\n"
        assert LeafParams.load(path) == leaf, name


def test_catalogue_extended_and_one_sided_leaves_round_trip(tmp_path):
    for leaf in _extended():
        doc = json.loads(C.dumps(leaf))
        assert len(doc["omega"]) == leaf.to_vector().size
        assert ("half" in doc) == (leaf.shape.half != 0)
        assert C.loads(C.dumps(leaf)) == leaf
    assert any(leaf.shape.extended for leaf in _extended())


def test_random_parameters_with_every_group_round_trip_bit_for_bit():
    rng = np.random.default_rng(4)
    for i in range(200):
        leaf = random_params(rng, jitter=bool(i % 2))
        if i % 3 == 0:
            leaf = leaf.replace(ripple=Ripple(enabled=True, beta=float(rng.uniform(0.5, 3)),
                                              seed=int(rng.integers(0, 10**6)), phase=(float(rng.normal()), 1e-300)),
                                bending=Bending(load=float(rng.uniform(0, 9)), twist=-0.0,
                                                direction=(float(rng.normal()), 0.0, -1.0)),
                                transform=Transform(translation=tuple(rng.normal(size=3) * 1e7),
                                                    rotation=(1e-17, -180.0, 33.3), scale=float(rng.uniform(0.01, 9))),
                                name=f"leaf \"{i}\" é")
        back = C.loads(C.dumps(leaf))
        assert back == leaf
        assert back.to_vector().tobytes() == leaf.to_vector().tobytes()


def test_defaults_are_left_out_and_presets_are_small():
    assert json.loads(C.dumps(LeafParams())) == {"leafview": 1, "omega": [0, 1 / 3, 0, 0, 2 / 3, 0, 0.25, 0.35, 0,
                                                                         0.5, 0.4, 0, 0.75, 0.25, 0, 0, 0, 0, 0, 0, 0]}
    leaf = LeafParams().replace(jitter=Jitter(enabled=True))
    assert json.loads(C.dumps(leaf))["jitter"] == {"enabled": True}
    presets = {k: v for k, v in _presets().items() if not v.lobes.enabled}
    sizes = {k: len(C.dumps(v)) for k, v in presets.items()}
    full = {k: len(json.dumps(v.to_dict(), separators=(",", ":"))) for k, v in presets.items()}
    assert 100 <= sizes["ovate"] <= 200
    # every unilobed preset has a [venation] table (leafview.core.venation): 25-110 bytes of the compact form
    veinless = {k: len(C.dumps(v.replace(venation=Venation()))) for k, v in presets.items()}
    assert float(np.median(list(veinless.values()))) <= 200, veinless
    assert all(25 <= sizes[k] - veinless[k] <= 110 for k in sizes), (sizes, veinless)
    assert all(sizes[k] <= 0.6 * full[k] for k in sizes), (sizes, full)
    # a lobed preset is its margin's control points: about 45 bytes each (two 17-digit numbers)
    for k, v in _presets().items():
        if v.lobes.enabled:
            n = len(v.lobes.outline) + len(v.lobes.valleys)
            assert len(C.dumps(v)) <= 200 + 48 * n, (k, len(C.dumps(v)), n)
            assert len(C.dumps(v, digits=6)) <= 200 + 24 * n, (k, len(C.dumps(v, digits=6)), n)


def test_rounding_is_idempotent_and_bounded():
    rng = np.random.default_rng(9)
    for _ in range(50):
        leaf = random_params(rng, jitter=True)
        text = C.dumps(leaf, digits=6)
        once = C.loads(text)
        assert C.dumps(once, digits=6) == text                     # a rounded file is written back unchanged
        assert C.loads(C.dumps(once)) == once                      # and is exact from then on
        w, w6 = leaf.to_vector(), once.to_vector()
        assert np.all(np.abs(w6 - w) <= 5e-6 * np.abs(w) + 1e-300)
        assert len(text) < len(C.dumps(leaf))
    assert C.round_params(leaf, 6) == once
    with pytest.raises(ParamError, match="digits"):
        C.dumps(leaf, digits=0)


def _doc(**changes):
    doc = json.loads(C.dumps(LeafParams.load(builtin_presets()["beech"])))
    for key, value in changes.items():
        if value is None:
            doc.pop(key)
        else:
            doc[key] = value
    return doc


def _omega(k, value):
    doc = _doc()
    doc["omega"][k] = value
    return doc


@pytest.mark.parametrize("doc, path, words", [
    (_doc(leafview=2), "leafview", "unsupported compact format version 2"),
    (_doc(leafview=None), "leafview", "missing"),
    (_doc(omega=None), "omega", "missing"),
    (_doc(omega=[0.0] * 20), "omega", "got 20"),
    (_omega(6, 0.0), "omega[6] (shape.silhouette[0][0])", "strictly inside"),
    (_omega(12, 0.3), "omega[12] (shape.silhouette[2][0])", "strictly increasing"),
    (_omega(7, "0.3"), "omega[7]", "expected a number"),
    (_omega(16, float("nan")), "omega[16] (shape.zf[1])", "NaN"),
    (_doc(half=2), "half", "above the maximum"),
    (_doc(jitter={"seed": -1}), "jitter.seed", "below the minimum"),
    (_doc(ripple={"veinz": 3}), "ripple.veinz", "unknown key"),
    (_doc(shape={}), "shape", "unknown key"),
    (_doc(name=3), "name", "expected a string"),
])
def test_bad_documents_name_the_entry(doc, path, words):
    with pytest.raises(ParamError) as info:
        C.parse_compact(doc)
    assert info.value.path == path
    assert words in info.value.message


def test_tilt_entries_are_named_in_extended_omega():
    leaf = _extended()[-1]
    doc = json.loads(C.dumps(leaf))
    n = leaf.shape.rows
    doc["omega"][6 + 3 * n + 2 * n + 1] = 120.0          # tilt of row 1
    with pytest.raises(ParamError) as info:
        C.parse_compact(doc)
    assert info.value.path == f"omega[{6 + 5 * n + 1}] (shape.tilt[1])"


def test_bad_file_names_the_file_and_writes_nothing(tmp_path):
    path = tmp_path / "bad.leaf.json"
    path.write_text(json.dumps(_omega(6, 1.5)), encoding="utf-8")
    with pytest.raises(ParamError) as info:
        LeafParams.load(path)
    assert str(path) in str(info.value) and "omega[6]" in str(info.value)
    out = tmp_path / "out.leaf.json"
    assert main(["export", str(path), "-o", str(out)]) == 2
    assert not out.exists()


def test_leaf_sets_round_trip_and_name_the_leaf(tmp_path):
    leaves = list(_presets().values())[:5] + [leaf.replace(name=f"x{i}") for i, leaf in enumerate(_extended())]
    path = tmp_path / "many.leaves.json"
    save_leaves(leaves, path)
    assert load_leaves(path) == leaves
    doc = json.loads(path.read_text(encoding="utf-8"))
    doc["leaves"][3]["omega"][9] = -1.0
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(ParamError) as info:
        load_leaves(path)
    assert info.value.path == "leaves[3].omega[9] (shape.silhouette[1][0])"
    with pytest.raises(ParamError, match="leaf set of"):
        LeafParams.load(path)
    unnamed = tmp_path / "plain.leaves.json"
    save_leaves([leaves[0].replace(name=""), leaves[1].replace(name="")], unnamed)
    assert [leaf.name for leaf in load_leaves(unnamed)] == ["plain-0", "plain-1"]


def test_transform_from_matrix_inverts_matrix():
    rng = np.random.default_rng(2)
    for _ in range(500):
        t = Transform(translation=tuple(rng.uniform(-9, 9, 3)), rotation=tuple(rng.uniform(-180, 180, 3)),
                      scale=float(rng.uniform(0.05, 5)))
        back = Transform.from_matrix(t.matrix())
        assert np.abs(back.matrix() - t.matrix()).max() < 1e-12
    for rot in ((10.0, 90.0, 30.0), (10.0, -90.0, 30.0)):        # gimbal lock
        m = Transform(rotation=rot).matrix()
        assert np.abs(Transform.from_matrix(m).matrix() - m).max() < 1e-12
    with pytest.raises(ParamError, match="uniform scale"):
        Transform.from_matrix(np.diag([1.0, 2.0, 1.0, 1.0]))
    with pytest.raises(ParamError, match="mirror"):
        Transform.from_matrix(np.diag([-1.0, 1.0, 1.0, 1.0]))


def test_scene_species_are_written_compact_and_old_tables_still_load(tmp_path):
    from leafview.scene.spec import SceneSpec, load_scene, save_scene

    presets = _presets()
    spec = SceneSpec(species=(presets["beech"].replace(transform=Transform()), presets["maize"]
                              .replace(transform=Transform())), weights=(2.0, 1.0), leaves=500)
    for suffix in (".json", ".toml"):
        path = tmp_path / f"s{suffix}"
        save_scene(spec, path)
        assert load_scene(path) == spec
    doc = json.loads((tmp_path / "s.json").read_text(encoding="utf-8"))
    assert "omega" in doc["species"][0]["leaf"]
    full = presets["beech"].to_dict()
    del full["schema"]
    doc["species"][0]["leaf"] = full
    (tmp_path / "old.json").write_text(json.dumps(doc), encoding="utf-8")
    assert load_scene(tmp_path / "old.json").species[0] == presets["beech"]
    doc["species"][1]["leaf"]["omega"][6] = 2.0
    (tmp_path / "bad.json").write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(ParamError) as info:
        load_scene(tmp_path / "bad.json")
    assert "species[1].leaf.omega[6] (shape.silhouette[0][0])" in str(info.value)
    doc["species"][1]["leaf"]["omega"][6] = 0.2
    doc["species"][1]["weight"] = "2"
    (tmp_path / "bad.json").write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(ParamError, match=r"species\[1\]\.weight"):
        load_scene(tmp_path / "bad.json")


def test_cli_writes_compact_files_and_a_scene_as_a_placed_leaf_set(tmp_path, capsys):
    out = tmp_path / "ovate.leaf.json"
    assert main(["export", "ovate", "-o", str(out)]) == 0
    assert LeafParams.load(out) == LeafParams.load(builtin_presets()["ovate"])
    assert "153 bytes" in capsys.readouterr().out or len(out.read_bytes()) < 200
    assert main(["export", "ovate", "maize", "-o", str(tmp_path / "two.leaf.json")]) == 2
    assert main(["export", "ovate", "-o", str(tmp_path / "o.glb"), "--digits", "5"]) == 2
    assert not (tmp_path / "two.leaf.json").exists() and not (tmp_path / "o.glb").exists()

    from leafview.scene.spec import SceneSpec, build_scene, save_scene

    presets = _presets()
    spec = SceneSpec(species=(presets["beech"], presets["ovate"]), layout="plant", leaves=120, seed=3)
    save_scene(spec, tmp_path / "tree.toml")
    leaves_path = tmp_path / "tree.leaves.json"
    assert main(["export", str(tmp_path / "tree.toml"), "-o", str(leaves_path), "-q"]) == 0
    scene = build_scene(spec)
    leaves = load_leaves(leaves_path)
    assert len(leaves) == len(scene)
    for i in (0, 7, len(scene) - 1):
        assert leaves[i].replace(transform=Transform(), name="") == scene.leaf(i).replace(name="")
        assert np.abs(leaves[i].transform.matrix() - scene.matrices[i]).max() < 1e-12
    rounded = tmp_path / "tree6.leaves.json"
    assert main(["export", str(tmp_path / "tree.toml"), "-o", str(rounded), "--digits", "6", "-q"]) == 0
    assert rounded.stat().st_size < 0.7 * leaves_path.stat().st_size


@pytest.mark.gl
def test_rendering_a_compact_file_matches_the_preset(tmp_path, gl):
    from leafview.export.images import read_image

    compact = tmp_path / "holly.leaf.json"
    LeafParams.load(builtin_presets()["holly"]).save(compact)
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    assert main(["render", "holly", "-o", str(a), "--size", "96", "-q"]) == 0
    assert main(["render", str(compact), "-o", str(b), "--size", "96", "-q"]) == 0
    assert np.array_equal(read_image(a)[0], read_image(b)[0])
    sheet = tmp_path / "sheet.png"
    save_leaves(list(_presets().values())[:4], tmp_path / "four.leaves.json")
    assert main(["render", str(tmp_path / "four.leaves.json"), "--sheet", "-o", str(sheet), "--size", "64",
                 "-q"]) == 0
    assert sheet.exists()


def test_docs_reader_runs(tmp_path):
    """docs/parametric.md's plain-Python reader (json + math only) evaluates a compact file to the
    same midrib and margin as leafview's reference."""
    from leafview.deform.surface import evaluate

    text = (Path(__file__).resolve().parents[1] / "docs" / "parametric.md").read_text(encoding="utf-8")
    code = text.split("```python\n", 1)[1].split("```", 1)[0]
    assert "import leafview" not in code and "numpy" not in code
    ns: dict = {}
    exec(compile(code, "docs/parametric.md", "exec"), ns)
    for leaf in (LeafParams.load(builtin_presets()["beech"]), _extended()[1], _extended()[3]):
        path = tmp_path / "x.leaf.json"
        leaf.save(path)
        doc = ns["read_leaf"](str(path))
        for u, v in ((0.0, 0.3), (1.0, 0.5), (-1.0, 0.7), (0.5, 0.1), (-0.25, 0.9)):
            ref = evaluate(leaf.replace(jitter=Jitter(), ripple=Ripple(), bending=Bending()), np.array([u]),
                           np.array([v]))
            got = ns["surface_point"](doc, u, v)
            assert np.allclose(got, np.asarray(ref).reshape(-1)[:3], atol=1e-12), (leaf.name, u, v)


@pytest.mark.gl
def test_a_scene_saved_as_a_leaf_set_draws_the_same_leaves(tmp_path, gl):
    """``leafview scene R --save S.leaves.json`` then ``leafview scene S.leaves.json`` draws what
    the recipe draws (no stems, finest level, no culling: the only difference is float32
    rounding of the varied Ω, done on the host instead of in the shader)."""
    from leafview.export.images import read_image
    from leafview.scene.spec import SceneSpec, save_scene

    presets = _presets()
    spec = SceneSpec(species=(presets["beech"], presets["ovate"]), layout="plant", leaves=150, seed=5, stems=False)
    recipe = tmp_path / "tree.toml"
    save_scene(spec, recipe)
    leaf_set = tmp_path / "tree.leaves.json"
    # the leaves alone: a leaf set has no plants, so its ground (height, contact shadows) and the
    # shadow cascades framed on it may differ from the recipe's
    common = ["--size", "200x160", "--no-lod", "--no-cull", "-q", "--sky", "off", "--ground", "off", "--shadows", "off"]
    assert main(["scene", str(recipe), "--save", str(leaf_set), "-o", str(tmp_path / "a.png"), *common]) == 0
    assert main(["scene", str(leaf_set), "-o", str(tmp_path / "b.png"), *common]) == 0
    a, b = read_image(tmp_path / "a.png")[0], read_image(tmp_path / "b.png")[0]
    assert (a[..., 3] > 0).mean() > 0.05                                     # the plant fills the frame
    differ = np.abs(a.astype(int) - b.astype(int)).max(axis=2) > 24
    assert differ.mean() < 0.01, differ.mean()
    assert main(["scene", str(leaf_set), "--seed", "2", "-o", str(tmp_path / "c.png"), "-q"]) == 2
    assert main(["scene", str(leaf_set), "--save", str(tmp_path / "r.toml"), "-q"]) == 2
    assert not (tmp_path / "c.png").exists() and not (tmp_path / "r.toml").exists()
    glb = tmp_path / "tree.glb"
    assert main(["export", str(leaf_set), "-o", str(glb), "--resolution", "5x9", "-q"]) == 0
    assert glb.stat().st_size > 0
