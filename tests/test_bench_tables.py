"""Quick runs of the scene and shapes benchmarks: every figure of their tables is measured and
printed (the export and core benchmarks have theirs in test_export_scene and test_benchmarks)."""

from __future__ import annotations

import json

import pytest


@pytest.mark.gl
@pytest.mark.slow
def test_scene_bench_quick_run_fills_the_table(gl):
    from leafview.bench.scene import format_table, run

    res = run(quick=True, ctx=gl.ctx)
    assert res["gl_renderer"] == gl.ctx.info["GL_RENDERER"]
    assert res["lod_speedup_leaves"] == 5_000 and res["lod_speedup"] > 0 and res["lod_off_ms"] > 0
    assert set(res["frames"]) == {"1000", "5000"}
    for row in res["frames"].values():
        for view in ("ground", "three-quarter"):
            assert 0 < row[view]["drawn"] <= 5_000 and sum(row[view]["levels"]) == row[view]["drawn"]
    assert res["lod_switch_px"] >= 0 and res["param_vs_baked_speed"] > 0
    table = format_table(res)
    for key in ("lod_speedup", "lod_switch_px", "param_vs_baked_speed", "baked_vs_param_bytes"):
        assert key in table
    json.dumps(res)


@pytest.mark.gl
@pytest.mark.slow
def test_shapes_bench_quick_run_fills_the_table(gl):
    from leafview.bench.shapes import format_table, run

    res = run(quick=True, ctx=gl.ctx)
    table = format_table(res)
    assert res["gl_renderer"] == gl.ctx.info["GL_RENDERER"] and "vs the paper's ~550 /s" in table
    assert "landmark leaves end to end" in table and "full batch fit" in table
    parts = sum(res[f"landmark_{k}_ms"] for k in ("generate", "ready", "draw"))
    assert abs(1e3 / parts - res["landmark_leaves_per_s"]) <= 1e-9 * res["landmark_leaves_per_s"]
    fit = sum(res[k] for k in ("landmark_fit_generate_ms", "landmark_fit_ms", "landmark_fit_pack_ms",
                               "landmark_fit_draw_ms"))
    assert abs(1e3 / fit - res["landmark_fit_leaves_per_s"]) <= 1e-9 * res["landmark_fit_leaves_per_s"]
    assert res["landmark_fit_generate_ms"] > res["landmark_generate_ms"] and "margin drawn" in table
    assert 0.0 <= res["landmark_fit_within_target"] <= 1.0 and res["landmark_fit_error_max"] > 0.0
    assert 0.0 <= res["landmark_refit_share"] <= 1.0 and "refitted" in table
    json.dumps(res)
