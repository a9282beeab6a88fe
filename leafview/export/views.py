"""Synthetic RGB-D views of a scene with exact ground truth: what a capture pipeline (segmenting
dense foliage and fitting Ω to the points, Chaurasia & Beardsley 2017, §§4-5) is tested on.

:func:`render_views` draws a scene from ``N`` cameras on a ring around its bounding sphere
(:func:`leafview.scene.camera.orbit_cameras`) and writes one transaction
(:func:`leafview.atomic.outputs`) into a folder. View ``NAME`` (``view_000``, ``view_001``, ...)
is the files

=======================  ==========================================================================
``NAME.color.png``       8-bit sRGB RGB: the picture, 4× multisampled, over the opaque background
                         :data:`BACKGROUND` (0.05, 0.05, 0.06), a neutral dark grey, taken as sRGB
                         values: the bytes (13, 13, 15)
``NAME.depth.npy``       float32 (h, w): distance along the optical axis in world units, 0 = no data
                         (the only file the optional sensor noise changes)
``NAME.instance.png``    16-bit grey: the leaf's index in ``truth.leaves.json`` + 1, 0 = background
                         and stems
``NAME.normal.exr``      float32 RGB: world-space unit normal of the side the camera sees, 0 background
``NAME.json``            ``width``, ``height``, ``K`` (3×3), ``world_from_camera`` (4×4), ``convention``
                         ``"opencv"`` (:func:`leafview.scene.camera.intrinsics`), then ``name``,
                         ``near``, ``far``, ``azimuth_deg``, ``elevation_deg`` and ``files``
=======================  ==========================================================================

(only the AOVs asked for; the JSON always). Stems hide the leaves behind them and have depth and
normals, but instance 0: a pixel with ``instance == 0`` and ``depth > 0`` is a stem. Beside the
views lie ``truth.leaves.json`` (every leaf of the scene, placed, in instance order:
:meth:`Scene.placed_leaves <leafview.scene.spec.Scene.placed_leaves>`) and ``views.json`` (the
manifest: format, leafview version, view names, size, AOVs, cameras, noise settings, seed,
GL_RENDERER).

Labels and depth come from one single-sample pass (:func:`leafview.gpu.aov.render_aovs`): each
pixel holds the nearest fragment at its centre. Every leaf is drawn at :data:`VIEW_GRID` with
culling and level of detail off, so no leaf in view is dropped and the drawn surface stays within
about 0.1 % of a leaf length of the analytic one (the chords of a 17×33 grid; rippled leaves up
to about 0.6 %), whatever the image size. (A varied scene's bent leaves droop with their species'
profile, as the scene draws them; :func:`leafview.scene.spec.bend_deviation` measures how far that
is from each leaf's own solve, which ``truth.leaves.json`` describes.)

**Sensor noise** (:func:`add_sensor_noise`, seeded per view, depth file only): Gaussian noise along
the optical axis with ``σ(z) = sigma · (z / z_ref)²`` (the quadratic growth of triangulating depth
sensors), ``z_ref`` being the cameras' distance to the scene's centre, so ``--depth-noise`` is the
standard deviation in world units at the middle of the scene; and with ``holes``, dropouts where
the surface is seen edge-on (probability rising linearly from 0 at :data:`GRAZING_DEG` [0] = 75°
between normal and view ray to 1 at 85°) plus :data:`DROPOUT` of all other pixels at random.

**The output folder** must be new, empty, or a previous views folder (its ``views.json`` says
so); a previous run's view files that this run does not write again (more views then, other AOVs)
are removed after the commit, so the folder always matches its manifest. Anything else is refused
before any work.
"""

from __future__ import annotations

import io
import json
import os
import re
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import moderngl
import numpy as np
import OpenImageIO as oiio
from numpy.typing import ArrayLike, NDArray

from leafview._version import __version__
from leafview.atomic import (
    atomic_output,
    check_folder,
    failed_write,
    is_temp_name,
    output_error,
    outputs,
    write_bytes,
    write_text,
)
from leafview.core.io import save_leaves
from leafview.core.params import LeafParams
from leafview.errors import ImageWriteError, UsageError
from leafview.gpu.aov import AovImages, render_aovs
from leafview.gpu.resources import GpuResources
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.scene.camera import (
    RING_ELEVATIONS,
    RING_FOV_DEG,
    Camera,
    camera_from_intrinsics,
    intrinsics,
    orbit_cameras,
    ring_angles,
)
from leafview.scene.spec import Scene, scene_from_leaves

