"""The scene viewer driven headless: a frame draws leaves, keys toggle culling and LOD, the panel
reports what the culling pass drew, and nothing leaks a GL error."""

from __future__ import annotations

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
