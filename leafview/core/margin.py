"""A landmark margin as the leaf's silhouette: the quadratic B-spline of Garg & Leow 2011
(eqs 2-6) evaluated directly, instead of an Ω quartic fitted to it.

A leaf built from landmarks (:mod:`leafview.botany.landmarks`) has on each side a margin through
N = 2..5 landmarks p_0 = base (0, 0) … p_{N-1} = apex (0, 1) at the knots 0 = u_0 < … < u_{N-1} = 1.
Each landmark gap [u_g, u_{g+1}] holds two quadratic Bézier spans of equal length (Garg & Leow
2011, eqs 3-6 with the knots of :func:`leafview.botany.hermite.hermite_knots`):

    first half  (p_g, a_g, m_g),   second half  (m_g, b_g, p_{g+1}),   m_g = (a_g + b_g) / 2

so a side is stored as its knots and the points ``p_0, a_0, b_0, p_1, a_1, b_1, …, p_{N-1}``.

**The surface** (the numpy reference :func:`leafview.core.blade.blade_partials` and
``margin_silhouette`` in ``shaders/leaf_eval.glsl``): the grid's v is the B-spline parameter of
both sides. A side's point (x(v), y(v)) is written in that side's own frame (x ≥ 0 across the
blade, y along the midrib) and placed on the midrib's frame at the height y:

    P_σ(v) = A(y(v)),   Q_σ(v) = x(v) n(y(v)),   S_σ = P_σ + σ Q_σ

with A the midrib (Chaurasia & Beardsley 2017, eq. 1) and n its in-plane normal (eq. 2). P and Q
take the place of the quartics of eqs 3-4 in the cross-section of eqs 5-6, so
``L = B_0(s) A(v) + (1 - B_0(s)) P_σ(v) + u Q_σ(v) + heights``: F and G lie at 1/3 and 2/3 of the
way from P to S as in the paper's model, the heights are the paper's quartics of z̄f, z̄g and
z̄s, and jitter, veins, ripples and bending act on the result unchanged. σ = +1 (u ≥ 0) is the
side drawn at -x in the top view, the landmark leaf's *left* side, σ = -1 its right side (the
convention of :mod:`leafview.core.blade`).

On the GPU a side is :data:`SIDE_TEXELS` texels (:meth:`Margin.texels`): the inner knots, then
per gap the texels (p_g, a_g) and (b_g, p_{g+1}); unused gaps and knots are padded so that the
span search never selects them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.bezier import derivative_points, evaluate_curve, in_plane_normal
from leafview.errors import ParamError

__all__ = ["MarginSide", "Margin", "MAX_GAPS", "SIDE_TEXELS", "MARGIN_TEXELS", "MARGIN_LIMIT",
           "side_points", "margin_frame"]

MAX_GAPS = 4            # landmark gaps per side: base, tail, waist, shoulder, apex
SIDE_TEXELS = 1 + 2 * MAX_GAPS
MARGIN_TEXELS = 2 * SIDE_TEXELS
MARGIN_LIMIT = 100.0    # |coordinate| in leaf lengths (as the landmarks themselves)
MIN_KNOT_GAP = 1e-4     # between consecutive knots (a gap's parameter is divided by its width)
_PAD_KNOT = 2.0         # past v = 1: the span search stops before it

Arr = NDArray[np.float64]


@dataclass(frozen=True)
class MarginSide:
    """One side's margin: ``knots`` (N,) from 0 to 1 and ``points`` (3N - 2, 2): the landmarks
    and the two inner Bézier points of every gap, ``p_0, a_0, b_0, p_1, …, p_{N-1}``, in the
    side's own frame (x across the blade, ≥ 0 on a plain blade)."""

    knots: tuple[float, ...]
    points: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        self.check("margin")

    def check(self, path: str) -> None:
        self.validate(self.knots, self.points, path)

    @staticmethod
    def validate(knots: Sequence[float], points: Sequence[Sequence[float]], path: str) -> None:
        """Refuse knots and points that are no side's margin, naming ``path``'s field."""
        k = np.asarray(knots, np.float64)
        p = np.asarray(points, np.float64)
        n = k.size
        if k.ndim != 1 or not 2 <= n <= MAX_GAPS + 1:
            raise ParamError(f"{path}.knots", f"expected 2 to {MAX_GAPS + 1} knots, got {k.size}")
        if not np.all(np.isfinite(k)) or k[0] != 0.0 or k[-1] != 1.0 or np.any(np.diff(k) < MIN_KNOT_GAP):
            raise ParamError(f"{path}.knots", f"expected knots increasing from 0 to 1 by at least {MIN_KNOT_GAP:g}, "
                                              f"got {list(knots)}")
        if p.shape != (3 * n - 2, 2):
            raise ParamError(f"{path}.points", f"{n} knots take {3 * n - 2} points [x, y], got shape {p.shape}")
        bad = ~np.isfinite(p) | (np.abs(p) > MARGIN_LIMIT)
        if bad.any():
            i = int(np.argwhere(bad)[0][0])
            raise ParamError(f"{path}.points[{i}]", f"expected finite coordinates within ±{MARGIN_LIMIT:g}, "
                                                    f"got {list(points[i])}")
        if tuple(p[0]) != (0.0, 0.0) or tuple(p[-1]) != (0.0, 1.0):
            raise ParamError(f"{path}.points", "the margin runs from the base [0, 0] to the apex [0, 1], "
                                               f"got {list(points[0])} … {list(points[-1])}")

    def to_dict(self) -> dict[str, Any]:
        return {"knots": list(self.knots), "points": [list(p) for p in self.points]}

    @classmethod
    def from_dict(cls, data: Any, path: str) -> MarginSide:
        if not isinstance(data, Mapping):
            raise ParamError(path, f"expected a table with knots and points, got {type(data).__name__}")
        for key in data:
            if key not in ("knots", "points"):
                raise ParamError(f"{path}.{key}", "unknown key (expected knots, points)")
        for key in ("knots", "points"):
            if key not in data:
                raise ParamError(f"{path}.{key}", "missing")
        knots = _numbers(data["knots"], f"{path}.knots")
        raw = data["points"]
        if not isinstance(raw, Sequence) or isinstance(raw, (str, bytes)):
            raise ParamError(f"{path}.points", f"expected a list of [x, y], got {type(raw).__name__}")
        points = []
        for i, pt in enumerate(raw):
            xy = _numbers(pt, f"{path}.points[{i}]")
            if len(xy) != 2:
                raise ParamError(f"{path}.points[{i}]", f"expected [x, y], got {len(xy)} numbers")
            points.append((xy[0], xy[1]))
        cls.validate(knots, points, path)   # named by the file's path, before __post_init__ checks again
        return cls(tuple(knots), tuple(points))

    def evaluate(self, v: ArrayLike) -> tuple[Arr, Arr]:
        """(x, y) of the margin at parameters ``v`` in [0, 1] and its derivative d/dv, each (M, 2)."""
        return side_points(np.asarray(self.knots, np.float64)[None], np.asarray(self.points, np.float64)[None],
                           np.asarray(v, np.float64).ravel()[None])


