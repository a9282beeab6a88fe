"""Textured leaves in the shader model (leafview.gpu.textures): what the fragment shader draws
at each pixel is the numpy twin of the lookup (texture_st, bilinear, clamp to edge, sRGB decoded)
at the (u, v) the label pass reads back there, and texels with alpha < 0.5 are background in the
picture and in the labels alike. For one leaf (the thumbnail path), for a rippled and bent leaf
(the texture follows the deformation), and for a scene of two textured species and a plain one,
drawn in as many draw calls as without textures."""

from __future__ import annotations

import dataclasses
import os

import moderngl
import numpy as np
import pytest
from scipy.ndimage import binary_erosion
from support.transforms import axis_rotation

from leafview.botany.vein_shading import without_veins
from leafview.cli import main
from leafview.core.defaults import DEFAULT_GRID
from leafview.core.params import Bending, LeafParams, Transform
from leafview.core.texture import LeafTexture, texture_st, with_folder
from leafview.errors import ParamError
from leafview.export.images import read_image, write_image
from leafview.gpu.aov import render_aovs
from leafview.gpu.layout import LEAF_SLOTS, PLAIN_DEFINES, pack_leaves, read_slot, texture_defines, texture_keys
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.gpu.sheets import render_leaves
from leafview.gpu.textures import (
    MAX_LAYER_SIZE,
    layer_size,
    load_layers,
    read_texture,
    sample_layer,
    srgb_to_linear,
    texture_lookup,
)
from leafview.resources import builtin_presets
from leafview.scene.camera import Camera, top_down
from leafview.scene.spec import Scene, SceneSpec, scene_from_leaves
from tests.conftest import assert_matches_reference

SIZE = (176, 144)        # one leaf
SCENE_SIZE = (320, 368)  # nine leaves
COLOUR_TOL = 0.01        # linear colour: the sampler filters 8-bit texels in 8 bits
SRGB_TOL = 0.02          # ... and again after the 8-bit sRGB picture's rounding, decoded
FIRM_TEXELS = 1.5        # the alpha test is compared where the twin decides it within this many texels
LEVEL0 = CullSettings(cull=False, lod=False)


# -- textures (files written by the tests) ------------------------------------------------------------
def _ramp(w: int, h: int, hole: tuple[float, float, float] | None) -> np.ndarray:
    """Red rises with s, green with t (both linear in the stored sRGB values), blue constant; alpha
    0 in a disc (s, t, radius in s units)."""
    s = (np.arange(w) + 0.5) / w
    t = (np.arange(h) + 0.5) / h
    img = np.empty((h, w, 4), np.uint8)
    img[..., 0] = np.rint(30 + 190 * s)[None, :]
    img[..., 1] = np.rint(40 + 180 * t)[:, None]
    img[..., 2] = 90
    img[..., 3] = 255
    if hole is not None:
        cs, ct, r = hole
        img[((s[None, :] - cs) ** 2 + ((t[:, None] - ct) * h / w) ** 2) < r * r, 3] = 0
    return img


def _stripes(w: int, h: int) -> np.ndarray:
    """A smooth colour field, with teeth cut into the u = +1 margin (s near 0)."""
    s = ((np.arange(w) + 0.5) / w)[None, :]
    t = ((np.arange(h) + 0.5) / h)[:, None]
    img = np.empty((h, w, 4), np.uint8)
    img[..., 0] = np.rint(140 + 90 * np.sin(2 * np.pi * t)) + 0 * s
    img[..., 1] = np.rint(200 - 150 * s) + 0 * t
    img[..., 2] = np.rint(60 + 120 * s * t)
    teeth = s < 0.08 + 0.10 * np.abs(((t * 6) % 1.0) - 0.5)
    img[..., 3] = np.where(teeth, 0, 255)
    return img


