"""Vein tubes on the GPU: the close-up geometry of a leaf's veins (Hong 2005, ch. 6.1), swept
from the veins' (u, v) polylines around the blade the leaf shader evaluates (numpy twin, frame and
level of detail: :mod:`leafview.botany.vein_tubes`). Two passes a draw:

1. ``shaders/vein_tube_frame.vert`` evaluates the blade (``leaf_eval.glsl``) at both ends of each
   drawn segment and captures the two end frames (transform feedback, one point a segment);
2. ``shaders/vein_tube.vert`` + ``vein_tube.frag`` sweep the rings from them: one instanced
   triangle-strip draw per level-of-detail bucket (ring sides), indirect, its segments a
   contiguous range of instances.

So the blade is evaluated twice per segment, not once per ring vertex (26 for 12 sides).

:class:`VeinTubes` owns one leaf's segment rows (static), the rows of the drawn segments sorted by
bucket (rewritten when the level of detail changes), their frames, one indirect command per
bucket, and its vertex arrays.
It draws with the leaf's state that :meth:`LeafRenderer.draw <leafview.gpu.renderer.LeafRenderer.draw>`
leaves bound (Leaf block, Frame block, jitter rows, ripple signals, and the vein grid when the
leaf has one), so a renderer calls :meth:`VeinTubes.draw` right after drawing the blade.
"""

from __future__ import annotations

from collections.abc import Sequence

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.botany.vein_tubes import (
    CREASE_U,
    OFFSET,
    SIDE_BUCKETS,
    TubeSegments,
    VeinCurve,
    strip_vertices,
    tube_lod,
    tube_segments,
)
from leafview.botany.venation import vein_tree
from leafview.core.params import LeafParams
from leafview.gpu.capture import FeedbackCapture
from leafview.gpu.frame import FrameUniforms
from leafview.gpu.limits import check_buffer, ensure_alive
from leafview.gpu.owner import GLObjects, GrowingBuffer
from leafview.gpu.programs import ProgramCache
from leafview.gpu.resources import LEAF_SPACE_VARYINGS, GpuResources
from leafview.scene.camera import Camera

__all__ = ["VeinTubes", "TUBE_TINT", "tube_defines"]

TUBE_TINT = 0.45          # how far a vein's colour goes toward the pale vein tissue (vein_tube.frag)
_RECORD_FORMAT = "4f 4f 4f"                    # a segment row (TubeSegments.records), one per point
_RECORD_ATTRIBUTES = ("in_a", "in_b", "in_r")
_FRAME_VARYINGS = ("t_ca", "t_na", "t_ba", "t_cb", "t_nb", "t_bb")
_FRAME_FORMAT = "4f 3f 3f 4f 3f 3f/i"           # the captured end frames, one per instance
_FRAME_ATTRIBUTES = ("in_ca", "in_na", "in_ba", "in_cb", "in_nb", "in_bb")
_FRAME_BYTES = 80
# DrawArraysIndirectCommand, padded to 20 bytes: moderngl's render_indirect steps commands by 20
# bytes (the indexed command's size) for non-indexed draws too
_COMMAND = np.dtype([("count", "<u4"), ("instances", "<u4"), ("first", "<u4"),
                     ("base_instance", "<u4"), ("unused", "<u4")])


def tube_defines() -> dict[str, str]:
    """The constants of the numpy twin as the shaders' defines (one place for each number)."""
    return {"TUBE_OFFSET": f"{OFFSET:.9e}", "TUBE_CREASE_U": f"{CREASE_U:.9e}", "TUBE_TINT": f"{TUBE_TINT:.9e}"}


def _view_proj(frame: FrameUniforms | Camera) -> NDArray[np.float64]:
    """``proj · view`` (column-vector) of a camera, or of a Frame block as the renderer filled it."""
    if isinstance(frame, Camera):
        return np.asarray(frame.proj, np.float64) @ np.asarray(frame.view, np.float64)
    rec = frame.record
    return np.asarray(rec["proj"], np.float64).T @ np.asarray(rec["view"], np.float64).T


