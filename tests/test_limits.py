"""Counts, sizes, names and physical ranges (leafview.core.limits, the FieldSpec hard ranges): every
value that passes validation evaluates, bends, frames and exports to finite numbers, and every
value beyond a limit is refused up front with one line naming the file and field."""

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from leafview.botany.lobes import lobed_from_dict
from leafview.cli import main
from leafview.core import compact, limits
from leafview.core.params import (
    LeafParams,
    ParamError,
    Transform,
    field_specs,
    parse_params,
)
from leafview.deform.beam import bend_profile
from leafview.deform.surface import evaluate, grid_uv, normals
from leafview.errors import NonFiniteMesh
from leafview.export import export_leaf, export_leaves
from leafview.scene.camera import VIEWS, check_framable, check_leaf_framable, frame_view, frame_views
from leafview.scene.plants import PLANT_RANGES
from leafview.scene.spec import SceneSpec, build_scene, load_scene

ROOT = Path(__file__).resolve().parent.parent
OVATE = ROOT / "assets/presets/ovate.toml"


def _ovate() -> LeafParams:
    return LeafParams.load(OVATE)


def _doc(**groups) -> dict:
    doc = json.loads(json.dumps(_ovate().to_dict()))
    for group, fields in groups.items():
        doc[group].update(fields)
    return doc


def _exit_code(argv) -> int:
    try:
        return main(argv)
    except SystemExit as exc:   # argparse type errors
        return int(exc.code)


# -- counts -------------------------------------------------------------------------------------
@pytest.mark.parametrize("text, expected", [("10", 10), ("10_000", 10_000), ("1e6", 1_000_000), (" 7 ", 7)])
def test_parse_count_accepts(text, expected):
    assert limits.parse_count(text, 1, 10_000_000, "leaves") == expected


@pytest.mark.parametrize("text", ["1e400", "-1e400", "nan", "inf", "1.5", "0", "2e7", "9" * 5000, "ten"])
def test_parse_count_refuses_with_a_message_never_an_overflow(text):
    with pytest.raises(ValueError) as info:
        limits.parse_count(text, 1, 10_000_000, "leaves")
    assert type(info.value) is ValueError and "\n" not in str(info.value) and len(str(info.value)) < 200


