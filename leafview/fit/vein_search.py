"""Looking for a vein tree's secondaries in a leaf texture: the texture in vein space, its ridges,
the midrib, a Hough transform over the secondaries' family of curves (:mod:`leafview.fit.vein_family`)
and the secondaries followed along their ridges. :func:`leafview.fit.photo_veins.detect_veins`
puts these together (its module docstring tells the method).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.signal import find_peaks
from skimage.feature import hessian_matrix, hessian_matrix_eigvals

from leafview.botany.vein_space import halfwidth_table, vein_space_of
from leafview.botany.venation import SECONDARY_V_RANGE
from leafview.core.params import LeafParams
from leafview.core.texture import texture_st
from leafview.errors import ParamError
from leafview.fit.vein_family import CLEAR, curve, departure, reach

__all__ = ["VeinImage", "RidgeMap", "Side", "Traced", "vein_image", "ridge_maps", "side_parts", "midrib", "origins",
           "candidates", "profiles", "highpass", "coarse_scores", "contrast", "fine_search", "trace", "loop_fraction",
           "spacing", "alternate", "RIDGE_ROWS", "RIDGE_SIGMAS", "MIDRIB_REACH", "BAND", "ANGLES", "CURVES", "SAMPLES",
           "TRACE_STEPS"]

RIDGE_ROWS = 256                    # vein-space cells per leaf length
RIDGE_SIGMAS = (1.0, 2.0)           # Hessian scales, cells
MIDRIB_REACH = 0.04                 # leaf lengths either side of u = 0 searched for the midrib
BAND = (0.12, 0.7)                  # fractions of ℓ averaged along each candidate vein
ANGLES = np.radians(np.arange(10.0, 86.0, 5.0))            # the coarse grid
CURVES = np.array([0.0, 0.3, 0.6, 0.9])
SAMPLES = (12, 20)                  # points along each candidate: coarse grid, fine grid
_FINE_ANGLES = np.radians(np.array([-2.5, 0.0, 2.5]))
_FINE_CURVES = np.array([-0.15, 0.0, 0.15])
_MIN_SPACING = 0.025                # peaks closer than this along v are one vein
_TRACE_STEP = 0.02                  # leaf lengths per tracing step
TRACE_STEPS = 30
_TRACE_REACH = 0.006                # leaf lengths either side searched per step

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]


@dataclass(frozen=True)
class VeinImage:
    """The texture in vein space: ``grey`` and ``alpha`` (rows, cols), row i at y = (i + ½)/rows
    (the base at row 0), column j at x = (j - half + ½)/rows; ``w`` (2, rows) the half-width of
    the u < 0 and the u ≥ 0 side at the row centres."""

    grey: F32
    alpha: F32
    w: F64
    half: int

    @property
    def rows(self) -> int:
        return int(self.grey.shape[0])


# -- the texture in vein space, its ridges and midrib --------------------------------------------------
def side_parts(parts: Sequence[LeafParams]) -> tuple[LeafParams, LeafParams]:
    """(the leaf drawing u < 0, the one drawing u ≥ 0)."""
    if len(parts) == 1:
        return parts[0], parts[0]
    by_half = {p.shape.half: p for p in parts}
    if len(parts) != 2 or set(by_half) != {-1, 1}:
        raise ParamError("parts", "expected one leaf or the two halves (shape.half -1 and +1)")
    return by_half[-1], by_half[1]


def vein_image(texture: NDArray[np.floating], parts: Sequence[LeafParams], rows: int = RIDGE_ROWS) -> VeinImage:
    """The green channel and alpha of ``texture`` (T, T, 4) resampled bilinearly into vein space
    (see :class:`VeinImage`; texel centres at (i + ½)/T, clamped at the edge)."""
    tex = np.asarray(texture, np.float32)
    if tex.ndim != 3 or tex.shape[2] != 4 or tex.shape[0] != tex.shape[1]:
        raise ParamError("texture", f"expected a square (T, T, 4) RGBA texture, got {tex.shape}")
    size = tex.shape[0]
    y = (np.arange(rows) + 0.5) / rows
    ones = np.stack([np.ones(rows), y], axis=1)
    w = np.stack([vein_space_of(halfwidth_table(p), ones)[:, 0] for p in side_parts(parts)])
    half = int(math.ceil(float(w.max()) * rows)) + 2
    x = (np.arange(2 * half) - half + 0.5) / rows
    u = x[None, :] / np.maximum(np.where(x[None, :] >= 0.0, w[1][:, None], w[0][:, None]), 1e-9)
    s, _ = texture_st(np.clip(u, -1.0, 1.0), 0.0)
    _, t = texture_st(0.0, y)
    r = np.clip(t * size - 0.5, 0.0, size - 1.0)                     # texel rows: one per row of the grid
    r0 = np.minimum(r.astype(np.intp), size - 2)
    fr = (r - r0).astype(np.float32)[:, None, None]
    c = np.clip(s * size - 0.5, 0.0, size - 1.0)
    c0 = np.minimum(c.astype(np.intp), size - 2)
    fc = (c - c0).astype(np.float32)[..., None]
    ga = np.ascontiguousarray(tex[..., 1::2]).reshape(-1, 2)           # green and alpha, bilinearly
    i = r0[:, None] * size + c0
    top = ga[i]
    top += (ga[i + 1] - top) * fc
    bottom = ga[i + size]
    bottom += (ga[i + size + 1] - bottom) * fc
    both = top + (bottom - top) * fr
    alpha = np.where(np.abs(u) > 1.0, np.float32(0.0), both[..., 1])
    return VeinImage(np.ascontiguousarray(both[..., 0]), alpha, w, half)


def ridge_maps(image: VeinImage, sigmas: Sequence[float] = RIDGE_SIGMAS) -> tuple[F32, F32, NDArray[np.bool_]]:
    """(lighter, darker, inside): the ridge strength of veins lighter and darker than the lamina
    (scale-normalised Hessian eigenvalues, the largest over ``sigmas``), 0 outside the blade
    eroded by three cells, and that eroded blade."""
    leaf = image.alpha > 0.5
    inside = ndimage.binary_erosion(leaf, iterations=3)
    weight = ndimage.uniform_filter(leaf.astype(np.float32), 17)
    mean = ndimage.uniform_filter(np.where(leaf, image.grey, 0.0).astype(np.float32), 17)
    flat = image.grey / np.maximum(mean / np.maximum(weight, 1e-3), 1e-3)
    lighter = np.zeros_like(flat)
    darker = np.zeros_like(flat)
    for s in sigmas:
        l1, l2 = hessian_matrix_eigvals(hessian_matrix(flat, sigma=s, order="rc", use_gaussian_derivatives=False))
        np.maximum(lighter, np.maximum(-l2, 0.0) * (s * s), out=lighter)
        np.maximum(darker, np.maximum(l1, 0.0) * (s * s), out=darker)
    lighter[~inside] = 0.0
    darker[~inside] = 0.0
    return lighter, darker, inside


class RidgeMap:
    """One polarity's ridge map, ready to be sampled: the image's geometry, the ridge and the
    eroded blade (padded by a cell of zeros, flattened), the midrib x_m per row and the blade's
    mean ridge ``level``."""

    def __init__(self, image: VeinImage, ridge: F32, inside: NDArray[np.bool_]) -> None:
        self.image, self.rows, self.half = image, image.rows, image.half
        self.cols = ridge.shape[1]
        self.ridge = np.pad(ridge, 1).ravel().astype(np.float32)
        self.inside = np.pad(inside, 1).ravel().astype(np.float32)
        self.level = float(ridge[inside].mean()) + 1e-12
        self.xm, self.midrib_rms = midrib(ridge, image)

    def sample(self, x: NDArray[np.floating], y: NDArray[np.floating]) -> tuple[F32, F32]:
        """(ridge, inside) at vein-space points (the nearest cell; 0 outside the eroded blade)."""
        col = np.clip(x * self.rows + (self.half + 1), 0, self.cols + 1).astype(np.intp)
        row = np.clip(y * self.rows + 1, 0, self.rows + 1).astype(np.intp)
        flat = row * (self.cols + 2) + col
        return self.ridge[flat], self.inside[flat]

    def midrib_at(self, y: F64) -> F64:
        return np.asarray(self.xm[np.clip((y * self.rows).astype(np.intp), 0, self.rows - 1)], np.float64)

    def w(self, side: int) -> F64:
        return np.asarray(self.image.w[0 if side < 0 else 1], np.float64)


def midrib(ridge: F32, image: VeinImage) -> tuple[F64, float]:
    """The midrib's offset x_m (rows,) from u = 0: a quadratic in y through each row's strongest
    ridge near u = 0, weighted by its strength; and its RMS over the blade."""
    rows, half = image.rows, image.half
    span = int(round(MIDRIB_REACH * rows))
    band = ridge[:, half - span:half + span]
    col = np.argmax(band, axis=1)
    strength = band[np.arange(rows), col].astype(np.float64)
    x = (col - span + 0.5) / rows
    y = (np.arange(rows) + 0.5) / rows
    keep = (y > 0.08) & (y < 0.92) & (strength > 0.0)
    if keep.sum() < 8:
        return np.zeros(rows), 0.0
    sw = np.sqrt(strength[keep])
    coef = np.linalg.lstsq(np.vander(y[keep], 3) * sw[:, None], x[keep] * sw, rcond=None)[0]
    xm = np.clip(np.polyval(coef, y), -MIDRIB_REACH, MIDRIB_REACH)
    return xm, float(np.sqrt(np.mean(xm[keep] ** 2)))


# -- the Hough transform ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Side:
    """One side's best candidate, θ (radians) and c, its contrast (÷ the median candidate's
    score), and the secondaries found: where they leave the midrib and their ℓ."""

    theta: float
    curv: float
    contrast: float
    at: F64
    ell: F64


def origins(rows: int, step: int = 1) -> F64:
    """Where candidate veins leave the midrib: every ``step`` cells of v in [0.02, 0.96]."""
    return (np.arange(int(0.02 * rows), int(0.96 * rows), step) + 0.5) / rows


def candidates(w: F64, y0: F64, thetas: F64, curvs: F64, samples: int,
                ell: F64 | None = None) -> tuple[F32, F32, F64]:
    """The candidate veins (len(thetas), len(curvs)) leaving the midrib at each ``y0``: their
    points over :data:`BAND` of ℓ from the departure point, (dx, dy) each (nt, nc, n0, samples),
    and ℓ (nt, n0) (computed unless given); ``w`` the side's half-width per row."""
    theta = departure(thetas[:, None], y0[None, :])                                 # (nt, n0)
    ell = reach(w, y0, theta) if ell is None else ell
    ux, uy = curve(theta[:, None, :, None].astype(np.float32), curvs[None, :, None, None].astype(np.float32),
                    np.linspace(BAND[0], BAND[1], samples, dtype=np.float32))
    e = ell.astype(np.float32)[:, None, :, None]
    return (e * ux).astype(np.float32), (e * uy).astype(np.float32), ell


