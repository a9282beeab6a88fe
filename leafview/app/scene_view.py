"""The scene viewer without its window: orbit around a scene of many leaves in its canopy look
(sun and shadows, sky, ground and wind: :class:`~leafview.gpu.canopy.CanopyRenderer`), with a panel
that shows what the culling pass drew at each level of detail and toggles culling and LOD live.

:class:`SceneView` has the frame interface of :class:`~leafview.app.viewer.Viewer`, so
:class:`~leafview.app.window.ViewerWindow` hosts it unchanged (``leafview scene --view``), and
the tests drive it headless with injected imgui events.

Mouse: left drag orbits, middle drag pans, the wheel dollies; a left click picks the leaf under
the cursor (GPU picking by instance id, :mod:`leafview.gpu.picking`; shift+click adds it to the
selection), a right drag or shift+left drag selects the leaves drawn inside a box. Keys: C
culling, L level of detail, V veins, F frame the scene, Ctrl+Z undo, Ctrl+Y (or Ctrl+Shift+Z)
redo, Esc or Q quit.

Scene-wide edits (:mod:`leafview.scene.scene_edits`, the panel of
:mod:`leafview.app.scene_edit_panel`) change the edited leaves' rows with one buffer write per
batch (:func:`leafview.gpu.scene_edits.update_rows`); **Save** writes the scene file with its
``[[edits]]``. Selected leaves are marked by a ring at their centre, drawn by imgui over the
frame (at most :data:`MAX_MARKERS` of them, projected in numpy: no extra scene pass).

Light and wind start from the scene file's ``[light]`` and ``[wind]`` and are changed live in
the panel: **Light** has a widget per :class:`~leafview.scene.lighting.LightSettings` field (sun
shadows, sun azimuth and elevation, intensity, sky, ground, exposure, tone map, transmission,
gloss, ambient occlusion, alpha to coverage, shadow map size, cascades and filter); **Wind** has *play
wind* (play/pause) and sliders for speed, direction, gustiness λ (Geng, Hu & Zhang 2014, eq. 5) and
blade flutter. While the wind plays, its time advances with the wall clock each frame: only the
Wind uniform block changes (no rebuild). **Save** writes the current light and wind into the
file's ``[light]`` and ``[wind]`` (the wind at the file's own ``time``). Picking draws its label
pass with the wind of the frame shown, so a click picks the leaf where it is drawn. A context
older than OpenGL 4.5 draws the plain look (no light or wind sections then).
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace
from pathlib import Path
from typing import Any, cast

import moderngl
import numpy as np
from imgui_bundle import imgui
from numpy.typing import NDArray

from leafview.app.imgui_gl import ImguiRenderer
from leafview.app.orbit import OrbitCamera
from leafview.app.scene_edit_panel import SceneEditPanel
from leafview.app.settings_panel import settings_widgets
from leafview.app.viewer import begin_io
from leafview.app.wind_panel import advance_wind, wind_widgets
from leafview.app.window import ViewerWindow
from leafview.deform.wind import WindSettings
from leafview.errors import GLUnavailable
from leafview.gpu.canopy import CanopyRenderer
from leafview.gpu.picking import pick, pick_box, project
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.gpu.scene_edits import update_rows
from leafview.gpu.targets import RenderTarget, read_rgba
from leafview.gpu.wind import wind_defines
from leafview.scene.lighting import LightSettings
from leafview.scene.scene_edits import SceneEditor
from leafview.scene.spec import Scene, SceneSpec

__all__ = ["SceneView", "view_scene"]

PANEL_WIDTH = 300
BACKGROUND = (0.62, 0.72, 0.80, 1.0)  # a pale sky behind the canopy
MAX_MARKERS = 4000                     # selected leaves marked on screen
CLICK_SLOP = 4.0                       # pixels a press may move and still be a click
_CULL = CullSettings()
SUN_RANGES = {"sun": ((-180.0, 360.0), (0.0, 90.0))}   # the sun's sliders: azimuth, elevation


class _Quit:
    """What the window asks of ``viewer.files``: quitting needs no confirmation here."""

    asking = False

    def __init__(self) -> None:
        self.quit_requested = False

    def request_quit(self) -> None:
        self.quit_requested = True


class _State:
    """What the window asks of ``viewer.state``: a title, no recoverable edits."""

    error = None
    params = None

    def __init__(self, title: str) -> None:
        self.title = title

    def write_recovery(self) -> Path | None:
        return None


class _WindyDraws:
    """A scene renderer whose draws add the wind's defines: picking's label pass
    (:func:`leafview.gpu.picking.pick` draws with ``renderer.draw(settings, defines=...)``) then
    labels the leaves where the wind has moved them, as drawn."""

    def __init__(self, renderer: SceneRenderer, defines: dict[str, int]) -> None:
        self._renderer, self._defines = renderer, defines

    def __getattr__(self, name: str) -> Any:
        return getattr(self._renderer, name)

    def draw(self, settings: CullSettings = _CULL, *, defines: Any = None) -> None:
        self._renderer.draw(settings, defines={**(defines or {}), **self._defines})


class SceneView:
    """Scene + panel for one GL context (creates and releases its own imgui context).

    ``light`` and ``wind`` default to the scene file's (``scene.spec.light``, ``scene.spec.wind``);
    :attr:`light`, :attr:`wind` and :attr:`wind_playing` are what the panel edits (tests set them).
    """

    def __init__(self, ctx: moderngl.Context, scene: Scene, *, veins: bool = True,
                 path: str | Path | None = None, light: LightSettings | None = None,
                 wind: WindSettings | None = None) -> None:
        self.ctx, self.scene = ctx, scene
        self.imgui_ctx: imgui.internal.Context | None = imgui.create_context()   # None once released
        imgui.get_io().set_ini_filename(None)
        self.gui: ImguiRenderer | None = None
        self.renderer: SceneRenderer | None = None
        self.canopy: CanopyRenderer | None = None   # None: a context without the canopy look
        self.light = scene.spec.light if light is None else light
        self.wind = scene.spec.wind if wind is None else wind
        self.wind_playing = True
        self.look_error: str | None = None           # a light or wind value the settings refused
        try:
            self.gui = ImguiRenderer(ctx)
            self.renderer = SceneRenderer(ctx, scene)   # the vein fields, shown or not by the checkbox
            self.renderer.show_veins = veins
            try:
                self.canopy = CanopyRenderer(self.renderer, self.light, self.wind)
            except GLUnavailable as exc:
                self.look_error = str(exc)
        except BaseException:
            self.release()
            raise
        self.settings = CullSettings()
        self.files = _Quit()
        self.state = _State(f"{scene.spec.name or 'scene'} ({len(scene):,} leaves)")
        self.gl_renderer = str(ctx.info["GL_RENDERER"])
        self.gl_errors: list[tuple[int, str]] = []
        self.camera = OrbitCamera(target=np.zeros(3))
        self._framed = False
        self.frame_index = 0
        self.fps = 0.0
        self._dts: deque[float] = deque(maxlen=30)
        self._drag: str | None = None
        self._render_target: RenderTarget | None = None
        self.counts = np.zeros(len(self.renderer.command_grids), np.int64)   # lobed levels after the others
        # scene-wide edits: the editor, its panel (Save writes ``path``) and the mouse's selection state
        self.editor = SceneEditor(scene)
        self.edit_panel = SceneEditPanel(self.editor, self._rows_changed, None if path is None else Path(path),
                                         spec=self.saved_spec)
        self._press: tuple[float, float] | None = None   # where a left or right press started
        self._box: tuple[float, float, float, float] | None = None   # the box being drawn (window points)
        self._view: tuple[int, int, float, float] = (1, 1, 1.0, 1.0)   # scene px size, points -> px scale

    def saved_spec(self) -> SceneSpec:
        """The scene's spec with the panel's light and wind (what **Save** writes; the wind at the
        file's own time, the clock's being the session's)."""
        spec = self.scene.spec
        return spec.replace(light=self.light, wind=self.wind.replace(time=spec.wind.time))

    def _rows_changed(self, leaves: NDArray[np.int64]) -> None:
        assert self.renderer is not None
        update_rows(self.renderer, leaves)

    def _corners(self) -> NDArray[np.float64]:
        lo, hi = self.scene.bounds()
        return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])

    # -- one frame ------------------------------------------------------------------------------
    def frame(self, window_size: tuple[int, int], fb_size: tuple[int, int] | None = None,
              dt: float = 1 / 60) -> moderngl.Framebuffer | None:
        """Input, panel and one frame; the framebuffer holding it, or None when minimised."""
        sizes = begin_io(window_size, fb_size, dt)
        if sizes is None:
            return None
        w, h, fw, fh = sizes
        io = imgui.get_io()
        scene_w = max(w - PANEL_WIDTH, 1)
        if not self._framed:
            self.camera.reset(self._corners(), scene_w / h)
            self.camera.radius *= 2.0  # room to dolly out and a generous far plane
            self._framed = True
        px_w = max(1, int(round(scene_w * fw / w)))
        self._view = (px_w, fh, fw / w, fh / h)
        imgui.new_frame()
        self._input(io, scene_w, h)
        self._panel(w, h)
        self._overlay()
        imgui.render()
        self.wind = advance_wind(self.wind, self.wind_playing, float(io.delta_time))
        fbo = self._target(fw, fh)
        assert self.renderer is not None and self.gui is not None
        camera = self.camera.camera(px_w, fh)
        if self.canopy is not None:
            self._sync_look()
            self.canopy.draw(camera, (px_w, fh), self.settings, framebuffer=fbo, background=BACKGROUND)
        else:
            fbo.use()
            fbo.clear(*BACKGROUND, depth=1.0)
            self.ctx.viewport = (0, 0, px_w, fh)
            self.renderer.set_camera(camera, (px_w, fh))
            self.renderer.draw(self.settings)
        fbo.use()
        self.counts = self.renderer.level_counts()
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.ctx.viewport = (0, 0, fw, fh)
        self.gui.render(imgui.get_draw_data())
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            self.gl_errors.append((self.frame_index, err))
        self.frame_index += 1
        if self.frame_index > 1:
            self._dts.append(io.delta_time)
            self.fps = len(self._dts) / sum(self._dts)
        return fbo

    def _sync_look(self) -> None:
        """Hand the panel's light and wind to the canopy renderer when they changed (the wind's
        time changes every frame it plays: one uniform block write)."""
        assert self.canopy is not None
        if self.canopy.light != self.light:
            self.canopy.set_light(self.light)
        if self.canopy.wind != self.wind:
            self.canopy.set_wind(self.wind)

    def _picking(self) -> SceneRenderer:
        """The renderer picking draws: with the wind of the frame shown (its block bound)."""
        assert self.renderer is not None
        if self.canopy is None or not self.canopy.wind.active:
            return self.renderer
        self.canopy.wind_uniforms.bind(self.renderer)
        return cast(SceneRenderer, _WindyDraws(self.renderer, wind_defines(self.canopy.wind)))

    def _input(self, io: Any, scene_w: float, h: int) -> None:
        def pressed(key: imgui.Key) -> bool:
            return imgui.is_key_pressed(key, False) and not io.want_text_input

        if pressed(imgui.Key.c):
            self.settings = replace(self.settings, cull=not self.settings.cull)
        if pressed(imgui.Key.l):
            self.settings = replace(self.settings, lod=not self.settings.lod)
        if pressed(imgui.Key.v) and self.renderer is not None:
            self.renderer.show_veins = not self.renderer.show_veins
        if pressed(imgui.Key.f):
            self.camera.frame(self._corners(), scene_w / h)
        if pressed(imgui.Key.escape) or pressed(imgui.Key.q):
            self.files.request_quit()
        if io.key_ctrl and pressed(imgui.Key.z):
            (self.edit_panel.redo if io.key_shift else self.edit_panel.undo)()
        if io.key_ctrl and pressed(imgui.Key.y):
            self.edit_panel.redo()
        mx, my = io.mouse_pos.x, io.mouse_pos.y
        inside = 0 <= mx < scene_w and 0 <= my < h and not io.want_capture_mouse
        left, right = imgui.MouseButton_.left, imgui.MouseButton_.right
        if self._drag is None and inside:
            if imgui.is_mouse_clicked(left):
                # a click (released within CLICK_SLOP) picks; a drag orbits, or with shift draws a box
                self._drag, self._press = ("box" if io.key_shift else "orbit"), (mx, my)
            elif imgui.is_mouse_clicked(right):
                self._drag, self._press = "box", (mx, my)
            elif imgui.is_mouse_clicked(imgui.MouseButton_.middle):
                self._drag = "pan"
            if io.mouse_wheel:
                self.camera.dolly(float(io.mouse_wheel))
        if self._drag is not None:
            moved = self._press is not None and max(abs(mx - self._press[0]), abs(my - self._press[1])) > CLICK_SLOP
            if not any(imgui.is_mouse_down(b) for b in (left, right, imgui.MouseButton_.middle)):
                if self._press is not None and not moved and self._drag != "pan":
                    self._click(self._press, add=bool(io.key_shift))
                elif self._drag == "box" and self._box is not None:
                    self._select_box(self._box, add=bool(io.key_shift))
                self._drag, self._press, self._box = None, None, None
            elif self._drag == "orbit" and moved:
                self.camera.orbit(io.mouse_delta.x, io.mouse_delta.y)
            elif self._drag == "box" and moved and self._press is not None:
                self._box = (self._press[0], self._press[1], min(mx, scene_w - 1), min(max(my, 0), h - 1))
            elif self._drag == "pan":
                self.camera.pan(io.mouse_delta.x, io.mouse_delta.y, h)

    # -- selection ------------------------------------------------------------------------------
    def _pixels(self, x: float, y: float) -> tuple[float, float]:
        _, _, sx, sy = self._view
        return x * sx, y * sy

    def _click(self, at: tuple[float, float], add: bool) -> None:
        """Pick the leaf drawn at window point ``at`` (label pass); select it (add: to the selection)."""
        assert self.renderer is not None
        px_w, fh, _, _ = self._view
        leaf = pick(self._picking(), self.camera.camera(px_w, fh), (px_w, fh), *self._pixels(*at), self.settings)
        if leaf is not None:
            self.editor.select([leaf], add=add)
            self.edit_panel.target = 2
        elif not add:
            self.editor.select(np.zeros(0, np.int64))

    def _select_box(self, box: tuple[float, float, float, float], add: bool) -> None:
        """Select the leaves drawn inside ``box`` (window points)."""
        assert self.renderer is not None
        px_w, fh, _, _ = self._view
        x0, y0 = self._pixels(box[0], box[1])
        x1, y1 = self._pixels(box[2], box[3])
        leaves = pick_box(self._picking(), self.camera.camera(px_w, fh), (px_w, fh), (x0, y0, x1, y1), self.settings)
        self.editor.select(leaves, add=add)
        self.edit_panel.target = 2

    def _overlay(self) -> None:
        """The selection box being drawn and a ring on each selected leaf (imgui, over the frame)."""
        dl = imgui.get_foreground_draw_list()
        colour = imgui.get_color_u32(imgui.ImVec4(1.0, 0.85, 0.1, 1.0))
        if self._box is not None:
            x0, y0, x1, y1 = self._box
            dl.add_rect(imgui.ImVec2(min(x0, x1), min(y0, y1)), imgui.ImVec2(max(x0, x1), max(y0, y1)), colour)
        sel = self.editor.selection[:MAX_MARKERS]
        if not sel.size or self.edit_panel.target != 2:
            return
        px_w, fh, sx, sy = self._view
        m = self.scene.matrices[sel]
        centre = m[:, :3, 3] + 0.5 * m[:, :3, 1]    # halfway along the leaf's axis (+y in leaf space)
        xy, ok = project(self.camera.camera(px_w, fh), centre, (px_w, fh))
        for (x, y), vis in zip(xy, ok):
            if vis:
                dl.add_circle(imgui.ImVec2(float(x) / sx, float(y) / sy), 4.0, colour, 0, 1.5)

    def _panel(self, w: int, h: int) -> None:
        assert self.renderer is not None
        imgui.set_next_window_pos(imgui.ImVec2(w - PANEL_WIDTH, 0))
        imgui.set_next_window_size(imgui.ImVec2(PANEL_WIDTH, h))
        flags = imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_collapse
        imgui.begin("Scene", None, flags)
        imgui.text(f"{len(self.scene):,} leaves, {len(self.scene.species)} species")
        imgui.text(f"{len(self.renderer.batches)} batch(es), {self.fps:.1f} fps")
        imgui.text(self.gl_renderer)
        imgui.separator()
        s = self.settings
        changed, cull = imgui.checkbox("culling (C)", s.cull)
        changed2, lod = imgui.checkbox("level of detail (L)", s.lod)
        _, self.renderer.show_veins = imgui.checkbox("veins (V)", self.renderer.show_veins)
        _, err = imgui.slider_float("max outline error (px)", s.max_error_px, 0.1, 8.0)
        _, minpx = imgui.slider_float("smallest leaf (px)", s.min_pixels, 0.0, 8.0)
        self.settings = replace(s, cull=cull, lod=lod, max_error_px=float(err), min_pixels=float(minpx))
        imgui.separator()
        total = int(self.counts.sum())
        imgui.text(f"drawn: {total:,} of {len(self.scene):,}")
        lobed = len(self.renderer.grids)
        for k, ((nu, nv), c) in enumerate(zip(self.renderer.command_grids, self.counts)):
            imgui.text(f"  {nu}×{nv} grid{' (lobed)' if k >= lobed else ''}: {int(c):,}")
        imgui.text(f"triangles: {self.renderer.triangles(self.counts):,}")
        self._look_panel()
        imgui.separator()
        self.edit_panel.draw()
        imgui.end()

    def _look_panel(self) -> None:
        """The Light and Wind sections (the canopy look only)."""
        if self.canopy is None:
            return
        imgui.separator()
        imgui.push_item_width(150)
        if imgui.collapsing_header("Light##look"):
            light, err = settings_widgets(self.light, "light", SUN_RANGES)
            self._look_changed(light is not self.light, err)
            self.light = light
        if imgui.collapsing_header("Wind##look", imgui.TreeNodeFlags_.default_open):
            wind, self.wind_playing, err = wind_widgets(self.wind, self.wind_playing, "wind")
            self._look_changed(wind is not self.wind, err)
            self.wind = wind
        if self.look_error:
            imgui.text_wrapped(self.look_error)
        imgui.pop_item_width()

    def _look_changed(self, changed: bool, err: str | None) -> None:
        if err:
            self.look_error = err
        elif changed:
            self.look_error = None

    # -- framebuffers -------------------------------------------------------------------------------
    def _target(self, w: int, h: int) -> moderngl.Framebuffer:
        if self._render_target is None or self._render_target.size != (w, h):
            self._release_targets()
            self._render_target = RenderTarget(self.ctx, (w, h))
        return self._render_target.fbo

    def _release_targets(self) -> None:
        if self._render_target is not None:
            self._render_target.release()
            self._render_target = None

    def read_frame(self) -> NDArray[np.uint8]:
        """The last frame as (h, w, 4) uint8, row 0 at the top, opaque."""
        if self._render_target is None:
            raise RuntimeError("no frame has been drawn yet")
        img = read_rgba(self._render_target.resolved)
        img[..., 3] = 255
        return img

    def release(self) -> None:
        self._release_targets()
        if self.canopy is not None:
            self.canopy.release()
            self.canopy = None
        if self.renderer is not None:
            self.renderer.release()
            self.renderer = None
        if self.gui is not None:
            self.gui.release()
            self.gui = None
        if self.imgui_ctx is not None:
            imgui.destroy_context(self.imgui_ctx)
            self.imgui_ctx = None


def view_scene(scene: Scene, size: tuple[int, int] = (1280, 800), frames: int | None = None,
               screenshot: str | Path | None = None, *, veins: bool = True, path: str | Path | None = None,
               light: LightSettings | None = None, wind: WindSettings | None = None) -> int:
    """Open ``scene`` in a window (blocks until closed), its veins shown or not (``veins``, the
    panel's checkbox); the edit panel's Save writes ``path`` (the scene file). ``light``, ``wind``:
    the look to start from (None: the scene file's). Returns the exit code."""

    with ViewerWindow(None, size, title="leafview scene",
                      make_view=lambda ctx: SceneView(ctx, scene, veins=veins, path=path, light=light,
                                                      wind=wind)) as win:
        return win.run(frames=frames, screenshot=screenshot)
