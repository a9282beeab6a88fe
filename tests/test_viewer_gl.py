"""The viewer's frames on the headless EGL context, no window: what is drawn, what an edit uploads,
keys and drags injected as imgui events, screenshots, 0×0 frames and shader hot reload. GL_NO_ERROR
after every frame."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from imgui_bundle import imgui  # a hard dependency: missing means broken, not skipped

from leafview.app.hotreload import ShaderWatcher  # noqa: E402
from leafview.app.lobe_handles import drag_lobe_handle, handle_flat
from leafview.app.lobe_panel import with_branch_knots
from leafview.app.orbit import project  # noqa: E402
from leafview.app.viewer import BACKGROUND, Viewer, open_state  # noqa: E402
from leafview.botany.lobes import builtin_lobed
from leafview.core.params import LeafParams  # noqa: E402
from leafview.export.images import PARAMS_ATTRIBUTE, read_image  # noqa: E402
from leafview.gpu.layout import LEAF_BLOCK  # noqa: E402
from leafview.resources import builtin_presets, shader_dir  # noqa: E402

pytestmark = pytest.mark.gl
SIZE = (960, 600)


@pytest.fixture
def viewer(gl, tmp_path):
    path = builtin_presets()["ovate"]
    v = Viewer(gl.ctx, open_state(LeafParams.load(path), path), samples=0, screenshot_dir=tmp_path)
    yield v
    v.release()


def frame(v: Viewer, size=SIZE, n: int = 1) -> np.ndarray:
    for _ in range(n):
        assert v.frame(size, size, 1 / 60) is not None
        err = v.ctx.error
        assert err == "GL_NO_ERROR", f"frame {v.frame_index}: {err}"
    return v.read_frame()


def scene(img: np.ndarray, v: Viewer) -> np.ndarray:
    """The viewport without the status line (its fps text is the only thing that varies)."""
    w = int(v.layout(img.shape[1])[0])
    return img[:-60, :w]


def leaf_pixels(img: np.ndarray) -> int:
    r, g, b = (img[..., i].astype(int) for i in range(3))
    return int(((g > r + 25) & (g > b + 25)).sum())


def press(v: Viewer, key, *, ctrl=False, shift=False) -> np.ndarray:
    io = imgui.get_io()
    for mod, on in ((imgui.Key.mod_ctrl, ctrl), (imgui.Key.mod_shift, shift)):
        io.add_key_event(mod, on)
    io.add_key_event(key, True)
    frame(v)
    io.add_key_event(key, False)
    io.add_key_event(imgui.Key.mod_ctrl, False)
    io.add_key_event(imgui.Key.mod_shift, False)
    return frame(v)


def test_frame_shows_leaf_overlays_and_panel(viewer):
    img = frame(viewer, n=6)
    assert img.shape == (SIZE[1], SIZE[0], 4)
    view = scene(img, viewer)
    assert leaf_pixels(view) > 0.05 * view.shape[0] * view.shape[1]
    bg = np.round(np.array(BACKGROUND[:3]) * 255)
    assert (np.abs(view[5:40, 5:40, :3].astype(int) - bg).max(axis=-1) <= 2).mean() > 0.5
    yellow = (view[..., 0] > 180) & (view[..., 1] > 150) & (view[..., 2] < 110)  # silhouette S
    assert yellow.sum() > 200
    panel = img[:, int(viewer.layout(SIZE[0])[0]) + 5:]
    assert (panel[..., :3].max(axis=-1) > 200).sum() > 2000  # text and widgets
    assert leaf_pixels(panel) < 0.01 * panel.shape[0] * panel.shape[1]


def test_multisampled_scene_resolves_with_smooth_edges(gl):
    path = builtin_presets()["ovate"]
    images = {}
    for samples in (0, 4):
        v = Viewer(gl.ctx, open_state(LeafParams.load(path), path), samples=samples)
        try:
            assert v.samples == min(samples, gl.ctx.max_samples)
            v.state.view.show_controls = v.state.view.show_ground = False
            images[samples] = scene(frame(v, (480, 320), n=2), v)[..., 1].astype(int)
        finally:
            v.release()
    if gl.ctx.max_samples < 4:
        from tests.conftest import require_or_skip

        require_or_skip("no 4× multisampling on this renderer")
    g0, g4 = images[0], images[4]
    bg = round(BACKGROUND[1] * 255)
    leaf = g0 > bg + 20
    inner = leaf.copy()
    for axis in (0, 1):
        for shift in (1, -1):
            inner &= np.roll(leaf, shift, axis=axis)
    edge = leaf & ~inner  # the outline without multisampling: pure leaf pixels
    partial = edge & (g4 > bg + 3) & (g4 < g0 - 3)  # the same pixels partly covered with 4×
    assert edge.sum() > 300 and partial.sum() > 0.2 * edge.sum()
    assert np.abs(g4 - g0)[inner].mean() < 1.0  # the inside is the same picture


def test_edit_uploads_only_the_block_and_shows_in_the_next_frame(viewer):
    before = scene(frame(viewer, n=3), viewer)
    assert viewer.last_upload_bytes == 0  # steady frames upload nothing
    rows = [[v, x * 1.4, z] for v, x, z in viewer.state.params.shape.silhouette]
    assert viewer.state.set_field("shape.silhouette", rows)
    wide = scene(frame(viewer), viewer)
    assert 0 < viewer.last_upload_bytes == LEAF_BLOCK.nbytes < 1024
    assert leaf_pixels(wide) > leaf_pixels(before) * 1.15
    frame(viewer)
    assert viewer.last_upload_bytes == 0
    assert viewer.state.undo()
    np.testing.assert_array_equal(scene(frame(viewer), viewer), before)
    assert viewer.state.redo()
    np.testing.assert_array_equal(scene(frame(viewer), viewer), wide)


def test_a_drag_keeps_the_veins_until_it_ends(viewer):
    """While a slider is dragged (a gesture) the vein tree, field and grid are not rebuilt per
    frame (15-35 ms each on llvmpipe): the frame uses the veins of the drag's start, and the first
    frame after the drag ends rebuilds them for the leaf as it now is."""
    from leafview.botany.vein_field import vein_key

    frame(viewer, n=2)
    veins = viewer.renderer.leaf_veins.fields
    start = vein_key(viewer.state.params)
    assert veins is not None and start in veins.keys
    for k in (1.1, 1.2):
        rows = [[v, x * k, z] for v, x, z in viewer.state.params.shape.silhouette]
        assert viewer.state.set_field("shape.silhouette", rows, gesture=True)
        frame(viewer)
        assert viewer.renderer.veins_pending == viewer.state.params      # veins a drag behind
        assert veins.keys.count(start) == 1 and vein_key(viewer.state.params) not in veins.keys
    viewer.state.end_gesture()
    frame(viewer)
    assert viewer.renderer.veins_pending is None
    assert vein_key(viewer.state.params) in viewer.renderer.leaf_veins.fields.keys
    rows = [[v, x * 0.9, z] for v, x, z in viewer.state.params.shape.silhouette]
    assert viewer.state.set_field("shape.silhouette", rows)                  # a click, not a drag: at once
    frame(viewer)
    assert viewer.renderer.veins_pending is None
    assert vein_key(viewer.state.params) in viewer.renderer.leaf_veins.fields.keys


def test_zero_and_tiny_sizes_do_not_crash(viewer):
    frame(viewer)
    for size in ((0, 0), (0, 600), (800, 0)):
        assert viewer.frame(size) is None
        assert viewer.ctx.error == "GL_NO_ERROR"
    for size in ((1, 1), (2, 700), (1500, 3), (64, 64)):
        img = frame(viewer, size)
        assert img.shape[:2] == (size[1], size[0])
    assert frame(viewer).shape[:2] == (SIZE[1], SIZE[0])


def test_dragging_a_handle_moves_the_outline_as_one_undo_step(viewer):
    frame(viewer, n=2)
    sw = int(round(viewer.layout(SIZE[0])[0]))
    names = viewer.overlay.handle_names
    screen = project(viewer.camera.camera(sw, SIZE[1]), viewer.overlay.handle_world, sw, SIZE[1])
    x, y = screen[names.index("s2-")]
    io = imgui.get_io()
    io.add_mouse_pos_event(x, y)
    frame(viewer)
    assert viewer.input.hot == "s2-"
    before = viewer.state.params.shape.silhouette[1]
    az = viewer.camera.azimuth
    io.add_mouse_button_event(0, True)
    frame(viewer)
    for k in range(1, 5):
        io.add_mouse_pos_event(x + 10 * k, y - 4 * k)
        frame(viewer)
    io.add_mouse_button_event(0, False)
    frame(viewer)
    after = viewer.state.params.shape.silhouette[1]
    assert after != before and viewer.camera.azimuth == az  # the handle moved, not the camera
    new_screen = project(viewer.camera.camera(sw, SIZE[1]), viewer.overlay.handle_world, sw, SIZE[1])
    np.testing.assert_allclose(new_screen[names.index("s2-")], (x + 40, y - 16), atol=1.5)
    assert viewer.state.undo() and viewer.state.params.shape.silhouette[1] == before
    assert not viewer.state.can_undo
    # a drag that starts away from the handles orbits the camera
    io.add_mouse_pos_event(20, 20)
    frame(viewer)
    io.add_mouse_button_event(0, True)
    frame(viewer)
    io.add_mouse_pos_event(120, 30)
    frame(viewer)
    io.add_mouse_button_event(0, False)
    frame(viewer)
    assert viewer.camera.azimuth != az and viewer.state.params.shape.silhouette[1] == before


def test_keys(viewer, tmp_path):
    base = scene(frame(viewer, n=2), viewer)
    wire = scene(press(viewer, imgui.Key.w), viewer)
    assert viewer.state.view.wireframe and leaf_pixels(wire) < 0.7 * leaf_pixels(base)
    press(viewer, imgui.Key.w)
    bare = scene(press(viewer, imgui.Key.c), viewer)
    assert not viewer.state.view.show_controls and not np.array_equal(bare, base)
    press(viewer, imgui.Key.g)
    assert not viewer.state.view.show_ground
    helped = press(viewer, imgui.Key.h)
    assert viewer.state.view.show_help
    assert (scene(helped, viewer)[..., :3].min(axis=-1) > 200).sum() > 500  # the key table's text
    press(viewer, imgui.Key.f1)
    assert not viewer.state.view.show_help
    # undo/redo from the keyboard
    viewer.state.set_field("jitter.enabled", True)
    press(viewer, imgui.Key.z, ctrl=True)
    assert not viewer.state.params.jitter.enabled
    press(viewer, imgui.Key.z, ctrl=True, shift=True)
    assert viewer.state.params.jitter.enabled
    # R after an orbit returns to the home view
    viewer.camera.orbit(200, -50)
    uploads = viewer.renderer.uploads
    press(viewer, imgui.Key.r)
    assert (viewer.camera.azimuth, viewer.camera.elevation) == (35.0, 50.0)
    press(viewer, imgui.Key.f)
    assert viewer.renderer.uploads == uploads  # view changes upload nothing
    # P: the viewport (no panel) from the offscreen framebuffer, with the leaf's parameters
    press(viewer, imgui.Key.p)
    shot = viewer.last_screenshot
    assert shot is not None and shot.parent == tmp_path and shot.suffix == ".png"
    pixels, meta = read_image(shot)
    assert pixels.shape[:2] == (SIZE[1], int(round(viewer.layout(SIZE[0])[0])))
    assert LeafParams.from_dict(__import__("json").loads(meta[PARAMS_ATTRIBUTE])) == viewer.state.params
    # Esc with unsaved edits asks instead of quitting
    press(viewer, imgui.Key.escape)
    assert viewer.files.asking and not viewer.files.quit_requested


def test_hot_reload_keeps_the_old_program_on_error(gl, tmp_path, monkeypatch):
    import leafview.gpu.shaders as shaders

    src = tmp_path / "shaders"
    shutil.copytree(shader_dir(), src)
    monkeypatch.setattr(shaders, "shader_dir", lambda: src)
    path = builtin_presets()["ovate"]
    v = Viewer(gl.ctx, open_state(LeafParams.load(path), path), dev=True, samples=0)
    try:
        v.watcher = ShaderWatcher(src, interval=0.0)
        v.state.view.show_controls = False
        good = scene(frame(v, n=2), v)
        frag = src / "leaf.frag"
        text = frag.read_text()
        lines = text.splitlines()
        # the drawing program's main (the last one: the label pass's main comes first, under LEAF_AOV)
        broken_line = max(i for i, line in enumerate(lines) if line.startswith("void main")) + 2
        lines.insert(broken_line - 1, "    this is not GLSL;")
        frag.write_text("\n".join(lines) + "\n")
        still = scene(frame(v), v)
        assert v.shader_error and f"leaf.frag:{broken_line}" in v.shader_error
        assert "fragment" in v.shader_error
        assert leaf_pixels(still[:, 300:]) == leaf_pixels(good[:, 300:])  # the old shader still draws
        frag.write_text(text.replace("void main() {", "void main_before_reload() {")
                        + "\nvoid main() { main_before_reload(); frag_color = vec4(1.0, 0.0, 0.0, 1.0); }\n")
        red = scene(frame(v), v)
        assert v.shader_error is None
        assert ((red[..., 0] == 255) & (red[..., 1] == 0)).sum() > 0.8 * leaf_pixels(good)
    finally:
        v.release()


def test_an_exception_in_the_ui_is_reported_not_fatal(viewer, capsys):
    frame(viewer)
    original = viewer.panel.draw_field

    def broken(path, spec):
        if path == "jitter.seed":
            raise ZeroDivisionError("a bug in a widget")
        return original(path, spec)

    viewer.panel.draw_field = broken
    frame(viewer, n=2)
    assert viewer.internal_errors == 2 and "ZeroDivisionError" in viewer.state.error
    viewer.panel.draw_field = original
    frame(viewer, n=2)
    assert viewer.internal_errors == 2
    assert "a bug in a widget" in capsys.readouterr().err


def test_edit_latency_measure_runs(gl):
    from leafview.bench.latency import measure_edit_latency

    res = measure_edit_latency(gl.ctx, pairs=2, warmup=1, size=(640, 400))
    assert res["edit_latency_ratio"] > 0 and res["viewer_frame_ms"] > 0
    assert res["viewer_edit_upload_bytes"] == LEAF_BLOCK.nbytes


# -- a lobed leaf (leafview.app.lobe_handles, leafview.app.lobe_panel) -----------------------------
@pytest.fixture
def maple_viewer(gl, tmp_path):
    path = builtin_presets()["maple"]
    v = Viewer(gl.ctx, open_state(LeafParams.load(path), path), samples=0, screenshot_dir=tmp_path)
    yield v
    v.release()


def _leaf_mask(img: np.ndarray, v: Viewer) -> np.ndarray:
    """Pixels of the viewport (status line included) that differ from the background and the
    ground grid: greenish leaf pixels."""
    view = img[:, : int(v.layout(img.shape[1])[0])]
    r, g, b = (view[..., i].astype(int) for i in range(3))
    return (g > r + 15) & (g > b + 25)


def test_maple_is_framed_with_its_lobe_handles(maple_viewer):
    v = maple_viewer
    img = frame(v, n=3)
    mask = _leaf_mask(img, v)
    assert mask.sum() > 0.04 * mask.size
    assert not (mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any()), "leaf cut by a border"
    rows, cols = np.nonzero(mask)
    assert rows.max() - rows.min() > 0.4 * mask.shape[0]       # framed to fill the view, not a speck
    names = v.overlay.handle_names
    assert v.overlay.lobed and sum(n.startswith("tip:") for n in names) == 5
    assert sum(n.startswith("valley:") for n in names) == 4 and len(v.overlay.fixed_world) >= 2
    # the panel hides the Ω-only groups and shows the curve editors
    assert "shape.a1" not in v.panel.rects and "lobes.branches[0].bend" in v.panel.rects
    assert v.gl_errors == [] and v.internal_errors == 0


def test_maple_tip_drag_through_the_viewport_changes_the_render(maple_viewer):
    v = maple_viewer
    base = frame(v, n=2)
    sw = int(round(v.layout(SIZE[0])[0]))
    names = v.overlay.handle_names
    screen = project(v.camera.camera(sw, SIZE[1]), v.overlay.handle_world, sw, SIZE[1])
    x, y = screen[names.index("tip:2")]
    io = imgui.get_io()
    io.add_mouse_pos_event(x, y)
    frame(v)
    assert v.input.hot == "tip:2"
    before, az = v.state.params, v.camera.azimuth
    io.add_mouse_button_event(0, True)
    frame(v)
    for k in range(1, 4):
        io.add_mouse_pos_event(x + 8 * k, y + 5 * k)
        frame(v)
    io.add_mouse_button_event(0, False)
    after = frame(v, n=2)
    assert v.state.params.lobes.outline != before.lobes.outline and v.camera.azimuth == az
    assert v.state.params.lobes.valleys == before.lobes.valleys
    moved = np.any(np.abs(after[:-60, :sw].astype(int) - base[:-60, :sw].astype(int)) > 30, axis=-1)
    assert moved.sum() > 100
    screen = project(v.camera.camera(sw, SIZE[1]), v.overlay.handle_world, sw, SIZE[1])
    assert np.hypot(*(screen[names.index("tip:2")] - (x + 24, y + 15))) < 8   # the handle followed
    assert v.state.undo() and v.state.params == before and not v.state.can_undo


def test_lobe_handle_drag_through_the_state_changes_the_render_and_refusal_keeps_it(maple_viewer):
    v = maple_viewer
    base = frame(v, n=2)
    p = v.state.params
    target = handle_flat(p.lobes, "valley:1") + np.array([0.05, -0.1])
    assert v.state.apply(lambda q: drag_lobe_handle(q, "valley:1", target))
    edited = frame(v)
    sw = int(v.layout(SIZE[0])[0])
    assert (np.abs(edited[:-60, :sw].astype(int) - base[:-60, :sw].astype(int)).max(axis=-1) > 30).sum() > 50
    revision = v.state.revision
    crossing = handle_flat(v.state.params.lobes, "tip:4") + np.array([-0.6, 0.2])
    assert not v.state.apply(lambda q: drag_lobe_handle(q, "tip:4", crossing))
    assert v.state.revision == revision and "crosses itself" in v.state.error
    again = frame(v)
    assert np.array_equal(again[:-60, :sw], edited[:-60, :sw])
    # a turtle edit (the curve editor's model function) reaches the render too
    assert v.state.apply(lambda q: with_branch_knots(q, 0, "bend", [0.0, 60.0, 60.0, 0.0]))
    bent = frame(v)
    assert (np.abs(bent[:-60, :sw].astype(int) - again[:-60, :sw].astype(int)).max(axis=-1) > 30).sum() > 50


def test_opening_a_compound_file_shows_it_as_one_lobed_leaf(maple_viewer):
    v = maple_viewer
    frame(v)
    assert v.state.open(builtin_lobed()["bilobed"])
    assert v.state.params.lobes.enabled and v.state.path is None and not v.state.can_save
    img = frame(v, n=2)
    mask = _leaf_mask(img, v)
    assert mask.sum() > 0.02 * mask.size and not (mask[0].any() or mask[-1].any() or mask[:, 0].any())
    assert sum(n.startswith("tip:") for n in v.overlay.handle_names) == 2


def test_wind_moves_the_leaf_live_and_speed_0_is_the_still_frame(viewer):
    from leafview.gpu.wind import WindUniforms

    view = viewer.state.view
    assert view.wind.speed == 0.0 and view.wind_playing
    still = scene(frame(viewer, n=2), viewer)
    assert view.wind.time == 0.0                                       # a still wind does not advance
    view.wind = view.wind.replace(speed=8.0)
    first = scene(frame(viewer), viewer)
    t = view.wind.time
    assert abs(t - 1 / 60) < 1e-6                                      # the frame's interval
    assert isinstance(viewer.wind_uniforms, WindUniforms) and viewer.wind_uniforms.wind == view.wind
    uploads = viewer.renderer.uploads
    later = scene(frame(viewer, n=20), viewer)                         # a third of a second later
    assert viewer.renderer.uploads == uploads                          # playing uploads no leaf
    for img in (first, later):
        assert (np.abs(img.astype(int) - still).max(axis=-1) > 8).mean() > 0.01   # the leaf moved
    assert (np.abs(later.astype(int) - first).max(axis=-1) > 8).mean() > 0.002   # and keeps moving
    # paused: the same frame again
    view.wind_playing = False
    paused = scene(frame(viewer), viewer)
    t = view.wind.time
    assert np.array_equal(scene(frame(viewer, n=2), viewer), paused) and view.wind.time == t
    # speed 0: the still frame, bit for bit
    view.wind = view.wind.replace(speed=0.0)
    assert np.array_equal(scene(frame(viewer), viewer), still)
    assert not viewer.gl_errors
