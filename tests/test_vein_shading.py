"""Veins and leaf tissue in the picture (shaders/leaf_veins.glsl): the unlit colour of a veined
leaf is the numpy twin (leafview.botany.vein_shading) at the (u, v) the label pass reads back,
read from the numpy vein field; draws without veins build no vein program and show exactly the
leaf without venation; ``--veins on|off`` on render, scene and view; reference images of two
presets with veins on and off."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.ndimage import binary_erosion, maximum_filter

from leafview.botany.vein_field import vein_field
from leafview.botany.vein_shading import (
    major_width,
    order_weight,
    sample_field,
    vein_albedo,
    vein_coverage,
    vein_height,
    vein_strength,
    without_veins,
)
from leafview.cli import main
from leafview.core.colour import linear_to_srgb
from leafview.core.edits import scale_width
from leafview.core.params import LeafParams
from leafview.deform.surface import evaluate, grid_uv
from leafview.export.images import read_image
from leafview.gpu.aov import render_aovs
from leafview.gpu.layout import NO_VEIN_DEFINES, pack_leaves, read_slot, vein_defines
from leafview.gpu.scene import CullSettings, SceneRenderer, single_leaf_scene
from leafview.gpu.vein_draw import MAX_VEIN_LAYERS, field_leaves, fresh_layers
from leafview.scene.camera import Camera, top_down
from tests.conftest import assert_matches_reference

SIZE = (160, 224)
LEVEL0 = CullSettings(cull=False, lod=False)
EDGE_PIXELS = 1.5     # colours are compared this many pixel footprints away from every vein edge
SRGB_TOL = 3          # /255


def _veined(leaf: LeafParams, **changes: float) -> LeafParams:
    return leaf.replace(venation=dataclasses.replace(leaf.venation, enabled=True, **changes))


@pytest.fixture
def veined(presets) -> LeafParams:
    return _veined(presets["ovate"], contrast=0.9, relief=0.5, midrib_width=0.02)


def _camera(leaf: LeafParams, size: tuple[int, int], zoom: float = 1.0) -> Camera:
    """Top view of the whole leaf, or ``zoom`` times closer on the middle of its box."""
    pts = evaluate(leaf, *grid_uv(33, 65).astype(np.float64).T)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    half_h = 0.55 * max(hi[1] - lo[1], (hi[0] - lo[0]) * size[1] / size[0]) / zoom
    return top_down((lo[:2] + hi[:2]) / 2, hi[2] + 1.0, half_h * size[0] / size[1], half_h, hi[2] - lo[2] + 2.0)


# -- the twin (numpy) ------------------------------------------------------------------------------
def test_twin_weights_coverage_and_height():
    assert order_weight([1, 2, 3, 4]).tolist() == pytest.approx([1.0, 0.7, 0.4, 0.4])
    # a wide vein: full inside, none outside, the edge ramp one footprint wide
    cov = vein_coverage([0.0, 0.004, 0.005, 0.006, 0.01], 0.01, 0.002)
    assert cov[0] == cov[1] == 1.0 and cov[2] == pytest.approx(0.5) and cov[3] == cov[4] == 0.0
    # a vein narrower than a pixel: drawn a pixel wide, as faint as it is narrow
    thin = vein_coverage(0.0, 0.001, 0.004)
    assert thin == pytest.approx(0.25)   # width 0.001 over a 0.004 footprint
    assert vein_height(0.0, 0.01, 2.0) == pytest.approx(0.01) and vein_height(0.006, 0.01, 2.0) == 0.0
    # the major vein (A) keeps a secondary whole where a tertiary (R) is nearer
    texel = np.array([0.0004, 3.0, 0.001, 0.0008])
    assert vein_strength(texel, 0.006, (1e-4, 1e-4)) == pytest.approx(order_weight(2.0))


def test_vein_layers_are_packed_and_choose_the_program(presets):
    leaves = [presets["ovate"], presets["maize"], presets["willow"]]
    records, _ = pack_leaves(leaves, vein_layers=[1, -1, 0])
    assert read_slot(records, "leaf_vein_layer").tolist() == [1, -1, 0]
    assert vein_defines(records) == {} and vein_defines(records[1:2]) == dict(NO_VEIN_DEFINES)
    plain, _ = pack_leaves(leaves)
    assert (plain["model"][:, 2, 3] == 0).all()   # untextured, unveined: the matrix keeps its last row
    assert (read_slot(plain, "leaf_vein_layer") == -1).all()


def test_a_leaf_set_of_varied_shapes_shares_fields(presets):
    """Beyond MAX_VEIN_LAYERS distinct (shape, venation) keys (a leaf set: a shape per leaf), leaves
    of one venation share the first one's field; venations beyond the budget borrow one of their
    pattern; the layers are those a fresh field array assigns."""
    ovate, maize = presets["ovate"], presets["maize"]
    varied = [ovate.replace(shape=scale_width(ovate, 1.0 + 0.001 * k).shape) for k in range(MAX_VEIN_LAYERS + 6)]
    assert field_leaves(varied[:MAX_VEIN_LAYERS]) == varied[:MAX_VEIN_LAYERS]   # within the budget: their own
    shared = field_leaves([maize, *varied])
    assert shared[0] is maize and all(p is varied[0] for p in shared[1:])
    assert fresh_layers([maize, *varied]).tolist() == [0] + [1] * len(varied)
    seeds = [_veined(ovate, seed=k) for k in range(3)]
    assert [p.venation.seed for p in field_leaves(seeds, budget=2)] == [0, 1, 0]
    assert fresh_layers([without_veins([ovate])[0], *seeds], budget=2).tolist() == [-1, 0, 1, 0]


# -- the picture ------------------------------------------------------------------------------------
@pytest.mark.gl
def test_unlit_colour_is_the_twin_at_the_read_uv(gl, veined):
    """One veined leaf drawn unlit, top view, close up on its middle (veins several pixels wide):
    away from vein edges (where the twin does not depend on the screen-space footprint) each
    pixel is the twin's colour at the (u, v) read there."""
    scene = single_leaf_scene(veined)
    camera = _camera(veined, SIZE, zoom=3.0)
    with SceneRenderer(gl.ctx, scene, grids=((33, 65),)) as r:
        assert r.veins.active and "LEAF_NO_VEINS" not in r._defines()
        rgb = r.render(camera, SIZE, LEVEL0, samples=0, flat=True)
        aov = render_aovs(r, camera, SIZE, ("instance", "uv"), settings=LEVEL0)
    inside = binary_erosion(aov.instance > 0, iterations=2)
    u, v = aov.uv[..., 0].astype(np.float64), aov.uv[..., 1].astype(np.float64)
    texel = sample_field(vein_field(veined), u, v)
    # fwidth of R and A from the neighbouring pixels' (u, v), widened over 3×3 for safety
    fw = np.stack([maximum_filter(np.abs(np.diff(c, axis=1, append=c[:, -1:])) + np.abs(np.diff(c, axis=0, append=c[-1:])),
                                  size=3) for c in (texel[..., 0], texel[..., 3])], axis=-1)
    major = major_width(veined.venation)
    firm = inside.copy()
    for d, w, f in ((texel[..., 0], texel[..., 2], fw[..., 0]), (texel[..., 3], major, fw[..., 1])):
        firm &= np.abs(d - np.maximum(0.5 * w, 0.5 * f)) > EDGE_PIXELS * f
    strength = vein_strength(texel, major, fw)
    twin = vein_albedo(np.asarray(veined.material.front), strength, u, v, veined.venation.contrast)
    expected = np.rint(linear_to_srgb(twin) * 255.0)
    diff = np.abs(rgb[..., :3].astype(np.float64) - expected)[firm]
    assert firm.sum() > 0.4 * inside.sum()
    on_veins = firm & (strength > 0.5)
    assert on_veins.sum() > 300, "the comparison must cover vein pixels"
    lamina = np.rint(linear_to_srgb(vein_albedo(np.asarray(veined.material.front), 0.0, u, v, 0.0)) * 255)
    assert np.abs(expected - lamina)[on_veins].max() > 20   # the veins do show
    assert diff.max() <= SRGB_TOL, f"{(diff > SRGB_TOL).any(axis=-1).sum()} pixels differ, max {diff.max()}"


