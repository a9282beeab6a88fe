"""A live, orbitable leaf (or scene) in a Jupyter notebook: :class:`LeafWidget`.

The canvas is a :class:`jupyter_rfb.RemoteFrameBuffer`: the kernel draws each frame offscreen on
the shared headless renderer (:func:`leafview.gpu.default_renderer`) and sends it to the browser,
which sends back pointer and wheel events. Drag orbits (shift+drag or the right/middle button
pans), the wheel dollies, a double click brings back the home view: the viewer's
:class:`~leafview.app.orbit.OrbitCamera`.

Beside a leaf sit ipywidgets sliders for its main parameters (:data:`KNOBS`): width, asymmetry
and curvature (the edits of Chaurasia & Beardsley 2017, sec. 6, :mod:`leafview.core.edits`),
serration (jitter) and bending. Each slider's range and step are the ``soft_range`` and
``step`` of a field's :class:`~leafview.core.params.FieldSpec`, the metadata the viewer's panel
draws its sliders from. A scene gets the canvas only.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

import ipywidgets
import numpy as np
from IPython.display import display
from jupyter_rfb import RemoteFrameBuffer
from numpy.typing import NDArray

from leafview.app.handles import to_world
from leafview.app.orbit import OrbitCamera
from leafview.app.state import get_field, with_field
from leafview.botany.leaf_surface import grid_points
from leafview.core.edits import curve_axis, curve_longitudinal, scale_width, skew_axis
from leafview.core.params import LeafParams, ParamError, field_specs
from leafview.errors import UsageError
from leafview.gpu import default_renderer
from leafview.gpu.scene import SceneRenderer
from leafview.scene.spec import Scene, SceneSpec, build_scene, load_scene

__all__ = ["LeafWidget", "Knob", "KNOBS", "LEAF_BACKGROUND", "SCENE_BACKGROUND"]

LEAF_BACKGROUND = (0.93, 0.94, 0.95, 1.0)   # light, as a notebook page
SCENE_BACKGROUND = (0.62, 0.72, 0.80, 1.0)  # a pale sky behind the canopy
WHEEL_PX_PER_STEP = 100.0                   # browser wheel pixels per dolly step


@dataclass(frozen=True)
class Knob:
    """One slider: ``get`` reads its value from a leaf, ``set`` returns the leaf with it changed
    (validated, may raise :class:`ParamError`); range and step come from the FieldSpec of
    ``spec`` (a dotted field path), ``positive`` keeps the lower end above zero."""

    key: str
    label: str
    spec: str
    get: Callable[[LeafParams], float]
    set: Callable[[LeafParams, float], LeafParams]
    positive: bool = False

    def range(self) -> tuple[float, float, float]:
        """(min, max, step) of the slider."""
        spec = field_specs()[self.spec]
        lo, hi = (float(x) for x in spec.soft_range)
        step = float(spec.step)
        return (max(lo, step) if self.positive else lo), hi, step


def _widest(p: LeafParams) -> float:
    return max(float(x) for _, x, _ in p.shape.silhouette)


def _set_widest(p: LeafParams, value: float) -> LeafParams:
    widest = _widest(p)
    if widest <= 0.0:
        raise ParamError("shape.silhouette", "the leaf has no width to scale")
    return scale_width(p, value / widest)


def _skew(p: LeafParams) -> float:
    return (p.shape.a1[0] + p.shape.a2[0]) / 2


def _axis_lift(p: LeafParams) -> float:
    return (p.shape.a1[2] + p.shape.a2[2]) / 2


def _mean(values: Any) -> float:
    vals = [float(v) for v in values]
    return sum(vals) / max(len(vals), 1)


def _serration(p: LeafParams) -> float:
    return float(p.jitter.amplitude) if p.jitter.enabled else 0.0


def _set_serration(p: LeafParams, value: float) -> LeafParams:
    return with_field(with_field(p, "jitter.amplitude", value), "jitter.enabled", value > 0.0)


def _field(path: str, label: str) -> Knob:
    """A knob for one scalar field, set through the viewer's validated ``with_field``."""
    return Knob(path, label, path, lambda p: float(get_field(p, path)), lambda p, v: with_field(p, path, v))


KNOBS: tuple[Knob, ...] = (
    Knob("width", "width (widest x̄s)", "shape.silhouette", _widest, _set_widest, positive=True),
    Knob("asymmetry", "asymmetry (axis skew)", "shape.a1", _skew, lambda p, v: skew_axis(p, v - _skew(p))),
    Knob("axis_curvature", "axis curvature", "shape.a1", _axis_lift, curve_axis),
    Knob("f_curvature", "F curvature (z̄f)", "shape.zf", lambda p: _mean(p.shape.zf),
         lambda p, v: curve_longitudinal(p, "F", v)),
    Knob("g_curvature", "G curvature (z̄g)", "shape.zg", lambda p: _mean(p.shape.zg),
         lambda p, v: curve_longitudinal(p, "G", v)),
    Knob("serration", "serration (jitter)", "jitter.amplitude", _serration, _set_serration),
    _field("jitter.density", "teeth per leaf"),
    _field("bending.load", "bend (load)"),
    _field("bending.twist", "twist (degrees)"),
)
"""The sliders of a leaf widget, in order."""


