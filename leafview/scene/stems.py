"""Stem geometry for the plant generators: spines, rotation-minimising frames, swept tubes, the
woody skeleton of many plants, and the nodes on it where leaves sit (phyllotaxis).

Every woody axis of a plant (trunk, branch, twig) and every petiole is a *generalized cylinder*
(Bloomenthal's branches, as recalled in Mündermann et al. 2003, sec. 2 and used for veins in Hong 2005, ch. 6.1):
a circle swept along a spine (the carrier curve) with a radius that tapers along it. All the
functions here work on many axes at once (arrays with a leading axis dimension), so a plant
generator loops over levels of the branching hierarchy in Python, never over axes or leaves.

Spines are polylines of ``K + 1`` points with equal segment lengths, integrated from a start
point, an initial direction ``d0`` and a *bend* vector ``b``: the direction at arc parameter
``s ∈ [0, 1]`` is ``normalize(d0 + s b)``. With ``b = g ẑ`` this is a simple gravitropism
(``g > 0`` curves the axis upwards, ``g < 0`` makes it droop).

Frames are carried along a spine by parallel transport (the rotation-minimising frame): at each
step the normal is turned by the smallest rotation that takes one tangent to the next
(Rodrigues' formula with the unnormalised axis ``c = t0 × t1``:
``n' = n (t0·t1) + c × n + c (c·n) / (1 + t0·t1)``). Azimuths measured in such a frame do not
drift along a curved axis, which is what keeps phyllotactic divergence angles exact.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.scene.threads import in_two_threads

__all__ = ["grow_spines", "soft_floor", "segment_tangents", "vertex_tangents", "transport_frames",
           "reference_normals", "sweep_tubes", "cross", "merge_meshes", "Mesh3", "Axes", "Skeleton",
           "grow_skeleton", "GOLDEN_ANGLE", "divergence", "auto_twigs", "Nodes", "place_nodes",
           "MAX_TWIGS", "split_counts", "PlantArchitecture"]

GOLDEN_ANGLE = 360.0 * (1.0 - 2.0 / (1.0 + math.sqrt(5.0)))     # 137.5077...°

F64 = NDArray[np.float64]
AlongOf = Callable[[NDArray[np.int64], F64], F64]   # (axis, arc parameter) -> position along the leafy part
Mesh3 = tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.uint32]]


_EPS = 1e-12
_Z_UP = np.array([0.0, 0.0, 1.0])


class PlantArchitecture(Protocol):
    """What the skeleton and the nodes read of a plant's architecture: the fields of
    :class:`leafview.scene.plants.PlantSpec` (which imports this module, so it is named here by
    shape; read-only, as that frozen dataclass's fields are)."""

    @property
    def phyllotaxis(self) -> str: ...
    @property
    def whorl(self) -> int: ...
    @property
    def per_node(self) -> int: ...
    @property
    def height(self) -> float: ...
    @property
    def branches(self) -> int: ...
    @property
    def branch_angle(self) -> float: ...
    @property
    def branch_length(self) -> float: ...
    @property
    def crown_base(self) -> float: ...
    @property
    def twigs(self) -> int: ...
    @property
    def twig_angle(self) -> float: ...
    @property
    def twig_length(self) -> float: ...
    @property
    def internode(self) -> float: ...
    @property
    def gravitropism(self) -> float: ...
    @property
    def lean(self) -> float: ...
    @property
    def radius(self) -> float: ...
    @property
    def taper(self) -> float: ...
    @property
    def variation(self) -> float: ...
    @property
    def leaf_size(self) -> float: ...
    @property
    def size_falloff(self) -> float: ...
    @property
    def petiole(self) -> float: ...
    @property
    def petiole_angle(self) -> float: ...


def _normalize(v: F64) -> F64:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, _EPS)


