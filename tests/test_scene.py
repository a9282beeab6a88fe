"""Scenes: the scene file, per-leaf rows, GPU culling and LOD against their numpy references, the
rendered picture, batching at the storage-block limit and the ``leafview scene`` command."""

from __future__ import annotations

import json

import numpy as np
import pytest

from leafview.cli import main
from leafview.core.params import LeafParams, ParamError
from leafview.gpu.layout import LEAF_BLOCK, branch_code, pack_leaf, read_slot, without_derived
from leafview.scene.spec import SceneSpec, build_scene, evaluate_leaf, load_scene, save_scene
from tests.conftest import assert_matches_reference


def _spec(presets, n=400, **kw) -> SceneSpec:
    kw.setdefault("seed", 5)
    kw.setdefault("plants", 9)  # several plants, so every species appears
    return SceneSpec(species=(presets["ovate"], presets["lanceolate"], presets["maize"]), leaves=n, **kw)


@pytest.fixture(scope="module")
def small(presets):
    return build_scene(_spec(presets))


# -- the scene file -------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_scene_file_round_trip(tmp_path, presets, suffix):
    spec = _spec(presets, layout="hedge", variation=0.15, plant={"phyllotaxis": "opposite"}, name="hedge")
    path = tmp_path / f"s{suffix}"
    save_scene(spec, path)
    back = load_scene(path)
    assert back.to_dict() == spec.to_dict()
    a, b = build_scene(spec), build_scene(back)
    assert np.array_equal(a.matrices, b.matrices) and np.array_equal(a.factors, b.factors)
    assert np.array_equal(a.species_id, b.species_id)


def test_same_seed_same_scene_and_different_seed_differs(presets):
    a, b = build_scene(_spec(presets)), build_scene(_spec(presets))
    c = build_scene(_spec(presets, seed=6))
    assert np.array_equal(a.matrices, b.matrices) and np.array_equal(a.tint, b.tint)
    assert not np.array_equal(a.factors, c.factors)
    assert len(a) == 400


@pytest.mark.parametrize("doc, field", [
    ({"scene": {"leaves": 0}}, "scene.leaves"),
    ({"scene": {"layout": "forest"}}, "scene.layout"),
    ({"scene": {"variation": 0.9}}, "scene.variation"),
    ({"scene": {"colour": 1}}, "scene.colour"),
    ({"species": [{"preset": "no-such-leaf"}]}, "species[0].preset"),
    ({"species": [{"leaf": {"shape": {"a1": [0, "x", 0]}}}]}, "species[0].leaf.shape"),
    ({"species": [{"preset": "ovate", "weight": -1}]}, "species[0].weight"),
    ({"plant": {"phyllotaxis": "spiral-ish"}}, "plant"),
    ({"plant": {"trunk": 3}}, "plant.trunk"),
])
def test_bad_scene_files_name_the_field(tmp_path, doc, field):
    data = {"schema": 1, "scene": {"leaves": 10}, "species": [{"preset": "ovate"}]}
    data.update(doc)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ParamError) as err:
        load_scene(path)
    assert field in str(err.value) and str(path) in str(err.value)


