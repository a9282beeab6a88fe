"""Scene-wide edits on the GPU: after :mod:`leafview.scene.scene_edits` changed some leaves'
factors and offsets, :func:`update_rows` rewrites those leaves' storage-buffer rows in place, one
``buffer.write`` per batch touched, and reruns the prepare pass on them, so the derived members
(axis, heights, Chaurasia & Beardsley 2017, eqs 2-4) follow. Nothing is rebuilt: the renderer's
programs, tables, textures and other rows stay as they are.

Per batch, one upload, in one of two ways:

* *span* (the changed leaves are dense: their span is at most :data:`SPAN_SLACK` times their
  number, or at most :data:`SPAN_ROWS` rows): the rows from the first to the last changed leaf of
  the batch (the first rounded down to a storage-buffer offset alignment) are packed again and
  written in place with one ``buffer.write(offset=...)``; the unchanged rows between are packed
  from the same arrays, so they get the bytes they held;
* *staged* (sparse: a few leaves far apart, e.g. a selection across a large batch): only the
  changed rows are packed (:func:`pack_leaves`: ``pack_scene`` of the scene's rows taken at those
  indices), written to a staging buffer made for the call (and released after it) with one
  ``buffer.write``, prepared there, and copied into place on the GPU, one ``copy_buffer`` per run
  of consecutive leaves.

Culling: the species' bounding spheres (:func:`leafview.gpu.scene.cull_rows_from_points`) hold
leaves whose factors lie within ``1 ± variation``. An edit can move a leaf beyond that (a width
factor of 2, an offset), so :func:`grow_spheres` widens the spheres of the species edited by the
same bound: a leaf point is a convex combination of Ω's control points (linear in Ω), so a
factor of ``1 ± d`` moves it by at most ``d · M`` (``M`` the species' largest point distance,
at most ``|centre| + radius``) and an offset of at most ``o`` per coordinate by ``√3 · o ·
max(1, M)`` (a v̄ offset moves a foot along an axis at most ``M`` long). The radius only grows
(one write of the species' culling rows, only when it does), and the level-of-detail errors are
scaled by ``(1 + 2d) / (1 + 2 · variation)`` like the variation's.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import fields, replace
from typing import Any

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.gpu.layout import LEAF_BLOCK, ROW_TEXELS, ROWS_PER_LINE
from leafview.gpu.limits import ensure_alive
from leafview.gpu.scene import SceneRenderer, pack_scene
from leafview.scene.spec import Scene

__all__ = ["update_rows", "grow_spheres", "pack_leaves", "SSBO_ALIGNMENT", "SPAN_SLACK", "SPAN_ROWS"]

SPAN_SLACK = 4         # a span this many times the changed leaves (or fewer rows) is written whole
SPAN_ROWS = 4096

SSBO_ALIGNMENT = 256
"""Bytes a storage-buffer binding offset is aligned to: the largest value OpenGL allows for
``GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT`` (moderngl does not report it), so any driver's holds."""
_ALIGN_ROWS = SSBO_ALIGNMENT // int(np.gcd(SSBO_ALIGNMENT, LEAF_BLOCK.nbytes))   # rows per aligned offset

# the culling rows each renderer started with (the spheres grow from these, never shrink)
_BASE_CULL: weakref.WeakKeyDictionary[SceneRenderer, NDArray[Any]] = weakref.WeakKeyDictionary()


def pack_leaves(scene: Scene, leaves: NDArray[np.int64], species_records: NDArray[Any]) -> NDArray[Any]:
    """LEAF_BLOCK rows of the given leaves (any order): :func:`~leafview.gpu.scene.pack_scene` of a
    scene whose per-leaf arrays are the scene's taken at ``leaves`` (every array field whose first
    axis has one entry per leaf, so the rows hold whatever the packer writes)."""
    n = len(scene)
    changes: dict[str, Any] = {f.name: value[leaves] for f in fields(scene)
                               if isinstance(value := getattr(scene, f.name), np.ndarray)
                               and value.shape[:1] == (n,)}
    return pack_scene(replace(scene, **changes), 0, len(leaves), species_records)


def _staged(renderer: SceneRenderer, batch: Any, mine: NDArray[np.int64]) -> None:
    """Rows ``mine`` (batch-local, sorted) packed alone, written to a staging buffer made for the
    call, prepared there and copied into place, one ``copy_buffer`` per run of consecutive leaves."""
    nbytes = LEAF_BLOCK.nbytes
    rows = pack_leaves(renderer.scene, mine + batch.start, renderer.species_records)
    staging = renderer.ctx.buffer(reserve=rows.nbytes)
    try:
        staging.write(rows)
        renderer.resources.prepare.run(staging, mine.size)
        breaks = np.flatnonzero(np.diff(mine) != 1) + 1
        for first, last in zip(np.r_[0, breaks], np.r_[breaks, mine.size]):
            renderer.ctx.copy_buffer(batch.rows, staging, size=int(last - first) * nbytes,
                                     read_offset=int(first) * nbytes, write_offset=int(mine[first]) * nbytes)
        renderer.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)
    finally:
        staging.release()


