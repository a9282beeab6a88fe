"""Procedural plants and scatters of plants: where every leaf of a large scene sits.

World convention: +z is up, the ground is ``z = 0``, lengths are in leaf lengths. A leaf matrix
``M`` (4×4, column vectors) maps leaf space (blade base at the origin, apex at +y, upper side
+z, width along x) to world: ``M[:3, :3] = R s`` with ``R`` a proper rotation and ``s`` the leaf
size, ``M[:3, 3]`` the end of the petiole, where the blade starts.

A plant is a trunk, ``branches`` first-order branches spiralling up the trunk by the golden
angle, and ``twigs`` second-order branches per branch alternating left and right, each a
generalized cylinder (:mod:`leafview.scene.stems`). Leaves sit on the outer part of the branches
and on the twigs (on the trunk itself when ``branches = 0``), placed node by node by
phyllotaxis:

========== ================ =============================================================
mode       leaves per node   azimuth of leaf ``slot`` at node ``j`` (degrees)
========== ================ =============================================================
golden     1                ``137.508 j`` (the golden angle 360 (1 - 1/φ))
alternate  1                ``180 j`` (distichous)
opposite   2                ``90 j + 180 slot`` (decussate)
whorled    ``whorl``         ``(180 / whorl) j + (360 / whorl) slot``
========== ================ =============================================================

Azimuths are measured around the axis in its rotation-minimising frame, so the divergence between
successive nodes stays exact along curved axes. The petiole leaves the axis at ``petiole_angle``
from the axis tangent; the blade points away from the axis, raised ``tilt`` degrees above the
horizontal (``tilt_top`` at the top of the plant, interpolated by relative height), and is then
turned towards the light by ``light_following`` of the angle between its normal and the light.
Leaf size falls linearly along the branch, from ``leaf_size`` to ``leaf_size (1 - size_falloff)``.

The papers give no plant architecture (their subject is the single leaf); these rules are the
usual ones of procedural tree modelling, chosen so that every quantity a test checks (divergence,
size falloff, attachment, light facing, ground clearance) holds by construction.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.params import ParamError
from leafview.scene.stems import (
    GOLDEN_ANGLE,
    Mesh3,
    Skeleton,
    auto_twigs,
    divergence,
    grow_skeleton,
    merge_meshes,
    place_nodes,
    split_counts,
    sweep_tubes,
)
from leafview.scene.threads import background, in_two_threads, two_threads

__all__ = ["PlantSpec", "Placement", "grow_plant", "scatter", "PHYLLOTAXIS", "LAYOUTS",
           "GOLDEN_ANGLE", "divergence", "PETIOLE_LIMIT", "PETIOLE_SIDES", "LEAF_BOX", "PLANT_RANGES",
           "MIN_LENGTH"]

PHYLLOTAXIS = ("golden", "alternate", "opposite", "whorled")
LAYOUTS = ("plant", "field", "hedge")
PETIOLE_LIMIT = 20_000      # petiole tubes only up to this many leaves (8 vertices each)
PETIOLE_SIDES = 4
LEAF_BOX = ((-0.6, 0.6), (0.0, 1.0), (-0.3, 0.3))   # conservative leaf-space box of a blade
LEAVES_PER_PLANT = 2000     # default split of a field or hedge into plants
_Z = np.array([0.0, 0.0, 1.0])


def _num(name: str, value: Any, lo: float | None = None, hi: float | None = None, *,
         open_lo: bool = False, integer: bool = False, prefix: str = "plant.") -> float | int:
    """``value`` checked as a finite number in range; errors name ``prefix + name``."""
    path = f"{prefix}{name}"
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ParamError(path, f"must be a number, got {value!r}")
    if not math.isfinite(float(value)):
        raise ParamError(path, f"must be finite, got {value!r}")
    if integer and float(value) != math.floor(float(value)):
        raise ParamError(path, f"must be an integer, got {value!r}")
    v = int(value) if integer else float(value)
    if lo is not None and (v <= lo if open_lo else v < lo):
        raise ParamError(path, f"must be {'>' if open_lo else '≥'} {lo:g}, got {v:g}")
    if hi is not None and v > hi:
        raise ParamError(path, f"must be ≤ {hi:g}, got {v:g}")
    return v


# The shortest length a plant setting may have, in leaf lengths (the smallest transform scale):
# a positive length closer to 0 (5e-324) underflows to 0 or inf in the growth arithmetic.
MIN_LENGTH = 1e-6

# The numeric settings of PlantSpec: name -> (lo, hi, open_lo, integer). The loader and the
# published scene schema (leafview.scene.schema) both read this table.
PLANT_RANGES: dict[str, tuple[float | None, float | None, bool, bool]] = {
    "whorl": (2, 12, False, True), "height": (MIN_LENGTH, 1e4, False, False),
    "branches": (0, 500, False, True), "branch_angle": (0, 120, False, False),
    "leaf_size": (MIN_LENGTH, 1e3, False, False), "size_falloff": (0, 0.95, False, False),
    "petiole": (0, 10, False, False), "tilt": (-90, 90, False, False),
    "light_following": (0, 1, False, False), "tilt_top": (-90, 90, False, False),
    "petiole_angle": (5, 175, False, False), "branch_length": (MIN_LENGTH, 3, False, False),
    "crown_base": (0, 0.95, False, False), "twigs": (-1, 200, False, True),
    "twig_angle": (0, 120, False, False), "twig_length": (MIN_LENGTH, 3, False, False),
    "internode": (MIN_LENGTH, 100, False, False), "gravitropism": (-1, 1, False, False),
    "lean": (0, 45, False, False), "radius": (MIN_LENGTH, 1e3, False, False),
    "taper": (0, 0.99, False, False), "variation": (0, 0.5, False, False),
    "leaf_jitter": (0, 90, False, False),
}


@dataclass(frozen=True)
class PlantSpec:
    """The architecture of one plant species (validated: bad values raise
    :class:`~leafview.core.params.ParamError` naming ``plant.<field>``).

    Angles in degrees, lengths in leaf lengths. The defaults grow a small round-crowned tree.

    Attributes
    ----------
    phyllotaxis : "golden", "alternate", "opposite" or "whorled" (see the module table).
    whorl : leaves per node in "whorled" mode (2-12).
    height : trunk height.
    branches : first-order branches (0: leaves directly on the trunk).
    branch_angle : angle between a branch and the trunk at its base (0-120).
    leaf_size : leaf length at the base of a branch.
    size_falloff : the leaf at a branch tip is ``leaf_size (1 - size_falloff)`` long.
    petiole : petiole length as a fraction of the leaf's size (plus the stem radius).
    tilt : blade elevation above the horizontal low in the plant.
    light : direction towards the light (normalised here).
    light_following : 0 leaves the blade as placed, 1 turns its upper side fully to the light.
    tilt_top : blade elevation at the top of the plant (tilt is interpolated by height).
    petiole_angle : angle between petiole and axis (towards the axis tip).
    branch_length : length of the lowest branch as a fraction of ``height`` (upper ones shorter).
    crown_base : fraction of the height where branches (or trunk leaves) start.
    twigs : second-order branches per branch; -1 chooses from the leaf count so that nodes
        lie about ``internode`` apart.
    twig_angle : angle between a twig and its branch.
    twig_length : length of a twig as a fraction of its branch's length (at the branch base).
    internode : target distance between successive nodes, × leaf size (used by ``twigs = -1``).
    gravitropism : curvature of branches: > 0 bends them upwards, < 0 makes them droop (-1..1).
    lean : largest random lean of the trunk.
    radius : trunk radius at the ground.
    taper : the trunk radius at the top is ``radius (1 - taper)``.
    variation : relative random variation of branch lengths, angles and leaf sizes (0-0.5).
    leaf_jitter : random yaw/elevation/roll of each blade (degrees, before light following).
    """

    phyllotaxis: str = "golden"
    whorl: int = 3
    height: float = 12.0
    branches: int = 12
    branch_angle: float = 50.0
    leaf_size: float = 1.0
    size_falloff: float = 0.5
    petiole: float = 0.25
    tilt: float = 35.0
    light: tuple[float, float, float] = (0.3, -0.4, 1.0)
    light_following: float = 0.6
    tilt_top: float = 60.0
    petiole_angle: float = 55.0
    branch_length: float = 0.45
    crown_base: float = 0.3
    twigs: int = -1
    twig_angle: float = 45.0
    twig_length: float = 0.45
    internode: float = 0.3
    gravitropism: float = 0.3
    lean: float = 4.0
    radius: float = 0.15
    taper: float = 0.7
    variation: float = 0.15
    leaf_jitter: float = 12.0

    def __post_init__(self) -> None:
        if self.phyllotaxis not in PHYLLOTAXIS:
            raise ParamError("plant.phyllotaxis",
                             f"unknown mode {self.phyllotaxis!r} (use {', '.join(PHYLLOTAXIS)})")
        light = self.light
        if isinstance(light, (str, bytes)) or not hasattr(light, "__len__") or len(light) != 3:
            raise ParamError("plant.light", f"must be three numbers, got {light!r}")
        lv = tuple(float(_num(f"light[{i}]", c)) for i, c in enumerate(light))
        if math.hypot(*lv) < 1e-9:
            raise ParamError("plant.light", "must not be the zero vector")
        object.__setattr__(self, "light", lv)
        for name, (lo, hi, open_lo, integer) in PLANT_RANGES.items():
            object.__setattr__(self, name, _num(name, getattr(self, name), lo, hi,
                                                open_lo=open_lo, integer=integer))

    @property
    def per_node(self) -> int:
        """Leaves per node of the phyllotaxis mode."""
        return {"golden": 1, "alternate": 1, "opposite": 2, "whorled": self.whorl}[self.phyllotaxis]

    def to_dict(self) -> dict[str, Any]:
        return {f.name: (list(getattr(self, f.name)) if f.name == "light" else getattr(self, f.name))
                for f in fields(self)}


@dataclass
class Placement:
    """Leaves of one or more plants (``N`` leaves, ``P`` plants).

    Attributes
    ----------
    matrices : (N, 4, 4) float64 leaf -> world (column vectors).
    plant : (N,) int32 index of the plant of each leaf (leaves are sorted by plant).
    along : (N,) float32 position along its first-order branch (0 base, 1 tip); along the trunk
        when the plant has no branches.
    height : (N,) float32 blade-base height relative to the plant's highest leaf (0 ground, 1 top).
    stems : (positions (M, 3) float32, normals (M, 3) float32, triangles (K, 3) uint32) of all
        trunks, branches, twigs and (up to :data:`PETIOLE_LIMIT` leaves) petioles, or None.
    plant_origins : (P, 3) float64 where each trunk meets the ground.
    stem_ranges : vertex range ``(start, stop)`` of each part ("trunks", "branches", "twigs",
        "petioles") in ``stems``. Petiole ``i`` owns :data:`PETIOLE_SIDES` × 2 rows from the
        start of its range, base ring first.
    """

    matrices: NDArray[np.float64]
    plant: NDArray[np.int32]
    along: NDArray[np.float32]
    height: NDArray[np.float32]
    stems: Mesh3 | None
    plant_origins: NDArray[np.float64]
    stem_ranges: dict[str, tuple[int, int]] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.matrices.shape[0])

    @property
    def sizes(self) -> NDArray[np.float64]:
        """(N,) leaf sizes (the uniform scale of each matrix)."""
        return np.linalg.norm(self.matrices[:, :3, 1], axis=1)

    @property
    def normals(self) -> NDArray[np.float64]:
        """(N, 3) unit normals of the blades' upper sides (leaf +z in world)."""
        z = self.matrices[:, :3, 2]
        return z / np.linalg.norm(z, axis=1, keepdims=True)


