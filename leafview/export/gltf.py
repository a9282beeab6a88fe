"""glTF 2.0 writer (``.glb`` binary or ``.gltf`` JSON with an embedded buffer), numpy + json only.

Layout of a written file:

* one root node ``leafview`` turns leafview's +z-up world into glTF's +y-up (a rotation of -90°
  about x: (x, y, z) → (x, z, -y)) and scales leaf lengths to metres (``length_m``); the
  vertex data stay in leaf space, exactly as baked;
* one mesh per distinct leaf shape with two primitives sharing POSITION and TEXCOORD_0: the
  front (upper) side with the front material and the back side with reversed winding, negated
  normals and the back material, both single-sided, so every viewer shows the two colours of
  leafview's two-sided shading (``back_faces="double-sided"``: one double-sided primitive with
  the front material instead);
* the copies of a shape: a node each (sharing the mesh, translation/rotation/scale), or one node
  with ``EXT_mesh_gpu_instancing`` (TRANSLATION, ROTATION, SCALE accessors) when a shape has at
  least ``instance_threshold`` copies; a matrix that is not TRS (shear) is baked into a
  world-space copy of the mesh instead, because glTF nodes and instances hold TRS only;
* materials: metallic 0, base colour = the side's colour, and translucency as
  ``KHR_materials_diffuse_transmission`` (factor = translucency, colour = the side's colour, the
  same Lambertian transmission term as ``shaders/leaf.frag``);
* textured leaves (:mod:`leafview.export.textures`): the image replaces the side's colour
  (``baseColorFactor`` white, ``pbrMetallicRoughness.baseColorTexture`` on ``TEXCOORD_0`` =
  :func:`leafview.core.texture.texture_st` of the vertex's (u, v), and the same texture as the
  transmission colour), ``alphaMode`` MASK with ``alphaCutoff`` 0.5 so the image's alpha cuts
  the margin out, one sampler (linear, trilinear mipmaps, clamp to edge). The front primitive
  shows the front image and the back primitive the back image (the front one when the leaf has
  none); with ``back_faces="double-sided"`` the one double-sided primitive shows the front image
  only (glTF has no per-face texture). Images are stored in the binary buffer (a buffer view
  with ``mimeType``) in ``.glb`` and ``.gltf`` alike, so a ``.gltf`` stays one self-contained
  file; each image file is stored once, and one material per image and side, however many
  leaves or shapes use it (a textured species' colour variation is not exported);
* baked vein textures (:mod:`leafview.export.vein_maps`, ``export --mesh cdt`` of a leaf with
  veins): each side's base colour image as its ``baseColorTexture`` (opaque: it covers the blade)
  and its tangent-space vein relief as ``normalTexture``, the primitives carrying the maps'
  frame as ``TANGENT`` (:func:`leafview.export.vein_maps.tangents`; the back's w negated), the
  images stored like those above.

Buffer views are 4-byte aligned, POSITION accessors carry min/max, indices are unsigned short
when every index fits below 65535 (the primitive-restart value), else unsigned int.
"""

from __future__ import annotations

import base64
import json
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview._version import __version__
from leafview.atomic import check_target, write_bytes
from leafview.errors import UsageError
from leafview.export.mesh import LeafMesh, check_mesh, gltf_st
from leafview.export.scene import BARK, TRS, TRS_TOLERANCE, ExportPart, ExportScene, parts_trs, scene_textures
from leafview.export.textures import TextureImage
from leafview.export.vein_maps import maps_of, tangents, with_maps

__all__ = ["BACK_FACES", "INSTANCING_MODES", "Z_UP_TO_Y_UP", "gltf_document", "write_gltf"]

INSTANCING_MODES = ("auto", "nodes", "ext")
BACK_FACES = ("primitive", "double-sided")
Z_UP_TO_Y_UP = [-0.7071067811865476, 0.0, 0.0, 0.7071067811865476]   # quaternion x, y, z, w
_EXT_INSTANCING = "EXT_mesh_gpu_instancing"
_EXT_DIFFUSE = "KHR_materials_diffuse_transmission"
_FLOAT, _USHORT, _UINT = 5126, 5123, 5125
_ARRAY, _ELEMENTS = 34962, 34963
_LINEAR, _LINEAR_MIPMAP_LINEAR, _CLAMP_TO_EDGE = 9729, 9987, 33071
ALPHA_CUTOFF = 0.5      # a texel with alpha below this is cut out of the leaf
_MAX_GLB = 2**32 - 1
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}


