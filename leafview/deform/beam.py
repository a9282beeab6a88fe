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
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.blade import blade_partials
from leafview.core.params import Bending, LeafParams, ParamError, Ripple, Shape, Transform, Vec3

__all__ = ["solve_bending", "residual", "bend_profile", "BendProfile", "BEND_SAMPLES", "MIDRIB_SEGMENTS",
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
    c1 = 0.5 * (p2 - p0)
    c2 = p0 - 2.5 * p1 + 2.0 * p2 - 0.5 * p3
    c3 = 0.5 * (p3 - p0) + 1.5 * (p1 - p2)
    value = ((c3 * x + c2) * x + c1) * x + p1
    slope = ((3.0 * c3 * x + 2.0 * c2) * x + c1) * (k - 1)
    return value, slope


def bend_profile(params: LeafParams) -> BendProfile:
    """Solve the petiole + midrib chain under the blade's load (see the module docstring).

    Cached on the parts of the parameters the bend depends on (shape, bending, rotation and
    scale), so the renderer and the viewer's overlay share one solve per edit."""
    t = params.transform
    return _bend_profile_cached(params.shape, params.bending, t.rotation, t.scale)


def _blade_points(params: LeafParams, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """Points of the undeformed blade (jitter included): the straight chain the beam bends."""
    return blade_partials(params, u, v)[0].L


@lru_cache(maxsize=64)
def _bend_profile_cached(shape: Shape, bending: Bending, rotation_deg: Vec3, scale: float) -> BendProfile:
    params = LeafParams(shape=shape, bending=bending, transform=Transform(rotation=rotation_deg, scale=scale))

    b = params.bending
    k = BEND_SAMPLES
    twist = float(np.radians(b.twist))
    m = params.transform.matrix()[:3, :3]
    g = np.linalg.solve(m, np.asarray(b.direction, np.float64))  # world direction into leaf space
    g /= np.linalg.norm(g)
    axis = np.cross([0.0, 1.0, 0.0], g)
    if b.load <= 0.0 or np.linalg.norm(axis) < 1e-9:
        return BendProfile(np.array([1.0, 0.0, 0.0]), np.zeros(k), np.zeros((k, 3)), twist)
    axis /= np.linalg.norm(axis)

    # the straight chain: petiole from (0, -Lp, 0) to the base, then the midrib A(v) of the
    # unbent, unrippled blade
    params = params.replace(bending=Bending(), ripple=Ripple())
    v = np.linspace(0.0, 1.0, MIDRIB_SEGMENTS + 1)
    joints = _blade_points(params, np.zeros_like(v), v)
    seg = np.diff(joints, axis=0)
    vm = 0.5 * (v[1:] + v[:-1])
    width = np.linalg.norm(_blade_points(params, np.ones_like(vm), vm) - _blade_points(params, -np.ones_like(vm), vm), axis=1)
    ds = np.linalg.norm(seg, axis=1)
    # a segment whose joints coincide (a cusp of the axis exactly between two samples) has no
    # direction: give it a tiny length along its neighbour's direction so eq. 4 stays defined
    floor = 1e-12 * max(float(ds.sum()), 1.0)
    short = ~(ds > floor)
    if short.any():
        seg = seg.copy()
        seg[short] = floor * np.array([0.0, 1.0, 0.0])
        ds = np.linalg.norm(seg, axis=1)
    # strip area × load, per unit of segment length (÷ the mean step), so that eq. 4's ds² makes
    # each φ_i ≈ ds_i · moment / EI and the shape does not depend on the number of segments
    forces = b.load * width * ds / ds.mean()
    ei = np.full(len(ds), b.stiffness)
    dirs = seg / ds[:, None]
    n_pet = PETIOLE_SEGMENTS if b.petiole_length > 0 else 0
    if n_pet:
        ds = np.r_[np.full(n_pet, b.petiole_length / n_pet), ds]
        forces = np.r_[np.zeros(n_pet), forces]
        ei = np.r_[np.full(n_pet, b.petiole_stiffness), ei]
        dirs = np.r_[np.tile([0.0, 1.0, 0.0], (n_pet, 1)), dirs]
    carried = np.cumsum(forces[::-1])[::-1]            # |Σ_{j>=i} F_j|, all along ĝ

    total = 0.0
    angles = np.empty(len(ds))
    for i in range(len(ds)):                           # sequential: θ⁰ after earlier rotations
        d = rotation(axis, total) @ dirs[i]
        theta = np.arctan2(np.dot(axis, np.cross(d, g)), np.dot(d, g))
        # a segment too short to have a length in float64 (a petiole of 1e-300 split in 8) cannot bend
        phi = solve_bending(ds[i], abs(theta), carried[i], ei[i]) if ds[i] > 0.0 else 0.0
        total += np.sign(theta) * float(phi)
        angles[i] = total
    bent_dirs = np.einsum("nij,nj->ni", rotation(axis, angles), dirs)
    start = np.array([0.0, -b.petiole_length, 0.0]) if n_pet else np.zeros(3)
    points = start + np.r_[[np.zeros(3)], np.cumsum(bent_dirs * ds[:, None], axis=0)]

    # back to the blade's v: joint n_pet is the leaf base
    blade_points = points[n_pet:]
    blade_phi = np.r_[angles[n_pet - 1] if n_pet else 0.0, angles[n_pet:]]
    blade_phi = np.r_[blade_phi[0], 0.5 * (blade_phi[1:-1] + blade_phi[2:]), blade_phi[-1]]
    vk = np.linspace(0.0, 1.0, k)
    phi_k = np.interp(vk, v, blade_phi)
    bent_k = np.stack([np.interp(vk, v, blade_points[:, c]) for c in range(3)], axis=1)
    straight_k = _blade_points(params, np.zeros(k), vk)
    delta = bent_k - straight_k
    if not (np.isfinite(phi_k).all() and np.isfinite(delta).all()):   # unreachable within the accepted ranges
        raise ParamError("bending", "the cantilever solve gave non-finite angles for this leaf")
    return BendProfile(axis, phi_k, delta, twist)
