"""The vein field (leafview.botany.vein_field, numpy; shaders/vein_field.comp through
leafview.gpu.vein_field.VeinFields): vein space and its half-width table, the tile lists against
brute force (exact, not within a tolerance), the GPU field read back against the numpy twin for
presets and synthetic segments (float32 distances; order and width exact except at ties), the
layer bookkeeping of VeinFields (each key computed once, freed layers reused), release, and bad
sizes."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from leafview.bench import veins as veins_bench
from leafview.botany.vein_field import (
    FIELD_CAP,
    TILE,
    box_bounds,
    brute_force_field,
    check_field_size,
    field_from_segments,
    halfwidth_table,
    segment_distance,
    segment_records,
    texel_space,
    texel_uv,
    tile_geometry,
    tile_lists,
    vein_field,
    vein_keys,
    vein_layers,
    vein_space,
    vein_space_of,
)
from leafview.botany.vein_shape import GRID_N, vein_grid
from leafview.botany.venation import vein_segments
from leafview.core.blade import blade_partials
from leafview.core.params import Jitter, LeafParams
from leafview.core.texture import texture_st
from leafview.core.venation import Venation
from leafview.errors import GpuLimitError, ParamError
from leafview.gpu import vein_field as gpu_vein_field
from leafview.gpu.programs import ProgramCache
from leafview.gpu.vein_field import LIST_START, VeinFields
from leafview.resources import builtin_presets
from leafview.scene.camera import frame_view

DIST_TOL = 5e-7   # float32 distances of O(0.05), squared on the GPU (seen: 7e-8)


def _preset(name: str) -> LeafParams:
    return LeafParams.load(builtin_presets()[name])


def _synthetic(seed: int, m: int = 240) -> tuple[np.ndarray, ...]:
    """Random polylines in (u, v) of orders 1-4, with zero-length, horizontal and vertical
    segments and segments on the domain's edges among them."""
    rng = np.random.default_rng(seed)
    uv0 = np.column_stack([rng.uniform(-1, 1, m), rng.uniform(0, 1, m)])
    uv1 = np.clip(uv0 + rng.normal(0, 0.06, (m, 2)), [-1, 0], [1, 1])
    if m > 16:
        uv1[:5] = uv0[:5]                                   # points
        uv1[5:10, 1] = uv0[5:10, 1]                         # across, at one v
        uv1[10:15, 0] = uv0[10:15, 0]                       # along v
        uv0[15], uv1[15] = (-1.0, 0.0), (-1.0, 1.0)         # the edges of the domain
        uv0[16], uv1[16] = (1.0, 1.0), (-1.0, 1.0)
    order = rng.integers(1, 5, m).astype(np.int32)
    width = (0.012 * 0.5 ** (order - 1)).astype(np.float32)
    return uv0, uv1, order, width


def _veined(name: str, **venation: object) -> LeafParams:
    p = _preset(name)
    return p.replace(venation=dataclasses.replace(p.venation, enabled=True, **venation))


# -- vein space -----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["ovate", "asymmetric", "curled", "maize", "deltoid"])
def test_halfwidth_is_the_arc_length_of_the_flat_cross_section(name):
    """The table is the mean over both sides of the arc length from the midrib to the margin of
    the blade without jitter (evaluated here through blade_partials, the surface's own code)."""
    p = _preset(name).replace(jitter=Jitter(enabled=True, amplitude=0.05))   # jitter must not count
    table = halfwidth_table(p)
    n, chords = len(table), 16
    v = np.linspace(0.0, 1.0, n)
    s = np.linspace(0.0, 1.0, chords + 1)
    uu = np.concatenate([s, -s])[None, :].repeat(n, axis=0)
    pts = blade_partials(p.replace(jitter=Jitter()), uu, np.broadcast_to(v[:, None], uu.shape))[0].L
    arc = np.linalg.norm(np.diff(pts.reshape(n, 2, chords + 1, 3), axis=2), axis=-1).sum(axis=2).mean(axis=1)
    assert table.dtype == np.float32 and table.shape == (64,)
    np.testing.assert_allclose(table, arc, atol=1e-7)
    assert table[0] < 1e-6 and table[-1] < 1e-6 and table.max() > 0.05   # pinched base and apex


