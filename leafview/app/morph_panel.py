"""The viewer's morph panel: pick a source, a target and an optional weighted reference shape from
the botanical catalogue and drag ``t`` along the morph path (Garg & Leow 2011, eq. 11).

:class:`MorphController` holds the choice and turns ``t`` into a leaf shape (no imgui, testable on
its own): the path's frame at ``t`` (evenly spaced along the path's arc length) is fitted to the
shader model and replaces only the leaf's ``shape``, so colours, ripples and bending stay as the
user set them. While the slider is dragged the fast linear fit is used (tens of ms); on release the
polished fit (the catalogue's accuracy, under 1 % of the leaf length) replaces it in the same undo
step. :class:`MorphPanel` draws the widgets.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

from imgui_bundle import imgui

from leafview.app.state import ViewerState
from leafview.botany.catalogue import catalogue_names
from leafview.botany.morph import morph_path
from leafview.core.params import Shape
from leafview.gpu.morph import fit_frame

__all__ = ["MorphController", "MorphPanel"]

NO_REFERENCE = "(none)"


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


@dataclass
class MorphController:
    """Source, target, reference (name and weight) and the position ``t`` on the morph path."""

    state: ViewerState
    source: str = "lanceolate"
    target: str = "cordate"
    reference: str = NO_REFERENCE
    weight: float = 1.0
    t: float = 0.0
    last_error: float | None = field(default=None, init=False)

    @staticmethod
    def names() -> tuple[str, ...]:
        return _names()

    def shape_at(self, t: float, *, polish: bool = True) -> Shape:
        """The fitted shader-model shape of the path's frame at ``t`` (cached by t to 1e-3)."""
        t = min(1.0, max(0.0, round(float(t), 3)))
        shape, err = _fit(self.source, self.target, self.reference, float(self.weight), t, polish)
        self.last_error = err
        return shape

    def set_t(self, t: float, *, dragging: bool = False) -> bool:
        """Move to ``t`` and give the leaf that frame's shape (one undo step per drag)."""
        self.t = min(1.0, max(0.0, float(t)))
        shape = self.shape_at(self.t, polish=not dragging)
        return self.state.apply(lambda p: p.replace(shape=shape), gesture="morph")

    def end_drag(self) -> None:
        """Release: the polished fit replaces the fast one, still within the drag's undo step."""
        self.set_t(self.t, dragging=False)
        self.state.end_gesture()

    def choose(self, **changes: str | float) -> bool:
        """Change ``source``, ``target``, ``reference`` or ``weight`` and re-apply the frame at t."""
        for key, value in changes.items():
            if key in ("source", "target") and value not in _names():
                raise ValueError(f"{key}: unknown catalogue shape {value!r}")
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
        if not imgui.collapsing_header("Morph (catalogue shapes)##group-morph"):
            return
        c = self.controller
        names = list(c.names())
        self._combo("source", "from", names)
        self._combo("target", "to", names)
        self._combo("reference", "through", [NO_REFERENCE] + names)
        if c.reference != NO_REFERENCE:
            changed, w = imgui.slider_float("weight##morph-weight", float(c.weight), 0.0, 8.0, "%.2f")
            self._record("morph.weight")
            if changed:
                c.weight = float(w)
            if imgui.is_item_deactivated_after_edit():   # re-fit once, on release
                c.choose(weight=c.weight)
        changed, t = imgui.slider_float("t##morph-t", float(c.t), 0.0, 1.0, "%.3f")
        self._record("morph.t")
        if changed:
            c.set_t(t, dragging=imgui.is_item_active())
        if imgui.is_item_deactivated():
            c.end_drag()
        if c.last_error is not None:
            imgui.text_disabled(f"fit error {100 * c.last_error:.2f} % of the leaf length")
