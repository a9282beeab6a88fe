"""Export of baked leaves and scenes: glTF 2.0 (.glb/.gltf), OBJ, PLY and USD (.usda/.usdc).

:func:`export_leaf` and :func:`export_scene` bake the leaves (:mod:`.mesh`), group them by shape
(:mod:`.scene`) and pick the writer from the file suffix (:mod:`.gltf`, :mod:`.objply`,
:mod:`.usd`). Every option is checked before anything is baked, every file is written through
:mod:`leafview.atomic` (target checked before the bake, written atomically and verified, a
failure leaves no file) and non-finite vertices are refused. A textured leaf's images
(:mod:`.textures`) are found before the bake and written beside the file (OBJ, PLY, USD) or into
it (glTF), each once. ``docs/export.md`` has the conventions (axes, units, texture coordinates,
the two leaf sides).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from leafview.atomic import check_target
from leafview.core.params import LeafParams
from leafview.errors import UsageError
from leafview.export.gltf import BACK_FACES, INSTANCING_MODES, write_gltf
from leafview.export.mesh import (
    BACKENDS,
    DEFAULT_RESOLUTION,
    LeafMesh,
    NonFiniteMesh,
    bake,
    bake_many,
    check_resolution,
)
from leafview.export.objply import UP_AXES, write_obj, write_ply
from leafview.export.scene import (
    ExportPart,
    ExportScene,
    SceneLike,
    check_world,
    leaves_scene,
    scene_from,
)
from leafview.export.textures import check_textures
from leafview.export.usd import write_usd
from leafview.export.vein_maps import bake_vein_maps, vein_scene
from leafview.gpu import LeafRenderer

__all__ = [
    "BACKENDS",
    "DEFAULT_LENGTH_M",
    "DEFAULT_RESOLUTION",
    "FORMATS",
    "ExportPart",
    "ExportScene",
    "LeafMesh",
    "NonFiniteMesh",
    "SceneLike",
    "bake",
    "bake_many",
    "export_leaf",
    "export_leaves",
    "export_scene",
    "format_of",
    "write",
]

FORMATS = {".glb": "glb", ".gltf": "gltf", ".obj": "obj", ".ply": "ply", ".usda": "usda", ".usdc": "usdc"}
DEFAULT_LENGTH_M = 0.1     # a leaf length in metres: a 10 cm leaf, typical of broad-leaved trees
_OPTIONS = {"glb": ("back_faces", "instancing", "instance_threshold"),
            "gltf": ("back_faces", "instancing", "instance_threshold"),
            "obj": ("up",), "ply": ("up",), "usda": ("back_faces",), "usdc": ("back_faces",)}


def format_of(path: str | Path) -> str:
    """The export format of ``path`` from its suffix; UsageError for anything else."""
    fmt = FORMATS.get(Path(path).suffix.lower())
    if fmt is None:
        raise UsageError(f"{path}: unknown export format {Path(path).suffix or '(no suffix)'!r} "
                         f"(use {', '.join(FORMATS)})")
    return fmt


def _check_options(fmt: str, options: dict[str, Any]) -> dict[str, Any]:
    """Keep the options ``fmt`` uses (None means default) and validate their values early."""

    kept = {k: v for k, v in options.items() if v is not None and k in _OPTIONS[fmt]}
    unknown = set(options) - {"back_faces", "instancing", "instance_threshold", "up"}
    if unknown:
        raise TypeError(f"unknown export option(s): {', '.join(sorted(unknown))}")
    for key, allowed in (("back_faces", BACK_FACES), ("instancing", INSTANCING_MODES), ("up", UP_AXES)):
        if key in kept and kept[key] not in allowed:
            raise UsageError(f"{key.replace('_', '-')} must be one of {', '.join(allowed)}, got {kept[key]!r}")
    if "instance_threshold" in kept and int(kept["instance_threshold"]) < 1:
        raise UsageError("instance threshold must be at least 1")
    return kept


def _check_length(length_m: float) -> float:
    try:
        value = float(length_m)
    except (TypeError, ValueError):
        raise UsageError(f"length must be a number of metres, got {length_m!r}") from None
    if not (value > 0.0 and value < float("inf")):
        raise UsageError(f"length must be a positive, finite number of metres, got {length_m!r}")
    return value


def _check_glb_size(scene: SceneLike, resolution: Sequence[int]) -> None:
    """Refuse before baking a scene whose GLB would pass the format's 4 GiB limit."""

    nu, nv = check_resolution(resolution)
    verts, tris = nu * nv - 2, 2 * (nu - 1) * (nv - 1) - 2 * (nu - 1)
    index_bytes = 2 if verts < 65535 else 4
    per_shape = verts * (12 + 12 + 8 + 12) + 2 * 3 * tris * index_bytes   # pos, nrm, st, back nrm; 2 sides
    shapes = len(np.unique(np.asarray(scene.shape_ids))) if len(scene) else 0
    estimate = shapes * per_shape + 40 * len(scene)
    if estimate > 2**32 - 1:
        raise UsageError(f"{shapes:,} distinct leaves at {nu}x{nv} would make a {estimate / 2**30:.1f} GiB GLB, "
                         "above the format's 4 GiB limit: lower --resolution, or use .usdc")


