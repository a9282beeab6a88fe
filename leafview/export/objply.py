"""Wavefront OBJ and binary PLY writers: plain triangle meshes in world space.

Neither format has instances, two-sided materials or units, so every leaf copy is written out in
world coordinates (its matrix applied, normals by the inverse transpose), scaled to metres by
``length_m``, and turned to +y up (OBJ's usual convention, and Blender's default for both
importers' "Y up") unless ``up="z"`` keeps leafview's +z up. One object (OBJ ``o``) per leaf;
the texture coordinates are the ``st = ((1 - u) / 2, v)`` of :mod:`leafview.export.mesh`
(origin lower left, as both formats expect). Stems, if any, are appended as one more object.
Materials are not written (no ``.mtl`` file); the leaf colours are in the glTF and USD exports.

PLY: ``binary_little_endian 1.0``, vertex properties ``x y z nx ny nz s t`` (float32), faces as
``list uchar uint vertex_indices``.
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from leafview._version import __version__
from leafview.atomic import check_target, write_bytes, write_text
from leafview.errors import UsageError
from leafview.export.mesh import check_mesh
from leafview.export.scene import ExportScene

__all__ = ["UP_AXES", "axis_matrix", "world_triangles", "write_obj", "write_ply"]

UP_AXES = ("y", "z")


def axis_matrix(up: str) -> NDArray[np.float64]:
    """3×3 map from leafview's +z-up world to the file's axes: identity for ``"z"``, and
    (x, y, z) → (x, z, -y) for ``"y"`` (a rotation of -90° about x, as the glTF root node)."""
    if up == "z":
        return np.eye(3)
    if up == "y":
        return np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    raise UsageError(f"unknown up axis {up!r} (use y or z)")


def world_triangles(scene: ExportScene, up: str = "y") -> Iterator[tuple[str, NDArray[np.float64], NDArray[np.float64],
                                                                            NDArray[np.float32], NDArray[np.uint32]]]:
    """``(name, positions, normals, st, triangles)`` of every leaf copy and the stems, in the
    file's axes and metres (positions and normals float64, normals unit length)."""
    axes = axis_matrix(up)
    scale = float(scene.length_m)
    for part in scene.parts:
        check_mesh(part.mesh)
        pos0 = part.mesh.positions.astype(np.float64)
        nrm0 = part.mesh.normals.astype(np.float64)
        for k, m in enumerate(part.matrices):
            a = axes @ m[:3, :3]
            pos = (pos0 @ a.T + axes @ m[:3, 3]) * scale
            nrm = nrm0 @ np.linalg.inv(a)
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
            tris = part.mesh.indices if np.linalg.det(a) > 0 else part.mesh.indices[:, ::-1]
            name = part.name if len(part.matrices) == 1 else f"{part.name}.{k}"
            yield name, pos, nrm, part.mesh.st, tris
    if scene.stems is not None:
        stem_pos, stem_nrm, stem_idx = scene.stems
        yield ("stems", (stem_pos.astype(np.float64) @ axes.T) * scale, stem_nrm.astype(np.float64) @ axes.T,
               np.zeros((len(stem_pos), 2), np.float32), stem_idx)


def _check_finite(name: str, pos: NDArray[np.float64]) -> None:
    if not np.isfinite(pos).all():
        raise UsageError(f"{name}: non-finite vertex after the transform; nothing was written")


def write_obj(scene: ExportScene, path: str | Path, *, up: str = "y") -> Path:
    """Write ``scene`` as a Wavefront OBJ (``v``, ``vt``, ``vn``, ``f a/a/a``) atomically."""
    path = check_target(path)
    buf = io.StringIO()
    buf.write(f"# leafview {__version__}: {scene.n_leaves} leaves, metres, +{up} up\n")
    base = 1
    for name, pos, nrm, st, tris in world_triangles(scene, up):
        _check_finite(name, pos)
        buf.write(f"o {_obj_name(name)}\n")
        np.savetxt(buf, pos, fmt="v %.9g %.9g %.9g")
        np.savetxt(buf, st, fmt="vt %.9g %.9g")
        np.savetxt(buf, nrm, fmt="vn %.7g %.7g %.7g")
        f = tris.astype(np.int64) + base
        np.savetxt(buf, np.repeat(f, 3, axis=1), fmt="f %d/%d/%d %d/%d/%d %d/%d/%d")
        base += len(pos)
    write_text(path, buf.getvalue())   # atomic, every byte checked
    return path


def _obj_name(name: str) -> str:
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in name) or "leaf"


def write_ply(scene: ExportScene, path: str | Path, *, up: str = "y") -> Path:
    """Write ``scene`` as one binary little-endian PLY mesh atomically."""
    path = check_target(path)
    chunks = list(world_triangles(scene, up))
    for name, pos, *_ in chunks:
        _check_finite(name, pos)
    columns = ("x", "y", "z", "nx", "ny", "nz", "s", "t")
    vert = np.zeros(sum(len(c[1]) for c in chunks), dtype=[(k, "<f4") for k in columns])
    faces = []
    base = 0
    for _, pos, nrm, st, tris in chunks:
        sl = slice(base, base + len(pos))
        for i, k in enumerate("xyz"):
            vert[k][sl] = pos[:, i]
            vert["n" + k][sl] = nrm[:, i]
        vert["s"][sl], vert["t"][sl] = st[:, 0], st[:, 1]
        faces.append(tris.astype(np.int64) + base)
        base += len(pos)
    tris = np.concatenate(faces) if faces else np.zeros((0, 3), np.int64)
    if base >= 2**32:
        raise UsageError(f"{base} vertices: too many for PLY's 32-bit indices")
    face = np.zeros(len(tris), dtype=[("n", "u1"), ("i", "<u4", (3,))])
    face["n"] = 3
    face["i"] = tris
    header = (f"ply\nformat binary_little_endian 1.0\ncomment leafview {__version__}: metres, +{up} up\n"
              f"element vertex {len(vert)}\n"
              + "".join(f"property float {k}\n" for k in columns)
              + f"element face {len(face)}\nproperty list uchar uint vertex_indices\nend_header\n")
    write_bytes(path, header.encode("ascii"), vert.tobytes(), face.tobytes())   # atomic, every byte checked
    return path
