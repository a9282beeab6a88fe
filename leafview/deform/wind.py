"""Wind: a time-varying turbulent load on every leaf (the ``[wind]`` table of a scene file,
``--wind SPEED --time T`` on the command line), and the numpy twin of ``shaders/leaf_wind.glsl``.

Conventions: the wind blows *towards* ``direction`` (degrees counter-clockwise from +x, in the
ground plane), ``speed`` in scene units per second, ``time`` in seconds. Leaf space has its base at
the origin, the midrib along +y (one leaf length to the apex) and the blade's normal along +z.

The load (Geng, Hu & Zhang 2014, eq. 5, with time as the sampling variable)::

    Q(t) = P_w (1 + λ (0.8 G + 0.6 T)),     P_w = (speed / stiffness)²       (drag ∝ speed²)
    G = N((speed t - x·ĥ) / L + c)            the gust: one fBm signal frozen in the air and
                                              carried downwind (Taylor), so a gust front reaching
                                              x·ĥ later arrives later; L = gust_length
    T = N(k_s t + θ_leaf)                     each leaf's own turbulence: θ_leaf is a hash of the
                                              leaf's index (its row in the scene), k_s = 3 speed / L

N is the normalised fBm signal of eqs 1-2 (:func:`leafview.deform.fbm.ripple_signal`, RIPPLE_SAMPLES
samples, spectrum exponent ``beta``), sampled as N'(t) = N(r t + c) (eq. 3) with Catmull-Rom
interpolation; 0.8² + 0.6² = 1 keeps λ the fluctuation of a unit-variance signal. Q pushes along
ĥ (or against it while a lull makes Q < 0: the leaf springs back past its rest). The paper's form
``P [λ' + (1 - λ') N]`` is this one with ``P_w = P λ'`` and ``λ = (1 - λ') / λ'``.

The response, all in leaf space before the model matrix (d = the heading in leaf space):

* petiole (eq. 4 for one segment): the leaf turns about its base by φ, the root of
  ``a sin(θ0 - φ) = φ`` with ``a = κ_p |Q|`` and θ0 the angle between the leaf's axis ê = +y and
  the load; the axis of the turn is ê × F̂. Solved by a bracketed Newton iteration, a fixed number
  of steps, as the shader does; φ never exceeds θ0, so a strong wind streamlines the leaf;
* midrib: the load left across the turned leaf, ``q_m = |Q| sin(θ0 - φ)`` (= φ / κ_p), bends it as
  a uniformly loaded cantilever, ``w(s) = c_m q_m s² (6 - 4 s + s²) / 24``; each point turns about
  the base, on the same axis, by the chord angle ``w(s) / s`` (s: its distance from the base in
  leaf lengths), a rotation, so distances from the base are kept exactly and the midrib's length
  to second order;
* flutter: the blade moves along its normal n by ``A = a_f |Q| / (1 + |Q| / 2) 3 x² (1/2 + y)
  N(k_f t + θ_leaf + 97 - 2 y)``, a wave running from base to apex, growing toward the margin and
  the apex, k_f = 6 speed / L. It vanishes on the midrib (x = 0), whose own motion is the bend's,
  so the two halves never part there; its Jacobian takes n as locally constant (the neglected
  term, A times the blade's curvature, is of the order of 10⁻³).

Normals follow the map exactly: two tangents of the surface go through the Jacobian and the
normal is their cross product (the cofactor rule). The shader mirrors this file line for line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.fieldspec import spec_field
from leafview.core.settings import SettingsTable
from leafview.deform.fbm import RIPPLE_SAMPLES, hash_uniform, ripple_signal, sample_periodic

__all__ = ["WindSettings", "WindFrame", "wind_frame", "leaf_phase", "gust", "leaf_load", "petiole_angle",
           "displace", "cull_bounds", "SIGNAL_SAMPLES", "PETIOLE_COMPLIANCE", "MIDRIB_COMPLIANCE",
           "FLUTTER_AMPLITUDE", "GUST_WEIGHT", "LEAF_WEIGHT", "SWAY_RATE", "FLUTTER_RATE", "FLUTTER_WAVE",
           "FLUTTER_OFFSET", "FLUTTER_LOAD_MAX", "NEWTON_STEPS", "MIDRIB_SATURATION", "SEED_SALT"]

_G = "wind"

SIGNAL_SAMPLES = RIPPLE_SAMPLES   # samples of the wind's fBm signal (one period)
PETIOLE_COMPLIANCE = 0.8          # κ_p = ds² / EI of eq. 4 for the petiole, radians per unit load
MIDRIB_COMPLIANCE = 1.2           # c_m of the midrib's cantilever deflection, leaf lengths per unit load
FLUTTER_AMPLITUDE = 0.02          # a_f: flutter in leaf lengths at the apex, per unit load, flutter = 1
FLUTTER_LOAD_MAX = 2.0            # the flutter's load saturates: |Q| / (1 + |Q| / 2)
GUST_WEIGHT, LEAF_WEIGHT = 0.8, 0.6   # the gust's and the leaf's own share of N (0.8² + 0.6² = 1)
SWAY_RATE = 3.0                   # k_s, × speed / gust_length: samples per second of each leaf's own turbulence
FLUTTER_RATE = 6.0                # k_f, × speed / gust_length
FLUTTER_WAVE = 2.0                # samples per leaf length of the flutter wave along the midrib
FLUTTER_OFFSET = 97.0             # samples between a leaf's turbulence and its flutter
MIDRIB_SATURATION = 0.5           # the midrib stiffens: q_m / (1 + 0.5 q_m) bends it
NEWTON_STEPS = 8                  # iterations of the petiole's root finding (numpy and GLSL)
SEED_SALT = 0x57494E44            # 'WIND': the wind's signal is not a ripple signal of the same seed


@dataclass(frozen=True)
class WindSettings(SettingsTable):
    """The wind of a frame: speed, direction, time and the turbulence of its load."""

    TABLE = "wind"

    speed: float = spec_field("wind speed", _G, 0.0, 20.0, 0.1, hard=(0.0, 60.0), default=0.0)
    direction: float = spec_field("wind direction (degrees)", _G, -180.0, 180.0, 1.0, hard=(-360.0, 360.0),
                                  default=0.0)
    time: float = spec_field("time (s)", _G, 0.0, 60.0, 0.01, hard=(0.0, 1e6), default=0.0)
    gust: float = spec_field("gustiness λ (eq. 5)", _G, 0.0, 1.0, 0.01, hard=(0.0, 2.0), default=0.7)
    flutter: float = spec_field("blade flutter", _G, 0.0, 2.0, 0.01, hard=(0.0, 4.0), default=1.0)
    seed: int = spec_field("seed", _G, 0, 9999, 1, hard=(0, 2**31 - 1), kind="int", default=0)
    beta: float = spec_field("turbulence spectrum β (eq. 1)", _G, 1.0, 3.0, 0.05, hard=(0.5, 4.0), default=1.6)
    gust_length: float = spec_field("gust length (scene units)", _G, 0.5, 20.0, 0.1, hard=(0.01, 1e4),
                                    positive=True, default=2.0)
    stiffness: float = spec_field("stiffness (the speed of unit load)", _G, 2.0, 30.0, 0.5, hard=(0.1, 1e3),
                                  positive=True, default=10.0)

    @property
    def active(self) -> bool:
        return self.speed > 0.0

    @property
    def heading(self) -> NDArray[np.float64]:
        """Unit vector the wind blows towards (world, z = 0)."""
        a = math.radians(self.direction)
        return np.array([math.cos(a), math.sin(a), 0.0])


@dataclass(frozen=True)
class WindFrame:
    """What the shader's Wind block holds for one frame (:func:`wind_frame`): the time-dependent
    phases are reduced modulo the signal's period here, in float64, so that the GPU's float32
    adds only the per-leaf parts."""

    heading: NDArray[np.float64]   # (3,) world, z = 0
    speed: float
    time: float
    load: float                    # P_w
    gust: float                    # λ
    inv_length: float              # samples per scene unit of the gust signal (1 / gust_length)
    gust_phase: float              # (speed t / L + c) mod n
    sway_phase: float              # k_s t mod n
    flutter_phase: float           # k_f t mod n
    flutter: float                 # a_f × settings.flutter
    seed: int                      # the leaves' phase hash seed
    signal: NDArray[np.float64]    # (SIGNAL_SAMPLES,) N of eqs 1-2


def wind_frame(wind: WindSettings) -> WindFrame:
    n = SIGNAL_SAMPLES
    seed = (int(wind.seed) + SEED_SALT) & 0xFFFFFFFF
    rate = wind.speed / wind.gust_length
    c = float(hash_uniform(seed, 0, 2)) * n            # the gust's own offset c (eq. 3)
    return WindFrame(
        heading=wind.heading, speed=float(wind.speed), time=float(wind.time), load=(wind.speed / wind.stiffness) ** 2,
        gust=float(wind.gust), inv_length=1.0 / wind.gust_length,
        gust_phase=math.fmod(rate * wind.time + c, n), sway_phase=math.fmod(SWAY_RATE * rate * wind.time, n),
        flutter_phase=math.fmod(FLUTTER_RATE * rate * wind.time, n),
        flutter=FLUTTER_AMPLITUDE * float(wind.flutter), seed=seed,
        signal=ripple_signal(float(wind.beta), seed))


def _frame(wind: WindSettings | WindFrame) -> WindFrame:
    return wind if isinstance(wind, WindFrame) else wind_frame(wind)


def leaf_phase(frame: WindFrame, index: ArrayLike) -> NDArray[np.float64]:
    """θ_leaf in samples: a hash of each leaf's index (``hash_uniform`` of fbm.py, stream 0)."""
    idx = np.asarray(index, np.int64) & 0xFFFFFFFF
    return hash_uniform(frame.seed, idx, 0) * SIGNAL_SAMPLES


