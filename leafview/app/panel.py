"""The parameter panel: one imgui widget per field of :func:`~leafview.core.params.field_specs`,
grouped by ``FieldSpec.group``, plus the sec. 6 edit sliders, the view settings and the wind
(a **Wind** header: *play wind* and sliders for speed, direction, gustiness and flutter; the leaf
moves live while it plays).

Nothing here knows the parameter groups by name: a group added to ``LeafParams`` (ripple,
bending, ...) gets a collapsing header and widgets from its metadata (label, soft range, step,
kind). Every change goes through :class:`~leafview.app.state.ViewerState`; a slider drag is one
undo step (a *gesture* that ends when the widget is released).

:attr:`ParamPanel.rects` records where each widget was drawn (by field path), which is how the
tests click and drag the real widgets through imgui's input queue.
"""

from __future__ import annotations

import math
import unicodedata
from collections.abc import Callable, Sequence
from typing import Any, Literal

import numpy as np
from imgui_bundle import imgui

from leafview.app.lobe_panel import LobePanel
from leafview.app.photo_reference import close_photo, fit_reference, report_line
from leafview.app.state import ViewerState
from leafview.app.wind_panel import wind_widgets
from leafview.botany.shapes import omega_of_margin
from leafview.core.edits import curve_axis, curve_longitudinal, scale_width, skew_axis
from leafview.core.params import FieldSpec, LeafParams

__all__ = ["ParamPanel", "decimals", "groups_of", "from_ui", "plain_label", "OMEGA_ONLY"]

_OPEN_BY_DEFAULT = {"axis", "silhouette", "curvature", "jitter", "ripple", "bending", "material", "lobes"}
#: groups that shape only the unilobed Ω: a lobed leaf (its sweep) ignores them, so they are hidden
OMEGA_ONLY = ("axis", "silhouette", "curvature", "jitter", "bending", "venation")


def decimals(step: float) -> int:
    """Digits after the decimal point that show a slider's ``step``."""
    if step <= 0 or not math.isfinite(step) or step >= 1:
        return 0
    return min(6, int(math.ceil(-math.log10(step) - 1e-9)))


def groups_of(specs: dict[str, FieldSpec]) -> dict[str, list[str]]:
    """Field paths by ``spec.group``, groups in order of first appearance."""
    out: dict[str, list[str]] = {}
    for path, spec in specs.items():
        out.setdefault(spec.group, []).append(path)
    return out


def plain_label(text: str) -> str:
    """``text`` without combining marks (for fonts that lack them: v̄ becomes v)."""
    return "".join(c for c in unicodedata.normalize("NFD", text) if not unicodedata.combining(c))


def _numbers(value: Any) -> list[float] | None:
    """``value`` as a list of floats if it is a flat tuple/list of numbers, else None."""
    if isinstance(value, (tuple, list)) and value and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
        return [float(x) for x in value]
    return None


def from_ui(old: Any, new: Any) -> Any:
    """A value returned by an imgui widget, cleaned: imgui edits float32 copies, so components
    the user did not change come back rounded (1/3 → 0.3333333432674408). Those keep their old
    value; changed ones get the shortest decimal of their float32 (0.10000000149 → 0.1)."""
    if isinstance(new, (list, tuple)):
        olds = list(old) if isinstance(old, (list, tuple)) and len(old) == len(new) else [None] * len(new)
        return [from_ui(o, n) for o, n in zip(olds, new)]
    if isinstance(new, float) and math.isfinite(new):
        if isinstance(old, (int, float)) and not isinstance(old, bool) and np.float32(old) == np.float32(new):
            return old
        return float(str(np.float32(new)))
    return new


def _is_rows(value: Any) -> bool:
    return isinstance(value, (tuple, list)) and bool(value) and all(_numbers(r) is not None for r in value)


Longitudinal = Literal["S", "F", "G"]


def _longitudinal_edit(curve: Longitudinal) -> Callable[[LeafParams, float], LeafParams]:
    """The curvature edit of one longitudinal curve (S, F or G) as a slider's edit function."""
    return lambda p, z: curve_longitudinal(p, curve, z)


