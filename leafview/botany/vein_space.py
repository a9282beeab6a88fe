"""Vein space: q(u, v) = (u · w(v), v), where w(v) is the half-width of the flat blade at v, so that a
step in q is about the same length on the leaf across and along it. The vein tree
(:mod:`leafview.botany.venation`), the vein field (:mod:`leafview.botany.vein_field`) and the vein
shape (:mod:`leafview.botany.vein_shape`) measure angles and distances here; the vein field's
compute pass reads the same table (``shaders/vein_field.comp``)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.bezier import bernstein
from leafview.core.blade import control_polygons
from leafview.core.params import LeafParams

__all__ = ["HALFWIDTH_SAMPLES", "halfwidth_table", "halfwidth_at", "vein_space_of", "vein_space"]

HALFWIDTH_SAMPLES = 64
"""Samples of w(v) in the half-width table (v = k / 63), linearly interpolated."""
_ARC_SAMPLES = 16   # chords per half cross-section for the arc length of w(v)
_CROSS = bernstein(3, np.linspace(0.0, 1.0, _ARC_SAMPLES + 1))   # the cross-section's cubic basis


# -- vein space ---------------------------------------------------------------------------------------
def halfwidth_table(params: LeafParams, n: int = HALFWIDTH_SAMPLES) -> NDArray[np.float32]:
    """w(v) at v = k / (n - 1), k = 0..n-1, float32: the mean over the two sides of the arc length
    (:data:`_ARC_SAMPLES` chords) of the cross-section ``Σ B³_k(s) c_k(v)``, c = (A, F, G, S)
    (Chaurasia & Beardsley 2017, eqs 5-6), from the midrib (s = 0) to the margin (s = 1), of the
    blade without jitter, ripple or bending (the control polygons of
    :func:`leafview.core.blade.control_polygons`)."""
    if n < 2:
        raise ValueError(f"a half-width table needs at least 2 samples, got {n}")
    cp = control_polygons(params)
    v = np.linspace(0.0, 1.0, n)
    sides = np.concatenate([cp[name + side] for side in "+-" for name in "FGS"], axis=1)   # (N + 2, 18)
    curves = (bernstein(len(sides) - 1, v) @ sides).reshape(n, 2, 3, 3)                   # (v, side, F/G/S, xyz)
    axis = np.broadcast_to((bernstein(3, v) @ cp["A"])[:, None, None, :], (n, 2, 1, 3))
    c = np.concatenate([axis, curves], axis=2)                                            # (v, side, A/F/G/S, xyz)
    pts = np.swapaxes(c, 2, 3) @ _CROSS.T                                                 # (v, side, xyz, s)
    step = np.diff(pts, axis=3)
    arcs = np.sqrt((step * step).sum(axis=2)).sum(axis=-1)                                # (v, side)
    return arcs.mean(axis=1).astype(np.float32)


def halfwidth_at(table: NDArray[np.floating], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """w(v) linearly interpolated in ``table`` exactly as the shader does: x = v (n - 1),
    k = min(⌊x⌋, n - 2), w = t_k + (t_{k+1} - t_k)(x - k)."""
    tab = np.asarray(table, np.float64)
    x = np.clip(v, 0.0, 1.0) * (len(tab) - 1)
    k = np.minimum(np.floor(x).astype(np.int64), len(tab) - 2)
    return tab[k] + (tab[k + 1] - tab[k]) * (x - k)


def vein_space_of(table: ArrayLike, uv: ArrayLike) -> NDArray[np.float64]:
    """q = (u · w(v), v) of the points ``uv`` (..., 2) for the half-width ``table``."""
    p = np.asarray(uv, np.float64)
    tab = np.asarray(table, np.float32)
    if p.shape[-1:] != (2,):
        raise ValueError(f"uv must have shape (..., 2), got {p.shape}")
    return np.stack([p[..., 0] * halfwidth_at(tab, p[..., 1]), p[..., 1]], axis=-1)


def vein_space(params: LeafParams, uv: ArrayLike) -> NDArray[np.float64]:
    """q(u, v) = (u · w(v), v) of the points ``uv`` (..., 2) of the leaf ``params`` (see the module
    docstring)."""
    return vein_space_of(halfwidth_table(params), uv)
