"""Long batch runs: 500 thumbnails in one process must not grow the number of live GL objects
nor the resident memory by more than 20 MB."""

import gc

import moderngl
import numpy as np
import pytest

from leafview.core.params import Jitter

pytestmark = [pytest.mark.gl, pytest.mark.slow]

_GL_TYPES = (moderngl.Buffer, moderngl.Texture, moderngl.Framebuffer, moderngl.Renderbuffer,
             moderngl.VertexArray, moderngl.Program, moderngl.ComputeShader)


def live_gl_objects() -> int:
    """moderngl wrappers alive and not released (each one holds a GL object)."""
    gc.collect()
    return sum(1 for o in gc.get_objects()
               if isinstance(o, _GL_TYPES) and type(o.mglo).__name__ != "InvalidObject")


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096


def test_500_thumbnails_leave_no_gl_objects_and_little_memory(gl, presets):
    ctx = gl.ctx
    ctx.gc_mode = "context_gc"  # unreleased objects dropped by Python land in ctx.objects
    leaves = list(presets.values())
    sizes = [(64, 64), (96, 96), (80, 48)]
    views = ["top", "three-quarter", "front"]

    def batch(n, offset):
        for i in range(n):
            p = leaves[(i + offset) % len(leaves)]
            if i % 3 == 0:  # exercise jitter re-uploads with changing seeds
                p = p.replace(jitter=Jitter(enabled=True, seed=i % 7))
            gl.render(p, sizes[i % 3], views[i % 3])
            gl.capture(p, np.linspace(-1, 1, 33), np.linspace(0, 1, 33))

    try:
        batch(30, 0)  # warm caches and allocator pools
        objects_before, rss_before = live_gl_objects(), rss_bytes()
        batch(500, 30)
        objects_after, rss_after = live_gl_objects(), rss_bytes()
        gc.collect()
        # moderngl's __del__ appends every collected wrapper's handle, released ones included
        # (as InvalidObject); only live handles are leaks
        dropped_unreleased = sum(1 for o in ctx.objects if type(o).__name__ != "InvalidObject")
        ctx.objects.clear()
    finally:
        ctx.gc_mode = None
    assert objects_after <= objects_before, f"live GL objects grew: {objects_before} -> {objects_after}"
    assert dropped_unreleased == 0, f"{dropped_unreleased} GL objects were dropped without release()"
    growth = (rss_after - rss_before) / 2**20
    assert growth < 20, f"RSS grew by {growth:.1f} MB over 500 thumbnails"
