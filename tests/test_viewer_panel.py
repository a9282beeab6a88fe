"""The panel without a window or GL: a real imgui context receives mouse events at the rectangles
where the panel drew its widgets, and the edits must arrive through the same ViewerState API
(validated, one undo step per drag, untouched components unchanged). A parameter group the panel
has never heard of gets widgets from its metadata alone."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from imgui_bundle import imgui  # a hard dependency: missing means broken, not skipped

from leafview.app.chrome import FileBar  # noqa: E402
from leafview.app.lobe_panel import (
    CURVES,
    PLOT_HEIGHT,
    branch_knots,
    knot_from_mouse,
    knot_positions,
    with_branch_knots,
)
from leafview.app.panel import OMEGA_ONLY, ParamPanel, decimals, from_ui, groups_of  # noqa: E402
from leafview.app.state import ViewerState  # noqa: E402
from leafview.botany.lobe_skeleton import skeleton
from leafview.core.params import FieldSpec, ParamError, field_specs  # noqa: E402
from leafview.resources import builtin_presets, preset_dir  # noqa: E402

SIZE = (700, 2200)


class UI:
    """An imgui context with no renderer: font textures are acknowledged, nothing is drawn."""

    def __init__(self) -> None:
        self.ctx = imgui.create_context()
        io = imgui.get_io()
        io.set_ini_filename(None)
        io.display_size = imgui.ImVec2(*SIZE)
        io.backend_flags |= imgui.BackendFlags_.renderer_has_textures

    def frame(self, draw: Callable[[], None], after: Callable[[], None] | None = None) -> None:
        io = imgui.get_io()
        io.delta_time = 1 / 60
        imgui.new_frame()
        imgui.set_next_window_pos(imgui.ImVec2(0, 0))
        imgui.set_next_window_size(imgui.ImVec2(*SIZE))
        imgui.begin("panel", None, imgui.WindowFlags_.no_saved_settings)
        imgui.push_item_width(-165)
        draw()
        imgui.pop_item_width()
        imgui.end()
        if after is not None:
            after()
        imgui.render()
        for tex in imgui.get_platform_io().textures:
            if tex.status == imgui.ImTextureStatus.want_create:
                tex.set_tex_id(1)
                tex.status = imgui.ImTextureStatus.ok
            elif tex.status == imgui.ImTextureStatus.want_updates:
                tex.status = imgui.ImTextureStatus.ok
            elif tex.status == imgui.ImTextureStatus.want_destroy and tex.unused_frames > 0:
                tex.status = imgui.ImTextureStatus.destroyed

    def drag(self, draw: Callable[[], None], rect: tuple[float, ...], fx0: float, fx1: float,
             after: Callable[[], None] | None = None, steps: int = 4) -> None:
        """Press at fraction ``fx0`` of the rectangle's width, move to ``fx1``, release."""
        io = imgui.get_io()
        x0, y0, x1, y1 = rect
        y = (y0 + y1) / 2
        io.add_mouse_pos_event(x0 + fx0 * (x1 - x0), y)
        self.frame(draw, after)
        io.add_mouse_button_event(0, True)
        self.frame(draw, after)
        for k in range(1, steps + 1):
            fx = fx0 + (fx1 - fx0) * k / steps
            io.add_mouse_pos_event(x0 + fx * (x1 - x0), y)
            self.frame(draw, after)
        io.add_mouse_button_event(0, False)
        self.frame(draw, after)
        self.frame(draw, after)

    def click(self, draw: Callable[[], None], rect: tuple[float, ...], fx: float = 0.5,
              after: Callable[[], None] | None = None) -> None:
        self.drag(draw, rect, fx, fx, after, steps=0)

    def close(self) -> None:
        imgui.destroy_context(self.ctx)


@pytest.fixture
def ui():
    driver = UI()
    yield driver
    driver.close()


@pytest.fixture
def state(presets) -> ViewerState:
    return ViewerState(presets["ovate"], builtin_presets()["ovate"], builtin_dir=preset_dir())


def _panel_draw(panel: ParamPanel) -> Callable[[], None]:
    def draw() -> None:
        panel.draw_edits()
        panel.draw_groups()
        panel.draw_view()
    return draw


def test_every_field_gets_a_widget(ui, state):
    panel = ParamPanel(state)
    panel.expand_all = True
    for _ in range(2):
        ui.frame(_panel_draw(panel))
    specs = field_specs()
    for path, spec in specs.items():
        keys = [path] if spec.kind != "rows" else [f"{path}[{i}]" for i in range(3)]
        for key in keys:
            x0, y0, x1, y1 = panel.rects[key]
            assert x1 > x0 and y1 > y0, key
    assert set(groups_of(specs)) >= {"axis", "silhouette", "curvature", "jitter", "material"}
    for key in ("edit:width", "edit:skew", "edit:axis", "edit:curveS", "view.grid", "view.light_azimuth"):
        assert key in panel.rects


