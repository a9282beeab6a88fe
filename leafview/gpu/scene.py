"""Scenes on the GPU: one storage-buffer row per leaf, GPU culling and level of detail, and one
indirect multi-draw per batch.

Per frame, for each batch of leaves:

1. the draw commands (one per level of detail) are reset: ``levels × 20`` bytes, the only
   upload, whatever the leaf count;
2. ``scene_cull.comp`` tests every leaf's bounding sphere against the frustum and a minimum
   projected size, picks its level (the coarsest grid whose outline error stays under
   ``max_error_px``) and appends its index to that level's list;
3. ``scene_compact.comp`` copies the visible leaves' :data:`~leafview.gpu.layout.LEAF_VERTEX_BLOCK`
   members (what every vertex reads) into one compact array, level after level, and points each
   command's ``baseInstance`` at its level's first record;
4. ``glMultiDrawElementsIndirect`` draws the levels' grids; ``leaf.vert`` (``LEAF_INDIRECT``)
   reads the record as per-instance vertex attributes, and the row (for ripples, bends and
   extended silhouettes, and the label pass's leaf index) through the record's ``leaf_vertex_row``.

Textured species (:mod:`leafview.gpu.textures`) share one array texture, a layer per image
file, bound for the whole scene: each record carries its layers, so they draw in the same
indirect multi-draws as plain species. Veined species the same way: one vein field layer per
species (:class:`~leafview.gpu.vein_draw.VeinDraw`; species with the same shape and venation
share one), which every leaf of the species reads; ``veins=False`` draws none.

Lobed species (``LeafParams.lobes`` with an outline) draw in the same multi-draws too: their sweep
tables are one array texture (:class:`~leafview.gpu.lobe_tables.LobeTables`, a layer per distinct
:class:`~leafview.core.lobes.Lobes`), bound for the whole scene, and their leaves are drawn on
grids of their own, :attr:`SceneRenderer.lobed_grids` (:func:`lobed_levels`: the lobed grid of each
level's grid, :func:`~leafview.deform.sweep.lobed_grid`), appended to the levels' grids as further
draw commands. A species' culling row says which grids it is drawn on (``lod_error[0]``, unused as
an error, holds its *grid group*: 0 the levels' grids, 1 the lobed ones); the culling pass picks a
lobed leaf's level by the same screen-space error rule, among its group's levels, and appends it
to command ``group_first[group] + level``. A scene without lobed species has one group and compiles
its programs with ``LEAF_NO_LOBES`` (:func:`~leafview.gpu.layout.lobe_defines`): it pays nothing.
A lobed leaf's Ω is not its shape, so per-leaf shape variation leaves it alone
(:func:`leafview.scene.spec.build_scene` gives its leaves factors of 1): lobed leaves of a species
differ by their transform and colour only.

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
from scipy.spatial import cKDTree

from leafview.botany import leaf_surface
from leafview.botany.vein_shape import shape_grid
from leafview.core.defaults import DEFAULT_GRID
from leafview.core.params import Bending, LeafParams
from leafview.deform.beam import bend_profiles
from leafview.deform.surface import drawn_uv, evaluate, grid_indices, grid_uv
from leafview.deform.sweep import lobed_grid
from leafview.errors import SceneLimitError
from leafview.gpu.bounds import LeafBounds
from leafview.gpu.context import check_error
from leafview.gpu.frame import FrameUniforms, Lighting
from leafview.gpu.layout import (
    COMMANDS_BINDING,
    DRAW_COMMAND_DTYPE,
    LEAF_BLOCK,
    LEAF_OFFSET_UNIFORM,
    LEAF_VERTEX_BLOCK,
    LEAVES_BINDING,
    NO_VEIN_DEFINES,
    PLAIN_DEFINES,
    SPECIES_BINDING,
    SPECIES_CULL_BLOCK,
    SPECIES_OF_BINDING,
    VEIN_SKIN_DEFINES,
    VERTICES_BINDING,
    VISIBLE_BINDING,
    feature_defines,
    lobe_defines,
    needs_row_texture,
    pack_leaves,
    ripple_keys,
    texture_defines,
    texture_layers,
    vein_defines,
    write_lobe_layers,
    write_slot,
    write_texture_layers,
    write_vein_layers,
)
from leafview.gpu.limits import check_scene, ensure_alive
from leafview.gpu.lobe_tables import LobeTables, lobe_keys
from leafview.gpu.owner import GLObjects
from leafview.gpu.resources import GpuResources, JitterTable, RowTexture, record_vertex_array
from leafview.gpu.textures import LeafTextures
from leafview.gpu.vein_draw import VeinDraw, fresh_layers
from leafview.resources import resolve_preset
from leafview.scene.camera import Camera, top_down
from leafview.scene.spec import VBAR_GAP, Scene, SceneSpec
from leafview.scene.threads import in_two_threads
from leafview.scene.variety import interpolate_bend, load_table, sphere_padding

__all__ = ["LOD_GRIDS", "CullSettings", "SceneRenderer", "SceneLimitError", "pack_scene", "species_cull", "plan_batches",
           "frustum_planes", "cull_reference", "lobed_levels", "lobed_species", "LOD_NEVER"]

LOD_GRIDS: tuple[tuple[int, int], ...] = ((9, 17), (5, 9), (3, 5), (2, 3))  # 256, 64, 16, 4 triangles
"""The levels of detail, finest first. The last, (2, 3), is a leaf of a few pixels drawn through
its margin at the base, the widest row and the tip: four triangles and six vertices. Its outline
error is about three times the (3, 5) level's, so the culling pass picks it (by the same
outline-error rule as the others, 0.75 px by default) for leaves shorter than about 3-5 pixels. A
10⁶-leaf field at 1280×720 is drawn almost wholly on it, and on llvmpipe its leaves' pass with 4×
multisampling then takes less than half the time: that pass's cost is in the fragment stage
(3.5× the single-sample pass; 2× samples cost as much as 4×), where each sub-pixel triangle that
covers a sample is shaded (docs/benchmarks.md, "10⁶ leaves")."""
STEM_FRONT = (0.30, 0.22, 0.14, 0.0)
STEM_BACK = (0.30, 0.22, 0.14)
_LOCAL = 64
LOD_NEVER = 1e30
"""``lod_error`` of a level a species has not (a lobed species' levels beyond :func:`lobed_levels`):
never picked."""
LOBED_GROUP = 1   # a lobed species' grid group (its culling row's lod_error[0])


def lobed_levels(grids: Sequence[tuple[int, int]]) -> tuple[tuple[int, int], ...]:
    """The grids a scene's lobed leaves are drawn on, finest first: the lobed grid of each level's
    grid (:func:`~leafview.deform.sweep.lobed_grid`), repeats dropped (the default levels all map to
    (2, 65): a tie is straight unless cupped, and 65 rows is the coarsest tour that keeps the ties'
    pairing, so lobed leaves have one level there)."""
    out: list[tuple[int, int]] = []
    for g in grids:
        lg = lobed_grid((int(g[0]), int(g[1])))
        if lg not in out:
            out.append(lg)
    return tuple(out)


def lobed_species(scene: Scene) -> NDArray[np.bool_]:
    """(S,) whether each species of ``scene`` is lobed (drawn from a sweep table)."""
    return np.array([bool(sp.lobes.enabled) for sp in scene.species], bool)
# the stems' vertex record: (attribute, format, the same bytes skipped)
_STEM_ATTRS = (("in_position", "3f", "12x"), ("in_normal", "3f", "12x"), ("in_uv", "2f", "8x"),
               ("in_front", "4f1", "4x"), ("in_back", "4f1", "4x"))


# -- packing (numpy) ------------------------------------------------------------------------------
def species_tables(scene: Scene, vein_layers: NDArray[np.int32] | None = None,
                   lobe_layers: NDArray[np.int32] | None = None
                   ) -> tuple[NDArray[Any], NDArray[np.float32], list[tuple[int, float]]]:
    """Per-species LEAF_BLOCK records, the jitter table rows they index and the ripple signal keys
    (row i of the signal buffer), equal to :func:`~leafview.gpu.layout.pack_leaves` of the species.

    Species that differ only in Ω's 21 numbers, their colours and their bend profile (a leaf set:
    a species per leaf) share one *template* record, packed once; each species' Ω and colours then
    go straight into its row, vectorised, and the bend profiles of the bent ones are solved
    together, once per distinct shape, bending and frame (:func:`leafview.deform.beam.bend_profiles`).
    An extended silhouette is a template of its own (its further rows depend on its whole shape), and
    so is a landmark margin (:mod:`leafview.core.margin`; its texels fill the extended members).
    Each species' texture layers are those of :func:`~leafview.gpu.layout.texture_keys` of the
    species (the array texture :class:`SceneRenderer` binds), its vein layer ``vein_layers[i]``
    (default: :func:`leafview.gpu.vein_draw.fresh_layers` of the species, the layers of a field
    array built for them, as :class:`SceneRenderer` builds it; -1 without veins), its sweep-table
    layer ``lobe_layers[i]`` (default: the index of its :class:`~leafview.core.lobes.Lobes` among
    :func:`~leafview.gpu.lobe_tables.lobe_keys` of the species, as
    :meth:`LobeTables.update <leafview.gpu.lobe_tables.LobeTables.update>` returns it; -1
    unlobed). A lobed species draws no veins (its vein layer is -1)."""
    index: dict[tuple[Any, ...], int] = {}
    by_identity: dict[tuple[int, ...], int] = {}   # the same objects (shared by the species) hash once
    templates: list[LeafParams] = []
    template_of = np.empty(len(scene.species), np.int64)
    values: list[tuple[float, ...]] = []
    bends: dict[tuple[Any, ...], int] = {}         # distinct bend problems
    bent: list[tuple[int, int]] = []               # (species, bend problem)
    for i, sp in enumerate(scene.species):
        s, m, t = sp.shape, sp.material, sp.transform
        # the objects of the key are the species' own, alive as long as the scene: ids stay unique
        parts = (s if s.extended else s.half, sp.jitter, m.translucency, t, sp.ripple, sp.bending, sp.margin)
        ids = tuple(map(id, parts))
        k = by_identity.get(ids)
        if k is None:
            k = index.get(parts)
            if k is None:
                k = index[parts] = len(templates)
                templates.append(sp)
            by_identity[ids] = k
        template_of[i] = k
        (v1, x1, z1), (v2, x2, z2), (v3, x3, z3) = s.silhouette[:3]
        values.append((*s.a1, *s.a2, v1, v2, v3, x1, x2, x3, z1, z2, z3, *s.zf[:3], *s.zg[:3], *m.front, *m.back))
        if sp.bending.active:
            bent.append((i, bends.setdefault((s, sp.bending, t.rotation, t.scale), len(bends))))
    unbent = Bending()
    recs_t, table = pack_leaves([t.replace(bending=unbent) if t.bending.active else t for t in templates])
    recs = recs_t[template_of]
    if len(recs):
        col = np.asarray(values, np.float64).astype(np.float32)
        for j, name in enumerate(("a1", "a2", "vbar", "xs", "zs", "zf", "zg", "front", "back")):
            recs[name][:, :3] = col[:, 3 * j:3 * j + 3]
        write_texture_layers(recs, texture_layers(scene.species))
        if lobe_layers is None:
            layer_of = {k: i for i, k in enumerate(lobe_keys(scene.species))}
            lobe_layers = np.array([layer_of.get(sp.lobes, -1) if sp.lobes.enabled else -1 for sp in scene.species],
                                   np.int32)
        veins = np.array(fresh_layers(scene.species) if vein_layers is None else vein_layers, np.int32)
        lobed = np.asarray(lobe_layers) >= 0
        veins[np.broadcast_to(lobed, veins.shape)] = -1   # a swept surface has no veins
        write_vein_layers(recs, veins)
        write_lobe_layers(recs, np.asarray(lobe_layers, np.int32))
    if bent:
        first: dict[int, int] = {}                 # bend problem -> the first species that poses it
        for i, b in bent:
            first.setdefault(b, i)
        profiles = bend_profiles([scene.species[first[b]] for b in range(len(bends))])
        for i, b in bent:
            p, rec = profiles[b], recs[i]
            write_slot(rec, "leaf_bend_on", 1.0)
            rec["bend_axis"][:3] = p.axis
            write_slot(rec, "leaf_twist", p.twist)
            rec["bend"][:, :3] = p.delta
            rec["bend"][:, 3] = p.phi
    return recs, table, ripple_keys(templates)


# Ω's members in LEAF_BLOCK order and, for each, the columns of Scene.factors (VARIED order) that scale them
_OMEGA_MEMBERS = ("a1", "a2", "vbar", "xs", "zs", "zf", "zg")
_OMEGA_FACTORS = np.array([0, 1, 2, 3, 4, 5, 6, 9, 12, 7, 10, 13, 8, 11, 14, 15, 16, 17, 18, 19, 20])
_PACK_CHUNK = 2048     # rows packed at once (1.6 MB of records)
# the factor columns of Ω's members as vec4s: column 21 (a column of ones) for each w
_OMEGA_PADDED = np.insert(_OMEGA_FACTORS.reshape(len(_OMEGA_MEMBERS), 3), 3, _OMEGA_FACTORS.size, axis=1).ravel()
_COLOUR_LOW = np.array([0, 0, 0, -np.inf] * 2, np.float32)   # front and back: rgb in [0, 1], w left alone
_COLOUR_HIGH = np.array([1, 1, 1, np.inf] * 2, np.float32)


def _run_start(recs: NDArray[Any], members: Sequence[str]) -> int:
    """Byte offset in a LEAF_BLOCK record of the consecutive vec4 ``members``."""
    fields = recs.dtype.fields
    assert fields is not None
    first = int(fields[members[0]][1])
    assert [int(fields[m][1]) for m in members] == list(range(first, first + 16 * len(members), 16)), members
    return first


def _vec4_run(recs: NDArray[Any], members: Sequence[str]) -> NDArray[np.float32]:
    """(N, len(members), 4) float32 view of consecutive vec4 members of LEAF_BLOCK records."""
    return np.ndarray((len(recs), len(members), 4), np.float32, recs, _run_start(recs, members),
                      (recs.dtype.itemsize, 16, 4))


def _float_run(recs: NDArray[Any], members: Sequence[str]) -> NDArray[np.float32]:
    """The same floats as :func:`_vec4_run`, (N, 4·len(members)): one contiguous run a row."""
    return np.ndarray((len(recs), 4 * len(members)), np.float32, recs, _run_start(recs, members),
                      (recs.dtype.itemsize, 4))


def pack_scene(scene: Scene, start: int = 0, stop: int | None = None,
               species_records: NDArray[Any] | None = None, out: NDArray[Any] | None = None) -> NDArray[Any]:
    """LEAF_BLOCK rows of leaves ``start:stop``, vectorised: the species' record with Ω scaled by
    the leaf's factors plus its offsets (``Scene.offsets``, scene-wide edits; as
    :func:`leafview.scene.spec.vary_shape`), colours by its tint and the model matrix set, and its
    variety (:mod:`leafview.scene.variety`): ripple amplitude P × its factor and phase θ + its
    offset on both sides, and, for a species with a bend load range, the bend samples Δ, Φ
    interpolated at its load factor between the species' solved loads
    (:func:`~leafview.scene.variety.interpolate_bend`, the same numbers as
    :func:`leafview.scene.spec.leaf_bend`). Derived members are filled later by the prepare pass
    on the GPU. ``out``: records to write into (at least ``stop - start``; the first ones are
    returned), so that the batches of a large scene reuse one host array.

    Rows are filled :data:`_PACK_CHUNK` at a time, so that each chunk's several passes run in
    the CPU's cache, and copied from the species' records as bytes (several times faster than
    field by field)."""
    stop = len(scene) if stop is None else stop
    if species_records is None:
        species_records = species_tables(scene)[0]
    n = stop - start
    recs = np.empty(n, LEAF_BLOCK.dtype) if out is None else out[:n]
    row = np.dtype((np.void, LEAF_BLOCK.nbytes))
    source = np.ascontiguousarray(species_records).view(row)
    loads = load_table(scene.species, scene.spec.varieties) if scene.load_scale is not None else None
    p_max = np.float32(1.0)   # the ripple amplitude's hard maximum (leafview.scene.variety.leaf_ripple)
    factors = np.ones((_PACK_CHUNK, _OMEGA_FACTORS.size + 1), np.float32)   # the last column: the w's 1
    tints = np.empty((_PACK_CHUNK, 8), np.float32)                            # each row: tint × 3, 1, tint × 3, 1
    for a in range(0, n, _PACK_CHUNK):
        b = min(a + _PACK_CHUNK, n)
        part = recs[a:b]
        np.take(source, scene.species_id[start + a:start + b], axis=0, out=part.view(row))
        # Ω's seven vec4s as one run of 28 floats a row, scaled by the factors with 1 in the w's
        # (which hold layers, exact under × 1): one contiguous inner loop a row, not seven of three
        factors[:b - a, :_OMEGA_FACTORS.size] = scene.factors[start + a:start + b]
        _float_run(part, _OMEGA_MEMBERS)[...] *= factors[:b - a, _OMEGA_PADDED]
        omega = _vec4_run(part, _OMEGA_MEMBERS)[:, :, :3]
        if scene.offsets is not None:   # scene-wide edits: Ω = species × factors + offsets
            omega += scene.offsets[start + a:start + b][:, _OMEGA_FACTORS].reshape(b - a, len(_OMEGA_MEMBERS), 3)
        vbar = omega[:, _OMEGA_MEMBERS.index("vbar")]
        np.clip(vbar, np.float32(0.02), np.float32(0.98), out=vbar)
        for k in (1, 2):   # the feet stay in order, as vary_shape keeps them
            np.maximum(vbar[:, k], vbar[:, k - 1] + np.float32(VBAR_GAP), out=vbar[:, k])
        # front and back as 8 floats a row: rgb × tint clipped to [0, 1], the w's (translucency,
        # drawn half) × 1 and clipped to ±inf, unchanged
        colours = _float_run(part, ("front", "back"))
        tints[:b - a] = scene.tint[start + a:start + b, None]
        tints[:b - a, 3::4] = 1.0
        colours *= tints[:b - a]
        np.clip(colours, _COLOUR_LOW, _COLOUR_HIGH, out=colours)
        # rows 0-2 of each column: the last row keeps the species' texture and vein layers (LEAF_SLOTS)
        part["model"][:, :, :3] = np.transpose(scene.matrices[start + a:start + b, :3], (0, 2, 1))
        _write_variety(scene, part, start + a, start + b, loads, p_max)
    return recs


def pack_rows(scene: Scene, start: int, stop: int, species_records: NDArray[Any], out: NDArray[Any]) -> NDArray[Any]:
    """:func:`pack_scene` of leaves ``start:stop`` into ``out``, a large run on two threads
    (:func:`leafview.scene.threads.in_two_threads`; rows are packed one by one, so the bytes are
    those of one call)."""
    rows = out[:stop - start]
    in_two_threads(stop - start, lambda a, b: pack_scene(scene, start + a, start + b, species_records, out=rows[a:b]))
    return rows


def _write_variety(scene: Scene, part: NDArray[Any], a: int, b: int, loads: Any, p_max: np.float32) -> None:
    """Leaves ``a:b``'s variety into their rows ``part`` (see :func:`pack_scene`)."""
    ripples = _vec4_run(part, ("ripple_l", "ripple_r"))    # (n, 2, 4): P, λ, k, θ of each side
    if scene.ripple_scale is not None:
        amp = ripples[:, :, 0]
        amp *= scene.ripple_scale[a:b, None]
        np.minimum(amp, p_max, out=amp)
    if scene.ripple_phase is not None:
        ripples[:, :, 3] += scene.ripple_phase[a:b, None]
    if loads is not None and scene.load_scale is not None:
        which, phi, delta = interpolate_bend(loads, scene.species_id[a:b], scene.load_scale[a:b])
        if which.size:
            bend = part["bend"]
            bend[which, :, :3] = delta
            bend[which, :, 3] = phi


