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
  count of the paper's quartic leaves (the cost of the extension);
* bytes of the leaf record;
* ``landmark_leaves_per_s`` (issue 6 §7): random instances of all 62 catalogue shapes generated
  (:func:`~leafview.botany.catalogue.random_instance` and its margin), fitted to within 1 % in one
  batch (:func:`~leafview.botany.batch_fit.fit_outlines`) and rendered as thumbnails
  (:meth:`~leafview.gpu.renderer.LeafRenderer.render_many`, 128², grid 32 × 64, read back), per
  second, against ``landmark_leaves_per_s_per_leaf``: the same leaves (a subset) through the old
  path, one :func:`~leafview.botany.outline_fit.fit_outline` each (least-squares polish); both
  divided by the paper's 550 /s.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import moderngl
import numpy as np

from leafview.bench import PAPER_LEAVES_PER_S, THUMB_GRID, THUMB_SIZE
from leafview.bench.timing import bench_context, gl_info, median_time
from leafview.botany.batch_fit import fit_outlines
from leafview.botany.catalogue import catalogue_names, landmark_leaf, random_instance
from leafview.botany.landmarks import outline
from leafview.botany.outline_fit import fit_outline
from leafview.botany.shapes import INSTANCE_TARGET, shapes_params
from leafview.core.params import LeafParams, Transform
from leafview.gpu.context import check_error
from leafview.gpu.instanced import InstancedLeaves, OffscreenTarget
from leafview.gpu.layout import LEAF_BLOCK, pack_leaves
from leafview.gpu.renderer import LeafRenderer
from leafview.scene.camera import top_down

__all__ = ["run", "format_table"]

GRID = (9, 15)            # 2 · 8 · 14 = 224 triangles, the paper's ~220
SIZE = (512, 512)
SHAPES = ("ovate", "lanceolate", "cordate", "obovate-convex-concave", "reniform", "elliptic-extended-extended")


def _instances(n: int) -> list[Any]:
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
    cam = top_down((0.0, 0.0), 10.0, 1.0, 1.0, 20.0)   # the [-1, 1]² square the leaves lie in, z ∈ [-10, 10]
    records, tables = pack_leaves(leaves)
    with OffscreenTarget(ctx, SIZE) as target:
        target.use()
        t0 = time.perf_counter()
        inst = InstancedLeaves(ctx, records, GRID, jitter_tables=tables)
        ctx.finish()
        upload = time.perf_counter() - t0
        with inst:
            inst.set_camera(cam)

            def frame() -> None:
                target.clear()
                inst.draw()

            frame()
            ctx.finish()
            return median_time(frame, repeats, ctx.finish), upload


