"""The minimum-volume enclosing ellipse of a point set (Khachiyan's algorithm) and the share of it a
leaf covers.

Chaurasia & Beardsley 2017 use the ellipse twice: its covered share is the "leaf confidence" of a
candidate leaf (sec. 4.1, Fig. 3), and in the model fit (sec. 5.1) its major-axis extremities give
base and apex and it weights the scanlines that fall short of it (eq. 10).

Decisions where the paper says nothing:

* Only the convex hull matters to the enclosing ellipse, so :func:`mvee` works on the hull's
  vertices (:class:`scipy.spatial.ConvexHull`), a few dozen points instead of thousands.
* Plain Khachiyan steps crawl once the ellipse nearly touches many points (thousands of steps,
  seconds, on a smooth leaf outline); Todd & Yildirim's away steps and, every few steps, a Newton
  solve of the optimality conditions on the current support finish the job in milliseconds. The
  iteration stops at Khachiyan's ε = ``tol``; the ellipse is then grown about its centre just
  enough to hold every point, so the result always encloses the input.
* :func:`occupancy` measures "the percentage of the enclosing ellipse occupied by the leaf" on a
  raster: cells of ``cell`` (default: twice the median nearest-neighbour spacing of the points)
  holding a point, dilated by one cell so that sampling gaps do not count as vacant, over the cells
  whose centres lie inside the ellipse.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError, cKDTree

from leafview.errors import ParamError

__all__ = ["Ellipse", "mvee", "occupancy", "MAX_OCCUPANCY_CELLS"]

_NEWTON_EVERY = 10          # Khachiyan steps between attempts at a Newton finish
MAX_OCCUPANCY_CELLS = 4_000_000   # raster size limit of occupancy(): the cell grows to stay below it

Arr = NDArray[np.float64]


@dataclass(frozen=True)
class Ellipse:
    """The ellipse (ellipsoid in 3-D) ``{x : (x - center)ᵀ shape (x - center) <= 1}``.

    Attributes
    ----------
    center
        (d,) its centre.
    shape
        (d, d) symmetric positive definite matrix; its eigenvalues are ``1 / radius²``.
    """

    center: Arr
    shape: Arr

    @property
    def dim(self) -> int:
        return int(self.center.shape[0])

    @property
    def axes(self) -> tuple[Arr, Arr]:
        """(radii sorted descending, unit directions as the columns of a (d, d) matrix)."""
        w, vecs = np.linalg.eigh(self.shape)      # ascending eigenvalues: descending radii
        return 1.0 / np.sqrt(w), vecs

    @property
    def area(self) -> float:
        """π a b in 2-D (the volume (4/3) π a b c in 3-D)."""
        radii, _ = self.axes
        return float(np.pi * np.prod(radii) * (4.0 / 3.0 if self.dim == 3 else 1.0))

    def major_extremities(self) -> Arr:
        """(2, d): the two ends of the major axis, ``center ∓ a · e₁``."""
        radii, vecs = self.axes
        e = vecs[:, 0] * radii[0]
        return np.stack([self.center - e, self.center + e])

    def level(self, points: ArrayLike) -> Arr:
        """``(x - center)ᵀ shape (x - center)`` of each point: 1 on the boundary, below 1 inside."""
        d = np.asarray(points, dtype=np.float64).reshape(-1, self.dim) - self.center
        return np.einsum("ni,ij,nj->n", d, self.shape, d)

    def contains(self, points: ArrayLike, slack: float = 0.0) -> NDArray[np.bool_]:
        """Boolean mask of the points inside the ellipse grown by the factor ``1 + slack``."""
        return self.level(points) <= (1.0 + slack) ** 2

    def ray_exit(self, origins: ArrayLike, directions: ArrayLike) -> Arr:
        """Distance ``t >= 0`` along each unit direction at which the ray leaves the ellipse (NaN
        where a ray that starts outside never meets it)."""
        o = np.asarray(origins, dtype=np.float64).reshape(-1, self.dim) - self.center
        d = np.asarray(directions, dtype=np.float64).reshape(-1, self.dim)
        a = np.einsum("ni,ij,nj->n", d, self.shape, d)
        b = np.einsum("ni,ij,nj->n", o, self.shape, d)
        c = np.einsum("ni,ij,nj->n", o, self.shape, o) - 1.0
        disc = b * b - a * c
        with np.errstate(invalid="ignore", divide="ignore"):
            t = (-b + np.sqrt(disc)) / a
        return np.where((disc >= 0.0) & (t >= 0.0), t, np.nan)


def _hull(points: Arr) -> Arr:
    """The vertices of the convex hull (all points where Qhull cannot build one)."""
    if len(points) <= points.shape[1] + 2:
        return points
    try:
        return points[ConvexHull(points).vertices]
    except (QhullError, ValueError):
        return points


def _initial_weights(h: Arr) -> Arr:
    """Kumar & Yildirim's start: uniform weight on the 2d points that are extreme along d
    mutually orthogonal directions (the first along the widest spread)."""
    n, d = h.shape
    chosen: list[int] = []
    basis = np.zeros((0, d))
    direction = np.linalg.svd(h - h.mean(axis=0), full_matrices=False)[2][0]
    for _ in range(d):
        proj = h @ direction
        chosen += [int(np.argmax(proj)), int(np.argmin(proj))]
        spread = h[chosen[-2]] - h[chosen[-1]]
        basis = np.vstack([basis, spread])
        q, _ = np.linalg.qr(basis.T)
        rest = h - h.mean(axis=0)
        rest = rest - (rest @ q) @ q.T
        direction = rest[int(np.argmax(np.linalg.norm(rest, axis=1)))]
        if not np.any(direction):
            break
    u = np.zeros(n)
    u[np.unique(chosen)] = 1.0
    return u / u.sum()


def _newton_finish(q: Arr, u: Arr, target: float, tol: float) -> Arr | None:
    """An active-set Newton method on the optimality conditions ``M_i = d + 1`` of the points that
    carry weight, started from the support the first-order steps found: quadratic convergence
    where Khachiyan's steps crawl. A point whose weight would turn negative leaves the support, the
    point farthest outside joins it. Returns the weights, or None if it does not settle (the caller
    goes on stepping)."""
    w = np.where(u > 1e-6 * u.max(), u, 0.0)
    w /= w.sum()
    for _ in range(40):
        idx = np.flatnonzero(w > 0.0)
        qs = q[idx]
        try:
            k_inv = np.linalg.inv((qs.T * w[idx]) @ qs)
        except np.linalg.LinAlgError:           # fewer than d + 1 independent points left
            return None
        cross = qs @ k_inv @ qs.T
        resid = np.diag(cross) - target
        if np.abs(resid).max() <= 0.1 * tol * target:
            m = np.sum((q @ k_inv) * q, axis=1)
            j = int(np.argmax(m))
            if m[j] <= (1.0 + tol) * target:
                return w
            w[j] = 0.01 * w[idx].min()          # the farthest point outside joins the support
        else:
            step = np.linalg.lstsq(cross * cross, resid, rcond=1e-12)[0]
            falling = step < 0.0
            ratio = np.full(len(idx), np.inf)
            ratio[falling] = -w[idx][falling] / step[falling]
            block = int(np.argmin(ratio))
            if ratio[block] > 1.0:
                w[idx] += step
            else:                               # go as far as the first weight to reach zero, drop it
                w[idx] += ratio[block] * step
                w[idx[block]] = 0.0
                w = np.maximum(w, 0.0)
        total = w.sum()
        if not total > 0.0:
            return None
        w /= total
    return None


def _khachiyan(h: Arr, tol: float, max_iter: int) -> Arr:
    """The barycentric weights of the minimum-volume enclosing ellipse of the rows of ``h``:
    Khachiyan's steps towards the point farthest outside the current ellipse and Todd & Yildirim's
    away steps from the supporting point deepest inside (with rank-one updates of
    ``M_i = q_iᵀ X⁻¹ q_i``), until every ``M_i`` is within ``tol`` (relative) of the optimum's
    ``d + 1``. Every :data:`_NEWTON_EVERY` steps a Newton finish on the current support is tried."""
    n, d = h.shape
    q = np.hstack([h, np.ones((n, 1))])             # lifted points (n, d + 1)
    target = d + 1.0
    u = _initial_weights(h)
    k_inv = np.linalg.inv((q.T * u) @ q)
    m = np.sum((q @ k_inv) * q, axis=1)
    for it in range(max_iter):
        if it % _NEWTON_EVERY == _NEWTON_EVERY - 1:
            done = _newton_finish(q, u, target, tol)
            if done is not None:
                return done
            k_inv = np.linalg.inv((q.T * u) @ q)    # refresh against drift of the rank-one updates
            m = np.sum((q @ k_inv) * q, axis=1)
        j = int(np.argmax(m))
        support = u > 0.0
        k = int(np.flatnonzero(support)[np.argmin(m[support])])
        grow, shrink = m[j] / target - 1.0, 1.0 - m[k] / target
        if max(grow, shrink) <= tol:
            break
        if grow >= shrink:              # move weight towards the farthest point: u <- (1 - b) u + b e_j
            i, b = j, (m[j] - target) / (target * (m[j] - 1.0))
        else:                           # move weight away from the deepest supporting point (b < 0)
            i = k
            b = -min((target - m[k]) / (target * (m[k] - 1.0)), u[k] / (1.0 - u[k]))
        g = k_inv @ q[i]
        denom = (1.0 - b) + b * m[i]
        qg = q @ g
        m = (m - b * qg * qg / denom) / (1.0 - b)
        k_inv = (k_inv - b * np.outer(g, g) / denom) / (1.0 - b)
        u = (1.0 - b) * u
        u[i] = max(u[i] + b, 0.0)
    return u


def mvee(points: ArrayLike, *, tol: float = 1e-7, max_iter: int = 2000) -> Ellipse:
    """The minimum-volume enclosing ellipse of ``points`` (N, d), d = 2 or 3, by Khachiyan's
    algorithm (the one Chaurasia & Beardsley 2017, sec. 5.1, cite) with Todd & Yildirim's away
    steps and a Newton finish (see :func:`_khachiyan`), on the convex hull's vertices.

    ``tol`` is Khachiyan's ε: the iteration stops when every point lies within the ellipse grown
    by ``sqrt(1 + tol)`` and every supporting point near its boundary, so the volume is within a
    factor ``(1 + tol)^(d/2)`` of the minimum; ``max_iter`` bounds the steps. Either way the
    ellipse is then grown about its centre just enough to hold every point.

    Raises :class:`ParamError` for fewer than d + 1 points, non-finite values, or points that do
    not span d dimensions (all on a line in 2-D).
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] < 1:
        raise ParamError("points", f"expected an (N, d) array, got shape {p.shape}")
    n_all, d = p.shape
    if n_all < d + 1:
        raise ParamError("points", f"an enclosing ellipse in {d}-D needs at least {d + 1} points, got {n_all}")
    if not np.all(np.isfinite(p)):
        raise ParamError("points", "contain NaN or infinite values")
    centre0 = p.mean(axis=0)
    scale = float(np.abs(p - centre0).max())
    if not scale > 0.0:
        raise ParamError("points", "all points coincide: no ellipse encloses them")
    q = (p - centre0) / scale                       # well-conditioned working copy
    h = _hull(q)
    sv = np.linalg.svd(h - h.mean(axis=0), compute_uv=False)
    if sv[-1] <= 1e-9 * sv[0]:
        raise ParamError("points", f"do not span {d} dimensions (collinear or coplanar): no ellipse encloses them")
    u = _khachiyan(h, tol, max(int(max_iter), 1))
    c = h.T @ u
    cov = (h.T * u) @ h - np.outer(c, c)
    shape = np.linalg.inv(cov) / d
    diff = q - c
    worst = float(np.einsum("ni,ij,nj->n", diff, shape, diff).max())
    if worst > 1.0:
        shape = shape / worst
    return Ellipse(center=centre0 + scale * c, shape=shape / scale**2)


