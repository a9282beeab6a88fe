"""Per-leaf variety (Geng, Hu & Zhang 2014, sec. 6): ripple phase, ripple amplitude and bend load drawn per
leaf from ranges set per species, packed into the GPU rows once (no per-frame CPU work), and
the numpy reference (Scene.leaf, evaluate_leaf) matching what the vertex shader draws."""

from __future__ import annotations

import json
from dataclasses import replace

import jsonschema
import numpy as np
import pytest

from leafview.core.params import LeafParams, ParamError
from leafview.deform.beam import bend_profiles
from leafview.deform.surface import grid_uv
from leafview.gpu.layout import pack_leaf
from leafview.resources import builtin_presets
from leafview.scene.schema import published_path
from leafview.scene.spec import SceneSpec, bend_deviation, build_scene, evaluate_leaf, load_scene, save_scene
from leafview.scene.variety import LOAD_SAMPLES, Variety, interpolate_bend, load_table

VARIED = Variety(ripple_phase=(0.0, 24.0), ripple_amplitude=(0.5, 1.5), bend_load=(0.7, 1.3))


@pytest.fixture(scope="module")
def maize() -> LeafParams:
    leaf = LeafParams.load(builtin_presets()["maize"])
    assert leaf.ripple.enabled and leaf.bending.load > 0   # rippled and bent: every part of the variety shows
    return leaf


@pytest.fixture(scope="module")
def beech() -> LeafParams:
    return LeafParams.load(builtin_presets()["beech"])


def _spec(maize, beech, varieties=(), **kw) -> SceneSpec:
    args = dict(species=(maize, beech), layout="field", leaves=300, plants=30, seed=5, varieties=varieties)
    args.update(kw)
    return SceneSpec(**args)


# -- drawing ------------------------------------------------------------------------------------
def test_defaults_leave_the_arrays_none_and_the_rows_as_before(maize, beech):
    from leafview.gpu.scene import pack_scene

    doc = _spec(maize, beech).to_dict()
    assert all("variety" not in s for s in doc["species"])       # nothing written by default
    keyed = json.loads(json.dumps(doc))
    for s in keyed["species"]:
        s["variety"] = {}
    plain, empty = build_scene(SceneSpec.from_dict(doc)), build_scene(SceneSpec.from_dict(keyed))
    for scene in (plain, empty):
        assert scene.ripple_phase is None and scene.ripple_scale is None and scene.load_scale is None
    assert pack_scene(plain).tobytes() == pack_scene(empty).tobytes()


def test_variety_draws_after_everything_else(maize, beech):
    """A scene keeps its numbers bit for bit when a species gains variety."""
    before = build_scene(_spec(maize, beech))
    after = build_scene(_spec(maize, beech, (VARIED, Variety())))
    for name in ("species_id", "factors", "tint", "matrices"):
        assert np.array_equal(getattr(before, name), getattr(after, name)), name


def test_ranges_respected_and_seeded(maize, beech):
    spec = _spec(maize, beech, (VARIED, Variety(ripple_amplitude=(0.9, 1.1))))
    a, b = build_scene(spec), build_scene(spec)
    other = build_scene(spec.replace(seed=6))
    mine = a.species_id == 0
    assert 50 < mine.sum() < len(a) - 50
    for name, field in (("ripple_phase", "ripple_phase"), ("ripple_scale", "ripple_amplitude"),
                        ("load_scale", "bend_load")):
        x = getattr(a, name)
        assert x is not None and x.dtype == np.float32 and x.shape == (len(a),)
        assert np.array_equal(x, getattr(b, name)), name             # same seed, same values
        assert not np.array_equal(x, getattr(other, name)), name     # another seed, others
        for k, v in enumerate(spec.varieties):
            lo, hi = getattr(v, field)
            own = x[a.species_id == k]
            assert own.min() >= np.float32(lo) and own.max() <= np.float32(hi), (name, k)
            if lo < hi:
                assert own.max() - own.min() > 0.8 * (hi - lo), (name, k)   # the range is used
            else:
                assert (own == np.float32(lo)).all(), (name, k)             # the species' value


def test_leaf_carries_its_variety(maize, beech):
    scene = build_scene(_spec(maize, beech, (VARIED, Variety())))
    i = int(np.flatnonzero(scene.species_id == 0)[3])
    leaf = scene.leaf(i)
    s, o, f = (float(getattr(scene, n)[i]) for n in ("ripple_scale", "ripple_phase", "load_scale"))
    assert leaf.ripple.amplitude == pytest.approx(tuple(p * s for p in maize.ripple.amplitude))
    assert leaf.ripple.phase == pytest.approx(tuple(t + o for t in maize.ripple.phase))
    assert leaf.bending.load == pytest.approx(maize.bending.load * f)
    j = int(np.flatnonzero(scene.species_id == 1)[0])
    assert scene.leaf(j).ripple == beech.ripple and scene.leaf(j).bending == beech.bending


