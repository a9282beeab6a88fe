"""Vein fields on the GPU: ``shaders/vein_field.comp`` turns each species' vein segments into its
vein field (:mod:`leafview.botany.vein_field`: distance to the nearest vein, its order and width,
distance to the nearest vein of order ≤ 2), one layer of an RGBA32F array texture per distinct
(shape, venation) key, all new layers in one dispatch.

:class:`VeinFields` owns the field array and the vein-shape grid array
(:func:`leafview.botany.vein_shape.vein_grid`, one layer per key as well, at the same index), and
assigns layers: a key keeps its layer while some leaf of an :meth:`~VeinFields.update` has it, a
layer whose key no leaf has any more is reused, and only keys not yet in the array are computed.
A scene therefore computes each species once, and an edit in the viewer computes one field.

What the CPU does per new species: the vein segments (:func:`leafview.botany.venation.vein_segments`),
the half-width table, the segment records (mapped to vein space) and the tile boxes, packed and
uploaded (about 0.5 ms). The segments are binned into the tiles on the GPU, in four stages of
``vein_field.comp`` (each tile's bound, each row's reach, each tile's list, then the field, one
work group a tile, an invocation a tile row of 8 texels): nothing per texel or per tile runs in
Python. The results go from the shader's storage buffer into the texture layers by a
buffer-to-texture copy on the GPU. About 3 ms of one llvmpipe core for a preset's field at 256²
(``leafview bench veins``).

The layers are RGBA32F as the shading reads them. RGBA16F would halve the memory (0.5 MiB a
layer) at an error of at most 2.4e-5 leaf lengths in the distances (11-bit mantissa at the cap,
0.05), well below a texel; it would need the field stage to write packed halves.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from typing import Any

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.botany.vein_field import (
    BOUND_REACH,
    FIELD_CAP,
    FIELD_SIZE,
    HALFWIDTH_SAMPLES,
    TILE,
    check_field_size,
    halfwidth_table,
    segment_records,
    tile_geometry,
    vein_key,
    vein_keys,
    vein_layers,
)
from leafview.botany.vein_shape import GRID_N, vein_grid
from leafview.botany.venation import vein_segments
from leafview.core.params import LeafParams
from leafview.errors import GpuLimitError
from leafview.gpu.layout import (
    VEIN_FIELD_UNIT,
    VEIN_GRID_UNIT,
    VEIN_SEGMENTS_BINDING,
    VEIN_TEXELS_BINDING,
    VEIN_TILES_BINDING,
)
from leafview.gpu.limits import check_buffer, ensure_alive, gib
from leafview.gpu.owner import GLObjects, GrowingBuffer, next_pow2
from leafview.gpu.programs import ProgramCache
from leafview.gpu.shaders import build_compute

__all__ = ["VeinFields", "LIST_START", "JOBS_PER_DISPATCH", "vein_field_defines", "tile_words", "pack_jobs",
           "vein_keys", "vein_layers"]

LIST_START = 64
"""Room for each tile's segment list at first (of the built-in presets, the longest list is 53:
maize's); a dispatch whose lists need more grows the room to the next power of two and lists
again."""
JOBS_PER_DISPATCH = 16
"""Fields computed by one dispatch at most (each holds a texel buffer and tile lists meanwhile)."""

_TEXEL_BYTES = 16   # RGBA32F
_GROUP = 64         # segments per work group of the bound and list stages
_STAGES = ("bound", "reach", "list", "field")   # VEIN_FIELD_STAGE 0-3 of vein_field.comp


def vein_field_defines(stage: int) -> dict[str, object]:
    """The compile-time constants of stage ``stage`` (0 bound, 1 reach, 2 list, 3 field) of
    ``vein_field.comp`` (sizes from :mod:`leafview.botany.vein_field`)."""
    return {"VEIN_FIELD_STAGE": stage, "VEIN_FIELD_TILE": TILE, "VEIN_FIELD_HALFWIDTH": HALFWIDTH_SAMPLES,
            "VEIN_FIELD_CAP": repr(float(FIELD_CAP)), "VEIN_FIELD_REACH": repr(float(BOUND_REACH)),
            "VEIN_FIELD_GROUP": _GROUP}


def tile_words(size: int) -> int:
    """uint words of one job's tile data in the VeinTiles buffer (its lists apart): bounds, counts
    and row reaches."""
    n = size // TILE
    return 3 * n * n + 2 * n


def pack_jobs(jobs: Sequence[tuple[NDArray[np.float32], NDArray[np.float32]]], size: int,
              capacity: int) -> NDArray[np.float32]:
    """The VeinSegments buffer of a dispatch (``vein_field.comp``) for ``jobs``, each a (half-width
    table, segment records) pair: job k's tile data from word k · :func:`tile_words` of VeinTiles,
    its lists (``capacity`` words a tile) after all jobs' tile data, its texels from k · size²."""
    tiles = (size // TILE) ** 2
    parts: list[NDArray[np.float32]] = []
    at = 2 * len(jobs)
    header = np.zeros((2 * len(jobs), 4), np.uint32)
    for k, (table, rec) in enumerate(jobs):
        geo = tile_geometry(table, size)
        tab = np.asarray(table, np.float32).reshape(-1, 4)
        rows_at = at + len(tab)
        boxes_at = rows_at + len(geo.rows)
        records_at = boxes_at + len(geo.boxes)
        header[2 * k] = (at, rows_at, boxes_at, records_at)
        header[2 * k + 1] = (len(rec), k * tile_words(size), (len(jobs) * tile_words(size) + k * tiles * capacity),
                             k * size * size)
        parts += [tab, geo.rows, geo.boxes, np.asarray(rec, np.float32).reshape(-1, 4)]
        at = records_at + 2 * len(rec)
    return np.concatenate([header.view(np.float32)] + parts)


class VeinFields:
    """The vein fields (:attr:`field`) and vein-shape grids (:attr:`grid`) of a draw's leaves, one
    layer per distinct key; :attr:`layers` the layer of each leaf of the last :meth:`update`
    (-1 without veins; ``pack_leaves(..., vein_layers=fields.layers)``), :attr:`keys` the key of
    each layer (None: free).

    ``programs``: a shared program cache (else the compute shader is built and owned here);
    ``size``: texels per side of a field (:func:`~leafview.botany.vein_field.check_field_size`)."""

    def __init__(self, ctx: moderngl.Context, *, size: int = FIELD_SIZE, programs: ProgramCache | None = None) -> None:
        self.ctx, self.size = ctx, check_field_size(size)
        max_side = int(ctx.info.get("GL_MAX_TEXTURE_SIZE", 2048))
        if self.size > max_side:
            raise GpuLimitError("size", f"{self.size} texels: this context's textures are at most {max_side} a side")
        self.max_layers = int(ctx.info.get("GL_MAX_ARRAY_TEXTURE_LAYERS", 256))
        self._owns_shader = programs is None
        self.shaders = [build_compute(ctx, "vein_field.comp", defines=vein_field_defines(stage)) if programs is None
                        else programs.compute("vein_field.comp", defines=vein_field_defines(stage))
                        for stage in range(len(_STAGES))]
        for shader in self.shaders:
            shader["field_size"] = self.size
        self._segments = GrowingBuffer(ctx)
        self._tiles = GrowingBuffer(ctx)
        self._texels = GrowingBuffer(ctx)
        self._textures = GLObjects()
        self.field: moderngl.TextureArray | None = None
        self.grid: moderngl.TextureArray | None = None
        self.keys: list[Hashable | None] = []
        self._shaded: set[Hashable] = set()   # keys whose shading field is computed (see update)
        self.layers = np.zeros(0, np.int32)
        self.computed = 0     # fields computed so far (tests, benchmarks)
        self.list_capacity = LIST_START
        self._allocate(1)

    @classmethod
    def build(cls, ctx: moderngl.Context, leaves: Sequence[LeafParams], *, size: int = FIELD_SIZE,
              programs: ProgramCache | None = None) -> VeinFields:
        """The fields of ``leaves``, each distinct key computed once."""
        fields = cls(ctx, size=size, programs=programs)
        try:
            fields.update(leaves)
        except BaseException:
            fields.release()
            raise
        return fields

    def __enter__(self) -> VeinFields:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    @property
    def capacity(self) -> int:
        return 0 if self.field is None else int(self.field.layers)

    def update(self, leaves: Sequence[LeafParams], *, shading: bool = True) -> int:
        """Make the arrays hold the keys of ``leaves`` and set :attr:`layers`; returns the number
        of fields computed (keys not already held, and held keys whose field was left out).
        ``shading=False``: the vein grids only (what the vertex shader reads: geometry capture),
        the shading fields left for a later update that asks for them."""
        leaves = list(leaves)
        wanted = vein_keys(leaves)
        held = {key: i for i, key in enumerate(self.keys) if key is not None}
        keep = set(wanted)
        keys: list[Hashable | None] = [key if key in keep else None for key in self.keys]
        new = [key for key in wanted if key not in held]
        if len(new) > keys.count(None) + self.capacity - len(keys):
            self._allocate(len(wanted))          # a larger array: every field again
            keys, new, held = [], list(wanted), {}
        free = [i for i, key in enumerate(keys) if key is None]
        jobs: list[tuple[int, LeafParams]] = []
        first_leaf = {vein_key(p): p for p in reversed(leaves)}
        for key in new:
            layer = free.pop(0) if free else len(keys)
            if layer == len(keys):
                keys.append(key)
            keys[layer] = key
            jobs.append((layer, first_leaf[key]))
        # held keys whose field a geometry-only update left out
        late = [(held[key], first_leaf[key]) for key in dict.fromkeys(wanted)
                if shading and key in held and key not in self._shaded]
        try:
            self._compute(jobs, jobs + late if shading else [])
        except BaseException:   # (a fold refused by vein_grid): the layers written to hold nothing
            spoilt = {layer for layer, _ in jobs}
            self.keys = [None if i in spoilt else key for i, key in enumerate(self.keys)]
            self._shaded &= {key for key in self.keys if key is not None}
            raise
        self.keys = keys
        self._shaded = {key for key in keys if key is not None and (key in self._shaded or shading)}
        self.layers = vein_layers(leaves, keys)
        return len(jobs) + len(late) if shading else 0

    def reserve(self, layers: int) -> None:
        """At least ``layers`` layers in the arrays; a larger array starts empty (every key is
        computed again by the next :meth:`update`)."""
        if layers > self.capacity:
            self._allocate(layers)

    def _allocate(self, layers: int) -> None:
        n = next_pow2(max(layers, 1))
        if n > self.max_layers and layers <= self.max_layers:
            n = self.max_layers
        if n > self.max_layers:
            raise GpuLimitError("leaves", f"{layers} distinct venations: this context's array textures hold at "
                                          f"most {self.max_layers} layers")
        # the field array is the largest resource: at most MAX_RESOURCE_BYTES, within the memory budget
        check_buffer(n * self.size * self.size * _TEXEL_BYTES, "leaves", f"{n} vein field layers of {self.size}²")
        self._textures.release()
        self.field = self.grid = None
        self._shaded = set()
        field = self._textures.own(self.ctx.texture_array((self.size, self.size, n), 4, dtype="f4"))
        grid = self._textures.own(self.ctx.texture_array((GRID_N, GRID_N, n), 4, dtype="f4"))
        for tex in (field, grid):
            tex.repeat_x = tex.repeat_y = False
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.field, self.grid = field, grid
        self.keys = []

    def _compute(self, grids: Sequence[tuple[int, LeafParams]], fields: Sequence[tuple[int, LeafParams]]) -> None:
        """The grid of each (layer, leaf) of ``grids`` and the field of each of ``fields`` into its
        layer."""
        assert self.grid is not None
        for layer, params in grids:
            grid = np.ascontiguousarray(vein_grid(params, GRID_N, GRID_N), np.float32)
            self.grid.write(grid.tobytes(), viewport=(0, 0, layer, GRID_N, GRID_N, 1))
        prepared = []
        for layer, params in fields:
            seg = vein_segments(params)
            table = halfwidth_table(params)
            prepared.append((layer, table, segment_records(seg.uv0, seg.uv1, seg.order, seg.width, table)))
        self.compute(prepared)

    def compute(self, jobs: Sequence[tuple[int, NDArray[np.float32], NDArray[np.float32]]]) -> None:
        """Compute the fields of ``jobs``, each (layer, half-width table, segment records of
        :func:`~leafview.botany.vein_field.segment_records`), into those layers of :attr:`field`
        (at most :data:`JOBS_PER_DISPATCH` a dispatch)."""
        for start in range(0, len(jobs), JOBS_PER_DISPATCH):
            self._dispatch(jobs[start:start + JOBS_PER_DISPATCH])

    def _dispatch(self, jobs: Sequence[tuple[int, NDArray[np.float32], NDArray[np.float32]]]) -> None:
        if not jobs:
            return
        assert self.field is not None
        if any(not 0 <= layer < self.capacity for layer, _, _ in jobs):
            raise IndexError(f"layers {[layer for layer, _, _ in jobs]} of an array of {self.capacity}")
        ensure_alive(self.ctx, "computing vein fields")
        data = [(table, rec) for _, table, rec in jobs]
        n = len(jobs)
        texel_bytes = self.size * self.size * _TEXEL_BYTES
        words, tiles_n, groups = tile_words(self.size), (self.size // TILE) ** 2, self.size // TILE
        check_buffer(n * texel_bytes, "leaves", f"{n} vein fields of {self.size}²")
        start = np.zeros(words, np.uint32)
        start[:2 * tiles_n] = np.float32(FIELD_CAP).view(np.uint32)   # bounds; counts 0
        tiles = self._tiles.ensure(4 * n * (words + tiles_n * self.list_capacity))
        tiles.write(np.tile(start, n))
        tiles.bind_to_storage_buffer(VEIN_TILES_BINDING)
        self._segments.write(pack_jobs(data, self.size, self.list_capacity)).bind_to_storage_buffer(VEIN_SEGMENTS_BINDING)
        out = self._texels.ensure(n * texel_bytes)
        out.bind_to_storage_buffer(VEIN_TEXELS_BINDING)
        most = max(len(rec) for _, rec in data)
        bound, reach, listing, fill = self.shaders
        if most:
            bound.run(group_x=-(-most // _GROUP), group_y=1, group_z=n)
            self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
            reach.run(group_x=-(-groups // _GROUP), group_y=1, group_z=n)
            self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
            for attempt in range(2):
                listing["list_capacity"] = self.list_capacity
                listing.run(group_x=-(-most // _GROUP), group_y=1, group_z=n)
                self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)
                head = np.frombuffer(tiles.read(size=4 * n * words), np.uint32).reshape(n, words).copy()
                longest = int(head[:, 2 * tiles_n:3 * tiles_n].max())
                if longest <= self.list_capacity:
                    break
                # more room for the lists, and list again (the bounds and reaches stand)
                assert attempt == 0
                self.list_capacity = next_pow2(longest)
                tiles = self._tiles.ensure(4 * n * (words + tiles_n * self.list_capacity))
                head[:, 2 * tiles_n:3 * tiles_n] = 0
                tiles.write(head)
                tiles.bind_to_storage_buffer(VEIN_TILES_BINDING)
                self._segments.write(pack_jobs(data, self.size, self.list_capacity)).bind_to_storage_buffer(
                    VEIN_SEGMENTS_BINDING)
        fill["list_capacity"] = self.list_capacity
        fill.run(group_x=groups, group_y=groups, group_z=n)
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)
        # into the layers, a run of consecutive layers at a time: the first run straight from the
        # texel buffer, the others through a copy to the start of a staging buffer
        runs: list[list[int]] = []
        for k, (layer, _, _) in enumerate(jobs):
            if runs and jobs[runs[-1][-1]][0] + 1 == layer:
                runs[-1].append(k)
            else:
                runs.append([k])
        staging: moderngl.Buffer | None = None
        try:
            for run in runs:
                src = out
                if run[0]:
                    staging = staging or self.ctx.buffer(reserve=len(jobs) * texel_bytes)
                    self.ctx.copy_buffer(staging, out, len(run) * texel_bytes, read_offset=run[0] * texel_bytes)
                    src = staging
                self.field.write(src, viewport=(0, 0, jobs[run[0]][0], self.size, self.size, len(run)))
        finally:
            if staging is not None:
                staging.release()
        self.computed += n

    def use(self) -> None:
        """Bind :attr:`field` at ``VEIN_FIELD_UNIT`` and :attr:`grid` at ``VEIN_GRID_UNIT``."""
        if self.field is not None and self.grid is not None:
            self.field.use(location=VEIN_FIELD_UNIT)
            self.grid.use(location=VEIN_GRID_UNIT)

    def read(self, layer: int) -> NDArray[np.float32]:
        """Layer ``layer`` of the field array, (size, size, 4) float32 [row j, column i] (tests)."""
        assert self.field is not None
        if not 0 <= layer < self.capacity:
            raise IndexError(f"layer {layer} of {self.capacity}")
        raw = np.frombuffer(self.field.read(), np.float32)
        return raw.reshape(self.capacity, self.size, self.size, 4)[layer].copy()

    def describe(self) -> dict[str, Any]:
        """Layers in use and allocated, field size and bytes, for logs and benchmarks."""
        used = sum(key is not None for key in self.keys)
        nbytes = self.capacity * (self.size * self.size + GRID_N * GRID_N) * _TEXEL_BYTES
        return {"layers": used, "capacity": self.capacity, "size": self.size, "bytes": nbytes, "readable": gib(nbytes)}

    def release(self) -> None:
        if self._owns_shader:
            for shader in self.shaders:
                shader.release()
        self._owns_shader = False
        self.shaders = []
        self._textures.release()
        self.field = self.grid = None
        self._segments.release()
        self._tiles.release()
        self._texels.release()
        self.keys = []
        self.layers = np.zeros(0, np.int32)