def cross(a: F64, b: F64) -> F64:
    """Row-wise cross product (several times faster than ``np.cross`` on (N, 3) arrays)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def soft_floor(z: F64, floor: F64 | float) -> F64:
    """Keep heights above zero without creases: ``z`` where ``z ≥ floor``, else
    ``floor · exp((z - floor) / floor)`` (continuous, with a continuous slope, strictly
    increasing, always > 0). ``floor`` broadcasts against ``z`` and must be > 0."""
    floor = np.asarray(floor, np.float64)
    low = floor * np.exp(np.minimum(z - floor, 0.0) / floor)
    return np.where(z >= floor, z, low)


def grow_spines(start: F64, d0: F64, bend: F64, length: F64, segments: int,
                floor: F64 | float | None = None) -> F64:
    """Integrate spines of ``segments`` equal steps.

    Parameters
    ----------
    start, d0, bend : (A, 3)
        First point, initial direction (unit), bend vector (see the module docstring).
    length : (A,)
        Arc length of each spine (before the optional floor).
    segments : int
        Number of segments ``K``; the result has ``K + 1`` points.
    floor : float or (A,), optional
        Heights are passed through :func:`soft_floor` with this floor (z stays > 0).

    Returns
    -------
    (A, K + 1, 3) float64 points.
    """
    s = (np.arange(segments) + 0.5) / segments                     # midpoint rule per segment
    dirs = _normalize(d0[:, None, :] + s[None, :, None] * bend[:, None, :])
    steps = dirs * (np.asarray(length, np.float64) / segments)[:, None, None]
    pts = np.concatenate([np.zeros_like(steps[:, :1]), np.cumsum(steps, axis=1)], axis=1)
    pts += start[:, None, :]
    if floor is not None:
        f = np.broadcast_to(np.asarray(floor, np.float64), (pts.shape[0],))[:, None]
        pts[..., 2] = soft_floor(pts[..., 2], f)
    return pts


def segment_tangents(spines: F64) -> F64:
    """Unit direction of each segment, (A, K, 3)."""
    return _normalize(np.diff(spines, axis=1))


def vertex_tangents(spines: F64) -> F64:
    """Unit tangent at each point, (A, K + 1, 3): the mean of the adjacent segment directions."""
    seg = segment_tangents(spines)
    t = np.concatenate([seg[:, :1], seg[:, :-1] + seg[:, 1:], seg[:, -1:]], axis=1)
    return _normalize(t)


def reference_normals(t0: F64, prefer: F64 | None = None) -> F64:
    """A unit vector perpendicular to each tangent ``t0`` (A, 3): ``prefer`` (default world up
    +z) made perpendicular, or world +x where ``prefer`` is nearly parallel to the tangent."""
    up = np.broadcast_to(np.array([0.0, 0.0, 1.0]) if prefer is None else prefer, t0.shape)
    n = up - np.sum(up * t0, axis=-1, keepdims=True) * t0
    bad = np.linalg.norm(n, axis=-1) < 1e-6
    if np.any(bad):
        x = np.zeros_like(t0[bad])
        x[:, 0] = 1.0
        alt = x - np.sum(x * t0[bad], axis=-1, keepdims=True) * t0[bad]
        y = np.zeros_like(alt)
        y[:, 1] = 1.0
        weak = np.linalg.norm(alt, axis=-1) < 1e-6
        alt[weak] = y[weak] - np.sum(y[weak] * t0[bad][weak], axis=-1, keepdims=True) * t0[bad][weak]
        n = n.copy()
        n[bad] = alt
    return _normalize(n)


def transport_frames(tangents: F64, n0: F64) -> tuple[F64, F64]:
    """Rotation-minimising frames along each row of ``tangents`` (A, R, 3), starting from the
    normal ``n0`` (A, 3; made perpendicular to the first tangent). Returns normals and
    binormals ``b = t × n``, both (A, R, 3); ``(t, n, b)`` is right-handed and orthonormal."""
    t = tangents
    normals = np.empty_like(t)
    n = _normalize(n0 - np.sum(n0 * t[:, 0], axis=-1, keepdims=True) * t[:, 0])
    normals[:, 0] = n
    for r in range(1, t.shape[1]):
        t0, t1 = t[:, r - 1], t[:, r]
        c = cross(t0, t1)
        d = np.sum(t0 * t1, axis=-1, keepdims=True)
        n = n * d + cross(c, n) + c * np.sum(c * n, axis=-1, keepdims=True) / np.maximum(1.0 + d, 1e-9)
        n = _normalize(n - np.sum(n * t1, axis=-1, keepdims=True) * t1)   # remove round-off
        normals[:, r] = n
    return normals, cross(t, normals)


def sweep_tubes(spines: F64, radii: F64, sides: int, n0: F64 | None = None) -> Mesh3:
    """Generalized cylinders: a circle of ``sides`` vertices swept along each spine.

    Parameters
    ----------
    spines : (A, R, 3)
        Ring centres (``R ≥ 2``).
    radii : (A, R)
        Ring radii (the taper profile).
    sides : int
        Vertices per ring (≥ 3).
    n0 : (A, 3), optional
        Start normal of the transported frame (default: world up made perpendicular).

    Returns
    -------
    positions (A·R·sides, 3) float32, outward unit normals (same), triangle indices
    (A·(R-1)·sides·2, 3) uint32, counter-clockwise seen from outside. Vertex ``(a, r, k)`` is at
    row ``(a·R + r)·sides + k``, so the centre of a ring is the mean of its ``sides`` rows.
    """
    a_n, r_n = spines.shape[:2]
    t = vertex_tangents(spines)
    normals, binormals = transport_frames(t, reference_normals(t[:, 0]) if n0 is None else n0)
    theta = 2.0 * np.pi * np.arange(sides) / sides
    ring = (np.cos(theta)[None, None, :, None] * normals[:, :, None, :]
            + np.sin(theta)[None, None, :, None] * binormals[:, :, None, :])      # (A, R, S, 3)
    pos = spines[:, :, None, :] + radii[:, :, None, None] * ring
    # one tube's quads: ring r, side k -> (r, k), (r, k+1), (r+1, k+1), (r+1, k)
    r, k = np.meshgrid(np.arange(r_n - 1), np.arange(sides), indexing="ij")
    v00 = r * sides + k
    v01 = r * sides + (k + 1) % sides
    v10 = v00 + sides
    v11 = v01 + sides
    # (t, n, b) right-handed: going around n -> b is counter-clockwise seen from +t, so the
    # outward-facing winding is v00, v01, v11 then v00, v11, v10.
    quad = np.stack([np.stack([v00, v01, v11], -1), np.stack([v00, v11, v10], -1)], axis=2).reshape(-1, 3)
    offsets = (np.arange(a_n, dtype=np.int64) * r_n * sides)[:, None, None]
    idx = (quad[None, :, :] + offsets).reshape(-1, 3)
    return (pos.reshape(-1, 3).astype(np.float32), ring.reshape(-1, 3).astype(np.float32),
            idx.astype(np.uint32))


def merge_meshes(meshes: list[Mesh3]) -> tuple[Mesh3, list[tuple[int, int]]]:
    """Concatenate meshes into one (indices offset), with each input's vertex range."""
    pos, nrm, idx, ranges = [], [], [], []
    base = 0
    for p, n, i in meshes:
        pos.append(p)
        nrm.append(n)
        idx.append((i.astype(np.int64) + base).astype(np.uint32))
        ranges.append((base, base + len(p)))
        base += len(p)
    if base >= 2**32:
        raise ValueError(f"stem mesh too large: {base} vertices (uint32 indices)")
    if not pos:
        return (np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32)), []
    return (np.concatenate(pos), np.concatenate(nrm), np.concatenate(idx)), ranges


