"""The shared GPU resources: one program cache, prepare pass, grids, targets and capture for every
renderer that is given them; created in one place, released in one place."""

from __future__ import annotations

import numpy as np
import pytest

import leafview
from leafview.deform.surface import grid_uv
from leafview.gpu.instanced import InstancedLeaves
from leafview.gpu.layout import pack_leaves, ripple_keys
from leafview.gpu.renderer import LeafRenderer
from leafview.gpu.resources import GpuResources
from leafview.gpu.targets import RenderTarget, unpremultiply
from leafview.scene.camera import frame_view
from tests.support.gl_objects import live_gl_objects

pytestmark = pytest.mark.gl



def test_renderers_given_one_set_compile_each_program_once(gl, presets):
    leaves = [presets["ovate"], presets["maize"]]
    before = live_gl_objects()
    with GpuResources(gl.ctx) as res:
        with LeafRenderer(gl.ctx, resources=res) as a:
            a.render(leaves[0], (24, 24))
            compiled = len(res.programs)
            with LeafRenderer(gl.ctx, resources=res) as b:
                assert b.program is a.program and b.prepare is a.prepare
                b.render(leaves[0], (24, 24))
            assert len(res.programs) == compiled       # nothing compiled twice
        records, tables = pack_leaves(leaves)
        with InstancedLeaves(gl.ctx, records, (5, 9), jitter_tables=tables, ripple_signals=ripple_keys(leaves),
                             resources=res) as inst:
            assert inst.resources is res
            fbo_before = gl.ctx.fbo
            pos, _ = inst.capture()
            assert gl.ctx.fbo is fbo_before               # the capture re-binds the caller's framebuffer
            assert pos.shape == (2, 45, 3) and np.isfinite(pos).all()
        # the renderers that borrowed the set released nothing of it: a new one still draws
        with LeafRenderer(gl.ctx, resources=res) as c:
            assert c.render(leaves[0], (24, 24))[..., 3].any()
    assert live_gl_objects() == before
    assert gl.ctx.error == "GL_NO_ERROR"


def test_release_in_one_place_leaves_no_gl_objects(gl, presets):
    before = live_gl_objects()
    res = GpuResources(gl.ctx)
    r = LeafRenderer(gl.ctx, resources=res)
    r.render(presets["serrate"], (32, 32), "three-quarter")          # programs, grid, MSAA target
    r.capture(presets["serrate"], [0.0, 0.5], [0.5, 0.5])              # capture framebuffer
    r.render_many([presets["ovate"], presets["holly"]], (16, 16))     # batch rows, atlas target
    assert live_gl_objects() > before
    r.release()
    res.release()
    res.release()   # idempotent
    r.release()
    assert live_gl_objects() == before
    assert gl.ctx.error == "GL_NO_ERROR"


def test_grid_caches_one_vertex_array_per_program(gl):
    with GpuResources(gl.ctx) as res:
        grid = res.grid(5, 9)
        assert res.grid(5, 9) is grid and grid.vertices == 45 and grid.triangles == 64
        full, instanced = res.leaf_program(), res.leaf_program({"LEAF_INSTANCED": 1})
        assert res.leaf_program() is full
        assert grid.vao(full) is grid.vao(full) and grid.vao(full) is not grid.vao(instanced)
        assert grid.points(full) is not grid.vao(full)


def test_multisampled_target_resolves_on_read(gl, presets):
    """A 4× target reads back resolved (partial coverage at the edges) and matches the renderer's
    own thumbnail path."""
    p = presets["orbicular"]
    uv = grid_uv(33, 65)
    cam = frame_view("three-quarter", leafview.evaluate(p, uv[:, 0], uv[:, 1]), (64, 64))
    with RenderTarget(gl.ctx, (64, 64), 4) as target:
        assert target.fbo is not target.resolved and target.fbo.samples == 4
        gl.set_leaf(p)
        gl.set_camera(cam, srgb=True)
        target.use()
        target.clear()
        gl.draw()
        img = unpremultiply(target.read())
    alpha = img[..., 3]
    assert ((alpha > 0) & (alpha < 255)).any() and (alpha == 255).any()
    ref = gl.render_many([p], (64, 64), "three-quarter", camera=cam)[0]
    diff = np.abs(img.astype(np.int16) - ref.astype(np.int16)).max(axis=-1)
    assert np.mean(diff > 2) < 0.005


def test_unpremultiply_in_place_is_the_copy():
    """``unpremultiply(img, out=img)`` (the thumbnail atlas, straightened once) writes what the
    copying form returns, and leaves full and empty pixels as they were."""
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, size=(40, 30, 4), dtype=np.uint8)
    img[..., :3] = np.minimum(img[..., :3], img[..., 3:4])   # premultiplied: colour <= alpha
    img[:5, :, 3] = 255
    img[5:9, :, 3] = 0
    copy = unpremultiply(img)
    assert copy is not img
    inplace = img.copy()
    assert unpremultiply(inplace, out=inplace) is inplace
    np.testing.assert_array_equal(inplace, copy)
    np.testing.assert_array_equal(copy[:9], img[:9])   # alpha 255 or 0: unchanged
    opaque = np.full((4, 4, 4), 255, np.uint8)
    assert unpremultiply(opaque) is opaque


def test_jitter_rows_uploaded_again_only_when_they_change(gl, presets):
    """JitterTable.upload writes nothing when the texture holds the same rows (one render() of a
    jittered leaf after another), writes again after set_seed replaced row 0 or for other rows,
    and the texture then holds what was asked."""
    from leafview.core.blade import JITTER_TABLE_SIZE, jitter_table
    from leafview.core.params import Jitter
    from leafview.gpu.resources import JitterTable

    a, b = jitter_table(Jitter(enabled=True, seed=3)), jitter_table(Jitter(enabled=True, seed=4))
    table = JitterTable(gl.ctx)
    try:
        assert table.upload(a[None]) == a.nbytes
        assert table.upload(a[None]) == 0
        assert table.upload(np.stack([a, b])) == 2 * a.nbytes
        assert table.set_seed(Jitter(enabled=True, seed=4)) == a.nbytes   # row 0 now b
        assert table.upload(np.stack([a, b])) == 2 * a.nbytes           # so a is written again
        rows = np.frombuffer(table.texture.read(), np.float32).reshape(-1, JITTER_TABLE_SIZE)
        np.testing.assert_array_equal(rows[:2], np.stack([a, b]))
    finally:
        table.release()


def test_repeated_render_reuses_its_vertex_array_and_pixels(gl, presets):
    """One render() after another with the same features draws through the same vertex array
    (none made per call) and gives the same pixels; another feature set (a textured or a lobed
    leaf) gets its own and still matches its render_many image."""
    leaf = presets["ovate"]
    first = gl.render(leaf, 48, "three-quarter")
    vao = gl._baked_vao._vao
    assert vao is not None
    again = gl.render(leaf, 48, "three-quarter")
    assert gl._baked_vao._vao is vao
    np.testing.assert_array_equal(first, again)
    others = [p for name, p in presets.items() if name != "ovate"][:3]
    for p in others:
        np.testing.assert_array_equal(gl.render(p, 48, "side"), gl.render_many([p], 48, "side")[0])
    np.testing.assert_array_equal(gl.render(leaf, 48, "three-quarter"), first)
