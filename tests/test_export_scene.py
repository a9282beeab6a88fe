"""Scene export against the SceneLike protocol, with a small stand-in scene: shared meshes,
EXT_mesh_gpu_instancing, USD PointInstancer, non-TRS and mirrored copies, stems, bad scenes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import trimesh
from support.gltf_read import read_gltf
from support.validate import usd_errors
from test_export import assert_gltf_clean

from leafview.core.params import LeafParams, Transform
from leafview.errors import UsageError
from leafview.export import export_scene
from leafview.export.mesh import bake
from leafview.export.objply import axis_matrix
from leafview.export.scene import (
    SceneLike,
    compose_trs,
    decompose_trs,
    quat_from_matrix,
)

GRID = (9, 17)
LENGTH = 0.1


@dataclass
class StandInScene:
    """The duck-typed scene interface of leafview.scene.spec.Scene, filled by hand."""

    species: list[LeafParams]
    shape_ids: np.ndarray
    matrices: np.ndarray
    stems: tuple | None = None

    def shapes(self) -> list[LeafParams]:
        return list(self.species)

    def __len__(self) -> int:
        return len(self.shape_ids)


def _random_trs(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.stack([Transform(translation=tuple(rng.uniform(-5, 5, 3)), rotation=tuple(rng.uniform(-180, 180, 3)),
                               scale=float(rng.uniform(0.4, 1.6))).matrix() for _ in range(n)])


def _cylinder(segments: int = 8, height: float = 3.0, radius: float = 0.05):
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], 1)
    pos = np.concatenate([ring * radius, ring * radius + [0, 0, height]]).astype(np.float32)
    nrm = np.concatenate([ring, ring]).astype(np.float32)
    i = np.arange(segments)
    j = (i + 1) % segments
    tris = np.concatenate([np.stack([i, j, i + segments], 1), np.stack([j, j + segments, i + segments], 1)])
    return pos, nrm, tris.astype(np.uint32)


@pytest.fixture
def scene(presets) -> StandInScene:
    """40 ovate (+1 sheared), 5 maize (+1 mirrored), 1 serrate, and a stem."""
    rng = np.random.default_rng(7)
    species = [presets[n].replace(transform=Transform()) for n in ("ovate", "maize", "serrate")]
    ids = np.r_[np.zeros(41), np.ones(6), [2]].astype(np.int32)
    mats = _random_trs(rng, len(ids))
    mats[40, 0, 1] += 0.4                              # shear: not TRS
    mats[46, :3, 0] *= -1                              # mirror: TRS with negative scale
    order = rng.permutation(len(ids))                  # leaves of one shape need not be adjacent
    return StandInScene(species, ids[order], mats[order], _cylinder())


def _expected_world(scene: StandInScene, mesh_by_shape: dict[int, np.ndarray], i: int) -> np.ndarray:
    m = scene.matrices[i]
    return mesh_by_shape[int(scene.shape_ids[i])] @ m[:3, :3].T + m[:3, 3]


def _baked(scene: StandInScene, gl) -> dict[int, np.ndarray]:
    return {k: bake(p, GRID, renderer=gl).positions.astype(np.float64) for k, p in enumerate(scene.shapes())}


def test_stand_in_satisfies_the_protocol(scene):
    assert isinstance(scene, SceneLike)


def test_decompose_trs_round_trip_and_rejects_shear():
    rng = np.random.default_rng(3)
    m = _random_trs(rng, 50)
    m[:10, :3, :3] *= rng.uniform(0.3, 3, (10, 1, 3))          # non-uniform scale is still TRS
    m[10:15, :3, 1] *= -1                                        # mirrored
    t, q, s, err = decompose_trs(m)
    assert err.max() < 1e-12
    assert np.abs(compose_trs(t, q, s) - m).max() < 1e-12
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0)
    shear = np.eye(4)
    shear[0, 2] = 0.2
    assert decompose_trs(shear)[3] > 0.05
    assert decompose_trs(np.diag([1.0, 0.0, 1.0, 1.0]))[3] == np.inf
    # quaternions near 180° (the unstable case of the trace formula)
    r = Transform(rotation=(180.0, 0.0, 0.0)).matrix()[:3, :3]
    assert np.allclose(np.abs(quat_from_matrix(r)), [1, 0, 0, 0], atol=1e-12)


@pytest.mark.usefixtures("gltf_validator")   # installs the Khronos validator on first use
def test_gltf_scene_shares_meshes_and_instances(gl, scene, tmp_path):
    path = export_scene(scene, tmp_path / "scene.glb", resolution=GRID, renderer=gl, length_m=LENGTH)
    report = assert_gltf_clean(path)
    f = read_gltf(path)
    assert f.doc["extensionsRequired"] == ["EXT_mesh_gpu_instancing"]
    names = [m["name"] for m in f.doc["meshes"]]
    assert len(names) == 5 and names[-1] == "stems" and sum("non-TRS" in n for n in names) == 1
    ext_nodes = [n for n in f.doc["nodes"] if "extensions" in n]
    assert len(ext_nodes) == 1 and ext_nodes[0]["mesh"] == 0     # the 40 TRS ovate copies
    # every leaf appears once in the file, where the scene puts it (z-up units -> y-up metres)
    to_file = np.eye(4)
    to_file[:3, :3] = axis_matrix("y") * LENGTH
    baked = _baked(scene, gl)
    drawn = [(mesh, world) for mesh, world, name in f.mesh_instances() if name != "stems"]
    assert len(drawn) == len(scene)
    unmatched = list(range(len(scene)))
    for mesh_id, world in drawn:
        prim = f.doc["meshes"][mesh_id]["primitives"][0]
        pos = f.accessor(prim["attributes"]["POSITION"]).astype(np.float64)
        got = pos @ world[:3, :3].T + world[:3, 3]
        errs = [np.abs(got - _expected_world(scene, baked, i) @ to_file[:3, :3].T).max()
                if len(got) == len(baked[int(scene.shape_ids[i])]) else np.inf for i in unmatched]
        best = int(np.argmin(errs))
        assert errs[best] < 2e-6, errs[best]
        unmatched.pop(best)
    assert unmatched == []
    assert report["info"]["drawCallCount"] >= 9


@pytest.mark.usefixtures("gltf_validator")   # installs the Khronos validator on first use
def test_gltf_scene_as_plain_nodes_opens_in_trimesh(gl, scene, tmp_path):
    path = export_scene(scene, tmp_path / "scene.gltf", resolution=GRID, renderer=gl, length_m=LENGTH,
                        instancing="nodes")
    assert_gltf_clean(path)
    f = read_gltf(path)
    assert "extensionsRequired" not in f.doc
    leaf_nodes = [n for n in f.doc["nodes"] if "mesh" in n and f.doc["meshes"][n["mesh"]]["name"] != "stems"]
    assert len(leaf_nodes) == len(scene)
    assert len({n["mesh"] for n in leaf_nodes}) == 4       # 3 shapes + the sheared copy
    baked = _baked(scene, gl)
    world = np.concatenate([_expected_world(scene, baked, i) for i in range(len(scene))] + [scene.stems[0]])
    expect = world @ axis_matrix("y").T * LENGTH
    loaded = trimesh.load(path, process=False)
    assert np.abs(loaded.bounds - [expect.min(0), expect.max(0)]).max() < 1e-6


def test_usd_scene_point_instancer(gl, scene, tmp_path):
    from pxr import Usd, UsdGeom

    path = export_scene(scene, tmp_path / "scene.usdc", resolution=GRID, renderer=gl, length_m=LENGTH)
    assert usd_errors(path) == []
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(LENGTH)
    root = stage.GetDefaultPrim()
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath(root.GetPath().AppendChild("Leaves")))
    assert inst
    protos = inst.GetPrototypesRel().GetTargets()
    assert [p.name for p in protos] == ["ovate", "maize"]
    ids = np.asarray(inst.GetProtoIndicesAttr().Get())
    assert np.bincount(ids).tolist() == [40, 6]
    xf = np.asarray(inst.ComputeInstanceTransformsAtTime(Usd.TimeCode.Default(), Usd.TimeCode.Default()))
    got = np.transpose(xf, (0, 2, 1))                          # USD row vectors -> column vectors
    for k, shape in enumerate((0, 1)):
        expect = scene.matrices[(scene.shape_ids == shape)]
        expect = expect[np.abs(decompose_trs(expect)[3]) <= 1e-6]
        mine = got[ids == k]
        for m in expect:                                        # each scene matrix has its instance
            assert np.abs(mine - m).max(axis=(1, 2)).min() < 1e-5
    # the sheared ovate and the lone serrate are plain Xforms with the exact matrix
    others = [p for p in root.GetChildren() if p.IsA(UsdGeom.Xform)]
    mats = [np.asarray(UsdGeom.Xformable(p).GetLocalTransformation()).T for p in others]
    for i in np.flatnonzero((scene.shape_ids == 2) | (np.abs(decompose_trs(scene.matrices)[3]) > 1e-6)):
        assert min(np.abs(m - scene.matrices[i]).max() for m in mats) < 1e-12
    stems = UsdGeom.Mesh(stage.GetPrimAtPath(root.GetPath().AppendChild("stems")))
    assert len(stems.GetPointsAttr().Get()) == len(scene.stems[0])


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_obj_ply_scene_world_copies(gl, scene, tmp_path, suffix):
    path = export_scene(scene, tmp_path / f"scene{suffix}", resolution=GRID, renderer=gl, length_m=LENGTH)
    loaded = trimesh.load(path, process=False, force="mesh")
    baked = _baked(scene, gl)
    world = np.concatenate([_expected_world(scene, baked, i) for i in range(len(scene))] + [scene.stems[0]])
    expect = world @ axis_matrix("y").T * LENGTH
    assert len(loaded.vertices) == len(expect)
    assert np.abs(loaded.bounds - [expect.min(0), expect.max(0)]).max() <= 1e-6


@pytest.mark.usefixtures("gltf_validator")   # installs the Khronos validator on first use
def test_distinct_leaves_get_one_mesh_each(gl, presets, tmp_path):
    rng = np.random.default_rng(1)
    shapes = [presets[n].replace(transform=Transform()) for n in ("ovate", "holly", "beech", "willow")]
    scene = StandInScene(shapes, np.arange(4, dtype=np.int32), _random_trs(rng, 4))
    path = export_scene(scene, tmp_path / "d.glb", resolution=GRID, renderer=gl)
    f = read_gltf(path)
    assert len(f.doc["meshes"]) == 4 and "extensionsUsed" in f.doc
    assert "EXT_mesh_gpu_instancing" not in f.doc["extensionsUsed"]
    assert_gltf_clean(path)


@pytest.mark.parametrize("break_it, message", [
    (lambda s: setattr(s, "shape_ids", s.shape_ids + 5), "shape_ids must lie in"),
    (lambda s: s.matrices.__setitem__((3, 0, 0), np.nan), r"matrices\[3\] is not finite"),
    (lambda s: setattr(s, "matrices", s.matrices[:, :3]), "matrices has shape"),
    (lambda s: setattr(s, "stems", (s.stems[0], s.stems[1], s.stems[2] + 100)), "stems: triangle indices"),
    (lambda s: s.stems[0].__setitem__((0, 0), np.inf), "stems: non-finite"),
])
def test_bad_scenes_write_nothing(scene, tmp_path, break_it, message):
    break_it(scene)
    with pytest.raises(UsageError, match=message):
        export_scene(scene, tmp_path / "bad.glb", resolution=GRID, backend="numpy")
    assert list(tmp_path.iterdir()) == []


def test_usd_half_precision_orientations_agree(gl, scene, tmp_path):
    """``orientations`` (quath, for older USD readers) holds the same rotations as
    ``orientationsf`` to half precision."""
    from pxr import Usd, UsdGeom

    path = export_scene(scene, tmp_path / "s.usda", resolution=GRID, renderer=gl)
    stage = Usd.Stage.Open(str(path))
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath(stage.GetDefaultPrim().GetPath().AppendChild("Leaves")))
    half = np.array([[q.GetReal(), *q.GetImaginary()] for q in inst.GetOrientationsAttr().Get()])
    full = np.array([[q.GetReal(), *q.GetImaginary()] for q in inst.GetOrientationsfAttr().Get()])
    assert half.shape == full.shape == (46, 4)
    assert np.abs(half - full).max() < 2e-3 and np.allclose(np.linalg.norm(full, axis=1), 1, atol=1e-6)


def test_export_bench_quick_reports_sizes_and_renderer(gl):
    import json

    from leafview.bench.export import format_table, run

    res = run(quick=True)
    assert res["gl_renderer"] and res["leaves"] > 0
    assert res["distinct_glb_bytes_per_leaf"] > res["shared_glb_bytes_per_leaf"] > 0
    assert res["glb_vs_leaf_json"] > 1 and "µs/leaf" in format_table(res)
    assert res["leaf_json_bytes"] > res["leaf_set_bytes_per_leaf"] > res["leaf_set6_bytes_per_leaf"] > 0
    assert res["glb_vs_leaf_set6"] > res["glb_vs_leaf_set"] > res["glb_vs_leaf_json"]
    json.dumps(res)                                                    # JSON-able


@pytest.mark.usefixtures("gltf_validator")   # installs the Khronos validator on first use
def test_cli_exports_a_scene_file(gl, tmp_path, capsys):
    """``leafview export SCENE.toml -o FILE`` with the scene module's own file format."""
    from leafview.cli import main

    scene_file = tmp_path / "plant.toml"
    scene_file.write_text('schema = 1\n[scene]\nlayout = "plant"\nleaves = 60\nseed = 2\nvariation = 0.0\n'
                          'colour_variation = 0.0\n\n[[species]]\npreset = "beech"\n', encoding="utf-8")
    out = tmp_path / "plant.glb"
    assert main(["export", str(scene_file), "-o", str(out), "--resolution", "5x9", "--instancing", "ext"]) == 0
    assert "(60 leaves, 1 distinct shapes" in capsys.readouterr().out
    assert_gltf_clean(out)
    f = read_gltf(out)
    drawn = [name for _, _, name in f.mesh_instances()]
    assert len(drawn) == 60 + 1 and drawn.count("stems") == 1
    assert main(["export", str(scene_file), "ovate", "-o", str(tmp_path / "x.glb")]) == 2


def test_oversized_glb_is_refused_before_baking(presets, tmp_path):
    leaf = presets["ovate"]
    n = 3000
    scene = StandInScene([leaf] * n, np.arange(n, dtype=np.int32), np.repeat(np.eye(4)[None], n, axis=0))
    with pytest.raises(UsageError, match="above the format's 4 GiB limit"):
        export_scene(scene, tmp_path / "huge.glb", resolution=(513, 1025), backend="numpy")
    assert list(tmp_path.iterdir()) == []
