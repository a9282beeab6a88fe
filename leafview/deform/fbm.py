"""1D fractional Brownian motion by spectral synthesis (Geng, Hu & Zhang 2014, sec. 3, eqs 1-3).

The spectrum of eq. 1, ``S_f = C · Nrand / f^(β/2)``, gets random phases (eq. 2) and is turned
into a real periodic signal of ``n`` samples::

    N(t) = Σ_{f=1}^{n/2} a_f cos(2π f t / n + φ_f),   a_f = g_f / f^(β/2)

(no DC term), then normalised to zero mean and unit (population) standard deviation, so ``C``
drops out. Its power spectrum falls as ``f^-β``.

The random numbers are a pure function of ``(seed, f)``, computed the same way in numpy and in
GLSL (``shaders/fbm.glsl``) so the CPU and GPU signals agree: ``pcg`` is the PCG hash of
Jarzynski & Olano (2020) on 32-bit words; for frequency ``f`` and stream ``s`` (0, 1: Gaussian,
2: phase) ``h = pcg(pcg(seed) + 3 f + s)``, ``u = (h >> 8 + 0.5) / 2^24`` in (0, 1);
``g_f = sqrt(-2 ln u_0) cos(2π u_1)`` (Box-Muller) and ``φ_f = 2π u_2``.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["pcg", "hash_uniform", "spectrum", "fbm_signal", "check_signal_args", "resample", "sample_periodic",
           "MAX_SAMPLES", "RIPPLE_SAMPLES", "ripple_signal"]

MAX_SAMPLES = 2048  # the GPU pass keeps half a spectrum in shared memory
RIPPLE_SAMPLES = 256  # samples per ripple signal (one period) on leaves
_M = np.uint64(0xFFFFFFFF)


def pcg(x: ArrayLike) -> NDArray[np.uint32]:
    """PCG hash (RXS-M-XS variant) of 32-bit words, wrapping like GLSL ``uint``."""
    s = (np.asarray(x, dtype=np.uint64) * np.uint64(747796405) + np.uint64(2891336453)) & _M
    word = (((s >> ((s >> np.uint64(28)) + np.uint64(4))) ^ s) * np.uint64(277803737)) & _M
    return ((word >> np.uint64(22)) ^ word).astype(np.uint32)


def hash_uniform(seed: int, f: ArrayLike, stream: int) -> NDArray[np.float64]:
    """Uniform numbers in (0, 1) for frequencies ``f``: exactly representable in float32."""
    base = np.uint64(pcg(np.uint32(seed & 0xFFFFFFFF)))
    key = (base + np.asarray(f, dtype=np.uint64) * np.uint64(3) + np.uint64(stream)) & _M
    h = pcg(key)
    return ((h >> np.uint32(8)).astype(np.float64) + 0.5) / 16777216.0


def spectrum(n: int, beta: float, seed: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Amplitudes ``a_f`` and phases ``φ_f`` for f = 1..n/2 (eq. 1 with random phase, eq. 2)."""
    f = np.arange(1, n // 2 + 1)
    u0, u1, u2 = (hash_uniform(seed, f, s) for s in range(3))
    gauss = np.sqrt(-2.0 * np.log(u0)) * np.cos(2.0 * np.pi * u1)
    return gauss / f ** (beta / 2.0), 2.0 * np.pi * u2


def check_signal_args(n: int, beta: float) -> None:
    if not isinstance(n, (int, np.integer)) or n < 4 or n % 2 or n > MAX_SAMPLES:
        raise ValueError(f"n must be an even number of samples in 4..{MAX_SAMPLES}, got {n!r}")
    if not np.isfinite(beta) or beta <= 0:
        raise ValueError(f"beta must be a finite number > 0, got {beta!r}")


def fbm_signal(n: int, beta: float, seed: int) -> NDArray[np.float64]:
    """The normalised fBm signal (zero mean, unit std), ``n`` samples, float64 (numpy)."""
    check_signal_args(n, beta)
    a, phi = spectrum(n, beta, seed)
    spec = np.zeros(n // 2 + 1, dtype=np.complex128)
    spec[1:n // 2] = (n / 2.0) * a[:-1] * np.exp(1j * phi[:-1])
    spec[n // 2] = n * a[-1] * np.cos(phi[-1])  # Nyquist: a cos(πt + φ) = a cos φ (-1)^t
    signal = np.fft.irfft(spec, n)
    signal -= signal.mean()
    return signal / signal.std()


def sample_periodic(signal: ArrayLike, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Catmull-Rom interpolation of a periodic signal at real positions ``t`` (sample units):
    value and derivative d/dt. C¹, so ripple normals stay smooth. Mirrors ``shaders/fbm.glsl``."""
    sig = np.asarray(signal, dtype=np.float64)
    n = sig.shape[-1]
    t = np.asarray(t, dtype=np.float64)
    i = np.floor(t)
    x = t - i
    i = i.astype(np.int64)
    p0, p1, p2, p3 = (sig[..., (i + k) % n] for k in (-1, 0, 1, 2))
    return catmull_rom(p0, p1, p2, p3, x)


def catmull_rom(p0: NDArray[np.float64], p1: NDArray[np.float64], p2: NDArray[np.float64], p3: NDArray[np.float64],
                x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The uniform Catmull-Rom segment from ``p1`` to ``p2`` (neighbours ``p0``, ``p3``) at fraction
    ``x`` (broadcast against the points): value and d/dx. The one formula behind the signal, bend
    and sweep splines here and in the shaders (``fbm.glsl``, ``leaf_eval.glsl``)."""
    c1 = 0.5 * (p2 - p0)
    c2 = p0 - 2.5 * p1 + 2.0 * p2 - 0.5 * p3
    c3 = 0.5 * (p3 - p0) + 1.5 * (p1 - p2)
    value = ((c3 * x + c2) * x + c1) * x + p1
    slope = (3.0 * c3 * x + 2.0 * c2) * x + c1
    return value, slope


def resample(signal: ArrayLike, r: float, c: float, t: ArrayLike) -> NDArray[np.float64]:
    """Eq. 3: ``N'(t) = N(r t + c)`` with periodic wrap and Catmull-Rom interpolation."""
    return sample_periodic(signal, r * np.asarray(t, dtype=np.float64) + c)[0]


def ripple_signal(beta: float, seed: int) -> NDArray[np.float64]:
    """The leaf ripple signal of ``(beta, seed)``: :data:`RIPPLE_SAMPLES` samples (cached)."""
    return _ripple_cache(float(beta), int(seed))


@lru_cache(maxsize=256)
def _ripple_cache(beta: float, seed: int) -> NDArray[np.float64]:
    sig = fbm_signal(RIPPLE_SAMPLES, beta, seed)
    sig.setflags(write=False)
    return sig
