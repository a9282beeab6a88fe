"""``leafview bench shapes``: botanical leaves generated (landmark model → Ω fit) and rendered
per second, against the ~550 leaf instances/s of Garg & Leow 2011, sec. 4.3 (~220 triangles, a
quad-core laptop).

Measured side by side in one process, medians, ``ctx.finish()`` before the clock stops; nothing
is asserted:

* ``landmark_per_s``: random instances (Fig. 8, ±20 %) of catalogue shapes and their margins
  (quadratic B-splines, eqs 2-6), numpy;
* ``fit_fast_per_s`` / ``fit_polished_per_s``: Ω fitted to those margins
  (:func:`~leafview.botany.outline_fit.fit_outline` without and with the least-squares polish, the
  latter to within 1 %), with the median and largest outline error of each;
* ``render_per_s``: the fitted leaves drawn by the instanced shader path, 224 triangles each
  (9 × 15 grid), 512², one draw per frame (upload + prepare pass included in ``upload_ms``);
* ``generated_per_s``: landmark → fast fit → drawn, end to end per leaf, and ``vs_paper_550``
  (``generated_polished_per_s`` the same with the polished fit);
* ``extended_vs_quartic_frame``: frame time of leaves on the extended silhouette path ÷ the same
  count of the paper's quartic leaves (the cost of the extension); ``margin_vs_quartic_frame`` the
  same for leaves drawn with their landmark margin (:mod:`leafview.core.margin`); both in
  interleaved rounds (``bench.timing.interleaved``), with their range (``…_range``);
* bytes of the leaf record;
* ``landmark_leaves_per_s`` (issue 20): random instances of all 62 catalogue shapes end to end,
  per leaf: generated (:func:`~leafview.botany.catalogue.random_instance`), made shader-ready
  (their landmark margins in closed form as the leaves' silhouettes,
  :func:`~leafview.botany.landmarks.margin_params`: nothing fitted; placed and packed into leaf
  records) and drawn (upload and one instanced draw of the whole batch, as ``render_per_s``),
  with its parts (``landmark_generate_ms``, ``landmark_ready_ms``, ``landmark_draw_ms``), the
  draw alone (``landmark_draw_only_per_s``) and this process's CPU time per leaf
  (``landmark_cpu_ms``, all threads: other jobs on a shared machine move it less than the wall
  time);
* ``landmark_fit_leaves_per_s``: the same instances, interleaved, through the Ω fit instead:
  margins sampled (:func:`~leafview.botany.landmarks.outlines`), Ω fitted to within 1 % by
  :func:`~leafview.botany.shapes.fit_instances` (the quick batch fit, then the full batch fit for
  the few leaves it misses), packed and drawn (``landmark_fit_generate_ms``, ``landmark_fit_ms``,
  ``landmark_fit_pack_ms``, ``landmark_fit_draw_ms``; ``landmark_margin_vs_fit`` the ratio), and
  the outline error of the fits as :func:`~leafview.botany.batch_fit.outline_errors` measures it
  (median / p95 / max, share within 1 % without a fold, rows; ``landmark_quick_within_target``:
  the share of that fit's quick pass within the target alone, ``landmark_refit_share``: the
  share it refitted); ``landmark_full_*``: a subset of the same leaves through the full batch fit
  (:func:`~leafview.botany.batch_fit.fit_outlines`, with its per-leaf fallback).
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

import moderngl
import numpy as np

from leafview.bench import PAPER_LEAVES_PER_S
from leafview.bench.timing import bench_context, gl_info, interleaved, median_time
from leafview.botany.batch_fit import controls_from_params, fit_outlines, min_jacobians, outline_errors, split_outlines
from leafview.botany.catalogue import catalogue_names, landmark_leaf, random_instance
from leafview.botany.landmarks import margin_params, outline, outlines
from leafview.botany.outline_fit import fit_outline
from leafview.botany.shapes import INSTANCE_TARGET, fit_instances, shapes_params
from leafview.core.params import LeafParams, Transform
from leafview.gpu.context import check_error
from leafview.gpu.instanced import InstancedLeaves, OffscreenTarget
from leafview.gpu.layout import LEAF_BLOCK, pack_leaves
from leafview.gpu.resources import GpuResources
from leafview.scene.camera import top_down

__all__ = ["run", "format_table"]

GRID = (9, 15)            # 2 · 8 · 14 = 224 triangles, the paper's ~220
SIZE = (512, 512)
SHAPES = ("ovate", "lanceolate", "cordate", "obovate-convex-concave", "reniform", "elliptic-extended-extended")


def _landmarks(n: int) -> list[Any]:
    return [random_instance(landmark_leaf(SHAPES[i % len(SHAPES)]), seed=i, amount=0.2) for i in range(n)]


def _scatter(leaves: list[Any], count: int, seed: int = 0) -> list[Any]:
    """``count`` copies of ``leaves`` on a jittered grid in the xy plane (all visible)."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(count)))
    out = []
    for k in range(count):
        x, y = (k % side) / side * 2 - 1, (k // side) / side * 2 - 1
        t = Transform(translation=(float(x), float(y), 0.0), rotation=(0.0, 0.0, float(rng.uniform(-40, 40))),
                      scale=1.6 / side)
        out.append(leaves[k % len(leaves)].replace(transform=t))
    return out


def _frame_time(ctx: moderngl.Context, leaves: list[Any], repeats: int) -> tuple[float, float]:
    """(median frame seconds, upload seconds) drawing ``leaves`` in one instanced draw."""
    with OffscreenTarget(ctx, SIZE) as target:
        t0 = time.perf_counter()
        inst = _instanced(ctx, leaves)
        ctx.finish()
        upload = time.perf_counter() - t0
        with inst:
            frame = _frame(target, inst)
            frame()
            ctx.finish()
            return median_time(frame, repeats, ctx.finish), upload


def _instanced(ctx: moderngl.Context, leaves: list[Any]) -> InstancedLeaves:
    """``leaves`` uploaded for one instanced draw, seen from above (the [-1, 1]² square they lie in)."""
    records, tables = pack_leaves(leaves)
    inst = InstancedLeaves(ctx, records, GRID, jitter_tables=tables)
    inst.set_camera(top_down((0.0, 0.0), 10.0, 1.0, 1.0, 20.0))
    return inst


def _rounds(r: list[float]) -> str:
    return f"{r[0]:.2f}-{r[1]:.2f}"


def _frame(target: OffscreenTarget, inst: InstancedLeaves) -> Callable[[], None]:
    def frame() -> None:
        target.use()
        target.clear()
        inst.draw()
    return frame


def _kind_ratios(ctx: moderngl.Context, res: dict[str, Any], count: int, n_fast: int, rounds: int) -> None:
    """Frame time of the same count of leaves on the extended silhouette and with their landmark
    margin drawn, each ÷ the paper's quartic leaves, in interleaved rounds."""
    kinds = {"quartic": _scatter([shapes_params("ovate")], count),
             "extended": _scatter([shapes_params("cordate")], count),
             "margin": _scatter(margin_params(_landmarks(n_fast)), count)}
    with OffscreenTarget(ctx, SIZE) as target:
        insts = {k: _instanced(ctx, v) for k, v in kinds.items()}
        try:
            quartic = _frame(target, insts["quartic"])
            for kind in ("extended", "margin"):
                r = interleaved(quartic, _frame(target, insts[kind]), rounds, ctx.finish)
                res[f"{kind}_vs_quartic_frame"] = r["ratio"]
                res[f"{kind}_vs_quartic_frame_range"] = r["range"]
                res[f"{kind}_frame_ms"] = r["other_ms"]
                res.setdefault("quartic_frame_ms", r["base_ms"])
        finally:
            for inst in insts.values():
                inst.release()


def _draw_batch(ctx: moderngl.Context, resources: GpuResources, target: OffscreenTarget, records: Any,
                tables: Any) -> None:
    """Upload ``records`` and draw them once (the instanced path, ``GRID``, into ``target``), waited for."""
    with InstancedLeaves(ctx, records, GRID, jitter_tables=tables, resources=resources) as inst:
        inst.set_camera(top_down((0.0, 0.0), 10.0, 1.0, 1.0, 20.0))
        target.clear()
        inst.draw()
        ctx.finish()


def _landmark_rates(ctx: moderngl.Context, res: dict[str, Any], quick: bool) -> None:
    """Issue 20: landmark leaves per second end to end, two ways side by side on the same random
    instances of all 62 catalogue shapes, interleaved in each repeat. Per leaf:

    * **margin** (``landmark_*``, the headline): *generate* the instances
      (:func:`~leafview.botany.catalogue.random_instance`), make them *shader-ready* (their
      margins in closed form, :func:`~leafview.botany.landmarks.margin_params`, placed and packed
      into leaf records: the shader draws the landmark B-spline itself, nothing is fitted) and
      *draw* them (upload and one instanced draw of the batch, as ``render_per_s``);
    * **fit** (``landmark_fit_*``): the same instances' margins sampled
      (:func:`~leafview.botany.landmarks.outlines`), Ω fitted to within 1 % by
      :func:`~leafview.botany.shapes.fit_instances` (the quick batch fit, the full batch fit for
      the few it misses), placed, packed and drawn. The fitted margins' outline error is then
      measured (untimed) with :func:`~leafview.botany.batch_fit.outline_errors`. A subset also
      goes through the full batch fit alone (``landmark_full_*``)."""
    names = catalogue_names()
    count, repeats, n_full = (248, 3, 62) if quick else (992, 5, 124)
    bases = [landmark_leaf(names[i % len(names)]) for i in range(count)]
    resources = GpuResources(ctx)
    try:
        with OffscreenTarget(ctx, SIZE) as target:
            target.use()
            warm = pack_leaves(_scatter(_warm_leaves(), 2))
            _draw_batch(ctx, resources, target, *warm)      # compile the programs once
            _draw_batch(ctx, resources, target, *pack_leaves(_scatter(margin_params(bases[:2]), 2)))
            stages: dict[str, list[float]] = {"generate": [], "ready": [], "draw": []}
            fit_stages: dict[str, list[float]] = {"generate": [], "fit": [], "pack": [], "draw": []}
            cpu: list[float] = []
            fitted, rings, names_now, instance_fit = None, None, [], None
            for rep in range(repeats):
                c0, t0 = time.process_time(), time.perf_counter()
                leaves = [random_instance(bases[i], seed=rep * count + i, amount=0.2) for i in range(count)]
                t1 = time.perf_counter()
                records, tables = pack_leaves(_scatter(margin_params(leaves), count))
                t2 = time.perf_counter()
                _draw_batch(ctx, resources, target, records, tables)
                t3 = time.perf_counter()
                cpu.append((time.process_time() - c0) / count)
                for key, dt in zip(stages, (t1 - t0, t2 - t1, t3 - t2)):
                    stages[key].append(dt / count)

                t0 = time.perf_counter()
                rings = outlines(leaves, 128)
                t1 = time.perf_counter()
                names_now = [leaf.name for leaf in leaves]
                instance_fit = fit_instances(rings, INSTANCE_TARGET, names_now)
                fitted = instance_fit.params
                t2 = time.perf_counter()
                records, tables = pack_leaves(_scatter(fitted, count))
                t3 = time.perf_counter()
                _draw_batch(ctx, resources, target, records, tables)
                t4 = time.perf_counter()
                gen = stages["generate"][-1] * count    # the same instances: generated once, above
                for key, dt in zip(fit_stages, (gen + t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
                    fit_stages[key].append(dt / count)
            assert fitted is not None and rings is not None and instance_fit is not None
            per = {k: statistics.median(v) for k, v in stages.items()}
            res["landmark_count"] = count
            for key, value in per.items():
                res[f"landmark_{key}_ms"] = 1e3 * value
            res["landmark_leaves_per_s"] = 1.0 / sum(per.values())
            # CPU seconds of this process (all its threads, llvmpipe's included) per leaf: less
            # sensitive than wall time to the other jobs sharing the machine
            res["landmark_cpu_ms"] = 1e3 * statistics.median(cpu)
            res["landmark_vs_paper_550"] = res["landmark_leaves_per_s"] / PAPER_LEAVES_PER_S
            res["landmark_draw_only_per_s"] = 1.0 / per["draw"]
            fper = {k: statistics.median(v) for k, v in fit_stages.items()}
            for key, value in fper.items():
                res[f"landmark_fit_{key}_ms" if key != "fit" else "landmark_fit_ms"] = 1e3 * value
            res["landmark_fit_leaves_per_s"] = 1.0 / sum(fper.values())
            res["landmark_margin_vs_fit"] = res["landmark_leaves_per_s"] / res["landmark_fit_leaves_per_s"]
            right, left = split_outlines(rings)
            ctrl = controls_from_params(fitted)
            measured = outline_errors(ctrl, right, left)[:, 0]
            min_jacobian = min_jacobians(ctrl)
            res.update(_error_figures("landmark_fit", measured, min_jacobian, [p.shape.rows for p in fitted]))
            # the quick pass of that same fit: its own bound against the measured error
            alone = instance_fit.quick
            res["landmark_refit_share"] = instance_fit.refit_share
            alone_measured = outline_errors(controls_from_params(alone.params), right, left)[:, 0]
            res["landmark_quick_within_target"] = float(((alone_measured <= INSTANCE_TARGET)
                                                         & (alone.min_jacobian > 0.0)).mean())
            res["landmark_fit_bound_gap"] = float(np.max(alone_measured - alone.errors))

            # side by side: the same kind of leaves through the full batch fit (a subset)
            t0 = time.perf_counter()
            full = fit_outlines(rings[:n_full], target=INSTANCE_TARGET, names=names_now[:n_full])
            t1 = time.perf_counter()
            _draw_batch(ctx, resources, target, *pack_leaves(_scatter(full.params, n_full)))
            t2 = time.perf_counter()
            res["landmark_full_count"] = n_full
            res["landmark_full_fit_ms"] = 1e3 * (t1 - t0) / n_full
            res["landmark_full_leaves_per_s"] = 1.0 / (fper["generate"] + (t2 - t0) / n_full)
            res.update(_error_figures("landmark_full_fit", full.errors, full.min_jacobian, full.rows))
            res["landmark_full_fit_fallback"] = full.n_fallback
            res["landmark_fit_speedup"] = res["landmark_full_fit_ms"] / res["landmark_fit_ms"]
    finally:
        resources.release()


def _error_figures(key: str, errors: Any, min_jacobian: Any, rows: Any) -> dict[str, Any]:
    """Median / 95th percentile / largest outline error, the share of leaves within
    ``INSTANCE_TARGET`` without a fold, and the rows histogram, under ``key``."""
    e = np.asarray(errors, np.float64)
    ok = (e <= INSTANCE_TARGET) & (np.asarray(min_jacobian) > 0.0)
    return {f"{key}_error_median": float(np.median(e)), f"{key}_error_p95": float(np.percentile(e, 95)),
            f"{key}_error_max": float(e.max()), f"{key}_within_target": float(ok.mean()),
            f"{key}_rows": {str(k): int(v) for k, v in zip(*np.unique(rows, return_counts=True))}}


def _warm_leaves() -> list[LeafParams]:
    return [shapes_params("ovate"), shapes_params("cordate")]


def run(quick: bool = False, ctx: moderngl.Context | None = None) -> dict[str, Any]:
    """Run the shapes benchmark on ``ctx`` (default a new headless context); see the module
    docstring for the keys."""
    with bench_context(ctx) as ctx:
        res: dict[str, Any] = {"gl_renderer": gl_info(ctx)["gl_renderer"], "quick": quick,
                               "paper_leaves_per_s": PAPER_LEAVES_PER_S,
                               "triangles_per_leaf": 2 * (GRID[0] - 1) * (GRID[1] - 1)}
        n_fast, n_polish = (12, 3) if quick else (60, 30)
        t0 = time.perf_counter()
        leaves = _landmarks(n_fast)
        rings = [outline(leaf, 128) for leaf in leaves]
        res["landmark_per_s"] = n_fast / (time.perf_counter() - t0)

        def timed_fits(key: str, outlines: list, **options: Any) -> list:
            fits, times = [], []
            for ring in outlines:
                t = time.perf_counter()
                fits.append(fit_outline(ring, **options))
                times.append(time.perf_counter() - t)
            res[f"fit_{key}_per_s"] = 1.0 / statistics.mean(times)
            res[f"fit_{key}_error_median"] = statistics.median(f.error for f in fits)
            res[f"fit_{key}_error_max"] = max(f.error for f in fits)
            return fits

        fast = timed_fits("fast", rings, polish=False)
        timed_fits("polished", rings[:n_polish], target=INSTANCE_TARGET)
        res["fit_extended_fraction"] = float(np.mean([not f.quartic for f in fast]))

        count = 1000 if quick else 10000
        drawn = _scatter([f.params for f in fast], count)
        frame, upload = _frame_time(ctx, drawn, 3 if quick else 7)
        res["render_leaves"] = count
        res["render_frame_ms"] = 1e3 * frame
        res["upload_ms"] = 1e3 * upload
        res["render_per_s"] = count / frame
        per_leaf = 1.0 / res["landmark_per_s"] + 1.0 / res["fit_fast_per_s"] + (frame + upload) / count
        res["generated_per_s"] = 1.0 / per_leaf
        res["generated_polished_per_s"] = 1.0 / (per_leaf - 1.0 / res["fit_fast_per_s"] + 1.0 / res["fit_polished_per_s"])
        res["vs_paper_550"] = res["generated_per_s"] / PAPER_LEAVES_PER_S

        # the extended silhouette and the landmark margin drawn as the silhouette
        # (leafview.core.margin): their cost in the shader, side by side with quartic leaves
        _kind_ratios(ctx, res, count, n_fast, 3 if quick else 7)
        res["record_bytes"] = LEAF_BLOCK.nbytes
        res["param_bytes"] = LEAF_BLOCK.parameter_nbytes
        _landmark_rates(ctx, res, quick)
        check_error(ctx, "shapes benchmark")
    return res


def format_table(res: dict[str, Any]) -> str:
    """The readable report of :func:`run`."""
    pct = lambda x: f"{100 * x:.2f} %"  # noqa: E731
    rows = [
        ("landmark instances + margins (numpy)", f"{res['landmark_per_s']:,.0f} /s"),
        ("Ω fit, linear (median / max error)", f"{res['fit_fast_per_s']:,.1f} /s  "
         f"({pct(res['fit_fast_error_median'])} / {pct(res['fit_fast_error_max'])})"),
        ("Ω fit, least-squares polish (median / max error)", f"{res['fit_polished_per_s']:,.2f} /s  "
         f"({pct(res['fit_polished_error_median'])} / {pct(res['fit_polished_error_max'])})"),
        ("fits on the extended silhouette", pct(res["fit_extended_fraction"])),
        (f"render, {res['render_leaves']:,} leaves × {res['triangles_per_leaf']} tri, 512², one draw",
         f"{res['render_per_s']:,.0f} /s  ({res['render_frame_ms']:.1f} ms/frame, upload {res['upload_ms']:.1f} ms)"),
        ("generated end to end (landmarks → fit → drawn)", f"{res['generated_per_s']:,.1f} /s  "
         f"(with the polished fit: {res['generated_polished_per_s']:,.2f} /s)"),
        ("  vs the paper's ~550 /s", f"{res['vs_paper_550']:.3g}×"),
        ("extended ÷ quartic frame time", f"{res['extended_vs_quartic_frame']:.2f}  "
         f"({res['extended_frame_ms']:.1f} / {res['quartic_frame_ms']:.1f} ms, "
         f"rounds {_rounds(res['extended_vs_quartic_frame_range'])})"),
        ("landmark margin ÷ quartic frame time", f"{res['margin_vs_quartic_frame']:.2f}  "
         f"({res['margin_frame_ms']:.1f} / {res['quartic_frame_ms']:.1f} ms, "
         f"rounds {_rounds(res['margin_vs_quartic_frame_range'])})"),
        ("leaf record: parameters / whole", f"{res['param_bytes']} B / {res['record_bytes']} B"),
    ]
    if "landmark_leaves_per_s" in res:
        def errors(key: str) -> str:
            return (f"{pct(res[key + '_error_median'])} / {pct(res[key + '_error_p95'])} / {pct(res[key + '_error_max'])}"
                    f"  (within 1 %: {pct(res[key + '_within_target'])})")

        rows += [
            (f"landmark leaves end to end, margin drawn ({res['landmark_count']} of all 62 shapes, 224 tri, 512²)",
             f"{res['landmark_leaves_per_s']:,.1f} /s  (generate {res['landmark_generate_ms']:.3f} + shader-ready "
             f"{res['landmark_ready_ms']:.3f} + draw {res['landmark_draw_ms']:.3f} ms/leaf; exact margin)"),
            ("  CPU time per leaf, all threads of this process", f"{res['landmark_cpu_ms']:.3f} ms"),
            ("  vs the paper's ~550 /s (end to end / draw only)", f"{res['landmark_vs_paper_550']:.3g}× / "
             f"{res['landmark_draw_only_per_s'] / res['paper_leaves_per_s']:.3g}×"),
            ("landmark leaves end to end, Ω fitted (the same leaves)",
             f"{res['landmark_fit_leaves_per_s']:,.1f} /s  (generate + sample {res['landmark_fit_generate_ms']:.3f} "
             f"+ fit {res['landmark_fit_ms']:.3f} + pack {res['landmark_fit_pack_ms']:.3f} + draw "
             f"{res['landmark_fit_draw_ms']:.3f} ms/leaf; margin path {res['landmark_margin_vs_fit']:.1f}× faster)"),
            ("  fit error (median / p95 / max)", errors("landmark_fit")),
            ("  quick pass within 1 % alone / refitted (timed above)",
             f"{100 * res['landmark_quick_within_target']:.1f} % / {100 * res['landmark_refit_share']:.1f} %"),
            ("  rows per leaf", ", ".join(f"{k}: {v}" for k, v in res["landmark_fit_rows"].items())),
            (f"landmark leaves, full batch fit ({res['landmark_full_count']} of them)",
             f"{res['landmark_full_leaves_per_s']:,.1f} /s  (fit {res['landmark_full_fit_ms']:.1f} ms/leaf, "
             f"{res['landmark_full_fit_fallback']} fallbacks; quick fit {res['landmark_fit_speedup']:.0f}× faster)"),
            ("  full fit error (median / p95 / max)", errors("landmark_full_fit")),
        ]
    width = max(len(r[0]) for r in rows)
    head = f"leafview shapes benchmark{' (quick)' if res['quick'] else ''}: {res['gl_renderer']}"
    return "\n".join([head] + [f"  {a:<{width}}  {b}" for a, b in rows])
