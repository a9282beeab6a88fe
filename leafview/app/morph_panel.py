"""The viewer's morph panel: pick a source, a target and an optional weighted reference shape from
the botanical catalogue and drag ``t`` along the morph path (Garg & Leow 2011, eq. 11).

:class:`MorphController` holds the choice and turns ``t`` into a leaf shape (no imgui, testable on
its own): the path's frame at ``t`` (evenly spaced along the path's arc length) is fitted to the
shader model and replaces only the leaf's ``shape``, so colours, ripples and bending stay as the
user set them. While the slider is dragged the fast linear fit is used (tens of ms); on release the
polished fit (the catalogue's accuracy, under 1 % of the leaf length) replaces it in the same undo
step. With *exact margins* the frame's landmark margin itself becomes the leaf's silhouette
(:mod:`leafview.core.margin`): nothing is fitted, dragging and release give the same leaf.
:class:`MorphPanel` draws the widgets.

The target may also be a lobed preset (maple, oak, bilobed: Garg & Leow 2011, Fig. 13): the frame
is then the margin-space morph of :mod:`leafview.botany.lobe_morph` and replaces the leaf's
``lobes`` (its closed margin) instead of its shape. The *grow* toggle (Figs 12-13, growth with
size) sets ``transform.scale`` from :data:`GROWTH_SIZES` (source, reference, target) along the path.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any

from imgui_bundle import imgui

from leafview.app.state import ViewerState
from leafview.botany.catalogue import catalogue_names
from leafview.botany.landmarks import margins
from leafview.botany.lobe_morph import is_lobed, load_key_shape, lobe_morph_path
from leafview.botany.morph import key_sizes, morph_path
from leafview.core.lobes import Lobes
from leafview.core.margin import Margin
from leafview.core.params import LeafParams, ParamError, Shape
from leafview.gpu.morph import fit_frame
from leafview.resources import builtin_presets

__all__ = ["MorphController", "MorphPanel", "LOBED_TARGETS", "GROWTH_SIZES"]

NO_REFERENCE = "(none)"
LOBED_TARGETS = ("maple", "oak", "bilobed")   # lobed presets offered as targets, when installed
GROWTH_SIZES = (0.35, 0.65, 1.0)              # leaf size at the source, the reference and the target


@lru_cache(maxsize=1)
def _lobed_names() -> tuple[str, ...]:
    presets = builtin_presets()
    out = []
    for name in LOBED_TARGETS:
        try:
            if name in presets and is_lobed(load_key_shape(name)):
                out.append(name)
        except ParamError:
            continue
    return tuple(out)


def _sizes(ref: str, grow: bool) -> list[float] | None:
    if not grow:
        return None
    return [GROWTH_SIZES[0], GROWTH_SIZES[2]] if ref == NO_REFERENCE else list(GROWTH_SIZES)


@lru_cache(maxsize=8)
def _lobe_path(source: str, target: str, ref: str, weight: float, grow: bool) -> Any:

    refs = [] if ref == NO_REFERENCE else [ref]
    return lobe_morph_path(source, target, references=refs, weights=[weight] * len(refs), sizes=_sizes(ref, grow))


@lru_cache(maxsize=256)
def _lobe_frame(source: str, target: str, ref: str, weight: float, grow: bool, t: float) -> LeafParams:

    return _lobe_path(source, target, ref, weight, grow).frame(t)


@lru_cache(maxsize=1)
def _names() -> tuple[str, ...]:

    return tuple(catalogue_names())


@lru_cache(maxsize=16)
def _path(source: str, target: str, ref: str, weight: float) -> Any:

    refs = [] if ref == NO_REFERENCE else [(ref, weight)]
    return morph_path(source, target, refs)


@lru_cache(maxsize=256)
def _fit(source: str, target: str, ref: str, weight: float, t: float, polish: bool) -> tuple[Shape, float]:

    fit = fit_frame(_path(source, target, ref, weight).sample(t), polish=polish)
    return fit.parts[0].shape, fit.error   # catalogue shapes and their morphs are symmetric: one leaf


@lru_cache(maxsize=256)
def _margin(source: str, target: str, ref: str, weight: float, t: float) -> Margin:

    return margins([_path(source, target, ref, weight).sample(t)])[0]


def _quartic(shape: Shape) -> Shape:
    """``shape`` itself, or the paper's quartic with its midrib when it is extended (a leaf drawn
    with a landmark margin takes its heights from three rows)."""
    return replace(Shape(), a1=shape.a1, a2=shape.a2) if shape.extended else shape


@dataclass
class MorphController:
    """Source, target, reference (name and weight) and the position ``t`` on the morph path."""

    state: ViewerState
    source: str = "lanceolate"
    target: str = "cordate"
    reference: str = NO_REFERENCE
    weight: float = 1.0
    t: float = 0.0
    grow: bool = False
    exact: bool = False     # draw each frame's landmark margin itself (leafview.core.margin): no fit
    last_error: float | None = field(default=None, init=False)
    _lobes_set: bool = field(default=False, init=False, repr=False)

    @staticmethod
    def names() -> tuple[str, ...]:
        return _names()

    @staticmethod
    def targets() -> tuple[str, ...]:
        """Catalogue shapes, then the installed lobed presets (:data:`LOBED_TARGETS`)."""
        return _names() + _lobed_names()

    @property
    def lobed(self) -> bool:
        """The target is a lobed preset: frames are lobed margins."""
        return self.target in _lobed_names()

    def size_at(self, t: float) -> float | None:
        """The leaf size at ``t`` with *grow* on (None when off)."""
        if not self.grow:
            return None
        t = min(1.0, max(0.0, round(float(t), 3)))
        if self.lobed:
            return _lobe_frame(self.source, self.target, self.reference, float(self.weight), True, t).transform.scale
        path = _path(self.source, self.target, self.reference, float(self.weight))
        weights = [] if self.reference == NO_REFERENCE else [float(self.weight)]
        sizes = key_sizes(_sizes(self.reference, True) or [], weights)
        return float(path.values_at(sizes, path.parameter([t]))[0])

    def lobes_at(self, t: float) -> Lobes:
        """The lobed frame's ``lobes`` at ``t`` (lobed targets only)."""
        t = min(1.0, max(0.0, round(float(t), 3)))
        self.last_error = None
        return _lobe_frame(self.source, self.target, self.reference, float(self.weight), self.grow, t).lobes

    def shape_at(self, t: float, *, polish: bool = True) -> Shape:
        """The fitted shader-model shape of the path's frame at ``t`` (cached by t to 1e-3)."""
        t = min(1.0, max(0.0, round(float(t), 3)))
        shape, err = _fit(self.source, self.target, self.reference, float(self.weight), t, polish)
        self.last_error = err
        return shape

    def set_t(self, t: float, *, dragging: bool = False) -> bool:
        """Move to ``t`` and give the leaf that frame's shape (one undo step per drag)."""
        self.t = min(1.0, max(0.0, float(t)))
        size = self.size_at(self.t)
        if self.lobed:
            lobes = self.lobes_at(self.t)

            def edit(p: LeafParams) -> LeafParams:
                return p.replace(lobes=lobes, margin=None)
        elif self.exact:
            t = min(1.0, max(0.0, round(float(self.t), 3)))
            margin = _margin(self.source, self.target, self.reference, float(self.weight), t)
            self.last_error = 0.0

            def edit(p: LeafParams) -> LeafParams:
                return p.replace(shape=_quartic(p.shape), margin=margin, lobes=Lobes() if self._lobes_set else p.lobes)
        else:
            shape = self.shape_at(self.t, polish=not dragging)

            def edit(p: LeafParams) -> LeafParams:   # back from a lobed target: unlobed again
                return p.replace(shape=shape, margin=None, lobes=Lobes() if self._lobes_set else p.lobes)

        def apply(p: LeafParams) -> LeafParams:
            q = edit(p)
            return q if size is None else q.replace(transform=replace(q.transform, scale=size))

        changed = self.state.apply(apply, gesture="morph")
        self._lobes_set = self.lobed
        return changed

    def end_drag(self) -> None:
        """Release: the polished fit replaces the fast one, still within the drag's undo step."""
        self.set_t(self.t, dragging=False)
        self.state.end_gesture()

    def choose(self, **changes: str | float | bool) -> bool:
        """Change ``source``, ``target``, ``reference``, ``weight`` or ``grow`` and re-apply the
        frame at t."""
        for key, value in changes.items():
            if key == "source" and value not in _names():
                raise ValueError(f"{key}: unknown catalogue shape {value!r}")
            if key == "target" and value not in self.targets():
                raise ValueError(f"{key}: unknown catalogue shape or lobed preset {value!r}")
            if key in ("grow", "exact"):
                value = bool(value)
            if key == "reference" and value != NO_REFERENCE and value not in _names():
                raise ValueError(f"reference: unknown catalogue shape {value!r}")
            if key == "weight" and not (0.0 <= float(value) <= 100.0):
                raise ValueError(f"weight must lie in 0..100, got {value}")
            setattr(self, key, value)
        changed = self.set_t(self.t)
        self.state.end_gesture()
        return changed


