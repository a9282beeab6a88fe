"""The leaf renderer: one program evaluating L_Ω (Chaurasia & Beardsley 2017, eqs 1-6) in the
vertex shader, drawn one leaf at a time from the Leaf uniform block or many leaves into one
atlas, and the transform-feedback capture that tests and export read back.

Programs, grids, render targets and the capture come from a :class:`~leafview.gpu.resources.
GpuResources` set (shared with other renderers through ``resources=``, else owned); this
renderer owns only its leaf and frame blocks, batch rows, jitter rows, ripple signals, image
textures (:class:`~leafview.gpu.textures.LeafTextures`) and vein textures
(:class:`~leafview.gpu.vein_draw.VeinDraw`, one for the single leaf and one for batches), and
releases them in :meth:`LeafRenderer.release` (or a ``with`` block).

Veins: a leaf whose venation is enabled is drawn with its vein field (``shaders/leaf_veins.glsl``)
while :attr:`LeafRenderer.veins` is true (the default; ``--veins off`` and the viewer's checkbox
set it false: no leaf shows veins, as if its venation were disabled). :meth:`LeafRenderer.draw` (the
viewer's path) also draws the veins as geometry (:class:`~leafview.gpu.vein_tubes.VeinTubes`, Hong
2005, ch. 6.1) wherever they are at least a pixel wide on screen; stills at thumbnail sizes have none
that wide.

Lobed leaves (``LeafParams.lobes``): drawn and captured by the same vertex shader from their sweep
tables (:class:`~leafview.gpu.lobe_tables.LobeTables`, one for the single leaf and one for
batches), on the lobed grid of the grid asked for (:func:`~leafview.gpu.lobe_tables.lobed_grid`),
without veins.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import moderngl
import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.blade import uv_arrays
from leafview.core.defaults import DEFAULT_GRID
from leafview.core.params import LeafParams
from leafview.errors import GpuLimitError
from leafview.gpu.context import acquire_headless_context, recycle_headless_context
from leafview.gpu.frame import FrameUniforms, Lighting, fill_frame
from leafview.gpu.layout import (
    FRAME_BINDING,
    FRAME_BLOCK,
    LEAF_BINDING,
    LEAF_BLOCK,
    NO_LOBE_DEFINES,
    feature_defines,
    lobe_defines,
    pack_leaf,
    pack_leaves,
    read_slot,
    ripple_keys,
    texture_defines,
    texture_layers,
    vein_defines,
)
from leafview.gpu.limits import (
    MAX_RESOURCE_BYTES,
    ContextLimits,
    capture_bytes,
    check_buffer,
    check_grid,
    check_image,
    check_memory,
    context_alive,
    ensure_alive,
)
from leafview.gpu.lobe_tables import LobeTables, lobed_grid
from leafview.gpu.owner import GLObjects, GrowingBuffer
from leafview.gpu.prepare import LeafPrepare
from leafview.gpu.resources import WORLD_VARYINGS, GpuResources, JitterTable
from leafview.gpu.targets import FlushTarget, unpremultiply
from leafview.gpu.textures import LeafTextures, check_textures
from leafview.gpu.vein_draw import VeinDraw
from leafview.gpu.vein_tubes import VeinTubes
from leafview.scene.camera import VIEWS, Camera, frame_view_arrays

__all__ = ["LeafRenderer", "DEFAULT_GRID", "BATCH", "Lighting", "fill_frame"]

BATCH = 64            # leaves per atlas in render_many
FLUSH_EVERY = 4       # leaves drawn before render_many hands them to the rasteriser (FlushTarget)
_MAX_ATLAS = 4096     # atlas side limit in pixels (well inside GL_MAX_RENDERBUFFER_SIZE)

# what a thumbnail captures of each vertex and then draws from: world position, world normal
# (as leaf.vert computes them), the drawn (u, v) that leaf.frag's textures and veins read and the
# vein band's coordinates (v_rib: the midrib, or a lobed leaf's skeleton)
DRAW_VARYINGS = (*WORLD_VARYINGS, "v_uv", "v_rib")
DRAW_VERTEX_FORMAT = "3f 3f 2f 2f"
DRAW_VERTEX_BYTES = 40
_COMMAND = np.dtype([("count", "<u4"), ("instances", "<u4"), ("first_index", "<u4"), ("base_vertex", "<i4"),
                     ("base_instance", "<u4")])   # DrawElementsIndirectCommand


def _present(program: moderngl.Program, fmt: str, names: Sequence[str]) -> tuple[str, ...]:
    """``fmt`` and ``names`` with the attributes ``program`` does not use (the compiler drops an
    input whose output no stage reads) turned into padding."""
    parts, kept = [], []
    for code, name in zip(fmt.split(), names):
        if name in program:
            parts.append(code)
            kept.append(name)
        else:
            parts.append(f"{4 * int(code[:-1])}x")   # "3f" -> "12x"
    return (" ".join(parts), *kept)


class LeafRenderer:
    """Draws leaves from their parameters: one at a time from the Leaf uniform block
    (:meth:`set_leaf`, :meth:`render`, :meth:`capture`) or many into one atlas
    (:meth:`render_many`).

    Parameters
    ----------
    ctx:
        A moderngl context (window or headless). ``None`` takes a headless EGL context that this
        renderer owns; :meth:`release` hands it back for the next renderer (a process keeps at
        most two; creating and destroying EGL contexts leaks driver memory).
    resources:
        Shared programs, grids, targets and capture (:class:`GpuResources`); ``None`` creates a
        set that this renderer owns and releases.
    """

    def __init__(self, ctx: moderngl.Context | None = None, *, resources: GpuResources | None = None) -> None:
        self._owns_ctx = ctx is None
        self.ctx = ctx if ctx is not None else acquire_headless_context()
        self._objects = GLObjects()
        self._pooled: GpuResources | None = None   # resources that go back to the pool with the context
        try:
            self.limits = ContextLimits.of(self.ctx)
            if resources is not None:
                self.resources = resources
            elif self._owns_ctx:   # a recycled context keeps its compiled programs in ctx.extra
                extra = self.ctx.extra
                self.resources = self._pooled = extra if isinstance(extra, GpuResources) else GpuResources(self.ctx)
            else:
                self.resources = self._objects.own(GpuResources(self.ctx))
            self.program = self.leaf_program({})  # every feature: set_leaf/draw/capture and the viewer
            self.ripples = self._objects.own(self.resources.ripple_pass())
            self.jitter = self._objects.own(JitterTable(self.ctx))
            self.textures = self._objects.own(LeafTextures(self.ctx))
            self.leaf_veins = self._objects.own(VeinDraw(self.ctx, self.resources.programs))    # set_leaf's leaf
            self.batch_veins = self._objects.own(VeinDraw(self.ctx, self.resources.programs))   # render_many's chunks
            self.leaf_lobes = self._objects.own(LobeTables(self.ctx))     # set_leaf's leaf, when lobed
            self.batch_lobes = self._objects.own(LobeTables(self.ctx))    # render_many's chunks
            self.vein_tubes = self._objects.own(VeinTubes(self.ctx, resources=self.resources))  # draw's close-ups
            self.leaf_ubo = self._objects.own(self.ctx.buffer(reserve=LEAF_BLOCK.nbytes))
            self.frame = self._objects.own(FrameUniforms(self.ctx))
            self._batch_leaf = self._objects.own(GrowingBuffer(self.ctx))
            self._batch_frame = self._objects.own(GrowingBuffer(self.ctx))
            self._batch_frame_rest = self._objects.own(GrowingBuffer(self.ctx))   # frames after the first group
            self._flush = self._objects.own(FlushTarget(self.ctx))
            self._batch_colour = self._objects.own(GrowingBuffer(self.ctx))
            self._batch_commands = self._objects.own(GrowingBuffer(self.ctx))
            self._baked_vao = self._objects.own(_BakedArray())
        except BaseException:
            self.release()
            raise
        self._leaf = LEAF_BLOCK.zeros()
        # batch rows are bound as uniform-block and storage-buffer ranges: honour both alignments
        self._row_align = max(16, int(self.ctx.info.get("GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT", 256)),
                              int(self.ctx.info.get("GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT", 256)))
        self.uploads = 0  # bytes written to GPU buffers/textures by set_leaf (for edit-cost tests)
        self.veins = True  # leaves whose venation is enabled show veins (False: none does)
        self.veins_pending: LeafParams | None = None   # set_leaf(defer_veins=True)'s leaf, veins not rebuilt yet
        self._tubes_for: LeafParams | None = None   # the leaf whose vein tubes draw() shows (built on first draw)
        self._tubes_stale = False                   # _tubes_for changed since draw() last followed it
        self._unshaded: LeafParams | None = None    # set_leaf(shading=False)'s leaf: its vein field not made yet
        self._vein_layer = -1
        self.lobed = False  # the leaf last given to set_leaf is lobed (drawn on lobed_grid)
        self._draw_defines: dict[str, int] = dict(NO_LOBE_DEFINES)   # draw's variant: no sweep branch unless lobed
        # render_many's programs by their defines: (capture program, baked program, colour format)
        self._chunk_programs: dict[tuple[Any, ...], tuple[moderngl.Program, moderngl.Program,
                                                          tuple[str, tuple[str, ...]]]] = {}

    # -- lifetime -------------------------------------------------------------------------------
    def release(self) -> None:
        """Release what this renderer owns (and its context, if it created it); idempotent, and
        safe after the context itself was released (the objects went with it)."""
        self._objects.release()
        if self._owns_ctx:   # every other object is released: the context goes back to the pool
            self._owns_ctx = False
            if context_alive(self.ctx):
                self.ctx.extra = self._pooled
            recycle_headless_context(self.ctx)

    def __enter__(self) -> LeafRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    @property
    def gl_renderer(self) -> str:
        return str(self.ctx.info["GL_RENDERER"])

    @property
    def prepare(self) -> LeafPrepare:
        """The shared prepare pass."""
        return self.resources.prepare

    # -- state ----------------------------------------------------------------------------------
    def set_leaf(self, params: LeafParams, *, textures: bool = True, defer_veins: bool = False,
                 shading: bool = True) -> None:
        """Upload the leaf's uniform block (under 1 KiB), refresh its derived constants (one
        compute dispatch) and, if its seed changed, its jitter row; with ``textures``, its image
        textures when their files changed (a missing or unreadable one raises ParamError first).

        Changing jitter amplitude or density only changes the block: nothing is rebuilt. A shape
        or venation edit rebuilds the leaf's vein field and grid (15-35 ms on llvmpipe), and its
        close-up vein tubes at the next :meth:`draw` (:meth:`capture` never builds them);
        with ``defer_veins`` (the viewer, while a slider is dragged) the veins held stay in use,
        a drag behind (they live in (u, v), so they still follow the blade), until
        :meth:`refresh_veins`. ``shading=False`` (:meth:`capture`: positions only) leaves the
        vein shading field out, made by the next :meth:`draw` if one comes.
        """
        layers = (-1, -1)
        if textures and params.texture is not None:
            before = self.textures.uploads
            keys = self.textures.update([params])
            self.uploads += self.textures.uploads - before
            front, back = texture_layers([params], keys)[0]
            layers = (int(front), int(back))
        if params.ripple.enabled:  # re-synthesises only when seed or β changed
            self.ripples.update([(params.ripple.seed, params.ripple.beta)])
        lobe_layer = int(self.leaf_lobes.update([params])[0])   # rebuilt when the lobes changed
        self.lobed = lobe_layer >= 0
        if self.lobed:                             # a swept surface has no veins
            vein_layer = int(self.leaf_veins.update([params], enabled=False)[0])
            self._tubes_for = self._unshaded = None
            self._tubes_stale = True
            self.veins_pending = None
        elif defer_veins and self.veins and params.venation.enabled and self._vein_layer >= 0:
            vein_layer = self._vein_layer          # the veins held, until refresh_veins
            self.veins_pending = params
        else:
            vein_layer = int(self.leaf_veins.update([params], enabled=self.veins, shading=shading)[0])
            self._tubes_for = params if self.veins else None   # tubes rebuilt by draw(), when the leaf changed
            self._tubes_stale = True
            self._unshaded = None if shading else params
            self.veins_pending = None
        self._vein_layer = vein_layer
        pack_leaf(params, self._leaf, layers=layers, vein_layer=vein_layer, lobe_layer=lobe_layer)
        self._draw_defines = lobe_defines(self._leaf)
        self.leaf_ubo.write(self._leaf.tobytes())
        self.uploads += LEAF_BLOCK.nbytes
        self.prepare.run(self.leaf_ubo, 1)
        if params.jitter.enabled:
            self.uploads += self.jitter.set_seed(params.jitter)

    def refresh_veins(self) -> bool:
        """Bring the veins up to the leaf last given to :meth:`set_leaf` with ``defer_veins``;
        False when they already were."""
        if self.veins_pending is None:
            return False
        self.set_leaf(self.veins_pending)
        return True

    def set_camera(self, camera: Camera, *, srgb: bool, flat: bool = False,
                   lighting: type[Lighting] = Lighting, size: tuple[int, int] | None = None) -> None:
        """The camera of :meth:`draw`; ``size`` (width, height) of the image sets the veins' level
        of detail (None: full detail)."""
        self.frame.set_camera(camera, srgb=srgb, flat=flat, lighting=lighting, size=size)

    def _bind(self) -> None:
        self.leaf_ubo.bind_to_uniform_block(LEAF_BINDING)
        self.frame.bind()
        self._bind_tables()
        self.leaf_veins.use()
        self.leaf_lobes.use()

    def _bind_tables(self) -> None:
        self.jitter.use()
        self.ripples.bind()
        self.textures.use()

    def leaf_program(self, defines: Mapping[str, object]) -> moderngl.Program:
        """The leaf program for a feature set (see ``feature_defines``), compiled once."""
        return self.resources.leaf_program(defines)

    def grid(self, nu: int, nv: int) -> moderngl.VertexArray:
        """The (cached) vertex array of the (nu × nv) grid for the full program: (u, v)
        attributes and triangles. Use it at once (a later grid may evict it)."""
        return self.resources.grid(nu, nv).vao(self.program)

    # -- drawing --------------------------------------------------------------------------------
    def draw(self, grid: tuple[int, int] = DEFAULT_GRID, *, wireframe: bool = False,
             defines: Mapping[str, object] | None = None) -> None:
        """Draw the leaf last given to :meth:`set_leaf` with the camera last given to
        :meth:`set_camera` into the currently bound framebuffer (interactive use: the viewer
        uploads only what an edit changed, then calls this every frame). A lobed leaf is drawn on
        :func:`~leafview.gpu.lobe_tables.lobed_grid` of ``grid``. ``defines``: extra defines of
        the program variant (e.g. ``LEAF_WIND``, with the Wind block bound by the caller); the
        close-up vein tubes are left out of a ``LEAF_WIND`` draw (they would not move with it)."""
        if self.lobed:
            grid = lobed_grid(grid)
        if self._unshaded is not None:   # the leaf came from capture(): its vein field is made now
            self.leaf_veins.update([self._unshaded], enabled=self.veins)
            self._unshaded = None
        self.frame.fit_viewport()   # the veins' level of detail: this draw's image height
        self._bind()
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.wireframe = wireframe
        try:
            # the full program, less the sweep branch for an unlobed leaf (llvmpipe runs untaken
            # branches too: it would cost every vertex of the viewer's leaf)
            program = self.leaf_program({**self._draw_defines, **(defines or {})})
            self.resources.grid(*grid).vao(program).render(moderngl.TRIANGLES)
            if not wireframe and "LEAF_WIND" not in (defines or {}):
                # veins as geometry where they are wide enough on screen; their tree is built here,
                # not by set_leaf, so that capture() (geometry only) never builds it
                if self._tubes_stale:
                    self.vein_tubes.update(self._tubes_for)
                    self._tubes_stale = False
                self.vein_tubes.draw(self.frame)
        finally:
            self.ctx.wireframe = False

    def render(self, params: LeafParams, size: Any = (256, 256), view: str = "top",
               background: ArrayLike | None = None, *, grid: tuple[int, int] = DEFAULT_GRID,
               samples: int | None = None, linear: bool = False, flat: bool = False) -> NDArray[Any]:
        """Render ``params`` offscreen; (h, w, 4) uint8 sRGB, or float32 linear if ``linear``.

        ``background=None`` leaves alpha 0 around the leaf; leaf pixels have alpha 255 (1.0),
        partial at multisampled edges (straight alpha in uint8, premultiplied in float).
        ``samples`` defaults to 0 for ``top`` and 4 otherwise; ``flat``: unlit colours (tests). A
        batch of one of :meth:`render_many`.
        """
        return self.render_many([params], size, view, background, grid=grid, samples=samples,
                                linear=linear, flat=flat)[0]

    def render_many(self, leaves: Sequence[LeafParams], size: Any = (256, 256), view: str = "top",
                    background: ArrayLike | None = None, *, grid: tuple[int, int] = DEFAULT_GRID,
                    samples: int | None = None, linear: bool = False,
                    camera: Camera | None = None, flat: bool = False) -> list[NDArray[Any]]:
        """Render several leaves, each framed on its own, in few GPU round trips.

        The vertex shader runs once per grid vertex: every leaf's world-space vertices are
        captured (transform feedback), each camera is framed on exactly those vertices, and the
        tiles of one atlas are drawn from the captured buffer (the baked-mesh program, the same
        fragment shader), resolved and read back once per chunk of up to :data:`BATCH` leaves.
        ``camera`` (from :func:`leafview.scene.camera.frame_view`) replaces the per-leaf framing with one
        camera for all (frame sequences that must not jump in scale); ``view`` still names it.
        ``flat``: unlit colours (tests).

        Textured leaves: every texture file is read (and checked: a missing or unreadable one raises
        :class:`~leafview.errors.ParamError` naming the leaf and the file) before anything is drawn;
        each chunk's files are one array texture (:mod:`leafview.gpu.textures`).
        """
        w, h = _check_size(size)
        if view not in VIEWS:
            raise ValueError(f"unknown view {view!r} (choose from {', '.join(VIEWS)})")
        nu, nv = check_grid(grid)
        ensure_alive(self.ctx, "rendering")
        if samples is None:
            samples = 0 if view == "top" else 4
        samples = min(samples, self.ctx.max_samples)
        bg = _background(background)
        # every size is checked before the first GL object of the request is made
        check_image(self.limits, (w, h), samples, linear=linear)
        cols = max(1, min(BATCH, _MAX_ATLAS // w))
        rows = max(1, _MAX_ATLAS // h)
        chunk = max(1, min(BATCH, cols * rows, MAX_RESOURCE_BYTES // (nu * nv * DRAW_VERTEX_BYTES)))
        first = min(len(leaves), chunk)
        if first:
            c = min(first, cols)
            check_image(self.limits, (c * w, -(-first // c) * h), samples, linear=linear)
            check_memory(len(leaves) * w * h * (16 if linear else 4), "leaves",
                         f"{len(leaves):,} images of {w}×{h}")
        check_textures(leaves)
        images: list[NDArray[Any]] = [np.zeros(0)] * len(leaves)
        # lobed leaves are drawn on their own grid: each kind in chunks of its own, images in order
        for lobed in (False, True):
            picks = [i for i, p in enumerate(leaves) if p.lobes.enabled == lobed]
            kind_grid = lobed_grid((nu, nv)) if lobed else (nu, nv)
            kind_chunk = max(1, min(chunk, MAX_RESOURCE_BYTES // (kind_grid[0] * kind_grid[1] * DRAW_VERTEX_BYTES)))
            for start in range(0, len(picks), kind_chunk):
                part = picks[start:start + kind_chunk]
                drawn = self._render_chunk([leaves[i] for i in part], w, h, view, bg, kind_grid, samples,
                                           linear, cols, camera, flat)
                for i, img in zip(part, drawn):
                    images[i] = img
        return images

    def _render_chunk(self, leaves: Sequence[LeafParams], w: int, h: int, view: str,
                      bg: tuple[float, float, float, float],
                      grid: tuple[int, int], samples: int, linear: bool, max_cols: int,
                      camera: Camera | None = None, flat: bool = False) -> list[NDArray[Any]]:
        """One vertex pass: every leaf's grid is evaluated once by ``leaf.vert`` and captured in
        world space (position, normal, drawn (u, v)), each camera is framed on exactly those
        vertices, and the tiles are drawn from the captured buffer itself with the baked-mesh
        program (the same ``leaf.frag``), one indirect draw a leaf; one
        readback. The first :data:`FLUSH_EVERY` leaves go through these steps first and are
        rasterised while the rest are captured, framed and drawn (:class:`FlushTarget`)."""
        n = len(leaves)
        files = self.textures.update(leaves)
        lobe_layers = self.batch_lobes.update(leaves)
        vein_layers = self.batch_veins.update(leaves, enabled=self.veins and not (lobe_layers >= 0).any())
        records, tables = pack_leaves(leaves, textures=files, vein_layers=vein_layers, lobe_layers=lobe_layers)
        self.jitter.upload(tables)
        keys = ripple_keys(leaves)
        if keys:
            self.ripples.update(keys)  # one batched dispatch for every signal that changed
        leaf_rows, leaf_stride = self._write_records(self._batch_leaf, records)
        if leaf_stride == LEAF_BLOCK.nbytes:   # tightly packed (llvmpipe: a 16-byte alignment): one dispatch
            self.prepare.run(leaf_rows, n)
        else:   # rows sit at the uniform-offset alignment: one small dispatch each
            for i in range(n):
                self.prepare.run(leaf_rows, 1, offset=i * leaf_stride)
        # the shader permutation without the features no leaf of this chunk uses, its output flags
        # and the kind of eye fixed (leaf.frag: LEAF_FRAME_SRGB, LEAF_FRAME_FLAT, LEAF_EYE_POINT)
        perspective = camera.perspective if camera is not None else view != "top"
        program, baked, colour_format = self._programs_for(records, {
            "LEAF_FRAME_SRGB": int(not linear), "LEAF_FRAME_FLAT": int(flat), "LEAF_EYE_POINT": int(perspective)})
        geometry = self.resources.grid(*grid)
        nverts = geometry.vertices
        points = geometry.points(program)
        self._bind_tables()
        self.batch_veins.use()
        self.batch_lobes.use()
        leaf_bytes, frame_bytes = LEAF_BLOCK.nbytes, FRAME_BLOCK.nbytes
        colours = self._batch_colour.write(_leaf_colours(records))
        commands = self._batch_commands.write(_draw_commands(n, geometry.triangles * 3, nverts))
        cols = min(n, max_cols)
        tiles_y = (n + cols - 1) // cols
        target = self.resources.target((cols * w, tiles_y * h), samples, linear=linear)
        with self.resources.capture.recording(n * nverts, DRAW_VERTEX_BYTES) as rec:
            # In groups of FLUSH_EVERY leaves (the first group, then the rest at once):
            # 1. the only vertex-shader pass over the group's leaves: capture (world space);
            # 2. frame each camera on its leaf's captured vertices (one numpy pass for the group);
            # 3. draw each leaf into its tile from the captured vertices, and hand every
            #    FLUSH_EVERY leaves to the driver's rasteriser threads at once (llvmpipe:
            #    FlushTarget), which shade them while this thread captures, frames and bins the
            #    next ones. Each leaf's capture, camera and triangles (in order) are the same as
            #    when the whole chunk went through each step at once: the same pixels.
            vao = None
            try:
                for first, last, buf in ((0, min(n, FLUSH_EVERY), self._batch_frame),
                                         (min(n, FLUSH_EVERY), n, self._batch_frame_rest)):
                    if first == last:
                        continue
                    self.frame.bind()   # the capture computes gl_Position too (discarded)
                    for i in range(first, last):
                        leaf_rows.bind_to_uniform_block(LEAF_BINDING, offset=i * leaf_stride, size=leaf_bytes)
                        rec.add(points, nverts)
                    world = (None if camera is not None
                             else rec.records()[first * nverts:, :3].reshape(last - first, nverts, 3))
                    frames = self._frames(world, camera, view, (w, h), linear, flat, last - first)
                    frame_rows, frame_stride = self._write_records(buf, frames)
                    if vao is None:   # the first group: the atlas is cleared, the state set once
                        target.use()
                        self.ctx.scissor = None
                        target.clear(bg)
                        self.ctx.enable_only(moderngl.DEPTH_TEST)
                        vao = self._baked_vao.get(self.ctx, baked, rec.buffer, colours, geometry.ibo, colour_format)
                    for i in range(first, last):
                        x, y = (i % cols) * w, (i // cols) * h
                        self.ctx.viewport = self.ctx.scissor = (x, y, w, h)
                        frame_rows.bind_to_uniform_block(FRAME_BINDING, offset=(i - first) * frame_stride,
                                                         size=frame_bytes)
                        vao.render_indirect(commands, moderngl.TRIANGLES, count=1, first=i)
                        if (i + 1) % FLUSH_EVERY == 0 and i + 1 < n:
                            self._flush.flush(target.fbo)
            finally:
                self.ctx.scissor = None

        # 3. one readback (resolving the samples), straightened once for the whole atlas (a pixel's
        # value depends on that pixel alone), split into tiles
        atlas = target.read()
        if samples and not linear and bg[3] == 0.0:
            unpremultiply(atlas, out=atlas)
        if n == 1 and atlas.shape[:2] == (h, w):
            return [atlas]   # one leaf: the atlas is its image
        images = []
        for i in range(n):
            x, y = (i % cols) * w, (tiles_y - 1 - i // cols) * h   # the readback has row 0 at the top
            images.append(np.ascontiguousarray(atlas[y:y + h, x:x + w]))
        return images

    def _frames(self, world: NDArray[np.float32] | None, camera: Camera | None, view: str,
                size: tuple[int, int], linear: bool, flat: bool, count: int = 0) -> NDArray[Any]:
        """FRAME_BLOCK records of leaves: each framed on its captured vertices ``world[i]`` (one
        numpy pass for them all), or ``camera`` for ``count`` leaves when ``world`` is None."""
        framed = None if world is None else frame_view_arrays(view, world, size)
        if framed is not None:
            views, projs, eyes = framed
            count, camera = len(views), Camera(views[0], projs[0], eyes[0], view != "top")
        assert camera is not None
        frames = np.zeros(count, dtype=FRAME_BLOCK.dtype)
        fill_frame(frames[0], camera, srgb=not linear, flat=flat, size=size)
        frames[1:] = frames[0]   # the lights and flags are every leaf's
        if framed is not None and count > 1:   # the matrices and eye each leaf's own
            frames["view"][1:] = views[1:].transpose(0, 2, 1)
            frames["proj"][1:] = projs[1:].transpose(0, 2, 1)
            frames["eye"][1:] = eyes[1:]
        return frames

    def _programs_for(self, records: NDArray[Any], frame_defines: Mapping[str, int] | None = None
                      ) -> tuple[moderngl.Program, moderngl.Program, tuple[str, tuple[str, ...]]]:
        """The capture program (the features the chunk's leaves use), the baked program that draws
        from its records (with ``frame_defines``: leaf.frag's fixed Frame flags) and the colour
        attributes' format of the latter: looked up once per set of defines (the cache's programs
        live as long as the shared program cache)."""
        veins = vein_defines(records)
        capture_defines = {**feature_defines(records), **veins, **lobe_defines(records)}
        baked_defines = {**texture_defines(records), **veins, "LEAF_BAKED_RIB": 1, **(frame_defines or {})}
        key = (tuple(sorted(capture_defines.items())), tuple(sorted(baked_defines.items())))
        found = self._chunk_programs.get(key)
        if found is None:
            program = self.resources.leaf_program(capture_defines, varyings=DRAW_VARYINGS)
            baked = self.resources.programs.program("leaf_baked.vert", "leaf.frag", defines=baked_defines)
            found = self._chunk_programs[key] = (program, baked, _colour_format(baked))
        return found

    def _write_records(self, buf: GrowingBuffer, records: np.ndarray) -> tuple[moderngl.Buffer, int]:
        """Write ``records`` one per aligned row into ``buf`` (grown when too small); returns the
        buffer in use and the row stride in bytes."""
        size = records.dtype.itemsize
        stride = -(-size // self._row_align) * self._row_align
        data = np.zeros((len(records), stride), np.uint8)
        data[:, :size] = records.view(np.uint8).reshape(len(records), size)
        return buf.write(data), stride

    def capture(self, params: LeafParams, u: ArrayLike, v: ArrayLike, *,
                defines: Mapping[str, object] | None = None) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Positions and normals (leaf space) computed by the rendering vertex shader at (u, v),
        read back through transform feedback: two (N, 3) float32 arrays. ``defines`` selects a
        shader permutation (default: the full program). A lobed leaf is evaluated on its swept
        surface (u along the tie, v along the tour: :func:`leafview.deform.sweep.sweep_eval`)."""
        uu, vv = uv_arrays(u, v)   # finite, |u| <= 1, 0 <= v <= 1 (ValueError), as the numpy reference
        uv = np.stack([uu, vv], axis=-1).astype(np.float32)
        n = uv.shape[0]
        if n == 0:
            return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)
        check_buffer(capture_bytes(n), "u, v", f"capturing {n:,} points")
        ensure_alive(self.ctx, "capturing")
        self.set_leaf(params, textures=False, shading=False)   # positions only: no image, no vein field
        self._bind()
        program = self.program if defines is None else self.leaf_program(defines)
        vbo = self.ctx.buffer(uv.tobytes())
        vao = self.ctx.vertex_array(program, [(vbo, "2f", "in_uv")])
        try:
            return self.resources.capture.points(vao, n)
        finally:
            vao.release()
            vbo.release()


