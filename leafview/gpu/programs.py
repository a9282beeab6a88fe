"""The program cache: every program of one context compiled once, keyed by its files, its
feature defines and its transform-feedback varyings, and released together.

Uniform blocks, storage buffers and samplers take their binding points from the ``layout(binding
= ...)`` qualifiers the loader resolves with :mod:`leafview.gpu.layout`'s defines, so nothing is
set on a program after linking.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import moderngl

from leafview.gpu.shaders import build_compute, build_program

__all__ = ["ProgramCache"]

_Key = tuple[str, str, str | None, tuple[tuple[str, str], ...], tuple[str, ...]]


def _key(kind: str, first: str, second: str | None, defines: Mapping[str, object] | None,
         varyings: Sequence[str]) -> _Key:
    items = tuple(sorted((str(k), str(v)) for k, v in (defines or {}).items()))
    return kind, first, second, items, tuple(varyings)


class ProgramCache:
    """Programs and compute shaders of ``ctx`` built from ``root`` (default the package's
    shaders/), each compiled on first use. A compile error raises
    :class:`~leafview.gpu.shaders.ShaderError` and caches nothing."""

    def __init__(self, ctx: moderngl.Context, root: Path | None = None) -> None:
        self.ctx, self.root = ctx, root
        self._programs: dict[_Key, moderngl.Program] = {}
        self._computes: dict[_Key, moderngl.ComputeShader] = {}

    def program(self, vertex: str, fragment: str | None = None, *, defines: Mapping[str, object] | None = None,
                varyings: Sequence[str] = ()) -> moderngl.Program:
        """The linked program of ``vertex`` (+ ``fragment``) for ``defines``, capturing
        ``varyings`` with transform feedback."""
        key = _key("program", vertex, fragment, defines, varyings)
        prog = self._programs.get(key)
        if prog is None:
            prog = self._programs[key] = build_program(self.ctx, vertex, fragment, defines=defines,
                                                       varyings=tuple(varyings), root=self.root)
        return prog

    def compute(self, name: str, *, defines: Mapping[str, object] | None = None) -> moderngl.ComputeShader:
        """The compute shader ``name`` for ``defines``."""
        key = _key("compute", name, None, defines, ())
        shader = self._computes.get(key)
        if shader is None:
            shader = self._computes[key] = build_compute(self.ctx, name, defines=defines, root=self.root)
        return shader

    def __len__(self) -> int:
        return len(self._programs) + len(self._computes)

    def all(self) -> list[moderngl.Program | moderngl.ComputeShader]:
        """Every program and compute shader compiled so far."""
        return [*self._programs.values(), *self._computes.values()]

    def release(self) -> None:
        for obj in self.all():
            obj.release()
        self._programs.clear()
        self._computes.clear()
