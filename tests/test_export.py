"""Single-leaf export: baking (pinched tips, GPU readback = reference), glTF/GLB, OBJ, PLY and
USD files checked by their own validators, re-imported and compared with the reference
evaluation; bad input and failures leave no file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
from support.gltf_read import read_gltf
from support.validate import ValidatorMissing, gltf_report, usd_errors

import leafview
from leafview.cli import main
from leafview.core.params import Transform
from leafview.deform.surface import grid_indices
from leafview.errors import UsageError
from leafview.export import bake, export_leaf, format_of
from leafview.export.mesh import LeafMesh, NonFiniteMesh, pinch_triangles
from leafview.export.objply import axis_matrix
from tests.conftest import require_or_skip

# presets covering plain, jitter, ripples and bending
SAMPLE = ("ovate", "serrate", "maize", "willow")
ALLOWED_INFOS = {"UNSUPPORTED_EXTENSION", "UNUSED_OBJECT"}   # see docs/export.md


def gltf_validate(path: Path) -> dict:
    try:
        return gltf_report(path)
    except ValidatorMissing as exc:
        require_or_skip(f"the Khronos glTF validator is unavailable: {exc}")
        raise


def assert_gltf_clean(path: Path) -> dict:
    report = gltf_validate(path)
    issues = report["issues"]
    messages = [(m["code"], m.get("pointer")) for m in issues["messages"]]
    assert issues["numErrors"] == 0, messages
    assert issues["numWarnings"] == 0, messages
    assert {m["code"] for m in issues["messages"]} <= ALLOWED_INFOS | {"UNSUPPORTED_EXTENSION"}, messages
    return report


def no_leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".part" in p.name)


# -- baking ----------------------------------------------------------------------------------
@pytest.mark.parametrize("grid", [(2, 3), (5, 4), (33, 65)])
def test_pinch_triangles_are_exactly_the_degenerate_ones(presets, grid):
    nu, nv = grid
    mask = pinch_triangles(nu, nv)
    tris = grid_indices(nu, nv)
    row = tris // nu
    two_on_tip = [(np.sum(r == 0) >= 2) or (np.sum(r == nv - 1) >= 2) for r in row]
    assert mask.tolist() == two_on_tip
    mesh = bake(presets["ovate"], grid, backend="numpy")
    assert mesh.n_vertices == nu * nv - 2
    assert mesh.n_triangles == 2 * (nu - 1) * (nv - 1) - 2 * (nu - 1)
    assert np.array_equal(np.unique(mesh.indices), np.arange(mesh.n_vertices))   # no unused vertex


def test_baked_triangles_have_area_and_unit_normals(presets):
    for name, params in presets.items():
        mesh = bake(params, backend="numpy")
        t = mesh.indices
        assert (t[:, 0] != t[:, 1]).all() and (t[:, 1] != t[:, 2]).all() and (t[:, 0] != t[:, 2]).all()
        p = mesh.positions.astype(np.float64)
        area = 0.5 * np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1)
        if params.lobes.enabled:
            # a lobed leaf's welded grid keeps the collinear triangles where a tie runs on past a
            # skeleton tip (leafview.botany.lobe_sweep.weld_grid: dropping them would slit the
            # sheet): a few slivers, no coincident corners
            assert (area <= 1e-9).mean() < 0.01, name
            assert len(np.unique(mesh.positions, axis=0)) == mesh.n_vertices, name
        else:
            assert area.min() > 1e-9, name
        assert np.abs(np.linalg.norm(mesh.normals, axis=1) - 1).max() < 1e-6, name
        # vertex normals agree with the counter-clockwise winding (front = +z side)
        face = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
        agree = np.einsum("ij,ij->i", face, mesh.normals[t[:, 0]]) > 0
        assert agree.mean() > 0.97, (name, agree.mean())


def test_texture_coordinates_follow_u_and_v(presets):
    mesh = bake(presets["ovate"], (5, 9), backend="numpy")
    assert np.allclose(mesh.st[:, 0], (1 - mesh.uv[:, 0]) / 2) and np.allclose(mesh.st[:, 1], mesh.uv[:, 1])
    assert mesh.st.min() == 0.0 and mesh.st.max() == 1.0


def test_gpu_bake_equals_reference_bake(gl, presets):
    for name in presets:
        gpu = bake(presets[name], (17, 33), backend="gpu", renderer=gl)
        ref = bake(presets[name], (17, 33), backend="numpy")
        assert np.array_equal(gpu.indices, ref.indices)
        assert np.abs(gpu.positions - ref.positions).max() <= 2e-5, name
        assert np.abs(gpu.normals - ref.normals).max() <= 1e-4, name


def test_nonfinite_vertices_are_refused_before_writing(tmp_path, presets, monkeypatch):
    import leafview.export.mesh as bake_mod

    real = bake_mod.tessellate

    def broken(params, nu, nv, **kwargs):
        m = real(params, nu, nv, **kwargs)
        m.vertices[nu * 3 + 2] = np.nan
        return m

    monkeypatch.setattr(bake_mod, "tessellate", broken)
    with pytest.raises(NonFiniteMesh, match=r"non-finite vertex .* at \(u, v\)"):
        bake(presets["ovate"], backend="numpy")
    out = tmp_path / "leaf.glb"
    assert main(["export", "ovate", "-o", str(out), "--backend", "numpy"]) == 2
    assert not out.exists() and not list(tmp_path.iterdir())


def test_writers_refuse_nonfinite_meshes(tmp_path, presets):
    from leafview.export import write
    from leafview.export.scene import leaf_scene

    good = bake(presets["ovate"], (5, 5), backend="numpy")
    pos = good.positions.copy()
    pos[3, 1] = np.inf
    bad = LeafMesh(pos, good.normals, good.st, good.uv, good.indices, "bad")
    for suffix in (".glb", ".gltf", ".obj", ".ply", ".usda", ".usdc"):
        with pytest.raises(NonFiniteMesh, match="bad: non-finite vertex"):
            write(leaf_scene(presets["ovate"], bad), tmp_path / f"x{suffix}")
    assert list(tmp_path.iterdir()) == []


# -- glTF ------------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
@pytest.mark.parametrize("back_faces", ["primitive", "double-sided"])
@pytest.mark.usefixtures("gltf_validator")   # installs the Khronos validator on first use
def test_gltf_passes_khronos_validator(gl, presets, tmp_path, suffix, back_faces):
    for name in SAMPLE[:2] if back_faces == "double-sided" else SAMPLE:
        path = export_leaf(presets[name], tmp_path / f"{name}{suffix}", renderer=gl, back_faces=back_faces)
        report = assert_gltf_clean(path)
        info = report["info"]
        assert info["drawCallCount"] == (2 if back_faces == "primitive" else 1)
        assert info["totalTriangleCount"] == (2 if back_faces == "primitive" else 1) * 4032


def test_glb_reimport_matches_reference_evaluation(gl, presets, tmp_path):
    """Vertices in the file, at the (u, v) recovered from its texture coordinates, equal the
    float64 reference L(u, v) (and the leaf's transform places them as in leafview's world)."""
    for name in SAMPLE:
        params = presets[name].replace(transform=Transform(translation=(0.5, -1.0, 2.0), rotation=(10, 20, 30),
                                                           scale=1.5))
        path = export_leaf(params, tmp_path / f"{name}.glb", renderer=gl, length_m=0.25)
        f = read_gltf(path)
        prim = f.doc["meshes"][0]["primitives"][0]
        pos = f.accessor(prim["attributes"]["POSITION"]).astype(np.float64)
        st = f.accessor(prim["attributes"]["TEXCOORD_0"]).astype(np.float64)
        u, v = 1.0 - 2.0 * st[:, 0], 1.0 - st[:, 1]
        ref = leafview.evaluate(params, np.clip(u, -1, 1), np.clip(v, 0, 1))
        assert np.abs(pos - ref).max() <= 2e-5, name
        nrm = f.accessor(prim["attributes"]["NORMAL"]).astype(np.float64)
        assert np.abs(nrm - leafview.normals(params, np.clip(u, -1, 1), np.clip(v, 0, 1))).max() <= 1e-4
        back = f.doc["meshes"][0]["primitives"][1]
        assert back["attributes"]["POSITION"] == prim["attributes"]["POSITION"]
        assert np.array_equal(f.accessor(back["attributes"]["NORMAL"]), -f.accessor(prim["attributes"]["NORMAL"]))
        assert np.array_equal(f.accessor(back["indices"]).reshape(-1, 3),
                              f.accessor(prim["indices"]).reshape(-1, 3)[:, ::-1])
        # world: leafview z-up leaf lengths -> glTF y-up metres
        (_, world, _), = list(f.mesh_instances())
        m = params.transform.matrix()
        expect = (ref @ m[:3, :3].T + m[:3, 3]) @ axis_matrix("y").T * 0.25
        got = pos @ world[:3, :3].T + world[:3, 3]
        assert np.abs(got - expect).max() <= 1e-5
        # an independent importer sees the same world-space leaf
        loaded = trimesh.load(path, process=False)
        assert np.allclose(loaded.bounds, [expect.min(0), expect.max(0)], atol=1e-6)


def test_gltf_materials_carry_both_sides_and_translucency(gl, presets, tmp_path):
    params = presets["beech"]
    f = read_gltf(export_leaf(params, tmp_path / "beech.gltf", renderer=gl))
    front, back = (f.doc["materials"][p["material"]] for p in f.doc["meshes"][0]["primitives"])
    mat = params.material
    assert np.allclose(front["pbrMetallicRoughness"]["baseColorFactor"][:3], mat.front)
    assert np.allclose(back["pbrMetallicRoughness"]["baseColorFactor"][:3], mat.back)
    assert front["doubleSided"] is False and back["doubleSided"] is False
    ext = front["extensions"]["KHR_materials_diffuse_transmission"]
    assert ext["diffuseTransmissionFactor"] == pytest.approx(mat.translucency)
    assert "KHR_materials_diffuse_transmission" in f.doc["extensionsUsed"]
    assert "extensionsRequired" not in f.doc        # a loader without it still shows the leaf


# -- OBJ / PLY --------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".obj", ".ply"])
@pytest.mark.parametrize("up", ["y", "z"])
def test_obj_ply_trimesh_round_trip(gl, presets, tmp_path, suffix, up):
    params = presets["willow"].replace(transform=Transform(translation=(1, 2, 3), rotation=(0, 0, 90)))
    mesh = bake(params, renderer=gl)
    path = export_leaf(params, tmp_path / f"w{suffix}", renderer=gl, up=up, length_m=0.2)
    loaded = trimesh.load(path, process=False)
    m = params.transform.matrix()
    expect = (mesh.positions.astype(np.float64) @ m[:3, :3].T + m[:3, 3]) @ axis_matrix(up).T * 0.2
    assert loaded.vertices.shape == (mesh.n_vertices, 3)
    assert loaded.faces.shape == (mesh.n_triangles, 3)
    assert np.abs(loaded.bounds - [expect.min(0), expect.max(0)]).max() <= 1e-6
    assert np.abs(loaded.vertices - expect).max() <= 1e-6
    assert np.array_equal(loaded.faces, mesh.indices)
    assert np.allclose(loaded.visual.uv, mesh.st, atol=1e-7)


# -- USD -------------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_usd_validates_and_reads_back(gl, presets, tmp_path, suffix):
    from pxr import Usd, UsdGeom, UsdShade

    params = presets["holly"].replace(transform=Transform(translation=(0, 0, 1), rotation=(0, 30, 0)))
    mesh = bake(params, renderer=gl)
    path = export_leaf(params, tmp_path / f"holly{suffix}", renderer=gl, length_m=0.07)
    assert usd_errors(path) == []
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.07)
    root = stage.GetDefaultPrim()
    assert root.IsValid() and root.GetName() == "holly"
    meshes = {p.GetName(): UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)}
    assert set(meshes) == {"front", "back"}
    front, back = meshes["front"], meshes["back"]
    assert np.array_equal(np.asarray(front.GetPointsAttr().Get()), mesh.positions)
    assert np.array_equal(np.asarray(front.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3), mesh.indices)
    assert back.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded
    assert np.array_equal(np.asarray(back.GetNormalsAttr().Get()), -mesh.normals)
    assert front.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
    world = np.asarray(UsdGeom.Xformable(front.GetPrim()).ComputeLocalToWorldTransform(Usd.TimeCode.Default())).T
    assert np.abs(world - params.transform.matrix()).max() < 1e-12
    colours = {}
    for name, m in meshes.items():
        material = UsdShade.MaterialBindingAPI(m.GetPrim()).ComputeBoundMaterial()[0]
        shader = UsdShade.Shader(stage.GetPrimAtPath(material.GetPath().AppendChild("PreviewSurface")))
        colours[name] = tuple(shader.GetInput("diffuseColor").Get())
        assert material.GetPrim().GetAttribute("leafview:translucency").Get() == pytest.approx(params.material.translucency)
    assert np.allclose(colours["front"], params.material.front) and np.allclose(colours["back"], params.material.back)


def test_usd_validation_catches_a_broken_stage(tmp_path):
    """The validators really run: a stage without the required metadata and with a bad mesh is
    reported."""
    from pxr import Usd, UsdGeom

    path = tmp_path / "bad.usda"
    stage = Usd.Stage.CreateNew(str(path))
    mesh = UsdGeom.Mesh.Define(stage, "/m")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 7])
    stage.GetRootLayer().Save()
    errors = "\n".join(usd_errors(path))
    assert "MissingUpAxisMetadata" in errors and "MissingMetersPerUnitMetadata" in errors
    assert "/m:" in errors


# -- command line ----------------------------------------------------------------------------
def test_cli_writes_every_format(gl, tmp_path, capsys):
    for suffix in (".glb", ".gltf", ".obj", ".ply", ".usda", ".usdc"):
        out = tmp_path / f"leaf{suffix}"
        assert main(["export", "maize", "-o", str(out), "--resolution", "9x17"]) == 0
        assert out.stat().st_size > 0 and format_of(out)
    text = capsys.readouterr().out
    assert "wrote" in text and "151 vertices, 240 triangles" in text
    assert no_leftovers(tmp_path) == []


def test_cli_directory_of_presets(gl, tmp_path):
    out = tmp_path / "leaves"
    assert main(["export", "ovate", "holly", "maize", "-o", str(out), "--format", "usdc", "-q"]) == 0
    maps = [f"{name}_{kind}.png" for name in ("holly", "maize", "ovate")
            for kind in ("back_basecolor", "back_normal", "basecolor", "normal")]   # the presets' veins, baked
    assert sorted(p.name for p in out.iterdir()) == sorted(["holly.usdc", "maize.usdc", "ovate.usdc", *maps])
    plain = tmp_path / "plain"
    assert main(["export", "ovate", "holly", "-o", str(plain), "--format", "usdc", "--veins", "off", "-q"]) == 0
    assert sorted(p.name for p in plain.iterdir()) == ["holly.usdc", "ovate.usdc"]


@pytest.mark.parametrize("argv, message", [
    (["ovate", "-o", "{d}/x.stl"], "unknown export format '.stl'"),
    (["nosuch", "-o", "{d}/x.glb"], "no such file, directory or built-in preset"),
    (["ovate", "-o", "{d}/x.glb", "--format", "obj"], "but --format obj was given"),
    (["ovate", "holly", "-o", "{d}/x.glb"], "need -o DIR"),
    (["{d}/broken.toml", "-o", "{d}/x.glb"], "broken.toml: shape.silhouette[1][0]"),
])
def test_cli_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, argv, message):
    (tmp_path / "broken.toml").write_text('schema = 1\n[shape]\nsilhouette = [[0.3, 0.4, 0], [0.2, 0.4, 0], '
                                          '[0.7, 0.2, 0]]\na1 = [0, 0.3, 0]\na2 = [0, 0.6, 0]\n'
                                          'zf = [0, 0, 0]\nzg = [0, 0, 0]\n')
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["export", *[a.format(d=tmp_path) for a in argv]]) == 2
    assert message in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


@pytest.mark.parametrize("argv", [["--resolution", "4x2"], ["--length-m", "-1"], ["--resolution", "big"]])
def test_cli_bad_options_exit_2(tmp_path, argv):
    with pytest.raises(SystemExit) as exc:
        main(["export", "ovate", "-o", str(tmp_path / "x.glb"), *argv])
    assert exc.value.code == 2
    assert list(tmp_path.iterdir()) == []


def test_failed_write_keeps_the_old_file(gl, tmp_path, monkeypatch):
    out = tmp_path / "leaf.glb"
    out.write_bytes(b"old")
    import leafview.export.gltf as gltf_mod

    def explode(doc, blob):
        raise UsageError("simulated failure while packing the GLB")

    monkeypatch.setattr(gltf_mod, "_glb", explode)
    assert main(["export", "ovate", "-o", str(out)]) == 2
    assert out.read_bytes() == b"old" and no_leftovers(tmp_path) == []


def test_gltf_json_is_plain_json(gl, presets, tmp_path):
    path = export_leaf(presets["ovate"], tmp_path / "ovate.gltf", renderer=gl)
    doc = json.loads(path.read_text())
    assert doc["asset"]["version"] == "2.0"
    acc = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    assert len(acc["min"]) == 3 and len(acc["max"]) == 3
    assert all(v["byteOffset"] % 4 == 0 for v in doc["bufferViews"])


def test_cli_without_gl_suggests_the_numpy_backend(tmp_path, monkeypatch, capsys):
    import leafview.export.mesh as mesh
    from leafview.errors import GLUnavailable

    def no_gl():
        raise GLUnavailable("no EGL here")

    monkeypatch.setattr(mesh, "default_renderer", no_gl)   # where the baker looks it up
    out = tmp_path / "leaf.glb"
    assert main(["export", "ovate", "-o", str(out)]) == 1
    assert "--backend numpy" in capsys.readouterr().err and not out.exists()
    assert main(["export", "ovate", "-o", str(out), "--backend", "numpy", "-q"]) == 0
    assert out.stat().st_size > 0
