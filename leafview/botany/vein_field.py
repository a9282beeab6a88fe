"""The vein field of a leaf: for each texel of a square image over the blade's (u, v), the
distance to the nearest vein and what that vein is. The numpy twin of ``shaders/vein_field.comp``
(:mod:`leafview.gpu.vein_field` runs it, one array layer per species).

**Vein space.** Distances between veins are measured in q(u, v) = (u · w(v), v), where w(v) is the
half-width of the flat blade at v (:func:`halfwidth_table`): the mean over both sides of the arc
length of the cross-section (Chaurasia & Beardsley 2017, eqs 5-6) from the midrib (u = 0) to the
margin (|u| = 1), of the blade without jitter, ripple or bending. A step in q is a step of about
the same length on the leaf in either direction, so "0.01 from the vein" means the same on a
narrow willow and a round leaf; near the pinched base and apex w → 0 and the margin converges on
the midrib as the blade does. Segments are straight in q between their mapped end points.

**The field** (:func:`field_from_segments`; :func:`vein_field` for a leaf), RGBA float32, texel
(row j, column i) at the texel centre (s, t) = ((i + ½)/size, (j + ½)/size) with
(u, v) = :func:`leafview.core.texture.uv_of_st` (s, t), the convention of the image textures
(:func:`~leafview.core.texture.texture_st`: s = (1 - u)/2, t = 1 - v):

* R: distance in vein space (leaf lengths) from the texel to the nearest vein's centre line,
  capped at :data:`FIELD_CAP` (texels farther from every vein read the cap);
* G: that vein's order (1 midrib and primaries, 2 secondaries, 3 tertiaries and finer; 0 when no
  vein is nearer than the cap);
* B: that vein's width (leaf lengths; 0 when none);
* A: the distance to the nearest vein of order ≤ 2, capped the same way. The tertiary network
  is dense, so R alone says little about where the major veins run; A does: it shapes the relief
  (a ridge along the major veins only) and the reduced transmission in back light, which belong
  to the thick veins. R ≤ A everywhere; R < A where the nearest vein is a fine one.

**Tiles.** The texels are binned into :data:`TILE` × :data:`TILE` tiles, and each tile keeps only
the segments that can be nearest (or nearest of order ≤ 2) for one of its texels within the cap
(:func:`tile_lists`). With B the tile's box in q (:func:`tile_geometry`, holding all its texels),
a segment is between ``lower`` = its distance to B (0 when it crosses B) and ``upper`` = its
distance to B's farthest corner (distance to a segment is convex, so its largest value over B is
at a corner) of every texel. No texel of the tile is farther from its nearest segment than the
tile's least ``upper`` (taken over the segments within :data:`BOUND_REACH` of the tile: any
subset gives a valid bound, and the near ones give the tight ones), so a segment is kept when its
``lower`` is at most that (and at most the cap; over segments of order ≤ 2 for those). The result
equals the brute-force minimum over all segments (the tests check this); the GPU tests only its
tile's list at a texel.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.botany.vein_space import HALFWIDTH_SAMPLES, halfwidth_at, halfwidth_table, vein_space, vein_space_of
from leafview.botany.venation import vein_segments
from leafview.core.params import LeafParams
from leafview.deform.surface import vein_grid_uv
from leafview.errors import ParamError

__all__ = ["FIELD_SIZE", "FIELD_CAP", "BOUND_REACH", "HALFWIDTH_SAMPLES", "TILE", "MAX_FIELD_SIZE", "RECORD_FLOATS",
           "TileLists", "TileGeometry", "check_field_size", "halfwidth_table", "vein_space", "vein_space_of", "texel_uv",
           "texel_space", "segment_records", "segment_distance", "box_bounds", "tile_geometry", "tile_lists", "field_from_segments",
           "brute_force_field", "vein_field", "vein_key", "vein_keys", "vein_layers"]

FIELD_SIZE = 256
"""Texels per side of a field. A texel is 1/256 of a leaf length along v and 2 w(v)/256 (at most
about 0.003) across: linear filtering of a distance field is exact along a straight vein except
within a texel of its centre line, so the secondaries (0.006 wide by default) and the midrib
(0.012) keep their edges in a close-up, tertiaries (0.003) are about a texel, and finer veins
fall to the shader's footprint antialiasing. 256² fits the 5 ms a new species may take on
llvmpipe (about 3 ms of one core; 512² takes 8-10 ms: ``leafview bench veins``)."""
FIELD_CAP = 0.05
"""Largest distance the field records (leaf lengths in vein space): the farthest the shading
reads, a vein's half width plus a pixel's footprint at the coarsest level of detail that still
draws veins (about 4 midrib widths)."""
TILE = 8
"""Texels per side of a tile (one work group of ``vein_field.comp``); sizes are multiples of it."""
_SLACK = 1e-6       # tile pruning keeps segments within this of the bound (float32 on the GPU)
MAX_FIELD_SIZE = 2048
"""Largest field size accepted."""
BOUND_REACH = 0.02
"""How far from a segment's box the bound stage looks for tiles to bound (leaf lengths): any
reach gives valid bounds, and tiles no segment is that near keep the cap."""
RECORD_FLOATS = 8
"""A segment record: q0 (2), d = q1 - q0 (2), 1 / |d|² (0 for a point), order, width, 0."""


class TileLists(NamedTuple):
    """The segments each tile tests: tile k (row-major over the (size/TILE)² tiles, row 0 at
    t = 0) tests ``segments[starts[k]:starts[k] + counts[k]]``, ascending."""

    starts: NDArray[np.int32]
    counts: NDArray[np.int32]
    segments: NDArray[np.int32]


def check_field_size(size: int, path: str = "size") -> int:
    """``size`` as an int: a multiple of :data:`TILE` in [2 TILE, :data:`MAX_FIELD_SIZE`];
    raises :class:`ParamError` naming ``path`` otherwise."""
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)):
        raise ParamError(path, f"the field size is a whole number of texels, got {size!r}")
    n = int(size)
    if not 2 * TILE <= n <= MAX_FIELD_SIZE or n % TILE:
        raise ParamError(path, f"{n} texels: a field is a multiple of {TILE} texels between {2 * TILE} and "
                               f"{MAX_FIELD_SIZE}")
    return n


def texel_uv(size: int) -> NDArray[np.float64]:
    """(size, size, 2): the (u, v) of each texel centre, [row j, column i]."""
    return np.stack(vein_grid_uv(size, size), axis=-1)


def texel_space(table: ArrayLike, size: int) -> NDArray[np.float64]:
    """(size, size, 2): the vein-space point q of each texel centre."""
    return vein_space_of(table, texel_uv(size))


# -- segments ------------------------------------------------------------------------------------------
def segment_records(uv0: ArrayLike, uv1: ArrayLike, order: ArrayLike, width: ArrayLike,
                    table: ArrayLike) -> NDArray[np.float32]:
    """(M, :data:`RECORD_FLOATS`) float32: the segments from ``uv0`` to ``uv1`` (M, 2) mapped to vein
    space, as the shader reads them (q0, d = q1 - q0, 1/|d|², order, width, 0)."""
    a, b = np.asarray(uv0, np.float64).reshape(-1, 2), np.asarray(uv1, np.float64).reshape(-1, 2)
    order_ = np.asarray(order).reshape(-1)
    width_ = np.asarray(width).reshape(-1)
    if not len(a) == len(b) == len(order_) == len(width_):
        raise ValueError(f"segment arrays of different lengths: {len(a)}, {len(b)}, {len(order_)}, {len(width_)}")
    rec = np.zeros((len(a), RECORD_FLOATS), np.float32)
    q0 = vein_space_of(table, a).astype(np.float32)
    d = vein_space_of(table, b).astype(np.float32) - q0
    dd = (d.astype(np.float64) ** 2).sum(axis=1)
    rec[:, 0:2], rec[:, 2:4] = q0, d
    rec[:, 4] = np.divide(1.0, dd, out=np.zeros_like(dd), where=dd > 0.0)
    rec[:, 5], rec[:, 6] = order_, width_
    return rec


def segment_distance(q: ArrayLike, rec: ArrayLike) -> NDArray[np.float64]:
    """Distance from the points ``q`` (..., 2) to the segment records ``rec`` (..., 8) (broadcast):
    h = clamp((q - q0)·d / |d|², 0, 1), |q - q0 - h d|."""
    p = np.asarray(q, np.float64)
    r = np.asarray(rec, np.float64)
    e = p - r[..., 0:2]
    h = np.clip((e * r[..., 2:4]).sum(-1) * r[..., 4], 0.0, 1.0)
    f = e - h[..., None] * r[..., 2:4]
    return np.sqrt((f * f).sum(-1))


# -- tiles ---------------------------------------------------------------------------------------------
class TileGeometry(NamedTuple):
    """Where the tiles of a field lie in vein space, float32 as the shader reads them. ``rows``
    (n, 4): per tile row (n = size / TILE, row 0 at t = 0) the least and largest w over its
    texels' v and that v range (w_lo, w_hi, v_lo, v_hi); ``boxes`` (n², 4), row-major: a box
    (x_lo, y_lo, x_hi, y_hi) in q holding every texel of the tile."""

    rows: NDArray[np.float32]
    boxes: NDArray[np.float32]


def _columns(size: int, tile: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """u of the last and the first texel column of each tile column (u_lo, u_hi)."""
    first = np.arange(size // tile) * tile
    return 1.0 - 2.0 * (first + tile - 0.5) / size, 1.0 - 2.0 * (first + 0.5) / size


def _x_extent(rows: NDArray[np.float64], u_lo: NDArray[np.float64], u_hi: NDArray[np.float64]
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(n, n) least and largest x = u w over each tile: x is bilinear in (u, w), so its extremes
    lie at the corners of [u_lo, u_hi] × [w_lo, w_hi]."""
    w_lo, w_hi = rows[:, 0:1], rows[:, 1:2]
    return np.minimum(u_lo * w_lo, u_lo * w_hi), np.maximum(u_hi * w_lo, u_hi * w_hi)


