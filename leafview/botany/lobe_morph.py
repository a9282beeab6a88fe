"""Morphing unilobed and lobed leaves through one margin space (Garg & Leow 2011, sec. 6, Figs 12-13).

Garg & Leow morph unilobed leaves in their landmark space (eq. 11, :mod:`leafview.botany.morph`)
and show, without giving the method, a unilobed leaf turning into a multilobed one (Fig. 13). A
lobed leaf in leafview is one closed uniform cubic B-spline margin (``LeafParams.lobes.outline``,
:mod:`leafview.core.lobes`), and any unilobed margin can be written the same way, so here every
key shape becomes a point of one *margin space*:

* :func:`closed_margin` writes a leaf's margin as ``controls`` control points of a closed B-spline
  in the lobed convention: leaf frame, C(0) at the base, clockwise (base → left side, x < 0 →
  apex → right side). The margin is sampled evenly by arc length from the base and fitted with
  :func:`leafview.core.bspline.fit_closed`, whose chord-length parameters make control point k sit
  at arc-length fraction ≈ k / controls on every leaf: the correspondence between two leaves is by
  arc length from the base, with the same control count.
* :class:`LobeMorphPath` is eq. 11 over those control vectors (2·controls numbers each): the NURBS
  of :class:`leafview.botany.morph.NurbsCurve`, through source and target, pulled towards each
  reference by its weight (soft constraints, Fig. 11); frames are evenly spaced along its arc
  length, the paper's "regular interval along M".
* Growth with size (Figs 12-13: "scaled the generated shapes according to the actual sizes"): a
  leaf length per key shape, carried along the path by the same NURBS (so sizes that grow from
  key to key grow monotonically) into ``transform.scale``.

Every frame is a :class:`~leafview.core.params.LeafParams` with ``lobes.outline`` set, checked by
:func:`leafview.core.lobes.parse_outline` (a simple closed curve); a frame that would cross itself
is reported by index (``frames[i].lobes.outline``). The frames take everything but the margin and
the size from the first lobed-or-preset key (material, ripples, the lobes' prune and cup); valley
points and per-branch turtle edits are dropped, since they belong to one particular margin.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.botany.catalogue import catalogue_names, landmark_leaf, load_landmark_leaf
from leafview.botany.landmarks import LandmarkLeaf, outline
from leafview.botany.morph import NurbsCurve, arclength_parameter, key_sizes
from leafview.botany.outline_fit import margin
from leafview.core.bspline import MAX_CONTROLS, MIN_CONTROLS, fit_closed, sample_closed, signed_area
from leafview.core.io import read_document
from leafview.core.limits import MAX_MORPH_FRAMES
from leafview.core.lobes import parse_outline
from leafview.core.params import LeafParams, ParamError
from leafview.resources import builtin_presets

__all__ = ["DEFAULT_CONTROLS", "KeyShape", "LobeMorphPath", "closed_margin", "lobe_morph", "lobe_morph_path",
           "load_key_shape", "is_lobed"]

DEFAULT_CONTROLS = 96     # control points of the shared margin when no lobed key asks for more
_SAMPLES_PER_CONTROL = 8  # arc-length samples per control point for the fit
_DENSE = 4096             # samples of a margin before arc-length resampling

KeyShape = LeafParams | LandmarkLeaf | str


def is_lobed(shape: object) -> bool:
    """True for a :class:`LeafParams` whose ``lobes.outline`` is set."""
    return isinstance(shape, LeafParams) and shape.lobes.enabled


def load_key_shape(spec: str, what: str = "shape") -> LeafParams | LandmarkLeaf:
    """A key shape from its name or file, for argument ``what``.

    Catalogue names (``ovate``, ``cordate``: their exact landmark margins) come first, then
    built-in presets (``maple``, ``oak``, ``bilobed``, ...: assets/presets), then files: a landmark
    leaf (``landmarks = 1``) or a leaf preset, lobed or not. Unknown names raise
    :class:`ParamError` naming ``what``.
    """
    if not isinstance(spec, str) or not spec:
        raise ParamError(what, f"expected a shape name or file, got {spec!r}")
    if spec in catalogue_names():
        return landmark_leaf(spec)
    presets = builtin_presets()
    try:
        if spec in presets:
            return LeafParams.load(presets[spec])
        path = Path(spec)
        if path.suffix.lower() in (".toml", ".json") and path.exists():
            data = read_document(spec)
            if isinstance(data, dict) and "landmarks" in data:
                return load_landmark_leaf(spec)
            return LeafParams.load(path)
    except ParamError as exc:
        raise ParamError(what, f"{spec}: {exc}") from None
    except OSError as exc:
        raise ParamError(what, f"{spec}: {exc}") from None
    raise ParamError(what, f"unknown shape {spec!r}: not a catalogue name (`leafview shapes`), a built-in "
                           f"preset ({', '.join(presets)}) or a .toml / .json file")


def _resolve(shape: KeyShape, what: str) -> LeafParams | LandmarkLeaf:
    if isinstance(shape, str):
        return load_key_shape(shape, what)
    if isinstance(shape, (LeafParams, LandmarkLeaf)):
        return shape
    raise ParamError(what, f"expected LeafParams, a LandmarkLeaf or a name, got {type(shape).__name__}")


def _ring(shape: LeafParams | LandmarkLeaf) -> NDArray[np.float64]:
    """A dense closed polyline of the margin, clockwise, starting at the base (not repeated)."""
    if isinstance(shape, LandmarkLeaf):
        ccw = outline(shape, _DENSE // 2)                  # right side up, left side down
        return np.roll(ccw[::-1], 1, axis=0)               # base, left side up, apex, right side down
    if shape.lobes.enabled:
        ring = sample_closed(np.asarray(shape.lobes.outline, dtype=np.float64), _DENSE)
        if signed_area(ring) > 0.0:                        # written counter-clockwise: turn it round at C(0)
            ring = np.roll(ring[::-1], 1, axis=0)
        return ring
    right, left = margin(shape, _DENSE // 2 + 1)
    return np.concatenate([left[:-1], right[::-1][:-1]])


def _by_arclength(ring: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    closed = np.vstack([ring, ring[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    target = np.linspace(0.0, s[-1], n, endpoint=False)
    return np.stack([np.interp(target, s, closed[:, j]) for j in range(2)], axis=1)


def _check_controls(controls: Any) -> int:
    if isinstance(controls, bool) or not isinstance(controls, (int, np.integer)) \
            or not MIN_CONTROLS <= int(controls) <= MAX_CONTROLS:
        raise ParamError("controls", f"must be an integer in [{MIN_CONTROLS}, {MAX_CONTROLS}], got {controls!r}")
    return int(controls)


def closed_margin(shape: KeyShape, controls: int = DEFAULT_CONTROLS) -> NDArray[np.float64]:
    """A leaf's margin as ``controls`` control points (controls, 2) of a closed uniform cubic
    B-spline in the lobed convention (leaf frame, C(0) at the base, clockwise).

    Parameters
    ----------
    shape : LeafParams, LandmarkLeaf or str
        A unilobed leaf (its margin from :func:`leafview.botany.outline_fit.margin`, the u = ±1
        curves of the shader model), a lobed one (its ``lobes.outline`` resampled), a landmark
        leaf (its exact margin), or a name (:func:`load_key_shape`).
    controls : int
        Control points, :data:`~leafview.core.bspline.MIN_CONTROLS` to ``MAX_CONTROLS``.

    The margin is sampled at 8·controls points evenly spaced in arc length from the base and
    fitted by least squares (:func:`~leafview.core.bspline.fit_closed`): leaves fitted with the
    same count correspond by arc length from the base. Transform (size) is not applied.
    """
    m = _check_controls(controls)
    return fit_closed(_by_arclength(_ring(_resolve(shape, "shape")), _SAMPLES_PER_CONTROL * m), m)


def _frame_template(keys: Sequence[LeafParams | LandmarkLeaf]) -> LeafParams:
    for k in keys:
        if is_lobed(k):
            return k  # type: ignore[return-value]
    for k in keys:
        if isinstance(k, LeafParams):
            return k
    return LeafParams()


@dataclass
class LobeMorphPath:
    """Eq. 11 over the margin control vectors of the key shapes (source, references..., target).

    Attributes
    ----------
    keys : (k, controls, 2) array
        The key margins (:func:`closed_margin`, same control count).
    weights : (k,) array
        w_0 = w_{k-1} = 1 and the references' weights (> 0).
    sizes : (k,) array
        Leaf length of each key (growth with size), carried along the path into transform.scale.
    template : LeafParams
        Everything but the margin and the size of each frame.
    """

    keys: NDArray[np.float64]
    weights: NDArray[np.float64]
    sizes: NDArray[np.float64]
    template: LeafParams = field(default_factory=LeafParams)
    name: str = "morph"

    def __post_init__(self) -> None:
        k, m = self.keys.shape[:2]
        self.controls = m
        self._curve = NurbsCurve(self.keys.reshape(k, 2 * m), self.weights)
        self._size = NurbsCurve(self.sizes.reshape(k, 1), self.weights)
        u = np.linspace(0.0, 1.0, 2049)
        p = self._curve(u)
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        self._table = (u, s, float(s[-1]))

    def __call__(self, u: ArrayLike) -> NDArray[np.float64]:
        """Control vectors (…, 2·controls) at curve parameters ``u``."""
        return self._curve(u)

    @property
    def length(self) -> float:
        """Length of the path in margin space (control-point units)."""
        return self._table[2]

    def parameter(self, t: ArrayLike) -> NDArray[np.float64]:
        """Curve parameter u at arc-length fractions t ∈ [0, 1]."""
        return arclength_parameter(self._table, t)

    def controls_at(self, t: float) -> NDArray[np.float64]:
        """The margin control points (controls, 2) at path position t."""
        return self(self.parameter(np.array([t])))[0].reshape(self.controls, 2)

    def size_at(self, t: ArrayLike) -> NDArray[np.float64]:
        """Leaf sizes at path positions t (eq. 11 with the path's weights over the key sizes)."""
        return self._size(self.parameter(t))[..., 0]

    def frame_vectors(self, steps: int) -> NDArray[np.float64]:
        """``steps`` control vectors evenly spaced along the path (first = source, last = target)."""
        return self(self.parameter(np.linspace(0.0, 1.0, steps)))

    def distance_to(self, vector: ArrayLike, samples: int = 4097) -> float:
        """Smallest margin-space distance from the path to a control vector."""
        p = self(np.linspace(0.0, 1.0, samples))
        return float(np.linalg.norm(p - np.asarray(vector, dtype=np.float64).ravel(), axis=1).min())

    def frame(self, t: float, name: str = "", where: str = "frame") -> LeafParams:
        """The leaf at path position t: a lobed :class:`LeafParams` (``lobes.outline`` checked
        by :func:`~leafview.core.lobes.parse_outline`; a crossing raises :class:`ParamError`
        naming ``where``)."""
        ctrl = self.controls_at(float(t))
        pts = parse_outline([tuple(map(float, p)) for p in ctrl], f"{where}.lobes.outline")
        base = self.template
        lobes = replace(base.lobes, outline=pts, valleys=(), branches=())
        scale = float(self.size_at(np.array([t]))[0])
        return base.replace(lobes=lobes, transform=replace(base.transform, scale=scale),
                            name=name or f"{self.name} t={float(t):.3f}")

    def frames(self, steps: int) -> list[LeafParams]:
        """``steps`` frames evenly spaced along the path's arc length."""
        _check_steps(steps)
        width = len(str(steps - 1))
        return [self.frame(float(t), f"{self.name} {i:0{width}d}", f"frames[{i}]")
                for i, t in enumerate(np.linspace(0.0, 1.0, steps))]


def _check_steps(steps: Any) -> int:
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or not 2 <= steps <= MAX_MORPH_FRAMES:
        raise ParamError("steps", f"must be an integer in [2, {MAX_MORPH_FRAMES}], got {steps!r}")
    return int(steps)


def lobe_morph_path(source: KeyShape, target: KeyShape, *, references: Sequence[KeyShape] = (),
                    weights: Sequence[float] = (), sizes: Sequence[float] | None = None,
                    controls: int | None = None) -> LobeMorphPath:
    """The margin-space morph path of :func:`lobe_morph` (same arguments, no frame count)."""
    refs = list(references)
    w = [1.0] * len(refs) if len(weights) == 0 else list(weights)
    if len(w) != len(refs):
        raise ParamError("weights", f"expected {len(refs)} weights (one per reference), got {len(w)}")
    for i, x in enumerate(w):
        if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(float(x)) and float(x) >= 0.0):
            raise ParamError(f"weights[{i}]", f"must be a finite number >= 0, got {x!r}")
    keys = [_resolve(source, "source")]
    keys += [_resolve(r, f"references[{i}]") for i, r in enumerate(refs)]
    keys.append(_resolve(target, "target"))
    if sizes is None:
        sizes = [k.transform.scale if isinstance(k, LeafParams) else 1.0 for k in keys]
    size = key_sizes(sizes, w)
    kept = [keys[0]] + [keys[1 + i] for i, x in enumerate(w) if float(x) != 0.0] + [keys[-1]]
    kw = np.array([1.0] + [float(x) for x in w if float(x) != 0.0] + [1.0])
    if controls is None:
        own = [len(k.lobes.outline) for k in keys if is_lobed(k)]  # type: ignore[union-attr]
        controls = min(MAX_CONTROLS, max([DEFAULT_CONTROLS] + own))
    m = _check_controls(controls)
    margins = np.stack([closed_margin(k, m) for k in kept])
    names = [getattr(k, "name", "") or "leaf" for k in (keys[0], keys[-1])]
    return LobeMorphPath(margins, kw, size, _frame_template(keys), name=f"{names[0]}->{names[1]}")


