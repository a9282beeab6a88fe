"""Cantilever-beam bending (Geng, Hu & Zhang 2014, sec. 4, eq. 4) of the midrib and petiole, and the bend
profile the leaf shader applies.

For a chain of segments from a fixed joint, segment i makes the angle θ⁰_i with the load
direction and carries ``load_i = |Σ_{j>=i} F_j|``; its bending angle φ_i solves (eq. 4)::

    ds_i² · sin(θ⁰_i - φ_i) · load_i = EI_i · φ_i

:func:`solve_bending` solves each equation by Newton's method kept inside the bracket
[0, θ⁰_i] (where the residual changes sign), falling back to bisection when a Newton step
leaves it. Stopping rule: ``|residual| <= 1e-11`` or a bracket narrower than 1e-15 rad (then
``|residual| <= |f'| · 1e-15``), at most 100 iterations; the residual is then below 1e-10 for
``ds_i² load_i + EI_i`` up to 1e5.

:func:`bend_profile` bends the midrib (and an optional petiole before the leaf base) under the
blade's own distributed load (``load`` × strip area, per unit segment length so the result does
not depend on how finely the chain is cut): segment by segment from the fixed end, each segment's θ⁰ is
measured after the rotations of the segments before it, and rotating a segment turns everything
beyond it (Hu et al.'s joint rotation). All rotations are about one axis ``N = ŷ × ĝ`` (ĝ the load
direction in leaf space), so the bend is described by the accumulated angle Φ(v) and the offset
Δ(v) of the bent midrib from the straight one, sampled at ``BEND_SAMPLES`` values of v.

The chain lives once: :func:`bend_profiles` walks the chains of many leaves together (a scene's
species, a leaf set), and :func:`bend_profile` is that walk for one leaf, cached.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.bezier import bernstein
from leafview.core.blade import axis_frames
from leafview.core.params import Bending, LeafParams, ParamError, Shape, Transform, Vec3, transform_matrices
from leafview.deform.fbm import catmull_rom

__all__ = ["solve_bending", "residual", "bend_profile", "bend_profiles", "BendProfile", "BEND_SAMPLES", "MIDRIB_SEGMENTS",
           "PETIOLE_SEGMENTS", "rotation", "sample_clamped"]

BEND_SAMPLES = 8
MIDRIB_SEGMENTS = 48
PETIOLE_SEGMENTS = 8


def residual(phi: ArrayLike, ds: ArrayLike, theta0: ArrayLike, load: ArrayLike, EI: ArrayLike) -> NDArray[np.float64]:
    """Left minus right side of eq. 4."""
    phi, ds, theta0, load, EI = np.broadcast_arrays(*(np.asarray(x, np.float64) for x in (phi, ds, theta0, load, EI)))
    return ds**2 * np.sin(theta0 - phi) * load - EI * phi


def solve_bending(ds: ArrayLike, theta0: ArrayLike, load: ArrayLike, EI: ArrayLike) -> NDArray[np.float64]:
    """Bending angles φ_i of eq. 4 for every segment (vectorised; see the module docstring).

    Parameters
    ----------
    ds: segment lengths (> 0). theta0: angle between segment and load direction, radians in
    [0, π]. load: magnitude of the load carried by the segment (>= 0). EI: flexural rigidity (> 0).
    """
    ds, theta0, load, EI = np.broadcast_arrays(*(np.asarray(x, np.float64) for x in (ds, theta0, load, EI)))
    if np.any(~np.isfinite(ds)) or np.any(ds <= 0):
        raise ValueError("ds: segment lengths must be finite and > 0")
    if np.any(~np.isfinite(theta0)) or np.any((theta0 < 0) | (theta0 > np.pi)):
        raise ValueError("theta0: angles must lie in [0, π]")
    if np.any(~np.isfinite(load)) or np.any(load < 0):
        raise ValueError("load: magnitudes must be finite and >= 0")
    if np.any(~np.isfinite(EI)) or np.any(EI <= 0):
        raise ValueError("EI: flexural rigidity must be finite and > 0")
    k = ds**2 * load
    lo, hi = np.zeros_like(theta0), theta0.copy()      # f(lo) >= 0 >= f(hi)
    phi = theta0 * k / (k + EI)                       # the small-angle solution as a start
    tol = 1e-11
    for _ in range(100):
        f = k * np.sin(theta0 - phi) - EI * phi
        done = (np.abs(f) <= tol) | (hi - lo <= 1e-15)
        if done.all():
            break
        lo = np.where(f > 0, phi, lo)
        hi = np.where(f < 0, phi, hi)
        fp = -k * np.cos(theta0 - phi) - EI
        step = np.where(fp != 0, phi - f / np.where(fp != 0, fp, 1.0), np.inf)
        inside = (step > lo) & (step < hi)
        phi = np.where(done, phi, np.where(inside, step, 0.5 * (lo + hi)))
    return phi


def rotation(axis: ArrayLike, angle: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrices (..., 3, 3) about unit ``axis`` by ``angle`` (Rodrigues)."""
    a = np.asarray(axis, np.float64)
    t = np.asarray(angle, np.float64)[..., None, None]
    kx = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.cos(t) * np.eye(3) + np.sin(t) * kx + (1 - np.cos(t)) * np.outer(a, a)


