"""The leaf renderer: one program evaluating L_Ω in the vertex shader, headless framebuffers,
and the transform-feedback capture that tests and export read back.

Every GL object is created and released here (``release()`` / context manager); caches of
grids and framebuffers are bounded so long batch runs do not grow.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

import moderngl
import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.defaults import DEFAULT_GRID
from leafview.core.params import LeafParams
from leafview.deform.surface import JITTER_TABLE_SIZE, grid_indices, grid_uv, jitter_table
from leafview.gpu.context import create_headless_context
from leafview.gpu.layout import (
    FRAME_BINDING,
    FRAME_BLOCK,
    LEAF_BINDING,
    LEAF_BLOCK,
    feature_defines,
    pack_leaf,
    pack_leaves,
    ripple_keys,
)
from leafview.gpu.prepare import LeafPrepare
from leafview.gpu.ripple import RipplePass
from leafview.gpu.shaders import build_program
from leafview.scene.camera import VIEWS, Camera, frame_view

__all__ = ["LeafRenderer", "DEFAULT_GRID", "BATCH", "Lighting", "fill_frame"]

BATCH = 64            # leaves per atlas in render_many
_MAX_ATLAS = 4096     # atlas side limit in pixels (well inside GL_MAX_RENDERBUFFER_SIZE)
_MAX_CACHED = 3       # framebuffers
_MAX_GRIDS = 8        # (program variant, grid) vertex arrays


class Lighting:
    """Default key + fill lights (world space, directions towards the light) and ambient."""

    key = (0.35, -0.45, 0.82, 1.05)
    fill = (-0.65, 0.45, 0.45, 0.35)
    ambient = (0.16, 0.17, 0.18)


def fill_frame(record: np.ndarray, camera: Camera, *, srgb: bool, flat: bool = False,
               lighting: type[Lighting] = Lighting) -> None:
    """Fill a FRAME_BLOCK record: camera matrices (column-major), lights and output flags."""
    record["view"] = camera.view.T
    record["proj"] = camera.proj.T
    record["eye"] = camera.eye
    record["key"] = lighting.key
    record["fill"] = lighting.fill
    record["ambient"][:3] = lighting.ambient
    record["flags"] = (int(srgb), int(flat), 0, 0)


class _LRU(OrderedDict):
    """A small cache whose evicted values are released."""

    def __init__(self, limit: int) -> None:
        super().__init__()
        self.limit = limit

    def get_or_make(self, key: Any, make: Any) -> Any:
        if key in self:
            self.move_to_end(key)
            return self[key]
        value = self[key] = make()
        while len(self) > self.limit:
            _, old = self.popitem(last=False)
            _release(old)
        return value

    def clear_all(self) -> None:
        for value in self.values():
            _release(value)
        self.clear()


def _release(obj: Any) -> None:
    if isinstance(obj, (tuple, list)):
        for o in obj:
            _release(o)
    elif obj is not None:
        obj.release()


class LeafRenderer:
    """Draws leaves from their parameters: one at a time from the Leaf uniform block
    (:meth:`set_leaf`, :meth:`render`, :meth:`capture`) or many into one atlas
    (:meth:`render_many`).

    Parameters
    ----------
    ctx:
        A moderngl context (window or headless). ``None`` creates a headless EGL context that
        this renderer owns and releases.
    """

    def __init__(self, ctx: moderngl.Context | None = None) -> None:
        self._owns_ctx = ctx is None
        self.ctx = ctx if ctx is not None else create_headless_context()
        self._programs: dict[tuple[str, ...], moderngl.Program] = {}
        self.program = self._program({})  # every feature: set_leaf/draw/capture and the viewer
        self.prepare = LeafPrepare(self.ctx)
        self.ripples = RipplePass(self.ctx)
        self.leaf_ubo = self.ctx.buffer(reserve=LEAF_BLOCK.nbytes)
        self.frame_ubo = self.ctx.buffer(reserve=FRAME_BLOCK.nbytes)
        self.jitter_tex = self.ctx.texture((JITTER_TABLE_SIZE, 1), 1, dtype="f4")
        self.jitter_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._jitter_seed: int | None = None
        self._leaf = LEAF_BLOCK.zeros()
        self._frame = FRAME_BLOCK.zeros()
        self._grids = _LRU(_MAX_GRIDS)
        self._targets = _LRU(_MAX_CACHED)
        self._capture_fbo: moderngl.Framebuffer | None = None
        self._capture_out: moderngl.Buffer | None = None
        self._batch_leaf: moderngl.Buffer | None = None
        self._batch_frame: moderngl.Buffer | None = None
        # batch rows are bound as uniform-block and storage-buffer ranges: honour both alignments
        self._row_align = max(16, int(self.ctx.info.get("GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT", 256)),
                              int(self.ctx.info.get("GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT", 256)))
        self.uploads = 0  # bytes written to GPU buffers/textures by set_leaf (for edit-cost tests)

    # -- lifetime -------------------------------------------------------------------------------
    def release(self) -> None:
        # bind the default framebuffer first: moderngl re-binds the current one on the next
        # framebuffer creation, which fails once it has been deleted
        self.ctx.detect_framebuffer(0).use()
        self._grids.clear_all()
        self._targets.clear_all()
        if self._capture_fbo is not None:
            _release([self._capture_fbo, *self._capture_fbo.color_attachments])
            self._capture_fbo = None
        _release([*self._programs.values(), self.prepare, self.ripples, self.leaf_ubo, self.frame_ubo, self.jitter_tex, self._capture_out,
                  self._batch_leaf, self._batch_frame])
        self._capture_out = self._batch_leaf = self._batch_frame = None
        if self._owns_ctx:
            self.ctx.release()

    def __enter__(self) -> LeafRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    @property
    def gl_renderer(self) -> str:
        return str(self.ctx.info["GL_RENDERER"])

    # -- state ----------------------------------------------------------------------------------
    def set_leaf(self, params: LeafParams) -> None:
        """Upload the leaf's uniform block (320 bytes), refresh its derived constants (one compute
        dispatch) and, if its seed changed, its jitter row.

        Changing jitter amplitude or density only changes the block: nothing is rebuilt.
        """
        if params.ripple.enabled:  # re-synthesises only when seed or β changed
            self.ripples.update([(params.ripple.seed, params.ripple.beta)])
        pack_leaf(params, self._leaf)
        self.leaf_ubo.write(self._leaf.tobytes())
        self.uploads += LEAF_BLOCK.nbytes
        self.prepare.run(self.leaf_ubo, 1)
        if params.jitter.enabled and self._jitter_seed != params.jitter.seed:
            table = jitter_table(params.jitter)
            self.jitter_tex.write(table.tobytes(), viewport=(0, 0, JITTER_TABLE_SIZE, 1))
            self.uploads += table.nbytes
            self._jitter_seed = params.jitter.seed

    def set_camera(self, camera: Camera, *, srgb: bool, flat: bool = False,
                   lighting: type[Lighting] = Lighting) -> None:
        fill_frame(self._frame, camera, srgb=srgb, flat=flat, lighting=lighting)
        self.frame_ubo.write(self._frame.tobytes())

    def _bind(self) -> None:
        self.leaf_ubo.bind_to_uniform_block(LEAF_BINDING)
        self.frame_ubo.bind_to_uniform_block(FRAME_BINDING)
        self._bind_tables()

    def _bind_tables(self) -> None:
        self.jitter_tex.use(location=0)
        self.ripples.bind()

    def _program(self, defines: dict[str, int]) -> moderngl.Program:
        """The leaf program for a feature set (see ``feature_defines``), compiled once."""
        key = tuple(sorted(defines))
        if key not in self._programs:
            prog = build_program(self.ctx, "leaf.vert", "leaf.frag", defines=defines,
                                 varyings=("v_object", "v_object_normal"))
            prog["Leaf"].binding = LEAF_BINDING
            prog["Frame"].binding = FRAME_BINDING
            self._programs[key] = prog
        return self._programs[key]

    def grid(self, nu: int, nv: int) -> moderngl.VertexArray:
        """The (cached) vertex array of the (nu × nv) grid: (u, v) attributes and triangles."""
        return self._grid_entry(nu, nv)[0]

    def _grid_entry(self, nu: int, nv: int, program: moderngl.Program | None = None) -> tuple[Any, ...]:
        """(indexed vao for drawing, non-indexed vao for capture, vbo, ibo) of a grid for
        ``program`` (default the full one), cached."""
        prog = program or self.program

        def make() -> tuple[Any, ...]:
            vbo = self.ctx.buffer(grid_uv(nu, nv).tobytes())
            ibo = self.ctx.buffer(grid_indices(nu, nv).tobytes())
            vao = self.ctx.vertex_array(prog, [(vbo, "2f", "in_uv")], index_buffer=ibo, index_element_size=4)
            points = self.ctx.vertex_array(prog, [(vbo, "2f", "in_uv")])
            return vao, points, vbo, ibo

        return self._grids.get_or_make((prog.glo, nu, nv), make)

    def _target(self, w: int, h: int, samples: int, linear: bool) -> tuple[moderngl.Framebuffer, ...]:
        def make() -> tuple[Any, ...]:
            dtype = "f4" if linear else "f1"
            color = self.ctx.renderbuffer((w, h), 4, dtype=dtype)
            depth = self.ctx.depth_renderbuffer((w, h))
            fbo = self.ctx.framebuffer([color], depth)
            if not samples:
                return fbo, fbo, color, depth
            mcolor = self.ctx.renderbuffer((w, h), 4, samples=samples, dtype=dtype)
            mdepth = self.ctx.depth_renderbuffer((w, h), samples=samples)
            mfbo = self.ctx.framebuffer([mcolor], mdepth)
            return mfbo, fbo, color, depth, mcolor, mdepth

        return self._targets.get_or_make((w, h, samples, linear), make)

    # -- drawing --------------------------------------------------------------------------------
    def draw(self, grid: tuple[int, int] = DEFAULT_GRID, *, wireframe: bool = False) -> None:
        """Draw the leaf last given to :meth:`set_leaf` with the camera last given to
        :meth:`set_camera` into the currently bound framebuffer (interactive use: the viewer
        uploads only what an edit changed, then calls this every frame)."""
        self._bind()
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.wireframe = wireframe
        try:
            self.grid(*grid).render(moderngl.TRIANGLES)
        finally:
            self.ctx.wireframe = False

    def render(self, params: LeafParams, size: Any = (256, 256), view: str = "top",
               background: ArrayLike | None = None, *, grid: tuple[int, int] = DEFAULT_GRID,
               samples: int | None = None, linear: bool = False) -> NDArray[Any]:
        """Render ``params`` offscreen; (h, w, 4) uint8 sRGB, or float32 linear if ``linear``.

        ``background=None`` leaves alpha 0 around the leaf; leaf pixels have alpha 255 (1.0),
        partial at multisampled edges (straight alpha in uint8, premultiplied in float).
        ``samples`` defaults to 0 for ``top`` and 4 otherwise. A batch of one of
        :meth:`render_many`.
        """
        return self.render_many([params], size, view, background, grid=grid, samples=samples,
                                linear=linear)[0]

    def render_many(self, leaves: Sequence[LeafParams], size: Any = (256, 256), view: str = "top",
                    background: ArrayLike | None = None, *, grid: tuple[int, int] = DEFAULT_GRID,
                    samples: int | None = None, linear: bool = False,
                    camera: Camera | None = None) -> list[NDArray[Any]]:
        """Render several leaves, each framed on its own, in few GPU round trips.

        The vertices of every leaf are first captured from the vertex shader in one pass (so the
        framing uses exactly the drawn vertices), then all leaves are drawn into tiles of one
        atlas, resolved and read back once per chunk of up to :data:`BATCH` leaves.
        ``camera`` (from :func:`leafview.scene.camera.frame_view`) replaces the per-leaf framing with one
        camera for all (frame sequences that must not jump in scale); ``view`` still names it.
        """
        w, h = _check_size(size)
        if view not in VIEWS:
            raise ValueError(f"unknown view {view!r} (choose from {', '.join(VIEWS)})")
        nu, nv = grid
        if samples is None:
            samples = 0 if view == "top" else 4
        samples = min(samples, self.ctx.max_samples)
        bg = _background(background)
        cols = max(1, min(BATCH, _MAX_ATLAS // w))
        rows = max(1, _MAX_ATLAS // h)
        chunk = max(1, min(BATCH, cols * rows))
        images: list[NDArray[Any]] = []
        for start in range(0, len(leaves), chunk):
            images += self._render_chunk(leaves[start:start + chunk], w, h, view, bg, (nu, nv), samples,
                                         linear, cols, camera)
        return images

    def _render_chunk(self, leaves: Sequence[LeafParams], w: int, h: int, view: str, bg: tuple[float, ...],
                      grid: tuple[int, int], samples: int, linear: bool, max_cols: int,
                      camera: Camera | None = None) -> list[NDArray[Any]]:
        n = len(leaves)
        records, tables = pack_leaves(leaves)
        self._upload_jitter(tables)
        keys = ripple_keys(leaves)
        if keys:
            self.ripples.update(keys)  # one batched dispatch for every signal that changed
        self._batch_leaf, leaf_stride = self._write_records(self._batch_leaf, records)
        for i in range(n):  # rows sit at the uniform-offset alignment: one small dispatch each
            self.prepare.run(self._batch_leaf, 1, offset=i * leaf_stride)

        # the shader permutation without the features no leaf of this chunk uses
        entry = self._grid_entry(*grid, self._program(feature_defines(records)))

        # 1. capture every leaf's grid from the vertex shader, frame each camera on it
        nverts = grid[0] * grid[1]
        positions = self._capture_rows(leaf_stride, n, grid, entry[1])
        frames = np.zeros(n, dtype=FRAME_BLOCK.dtype)
        for i, leaf in enumerate(leaves):
            if camera is not None:
                fill_frame(frames[i], camera, srgb=not linear)
                continue
            m = leaf.transform.matrix()
            world = positions[i * nverts:(i + 1) * nverts].astype(np.float64) @ m[:3, :3].T + m[:3, 3]
            fill_frame(frames[i], frame_view(view, world, (w, h)), srgb=not linear)
        self._batch_frame, frame_stride = self._write_records(self._batch_frame, frames)

        # 2. draw each leaf into its tile
        cols = min(n, max_cols)
        tiles_y = (n + cols - 1) // cols
        target = self._target(cols * w, tiles_y * h, samples, linear)
        draw_fbo, read_fbo = target[0], target[1]
        draw_fbo.use()
        self.ctx.scissor = None
        draw_fbo.clear(*bg, depth=1.0)
        self.ctx.enable_only(moderngl.DEPTH_TEST)
        self._bind_tables()
        vao = entry[0]
        for i in range(n):
            x, y = (i % cols) * w, (i // cols) * h
            self.ctx.viewport = self.ctx.scissor = (x, y, w, h)
            self._batch_leaf.bind_to_uniform_block(LEAF_BINDING, offset=i * leaf_stride, size=LEAF_BLOCK.nbytes)
            self._batch_frame.bind_to_uniform_block(FRAME_BINDING, offset=i * frame_stride, size=FRAME_BLOCK.nbytes)
            vao.render(moderngl.TRIANGLES)
        self.ctx.scissor = None
        if draw_fbo is not read_fbo:
            self.ctx.copy_framebuffer(read_fbo, draw_fbo)

        # 3. one readback, split into tiles (GL rows run bottom-up)
        dtype = np.float32 if linear else np.uint8
        raw = read_fbo.read(components=4, dtype="f4" if linear else "f1")
        atlas = np.frombuffer(raw, dtype=dtype).reshape(tiles_y * h, cols * w, 4)
        images = []
        for i in range(n):
            x, y = (i % cols) * w, (i // cols) * h
            img = atlas[y:y + h, x:x + w][::-1]
            if samples and not linear and bg[3] == 0.0:
                img = _unpremultiply(img)
            images.append(np.ascontiguousarray(img))
        return images

    def _capture_rows(self, leaf_stride: int, n: int, grid: tuple[int, int],
                      vao: moderngl.VertexArray) -> NDArray[np.float32]:
        """Leaf-space positions of the grid of each of ``n`` leaves stored in the batch buffer."""
        nverts = grid[0] * grid[1]
        need = n * nverts * 24
        if self._capture_out is None or self._capture_out.size < need:
            _release(self._capture_out)
            self._capture_out = self.ctx.buffer(reserve=_grow(need))
        self._capture_target().use()
        self._bind_tables()
        self.frame_ubo.bind_to_uniform_block(FRAME_BINDING)
        for i in range(n):
            self._batch_leaf.bind_to_uniform_block(LEAF_BINDING, offset=i * leaf_stride, size=LEAF_BLOCK.nbytes)
            vao.transform(self._capture_out, mode=moderngl.POINTS, vertices=nverts, buffer_offset=i * nverts * 24)
        data = np.frombuffer(self._capture_out.read(size=need), dtype=np.float32).reshape(n * nverts, 6)
        return data[:, :3]

    def _capture_target(self) -> moderngl.Framebuffer:
        # a surfaceless EGL context has no default framebuffer; draws (even with rasterizer
        # discard) need a complete one bound, else GL_INVALID_FRAMEBUFFER_OPERATION
        if self._capture_fbo is None:
            self._capture_fbo = self.ctx.framebuffer([self.ctx.renderbuffer((1, 1), 4)])
        return self._capture_fbo

    def _write_records(self, buf: moderngl.Buffer | None, records: np.ndarray) -> tuple[moderngl.Buffer, int]:
        """Write ``records`` one per aligned row into ``buf``, replaced by a larger buffer when
        too small; returns the buffer in use and the row stride in bytes."""
        size = records.dtype.itemsize
        stride = -(-size // self._row_align) * self._row_align
        data = np.zeros((len(records), stride), np.uint8)
        data[:, :size] = records.view(np.uint8).reshape(len(records), size)
        if buf is None or buf.size < data.nbytes:
            _release(buf)
            buf = self.ctx.buffer(reserve=_grow(data.nbytes))
        buf.write(data.tobytes())
        return buf, stride

    def _upload_jitter(self, tables: NDArray[np.float32]) -> None:
        """Make the jitter texture hold ``tables`` (one row per seed used in the batch)."""
        rows = tables.shape[0]
        if rows == 1 and not tables.any():
            return  # no leaf in the batch has jitter on: nothing reads the texture
        if self.jitter_tex.height < rows:
            _release(self.jitter_tex)
            self.jitter_tex = self.ctx.texture((JITTER_TABLE_SIZE, _grow(rows)), 1, dtype="f4")
            self.jitter_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.jitter_tex.write(np.ascontiguousarray(tables).tobytes(), viewport=(0, 0, JITTER_TABLE_SIZE, rows))
        self._jitter_seed = None  # row 0 no longer holds the single-leaf seed

    def capture(self, params: LeafParams, u: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float32], ...]:
        """Positions and normals (leaf space) computed by the rendering vertex shader at (u, v),
        read back through transform feedback: two (N, 3) float32 arrays."""
        uu, vv = np.broadcast_arrays(np.asarray(u, np.float32), np.asarray(v, np.float32))
        uv = np.stack([uu.ravel(), vv.ravel()], axis=-1)
        n = uv.shape[0]
        if n == 0:
            return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)
        self.set_leaf(params)
        self._bind()
        self._capture_target().use()
        vbo = self.ctx.buffer(uv.tobytes())
        out = self.ctx.buffer(reserve=n * 24)
        vao = self.ctx.vertex_array(self.program, [(vbo, "2f", "in_uv")])
        try:
            vao.transform(out, mode=moderngl.POINTS, vertices=n)
            data = np.frombuffer(out.read(), dtype=np.float32).reshape(n, 6)
        finally:
            _release([vao, vbo, out])
        return data[:, :3].copy(), data[:, 3:].copy()


def _grow(n: int) -> int:
    """Capacity for ``n``: the next power of two, so repeated batches reuse buffers."""
    return 1 << max(0, int(n - 1).bit_length())


def _unpremultiply(img: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Resolved multisampled edges over a transparent clear are premultiplied (colour · coverage);
    8-bit images carry straight alpha, so divide the coverage back out."""
    alpha = img[..., 3:4].astype(np.float32)
    partial = (alpha > 0) & (alpha < 255)
    if not partial.any():
        return img
    out = img.copy()
    rgb = np.clip(img[..., :3].astype(np.float32) * 255.0 / np.maximum(alpha, 1.0) + 0.5, 0, 255)
    out[..., :3] = np.where(partial, rgb, img[..., :3]).astype(np.uint8)
    return out


def _check_size(size: Any) -> tuple[int, int]:
    try:
        w, h = (int(size), int(size)) if np.isscalar(size) else (int(size[0]), int(size[1]))
    except (TypeError, ValueError, IndexError):
        raise ValueError(f"size must be N or (width, height), got {size!r}") from None
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise ValueError(f"image size {w}×{h} outside 1..16384")
    return w, h


def _background(bg: ArrayLike | None) -> tuple[float, float, float, float]:
    if bg is None:
        return (0.0, 0.0, 0.0, 0.0)
    c = [float(x) for x in np.asarray(bg, dtype=np.float64).ravel()]
    if len(c) not in (3, 4) or not all(0.0 <= x <= 1.0 for x in c):
        raise ValueError(f"background must be 3 or 4 numbers in [0, 1], got {bg!r}")
    return (c[0], c[1], c[2], c[3] if len(c) == 4 else 1.0)