def _numbers(value: Any, path: str) -> list[float]:
    if not isinstance(value, Sequence) or isinstance(value, (str, bytes)):
        raise ParamError(path, f"expected a list of numbers, got {type(value).__name__}")
    out = []
    for i, x in enumerate(value):
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(float(x)):
            raise ParamError(f"{path}[{i}]", f"expected a finite number, got {x!r}")
        out.append(float(x))
    return out


@dataclass(frozen=True)
class Margin:
    """The margins of both sides (see the module docstring); ``left`` is written in its own
    frame like ``right`` (x ≥ 0), as :class:`leafview.botany.landmarks.LandmarkLeaf` writes sides."""

    right: MarginSide
    left: MarginSide

    def to_dict(self) -> dict[str, Any]:
        return {"right": self.right.to_dict(), "left": self.left.to_dict()}

    @classmethod
    def from_dict(cls, data: Any, path: str = "margin") -> Margin:
        if not isinstance(data, Mapping):
            raise ParamError(path, f"expected a table with right and left, got {type(data).__name__}")
        for key in data:
            if key not in ("right", "left"):
                raise ParamError(f"{path}.{key}", "unknown key (expected right, left)")
        if "right" not in data:
            raise ParamError(f"{path}.right", "missing")
        right = MarginSide.from_dict(data["right"], f"{path}.right")
        left = MarginSide.from_dict(data["left"], f"{path}.left") if "left" in data else right
        return cls(right, left)

    def scaled_width(self, factor: float) -> Margin:
        """Both sides with every point's x (across the blade) times ``factor``."""
        def scale(side: MarginSide) -> MarginSide:
            return MarginSide(side.knots, tuple((x * factor, y) for x, y in side.points))
        right = scale(self.right)
        return Margin(right, right if self.left == self.right else scale(self.left))

    def side(self, sigma: float) -> MarginSide:
        """The side drawn for u ≥ 0 (σ = +1: the left side) or u < 0 (σ = -1: the right side)."""
        return self.left if sigma > 0 else self.right

    def texels(self) -> NDArray[np.float32]:
        """The (MARGIN_TEXELS, 4) float32 texels the shader reads: the σ = +1 (left) side first."""
        out = np.empty((MARGIN_TEXELS, 4), np.float32)
        for k, side in enumerate((self.left, self.right)):
            out[k * SIDE_TEXELS:(k + 1) * SIDE_TEXELS] = side_texels(np.asarray(side.knots)[None],
                                                                    np.asarray(side.points)[None])[0]
        return out