class VeinTubes:
    """The vein tubes of one leaf.

    Parameters
    ----------
    ctx:
        The context the leaf is drawn in.
    leaf:
        The leaf (its venation, shape and transform); ``None``: no tubes until :meth:`update`.
    veins:
        The veins to sweep (objects with ``uv``, ``points``, ``order`` and ``width``, like
        :class:`leafview.botany.venation.Vein`); default the leaf's vein tree when its venation
        is enabled (:func:`~leafview.botany.venation.vein_tree`: unedited (u, v), as the vein
        field; the leaf's vein-shape grid moves them with the blade), else none.
    resources:
        Shared programs and capture (:class:`~leafview.gpu.resources.GpuResources`, e.g. the
        renderer's); ``None``: a program cache and capture of its own.
    """

    def __init__(self, ctx: moderngl.Context, leaf: LeafParams | None = None,
                 veins: Sequence[VeinCurve] | None = None, *, resources: GpuResources | None = None) -> None:
        self.ctx = ctx
        self._objects = GLObjects()
        self._vaos: dict[str, tuple[tuple[int, int], moderngl.VertexArray]] = {}
        try:
            if resources is not None:
                self.programs, self._capture = resources.programs, resources.capture
            else:
                self.programs = self._objects.own(ProgramCache(ctx))
                self._capture = self._objects.own(FeedbackCapture(ctx))
            self._static = self._objects.own(GrowingBuffer(ctx))
            self._rows = self._objects.own(GrowingBuffer(ctx))
            self._commands = self._objects.own(GrowingBuffer(ctx))
            self._frame_rows = self._objects.own(GrowingBuffer(ctx))
            self.leaf: LeafParams | None = None
            self.set_veins(leaf, veins)
        except BaseException:
            self.release()
            raise

    @property
    def program(self) -> moderngl.Program:
        """``vein_tube.vert`` + ``vein_tube.frag``, the sweep (compiled on first use, cached with
        the others; captures leaf-space positions and normals)."""
        return self.programs.program("vein_tube.vert", "vein_tube.frag", defines=tube_defines(),
                                     varyings=LEAF_SPACE_VARYINGS)

    @property
    def frame_program(self) -> moderngl.Program:
        """``vein_tube_frame.vert``, the end frames of each segment (transform feedback only)."""
        return self.programs.program("vein_tube_frame.vert", defines=tube_defines(), varyings=_FRAME_VARYINGS)

    # -- data -----------------------------------------------------------------------------------
    def set_veins(self, leaf: LeafParams | None, veins: Sequence[VeinCurve] | None = None) -> None:
        """Replace the leaf and its veins (default: see the class); re-uploads the segment rows."""
        if veins is None:
            veins = vein_tree(leaf) if leaf is not None and leaf.venation.enabled else []
        self.leaf = leaf
        self.segments: TubeSegments = tube_segments(veins)
        self.veins = len(veins)
        m = leaf.transform.matrix() if leaf is not None else np.eye(4)
        self._world = self.segments.points @ m[:3, :3].T + m[:3, 3]   # every polyline point once
        self._scale = float(leaf.transform.scale) if leaf is not None else 1.0
        records = self.segments.records()
        check_buffer(records.nbytes, "venation", f"{len(self.segments):,} vein tube segments")
        if len(records):
            self._static.write(records)
        self._drawn_key: bytes | None = None
        self.buckets: dict[int, int] = {}

    def update(self, leaf: LeafParams | None) -> None:
        """Follow the renderer's leaf: its vein tree when its venation is enabled, none for
        ``None`` (veins switched off); rebuilt only when the leaf changed."""
        if leaf is None:
            if self.leaf is not None or len(self.segments):
                self.set_veins(None)
        elif leaf != self.leaf:
            self.set_veins(leaf)

    # -- level of detail ------------------------------------------------------------------------
    def lod(self, frame: FrameUniforms | Camera, size: tuple[int, int], detail: float = 1.0) -> NDArray[np.int32]:
        """Ring sides of each vein for this camera and viewport size in pixels (0: not drawn);
        see :func:`leafview.botany.vein_tubes.tube_lod`."""
        seg = self.segments
        return tube_lod(self._world, seg.r[:, 1], seg.vein, self.veins, _view_proj(frame), size,
                        scale=self._scale, detail=detail)

    def _arrange(self, sides: NDArray[np.int32]) -> list[tuple[int, int]]:
        """Upload the drawn segments sorted by bucket (only when that changed) and the bucket
        commands; returns (sides, command index) per non-empty bucket."""
        seg_sides = sides[self.segments.vein] if len(self.segments) else np.zeros(0, np.int32)
        key = seg_sides.tobytes()
        if key != self._drawn_key:
            rows = np.flatnonzero(seg_sides > 0)
            rows = rows[np.argsort(seg_sides[rows], kind="stable")]
            if len(rows):
                self._rows.write(self.segments.records()[rows])
            counts = [int(np.count_nonzero(seg_sides == s)) for s in SIDE_BUCKETS]
            cmd = np.zeros(len(SIDE_BUCKETS), _COMMAND)
            cmd["count"] = [strip_vertices(s) for s in SIDE_BUCKETS]
            cmd["instances"] = counts
            cmd["base_instance"] = np.r_[0, np.cumsum(counts)[:-1]]
            self._commands.write(cmd.tobytes())
            self.buckets = {s: c for s, c in zip(SIDE_BUCKETS, counts, strict=True) if c}
            self._drawn_key = key
        return [(s, i) for i, s in enumerate(SIDE_BUCKETS) if s in self.buckets]

    def _vao(self, role: str, program: moderngl.Program, buf: moderngl.Buffer, fmt: str,
             names: tuple[str, ...]) -> moderngl.VertexArray:
        """The vertex array of ``role`` over ``buf``, rebuilt when the buffer was replaced."""
        held = self._vaos.get(role)
        if held is not None and held[0] == (buf.glo, program.glo):
            return held[1]
        if held is not None:
            held[1].release()
        vao = self.ctx.vertex_array(program, [(buf, fmt, *names)])
        self._vaos[role] = ((buf.glo, program.glo), vao)
        return vao

    def _frames(self, role: str, rows: moderngl.Buffer, count: int) -> moderngl.VertexArray:
        """Pass 1 over ``count`` segment rows of ``rows`` (``role``: which buffer that is): their
        end frames into the frame buffer; returns pass 2's vertex array over them."""
        check_buffer(count * _FRAME_BYTES, "venation", f"the frames of {count:,} vein tube segments")
        frames = self._frame_rows.ensure(count * _FRAME_BYTES)
        source = self._vao(role, self.frame_program, rows, _RECORD_FORMAT, _RECORD_ATTRIBUTES)
        source.transform(frames, mode=moderngl.POINTS, vertices=count)
        return self._vao("sweep", self.program, frames, _FRAME_FORMAT, _FRAME_ATTRIBUTES)

    # -- drawing --------------------------------------------------------------------------------
    def draw(self, frame: FrameUniforms | Camera, *, lod: float = 1.0, size: tuple[int, int] | None = None) -> int:
        """Draw the tubes into the bound framebuffer with the leaf's state bound as
        :meth:`LeafRenderer.draw` leaves it (Leaf and Frame blocks, jitter rows, ripple signals,
        vein grid). ``frame``: the renderer's :class:`FrameUniforms` (or the camera they were
        filled from), for the level of detail; ``lod`` multiplies the projected widths (2:
        finer); ``size`` defaults to the viewport's. Returns the number of vertices drawn."""
        if not len(self.segments):
            return 0
        ensure_alive(self.ctx, "drawing vein tubes")
        if size is None:
            size = (int(self.ctx.viewport[2]), int(self.ctx.viewport[3]))
        buckets = self._arrange(self.lod(frame, size, lod))
        if not buckets:
            return 0
        sweep = self._frames("drawn", self._rows.buffer, sum(self.buckets.values()))
        # tubes are closed (capped start, pointed end) and wound outwards: back faces are never
        # seen, so they are culled (half the fragments); culling is off again afterwards, as the
        # two-sided leaves of every other draw need
        self.ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self.ctx.front_face, self.ctx.cull_face = "ccw", "back"
        commands = self._commands.buffer
        program = self.program
        try:
            for sides, index in buckets:
                program["sides"] = sides
                sweep.render_indirect(commands, moderngl.TRIANGLE_STRIP, count=1, first=index)
        finally:
            self.ctx.disable(moderngl.CULL_FACE)
        return sum(strip_vertices(s) * c for s, c in self.buckets.items())

    def capture(self, sides: int) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Every segment's strip with ``sides`` ring sides as the two passes compute it, read
        back through transform feedback: leaf-space positions and outward normals, two
        (segments · strip_vertices(sides), 3) float32 arrays in the vertex order of
        :mod:`leafview.botany.vein_tubes` (the leaf's state bound, as for :meth:`draw`)."""
        n = len(self.segments)
        per = strip_vertices(sides)
        if n == 0:
            return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)
        ensure_alive(self.ctx, "capturing vein tubes")
        with self._capture.recording(n * per) as rec:   # binds a framebuffer for pass 1 too
            sweep = self._frames("all", self._static.buffer, n)
            self.program["sides"] = int(sides)
            rec.add(sweep, per, n)
            return rec.read()

    def release(self) -> None:
        """Release what this owns (idempotent)."""
        for _, vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        self._objects.release()

    def __enter__(self) -> VeinTubes:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
