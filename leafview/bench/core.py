"""``leafview bench``: throughput of the GPU paths, measured side by side in one process.

Benchmarks are not tests: nothing here asserts a timing. Every timing is the median of several
repeats, with ``ctx.finish()`` before the clock stops; the GL renderer (``GL_RENDERER``) is part
of the result because numbers from llvmpipe (software) and a real GPU are not comparable.

Measured (see :func:`run` for the keys):

* 128×128 thumbnails (grid 32×64, readback included) with :class:`LeafRenderer`, top view (as
  ``leafview render DIR``) and, like for like against matplotlib, the three-quarter view:
  ``plot_trisurf`` (Agg) of the same tessellated mesh seen through leafview's own camera (same
  view, framing and size), one call per leaf and batched, antialiased and not (see
  :func:`thumbnail_mesh`, :func:`mpl_thumbnail`);
* 10⁴ scattered leaves (grid 9×15 = 224 triangles each) into a 512×512 framebuffer with depth
  test: the parametric path (:class:`~leafview.gpu.instanced.InstancedLeaves`, one instanced
  draw from a 288-byte record per leaf) against the same triangles pre-baked
  (:class:`~leafview.gpu.instanced.BakedLeaves`, one indexed draw);
* bytes per leaf of a baked 32×64 mesh against the parameter record.

Run: ``leafview bench [--json] [--quick]`` or ``python bench/run_bench.py``; timings with
:mod:`leafview.bench.timing`, the instancing measurement in :mod:`leafview.bench.instancing`.
"""

from __future__ import annotations

import os
import platform
import statistics
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import moderngl
import numpy as np

from leafview._version import __version__
from leafview.bench import PAPER_LEAVES_PER_S, THUMB_GRID, THUMB_SIZE
from leafview.bench.instancing import BYTES_GRID, SCENE_GRID, SCENE_SIZE, bytes_per_leaf, instanced_vs_baked
from leafview.bench.latency import measure_edit_latency
from leafview.bench.timing import Progress, bench_context, gl_info, median_time
from leafview.core.colour import linear_to_srgb
from leafview.core.params import Bending, Jitter, LeafParams, Shape
from leafview.deform.fbm import RIPPLE_SAMPLES
from leafview.deform.surface import evaluate, grid_uv, tessellate
from leafview.gpu.context import check_error
from leafview.gpu.instanced import OffscreenTarget
from leafview.gpu.renderer import LeafRenderer
from leafview.gpu.ripple import RipplePass
from leafview.resources import builtin_presets
from leafview.scene.camera import Camera, frame_view

__all__ = ["run", "format_table", "thumbnail_params", "GOALS", "PAPER_LEAVES_PER_S", "THUMB_SIZE",
           "THUMB_GRID"]


# goals (reported, never asserted): key -> minimum
GOALS = {
    "thumbnail_speedup": 20.0,
    "param_vs_baked_speed": 0.9,
    "baked_vs_param_bytes": 250.0,
    "ripple_overhead": 1.3,  # at most: lower is better
    "edit_latency_ratio": 1.2,  # at most: viewer frame carrying an edit ÷ steady frame
}

_CONFIG = {
    # thumbnail params, passes over them per batch, interleaved rounds (leafview and matplotlib),
    # matplotlib passes per round, scene leaves, repeats
    False: dict(thumb_params=4, thumb_passes=16, thumb_rounds=5, mpl_passes=2,
                leaves=10_000, scene_repeats=15),
    True: dict(thumb_params=2, thumb_passes=1, thumb_rounds=1, mpl_passes=1,
               leaves=300, scene_repeats=2),
}


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


@dataclass(frozen=True)
class ThumbnailMesh:
    """What every renderer of the like-for-like thumbnail draws: the leaf tessellated on
    ``THUMB_GRID`` by the numpy reference (world space), its unit normals, triangles, front colour
    (sRGB) and leafview's own camera for the three-quarter view at ``THUMB_SIZE``, framed on these
    vertices (what :class:`LeafRenderer` frames on, to float32 rounding)."""

    vertices: np.ndarray    # (N, 3) float64, world space
    normals: np.ndarray     # (N, 3) float64, unit, the upper side
    triangles: np.ndarray   # (T, 3) uint32, counter-clockwise seen from the upper side
    colour: tuple[float, float, float]   # front colour, sRGB in [0, 1]
    camera: Camera