# ---------------------------------------------------------------------------------------------
# the woody skeleton of many plants at once
TRUNK_SEGMENTS, BRANCH_SEGMENTS, TWIG_SEGMENTS = 8, 6, 4


@dataclass
class Axes:
    """One level of the branching hierarchy for all plants (``A`` axes, ``K`` segments each).

    ``spines`` (A, K+1, 3) points, ``radii`` (A, K+1), ``tangent``/``normal``/``binormal``
    (A, K, 3) rotation-minimising frames per segment, ``length`` (A,) nominal arc length,
    ``plant`` (A,) owning plant, ``parent`` (A,) index of the parent axis in the level above
    (-1 for trunks) and ``attach`` (A,) arc parameter on the parent where it starts.
    Axes are ordered plant by plant.
    """

    spines: F64
    radii: F64
    tangent: F64
    normal: F64
    binormal: F64
    length: F64
    plant: NDArray[np.int64]
    parent: NDArray[np.int64]
    attach: F64

    def __len__(self) -> int:
        return int(self.spines.shape[0])

    def sample(self, axis: NDArray[np.int64], s: F64) -> tuple[F64, F64, F64, F64, F64]:
        """Point, radius and segment frame (t, n, b) at arc parameter ``s`` of each ``axis``."""
        k_n = self.tangent.shape[1]
        k = np.minimum((s * k_n).astype(np.int64), k_n - 1)
        f = s * k_n - k
        p = self.spines[axis, k] * (1.0 - f)[:, None] + self.spines[axis, k + 1] * f[:, None]
        r = self.radii[axis, k] * (1.0 - f) + self.radii[axis, k + 1] * f
        return p, r, self.tangent[axis, k], self.normal[axis, k], self.binormal[axis, k]


