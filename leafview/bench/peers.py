"""``leafview bench peers``: leafview side by side with what users would pick instead, drawing the
same leaf meshes through the same camera at the same size, readback included.

Peers (optional: ``pip install 'leafview[peers]'``): **PyVista/VTK** (its default wheel renders
offscreen through EGL, here on the same llvmpipe as leafview) and **pygfx** (wgpu: its Vulkan
backend where there is a Vulkan driver, e.g. Mesa's lavapipe, else its OpenGL backend, on a
machine without a GPU the same llvmpipe). A peer that is missing or cannot start gets rows that
say so (``not installed`` / ``unavailable: <reason>``) and the run goes on.

Rows (see :func:`run` for the keys):

* **thumbnails**, 128×128, the three-quarter view of :func:`~leafview.bench.core.thumbnail_mesh`
  (the leaf tessellated on the 32×64 grid, leafview's own camera), 4 samples a pixel each (leafview
  and VTK 4× MSAA; pygfx has no MSAA and draws at twice the resolution, its default):
  one call per leaf (one renderer kept, a new mesh each call) and batched (leafview
  ``render_many``; PyVista one plotter with a subplot per leaf; pygfx one target with a viewport
  per leaf), each with one readback;
* **scenes** of 10⁴ and 10⁵ leaves (the field of ``leafview bench scene``, without shape and
  colour variation so that the peers can instance one mesh per species, and without stems),
  1280×720, the ``ground`` camera, no antialiasing: leafview's :class:`~leafview.gpu.scene.
  SceneRenderer` with culling and LOD, and without (every leaf at the finest 9×17 grid:
  identical triangles to the peers'), and :class:`~leafview.gpu.instanced.InstancedLeaves` on the
  same grid; each peer draws the same triangles as one merged mesh and as one instanced mesh per
  species (VTK ``vtkGlyph3DMapper``, pygfx ``InstancedMesh``). The peers shade plain colours, so
  leafview's rows draw without the species' vein fields (``veins=False``; ``InstancedLeaves``
  draws none anyway); one more leafview row, without a ratio, draws the no-LOD frame with them,
  to show what they cost.

The meshes come from leafview's numpy tessellation of the same leaves; every row's image is
compared with leafview's (``coverage_iou``: intersection over union of the covered pixels), so
"the same framing" is measured, not assumed. Rounds are interleaved (every row once per round);
a speed-up is the median over rounds of peer time ÷ leafview time. Each peer runs in a worker
process of its own (:mod:`leafview.bench.peer_renderers`), which times its drawing and readback
itself. Nothing is asserted.
"""

from __future__ import annotations

import importlib.util
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

import moderngl
import numpy as np

from leafview._version import __version__
from leafview.bench import THUMB_GRID, THUMB_SIZE
from leafview.bench.core import thumbnail_params
from leafview.bench.peer_renderers import (
    MODULES,
    PEERS,
    SCENE_GRID,
    SCENE_SIZE,
    SCENE_VIEW,
    SPECIES,
    THUMB_SAMPLES,
    peer_scene,
    scene_meshes,
)
from leafview.bench.timing import Progress, bench_context, gl_info, log_gl_renderer
from leafview.gpu.context import check_error
from leafview.gpu.instanced import InstancedLeaves
from leafview.gpu.renderer import LeafRenderer
from leafview.gpu.scene import CullSettings, SceneRenderer, pack_scene, species_tables
from leafview.gpu.targets import RenderTarget
from leafview.scene.camera import scene_camera

__all__ = ["run", "format_table", "PEERS", "PeerProcess", "PeerError", "coverage_iou", "installed"]

_CONFIG: dict[bool, dict[str, Any]] = {
    # thumbnail leaves (distinct × passes), interleaved thumbnail rounds, scene sizes, rounds per size
    False: dict(thumb_params=4, thumb_passes=4, thumb_rounds=3, scenes=(10_000, 100_000), scene_rounds=(3, 1)),
    True: dict(thumb_params=1, thumb_passes=2, thumb_rounds=1, scenes=(100,), scene_rounds=(1,)),
}
_REPLY_TIMEOUT_S = 900.0   # a peer that takes longer to answer one command is stopped


def installed(peer: str) -> bool:
    """Whether every module ``peer`` needs can be imported (looked up, not imported: the peers'
    modules load only in their worker processes)."""
    return all(importlib.util.find_spec(name.split(".")[0]) is not None for name in MODULES[peer])


class PeerError(RuntimeError):
    """A command a peer's worker could not carry out (its message says why)."""