def profiles(m: RidgeMap, side: int, y0: F64, dx: F32, dy: F32) -> F64:
    """The mean ridge along each candidate vein of :func:`candidates` (its points ``dx``,
    ``dy``) leaving the midrib at each ``y0``: (nt, nc, n0); where fewer than a third of a
    vein's points lie on the blade, the candidate's mean over the others."""
    origin = m.midrib_at(y0).astype(np.float32)[None, None, :, None]
    vals, valid = m.sample(origin + side * dx, y0.astype(np.float32)[None, None, :, None] + dy)
    valid *= dx >= CLEAR
    count = valid.sum(axis=-1)
    prof = (vals * valid).sum(axis=-1).astype(np.float64) / np.maximum(count, 1.0)
    good = count >= dx.shape[-1] / 3
    fill = (prof * good).sum(axis=-1, keepdims=True) / np.maximum(good.sum(axis=-1, keepdims=True), 1)
    return np.asarray(np.where(good, prof, fill), np.float64)


def highpass(prof: F64, sigma: float) -> F64:
    """``prof`` less its Gaussian smoothing over ``sigma`` origins (the background's slow change)."""
    return np.asarray(prof - ndimage.gaussian_filter1d(prof, sigma, axis=-1, mode="nearest"), np.float64)


def coarse_scores(m: RidgeMap, side: int, dx: F32, dy: F32) -> F64:
    """The score of each candidate of the coarse grid (origins every other cell; its points
    ``dx``, ``dy`` from :func:`candidates`): the standard deviation of its high-passed profile
    ÷ the blade's mean ridge."""
    prof = profiles(m, side, origins(m.rows, 2), dx, dy)
    return np.asarray(highpass(prof, 4.0).std(axis=-1) / m.level, np.float64)


