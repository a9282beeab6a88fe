"""leafview in Jupyter, headless: the LeafWidget canvas (jupyter_rfb) and its sliders (ipywidgets)
driven without a kernel frontend, and the PNG thumbnails behind ``_repr_png_``."""

from __future__ import annotations

import json
import subprocess
import sys

import jupyter_rfb  # the [notebook] extra, part of [test]: a missing package fails, never skips
import numpy as np
import pytest

from leafview.core import display
from leafview.core.display import PNG_SIGNATURE, png_of, register_png_renderer
from leafview.core.params import LeafParams, ParamError, field_specs
from leafview.errors import GLUnavailable
from leafview.export.images import ImageWriteError, png_bytes, read_image
from leafview.notebook import KNOBS, Knob, LeafWidget
from leafview.resources import resolve_preset
from leafview.scene.spec import SceneSpec, build_scene

SIZE = (160, 120)
DRAG = [{"type": "pointer_down", "x": 80, "y": 60, "button": 1, "buttons": (1,), "modifiers": ()},
        {"type": "pointer_move", "x": 150, "y": 20, "button": 1, "buttons": (1,), "modifiers": ()},
        {"type": "pointer_up", "x": 150, "y": 20, "button": 1, "buttons": (), "modifiers": ()}]


@pytest.fixture(scope="module")
def serrate() -> LeafParams:
    return LeafParams.load(resolve_preset("serrate"))


@pytest.fixture(scope="module")
def small_scene():
    return build_scene(SceneSpec(species=(LeafParams.load(resolve_preset("ovate")),), layout="plant",
                                 leaves=80, seed=1))


