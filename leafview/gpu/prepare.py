"""The per-leaf prepare pass: ``shaders/leaf_prepare.comp`` fills the derived fields
(``axis``, ``heights`` and, for extended silhouettes, ``sil_axis``, ``sil_heights``,
``sil_tilt``) of LeafData rows from Ω, once per leaf, so the vertex shader does not recompute
them for every vertex (Chaurasia & Beardsley 2017, eqs 2-4). Run it after writing rows and
before drawing them.
"""

from __future__ import annotations

import moderngl

from leafview.gpu.layout import LEAF_BLOCK, LEAVES_BINDING
from leafview.gpu.programs import ProgramCache
from leafview.gpu.shaders import build_compute

__all__ = ["LeafPrepare"]

_LOCAL_SIZE = 64


class LeafPrepare:
    """:meth:`run` prepares ``count`` tightly packed rows of ``buffer`` starting at byte
    ``offset`` (a uniform buffer holding one row works too).

    The compute program comes from ``programs`` (shared, released with the cache) or, without
    one, is compiled here and released by :meth:`release`."""

    def __init__(self, ctx: moderngl.Context, *, programs: ProgramCache | None = None) -> None:
        self.ctx = ctx
        self._owned = programs is None
        self.shader = (build_compute(ctx, "leaf_prepare.comp") if programs is None
                       else programs.compute("leaf_prepare.comp"))

    def run(self, buffer: moderngl.Buffer, count: int, offset: int = 0) -> None:
        if count <= 0:
            return
        buffer.bind_to_storage_buffer(LEAVES_BINDING, offset=offset, size=count * LEAF_BLOCK.nbytes)
        self.shader["count"] = count
        self.shader.run(group_x=-(-count // _LOCAL_SIZE))
        # the rows are read next as uniform blocks, storage buffers or transform-feedback input
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)

    def release(self) -> None:
        """Release the program if this pass compiled it (idempotent)."""
        if self._owned:
            self._owned = False
            self.shader.release()
