"""Lobed leaves exported (issue 21): glTF, OBJ, PLY and USD files of the maple, oak and bilobed
presets pass their validators and read back as one connected, edge-manifold sheet with exactly
one boundary loop, nothing stacked (triangle areas in the leaf plane over the area of their
union <= 1.05) and the outline of the source margin (Hausdorff <= 1 % of the leaf length); the
compact form round-trips, and compound (``lobed = 1``) files export as their fitted margin.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import shapely
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from support.gltf_read import read_gltf
from support.validate import ValidatorMissing, gltf_report, usd_errors

from leafview.botany.leaf_surface import sweep_of, tessellate
from leafview.botany.lobe_sweep import sweep_table
from leafview.cli import main
from leafview.core.blade import grid_uv
from leafview.core.defaults import DEFAULT_GRID
from leafview.core.lobes import outline_samples
from leafview.core.params import LeafParams, Transform, Venation
from leafview.deform.sweep import lobed_grid, texture_uv
from leafview.errors import UsageError
from leafview.export import bake, export_leaf
from leafview.export.cdt import bake_cdt
from leafview.export.mesh import lower_left_st
from leafview.export.objply import axis_matrix
from leafview.export.vein_maps import bake_vein_maps
from tests.conftest import require_or_skip

LOBED = ("maple", "oak", "bilobed")
FORMATS = (".glb", ".obj", ".ply", ".usda")
COMPOUND = Path(__file__).resolve().parents[1] / "assets" / "compound"
MAX_AREA_RATIO = 1.05
MAX_HAUSDORFF = 0.01        # of the leaf length
FIT_TOLERANCE = 0.01        # a compound file's margin against its preset's (a leaf length)


# -- measuring a sheet -----------------------------------------------------------------------
def edge_uses(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unique undirected edges (E, 2), how many triangles use each)."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def components(n: int, edges: np.ndarray) -> tuple[int, np.ndarray]:
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """The boundary edges chained into closed loops (vertex ids in order); raises when a boundary
    vertex is not on exactly two boundary edges (a bow tie)."""
    edges, uses = edge_uses(faces)
    border = edges[uses == 1]
    nbrs: dict[int, list[int]] = {}
    for a, b in border.tolist():
        nbrs.setdefault(a, []).append(b)
        nbrs.setdefault(b, []).append(a)
    assert all(len(v) == 2 for v in nbrs.values()), "a boundary vertex on more than two boundary edges"
    loops, seen = [], set()
    for start in nbrs:
        if start in seen:
            continue
        loop, prev, cur = [start], -1, start
        seen.add(start)
        while True:
            nxt = next(x for x in nbrs[cur] if x != prev) if prev != -1 else nbrs[cur][0]
            if nxt == start:
                break
            loop.append(nxt)
            seen.add(nxt)
            prev, cur = cur, nxt
        loops.append(np.array(loop))
    return loops


def sheet_figures(points: np.ndarray, faces: np.ndarray, params: LeafParams) -> dict[str, float]:
    """Components, most triangles on one edge, boundary loops, area ratio and the outline's
    Hausdorff distance (fraction of the leaf length) of a mesh in leaf space (z the normal of the
    leaf plane)."""
    faces = np.asarray(faces, dtype=np.int64)
    used = np.unique(faces)
    _, uses = edge_uses(faces)
    n_comp, labels = components(len(points), edge_uses(faces)[0])
    comps = len(np.unique(labels[used]))
    loops = boundary_loops(faces)
    xy = np.asarray(points, np.float64)[:, :2]
    a, b, c = (xy[faces[:, k]] for k in range(3))
    d, e = b - a, c - a
    areas = 0.5 * np.abs(d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0])
    union = shapely.unary_union(shapely.polygons(np.stack([a, b, c], axis=1)))
    margin = outline_samples(params.lobes.outline)
    loop = max(loops, key=len)
    ring = shapely.LinearRing(xy[loop])
    source = shapely.LinearRing(margin)
    length = 1.0                    # the leaf frame's unit: base (0, 0) to apex (0, 1)
    return {"components": comps, "max_edge_uses": int(uses.max()), "loops": len(loops),
            "area_ratio": float(areas.sum() / union.area),
            "hausdorff": float(shapely.hausdorff_distance(ring, source, densify=0.02)) / length}


def check_sheet(fig: dict[str, float]) -> None:
    assert fig["components"] == 1, fig
    assert fig["max_edge_uses"] <= 2, fig
    assert fig["loops"] == 1, fig
    assert fig["area_ratio"] <= MAX_AREA_RATIO, fig
    assert fig["hausdorff"] <= MAX_HAUSDORFF, fig


# -- reading the files back in leaf space ------------------------------------------------------
def gltf_clean(path: Path) -> None:
    try:
        report = gltf_report(path)
    except ValidatorMissing as exc:
        require_or_skip(f"the Khronos glTF validator is unavailable: {exc}")
        raise
    issues = report["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, [(m["code"], m.get("pointer"))
                                                                      for m in issues["messages"]]


def read_back(path: Path, up: str = "y", length_m: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(points, triangles) of the front surface of an exported single leaf, in leaf space."""
    if path.suffix == ".glb":
        f = read_gltf(path)
        prim = f.doc["meshes"][0]["primitives"][0]             # the front; [1] is the back
        pos = f.accessor(prim["attributes"]["POSITION"]).astype(np.float64)
        (_, world, _), = list(f.mesh_instances())
        world_pos = pos @ world[:3, :3].T + world[:3, 3]
        return world_pos / length_m @ axis_matrix("y"), f.accessor(prim["indices"]).reshape(-1, 3)
    if path.suffix in (".obj", ".ply"):
        loaded = trimesh.load(path, process=False)
        return np.asarray(loaded.vertices) / length_m @ axis_matrix(up), np.asarray(loaded.faces)
    from pxr import Usd, UsdGeom  # optional dependency: only the USD cases need it

    stage = Usd.Stage.Open(str(path))
    front = next(UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh) and p.GetName() == "front")
    world = np.asarray(UsdGeom.Xformable(front.GetPrim()).ComputeLocalToWorldTransform(Usd.TimeCode.Default())).T
    pts = np.asarray(front.GetPointsAttr().Get(), np.float64)
    counts = np.asarray(front.GetFaceVertexCountsAttr().Get())
    assert (counts == 3).all()
    return pts @ world[:3, :3].T + world[:3, 3], np.asarray(front.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)


