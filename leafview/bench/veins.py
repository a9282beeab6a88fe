"""``leafview bench veins``: the vein field of a new species (issue 17: at most 5 ms on llvmpipe),
on the GPU (:class:`leafview.gpu.vein_field.VeinFields`, ``shaders/vein_field.comp``) beside its
numpy twin (:func:`leafview.botany.vein_field.vein_field`).

For each built-in preset with veins (4 of them with ``--quick``), ``repeats`` new species (the
preset with another venation seed, so a new key each time): the vein tree
(:func:`~leafview.botany.venation.vein_segments`) and the vein-shape grid
(:func:`~leafview.botany.vein_shape.vein_grid`) are computed first and timed on their own, then
``VeinFields.update`` with that one new leaf is the field time: half-width table, segment records,
tile boxes, upload, the three compute stages, the copy into the array layer (and the grid's
upload), ``ctx.finish()`` before the clock stops. Medians; the process's CPU time over the same
span (``field_cpu_ms``: llvmpipe runs in this process, so on a busy machine it moves less than
the wall time). The numpy twin takes the same leaf's segments. ``scene_ms_per_species``: every
preset's field at once (one :meth:`~leafview.gpu.vein_field.VeinFields.build`, one dispatch of up
to 16 fields), per species. ``frames``: the frame cost of veins on a 10⁴-leaf scene, with against
without (goal ≤ 1.3×; :func:`leafview.bench.vein_frames.vein_frame_cost`; 1,000 leaves at 320×180
with ``--quick``). Nothing is asserted.
"""

from __future__ import annotations

import dataclasses
import os
import statistics
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import moderngl

from leafview.bench.timing import Progress, bench_context, gl_info, log_gl_renderer
from leafview.bench.vein_frames import format_vein_frames, vein_frame_cost
from leafview.botany.vein_field import (
    FIELD_CAP,
    FIELD_SIZE,
    field_from_segments,
    halfwidth_table,
    segment_records,
    tile_geometry,
    tile_lists,
)
from leafview.botany.vein_shape import vein_grid
from leafview.botany.venation import vein_segments
from leafview.core.params import LeafParams
from leafview.gpu.programs import ProgramCache
from leafview.gpu.vein_field import VeinFields
from leafview.resources import builtin_presets

__all__ = ["GOAL_MS", "run", "format_table"]

GOAL_MS = 5.0
"""Issue 17: the vein-field compute for a new species takes at most this on llvmpipe."""
QUICK_PRESETS = ("ovate", "maize", "orbicular", "willow")


def _presets(quick: bool) -> list[tuple[str, LeafParams]]:
    out = []
    for name, path in builtin_presets().items():
        p = LeafParams.load(path)
        if p.venation.enabled and (not quick or name in QUICK_PRESETS):
            out.append((name, p))
    return out


def _timed(fn: Callable[[], Any], finish: Callable[[], None] | None = None) -> tuple[float, float]:
    """(wall, process CPU) seconds of one call."""
    t0, c0 = time.perf_counter(), time.process_time()
    fn()
    if finish is not None:
        finish()
    return time.perf_counter() - t0, time.process_time() - c0


def _species(ctx: moderngl.Context, fields: VeinFields, name: str, p: LeafParams, repeats: int,
             twin_repeats: int) -> dict[str, Any]:
    tree, grid, wall, cpu = [], [], [], []
    for k in range(repeats):
        new = p.replace(venation=dataclasses.replace(p.venation, seed=p.venation.seed + 1000 + k))
        tree.append(_timed(partial(vein_segments, new))[0])
        grid.append(_timed(partial(vein_grid, new))[0])
        w, c = _timed(partial(fields.update, [new]), ctx.finish)
        wall.append(w)
        cpu.append(c)
    seg = vein_segments(p)
    table = halfwidth_table(p)
    twin = [_timed(lambda: field_from_segments(seg.uv0, seg.uv1, seg.order, seg.width, table, fields.size))[0]
            for _ in range(twin_repeats)]
    lists = tile_lists(segment_records(seg.uv0, seg.uv1, seg.order, seg.width, table),
                       tile_geometry(table, fields.size))
    field_ms = 1e3 * statistics.median(wall)
    twin_ms = 1e3 * statistics.median(twin)
    return {"name": name, "pattern": p.venation.pattern, "segments": len(seg.order),
            "list_mean": float(lists.counts.mean()), "list_max": int(lists.counts.max()),
            "tree_ms": 1e3 * statistics.median(tree), "grid_ms": 1e3 * statistics.median(grid),
            "field_ms": field_ms, "field_min_ms": 1e3 * min(wall), "field_cpu_ms": 1e3 * statistics.median(cpu),
            "twin_ms": twin_ms, "twin_vs_gpu": twin_ms / field_ms, "vs_goal": field_ms / GOAL_MS}


