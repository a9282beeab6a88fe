"""What the file writers receive: baked shapes, their materials and where each copy goes.

A single leaf and a whole scene both become an :class:`ExportScene`: a list of
:class:`ExportPart` (one baked mesh per distinct leaf shape, with its material and the
leaf-space → world matrices of every leaf that uses it) and optional stem geometry. Writers
never evaluate the model; they decide only how to store the instances (glTF nodes sharing a
mesh, EXT_mesh_gpu_instancing, a USD PointInstancer, or world-space copies in OBJ/PLY).

Conventions: the world of leafview is +z up, lengths in leaf lengths (a leaf of scale 1 is 1 unit
from base to apex); matrices are 4×4 float64 with column vectors (``world = M @ [x, y, z, 1]``),
as :meth:`leafview.core.params.Transform.matrix`. Instanced formats store a matrix as
translation, rotation and scale (TRS); :func:`decompose_trs` splits it and reports how far the
TRS product is from the matrix, so a matrix with shear is never silently changed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.limits import MAX_WORLD_COORD
from leafview.core.params import LeafParams, Material
from leafview.core.texture import LeafTexture
from leafview.errors import NonFiniteMesh, UsageError
from leafview.export.mesh import DEFAULT_RESOLUTION, LeafMesh, bake_many, check_mesh
from leafview.export.textures import SceneTextures, check_textures, load_textures
from leafview.gpu import LeafRenderer

if TYPE_CHECKING:      # vein_maps builds on this module; the annotation alone needs the type
    from leafview.export.vein_maps import VeinMaps

__all__ = [
    "BARK",
    "TRS",
    "TRS_TOLERANCE",
    "check_world",
    "ExportPart",
    "ExportScene",
    "SceneLike",
    "Stems",
    "compose_trs",
    "decompose_trs",
    "leaf_scene",
    "leaves_scene",
    "matrix_from_quat",
    "parts_trs",
    "quat_from_matrix",
    "scene_from",
    "scene_textures",
]

TRS_TOLERANCE = 1e-6   # largest |TRS - M| / max(1, |M|) accepted as a TRS transform
BARK = (0.18, 0.11, 0.06)   # stem base colour (linear RGB)

Stems = tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.uint32]]


@runtime_checkable
class SceneLike(Protocol):
    """The scene interface the exporters read (``leafview.scene.spec.Scene`` provides it).

    ``shapes()``: the distinct leaf shapes (identity transform); ``shape_ids``: (N,) int32 index
    into it per leaf; ``matrices``: (N, 4, 4) float64 leaf space → world, column vectors, +z up;
    ``stems``: None or (positions (M, 3) float32, normals (M, 3) float32, indices (K, 3)
    uint32) in world space; ``len(scene)`` = N.
    """

    # read-only members: Scene derives shape_ids, and a reader needs no setters
    @property
    def shape_ids(self) -> ArrayLike: ...

    @property
    def matrices(self) -> ArrayLike: ...

    @property
    def stems(self) -> tuple[ArrayLike, ArrayLike, ArrayLike] | None: ...

    def shapes(self) -> list[LeafParams]: ...

    def __len__(self) -> int: ...


@dataclass
class ExportPart:
    """One distinct leaf shape: its baked mesh, material, image texture (None: the material's
    colours), the matrices of its copies and its baked vein textures (``vein_maps``, a
    :class:`leafview.export.vein_maps.VeinMaps`; None: none, the file as without venation)."""

    mesh: LeafMesh
    material: Material
    matrices: NDArray[np.float64]          # (K, 4, 4) leaf space -> world
    name: str = ""
    leaf_ids: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    texture: LeafTexture | None = None
    vein_maps: VeinMaps | None = None


@dataclass
class ExportScene:
    """Everything a writer needs. ``length_m``: metres per leaf-length unit."""

    parts: list[ExportPart]
    stems: Stems | None = None
    length_m: float = 0.1
    name: str = "leafview"

    @property
    def n_leaves(self) -> int:
        return sum(len(p.matrices) for p in self.parts)


def scene_textures(scene: ExportScene) -> SceneTextures:
    """The images of ``scene``'s textured parts (:func:`leafview.export.textures.load_textures`,
    indexed like ``scene.parts``), read and checked before a writer writes anything."""
    return load_textures([(p.name or p.mesh.name or "leaf", p.texture) for p in scene.parts])


# -- rotations -------------------------------------------------------------------------------
def quat_from_matrix(r: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit quaternions (x, y, z, w), w >= 0, of rotation matrices (..., 3, 3) (Shepperd's
    method: the largest of the four squared components is taken first, so it is stable)."""
    r = np.asarray(r, dtype=np.float64)
    m00, m11, m22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack([tr, m00, m11, m22], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty(r.shape[:-2] + (4,))
    t = 1.0 + 2.0 * np.take_along_axis(cand, k[..., None], -1)[..., 0] - tr
    s = 0.5 / np.sqrt(np.maximum(t, 1e-300))
    w_, x_, y_ = (k == 0), (k == 1), (k == 2)          # else k == 3: z is the largest
    d10, d01 = r[..., 1, 0], r[..., 0, 1]
    d20, d02 = r[..., 2, 0], r[..., 0, 2]
    d21, d12 = r[..., 2, 1], r[..., 1, 2]
    q[..., 3] = np.where(w_, 0.25 / s, np.where(x_, (d21 - d12) * s, np.where(y_, (d02 - d20) * s, (d10 - d01) * s)))
    q[..., 0] = np.where(w_, (d21 - d12) * s, np.where(x_, 0.25 / s, np.where(y_, (d01 + d10) * s, (d02 + d20) * s)))
    q[..., 1] = np.where(w_, (d02 - d20) * s, np.where(x_, (d01 + d10) * s, np.where(y_, 0.25 / s, (d12 + d21) * s)))
    q[..., 2] = np.where(w_, (d10 - d01) * s, np.where(x_, (d02 + d20) * s, np.where(y_, (d12 + d21) * s, 0.25 / s)))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0.0, -q, q)