@pytest.fixture(scope="module")
def lobed(presets) -> dict[str, LeafParams]:
    return {name: presets[name] for name in LOBED}


# -- baking ----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", LOBED)
def test_gpu_bake_is_the_welded_reference(gl, lobed, name):
    """The shader capture on the lobed grid, welded, is leaf_surface.tessellate's mesh: the same
    triangles, positions and normals to float32, uv the flat position and st texture_st of it."""
    params = lobed[name]
    mesh = bake(params, renderer=gl)
    ref = tessellate(params)
    assert np.array_equal(mesh.indices, ref.indices)
    assert np.abs(mesh.positions - ref.vertices).max() <= 2e-6
    assert np.abs(mesh.normals - ref.normals).max() <= 1e-4
    assert np.array_equal(mesh.uv, ref.uv)
    assert np.array_equal(mesh.st, lower_left_st(ref.uv))
    numpy = bake(params, backend="numpy")
    assert np.array_equal(numpy.indices, mesh.indices)
    assert np.abs(numpy.positions - mesh.positions).max() <= 2e-6
    check_sheet(sheet_figures(mesh.positions, mesh.indices, params))


def test_a_coarse_grid_still_makes_one_sheet(gl, lobed):
    params = lobed["maple"]
    mesh = bake(params, (9, 17), renderer=gl)
    fig = sheet_figures(mesh.positions, mesh.indices, params)
    assert fig["components"] == 1 and fig["loops"] == 1 and fig["max_edge_uses"] <= 2, fig


