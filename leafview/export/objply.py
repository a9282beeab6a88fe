"""Wavefront OBJ and binary PLY writers: plain triangle meshes in world space.

Neither format has instances, two-sided materials or units, so every leaf copy is written out in
world coordinates (its matrix applied, normals by the inverse transpose), scaled to metres by
``length_m``, and turned to +y up (OBJ's usual convention, and Blender's default for both
importers' "Y up") unless ``up="z"`` keeps leafview's +z up. One object (OBJ ``o``) per leaf;
the texture coordinates are ``LeafMesh.st``: (s, 1 - t) of
:func:`leafview.core.texture.texture_st`, origin lower left, as both formats expect. Stems, if
any, are appended as one more object.

Textured leaves (:mod:`leafview.export.textures`): their images are written beside the file,
each once, in one transaction with it (all files or none). Both formats are one-sided here: a
leaf shows its front image.

* OBJ: ``NAME.mtl`` beside ``NAME.obj`` (``mtllib``), one material per image (``map_Kd`` for
  the colour and ``map_d``, the same file, for the alpha that cuts the margin out; ``Kd 1 1 1``)
  and ``usemtl`` per object; in a scene that mixes textured and plain leaves, the plain ones get
  a material of their front colour (``Kd``). Without textured leaves no ``.mtl`` is written and
  the leaf colours are in the glTF and USD exports only.
* PLY: a ``comment TextureFile NAME`` line per image (the convention MeshLab and others read);
  with more than one image each face has an ``int texnumber`` (the image's order among those
  comments, -1 for a plain leaf or the stems).

Baked vein textures (:mod:`leafview.export.vein_maps`, ``export --mesh cdt`` of a leaf with veins)
count as the front image (without ``map_d``: they cover the blade); OBJ adds the front normal map
as ``map_Bump -bm 1`` (what Blender's importer reads as a tangent-space normal map), PLY has no
place for it.

PLY: ``binary_little_endian 1.0``, vertex properties ``x y z nx ny nz s t`` (float32), faces as
``list uchar uint vertex_indices``.
"""

from __future__ import annotations

import io
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview._version import __version__
from leafview.atomic import check_target, outputs, write_bytes, write_text
from leafview.errors import UsageError
from leafview.export.mesh import check_mesh
from leafview.export.scene import BARK, ExportScene, scene_textures
from leafview.export.textures import SceneTextures, TextureImage, write_images
from leafview.export.vein_maps import maps_of, with_maps

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
                                                                            NDArray[np.float32], NDArray[np.uint32],
                                                                            int]]:
    """``(name, positions, normals, st, triangles, part)`` of every leaf copy and the stems, in
    the file's axes and metres (positions and normals float64, normals unit length); ``part`` is
    the copy's index in ``scene.parts`` (-1 for the stems)."""
    axes = axis_matrix(up)
    scale = float(scene.length_m)
    for index, part in enumerate(scene.parts):
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
            yield name, pos, nrm, part.mesh.st, tris, index
    if scene.stems is not None:
        stem_pos, stem_nrm, stem_idx = scene.stems
        yield ("stems", (stem_pos.astype(np.float64) @ axes.T) * scale, stem_nrm.astype(np.float64) @ axes.T,
               np.zeros((len(stem_pos), 2), np.float32), stem_idx, -1)


def _check_finite(name: str, pos: NDArray[np.float64]) -> None:
    if not np.isfinite(pos).all():
        raise UsageError(f"{name}: non-finite vertex after the transform; nothing was written")


def _mtl(scene: ExportScene, textures: SceneTextures, files: dict[TextureImage, str]) -> tuple[str, list[str]]:
    """The ``.mtl`` text and the material of each part (``-1``, the stems, last)."""
    lines = [f"# leafview {__version__}: one material per leaf image (map_d: its alpha)\n"]
    names: dict[Any, str] = {}
    used: set[str] = set()

    def add(key: Any, base: str, body: str) -> str:
        if key not in names:
            name, k = base, 1
            while name in used:
                k += 1
                name = f"{base}_{k}"
            used.add(name)
            names[key] = name
            lines.append(f"\nnewmtl {name}\n{body}")
        return names[key]

    plain = "Ka 0 0 0\nKs 0 0 0\nd 1\nillum 1\n"
    per_part = []
    for index, part in enumerate(scene.parts):
        sides = textures.of(index)
        maps = maps_of(part)
        bump = "" if maps is None else f"map_Bump -bm 1 {files[maps.normal]}\n"
        if sides is None:
            colour = part.material.front
            per_part.append(add(("colour", tuple(colour), bump), _obj_name(f"leaf_{_hex(colour)}"),
                                f"Kd {colour[0]:.6g} {colour[1]:.6g} {colour[2]:.6g}\n{plain}{bump}"))
        else:
            file = files[sides[0]]
            cut = f"map_d {file}\n" if part.texture is not None else ""   # a photograph's alpha; baked maps cover the blade
            per_part.append(add((sides[0], bump), _obj_name(f"leaf_{Path(file).stem}"),
                                f"Kd 1 1 1\n{plain}map_Kd {file}\n{cut}{bump}"))
    if scene.stems is not None:
        per_part.append(add("bark", "bark", f"Kd {BARK[0]:.6g} {BARK[1]:.6g} {BARK[2]:.6g}\n{plain}"))
    return "".join(lines), per_part


