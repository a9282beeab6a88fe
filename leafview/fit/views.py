"""RGB-D views on disk and their 3D points: the input of the dense-foliage capture (Chaurasia &
Beardsley 2017, sec. 4).

A view named ``NAME`` in a folder is

* ``NAME.json``: ``width``, ``height``, ``K`` (3×3 pinhole intrinsics, pixels) and
  ``world_from_camera`` (4×4 rigid motion), in the OpenCV convention: camera x right, y down,
  z forward; the centre of pixel (column ``i``, row ``j``) is at image coordinates ``(i, j)``,
  so a camera point ``X`` lands at ``(K @ X)[:2] / X[2]``;
* ``NAME.color.png``: 8-bit sRGB colour (RGB, or RGBA whose alpha is ignored, or grey);
* ``NAME.depth.npy`` (float (h, w)) or ``NAME.depth.exr`` (its first channel): metres, or any
  unit the cameras use, along the optical axis; 0 means no data;
* ``NAME.instance.png`` (optional, 16-bit): leaf index + 1, 0 background. The truth of a
  rendered view, for scoring only; the capture never reads it.

Other files (``truth.leaves.json``, ``views.json``, a ``NAME.normal.exr``) may sit beside them
and are ignored. Any RGB-D sensor's frames can be captured once written this way: only colour,
depth and the json are required.

Every error is a :class:`~leafview.errors.UsageError` (or a :class:`~leafview.errors.ParamError`
for a json's syntax) whose message starts with the file it is about.
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio
from numpy.typing import NDArray

from leafview.errors import UsageError
from leafview.inputs import read_bytes, read_json

__all__ = ["View", "read_view", "read_views", "view_names", "check_views", "backproject", "MAX_VIEW_PIXELS"]

MAX_VIEW_PIXELS = 64 * 2**20      # width × height of one view (a 8192 × 8192 image)
_RIGID_TOL = 1e-5


@dataclass(frozen=True, eq=False)
class View:
    """One RGB-D frame: ``color`` (h, w, 3) uint8 sRGB, ``depth`` (h, w) float32 along the optical
    axis (0: no data), pinhole intrinsics ``k`` (3×3) and pose ``world_from_camera`` (4×4), both
    float64 in the OpenCV convention (see the module docstring); ``instance`` (h, w) uint32 is the
    leaf index + 1 of each pixel where the truth is known (rendered views), else None."""

    name: str
    color: NDArray[np.uint8]
    depth: NDArray[np.float32]
    k: NDArray[np.float64]
    world_from_camera: NDArray[np.float64]
    instance: NDArray[np.uint32] | None = None

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return int(self.depth.shape[1]), int(self.depth.shape[0])

    @property
    def eye(self) -> NDArray[np.float64]:
        """The camera centre in world coordinates."""
        return np.asarray(self.world_from_camera[:3, 3], np.float64)

    def points(self, mask: NDArray[np.bool_] | None = None) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """World points of the pixels with depth (and ``mask``, (h, w) bool, where given): ``(points
        (M, 3), flat pixel indices (M,))``, in row-major pixel order (index = row · width + column)."""
        return backproject(self.depth, self.k, self.world_from_camera, mask)


def backproject(depth: NDArray[np.floating[Any]], k: NDArray[np.float64], world_from_camera: NDArray[np.float64],
                mask: NDArray[np.bool_] | None = None) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The world points seen at the pixels of ``depth`` (h, w) that hold a positive depth (and
    ``mask``): pixel (column ``i``, row ``j``) at depth ``z`` is the camera point
    ``z · K⁻¹ (i, j, 1)``, moved to the world by ``world_from_camera``. The inverse of the
    projection ``(K @ X)[:2] / X[2]``. Returns ``(points (M, 3) float64, flat indices (M,))``."""
    d = np.asarray(depth)
    valid = np.isfinite(d) & (d > 0)
    if mask is not None:
        valid &= np.asarray(mask, bool)
    flat = np.flatnonzero(valid)
    w = d.shape[1]
    rows, cols = np.divmod(flat, w)
    z = d.reshape(-1)[flat].astype(np.float64)
    pix = np.stack([cols.astype(np.float64), rows.astype(np.float64), np.ones(len(flat))], axis=1)
    cam = (pix @ np.linalg.inv(np.asarray(k, np.float64)).T) * z[:, None]
    m = np.asarray(world_from_camera, np.float64)
    return cam @ m[:3, :3].T + m[:3, 3], flat.astype(np.int64)


# -- reading --------------------------------------------------------------------------------------
_DEPTHS = (".depth.npy", ".depth.exr")
_SUFFIXES = (".color.png", *_DEPTHS, ".instance.png", ".normal.exr")


def _fail(path: Path | str, message: str) -> UsageError:
    return UsageError(f"{path}: {message}")


