"""Baking a leaf into a triangle mesh: the vertices the renderer draws, ready for a file.

The (u, v) grid of :func:`leafview.deform.surface.grid_uv` is evaluated either by the rendering
vertex shader (``backend="gpu"``: transform-feedback readback through
:meth:`leafview.gpu.LeafRenderer.capture`, the positions and normals the rasteriser receives) or
by the float64 numpy reference the shader is tested against (``backend="numpy"``, no OpenGL
needed; the two agree to float32 rounding, see ``tests/test_gpu_eval.py``). Jitter, ripples and
bending are part of both.

The pinched tips. Every curve of the model starts at the base (0, 0, 0) and ends at the apex
(0, 1, 0) (Chaurasia & Beardsley 2017, sec. 3, eqs 3-4), so the grid rows v = 0 and v = 1 each collapse to one
point and half of the quads along them turn into triangles with two corners on that point. The
renderer rasterises nothing for them; an exported file would carry them as degenerate triangles
(validators flag them, some tools divide by their zero area). :func:`bake` drops exactly those
``2 (nu - 1)`` triangles, then the two corner vertices no triangle uses any more. The other tip
vertices stay as separate copies of the point, each with the normal and texture coordinate of
its own column (a seam, as at a UV border), so every exported triangle is one the renderer draws.

Texture coordinates. ``LeafMesh.st`` is the image point of each vertex's (u, v) by the one
convention of :func:`leafview.core.texture.texture_st`, stored with the origin at the lower left
as OBJ, PLY and USD expect (s, 1 - t): the leaf's (u, v) rectangle seen from the top view, left
edge u = +1 (the -x half of a straight leaf), right edge u = -1, base at the bottom, apex at the
top. glTF counts t downwards and takes ``texture_st`` as it is (:func:`gltf_st`).

Lobed leaves (``params.lobes.enabled``; Mündermann et al. 2003, secs 3.3-4). The shader draws them
on :func:`leafview.deform.sweep.lobed_grid` of the grid asked for (u along each railroad tie, v
along the tour of ties); paired ties meet, so the bake evaluates that grid (the shader capture or
the float64 sweep of :mod:`leafview.botany.leaf_surface`), decides the welding on the float64
reference (:func:`leafview.botany.lobe_sweep.weld_grid`: grid samples that coincide become one
vertex, triangles two of whose corners merged are dropped) and keeps, for each welded vertex, the
position and normal of its first grid sample: one sheet with one boundary loop, the margin. Its
``uv`` are the texture coordinates the shader shades and samples the image at: the flat leaf's
position (Mündermann et al. 2003, eq. 1: texture coordinates from the flat position) mapped
into u in [-1, 1], v in [0, 1] by the margin's bounding box
(:func:`leafview.deform.sweep.texture_uv`), so ``st`` is
:func:`~leafview.core.texture.texture_st` of them as for any leaf, in [0, 1]²: the top view of the
flat leaf, base at the bottom.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.botany.leaf_surface import sweep_of
from leafview.botany.lobe_sweep import weld_grid
from leafview.botany.vein_shape import shape_grid
from leafview.core.blade import drawn_uv
from leafview.core.defaults import DEFAULT_GRID
from leafview.core.params import LeafParams
from leafview.core.texture import texture_st
from leafview.deform.surface import grid_indices, grid_uv, tessellate
from leafview.deform.sweep import lobed_grid
from leafview.errors import NonFiniteMesh, UsageError
from leafview.gpu import LeafRenderer, default_renderer

__all__ = [
    "BACKENDS",
    "DEFAULT_RESOLUTION",
    "LeafMesh",
    "NonFiniteMesh",
    "bake",
    "bake_many",
    "check_mesh",
    "lobed_weld",
    "gltf_st",
    "lower_left_st",
    "pinch_triangles",
]

BACKENDS = ("gpu", "numpy")
DEFAULT_RESOLUTION = DEFAULT_GRID
_UNIT_TOL = 1e-3   # a normal further than this from unit length is rebuilt from the faces


@dataclass(frozen=True)
class LeafMesh:
    """One baked leaf in leaf space (base at the origin, apex at (0, 1, 0), front towards +z).

    Attributes
    ----------
    positions, normals:
        (V, 3) float32; normals are unit length and point to the front (upper, adaxial) side.
    st:
        (V, 2) float32 texture coordinates, origin lower left (:func:`lower_left_st` of ``uv``).
    uv:
        (V, 2) float64, the model's (u, v) of each vertex as drawn (:func:`leafview.core.blade.drawn_uv`:
        a one-sided leaf's grid spread over its half), for comparisons with the reference; for a
        lobed leaf its texture coordinates, the flat position in its texture window (see the
        module docstring).
    indices:
        (T, 3) uint32 triangles, counter-clockwise seen from the front.
    name:
        The leaf's name (empty if it has none).
    """

    positions: NDArray[np.float32]
    normals: NDArray[np.float32]
    st: NDArray[np.float32]
    uv: NDArray[np.float64]
    indices: NDArray[np.uint32]
    name: str = ""

    @property
    def n_vertices(self) -> int:
        return int(self.positions.shape[0])

    @property
    def n_triangles(self) -> int:
        return int(self.indices.shape[0])

    def bounds(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """(min, max) corners of the positions, float32."""
        return self.positions.min(axis=0), self.positions.max(axis=0)


def check_resolution(resolution: Sequence[int]) -> tuple[int, int]:
    """Validate ``(nu, nv)``: nu >= 2 and nv >= 3 (two rows collapse into the tips)."""
    try:
        nu, nv = (int(x) for x in resolution)
    except (TypeError, ValueError):
        raise UsageError(f"resolution must be two whole numbers NUxNV, got {resolution!r}") from None
    if nu < 2 or nv < 3 or nu > 1025 or nv > 1025:
        raise UsageError(f"resolution {nu}x{nv}: need 2 <= NU <= 1025 and 3 <= NV <= 1025 "
                         "(the first and last rows collapse into base and apex)")
    return nu, nv


def pinch_triangles(nu: int, nv: int) -> NDArray[np.bool_]:
    """Mask over :func:`grid_indices` of the triangles with two corners on the pinched rows
    v = 0 (the first triangle of each quad in the first row) and v = 1 (the second triangle of
    each quad in the last row)."""
    quads = (nu - 1) * (nv - 1)
    mask = np.zeros(2 * quads, dtype=bool)
    mask[: nu - 1] = True                      # (p00, p01, p10): p00 and p10 on the base row
    mask[quads + quads - (nu - 1):] = True     # (p10, p01, p11): p01 and p11 on the apex row
    return mask


@lru_cache(maxsize=16)
def _topology(nu: int, nv: int) -> tuple[NDArray[np.uint32], NDArray[np.uint32]]:
    """(kept grid vertex ids, compacted triangles) for a grid without its pinch triangles
    (cached, read-only: every leaf of a grid shares them)."""
    tris = grid_indices(nu, nv)[~pinch_triangles(nu, nv)]
    used = np.unique(tris)
    remap = np.full(nu * nv, -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    tris = remap[tris].astype(np.uint32)
    used.flags.writeable = tris.flags.writeable = False
    return used, tris


def _face_normals(pos: NDArray[np.float64], tris: NDArray[np.uint32]) -> NDArray[np.float64]:
    """Area-weighted vertex normals from the triangles (used only to repair bad normals)."""
    a, b, c = (pos[tris[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)
    acc = np.zeros_like(pos)
    for k in range(3):
        np.add.at(acc, tris[:, k], face)
    return acc


def _finish(name: str, uv: NDArray[np.float64], pos: Any, nrm: Any, nu: int, nv: int) -> LeafMesh:
    """Drop the pinch triangles, check and repair, and pack a :class:`LeafMesh`."""
    keep, tris = _topology(nu, nv)
    return _pack(name, uv[keep], np.asarray(pos, dtype=np.float64)[keep], np.asarray(nrm, dtype=np.float64)[keep],
                 tris)


def _pack(name: str, uv: NDArray[np.float64], pos: NDArray[np.float64], nrm: NDArray[np.float64],
          tris: NDArray[np.uint32]) -> LeafMesh:
    """Check the vertices, repair bad normals from the faces and pack a :class:`LeafMesh`."""
    nrm = nrm.copy()
    label = name or "leaf"
    bad = ~np.isfinite(pos).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise NonFiniteMesh(f"{label}: non-finite vertex {pos[i].tolist()} at (u, v) = "
                            f"({uv[i, 0]:.4g}, {uv[i, 1]:.4g}); nothing was written")
    length = np.linalg.norm(nrm, axis=1)
    off = ~np.isfinite(length) | (np.abs(length - 1.0) > _UNIT_TOL)
    if off.any():  # zero or NaN normal (a flat spot of the parameterisation): use the faces'
        repaired = _face_normals(pos, tris)[off]
        rlen = np.linalg.norm(repaired, axis=1)
        if not (np.isfinite(rlen).all() and (rlen > 0).all()):
            i = int(np.flatnonzero(off)[0])
            raise NonFiniteMesh(f"{label}: no usable normal at (u, v) = ({uv[i, 0]:.4g}, {uv[i, 1]:.4g}) "
                                "(the surface is degenerate there); nothing was written")
        nrm[off] = repaired
        length = np.linalg.norm(nrm, axis=1)
    nrm = nrm / length[:, None]
    return LeafMesh(pos.astype(np.float32), nrm.astype(np.float32), lower_left_st(uv), uv, tris, name)


def lobed_weld(reference: NDArray[np.float64], nu: int, nv: int) -> tuple[NDArray[np.int64], NDArray[np.uint32]]:
    """The welded mesh of a lobed leaf's (nu × nv) grid (its :func:`~leafview.deform.sweep.lobed_grid`)
    from the float64 ``reference`` positions (nu·nv, 3): ``(samples, triangles)``, the grid sample
    each welded vertex takes its position, normal and flat position from (the first of those that
    coincide, in grid order) and the triangles over those vertices
    (:func:`leafview.botany.lobe_sweep.weld_grid`). Vertices no triangle uses are dropped."""
    ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    verts, faces = weld_grid(ref, nu, nv)
    first: dict[tuple[float, ...], int] = {}
    for i, row in enumerate(map(tuple, ref.tolist())):
        first.setdefault(row, i)                      # weld_grid keeps each group's first sample
    samples = np.array([first[tuple(p)] for p in verts.tolist()], dtype=np.int64)
    used = np.unique(faces)
    remap = np.full(len(samples), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return samples[used], remap[faces].astype(np.uint32)


def _bake_lobed(params: LeafParams, nu: int, nv: int, backend: str, renderer: LeafRenderer | None) -> LeafMesh:
    """One lobed leaf on its :func:`~leafview.deform.sweep.lobed_grid` of (nu, nv), welded."""
    gu, gv = lobed_grid((nu, nv))
    uv32 = grid_uv(gu, gv)
    ref = sweep_of(params, uv32.astype(np.float64))
    samples, tris = lobed_weld(ref.L, gu, gv)
    pos, nrm = ref.L, ref.normal
    if renderer is not None and backend == "gpu":
        pos, nrm = (np.asarray(a, dtype=np.float64) for a in renderer.capture(params, uv32[:, 0], uv32[:, 1]))
    return _pack(params.name, ref.uv[samples], pos[samples], nrm[samples], tris)


def lower_left_st(uv: NDArray[np.float64]) -> NDArray[np.float32]:
    """(V, 2) float32 texture coordinates of the (V, 2) leaf points ``uv`` with the origin at the
    image's lower left (OBJ ``vt``, PLY ``s t``, USD ``primvars:st``): (s, 1 - t) of
    :func:`~leafview.core.texture.texture_st`."""
    s, t = texture_st(uv[:, 0], uv[:, 1])
    return np.stack([s, 1.0 - t], axis=1).astype(np.float32)


def gltf_st(uv: NDArray[np.float64]) -> NDArray[np.float32]:
    """(V, 2) float32 glTF ``TEXCOORD_0`` of the leaf points ``uv``: :func:`~leafview.core.texture.texture_st`
    as it is (glTF's origin is the image's upper left)."""
    return np.stack(texture_st(uv[:, 0], uv[:, 1]), axis=1).astype(np.float32)


def check_mesh(mesh: LeafMesh) -> None:
    """Refuse a mesh with non-finite numbers or out-of-range indices (raises NonFiniteMesh)."""
    label = mesh.name or "leaf"
    for what, arr in (("vertex", mesh.positions), ("normal", mesh.normals), ("texture coordinate", mesh.st)):
        bad = ~np.isfinite(arr).all(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise NonFiniteMesh(f"{label}: non-finite {what} {arr[i].tolist()} (vertex {i}); nothing was written")
    if mesh.indices.size and int(mesh.indices.max()) >= mesh.n_vertices:
        raise NonFiniteMesh(f"{label}: triangle index {int(mesh.indices.max())} >= {mesh.n_vertices} vertices")


def bake(params: LeafParams, resolution: Sequence[int] = DEFAULT_RESOLUTION, *, backend: str = "gpu",
         renderer: LeafRenderer | None = None) -> LeafMesh:
    """Bake one leaf (leaf space; the world transform is left to the file's node).

    Parameters
    ----------
    params:
        The leaf. ``params.transform`` matters only through the bend (Geng, Hu & Zhang 2014, eq. 4 loads the
        blade along a world direction); the mesh itself is in leaf space.
    resolution:
        ``(nu, nv)`` grid samples across and along the blade (default 33×65, the renderer's).
    backend:
        ``"gpu"``: positions and normals read back from the rendering vertex shader;
        ``"numpy"``: the float64 reference (Chaurasia & Beardsley 2017, eqs 1-6; Geng, Hu & Zhang 2014, eqs 4-5).
    renderer:
        A :class:`~leafview.gpu.LeafRenderer` for ``"gpu"`` (default: the shared headless one).
    """
    return bake_many([params], resolution, backend=backend, renderer=renderer)[0]


def bake_many(leaves: Iterable[LeafParams], resolution: Sequence[int] = DEFAULT_RESOLUTION, *,
              backend: str = "gpu", renderer: LeafRenderer | None = None,
              progress: Callable[[int], None] | None = None) -> list[LeafMesh]:
    """Bake several leaves on one grid; ``progress(n)`` is called after each leaf."""
    nu, nv = check_resolution(resolution)
    if backend not in BACKENDS:
        raise UsageError(f"unknown backend {backend!r} (use {' or '.join(BACKENDS)})")
    uv32 = grid_uv(nu, nv)
    uv = uv32.astype(np.float64)
    if backend == "gpu" and renderer is None:

        renderer = default_renderer()
    out = []
    for params in leaves:
        if params.lobes.enabled:
            out.append(_bake_lobed(params, nu, nv, backend, renderer))
            if progress is not None:
                progress(1)
            continue
        pos: NDArray[np.floating]
        nrm: NDArray[np.floating]
        if renderer is not None and backend == "gpu":   # "gpu" always has a renderer by now
            pos, nrm = renderer.capture(params, uv32[:, 0], uv32[:, 1])
        else:
            ref = tessellate(params, nu, nv, vein_grid=shape_grid(params))  # the same grid_uv order, float64
            pos, nrm = ref.vertices, ref.normals
        # the surface parameters drawn (a one-sided leaf spreads the grid over its half), so that
        # the texture coordinates of both halves of an asymmetric leaf follow texture_st
        out.append(_finish(params.name, drawn_uv(params, uv), pos, nrm, nu, nv))
        if progress is not None:
            progress(1)
    return out
