"""The benchmark's two many-leaf paths draw the same picture, and ``leafview bench`` reports every
key. Benchmarks are not tests: nothing here checks a timing."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from leafview.deform.surface import jitter_table, tessellate
from leafview.gpu.layout import LEAF_BLOCK, pack_leaf
from leafview.scene.camera import frame_view
from tests.conftest import draw_each

NUMERIC_KEYS = (
    "thumbnails_per_s", "matplotlib_thumbnails_per_s", "thumbnail_speedup",
    "instanced_leaves_per_s", "baked_leaves_per_s", "param_vs_baked_speed",
    "baked_vs_param_bytes", "baked_bytes_per_leaf", "param_bytes_per_leaf",
    "leaves_per_s_220tri", "vs_paper_550", "triangles_per_leaf", "cpu_count",
    "thumbnail_count", "matplotlib_thumbnail_count", "scene_leaves",
    "thumbnails_per_s_single", "thumbnails_per_s_three_quarter", "record_bytes_per_leaf",
    "baked_vs_record_bytes", "ripple_overhead", "ripple_pass_ms", "ripple_pass_ms_1000",
    # like for like against matplotlib: three-quarter, same mesh, camera and size
    "thumbnails_per_s_three_quarter_single", "thumbnails_per_s_three_quarter_aliased",
    "matplotlib_thumbnails_per_s_single", "matplotlib_thumbnails_per_s_aliased",
    "thumbnail_speedup_single", "thumbnail_speedup_aliased",
)


def _no_error(ctx, where: str) -> None:
    err = ctx.error
    assert err == "GL_NO_ERROR", f"{where}: {err}"


# -- numpy only ---------------------------------------------------------------------------------
def test_pack_leaves_rows_and_transforms():
    from leafview.gpu.instanced import pack_leaves, scatter_leaves

    params = scatter_leaves(40, seed=3, jitter_fraction=0.5)
    recs, table = pack_leaves(params)
    assert recs.dtype == LEAF_BLOCK.dtype and recs.shape == (40,)
    seeds = sorted({p.jitter.seed for p in params if p.jitter.enabled})
    assert table.shape == (max(len(seeds), 1), 256) and table.dtype == np.float32
    for p, r in zip(params, recs):
        assert np.allclose(r["model"].T, p.transform.matrix(), atol=1e-6)
        if p.jitter.enabled:
            assert r["jitter"][0] > 0
            assert np.array_equal(table[int(r["jitter"][3])], jitter_table(p.jitter))
        else:
            assert r["jitter"][0] == 0
    # shapes differ leaf to leaf (slightly)
    assert len({p.shape for p in params}) == len(params)


def test_bake_leaves_matches_tessellate():
    from leafview.gpu.instanced import bake_leaves, scatter_leaves

    params = scatter_leaves(3, seed=5)
    pos, nrm = bake_leaves(params, (9, 15))
    assert pos.shape == nrm.shape == (3, 135, 3)
    for i, p in enumerate(params):
        mesh = tessellate(p, 9, 15)
        m = p.transform.matrix()
        assert np.allclose(pos[i], mesh.vertices @ m[:3, :3].T + m[:3, 3], atol=1e-5)
    assert np.allclose(np.linalg.norm(nrm, axis=-1), 1.0, atol=1e-5)


# -- GL -----------------------------------------------------------------------------------------
def _scene(n: int = 6, seed: int = 2):
    from leafview.gpu.instanced import pack_leaves, scatter_leaves

    params = scatter_leaves(n, seed=seed, radius=0.2, jitter_fraction=0.5)
    recs, table = pack_leaves(params)
    return params, recs, table


@pytest.mark.gl
def test_instanced_and_baked_draw_the_same_picture(gl):
    from leafview.gpu.instanced import BakedLeaves, InstancedLeaves, OffscreenTarget, bake_leaves

    ctx = gl.ctx
    params, recs, table = _scene()
    pos, _ = bake_leaves(params, (9, 15))
    camera = frame_view("three-quarter", pos.reshape(-1, 3), (256, 256))
    with OffscreenTarget(ctx, (256, 256)) as target, \
            InstancedLeaves(ctx, recs, (9, 15), jitter_tables=table) as inst, \
            BakedLeaves.from_params(ctx, params, (9, 15)) as baked:
        images = draw_each(target, (inst, baked), camera, lambda batch: _no_error(ctx, f"{type(batch).__name__}.draw"))
    a, b = images
    cover_a, cover_b = (a[..., 3] > 0).mean(), (b[..., 3] > 0).mean()
    assert cover_a > 0.03, "the leaves should fill a good part of the image"
    assert abs(cover_a - cover_b) < 0.002
    diff = np.abs(a.astype(np.int16) - b.astype(np.int16))
    assert diff.mean() < 0.5, diff.mean()
    assert (diff.max(axis=-1) > 24).mean() < 0.002  # only a few edge pixels may differ much


@pytest.mark.gl
def test_instanced_capture_matches_numpy_reference(gl):
    from leafview.gpu.instanced import InstancedLeaves, OffscreenTarget, bake_leaves

    ctx = gl.ctx
    params, recs, table = _scene(5, seed=4)
    ref_pos, ref_nrm = bake_leaves(params, (9, 15))
    with OffscreenTarget(ctx, (1, 1)) as target, \
            InstancedLeaves(ctx, recs, (9, 15), jitter_tables=table) as inst:
        target.use()
        pos, nrm = inst.capture()
        _no_error(ctx, "capture")
    assert pos.shape == nrm.shape == (5, 135, 3)
    assert np.abs(pos - ref_pos).max() < 1e-4
    assert np.abs(nrm - ref_nrm).max() < 1e-3
    # one leaf without jitter, from a single record made by pack_leaf
    i = next(k for k, p in enumerate(params) if not p.jitter.enabled)
    with OffscreenTarget(ctx, (1, 1)) as target, \
            InstancedLeaves(ctx, [pack_leaf(params[i])], (9, 15)) as one:
        target.use()
        p1, n1 = one.capture()
        _no_error(ctx, "capture one")
    assert np.abs(p1[0] - ref_pos[i]).max() < 1e-4
    assert np.abs(n1[0] - ref_nrm[i]).max() < 1e-3


class _SmallLimits:
    """A context whose storage-block limit is tiny; everything else is the real context."""

    def __init__(self, ctx, limit: int) -> None:
        self._ctx = ctx
        self.info = {**ctx.info, "GL_MAX_SHADER_STORAGE_BLOCK_SIZE": limit}

    def __getattr__(self, name):
        return getattr(self._ctx, name)


@pytest.mark.gl
def test_too_many_leaves_for_the_storage_buffer(gl):
    from leafview.gpu.instanced import InstancedLeaves

    _, recs, table = _scene(5)
    with pytest.raises(ValueError, match="GL_MAX_SHADER_STORAGE_BLOCK_SIZE"):
        InstancedLeaves(_SmallLimits(gl.ctx, 4 * LEAF_BLOCK.nbytes), recs, (9, 15))
    # the real limit is far above five records
    with InstancedLeaves(gl.ctx, recs, (9, 15), jitter_tables=table) as inst:
        assert inst.count == 5 and inst.triangles_per_leaf == 224
    inst.release()  # idempotent
    _no_error(gl.ctx, "release")


@pytest.mark.gl
def test_quick_run_reports_every_key(gl):
    from leafview.bench.core import format_table, run

    # share the session context: a second standalone context would become current behind it
    res = run(quick=True, ctx=gl.ctx)
    _no_error(gl.ctx, "benchmark")
    for key in NUMERIC_KEYS:
        value = res[key]
        assert isinstance(value, (int, float)) and not isinstance(value, bool), key
        assert math.isfinite(value) and value > 0, (key, value)
    assert res["gl_renderer"] == gl.ctx.info["GL_RENDERER"]
    assert res["triangles_per_leaf"] == 224
    assert res["baked_bytes_per_leaf"] == 32 * 64 * 32 + 2 * 31 * 63 * 12
    assert res["param_bytes_per_leaf"] == LEAF_BLOCK.parameter_nbytes < res["record_bytes_per_leaf"] == LEAF_BLOCK.nbytes
    assert res["leaves_per_s_220tri"] == res["instanced_leaves_per_s"]
    assert res["param_vs_baked_mean_abs_diff"] < 1.0  # same picture (captured vertices)
    for key in ("python", "numpy", "moderngl", "thumbnail_grid", "scene_grid", "bytes_grid"):
        assert res[key]
    json.dumps(res, allow_nan=False)

    text = format_table(res)
    assert res["gl_renderer"] in text
    for label in ("thumbnail speedup", "param / baked speed", "baked / param bytes", "vs paper"):
        assert label in text
    for key in ("thumbnail_speedup", "thumbnail_speedup_single", "thumbnail_speedup_aliased"):
        lo, hi = res[f"{key}_range"]
        assert 0 < lo <= res[key] <= hi   # the median of the rounds' ratios