def gust(wind: WindSettings | WindFrame, positions: ArrayLike) -> NDArray[np.float64]:
    """G at world ``positions`` (..., 3): the gust signal, frozen in the air, carried downwind."""
    f = _frame(wind)
    x = np.asarray(positions, np.float64)
    return sample_periodic(f.signal, f.gust_phase - (x @ f.heading) * f.inv_length)[0]


def leaf_load(wind: WindSettings | WindFrame, bases: ArrayLike, index: ArrayLike) -> NDArray[np.float64]:
    """Q of each leaf (eq. 5 in time): ``bases`` (L, 3) world positions of the leaves' bases."""
    f = _frame(wind)
    turb = sample_periodic(f.signal, f.sway_phase + leaf_phase(f, index))[0]
    return f.load * (1.0 + f.gust * (GUST_WEIGHT * gust(f, bases) + LEAF_WEIGHT * turb))


def petiole_angle(a: ArrayLike, theta0: ArrayLike) -> NDArray[np.float64]:
    """φ with ``a sin(θ0 - φ) = φ`` in [0, θ0] (eq. 4, one segment, a = ds² |F| / EI):
    :data:`NEWTON_STEPS` Newton steps from the linearised root, falling back to bisection when a
    step leaves the bracket (as ``leaf_wind.glsl``)."""
    a = np.asarray(a, np.float64)
    th = np.asarray(theta0, np.float64)
    a, th = np.broadcast_arrays(a, th)
    lo, hi = np.zeros_like(th), th.copy()
    phi = a * th / (1.0 + a)
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(NEWTON_STEPS):
            g = a * np.sin(th - phi) - phi
            lo = np.where(g > 0.0, phi, lo)
            hi = np.where(g > 0.0, hi, phi)
            step = phi - g / (-a * np.cos(th - phi) - 1.0)
            phi = np.where((step >= lo) & (step <= hi), step, 0.5 * (lo + hi))
    return phi


