"""``leafview bench``: throughput of the GPU paths, measured side by side in one process.

Benchmarks are not tests: nothing here asserts a timing. Every timing is the median of several
repeats, with ``ctx.finish()`` before the clock stops; the GL renderer (``GL_RENDERER``) is part
of the result because numbers from llvmpipe (software) and a real GPU are not comparable.

Measured (see :func:`run` for the keys):

* 128×128 three-quarter thumbnails (grid 32×64, readback included) with :class:`LeafRenderer`,
  against matplotlib ``plot_trisurf`` (Agg) of the same tessellated mesh at 128×128 px;
* 10⁴ scattered leaves (grid 9×15 = 224 triangles each) into a 512×512 framebuffer with depth
  test: the parametric path (:class:`~leafview.gpu.instanced.InstancedLeaves`, one instanced
  draw from a 288-byte record per leaf) against the same triangles pre-baked
  (:class:`~leafview.gpu.instanced.BakedLeaves`, one indexed draw);
* bytes per leaf of a baked 32×64 mesh against the parameter record.

Run: ``leafview bench [--json] [--quick]`` or ``python bench/run_bench.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from leafview._version import __version__
from leafview.bench.latency import measure_edit_latency
from leafview.core.params import Bending, Jitter, LeafParams, Shape
from leafview.deform.fbm import RIPPLE_SAMPLES
from leafview.deform.surface import evaluate, grid_uv, tessellate
from leafview.gpu.context import GLUnavailable, check_error, create_headless_context
from leafview.gpu.instanced import BakedLeaves, InstancedLeaves, OffscreenTarget, pack_leaves, read_rgba, scatter_leaves
from leafview.gpu.layout import LEAF_BLOCK
from leafview.gpu.renderer import LeafRenderer
from leafview.gpu.ripple import RipplePass
from leafview.resources import builtin_presets
from leafview.scene.camera import frame_view

__all__ = ["run", "main", "GOALS", "PAPER_LEAVES_PER_S"]

PAPER_LEAVES_PER_S = 550.0  # Garg & Leow 2011: ~550 leaf instances/s on a quad-core laptop
THUMB_SIZE = (128, 128)
THUMB_GRID = (32, 64)
SCENE_GRID = (9, 15)        # 2·8·14 = 224 triangles per leaf
SCENE_SIZE = (512, 512)
BYTES_GRID = (32, 64)

# goals (reported, never asserted): key -> minimum
GOALS = {
    "thumbnail_speedup": 20.0,
    "param_vs_baked_speed": 0.9,
    "baked_vs_param_bytes": 250.0,
    "ripple_overhead": 1.3,  # at most: lower is better
    "edit_latency_ratio": 1.2,  # at most: viewer frame carrying an edit ÷ steady frame
    "vs_paper_550": 20.0,
}

_CONFIG = {
    # thumbnail params, passes over them per repeat, repeats, matplotlib repeats, scene leaves, repeats
    False: dict(thumb_params=4, thumb_passes=16, thumb_repeats=5, mpl_passes=2, mpl_repeats=5,
                leaves=10_000, scene_repeats=15),
    True: dict(thumb_params=2, thumb_passes=1, thumb_repeats=2, mpl_passes=1, mpl_repeats=2,
               leaves=300, scene_repeats=2),
}


class _Progress:
    """Step names on stderr, only when stderr is a terminal."""

    def __init__(self, total: int) -> None:
        self.enabled = sys.stderr.isatty()
        self.total, self.done = total, 0

    def step(self, what: str) -> None:
        self.done += 1
        if self.enabled:
            sys.stderr.write(f"\r\033[K[{self.done}/{self.total}] {what}")
            sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\r\033[K")
            sys.stderr.flush()


def _median_time(fn: Callable[[], Any], repeats: int, finish: Callable[[], None] | None = None) -> float:
    """Median wall time of ``fn`` over ``repeats`` runs (``finish`` before the clock stops)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        if finish is not None:
            finish()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bytes_per_leaf() -> dict[str, Any]:
    """Bytes of a baked BYTES_GRID leaf mesh (f32 position, normal, uv; u32 indices) against the
    leaf record: its host-set parameter fields, and the whole record with derived data."""

    nu, nv = BYTES_GRID
    verts, tri_count = nu * nv, 2 * (nu - 1) * (nv - 1)
    baked = verts * (3 + 3 + 2) * 4 + tri_count * 3 * 4
    return {"baked_bytes_per_leaf": baked, "param_bytes_per_leaf": LEAF_BLOCK.parameter_nbytes,
            "record_bytes_per_leaf": LEAF_BLOCK.nbytes,
            "baked_vs_param_bytes": baked / LEAF_BLOCK.parameter_nbytes,
            "baked_vs_record_bytes": baked / LEAF_BLOCK.nbytes}


