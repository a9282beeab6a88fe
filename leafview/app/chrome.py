"""Everything around the parameters: the file bar (presets, open, save, save as, reset, undo,
redo), the unsaved-changes question, error boxes, the help overlay and the status line.

Actions that would drop unsaved edits (open, switch preset, quit) go through
:meth:`FileBar.request`, which asks first when the leaf is dirty.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from imgui_bundle import imgui

from leafview.app.photo_reference import is_photo_path, open_photo
from leafview.app.state import ViewerState

__all__ = ["FileBar", "KEYS", "draw_help", "draw_status", "draw_error_window", "ERROR_COLOR", "load_font"]

ERROR_COLOR = imgui.ImVec4(1.0, 0.45, 0.4, 1.0)
CONFIRM_POPUP = "Unsaved changes##confirm"

#: the key table (README and help overlay)
KEYS: tuple[tuple[str, str], ...] = (
    ("left drag", "orbit (on a white handle: move that control point)"),
    ("left drag on an orange / blue point", "move the reference photo's base / apex (for Fit)"),
    ("middle drag / shift+left drag", "pan"),
    ("wheel", "dolly"),
    ("R", "reset the view"),
    ("F", "frame the leaf"),
    ("W", "wireframe"),
    ("C", "control polygons of A, S, F, G and the handles"),
    ("G", "ground grid"),
    ("P", "screenshot of the viewport (PNG, name printed)"),
    ("H / F1", "this help"),
    ("Ctrl+Z / Ctrl+Shift+Z", "undo / redo (also Ctrl+Y)"),
    ("Ctrl+S", "save (save as for built-in presets)"),
    ("Esc / Q", "quit (asks first about unsaved edits)"),
)


class FileBar:
    """Preset dropdown and file buttons; owns the unsaved-changes modal."""

    def __init__(self, state: ViewerState, presets: dict[str, Path]) -> None:
        self.state = state
        self.presets = presets
        self.open_path = ""
        self.save_path = ""
        self.show_open = False
        self.show_save_as = False
        self.quit_requested = False
        self._pending: Callable[[], object] | None = None   # what runs once the question is answered
        self._pending_what = ""
        self._want_popup = False
        self._opened_at = 0
        self.rects: dict[str, tuple[float, float, float, float]] = {}  # where each button was drawn

    def _button(self, label: str) -> bool:
        """``imgui.button`` that records its rectangle under its label."""
        pressed = imgui.button(label)
        lo, hi = imgui.get_item_rect_min(), imgui.get_item_rect_max()
        self.rects[label] = (lo.x, lo.y, hi.x, hi.y)
        return pressed

    # -- guarded actions --------------------------------------------------------------------------
    def request(self, what: str, action: Callable[[], object]) -> None:
        """Run ``action`` now if nothing is unsaved, else ask (Save / Discard / Cancel) first
        (its result, if any, is ignored)."""
        if not self.state.dirty:
            action()
            return
        self._pending, self._pending_what, self._want_popup = action, what, True

    @property
    def asking(self) -> bool:
        """Whether the unsaved-changes question is waiting for an answer."""
        return self._pending is not None

    def request_quit(self) -> None:
        self.request("quit", self._quit)

    def _quit(self) -> None:
        self.quit_requested = True

    def request_open(self, path: str | Path) -> None:
        """Open a leaf preset (asking first about unsaved edits), or an image file (PNG, JPEG,
        TIFF): that becomes the reference photo behind the current leaf, which is kept."""
        if is_photo_path(path):
            open_photo(self.state, path)
            return
        self.request(f"open {Path(path).name}", lambda: self.state.open(path))

    def save(self) -> None:
        """Ctrl+S / the Save button: save in place, or open the save-as field."""
        if self.state.can_save:
            self.state.save()
        else:
            self.show_save_as, self.show_open = True, False
            if not self.save_path:
                self.save_path = self._suggested_path()

    def _suggested_path(self) -> str:
        """A save-as name in the current directory (never inside the built-in presets)."""
        stem = self.state.path.stem if self.state.path else (self.state.params.name or "leaf")
        return str(Path.cwd() / f"{stem}.toml")

    # -- drawing ----------------------------------------------------------------------------------
    def draw(self) -> None:
        state = self.state
        names = list(self.presets)
        current = state.path.stem if state.path is not None and state.is_builtin() else ""
        if imgui.begin_combo("preset##file", current or "(choose a built-in preset)"):
            for name in names:
                selected = name == current
                if imgui.selectable(name, selected)[0]:
                    self.request_open(self.presets[name])
            imgui.end_combo()
        imgui.begin_disabled(not state.can_undo)
        if self._button("Undo##file"):
            state.undo()
        imgui.end_disabled()
        imgui.same_line()
        imgui.begin_disabled(not state.can_redo)
        if self._button("Redo##file"):
            state.redo()
        imgui.end_disabled()
        imgui.same_line()
        if self._button("Open…##file"):
            self.show_open, self.show_save_as = not self.show_open, False
        imgui.same_line()
        if self._button("Save##file"):
            self.save()
        imgui.same_line()
        if self._button("Save as…##file"):
            self.show_save_as, self.show_open = not self.show_save_as, False
            if self.show_save_as and not self.save_path:
                self.save_path = self._suggested_path()
        imgui.same_line()
        if self._button("Reset##file"):
            state.reset_to_preset()
        if imgui.is_item_hovered():
            imgui.set_tooltip("back to the leaf as it was opened (undoable)")

        if self.show_open:
            imgui.set_next_item_width(-60)
            entered, self.open_path = imgui.input_text("##open-path", self.open_path,
                                                       imgui.InputTextFlags_.enter_returns_true)
            if imgui.is_item_hovered():
                imgui.set_tooltip("a leaf (.toml, .json), or a photo (.png, .jpg, .tif) to show behind the leaf")
            imgui.same_line()
            if (self._button("Open##open-go") or entered) and self.open_path.strip():
                self.request_open(self.open_path.strip())
                self.show_open = False
        if self.show_save_as:
            imgui.set_next_item_width(-60)
            entered, self.save_path = imgui.input_text("##save-path", self.save_path,
                                                       imgui.InputTextFlags_.enter_returns_true)
            imgui.same_line()
            if self._button("Save##save-go") or entered:
                if state.save_as(self.save_path.strip()):
                    self.show_save_as = False
        where = str(state.path) if state.path else "(not saved)"
        imgui.text_disabled(f"{where}{'   ● unsaved edits' if state.dirty else ''}")
        if state.error:
            imgui.push_text_wrap_pos(0.0)
            imgui.text_colored(ERROR_COLOR, state.error)
            imgui.pop_text_wrap_pos()
            if imgui.small_button("dismiss##error"):
                state.error = None
        elif state.message:
            imgui.text_disabled(state.message)

    def draw_confirm(self) -> None:
        """The unsaved-changes modal (call at the top level, outside other windows)."""
        if self._want_popup:
            imgui.open_popup(CONFIRM_POPUP)
            self._want_popup = False
            self._opened_at = imgui.get_frame_count()  # the key that asked must not also answer
        center = imgui.get_main_viewport().get_center()
        imgui.set_next_window_pos(center, imgui.Cond_.appearing, imgui.ImVec2(0.5, 0.5))
        opened, _ = imgui.begin_popup_modal(CONFIRM_POPUP, None, imgui.WindowFlags_.always_auto_resize)
        if not opened:
            return
        state = self.state
        imgui.text(f"{state.title} has unsaved edits.")
        imgui.text(f"Save them before you {self._pending_what}?")
        if state.error:
            imgui.text_colored(ERROR_COLOR, state.error)
        if not state.can_save:
            imgui.set_next_item_width(360)
            _, self.save_path = imgui.input_text("save as##confirm-path", self.save_path or self._suggested_path())
        if self._button("Save##confirm"):
            ok = state.save() if state.can_save else state.save_as(self.save_path.strip())
            if ok:
                self._finish(run=True)
                imgui.close_current_popup()
        imgui.same_line()
        if self._button("Discard##confirm"):
            self._finish(run=True)
            imgui.close_current_popup()
        imgui.same_line()
        escape = imgui.is_key_pressed(imgui.Key.escape, False) and imgui.get_frame_count() > self._opened_at
        if self._button("Cancel##confirm") or escape:
            self._finish(run=False)
            imgui.close_current_popup()
        imgui.end_popup()

    def _finish(self, run: bool) -> None:
        action, self._pending = self._pending, None
        if run and action is not None:
            action()


def draw_help(center: imgui.ImVec2) -> None:
    """The key table, centred over the viewport; it takes no input."""
    imgui.set_next_window_pos(center, imgui.Cond_.always, imgui.ImVec2(0.5, 0.5))
    imgui.set_next_window_bg_alpha(0.88)
    flags = (imgui.WindowFlags_.no_inputs | imgui.WindowFlags_.always_auto_resize
             | imgui.WindowFlags_.no_saved_settings | imgui.WindowFlags_.no_focus_on_appearing
             | imgui.WindowFlags_.no_nav)
    imgui.begin("Keys (H or F1 to close)##help", None, flags)
    if imgui.begin_table("keys", 2, imgui.TableFlags_.row_bg):
        for key, what in KEYS:
            imgui.table_next_row()
            imgui.table_next_column()
            imgui.text(key)
            imgui.table_next_column()
            imgui.text(what)
        imgui.end_table()
    imgui.end()


def draw_status(pos: imgui.ImVec2, text: str, max_width: float) -> None:
    """The status line (fps, triangles, GL_RENDERER) at ``pos`` (bottom-left of the viewport),
    wrapped to stay inside the viewport's ``max_width``."""
    imgui.set_next_window_pos(pos, imgui.Cond_.always, imgui.ImVec2(0.0, 1.0))
    imgui.set_next_window_size_constraints(imgui.ImVec2(0, 0), imgui.ImVec2(max(max_width, 40.0), 400.0))
    imgui.set_next_window_bg_alpha(0.55)
    flags = (imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.no_inputs
             | imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_saved_settings
             | imgui.WindowFlags_.no_focus_on_appearing | imgui.WindowFlags_.no_nav)
    imgui.begin("##status", None, flags)
    imgui.push_text_wrap_pos(imgui.get_cursor_pos_x() + max(max_width - 20.0, 20.0))
    imgui.text(text)
    imgui.pop_text_wrap_pos()
    imgui.end()