def test_checkbox_click_is_one_undoable_edit(ui, state):
    panel = ParamPanel(state)
    draw = _panel_draw(panel)
    ui.frame(draw)
    assert not state.params.jitter.enabled
    ui.click(draw, panel.rects["jitter.enabled"], fx=0.05)
    assert state.params.jitter.enabled and state.dirty
    assert state.undo() and not state.params.jitter.enabled and not state.can_undo


def test_slider_drag_is_one_undo_step_and_reaches_the_leaf(ui, state):
    panel = ParamPanel(state)
    draw = _panel_draw(panel)
    ui.frame(draw)
    revision = state.revision
    ui.drag(draw, panel.rects["material.translucency"], 0.1, 0.9)  # soft range 0..1
    value = state.params.material.translucency
    assert 0.8 < value < 0.95, value
    assert state.revision > revision + 1  # the leaf followed the drag, frame by frame
    assert repr(value) == repr(float(repr(value)))  # a clean decimal, no float32 tail
    assert state.undo() and state.params.material.translucency == 0.35 and not state.can_undo


def test_vector_component_drag_leaves_other_components_exact(ui, state):
    panel = ParamPanel(state)
    draw = _panel_draw(panel)
    ui.frame(draw)
    before = state.params.shape.a1  # (0, 1/3, 0): 1/3 is not a float32
    x0, y0, x1, y1 = panel.rects["shape.a1"]
    third = (x1 - x0) / 3
    ui.drag(draw, (x0, y0, x0 + third - 4, y1), 0.5, 0.8)  # the x component only
    after = state.params.shape.a1
    assert after[0] > 0.05 and after[1] == before[1] and after[2] == before[2]


def test_relative_width_slider_scales_and_springs_back(ui, state):
    panel = ParamPanel(state)
    draw = _panel_draw(panel)
    ui.frame(draw)
    xs = state.params.shape.xs.copy()
    ui.drag(draw, panel.rects["edit:width"], 0.3, 0.6)  # ×0.25 … ×2.5
    factor = state.params.shape.xs / xs
    assert factor.min() == pytest.approx(factor.max()) and factor[0] > 1.05
    assert panel._relative["width"] == 1.0  # released: back to ×1 for the next drag
    assert state.undo() and (state.params.shape.xs == xs).all() and not state.can_undo


def test_invalid_value_shows_the_field_and_keeps_the_leaf(ui, state):
    panel = ParamPanel(state)
    draw = _panel_draw(panel)
    ui.frame(draw)
    before = state.params
    # drag silhouette row S2's v̄ (first component) far left, past S1's v̄: invalid
    x0, y0, x1, y1 = panel.rects["shape.silhouette[1]"]
    third = (x1 - x0) / 3
    ui.drag(draw, (x0, y0, x0 + third - 4, y1), 0.6, 0.0)
    assert state.error and "shape.silhouette[1][0]" in state.error
    assert state.params.shape.silhouette[0] == before.shape.silhouette[0]
    assert state.params.shape.vbar[1] > state.params.shape.vbar[0]  # never an invalid leaf


class _FutureState(ViewerState):
    """A state whose leaf has a parameter group the panel was never written for."""

    EXTRA = {
        "petals.count": FieldSpec("petal count", "petals", (1, 12), 1, kind="int"),
        "petals.curl": FieldSpec("curl", "petals", (0.0, 2.0), 0.01),
        "petals.tint": FieldSpec("tint", "petals", (0, 1), 0.01, kind="color"),
        "petals.offset": FieldSpec("offset [l, r]", "petals", (-1, 1), 0.01, kind="pair"),
        "petals.profile": FieldSpec("profile", "petals", (0, 1), 0.1, kind="spline"),
    }

    def __init__(self, *a: Any, **k: Any) -> None:
        super().__init__(*a, **k)
        self.extra = {"petals.count": 5, "petals.curl": 0.5, "petals.tint": (0.9, 0.2, 0.4),
                      "petals.offset": (0.1, -0.1), "petals.profile": {"knots": 3}}
        self.calls: list[tuple[str, Any]] = []

    def specs(self) -> dict[str, FieldSpec]:
        return {**super().specs(), **self.EXTRA}

    def get(self, path: str) -> Any:
        return self.extra[path] if path in self.extra else super().get(path)

    def set_field(self, path: str, value: Any, *, gesture: bool = False) -> bool:
        if path in self.extra:
            self.calls.append((path, value))
            self.extra[path] = value
            return True
        return super().set_field(path, value, gesture=gesture)


