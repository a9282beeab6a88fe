"""The venation mesh: a constrained Delaunay triangulation of the leaf with its veins as
constraint edges (``leafview export PRESET --mesh cdt``; Hong 2005, ch. 6.2, which uses
Shewchuk's Triangle, as this module does through the ``triangle`` package).

**The plane** (:mod:`.cdt_plane`): the leaf plane of the flat blade, where angles are the
leaf's, inverted by Newton's method; or vein space ``q = (u w(v), v)``, inverted in closed form,
for a blade whose flat map folds. The outline is one loop (base, margin u = +1, apex, margin
u = -1; a one-sided leaf's margin and midrib), and its vertices get u = ±1 (0 on the midrib edge
and at base and apex) exactly.

**The constraints.** Every vein of order <= :data:`MAX_ORDER` (the midrib or primaries, and the
secondaries; :func:`leafview.botany.venation.vein_tree`) is a chain of segments, clipped to the
blade. The planar straight line graph must be valid before Triangle sees it, so a vein end
within :func:`snap_tolerance` of the outline is moved onto it, one near another vein is moved onto
that vein (split there), and vertices closer than a hundredth of the tolerance are merged;
crossings that remain are split by Triangle.

**Quality.** ``q<min_angle>`` (default 20°): no angle below that, except near input angles that
are sharper, where Triangle relaxes the bound by design (Shewchuk 2002, "Delaunay refinement
algorithms for triangular mesh generation", sec. 5); ``a<max_area>`` bounds the area in leaf
lengths². :func:`quality` reports the smallest angle in the plane and on the surface, over all
triangles and away from the sharp input angles.

**The surface.** Positions and normals at the vertices' (u, v) come from the grid export's two
evaluations (:mod:`leafview.export.mesh`): the rendering vertex shader read back
(``backend="gpu"``, :meth:`leafview.gpu.LeafRenderer.capture`) or the float64 reference
(``backend="numpy"``, :func:`leafview.deform.surface.partials` with the leaf's
:func:`leafview.botany.vein_shape.vein_grid` when its venation is on, as the shader samples it),
so jitter, vein edits, ripples and bending are in the mesh. Texture coordinates are
:func:`leafview.core.texture.texture_st` of (u, v), as in the grid export.

**Lobed leaves** (``lobes.outline`` set) are refused (:func:`check_not_lobed`, a UsageError
naming ``--mesh``): they have no venation to constrain and their surface is not Ω over (u, v).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import triangle  # type: ignore[import-untyped]
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from leafview.botany.vein_shape import vein_grid
from leafview.botany.venation import vein_tree
from leafview.core.blade import normal_from
from leafview.core.params import LeafParams
from leafview.deform.surface import partials
from leafview.errors import NonFiniteMesh, UsageError
from leafview.export.cdt_plane import PLANES, Plane, leaf_plane, outline
from leafview.export.mesh import BACKENDS, LeafMesh, lower_left_st
from leafview.gpu import LeafRenderer, default_renderer

__all__ = [
    "ANGLE_RANGE",
    "AREA_RANGE",
    "DEFAULT_MAX_AREA",
    "DEFAULT_MIN_ANGLE",
    "MAX_ORDER",
    "PLANES",
    "CdtLeaf",
    "CdtMesh",
    "CdtQuality",
    "Pslg",
    "bake_cdt",
    "check_not_lobed",
    "check_max_area",
    "check_min_angle",
    "leaf_plane",
    "leaf_pslg",
    "near_sharp",
    "quality",
    "snap_tolerance",
    "triangle_angles",
    "triangulate_leaf",
]

MAX_ORDER = 2                  # veins of this order and lower are constraint edges
DEFAULT_MAX_AREA = 2e-4        # leaf lengths²: about 4,000 triangles for the ovate preset
DEFAULT_MIN_ANGLE = 20.0       # degrees, Triangle's 'q' (Hong 2005, ch. 6.2)
AREA_RANGE = (1e-6, 1.0)       # below 1e-6 a leaf has millions of triangles; 1 bounds nothing
ANGLE_RANGE = (0.0, 33.0)      # Triangle may not terminate above about 33.8° (its manual, -q)
SHELL_ANGLE = 60.0             # junctions below this get Triangle's concentric shells (Shewchuk 2002)
BOUNDARY, VEIN = 1, 2          # segment markers: the outline, a vein


# -- options ---------------------------------------------------------------------------------
def _in_range(value: object, name: str, bounds: tuple[float, float], what: str) -> float:
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise UsageError(f"{name} must be {what}, got {value!r}") from None
    lo, hi = bounds
    if not lo <= x <= hi:          # NaN fails too
        raise UsageError(f"{name} must be between {lo:g} and {hi:g} ({what}), got {value!r}")
    return x


def check_max_area(value: object, name: str = "max_area") -> float:
    """``value`` as a largest triangle area in leaf lengths², in :data:`AREA_RANGE`; a
    UsageError naming ``name`` otherwise."""
    return _in_range(value, name, AREA_RANGE, "an area in leaf lengths²")


def check_min_angle(value: object, name: str = "min_angle") -> float:
    """``value`` as a smallest angle in degrees, in :data:`ANGLE_RANGE`; a UsageError naming
    ``name`` otherwise."""
    return _in_range(value, name, ANGLE_RANGE, "an angle in degrees")


def snap_tolerance(max_area: float) -> float:
    """Vein ends closer than this (leaf lengths in the plane) to the outline or another vein are
    moved onto it: a tenth of the target edge length, at most 10⁻³."""
    return float(min(1e-3, 0.1 * np.sqrt(max_area)))


# -- the planar straight line graph ----------------------------------------------------------
@dataclass(frozen=True)
class Pslg:
    """What Triangle receives: ``points`` (P, 2) in the plane, their ``uv`` (P, 2; NaN where
    Triangle's inverse is needed: a vein split where another vein's end was snapped),
    ``segments`` (S, 2) int32, ``markers`` (S,) int32 (:data:`BOUNDARY` or :data:`VEIN`) and
    ``order`` (S,) int32 (the vein order, 0 on the outline)."""

    points: NDArray[np.float64]
    uv: NDArray[np.float64]
    segments: NDArray[np.int32]
    markers: NDArray[np.int32]
    order: NDArray[np.int32]


def _clip(uv: NDArray[np.float64], lo: float, hi: float) -> list[NDArray[np.float64]]:
    """The pieces of the polyline ``uv`` inside lo <= u <= hi, 0 <= v <= 1 (straight in (u, v)
    between samples, cut where it leaves: Liang-Barsky per segment)."""
    pieces: list[list[NDArray[np.float64]]] = []
    current: list[NDArray[np.float64]] = []
    box = ((lo, 0.0), (hi, 1.0))
    for a, b in zip(uv[:-1], uv[1:]):
        t0, t1, d = 0.0, 1.0, b - a
        for k in range(2):
            for bound, sign in ((box[0][k], -1.0), (box[1][k], 1.0)):
                p, r = sign * d[k], sign * (bound - a[k])
                if p == 0.0:
                    t0, t1 = (1.0, 0.0) if r < 0.0 else (t0, t1)
                elif p > 0.0:
                    t1 = min(t1, r / p)
                else:
                    t0 = max(t0, r / p)
        if t0 > t1:
            if current:
                pieces.append(current)
            current = []
            continue
        if current and t0 > 0.0:
            pieces.append(current)
            current = []
        if not current:
            current = [a + t0 * d]
        current.append(a + t1 * d)
        if t1 < 1.0:
            pieces.append(current)
            current = []
    if current:
        pieces.append(current)
    return [np.array(p) for p in pieces if len(p) >= 2]


def _veins(params: LeafParams, u_range: tuple[float, float]) -> list[tuple[int, NDArray[np.float64]]]:
    """(order, uv polyline) of every vein of order <= MAX_ORDER clipped to the drawn blade;
    pieces on the midrib edge of a one-sided leaf are dropped (the outline holds them)."""
    lo, hi = u_range
    out = []
    for vein in vein_tree(params):
        if vein.order > MAX_ORDER or len(vein.uv) < 2:
            continue
        for piece in _clip(np.asarray(vein.uv, np.float64), lo, hi):
            if not any(edge == 0.0 and np.all(np.abs(piece[:, 0]) < 1e-9) for edge in (lo, hi)):
                out.append((int(vein.order), piece))
    return out


def _margin_snap(plane: Plane, veins: list[tuple[int, NDArray[np.float64]]], eps: float) -> dict[float, list[float]]:
    """Move vein ends within ``eps`` of a side of the outline onto it (in place); returns the v of
    those ends per side, to be outline vertices."""
    extra: dict[float, list[float]] = {side: [] for side in plane.u_range}
    for _, uv in veins:
        for end in (0, -1):
            if not 0.0 < uv[end, 1] < 1.0:
                continue
            for side in plane.u_range:
                moved = np.array([[side, uv[end, 1]]])
                if np.linalg.norm(plane.forward(moved) - plane.forward(uv[end][None])) < eps:
                    uv[end, 0] = side
                    extra[side].append(float(uv[end, 1]))
                    break
    return extra


def _vein_snap(chains: list[NDArray[np.float64]], uvs: list[NDArray[np.float64]],
               eps: float) -> None:
    """Move each chain's ends within ``eps`` of another chain onto it, in place: onto its vertex
    when one is that close, else onto a new vertex splitting the segment (uv NaN: found later)."""
    for i in range(len(chains)):
        for end in (0, -1):
            p = chains[i][end]
            best: tuple[float, int, int, float] | None = None
            for j, other in enumerate(chains):
                if j == i:
                    continue
                a, b = other[:-1], other[1:]
                d = b - a
                t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0, 1)
                dist = np.linalg.norm(p - a - t[:, None] * d, axis=1)
                k = int(np.argmin(dist))
                if dist[k] < eps and (best is None or dist[k] < best[0]):
                    best = (float(dist[k]), j, k, float(t[k]))
            if best is None:
                continue
            _, j, k, t = best
            a, b = chains[j][k], chains[j][k + 1]
            point = a + t * (b - a)
            if np.linalg.norm(point - a) < eps:
                chains[i][end], uvs[i][end] = a, uvs[j][k]
            elif np.linalg.norm(point - b) < eps:
                chains[i][end], uvs[i][end] = b, uvs[j][k + 1]
            else:
                chains[j] = np.insert(chains[j], k + 1, point, axis=0)
                uvs[j] = np.insert(uvs[j], k + 1, np.nan, axis=0)
                chains[i][end], uvs[i][end] = point, np.nan


def _merge(points: NDArray[np.float64], tol: float) -> NDArray[np.int64]:
    """For each point the index of the first point within ``tol`` of it (union-find over pairs)."""
    root = np.arange(len(points))

    def find(i: int) -> int:
        while root[i] != i:
            root[i] = root[root[i]]
            i = int(root[i])
        return i

    for a, b in cKDTree(points).query_pairs(tol):
        ra, rb = find(a), find(b)
        root[max(ra, rb)] = min(ra, rb)
    return np.array([find(i) for i in range(len(points))], np.int64)


def leaf_pslg(params: LeafParams, plane: Plane, eps: float = 1e-3) -> Pslg:
    """The planar straight line graph of the leaf: the outline loop and every vein of order <=
    MAX_ORDER, snapped with tolerance ``eps`` (see the module docstring)."""
    veins = _veins(params, plane.u_range)
    extra = _margin_snap(plane, veins, eps)
    outline_uv = outline(plane, extra, 1e-2 * eps)
    uvs = [uv for _, uv in veins]
    chains = [plane.forward(uv) for uv in uvs]
    _vein_snap(chains, uvs, eps)
    points = np.concatenate([plane.forward(outline_uv), *chains])
    uv_all = np.concatenate([outline_uv, *uvs])
    n = len(outline_uv)
    seg = [np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1)]
    mark, order = [np.full(n, BOUNDARY)], [np.zeros(n, np.int64)]
    at = n
    for (o, _), chain in zip(veins, chains):
        k = len(chain)
        seg.append(np.stack([np.arange(at, at + k - 1), np.arange(at + 1, at + k)], axis=1))
        mark.append(np.full(k - 1, VEIN))
        order.append(np.full(k - 1, o))
        at += k
    root = _merge(points, 1e-2 * eps)
    kept, index = np.unique(root, return_inverse=True)
    segments = index[np.concatenate(seg)]
    good = segments[:, 0] != segments[:, 1]
    segments, markers, orders = segments[good], np.concatenate(mark)[good], np.concatenate(order)[good]
    _, first = np.unique(np.sort(segments, axis=1), axis=0, return_index=True)
    first = np.sort(first)
    return Pslg(points[kept], uv_all[kept], segments[first].astype(np.int32), markers[first].astype(np.int32),
                orders[first].astype(np.int32))


# -- triangulation ---------------------------------------------------------------------------
@dataclass(frozen=True)
class CdtMesh:
    """A triangulated leaf: ``points`` (V, 2) in the plane, ``uv`` (V, 2) the leaf's (u, v),
    ``triangles`` (T, 3) int64 in the grid export's winding (counter-clockwise seen from the
    front), ``edges`` (E, 2) the constraint edges of the mesh (pieces of the outline and the veins),
    ``pslg`` the input, ``junction`` (V,) the smallest angle between constraint edges at each
    vertex (360 where fewer than two meet; Triangle relaxes the bound near small ones), ``plane``
    the plane's name and ``inverse_error`` the
    largest distance in the plane between a vertex and the image of its (u, v)."""

    points: NDArray[np.float64]
    uv: NDArray[np.float64]
    triangles: NDArray[np.int64]
    edges: NDArray[np.int64]
    pslg: Pslg
    junction: NDArray[np.float64]
    plane: str
    inverse_error: float
    min_angle: float
    max_area: float

    @property
    def sharp(self) -> NDArray[np.bool_]:
        """(V,) the vertices where constraint edges meet at less than the quality bound."""
        return self.junction < self.min_angle


def _boundary_edges(tris: NDArray[np.int64]) -> NDArray[np.int64]:
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    return uniq[count == 1]


def _junction_angles(points: NDArray[np.float64], edges: NDArray[np.int64]) -> NDArray[np.float64]:
    """(V,) the smallest angle (degrees) at which two of ``edges`` meet at each vertex (360 where
    fewer than two meet)."""
    out = np.full(len(points), 360.0)
    ends = np.concatenate([edges, edges[:, ::-1]])
    order = np.argsort(ends[:, 0], kind="stable")
    ends = ends[order]
    starts = np.searchsorted(ends[:, 0], np.arange(len(points) + 1))
    for vertex in np.flatnonzero(np.diff(starts) >= 2):
        d = points[ends[starts[vertex]:starts[vertex + 1], 1]] - points[vertex]
        ang = np.sort(np.arctan2(d[:, 1], d[:, 0]))
        gaps = np.diff(np.concatenate([ang, ang[:1] + 2 * np.pi]))
        out[vertex] = np.degrees(gaps.min())
    return out


def _outline_uv(uv: NDArray[np.float64], points: NDArray[np.float64], tris: NDArray[np.int64]) -> None:
    """Fill in the (u, v) of Triangle's vertices on the outline (in place): each lies on a chord
    between two outline vertices A and B of known (u, v) and gets the side's u (0 at base and
    apex) and the v interpolated by its distance along the chord."""
    edges = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    key = np.sort(edges, axis=1)
    _, inverse, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    rim = edges[count[inverse.ravel()] == 1]
    after = dict(zip(rim[:, 0].tolist(), rim[:, 1].tolist()))
    known = [i for i in after if not np.isnan(uv[i, 0])]
    if len(known) < 2 or len(after) != len(rim):
        raise NonFiniteMesh("the venation mesh's outline is not one loop")   # Triangle broke the outline
    start = known[0]
    run, at = [start], after[start]
    for _ in range(len(rim)):
        run.append(at)
        if not np.isnan(uv[at, 0]):
            a, b = run[0], run[-1]
            if len(run) > 2:
                inner = np.array(run[1:-1])
                steps = np.linalg.norm(np.diff(points[run], axis=0), axis=1)
                t = np.cumsum(steps)[:-1] / steps.sum()
                tip_a = uv[a, 1] in (0.0, 1.0)
                uv[inner, 0] = uv[b, 0] if tip_a else uv[a, 0]
                uv[inner, 1] = uv[a, 1] + t * (uv[b, 1] - uv[a, 1])
            run = [at]
            if at == start:
                break
        at = after[at]


def triangulate_leaf(params: LeafParams, *, max_area: float = DEFAULT_MAX_AREA,
                     min_angle: float = DEFAULT_MIN_ANGLE, plane: str = "auto") -> CdtMesh:
    """The constrained Delaunay quality triangulation of ``params`` (see the module docstring)."""
    max_area = check_max_area(max_area)
    min_angle = check_min_angle(min_angle)
    where = leaf_plane(params, plane)
    pslg = leaf_pslg(params, where, snap_tolerance(max_area))
    flags = f"pq{min_angle:.6f}a{max_area:.12f}Q"     # fixed-point: Triangle reads no exponents
    out = triangle.triangulate({"vertices": pslg.points, "segments": pslg.segments,
                                "segment_markers": pslg.markers[:, None]}, flags)
    points = np.asarray(out["vertices"], np.float64)
    tris = np.asarray(out["triangles"], np.int64)
    edges = np.asarray(out["segments"], np.int64)
    # Triangle keeps the input points first, in order: their (u, v) are known; its own are found
    uv = np.full((len(points), 2), np.nan)
    uv[:len(pslg.uv)] = pslg.uv
    used = np.unique(tris)                      # drop input points Triangle left outside the blade
    remap = np.full(len(points), -1, np.int64)
    remap[used] = np.arange(len(used))
    points, uv, tris, edges = points[used], uv[used], remap[tris], remap[edges]
    edges = edges[(edges >= 0).all(axis=1)]
    _outline_uv(uv, points, tris)
    todo = np.flatnonzero(np.isnan(uv[:, 0]))
    uv[todo], error = where.inverse(points[todo])
    # Triangle's triangles turn counter-clockwise in its plane; the grid export's turn clockwise in
    # (u, v), which is counter-clockwise seen from the front (u runs towards -x)
    t = uv[tris]
    area = ((t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1]) - (t[:, 1, 1] - t[:, 0, 1]) * (t[:, 2, 0] - t[:, 0, 0]))
    if area.sum() > 0.0:
        tris = tris[:, ::-1]
    junction = _junction_angles(points, edges)
    return CdtMesh(points, uv, np.ascontiguousarray(tris), edges, pslg, junction, where.name, error, min_angle,
                   max_area)


# -- quality ---------------------------------------------------------------------------------
def triangle_angles(points: NDArray[np.floating], tris: NDArray[np.integer]) -> NDArray[np.float64]:
    """(T, 3) interior angles in degrees of triangles in 2D or 3D."""
    p = np.asarray(points, np.float64)[tris]
    out = np.empty(tris.shape)
    for k in range(3):
        e1, e2 = p[:, (k + 1) % 3] - p[:, k], p[:, (k + 2) % 3] - p[:, k]
        norm = np.maximum(np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1), 1e-300)
        out[:, k] = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", e1, e2) / norm, -1.0, 1.0)))
    return out


@dataclass(frozen=True)
class CdtQuality:
    """Figures of a venation mesh: counts, the smallest angle in the plane and on the surface
    (over all triangles, and away from sharp input angles: no corner on a :attr:`CdtMesh.sharp`
    vertex) and the seconds spent."""

    plane: str
    vertices: int
    triangles: int
    constraint_edges: int
    min_angle_plane: float
    min_angle_plane_away: float
    min_angle_3d: float
    min_angle_3d_away: float
    seconds: float

    def __str__(self) -> str:
        return (f"{self.triangles:,} triangles, {self.vertices:,} vertices, {self.constraint_edges:,} vein and "
                f"outline edges; smallest angle {self.min_angle_plane_away:.1f}° in the {self.plane} plane and "
                f"{self.min_angle_3d_away:.1f}° on the leaf away from sharp input angles "
                f"({self.min_angle_plane:.1f}° and {self.min_angle_3d:.1f}° overall); {self.seconds:.2f} s")


def near_sharp(cdt: CdtMesh) -> NDArray[np.bool_]:
    """(T,) bool: the triangles where Triangle relaxes the angle bound near a sharp input angle
    (Shewchuk 2002, sec. 5): those with a corner on a :attr:`CdtMesh.sharp` vertex, and the
    "concentric shells" it leaves unsplit, a triangle whose shortest edge joins two points on
    different constraint edges out of a junction X at equal distances from X (to 1 %), for
    junctions under :data:`SHELL_ANGLE`."""
    pts, tris = cdt.points, cdt.triangles
    out = np.asarray(cdt.sharp[tris].any(axis=1), bool)
    length = np.stack([np.linalg.norm(pts[tris[:, (k + 1) % 3]] - pts[tris[:, k]], axis=1) for k in range(3)], 1)
    k = np.argmin(length, axis=1)
    p1, p2 = pts[tris[np.arange(len(tris)), k]], pts[tris[np.arange(len(tris)), (k + 1) % 3]]
    ends = np.concatenate([cdt.edges, cdt.edges[:, ::-1]])
    for x in np.flatnonzero(cdt.junction < SHELL_ANGLE):
        out_of = pts[ends[ends[:, 0] == x, 1]] - pts[x]
        rays = out_of / np.linalg.norm(out_of, axis=1, keepdims=True)
        d1, d2 = p1 - pts[x], p2 - pts[x]
        r1, r2 = np.linalg.norm(d1, axis=1), np.linalg.norm(d2, axis=1)
        # which ray each end lies on (cross product ~ 0, dot > 0), -1 for none
        on1 = np.abs(d1[:, None, 0] * rays[None, :, 1] - d1[:, None, 1] * rays[None, :, 0]) <= 1e-9 + 1e-6 * r1[:, None]
        on2 = np.abs(d2[:, None, 0] * rays[None, :, 1] - d2[:, None, 1] * rays[None, :, 0]) <= 1e-9 + 1e-6 * r2[:, None]
        on1 &= (d1 @ rays.T) > 0.0
        on2 &= (d2 @ rays.T) > 0.0
        ray1 = np.where(on1.any(axis=1), np.argmax(on1, axis=1), -1)
        ray2 = np.where(on2.any(axis=1), np.argmax(on2, axis=1), -2)
        equal = np.abs(r1 - r2) <= 0.01 * np.maximum(r1, r2)
        out |= (ray1 >= 0) & (ray2 >= 0) & (ray1 != ray2) & equal
    return out


def quality(cdt: CdtMesh, positions: NDArray[np.floating], seconds: float = 0.0) -> CdtQuality:
    """:class:`CdtQuality` of ``cdt`` with surface ``positions`` (V, 3)."""
    away = ~near_sharp(cdt)
    a2 = triangle_angles(cdt.points, cdt.triangles).min(axis=1)
    a3 = triangle_angles(positions, cdt.triangles).min(axis=1)

    def low(a: NDArray[np.float64]) -> float:
        return float(a.min()) if a.size else 180.0

    return CdtQuality(cdt.plane, len(cdt.points), len(cdt.triangles), len(cdt.edges), low(a2), low(a2[away]),
                      low(a3), low(a3[away]), seconds)


# -- the surface -----------------------------------------------------------------------------
@dataclass(frozen=True)
class CdtLeaf:
    """A baked venation mesh (:class:`~leafview.export.mesh.LeafMesh`), its triangulation and
    its figures."""

    mesh: LeafMesh
    cdt: CdtMesh
    quality: CdtQuality


def _surface(params: LeafParams, uv: NDArray[np.float64], backend: str,
             renderer: LeafRenderer | None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Positions and normals at the drawn (u, v), by the grid export's two evaluations."""
    if backend == "gpu":
        half = params.shape.half
        grid_u = 2.0 * uv[:, 0] - half if half else uv[:, 0]      # the inverse of drawn_uv
        pos, nrm = (renderer or default_renderer()).capture(params, grid_u, uv[:, 1])
        return np.asarray(pos, np.float64), np.asarray(nrm, np.float64)
    grid = vein_grid(params) if params.venation.enabled else None    # what the vertex shader samples
    p = partials(params, uv[:, 0], uv[:, 1], vein_grid=grid)
    return p.L, normal_from(p, uv[:, 1])


