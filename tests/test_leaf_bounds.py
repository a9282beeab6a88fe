"""Leaf sets at scale: the culling rows computed on the GPU (leaf_bounds.comp) against their numpy
reference, the vectorised packing of per-leaf shapes against the per-leaf packer, the cantilever
solved for many leaves at once against the single-leaf solve, and the vectorised transforms."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

from leafview.core.params import Bending, Jitter, LeafParams, Transform
from leafview.gpu.layout import pack_leaves, ripple_keys
from leafview.scene.spec import SceneSpec, build_scene, scene_from_leaves, transform_matrices
from leafview.shapes import shapes_params


def _mixed_leaves(presets: dict[str, LeafParams], n: int = 24, seed: int = 3) -> list[LeafParams]:
    """Placed leaves that take every branch of the leaf shader: jitter (two seeds), ripples, bends
    with and without a petiole, an extended silhouette, one-sided halves; most shapes varied."""
    extended = shapes_params("elliptic-concave-extended", polish=False)
    base = presets["ovate"]
    special = [
        extended,
        extended.replace(shape=dataclasses.replace(extended.shape, half=1)),
        base.replace(shape=dataclasses.replace(base.shape, half=-1),
                     jitter=Jitter(enabled=True, seed=3, amplitude=0.04, density=31.0)),
        presets["serrate"].replace(bending=Bending(load=8.0, twist=35.0, petiole_length=0.1)),
        presets["willow"],
    ]
    species = (presets["maize"], presets["holly"], presets["lanceolate"], presets["beech"])
    placed = build_scene(SceneSpec(species=species, leaves=n, seed=seed, plants=6)).placed_leaves()
    rng = np.random.default_rng(seed)
    for leaf in special:
        t = Transform(translation=tuple(rng.uniform(-3, 3, 3)), rotation=tuple(rng.uniform(-180, 180, 3)),
                      scale=float(rng.uniform(0.5, 1.5)))
        placed.append(leaf.replace(transform=t))
    return placed


@pytest.fixture(scope="module")
def leaf_set(presets) -> list[LeafParams]:
    return _mixed_leaves(presets)


# -- packing ---------------------------------------------------------------------------------------
def test_species_rows_equal_the_per_leaf_packer(leaf_set):
    from leafview.gpu.scene import species_tables
    from leafview.gpu.vein_draw import fresh_layers

    scene = scene_from_leaves(leaf_set)
    recs, table, keys = species_tables(scene)
    ref, ref_table = pack_leaves(scene.species, vein_layers=fresh_layers(scene.species))
    assert recs.tobytes() == ref.tobytes()
    assert np.array_equal(table, ref_table) and len(table) > 1
    assert keys == ripple_keys(scene.species) and len(keys) > 1
    assert (recs["bend"] != 0).any(axis=(1, 2)).sum() >= 3      # the bent leaves got their profiles


def test_rows_of_a_varied_scene_in_chunks_and_into_a_reused_array(presets):
    """pack_scene over several of its chunks, fresh or into a larger array, equals the per-leaf
    packer of each leaf's own varied shape."""
    from leafview.gpu.layout import LEAF_BLOCK, pack_leaf, write_vein_layers
    from leafview.gpu.scene import _PACK_CHUNK, pack_scene, species_tables
    from leafview.gpu.vein_draw import fresh_layers

    scene = build_scene(SceneSpec(species=(presets["ovate"], presets["holly"], presets["lanceolate"]),
                                  leaves=2 * _PACK_CHUNK + 300, seed=9, plants=5))
    records = species_tables(scene)[0]
    start, stop = 100, len(scene) - 7
    rows = pack_scene(scene, start, stop, records)
    out = np.zeros(len(scene), LEAF_BLOCK.dtype)
    again = pack_scene(scene, start, stop, records, out=out)
    assert again.base is out or again.base is out.base
    assert rows.tobytes() == again.tobytes() and len(rows) == stop - start > 2 * _PACK_CHUNK
    fields = [name for name, _, _ in LEAF_BLOCK.members if name not in LEAF_BLOCK.derived]
    for i in (start, start + _PACK_CHUNK - 1, start + _PACK_CHUNK, stop - 1):
        one = pack_leaf(scene.leaf(i))
        one["model"] = scene.matrices[i].T
        write_vein_layers(one, fresh_layers(scene.species)[scene.species_id[i]])   # the species' vein field layer
        for name in fields:
            assert np.allclose(rows[i - start][name], one[name], rtol=2e-6, atol=1e-7), (i, name)
    assert len(set(rows["xs"][:, 0].tolist())) > 100       # leaves differ