def test_a_new_parameter_group_appears_without_panel_code(ui, presets):
    state = _FutureState(presets["ovate"])
    panel = ParamPanel(state)
    panel.expand_all = True
    draw = _panel_draw(panel)
    ui.frame(draw)
    ui.frame(draw)
    for path in _FutureState.EXTRA:
        assert path in panel.rects, path  # an unknown kind ("spline") is shown, not crashed on
    ui.drag(draw, panel.rects["petals.curl"], 0.2, 0.7)
    ui.drag(draw, panel.rects["petals.count"], 0.2, 0.9)
    x0, y0, x1, y1 = panel.rects["petals.offset"]
    ui.drag(draw, (x0 + (x1 - x0) / 2 + 4, y0, x1, y1), 0.5, 0.9)  # second component of a pair
    paths = {p for p, _ in state.calls}
    assert paths == {"petals.curl", "petals.count", "petals.offset"}
    assert 0.7 < state.extra["petals.curl"] < 1.6 and state.extra["petals.count"] > 8
    assert state.extra["petals.offset"][0] == 0.1 and state.extra["petals.offset"][1] > 0.2


def test_unsaved_changes_are_asked_about_before_quit_and_open(ui, state, tmp_path):
    files = FileBar(state, builtin_presets())

    def draw() -> None:
        files.draw()

    after = files.draw_confirm
    ui.frame(draw, after)
    files.request_quit()
    assert files.quit_requested  # nothing unsaved: quits at once
    files.quit_requested = False
    state.set_field("jitter.seed", 7)
    files.request_quit()
    ui.frame(draw, after)
    ui.frame(draw, after)
    assert files.asking and not files.quit_requested
    ui.click(draw, files.rects["Cancel##confirm"], after=after)
    assert not files.asking and not files.quit_requested and state.params.jitter.seed == 7

    # opening a broken preset from the UI: asked first, then the error is shown, nothing changes
    bad = tmp_path / "broken.toml"
    bad.write_text("schema = 1\n[shape]\na1 = [0, 0.3, 0]\na2 = [0, 0.6, 0]\n"
                   "silhouette = [[0.2, 0.3, 0], [0.1, 0.3, 0], [0.8, 0.2, 0]]\nzf = [0,0,0]\nzg = [0,0,0]\n")
    ui.click(draw, files.rects["Open…##file"], after=after)
    files.open_path = str(bad)
    ui.frame(draw, after)
    ui.click(draw, files.rects["Open##open-go"], after=after)
    assert files.asking
    ui.frame(draw, after)
    ui.click(draw, files.rects["Discard##confirm"], after=after)
    assert not files.asking
    assert state.error and "broken.toml" in state.error and "shape.silhouette[1][0]" in state.error
    assert state.params.jitter.seed == 7 and state.path.name == "ovate.toml"

    # quit with Save for a built-in preset saves as a new file, then quits
    files.request_quit()
    ui.frame(draw, after)
    files.save_path = str(tmp_path / "kept.toml")
    ui.frame(draw, after)
    ui.click(draw, files.rects["Save##confirm"], after=after)
    assert files.quit_requested and (tmp_path / "kept.toml").exists() and not state.dirty


def test_ui_value_cleaning():
    assert from_ui(1 / 3, 0.3333333432674408) == 1 / 3
    assert from_ui(0.0, 0.10000000149011612) == 0.1
    assert from_ui([1 / 3, 0.0], [0.3333333432674408, 0.25]) == [1 / 3, 0.25]
    assert decimals(0.005) == 3 and decimals(1) == 0 and decimals(0.1) == 1


# -- a lobed leaf (leafview.app.lobe_panel) ---------------------------------------------------------
@pytest.fixture
def maple_state(presets) -> ViewerState:
    return ViewerState(presets["maple"], builtin_presets()["maple"], builtin_dir=preset_dir())


def test_lobed_leaf_hides_the_omega_groups_and_shows_prune_cup_and_curves(ui, maple_state):
    panel = ParamPanel(maple_state)
    panel.expand_all = True
    for _ in range(2):
        ui.frame(_panel_draw(panel))
    assert not any(k.split(".")[0] in OMEGA_ONLY for k in panel.rects), "Ω-only groups are hidden"
    assert "hidden-groups" in panel.rects and "edit:lobed" in panel.rects and "edit:width" not in panel.rects
    for key in ("lobes.prune", "lobes.cup", "material.translucency", "ripple.enabled", "transform.scale"):
        assert key in panel.rects, key
    branches = len(skeleton(maple_state.params.lobes).branches)
    for b in range(branches):
        for curve in CURVES:
            x0, y0, x1, y1 = panel.rects[f"lobes.branches[{b}].{curve}"]
            assert x1 - x0 > 50 and y1 - y0 >= PLOT_HEIGHT - 1
    ui.drag(_panel_draw(panel), panel.rects["lobes.cup"], 0.5, 0.8)   # soft range -0.5 … 0.5
    assert 0.2 < maple_state.params.lobes.cup < 0.4
    assert maple_state.undo() and maple_state.params.lobes.cup == 0.0


