"""The viewer without its window: one :meth:`Viewer.frame` draws the leaf, the overlays and the
imgui panel into an offscreen framebuffer, from imgui's io (keys, mouse) and the shared
:class:`~leafview.app.state.ViewerState`.

:mod:`leafview.app.window` feeds it glfw input and copies the frame to the screen; the tests and
``leafview bench`` drive it on a headless EGL context with injected imgui events. An edit made
during a frame (panel, handle drag, shortcut) is uploaded (the leaf's uniform block, under 1 KiB,
plus one tiny compute dispatch; nothing else) before that same frame's scene is drawn.

Wind (the panel's **Wind** header, :mod:`leafview.app.wind_panel`): with a speed above 0 the leaf
is drawn with ``LEAF_WIND`` (petiole turned, midrib bent and blade fluttering by the turbulent load
of Geng, Hu & Zhang 2014, eq. 5; the single leaf takes the phase of leaf index 0), and while *play
wind* is on its time advances with the wall clock each frame: one Wind uniform block write a
frame, nothing rebuilt. The control polygons, handles and close-up vein tubes show the leaf at
rest. Speed 0 draws the still leaf, bit for bit.
"""

from __future__ import annotations

import sys
import time
import traceback
from collections import deque
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path
from typing import Any

import moderngl
import numpy as np
from imgui_bundle import imgui
from numpy.typing import NDArray

from leafview.app import hotreload
from leafview.app.chrome import FileBar, draw_error_window, draw_help, draw_status, load_font
from leafview.app.handles import to_world
from leafview.app.imgui_gl import ImguiRenderer
from leafview.app.input import ViewportInput
from leafview.app.morph_panel import MorphPanel
from leafview.app.orbit import OrbitCamera
from leafview.app.overlay import Overlay
from leafview.app.panel import ParamPanel
from leafview.app.photo_reference import PhotoLayer
from leafview.app.state import ViewerState
from leafview.app.wind_panel import advance_wind
from leafview.botany.leaf_surface import drawn_grid, grid_points
from leafview.core.params import LeafParams
from leafview.export.images import ImageWriteError, write_image
from leafview.gpu.context import is_software
from leafview.gpu.renderer import LeafRenderer, Lighting
from leafview.gpu.targets import RenderTarget
from leafview.gpu.wind import WindUniforms, wind_defines
from leafview.resources import builtin_presets, preset_dir

__all__ = ["Viewer", "PANEL_WIDTH", "BACKGROUND", "open_state"]

PANEL_WIDTH = 400
BACKGROUND = (0.115, 0.125, 0.14, 1.0)


def begin_io(window_size: tuple[int, int], fb_size: tuple[int, int] | None,
             dt: float) -> tuple[int, int, int, int] | None:
    """Tell imgui this frame's window and framebuffer sizes and time step; returns
    ``(w, h, fb_w, fb_h)``, or None when the window is minimised (nothing is drawn then)."""
    w, h = int(window_size[0]), int(window_size[1])
    fw, fh = (w, h) if fb_size is None else (int(fb_size[0]), int(fb_size[1]))
    if min(w, h, fw, fh) <= 0:
        return None
    io = imgui.get_io()
    io.display_size = imgui.ImVec2(w, h)
    io.display_framebuffer_scale = imgui.ImVec2(fw / w, fh / h)
    io.delta_time = float(min(max(dt, 1e-4), 1.0))
    return w, h, fw, fh


@lru_cache(maxsize=8)
def _lighting(direction: tuple[float, float, float]) -> type[Lighting]:
    """The renderer's lights with the key light moved to ``direction`` (towards the light)."""
    return type("ViewerLighting", (Lighting,), {"key": (*direction, Lighting.key[3])})


