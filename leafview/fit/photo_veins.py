"""The secondary veins of a photographed leaf, read from its fitted front texture.

:func:`detect_veins` looks for a pinnate vein tree (Hong 2005, ch. 6.1, as
:mod:`leafview.botany.venation` lays it out) in the texture the photo fit cut
(:mod:`leafview.fit.photo_texture`), and :func:`with_veins` gives the fitted leaf what it found as
its :class:`~leafview.core.venation.Venation`. Where no vein structure can be trusted the leaf
keeps its veins off and the fit reports :data:`NOT_VISIBLE` with the reason: nothing is invented.

1. **Vein space.** The texture is addressed by (u, v) (s = (1 - u)/2, t = 1 - v:
   :func:`leafview.core.texture.texture_st`), its u axis the blade's half-width w(v) wide. The
   green channel and the alpha are resampled onto a square grid of :data:`RIDGE_ROWS` cells per
   leaf length in vein space q = (u · w(v), v) (:func:`leafview.botany.vein_space.vein_space_of`;
   the u < 0 side with the w of the leaf drawing it), where the vein tree's angles are laid out
   and a step has about the same length on the leaf in either direction. Because q is the
   *fitted* leaf's, the numbers found are the ones that put the rendered veins of the fitted leaf
   where the photo's are, whatever its (u, v) does to them.
2. **Ridges.** The grey level over its local mean (17 cells square: the light's gradients out), then the Hessian's
   eigenvalues at :data:`RIDGE_SIGMAS` cells, scale-normalised, the largest over the scales
   (Sato et al. 1998): -λ₂ for veins lighter than the lamina, λ₁ for darker ones. The mask is
   eroded by three cells so that the margin makes no ridge.
3. **Midrib.** Per row the strongest ridge within :data:`MIDRIB_REACH` of u = 0; a quadratic
   x_m(y) through them, weighted by strength, is where the secondaries leave from.
4. **A Hough transform over the tree's secondaries.** A secondary leaves the midrib at angle θ
   and turns towards the apex by ``curvature`` c: at arc length s its heading is
   θ (1 - c min(s/ℓ, 1)) from the midrib, ℓ the straight vein's length to the margin
   (:mod:`leafview.botany.venation`), so it is a circular arc, then straight
   (:mod:`leafview.fit.vein_family`). For
   every (θ, c) of a grid, per side and for both polarities, the ridge is averaged along the
   vein leaving at each v₀ over :data:`BAND` of its way: at the right (θ, c) the veins make sharp
   peaks in v₀, a wrong one smears them, so the profile (high-passed) varies most. The polarity
   whose best candidate stands out more from the median candidate wins; a finer grid round the
   best follows, and its peaks are the secondaries.
5. **Tracing and fitting.** Each secondary is followed from the midrib, step by step along the
   family's heading and drawn sideways onto the ridge, until it fades. θ and c are then fitted
   by least squares to the traced veins (:func:`family_misfit`: each vein with its best family
   member, the departure point free), out to :data:`OUTER` of the half-width.
6. **The rest.** ``secondaries`` from the median spacing over the tree's v range,
   ``irregularity`` from the jitter about even spacing, ``alternate`` from the shift between the
   sides, ``loop`` from where most traced veins fade well before the margin (a brochidodromous
   vein turns into its arch there) or 0 when they reach it.
7. **Trust.** The veins count as visible when both sides show :data:`MIN_SECONDARIES` or more,
   their angles agree within :data:`MAX_SIDE_ANGLE`, the best candidate stands out by
   :data:`MIN_CONTRAST`, and the traced veins' ridge is :data:`MIN_STRENGTH` times the blade's
   mean ridge (a plain blade's noise, followed the same way, reaches about 2).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.botany.venation import check_veins
from leafview.core.params import LeafParams
from leafview.core.venation import Venation
from leafview.errors import ParamError
from leafview.fit.vein_family import family_misfit
from leafview.fit.vein_search import (
    ANGLES,
    CURVES,
    SAMPLES,
    RidgeMap,
    Side,
    Traced,
    VeinImage,
    alternate,
    candidates,
    coarse_scores,
    contrast,
    fine_search,
    loop_fraction,
    origins,
    ridge_maps,
    spacing,
    trace,
    vein_image,
)

__all__ = ["VeinEstimate", "VeinImage", "detect_veins", "vein_image", "ridge_maps", "family_misfit", "with_veins",
           "MIN_CONTRAST", "MIN_STRENGTH", "MIN_SECONDARIES", "MAX_SIDE_ANGLE", "MAX_MISFIT", "NOT_VISIBLE"]

MIN_CONTRAST = 1.5                  # best candidate's score ÷ the median candidate's
MIN_STRENGTH = 2.2                  # traced veins' median ridge ÷ the blade's mean ridge
MIN_SECONDARIES = 3                 # found on each side
MAX_SIDE_ANGLE = 15.0               # degrees between the two sides' angles
MAX_MISFIT = 0.003                  # leaf lengths: RMS of the traced veins about the fitted family
NOT_VISIBLE = "not visible"
_FIT_GRIDS = ((np.radians(np.arange(-15.0, 15.01, 3.0)), np.arange(-0.3, 0.301, 0.15)),   # about the Hough's
              (np.radians(np.arange(-2.0, 2.01, 1.0)), np.arange(-0.1, 0.101, 0.05)))    # about the first fit's
_ANGLE_RANGE = (10.0, 85.0)         # degrees: Venation.angle's soft range
_KEEP_STRENGTH = 0.55               # a traced vein's ridge ÷ its side's upper quartile, at least
_KEEP_REACH = 0.2                   # and the fraction of its way it was followed


@dataclass(frozen=True)
class VeinEstimate:
    """What :func:`detect_veins` found. ``visible`` False: ``reason`` says why (the numbers are
    what was measured, for the report). Angles in degrees from the midrib in the fitted leaf's
    vein space; ``sides`` per side (-1 the u < 0 half, +1 the other): angle, curvature, the
    count over the tree's range, how many were found, loop, irregularity, contrast, how far the
    traced veins reached (fraction of the way to the margin) and their ridge strength."""

    visible: bool
    reason: str
    polarity: str = ""
    angle: float = 0.0
    curvature: float = 0.0
    secondaries: int = 0
    loop: float = 0.0
    alternate: float = 0.0
    irregularity: float = 0.0
    contrast: float = 0.0
    strength: float = 0.0
    midrib_offset: float = 0.0
    sides: dict[int, dict[str, float]] = field(default_factory=dict)
    seconds: float = 0.0

    def venation(self, seed: int = 0, side: int | None = None) -> Venation:
        """The pinnate :class:`Venation` of the estimate (with ``side``, that side's angle,
        curvature, count and loop), or the default, disabled one when nothing was visible.
        The tertiary network is off: the photo says nothing about it that is kept."""
        if not self.visible:
            return Venation()
        s = self.sides.get(side, {}) if side is not None else {}
        return Venation(enabled=True, pattern="pinnate", seed=seed,
                        secondaries=int(np.clip(s.get("secondaries", self.secondaries), 1, 64)),
                        angle=float(np.clip(s.get("angle", self.angle), *_ANGLE_RANGE)),
                        curvature=float(np.clip(s.get("curvature", self.curvature), 0.0, 1.0)),
                        irregularity=float(np.clip(self.irregularity, 0.0, 1.0)),
                        alternate=float(np.clip(self.alternate, 0.0, 1.0)),
                        loop=float(np.clip(s.get("loop", self.loop), 0.0, 0.95)), tertiary=0.0)

    def report(self) -> dict[str, Any]:
        """JSON-able: ``status`` (``pinnate`` or :data:`NOT_VISIBLE`), the ``reason`` when not
        visible, and the numbers measured."""
        out: dict[str, Any] = {"status": "pinnate" if self.visible else NOT_VISIBLE}
        if not self.visible:
            out["reason"] = self.reason
        out.update(polarity=self.polarity, angle_deg=round(self.angle, 2), curvature=round(self.curvature, 3),
                   secondaries=self.secondaries, loop=round(self.loop, 3), alternate=round(self.alternate, 3),
                   irregularity=round(self.irregularity, 3), contrast=round(self.contrast, 3),
                   strength=round(self.strength, 3), midrib_offset=round(self.midrib_offset, 5),
                   sides={f"{k:+d}": {n: round(float(v), 3) for n, v in s.items()} for k, s in self.sides.items()},
                   seconds=round(self.seconds, 4))
        return out


# -- the whole ---------------------------------------------------------------------------------------------
def _side_numbers(m: RidgeMap, s: int, side: Side, traced: Traced | None) -> tuple[Side, dict[str, float]]:
    """One side's secondaries kept (the traced veins whose ridge is at least
    :data:`_KEEP_STRENGTH` of the side's upper quartile and that reach :data:`_KEEP_REACH` of the way:
    a peak of the profile made by the tertiary net or noise fades at once), their fitted (θ, c)
    and the side's numbers for the report."""
    loop = reach = strength = 0.0
    misfit_rms = float("nan")
    if traced is not None and len(side.at):
        which = np.flatnonzero(traced.side == s)
        veins = traced.vein_strength()[which]
        strong = float(np.percentile(veins[veins > 0.0], 75)) if (veins > 0.0).any() else 0.0
        keep = (veins >= _KEEP_STRENGTH * strong) & (veins > 0.0) & (traced.faded[which] >= _KEEP_REACH)
        which = which[keep]
        side = replace(side, at=side.at[keep], ell=side.ell[keep])
        seen = traced.seen()
        lines = [traced.points[k, 1:][seen[k]] for k in which]
        for d_theta, d_curv in _FIT_GRIDS:
            thetas = np.clip(side.theta + d_theta, math.radians(5.0), math.radians(88.0))
            curvs = np.unique(np.clip(side.curv + d_curv, 0.0, 1.0))
            misfit = family_misfit(lines, m.w(s), thetas, curvs)
            if np.isfinite(misfit).any():
                a, b = np.unravel_index(int(np.argmin(misfit)), misfit.shape)
                side = replace(side, theta=float(thetas[a]), curv=float(curvs[b]))
                misfit_rms = float(misfit[a, b])
        if len(which):
            faded = traced.faded[which]
            loop, reach = loop_fraction(faded), float(np.median(faded))
            measured = traced.strength[which][seen[which]]
            strength = float(np.median(measured)) / m.level if measured.size else 0.0
    count, irregular = spacing(side.at)
    return side, {"angle": math.degrees(side.theta), "curvature": side.curv, "secondaries": count,
                  "found": len(side.at), "loop": loop, "irregularity": irregular, "contrast": side.contrast,
                  "reach": reach, "strength": strength, "misfit": misfit_rms}