def test_curve_model_functions_add_and_remove_a_branch_edit(maple_state):
    p = maple_state.params
    assert branch_knots(p.lobes, 2, "twist") == (0.0,) * 4
    q = with_branch_knots(p, 2, "twist", [0.0, 30.0, 30.0, 0.0])
    assert [b.branch for b in q.lobes.branches] == [2] and q.lobes.branches[0].twist == (0.0, 30.0, 30.0, 0.0)
    assert q.lobes.branches[0].bend == (0.0,) * 4 and branch_knots(q.lobes, 2, "twist")[1] == 30.0
    r = with_branch_knots(q, 0, "bend", [10.0, 0.0, 0.0, 0.0])
    assert [b.branch for b in r.lobes.branches] == [0, 2]
    assert with_branch_knots(r, 0, "bend", [0.0] * 4).lobes.branches == q.lobes.branches   # all zero: removed
    assert with_branch_knots(q, 2, "twist", [0.0] * 4).lobes.branches == ()
    with pytest.raises(ParamError, match=r"lobes.branches\[0\].turn\[3\]"):
        with_branch_knots(p, 1, "turn", [0.0, 0.0, 0.0, 1000.0])
    rect = (100.0, 200.0, 400.0, 260.0)
    pts = knot_positions(rect, -180.0, 180.0, [180.0, 0.0, -180.0, 90.0])
    assert np.allclose(pts[:, 0], [100, 200, 300, 400]) and np.allclose(pts[:3, 1], [200, 230, 260])
    assert knot_from_mouse(rect, -180.0, 180.0, 205.0, 215.0) == (1, 90.0)
    assert knot_from_mouse(rect, -180.0, 180.0, 390.0, 100.0) == (3, 180.0)        # clamped
    assert knot_from_mouse(rect, -180.0, 180.0, 390.0, 245.0, index=0) == (0, -90.0)  # the held knot


def test_dragging_a_knot_edits_lobes_branches_as_one_undo_step(ui, maple_state):
    panel = ParamPanel(maple_state)
    panel.expand_all = True
    draw = _panel_draw(panel)
    for _ in range(2):
        ui.frame(draw)
    x0, y0, x1, y1 = panel.rects["lobes.branches[1].bend"]
    io = imgui.get_io()
    x = x0 + (x1 - x0) / 3            # knot s = 1/3
    io.add_mouse_pos_event(x, (y0 + y1) / 2)
    ui.frame(draw)
    io.add_mouse_button_event(0, True)
    ui.frame(draw)
    for k in range(1, 5):             # up to three quarters of the plot's height
        io.add_mouse_pos_event(x, (y0 + y1) / 2 - k * (y1 - y0) / 16)
        ui.frame(draw)
    io.add_mouse_button_event(0, False)
    ui.frame(draw)
    ui.frame(draw)
    (edit,) = maple_state.params.lobes.branches
    assert edit.branch == 1 and edit.bend[0] == edit.bend[2] == edit.bend[3] == 0.0
    assert 80.0 <= edit.bend[1] <= 100.0, edit.bend    # soft range ±180: 3/4 of the height is +90
    assert edit.twist == edit.turn == (0.0,) * 4
    assert maple_state.undo() and maple_state.params.lobes.branches == () and not maple_state.can_undo


# -- a leaf drawn with its landmark margin (leafview.core.margin) ------------------------------------
def test_margin_leaf_says_so_and_fits_omega_on_request(ui, presets):
    from leafview.botany.catalogue import landmark_leaf
    from leafview.botany.landmarks import margin_params

    leaf = margin_params([landmark_leaf("cordate")], presets["ovate"].replace(name="cordate"))[0]
    st = ViewerState(leaf, None, builtin_dir=preset_dir())
    panel = ParamPanel(st)
    panel.expand_all = True
    for _ in range(2):
        ui.frame(_panel_draw(panel))
    assert "margin-note" in panel.rects and "margin:fit" in panel.rects
    assert "edit:width" in panel.rects                        # the width edit scales the margin
    ui.click(_panel_draw(panel), panel.rects["margin:fit"])
    assert st.params.margin is None and st.params.shape != leaf.shape
    assert st.params.material == leaf.material
    panel.rects.clear()
    ui.frame(_panel_draw(panel))
    assert "margin-note" not in panel.rects and "shape.a1" in panel.rects
    assert st.undo() and st.params.margin == leaf.margin     # one undo step back to the margin