def tile_geometry(table: ArrayLike, size: int, *, tile: int = TILE) -> TileGeometry:
    """The :class:`TileGeometry` of a ``size``² field over the half-widths ``table``: w's extremes
    over a row lie at its ends or at table knots between them (w is linear between knots); the
    boxes are widened by :data:`_SLACK` for float32 rounding."""
    tab = np.asarray(table, np.float32)
    n = size // tile
    first = np.arange(n) * tile
    v_hi = 1.0 - (first + 0.5) / size
    v_lo = 1.0 - (first + tile - 0.5) / size
    ends = np.stack([halfwidth_at(tab, v_lo), halfwidth_at(tab, v_hi)], axis=1)
    knots = np.arange(len(tab)) / (len(tab) - 1)
    inside = (knots[None, :] > v_lo[:, None]) & (knots[None, :] < v_hi[:, None])
    tab64 = tab.astype(np.float64)[None, :]
    w_lo = np.minimum(ends.min(axis=1), np.where(inside, tab64, np.inf).min(axis=1)) * (1.0 - 1e-6)
    w_hi = np.maximum(ends.max(axis=1), np.where(inside, tab64, -np.inf).max(axis=1)) * (1.0 + 1e-6)
    rows = np.stack([w_lo, w_hi, v_lo, v_hi], axis=1)
    x_lo, x_hi = _x_extent(rows, *_columns(size, tile))
    boxes = np.stack([x_lo - _SLACK, np.broadcast_to(v_lo[:, None] - _SLACK, x_lo.shape),
                      x_hi + _SLACK, np.broadcast_to(v_hi[:, None] + _SLACK, x_lo.shape)], axis=-1)
    return TileGeometry(rows.astype(np.float32), boxes.reshape(-1, 4).astype(np.float32))


