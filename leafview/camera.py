"""Camera framing for the named views (numpy + pyrr, no GL).

Matrices use the column-vector convention (``clip = P · V · world``); upload ``M.T`` bytes for
GLSL's column-major layout.

Views:

``top``
    Orthographic, looking down -z, +x to the right and +y up in the image. The xy bounding box
    of the leaf's world-space vertices is centred and scaled uniformly so that it fits in 90 % of
    the image in both directions; in a square image its longer side spans exactly 90 % (a 5 %
    margin each side).
``front``
    Perspective (30° vertical field of view) from the -y side, 20° above the leaf plane, +z up:
    shows the cross-section curvature.
``three-quarter``
    Perspective from azimuth 35° (towards +x from the front) and 50° elevation.
``side``
    Perspective from +x, 15° above the leaf plane: shows droop, twist and rippled margins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyrr
from numpy.typing import NDArray

__all__ = ["VIEWS", "Camera", "frame_view"]

VIEWS = ("top", "front", "three-quarter", "side")
_ORBITS = {"front": (0.0, 20.0), "three-quarter": (35.0, 50.0), "side": (90.0, 15.0)}
FOV_DEG = 30.0
TOP_FILL = 0.9


@dataclass(frozen=True)
class Camera:
    view: NDArray[np.float64]
    proj: NDArray[np.float64]
    eye: NDArray[np.float64]   # xyz position, w = 1 (perspective) or xyz view direction, w = 0 (ortho)
    perspective: bool


def frame_view(view: str, points: NDArray[np.float64], size: tuple[int, int]) -> Camera:
    """Camera for ``view`` framing ``points`` (world space, (N, 3)) in an image of ``size`` = (w, h)."""
    if view not in VIEWS:
        raise ValueError(f"unknown view {view!r} (choose from {', '.join(VIEWS)})")
    w, h = size
    lo, hi = points.min(axis=0), points.max(axis=0)
    if view == "top":
        return _top(lo, hi, w, h)
    az, el = _ORBITS[view]
    return _orbit(points, lo, hi, w, h, az, el)


def _top(lo, hi, w, h) -> Camera:
    extent = np.maximum(hi[:2] - lo[:2], 1e-9)
    scale = TOP_FILL * min(w / extent[0], h / extent[1])  # pixels per world unit
    cx, cy = (lo[:2] + hi[:2]) / 2
    half_w, half_h = w / (2 * scale), h / (2 * scale)
    z_top = hi[2] + 1.0
    depth = (hi[2] - lo[2]) + 2.0
    view = np.eye(4)
    view[:3, 3] = (-cx, -cy, -z_top)
    proj = pyrr.matrix44.create_orthogonal_projection(-half_w, half_w, -half_h, half_h, 0.01, depth,
                                                      dtype=np.float64).T
    return Camera(view, proj, np.array([0.0, 0.0, -1.0, 0.0]), False)


def _orbit(points, lo, hi, w, h, az_deg, el_deg) -> Camera:
    center = (lo + hi) / 2
    radius = max(float(np.linalg.norm(points - center, axis=1).max()), 1e-6)
    az, el = np.radians(az_deg), np.radians(el_deg)
    direction = np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])
    fov_y = np.radians(FOV_DEG)
    fov_x = 2 * np.arctan(np.tan(fov_y / 2) * w / h)
    half = min(fov_y, fov_x) / 2
    dist = radius / np.sin(half) * 1.08
    eye = center + dist * direction
    view = pyrr.matrix44.create_look_at(eye, center, np.array([0.0, 0.0, 1.0]), dtype=np.float64).T
    near, far = max(dist - radius * 1.5, 1e-3), dist + radius * 1.5
    proj = pyrr.matrix44.create_perspective_projection(FOV_DEG, w / h, near, far, dtype=np.float64).T
    return Camera(view, proj, np.array([*eye, 1.0]), True)
