"""Offscreen render targets: colour + depth, optionally multisampled with a single-sample resolve
target, and the readback helpers (row 0 at the top, straight alpha).

:class:`RenderTarget` is the framebuffer of every colour image of the package (thumbnails,
atlases, scenes, the viewer's frame, benchmarks); :class:`AovTarget` the single-sample,
multiple-render-target framebuffer of the label pass (:mod:`leafview.gpu.aov`). Each is created in
one place and released in one place.
"""

from __future__ import annotations

from typing import Any, Self

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.gpu.layout import AOV_OUTPUTS
from leafview.gpu.limits import ContextLimits, check_image, check_memory, context_alive

__all__ = ["RenderTarget", "OffscreenTarget", "AovTarget", "FlushTarget", "read_rgba", "unpremultiply"]


def read_rgba(fbo: moderngl.Framebuffer) -> NDArray[np.uint8]:
    """(h, w, 4) uint8, row 0 at the top."""
    w, h = fbo.size
    img = np.frombuffer(fbo.read(components=4), np.uint8).reshape(h, w, 4)
    return np.ascontiguousarray(img[::-1])


def _straight_table() -> NDArray[np.uint8]:
    """(256, 256) uint8: [alpha, premultiplied value] -> straight value, round(v · 255 / alpha)
    clipped to 255, in float32 as :func:`unpremultiply` once computed it per pixel (row 0 unused)."""
    a = np.maximum(np.arange(256, dtype=np.float32), np.float32(1.0))[:, None]
    v = np.arange(256, dtype=np.float32)[None, :]
    return np.clip(v * 255.0 / a + 0.5, 0, 255).astype(np.uint8)


_STRAIGHT = _straight_table()


def unpremultiply(img: NDArray[np.uint8], *, out: NDArray[np.uint8] | None = None) -> NDArray[np.uint8]:
    """Resolved multisampled edges over a transparent clear are premultiplied (colour · coverage);
    8-bit images carry straight alpha, so divide the coverage back out (a table lookup: a
    thumbnail's edge pixels cost a quarter of the float arithmetic's time). ``out``: where to
    write (``img`` itself, C-contiguous, straightens in place); by default a copy when any pixel
    changes, else ``img``."""
    flat = img.reshape(-1, 4)
    alpha = flat[:, 3]
    edge = np.flatnonzero((alpha - np.uint8(1)) < np.uint8(254))   # 0 < alpha < 255: the partly covered pixels
    if out is None:
        if edge.size == 0:
            return img
        out = img.copy()
    elif out is not img:
        out[...] = img
    if edge.size:
        px = flat[edge]
        out.reshape(-1, 4)[edge, :3] = _STRAIGHT[px[:, 3:4], px[:, :3]]
    return out


class _Framebuffers:
    """What every render target shares: the GL objects it owns (released in reverse order, once),
    binding ``fbo`` to draw into, and use as a context manager. ``release()`` first binds
    framebuffer 0: moderngl re-binds the *current* framebuffer after creating a new one, so a
    deleted-but-current framebuffer would make the next ``ctx.framebuffer()`` raise
    GL_INVALID_OPERATION."""

    ctx: moderngl.Context
    fbo: moderngl.Framebuffer
    _objects: list[Any]

    def _own(self, obj: Any) -> Any:
        self._objects.append(obj)
        return obj

    def use(self) -> None:
        """Bind the framebuffer to draw into (its viewport: the whole target)."""
        self.fbo.use()

    def release(self) -> None:
        """Release the framebuffers and attachments (idempotent; safe after the context was released)."""
        if self._objects and context_alive(self.ctx):
            self.ctx.detect_framebuffer(0).use()
        while self._objects:
            self._objects.pop().release()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