def test_syntax_error_names_file_line(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("schema = 1\n[scene]\nleaves = = 3\n")
    with pytest.raises(ParamError, match=r"bad.toml:3:"):
        load_scene(path)


# -- per-leaf rows (numpy) ----------------------------------------------------------------------
def test_vectorised_rows_match_per_leaf_packing(small):
    from leafview.gpu.layout import write_vein_layers
    from leafview.gpu.scene import pack_scene
    from leafview.gpu.vein_draw import fresh_layers

    rows = pack_scene(small)
    assert rows.dtype == LEAF_BLOCK.dtype and rows.shape == (len(small),)
    params_fields = [name for name, _, _ in LEAF_BLOCK.members if name not in LEAF_BLOCK.derived]
    layers = fresh_layers(small.species)   # each species' vein field layer (leafview.gpu.vein_draw)
    for i in (0, 1, 57, 199, len(small) - 1):
        one = pack_leaf(small.leaf(i))
        one["model"] = small.matrices[i].T
        write_vein_layers(one, layers[small.species_id[i]])   # in the matrix's last row, as the species'
        for name in params_fields:
            if name in ("bend", "bend_axis"):
                continue  # the species' droop (see leafview.scene.spec)
            assert np.allclose(rows[i][name], one[name], rtol=2e-6, atol=1e-7), (i, name)
    assert not np.allclose(rows["xs"][0], rows["xs"][1])  # leaves differ


def test_varied_leaves_keep_their_rows_in_order_and_read_back(tmp_path):
    """acuminate's second and third feet (v̄ 0.45, 0.62) cross under 30 % variation: a varied leaf
    keeps them in order (found by the CLI fuzz run: `export SCENE -o x.leaves.json` wrote leaves
    that did not read back), and the GPU rows keep them the same way."""
    from leafview.core.io import load_leaves, save_leaves
    from leafview.gpu.scene import pack_scene
    from leafview.resources import builtin_presets
    from leafview.scene.spec import VBAR_GAP

    acuminate = LeafParams.load(builtin_presets()["acuminate"])
    scene = build_scene(SceneSpec(species=(acuminate,), leaves=300, plants=3, variation=0.3, seed=4))
    raw = scene.factors[:, [6, 9, 12]] * np.array([row[0] for row in scene.species[0].shape.silhouette[:3]])
    assert (np.diff(np.clip(raw, 0.02, 0.98), axis=1) <= 0).any()      # the case happens in this scene
    leaves = [scene.leaf(i) for i in range(len(scene))]
    vbar = np.array([[row[0] for row in leaf.shape.silhouette] for leaf in leaves])
    assert (np.diff(vbar, axis=1) >= VBAR_GAP - 1e-12).all()
    save_leaves(leaves, tmp_path / "x.leaves.json")
    assert [leaf.shape for leaf in load_leaves(tmp_path / "x.leaves.json")] == [leaf.shape for leaf in leaves]
    np.testing.assert_allclose(pack_scene(scene)["vbar"][:, :3], vbar, rtol=2e-6, atol=1e-6)


def test_batches_respect_the_block_limit():
    from leafview.gpu.scene import SceneLimitError, plan_batches

    per = (128 << 20) // LEAF_BLOCK.nbytes
    plan = plan_batches(1_000_000, 128 << 20)
    assert plan[0] == (0, per) and plan[-1][1] == 1_000_000 and len(plan) == -(-1_000_000 // per)
    assert all(b - a <= (128 << 20) // LEAF_BLOCK.nbytes for a, b in plan)
    assert len(plan_batches(10_000, 1 << 30, max_groups=10)) == -(-10_000 // 640)
    with pytest.raises(SceneLimitError, match="GL_MAX_SHADER_STORAGE_BLOCK_SIZE = 100 bytes"):
        plan_batches(10, 100)


def test_frustum_planes_against_projected_points():
    from leafview.gpu.scene import frustum_planes
    from leafview.scene.camera import frame_view

    cam = frame_view("three-quarter", np.random.default_rng(0).uniform(-1, 1, (50, 3)), (320, 200))
    planes = frustum_planes(cam.proj @ cam.view)
    pts = np.random.default_rng(1).uniform(-6, 6, (4000, 3))
    clip = np.c_[pts, np.ones(len(pts))] @ (cam.proj @ cam.view).T
    inside_clip = np.all(np.abs(clip[:, :3]) <= clip[:, 3:], axis=1)
    inside_planes = np.all(pts @ planes[:, :3].T + planes[:, 3] >= 0, axis=1)
    assert inside_clip.any() and (~inside_clip).any()
    assert np.array_equal(inside_clip, inside_planes)


def test_too_many_leaves_refused():
    with pytest.raises(ParamError, match="scene.leaves"):
        SceneSpec(species=(LeafParams(),), leaves=10**8)


@pytest.mark.parametrize("layout", ["field", "hedge", "plant"])
def test_two_threads_give_the_bytes_of_one(presets, monkeypatch, layout):
    """A large scene builds its twigs, nodes, leaf frames and stem mesh and packs its rows on two
    threads (leafview.scene.threads.in_two_threads): the same bytes as on one thread."""
    import leafview.scene.plants as plants
    import leafview.scene.threads as threads
    from leafview.gpu.scene import pack_rows, pack_scene, species_tables

    spec = _spec(presets, n=3001, layout=layout, plants=1 if layout == "plant" else 9, colour_variation=0.1)
    monkeypatch.setattr(threads, "PARALLEL_MIN", 10**12)
    one = build_scene(spec)
    used: list[object] = []
    spy = threads.background

    def counted(fn, *args):
        used.append(fn)
        return spy(fn, *args)

    monkeypatch.setattr(threads, "background", counted)
    monkeypatch.setattr(plants, "background", counted)
    monkeypatch.setattr(threads, "PARALLEL_MIN", 7)
    monkeypatch.setattr(threads.os, "cpu_count", lambda: 2)
    two = build_scene(spec)
    assert len(used) >= 5   # twigs (where the layout has them), nodes, sort, petiole ends, blades, stems
    for name in ("matrices", "factors", "tint", "species_id"):
        assert getattr(one, name).tobytes() == getattr(two, name).tobytes(), name
    assert one.placement is not None and two.placement is not None
    for name in ("along", "height", "plant", "plant_origins"):
        assert getattr(one.placement, name).tobytes() == getattr(two.placement, name).tobytes(), name
    assert one.stems is not None and two.stems is not None
    assert all(a.tobytes() == b.tobytes() for a, b in zip(one.stems, two.stems))
    assert one.placement.stem_ranges == two.placement.stem_ranges
    records = species_tables(one)[0]
    a = pack_scene(one, 0, len(one), records)
    b = pack_rows(two, 0, len(two), records, np.empty(len(two) + 3, LEAF_BLOCK.dtype))
    assert a.tobytes() == b.tobytes()


# -- GPU ----------------------------------------------------------------------------------------
@pytest.fixture
def ctx(gl):
    return gl.ctx


@pytest.fixture
def drawn(ctx, small):
    from leafview.gpu.instanced import OffscreenTarget
    from leafview.gpu.scene import SceneRenderer

    with SceneRenderer(ctx, small) as r, OffscreenTarget(ctx, (64, 64)) as target:
        target.use()
        yield r
    assert ctx.error == "GL_NO_ERROR"


def test_rows_on_the_gpu_round_trip(drawn, small):
    from leafview.deform.surface import axis_frames
    from leafview.gpu.scene import pack_scene

    back = np.frombuffer(drawn.batches[0].rows.read(), LEAF_BLOCK.dtype)
    rows = pack_scene(small)
    host = without_derived(back)
    for name, _, _ in LEAF_BLOCK.members:
        if name not in LEAF_BLOCK.derived:
            assert np.array_equal(host[name], rows[name]), name
    # the prepare pass wrote each row's branch code (maize ripples and bends, the others do not)
    assert np.array_equal(read_slot(back, "leaf_branches"), branch_code(rows))
    assert len(set(read_slot(back, "leaf_branches").tolist())) > 1
    # the prepare pass filled the derived axis points of every row
    for i in (3, 77):
        pts, _ = axis_frames(small.leaf(i))
        assert np.allclose(back[i]["axis"][:, :3], pts, atol=2e-6)


def test_per_instance_readback_matches_reference(drawn, small):
    from leafview.deform.surface import grid_uv

    # three leaves of each species (maize: rippled and bent) and the last leaf
    picks = [int(i) for k in range(3) for i in np.flatnonzero(small.species_id == k)[:3]] + [len(small) - 1]
    assert len(picks) == 10
    for level in (0, 2):
        got = drawn.capture(picks, level)
        uv = grid_uv(*drawn.grids[level]).astype(np.float64)
        for row, i in zip(got, picks):
            ref = evaluate_leaf(small, i, uv[:, 0], uv[:, 1])
            assert np.abs(row - ref).max() <= 2e-5, (i, level, np.abs(row - ref).max())


def test_bounding_spheres_hold_every_vertex(drawn, small):
    picks = list(range(0, len(small), 37))
    pts = drawn.capture(picks, 0)
    sc = drawn.cull_rows[small.species_id[picks]]
    dist = np.linalg.norm(pts - sc["sphere"][:, None, :3], axis=-1)
    assert (dist <= sc["sphere"][:, None, 3]).all()


@pytest.mark.parametrize("view", ["ground", "three-quarter", "top"])
def test_gpu_culling_and_lod_equal_numpy(ctx, drawn, small, view):
    from leafview.gpu.scene import CullSettings, cull_reference
    from leafview.scene.camera import scene_camera

    size = (640, 360)
    cam = scene_camera(small, size, view)
    if view == "top":  # zoom in so that part of the scene is outside the frustum
        cam = type(cam)(cam.view, cam.proj @ np.diag([3.0, 3.0, 1.0, 1.0]), cam.eye, cam.perspective)
    for settings in (CullSettings(), CullSettings(max_error_px=0.2, min_pixels=4.0), CullSettings(lod=False)):
        drawn.set_camera(cam, size)
        drawn.draw(settings)
        got = drawn.levels()
        ref = cull_reference(small, drawn.cull_rows, cam, size, settings)
        assert np.array_equal(got, ref), (view, settings, np.flatnonzero(got != ref)[:5])
        assert np.array_equal(drawn.level_counts(), [(ref == k).sum() for k in range(len(drawn.grids))])
    if view == "top":
        assert (ref == -1).any() and (ref >= 0).any()


def test_lod_picks_coarser_grids_further_away(ctx, drawn, small):
    from leafview.gpu.scene import CullSettings
    from leafview.scene.camera import scene_camera

    size = (640, 360)
    cam = scene_camera(small, size, "ground")
    drawn.set_camera(cam, size)
    drawn.draw(CullSettings(cull=False))
    lv = drawn.levels()
    assert len(set(lv.tolist())) >= 2
    dist = np.linalg.norm(small.matrices[:, :3, 3] - cam.eye[:3], axis=1) / np.linalg.norm(small.matrices[:, :3, 0], axis=1)
    # level grows with distance (per unit of leaf size): medians are ordered
    meds = [np.median(dist[lv == k]) for k in sorted(set(lv.tolist()))]
    assert meds == sorted(meds)


def test_leaves_of_a_few_pixels_take_the_coarsest_level(ctx, drawn, small):
    """A small image makes the leaves a few pixels long: the culling pass puts some on the 2×3
    grid (4 triangles), exactly where the numpy reference does."""
    from leafview.gpu.scene import LOD_GRIDS, CullSettings, cull_reference
    from leafview.scene.camera import scene_camera

    assert LOD_GRIDS[-1] == (2, 3) and drawn.grids[-1] == (2, 3)
    size = (96, 54)
    cam = scene_camera(small, size, "three-quarter")
    drawn.set_camera(cam, size)
    drawn.draw(CullSettings())
    got = drawn.levels()
    assert np.array_equal(got, cull_reference(small, drawn.cull_rows, cam, size, CullSettings()))
    assert (got == len(LOD_GRIDS) - 1).sum() > 0


def test_lod_switch_moves_the_outline_by_at_most_a_pixel(ctx):
    from leafview.gpu.scene import lod_switch_error

    worst = lod_switch_error(ctx, ("ovate", "lanceolate", "serrate", "maize"))
    assert worst <= 1.5, worst


def test_same_seed_same_image_and_batches_do_not_change_it(ctx, presets):
    from leafview.gpu.scene import SceneRenderer
    from leafview.scene.camera import scene_camera

    scene = build_scene(_spec(presets, n=600, seed=9))
    cam = scene_camera(scene, (128, 96), "three-quarter")
    with SceneRenderer(ctx, scene) as r:
        a = r.render(cam, (128, 96))
    with SceneRenderer(ctx, build_scene(_spec(presets, n=600, seed=9)), max_block_bytes=100 * LEAF_BLOCK.nbytes) as r:
        assert len(r.batches) == 6
        b = r.render(cam, (128, 96))
    assert np.array_equal(a, b)
    assert (a[..., 3] > 0).mean() > 0.05
    assert ctx.error == "GL_NO_ERROR"


def test_reference_image_of_a_small_scene(ctx, presets, request):
    from leafview.gpu.scene import SceneRenderer
    from leafview.scene.camera import scene_camera

    spec = SceneSpec(species=(presets["ovate"], presets["lanceolate"]), layout="plant", leaves=300, seed=2)
    scene = build_scene(spec)
    with SceneRenderer(ctx, scene) as r:
        image = r.render(scene_camera(scene, (128, 128), "three-quarter"), (128, 128))
    assert_matches_reference(image, "scene_plant_three-quarter", request)


# -- the command ----------------------------------------------------------------------------------
def test_cli_renders_and_saves(tmp_path, capsys, gl):
    out, saved = tmp_path / "s.png", tmp_path / "s.toml"
    rc = main(["scene", "--leaves", "500", "--species", "ovate,lanceolate", "--seed", "4", "--size", "160x120",
               "-o", str(out), "--save", str(saved)])
    assert rc == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "500 leaves" in text and "llvmpipe" in text.lower() or "drawn" in text
    from leafview.export.images import read_image

    image, _ = read_image(out)
    assert image.shape == (120, 160, 4) and (image[..., 3] > 0).any()
    spec = load_scene(saved)
    assert spec.leaves == 500 and spec.seed == 4 and [s.name for s in spec.species] == ["ovate", "lanceolate"]


@pytest.mark.parametrize("argv, message", [
    (["--leaves", "0"], "leaf count"),
    (["--species", "ovate,nope"], "'nope'"),
    (["--variation", "2"], "variation"),
    (["--size", "10x10"], "10x10"),
    ([], "nothing to do"),
])
def test_cli_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "x.png"
    args = ["scene", *argv] + (["-o", str(out)] if argv else [])
    try:
        rc = main(args)
    except SystemExit as exc:  # argparse type errors
        rc = exc.code
    assert rc == 2
    assert message in capsys.readouterr().err
    assert not out.exists() and not list(tmp_path.iterdir())


def test_cli_bad_scene_file(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("schema = 1\n[scene]\nlayout = 'forest'\n[[species]]\npreset = 'ovate'\n")
    out = tmp_path / "x.png"
    assert main(["scene", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "scene.layout" in err and not out.exists()


def test_bend_deviation_measures_the_shared_species_droop(presets):
    """A varied bent leaf droops with its species' profile, not its own solve: the deviation is
    reported (non-zero with variation, zero without)."""
    from leafview.scene.spec import bend_deviation

    maize = (presets["maize"],)
    varied = build_scene(SceneSpec(species=maize, leaves=60, seed=3, plants=1))
    plain = build_scene(SceneSpec(species=maize, leaves=60, seed=3, plants=1, variation=0.0, colour_variation=0.0))
    d = bend_deviation(varied, range(10))
    assert 1e-4 < d < 0.1
    assert bend_deviation(plain, range(10)) < 1e-12