def _lod_error(params: Any, coarse: tuple[int, int], fine: tuple[int, int] = DEFAULT_GRID) -> float:
    """Largest distance (leaf lengths) between the surface and the piecewise-bilinear surface
    through the ``coarse`` grid, sampled at the ``fine`` grid: how far the drawn outline can
    move when a leaf drops to ``coarse``. The surface is the drawn one
    (:func:`leafview.botany.leaf_surface.evaluate`: a lobed leaf's sweep at the grids given, which
    for a lobed leaf should be lobed grids)."""
    uv = grid_uv(*fine).astype(np.float64)
    ref = leaf_surface.evaluate(params, uv[:, 0], uv[:, 1])
    cu, cv = coarse
    g = leaf_surface.evaluate(params, *grid_uv(cu, cv).astype(np.float64).T).reshape(cv, cu, 3)
    x = (uv[:, 0] + 1.0) / 2.0 * (cu - 1)
    y = uv[:, 1] * (cv - 1)
    i = np.minimum(x.astype(int), cu - 2)
    j = np.minimum(y.astype(int), cv - 2)
    a, b = (x - i)[:, None], (y - j)[:, None]
    approx = ((1 - a) * (1 - b) * g[j, i] + a * (1 - b) * g[j, i + 1]
              + (1 - a) * b * g[j + 1, i] + a * b * g[j + 1, i + 1])
    return float(np.linalg.norm(ref - approx, axis=1).max())


