"""Quadratic B-spline through points with prescribed tangent directions (Garg & Leow 2011, eqs 2-6).

The margin fit of the landmark model (:mod:`leafview.botany.landmarks`): N landmarks p_i with unit
tangents t_i give 2N linear equations (eqs 3-4) for the 2N control points of a degree-2 B-spline,
with chord-length parameters (eqs 5-6) and the knot vector of Piegl & Tiller's Hermite
interpolation. The condition number of the system is reported (Fig. 3); where it is singular
(coincident consecutive landmarks) the closed form is used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BSpline

from leafview.core.params import ParamError

__all__ = ["SINGULAR_CONDITION", "MarginFit", "MarginPieces", "chord_parameters", "fit_margin", "fit_margin_report",
           "hermite_knots", "margin_pieces"]

#: Above this condition number of the 2N×2N collocation matrix (eqs 3-4) the linear solve is
#: replaced by the closed form (the matrix is exactly singular when two consecutive landmarks
#: coincide, i.e. some u_i - u_{i-1} = 0, the "u_i at 0 or 1" cases of Fig. 3).
SINGULAR_CONDITION = 1e12


# ---------------------------------------------------------------------------------------------
# eqs 2-6: quadratic B-spline through points with prescribed tangent directions
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class MarginFit:
    """A fitted margin and how it was obtained.

    Attributes
    ----------
    spline : scipy.interpolate.BSpline
        Degree 2, 2N control points (``spline.c``, shape (2N, 2)), clamped on [0, 1].
    u : ndarray (N,)
        Landmark parameters of eq. 6 (chord length); ``spline(u[i]) == points[i]``.
    alpha : ndarray (N,)
        Tangent magnitudes of eq. 4 (``spline.derivative()(u[i]) == alpha[i] * tangents[i]``).
    condition : float
        2-norm condition number of the collocation matrix of eqs 3-4 (``inf`` when singular).
    method : str
        ``"solve"`` (the linear system was solved) or ``"closed-form"``.
    """

    spline: BSpline
    u: NDArray[np.float64]
    alpha: NDArray[np.float64]
    condition: float
    method: str

    @property
    def control_points(self) -> NDArray[np.float64]:
        return np.asarray(self.spline.c)


def chord_parameters(points: ArrayLike) -> tuple[NDArray[np.float64], float]:
    """Eqs 5-6: normalised cumulative chord lengths ``u`` (u_1 = 0, u_N = 1) and the total D."""
    p = np.asarray(points, dtype=np.float64)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    total = float(seg.sum())
    if not total > 0.0:
        raise ParamError("points", "all landmarks coincide: the margin has zero chord length")
    u = np.concatenate([[0.0], np.cumsum(seg) / total])
    u[-1] = 1.0
    return u, total


def hermite_knots(u: ArrayLike) -> NDArray[np.float64]:
    """Knot vector of the quadratic Hermite interpolant (Piegl & Tiller, sec. 9.2.4, eq. 9.21).

    ``{0,0,0, u_1/2, u_1, (u_1+u_2)/2, u_2, ..., u_{N-2}, (u_{N-2}+1)/2, 1,1,1}``: every interior
    landmark parameter is a knot and every gap gets a knot at its midpoint, which gives the 2N + 3
    knots of a quadratic B-spline with 2N control points.
    """
    u = np.asarray(u, dtype=np.float64)
    mids = 0.5 * (u[:-1] + u[1:])
    interior = np.empty(2 * len(u) - 3)
    interior[0::2] = mids
    interior[1::2] = u[1:-1]
    return np.concatenate([[0.0, 0.0, 0.0], interior, [1.0, 1.0, 1.0]])


def _collocation(knots: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rows B_k(u_i) (eq. 3) interleaved with rows B'_k(u_i) (eq. 4): the 2N×2N system matrix.

    Interior landmarks sit on knots where a quadratic is C¹, so B' is well defined there.
    """
    m = len(knots) - 3
    basis = BSpline(knots, np.eye(m), 2)
    a = np.empty((2 * len(u), m))
    a[0::2] = basis(u)
    a[1::2] = basis(u, nu=1)
    return a


