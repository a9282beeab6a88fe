"""Multilobed leaves (Garg & Leow 2011, sec. 5): palmate, pinnate and bilobed leaves built from
unilobed lobes, each a shader-model leaf in its own frame.

Placement. A lobed leaf has a primary vein along +y from the base (0, 0) to (0, 1). ``half``
lateral lobes per side are placed by eqs 7-9 (or given explicitly, ``positions``)::

    r_i = i r_1 + i (i - 1) / 2 Δs                  (7)   base of lobe i on the primary vein (y)
    θ_i = θ_1 + (i - 1) (θ_n - θ_1) / (n - 1)       (8)   angle from the vein (degrees)
    l_i = l_1 + (i - 1) (l_n - l_1) / (n - 1)       (9)   lobe length

with n = ``half``; each lateral lobe appears on both sides (±θ_i). Palmate leaves put every lobe
at the base (r_1 = Δs = 0) and add a terminal lobe along the vein; pinnate leaves spread them
along the vein and end in a terminal lobe; bilobed leaves have one lobe per side and no terminal
lobe.

Joining. The parts are the *construction* of a lobed leaf, not what is drawn. Adjacent lobes
overlap, and where their margins cross lies the valley (sec. 5: "the intersections of adjacent
margins form the valleys"); where they do not cross, a ``web`` blade (a catalogue shape along the
vein, its half-width scaled) fills between the lobes and its margin draws the valley (the paper's
"default valley points"). :mod:`leafview.botany.lobe_outline` joins the parts' margins into ONE
closed margin with valley B-splines, and that margin is what a lobed leaf carries
(``LeafParams.lobes``) and what the shader sweeps (Mündermann et al. 2003). :func:`lobe_leaves`
still places every part as a leaf of its own, lifted by a tiny ordered offset (``Z_STEP``) so
that the parts can be inspected together.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.botany.outline_fit import margin, rows_from_controls
from leafview.botany.shapes import fit_info, shapes_params
from leafview.core.limits import MAX_LOBES_PER_SIDE, check_name
from leafview.core.lobes import MAX_VALLEYS
from leafview.core.params import LeafParams, Material, ParamError, Transform, _parse_group
from leafview.deform.surface import control_polygons
from leafview.inputs import read_toml
from leafview.resources import asset_dir

__all__ = ["Z_STEP", "KINDS", "LobePlacement", "LobedLeaf", "place_lobes", "lobe_leaves", "lobe_outlines",
           "valleys", "load_lobed_leaf", "lobed_from_dict", "scale_width_exact"]

Z_STEP = 2e-4            # leaf lengths between the z levels of consecutive parts
KINDS = ("palmate", "pinnate", "bilobed")


@dataclass(frozen=True)
class LobePlacement:
    """One part of a lobed leaf in the leaf frame: ``base`` (x, y), ``angle`` (degrees,
    counter-clockwise from +y: positive lobes point to the left, -x), ``length``, the catalogue
    ``shape`` and an optional half-width factor ``width``; ``role`` is lateral, terminal or web."""

    shape: str
    base: tuple[float, float]
    angle: float
    length: float
    role: str = "lateral"
    width: float = 1.0


@dataclass(frozen=True)
class LobedLeaf:
    """A palmate, pinnate or bilobed leaf (sec. 5). Lengths are in units of the primary vein.

    Attributes
    ----------
    kind
        ``palmate``, ``pinnate`` or ``bilobed``.
    shape
        Catalogue name of the lateral lobes (``leafview shapes`` lists them).
    half
        n, the number of lateral lobes per side (eqs 7-9).
    r1, spacing
        r_1 and Δs of eq. 7 (palmate: both 0).
    theta
        (θ_1, θ_n) of eq. 8, degrees from the vein.
    length
        (l_1, l_n) of eq. 9.
    terminal, terminal_length, terminal_base
        Catalogue shape of the terminal lobe ("" for none), its length and the y of its base.
    web, web_length, web_width
        Catalogue shape of the valley filler along the vein ("" for none), its length and
        half-width factor.
    lobe_width
        Half-width factor of the lateral and terminal lobes (1: the catalogue shape as fitted).
    positions
        Explicit ``(r, θ, l)`` per lateral lobe, replacing eqs 7-9 (user positions).
    valleys
        User valley points ``(x, y)`` (sec. 5: "valley points ... may be specified"): each
        replaces the valley at the nearest corner of the joined margin
        (:func:`leafview.botany.lobe_outline.lobed_outline`); empty: the crossings of adjacent
        margins (or the web's margin) form the valleys.
    """

    name: str = ""
    kind: str = "palmate"
    shape: str = "ovate"
    half: int = 2
    r1: float = 0.0
    spacing: float = 0.0
    theta: tuple[float, float] = (45.0, 90.0)
    length: tuple[float, float] = (0.85, 0.55)
    terminal: str = "ovate"
    terminal_length: float = 1.0
    terminal_base: float = 0.0
    web: str = ""
    web_length: float = 0.3
    web_width: float = 1.0
    lobe_width: float = 1.0
    positions: tuple[tuple[float, float, float], ...] = ()
    valleys: tuple[tuple[float, float], ...] = ()
    material: Material = field(default_factory=Material)

    def lobes(self) -> list[LobePlacement]:
        """Every part, lowest z first (see :func:`place_lobes`)."""
        return place_lobes(self)

    def describe(self) -> str:
        parts = self.lobes()
        lat = [p for p in parts if p.role == "lateral"]
        return (f"{self.name or '(unnamed)'}: {self.kind}, {len(lat)} lateral lobes ({self.shape})"
                f"{', terminal ' + self.terminal if self.terminal else ''}"
                f"{', web ' + self.web if self.web else ''}; {len(parts)} parts joined into one margin")


def _linear(i: int, n: int, a: float, b: float) -> float:
    """Eqs 8-9: a + (i - 1)(b - a)/(n - 1); a when n = 1."""
    return a if n <= 1 else a + (i - 1) * (b - a) / (n - 1)


def place_lobes(leaf: LobedLeaf) -> list[LobePlacement]:
    """Parts of ``leaf`` in draw order (lowest first): the web, lateral lobes from the outermost
    (last, i = n) in, then the terminal lobe. Lateral lobe i of eqs 7-9 sits at (0, r_i) with
    angle ±θ_i and length l_i (or at the user ``positions``)."""
    n = leaf.half
    if leaf.positions:
        specs = [(float(r), float(t), float(l)) for r, t, l in leaf.positions]
    else:
        specs = [(i * leaf.r1 + i * (i - 1) / 2.0 * leaf.spacing,            # eq. 7
                  _linear(i, n, *leaf.theta),                                 # eq. 8
                  _linear(i, n, *leaf.length)) for i in range(1, n + 1)]     # eq. 9
    parts: list[LobePlacement] = []
    if leaf.web:
        parts.append(LobePlacement(leaf.web, (0.0, 0.0), 0.0, leaf.web_length, "web", leaf.web_width))
    for r, theta, length in reversed(specs):
        for sign in (-1.0, 1.0):  # right (x > 0: clockwise) then left
            parts.append(LobePlacement(leaf.shape, (0.0, r), sign * theta, length, "lateral", leaf.lobe_width))
    if leaf.terminal and leaf.kind != "bilobed":
        parts.append(LobePlacement(leaf.terminal, (0.0, leaf.terminal_base), 0.0, leaf.terminal_length,
                                   "terminal", leaf.lobe_width))
    return parts


def scale_width_exact(params: LeafParams, factor: float) -> LeafParams:
    """Scale the blade's half-width by ``factor`` exactly (x of every silhouette control point,
    heights kept; tilted rows are re-split into foot, x̄s and φ), for a straight axis."""

    if factor == 1.0:
        return params
    ctrl = control_polygons(params)["S-"][:, :2].copy()    # the right side, x > 0
    ctrl[:, 0] *= factor
    rows, tilt = rows_from_controls(ctrl)
    sh = params.shape
    rows = tuple((v, x, z) for (v, x, _), (_, _, z) in zip(rows, sh.silhouette))
    return params.replace(shape=replace(sh, silhouette=rows, tilt=tilt))


ShapeSource = Callable[[str], LeafParams]   # catalogue name -> its fitted leaf


def _part_params(part: LobePlacement, z: float, material: Material, shape_source: ShapeSource) -> LeafParams:
    base = shape_source(part.shape)
    if part.width != 1.0:
        base = scale_width_exact(base, part.width)
    t = Transform(translation=(part.base[0], part.base[1], z), rotation=(0.0, 0.0, part.angle),
                  scale=part.length)
    return base.replace(transform=t, material=material, name=f"{part.role}:{part.shape}")


def lobe_leaves(leaf: LobedLeaf, shape_source: ShapeSource | None = None) -> list[LeafParams]:
    """One :class:`LeafParams` per part, placed by its transform (rotation about z, scale =
    length, translation = base + its z level): the leaves to draw together. ``shape_source``
    maps a catalogue name to its fitted leaf (default :func:`leafview.botany.shapes.shapes_params`)."""
    if shape_source is None:
        shape_source = shapes_params
    parts = leaf.lobes()
    return [_part_params(p, k * Z_STEP, leaf.material, shape_source) for k, p in enumerate(parts)]


def lobe_outlines(leaf: LobedLeaf, shape_source: ShapeSource | None = None, n: int = 257) -> list[NDArray[np.float64]]:
    """The margin of every part in the leaf frame (closed (2n, 2) polylines), from the fitted
    leaves (the u = ±1 curves of eq. 6) and their transforms."""

    out = []
    for p in lobe_leaves(leaf, shape_source):
        right, left = margin(p, n)
        ring = np.vstack([right, left[::-1]])
        m = p.transform.matrix()
        out.append(ring @ m[:2, :2].T + m[:2, 3])
    return out


def _segment_hits(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Intersection points of two polylines (brute force over segment pairs)."""
    p, r = a[:-1], np.diff(a, axis=0)
    q, s = b[:-1], np.diff(b, axis=0)
    rxs = r[:, None, 0] * s[None, :, 1] - r[:, None, 1] * s[None, :, 0]
    qp = q[None, :, :] - p[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (qp[..., 0] * s[None, :, 1] - qp[..., 1] * s[None, :, 0]) / rxs
        u = (qp[..., 0] * r[:, None, 1] - qp[..., 1] * r[:, None, 0]) / rxs
    ok = (np.abs(rxs) > 1e-14) & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
    i, _ = np.nonzero(ok)
    return p[i] + t[ok][:, None] * r[i]


def valleys(leaf: LobedLeaf, shape_source: ShapeSource | None = None) -> list[NDArray[np.float64] | None]:
    """The valley between each pair of angularly adjacent parts on each side: the crossing of
    their margins farthest from the base (sec. 5), or None where the margins do not cross (the
    web, if any, closes that valley)."""
    parts = leaf.lobes()
    rings = lobe_outlines(leaf, shape_source, 129)
    order = [k for k, p in enumerate(parts) if p.role != "web"]
    order.sort(key=lambda k: (parts[k].angle, parts[k].base[1]))
    out: list[NDArray[np.float64] | None] = []
    for a, b in zip(order[:-1], order[1:]):
        hits = _segment_hits(rings[a], rings[b])
        hits = hits[np.linalg.norm(hits, axis=1) > 1e-6] if len(hits) else hits
        out.append(hits[np.argmax(np.linalg.norm(hits, axis=1))] if len(hits) else None)
    return out


# -- files ------------------------------------------------------------------------------------
_FLOAT_KEYS = ("r1", "spacing", "terminal_length", "terminal_base", "web_length", "web_width", "lobe_width")
_PAIR_KEYS = ("theta", "length")
_STR_KEYS = ("name", "kind", "shape", "terminal", "web")


LOBE_LIMIT = 360.0   # |number| of a lobed leaf file: lengths in primary-vein units, angles in degrees


def _bounded(x: float, path: str) -> float:
    if not abs(x) <= LOBE_LIMIT:
        raise ParamError(path, f"{x!r} is outside ±{LOBE_LIMIT:g}")
    return float(x)


def _valley_points(value: Any) -> tuple[tuple[float, float], ...]:
    """The ``valleys`` key: up to MAX_VALLEYS finite [x, y] points (primary-vein units)."""
    if not isinstance(value, list):
        raise ParamError("valleys", f"expected a list of [x, y] points, got {type(value).__name__}")
    if len(value) > MAX_VALLEYS:
        raise ParamError("valleys", f"{len(value):,} valley points; at most {MAX_VALLEYS}")
    out = []
    for i, p in enumerate(value):
        if not isinstance(p, list) or len(p) != 2:
            raise ParamError(f"valleys[{i}]", f"expected [x, y], got {p!r}")
        for j, x in enumerate(p):
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                raise ParamError(f"valleys[{i}][{j}]", f"expected a finite number, got {x!r}")
        out.append((_bounded(p[0], f"valleys[{i}][0]"), _bounded(p[1], f"valleys[{i}][1]")))
    return tuple(out)


def lobed_from_dict(data: Mapping[str, Any]) -> LobedLeaf:
    """Validate a ``lobed = 1`` document (see ``assets/compound/*.toml``); ParamError names the
    field."""

    if not isinstance(data, Mapping) or data.get("lobed") != 1:
        raise ParamError("lobed", "a multilobed leaf file starts with lobed = 1")
    known = {"lobed", "half", "positions", "valleys", "material", *_FLOAT_KEYS, *_PAIR_KEYS, *_STR_KEYS}
    for key in data:
        if key not in known:
            raise ParamError(str(key), f"unknown key (known: {', '.join(sorted(known))})")
    kw: dict[str, Any] = {}
    for key in _STR_KEYS:
        if key in data:
            if not isinstance(data[key], str):
                raise ParamError(key, f"expected a string, got {type(data[key]).__name__}")
            kw[key] = check_name(data[key], key) if key == "name" else data[key]
    for key in _FLOAT_KEYS:
        if key in data:
            x = data[key]
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                raise ParamError(key, f"expected a finite number, got {x!r}")
            kw[key] = _bounded(x, key)
    for key in _PAIR_KEYS:
        if key in data:
            v = data[key]
            if (not isinstance(v, list) or len(v) != 2
                    or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
                raise ParamError(key, f"expected two finite numbers [first, last], got {v!r}")
            kw[key] = (_bounded(v[0], f"{key}[0]"), _bounded(v[1], f"{key}[1]"))
    if "half" in data:
        h = data["half"]
        if isinstance(h, bool) or not isinstance(h, int) or not 1 <= h <= MAX_LOBES_PER_SIDE:
            raise ParamError("half", f"expected a whole number of lobes per side in 1..{MAX_LOBES_PER_SIDE}, got {h!r}")
        kw["half"] = h
    if "positions" in data:
        pos = data["positions"]
        if not isinstance(pos, list) or not all(isinstance(r, list) and len(r) == 3 for r in pos):
            raise ParamError("positions", "expected a list of [r, θ, l] rows")
        if not 1 <= len(pos) <= MAX_LOBES_PER_SIDE:
            raise ParamError("positions", f"{len(pos):,} lateral lobes; 1..{MAX_LOBES_PER_SIDE} per side are accepted")
        for i, row in enumerate(pos):
            for j, x in enumerate(row):
                if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                    raise ParamError(f"positions[{i}][{j}]", f"expected a finite number, got {x!r}")
        kw["positions"] = tuple(tuple(_bounded(x, f"positions[{i}][{j}]") for j, x in enumerate(row))
                                for i, row in enumerate(pos))
    if "valleys" in data:
        kw["valleys"] = _valley_points(data["valleys"])
    if "material" in data:
        kw["material"] = _parse_group(Material, data["material"], "material", required=False)
    leaf = LobedLeaf(**kw)
    if leaf.kind not in KINDS:
        raise ParamError("kind", f"unknown kind {leaf.kind!r} (choose from {', '.join(KINDS)})")
    if leaf.kind == "bilobed" and (leaf.half != 1 and not leaf.positions):
        raise ParamError("half", "a bilobed leaf has one lobe per side (half = 1)")
    for key in ("shape", "terminal", "web"):
        name = getattr(leaf, key)
        if name:
            try:
                fit_info(name)
            except ParamError as exc:
                raise ParamError(key, exc.message) from None
    for key in ("terminal_length", "web_length", "web_width", "lobe_width"):
        if getattr(leaf, key) <= 0.0:
            raise ParamError(key, f"must be greater than 0, got {getattr(leaf, key)!r}")
    for i, (_, _, l) in enumerate(leaf.positions or ((0.0, 0.0, x) for x in leaf.length)):
        if l <= 0.0:
            raise ParamError("positions" if leaf.positions else f"length[{i}]", f"lobe length must be > 0, got {l!r}")
    return leaf


def _compound_dir() -> Path:

    return asset_dir() / "compound"


def builtin_lobed() -> dict[str, Path]:
    """Built-in multilobed leaves (``assets/compound/*.toml``) by name."""
    return {p.stem: p for p in sorted(_compound_dir().glob("*.toml"))}


def load_lobed_leaf(spec: str | os.PathLike[str]) -> LobedLeaf:
    """A multilobed leaf from a ``.toml`` file or a built-in name (``maple``, ``oak``, ...);
    :class:`ParamError` carries the file (and ``line:col`` for TOML syntax errors)."""
    path = Path(spec)
    if not path.exists() and not path.suffix:
        found = builtin_lobed()
        if str(spec) in found:
            path = found[str(spec)]
        else:
            raise ParamError("", f"no such file or built-in multilobed leaf {str(spec)!r} "
                             f"(built-in: {', '.join(found)})")
    data = read_toml(path, what="multilobed leaf file")
    try:
        leaf = lobed_from_dict(data)
    except ParamError as exc:
        raise exc.with_source(str(path)) from None
    return leaf if leaf.name else replace(leaf, name=path.stem)