@pytest.mark.parametrize("argv, words", [
    (["--leaves", "1e400"], "whole number of leaves"),
    (["--leaves", "9" * 5000], "whole number of leaves"),
    (["--plants", "1000000"], "plants must be in 1..100,000"),
    (["--frames", "99999999999", "--view"], "frames must be in"),
])
def test_scene_cli_counts_exit_2(tmp_path, capsys, argv, words):
    out = tmp_path / "x.png"
    assert _exit_code(["scene", *argv, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())


def test_scene_memory_is_estimated_against_the_machine(monkeypatch):
    species = (_ovate(),)
    monkeypatch.setattr(limits, "physical_memory", lambda: 24 * 2**30)
    with pytest.raises(ParamError, match=r"scene\.leaves: 10,000,000 leaves on 5,000 plants would need about "
                                         r"\d+\.\d GiB of memory, more than 50% of this machine's 24\.0 GiB"):
        SceneSpec(species=species, leaves=10_000_000)
    assert SceneSpec(species=species, leaves=1_000_000).leaves == 1_000_000
    monkeypatch.setattr(limits, "physical_memory", lambda: 2 * 2**30)
    with pytest.raises(ParamError, match=r"scene\.plants: .* on 100,000 plants"):
        SceneSpec(species=species, leaves=100_000, plants=100_000)
    assert SceneSpec(species=species, leaves=100_000, plants=100_000, stems=False).plants == 100_000
    with pytest.raises(ParamError, match=r"scene\.plants: must be in 0\.\.100,000, got 1,000,000"):
        SceneSpec(species=species, leaves=100, plants=1_000_000)


def test_scene_file_names_and_counts(tmp_path):
    path = tmp_path / "s.toml"
    for body, words in (('[scene]\nname = "' + "x" * 300 + '"\n', "scene.name: 300 characters"),
                        ('[scene]\nname = "a\\u0000b"\n', "scene.name: control character U+0000"),
                        ("[scene]\nplants = 1000000\n", "scene.plants: must be in 0..100,000"),
                        ("[scene]\nleaves = 100000000000\n", "scene.leaves: must be in 1..10,000,000")):
        path.write_text("schema = 1\n" + body + '[[species]]\npreset = "ovate"\n')
        with pytest.raises(ParamError, match=rf"s\.toml: {re.escape(words)}"):
            load_scene(path)


def test_lobed_positions_are_bounded():
    rows = [[0.01 * i, 45.0, 0.5] for i in range(2000)]
    with pytest.raises(ParamError, match=r"positions: 2,000 lateral lobes; 1\.\.12 per side"):
        lobed_from_dict({"lobed": 1, "positions": rows})
    with pytest.raises(ParamError, match="half"):
        lobed_from_dict({"lobed": 1, "half": 13})
    with pytest.raises(ParamError, match=r"r1: 1e\+300 is outside"):
        lobed_from_dict({"lobed": 1, "r1": 1e300})
    assert len(lobed_from_dict({"lobed": 1, "positions": rows[:12]}).positions) == 12


# -- physical ranges: what passes validation can never fail deeper ------------------------------
@pytest.mark.parametrize("group, fields, path", [
    ("shape", {"zf": [1e308, 0.0, 0.0]}, r"shape\.zf\[0\]"),
    ("shape", {"a1": [0.0, 1e300, 0.0]}, r"shape\.a1\[1\]"),
    ("shape", {"silhouette": [[0.25, 1e200, 0.0], [0.5, 0.4, 0.0], [0.75, 0.25, 0.0]]}, r"shape\.silhouette\[0\]\[1\]"),
    ("transform", {"translation": [1e308, 0.0, 0.0]}, r"transform\.translation\[0\]"),
    ("transform", {"scale": 1e300}, r"transform\.scale"),
    ("transform", {"rotation": [0.0, 1e300, 0.0]}, r"transform\.rotation\[1\]"),
    ("bending", {"direction": [1e-300, 0.0, 0.0]}, r"bending\.direction"),
    ("bending", {"stiffness": 1e-300}, r"bending\.stiffness"),
    ("ripple", {"phase": [1e300, 0.0]}, r"ripple\.phase\[0\]"),
])
def test_values_beyond_the_physical_ranges_are_refused(group, fields, path):
    with pytest.raises(ParamError, match=path):
        parse_params(_doc(**{group: fields}))


def test_schema_publishes_the_ranges():
    specs = field_specs()
    for name in ("shape.a1", "shape.a2", "shape.silhouette", "shape.zf", "shape.zg"):
        assert specs[name].hard_range == (-10.0, 10.0)
    assert specs["transform.scale"].hard_range == (1e-6, 1e6)
    assert specs["bending.stiffness"].hard_range == (1e-4, 1e4)
    schema = json.loads((ROOT / "assets/schema/leaf.schema.json").read_text())
    shape = schema["properties"]["shape"]["properties"]
    assert shape["zf"]["items"]["maximum"] == 10.0
    assert shape["silhouette"]["items"]["prefixItems"][1]["minimum"] == -10.0
    assert schema["properties"]["name"]["maxLength"] == limits.MAX_NAME_CHARS


def _pick(rng, lo, hi, *, log=False):
    """A value in [lo, hi]: an end point 30 % of the time, else uniform (log-uniform if ``log``)."""
    r = rng.uniform()
    if r < 0.15:
        return lo
    if r < 0.3:
        return hi
    if log and lo > 0:
        return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
    return float(rng.uniform(lo, hi))


def _accepted_leaf(rng) -> LeafParams:
    """A random leaf anywhere in the accepted ranges, extremes included."""
    om = 10.0
    n = int(rng.integers(3, limits.MAX_SILHOUETTE_ROWS + 1))
    cuts = np.sort(rng.uniform(0, 1, n))
    if rng.uniform() < 0.3:
        cuts = np.linspace(1e-9, 1 - 1e-9, n)          # feet at the very ends of the axis
    cuts = np.maximum.accumulate(cuts)
    vbar = [float(np.clip(c, 1e-9, 1 - 1e-9)) for c in cuts]
    for i in range(1, n):
        if not vbar[i] > vbar[i - 1]:
            vbar[i] = float(np.nextafter(vbar[i - 1], 1.0))
    if any(not 0 < v < 1 for v in vbar):
        vbar = list(np.linspace(0.1, 0.9, n))

    def vec(k, lo, hi, log=False):
        return [_pick(rng, lo, hi, log=log) for _ in range(k)]

    shape = {"a1": vec(3, -om, om), "a2": vec(3, -om, om),
             "silhouette": [[vbar[i], _pick(rng, -om, om), _pick(rng, -om, om)] for i in range(n)],
             "zf": vec(n, -om, om), "zg": vec(n, -om, om), "tilt": vec(n, -90.0, 90.0),
             "half": int(rng.integers(-1, 2))}
    direction = vec(3, -1e3, 1e3)
    if math.hypot(*direction) < 1e-6:
        direction = [0.0, 0.0, -1e-6]
    doc = {
        "schema": 1, "name": "sample", "shape": shape,
        "jitter": {"enabled": bool(rng.integers(2)), "amplitude": _pick(rng, 0.0, 1.0),
                   "density": _pick(rng, 1e-3, 4096.0, log=True), "seed": int(rng.integers(0, 2**31 - 1))},
        "transform": {"translation": vec(3, -1e9, 1e9), "rotation": vec(3, -720.0, 720.0),
                      "scale": _pick(rng, 1e-6, 1e6, log=True)},
        "ripple": {"enabled": bool(rng.integers(2)), "beta": _pick(rng, 1e-6, 8.0), "seed": int(rng.integers(0, 9999)),
                   "veins": _pick(rng, 1e-3, 4096.0, log=True), "amplitude": vec(2, 0.0, 1.0),
                   "fluctuation": vec(2, 0.0, 1.0), "interval": vec(2, 0.0, 64.0), "phase": vec(2, -1e4, 1e4)},
        "bending": {"load": _pick(rng, 0.0, 1e4), "direction": direction,
                    "stiffness": _pick(rng, 1e-4, 1e4, log=True), "twist": _pick(rng, -720.0, 720.0),
                    "petiole_length": _pick(rng, 0.0, 10.0), "petiole_stiffness": _pick(rng, 1e-4, 1e4, log=True)},
    }
    return parse_params(doc)        # accepted: it passed validation


def test_every_accepted_leaf_evaluates_bends_and_has_normals_finite():
    """Property test (seeded random sampling over the accepted ranges, end points included): the
    numpy model (Chaurasia & Beardsley 2017, eqs 1-6) and the cantilever bend (Geng, Hu & Zhang
    2014, eq. 4) never raise and return finite numbers for any leaf that passes validation."""
    rng = np.random.default_rng(1414)
    uv = grid_uv(7, 13).astype(np.float64)
    for i in range(250):
        leaf = _accepted_leaf(rng)
        try:
            profile = bend_profile(leaf)
            pts = evaluate(leaf, uv[:, 0], uv[:, 1])
            nrm = normals(leaf, uv[:, 0], uv[:, 1])
        except Exception as exc:  # the failure names the sample
            pytest.fail(f"sample {i}: {type(exc).__name__}: {exc}\n{leaf}")
        assert np.isfinite(profile.phi).all() and np.isfinite(profile.delta).all(), (i, leaf)
        assert np.isfinite(pts).all(), (i, leaf)
        assert np.isfinite(nrm).all(), (i, leaf)


def test_beam_chain_with_a_cusp_on_a_sample_does_not_raise():
    # the axis doubles back on itself: joints coincide, and the straight chain has zero-length segments
    leaf = parse_params(_doc(shape={"a1": [0.0, 10.0, 0.0], "a2": [0.0, -10.0, 0.0]},
                             bending={"load": 1e4, "stiffness": 1e-4}))
    profile = bend_profile(leaf)
    assert np.isfinite(profile.phi).all() and np.isfinite(profile.delta).all()


# -- framing and exports ------------------------------------------------------------------------
def test_unframable_leaves_are_named():
    far = _ovate().replace(transform=Transform(translation=(1e9, 0.0, 0.0), scale=1e-6), name="speck")
    with pytest.raises(ParamError, match=r"transform: leaf speck: spans .* too small for 32-bit"):
        check_leaf_framable(far)
    huge = _ovate().replace(transform=Transform(translation=(1e30, 0.0, 0.0)), name="far")
    with pytest.raises(ParamError, match="beyond"):
        check_leaf_framable(huge)
    with pytest.raises(ParamError, match="not finite"):
        check_framable(np.array([[0.0, 0.0, 0.0], [np.inf, 0.0, 0.0]]))
    check_leaf_framable(_ovate())


@pytest.mark.parametrize("view", VIEWS)
def test_batched_framing_is_the_framing_of_each_set(view):
    """frame_views (the thumbnails' framing of a whole chunk) gives each point set exactly the
    camera frame_view gives it, and refuses an unframable set with frame_view's error."""
    rng = np.random.default_rng(4)
    pts = rng.normal(size=(9, 300, 3)) * rng.uniform(0.01, 2.0, size=(9, 1, 3)) + rng.normal(size=(9, 1, 3))
    for one, many in zip([frame_view(view, p, (96, 64)) for p in pts], frame_views(view, pts, (96, 64))):
        for a, b in ((one.view, many.view), (one.proj, many.proj), (one.eye, many.eye)):
            np.testing.assert_array_equal(a, b)
    pts[5, 7, 1] = np.nan
    with pytest.raises(ParamError, match="not finite"):
        frame_views(view, pts, (96, 64))
    pts[5, 7, 1] = 1e30
    with pytest.raises(ParamError, match="beyond"):
        frame_views(view, pts, (96, 64))


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".usda", ".glb"])
def test_non_finite_world_vertices_are_refused_in_every_format(tmp_path, suffix):
    leaf = _ovate().replace(transform=Transform(translation=(1e308, 0.0, 0.0)), name="far")
    out = tmp_path / f"far{suffix}"
    with pytest.raises(NonFiniteMesh, match=r"far: transform\.translation puts its vertices outside"):
        export_leaf(leaf, out, backend="numpy", resolution=(5, 9))
    big = _ovate().replace(transform=Transform(scale=1e300), name="big")
    with pytest.raises(NonFiniteMesh, match=r"big: transform\.scale/rotation"):
        export_leaves([_ovate(), big], out, backend="numpy", resolution=(5, 9))
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("field, value, path", [("transform", {"translation": [1e308, 0, 0]}, "transform.translation[0]"),
                                                ("shape", {"zf": [1e308, 0, 0]}, "shape.zf[0]")])
