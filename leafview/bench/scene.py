"""``leafview bench scene``: large scenes, measured side by side in one process.

* ms/frame and leaves/s for field scenes of 10³, 10⁴ and 10⁵ leaves (1280×720, ``ground`` and
  ``three-quarter`` cameras, culling and LOD on);
* ``lod_speedup``: frame time with culling and LOD off ÷ on, for the 10⁵-leaf field seen from the
  ``ground`` camera (interleaved pairs, median);
* ``lod_switch_px``: largest outline change in pixels when a leaf switches level;
* ``param_vs_baked_speed`` and ``baked_vs_param_bytes`` from the core suite's instancing
  measurement (:func:`leafview.bench.instancing.instanced_vs_baked`), so both suites report the
  same quantity;
* the 10⁶-leaf field: build, upload and one 1280×720 frame, wall time (not in ``--quick``);
* ``lobed_frame_ratio``: ms/frame of the 10⁴-leaf field (10³ in ``--quick``) with every leaf
  ``maple`` (lobed, drawn from its sweep table on its lobed grids) ÷ the same field with every
  leaf ``ovate``: the same placements, cameras and size, culling and LOD on, the two renderers'
  frames interleaved (median of the per-pair ratios), the worse of the ``ground`` and
  ``three-quarter`` cameras (goal ≤ 2; per camera in ``lobed_views``);
* ``leaf_set_upload_ms_per_leaf``: a leaf set of 10⁴ explicit leaves (10³ in ``--quick``), each
  its own species and shape (the field's leaves, placed, bending off):
  :func:`~leafview.scene.spec.scene_from_leaves` and the :class:`~leafview.gpu.scene.SceneRenderer`
  set-up (its own programs compiled), milliseconds per leaf, median of 3;
  ``leaf_set_bent_ms_per_leaf`` the same for 10³ leaves (10² in ``--quick``) of the bent presets
  (:data:`BENT_SPECIES`), each with a shape of its own, so a cantilever solve per leaf.

Timings are medians with ``ctx.finish()`` before the clock stops; GL_RENDERER is part of the
result. Nothing here is asserted.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import moderngl

from leafview.bench.instancing import bytes_per_leaf, instanced_vs_baked
from leafview.bench.timing import Progress, bench_context, gl_info, interleaved, median_time
from leafview.core.params import Bending, LeafParams
from leafview.gpu.context import check_error
from leafview.gpu.instanced import OffscreenTarget
from leafview.gpu.scene import LOD_GRIDS, CullSettings, SceneRenderer, lod_switch_error
from leafview.resources import resolve_preset
from leafview.scene.camera import scene_camera
from leafview.scene.spec import SceneSpec, build_scene, scene_from_leaves

__all__ = ["run", "format_table", "GOALS", "BENT_SPECIES"]

GOALS = {"lod_speedup": 2.0, "param_vs_baked_speed": 0.9, "baked_vs_param_bytes": 250.0,
         "million_leaf_seconds": 10.0, "leaf_set_upload_ms_per_leaf": 0.05, "lobed_frame_ratio": 2.0}
SIZE = (1280, 720)
SPECIES = ("ovate", "lanceolate", "elliptic")
BENT_SPECIES = ("maize", "willow")   # the presets that bend (cantilever load, twist, petiole)
LOBED_PAIR = ("maple", "ovate")      # lobed_frame_ratio: every leaf the first ÷ every leaf the second


def _spec(n: int, species: tuple[str, ...] = SPECIES) -> SceneSpec:
    return SceneSpec(species=tuple(LeafParams.load(resolve_preset(s)) for s in species), leaves=n, seed=1,
                     layout="field")


def _leaf_set_ms(ctx: moderngl.Context, leaves: list[LeafParams], repeats: int) -> float:
    """Median milliseconds per leaf of :func:`scene_from_leaves` and a :class:`SceneRenderer` of
    ``leaves`` (its own resources: programs compiled, rows uploaded and prepared, culling rows)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        with SceneRenderer(ctx, scene_from_leaves(leaves)):
            ctx.finish()
            times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times) / len(leaves)


