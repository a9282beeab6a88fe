"""``leafview bench shapes``: botanical leaves generated (landmark model → Ω fit) and rendered
per second, against Garg & Leow's ~550 leaf instances/s (seed 001 sec. 4.3, ~220 triangles, a
quad-core laptop).

Measured side by side in one process, medians, ``ctx.finish()`` before the clock stops; nothing
is asserted:

* ``landmark_per_s``: random instances (Fig. 8, ±20 %) of catalogue shapes and their margins
  (quadratic B-splines, eqs 2-6), numpy;
* ``fit_fast_per_s`` / ``fit_polished_per_s``: Ω fitted to those margins
  (:func:`~leafview.model.outline_fit.fit_outline` without and with the least-squares polish, the
  latter to within 1 %), with the median and largest outline error of each;
* ``render_per_s``: the fitted leaves drawn by the instanced shader path, 224 triangles each
  (9 × 15 grid), 512², one draw per frame (upload + prepare pass included in ``upload_ms``);
* ``generated_per_s``: landmark → fast fit → drawn, end to end per leaf, and ``vs_paper_550``
  (``generated_polished_per_s`` the same with the polished fit);
* ``extended_vs_quartic_frame``: frame time of leaves on the extended silhouette path ÷ the same
  count of the paper's quartic leaves (the cost of the extension);
* bytes of the leaf record.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np

__all__ = ["run", "format_table"]

GRID = (9, 15)            # 2 · 8 · 14 = 224 triangles, the paper's ~220
SIZE = (512, 512)
SHAPES = ("ovate", "lanceolate", "cordate", "obovate-convex-concave", "reniform", "elliptic-extended-extended")


def _instances(n: int) -> list[Any]:
    from ..model.shapes import landmark_leaf, random_instance

    return [random_instance(landmark_leaf(SHAPES[i % len(SHAPES)]), seed=i, amount=0.2) for i in range(n)]


def _scatter(leaves: list[Any], count: int, seed: int = 0) -> list[Any]:
    """``count`` copies of ``leaves`` on a jittered grid in the xy plane (all visible)."""
    from ..model.params import Transform

    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(count)))
    out = []
    for k in range(count):
        x, y = (k % side) / side * 2 - 1, (k // side) / side * 2 - 1
        t = Transform(translation=(float(x), float(y), 0.0), rotation=(0.0, 0.0, float(rng.uniform(-40, 40))),
                      scale=1.6 / side)
        out.append(leaves[k % len(leaves)].replace(transform=t))
    return out


def _frame_time(ctx: Any, leaves: list[Any], repeats: int) -> tuple[float, float]:
    """(median frame seconds, upload seconds) drawing ``leaves`` in one instanced draw."""
    from ..benchmarks import _median_time
    from ..camera import Camera
    from ..gpu.instanced import InstancedLeaves, OffscreenTarget
    from ..gpu.layout import pack_leaves

    view = np.eye(4)
    proj = np.diag([1.0, 1.0, -0.1, 1.0])
    cam = Camera(view=view, proj=proj, eye=np.array([0.0, 0.0, -1.0, 0.0]), perspective=False)
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
            return _median_time(frame, repeats, ctx.finish), upload


def run(quick: bool = False, ctx: Any = None) -> dict[str, Any]:
    from ..benchmarks import PAPER_LEAVES_PER_S
    from ..gpu.context import check_error, create_headless_context
    from ..gpu.layout import LEAF_BLOCK
    from ..model.landmarks import outline
    from ..model.outline_fit import fit_outline
    from . import INSTANCE_TARGET, shapes_params

    own = ctx is None
    if own:
        ctx = create_headless_context()
    res: dict[str, Any] = {"gl_renderer": str(ctx.info["GL_RENDERER"]), "quick": quick,
                           "paper_leaves_per_s": PAPER_LEAVES_PER_S, "triangles_per_leaf": 2 * (GRID[0] - 1) * (GRID[1] - 1)}
    try:
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
        check_error(ctx, "shapes benchmark")
    finally:
        if own:
            ctx.release()
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
    width = max(len(r[0]) for r in rows)
    head = f"leafview shapes benchmark{' (quick)' if res['quick'] else ''}: {res['gl_renderer']}"
    return "\n".join([head] + [f"  {a:<{width}}  {b}" for a, b in rows])
