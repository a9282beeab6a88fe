"""The reference photo in the viewer (Garg & Leow 2011, Fig. 1): Open… with an image, the photo
drawn in the leaf's plane behind the leaf (read back and compared with a numpy twin of its
placement and bilinear lookup), opacity, the base/apex markers dragged in the viewport, Fit
(undoable) and errors that change nothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from imgui_bundle import imgui
from scipy import ndimage

from leafview.app.chrome import FileBar
from leafview.app.orbit import project
from leafview.app.photo_reference import (
    MARKERS,
    display_image,
    fit_reference,
    is_photo_path,
    marker_world,
    move_marker,
    open_photo,
    pixel_of_world,
    world_from_pixel,
)
from leafview.app.state import ViewerState
from leafview.app.viewer import BACKGROUND, Viewer, open_state
from leafview.core.params import LeafParams, Transform
from leafview.export.images import write_image
from leafview.fit.photo import canonical_frame
from leafview.fit.photo_outline import leaf_outline, read_photo
from leafview.fit.synthetic_photos import synthetic_photo, write_photo
from leafview.resources import builtin_presets

SIZE = (960, 600)


def ellipse_photo(path: Path, size: tuple[int, int] = (96, 72)) -> Path:
    """A green ellipse (a leaf) on paper whose colour varies smoothly across the image, so that
    every pixel of the drawn photo says where it came from."""
    w, h = size
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    img = np.empty((h, w, 3))
    img[..., 0] = 0.75 + 0.2 * x / w
    img[..., 1] = 0.55 + 0.25 * y / h
    img[..., 2] = 0.95 - 0.3 * x / w
    inside = ((x - 0.55 * w) / (0.3 * w)) ** 2 + ((y - 0.5 * h) / (0.16 * h)) ** 2 <= 1.0
    img[inside] = np.stack([np.full(inside.sum(), 0.2), 0.5 + 0.15 * x[inside] / w, np.full(inside.sum(), 0.15)], -1)
    write_image(path, np.round(img * 255).astype(np.uint8))
    return path


@pytest.fixture
def leaf_photo(tmp_path) -> Path:
    """A synthetic photo (symmetric preset leaf, no petiole) written as PNG."""
    return write_photo(synthetic_photo(11, size=(400, 300), kind="preset", petiole=False, jpeg_quality=0),
                       tmp_path / "leaf.png")


@pytest.fixture
def state() -> ViewerState:
    path = builtin_presets()["ovate"]
    return open_state(LeafParams.load(path), path)


@pytest.fixture
def viewer(gl, state, tmp_path):
    v = Viewer(gl.ctx, state, samples=0, screenshot_dir=tmp_path)
    yield v
    v.release()


def frame(v: Viewer, n: int = 1) -> np.ndarray:
    for _ in range(n):
        assert v.frame(SIZE, SIZE, 1 / 60) is not None
        assert v.ctx.error == "GL_NO_ERROR"
    return v.read_frame()


# -- without GL ---------------------------------------------------------------------------------
def test_open_dispatches_by_suffix_and_keeps_the_leaf(state, tmp_path):
    photo = ellipse_photo(tmp_path / "Leaf.TIF")
    assert is_photo_path(photo) and is_photo_path("a.tiff") and not is_photo_path("a.toml")
    files = FileBar(state, {})
    assert state.set_field("shape.a1", [0.05, 0.33, 0.0])   # unsaved edits: a preset would ask first
    leaf, loads = state.params, state.loads
    files.request_open(photo)
    assert not files.asking and state.error is None
    assert state.reference.path == photo and state.reference.image is not None
    assert state.params == leaf and state.loads == loads and state.can_undo
    files.request_open(builtin_presets()["lanceolate"])       # a leaf file: asks about the edits
    assert files.asking and state.params == leaf


def test_placement_puts_the_photo_landmarks_on_the_leaf(state, tmp_path):
    path = ellipse_photo(tmp_path / "e.png")
    state.apply(lambda p: p.replace(transform=Transform(translation=(0.2, -0.1, 0.3), rotation=(10, 20, 30),
                                                        scale=1.7)))
    assert open_photo(state, path)
    ref = state.reference
    found = leaf_outline(read_photo(path))
    np.testing.assert_allclose(ref.leaf_from_pixel, canonical_frame(found.base, found.apex))
    m = state.params.transform.matrix()
    where = marker_world(ref, state.params)
    np.testing.assert_allclose(where["photo:base"], m[:3, 3], atol=1e-9)                 # leaf (0, 0, 0)
    np.testing.assert_allclose(where["photo:apex"], m[:3, 3] + m[:3, 1], atol=1e-9)      # leaf (0, 1, 0)
    px = np.array([[3.0, 4.0], [90.0, 10.0], [40.0, 70.0]])
    world = (np.c_[px, np.zeros(3), np.ones(3)] @ world_from_pixel(ref.leaf_from_pixel, state.params).T)[:, :3]
    np.testing.assert_allclose(pixel_of_world(ref.leaf_from_pixel, state.params, world), px, atol=1e-9)
    # a marker moves over the photo (clamped to it); the placement stays
    placement, apex = ref.leaf_from_pixel.copy(), ref.apex_px
    assert move_marker(state, "photo:base", world[1])
    np.testing.assert_allclose(ref.base_px, px[1], atol=1e-9)
    assert move_marker(state, "photo:base", world[1] + 50 * m[:3, 0])
    assert ref.base_px is not None and 0 <= ref.base_px[0] <= 95 and 0 <= ref.base_px[1] <= 71
    assert ref.apex_px == apex and np.array_equal(ref.leaf_from_pixel, placement)


def test_bad_images_show_an_error_and_change_nothing(state, tmp_path):
    good = ellipse_photo(tmp_path / "good.png")
    assert open_photo(state, good)
    before, leaf = state.reference, state.params
    paper = tmp_path / "paper.png"
    write_image(paper, np.full((64, 64, 3), 230, np.uint8))
    truncated = tmp_path / "cut.png"
    truncated.write_bytes(good.read_bytes()[:200])
    for bad in (paper, truncated, tmp_path / "missing.jpg", tmp_path):
        assert not open_photo(state, bad)
        assert state.error and str(bad.name) in state.error
        assert state.reference is before and state.params == leaf
    # a fit that fails (the file became a photo of bare paper) keeps the leaf and its history
    state.error = None
    good.write_bytes(paper.read_bytes())
    undo = state.can_undo
    assert not fit_reference(state)
    assert state.error and "Fit" in state.error and state.params == leaf and state.can_undo == undo
    assert state.reference is before and not before.fitted
    fresh = open_state(leaf, None)
    assert not fit_reference(fresh) and "open a photo" in (fresh.error or "")


def test_display_copy_is_reduced_by_block_means():
    rgb = np.random.default_rng(0).random((50, 70, 3)).astype(np.float32)
    full, f1 = display_image(rgb)
    assert f1 == 1 and full.shape == (50, 70, 4)
    np.testing.assert_array_equal(full[..., :3], np.rint(rgb * 255))
    small, f = display_image(rgb, max_side=20)
    assert f == 4 and small.shape == (13, 18, 4)
    np.testing.assert_allclose(small[1, 2, :3], rgb[4:8, 8:12].mean(axis=(0, 1)) * 255, atol=0.51)
    edge = rgb[[48, 49, 49, 49]][:, [68, 69, 69, 69]]          # the last row and column repeated
    np.testing.assert_allclose(small[12, 17, :3], edge.mean(axis=(0, 1)) * 255, atol=0.51)


# -- drawn --------------------------------------------------------------------------------------
def twin(v: Viewer, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What the viewport should show of the photo: (colour (h, w, 3) in [0, 255], where the photo
    is), each viewport pixel centre's ray met with the photo's plane, taken to photo pixels by the
    placement and sampled bilinearly (clamped to the edge) from ``image``."""
    sw = int(round(v.layout(SIZE[0])[0]))
    h = SIZE[1]
    cam = v.camera.camera(sw, h)
    inv = np.linalg.inv(cam.proj @ cam.view)
    ys, xs = np.mgrid[0:h, 0:sw] + 0.5
    ndc = np.stack([2 * xs / sw - 1, 1 - 2 * ys / h], axis=-1).reshape(-1, 2)
    ends = [np.c_[ndc, np.full(len(ndc), z), np.ones(len(ndc))] @ inv.T for z in (-1.0, 1.0)]
    a, b = (e[:, :3] / e[:, 3:] for e in ends)
    params, ref = v.state.params, v.state.reference
    m = world_from_pixel(ref.leaf_from_pixel, params)
    normal, point = m[:3, 2] / np.linalg.norm(m[:3, 2]), m[:3, 3]
    t = ((point - a) @ normal) / ((b - a) @ normal)
    px = pixel_of_world(ref.leaf_from_pixel, params, a + t[:, None] * (b - a))
    ih, iw = image.shape[:2]
    inside = (px[:, 0] >= -0.5) & (px[:, 0] <= iw - 0.5) & (px[:, 1] >= -0.5) & (px[:, 1] <= ih - 0.5)
    x, y = np.clip(px[:, 0], 0, iw - 1), np.clip(px[:, 1], 0, ih - 1)
    x0, y0 = np.minimum(x.astype(int), iw - 2), np.minimum(y.astype(int), ih - 2)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    img = image[..., :3].astype(np.float64)
    col = ((1 - fy) * ((1 - fx) * img[y0, x0] + fx * img[y0, x0 + 1])
           + fy * ((1 - fx) * img[y0 + 1, x0] + fx * img[y0 + 1, x0 + 1]))
    return col.reshape(h, sw, 3), inside.reshape(h, sw)


