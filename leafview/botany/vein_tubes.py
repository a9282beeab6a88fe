"""Vein tubes for close-ups: generalised cylinders swept along the vein polylines and offset from
the blade (Hong 2005, ch. 6.1; Hong, Simpson & Baranoski 2005, sec. 3: the larger veins rendered
as generalised cylinders of measured width). The numpy twin of ``shaders/vein_tube_frame.vert``
(the frames) and ``shaders/vein_tube.vert`` (the rings); GPU owner :mod:`leafview.gpu.vein_tubes`.

Nothing is stored in leaf space: each tube segment is uploaded as the (u, v) of its two end points,
the polyline's direction in (u, v) there and the tube radius there, and the vertex shader
evaluates the leaf surface at those (u, v) with the same code the blade uses
(``shaders/leaf_eval.glsl``), so the tubes follow ripples, bending, the vein-shape grid and any
other deformation.

The frame at a polyline point p = (u, v) with (u, v)-direction d = (du, dv) and radius r:

* ``T = L_u du + L_v dv`` (chain rule: the curve's tangent on the surface), ``t = T / |T|``;
* ``n``: the blade's upper-side normal ``normalize(L_v × L_u)`` made orthogonal to t; on the
  midrib crease (u = 0 exactly) the two halves meet at an angle, so ``n`` is the bisector of the
  two one-sided normals, and ``L_u`` in ``T`` is the one of the side the vein heads to (sign of du);
  a one-sided leaf (``shape.half = ±1``) uses its own side only;
* ``b = t × n`` (in the blade's tangent plane, across the vein);
* centre ``C = L(u, v) - OFFSET · r · n``; ring vertex k of ``sides``:
  ``P_k = C + r (cos θ_k b + sin θ_k n)``, ``θ_k = π/2 + 2π (k - 1/2) / sides`` (a face centred
  on top, so that a three-sided tube seen from above shows a face lit like the blade), outward
  normal ``cos θ_k b + sin θ_k n``.

Offset (our choice, after Hong 2005, ch. 6.1, where the major veins protrude mainly from the lower,
abaxial side): the centre sits :data:`OFFSET` = 0.5 radii below the blade, so a tube stands 0.5 r
proud of the upper side (a low ridge seen from above) and 1.5 r below it (the rib seen from below).

Radius along a vein: ``r(t) = width / 2 · sqrt(1 - t)`` with t the fraction of the vein's arc
length (leaf space), so every vein tapers and closes to a point at its end; each vein also starts
with a zero-radius ring at its first point, which caps its start with a disc.

Vertex order (what a triangle-strip instance of :func:`strip_vertices` vertices draws, and what a
capture reads back): vertex j of segment i is ring ``k = (j // 2) mod sides`` of end ``j mod 2``
(0: the segment's first point). Front faces point out of the tube.

Level of detail (:func:`tube_lod`): per vein, the largest projected diameter in pixels of its
on-screen points decides whether it is drawn (at least :data:`MIN_PIXELS`) and with how many
sides (its projected circumference over :data:`PIXELS_PER_SIDE`, rounded up to one of
:data:`SIDE_BUCKETS`); the GPU draws one instanced triangle strip per bucket.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.params import LeafParams
from leafview.deform.surface import Partials, partials

__all__ = ["OFFSET", "CREASE_U", "SIDE_BUCKETS", "PIXELS_PER_SIDE", "MIN_PIXELS", "TubeSegments", "VeinCurve",
           "tube_radii", "tube_segments", "strip_vertices", "tube_vertices", "tube_lod", "ring_sides"]

OFFSET = 0.5               # tube centre below the blade (lower side), in radii
CREASE_U = -1e-30          # u evaluated for the u < 0 side of the midrib crease (sigma = -1, s ~ 0)
SIDE_BUCKETS = (3, 4, 6, 8, 12)   # ring sides of the LOD buckets
PIXELS_PER_SIDE = 4.0      # projected circumference per ring side
MIN_PIXELS = 1.0           # smallest projected diameter drawn

Arr = NDArray[np.float64]


class VeinCurve(Protocol):
    """What a tube needs of a vein (``leafview.botany.venation.Vein``): its polyline in (u, v) and
    on the surface, its order and its width (leaf lengths)."""

    @property
    def uv(self) -> NDArray[np.float64]: ...
    @property
    def points(self) -> NDArray[np.float64]: ...
    @property
    def order(self) -> int: ...
    @property
    def width(self) -> float: ...


@dataclass(frozen=True)
class TubeSegments:
    """One row per tube segment (uploaded as is, one instance each): ``a`` and ``b`` (M, 4) float32
    the first and second point (u, v, du, dv); ``r`` (M, 4) float32 the radius at a and at b, the
    vein's order, 0; ``vein`` (M,) int32 the vein's index; ``points`` (M, 3) float64 the vein's
    point at b in leaf space (every polyline point once, for the level of detail)."""

    a: NDArray[np.float32]
    b: NDArray[np.float32]
    r: NDArray[np.float32]
    vein: NDArray[np.int32]
    points: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.vein.shape[0])

    def records(self) -> NDArray[np.float32]:
        """(M, 12) float32: a, b, r per row, the attributes of ``vein_tube_frame.vert``."""
        return np.ascontiguousarray(np.concatenate([self.a, self.b, self.r], axis=1), dtype=np.float32)


def _radii(points: Arr, first: NDArray[np.bool_], width: Arr) -> Arr:
    """Radius at each point of concatenated polylines (``first`` marks each one's first point):
    ``width / 2 · sqrt(1 - t)``, t the fraction of the polyline's arc length in leaf space."""
    steps = np.r_[0.0, np.linalg.norm(np.diff(points, axis=0), axis=1)]
    steps[first] = 0.0
    arc = np.cumsum(steps)
    start = np.flatnonzero(first)
    count = np.diff(np.r_[start, len(points)])
    arc -= np.repeat(arc[start], count)
    total = np.repeat(arc[np.r_[start[1:], len(points)] - 1], count)
    t = np.where(total > 0.0, arc / np.where(total > 0.0, total, 1.0), 0.0)
    return 0.5 * width * np.sqrt(np.clip(1.0 - t, 0.0, 1.0))


def tube_radii(vein: VeinCurve) -> Arr:
    """Radius at each point of ``vein``: ``width / 2 · sqrt(1 - t)``, t the fraction of its arc
    length in leaf space (zero at the last point)."""
    pts = np.asarray(vein.points, dtype=np.float64).reshape(-1, 3)
    first = np.zeros(len(pts), bool)
    first[:1] = True
    return _radii(pts, first, np.full(len(pts), float(vein.width)))


def tube_segments(veins: Sequence[VeinCurve]) -> TubeSegments:
    """The segments of every vein with at least two points: a zero-length cap segment from a
    zero-radius ring to the first ring, then one per polyline step. The direction (du, dv) at a
    point is the polyline's central difference there (one-sided at the ends), normalised."""
    kept = [(i, v) for i, v in enumerate(veins) if np.ndim(v.uv) == 2 and len(v.uv) >= 2]
    if not kept:
        z4 = np.zeros((0, 4), np.float32)
        return TubeSegments(z4, z4.copy(), z4.copy(), np.zeros(0, np.int32), np.zeros((0, 3)))
    count = np.array([len(v.uv) for _, v in kept])
    uv = np.concatenate([np.asarray(v.uv, np.float64).reshape(-1, 2) for _, v in kept])
    pts = np.concatenate([np.asarray(v.points, np.float64).reshape(-1, 3) for _, v in kept])
    start = np.r_[0, np.cumsum(count)[:-1]]
    first = np.zeros(len(uv), bool)
    first[start] = True
    last = np.r_[first[1:], True]
    idx = np.arange(len(uv))
    d = uv[np.where(last, idx, idx + 1 - last)] - uv[np.where(first, idx, idx - 1)]
    length = np.linalg.norm(d, axis=1, keepdims=True)
    rec = np.concatenate([uv, d / np.where(length > 0.0, length, 1.0)], axis=1)
    rad = _radii(pts, first, np.repeat([float(v.width) for _, v in kept], count))
    prev = np.where(first, idx, idx - 1)
    order = np.repeat([float(v.order) for _, v in kept], count)
    r = np.stack([np.where(first, 0.0, rad[prev]), rad, order, np.zeros(len(uv))], axis=1)
    vein = np.repeat(np.array([i for i, _ in kept], np.int32), count)
    return TubeSegments(rec[prev].astype(np.float32), rec.astype(np.float32), r.astype(np.float32), vein, pts)


def strip_vertices(sides: int) -> int:
    """Vertices of one segment's triangle strip with ``sides`` ring sides."""
    return 2 * (int(sides) + 1)


def _unit(x: Arr) -> Arr:
    length = np.linalg.norm(x, axis=-1, keepdims=True)
    return x / np.where(length > 0.0, length, 1.0)


def _upper_normal(p: Partials, v: Arr) -> Arr:
    """``normalize(L_v × L_u)``, with ±L_uv at the pinched base and apex (leaf_normal in GLSL)."""
    lu = np.where((v <= 0.0)[:, None], p.Luv, np.where((v >= 1.0)[:, None], -p.Luv, p.Lu))
    n = np.cross(p.Lv, lu)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 0.0, n / np.where(length > 0.0, length, 1.0), np.array([0.0, 0.0, 1.0]))


