"""The botanical catalogue of unilobed leaf shapes (Garg & Leow 2011, Table 1, Figs 4-6 and 8).

A shape type is a waist type (where the blade is widest: elliptic = middle, ovate = low,
obovate = high, oblong = parallel-sided middle, linear = width < 1/10 of length) combined with a
base type and an apex type (concave, straight, convex, or with a basal/apical extension). Table 1
counts 3 × 4 × 4 = 48 such types plus one oblong and one linear: 50. Fig. 5 adds 14 names
botanists use (elliptic, lanceolate, ...); oblong and linear are both a Table 1 type and a Fig. 5
name, so the Table 1 and Fig. 5 shapes are 50 + 12 = 62 entries; two drip-tip shapes of Fig. 7
(``ovate-drip``, ``elliptic-drip``) make :func:`catalogue` 64.

How a type becomes landmarks (our construction; the paper shows pictures, not numbers):

* ``straight`` base: θ_b is chosen so that the first span of the quadratic B-spline (from the base
  to the first knot) is a straight segment. With the tangent handles of
  :func:`~leafview.botany.landmarks.fit_margin` this is t_b ∥ (x_w, y_w - c/4), c = |p_w - p_b|,
  in closed form. ``concave`` turns that angle towards the midrib, θ_b = θ_s (1 - a), so the margin
  first hugs the vein (negative curvature); ``convex`` opens it, θ_b = θ_s + a (π/2 - θ_s), so the
  margin bulges out (positive curvature). The apex is the mirror image with t_a ∥ (-x_w, 1 - y_w - c/4).
* ``extended`` base: a tail landmark below the base (y_t < 0) and θ_b > π/2 (the margin leaves the
  base downwards); ``extended`` apex: a shoulder above the apex (y_s > 1) and θ_a > π/2.
* ``drip`` apex (Fig. 7, sec. 3.1: "initially concave and then convex"): an extra margin
  landmark at the foot of a long slender tip, in the shoulder slot below the apex
  (:func:`~leafview.botany.landmarks.drip_tip`; recipe values ``drip`` = tip length and
  ``tip_width`` = half-width at its foot).
* ``oblong``: parallel sides over the middle fifth and more need two extra margin landmarks with
  tangent (0, 1) (see :func:`_parallel_side`); ``linear``: full width 0.08 of the length.

Curvature signs are for the right side traversed from base to apex (counter-clockwise round the
blade): convex > 0, concave < 0.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from leafview.atomic import atomic_output
from leafview.botany.landmarks import (
    LandmarkLeaf,
    SideLandmarks,
    check_margin,
    drip_tip,
    outline,
    outline_sides,
)
from leafview.core.io import read_document
from leafview.core.params import ParamError

__all__ = [
    "APEX_TYPES",
    "MARGIN_TYPES",
    "WAIST_TYPES",
    "ShapeEntry",
    "catalogue",
    "catalogue_names",
    "combine_sides",
    "dumps_landmark_leaf",
    "entry",
    "landmark_leaf",
    "load_landmark_leaf",
    "outline",
    "outline_sides",
    "random_instance",
    "save_landmark_leaf",
    "straight_apex_angle",
    "straight_base_angle",
]

WAIST_TYPES = ("elliptic", "ovate", "obovate", "oblong", "linear")
MARGIN_TYPES = ("concave", "straight", "convex", "extended")
APEX_TYPES = MARGIN_TYPES + ("drip",)


@dataclass(frozen=True)
class ShapeEntry:
    """One catalogue shape: its botanical type and the recipe that builds its landmarks.

    Attributes
    ----------
    name : str
        ``"elliptic-concave-convex"`` for the 48 waist × base × apex types of Fig. 4, else the
        botanical name (``"cordate"``).
    waist, base, apex : str
        Waist type (:data:`WAIST_TYPES`), base type (:data:`MARGIN_TYPES`) and apex type
        (:data:`APEX_TYPES`: the margin types or ``"drip"``).
    unilobed : bool
        Always True here (multilobed leaves are built from these, sec. 5).
    table1 : bool
        One of the 50 types counted in Table 1.
    named : bool
        A named shape of Fig. 5.
    figure : str
        Where the paper shows it.
    half_width, waist_y : float
        The waist landmark (x_w, y_w) of eq. 1.
    base_amount, apex_amount : float
        How concave / convex (0..1, see the module docstring); ignored for straight and extended.
    tail, shoulder : (x, y) or None
        Extension landmarks; with them ``theta_b`` / ``theta_a`` (degrees) give the base / apex
        tangent angles.
    parallel : float
        Oblong only: the margin runs straight up at x = x_w from y_w - parallel to
        y_w + parallel (see :func:`_parallel_side`).
    drip, tip_width : float
        Drip apex only: the tip's length and its half-width at the foot, in leaf lengths
        (:func:`~leafview.botany.landmarks.drip_tip`).
    """

    name: str
    waist: str
    base: str
    apex: str
    unilobed: bool = True
    table1: bool = False
    named: bool = False
    figure: str = ""
    half_width: float = 0.25
    waist_y: float = 0.5
    base_amount: float = 0.6
    apex_amount: float = 0.6
    tail: tuple[float, float] | None = None
    shoulder: tuple[float, float] | None = None
    theta_b: float = 150.0
    theta_a: float = 150.0
    parallel: float = 0.0
    drip: float = 0.25
    tip_width: float = 0.03

    def side(self) -> SideLandmarks:
        """The right side's landmarks (eq. 1) for this recipe."""
        if self.apex == "drip":
            return _drip_side(self.half_width, self.waist_y, self.base, self.base_amount, self.drip, self.tip_width)
        if self.parallel > 0.0:
            return _parallel_side(self.half_width, self.waist_y, self.parallel, self.base, self.apex,
                                  self.base_amount, self.apex_amount)
        return _side_from_recipe(self.half_width, self.waist_y, self.base, self.apex, self.base_amount,
                                 self.apex_amount, self.tail, self.shoulder, self.theta_b, self.theta_a)