def _rotate(v: NDArray[np.float64], axis: NDArray[np.float64], angle: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rodrigues: ``v`` turned by ``angle`` about unit ``axis`` (broadcast over leading axes)."""
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, axis=-1, keepdims=True) * (1.0 - c)


def displace(points: ArrayLike, normals: ArrayLike, models: ArrayLike, index: ArrayLike,
             wind: WindSettings | WindFrame) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Leaf-space points and normals moved by the wind (module docstring), vectorised over leaves.

    points, normals: (L, V, 3) leaf-space positions and unit upper-side normals of L leaves.
    models: (L, 4, 4) leaf space -> world (rotation × uniform scale, translation in column 3).
    index: (L,) the leaves' indices in the scene (their own phases).
    Returns the moved (points, normals), float64, same shapes; speed 0 returns copies.
    """
    f = _frame(wind)
    p = np.array(points, np.float64)
    n = np.array(normals, np.float64)
    m = np.asarray(models, np.float64)
    if f.speed <= 0.0:
        return p, n
    idx = np.asarray(index, np.int64).reshape(-1)
    q = leaf_load(f, m[:, :3, 3], idx)                                     # (L,)
    d = np.einsum("lji,j->li", m[:, :3, :3], f.heading)                    # M3ᵀ ĥ
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    fhat = np.where(q[:, None] < 0.0, -d, d)
    e = np.array([0.0, 1.0, 0.0])
    cr = np.cross(e, fhat)
    sin0 = np.linalg.norm(cr, axis=1)
    theta0 = np.arctan2(sin0, fhat @ e)
    axis = np.where(sin0[:, None] > 1e-7, cr / np.maximum(sin0, 1e-30)[:, None], np.array([1.0, 0.0, 0.0]))
    load = np.abs(q)
    phi = petiole_angle(PETIOLE_COMPLIANCE * load, theta0)
    qm = load * np.sin(theta0 - phi)
    km = MIDRIB_COMPLIANCE * qm / (1.0 + MIDRIB_SATURATION * qm) / 24.0    # c_m q_m / 24, saturating
    # flutter, along the normal
    amp = f.flutter * load / (1.0 + load / FLUTTER_LOAD_MAX)
    xi = (f.flutter_phase + leaf_phase(f, idx) + FLUTTER_OFFSET)[:, None] - FLUTTER_WAVE * p[..., 1]
    nf, dnf = sample_periodic(f.signal, xi)
    x, y = p[..., 0], p[..., 1]
    h = 3.0 * x * x * (0.5 + y)
    amp_ = amp[:, None]
    grad_a = np.stack([6.0 * x * (0.5 + y) * nf, 3.0 * x * x * nf - h * dnf * FLUTTER_WAVE, np.zeros_like(x)],
                      axis=-1) * amp_[..., None]
    z = n                                   # along the blade's normal: no first-order stretch
    p1 = p + (amp_ * h * nf)[..., None] * z
    # the rotation field about the base
    r = np.linalg.norm(p1, axis=-1)
    s = r
    ax = axis[:, None, :]
    psi = phi[:, None] + km[:, None] * s * (6.0 - 4.0 * s + s * s)
    dpsi = km[:, None] * (6.0 - 8.0 * s + 3.0 * s * s)
    b_x_p = np.cross(ax, p1)
    radial = np.where(r[..., None] > 1e-12, p1 / np.maximum(r, 1e-30)[..., None], 0.0)

    def jac(t: NDArray[np.float64]) -> NDArray[np.float64]:
        t1 = t + z * np.sum(grad_a * t, axis=-1, keepdims=True)
        t2 = t1 + (dpsi * np.sum(radial * t1, axis=-1))[..., None] * b_x_p
        return _rotate(t2, ax, psi)

    ref = np.where(np.abs(n[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    ta = np.cross(n, ref)
    ta /= np.linalg.norm(ta, axis=-1, keepdims=True)
    tb = np.cross(n, ta)
    nn = np.cross(jac(ta), jac(tb))
    nn /= np.linalg.norm(nn, axis=-1, keepdims=True)
    return _rotate(p1, ax, psi), nn


def cull_bounds(wind: WindSettings | WindFrame) -> tuple[float, float, float]:
    """Bounds for culling (``scene_cull.comp``'s ``wind_pad``): the largest petiole turn φ
    (radians, ≤ π), the largest midrib coefficient k = c_m q' / 24 and the largest flutter factor
    f = a_f |Q| / (1 + |Q| / 2) |N|. A point within ``s`` leaf lengths of its base flutters by at
    most ``A = 3 f s² (1/2 + s)`` (|x|, y ≤ s), then turns about the base by at most
    ``ψ = min(φ + k s (6 - 4 s + s²), π)``: it moves by at most ``A + 2 (s + A) sin(ψ / 2)``."""
    f = _frame(wind)
    if f.speed <= 0.0:
        return 0.0, 0.0, 0.0
    peak = float(np.abs(f.signal).max()) * 1.25          # Catmull-Rom may overshoot the samples a little
    qmax = f.load * (1.0 + f.gust * (GUST_WEIGHT + LEAF_WEIGHT) * peak)
    phi = min(PETIOLE_COMPLIANCE * qmax, math.pi)
    qm = min(qmax, math.pi / PETIOLE_COMPLIANCE)
    return (phi, MIDRIB_COMPLIANCE * qm / (1.0 + MIDRIB_SATURATION * qm) / 24.0,
            f.flutter * qmax / (1.0 + qmax / FLUTTER_LOAD_MAX) * peak)