class PeerProcess:
    """One peer's worker process (:func:`~leafview.bench.peer_renderers.serve`), started at once;
    :meth:`ready` waits for it, :meth:`call` sends a command and returns its result. ``info`` is
    what the worker said when it started (``status`` ``ok`` or why not, ``version``,
    ``renderer``)."""

    def __init__(self, peer: str) -> None:
        self.peer = peer
        to_child, from_parent = os.pipe()
        to_parent, from_child = os.pipe()
        # a fresh interpreter (no GL state, no re-import of the caller's main module); what the
        # peer prints goes to stderr, so that --json output stays clean
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "leafview.bench.peer_renderers", peer, str(to_child), str(from_child)],
            pass_fds=(to_child, from_child), stdin=subprocess.DEVNULL, stdout=2)
        os.close(to_child)
        os.close(from_child)
        self._out = Connection(from_parent, readable=False)
        self._in = Connection(to_parent, writable=False)
        self.info: dict[str, Any] = {"status": "starting"}

    def ready(self) -> bool:
        """Wait for the worker's first message (its info); False (and the worker stopped) when
        the peer cannot draw."""
        try:
            self.info = self._receive()
        except PeerError as exc:
            self.info = {"status": f"unavailable: {exc}"}
        if not self.ok:
            self.close()
        return self.ok

    @property
    def ok(self) -> bool:
        return self.info.get("status") == "ok"

    def _receive(self) -> Any:
        if not self._in.poll(_REPLY_TIMEOUT_S):
            raise PeerError(f"no answer from the {self.peer} worker in {_REPLY_TIMEOUT_S:.0f} s")
        try:
            return self._in.recv()
        except EOFError:
            raise PeerError(f"the {self.peer} worker exited (code {self._proc.wait()})") from None

    def call(self, *command: Any) -> Any:
        try:
            self._out.send(command)
        except OSError:
            raise PeerError(f"the {self.peer} worker is gone") from None
        status, result = self._receive()
        if status != "ok":
            raise PeerError(str(result).strip())
        return result

    def close(self) -> None:
        """Stop the worker (idempotent)."""
        if self._proc.poll() is None:
            try:
                self._out.send(("quit",))
            except OSError:
                pass
            try:
                self._proc.wait(30)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        self._out.close()
        self._in.close()


def coverage_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of the covered pixels (alpha above half) of two RGBA images."""
    ma, mb = a[..., 3] > 127, b[..., 3] > 127
    union = int(np.count_nonzero(ma | mb))
    return float(np.count_nonzero(ma & mb)) / union if union else 1.0


def _unavailable(exc: Exception) -> str:
    """``unavailable: <reason>``: the error's first line and, for wgpu's multi-line validation
    errors, the line that names the cause."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip() and not line.startswith("Traceback")]
    detail = [line for line in lines[1:] if not line.startswith(("File ", "Caused by", "In wgpu"))][:1]
    return "unavailable: " + "; ".join(lines[:1] + detail)


def _timed(fn: Callable[[], Any], ctx: moderngl.Context) -> tuple[float, Any]:
    t0 = time.perf_counter()
    out = fn()
    ctx.finish()
    return time.perf_counter() - t0, out


def _speedup(times: dict[str, list[float]], lv: str, peer: str) -> float:
    """Median over rounds of peer time ÷ leafview time."""
    return statistics.median(p / t for t, p in zip(times[lv], times[peer]))


