"""The venation mesh (``export --mesh cdt``): a constrained Delaunay triangulation whose edges hold
every vein of order <= 2, at least 20° away from sharp input angles, one sheet with one boundary
loop, (u, v) recovered for every vertex; its baked vein textures (base colour, normal maps with
their tangent frame) in glTF, USD, OBJ and PLY files that the formats' validators pass; bad options
refused with exit 2 and nothing written."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
import trimesh
from support.gltf_read import read_gltf
from support.validate import usd_errors
from test_export import assert_gltf_clean

import leafview.cli.export as cli_export
import leafview.export.vein_maps as vein_maps
from leafview.botany.vein_field import vein_field
from leafview.botany.vein_shading import major_width, vein_albedo, vein_strength
from leafview.botany.venation import vein_tree
from leafview.cli import main
from leafview.core.blade import blade_partials
from leafview.core.colour import srgb_to_linear
from leafview.core.io import save_params
from leafview.deform.surface import vein_grid_uv
from leafview.errors import UsageError
from leafview.export.cdt import (
    MAX_ORDER,
    bake_cdt,
    check_max_area,
    check_min_angle,
    leaf_plane,
    near_sharp,
    triangle_angles,
    triangulate_leaf,
)
from leafview.export.vein_maps import bake_vein_maps, normal_map, tangents

KINDS = ("ovate", "deltoid", "maize")          # pinnate, palmate, parallel


@pytest.fixture(autouse=True)
def small_maps(monkeypatch):
    """Vein textures of 64 texels a side in the file tests (the default 512 costs seconds)."""
    monkeypatch.setattr(vein_maps, "MAPS_SIZE", 64)


def _rim(tris: np.ndarray) -> np.ndarray:
    """The vertices on edges that only one triangle has."""
    key = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(key, axis=0, return_counts=True)
    return np.unique(uniq[count == 1])


@pytest.fixture(scope="module")
def meshes(presets):
    return {name: triangulate_leaf(presets[name]) for name in KINDS}


def _edges(tris: np.ndarray) -> set[tuple[int, int]]:
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    return set(map(tuple, np.sort(e, axis=1).tolist()))


# -- the triangulation -------------------------------------------------------------------------
@pytest.mark.parametrize("name", KINDS)
def test_every_constraint_segment_is_a_union_of_mesh_edges(meshes, name):
    cdt = meshes[name]
    edges = _edges(cdt.triangles)
    pslg = cdt.pslg
    assert (pslg.order <= MAX_ORDER).all() and (pslg.markers == 2).sum() > 50
    for a, b in pslg.points[pslg.segments]:
        d = b - a
        t = (cdt.points - a) @ d / (d @ d)
        off = np.abs((cdt.points[:, 0] - a[0]) * d[1] - (cdt.points[:, 1] - a[1]) * d[0]) / np.linalg.norm(d)
        on = np.flatnonzero((off < 1e-10) & (t > -1e-9) & (t < 1 + 1e-9))
        chain = on[np.argsort(t[on])]
        assert len(chain) >= 2 and np.isclose(t[chain[0]], 0, atol=1e-9) and np.isclose(t[chain[-1]], 1, atol=1e-9)
        for p, q in zip(chain[:-1], chain[1:]):
            assert (min(p, q), max(p, q)) in edges


@pytest.mark.parametrize("name", KINDS)
def test_every_vein_of_order_two_or_less_is_in_the_graph(meshes, presets, name):
    """Each vein's (u, v) samples lie on the constraint edges (snapped ends excepted)."""
    cdt = meshes[name]
    plane = leaf_plane(presets[name], cdt.plane)
    seg = cdt.pslg.points[cdt.pslg.segments]
    veins = [v for v in vein_tree(presets[name]) if v.order <= MAX_ORDER]
    assert veins
    for vein in veins:
        p = plane.forward(vein.uv[1:-1])
        a, d = seg[:, 0], seg[:, 1] - seg[:, 0]
        t = np.clip(np.einsum("pkj,kj->pk", p[:, None] - a, d) / np.einsum("kj,kj->k", d, d), 0, 1)
        dist = np.linalg.norm(p[:, None] - a - t[..., None] * d, axis=2).min(axis=1)
        assert dist.max() < 1e-9


@pytest.mark.parametrize("name", KINDS)
def test_angles_are_at_least_20_degrees_away_from_sharp_input_angles(meshes, name):
    cdt = meshes[name]
    angles = triangle_angles(cdt.points, cdt.triangles).min(axis=1)
    away = ~near_sharp(cdt)
    assert away.mean() > 0.85
    assert angles[away].min() >= 20.0 - 1e-6
    touching = cdt.junction[cdt.triangles].min(axis=1) < 20.0
    assert (angles[touching | ~away] < 20.0).any() or name == "ovate"   # only where the input is sharper