def draw_error_window(title: str, text: str, pos: imgui.ImVec2, width: float) -> bool:
    """A red-text error panel (shader compile logs); returns True when dismissed."""
    imgui.set_next_window_pos(pos, imgui.Cond_.always)
    imgui.set_next_window_size_constraints(imgui.ImVec2(width, 0), imgui.ImVec2(width, 600))
    flags = imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_saved_settings
    imgui.begin(f"{title}##error-window", None, flags)
    imgui.push_text_wrap_pos(0.0)
    imgui.text_colored(ERROR_COLOR, text)
    imgui.pop_text_wrap_pos()
    dismissed = imgui.button("dismiss##error-window")
    imgui.end()
    return dismissed


_FONTS = (
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu-sans-fonts/DejaVuSans.ttf",
    "/Library/Fonts/DejaVuSans.ttf",
    "C:/Windows/Fonts/DejaVuSans.ttf",
)


def _font_candidates() -> list[Path]:
    found = [Path(p) for p in _FONTS if Path(p).is_file()]
    if not found:
        try:  # matplotlib (an optional extra) ships DejaVu Sans
            import matplotlib

            found.append(Path(matplotlib.get_data_path()) / "fonts/ttf/DejaVuSans.ttf")
        except ImportError:
            pass
    return found


def load_font(size: float = 15.0) -> bool:
    """Use DejaVu Sans (it has the combining macron of v̄, x̄s) if one is found; else imgui's
    built-in font. Returns whether labels may use combining marks."""
    io = imgui.get_io()
    for path in _font_candidates():
        if path.is_file():
            try:
                io.fonts.add_font_from_file_ttf(str(path), size)
                return True
            except Exception:  # a corrupt font file: try the next
                continue
    return False