class _Builder:
    """Accumulates the binary buffer, buffer views, accessors, meshes, materials and nodes."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.doc: dict[str, Any] = {"bufferViews": [], "accessors": [], "meshes": [], "materials": [],
                                    "nodes": []}
        self.used: set[str] = set()
        self.required: set[str] = set()
        self._materials: dict[tuple[Any, ...], int] = {}
        self._textures: dict[TextureImage, int] = {}

    def view(self, data: bytes, target: int | None) -> int:
        self.blob += b"\0" * (-len(self.blob) % 4)
        entry: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if target is not None:
            entry["target"] = target
        self.blob += data
        self.doc["bufferViews"].append(entry)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, array: NDArray[Any], *, target: int | None = _ARRAY, bounds: bool = False) -> int:
        array = np.ascontiguousarray(array)
        comps = 1 if array.ndim == 1 else array.shape[1]
        ctype = {np.dtype(np.float32): _FLOAT, np.dtype(np.uint16): _USHORT, np.dtype(np.uint32): _UINT}[array.dtype]
        entry: dict[str, Any] = {"bufferView": self.view(array.tobytes(), target), "componentType": ctype,
                                 "count": array.shape[0], "type": _TYPES[comps]}
        if bounds:
            flat = array.reshape(array.shape[0], comps)
            entry["min"] = [float(x) for x in flat.min(axis=0)]
            entry["max"] = [float(x) for x in flat.max(axis=0)]
        self.doc["accessors"].append(entry)
        return len(self.doc["accessors"]) - 1

    def indices(self, tris: NDArray[np.uint32], n_vertices: int) -> int:
        dtype = np.uint16 if n_vertices < 65535 else np.uint32
        return self.accessor(tris.astype(dtype).ravel(), target=_ELEMENTS)

    def texture(self, image: TextureImage) -> int:
        """The texture of ``image`` (its image and the one sampler made on first use)."""
        if image not in self._textures:
            if not self._textures:
                self.doc["samplers"] = [{"magFilter": _LINEAR, "minFilter": _LINEAR_MIPMAP_LINEAR,
                                         "wrapS": _CLAMP_TO_EDGE, "wrapT": _CLAMP_TO_EDGE}]
                self.doc["images"], self.doc["textures"] = [], []
            self.doc["images"].append({"name": image.name, "bufferView": self.view(image.data, None),
                                       "mimeType": image.mime})
            self.doc["textures"].append({"sampler": 0, "source": len(self.doc["images"]) - 1})
            self._textures[image] = len(self.doc["textures"]) - 1
        return self._textures[image]

    def material(self, name: str, colour: Sequence[float], translucency: float, double_sided: bool,
                 extras: dict[str, Any], image: TextureImage | None = None, *, mask: bool = True,
                 normal: TextureImage | None = None) -> int:
        """A material of ``colour``, or of ``image`` (cut out by its alpha unless ``mask`` is
        false: a baked vein texture covers the blade) when one is given, with the tangent-space
        ``normal`` map when given."""
        tex = None if image is None else self.texture(image)
        ntex = None if normal is None else self.texture(normal)
        key = (name, tuple(colour) if tex is None else None, translucency, double_sided, tex, mask, ntex)
        if key in self._materials:
            return self._materials[key]
        factor = [*map(float, colour)] if tex is None else [1.0, 1.0, 1.0]
        pbr: dict[str, Any] = {"baseColorFactor": [*factor, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.6}
        mat: dict[str, Any] = {"name": name, "pbrMetallicRoughness": pbr, "doubleSided": double_sided,
                               "extras": {"leafview": extras}}
        if tex is not None:
            pbr["baseColorTexture"] = {"index": tex, "texCoord": 0}
            if mask:
                mat["alphaMode"], mat["alphaCutoff"] = "MASK", ALPHA_CUTOFF
        if ntex is not None:
            mat["normalTexture"] = {"index": ntex, "texCoord": 0}
        if translucency > 0.0:
            diffuse: dict[str, Any] = {"diffuseTransmissionFactor": float(translucency),
                                       "diffuseTransmissionColorFactor": factor}
            if tex is not None:
                diffuse["diffuseTransmissionColorTexture"] = {"index": tex, "texCoord": 0}
            mat["extensions"] = {_EXT_DIFFUSE: diffuse}
            self.used.add(_EXT_DIFFUSE)
        self.doc["materials"].append(mat)
        self._materials[key] = len(self.doc["materials"]) - 1
        return self._materials[key]

    def node(self, entry: dict[str, Any]) -> int:
        self.doc["nodes"].append(entry)
        return len(self.doc["nodes"]) - 1


def _leaf_materials(b: _Builder, part: ExportPart, back_faces: str,
                    images: tuple[TextureImage, TextureImage] | None) -> tuple[int, int | None]:
    """The front and back materials of ``part`` (back None for ``back_faces="double-sided"``),
    textured with ``images`` (front, back) when the leaf has them, with the normal maps of its
    baked vein textures (:mod:`leafview.export.vein_maps`) when it has those."""
    m = part.material
    extras: dict[str, Any] = {"front": list(m.front), "back": list(m.back), "translucency": m.translucency}
    front_img: TextureImage | None = None
    back_img: TextureImage | None = None
    front_label, back_label = _hex(m.front), _hex(m.back)
    if images is not None:
        front_img, back_img = images
        front_label, back_label = front_img.name, back_img.name
        extras["texture"] = {"front": front_label, "back": back_label}
    maps = maps_of(part)
    front_nrm, back_nrm = (maps.normal, maps.back_normal) if maps is not None else (None, None)
    if maps is not None:
        extras["vein_maps"] = [image.name for image in maps.images]
    mask = part.texture is not None       # a photograph's alpha cuts the margin out; baked maps cover the blade
    if back_faces == "double-sided":
        return b.material(f"leaf {front_label}", m.front, m.translucency, True, extras, front_img, mask=mask,
                          normal=front_nrm), None
    front = b.material(f"leaf front {front_label}", m.front, m.translucency, False, {**extras, "side": "front"},
                       front_img, mask=mask, normal=front_nrm)
    back = b.material(f"leaf back {back_label}", m.back, m.translucency, False, {**extras, "side": "back"}, back_img,
                      mask=mask, normal=back_nrm)
    return front, back


def _hex(colour: Sequence[float]) -> str:
    return "#" + "".join(f"{round(min(max(c, 0.0), 1.0) * 255):02x}" for c in colour)


def _mesh(b: _Builder, mesh: LeafMesh, name: str, front_mat: int, back_mat: int | None, *,
          with_tangents: bool = False) -> int:
    """A glTF mesh for ``mesh``: front primitive, plus the back one when ``back_mat`` is set;
    ``with_tangents``: TANGENT attributes for normal maps (:func:`leafview.export.vein_maps.tangents`)."""
    check_mesh(mesh)
    v = mesh.n_vertices
    pos = b.accessor(mesh.positions, bounds=True)
    nrm = b.accessor(mesh.normals)
    tex = b.accessor(gltf_st(mesh.uv))      # glTF texture space: t runs downwards
    tan = tangents(mesh) if with_tangents else None     # the frame of the normal maps
    front: dict[str, Any] = {"POSITION": pos, "NORMAL": nrm, "TEXCOORD_0": tex}
    if tan is not None:
        front["TANGENT"] = b.accessor(tan)
    prims = [{"attributes": front, "indices": b.indices(mesh.indices, v), "material": front_mat, "mode": 4}]
    if back_mat is not None:
        back: dict[str, Any] = {"POSITION": pos, "NORMAL": b.accessor(-mesh.normals), "TEXCOORD_0": tex}
        if tan is not None:       # w negated: the back's bitangent, cross(-n, t) w, keeps its direction
            back["TANGENT"] = b.accessor(tan * np.array([1.0, 1.0, 1.0, -1.0], np.float32))
        prims.append({"attributes": back, "indices": b.indices(mesh.indices[:, ::-1], v), "material": back_mat,
                      "mode": 4})
    b.doc["meshes"].append({"name": name, "primitives": prims})
    return len(b.doc["meshes"]) - 1


def _world_copy(mesh: LeafMesh, m: NDArray[np.float64]) -> LeafMesh:
    """``mesh`` moved into world space by a general (non-TRS) matrix."""
    a = m[:3, :3]
    pos = mesh.positions.astype(np.float64) @ a.T + m[:3, 3]
    nrm = mesh.normals.astype(np.float64) @ np.linalg.inv(a)    # inverse transpose, row vectors
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    tris = mesh.indices if np.linalg.det(a) > 0 else mesh.indices[:, ::-1]
    return LeafMesh(pos.astype(np.float32), nrm.astype(np.float32), mesh.st, mesh.uv, np.ascontiguousarray(tris),
                    mesh.name)


def _trs_entry(t: NDArray[np.float64], q: NDArray[np.float64], s: NDArray[np.float64]) -> dict[str, Any]:
    entry: dict[str, Any] = {}
    if np.any(t != 0.0):
        entry["translation"] = [float(x) for x in t]
    if not (q[3] == 1.0 and not np.any(q[:3])):
        entry["rotation"] = [float(x) for x in q]
    if np.any(s != 1.0):
        entry["scale"] = [float(x) for x in s]
    return entry


def _place(b: _Builder, part: ExportPart, trs: TRS, mesh_id: int,
           mats: tuple[int, int | None], instancing: str, threshold: int) -> list[int]:
    """Nodes (children of the root) that place every copy of ``part`` (``trs``: its matrices
    decomposed)."""
    t, q, s, err = trs
    ok = err <= TRS_TOLERANCE
    nodes = []
    k_ok = int(ok.sum())
    use_ext = k_ok > 0 and (instancing == "ext" or (instancing == "auto" and k_ok >= threshold))
    if use_ext:
        attrs = {"TRANSLATION": b.accessor(t[ok].astype(np.float32), target=None),
                 "ROTATION": b.accessor(q[ok].astype(np.float32), target=None),
                 "SCALE": b.accessor(s[ok].astype(np.float32), target=None)}
        nodes.append(b.node({"name": f"{part.name} ×{k_ok}", "mesh": mesh_id,
                             "extensions": {_EXT_INSTANCING: {"attributes": attrs}}}))
        b.used.add(_EXT_INSTANCING)
        b.required.add(_EXT_INSTANCING)   # without it a loader would draw one copy, silently
    else:
        for i in np.flatnonzero(ok):
            entry = {"name": part.name if len(part.matrices) == 1 else f"{part.name}.{i}", "mesh": mesh_id}
            nodes.append(b.node({**entry, **_trs_entry(t[i], q[i], s[i])}))
    for i in np.flatnonzero(~ok):      # shear: bake this copy into world space
        copy = _world_copy(part.mesh, part.matrices[i])
        mid = _mesh(b, copy, f"{part.name}.{i} (baked, non-TRS)", *mats, with_tangents=maps_of(part) is not None)
        nodes.append(b.node({"name": f"{part.name}.{i}", "mesh": mid}))
    return nodes


def gltf_document(scene: ExportScene, *, back_faces: str = "primitive", instancing: str = "auto",
                  instance_threshold: int = 16) -> tuple[dict[str, Any], bytes]:
    """The glTF JSON document and its binary buffer for ``scene`` (buffer URI not yet set)."""
    if back_faces not in BACK_FACES:
        raise UsageError(f"unknown back-face mode {back_faces!r} (use {', '.join(BACK_FACES)})")
    if instancing not in INSTANCING_MODES:
        raise UsageError(f"unknown instancing mode {instancing!r} (use {', '.join(INSTANCING_MODES)})")
    if not (np.isfinite(scene.length_m) and scene.length_m > 0):
        raise UsageError(f"length_m must be a positive number of metres, got {scene.length_m!r}")
    textures = with_maps(scene, scene_textures(scene))   # every image read and checked before anything is built
    b = _Builder()
    children: list[int] = []
    for k, (part, trs) in enumerate(zip(scene.parts, parts_trs(scene.parts))):
        mats = _leaf_materials(b, part, back_faces, textures.of(k))
        mesh_id = _mesh(b, part.mesh, part.name, *mats, with_tangents=maps_of(part) is not None)
        children += _place(b, part, trs, mesh_id, mats, instancing, instance_threshold)
    if scene.stems is not None:
        pos, nrm, idx = scene.stems
        bark = b.material("bark", BARK, 0.0, False, {"side": "bark"})
        stem_mesh = LeafMesh(pos, nrm, np.zeros((len(pos), 2), np.float32), np.zeros((len(pos), 2)), idx, "stems")
        check_mesh(stem_mesh)
        prim = {"attributes": {"POSITION": b.accessor(pos, bounds=True), "NORMAL": b.accessor(nrm)},
                "indices": b.indices(idx, len(pos)), "material": bark, "mode": 4}
        b.doc["meshes"].append({"name": "stems", "primitives": [prim]})
        children.append(b.node({"name": "stems", "mesh": len(b.doc["meshes"]) - 1}))

    root: dict[str, Any] = {"name": scene.name or "leafview", "rotation": Z_UP_TO_Y_UP}
    if scene.length_m != 1.0:
        root["scale"] = [float(scene.length_m)] * 3
    if children:
        root["children"] = children
    root_id = b.node(root)
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": f"leafview {__version__}"},
        "scene": 0,
        "scenes": [{"name": scene.name or "leafview", "nodes": [root_id]}],
        "extras": {"leafview": {"length_m": scene.length_m, "leaves": scene.n_leaves,
                                "note": "root node: leafview +z up -> glTF +y up, leaf lengths -> metres"}},
    }
    for key in ("nodes", "meshes", "materials", "textures", "images", "samplers", "accessors", "bufferViews"):
        if b.doc.get(key):
            doc[key] = b.doc[key]
    if b.used:
        doc["extensionsUsed"] = sorted(b.used)
    if b.required:
        doc["extensionsRequired"] = sorted(b.required)
    b.blob += b"\0" * (-len(b.blob) % 4)
    if b.blob:
        doc["buffers"] = [{"byteLength": len(b.blob)}]
    return doc, bytes(b.blob)


def _glb(doc: dict[str, Any], blob: bytes) -> bytes:
    text = json.dumps(doc, separators=(",", ":"), ensure_ascii=False).encode("utf-8")
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + (8 + len(blob) if blob else 0)
    if total > _MAX_GLB:
        raise UsageError(f"the GLB would be {total / 2**30:.1f} GiB, above the format's 4 GiB limit: "
                         "lower --resolution or export fewer leaves")
    out = bytearray(struct.pack("<4sII", b"glTF", 2, total))
    out += struct.pack("<II", len(text), 0x4E4F534A) + text
    if blob:
        out += struct.pack("<II", len(blob), 0x004E4942) + blob
    return bytes(out)


def write_gltf(scene: ExportScene, path: str | Path, **options: Any) -> Path:
    """Write ``scene`` to ``path`` (``.glb`` or ``.gltf``) atomically; returns the path.

    ``options``: ``back_faces`` (``"primitive"`` or ``"double-sided"``), ``instancing``
    (``"auto"``, ``"nodes"``, ``"ext"``) and ``instance_threshold`` (copies of one shape from
    which ``"auto"`` uses EXT_mesh_gpu_instancing, default 16).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".glb", ".gltf"):
        raise UsageError(f"{path}: a glTF file ends in .glb or .gltf")
    check_target(path)   # before building the document
    doc, blob = gltf_document(scene, **options)
    if suffix == ".glb":
        data = _glb(doc, blob)
    else:
        if blob:
            doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode("ascii")
        data = (json.dumps(doc, indent=1, ensure_ascii=False) + "\n").encode("utf-8")
    write_bytes(path, data)   # atomic, every byte checked
    return path
