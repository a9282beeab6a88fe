"""The interactive viewer (``leafview view``): a glfw window, moderngl drawing the leaf and its
control polygons, and an imgui-bundle panel generated from the parameters' field metadata.

Layers, each usable without the ones above it:

* :mod:`~leafview.app.state`: the leaf, its file, undo/redo, view toggles (no GL, no imgui);
* :mod:`~leafview.app.panel` and :mod:`~leafview.app.chrome`: the imgui widgets, all editing
  through the state;
* :mod:`~leafview.app.viewer`: one frame of scene + panel into an offscreen framebuffer, on any
  moderngl context (headless EGL in tests and benchmarks);
* :mod:`~leafview.app.window`: the glfw window and event loop.

The layers below (``leafview.core`` … ``leafview.gpu``) never import this package (import-linter contracts in pyproject.toml).
"""

from __future__ import annotations

from leafview.app.state import ViewerState, ViewSettings

__all__ = ["ViewerState", "ViewSettings"]