def _point_box(p: NDArray[np.float64], box: NDArray[np.float64]) -> NDArray[np.float64]:
    gap = np.maximum(np.maximum(box[..., 0:2] - p, p - box[..., 2:4]), 0.0)
    return np.sqrt((gap * gap).sum(-1))


def box_bounds(box: ArrayLike, rec: NDArray[np.float32]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(lower, upper): the least and the largest distance from a point of the boxes ``box`` (..., 4)
    to the segments ``rec`` (..., 8), broadcast (the shader's box_lower and box_upper). Lower: 0
    where the segment crosses the box (Liang-Barsky clipping), else the least distance between an
    end point and the box or a corner and the segment; upper: the farthest corner."""
    b = np.asarray(box, np.float64)
    r = np.asarray(rec, np.float64)
    b, r = np.broadcast_arrays(b, r[..., :4])[0], np.broadcast_arrays(b[..., :1], r)[1]
    corners = [b[..., [0, 1]], b[..., [2, 1]], b[..., [0, 3]], b[..., [2, 3]]]
    to_corner = np.stack([segment_distance(c, r) for c in corners])
    p0, d = r[..., 0:2], r[..., 2:4]
    t0, t1 = np.zeros(p0.shape[:-1]), np.ones(p0.shape[:-1])
    for k in range(2):
        lo, hi, p, dk = b[..., k], b[..., k + 2], p0[..., k], d[..., k]
        flat = dk == 0.0
        safe = np.where(flat, 1.0, dk)
        ta, tb = (lo - p) / safe, (hi - p) / safe
        outside = flat & ((p < lo) | (p > hi))
        t0 = np.where(flat, np.where(outside, 2.0, t0), np.maximum(t0, np.minimum(ta, tb)))
        t1 = np.where(flat, t1, np.minimum(t1, np.maximum(ta, tb)))
    apart = np.minimum(np.minimum(_point_box(p0, b), _point_box(p0 + d, b)), to_corner.min(axis=0))
    return np.where(t0 <= t1, 0.0, apart), to_corner.max(axis=0)


def tile_lists(rec: NDArray[np.float32], geometry: TileGeometry, *, cap: float = FIELD_CAP,
               reach: float = BOUND_REACH) -> TileLists:
    """The segments each tile must test (see the module docstring): of those whose box widened by
    ``cap`` meets the tile's box, each whose least distance to the tile is at most ``cap`` and at
    most the tile's bound (over segments of order ≤ 2 for those), the least farthest-corner
    distance of the segments whose box widened by ``reach`` meets the tile's: a superset of every
    segment that is nearest, or nearest of order ≤ 2, for one of the tile's texels and within
    ``cap`` of it."""
    rows = geometry.rows.astype(np.float64)
    n = len(rows)
    m = len(rec)
    if m == 0:
        empty = np.zeros(n * n, np.int32)
        return TileLists(empty, empty.copy(), np.zeros(0, np.int32))
    boxes = geometry.boxes.astype(np.float64)
    q0 = rec[:, 0:2].astype(np.float64)
    q1 = q0 + rec[:, 2:4]
    slo, shi = np.minimum(q0, q1) - cap, np.maximum(q0, q1) + cap
    # candidates: tile rows by v, then the tiles of each row by x
    seg_i, row_i = np.nonzero((boxes[None, ::n, 1] <= shi[:, 1:2]) & (boxes[None, ::n, 3] >= slo[:, 1:2]))
    x_lo, x_hi = boxes[:, 0].reshape(n, n), boxes[:, 2].reshape(n, n)
    pair_i, col_i = np.nonzero((x_lo[row_i] <= shi[seg_i, 0:1]) & (x_hi[row_i] >= slo[seg_i, 0:1]))
    seg = seg_i[pair_i]
    tiles = row_i[pair_i] * n + col_i
    lower, upper = box_bounds(boxes[tiles], rec[seg])
    major = rec[seg, 5] <= 2.0
    # the bounds, from the tiles within ``reach`` of each segment (as the shader's bound stage)
    b = boxes[tiles]
    near = ((b[:, 0:2] <= shi[seg] - cap + reach) & (b[:, 2:4] >= slo[seg] + cap - reach)).all(axis=1)
    bound = np.full(n * n, cap)
    np.minimum.at(bound, tiles[near], upper[near])
    bound_major = np.full(n * n, cap)
    np.minimum.at(bound_major, tiles[near & major], upper[near & major])
    keep = lower <= np.where(major, bound_major[tiles], bound[tiles]) + _SLACK
    seg, tiles = seg[keep], tiles[keep]
    by_tile = np.lexsort((seg, tiles))
    seg, tiles = seg[by_tile], tiles[by_tile]
    count = np.bincount(tiles, minlength=n * n).astype(np.int32)
    first = (np.cumsum(count) - count).astype(np.int32)
    return TileLists(first, count, seg.astype(np.int32))


# -- the field -----------------------------------------------------------------------------------------
def _nearest(d: NDArray[np.float64], starts: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Per group (consecutive runs of ``d`` from ``starts``, none empty): the smallest value and
    the index of its first occurrence."""
    best = np.minimum.reduceat(d, starts)
    lens = np.diff(np.append(starts, len(d)))
    hits = np.flatnonzero(d <= np.repeat(best, lens))
    return best, hits[np.searchsorted(hits, starts)]


def _empty_field(size: int, cap: float) -> NDArray[np.float32]:
    out = np.zeros((size, size, 4), np.float32)
    out[..., 0] = out[..., 3] = cap
    return out


def field_from_segments(uv0: ArrayLike, uv1: ArrayLike, order: ArrayLike, width: ArrayLike, table: ArrayLike,
                        size: int = FIELD_SIZE, *, cap: float = FIELD_CAP, chunk: int = 1 << 21
                        ) -> NDArray[np.float32]:
    """The vein field (size, size, 4) float32 of the segments ``uv0`` → ``uv1`` (M, 2) of orders
    ``order`` and widths ``width`` (M,), over a blade of half-widths ``table``: see the module
    docstring. Evaluated tile by tile through :func:`tile_lists`, ``chunk`` texel-segment pairs
    at a time."""
    size = check_field_size(size)
    rec = segment_records(uv0, uv1, order, width, table)
    texel_q = texel_space(table, size)
    lists = tile_lists(rec, tile_geometry(table, size), cap=cap)
    out = _empty_field(size, cap)
    n = size // TILE
    # texels of each tile, row-major inside the tile: (tiles, TILE²) flat texel indices
    jj, ii = np.divmod(np.arange(TILE * TILE), TILE)
    ty, tx = np.divmod(np.arange(n * n), n)
    texels = (ty[:, None] * TILE + jj[None, :]) * size + (tx[:, None] * TILE + ii[None, :])
    flat_q = texel_q.reshape(-1, 2)
    flat_out = out.reshape(-1, 4)
    busy = np.flatnonzero(lists.counts)
    pairs = np.cumsum(lists.counts[busy].astype(np.int64) * TILE * TILE)
    cuts = np.searchsorted(pairs, np.arange(chunk, pairs[-1] if len(pairs) else 0, chunk), side="right")
    for part in np.split(busy, cuts):
        if not len(part):
            continue
        cnt = lists.counts[part].astype(np.int64)
        group_len = np.repeat(cnt, TILE * TILE)                   # one group per texel
        group_texel = texels[part].reshape(-1)
        group_first = np.repeat(lists.starts[part].astype(np.int64), TILE * TILE)
        starts = np.cumsum(group_len) - group_len
        pos = np.arange(int(group_len.sum())) - np.repeat(starts, group_len)
        seg = lists.segments[np.repeat(group_first, group_len) + pos]
        d = segment_distance(flat_q[np.repeat(group_texel, group_len)], rec[seg])
        best, arg = _nearest(d, starts)
        hit = best < cap
        texel = group_texel[hit]
        flat_out[texel, 0] = best[hit]
        flat_out[texel, 1] = rec[seg[arg[hit]], 5]
        flat_out[texel, 2] = rec[seg[arg[hit]], 6]
        d_major = np.where(rec[seg, 5] <= 2.0, d, np.inf)
        best2 = np.minimum.reduceat(d_major, starts)
        flat_out[group_texel, 3] = np.minimum(best2, cap)
    return out


def brute_force_field(uv0: ArrayLike, uv1: ArrayLike, order: ArrayLike, width: ArrayLike, table: ArrayLike,
                      size: int, *, cap: float = FIELD_CAP) -> NDArray[np.float32]:
    """The field of :func:`field_from_segments` by testing every segment at every texel (the
    reference the tile lists are checked against; small sizes only)."""
    rec = segment_records(uv0, uv1, order, width, table)
    texel_q = texel_space(table, size).reshape(-1, 1, 2)
    out = _empty_field(size, cap).reshape(-1, 4)
    if len(rec):
        d = segment_distance(texel_q, rec[None, :, :])
        arg = np.argmin(d, axis=1)
        best = d[np.arange(len(d)), arg]
        hit = best < cap
        out[hit, 0], out[hit, 1], out[hit, 2] = best[hit], rec[arg[hit], 5], rec[arg[hit], 6]
        out[:, 3] = np.minimum(np.where(rec[None, :, 5] <= 2.0, d, np.inf).min(axis=1), cap)
    return out.reshape(size, size, 4)


def vein_field(params: LeafParams, size: int = FIELD_SIZE) -> NDArray[np.float32]:
    """The vein field (size, size, 4) float32 of the leaf ``params`` (its veins from
    :func:`leafview.botany.venation.vein_segments`); see the module docstring."""
    seg = vein_segments(params)
    return field_from_segments(seg.uv0, seg.uv1, seg.order, seg.width, halfwidth_table(params), size)


# -- layers --------------------------------------------------------------------------------------------
def vein_key(params: LeafParams) -> Hashable | None:
    """What a leaf's vein field depends on, (shape, venation); None for a leaf without veins."""
    venation = params.venation
    return (params.shape, venation) if venation.enabled else None


def vein_keys(leaves: Sequence[LeafParams]) -> list[Hashable]:
    """The distinct :func:`vein_key` of the leaves with veins, in order of first use: layer i of a
    field array built fresh for ``leaves`` holds ``keys[i]``."""
    keys: dict[Hashable, None] = {}
    for p in leaves:
        key = vein_key(p)
        if key is not None:
            keys.setdefault(key, None)
    return list(keys)


def vein_layers(leaves: Sequence[LeafParams], keys: Sequence[Hashable | None] | None = None) -> NDArray[np.int32]:
    """(N,) int32: the layer of each leaf's field in an array whose layer i holds ``keys[i]``
    (default :func:`vein_keys` of ``leaves``); -1 for a leaf without veins."""
    where = {key: i for i, key in enumerate(vein_keys(leaves) if keys is None else keys) if key is not None}
    out = np.full(len(leaves), -1, np.int32)
    for n, p in enumerate(leaves):
        key = vein_key(p)
        if key is not None:
            if key not in where:
                raise KeyError(f"leaf {n}: its vein field is not among the keys")
            out[n] = where[key]
    return out