def _decimals(step: float) -> int:
    return 0 if step >= 1 else min(6, math.ceil(-math.log10(step) - 1e-9))


def _scene_of(obj: Scene | SceneSpec | str | os.PathLike[str]) -> Scene:
    if isinstance(obj, Scene):
        return obj
    spec = obj if isinstance(obj, SceneSpec) else load_scene(obj)
    return build_scene(spec)


class LeafWidget(RemoteFrameBuffer):
    """A leaf (with sliders) or a scene (orbit only) drawn live in a notebook.

    Parameters
    ----------
    params_or_scene:
        :class:`~leafview.core.params.LeafParams`, or a :class:`~leafview.scene.spec.Scene`, a
        :class:`~leafview.scene.spec.SceneSpec` or the path of a scene file (built here).
    size:
        (width, height) of the canvas in CSS pixels; the frame follows the browser's pixel ratio
        and later resizes.
    knobs:
        The sliders beside a leaf (default :data:`KNOBS`; ``()`` for none).
    background:
        RGBA clear colour (default :data:`LEAF_BACKGROUND`, or :data:`SCENE_BACKGROUND`).

    Display the widget (last expression of a cell, or ``display(w)``) to get the canvas with its
    sliders (:attr:`ui`). :attr:`params` is the current leaf (settable), :meth:`snapshot` the
    current frame, :meth:`get_frame` renders one, :meth:`close` frees the GPU rows of a scene.
    """

    def __init__(self, params_or_scene: LeafParams | Scene | SceneSpec | str | os.PathLike[str],
                 size: tuple[int, int] = (480, 360), *, knobs: tuple[Knob, ...] = KNOBS,
                 background: tuple[float, float, float, float] | None = None, **kwargs: Any) -> None:
        width, height = (int(x) for x in size)
        if width < 1 or height < 1:
            raise UsageError(f"size must be two positive numbers of pixels, got {size!r}")
        kwargs.setdefault("css_width", f"{width}px")
        kwargs.setdefault("css_height", f"{height}px")
        super().__init__(**kwargs)
        self._size = (width, height)    # logical (CSS) pixels: what pointer events measure
        self._pixels = (width, height)  # the frame: physical pixels
        self._renderer = default_renderer()
        self._scene_renderer: SceneRenderer | None = None
        self._params: LeafParams | None = None
        self.scene: Scene | None = None
        self.knobs = knobs
        self._drag: tuple[str, float, float] | None = None
        self._syncing = False
        self.camera = OrbitCamera(target=np.zeros(3))
        if isinstance(params_or_scene, LeafParams):
            self._params = params_or_scene
            self.background = background if background is not None else LEAF_BACKGROUND
        else:
            self.scene = _scene_of(params_or_scene)
            self.background = background if background is not None else SCENE_BACKGROUND
            self._scene_renderer = SceneRenderer(self._renderer.ctx, self.scene, resources=self._renderer.resources)
        self.reset_view()
        self.sliders: dict[str, ipywidgets.FloatSlider] = {}
        self.status = ipywidgets.HTML("")
        if self._params is not None:
            for knob in knobs:
                self.sliders[knob.key] = self._slider(knob, self._params)
        controls: list[Any] = list(self.sliders.values())
        reset = ipywidgets.Button(description="reset view", layout=ipywidgets.Layout(width="120px"))
        reset.on_click(lambda _: self.reset_view())
        controls += [reset, self.status]
        self.ui = ipywidgets.HBox([self, ipywidgets.VBox(controls)])

    # -- the leaf -------------------------------------------------------------------------------
    @property
    def params(self) -> LeafParams | None:
        """The current leaf (None for a scene); setting it moves the sliders and redraws."""
        return self._params

    @params.setter
    def params(self, value: LeafParams) -> None:
        if self._params is None:
            raise UsageError("this widget shows a scene: it has no leaf parameters to set")
        if not isinstance(value, LeafParams):
            raise UsageError(f"expected LeafParams, got {type(value).__name__}")
        self._params = value
        self._sync_sliders()
        self.request_draw()

    def _slider(self, knob: Knob, params: LeafParams) -> ipywidgets.FloatSlider:
        lo, hi, step = knob.range()
        value = knob.get(params)
        slider = ipywidgets.FloatSlider(
            value=value, min=min(lo, value), max=max(hi, value), step=step, description=knob.label,
            continuous_update=True, readout_format=f".{_decimals(step)}f",
            style={"description_width": "150px"}, layout=ipywidgets.Layout(width="360px"))
        slider.observe(partial(self._on_slider, knob), names="value")
        return slider

    def _on_slider(self, knob: Knob, change: dict[str, Any]) -> None:
        if self._syncing or self._params is None:
            return
        try:
            new = knob.set(self._params, float(change["new"]))
        except (ParamError, ValueError) as exc:   # an edit that would make an invalid leaf
            self.status.value = f"<span style='color:#b00'>{exc}</span>"
            return
        self.status.value = ""
        self._params = new
        self._sync_sliders(skip=knob.key)
        self.request_draw()

    def _sync_sliders(self, skip: str | None = None) -> None:
        """Move every slider (but ``skip``) to the current leaf without firing its edit."""
        if self._params is None:
            return
        self._syncing = True
        try:
            for knob in self.knobs:
                slider = self.sliders.get(knob.key)
                if slider is None or knob.key == skip:
                    continue
                value = knob.get(self._params)
                slider.min, slider.max = min(slider.min, value), max(slider.max, value)
                slider.value = value
        finally:
            self._syncing = False

    # -- the camera -----------------------------------------------------------------------------
    def _points(self) -> NDArray[np.float64]:
        if self._params is not None:
            # the drawn surface (a lobed leaf's sweep; deform.surface knows only Ω)
            return to_world(self._params, grid_points(self._params, (17, 33)))
        assert self.scene is not None
        lo, hi = self.scene.bounds()
        return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])

    def reset_view(self) -> None:
        """The home (three-quarter) view, framed on the leaf or the scene."""
        w, h = self._size
        self.camera.reset(self._points(), w / h)
        if self.scene is not None:
            self.camera.radius *= 2.0   # room to dolly out and a generous far plane (as the scene viewer)
        self.request_draw()

    # -- jupyter_rfb ----------------------------------------------------------------------------
    def get_frame(self) -> NDArray[np.uint8]:
        """Render the current view: (h, w, 4) uint8 RGBA at the canvas's physical size."""
        w, h = self._pixels
        camera = self.camera.camera(w, h)
        if self._scene_renderer is not None:
            return self._scene_renderer.render(camera, (w, h), background=self.background)
        if self._params is None:
            raise UsageError("this scene widget was closed: its GPU rows are released")
        frame: NDArray[np.uint8] = self._renderer.render_many(
            [self._params], (w, h), "three-quarter", self.background, camera=camera)[0]
        return frame

    def handle_event(self, event: dict[str, Any]) -> None:
        """Pointer drags orbit (shift or a second button: pan), the wheel dollies, a double click
        resets the view; resize follows the canvas; close frees the scene's GPU rows."""
        kind = event.get("type", event.get("event_type"))
        if kind == "resize":
            w, h = max(1.0, float(event["width"])), max(1.0, float(event["height"]))
            ratio = float(event.get("ratio", event.get("pixel_ratio", 1.0)) or 1.0)
            self._size = (max(1, round(w)), max(1, round(h)))
            self._pixels = (max(1, int(event.get("pwidth", w * ratio))), max(1, int(event.get("pheight", h * ratio))))
        elif kind == "pointer_down":
            pan = event.get("button") in (2, 3) or "Shift" in event.get("modifiers", ())
            self._drag = ("pan" if pan else "orbit", float(event["x"]), float(event["y"]))
        elif kind == "pointer_move" and self._drag is not None:
            mode, x0, y0 = self._drag
            x, y = float(event["x"]), float(event["y"])
            if mode == "pan":
                self.camera.pan(x - x0, y - y0, self._size[1])
            else:
                self.camera.orbit(x - x0, y - y0)
            self._drag = (mode, x, y)
            self.request_draw()
        elif kind == "pointer_up":
            self._drag = None
        elif kind == "wheel":
            self.camera.dolly(-float(event.get("dy", 0.0)) / WHEEL_PX_PER_STEP)
            self.request_draw()
        elif kind == "double_click":
            self.reset_view()
        elif kind == "close":
            self.release()

    def snapshot(self, pixel_ratio: float | None = None) -> Any:
        """The current view as a fresh frame: jupyter_rfb's snapshot (shows as an image in a cell;
        its ``data`` is the (h, w, 4) uint8 array)."""
        self.send_frame(self.get_frame())
        return super().snapshot()

    # -- display and lifetime -------------------------------------------------------------------
    def _ipython_display_(self) -> None:
        display(self.ui)

    def release(self) -> None:
        """Free the scene's GPU rows (idempotent; the shared renderer stays)."""
        if self._scene_renderer is not None:
            self._scene_renderer.release()
            self._scene_renderer = None