def _frames(params: LeafParams, pts: NDArray[np.float32],
            vein_grid: ArrayLike | None) -> tuple[Arr, Arr, Arr]:
    """Centre line point L, normal n and binormal b at (u, v, du, dv) records (float64)."""
    rec = pts.astype(np.float64)
    u, v, du, dv = rec.T
    p = partials(params, u, v, vein_grid=vein_grid)
    lu, n = p.Lu.copy(), _upper_normal(p, v)
    crease = u == 0.0
    half = float(params.shape.half)
    if crease.any() and half <= 0.0:
        m = partials(params, np.full(int(crease.sum()), CREASE_U), v[crease], vein_grid=vein_grid)
        nm = _upper_normal(m, v[crease])
        if half < 0.0:
            lu[crease], n[crease] = m.Lu, nm
        else:
            n[crease] = _unit(n[crease] + nm)
            lu[crease] = np.where((du[crease] < 0.0)[:, None], m.Lu, lu[crease])
    tan = _unit(lu * du[:, None] + p.Lv * dv[:, None])
    n = _unit(n - np.sum(n * tan, axis=1, keepdims=True) * tan)
    return p.L, n, np.cross(tan, n)


def tube_vertices(params: LeafParams, segments: TubeSegments, sides: int, *,
                  vein_grid: ArrayLike | None = None) -> tuple[Arr, Arr]:
    """Leaf-space positions and outward unit normals of every segment's strip with ``sides`` ring
    sides, in the vertex order of the module docstring: two (M · strip_vertices(sides), 3) arrays.
    ``vein_grid``: the leaf's vein-shape grid, as the blade is evaluated with it
    (:func:`leafview.deform.surface.partials`)."""
    sides = int(sides)
    if sides < 3:
        raise ValueError(f"a tube needs at least 3 sides, got {sides}")
    m = len(segments)
    la, na, ba = _frames(params, segments.a, vein_grid)
    lb, nb, bb = _frames(params, segments.b, vein_grid)
    j = np.arange(strip_vertices(sides))
    k = (j // 2) % sides
    far = (j % 2).astype(bool)
    theta = 0.5 * np.pi + 2.0 * np.pi * (k - 0.5) / sides
    c, s = np.cos(theta)[None, :, None], np.sin(theta)[None, :, None]
    r = segments.r[:, :2].astype(np.float64)

    def pick(x: Arr, y: Arr) -> Arr:   # (M, 3) at a and b -> (M, V, 3) by vertex end
        return np.where(far[None, :, None], y[:, None, :], x[:, None, :])

    L, n, b = pick(la, lb), pick(na, nb), pick(ba, bb)
    rad = np.where(far[None, :], r[:, 1:2], r[:, 0:1])[..., None]
    d = c * b + s * n
    pos = L - OFFSET * rad * n + rad * d
    return pos.reshape(m * len(j), 3), d.reshape(m * len(j), 3)


def ring_sides(diameter_px: ArrayLike) -> NDArray[np.int32]:
    """Ring sides for projected diameters in pixels: the circumference over
    :data:`PIXELS_PER_SIDE`, rounded up to a bucket of :data:`SIDE_BUCKETS` (at most the last)."""
    want = np.ceil(np.pi * np.asarray(diameter_px, dtype=np.float64) / PIXELS_PER_SIDE)
    buckets = np.asarray(SIDE_BUCKETS)
    idx = np.searchsorted(buckets, np.nan_to_num(want, nan=0.0, posinf=1e9), side="left")
    return buckets[np.minimum(idx, len(buckets) - 1)].astype(np.int32)


def tube_lod(world: ArrayLike, radius: ArrayLike, vein_of_point: ArrayLike, veins: int,
             view_proj: ArrayLike, size: tuple[int, int], *, scale: float = 1.0,
             detail: float = 1.0) -> NDArray[np.int32]:
    """Ring sides per vein (0: not drawn) for a camera.

    ``world`` (P, 3) the polyline points in world space, ``radius`` (P,) their tube radii in leaf
    space (``scale``: the leaf's world scale), ``vein_of_point`` (P,) their vein, ``view_proj``
    the 4×4 column-vector ``proj · view``, ``size`` the viewport (width, height) in pixels;
    ``detail`` multiplies every projected width (2: finer). A point counts when it is in front of
    the camera and within the viewport widened by its own projected radius plus 10 %, or ends a
    polyline step whose bounding box meets it; a vein's diameter is the largest of its counted
    points'."""
    pts = np.asarray(world, dtype=np.float64).reshape(-1, 3)
    clip = np.c_[pts, np.ones(len(pts))] @ np.asarray(view_proj, dtype=np.float64).T
    w = clip[:, 3]
    ahead = w > 0.0
    safe_w = np.where(ahead, w, 1.0)
    vp = np.asarray(view_proj, dtype=np.float64)
    owner = np.asarray(vein_of_point, dtype=np.intp)
    # pixels per world unit at each point: the projection's vertical focal term over w
    focal = 0.5 * float(size[1]) * float(np.hypot(vp[1, 0], np.hypot(vp[1, 1], vp[1, 2])))
    diam = 2.0 * np.asarray(radius, dtype=np.float64) * float(scale) * focal / safe_w * float(detail)
    reach = 1.1 + diam / max(float(min(size)), 1.0)
    ndc = clip[:, :2] / safe_w[:, None]
    seen = ahead & (np.abs(ndc) <= reach[:, None]).all(axis=1)
    # a step whose two ends are off screen on either side still crosses it: its ends count too
    pair = (owner[:-1] == owner[1:]) & ahead[:-1] & ahead[1:]
    lo, hi = np.minimum(ndc[:-1], ndc[1:]), np.maximum(ndc[:-1], ndc[1:])
    edge = np.maximum(reach[:-1], reach[1:])[:, None]
    cross = pair & ((lo <= edge) & (hi >= -edge)).all(axis=1)
    seen[:-1] |= cross
    seen[1:] |= cross
    best = np.zeros(int(veins))
    np.maximum.at(best, owner[seen], diam[seen])
    return np.where(best >= MIN_PIXELS, ring_sides(best), 0).astype(np.int32)
