"""glfw → Dear ImGui input: keys, modifiers, text, mouse and wheel become imgui io events.

Adapted from imgui-bundle's ``python_backends/glfw_backend.py`` (which also draws through
PyOpenGL; the drawing here is :mod:`leafview.app.imgui_gl`). The viewer reads every shortcut and
viewport drag back from imgui's io, so one input path serves the window and the tests, which
inject the same events without a window.
"""

from __future__ import annotations

import string
from typing import Any

import glfw
from imgui_bundle import imgui

__all__ = ["GlfwInput", "key_map"]

_FLT_MAX = 3.4028234663852886e38


def key_map() -> dict[int, imgui.Key]:
    """glfw key code → imgui key."""
    k = imgui.Key
    out: dict[int, imgui.Key] = {
        glfw.KEY_TAB: k.tab, glfw.KEY_BACKSPACE: k.backspace, glfw.KEY_ENTER: k.enter,
        glfw.KEY_ESCAPE: k.escape, glfw.KEY_INSERT: k.insert, glfw.KEY_DELETE: k.delete,
        glfw.KEY_SPACE: k.space, glfw.KEY_LEFT: k.left_arrow, glfw.KEY_RIGHT: k.right_arrow,
        glfw.KEY_UP: k.up_arrow, glfw.KEY_DOWN: k.down_arrow, glfw.KEY_PAGE_UP: k.page_up,
        glfw.KEY_PAGE_DOWN: k.page_down, glfw.KEY_HOME: k.home, glfw.KEY_END: k.end,
        glfw.KEY_KP_ENTER: k.keypad_enter, glfw.KEY_LEFT_CONTROL: k.left_ctrl,
        glfw.KEY_RIGHT_CONTROL: k.right_ctrl, glfw.KEY_LEFT_SHIFT: k.left_shift,
        glfw.KEY_RIGHT_SHIFT: k.right_shift, glfw.KEY_LEFT_ALT: k.left_alt,
        glfw.KEY_RIGHT_ALT: k.right_alt, glfw.KEY_LEFT_SUPER: k.left_super,
        glfw.KEY_RIGHT_SUPER: k.right_super, glfw.KEY_MINUS: k.minus, glfw.KEY_PERIOD: k.period,
        glfw.KEY_COMMA: k.comma, glfw.KEY_SLASH: k.slash, glfw.KEY_EQUAL: k.equal,
    }
    for c in string.ascii_uppercase:
        out[getattr(glfw, f"KEY_{c}")] = getattr(k, c.lower())
    for d in string.digits:
        out[getattr(glfw, f"KEY_{d}")] = getattr(k, f"_{d}")
    for n in range(1, 13):
        out[getattr(glfw, f"KEY_F{n}")] = getattr(k, f"f{n}")
    return out


class GlfwInput:
    """Installs glfw callbacks on ``window`` that feed the current imgui context."""

    def __init__(self, window: Any) -> None:
        self.window = window
        self.keys = key_map()
        self.events = 0  # input events seen (the loop renders continuously while they come)
        glfw.set_key_callback(window, self._key)
        glfw.set_char_callback(window, self._char)
        glfw.set_cursor_pos_callback(window, self._cursor)
        glfw.set_cursor_enter_callback(window, self._enter)
        glfw.set_mouse_button_callback(window, self._button)
        glfw.set_scroll_callback(window, self._scroll)
        glfw.set_window_focus_callback(window, self._focus)

    def _mods(self, mods: int) -> None:
        io = imgui.get_io()
        io.add_key_event(imgui.Key.mod_ctrl, bool(mods & glfw.MOD_CONTROL))
        io.add_key_event(imgui.Key.mod_shift, bool(mods & glfw.MOD_SHIFT))
        io.add_key_event(imgui.Key.mod_alt, bool(mods & glfw.MOD_ALT))
        io.add_key_event(imgui.Key.mod_super, bool(mods & glfw.MOD_SUPER))

    def _key(self, window: Any, key: int, scancode: int, action: int, mods: int) -> None:
        self.events += 1
        if action == glfw.REPEAT:
            return  # imgui makes its own repeats from the held state
        down = action == glfw.PRESS
        # glfw reports the modifier state before a modifier key changes it: fix that up
        bit = {glfw.KEY_LEFT_CONTROL: glfw.MOD_CONTROL, glfw.KEY_RIGHT_CONTROL: glfw.MOD_CONTROL,
               glfw.KEY_LEFT_SHIFT: glfw.MOD_SHIFT, glfw.KEY_RIGHT_SHIFT: glfw.MOD_SHIFT,
               glfw.KEY_LEFT_ALT: glfw.MOD_ALT, glfw.KEY_RIGHT_ALT: glfw.MOD_ALT,
               glfw.KEY_LEFT_SUPER: glfw.MOD_SUPER, glfw.KEY_RIGHT_SUPER: glfw.MOD_SUPER}.get(key, 0)
        mods = (mods | bit) if down else (mods & ~bit)
        self._mods(mods)
        imgui_key = self.keys.get(key)
        if imgui_key is not None:
            imgui.get_io().add_key_event(imgui_key, down)

    def _char(self, window: Any, char: int) -> None:
        self.events += 1
        if 0 < char < 0x110000:
            imgui.get_io().add_input_character(char)

    def _cursor(self, window: Any, x: float, y: float) -> None:
        self.events += 1
        imgui.get_io().add_mouse_pos_event(float(x), float(y))

    def _enter(self, window: Any, entered: int) -> None:
        self.events += 1
        if not entered:
            imgui.get_io().add_mouse_pos_event(-_FLT_MAX, -_FLT_MAX)

    def _button(self, window: Any, button: int, action: int, mods: int) -> None:
        self.events += 1
        self._mods(mods)
        if 0 <= button < 5:
            imgui.get_io().add_mouse_button_event(button, action == glfw.PRESS)

    def _scroll(self, window: Any, dx: float, dy: float) -> None:
        self.events += 1
        imgui.get_io().add_mouse_wheel_event(float(dx), float(dy))

    def _focus(self, window: Any, focused: int) -> None:
        self.events += 1
        imgui.get_io().add_focus_event(bool(focused))
