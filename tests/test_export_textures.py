"""Textured leaves in every export format: glTF baseColorTexture with an alpha mask, USD
UsdPreviewSurface fed by a UsdUVTexture, OBJ .mtl map_Kd/map_d and PLY TextureFile; texture
coordinates from leafview.core.texture.texture_st of each vertex's drawn (u, v); one image per
texture file however many leaves use it; a missing image refused before anything is written."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
import trimesh
from support.gltf_read import read_gltf
from support.validate import usd_errors
from test_export import assert_gltf_clean
from test_export_scene import StandInScene

import leafview.export.objply as objply
from leafview.cli import main
from leafview.core.io import load_leaves, load_params, save_leaves, save_params
from leafview.core.params import LeafParams, Transform
from leafview.core.texture import LeafTexture, texture_st
from leafview.errors import ParamError
from leafview.export import export_leaf, export_leaves, export_scene
from leafview.export.mesh import bake

GRID = (9, 17)
SUFFIXES = (".glb", ".gltf", ".obj", ".ply", ".usda", ".usdc")


def write_png(path: Path, pixels: np.ndarray) -> bytes:
    """A PNG written with OpenImageIO; returns its bytes."""
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    assert out is not None and out.open(str(path), oiio.ImageSpec(w, h, c, "uint8"))
    assert out.write_image(np.ascontiguousarray(pixels)) and out.close()
    return path.read_bytes()


def rgba(seed: int, size: tuple[int, int] = (32, 64)) -> np.ndarray:
    """Random colours with a cut-out alpha (the outer quarter transparent)."""
    h, w = size
    px = np.random.default_rng(seed).integers(0, 256, (h, w, 4), dtype=np.uint8)
    px[..., 3] = 0
    px[h // 4: 3 * h // 4, w // 4: 3 * w // 4, 3] = 255
    return px


def textured_leaf(folder: Path, preset: LeafParams, name: str = "oak", *, front: str = "front.png",
                  back: str = "", seed: int = 1) -> tuple[LeafParams, dict[str, bytes]]:
    """A leaf file ``folder/leaf.leaf.json`` naming a front (and optional back) PNG beside it,
    loaded back."""
    folder.mkdir(parents=True, exist_ok=True)
    data = {"front": write_png(folder / front, rgba(seed))}
    if back:
        data["back"] = write_png(folder / back, rgba(seed + 100))
    save_params(preset.replace(name=name, texture=LeafTexture(front, back)), folder / "leaf.leaf.json")
    return load_params(folder / "leaf.leaf.json"), data


@pytest.fixture
def ovate(presets) -> LeafParams:
    return presets["ovate"].replace(transform=Transform(translation=(0.5, 0, 0.2), rotation=(10, 20, 30)))


def files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# -- glTF --------------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix, back_faces, back", [(".glb", "primitive", "back.png"), (".gltf", "primitive", ""),
                                                      (".glb", "double-sided", "back.png")])
@pytest.mark.usefixtures("gltf_validator")
def test_gltf_material_masks_the_image_and_texcoords_follow_texture_st(tmp_path, ovate, suffix, back_faces, back):
    leaf, data = textured_leaf(tmp_path / "src", ovate, back=back)
    path = export_leaf(leaf, tmp_path / "out" / f"oak{suffix}", backend="numpy", resolution=GRID,
                       back_faces=back_faces)
    assert files(path.parent) == [path.name]                 # the image is inside, not beside
    assert_gltf_clean(path)
    f = read_gltf(path)
    prims = f.doc["meshes"][0]["primitives"]
    assert len(prims) == (2 if back_faces == "primitive" else 1)
    mesh = bake(leaf, GRID, backend="numpy")
    expected_images = [data["front"], data.get("back", data["front"])]
    for prim, image_bytes in zip(prims, expected_images):
        mat = f.doc["materials"][prim["material"]]
        assert mat["alphaMode"] == "MASK" and mat["alphaCutoff"] == 0.5
        assert mat["doubleSided"] is (back_faces == "double-sided")
        pbr = mat["pbrMetallicRoughness"]
        assert pbr["baseColorFactor"] == [1.0, 1.0, 1.0, 1.0] and pbr["baseColorTexture"]["texCoord"] == 0
        tex = f.doc["textures"][pbr["baseColorTexture"]["index"]]
        assert f.doc["samplers"][tex["sampler"]] == {"magFilter": 9729, "minFilter": 9987, "wrapS": 33071,
                                                     "wrapT": 33071}
        image = f.doc["images"][tex["source"]]
        view = f.doc["bufferViews"][image["bufferView"]]
        assert image["mimeType"] == "image/png"
        assert f.blob[view["byteOffset"]:view["byteOffset"] + view["byteLength"]] == image_bytes
        st = f.accessor(prim["attributes"]["TEXCOORD_0"]).astype(np.float64)
        assert np.array_equal(f.accessor(prim["attributes"]["POSITION"]), mesh.positions)
        assert np.abs(st - np.stack(texture_st(mesh.uv[:, 0], mesh.uv[:, 1]), 1)).max() <= 1e-7
    assert len(f.doc["images"]) == (2 if back and back_faces == "primitive" else 1)


@pytest.mark.usefixtures("gltf_validator")
def test_both_halves_of_an_asymmetric_leaf_share_one_image_and_the_convention(tmp_path, presets):
    leaf, _ = textured_leaf(tmp_path / "src", presets["ovate"])
    halves = [leaf.replace(name=f"half{h:+d}", shape=replace(leaf.shape, half=h)) for h in (-1, 1)]
    path = export_leaves(halves, tmp_path / "halves.glb", backend="numpy", resolution=GRID)
    assert_gltf_clean(path)
    f = read_gltf(path)
    assert len(f.doc["images"]) == 1 and len(f.doc["textures"]) == 1
    for h, gmesh in zip((-1, 1), f.doc["meshes"]):
        prim = gmesh["primitives"][0]
        s = f.accessor(prim["attributes"]["TEXCOORD_0"])[:, 0]
        # half -1 draws u in [-1, 0]: the right half of the image; half +1 the left half
        assert (s.min(), s.max()) == ((0.5, 1.0) if h == -1 else (0.0, 0.5))
        mesh = bake(halves[(h + 1) // 2], GRID, backend="numpy")
        assert np.array_equal(f.accessor(prim["attributes"]["TEXCOORD_0"]),
                              np.stack(texture_st(mesh.uv[:, 0], mesh.uv[:, 1]), 1).astype(np.float32))


# -- USD ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_usd_preview_surface_reads_the_image_beside_it(tmp_path, ovate, suffix):
    from pxr import Sdf, Usd, UsdGeom, UsdShade

    leaf, data = textured_leaf(tmp_path / "src", ovate, back="back.png")
    path = export_leaf(leaf, tmp_path / "out" / f"oak{suffix}", backend="numpy", resolution=GRID)
    assert files(path.parent) == sorted(["back.png", "front.png", path.name])
    assert usd_errors(path) == []       # UsdValidation: shader types (Sdr), unresolvable assets, bindings
    mesh = bake(leaf, GRID, backend="numpy")
    s, t = texture_st(mesh.uv[:, 0], mesh.uv[:, 1])
    stage = Usd.Stage.Open(str(path))
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    assert [p.GetName() for p in meshes] == ["front", "back"]
    for prim, side in zip(meshes, ("front", "back")):
        st = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
        assert st.GetInterpolation() == "vertex"
        assert np.abs(np.asarray(st.Get()) - np.stack([s, 1.0 - t], 1)).max() <= 1e-7   # origin lower left
        material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        surface = material.ComputeSurfaceSource()[0]
        assert surface.GetIdAttr().Get() == "UsdPreviewSurface"
        assert surface.GetInput("opacityThreshold").Get() == pytest.approx(0.5)
        (colour,) = surface.GetInput("diffuseColor").GetConnectedSources()[0]
        (alpha,) = surface.GetInput("opacity").GetConnectedSources()[0]
        image = UsdShade.Shader(colour.source.GetPrim())
        assert (colour.sourceName, alpha.sourceName) == ("rgb", "a") and alpha.source.GetPrim() == image.GetPrim()
        assert image.GetIdAttr().Get() == "UsdUVTexture"
        asset = image.GetInput("file").Get()
        assert isinstance(asset, Sdf.AssetPath) and asset.path == f"./{side}.png"
        assert Path(asset.resolvedPath).read_bytes() == data[side]
        assert image.GetInput("wrapS").Get() == "clamp" and image.GetInput("sourceColorSpace").Get() == "sRGB"
        (coord,) = image.GetInput("st").GetConnectedSources()[0]
        reader = UsdShade.Shader(coord.source.GetPrim())
        assert reader.GetIdAttr().Get() == "UsdPrimvarReader_float2" and reader.GetInput("varname").Get() == "st"


# -- OBJ / PLY ---------------------------------------------------------------------------------
def test_obj_mtl_names_the_copied_image(tmp_path, ovate):
    leaf, data = textured_leaf(tmp_path / "src", ovate, front="my leaf.png", back="back.png")
    path = export_leaf(leaf, tmp_path / "out" / "oak leaf.obj", backend="numpy", resolution=GRID)
    # one-sided format: the front image only; names without blanks (mtllib splits on them)
    assert files(path.parent) == ["my_leaf.png", "oak leaf.obj", "oak_leaf.mtl"]
    lines = path.read_text().splitlines()
    v = [ln for ln in lines if ln.startswith("v ")]
    vt = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("vt ")])
    assert len(vt) == len(v) and "mtllib oak_leaf.mtl" in lines
    mesh = bake(leaf, GRID, backend="numpy")
    s, t = texture_st(mesh.uv[:, 0], mesh.uv[:, 1])
    assert np.abs(vt - np.stack([s, 1.0 - t], 1)).max() <= 1e-7
    used = {ln.split()[1] for ln in lines if ln.startswith("usemtl ")}
    mtl = (path.parent / "oak_leaf.mtl").read_text().splitlines()
    assert used == {ln.split()[1] for ln in mtl if ln.startswith("newmtl ")}
    assert "map_Kd my_leaf.png" in mtl and "map_d my_leaf.png" in mtl
    assert (path.parent / "my_leaf.png").read_bytes() == data["front"]
    loaded = trimesh.load(path, process=False)        # an independent importer finds the image
    assert loaded.visual.material.image.size == (64, 32)


def test_ply_names_the_image_and_carries_s_t(tmp_path, ovate):
    leaf, data = textured_leaf(tmp_path / "src", ovate)
    path = export_leaf(leaf, tmp_path / "out" / "oak.ply", backend="numpy", resolution=GRID)
    assert files(path.parent) == ["front.png", "oak.ply"]
    raw = path.read_bytes()
    header = raw[:raw.index(b"end_header\n") + 11].decode("ascii")
    assert "comment TextureFile front.png\n" in header and "texnumber" not in header
    mesh = bake(leaf, GRID, backend="numpy")
    vert = np.frombuffer(raw, [(k, "<f4") for k in ("x", "y", "z", "nx", "ny", "nz", "s", "t")], mesh.n_vertices,
                         len(header))
    s, t = texture_st(mesh.uv[:, 0], mesh.uv[:, 1])
    assert np.abs(vert["s"] - s).max() <= 1e-7 and np.abs(vert["t"] - (1.0 - t)).max() <= 1e-7
    assert (path.parent / "front.png").read_bytes() == data["front"]


def test_tiff_and_exr_textures_become_png(tmp_path, ovate):
    src = tmp_path / "src"
    src.mkdir()
    px = rgba(5)
    out = oiio.ImageOutput.create(str(src / "a.tif"))
    assert out.open(str(src / "a.tif"), oiio.ImageSpec(64, 32, 4, "uint8")) and out.write_image(px) and out.close()
    linear = np.full((8, 8, 3), 0.5, np.float32)
    out = oiio.ImageOutput.create(str(src / "b.exr"))
    assert out.open(str(src / "b.exr"), oiio.ImageSpec(8, 8, 3, "float")) and out.write_image(linear) and out.close()
    leaves = [ovate.replace(name=n, texture=LeafTexture(f, folder=str(src))) for n, f in (("a", "a.tif"), ("b", "b.exr"))]
    path = export_leaves(leaves, tmp_path / "out" / "set.obj", backend="numpy", resolution=GRID)
    assert files(path.parent) == ["a.png", "b.png", "set.mtl", "set.obj"]
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    a = oiio.ImageInput.open(str(path.parent / "a.png"), config)
    assert np.array_equal(a.read_image("uint8"), px)
    a.close()
    b = oiio.ImageInput.open(str(path.parent / "b.png"))
    got = b.read_image("uint8")
    assert (got[..., :3] == 188).all() and (got[..., 3] == 255).all()   # linear 0.5 sRGB-encoded: 0.7354 * 255
    b.close()


# -- errors and atomicity ----------------------------------------------------------------------
@pytest.mark.parametrize("suffix", SUFFIXES)
def test_a_missing_image_is_refused_naming_leaf_and_file_and_nothing_is_written(tmp_path, ovate, suffix):
    leaf, _ = textured_leaf(tmp_path / "src", ovate, name="holm oak", back="back.png")
    os.remove(tmp_path / "src" / "back.png")
    (tmp_path / "out").mkdir()
    with pytest.raises(ParamError) as info:
        export_leaf(leaf, tmp_path / "out" / f"oak{suffix}", backend="numpy", resolution=GRID)
    assert info.value.path == "texture.back"
    assert "'holm oak'" in str(info.value) and str(tmp_path / "src" / "back.png") in str(info.value)
    assert files(tmp_path / "out") == []


@pytest.mark.parametrize("suffix", [".glb", ".obj"])
def test_a_truncated_image_is_refused_before_anything_is_written(tmp_path, ovate, suffix):
    leaf, data = textured_leaf(tmp_path / "src", ovate)
    (tmp_path / "src" / "front.png").write_bytes(data["front"][: len(data["front"]) // 2])
    (tmp_path / "out").mkdir()
    with pytest.raises(ParamError) as info:
        export_leaf(leaf, tmp_path / "out" / f"oak{suffix}", backend="numpy", resolution=GRID)
    assert info.value.path == "texture.front" and "front.png" in str(info.value)
    assert files(tmp_path / "out") == []


def test_the_command_line_refuses_a_missing_image_with_exit_2(tmp_path, ovate, capsys):
    textured_leaf(tmp_path / "src", ovate)
    os.remove(tmp_path / "src" / "front.png")
    (tmp_path / "out").mkdir()
    assert main(["export", str(tmp_path / "src" / "leaf.leaf.json"), "-o", str(tmp_path / "out" / "oak.obj"),
                 "--backend", "numpy"]) == 2
    assert "front.png" in capsys.readouterr().err and files(tmp_path / "out") == []


def test_a_failure_after_the_image_is_staged_leaves_nothing(tmp_path, ovate, monkeypatch):
    leaf, _ = textured_leaf(tmp_path / "src", ovate)
    real = objply.write_text

    def failing(path, text, *args):
        if str(path).endswith(".obj"):
            raise OSError(28, "No space left on device")
        return real(path, text, *args)

    monkeypatch.setattr(objply, "write_text", failing)
    (tmp_path / "out").mkdir()
    with pytest.raises(OSError):
        export_leaf(leaf, tmp_path / "out" / "oak.obj", backend="numpy", resolution=GRID)
    assert files(tmp_path / "out") == []      # neither the image, the .mtl nor a temporary file


def test_image_names_come_from_the_files_and_stay_unique(tmp_path, ovate):
    a, a_data = textured_leaf(tmp_path / "a", ovate, name="../../escape", seed=1)
    b, b_data = textured_leaf(tmp_path / "b", ovate, name="/abs/path", seed=2)    # also front.png
    out = tmp_path / "out"
    path = export_leaves([a, b], out / "set.usda", backend="numpy", resolution=GRID)
    assert files(out) == ["front-2.png", "front.png", "set.usda"]
    assert (out / "front.png").read_bytes() == a_data["front"] and (out / "front-2.png").read_bytes() == b_data["front"]
    assert usd_errors(path) == []
    assert files(tmp_path) == ["a", "b", "out"]
    # one run writing one file per leaf into one folder: two different images never share a name
    cli = tmp_path / "cli"
    assert main(["export", str(tmp_path / "a" / "leaf.leaf.json"), str(tmp_path / "b" / "leaf.leaf.json"),
                 "-o", str(cli), "--format", "obj", "--backend", "numpy", "--veins", "off", "--quiet"]) == 0
    assert files(tmp_path) == ["a", "b", "cli", "out"]
    objs = sorted(cli.glob("*.obj"))
    assert len(objs) == 2 and len([n for n in files(cli) if n.endswith(".png")]) == 2
    for obj, data in zip(objs, (a_data, b_data) if "escape" in objs[0].name else (b_data, a_data)):
        mtl = obj.with_suffix(".mtl").read_text().splitlines()
        (image,) = [ln.split()[1] for ln in mtl if ln.startswith("map_Kd ")]
        assert (cli / image).read_bytes() == data["front"]


# -- scenes ------------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.usefixtures("gltf_validator")
def test_a_textured_species_writes_its_image_once(tmp_path, presets, suffix):
    leaf, _ = textured_leaf(tmp_path / "src", presets["ovate"].replace(transform=Transform()))
    # a textured species in three varied shapes (five leaves) and a plain one
    shapes = [leaf.replace(shape=replace(leaf.shape, a1=(z, 1 / 3, 0.0))) for z in (0.0, 0.05, 0.1)] + [presets["maize"]]
    mats = np.stack([Transform(translation=(i, 0, 0)).matrix() for i in range(6)])
    scene = StandInScene(shapes, np.array([0, 0, 1, 2, 2, 3], np.int32), mats)
    path = export_scene(scene, tmp_path / "out" / f"scene{suffix}", backend="numpy", resolution=GRID)
    beside = [n for n in files(path.parent) if n.endswith(".png")]
    if suffix in (".glb", ".gltf"):
        assert beside == []
        assert_gltf_clean(path)
        doc = read_gltf(path).doc
        assert len(doc["images"]) == 1 and len(doc["textures"]) == 1
        textured = [m for m in doc["materials"] if "baseColorTexture" in m["pbrMetallicRoughness"]]
        assert len(textured) == 2                                    # front and back, shared by 3 shapes
    else:
        assert beside == ["front.png"]
    if suffix == ".obj":
        mtl = (path.parent / "scene.mtl").read_text()
        assert mtl.count("map_Kd front.png") == 1 and mtl.count("newmtl") == 2   # the image, maize's colour
    if suffix.startswith(".usd"):
        assert usd_errors(path) == []
        from pxr import Usd, UsdShade

        stage = Usd.Stage.Open(str(path))
        images = [p for p in stage.Traverse() if p.GetName() == "Image"]
        assert len(images) == 2                                      # front and back materials
        assert {UsdShade.Shader(p).GetInput("file").Get().path for p in images} == {"./front.png"}


def test_a_leaf_set_sharing_an_image_writes_it_once(tmp_path, presets):
    leaf, data = textured_leaf(tmp_path / "src", presets["ovate"])
    leaves = [leaf.replace(name=f"leaf{i}", transform=Transform(translation=(i, 0, 0))) for i in range(3)]
    save_leaves(leaves, tmp_path / "src" / "set.leaves.json")
    loaded = load_leaves(tmp_path / "src" / "set.leaves.json")
    assert main(["export", str(tmp_path / "src" / "set.leaves.json"), "-o", str(tmp_path / "out" / "set.obj"),
                 "--backend", "numpy", "--quiet"]) == 0
    assert files(tmp_path / "out") == ["front.png", "set.mtl", "set.obj"]
    assert all(leaf.texture is not None for leaf in loaded)
    assert (tmp_path / "out" / "front.png").read_bytes() == data["front"]
