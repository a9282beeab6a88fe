"""Ripples and bending on the GPU: the rendering shader against the numpy reference, what an
edit recomputes, batched signal synthesis for many leaves."""

import numpy as np
import pytest

import leafview
from leafview.core.params import Bending, Jitter, Ripple
from leafview.gpu.layout import LEAF_BLOCK, pack_leaves, ripple_keys
from tests.conftest import random_params

pytestmark = pytest.mark.gl
TOL = 2e-5


def _deformed(rng, case):
    p = random_params(rng, jitter=case % 2 == 0)
    return p.replace(
        ripple=Ripple(enabled=True, beta=float(rng.uniform(0.6, 3)), seed=int(rng.integers(0, 10**6)),
                      veins=float(rng.uniform(10, 120)), amplitude=tuple(rng.uniform(0, 0.06, 2)),
                      fluctuation=tuple(rng.uniform(0, 1, 2)), interval=tuple(rng.uniform(0.05, 0.6, 2)),
                      phase=tuple(rng.uniform(0, 30, 2))),
        bending=Bending(load=float(rng.uniform(0, 30)) * (case % 3 != 0), twist=float(rng.uniform(-90, 90)),
                        petiole_length=float(rng.uniform(0, 0.2)) * (case % 2)))


def test_readback_with_ripples_and_bending_matches_reference(gl):
    rng = np.random.default_rng(31)
    worst_pos, worst_cos = 0.0, 1.0
    for case in range(40):
        p = _deformed(rng, case)
        u = np.r_[rng.uniform(-1, 1, 300), -1, 1, 0, 0.3]
        v = np.r_[rng.uniform(0, 1, 300), 0.5, 0.5, 0, 1]
        pos, nrm = gl.capture(p, u, v)
        worst_pos = max(worst_pos, float(np.abs(pos - leafview.evaluate(p, u, v)).max()))
        worst_cos = min(worst_cos, float(np.sum(nrm * leafview.normals(p, u, v), axis=1).min()))
    assert worst_pos <= TOL, f"largest GPU/CPU difference {worst_pos:.3g}"
    assert worst_cos > 1 - 1e-3, f"normals differ by {np.degrees(np.arccos(worst_cos)):.2f}°"


def test_ripple_is_out_of_plane_zero_at_midrib_full_at_margin():
    base = leafview.LeafParams.load("assets/presets/oblong.toml")
    rip = base.replace(ripple=Ripple(enabled=True, amplitude=(0.05, 0.05), fluctuation=(1.0, 1.0)))
    v = np.full(9, 0.5)
    u = np.linspace(0, 1, 9)
    d = leafview.evaluate(rip, u, v) - leafview.evaluate(base, u, v)
    np.testing.assert_allclose(d[:, :2], 0.0, atol=1e-15)        # only z moves (leaf space)
    assert d[0, 2] == 0.0 and np.all(np.diff(d[:, 2]) > 0)       # grows from the midrib outwards
    assert d[-1, 2] == pytest.approx(0.05)                       # λ = 1: the full load P at the margin
    tips = leafview.evaluate(rip, [-1, 1], [0.0, 1.0]) - leafview.evaluate(base, [-1, 1], [0.0, 1.0])
    np.testing.assert_allclose(tips, 0.0, atol=1e-15)            # tapered away at base and apex


def test_editing_k_theta_lambda_touches_only_the_uniform_block_and_beta_seed_only_the_pass(gl):
    p = leafview.LeafParams.load("assets/presets/maize.toml")
    gl.set_leaf(p)
    dispatches, uploads = gl.ripples.dispatches, gl.uploads
    for k in (0.1, 0.2, 0.5):
        gl.set_leaf(p.replace(ripple=Ripple(**{**vars(p.ripple), "interval": (k, k), "phase": (k, 2 * k),
                                              "fluctuation": (k, k)})))
    assert gl.ripples.dispatches == dispatches                   # signal untouched
    assert gl.uploads - uploads == 3 * LEAF_BLOCK.nbytes         # one block per edit, nothing else
    gl.set_leaf(p.replace(ripple=Ripple(**{**vars(p.ripple), "beta": 2.0})))
    gl.set_leaf(p.replace(ripple=Ripple(**{**vars(p.ripple), "seed": 99})))
    assert gl.ripples.dispatches == dispatches + 2               # one pass each, no geometry


def test_many_leaves_get_their_signals_from_one_dispatch(gl, presets):
    from leafview.gpu.instanced import InstancedLeaves

    rng = np.random.default_rng(5)
    leaves = [_deformed(rng, i) for i in range(24)]
    records, tables = pack_leaves(leaves)
    keys = ripple_keys(leaves)
    assert len(keys) == 24
    with InstancedLeaves(gl.ctx, records, (9, 15), jitter_tables=tables, ripple_signals=keys) as inst:
        assert inst.ripples.dispatches == 1
        fbo = gl.ctx.simple_framebuffer((8, 8))
        fbo.use()
        try:
            pos, _ = inst.capture()
        finally:
            gl.ctx.detect_framebuffer(0).use()
            fbo.release()
    from leafview.deform.surface import grid_uv

    uv = grid_uv(9, 15)
    for i in (0, 11, 23):
        m = leaves[i].transform.matrix()
        ref = leafview.evaluate(leaves[i], uv[:, 0], uv[:, 1]) @ m[:3, :3].T + m[:3, 3]
        np.testing.assert_allclose(pos[i], ref, atol=5e-5)


def test_batched_thumbnails_with_different_signals_match_single_renders(gl, presets):
    leaves = [presets["maize"], presets["holly"], presets["willow"],
              presets["maize"].replace(ripple=Ripple(**{**vars(presets["maize"].ripple), "seed": 4}))]
    batch = gl.render_many(leaves, (64, 64), "three-quarter")
    for leaf, img in zip(leaves, batch):
        diff = np.abs(img.astype(int) - gl.render(leaf, (64, 64), "three-quarter").astype(int)).max(axis=-1)
        assert np.mean(diff > 2) < 0.005, leaf.name
    assert np.abs(batch[0].astype(int) - batch[3].astype(int)).max() > 20  # the seed shows


def test_jitter_ripple_and_bend_together_render_cleanly(gl, presets):
    p = presets["holly"].replace(bending=Bending(load=10, twist=40, petiole_length=0.1),
                                 jitter=Jitter(enabled=True, amplitude=0.03, density=30, seed=2))
    for view in ("top", "side", "three-quarter", "front"):
        img = gl.render(p, (96, 96), view)
        assert 300 < np.count_nonzero(img[..., 3]) < 96 * 96, view