def species_cull(scene: Scene, grids: Sequence[tuple[int, int]] = LOD_GRIDS) -> NDArray[Any]:
    """SPECIES_CULL_BLOCK rows, the numpy reference: every unlobed species evaluated at every
    level's grid as drawn (:func:`leafview.deform.surface.evaluate` at
    :func:`~leafview.deform.surface.drawn_uv`, with the species' vein grid), every lobed one at
    every grid of :func:`lobed_levels` (:func:`leafview.botany.leaf_surface.evaluate`, its sweep),
    then :func:`cull_rows_from_points`, each kind on its own grids.

    A lobed species' row: no variation (its leaves keep its shape), ``lod_error[0]`` its grid group
    (1) and :data:`LOD_NEVER` at the levels beyond its own.
    :class:`SceneRenderer` computes the same rows on the GPU (:mod:`leafview.gpu.bounds`)."""
    if len(grids) > 4:
        raise ValueError("at most 4 levels of detail")
    lobed = lobed_species(scene)
    out = np.zeros(len(scene.species), SPECIES_CULL_BLOCK.dtype)
    plain = [sp for sp, lb in zip(scene.species, lobed) if not lb]
    if plain:
        veins = [shape_grid(sp) for sp in plain]
        points = [np.stack([evaluate(sp, *drawn_uv(sp, grid_uv(*g)).T, vein_grid=vg) for sp, vg in zip(plain, veins)])
                  for g in grids]
        out[~lobed] = cull_rows_from_points(points, grids, scene.spec.variation)
    if lobed.any():
        lgrids = lobed_levels(grids)
        swept = [sp for sp, lb in zip(scene.species, lobed) if lb]
        points = [np.stack([leaf_surface.evaluate(sp, *grid_uv(*g).astype(np.float64).T) for sp in swept])
                  for g in lgrids]
        out[lobed] = mark_lobed(cull_rows_from_points(points, lgrids, 0.0), len(lgrids))
    out["sphere"][:, 3] += sphere_padding(scene.species, scene.spec.varieties, out["sphere"], scene.spec.variation)
    return out