# -- files and bad input ------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_variety_round_trips_through_files(tmp_path, maize, beech, suffix):
    spec = _spec(maize, beech, (Variety(), VARIED))
    doc = spec.to_dict()
    assert "variety" not in doc["species"][0]
    assert doc["species"][1]["variety"] == {"ripple_phase": [0.0, 24.0], "ripple_amplitude": [0.5, 1.5],
                                            "bend_load": [0.7, 1.3]}
    save_scene(spec, tmp_path / f"s{suffix}")
    assert load_scene(tmp_path / f"s{suffix}").varieties == spec.varieties


BAD = [
    ({"ripple_phase": [10.0, 2.0]}, "species[1].variety.ripple_phase"),       # reversed
    ({"bend_load": [1.3, 0.7]}, "species[1].variety.bend_load"),
    ({"bend_load": [-0.5, 1.0]}, "species[1].variety.bend_load[0]"),          # negative
    ({"ripple_amplitude": [0.5, -1.0]}, "species[1].variety.ripple_amplitude[1]"),
    ({"ripple_phase": [0.0, float("nan")]}, "species[1].variety.ripple_phase[1]"),
    ({"ripple_phase": 3.0}, "species[1].variety.ripple_phase"),
    ({"colour": [0, 1]}, "species[1].variety.colour"),                       # unknown key
    ({"ripple_amplitude": [1.0, 9.0]}, "species[1].variety.ripple_amplitude"),  # P x 9 leaves P's range
]


@pytest.mark.parametrize("table, path", BAD, ids=[p.split(".")[-1] + str(i) for i, (_, p) in enumerate(BAD)])
def test_bad_variety_names_the_field(maize, table, path):
    rippled = maize.replace(ripple=replace(maize.ripple, amplitude=(0.2, 0.2)))
    doc = SceneSpec(species=(rippled, rippled), leaves=10).to_dict()
    doc["species"][1]["variety"] = table
    with pytest.raises(ParamError) as err:
        SceneSpec.from_dict(json.loads(json.dumps(doc)))
    assert err.value.path == path, str(err.value)


def test_bad_variety_in_python_names_the_species(maize):
    with pytest.raises(ParamError) as err:
        SceneSpec(species=(maize,), leaves=10, varieties=(Variety(), VARIED))
    assert err.value.path == "species"
    # none set (the species replaced, as the command line's --species does): the defaults
    spec = SceneSpec(species=(maize,), leaves=10).replace(species=(maize, maize), weights=())
    assert spec.varieties == (Variety(), Variety())
    heavy = maize.replace(bending=replace(maize.bending, load=2000.0))
    SceneSpec(species=(maize, heavy), leaves=10, varieties=(Variety(), Variety(bend_load=(1.0, 5.0))))
    with pytest.raises(ParamError) as err:   # 2000 x 6 leaves the load's range
        SceneSpec(species=(maize, heavy), leaves=10, varieties=(Variety(), Variety(bend_load=(1.0, 6.0))))
    assert err.value.path == "species[1].variety.bend_load"
    with pytest.raises(ParamError, match="variety.ripple_phase"):
        Variety(ripple_phase=(5.0, 1.0))


def test_published_schema_knows_variety_light_wind_and_edits(maize, beech):
    schema = json.loads(published_path("scene.schema.json").read_text(encoding="utf-8"))
    check = jsonschema.Draft202012Validator(schema)
    doc = json.loads(json.dumps(_spec(maize, beech, (VARIED, Variety())).to_dict()))
    doc["light"] = {"sun": [120.0, 40.0], "shadows": False, "tone": "linear", "shadow_size": 1024}
    doc["wind"] = {"speed": 6.0, "time": 0.5}
    doc["edits"] = [{"op": "width", "value": 1.2, "target": "species", "species": 1},
                    {"op": "curvature", "value": 0.05, "curve": "F", "target": "leaves", "leaves": [1, 2]}]
    assert list(check.iter_errors(doc)) == []
    SceneSpec.from_dict(doc)
    bad = [("species", 0, "variety", "bend_load", [-1.0, 1.0]), ("species", 0, "variety", "jitter", 1),
           ("light", "tone", "aces"), ("light", "shadow_size", 10), ("light", "shadows", "yes"),
           ("wind", "speed", -1.0), ("wind", "gale", 1), ("edits", 0, "op", "twist"), ("edits", 0, "value", 50.0),
           ("edits", 1, "curve", "Z"), ("edits", 1, "leaves", [])]
    for path in bad:
        changed = json.loads(json.dumps(doc))
        node = changed
        for key in path[:-2]:
            node = node[key]
        node[path[-2]] = path[-1]
        assert list(check.iter_errors(changed)), path
        with pytest.raises(ParamError):
            SceneSpec.from_dict(changed)


