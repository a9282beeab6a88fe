"""The sRGB transfer function (IEC 61966-2-1), the one numpy place for it.

:func:`srgb_to_linear` is the twin of ``srgb_to_linear`` in ``shaders/leaf_texture.glsl`` (texture
files are sRGB), :func:`linear_to_srgb` of ``linear_to_srgb`` in ``shaders/color.glsl`` (what
``leaf.frag`` writes); both follow GLSL's ``step``: the linear segment strictly below the knee.
The photo fit, the capture's leaf colours and the benchmarks use the same two functions.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["srgb_to_linear", "linear_to_srgb"]


def srgb_to_linear(c: ArrayLike) -> NDArray[np.float64]:
    """The sRGB decoding of values in [0, 1]."""
    x = np.asarray(c, np.float64)
    return np.where(x < 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c: ArrayLike) -> NDArray[np.float64]:
    """The sRGB encoding of linear values (clamped to [0, 1])."""
    x = np.clip(np.asarray(c, np.float64), 0.0, 1.0)
    return np.where(x < 0.0031308, 12.92 * x, 1.055 * x ** (1.0 / 2.4) - 0.055)