# -- thumbnails ---------------------------------------------------------------------------------------
def _thumbnail_rows(ctx: moderngl.Context, peers: dict[str, PeerProcess], cfg: dict[str, Any],
                    progress: Progress) -> dict[str, Any]:
    params = thumbnail_params(cfg["thumb_params"]) * cfg["thumb_passes"]
    n = len(params)
    rows: dict[str, dict[str, Any]] = {}
    times: dict[str, list[float]] = {}
    images: dict[str, np.ndarray] = {}
    ready = {}
    for name, proc in peers.items():
        progress.step(f"{name} thumbnails: set-up")
        try:
            proc.info["renderer"] = proc.call("thumbnails", cfg["thumb_params"], cfg["thumb_passes"])
            for mode in ("single", "batched"):   # warm-up
                proc.call("thumbnail_run", mode)
            ready[name] = proc
        except PeerError as exc:
            for mode in ("single", "batched"):
                rows[f"{name}/{mode}"] = {"status": _unavailable(exc)}
    with LeafRenderer(ctx) as renderer:
        def lv(mode: str) -> Callable[[], np.ndarray]:
            def go() -> np.ndarray:
                if mode == "single":
                    return np.stack([renderer.render(p, THUMB_SIZE, "three-quarter", grid=THUMB_GRID,
                                                     samples=THUMB_SAMPLES) for p in params])
                return np.stack(renderer.render_many(params, THUMB_SIZE, "three-quarter", grid=THUMB_GRID,
                                                     samples=THUMB_SAMPLES))
            return go

        for mode in ("single", "batched"):
            lv(mode)()   # warm-up: compile, allocate
        check_error(ctx, "thumbnail warm-up")
        progress.step("thumbnails: interleaved rounds")
        for _ in range(cfg["thumb_rounds"]):
            for mode in ("single", "batched"):
                dt, images[f"leafview/{mode}"] = _timed(lv(mode), ctx)
                times.setdefault(f"leafview/{mode}", []).append(dt)
                for name, proc in list(ready.items()):
                    try:
                        dt, images[f"{name}/{mode}"] = proc.call("thumbnail_run", mode)
                        times.setdefault(f"{name}/{mode}", []).append(dt)
                    except PeerError as exc:
                        del ready[name]
                        for m in ("single", "batched"):
                            rows[f"{name}/{m}"] = {"status": _unavailable(exc)}
                            times.pop(f"{name}/{m}", None)
        check_error(ctx, "thumbnails")
    for proc in peers.values():
        try:
            proc.call("close")
        except PeerError:
            pass
    for key, ts in times.items():
        who, mode = key.split("/")
        ref, img = images[f"leafview/{mode}"], images[key]
        t = statistics.median(ts)
        row: dict[str, Any] = {"per_s": n / t, "ms_per_thumbnail": 1e3 * t / n,
                               "coverage_iou": min(coverage_iou(a, b) for a, b in zip(ref, img))}
        if who != "leafview":
            row["leafview_speedup"] = _speedup(times, f"leafview/{mode}", key)
        rows[key] = row
    return {"count": n, "rounds": cfg["thumb_rounds"], "size": list(THUMB_SIZE), "grid": list(THUMB_GRID),
            "samples": THUMB_SAMPLES, "rows": rows}


# -- scenes -------------------------------------------------------------------------------------------
_LV_SCENE_ROWS = {
    "leafview/scene": "scene, culling + LOD",
    "leafview/scene_no_lod": "scene, no culling or LOD (identical triangles)",
    "leafview/instanced": "InstancedLeaves (identical triangles)",
}
# leafview rows shown without a ratio (the peers draw nothing like them)
_LV_REFERENCE_ROWS = {"leafview/scene_no_lod_veins": "scene, no culling or LOD, with veins"}
_PEER_KINDS = {"merged": "merged mesh", "instanced": "instanced mesh per species"}