def straight_base_angle(x_w: float, y_w: float) -> float:
    """θ_b that makes the first B-spline span straight for a base → waist margin (radians)."""
    c = math.hypot(x_w, y_w)
    return math.atan2(x_w, y_w - c / 4.0)


def straight_apex_angle(x_w: float, y_w: float) -> float:
    """θ_a that makes the last B-spline span straight for a waist → apex margin (radians)."""
    c = math.hypot(x_w, 1.0 - y_w)
    return math.atan2(x_w, 1.0 - y_w - c / 4.0)


def _shaped_angle(straight: float, kind: str, amount: float) -> float:
    if kind == "straight":
        return straight
    if kind == "concave":
        return straight * (1.0 - amount)
    if kind == "convex":
        return straight + amount * (math.pi / 2.0 - straight)
    raise ParamError("base", f"unknown margin type {kind!r}")


def _extension_x(x_w: float, rise: float) -> float:
    """Default x of a tail or shoulder that keeps the waist the widest point.

    Between the extension point (tangent ±x) and the waist (tangent +y) the B-spline stays inside
    x ≤ max(x_ext + c/4, x_w), c = chord to the waist (the handle of eq. 4 with α = D), so the
    extension is placed at x = min(x_w / 2, 0.95 (x_w - c/4)); ``rise`` is its height difference
    to the waist.
    """
    x = 0.5 * x_w
    for _ in range(20):  # fixed point: c depends (weakly) on x
        x = min(0.5 * x_w, 0.95 * (x_w - math.hypot(x_w - x, rise) / 4.0))
    return max(x, 0.0)


