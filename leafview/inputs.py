"""The one reader of every input file: presets, compact leaves and leaf sets, scene files,
multilobed and landmark leaves, morph inputs.

Every file is checked before it is parsed, so that no input can hang, exhaust memory or crash the
parser (the limits are also listed in ``docs/reliability.md``, "Inputs and limits"):

* **Only regular files.** The path is ``stat``-ed first; FIFOs, character and block devices
  (``/dev/zero``), sockets and directories are refused without being opened. The file is then
  opened with ``O_NONBLOCK`` and checked again with ``fstat`` (it may have been swapped between
  the two calls), so a FIFO can never block the reader.
* **Size.** At most :data:`DEFAULT_MAX_BYTES` (256 MiB); the environment variable
  ``LEAFVIEW_MAX_INPUT_BYTES`` (a whole number of bytes) or the ``max_bytes`` argument changes it.
  The size is checked from ``stat`` and again while reading (a file that grows is cut off).
* **Encoding.** UTF-8; an invalid byte is reported with its byte offset and line.
* **Structure.** JSON and TOML documents may nest arrays and tables at most
  :data:`MAX_DEPTH` (64) deep, and an integer literal may have at most :data:`MAX_INT_DIGITS`
  (100) digits. Both are checked on the text before the parser sees it (the parsers recurse, and
  Python refuses to convert integers of more than 4300 digits), and again on the parsed document.

Errors are :class:`~leafview.errors.ParamError` with the file as ``source`` (``file:line:col``
where a position is known) and never quote the file's content. The module imports only the
standard library and :mod:`leafview.errors`.
"""

from __future__ import annotations

import json
import os
import re
import stat
import tomllib
from pathlib import Path
from typing import Any

from leafview.errors import ParamError

__all__ = ["DEFAULT_MAX_BYTES", "MAX_BYTES_ENV", "MAX_DEPTH", "MAX_INT_DIGITS", "max_input_bytes", "read_bytes",
           "read_text", "read_json", "read_toml", "read_structured", "check_structure"]

DEFAULT_MAX_BYTES = 256 * 2**20        # 256 MiB
MAX_BYTES_ENV = "LEAFVIEW_MAX_INPUT_BYTES"
MAX_DEPTH = 64                         # nested arrays / tables / objects
MAX_INT_DIGITS = 100                   # digits of one integer literal
_MAX_INT = 10**MAX_INT_DIGITS
_CHUNK = 1 << 20


def max_input_bytes(max_bytes: int | None = None) -> int:
    """The size limit in force: ``max_bytes`` if given, else ``$LEAFVIEW_MAX_INPUT_BYTES``, else
    :data:`DEFAULT_MAX_BYTES`."""
    if max_bytes is not None:
        return int(max_bytes)
    text = os.environ.get(MAX_BYTES_ENV, "").strip()
    if not text:
        return DEFAULT_MAX_BYTES
    try:
        value = int(text)
    except ValueError:
        raise ParamError("", f"expected a whole number of bytes, got {text[:40]!r}", MAX_BYTES_ENV) from None
    if value < 1:
        raise ParamError("", f"must be at least 1 byte, got {value}", MAX_BYTES_ENV)
    return value


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _mib(n: int) -> str:
    return f"{n / 2**20:.1f} MiB" if n >= 2**20 else f"{n:,} bytes"


