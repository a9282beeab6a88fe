"""An independent check of the glTF extensions leafview writes (tests and tools only).

The Khronos glTF-Validator passes leafview's files but skips ``EXT_mesh_gpu_instancing`` and
``KHR_materials_diffuse_transmission`` (it reports them as ``UNSUPPORTED_EXTENSION``). This module
checks them instead, in two layers:

* every extension object is validated against its official JSON schema (draft-04), copied
  verbatim from KhronosGroup/glTF into ``tests/data/gltf_schemas/`` and resolved through an
  offline ``referencing`` registry (no network);
* the rules a schema cannot express, from the extension specifications and the core glTF 2.0
  specification: accessor types and component types of the instance attributes, equal counts,
  unit quaternions read from the binary data, accessor and buffer-view bounds and alignment,
  ``extensionsUsed``/``extensionsRequired``, texture references, placement (nodes or materials)
  and the extension's exclusions. ``docs/export_extensions.md`` lists each rule with its source.

``jsonschema`` is a test dependency, so it is imported only when :func:`check_extensions` runs.
Every problem names the JSON pointer of the offending value.
"""

from __future__ import annotations

import base64
import json
import math
import sys
from collections.abc import Iterator
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["CHECKED_EXTENSIONS", "SCHEMA_DIR", "check_extensions", "check_file", "main", "read_container"]

SCHEMA_DIR = Path(__file__).resolve().parents[2] / "tests" / "data" / "gltf_schemas"
INSTANCING = "EXT_mesh_gpu_instancing"
DIFFUSE = "KHR_materials_diffuse_transmission"
#: extension -> (schema file, the top-level array whose elements may carry it)
CHECKED_EXTENSIONS = {
    INSTANCING: ("glTF.EXT_mesh_gpu_instancing.schema.json", "nodes"),
    DIFFUSE: ("material.KHR_materials_diffuse_transmission.schema.json", "materials"),
}
_EXCLUDED_WITH_DIFFUSE = ("KHR_materials_pbrSpecularGlossiness", "KHR_materials_unlit")