def test_area_bound_and_min_angle_options(presets):
    coarse = triangulate_leaf(presets["ovate"], max_area=1e-3)
    fine = triangulate_leaf(presets["ovate"], max_area=1e-4, min_angle=28.0)
    for cdt in (coarse, fine):
        p = cdt.points[cdt.triangles]
        e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        assert area.max() <= cdt.max_area * (1 + 1e-9)
    assert len(fine.triangles) > 3 * len(coarse.triangles)
    angles = triangle_angles(fine.points, fine.triangles).min(axis=1)
    assert angles[~near_sharp(fine)].min() >= 28.0 - 1e-6


@pytest.mark.parametrize("name", KINDS)
def test_uv_is_recovered_for_every_vertex(meshes, presets, name):
    cdt = meshes[name]
    plane = leaf_plane(presets[name], cdt.plane)
    assert cdt.plane == "flat" and cdt.inverse_error < 1e-9
    rim = _rim(cdt.triangles)
    inner = np.setdiff1d(np.arange(len(cdt.points)), rim)
    assert np.abs(plane.forward(cdt.uv[inner]) - cdt.points[inner]).max() < 1e-9
    tips = (cdt.uv[:, 1] == 0.0) | (cdt.uv[:, 1] == 1.0)
    assert tips.sum() == 2 and (cdt.uv[tips, 0] == 0.0).all()
    assert (np.abs(cdt.uv[np.setdiff1d(rim, np.flatnonzero(tips)), 0]) == 1.0).all()   # on the margin exactly


def test_vein_space_plane_inverts_in_closed_form(presets):
    cdt = triangulate_leaf(presets["ovate"], plane="vein")
    plane = leaf_plane(presets["ovate"], "vein")
    assert cdt.plane == "vein" and cdt.inverse_error == 0.0
    inner = (np.abs(cdt.uv[:, 0]) < 1.0) & (cdt.uv[:, 1] > 0) & (cdt.uv[:, 1] < 1)
    assert np.abs(plane.forward(cdt.uv[inner]) - cdt.points[inner]).max() < 1e-12
    angles = triangle_angles(cdt.points, cdt.triangles).min(axis=1)
    assert angles[~near_sharp(cdt)].min() >= 20.0 - 1e-6


def test_a_one_sided_leaf_triangulates_its_half(presets):
    leaf = presets["ovate"].replace(shape=replace(presets["ovate"].shape, half=1))
    baked = bake_cdt(leaf, backend="numpy")
    assert baked.cdt.uv[:, 0].min() >= 0.0 and baked.cdt.uv[:, 0].max() == 1.0
    _assert_sheet(baked.mesh.positions, baked.mesh.normals, baked.mesh.indices)


def _assert_sheet(pos: np.ndarray, nrm: np.ndarray, tris: np.ndarray) -> None:
    """Edge-manifold, consistently oriented, one boundary loop, winding that agrees with the normals."""
    tris = tris.astype(np.int64)
    directed = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    assert len({tuple(e) for e in directed.tolist()}) == len(directed)    # no edge twice the same way
    key = np.sort(directed, axis=1)
    _, count = np.unique(key, axis=0, return_counts=True)
    assert count.max() <= 2
    once = {tuple(k) for k, c in zip(*np.unique(key, axis=0, return_counts=True)) if c == 1}
    rim = [tuple(e) for e in directed.tolist() if tuple(sorted(e)) in once]
    after = dict(rim)
    assert len(after) == len(rim)
    start = rim[0][0]
    at, steps = after[start], 1
    while at != start:
        at, steps = after[at], steps + 1
    assert steps == len(rim)                                               # one loop
    face = np.cross(pos[tris[:, 1]] - pos[tris[:, 0]], pos[tris[:, 2]] - pos[tris[:, 0]])
    agree = np.einsum("ij,ij->i", face, nrm[tris].mean(axis=1)) > 0
    assert agree.mean() > 0.999


@pytest.mark.parametrize("name", ("ovate", "holly", "maize"))
def test_baked_sheet_and_quality_figures(presets, name):
    baked = bake_cdt(presets[name], backend="numpy")
    _assert_sheet(baked.mesh.positions.astype(np.float64), baked.mesh.normals, baked.mesh.indices)
    q = baked.quality
    assert q.triangles == baked.mesh.n_triangles and q.min_angle_plane_away >= 20.0 - 1e-6
    assert q.min_angle_3d_away > 10.0 and "triangles" in str(q)


