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
    shows the cross-section curvature. Perspective views put the camera as close as every
    vertex allows within the central 92 % of the image.
``three-quarter``
    Perspective from azimuth 35° (towards +x from the front) and 50° elevation.
``side``
    Perspective from +x, 15° above the leaf plane: shows droop, twist and rippled margins.

What can be framed. The GPU draws in float32, which resolves about 7 significant digits, so
points whose extent is below :data:`~leafview.core.limits.MIN_FRAME_RATIO` of their distance from
the origin (a small leaf translated far away) or beyond :data:`MAX_FRAME_REACH` would come out as a
blank or speckled image: :func:`frame_view` refuses them (:func:`check_framable`), and
:func:`check_leaf_framable` says which leaf before anything is drawn.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import pyrr
from numpy.typing import ArrayLike, NDArray

from leafview.botany import leaf_surface
from leafview.core.limits import MIN_FRAME_RATIO
from leafview.core.params import LeafParams, ParamError
from leafview.deform.surface import evaluate, grid_uv

__all__ = ["VIEWS", "Camera", "frame_view", "frame_views", "frame_view_arrays", "look_at_arrays", "check_framable", "check_leaf_framable", "MAX_FRAME_REACH",
           "intrinsics", "camera_from_intrinsics", "CV_FROM_GL", "RING_FOV_DEG", "RING_ELEVATIONS", "ring_angles",
           "orbit_cameras"]

MAX_FRAME_REACH = 1e18     # farthest framed point from the origin (its square must fit float32)

VIEWS = ("top", "front", "three-quarter", "side")
_ORBITS = {"front": (0.0, 20.0), "three-quarter": (35.0, 50.0), "side": (90.0, 15.0)}
FOV_DEG = 30.0
TOP_FILL = 0.9
ORBIT_FILL = 0.92


@dataclass(frozen=True)
class Camera:
    view: NDArray[np.float64]
    proj: NDArray[np.float64]
    eye: NDArray[np.float64]   # xyz position, w = 1 (perspective) or xyz view direction, w = 0 (ortho)
    perspective: bool


def look_at(eye: ArrayLike, target: ArrayLike, aspect: float, near: float, far: float,
            fov_deg: float = FOV_DEG) -> Camera:
    """Perspective camera at ``eye`` looking at ``target`` with +z up; ``fov_deg`` is the vertical
    field of view. Every perspective camera of leafview is made here or, several at once, by
    :func:`look_at_arrays`."""
    views, projs, eyes = look_at_arrays(np.asarray(eye, dtype=np.float64)[None], np.asarray(target, dtype=np.float64)[None],
                                        aspect, np.array([near], np.float64), np.array([far], np.float64), fov_deg)
    return Camera(views[0], projs[0], eyes[0], True)


_NEXT, _LAST = [1, 2, 0], [2, 0, 1]   # cross product index cycles