def contrast(score: F64) -> float:
    return float(score.max() / max(float(np.median(score)), 1e-12))


def fine_search(m: RidgeMap, side: int, coarse: F64) -> Side:
    """The best candidate of a finer grid round the coarse grid's best, and the secondaries it
    finds: the peaks of its profile (origins every cell) at least :data:`_MIN_SPACING` apart,
    standing out by three robust deviations and by a quarter of the highest."""
    i, j = np.unravel_index(int(np.argmax(coarse)), coarse.shape)
    y0 = origins(m.rows)
    thetas = np.clip(ANGLES[i] + _FINE_ANGLES, math.radians(5.0), math.radians(88.0))
    curvs = np.clip(CURVES[j] + _FINE_CURVES, 0.0, 1.0)
    dx, dy, ell = candidates(m.w(side), y0, thetas, curvs, SAMPLES[1])
    prof = profiles(m, side, y0, dx, dy)
    score = highpass(prof, 8.0).std(axis=-1)
    a, b = np.unravel_index(int(np.argmax(score)), score.shape)
    best = highpass(prof[a, b], 8.0)
    noise = 1.4826 * float(np.median(np.abs(best - np.median(best))))
    peaks, _ = find_peaks(best, distance=max(int(_MIN_SPACING * m.rows), 1),
                          prominence=max(3.0 * noise, 0.25 * float(best.max())))
    return Side(float(thetas[a]), float(curvs[b]), contrast(coarse), y0[peaks], ell[a][peaks])


