"""The landmark leaf model (Garg & Leow 2011, secs 4.1-4.2).

One side of a unilobed leaf is a margin through a few landmark points, each with a unit tangent:

=============  ==================  ===============================================
landmark       point               unit tangent (direction of travel base → apex)
=============  ==================  ===============================================
base           ``(0, 0)``          ``(sin θ_b, cos θ_b)``                   (eq. 1)
tail (opt.)    ``(x_t, y_t)``      ``(cos φ_t, sin φ_t)``, eq. 1: φ_t = 0, i.e. (1, 0)
waist          ``(x_w, y_w)``      ``(0, 1)``                               (eq. 1)
shoulder (opt) ``(x_s, y_s)``      ``(cos φ_s, sin φ_s)``, default φ_s = π, i.e. (-1, 0)
apex           ``(0, 1)``          ``(-sin θ_a, cos θ_a)``                  (eq. 1)
=============  ==================  ===============================================

The tail is the lowest point of a basal extension (cordate base), the shoulder the highest point
of an apical extension (emarginate / obcordate apex); the paper only writes eq. 1 for the tail and
says "other leaf types are defined in a similar manner", so the shoulder tangent (-1, 0) is our
reading. A *drip tip* (sec. 3.1, Fig. 7: "apex shapes initially concave and then convex") is the
shoulder slot used below the apex: :func:`drip_tip` puts an extra margin landmark at the foot of
the tip (y_s = 1 - tip length, a small x_s) whose tangent points almost straight up, slightly in
towards the midrib. The quadratic margin then bends in from the waist (concave) to the foot of the
tip and closes over the slender tip to the apex (convex), the additional landmark the paper says
makes a long drip tip match.

φ_t and φ_s are free only in the unified leaf space of sec. 6.2 (eq. 10), where a tail or
shoulder inserted into a leaf without one sits on its margin with the margin's tangent.

:func:`fit_margin` fits the quadratic B-spline of eqs 2-6 through the landmarks (implemented in
:mod:`leafview.botany.hermite`, re-exported here); the whole leaf is
a :class:`LandmarkLeaf` with separately parameterised right and left sides (asymmetric leaves,
Fig. 6). Coordinates are the leaf space of leafview's Ω model: base at (0, 0), apex at (0, 1),
x across the blade. A side's parameters are always written as if it were the right side (x > 0);
the left side is mirrored (x → -x) when drawn, so a symmetric leaf has ``left == right``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import BSpline

from leafview.botany.hermite import (
    SINGULAR_CONDITION,
    MarginFit,
    MarginPieces,
    chord_parameters,
    fit_margin,
    fit_margin_report,
    hermite_knots,
    margin_pieces,
)
from leafview.core.limits import check_name
from leafview.core.margin import Margin, MarginSide
from leafview.core.params import LeafParams, ParamError

__all__ = [
    "SINGULAR_CONDITION",
    "LandmarkLeaf",
    "MarginFit",
    "SideLandmarks",
    "check_margin",
    "chord_parameters",
    "drip_tip",
    "fit_margin",
    "fit_margin_report",
    "hermite_knots",
    "margin_pieces",
    "margins",
    "margin_params",
    "outline",
    "outline_sides",
    "outlines",
    "outlines_sides",
    "side_fit",
]

# ---------------------------------------------------------------------------------------------
# eq. 1: the free parameters of one side, and a leaf made of two sides
# ---------------------------------------------------------------------------------------------

LANDMARK_LIMIT = 100.0    # |landmark coordinate| in leaf lengths (the midrib runs from 0 to 1)


def _pair(value: Any, path: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ParamError(path, f"expected two numbers [x, y], got {value!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ParamError(path, f"must be finite, got [{x}, {y}]")
    if not (abs(x) <= LANDMARK_LIMIT and abs(y) <= LANDMARK_LIMIT):
        raise ParamError(path, f"must lie within ±{LANDMARK_LIMIT:g} leaf lengths, got [{x:.3g}, {y:.3g}]")
    return (x, y)


def _angle(value: Any, path: str, lo: float, hi: float) -> float:
    try:
        a = float(value)
    except (TypeError, ValueError):
        raise ParamError(path, f"expected a number (radians), got {value!r}") from None
    if not (math.isfinite(a) and lo <= a <= hi):
        raise ParamError(path, f"must lie in [{lo:.4g}, {hi:.4g}] rad, got {a!r}")
    return a


@dataclass(frozen=True)
class SideLandmarks:
    """The free parameters of one side of the margin (eq. 1), written as for the right side.

    Attributes
    ----------
    theta_b, theta_a : float
        Base and apex tangent angles in radians, t_b = (sin θ_b, cos θ_b) and
        t_a = (-sin θ_a, cos θ_a). In [0, π]: below π/2 a plain base/apex, above π/2 the margin
        leaves the base downwards (basal extension) or enters the apex from above (apical one).
    waist : (x_w, y_w)
        The widest point, tangent (0, 1); x_w > 0 and 0 < y_w < 1.
    tail : (x_t, y_t) or None
        Basal extension landmark (between base and waist along the margin), tangent angle
        ``tail_angle`` (0 = the (1, 0) of eq. 1).
    shoulder : (x_s, y_s) or None
        Apical extension landmark (between waist and apex), tangent angle ``shoulder_angle``
        (π = (-1, 0)).
    """

    theta_b: float
    theta_a: float
    waist: tuple[float, float]
    tail: tuple[float, float] | None = None
    shoulder: tuple[float, float] | None = None
    tail_angle: float = 0.0
    shoulder_angle: float = math.pi

    def __post_init__(self) -> None:
        self.validated("")

    def validated(self, prefix: str) -> SideLandmarks:
        """Check every field; errors name the field as ``prefix + name``."""
        object.__setattr__(self, "theta_b", _angle(self.theta_b, prefix + "theta_b", 0.0, math.pi))
        object.__setattr__(self, "theta_a", _angle(self.theta_a, prefix + "theta_a", 0.0, math.pi))
        xw, yw = _pair(self.waist, prefix + "waist")
        if not xw > 0.0:
            raise ParamError(prefix + "waist[0]", f"the waist half-width x_w must be > 0, got {xw}")
        if not 0.0 < yw < 1.0:
            raise ParamError(prefix + "waist[1]", f"the waist must lie between base and apex (0 < y_w < 1), got {yw}")
        object.__setattr__(self, "waist", (xw, yw))
        if self.tail is not None:
            xt, yt = _pair(self.tail, prefix + "tail")
            if xt < 0.0:
                raise ParamError(prefix + "tail[0]", f"must be >= 0 (the side's own half), got {xt}")
            object.__setattr__(self, "tail", (xt, yt))
        if self.shoulder is not None:
            xs, ys = _pair(self.shoulder, prefix + "shoulder")
            if xs < 0.0:
                raise ParamError(prefix + "shoulder[0]", f"must be >= 0 (the side's own half), got {xs}")
            object.__setattr__(self, "shoulder", (xs, ys))
        object.__setattr__(self, "tail_angle", _angle(self.tail_angle, prefix + "tail_angle", -math.pi, math.pi))
        object.__setattr__(self, "shoulder_angle",
                           _angle(self.shoulder_angle, prefix + "shoulder_angle", 0.0, 2.0 * math.pi))
        return self

    # -- landmarks of eq. 1 -------------------------------------------------------------------
    def landmarks(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Points and unit tangents in margin order: base, [tail], waist, [shoulder], apex."""
        pts = [(0.0, 0.0)]
        tan = [(math.sin(self.theta_b), math.cos(self.theta_b))]
        if self.tail is not None:
            pts.append(self.tail)
            tan.append((math.cos(self.tail_angle), math.sin(self.tail_angle)))
        pts.append(self.waist)
        tan.append((0.0, 1.0))
        if self.shoulder is not None:
            pts.append(self.shoulder)
            tan.append((math.cos(self.shoulder_angle), math.sin(self.shoulder_angle)))
        pts.append((0.0, 1.0))
        tan.append((-math.sin(self.theta_a), math.cos(self.theta_a)))
        return np.array(pts, dtype=np.float64), np.array(tan, dtype=np.float64)

    @property
    def basal_extension(self) -> bool:
        """A tail below the base (y_t < 0): a true basal extension, not just an extra margin point."""
        return self.tail is not None and self.tail[1] < 0.0

    @property
    def apical_extension(self) -> bool:
        """A shoulder above the apex (y_s > 1)."""
        return self.shoulder is not None and self.shoulder[1] > 1.0

    @property
    def drip_tip(self) -> bool:
        """A shoulder below the apex, close to the midrib, entered almost straight up: the foot of a
        drip tip (:func:`drip_tip`), not an apical extension nor an oblong side's parallel end."""
        if self.shoulder is None:
            return False
        xs, ys = self.shoulder
        return ys < 1.0 and xs < self.waist[0] / 3.0 and math.pi / 2.0 < self.shoulder_angle <= 0.75 * math.pi

    @property
    def waist_index(self) -> int:
        """Index of the waist in :meth:`landmarks`."""
        return 2 if self.tail is not None else 1

    def replace(self, **changes: Any) -> SideLandmarks:
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain TOML/JSON-able dict (angles in degrees, which people read more easily)."""
        d: dict[str, Any] = {"theta_b": math.degrees(self.theta_b), "theta_a": math.degrees(self.theta_a),
                             "waist": list(self.waist)}
        if self.tail is not None:
            d["tail"] = list(self.tail)
            if self.tail_angle != 0.0:
                d["tail_angle"] = math.degrees(self.tail_angle)
        if self.shoulder is not None:
            d["shoulder"] = list(self.shoulder)
            if self.shoulder_angle != math.pi:
                d["shoulder_angle"] = math.degrees(self.shoulder_angle)
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], prefix: str = "") -> SideLandmarks:
        """Inverse of :meth:`to_dict` (angles in degrees); unknown keys are errors."""
        if not isinstance(data, Mapping):
            raise ParamError(prefix.rstrip("."), f"expected a table, got {type(data).__name__}")
        known = {"theta_b", "theta_a", "waist", "tail", "shoulder", "tail_angle", "shoulder_angle"}
        for key in data:
            if key not in known:
                raise ParamError(prefix + str(key), f"unknown key (expected one of {', '.join(sorted(known))})")
        for key in ("theta_b", "theta_a", "waist"):
            if key not in data:
                raise ParamError(prefix + key, "missing")

        def deg(key: str, default: float) -> float:
            if key not in data:
                return default
            v = data[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ParamError(prefix + key, f"expected a number of degrees, got {v!r}")
            return math.radians(float(v))

        side = object.__new__(cls)
        for name, value in (("theta_b", deg("theta_b", 0.0)), ("theta_a", deg("theta_a", 0.0)),
                            ("waist", data["waist"]), ("tail", data.get("tail")), ("shoulder", data.get("shoulder")),
                            ("tail_angle", deg("tail_angle", 0.0)), ("shoulder_angle", deg("shoulder_angle", math.pi))):
            object.__setattr__(side, name, value)
        return side.validated(prefix)


@dataclass(frozen=True)
class LandmarkLeaf:
    """A unilobed leaf: right and left :class:`SideLandmarks` (Fig. 6: they may differ)."""

    right: SideLandmarks
    left: SideLandmarks
    name: str = ""

    def __post_init__(self) -> None:
        for side in ("right", "left"):
            if not isinstance(getattr(self, side), SideLandmarks):
                raise ParamError(side, f"expected SideLandmarks, got {type(getattr(self, side)).__name__}")

    @classmethod
    def symmetric(cls, side: SideLandmarks, name: str = "") -> LandmarkLeaf:
        return cls(side, side, name)

    @property
    def is_symmetric(self) -> bool:
        return self.right == self.left

    @property
    def has_tail(self) -> bool:
        """Some side has a tail landmark (a basal extension, or an extra margin point: oblong)."""
        return self.right.tail is not None or self.left.tail is not None

    @property
    def has_shoulder(self) -> bool:
        return self.right.shoulder is not None or self.left.shoulder is not None

    @property
    def has_basal_extension(self) -> bool:
        """Some side reaches below the base (a tail with y < 0; cordate, reniform)."""
        return self.right.basal_extension or self.left.basal_extension

    @property
    def has_apical_extension(self) -> bool:
        """Some side reaches above the apex (a shoulder with y > 1; obcordate)."""
        return self.right.apical_extension or self.left.apical_extension

    def replace(self, **changes: Any) -> LandmarkLeaf:
        return replace(self, **changes)

    def mirrored(self) -> LandmarkLeaf:
        """The same leaf seen from the other face (left and right swapped)."""
        return LandmarkLeaf(self.left, self.right, self.name)

    def to_dict(self) -> dict[str, Any]:
        """``{landmarks = 1, name, right = {...}, left = {...}}``; ``left`` is left out when it
        equals ``right``."""
        d: dict[str, Any] = {"landmarks": 1}
        if self.name:
            d["name"] = self.name
        d["right"] = self.right.to_dict()
        if not self.is_symmetric:
            d["left"] = self.left.to_dict()
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LandmarkLeaf:
        """Read ``{landmarks = 1, name?, right = {...}, left = {...}}``; a missing ``left`` copies
        ``right`` (a symmetric leaf)."""
        if not isinstance(data, Mapping):
            raise ParamError("", f"expected a table, got {type(data).__name__}")
        for key in data:
            if key not in ("landmarks", "name", "right", "left"):
                raise ParamError(str(key), "unknown key (expected landmarks, name, right, left)")
        if data.get("landmarks") != 1:
            raise ParamError("landmarks", f"expected landmarks = 1 (format version), got {data.get('landmarks')!r}")
        if "right" not in data:
            raise ParamError("right", "missing: the right side's landmarks")
        right = SideLandmarks.from_dict(data["right"], "right.")
        left = SideLandmarks.from_dict(data["left"], "left.") if "left" in data else right
        name = check_name(data.get("name", ""), "name")
        return cls(right, left, name)


DRIP_LEAN = 0.5      # the tip-foot tangent leans in by this share of the tip's half-angle
DRIP_APEX = 1.6      # the apex tangent angle θ_a, in tip half-angles (> 1: a pointed, convex tip end)


def drip_tip(length: float, half_width: float, waist: tuple[float, float] = (1.0, 0.0)
             ) -> tuple[tuple[float, float], float, float]:
    """The landmarks of a drip tip (Garg & Leow 2011, sec. 3.1, Fig. 7): ``(shoulder,
    shoulder_angle, theta_a)`` for a :class:`SideLandmarks`.

    The tip is ``length`` long (from y = 1 - length to the apex) and ``half_width`` wide at its
    foot. With the tip's half-angle γ = atan(half_width / length), the foot landmark's tangent leans
    in by :data:`DRIP_LEAN` γ from (0, 1) and the apex tangent angle is θ_a = :data:`DRIP_APEX` γ:
    walking up the right side the margin turns right between the waist and the foot (concave),
    then left over the tip (convex), and ends in a point. Our construction; the paper shows
    pictures only.

    Parameters
    ----------
    length : float
        Tip length in leaf lengths, 0 < length < 1 - y_w.
    half_width : float
        Half-width at the foot of the tip, 0 < half_width < x_w / 3.
    waist : (x_w, y_w)
        The side's waist, for the range checks.
    """
    xw, yw = waist
    length = float(length)
    half_width = float(half_width)
    if not (math.isfinite(length) and 0.0 < length < 1.0 - yw):
        raise ParamError("drip", f"the tip length must lie in (0, 1 - y_w) = (0, {1.0 - yw:.3g}), got {length!r}")
    if not (math.isfinite(half_width) and 0.0 < half_width < xw / 3.0):
        raise ParamError("tip_width", f"the tip's half-width must lie in (0, x_w / 3) = (0, {xw / 3.0:.3g}), "
                         f"got {half_width!r}")
    gamma = math.atan2(half_width, length)
    return (half_width, 1.0 - length), math.pi / 2.0 + DRIP_LEAN * gamma, DRIP_APEX * gamma


# ---------------------------------------------------------------------------------------------
# margins in leaf space
# ---------------------------------------------------------------------------------------------

def side_fit(side: SideLandmarks) -> MarginFit:
    """The fitted B-spline of one side, in its own (right-side) frame, base at u = 0."""
    pts, tan = side.landmarks()
    return fit_margin_report(pts, tan)


def _sample(spline: BSpline, n: int, spacing: str) -> NDArray[np.float64]:
    if spacing == "parameter":
        return np.asarray(spline(np.linspace(0.0, 1.0, n)))
    if spacing != "arclength":
        raise ValueError(f"spacing must be 'arclength' or 'parameter', not {spacing!r}")
    dense_u = np.linspace(0.0, 1.0, max(8 * n, 512))
    dense = np.asarray(spline(dense_u))
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))])
    u = np.interp(np.linspace(0.0, s[-1], n), s, dense_u)
    u[0], u[-1] = 0.0, 1.0
    return np.asarray(spline(u))


def outline_sides(leaf: LandmarkLeaf, n: int = 128, *, spacing: str = "arclength"
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The two margins of a leaf in leaf space, each (n, 2) from the base (0, 0) to the apex (0, 1).

    The right side is drawn as fitted (x ≥ 0 on a plain blade); the left one is mirrored to x ≤ 0.
    Points are evenly spaced along the curve (``spacing="arclength"``) or in the B-spline
    parameter (``"parameter"``). The first row is exactly (0, 0), the last exactly (0, 1).
    """
    if n < 2:
        raise ValueError(f"n must be >= 2, got {n}")
    right = _sample(side_fit(leaf.right).spline, n, spacing)
    left = _sample(side_fit(leaf.left).spline, n, spacing) * np.array([-1.0, 1.0])
    for side in (right, left):
        side[0] = (0.0, 0.0)
        side[-1] = (0.0, 1.0)
    return right, left


