"""The glfw window around :class:`~leafview.app.viewer.Viewer`: context creation, the event
loop, resizing and minimising, the close button, and scripted runs (``--frames``,
``--screenshot``).

The loop renders continuously while input arrives and for a second after, then waits for events
(``glfw.wait_events_timeout``) so an idle viewer left open all day costs almost nothing.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import glfw
import moderngl

from leafview.app.platform import GlfwInput
from leafview.app.state import ViewerState
from leafview.app.viewer import Viewer
from leafview.export.images import write_image
from leafview.gpu.context import GLUnavailable

__all__ = ["ViewerWindow", "NO_DISPLAY_HELP"]

NO_DISPLAY_HELP = (
    "leafview view opens a window and needs a display with OpenGL 4.5.\n"
    "  On a machine without one, run it under a virtual display:  xvfb-run -a leafview view ...\n"
    "  (Debian/Ubuntu: apt-get install xvfb libgl1-mesa-dri; Mesa's llvmpipe is enough)"
)
_IDLE_AFTER = 1.0   # seconds of continuous rendering after the last input event


class ViewerWindow:
    """A window showing a :class:`Viewer` of ``state``; release with :meth:`close` (or ``with``).

    Raises :class:`~leafview.gpu.context.GLUnavailable` (with what to install) when there is no
    display or no OpenGL 4.5.
    """

    def __init__(self, state: ViewerState | None, size: tuple[int, int] = (1280, 800), *, dev: bool = False,
                 samples: int | None = None, title: str = "leafview",
                 make_view: Callable[[moderngl.Context], Any] | None = None) -> None:
        self._errors: list[str] = []
        self.window: Any = None
        self.ctx: moderngl.Context | None = None
        self.viewer: Viewer | None = None
        glfw.ERROR_REPORTING = "ignore"
        glfw.set_error_callback(lambda code, text: self._errors.append(
            text.decode(errors="replace") if isinstance(text, bytes) else str(text)))
        if not glfw.init():
            raise GLUnavailable(f"{NO_DISPLAY_HELP}\n  (glfw: {self._last_error()})")
        try:
            glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 4)
            glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 5)
            glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
            glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
            glfw.window_hint(glfw.SAMPLES, 0)  # the scene has its own multisampled target
            self.window = glfw.create_window(int(size[0]), int(size[1]), title, None, None)
            if not self.window:
                raise GLUnavailable(f"{NO_DISPLAY_HELP}\n  (glfw could not create an OpenGL 4.5 window: "
                                    f"{self._last_error()})")
            glfw.make_context_current(self.window)
            glfw.swap_interval(1)
            try:
                self.ctx = moderngl.create_context(require=450)
            except Exception as exc:
                raise GLUnavailable(f"{NO_DISPLAY_HELP}\n  (moderngl: {exc})") from None
            # the leaf editor, or another view with the same frame interface (the scene viewer)
            if make_view is not None:
                self.viewer = make_view(self.ctx)
            elif state is not None:
                self.viewer = Viewer(self.ctx, state, dev=dev, samples=samples)
            else:
                raise TypeError("ViewerWindow needs a ViewerState or make_view")
            self.input = GlfwInput(self.window)
            glfw.set_window_close_callback(self.window, self._on_close)
        except BaseException:
            self.close()
            raise
        self.title = title
        self._last_time = time.perf_counter()
        self._last_events = -1
        self._active_until = 0.0
        self._shown_title = ""

    def _last_error(self) -> str:
        return self._errors[-1] if self._errors else "no reason given"

    def _on_close(self, window: Any) -> None:
        # the close button asks first when there are unsaved edits
        glfw.set_window_should_close(window, False)
        assert self.viewer is not None
        self.viewer.files.request_quit()

    @property
    def should_quit(self) -> bool:
        return self.viewer is None or self.viewer.files.quit_requested

    def step(self, *, wait: bool = False) -> bool:
        """Process input and draw one frame. Returns False once the viewer asked to quit.

        ``wait``: block (up to 0.5 s) for input when nothing happened for a second.
        """
        assert self.viewer is not None and self.ctx is not None
        now = time.perf_counter()
        if self.input.events != self._last_events:
            self._last_events = self.input.events
            self._active_until = now + _IDLE_AFTER
        if wait and now > self._active_until and not self.viewer.state.error:
            glfw.wait_events_timeout(0.5)
        else:
            glfw.poll_events()
        win_size = glfw.get_window_size(self.window)
        fb_size = glfw.get_framebuffer_size(self.window)
        now = time.perf_counter()
        dt, self._last_time = now - self._last_time, now
        fbo = self.viewer.frame(win_size, fb_size, dt)
        if fbo is None:  # minimised: draw nothing, do not spin
            glfw.wait_events_timeout(0.1)
            return not self.should_quit
        self.ctx.copy_framebuffer(self.ctx.screen, fbo)
        title = f"{self.title}: {self.viewer.state.title}"
        if title != self._shown_title:
            glfw.set_window_title(self.window, title)
            self._shown_title = title
        glfw.swap_buffers(self.window)
        return not self.should_quit

    def run(self, frames: int | None = None, screenshot: str | Path | None = None) -> int:
        """The main loop; with ``frames``, exactly that many frames (no waiting), then the
        optional full-window screenshot. Returns the exit code (1 if any frame had a GL error)."""
        assert self.viewer is not None
        scripted = frames is not None
        n = 0
        try:
            while frames is None or n < frames:
                if not self.step(wait=not scripted):
                    break
                n += 1
        except BaseException:  # Ctrl+C in the terminal, or a failure outside the UI's guard
            rescued = self.viewer.state.write_recovery()
            if rescued is not None:
                print(f"leafview view: stopped with unsaved edits; they were written to {rescued}",
                      file=sys.stderr, flush=True)
            raise
        if scripted:
            v = self.viewer
            print(f"leafview view: {n} frames, {v.fps:.1f} fps over the last {len(v._dts)} "
                  f"({v.gl_renderer})", flush=True)
        if screenshot is not None:
            self.write_screenshot(screenshot, n)
        if self.viewer.gl_errors:
            first = self.viewer.gl_errors[0]
            print(f"leafview view: {len(self.viewer.gl_errors)} frame(s) had OpenGL errors "
                  f"(first: frame {first[0]}, {first[1]})", file=sys.stderr)
            return 1
        return 0

    def write_screenshot(self, path: str | Path, frames: int) -> Path:
        """The whole window (scene and panel) of the last frame, written with OpenImageIO."""

        assert self.viewer is not None
        img = self.viewer.read_frame()
        out = write_image(path, img, params=self.viewer.state.params,
                          description="leafview viewer window")
        h, w = img.shape[:2]
        print(f"leafview view: wrote {out} ({w}×{h}, window after {frames} frames)", flush=True)
        return Path(out)

    def close(self) -> None:
        """Release the viewer, the context and the window; terminate glfw (idempotent)."""
        if self.viewer is not None:
            self.viewer.release()
            self.viewer = None
        if self.ctx is not None:
            self.ctx.release()
            self.ctx = None
        if self.window:
            glfw.destroy_window(self.window)
            self.window = None
        glfw.terminate()

    def __enter__(self) -> ViewerWindow:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