@pytest.mark.gl
def test_veins_off_is_the_leaf_without_venation(gl, veined):
    plain = without_veins([veined])[0]
    assert not plain.venation.enabled and without_veins([plain])[0] is plain
    reference = gl.render(plain, (96, 96), "three-quarter")
    assert np.abs(gl.render(veined, (96, 96), "three-quarter").astype(int) - reference).max() > 30
    gl.veins = False
    try:
        assert np.array_equal(gl.render(veined, (96, 96), "three-quarter"), reference)
        assert not gl.batch_veins.active   # nothing built for a draw without veins
    finally:
        gl.veins = True
    # a scene: built without veins, or drawn with them turned off, is the scene without venation
    camera = _camera(veined, (96, 96))
    with SceneRenderer(gl.ctx, single_leaf_scene(plain)) as r:
        assert "LEAF_NO_VEINS" in r._defines() and not r.veins.active
        want = r.render(camera, (96, 96), LEVEL0)
    with SceneRenderer(gl.ctx, single_leaf_scene(veined), veins=False) as r:
        assert np.array_equal(r.render(camera, (96, 96), LEVEL0), want)
    with SceneRenderer(gl.ctx, single_leaf_scene(veined)) as r:
        assert not np.array_equal(r.render(camera, (96, 96), LEVEL0), want)
        r.show_veins = False
        assert np.abs(r.render(camera, (96, 96), LEVEL0).astype(int) - want).max() <= 1