class _BakedArray:
    """The vertex array of the thumbnail draw (captured records, per-leaf colours, the grid's
    triangles), kept while the same program and buffers are asked for: one render() after another
    makes none. Keyed by the objects themselves (held here, so their identities are not reused);
    a new program or buffer (a grown capture, an evicted grid) replaces it."""

    def __init__(self) -> None:
        self._key: tuple[Any, ...] = ()
        self._vao: moderngl.VertexArray | None = None

    def get(self, ctx: moderngl.Context, baked: moderngl.Program, records: moderngl.Buffer,
            colours: moderngl.Buffer, ibo: moderngl.Buffer,
            colour_format: tuple[str, tuple[str, ...]]) -> moderngl.VertexArray:
        key = (baked, records, colours, ibo)
        if self._vao is not None and len(self._key) == len(key) and all(a is b for a, b in zip(self._key, key)):
            return self._vao
        self.release()
        fmt, names = colour_format
        self._vao = ctx.vertex_array(
            baked,
            [(records, *_present(baked, DRAW_VERTEX_FORMAT, ("in_position", "in_normal", "in_uv", "in_rib"))),
             (colours, fmt, *names)],
            index_buffer=ibo, index_element_size=4)
        self._key = key
        return self._vao

    def release(self) -> None:
        """Release the vertex array (idempotent; safe after the context was released)."""
        if self._vao is not None:
            self._vao.release()
        self._vao, self._key = None, ()


