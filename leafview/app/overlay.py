"""Viewport overlays drawn with ``shaders/overlay.vert``/``overlay.frag``: the control polygons
and curves of A, S±, F± and G± (as in Chaurasia & Beardsley 2017, Figs 1 and 7), the drag handles and the ground
grid. A lobed leaf shows instead its skeleton (Mündermann et al. 2003, sec. 3.2), the margin's control polygon,
its tip and valley handles and its display-only junctions (:mod:`leafview.app.lobe_handles`).

Vertex data is rebuilt only when the leaf changes (the viewer passes its revision); every frame
then costs one small uniform write and a few draws.
"""

from __future__ import annotations

from collections.abc import Sequence

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.app.handles import HANDLE_NAMES, LeafFrame, handle_names, handle_parameters, handle_points, to_world
from leafview.app.lobe_handles import lift_flat, lift_margin, lobe_handles, margin_offsets, skeleton_lines
from leafview.core.bezier import bernstein
from leafview.core.params import LeafParams
from leafview.deform.surface import control_polygons
from leafview.gpu.shaders import build_program

__all__ = ["Overlay", "CURVE_COLORS", "control_lines", "lobe_lines", "lobe_points", "ground_lines"]

# sRGB colours (the target is 8-bit sRGB, like the leaf's output)
CURVE_COLORS = {
    "A": (0.95, 0.30, 0.20),   # axis: red
    "S": (1.00, 0.82, 0.15),   # silhouette: yellow
    "F": (0.25, 0.75, 1.00),   # F (1/3 width): blue
    "G": (0.85, 0.45, 1.00),   # G (2/3 width): violet
}
SKELETON_COLOR = (0.95, 0.30, 0.20)   # a lobed leaf's skeleton: red, like the axis A
MARGIN_COLOR = (1.00, 0.82, 0.15)     # its margin's control polygon: yellow, like S
FIXED_COLOR = (0.62, 0.62, 0.66, 1.0)  # display-only points (junctions, root)
HANDLE_COLOR = (1.0, 1.0, 1.0, 1.0)
HANDLE_HOT = (1.0, 0.45, 0.1, 1.0)
_CURVE_SAMPLES = 48
_VERTEX = np.dtype([("pos", "f4", 3), ("color", "f4", 4)])