def _axes(spines: F64, radii: F64, length: F64, plant: ArrayLike, parent: ArrayLike, attach: ArrayLike) -> Axes:
    t = segment_tangents(spines)
    n, b = transport_frames(t, reference_normals(t[:, 0]))
    return Axes(spines, radii, t, n, b, np.asarray(length, np.float64), np.asarray(plant, np.int64),
                np.asarray(parent, np.int64), np.asarray(attach, np.float64))


@dataclass
class Skeleton:
    """Trunks, first-order branches and twigs of ``P`` plants grown at the origin."""

    trunks: Axes
    branches: Axes | None
    twigs: Axes | None


def _out(t: F64, n: F64, b: F64, polar: F64, azimuth: F64) -> F64:
    """Unit vectors at ``polar`` (radians) from the tangent ``t`` and ``azimuth`` from ``n``
    towards ``b``."""
    sp = np.sin(polar)[:, None]
    return (np.cos(polar)[:, None] * t + sp * np.cos(azimuth)[:, None] * n
            + sp * np.sin(azimuth)[:, None] * b)


def branch_envelope(frac: F64) -> F64:
    """Length of a branch relative to the lowest one, by its position in the crown (0 bottom,
    1 top): a rounded cone."""
    return 0.25 + 0.75 * np.clip(1.0 - frac, 0.0, 1.0) ** 0.6


