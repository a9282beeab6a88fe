"""Constrained leaf morphing in leaf space (Garg & Leow 2011, sec. 6).

A leaf is a point of a *leaf space*: per side the free parameters of eq. 1,

    [θ_b, θ_a, x_w, y_w]  (+ [x_t, y_t, φ_t] with a tail)  (+ [x_s, y_s, φ_s] with a shoulder)

right side first, then left (angles in radians, lengths in leaf lengths). That is 4, 7 or 10
numbers per side, the dimensions the paper gives for the unified spaces; a symmetric leaf simply
has equal halves (the paper's "doubling of the dimensionality" for asymmetric morphing is always
on, so asymmetric sources and targets need nothing special).

Shapes with and without extensions are brought into one space by inserting a tail (shoulder) into
the shapes that lack one (eq. 10): at the margin point whose arc-length ratio to the waist and the
base (apex) equals that of the neighbour's tail, with the margin's own tangent angle φ there.
Inserting a landmark on the curve changes the refitted B-spline slightly; :func:`insertion_error`
measures it. Tails and shoulders spread from shape to shape along the ordered list
source, references..., target exactly as the algorithm of sec. 6.3 describes.

:class:`MorphPath` is the NURBS of eq. 11 over the unified shape vectors: it passes through the
source and target (weights 1, clamped knots) and is pulled towards each reference by its weight.
:class:`KeyframePath` is the linear key-framing the paper compares against. :func:`smoothness`
measures both.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BSpline

from leafview.botany.catalogue import landmark_leaf
from leafview.botany.landmarks import LandmarkLeaf, SideLandmarks, outline, side_fit
from leafview.core.params import ParamError

__all__ = [
    "KeyframePath",
    "LeafSpace",
    "MorphPath",
    "NurbsCurve",
    "arclength_parameter",
    "insertion_error",
    "key_sizes",
    "keyframe_path",
    "leaf_from_vector",
    "leaf_space",
    "leaf_vector",
    "max_step",
    "morph_path",
    "smoothness",
    "unify",
]

_BASE_NAMES = ("theta_b", "theta_a", "waist_x", "waist_y")
_TAIL_NAMES = ("tail_x", "tail_y", "tail_angle")
_SHOULDER_NAMES = ("shoulder_x", "shoulder_y", "shoulder_angle")


@dataclass(frozen=True)
class LeafSpace:
    """Which extension landmarks each side carries, hence the layout of a shape vector."""

    right_tail: bool = False
    right_shoulder: bool = False
    left_tail: bool = False
    left_shoulder: bool = False

    def side_names(self, side: str) -> list[str]:
        tail, shoulder = getattr(self, f"{side}_tail"), getattr(self, f"{side}_shoulder")
        return list(_BASE_NAMES) + (list(_TAIL_NAMES) if tail else []) + (list(_SHOULDER_NAMES) if shoulder else [])

    @property
    def names(self) -> list[str]:
        """Coordinate names, ``right.theta_b`` ... ``left.shoulder_angle``."""
        return [f"{s}.{n}" for s in ("right", "left") for n in self.side_names(s)]

    @property
    def dim(self) -> int:
        return len(self.names)

    def union(self, other: LeafSpace) -> LeafSpace:
        return LeafSpace(*(a or b for a, b in zip(self._flags(), other._flags())))

    def _flags(self) -> tuple[bool, bool, bool, bool]:
        return (self.right_tail, self.right_shoulder, self.left_tail, self.left_shoulder)


def leaf_space(*leaves: LandmarkLeaf) -> LeafSpace:
    """The lowest-dimensional leaf space holding all the given leaves (sec. 6.3)."""
    space = LeafSpace()
    for leaf in leaves:
        space = space.union(LeafSpace(leaf.right.tail is not None, leaf.right.shoulder is not None,
                                      leaf.left.tail is not None, leaf.left.shoulder is not None))
    return space


def _side_vector(side: SideLandmarks, tail: bool, shoulder: bool, where: str) -> list[float]:
    v = [side.theta_b, side.theta_a, *side.waist]
    for present, point, angle, what in ((tail, side.tail, side.tail_angle, "tail"),
                                        (shoulder, side.shoulder, side.shoulder_angle, "shoulder")):
        if present:
            if point is None:
                raise ParamError(f"{where}.{what}", f"the leaf space has a {what} here but the leaf has none: "
                                 "bring the leaves into one space with unify() first")
            v += [*point, angle]
        elif point is not None:
            raise ParamError(f"{where}.{what}", f"the leaf has a {what} but the leaf space has none")
    return v


def leaf_vector(leaf: LandmarkLeaf, space: LeafSpace | None = None) -> NDArray[np.float64]:
    """The shape vector of a leaf in ``space`` (default: the leaf's own, smallest space).

    Raises :class:`ParamError` when the leaf lacks an extension the space has (use :func:`unify`)
    or has one the space lacks.
    """
    space = space or leaf_space(leaf)
    return np.array(_side_vector(leaf.right, space.right_tail, space.right_shoulder, "right")
                    + _side_vector(leaf.left, space.left_tail, space.left_shoulder, "left"))


def leaf_from_vector(vector: ArrayLike, space: LeafSpace, name: str = "") -> LandmarkLeaf:
    """Inverse of :func:`leaf_vector` (validated: a bad vector gives a :class:`ParamError`)."""
    v = np.asarray(vector, dtype=np.float64)
    if v.shape != (space.dim,):
        raise ParamError("vector", f"expected {space.dim} numbers for this leaf space, got shape {v.shape}")
    sides = []
    i = 0
    for which in ("right", "left"):
        # keyword arguments of SideLandmarks: angles (float) and points (pairs of floats)
        kw: dict[str, Any] = {"theta_b": v[i], "theta_a": v[i + 1], "waist": (v[i + 2], v[i + 3])}
        i += 4
        if getattr(space, f"{which}_tail"):
            kw.update(tail=(v[i], v[i + 1]), tail_angle=v[i + 2])
            i += 3
        if getattr(space, f"{which}_shoulder"):
            kw.update(shoulder=(v[i], v[i + 1]), shoulder_angle=v[i + 2])
            i += 3
        try:
            args: dict[str, Any] = {k: (float(x) if np.ndim(x) == 0 else tuple(map(float, x))) for k, x in kw.items()}
            sides.append(SideLandmarks(**args))
        except ParamError as exc:
            raise ParamError(f"{which}.{exc.path}", exc.message) from None
    return LandmarkLeaf(sides[0], sides[1], name)


# ---------------------------------------------------------------------------------------------
# eq. 10: inserting tails and shoulders
# ---------------------------------------------------------------------------------------------

_ARC_SAMPLES = 1024


def _arc_table(spline: BSpline, u0: float, u1: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Parameters and cumulative arc length from u0 to u1 (dense polyline)."""
    u = np.linspace(u0, u1, _ARC_SAMPLES)
    p = np.asarray(spline(u))
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    return u, s


def _extension_ratio(side: SideLandmarks, kind: str) -> float:
    """L(p_ext, p_w) / L(p_ext, p_end) of eq. 10 along the side's margin (end = base or apex)."""
    fit = side_fit(side)
    k = side.waist_index
    if kind == "tail":
        _, to_base = _arc_table(fit.spline, fit.u[0], fit.u[1])
        _, to_waist = _arc_table(fit.spline, fit.u[1], fit.u[k])
        return float(to_waist[-1] / to_base[-1])
    _, to_waist = _arc_table(fit.spline, fit.u[k], fit.u[k + 1])
    _, to_apex = _arc_table(fit.spline, fit.u[k + 1], fit.u[-1])
    return float(to_waist[-1] / to_apex[-1])


def _insert(side: SideLandmarks, kind: str, ratio: float) -> SideLandmarks:
    """Add a tail (between base and waist) or shoulder (between waist and apex) on the margin at
    the point p with L(p, p_w) / L(p, p_end) = ratio (eq. 10), tangent = the margin's there."""
    fit = side_fit(side)
    k = side.waist_index
    if kind == "tail":
        u, s = _arc_table(fit.spline, fit.u[0], fit.u[k])
        target = s[-1] / (1.0 + ratio)          # L(p_b, p)
    else:
        u, s = _arc_table(fit.spline, fit.u[k], fit.u[-1])
        target = s[-1] * ratio / (1.0 + ratio)  # L(p_w, p)
    up = float(np.interp(target, s, u))
    point = tuple(float(c) for c in fit.spline(up))
    d = np.asarray(fit.spline(up, nu=1))
    angle = math.atan2(d[1], d[0])
    if kind == "tail":
        return side.replace(tail=(max(point[0], 0.0), point[1]), tail_angle=angle)
    return side.replace(shoulder=(max(point[0], 0.0), point[1]), shoulder_angle=angle % (2.0 * math.pi))


def unify(leaves: Sequence[LandmarkLeaf]) -> tuple[LeafSpace, list[LandmarkLeaf]]:
    """Map an ordered list of shapes (source, references..., target) into one leaf space (sec. 6.3).

    For each side and each extension kind separately: the shapes that have the landmark hand it to
    their immediate neighbours that lack it (eq. 10, using the giver's arc-length ratio; a shape
    between two givers takes the mean of their ratios), and the new holders hand it on, until
    every shape has it. Shapes that already have it are unchanged.

    Returns
    -------
    (LeafSpace, list of LandmarkLeaf)
        The space and the leaves with inserted landmarks, in the input order.
    """
    out = list(leaves)
    space = leaf_space(*out)
    for which in ("right", "left"):
        for kind in ("tail", "shoulder"):
            if not getattr(space, f"{which}_{kind}"):
                continue
            ratios: dict[int, float] = {i: _extension_ratio(getattr(leaf, which), kind)
                                        for i, leaf in enumerate(out) if getattr(getattr(leaf, which), kind) is not None}
            while len(ratios) < len(out):
                new: dict[int, list[float]] = {}
                for i, r in ratios.items():
                    for j in (i - 1, i + 1):
                        if 0 <= j < len(out) and j not in ratios:
                            new.setdefault(j, []).append(r)
                for j, rs in new.items():
                    ratio = float(np.mean(rs))
                    side = _insert(getattr(out[j], which), kind, ratio)
                    out[j] = out[j].replace(**{which: side})
                    ratios[j] = ratio
    return space, out


def insertion_error(original: LandmarkLeaf, unified: LandmarkLeaf, n: int = 256) -> float:
    """Symmetric Hausdorff distance between the two outlines (leaf lengths): how much inserting a
    landmark on the margin changed the refitted curve."""
    a, b = outline(original, n), outline(unified, n)
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return float(max(d.min(axis=0).max(), d.min(axis=1).max()))


# ---------------------------------------------------------------------------------------------
# eq. 11: the morph path, and linear key-framing
# ---------------------------------------------------------------------------------------------

ArcTable = tuple[NDArray[np.float64], NDArray[np.float64], float]   # (u, arc length at u, total length)


def _arclength_inverse(curve: Callable[[ArrayLike], NDArray[np.float64]], samples: int = 2049) -> ArcTable:
    u = np.linspace(0.0, 1.0, samples)
    p = curve(u)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    return u, s, float(s[-1])


def arclength_parameter(table: ArcTable, t: ArrayLike) -> NDArray[np.float64]:
    """The curve parameter u at arc-length fractions t ∈ [0, 1] of a path, from its table
    ``(u, arc length at u, total)``; t = 0 and 1 map exactly to u = 0 and 1."""
    t = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)
    u, s, total = table
    out = np.interp(t * total, s, u) if total > 0 else t
    return np.where(t <= 0.0, 0.0, np.where(t >= 1.0, 1.0, out))


