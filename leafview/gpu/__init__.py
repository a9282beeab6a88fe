"""Everything that touches OpenGL: contexts, shader loading, the data layout, the shared GPU
resources, the leaf, instanced and scene renderers, readback.

The module-level :func:`render` and :func:`evaluate` use one process-wide headless renderer,
created on first use and released by :func:`shutdown` (also registered with ``atexit``); its
:class:`GpuResources` are shared by the other module-level helpers (sheets, morph frames).
"""

from __future__ import annotations

import atexit
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.params import LeafParams
from leafview.gpu.context import GLUnavailable, check_error, create_headless_context
from leafview.gpu.renderer import DEFAULT_GRID, LeafRenderer
from leafview.gpu.resources import GpuResources
from leafview.gpu.shaders import ShaderError

__all__ = ["LeafRenderer", "GpuResources", "GLUnavailable", "ShaderError", "create_headless_context", "check_error",
           "default_renderer", "render", "evaluate", "shutdown", "DEFAULT_GRID", "gpu_fbm_noise"]

_default: LeafRenderer | None = None


def default_renderer() -> LeafRenderer:
    """The shared headless renderer (created on first use)."""
    global _default
    if _default is None:
        _default = LeafRenderer()
    return _default


def shutdown() -> None:
    """Release the shared renderer and its context."""
    global _default
    if _default is not None:
        _default.release()
        _default = None


atexit.register(shutdown)


def render(params: LeafParams, size: Any = (256, 256), view: str = "top",
           background: ArrayLike | None = None, **kwargs: Any) -> NDArray[Any]:
    """Render one leaf offscreen: (h, w, 4) uint8 RGBA, sRGB, row 0 at the top.

    See :meth:`LeafRenderer.render` for ``grid``, ``samples`` and ``linear``.
    """
    return default_renderer().render(params, size, view, background, **kwargs)


def evaluate(params: LeafParams, u: ArrayLike, v: ArrayLike) -> NDArray[np.float32]:
    """Positions computed by the rendering vertex shader for grid parameters (u, v), (N, 3)
    float32: L_Ω(u, v), or for a one-sided leaf (``shape.half = ±1``) L_Ω at
    :func:`leafview.deform.surface.drawn_uv` of (u, v)."""
    return default_renderer().capture(params, u, v)[0]


def gpu_fbm_noise(n: int, beta: float, seed: int) -> NDArray[np.float32]:
    """One fBm signal (Geng, Hu & Zhang 2014, eqs 1-2) from the compute pass on the shared headless
    context, float32; :func:`leafview.fbm_noise` with ``backend="gpu"``."""
    rp = default_renderer().resources.ripple_pass(n)
    try:
        rp.update([(seed, beta)])
        return rp.read(0)
    finally:
        rp.release()