__all__ = ["VIEW_AOVS", "VIEW_GRID", "BACKGROUND", "GRAZING_DEG", "DROPOUT", "MANIFEST", "TRUTH", "FORMAT",
           "SUFFIXES", "MAX_VIEWS", "ViewsReport", "render_views", "render_instance_ids", "add_sensor_noise",
           "grazing_angles", "check_aovs", "check_views_folder", "view_name", "write_pixels", "camera_document",
           "scene_sphere"]

VIEW_AOVS: tuple[str, ...] = ("rgb", "depth", "instance", "normal")
SUFFIXES = {"rgb": ".color.png", "depth": ".depth.npy", "instance": ".instance.png", "normal": ".normal.exr"}
VIEW_GRID: tuple[int, int] = (17, 33)
BACKGROUND: tuple[float, float, float] = (0.05, 0.05, 0.06)
SAMPLES = 4
GRAZING_DEG: tuple[float, float] = (75.0, 85.0)
DROPOUT = 0.002
MANIFEST, TRUTH, FORMAT = "views.json", "truth.leaves.json", "leafview-views"
MAX_VIEWS = 1000
MAX_INSTANCES = 0xFFFF
_VIEW_FILE = re.compile(r"^view_\d{3,}\.(color\.png|depth\.npy|instance\.png|normal\.exr|json)$")
_SETTINGS = CullSettings(cull=False, lod=False)   # every leaf, finest grid: the truth, not a preview


def view_name(index: int) -> str:
    return f"view_{index:03d}"


# -- pixels and cameras to files ------------------------------------------------------------------
def write_pixels(path: Path, data: NDArray[Any], fmt: str, channels: Sequence[str]) -> None:
    """Write (h, w, c) ``data`` (``fmt``: OpenImageIO's "uint8", "uint16" or "float") to ``path``
    atomically; the file is read back and must give the same pixels."""
    h, w, c = data.shape
    spec = oiio.ImageSpec(w, h, c, fmt)
    spec.channelnames = tuple(channels)
    spec.attribute("Software", f"leafview {__version__}")
    spec.attribute("DateTime", "")    # OpenImageIO stamps EXR files with the time unless given an empty one
    if path.suffix == ".exr":
        spec.attribute("compression", "zip")
        spec.attribute("oiio:ColorSpace", "Raw")
    elif fmt == "uint8":
        spec.attribute("oiio:ColorSpace", "sRGB")
    else:
        spec.attribute("oiio:ColorSpace", "Raw")
    pixels = np.ascontiguousarray(data)

    def verify(tmp: Path) -> None:
        inp = oiio.ImageInput.open(str(tmp))
        if inp is None:
            raise _failure(path, "the written image cannot be read back", oiio.geterror())
        try:
            back = inp.read_image(fmt)
        finally:
            inp.close()
        if back is None or back.shape != pixels.shape or not np.array_equal(back, pixels):
            raise _failure(path, "the written image reads back differently", "")

    with atomic_output(path, verify=verify) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise ImageWriteError(f"{path}: cannot create a writer: {oiio.geterror()}")
        ok = out.open(str(tmp), spec) and out.write_image(pixels)
        detail = "" if ok else out.geterror()
        if not out.close() and ok:
            ok, detail = False, out.geterror()
        if not ok:
            raise _failure(path, "writing failed", detail)


def _failure(path: Path, what: str, detail: str) -> Exception:
    return failed_write(path, f"{what}: {detail}") or ImageWriteError(f"{path}: {what}: {detail}".rstrip(": "))


def camera_document(camera: Camera, size: tuple[int, int], extra: Mapping[str, Any] | None = None) -> str:
    """The camera as JSON: ``width``, ``height``, ``K`` and ``world_from_camera`` (OpenCV
    convention, :func:`~leafview.scene.camera.intrinsics`), ``convention``; then ``extra``'s keys."""
    k, world_from_camera = intrinsics(camera, size)
    doc = {"width": size[0], "height": size[1], "K": k.tolist(), "world_from_camera": world_from_camera.tolist(),
           "convention": "opencv", **(extra or {})}
    return "{\n" + ",\n".join(f" {json.dumps(k)}: {json.dumps(v)}" for k, v in doc.items()) + "\n}\n"


