"""Closed uniform cubic B-splines: the margin of a lobed leaf (Mündermann et al. 2003, sec. 3.1,
the silhouette as a closed B-spline; Garg & Leow 2011, sec. 5, the multilobed margin).

A closed curve of M control points c_0 … c_{M-1} is parametrised by t in [0, 1): with x = t M,
i = floor(x) and f = x - i, its point is the uniform cubic B-spline segment

    C(t) = [(1 - f)^3 c_{i-1} + (3f^3 - 6f^2 + 4) c_i + (-3f^3 + 3f^2 + 3f + 1) c_{i+1} + f^3 c_{i+2}] / 6

with indices taken modulo M. The curve is C² everywhere and lies in the convex hull of each four
consecutive control points. :func:`fit_closed` finds the control points of M segments that are
nearest, in the least-squares sense, to a closed polyline (the inverse of sampling: Mündermann et
al. reduce a traced silhouette to a B-spline the same way, by least-squares reversal of
subdivision), with the parameters corrected by projection a few times.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["basis", "basis_dt", "evaluate_closed", "derivative_closed", "sample_closed", "fit_closed",
           "signed_area", "MIN_CONTROLS", "MAX_CONTROLS"]

MIN_CONTROLS = 8      # control points of a closed margin, at least
MAX_CONTROLS = 512    # and at most


def basis(f: ArrayLike) -> NDArray[np.float64]:
    """The four uniform cubic B-spline weights at segment fraction ``f``, shape ``f.shape + (4,)``."""
    f = np.asarray(f, dtype=np.float64)[..., None]
    f2, f3 = f * f, f * f * f
    w = np.concatenate([(1.0 - f) ** 3, 3.0 * f3 - 6.0 * f2 + 4.0, -3.0 * f3 + 3.0 * f2 + 3.0 * f + 1.0, f3], axis=-1)
    return w / 6.0


def basis_dt(f: ArrayLike) -> NDArray[np.float64]:
    """d/df of :func:`basis`."""
    f = np.asarray(f, dtype=np.float64)[..., None]
    f2 = f * f
    w = np.concatenate([-3.0 * (1.0 - f) ** 2, 9.0 * f2 - 12.0 * f, -9.0 * f2 + 6.0 * f + 3.0, 3.0 * f2], axis=-1)
    return w / 6.0


def _segments(m: int, t: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    x = np.mod(t, 1.0) * m
    i = np.minimum(np.floor(x).astype(np.int64), m - 1)
    return i, x - i


def _gather(ctrl: NDArray[np.float64], i: NDArray[np.int64]) -> NDArray[np.float64]:
    m = len(ctrl)
    idx = (i[..., None] + np.arange(-1, 3)) % m
    return ctrl[idx]                          # (..., 4, dim)


def evaluate_closed(ctrl: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """Points C(t) of the closed curve, shape ``t.shape + (dim,)``; t is taken modulo 1."""
    c = np.asarray(ctrl, dtype=np.float64)
    i, f = _segments(len(c), np.asarray(t, dtype=np.float64))
    return np.einsum("...k,...kd->...d", basis(f), _gather(c, i))


def derivative_closed(ctrl: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """dC/dt (t in [0, 1): the segment derivative times M)."""
    c = np.asarray(ctrl, dtype=np.float64)
    i, f = _segments(len(c), np.asarray(t, dtype=np.float64))
    return len(c) * np.einsum("...k,...kd->...d", basis_dt(f), _gather(c, i))


def sample_closed(ctrl: ArrayLike, n: int) -> NDArray[np.float64]:
    """``n`` points at t = k / n (the closing point is not repeated)."""
    return evaluate_closed(ctrl, np.arange(n) / n)


def signed_area(points: ArrayLike) -> float:
    """Shoelace area of a closed polyline: positive when counter-clockwise."""
    p = np.asarray(points, dtype=np.float64)
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _chord_params(p: NDArray[np.float64]) -> NDArray[np.float64]:
    seg = np.linalg.norm(np.diff(np.vstack([p, p[:1]]), axis=0), axis=1)
    total = float(seg.sum())
    if not total > 0.0:
        raise ValueError("a closed outline needs at least two distinct points")
    return np.concatenate([[0.0], np.cumsum(seg)[:-1]]) / total


def _design(m: int, t: NDArray[np.float64]) -> NDArray[np.float64]:
    i, f = _segments(m, t)
    a = np.zeros((len(t), m))
    rows = np.repeat(np.arange(len(t)), 4)
    cols = ((i[:, None] + np.arange(-1, 3)) % m).ravel()
    np.add.at(a, (rows, cols), basis(f).ravel())
    return a


def fit_closed(points: ArrayLike, m: int, *, iterations: int = 4, smooth: float = 1e-6) -> NDArray[np.float64]:
    """Control points (m, 2) of the closed uniform cubic B-spline nearest to the closed polyline
    ``points`` (n, 2), n >= m: linear least squares on chord-length parameters, then
    ``iterations`` rounds of moving each parameter to its point's foot on the curve (one Newton
    step) and solving again. ``smooth`` weights a second-difference penalty on the control points
    (relative to the data term), which keeps sparse stretches of the polyline from ringing.
    The first control segment starts at ``points[0]``'s parameter, t = 0."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"expected (n, 2) points, got shape {p.shape}")
    if not MIN_CONTROLS <= m <= MAX_CONTROLS:
        raise ValueError(f"{m} control points: a closed margin has {MIN_CONTROLS}-{MAX_CONTROLS}")
    if len(p) < m:
        raise ValueError(f"{len(p)} outline points cannot fix {m} control points")
    t = _chord_params(p)
    d2 = np.zeros((m, m))
    for k in range(m):
        d2[k, [(k - 1) % m, k, (k + 1) % m]] = (1.0, -2.0, 1.0)
    reg = np.sqrt(smooth * len(p)) * d2
    ctrl = np.zeros((m, 2))
    for it in range(iterations + 1):
        a = np.vstack([_design(m, t), reg])
        b = np.vstack([p, np.zeros((m, 2))])
        ctrl = np.linalg.lstsq(a, b, rcond=None)[0]
        if it == iterations:
            break
        c = evaluate_closed(ctrl, t)
        d = derivative_closed(ctrl, t)
        step = np.sum((p - c) * d, axis=1) / np.maximum(np.sum(d * d, axis=1), 1e-30)
        t = t + np.clip(step, -0.5 / m, 0.5 / m)
        t[0] = 0.0                               # the curve starts at the first point
        t = np.mod(t, 1.0)
    return ctrl