def test_vein_space_scales_u_by_the_halfwidth():
    p = _preset("ovate")
    table = halfwidth_table(p).astype(np.float64)
    uv = np.array([[0.0, 0.3], [1.0, 0.5], [-0.5, 1.0], [0.25, 0.0], [-1.0, 0.123]])
    q = vein_space(p, uv)
    np.testing.assert_allclose(q[:, 1], uv[:, 1])
    np.testing.assert_allclose(q[:, 0], uv[:, 0] * np.interp(uv[:, 1], np.linspace(0, 1, 64), table), atol=1e-7)
    np.testing.assert_array_equal(q, vein_space_of(halfwidth_table(p), uv))
    with pytest.raises(ValueError):
        vein_space(p, np.zeros((3, 3)))


def test_texels_follow_the_texture_convention():
    size = 32
    uv = texel_uv(size)
    s, t = texture_st(uv[..., 0], uv[..., 1])
    centres = (np.arange(size) + 0.5) / size
    np.testing.assert_allclose(s, np.broadcast_to(centres[None, :], (size, size)), atol=1e-12)
    np.testing.assert_allclose(t, np.broadcast_to(centres[:, None], (size, size)), atol=1e-12)


# -- tiles: exact against brute force -------------------------------------------------------------------
def test_tile_boxes_hold_their_texels():
    for name in ("ovate", "maize", "deltoid"):
        table = halfwidth_table(_preset(name))
        for size in (16, 64, 256):
            geo = tile_geometry(table, size)
            n = size // TILE
            q = texel_space(table, size).reshape(n, TILE, n, TILE, 2).transpose(0, 2, 1, 3, 4).reshape(n * n, -1, 2)
            box = geo.boxes.astype(np.float64)
            assert (q >= box[:, None, 0:2]).all() and (q <= box[:, None, 2:4]).all(), (name, size)


def test_box_bounds_enclose_every_distance_from_the_box():
    rng = np.random.default_rng(3)
    uv0, uv1, order, width = _synthetic(5, 60)
    rec = segment_records(uv0, uv1, order, width, halfwidth_table(_preset("ovate")))
    lo = rng.uniform(-0.4, 0.4, (60, 2))
    box = np.concatenate([lo, lo + rng.uniform(0.0, 0.06, (60, 2))], axis=1)
    box[:3, 2:4] = box[:3, 0:2]                                  # boxes that are points
    lower, upper = box_bounds(box, rec)
    t = rng.uniform(0.0, 1.0, (400, 1, 2))
    pts = box[None, :, 0:2] + t * (box[None, :, 2:4] - box[None, :, 0:2])
    d = segment_distance(pts, rec[None])
    assert (d >= lower - 1e-12).all() and (d <= upper + 1e-12).all()
    np.testing.assert_allclose(lower[:3], upper[:3], atol=1e-12)   # a point: both are its distance
    crossing = segment_distance(0.5 * (box[:, 0:2] + box[:, 2:4]), rec) == 0.0
    assert (lower[crossing] == 0.0).all()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_tile_lists_give_exactly_the_brute_force_field(seed):
    uv0, uv1, order, width = _synthetic(seed)
    table = halfwidth_table(_preset("ovate"))
    for size in (16, 48):
        field = field_from_segments(uv0, uv1, order, width, table, size)
        np.testing.assert_array_equal(field, brute_force_field(uv0, uv1, order, width, table, size))
        np.testing.assert_array_equal(field, field_from_segments(uv0, uv1, order, width, table, size, chunk=500))
    # no segments: the cap everywhere, no vein
    empty = field_from_segments(np.zeros((0, 2)), np.zeros((0, 2)), [], [], table, 16)
    assert (empty[..., [0, 3]] == np.float32(FIELD_CAP)).all() and (empty[..., 1:3] == 0).all()


@pytest.mark.parametrize("name", ["beech", "maize", "orbicular"])
def test_preset_fields_equal_brute_force(name):
    p = _preset(name)
    seg = vein_segments(p)
    table = halfwidth_table(p)
    field = vein_field(p, 64)
    np.testing.assert_array_equal(field, brute_force_field(seg.uv0, seg.uv1, seg.order, seg.width, table, 64))
    assert field.dtype == np.float32 and field.shape == (64, 64, 4)
    assert (field[..., 0] <= field[..., 3]).all() and (field[..., 3] <= FIELD_CAP).all()
    assert set(np.unique(field[..., 1])) <= {0.0, 1.0, 2.0, 3.0, 4.0}


