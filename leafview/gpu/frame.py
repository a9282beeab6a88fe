"""The Frame uniform block (camera, lights, output flags) and the buffer each renderer keeps it in.

Every renderer draws with its own camera, so each owns one :class:`FrameUniforms`; the packing
(:data:`~leafview.gpu.layout.FRAME_BLOCK`) and the default lights are shared.
"""

from __future__ import annotations

import moderngl
import numpy as np

from leafview.gpu.layout import FRAME_BINDING, FRAME_BLOCK
from leafview.scene.camera import Camera

__all__ = ["Lighting", "fill_frame", "unit_lights", "FrameUniforms"]


class Lighting:
    """Default key + fill lights (world space, directions towards the light) and ambient."""

    key = (0.35, -0.45, 0.82, 1.05)
    fill = (-0.65, 0.45, 0.45, 0.35)
    ambient = (0.16, 0.17, 0.18)


def fill_frame(record: np.ndarray, camera: Camera, *, srgb: bool, flat: bool = False,
               lighting: type[Lighting] = Lighting, size: tuple[int, int] | None = None) -> None:
    """Fill a FRAME_BLOCK record: camera matrices (column-major), lights and output flags; ``size``
    (width, height) of the image, whose height sets the veins' level of detail (``flags.z``; None:
    unknown, veins always at full detail)."""
    record["view"] = camera.view.T
    record["proj"] = camera.proj.T
    record["eye"] = camera.eye
    record["key"] = lighting.key
    record["fill"] = lighting.fill
    unit_lights(record)   # leaf.frag takes the directions as they are: no normalize per fragment
    record["ambient"][:3] = lighting.ambient
    record["flags"] = (int(srgb), int(flat), 0 if size is None else int(size[1]), 0)


def unit_lights(frames: np.ndarray) -> None:
    """Normalise the key and fill lights' directions of FRAME_BLOCK records in place (their
    strengths, the w components, unchanged; a zero direction stays zero)."""
    for name in ("key", "fill"):
        d = frames[name][..., :3].astype(np.float64)
        frames[name][..., :3] = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-30)


class FrameUniforms:
    """One Frame uniform block: :meth:`set_camera` writes it (208 bytes), :meth:`bind` binds it
    at ``FRAME_BINDING``."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.record = FRAME_BLOCK.zeros()
        self.buffer = ctx.buffer(reserve=FRAME_BLOCK.nbytes)
        self._sized = False

    def set_camera(self, camera: Camera, *, srgb: bool = True, flat: bool = False,
                   lighting: type[Lighting] = Lighting, size: tuple[int, int] | None = None) -> None:
        """Write the block; without ``size``, :meth:`fit_viewport` takes the image height (the
        veins' level of detail) from the viewport of each draw."""
        fill_frame(self.record, camera, srgb=srgb, flat=flat, lighting=lighting, size=size)
        self._sized = size is not None
        self.buffer.write(self.record.tobytes())

    def fit_viewport(self) -> None:
        """Unless :meth:`set_camera` was given the image size, make the block's image height that
        of the current viewport (a draw into a window or target set up by the caller)."""
        if self._sized:
            return
        height = int(self.ctx.viewport[3])
        if int(self.record["flags"][2]) != height:
            self.record["flags"][2] = height
            self.buffer.write(self.record.tobytes())

    def bind(self) -> None:
        self.buffer.bind_to_uniform_block(FRAME_BINDING)

    def release(self) -> None:
        """Release the buffer (idempotent)."""
        self.buffer.release()
