"""Every vertex shader that feeds leaf.frag (leaf.vert's single, instanced and scene draws;
leaf_baked.vert) passes a leaf's colours as halves in one flat slot (``v_colours``,
``shaders/leaf_colours.glsl``). The captured slot equals its numpy twin
(:func:`leafview.gpu.layout.pack_colours`) bit for bit, and the instanced draw (colours from the
float record) and the baked draw (colours from unorm8 vertex attributes) agree to one 8-bit step."""

from __future__ import annotations

import dataclasses

import moderngl
import numpy as np
import pytest

from leafview.gpu.instanced import (
    _BAKED_ATTRS,
    _BAKED_FORMAT,
    BakedLeaves,
    InstancedLeaves,
    OffscreenTarget,
    pack_leaves,
    scatter_leaves,
)
from leafview.gpu.layout import (
    LEAF_BLOCK,
    NO_LOBE_DEFINES,
    NO_VEIN_DEFINES,
    PLAIN_DEFINES,
    feature_defines,
    pack_colours,
)
from leafview.gpu.resources import record_vertex_array
from leafview.scene.camera import frame_view
from tests.conftest import draw_each

SIZE = (256, 256)


def _coloured_leaves(n: int = 8):
    """``scatter_leaves`` with distinct colours on an 8-bit grid (the baked draw stores unorm8),
    dark ones included (where the sRGB encoding magnifies a colour's error most)."""
    rng = np.random.default_rng(7)
    out = []
    for p in scatter_leaves(n, seed=4, radius=0.2, jitter_fraction=0.0):
        front, back = rng.integers(1, 256, 3) / 255.0, rng.integers(1, 256, 3) / 255.0
        front[0] = 3 / 255.0
        mat = dataclasses.replace(p.material, front=tuple(front), back=tuple(back),
                                  translucency=float(rng.integers(0, 256)) / 255.0)
        out.append(p.replace(material=mat))
    return out


@pytest.mark.gl
def test_instanced_and_baked_colours_draw_alike(gl):
    ctx = gl.ctx
    params = _coloured_leaves()
    recs, table = pack_leaves(params)
    with OffscreenTarget(ctx, SIZE) as target, \
            InstancedLeaves(ctx, recs, (9, 15), jitter_tables=table, resources=gl.resources) as inst, \
            BakedLeaves.from_instanced(inst, resources=gl.resources) as baked:
        pos, _ = inst.capture()
        camera = frame_view("three-quarter", pos.reshape(-1, 3).astype(np.float64), SIZE)
        images = draw_each(target, (inst, baked), camera)
    assert ctx.error == "GL_NO_ERROR"
    a, b = (img.astype(np.int16) for img in images)
    covered = a[..., 3] > 0
    assert covered.mean() > 0.03, "the leaves should fill a good part of the image"
    assert np.array_equal(covered, b[..., 3] > 0)
    # many colours, so that a swapped or misread half would show
    assert len(np.unique(a[covered][:, :3], axis=0)) > 50
    assert np.abs(a - b).max() <= 1


def _captured_colours(gl, vao, vertices: int, instances: int = 1) -> np.ndarray:
    """``v_colours`` of every vertex a transform-feedback pass of ``vao`` emits, as (k, 4) uint32."""
    ctx = gl.ctx
    buf = ctx.buffer(reserve=16 * vertices * instances)
    try:
        gl.resources.capture.framebuffer().use()   # a complete framebuffer, as the captures bind
        vao.transform(buf, mode=moderngl.POINTS, vertices=vertices, instances=instances)
        return np.frombuffer(buf.read(), np.uint32).reshape(-1, 4).copy()
    finally:
        buf.release()


@pytest.mark.gl
def test_colour_slot_is_its_numpy_twin(gl):
    """Bit for bit: the instanced path packs the record's float colours, the baked path its
    unorm8 vertex colours; both as :func:`pack_colours` does (dark, mid and bright values, and
    colours between two halves, where a different rounding would show)."""
    ctx = gl.ctx
    rng = np.random.default_rng(11)
    params = []
    for p in scatter_leaves(6, seed=2, radius=0.2, jitter_fraction=0.0):
        front = rng.uniform(0.0, 1.0, 3) ** 3          # many small values: the halves' finest steps
        mat = dataclasses.replace(p.material, front=tuple(front), back=tuple(rng.uniform(0.0, 1.0, 3)),
                                  translucency=float(rng.uniform()))
        params.append(p.replace(material=mat))
    recs, table = pack_leaves(params)
    nverts = 9 * 15
    with InstancedLeaves(ctx, recs, (9, 15), jitter_tables=table, resources=gl.resources) as inst, \
            BakedLeaves.from_instanced(inst, resources=gl.resources) as baked:
        defines = {"LEAF_INSTANCED": 1, **feature_defines(recs), **PLAIN_DEFINES, **NO_VEIN_DEFINES,
                   **NO_LOBE_DEFINES}
        prog = gl.resources.leaf_program(defines, varyings=("v_colours",))
        vao = record_vertex_array(ctx, prog, inst.grid.vbo, inst.ssbo, LEAF_BLOCK)
        inst._bind()
        got = _captured_colours(gl, vao, nverts, len(params)).reshape(len(params), nverts, 4)
        vao.release()
        bprog = gl.resources.programs.program("leaf_baked.vert", "leaf.frag",
                                              defines={**PLAIN_DEFINES, **NO_VEIN_DEFINES}, varyings=("v_colours",))
        bvao = ctx.vertex_array(bprog, [(baked.vbo, _BAKED_FORMAT, *_BAKED_ATTRS)])
        got_baked = _captured_colours(gl, bvao, nverts * len(params)).reshape(len(params), nverts, 4)
        bvao.release()
    assert ctx.error == "GL_NO_ERROR"
    want = pack_colours(recs["front"], recs["back"][:, :3])
    assert np.array_equal(got, np.broadcast_to(want[:, None], got.shape))
    unorm = np.rint(np.clip(recs["front"], 0, 1) * 255) / 255, np.rint(np.clip(recs["back"][:, :3], 0, 1) * 255) / 255
    want_baked = pack_colours(*unorm)
    assert np.array_equal(got_baked, np.broadcast_to(want_baked[:, None], got_baked.shape))
    # the slot carries distinct colours, so a swapped half or channel would have shown
    assert not np.array_equal(want[:, 0], want[:, 1]) and len(np.unique(want[:, 0])) == len(params)