def _closed_form(points: NDArray[np.float64], vel: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """Control points of eqs 3-4 without a matrix inverse.

    With the knots of :func:`hermite_knots`, a landmark at knot u_i lies on the leg between its two
    control points and the derivative there is 2(q_{2i} - q_{2i-1}) / (knot gap), which gives

        q_{2i-1} = p_i - (u_i - u_{i-1})/4 · α_i t_i,     q_{2i} = p_i + (u_{i+1} - u_i)/4 · α_i t_i

    (q_0 = p_1 and q_{2N-1} = p_N at the clamped ends). It stays valid when a gap is zero, where
    the matrix is singular: both control points collapse onto the landmark and the margin has a
    corner there (one-sided tangents t_i and t_{i+1}).
    """
    gaps = np.diff(u)
    before = np.concatenate([[0.0], gaps])[:, None] / 4.0
    after = np.concatenate([gaps, [0.0]])[:, None] / 4.0
    q = np.empty((2 * len(u), 2))
    q[0::2] = points - before * vel
    q[1::2] = points + after * vel
    return q


def fit_margin_report(points: ArrayLike, tangents: ArrayLike, alpha: ArrayLike | None = None,
                      *, method: str = "auto") -> MarginFit:
    """Fit the quadratic B-spline of eqs 2-4 through N landmarks with given tangent directions.

    Parameters
    ----------
    points : (N, 2) array_like
        Landmarks p_1..p_N in margin order (N ≥ 2).
    tangents : (N, 2) array_like
        Tangent directions t_i (normalised here; only the direction matters).
    alpha : float or (N,) array_like, optional
        The scalars α_i of eq. 4 (|p'(u_i)|). Default: the total chord length D of eq. 5 for every
        landmark, as Piegl & Tiller do for derivative constraints, since with u ∈ [0, 1] the curve
        speed is about its length.
    method : {"auto", "solve", "closed-form"}
        ``"auto"`` solves the 2N×2N linear system of eqs 3-4 unless its condition number exceeds
        :data:`SINGULAR_CONDITION` (coincident consecutive landmarks make it singular), in which
        case it uses the closed form of :func:`_closed_form`; both give the same curve otherwise.

    Returns
    -------
    MarginFit
        The spline, the landmark parameters u_i of eqs 5-6, α, the condition number and method.
    """
    p = np.asarray(points, dtype=np.float64)
    t = np.asarray(tangents, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 2:
        raise ParamError("points", f"expected an (N, 2) array with N >= 2, got shape {p.shape}")
    if t.shape != p.shape:
        raise ParamError("tangents", f"expected shape {p.shape} like the points, got {t.shape}")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(t))):
        raise ParamError("points", "landmarks and tangents must be finite")
    norms = np.linalg.norm(t, axis=1)
    if np.any(norms == 0.0):
        raise ParamError(f"tangents[{int(np.argmin(norms))}]", "zero tangent has no direction")
    t = t / norms[:, None]
    u, total = chord_parameters(p)
    a = np.full(len(p), total) if alpha is None else np.broadcast_to(np.asarray(alpha, float), (len(p),)).copy()
    if np.any(~np.isfinite(a)) or np.any(a <= 0):
        raise ParamError("alpha", "tangent magnitudes must be finite and positive")
    vel = a[:, None] * t
    knots = hermite_knots(u)
    if np.any(np.diff(u) <= 0.0):
        cond = math.inf
    else:
        cond = float(np.linalg.cond(_collocation(knots, u)))
    if method not in ("auto", "solve", "closed-form"):
        raise ValueError(f"method must be 'auto', 'solve' or 'closed-form', not {method!r}")
    use_solve = method == "solve" or (method == "auto" and cond < SINGULAR_CONDITION)
    if use_solve:
        if not math.isfinite(cond):
            raise ParamError("points", "two consecutive landmarks coincide: the system of eqs 3-4 is singular")
        rhs = np.empty((2 * len(p), 2))
        rhs[0::2] = p
        rhs[1::2] = vel
        q = np.linalg.solve(_collocation(knots, u), rhs)
        used = "solve"
    else:
        q = _closed_form(p, vel, u)
        used = "closed-form"
    return MarginFit(BSpline(knots, q, 2), u, a, cond, used)


def fit_margin(points: ArrayLike, tangents: ArrayLike, alpha: ArrayLike | None = None) -> BSpline:
    """The quadratic B-spline with 2N control points through N landmarks with tangents (eqs 2-6).

    Shorthand for ``fit_margin_report(points, tangents, alpha).spline``; see
    :func:`fit_margin_report` for the parameters and for the condition number.
    """
    return fit_margin_report(points, tangents, alpha).spline