def side_texels(knots: ArrayLike, points: ArrayLike) -> NDArray[np.float32]:
    """(B, SIDE_TEXELS, 4) texels of B sides with the same number N of knots: ``knots`` (B, N),
    ``points`` (B, 3N - 2, 2). Texel 0 holds the inner knots u_1 … u_{N-2} padded with 2 (past
    every v), texels 1 + 2g and 2 + 2g the points (p_g, a_g) and (b_g, p_{g+1}) of gap g; unused
    gaps repeat the apex."""
    k = np.asarray(knots, np.float64)
    p = np.asarray(points, np.float64)
    b, n = k.shape
    out = np.zeros((b, SIDE_TEXELS, 4), np.float32)
    out[:, 0, :] = _PAD_KNOT
    out[:, 0, :n - 2] = k[:, 1:-1]
    out[:, 0, 3] = k.shape[1] - 1          # gaps (read by the shader for the last knot)
    g = n - 1
    starts = p[:, 0:3 * g:3]               # p_g
    a = p[:, 1:3 * g:3]
    bb = p[:, 2:3 * g:3]
    ends = p[:, 3:3 * g + 1:3]             # p_{g+1}
    out[:, 1:1 + 2 * g:2] = np.concatenate([starts, a], axis=2)
    out[:, 2:2 + 2 * g:2] = np.concatenate([bb, ends], axis=2)
    out[:, 1 + 2 * g:] = (0.0, 1.0, 0.0, 1.0)
    return out


def side_points(knots: Arr, points: Arr, v: Arr) -> tuple[Arr, Arr]:
    """Margins of B sides with N knots each at parameters ``v`` (B, M): points and d/dv, each
    (B, M, 2). The twin of ``margin_side`` in ``shaders/leaf_eval.glsl``."""
    b, n = knots.shape
    g = np.clip(np.sum(v[:, :, None] >= knots[:, None, 1:-1], axis=2), 0, n - 2)    # gap of each v
    rows = np.arange(b)[:, None]
    lo, hi = knots[rows, g], knots[rows, g + 1]
    h = hi - lo
    f = (v - lo) / h
    first = (f < 0.5)[..., None]
    t = np.where(first[..., 0], 2.0 * f, 2.0 * f - 1.0)[..., None]
    p0, a, bb, p1 = (points[rows, 3 * g + i] for i in range(4))
    m = 0.5 * (a + bb)
    c0 = np.where(first, p0, m)
    c1 = np.where(first, a, bb)
    c2 = np.where(first, m, p1)
    r = 1.0 - t
    pos = r * r * c0 + 2.0 * r * t * c1 + t * t * c2
    der = 2.0 * (r * (c1 - c0) + t * (c2 - c1)) * (2.0 / h)[..., None]
    return pos, der


def margin_frame(xy: Arr, dxy: Arr, axis: Arr) -> tuple[Arr, Arr, Arr, Arr]:
    """P = A(y), Q = x n(y) and their v-derivatives ((M, 3) each) of a side sampled as ``xy`` and
    ``dxy`` ((M, 2), :func:`side_points`), on the midrib with control points ``axis`` (4, 3)."""
    y, x = xy[:, 1], xy[:, 0]
    dy, dx = dxy[:, 1], dxy[:, 0]
    d1 = derivative_points(axis)
    a, da, dda = (evaluate_curve(c, y) for c in (axis, d1, derivative_points(d1)))
    n, dn = in_plane_normal(da, dda, y)
    P = a
    Q = x[:, None] * n
    dP = da * dy[:, None]
    dQ = dx[:, None] * n + (x * dy)[:, None] * dn
    return P, Q, dP, dQ