class NurbsCurve:
    """The rational B-spline of eq. 11 over any key vectors R_0..R_{n+1} (rows of ``vectors``).

    Degree min(2, n + 1) (eq. 11 uses B_{k,2}; two keys give the straight segment), clamped uniform
    knots so that s(0) = R_0 and s(1) = R_{n+1}, weights ``weights`` (w_0 = w_{n+1} = 1 for a morph
    path). Positive weights keep s(u) a convex combination of the R_k. :class:`MorphPath` uses it
    over landmark shape vectors, :mod:`leafview.botany.lobe_morph` over margin control points.
    """

    def __init__(self, vectors: ArrayLike, weights: ArrayLike) -> None:
        r = np.asarray(vectors, dtype=np.float64)
        w = np.asarray(weights, dtype=np.float64)
        if r.ndim != 2 or len(r) < 2 or w.shape != (len(r),):
            raise ValueError(f"need (k >= 2, dim) vectors and k weights, got {r.shape} and {w.shape}")
        m = len(r)
        self.degree = min(2, m - 1)
        inner = np.linspace(0.0, 1.0, m - self.degree + 1)[1:-1]
        self.knots = np.concatenate([np.zeros(self.degree + 1), inner, np.ones(self.degree + 1)])
        self._num = BSpline(self.knots, w[:, None] * r, self.degree)
        self._den = BSpline(self.knots, w, self.degree)

    def __call__(self, u: ArrayLike) -> NDArray[np.float64]:
        u = np.asarray(u, dtype=np.float64)
        return np.asarray(self._num(u)) / np.asarray(self._den(u))[..., None]