class ParamPanel:
    """Draws the parameter widgets inside the current imgui window.

    Parameters
    ----------
    state:
        The shared viewer state every widget edits.
    unicode_labels:
        False when the loaded font has no combining marks: labels are shown without them.
    """

    def __init__(self, state: ViewerState, *, unicode_labels: bool = True) -> None:
        self.state = state
        self.unicode_labels = unicode_labels
        self.rects: dict[str, tuple[float, float, float, float]] = {}
        self._relative: dict[str, float] = {"width": 1.0, "skew": 0.0}
        self._base: dict[str, LeafParams] = {}
        self.expand_all = False  # open every header (tests, documentation screenshots)
        self.lobes = LobePanel(state, self.draw_field, self._record)

    def label(self, text: str, path: str) -> str:
        shown = text if self.unicode_labels else plain_label(text)
        return f"{shown}##{path}"

    def _record(self, key: str) -> None:
        """Remember the widget's frame (without its label) under ``key``."""
        lo, hi = imgui.get_item_rect_min(), imgui.get_item_rect_max()
        self.rects[key] = (lo.x, lo.y, min(hi.x, lo.x + imgui.calc_item_width()), hi.y)

    def _after_widget(self, key: str) -> None:
        self._record(key)
        if imgui.is_item_deactivated():
            self.state.end_gesture()

    # -- fields from their metadata -------------------------------------------------------------
    def draw_field(self, path: str, spec: FieldSpec) -> None:
        """One widget for ``path``, chosen by ``spec.kind`` and, for kinds this panel does not
        name, by the shape of the value (a tuple of 2-4 numbers gets a slider per component)."""
        state = self.state
        value = state.get(path)
        lo, hi = (float(x) for x in spec.soft_range)
        fmt = f"%.{decimals(spec.step)}f"
        label = self.label(spec.label, path)
        kind = spec.kind
        vector = _numbers(value)
        new: bool | int | float | str | list[float]
        if kind == "choice" and spec.choices:
            current = spec.choices.index(value) if value in spec.choices else 0
            changed, index = imgui.combo(label, current, list(spec.choices))
            new = spec.choices[index]
        elif kind == "bool" or isinstance(value, bool):
            changed, new = imgui.checkbox(label, bool(value))
        elif kind == "int" or (isinstance(value, int) and kind != "float"):
            changed, new = imgui.slider_int(label, int(value), int(lo), int(hi))
        elif kind == "float" or isinstance(value, (int, float)):
            changed, new = imgui.slider_float(label, float(value), lo, hi, fmt)
        elif kind == "color" and vector is not None and len(vector) == 3:
            changed, new = imgui.color_edit3(label, vector, imgui.ColorEditFlags_.float)
        elif kind == "rows" or _is_rows(value):
            self._draw_rows(path, spec, value, fmt)
            return
        elif vector is not None and 2 <= len(vector) <= 4:
            slider = {2: imgui.slider_float2, 3: imgui.slider_float3, 4: imgui.slider_float4}[len(vector)]
            changed, new = slider(label, vector, lo, hi, fmt)
        else:  # a kind this panel cannot edit: show it, never crash
            imgui.text_disabled(f"{plain_label(spec.label)}: {value!r} ({kind})")
            self._record(path)
            return
        if changed:
            state.set_field(path, from_ui(value, new), gesture=not isinstance(new, bool))
        self._after_widget(path)
        self._tooltip(path, spec)

    @staticmethod
    def _tooltip(path: str, spec: FieldSpec) -> None:
        if imgui.is_item_hovered(imgui.HoveredFlags_.for_tooltip):
            lo, hi = spec.soft_range
            imgui.set_tooltip(f"{spec.label}\n{path}: slider {lo:g} … {hi:g}, step {spec.step:g}\n"
                              "Ctrl+click to type a value")

    def _draw_rows(self, path: str, spec: FieldSpec, value: Any, fmt: str) -> None:
        lo, hi = spec.soft_range
        imgui.text(spec.label if self.unicode_labels else plain_label(spec.label))
        rows = [list(map(float, r)) for r in value]
        prefix = "S" if spec.group == "silhouette" else "row "
        for i, row in enumerate(rows):
            key = f"{path}[{i}]"
            slider = {2: imgui.slider_float2, 3: imgui.slider_float3, 4: imgui.slider_float4}.get(len(row))
            if slider is None:
                imgui.text_disabled(f"{prefix}{i + 1}: {row}")
                continue
            changed, new = slider(f"{prefix}{i + 1}##{key}", row, float(lo), float(hi), fmt)
            if changed:
                rows[i] = from_ui(row, new)
                self.state.set_field(path, rows, gesture=True)
            self._after_widget(key)

    def draw_groups(self) -> None:
        """A collapsing header per parameter group, in field_specs order."""
        specs = self.state.specs()
        lobed = self.state.params.lobes.enabled
        if lobed:
            imgui.push_text_wrap_pos(0.0)
            imgui.text_disabled(f"lobed leaf: the groups {', '.join(OMEGA_ONLY)} shape only the unilobed Ω "
                                "and are hidden")
            imgui.pop_text_wrap_pos()
            self._record("hidden-groups")
        if self.state.params.margin is not None:
            self.draw_margin_note()
        for group, paths in groups_of(specs).items():
            if lobed and group in OMEGA_ONLY:
                continue
            if self.expand_all:
                imgui.set_next_item_open(True, imgui.Cond_.always)
            elif group in _OPEN_BY_DEFAULT:
                imgui.set_next_item_open(True, imgui.Cond_.first_use_ever)
            if imgui.collapsing_header(f"{group.capitalize()}##group-{group}"):
                imgui.push_id(group)
                if group == "lobes" and lobed:
                    self.lobes.expand_all = self.expand_all
                    self.lobes.draw(specs)
                else:
                    if group == "lobes":
                        imgui.text_disabled("not a lobed leaf (no margin): open maple, oak or bilobed")
                    for path in paths:
                        self.draw_field(path, specs[path])
                imgui.pop_id()

    def draw_margin_note(self) -> None:
        """A leaf drawn with its landmark margin (leafview.core.margin): the silhouette rows below
        are not drawn; a button replaces the margin by Ω fitted to it, whose rows can be edited."""
        imgui.push_text_wrap_pos(0.0)
        imgui.text_disabled("landmark margin (Garg & Leow 2011): the shader draws the B-spline itself, so the "
                            "silhouette rows are not drawn; axis, heights, width and the other groups apply")
        imgui.pop_text_wrap_pos()
        self._record("margin-note")
        if imgui.button("Fit Ω to the margin (edit its rows)##margin-fit"):
            self.state.apply(lambda p: omega_of_margin(p).params)   # one undo step
        self._record("margin:fit")

    # -- the artist edits of sec. 6 -------------------------------------------------------------
    def _relative_slider(self, key: str, label: str, lo: float, hi: float, fmt: str,
                         edit: Callable[[LeafParams, float], LeafParams]) -> None:
        """A slider relative to the leaf at the start of the drag; it springs back on release."""
        changed, value = imgui.slider_float(f"{label}##edit-{key}", self._relative[key], lo, hi, fmt)
        if changed:
            value = from_ui(None, value)
            base = self._base.setdefault(key, self.state.params)
            self._relative[key] = value
            self.state.apply(lambda _: edit(base, value), gesture=f"edit:{key}")
        self._record(f"edit:{key}")
        if imgui.is_item_deactivated():
            self.state.end_gesture()
            self._base.pop(key, None)
            self._relative[key] = 1.0 if key == "width" else 0.0

    def _absolute_slider(self, key: str, label: str, value: float,
                         edit: Callable[[LeafParams, float], LeafParams]) -> None:
        changed, new = imgui.slider_float(f"{label}##edit-{key}", float(value), -0.3, 0.3, "%.3f")
        if changed:
            new = from_ui(value, new)
            self.state.apply(lambda p: edit(p, new), gesture=f"edit:{key}")
        self._after_widget(f"edit:{key}")

    def draw_edits(self) -> None:
        """Width scaling, asymmetry and curvature sliders (Chaurasia & Beardsley 2017, sec. 6, Fig. 7)."""
        imgui.set_next_item_open(True, imgui.Cond_.always if self.expand_all else imgui.Cond_.first_use_ever)
        if not imgui.collapsing_header("Edits (Chaurasia & Beardsley 2017 sec. 6)##group-edits"):
            return
        if self.state.params.lobes.enabled:
            imgui.push_text_wrap_pos(0.0)
            imgui.text_disabled("width, asymmetry and curvature edits act on the unilobed Ω (hidden): for a "
                                "lobed leaf drag its tips and valleys, and use the turtle curves of the Lobes group")
            imgui.pop_text_wrap_pos()
            self._record("edit:lobed")
            return
        sh = self.state.params.shape
        self._relative_slider("width", "width ×", 0.25, 2.5, "×%.2f", scale_width)
        self._relative_slider("skew", "asymmetry (skew axis)", -0.3, 0.3, "%+.3f", skew_axis)
        self._absolute_slider("axis", "axis curvature", (sh.a1[2] + sh.a2[2]) / 2, curve_axis)
        curves: tuple[tuple[Longitudinal, Sequence[float]], ...] = (
            ("S", [r[2] for r in sh.silhouette]), ("F", sh.zf), ("G", sh.zg))
        for curve, zs in curves:
            self._absolute_slider(f"curve{curve}", f"{curve} curvature (z̄{curve.lower()})"
                                  if self.unicode_labels else f"{curve} curvature (z{curve.lower()})",
                                  sum(zs) / 3, _longitudinal_edit(curve))
        imgui.text_disabled("drag the white handles in the viewport:\na1, a2 skew the axis; s1..sN shape the outline")

    # -- the reference photo (Garg & Leow 2011, Fig. 1) ---------------------------------------
    def draw_reference(self) -> None:
        """Opacity, show/hide, the base and apex points handed to the fit, Fit and its report.
        Drawn only while a photo is open (Open… accepts PNG, JPEG and TIFF)."""
        ref = self.state.reference
        if ref.path is None:
            return
        imgui.set_next_item_open(True, imgui.Cond_.always if self.expand_all else imgui.Cond_.first_use_ever)
        if not imgui.collapsing_header("Reference photo##group-reference"):
            return
        w, h = ref.size
        dpi = f", {ref.dpi:g} dpi" if ref.dpi else ""
        imgui.text_disabled(f"{ref.path.name}: {w}×{h} px{dpi}{', fitted' if ref.fitted else ''}")
        _, ref.visible = imgui.checkbox("show##reference", ref.visible)
        self._record("reference.visible")
        changed, opacity = imgui.slider_float("opacity##reference", ref.opacity, 0.0, 1.0, "%.2f")
        if changed:
            ref.opacity = float(min(max(opacity, 0.0), 1.0))
        self._record("reference.opacity")
        for key, label in (("base_px", "base (px)"), ("apex_px", "apex (px)")):
            point = getattr(ref, key)
            if point is None:
                continue
            changed, new = imgui.drag_float2(f"{label}##reference", list(point), 0.5, 0.0, float(max(w, h)), "%.1f")
            if changed:
                setattr(ref, key, (float(min(max(new[0], 0.0), w - 1.0)), float(min(max(new[1], 0.0), h - 1.0))))
            self._record(f"reference.{key}")
        if imgui.button("Fit##reference"):
            fit_reference(self.state)
        self._record("reference.fit")
        if imgui.is_item_hovered():
            imgui.set_tooltip("fit the leaf to the photo from these base and apex points (undoable)")
        imgui.same_line()
        if imgui.button("Close photo##reference"):
            close_photo(self.state)
        self._record("reference.close")
        if ref.report:
            imgui.text(report_line(ref.report))
        for line in ref.warnings:
            imgui.push_text_wrap_pos(0.0)
            imgui.text_disabled(line)
            imgui.pop_text_wrap_pos()
        imgui.text_disabled("drag the orange (base) and blue (apex) points\nand the white handles over the photo")

    # -- view settings (not saved with the leaf) ------------------------------------------------
    def draw_wind(self) -> None:
        """The leaf in the wind (:mod:`leafview.app.wind_panel`): play/pause, speed, direction,
        gustiness and flutter; not saved with the leaf."""
        if self.expand_all:
            imgui.set_next_item_open(True, imgui.Cond_.always)
        if not imgui.collapsing_header("Wind##group-wind"):
            return
        view = self.state.view
        view.wind, view.wind_playing, err = wind_widgets(view.wind, view.wind_playing, "view-wind")
        self._record("view.wind")
        if err:
            self.state.error = err

    def draw_view(self) -> None:
        """Light direction, grid resolution and viewport toggles."""
        if self.expand_all:
            imgui.set_next_item_open(True, imgui.Cond_.always)
        if not imgui.collapsing_header("View##group-view"):
            return
        view = self.state.view
        _, view.light_azimuth = imgui.slider_float("light azimuth##view", view.light_azimuth, -180.0, 180.0, "%.0f°")
        self._record("view.light_azimuth")
        _, view.light_elevation = imgui.slider_float("light elevation##view", view.light_elevation, -90.0, 90.0,
                                                     "%.0f°")
        self._record("view.light_elevation")
        changed, grid = imgui.slider_int2("grid (u, v)##view", list(view.grid), 3, 257)
        self._record("view.grid")
        if changed:
            view.grid = (max(3, min(257, int(grid[0]))), max(3, min(513, int(grid[1]))))
        _, view.wireframe = imgui.checkbox("wireframe (W)##view", view.wireframe)
        self._record("view.wireframe")
        _, view.show_controls = imgui.checkbox("control polygons + handles (C)##view", view.show_controls)
        self._record("view.show_controls")
        _, view.show_ground = imgui.checkbox("ground grid (G)##view", view.show_ground)
        self._record("view.show_ground")
