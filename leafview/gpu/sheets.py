"""Drawing several leaves into one image with one instanced draw
(:class:`leafview.gpu.instanced.InstancedLeaves`), and a multilobed compound leaf (Garg & Leow
2011, sec. 5) as the one lobed leaf its parts join into (:mod:`leafview.botany.lobe_outline`:
one closed margin, swept by the shader)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.botany.lobe_outline import lobed_outline_params
from leafview.botany.lobes import LobedLeaf
from leafview.core.defaults import DETAIL_GRID
from leafview.core.params import LeafParams
from leafview.gpu import default_renderer
from leafview.gpu.context import check_error
from leafview.gpu.instanced import InstancedLeaves
from leafview.gpu.layout import pack_leaves, ripple_keys
from leafview.gpu.lobe_tables import LobeTables, lobed_grid
from leafview.gpu.renderer import LeafRenderer
from leafview.gpu.targets import unpremultiply
from leafview.gpu.textures import LeafTextures
from leafview.gpu.vein_draw import VeinDraw
from leafview.scene.camera import Camera, frame_view

__all__ = ["render_leaves", "render_lobed"]


def render_leaves(leaves: Sequence[LeafParams], size: tuple[int, int] = (256, 256), view: str = "top",
                  *, grid: tuple[int, int] = DETAIL_GRID, samples: int | None = None,
                  flat: bool = False, renderer: LeafRenderer | None = None,
                  camera: Camera | None = None, veins: bool = True) -> NDArray[np.uint8]:
    """Draw ``leaves`` (world placement from each one's transform) into one (h, w, 4) uint8 sRGB
    image with a transparent background, framed like :meth:`LeafRenderer.render` (top view: no
    multisampling; other views 4×), or by ``camera`` (:func:`leafview.scene.camera.frame_view`) when
    given; lobed leaves (``LeafParams.lobes``) from their sweep tables, all on the lobed grid of
    ``grid`` (:func:`~leafview.gpu.lobe_tables.lobed_grid`). ``flat``: unlit colours (tests); ``veins``: leaves whose venation is enabled show their
    veins (``--veins``). Draws with ``renderer``'s shared resources (default: the shared headless
    renderer's)."""
    resources = (renderer or default_renderer()).resources
    ctx = resources.ctx
    w, h = int(size[0]), int(size[1])
    if samples is None:
        samples = 0 if view == "top" else 4
    samples = min(samples, ctx.max_samples)
    textures = LeafTextures(ctx)
    vein_draw = VeinDraw(ctx, resources.programs)
    lobes = LobeTables(ctx)
    try:
        keys = textures.update(leaves)        # a missing or unreadable image: refused before anything is drawn
        lobe_layers = lobes.update(leaves)
        unlobed = [p for p, layer in zip(leaves, lobe_layers.tolist()) if layer < 0]
        vein_layers = np.full(len(leaves), -1, np.int32)
        vein_layers[lobe_layers < 0] = vein_draw.update(unlobed, enabled=veins)   # swept leaves have no veins
        if lobes.active:     # one grid for all: the lobed leaves' rows on their ties
            grid = lobed_grid(grid)
        records, tables = pack_leaves(leaves, textures=keys, vein_layers=vein_layers, lobe_layers=lobe_layers)
        with InstancedLeaves(ctx, records, grid, jitter_tables=tables, ripple_signals=ripple_keys(leaves),
                             resources=resources, textures=textures, veins=vein_draw, lobes=lobes) as inst:
            pos, _ = inst.capture()
            if camera is None:
                camera = frame_view(view, pos.reshape(-1, 3).astype(np.float64), (w, h))
            inst.set_camera(camera, flat=flat)
            target = resources.target((w, h), samples)
            target.use()
            target.clear()
            inst.draw()
            img: NDArray[np.uint8] = target.read()
            check_error(ctx, "multilobed leaf")
            ctx.disable(moderngl.DEPTH_TEST)
    finally:
        textures.release()
        vein_draw.release()
        lobes.release()
    return unpremultiply(img) if samples else img


def render_lobed(lobed: LobedLeaf, size: tuple[int, int] = (256, 256), view: str = "top", **kwargs: Any
                 ) -> NDArray[np.uint8]:
    """Render a multilobed compound leaf as one lobed leaf (its parts joined into one margin,
    :func:`~leafview.botany.lobe_outline.lobed_outline_params`); see :func:`render_leaves`."""
    return render_leaves([lobed_outline_params(lobed)], size, view, **kwargs)
