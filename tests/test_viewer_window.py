"""The viewer in a real glfw window on its own Xvfb display, end to end, each run in a subprocess
(glfw reads DISPLAY when it starts): ``leafview view --frames N --screenshot F`` and a scripted
session with edits, undo/redo, keys, resizing and the close button. Without Xvfb these skip, unless
LEAFVIEW_REQUIRE_GL is set (CI), where they fail."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from support.display import DisplayUnavailable, display_env, xvfb

from leafview.core.params import LeafParams
from leafview.export.images import PARAMS_ATTRIBUTE, read_image
from leafview.fit.synthetic_photos import synthetic_photo, write_photo
from leafview.resources import builtin_presets
from tests.conftest import require_or_skip

pytestmark = pytest.mark.gl  # the window tests also need Xvfb (started here)
ROOT = Path(__file__).resolve().parent.parent


def _unavailable(reason: str) -> None:
    require_or_skip(reason)


@pytest.fixture(scope="module")
def display(tmp_path_factory):
    """A private Xvfb server (tests/support/display.py)."""
    try:
        with xvfb(tmp_path_factory.mktemp("xvfb") / "xvfb.log") as number:
            yield number
    except DisplayUnavailable as exc:
        _unavailable(str(exc))


def _env(display: str) -> dict[str, str]:
    return display_env(display)


def _run(args: list[str], display: str, cwd: Path, timeout: int = 120) -> subprocess.CompletedProcess:
    return subprocess.run(args, cwd=cwd, env=_env(display), capture_output=True, text=True, timeout=timeout)


def _session(script: str, display: str, cwd: Path) -> dict:
    """Run a scripted window session in a new Python process; its last stdout line is JSON."""
    result = _run([sys.executable, "-c", script], display, cwd)
    assert result.returncode == 0, result.stderr[-3000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


def test_scripted_run_writes_the_whole_window(gl, display, tmp_path):
    exe = shutil.which("leafview") or pytest.fail("the leafview console script is not installed")
    out = tmp_path / "window.png"
    result = _run([exe, "view", "asymmetric", "--frames", "8", "--screenshot", str(out), "--size", "1024x640"],
                  display, tmp_path)
    assert result.returncode == 0, result.stderr
    assert f"wrote {out}" in result.stdout and "Traceback" not in result.stderr
    assert "OpenGL error" not in result.stderr  # checked after every frame
    pixels, meta = read_image(out)
    assert pixels.shape == (640, 1024, 4) and pixels.dtype == np.uint8
    preset = LeafParams.load(builtin_presets()["asymmetric"])
    assert LeafParams.from_dict(json.loads(meta[PARAMS_ATTRIBUTE])) == preset
    rgb = pixels[..., :3].astype(int)
    scene, panel = rgb[:, :1024 - 400], rgb[:, 1024 - 400 + 4:]
    green = (scene[..., 1] > scene[..., 0] + 25) & (scene[..., 1] > scene[..., 2] + 25)
    assert green.mean() > 0.05  # the leaf
    ys, xs = np.nonzero(green)
    assert 150 < xs.mean() < 470 and 170 < ys.mean() < 470  # framed in the middle of the viewport
    assert (panel.max(axis=-1) > 200).sum() > 3000  # the panel's text and widgets
    title_bar = rgb[2:14, 1024 - 390:1024 - 10]
    assert (title_bar[..., 2] > title_bar[..., 0] + 20).mean() > 0.5  # imgui's blue title bar
    status = rgb[-30:, :300]
    assert (status.max(axis=-1) > 200).sum() > 100  # "… fps  4,096 triangles  llvmpipe …"


def test_bad_input_exits_2_before_any_window(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("schema = 1\n[shape]\na1 = [0, 0.3, 0]\n")
    exe = shutil.which("leafview") or pytest.fail("the leafview console script is not installed")
    (tmp_path / "cut.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 40)
    for args, words in (([str(bad)], "shape.a2"), (["nope"], "no such file"),
                        (["--photo", "cut.png"], "cut.png"), (["cut.png"], "cut.png"),
                        (["ovate", "--screenshot", "x.jpg"], ".png or .tif"),
                        (["ovate", "--frames", "0"], "at least 1")):
        result = subprocess.run([exe, "view", *args], cwd=tmp_path, capture_output=True, text=True, timeout=60,
                                env={k: v for k, v in os.environ.items() if k != "DISPLAY"})
        assert result.returncode == 2, (args, result.stderr)
        assert words in result.stderr and "Traceback" not in result.stderr
    assert [p.name for p in tmp_path.glob("*.png")] == ["cut.png"] and not list(tmp_path.glob("*.jpg"))


def test_a_photo_opens_behind_the_leaf(gl, display, tmp_path):
    """``leafview view PHOTO``: the default leaf over the photo, placed by the photo's base and apex."""
    exe = shutil.which("leafview") or pytest.fail("the leafview console script is not installed")
    photo = write_photo(synthetic_photo(3, size=(480, 360), background="pink"), tmp_path / "leaf.png")
    out = tmp_path / "window.png"
    result = _run([exe, "view", str(photo), "--frames", "6", "--screenshot", str(out), "--size", "1024x640"],
                  display, tmp_path)
    assert result.returncode == 0, result.stderr
    rgb = read_image(out)[0][..., :3].astype(int)[:, :1024 - 400]
    # the photo's pink paper behind the leaf, at the default opacity over the dark background
    pink = (rgb[..., 0] > rgb[..., 1] + 10) & (rgb[..., 2] > rgb[..., 1] + 5) & (rgb.sum(axis=-1) > 300)
    green = (rgb[..., 1] > rgb[..., 0] + 25) & (rgb[..., 1] > rgb[..., 2] + 25)
    assert pink.mean() > 0.2 and green.mean() > 0.05


