"""Per-leaf variety within a species (Geng, Hu & Zhang 2014, sec. 6: many different leaves from
one set of parameters): each leaf draws its ripple phase, ripple amplitude and bend load from
ranges set per species (``[[species]] variety = {...}`` in a scene file).

What a leaf gets (:func:`draw_variety`, called by :func:`leafview.scene.spec.build_scene` after
every other draw of the scene's generator): a phase offset ``o`` added to θ of eq. 5 on both
sides, a factor ``s`` on the ripple amplitude P of both sides, and a factor ``f`` on the bend load
of eq. 4. The GPU rows carry ``P s`` and ``θ + o`` directly (:func:`leafview.gpu.scene.pack_scene`),
so nothing is computed per leaf per frame.

The bend (eq. 4) is not solved per leaf: that costs about a millisecond a leaf. Instead each bent
species with a load range is solved at :data:`LOAD_SAMPLES` loads spanning its range
(:func:`load_table`, one vectorised :func:`~leafview.deform.beam.bend_profiles` call; at least
:data:`LOAD_SAMPLES`, at most :data:`LOAD_STEP` apart in load / EI), and a
leaf's profile samples (Δ_k and Φ_k) are interpolated linearly between the two neighbouring
solved loads (:func:`interpolate_bend`). The GPU rows and the numpy reference
(:func:`leafview.scene.spec.evaluate_leaf`) use the same interpolation; how far it lies from an
exact per-leaf solve is what :func:`leafview.scene.spec.bend_deviation` measures.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.botany.vein_shape import shape_grid
from leafview.core.fieldspec import spec_field
from leafview.core.params import Bending, LeafParams, Ripple, Transform
from leafview.core.settings import SettingsTable, field_specs
from leafview.deform.beam import BEND_SAMPLES, BendProfile, bend_profile, bend_profiles
from leafview.deform.fbm import ripple_signal
from leafview.deform.surface import grid_uv, partials
from leafview.errors import ParamError

__all__ = ["Variety", "LOAD_SAMPLES", "LOAD_STEP", "MAX_LOAD_SAMPLES", "LoadTable", "check_variety", "draw_variety", "load_table",
           "interpolate_bend", "leaf_ripple", "leaf_bending", "sphere_padding"]

_G = "variety"


@dataclass(frozen=True)
class Variety(SettingsTable):
    """Ranges a species' leaves draw from (uniformly, seeded by the scene): a ripple phase offset
    (added to θ of eq. 5, in units of the signal's samples), factors on the ripple amplitude P and
    on the bend load. The defaults give every leaf its species' values."""

    TABLE = "variety"

    ripple_phase: tuple[float, float] = spec_field("ripple phase offset (samples)", _G, 0.0, 64.0, 0.5,
                                                   hard=(0.0, 1e4), kind="pair", default=(0.0, 0.0))
    ripple_amplitude: tuple[float, float] = spec_field("ripple amplitude factor", _G, 0.0, 2.0, 0.01,
                                                       hard=(0.0, 10.0), kind="pair", default=(1.0, 1.0))
    bend_load: tuple[float, float] = spec_field("bend load factor", _G, 0.0, 2.0, 0.01, hard=(0.0, 10.0),
                                                kind="pair", default=(1.0, 1.0))

    def check(self) -> None:
        for name in ("ripple_phase", "ripple_amplitude", "bend_load"):
            lo, hi = getattr(self, name)
            if lo > hi:
                raise ParamError(f"variety.{name}", f"range [{lo}, {hi}] is empty: the first number must not exceed "
                                 "the second")

    @property
    def active(self) -> bool:
        return self != Variety()


LOAD_SAMPLES = 5
"""Fewest loads a bent species with a load range is solved at (evenly spaced over its range)."""
LOAD_STEP = 0.15
"""Largest step between solved loads, in units of load / EI (only their ratio shapes the bend,
eq. 4; EI the smaller of the midrib's and the petiole's): a species with load ``q``, stiffness
``EI`` and factor range ``[lo, hi]`` is solved at ``max(LOAD_SAMPLES, ceil(q (hi - lo) / (EI ·
LOAD_STEP)) + 1)`` loads, at most :data:`MAX_LOAD_SAMPLES`. The interpolation error falls with the
step squared; the solves of one table run together, so more samples cost little. Measured over
the built-in presets (ranges 0.7-1.3 and 0-2, loads 1, 6 and 20): at most 1.8e-4 leaf lengths
from each leaf's own solve (:func:`leafview.scene.spec.bend_deviation`)."""
MAX_LOAD_SAMPLES = 257

_KINDS = ("ripple_phase", "ripple_amplitude", "bend_load")


def check_variety(leaf: LeafParams, variety: Variety, where: str) -> None:
    """Raise :class:`ParamError` naming ``where.field`` when ``variety`` would take a leaf of the
    species ``leaf`` out of the parameters' hard ranges (ripple amplitude P × factor, phase θ +
    offset, bend load × factor)."""
    ripple, bending = field_specs(Ripple), field_specs(Bending)
    p_max = ripple["amplitude"].hard_range[1]
    hi = variety.ripple_amplitude[1]
    if p_max is not None and max(leaf.ripple.amplitude) * hi > p_max:
        raise ParamError(f"{where}.ripple_amplitude", f"the species' ripple amplitude {max(leaf.ripple.amplitude)!r} "
                                                      f"× {hi!r} exceeds the maximum {p_max}")
    t_max = ripple["phase"].hard_range[1]
    hi = variety.ripple_phase[1]
    if t_max is not None and max(leaf.ripple.phase) + hi > t_max:
        raise ParamError(f"{where}.ripple_phase", f"the species' ripple phase {max(leaf.ripple.phase)!r} + {hi!r} "
                                                  f"exceeds the maximum {t_max}")
    l_max = bending["load"].hard_range[1]
    hi = variety.bend_load[1]
    if l_max is not None and leaf.bending.load * hi > l_max:
        raise ParamError(f"{where}.bend_load", f"the species' bend load {leaf.bending.load!r} × {hi!r} exceeds the "
                                               f"maximum {l_max}")


def draw_variety(rng: np.random.Generator, species_id: NDArray[np.integer[Any]], varieties: Sequence[Variety]
                 ) -> tuple[NDArray[np.float32] | None, NDArray[np.float32] | None, NDArray[np.float32] | None]:
    """Each leaf's ripple phase offset, ripple amplitude factor and bend load factor, uniform in
    its species' ranges: three (N,) float32 arrays, each None when no species varies it (all None,
    and nothing drawn from ``rng``, when no species has variety). One uniform number per leaf and
    quantity is drawn for every quantity once any species has variety, so widening one range does
    not change the numbers of another."""
    if not any(v.active for v in varieties):
        return None, None, None
    default = Variety()
    sid = np.asarray(species_id, np.int64)
    out: list[NDArray[np.float32] | None] = []
    for name in _KINDS:
        u = rng.random(len(sid))
        if all(getattr(v, name) == getattr(default, name) for v in varieties):
            out.append(None)
            continue
        ranges = np.array([getattr(v, name) for v in varieties], np.float64)
        lo, hi = ranges[sid, 0], ranges[sid, 1]
        u *= hi - lo
        u += lo
        out.append(np.clip(u.astype(np.float32), lo.astype(np.float32), hi.astype(np.float32)))
    return out[0], out[1], out[2]


def leaf_ripple(ripple: Ripple, offset: float, scale: float) -> Ripple:
    """``ripple`` with the phase θ of both sides moved by ``offset`` and the amplitude P of both
    sides multiplied by ``scale`` (kept inside P's hard range)."""
    p_max = field_specs(Ripple)["amplitude"].hard_range[1]
    cap = float("inf") if p_max is None else float(p_max)
    amp = tuple(min(float(p) * float(scale), cap) for p in ripple.amplitude)
    phase = tuple(float(t) + float(offset) for t in ripple.phase)
    return replace(ripple, amplitude=(amp[0], amp[1]), phase=(phase[0], phase[1]))


def leaf_bending(bending: Bending, scale: float) -> Bending:
    """``bending`` with its load multiplied by ``scale`` (kept inside the load's hard range)."""
    l_max = field_specs(Bending)["load"].hard_range[1]
    load = float(bending.load) * float(scale)
    return replace(bending, load=load if l_max is None else min(load, float(l_max)))


@dataclass(frozen=True)
class LoadTable:
    """Bend profiles of the species with a load range, each solved at ``K`` load factors evenly
    spaced over its range.

    Attributes
    ----------
    row: (S,) the table row of each species; -1 where its leaves keep the species' profile (not
        bent by a load, lobed, or no load range).
    lo, hi: (R,) each row's load factor range.
    phi: (R, K, B) Φ samples (B = :data:`~leafview.deform.beam.BEND_SAMPLES`) at each solved load.
    delta: (R, K, B, 3) Δ samples at each solved load.
    """

    row: NDArray[np.int64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    phi: NDArray[np.float64]
    delta: NDArray[np.float64]


def _problem(leaf: LeafParams, variety: Variety) -> tuple[Any, ...] | None:
    """What a species' load table depends on (hashable), or None when it needs none."""
    if leaf.lobes.enabled or not leaf.bending.load > 0.0 or variety.bend_load == Variety().bend_load:
        return None   # a swept surface is drawn unbent; no load: nothing to scale; no range: the species' own
    t = leaf.transform
    return (leaf.shape, leaf.bending, t.rotation, t.scale, *variety.bend_load)


def _samples(problem: tuple[Any, ...]) -> int:
    """Loads a species' problem needs for steps of at most :data:`LOAD_STEP` (load / EI)."""
    bending: Bending = problem[1]
    ei = min(bending.stiffness, bending.petiole_stiffness) if bending.petiole_length > 0 else bending.stiffness
    return math.ceil(bending.load * (problem[5] - problem[4]) / (ei * LOAD_STEP) - 1e-9) + 1


def load_table(species: Sequence[LeafParams], varieties: Sequence[Variety],
               samples: int | None = None) -> LoadTable | None:
    """The :class:`LoadTable` of ``species`` and their ``varieties`` (None when no species needs
    one). Each row is ``samples`` solves of eq. 4 (Geng, Hu & Zhang 2014) at load × f for f evenly
    spaced over the species' ``bend_load`` range (default: enough for steps of at most
    :data:`LOAD_STEP` in every row, see there), all rows solved in one
    :func:`~leafview.deform.beam.bend_profiles` call; cached on the problems (the GPU packing and
    the numpy reference share one table)."""
    problems = tuple(_problem(sp, v) for sp, v in zip(species, varieties))
    if all(p is None for p in problems):
        return None
    if samples is None:
        samples = min(max(LOAD_SAMPLES, *(_samples(p) for p in problems if p is not None)), MAX_LOAD_SAMPLES)
    return _load_table_cached(problems, max(int(samples), 2))


@lru_cache(maxsize=16)
def _load_table_cached(problems: tuple[tuple[Any, ...] | None, ...], samples: int) -> LoadTable:
    distinct = list(dict.fromkeys(p for p in problems if p is not None))
    row = np.array([-1 if p is None else distinct.index(p) for p in problems], np.int64)
    lo = np.array([p[4] for p in distinct], np.float64)
    hi = np.array([p[5] for p in distinct], np.float64)
    leaves = []
    for (shape, bending, rotation, scale, a, b) in distinct:
        for f in np.linspace(a, b, samples):
            leaves.append(LeafParams(shape=shape, bending=leaf_bending(bending, float(f)),
                                     transform=Transform(rotation=rotation, scale=scale)))
    profiles = bend_profiles(leaves)
    phi = np.array([p.phi for p in profiles], np.float64).reshape(len(distinct), samples, BEND_SAMPLES)
    delta = np.array([p.delta for p in profiles], np.float64).reshape(len(distinct), samples, BEND_SAMPLES, 3)
    for a in (row, lo, hi, phi, delta):
        a.setflags(write=False)   # cached and shared
    return LoadTable(row, lo, hi, phi, delta)


def interpolate_bend(table: LoadTable, species_id: NDArray[np.integer[Any]], load_scale: NDArray[np.floating[Any]]
                     ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """The bend profile samples of leaves at their load factors, linear between the two
    neighbouring solved loads of their species' row (vectorised; no solve).

    Returns ``(which, phi, delta)``: the indices (into ``species_id``) of the leaves whose species
    has a row, and their Φ (M, B) and Δ (M, B, 3) samples; the other leaves keep their species'
    profile."""
    r_all = table.row[np.asarray(species_id, np.int64)]
    which = np.flatnonzero(r_all >= 0)
    r = r_all[which]
    f = np.asarray(load_scale, np.float64)[which]
    k = table.phi.shape[1]
    lo, span = table.lo[r], table.hi[r] - table.lo[r]
    t = np.where(span > 0, (f - lo) / np.where(span > 0, span, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0) * (k - 1)
    i = np.minimum(np.floor(t).astype(np.int64), k - 2)
    w = t - i
    phi = (1.0 - w)[:, None] * table.phi[r, i] + w[:, None] * table.phi[r, i + 1]
    delta = (1.0 - w)[:, None, None] * table.delta[r, i] + w[:, None, None] * table.delta[r, i + 1]
    return which, phi, delta


def sphere_padding(species: Sequence[LeafParams], varieties: Sequence[Variety], spheres: NDArray[np.floating[Any]],
                   variation: float = 0.0) -> NDArray[np.float64]:
    """(S,) what each species' culling sphere (``spheres`` (S, 4): centre, radius, as computed
    for the species' own surface and widened for its shape ``variation``) must grow by so that it
    holds every leaf of the species whatever its variety.

    * Ripples (eq. 5): the displacement ``τ r c`` has ``|τ c| <= 1`` and ``|r| <= P (λ + (1 - λ)
      max|N|)`` (max|N| of the signal's samples × 1.25 for the curve between them), so a leaf's
      ripple differs from its species' by at most that bound at P × its largest factor plus the
      bound at P (a bend turns the offset, it does not lengthen it).
    * Bend load: the species' surface (ripples off) bent by each solved load's profile
      (:func:`load_table`) on a fine grid (17 × 33, finer than any drawn level), each point
      pushed out by ``variation × |p|`` as the shape variation's widening is; the sphere grows to
      hold them all, × 1.05 for the profiles interpolated between solved loads and the points
      between the grid's."""
    sph = np.asarray(spheres, np.float64).reshape(len(species), 4)
    out = np.zeros(len(species), np.float64)
    default = Variety()
    for s, (sp, v) in enumerate(zip(species, varieties)):
        rip = sp.ripple
        if rip.enabled and (v.ripple_phase != default.ripple_phase or v.ripple_amplitude != default.ripple_amplitude):
            peak = 1.25 * float(np.abs(ripple_signal(rip.beta, rip.seed)).max())   # Catmull-Rom overshoot
            bound = max(p * (lam + (1.0 - lam) * peak) for p, lam in zip(rip.amplitude, rip.fluctuation))
            out[s] += bound * (1.0 + max(v.ripple_amplitude[1], 1.0))
    table = load_table(species, varieties)
    if table is not None:
        uv = grid_uv(17, 33).astype(np.float64)
        for j in np.flatnonzero(table.row >= 0):
            sp = species[int(j)]
            own = bend_profile(sp)
            flat, grid = sp.replace(bending=Bending(), ripple=replace(sp.ripple, enabled=False)), shape_grid(sp)
            r = int(table.row[j])
            reach = 0.0
            for k in range(table.phi.shape[1]):
                bent = BendProfile(own.axis.copy(), table.phi[r, k].copy(), table.delta[r, k].copy(), own.twist)
                pts = partials(flat, uv[:, 0], uv[:, 1], bend=bent, vein_grid=grid).L
                far = np.linalg.norm(pts - sph[j, :3], axis=1) + variation * np.linalg.norm(pts, axis=1)
                reach = max(reach, float(far.max()))
            out[j] += max(0.0, 1.05 * reach - sph[j, 3])
    return out