def mark_lobed(rows: NDArray[Any], levels: int) -> NDArray[Any]:
    """Culling ``rows`` of lobed species made theirs: grid group 1 in ``lod_error[0]`` and
    :data:`LOD_NEVER` at levels ``levels`` and up (in place; returned)."""
    rows["lod_error"][:, 0] = LOBED_GROUP
    rows["lod_error"][:, levels:] = LOD_NEVER
    return rows


def cull_rows_from_points(points: Sequence[NDArray[Any]], grids: Sequence[tuple[int, int]],
                          variation: float) -> NDArray[Any]:
    """SPECIES_CULL_BLOCK rows of S species from their leaf-space points at each level's grid
    (``points[k]``: (S, nu_k·nv_k, 3), :func:`~leafview.deform.surface.grid_uv` order), vectorised
    over species.

    * ``sphere``: centre of the box of the coarsest level's points, radius to the farthest point
      of any level (every drawn vertex is inside), widened for the variation and by 1e-3.
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
    center = (pts[-1].min(axis=1) + pts[-1].max(axis=1)) / 2
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
                   settings: CullSettings = CullSettings(), levels: int = len(LOD_GRIDS),
                   lobed: int | None = None) -> NDArray[np.int32]:
    """The level each leaf gets (-1: culled), computed in numpy exactly as ``scene_cull.comp``:
    among ``levels`` levels for a species of grid group 0, ``lobed`` for a lobed one (default: the
    levels of :func:`lobed_levels` of the first ``levels`` :data:`LOD_GRIDS`; a forced level is
    clamped to the group's last)."""
    m = scene.matrices
    sc = cull_rows[scene.species_id]
    if lobed is None:
        lobed = len(lobed_levels(LOD_GRIDS[:levels]))
    own = np.where(sc["lod_error"][:, 0] >= LOBED_GROUP, lobed, levels)
    center = np.einsum("nij,nj->ni", m[:, :3, :3], sc["sphere"][:, :3]) + m[:, :3, 3]
    scale = np.linalg.norm(m[:, :3, 0], axis=1)
    radius = sc["sphere"][:, 3] * scale
    ppu = np.full(len(scene), _pixel_scale(camera, size))
    if camera.perspective:
        ppu = ppu / np.maximum(np.linalg.norm(center - camera.eye[:3], axis=1) - radius, 1e-4)
    level = np.minimum(max(settings.forced_level, 0), own - 1).astype(np.int32)
    if settings.forced_level < 0:
        for k in range(1, max(levels, lobed)):
            ok = (level == k - 1) & (k < own) & (sc["lod_error"][:, k] * scale * ppu <= settings.max_error_px)
            level[ok] = k
    if settings.cull:
        planes = frustum_planes(camera.proj @ camera.view)
        inside = np.all(center @ planes[:, :3].T + planes[:, 3] >= -radius[:, None], axis=1)
        level[~inside | (2.0 * radius * ppu < settings.min_pixels)] = -1
    return level


# -- GPU ----------------------------------------------------------------------------------------
class _SceneBatch:
    """GL objects of one batch of leaves: rows, species ids, the per-level visible lists, the draw
    commands, the vertex array that reads the visible leaves' vertex records (in the renderer's
    :attr:`SceneRenderer.vertices`, which every batch overwrites in turn) and, when a species
    takes an optional branch, the rows as texels."""

    def __init__(self, owner: SceneRenderer, start: int, stop: int) -> None:
        ctx = owner.ctx
        self.start, self.count = start, stop - start
        self._objects = GLObjects()
        try:
            assert owner._host_rows is not None
            rows = pack_rows(owner.scene, start, stop, owner.species_records, owner._host_rows)
            self.rows = self._objects.own(ctx.buffer(rows))
            owner.resources.prepare.run(self.rows, self.count)
            # the members of ripples, bends and extended silhouettes as texels, when a species has one
            self.row_texture = (self._objects.own(RowTexture(ctx, self.rows, self.count))
                                if needs_row_texture(owner.species_records) else None)
            self.species_of = self._objects.own(
                ctx.buffer(owner.scene.species_id[start:stop].astype(np.uint32)))
            levels = len(owner.command_grids)
            self.visible = self._objects.own(ctx.buffer(reserve=4 * self.count * levels))
            self.vertices = owner.vertices   # the renderer's, shared by the batches (not owned here)
            self.reset = np.zeros(levels, DRAW_COMMAND_DTYPE)
            self.reset["count"] = owner.index_counts
            self.reset["first_index"] = owner.first_index
            self.reset["base_vertex"] = owner.base_vertex
            self.reset["base_instance"] = np.arange(levels) * self.count
            self.commands = self._objects.own(ctx.buffer(self.reset.tobytes()))
            self.vao = self._objects.own(record_vertex_array(ctx, owner.program, owner.uv_vbo, self.vertices,
                                                             LEAF_VERTEX_BLOCK, owner.ibo))
        except BaseException:
            self.release()
            raise

    def use_rows(self) -> None:
        """Bind what ``leaf.vert`` reads of the rows besides the vertex records (the row texture)."""
        if self.row_texture is not None:
            self.row_texture.use()

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
    veins: species whose venation is enabled show veins (False: none does; ``--veins off``, no
        vein field is built). :attr:`show_veins` turns them off and on again per frame (the
        viewer's checkbox), drawing a ``LEAF_NO_VEINS`` program variant while off.

    Lobed species are drawn on :attr:`lobed_grids` (empty without one), whose draw commands follow
    the levels' in every batch: :attr:`command_grids` is the grid of each command.

    Raises :class:`SceneLimitError` when the rows cannot fit the context's limits; checks
    ``ctx.error`` after allocating so an out-of-memory is reported, not ignored.
    """

    def __init__(self, ctx: moderngl.Context, scene: Scene, *, grids: Sequence[tuple[int, int]] = LOD_GRIDS,
                 max_block_bytes: int | None = None, progress: Callable[[int], None] | None = None,
                 resources: GpuResources | None = None, veins: bool = True) -> None:
        self.ctx, self.scene = ctx, scene
        # the world box of the leaf bases and stems (placement never changes after upload: edits change
        # Ω only): the shadow and ground passes frame on it every frame without an O(N) pass
        self.bounds: tuple[NDArray[np.float64], NDArray[np.float64]] = scene.bounds()
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
            # the species' image files, read (a missing or unreadable one raises ParamError naming the
            # leaf and the file) and uploaded as one array texture before any row is packed
            self.textures = self._objects.own(LeafTextures(ctx))
            self.textures.update(scene.species)
            # the species' vein fields (one layer per distinct shape and venation), before the rows too
            self.veins = self._objects.own(VeinDraw(ctx, self.resources.programs))
            self.show_veins = veins   # False: draws without veins (a LEAF_NO_VEINS variant), fields kept
            layers = self.veins.update(scene.species, enabled=veins)
            # the lobed species' sweep tables, one array texture for the whole scene
            self.lobes = self._objects.own(LobeTables(ctx))
            lobe_layers = self.lobes.update(scene.species)
            self.lobed = lobe_layers >= 0
            self.lobed_grids: tuple[tuple[int, int], ...] = lobed_levels(self.grids) if self.lobed.any() else ()
            self.command_grids = self.grids + self.lobed_grids
            self.species_records, table, keys = species_tables(scene, layers, lobe_layers)
            self.program = self.resources.leaf_program({"LEAF_INDIRECT": 1, **self._defines()})
            self.cull = self.resources.programs.compute("scene_cull.comp")
            self.compact = self.resources.programs.compute("scene_compact.comp")
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
            for nu, nv in self.command_grids:
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
            # one host array reused for every batch's rows (a 10⁶-leaf scene packs 7 batches)
            largest = max((b - a for a, b in self.plan), default=0)
            self._host_rows: NDArray[Any] | None = np.empty(largest, LEAF_BLOCK.dtype)
            # the visible leaves' vertex records: one buffer for every batch, each batch's culling pass
            # writes its records just before its draw reads them (34 MB for 10⁶ leaves, not 240 MB of
            # fresh driver memory faulted in every frame)
            self.vertices = self._objects.own(ctx.buffer(reserve=LEAF_VERTEX_BLOCK.nbytes * max(largest, 1)))
            for start, stop in self.plan:
                ensure_alive(ctx, f"uploading leaves {start:,}..{stop:,} of {len(scene):,}")
                self.batches.append(_SceneBatch(self, start, stop))
                err = ctx.error
                if err != "GL_NO_ERROR":
                    raise SceneLimitError(f"allocating leaves {start}..{stop} of {len(scene)} failed with {err} "
                                          f"({(stop - start) * LEAF_BLOCK.nbytes:,} bytes of rows)")
                if progress is not None:
                    progress(stop - start)
            self._host_rows = None
        except BaseException:
            self.release()
            raise

    def _species_cull(self, records: NDArray[Any]) -> NDArray[Any]:
        """:func:`species_cull` of the species ``records``, computed on the GPU
        (:class:`~leafview.gpu.bounds.LeafBounds`: one dispatch evaluates every record at every
        level's grid with the vertex shader's code; a record costs microseconds there, less than
        finding duplicates would)."""
        self._bind_tables()
        out = np.zeros(len(records), SPECIES_CULL_BLOCK.dtype)
        for lobed in (False, True):
            mine = self.lobed == lobed
            if not mine.any():
                continue
            recs = records[mine] if lobed or self.lobed.any() else records
            grids = self.lobed_grids if lobed else self.grids
            bounds = LeafBounds(self.ctx, self.resources.programs, self.resources.prepare, grids)
            # a lobed species' shape does not vary (pack_scene): its sphere and errors are its own
            rows = bounds.run(recs, 0.0 if lobed else self.scene.spec.variation,
                              {**feature_defines(recs), **vein_defines(recs), **lobe_defines(recs)},
                              block_limit=self._block_limit)
            out[mine] = mark_lobed(rows, len(grids)) if lobed else rows
        # per-leaf variety (ripple amplitude, bend load) can carry a leaf beyond its species' sphere
        out["sphere"][:, 3] += sphere_padding(self.scene.species, self.scene.spec.varieties, out["sphere"],
                                              self.scene.spec.variation)
        return out

    def _defines(self) -> dict[str, int]:
        """The feature defines of this scene's leaf programs (vertex branches, textures, veins, and
        ``LEAF_NO_LOBES`` without a lobed species)."""
        recs = self.species_records
        return {**feature_defines(recs), **texture_defines(recs), **vein_defines(recs), **lobe_defines(recs)}

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
        vbo = self._objects.own(self.ctx.buffer(verts))   # the arrays' own bytes, no copies
        ibo = self._objects.own(self.ctx.buffer(np.ascontiguousarray(tris, np.uint32)))
        self._stem_buffers = (vbo, ibo)
        return self._stem_vao(self.resources.programs.program("leaf_baked.vert", "leaf.frag",
                                                              defines={**PLAIN_DEFINES, **NO_VEIN_DEFINES}))

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
            prog = self.resources.leaf_program({"LEAF_INDIRECT": 1, **self._defines(), **defines})
            vaos = [self._objects.own(record_vertex_array(self.ctx, prog, self.uv_vbo, b.vertices, LEAF_VERTEX_BLOCK,
                                                          self.ibo))
                    for b in self.batches]
            stems = None
            if self._stem_buffers is not None:
                stems = self._stem_vao(self.resources.programs.program(
                    "leaf_baked.vert", "leaf.frag",
                    defines={**defines, **PLAIN_DEFINES, **NO_VEIN_DEFINES, "LEAF_STEMS": 1}))
            found = self._variants[key] = (prog, vaos, stems)
        return found

    # -- per frame ---------------------------------------------------------------------------
    def set_camera(self, camera: Camera, size: tuple[int, int], *, srgb: bool = True,
                   lighting: type[Lighting] = Lighting) -> None:
        self.camera, self.size = camera, (int(size[0]), int(size[1]))
        self.frame.set_camera(camera, srgb=srgb, lighting=lighting, size=self.size)

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
        s["group_levels"] = (len(self.grids), len(self.lobed_grids))
        s["group_first"] = (0, len(self.grids))
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
        self.ctx.memory_barrier(moderngl.SHADER_STORAGE_BARRIER_BIT)
        self._compact(batch.rows, batch.commands, batch.visible, batch.vertices, batch.count,
                      len(self.command_grids))

    def _compact(self, rows: moderngl.Buffer, commands: moderngl.Buffer, visible: moderngl.Buffer,
                 vertices: moderngl.Buffer, stride: int, levels: int) -> None:
        """``scene_compact.comp``: the vertex records of the ``levels`` lists of ``visible`` (level k's
        from entry ``k · stride``, as many as its command counts), rows read from ``rows``, into
        ``vertices``; each command's ``baseInstance`` set to its level's first record."""
        c = self.compact
        c["stride"] = stride
        c["levels"] = levels
        rows.bind_to_storage_buffer(LEAVES_BINDING)
        commands.bind_to_storage_buffer(COMMANDS_BINDING)
        visible.bind_to_storage_buffer(VISIBLE_BINDING)
        vertices.bind_to_storage_buffer(VERTICES_BINDING)
        c.run(group_x=-(-stride // _LOCAL))
        self.ctx.memory_barrier(moderngl.COMMAND_BARRIER_BIT | moderngl.VERTEX_ATTRIB_ARRAY_BARRIER_BIT
                                | moderngl.SHADER_STORAGE_BARRIER_BIT | moderngl.BUFFER_UPDATE_BARRIER_BIT)

    def _bind_tables(self) -> None:
        self.frame.bind()
        self.jitter.use()
        self.ripples.bind()
        self.textures.use()
        self.veins.use()
        self.lobes.use()

    def draw(self, settings: CullSettings = CullSettings(), *, defines: Mapping[str, object] | None = None,
             batches: Sequence[int] | None = None) -> None:
        """Cull and draw every batch (and the stems) into the bound framebuffer. A context
        released or lost before or between batches raises :class:`~leafview.errors.GLContextLost`.
        ``batches``: the indices (into :attr:`batches`) of those to cull and draw (None: all); the
        vertex records in :attr:`vertices` after a draw are those of the last batch drawn.

        ``defines``: extra feature defines of a program variant to draw with (e.g. ``LEAF_AOV``,
        the label pass of :mod:`leafview.gpu.aov`); a variant whose vertex shader declares
        :data:`~leafview.gpu.layout.LEAF_OFFSET_UNIFORM` gets each batch's first leaf there.

        Veined scenes draw their finest level with the vein field and the coarser levels (leaves
        too small on screen for their veins) with the ``LEAF_VEIN_SKIN`` variant, two indirect
        draws a batch; with :attr:`show_veins` off, the ``LEAF_NO_VEINS`` variant, one. Lobed
        leaves (no veins) are drawn by the same multi-draws: their commands follow the levels'
        (in the second draw of a veined scene)."""
        ensure_alive(self.ctx, "drawing a scene")
        levels = len(self.grids)
        commands = len(self.command_grids)
        far: tuple[moderngl.Program, list[moderngl.VertexArray], Any] | None = None
        if self.veins.active and not self.show_veins:
            defines = {**(defines or {}), **NO_VEIN_DEFINES}
        elif self.veins.active and levels > 1 and "LEAF_AOV" not in (defines or {}):
            # the finest level with its veins, the coarser ones (leaves too small for them) without
            far = self._variant({**(defines or {}), **VEIN_SKIN_DEFINES})
        program, vaos, stems = self._variant(defines)
        offsets = [p.get(LEAF_OFFSET_UNIFORM, None) for p in (program, *(far[:1] if far else ()))]
        self.ctx.enable_only(moderngl.DEPTH_TEST)
        self._bind_tables()
        if stems is not None:
            stems.render(moderngl.TRIANGLES)
        self._set_cull_uniforms(settings)
        chosen = None if batches is None else {int(i) for i in batches}
        for i, (batch, vao) in enumerate(zip(self.batches, vaos)):
            if chosen is not None and i not in chosen:
                continue
            ensure_alive(self.ctx, f"drawing batch {i + 1} of {len(self.batches)}")
            self._cull(batch)
            batch.use_rows()
            for offset in offsets:
                if isinstance(offset, moderngl.Uniform):
                    offset.value = batch.start
            if far is None:
                vao.render_indirect(batch.commands, moderngl.TRIANGLES, count=commands)
            else:
                vao.render_indirect(batch.commands, moderngl.TRIANGLES, count=1)
                far[1][i].render_indirect(batch.commands, moderngl.TRIANGLES, count=commands - 1, first=1)

    def level_counts(self) -> NDArray[np.int64]:
        """Leaves drawn by each draw command in the last :meth:`draw` (reads the commands back):
        the levels of :attr:`grids`, then those of :attr:`lobed_grids` (:attr:`command_grids`)."""
        ensure_alive(self.ctx, "reading the draw commands back")
        total = np.zeros(len(self.command_grids), np.int64)
        for batch in self.batches:
            total += np.frombuffer(batch.commands.read(), DRAW_COMMAND_DTYPE)["instance_count"]
        return total

    def levels(self) -> NDArray[np.int32]:
        """Each leaf's level in the last :meth:`draw` (-1: culled), read back from the lists: of
        :attr:`grids`, or of :attr:`lobed_grids` for a lobed leaf (as :func:`cull_reference`)."""
        ensure_alive(self.ctx, "reading the visible lists back")
        out = np.full(len(self.scene), -1, np.int32)
        for batch in self.batches:
            counts = np.frombuffer(batch.commands.read(), DRAW_COMMAND_DTYPE)["instance_count"]
            vis = np.frombuffer(batch.visible.read(), np.uint32)
            for k, c in enumerate(counts):
                level = k if k < len(self.grids) else k - len(self.grids)
                out[batch.start + vis[k * batch.count:k * batch.count + int(c)]] = level
        return out

    def triangles(self, counts: NDArray[np.int64] | None = None) -> int:
        """Leaf triangles drawn in the last :meth:`draw`, from ``counts`` (as
        :meth:`level_counts` returned them; counts of only the first commands, e.g. of the
        levels of :attr:`grids`, count those) or read back."""
        counts = self.level_counts() if counts is None else np.asarray(counts)
        per = np.array([2 * (nu - 1) * (nv - 1) for nu, nv in self.command_grids[:len(counts)]])
        return int(counts @ per)

    def capture_grid(self, leaves: Sequence[int] | NDArray[np.integer[Any]], level: int = 0) -> tuple[int, int]:
        """The grid :meth:`capture` evaluates ``leaves`` on at ``level``: ``grids[level]``, or for
        lobed leaves ``lobed_grids[level]`` (their last level at most, as the culling pass clamps
        a forced level). Raises ValueError when ``leaves`` mix lobed and unlobed species."""
        picks = np.asarray(list(leaves), dtype=np.int64).reshape(-1)
        kinds = set(self.lobed[self.scene.species_id[picks]].tolist()) if picks.size else {False}
        if len(kinds) > 1:
            raise ValueError("leaves: lobed and unlobed leaves are drawn on different grids; capture them apart")
        if kinds == {True}:
            return self.lobed_grids[min(int(level), len(self.lobed_grids) - 1)]
        return self.grids[level]

    def capture(self, leaves: Sequence[int], level: int = 0, *,
                defines: Mapping[str, object] | None = None) -> NDArray[np.float32]:
        """Leaf-space positions that ``leaf.vert`` computes for the given leaves at ``level``'s
        grid (:meth:`capture_grid`: lobed leaves on their own) (transform feedback of the drawing
        program reading the vertex records that ``scene_compact.comp`` writes, one instanced
        capture per batch): (len(leaves), nu·nv, 3). The framebuffer binding is left as it was.
        ``defines``: the program variant of ``draw(defines=...)`` to capture (e.g. ``LEAF_WIND``,
        whose leaves move; its blocks bound by the caller), with each batch's first leaf in
        :data:`~leafview.gpu.layout.LEAF_OFFSET_UNIFORM` as a draw sets it."""
        picks = np.asarray(list(leaves), dtype=np.int64).reshape(-1)
        if picks.size and (picks.min() < 0 or picks.max() >= len(self.scene)):
            raise IndexError(f"leaf index out of range 0..{len(self.scene) - 1}")
        grid = self.resources.grid(*self.capture_grid(picks, level))
        nverts = grid.vertices
        order: list[NDArray[np.int64]] = []
        program = self._variant(defines)[0] if defines else self.program
        offset = program.get(LEAF_OFFSET_UNIFORM, None)
        self._bind_tables()
        with self.resources.capture.recording(picks.size * nverts) as rec:
            for b in self.batches:
                mine = np.flatnonzero((picks >= b.start) & (picks < b.start + b.count))
                if not mine.size:
                    continue
                # the picks as one level's list, through the same compaction and vertex records as a draw
                command = np.zeros(1, DRAW_COMMAND_DTYPE)
                command["instance_count"] = mine.size
                local = GLObjects()
                try:
                    ids = local.own(self.ctx.buffer((picks[mine] - b.start).astype(np.uint32).tobytes()))
                    commands = local.own(self.ctx.buffer(command.tobytes()))
                    vertices = local.own(self.ctx.buffer(reserve=LEAF_VERTEX_BLOCK.nbytes * mine.size))
                    self._compact(b.rows, commands, ids, vertices, int(mine.size), 1)
                    vao = local.own(record_vertex_array(self.ctx, program, grid.vbo, vertices,
                                                        LEAF_VERTEX_BLOCK))
                    if isinstance(offset, moderngl.Uniform):
                        offset.value = b.start
                    b.use_rows()
                    rec.add(vao, nverts, instances=mine.size)
                finally:
                    local.release()
                order.append(mine)
            pos, _ = rec.read()
        out = np.empty((picks.size, nverts, 3), np.float32)
        if order:
            out[np.concatenate(order)] = pos.reshape(-1, nverts, 3)
        return out

    def render(self, camera: Camera, size: tuple[int, int], settings: CullSettings = CullSettings(), *,
               samples: int = 4, background: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
               flat: bool = False) -> NDArray[np.uint8]:
        """One frame offscreen: (h, w, 4) uint8 RGBA, row 0 at the top (a render target of the
        shared resources, resolved when multisampled); ``flat``: unlit colours (tests)."""
        ctx = self.ctx
        size = (int(size[0]), int(size[1]))
        ensure_alive(ctx, "rendering a scene")
        target = self.resources.target(size, min(int(samples), int(ctx.max_samples)))
        target.use()
        ctx.viewport = (0, 0, *size)
        target.clear(background)
        self.set_camera(camera, size)
        if flat:   # the same frame, lighting off
            self.frame.set_camera(camera, flat=True, size=size)
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
    each level (no MSAA), and the Hausdorff distance between the two coverage masks is taken
    (a lobed preset among its own levels, :func:`lobed_levels`)."""
    worst = 0.0
    for name in presets:
        params = LeafParams.load(resolve_preset(name))
        scene = single_leaf_scene(params)
        with SceneRenderer(ctx, scene, grids=grids) as r:
            pts = leaf_surface.grid_points(params, DEFAULT_GRID)
            for k in range(1, len(r.lobed_grids if r.lobed[0] else grids)):
                err = float(r.cull_rows[0]["lod_error"][k])
                if err <= 0:
                    continue
                ppu = settings.max_error_px / err * (1.0 + 1e-6)   # pixels per leaf length at the switch
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
                    worst = max(worst, _farthest(a, b), _farthest(b, a))
    return worst


def _edge(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The pixels of ``mask`` with a 4-neighbour outside it (or on the image's border)."""
    p = np.pad(mask, 1)
    inner = p[1:-1, :-2] & p[1:-1, 2:] & p[:-2, 1:-1] & p[2:, 1:-1]
    return mask & ~inner


def _farthest(a: NDArray[np.bool_], b: NDArray[np.bool_]) -> float:
    """Largest distance (pixels) from a pixel of ``b`` to the nearest pixel of ``a`` (not empty):
    one half of the Hausdorff distance, the largest of ``b``'s values in the Euclidean distance
    transform of ``~a``. The nearest pixel of ``a`` to a pixel outside it is on ``a``'s edge (a
    step from an inner pixel towards the outside one stays in ``a`` and comes closer), so only the
    edge goes into the tree."""
    outside = b & ~a
    if not outside.any():
        return 0.0
    distance, _ = cKDTree(np.argwhere(_edge(a))).query(np.argwhere(outside))
    return float(np.max(distance))