# -- the files -------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", FORMATS)
@pytest.mark.parametrize("name", LOBED)
def test_exported_lobed_leaf_is_one_clean_sheet(gl, lobed, tmp_path, name, suffix, request):
    params = lobed[name]
    assert params.transform == Transform()          # leaf space is world space (up to axes, metres)
    up = "z" if suffix in (".obj", ".ply") else "y"
    opts = {"up": up} if suffix in (".obj", ".ply") else {}
    path = export_leaf(params, tmp_path / f"{name}{suffix}", renderer=gl, length_m=1.0, **opts)
    if suffix == ".glb":
        request.getfixturevalue("gltf_validator")
        gltf_clean(path)
    if suffix == ".usda":
        assert usd_errors(path) == []     # pxr (usd-core) is a dependency: no skip
    points, faces = read_back(path, up)
    mesh = bake(params, renderer=gl)
    assert faces.shape == mesh.indices.shape
    assert np.abs(points - mesh.positions).max() <= 1e-6
    check_sheet(sheet_figures(points, faces, params))


def test_texture_coordinates_are_the_flat_position_in_its_window(gl, lobed, tmp_path):
    """OBJ ``vt`` = ((1 - u) / 2, v) of u, v = the flat position mapped by the margin's bounding
    box (texture_uv; Mündermann et al. 2003, eq. 1): in [0, 1]², spanning it."""
    params = lobed["maple"]
    path = export_leaf(params, tmp_path / "maple.obj", renderer=gl)
    loaded = trimesh.load(path, process=False)
    mesh = bake(params, renderer=gl)
    table = sweep_table(params.lobes)
    expect = texture_uv(sweep_of(params, grid_uv(*lobed_grid(DEFAULT_GRID)).astype(np.float64)).flat,
                        table.window)
    ref = tessellate(params)
    assert np.abs(mesh.uv - ref.uv).max() == 0.0
    assert cKDTree(expect).query(mesh.uv)[0].max() <= 1e-6       # each vertex: its grid sample
    assert expect.min(axis=0) == pytest.approx([-1.0, 0.0], abs=1e-6)
    assert expect.max(axis=0) == pytest.approx([1.0, 1.0], abs=1e-6)
    st = np.c_[(1 - mesh.uv[:, 0]) / 2, mesh.uv[:, 1]]
    assert np.allclose(loaded.visual.uv, st, atol=1e-6)
    assert st.min() >= -1e-6 and st.max() <= 1 + 1e-6
    assert st.min(axis=0) == pytest.approx([0.0, 0.0], abs=0.01) and st.max(axis=0) == pytest.approx([1, 1], abs=0.01)


def test_cli_exports_every_format(gl, tmp_path):
    for suffix in (".glb", ".gltf", ".obj", ".ply", ".usda", ".usdc"):
        out = tmp_path / f"oak{suffix}"
        assert main(["export", "oak", "-o", str(out), "-q"]) == 0
        assert out.is_file()
        if suffix.startswith(".usd"):
            assert usd_errors(out) == []


@pytest.mark.usefixtures("gltf_validator")
def test_leaf_set_with_lobed_leaves_exports_as_a_scene(gl, lobed, tmp_path):
    leaves = tmp_path / "mixed.leaves.json"
    assert main(["export", "maple", "ovate", "bilobed", "-o", str(leaves), "-q"]) == 0
    out = tmp_path / "mixed.glb"
    assert main(["export", str(leaves), "-o", str(out), "-q", "--length-m", "1"]) == 0
    gltf_clean(out)
    f = read_gltf(out)
    assert len(f.doc["meshes"]) == 3
    for mesh in f.doc["meshes"]:
        name = mesh["name"]
        if name not in lobed:
            continue
        prim = mesh["primitives"][0]
        pos = f.accessor(prim["attributes"]["POSITION"]).astype(np.float64)
        check_sheet(sheet_figures(pos, f.accessor(prim["indices"]).reshape(-1, 3), lobed[name]))


def test_scene_file_with_a_lobed_species(gl, tmp_path):
    scene_file = tmp_path / "grove.toml"
    scene_file.write_text('schema = 1\n[scene]\nlayout = "plant"\nleaves = 12\nseed = 3\nvariation = 0.0\n'
                          'colour_variation = 0.0\n\n[[species]]\npreset = "oak"\n', encoding="utf-8")
    for suffix in (".glb", ".usdc", ".obj"):
        out = tmp_path / f"grove{suffix}"
        assert main(["export", str(scene_file), "-o", str(out), "-q"]) == 0
        assert out.is_file()