_FLOAT, _BYTE, _UBYTE, _SHORT, _USHORT, _UINT = 5126, 5120, 5121, 5122, 5123, 5125
_COMPONENT = {_BYTE: np.int8, _UBYTE: np.uint8, _SHORT: np.int16, _USHORT: np.uint16, _UINT: np.uint32,
              _FLOAT: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_NAMES = {_BYTE: "BYTE", _UBYTE: "UNSIGNED_BYTE", _SHORT: "SHORT", _USHORT: "UNSIGNED_SHORT", _UINT: "UNSIGNED_INT",
          _FLOAT: "FLOAT"}
_ELEMENT_ARRAY_BUFFER = 34963
# the instance attribute table of the EXT_mesh_gpu_instancing specification:
# semantic -> (accessor type, allowed (componentType, normalized) pairs)
_INSTANCE_ATTRIBUTES = {
    "TRANSLATION": ("VEC3", {(_FLOAT, False)}),
    "ROTATION": ("VEC4", {(_FLOAT, False), (_BYTE, True), (_SHORT, True)}),
    "SCALE": ("VEC3", {(_FLOAT, False)}),
}
#: | |q| - 1 | allowed: float32 unit quaternions are good to ~1e-7; normalized integers are
#: quantised, so they get the glTF-Validator's own tolerance for node rotations (0.00769)
UNIT_TOLERANCE = {_FLOAT: 1e-5, _BYTE: 0.00769, _SHORT: 0.00769}


# -- schemas -----------------------------------------------------------------------------------
@lru_cache(maxsize=4)
def _validators(schema_dir: Path) -> dict[str, Any]:
    """One jsonschema validator per checked extension, with every ``*.schema.json`` of
    ``schema_dir`` in an offline registry under its file name (the extension schemas ``$ref``
    core schemas by relative file name)."""
    from jsonschema.validators import validator_for
    from referencing import Registry, Resource
    from referencing.jsonschema import DRAFT4

    if not schema_dir.is_dir():
        raise FileNotFoundError(f"{schema_dir}: the glTF extension schemas are not there "
                                "(they ship in a source checkout under tests/data/gltf_schemas)")
    contents = {p.name: json.loads(p.read_text(encoding="utf-8")) for p in sorted(schema_dir.glob("*.schema.json"))}
    registry: Registry = Registry().with_resources(
        (name, Resource.from_contents(schema, default_specification=DRAFT4)) for name, schema in contents.items())
    out = {}
    for ext, (filename, _) in CHECKED_EXTENSIONS.items():
        schema = contents[filename]
        cls = validator_for(schema)
        cls.check_schema(schema)
        out[ext] = cls(schema, registry=registry)
    return out


def _schema_problems(validator: Any, value: Any, where: str, filename: str) -> list[str]:
    out = []
    for err in sorted(validator.iter_errors(value), key=lambda e: list(map(str, e.absolute_path))):
        path = "".join(f"/{p}" for p in err.absolute_path)
        out.append(f"{where}{path}: {err.message} (schema {filename})")
    return out


# -- walking the document --------------------------------------------------------------------
def _extension_objects(node: Any, pointer: str = "") -> Iterator[tuple[str, str, Any]]:
    """``(owner pointer, extension name, value)`` for every ``extensions`` dictionary in the
    document; ``extras`` are application data and are not searched."""
    if isinstance(node, dict):
        exts = node.get("extensions")
        if isinstance(exts, dict):
            for name, value in exts.items():
                yield pointer, name, value
        for key, value in node.items():
            if key != "extras":
                yield from _extension_objects(value, f"{pointer}/{key}")
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _extension_objects(value, f"{pointer}/{i}")


def _get(doc: dict[str, Any], key: str, index: Any) -> Any:
    items = doc.get(key)
    if isinstance(index, int) and not isinstance(index, bool) and isinstance(items, list) and 0 <= index < len(items):
        return items[index]
    return None


# -- accessor data -------------------------------------------------------------------------------
def _accessor_data(doc: dict[str, Any], buffers: list[bytes | None], index: int,
                   where: str) -> tuple[NDArray[np.float64] | None, list[str]]:
    """Accessor ``index`` decoded to (count, width) float64 (normalized integers mapped to
    [-1, 1] as glTF 2.0 §3.11 says), and the layout problems found on the way (glTF 2.0 §3.6.2:
    alignment, byteStride, bounds)."""
    acc = _get(doc, "accessors", index)
    if acc is None:
        return None, [f"{where}: accessor {index} does not exist"]
    ctype, atype, count = acc.get("componentType"), acc.get("type"), acc.get("count")
    if ctype not in _COMPONENT or atype not in _WIDTH or not isinstance(count, int) or count < 1:
        return None, [f"{where}: accessor {index} has componentType {ctype}, type {atype}, count {count}"]
    if "sparse" in acc:
        return None, [f"{where}: accessor {index} is sparse; this checker does not decode sparse data"]
    dtype = np.dtype(_COMPONENT[ctype]).newbyteorder("<")
    width = _WIDTH[atype]
    element = dtype.itemsize * width
    acc_at = f"/accessors/{index}"
    if "bufferView" not in acc:                        # all zeros (glTF 2.0 §3.6.2.1)
        data = np.zeros((count, width))
        return data, []
    problems = []
    view = _get(doc, "bufferViews", acc["bufferView"])
    if view is None:
        return None, [f"{acc_at}/bufferView: buffer view {acc['bufferView']} does not exist"]
    view_at = f"/bufferViews/{acc['bufferView']}"
    acc_off, view_off = acc.get("byteOffset", 0), view.get("byteOffset", 0)
    if acc_off % dtype.itemsize or (acc_off + view_off) % dtype.itemsize:
        problems.append(f"{acc_at}/byteOffset: offset {acc_off} (+ view {view_off}) is not a multiple of the "
                        f"component size {dtype.itemsize}")
    stride = view.get("byteStride", element)
    if "byteStride" in view and (stride < element or stride % 4 or not 4 <= stride <= 252):
        problems.append(f"{view_at}/byteStride: {stride} for {count} elements of {element} bytes "
                        "(must be ≥ the element size, a multiple of 4, in 4..252)")
        stride = max(stride, element)
    if view.get("target") == _ELEMENT_ARRAY_BUFFER:
        problems.append(f"{view_at}/target: an instance attribute in an ELEMENT_ARRAY_BUFFER view")
    end = acc_off + stride * (count - 1) + element
    if end > view.get("byteLength", 0):
        problems.append(f"{acc_at}: {count} elements end at byte {end} of buffer view {acc['bufferView']}, "
                        f"which is {view.get('byteLength', 0)} bytes long")
    buf_index = view.get("buffer", 0)
    buffer = _get(doc, "buffers", buf_index)
    blob = buffers[buf_index] if isinstance(buf_index, int) and 0 <= buf_index < len(buffers) else None
    if buffer is None or blob is None:
        return None, problems + [f"{view_at}/buffer: buffer {buf_index} is not available to the checker"]
    if view_off + view.get("byteLength", 0) > buffer.get("byteLength", 0):
        problems.append(f"{view_at}: ends at byte {view_off + view.get('byteLength', 0)}, past buffer "
                        f"{buf_index}'s byteLength {buffer.get('byteLength', 0)}")
    if buffer.get("byteLength", 0) > len(blob):
        problems.append(f"/buffers/{buf_index}/byteLength: {buffer.get('byteLength')} but only {len(blob)} "
                        "bytes of data")
    if problems:
        return None, problems
    raw = np.frombuffer(blob, dtype=np.uint8, count=stride * (count - 1) + element, offset=view_off + acc_off)
    rows = np.lib.stride_tricks.as_strided(raw, shape=(count, element), strides=(stride, 1))
    data = np.ascontiguousarray(rows).view(dtype).reshape(count, width).astype(np.float64)
    if acc.get("normalized") and ctype != _FLOAT:
        data = np.maximum(data / float(np.iinfo(dtype).max), -1.0)
    for key, reduce in (("min", np.min), ("max", np.max)):
        if key in acc and len(acc[key]) == width and not np.allclose(acc[key], reduce(data, axis=0), rtol=0,
                                                                     atol=1e-6 * max(1.0, np.abs(data).max())):
            problems.append(f"{acc_at}/{key}: {acc[key]} but the data give {reduce(data, axis=0).tolist()}")
    return data, problems


# -- the extensions -------------------------------------------------------------------------------
def _kind(ctype: Any, normalized: bool) -> str:
    return f"{_NAMES.get(ctype, ctype)}{' normalized' if normalized else ''}"


def _check_instancing(doc: dict[str, Any], buffers: list[bytes | None], owner: str, ext: Any) -> list[str]:
    """EXT_mesh_gpu_instancing on ``owner`` (a node): the attribute table, equal counts, a mesh,
    unit rotations, finite values, ``extensionsRequired``."""
    where = f"{owner}/extensions/{INSTANCING}"
    node = _get(doc, "nodes", int(owner.rsplit("/", 1)[1]))
    problems = []
    if "mesh" not in node:
        problems.append(f"{owner}: has {INSTANCING} but no mesh (the extension applies to mesh nodes only)")
    if INSTANCING not in doc.get("extensionsRequired", []):
        problems.append(f"/extensionsRequired: lacks {INSTANCING}; files using it should require it, since "
                        "it has no non-instanced fallback")
    attrs = ext.get("attributes") if isinstance(ext, dict) else None
    if not isinstance(attrs, dict):
        return problems
    counts: dict[str, int] = {}
    for name, index in attrs.items():
        at = f"{where}/attributes/{name}"
        if name not in _INSTANCE_ATTRIBUTES and not name.startswith("_"):
            problems.append(f"{at}: unknown instance attribute (use TRANSLATION, ROTATION, SCALE or an "
                            "application-specific name starting with '_')")
        acc = _get(doc, "accessors", index)
        if acc is None:
            problems.append(f"{at}: accessor {index} does not exist")
            continue
        counts[name] = acc.get("count")
        if name not in _INSTANCE_ATTRIBUTES:
            continue
        want_type, allowed = _INSTANCE_ATTRIBUTES[name]
        ctype, normalized = acc.get("componentType"), bool(acc.get("normalized", False))
        if acc.get("type") != want_type or (ctype, normalized) not in allowed:
            kinds = " or ".join(_kind(c, n) for c, n in sorted(allowed, reverse=True))
            problems.append(f"{at}: accessor {index} is {acc.get('type')} of {_kind(ctype, normalized)}; "
                            f"{name} must be {want_type} of {kinds}")
            continue
        data, layout = _accessor_data(doc, buffers, index, at)
        problems += layout
        if data is None:
            continue
        bad = ~np.isfinite(data).all(axis=1)
        if bad.any():
            problems.append(f"{at}: accessor {index} element {int(np.argmax(bad))} is not finite")
        elif name == "ROTATION":
            err = np.abs(np.linalg.norm(data, axis=1) - 1.0)
            if err.max() > UNIT_TOLERANCE[ctype]:
                i = int(np.argmax(err))
                problems.append(f"{at}: accessor {index} element {i} is not a unit quaternion "
                                f"(|q| = {np.linalg.norm(data[i]):.7f}; {int((err > UNIT_TOLERANCE[ctype]).sum())} "
                                f"of {len(data)} off by more than {UNIT_TOLERANCE[ctype]})")
    if len(set(counts.values())) > 1:
        problems.append(f"{where}/attributes: accessor counts differ ({', '.join(f'{k} {v}' for k, v in counts.items())}); "
                        "all attribute accessors of a node must have the same count")
    return problems


def _material_primitives(doc: dict[str, Any], material: int) -> Iterator[tuple[str, dict[str, Any]]]:
    for m, mesh in enumerate(doc.get("meshes", [])):
        for p, prim in enumerate(mesh.get("primitives", [])):
            if prim.get("material") == material:
                yield f"/meshes/{m}/primitives/{p}", prim


def _check_diffuse(doc: dict[str, Any], owner: str, ext: Any) -> list[str]:
    """KHR_materials_diffuse_transmission on ``owner`` (a material): finite factors, textures that
    exist, texture coordinates the meshes have, no excluded extension beside it."""
    where = f"{owner}/extensions/{DIFFUSE}"
    material_index = int(owner.rsplit("/", 1)[1])
    material = _get(doc, "materials", material_index)
    problems = [f"{owner}/extensions/{other}: must not be used together with {DIFFUSE}"
                for other in _EXCLUDED_WITH_DIFFUSE if other in material.get("extensions", {})]
    if not isinstance(ext, dict):
        return problems
    factor = ext.get("diffuseTransmissionFactor", 0.0)
    if isinstance(factor, float) and not math.isfinite(factor):       # NaN passes the schema's bounds
        problems.append(f"{where}/diffuseTransmissionFactor: {factor} is not a finite number in [0, 1]")
    colour = ext.get("diffuseTransmissionColorFactor", [1.0, 1.0, 1.0])
    if isinstance(colour, list) and any(isinstance(c, float) and not math.isfinite(c) for c in colour):
        problems.append(f"{where}/diffuseTransmissionColorFactor: {colour} has a non-finite component")
    for key in ("diffuseTransmissionTexture", "diffuseTransmissionColorTexture"):
        info = ext.get(key)
        if not isinstance(info, dict) or "index" not in info:
            continue
        if _get(doc, "textures", info["index"]) is None:
            problems.append(f"{where}/{key}/index: texture {info['index']} does not exist "
                            f"(the file has {len(doc.get('textures', []))} textures)")
        coord = f"TEXCOORD_{info.get('texCoord', 0)}"
        for at, prim in _material_primitives(doc, material_index):
            if coord not in prim.get("attributes", {}):
                problems.append(f"{where}/{key}/texCoord: {at} uses this material but has no {coord}")
    return problems


# -- entry points --------------------------------------------------------------------------------
def check_extensions(gltf_json: dict[str, Any] | str | bytes, bin_chunk: bytes | None = None, *,
                     schema_dir: str | Path | None = None) -> list[str]:
    """Problems of the checked extensions in a glTF document; an empty list means none found.

    Parameters
    ----------
    gltf_json : dict, str or bytes
        The glTF JSON (parsed or as text).
    bin_chunk : bytes, optional
        The data of buffer 0: a GLB's BIN chunk, or the decoded data URI of a ``.gltf``.
        Instance attributes in other buffers are reported as not available.
    schema_dir : path, optional
        Folder with the extension and core schemas (default :data:`SCHEMA_DIR`).

    Returns
    -------
    list of str
        One line per problem, starting with the JSON pointer of the offending value.
    """
    doc = json.loads(gltf_json) if isinstance(gltf_json, (str, bytes)) else gltf_json
    if not isinstance(doc, dict):
        return ["/: a glTF document is a JSON object"]
    validators = _validators(Path(schema_dir) if schema_dir is not None else SCHEMA_DIR)
    buffers: list[bytes | None] = [bin_chunk] + [None] * max(0, len(doc.get("buffers", [])) - 1)
    used, required = doc.get("extensionsUsed", []), doc.get("extensionsRequired", [])
    problems = [f"/extensionsRequired/{i}: {name} is required but not in extensionsUsed"
                for i, name in enumerate(required) if name not in used]
    problems += [f"/extensionsUsed/{i}: {name} is listed twice" for i, name in enumerate(used)
                 if name in used[:i]]
    for owner, name, ext in _extension_objects(doc):
        where = f"{owner}/extensions/{name}"
        if name not in used:
            problems.append(f"{where}: {name} is used but not listed in extensionsUsed")
        if name not in CHECKED_EXTENSIONS:
            continue
        filename, home = CHECKED_EXTENSIONS[name]
        parent, _, index = owner.rpartition("/")
        if parent != f"/{home}" or not index.isdigit():
            problems.append(f"{where}: {name} belongs on {home}, not on {owner or '/'}")
            continue
        schema_found = _schema_problems(validators[name], ext, where, filename)
        problems += schema_found
        if schema_found:
            continue
        if name == INSTANCING:
            problems += _check_instancing(doc, buffers, owner, ext)
        else:
            problems += _check_diffuse(doc, owner, ext)
    return list(dict.fromkeys(problems))      # one line per problem, even if several nodes share it


def read_container(path: str | Path) -> tuple[dict[str, Any], bytes | None]:
    """(JSON document, buffer 0's data) of a ``.glb``, or of a ``.gltf`` with a base64 data URI."""
    data = Path(path).read_bytes()
    if data[:4] == b"glTF":
        jlen = int.from_bytes(data[12:16], "little")
        doc = json.loads(data[20:20 + jlen])
        at = 20 + jlen
        blob = data[at + 8:at + 8 + int.from_bytes(data[at:at + 4], "little")] if at + 8 <= len(data) else None
        return doc, blob
    doc = json.loads(data)
    uri = (doc.get("buffers") or [{}])[0].get("uri", "")
    return doc, base64.b64decode(uri.split(",", 1)[1]) if uri.startswith("data:") else None


def check_file(path: str | Path, **kwargs: Any) -> list[str]:
    """:func:`check_extensions` of a ``.glb`` or ``.gltf`` file."""
    doc, blob = read_container(path)
    return check_extensions(doc, blob, **kwargs)


def main(argv: list[str] | None = None) -> int:
    """``python -m support.gltf_extensions FILE...``: the problems of each file; exit 1 if any."""
    files = sys.argv[1:] if argv is None else argv
    bad = 0
    for name in files:
        doc, blob = read_container(name)
        problems = check_extensions(doc, blob)
        found = sorted(n for n in CHECKED_EXTENSIONS if n in doc.get("extensionsUsed", []))
        print(f"{name}: {len(problems)} problems in {', '.join(found) or 'no checked extension'}")
        for p in problems:
            print(f"  {p}")
        bad += bool(problems)
    return 1 if bad else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
