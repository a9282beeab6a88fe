"""The README's promise as code: what a finished ``leafview`` run may print and leave behind.

Shared by the property-based tests (``tests/fuzz/``) and the hostile-case rerun
(``tools/hostile_cases.py``). The promise: exit 0 with complete output files, or exit 1/2 with
exactly one line on stderr naming the file and field, and nothing written. Never a traceback,
never a hang. Concretely, :func:`stream_problems`, :func:`tree_problems` and
:func:`file_problem` return what a run broke, as short sentences (an empty list: kept).

* **One line.** argparse's own refusals print a ``usage:`` block before the error line; that
  block is allowed (it is the standard form of a bad-argument message), the error line after it
  must be the only other line. The line starts with ``leafview``, is at most
  :data:`MAX_ERROR_LINE` characters and names what the test says it must name (the input file).
* **Nothing written** on a refusal: no new or changed file anywhere in the sandbox (empty
  folders are tolerated). On success: new files only under the output folder.
* **No leftovers**: no temporary or partial file (``.NAME.XXXX.part.EXT`` or any dot-file)
  after any run.
* **Complete files**: every file a successful run wrote reads back with an independent reader
  (OpenImageIO, a glTF/GLB reader, OBJ/PLY parsers, USD, JSON/TOML and leafview's own loaders)
  and holds finite numbers only.
"""

from __future__ import annotations

import base64
import json
import math
import os
import re
import stat
import struct
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pxr import Usd

from leafview.core.io import load_leaves
from leafview.export.images import read_image
from leafview.scene.spec import load_scene

__all__ = ["MAX_ERROR_LINE", "Entry", "snapshot", "tree_problems", "stream_problems", "error_line",
           "file_problem", "image_coverage", "is_temp_name", "non_finite_path"]

MAX_ERROR_LINE = 1000    # characters: an error that quotes a 10⁵-character field is not a readable line
_TEMP = re.compile(r"^\.|\.part(\.|$)|\.tmp$|~$")
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".exr")


# -- the sandbox ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Entry:
    """One path of a sandbox as :func:`snapshot` saw it (``lstat``: links are not followed)."""

    kind: str          # file, dir, link, fifo, char, block, socket
    size: int
    mtime_ns: int
    ino: int
    target: str = ""   # a link's target


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISREG, "file"), (stat.S_ISDIR, "dir"), (stat.S_ISLNK, "link"),
                       (stat.S_ISFIFO, "fifo"), (stat.S_ISCHR, "char"), (stat.S_ISBLK, "block"),
                       (stat.S_ISSOCK, "socket")):
        if test(mode):
            return name
    return "other"


def snapshot(root: str | os.PathLike[str]) -> dict[str, Entry]:
    """Every path under ``root`` (relative, '/'-separated) with its kind, size and mtime."""
    out: dict[str, Entry] = {}
    base = os.fspath(root)
    for dirpath, dirnames, filenames in os.walk(base, followlinks=False):
        for name in [*dirnames, *filenames]:
            full = os.path.join(dirpath, name)
            try:
                st = os.lstat(full)
            except OSError:
                continue
            kind = _kind(st.st_mode)
            target = os.readlink(full) if kind == "link" else ""
            out[os.path.relpath(full, base)] = Entry(kind, st.st_size if kind == "file" else 0, st.st_mtime_ns,
                                                    st.st_ino, target)
    return out


def is_temp_name(rel: str) -> bool:
    """A temporary or partial file's name (``.x.abcd.part.png``, a dot-file, ``x.tmp``)."""
    return bool(_TEMP.search(os.path.basename(rel)))


def _under(rel: str, folder: str) -> bool:
    return folder in ("", ".") or rel == folder or rel.startswith(folder.rstrip("/") + "/")