def occupancy(points2d: ArrayLike, ellipse: Ellipse, *, cell: float | None = None) -> float:
    """The share of ``ellipse`` (2-D) covered by ``points2d``: the "leaf confidence" of
    Chaurasia & Beardsley 2017, sec. 4.1 (Fig. 3): close to 1 for a well-segmented leaf, low for
    conjoined leaves or large missing chunks.

    The points are rasterised into square cells of side ``cell`` (default: twice the median
    distance between nearest neighbours), the covered cells dilated by one cell, and the covered
    cells whose centres lie inside the ellipse counted against all cells inside it.
    """
    p = np.asarray(points2d, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or ellipse.dim != 2:
        raise ParamError("points2d", f"expected (N, 2) points and a 2-D ellipse, got shape {p.shape}")
    if len(p) < 2 or not np.all(np.isfinite(p)):
        raise ParamError("points2d", "need at least 2 finite points")
    if cell is None:
        dist, _ = cKDTree(p).query(p, k=2)
        spacing = float(np.median(dist[:, 1]))
        cell = 2.0 * spacing if spacing > 0.0 else 0.0
    radii, _ = ellipse.axes
    lo = ellipse.center - radii[0]
    side = 2.0 * float(radii[0])
    if not (cell is not None and np.isfinite(cell) and cell > 0.0):
        cell = side / 64.0
    cell = max(float(cell), side / np.sqrt(MAX_OCCUPANCY_CELLS))
    n = int(np.ceil(side / cell)) + 1
    idx = np.floor((p - lo) / cell).astype(np.int64)
    keep = np.all((idx >= 0) & (idx < n), axis=1)
    covered = np.zeros((n, n), dtype=bool)
    covered[idx[keep, 0], idx[keep, 1]] = True
    covered = ndimage.binary_dilation(covered, structure=np.ones((3, 3), dtype=bool))
    centres = lo + (np.indices((n, n)).reshape(2, -1).T + 0.5) * cell
    inside = ellipse.contains(centres).reshape(n, n)
    total = int(inside.sum())
    if total == 0:
        return 1.0 if keep.any() else 0.0
    return float((covered & inside).sum() / total)