# ---------------------------------------------------------------------------------------------
# many margins at once: the closed form as quadratic Bézier pieces
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class MarginPieces:
    """A batch of margins of eqs 2-6 (B sides, N landmarks each) as their quadratic Bézier pieces.

    With the knots of :func:`hermite_knots`, each landmark gap [u_i, u_{i+1}] holds two spans of
    equal length (split at the mid knot), so the B-spline is 2(N - 1) quadratic Béziers: the
    first from p_i through ``q_{2i} = p_i + (u_{i+1} - u_i)/4 · α_i t_i`` to the mid point
    ``m = (q_{2i} + q_{2i+1}) / 2``, the second from m through
    ``q_{2i+1} = p_{i+1} - (u_{i+1} - u_i)/4 · α_{i+1} t_{i+1}`` to p_{i+1} (the closed form of
    :func:`fit_margin_report`, which equals its linear solve wherever that is regular).

    Attributes
    ----------
    breaks : ndarray (B, 2N - 1)
        The distinct knots 0, u_1/2, u_1, ..., 1 of each side (span k is [breaks[k], breaks[k + 1]]).
    pieces : ndarray (B, 2N - 2, 3, 2)
        Bézier control points of every span.
    """

    breaks: NDArray[np.float64]
    pieces: NDArray[np.float64]

    def __call__(self, u: ArrayLike) -> NDArray[np.float64]:
        """(B, M, 2): every margin at the parameters ``u`` ((M,) for all sides or (B, M)), in [0, 1]."""
        b = len(self.breaks)
        uu = np.broadcast_to(np.asarray(u, dtype=np.float64), (b, np.shape(u)[-1]))
        inner = self.breaks[:, 1:-1]
        spans = self.pieces.shape[1]
        span = np.sum(uu[:, :, None] >= inner[:, None, :], axis=2)          # (B, M): 0 .. 2N - 3
        flat = span + (spans * np.arange(b))[:, None]                        # row of each sample's span
        lo = self.breaks[:, :-1].ravel()[flat]
        width = np.diff(self.breaks, axis=1).ravel()[flat]
        s = np.where(width > 0.0, (uu - lo) / np.where(width > 0.0, width, 1.0), 0.0)[..., None]
        ctrl = self.pieces.reshape(b * spans, 6)[flat]                        # (B, M, 6): three points
        r = 1.0 - s
        return r * r * ctrl[..., 0:2] + 2.0 * r * s * ctrl[..., 2:4] + s * s * ctrl[..., 4:6]


def margin_pieces(points: ArrayLike, tangents: ArrayLike) -> MarginPieces:
    """The margins of eqs 2-6 for a batch of B sides with the same number N of landmarks.

    ``points`` and ``tangents`` are (B, N, 2) (tangents need not be unit); α is the total chord
    length D of eq. 5, as in :func:`fit_margin_report` by default. Vectorised over the batch: no
    linear solve and no scipy object per margin, so thousands of margins cost milliseconds."""
    p = np.asarray(points, dtype=np.float64)
    t = np.asarray(tangents, dtype=np.float64)
    if p.ndim != 3 or p.shape[2] != 2 or p.shape[1] < 2:
        raise ParamError("points", f"expected a (B, N, 2) array with N >= 2, got shape {p.shape}")
    if t.shape != p.shape:
        raise ParamError("tangents", f"expected shape {p.shape} like the points, got {t.shape}")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(t))):
        raise ParamError("points", "landmarks and tangents must be finite")
    norms = np.linalg.norm(t, axis=2, keepdims=True)
    if np.any(norms == 0.0):
        raise ParamError("tangents", "zero tangent has no direction")
    seg = np.linalg.norm(np.diff(p, axis=1), axis=2)                          # (B, N - 1)
    total = seg.sum(axis=1, keepdims=True)
    if np.any(total <= 0.0):
        raise ParamError("points", "all landmarks coincide: the margin has zero chord length")
    u = np.concatenate([np.zeros((len(p), 1)), np.cumsum(seg, axis=1) / total], axis=1)
    u[:, -1] = 1.0
    vel = t / norms * total[:, :, None]                                       # α_i t_i, α = D
    gap = np.diff(u, axis=1)[..., None] / 4.0
    out = p[:, :-1] + gap * vel[:, :-1]                                       # q_{2i}
    into = p[:, 1:] - gap * vel[:, 1:]                                        # q_{2i+1}
    mid = 0.5 * (out + into)
    first = np.stack([p[:, :-1], out, mid], axis=2)
    second = np.stack([mid, into, p[:, 1:]], axis=2)
    pieces = np.stack([first, second], axis=2).reshape(len(p), -1, 3, 2)
    breaks = np.empty((len(p), 2 * p.shape[1] - 1))
    breaks[:, 0::2] = u
    breaks[:, 1::2] = 0.5 * (u[:, :-1] + u[:, 1:])
    return MarginPieces(breaks, pieces)