def tree_problems(before: dict[str, Entry], after: dict[str, Entry], *, out: str | tuple[str, ...],
                  success: bool, keep: tuple[str, ...] = ()) -> tuple[list[str], list[str]]:
    """(problems, written): what a run changed in its sandbox, judged by the promise. ``out`` is
    the output folder (or folders), relative to the sandbox; ``keep`` are paths the test changes
    itself. ``written`` lists the new or changed regular files under ``out`` (to be read back)."""
    outs = (out,) if isinstance(out, str) else out
    problems: list[str] = []
    written: list[str] = []
    for rel, entry in sorted(after.items()):
        old = before.get(rel)
        if old == entry or rel in keep or (entry.kind == "dir" and (old is None or old.kind == "dir")):
            continue
        inside = any(_under(rel, o) for o in outs)
        if old is not None and old.kind != entry.kind:
            problems.append(f"replaced the {old.kind} {rel} with a {entry.kind}")
            continue
        if old is not None and old.kind == "link" and old.target != entry.target:
            problems.append(f"changed the link {rel}")
            continue
        if is_temp_name(rel):
            problems.append(f"left a temporary file {rel}")
        elif not inside:
            problems.append(f"wrote {rel} outside the output folder")
        elif not success:
            problems.append(f"a failed run left {rel}")
        elif entry.kind == "file":
            written.append(rel)
        elif entry.kind != "dir":
            problems.append(f"created the {entry.kind} {rel}")
    for rel in sorted(set(before) - set(after)):   # removing a stale temporary file is fine
        if rel not in keep and not any(rel.startswith(k + "/") for k in keep) and not is_temp_name(rel):
            problems.append(f"removed {rel}")
    return problems, written


# -- the streams ----------------------------------------------------------------------------------
def error_line(stderr: str) -> tuple[str | None, int]:
    """(the error line, how many lines besides argparse's usage block) of a refusal's stderr."""
    lines = [line for line in stderr.splitlines() if line.strip()]
    if lines and lines[0].startswith("usage:"):
        i = 1
        while i < len(lines) and lines[i].startswith(" "):
            i += 1
        lines = lines[i:]
    return (lines[0] if len(lines) == 1 else None), len(lines)


def stream_problems(code: int | None, stdout: str, stderr: str, *, must_name: tuple[str, ...] = ()) -> list[str]:
    """What the exit code and the two streams break: a traceback, an exit code other than
    0/1/2, and on a refusal anything but one short ``leafview ...`` line (naming ``must_name``,
    any of them, when given)."""
    problems: list[str] = []
    if "Traceback (most recent call last)" in stderr or "Traceback (most recent call last)" in stdout:
        problems.append("printed a Python traceback")
    if code not in (0, 1, 2):
        problems.append(f"exit code {code} (expected 0, 1 or 2)")
        return problems
    if code == 0:
        return problems
    line, count = error_line(stderr)
    if line is None:
        shown = " | ".join(s[:160] for s in stderr.splitlines()[-4:]) or "nothing"
        problems.append(f"{count} lines on stderr, expected one error line: {shown}")
        return problems
    if len(line) > MAX_ERROR_LINE:
        problems.append(f"an error line of {len(line):,} characters")
    if not line.startswith("leafview"):
        problems.append(f"the error line does not start with 'leafview': {line[:200]}")
    if must_name and not any(n and n in line for n in must_name):
        problems.append(f"the error line names none of {', '.join(repr(n[:60]) for n in must_name)}: {line[:300]}")
    return problems


# -- the files ------------------------------------------------------------------------------------
def non_finite_path(value: Any, path: str = "") -> str | None:
    """The path of the first NaN/Inf in a parsed JSON/TOML document, or None."""
    if isinstance(value, float) and not math.isfinite(value):
        return path or "(top)"
    if isinstance(value, dict):
        for k, v in value.items():
            found = non_finite_path(v, f"{path}.{k}" if path else str(k))
            if found:
                return found
    if isinstance(value, list):
        for i, v in enumerate(value):
            found = non_finite_path(v, f"{path}[{i}]")
            if found:
                return found
    return None


def _strict_json(data: bytes) -> Any:
    def refuse(token: str) -> Any:
        raise ValueError(f"non-finite JSON number {token}")
    return json.loads(data.decode("utf-8"), parse_constant=refuse)


def _finite(arr: Any, what: str) -> None:
    a = np.asarray(arr)
    if a.dtype.kind in "fc" and not np.isfinite(a).all():
        raise ValueError(f"non-finite {what}")