def update_rows(renderer: SceneRenderer, leaves: Sequence[int] | NDArray[np.integer[Any]]) -> int:
    """Rewrite the rows of ``leaves`` (scene indices) from ``renderer.scene``'s arrays, run the
    prepare pass on them and refresh the row texture where the batch has one; widen the culling
    spheres when the edit asks for it (:func:`grow_spheres`). Returns the number of uploads: one
    ``buffer.write`` per batch touched, to its rows or to the staging buffer (module docstring)."""
    ids = np.unique(np.asarray(leaves, np.int64).reshape(-1))
    if not ids.size:
        return 0
    n = len(renderer.scene)
    if ids[0] < 0 or ids[-1] >= n:
        raise IndexError(f"leaf index out of range 0..{n - 1}")
    ensure_alive(renderer.ctx, "updating edited leaf rows")
    writes = 0
    nbytes = LEAF_BLOCK.nbytes
    for batch in renderer.batches:
        mine = ids[(ids >= batch.start) & (ids < batch.start + batch.count)] - batch.start
        if not mine.size:
            continue
        lo = int(mine[0]) // _ALIGN_ROWS * _ALIGN_ROWS
        hi = int(mine[-1]) + 1
        if hi - lo <= max(SPAN_SLACK * mine.size, SPAN_ROWS):
            rows = pack_scene(renderer.scene, batch.start + lo, batch.start + hi, renderer.species_records)
            batch.rows.write(rows, offset=lo * nbytes)
            renderer.resources.prepare.run(batch.rows, hi - lo, offset=lo * nbytes)
        else:
            _staged(renderer, batch, mine)
        writes += 1
        if batch.row_texture is not None:
            lines = np.unique(mine // ROWS_PER_LINE)
            breaks = np.flatnonzero(np.diff(lines) != 1) + 1
            for first, last in zip(np.r_[0, breaks], np.r_[breaks, lines.size]):
                _refresh_texture(renderer, batch, int(lines[first]), int(lines[last - 1]) + 1)
    grow_spheres(renderer, ids)
    return writes


def _refresh_texture(renderer: SceneRenderer, batch: Any, first: int, last: int) -> None:
    """Copy the rows of texture lines ``first:last`` of ``batch`` (prepared) into its row texture,
    through a buffer on the GPU (as :class:`~leafview.gpu.resources.RowTexture` fills it)."""
    ctx = renderer.ctx
    width = ROWS_PER_LINE * ROW_TEXELS
    stop = min(last * ROWS_PER_LINE, batch.count)
    padded = ctx.buffer(reserve=(last - first) * width * 16)
    try:
        nbytes = LEAF_BLOCK.nbytes
        ctx.copy_buffer(padded, batch.rows, size=(stop - first * ROWS_PER_LINE) * nbytes,
                        read_offset=first * ROWS_PER_LINE * nbytes)
        batch.row_texture.texture.write(padded, viewport=(0, first, width, last - first))
    finally:
        padded.release()


def grow_spheres(renderer: SceneRenderer, leaves: NDArray[np.int64]) -> bool:
    """Widen the culling spheres (and level-of-detail errors) of the species of ``leaves`` so they
    hold those leaves as edited (the bound of the module docstring); writes the species' culling
    rows once when one grew. Returns whether it wrote."""
    scene = renderer.scene
    base = _BASE_CULL.setdefault(renderer, renderer.cull_rows.copy())
    variation = float(scene.spec.variation)
    lobed = np.asarray(renderer.lobed, bool)
    rows = renderer.cull_rows.copy()
    sid = scene.species_id[leaves]
    dev = np.abs(scene.factors[leaves].astype(np.float64) - 1.0).max(axis=1)
    off = (np.zeros(len(leaves)) if scene.offsets is None
           else np.abs(scene.offsets[leaves].astype(np.float64)).max(axis=1))
    changed = False
    for s in np.unique(sid):
        if lobed[s]:
            continue
        mine = sid == s
        d, o = float(dev[mine].max()), float(off[mine].max())
        r0 = float(base["sphere"][s, 3])
        reach = float(np.linalg.norm(base["sphere"][s, :3])) + r0
        radius = r0 + max(0.0, d - variation) * reach + np.sqrt(3.0) * o * max(1.0, reach)
        if radius > rows["sphere"][s, 3]:
            rows["sphere"][s, 3] = radius
            scale = (1.0 + 2.0 * max(d, variation)) / (1.0 + 2.0 * variation)
            rows["lod_error"][s, 1:] = np.maximum(rows["lod_error"][s, 1:], base["lod_error"][s, 1:] * scale)
            changed = True
    if changed:
        renderer.cull_rows = rows
        renderer.species_ssbo.write(rows.tobytes())
    return changed