def _scene_rows(ctx: moderngl.Context, n_leaves: int, rounds: int, peers: dict[str, PeerProcess],
                progress: Progress) -> dict[str, Any]:
    progress.step(f"{n_leaves:,} leaves: set-up")
    scene = peer_scene(n_leaves)
    camera = scene_camera(scene, SCENE_SIZE, SCENE_VIEW)
    out: dict[str, Any] = {"leaves": n_leaves, "triangles": scene_meshes(scene).triangles, "rounds": rounds,
                           "rows": {}}
    ready: dict[str, PeerProcess] = {}
    for name, proc in peers.items():
        for kind in _PEER_KINDS:
            progress.step(f"{n_leaves:,} leaves: {name} {kind} set-up")
            try:
                proc.info["renderer"] = proc.call("scene", n_leaves, camera, kind)   # uploads, draws once
                ready[f"{name}/{kind}"] = proc
            except PeerError as exc:
                out["rows"][f"{name}/{kind}"] = {"status": _unavailable(exc)}
    times: dict[str, list[float]] = {}
    images: dict[str, np.ndarray] = {}
    # like the peers (and InstancedLeaves), in the species' plain colours; `veined`: with their veins
    with RenderTarget(ctx, SCENE_SIZE) as target, SceneRenderer(ctx, scene, veins=False) as sr, \
            SceneRenderer(ctx, scene, resources=sr.resources) as veined:
        _, tables, ripples = species_tables(scene)
        with InstancedLeaves(ctx, pack_scene(scene), SCENE_GRID, jitter_tables=tables, ripple_signals=ripples,
                             resources=sr.resources) as inst:
            sr.set_camera(camera, SCENE_SIZE)
            veined.set_camera(camera, SCENE_SIZE)
            inst.set_camera(camera)

            def lv(draw: Callable[[], None]) -> Callable[[], np.ndarray]:
                def go() -> np.ndarray:
                    target.use()
                    ctx.viewport = (0, 0, *SCENE_SIZE)
                    target.clear()
                    draw()
                    return target.read()
                return go

            mine = {"leafview/scene": lv(lambda: sr.draw(CullSettings())),
                    "leafview/scene_no_lod": lv(lambda: sr.draw(CullSettings(cull=False, lod=False))),
                    "leafview/instanced": lv(inst.draw),
                    "leafview/scene_no_lod_veins": lv(lambda: veined.draw(CullSettings(cull=False, lod=False)))}
            for key, fn in mine.items():   # warm-up
                fn()
                if key == "leafview/scene":
                    out["leafview_levels"] = [int(c) for c in sr.level_counts()]   # what culling and LOD left
            check_error(ctx, f"{n_leaves} leaves: warm-up")
            for r in range(rounds):
                progress.step(f"{n_leaves:,} leaves: round {r + 1} of {rounds}")
                for key, fn in mine.items():
                    dt, images[key] = _timed(fn, ctx)
                    times.setdefault(key, []).append(dt)
                for key, proc in list(ready.items()):
                    try:
                        dt, images[key] = proc.call("frame", key.split("/")[1])
                        times.setdefault(key, []).append(dt)
                    except PeerError as exc:
                        del ready[key]
                        times.pop(key, None)
                        out["rows"][key] = {"status": _unavailable(exc)}
            check_error(ctx, f"{n_leaves} leaves")
    for proc in peers.values():
        try:
            proc.call("close")
        except PeerError:
            pass
    ref = images["leafview/scene_no_lod"]
    for key, ts in times.items():
        row: dict[str, Any] = {"ms": 1e3 * statistics.median(ts), "coverage_iou": coverage_iou(ref, images[key])}
        if not key.startswith("leafview"):
            row["leafview_speedup"] = {lv_key.split("/")[1]: _speedup(times, lv_key, key) for lv_key in _LV_SCENE_ROWS}
        out["rows"][key] = row
    return out


def run(quick: bool = False, ctx: moderngl.Context | None = None) -> dict[str, Any]:
    """Run the side-by-side benchmark; returns a JSON-able dict.

    Keys: ``gl_renderer``, ``gl_version`` (leafview's context), ``peers`` (per peer: ``status``
    (``ok``, ``not installed ...``, ``unavailable: ...``), ``version``, ``renderer``),
    ``thumbnails`` (``rows`` keyed ``<renderer>/<single|batched>``: ``per_s``,
    ``ms_per_thumbnail``, ``coverage_iou`` against leafview's image (the lowest over the leaves),
    and for peers ``leafview_speedup``; or ``status`` when a peer failed), ``scenes`` (per leaf
    count: ``rows`` keyed ``leafview/scene``, ``leafview/scene_no_lod``, ``leafview/instanced``
    (without veins, as the peers), ``leafview/scene_no_lod_veins`` (with the species' veins),
    ``<peer>/merged``, ``<peer>/instanced``: ``ms``, ``coverage_iou`` against leafview without
    LOD, and for peers ``leafview_speedup`` per leafview row but the veined one), the
    configuration and versions.
    """
    cfg = _CONFIG[bool(quick)]
    t_start = time.perf_counter()
    info: dict[str, dict[str, Any]] = {}
    peers: dict[str, PeerProcess] = {}
    try:
        starting = {}
        for name in PEERS:   # the workers start side by side (importing VTK or wgpu takes seconds)
            if installed(name):
                starting[name] = PeerProcess(name)
            else:
                info[name] = {"status": f"not installed: pip install 'leafview[peers]' ({', '.join(MODULES[name])})"}
        for name, proc in starting.items():
            if proc.ready():
                peers[name] = proc
            info[name] = proc.info
        with bench_context(ctx) as ctx:
            res: dict[str, Any] = {**gl_info(ctx), "quick": bool(quick)}
            log_gl_renderer("peers", res["gl_renderer"])
            steps = 2 + len(peers) * (1 + 2 * len(cfg["scenes"])) + len(cfg["scenes"]) + sum(cfg["scene_rounds"])
            with Progress(steps) as progress:
                res["thumbnails"] = _thumbnail_rows(ctx, peers, cfg, progress)
                res["scenes"] = {str(n): _scene_rows(ctx, n, r, peers, progress)
                                 for n, r in zip(cfg["scenes"], cfg["scene_rounds"])}
    finally:
        for proc in peers.values():
            proc.close()
    res.update({
        "peers": info,
        "scene_size": list(SCENE_SIZE), "scene_view": SCENE_VIEW, "scene_grid": list(SCENE_GRID),
        "scene_species": list(SPECIES), "antialiasing": {
            "thumbnails": "leafview and VTK 4× MSAA; pygfx renders at 2× and filters down (its default)",
            "scenes": "none"},
        "seconds": time.perf_counter() - t_start,
        "cpu_count": os.cpu_count() or 0, "python": platform.python_version(), "numpy": np.__version__,
        "moderngl": moderngl.__version__,  # type: ignore[attr-defined]
        "leafview": __version__, "platform": platform.platform(),
    })
    return res


