"""``leafview bench dataset``: dataset images per second on the local engine, 1 worker against 2.

Each round makes the same dataset (640×480, 100 leaves per image, the default plant layout and
species, every output: picture, instance ids, depth, normals, (u, v), COCO records, cameras,
leaf sets) once with 1 worker and once with 2, in alternating order, into fresh folders; the
workers get ``LP_NUM_THREADS`` = CPUs // workers (llvmpipe's rasteriser threads).

* ``images_per_s``: steady throughput, the images after each worker's first one over the time
  from the ``workers``-th image to the last (worker start-up, context creation and shader
  compilation left out); ``wall_images_per_s``: all images over the whole call;
* ``ratio``: the median over rounds of (2 workers ÷ 1 worker) steady throughput; goal ≥ 1.6.

The GL renderer is logged before the run and is part of the result: on llvmpipe the workers share
this machine's CPUs, on a GPU driver they share the GPU. Nothing here is asserted.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import moderngl

from leafview.bench.timing import Progress, bench_context, gl_info, log_gl_renderer
from leafview.dataset import make_dataset
from leafview.dataset.engines import default_threads

__all__ = ["run", "format_table", "GOALS", "SIZE", "LEAVES"]

GOALS = {"ratio": 1.6}
SIZE = (640, 480)
LEAVES = 100
WORKERS = (1, 2)


def _measure(folder: Path, workers: int, count: int, size: tuple[int, int], leaves: int,
             shard_size: int) -> dict[str, float]:
    stamps: list[float] = []
    t0 = time.perf_counter()
    report = make_dataset(folder, count, leaves=leaves, size=size, seed=1, shard_size=shard_size, workers=workers,
                          threads=default_threads(workers), on_image=lambda: stamps.append(time.perf_counter()))
    wall = time.perf_counter() - t0
    first = stamps[min(workers, len(stamps)) - 1]
    steady = (len(stamps) - workers) / (stamps[-1] - first) if len(stamps) > workers and stamps[-1] > first else 0.0
    return {"images_per_s": steady, "wall_images_per_s": report.images_rendered / wall, "seconds": wall}


def run(quick: bool = False, ctx: moderngl.Context | None = None) -> dict[str, Any]:
    """Measure (see the module docstring); ``quick``: 160×120, 20 leaves, 6 images, one round."""
    size, leaves = ((160, 120), 20) if quick else (SIZE, LEAVES)
    count, shard_size, rounds = (6, 1, 1) if quick else (24, 2, 3)
    with bench_context(ctx) as c:
        info = gl_info(c)
    log_gl_renderer("dataset", info["gl_renderer"])
    runs: dict[int, list[dict[str, float]]] = {w: [] for w in WORKERS}
    with Progress(rounds * len(WORKERS)) as progress, tempfile.TemporaryDirectory(prefix="leafview-bench-") as tmp:
        for r in range(rounds):
            order = WORKERS if r % 2 == 0 else WORKERS[::-1]
            for w in order:
                progress.step(f"round {r + 1}: {w} worker{'s' if w > 1 else ''}")
                runs[w].append(_measure(Path(tmp) / f"r{r}w{w}", w, count, size, leaves, shard_size))
    ratios = [b["images_per_s"] / a["images_per_s"] for a, b in zip(runs[1], runs[2]) if a["images_per_s"] > 0]
    return {**info, "quick": quick, "size": list(size), "leaves": leaves, "images_per_run": count,
            "shard_size": shard_size, "rounds": rounds, "threads": {str(w): default_threads(w) for w in WORKERS},
            "images_per_s": {str(w): statistics.median(x["images_per_s"] for x in runs[w]) for w in WORKERS},
            "wall_images_per_s": {str(w): statistics.median(x["wall_images_per_s"] for x in runs[w])
                                  for w in WORKERS},
            "ratio": statistics.median(ratios) if ratios else 0.0,
            "ratio_range": [min(ratios), max(ratios)] if ratios else [0.0, 0.0], "goal": GOALS["ratio"]}


def format_table(res: dict[str, Any]) -> str:
    """The readable report printed by ``leafview bench dataset``."""
    lines = [f"leafview dataset benchmark{' (quick)' if res['quick'] else ''}: {res['gl_renderer']} "
             f"({res['gl_version']}), {res['size'][0]}×{res['size'][1]}, {res['leaves']} leaves per image, "
             f"{res['images_per_run']} images per run, {res['rounds']} interleaved round(s)"]
    lines.append(f"{'workers':>7}  {'LP_NUM_THREADS':>14}  {'images/s':>9}  {'wall images/s':>13}")
    for w in (str(x) for x in WORKERS):
        lines.append(f"{w:>7}  {res['threads'][w]:>14}  {res['images_per_s'][w]:>9.2f}  "
                     f"{res['wall_images_per_s'][w]:>13.2f}")
    ok = res["ratio"] >= res["goal"]
    lo, hi = res["ratio_range"]
    lines.append(f"ratio 2 ÷ 1 workers  {res['ratio']:.2f}×  (goal ≥ {res['goal']:g}: {'met' if ok else 'NOT met'}; "
                 f"rounds {lo:.2f}-{hi:.2f})")
    return "\n".join(lines)