def lobed_frame_ratio(ctx: moderngl.Context, target: OffscreenTarget, n: int, pairs: int,
                      views: tuple[str, ...] = ("ground", "three-quarter"),
                      pair: tuple[str, str] = LOBED_PAIR) -> dict[str, Any]:
    """ms/frame of an ``n``-leaf field whose every leaf is ``pair[0]`` and of the same field whose
    every leaf is ``pair[1]`` (same seed, hence the same placements; for each view one camera,
    framed on the second; culling and LOD on), measured in ``pairs`` interleaved pairs of frames.
    A view's ratio is the median of its pairs' ratios; ``lobed_frame_ratio`` is the largest."""
    scenes = [build_scene(_spec(n, (name,))) for name in pair]
    on = CullSettings()
    out: dict[str, Any] = {"lobed_species": list(pair), "lobed_leaves": n, "lobed_views": {}}
    with SceneRenderer(ctx, scenes[0]) as a, SceneRenderer(ctx, scenes[1]) as b:
        out["lobed_grids"] = [list(g) for g in a.command_grids]
        for view in views:
            camera = scene_camera(scenes[1], SIZE, view)
            frames = []
            for r in (a, b):
                r.set_camera(camera, SIZE)

                def frame(r: SceneRenderer = r) -> None:
                    target.use()
                    target.clear()
                    r.draw(on)

                frame()
                ctx.finish()
                frames.append(frame)
            timed = interleaved(frames[1], frames[0], pairs, ctx.finish)   # ratio: lobed ÷ unlobed
            check_error(ctx, "lobed scene frames")
            counts = [r.level_counts() for r in (a, b)]
            out["lobed_views"][view] = {
                "ratio": timed["ratio"], "lobed_ms": timed["other_ms"], "unlobed_ms": timed["base_ms"],
                "lobed_triangles": a.triangles(counts[0]), "unlobed_triangles": b.triangles(counts[1]),
                "lobed_counts": [int(c) for c in counts[0]], "unlobed_counts": [int(c) for c in counts[1]]}
    out["lobed_frame_ratio"] = max(v["ratio"] for v in out["lobed_views"].values())
    return out


def run(quick: bool = False, ctx: moderngl.Context | None = None) -> dict[str, Any]:
    """Run the scene benchmarks on ``ctx`` (default a new headless context); see the module
    docstring for what is measured."""
    leaf_counts = (1_000, 5_000) if quick else (1_000, 10_000, 100_000)
    on, off = CullSettings(), CullSettings(cull=False, lod=False)
    with bench_context(ctx) as ctx, Progress(len(leaf_counts) + 5) as progress:
        res: dict[str, Any] = {**gl_info(ctx), "size": list(SIZE), "quick": quick, "species": list(SPECIES),
                               "frames": {}}
        with OffscreenTarget(ctx, SIZE) as target:
            for n in leaf_counts:
                progress.step(f"{n:,} leaves")
                scene = build_scene(_spec(n))
                with SceneRenderer(ctx, scene) as r:
                    row: dict[str, Any] = {}
                    for view in ("ground", "three-quarter"):
                        r.set_camera(scene_camera(scene, SIZE, view), SIZE)

                        def frame(settings: CullSettings = on) -> None:
                            target.use()
                            target.clear()
                            r.draw(settings)

                        frame()
                        ctx.finish()
                        t = median_time(frame, 3 if quick else 5, ctx.finish)
                        counts = r.level_counts()
                        row[view] = {"ms": 1e3 * t, "leaves_per_s": n / t, "drawn": int(counts.sum()),
                                     "levels": [int(c) for c in counts], "triangles": r.triangles(counts)}
                        if view == "ground" and n == leaf_counts[-1]:
                            # culling and LOD off ÷ on, in pairs (the frame with them on is warm)
                            timed = interleaved(frame, lambda: frame(off), 2 if quick else 3, ctx.finish, warm=False)
                            res["lod_speedup"] = timed["ratio"]
                            res["lod_speedup_leaves"] = n
                            res["lod_off_ms"] = timed["other_ms"]
                        check_error(ctx, f"scene frame ({n} leaves, {view})")
                    res["frames"][str(n)] = row
            progress.step("lobed vs unlobed")
            res.update(lobed_frame_ratio(ctx, target, 1_000 if quick else 10_000, 3 if quick else 7))
            progress.step("leaf sets")
            for key, n_set, bent in (("leaf_set_upload_ms_per_leaf", 1_000 if quick else 10_000, False),
                                     ("leaf_set_bent_ms_per_leaf", 100 if quick else 1_000, True)):
                spec = _spec(n_set, BENT_SPECIES if bent else SPECIES)
                if not bent:   # bent leaves are measured on their own
                    spec = spec.replace(species=tuple(s.replace(bending=Bending()) for s in spec.species))
                leaf_set = build_scene(spec).placed_leaves()
                res[key] = _leaf_set_ms(ctx, leaf_set, 1 if bent else 3)
                res[key.replace("_ms_per_leaf", "_leaves")] = n_set
            progress.step("LOD switch")
            res["lod_switch_px"] = lod_switch_error(ctx, ("ovate", "lanceolate", "serrate", "maize"))
            progress.step("parameters vs baked mesh")
            n_pb = 300 if quick else 10_000
            core = instanced_vs_baked(ctx, n_pb, 2 if quick else 9, progress)
            res.update(param_vs_baked_speed=core["ratio"], param_vs_baked_range=list(core["ratio_range"]),
                       instanced_leaves_per_s=n_pb / core["t_instanced"], baked_leaves_per_s=n_pb / core["t_baked"],
                       scene_leaves=n_pb, triangles_per_leaf=core["triangles_per_leaf"], **bytes_per_leaf())
            if not quick:
                progress.step("10⁶ leaves")
                t0 = time.perf_counter()
                scene = build_scene(_spec(1_000_000))
                t1 = time.perf_counter()
                with SceneRenderer(ctx, scene) as r:
                    t2 = time.perf_counter()
                    r.render(scene_camera(scene, SIZE, "three-quarter"), SIZE)
                    t3 = time.perf_counter()
                    counts = r.level_counts()
                    res["million"] = {"build_s": t1 - t0, "upload_s": t2 - t1, "frame_s": t3 - t2,
                                      "batches": len(r.batches), "drawn": int(counts.sum()),
                                      "triangles": r.triangles(counts)}
                res["million_leaf_seconds"] = t3 - t0
    return res