# -- rows and the bend interpolation ------------------------------------------------------------
def test_rows_carry_each_leaf_s_ripple_and_bend(maize, beech):
    from leafview.gpu.scene import pack_scene

    scene = build_scene(_spec(maize, beech, (VARIED, Variety()), variation=0.0, colour_variation=0.0))
    rows = pack_scene(scene)
    plain = pack_scene(build_scene(_spec(maize, beech, variation=0.0, colour_variation=0.0)))
    for i in np.flatnonzero(scene.species_id == 0)[:5]:
        own = pack_leaf(scene.leaf(int(i)))
        for name in ("ripple_l", "ripple_r"):
            assert np.allclose(rows[name][i], own[name], rtol=1e-6, atol=1e-6), name
        assert not np.allclose(rows["ripple_l"][i], plain["ripple_l"][i])
        # the bend: interpolated between solved loads, within 1e-3 of the leaf's own solve
        assert np.abs(rows["bend"][i] - own["bend"]).max() < 1e-3
        assert not np.allclose(rows["bend"][i], plain["bend"][i], atol=1e-4)
    beech_rows = scene.species_id == 1
    assert rows[beech_rows].tobytes() == plain[beech_rows].tobytes()


def test_interpolation_exact_at_solved_loads_and_close_between(maize, beech):
    leaf = beech.replace(bending=replace(beech.bending, load=6.0))
    v = Variety(bend_load=(0.7, 1.3))
    table = load_table((leaf,), (v,))
    assert table is not None and table.phi.shape[1] >= LOAD_SAMPLES
    k = table.phi.shape[1]
    f = np.linspace(0.7, 1.3, k)
    which, phi, delta = interpolate_bend(table, np.zeros(k, np.int32), f.astype(np.float64))
    exact = bend_profiles([leaf.replace(bending=replace(leaf.bending, load=6.0 * x)) for x in f])
    assert np.abs(phi - [p.phi for p in exact]).max() < 1e-12
    assert np.abs(delta - [p.delta for p in exact]).max() < 1e-12
    # between the solved loads: the drawn leaf within 5e-4 leaf lengths of its own solve
    spec = SceneSpec(species=(leaf,), leaves=200, seed=3, varieties=(Variety(bend_load=(0.0, 2.0)),),
                     variation=0.0, colour_variation=0.0)
    scene = build_scene(spec)
    assert 0.0 < bend_deviation(scene, range(0, 200, 10)) < 2e-4
    assert load_table((leaf,), (Variety(),)) is None


def test_offsets_apply_before_the_clamp(maize, beech):
    from leafview.gpu.scene import pack_scene

    scene = build_scene(_spec(maize, beech, variation=0.0, colour_variation=0.0))
    base = pack_scene(scene)
    scene.offsets = np.zeros_like(scene.factors)
    scene.offsets[:, 0] = 0.05       # a1.x
    scene.offsets[:, 6] = 5.0        # vbar1: pushed past the clamp
    rows = pack_scene(scene)
    assert np.allclose(rows["a1"][:, 0], base["a1"][:, 0] + 0.05, atol=1e-6)
    assert np.allclose(rows["vbar"][:, 0], 0.98)


# -- on the GPU ---------------------------------------------------------------------------------
@pytest.fixture
def ctx(gl):
    return gl.ctx


def _two(maize):
    spec = SceneSpec(species=(maize,), layout="plant", leaves=40, seed=2, variation=0.0, colour_variation=0.0,
                     stems=False, varieties=(VARIED,))
    scene = build_scene(spec)
    a, b = 3, 17
    assert scene.ripple_phase is not None and scene.ripple_scale is not None and scene.load_scale is not None
    scene.load_scale[[a, b]] = (0.7, 1.3)
    scene.ripple_phase[[a, b]] = (0.0, 11.0)
    scene.ripple_scale[[a, b]] = (0.6, 1.4)
    return scene, a, b