# -- tracing -----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Traced:
    """The found secondaries of both sides followed from the midrib (:func:`trace`): per vein its
    side, its points (K, steps + 1, 2) in its side's frame (x ≥ 0), the ridge at each step (NaN
    where not measured), the steps it was seen for, and where it faded as a fraction of its
    family vein's way to the margin."""

    side: NDArray[np.int_]
    points: F64
    strength: F64
    end: NDArray[np.intp]
    faded: F64

    def seen(self) -> NDArray[np.bool_]:
        """(K, steps): where each vein's ridge was measured, up to where it faded."""
        return np.isfinite(self.strength) & (np.arange(TRACE_STEPS)[None, :] < self.end[:, None])

    def vein_strength(self) -> F64:
        """(K,): each vein's median ridge where it was seen (0 where never)."""
        seen = self.seen()
        return np.array([float(np.median(r[ok])) if ok.any() else 0.0 for r, ok in zip(self.strength, seen)])


def trace(m: RidgeMap, sides: dict[int, Side]) -> Traced:
    """Follow each found secondary (both sides at once) from the midrib: steps of
    :data:`_TRACE_STEP` along its family's heading, each moved sideways within
    :data:`_TRACE_REACH` onto the ridge (the peak of a parabola through the strongest three),
    until the ridge stays below half the vein's own first strength (or the blade's mean) for two
    steps, or the blade ends."""
    side = np.concatenate([np.full(len(sd.at), s) for s, sd in sides.items()]).astype(np.int_)
    theta = departure(np.concatenate([np.full(len(sd.at), sd.theta) for sd in sides.values()]),
                       np.concatenate([sd.at for sd in sides.values()]))
    curv = np.concatenate([np.full(len(sd.at), sd.curv) for sd in sides.values()])
    ell = np.concatenate([sd.ell for sd in sides.values()])
    y0 = np.concatenate([sd.at for sd in sides.values()])
    k = len(side)
    veins = np.arange(k)
    offsets = np.linspace(-_TRACE_REACH, _TRACE_REACH, 7)
    pos = np.stack([side * m.midrib_at(y0), y0], axis=1)
    path = [pos]
    strength = np.full((k, TRACE_STEPS), np.nan)
    gone = np.zeros((k, TRACE_STEPS), bool)          # past the eroded blade
    for step in range(TRACE_STEPS):
        alpha = theta * (1.0 - curv * np.minimum((step + 1) * _TRACE_STEP / ell, 1.0))
        tangent = np.stack([np.sin(alpha), np.cos(alpha)], axis=1)
        normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
        ahead = pos + _TRACE_STEP * tangent
        cand = ahead[:, None, :] + offsets[None, :, None] * normal[:, None, :]
        x = side[:, None] * cand[..., 0]
        vals, valid = m.sample(x, cand[..., 1])
        clear = side[:, None] * (x - m.midrib_at(cand[..., 1])) >= 2.0 * CLEAR
        use = vals * valid * clear
        j = np.clip(np.argmax(use, axis=1), 1, len(offsets) - 2)
        a, b, c = use[veins, j - 1], use[veins, j], use[veins, j + 1]
        bend = a - 2.0 * b + c
        shift = np.clip(0.5 * (a - c) / np.where(bend < 0.0, bend, -1e-12), -0.5, 0.5)
        seen = (valid * clear).any(axis=1)
        moved = ahead + (offsets[j] + shift * (offsets[1] - offsets[0]))[:, None] * normal
        pos = np.where(seen[:, None], moved, ahead)
        path.append(pos)
        strength[:, step] = np.where(seen, use.max(axis=1), np.nan)
        gone[:, step] = ~valid.any(axis=1) & clear.all(axis=1)
    counted = np.cumsum(np.isfinite(strength), axis=1)
    early = np.where(np.isfinite(strength) & (counted <= 6), strength, np.nan)
    inner = np.array([np.median(r[np.isfinite(r)]) if np.isfinite(r).any() else 0.0 for r in early])
    faint = (strength < np.maximum(0.5 * inner, m.level)[:, None]) | gone
    run = faint & np.roll(faint, -1, axis=1)
    run[:, -1] = faint[:, -1]
    end = np.where(run.any(axis=1), run.argmax(axis=1), TRACE_STEPS)
    # the family vein's way to the margin, to say where the traced one faded
    frac = np.linspace(0.0, 2.0, 101)
    ux, uy = curve(theta[:, None], curv[:, None], frac[None, :])
    yy = y0[:, None] + ell[:, None] * uy
    w = m.image.w[(side > 0).astype(np.intp)]
    row = np.clip((yy * m.rows).astype(np.intp), 0, m.rows - 1)
    past = (ell[:, None] * ux > np.take_along_axis(w, row, 1)) | (yy > 1.0)
    length = ell * np.where(past.any(axis=1), frac[np.argmax(past, axis=1)], frac[-1])
    return Traced(side, np.stack(path, axis=1), strength, end, end * _TRACE_STEP / np.maximum(length, 1e-9))


