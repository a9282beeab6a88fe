"""A numpy stand-in for the GPU instance pass: leaves splatted into a z-buffer.

Each leaf is evaluated on its drawn (u, v) grid (:data:`BASE_GRID`), interpolated bilinearly to
about 1.5 samples per pixel, placed by its transform and projected with an OpenCV pinhole camera
(``K``, ``world_from_camera``: x right, y down, z forward, pixel centres at integer coordinates);
every sample writes its leaf's id (index + 1) into the pixel it lands in, and the nearest sample of
a pixel wins. Samples less than a pixel apart leave no holes, so the masks match a triangle
rasteriser's up to about one pixel at the silhouette.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from leafview.core.blade import drawn_uv
from leafview.core.params import LeafParams
from leafview.deform.surface import evaluate

BASE_GRID = (65, 129)   # the surface is evaluated here; finer grids interpolate it bilinearly


@lru_cache(maxsize=256)
def _base_points(leaf: LeafParams, samples: tuple[int, int]) -> NDArray[np.float64]:
    nu, nv = samples
    uu, vv = np.meshgrid(np.linspace(-1.0, 1.0, nu), np.linspace(0.0, 1.0, nv))
    uv = drawn_uv(leaf, np.stack([uu.ravel(), vv.ravel()], axis=-1))
    m = leaf.transform.matrix()
    points = evaluate(leaf, uv[:, 0], uv[:, 1]) @ m[:3, :3].T + m[:3, 3]
    return points.reshape(nv, nu, 3)


def leaf_points(leaf: LeafParams, samples: tuple[int, int]) -> NDArray[np.float64]:
    """World-space points of ``leaf`` on a (nu, nv) grid of (u, v) (u fastest), as drawn: the
    surface evaluated on :data:`BASE_GRID` (cached) and interpolated bilinearly in (u, v), which is
    what a GPU drawing that grid's triangles shows; grids no finer than it are evaluated exactly."""
    nu, nv = samples
    if nu <= BASE_GRID[0] and nv <= BASE_GRID[1]:
        return _base_points(leaf, (nu, nv)).reshape(-1, 3)
    base = _base_points(leaf, BASE_GRID)

    def axis(n: int, n0: int) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        f = np.linspace(0.0, n0 - 1.0, n)
        i = np.minimum(np.floor(f).astype(np.int64), n0 - 2)
        return i, f - i

    i, s = axis(nu, BASE_GRID[0])
    j, t = axis(nv, BASE_GRID[1])
    s, t = s[None, :, None], t[:, None, None]
    rows0, rows1 = base[j], base[j + 1]
    out = ((1 - t) * ((1 - s) * rows0[:, i] + s * rows0[:, i + 1]) + t * ((1 - s) * rows1[:, i] + s * rows1[:, i + 1]))
    return out.reshape(-1, 3)


def _project(world: NDArray[np.float64], k: NDArray[np.float64],
             camera_from_world: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Pixel coordinates (N, 2) and depth (N,) of world points; depth <= 0 behind the camera."""
    x = world @ camera_from_world[:3, :3].T + camera_from_world[:3, 3]
    z = x[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        pix = np.stack([(x @ k[0]) / z, (x @ k[1]) / z], axis=-1)
    return pix, z


def _grid_for(leaf: LeafParams, k: NDArray[np.float64], camera_from_world: NDArray[np.float64],
              per_pixel: float) -> tuple[int, int]:
    """A (nu, nv) grid fine enough that neighbouring samples land at most 1 / ``per_pixel``
    pixels apart (measured on a coarse 17 × 17 grid, capped at 1025 a side)."""
    pix, z = _project(leaf_points(leaf, (17, 17)), k, camera_from_world)
    if not np.all(z > 0.0):
        return 1025, 1025
    pix = pix.reshape(17, 17, 2)
    du = float(np.linalg.norm(np.diff(pix, axis=1), axis=-1).max())
    dv = float(np.linalg.norm(np.diff(pix, axis=0), axis=-1).max())
    return tuple(int(np.clip(np.ceil(16 * d * per_pixel), 16, 1024)) + 1 for d in (du, dv))  # type: ignore[return-value]


def splat(leaves: Sequence[LeafParams], k: NDArray[np.float64], world_from_camera: NDArray[np.float64],
          size: tuple[int, int], samples: tuple[int, int] | None = None,
          per_pixel: float = 1.5) -> tuple[NDArray[np.uint32], NDArray[np.float64]]:
    """``(instance, depth)`` images of ``size`` = (w, h): leaf index + 1 (0 background) and the
    depth along the optical axis of the nearest sample (inf background). Each leaf is sampled on
    ``samples`` = (nu, nv), or by default on a grid with ``per_pixel`` samples per pixel."""
    w, h = size
    instance = np.zeros(h * w, dtype=np.uint32)
    depth = np.full(h * w, np.inf)
    if not leaves:
        return instance.reshape(h, w), depth.reshape(h, w)
    camera_from_world = np.asarray(np.linalg.inv(world_from_camera), dtype=np.float64)
    points = [leaf_points(leaf, samples or _grid_for(leaf, k, camera_from_world, per_pixel)) for leaf in leaves]
    pix, z = _project(np.concatenate(points), k, camera_from_world)
    ids = np.repeat(np.arange(1, len(leaves) + 1, dtype=np.uint32), [len(p) for p in points])
    front = z > 1e-9
    col = np.floor(pix[:, 0] + 0.5)
    row = np.floor(pix[:, 1] + 0.5)
    inside = front & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    pixel = (row[inside] * w + col[inside]).astype(np.int64)
    z, ids = z[inside], ids[inside]
    order = np.lexsort((z, pixel))                      # by pixel, then nearest first
    pixel, z, ids = pixel[order], z[order], ids[order]
    first = np.flatnonzero(np.r_[True, pixel[1:] != pixel[:-1]])
    instance[pixel[first]] = ids[first]
    depth[pixel[first]] = z[first]
    return instance.reshape(h, w), depth.reshape(h, w)
