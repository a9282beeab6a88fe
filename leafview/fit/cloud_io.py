"""Reading one leaf's point cloud: PLY (ascii, binary little and big endian), text (xyz, txt, csv,
pts) and numpy ``.npy`` files, and the checks every cloud passes before a fit.

Every error is a :class:`~leafview.errors.ParamError` (bad content) or
:class:`~leafview.errors.UsageError` (an extension leafview does not read) whose message starts with
``PATH:LINE:`` where a line is known (text files and ASCII PLY) or ``PATH:`` otherwise, and says
what is wrong. Files are read through :func:`leafview.inputs.read_bytes` (regular files only, size
limit), nothing is written.

Formats:

* **PLY.** The header must start with ``ply`` and a ``format`` line and end with ``end_header``;
  ``comment`` and ``obj_info`` lines are skipped. The ``vertex`` element must have ``x``, ``y`` and
  ``z`` properties of any numeric type; its other properties (normals, colours, ...) and every
  other element (faces, edges, ...) are skipped, list properties included, in all three formats
  (in binary files the elements after the vertices are not read at all).
* **Text** (``.xyz``, ``.txt``, ``.csv``, ``.pts``). One point a line, at least three numbers
  separated by commas, spaces, tabs or semicolons; the first three are x, y, z and further columns
  are ignored. ``#`` starts a comment; blank lines are skipped; the first content line may be a
  header (text, or a lone point count as in ``.pts`` files) and is skipped.
* **NumPy** (``.npy``). An (N, k) array with k >= 3 of a real or integer type; the first three
  columns are x, y, z.
"""

from __future__ import annotations

import io
import os
import re
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.errors import ParamError, UsageError
from leafview.inputs import read_bytes

__all__ = ["MIN_POINTS", "MIN_SPREAD", "CLOUD_EXTENSIONS", "read_cloud", "check_cloud"]

MIN_POINTS = 20             # distinct points a cloud needs for a fit
MIN_SPREAD = 0.01           # second singular value / first of the centred cloud: below, a line
TEXT_EXTENSIONS = (".xyz", ".txt", ".csv", ".pts")
CLOUD_EXTENSIONS = (".ply", *TEXT_EXTENSIONS, ".npy")

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_SEPARATORS = re.compile(r"[,;\s]+")

Arr = NDArray[np.float64]


def _fail(where: str, message: str) -> ParamError:
    return ParamError("", message, where)


def read_cloud(path: str | os.PathLike[str]) -> Arr:
    """The points (N, 3) float64 of the cloud file ``path`` (see the module docstring for the
    formats), checked by :func:`check_cloud`."""
    src = os.fspath(path)
    ext = Path(src).suffix.lower()
    if ext not in CLOUD_EXTENSIONS:
        raise UsageError(f"{src}: unknown point cloud extension {ext or '(none)'!r} "
                         f"(leafview reads {', '.join(CLOUD_EXTENSIONS)})")
    data = read_bytes(src, what="point cloud file")
    if ext == ".ply":
        points = _read_ply(data, src)
    elif ext == ".npy":
        points = _read_npy(data, src)
    else:
        points = _read_text(data, src)
    return check_cloud(points, src)


def check_cloud(points: ArrayLike, where: str = "points") -> Arr:
    """``points`` as a float64 (N, 3) array, after the checks a fit needs: shape (N, 3), finite,
    at least :data:`MIN_POINTS` distinct points, and not all on a line: the second singular
    value of the centred cloud must be at least :data:`MIN_SPREAD` of the first (a flat leaf
    passes: its third singular value may be zero). Raises :class:`ParamError` starting with
    ``where``."""
    try:
        p = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise _fail(where, f"expected an (N, 3) array of numbers: {exc}") from None
    if p.ndim != 2 or p.shape[1] != 3:
        raise _fail(where, f"expected an (N, 3) array of points, got shape {p.shape}")
    bad = ~np.isfinite(p)
    if bad.any():
        i, j = (int(k) for k in np.argwhere(bad)[0])
        raise _fail(where, f"point {i} has a non-finite coordinate ({'xyz'[j]} = {p[i, j]}); "
                           f"{int(bad.any(axis=1).sum())} such point(s)")
    if len(p) < MIN_POINTS:
        raise _fail(where, f"{len(p)} points; a leaf fit needs at least {MIN_POINTS}")
    distinct = len(np.unique(p, axis=0))
    if distinct < MIN_POINTS:
        raise _fail(where, f"only {distinct} distinct points; a leaf fit needs at least {MIN_POINTS}")
    rel = p - p.mean(axis=0)
    scatter = np.einsum("ni,nj->ij", rel, rel)             # no threaded BLAS for a tall product
    sv = np.sqrt(np.maximum(np.linalg.eigvalsh(scatter)[::-1], 0.0))     # the singular values
    if not sv[1] >= MIN_SPREAD * sv[0]:
        raise _fail(where, f"the points lie on a line (spread across it {sv[1] / sv[0]:.2g} of the spread along "
                           f"it, at least {MIN_SPREAD:g} needed): not a leaf")
    return p


