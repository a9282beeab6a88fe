"""Headless rendering: the documented top view (exact framing, orientation, alpha), the
perspective views, linear output, determinism and input checks."""

import numpy as np
import pytest

import leafview
from leafview.core.params import Transform
from leafview.deform.surface import grid_uv

pytestmark = pytest.mark.gl


def _bbox(alpha):
    ys, xs = np.nonzero(alpha)
    return xs.min(), xs.max(), ys.min(), ys.max()


@pytest.mark.parametrize("name", ["ovate", "linear", "orbicular", "asymmetric"])
def test_top_view_framing_is_exact(gl, presets, name):
    size = 200
    img = gl.render(presets[name], (size, size), "top")
    assert img.shape == (size, size, 4) and img.dtype == np.uint8
    alpha = img[..., 3]
    assert set(np.unique(alpha)) <= {0, 255}  # no multisampling in the top view: binary alpha
    x0, x1, y0, y1 = _bbox(alpha > 0)
    w, h = x1 - x0 + 1, y1 - y0 + 1
    assert max(w, h) == pytest.approx(0.9 * size, abs=2)  # longer side spans 90 %
    assert (x0 + x1) / 2 == pytest.approx((size - 1) / 2, abs=1.5)  # centred
    assert (y0 + y1) / 2 == pytest.approx((size - 1) / 2, abs=1.5)


def test_top_view_orientation_plus_y_up(gl, presets):
    """Image row 0 is the top and +y points up: a symmetric leaf widest near its base (small y)
    is widest near the bottom of the image, and the other way round."""
    size = 160
    uv = grid_uv(33, 65)
    for name in ("deltoid", "ovate", "obovate"):
        p = presets[name]
        pts = leafview.evaluate(p, uv[:, 0], uv[:, 1])
        y_widest = pts[np.argmax(np.abs(pts[:, 0])), 1]
        frac_ref = (y_widest - pts[:, 1].min()) / np.ptp(pts[:, 1])
        widths = (gl.render(p, (size, size), "top")[..., 3] > 0).sum(axis=1)
        rows = np.nonzero(widths)[0]
        widest_row = rows[np.argmax(widths[rows])]
        frac_from_bottom = (rows.max() - widest_row) / (rows.max() - rows.min())
        assert abs(frac_ref - 0.5) > 0.15, name  # a flipped image would read 1 - frac_ref
        assert frac_from_bottom == pytest.approx(frac_ref, abs=0.1), name


