"""The default (u, v) grid export carries the baked vein textures the venation mesh has: base colour
and normal maps of both sides (glTF with TANGENT, USD, OBJ/PLY beside the file), validators at 0
errors, written in one transaction with the mesh; a leaf without venation (or ``--veins off``)
exports byte for byte as before; a photograph stays the base colour."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from support.gltf_read import read_gltf
from support.validate import usd_errors
from test_export import assert_gltf_clean
from test_export_textures import textured_leaf

import leafview.cli.export as cli_export
import leafview.export.objply as objply
import leafview.export.usd as usd
import leafview.export.vein_maps as vein_maps
from leafview.cli import main
from leafview.core.io import save_params
from leafview.core.venation import Venation
from leafview.errors import UsageError
from leafview.export import export_leaf
from leafview.export.mesh import bake
from leafview.export.vein_maps import tangents

GRID = ["--resolution", "9x17", "--backend", "numpy", "-q"]
MAPS = ["beech_back_basecolor.png", "beech_back_normal.png", "beech_basecolor.png", "beech_normal.png"]


@pytest.fixture(autouse=True)
def small_maps(monkeypatch):
    """Vein textures of 64 texels a side (the default 512 costs about a second a leaf)."""
    monkeypatch.setattr(vein_maps, "MAPS_SIZE", 64)


def _names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.usefixtures("gltf_validator")
def test_gltf_grid_carries_the_vein_textures_and_tangents(tmp_path, presets):
    out = tmp_path / "x.gltf"
    assert main(["export", "beech", "-o", str(out), *GRID]) == 0
    assert_gltf_clean(out)
    f = read_gltf(out)
    doc = f.doc
    mats = doc["materials"]
    assert len(mats) == 2 and all("normalTexture" in m and "baseColorTexture" in m["pbrMetallicRoughness"]
                                  for m in mats)
    prims = doc["meshes"][0]["primitives"]
    front, back = (f.accessor(p["attributes"]["TANGENT"]) for p in prims)
    mesh = bake(presets["beech"], (9, 17), backend="numpy")
    assert np.array_equal(front, tangents(mesh))          # the grid's own frame of the maps
    assert np.array_equal(front[:, :3], back[:, :3]) and np.array_equal(front[:, 3], -back[:, 3])
    assert len(doc["images"]) == 4 and _names(tmp_path) == ["x.gltf"]
    assert doc["accessors"][prims[0]["indices"]]["count"] == 3 * mesh.n_triangles


def test_usda_obj_ply_grid_write_the_textures_beside_the_file(tmp_path):
    usda, obj, ply = (tmp_path / k / f"x.{k}" for k in ("usda", "obj", "ply"))
    for out in (usda, obj, ply):
        assert main(["export", "beech", "-o", str(out), *GRID]) == 0
    assert usd_errors(usda) == []
    text = usda.read_text()
    assert "inputs:normal.connect" in text and "beech_back_normal.png" in text and "beech_basecolor.png" in text
    assert _names(usda.parent) == sorted([*MAPS, "x.usda"])
    mtl = (obj.parent / "x.mtl").read_text()
    assert "map_Kd beech_basecolor.png" in mtl and "map_Bump -bm 1 beech_normal.png" in mtl
    loaded = trimesh.load(obj, process=False)
    assert len(loaded.faces) == 2 * 8 * 16 - 2 * 8 and loaded.visual.material.image is not None
    assert _names(ply.parent) == ["beech_basecolor.png", "x.ply"]
    assert b"comment TextureFile beech_basecolor.png" in ply.read_bytes()[:400]


@pytest.mark.parametrize("suffix", [".glb", ".gltf", ".obj", ".ply", ".usda", ".usdc"])
def test_a_leaf_without_venation_exports_as_before(tmp_path, presets, suffix):
    plain = presets["beech"].replace(venation=Venation())
    save_params(plain, tmp_path / "plain.leaf.json")
    old = export_leaf(plain, tmp_path / "old" / f"x{suffix}", resolution=(9, 17), backend="numpy")
    new = tmp_path / "new" / f"x{suffix}"
    assert main(["export", str(tmp_path / "plain.leaf.json"), "-o", str(new), *GRID]) == 0
    off = tmp_path / "off" / f"x{suffix}"                  # --veins off: the veined leaf without its maps
    assert main(["export", "beech", "-o", str(off), "--veins", "off", *GRID]) == 0
    before = export_leaf(presets["beech"], tmp_path / "before" / f"x{suffix}", resolution=(9, 17), backend="numpy")
    for a, b in ((old, new), (before, off)):
        assert _names(a.parent) == _names(b.parent)
        for name in _names(a.parent):
            assert (a.parent / name).read_bytes() == (b.parent / name).read_bytes(), name
    assert not any(n.endswith(".png") for n in _names(new.parent))


def test_a_photograph_stays_the_base_colour(tmp_path, presets):
    leaf, data = textured_leaf(tmp_path / "src", presets["beech"], "oak")
    out = tmp_path / "out" / "x.usda"
    assert main(["export", str(tmp_path / "src" / "leaf.leaf.json"), "-o", str(out), *GRID]) == 0
    assert usd_errors(out) == []
    assert _names(out.parent) == ["front.png", "oak_back_normal.png", "oak_normal.png", "x.usda"]
    assert (out.parent / "front.png").read_bytes() == data["front"]
    assert "oak_basecolor" not in out.read_text() and "inputs:normal.connect" in out.read_text()


@pytest.mark.parametrize("suffix, module, name", [(".usda", usd, "usd_layer"), (".obj", objply, "_obj_body")])
def test_a_failed_write_leaves_neither_mesh_nor_textures(tmp_path, monkeypatch, suffix, module, name):
    def explode(*args, **kwargs):
        raise UsageError("simulated failure after the images were staged")

    monkeypatch.setattr(module, name, explode)
    out = tmp_path / "out" / f"x{suffix}"
    out.parent.mkdir()
    assert main(["export", "beech", "-o", str(out), *GRID]) == 2
    assert _names(out.parent) == []


def test_a_failure_in_a_directory_export_leaves_no_file(tmp_path, monkeypatch):
    calls = []
    real = cli_export.write

    def failing(*args, **kwargs):
        calls.append(args)
        if len(calls) == 2:
            raise OSError("disk full")
        return real(*args, **kwargs)

    monkeypatch.setattr(cli_export, "write", failing)
    out = tmp_path / "out"
    with pytest.raises(OSError, match="disk full"):
        main(["export", "beech", "ovate", "--format", "usda", "-o", str(out), *GRID])
    assert len(calls) == 2 and (not out.exists() or not any(out.iterdir()))   # the first leaf's maps too
