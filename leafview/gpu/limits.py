"""Sizes checked before anything is allocated: the context's limits, the caps leafview sets
itself, and an estimate of the memory a request needs against a budget from the machine's memory.

Every renderer calls these helpers first, so a request that cannot fit raises
:class:`~leafview.errors.GpuLimitError` (a :class:`~leafview.errors.ParamError`: the CLI exits 2)
naming the parameter, the limit and the value asked for, and no GL object is created; nothing is
left to ``GL_OUT_OF_MEMORY`` or an incomplete framebuffer. docs/reliability.md ("GPU limits and
faults") lists the limits.

* **Images**: each side at most ``min(GL_MAX_RENDERBUFFER_SIZE, GL_MAX_TEXTURE_SIZE,
  GL_MAX_VIEWPORT_DIMS)``; each attachment (colour or depth, all its samples) at most
  :data:`MAX_RESOURCE_BYTES`.
* **Grids**: at least 2 × 2 samples and at most :data:`MAX_GRID_VERTICES` vertices.
* **Buffers** (grids, captures, leaf rows): at most :data:`MAX_RESOURCE_BYTES` each; leaf rows
  drawn in one storage block at most ``GL_MAX_SHADER_STORAGE_BLOCK_SIZE``.
* **Memory**: what a request allocates in all (GPU objects, and on llvmpipe the GPU *is* host
  memory, plus the host arrays that feed or read them) at most :func:`memory_budget`:
  :data:`MEMORY_FRACTION` of the machine's physical memory, as :mod:`leafview.core.limits` checks
  scenes and leaf sets when they are read.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import moderngl

from leafview.core import limits as core_limits
from leafview.errors import GLContextLost, GpuLimitError

__all__ = ["MAX_RESOURCE_BYTES", "MAX_GRID_VERTICES", "MEMORY_FRACTION", "ContextLimits", "physical_memory",
           "memory_budget", "check_grid", "check_image", "check_buffer", "check_memory", "scene_bytes",
           "SCENE_BYTES_PER_LEAF", "check_scene", "capture_bytes", "ensure_alive", "context_alive", "gib"]

MAX_RESOURCE_BYTES = 1 << 30
"""Largest single GL resource leafview allocates (a buffer, or one attachment with all its
samples): 1 GiB, Mesa llvmpipe's own largest texture (``LP_MAX_TEXTURE_SIZE``), and a size every
desktop driver accepts. A 16384² RGBA8 image fits; the same image with 4 samples does not."""

MAX_GRID_VERTICES = 1 << 22
"""Largest (u, v) grid: 4,194,304 vertices (e.g. 2048 × 2048), 32 MiB of (u, v), 96 MiB of
triangle indices and 96 MiB a leaf when captured."""

MEMORY_FRACTION = core_limits.MEMORY_FRACTION
"""Share of the machine's physical memory one request may allocate in all (the same share as the
scene and leaf-set checks of :mod:`leafview.core.limits`)."""

SCENE_BYTES_PER_LEAF = core_limits.BYTES_PER_LEAF
"""Memory a scene leaf costs, host and GPU together (measured at about 1.3 KB: the 816-byte row on
the GPU, its visible-list entries and species index, the expanded scene's per-leaf arrays and
placement on the host), rounded up: :data:`leafview.core.limits.BYTES_PER_LEAF`."""

_CAPTURE_VERTEX_BYTES = 24


def gib(nbytes: float) -> str:
    """``nbytes`` as a short human size (GiB above 1 GiB, else MiB)."""
    return f"{nbytes / 2**30:.1f} GiB" if nbytes >= 2**30 else f"{nbytes / 2**20:.1f} MiB"


@dataclass(frozen=True)
class ContextLimits:
    """The limits of one context that leafview checks against (from ``ctx.info``)."""

    renderbuffer: int
    texture: int
    viewport: tuple[int, int]
    storage_block: int
    renderer: str

    @classmethod
    def of(cls, ctx: moderngl.Context) -> ContextLimits:
        ensure_alive(ctx, "reading the context's limits")
        info = ctx.info
        vp = info.get("GL_MAX_VIEWPORT_DIMS", (16384, 16384))
        return cls(renderbuffer=int(info.get("GL_MAX_RENDERBUFFER_SIZE", 16384)),
                   texture=int(info.get("GL_MAX_TEXTURE_SIZE", 16384)),
                   viewport=(int(vp[0]), int(vp[1])),
                   storage_block=int(info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE", 1 << 27)),
                   renderer=str(info.get("GL_RENDERER", "")))

    @property
    def max_image(self) -> tuple[int, int]:
        """Largest image (width, height) a framebuffer of this context can have."""
        side = min(self.renderbuffer, self.texture)
        return min(side, self.viewport[0]), min(side, self.viewport[1])


def physical_memory() -> int:
    """Bytes of memory of this machine (:func:`leafview.core.limits.physical_memory`; 0 where the
    system does not say, which turns the memory check off)."""
    return core_limits.physical_memory() or 0


def memory_budget() -> int:
    """Bytes one request may allocate: :data:`MEMORY_FRACTION` of :func:`physical_memory` (no
    limit where the machine's memory is unknown)."""
    total = physical_memory()
    return int(total * MEMORY_FRACTION) if total else 1 << 62


def check_memory(nbytes: int, what: str, detail: str) -> None:
    """Refuse ``detail`` (a request of parameter ``what``) when ``nbytes`` exceed the budget."""
    budget = memory_budget()
    if nbytes > budget:
        raise GpuLimitError(what, f"{detail} needs about {gib(nbytes)}, above the memory budget of "
                                  f"{gib(budget)} ({MEMORY_FRACTION:.0%} of this machine's "
                                  f"{gib(physical_memory())})")


def check_buffer(nbytes: int, what: str, detail: str) -> None:
    """Refuse one buffer of ``nbytes`` above :data:`MAX_RESOURCE_BYTES` (and the memory budget)."""
    if nbytes > MAX_RESOURCE_BYTES:
        raise GpuLimitError(what, f"{detail} needs a {gib(nbytes)} buffer ({nbytes:,} bytes), above the "
                                  f"{gib(MAX_RESOURCE_BYTES)} limit of one GL resource (MAX_RESOURCE_BYTES)")
    check_memory(nbytes, what, detail)


def check_grid(grid: Any, what: str = "grid") -> tuple[int, int]:
    """``(nu, nv)`` as ints, each at least 2, at most :data:`MAX_GRID_VERTICES` vertices."""
    try:
        nu, nv = (int(grid[0]), int(grid[1]))
        if len(grid) != 2 or nu != grid[0] or nv != grid[1]:
            raise ValueError
    except (TypeError, ValueError, IndexError, OverflowError):
        raise GpuLimitError(what, f"must be two whole numbers (nu, nv), got {grid!r}") from None
    if nu < 2 or nv < 2:
        raise GpuLimitError(what, f"{nu}×{nv}: each side needs at least 2 samples")
    if nu * nv > MAX_GRID_VERTICES:
        raise GpuLimitError(what, f"{nu}×{nv} = {nu * nv:,} vertices, above the cap of {MAX_GRID_VERTICES:,} "
                                  f"(MAX_GRID_VERTICES)")
    return nu, nv


def check_image(limits: ContextLimits, size: tuple[int, int], samples: int = 0, *, linear: bool = False,
                what: str = "size", copies: int = 2) -> None:
    """Refuse a ``size`` (w, h) framebuffer with ``samples`` that this context cannot hold:
    sides vs ``GL_MAX_RENDERBUFFER_SIZE``/``GL_MAX_TEXTURE_SIZE``/``GL_MAX_VIEWPORT_DIMS``, each
    attachment vs :data:`MAX_RESOURCE_BYTES`, and the target plus ``copies`` host copies of the
    readback vs the memory budget."""
    w, h = int(size[0]), int(size[1])
    mw, mh = limits.max_image
    if not (1 <= w <= mw and 1 <= h <= mh):
        raise GpuLimitError(what, f"{w}×{h} outside 1..{mw}×{mh}, the largest framebuffer of this context "
                                  f"(GL_MAX_RENDERBUFFER_SIZE = {limits.renderbuffer}, GL_MAX_TEXTURE_SIZE = "
                                  f"{limits.texture}, GL_MAX_VIEWPORT_DIMS = {limits.viewport[0]}×"
                                  f"{limits.viewport[1]})")
    px = 16 if linear else 4
    layers = max(int(samples), 1)
    colour = w * h * px * layers
    if max(colour, w * h * 4 * layers) > MAX_RESOURCE_BYTES:
        hint = "; use fewer samples (samples=0) or a smaller size" if samples else "; use a smaller size"
        raise GpuLimitError(what, f"{w}×{h} {'float32' if linear else 'RGBA8'} with {int(samples)} samples needs "
                                  f"{gib(colour)} for one attachment, above the {gib(MAX_RESOURCE_BYTES)} limit of "
                                  f"one GL resource (MAX_RESOURCE_BYTES){hint}")
    target = w * h * (px + 4) * (1 + (int(samples) if samples else 0))
    check_memory(target + copies * w * h * px, what, f"a {w}×{h} image with {int(samples)} samples")


def scene_bytes(n_leaves: int) -> int:
    """Estimated memory of a scene of ``n_leaves`` leaves, expanded and uploaded."""
    return int(n_leaves) * SCENE_BYTES_PER_LEAF


def check_scene(n_leaves: int, what: str = "scene.leaves") -> None:
    """Refuse a scene whose estimated memory (:func:`scene_bytes`) exceeds the budget: call it
    before building the scene's arrays."""
    check_memory(scene_bytes(n_leaves), what, f"a scene of {int(n_leaves):,} leaves")


def capture_bytes(vertices: int) -> int:
    """Bytes of a transform-feedback capture of ``vertices`` (position and normal a vertex)."""
    return int(vertices) * _CAPTURE_VERTEX_BYTES


def context_alive(ctx: moderngl.Context) -> bool:
    """Whether ``ctx`` has not been released."""
    return type(ctx.mglo).__name__ != "InvalidObject"


def ensure_alive(ctx: moderngl.Context, where: str) -> None:
    """Raise :class:`~leafview.errors.GLContextLost` when ``ctx`` was released."""
    if not context_alive(ctx):
        raise GLContextLost(f"the OpenGL context was released or lost before {where}; "
                            "nothing more was drawn (create a new renderer)")
