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