def test_photo_quad_matches_its_numpy_twin_and_blends(viewer, tmp_path):
    path = ellipse_photo(tmp_path / "e.png")
    viewer.files.request_open(path)
    view, ref = viewer.state.view, viewer.state.reference
    view.show_ground = view.show_controls = False
    sw = int(round(viewer.layout(SIZE[0])[0]))
    ref.visible = False
    plain = frame(viewer, 2)[:, :sw, :3].astype(int)
    bg = np.round(np.array(BACKGROUND[:3]) * 255)
    no_leaf = (np.abs(plain - bg).max(axis=-1) == 0)[:-60]                # not the leaf, not the status line
    expected, inside = twin(viewer, ref.image)
    # compare away from the photo's border (a pixel there is partly photo, partly background)
    core = ndimage.binary_erosion(inside, iterations=2)[:-60] & no_leaf
    rim = ~ndimage.binary_dilation(inside, iterations=2)[:-60] & no_leaf
    assert core.sum() > 20_000 and rim.sum() > 20_000
    ref.visible, ref.opacity = True, 1.0
    shown = frame(viewer)[:-60, :sw, :3].astype(int)
    diff = np.abs(shown - expected[:-60]).max(axis=-1)
    assert np.mean(diff[core] > 3) < 0.005 and diff[core].max() <= 8, (np.mean(diff[core] > 3), diff[core].max())
    assert (np.abs(shown - bg).max(axis=-1)[rim] == 0).all()              # nothing drawn off the photo
    leaf = ~no_leaf & ~np.all(shown == plain[:-60], axis=-1)
    assert leaf.sum() == 0                                                 # the leaf is drawn over the photo
    ref.opacity = 0.5
    half = frame(viewer)[:-60, :sw, :3].astype(int)
    diff = np.abs(half - (0.5 * expected[:-60] + 0.5 * bg)).max(axis=-1)
    assert np.mean(diff[core] > 3) < 0.005 and diff[core].max() <= 6


