"""The ``lobes`` group of the panel for a lobed leaf: pruning and cupping sliders, and for every
skeleton branch three small curve editors, the extra bend, twist and turn rates of the turtle
along the branch (Mündermann et al. 2003, sec. 4, eqs 2-3: the per-branch functions).

Each curve is the four knots of a :class:`~leafview.core.lobes.BranchTurtle` (s = 0, 1/3, 2/3, 1
of the branch, linear between them). Pressing in a curve's plot grabs the knot nearest the mouse
(in s) and dragging sets its value; the drag is one undo step. The first edit of a branch adds
its ``BranchTurtle`` to ``lobes.branches``, an edit that leaves all three curves at zero removes
it. Branches are numbered as ``leafview.core.lobes`` documents (0 the main branch, the others by
their tips clockwise from the base), from ``leafview.botany.lobe_skeleton.skeleton``.

The plot geometry and the edits are plain functions (:func:`knot_positions`,
:func:`knot_from_mouse`, :func:`with_branch_knots`), so the tests drive them without a window.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from imgui_bundle import imgui
from numpy.typing import NDArray

from leafview.app.state import ViewerState, with_field
from leafview.botany.lobe_skeleton import skeleton
from leafview.core.lobes import TURTLE_KNOTS, Lobes, turtle_dict, turtle_specs
from leafview.core.params import FieldSpec, LeafParams, ParamError

__all__ = ["CURVES", "LobePanel", "branch_knots", "with_branch_knots", "curve_range", "knot_positions",
           "knot_from_mouse", "PLOT_HEIGHT"]

CURVES = ("bend", "twist", "turn")
PLOT_HEIGHT = 54.0
_KNOT_S = np.linspace(0.0, 1.0, TURTLE_KNOTS)
Rect = tuple[float, float, float, float]


def branch_knots(lobes: Lobes, branch: int, curve: str) -> tuple[float, ...]:
    """The four knots of ``curve`` (bend, twist or turn) of skeleton branch ``branch`` (zeros
    when the branch has no edit)."""
    if curve not in CURVES:
        raise ParamError(f"lobes.branches.{curve}", f"unknown curve (known: {', '.join(CURVES)})")
    for b in lobes.branches:
        if b.branch == branch:
            return tuple(float(x) for x in getattr(b, curve))
    return (0.0,) * TURTLE_KNOTS


def with_branch_knots(params: LeafParams, branch: int, curve: str, knots: Sequence[float]) -> LeafParams:
    """``params`` with ``curve`` of branch ``branch`` set to ``knots`` (validated): adds the
    branch's :class:`BranchTurtle` on its first edit, removes it when all its curves are zero."""
    if curve not in CURVES:
        raise ParamError(f"lobes.branches.{curve}", f"unknown curve (known: {', '.join(CURVES)})")
    knots = [float(x) for x in knots]
    if len(knots) != TURTLE_KNOTS:
        raise ParamError(f"lobes.branches.{curve}", f"expected {TURTLE_KNOTS} knots, got {len(knots)}")
    rows = [turtle_dict(b) for b in params.lobes.branches]
    row = next((r for r in rows if r["branch"] == branch), None)
    if row is None:
        row = {"branch": int(branch), **{c: [0.0] * TURTLE_KNOTS for c in CURVES}}
        rows.append(row)
    row[curve] = knots
    if all(x == 0.0 for c in CURVES for x in row[c]):
        rows.remove(row)
    rows.sort(key=lambda r: r["branch"])
    return with_field(params, "lobes.branches", rows)


def curve_range(spec: FieldSpec, knots: Sequence[float]) -> tuple[float, float]:
    """The plot's value range: the field's soft range, widened to show every knot."""
    lo, hi = (float(x) for x in spec.soft_range)
    return min(lo, *knots), max(hi, *knots)


def knot_positions(rect: Rect, lo: float, hi: float, knots: Sequence[float]) -> NDArray[np.float64]:
    """Screen positions (4, 2) of the knots in the plot ``rect`` (x0, y0, x1, y1): s across,
    the value up (``hi`` at the top)."""
    x0, y0, x1, y1 = rect
    k = np.asarray(knots, dtype=np.float64)
    x = x0 + _KNOT_S * (x1 - x0)
    y = y1 - (k - lo) / max(hi - lo, 1e-12) * (y1 - y0)
    return np.stack([x, y], axis=-1)


def knot_from_mouse(rect: Rect, lo: float, hi: float, mx: float, my: float, step: float = 1.0,
                    index: int | None = None) -> tuple[int, float]:
    """The knot a press at (mx, my) grabs (nearest in s, unless ``index`` is already held) and
    the value the mouse's height gives it, clamped to [lo, hi] and rounded to ``step``."""
    x0, y0, x1, y1 = rect
    if index is None:
        s = (mx - x0) / max(x1 - x0, 1e-12)
        index = int(np.argmin(np.abs(_KNOT_S - s)))
    f = (y1 - my) / max(y1 - y0, 1e-12)
    value = lo + min(max(f, 0.0), 1.0) * (hi - lo)
    if step > 0:
        value = round(value / step) * step
    value = float(min(max(value, lo), hi))
    return index, value + 0.0   # no -0.0


