"""Picking leaves of a scene: by a click (the leaf drawn at a pixel) or by a box (the leaves drawn
inside it, or every leaf whose base projects into it, visible or not).

The GPU picks read the label pass of :mod:`leafview.gpu.aov` (``instance`` = the scene's leaf index
+ 1, 0 for background and stems), drawn with the same culling and level of detail as the picture,
so a pick returns the leaf the user sees at that pixel. Pixel coordinates: ``x`` right, ``y`` down,
row 0 at the top (the viewer's mouse coordinates, in framebuffer pixels); a box is
``(x0, y0, x1, y1)`` in the same coordinates, corners in any order, both ends included.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.gpu.aov import render_aovs
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.scene.camera import Camera
from leafview.scene.spec import Scene

__all__ = ["pick", "pick_box", "pick_box_centres", "instance_image"]

_DEFAULT = CullSettings()


def instance_image(renderer: SceneRenderer, camera: Camera, size: tuple[int, int],
                   settings: CullSettings = _DEFAULT) -> NDArray[np.uint32]:
    """(h, w) uint32: leaf index + 1 at each pixel (0: background or stem), from the label pass."""
    image = render_aovs(renderer, camera, size, ("instance",), settings=settings).instance
    assert image is not None
    return image


def pick(renderer: SceneRenderer, camera: Camera, size: tuple[int, int], x: float, y: float,
         settings: CullSettings = _DEFAULT) -> int | None:
    """The index of the leaf drawn at pixel (``x``, ``y``) of a ``size`` = (w, h) view, or None
    (background, a stem, or outside the view)."""
    w, h = int(size[0]), int(size[1])
    i, j = int(np.floor(x)), int(np.floor(y))
    if not (0 <= i < w and 0 <= j < h):
        return None
    k = int(instance_image(renderer, camera, (w, h), settings)[j, i])
    return k - 1 if k > 0 else None


def _box(box: Any, size: tuple[int, int]) -> tuple[int, int, int, int] | None:
    """(i0, j0, i1, j1) half-open pixel ranges of ``box`` clipped to the view; None when empty."""
    x0, y0, x1, y1 = (float(c) for c in box)
    i0, i1 = sorted((int(np.floor(x0)), int(np.floor(x1))))
    j0, j1 = sorted((int(np.floor(y0)), int(np.floor(y1))))
    i0, j0 = max(i0, 0), max(j0, 0)
    i1, j1 = min(i1 + 1, int(size[0])), min(j1 + 1, int(size[1]))
    return (i0, j0, i1, j1) if i0 < i1 and j0 < j1 else None


def pick_box(renderer: SceneRenderer, camera: Camera, size: tuple[int, int], box: Any,
             settings: CullSettings = _DEFAULT) -> NDArray[np.int64]:
    """Sorted indices of the leaves drawn (at least one pixel visible) inside ``box``."""
    b = _box(box, size)
    if b is None:
        return np.zeros(0, np.int64)
    i0, j0, i1, j1 = b
    ids = np.unique(instance_image(renderer, camera, size, settings)[j0:j1, i0:i1])
    return ids[ids > 0].astype(np.int64) - 1


def project(camera: Camera, points: NDArray[np.floating], size: tuple[int, int]
            ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """(n, 2) pixel coordinates (x right, y down; pixel i covers [i, i + 1)) of world ``points``
    and whether each lies inside the view volume (in front of the camera, between near and far)."""
    p = np.asarray(points, np.float64)
    clip = np.c_[p, np.ones(len(p))] @ (camera.proj @ camera.view).T
    wc = clip[:, 3]
    ok = wc > 1e-12
    ndc = clip[:, :3] / np.where(ok, wc, 1.0)[:, None]
    ok &= np.abs(ndc[:, 2]) <= 1.0
    xy = np.c_[(ndc[:, 0] + 1.0) * 0.5 * size[0], (1.0 - ndc[:, 1]) * 0.5 * size[1]]
    return xy, ok


def pick_box_centres(scene: Scene, camera: Camera, size: tuple[int, int], box: Any) -> NDArray[np.int64]:
    """Sorted indices of every leaf whose base (its matrix's translation) projects into ``box``,
    hidden or not (numpy; what a box selection through the canopy wants)."""
    b = _box(box, size)
    if b is None:
        return np.zeros(0, np.int64)
    i0, j0, i1, j1 = b
    xy, ok = project(camera, scene.matrices[:, :3, 3], size)
    inside = ok & (xy[:, 0] >= i0) & (xy[:, 0] < i1) & (xy[:, 1] >= j0) & (xy[:, 1] < j1)
    return np.flatnonzero(inside).astype(np.int64)