def test_no_display_is_a_message_not_a_traceback(tmp_path):
    exe = shutil.which("leafview") or pytest.fail("the leafview console script is not installed")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    result = subprocess.run([exe, "view", "ovate", "--frames", "2", "--screenshot", "x.png"], cwd=tmp_path,
                            env=env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert "xvfb-run" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "x.png").exists()


SESSION = textwrap.dedent('''
    import json, sys
    import glfw, numpy as np
    from imgui_bundle import imgui
    from leafview.app.viewer import open_state
    from leafview.app.window import ViewerWindow
    from leafview.core.params import LeafParams
    from leafview.resources import builtin_presets

    out = {"errors": []}
    path = builtin_presets()["ovate"]
    state = open_state(LeafParams.load(path), path)
    win = ViewerWindow(state, (900, 560))
    v = win.viewer

    def step(n=1):
        for _ in range(n):
            alive = win.step()
            err = win.ctx.error
            if err != "GL_NO_ERROR":
                out["errors"].append((v.frame_index, err))
        return alive

    def view():
        img = v.read_frame()
        return img[:-60, :int(v.layout(img.shape[1])[0])]

    def green(img):
        r, g, b = (img[..., i].astype(int) for i in range(3))
        return int(((g > r + 25) & (g > b + 25)).sum())

    step(4)
    out["renderer"] = v.gl_renderer
    out["window_fb"] = list(glfw.get_framebuffer_size(win.window))
    before = view()
    rows = [[a, x * 1.4, z] for a, x, z in state.params.shape.silhouette]
    state.set_field("shape.silhouette", rows)
    step()
    out["upload_bytes"] = v.last_upload_bytes
    wide = view()
    out["green"] = [green(before), green(wide)]
    state.undo(); step()
    out["undo_identical"] = bool(np.array_equal(view(), before))
    state.redo(); step()
    out["redo_identical"] = bool(np.array_equal(view(), wide))
    io = imgui.get_io()
    io.add_key_event(imgui.Key.w, True); step(); io.add_key_event(imgui.Key.w, False); step()
    out["wireframe"] = [state.view.wireframe, green(view())]
    for size in ((320, 200), (64, 64), (1, 1), (1000, 620)):
        glfw.set_window_size(win.window, *size)
        step(3)
    out["resized_fb"] = list(v._target_key)
    out["minimised_frame"] = v.frame((0, 0), (0, 0)) is None
    # the close button with unsaved edits asks; Discard (clicked in the modal) closes
    win._on_close(win.window)
    alive = step(3)
    out["asking"] = [alive, v.files.asking, bool(glfw.window_should_close(win.window))]
    x0, y0, x1, y1 = v.files.rects["Discard##confirm"]
    io.add_mouse_pos_event((x0 + x1) / 2, (y0 + y1) / 2); step()
    io.add_mouse_button_event(0, True); step()
    io.add_mouse_button_event(0, False)
    out["closed"] = not step()
    out["gl_errors"] = v.gl_errors
    win.close()
    print(json.dumps(out))
''')


