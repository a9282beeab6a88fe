"""``leafview bench capture``: accuracy and speed of fitting to captured data (Chaurasia &
Beardsley 2017, secs 4-5), on synthetic captures with a known truth.

Two tables:

* **one leaf** (:func:`leafview.fit.cloud.fit_cloud`): curved presets (:func:`leafview.fit.synthetic.curled`,
  8 cm long, random pose), 5,000 area-uniform points, the outer part of one half hidden (about
  30 % of the leaf), noise σ = 0.5 % of the length. Per leaf: the median distance of the visible
  and of the hidden truth points to the fit (in % of the length), the alternations of
  Levenberg-Marquardt and UV update, and the time of the fit.
* **a plant** (:func:`leafview.fit.capture.capture`): a plant of 200 leaves with stems
  (``leafview scene --layout plant``), 8 views at 1024×768 with depth noise and grazing holes
  (:func:`leafview.export.views.render_views`), captured, then scored by
  :func:`leafview.fit.evaluate.evaluate_capture` against the truth: recall of the leaves at least
  half visible, precision, median Chamfer distance, and the capture's time (reading the views
  included, rendering them not).

The GL renderer is logged and part of the result (it draws the views and the captured leaves; the
fitting itself runs on the CPU). Nothing here is asserted: the goals are printed beside the figures.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import moderngl
import numpy as np

from leafview.bench.timing import Progress, bench_context, gl_info, log_gl_renderer
from leafview.core.params import LeafParams
from leafview.export.views import render_instance_ids, render_views
from leafview.fit.capture import capture
from leafview.fit.cloud import fit_cloud, surface_distance
from leafview.fit.evaluate import evaluate_capture
from leafview.fit.synthetic import curled, occluded_cloud
from leafview.fit.views import read_views
from leafview.gpu.resources import GpuResources
from leafview.resources import builtin_presets
from leafview.scene.spec import SceneSpec, build_scene

__all__ = ["run", "format_table", "GOALS", "LEAF_PRESETS", "PLANT_LEAVES", "PLANT_VIEWS", "PLANT_SIZE"]

GOALS = {"visible_pct": 1.0, "hidden_pct": 3.0, "iterations": (4, 15), "fit_seconds": 0.2,
         "recall_visible_50": 0.8, "precision": 0.9, "median_chamfer_pct": 3.0, "capture_seconds": 120.0}
LEAF_PRESETS = ("ovate", "beech", "elliptic", "lanceolate", "obovate")
LENGTH = 0.08
PLANT_LEAVES, PLANT_VIEWS, PLANT_SIZE, PLANT_SEED = 200, 8, (1024, 768), 7
DEPTH_NOISE, HOLES = 0.005, True


def _leaf_rows(count: int) -> list[dict[str, Any]]:
    rows = []
    for i in range(count):
        name = LEAF_PRESETS[i % len(LEAF_PRESETS)]
        truth = curled(LeafParams.load(builtin_presets()[name]), seed=100 + i, length=LENGTH)
        case = occluded_cloud(truth, 5000, seed=100 + i)
        t0 = time.perf_counter()
        fit = fit_cloud(case.cloud, seed=i)
        seconds = time.perf_counter() - t0
        rows.append({"preset": name, "points": len(case.cloud),
                     "hidden_share": len(case.hidden) / (len(case.hidden) + len(case.visible)),
                     "visible_pct": 100 * float(np.median(surface_distance(case.visible, fit.params))) / LENGTH,
                     "hidden_pct": 100 * float(np.median(surface_distance(case.hidden, fit.params))) / LENGTH,
                     "iterations": fit.iterations, "seconds": seconds, "explained": fit.explained})
    return rows


def _plant(ctx: moderngl.Context, quick: bool, progress: Progress) -> dict[str, Any]:
    leaves, views, size = (40, 3, (480, 360)) if quick else (PLANT_LEAVES, PLANT_VIEWS, PLANT_SIZE)
    spec = SceneSpec(species=(LeafParams.load(builtin_presets()["ovate"]),), name="plant", leaves=leaves,
                     layout="plant", seed=PLANT_SEED)   # what `leafview scene --layout plant` builds
    scene = build_scene(spec)
    resources = GpuResources(ctx)   # one set of programs for the views and every view's ids
    with resources, tempfile.TemporaryDirectory(prefix="leafview-bench-capture-") as tmp:
        out = Path(tmp) / "views"
        progress.step(f"rendering {views} views of {leaves} leaves")
        render_views(ctx, scene, out, views=views, size=size, depth_noise=DEPTH_NOISE,
                     holes=HOLES, seed=PLANT_SEED, resources=resources)
        progress.step("capturing")
        t0 = time.perf_counter()
        read = read_views(out)
        result = capture(read, seed=0)
        seconds = time.perf_counter() - t0
        progress.step("scoring")
        truth = scene.placed_leaves()
        predicted = [render_instance_ids(ctx, list(result.leaves), v.k, v.world_from_camera,
                                         (v.depth.shape[1], v.depth.shape[0]), resources=resources) for v in read]
        cameras = []
        for v in read:
            assert v.instance is not None   # render_views wrote it
            cameras.append((v.k, v.world_from_camera, v.instance))
        ev = evaluate_capture(truth, list(result.leaves), cameras, predicted)
    return {"leaves": leaves, "views": views, "size": list(size), "depth_noise": DEPTH_NOISE,
            "holes": HOLES, "candidates": len(result.candidates), "captured": len(result.leaves),
            "rejected": len(result.rejected), "seconds": seconds,
            "stage_seconds": {k: float(v) for k, v in result.timings.items()},
            "recall_visible_50": ev.recall_visible_50, "recall": ev.recall, "precision": ev.precision,
            "median_chamfer_pct": ev.median_chamfer, "table": ev.table(), "delta_plane": result.delta_plane}


def run(quick: bool = False, ctx: moderngl.Context | None = None) -> dict[str, Any]:
    """Measure (see the module docstring); ``quick``: 2 leaves, a 40-leaf plant in 3 views at 480×360."""
    count = 2 if quick else 10
    with bench_context(ctx) as c:
        info = gl_info(c)
        log_gl_renderer("capture", info["gl_renderer"])
        with Progress(count + 3) as progress:
            progress.step(f"fitting {count} occluded leaves")
            rows = _leaf_rows(count)
            plant = _plant(c, quick, progress)
    single = {"leaves": rows, "visible_pct": statistics.median(r["visible_pct"] for r in rows),
              "hidden_pct": statistics.median(r["hidden_pct"] for r in rows),
              "hidden_pct_max": max(r["hidden_pct"] for r in rows),
              "iterations": [min(r["iterations"] for r in rows), max(r["iterations"] for r in rows)],
              "fit_seconds": statistics.median(r["seconds"] for r in rows)}
    return {**info, "quick": quick, "goals": GOALS, "single_leaf": single, "plant": plant}


def format_table(res: dict[str, Any]) -> str:
    """The readable report printed by ``leafview bench capture``."""
    g, s, p = res["goals"], res["single_leaf"], res["plant"]

    def mark(ok: bool) -> str:
        return "met" if ok else "NOT met"

    lines = [f"leafview capture benchmark{' (quick)' if res['quick'] else ''}: {res['gl_renderer']} ({res['gl_version']})",
             f"one leaf: {len(s['leaves'])} curved leaves, 5,000 points, ~30 % of one side hidden, noise 0.5 % "
             "of the length",
             f"  visible points to the fit, median   {s['visible_pct']:6.2f} % of the length  (goal ≤ "
             f"{g['visible_pct']:g} %: {mark(s['visible_pct'] <= g['visible_pct'])})",
             f"  hidden points to the fit, median    {s['hidden_pct']:6.2f} %  (worst leaf {s['hidden_pct_max']:.2f} %;"
             f" goal ≤ {g['hidden_pct']:g} %: {mark(s['hidden_pct'] <= g['hidden_pct'])})",
             f"  alternations                        {s['iterations'][0]}-{s['iterations'][1]}  (goal "
             f"{g['iterations'][0]}-{g['iterations'][1]})",
             f"  time per leaf, median               {1e3 * s['fit_seconds']:6.0f} ms  (goal ≤ "
             f"{1e3 * g['fit_seconds']:g} ms: {mark(s['fit_seconds'] <= g['fit_seconds'])})",
             f"a plant: {p['leaves']} leaves, {p['views']} views at {p['size'][0]}×{p['size'][1]}, depth noise "
             f"{p['depth_noise']:g}{', holes' if p['holes'] else ''}: {p['candidates']} candidates, {p['captured']} "
             f"leaves captured, {p['rejected']} rejected",
             f"  recall (leaves ≥ 50 % visible)      {p['recall_visible_50']:6.2f}  (goal ≥ {g['recall_visible_50']:g}: "
             f"{mark(p['recall_visible_50'] >= g['recall_visible_50'])})",
             f"  precision                           {p['precision']:6.2f}  (goal ≥ {g['precision']:g}: "
             f"{mark(p['precision'] >= g['precision'])})",
             f"  median Chamfer distance             {p['median_chamfer_pct']:6.2f} % of the length  (goal ≤ "
             f"{g['median_chamfer_pct']:g} %: {mark(p['median_chamfer_pct'] <= g['median_chamfer_pct'])})",
             f"  capture time                        {p['seconds']:6.1f} s  (goal ≤ {g['capture_seconds']:g} s: "
             f"{mark(p['seconds'] <= g['capture_seconds'])}; "
             + ", ".join(f"{k} {v:.1f} s" for k, v in p["stage_seconds"].items()) + ")",
             p["table"]]
    return "\n".join(lines)