def test_gpu_vertices_are_the_reference(gl, presets):
    """The shader's readback at the mesh's (u, v) is the float64 reference (float32 tolerance);
    normals may differ only on the jitter's corners, where the margin has a crease."""
    for name in ("ovate", "holly", "maize"):
        leaf = presets[name]
        ref = bake_cdt(leaf, backend="numpy").mesh
        gpu = bake_cdt(leaf, backend="gpu", renderer=gl).mesh
        assert np.abs(gpu.positions - ref.positions).max() < 2e-6
        x = ref.uv[:, 1] * leaf.jitter.density
        crease = (np.abs(x - np.round(x)) < 1e-9) & leaf.jitter.enabled
        assert np.abs(gpu.normals - ref.normals)[~crease].max() < 1e-4


# -- options -----------------------------------------------------------------------------------
@pytest.mark.parametrize("value", [0, -1, 1e-9, 2.0, float("nan"), "big"])
def test_bad_max_area_names_the_option(value):
    with pytest.raises(UsageError, match="max_area"):
        check_max_area(value)


@pytest.mark.parametrize("value", [-1, 40, float("inf")])
def test_bad_min_angle_names_the_option(value):
    with pytest.raises(UsageError, match="min_angle"):
        check_min_angle(value)


@pytest.mark.parametrize("argv, flag", [
    (["--mesh", "cdt", "--max-area", "0"], "--max-area"),
    (["--mesh", "cdt", "--max-area", "1e-9"], "--max-area"),
    (["--mesh", "cdt", "--max-area", "lots"], "--max-area"),
    (["--mesh", "cdt", "--min-angle", "45"], "--min-angle"),
    (["--max-area", "0.001"], "--max-area"),
    (["--mesh", "cdt", "--resolution", "9x17"], "--resolution"),
])
def test_cli_refuses_bad_options_with_exit_2_and_writes_nothing(tmp_path, capsys, argv, flag):
    out = tmp_path / "out"
    try:
        code = main(["export", "ovate", "-o", str(out / "x.gltf"), "--backend", "numpy", *argv])
    except SystemExit as exc:      # argparse refuses a bad option value itself
        code = exc.code
    assert code == 2
    assert flag in capsys.readouterr().err
    assert not out.exists()


def test_a_failure_leaves_no_file(tmp_path, monkeypatch):
    calls = []

    def failing(*args, **kwargs):
        calls.append(args)
        if len(calls) == 2:
            raise OSError("disk full")
        return real(*args, **kwargs)

    real = cli_export.write
    monkeypatch.setattr(cli_export, "write", failing)
    out = tmp_path / "out"
    with pytest.raises(OSError, match="disk full"):
        main(["export", "ovate", "elliptic", "--mesh", "cdt", "--backend", "numpy", "--format", "usda",
              "-o", str(out), "-q"])
    assert len(calls) == 2 and (not out.exists() or not any(out.iterdir()))   # the first leaf's files too


# -- textures ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def ovate_maps(presets):
    return bake_vein_maps(presets["ovate"], size=128)


def _pixels(data: bytes, path: Path) -> np.ndarray:
    path.write_bytes(data)
    return oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)


def test_base_colour_is_the_shaders_albedo(presets, ovate_maps, tmp_path):
    leaf = presets["ovate"]
    field = vein_field(leaf, 128).astype(np.float64)
    u, v = vein_grid_uv(128, 128)
    img = srgb_to_linear(_pixels(ovate_maps.front.data, tmp_path / "f.png"))[..., :3]
    fw = np.stack([np.abs(np.gradient(field[..., k], axis=1)) + np.abs(np.gradient(field[..., k], axis=0))
                   for k in (0, 3)], axis=-1)
    want = vein_albedo(leaf.material.front, vein_strength(field, major_width(leaf.venation), fw), u, v,
                       leaf.venation.contrast)
    assert np.abs(img - want).max() < 0.01     # 8-bit sRGB
    midrib = img[64, 63:65].mean(axis=0)
    assert midrib.sum() > img[64, 32].sum()    # the midrib is paler than the lamina beside it


def test_normal_map_is_the_relief_gradient_on_the_leaf(presets):
    """For a smooth height field, the tangent-space normal rebuilt in the (T, B, N) frame equals the
    normal of the displaced flat blade computed by finite differences in 3D."""
    leaf = presets["ovate"]
    size = 128
    u, v = vein_grid_uv(size, size)
    height = 0.004 * np.sin(6.0 * u + 9.0 * v)
    n = normal_map(leaf, height)
    for i, j in ((40, 30), (64, 90), (90, 50)):
        p = blade_partials(leaf, [u[i, j]], [v[i, j]])[0]
        normal = np.cross(p.Lv[0], p.Lu[0])
        normal /= np.linalg.norm(normal)
        t = -p.Lu[0] / np.linalg.norm(p.Lu[0])
        b = np.cross(normal, t)
        world = n[i, j, 0] * t + n[i, j, 1] * b + n[i, j, 2] * normal
        eps = 1e-4
        uv = np.array([[u[i, j], v[i, j]]]) + np.array([[0, eps], [0, -eps], [eps, 0], [-eps, 0]])
        q = blade_partials(leaf, uv[:, 0], uv[:, 1])[0].L + (0.004 * np.sin(6.0 * uv[:, 0] + 9.0 * uv[:, 1]))[:, None] * normal
        ref = np.cross(q[0] - q[1], q[2] - q[3])
        ref /= np.linalg.norm(ref)
        assert np.degrees(np.arccos(np.clip(world @ ref, -1, 1))) < 1.5


