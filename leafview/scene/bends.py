"""Cantilever bend profiles of many leaves at once (Geng, Hu & Zhang 2014, sec. 4, eq. 4).

:func:`bend_profiles` gives, for every leaf of a list, what
:func:`leafview.deform.beam.bend_profile` gives for one: the petiole + midrib chain bent segment
by segment from the fixed end under the blade's own load, sampled as the accumulated angle Φ(v)
and the offset Δ(v) of the bent midrib. The chain is the same (the same segments, strip loads,
Newton solve :func:`~leafview.deform.beam.solve_bending` and joint rotations), but every step
runs for all leaves together: the straight chains come from the axis and the margins' Bézier
control points of all leaves at once (instead of an evaluation of each blade), and the sequential
walk along the chain advances all leaves by one segment per numpy step. A leaf set of bent
leaves, each with a shape of its own, costs a few small per-leaf steps (its axis frames) and
vectorised work for the rest. A test holds the two to 1e-12.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from leafview.core.bezier import bernstein
from leafview.core.blade import axis_frames
from leafview.core.params import LeafParams, ParamError
from leafview.deform.beam import BEND_SAMPLES, MIDRIB_SEGMENTS, PETIOLE_SEGMENTS, BendProfile, solve_bending
from leafview.scene.spec import transform_matrices

__all__ = ["bend_profiles"]

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
    """:func:`~leafview.deform.beam.bend_profile` of every leaf, the chains walked together (see
    the module docstring). Raises :class:`~leafview.core.params.ParamError` (``bending``) when a
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