class Viewer:
    """Scene + panel for one GL context. Creates (and on :meth:`release` destroys) its own imgui
    context, so create at most one at a time.

    Parameters
    ----------
    ctx:
        The moderngl context (a glfw window's, or headless EGL).
    state:
        The leaf and history the panel and viewport edit.
    dev:
        Watch ``shaders/`` and hot-reload (``leafview view --dev``).
    samples:
        Multisampling of the scene (capped to the context's limit; 0 = off). ``None``: 4, or 0
        on a software renderer (llvmpipe spends ~30 ms a 1280×800 frame on 4× MSAA).
    screenshot_dir:
        Where P writes screenshots (default: the current directory).
    """

    def __init__(self, ctx: moderngl.Context, state: ViewerState, *, dev: bool = False, samples: int | None = None,
                 screenshot_dir: str | Path | None = None) -> None:
        self.ctx, self.state = ctx, state
        self.imgui_ctx: imgui.internal.Context | None = imgui.create_context()   # None once released
        imgui.get_io().set_ini_filename(None)  # never write imgui.ini into the user's directory
        self.unicode_labels = load_font()
        self.gui: ImguiRenderer | None = None
        self.renderer: LeafRenderer | None = None
        self.overlay: Overlay | None = None
        self.photo: PhotoLayer | None = None     # the reference photo behind the leaf
        self.wind_uniforms: WindUniforms | None = None
        try:
            self.gui = ImguiRenderer(ctx)
            self.renderer = LeafRenderer(ctx)
            self.overlay = Overlay(ctx)
            self.photo = PhotoLayer(ctx)
            self.wind_uniforms = WindUniforms(ctx)
        except BaseException:
            self.release()
            raise
        self.panel = ParamPanel(state, unicode_labels=self.unicode_labels)
        self.custom_panels: list[Callable[[ViewerState], None]] = []   # see add_panel
        self.morph = MorphPanel(state)
        self.files = FileBar(state, builtin_presets())
        self.camera = OrbitCamera(target=np.zeros(3))
        self.input = ViewportInput(self)
        self.gl_renderer = str(ctx.info["GL_RENDERER"])
        if samples is None:
            samples = 0 if is_software(self.gl_renderer) else 4
        self.samples = max(0, min(int(samples), int(ctx.max_samples)))
        self.screenshot_dir = Path(screenshot_dir) if screenshot_dir is not None else Path.cwd()
        self.watcher = hotreload.ShaderWatcher() if dev else None
        self.shader_error: str | None = None
        self.gl_errors: list[tuple[int, str]] = []
        self.internal_errors = 0  # exceptions caught in the UI code (reported, never fatal)
        self.frame_index = 0
        self.fps = 0.0
        self._dts: deque[float] = deque(maxlen=30)
        self.last_upload_bytes = 0
        self.last_screenshot: Path | None = None
        self.screenshot_requested = False
        self.ground = (np.zeros(2), 0.0, 1.0)
        self._uploaded = -1
        self._framed_loads = -1
        self._framed_fits = 0
        self._targets: list[Any] = []
        self._target_key: tuple[int, int] | None = None

    # -- geometry helpers -----------------------------------------------------------------------
    @staticmethod
    def layout(width: float) -> tuple[float, float]:
        """(scene width, panel width) in window units for a window ``width`` wide."""
        panel = min(float(PANEL_WIDTH), max(width * 0.5, 1.0))
        return max(width - panel, 1.0), panel

    def leaf_points(self) -> NDArray[np.float64]:
        """World positions of the coarse grid the leaf is drawn on (framing and the ground grid):
        :func:`leafview.botany.leaf_surface.grid_points`, the swept surface of a lobed leaf."""
        p = self.state.params
        return to_world(p, grid_points(p, (17, 33)))

    def frame_leaf(self, aspect: float, *, reset: bool) -> None:
        """F (keep direction) or R (home direction): fit the leaf, re-place the ground grid."""
        pts = self.leaf_points()
        (self.camera.reset if reset else self.camera.frame)(pts, aspect)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        size = float(np.max(hi - lo))
        self.ground = ((lo[:2] + hi[:2]) / 2, float(lo[2] - 0.03 * size), max(1.0, 1.5 * size))

    # -- one frame ------------------------------------------------------------------------------
    def frame(self, window_size: tuple[int, int], fb_size: tuple[int, int] | None = None,
              dt: float = 1 / 60) -> moderngl.Framebuffer | None:
        """Run the UI and draw one frame; returns the framebuffer holding it (window size in
        pixels), or None when the window is minimised (0 × 0): nothing is drawn then."""
        sizes = begin_io(window_size, fb_size, dt)
        if sizes is None:
            return None
        w, h, fw, fh = sizes
        io = imgui.get_io()
        self._poll_shaders()
        scene_w, _ = self.layout(w)
        if self._framed_loads != self.state.loads:
            self.frame_leaf(scene_w / h, reset=True)
            self._framed_loads = self.state.loads
        if self._framed_fits != self.state.reference.fits:   # a fit may change the leaf's size
            self.frame_leaf(scene_w / h, reset=False)
            self._framed_fits = self.state.reference.fits

        imgui.new_frame()
        self._run_ui(scene_w, w, h)
        imgui.render()

        self._upload()
        view = self.state.view
        view.wind = advance_wind(view.wind, view.wind_playing, float(io.delta_time))
        fbo = self._target(fw, fh)
        scene_px = max(1, int(round(scene_w * fw / w)))
        self._draw_scene(scene_px, fh, scene_w, h)
        if self.screenshot_requested:
            self.screenshot_requested = False
            self._write_screenshot(scene_px, fh)
        fbo.use()
        self.ctx.viewport = (0, 0, fw, fh)
        assert self.gui is not None
        self.gui.render(imgui.get_draw_data())
        self._check_gl()
        self.frame_index += 1
        if self.frame_index > 1:  # the first interval includes start-up
            self._dts.append(io.delta_time)
            self.fps = len(self._dts) / sum(self._dts)
        return fbo

    def add_panel(self, draw: Callable[[ViewerState], None]) -> None:
        """Draw ``draw(state)`` in the settings panel every frame, below the parameter groups.

        ``draw`` uses imgui (``from imgui_bundle import imgui``) and edits the leaf through the
        state (:meth:`ViewerState.set_field`, :meth:`ViewerState.apply`), so its edits are undoable
        like every other. An exception in it is reported on the panel and never loses the leaf."""
        self.custom_panels.append(draw)

    def _run_ui(self, scene_w: float, w: int, h: int) -> None:
        """Input and panel for this frame. A bug in them must not take the user's work down:
        the exception is reported (terminal and panel), imgui's stacks are unwound and the
        leaf stays as the last valid edit left it."""
        recovery = imgui.internal.ErrorRecoveryState()
        imgui.internal.error_recovery_store_state(recovery)
        try:
            self.input.update(scene_w, h)
            self._draw_ui(w, h, scene_w)
        except Exception as exc:
            traceback.print_exc(file=sys.stderr)
            self.internal_errors += 1
            self.state.error = (f"internal error: {type(exc).__name__}: {exc} (details on the terminal; "
                                "your leaf is unchanged: save it)")
            io = imgui.get_io()
            asserting = io.config_error_recovery_enable_assert
            io.config_error_recovery_enable_assert = False
            try:
                imgui.internal.error_recovery_try_to_recover_state(recovery)
            finally:
                io.config_error_recovery_enable_assert = asserting

    def _draw_ui(self, w: int, h: int, scene_w: float) -> None:
        _, panel_w = self.layout(w)
        imgui.set_next_window_pos(imgui.ImVec2(w - panel_w, 0), imgui.Cond_.always)
        imgui.set_next_window_size(imgui.ImVec2(panel_w, h), imgui.Cond_.always)
        flags = (imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_collapse
                 | imgui.WindowFlags_.no_saved_settings)
        imgui.begin(f"leafview: {self.state.title}###panel", None, flags)
        view = self.state.view
        imgui.push_item_width(-165)
        self.files.draw()
        imgui.separator()
        self.panel.draw_reference()
        self.panel.draw_edits()
        self.morph.draw()
        self.panel.draw_groups()
        for draw in self.custom_panels:
            draw(self.state)
        self.panel.draw_wind()
        self.panel.draw_view()
        _, view.show_veins = imgui.checkbox("veins##view", view.show_veins)
        imgui.pop_item_width()
        imgui.end()
        self.files.draw_confirm()
        nu, nv = drawn_grid(self.state.params, view.grid)
        fps = f"{self.fps:5.1f} fps ({1000 / self.fps:.1f} ms)" if self.fps else "  –  fps"
        status = f"{fps}   {2 * (nu - 1) * (nv - 1):,} triangles   {self.gl_renderer}   H: keys"
        if self.input.refused:   # a lobe handle that could not go where it was dragged
            status = f"{status}\nhandle stays: {self.input.refused}"
        draw_status(imgui.ImVec2(8, h - 8), status, scene_w - 16)
        if view.show_help:
            draw_help(imgui.ImVec2(scene_w / 2, h / 2))
        if self.shader_error and draw_error_window("Shader error (--dev)", self.shader_error,
                                                   imgui.ImVec2(10, 10), max(200.0, min(720.0, scene_w - 20))):
            self.shader_error = None

    def _upload(self) -> None:
        """Upload the leaf if it changed since the last frame (uniform block only); rebuild the
        overlay's vertices if the leaf or the ground placement changed. Toggling the veins checkbox
        uploads the leaf again, with or without its vein layer. During a drag the veins stay as
        they were at its start and are rebuilt in the first frame after it ends."""
        state = self.state
        assert self.renderer is not None and self.overlay is not None
        self.last_upload_bytes = 0
        if state.revision != self._uploaded or self.renderer.veins != state.view.show_veins:
            before = self.renderer.uploads
            self.renderer.veins = state.view.show_veins   # the veins checkbox (--veins on|off)
            # while a slider is dragged the veins follow at its release (rebuilding them takes 15-35 ms)
            self.renderer.set_leaf(state.params, defer_veins=state.in_gesture)
            self.last_upload_bytes = self.renderer.uploads - before
            self._uploaded = state.revision
        elif not state.in_gesture:
            self.renderer.refresh_veins()
        center, z, half = self.ground
        self.overlay.update(state.params, state.revision, center, z, half)

    def _draw_scene(self, px_w: int, px_h: int, scene_w: float, h: int) -> None:
        assert self.renderer is not None and self.overlay is not None
        view = self.state.view
        msaa, fbo = self._targets[0], self._targets[1]
        draw = msaa if msaa is not None else fbo
        draw.use()
        self.ctx.scissor = None
        draw.clear(*BACKGROUND, depth=1.0)
        self.ctx.viewport = (0, 0, px_w, px_h)
        cam = self.camera.camera(int(round(scene_w)), h)
        light = _lighting(view.light_direction())
        view_proj = cam.proj @ cam.view
        ref = self.state.reference
        # the reference photo is a backdrop: over the ground grid, under the leaf and its handles
        behind = self.photo is not None and ref.visible and ref.image is not None
        if behind and view.show_ground:
            self.overlay.draw_ground(view_proj)
        if self.photo is not None:
            self.photo.draw_photo(view_proj, ref, self.state.params)
        self.renderer.set_camera(cam, srgb=True, lighting=light)
        self.renderer.draw(grid=view.grid, wireframe=view.wireframe, defines=self._wind())
        if view.show_ground and not behind:
            self.overlay.draw_ground(view_proj)
        if view.show_controls:
            self.overlay.draw_controls(view_proj, self.input.hot)
        if self.photo is not None:
            self.photo.draw_markers(view_proj, ref, self.state.params, self.input.hot, show=view.show_controls)
        self.ctx.disable(moderngl.DEPTH_TEST)
        if msaa is not None:
            self.ctx.copy_framebuffer(fbo, msaa)

    def _wind(self) -> dict[str, int]:
        """The wind's defines for this frame's leaf, its block written and bound when it blows."""
        wind = self.state.view.wind
        if not wind.active or self.wind_uniforms is None:
            return {}
        if self.wind_uniforms.wind != wind:
            self.wind_uniforms.set(wind)
        self.wind_uniforms.bind()
        return wind_defines(wind)

    # -- framebuffers -----------------------------------------------------------------------------
    def _target(self, w: int, h: int) -> moderngl.Framebuffer:
        """(Re)create the offscreen targets for a frame of w × h pixels."""
        if self._target_key != (w, h):
            self._release_targets()
            target = RenderTarget(self.ctx, (w, h), self.samples)
            # [multisampled framebuffer or None, resolved framebuffer, owner]
            self._targets = [target.fbo if target.samples else None, target.resolved, target]
            self._target_key = (w, h)
        return self._targets[1]

    def _release_targets(self) -> None:
        for target in self._targets[2:]:
            target.release()
        self._targets, self._target_key = [], None

    def read_frame(self, viewport: tuple[int, int, int, int] | None = None) -> NDArray[np.uint8]:
        """The last frame (or a region of it) as (h, w, 4) uint8 sRGB, row 0 at the top, opaque."""
        if self._target_key is None:
            raise RuntimeError("no frame has been drawn yet")
        fbo = self._targets[1]
        x, y, w, h = viewport if viewport is not None else (0, 0, *self._target_key)
        raw = fbo.read(viewport=(x, y, w, h), components=4, alignment=1)
        img = np.frombuffer(raw, np.uint8).reshape(h, w, 4)[::-1].copy()
        img[..., 3] = 255
        return img

    # -- screenshots, shaders, errors -----------------------------------------------------------
    def _write_screenshot(self, w: int, h: int) -> None:

        img = self.read_frame((0, 0, w, h))
        stem = (self.state.path.stem if self.state.path else self.state.params.name) or "leaf"
        base = self.screenshot_dir / f"leafview-{stem}-{time.strftime('%Y%m%d-%H%M%S')}"
        path, n = base.with_suffix(".png"), 1
        while path.exists():
            path, n = Path(f"{base}-{n}.png"), n + 1
        try:
            write_image(path, img, params=self.state.params, description="leafview viewer screenshot")
        except (ImageWriteError, OSError) as exc:
            self.state.error = f"screenshot failed: {exc}"
            return
        self.last_screenshot = path
        self.state.message = f"wrote {path}"
        print(f"leafview view: wrote {path}", flush=True)

    def _poll_shaders(self) -> None:
        if self.watcher is None or not self.watcher.changed():
            return
        self.reload_shaders()

    def reload_shaders(self) -> bool:
        """Compile the current shader files; swap them in only if all compile."""
        assert self.renderer is not None
        try:
            hotreload.compile_check(self.ctx)
            renderer = LeafRenderer(self.ctx)
            overlay = Overlay(self.ctx)
            photo = PhotoLayer(self.ctx)
        except Exception as exc:  # ShaderError, a missing include, a driver message
            self.shader_error = hotreload.describe(exc)
            print(f"leafview view: shader reload failed, keeping the previous shaders:\n{exc}",
                  file=sys.stderr, flush=True)
            return False
        self.renderer.release()
        assert self.overlay is not None
        self.overlay.release()
        if self.photo is not None:
            self.photo.release()
        self.renderer, self.overlay, self.photo = renderer, overlay, photo
        self._uploaded = -1
        self.shader_error = None
        self.state.message = "shaders reloaded"
        return True

    def _check_gl(self) -> None:
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            self.gl_errors.append((self.frame_index, err))
            if len(self.gl_errors) <= 3:
                print(f"leafview view: OpenGL error in frame {self.frame_index}: {err}", file=sys.stderr)

    def release(self) -> None:
        """Release every GL object and the imgui context (idempotent)."""
        self._release_targets()
        for name in ("gui", "renderer", "overlay", "photo", "wind_uniforms"):
            obj = getattr(self, name, None)
            if obj is not None:
                obj.release()
                setattr(self, name, None)
        if getattr(self, "imgui_ctx", None) is not None:
            imgui.destroy_context(self.imgui_ctx)
            self.imgui_ctx = None

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def open_state(params: LeafParams, path: Path | None) -> ViewerState:
    """A :class:`ViewerState` for a leaf, with the built-in preset folder marked read-only."""
    return ViewerState(params, path, builtin_dir=preset_dir())