def image_coverage(path: str | os.PathLike[str]) -> float:
    """The fraction of an image's pixels with alpha > 0 (0.0: a blank image)."""
    pixels, _ = read_image(path)
    return float((np.asarray(pixels)[..., -1] > 0).mean())


def _check_image(path: Path) -> None:
    pixels, _ = read_image(path)
    a = np.asarray(pixels)
    if a.ndim != 3 or a.shape[0] < 1 or a.shape[1] < 1 or a.shape[2] not in (1, 2, 3, 4):   # 1, 2: dataset labels
        raise ValueError(f"unexpected pixel array {a.shape}")
    _finite(a, "pixels")


def _gltf_document(path: Path) -> tuple[dict[str, Any], bytes]:
    data = path.read_bytes()
    if path.suffix.lower() == ".gltf":
        doc = _strict_json(data)
        blobs = []
        for buf in doc.get("buffers", []):
            uri = buf.get("uri", "")
            if not uri.startswith("data:"):
                raise ValueError(f"external buffer {uri[:60]!r}")
            blobs.append(base64.b64decode(uri.split(",", 1)[1]))
        if len(blobs) > 1:
            raise ValueError("several buffers")
        return doc, blobs[0] if blobs else b""
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF" or version != 2:
        raise ValueError("not a GLB 2 file")
    if length != len(data):
        raise ValueError(f"GLB header says {length} bytes, the file has {len(data)}")
    offset, doc, blob = 12, None, b""
    while offset < len(data):
        size, kind = struct.unpack_from("<I4s", data, offset)
        chunk = data[offset + 8: offset + 8 + size]
        if len(chunk) != size:
            raise ValueError("truncated GLB chunk")
        if kind == b"JSON":
            doc = _strict_json(chunk)
        elif kind == b"BIN\x00":
            blob = chunk
        offset += 8 + size
    if doc is None:
        raise ValueError("GLB without a JSON chunk")
    return doc, blob


