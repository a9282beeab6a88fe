"""Lobed leaves for the synthetic photos: a built-in lobed preset's closed margin (maple, oak,
bilobed; :mod:`leafview.core.lobes`), randomly varied, as the top view the photo generator lays
on the paper (``synthetic_photo(seed, kind="lobed")``).

A lobed preset's margin is one closed uniform cubic B-spline (Mündermann et al. 2003, sec. 3.1),
clockwise in the leaf frame with C(0) at the base. :func:`lobed_sides` varies it by

* **lobe depth**: every control point moved along the ray from the blade's middle (0, 0.45) so
  that its distance r becomes r̄ + k (r - r̄), r̄ the mean distance, k in [0.85, 1.15]: the lobes
  grow or shrink against the sinuses between them;
* **lobe spread**: the ray's angle φ turned by a sin(2 (φ - 90°)), |a| <= 0.12 rad, which fans the
  side lobes up or down while the midline (φ = ±90°) stays put,

(a varied margin that crosses itself is drawn again, at last the preset's own), then measures the
truth: the base is C(0); the apex is the highest point where the margin crosses the base's
vertical (the terminal lobe's tip of a palmate or pinnately lobed leaf; the sinus between the two
lobes of a bilobed one, which the photo fit finds as an emarginate apex), and a similarity takes
them to (0, 0) and (0, 1). numpy only; the presets are read once.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.core.bspline import evaluate_closed, sample_closed
from leafview.core.io import load_params
from leafview.core.lobes import self_intersections
from leafview.errors import ParamError
from leafview.resources import builtin_presets

__all__ = ["LOBED_PRESETS", "lobed_sides", "preset_outline", "vary_outline", "frame_outline"]

LOBED_PRESETS = ("maple", "oak", "bilobed")
_CENTRE = np.array([0.0, 0.45])
_SAMPLES = 1600            # margin samples of the drawn top view
Arr = NDArray[np.float64]


@cache
def preset_outline(name: str) -> Arr:
    """The control points (m, 2) of a built-in lobed preset's margin."""
    if name not in LOBED_PRESETS:
        raise ParamError("lobed_preset", f"must be one of {', '.join(LOBED_PRESETS)}, got {name!r}")
    ctrl = np.asarray(load_params(builtin_presets()[name]).lobes.outline, np.float64)
    ctrl.setflags(write=False)
    return ctrl


def vary_outline(ctrl: Arr, depth: float, spread: float) -> Arr:
    """``ctrl`` with its lobes ``depth`` times as deep about the mean distance from (0, 0.45) and
    fanned by ``spread`` radians (see the module docstring)."""
    d = np.asarray(ctrl, np.float64) - _CENTRE
    r = np.hypot(d[:, 0], d[:, 1])
    phi = np.arctan2(d[:, 1], d[:, 0])
    r_new = r.mean() + depth * (r - r.mean())
    phi_new = phi + spread * np.sin(2.0 * (phi - 0.5 * np.pi))
    return np.stack([r_new * np.cos(phi_new), r_new * np.sin(phi_new)], axis=1) + _CENTRE


def _top_crossing(ring: Arr, x0: float) -> Arr:
    """The highest point where the closed polyline ``ring`` crosses the vertical x = ``x0``."""
    a, b = ring, np.roll(ring, -1, axis=0)
    hit = (a[:, 0] - x0) * (b[:, 0] - x0) <= 0.0
    hit &= a[:, 0] != b[:, 0]
    f = (x0 - a[hit, 0]) / (b[hit, 0] - a[hit, 0])
    y = a[hit, 1] + f * (b[hit, 1] - a[hit, 1])
    if not len(y):
        raise ParamError("lobes.outline", "the margin does not cross the base's vertical")
    return np.array([x0, float(y.max())])


def frame_outline(ctrl: Arr, samples: int = _SAMPLES) -> tuple[Arr, Arr, Arr]:
    """The margin of ``ctrl`` sampled counter-clockwise from the base, in the frame whose base is
    (0, 0) and apex (0, 1) (see the module docstring): ``(ring, base, apex)`` with base and apex in
    the preset's own frame (the ring's first point is the base; the apex is one of its points)."""
    c = np.asarray(ctrl, np.float64)
    base = evaluate_closed(c, np.zeros(1))[0]
    ring = sample_closed(c, samples)[::-1]               # clockwise -> counter-clockwise
    ring = np.roll(ring, 1, axis=0)                      # C(0) first again
    apex = _top_crossing(ring, float(base[0]))
    d = apex - base
    length = float(np.hypot(*d))
    turn = np.arctan2(d[0], d[1])                        # the base->apex direction onto +y
    cs, sn = np.cos(turn), np.sin(turn)
    rot = np.array([[cs, -sn], [sn, cs]]) / length
    out = (ring - base) @ rot.T
    k = int(np.argmin(np.hypot(out[:, 0], out[:, 1] - 1.0)))
    out[k] = (0.0, 1.0)
    out[0] = (0.0, 0.0)
    return out, base, apex


def lobed_sides(rng: np.random.Generator, name: str | None = None) -> tuple[Arr, Arr, Arr, dict[str, Any]]:
    """A random lobed leaf's top view: ``(right, left, axis, info)``, the sides from the base
    (0, 0) to the apex (0, 1) (the right one counter-clockwise round the blade), a straight
    midrib, and the truth (preset, lobe depth, spread)."""
    chosen = str(rng.choice(LOBED_PRESETS)) if name is None else name
    ctrl0 = preset_outline(chosen)
    depth, spread = float(rng.uniform(0.85, 1.15)), float(rng.uniform(-0.12, 0.12))
    ring = None
    for attempt in range(4):
        if attempt == 3:
            depth, spread = 1.0, 0.0
        c = vary_outline(ctrl0, depth, spread)
        if not self_intersections(sample_closed(c, 8 * len(c))):
            ring = frame_outline(c)[0]
            break
        depth, spread = float(rng.uniform(0.9, 1.1)), float(rng.uniform(-0.06, 0.06))
    assert ring is not None
    ia = int(np.argmin(np.hypot(ring[:, 0], ring[:, 1] - 1.0)))
    right = ring[: ia + 1]
    left = np.vstack([ring[ia:], ring[:1]])[::-1]
    axis = np.stack([np.zeros(33), np.linspace(0.0, 1.0, 33)], axis=1)
    info: dict[str, Any] = {"name": chosen, "serration": None,
                            "lobes": {"preset": chosen, "depth": depth, "spread": spread}}
    return right, left, axis, info
