"""The shaders' sRGB encoding (color.glsl's linear_to_srgb, frexp and a polynomial) read back through
transform feedback and compared with its numpy twin, leafview.core.colour.linear_to_srgb, and with
the pow() form of the transfer function it replaced."""

import shutil

import numpy as np
import pytest

from leafview.core.colour import linear_to_srgb
from leafview.gpu.shaders import build_program
from leafview.resources import shader_dir

pytestmark = pytest.mark.gl

VERT = """#version 450
#include "color.glsl"
vec3 pow_srgb(vec3 c) {   // the transfer function with pow(), as the shaders had it before
    c = clamp(c, 0.0, 1.0);
    return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
}
in float x;
out vec3 fast;
out vec3 exact;
void main() {
    vec3 c = vec3(x, 0.5 * x, 1.0 - x);
    fast = linear_to_srgb(c);
    exact = pow_srgb(c);
    gl_Position = vec4(0.0);
}
"""


def _encode(gl, tmp_path, x):
    shutil.copy(shader_dir() / "color.glsl", tmp_path / "color.glsl")
    (tmp_path / "t.vert").write_text(VERT)
    ctx = gl.ctx
    prog = build_program(ctx, "t.vert", None, varyings=("fast", "exact"), root=tmp_path)
    src = ctx.buffer(x.astype(np.float32).tobytes())
    vao = ctx.vertex_array(prog, [(src, "f", "x")])
    try:
        with gl.resources.capture.recording(len(x)) as rec:   # two vec3 a vertex
            rec.add(vao, len(x))
            out = rec.records().reshape(len(x), 2, 3).copy()
    finally:
        for obj in (vao, src, prog):
            obj.release()
    c = np.stack([x, 0.5 * x, 1.0 - x], axis=-1)
    return c, out[:, 0], out[:, 1]


def test_fast_srgb_matches_the_transfer_function(gl, tmp_path):
    # the whole range, the knee from both sides, the ends, values clamped from outside [0, 1]
    x = np.concatenate([np.linspace(0.0, 1.0, 20001), 0.0031308 * np.array([0.5, 0.999, 1.0, 1.001, 2.0]),
                        [-0.5, 1.5, 1e-6, 0.999999]])
    c, fast, exact = _encode(gl, tmp_path, x)
    want = linear_to_srgb(c)
    assert np.abs(fast - want).max() < 1e-6   # pow() itself: 4e-7 here
    # on 8 bits: the same code as the pow() it replaces for (nearly) every value
    codes = lambda v: np.floor(np.clip(v, 0.0, 1.0) * 255.0 + 0.5)   # noqa: E731
    differ = codes(fast) != codes(exact)
    assert differ.mean() < 1e-4
    assert np.abs(codes(fast) - codes(exact)).max() <= 1
    # monotonic, as an encoding must be
    order = np.argsort(c[:, 0])
    assert (np.diff(fast[order, 0]) >= -1e-7).all()