# the per-leaf attributes of the thumbnail draw (_leaf_colours): name, format, bytes
_COLOUR_ATTRS = (("in_front", "4f", 16), ("in_back", "4f", 16), ("in_layers", "2f", 8), ("in_veins", "2f", 8))


def _leaf_colours(records: NDArray[Any]) -> NDArray[np.float32]:
    """Per-leaf attributes of the thumbnail draw: front (rgb, translucency) and back colours, the
    texture layers plus one (``in_layers`` of leaf_baked.vert; 0 untextured) and the vein layer
    plus one and the world scale (``in_veins``; 0 without veins)."""
    layers = np.stack([read_slot(records, "leaf_front_layer"), read_slot(records, "leaf_back_layer")], axis=1) + 1
    veins = np.stack([read_slot(records, "leaf_vein_layer") + 1,
                      np.linalg.norm(records["model"][:, 0, :3], axis=1)], axis=1)
    return np.ascontiguousarray(np.concatenate([records["front"], records["back"], layers, veins], axis=1),
                                np.float32)


def _colour_format(program: moderngl.Program) -> tuple[str, tuple[str, ...]]:
    """moderngl format and names of the :func:`_leaf_colours` attributes ``program`` reads (the
    others, compiled out of its variant, are skipped as padding)."""
    parts = [f"{fmt}" if name in program else f"{size}x" for name, fmt, size in _COLOUR_ATTRS]
    return " ".join(parts) + "/i", tuple(name for name, _, _ in _COLOUR_ATTRS if name in program)