def _side_from_recipe(x_w: float, y_w: float, base: str, apex: str, base_amount: float, apex_amount: float,
                      tail: tuple[float, float] | None, shoulder: tuple[float, float] | None,
                      theta_b_deg: float, theta_a_deg: float) -> SideLandmarks:
    if base == "extended":
        if tail is None:
            tail = (_extension_x(x_w, y_w + 0.1), -0.1)
        theta_b = math.radians(theta_b_deg)
    else:
        tail = None
        theta_b = _shaped_angle(straight_base_angle(x_w, y_w), base, base_amount)
    if apex == "extended":
        if shoulder is None:
            shoulder = (_extension_x(x_w, 1.1 - y_w), 1.1)
        theta_a = math.radians(theta_a_deg)
    else:
        shoulder = None
        theta_a = _shaped_angle(straight_apex_angle(x_w, y_w), apex, apex_amount)
    return SideLandmarks(theta_b, theta_a, (x_w, y_w), tail=tail, shoulder=shoulder)


def _drip_side(x_w: float, y_w: float, base: str, base_amount: float, length: float,
               half_width: float) -> SideLandmarks:
    """A side ending in a drip tip (Fig. 7): the base as for the other types, then the foot of
    the tip in the shoulder slot and the apex angle of :func:`~leafview.botany.landmarks.drip_tip`."""
    shoulder, angle, theta_a = drip_tip(length, half_width, (x_w, y_w))
    theta_b = _shaped_angle(straight_base_angle(x_w, y_w), base, base_amount)
    return SideLandmarks(theta_b, theta_a, (x_w, y_w), shoulder=shoulder, shoulder_angle=angle)


def _parallel_side(x_w: float, y_w: float, half: float, base: str, apex: str, base_amount: float,
                   apex_amount: float) -> SideLandmarks:
    """An oblong side: parallel to the midrib over y_w ± half.

    One waist landmark cannot make the sides parallel (the quadratic bends away right after it),
    so the two ends of the parallel part are extra margin landmarks with tangent (0, 1), stored in
    the tail and shoulder slots (``tail_angle = shoulder_angle = π/2``; they are ordinary margin
    points of the unified leaf space of sec. 6.2, not extensions). Three landmarks on one vertical
    line with vertical tangents make both spans between them exactly straight.
    """
    lo, hi = (x_w, y_w - half), (x_w, y_w + half)
    theta_b = _shaped_angle(straight_base_angle(*lo), base, base_amount)
    theta_a = _shaped_angle(straight_apex_angle(*hi), apex, apex_amount)
    return SideLandmarks(theta_b, theta_a, (x_w, y_w), tail=lo, shoulder=hi,
                         tail_angle=math.pi / 2.0, shoulder_angle=math.pi / 2.0)


# ---------------------------------------------------------------------------------------------
# the catalogue
# ---------------------------------------------------------------------------------------------

_TYPE_WAIST = {"elliptic": (0.25, 0.5), "ovate": (0.28, 0.32), "obovate": (0.28, 0.68)}