class RenderTarget(_Framebuffers):
    """An RGBA (8-bit, or float32 with ``linear``) + depth framebuffer of ``size``; with
    ``samples`` > 0 the draws go to a multisampled framebuffer that :meth:`resolve` copies into
    the single-sample one.

    ``fbo`` is the framebuffer to draw into, ``resolved`` the one to read. ``release()`` first
    binds framebuffer 0: moderngl re-binds the *current* framebuffer after creating a new one,
    so a deleted-but-current framebuffer would make the next ``ctx.framebuffer()`` raise
    GL_INVALID_OPERATION.
    """

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int], samples: int = 0, *,
                 linear: bool = False) -> None:
        self.ctx, self.size = ctx, (int(size[0]), int(size[1]))
        self.samples, self.linear = int(samples), bool(linear)
        dtype = "f4" if linear else "f1"
        self._objects: list[Any] = []
        # sides vs the context's limits, attachment bytes and memory, before any GL object
        check_image(ContextLimits.of(ctx), self.size, self.samples, linear=self.linear, copies=1)
        try:
            color = self._own(ctx.renderbuffer(self.size, 4, dtype=dtype))
            depth = self._own(ctx.depth_renderbuffer(self.size))
            self.resolved: moderngl.Framebuffer = self._own(ctx.framebuffer([color], depth))
            self.fbo: moderngl.Framebuffer = self.resolved
            if self.samples:
                mcolor = self._own(ctx.renderbuffer(self.size, 4, samples=self.samples, dtype=dtype))
                mdepth = self._own(ctx.depth_renderbuffer(self.size, samples=self.samples))
                self.fbo = self._own(ctx.framebuffer([mcolor], mdepth))
        except BaseException:
            self.release()
            raise


    def clear(self, rgba: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)) -> None:
        r, g, b, a = (float(x) for x in rgba)
        self.fbo.clear(r, g, b, a, depth=1.0)

    def resolve(self) -> moderngl.Framebuffer:
        """Copy the multisampled draws into ``resolved`` (nothing to do without samples)."""
        if self.fbo is not self.resolved:
            self.ctx.copy_framebuffer(self.resolved, self.fbo)
        return self.resolved

    def read(self, viewport: tuple[int, int, int, int] | None = None, *, copy: bool = True) -> NDArray[Any]:
        """Resolve and read back: (h, w, 4) uint8 (or float32 if ``linear``), row 0 at the top.
        Colours at multisampled edges over a transparent clear are premultiplied (see
        :func:`unpremultiply`). ``copy=False`` returns a read-only view of the readback (callers
        that cut it into tiles copy only the tiles)."""
        fbo = self.resolve()
        x, y, w, h = viewport if viewport is not None else (0, 0, *self.size)
        dtype, gl_dtype = (np.float32, "f4") if self.linear else (np.uint8, "f1")
        raw = fbo.read(viewport=(x, y, w, h), components=4, dtype=gl_dtype, alignment=1)
        image = np.frombuffer(raw, dtype).reshape(h, w, 4)[::-1]
        return np.ascontiguousarray(image) if copy else image



OffscreenTarget = RenderTarget   # the name the benchmarks and tests know


class FlushTarget(_Framebuffers):
    """A one-pixel framebuffer whose :meth:`flush` hands the draws made so far to the driver
    without waiting for them (moderngl has no ``glFlush``). llvmpipe bins draws on the calling
    thread and shades them on its rasteriser threads only when the batch ends: at a readback, a
    finish, or when another framebuffer is drawn into. A clear of this pixel is such a change:
    the draws so far are queued to the rasteriser threads at once, and the caller bins its next
    draws meanwhile (``render_many``: about half the waiting for the last tile of a 16-leaf atlas
    is gone). Nothing drawn changes: the atlas's pixels are shaded as before, in the same order.
    On a hardware driver it is a one-pixel clear."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self._objects: list[Any] = []
        try:
            colour = self._own(ctx.renderbuffer((1, 1), 4))
            self.fbo: moderngl.Framebuffer = self._own(ctx.framebuffer([colour]))
        except BaseException:
            self.release()
            raise

    def flush(self, back: moderngl.Framebuffer) -> None:
        """Queue the draws made so far, then bind ``back`` again (its viewport and scissor as
        they were)."""
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)
        back.use()


class AovTarget(_Framebuffers):
    """The label pass's framebuffer: one single-sample colour attachment per
    :data:`~leafview.gpu.layout.AOV_OUTPUTS` entry (R32UI instance, R32F depth, RGBA32F normal,
    RG32F uv, at the entry's location) and a depth buffer. No multisampling and no blending, so
    every pixel holds the values of exactly one fragment (the nearest).

    The sides, the largest attachment and the memory (every attachment, the depth buffer and two
    host copies of each readback) are checked against the context's limits before any GL object
    is made. ``release()`` first binds framebuffer 0, as :class:`RenderTarget` does.
    """

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        self.ctx, self.size = ctx, (int(size[0]), int(size[1]))
        w, h = self.size
        # sides and the largest (16-byte RGBA32F) attachment, then the whole target's memory
        check_image(ContextLimits.of(ctx), self.size, 0, linear=True, copies=0)
        per_pixel = sum(o.nbytes for o in AOV_OUTPUTS)
        check_memory(w * h * (3 * per_pixel + 4), "size", f"the {w}×{h} label images (instance, depth, normal, uv)")
        self._objects: list[Any] = []
        try:
            colour = [self._own(ctx.renderbuffer(self.size, o.components, dtype=o.dtype)) for o in AOV_OUTPUTS]
            depth = self._own(ctx.depth_renderbuffer(self.size))
            self.fbo: moderngl.Framebuffer = self._own(ctx.framebuffer(colour, depth))
        except BaseException:
            self.release()
            raise


    def clear(self) -> None:
        """Every attachment to 0 (background), the depth buffer to the far plane."""
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)

    def read(self, name: str) -> NDArray[Any]:
        """The attachment of AOV ``name``: (h, w) for one component, else (h, w, components);
        uint32 or float32 as declared; row 0 at the top."""
        out = next((o for o in AOV_OUTPUTS if o.name == name), None)
        if out is None:
            raise ValueError(f"no label output {name!r} (the outputs are {', '.join(o.name for o in AOV_OUTPUTS)})")
        w, h = self.size
        raw = self.fbo.read(attachment=out.location, components=out.components, dtype=out.dtype, alignment=1)
        image = np.frombuffer(raw, np.dtype(f"<{out.dtype}")).reshape(h, w, out.components)[::-1]
        return np.ascontiguousarray(image[..., 0] if out.components == 1 else image)