def test_top_view_orientation_plus_x_right(gl, presets):
    """The asymmetric preset's midrib bows towards +x: in the image the blade's middle lies to
    the right of its base and apex."""
    p = presets["asymmetric"]
    assert leafview.evaluate(p, 0.0, 0.5)[0, 0] > 0.05
    mask = gl.render(p, (160, 160), "top")[..., 3] > 0
    rows = np.nonzero(mask.any(axis=1))[0]
    centre = lambda r: np.nonzero(mask[r])[0].mean()  # noqa: E731
    middle = centre((rows.min() + rows.max()) // 2)
    assert middle > centre(rows.max() - 2) + 3 and middle > centre(rows.min() + 2) + 3


def test_transparent_background_and_solid_background(gl, presets):
    img = gl.render(presets["ovate"], (96, 96), "top")
    assert img[0, 0, 3] == 0 and img[48, 48, 3] == 255
    img = gl.render(presets["ovate"], (96, 96), "top", background=(1.0, 1.0, 1.0))
    assert img[0, 0].tolist() == [255, 255, 255, 255]


def test_perspective_views_are_multisampled_and_framed(gl, presets):
    for view in ("front", "three-quarter"):
        img = gl.render(presets["elliptic"], (128, 128), view)
        alpha = img[..., 3]
        assert 0 < np.count_nonzero(alpha) < alpha.size
        partial = np.count_nonzero((alpha > 0) & (alpha < 255))
        assert partial > 0, f"{view}: no partially covered edge pixels, multisampling is off"
        x0, x1, y0, y1 = _bbox(alpha > 0)
        assert x0 > 0 and y0 > 0 and x1 < 127 and y1 < 127, f"{view}: leaf touches the border"


def test_transparent_multisampled_edges_are_not_darkened(gl, presets):
    """8-bit output has straight (unassociated) alpha: partially covered edge pixels keep the
    leaf's colour instead of fading towards the black of the cleared background."""
    img = gl.render(presets["orbicular"], (128, 128), "three-quarter").astype(np.float64)
    alpha = img[..., 3]
    luma = img[..., :3].mean(axis=-1)
    edge, solid = (alpha > 20) & (alpha < 200), alpha == 255
    assert edge.sum() > 20
    assert luma[edge].mean() > 0.75 * luma[solid].mean()


def test_linear_output_is_float_and_matches_srgb(gl, presets):
    p = presets["ovate"]
    lin = gl.render(p, (64, 64), "top", linear=True)
    srgb = gl.render(p, (64, 64), "top")
    assert lin.dtype == np.float32
    inside = srgb[..., 3] == 255
    encoded = np.where(lin[..., :3] <= 0.0031308, 12.92 * lin[..., :3],
                       1.055 * np.clip(lin[..., :3], 0, None) ** (1 / 2.4) - 0.055)
    assert np.abs(encoded[inside] * 255 - srgb[..., :3][inside]).max() <= 1.0


def test_same_params_same_pixels_and_world_transform_does_not_move_top_view(gl, presets):
    p = presets["serrate"]
    a = gl.render(p, (96, 96), "three-quarter")
    b = gl.render(p, (96, 96), "three-quarter")
    np.testing.assert_array_equal(a, b)
    moved = p.replace(transform=Transform(translation=(3.0, -2.0, 1.0)))
    here, there = gl.render(p, (96, 96), "top"), gl.render(moved, (96, 96), "top")
    np.testing.assert_array_equal(here[..., 3], there[..., 3])   # the same pixels covered: nothing moved
    # the shading's world positions round differently once translated (linear colours differ by up
    # to 5e-6), which moves a colour lying on an 8-bit step by one code on a pixel or two
    diff = np.abs(here.astype(np.int16) - there)
    assert diff.max() <= 1 and (diff > 0).any(axis=-1).sum() <= 3


def test_module_level_render_and_errors(gl, presets):
    img = leafview.render(presets["ovate"], size=(80, 60))
    assert img.shape == (60, 80, 4)
    with pytest.raises(ValueError, match="unknown view"):
        leafview.render(presets["ovate"], view="bottom")
    with pytest.raises(ValueError, match="size"):
        leafview.render(presets["ovate"], size=(0, 10))
    with pytest.raises(ValueError, match="background"):
        leafview.render(presets["ovate"], background=(2, 0, 0))


def test_render_many_equals_one_at_a_time(gl, presets):
    """The batched atlas path gives each leaf the image of a single render (up to interpolation
    rounding from the tile's viewport offset), also with different jitter seeds and with batches
    that span several chunks."""
    from leafview.core.params import Jitter
    from leafview.gpu import renderer as renderer_module

    leaves = list(presets.values())
    leaves += [presets["ovate"].replace(jitter=Jitter(enabled=True, seed=s, amplitude=0.04)) for s in (1, 2, 3)]
    for view in ("top", "three-quarter"):
        batch = gl.render_many(leaves, (48, 40), view)
        assert len(batch) == len(leaves)
        for leaf, img in zip(leaves, batch):
            _same(img, gl.render(leaf, (48, 40), view), f"{leaf.name} {view}")
    small = renderer_module.BATCH
    try:
        renderer_module.BATCH = 4  # force several chunks
        chunked = gl.render_many(leaves, (32, 32), "top")
    finally:
        renderer_module.BATCH = small
    for leaf, img in zip(leaves, chunked):
        _same(img, gl.render(leaf, (32, 32), "top"), leaf.name)
    assert gl.render_many([], (32, 32)) == []


def _premultiplied(img):
    """Colour times coverage: a partly covered edge pixel's unpremultiplied colour magnifies one
    level of rounding by 255 / alpha (shading that varies over the blade, as veined skin does,
    lands some edge pixel on a rounding boundary)."""
    out = img.astype(np.float64)
    out[..., :3] *= out[..., 3:] / 255.0
    return np.rint(out).astype(np.int16)


def _same(a, b, what):
    diff = np.abs(_premultiplied(a) - _premultiplied(b)).max(axis=-1)
    assert diff.max() <= 2 and np.mean(diff > 0) <= 0.005, f"{what}: {np.mean(diff > 0):.2%} differ, max {diff.max()}"


def test_interactive_draw_into_a_bound_framebuffer(gl, presets):
    """set_leaf + set_camera + draw(): the viewer's per-frame path, with wireframe."""
    from leafview.scene.camera import frame_view

    fbo = gl.ctx.simple_framebuffer((64, 64))
    try:
        p = presets["ovate"]
        gl.set_leaf(p)
        uv = grid_uv(33, 65)
        gl.set_camera(frame_view("top", leafview.evaluate(p, uv[:, 0], uv[:, 1]), (64, 64)), srgb=True)
        covered = {}
        for wire in (False, True):
            fbo.use()
            fbo.clear(0, 0, 0, 0, depth=1.0)
            gl.draw((5, 9), wireframe=wire)
            img = np.frombuffer(fbo.read(components=4), np.uint8).reshape(64, 64, 4)
            covered[wire] = np.count_nonzero(img[..., 3])
        assert covered[False] > 1000  # the filled leaf
        assert 0 < covered[True] < covered[False]  # the wireframe draws only its edges
        assert gl.ctx.wireframe is False
    finally:
        gl.ctx.detect_framebuffer(0).use()
        fbo.release()