def matrix_from_quat(q: NDArray[np.floating]) -> NDArray[np.float64]:
    """Rotation matrices (..., 3, 3) of quaternions (x, y, z, w) (normalised first)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def compose_trs(t: NDArray[np.floating], q: NDArray[np.floating], s: NDArray[np.floating]) -> NDArray[np.float64]:
    """4×4 matrices ``T · R(q) · S`` from (..., 3) translations, (..., 4) quaternions, (..., 3) scales."""
    t = np.asarray(t, np.float64)
    m = np.zeros(t.shape[:-1] + (4, 4))
    m[..., :3, :3] = matrix_from_quat(q) * np.asarray(s, np.float64)[..., None, :]
    m[..., :3, 3] = t
    m[..., 3, 3] = 1.0
    return m


TRS = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


def decompose_trs(m: NDArray[np.floating]) -> TRS:
    """Split matrices (..., 4, 4) into ``M ≈ T · R · S`` (S diagonal, may be negative for mirrors).

    Returns ``(t (..., 3), q (..., 4) as x, y, z, w, s (..., 3), error (...))`` where ``error``
    is ``max |T R S - M| / max(1, max |M|)``: zero up to rounding for a true TRS matrix, large
    for shear or a projective bottom row.
    """
    m64 = np.asarray(m, dtype=np.float64)
    a = m64[..., :3, :3]
    s = np.linalg.norm(a, axis=-2)                       # column lengths
    det = np.linalg.det(a)
    s = np.where((det < 0.0)[..., None], -s, s)          # mirror: all three negative, R proper
    safe = np.where(np.abs(s) > 0.0, s, 1.0)
    r = a / safe[..., None, :]
    # nearest rotation (polar factor) so that a slightly non-orthogonal input still gives a unit q
    u, _, vt = np.linalg.svd(r)
    rot = u @ vt
    q = quat_from_matrix(rot)
    t = m64[..., :3, 3].copy()
    back = compose_trs(t, q, s)
    scale = np.maximum(1.0, np.abs(m64).max(axis=(-2, -1)))
    err = np.abs(back - m64).max(axis=(-2, -1)) / scale
    err = np.where(np.abs(s).min(axis=-1) > 0.0, err, np.inf)   # a zero scale cannot be inverted
    return t, q, s, err


def parts_trs(parts: Sequence[ExportPart]) -> list[TRS]:
    """:func:`decompose_trs` of every part's matrices, computed in one batch (thousands of
    single-leaf parts would otherwise pay numpy's per-call overhead each)."""
    if not parts:
        return []
    t, q, s, err = decompose_trs(np.concatenate([p.matrices for p in parts]))
    out: list[TRS] = []
    at = 0
    for p in parts:
        k = len(p.matrices)
        out.append((t[at:at + k], q[at:at + k], s[at:at + k], err[at:at + k]))
        at += k
    return out