# ---------------------------------------------------------------------------------------------
# leaf placement
def _unit(v: NDArray[np.float64]) -> NDArray[np.float64]:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


# _orient works on (3, N) arrays, one contiguous row per component: every step is a few passes
# over contiguous memory (10⁶ leaves in a field), without (N, 3) temporaries or strided columns
def _cross_rows(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cross products of the columns of (3, N) arrays (``b`` may be a (3, 1) constant)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    for i, (j, k) in enumerate(((1, 2), (2, 0), (0, 1))):   # each row written in place: no stacked copy
        np.multiply(a[j], b[k], out=out[i])
        out[i] -= a[k] * b[j]
    return out


def _rotate_rows(v: NDArray[np.float64], axis: NDArray[np.float64], c: NDArray[np.float64],
                 s: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rodrigues rotation of the columns of ``v`` about the unit columns of ``axis`` by the angles
    whose cosines and sines are ``c`` and ``s`` (all (3, N) or (N,))."""
    k = (axis * v).sum(axis=0) * (1.0 - c)
    return v * c + _cross_rows(axis, v) * s + axis * k


def _orient(spec: PlantSpec, out: NDArray[np.float64], normal: NDArray[np.float64],
            rel_height: NDArray[np.float64], jit: NDArray[np.float64]
            ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The rotation of every blade as its three columns, (3, N) each: the world directions of leaf
    x (width), y (base to apex) and z (upper side), from the petiole directions ``out`` and the
    axis normals ``normal`` (N, 3) and the jitter angles ``jit`` (N, 3; radians): leaf by leaf,
    so that any run of leaves gives the same numbers alone as in the whole."""
    n = len(out)
    hx, hy = out[:, 0].copy(), out[:, 1].copy()      # the petiole's horizontal direction
    for fallback in (normal, np.array([1.0, 0.0, 0.0])):      # petiole (nearly) vertical
        weak = np.hypot(hx, hy) < 1e-6
        if not weak.any():
            break
        alt = np.broadcast_to(fallback, out.shape)[weak]
        hx[weak], hy[weak] = alt[:, 0], alt[:, 1]
    weak = np.hypot(hx, hy) < 1e-6
    hx[weak], hy[weak] = 1.0, 0.0
    yaw = np.arctan2(hy, hx)
    yaw += jit[:, 0]
    elev = np.radians(spec.tilt + (spec.tilt_top - spec.tilt) * rel_height)
    elev += jit[:, 1]
    cy, sy, ce, se = np.cos(yaw), np.sin(yaw), np.cos(elev), np.sin(elev)
    # y = cos(elev) h + sin(elev) ẑ with h = (cos yaw, sin yaw, 0); x = h × ẑ = (sin yaw, -cos yaw, 0)
    # (horizontal, x × y = normal up), rolled about y by the third jitter angle: x ⊥ y, so
    # x' = x cos r + (y × x) sin r with y × x = (sin(elev) cos yaw, sin(elev) sin yaw, -cos(elev))
    y = np.empty((3, n))
    np.multiply(ce, cy, out=y[0])
    np.multiply(ce, sy, out=y[1])
    y[2] = se
    cr, sr = np.cos(jit[:, 2]), np.sin(jit[:, 2])
    x = np.empty((3, n))
    np.multiply(sy, cr, out=x[0])
    x[0] += se * cy * sr
    np.multiply(se * sy, sr, out=x[1])
    x[1] -= cy * cr
    np.multiply(-ce, sr, out=x[2])
    z = _cross_rows(x, y)
    f = spec.light_following
    if f > 0:
        light = _unit(np.asarray(spec.light, np.float64))[:, None]
        cos_a = np.clip((z * light).sum(axis=0), -1.0, 1.0)
        axis = _cross_rows(z, light)
        na = np.sqrt((axis * axis).sum(axis=0))
        flip = na < 1e-9                                          # parallel or opposite
        axis[:, flip] = x[:, flip]
        na[flip] = np.sqrt((x[:, flip] ** 2).sum(axis=0))
        axis /= np.maximum(na, 1e-12)
        ang = f * np.arccos(cos_a)
        ang[flip & (cos_a > 0)] = 0.0
        c, s = np.cos(ang), np.sin(ang)
        x, y = _rotate_rows(x, axis, c, s), _rotate_rows(y, axis, c, s)
        z = _cross_rows(x, y)
    return x, y, z


def _blade_low(m: NDArray[np.float64]) -> NDArray[np.float64]:
    """Lowest world z of each blade's conservative leaf-space box :data:`LEAF_BOX`."""
    low = m[:, 2, 3].copy()
    for c, (lo, hi) in enumerate(LEAF_BOX):
        low += np.minimum(m[:, 2, c] * lo, m[:, 2, c] * hi)
    return low


@dataclass
class _Grown:
    placement: Placement
    skeleton: Skeleton
    petiole_start: NDArray[np.float64]      # (N, 3) node on the axis
    petiole_radius: NDArray[np.float64]     # (N,)


def grow_plants(spec: PlantSpec, counts: NDArray[np.int64], scales: NDArray[np.float64],
                rng: np.random.Generator) -> _Grown:
    """Grow ``len(counts)`` plants at the origin, plant ``i`` with ``counts[i]`` leaves and scale
    ``scales[i]`` (all arrays vectorised over plants, axes and leaves)."""
    counts = np.asarray(counts, np.int64)
    scales = np.asarray(scales, np.float64)
    p_n = len(counts)
    twigs = auto_twigs(spec, float(np.median(counts)) if p_n else 0.0)
    sk = grow_skeleton(spec, scales, twigs, rng)
    lv = place_nodes(spec, sk, counts, rng)
    n = len(lv.plant)
    var = spec.variation
    # the numbers first, in their order; then the leaves one by one, on two threads (in_two_threads)
    spread = rng.uniform(-1.0, 1.0, n)
    jit = np.radians(spec.leaf_jitter) * rng.uniform(-1.0, 1.0, (n, 3))   # the last number drawn here
    size, base = np.empty(n), np.empty((n, 3))

    def petiole_ends(a: int, b: int) -> None:
        s = size[a:b] = (spec.leaf_size * scales[lv.plant[a:b]] * (1.0 - spec.size_falloff * lv.along[a:b])
                         * (1.0 + var * spread[a:b]))
        base[a:b] = lv.node[a:b] + (lv.radius[a:b] + spec.petiole * s)[:, None] * lv.out[a:b]

    in_two_threads(n, petiole_ends)
    top = np.zeros(p_n)
    np.maximum.at(top, lv.plant, base[:, 2])
    rel = np.empty(n)
    m = np.zeros((n, 4, 4))

    def blades(a: int, b: int) -> None:
        """Leaves ``a:b``'s matrices: oriented, scaled, placed and lifted (leaf by leaf)."""
        rel[a:b] = np.clip(base[a:b, 2] / np.maximum(top[lv.plant[a:b]], 1e-12), 0.0, 1.0)
        part, s = m[a:b], size[a:b]
        columns = _orient(spec, lv.out[a:b], lv.normal[a:b], rel[a:b], jit[a:b])
        for c, col in enumerate(columns):   # scaled straight into the matrices, no (N, 3, 3) temporaries
            for i in range(3):
                np.multiply(col[i], s, out=part[:, i, c])
        part[:, :3, 3] = base[a:b]
        part[:, 3, 3] = 1.0
        low = _blade_low(part)                   # lift blades that would reach below the ground
        margin = 0.02 * s
        lift = np.maximum(margin - low, 0.0)
        part[:, 2, 3] += lift

    in_two_threads(n, blades)
    placement = Placement(m, lv.plant.astype(np.int32), np.clip(lv.along, 0, 1).astype(np.float32),
                          rel.astype(np.float32), None, np.zeros((p_n, 3)))
    return _Grown(placement, sk, lv.node, 0.03 * size)


BIG_SCENE = 200_000     # above this many leaves (or 100 plants) stems are drawn coarsely


def stem_detail(n_leaves: int, n_plants: int) -> dict[str, tuple[int, int]]:
    """``(sides, ring step)`` of the tubes of each level: full detail for small scenes; for big
    ones fewer sides, and branches and twigs keep every second / fourth ring only (a twig is
    then a straight 3-sided prism, 6 vertices)."""
    if n_leaves > BIG_SCENE or n_plants > 100:
        return {"trunks": (6, 1), "branches": (4, 2), "twigs": (3, 4)}
    return {"trunks": (12, 1), "branches": (6, 1), "twigs": (4, 1)}


def finish(grown: _Grown, origins: NDArray[np.float64], stems: bool) -> Placement:
    """Move plant ``i`` to ``origins[i]`` and build the stem mesh (if ``stems``)."""
    pl, wait = finish_later(grown, origins, stems)
    wait()
    return pl


def finish_later(grown: _Grown, origins: NDArray[np.float64], stems: bool
                 ) -> tuple[Placement, Callable[[], None]]:
    """:func:`finish`, the stem mesh of a large scene built on the worker thread
    (:func:`~leafview.scene.threads.two_threads`): the placement (its leaves moved, its ``stems``
    not yet set) and the call that waits for the mesh and sets them."""
    pl = grown.placement
    pl.matrices[:, :3, 3] += origins[pl.plant]
    pl.plant_origins = pl.plant_origins + origins
    if not stems:
        return pl, lambda: None
    if not two_threads(len(pl)):
        _stem_mesh(grown, origins)
        return pl, lambda: None
    pending = background(_stem_mesh, grown, origins)
    return pl, lambda: pending.result()


def _stem_mesh(grown: _Grown, origins: NDArray[np.float64]) -> None:
    """The stem mesh of the placement ``grown`` moved to ``origins`` into its ``stems`` and
    ``stem_ranges``."""
    pl, sk = grown.placement, grown.skeleton
    detail = stem_detail(len(pl), len(origins))
    meshes, names = [], []
    for name, axes in (("trunks", sk.trunks), ("branches", sk.branches), ("twigs", sk.twigs)):
        if axes is not None and len(axes):
            sides, step = detail[name]
            rings = np.unique(np.r_[np.arange(0, axes.spines.shape[1], step), axes.spines.shape[1] - 1])
            spines = axes.spines[:, rings] + origins[axes.plant][:, None, :]
            meshes.append(sweep_tubes(spines, axes.radii[:, rings], sides))
            names.append(name)
    if 0 < len(pl) <= PETIOLE_LIMIT:
        start = grown.petiole_start + origins[pl.plant]
        spines = np.stack([start, pl.matrices[:, :3, 3]], axis=1)
        r = grown.petiole_radius
        meshes.append(sweep_tubes(spines, np.stack([r, 0.7 * r], axis=1), PETIOLE_SIDES))
        names.append("petioles")
    mesh, ranges = merge_meshes(meshes)
    pl.stems = mesh
    pl.stem_ranges = dict(zip(names, ranges))


# ---------------------------------------------------------------------------------------------
# public entry points
def _seed(seed: Any) -> int:
    return int(_num("seed", seed, 0, 2**63 - 1, integer=True, prefix=""))


def grow_plant(spec: PlantSpec, n_leaves: int, seed: int, origin: ArrayLike = (0.0, 0.0, 0.0),
               scale: float = 1.0, *, stems: bool = True) -> Placement:
    """One plant with exactly ``n_leaves`` leaves (deterministic for ``seed``).

    Parameters
    ----------
    spec : PlantSpec
        The architecture.
    n_leaves : int
        Number of leaves (≥ 1).
    seed : int
        Random seed (≥ 0).
    origin : (3,)
        Where the trunk meets the ground.
    scale : float
        Uniform size of the whole plant (trunk, branches and leaves).
    stems : bool
        Build the stem mesh (with petioles up to :data:`PETIOLE_LIMIT` leaves).
    """
    if not isinstance(spec, PlantSpec):
        raise ParamError("plant", f"expected a PlantSpec, got {type(spec).__name__}")
    n = int(_num("n_leaves", n_leaves, 1, integer=True, prefix=""))
    rng = np.random.default_rng([_seed(seed), 0x91A47])
    scale = float(_num("scale", scale, 0, 1e6, open_lo=True, prefix=""))
    o = np.asarray(origin, np.float64)
    if o.shape != (3,) or not np.all(np.isfinite(o)):
        raise ParamError("origin", f"must be three finite numbers, got {origin!r}")
    grown = grow_plants(spec, np.array([n]), np.array([scale]), rng)
    return finish(grown, o[None, :], bool(stems))


def scatter(layout: str, n_leaves: int, seed: int, spec: PlantSpec | None = None,
            plants: int | None = None, extent: float | None = None, stems: bool = True) -> Placement:
    """Leaves of one plant or of many.

    Parameters
    ----------
    layout : str
        ``"plant"``: one plant at the origin, scale 1. ``"field"``: plants on a jittered grid
        (``ceil(√P)`` columns and as many rows as needed, one plant per cell, ±30 % of a cell off
        centre) over a square of side ``extent`` centred on
        the origin; by default about one crown width per plant, so crowns meet. ``"hedge"``:
        plants along the x axis, each crown touching the next (or spread evenly over a length
        ``extent``), centred on the origin.
    n_leaves : int
        Total number of leaves (≥ 1), split exactly among the plants in proportion to their
        scale squared.
    seed : int
        Random seed (≥ 0); the same seed gives identical arrays.
    spec : PlantSpec, optional
        The architecture (default ``PlantSpec()``).
    plants : int, optional
        Number of plants (default ``round(n_leaves / 2000)``, at least 1, at most ``n_leaves``).
    extent : float, optional
        Side of the field or length of the hedge.
    stems : bool
        Build the stem mesh.

    Plant scales vary by ±20 % by seed in fields and hedges.
    """
    pl, wait = scatter_later(layout, n_leaves, seed, spec, plants, extent, stems)
    wait()
    return pl


def scatter_later(layout: str, n_leaves: int, seed: int, spec: PlantSpec | None = None,
                  plants: int | None = None, extent: float | None = None, stems: bool = True
                  ) -> tuple[Placement, Callable[[], None]]:
    """:func:`scatter` with the stem mesh of a large scene still being built on the worker thread
    (:func:`finish_later`): the placement and the call that waits for its ``stems``."""
    if layout not in LAYOUTS:
        raise ParamError("layout", f"unknown layout {layout!r} (use {', '.join(LAYOUTS)})")
    spec = PlantSpec() if spec is None else spec
    if not isinstance(spec, PlantSpec):
        raise ParamError("plant", f"expected a PlantSpec, got {type(spec).__name__}")
    n = int(_num("n_leaves", n_leaves, 1, integer=True, prefix=""))
    rng = np.random.default_rng([_seed(seed), 0x5CA77])
    if plants is None:
        p = 1 if layout == "plant" else max(1, min(n, int(round(n / LEAVES_PER_PLANT))))
    else:
        p = int(_num("plants", plants, 1, 10_000_000, integer=True, prefix=""))
        if layout == "plant" and p != 1:
            raise ParamError("plants", f"layout 'plant' grows exactly one plant, got {p}")
    if extent is not None:
        extent = float(_num("extent", extent, 0, 1e7, open_lo=True, prefix=""))
    scales = np.ones(1) if layout == "plant" else 1.0 + 0.2 * rng.uniform(-1.0, 1.0, p)
    counts = split_counts(np.array([n]), (scales**2)[None, :])[0]
    grown = grow_plants(spec, counts, scales, rng)
    origins = _arrange(layout, grown.placement, scales, extent, rng)
    return finish_later(grown, origins, bool(stems))


def _crown_x(pl: Placement, n_plants: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per plant grown at the origin: smallest and largest x reached by its leaves."""
    lo = np.full(n_plants, np.inf)
    hi = np.full(n_plants, -np.inf)
    x, size = pl.matrices[:, 0, 3], pl.sizes
    np.minimum.at(lo, pl.plant, x - size)
    np.maximum.at(hi, pl.plant, x + size)
    empty = ~np.isfinite(lo)
    if empty.any():
        lo[empty], hi[empty] = -0.5, 0.5
    return lo, hi


def _arrange(layout: str, pl: Placement, scales: NDArray[np.float64], extent: float | None,
             rng: np.random.Generator) -> NDArray[np.float64]:
    """Origins of the plants for ``layout`` (see :func:`scatter`)."""
    p = len(scales)
    origins = np.zeros((p, 3))
    if layout == "plant":
        return origins
    lo, hi = _crown_x(pl, p)
    width = float(np.median(hi - lo))
    if layout == "hedge":
        if extent is None:
            centres = np.concatenate([[0.0], np.cumsum(hi[:-1] - lo[1:])])   # crowns touch
        else:
            centres = (np.arange(p) + 0.5) * extent / p
        origins[:, 0] = centres - 0.5 * (centres[0] + lo[0] + centres[-1] + hi[-1])
        origins[:, 1] = 0.05 * width * rng.uniform(-1.0, 1.0, p)
        return origins
    if extent is None:
        extent = width * math.sqrt(p)
    gx = int(math.ceil(math.sqrt(p)))          # gx × gy cells (gx gy ≥ p), one plant per cell
    gy = int(math.ceil(p / gx))
    cell = np.array([extent / gx, extent / gy])
    chosen = rng.permutation(gx * gy)[:p]
    ij = np.stack([chosen % gx, chosen // gx], axis=1).astype(np.float64)
    origins[:, :2] = (ij + 0.5 + 0.3 * rng.uniform(-1.0, 1.0, (p, 2))) * cell - 0.5 * extent
    return origins