def read_bytes(path: str | os.PathLike[str], *, max_bytes: int | None = None, what: str = "input file") -> bytes:
    """The bytes of the regular file ``path`` (see the module docstring); :class:`ParamError`
    naming the file for anything else."""
    src = os.fspath(path)
    limit = max_input_bytes(max_bytes)
    try:
        st = os.stat(src)
    except FileNotFoundError:
        raise ParamError("", "no such file", src) from None
    except OSError as exc:
        raise ParamError("", f"cannot read: {exc.strerror or exc}", src) from None
    if not stat.S_ISREG(st.st_mode):
        raise ParamError("", f"is {_kind(st.st_mode)}, expected a regular {what}", src)
    if st.st_size > limit:
        raise ParamError("", f"is {_mib(st.st_size)}, above the {_mib(limit)} size limit of input files "
                             f"(set {MAX_BYTES_ENV} to change it)", src)
    try:
        fd = os.open(src, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise ParamError("", f"cannot read: {exc.strerror or exc}", src) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):   # swapped after the stat above
            raise ParamError("", f"is {_kind(st.st_mode)}, expected a regular {what}", src)
        chunks: list[bytes] = []
        size = 0
        while True:
            chunk = os.read(fd, min(_CHUNK, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
            if size > limit:
                raise ParamError("", f"grew above the {_mib(limit)} size limit of input files while being read "
                                     f"(set {MAX_BYTES_ENV} to change it)", src)
    except OSError as exc:
        raise ParamError("", f"cannot read: {exc.strerror or exc}", src) from None
    finally:
        os.close(fd)
    return b"".join(chunks)


def read_text(path: str | os.PathLike[str], *, max_bytes: int | None = None, what: str = "input file") -> str:
    """:func:`read_bytes` decoded as UTF-8 (a leading byte-order mark is dropped); a bad byte is
    reported with its offset and line."""
    data = read_bytes(path, max_bytes=max_bytes, what=what)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ParamError("", f"not UTF-8 text: {exc.reason} at byte {exc.start} (line {line})",
                         os.fspath(path)) from None
    return text[1:] if text.startswith("\ufeff") else text


# -- structure ----------------------------------------------------------------------------------
# Tokens that matter for nesting and integer size; strings and comments are matched first so that
# brackets and digits inside them are skipped. Strings use the unrolled loop "[^"\\]*(?:\\.[^"\\]*)*":
# a repeated character class needs no per-character backtracking state, which (?:a|b)* keeps
# (a 200 MB string took over 24 GB of memory that way).
_JSON_TOKENS = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"?|[\[\]{}]|-?\d[\d]*')
_TOML_TOKENS = re.compile(r'"""[\s\S]*?(?:"""|\Z)|\'\'\'[\s\S]*?(?:\'\'\'|\Z)|"[^"\\\n]*(?:\\.[^"\\\n]*)*"?|\'[^\'\n]*\'?'
                          r'|#[^\n]*|[\[\]{}]|[0-9][0-9_]*')


def _where(text: str, index: int) -> str:
    line = text.count("\n", 0, index) + 1
    col = index - (text.rfind("\n", 0, index) + 1) + 1
    return f"{line}:{col}"


def _scan(text: str, fmt: str, source: str) -> None:
    """Refuse nesting deeper than :data:`MAX_DEPTH` and integers longer than :data:`MAX_INT_DIGITS`
    digits, on the text (before the recursive parsers run)."""
    depth = 0
    for m in (_TOML_TOKENS if fmt == "toml" else _JSON_TOKENS).finditer(text):
        tok = m.group()
        c = tok[0]
        if c in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                raise ParamError("", f"nested more than {MAX_DEPTH} levels deep", f"{source}:{_where(text, m.start())}")
        elif c in "]}":
            depth = max(depth - 1, 0)
        elif c.isdigit() or c == "-":
            digits = len(tok) - tok.count("_") - tok.startswith("-")
            if digits > MAX_INT_DIGITS:
                raise ParamError("", f"a number of {digits} digits; at most {MAX_INT_DIGITS} are accepted",
                                 f"{source}:{_where(text, m.start())}")


def check_structure(doc: Any, source: str) -> None:
    """Refuse a parsed document nested deeper than :data:`MAX_DEPTH` or holding an integer of
    more than :data:`MAX_INT_DIGITS` digits (iterative: no recursion)."""
    stack: list[tuple[Any, int]] = [(doc, 0)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, dict):
            children: Any = value.values()
        elif isinstance(value, list):
            children = value
        else:
            if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= _MAX_INT:
                raise ParamError("", f"an integer of more than {MAX_INT_DIGITS} digits", source)
            continue
        if depth >= MAX_DEPTH:
            raise ParamError("", f"nested more than {MAX_DEPTH} levels deep", source)
        stack.extend((child, depth + 1) for child in children)


def _json_int(text: str) -> int:
    if len(text.lstrip("-")) > MAX_INT_DIGITS:
        raise ValueError(f"a number of more than {MAX_INT_DIGITS} digits")
    return int(text)


def _toml_position(message: str) -> str:
    m = re.search(r"line (\d+), column (\d+)", message)
    return f"{m.group(1)}:{m.group(2)}" if m else ""


def parse_json(text: str, source: str) -> Any:
    """Parse JSON text read from ``source`` within the limits (see the module docstring)."""
    _scan(text, "json", source)
    try:
        doc = json.loads(text, parse_int=_json_int)
    except json.JSONDecodeError as exc:
        raise ParamError("", f"JSON syntax error: {exc.msg}", f"{source}:{exc.lineno}:{exc.colno}") from None
    except (ValueError, RecursionError) as exc:
        raise ParamError("", f"JSON error: {exc}" if isinstance(exc, ValueError) else
                         f"nested more than {MAX_DEPTH} levels deep", source) from None
    check_structure(doc, source)
    return doc


def parse_toml(text: str, source: str) -> Any:
    """Parse TOML text read from ``source`` within the limits (see the module docstring)."""
    _scan(text, "toml", source)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        pos = _toml_position(str(exc))
        msg = str(exc).split(" (at ")[0]
        raise ParamError("", f"TOML syntax error: {msg}", f"{source}:{pos}" if pos else source) from None
    except RecursionError:
        raise ParamError("", f"nested more than {MAX_DEPTH} levels deep", source) from None
    except ValueError:
        raise ParamError("", f"a number outside what can be read (more than {MAX_INT_DIGITS} digits?)",
                         source) from None
    check_structure(doc, source)
    return doc


def read_json(path: str | os.PathLike[str], *, max_bytes: int | None = None, what: str = "input file") -> Any:
    """A JSON file, through :func:`read_text` and :func:`parse_json`."""
    return parse_json(read_text(path, max_bytes=max_bytes, what=what), os.fspath(path))


def read_toml(path: str | os.PathLike[str], *, max_bytes: int | None = None, what: str = "input file") -> Any:
    """A TOML file, through :func:`read_text` and :func:`parse_toml`."""
    return parse_toml(read_text(path, max_bytes=max_bytes, what=what), os.fspath(path))


def read_structured(path: str | os.PathLike[str], *, max_bytes: int | None = None,
                    what: str = "input file") -> Any:
    """A ``.json`` file as JSON, anything else as TOML."""
    if Path(path).suffix.lower() == ".json":
        return read_json(path, max_bytes=max_bytes, what=what)
    return read_toml(path, max_bytes=max_bytes, what=what)