def test_scene_from_leaves_keeps_each_leaf_in_its_own_frame(leaf_set):
    # scene_from_leaves copies each leaf field for field with the transform swapped (spec._unplaced),
    # which skips LeafParams.__post_init__: that holds while the check reads nothing of the transform
    assert "transform" not in inspect.getsource(LeafParams.__post_init__)
    scene = scene_from_leaves(leaf_set)
    assert len(scene) == len(leaf_set) == len(scene.species)
    for leaf, sp, m in zip(leaf_set, scene.species, scene.matrices):
        assert sp == leaf.replace(transform=Transform())
        assert np.array_equal(m, leaf.transform.matrix())


def test_transform_matrices_equal_the_single_transform():
    rng = np.random.default_rng(7)
    transforms = [Transform(translation=tuple(rng.normal(size=3) * 100), rotation=tuple(rng.uniform(-720, 720, 3)),
                            scale=float(rng.uniform(1e-3, 1e3))) for _ in range(200)] + [Transform()]
    got = transform_matrices(transforms)
    assert got.shape == (201, 4, 4)
    assert np.array_equal(got, np.stack([t.matrix() for t in transforms]))


# -- bending ---------------------------------------------------------------------------------------
def test_bend_profiles_walked_together_equal_each_leaf_walked_alone(presets):
    """The batched walk groups leaves by silhouette rows and petiole: each leaf's profile must not
    depend on the leaves it is walked with."""
    from leafview.deform.beam import bend_profiles

    rng = np.random.default_rng(11)
    leaves = [presets["maize"], presets["willow"]]
    for name in ("ovate", "curled", "serrate"):
        for _ in range(6):
            b = Bending(load=float(rng.uniform(0.0, 30.0)), direction=tuple(rng.normal(size=3)),
                        stiffness=float(rng.uniform(0.1, 5.0)), twist=float(rng.uniform(-90, 90)),
                        petiole_length=float(rng.choice([0.0, 0.1, 0.3])), petiole_stiffness=float(rng.uniform(0.2, 3)))
            t = Transform(rotation=tuple(rng.uniform(-180, 180, 3)), scale=float(rng.uniform(0.5, 2.0)))
            leaves.append(presets[name].replace(bending=b, transform=t))
    extended = shapes_params("elliptic-concave-extended", polish=False)     # 5 rows, tilted
    assert extended.shape.extended and any(extended.shape.tilt)
    leaves += [presets["ovate"].replace(bending=Bending(load=5.0, direction=(0.0, 1.0, 0.0))),  # along the midrib
               presets["ovate"].replace(bending=Bending(twist=30.0)),                         # twist only
               extended.replace(bending=Bending(load=12.0, twist=-20.0)),
               extended.replace(bending=Bending(load=4.0, petiole_length=0.2))]
    got = bend_profiles(leaves)
    assert len(got) == len(leaves)
    bent = 0
    for leaf, p in zip(leaves, got):
        ref = bend_profiles([leaf])[0]
        for a, b in ((p.axis, ref.axis), (p.phi, ref.phi), (p.delta, ref.delta)):
            assert np.allclose(a, b, rtol=0.0, atol=1e-12)
        assert p.twist == pytest.approx(ref.twist, abs=1e-15)
        bent += bool(np.abs(ref.phi).max() > 1e-3)
    assert bent >= 10     # most of them really bend


# -- the culling rows on the GPU -------------------------------------------------------------------
@pytest.mark.gl
@pytest.mark.parametrize("grids", [((9, 17), (5, 9), (3, 5)), ((7, 12), (4, 5)), ((6, 9),)],
                         ids=["default", "not-nested", "one-level"])