def grow_skeleton(spec: PlantArchitecture, scales: F64, twigs: int, rng: np.random.Generator) -> Skeleton:
    """Grow the woody axes of ``len(scales)`` plants of architecture ``spec`` (a
    :class:`~leafview.scene.plants.PlantSpec`) at the origin, ``twigs`` twigs per branch.

    Trunk: vertical, leaning by up to ``spec.lean`` degrees in a random direction and curving
    into it. Branches: ``spec.branches`` between ``crown_base`` and the top, azimuths spiralling by
    the golden angle, ``branch_angle`` from the trunk, lengths by :func:`branch_envelope`.
    Twigs: alternate left and right on the outer 75 % of each branch, ``twig_angle`` from it and
    spreading sideways (75° from the branch's upward normal). Branches and twigs bend by
    ``gravitropism`` and stay above ``z = clearance`` (:func:`soft_floor`). All lengths, radii
    and random perturbations (``variation``) are per plant × ``scales``.
    """
    p_n = len(scales)
    var = spec.variation
    height = spec.height * scales
    jig = lambda *shape: var * rng.uniform(-1.0, 1.0, shape)  # noqa: E731
    clearance = spec.leaf_size * scales * (1.3 + spec.petiole)
    # trunk
    lean = np.radians(spec.lean) * rng.uniform(0.0, 1.0, p_n)
    lean_az = rng.uniform(0.0, 2.0 * np.pi, p_n)
    lean_dir = np.stack([np.cos(lean_az), np.sin(lean_az), np.zeros(p_n)], axis=1)
    up = np.tile(_Z_UP, (p_n, 1))
    trunk_sp = grow_spines(np.zeros((p_n, 3)), up, 2.0 * np.tan(lean)[:, None] * lean_dir, height,
                           TRUNK_SEGMENTS)
    s_tr = np.linspace(0.0, 1.0, TRUNK_SEGMENTS + 1)
    trunk_r = (spec.radius * scales)[:, None] * (1.0 - spec.taper * s_tr)[None, :]
    trunks = _axes(trunk_sp, trunk_r, height, np.arange(p_n), np.full(p_n, -1), np.zeros(p_n))
    n_b = spec.branches
    if n_b == 0:
        return Skeleton(trunks, None, None)
    # first-order branches (P, B) flattened plant-major
    b = np.arange(n_b)
    frac = np.clip((b[None, :] + 0.5 + 0.8 * jig(p_n, n_b)) / n_b, 0.01, 0.99)
    t_att = spec.crown_base + (0.97 - spec.crown_base) * frac
    az = rng.uniform(0.0, 2.0 * np.pi, (p_n, 1)) + np.radians(GOLDEN_ANGLE) * b[None, :] + 0.5 * jig(p_n, n_b)
    polar = np.radians(spec.branch_angle) * (1.0 + jig(p_n, n_b))
    parent = np.repeat(np.arange(p_n), n_b)
    p0, r0, t0, n0, b0 = trunks.sample(parent, t_att.ravel())
    d0 = _out(t0, n0, b0, polar.ravel(), az.ravel())
    length = (spec.branch_length * height[:, None] * branch_envelope(frac) * (1.0 + jig(p_n, n_b))).ravel()
    bend = 1.5 * spec.gravitropism * _Z_UP + 0.5 * jig(p_n * n_b, 3)
    sp = grow_spines(p0, d0, bend, length, BRANCH_SEGMENTS, clearance[parent])
    s_br = np.linspace(0.0, 1.0, BRANCH_SEGMENTS + 1)
    radii = (0.5 * r0)[:, None] * (1.0 - 0.75 * s_br)[None, :]
    branches = _axes(sp, radii, length, parent, parent, t_att.ravel())
    if twigs <= 0:
        return Skeleton(trunks, branches, None)
    # twigs (P·B, T) flattened branch-major
    a_n = len(branches)
    j = np.arange(twigs)
    t_tw = np.clip(0.25 + 0.7 * (j[None, :] + 0.5 + 0.8 * jig(a_n, twigs)) / twigs, 0.05, 0.98)
    side = np.where(j % 2 == 0, 1.0, -1.0)[None, :]
    az_tw = side * np.radians(75.0) + 0.5 * jig(a_n, twigs)
    polar_tw = np.radians(spec.twig_angle) * (1.0 + jig(a_n, twigs))
    owner = np.repeat(np.arange(a_n), twigs)
    tw_len = (spec.twig_length * length[:, None] * (1.0 - 0.5 * t_tw) * (1.0 + jig(a_n, twigs))).ravel()
    tw_bend = spec.gravitropism * _Z_UP + 0.5 * jig(a_n * twigs, 3)   # the last number drawn here
    plant = branches.plant[owner]
    s_tw = np.linspace(0.0, 1.0, TWIG_SEGMENTS + 1)
    # every twig on its own from here: on two threads (in_two_threads), into these arrays
    tw_n = len(owner)
    sp_tw = np.empty((tw_n, TWIG_SEGMENTS + 1, 3))
    tw_r = np.empty((tw_n, TWIG_SEGMENTS + 1))
    frames = [np.empty((tw_n, TWIG_SEGMENTS, 3)) for _ in range(3)]

    def grow_twigs(a0: int, a1: int) -> None:
        p1, r1, t1, n1, b1 = branches.sample(owner[a0:a1], t_tw.ravel()[a0:a1])
        d1 = _out(t1, n1, b1, polar_tw.ravel()[a0:a1], az_tw.ravel()[a0:a1])
        sp = sp_tw[a0:a1] = grow_spines(p1, d1, tw_bend[a0:a1], tw_len[a0:a1], TWIG_SEGMENTS,
                                        clearance[plant[a0:a1]])
        tw_r[a0:a1] = (0.5 * r1)[:, None] * (1.0 - 0.6 * s_tw)[None, :]
        t = segment_tangents(sp)
        n, b = transport_frames(t, reference_normals(t[:, 0]))
        for dst, src in zip(frames, (t, n, b)):
            dst[a0:a1] = src

    in_two_threads(tw_n, grow_twigs)
    twig_axes = Axes(sp_tw, tw_r, frames[0], frames[1], frames[2], np.asarray(tw_len, np.float64),  # as _axes
                     np.asarray(plant, np.int64), np.asarray(owner, np.int64), np.asarray(t_tw.ravel(), np.float64))
    return Skeleton(trunks, branches, twig_axes)