def _changed(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of pixels that differ by more than 8/255 in some channel."""
    return float(np.mean(np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=-1) > 8))


def _not_background(frame: np.ndarray, background: tuple[float, ...]) -> float:
    bg = np.round(np.asarray(background[:3]) * 255)
    return float(np.mean(np.abs(frame[..., :3].astype(np.float64) - bg).max(axis=-1) > 12))


def _decode(png: bytes, tmp_path) -> np.ndarray:
    path = tmp_path / "decoded.png"
    path.write_bytes(png)
    pixels, _ = read_image(path)
    return np.asarray(pixels)


# -- the widget ---------------------------------------------------------------------------------
def test_widget_frame_has_the_size_and_shows_the_leaf(gl, serrate) -> None:
    w = LeafWidget(serrate, size=SIZE)
    assert isinstance(w, jupyter_rfb.RemoteFrameBuffer)
    assert (w.css_width, w.css_height) == ("160px", "120px")
    w.request_draw()   # no event loop, no frontend: scheduling is a no-op, never an error
    frame = w.get_frame()
    assert frame.shape in ((120, 160, 3), (120, 160, 4)) and frame.dtype == np.uint8
    assert 0.1 < _not_background(frame, w.background) < 0.9   # a leaf, framed, on the background
    assert w.params == serrate
    snap = w.snapshot()
    assert np.array_equal(snap.data, frame)
    assert w.ui.children[0] is w and len(w.sliders) == len(KNOBS)


def test_a_lobed_leaf_is_framed_whole(gl) -> None:
    """Framing uses the drawn (swept) surface of a lobed leaf, not the default Ω."""
    w = LeafWidget(LeafParams.load(resolve_preset("maple")), size=SIZE)
    frame = w.get_frame()
    bg = np.round(np.asarray(w.background[:3]) * 255)
    leaf = np.abs(frame[..., :3].astype(np.float64) - bg).max(axis=-1) > 12
    assert 0.1 < leaf.mean() < 0.9
    assert not (leaf[0].any() or leaf[-1].any() or leaf[:, 0].any() or leaf[:, -1].any()), "a lobe cut off"
    rows, cols = np.nonzero(leaf)
    assert np.ptp(rows) > 0.5 * SIZE[1] or np.ptp(cols) > 0.5 * SIZE[0]   # filling the view


def test_sliders_take_their_ranges_from_the_field_specs(gl, serrate) -> None:
    w = LeafWidget(serrate, size=SIZE)
    specs = field_specs()
    for knob in KNOBS:
        slider = w.sliders[knob.key]
        lo, hi = specs[knob.spec].soft_range
        assert slider.step == specs[knob.spec].step
        assert slider.max == max(hi, knob.get(serrate))
        assert slider.min == min(max(lo, slider.step) if knob.positive else lo, knob.get(serrate))
        assert slider.value == pytest.approx(knob.get(serrate))


def test_a_slider_changes_the_leaf_and_the_frame(gl, serrate) -> None:
    w = LeafWidget(serrate, size=SIZE)
    before = w.get_frame()
    w.sliders["width"].value = 0.15
    assert max(x for _, x, _ in w.params.shape.silhouette) == pytest.approx(0.15)
    narrow, narrow_shape = w.get_frame(), w.params.shape
    assert _changed(before, narrow) > 0.05
    assert _not_background(narrow, w.background) < _not_background(before, w.background)
    w.sliders["bending.load"].value = 6.0
    assert w.params.bending.load == 6.0 and w.params.shape == narrow_shape
    assert _changed(narrow, w.get_frame()) > 0.01
    w.sliders["serration"].value = 0.0
    assert not w.params.jitter.enabled
    w.params = serrate   # setting the leaf moves the sliders back
    assert w.sliders["width"].value == pytest.approx(max(x for _, x, _ in serrate.shape.silhouette))
    assert w.sliders["serration"].value == pytest.approx(serrate.jitter.amplitude)


def test_an_invalid_edit_is_reported_and_changes_nothing(gl, serrate) -> None:
    def refuse(p: LeafParams, v: float) -> LeafParams:
        raise ParamError("jitter.amplitude", "refused for the test")

    w = LeafWidget(serrate, size=SIZE, knobs=(Knob("bad", "bad", "jitter.amplitude", lambda p: 0.0, refuse),))
    w.sliders["bad"].value = 0.05
    assert w.params == serrate
    assert "refused for the test" in w.status.value


def test_drag_orbits_wheel_dollies_double_click_resets(gl, serrate) -> None:
    w = LeafWidget(serrate, size=SIZE)
    home = w.get_frame()
    azimuth = w.camera.azimuth
    for event in DRAG:
        w.handle_event(event)
    assert w.camera.azimuth != azimuth
    orbited = w.get_frame()
    assert _changed(home, orbited) > 0.02
    distance = w.camera.distance
    w.handle_event({"type": "wheel", "x": 80, "y": 60, "dx": 0.0, "dy": -200.0, "buttons": (), "modifiers": ()})
    assert w.camera.distance < distance
    w.handle_event({"type": "double_click", "x": 80, "y": 60, "button": 1, "buttons": (), "modifiers": ()})
    assert _changed(home, w.get_frame()) < 0.01


def test_resize_follows_the_canvas(gl, serrate) -> None:
    w = LeafWidget(serrate, size=SIZE)
    w.handle_event({"type": "resize", "width": 100, "height": 80, "pwidth": 200, "pheight": 160, "ratio": 2.0})
    assert w.get_frame().shape[:2] == (160, 200)


def test_scene_widget_orbits_and_releases(gl, small_scene) -> None:
    w = LeafWidget(small_scene, size=SIZE)
    assert w.params is None and w.sliders == {}
    home = w.get_frame()
    assert home.shape[:2] == (120, 160) and home.dtype == np.uint8
    assert _not_background(home, w.background) > 0.01
    for event in DRAG:
        w.handle_event(event)
    assert _changed(home, w.get_frame()) > 0.01
    w.close()
    w.release()   # idempotent
    assert gl.ctx.error == "GL_NO_ERROR"


# -- _repr_png_ -----------------------------------------------------------------------------------
def test_leaf_repr_png_is_a_thumbnail(gl, serrate, tmp_path) -> None:
    png = serrate._repr_png_()
    assert isinstance(png, bytes) and png.startswith(b"\x89PNG")
    pixels = _decode(png, tmp_path)
    assert pixels.shape == (256, 256, 4) and pixels.dtype == np.uint8
    assert 0.1 < np.mean(pixels[..., 3] > 0) < 0.95


def test_scene_repr_png_is_a_thumbnail(gl, small_scene, tmp_path) -> None:
    png = small_scene._repr_png_()
    assert png is not None and png.startswith(PNG_SIGNATURE)
    pixels = _decode(png, tmp_path)
    assert pixels.shape == (256, 256, 4)
    assert 0.01 < np.mean(pixels[..., 3] > 0) < 0.9


def test_repr_png_is_none_without_a_renderer(small_scene) -> None:
    leaf, scene = register_png_renderer("leaf", None), register_png_renderer("scene", None)
    try:
        assert LeafParams()._repr_png_() is None
        assert small_scene._repr_png_() is None
    finally:
        register_png_renderer("leaf", leaf)
        register_png_renderer("scene", scene)
    assert leaf is not None and scene is not None   # import leafview registered both


def test_repr_png_is_none_when_gl_is_unavailable() -> None:
    def no_gl(obj: object) -> bytes:
        raise GLUnavailable("no EGL here (test)")

    previous = register_png_renderer("leaf", no_gl)
    try:
        assert LeafParams()._repr_png_() is None
        assert png_of("nothing registered", object()) is None
    finally:
        register_png_renderer("leaf", previous)
    assert display._PNG_RENDERERS["leaf"] is previous


@pytest.mark.parametrize("channels", [1, 3, 4])
def test_png_bytes_round_trip(channels, tmp_path) -> None:
    rng = np.random.default_rng(channels)
    pixels = rng.integers(0, 256, (7, 11, channels), dtype=np.uint8)
    png = png_bytes(pixels)
    assert png.startswith(PNG_SIGNATURE) and png == png_bytes(pixels)   # deterministic bytes
    decoded = _decode(png, tmp_path)
    assert np.array_equal(decoded.reshape(pixels.shape), pixels)
    with pytest.raises(ImageWriteError):
        png_bytes(pixels.astype(np.float32))


def test_import_leafview_loads_no_gl_and_no_notebook_package() -> None:
    code = ("import json, sys, leafview; leafview.LeafParams(); "
            "print(json.dumps(sorted(sys.modules)))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    loaded = json.loads(result.stdout.splitlines()[-1])
    heavy = [m for m in loaded if m.split(".")[0] in ("moderngl", "glcontext", "jupyter_rfb", "ipywidgets")
             or m.startswith("leafview.notebook") or m.startswith("leafview.gpu")]
    assert heavy == []
