"""The peers of ``leafview bench peers`` (:mod:`leafview.bench.peers`): PyVista/VTK and pygfx
drawing the thumbnails and scenes that leafview draws, each in a process of its own.

Each peer runs in a worker process (:func:`serve`, started by :class:`leafview.bench.peers.
PeerProcess` as ``python -m leafview.bench.peer_renderers``): VTK and wgpu create EGL contexts of their own, and VTK terminates the EGL display
when a plotter closes, which would take leafview's context (and a caller's) with it. A worker
builds its meshes itself from the same deterministic inputs (thumbnail leaves, the scene's leaf
count) and times only the drawing and the readback, as leafview's side is timed.

Shared by both sides: the scene (:func:`peer_scene`, :func:`scene_meshes`) and a camera as the
peers take it (:func:`camera_setup`).
"""

from __future__ import annotations

import importlib
import math
import os
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from types import ModuleType
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from leafview.bench import THUMB_SIZE
from leafview.bench.core import ThumbnailMesh, srgb, thumbnail_mesh, thumbnail_params
from leafview.core.params import LeafParams
from leafview.deform.surface import tessellate
from leafview.gpu.scene import LOD_GRIDS
from leafview.resources import resolve_preset
from leafview.scene.camera import Camera
from leafview.scene.spec import Scene, SceneSpec, build_scene

__all__ = ["PEERS", "MODULES", "SCENE_SIZE", "SPECIES", "SCENE_VIEW", "SCENE_GRID", "THUMB_SAMPLES", "CameraSetup",
           "camera_setup", "SceneMeshes", "peer_scene", "scene_meshes", "serve"]

PEERS = ("pyvista", "pygfx")
MODULES = {"pyvista": ("pyvista", "vtk"), "pygfx": ("pygfx", "wgpu")}
SCENE_SIZE = (1280, 720)
SPECIES = ("ovate", "lanceolate", "elliptic")
SCENE_VIEW = "ground"
SCENE_GRID = LOD_GRIDS[0]       # the finest level: what every leaf is drawn with when LOD is off
THUMB_SAMPLES = 4


@dataclass(frozen=True)
class CameraSetup:
    """A perspective :class:`Camera` as the peers take it: eye, a point ahead, up, vertical field
    of view (degrees) and the clip planes."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float]
    fov_deg: float
    near: float
    far: float


def camera_setup(camera: Camera) -> CameraSetup:
    """The eye, aim, up, field of view and clip planes of leafview's perspective ``camera`` (the
    rows of its view matrix are the camera's right, up and backward axes)."""
    if not camera.perspective:
        raise ValueError("the peers are set up with perspective cameras only")
    v, p = np.asarray(camera.view, np.float64), np.asarray(camera.proj, np.float64)
    eye = np.asarray(camera.eye[:3], np.float64)
    near, far = p[2, 3] / (p[2, 2] - 1.0), p[2, 3] / (p[2, 2] + 1.0)

    def vec(x: np.ndarray) -> tuple[float, float, float]:
        return float(x[0]), float(x[1]), float(x[2])

    return CameraSetup(vec(eye), vec(eye - v[2, :3]), vec(v[1, :3]), math.degrees(2.0 * math.atan(1.0 / p[1, 1])),
                       float(near), float(far))