def _landmark_rates(ctx: moderngl.Context, res: dict[str, Any], quick: bool) -> None:
    """Issue 6 §7: landmark leaves generated, fitted and rendered per second, batched path and
    per-leaf path side by side (same leaves, same renderer, same thumbnail size)."""
    names = catalogue_names()
    count, repeats, n_old = (62, 1, 2) if quick else (248, 3, 8)
    bases = [landmark_leaf(names[i % len(names)]) for i in range(count)]

    def generate(k: int) -> tuple[list[Any], np.ndarray]:
        leaves = [random_instance(bases[i], seed=i, amount=0.2) for i in range(k)]
        return leaves, np.stack([outline(leaf, 128) for leaf in leaves])

    renderer = LeafRenderer(ctx)
    try:
        renderer.render_many(_warm_leaves(), THUMB_SIZE, "top", grid=THUMB_GRID)  # compile the shader variants
        ctx.finish()
        stages: dict[str, list[float]] = {"generate": [], "fit": [], "render": []}
        fit = None
        for _ in range(repeats):
            t0 = time.perf_counter()
            leaves, rings = generate(count)
            t1 = time.perf_counter()
            fit = fit_outlines(rings, target=INSTANCE_TARGET, names=[leaf.name for leaf in leaves])
            t2 = time.perf_counter()
            renderer.render_many(fit.params, THUMB_SIZE, "top", grid=THUMB_GRID)
            ctx.finish()
            t3 = time.perf_counter()
            for key, dt in zip(stages, (t1 - t0, t2 - t1, t3 - t2)):
                stages[key].append(dt / count)
        assert fit is not None
        per = {k: statistics.median(v) for k, v in stages.items()}
        res["landmark_count"] = count
        res["landmark_thumbnail"] = list(THUMB_SIZE)
        res["landmark_generate_ms"] = 1e3 * per["generate"]
        res["landmark_fit_batched_ms"] = 1e3 * per["fit"]
        res["landmark_render_ms"] = 1e3 * per["render"]
        res["landmark_leaves_per_s"] = 1.0 / sum(per.values())
        summary = fit.summary()
        res["landmark_fit_error_median"] = summary["error_median"]
        res["landmark_fit_error_p95"] = summary["error_p95"]
        res["landmark_fit_error_max"] = summary["error_max"]
        res["landmark_fit_rows"] = {str(k): v for k, v in summary["rows"].items()}
        res["landmark_fit_fallback"] = summary["fallback"]
        res["landmark_fit_missed"] = summary["missed"]

        # the old path on a subset of the same leaves: one polished fit and one render per leaf
        step = count // n_old
        t0 = time.perf_counter()
        leaves = [random_instance(bases[i], seed=i, amount=0.2) for i in range(0, count, step)][:n_old]
        old_rings = [outline(leaf, 128) for leaf in leaves]
        t1 = time.perf_counter()
        old = [fit_outline(ring, target=INSTANCE_TARGET).params for ring in old_rings]
        t2 = time.perf_counter()
        for params in old:
            renderer.render(params, THUMB_SIZE, "top", grid=THUMB_GRID)
        ctx.finish()
        t3 = time.perf_counter()
        res["landmark_per_leaf_count"] = n_old
        res["landmark_fit_per_leaf_ms"] = 1e3 * (t2 - t1) / n_old
        res["landmark_leaves_per_s_per_leaf"] = n_old / (t3 - t0)
        res["landmark_batched_vs_per_leaf"] = res["landmark_leaves_per_s"] / res["landmark_leaves_per_s_per_leaf"]
        res["landmark_fit_speedup"] = res["landmark_fit_per_leaf_ms"] / res["landmark_fit_batched_ms"]
        res["landmark_vs_paper_550"] = res["landmark_leaves_per_s"] / PAPER_LEAVES_PER_S
        res["landmark_per_leaf_vs_paper_550"] = res["landmark_leaves_per_s_per_leaf"] / PAPER_LEAVES_PER_S
    finally:
        renderer.release()


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
        leaves = _instances(n_fast)
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

        quartic = _scatter([shapes_params("ovate")], count)
        extended = _scatter([shapes_params("cordate")], count)
        tq, _ = _frame_time(ctx, quartic, 3 if quick else 7)
        te, _ = _frame_time(ctx, extended, 3 if quick else 7)
        res["quartic_frame_ms"], res["extended_frame_ms"] = 1e3 * tq, 1e3 * te
        res["extended_vs_quartic_frame"] = te / tq
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
         f"({res['extended_frame_ms']:.1f} / {res['quartic_frame_ms']:.1f} ms)"),
        ("leaf record: parameters / whole", f"{res['param_bytes']} B / {res['record_bytes']} B"),
    ]
    if "landmark_leaves_per_s" in res:
        size = "×".join(str(s) for s in res["landmark_thumbnail"])
        rows += [
            (f"landmark leaves, batched ({res['landmark_count']} of all 62 shapes, {size} thumbnails)",
             f"{res['landmark_leaves_per_s']:,.1f} /s  (generate {res['landmark_generate_ms']:.2f} + fit "
             f"{res['landmark_fit_batched_ms']:.2f} + render {res['landmark_render_ms']:.2f} ms/leaf)"),
            ("  batched fit error (median / p95 / max)", f"{pct(res['landmark_fit_error_median'])} / "
             f"{pct(res['landmark_fit_error_p95'])} / {pct(res['landmark_fit_error_max'])}  (fallbacks "
             f"{res['landmark_fit_fallback']}, above 1 %: {res['landmark_fit_missed']})"),
            ("  rows per leaf", ", ".join(f"{k}: {v}" for k, v in res["landmark_fit_rows"].items())),
            (f"landmark leaves, per-leaf polished fit ({res['landmark_per_leaf_count']} of them)",
             f"{res['landmark_leaves_per_s_per_leaf']:,.2f} /s  (fit {res['landmark_fit_per_leaf_ms']:.0f} ms/leaf)"),
            ("  batched ÷ per-leaf (end to end / fit only)", f"{res['landmark_batched_vs_per_leaf']:.1f}× / "
             f"{res['landmark_fit_speedup']:.1f}×"),
            ("  vs the paper's ~550 /s (batched / per-leaf)", f"{res['landmark_vs_paper_550']:.3g}× / "
             f"{res['landmark_per_leaf_vs_paper_550']:.3g}×"),
        ]
    width = max(len(r[0]) for r in rows)
    head = f"leafview shapes benchmark{' (quick)' if res['quick'] else ''}: {res['gl_renderer']}"
    return "\n".join([head] + [f"  {a:<{width}}  {b}" for a, b in rows])