def test_markers_drag_in_the_viewport_and_fit_replaces_the_leaf_undoably(viewer, leaf_photo):
    state = viewer.state
    before = state.params
    viewer.files.request_open(leaf_photo)
    assert state.error is None
    frame(viewer, 2)
    sw = int(round(viewer.layout(SIZE[0])[0]))
    cam = viewer.camera.camera(sw, SIZE[1])
    where = marker_world(state.reference, state.params)
    x, y = np.round(project(cam, np.array([where["photo:apex"]]), sw, SIZE[1])[0])   # imgui floors the mouse
    apex0 = np.array(state.reference.apex_px)
    io = imgui.get_io()
    io.add_mouse_pos_event(x, y)
    frame(viewer)
    assert viewer.input.hot == "photo:apex"
    io.add_mouse_button_event(0, True)
    frame(viewer)
    for k in range(1, 4):
        io.add_mouse_pos_event(x + 2 * k, y + k)
        frame(viewer)
    io.add_mouse_button_event(0, False)
    frame(viewer)
    moved = marker_world(state.reference, state.params)["photo:apex"]
    np.testing.assert_allclose(project(cam, moved[None], sw, SIZE[1])[0], (x + 6, y + 3), atol=0.5)
    assert 1.0 < np.hypot(*(np.array(state.reference.apex_px) - apex0)) < 20.0
    assert state.params == before and not state.can_undo                 # the leaf did not move
    io.add_mouse_pos_event(x - 5, y - 5)
    # put the apex back where it was found, then press Fit in the panel
    state.reference.apex_px = (float(apex0[0]), float(apex0[1]))
    frame(viewer)
    rect = viewer.panel.rects["reference.fit"]
    io.add_mouse_pos_event((rect[0] + rect[2]) / 2, (rect[1] + rect[3]) / 2)
    frame(viewer)
    io.add_mouse_button_event(0, True)
    frame(viewer)
    io.add_mouse_button_event(0, False)
    frame(viewer)
    ref = state.reference
    assert state.error is None and ref.fitted and state.params != before, state.error
    assert ref.report["iou"] >= 0.9, ref.report
    np.testing.assert_allclose(ref.report["apex_px"], apex0, atol=1e-3)  # the markers were the fit's landmarks
    assert MARKERS[0] in marker_world(ref, state.params)
    frame(viewer)
    assert state.undo() and state.params == before and not state.can_undo
    assert state.redo() and state.params != before