# -- the world-space check every writer relies on ---------------------------------------------
def check_world(scene: ExportScene) -> None:
    """Refuse a scene whose world-space vertices are not finite or do not fit float32 (what every
    format stores): each part's mesh must be finite (:func:`leafview.export.mesh.check_mesh`) and
    every copy's matrix must keep the mesh's bounding box within ±MAX_WORLD_COORD. Raises
    :class:`~leafview.errors.NonFiniteMesh` naming the leaf and the field (``transform.translation``
    or ``transform.scale``/``rotation``); nothing is written."""
    for part in scene.parts:
        label = part.name or part.mesh.name or "leaf"
        mats = np.asarray(part.matrices, dtype=np.float64).reshape(-1, 4, 4)
        if not len(mats) or not part.mesh.n_vertices:
            continue
        if not np.isfinite(mats).all():
            raise NonFiniteMesh(f"{label}: non-finite transform matrix; nothing was written")
        check_mesh(part.mesh)       # leaf space: finite vertices, normals, texture coordinates
        lo, hi = (np.asarray(b, np.float64) for b in part.mesh.bounds())
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        with np.errstate(over="ignore", invalid="ignore"):
            world = np.einsum("kij,cj->kci", mats[:, :3, :3], corners) + mats[:, None, :3, 3]
            bad = ~(np.abs(world) <= MAX_WORLD_COORD).all(axis=(1, 2))
        if bad.any():
            k = int(np.argmax(bad))
            ids = np.asarray(part.leaf_ids)
            which = f" (leaf {int(ids[k])})" if len(ids) > k and len(mats) > 1 else ""
            t = mats[k, :3, 3]
            field = ("transform.translation" if not (np.abs(t) <= MAX_WORLD_COORD / 2).all()
                     else "transform.scale/rotation")
            raise NonFiniteMesh(f"{label}{which}: {field} puts its vertices outside the finite float32 range "
                                f"(|x| > {MAX_WORLD_COORD:.1e}); nothing was written")


# -- building export scenes ------------------------------------------------------------------
def leaf_scene(params: LeafParams, mesh: LeafMesh, *, length_m: float = 0.1,
               maps: VeinMaps | None = None) -> ExportScene:
    """A single leaf placed by its own ``params.transform``, with its baked vein textures ``maps``
    (:func:`leafview.export.vein_maps.bake_vein_maps`; None: none)."""
    part = ExportPart(mesh, params.material, params.transform.matrix()[None], params.name or "leaf",
                      np.zeros(1, np.int64), params.texture, maps)
    return ExportScene([part], None, length_m, params.name or "leaf")


