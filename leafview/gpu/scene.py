"""Scenes on the GPU: one storage-buffer row per leaf, GPU culling and level of detail, and one
indirect multi-draw per batch.

Per frame, for each batch of leaves:

1. the draw commands (one per level of detail) are reset: ``levels × 20`` bytes, the only
   upload, whatever the leaf count;
2. ``scene_cull.comp`` tests every leaf's bounding sphere against the frustum and a minimum
   projected size, picks its level (the coarsest grid whose outline error stays under
   ``max_error_px``) and appends its index to that level's list;
3. ``glMultiDrawElementsIndirect`` draws the levels' grids; ``leaf.vert`` (``LEAF_INDIRECT``)
   reads the leaf index as a per-instance attribute from the list (the command's
   ``baseInstance`` selects the list) and evaluates the leaf from its row.

No per-leaf work happens on the CPU after the scene is uploaded. Leaf rows are
:data:`~leafview.gpu.layout.LEAF_BLOCK` records (the same declaration as the single-leaf uniform
block); a batch holds at most ``GL_MAX_SHADER_STORAGE_BLOCK_SIZE`` bytes of them, so large scenes
are split into batches automatically (:func:`plan_batches`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import moderngl
import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import distance_transform_edt

from leafview.core.defaults import DEFAULT_GRID
from leafview.core.params import LeafParams
from leafview.deform.surface import evaluate, grid_indices, grid_uv
from leafview.errors import SceneLimitError
from leafview.gpu.context import check_error
from leafview.gpu.frame import FrameUniforms, Lighting
from leafview.gpu.layout import (
    COMMANDS_BINDING,
    DRAW_COMMAND_DTYPE,
    LEAF_BLOCK,
    LEAF_OFFSET_UNIFORM,
    LEAVES_BINDING,
    SPECIES_BINDING,
    SPECIES_CULL_BLOCK,
    SPECIES_OF_BINDING,
    VISIBLE_BINDING,
    feature_defines,
    pack_leaves,
    ripple_keys,
)
from leafview.gpu.limits import MAX_RESOURCE_BYTES, capture_bytes, check_scene, ensure_alive
from leafview.gpu.owner import GLObjects
from leafview.gpu.resources import GpuResources, JitterTable
from leafview.resources import resolve_preset
from leafview.scene.camera import Camera, top_down
from leafview.scene.spec import Scene, SceneSpec

__all__ = ["LOD_GRIDS", "CullSettings", "SceneRenderer", "SceneLimitError", "pack_scene", "species_cull", "plan_batches",
           "frustum_planes", "cull_reference"]

LOD_GRIDS: tuple[tuple[int, int], ...] = ((9, 17), (5, 9), (3, 5))  # 256, 64, 16 triangles
STEM_FRONT = (0.30, 0.22, 0.14, 0.0)
STEM_BACK = (0.30, 0.22, 0.14)
_LOCAL = 64
# the stems' vertex record: (attribute, format, the same bytes skipped)
_STEM_ATTRS = (("in_position", "3f", "12x"), ("in_normal", "3f", "12x"), ("in_uv", "2f", "8x"),
               ("in_front", "4f1", "4x"), ("in_back", "4f1", "4x"))
_CULL_CHUNK = 8192     # species records captured at once when measuring culling spheres and LOD errors


# -- packing (numpy) ------------------------------------------------------------------------------
def species_tables(scene: Scene) -> tuple[NDArray[Any], NDArray[np.float32], list[tuple[int, float]]]:
    """Per-species LEAF_BLOCK records (bend solved once per distinct species), the jitter table
    rows they index and the ripple signal keys (row i of the signal buffer). Species that differ
    only in name (a leaf set's leaves of one shape) are packed once."""
    index: dict[tuple[Any, ...], int] = {}
    species: list[LeafParams] = []
    inverse = np.empty(len(scene.species), np.int64)
    for i, sp in enumerate(scene.species):
        key = (sp.shape, sp.jitter, sp.material, sp.transform, sp.ripple, sp.bending)
        k = index.get(key)
        if k is None:
            k = index[key] = len(species)
            species.append(sp)
        inverse[i] = k
    recs, table = pack_leaves(species)
    return recs[inverse], table, ripple_keys(species)


def pack_scene(scene: Scene, start: int = 0, stop: int | None = None,
               species_records: NDArray[Any] | None = None) -> NDArray[Any]:
    """LEAF_BLOCK rows of leaves ``start:stop``, vectorised: the species' record with Ω scaled by
    the leaf's factors (as :func:`leafview.scene.spec.vary_shape`), colours by its tint and the
    model matrix set. Derived members are filled later by the prepare pass on the GPU."""
    stop = len(scene) if stop is None else stop
    if species_records is None:
        species_records = species_tables(scene)[0]
    ids = scene.species_id[start:stop]
    recs = species_records[ids]
    f = scene.factors[start:stop].astype(np.float32)
    recs["a1"][:, :3] *= f[:, 0:3]
    recs["a2"][:, :3] *= f[:, 3:6]
    recs["vbar"][:, :3] = np.clip(recs["vbar"][:, :3] * f[:, 6:15:3], np.float32(0.02), np.float32(0.98))
    recs["xs"][:, :3] *= f[:, 7:15:3]
    recs["zs"][:, :3] *= f[:, 8:15:3]
    recs["zf"][:, :3] *= f[:, 15:18]
    recs["zg"][:, :3] *= f[:, 18:21]
    t = scene.tint[start:stop, None].astype(np.float32)
    recs["front"][:, :3] = np.clip(recs["front"][:, :3] * t, 0.0, 1.0)
    recs["back"][:, :3] = np.clip(recs["back"][:, :3] * t, 0.0, 1.0)
    recs["model"] = np.transpose(scene.matrices[start:stop], (0, 2, 1)).astype(np.float32)
    return recs


def _lod_error(params: Any, coarse: tuple[int, int], fine: tuple[int, int] = DEFAULT_GRID) -> float:
    """Largest distance (leaf lengths) between the surface and the piecewise-bilinear surface
    through the ``coarse`` grid, sampled at the ``fine`` grid: how far the drawn outline can
    move when a leaf drops to ``coarse``."""
    uv = grid_uv(*fine).astype(np.float64)
    ref = evaluate(params, uv[:, 0], uv[:, 1])
    cu, cv = coarse
    g = evaluate(params, *grid_uv(cu, cv).astype(np.float64).T).reshape(cv, cu, 3)
    x = (uv[:, 0] + 1.0) / 2.0 * (cu - 1)
    y = uv[:, 1] * (cv - 1)
    i = np.minimum(x.astype(int), cu - 2)
    j = np.minimum(y.astype(int), cv - 2)
    a, b = (x - i)[:, None], (y - j)[:, None]
    approx = ((1 - a) * (1 - b) * g[j, i] + a * (1 - b) * g[j, i + 1]
              + (1 - a) * b * g[j + 1, i] + a * b * g[j + 1, i + 1])
    return float(np.linalg.norm(ref - approx, axis=1).max())


def species_cull(scene: Scene, grids: Sequence[tuple[int, int]] = LOD_GRIDS) -> NDArray[Any]:
    """SPECIES_CULL_BLOCK rows, the numpy reference: every species evaluated at every level's
    grid (:func:`leafview.deform.surface.evaluate`), then :func:`cull_rows_from_points`.
    :class:`SceneRenderer` computes the same rows from the points its vertex shader captures, once
    per distinct species record."""
    if len(grids) > 4:
        raise ValueError("at most 4 levels of detail")
    points = [np.stack([evaluate(sp, *grid_uv(*g).astype(np.float64).T) for sp in scene.species]) for g in grids]
    return cull_rows_from_points(points, grids, scene.spec.variation)


def cull_rows_from_points(points: Sequence[NDArray[Any]], grids: Sequence[tuple[int, int]],
                          variation: float) -> NDArray[Any]:
    """SPECIES_CULL_BLOCK rows of S species from their leaf-space points at each level's grid
    (``points[k]``: (S, nu_k·nv_k, 3), :func:`~leafview.deform.surface.grid_uv` order), vectorised
    over species.

    * ``sphere``: centre of the points' box, radius to the farthest point of any level (every
      drawn vertex is inside), widened for the variation and by 1e-3.
    * ``lod_error[k]``: largest distance between the level-0 points and the piecewise-bilinear
      surface through level k's points (see :func:`_lod_error`).

    Variation bound: every control point moves by at most ``variation × |point|`` (factors in
    ``1 ± variation``) and the surface is a convex combination of control points, so the sphere
    grows by ``variation × max |point|``; the LOD errors are scaled by ``1 + 2 variation``."""
    pts = [np.asarray(p, np.float64) for p in points]
    n = pts[0].shape[0]
    out = np.zeros(n, SPECIES_CULL_BLOCK.dtype)
    if n == 0:
        return out
    every = np.concatenate(pts, axis=1)
    center = (every.min(axis=1) + every.max(axis=1)) / 2
    radius = np.linalg.norm(every - center[:, None], axis=2).max(axis=1)
    radius += variation * np.linalg.norm(every, axis=2).max(axis=1) + 1e-3
    out["sphere"][:, :3] = center
    out["sphere"][:, 3] = radius
    uv = grid_uv(*grids[0]).astype(np.float64)
    ref = pts[0]
    for k in range(1, len(grids)):
        cu, cv = grids[k]
        g = pts[k].reshape(n, cv, cu, 3)
        x = (uv[:, 0] + 1.0) / 2.0 * (cu - 1)
        y = uv[:, 1] * (cv - 1)
        i = np.minimum(x.astype(int), cu - 2)
        j = np.minimum(y.astype(int), cv - 2)
        a, b = (x - i)[None, :, None], (y - j)[None, :, None]
        approx = ((1 - a) * (1 - b) * g[:, j, i] + a * (1 - b) * g[:, j, i + 1]
                  + (1 - a) * b * g[:, j + 1, i] + a * b * g[:, j + 1, i + 1])
        out["lod_error"][:, k] = np.linalg.norm(ref - approx, axis=2).max(axis=1) * (1.0 + 2.0 * variation)
    return out


def _nested(fine: tuple[int, int], coarse: tuple[int, int]) -> NDArray[np.intp] | None:
    """Indices of ``coarse``'s (u, v) samples among ``fine``'s (both in
    :func:`~leafview.deform.surface.grid_uv` order), or None when they are not all among them."""
    (fu, fv), (cu, cv) = fine, coarse
    if (fu - 1) % (cu - 1) or (fv - 1) % (cv - 1):
        return None
    su, sv = (fu - 1) // (cu - 1), (fv - 1) // (cv - 1)
    idx = (np.arange(cv)[:, None] * sv * fu + np.arange(cu)[None, :] * su).reshape(-1)
    fine_uv, coarse_uv = grid_uv(fu, fv), grid_uv(cu, cv)
    return idx if np.array_equal(fine_uv[idx], coarse_uv) else None


def plan_batches(n_leaves: int, max_block_bytes: int, max_groups: int = 65535,
                 row_bytes: int = LEAF_BLOCK.nbytes) -> list[tuple[int, int]]:
    """``(start, stop)`` ranges of leaves, each fitting one storage block of at most
    ``max_block_bytes`` bytes and one dispatch of at most ``max_groups`` work groups."""
    per = min(max_block_bytes // row_bytes, max_groups * _LOCAL)
    if per < 1:
        raise SceneLimitError(f"one {row_bytes}-byte leaf row exceeds GL_MAX_SHADER_STORAGE_BLOCK_SIZE = "
                              f"{max_block_bytes} bytes")
    return [(s, min(s + per, n_leaves)) for s in range(0, n_leaves, per)]


# -- culling reference (numpy) ----------------------------------------------------------------
def frustum_planes(view_proj: NDArray[np.float64]) -> NDArray[np.float64]:
    """(6, 4) world-space planes (n, d), inside where ``n·p + d ≥ 0``, unit normals, from the
    column-vector matrix ``P · V`` (Gribb-Hartmann)."""
    m = np.asarray(view_proj, np.float64)
    r = [m[0], m[1], m[2], m[3]]
    planes = np.array([r[3] + r[0], r[3] - r[0], r[3] + r[1], r[3] - r[1], r[3] + r[2], r[3] - r[2]])
    return planes / np.linalg.norm(planes[:, :3], axis=1, keepdims=True)


def _pixel_scale(camera: Camera, size: tuple[int, int]) -> float:
    return float(camera.proj[1, 1]) * size[1] / 2.0


@dataclass(frozen=True)
class CullSettings:
    """What the culling pass decides with: ``min_pixels`` (drop leaves whose bounding sphere
    spans fewer pixels), ``max_error_px`` (largest outline error a coarser level may add),
    ``cull`` (frustum and size tests on) and ``lod`` (levels chosen; off = finest grid)."""

    min_pixels: float = 1.0
    max_error_px: float = 0.75
    cull: bool = True
    lod: bool = True
    level: int = -1      # >= 0: every visible leaf at this level (with lod on)

    @property
    def forced_level(self) -> int:
        return self.level if self.lod else 0


def cull_reference(scene: Scene, cull_rows: NDArray[Any], camera: Camera, size: tuple[int, int],
                   settings: CullSettings = CullSettings(), levels: int = len(LOD_GRIDS)
                   ) -> NDArray[np.int32]:
    """The level each leaf gets (-1: culled), computed in numpy exactly as ``scene_cull.comp``."""
    m = scene.matrices
    sc = cull_rows[scene.species_id]
    center = np.einsum("nij,nj->ni", m[:, :3, :3], sc["sphere"][:, :3]) + m[:, :3, 3]
    scale = np.linalg.norm(m[:, :3, 0], axis=1)
    radius = sc["sphere"][:, 3] * scale
    ppu = np.full(len(scene), _pixel_scale(camera, size))
    if camera.perspective:
        ppu = ppu / np.maximum(np.linalg.norm(center - camera.eye[:3], axis=1) - radius, 1e-4)
    level = np.full(len(scene), max(settings.forced_level, 0), np.int32)
    if settings.forced_level < 0:
        for k in range(1, levels):
            ok = (level == k - 1) & (sc["lod_error"][:, k] * scale * ppu <= settings.max_error_px)
            level[ok] = k
    if settings.cull:
        planes = frustum_planes(camera.proj @ camera.view)
        inside = np.all(center @ planes[:, :3].T + planes[:, 3] >= -radius[:, None], axis=1)
        level[~inside | (2.0 * radius * ppu < settings.min_pixels)] = -1
    return level


# -- GPU ----------------------------------------------------------------------------------------
class _SceneBatch:
    """GL objects of one batch of leaves: rows, species ids, the per-level visible lists, the
    draw commands and the vertex array that reads them."""

    def __init__(self, owner: SceneRenderer, start: int, stop: int) -> None:
        ctx = owner.ctx
        self.start, self.count = start, stop - start
        self._objects = GLObjects()
        try:
            rows = pack_scene(owner.scene, start, stop, owner.species_records)
            self.rows = self._objects.own(ctx.buffer(rows.tobytes()))
            del rows
            owner.resources.prepare.run(self.rows, self.count)
            self.species_of = self._objects.own(
                ctx.buffer(owner.scene.species_id[start:stop].astype(np.uint32).tobytes()))
            levels = len(owner.grids)
            self.visible = self._objects.own(ctx.buffer(reserve=4 * self.count * levels))
            self.reset = np.zeros(levels, DRAW_COMMAND_DTYPE)
            self.reset["count"] = owner.index_counts
            self.reset["first_index"] = owner.first_index
            self.reset["base_vertex"] = owner.base_vertex
            self.reset["base_instance"] = np.arange(levels) * self.count
            self.commands = self._objects.own(ctx.buffer(self.reset.tobytes()))
            self.vao = self._objects.own(ctx.vertex_array(owner.program, [(owner.uv_vbo, "2f", "in_uv"),
                                                                          (self.visible, "1u/i", "in_leaf")],
                                                          index_buffer=owner.ibo, index_element_size=4))
        except BaseException:
            self.release()
            raise

    def release(self) -> None:
        self._objects.release()


class SceneRenderer:
    """Draws a :class:`~leafview.scene.spec.Scene` with GPU culling and LOD.

    Parameters
    ----------
    ctx: moderngl context (OpenGL 4.5).
    scene: the expanded scene.
    grids: (nu, nv) of each level of detail, finest first (2-4 levels).
    max_block_bytes: storage-block size per batch (default: the context's
        ``GL_MAX_SHADER_STORAGE_BLOCK_SIZE``; smaller values force batching, for tests).
    progress: called with the number of leaves uploaded after each batch (progress bars).
    resources: shared programs, prepare pass, targets and capture
        (:class:`~leafview.gpu.resources.GpuResources`); ``None``: a private set.

    Raises :class:`SceneLimitError` when the rows cannot fit the context's limits; checks
    ``ctx.error`` after allocating so an out-of-memory is reported, not ignored.
    """

    def __init__(self, ctx: moderngl.Context, scene: Scene, *, grids: Sequence[tuple[int, int]] = LOD_GRIDS,
                 max_block_bytes: int | None = None, progress: Callable[[int], None] | None = None,
                 resources: GpuResources | None = None) -> None:
        self.ctx, self.scene = ctx, scene
        self.grids: tuple[tuple[int, int], ...] = tuple((int(g[0]), int(g[1])) for g in grids)
        if not 1 <= len(self.grids) <= 4:
            raise ValueError("between 1 and 4 levels of detail")
        # the memory estimate and the context, before any GL object or per-leaf array
        check_scene(len(scene))
        ensure_alive(ctx, "uploading a scene")
        self._objects = GLObjects()
        self.batches: list[_SceneBatch] = []
        self._stem_buffers: tuple[moderngl.Buffer, moderngl.Buffer] | None = None
        # program variants (draw(defines=...)): leaf program, one vertex array per batch, stems
        self._variants: dict[tuple[tuple[str, str], ...], tuple[moderngl.Program, list[moderngl.VertexArray],
                                                                moderngl.VertexArray | None]] = {}
        try:
            self.resources = resources if resources is not None else self._objects.own(GpuResources(ctx))
            limit = int(ctx.info["GL_MAX_SHADER_STORAGE_BLOCK_SIZE"])
            if max_block_bytes is not None:
                limit = min(limit, int(max_block_bytes))
            self._block_limit = limit
            groups = int(ctx.info["GL_MAX_COMPUTE_WORK_GROUP_COUNT"][0])
            self.plan = plan_batches(len(scene), limit, groups)
            self.species_records, table, keys = species_tables(scene)
            self.program = self.resources.leaf_program({"LEAF_INDIRECT": 1, **feature_defines(self.species_records)})
            self.cull = self.resources.programs.compute("scene_cull.comp")
            self.ripples = self._objects.own(self.resources.ripple_pass())
            self.ripples.update(keys)
            self.jitter = self._objects.own(JitterTable(ctx, table))
            self.frame = self._objects.own(FrameUniforms(ctx))
            self.cull_rows = self._species_cull(self.species_records)
            self.species_ssbo = self._objects.own(ctx.buffer(self.cull_rows.tobytes()))
            # every level's grid in one vertex and one index buffer
            uvs, idx = [], []
            self.first_index: list[int] = []
            self.base_vertex: list[int] = []
            self.index_counts: list[int] = []
            nverts = nidx = 0
            for nu, nv in self.grids:
                tri = grid_indices(nu, nv).ravel()
                self.first_index.append(nidx)
                self.base_vertex.append(nverts)
                self.index_counts.append(tri.size)
                uvs.append(grid_uv(nu, nv))
                idx.append(tri)
                nverts += nu * nv
                nidx += tri.size
            self.uv_vbo = self._objects.own(ctx.buffer(np.concatenate(uvs).astype(np.float32).tobytes()))
            self.ibo = self._objects.own(ctx.buffer(np.concatenate(idx).astype(np.uint32).tobytes()))
            self.stems = self._make_stems(scene.stems)
            for start, stop in self.plan:
                ensure_alive(ctx, f"uploading leaves {start:,}..{stop:,} of {len(scene):,}")
                self.batches.append(_SceneBatch(self, start, stop))
                err = ctx.error
                if err != "GL_NO_ERROR":
                    raise SceneLimitError(f"allocating leaves {start}..{stop} of {len(scene)} failed with {err} "
                                          f"({(stop - start) * LEAF_BLOCK.nbytes:,} bytes of rows)")
                if progress is not None:
                    progress(stop - start)
        except BaseException:
            self.release()
            raise

    def _species_cull(self, records: NDArray[Any], chunk: int = _CULL_CHUNK) -> NDArray[Any]:
        """:func:`species_cull` of the species ``records`` from the points this renderer's vertex
        shader computes: identical records are captured once, the others in chunks of ``chunk``
        (one prepare dispatch and one instanced capture per level each), so a leaf set with a
        species per leaf costs a few GPU passes, not a numpy evaluation per leaf."""
        ctx = self.ctx
        raw = np.ascontiguousarray(records).view(np.dtype((np.void, records.dtype.itemsize))).reshape(-1)
        _, first, inverse = np.unique(raw, return_index=True, return_inverse=True)
        unique = np.ascontiguousarray(records[first])
        # a coarser level whose samples are among the finest level's (the default grids nest) is
        # read out of the finest capture; only the others are captured themselves
        subsets = [_nested(self.grids[0], g) for g in self.grids]
        captured = [k for k, sub in enumerate(subsets) if sub is None or k == 0]
        per = [self.grids[k][0] * self.grids[k][1] for k in captured]
        chunk = max(1, min(chunk, self._block_limit // LEAF_BLOCK.nbytes,
                           MAX_RESOURCE_BYTES // capture_bytes(sum(per))))
        points: list[list[NDArray[np.float32]]] = [[] for _ in self.grids]
        self._bind_tables()
        for start in range(0, len(unique), chunk):
            part = unique[start:start + chunk]
            n = len(part)
            ensure_alive(ctx, "measuring the species of a scene")
            local = GLObjects()
            try:
                rows = local.own(ctx.buffer(part.tobytes()))
                self.resources.prepare.run(rows, n)
                ids = local.own(ctx.buffer(np.arange(n, dtype=np.uint32).tobytes()))
                with self.resources.capture.recording(n * sum(per)) as rec:
                    for k in captured:
                        g = self.resources.grid(*self.grids[k])
                        vao = local.own(ctx.vertex_array(self.program, [(g.vbo, "2f", "in_uv"),
                                                                        (ids, "1u/i", "in_leaf")]))
                        rows.bind_to_storage_buffer(LEAVES_BINDING)
                        rec.add(vao, g.vertices, instances=n)
                    pos, _ = rec.read()
            finally:
                local.release()
            offset = 0
            for k, nverts in zip(captured, per):
                points[k].append(pos[offset:offset + n * nverts].reshape(n, nverts, 3))
                offset += n * nverts
            for k, sub in enumerate(subsets):
                if k not in captured and sub is not None:
                    points[k].append(points[0][-1][:, sub])
        rows_out = cull_rows_from_points([np.concatenate(p) for p in points], self.grids, self.scene.spec.variation)
        return rows_out[inverse.reshape(-1)]

    def _make_stems(self, stems: Any) -> moderngl.VertexArray | None:
        if stems is None or len(stems[2]) == 0:
            return None
        pos, nrm, tris = stems
        n = len(pos)
        vdt = np.dtype([("p", "<f4", 3), ("n", "<f4", 3), ("uv", "<f4", 2), ("front", "u1", 4), ("back", "u1", 4)])
        verts = np.zeros(n, vdt)
        verts["p"], verts["n"], verts["uv"] = pos, nrm, (1.0, 0.5)  # u = 1: no midrib band
        verts["front"] = np.round(np.asarray(STEM_FRONT) * 255)
        verts["back"][:, :3] = np.round(np.asarray(STEM_BACK) * 255)
        vbo = self._objects.own(self.ctx.buffer(verts.tobytes()))
        ibo = self._objects.own(self.ctx.buffer(np.asarray(tris, np.uint32).tobytes()))
        self._stem_buffers = (vbo, ibo)
        return self._stem_vao(self.resources.baked_program())

    def _stem_vao(self, prog: moderngl.Program) -> moderngl.VertexArray:
        assert self._stem_buffers is not None
        vbo, ibo = self._stem_buffers
        # attributes a variant does not read (the label pass: colours, uv) are skipped as padding
        attrs = [(name, fmt, pad) for name, fmt, pad in _STEM_ATTRS if name in prog]
        layout = " ".join(fmt if name in prog else pad for name, fmt, pad in _STEM_ATTRS)
        vao: moderngl.VertexArray = self._objects.own(self.ctx.vertex_array(
            prog, [(vbo, layout, *(name for name, _, _ in attrs))], index_buffer=ibo, index_element_size=4))
        return vao

    def _variant(self, defines: Mapping[str, object] | None
                 ) -> tuple[moderngl.Program, list[moderngl.VertexArray], moderngl.VertexArray | None]:
        """The leaf program, per-batch vertex arrays and stem vertex array that draw with the extra
        feature ``defines`` (None: the renderer's own). The stems' program is ``leaf_baked.vert``
        + ``leaf.frag`` with the same defines and ``LEAF_STEMS``. Built on first use, released
        with the renderer."""
        if not defines:
            return self.program, [b.vao for b in self.batches], self.stems
        key = tuple(sorted((str(k), str(v)) for k, v in defines.items()))
        found = self._variants.get(key)
        if found is None:
            prog = self.resources.leaf_program({"LEAF_INDIRECT": 1, **feature_defines(self.species_records),
                                                **defines})
            vaos = [self._objects.own(self.ctx.vertex_array(prog, [(self.uv_vbo, "2f", "in_uv"),
                                                                   (b.visible, "1u/i", "in_leaf")],
                                                            index_buffer=self.ibo, index_element_size=4))
                    for b in self.batches]
            stems = None
            if self._stem_buffers is not None:
                stems = self._stem_vao(self.resources.programs.program(
                    "leaf_baked.vert", "leaf.frag", defines={**defines, "LEAF_STEMS": 1}))
            found = self._variants[key] = (prog, vaos, stems)
        return found

    # -- per frame ---------------------------------------------------------------------------
    def set_camera(self, camera: Camera, size: tuple[int, int], *, srgb: bool = True,
                   lighting: type[Lighting] = Lighting) -> None:
        self.camera, self.size = camera, (int(size[0]), int(size[1]))
        self.frame.set_camera(camera, srgb=srgb, lighting=lighting)

    def _set_cull_uniforms(self, settings: CullSettings) -> None:
        """Camera and settings uniforms of the culling pass: once per frame, for every batch."""
        cam = self.camera
        s = self.cull
        planes = s["planes"]
        assert isinstance(planes, moderngl.Uniform)
        planes.write(frustum_planes(cam.proj @ cam.view).astype(np.float32).tobytes())
        s["eye"] = tuple(float(x) for x in (cam.eye if cam.perspective else (*cam.eye[:3], 0.0)))
        s["pixel_scale"] = _pixel_scale(cam, self.size)
        s["min_pixels"] = settings.min_pixels
        s["max_error_px"] = settings.max_error_px
        s["levels"] = len(self.grids)
        s["forced_level"] = settings.forced_level
        s["frustum"] = settings.cull
        self.species_ssbo.bind_to_storage_buffer(SPECIES_BINDING)

    def _cull(self, batch: _SceneBatch) -> None:
        batch.commands.write(batch.reset.tobytes())
        s = self.cull
        s["count"] = batch.count
        batch.rows.bind_to_storage_buffer(LEAVES_BINDING)
        batch.species_of.bind_to_storage_buffer(SPECIES_OF_BINDING)
        batch.commands.bind_to_storage_buffer(COMMANDS_BINDING)
        batch.visible.bind_to_storage_buffer(VISIBLE_BINDING)
        s.run(group_x=-(-batch.count // _LOCAL))
        self.ctx.memory_barrier(moderngl.COMMAND_BARRIER_BIT | moderngl.VERTEX_ATTRIB_ARRAY_BARRIER_BIT
                                | moderngl.SHADER_STORAGE_BARRIER_BIT)

    def _bind_tables(self) -> None:
        self.frame.bind()
        self.jitter.use()
        self.ripples.bind()

    def draw(self, settings: CullSettings = CullSettings(), *, defines: Mapping[str, object] | None = None) -> None:
        """Cull and draw every batch (and the stems) into the bound framebuffer. A context
        released or lost before or between batches raises :class:`~leafview.errors.GLContextLost`.

        ``defines``: extra feature defines of a program variant to draw with (e.g. ``LEAF_AOV``,
        the label pass of :mod:`leafview.gpu.aov`); a variant whose vertex shader declares
        :data:`~leafview.gpu.layout.LEAF_OFFSET_UNIFORM` gets each batch's first leaf there."""
        ensure_alive(self.ctx, "drawing a scene")
        program, vaos, stems = self._variant(defines)
        offset = program.get(LEAF_OFFSET_UNIFORM, None)
        self.ctx.enable_only(moderngl.DEPTH_TEST)
        self._bind_tables()
        if stems is not None:
            stems.render(moderngl.TRIANGLES)
        self._set_cull_uniforms(settings)
        for i, (batch, vao) in enumerate(zip(self.batches, vaos)):
            ensure_alive(self.ctx, f"drawing batch {i + 1} of {len(self.batches)}")
            self._cull(batch)
            batch.rows.bind_to_storage_buffer(LEAVES_BINDING)
            if isinstance(offset, moderngl.Uniform):
                offset.value = batch.start
            vao.render_indirect(batch.commands, moderngl.TRIANGLES, count=len(self.grids))

    def level_counts(self) -> NDArray[np.int64]:
        """Leaves drawn at each level in the last :meth:`draw` (reads the commands back)."""
        ensure_alive(self.ctx, "reading the draw commands back")
        total = np.zeros(len(self.grids), np.int64)
        for batch in self.batches:
            total += np.frombuffer(batch.commands.read(), DRAW_COMMAND_DTYPE)["instance_count"]
        return total

    def levels(self) -> NDArray[np.int32]:
        """Each leaf's level in the last :meth:`draw` (-1: culled), read back from the lists."""
        ensure_alive(self.ctx, "reading the visible lists back")
        out = np.full(len(self.scene), -1, np.int32)
        for batch in self.batches:
            counts = np.frombuffer(batch.commands.read(), DRAW_COMMAND_DTYPE)["instance_count"]
            vis = np.frombuffer(batch.visible.read(), np.uint32)
            for k, c in enumerate(counts):
                out[batch.start + vis[k * batch.count:k * batch.count + int(c)]] = k
        return out

    def triangles(self, counts: NDArray[np.int64] | None = None) -> int:
        """Leaf triangles drawn in the last :meth:`draw`, from ``counts`` (as
        :meth:`level_counts` returned them) or read back."""
        per = np.array([2 * (nu - 1) * (nv - 1) for nu, nv in self.grids])
        return int((self.level_counts() if counts is None else counts) @ per)

    def capture(self, leaves: Sequence[int], level: int = 0) -> NDArray[np.float32]:
        """Leaf-space positions that ``leaf.vert`` computes for the given leaves at ``level``'s
        grid (transform feedback of the drawing program, one instanced capture per batch):
        (len(leaves), nu·nv, 3). The framebuffer binding is left as it was."""
        picks = np.asarray(list(leaves), dtype=np.int64).reshape(-1)
        if picks.size and (picks.min() < 0 or picks.max() >= len(self.scene)):
            raise IndexError(f"leaf index out of range 0..{len(self.scene) - 1}")
        grid = self.resources.grid(*self.grids[level])
        nverts = grid.vertices
        order: list[NDArray[np.int64]] = []
        self._bind_tables()
        with self.resources.capture.recording(picks.size * nverts) as rec:
            for b in self.batches:
                mine = np.flatnonzero((picks >= b.start) & (picks < b.start + b.count))
                if not mine.size:
                    continue
                ids = self.ctx.buffer((picks[mine] - b.start).astype(np.uint32).tobytes())
                vao = self.ctx.vertex_array(self.program, [(grid.vbo, "2f", "in_uv"), (ids, "1u/i", "in_leaf")])
                try:
                    b.rows.bind_to_storage_buffer(LEAVES_BINDING)
                    rec.add(vao, nverts, instances=mine.size)
                finally:
                    vao.release()
                    ids.release()
                order.append(mine)
            pos, _ = rec.read()
        out = np.empty((picks.size, nverts, 3), np.float32)
        if order:
            out[np.concatenate(order)] = pos.reshape(-1, nverts, 3)
        return out

    def render(self, camera: Camera, size: tuple[int, int], settings: CullSettings = CullSettings(), *,
               samples: int = 4, background: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
               ) -> NDArray[np.uint8]:
        """One frame offscreen: (h, w, 4) uint8 RGBA, row 0 at the top (a render target of the
        shared resources, resolved when multisampled)."""
        ctx = self.ctx
        size = (int(size[0]), int(size[1]))
        ensure_alive(ctx, "rendering a scene")
        target = self.resources.target(size, min(int(samples), int(ctx.max_samples)))
        target.use()
        ctx.viewport = (0, 0, *size)
        target.clear(background)
        self.set_camera(camera, size)
        self.draw(settings)
        image: NDArray[np.uint8] = target.read()
        check_error(ctx, "scene frame")
        return image

    def release(self) -> None:
        """Release every GL object (idempotent)."""
        self._variants.clear()
        while self.batches:
            self.batches.pop().release()
        self._objects.release()

    def __enter__(self) -> SceneRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def single_leaf_scene(params: Any) -> Scene:
    """A one-leaf :class:`Scene` at the origin (no variation): for LOD measurements."""

    spec = SceneSpec(species=(params,), leaves=1, variation=0.0, colour_variation=0.0, stems=False)
    sp = (params.replace(transform=type(params.transform)()),)
    return Scene(spec, sp, np.zeros(1, np.int32), np.ones((1, 21), np.float32), np.ones(1, np.float32),
                 np.eye(4)[None], None, None)


def lod_switch_error(ctx: moderngl.Context, presets: Sequence[str], settings: CullSettings = CullSettings(),
                     grids: Sequence[tuple[int, int]] = LOD_GRIDS) -> float:
    """Largest outline change, in pixels, when a leaf switches level: each preset's leaf is drawn
    top-down at the exact size where the culling pass switches it from level k to k + 1, once at
    each level (no MSAA), and the Hausdorff distance between the two coverage masks is taken."""
    worst = 0.0
    for name in presets:
        params = LeafParams.load(resolve_preset(name))
        scene = single_leaf_scene(params)
        with SceneRenderer(ctx, scene, grids=grids) as r:
            for k in range(1, len(grids)):
                err = float(r.cull_rows[0]["lod_error"][k])
                if err <= 0:
                    continue
                ppu = settings.max_error_px / err * (1.0 + 1e-6)   # pixels per leaf length at the switch
                pts = evaluate(params, *grid_uv(*DEFAULT_GRID).astype(np.float64).T)
                lo, hi = pts.min(axis=0), pts.max(axis=0)
                w, h = (int(np.ceil((hi[i] - lo[i]) * ppu)) + 8 for i in (0, 1))
                if max(w, h) > 4096:
                    continue  # switch happens above any image size we draw single leaves at
                cam = top_down((lo[:2] + hi[:2]) / 2, hi[2] + 1.0, w / (2 * ppu), h / (2 * ppu),
                               hi[2] - lo[2] + 2.0)
                masks = []
                for level in (k - 1, k):
                    img = r.render(cam, (w, h), CullSettings(level=level), samples=0)
                    masks.append(img[..., 3] > 127)
                a, b = masks
                if a.any() and b.any():
                    da, db = distance_transform_edt(~a), distance_transform_edt(~b)
                    worst = max(worst, float(da[b].max()), float(db[a].max()))
    return worst