class MorphPanel:
    """imgui widgets of :class:`MorphController`, in a collapsing header of the viewer's panel."""

    def __init__(self, state: ViewerState) -> None:
        self.controller = MorphController(state)
        self.rects: dict[str, tuple[float, float, float, float]] = {}
        self.expand_all = False

    def _record(self, key: str) -> None:

        lo, hi = imgui.get_item_rect_min(), imgui.get_item_rect_max()
        self.rects[key] = (lo.x, lo.y, min(hi.x, lo.x + imgui.calc_item_width()), hi.y)

    def _combo(self, key: str, label: str, items: list[str]) -> None:

        c = self.controller
        current = getattr(c, key)
        changed, index = imgui.combo(f"{label}##morph-{key}", items.index(current), items)
        self._record(f"morph.{key}")
        if changed and items[index] != current:
            c.choose(**{key: items[index]})

    def draw(self) -> None:

        flags = imgui.Cond_.always if self.expand_all else imgui.Cond_.first_use_ever
        imgui.set_next_item_open(self.expand_all, flags)
        if not imgui.collapsing_header("Morph (catalogue shapes, lobed)##group-morph"):
            return
        c = self.controller
        names = list(c.names())
        self._combo("source", "from", names)
        self._combo("target", "to", list(c.targets()))
        self._combo("reference", "through", [NO_REFERENCE] + names)
        if c.reference != NO_REFERENCE:
            changed, w = imgui.slider_float("weight##morph-weight", float(c.weight), 0.0, 8.0, "%.2f")
            self._record("morph.weight")
            if changed:
                c.weight = float(w)
            if imgui.is_item_deactivated_after_edit():   # re-fit once, on release
                c.choose(weight=c.weight)
        changed, grow = imgui.checkbox("grow (size along the path)##morph-grow", c.grow)
        self._record("morph.grow")
        if changed:
            c.choose(grow=grow)
        if not c.lobed:
            changed, exact = imgui.checkbox("exact margins (no fit)##morph-exact", c.exact)
            self._record("morph.exact")
            if changed:
                c.choose(exact=exact)
        changed, t = imgui.slider_float("t##morph-t", float(c.t), 0.0, 1.0, "%.3f")
        self._record("morph.t")
        if changed:
            c.set_t(t, dragging=imgui.is_item_active())
        if imgui.is_item_deactivated():
            c.end_drag()
        if c.exact and not c.lobed:
            imgui.text_disabled("each frame drawn from its landmark margin: exact, nothing fitted")
        elif c.last_error is not None:
            imgui.text_disabled(f"fit error {100 * c.last_error:.2f} % of the leaf length")