# -- the table ----------------------------------------------------------------------------------------
def _status_line(name: str, peer: dict[str, Any]) -> str:
    if peer["status"] != "ok":
        return f"{name}: {peer['status']}"
    return f"{name}: {peer['version']} on {peer['renderer']}"


def format_table(res: dict[str, Any]) -> str:
    """The readable report printed by ``leafview bench peers``."""
    lines = [f"leafview {res['leafview']} against other renderers{' (quick)' if res['quick'] else ''}",
             f"leafview: moderngl {res['moderngl']} on {res['gl_renderer']} ({res['gl_version']})"]
    lines += [_status_line(name, peer) for name, peer in res["peers"].items()]
    th = res["thumbnails"]
    lines.append("")
    lines.append(f"thumbnails: {th['size'][0]}×{th['size'][1]}, three-quarter, grid {th['grid'][0]}×{th['grid'][1]}, "
                 f"{th['count']} leaves, 4 samples a pixel, readback included, {th['rounds']} rounds")
    lines.append(f"  {'renderer':<22} {'thumbnails/s':>12} {'ms each':>8} {'IoU':>6}  leafview ÷ peer")
    for mode in ("single", "batched"):
        for name in ("leafview", *res["peers"]):
            row = th["rows"].get(f"{name}/{mode}")
            label = f"{name}, {'one call each' if mode == 'single' else 'batched'}"
            if row is None or "per_s" not in row:
                lines.append(f"  {label:<22} {(row or res['peers'][name])['status']}")
                continue
            speed = f"{row['leafview_speedup']:.2f}×" if "leafview_speedup" in row else ""
            lines.append(f"  {label:<22} {row['per_s']:>12.1f} {row['ms_per_thumbnail']:>8.2f} "
                         f"{row['coverage_iou']:>6.3f}  {speed}")
    for n, sc in res["scenes"].items():
        lines.append("")
        lines.append(f"scene: {int(n):,} leaves ({sc['triangles']:,} triangles at {res['scene_grid'][0]}×"
                     f"{res['scene_grid'][1]}), {res['scene_size'][0]}×{res['scene_size'][1]}, {res['scene_view']} "
                     f"camera, no antialiasing, {sc['rounds']} round(s); LOD drew {'/'.join(map(str, sc['leafview_levels']))}")
        lines.append(f"  {'renderer':<57} {'ms/frame':>9} {'IoU':>6}  leafview ÷ peer: LOD / no LOD / instanced")
        for key, label in {**_LV_SCENE_ROWS, **_LV_REFERENCE_ROWS}.items():
            row = sc["rows"].get(key)
            if row is None:   # a result of an older leafview
                continue
            lines.append(f"  {'leafview ' + label:<57} {row['ms']:>9.1f} {row['coverage_iou']:>6.3f}")
        for name in res["peers"]:
            for kind, what in (("merged", "merged mesh"), ("instanced", "instanced mesh per species")):
                row = sc["rows"].get(f"{name}/{kind}")
                label = f"{name} {what}"
                if row is None:
                    lines.append(f"  {label:<57} {res['peers'][name]['status']}")
                elif "ms" not in row:
                    lines.append(f"  {label:<57} {row['status']}")
                else:
                    s = row["leafview_speedup"]
                    lines.append(f"  {label:<57} {row['ms']:>9.1f} {row['coverage_iou']:>6.3f}  "
                                 f"{s['scene']:.2f}× / {s['scene_no_lod']:.2f}× / {s['instanced']:.2f}×")
    lines.append(f"(medians over interleaved rounds; IoU: covered pixels shared with leafview's image; "
                 f"{res['cpu_count']} CPUs, {res['seconds']:.0f} s)")
    return "\n".join(lines)
