"""The GPU resources every renderer shares: programs, the prepare pass, (u, v) grids with one
vertex array per program, render targets and the transform-feedback capture.

:class:`GpuResources` holds one set of them for a context. Renderers (:class:`~leafview.gpu.
renderer.LeafRenderer`, :class:`~leafview.gpu.instanced.InstancedLeaves`,
:class:`~leafview.gpu.scene.SceneRenderer`) take one with ``resources=``, or create and own a
private set when given none; whoever created a set releases it (``release()`` or ``with``).

What a renderer owns itself is only what differs between draws: its leaf rows, its Frame block,
its jitter rows (:class:`JitterTable`) and its ripple signal rows
(:class:`~leafview.gpu.ripple.RipplePass`, whose synthesis program comes from the shared cache).
Those hold data of one draw, so sharing them would mean re-uploading them before every frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import moderngl
import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.params import Jitter
from leafview.deform.fbm import RIPPLE_SAMPLES
from leafview.deform.surface import JITTER_TABLE_SIZE, grid_indices, grid_uv, jitter_table
from leafview.errors import GpuLimitError
from leafview.gpu.capture import FeedbackCapture
from leafview.gpu.layout import JITTER_UNIT, LEAF_BLOCK, ROWS_UNIT, Block, attribute_format, row_texture_size
from leafview.gpu.limits import check_grid
from leafview.gpu.owner import GLObjects, ReleasingLRU, next_pow2
from leafview.gpu.prepare import LeafPrepare
from leafview.gpu.programs import ProgramCache
from leafview.gpu.ripple import RipplePass
from leafview.gpu.targets import RenderTarget

__all__ = ["GpuResources", "Grid", "JitterTable", "RowTexture", "LEAF_SPACE_VARYINGS", "WORLD_VARYINGS",
           "record_vertex_array"]

LEAF_SPACE_VARYINGS = ("v_object", "v_object_normal")   # captures in leaf space (tests, export)
WORLD_VARYINGS = ("v_world", "v_normal")                 # captures in world space (baking)
_MAX_GRIDS = 8          # (nu, nv) grids kept
_MAX_GRID_VAOS = 16     # vertex arrays per grid (one or two per program variant)
_MAX_TARGETS = 3        # render targets kept


class Grid:
    """The (nu × nv) (u, v) grid of :func:`leafview.deform.surface.grid_uv` on the GPU: one vertex
    buffer, one index buffer, and a vertex array per program (like moderngl-window's
    ``VAO.instance(program)``), made on first use. Vertex arrays are looked up at each use and
    not kept by callers: an evicted grid releases them."""

    def __init__(self, ctx: moderngl.Context, nu: int, nv: int) -> None:
        self.nu, self.nv = check_grid((nu, nv))   # before grid_uv allocates anything
        self.ctx = ctx
        self.vertices = self.nu * self.nv
        self._objects = GLObjects()
        try:
            self.vbo = self._objects.own(ctx.buffer(grid_uv(self.nu, self.nv).tobytes()))
            self.ibo = self._objects.own(ctx.buffer(grid_indices(self.nu, self.nv).tobytes()))
        except BaseException:
            self._objects.release()
            raise
        self._vaos: ReleasingLRU[moderngl.VertexArray] = ReleasingLRU(_MAX_GRID_VAOS)

    @property
    def triangles(self) -> int:
        return 2 * (self.nu - 1) * (self.nv - 1)

    def vao(self, program: moderngl.Program) -> moderngl.VertexArray:
        """Indexed triangles of the grid for ``program`` (attribute ``in_uv``)."""
        return self._vaos.get((program.glo, True), lambda: self.ctx.vertex_array(
            program, [(self.vbo, "2f", "in_uv")], index_buffer=self.ibo, index_element_size=4))

    def points(self, program: moderngl.Program) -> moderngl.VertexArray:
        """Every grid vertex once, in grid order, for ``program`` (transform-feedback capture)."""
        return self._vaos.get((program.glo, False), lambda: self.ctx.vertex_array(
            program, [(self.vbo, "2f", "in_uv")]))

    def release(self) -> None:
        self._vaos.release()
        self._objects.release()


def record_vertex_array(ctx: moderngl.Context, program: moderngl.Program, uv: moderngl.Buffer,
                        records: moderngl.Buffer, block: Block,
                        index_buffer: moderngl.Buffer | None = None) -> moderngl.VertexArray:
    """A vertex array of ``leaf.vert`` built with ``LEAF_INSTANCED`` or ``LEAF_INDIRECT``: ``in_uv``
    per vertex from ``uv`` and the leaf record's attributes
    (:data:`~leafview.gpu.layout.LEAF_ATTRIBUTES`) per instance from ``records``, a buffer of
    ``block`` rows (the leaves' storage buffer read in place, or a scene's compact vertex records;
    see :func:`~leafview.gpu.layout.attribute_format`). With ``index_buffer``: indexed triangles
    (32-bit indices); without: every vertex once (transform-feedback capture)."""
    fmt, names = attribute_format(block, present=frozenset(program))
    content = [(uv, "2f", "in_uv"), (records, fmt, *names)]
    if index_buffer is None:
        return ctx.vertex_array(program, content)
    return ctx.vertex_array(program, content, index_buffer=index_buffer, index_element_size=4)


class RowTexture:
    """``count`` LeafData rows of ``rows`` (a buffer, after the prepare pass) as an RGBA32F texture,
    texel for texel (:func:`~leafview.gpu.layout.row_texture_size`): what ``leaf.vert``'s ripple,
    bend and extended-silhouette branches read (``LEAF_ROW_TEXTURE``), at texture unit
    ``ROWS_UNIT``. The copy stays on the GPU (through a buffer padded to whole texture lines)."""

    def __init__(self, ctx: moderngl.Context, rows: moderngl.Buffer, count: int) -> None:
        width, height = row_texture_size(count)
        limit = int(ctx.info["GL_MAX_TEXTURE_SIZE"])
        if max(width, height) > limit:
            raise GpuLimitError("leaves", f"{count:,} leaf rows need a {width}×{height} texture, above this "
                                f"driver's GL_MAX_TEXTURE_SIZE = {limit}")
        self.texture = ctx.texture((width, height), 4, dtype="f4")
        try:
            self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            padded = ctx.buffer(reserve=width * height * 16)
            try:
                ctx.copy_buffer(padded, rows, size=min(int(count), rows.size // LEAF_BLOCK.nbytes) * LEAF_BLOCK.nbytes)
                self.texture.write(padded)
            finally:
                padded.release()
        except BaseException:
            self.texture.release()
            raise

    def use(self) -> None:
        self.texture.use(location=ROWS_UNIT)

    def release(self) -> None:
        self.texture.release()


class JitterTable:
    """The jitter texture of Chaurasia & Beardsley 2017, sec. 6: one row of
    :data:`JITTER_TABLE_SIZE` values per seed (moderngl has no 1D textures), read with
    ``texelFetch`` by ``leaf.vert`` at texture unit ``JITTER_UNIT``."""

    def __init__(self, ctx: moderngl.Context, tables: ArrayLike | None = None) -> None:
        self.ctx = ctx
        rows = (np.zeros((1, JITTER_TABLE_SIZE), np.float32) if tables is None
                else np.ascontiguousarray(np.atleast_2d(np.asarray(tables, np.float32))))
        self.texture = self._make(rows.shape[1], rows.shape[0], rows.tobytes())
        self._seed: int | None = None
        self._rows: bytes | None = None   # what the last upload() wrote (the same tables again write nothing)

    def _make(self, width: int, height: int, data: bytes | None = None) -> moderngl.Texture:
        tex = self.ctx.texture((width, height), 1, data, dtype="f4")
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        return tex

    def set_seed(self, jitter: Jitter) -> int:
        """Make row 0 hold ``jitter``'s table (only when its seed changed); returns bytes written."""
        if self._seed == jitter.seed:
            return 0
        table = jitter_table(jitter)
        self.texture.write(table.tobytes(), viewport=(0, 0, JITTER_TABLE_SIZE, 1))
        self._seed = jitter.seed
        self._rows = None
        return int(table.nbytes)

    def upload(self, tables: NDArray[np.float32]) -> int:
        """Make the texture hold ``tables`` (one row per seed of a batch, as
        :func:`~leafview.gpu.layout.pack_leaves` returns them); returns bytes written. One row of
        zeros (no leaf has jitter on, so nothing reads the texture) writes nothing."""
        rows = int(tables.shape[0])
        if rows == 1 and not tables.any():
            return 0
        data = np.ascontiguousarray(tables, dtype=np.float32).tobytes()
        if data == self._rows:   # the texture holds these rows already (one render() after another)
            return 0
        if self.texture.height < rows:
            self.texture.release()
            self.texture = self._make(JITTER_TABLE_SIZE, next_pow2(rows))
        self.texture.write(data, viewport=(0, 0, JITTER_TABLE_SIZE, rows))
        self._seed = None  # row 0 no longer holds a single leaf's seed
        self._rows = data
        return len(data)

    def use(self) -> None:
        self.texture.use(location=JITTER_UNIT)

    def release(self) -> None:
        self.texture.release()