def leaves_scene(leaves: Sequence[LeafParams], resolution: Sequence[int] = DEFAULT_RESOLUTION, *,
                 backend: str = "gpu", renderer: LeafRenderer | None = None, length_m: float = 0.1,
                 progress: Callable[[int], None] | None = None, name: str = "leaves") -> ExportScene:
    """Several leaves, each at its own transform, each its own mesh."""
    check_textures((p.name or f"leaf_{i}", p.texture) for i, p in enumerate(leaves))   # before the bake
    meshes = bake_many(leaves, resolution, backend=backend, renderer=renderer, progress=progress)
    parts = [ExportPart(m, p.material, p.transform.matrix()[None], p.name or f"leaf_{i}", np.array([i]), p.texture)
             for i, (p, m) in enumerate(zip(leaves, meshes))]
    return ExportScene(parts, None, length_m, name)


def _check_stems(stems: Any) -> Stems | None:
    if stems is None:
        return None
    try:
        pos, nrm, idx = stems
    except (TypeError, ValueError):
        raise UsageError("scene.stems must be None or (positions, normals, indices)") from None
    pos = np.asarray(pos, np.float32).reshape(-1, 3)
    nrm = np.asarray(nrm, np.float32).reshape(-1, 3)
    idx = np.asarray(idx).reshape(-1, 3)
    if pos.shape != nrm.shape:
        raise UsageError(f"scene.stems: {len(pos)} positions but {len(nrm)} normals")
    if idx.size and (idx.min() < 0 or idx.max() >= len(pos)):
        raise UsageError(f"scene.stems: triangle indices outside 0..{len(pos) - 1}")
    if not (np.isfinite(pos).all() and np.isfinite(nrm).all()):
        raise UsageError("scene.stems: non-finite positions or normals; nothing was written")
    if len(idx) == 0:
        return None
    lens = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.where(lens > 0, nrm / np.where(lens > 0, lens, 1), np.array([0, 0, 1], np.float32)).astype(np.float32)
    return pos, nrm, idx.astype(np.uint32)


def scene_from(scene: SceneLike, resolution: Sequence[int] = DEFAULT_RESOLUTION, *, backend: str = "gpu",
               renderer: LeafRenderer | None = None, length_m: float = 0.1,
               progress: Callable[[int], None] | None = None, name: str = "scene") -> ExportScene:
    """Bake every distinct shape of ``scene`` once and group the leaves by shape.

    Raises UsageError for inconsistent arrays (wrong shapes, ids out of range, non-finite
    matrices) before anything is baked.
    """
    n = len(scene)
    ids = np.asarray(scene.shape_ids)
    mats = np.asarray(scene.matrices, dtype=np.float64)
    if ids.shape != (n,):
        raise UsageError(f"scene.shape_ids has shape {ids.shape}, expected ({n},)")
    if mats.shape != (n, 4, 4):
        raise UsageError(f"scene.matrices has shape {mats.shape}, expected ({n}, 4, 4)")
    bad = ~np.isfinite(mats).all(axis=(1, 2))
    if bad.any():
        raise UsageError(f"scene.matrices[{int(np.argmax(bad))}] is not finite; nothing was written")
    shapes = scene.shapes()
    if n and (ids.min() < 0 or ids.max() >= len(shapes)):
        raise UsageError(f"scene.shape_ids must lie in 0..{len(shapes) - 1}")
    stems = _check_stems(scene.stems)
    used = np.unique(ids) if n else np.zeros(0, np.int64)
    check_textures((shapes[i].name or f"shape_{i}", shapes[i].texture) for i in used)   # before the bake
    meshes = bake_many([shapes[i] for i in used], resolution, backend=backend, renderer=renderer,
                       progress=progress)
    order = np.argsort(ids, kind="stable")
    starts = np.searchsorted(ids[order], used)
    ends = np.searchsorted(ids[order], used, side="right")
    parts = []
    for sid, mesh, a, b in zip(used, meshes, starts, ends):
        leaf_ids = order[a:b]
        params = shapes[int(sid)]
        parts.append(ExportPart(mesh, params.material, mats[leaf_ids], params.name or f"shape_{sid}", leaf_ids,
                                params.texture))
    return ExportScene(parts, stems, length_m, name)