def test_tile_lists_are_short_and_hold_each_texels_nearest():
    p = _preset("maize")
    seg = vein_segments(p)
    table = halfwidth_table(p)
    rec = segment_records(seg.uv0, seg.uv1, seg.order, seg.width, table)
    lists = tile_lists(rec, tile_geometry(table, 256))
    assert lists.counts.max() <= LIST_START and lists.counts.mean() < 30
    # spot check: a tile's texels find their brute-force nearest in its list
    q = texel_space(table, 256)
    for tile in (0, 77, 500, 1023):
        ty, tx = divmod(tile, 256 // TILE)
        pts = q[ty * TILE:(ty + 1) * TILE, tx * TILE:(tx + 1) * TILE].reshape(-1, 1, 2)
        nearest = np.argmin(segment_distance(pts, rec[None]), axis=1)
        listed = lists.segments[lists.starts[tile]:lists.starts[tile] + lists.counts[tile]]
        near = segment_distance(pts[:, 0], rec[nearest]) < FIELD_CAP
        assert np.isin(nearest[near], listed).all()


@pytest.mark.parametrize("size", [0, 8, 20, 100, 4096, 256.0, True, "256"])
def test_bad_sizes_are_refused_naming_the_size(size):
    with pytest.raises(ParamError) as err:
        check_field_size(size)
    assert err.value.path == "size"


# -- keys and layers ------------------------------------------------------------------------------------
def test_keys_and_layers():
    a, b = _veined("ovate"), _veined("ovate", seed=7)
    plain = _preset("ovate").replace(venation=Venation())
    leaves = [a, plain, b, a, b]
    keys = vein_keys(leaves)
    assert keys == [(a.shape, a.venation), (b.shape, b.venation)]
    np.testing.assert_array_equal(vein_layers(leaves), [0, -1, 1, 0, 1])
    np.testing.assert_array_equal(vein_layers(leaves, [None, keys[1], keys[0]]), [2, -1, 1, 2, 1])
    with pytest.raises(KeyError):
        vein_layers(leaves, keys[:1])


# -- GPU ---------------------------------------------------------------------------------------------------
def _assert_matches_twin(gpu: np.ndarray, uv0, uv1, order, width, table) -> None:
    """Distances within float32 rounding; order and width exact except where the GPU's choice is
    a segment as near as the twin's (a tie)."""
    size = gpu.shape[0]
    twin = field_from_segments(uv0, uv1, order, width, table, size)
    np.testing.assert_allclose(gpu[..., [0, 3]], twin[..., [0, 3]], atol=DIST_TOL, rtol=0)
    differ = (gpu[..., 1:3] != twin[..., 1:3]).any(axis=-1) & (twin[..., 0] < FIELD_CAP - DIST_TOL)
    differ = np.flatnonzero(differ.ravel())
    assert len(differ) <= max(3, gpu.shape[0] * gpu.shape[1] // 2000), f"{len(differ)} texels differ"
    if len(differ):
        rec = segment_records(uv0, uv1, order, width, table)
        q = texel_space(table, size).reshape(-1, 1, 2)[differ]
        d = segment_distance(q, rec[None])
        flat = gpu.reshape(-1, 4)[differ]
        same = (rec[None, :, 5] == flat[:, None, 1]) & (rec[None, :, 6] == flat[:, None, 2])
        chosen = np.where(same, d, np.inf).min(axis=1)
        np.testing.assert_allclose(chosen, d.min(axis=1), atol=DIST_TOL, rtol=0)


@pytest.fixture
def fields(gl):
    with VeinFields(gl.ctx, size=128, programs=gl.resources.programs) as out:
        yield out


@pytest.mark.gl
def test_gpu_field_matches_the_twin_for_presets(gl):
    names = ["ovate", "maize", "deltoid", "holly", "willow"]
    leaves = [_preset(name) for name in names]
    with VeinFields.build(gl.ctx, leaves, programs=gl.resources.programs) as fields:   # one dispatch, 256²
        assert fields.computed == len(names) and fields.size == 256
        np.testing.assert_array_equal(fields.layers, np.arange(len(names)))
        for layer, p in enumerate(leaves):
            seg = vein_segments(p)
            _assert_matches_twin(fields.read(layer), seg.uv0, seg.uv1, seg.order, seg.width, halfwidth_table(p))


@pytest.mark.gl
def test_gpu_field_matches_the_twin_for_synthetic_segments(fields):
    table = halfwidth_table(_preset("lanceolate"))
    jobs = [_synthetic(seed, m) for seed, m in ((4, 300), (5, 1), (6, 0))]
    fields.reserve(3)
    fields.compute([(k, table, segment_records(*job, table)) for k, job in enumerate(jobs)])
    for k, job in enumerate(jobs):
        _assert_matches_twin(fields.read(k), *job, table)


@pytest.mark.gl
def test_long_lists_get_room(fields):
    """More than LIST_START segments as near as each other to some tiles: the dispatch grows the
    room for the lists and lists again."""
    table = halfwidth_table(_preset("ovate"))
    m = 3 * LIST_START
    v = 0.5 + np.linspace(-1e-4, 1e-4, m)
    uv0 = np.column_stack([np.full(m, -0.02), v])
    uv1 = np.column_stack([np.full(m, 0.02), v])
    order = np.full(m, 2, np.int32)
    width = np.linspace(0.001, 0.002, m).astype(np.float32)
    rec = segment_records(uv0, uv1, order, width, table)
    longest = int(tile_lists(rec, tile_geometry(table, 128)).counts.max())
    assert longest > LIST_START
    fields.compute([(0, table, rec)])
    assert fields.list_capacity >= longest
    _assert_matches_twin(fields.read(0), uv0, uv1, order, width, table)


@pytest.mark.gl
def test_each_key_is_computed_once_and_freed_layers_are_reused(fields):
    a, b, c, d, e = (_veined("elliptic", seed=s, tertiary=4.0) for s in range(5))
    plain = _preset("elliptic").replace(venation=Venation())
    assert fields.update([a, b, a, plain, c, b, d]) == 4
    np.testing.assert_array_equal(fields.layers, [0, 1, 0, -1, 2, 1, 3])
    assert fields.update([c, a, d, b]) == 0 and fields.computed == 4
    # b and d go; e and a new one take their layers (1 and 3: two runs, the second through a copy)
    f = _veined("elliptic", seed=9, tertiary=4.0)
    assert fields.update([a, e, c, f]) == 2
    np.testing.assert_array_equal(fields.layers, [0, 1, 2, 3])
    for layer, p in enumerate([a, e, c, f]):
        seg = vein_segments(p)
        _assert_matches_twin(fields.read(layer), seg.uv0, seg.uv1, seg.order, seg.width, halfwidth_table(p))
    grid = np.frombuffer(fields.grid.read(), np.float32).reshape(fields.capacity, GRID_N, GRID_N, 4)
    np.testing.assert_array_equal(grid[3], vein_grid(f, GRID_N, GRID_N))
    # more keys than layers: a larger array, every field again
    more = [_veined("elliptic", seed=20 + s, tertiary=4.0) for s in range(5)]
    assert fields.update(more) == 5 and fields.capacity == 8
    np.testing.assert_array_equal(fields.layers, np.arange(5))
    assert fields.update([plain]) == 0
    np.testing.assert_array_equal(fields.layers, [-1])
    fields.use()


@pytest.mark.gl
def test_release_frees_everything_and_leaves_shared_programs(gl):
    programs = ProgramCache(gl.ctx)
    try:
        fields = VeinFields.build(gl.ctx, [_preset("ovate")], size=64, programs=programs)
        field, grid = fields.field, fields.grid
        fields.release()
        fields.release()   # twice is fine
        assert fields.field is None and fields.grid is None and fields.capacity == 0
        assert type(field.mglo).__name__ == "InvalidObject" and type(grid.mglo).__name__ == "InvalidObject"
        assert len(programs) == 4 and all(type(s.mglo).__name__ != "InvalidObject" for s in programs.all())
        own = VeinFields(gl.ctx, size=64)   # builds its own shaders and releases them
        shaders = list(own.shaders)
        own.release()
        assert all(type(s.mglo).__name__ == "InvalidObject" for s in shaders)
    finally:
        programs.release()


@pytest.mark.gl
def test_bad_sizes_on_the_gpu(gl):
    with pytest.raises(ParamError) as err:
        VeinFields(gl.ctx, size=100)
    assert err.value.path == "size"
    fields = VeinFields(gl.ctx, size=64, programs=gl.resources.programs)
    try:
        fields.max_layers = 2
        with pytest.raises(GpuLimitError):
            fields.update([_veined("ovate", seed=s) for s in range(3)])
        with pytest.raises(IndexError):
            fields.compute([(5, halfwidth_table(_preset("ovate")), np.zeros((0, 8), np.float32))])
    finally:
        fields.release()


@pytest.mark.gl
def test_a_failed_update_leaves_no_layer_claiming_a_key(fields, monkeypatch):
    """A grid refused (a fold) while computing: the layers it wrote to hold no key afterwards."""
    a, b, c = (_veined("ovate", seed=s, tertiary=4.0) for s in range(3))
    assert fields.update([a, b]) == 2
    real = gpu_vein_field.vein_grid

    def refuse(params, nu, nv):
        if params.venation.seed == 2:
            raise ParamError("venation.edits[0].angle", "folds the blade")
        return real(params, nu, nv)

    monkeypatch.setattr(gpu_vein_field, "vein_grid", refuse)
    with pytest.raises(ParamError):
        fields.update([a, c])        # c takes b's layer, and fails there
    monkeypatch.undo()
    assert fields.update([a, b]) == 1   # b again: its layer was spoilt
    seg = vein_segments(b)
    _assert_matches_twin(fields.read(int(fields.layers[1])), seg.uv0, seg.uv1, seg.order, seg.width,
                         halfwidth_table(b))


@pytest.mark.gl
def test_a_geometry_only_update_writes_the_grid_and_leaves_the_field_for_later(fields):
    """shading=False (geometry capture): the vein grid is written, no field is computed; the next
    update that shades computes just that field, equal to the twin."""
    a, b = (_veined("ovate", seed=s, tertiary=4.0) for s in range(2))
    fields.reserve(2)   # room for both (a larger array would start empty)
    assert fields.update([a], shading=False) == 0 and fields.computed == 0
    layer = int(fields.layers[0])
    assert fields.grid is not None
    grid = np.frombuffer(fields.grid.read(), np.float32).reshape(fields.capacity, GRID_N, GRID_N, 4)[layer]
    np.testing.assert_allclose(grid, vein_grid(a, GRID_N, GRID_N), atol=1e-6)
    assert fields.update([a]) == 1 and fields.computed == 1 and int(fields.layers[0]) == layer
    seg = vein_segments(a)
    _assert_matches_twin(fields.read(layer), seg.uv0, seg.uv1, seg.order, seg.width, halfwidth_table(a))
    assert fields.update([a]) == 0                        # held and shaded: nothing again
    assert fields.update([a, b], shading=False) == 0 and fields.update([a, b]) == 1   # b's field only
    assert fields.computed == 2


@pytest.mark.gl
def test_capture_builds_no_vein_field_or_tubes_until_a_draw(gl):
    """LeafRenderer.capture (export's path) makes only what positions need; a draw afterwards makes
    the captured leaf's vein field and close-up tubes."""
    leaf = _veined("ovate", seed=11, tertiary=4.0)
    gl.capture(leaf, [0.0, 0.5], [0.5, 0.5])
    fields = gl.leaf_veins.fields
    assert fields is not None
    before = fields.computed
    assert gl.vein_tubes.leaf != leaf                     # no tubes built for the capture
    gl.capture(leaf, [0.0], [0.25])
    assert fields.computed == before
    target = gl.ctx.simple_framebuffer((32, 32))
    try:
        target.use()
        gl.set_camera(frame_view("top", np.array([[-1.0, -1.0, -0.5], [1.0, 1.0, 0.5]]), (32, 32)), srgb=True,
                      size=(32, 32))
        gl.draw()
    finally:
        gl.ctx.detect_framebuffer(0).use()
        target.release()
    assert fields.computed == before + 1 and gl.vein_tubes.leaf == leaf


@pytest.mark.gl
@pytest.mark.slow
def test_veins_bench_quick_run_fills_the_table(gl):
    res = veins_bench.run(quick=True, ctx=gl.ctx)
    assert res["gl_renderer"] == gl.ctx.info["GL_RENDERER"] and res["goal_ms"] == 5.0
    assert [r["name"] for r in res["species"]] == sorted(veins_bench.QUICK_PRESETS)
    for r in res["species"]:
        assert r["field_ms"] > 0 and r["twin_ms"] > 0 and 0 < r["list_mean"] <= r["list_max"] <= LIST_START
    table = veins_bench.format_table(res)
    assert "goal ≤ 5 ms" in table and "numpy twin" in table and "maize" in table
    json.dumps(res, allow_nan=False)