# -- what lobed leaves do not have -----------------------------------------------------------
def test_cdt_mesh_is_refused_naming_the_option(lobed, tmp_path, capsys):
    out = tmp_path / "maple.glb"
    assert main(["export", "maple", "--mesh", "cdt", "-o", str(out)]) == 2
    assert "--mesh" in capsys.readouterr().err
    assert not out.exists() and list(tmp_path.iterdir()) == []
    with pytest.raises(UsageError, match="--mesh"):
        bake_cdt(lobed["oak"], backend="numpy")


def test_vein_maps_of_a_lobed_leaf_are_none(gl, lobed, tmp_path):
    veined = lobed["maple"].replace(venation=Venation(enabled=True))
    assert bake_vein_maps(veined) is None
    path = export_leaf(veined, tmp_path / "v.glb", renderer=gl, vein_maps=True)
    assert len(read_gltf(path).doc.get("images", [])) == 0


# -- compact and compound files --------------------------------------------------------------
@pytest.mark.parametrize("name", LOBED)
def test_compact_round_trip(lobed, tmp_path, name):
    out = tmp_path / f"{name}.leaf.json"
    assert main(["export", name, "-o", str(out), "-q"]) == 0
    assert LeafParams.load(out) == lobed[name]


@pytest.mark.parametrize("name", LOBED)
def test_compound_file_exports_as_its_preset(gl, lobed, tmp_path, name):
    compound = tmp_path / f"{name}.glb"
    preset = tmp_path / f"{name}-preset.glb"
    assert main(["export", str(COMPOUND / f"{name}.toml"), "-o", str(compound), "-q", "--length-m", "1"]) == 0
    assert main(["export", name, "-o", str(preset), "-q", "--length-m", "1"]) == 0
    a, b = (read_back(p) for p in (compound, preset))
    fig = sheet_figures(*a, lobed[name])
    check_sheet(fig)                                        # against the preset's margin
    ring = [shapely.LinearRing(pts[max(boundary_loops(tris), key=len)][:, :2]) for pts, tris in (a, b)]
    assert shapely.hausdorff_distance(*ring, densify=0.02) <= FIT_TOLERANCE
    compact = tmp_path / f"{name}.leaf.json"
    assert main(["export", str(COMPOUND / f"{name}.toml"), "-o", str(compact), "-q"]) == 0
    assert LeafParams.load(compact).lobes.enabled


def test_maple_compound_equals_the_preset_exactly(gl, tmp_path):
    """The maple preset is its compound file's fit at the default controls: the same file."""
    a, b = tmp_path / "a.glb", tmp_path / "b.glb"
    assert main(["export", str(COMPOUND / "maple.toml"), "-o", str(a), "-q"]) == 0
    assert main(["export", "maple", "-o", str(b), "-q"]) == 0
    assert a.read_bytes() == b.read_bytes()


def test_compound_file_loads_through_leafparams_load():
    import leafview.cli.args  # noqa: F401  installs the compound-aware loader

    leaf = LeafParams.load(COMPOUND / "oak.toml")
    assert leaf.lobes.enabled and leaf.name == "oak"


@pytest.mark.parametrize("edit, field", [
    ('theta = [52.0, "x"]', "theta"),
    ("colour = 3", "colour"),
    ('kind = "spiral"', "kind"),
    ("half = 0", "half"),
])
def test_bad_compound_file_exits_2_and_writes_nothing(tmp_path, capsys, edit, field):
    text = (COMPOUND / "maple.toml").read_text(encoding="utf-8")
    key = edit.split(" = ")[0]
    lines = [ln for ln in text.splitlines() if not ln.startswith(f"{key} ")]
    at = lines.index("[material]")
    bad = tmp_path / "bad.toml"
    bad.write_text("\n".join(lines[:at] + [edit] + lines[at:]) + "\n", encoding="utf-8")
    for out in (tmp_path / "o.glb", tmp_path / "o.leaf.json"):
        assert main(["export", str(bad), "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert field in err and "bad.toml" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]