# -- text -----------------------------------------------------------------------------------------
def _read_text(data: bytes, src: str) -> Arr:
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        bad_line = data.count(b"\n", 0, exc.start) + 1
        raise _fail(f"{src}:{bad_line}", f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    rows: list[tuple[float, float, float]] = []
    header_seen = False
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        tokens = [t for t in _SEPARATORS.split(line) if t]
        values = _numbers(tokens[:3])
        if values is None or len(tokens) < 3:
            if not rows and not header_seen:        # one header line: names, or a point count
                header_seen = True
                continue
            if len(tokens) < 3:
                raise _fail(f"{src}:{number}", f"expected at least 3 numbers (x, y, z), got {len(tokens)} value(s)")
            bad = next(t for t in tokens[:3] if _numbers([t]) is None)
            raise _fail(f"{src}:{number}", f"not a number: {bad[:40]!r}")
        if not all(np.isfinite(values)):
            raise _fail(f"{src}:{number}", "a coordinate is NaN or infinite")
        rows.append(values)
    if not rows:
        raise _fail(src, "no points: expected lines of x y z")
    return np.array(rows, dtype=np.float64)


def _numbers(tokens: list[str]) -> tuple[float, float, float] | None:
    try:
        x = [float(t) for t in tokens]
    except ValueError:
        return None
    return (x[0], x[1], x[2]) if len(x) == 3 else None


# -- numpy ----------------------------------------------------------------------------------------
def _read_npy(data: bytes, src: str) -> Arr:
    try:
        a = np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise _fail(src, f"not a readable .npy array: {str(exc)[:120]}") from None
    if not isinstance(a, np.ndarray):
        raise _fail(src, "not a single .npy array")
    if a.dtype.kind not in "iuf":
        raise _fail(src, f"expected numbers (integer or float), got dtype {a.dtype}")
    if a.ndim != 2 or a.shape[1] < 3:
        raise _fail(src, f"expected an (N, 3) array (or N×k with k >= 3), got shape {a.shape}")
    return np.asarray(a[:, :3], dtype=np.float64)


# -- PLY ------------------------------------------------------------------------------------------
class _Property:
    def __init__(self, name: str, dtype: str, count_dtype: str | None = None) -> None:
        self.name, self.dtype, self.count_dtype = name, dtype, count_dtype

    @property
    def is_list(self) -> bool:
        return self.count_dtype is not None


class _Element:
    def __init__(self, name: str, count: int) -> None:
        self.name, self.count = name, count
        self.properties: list[_Property] = []


def _ply_header(data: bytes, src: str) -> tuple[str, list[_Element], int, int]:
    """(format, elements, offset of the body, line number of the first body line)."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        what = "does not start with 'ply'" if not data.startswith(b"ply") else "has no 'end_header' line"
        raise _fail(f"{src}:1", f"not a PLY file: the header {what}")
    stop = data.find(b"\n", end)
    body = len(data) if stop < 0 else stop + 1
    try:
        lines = data[:body].decode("ascii").splitlines()
    except UnicodeDecodeError:
        raise _fail(src, "the PLY header is not ASCII text") from None
    fmt = ""
    elements: list[_Element] = []
    for number, raw in enumerate(lines, start=1):
        words = raw.split()
        where = f"{src}:{number}"
        if not words or words[0] in ("comment", "obj_info"):
            continue
        key = words[0]
        if number == 1:
            if words != ["ply"]:
                raise _fail(where, "the first line of a PLY file must be 'ply'")
        elif key == "format":
            if len(words) != 3 or words[1] not in ("ascii", "binary_little_endian", "binary_big_endian"):
                raise _fail(where, "expected 'format ascii|binary_little_endian|binary_big_endian 1.0'")
            fmt = words[1]
        elif key == "element":
            if len(words) != 3 or not words[2].isdigit():
                raise _fail(where, "expected 'element NAME COUNT'")
            elements.append(_Element(words[1], int(words[2])))
        elif key == "property":
            if not elements:
                raise _fail(where, "a property before any element")
            elements[-1].properties.append(_ply_property(words, where))
        elif key == "end_header":
            break
        else:
            raise _fail(where, f"unexpected header line starting {key[:40]!r}")
    if not fmt:
        raise _fail(f"{src}:2", "the PLY header has no 'format' line")
    return fmt, elements, body, len(lines) + 1


def _ply_property(words: list[str], where: str) -> _Property:
    if len(words) == 5 and words[1] == "list":
        if words[2] not in _PLY_TYPES or words[3] not in _PLY_TYPES:
            raise _fail(where, f"unknown PLY list types {words[2][:20]!r} {words[3][:20]!r}")
        return _Property(words[4], _PLY_TYPES[words[3]], _PLY_TYPES[words[2]])
    if len(words) != 3 or words[1] not in _PLY_TYPES:
        raise _fail(where, f"expected 'property TYPE NAME' with TYPE one of {', '.join(sorted(set(_PLY_TYPES)))}")
    return _Property(words[2], _PLY_TYPES[words[1]])


def _read_ply(data: bytes, src: str) -> Arr:
    fmt, elements, offset, first_line = _ply_header(data, src)
    vertex = next((e for e in elements if e.name == "vertex"), None)
    if vertex is None:
        raise _fail(src, "the PLY file has no 'vertex' element")
    names = [p.name for p in vertex.properties]
    missing = [c for c in "xyz" if c not in names]
    if missing:
        raise _fail(src, f"the vertex element has no {', '.join(missing)} propert{'y' if len(missing) == 1 else 'ies'}")
    if fmt == "ascii":
        return _ply_ascii(data[offset:], elements, vertex, src, first_line)
    return _ply_binary(data, offset, elements, vertex, "<" if fmt == "binary_little_endian" else ">", src)


def _ply_ascii(body: bytes, elements: list[_Element], vertex: _Element, src: str, first_line: int) -> Arr:
    try:
        lines = body.decode("ascii").splitlines()
    except UnicodeDecodeError:
        raise _fail(src, "the body of an ascii PLY file is not ASCII text") from None
    line = 0
    cols = [[p.name for p in vertex.properties].index(c) for c in "xyz"]
    if vertex.count > len(lines):          # before allocating: the header may claim anything
        raise _fail(src, f"the header declares {vertex.count:,} vertices but the body has only {len(lines):,} lines")
    for element in elements:
        if element is not vertex:
            line += element.count          # one element a line
            continue
        out = np.empty((vertex.count, 3))
        for i in range(vertex.count):
            while line < len(lines) and not lines[line].strip():
                line += 1
            where = f"{src}:{first_line + line}"
            if line >= len(lines):
                raise _fail(where, f"the file ends after {i} of {vertex.count} vertices")
            values = _ascii_row(lines[line].split(), vertex, where)
            out[i] = [values[c] for c in cols]
            if not np.all(np.isfinite(out[i])):
                raise _fail(where, f"vertex {i}: a coordinate is NaN or infinite")
            line += 1
        return out
    raise AssertionError("unreachable: the vertex element is in the list")


def _ascii_row(tokens: list[str], element: _Element, where: str) -> list[float]:
    """The scalar values of one ascii element row (list properties skipped, as NaN placeholders)."""
    values: list[float] = []
    k = 0
    try:
        for prop in element.properties:
            if prop.is_list:
                count = int(tokens[k])
                k += 1 + count
                values.append(float("nan"))
            else:
                values.append(float(tokens[k]))
                k += 1
    except IndexError:
        raise _fail(where, f"expected {len(element.properties)} properties, the line ends early") from None
    except ValueError:
        raise _fail(where, f"not a number: {tokens[k][:40]!r}") from None
    return values


def _ply_binary(data: bytes, offset: int, elements: list[_Element], vertex: _Element, order: str, src: str) -> Arr:
    for element in elements:
        if element is vertex:
            break
        offset = _skip_binary(data, offset, element, order, src)
    if any(p.is_list for p in vertex.properties):
        raise _fail(src, "list properties in the vertex element are not supported")
    dtype = np.dtype([(f"p{i}_{p.name}", order + p.dtype) for i, p in enumerate(vertex.properties)])
    need = dtype.itemsize * vertex.count
    if len(data) - offset < need:
        raise _fail(src, f"truncated binary body: {vertex.count} vertices need {need:,} bytes, "
                         f"{max(len(data) - offset, 0):,} remain after the header")
    rows = np.frombuffer(data, dtype=dtype, count=vertex.count, offset=offset)
    index = {p.name: f"p{i}_{p.name}" for i, p in enumerate(vertex.properties)}
    out = np.stack([rows[index[c]].astype(np.float64) for c in "xyz"], axis=1)
    bad = ~np.isfinite(out)
    if bad.any():
        i = int(np.argwhere(bad)[0][0])
        raise _fail(src, f"vertex {i}: a coordinate is NaN or infinite")
    return out


def _skip_binary(data: bytes, offset: int, element: _Element, order: str, src: str) -> int:
    """The offset just after ``element``'s rows in a binary body."""
    if not any(p.is_list for p in element.properties):
        size = sum(np.dtype(p.dtype).itemsize for p in element.properties) * element.count
        if offset + size > len(data):
            raise _fail(src, f"truncated binary body inside the '{element.name}' element")
        return offset + size
    for _ in range(element.count):               # rows of varying length: walk them
        for prop in element.properties:
            if prop.is_list:
                assert prop.count_dtype is not None
                width = np.dtype(prop.count_dtype).itemsize
                if offset + width > len(data):
                    raise _fail(src, f"truncated binary body inside the '{element.name}' element")
                count = int(np.frombuffer(data, order + prop.count_dtype, 1, offset)[0])
                if count < 0:
                    raise _fail(src, f"a negative list length in the '{element.name}' element")
                offset += width + count * np.dtype(prop.dtype).itemsize
            else:
                offset += np.dtype(prop.dtype).itemsize
        if offset > len(data):
            raise _fail(src, f"truncated binary body inside the '{element.name}' element")
    return offset