def srgb(linear: Any) -> tuple[float, float, float]:
    """sRGB encoding of a linear RGB colour (what ``leaf.frag`` writes)."""
    e = linear_to_srgb(linear)
    return float(e[0]), float(e[1]), float(e[2])


def thumbnail_mesh(params: LeafParams, view: str = "three-quarter") -> ThumbnailMesh:
    """The mesh and camera of ``params``' thumbnail (see :class:`ThumbnailMesh`)."""
    mesh = tessellate(params, *THUMB_GRID)
    m = params.transform.matrix()
    world = mesh.vertices @ m[:3, :3].T + m[:3, 3]
    normals = mesh.normals @ m[:3, :3].T
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    return ThumbnailMesh(world, normals, mesh.indices.reshape(-1, 3).astype(np.uint32),
                         srgb(params.material.front), frame_view(view, world, THUMB_SIZE))


class MplCanvas:
    """A matplotlib (Agg) figure of ``THUMB_SIZE`` with one 3D axes filling it: :meth:`draw`
    puts a :class:`ThumbnailMesh` in it (``plot_trisurf``) and reads the RGBA pixels back. Kept
    and reused for a batch (the faster way); a new one per leaf for one call per leaf."""

    def __init__(self) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg  # optional: leafview[bench]
        from matplotlib.figure import Figure

        self.figure = Figure(figsize=(THUMB_SIZE[0] / 100, THUMB_SIZE[1] / 100), dpi=100)
        self.canvas = FigureCanvasAgg(self.figure)
        self.axes: Any = self.figure.add_axes((0.0, 0.0, 1.0, 1.0), projection="3d")   # mplot3d Axes3D
        self.axes.set_axis_off()

    def draw(self, mesh: ThumbnailMesh, *, antialiased: bool = True) -> np.ndarray:
        """(h, w, 4) uint8, row 0 at the top, white where no leaf is."""
        ax = self.axes
        for old in list(ax.collections):
            old.remove()
        p = mesh.vertices
        ax.plot_trisurf(p[:, 0], p[:, 1], p[:, 2], triangles=mesh.triangles, color=mesh.colour,
                        linewidth=0, antialiased=antialiased, shade=True)
        # leafview's camera instead of mplot3d's orbit: clip = P·V; mplot3d divides by w and
        # maps x, y in [-1, 1] onto the axes, as GL's viewport does
        clip = mesh.camera.proj @ mesh.camera.view
        ax.get_proj = lambda: clip
        ax.viewLim.intervalx = ax.viewLim.intervaly = (-1.0, 1.0)
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba()).copy()


def mpl_thumbnail(mesh: ThumbnailMesh, *, antialiased: bool = True, canvas: MplCanvas | None = None) -> np.ndarray:
    """matplotlib baseline: ``plot_trisurf`` (Agg) of ``mesh`` through leafview's camera, read back;
    into ``canvas`` (reused) or a new figure."""
    return (canvas or MplCanvas()).draw(mesh, antialiased=antialiased)