class BendProfile:
    """The sampled bend: ``axis`` N (3,), ``phi`` Φ_k (K,), ``delta`` Δ_k (K, 3) at v_k = k/(K-1),
    and ``twist`` α (radians at the apex). ``identity`` when nothing bends or twists."""

    def __init__(self, axis: NDArray[np.float64], phi: NDArray[np.float64], delta: NDArray[np.float64],
                 twist: float) -> None:
        for a in (axis, phi, delta):
            a.setflags(write=False)  # profiles are cached and shared
        self.axis, self.phi, self.delta, self.twist = axis, phi, delta, twist

    @property
    def identity(self) -> bool:
        return not self.phi.any() and not self.delta.any() and self.twist == 0.0


def sample_clamped(values: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Catmull-Rom through K uniform samples on [0, 1] (ends extrapolated linearly): value and
    d/dv at ``v``. ``values`` is (K,) or (K, d). Mirrors ``bend_samples`` in leaf_eval.glsl."""
    vals = np.asarray(values, np.float64)
    k = vals.shape[0]
    ext = np.concatenate([2 * vals[:1] - vals[1:2], vals, 2 * vals[-1:] - vals[-2:-1]])
    t = np.clip(np.asarray(v, np.float64), 0.0, 1.0) * (k - 1)
    i = np.minimum(np.floor(t).astype(np.int64), k - 2)
    x = t - i
    p0, p1, p2, p3 = ext[i], ext[i + 1], ext[i + 2], ext[i + 3]
    if vals.ndim > 1:
        x = x[..., None]
    value, slope = catmull_rom(p0, p1, p2, p3, x)
    return value, slope * (k - 1)


def bend_profile(params: LeafParams) -> BendProfile:
    """Solve the petiole + midrib chain under the blade's load (see the module docstring).

    Cached on the parts of the parameters the bend depends on (shape, bending, rotation and
    scale), so the renderer and the viewer's overlay share one solve per edit."""
    t = params.transform
    return _bend_profile_cached(params.shape, params.bending, t.rotation, t.scale)


@lru_cache(maxsize=64)
def _bend_profile_cached(shape: Shape, bending: Bending, rotation_deg: Vec3, scale: float) -> BendProfile:
    params = LeafParams(shape=shape, bending=bending, transform=Transform(rotation=rotation_deg, scale=scale))
    return bend_profiles([params])[0]


_V = np.linspace(0.0, 1.0, MIDRIB_SEGMENTS + 1)           # the joints' v
_VM = 0.5 * (_V[1:] + _V[:-1])                              # the segments' middles (strip widths)
_VK = np.linspace(0.0, 1.0, BEND_SAMPLES)                   # the samples the shader reads
_Y = np.array([0.0, 1.0, 0.0])


def _rotate(d: NDArray[np.float64], axis: NDArray[np.float64], angle: NDArray[np.float64]) -> NDArray[np.float64]:
    """``d`` turned about the unit ``axis`` by ``angle`` (Rodrigues), broadcast over leading axes."""
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    return d * c + np.cross(axis, d) * s + axis * (np.sum(axis * d, axis=-1)[..., None] * (1.0 - c))


def _loads(leaves: Sequence[LeafParams]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Per leaf: the bend axis N = ŷ × ĝ and the load direction ĝ in leaf space (L, 3) each, and
    whether anything bends (a load, not along the midrib)."""
    m = transform_matrices([leaf.transform for leaf in leaves])[:, :3, :3]
    direction = np.array([leaf.bending.direction for leaf in leaves], np.float64).reshape(-1, 3)
    g = np.asarray(np.linalg.solve(m, direction[:, :, None])[:, :, 0], np.float64)   # world direction into leaf space
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    axis: NDArray[np.float64] = np.cross(_Y, g)
    norm = np.linalg.norm(axis, axis=1)
    load = np.array([leaf.bending.load for leaf in leaves], np.float64)
    bends: NDArray[np.bool_] = (load > 0.0) & (norm >= 1e-9)
    axis[bends] /= norm[bends, None]
    return axis, g, bends


def _straight(leaves: Sequence[LeafParams]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The unbent blades' midribs at the joints (L, J, 3) and at the samples (L, K, 3), and their
    widths at the segments' middles (L, J - 1), all leaves of one silhouette row count N at
    once. The midrib is the axis A(v) (Chaurasia & Beardsley 2017, eq. 3; the surface at u = 0);
    the margins are S± = P ± Q (eq. 4, the quartics through A(v̄_i) and the in-plane offsets
    q_i of :func:`~leafview.core.blade.axis_frames`), so the width is |S+ - S-| = 2 |Q(v)|."""
    axis_points = np.stack([leaf.shape.axis_points() for leaf in leaves])          # (L, 4, 3)
    joints = np.einsum("vk,lkd->lvd", bernstein(3, _V), axis_points)
    straight_k = np.einsum("vk,lkd->lvd", bernstein(3, _VK), axis_points)
    rows = leaves[0].shape.rows
    q = np.zeros((len(leaves), rows + 2, 3))                                          # Q's control points
    q[:, 1:-1] = np.stack([axis_frames(leaf)[1] for leaf in leaves])
    width = 2.0 * np.linalg.norm(np.einsum("vk,lkd->lvd", bernstein(rows + 1, _VM), q), axis=2)
    return joints, straight_k, width


def _chains(leaves: Sequence[LeafParams]) -> tuple[NDArray[np.float64], ...]:
    """The straight chains of leaves of one silhouette row count and one petiole state (all with
    a petiole or none): segment directions (L, S, 3), lengths, carried loads and EI (L, S), and
    the straight midrib at the samples (L, K, 3)."""
    joints, straight_k, width = _straight(leaves)
    load = np.array([leaf.bending.load for leaf in leaves])[:, None]
    seg = np.diff(joints, axis=1)
    ds = np.linalg.norm(seg, axis=2)
    floor = 1e-12 * np.maximum(ds.sum(axis=1), 1.0)    # coinciding joints: a tiny segment along y
    short = ~(ds > floor[:, None])
    if short.any():
        seg[short] = np.broadcast_to((floor[:, None] * _Y)[:, None, :], seg.shape)[short]
        ds = np.linalg.norm(seg, axis=2)
    # strip area × load, per unit of segment length (÷ the mean step)
    forces = load * width * ds / ds.mean(axis=1, keepdims=True)
    ei = np.repeat(np.array([leaf.bending.stiffness for leaf in leaves])[:, None], ds.shape[1], axis=1)
    dirs = seg / ds[:, :, None]
    if leaves[0].bending.petiole_length > 0:
        n, k = len(leaves), PETIOLE_SEGMENTS
        length = np.array([leaf.bending.petiole_length for leaf in leaves])
        ds = np.concatenate([np.repeat((length / k)[:, None], k, axis=1), ds], axis=1)
        forces = np.concatenate([np.zeros((n, k)), forces], axis=1)
        stiff = np.array([leaf.bending.petiole_stiffness for leaf in leaves])
        ei = np.concatenate([np.repeat(stiff[:, None], k, axis=1), ei], axis=1)
        dirs = np.concatenate([np.broadcast_to(_Y, (n, k, 3)), dirs], axis=1)
    carried = np.cumsum(forces[:, ::-1], axis=1)[:, ::-1]     # |Σ_{j>=i} F_j|, all along ĝ
    return dirs, ds, carried, ei, straight_k


def _walk(axis: NDArray[np.float64], g: NDArray[np.float64], dirs: NDArray[np.float64], ds: NDArray[np.float64],
          carried: NDArray[np.float64], ei: NDArray[np.float64], petiole: NDArray[np.float64]
          ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Bend chains of equal length together (bend axes and load directions (G, 3), the chains as
    :func:`_chains` gives them): Φ_k (G, K) and the bent midrib at the samples (G, K, 3), for
    leaves with petioles of length ``petiole`` (G,) (0: none)."""
    count, n_seg = ds.shape
    n_pet = n_seg - MIDRIB_SEGMENTS
    total = np.zeros(count)
    angles = np.empty_like(ds)
    for i in range(n_seg):   # sequential: θ⁰ after the earlier rotations
        d = _rotate(dirs[:, i], axis, total)
        theta = np.arctan2(np.sum(axis * np.cross(d, g), axis=1), np.sum(d * g, axis=1))
        phi = np.zeros(count)
        ok = ds[:, i] > 0.0   # a segment too short to have a length in float64 cannot bend
        if ok.any():
            phi[ok] = solve_bending(ds[ok, i], np.abs(theta[ok]), carried[ok, i], ei[ok, i])
        total = total + np.sign(theta) * phi
        angles[:, i] = total
    bent_dirs = _rotate(dirs, axis[:, None, :], angles)
    start = np.zeros((count, 1, 3))
    start[:, 0, 1] = -petiole
    points = start + np.concatenate([np.zeros((count, 1, 3)), np.cumsum(bent_dirs * ds[:, :, None], axis=1)], axis=1)
    blade_points = points[:, n_pet:]          # joint n_pet is the leaf base
    first = angles[:, n_pet - 1] if n_pet else np.zeros(count)
    blade_phi = np.concatenate([first[:, None], angles[:, n_pet:]], axis=1)
    blade_phi = np.concatenate([blade_phi[:, :1], 0.5 * (blade_phi[:, 1:-1] + blade_phi[:, 2:]), blade_phi[:, -1:]],
                               axis=1)
    phi_k = np.stack([np.interp(_VK, _V, row) for row in blade_phi])
    bent_k = np.stack([np.stack([np.interp(_VK, _V, pts[:, c]) for c in range(3)], axis=1) for pts in blade_points])
    return phi_k, bent_k


def bend_profiles(leaves: Sequence[LeafParams]) -> list[BendProfile]:
    """The bend profile of every leaf (see the module docstring), the chains walked together:
    the straight chains come from the axis and the margins' Bézier control points of all leaves
    at once, and the sequential walk along the chain advances all leaves by one segment per numpy
    step, so a leaf set of bent leaves, each with a shape of its own, costs a few small per-leaf
    steps (its axis frames) and vectorised work for the rest. Raises :class:`~leafview.core.params.ParamError` (``bending``) when a
    solve gives non-finite numbers (unreachable within the accepted ranges)."""
    out: list[BendProfile | None] = [None] * len(leaves)
    if not leaves:
        return []
    axes, gs, bends = _loads(leaves)
    groups: dict[tuple[int, bool], list[int]] = {}      # (silhouette rows, petiole) -> leaves that bend
    for i, leaf in enumerate(leaves):
        if not bends[i]:
            out[i] = BendProfile(np.array([1.0, 0.0, 0.0]), np.zeros(BEND_SAMPLES), np.zeros((BEND_SAMPLES, 3)),
                                 float(np.radians(leaf.bending.twist)))
        else:
            groups.setdefault((leaf.shape.rows, leaf.bending.petiole_length > 0), []).append(i)
    for members in groups.values():
        group = [leaves[i] for i in members]
        dirs, ds, carried, ei, straight_k = _chains(group)
        axis, g = axes[members], gs[members]
        petiole = np.array([leaf.bending.petiole_length for leaf in group], np.float64)
        phi_k, bent_k = _walk(axis, g, dirs, ds, carried, ei, petiole)
        delta = bent_k - straight_k
        for row, i in enumerate(members):
            if not (np.isfinite(phi_k[row]).all() and np.isfinite(delta[row]).all()):
                raise ParamError("bending", "the cantilever solve gave non-finite angles for this leaf")
            out[i] = BendProfile(axis[row].copy(), phi_k[row].copy(), delta[row].copy(),
                                 float(np.radians(leaves[i].bending.twist)))
    return [p for p in out if p is not None]