def run(quick: bool = False, ctx: moderngl.Context | None = None) -> dict[str, Any]:
    """Measure (see the module docstring); ``quick``: 4 presets, 3 new species each."""
    presets = _presets(quick)
    repeats, twin_repeats = (3, 1) if quick else (9, 3)
    with bench_context(ctx) as c, Progress(len(presets) + 2) as progress:
        info = gl_info(c)
        log_gl_renderer("veins", info["gl_renderer"])
        programs = ProgramCache(c)
        try:
            with VeinFields(c, programs=programs) as fields:
                fields.update([p for _, p in presets[:1]])          # compile and warm up
                rows = []
                for name, p in presets:
                    progress.step(f"{name}: {repeats} new species")
                    rows.append(_species(c, fields, name, p, repeats, twin_repeats))
            progress.step(f"all {len(presets)} presets at once")
            for _, p in presets:                                     # trees and grids first
                vein_segments(p)
                vein_grid(p)
            leaves = [p for _, p in presets]
            scene = []
            for _ in range(max(1, repeats // 3)):
                def build() -> None:
                    VeinFields.build(c, leaves, programs=programs).release()
                scene.append(_timed(build, c.finish)[0])
        finally:
            programs.release()
        progress.step("frame cost on a scene, veins on and off")
        frames = (vein_frame_cost(c, leaves=1_000, size=(320, 180), pairs=1) if quick
                  else vein_frame_cost(c))
    field = [r["field_ms"] for r in rows]
    return {**info, "quick": quick, "goal_ms": GOAL_MS, "size": FIELD_SIZE, "cap": FIELD_CAP,
            "cpus": os.cpu_count(), "load_average": list(os.getloadavg()), "repeats": repeats, "species": rows,
            "field_ms_median": statistics.median(field), "field_ms_max": max(field),
            "field_cpu_ms_median": statistics.median(r["field_cpu_ms"] for r in rows),
            "twin_ms_median": statistics.median(r["twin_ms"] for r in rows),
            "presets_within_goal": sum(f <= GOAL_MS for f in field),
            "scene_species": len(leaves), "scene_ms_per_species": 1e3 * statistics.median(scene) / len(leaves),
            "bytes_per_layer": int(FIELD_SIZE * FIELD_SIZE * 16), "frames": frames}


def format_table(res: dict[str, Any]) -> str:
    """The readable report printed by ``leafview bench veins``."""
    head = (f"leafview veins benchmark{' (quick)' if res['quick'] else ''}: {res['gl_renderer']} "
            f"({res['cpus']} CPUs, load {res['load_average'][0]:.1f}); field {res['size']}² RGBA32F "
            f"({res['bytes_per_layer'] / 2**20:.0f} MiB a layer), cap {res['cap']:g}; medians of {res['repeats']} "
            f"new species each")
    lines = [head, f"  {'preset':<13}{'pattern':<9}{'segments':>9}{'list':>11}{'tree':>8}{'grid':>8}"
                   f"{'field':>8}{'cpu':>7}{'numpy':>9}{'numpy/GPU':>10}{'vs 5 ms':>9}"]
    for r in res["species"]:
        lines.append(f"  {r['name']:<13}{r['pattern']:<9}{r['segments']:>9}{r['list_mean']:>6.1f}/{r['list_max']:<4}"
                     f"{r['tree_ms']:>8.1f}{r['grid_ms']:>8.1f}{r['field_ms']:>8.2f}{r['field_cpu_ms']:>7.2f}"
                     f"{r['twin_ms']:>9.1f}{r['twin_vs_gpu']:>9.0f}×{r['vs_goal']:>8.2f}×")
    lines += ["  (ms; list: segments a tile tests, mean/max; tree and grid: vein_segments and vein_grid, before "
              "the field and not part of it)",
              f"  field for a new species, median over presets  {res['field_ms_median']:.2f} ms (CPU "
              f"{res['field_cpu_ms_median']:.2f} ms; worst preset {res['field_ms_max']:.2f} ms); goal ≤ "
              f"{res['goal_ms']:g} ms: {res['presets_within_goal']} of {len(res['species'])} presets within it",
              f"  numpy twin, median                           {res['twin_ms_median']:.0f} ms",
              f"  all {res['scene_species']} presets in one build             {res['scene_ms_per_species']:.2f} ms "
              f"a species", format_vein_frames(res["frames"])]
    return "\n".join(lines)