def outline(leaf: LandmarkLeaf, n: int = 128, *, spacing: str = "arclength") -> NDArray[np.float64]:
    """The closed margin polyline, (2n - 2, 2), counter-clockwise, starting at the base.

    Rows 0..n-1 are the right side from the base (0, 0) up to the apex (0, 1) (row n - 1); then
    the left side comes back down, its apex and base rows dropped, so the closing segment from the
    last row back to row 0 is implied (the first point is not repeated). Basal extensions reach
    below y = 0 and apical ones above y = 1; base and apex stay exactly at (0, 0) and (0, 1).
    """
    right, left = outline_sides(leaf, n, spacing=spacing)
    return np.concatenate([right, left[-2:0:-1]])


def _arclength_parameters(margins: MarginPieces, n: int) -> NDArray[np.float64]:
    """(B, n) parameters evenly spaced in arc length along each margin, as :func:`_sample` finds
    them (the chord lengths of max(8n, 512) even parameter steps, inverted by interpolation)."""
    b = len(margins.breaks)
    dense_u = np.linspace(0.0, 1.0, max(8 * n, 512))
    dense = margins(dense_u)
    s = np.concatenate([np.zeros((b, 1)), np.cumsum(np.linalg.norm(np.diff(dense, axis=1), axis=2), axis=1)], axis=1)
    lane = 2.0 * np.arange(b)[:, None]          # row k lives in [2k, 2k + 1]: one global interpolation
    xp = (s / np.where(s[:, -1:] > 0.0, s[:, -1:], 1.0) + lane).ravel()
    u = np.interp((np.linspace(0.0, 1.0, n)[None, :] + lane).ravel(), xp, np.tile(dense_u, b)).reshape(b, n)
    u[:, 0], u[:, -1] = 0.0, 1.0
    return u