@dataclass
class SceneMeshes:
    """A scene's leaves as triangles: per species its tessellation on ``SCENE_GRID`` (leaf space),
    colour (sRGB) and the leaves' matrices; :meth:`merged` bakes them into one world-space mesh."""

    local: list[Any]                 # per species: leafview.core.blade.Mesh
    colours: list[tuple[float, float, float]]
    matrices: list[np.ndarray]       # per species: (n_k, 4, 4) leaf -> world

    @property
    def triangles(self) -> int:
        return sum(len(m) * (len(s.indices.reshape(-1, 3))) for s, m in zip(self.local, self.matrices))

    def split(self, max_leaves: int) -> list[SceneMeshes]:
        """The same leaves in parts of at most ``max_leaves`` leaves (in order)."""
        parts: list[SceneMeshes] = []
        current = SceneMeshes([], [], [])
        room = max_leaves
        for mesh, colour, mats in zip(self.local, self.colours, self.matrices):
            start = 0
            while start < len(mats):
                take = min(room, len(mats) - start)
                current.local.append(mesh)
                current.colours.append(colour)
                current.matrices.append(mats[start:start + take])
                start += take
                room -= take
                if room == 0:
                    parts.append(current)
                    current, room = SceneMeshes([], [], []), max_leaves
        if current.local:
            parts.append(current)
        return parts

    def merged(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(positions (N, 3) f4, unit normals (N, 3) f4, RGB (N, 3) u1, triangles (T, 3) i4) of
        every leaf in world space."""
        pos, nrm, rgb, tri = [], [], [], []
        base = 0
        for mesh, colour, mats in zip(self.local, self.colours, self.matrices):
            n, nv = len(mats), len(mesh.vertices)
            rot, shift = mats[:, :3, :3].astype(np.float32), mats[:, :3, 3].astype(np.float32)
            pos.append((np.einsum("nij,vj->nvi", rot, mesh.vertices.astype(np.float32)) + shift[:, None]).reshape(-1, 3))
            wn = np.einsum("nij,vj->nvi", rot, mesh.normals.astype(np.float32))
            wn /= np.maximum(np.linalg.norm(wn, axis=-1, keepdims=True), np.float32(1e-12))
            nrm.append(wn.reshape(-1, 3))
            rgb.append(np.broadcast_to(np.round(np.asarray(colour) * 255).astype(np.uint8), (n * nv, 3)))
            faces = mesh.indices.reshape(-1, 3).astype(np.int32)
            tri.append((faces[None] + (base + np.arange(n, dtype=np.int32) * nv)[:, None, None]).reshape(-1, 3))
            base += n * nv
        return np.concatenate(pos), np.concatenate(nrm), np.ascontiguousarray(np.concatenate(rgb)), np.concatenate(tri)


def peer_scene(leaves: int) -> Scene:
    """The field of ``leafview bench scene`` (same species, seed and layout) with every leaf its
    species' shape and colour and no stems: what the peers can draw as one mesh per species."""
    species = tuple(LeafParams.load(resolve_preset(s)) for s in SPECIES)
    return build_scene(SceneSpec(species=species, leaves=leaves, seed=1, layout="field", variation=0.0,
                                 colour_variation=0.0, stems=False))


def scene_meshes(scene: Scene, grid: tuple[int, int] = SCENE_GRID) -> SceneMeshes:
    """Per species of ``scene`` (which must not vary shapes): the numpy tessellation on ``grid``,
    the front colour and the matrices of its leaves."""
    if scene.varied:
        raise ValueError("scene_meshes needs a scene without shape or colour variation")
    local, colours, mats = [], [], []
    for k, sp in enumerate(scene.species):
        idx = np.flatnonzero(scene.species_id == k)
        if not idx.size:
            continue
        local.append(tessellate(sp, *grid))
        colours.append(srgb(sp.material.front))
        mats.append(scene.matrices[idx])
    return SceneMeshes(local, colours, mats)


class _Frame:
    """A prepared scene of one renderer: ``draw()`` renders it and returns the RGBA image."""

    def __init__(self, draw: Callable[[], np.ndarray], close: Callable[[], None] = lambda: None) -> None:
        self.draw, self.close = draw, close


class _PyVista:
    name = "pyvista"

    def __init__(self, mods: dict[str, ModuleType]) -> None:
        self.pv, self.vtk = mods["pyvista"], mods["vtk"]
        self.version = f"pyvista {self.pv.__version__}, VTK {self.vtk.vtkVersion.GetVTKVersion()}"
        self.renderer = "?"

    def _plotter(self, size: tuple[int, int], samples: int, shape: tuple[int, int] = (1, 1)) -> Any:
        pl = self.pv.Plotter(off_screen=True, window_size=list(size), shape=shape, border=False)
        if samples:
            pl.enable_anti_aliasing("msaa", multi_samples=samples, all_renderers=True)
        else:
            pl.disable_anti_aliasing(all_renderers=True)
        return pl

    def _mesh(self, positions: np.ndarray, normals: np.ndarray, triangles: np.ndarray) -> Any:
        mesh = self.pv.PolyData.from_regular_faces(np.asarray(positions, np.float32),
                                                   np.asarray(triangles, np.int32))
        mesh.point_data["Normals"] = np.asarray(normals, np.float32)
        mesh.point_data.active_normals_name = "Normals"
        return mesh

    def _aim(self, renderer: Any, setup: CameraSetup) -> None:
        cam = renderer.camera
        cam.position, cam.focal_point, cam.up = setup.eye, setup.target, setup.up
        cam.view_angle = setup.fov_deg
        cam.clipping_range = (setup.near, setup.far)
        renderer.camera_set = True     # keep pyvista from resetting the camera at the first render

    def _shot(self, pl: Any) -> np.ndarray:
        pl.render()
        return np.asarray(pl.screenshot(transparent_background=True, return_img=True))

    def _start(self, pl: Any) -> np.ndarray:
        # the first image needs show(auto_close=False): screenshot() before it returns a stale image
        pl.show(auto_close=False)
        if self.renderer == "?":
            rep = pl.render_window.ReportCapabilities()
            self.renderer = next((line.split(":", 1)[1].strip() for line in rep.splitlines()
                                  if "renderer string" in line), type(pl.render_window).__name__)
        return self._shot(pl)

    def thumbnails(self, meshes: Sequence[ThumbnailMesh]) -> tuple[Callable[[], list[np.ndarray]],
                                                                    Callable[[], list[np.ndarray]], Callable[[], None]]:
        """(one call per leaf, batched, close): per leaf one plotter kept and its mesh replaced;
        batched one plotter with a subplot per leaf and one screenshot."""
        w, h = THUMB_SIZE
        one = self._plotter(THUMB_SIZE, THUMB_SAMPLES)
        cols = min(len(meshes), 32)
        rows = -(-len(meshes) // cols)
        many = self._plotter((cols * w, rows * h), THUMB_SAMPLES, (rows, cols))
        self._start(one)
        self._start(many)

        def add(pl: Any, m: ThumbnailMesh) -> None:
            pl.add_mesh(self._mesh(m.vertices, m.normals, m.triangles), color=m.colour, smooth_shading=True,
                        name="leaf", reset_camera=False, render=False)   # one render a screenshot
            self._aim(pl.renderer, camera_setup(m.camera))

        def single() -> list[np.ndarray]:
            out = []
            for m in meshes:
                add(one, m)
                out.append(self._shot(one))
            return out

        def batched() -> list[np.ndarray]:
            for i, m in enumerate(meshes):
                many.subplot(i // cols, i % cols)
                add(many, m)
            atlas = self._shot(many)
            return [atlas[(i // cols) * h:(i // cols + 1) * h, (i % cols) * w:(i % cols + 1) * w].copy()
                    for i in range(len(meshes))]

        def close() -> None:
            one.close()
            many.close()

        return single, batched, close

    def scene(self, meshes: SceneMeshes, camera: Camera, instanced: bool) -> _Frame:
        pl = self._plotter(SCENE_SIZE, 0)
        if instanced:
            for mesh, colour, mats in zip(meshes.local, meshes.colours, meshes.matrices):
                pl.add_actor(self._glyphs(mesh, colour, mats), reset_camera=False, render=False)
        else:
            pos, nrm, rgb, tri = meshes.merged()
            merged = self._mesh(pos, nrm, tri)
            merged.point_data["rgb"] = rgb
            del pos, nrm, rgb, tri
            pl.add_mesh(merged, scalars="rgb", rgb=True, smooth_shading=True, reset_camera=False, render=False)
        self._aim(pl.renderer, camera_setup(camera))
        self._start(pl)
        return _Frame(lambda: self._shot(pl), pl.close)

    def _glyphs(self, mesh: Any, colour: tuple[float, float, float], mats: np.ndarray) -> Any:
        """One species as a ``vtkGlyph3DMapper`` (GPU instancing): the leaf mesh at every leaf's
        position, rotation (a quaternion) and uniform scale."""
        pv, vtk = self.pv, self.vtk
        scale = np.linalg.norm(mats[:, :3, 0], axis=1)
        points = pv.PolyData(np.ascontiguousarray(mats[:, :3, 3], np.float32))
        points.point_data["orientation"] = _quaternions(mats[:, :3, :3] / scale[:, None, None]).astype(np.float32)
        points.point_data["scale"] = scale.astype(np.float32)
        source = self._mesh(mesh.vertices, mesh.normals, mesh.indices.reshape(-1, 3))
        mapper = vtk.vtkGlyph3DMapper()
        mapper.SetInputData(points)
        mapper.SetSourceData(source)
        mapper.SetOrientationArray("orientation")
        mapper.SetOrientationModeToQuaternion()
        mapper.SetScaleArray("scale")
        mapper.SetScaleModeToScaleByMagnitude()
        mapper.ScalingOn()
        mapper.ScalarVisibilityOff()
        actor = vtk.vtkActor()
        actor.SetMapper(mapper)
        actor.GetProperty().SetColor(*colour)
        actor.GetProperty().SetInterpolationToGouraud()
        return actor


def _quaternions(rot: np.ndarray) -> np.ndarray:
    """(w, x, y, z) unit quaternions (VTK's order) of rotation matrices (n, 3, 3)."""
    return Rotation.from_matrix(rot).as_quat()[:, [3, 0, 1, 2]]


class _Pygfx:
    """pygfx drawing into a texture (``WgpuRenderer(texture)``, read back with ``snapshot()``):
    errors raise, and no window system is involved. Its default post-processing antialiasing
    (DDAA) is off everywhere; thumbnails are antialiased by drawing at twice the resolution and
    filtering down (pygfx's default on an ordinary display), scenes are not antialiased."""

    name = "pygfx"

    def __init__(self, mods: dict[str, ModuleType]) -> None:
        self.gfx, self.wgpu = mods["pygfx"], mods["wgpu"]
        self.version = f"pygfx {self.gfx.__version__}, wgpu {self.wgpu.__version__}"
        engine = self.gfx.renderers.wgpu
        if not os.environ.get("PYGFX_WGPU_ADAPTER_NAME"):   # else the adapter the user named to pygfx
            adapter = self.wgpu.gpu.request_adapter_sync(power_preference="high-performance")   # pygfx's choice
            if adapter is None:
                raise RuntimeError("wgpu found no adapter")
            if "float32-filterable" not in adapter.features:
                # pygfx asks for it by default (for filtered float textures, which these meshes do
                # not use); wgpu's OpenGL backend on llvmpipe (no Vulkan driver) does not offer it
                engine.enable_wgpu_features("!float32-filterable")
            engine.select_adapter(adapter)
        shared = engine.get_shared()   # raises when no device can be made
        info = shared.adapter.info
        self.renderer = f"{info.get('device', '?')} ({info.get('backend_type', '?')}, {info.get('adapter_type', '?')})"
        self.device = shared.device
        self.max_binding = int(shared.device.limits["max-storage-buffer-binding-size"])

    def _renderer(self, size: tuple[int, int], ssaa: bool) -> Any:
        target = self.gfx.Texture(dim=2, size=(size[0], size[1], 1), format="rgba8unorm",
                                  usage=self.wgpu.TextureUsage.COPY_SRC)   # to read it back
        return self.gfx.WgpuRenderer(target, pixel_ratio=2 if ssaa else 1, ppaa="none",
                                     pixel_filter="mitchell" if ssaa else "nearest")

    def _read(self, renderer: Any) -> np.ndarray:
        """The target texture (what a flush wrote, filtered to the target's size) read back;
        ``snapshot()`` would read the internal, not yet filtered image."""
        texture = renderer.target._wgpu_default_view.texture
        w, h = texture.size[:2]
        data = self.device.queue.read_texture({"texture": texture, "mip_level": 0, "origin": (0, 0, 0)},
                                              {"offset": 0, "bytes_per_row": 4 * w, "rows_per_image": h},
                                              (w, h, 1))
        return np.frombuffer(data, np.uint8).reshape(h, w, 4)

    def _camera(self, setup: CameraSetup, size: tuple[int, int]) -> Any:
        aspect = size[0] / size[1]
        # pygfx's fov spans the mean of width and height; leafview's is vertical
        fov = 2.0 * math.degrees(math.atan(math.tan(math.radians(setup.fov_deg) / 2.0) * (1.0 + aspect) / 2.0))
        cam = self.gfx.PerspectiveCamera(fov, aspect, depth_range=(setup.near, setup.far))
        cam.local.position = setup.eye
        cam.world.reference_up = setup.up
        cam.look_at(setup.target)
        return cam

    def _world(self) -> Any:
        scene = self.gfx.Scene()
        scene.add(self.gfx.AmbientLight(), self.gfx.DirectionalLight())
        return scene

    def _geometry(self, positions: np.ndarray, normals: np.ndarray, triangles: np.ndarray,
                  colours: np.ndarray | None = None) -> Any:
        kw: dict[str, Any] = {}
        if colours is not None:
            kw["colors"] = colours
        return self.gfx.Geometry(positions=np.asarray(positions, np.float32), normals=np.asarray(normals, np.float32),
                                 indices=np.asarray(triangles, np.int32), **kw)

    def _material(self, colour: tuple[float, float, float] | None = None) -> Any:
        if colour is None:
            return self.gfx.MeshPhongMaterial(color_mode="vertex", side="both")
        return self.gfx.MeshPhongMaterial(color=colour, side="both")

    def thumbnails(self, meshes: Sequence[ThumbnailMesh]) -> tuple[Callable[[], list[np.ndarray]],
                                                                    Callable[[], list[np.ndarray]], Callable[[], None]]:
        """(one call per leaf, batched, close): per leaf one renderer kept and a new mesh each
        draw; batched one target with a viewport per leaf, one readback."""
        w, h = THUMB_SIZE
        gfx = self.gfx
        one = self._renderer(THUMB_SIZE, True)
        cols = min(len(meshes), 32)
        rows = -(-len(meshes) // cols)
        many = self._renderer((cols * w, rows * h), True)

        def world(m: ThumbnailMesh) -> tuple[Any, Any]:
            scene = self._world()
            scene.add(gfx.Mesh(self._geometry(m.vertices, m.normals, m.triangles), self._material(m.colour)))
            return scene, self._camera(camera_setup(m.camera), THUMB_SIZE)

        def single() -> list[np.ndarray]:
            out = []
            for m in meshes:
                one.render(*world(m))
                out.append(self._read(one))
            return out

        def batched() -> list[np.ndarray]:
            for i, m in enumerate(meshes):
                many.render(*world(m), rect=((i % cols) * w, (i // cols) * h, w, h), flush=False)
            many.flush()
            atlas = self._read(many)
            return [atlas[(i // cols) * h:(i // cols + 1) * h, (i % cols) * w:(i % cols + 1) * w].copy()
                    for i in range(len(meshes))]

        return single, batched, lambda: None

    def scene(self, meshes: SceneMeshes, camera: Camera, instanced: bool) -> _Frame:
        gfx = self.gfx
        renderer = self._renderer(SCENE_SIZE, False)
        world = self._world()
        if instanced:
            for mesh, colour, mats in zip(meshes.local, meshes.colours, meshes.matrices):
                obj = gfx.InstancedMesh(self._geometry(mesh.vertices, mesh.normals, mesh.indices.reshape(-1, 3)),
                                        self._material(colour), len(mats))
                obj.instance_buffer.data["matrix"][:] = np.transpose(mats, (0, 2, 1)).astype(np.float32)
                obj.instance_buffer.update_full()
                world.add(obj)
        else:
            # as few meshes as the device's storage-buffer binding limit allows (a 10⁵-leaf mesh's
            # index buffer alone is 307 MB, over wgpu's default 128 MiB)
            per_leaf = max(max(m.indices.size * 4, len(m.vertices) * 16) for m in meshes.local)
            for part in meshes.split(max(1, self.max_binding // per_leaf)):
                pos, nrm, rgb, tri = part.merged()
                world.add(gfx.Mesh(self._geometry(pos, nrm, tri, rgb.astype(np.float32) / 255.0), self._material()))
                del pos, nrm, rgb, tri
        cam = self._camera(camera_setup(camera), SCENE_SIZE)

        def draw() -> np.ndarray:
            renderer.render(world, cam)
            return self._read(renderer)

        draw()   # uploads everything
        return _Frame(draw)


# -- the worker process -------------------------------------------------------------------------------
def _import_peer(peer: str) -> Any:
    """The peer's renderer, or a status string saying why there is none."""
    if peer == "pyvista" and not os.environ.get("DISPLAY"):
        # without a display VTK's default (X) window fails first and falls back to EGL
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    mods: dict[str, ModuleType] = {}
    for name in MODULES[peer]:
        try:
            mods[name] = importlib.import_module(name)
        except ImportError as exc:
            return f"not installed ({exc.name or name}): pip install 'leafview[peers]'"
    try:
        return (_PyVista if peer == "pyvista" else _Pygfx)(mods)
    except Exception as exc:   # no driver, no adapter: reported, not fatal
        # one line: wgpu's validation errors span several ("Caused by: ..." names the cause)
        lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
        cause = [line for line in lines[1:] if not line.startswith(("Caused by", "In wgpu"))][:1]
        return f"unavailable: {type(exc).__name__}: {'; '.join(lines[:1] + cause)}"


def _timed(fn: Callable[[], Any]) -> tuple[float, Any]:
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def serve(peer: str, inbox: Any, outbox: Any) -> None:
    """The worker loop of one peer: answers ``(command, *args)`` messages from ``inbox`` on
    ``outbox`` with ``("ok", result)`` or ``("error", message)``. The first message sent is the peer's info
    (``status``, ``version``, ``renderer``); a peer that cannot start sends only that.

    Commands: ``("thumbnails", leaves, passes)`` sets up the thumbnail renderers;
    ``("thumbnail_run", "single" | "batched")`` draws them all: (seconds, images (n, h, w, 4));
    ``("scene", leaves, camera, "merged" | "instanced")`` sets up a scene and draws it once;
    ``("frame", "merged" | "instanced")``: (seconds, image); ``("close",)`` frees everything;
    ``("quit",)``."""
    obj = _import_peer(peer)
    if isinstance(obj, str):
        outbox.send({"status": obj})
        return
    outbox.send({"status": "ok", "version": obj.version, "renderer": obj.renderer})   # VTK's: known once it drew
    thumbs: tuple[Callable[[], list[np.ndarray]], Callable[[], list[np.ndarray]], Callable[[], None]] | None = None
    frames: dict[str, _Frame] = {}
    meshes: tuple[int, SceneMeshes] | None = None

    def close() -> None:
        nonlocal thumbs
        if thumbs is not None:
            thumbs[2]()
            thumbs = None
        while frames:
            frames.popitem()[1].close()

    while True:
        try:
            cmd, *args = inbox.recv()
        except EOFError:   # the benchmark went away
            break
        if cmd == "quit":
            break
        try:
            result: Any = None
            if cmd == "thumbnails":
                leaves = thumbnail_params(args[0]) * args[1]
                thumbs = obj.thumbnails([thumbnail_mesh(p) for p in leaves])
                result = obj.renderer
            elif cmd == "thumbnail_run":
                assert thumbs is not None, "thumbnails were not set up"
                dt, images = _timed(thumbs[0] if args[0] == "single" else thumbs[1])
                result = (dt, np.stack(images))
            elif cmd == "scene":
                leaves, camera, kind = args
                if meshes is None or meshes[0] != leaves:
                    meshes = (leaves, scene_meshes(peer_scene(leaves)))
                frames[kind] = obj.scene(meshes[1], camera, kind == "instanced")
                result = obj.renderer
            elif cmd == "frame":
                result = _timed(frames[args[0]].draw)
            elif cmd == "close":
                close()
                meshes = None
            else:
                raise ValueError(f"unknown command {cmd!r}")
            outbox.send(("ok", result))
        except Exception as exc:
            outbox.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}"))
    close()


def main(argv: Sequence[str]) -> None:
    """``python -m leafview.bench.peer_renderers PEER IN_FD OUT_FD``: :func:`serve` on two pipe
    ends inherited from :class:`leafview.bench.peers.PeerProcess`."""
    peer, fd_in, fd_out = argv[0], int(argv[1]), int(argv[2])
    serve(peer, Connection(fd_in, writable=False), Connection(fd_out, readable=False))


if __name__ == "__main__":
    main(sys.argv[1:])