# ---------------------------------------------------------------------------------------------
# nodes: where the leaves sit on the skeleton
MAX_TWIGS = 48
S0_TRUNK, S0_BRANCH, S0_TWIG = 0.0, 0.35, 0.1     # where the leafy part of an axis starts


def divergence(spec: PlantArchitecture) -> float:
    """Angle (degrees) between successive nodes: 137.508 (golden), 180 (alternate), 90
    (opposite, decussate) or 180 / whorl (whorled: each whorl sits between the last one's leaves)."""
    return {"golden": GOLDEN_ANGLE, "alternate": 180.0, "opposite": 90.0,
            "whorled": 180.0 / spec.whorl}[spec.phyllotaxis]


def split_counts(total: NDArray[np.int64], weights: NDArray[np.float64]) -> NDArray[np.int64]:
    """Rows of non-negative integers proportional to the rows of ``weights`` (P, W) that sum
    exactly to ``total`` (P,): floors, then one more for the largest remainders."""
    w = np.asarray(weights, np.float64)
    total = np.asarray(total, np.int64)
    wsum = w.sum(axis=1, keepdims=True)
    w = np.where(wsum > 0, w / np.where(wsum > 0, wsum, 1.0), 1.0 / w.shape[1])
    quota = w * total[:, None]
    base = np.floor(quota).astype(np.int64)
    short = total - base.sum(axis=1)
    order = np.argsort(-(quota - base), axis=1, kind="stable")
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.broadcast_to(np.arange(w.shape[1]), w.shape).copy(), axis=1)
    return base + (rank < short[:, None])


def auto_twigs(spec: PlantArchitecture, leaves_per_plant: float) -> int:
    """Twigs per branch: ``spec.twigs``, or for ``twigs = -1`` the fewest that give the leaves
    room at about ``internode × leaf size`` between nodes (at most :data:`MAX_TWIGS`)."""
    if spec.branches == 0:
        return 0
    if spec.twigs >= 0:
        return spec.twigs
    lb = spec.branch_length * spec.height * branch_envelope((np.arange(spec.branches) + 0.5) / spec.branches)
    branch_zone = (1.0 - S0_BRANCH) * lb.sum()
    per_twig = (1.0 - S0_TWIG) * spec.twig_length * 0.7 * lb.sum()
    spacing = spec.internode * spec.leaf_size * (1.0 - 0.5 * spec.size_falloff)
    need = leaves_per_plant / spec.per_node * spacing
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        twigs = (need - branch_zone) / per_twig if per_twig > 0 else math.inf
    if not math.isfinite(twigs):   # vanishing twig or branch lengths: as many twigs as allowed
        return MAX_TWIGS if twigs > 0 else 0
    return int(np.clip(math.ceil(twigs), 0, MAX_TWIGS))


@dataclass
class Nodes:
    """Per-leaf arrays of the leaves' nodes, before the blades are oriented."""

    plant: NDArray[np.int64]
    node: NDArray[np.float64]       # point on the axis where the petiole starts
    out: NDArray[np.float64]        # unit petiole direction
    radius: NDArray[np.float64]     # axis radius at the node
    along: NDArray[np.float64]
    normal: NDArray[np.float64]     # the axis frame's normal (fallback for the blade direction)


