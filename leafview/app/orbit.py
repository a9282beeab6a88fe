"""The viewport camera: orbit about a target, pan, dolly, reset and frame (numpy only).

Angles follow :mod:`leafview.scene.camera`: azimuth 0 looks from -y towards +y, positive azimuth moves
the eye towards +x, elevation is above the leaf plane (z up). Screen coordinates are pixels with
the origin at the top-left of the viewport, as imgui reports the mouse.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.scene.camera import FOV_DEG, Camera, look_at

__all__ = ["OrbitCamera", "project", "HOME_AZIMUTH", "HOME_ELEVATION"]

HOME_AZIMUTH = 35.0    # the three-quarter view of ``leafview render --view three-quarter``
HOME_ELEVATION = 50.0
ORBIT_DEG_PER_PX = 0.4
DOLLY_PER_STEP = 0.88


@dataclass
class OrbitCamera:
    """A z-up orbit camera; mutable, one per viewport."""

    target: NDArray[np.float64]
    distance: float = 3.0
    azimuth: float = HOME_AZIMUTH
    elevation: float = HOME_ELEVATION
    radius: float = 0.6        # size of what is framed: sets near/far and dolly limits

    @classmethod
    def framing(cls, points: ArrayLike, aspect: float = 1.0) -> OrbitCamera:
        """The home view (three-quarter) framed on ``points`` (N, 3)."""
        cam = cls(target=np.zeros(3))
        cam.frame(points, aspect)
        return cam

    # -- derived --------------------------------------------------------------------------------
    def direction(self) -> NDArray[np.float64]:
        """Unit vector from the target towards the eye."""
        az, el = math.radians(self.azimuth), math.radians(self.elevation)
        return np.array([math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el)])

    def eye(self) -> NDArray[np.float64]:
        return self.target + self.distance * self.direction()

    def camera(self, width: int, height: int) -> Camera:
        """The :class:`~leafview.scene.camera.Camera` for a viewport of ``width`` × ``height`` pixels."""
        aspect = max(width, 1) / max(height, 1)
        near = max(self.distance - 4.0 * self.radius, self.distance * 0.01, 1e-4)
        far = self.distance + 12.0 * self.radius
        return look_at(self.eye(), self.target, aspect, near, far)

    # -- interaction ----------------------------------------------------------------------------
    def orbit(self, dx: float, dy: float) -> None:
        """Rotate by a mouse motion of (dx, dy) pixels (drag right: the leaf turns right)."""
        self.azimuth = (self.azimuth - dx * ORBIT_DEG_PER_PX + 180.0) % 360.0 - 180.0
        self.elevation = float(np.clip(self.elevation + dy * ORBIT_DEG_PER_PX, -89.0, 89.0))

    def pan(self, dx: float, dy: float, height: int) -> None:
        """Move the target with the mouse: the point under the cursor follows it."""
        per_px = 2.0 * self.distance * math.tan(math.radians(FOV_DEG) / 2) / max(height, 1)
        forward = -self.direction()
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= max(float(np.linalg.norm(right)), 1e-12)
        up = np.cross(right, forward)
        self.target = self.target + per_px * (-dx * right + dy * up)

    def dolly(self, steps: float) -> None:
        """Move towards (steps > 0, wheel up) or away from the target."""
        self.distance = float(np.clip(self.distance * DOLLY_PER_STEP ** steps,
                                      0.05 * self.radius, 50.0 * self.radius))

    def frame(self, points: ArrayLike, aspect: float = 1.0) -> None:
        """Keep the direction, centre ``points`` and move so their bounding sphere fills the view."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        p = p[np.all(np.isfinite(p), axis=1)]
        if len(p) == 0:
            return
        lo, hi = p.min(axis=0), p.max(axis=0)
        self.target = (lo + hi) / 2
        self.radius = max(float(np.linalg.norm(p - self.target, axis=1).max()), 1e-3)
        fov_y = math.radians(FOV_DEG)
        fov_x = 2 * math.atan(math.tan(fov_y / 2) * max(aspect, 1e-3))
        self.distance = self.radius / math.sin(min(fov_x, fov_y) / 2) * 1.15

    def reset(self, points: ArrayLike, aspect: float = 1.0) -> None:
        """Back to the home (three-quarter) direction, framed on ``points``."""
        self.azimuth, self.elevation = HOME_AZIMUTH, HOME_ELEVATION
        self.frame(points, aspect)

    def ray(self, x: float, y: float, width: int, height: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """World-space ray (origin, unit direction) through viewport pixel (x, y)."""
        cam = self.camera(width, height)
        inv = np.linalg.inv(cam.proj @ cam.view)
        ndc = np.array([2.0 * x / max(width, 1) - 1.0, 1.0 - 2.0 * y / max(height, 1)])
        near = inv @ np.array([*ndc, -1.0, 1.0])
        far = inv @ np.array([*ndc, 1.0, 1.0])
        a, b = near[:3] / near[3], far[:3] / far[3]
        d = b - a
        return a, d / np.linalg.norm(d)


def project(camera: Camera, points: ArrayLike, width: int, height: int) -> NDArray[np.float64]:
    """Viewport pixel coordinates (x right, y down) of world ``points`` (N, 3); rows behind the
    eye are NaN."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    clip = np.c_[p, np.ones(len(p))] @ (camera.proj @ camera.view).T
    w = clip[:, 3:4]
    with np.errstate(divide="ignore", invalid="ignore"):
        ndc = clip[:, :2] / w
    out = np.c_[(ndc[:, 0] + 1.0) * 0.5 * width, (1.0 - ndc[:, 1]) * 0.5 * height]
    out[w[:, 0] <= 1e-9] = np.nan
    return out
