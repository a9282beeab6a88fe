"""GLSL loading: ``#include "file"`` with a depth cap and ``#line`` markers, and compile/link
errors turned into :class:`ShaderError` naming the stage, the file and the line.

Every program gets the binding points of :mod:`leafview.gpu.layout` as ``#define``s right after
``#version`` (``layout(std430, binding = LEAVES_BINDING)``), then the caller's feature defines.

Drivers disagree on the source-string number of ``#line`` (Mesa drops it), so the loader
encodes the file in the line number itself: line ``L`` of the k-th file becomes
``k · 100000 + L``. The error parser decodes it back to ``file:line``.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import moderngl

from leafview.errors import ShaderError
from leafview.gpu.layout import binding_defines, generated_sources
from leafview.resources import shader_dir

__all__ = ["ShaderError", "ShaderSource", "preprocess", "build_program", "build_compute"]

_LINE_STRIDE = 100_000
_MAX_DEPTH = 8
_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')
_CONDITIONAL = re.compile(r"^\s*#\s*(else|elif|endif)\b")
_VERSION = re.compile(r"^\s*#\s*version\b")
# Mesa "0:12(5): error: ..."; NVIDIA "0(12) : error C1008: ..."; AMD/Intel "ERROR: 0:12: ..."
_LOG_LINE = re.compile(r"(?:^|\s)(\d+)(?::(\d+)\((\d+)\)|\((\d+)\)|:(\d+):)")


@dataclass
class ShaderSource:
    """Preprocessed GLSL text plus the table that maps encoded lines back to files."""

    text: str
    files: list[str] = field(default_factory=list)

    def locate(self, encoded_line: int) -> str:
        idx, line = divmod(encoded_line, _LINE_STRIDE)
        name = self.files[idx] if 0 <= idx < len(self.files) else "?"
        return f"{name}:{line}"

    def rewrite_log(self, log: str) -> tuple[str, str | None]:
        """Replace encoded line numbers in a driver log by ``file:line``; also return the first."""
        first: list[str] = []

        def sub(m: re.Match[str]) -> str:
            num = m.group(2) or m.group(4) or m.group(5)
            loc = self.locate(int(num))
            if not first:
                first.append(loc)
            return f" {loc}:"

        out = "\n".join(_LOG_LINE.sub(sub, line, count=1) for line in log.splitlines())
        return out.strip(), (first[0] if first else None)


def _read(name: str, root: Path, extra: Mapping[str, str]) -> str:
    if name in extra:
        return extra[name]
    path = (root / name).resolve()
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileNotFoundError(f"shader file not found: {path}") from None


def preprocess(name: str, *, defines: Mapping[str, object] | None = None, root: Path | None = None,
               extra: Mapping[str, str] | None = None) -> ShaderSource:
    """Resolve includes of ``name`` (relative to ``root``, default the package's shaders/).

    The binding points of the layout, then ``defines``, are inserted after ``#version``;
    ``extra`` maps virtual file names to text (the generated layout blocks are always available
    as ``generated/*.glsl``).
    """
    root = root or shader_dir()
    virtual = {**generated_sources(), **(extra or {})}
    injected: dict[str, object] = dict(binding_defines())
    clash = sorted(set(injected) & set(defines or {}))
    if clash:
        raise ValueError(f"the binding points of leafview.gpu.layout cannot be redefined: {', '.join(clash)}")
    injected.update(defines or {})
    src = ShaderSource("")
    out: list[str] = []

    def emit(fname: str, depth: int, stack: tuple[str, ...]) -> None:
        if depth > _MAX_DEPTH:
            raise ShaderError("preprocess", None, f"#include nested deeper than {_MAX_DEPTH}: "
                              + " -> ".join(stack))
        idx = len(src.files)
        src.files.append(fname)
        lines = _read(fname, root, virtual).splitlines()
        out.append(f"#line {idx * _LINE_STRIDE + 1}")
        for n, line in enumerate(lines, start=1):
            m = _INCLUDE.match(line)
            if m:
                inc = m.group(1)
                if inc in stack:
                    raise ShaderError("preprocess", f"{fname}:{n}", f"circular #include of {inc!r}")
                try:
                    emit(inc, depth + 1, stack + (inc,))
                except FileNotFoundError as exc:
                    raise ShaderError("preprocess", f"{fname}:{n}", str(exc)) from None
                out.append(f"#line {idx * _LINE_STRIDE + n + 1}")
            elif _VERSION.match(line):
                if depth:
                    raise ShaderError("preprocess", f"{fname}:{n}", "#version inside an included file")
                out.pop()  # #version must come first
                out.append(line)
                for key, value in injected.items():
                    out.append(f"#define {key} {value}")
                out.append(f"#line {idx * _LINE_STRIDE + n + 1}")
            elif _CONDITIONAL.match(line):
                # a #line inside a skipped branch (after an #include there) is ignored by the
                # compiler: restate the position after every #else/#elif/#endif
                out.append(line)
                out.append(f"#line {idx * _LINE_STRIDE + n + 1}")
            else:
                out.append(line)

    emit(name, 0, (name,))
    src.text = "\n".join(out) + "\n"
    return src


_STAGE_HEADERS = {"vertex_shader": "vertex", "fragment_shader": "fragment", "geometry_shader": "geometry",
                  "compute_shader": "compute"}


def _raise_from(exc: Exception, sources: Mapping[str, ShaderSource]) -> None:
    text = str(exc)
    if "Linker failed" in text:
        log = text.split("=======", 1)[-1].strip()
        raise ShaderError("link", None, log) from None
    for header, stage in _STAGE_HEADERS.items():
        if f"\n{header}\n" in text and stage in sources:
            log = text.split(header, 1)[1].split("\n", 2)[-1]
            log, loc = sources[stage].rewrite_log(log)
            raise ShaderError(stage, loc, log) from None
    raise ShaderError("compile", None, text) from None


def build_program(ctx: moderngl.Context, vertex: str, fragment: str | None = None, *,
                  defines: Mapping[str, object] | None = None, varyings: tuple[str, ...] = (),
                  root: Path | None = None) -> moderngl.Program:
    """Compile and link a program from files in ``shaders/``; raises :class:`ShaderError`."""
    sources = {"vertex": preprocess(vertex, defines=defines, root=root)}
    if fragment is not None:
        sources["fragment"] = preprocess(fragment, defines=defines, root=root)
    try:
        return ctx.program(
            vertex_shader=sources["vertex"].text,
            fragment_shader=sources["fragment"].text if fragment else None,
            varyings=tuple(varyings),
        )
    except moderngl.Error as exc:
        _raise_from(exc, sources)
        raise  # unreachable


def build_compute(ctx: moderngl.Context, name: str, *, defines: Mapping[str, object] | None = None,
                  root: Path | None = None) -> moderngl.ComputeShader:
    """Compile a compute shader from ``shaders/``; raises :class:`ShaderError`."""
    src = preprocess(name, defines=defines, root=root)
    try:
        return ctx.compute_shader(src.text)
    except moderngl.Error as exc:
        _raise_from(exc, {"compute": src})
        raise