def _checker(n: int) -> np.ndarray:
    """Yellow and green squares of 8 texels with a hole: to look at."""
    yy, xx = np.mgrid[0:n, 0:n]
    on = ((xx // 8) + (yy // 8)) % 2 == 1
    img = np.zeros((n, n, 4), np.uint8)
    img[..., 0] = np.where(on, 230, 40)
    img[..., 1] = np.where(on, 200, 120)
    img[..., 2] = 60
    img[..., 3] = np.where((xx - 0.62 * n) ** 2 + (yy - 0.4 * n) ** 2 < (0.1 * n) ** 2, 0, 255)
    return img


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("textured")
    write_image(d / "ramp.png", _ramp(32, 32, (0.62, 0.45, 0.14)))
    write_image(d / "stripes.png", _stripes(24, 16))
    back = _ramp(16, 16, None)[..., [2, 0, 1, 3]]   # another colour field
    write_image(d / "back.png", back)
    write_image(d / "checker.png", _checker(64))
    return d


def _leaf(name: str, folder, front: str | None, back: str = "", **changes) -> LeafParams:
    base = LeafParams.load(builtin_presets()["ovate"])
    tex = None if front is None else with_folder(LeafTexture(front, back), folder)
    return base.replace(name=name, texture=tex, transform=Transform(), **changes)


def _rippled_bent(name: str, folder, front: str | None) -> LeafParams:
    rip = LeafParams.load(builtin_presets()["maize"]).ripple
    return _leaf(name, folder, front, ripple=dataclasses.replace(rip, enabled=True, seed=11),
                 bending=Bending(load=3.0, twist=-20.0))


def _untextured(scene: Scene) -> Scene:
    """The same scene without images: its labels give the (u, v) under every texel, holes included."""
    species = tuple(sp.replace(texture=None) for sp in scene.species)
    spec = dataclasses.replace(scene.spec, species=species)
    return dataclasses.replace(scene, spec=spec, species=species)


def _camera(lo: tuple[float, float], hi: tuple[float, float], size: tuple[int, int] = SIZE) -> Camera:
    """Top-down orthographic camera over the box lo..hi (x, y), aspect of ``size``."""
    cx, cy = (lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2
    half_h = max((hi[1] - lo[1]) / 2, (hi[0] - lo[0]) / 2 * size[1] / size[0])
    return top_down((cx, cy), 3.0, half_h * size[0] / size[1], half_h, 6.0)


def _labels(gl, scene: Scene, camera: Camera, size: tuple[int, int] = SIZE):
    """(unlit sRGB picture, instance, uv) of ``scene``, all single-sample, grid level 0 everywhere."""
    with SceneRenderer(gl.ctx, scene, grids=(DEFAULT_GRID,), resources=gl.resources) as r:
        rgb = r.render(camera, size, LEVEL0, samples=0, flat=True)
        aov = render_aovs(r, camera, size, ("instance", "uv"), settings=LEVEL0)
    return rgb, aov.instance, aov.uv


def _firm_keep(layer: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(keep, firm): the twin's alpha test at (u, v), and where it is the same within
    FIRM_TEXELS texels around (the GPU's 8-bit filter and mipmaps may decide otherwise at the
    mask's edge)."""
    h, w = layer.shape[:2]
    keep = texture_lookup(layer, u, v)[1]
    firm = np.ones_like(keep)
    du, dv = 2 * FIRM_TEXELS / w, FIRM_TEXELS / h
    for a in (-du, 0.0, du):
        for b in (-dv, 0.0, dv):
            firm &= texture_lookup(layer, np.clip(u + a, -1, 1), np.clip(v + b, 0, 1))[1] == keep
    return keep, firm


def _level0(uv: np.ndarray, layer: np.ndarray) -> np.ndarray:
    """Pixels where a pixel step moves (s, t) by at most one texel: the GPU samples mipmap level 0
    there, as the twin does (elsewhere, near the tips, coarser levels clamp at other texels)."""
    h, w = layer.shape[:2]
    s, t = texture_st(uv[..., 0], uv[..., 1])
    steps = [np.hypot(np.gradient(s, axis=a) * w, np.gradient(t, axis=a) * h) for a in (0, 1)]
    return np.maximum(*steps) <= 1.0


# -- numpy: the twin and the layers -------------------------------------------------------------------
def test_twin_samples_texel_centres_and_clamps():
    img = _ramp(8, 4, None)
    cols, rows = np.meshgrid(np.arange(8), np.arange(4))
    got = sample_layer(img, (cols + 0.5) / 8, (rows + 0.5) / 4)
    np.testing.assert_allclose(got * 255, img.astype(np.float64), atol=1e-9)
    # halfway between two texel centres: their mean; outside the centres: the edge texel
    mid = sample_layer(img, np.array([1.0 / 8]), np.array([0.5 / 4]))[0]
    np.testing.assert_allclose(mid * 255, (img[0, 0] + img[0, 1].astype(np.float64)) / 2)
    np.testing.assert_allclose(sample_layer(img, np.array([0.0]), np.array([1.0]))[0] * 255, img[3, 0])
    # the convention: u = +1 is the left column, v = 1 (apex) the top row
    s, t = texture_st(1.0, 1.0)
    assert (float(s), float(t)) == (0.0, 0.0)
    rgb, keep = texture_lookup(img, np.array([1.0]), np.array([1.0]))
    np.testing.assert_allclose(rgb[0], srgb_to_linear(img[0, 0, :3] / 255.0))
    assert keep[0]
    # sRGB decoding: the curve's own values
    np.testing.assert_allclose(srgb_to_linear([0.0, 0.04, 0.5, 1.0]), [0.0, 0.04 / 12.92, 0.21404114, 1.0], rtol=1e-6)


def test_layers_records_and_common_size(folder):
    a = _leaf("a", folder, "ramp.png")
    b = _leaf("b", folder, "stripes.png", "back.png")
    plain = _leaf("plain", folder, None)
    leaves = [plain, a, b, a]
    data = load_layers(leaves)
    assert [os.path.basename(k) for k in data.keys] == ["ramp.png", "stripes.png", "back.png"]
    assert data.images.shape == (3, 32, 32, 4)       # the largest width and the largest height
    np.testing.assert_array_equal(load_layers([a]).images[0], _ramp(32, 32, (0.62, 0.45, 0.14)))  # as stored
    np.testing.assert_array_equal(read_texture(folder / "stripes.png"), _stripes(24, 16))   # straight alpha
    assert layer_size([(1500, 300, 4), (10, 5000, 4)]) == (MAX_LAYER_SIZE, 1500)   # (h, w) shapes -> (w, h)
    records, _ = pack_leaves(leaves, textures=data.keys)
    assert read_slot(records, "leaf_front_layer").tolist() == [-1, 0, 1, 0]
    assert read_slot(records, "leaf_back_layer").tolist() == [-1, 0, 2, 0]   # a: its front on the back
    assert texture_defines(records) == {} and texture_defines(records[:1]) == PLAIN_DEFINES
    # the layers sit in the model matrix's last row; an untextured record keeps it (0, 0, 0, 1)
    assert {s.accessor for s in LEAF_SLOTS if s.member == "model"} == {"leaf_front_layer", "leaf_back_layer",
                                                                       "leaf_vein_layer"}
    np.testing.assert_array_equal(records["model"][0].T, plain.transform.matrix())
    np.testing.assert_array_equal(records["model"][2, :, :3], records["model"][0, :, :3])
    assert texture_keys(leaves) == list(data.keys)


# -- errors -----------------------------------------------------------------------------------------
@pytest.mark.gl
def test_missing_or_unreadable_texture_names_the_leaf_and_the_file(gl, folder, tmp_path):
    (tmp_path / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n not really")
    good = _leaf("good", folder, "ramp.png")
    for name, leaf, file in (("lost", _leaf("lost", tmp_path, "missing.png"), tmp_path / "missing.png"),
                             ("broken", _leaf("broken", tmp_path, "broken.png"), tmp_path / "broken.png")):
        before = gl.textures.uploads
        with pytest.raises(ParamError) as err:
            gl.render_many([good, leaf], (32, 32))
        assert err.value.source == str(file.resolve())
        assert f"'{name}'" in str(err.value) and "texture." in err.value.path
        assert gl.textures.uploads == before          # raised before anything was uploaded or drawn
        with pytest.raises(ParamError, match=name):
            SceneRenderer(gl.ctx, scene_from_leaves([good, leaf]), resources=gl.resources)
    assert gl.ctx.error == "GL_NO_ERROR"


# -- readback: one leaf (the thumbnail path) ---------------------------------------------------------------
@pytest.mark.gl
def test_one_leaf_render_is_the_twin_at_the_read_uv(gl, folder):
    leaf = _leaf("ramp leaf", folder, "ramp.png")
    scene = scene_from_leaves([leaf])
    camera = _camera((-0.45, -0.05), (0.45, 1.05))
    _, inst_plain, uv_plain = _labels(gl, _untextured(scene), camera)
    _, inst_tex, uv_tex = _labels(gl, scene, camera)
    img = gl.render_many([leaf], SIZE, "top", camera=camera, samples=0, linear=True, flat=True)[0]
    layer = load_layers([leaf]).images[0]
    inside = binary_erosion(inst_plain > 0, iterations=2)
    u, v = uv_plain[..., 0][inside], uv_plain[..., 1][inside]
    keep, firm = _firm_keep(layer, u, v)
    albedo = texture_lookup(layer, u, v)[0]
    assert firm.sum() > 0.8 * inside.sum() and (~keep & firm).sum() > 30   # a leaf, with a hole in it
    # the picture: the twin's colour where kept, background where the mask is transparent
    drawn = img[..., 3][inside] > 0.5
    assert np.array_equal(drawn[firm], keep[firm])
    level0 = keep & firm & _level0(uv_plain, layer)[inside]
    assert level0.sum() > 0.7 * keep.sum()
    err = np.abs(img[..., :3][inside] - albedo)[level0].max()
    assert err < COLOUR_TOL, err
    # the labels discard the same texels, and label the rest with the same (u, v)
    labelled = inst_tex[inside] > 0
    assert np.array_equal(labelled[firm], keep[firm])
    np.testing.assert_allclose(uv_tex[inside][keep & firm], uv_plain[inside][keep & firm], atol=1e-5)


# -- readback: a scene with two textured species and a plain one -------------------------------------------
@pytest.fixture(scope="module")
def mixed(folder) -> Scene:
    return _mixed(folder)


def _mixed(folder) -> Scene:
    """Three species (rippled and bent on the ramp with its hole; flat on the stripes with teeth and
    a back image; plain), three leaves each in a grid, one of each turned over (its back up), with
    shape and colour variation."""
    # the textured species keep their veins (relief only: the unlit colour is the image's); the plain
    # one has none, so that its colour is its material's
    species = (_rippled_bent("ramp", folder, "ramp.png"), _leaf("stripes", folder, "stripes.png", "back.png"),
               without_veins([_leaf("plain", folder, None)])[0])
    n = 9
    rng = np.random.default_rng(5)
    matrices = []
    for i in range(n):
        place = np.eye(4)
        place[:3, 3] = (1.1 * (i % 3), 1.25 * (i // 3), 0.0)
        turn = axis_rotation(1, np.pi) if i // 3 == 1 else np.eye(4)    # the middle row shows its backs
        matrices.append(place @ turn @ axis_rotation(2, rng.uniform(-0.15, 0.15)))
    factors = (1.0 + 0.08 * rng.uniform(-1.0, 1.0, (n, 21))).astype(np.float32)
    tint = (1.0 + 0.1 * rng.uniform(-1.0, 1.0, n)).astype(np.float32)
    spec = SceneSpec(species=species, leaves=n, variation=0.08, colour_variation=0.1, stems=False)
    return Scene(spec, species, (np.arange(n) % 3).astype(np.int32), factors, tint, np.stack(matrices), None, None)


@pytest.mark.gl
def test_scene_species_are_their_twins_per_pixel(gl, mixed):
    camera = _camera((-0.6, -0.25), (2.8, 3.7), SCENE_SIZE)
    _, inst_plain, uv_plain = _labels(gl, _untextured(mixed), camera, SCENE_SIZE)
    rgb, inst_tex, uv_tex = _labels(gl, mixed, camera, SCENE_SIZE)
    layers = load_layers(mixed.species).images        # ramp, stripes, back: the uploaded layers
    front_of = {0: layers[0], 1: layers[1]}
    back_of = {0: layers[0], 1: layers[2]}
    inside = binary_erosion(inst_plain > 0, iterations=2)
    leaf = inst_plain.astype(np.int64) - 1
    picture = srgb_to_linear(rgb[..., :3] / 255.0)
    checked = {k: 0 for k in range(3)}
    holes = 0
    for i in range(len(mixed)):
        mine = inside & (leaf == i)
        sp, turned = int(mixed.species_id[i]), i // 3 == 1
        u, v = uv_plain[..., 0][mine], uv_plain[..., 1][mine]
        if sp == 2:   # plain: its colour times its tint (away from the midrib band), every pixel drawn
            m = mixed.species[2].material
            colour = np.clip(np.asarray(m.back if turned else m.front) * mixed.tint[i], 0, 1)
            away = np.abs(u) > 0.06
            assert (inst_tex[mine] == i + 1).all()
            assert np.abs(picture[mine][away] - colour).max() < SRGB_TOL
            checked[sp] += int(away.sum())
            continue
        layer = (back_of if turned else front_of)[sp]
        keep, firm = _firm_keep(layer, u, v)
        albedo = texture_lookup(layer, u, v)[0]
        drawn = rgb[..., 3][mine] > 127
        labelled = inst_tex[mine] == i + 1
        assert np.array_equal(drawn[firm], keep[firm]), (i, int((drawn != keep)[firm].sum()))
        assert np.array_equal(labelled[firm], keep[firm]), i
        level0 = keep & firm & _level0(uv_plain, layer)[mine]
        err = np.abs(picture[mine] - albedo)[level0]
        assert err.max() < SRGB_TOL, (i, float(err.max()))
        np.testing.assert_allclose(uv_tex[mine][keep & firm], uv_plain[mine][keep & firm], atol=1e-5)
        checked[sp] += int(level0.sum())
        holes += int((~keep & firm).sum())
    assert min(checked.values()) > 500 and holes > 100, (checked, holes)
    # the picture and its labels agree everywhere, edges included (one pass each, one sample)
    assert np.array_equal(rgb[..., 3] > 0, inst_tex > 0)


@pytest.mark.gl
def test_textured_scene_draws_in_as_many_calls(gl, mixed, monkeypatch):
    calls = {"n": 0}
    for name in ("render", "render_indirect"):
        original = getattr(moderngl.VertexArray, name)

        def counted(self, *args, _original=original, **kwargs):
            calls["n"] += 1
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(moderngl.VertexArray, name, counted)
    camera = _camera((-0.6, -0.25), (2.8, 3.7))
    counts = []
    for scene in (mixed, _untextured(mixed)):
        with SceneRenderer(gl.ctx, scene, resources=gl.resources) as r:
            r.render(camera, SIZE, samples=0)   # compile and cull once
            calls["n"] = 0
            r.render(camera, SIZE, samples=0)
            counts.append(calls["n"])
    # one indirect multi-draw for every species (two with veins: the finest level with its vein field,
    # the coarser ones without; leafview.gpu.scene.SceneRenderer.draw)
    assert counts[0] == counts[1] == (2 if any(p.venation.enabled for p in mixed.species) else 1), counts


# -- the viewer's path, the command line, the lit picture -----------------------------------------------
@pytest.mark.gl
def test_set_leaf_uploads_an_image_once_per_file_version(gl, folder, tmp_path):
    (tmp_path / "leaf.png").write_bytes((folder / "ramp.png").read_bytes())
    leaf = _leaf("viewer", tmp_path, "leaf.png")
    gl.set_leaf(leaf)
    first = gl.textures.uploads
    gl.set_leaf(leaf.replace(name="edited"))         # an edit of the parameters: nothing re-read or re-sent
    assert gl.textures.uploads == first
    stat = (tmp_path / "leaf.png").stat()
    os.utime(tmp_path / "leaf.png", ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))
    gl.set_leaf(leaf)                                 # the file changed on disk: uploaded again
    assert gl.textures.uploads == first + 32 * 32 * 4
    assert read_slot(gl._leaf, "leaf_front_layer") == read_slot(gl._leaf, "leaf_back_layer") == 0


@pytest.mark.gl
def test_render_command_draws_a_leaf_file_with_its_image(gl, folder, tmp_path):
    leaf = _leaf("cli leaf", folder, "ramp.png")
    leaf.save(folder / "cli.leaf.json")
    out = tmp_path / "cli.png"
    assert main(["render", str(folder / "cli.leaf.json"), "-o", str(out), "--size", "96", "-q"]) == 0
    image, _ = read_image(out)
    plain = gl.render(leaf.replace(texture=None), (96, 96))
    hole = (plain[..., 3] == 255) & (image[..., 3] == 0)
    assert 20 < hole.sum() < 0.2 * (plain[..., 3] == 255).sum()     # the mask's hole, and only it
    _leaf("lost", tmp_path, "gone.png").save(tmp_path / "lost.leaf.json")
    assert main(["render", str(tmp_path / "lost.leaf.json"), "-o", str(tmp_path / "lost.png"), "-q"]) == 2
    assert not (tmp_path / "lost.png").exists()


@pytest.mark.gl
def test_lit_textured_leaf_reference(gl, folder, request):
    """Lights times the images, multisampled edges and sRGB output (the readback tests above are
    unlit and single-sample): a rippled leaf, bent and twisted so that the front view shows the
    checker of its upper side and the colour field of its lower side."""
    leaf = _rippled_bent("lit", folder, None).replace(texture=with_folder(LeafTexture("checker.png", "back.png"), folder),
                                                      bending=Bending(load=3.0, twist=-60.0))
    assert_matches_reference(gl.render(leaf, (128, 80), "front"), "textured_leaf_lit", request)


def test_leaf_sheets_draw_the_images_too(gl, folder):
    """gpu.sheets.render_leaves (morph frames, multilobed leaves): the textured leaf shows its
    image, with the mask's hole transparent, where the plain leaf is one colour."""
    leaf = _leaf("ramp leaf", folder, "ramp.png")
    textured = render_leaves([leaf], (96, 96), "top", flat=True)
    plain = render_leaves([leaf.replace(texture=None)], (96, 96), "top", flat=True)
    drawn_t, drawn_p = textured[..., 3] > 127, plain[..., 3] > 127
    assert drawn_p.sum() > 1500 and drawn_t.sum() < drawn_p.sum() - 20     # the hole
    assert not (drawn_t & ~drawn_p).any()
    colours_t = np.unique(textured[drawn_t][:, :3] // 16, axis=0)
    colours_p = np.unique(plain[drawn_p][:, :3] // 16, axis=0)
    assert len(colours_t) > 4 * len(colours_p)     # a ramp, not the flat material colour
