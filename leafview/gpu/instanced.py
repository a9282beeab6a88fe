"""Many leaves in one draw call: the parametric (instanced) path and its baked-mesh twin.

:class:`InstancedLeaves` uploads one :data:`~leafview.gpu.layout.LEAF_BLOCK` record per leaf to a
shader storage buffer (``LEAVES_BINDING``) and draws a single (nu × nv) grid ``N`` times with one
instanced call; ``leaf.vert`` (built with ``LEAF_INSTANCED``) evaluates L_Ω per vertex from the
record's :data:`~leafview.gpu.layout.LEAF_ATTRIBUTES`, per-instance vertex attributes read in
place from the same buffer (nothing is copied), and reads the members of ripples, bends and
extended silhouettes from the row's texels (:class:`~leafview.gpu.resources.RowTexture`, made only
when a leaf takes one of those branches) in those branches only.

:class:`BakedLeaves` draws the *same triangles* from world-space positions and normals baked
ahead of time, either on the CPU with the numpy reference (:meth:`BakedLeaves.from_params`,
:func:`leafview.deform.surface.tessellate`) or captured from the instanced vertex shader
(:meth:`BakedLeaves.from_instanced`, fast for 10⁴ leaves): one vertex buffer for all leaves
(40 bytes a vertex), one index buffer, one draw call, ``leaf_baked.vert`` + the same ``leaf.frag``,
in the leaves' plain colours (image textures and veins: :class:`InstancedLeaves` with
``textures=`` and ``veins=``).

Both are used by :mod:`leafview.bench.core` (parameters vs baked meshes) and by the tests that
check they draw the same picture. Neither changes the framebuffer binding: bind a target, call
``set_camera`` and ``draw``. ``draw`` enables only the depth test. Programs, the grid and the
capture come from a shared :class:`~leafview.gpu.resources.GpuResources` (``resources=``), or
from a private set each batch owns.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import moderngl
import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.params import Jitter, LeafParams, Material, Shape, Transform
from leafview.deform.surface import grid_indices, grid_uv, tessellate
from leafview.errors import GpuLimitError
from leafview.gpu.frame import FrameUniforms, Lighting
from leafview.gpu.layout import (
    LEAF_BLOCK,
    LEAVES_BINDING,
    NO_LOBE_DEFINES,
    NO_VEIN_DEFINES,
    PLAIN_DEFINES,
    feature_defines,
    lobe_defines,
    needs_row_texture,
    pack_leaves,
    texture_defines,
    vein_defines,
)
from leafview.gpu.limits import capture_bytes, check_buffer, check_grid, ensure_alive
from leafview.gpu.lobe_tables import LobeTables
from leafview.gpu.owner import GLObjects
from leafview.gpu.resources import WORLD_VARYINGS, GpuResources, Grid, JitterTable, RowTexture, record_vertex_array
from leafview.gpu.targets import OffscreenTarget, read_rgba
from leafview.gpu.textures import LeafTextures
from leafview.gpu.vein_draw import VeinDraw
from leafview.scene.camera import Camera

__all__ = ["LEAVES_BINDING", "InstancedLeaves", "BakedLeaves", "pack_leaves", "bake_leaves",
           "scatter_leaves", "OffscreenTarget", "read_rgba"]

_BAKED_FORMAT = "3f 3f 2f 4f1 4f1"  # position, normal, uv, front (rgb, translucency), back (rgb, -)
_BAKED_ATTRS = ("in_position", "in_normal", "in_uv", "in_front", "in_back")
BAKED_VERTEX_BYTES = 12 + 12 + 8 + 4 + 4


# ---------------------------------------------------------------------------------------------
# scene data (numpy only)
def scatter_leaves(n: int, seed: int = 0, *, radius: float | None = None,
                   jitter_fraction: float = 0.25) -> list[LeafParams]:
    """``n`` varied leaves scattered in a ball (a crude crown): each leaf gets its own slightly
    perturbed shape, material, rotation, scale and position; about ``jitter_fraction`` of them
    have a serrated margin (three jitter seeds)."""
    rng = np.random.default_rng(seed)
    base = Shape()
    if radius is None:
        radius = 0.35 * max(n, 1) ** (1 / 3) + 0.5
    out = []
    for i in range(n):
        d = rng.normal(size=3)
        d /= max(float(np.linalg.norm(d)), 1e-9)
        pos = d * radius * rng.random() ** (1 / 3)
        rows = tuple((vb, xs * (1.0 + 0.15 * (rng.random() - 0.5)), zs + 0.04 * (rng.random() - 0.5))
                     for vb, xs, zs in base.silhouette)
        shape = Shape(
            a1=(0.06 * (rng.random() - 0.5), base.a1[1], 0.05 * (rng.random() - 0.5)),
            a2=(0.06 * (rng.random() - 0.5), base.a2[1], 0.05 * (rng.random() - 0.5)),
            silhouette=rows,
            zf=tuple(float(x) for x in 0.06 * (rng.random(3) - 0.5)),
            zg=tuple(float(x) for x in 0.06 * (rng.random(3) - 0.5)),
        )
        jit = Jitter(enabled=bool(rng.random() < jitter_fraction), amplitude=0.02,
                     density=24.0, seed=int(rng.integers(0, 3)))
        tint = 0.85 + 0.3 * rng.random()
        mat = Material(front=_vec3(np.clip(np.array([0.18, 0.42, 0.12]) * tint, 0, 1)),
                       back=_vec3(np.clip(np.array([0.40, 0.58, 0.26]) * tint, 0, 1)),
                       translucency=float(0.25 + 0.2 * rng.random()))
        tr = Transform(translation=_vec3(pos),
                       rotation=(float(rng.uniform(-70, 70)), float(rng.uniform(-70, 70)),
                                 float(rng.uniform(-180, 180))),
                       scale=float(rng.uniform(0.3, 0.5)))
        out.append(LeafParams(shape=shape, jitter=jit, material=mat, transform=tr, name=f"leaf{i}"))
    return out


def _vec3(x: NDArray[np.float64]) -> tuple[float, float, float]:
    return float(x[0]), float(x[1]), float(x[2])


def bake_leaves(params: Sequence[LeafParams], grid: tuple[int, int]
                ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """World-space positions and unit normals of every grid vertex of every leaf, both
    (N, nu·nv, 3) float32, from the numpy reference (leaves sharing shape and jitter are
    tessellated once)."""
    nu, nv = grid
    n, nverts = len(params), nu * nv
    pos = np.empty((n, nverts, 3), np.float32)
    nrm = np.empty((n, nverts, 3), np.float32)
    cache: dict[Any, Any] = {}
    for i, p in enumerate(params):
        key = (p.shape, p.jitter if p.jitter.enabled else None)
        mesh = cache.get(key)
        if mesh is None:
            mesh = cache[key] = tessellate(p, nu, nv)
        m = p.transform.matrix()
        pos[i] = mesh.vertices @ m[:3, :3].T + m[:3, 3]
        wn = mesh.normals @ m[:3, :3].T
        length = np.linalg.norm(wn, axis=-1, keepdims=True)
        nrm[i] = wn / np.where(length > 0.0, length, 1.0)
    return pos, nrm


# ---------------------------------------------------------------------------------------------
# GL
class _Batch:
    """Shared state of the two paths: the resources they draw with (borrowed or owned), their
    Frame block and the GL objects to release."""

    program: moderngl.Program
    nu: int
    nv: int
    count: int

    def __init__(self, ctx: moderngl.Context, resources: GpuResources | None) -> None:
        self.ctx = ctx
        self._objects = GLObjects()
        self.resources = resources if resources is not None else self._objects.own(GpuResources(ctx))
        self.frame = self._objects.own(FrameUniforms(ctx))

    def _own(self, obj: Any) -> Any:
        return self._objects.own(obj)

    def release(self) -> None:
        """Release every GL object this batch created (idempotent)."""
        self._objects.release()

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def set_camera(self, camera: Camera, *, srgb: bool = True, flat: bool = False,
                   lighting: type[Lighting] = Lighting, size: tuple[int, int] | None = None) -> None:
        self.frame.set_camera(camera, srgb=srgb, flat=flat, lighting=lighting, size=size)

    @property
    def triangles_per_leaf(self) -> int:
        return 2 * (self.nu - 1) * (self.nv - 1)

    def _bind(self) -> None:
        self.frame.fit_viewport()   # the veins' level of detail, unless set_camera had the size
        self.frame.bind()


class InstancedLeaves(_Batch):
    """All leaves from their parameters: one SSBO row each, one instanced draw of one grid.

    Parameters
    ----------
    ctx:
        moderngl context (OpenGL 4.5).
    records:
        LEAF_BLOCK records, an (N,) array of ``LEAF_BLOCK.dtype`` or a sequence of 0-d records
        (as :func:`~leafview.gpu.layout.pack_leaf` returns).
    grid:
        (nu, nv) samples of the shared (u, v) grid; 2(nu-1)(nv-1) triangles per leaf.
    jitter_tables:
        (rows, JITTER_TABLE_SIZE) float32 jitter values indexed by each record's jitter row
        (see :func:`pack_leaves`); default one row of zeros.
    ripple_signals:
        ``(seed, beta)`` of each ripple signal row (:func:`~leafview.gpu.layout.ripple_keys`).
    resources:
        Shared programs, grids and capture; ``None``: a private set, released with this batch.
    textures:
        The image textures of the records' texture layers (the caller's: ``keys =
        textures.update(params)``, then ``pack_leaves(params, textures=keys)``); ``None``: every
        leaf in its plain colours.
    veins:
        The vein textures of the records' vein layers (the caller's: ``layers =
        veins.update(params)``, then ``pack_leaves(params, vein_layers=layers)``); ``None``: no
        leaf shows veins.
    lobes:
        The sweep tables of the records' lobe layers (the caller's: ``layers =
        lobes.update(params)``, then ``pack_leaves(params, lobe_layers=layers)``; lobed leaves want
        a grid of :func:`~leafview.gpu.lobe_tables.lobed_grid`); ``None``: every leaf drawn unlobed.
    """

    def __init__(self, ctx: moderngl.Context, records: Any, grid: tuple[int, int] = (9, 15), *,
                 jitter_tables: ArrayLike | None = None,
                 ripple_signals: Sequence[tuple[int, float]] = (),
                 resources: GpuResources | None = None, textures: LeafTextures | None = None,
                 veins: VeinDraw | None = None, lobes: LobeTables | None = None) -> None:
        recs = self.records = _as_records(records)
        self.count = int(recs.shape[0])
        ensure_alive(ctx, "uploading instanced leaves")
        check_grid(grid)
        limit = int(ctx.info["GL_MAX_SHADER_STORAGE_BLOCK_SIZE"])
        nbytes = max(recs.nbytes, LEAF_BLOCK.nbytes)
        if nbytes > limit:
            raise GpuLimitError(
                "leaves", f"{self.count:,} leaves need a {nbytes:,}-byte storage buffer, above this driver's "
                f"GL_MAX_SHADER_STORAGE_BLOCK_SIZE = {limit:,} bytes "
                f"(at most {limit // LEAF_BLOCK.nbytes:,} leaves per draw)")
        super().__init__(ctx, resources)
        try:
            self.nu, self.nv = grid
            self.textures = textures
            self.veins = veins if veins is not None and veins.active else None
            self.lobes = lobes if lobes is not None and lobes.active else None
            plain = textures is None or textures.texture is None
            self.program = self.resources.leaf_program(
                {"LEAF_INSTANCED": 1, **feature_defines(recs), **(PLAIN_DEFINES if plain else texture_defines(recs)),
                 **(NO_VEIN_DEFINES if self.veins is None else vein_defines(recs)),
                 **(NO_LOBE_DEFINES if self.lobes is None else lobe_defines(recs))},
                varyings=WORLD_VARYINGS)
            self.ssbo = self._own(ctx.buffer(recs.tobytes() if self.count else bytes(LEAF_BLOCK.nbytes)))
            self.resources.prepare.run(self.ssbo, self.count)  # derived per-leaf fields, one dispatch
            self.rows = self._own(RowTexture(ctx, self.ssbo, self.count)) if needs_row_texture(recs) else None
            # the grid of this batch (its vertex arrays hold its buffers: not one the shared cache
            # may evict), drawn as triangles and captured as points, the rows as instanced attributes
            self.grid = self._own(Grid(ctx, self.nu, self.nv))
            self.vao = self._own(record_vertex_array(ctx, self.program, self.grid.vbo, self.ssbo, LEAF_BLOCK,
                                                     self.grid.ibo))
            self.points = self._own(record_vertex_array(ctx, self.program, self.grid.vbo, self.ssbo, LEAF_BLOCK))
            # every leaf's ripple signal (rows as pack_leaves assigned them), one dispatch for all
            self.ripples = self._own(self.resources.ripple_pass())
            self.ripples.update(list(ripple_signals))
            self.jitter = self._own(JitterTable(ctx, jitter_tables))
        except BaseException:
            self.release()
            raise

    def _bind(self) -> None:
        super()._bind()
        if self.rows is not None:
            self.rows.use()
        self.jitter.use()
        self.ripples.bind()
        if self.textures is not None:
            self.textures.use()
        if self.veins is not None:
            self.veins.use()
        if self.lobes is not None:
            self.lobes.use()

    def draw(self) -> None:
        """All leaves, one instanced draw, into the bound framebuffer (depth test on)."""
        if not self.count:
            return
        self.ctx.enable_only(moderngl.DEPTH_TEST)
        self._bind()
        self.vao.render(moderngl.TRIANGLES, instances=self.count)

    def capture(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """World positions and normals of every grid vertex of every instance as the vertex
        shader computes them (transform feedback): two (N, nu·nv, 3) float32 arrays. The
        framebuffer binding is left as it was."""
        nverts = self.nu * self.nv
        if not self.count:
            z = np.zeros((0, nverts, 3), np.float32)
            return z, z.copy()
        check_buffer(capture_bytes(self.count * nverts), "leaves",
                     f"capturing {self.count:,} leaves of {self.nu}×{self.nv} vertices")
        self._bind()
        pos, nrm = self.resources.capture.points(self.points, nverts, self.count)
        return pos.reshape(self.count, nverts, 3), nrm.reshape(self.count, nverts, 3)


class BakedLeaves(_Batch):
    """The same triangles from pre-baked world-space vertices: one VBO, one IBO, one draw.

    ``positions`` and ``normals`` are (N, nu·nv, 3) (see :func:`bake_leaves`), ``front`` (N, 4)
    rgb + translucency and ``back`` (N, 3) per leaf; use :meth:`from_params` to build all of it.
    """

    def __init__(self, ctx: moderngl.Context, positions: ArrayLike, normals: ArrayLike,
                 grid: tuple[int, int], front: ArrayLike, back: ArrayLike, *,
                 resources: GpuResources | None = None) -> None:
        nu, nv = check_grid(grid)
        pos = np.asarray(positions, np.float32).reshape(-1, nu * nv, 3)
        check_buffer(pos.shape[0] * nu * nv * BAKED_VERTEX_BYTES, "leaves",
                     f"{pos.shape[0]:,} baked leaves of {nu}×{nv} vertices")
        ensure_alive(ctx, "uploading baked leaves")
        super().__init__(ctx, resources)
        try:
            self.nu, self.nv = nu, nv
            nverts = self.nu * self.nv
            nrm = np.asarray(normals, np.float32).reshape(-1, nverts, 3)
            self.count = n = pos.shape[0]
            if nrm.shape[0] != n:
                raise ValueError(f"{n} leaves of positions but {nrm.shape[0]} of normals")
            front = np.broadcast_to(np.asarray(front, np.float64).reshape(-1, 4), (n, 4))
            back = np.broadcast_to(np.asarray(back, np.float64).reshape(-1, 3), (n, 3))
            vdt = np.dtype([("p", "<f4", 3), ("n", "<f4", 3), ("uv", "<f4", 2),
                            ("front", "u1", 4), ("back", "u1", 4)])
            verts = np.empty((n, nverts), vdt)
            verts["p"] = pos
            verts["n"] = nrm
            verts["uv"] = grid_uv(self.nu, self.nv)[None]
            verts["front"] = _unorm8(front)[:, None]
            verts["back"][..., :3] = _unorm8(back)[:, None]
            verts["back"][..., 3] = 0
            tris = grid_indices(self.nu, self.nv)
            idx = (tris[None] + (np.arange(n, dtype=np.uint32) * nverts)[:, None, None])
            self.index_count = int(idx.size)
            self.program = self.resources.programs.program("leaf_baked.vert", "leaf.frag",
                                                           defines={**PLAIN_DEFINES, **NO_VEIN_DEFINES})
            self.vbo = self._own(ctx.buffer(verts.tobytes() if n else bytes(vdt.itemsize)))
            self.ibo = self._own(ctx.buffer(idx.astype(np.uint32).tobytes() if n else bytes(12)))
            self.vao = self._own(ctx.vertex_array(self.program, [(self.vbo, _BAKED_FORMAT, *_BAKED_ATTRS)],
                                                  index_buffer=self.ibo, index_element_size=4))
        except BaseException:
            self.release()
            raise

    @classmethod
    def from_params(cls, ctx: moderngl.Context, params: Sequence[LeafParams],
                    grid: tuple[int, int] = (9, 15), *, resources: GpuResources | None = None) -> BakedLeaves:
        pos, nrm = bake_leaves(params, grid)
        front = [(*p.material.front, p.material.translucency) for p in params]
        back = [p.material.back for p in params]
        return cls(ctx, pos, nrm, grid, np.reshape(front, (-1, 4)), np.reshape(back, (-1, 3)),
                   resources=resources)

    @classmethod
    def from_instanced(cls, leaves: InstancedLeaves, *, resources: GpuResources | None = None) -> BakedLeaves:
        """Bake by capturing what ``leaves``' vertex shader computes (transform feedback): the
        fast way to bake many leaves; bit-identical vertices to the instanced draw."""
        pos, nrm = leaves.capture()
        recs = leaves.records
        return cls(leaves.ctx, pos, nrm, (leaves.nu, leaves.nv), recs["front"], recs["back"][:, :3],
                   resources=resources)

    def draw(self) -> None:
        """All leaves, one indexed draw, into the bound framebuffer (depth test on)."""
        if not self.count:
            return
        self.ctx.enable_only(moderngl.DEPTH_TEST)
        self._bind()
        self.vao.render(moderngl.TRIANGLES, vertices=self.index_count)


def _unorm8(x: NDArray[np.float64]) -> NDArray[np.uint8]:
    return np.clip(np.rint(np.asarray(x) * 255.0), 0, 255).astype(np.uint8)


def _as_records(records: Any) -> NDArray[Any]:
    if isinstance(records, np.ndarray) and records.dtype == LEAF_BLOCK.dtype:
        return np.ascontiguousarray(records.reshape(-1))
    items = list(records)
    out = np.zeros(len(items), dtype=LEAF_BLOCK.dtype)
    for i, r in enumerate(items):
        r = np.asarray(r)
        if r.dtype != LEAF_BLOCK.dtype:
            raise TypeError(f"record {i} has dtype {r.dtype}, expected LEAF_BLOCK.dtype")
        out[i] = r
    return out