@pytest.mark.gl
def test_set_leaf_builds_a_field_per_key(gl, veined):
    gl.set_leaf(without_veins([veined])[0])
    assert not gl.leaf_veins.active                   # a leaf without veins holds none
    gl.set_leaf(veined)
    fields = gl.leaf_veins.fields
    assert fields is not None and fields.computed == 1
    gl.set_leaf(veined.replace(material=dataclasses.replace(veined.material, front=(0.2, 0.5, 0.1))))
    assert fields.computed == 1                       # the same shape and venation: nothing computed
    gl.set_leaf(_veined(veined, contrast=0.3))
    assert fields.computed == 2                       # a new key: one field
    gl.set_leaf(without_veins([veined])[0])
    assert not gl.leaf_veins.active                   # released


@pytest.mark.gl
def test_viewer_checkboxes_turn_veins_off_and_on(gl, veined, tmp_path):
    from imgui_bundle import imgui

    from leafview.app.scene_view import SceneView
    from leafview.app.viewer import Viewer, open_state

    v = Viewer(gl.ctx, open_state(veined, None), samples=0, screenshot_dir=tmp_path)
    try:
        size = (720, 480)
        shots = []
        v.frame(size, size, 1 / 60)   # frames the leaf
        for show in (True, False, True):
            v.state.view.show_veins = show   # the panel's "veins" checkbox
            v.frame(size, size, 1 / 60)
            assert v.renderer is not None and v.renderer.veins is show and v.renderer.leaf_veins.active is show
            shots.append(v.read_frame()[:-60, :int(v.layout(size[0])[0])].astype(int))   # no status line
        assert np.abs(shots[0] - shots[1]).max() > 20 and np.abs(shots[0] - shots[2]).max() <= 1
    finally:
        v.release()
    scene = single_leaf_scene(veined)
    view = SceneView(gl.ctx, scene, veins=False)   # leafview scene --view --veins off
    try:
        assert view.renderer is not None and view.renderer.veins.active and not view.renderer.show_veins
        view.frame((600, 400))
        imgui.get_io().add_key_event(imgui.Key.v, True)
        view.frame((600, 400))
        imgui.get_io().add_key_event(imgui.Key.v, False)
        view.frame((600, 400))
        assert view.renderer.show_veins and not view.gl_errors
    finally:
        view.release()


# -- the command line ---------------------------------------------------------------------------------
@pytest.mark.parametrize("command", [["render", "ovate", "-o", "x.png"], ["scene", "-o", "x.png"], ["view"]])
def test_bad_veins_value_exits_2(tmp_path, monkeypatch, capsys, command):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main([*command, "--veins", "maybe"])
    assert info.value.code == 2
    assert "--veins" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.gl
def test_render_veins_off_draws_no_veins(gl, veined, tmp_path):
    path = tmp_path / "veined.toml"
    veined.save(path)
    on, off = tmp_path / "on.png", tmp_path / "off.png"
    assert main(["render", str(path), "-o", str(on), "--size", "64", "-q"]) == 0
    assert main(["render", str(path), "-o", str(off), "--size", "64", "-q", "--veins", "off"]) == 0
    plain = gl.render(without_veins([veined])[0], (64, 64), "top")
    assert np.array_equal(read_image(off)[0], plain)
    assert not np.array_equal(read_image(on)[0], plain)


# -- reference images ---------------------------------------------------------------------------------
REFERENCE = [("ovate", "three-quarter"), ("orbicular", "top")]   # pinnate lit; palmate


@pytest.mark.gl
@pytest.mark.parametrize("name, view", REFERENCE, ids=[f"{n}-{v}" for n, v in REFERENCE])
@pytest.mark.parametrize("veins", [True, False], ids=["veins", "no-veins"])
def test_reference_veins(gl, presets, request, name, view, veins):
    leaf = presets[name]
    assert leaf.venation.enabled, f"the {name} preset has a [venation] table"
    gl.veins = veins
    try:
        image = gl.render(leaf, (128, 128), view)
    finally:
        gl.veins = True
    assert_matches_reference(image, f"veins_{name}_{view}_{'on' if veins else 'off'}", request)
