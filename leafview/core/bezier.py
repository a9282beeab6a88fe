"""Bézier curves in power-basis form (Chaurasia & Beardsley 2017, eq. 1) and their derivatives.

A degree-n curve is ``B(t) = [1, t, ..., t^n] · Z · [b_0 ... b_n]^T`` where ``Z`` holds
the Bernstein coefficients. The same basis is written in ``shaders/bezier.glsl``; tests compare
the two through the leaf evaluator.
"""

from __future__ import annotations

from functools import lru_cache
from math import comb

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["bernstein", "bernstein_matrix", "evaluate_curve", "derivative_points", "in_plane_normal"]


def bernstein_matrix(n: int) -> NDArray[np.float64]:
    """The (n+1)×(n+1) matrix ``Z`` of eq. 1: row k holds the coefficients of t^k.

    ``Z[k, i] = C(n, i) C(n-i, k-i) (-1)^(k-i)`` for ``k >= i``; for n = 3 it is the matrix of eq. 6.
    """
    z = np.zeros((n + 1, n + 1))
    for i in range(n + 1):
        for k in range(i, n + 1):
            z[k, i] = comb(n, i) * comb(n - i, k - i) * (-1) ** (k - i)
    return z


def bernstein(n: int, t: ArrayLike) -> NDArray[np.float64]:
    """Bernstein basis values ``B_{i,n}(t)``, shape ``t.shape + (n+1,)``."""
    t = np.asarray(t, dtype=np.float64)[..., None]
    i, coeff = _basis_consts(n)
    return coeff * t**i * (1.0 - t) ** (n - i)


@lru_cache(maxsize=16)
def _basis_consts(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    i = np.arange(n + 1, dtype=np.float64)
    return i, np.array([comb(n, k) for k in range(n + 1)], dtype=np.float64)


def evaluate_curve(points: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """Evaluate the Bézier curve with control points ``points`` (n+1, d) at ``t``.

    Batched control points ``(..., n+1, d)`` broadcast against ``t`` of shape ``(...)``.
    """
    p = np.asarray(points, dtype=np.float64)
    basis = bernstein(p.shape[-2] - 1, t)
    return np.einsum("...i,...id->...d", basis, p)


def derivative_points(points: ArrayLike) -> NDArray[np.float64]:
    """Control points of the hodograph: ``B'(t)`` is the degree n-1 curve ``n (b_{i+1} - b_i)``."""
    p = np.asarray(points, dtype=np.float64)
    n = p.shape[-2] - 1
    return n * (p[..., 1:, :] - p[..., :-1, :])


def in_plane_normal(d1: ArrayLike, d2: ArrayLike, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The unit in-plane normal ``n = normalize((-A'_y, A'_x, 0))`` of a curve (Chaurasia &
    Beardsley 2017, eq. 2) and ``dn/dt``, (N, 3) each, from ``d1 = A'(t)`` and ``d2 = A''(t)``
    ((N, 3)). Where the tangent vanishes (a midrib whose a1 sits on the base, or a2 on the apex)
    its limit direction, +A'' towards t = 0 and -A'' towards t = 1, stands in, with dn = 0. The
    twin of ``in_plane_normal`` in ``shaders/bezier.glsl``."""
    a = np.asarray(d1, np.float64)
    b = np.asarray(d2, np.float64)
    m = np.stack([-a[:, 1], a[:, 0], np.zeros(len(a))], axis=-1)
    dm = np.stack([-b[:, 1], b[:, 0], np.zeros(len(b))], axis=-1)
    flat = (np.linalg.norm(m, axis=-1) < 1e-12)[:, None]
    if flat.any():
        sign = np.where(np.asarray(t, np.float64).reshape(-1) < 0.5, 1.0, -1.0)[:, None]
        m = np.where(flat, sign * dm, m)
        dm = np.where(flat, 0.0, dm)
    mlen = np.linalg.norm(m, axis=-1, keepdims=True)
    n = m / mlen
    return n, (dm - n * np.sum(n * dm, axis=-1, keepdims=True)) / mlen