def _thumbnails(ctx: moderngl.Context, cfg: dict[str, Any], progress: Progress) -> dict[str, Any]:
    """Thumbnail rates: leafview (top view as ``leafview render DIR``; three-quarter with 4× MSAA
    and without) and matplotlib (the same mesh and camera, antialiased and not), batched and one
    call per leaf, measured in interleaved rounds; the speed-ups are medians of the per-round
    ratios."""
    thumbs = thumbnail_params(cfg["thumb_params"])
    batch = thumbs * cfg["thumb_passes"]
    meshes = [thumbnail_mesh(p) for p in thumbs]
    n_mpl = cfg["mpl_passes"] * len(thumbs)
    shared = MplCanvas()
    rounds: dict[str, list[float]] = {}

    def timed(key: str, fn: Callable[[], Any], count: int, finish: Callable[[], None] | None = None) -> None:
        rounds.setdefault(key, []).append(count / median_time(fn, 1, finish))

    with LeafRenderer(ctx) as renderer:
        progress.step("thumbnails (warm-up)")
        for view, samples in (("top", 0), ("three-quarter", 4), ("three-quarter", 0)):
            renderer.render_many(batch, THUMB_SIZE, view, grid=THUMB_GRID, samples=samples)
        for aa in (True, False):
            mpl_thumbnail(meshes[0], antialiased=aa, canvas=shared)   # 3D machinery, fonts, caches
        check_error(ctx, "thumbnail warm-up")

        def gl_batch(view: str, samples: int) -> Callable[[], Any]:
            return lambda: renderer.render_many(batch, THUMB_SIZE, view, grid=THUMB_GRID, samples=samples)

        def gl_single(view: str) -> Callable[[], None]:
            def go() -> None:
                for p in batch:
                    renderer.render(p, THUMB_SIZE, view, grid=THUMB_GRID)
            return go

        def mpl(antialiased: bool, reuse: bool) -> Callable[[], None]:
            def go() -> None:
                for _ in range(cfg["mpl_passes"]):
                    for mesh in meshes:
                        mpl_thumbnail(mesh, antialiased=antialiased, canvas=shared if reuse else None)
            return go

        progress.step("thumbnails: leafview and matplotlib, interleaved")
        for _ in range(cfg["thumb_rounds"]):
            timed("thumbnails_per_s", gl_batch("top", 0), len(batch), ctx.finish)
            timed("thumbnails_per_s_single", gl_single("top"), len(batch), ctx.finish)
            timed("thumbnails_per_s_three_quarter", gl_batch("three-quarter", 4), len(batch), ctx.finish)
            timed("thumbnails_per_s_three_quarter_single", gl_single("three-quarter"), len(batch), ctx.finish)
            timed("thumbnails_per_s_three_quarter_aliased", gl_batch("three-quarter", 0), len(batch), ctx.finish)
            timed("matplotlib_thumbnails_per_s", mpl(True, True), n_mpl)
            timed("matplotlib_thumbnails_per_s_single", mpl(True, False), n_mpl)
            timed("matplotlib_thumbnails_per_s_aliased", mpl(False, True), n_mpl)
        check_error(ctx, "thumbnails")
    res: dict[str, Any] = {key: statistics.median(rates) for key, rates in rounds.items()}
    for key, gl_key, mpl_key in (
            ("thumbnail_speedup", "thumbnails_per_s_three_quarter", "matplotlib_thumbnails_per_s"),
            ("thumbnail_speedup_single", "thumbnails_per_s_three_quarter_single", "matplotlib_thumbnails_per_s_single"),
            ("thumbnail_speedup_aliased", "thumbnails_per_s_three_quarter_aliased",
             "matplotlib_thumbnails_per_s_aliased")):
        ratios = sorted(g / m for g, m in zip(rounds[gl_key], rounds[mpl_key]))
        res[key] = statistics.median(ratios)
        res[f"{key}_range"] = [ratios[0], ratios[-1]]
    res.update(thumbnail_count=len(batch), matplotlib_thumbnail_count=n_mpl, thumbnail_rounds=cfg["thumb_rounds"])
    return res