@pytest.mark.parametrize("command, out", [("export", "x.ply"), ("export", "x.usda"), ("render", "x.png")])
def test_cli_refuses_huge_values_naming_leaf_and_field(tmp_path, capsys, field, value, path, command, out):
    preset = tmp_path / "huge.json"
    preset.write_text(json.dumps(_doc(**{field: value})))
    assert main([command, str(preset), "-o", str(tmp_path / out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "huge.json" in err and path in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["huge.json"]


def test_cli_refuses_an_unframable_leaf(tmp_path, capsys):
    preset = tmp_path / "speck.json"
    preset.write_text(json.dumps({**_doc(transform={"translation": [1e9, 0, 0], "scale": 1e-6}), "name": "speck"}))
    assert main(["render", str(preset), "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "leaf speck" in err and "too small" in err, err
    assert not (tmp_path / "x.png").exists()


# -- files named inside an input ------------------------------------------------------------------
def _scene(folder: Path, preset: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "scene.toml"
    path.write_text(f'schema = 1\n[scene]\nleaves = 50\n[[species]]\npreset = "{preset}"\n')
    return path


def test_species_presets_stay_inside_the_scene_folder(tmp_path):
    (tmp_path / "outside.toml").write_text(OVATE.read_text())
    inner = tmp_path / "scenes"
    (inner / "leaves").mkdir(parents=True)
    (inner / "leaves" / "mine.toml").write_text(OVATE.read_text())
    assert load_scene(_scene(inner, "leaves/mine.toml")).species[0].name == "ovate"
    assert load_scene(_scene(inner, "ovate")).species[0].name == "ovate"          # built-in names are fine
    for preset in ("../outside.toml", str(tmp_path / "outside.toml"), "leaves/../../outside.toml"):
        with pytest.raises(ParamError, match=r"scene\.toml: species\[0\]\.preset: .* leaves the scene file's folder"):
            load_scene(_scene(inner, preset))
        assert load_scene(_scene(inner, preset), allow_outside_presets=True).species[0].name == "ovate"
    (inner / "link.toml").symlink_to(tmp_path / "outside.toml")
    with pytest.raises(ParamError, match="leaves the scene file's folder"):
        load_scene(_scene(inner, "link.toml"))


def test_a_failing_preset_is_named_without_quoting_it(tmp_path):
    secret = tmp_path / "secret.json"
    secret.write_text(json.dumps({"schema": 1, "hunter2_password": "s3cr3t", "shape": {}}))
    for scene in (_scene(tmp_path / "a", str(secret)), _scene(tmp_path, "secret.json")):
        with pytest.raises(ParamError) as info:
            load_scene(scene, allow_outside_presets=True)
        text = str(info.value)
        assert "species[0].preset" in text and "secret.json" in text and "not a usable leaf preset" in text
        assert "hunter2" not in text and "s3cr3t" not in text
    broken = tmp_path / "broken.toml"
    broken.write_text("schema = 1\n[shape\npassword = 'xyz'\n")
    with pytest.raises(ParamError, match=r"a syntax error at line 2") as info:
        load_scene(_scene(tmp_path / "b", "../broken.toml"), allow_outside_presets=True)
    assert "xyz" not in str(info.value)


def test_scene_cli_allow_outside_presets(tmp_path, capsys):
    (tmp_path / "outside.toml").write_text(OVATE.read_text())
    scene = _scene(tmp_path / "s", "../outside.toml")
    save = tmp_path / "out.toml"
    assert main(["scene", str(scene), "--save", str(save), "-q"]) == 2
    assert "--allow-outside-presets" in capsys.readouterr().err and not save.exists()
    assert main(["scene", str(scene), "--save", str(save), "-q", "--allow-outside-presets"]) == 0
    assert save.exists()


def test_subprocess_counts_exit_2_without_a_traceback(tmp_path):
    for argv in (["scene", "--leaves", "1e400", "-o", "x.png"], ["scene", "--plants", "1000000", "-o", "x.png"]):
        result = subprocess.run([sys.executable, "-c", "import sys; from leafview.cli import main; sys.exit(main())",
                                 *argv], cwd=tmp_path, capture_output=True, text=True, timeout=60)
        assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
        assert "error:" in result.stderr.strip().splitlines()[-1]
    assert not list(tmp_path.iterdir())


def test_an_invalid_compact_preset_is_named_by_field(tmp_path):
    leaf = json.loads(compact.dumps(_ovate()))
    leaf["omega"][7] = 1e300
    (tmp_path / "c.leaf.json").write_text(json.dumps(leaf))
    with pytest.raises(ParamError, match=r"'c\.leaf\.json' is not a usable leaf preset: an invalid value at omega\[7\]$"):
        load_scene(_scene(tmp_path, "c.leaf.json"))


@pytest.mark.parametrize("layout", ["plant", "field"])
def test_every_plant_setting_at_its_limits_expands_to_finite_leaves(tmp_path, layout):
    """Each numeric [plant] setting at the bounds PLANT_RANGES accepts (lengths down to
    MIN_LENGTH) grows finite leaf matrices; a positive denormal length (5e-324 made the growth
    arithmetic divide by zero) is refused naming the field."""
    for name, (lo, hi, _, integer) in PLANT_RANGES.items():
        for value in (lo, hi):
            value = int(value) if integer else value
            doc = {"schema": 1, "scene": {"leaves": 40, "layout": layout}, "plant": {name: value},
                   "species": [{"preset": "ovate"}]}
            path = tmp_path / "s.json"
            path.write_text(json.dumps(doc))
            scene = build_scene(load_scene(path))
            assert np.isfinite(scene.matrices).all(), f"plant.{name} = {value}"
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps({"schema": 1, "scene": {"leaves": 10}, "plant": {"height": 5e-324},
                                "species": [{"preset": "ovate"}]}))
    with pytest.raises(ParamError, match=r"plant\.height: must be ≥ 1e-06"):
        load_scene(path)


def test_species_weights_at_the_float_limit_still_draw_species(tmp_path):
    """Weights are relative: two of 1e308 summed to inf and made the species draw raise
    (found by the long fuzz run); any positive finite weights give probabilities."""
    path = tmp_path / "s.toml"
    path.write_text('schema = 1\nspecies = [\n    { preset = "ovate", weight = 1e+308 },\n    { preset = "ovate" },\n'
                    '    { preset = "lanceolate", weight = 1e+308 },\n    { preset = "ovate", weight = 5e-324 },\n]\n\n'
                    '[scene]\nleaves = 400\nplants = 40\nlayout = "field"\n')
    scene = build_scene(load_scene(path))
    used = set(np.unique(scene.species_id).tolist())
    assert used == {0, 2}, used   # the two heavy species; the others (1e-308 of their weight) never