def nodes_on(axes: Axes, counts: NDArray[np.int64], s0: float, spec: PlantArchitecture,
             rng: np.random.Generator, along_of: AlongOf) -> Nodes:
    """Place ``counts[a]`` leaves on axis ``a`` node by node (phyllotaxis of ``spec``), base
    to tip over the arc parameters ``[s0, 1]``."""
    k = spec.per_node
    axis = np.repeat(np.arange(len(axes)), counts)
    start = np.cumsum(counts) - counts
    nodes = -(-counts // k)
    phase = rng.uniform(0.0, 360.0, len(axes))   # the only number drawn: the leaves below on two threads
    sp = math.sin(math.radians(spec.petiole_angle))
    cp = math.cos(math.radians(spec.petiole_angle))
    n_leaves = len(axis)
    node, out, normal = np.empty((n_leaves, 3)), np.empty((n_leaves, 3)), np.empty((n_leaves, 3))
    radius, along = np.empty(n_leaves), np.empty(n_leaves)

    def leaves(a0: int, a1: int) -> None:
        ax = axis[a0:a1]
        i = np.arange(a0, a1) - start[ax]
        j, slot = i // k, i % k
        s = s0 + (1.0 - s0) * (j + 0.5) / np.maximum(nodes[ax], 1)
        azimuth = np.radians(phase[ax] + j * divergence(spec) + slot * (360.0 / k))
        p, r, t, n, b = axes.sample(ax, s)
        node[a0:a1], radius[a0:a1], normal[a0:a1] = p, r, n
        out[a0:a1] = cp * t + sp * (np.cos(azimuth)[:, None] * n + np.sin(azimuth)[:, None] * b)
        along[a0:a1] = along_of(ax, s)

    in_two_threads(n_leaves, leaves)
    return Nodes(axes.plant[axis], node, out, radius, along, normal)


def place_nodes(spec: PlantArchitecture, sk: Skeleton, counts: NDArray[np.int64], rng: np.random.Generator) -> Nodes:
    """Split each plant's leaves over its leafy axes by leafy length and place them."""
    p_n = len(counts)
    if sk.branches is None:
        clear = spec.leaf_size * (1.3 + spec.petiole) / spec.height
        zone0 = min(max(spec.crown_base, clear, S0_TRUNK), 0.9)
        levels = [(sk.trunks, zone0, lambda a, s: (s - zone0) / max(1.0 - zone0, 1e-9))]
    else:
        br, tw = sk.branches, sk.twigs
        reach = br.length.copy()                   # longest path from a branch base to a tip
        if tw is not None:
            np.maximum.at(reach, tw.parent, tw.attach * br.length[tw.parent] + tw.length)
        levels = [(br, S0_BRANCH, lambda a, s: s * br.length[a] / reach[a])]
        if tw is not None:
            levels.append((tw, S0_TWIG, lambda a, s: (tw.attach[a] * br.length[tw.parent[a]]
                                                      + s * tw.length[a]) / reach[tw.parent[a]]))
    weights = np.concatenate([(ax.length * (1.0 - s0)).reshape(p_n, -1) for ax, s0, _ in levels], axis=1)
    alloc = split_counts(counts, weights)
    parts, col = [], 0
    for ax, s0, along_of in levels:
        w = len(ax) // p_n
        parts.append(nodes_on(ax, alloc[:, col:col + w].ravel(), s0, spec, rng, along_of))
        col += w
    if len(parts) == 1:
        return parts[0]
    order = np.argsort(np.concatenate([q.plant for q in parts]), kind="stable")
    merged = [np.concatenate([getattr(q, f.name) for q in parts]) for f in fields(Nodes)]
    sorted_ = [np.empty_like(m) for m in merged]

    def gather(a: int, b: int) -> None:
        for m, dst in zip(merged, sorted_):
            np.take(m, order[a:b], axis=0, out=dst[a:b])

    in_two_threads(len(order), gather)
    return Nodes(*sorted_)
