"""Thumbnails of leaves and scenes for Jupyter's rich display: the renderers behind
``LeafParams._repr_png_`` and ``Scene._repr_png_`` (:mod:`leafview.core.display`).

They draw on the shared headless renderer (:func:`leafview.gpu.default_renderer`: one EGL
context per process, its programs and render targets) and need no notebook package, so a leaf
shows as a picture in any Jupyter kernel where leafview and OpenGL are installed.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.core.params import LeafParams
from leafview.export.images import png_bytes
from leafview.gpu import default_renderer
from leafview.gpu.scene import SceneRenderer
from leafview.scene.camera import scene_camera
from leafview.scene.spec import Scene

__all__ = ["THUMBNAIL_SIZE", "THUMBNAIL_VIEW", "leaf_thumbnail", "scene_thumbnail", "leaf_png", "scene_png"]

THUMBNAIL_SIZE = (256, 256)
THUMBNAIL_VIEW = "three-quarter"


def leaf_thumbnail(params: LeafParams, size: tuple[int, int] = THUMBNAIL_SIZE,
                   view: str = THUMBNAIL_VIEW) -> NDArray[np.uint8]:
    """``params`` framed in ``view``: (h, w, 4) uint8 RGBA, transparent around the leaf."""
    image: NDArray[np.uint8] = default_renderer().render(params, size, view)
    return image


def scene_thumbnail(scene: Scene, size: tuple[int, int] = THUMBNAIL_SIZE,
                    view: str = THUMBNAIL_VIEW) -> NDArray[np.uint8]:
    """``scene`` from :func:`~leafview.scene.camera.scene_camera` ``view``: (h, w, 4) uint8 RGBA,
    transparent behind the plants. The scene's GPU rows live only for this call."""
    shared = default_renderer()
    with SceneRenderer(shared.ctx, scene, resources=shared.resources) as renderer:
        return renderer.render(scene_camera(scene, size, view), size)


def leaf_png(params: Any) -> bytes:
    """:func:`leaf_thumbnail` as PNG bytes (registered for ``"leaf"`` by ``import leafview``)."""
    return png_bytes(leaf_thumbnail(params))


def scene_png(scene: Any) -> bytes:
    """:func:`scene_thumbnail` as PNG bytes (registered for ``"scene"`` by ``import leafview``)."""
    return png_bytes(scene_thumbnail(scene))