def test_window_session_edits_undo_resize_and_close(gl, display, tmp_path):
    out = _session(SESSION, display, tmp_path)
    assert out["errors"] == [] and out["gl_errors"] == []  # ctx.error after every frame
    assert out["window_fb"] == [900, 560]
    assert 0 < out["upload_bytes"] < 1024
    assert out["green"][1] > 1.15 * out["green"][0] > 0
    assert out["undo_identical"] and out["redo_identical"]
    assert out["wireframe"][0] and out["wireframe"][1] < 0.7 * out["green"][1]
    assert out["resized_fb"] == [1000, 620] and out["minimised_frame"]
    assert out["asking"] == [True, True, False]  # still open, asking, not closed behind its back
    assert out["closed"]
    assert not list(tmp_path.iterdir())  # nothing written: no imgui.ini, no stray files


def test_scene_window_scripted_run(gl, display, tmp_path):
    """``leafview scene --view`` hosts the scene viewer in the same window class."""
    out = tmp_path / "scene_window.png"
    exe = shutil.which("leafview") or sys.executable
    result = _run([exe, "scene", "--leaves", "800", "--layout", "plant", "--view", "--frames", "4",
                   "--screenshot", str(out), "--size", "800x500"], display, tmp_path)
    assert result.returncode == 0, result.stderr
    assert "4 frames" in result.stdout
    image, _ = read_image(out)
    assert image.shape == (500, 800, 4)
    scene_part = image[:, :500, :3].astype(int)
    # leaves (green dominant) cover part of the viewport, the sky the rest
    green = (scene_part[..., 1] > scene_part[..., 0] + 10) & (scene_part[..., 1] > scene_part[..., 2] + 10)
    assert 0.02 < green.mean() < 0.9


WIND_SESSION = textwrap.dedent('''
    import json
    from leafview.app.scene_view import SceneView
    from leafview.app.viewer import open_state
    from leafview.app.window import ViewerWindow
    from leafview.core.params import LeafParams
    from leafview.deform.wind import WindSettings
    from leafview.resources import builtin_presets
    from leafview.scene.spec import SceneSpec, build_scene

    out = {}
    path = builtin_presets()["ovate"]
    # the scene viewer: the scene file's wind plays with the wall clock
    spec = SceneSpec(species=(LeafParams.load(path),), layout="plant", leaves=200, seed=2,
                     wind=WindSettings(speed=8.0))
    win = ViewerWindow(None, (640, 400), make_view=lambda ctx: SceneView(ctx, build_scene(spec)))
    v = win.viewer
    win.step(); win.step(); first = v.read_frame()[:, :300]
    t0, w0 = win._last_time, v.wind.time     # the clock reading of the frame just drawn
    for _ in range(6):
        win.step()
    out["scene"] = [v.wind.time - w0, win._last_time - t0,
                    float((v.read_frame()[:, :300] != first).any(axis=-1).mean()), v.gl_errors]
    win.close()
    # the single-leaf viewer: the panel's wind speed moves the leaf live
    state = open_state(LeafParams.load(path), path)
    win = ViewerWindow(state, (640, 400))
    v = win.viewer
    win.step(); still = v.read_frame()[:-60, :240]
    state.view.wind = state.view.wind.replace(speed=8.0)
    t0 = win._last_time
    for _ in range(6):
        win.step()
    out["leaf"] = [state.view.wind.time, win._last_time - t0,
                   float((v.read_frame()[:-60, :240] != still).any(axis=-1).mean()), v.gl_errors]
    win.close()
    print(json.dumps(out))
''')


def test_wind_plays_with_the_wall_clock_in_a_window(gl, display, tmp_path):
    out = _session(WIND_SESSION, display, tmp_path)
    for name in ("scene", "leaf"):
        advanced, elapsed, moved, errors = out[name]
        # the wind's time is the wall clock's between the frames (each frame's interval, capped at 1 s)
        assert 0.0 < advanced <= elapsed + 1e-4, (name, advanced, elapsed)
        if elapsed < 1.0:   # no interval can have been capped
            assert abs(advanced - elapsed) < 1e-4, (name, advanced, elapsed)
        assert moved > 0.005 and errors == [], (name, moved)