def look_at_arrays(eye: NDArray[np.float64], target: NDArray[np.float64], aspect: float,
                   near: NDArray[np.float64], far: NDArray[np.float64], fov_deg: float = FOV_DEG
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """K perspective cameras at ``eye`` (K, 3) looking at ``target`` (K, 3) with +z up, clip planes
    ``near``, ``far`` (K,): view and projection matrices (K, 4, 4) and eyes (K, 4), in one numpy
    pass (a chunk of thumbnails is framed at once). The arithmetic of ``pyrr.matrix44``'s
    ``create_look_at`` and ``create_perspective_projection``, operation for operation, except that
    the view's translation sums its three products left to right (the same bits whatever K is;
    ``np.dot`` may differ in the last bit of a float64, never of a float32)."""
    k = len(eye)

    def normalize(v: NDArray[np.float64]) -> NDArray[np.float64]:
        return v / np.sqrt(np.sum(v ** 2, axis=-1))[:, None]

    def cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
        # np.cross's products and differences, without its axis handling (a tenth of its time)
        return a[:, _NEXT] * b[:, _LAST] - a[:, _LAST] * b[:, _NEXT]

    forward = normalize(target - eye)
    side = normalize(cross(forward, np.broadcast_to(np.array([0.0, 0.0, 1.0]), forward.shape)))
    up = normalize(cross(side, forward))
    views = np.zeros((k, 4, 4))
    views[:, 0, :3], views[:, 1, :3], views[:, 2, :3] = side, up, -forward
    for row, axis, sign in ((0, side, -1.0), (1, up, -1.0), (2, forward, 1.0)):
        prod = axis * eye
        views[:, row, 3] = sign * (prod[:, 0] + prod[:, 1] + prod[:, 2])
    views[:, 3, 3] = 1.0
    ymax = near * np.tan(fov_deg * np.pi / 360.0)
    xmax = ymax * aspect
    left, right, bottom, top = -xmax, xmax, -ymax, ymax
    projs = np.zeros((k, 4, 4))
    projs[:, 0, 0] = 2. * near / (right - left)
    projs[:, 1, 1] = 2. * near / (top - bottom)
    projs[:, 0, 2] = (right + left) / (right - left)
    projs[:, 1, 2] = (top + bottom) / (top - bottom)
    projs[:, 2, 2] = -(far + near) / (far - near)
    projs[:, 2, 3] = -2. * far * near / (far - near)
    projs[:, 3, 2] = -1.0
    eyes = np.ones((k, 4))
    eyes[:, :3] = eye
    return views, projs, eyes


def top_down(center: ArrayLike, z_top: float, half_w: float, half_h: float, depth: float) -> Camera:
    """Orthographic camera looking down -z from height ``z_top`` above the point ``center`` (x, y),
    seeing ``±half_w`` × ``±half_h`` world units and ``depth`` units below ``z_top``. Every
    orthographic camera of leafview is made here."""
    cx, cy = (float(c) for c in np.asarray(center, dtype=np.float64)[:2])
    view = np.eye(4)
    view[:3, 3] = (-cx, -cy, -z_top)
    proj = pyrr.matrix44.create_orthogonal_projection(-half_w, half_w, -half_h, half_h, 0.01, depth,
                                                      dtype=np.float64).T
    return Camera(view, proj, np.array([0.0, 0.0, -1.0, 0.0]), False)


CV_FROM_GL = np.diag([1.0, -1.0, -1.0, 1.0])
"""Camera axes from OpenGL's (x right, y up, z backwards) to OpenCV's (x right, y down, z forward)."""


def intrinsics(camera: Camera, size: tuple[int, int]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The pinhole model of a perspective ``camera`` drawing an image of ``size`` = (w, h), in the
    OpenCV convention: ``(K, world_from_camera)``, both float64.

    Convention, exactly:

    * camera axes: x right, y down, z forward (the optical axis); ``world_from_camera`` (4×4)
      maps camera to world coordinates, its columns are the axes and the centre in world space
      (``inv(camera.view) @ CV_FROM_GL``).
    * pixels, as OpenCV has them: the centre of pixel (column ``i``, row ``j``; row 0 at the top,
      as every readback of leafview) is at image coordinates ``(i, j)``, and the pixel covers
      ``[i - 0.5, i + 0.5) × [j - 0.5, j + 0.5)``. A point ``X`` in camera coordinates lands at
      ``(x, y) = (K @ X)[:2] / X[2]`` (what ``cv2.projectPoints`` gives), inside pixel
      ``(round(x), round(y))``; a centred projection has ``cx = (w - 1) / 2``, ``cy = (h - 1) / 2``.
    * ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels: ``fx = P[0,0] w / 2``,
      ``fy = P[1,1] h / 2``, ``cx = (1 - P[0,2]) w / 2 - 1/2``, ``cy = (1 + P[1,2]) h / 2 - 1/2``
      from the projection matrix ``P = camera.proj`` (an off-centre frustum moves the principal
      point).
      ``X[2]`` is the depth along the optical axis, the ``depth`` of :mod:`leafview.gpu.aov`.

    Raises ValueError for an orthographic camera (no pinhole model: points map to pixels by
    ``camera.proj @ camera.view`` alone) or a projection with skew or without the pinhole's last
    row ``(0, 0, -1, 0)``.
    """
    if not camera.perspective:
        raise ValueError("intrinsics: an orthographic camera has no pinhole model (K); "
                         "project with camera.proj @ camera.view instead")
    w, h = float(size[0]), float(size[1])
    if not (w > 0 and h > 0):
        raise ValueError(f"intrinsics: size must be positive, got {size!r}")
    p = np.asarray(camera.proj, np.float64)
    if not (np.allclose(p[3], (0.0, 0.0, -1.0, 0.0)) and p[0, 1] == 0.0 and p[1, 0] == 0.0
            and p[0, 3] == 0.0 and p[1, 3] == 0.0):
        raise ValueError("intrinsics: the projection is not a pinhole perspective (skew, a shifted "
                         "eye or a last row other than (0, 0, -1, 0))")
    k = np.array([[p[0, 0] * w / 2.0, 0.0, (1.0 - p[0, 2]) * w / 2.0 - 0.5],
                  [0.0, p[1, 1] * h / 2.0, (1.0 + p[1, 2]) * h / 2.0 - 0.5],
                  [0.0, 0.0, 1.0]])
    world_from_camera = np.linalg.inv(np.asarray(camera.view, np.float64)) @ CV_FROM_GL
    return k, world_from_camera


def camera_from_intrinsics(k: ArrayLike, world_from_camera: ArrayLike, size: tuple[int, int], near: float,
                           far: float) -> Camera:
    """The perspective :class:`Camera` whose :func:`intrinsics` at ``size`` are ``(k,
    world_from_camera)`` (OpenCV convention), with clip planes ``near`` < ``far`` along the optical
    axis: how a view read from disk (a capture, a dataset image) is drawn again.

    Raises ValueError for a ``k`` with skew, non-positive focal lengths, a ``world_from_camera``
    that is not a rigid motion, or clip planes not ``0 < near < far``.
    """
    k = np.asarray(k, np.float64)
    m = np.asarray(world_from_camera, np.float64)
    w, h = float(size[0]), float(size[1])
    if k.shape != (3, 3) or m.shape != (4, 4) or not (np.all(np.isfinite(k)) and np.all(np.isfinite(m))):
        raise ValueError("camera_from_intrinsics: K must be a finite 3×3 and world_from_camera a finite 4×4 matrix")
    if k[0, 1] != 0.0 or k[1, 0] != 0.0 or k[2, 0] != 0.0 or k[2, 1] != 0.0 or k[2, 2] != 1.0:
        raise ValueError("camera_from_intrinsics: K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]")
    if not (k[0, 0] > 0.0 and k[1, 1] > 0.0 and w > 0 and h > 0):
        raise ValueError("camera_from_intrinsics: focal lengths and the image size must be positive")
    r = m[:3, :3]
    if (np.abs(r.T @ r - np.eye(3)).max() > 1e-6 or np.linalg.det(r) < 0.0
            or not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0))):
        raise ValueError("camera_from_intrinsics: world_from_camera is not a rotation and a translation")
    if not (0.0 < near < far and np.isfinite(far)):
        raise ValueError(f"camera_from_intrinsics: clip planes must satisfy 0 < near < far, got {near}, {far}")
    proj = np.zeros((4, 4))
    proj[0, 0] = 2.0 * k[0, 0] / w
    proj[1, 1] = 2.0 * k[1, 1] / h
    proj[0, 2] = 1.0 - 2.0 * (k[0, 2] + 0.5) / w
    proj[1, 2] = 2.0 * (k[1, 2] + 0.5) / h - 1.0
    proj[2, 2] = -(far + near) / (far - near)
    proj[2, 3] = -2.0 * far * near / (far - near)
    proj[3, 2] = -1.0
    view = CV_FROM_GL @ np.linalg.inv(m)
    return Camera(view, proj, np.array([*m[:3, 3], 1.0]), True)


def frame_view(view: str, points: NDArray[np.float64], size: tuple[int, int]) -> Camera:
    """Camera for ``view`` framing ``points`` (world space, (N, 3)) in an image of ``size`` = (w, h)."""
    return frame_views(view, np.asarray(points, dtype=np.float64).reshape(1, -1, 3), size)[0]


def frame_views(view: str, points: NDArray[np.floating[Any]], size: tuple[int, int]) -> list[Camera]:
    """Cameras for ``view`` framing each of the point sets ``points`` (K, N, 3) in an image of
    ``size``: each set's checks (:func:`check_framable`), its distance and aim, vectorised over
    the batch (a chunk of thumbnails is framed without a Python loop over numpy calls per leaf).
    The orbit camera is as close as it can be with every point inside the central
    ``ORBIT_FILL`` of the image (tighter than a bounding sphere for long, narrow leaves), aimed at
    the middle of the projected extent."""
    views, projs, eyes = frame_view_arrays(view, points, size)
    return [Camera(views[k], projs[k], eyes[k], view != "top") for k in range(len(views))]


def frame_view_arrays(view: str, points: NDArray[np.floating[Any]], size: tuple[int, int]
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`frame_views` without a :class:`Camera` per point set: the view and projection
    matrices (K, 4, 4) and eyes (K, 4) as three arrays (perspective unless ``view`` is ``top``),
    the orbit views made by one numpy pass over the batch (:func:`look_at_arrays`: a chunk of
    thumbnails is framed at once, not one ``look_at`` per leaf)."""
    if view not in VIEWS:
        raise ValueError(f"unknown view {view!r} (choose from {', '.join(VIEWS)})")
    pts = np.asarray(points)
    if pts.ndim != 3 or pts.shape[2] != 3:
        raise ValueError(f"expected point sets of shape (K, N, 3), got {pts.shape}")
    if pts.size == 0:
        for p in pts:
            check_framable(p)   # raises: nothing to frame
        return np.zeros((0, 4, 4)), np.zeros((0, 4, 4)), np.zeros((0, 4))
    # each coordinate's extremes from a (K, 3, N) float64 copy (one pass from float32 records): a
    # reduction along contiguous rows, 15× faster than along the middle axis of (K, N, 3) and the
    # same values (min and max are exact)
    rows = np.empty((pts.shape[0], 3, pts.shape[1]))
    rows[...] = pts.transpose(0, 2, 1)
    lo, hi = rows.min(axis=2), rows.max(axis=2)
    finite = np.isfinite(lo).all(axis=1) & np.isfinite(hi).all(axis=1)
    reach = np.max(np.maximum(np.abs(lo), np.abs(hi)), axis=1)
    extent = np.max(hi - lo, axis=1)
    bad = ~(finite & (reach <= MAX_FRAME_REACH) & (extent > reach * MIN_FRAME_RATIO))
    if bad.any():
        check_framable(pts[int(np.argmax(bad))])   # raises the same error as frame_view
    w, h = size
    if view == "top":
        tops = [_top(lo[k], hi[k], w, h) for k in range(len(pts))]
        return (np.stack([c.view for c in tops]), np.stack([c.proj for c in tops]),
                np.stack([c.eye for c in tops]))
    az_deg, el_deg = _ORBITS[view]
    basis, tan_x, tan_y = _orbit_axes(az_deg, el_deg, w, h)
    center = (lo + hi) / 2
    # camera coordinates of every point, one (K, N) row array per axis (contiguous: the
    # reductions below run along rows); the same sums as (pts - center) @ basis.T, term by term
    rel = rows - center[:, :, None]
    x, y, z = (rel[:, 0] * b[0] + rel[:, 1] * b[1] + rel[:, 2] * b[2] for b in basis)
    shift_x, shift_y = np.zeros(len(pts)), np.zeros(len(pts))
    for _ in range(3):  # distance for the current aim, then re-aim at the projected middle
        xs, ys = x - shift_x[:, None], y - shift_y[:, None]
        dist = np.maximum(np.max(z + np.maximum(np.abs(xs) / tan_x, np.abs(ys) / tan_y), axis=1), 1e-6)
        depth = dist[:, None] - z
        sx, sy = xs / depth, ys / depth
        shift_x = shift_x + dist * (sx.max(axis=1) + sx.min(axis=1)) / 2
        shift_y = shift_y + dist * (sy.max(axis=1) + sy.min(axis=1)) / 2
    xs, ys = x - shift_x[:, None], y - shift_y[:, None]
    dist = np.maximum(np.max(z + np.maximum(np.abs(xs) / tan_x, np.abs(ys) / tan_y), axis=1), 1e-6)
    center = center + basis[0] * shift_x[:, None] + basis[1] * shift_y[:, None]
    zmax = np.abs(z).max(axis=1)
    return _orbit_cameras(center, basis[2], dist, zmax, w, h)


def _orbit_cameras(center: NDArray[np.float64], back: NDArray[np.float64], dist: NDArray[np.float64],
                   zmax: NDArray[np.float64], w: int, h: int
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The orbit cameras aimed at ``center`` (K, 3) from ``dist`` (K,) along ``back``, their clip
    planes around the depth ``zmax`` (K,) of the points along the view axis (the aim moved across
    it only), as :func:`look_at_arrays` returns them."""
    eye = center + dist[:, None] * back
    near = np.maximum(dist - zmax * 1.5 - 1e-3, dist * 1e-3)
    far = dist + zmax * 1.5 + 1e-3
    return look_at_arrays(eye, center, w / h, near, far)


def check_framable(points: ArrayLike, what: str = "the geometry", path: str = "transform") -> None:
    """ParamError (at ``path``, naming ``what``) unless the world-space ``points`` are finite and
    can be framed in float32 (see the module docstring)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if pts.size == 0:
        raise ParamError(path, f"{what}: nothing to frame")
    if not np.isfinite(pts).all():
        raise ParamError(path, f"{what}: world-space geometry is not finite; it cannot be drawn")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    extent = float(np.max(hi - lo))
    reach = float(np.max(np.maximum(np.abs(lo), np.abs(hi))))
    if reach > MAX_FRAME_REACH:
        raise ParamError(path, f"{what}: reaches {reach:.3g} from the origin, beyond the {MAX_FRAME_REACH:.0e} "
                               "that 32-bit rendering can frame")
    if not extent > reach * MIN_FRAME_RATIO:
        raise ParamError(path, f"{what}: spans {extent:.3g} at {reach:.3g} from the origin, too small for 32-bit "
                               f"rendering to resolve (at least {MIN_FRAME_RATIO:g} of the distance): move it "
                               "nearer the origin or scale it up")


def check_leaf_framable(leaf: LeafParams, label: str | None = None) -> None:
    """:func:`check_framable` on a coarse grid of ``leaf`` placed by its transform, naming the leaf
    (``label``, default its name) and the field (``transform``, or ``shape`` when the leaf-space
    geometry itself is not finite). A lobed leaf is checked on its swept surface
    (:func:`leafview.botany.leaf_surface.grid_points`, the lobed grid drawn for 5 × 9), not on Ω."""
    what = f"leaf {label or leaf.name or '(unnamed)'}"
    if leaf.lobes.enabled:
        local = leaf_surface.grid_points(leaf, (5, 9))
    else:
        uv = grid_uv(5, 9).astype(np.float64)
        local = evaluate(leaf, uv[:, 0], uv[:, 1])
    if not np.isfinite(local).all():
        raise ParamError("shape", f"{what}: its surface is not finite; it cannot be drawn")
    m = leaf.transform.matrix()
    with np.errstate(over="ignore", invalid="ignore"):
        world = local @ m[:3, :3].T + m[:3, 3]
    check_framable(world, what, "transform")


def _top(lo: NDArray[np.float64], hi: NDArray[np.float64], w: int, h: int) -> Camera:
    extent = np.maximum(hi[:2] - lo[:2], 1e-9)
    scale = TOP_FILL * min(w / extent[0], h / extent[1])  # pixels per world unit
    return top_down((lo[:2] + hi[:2]) / 2, hi[2] + 1.0, w / (2 * scale), h / (2 * scale), (hi[2] - lo[2]) + 2.0)


@functools.lru_cache(maxsize=32)
def _orbit_axes(az_deg: float, el_deg: float, w: int, h: int) -> tuple[NDArray[np.float64], float, float]:
    """The orbit camera's axes (rows: right, up, back = towards the camera) and the tangents of
    the half field of view that ``ORBIT_FILL`` leaves, across and up; computed once per view and
    image shape (the axes are read-only)."""
    az, el = np.radians(az_deg), np.radians(el_deg)
    back = np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])  # towards camera
    right = np.array([-back[1], back[0], 0.0])   # -back × z
    right /= np.linalg.norm(right)
    up = np.cross(right, -back)
    tan_y = float(np.tan(np.radians(FOV_DEG) / 2) * ORBIT_FILL)
    basis = np.stack([right, up, back])
    basis.setflags(write=False)
    return basis, tan_y * w / h, tan_y


SCENE_VIEWS = ("three-quarter", "top", "front", "side", "ground")
GROUND_FOV_DEG = 50.0


class Bounded(Protocol):
    """Anything with world-space bounds, such as :class:`leafview.scene.spec.Scene`."""

    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...


def scene_camera(scene: Bounded, size: tuple[int, int], view: str = "three-quarter") -> Camera:
    """A camera for ``view``: the standard views frame the scene's bounding box; ``ground`` stands
    at the edge of the scene at 60 % of its height, looking across it (a walker's view, where
    leaves span from a few pixels to the whole image)."""
    lo, hi = scene.bounds()
    return box_camera(lo, hi, size, view)


def box_camera(lo: NDArray[np.float64], hi: NDArray[np.float64], size: tuple[int, int],
               view: str = "three-quarter") -> Camera:
    """:func:`scene_camera` for a world box (``lo``, ``hi``) already computed, such as a scene
    renderer's ``bounds``."""
    if view not in SCENE_VIEWS:
        raise ValueError(f"unknown view {view!r} (choose from {', '.join(SCENE_VIEWS)})")
    if view != "ground":
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        return frame_view(view, corners, size)
    center = (lo + hi) / 2
    extent = hi - lo
    eye = np.array([center[0], lo[1] - 0.15 * extent[1], lo[2] + 0.6 * extent[2]])
    target = np.array([center[0], center[1], lo[2] + 0.35 * extent[2]])
    far = float(np.linalg.norm(extent)) * 2 + 10.0
    return look_at(eye, target, size[0] / size[1], 0.05, far, fov_deg=GROUND_FOV_DEG)


RING_FOV_DEG = 40.0
RING_ELEVATIONS = (25.0, 50.0)
MAX_RING_ELEVATION = 85.0   # look_at keeps +z up: the pole itself has no "up"


def ring_angles(count: int, elevations: Sequence[float] = RING_ELEVATIONS,
                azimuth_deg: float = 0.0) -> list[tuple[float, float]]:
    """(azimuth, elevation) in degrees of ``count`` views on a ring: azimuths evenly spaced from
    ``azimuth_deg`` (0: from the -y side, like the ``front`` view; increasing towards +x), view
    ``k`` at ``elevations[k % len(elevations)]`` (alternating rows for two elevations).

    Raises ValueError for a count below 1, no elevation, or one that is not finite or beyond
    ±:data:`MAX_RING_ELEVATION`."""
    if int(count) < 1:
        raise ValueError(f"a ring needs at least 1 view, got {count}")
    els = [float(e) for e in elevations]
    if not els:
        raise ValueError("a ring needs at least one elevation")
    for e in els:
        if not (np.isfinite(e) and abs(e) <= MAX_RING_ELEVATION):
            raise ValueError(f"elevation {e:g}° outside ±{MAX_RING_ELEVATION:g}°")
    return [((float(azimuth_deg) + 360.0 * k / int(count)) % 360.0, els[k % len(els)]) for k in range(int(count))]


def orbit_cameras(sphere: Bounded | tuple[ArrayLike, float], count: int, size: tuple[int, int],
                  elevations: Sequence[float] = RING_ELEVATIONS, *, fov_deg: float = RING_FOV_DEG,
                  azimuth_deg: float = 0.0) -> list[Camera]:
    """``count`` perspective cameras on a ring around a bounding sphere, each aimed at its centre
    (the angles of :func:`ring_angles`, +z up, ``fov_deg`` vertical field of view).

    ``sphere`` is ``(centre, radius)`` in world space, or anything :class:`Bounded` (its box's
    circumscribed sphere). Every camera stands at the distance where the sphere just fits the
    narrower of the two fields of view (``radius / sin(half angle)``), so whatever lies in the
    sphere is in every image; the clip planes hug the sphere (``near`` 2 % in front of it, ``far``
    2 % behind), which keeps the depth buffer's precision for the scene. Deterministic: the same
    arguments give the same matrices.

    Raises ValueError for a radius that is not positive and finite, a bad size or field of view,
    and :class:`~leafview.core.params.ParamError` for a sphere that float32 cannot frame
    (:func:`check_framable`)."""
    if isinstance(sphere, tuple):
        centre, radius = np.asarray(sphere[0], np.float64).reshape(3), float(sphere[1])
    else:
        lo, hi = (np.asarray(b, np.float64) for b in sphere.bounds())
        centre, radius = (lo + hi) / 2.0, float(np.linalg.norm(hi - lo)) / 2.0
    if not (np.isfinite(radius) and radius > 0.0 and np.isfinite(centre).all()):
        raise ValueError(f"the bounding sphere needs a finite centre and a positive radius, got {radius!r}")
    w, h = int(size[0]), int(size[1])
    if w <= 0 or h <= 0:
        raise ValueError(f"size must be positive, got {size!r}")
    if not 1.0 <= float(fov_deg) <= 170.0:
        raise ValueError(f"field of view must be in [1°, 170°], got {fov_deg}")
    check_framable(centre + radius * np.vstack([np.eye(3), -np.eye(3)]), "the scene", "transform")
    half_v = np.radians(float(fov_deg)) / 2.0
    half = min(half_v, float(np.arctan(np.tan(half_v) * w / h)))
    dist = radius / np.sin(half)
    near, far = (dist - radius) * 0.98, (dist + radius) * 1.02
    cameras = []
    for az_deg, el_deg in ring_angles(count, elevations, azimuth_deg):
        az, el = np.radians(az_deg), np.radians(el_deg)
        back = np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])  # towards the camera
        cameras.append(look_at(centre + dist * back, centre, w / h, near, far, fov_deg=float(fov_deg)))
    return cameras