def _matrix(doc: dict[str, Any], key: str, shape: tuple[int, int], path: Path) -> NDArray[np.float64]:
    if key not in doc:
        raise _fail(path, f"missing field {key!r}")
    value = doc[key]
    try:
        m = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise _fail(path, f"{key}: expected a {shape[0]}×{shape[1]} matrix of numbers") from None
    if m.shape != shape or any(isinstance(x, bool) for row in value for x in (row if isinstance(row, list) else [])):
        raise _fail(path, f"{key}: expected a {shape[0]}×{shape[1]} matrix of numbers, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise _fail(path, f"{key}: every entry must be a finite number")
    return m


def _size(doc: dict[str, Any], key: str, path: Path) -> int:
    value = doc.get(key)
    if value is None:
        raise _fail(path, f"missing field {key!r}")
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise _fail(path, f"{key}: expected a positive whole number of pixels, got {value!r}")
    return value


def _camera(path: Path) -> tuple[int, int, NDArray[np.float64], NDArray[np.float64]]:
    """(width, height, K, world_from_camera) of a view's json, checked."""
    doc = read_json(path, what="view json")
    if not isinstance(doc, dict):
        raise _fail(path, f"expected a JSON object at the top level, got {type(doc).__name__}")
    w, h = _size(doc, "width", path), _size(doc, "height", path)
    if w * h > MAX_VIEW_PIXELS:
        raise _fail(path, f"{w}×{h} pixels is above the {MAX_VIEW_PIXELS:,} pixels a view may have")
    k = _matrix(doc, "K", (3, 3), path)
    if k[1, 0] != 0 or k[2, 0] != 0 or k[2, 1] != 0 or k[2, 2] != 1 or k[0, 1] != 0:
        raise _fail(path, "K: not a pinhole camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)")
    if not (k[0, 0] > 0 and k[1, 1] > 0):
        raise _fail(path, f"K: focal lengths must be positive, got fx = {k[0, 0]:g}, fy = {k[1, 1]:g}")
    m = _matrix(doc, "world_from_camera", (4, 4), path)
    r = m[:3, :3]
    if (np.abs(r.T @ r - np.eye(3)).max() > _RIGID_TOL or np.linalg.det(r) < 0
            or np.abs(m[3] - (0, 0, 0, 1)).max() > 0):
        raise _fail(path, "world_from_camera: not a rigid motion (a rotation, then a translation; last row 0 0 0 1)")
    return w, h, k, m


def _read_image(path: Path, what: str) -> NDArray[Any]:
    """Pixels (h, w, c) in the file's own type, through OpenImageIO."""
    if not path.is_file():
        raise _fail(path, f"no such file (the view's {what})")
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise _fail(path, f"cannot read the {what}: {oiio.geterror() or 'unknown image format'}")
    try:
        spec = inp.spec()
        if spec.width * spec.height > MAX_VIEW_PIXELS:
            raise _fail(path, f"{spec.width}×{spec.height} pixels is above the {MAX_VIEW_PIXELS:,} a view may have")
        pixels = inp.read_image(spec.format)
        if pixels is None:
            raise _fail(path, f"cannot read the {what}'s pixels: {inp.geterror() or oiio.geterror()}")
    finally:
        inp.close()
    arr = np.asarray(pixels)
    return arr[:, :, None] if arr.ndim == 2 else arr


def _color(path: Path, size: tuple[int, int]) -> NDArray[np.uint8]:
    px = _read_image(path, "colour image")
    _check_size(path, px.shape, size)
    if px.dtype != np.uint8:
        raise _fail(path, f"expected 8-bit colour, got {px.dtype}")
    c = px.shape[2]
    if c in (1, 2):
        px = np.repeat(px[:, :, :1], 3, axis=2)
    return np.ascontiguousarray(px[:, :, :3])


def _depth(path: Path, size: tuple[int, int]) -> NDArray[np.float32]:
    if path.suffix == ".npy":
        data = read_bytes(path, what="depth array")
        try:
            arr = np.load(io.BytesIO(data), allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:
            raise _fail(path, f"not a numpy array file: {exc}") from None
        if not isinstance(arr, np.ndarray) or arr.ndim != 2 or arr.dtype.kind not in "fiu":
            raise _fail(path, f"expected a 2-D array of numbers, got {getattr(arr, 'dtype', '?')} "
                              f"{getattr(arr, 'shape', '?')}")
        depth = arr.astype(np.float32)
    else:
        px = _read_image(path, "depth image")
        depth = px[:, :, 0].astype(np.float32)
    _check_size(path, depth.shape, size)
    bad = ~np.isfinite(depth)
    if bad.any():
        raise _fail(path, f"{int(bad.sum()):,} pixels hold a depth that is not finite (NaN or Inf); "
                          "write 0 where there is no data")
    negative = depth < 0
    if negative.any():
        raise _fail(path, f"{int(negative.sum()):,} pixels hold a negative depth; write 0 where there is no data")
    return depth


def _instance(path: Path, size: tuple[int, int]) -> NDArray[np.uint32]:
    px = _read_image(path, "instance image")
    _check_size(path, px.shape, size)
    if px.dtype.kind not in "ui":
        raise _fail(path, f"expected whole-number leaf labels (16-bit), got {px.dtype}")
    return px[:, :, 0].astype(np.uint32)


def _check_size(path: Path, shape: tuple[int, ...], size: tuple[int, int]) -> None:
    w, h = size
    if tuple(shape[:2]) != (h, w):
        raise _fail(path, f"is {shape[1]}×{shape[0]} pixels, but the view's json says {w}×{h}")


def _depth_path(folder: Path, name: str) -> Path | None:
    found = [folder / f"{name}{s}" for s in _DEPTHS if (folder / f"{name}{s}").exists()]
    if len(found) > 1:
        raise _fail(found[0], f"{name} has two depth files ({', '.join(p.name for p in found)}): keep one")
    return found[0] if found else None


def read_view(directory: str | os.PathLike[str], name: str) -> View:
    """The view ``name`` in ``directory`` (see the module docstring), checked: the json's camera,
    the images' sizes against its ``width`` and ``height``, the depth finite and non-negative."""
    folder = Path(directory)
    meta = folder / f"{name}.json"
    if not meta.is_file():
        raise _fail(meta, "no such file (the view's camera)")
    w, h, k, m = _camera(meta)
    color_path = folder / f"{name}.color.png"
    if not color_path.is_file():
        raise _fail(color_path, f"no such file (the colour image of {meta.name})")
    depth_path = _depth_path(folder, name)
    if depth_path is None:
        raise _fail(folder / f"{name}.depth.npy", f"no such file, nor {name}.depth.exr (the depth of {meta.name})")
    color = _color(color_path, (w, h))
    depth = _depth(depth_path, (w, h))
    inst_path = folder / f"{name}.instance.png"
    instance = _instance(inst_path, (w, h)) if inst_path.is_file() else None
    for arr in (color, depth, k, m, instance):
        if arr is not None:
            arr.setflags(write=False)
    return View(name, color, depth, k, m, instance)


def view_names(directory: str | os.PathLike[str]) -> list[str]:
    """The names of the views in ``directory``, sorted: every ``NAME`` with a ``NAME.json`` and a
    colour or depth image beside it, or an image without its json (an error when read). Other
    json files (``truth.leaves.json``, ``views.json``) are not views."""
    folder = Path(directory)
    try:
        if not folder.exists():
            raise _fail(folder, "no such folder of views")
        if not folder.is_dir():
            raise _fail(folder, "is not a folder (expected a folder of views: NAME.json, NAME.color.png, "
                                "NAME.depth.npy)")
        files = {p.name for p in folder.iterdir()}
    except OSError as exc:   # a name too long, no permission, a loop of links
        raise _fail(folder, f"cannot be read: {exc.strerror or exc}") from None
    names = set()
    for f in files:
        for s in (".color.png", *_DEPTHS):
            if f.endswith(s) and len(f) > len(s):
                names.add(f[: -len(s)])
    return sorted(names)


def read_views(directory: str | os.PathLike[str]) -> list[View]:
    """Every view in ``directory`` (:func:`view_names`), sorted by name. Raises
    :class:`~leafview.errors.UsageError` naming the folder when it is missing or holds no view,
    and naming the file for anything wrong with one view (:func:`read_view`)."""
    names = view_names(directory)
    if not names:
        raise _fail(Path(directory), "holds no views (expected NAME.json with NAME.color.png and NAME.depth.npy "
                                     "or NAME.depth.exr beside it)")
    return [read_view(directory, n) for n in names]


def check_views(views: Sequence[View]) -> None:
    """UsageError unless ``views`` is a non-empty sequence of :class:`View` whose arrays agree in
    size (for views built in memory rather than read)."""
    if not views:
        raise UsageError("capture: no views given")
    for v in views:
        h, w = v.depth.shape
        if v.color.shape != (h, w, 3) or v.k.shape != (3, 3) or v.world_from_camera.shape != (4, 4):
            raise UsageError(f"{v.name}: colour {v.color.shape} and depth {v.depth.shape} disagree, or the camera "
                             "matrices are not 3×3 and 4×4")
        if not math.isfinite(float(np.sum(v.depth, dtype=np.float64))) or float(v.depth.min(initial=0.0)) < 0:
            raise UsageError(f"{v.name}: depth must be finite and non-negative")