def write(scene: ExportScene, path: str | Path, **options: Any) -> Path:
    """Write an :class:`ExportScene` with the writer for ``path``'s suffix (atomically)."""
    fmt = format_of(path)
    kept = _check_options(fmt, options)
    scene.length_m = _check_length(scene.length_m)
    check_world(scene)          # every format: finite world-space vertices, or nothing is written
    if fmt in ("glb", "gltf"):

        return write_gltf(scene, path, **kept)
    if fmt == "obj":

        return write_obj(scene, path, **kept)
    if fmt == "ply":

        return write_ply(scene, path, **kept)

    return write_usd(scene, path, **kept)


def export_leaf(params: LeafParams, path: str | Path, *, resolution: Sequence[int] = DEFAULT_RESOLUTION,
                backend: str = "gpu", length_m: float = DEFAULT_LENGTH_M, renderer: LeafRenderer | None = None,
                vein_maps: bool = False, **options: Any) -> Path:
    """Bake ``params`` and write it to ``path`` (format from the suffix), placed by its transform.
    With ``vein_maps``, a leaf whose venation is enabled carries its baked vein textures (base
    colour and normal maps, :func:`leafview.export.vein_maps.bake_vein_maps`), as ``leafview
    export`` writes them; without, its material colours only.

    ``options``: ``back_faces`` and ``instancing`` (glTF), ``back_faces`` (USD), ``up`` (OBJ/PLY).
    """
    fmt = format_of(path)
    _check_options(fmt, options)
    length_m = _check_length(length_m)
    check_target(path)   # a folder that cannot take the file fails before the bake
    check_textures([(params.name or "leaf", params.texture)])   # and a missing texture file
    mesh = bake(params, resolution, backend=backend, renderer=renderer)
    maps = bake_vein_maps(params) if vein_maps else None
    return write(vein_scene(params, mesh, maps, length_m=length_m), path, **options)


def export_leaves(leaves: Sequence[LeafParams], path: str | Path, *, resolution: Sequence[int] = DEFAULT_RESOLUTION,
                  backend: str = "gpu", length_m: float = DEFAULT_LENGTH_M, renderer: LeafRenderer | None = None,
                  progress: Callable[[int], None] | None = None, **options: Any) -> Path:
    """Several leaves, each at its own transform, into one file."""
    fmt = format_of(path)
    _check_options(fmt, options)
    check_target(path)
    scene = leaves_scene(leaves, resolution, backend=backend, renderer=renderer, length_m=_check_length(length_m),
                         progress=progress, name=Path(path).stem)
    return write(scene, path, **options)


def export_scene(scene: SceneLike, path: str | Path, *, resolution: Sequence[int] = DEFAULT_RESOLUTION,
                 backend: str = "gpu", length_m: float = DEFAULT_LENGTH_M, renderer: LeafRenderer | None = None,
                 progress: Callable[[int], None] | None = None, name: str | None = None,
                 **options: Any) -> Path:
    """Bake every distinct shape of ``scene`` once and write all leaves and stems to ``path``.

    Leaves sharing a shape share one mesh (glTF nodes or EXT_mesh_gpu_instancing, a USD
    PointInstancer); OBJ and PLY get world-space copies. ``progress(n)`` counts baked shapes.
    """
    fmt = format_of(path)
    _check_options(fmt, options)
    if fmt == "glb":
        _check_glb_size(scene, resolution)
    check_target(path)
    export = scene_from(scene, resolution, backend=backend, renderer=renderer, length_m=_check_length(length_m),
                        progress=progress, name=name or Path(path).stem)
    return write(export, path, **options)
