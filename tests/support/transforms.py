"""Small transforms the tests build scenes with."""

from __future__ import annotations

import numpy as np


def axis_rotation(axis: int, angle: float) -> np.ndarray:
    """4×4 rotation by ``angle`` (radians) about coordinate axis ``axis`` (0 x, 1 y, 2 z)."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = [k for k in range(3) if k != axis]
    m = np.eye(4)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m