class GpuResources:
    """One set of shared GPU resources for ``ctx`` (see the module docstring).

    Attributes
    ----------
    programs: every program and compute shader, compiled once (:class:`ProgramCache`).
    prepare: the per-leaf prepare pass (:class:`~leafview.gpu.prepare.LeafPrepare`).
    capture: transform-feedback capture (:class:`~leafview.gpu.capture.FeedbackCapture`).
    """

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.programs = ProgramCache(ctx)
        self._grids: ReleasingLRU[Grid] = ReleasingLRU(_MAX_GRIDS)
        self._targets: ReleasingLRU[RenderTarget] = ReleasingLRU(_MAX_TARGETS)
        self.capture = FeedbackCapture(ctx)
        try:
            self.prepare = LeafPrepare(ctx, programs=self.programs)
        except BaseException:
            self.release()
            raise

    def leaf_program(self, defines: Mapping[str, object] | None = None, *,
                     varyings: Sequence[str] = LEAF_SPACE_VARYINGS) -> moderngl.Program:
        """``leaf.vert`` + ``leaf.frag`` for a feature set (``LEAF_INSTANCED``/``LEAF_INDIRECT``
        and :func:`~leafview.gpu.layout.feature_defines`), capturing ``varyings``."""
        return self.programs.program("leaf.vert", "leaf.frag", defines=defines, varyings=varyings)

    def baked_program(self) -> moderngl.Program:
        """``leaf_baked.vert`` + ``leaf.frag``: pre-baked world-space vertices."""
        return self.programs.program("leaf_baked.vert", "leaf.frag")

    def ripple_pass(self, n: int = RIPPLE_SAMPLES) -> RipplePass:
        """A new signal buffer with the shared synthesis program; the caller owns (releases) it."""
        return RipplePass(self.ctx, n, programs=self.programs)

    def grid(self, nu: int, nv: int) -> Grid:
        """The (nu × nv) grid (cached, at most a few kept)."""
        nu, nv = check_grid((nu, nv))
        return self._grids.get((nu, nv), lambda: Grid(self.ctx, nu, nv))

    def target(self, size: tuple[int, int], samples: int = 0, *, linear: bool = False) -> RenderTarget:
        """A render target (cached by size, samples and format; at most a few kept). Use it at
        once: the next request may evict it."""
        key = (int(size[0]), int(size[1]), int(samples), bool(linear))
        return self._targets.get(key, lambda: RenderTarget(self.ctx, size, samples, linear=linear))

    def release(self) -> None:
        """Release everything (idempotent)."""
        self._targets.release()
        self._grids.release()
        self.capture.release()
        self.programs.release()   # the prepare pass's program is one of them

    def __enter__(self) -> GpuResources:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