def test_tangents_frame_the_maps(presets):
    mesh = bake_cdt(presets["ovate"], backend="numpy").mesh
    tan = tangents(mesh)
    assert np.allclose(np.linalg.norm(tan[:, :3], axis=1), 1, atol=1e-5) and set(np.unique(tan[:, 3])) <= {-1.0, 1.0}
    assert np.abs(np.einsum("ij,ij->i", tan[:, :3], mesh.normals)).max() < 1e-4
    inner = (mesh.uv[:, 1] > 0.05) & (mesh.uv[:, 1] < 0.95)
    assert (tan[inner, 0] > 0.5).mean() > 0.99          # along +s: towards +x on a straight leaf


# -- files -------------------------------------------------------------------------------------
@pytest.mark.usefixtures("gltf_validator")
def test_cli_gltf_carries_the_mesh_and_its_vein_textures(gl, tmp_path, presets):
    out = tmp_path / "x.gltf"
    assert main(["export", "ovate", "--mesh", "cdt", "-o", str(out), "-q"]) == 0
    assert_gltf_clean(out)
    f = read_gltf(out)
    doc = f.doc
    mats = doc["materials"]
    assert len(mats) == 2 and all("normalTexture" in m and "baseColorTexture" in m["pbrMetallicRoughness"]
                                  and "alphaMode" not in m for m in mats)
    prims = doc["meshes"][0]["primitives"]
    assert all("TANGENT" in p["attributes"] for p in prims)
    front, back = (f.accessor(p["attributes"]["TANGENT"]) for p in prims)
    assert np.array_equal(front[:, :3], back[:, :3]) and np.array_equal(front[:, 3], -back[:, 3])
    assert len(doc["images"]) == 4 and sorted(p.name for p in tmp_path.iterdir()) == ["x.gltf"]
    ref = bake_cdt(presets["ovate"], backend="numpy").mesh
    assert doc["accessors"][prims[0]["indices"]]["count"] == 3 * ref.n_triangles


def test_cli_usda_and_obj_write_the_textures_beside_the_file(tmp_path, presets):
    usd = tmp_path / "usd" / "x.usda"
    obj = tmp_path / "obj" / "x.obj"
    ply = tmp_path / "ply" / "x.ply"
    for out in (usd, obj, ply):
        assert main(["export", "ovate", "--mesh", "cdt", "--backend", "numpy", "-o", str(out), "-q"]) == 0
    assert usd_errors(usd) == []
    text = usd.read_text()
    assert "inputs:normal.connect" in text and "ovate_back_normal.png" in text and "inputs:opacity" not in text
    assert sorted(p.name for p in usd.parent.iterdir()) == ["ovate_back_basecolor.png", "ovate_back_normal.png",
                                                            "ovate_basecolor.png", "ovate_normal.png", "x.usda"]
    mtl = (obj.parent / "x.mtl").read_text()
    assert "map_Kd ovate_basecolor.png" in mtl and "map_Bump -bm 1 ovate_normal.png" in mtl and "\nmap_d" not in mtl
    loaded = trimesh.load(obj, process=False)
    ref = bake_cdt(presets["ovate"], backend="numpy").mesh
    assert len(loaded.faces) == ref.n_triangles and loaded.visual.material.image is not None
    assert sorted(p.name for p in ply.parent.iterdir()) == ["ovate_basecolor.png", "x.ply"]
    assert b"comment TextureFile ovate_basecolor.png" in ply.read_bytes()[:400]


def test_a_leaf_without_veins_gets_the_mesh_but_no_textures(tmp_path, presets):
    leaf = presets["ovate"].replace(venation=replace(presets["ovate"].venation, enabled=False))
    assert bake_vein_maps(leaf) is None
    save_params(leaf, tmp_path / "plain.leaf.json")
    out = tmp_path / "out" / "plain.usda"
    assert main(["export", str(tmp_path / "plain.leaf.json"), "--mesh", "cdt", "--backend", "numpy", "-o", str(out),
                 "-q"]) == 0
    assert usd_errors(out) == [] and sorted(p.name for p in out.parent.iterdir()) == ["plain.usda"]