def _side_groups(leaves: Sequence[LandmarkLeaf]) -> tuple[NDArray[np.int64], list[tuple[list[int], MarginPieces]]]:
    """The distinct sides of ``leaves`` (a symmetric leaf's two sides are one object, built once):
    ``rows`` (B, 2), each leaf's right and left side index, and per landmark count the side
    indices and their margins, built together in closed form (:func:`margin_pieces`)."""
    sides: list[SideLandmarks] = []
    index: dict[int, int] = {}                  # id of a side -> its row
    rows = np.empty((len(leaves), 2), dtype=np.int64)
    for k, leaf in enumerate(leaves):
        if not isinstance(leaf, LandmarkLeaf):
            raise ParamError(f"leaves[{k}]", f"expected a LandmarkLeaf, got {type(leaf).__name__}")
        for j, side in enumerate((leaf.right, leaf.left)):
            row = index.get(id(side))
            if row is None:
                row = index[id(side)] = len(sides)
                sides.append(side)
            rows[k, j] = row
    marks = [side.landmarks() for side in sides]
    by_count: dict[int, list[int]] = {}
    for i, (pts, _) in enumerate(marks):
        by_count.setdefault(len(pts), []).append(i)
    return rows, [(group, margin_pieces(np.stack([marks[i][0] for i in group]), np.stack([marks[i][1] for i in group])))
                  for group in by_count.values()]


