"""The secondary veins of a pinnate vein tree as a family of curves in vein space, for reading
them back from pictures (:mod:`leafview.fit.photo_veins`).

:mod:`leafview.botany.venation` traces a secondary from the midrib at angle θ (opened towards 90°
near the base, :func:`departure`), its heading θ (1 - c min(s/ℓ, 1)) at arc length s, ℓ the
length of the straight vein to the margin (:func:`reach`). That is a circular arc up to ℓ and a
straight line after, in closed form (:func:`curve`, and inverted, :func:`rise`), and every vein of
the family is the one of ℓ = 1 scaled by ℓ. :func:`family_misfit` says how far given polylines lie
from the family of each (θ, c). Vein space is q = (u · w(v), v)
(:mod:`leafview.botany.vein_space`); x here is the distance from the midrib (x ≥ 0 outwards).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from leafview.botany.venation import BASAL_ANGLE, basal_lift

__all__ = ["CLEAR", "OUTER", "departure", "reach", "curve", "rise", "family_misfit"]

CLEAR = 0.012                       # leaf lengths about the midrib's centre line where veins are not looked at
OUTER = 0.7                         # fitted veins count out to this fraction of the half-width

F64 = NDArray[np.float64]


def departure(theta: F64 | float, y0: F64) -> F64:
    """The angle (radians) at which a secondary of the tree with ``angle`` θ leaves the midrib at
    v = ``y0``: θ, opened up towards 90° below v = 0.3 (:mod:`leafview.botany.venation`: the
    basal secondaries fill the base of the blade). Broadcasts."""
    return np.asarray(theta + (math.radians(BASAL_ANGLE) - np.asarray(theta)) * basal_lift(y0), np.float64)


def reach(w: F64, y0: F64, theta: F64) -> F64:
    """ℓ (len(theta), n0): the length of the straight vein from (0, y0) at ``theta`` from the
    midrib to the margin |x| = w(y) (or to v = 1); ``w`` (rows,) at the row centres. ``theta``
    (nt,) holds for every origin, (nt, n0) gives each its own; ``y0`` is (n0,) or (nt, n0)."""
    rows = len(w)
    lam = np.arange(0.0, 1.2, 0.02)
    th = theta[:, None] if theta.ndim == 1 else theta
    y0 = np.broadcast_to(y0, (len(theta), y0.shape[-1]))
    y = y0[..., None] + lam * np.cos(th)[..., None]
    out = np.maximum(lam * np.sin(th)[..., None] - w[np.clip((y * rows).astype(np.intp), 0, rows - 1)], y - 1.0)
    out[..., 0] = -1.0
    hit = out > 0.0
    j = np.where(hit.any(axis=-1), hit.argmax(axis=-1), len(lam) - 1)
    f0 = np.take_along_axis(out, np.maximum(j - 1, 0)[..., None], -1)[..., 0]
    f1 = np.take_along_axis(out, j[..., None], -1)[..., 0]
    t = np.clip(f0 / np.where(f1 != f0, f0 - f1, -1.0), 0.0, 1.0)
    return np.asarray(np.maximum(lam[np.maximum(j - 1, 0)] + 0.02 * t, 0.02), np.float64)


def curve(theta: F64 | float, curv: F64 | float, frac: F64) -> tuple[F64, F64]:
    """(x, y) from its departure point of the secondary with ℓ = 1 at arc length ``frac``: the
    heading θ (1 - c min(s/ℓ, 1)) of :mod:`leafview.botany.venation` integrated in closed form (a
    circular arc up to ℓ, straight after); a vein of another ℓ is this one scaled by ℓ. The
    arguments broadcast."""
    k = np.multiply(theta, curv)
    f = np.minimum(frac, 1.0)
    alpha = theta * (1.0 - np.multiply(curv, f))
    bent = np.abs(k) > 1e-6
    r = 1.0 / np.where(bent, k, 1.0)
    xa = np.where(bent, r * (np.cos(alpha) - np.cos(theta)), f * np.sin(theta))
    ya = np.where(bent, r * (np.sin(theta) - np.sin(alpha)), f * np.cos(theta))
    rest = np.maximum(frac - 1.0, 0.0)
    return xa + rest * np.sin(alpha), ya + rest * np.cos(alpha)


def rise(theta: F64, curv: F64, u: F64) -> tuple[F64, F64]:
    """(y, sine of the heading) of the secondary with ℓ = 1 where it is ``u`` out from its
    departure point: :func:`curve` inverted in closed form (cos α = cos θ + θ c u on the arc,
    straight at θ (1 - c) beyond); NaN where the vein never gets that far out. Broadcasts."""
    k = theta * curv
    bent = np.abs(k) > 1e-6
    kk = np.where(bent, k, 1.0)
    end = theta * (1.0 - curv)                                              # heading past ℓ
    x1 = np.where(bent, (np.cos(end) - np.cos(theta)) / kk, np.sin(theta))  # x at s = ℓ
    y1 = np.where(bent, (np.sin(theta) - np.sin(end)) / kk, np.cos(theta))
    on_arc = u <= x1
    alpha = np.where(on_arc, np.arccos(np.clip(np.cos(theta) + k * u, -1.0, 1.0)), end)
    y_arc = np.where(bent, (np.sin(theta) - np.sin(alpha)) / kk, u / np.maximum(np.tan(theta), 1e-9))
    y = np.where(on_arc, y_arc, y1 + (u - x1) / np.maximum(np.tan(end), 1e-9))
    y = np.where(u > x1 + 2.0 * np.sin(end), np.nan, y)                     # beyond 3 ℓ of vein
    return y, np.sin(alpha)


def family_misfit(lines: Sequence[F64], w: F64, thetas: F64, curvs: F64) -> F64:
    """How far the polylines ``lines`` (one side's veins in vein space, x ≥ 0 outwards; they need
    not reach the midrib) lie across from the tree's secondaries of each (θ, c): the RMS (leaf
    lengths; (len(thetas), len(curvs))) with each line matched to its best family member (its
    departure point free) and the worst tenth of the residuals dropped. Points from
    2 · :data:`CLEAR` out to :data:`OUTER` of the half-width count. ``w`` (rows,): the side's
    half-width at the row centres.

    The family vein leaving at y₀ is y = y₀ + ℓ Y(x/ℓ) (:func:`rise`), its departure angle from
    :func:`departure` and ℓ from :func:`reach` at the y₀ of the straight vein at that angle
    through the line's first point; points it never gets out to count 0.05."""
    rows = len(w)
    pts, ids = [], []
    for i, line in enumerate(lines):
        half = w[np.clip((line[:, 1] * rows).astype(np.intp), 0, rows - 1)]
        keep = (line[:, 0] >= 2.0 * CLEAR) & (line[:, 0] <= OUTER * half)
        pts.append(line[keep])
        ids.append(np.full(int(keep.sum()), i))
    out = np.full((len(thetas), len(curvs)), np.inf)
    p = np.concatenate(pts) if pts else np.zeros((0, 2))
    if len(p) < 6:
        return out
    idx = np.concatenate(ids)
    n, nc = len(lines), len(curvs)
    counts = np.maximum(np.bincount(idx, None, n), 1)
    first = np.array([q[0] if len(q) else (0.0, 0.0) for q in pts])
    theta = np.broadcast_to(thetas[:, None], (len(thetas), n))
    for _ in range(3):                       # the departure angle depends on y₀ near the base
        y0 = np.clip(first[None, :, 1] - first[None, :, 0] / np.tan(theta), 0.0, 1.0)      # (nt, n)
        theta = departure(thetas[:, None], y0)
    ell = reach(w, y0, theta)[:, idx][:, None, :]                                             # (nt, 1, points)
    y, sine = rise(theta[:, idx][:, None, :], curvs[None, :, None], p[None, None, :, 0] / ell)
    r = p[:, 1] - ell * y                                                                      # (nt, nc, points)
    far = np.isnan(r)
    r = np.where(far, 0.0, r)
    group = (idx + n * np.arange(len(thetas) * nc)[:, None]).ravel()
    r -= (np.bincount(group, r.ravel(), n * len(thetas) * nc).reshape(len(thetas), nc, n) / counts)[..., idx]
    r = np.where(far, 0.05, r * sine)                                                          # across the vein
    best = max(int(0.9 * len(p)), 1)
    return np.asarray(np.sqrt(np.partition(r * r, best - 1, axis=-1)[..., :best].mean(axis=-1)), np.float64)