def lobe_morph(source: KeyShape, target: KeyShape, steps: int, *, references: Sequence[KeyShape] = (),
               weights: Sequence[float] = (), sizes: Sequence[float] | None = None,
               controls: int | None = None) -> list[LeafParams]:
    """Frames of the morph from ``source`` to ``target``, unilobed or lobed (Fig. 13).

    Parameters
    ----------
    source, target : LeafParams, LandmarkLeaf or str
        Key shapes: unilobed or lobed leaves, landmark leaves, catalogue names or preset names
        (``"maple"``: :func:`load_key_shape`).
    steps : int
        Frames, ends included (2 to ``MAX_MORPH_FRAMES``), evenly spaced along the path.
    references : sequence
        Ordered reference shapes R_1..R_n (soft constraints of eq. 11).
    weights : sequence of float
        One weight ≥ 0 per reference (default 1 each; 0 drops the reference).
    sizes : sequence of float or None
        Leaf length per key shape (source, references..., target), > 0: growth with size
        (Figs 12-13), interpolated along the path into ``transform.scale``. None: each key's own
        ``transform.scale`` (1 for landmark leaves and names of catalogue shapes).
    controls : int or None
        Control points of the shared margin (default: the most any lobed key has, at least
        :data:`DEFAULT_CONTROLS`).

    Returns
    -------
    list of LeafParams
        ``steps`` lobed leaves; frame 0 and frame ``steps - 1`` carry the source and target
        margins as :func:`closed_margin` fits them.
    """
    n = _check_steps(steps)
    return lobe_morph_path(source, target, references=references, weights=weights, sizes=sizes,
                           controls=controls).frames(n)
