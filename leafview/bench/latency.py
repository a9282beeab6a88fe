"""``edit_latency_ratio`` for ``leafview bench``: how much longer a frame that carries an edit
takes than a steady frame, in the viewer's own pipeline.

Both kinds of frame are complete viewer frames (imgui panel, leaf, control polygons, ground
grid) of a 1280×800 window drawn into the viewer's offscreen framebuffer and read back with
``glReadPixels`` (which waits for the GPU). The edit frame starts the clock *before* the edit is
made through the state API the panel uses (a silhouette slider being dragged), so it includes
validation, the uniform-block upload, the compute dispatch of the derived constants and the
overlay rebuild. Frames are interleaved (steady, edit, steady, ...) and the ratio is the median of
the per-pair ratios, so machine drift cancels. Goal: ≤ 1.2.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import moderngl

from leafview.app.viewer import Viewer, open_state
from leafview.core.params import LeafParams
from leafview.resources import builtin_presets

__all__ = ["measure_edit_latency", "EDIT_LATENCY_GOAL", "VIEWER_SIZE"]

EDIT_LATENCY_GOAL = 1.2
VIEWER_SIZE = (1280, 800)


def measure_edit_latency(ctx: moderngl.Context, *, pairs: int = 30, warmup: int = 5,
                         size: tuple[int, int] = VIEWER_SIZE) -> dict[str, Any]:
    """Median (edit frame ÷ steady frame) over ``pairs`` interleaved pairs; also the median
    times in ms and the bytes uploaded by one edit."""
    path = builtin_presets()["ovate"]
    state = open_state(LeafParams.load(path), path)
    rows = [list(r) for r in state.params.shape.silhouette]
    steady: list[float] = []
    edited: list[float] = []
    uploads: list[int] = []
    with Viewer(ctx, state) as viewer:
        def frame() -> None:
            viewer.frame(size, size, 1 / 60)
            viewer.read_frame()

        for _ in range(warmup):
            frame()
        for i in range(pairs):
            t0 = time.perf_counter()
            frame()
            steady.append(time.perf_counter() - t0)
            wide = [[v, x * (1.0 + 0.02 * (1 + i % 5)), z] for v, x, z in rows]
            t0 = time.perf_counter()
            changed = state.set_field("shape.silhouette", wide, gesture=True)
            frame()
            edited.append(time.perf_counter() - t0)
            if not changed:
                raise RuntimeError(f"the benchmark edit was rejected: {state.error}")
            uploads.append(viewer.last_upload_bytes)
        state.end_gesture()
        if viewer.gl_errors:
            raise RuntimeError(f"OpenGL errors while measuring the viewer: {viewer.gl_errors[:3]}")
        samples = viewer.samples
    ratios = [e / s for e, s in zip(edited, steady)]
    return {
        "edit_latency_ratio": statistics.median(ratios),
        "viewer_frame_ms": 1e3 * statistics.median(steady),
        "viewer_edit_frame_ms": 1e3 * statistics.median(edited),
        "viewer_edit_upload_bytes": max(uploads),
        "viewer_size": list(size),
        "viewer_samples": samples,
    }
