"""The frame cost of veins on a scene: the same 10⁴-leaf scene, the same view, drawn with its veins
and without them, side by side in one process (goal: at most :data:`GOAL` times the frame without).

One :class:`~leafview.gpu.scene.SceneRenderer` holds the scene with its vein fields (one per
species, :class:`~leafview.gpu.vein_draw.VeinDraw`); a frame without veins is the same renderer
drawing its ``LEAF_NO_VEINS`` program variant (:attr:`SceneRenderer.show_veins` false: no field
read in ``leaf.frag``, no vein grid in ``leaf.vert``), so the two differ in nothing else. Frames
are timed in interleaved pairs (with, without), ``ctx.finish()`` before each clock stops; the
ratio is that of the fastest frames of each kind (``ratio``: the least disturbed by other work
on a shared machine), and the median of the pairs' ratios is reported beside it. On a software
rasteriser (llvmpipe draws in this process's threads) the process's CPU time per frame is
reported too (``cpu_ratio``): other programs sharing the cores do not inflate it. The one-off cost of computing the species' fields is
reported beside it (``field_ms``), as is GL_RENDERER. Nothing here is asserted.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import moderngl

from leafview.bench.timing import bench_context, gl_info, median_time
from leafview.core.params import LeafParams
from leafview.gpu.context import check_error
from leafview.gpu.instanced import OffscreenTarget
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.gpu.vein_draw import VeinDraw
from leafview.resources import resolve_preset
from leafview.scene.camera import scene_camera
from leafview.scene.spec import SceneSpec, build_scene

__all__ = ["GOAL", "SPECIES", "vein_frame_cost", "format_vein_frames"]

GOAL = 1.3
"""Largest frame time with veins ÷ without (issue 17)."""
SPECIES = ("ovate", "lanceolate", "elliptic")
SIZE = (1280, 720)


def vein_frame_cost(ctx: moderngl.Context | None = None, *, leaves: int = 10_000, size: tuple[int, int] = SIZE,
                    views: tuple[str, ...] = ("three-quarter", "ground"), pairs: int = 5,
                    species: tuple[str, ...] = SPECIES) -> dict[str, Any]:
    """Milliseconds per frame (fastest of ``pairs`` interleaved pairs) of a field scene of
    ``leaves`` leaves of ``species`` (their presets' venation) with and without veins, per view,
    and their ratio; ``field_ms``: computing the species' vein fields once (fresh)."""
    spec = SceneSpec(species=tuple(LeafParams.load(resolve_preset(s)) for s in species), leaves=leaves, seed=1,
                     layout="field")
    scene = build_scene(spec)
    veined = sum(p.venation.enabled for p in scene.species)
    with bench_context(ctx) as ctx:
        res: dict[str, Any] = {**gl_info(ctx), "leaves": leaves, "size": list(size), "species": list(species),
                               "veined_species": veined, "goal": GOAL, "views": {}}
        fields = VeinDraw(ctx)
        try:
            t0 = time.perf_counter()
            fields.update(scene.species)
            ctx.finish()
            res["field_ms"] = 1e3 * (time.perf_counter() - t0)
        finally:
            fields.release()
        with OffscreenTarget(ctx, size) as target, SceneRenderer(ctx, scene) as r:
            for view in views:
                r.set_camera(scene_camera(scene, size, view), size)

                def frame(veins: bool) -> None:
                    r.show_veins = veins
                    target.use()
                    target.clear()
                    r.draw(CullSettings())

                def cpu(veins: bool) -> float:
                    t0 = time.process_time()
                    frame(veins)
                    ctx.finish()
                    return time.process_time() - t0

                for veins in (True, False):   # compile both variants, warm the caches
                    frame(veins)
                    ctx.finish()
                on, off, ratios, cpu_on, cpu_off = [], [], [], [], []
                for _ in range(pairs):
                    a = median_time(lambda: frame(True), 1, ctx.finish)
                    b = median_time(lambda: frame(False), 1, ctx.finish)
                    on.append(a)
                    off.append(b)
                    ratios.append(a / b)
                    cpu_on.append(cpu(True))
                    cpu_off.append(cpu(False))
                check_error(ctx, f"vein frames ({view})")
                res["views"][view] = {"veins_ms": 1e3 * min(on), "no_veins_ms": 1e3 * min(off),
                                      "ratio": min(on) / min(off), "ratio_median": statistics.median(ratios),
                                      "cpu_veins_ms": 1e3 * min(cpu_on), "cpu_no_veins_ms": 1e3 * min(cpu_off),
                                      "cpu_ratio": min(cpu_on) / max(min(cpu_off), 1e-9),
                                      "drawn": int(r.level_counts().sum())}
        res["ratio"] = max(v["ratio"] for v in res["views"].values())
    return res


def format_vein_frames(res: dict[str, Any]) -> str:
    """A few lines for the terminal."""
    lines = [f"veins on a {res['leaves']:,}-leaf scene ({res['veined_species']} veined species), "
             f"{res['size'][0]}×{res['size'][1]} [{res['gl_renderer']}]",
             f"  fields of the species: {res['field_ms']:.1f} ms (once)"]
    for view, v in res["views"].items():
        lines.append(f"  {view:>14}: {v['veins_ms']:.1f} ms with veins, {v['no_veins_ms']:.1f} ms without: "
                     f"{v['ratio']:.2f}× (median of pairs {v['ratio_median']:.2f}×, CPU time {v['cpu_ratio']:.2f}×; "
                     f"goal ≤ {res['goal']}×)")
    return "\n".join(lines)