def run(quick: bool = False, ctx: moderngl.Context | None = None) -> dict[str, Any]:
    """Run every benchmark in this process; returns a flat dict (see the module docstring).

    ``ctx``: an existing moderngl context to measure on (kept open); default a new headless
    one, released at the end. Pass the context already in use when the process has one:
    creating a second standalone context makes it current behind the first one's back.

    Keys: ``gl_renderer``; thumbnails (:func:`_thumbnails`): ``thumbnails_per_s`` (top view,
    batched) and ``_single``, ``thumbnails_per_s_three_quarter`` (4× MSAA, batched), ``_single``
    and ``_aliased``, ``matplotlib_thumbnails_per_s`` (same mesh and camera, antialiased, one figure
    reused), ``_single`` (a new figure each) and ``_aliased``, ``thumbnail_speedup`` (three-quarter,
    batched, antialiased; the goal), ``thumbnail_speedup_single``, ``thumbnail_speedup_aliased``
    (each with ``_range`` over the rounds); ``param_vs_baked_speed`` (+ ``instanced_leaves_per_s``,
    ``baked_leaves_per_s``, ``param_vs_baked_mean_abs_diff``), ``baked_vs_param_bytes`` (+
    ``baked_bytes_per_leaf``, ``param_bytes_per_leaf``), ``leaves_per_s_220tri``,
    ``vs_paper_550``, ``edit_latency_ratio`` (+ ``viewer_frame_ms``, ``viewer_edit_frame_ms``,
    ``viewer_edit_upload_bytes``; see :mod:`leafview.bench.latency`), and the configuration:
    counts, grids, versions, ``cpu_count``.
    """
    import matplotlib  # optional: leafview[bench]

    cfg = _CONFIG[bool(quick)]
    res: dict[str, Any] = {}
    with bench_context(ctx) as ctx, Progress(7) as progress:
        res.update(gl_info(ctx))

        # -- thumbnails: leafview and matplotlib, same mesh, camera and size ---------------------
        res.update(_thumbnails(ctx, cfg, progress))

        # -- many leaves: parameters (instanced) vs baked meshes, identical triangles ----------
        progress.step(f"scene setup ({cfg['leaves']} leaves)")
        n_leaves = cfg["leaves"]
        scene = instanced_vs_baked(ctx, n_leaves, cfg["scene_repeats"], progress)
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

    res.update({
        "quick": bool(quick),
        "thumbnail_size": list(THUMB_SIZE),
        "thumbnail_grid": list(THUMB_GRID),
        "scene_leaves": n_leaves,
        "scene_grid": list(SCENE_GRID),
        "scene_size": list(SCENE_SIZE),
        "bytes_grid": list(BYTES_GRID),
        "cpu_count": os.cpu_count() or 0,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "moderngl": moderngl.__version__,  # type: ignore[attr-defined]
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


def _span(r: list[float]) -> str:
    return f"{r[0]:.1f}-{r[1]:.1f}"


RIPPLE_GRID = (65, 257)
RIPPLE_SIZE = (512, 512)


def _ripples(ctx: moderngl.Context, repeats: int) -> dict[str, Any]:
    """Frame time of one rippled leaf ÷ the same leaf and grid without ripples (interleaved
    pairs), and the time to re-synthesise ripple signals after a β or seed change."""
    on = LeafParams.load(builtin_presets()["maize"]).replace(bending=Bending())
    off = on.replace(ripple=replace(on.ripple, enabled=False))
    with LeafRenderer(ctx) as renderer, OffscreenTarget(ctx, RIPPLE_SIZE) as target:
        uv = grid_uv(*RIPPLE_GRID)
        renderer.set_camera(frame_view("three-quarter", evaluate(on, uv[:, 0], uv[:, 1]), RIPPLE_SIZE), srgb=True)

        def frame(params: LeafParams) -> Callable[[], None]:
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
            t_on = median_time(frame(on), 3, ctx.finish)
            t_off = median_time(frame(off), 3, ctx.finish)
            ratios.append(t_on / t_off)
        check_error(ctx, "ripple frames")
    rp = RipplePass(ctx)
    try:
        rp.update([(0, 1.0)])
        ctx.finish()
        seeds = iter(range(1, 10**6))
        t_one = median_time(lambda: rp.update([(next(seeds), 1.0)]), 9, ctx.finish)
        t_many = median_time(lambda: rp.update([(next(seeds), 1.0 + (i % 7) * 0.25) for i in range(1000)]),
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
        ("three-quarter, 4× MSAA", num(res["thumbnails_per_s_three_quarter"]),
         "render_many; like for like below: same mesh, camera and size, readback included"),
        ("  one render() call each", num(res["thumbnails_per_s_three_quarter_single"]), ""),
        ("  no antialiasing", num(res["thumbnails_per_s_three_quarter_aliased"]), "render_many, samples=0"),
        ("matplotlib, antialiased", num(res["matplotlib_thumbnails_per_s"]),
         f"plot_trisurf (Agg) through leafview's camera, one figure reused, {res['matplotlib_thumbnail_count']} "
         "per round"),
        ("  a new figure each", num(res["matplotlib_thumbnails_per_s_single"]), ""),
        ("  antialiased=False", num(res["matplotlib_thumbnails_per_s_aliased"]), "one figure reused"),
        ("thumbnail speedup", f"{num(res['thumbnail_speedup'])}×",
         f"{_goal('thumbnail_speedup', res)}; three-quarter, batched, antialiased (rounds "
         f"{_span(res['thumbnail_speedup_range'])})"),
        ("  one call per leaf", f"{num(res['thumbnail_speedup_single'])}×",
         f"render() ÷ a new figure each (rounds {_span(res['thumbnail_speedup_single_range'])})"),
        ("  without antialiasing", f"{num(res['thumbnail_speedup_aliased'])}×",
         f"batched (rounds {_span(res['thumbnail_speedup_aliased_range'])})"),
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
        ("vs paper (550 leaves/s), draw only", f"{num(res['vs_paper_550'])}×",
         "not the same work: the paper generates each leaf; end to end: leafview bench shapes"),
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