_NAMED: tuple[ShapeEntry, ...] = (
    ShapeEntry("elliptic", "elliptic", "convex", "convex", named=True, figure="Fig. 5(a)",
               half_width=0.25, waist_y=0.5, base_amount=0.55, apex_amount=0.55),
    ShapeEntry("lanceolate", "ovate", "convex", "straight", named=True, figure="Fig. 5(b)",
               half_width=0.11, waist_y=0.33, base_amount=0.5),
    ShapeEntry("oblanceolate", "obovate", "straight", "convex", named=True, figure="Fig. 5(c)",
               half_width=0.11, waist_y=0.67, apex_amount=0.5),
    ShapeEntry("rhomboidal", "elliptic", "straight", "straight", named=True, figure="Fig. 5(d)",
               half_width=0.3, waist_y=0.5),
    ShapeEntry("deltoid", "ovate", "convex", "straight", named=True, figure="Fig. 5(e)",
               half_width=0.42, waist_y=0.14, base_amount=0.85),
    ShapeEntry("linear", "linear", "straight", "straight", table1=True, named=True, figure="Fig. 5(f)",
               half_width=0.04, waist_y=0.5),
    ShapeEntry("oval", "elliptic", "convex", "convex", named=True, figure="Fig. 5(g)",
               half_width=0.34, waist_y=0.5, base_amount=0.75, apex_amount=0.75),
    ShapeEntry("ovate", "ovate", "convex", "convex", named=True, figure="Fig. 5(h)",
               half_width=0.3, waist_y=0.36, base_amount=0.6, apex_amount=0.2),
    ShapeEntry("obovate", "obovate", "convex", "convex", named=True, figure="Fig. 5(i)",
               half_width=0.3, waist_y=0.64, base_amount=0.2, apex_amount=0.6),
    ShapeEntry("orbicular", "elliptic", "convex", "convex", named=True, figure="Fig. 5(j)",
               half_width=0.5, waist_y=0.5, base_amount=1.0, apex_amount=1.0),
    ShapeEntry("oblong", "oblong", "convex", "convex", table1=True, named=True, figure="Fig. 5(k)",
               half_width=0.24, waist_y=0.5, base_amount=0.75, apex_amount=0.75, parallel=0.2),
    ShapeEntry("cordate", "ovate", "extended", "straight", named=True, figure="Fig. 5(l)",
               half_width=0.36, waist_y=0.36, tail=(0.2, -0.1), theta_b=155.0),
    ShapeEntry("obcordate", "obovate", "straight", "extended", named=True, figure="Fig. 5(m)",
               half_width=0.36, waist_y=0.64, shoulder=(0.2, 1.1), theta_a=155.0),
    ShapeEntry("reniform", "elliptic", "extended", "convex", named=True, figure="Fig. 5(n)",
               half_width=0.62, waist_y=0.45, tail=(0.32, -0.2), theta_b=165.0, apex_amount=0.95),
)

# Fig. 7 (top row): leaves with drip tips (Ficus religiosa-like ovate, and an elliptic one).
_DRIP: tuple[ShapeEntry, ...] = (
    ShapeEntry("ovate-drip", "ovate", "convex", "drip", figure="Fig. 7 (top)",
               half_width=0.3, waist_y=0.34, base_amount=0.6, drip=0.28, tip_width=0.03),
    ShapeEntry("elliptic-drip", "elliptic", "convex", "drip", figure="Fig. 7 (top)",
               half_width=0.22, waist_y=0.42, base_amount=0.5, drip=0.22, tip_width=0.028),
)


def _table1_types() -> list[ShapeEntry]:
    out = []
    for row, waist in enumerate(("elliptic", "ovate", "obovate")):
        x_w, y_w = _TYPE_WAIST[waist]
        for base in MARGIN_TYPES:
            for apex in MARGIN_TYPES:
                fig_row = 2 * row + 1 + (base in ("convex", "extended"))
                col = 4 * (base in ("straight", "extended")) + MARGIN_TYPES.index(apex) + 1
                out.append(ShapeEntry(f"{waist}-{base}-{apex}", waist, base, apex, table1=True,
                                      figure=f"Fig. 4 row {fig_row} shape {col}", half_width=x_w, waist_y=y_w))
    return out


_CATALOGUE: tuple[ShapeEntry, ...] = tuple(_table1_types()) + _NAMED + _DRIP
_BY_NAME = {e.name: e for e in _CATALOGUE}


def catalogue() -> list[ShapeEntry]:
    """All catalogue shapes: the 48 waist × base × apex types of Fig. 4 in Fig. 4's order, then
    the 14 named shapes of Fig. 5 in its order (oblong and linear, Table 1's last two types,
    are among them), then the 2 drip-tip shapes of Fig. 7: 64 entries, 50 with ``table1``, 14 with
    ``named`` and 2 with apex ``"drip"``."""
    return list(_CATALOGUE)


def catalogue_names() -> list[str]:
    return [e.name for e in _CATALOGUE]


def entry(name: str) -> ShapeEntry:
    """The catalogue entry called ``name``; a :class:`ParamError` lists near names otherwise."""
    try:
        return _BY_NAME[name]
    except KeyError:
        near = [n for n in _BY_NAME if name and (name in n or n in name)][:8]
        hint = f" (did you mean {', '.join(near)}?)" if near else f" ({len(_BY_NAME)} names: see catalogue())"
        raise ParamError("shape", f"unknown catalogue shape {name!r}{hint}") from None


