"""Keyboard shortcuts and viewport mouse handling, read from imgui's io every frame.

Left drag orbits (or, on a handle, moves that control point), middle or shift+left drag pans,
the wheel dollies. Shortcuts act only when imgui does not want the keyboard (no text field is
being typed in) and no question is open. See :data:`leafview.app.chrome.KEYS`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from imgui_bundle import imgui

from leafview.app.handles import drag_handle, drag_plane_normal, pick, plane_hit, to_leaf_space
from leafview.app.lobe_handles import drag_lobe_handle, handle_flat
from leafview.app.orbit import project
from leafview.app.photo_reference import marker_world, move_marker, plane_normal

if TYPE_CHECKING:  # pragma: no cover
    from leafview.app.viewer import Viewer

__all__ = ["ViewportInput"]

PICK_RADIUS = 10.0


class ViewportInput:
    """The viewport's interaction state: the current drag and the handle under the mouse."""

    def __init__(self, viewer: Viewer) -> None:
        self.viewer = viewer
        self.drag: dict[str, Any] | None = None   # kind, button, (handle, plane point, normal)
        self.hot: str | None = None
        self.refused: str | None = None           # why the last lobe-handle move was refused

    def update(self, scene_w: float, h: int) -> None:
        """Call between ``imgui.new_frame()`` and drawing the panel."""
        io = imgui.get_io()
        if not io.want_capture_keyboard and not self.viewer.files.asking:
            self._shortcuts(scene_w / max(h, 1))
        self._mouse(io, scene_w, h)

    # -- keys -------------------------------------------------------------------------------------
    def _shortcuts(self, aspect: float) -> None:
        v = self.viewer
        state, view = v.state, v.state.view
        io = imgui.get_io()
        key = imgui.Key

        def pressed(k: imgui.Key) -> bool:
            return imgui.is_key_pressed(k, False)

        if io.key_ctrl:
            if pressed(key.z):
                state.redo() if io.key_shift else state.undo()
            elif pressed(key.y):
                state.redo()
            elif pressed(key.s):
                v.files.save()
            return
        if pressed(key.r):
            v.frame_leaf(aspect, reset=True)
        if pressed(key.f):
            v.frame_leaf(aspect, reset=False)
        if pressed(key.w):
            view.wireframe = not view.wireframe
        if pressed(key.c):
            view.show_controls = not view.show_controls
        if pressed(key.g):
            view.show_ground = not view.show_ground
        if pressed(key.p):
            v.screenshot_requested = True
        if pressed(key.h) or pressed(key.f1):
            view.show_help = not view.show_help
        if pressed(key.escape) or pressed(key.q):
            v.files.request_quit()

    # -- mouse ------------------------------------------------------------------------------------
    def _handles_on_screen(self, scene_w: float, h: int) -> np.ndarray:
        v = self.viewer
        assert v.overlay is not None
        cam = v.camera.camera(int(round(scene_w)), h)
        return project(cam, v.overlay.handle_world, int(round(scene_w)), h)

    def _mouse(self, io: Any, scene_w: float, h: int) -> None:
        v = self.viewer
        mx, my = io.mouse_pos.x, io.mouse_pos.y
        inside = 0.0 <= mx < scene_w and 0.0 <= my < h
        overlay = v.overlay if v.state.view.show_controls else None   # the handles, when shown
        if self.drag is None:
            self.hot = None
            if inside and overlay is not None and not io.want_capture_mouse and len(overlay.handle_world):
                self.hot = pick(self._handles_on_screen(scene_w, h), overlay.handle_names, mx, my, PICK_RADIUS)
            if self.hot is None and inside and overlay is not None and not io.want_capture_mouse:
                self.hot = self._pick_marker(mx, my, scene_w, h)
        if self.drag is None and inside and not io.want_capture_mouse and not v.files.asking:
            if imgui.is_mouse_clicked(imgui.MouseButton_.left):
                if self.hot is not None and self.hot.startswith("photo:"):
                    self.drag = {"kind": "marker", "button": imgui.MouseButton_.left, "handle": self.hot}
                elif self.hot is not None:
                    self._start_handle(self.hot, scene_w, h)
                else:
                    self.drag = {"kind": "pan" if io.key_shift else "orbit", "button": imgui.MouseButton_.left}
            elif imgui.is_mouse_clicked(imgui.MouseButton_.middle):
                self.drag = {"kind": "pan", "button": imgui.MouseButton_.middle}
            if io.mouse_wheel:
                v.camera.dolly(float(io.mouse_wheel))
        if self.drag is None:
            return
        if not imgui.is_mouse_down(self.drag["button"]):
            if self.drag["kind"] in ("handle", "lobe"):
                v.state.end_gesture()
            self.drag = None
            return
        dx, dy = io.mouse_delta.x, io.mouse_delta.y
        kind = self.drag["kind"]
        if kind == "orbit" and (dx or dy):
            v.camera.orbit(dx, dy)
        elif kind == "pan" and (dx or dy):
            v.camera.pan(dx, dy, h)
        elif kind == "handle" and (dx or dy):
            self._move_handle(mx, my, scene_w, h)
        elif kind == "lobe" and (dx or dy):
            self._move_lobe_handle(mx, my, scene_w, h)
        elif kind == "marker" and (dx or dy):
            self._move_marker(mx, my, scene_w, h)

    def _pick_marker(self, mx: float, my: float, scene_w: float, h: int) -> str | None:
        """The reference photo's base or apex marker under the mouse, if shown."""
        state = self.viewer.state
        where = marker_world(state.reference, state.params) if state.reference.visible else {}
        if not where:
            return None
        cam = self.viewer.camera.camera(int(round(scene_w)), h)
        screen = project(cam, np.array(list(where.values())), int(round(scene_w)), h)
        return pick(screen, where, mx, my, PICK_RADIUS)

    def _move_marker(self, mx: float, my: float, scene_w: float, h: int) -> None:
        """Drag a photo marker within the photo's plane."""
        v, d = self.viewer, self.drag
        assert d is not None
        where = marker_world(v.state.reference, v.state.params)
        if d["handle"] not in where:
            return
        origin, direction = v.camera.ray(mx, my, int(round(scene_w)), h)
        hit = plane_hit(origin, direction, where[d["handle"]], plane_normal(v.state.params))
        if hit is not None:
            move_marker(v.state, d["handle"], hit)

    def _start_handle(self, name: str, scene_w: float, h: int) -> None:
        v = self.viewer
        assert v.overlay is not None
        i = v.overlay.handle_names.index(name)
        self.refused = None
        if v.overlay.lobed:
            self._start_lobe_handle(name, v.overlay.handle_world[i])
            return
        point, along = v.overlay.handle_world[i], float(v.overlay.handle_v[i])
        view_dir = point - v.camera.eye()
        assert v.overlay.frame is not None
        normal = drag_plane_normal(v.overlay.frame, along, view_dir / np.linalg.norm(view_dir))
        self.drag = {"kind": "handle", "button": imgui.MouseButton_.left, "handle": name,
                     "point": point, "normal": normal, "v": along, "frame": v.overlay.frame}
        self.hot = name

    def _drag_hit(self, mx: float, my: float, scene_w: float, h: int) -> np.ndarray | None:
        """Where the cursor's ray meets the dragged handle's plane (None: parallel to it)."""
        d = self.drag
        assert d is not None
        origin, direction = self.viewer.camera.ray(mx, my, int(round(scene_w)), h)
        return plane_hit(origin, direction, d["point"], d["normal"])

    def _move_handle(self, mx: float, my: float, scene_w: float, h: int) -> None:
        v, d = self.viewer, self.drag
        assert d is not None
        hit = self._drag_hit(mx, my, scene_w, h)
        if hit is None:
            return
        leaf_point = d["frame"].to_leaf(hit, [d["v"]])[0]
        name = d["handle"]
        v.state.apply(lambda p: drag_handle(p, name, leaf_point), gesture=f"handle:{name}")

    # -- lobed leaves (leafview.app.lobe_handles) ---------------------------------------------
    def _start_lobe_handle(self, name: str, point: np.ndarray) -> None:
        """A lobe tip or valley: moved in the leaf plane through its rim point; every move is
        applied to the leaf as it was when the drag started (no drift, one undo step)."""
        v = self.viewer
        params = v.state.params
        view_dir = point - v.camera.eye()
        view_dir = view_dir / np.linalg.norm(view_dir)
        m = params.transform.matrix()
        normal = m[:3, 2] / np.linalg.norm(m[:3, 2])
        if abs(float(np.dot(normal, view_dir))) < 0.15:   # the leaf plane seen edge-on
            normal = -view_dir
        self.drag = {"kind": "lobe", "button": imgui.MouseButton_.left, "handle": name, "point": point,
                     "normal": normal, "base": params, "start": to_leaf_space(params, point)[0],
                     "flat": handle_flat(params.lobes, name)}
        self.hot = name

    def _move_lobe_handle(self, mx: float, my: float, scene_w: float, h: int) -> None:
        v, d = self.viewer, self.drag
        assert d is not None
        hit = self._drag_hit(mx, my, scene_w, h)
        if hit is None:
            return
        base, name = d["base"], d["handle"]
        target = d["flat"] + (to_leaf_space(base, hit)[0] - d["start"])[:2]
        changed = v.state.apply(lambda _: drag_lobe_handle(base, name, target), gesture=f"lobe:{name}")
        self.refused = v.state.error if not changed and v.state.error else None
