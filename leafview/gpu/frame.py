"""The Frame uniform block (camera, lights, output flags) and the buffer each renderer keeps it in.

Every renderer draws with its own camera, so each owns one :class:`FrameUniforms`; the packing
(:data:`~leafview.gpu.layout.FRAME_BLOCK`) and the default lights are shared.
"""

from __future__ import annotations

import moderngl
import numpy as np

from leafview.gpu.layout import FRAME_BINDING, FRAME_BLOCK
from leafview.scene.camera import Camera

__all__ = ["Lighting", "fill_frame", "FrameUniforms"]


class Lighting:
    """Default key + fill lights (world space, directions towards the light) and ambient."""

    key = (0.35, -0.45, 0.82, 1.05)
    fill = (-0.65, 0.45, 0.45, 0.35)
    ambient = (0.16, 0.17, 0.18)


def fill_frame(record: np.ndarray, camera: Camera, *, srgb: bool, flat: bool = False,
               lighting: type[Lighting] = Lighting) -> None:
    """Fill a FRAME_BLOCK record: camera matrices (column-major), lights and output flags."""
    record["view"] = camera.view.T
    record["proj"] = camera.proj.T
    record["eye"] = camera.eye
    record["key"] = lighting.key
    record["fill"] = lighting.fill
    record["ambient"][:3] = lighting.ambient
    record["flags"] = (int(srgb), int(flat), 0, 0)


class FrameUniforms:
    """One Frame uniform block: :meth:`set_camera` writes it (208 bytes), :meth:`bind` binds it
    at ``FRAME_BINDING``."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.record = FRAME_BLOCK.zeros()
        self.buffer = ctx.buffer(reserve=FRAME_BLOCK.nbytes)

    def set_camera(self, camera: Camera, *, srgb: bool = True, flat: bool = False,
                   lighting: type[Lighting] = Lighting) -> None:
        fill_frame(self.record, camera, srgb=srgb, flat=flat, lighting=lighting)
        self.buffer.write(self.record.tobytes())

    def bind(self) -> None:
        self.buffer.bind_to_uniform_block(FRAME_BINDING)

    def release(self) -> None:
        """Release the buffer (idempotent)."""
        self.buffer.release()