def loop_fraction(faded: F64) -> float:
    """``loop`` from where the traced veins faded (fractions of the way to the margin): their
    median when most faded well before the margin, else 0 (they run to it)."""
    if len(faded) < 2 or np.mean(faded < 0.9) < 0.6:
        return 0.0
    return float(np.clip(np.median(faded[faded < 0.9]), 0.3, 0.95))


def spacing(at: F64) -> tuple[int, float]:
    """(secondaries over the tree's v range, irregularity) from where the veins leave: the median
    spacing, and the jitter about even spacing (uniform in ± 0.35 · irregularity of a spacing in
    :mod:`leafview.botany.venation`, so its deviation is 0.35 · irregularity / √3)."""
    at = np.sort(at)
    if len(at) < 2:
        return len(at), 0.0
    step = float(np.median(np.diff(at)))
    count = int(np.clip(round((SECONDARY_V_RANGE[1] - SECONDARY_V_RANGE[0]) / step), 1, 64))
    if len(at) < 3:
        return count, 0.0
    k = np.round((at - at[0]) / step)
    resid = at - np.polyval(np.polyfit(k, at, 1), k)
    return count, float(np.clip(np.std(resid) * math.sqrt(3.0) / (0.35 * step), 0.0, 1.0))


def alternate(a: F64, b: F64, period: float) -> float:
    """``alternate`` from the veins of the u < 0 side (``a``) and the other (``b``): the tree
    shifts the u > 0 side up and the other down by ¼ · alternate of a spacing."""
    phase = [np.angle(np.mean(np.exp(2j * np.pi * x / period))) / (2.0 * np.pi) for x in (a, b)]
    d = (phase[1] - phase[0] + 0.5) % 1.0 - 0.5
    return float(np.clip(2.0 * abs(d), 0.0, 1.0))