_GLTF_TYPES = {5126: "<f4", 5125: "<u4", 5123: "<u2", 5121: "u1"}
_GLTF_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _check_gltf(path: Path) -> None:
    doc, blob = _gltf_document(path)
    views = doc.get("bufferViews", [])
    for i, acc in enumerate(doc.get("accessors", [])):
        view = views[acc["bufferView"]]
        dtype = np.dtype(_GLTF_TYPES[acc["componentType"]])
        n = acc["count"] * _GLTF_WIDTH[acc["type"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        if start + n * dtype.itemsize > len(blob):
            raise ValueError(f"accessor {i} runs past the end of the buffer")
        arr = np.frombuffer(blob, dtype=dtype, count=n, offset=start)
        _finite(arr, f"accessor {i}")
    bad = non_finite_path(doc)
    if bad:
        raise ValueError(f"non-finite number at {bad}")


def _check_obj(path: Path) -> None:
    counts = {"v": 0, "vn": 0, "vt": 0}
    faces: list[list[str]] = []
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        if parts[0] in counts:
            values = [float(x) for x in parts[1:]]
            if not values or not all(math.isfinite(x) for x in values):
                raise ValueError(f"line {n}: non-finite or empty {parts[0]}")
            counts[parts[0]] += 1
        elif parts[0] == "f":
            faces.append(parts[1:])
    for face in faces:
        for corner in face:
            for idx, key in zip(corner.split("/"), ("v", "vt", "vn")):
                if idx:
                    k = int(idx)
                    if k == 0 or abs(k) > counts[key]:
                        raise ValueError(f"face index {corner} out of range")


_PLY_TYPES = {"char": "i1", "uchar": "u1", "short": "<i2", "ushort": "<u2", "int": "<i4", "uint": "<u4",
              "float": "<f4", "double": "<f8", "int8": "i1", "uint8": "u1", "int32": "<i4", "uint32": "<u4",
              "float32": "<f4", "float64": "<f8"}


def _check_ply(path: Path) -> None:
    data = path.read_bytes()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise ValueError("no PLY header")
    header = data[:end].decode("ascii").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise ValueError("not binary little-endian PLY")
    elements: list[tuple[str, int, list[list[str]]]] = []
    for line in header:
        parts = line.split()
        if parts[:1] == ["element"]:
            elements.append((parts[1], int(parts[2]), []))
        elif parts[:1] == ["property"]:
            elements[-1][2].append(parts[1:])
    offset = end + len(b"end_header\n")
    for name, count, props in elements:
        if all(p[0] != "list" for p in props):
            dtype = np.dtype([(p[1], _PLY_TYPES[p[0]]) for p in props])
            if offset + count * dtype.itemsize > len(data):
                raise ValueError(f"truncated PLY element {name}")
            arr = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
            for field in dtype.names or ():
                _finite(arr[field], f"{name}.{field}")
            offset += count * dtype.itemsize
        else:
            (kind, count_t, item_t, _), = props
            ct, it = np.dtype(_PLY_TYPES[count_t]), np.dtype(_PLY_TYPES[item_t])
            for _ in range(count):
                k = int(np.frombuffer(data, ct, 1, offset)[0])
                offset += ct.itemsize + k * it.itemsize
                if offset > len(data):
                    raise ValueError(f"truncated PLY element {name}")
    if offset != len(data):
        raise ValueError(f"PLY has {len(data) - offset} bytes after its last element")


def _check_usd(path: Path) -> None:
    stage = Usd.Stage.Open(str(path))
    if stage is None:
        raise ValueError("USD cannot open the stage")
    for prim in stage.Traverse():
        for attr in prim.GetAttributes():
            value = attr.Get()
            if value is None or isinstance(value, (str, bool)):
                continue
            try:
                arr = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError):
                continue
            if not np.isfinite(arr).all():
                raise ValueError(f"non-finite {prim.GetPath()}.{attr.GetName()}")


def _check_document(path: Path) -> None:
    data = path.read_bytes()
    name = path.name.lower()
    if name.endswith(".json"):
        doc = _strict_json(data)
    else:
        doc = tomllib.loads(data.decode("utf-8"))
        bad = non_finite_path(doc)
        if bad:
            raise ValueError(f"non-finite number at {bad}")
    if not isinstance(doc, dict):
        return
    if "species" in doc:
        load_scene(path)
    elif "format" in doc and "arguments" in doc:   # a dataset's manifest (dataset.json)
        return
    elif "leafview" in doc or "schema" in doc and "shape" in doc:
        load_leaves(path)


def _check_mtl(path: Path) -> None:
    """An OBJ material library: text with at least one material, every image it names beside it."""
    lines = path.read_text(encoding="utf-8").splitlines()
    if not any(line.startswith("newmtl ") for line in lines):
        raise ValueError("no newmtl")
    for line in lines:
        if line.startswith(("map_Kd ", "map_Bump ")):
            image = path.parent / line.split()[-1]
            if not image.is_file():
                raise ValueError(f"{line.split()[0]} names {image.name}, which is not there")


def file_problem(path: str | os.PathLike[str]) -> str | None:
    """Why the file a successful run wrote is not complete (None: it reads back, finite)."""
    p = Path(path)
    suffix = p.suffix.lower()
    try:
        if p.stat().st_size == 0:
            return f"{p.name}: empty file"
        if suffix in IMAGE_SUFFIXES:
            _check_image(p)
        elif suffix in (".glb", ".gltf"):
            _check_gltf(p)
        elif suffix == ".obj":
            _check_obj(p)
        elif suffix == ".ply":
            _check_ply(p)
        elif suffix == ".mtl":
            _check_mtl(p)
        elif suffix in (".usda", ".usdc", ".usd"):
            _check_usd(p)
        elif suffix in (".json", ".toml"):
            _check_document(p)
        elif suffix == ".txt":   # a dataset's split lists: file stems, one a line
            p.read_text(encoding="utf-8")
        else:
            return f"{p.name}: a file of unexpected type"
    except Exception as exc:   # any failure to read back is the finding
        return f"{p.name}: does not read back ({type(exc).__name__}: {str(exc)[:200]})"
    return None