def test_gpu_draws_each_leaf_s_variety(ctx, maize):
    from leafview.gpu.instanced import OffscreenTarget
    from leafview.gpu.scene import SceneRenderer

    scene, a, b = _two(maize)
    with SceneRenderer(ctx, scene) as r, OffscreenTarget(ctx, (64, 64)) as target:
        target.use()
        got = r.capture([a, b], 0)
        uv = grid_uv(*r.grids[0]).astype(np.float64)
    assert ctx.error == "GL_NO_ERROR"
    refs = [evaluate_leaf(scene, i, uv[:, 0], uv[:, 1]) for i in (a, b)]
    for row, ref in zip(got, refs):
        assert np.abs(row - ref).max() <= 2e-5, np.abs(row - ref).max()
    # the tip (u = 0, v = 1) droops more under the larger load
    tip = int(np.flatnonzero((uv[:, 0] == 0.0) & (uv[:, 1] == 1.0))[0])
    assert got[1][tip, 2] < got[0][tip, 2] - 0.02, (got[0][tip], got[1][tip])
    # each leaf's own ripple reached the GPU: leaf b with leaf a's ripple is far from what was drawn
    assert scene.ripple_phase is not None and scene.ripple_scale is not None
    scene.ripple_phase[b], scene.ripple_scale[b] = scene.ripple_phase[a], scene.ripple_scale[a]
    swapped = evaluate_leaf(scene, b, uv[:, 0], uv[:, 1])
    assert np.abs(got[1] - swapped)[:, 2].max() > 1e-3


def test_no_per_frame_cpu_work(ctx, maize, monkeypatch):
    """SceneRenderer.draw reads nothing of the per-leaf arrays: the rows are packed once, at upload."""
    import leafview.gpu.scene as G
    from leafview.gpu.instanced import OffscreenTarget
    from leafview.scene.camera import scene_camera

    scene, _, _ = _two(maize)
    with G.SceneRenderer(ctx, scene) as r, OffscreenTarget(ctx, (64, 64)) as target:
        def refuse(*a, **k):
            raise AssertionError("per-leaf packing during a frame")
        for name in ("pack_scene", "load_table", "interpolate_bend", "_write_variety"):
            monkeypatch.setattr(G, name, refuse)
        scene.ripple_phase = scene.ripple_scale = scene.load_scale = None   # draw must not need them
        target.use()
        r.set_camera(scene_camera(scene, (64, 64), "three-quarter"), (64, 64))
        r.draw()
        assert r.level_counts().sum() > 0
    assert ctx.error == "GL_NO_ERROR"


def test_padded_spheres_hold_every_leaf(ctx, beech):
    """SceneRenderer's culling spheres, grown by sphere_padding, hold every vertex of every leaf,
    whatever its variety; the species' own sphere (the same scene without variety) does not: the
    padding is needed."""
    from leafview.gpu.instanced import OffscreenTarget
    from leafview.gpu.scene import SceneRenderer

    leaf = beech.replace(bending=replace(beech.bending, load=4.0),
                         ripple=replace(beech.ripple, enabled=True, amplitude=(0.03, 0.03)))
    wide = Variety(ripple_phase=(0.0, 30.0), ripple_amplitude=(0.0, 2.0), bend_load=(0.0, 2.0))
    for variation in (0.0, 0.2):
        spec = SceneSpec(species=(leaf,), layout="plant", leaves=120, seed=2, variation=variation, stems=False,
                         varieties=(wide,))
        scene = build_scene(spec)
        with SceneRenderer(ctx, scene) as r, OffscreenTarget(ctx, (64, 64)) as target:
            target.use()
            pts = r.capture(list(range(len(scene))), 0)
            rows = r.cull_rows
        with SceneRenderer(ctx, build_scene(spec.replace(varieties=(Variety(),)))) as plain:
            own = plain.cull_rows["sphere"][scene.species_id]
        sph = rows["sphere"][scene.species_id]
        out = np.linalg.norm(pts - sph[:, None, :3], axis=-1) - sph[:, None, 3]
        assert out.max() <= 1e-5, out.max()
        if variation == 0.0:
            poke = np.linalg.norm(pts - own[:, None, :3], axis=-1) - own[:, None, 3]
            assert poke.max() > 0.05          # the species' own sphere is not enough
        assert rows["sphere"][0, 3] < 3.0 * own[0, 3]     # and the padding stays a fraction of the leaf
    assert ctx.error == "GL_NO_ERROR"