_SIDE_FIELDS = tuple(f.name for f in fields(SideLandmarks))
_RECIPE_FIELDS = ("half_width", "waist_y", "base_amount", "apex_amount", "parallel", "drip", "tip_width")


def _as_side(value: Any, key: str, which: str) -> SideLandmarks:
    if isinstance(value, SideLandmarks):
        return value
    if isinstance(value, LandmarkLeaf):
        return getattr(value, which)
    if isinstance(value, (str, ShapeEntry)):
        return getattr(landmark_leaf(value), which)
    raise ParamError(key, f"expected a catalogue name, a LandmarkLeaf or SideLandmarks, got {type(value).__name__}")


def landmark_leaf(name_or_entry: str | ShapeEntry, **overrides: Any) -> LandmarkLeaf:
    """Landmarks of a catalogue shape, optionally changed.

    Parameters
    ----------
    name_or_entry : str or ShapeEntry
        A catalogue name (``"ovate"``, ``"elliptic-concave-convex"``) or entry.
    **overrides
        * recipe values ``half_width``, ``waist_y``, ``base_amount``, ``apex_amount``, ``parallel``,
          ``drip``, ``tip_width``: rebuild the landmarks (the base and apex angles follow, so a
          straight base stays straight; ``drip`` / ``tip_width`` act on drip-tip shapes);
        * :class:`SideLandmarks` fields (``theta_b``, ``theta_a`` in radians, ``waist``,
          ``tail``, ``shoulder``, ``tail_angle``, ``shoulder_angle``) set on both sides, or on one
          side with a ``right_`` / ``left_`` prefix (``left_waist=(0.2, 0.45)``);
        * ``right`` / ``left``: a whole side taken from another catalogue name, LandmarkLeaf or
          SideLandmarks (asymmetric leaves of Fig. 6: ``landmark_leaf("ovate", left="elliptic")``);
        * ``name``: the leaf's name.

    Returns
    -------
    LandmarkLeaf
        Symmetric unless a side was changed on its own.
    """
    e = name_or_entry if isinstance(name_or_entry, ShapeEntry) else entry(name_or_entry)
    recipe = {k: overrides.pop(k) for k in _RECIPE_FIELDS if k in overrides}
    if recipe:
        e = ShapeEntry(**{**{f.name: getattr(e, f.name) for f in fields(ShapeEntry)}, **recipe})
    name = overrides.pop("name", e.name)
    sides = {"right": e.side(), "left": e.side()}
    for which in ("right", "left"):
        if which in overrides:
            sides[which] = _as_side(overrides.pop(which), which, which)
    both = {k: overrides.pop(k) for k in _SIDE_FIELDS if k in overrides}
    per_side: dict[str, dict[str, Any]] = {"right": dict(both), "left": dict(both)}
    for key in list(overrides):
        prefix, _, field_name = key.partition("_")
        if prefix in per_side and field_name in _SIDE_FIELDS:
            per_side[prefix][field_name] = overrides.pop(key)
    if overrides:
        bad = min(overrides)
        raise ParamError(bad, "unknown override (expected a SideLandmarks field, optionally prefixed right_/left_, "
                         f"or one of {', '.join(_RECIPE_FIELDS)}, right, left, name)")
    for which, changes in per_side.items():
        if changes:
            try:
                sides[which] = sides[which].replace(**changes)
            except ParamError as exc:
                raise ParamError(f"{which}.{exc.path}", exc.message) from None
    return LandmarkLeaf(sides["right"], sides["left"], name)


def combine_sides(right: str | LandmarkLeaf, left: str | LandmarkLeaf, name: str = "") -> LandmarkLeaf:
    """An asymmetric leaf (Fig. 6): the right side of one shape and the left side of another."""
    r = landmark_leaf(right) if isinstance(right, str) else right
    lf = landmark_leaf(left) if isinstance(left, str) else left
    return LandmarkLeaf(r.right, lf.left, name or f"{r.name}|{lf.name}")


