"""The lobed-leaf parameters of a leaf (``LeafParams.lobes``, the ``[lobes]`` table).

A lobed leaf (maple, oak, a two-lobed leaf) is not described by the unilobed Ω of Chaurasia &
Beardsley: its margin is **one closed curve**, a closed uniform cubic B-spline
(:mod:`leafview.core.bspline`, Mündermann et al. 2003, sec. 3.1) through ``outline``'s control
points in the leaf frame (x across, y from base towards apex, in leaf lengths). The point at
t = 0 is the leaf's base, where the petiole joins. The surface is swept between the margin and
its medial-axis skeleton (Mündermann et al. 2003, secs 3.2-3.3: ``leafview.botany.lobe_sweep``).

* ``valleys``: points on the margin where adjacent lobes meet (Garg & Leow 2011, sec. 5, user
  valley points). They become anchor points of the sweep's segments, so each valley's railroad
  tie runs from the skeleton straight to it. Each must lie on the margin, within
  :data:`VALLEY_TOLERANCE` leaf lengths.
* ``prune``: skeleton branches shorter than this (in leaf lengths, measured past the disc
  their junction already covers) are pruned from the medial axis.
* ``cup``: the railroad ties rise by ``cup · ℓ · t²`` along their length ℓ (t from the skeleton
  to the margin): a cupped lobe (0: flat ties, Mündermann et al.'s straight generating line).
* ``branches``: turtle edits per skeleton branch (Mündermann et al. 2003, sec. 4): a
  :class:`BranchTurtle` gives the extra bend, twist and turn rates (degrees per leaf length) at
  four evenly spaced points along branch ``branch`` (0 the main branch from the base to the
  apex, then the others in the order their tips come clockwise around the margin from the
  base), interpolated linearly between them.

A leaf without a ``[lobes]`` table (``outline`` empty) is an ordinary unilobed leaf; its files
read and write back unchanged. This module is numpy-only: it checks the outline (a simple
closed curve), the valleys (on it) and the edits; the skeleton and the sweep live in
``leafview.botany``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.core.bspline import MAX_CONTROLS, MIN_CONTROLS, sample_closed
from leafview.core.fieldspec import FieldSpec, check_range, check_table, integer, number, parse_list, spec_field
from leafview.errors import ParamError

__all__ = ["Lobes", "BranchTurtle", "MAX_BRANCHES", "MAX_VALLEYS", "OUTLINE_LIMIT", "VALLEY_TOLERANCE",
           "TURTLE_KNOTS", "parse_outline", "parse_valleys", "parse_branches", "lobes_dict", "turtle_specs",
           "outline_samples", "self_intersections"]

MAX_BRANCHES = 64          # turtle-edited branches per leaf
MAX_VALLEYS = 64
OUTLINE_LIMIT = 4.0        # |x|, |y| of a control point, in leaf lengths
VALLEY_TOLERANCE = 0.01    # leaf lengths between a valley point and the margin
TURTLE_KNOTS = 4           # rate values along a branch (s = 0, 1/3, 2/3, 1)
_G = "lobes"
_SAMPLES_PER_CONTROL = 8   # margin samples per control point for the checks


@dataclass(frozen=True)
class BranchTurtle:
    """Extra turtle rotations along one skeleton branch (Mündermann et al. 2003, sec. 4): rates in
    degrees per leaf length about the turtle's left axis (``bend``, + lifts the branch out of the
    blade's upper side), its heading (``twist``, right-handed) and its up axis (``turn``, +
    counter-clockwise seen from above), each at s = 0, 1/3, 2/3, 1 of the branch."""

    branch: int = spec_field("branch (0: main)", "lobes.branches", 0, 16, 1, hard=(0, MAX_BRANCHES - 1),
                             kind="int", default=0)
    bend: tuple[float, ...] = spec_field("bend (deg per length)", "lobes.branches", -180.0, 180.0, 1.0,
                                         hard=(-720.0, 720.0), kind="knots", default=(0.0,) * TURTLE_KNOTS)
    twist: tuple[float, ...] = spec_field("twist (deg per length)", "lobes.branches", -180.0, 180.0, 1.0,
                                          hard=(-720.0, 720.0), kind="knots", default=(0.0,) * TURTLE_KNOTS)
    turn: tuple[float, ...] = spec_field("turn (deg per length)", "lobes.branches", -90.0, 90.0, 1.0,
                                         hard=(-720.0, 720.0), kind="knots", default=(0.0,) * TURTLE_KNOTS)


def _empty() -> tuple[Any, ...]:
    return ()


@dataclass(frozen=True)
class Lobes:
    """The closed margin of a lobed leaf, its valleys, skeleton pruning, cupping and per-branch
    turtle edits (see the module docstring). ``outline`` empty: not a lobed leaf."""

    outline: tuple[tuple[float, float], ...] = spec_field(
        "margin control points (closed B-spline)", _G, -1.0, 1.0, 0.001, hard=(-OUTLINE_LIMIT, OUTLINE_LIMIT),
        kind="outline", default_factory=_empty)
    valleys: tuple[tuple[float, float], ...] = spec_field(
        "valley points", _G, -1.0, 1.0, 0.001, hard=(-OUTLINE_LIMIT, OUTLINE_LIMIT), kind="points",
        default_factory=_empty)
    prune: float = spec_field("skeleton pruning (leaf lengths)", _G, 0.0, 0.3, 0.005, hard=(0.0, 1.0),
                              default=0.06)
    cup: float = spec_field("cupping of the ties", _G, -0.5, 0.5, 0.01, hard=(-2.0, 2.0), default=0.0)
    branches: tuple[BranchTurtle, ...] = spec_field("turtle edits per branch", _G, 0, MAX_BRANCHES, 1,
                                                    kind="turtle", default_factory=_empty)

    @property
    def enabled(self) -> bool:
        """True for a lobed leaf (an outline is set)."""
        return bool(self.outline)


def turtle_specs() -> dict[str, FieldSpec]:
    """The :class:`FieldSpec` of each :class:`BranchTurtle` field by name."""
    return {f.name: f.metadata["spec"] for f in fields(BranchTurtle)}


def _point_list(value: Any, path: str, lo: int, hi: int, what: str) -> tuple[tuple[float, float], ...]:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)):
        raise ParamError(path, f"expected a list of [x, y] {what}, got {type(value).__name__}")
    if not lo <= len(value) <= hi:
        raise ParamError(path, f"{len(value)} {what}; expected {lo} to {hi}")
    out = []
    for i, p in enumerate(value):
        if isinstance(p, np.ndarray):
            p = p.tolist()
        if not isinstance(p, (list, tuple)) or len(p) != 2:
            raise ParamError(f"{path}[{i}]", f"expected [x, y], got {p!r}")
        xy = (number(p[0], f"{path}[{i}][0]"), number(p[1], f"{path}[{i}][1]"))
        for j, x in enumerate(xy):
            if abs(x) > OUTLINE_LIMIT:
                raise ParamError(f"{path}[{i}][{j}]", f"{x!r} is outside ±{OUTLINE_LIMIT:g} leaf lengths")
        out.append(xy)
    return tuple(out)


def outline_samples(outline: Any, per_control: int = _SAMPLES_PER_CONTROL) -> NDArray[np.float64]:
    """The margin sampled at ``per_control`` points per control point (closing point not repeated)."""
    c = np.asarray(outline, dtype=np.float64)
    return sample_closed(c, per_control * len(c))


def self_intersections(ring: NDArray[np.float64]) -> list[tuple[int, int]]:
    """Pairs (i, j), i < j, of non-adjacent segments of the closed polyline ``ring`` that cross
    (or touch): empty for a simple closed curve."""
    p = np.asarray(ring, dtype=np.float64)
    q = np.roll(p, -1, axis=0)
    n = len(p)
    d = q - p
    # segment i: p_i + a d_i; segment j: p_j + b d_j
    den = d[:, None, 0] * d[None, :, 1] - d[:, None, 1] * d[None, :, 0]
    w = p[None, :, :] - p[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (w[..., 0] * d[None, :, 1] - w[..., 1] * d[None, :, 0]) / den
        b = (w[..., 0] * d[:, None, 1] - w[..., 1] * d[:, None, 0]) / den
    hit = (np.abs(den) > 1e-18) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
    i, j = np.nonzero(np.triu(hit, 1))
    keep = (j - i > 1) & ~((i == 0) & (j == n - 1))
    return list(zip(i[keep].tolist(), j[keep].tolist()))


def parse_outline(value: Any, path: str = "lobes.outline") -> tuple[tuple[float, float], ...]:
    """Validate the margin's control points: MIN_CONTROLS to MAX_CONTROLS finite [x, y] pairs
    whose closed B-spline is a simple curve enclosing some area. An empty list: not lobed."""
    if isinstance(value, (list, tuple)) and len(value) == 0:
        return ()
    pts = _point_list(value, path, MIN_CONTROLS, MAX_CONTROLS, "control points")
    ring = outline_samples(pts)
    area = 0.5 * abs(float(np.sum(ring[:, 0] * np.roll(ring[:, 1], -1) - np.roll(ring[:, 0], -1) * ring[:, 1])))
    if not area > 1e-4:
        raise ParamError(path, f"the margin encloses no area ({area:.2g} square leaf lengths)")
    crossings = self_intersections(ring)
    if crossings:
        i, _ = crossings[0]
        k = i // _SAMPLES_PER_CONTROL
        raise ParamError(path, f"the margin crosses itself ({len(crossings)} crossings; the first near "
                               f"control point {k}, {ring[i, 0]:.3f}, {ring[i, 1]:.3f})")
    return pts


def parse_valleys(value: Any, outline: tuple[tuple[float, float], ...], path: str = "lobes.valleys"
                  ) -> tuple[tuple[float, float], ...]:
    """Validate the valley points: each within :data:`VALLEY_TOLERANCE` of the margin."""
    pts = _point_list(value, path, 0, MAX_VALLEYS, "valley points")
    if pts and not outline:
        raise ParamError(path, "valley points need a margin: set lobes.outline first")
    if pts:
        ring = outline_samples(outline, 64)
        for i, p in enumerate(pts):
            dist = float(np.min(np.linalg.norm(ring - np.asarray(p), axis=1)))
            if dist > VALLEY_TOLERANCE:
                raise ParamError(f"{path}[{i}]", f"({p[0]:.4g}, {p[1]:.4g}) is {dist:.4f} leaf lengths off the "
                                                 f"margin (at most {VALLEY_TOLERANCE:g})")
    return pts


def _turtle(value: Any, path: str) -> BranchTurtle:
    if isinstance(value, BranchTurtle):
        value = turtle_dict(value)
    specs = turtle_specs()
    check_table(value, path, specs, ("branch",), "branch, bend, twist and turn")
    out: dict[str, Any] = {}
    for name, spec in specs.items():
        if name not in value:
            continue
        where = f"{path}.{name}"
        if name == "branch":
            out[name] = integer(value[name], spec, where)
            continue
        x = value[name]
        if isinstance(x, np.ndarray):
            x = x.tolist()
        if not isinstance(x, (list, tuple)) or len(x) != TURTLE_KNOTS:
            raise ParamError(where, f"expected {TURTLE_KNOTS} rates (at s = 0, 1/3, 2/3, 1), got {x!r}")
        vals = tuple(number(v, f"{where}[{k}]") for k, v in enumerate(x))
        for k, v in enumerate(vals):
            check_range(v, spec, f"{where}[{k}]")
        out[name] = vals
    return BranchTurtle(**out)


def parse_branches(value: Any, path: str = "lobes.branches") -> tuple[BranchTurtle, ...]:
    """Validate the turtle edits (``[[lobes.branches]]`` tables); each branch at most once."""
    out = parse_list(value, path, BranchTurtle, turtle_dict, _turtle, MAX_BRANCHES, "branch edit")
    seen: dict[int, int] = {}
    for i, b in enumerate(out):
        if b.branch in seen:
            raise ParamError(f"{path}[{i}].branch", f"branch {b.branch} is already edited by {path}[{seen[b.branch]}]")
        seen[b.branch] = i
    return out


def turtle_dict(b: BranchTurtle) -> dict[str, Any]:
    """One branch edit as a plain table."""
    return {"branch": b.branch, "bend": list(b.bend), "twist": list(b.twist), "turn": list(b.turn)}


def lobes_dict(lobes: Lobes) -> dict[str, Any]:
    """The ``[lobes]`` table of ``lobes`` (plain lists and floats)."""
    return {"outline": [list(p) for p in lobes.outline], "valleys": [list(p) for p in lobes.valleys],
            "prune": lobes.prune, "cup": lobes.cup, "branches": [turtle_dict(b) for b in lobes.branches]}


def parse_lobes_field(name: str, value: Any, path: str, outline: tuple[tuple[float, float], ...]) -> Any:
    """Dispatch for :func:`leafview.core.params.parse_field` on the lobes-specific kinds."""
    if name == "outline":
        return parse_outline(value, path)
    if name == "valleys":
        return parse_valleys(value, outline, path)
    return parse_branches(value, path)
