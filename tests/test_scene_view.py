"""The scene viewer driven headless: a frame draws leaves, keys toggle culling and LOD, the panel
reports what the culling pass drew, and nothing leaks a GL error."""

from __future__ import annotations

import numpy as np
import pytest
from imgui_bundle import imgui

from leafview.scene.spec import SceneSpec, build_scene

pytestmark = pytest.mark.gl


@pytest.fixture
def view(gl, presets):
    from leafview.app.scene_view import SceneView

    scene = build_scene(SceneSpec(species=(presets["ovate"],), layout="plant", leaves=600, seed=1))
    v = SceneView(gl.ctx, scene)
    yield v
    v.release()
    assert gl.ctx.error == "GL_NO_ERROR"


def _key(k):
    io = imgui.get_io()
    io.add_key_event(k, True)


def _release(k):
    imgui.get_io().add_key_event(k, False)


def test_frames_draw_the_scene_and_keys_toggle(view):
    view.frame((900, 500))
    img = view.read_frame()
    assert img.shape == (500, 900, 4)
    assert view.counts.sum() > 0 and not view.gl_errors
    assert view.settings.cull and view.settings.lod
    for key, attr in ((imgui.Key.c, "cull"), (imgui.Key.l, "lod")):
        _key(key)
        view.frame((900, 500))
        _release(key)
        view.frame((900, 500))
        assert getattr(view.settings, attr) is False
    # LOD off: every drawn leaf at the finest grid
    assert view.counts[1:].sum() == 0 and view.counts[0] == len(view.scene)
    _key(imgui.Key.escape)
    view.frame((900, 500))
    assert view.files.quit_requested
    assert view.frame((0, 0)) is None  # minimised


# -- the canopy look, its light and wind -----------------------------------------------------------
SIZE = (700, 400)   # the scene takes SIZE[0] - PANEL_WIDTH pixels
PLAIN = {"shadows": False, "sky": False, "ground": False}   # background left: silhouettes by colour


@pytest.fixture
def canopy_view(gl, presets):
    from leafview.app.scene_view import SceneView
    from leafview.deform.wind import WindSettings
    from leafview.scene.lighting import LightSettings

    spec = SceneSpec(species=(presets["ovate"],), layout="plant", leaves=300, seed=3,
                     light=LightSettings(sun=(120.0, 40.0)), wind=WindSettings(speed=0.0, time=0.25))
    v = SceneView(gl.ctx, build_scene(spec))
    yield v
    v.release()
    assert gl.ctx.error == "GL_NO_ERROR"


def _frames(v, n=1, dt=0.1):
    for _ in range(n):
        assert v.frame(SIZE, SIZE, dt) is not None
    assert not v.gl_errors
    return v.read_frame()[:, :v._view[0], :3].astype(int)


def _silhouette(img):
    from leafview.app.scene_view import BACKGROUND

    bg = np.round(np.array(BACKGROUND[:3]) * 255)
    return np.abs(img - bg).max(axis=-1) > 3


def test_scene_view_draws_the_canopy_from_the_scene_file(canopy_view):
    v = canopy_view
    assert v.canopy is not None and v.light.sun == (120.0, 40.0) and v.wind.time == 0.25
    img = _frames(v)
    px = (v._view[0], v._view[1])
    camera = v.camera.camera(*px)
    ref = v.canopy.render(camera, px, v.settings, samples=0)[..., :3].astype(int)
    assert np.abs(img - ref).max() <= 2                                 # the canopy renderer's frame
    old = v.renderer.render(camera, px, v.settings, samples=0, background=(0.62, 0.72, 0.80, 1.0))
    assert np.abs(img - old[..., :3].astype(int)).max(axis=-1).mean() > 10   # not the old look
    # the panel's light: another sun changes the frame; back to the first gives it again
    v.light = v.light.replace(sun=(300.0, 15.0), exposure=1.0)
    lit = _frames(v)
    assert np.abs(lit - img).max(axis=-1).mean() > 5
    v.light = v.scene.spec.light
    assert np.abs(_frames(v) - img).max() <= 1


def test_wind_plays_live_and_pauses(canopy_view):
    v = canopy_view
    v.light = v.light.replace(**PLAIN)
    v.wind = v.wind.replace(speed=8.0)
    v.wind_playing = False
    still = _frames(v, 2)
    counts = v.counts.sum()
    paused = _frames(v, 3)
    assert v.wind.time == 0.25 and np.array_equal(paused, still)        # paused: nothing moves
    v.wind_playing = True
    moved = _frames(v, 4, dt=0.1)
    assert abs(v.wind.time - 0.65) < 1e-5                              # wall-clock time each frame
    a, b = _silhouette(still), _silhouette(moved)
    changed = (a ^ b).sum() / max(a.sum(), 1)
    assert 0.02 < changed < 0.6, changed                               # the silhouette moves
    assert v.counts.sum() == counts                                    # the same leaves drawn
    # speed 0: the still canopy again, bit for bit as a scene without wind
    v.wind = v.wind.replace(speed=0.0)
    t = v.wind.time
    calm = _frames(v, 2)
    assert v.wind.time == t                                            # a still wind does not advance
    px = (v._view[0], v._view[1])
    ref = v.canopy.render(v.camera.camera(*px), px, v.settings, samples=0, background=(0.62, 0.72, 0.80, 1.0))
    assert np.array_equal(calm, ref[..., :3].astype(int))


def test_picking_in_the_wind_picks_what_is_drawn(canopy_view):
    from leafview.gpu.picking import instance_image

    v = canopy_view
    v.light = v.light.replace(**PLAIN)
    v.wind = v.wind.replace(speed=12.0, time=0.7)
    v.wind_playing = False
    drawn = _silhouette(_frames(v, 2))
    px = (v._view[0], v._view[1])
    camera = v.camera.camera(*px)
    windy = instance_image(v._picking(), camera, px, v.settings)
    still = instance_image(v.renderer, camera, px, v.settings)
    assert (windy > 0).sum() > 1000
    # labelled leaf pixels lie on drawn pixels (stems are drawn, unlabelled)
    assert drawn[windy > 0].mean() > 0.99
    assert drawn[still > 0].mean() < 0.97                               # the still labels do not
    # a click where only the wind put a leaf selects that leaf
    js, is_ = np.nonzero((windy > 0) & (still == 0))
    assert js.size
    k = len(js) // 2
    v._click((is_[k] + 0.5, js[k] + 0.5), add=False)
    assert v.editor.selection.tolist() == [int(windy[js[k], is_[k]]) - 1]


def test_save_writes_the_panels_light_and_wind(canopy_view, tmp_path):
    from leafview.scene.spec import load_scene

    v = canopy_view
    v.light = v.light.replace(sun=(200.0, 30.0), shadows=False)
    v.wind = v.wind.replace(speed=5.0, direction=45.0, time=3.0)
    v.edit_panel.path = tmp_path / "look.toml"
    assert v.edit_panel.save(), v.edit_panel.message
    spec = load_scene(tmp_path / "look.toml")
    assert spec.light == v.light and spec.wind == v.wind.replace(time=0.25)


def test_light_and_wind_sections_draw_every_widget(canopy_view, monkeypatch):
    v = canopy_view
    shown = []

    def header(label, *args):
        shown.append(label.split("##")[0])
        return True                                                    # every section open

    monkeypatch.setattr(imgui, "collapsing_header", header)
    light, wind = v.light, v.wind
    _frames(v)
    assert {"Light", "Wind"} <= set(shown) and v.look_error is None
    assert v.light == light and v.wind == wind                         # drawn, untouched