def format_table(res: dict[str, Any]) -> str:
    """The readable report printed by ``leafview bench scene``."""
    lines = [f"leafview scene benchmark{' (quick)' if res['quick'] else ''}: {res['gl_renderer']} "
             f"({res['gl_version']}), {res['size'][0]}×{res['size'][1]}, species {', '.join(res['species'])}"]
    grids = "/".join(f"{nu}×{nv}" for nu, nv in LOD_GRIDS)
    lines.append(f"{'leaves':>9}  {'camera':<13} {'ms/frame':>9} {'leaves/s':>12} {'drawn':>9}  levels ({grids})")
    for n, row in res["frames"].items():
        for view, r in row.items():
            lines.append(f"{int(n):>9,}  {view:<13} {r['ms']:>9.1f} {r['leaves_per_s']:>12,.0f} {r['drawn']:>9,}  "
                         f"{'/'.join(str(c) for c in r['levels'])}")

    def goal(key: str, at_most: bool = False) -> str:
        ok = res[key] <= GOALS[key] if at_most else res[key] >= GOALS[key]
        return f"goal {'≤' if at_most else '≥'} {GOALS[key]:g}: {'met' if ok else 'NOT met'}"

    lines.append(f"lod_speedup            {res['lod_speedup']:.2f}×  ({goal('lod_speedup')}; "
                 f"{res['lod_speedup_leaves']:,} leaves, ground camera, off {res['lod_off_ms']:.0f} ms)")
    lines.append(f"lod_switch_px          {res['lod_switch_px']:.2f} px (largest outline change at a level switch)")
    if "lobed_frame_ratio" in res:
        views = "; ".join(f"{view} {v['ratio']:.2f}× ({v['lobed_ms']:.0f} vs {v['unlobed_ms']:.0f} ms, "
                          f"{v['lobed_triangles']:,} vs {v['unlobed_triangles']:,} triangles)"
                          for view, v in res["lobed_views"].items())
        lines.append(f"lobed_frame_ratio      {res['lobed_frame_ratio']:.2f}×  ({goal('lobed_frame_ratio', True)}; "
                     f"{res['lobed_leaves']:,} leaves, every one {res['lobed_species'][0]} ÷ every one "
                     f"{res['lobed_species'][1]}, worst camera; {views})")
    lines.append(f"leaf_set_upload_ms_per_leaf {res['leaf_set_upload_ms_per_leaf']:.3f} ms  "
                 f"({goal('leaf_set_upload_ms_per_leaf', True)}; {res['leaf_set_upload_leaves']:,} explicit leaves, "
                 f"a shape each: scene and GPU set-up; bent: {res['leaf_set_bent_ms_per_leaf']:.2f} ms, "
                 f"{res['leaf_set_bent_leaves']:,} leaves of {', '.join(BENT_SPECIES)})")
    lines.append(f"param_vs_baked_speed   {res['param_vs_baked_speed']:.3f}  ({goal('param_vs_baked_speed')}; "
                 f"{res['scene_leaves']:,} leaves of {res['triangles_per_leaf']} triangles)")
    lines.append(f"baked_vs_param_bytes   {res['baked_vs_param_bytes']:.0f}×  ({goal('baked_vs_param_bytes')})")
    if "million" in res:
        m = res["million"]
        lines.append(f"10⁶ leaves offscreen   {res['million_leaf_seconds']:.1f} s  ({goal('million_leaf_seconds', True)}; "
                     f"build {m['build_s']:.1f} s, upload {m['upload_s']:.1f} s in {m['batches']} batches, "
                     f"frame {m['frame_s']:.1f} s, {m['drawn']:,} drawn, {m['triangles']:,} triangles)")
    return "\n".join(lines)