def thumbnail_params(k: int) -> list[Any]:
    """``k`` distinct single leaves at the origin: plain, serrated, cupped, curved axis, …"""

    variants = [
        LeafParams(name="ovate"),
        LeafParams(shape=Shape(silhouette=((0.2, 0.25, 0.0), (0.5, 0.3, 0.02), (0.8, 0.15, 0.0))),
                   jitter=Jitter(enabled=True, amplitude=0.02, density=36.0, seed=3), name="serrated"),
        LeafParams(shape=Shape(zf=(0.03, 0.05, 0.03), zg=(0.06, 0.09, 0.05)), name="cupped"),
        LeafParams(shape=Shape(a1=(0.08, 0.33, 0.05), a2=(0.12, 0.66, 0.1),
                               silhouette=((0.3, 0.45, 0.0), (0.55, 0.4, 0.0), (0.8, 0.2, 0.0))),
                   name="curved"),
    ]
    return [variants[i % len(variants)] for i in range(k)]


def _mpl_thumbnail(params: Any) -> np.ndarray:
    """matplotlib baseline: plot_trisurf of tessellate(params, 32, 64), 128×128 px RGBA."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure


    mesh = tessellate(params, *THUMB_GRID)
    m = params.transform.matrix()
    p = mesh.vertices @ m[:3, :3].T + m[:3, 3]
    fig = Figure(figsize=(THUMB_SIZE[0] / 100, THUMB_SIZE[1] / 100), dpi=100)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0), projection="3d")
    front = np.asarray(params.material.front)
    srgb = np.where(front <= 0.0031308, 12.92 * front, 1.055 * front ** (1 / 2.4) - 0.055)
    ax.plot_trisurf(p[:, 0], p[:, 1], p[:, 2], triangles=mesh.indices, color=tuple(srgb),
                    linewidth=0, antialiased=False, shade=True)
    lo, hi = p.min(axis=0), p.max(axis=0)
    c, r = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 1e-6)  # equal axes, like the GL camera
    ax.set_xlim(c[0] - r, c[0] + r), ax.set_ylim(c[1] - r, c[1] + r), ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_box_aspect((1, 1, 1), zoom=1.6)  # mplot3d leaves wide margins by default
    ax.view_init(elev=35, azim=-55)  # the three-quarter view: 35° towards +x from -y, 35° up
    ax.set_axis_off()
    canvas.draw()
    img = np.asarray(canvas.buffer_rgba()).copy()
    fig.clear()
    return img


def _scene(ctx: Any, n_leaves: int, repeats: int, progress: _Progress) -> dict[str, Any]:
    """Median seconds per frame of ``n_leaves`` scattered leaves, instanced vs baked."""

    params = scatter_leaves(n_leaves, seed=1)
    records, tables = pack_leaves(params)
    with OffscreenTarget(ctx, SCENE_SIZE) as target:
        fbo = target.fbo
        fbo.use()
        with InstancedLeaves(ctx, records, SCENE_GRID, jitter_tables=tables) as inst:
            # bake by capturing the instanced vertex shader: bit-identical vertices, and seconds
            # faster than 10⁴ numpy tessellations (the tests compare both bakes)
            pos, nrm = inst.capture()
            camera = frame_view("three-quarter", pos.reshape(-1, 3), SCENE_SIZE)
            with BakedLeaves(ctx, pos, nrm, SCENE_GRID, records["front"],
                             records["back"][:, :3]) as baked:
                del pos, nrm
                check_error(ctx, "scene setup")
                images = []
                for batch in (inst, baked):  # warm-up: JIT-compiles the shader variants
                    batch.set_camera(camera)
                    fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
                    batch.draw()
                    check_error(ctx, f"{type(batch).__name__}.draw")
                    images.append(read_rgba(fbo))

                def frame(batch: Any) -> Callable[[], None]:
                    def go() -> None:
                        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
                        batch.draw()
                    return go

                progress.step("instanced vs baked leaves")
                t_inst, t_baked = [], []
                for _ in range(repeats):  # interleaved, so drift hits both alike
                    t_inst.append(_median_time(frame(inst), 1, ctx.finish))
                    t_baked.append(_median_time(frame(baked), 1, ctx.finish))
                check_error(ctx, "scene draws")
                tris = inst.triangles_per_leaf
    a, b = (im.astype(np.int16) for im in images)
    ratios = sorted(b / a for a, b in zip(t_inst, t_baked))  # per interleaved pair
    return {"t_instanced": statistics.median(t_inst), "t_baked": statistics.median(t_baked),
            "ratio": statistics.median(ratios), "ratio_range": (ratios[0], ratios[-1]),
            "mean_abs_diff": float(np.abs(a - b).mean()),
            "coverage": float((images[0][..., 3] > 0).mean()), "triangles_per_leaf": tris}


def run(quick: bool = False, ctx: Any = None) -> dict[str, Any]:
    """Run every benchmark in this process; returns a flat dict (see the module docstring).

    ``ctx``: an existing moderngl context to measure on (kept open); default a new headless
    one, released at the end. Pass the context already in use when the process has one:
    creating a second standalone context makes it current behind the first one's back.

    Keys: ``gl_renderer``, ``thumbnails_per_s``, ``matplotlib_thumbnails_per_s``,
    ``thumbnail_speedup``, ``param_vs_baked_speed`` (+ ``instanced_leaves_per_s``,
    ``baked_leaves_per_s``, ``param_vs_baked_mean_abs_diff``), ``baked_vs_param_bytes`` (+
    ``baked_bytes_per_leaf``, ``param_bytes_per_leaf``), ``leaves_per_s_220tri``,
    ``vs_paper_550``, ``edit_latency_ratio`` (+ ``viewer_frame_ms``, ``viewer_edit_frame_ms``,
    ``viewer_edit_upload_bytes``; see :mod:`leafview.bench.latency`), and the configuration:
    counts, grids, versions, ``cpu_count``.
    """
    import matplotlib
    import moderngl


    cfg = _CONFIG[bool(quick)]
    progress = _Progress(7)
    res: dict[str, Any] = {}
    own_ctx = ctx is None
    if own_ctx:
        ctx = create_headless_context()
    try:
        res["gl_renderer"] = str(ctx.info["GL_RENDERER"])
        res["gl_version"] = str(ctx.info["GL_VERSION"])

        # -- thumbnails: LeafRenderer vs matplotlib, same params, same mesh --------------------
        thumbs = thumbnail_params(cfg["thumb_params"])
        n_gl = cfg["thumb_passes"] * len(thumbs)
        batch = thumbs * cfg["thumb_passes"]
        with LeafRenderer(ctx) as renderer:
            progress.step("GL thumbnails (warm-up)")
            for view in ("top", "three-quarter"):  # compile shader variants, allocate targets
                renderer.render_many(batch, THUMB_SIZE, view, grid=THUMB_GRID)
            check_error(ctx, "thumbnail warm-up")

            def batched(view: str) -> Callable[[], None]:
                return lambda: renderer.render_many(batch, THUMB_SIZE, view, grid=THUMB_GRID)

            def single() -> None:
                for p in batch:
                    renderer.render(p, THUMB_SIZE, "top", grid=THUMB_GRID)

            progress.step("GL thumbnails")
            t_gl = _median_time(batched("top"), cfg["thumb_repeats"], ctx.finish)
            t_single = _median_time(single, cfg["thumb_repeats"], ctx.finish)
            t_3q = _median_time(batched("three-quarter"), cfg["thumb_repeats"], ctx.finish)
            check_error(ctx, "thumbnails")
        res["thumbnails_per_s_single"] = n_gl / t_single
        res["thumbnails_per_s_three_quarter"] = n_gl / t_3q
        res["thumbnails_per_s"] = n_gl / t_gl

        progress.step("matplotlib thumbnails")
        _mpl_thumbnail(thumbs[0])  # import 3D machinery, fonts, caches

        def mpl_pass() -> None:
            for _ in range(cfg["mpl_passes"]):
                for p in thumbs:
                    _mpl_thumbnail(p)

        n_mpl = cfg["mpl_passes"] * len(thumbs)
        t_mpl = _median_time(mpl_pass, cfg["mpl_repeats"])
        res["matplotlib_thumbnails_per_s"] = n_mpl / t_mpl
        res["thumbnail_speedup"] = res["thumbnails_per_s"] / res["matplotlib_thumbnails_per_s"]

        # -- many leaves: parameters (instanced) vs baked meshes, identical triangles ----------
        progress.step(f"scene setup ({cfg['leaves']} leaves)")
        n_leaves = cfg["leaves"]
        scene = _scene(ctx, n_leaves, cfg["scene_repeats"], progress)
        res["instanced_leaves_per_s"] = n_leaves / scene["t_instanced"]
        res["baked_leaves_per_s"] = n_leaves / scene["t_baked"]
        # median over interleaved pairs of (baked time / instanced time): drift cancels per pair
        res["param_vs_baked_speed"] = scene["ratio"]
        res["param_vs_baked_range"] = list(scene["ratio_range"])
        res["param_vs_baked_mean_abs_diff"] = scene["mean_abs_diff"]
        res["scene_coverage"] = scene["coverage"]
        tris = scene["triangles_per_leaf"]

        # -- bytes per leaf ---------------------------------------------------------------------
        progress.step("bytes per leaf")
        res.update(bytes_per_leaf())

        # -- ripples: frame time with ÷ without, and the cost of re-running the fBm pass --------
        progress.step("ripples")
        res.update(_ripples(ctx, cfg["scene_repeats"]))

        # -- the viewer: a frame that carries an edit ÷ a steady frame (leafview.bench.latency) ----
        progress.step("viewer edit latency")

        res.update(measure_edit_latency(ctx, pairs=5 if quick else 30, warmup=2 if quick else 5))

        # -- against the paper: the instanced path at ~220 triangles per leaf (same run) --------
        res["leaves_per_s_220tri"] = res["instanced_leaves_per_s"]
        res["triangles_per_leaf"] = tris
        res["vs_paper_550"] = res["leaves_per_s_220tri"] / PAPER_LEAVES_PER_S
    finally:
        progress.close()
        if own_ctx:
            ctx.release()

    res.update({
        "quick": bool(quick),
        "thumbnail_size": list(THUMB_SIZE),
        "thumbnail_grid": list(THUMB_GRID),
        "thumbnail_count": n_gl,
        "matplotlib_thumbnail_count": n_mpl,
        "scene_leaves": n_leaves,
        "scene_grid": list(SCENE_GRID),
        "scene_size": list(SCENE_SIZE),
        "bytes_grid": list(BYTES_GRID),
        "cpu_count": os.cpu_count() or 0,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "moderngl": moderngl.__version__,
        "matplotlib": matplotlib.__version__,
        "leafview": __version__,
        "platform": platform.platform(),
    })
    return res


_AT_MOST = {"ripple_overhead", "edit_latency_ratio"}


def _goal(key: str, res: dict[str, Any]) -> str:
    if key not in GOALS:
        return ""
    if key in _AT_MOST:
        return f"goal ≤ {GOALS[key]:g}: {'met' if res[key] <= GOALS[key] else 'NOT met'}"
    ok = res[key] >= GOALS[key]
    return f"goal ≥ {GOALS[key]:g}: {'met' if ok else 'NOT met'}"


RIPPLE_GRID = (65, 257)
RIPPLE_SIZE = (512, 512)


def _ripples(ctx: Any, repeats: int) -> dict[str, Any]:
    """Frame time of one rippled leaf ÷ the same leaf and grid without ripples (interleaved
    pairs), and the time to re-synthesise ripple signals after a β or seed change."""
    from dataclasses import replace


    on = LeafParams.load(builtin_presets()["maize"]).replace(bending=Bending())
    off = on.replace(ripple=replace(on.ripple, enabled=False))
    with LeafRenderer(ctx) as renderer, OffscreenTarget(ctx, RIPPLE_SIZE) as target:
        uv = grid_uv(*RIPPLE_GRID)
        renderer.set_camera(frame_view("three-quarter", evaluate(on, uv[:, 0], uv[:, 1]), RIPPLE_SIZE), srgb=True)

        def frame(params: Any) -> Callable[[], None]:
            def go() -> None:
                renderer.set_leaf(params)
                target.use()
                target.clear()
                renderer.draw(RIPPLE_GRID)
            return go

        for p in (on, off):  # warm-up
            frame(p)()
            ctx.finish()
        ratios = []
        for _ in range(max(repeats, 3)):
            t_on = _median_time(frame(on), 3, ctx.finish)
            t_off = _median_time(frame(off), 3, ctx.finish)
            ratios.append(t_on / t_off)
        check_error(ctx, "ripple frames")
    rp = RipplePass(ctx)
    try:
        rp.update([(0, 1.0)])
        ctx.finish()
        seeds = iter(range(1, 10**6))
        t_one = _median_time(lambda: rp.update([(next(seeds), 1.0)]), 9, ctx.finish)
        t_many = _median_time(lambda: rp.update([(next(seeds), 1.0 + (i % 7) * 0.25) for i in range(1000)]),
                              3, ctx.finish)
    finally:
        rp.release()
    return {"ripple_overhead": statistics.median(ratios), "ripple_grid": list(RIPPLE_GRID),
            "ripple_size": list(RIPPLE_SIZE), "ripple_pass_ms": 1e3 * t_one, "ripple_pass_ms_1000": 1e3 * t_many,
            "ripple_samples": RIPPLE_SAMPLES}



def format_table(res: dict[str, Any]) -> str:
    """The readable report printed by ``leafview bench``."""
    def num(x: float) -> str:
        return f"{x:,.1f}" if abs(x) >= 100 else f"{x:.3g}" if x < 10 else f"{x:.1f}"

    tg, sg = res["thumbnail_grid"], res["scene_grid"]
    rows: list[tuple[str, str, str]] = [
        ("GL renderer", res["gl_renderer"], res["gl_version"]),
        ("thumbnails/s (GL)", num(res["thumbnails_per_s"]),
         f"{res['thumbnail_size'][0]}×{res['thumbnail_size'][1]}, top view, grid {tg[0]}×{tg[1]}, "
         f"render_many of {res['thumbnail_count']} (as leafview render DIR)"),
        ("  one render() call each", num(res["thumbnails_per_s_single"]), "top view, same leaves"),
        ("  three-quarter, 4× MSAA", num(res["thumbnails_per_s_three_quarter"]), "render_many, same leaves"),
        ("thumbnails/s (matplotlib)", num(res["matplotlib_thumbnails_per_s"]),
         f"plot_trisurf, Agg, same mesh, {res['matplotlib_thumbnail_count']} per repeat"),
        ("thumbnail speedup", f"{num(res['thumbnail_speedup'])}×", _goal("thumbnail_speedup", res)),
        ("leaves/s instanced (params)", num(res["instanced_leaves_per_s"]),
         f"{res['scene_leaves']} leaves, {res['triangles_per_leaf']} tris each, "
         f"{res['scene_size'][0]}×{res['scene_size'][1]}, one draw"),
        ("leaves/s baked mesh", num(res["baked_leaves_per_s"]), "same triangles, one indexed draw"),
        ("param / baked speed", f"{res['param_vs_baked_speed']:.3f}",
         f"{_goal('param_vs_baked_speed', res)} (pairs {res['param_vs_baked_range'][0]:.2f}"
         f"-{res['param_vs_baked_range'][1]:.2f})"),
        ("param vs baked image diff", f"{res['param_vs_baked_mean_abs_diff']:.4f}",
         f"mean |Δ| of 8-bit RGBA, coverage {100 * res['scene_coverage']:.0f} %"),
        ("bytes/leaf baked", f"{res['baked_bytes_per_leaf']:,}",
         f"grid {res['bytes_grid'][0]}×{res['bytes_grid'][1]}: f32 pos+normal+uv, u32 indices"),
        ("bytes/leaf params", f"{res['param_bytes_per_leaf']:,}",
         f"host-set fields of the {res['record_bytes_per_leaf']}-byte leaf record"),
        ("baked / param bytes", f"{num(res['baked_vs_param_bytes'])}×",
         f"{_goal('baked_vs_param_bytes', res)} (÷ whole record: {num(res['baked_vs_record_bytes'])}×)"),
        ("ripple overhead", f"{res['ripple_overhead']:.3f}",
         f"{_goal('ripple_overhead', res)}; maize, grid {res['ripple_grid'][0]}×{res['ripple_grid'][1]}, "
         f"{res['ripple_size'][0]}², with ÷ without"),
        ("ripple pass re-run", f"{res['ripple_pass_ms']:.2f} ms",
         f"one signal of {res['ripple_samples']} samples; 1000 signals in one dispatch: "
         f"{res['ripple_pass_ms_1000']:.1f} ms"),
        ("edit latency ratio", f"{res['edit_latency_ratio']:.3f}",
         f"{_goal('edit_latency_ratio', res)}; viewer {res['viewer_size'][0]}×{res['viewer_size'][1]}: "
         f"edit → read-back frame {res['viewer_edit_frame_ms']:.1f} ms ÷ steady {res['viewer_frame_ms']:.1f} ms, "
         f"{res['viewer_edit_upload_bytes']} B uploaded"),
        (f"leaves/s at {res['triangles_per_leaf']} tris", num(res["leaves_per_s_220tri"]),
         f"instanced path, grid {sg[0]}×{sg[1]}"),
        ("vs paper (550 leaves/s)", f"{num(res['vs_paper_550'])}×", _goal("vs_paper_550", res)),
        ("machine", f"{res['cpu_count']} CPUs",
         f"Python {res['python']}, numpy {res['numpy']}, moderngl {res['moderngl']}, "
         f"matplotlib {res['matplotlib']}"),
    ]
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows[1:])
    lines = [f"leafview {res['leafview']} benchmark{' (quick)' if res['quick'] else ''}"]
    for i, (name, value, note) in enumerate(rows):
        if i == 0:
            lines.append(f"{name:<{w0}}  {value}  ({note})")
        else:
            lines.append(f"{name:<{w0}}  {value:>{w1}}  {note}".rstrip())
    lines.append("(timings: median of repeats, ctx.finish() before the clock stops; param/baked: median "
                 "of interleaved pairs; goals are reported, never asserted)")
    return "\n".join(lines)


# Benchmark suites: name -> (module, run function, table function). ``run(quick, ctx)`` returns a
# JSON-able dict with ``gl_renderer``; ``table(res)`` the readable report. "core" is this module.
SUITES: dict[str, tuple[str, str, str]] = {
    "core": ("leafview.bench.core", "run", "format_table"),
    "export": ("leafview.bench.export", "run", "format_table"),
    "scene": ("leafview.bench.scene", "run", "format_table"),
    "shapes": ("leafview.bench.shapes", "run", "format_table"),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``leafview bench`` (shared by the CLI and ``bench/run_bench.py``)."""
    parser.add_argument("suite", nargs="?", default="core", choices=[*SUITES, "all"],
                        help="which benchmarks (default core: thumbnails, instancing, ripples, viewer)")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.add_argument("--quick", action="store_true", help="small counts: a smoke run, not a measurement")


def run_args(args: argparse.Namespace) -> int:
    """Run the suite(s) named in ``args``; exit code 2 when GL or a baseline is missing."""
    import importlib


    names = list(SUITES) if args.suite == "all" else [args.suite]
    if "core" in names:
        try:
            import matplotlib  # noqa: F401  (the thumbnail baseline)
        except ImportError:
            print("leafview bench: matplotlib is needed for the baseline: pip install 'leafview[bench]'",
                  file=sys.stderr)
            return 2
    results: dict[str, Any] = {}
    try:
        for name in names:
            module, run_name, table_name = SUITES[name]
            mod = importlib.import_module(module)
            res = getattr(mod, run_name)(quick=args.quick)
            results[name] = res
            if not args.json:
                print(getattr(mod, table_name)(res), flush=True)
    except GLUnavailable as exc:
        print(f"leafview bench: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(results[names[0]] if len(names) == 1 else results, indent=2, allow_nan=False))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="leafview bench", description=__doc__.split("\n\n")[0])
    add_arguments(parser)
    return run_args(parser.parse_args(list(sys.argv[1:] if argv is None else argv)))


if __name__ == "__main__":
    raise SystemExit(main())