def _repair_normals(pos: NDArray[np.float64], nrm: NDArray[np.float64], tris: NDArray[np.int64]) -> NDArray[np.float64]:
    """Unit normals; a zero or non-finite one (a flat spot of the parameterisation) is replaced
    by the area-weighted normal of its triangles."""
    length = np.linalg.norm(nrm, axis=1)
    bad = ~np.isfinite(length) | (np.abs(length - 1.0) > 1e-3)
    if bad.any():
        a, b, c = (pos[tris[:, k]] for k in range(3))
        face = np.cross(b - a, c - a)
        acc = np.zeros_like(pos)
        for k in range(3):
            np.add.at(acc, tris[:, k], face)
        nrm = np.where(bad[:, None], acc, nrm)
    return nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def check_not_lobed(params: LeafParams) -> None:
    """Refuse a lobed leaf (``lobes.outline`` set): its surface is the sweep of railroad ties, not
    Ω over (u, v), and it has no venation to constrain; a UsageError naming ``--mesh``."""
    if params.lobes.enabled:
        raise UsageError(f"{params.name or 'leaf'} is a lobed leaf: --mesh cdt meshes the venation of a "
                         "unilobed leaf; export lobed leaves with --mesh grid (the default)")


def bake_cdt(params: LeafParams, *, max_area: float = DEFAULT_MAX_AREA, min_angle: float = DEFAULT_MIN_ANGLE,
             plane: str = "auto", backend: str = "gpu", renderer: LeafRenderer | None = None) -> CdtLeaf:
    """Triangulate ``params`` (:func:`triangulate_leaf`) and evaluate its surface at the
    vertices: a :class:`CdtLeaf` whose mesh the grid export's writers take as it is."""
    if backend not in BACKENDS:
        raise UsageError(f"unknown backend {backend!r} (use {' or '.join(BACKENDS)})")
    check_not_lobed(params)
    started = time.perf_counter()
    cdt = triangulate_leaf(params, max_area=max_area, min_angle=min_angle, plane=plane)
    pos, nrm = _surface(params, cdt.uv, backend, renderer)
    bad = ~np.isfinite(pos).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise NonFiniteMesh(f"{params.name or 'leaf'}: non-finite vertex at (u, v) = ({cdt.uv[i, 0]:.4g}, "
                            f"{cdt.uv[i, 1]:.4g}); nothing was written")
    nrm = _repair_normals(pos, nrm, cdt.triangles)
    mesh = LeafMesh(pos.astype(np.float32), nrm.astype(np.float32), lower_left_st(cdt.uv), cdt.uv,
                    cdt.triangles.astype(np.uint32), params.name)
    return CdtLeaf(mesh, cdt, quality(cdt, pos, time.perf_counter() - started))