def detect_veins(texture: NDArray[np.floating], parts: Sequence[LeafParams]) -> VeinEstimate:
    """The pinnate venation visible in the fitted ``texture`` (T, T, 4) of the leaf ``parts``
    (one leaf or the two halves), or why none is trusted (see the module docstring)."""
    t0 = time.perf_counter()
    image = vein_image(texture, parts)
    lighter, darker, inside = ridge_maps(image)
    if inside.sum() < 400:
        return VeinEstimate(False, "the blade covers too little of the texture", seconds=time.perf_counter() - t0)
    maps = {"lighter": RidgeMap(image, lighter, inside), "darker": RidgeMap(image, darker, inside)}
    y0 = origins(image.rows, 2)
    grid = {s: candidates(image.w[0 if s < 0 else 1], y0, ANGLES, CURVES, SAMPLES[0])[:2] for s in (-1, 1)}
    coarse = {name: {s: coarse_scores(m, s, *grid[s]) for s in (-1, 1)} for name, m in maps.items()}
    polarity = max(coarse, key=lambda name: min(contrast(c) for c in coarse[name].values()))
    m = maps[polarity]
    found = {s: fine_search(m, s, coarse[polarity][s]) for s in (-1, 1)}
    traced = trace(m, found) if any(len(sd.at) for sd in found.values()) else None
    sides, per = {}, {}
    for s, sd in found.items():
        sides[s], per[s] = _side_numbers(m, s, sd, traced)
    stand_out = min(sd.contrast for sd in sides.values())
    strength = float(np.mean([p["strength"] for p in per.values()]))
    gap = float(np.median(np.concatenate([np.diff(np.sort(sd.at)) for sd in sides.values()]))) \
        if min(len(sd.at) for sd in sides.values()) >= 2 else 0.0
    numbers: dict[str, Any] = dict(
        polarity=polarity, angle=float(np.mean([p["angle"] for p in per.values()])),
        curvature=float(np.mean([p["curvature"] for p in per.values()])),
        secondaries=int(round(float(np.mean([p["secondaries"] for p in per.values()])))),
        loop=float(np.mean([p["loop"] for p in per.values()])),
        alternate=alternate(sides[-1].at, sides[1].at, gap) if gap > 0.0 else 0.0,
        irregularity=float(np.mean([p["irregularity"] for p in per.values()])), contrast=stand_out,
        strength=strength, midrib_offset=m.midrib_rms, sides=per)
    reason = ""
    if min(len(sd.at) for sd in sides.values()) < MIN_SECONDARIES:
        reason = f"fewer than {MIN_SECONDARIES} secondaries found on a side"
    elif abs(per[-1]["angle"] - per[1]["angle"]) > MAX_SIDE_ANGLE:
        reason = (f"the sides disagree: secondaries at {per[-1]['angle']:.0f}° and {per[1]['angle']:.0f}° "
                  "from the midrib")
    elif stand_out < MIN_CONTRAST:
        reason = (f"no consistent secondaries: the best vein family stands out {stand_out:.2f}× "
                  f"(at least {MIN_CONTRAST:g})")
    elif strength < MIN_STRENGTH:
        reason = f"faint ridges: {strength:.2f}× the blade's mean (at least {MIN_STRENGTH:g})"
    elif max(p["misfit"] for p in per.values()) > MAX_MISFIT:
        reason = (f"the veins do not follow a pinnate tree's secondaries: {1e3 * max(p['misfit'] for p in per.values()):.1f}"
                  f" thousandths of the length off (at most {1e3 * MAX_MISFIT:g})")
    return VeinEstimate(not reason, reason, **numbers, seconds=time.perf_counter() - t0)


def with_veins(parts: Sequence[LeafParams], estimate: VeinEstimate, seed: int = 0) -> tuple[LeafParams, ...]:
    """``parts`` with the venation of ``estimate`` (each half of an asymmetric leaf its own side's
    angle, curvature, count and loop); unchanged when nothing was visible or when the venation
    would not make a valid tree on the fitted shape (:func:`~leafview.botany.venation.check_veins`)."""
    if not estimate.visible:
        return tuple(parts)
    out = []
    for p in parts:
        q = p.replace(venation=estimate.venation(seed, p.shape.half if len(parts) == 2 else None))
        try:
            check_veins(q)
        except ParamError:
            return tuple(parts)
        out.append(q)
    return tuple(out)