def test_gpu_cull_rows_match_numpy_for_every_branch(gl, leaf_set, grids):
    from leafview.gpu.bounds import bounds_defines
    from leafview.gpu.scene import SceneRenderer, species_cull

    nested = bounds_defines(grids)["BOUNDS_NESTED"]
    assert nested == (grids != ((7, 12), (4, 5)))
    scene = scene_from_leaves(leaf_set)
    with SceneRenderer(gl.ctx, scene, grids=grids) as r:
        got = r.cull_rows
        ref = species_cull(scene, r.grids)
        assert np.allclose(got["sphere"], ref["sphere"], rtol=0.0, atol=2e-5)
        assert np.allclose(got["lod_error"], ref["lod_error"], rtol=0.0, atol=2e-5)
        assert (got["lod_error"][:, 1:len(grids)] > 1e-3).all()
        # every vertex the leaf shader draws, at every level, lies in the sphere
        picks = list(range(len(scene)))
        for level in range(len(grids)):
            pts = r.capture(picks, level)
            dist = np.linalg.norm(pts - got["sphere"][:, None, :3], axis=-1)
            assert (dist <= got["sphere"][:, None, 3]).all(), level


@pytest.mark.gl
def test_gpu_cull_rows_in_chunks(gl, leaf_set):
    """Records measured a few at a time (a small storage block) give the same rows."""
    from leafview.gpu.bounds import LeafBounds
    from leafview.gpu.layout import LEAF_BLOCK, feature_defines
    from leafview.gpu.resources import GpuResources, JitterTable
    from leafview.gpu.scene import LOD_GRIDS, species_tables

    records, table, keys = species_tables(scene_from_leaves(leaf_set))
    with GpuResources(gl.ctx) as res:
        jitter, ripples = JitterTable(gl.ctx, table), res.ripple_pass()
        try:
            ripples.update(keys)
            jitter.use()
            ripples.bind()
            bounds = LeafBounds(gl.ctx, res.programs, res.prepare, LOD_GRIDS)
            whole = bounds.run(records, 0.1, feature_defines(records))
            parts = bounds.run(records, 0.1, feature_defines(records), block_limit=7 * LEAF_BLOCK.nbytes)
        finally:
            jitter.release()
            ripples.release()
    assert len(records) > 21 and whole.tobytes() == parts.tobytes()
    assert (whole["sphere"][:, 3] > 0.1).all()


@pytest.mark.gl
def test_gpu_cull_rows_of_varied_species(gl, presets):
    """A built scene: one row per species, widened for the leaves' variation."""
    from leafview.gpu.scene import SceneRenderer, species_cull

    scene = build_scene(SceneSpec(species=(presets["ovate"], presets["willow"], presets["holly"]), leaves=120,
                                  seed=3, plants=6, variation=0.3))
    with SceneRenderer(gl.ctx, scene) as r:
        got = r.cull_rows
    ref = species_cull(scene, r.grids)
    assert len(got) == 3
    assert np.allclose(got["sphere"], ref["sphere"], rtol=0.0, atol=2e-5)
    assert np.allclose(got["lod_error"], ref["lod_error"], rtol=0.0, atol=2e-5)
    plain = species_cull(scene_from_leaves(list(scene.species)), r.grids)
    assert (ref["sphere"][:, 3] > plain["sphere"][:, 3] + 0.05).all()


def test_grid_defines_refuse_levels_that_do_not_fit():
    from leafview.gpu.bounds import MAX_COARSE_SAMPLES, bounds_defines

    d = bounds_defines(((9, 17), (5, 9), (3, 5)))
    assert d["BOUNDS_NESTED"] == 1 and (d["BOUNDS_SU1"], d["BOUNDS_SV1"], d["BOUNDS_SU2"], d["BOUNDS_SV2"]) == (2, 2, 4, 4)
    assert bounds_defines(((2049, 2049),))["BOUNDS_NESTED"] == 0        # one big level: evaluated twice, not kept
    with pytest.raises(ValueError, match=str(MAX_COARSE_SAMPLES)):
        bounds_defines(((80, 80), (33, 33)))
    with pytest.raises(ValueError, match="between 1 and 4"):
        bounds_defines(())
