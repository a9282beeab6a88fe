"""The instanced and scene draws pass a leaf's colours to leaf.frag as halves in one flat slot
(leaf.vert's ``v_colours``); the baked draw passes them as floats. Same vertices (captured from
the instanced vertex shader), same fragment shader: the pictures agree to one 8-bit step."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from leafview.gpu.instanced import BakedLeaves, InstancedLeaves, OffscreenTarget, pack_leaves, scatter_leaves
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
def test_packed_colours_draw_as_the_float_colours(gl):
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
