"""A small glTF 2.0 reader for what :mod:`leafview.export.gltf` writes (tests, benchmark, tools).

It reads ``.glb`` and ``.gltf`` (embedded data URI) files, decodes accessors (tightly packed,
float / unsigned short / unsigned int) and walks the node tree into world matrices, including
``EXT_mesh_gpu_instancing`` instances. It is not a general importer (no sparse accessors, no
external buffers, no strides, no animations).
"""

from __future__ import annotations

import base64
import json
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.export.scene import compose_trs

__all__ = ["GltfFile", "read_gltf"]

_DTYPES = {5126: np.float32, 5123: np.uint16, 5125: np.uint32, 5121: np.uint8}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


@dataclass
class GltfFile:
    doc: dict[str, Any]
    blob: bytes

    def accessor(self, index: int) -> NDArray[Any]:
        """Accessor ``index`` as an (count, width) array (width 1 squeezed)."""
        acc = self.doc["accessors"][index]
        view = self.doc["bufferViews"][acc["bufferView"]]
        if "byteStride" in view:
            raise ValueError("strided buffer views are not supported by this reader")
        dtype = np.dtype(_DTYPES[acc["componentType"]]).newbyteorder("<")
        width = _WIDTH[acc["type"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        data = np.frombuffer(self.blob, dtype=dtype, count=acc["count"] * width, offset=start)
        return data.reshape(acc["count"], width) if width > 1 else data

    def node_matrix(self, node: dict[str, Any]) -> NDArray[np.float64]:
        if "matrix" in node:
            return np.asarray(node["matrix"], np.float64).reshape(4, 4).T
        return compose_trs(np.asarray(node.get("translation", [0, 0, 0]), np.float64),
                           np.asarray(node.get("rotation", [0, 0, 0, 1]), np.float64),
                           np.asarray(node.get("scale", [1, 1, 1]), np.float64))

    def mesh_instances(self) -> Iterator[tuple[int, NDArray[np.float64], str]]:
        """``(mesh index, world matrix (4, 4), node name)`` for every drawn copy of a mesh."""
        scene = self.doc["scenes"][self.doc.get("scene", 0)]
        stack = [(i, np.eye(4)) for i in scene["nodes"]]
        while stack:
            i, parent = stack.pop()
            node = self.doc["nodes"][i]
            world = parent @ self.node_matrix(node)
            if "mesh" in node:
                ext = node.get("extensions", {}).get("EXT_mesh_gpu_instancing")
                if ext is None:
                    yield node["mesh"], world, node.get("name", "")
                else:
                    attrs = ext["attributes"]
                    t = self.accessor(attrs["TRANSLATION"]).astype(np.float64)
                    q = self.accessor(attrs["ROTATION"]).astype(np.float64)
                    s = self.accessor(attrs["SCALE"]).astype(np.float64)
                    for m in compose_trs(t, q, s):
                        yield node["mesh"], world @ m, node.get("name", "")
            stack.extend((c, world) for c in node.get("children", []))


def read_gltf(path: str | Path) -> GltfFile:
    """Parse a ``.glb`` or a ``.gltf`` with an embedded buffer."""
    data = Path(path).read_bytes()
    if data[:4] == b"glTF":
        _, version, length = struct.unpack_from("<4sII", data, 0)
        if version != 2 or length != len(data):
            raise ValueError(f"{path}: GLB header says version {version}, {length} bytes; file has {len(data)}")
        jlen, jtype = struct.unpack_from("<II", data, 12)
        if jtype != 0x4E4F534A:
            raise ValueError(f"{path}: first GLB chunk is not JSON")
        doc = json.loads(data[20:20 + jlen])
        blob = b""
        at = 20 + jlen
        if at < len(data):
            blen, btype = struct.unpack_from("<II", data, at)
            if btype != 0x004E4942:
                raise ValueError(f"{path}: second GLB chunk is not BIN")
            blob = data[at + 8:at + 8 + blen]
        return GltfFile(doc, blob)
    doc = json.loads(data)
    blob = b""
    if doc.get("buffers"):
        uri = doc["buffers"][0]["uri"]
        prefix = "data:application/octet-stream;base64,"
        if not uri.startswith(prefix):
            raise ValueError(f"{path}: only embedded buffers are supported")
        blob = base64.b64decode(uri[len(prefix):])
    return GltfFile(doc, blob)