def _segments(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """A polyline as GL_LINES pairs."""
    return np.repeat(points, 2, axis=0)[1:-1]


def control_lines(params: LeafParams, frame: LeafFrame | None = None) -> NDArray:
    """Line vertices (world space) of every control polygon (dim) and curve (bright); with the
    midrib bend of ``frame`` (control points at their axis parameter, curve points at theirs)."""
    frame = frame if frame is not None else LeafFrame(params)
    polys = control_polygons(params)
    t = np.linspace(0.0, 1.0, _CURVE_SAMPLES)
    basis = {n: bernstein(n, t) for n in (3, len(polys["S+"]) - 1)}  # axis; S, F, G (degree N + 1)
    v_axis = np.linspace(0.0, 1.0, 4)
    v_side = np.array([0.0, *params.shape.vbar, 1.0])
    chunks = []
    for name, ctrl in polys.items():
        curve = basis[len(ctrl) - 1] @ ctrl
        v_ctrl = v_axis if len(ctrl) == 4 else v_side
        for pts, v, alpha in ((ctrl, v_ctrl, 0.55), (curve, t, 1.0)):
            world = frame.to_world(pts, v)
            seg = _segments(world)
            out = np.empty(len(seg), _VERTEX)
            out["pos"] = seg
            out["color"] = (*CURVE_COLORS[name[0]], alpha)
            chunks.append(out)
    return np.concatenate(chunks)


def _lines(polylines: list[NDArray[np.float64]], color: tuple[float, ...]) -> NDArray:
    chunks = []
    for pts in polylines:
        seg = _segments(pts)
        out = np.empty(len(seg), _VERTEX)
        out["pos"] = seg
        out["color"] = color
        chunks.append(out)
    return np.concatenate(chunks) if chunks else np.zeros(0, _VERTEX)


def lobe_lines(params: LeafParams) -> NDArray:
    """Line vertices (world space) of a lobed leaf's skeleton (bright, each tip extended to its
    anchor on the margin) and its margin's closed control polygon (dim)."""
    ctrl = np.zeros((len(params.lobes.outline) + 1, 3))
    ctrl[:-1, :2] = params.lobes.outline
    # each control point moves with the drawn rim at its own curve point (t = j / m): bent and
    # twisted branches carry the polygon with them
    ctrl[:-1] += margin_offsets(params)
    ctrl[-1] = ctrl[0]
    skel = [to_world(params, line) for line in skeleton_lines(params)]
    return np.concatenate([_lines([to_world(params, ctrl)], (*MARGIN_COLOR, 0.35)),
                           _lines(skel, (*SKELETON_COLOR, 1.0))])


def lobe_points(params: LeafParams) -> tuple[tuple[str, ...], NDArray[np.float64], NDArray[np.float64]]:
    """A lobed leaf's handle names, their world positions (on the drawn rim) and the world
    positions of its display-only points (junctions, root)."""
    h = lobe_handles(params.lobes)
    handles = to_world(params, lift_margin(params, h.w))
    fixed = to_world(params, lift_flat(params, h.fixed_points))
    return h.names, handles, fixed


def _uniform(program: moderngl.Program, name: str) -> moderngl.Uniform:
    """``program[name]`` as the plain uniform it is (moderngl types a lookup as any member kind)."""
    member = program[name]
    assert isinstance(member, moderngl.Uniform), f"{name} is not a plain uniform"
    return member


def ground_lines(center: Sequence[float] | NDArray[np.float64], z: float, half: float, step: float) -> NDArray:
    """A square grid of lines in the plane ``z``, centred under ``center`` (world xy)."""
    n = max(1, int(round(half / step)))
    cx, cy = round(center[0] / step) * step, round(center[1] / step) * step
    ticks = np.arange(-n, n + 1) * step
    lines = []
    for t in ticks:
        lines += [(cx + t, cy - n * step, z), (cx + t, cy + n * step, z),
                  (cx - n * step, cy + t, z), (cx + n * step, cy + t, z)]
    v = np.zeros(len(lines), _VERTEX)
    v["pos"] = lines
    major = np.repeat(np.abs(ticks) < 1e-9, 4)
    v["color"] = np.where(major[:, None], (0.55, 0.58, 0.62, 0.9), (0.38, 0.40, 0.44, 0.6))
    return v


class Overlay:
    """GL objects for the overlays of one context; :meth:`release` frees them."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.program = build_program(ctx, "overlay.vert", "overlay.frag")
        self.vbo = ctx.buffer(reserve=1 << 16, dynamic=True)
        self.vao = ctx.vertex_array(self.program, [(self.vbo, "3f 4f", "in_pos", "in_color")])
        self._lines = np.zeros(0, _VERTEX)
        self._ground = np.zeros(0, _VERTEX)
        self._handles = np.zeros(0, _VERTEX)
        self._key: tuple | None = None
        self.handle_world = np.zeros((0, 3))
        self.handle_v = np.zeros(0)
        self.frame: LeafFrame | None = None
        self.handle_names: tuple[str, ...] = HANDLE_NAMES
        self.fixed_world = np.zeros((0, 3))   # display-only points (a lobed leaf's junctions)
        self.lobed = False

    def update(self, params: LeafParams, revision: int, ground_center: Sequence[float] | NDArray[np.float64],
               ground_z: float, ground_half: float) -> None:
        """Rebuild the vertex data if the leaf (``revision``) or the ground placement changed."""
        key = (revision, tuple(np.round(ground_center, 6)), round(ground_z, 6), round(ground_half, 6))
        if key == self._key:
            return
        self._key = key
        self.frame = LeafFrame(params)
        self.lobed = params.lobes.enabled
        if self.lobed:
            self.handle_names, self.handle_world, self.fixed_world = lobe_points(params)
            self.handle_v = np.zeros(len(self.handle_names))
            self._lines = lobe_lines(params)
        else:
            self.handle_names = handle_names(params)
            self._lines = control_lines(params, self.frame)
            hp, hv = handle_points(params), handle_parameters(params)
            self.handle_v = np.array([hv[n] for n in self.handle_names])
            self.handle_world = self.frame.to_world(np.array([hp[n] for n in self.handle_names]), self.handle_v)
            self.fixed_world = np.zeros((0, 3))
        step = 10 ** np.floor(np.log10(max(ground_half, 1e-3) / 2.0))
        self._ground = ground_lines(ground_center, ground_z, ground_half, step)

    def _draw(self, data: NDArray, mode: int, view_proj: NDArray[np.float64], point_size: float = 1.0,
              round_points: bool = False) -> None:
        if len(data) == 0:
            return
        raw = data.tobytes()
        if len(raw) > self.vbo.size:
            self.vbo.orphan(1 << (len(raw) - 1).bit_length())
        self.vbo.write(raw)
        _uniform(self.program, "view_proj").write(view_proj.T.astype("f4").tobytes())
        _uniform(self.program, "point_size").value = float(point_size)
        _uniform(self.program, "round_points").value = bool(round_points)
        self.vao.render(mode, vertices=len(data))

    def draw_ground(self, view_proj: NDArray[np.float64]) -> None:
        """The ground grid, depth-tested against the leaf, blended."""
        self.ctx.enable(moderngl.DEPTH_TEST | moderngl.BLEND)
        self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        try:
            self._draw(self._ground, moderngl.LINES, view_proj)
        finally:
            self.ctx.disable(moderngl.BLEND)

    def draw_controls(self, view_proj: NDArray[np.float64], hot: str | None = None) -> None:
        """Control polygons, curves and handles, on top of the leaf (no depth test)."""
        ctx = self.ctx
        ctx.disable(moderngl.DEPTH_TEST)
        ctx.enable(moderngl.BLEND | moderngl.PROGRAM_POINT_SIZE)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        try:
            self._draw(self._lines, moderngl.LINES, view_proj)
            if len(self.fixed_world):
                fixed = np.zeros(len(self.fixed_world), _VERTEX)
                fixed["pos"] = self.fixed_world
                fixed["color"] = FIXED_COLOR
                self._draw(fixed, moderngl.POINTS, view_proj, point_size=6.0, round_points=True)
            pts = np.zeros(len(self.handle_world), _VERTEX)
            pts["pos"] = self.handle_world
            pts["color"] = HANDLE_COLOR
            self._draw(pts, moderngl.POINTS, view_proj, point_size=9.0, round_points=True)
            if hot in self.handle_names:
                i = self.handle_names.index(hot)
                self._draw(pts[i:i + 1].copy(), moderngl.POINTS, view_proj, point_size=14.0, round_points=True)
                hot_pt = pts[i:i + 1].copy()
                hot_pt["color"] = HANDLE_HOT
                self._draw(hot_pt, moderngl.POINTS, view_proj, point_size=10.0, round_points=True)
        finally:
            ctx.disable(moderngl.BLEND | moderngl.PROGRAM_POINT_SIZE)

    def release(self) -> None:
        for obj in (self.vao, self.vbo, self.program):
            obj.release()