def _hex(colour: Sequence[float]) -> str:
    return "".join(f"{round(min(max(c, 0.0), 1.0) * 255):02x}" for c in colour)


def write_obj(scene: ExportScene, path: str | Path, *, up: str = "y") -> Path:
    """Write ``scene`` as a Wavefront OBJ (``v``, ``vt``, ``vn``, ``f a/a/a``) atomically, with
    ``NAME.mtl`` and the images beside it when some leaves are textured (all files or none)."""
    path = check_target(path)
    textures = with_maps(scene, scene_textures(scene).front_only(), one_sided=True)   # read and checked first
    mtl_path = path.with_name("_".join(path.stem.split()) + ".mtl")   # mtllib names may not hold blanks
    if textures:
        check_target(mtl_path)
    with outputs():
        materials: list[str] = []
        buf = io.StringIO()
        buf.write(f"# leafview {__version__}: {scene.n_leaves} leaves, metres, +{up} up\n")
        if textures:
            text, materials = _mtl(scene, textures, write_images(textures, path.parent))
            write_text(mtl_path, text)
            buf.write(f"mtllib {mtl_path.name}\n")
        _obj_body(buf, scene, up, materials)
        write_text(path, buf.getvalue())   # atomic, every byte checked
    return path


def _obj_body(buf: io.StringIO, scene: ExportScene, up: str, materials: list[str]) -> None:
    """The objects of ``scene`` (``usemtl`` from ``materials`` per part when given)."""
    base = 1
    for name, pos, nrm, st, tris, part in world_triangles(scene, up):
        _check_finite(name, pos)
        buf.write(f"o {_obj_name(name)}\n")
        if materials:
            buf.write(f"usemtl {materials[part]}\n")
        np.savetxt(buf, pos, fmt="v %.9g %.9g %.9g")
        np.savetxt(buf, st, fmt="vt %.9g %.9g")
        np.savetxt(buf, nrm, fmt="vn %.7g %.7g %.7g")
        f = tris.astype(np.int64) + base
        np.savetxt(buf, np.repeat(f, 3, axis=1), fmt="f %d/%d/%d %d/%d/%d %d/%d/%d")
        base += len(pos)


def _obj_name(name: str) -> str:
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in name) or "leaf"


def write_ply(scene: ExportScene, path: str | Path, *, up: str = "y") -> Path:
    """Write ``scene`` as one binary little-endian PLY mesh atomically, with the images of its
    textured leaves beside it (all files or none)."""
    path = check_target(path)
    textures = with_maps(scene, scene_textures(scene).front_only(), one_sided=True, normals=False)   # read first
    chunks = list(world_triangles(scene, up))
    for name, pos, *_ in chunks:
        _check_finite(name, pos)
    columns = ("x", "y", "z", "nx", "ny", "nz", "s", "t")
    vert = np.zeros(sum(len(c[1]) for c in chunks), dtype=[(k, "<f4") for k in columns])
    faces = []
    base = 0
    image_of = {image: k for k, image in enumerate(textures.images)}
    texnumber = []
    for _, pos, nrm, st, tris, part in chunks:
        sides = textures.of(part)
        texnumber.append(np.full(len(tris), -1 if sides is None else image_of[sides[0]], np.int32))
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
    several = len(textures.images) > 1
    face = np.zeros(len(tris), dtype=[("n", "u1"), ("i", "<u4", (3,))] + ([("tex", "<i4")] if several else []))
    face["n"] = 3
    face["i"] = tris
    if several:
        face["tex"] = np.concatenate(texnumber)
    with outputs():
        files = write_images(textures, path.parent)
        header = (f"ply\nformat binary_little_endian 1.0\ncomment leafview {__version__}: metres, +{up} up\n"
                  + "".join(f"comment TextureFile {files[image]}\n" for image in textures.images)
                  + f"element vertex {len(vert)}\n"
                  + "".join(f"property float {k}\n" for k in columns)
                  + f"element face {len(face)}\nproperty list uchar uint vertex_indices\n"
                  + ("property int texnumber\n" if several else "") + "end_header\n")
        write_bytes(path, header.encode("ascii"), vert.tobytes(), face.tobytes())   # atomic, every byte checked
    return path