@dataclass
class _Path(ABC):
    """Shared sampling of a path in leaf space; subclasses define :meth:`__call__`."""

    space: LeafSpace
    shapes: list[LandmarkLeaf]        # unified: source, references..., target
    originals: list[LandmarkLeaf]
    _table: ArcTable | None = field(default=None, init=False, repr=False)

    @abstractmethod
    def __call__(self, u: ArrayLike) -> NDArray[np.float64]:
        """Points of the path (shape vectors) at curve parameters ``u``."""

    @property
    def vectors(self) -> NDArray[np.float64]:
        """Shape vectors of source, references and target in the unified space."""
        return np.array([leaf_vector(s, self.space) for s in self.shapes])

    @property
    def length(self) -> float:
        """Length of the path in leaf space."""
        return self._arc()[2]

    def _arc(self) -> ArcTable:
        if self._table is None:
            self._table = _arclength_inverse(self)
        return self._table

    def parameter(self, t: ArrayLike, by: str = "arclength") -> NDArray[np.float64]:
        """Curve parameter u for path positions t ∈ [0, 1]: t itself (``by="parameter"``) or the
        u at arc-length fraction t (``"arclength"``, the paper's "regular interval along M")."""
        if by == "parameter":
            return np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)
        if by != "arclength":
            raise ValueError(f"by must be 'arclength' or 'parameter', not {by!r}")
        return arclength_parameter(self._arc(), t)

    @abstractmethod
    def values_at(self, values: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
        """Per-key numbers (one per shape: source, references, target) carried along the path to
        curve parameters ``u`` the way the shapes are: leaf sizes for growth (Figs 12-13)."""

    def frame_vectors(self, frames: int, by: str = "arclength") -> NDArray[np.float64]:
        """``frames`` shape vectors evenly spread along the path (first = source, last = target)."""
        if frames < 2:
            raise ValueError(f"frames must be >= 2, got {frames}")
        return self(self.parameter(np.linspace(0.0, 1.0, frames), by))

    def sample(self, t: float, by: str = "arclength") -> LandmarkLeaf:
        """The leaf at path position t ∈ [0, 1]; t = 0 and t = 1 give the original source and
        target exactly (not their unified copies, which differ by :func:`insertion_error`)."""
        if t <= 0.0:
            return self.originals[0]
        if t >= 1.0:
            return self.originals[-1]
        return leaf_from_vector(self(self.parameter(np.array([t]), by))[0], self.space)

    def frames(self, frames: int, by: str = "arclength") -> list[LandmarkLeaf]:
        vecs = self.frame_vectors(frames, by)
        out = [leaf_from_vector(v, self.space) for v in vecs]
        out[0], out[-1] = self.originals[0], self.originals[-1]
        return out

    def distance_to(self, vector: ArrayLike, samples: int = 4097) -> float:
        """Smallest leaf-space distance from the path to a shape vector."""
        p = self(np.linspace(0.0, 1.0, samples))
        return float(np.linalg.norm(p - np.asarray(vector, dtype=np.float64), axis=1).min())


@dataclass
class MorphPath(_Path):
    """The rational B-spline of eq. 11 over the unified shape vectors R_0..R_{n+1}.

    Degree min(2, n + 1) (eq. 11 uses B_{k,2}; with no reference the path is the straight
    segment), clamped uniform knots so that s(0) = R_0 and s(1) = R_{n+1}, weights w_0 = w_{n+1} = 1.
    Positive weights keep s(u) a convex combination of the R_k, so every frame is a valid leaf.
    """

    weights: NDArray[np.float64] = field(default_factory=lambda: np.ones(0))

    def __post_init__(self) -> None:
        self._curve = NurbsCurve(self.vectors, self.weights)
        self.degree, self.knots = self._curve.degree, self._curve.knots

    def __call__(self, u: ArrayLike) -> NDArray[np.float64]:
        return self._curve(u)

    def values_at(self, values: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
        """Eq. 11 with the path's weights over per-key numbers: a NURBS is variation diminishing,
        so sizes that grow from key to key grow monotonically along the path."""
        v = np.asarray(values, dtype=np.float64).reshape(-1, 1)
        return NurbsCurve(v, self.weights)(u)[..., 0]


@dataclass
class KeyframePath(_Path):
    """Linear key-framing: straight segments through R_0, R_1, ..., R_{n+1}, the key R_k reached at
    u = k / (n + 1) (hard constraints, the comparison method of sec. 6.1 and Fig. 10)."""

    def __call__(self, u: ArrayLike) -> NDArray[np.float64]:
        r = self.vectors
        keys = np.linspace(0.0, 1.0, len(r))
        u = np.asarray(u, dtype=np.float64)
        return np.stack([np.interp(u, keys, r[:, j]) for j in range(r.shape[1])], axis=-1)

    def values_at(self, values: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
        """Per-key numbers interpolated linearly between the keys, like the shapes."""
        v = np.asarray(values, dtype=np.float64).ravel()
        return np.interp(np.asarray(u, dtype=np.float64), np.linspace(0.0, 1.0, len(v)), v)


def _prepare(source: LandmarkLeaf | str, target: LandmarkLeaf | str,
             refs: Sequence[tuple[LandmarkLeaf | str, float]]) -> tuple[list[LandmarkLeaf], NDArray[np.float64]]:

    def as_leaf(x: LandmarkLeaf | str, what: str) -> LandmarkLeaf:
        if isinstance(x, str):
            return landmark_leaf(x)
        if not isinstance(x, LandmarkLeaf):
            raise ParamError(what, f"expected a LandmarkLeaf or catalogue name, got {type(x).__name__}")
        return x

    shapes = [as_leaf(source, "source")]
    weights = [1.0]
    for i, ref in enumerate(refs):
        try:
            leaf, w = ref
        except (TypeError, ValueError):
            raise ParamError(f"refs[{i}]", "expected a (leaf, weight) pair") from None
        if isinstance(w, bool) or not isinstance(w, (int, float)) or not (math.isfinite(w) and w >= 0.0):
            raise ParamError(f"refs[{i}].weight", f"must be a finite number >= 0, got {w!r}")
        if w == 0.0:
            continue  # weight 0: no constraint (Fig. 11, row 1)
        shapes.append(as_leaf(leaf, f"refs[{i}]"))
        weights.append(float(w))
    shapes.append(as_leaf(target, "target"))
    weights.append(1.0)
    return shapes, np.array(weights)


def key_sizes(sizes: Sequence[float], ref_weights: Sequence[float], field_name: str = "sizes"
              ) -> NDArray[np.float64]:
    """Check leaf sizes given per key shape (source, references..., target: Figs 12-13, growth
    with size) and keep those of the shapes on the path (a reference of weight 0 is dropped, so is
    its size). Raises :class:`ParamError` naming ``sizes`` (wrong count) or ``sizes[i]`` (not a
    finite number > 0)."""
    try:
        values = list(sizes)
    except TypeError:
        raise ParamError(field_name, f"expected a sequence of leaf sizes, got {type(sizes).__name__}") from None
    expect = len(ref_weights) + 2
    if len(values) != expect:
        raise ParamError(field_name, f"expected {expect} sizes (source, {len(ref_weights)} reference(s), target), "
                                     f"got {len(values)}")
    out = []
    for i, v in enumerate(values):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(float(v)) and float(v) > 0.0):
            raise ParamError(f"{field_name}[{i}]", f"a leaf size must be a finite number > 0, got {v!r}")
        out.append(float(v))
    keep = [0] + [1 + i for i, w in enumerate(ref_weights) if float(w) != 0.0] + [expect - 1]
    return np.array([out[i] for i in keep])


def morph_path(source: LandmarkLeaf | str, target: LandmarkLeaf | str,
               refs: Sequence[tuple[LandmarkLeaf | str, float]] = ()) -> MorphPath:
    """The morph path of sec. 6.3 from ``source`` to ``target`` pulled towards weighted references.

    Parameters
    ----------
    source, target : LandmarkLeaf or str (catalogue name)
    refs : sequence of (leaf, weight)
        Ordered reference shapes R_1..R_n with weights w_k ≥ 0 (soft constraints; the larger the
        weight, the closer the path passes; 0 drops the reference).

    Returns
    -------
    MorphPath
        ``path(u)`` gives shape vectors, ``path.sample(t)`` / ``path.frames(n)`` leaves, evenly
        spaced along the path by default.
    """
    shapes, weights = _prepare(source, target, refs)
    space, unified = unify(shapes)
    return MorphPath(space, unified, shapes, weights=weights)


def keyframe_path(source: LandmarkLeaf | str, target: LandmarkLeaf | str,
                  refs: Sequence[tuple[LandmarkLeaf | str, float]] = ()) -> KeyframePath:
    """Linear key-framing through the same references (their weights are ignored, except that a
    zero weight drops the reference as in :func:`morph_path`)."""
    shapes, _ = _prepare(source, target, refs)
    space, unified = unify(shapes)
    return KeyframePath(space, unified, shapes)


def max_step(vectors: ArrayLike) -> float:
    """The largest leaf-space distance between consecutive frames."""
    v = np.asarray(vectors, dtype=np.float64)
    return float(np.linalg.norm(np.diff(v, axis=0), axis=1).max())


def smoothness(vectors: ArrayLike) -> dict[str, float]:
    """Smoothness figures of a frame sequence in leaf space.

    Returns
    -------
    dict
        ``max_step`` (largest distance between consecutive frames), ``mean_step``,
        ``step_ratio`` = max / mean (1 for perfectly even steps), ``max_turn`` (largest angle in
        radians between consecutive steps: a kink shows as a jump) and ``max_accel`` (largest
        second difference |v_{i+1} - 2 v_i + v_{i-1}|).
    """
    v = np.asarray(vectors, dtype=np.float64)
    d = np.diff(v, axis=0)
    steps = np.linalg.norm(d, axis=1)
    out = {"max_step": float(steps.max()), "mean_step": float(steps.mean()),
           "step_ratio": float(steps.max() / steps.mean()) if steps.mean() > 0 else 1.0,
           "max_turn": 0.0, "max_accel": 0.0}
    if len(d) >= 2:
        a, b = d[:-1], d[1:]
        na, nb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
        ok = (na > 0) & (nb > 0)
        cos = np.einsum("ij,ij->i", a[ok], b[ok]) / (na[ok] * nb[ok])
        out["max_turn"] = float(np.arccos(np.clip(cos, -1.0, 1.0)).max()) if ok.any() else 0.0
        out["max_accel"] = float(np.linalg.norm(b - a, axis=1).max())
    return out