def outlines_sides(leaves: Sequence[LandmarkLeaf], n: int = 128, *, spacing: str = "arclength"
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`outline_sides` of many leaves at once: ``(right, left)``, each (B, n, 2).

    The margins of all sides with the same number of landmarks are built together in closed form
    (:func:`~leafview.botany.hermite.margin_pieces`) and sampled together, so a batch costs a few
    array operations per landmark count instead of a spline fit and two spline evaluations per
    side. The result equals :func:`outline_sides` leaf by leaf to rounding."""
    if n < 2:
        raise ValueError(f"n must be >= 2, got {n}")
    if spacing not in ("arclength", "parameter"):
        raise ValueError(f"spacing must be 'arclength' or 'parameter', not {spacing!r}")
    rows, groups = _side_groups(leaves)
    out = np.empty((int(rows.max(initial=-1)) + 1, n, 2))
    for group, margins in groups:
        u = _arclength_parameters(margins, n) if spacing == "arclength" else np.linspace(0.0, 1.0, n)
        out[group] = margins(u)
    out[:, 0], out[:, -1] = (0.0, 0.0), (0.0, 1.0)
    return out[rows[:, 0]], out[rows[:, 1]] * np.array([-1.0, 1.0])


def outlines(leaves: Sequence[LandmarkLeaf], n: int = 128, *, spacing: str = "arclength") -> NDArray[np.float64]:
    """:func:`outline` of many leaves at once, (B, 2n - 2, 2) (see :func:`outlines_sides`)."""
    right, left = outlines_sides(leaves, n, spacing=spacing)
    return np.concatenate([right, left[:, -2:0:-1]], axis=1)


def _self_crossing(poly: NDArray[np.float64]) -> int | None:
    """Index of a segment that properly crosses a non-adjacent one, or None."""
    a, b = poly[:-1], poly[1:]

    def orient(p: NDArray[np.float64], q: NDArray[np.float64], r: NDArray[np.float64]) -> NDArray[np.float64]:
        # sign of the turn p -> q -> r, broadcast over pairs
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    A, B = a[:, None], b[:, None]
    C, D = a[None, :], b[None, :]
    hit = (orient(A, B, C) * orient(A, B, D) < 0) & (orient(C, D, A) * orient(C, D, B) < 0)
    i, _ = np.nonzero(np.triu(hit, k=2))
    return int(i[0]) if len(i) else None


def check_margin(leaf: LandmarkLeaf, n: int = 200) -> None:
    """Reject landmarks whose margin is not a simple blade outline.

    Raises :class:`ParamError` naming the side when a side's margin crosses the midrib (x < 0
    between base and apex, so the two sides would overlap) or crosses itself (a loop, e.g. from a
    tail tangent that points back). Valid catalogue shapes, their random instances and morph frames
    pass; files loaded by :func:`leafview.botany.catalogue.load_landmark_leaf` are checked with it.
    """
    for which in ("right", "left"):
        side = getattr(leaf, which)
        poly = _sample(side_fit(side).spline, n, "arclength")
        inner = poly[1:-1, 0]
        if inner.min() < -1e-9:
            y = float(poly[1 + int(np.argmin(inner)), 1])
            raise ParamError(which, f"the margin crosses the midrib (x < 0) near y = {y:.3f}: "
                             "check theta_b / theta_a and the tail or shoulder")
        k = _self_crossing(poly)
        if k is not None:
            raise ParamError(which, f"the margin crosses itself near ({poly[k, 0]:.3f}, {poly[k, 1]:.3f}): "
                             "check the tangent angles of the tail or shoulder")


# ---------------------------------------------------------------------------------------------
# margins drawn as they are: the shader's landmark-margin silhouette (leafview.core.margin)
# ---------------------------------------------------------------------------------------------

def _side_margin(breaks: NDArray[np.float64], pieces: NDArray[np.float64]) -> MarginSide:
    """A :class:`~leafview.core.margin.MarginSide` from one side's Bézier spans (as
    :class:`~leafview.botany.hermite.MarginPieces` holds them): the landmark knots and, per gap,
    the landmark, the two inner points and (last) the apex."""
    gaps = pieces.shape[0] // 2
    pts = np.empty((3 * gaps + 1, 2))
    pts[0:3 * gaps:3] = pieces[0::2, 0]
    pts[1:3 * gaps:3] = pieces[0::2, 1]
    pts[2:3 * gaps:3] = pieces[1::2, 1]
    pts[-1] = pieces[-1, 2]
    pts[0], pts[-1] = (0.0, 0.0), (0.0, 1.0)
    return MarginSide(tuple(float(k) for k in breaks[0::2]), tuple((float(x), float(y)) for x, y in pts))


def margins(leaves: Sequence[LandmarkLeaf]) -> list[Margin]:
    """The margins of eqs 2-6 of many leaves, as the shader draws them (no Ω fit): sides with the
    same number of landmarks are built together in closed form
    (:func:`~leafview.botany.hermite.margin_pieces`)."""
    rows, groups = _side_groups(leaves)
    built: list[MarginSide | None] = [None] * (int(rows.max(initial=-1)) + 1)
    for group, mp in groups:
        for j, i in enumerate(group):
            built[i] = _side_margin(mp.breaks[j], mp.pieces[j])
    out = []
    for r, lft in rows:
        right, left = built[r], built[lft]
        assert right is not None and left is not None
        out.append(Margin(right, left))
    return out


def margin_params(leaves: Sequence[LandmarkLeaf], template: LeafParams | None = None) -> list[LeafParams]:
    """Leaves drawn with their landmark margins (:func:`margins`): ``template`` (default
    :class:`~leafview.core.params.LeafParams`: a straight midrib, flat, default colours) with each
    margin and the landmark leaf's name. The template's silhouette rows are not used; its midrib,
    heights, material, jitter, ripples and bending are."""
    base = LeafParams() if template is None else template
    return [replace(base, margin=m, name=leaf.name or base.name) for leaf, m in zip(leaves, margins(leaves))]