def _draw_commands(n: int, indices: int, vertices: int) -> NDArray[Any]:
    """One indexed draw of the grid per leaf: leaf ``i`` reads captured vertices from
    ``i * vertices`` and its colours from instance row ``i``."""
    cmd = np.zeros(n, _COMMAND)
    cmd["count"], cmd["instances"] = indices, 1
    cmd["base_vertex"] = np.arange(n) * vertices
    cmd["base_instance"] = np.arange(n)
    return cmd


def _check_size(size: Any) -> tuple[int, int]:
    """``size`` (N or (width, height)) as two positive ints; the context's limits are checked by
    :func:`~leafview.gpu.limits.check_image`."""
    scalar = bool(np.isscalar(size))
    try:
        w, h = (int(size), int(size)) if scalar else (int(size[0]), int(size[1]))
    except (TypeError, ValueError, IndexError, OverflowError):
        raise GpuLimitError("size", f"must be N or (width, height), got {size!r}") from None
    if w < 1 or h < 1:
        raise GpuLimitError("size", f"{w}×{h}: width and height must be at least 1")
    return w, h


def _background(bg: ArrayLike | None) -> tuple[float, float, float, float]:
    if bg is None:
        return (0.0, 0.0, 0.0, 0.0)
    c = [float(x) for x in np.asarray(bg, dtype=np.float64).ravel()]
    if len(c) not in (3, 4) or not all(0.0 <= x <= 1.0 for x in c):
        raise ValueError(f"background must be 3 or 4 numbers in [0, 1], got {bg!r}")
    return (c[0], c[1], c[2], c[3] if len(c) == 4 else 1.0)