# ---------------------------------------------------------------------------------------------
# Fig. 8: random instances
# ---------------------------------------------------------------------------------------------

def _perturb_side(side: SideLandmarks, rng: np.random.Generator, amount: float) -> SideLandmarks:
    def f() -> float:
        return 1.0 + amount * float(rng.uniform(-1.0, 1.0))

    theta_b = min(side.theta_b * f(), math.pi)
    theta_a = min(side.theta_a * f(), math.pi)
    x_w, y_w = side.waist
    waist = (x_w * f(), min(max(y_w * f(), 0.02), 0.98))
    tail = None if side.tail is None else (side.tail[0] * f(), side.tail[1] * f())
    shoulder = None
    if side.shoulder is not None:
        shoulder = (side.shoulder[0] * f(), 1.0 + (side.shoulder[1] - 1.0) * f())
    return side.replace(theta_b=theta_b, theta_a=theta_a, waist=waist, tail=tail, shoulder=shoulder)


def random_instance(leaf: LandmarkLeaf | str, seed: int, amount: float = 0.2, *,
                    independent_sides: bool = False) -> LandmarkLeaf:
    """A random variant of a leaf with the same overall shape (Fig. 8).

    Every free parameter of eq. 1 is multiplied by an independent factor uniform in
    [1 - amount, 1 + amount]: θ_b, θ_a, x_w, y_w, x_t, y_t, x_s and the apical extension
    y_s - 1 (so a shoulder stays above the apex). Angles are capped at π and y_w kept in
    [0.02, 0.98]. The tail/shoulder tangent angles keep their eq. 1 values.

    Parameters
    ----------
    leaf : LandmarkLeaf or str
        The reference shape (or a catalogue name).
    seed : int
        Seed of ``numpy.random.default_rng``: the same seed gives the same instance.
    amount : float
        Relative perturbation, 0 ≤ amount < 1 (the paper uses 0.2).
    independent_sides : bool
        Draw the two sides separately (a slightly asymmetric instance); by default both sides get
        the same draws when they start equal, so a symmetric leaf stays symmetric.
    """
    if isinstance(leaf, str):
        leaf = landmark_leaf(leaf)
    if not (isinstance(amount, (int, float)) and 0.0 <= amount < 1.0):
        raise ParamError("amount", f"must be in [0, 1), got {amount!r}")
    rng = np.random.default_rng(seed)
    right = _perturb_side(leaf.right, rng, amount)
    if leaf.is_symmetric and not independent_sides:
        left = right
    else:
        left = _perturb_side(leaf.left, rng, amount)
    return LandmarkLeaf(right, left, f"{leaf.name}#{seed}" if leaf.name else "")


# ---------------------------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------------------------

def dumps_landmark_leaf(leaf: LandmarkLeaf) -> str:
    """TOML text of a landmark leaf (``landmarks = 1``, angles in degrees)."""

    return tomli_w.dumps(leaf.to_dict())


def save_landmark_leaf(leaf: LandmarkLeaf, path: str | os.PathLike[str]) -> None:
    """Write a landmark leaf as TOML, atomically (no partial file on failure)."""

    text = dumps_landmark_leaf(leaf)
    with atomic_output(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")


def load_landmark_leaf(spec: str | os.PathLike[str]) -> LandmarkLeaf:
    """A landmark leaf from a ``.toml`` / ``.json`` file or a catalogue name.

    Errors are :class:`ParamError` naming the file and the field (``right.waist[1]``); a file whose
    margin crosses the midrib or itself is rejected too (:func:`check_margin`).
    """

    text = os.fspath(spec)
    if Path(text).suffix.lower() in (".toml", ".json") or Path(text).exists():
        data = read_document(text)
        try:
            leaf = LandmarkLeaf.from_dict(data)
            check_margin(leaf)
        except ParamError as exc:
            raise exc.with_source(text) from None
        return leaf
    return landmark_leaf(text)

