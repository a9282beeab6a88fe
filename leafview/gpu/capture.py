"""Transform-feedback capture, written once: what the rendering vertex shader computes, read back.

Every capture of the package (single leaves at arbitrary (u, v), the thumbnail atlas, instanced
leaves, scene leaves, the exporters' meshes) records the program's varyings of ``POINTS`` draws
into one growing buffer, then reads it once: two ``vec3`` (position, normal) a vertex, or with
``vertex_bytes`` more (the thumbnails also keep the drawn (u, v), and draw from the buffer itself). A surfaceless EGL context has no default framebuffer and draws (even with rasterizer
discard) need a complete one bound, so a recording binds a 1 × 1 one and re-binds the caller's
framebuffer when it ends.
"""

from __future__ import annotations

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.gpu.limits import check_buffer, context_alive, ensure_alive
from leafview.gpu.owner import GrowingBuffer, release_all

__all__ = ["FeedbackCapture", "Recording", "VERTEX_BYTES"]

VERTEX_BYTES = 24          # two vec3 varyings a vertex: position, normal
_KEEP_BYTES = 1 << 24      # larger captures use a buffer of their own, released when read


class Recording:
    """One capture in progress (see :meth:`FeedbackCapture.recording`): :meth:`add` draws append
    after each other, :meth:`read` returns everything recorded. ``buffer`` holds the records
    (``vertex_bytes`` each, position and normal first) until the recording closes."""

    def __init__(self, capture: FeedbackCapture, vertices: int, vertex_bytes: int = VERTEX_BYTES) -> None:
        self._capture = capture
        self.capacity = int(vertices)
        self.vertex_bytes = int(vertex_bytes)
        if self.vertex_bytes < VERTEX_BYTES or self.vertex_bytes % 4:
            raise ValueError(f"vertex_bytes must be a multiple of 4 of at least {VERTEX_BYTES}, got {vertex_bytes}")
        self.count = 0
        self._temporary: moderngl.Buffer | None = None
        need = self.capacity * self.vertex_bytes
        check_buffer(need, "vertices", f"a capture of {self.capacity:,} vertices")  # before allocating
        ensure_alive(capture.ctx, "a capture")
        if need > _KEEP_BYTES:
            self._temporary = capture.ctx.buffer(reserve=need)
            self.buffer = self._temporary
        else:
            self.buffer = capture.out.ensure(need)
        self._previous = capture.ctx.fbo
        capture.framebuffer().use()

    def add(self, vao: moderngl.VertexArray, vertices: int, instances: int = 1) -> None:
        """Draw ``vertices`` points (× ``instances``) of ``vao`` into the next rows."""
        n = int(vertices) * int(instances)
        if self.count + n > self.capacity:
            raise ValueError(f"capture of {self.capacity} vertices is full ({self.count} + {n})")
        vao.transform(self.buffer, mode=moderngl.POINTS, vertices=int(vertices), instances=int(instances),
                      buffer_offset=self.count * self.vertex_bytes)
        self.count += n

    def records(self) -> NDArray[np.float32]:
        """Everything recorded so far, one row of ``vertex_bytes / 4`` floats a vertex (read-only)."""
        raw = self.buffer.read(size=self.count * self.vertex_bytes) if self.count else b""
        return np.frombuffer(raw, np.float32).reshape(self.count, self.vertex_bytes // 4)

    def read(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Positions and normals recorded so far: two (count, 3) float32 arrays."""
        data = self.records()
        return data[:, :3].copy(), data[:, 3:6].copy()

    def close(self) -> None:
        release_all(self._temporary)
        self._temporary = None
        prev = self._previous
        if prev is not None and type(prev.mglo).__name__ != "InvalidObject" and context_alive(self._capture.ctx):
            prev.use()

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class FeedbackCapture:
    """The capture output buffer and the 1 × 1 framebuffer of one context."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.out = GrowingBuffer(ctx)
        self._fbo: moderngl.Framebuffer | None = None
        self._color: moderngl.Renderbuffer | None = None

    def framebuffer(self) -> moderngl.Framebuffer:
        if self._fbo is None:
            self._color = self.ctx.renderbuffer((1, 1), 4)
            self._fbo = self.ctx.framebuffer([self._color])
        return self._fbo

    def recording(self, vertices: int, vertex_bytes: int = VERTEX_BYTES) -> Recording:
        """Start a capture of up to ``vertices`` points of ``vertex_bytes`` each (the program's
        varyings, position and normal first); use as a ``with`` block."""
        return Recording(self, vertices, vertex_bytes)

    def points(self, vao: moderngl.VertexArray, vertices: int, instances: int = 1
               ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Capture one draw of ``vertices`` points (× ``instances``): (N, 3) positions, normals."""
        with self.recording(int(vertices) * int(instances)) as rec:
            rec.add(vao, vertices, instances)
            return rec.read()

    def release(self) -> None:
        if self._fbo is not None and context_alive(self.ctx):
            self.ctx.detect_framebuffer(0).use()
        release_all(self._fbo, self._color)
        self._fbo = self._color = None
        self.out.release()