class LobePanel:
    """Draws the ``lobes`` group of a lobed leaf inside the current imgui window.

    ``draw_field`` draws one ordinary field (the panel's own); ``record`` stores the last item's
    rectangle under a key (the panel's ``rects``)."""

    def __init__(self, state: ViewerState, draw_field: Callable[[str, FieldSpec], None],
                 record: Callable[[str], None]) -> None:
        self.state = state
        self.draw_field = draw_field
        self.record = record
        self.rects: dict[str, Rect] = {}      # plot rectangles by "lobes.branches[b].curve"
        self._held: tuple[str, int] | None = None   # (plot key, knot index) while dragging
        self.expand_all = False   # open every branch (tests, documentation screenshots)

    def draw(self, specs: dict[str, FieldSpec]) -> None:
        lobes = self.state.params.lobes
        for name in ("prune", "cup"):
            self.draw_field(f"lobes.{name}", specs[f"lobes.{name}"])
        imgui.text_disabled(f"margin: {len(lobes.outline)} control points, {len(lobes.valleys)} valleys")
        self.record("lobes.outline")
        imgui.push_text_wrap_pos(0.0)
        imgui.text_disabled("drag the white tip and valley handles in the viewport; the grey junctions "
                            "follow the margin (display-only)")
        imgui.pop_text_wrap_pos()
        self.record("lobes.valleys")
        try:
            branches = len(skeleton(lobes).branches)
        except ParamError as exc:
            imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.4, 1.0), f"no skeleton: {exc}")
            self.record("lobes.branches")
            return
        imgui.text("turtle per branch (deg per leaf length; s = 0 … 1)")
        self.record("lobes.branches")
        edited = {b.branch for b in lobes.branches}
        tspecs = turtle_specs()
        for b in range(branches):
            label = f"branch {b}{' (main)' if b == 0 else ''}{' *' if b in edited else ''}###turtle-{b}"
            if self.expand_all:
                imgui.set_next_item_open(True, imgui.Cond_.always)
            if imgui.tree_node_ex(label, int(imgui.TreeNodeFlags_.default_open) if b == 0 else 0):
                for curve in CURVES:
                    self._curve(b, curve, tspecs[curve])
                imgui.tree_pop()
        stale = sorted(x for x in edited if x >= branches)
        if stale:
            imgui.text_disabled(f"edits of branches {stale} are ignored: the skeleton has {branches}")

    def _curve(self, branch: int, curve: str, spec: FieldSpec) -> None:
        """One curve editor: a plot with the four knots; press and drag a knot up or down."""
        key = f"lobes.branches[{branch}].{curve}"
        knots = branch_knots(self.state.params.lobes, branch, curve)
        lo, hi = curve_range(spec, knots)
        width = max(60.0, imgui.calc_item_width())
        pos = imgui.get_cursor_screen_pos()
        imgui.invisible_button(f"##{key}", imgui.ImVec2(width, PLOT_HEIGHT))
        rect = (pos.x, pos.y, pos.x + width, pos.y + PLOT_HEIGHT)
        self.rects[key] = rect
        self.record(key)
        io = imgui.get_io()
        if imgui.is_item_activated():
            self._held = (key, knot_from_mouse(rect, lo, hi, io.mouse_pos.x, io.mouse_pos.y, spec.step)[0])
        if imgui.is_item_active() and self._held is not None and self._held[0] == key:
            index, value = knot_from_mouse(rect, lo, hi, io.mouse_pos.x, io.mouse_pos.y, spec.step, self._held[1])
            if value != knots[index]:
                new = list(knots)
                new[index] = value
                self.state.apply(lambda p: with_branch_knots(p, branch, curve, new), gesture=f"turtle:{key}")
                knots = tuple(new) if self.state.error is None else knots
        if imgui.is_item_deactivated():
            self._held = None
            self.state.end_gesture()
        if imgui.is_item_hovered():
            imgui.set_tooltip(f"{spec.label} of branch {branch} at s = 0, 1/3, 2/3, 1\n"
                              f"{', '.join(f'{k:g}' for k in knots)}\ndrag a knot up or down")
        self._plot(rect, lo, hi, knots, curve)

    @staticmethod
    def _plot(rect: Rect, lo: float, hi: float, knots: Sequence[float], curve: str) -> None:
        dl = imgui.get_window_draw_list()
        x0, y0, x1, y1 = rect
        col = imgui.color_convert_float4_to_u32
        dl.add_rect_filled(imgui.ImVec2(x0, y0), imgui.ImVec2(x1, y1), col(imgui.ImVec4(0.1, 0.11, 0.13, 1.0)))
        dl.add_rect(imgui.ImVec2(x0, y0), imgui.ImVec2(x1, y1), col(imgui.ImVec4(0.4, 0.42, 0.46, 1.0)))
        if lo < 0.0 < hi:
            zy = float(knot_positions(rect, lo, hi, [0.0] * TURTLE_KNOTS)[0, 1])
            dl.add_line(imgui.ImVec2(x0, zy), imgui.ImVec2(x1, zy), col(imgui.ImVec4(0.5, 0.5, 0.55, 0.6)))
        pts = [imgui.ImVec2(float(x), float(y)) for x, y in knot_positions(rect, lo, hi, knots)]
        line = col(imgui.ImVec4(0.35, 0.85, 0.45, 1.0))
        for a, b in zip(pts[:-1], pts[1:]):
            dl.add_line(a, b, line, 2.0)
        for p in pts:
            dl.add_circle_filled(p, 4.0, col(imgui.ImVec4(1.0, 1.0, 1.0, 1.0)))
        dl.add_text(imgui.ImVec2(x0 + 4, y0 + 2), col(imgui.ImVec4(0.8, 0.8, 0.85, 1.0)),
                    f"{curve}  {', '.join(f'{k:g}' for k in knots)}")