def _npy_bytes(array: NDArray[Any]) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(array), allow_pickle=False)
    return buf.getvalue()


def _clip_planes(camera: Camera) -> tuple[float, float]:
    p = camera.proj
    return float(p[2, 3] / (p[2, 2] - 1.0)), float(p[2, 3] / (p[2, 2] + 1.0))


# -- sensor noise (numpy) -------------------------------------------------------------------------
def grazing_angles(normal: NDArray[np.floating], k: ArrayLike, world_from_camera: ArrayLike) -> NDArray[np.float64]:
    """(h, w) angle in degrees between each pixel's world-space ``normal`` (h, w, 3) and its view
    ray through the pixel centre (OpenCV ``k``, ``world_from_camera``): 0 head-on, 90 edge-on
    (the sign of the normal does not matter); NaN where the normal is 0 (background)."""
    n = np.asarray(normal, np.float64)
    h, w = n.shape[:2]
    kk, m = np.asarray(k, np.float64), np.asarray(world_from_camera, np.float64)
    jj, ii = np.mgrid[0:h, 0:w].astype(np.float64)
    pix = np.stack([ii, jj, np.ones_like(ii)], axis=-1)
    rays = pix @ np.linalg.inv(kk).T @ m[:3, :3].T
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    length = np.linalg.norm(n, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(np.einsum("hwj,hwj->hw", n, rays)) / length
    return np.where(length > 0, np.degrees(np.arccos(np.clip(cos, 0.0, 1.0))), np.nan)


def add_sensor_noise(depth: NDArray[np.floating], normal: NDArray[np.floating] | None, k: ArrayLike,
                     world_from_camera: ArrayLike, *, sigma: float, holes: bool, rng: np.random.Generator,
                     z_ref: float = 1.0, grazing: tuple[float, float] = GRAZING_DEG,
                     dropout: float = DROPOUT) -> NDArray[np.float32]:
    """A noisy copy of ``depth`` (h, w; 0 = no data), as a depth sensor would measure it.

    * With ``holes``: a pixel whose ``normal`` makes an angle θ with its view ray
      (:func:`grazing_angles`) drops out (depth 0) with probability ``(θ - grazing[0]) /
      (grazing[1] - grazing[0])`` clipped to [0, 1], and any pixel with probability ``dropout``.
      Pixels with depth but no normal (none in leafview's images) only get the random dropouts.
    * ``sigma > 0``: each remaining pixel gets Gaussian noise with standard deviation
      ``sigma · (z / z_ref)²`` (world units; the quadratic growth of stereo and structured-light
      sensors), added to its depth; a pixel pushed to ``z ≤ 0`` loses its depth.

    Pixels without depth stay 0. ``rng`` draws one uniform and one normal field of the image's
    size whatever the settings are, so the same seed gives the same pixels. ``sigma = 0`` without
    holes returns the depth unchanged (as float32)."""
    z = np.asarray(depth, np.float64)
    if z.ndim != 2:
        raise ValueError(f"depth must be an (h, w) image, got shape {z.shape}")
    if not (np.isfinite(sigma) and sigma >= 0.0):
        raise ValueError(f"the depth noise must be a finite number ≥ 0, got {sigma}")
    if not (np.isfinite(z_ref) and z_ref > 0.0):
        raise ValueError(f"z_ref must be positive, got {z_ref}")
    lo, hi = (float(g) for g in grazing)
    if not 0.0 <= lo < hi <= 90.0:
        raise ValueError(f"grazing angles must satisfy 0 ≤ start < end ≤ 90, got {grazing}")
    if not 0.0 <= dropout <= 1.0:
        raise ValueError(f"dropout must be a probability, got {dropout}")
    u = rng.random(z.shape)
    g = rng.standard_normal(z.shape)
    valid = z > 0
    out = z.copy()
    if holes:
        p = np.full(z.shape, float(dropout))
        if normal is not None:
            if np.shape(normal)[:2] != z.shape:
                raise ValueError(f"normal image {np.shape(normal)} does not match depth {z.shape}")
            theta = grazing_angles(normal, k, world_from_camera)
            ramp = np.clip((np.nan_to_num(theta, nan=0.0) - lo) / (hi - lo), 0.0, 1.0)
            p = np.maximum(p, ramp)
        valid &= ~(u < p)
    if sigma > 0.0:
        out = out + g * float(sigma) * (z / float(z_ref)) ** 2
        valid &= out > 0
    out[~valid] = 0.0
    return out.astype(np.float32)


# -- checks ---------------------------------------------------------------------------------------
def check_aovs(aovs: Iterable[str] | str) -> tuple[str, ...]:
    """The AOV names in :data:`VIEW_AOVS` order, duplicates dropped; UsageError naming an unknown
    name or an empty list."""
    names = [aovs] if isinstance(aovs, str) else [str(a) for a in aovs]
    bad = [n for n in names if n not in VIEW_AOVS]
    if bad:
        raise UsageError(f"unknown AOV {bad[0]!r} (choose from {', '.join(VIEW_AOVS)})")
    if not names:
        raise UsageError(f"no AOV asked for (choose from {', '.join(VIEW_AOVS)})")
    return tuple(a for a in VIEW_AOVS if a in names)


def check_views_folder(out: str | os.PathLike[str], flag: str = "-o") -> Path:
    """``out`` as a views folder: absent, empty, or a previous views folder (a ``views.json`` of
    :data:`FORMAT`); else UsageError (a file, a folder holding anything else: exit 2, nothing
    written). Temporary files a killed run left there are removed."""
    folder = check_folder(out, flag)
    if not folder.is_dir():
        return folder
    others = [e.name for e in os.scandir(folder) if not is_temp_name(e.name)]
    if not others:
        return folder
    manifest = folder / MANIFEST
    try:
        doc = json.loads(manifest.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        doc = None
    if not (isinstance(doc, dict) and doc.get("format") == FORMAT):
        raise UsageError(f"{flag} {folder}: the folder is not empty and is not a previous views folder (no "
                         f"{MANIFEST} of leafview views); give a new or empty folder")
    return folder


def _check_options(views: int, size: tuple[int, int], depth_noise: float, holes: bool, aovs: tuple[str, ...],
                   scene: Scene, seed: int) -> None:
    if not (isinstance(seed, (int, np.integer)) and 0 <= int(seed) < 2**63):
        raise UsageError(f"the seed must be a whole number in 0..2**63 - 1, got {seed!r}")
    if not 1 <= int(views) <= MAX_VIEWS:
        raise UsageError(f"views must be between 1 and {MAX_VIEWS}, got {views}")
    if int(size[0]) < 1 or int(size[1]) < 1:
        raise UsageError(f"image size must be positive, got {size}")
    if not (np.isfinite(depth_noise) and depth_noise >= 0.0):
        raise UsageError(f"depth noise must be a finite number ≥ 0, got {depth_noise}")
    if (depth_noise > 0.0 or holes) and "depth" not in aovs:
        raise UsageError("depth noise and holes change the depth images: ask for the depth AOV too")
    if "instance" in aovs and len(scene) > MAX_INSTANCES:
        raise UsageError(f"{len(scene):,} leaves do not fit 16-bit instance images (at most {MAX_INSTANCES:,})")


# -- rendering ------------------------------------------------------------------------------------
def scene_sphere(renderer: SceneRenderer) -> tuple[NDArray[np.float64], float]:
    """(centre, radius): a world-space sphere holding every leaf and stem of ``renderer``'s scene,
    from the leaves' culling spheres (every drawn vertex is inside them) and the stem vertices."""
    scene = renderer.scene
    sph = renderer.cull_rows[scene.species_id]["sphere"].astype(np.float64)
    m = scene.matrices
    centres = np.einsum("nij,nj->ni", m[:, :3, :3], sph[:, :3]) + m[:, :3, 3]
    radii = sph[:, 3] * np.linalg.norm(m[:, :3, :3], axis=1).max(axis=1)
    if scene.stems is not None and len(scene.stems[0]):
        stem_pts = np.asarray(scene.stems[0], np.float64).reshape(-1, 3)
        centres = np.concatenate([centres, stem_pts])
        radii = np.concatenate([radii, np.zeros(len(stem_pts))])
    lo, hi = (centres - radii[:, None]).min(axis=0), (centres + radii[:, None]).max(axis=0)
    centre = (lo + hi) / 2.0
    return centre, float((np.linalg.norm(centres - centre, axis=1) + radii).max())


@dataclass
class ViewsReport:
    """What :func:`render_views` wrote."""

    out: Path
    views: list[str]
    size: tuple[int, int]
    aovs: tuple[str, ...]
    leaves: int
    gl_renderer: str
    seconds: float
    files: list[Path] = field(default_factory=list)      # committed, views.json last
    removed: list[Path] = field(default_factory=list)    # a previous run's view files not written again
    labelled: float = 0.0                                # mean fraction of pixels with a leaf


def render_views(ctx: moderngl.Context, scene: Scene, out: str | os.PathLike[str], *, views: int,
                 size: tuple[int, int], aovs: Iterable[str] = VIEW_AOVS, depth_noise: float = 0.0,
                 holes: bool = False, seed: int = 0, elevations: Sequence[float] = RING_ELEVATIONS,
                 grid: tuple[int, int] = VIEW_GRID, resources: GpuResources | None = None,
                 progress: Callable[[int], object] | None = None) -> ViewsReport:
    """Render ``views`` views of ``scene`` at ``size`` = (w, h) into the folder ``out`` (the layout
    of the module docstring), in one transaction: every file, or none and no folder made.

    Cameras: :func:`~leafview.scene.camera.orbit_cameras` around :func:`scene_sphere`, vertical
    field of view :data:`~leafview.scene.camera.RING_FOV_DEG`, ``elevations`` alternating.
    ``depth_noise`` and ``holes``: :func:`add_sensor_noise` with ``np.random.default_rng([seed,
    view index])``. ``resources``: shared GPU resources (None: the renderer makes its own).
    ``progress(1)`` after each view. Called inside a caller's :func:`~leafview.atomic.outputs`
    block, the files join that transaction and a previous run's extra view files are left alone.

    Raises UsageError for bad options or an output folder that is not new, empty or a previous
    views folder (before anything is drawn), :class:`~leafview.errors.GpuLimitError` for a size the
    context cannot hold, OutputError when writing fails (nothing is left behind)."""
    started = time.perf_counter()
    names = check_aovs(aovs)
    size = (int(size[0]), int(size[1]))
    _check_options(views, size, depth_noise, holes, names, scene, seed)
    try:
        angles = ring_angles(views, elevations)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    folder = check_views_folder(out)
    labels = tuple(dict.fromkeys([*names, *(("depth", "normal") if holes else ())]))
    view_names = [view_name(i) for i in range(views)]
    fractions = []
    with SceneRenderer(ctx, scene, grids=(grid,), resources=resources) as renderer:
        centre, radius = scene_sphere(renderer)
        cameras = orbit_cameras((centre, radius), views, size, elevations)
        z_ref = float(np.linalg.norm(cameras[0].eye[:3] - centre))
        with outputs() as tx:
            for i, (name, camera, (az, el)) in enumerate(zip(view_names, cameras, angles)):
                img = render_aovs(renderer, camera, size, labels, settings=_SETTINGS, samples=SAMPLES,
                                  background=(*BACKGROUND, 1.0))
                if img.depth is not None and (depth_noise > 0.0 or holes):
                    k, world_from_camera = intrinsics(camera, size)
                    img.depth = add_sensor_noise(img.depth, img.normal, k, world_from_camera, sigma=depth_noise,
                                                 holes=holes, rng=np.random.default_rng([int(seed), i]), z_ref=z_ref)
                _write_view(folder, name, names, img, camera, size, {"azimuth_deg": az, "elevation_deg": el})
                if img.instance is not None:
                    fractions.append(float(np.mean(img.instance > 0)))
                if progress is not None:
                    progress(1)
            save_leaves(scene.placed_leaves(), folder / TRUTH)
            gl_renderer = str(ctx.info["GL_RENDERER"])
            manifest = {
                "format": FORMAT, "version": 1, "leafview": __version__, "views": view_names,
                "width": size[0], "height": size[1], "aovs": list(names),
                "files": {a: SUFFIXES[a] for a in names}, "truth": TRUTH, "leaves": len(scene),
                "depth_units": "world units along the optical axis, 0 = no data",
                "background": list(BACKGROUND), "grid": list(grid), "seed": int(seed),
                "noise": {"depth_sigma": float(depth_noise), "model": "sigma * (z / z_ref)^2", "z_ref": z_ref,
                          "holes": bool(holes), "grazing_deg": list(GRAZING_DEG) if holes else None,
                          "dropout": DROPOUT if holes else 0.0},
                "cameras": {"fov_deg": RING_FOV_DEG, "elevations_deg": [float(e) for e in elevations],
                            "centre": centre.tolist(), "radius": radius, "distance": z_ref},
                "gl_renderer": gl_renderer,
            }
            write_text(folder / MANIFEST, json.dumps(manifest, indent=1) + "\n")
    removed = _remove_stale(folder, {p.name for p in tx.committed}) if tx.committed else []
    return ViewsReport(folder, view_names, size, names, len(scene), gl_renderer, time.perf_counter() - started,
                       list(tx.committed), removed, float(np.mean(fractions)) if fractions else 0.0)


def _write_view(folder: Path, name: str, names: tuple[str, ...], img: AovImages, camera: Camera,
                size: tuple[int, int], extra: dict[str, Any]) -> None:
    """The files of view ``name``: the AOVs of ``names`` and the camera JSON (staged)."""
    files = {a: name + SUFFIXES[a] for a in names}
    if "rgb" in names and img.rgb is not None:
        write_pixels(folder / files["rgb"], np.ascontiguousarray(img.rgb[..., :3]), "uint8", ("R", "G", "B"))
    if "depth" in names and img.depth is not None:
        write_bytes(folder / files["depth"], _npy_bytes(img.depth.astype(np.float32)))
    if "instance" in names and img.instance is not None:
        write_pixels(folder / files["instance"], img.instance.astype(np.uint16)[..., None], "uint16", ("Y",))
    if "normal" in names and img.normal is not None:
        write_pixels(folder / files["normal"], img.normal.astype(np.float32), "float", ("R", "G", "B"))
    near, far = _clip_planes(camera)
    doc = {"name": name, "near": near, "far": far, **extra, "files": files}
    write_text(folder / f"{name}.json", camera_document(camera, size, doc))


def _remove_stale(folder: Path, written: set[str]) -> list[Path]:
    """Remove the view files (names of this module's pattern only) of a previous run in
    ``folder`` that this run did not write; returns them."""
    removed = []
    for entry in os.scandir(folder):
        if _VIEW_FILE.match(entry.name) and entry.name not in written and entry.is_file(follow_symlinks=False):
            try:
                os.unlink(entry.path)
            except FileNotFoundError:
                continue
            except OSError as exc:
                raise output_error(exc, entry.path) from None
            removed.append(Path(entry.path))
    return removed


def render_instance_ids(ctx: moderngl.Context, leaves: Sequence[LeafParams], k: ArrayLike,
                        world_from_camera: ArrayLike, size: tuple[int, int], *, grid: tuple[int, int] = VIEW_GRID,
                        resources: GpuResources | None = None) -> NDArray[np.uint32]:
    """(h, w) uint32 instance image of ``leaves`` (each at its transform; index + 1, 0 where no
    leaf is) seen by the OpenCV camera ``k``, ``world_from_camera`` at ``size`` = (w, h): a view
    read from disk, drawn again with other leaves (fitted ones, to compare with the truth).

    The clip planes come from the leaves' culling spheres along the optical axis (a leaf partly
    behind the camera is cut at a near plane of 1e-4 of the far one); all leaves behind the
    camera give an empty image. Every leaf is drawn at ``grid``, without culling."""
    w, h = int(size[0]), int(size[1])
    if not leaves:
        return np.zeros((h, w), np.uint32)
    m = np.asarray(world_from_camera, np.float64)
    with SceneRenderer(ctx, scene_from_leaves(list(leaves)), grids=(grid,), resources=resources) as renderer:
        scene = renderer.scene
        sph = renderer.cull_rows[scene.species_id]["sphere"].astype(np.float64)
        mats = scene.matrices
        centres = np.einsum("nij,nj->ni", mats[:, :3, :3], sph[:, :3]) + mats[:, :3, 3]
        radii = sph[:, 3] * np.linalg.norm(mats[:, :3, :3], axis=1).max(axis=1)
        z = (centres - m[:3, 3]) @ m[:3, 2]
        far = float((z + radii).max()) * 1.01
        if not far > 0.0:
            return np.zeros((h, w), np.uint32)
        near = max(float((z - radii).min()) * 0.99, far * 1e-4)
        camera = camera_from_intrinsics(k, m, (w, h), near, far)
        ids = render_aovs(renderer, camera, (w, h), ("instance",), settings=_SETTINGS).instance
    assert ids is not None
    return ids
