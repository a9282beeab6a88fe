"""``leafview view --dev``: reload the shaders when their files change.

The watcher polls modification times of ``shaders/`` (twice a second at most). On a change the
viewer compiles the *new* programs first (:func:`compile_check`); only when every one of them
compiles does it replace the running ones. On failure the old programs keep drawing and the
compiler log, with ``file:line`` decoded by :mod:`leafview.gpu.shaders`, goes to an error panel.
"""

from __future__ import annotations

import time
from pathlib import Path

import moderngl

from leafview.gpu.renderer import LeafRenderer
from leafview.gpu.shaders import ShaderError, build_compute, build_program
from leafview.resources import shader_dir

__all__ = ["ShaderWatcher", "compile_check", "rebuild_renderer", "SHADER_SUFFIXES"]

SHADER_SUFFIXES = {".glsl", ".vert", ".frag", ".comp", ".geom"}


class ShaderWatcher:
    """Reports when any shader source under ``root`` changed since the last call."""

    def __init__(self, root: Path | None = None, interval: float = 0.5) -> None:
        self.root = Path(root) if root is not None else shader_dir()
        self.interval = interval
        self._last_poll = 0.0
        self._stamps = self._scan()

    def _scan(self) -> dict[Path, float]:
        stamps: dict[Path, float] = {}
        for path in self.root.iterdir():
            if path.suffix in SHADER_SUFFIXES:
                try:
                    stamps[path] = path.stat().st_mtime
                except OSError:  # removed between listing and stat
                    continue
        return stamps

    def changed(self, now: float | None = None) -> bool:
        """True once after files were edited, added or removed (rate-limited to ``interval``)."""
        now = time.monotonic() if now is None else now
        if now - self._last_poll < self.interval:
            return False
        self._last_poll = now
        stamps = self._scan()
        if stamps != self._stamps:
            self._stamps = stamps
            return True
        return False


def compile_check(ctx: moderngl.Context) -> None:
    """Compile every program the viewer uses from the current files and release them again;
    raises :class:`~leafview.gpu.shaders.ShaderError` naming the stage and ``file:line``."""
    built: list = []
    try:
        built.append(build_program(ctx, "leaf.vert", "leaf.frag", varyings=("v_object", "v_object_normal")))
        built.append(build_compute(ctx, "leaf_prepare.comp"))
        built.append(build_program(ctx, "overlay.vert", "overlay.frag"))
        built.append(build_program(ctx, "overlay_imgui.vert", "overlay_imgui.frag"))
        built.append(build_program(ctx, "photo_reference.vert", "photo_reference.frag"))
    finally:
        for obj in built:
            obj.release()


def rebuild_renderer(ctx: moderngl.Context, old: LeafRenderer) -> LeafRenderer:
    """A new :class:`LeafRenderer` from the current shader files, or ``old`` unchanged when they
    do not compile (the :class:`ShaderError` propagates; nothing of ``old`` is touched)."""
    compile_check(ctx)
    new = LeafRenderer(ctx)
    old.release()
    return new


def describe(exc: BaseException) -> str:
    """The message shown in the error panel."""
    if isinstance(exc, ShaderError):
        return f"{exc}\n\n(the previous shaders keep running; fix the file and save)"
    if isinstance(exc, FileNotFoundError):
        return f"{exc}\n\n(the previous shaders keep running)"
    return f"{type(exc).__name__}: {exc}"
