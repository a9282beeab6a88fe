"""Rich display hooks: how a leaf or a scene becomes a PNG thumbnail in a Jupyter notebook.

``LeafParams._repr_png_`` and ``Scene._repr_png_`` ask :func:`png_of`, which calls the renderer
registered for their kind (``"leaf"``, ``"scene"``). The layers that own those classes know
nothing of OpenGL (import-linter contracts), so the renderers are registered from above:
``import leafview`` registers functions that load the GPU thumbnail code on first use
(:mod:`leafview.notebook.thumbnails`). With no renderer, or when OpenGL cannot be had,
:func:`png_of` returns None and Jupyter falls back to the text repr.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from leafview.errors import GLContextLost, GLUnavailable

__all__ = ["PngRenderer", "register_png_renderer", "png_of", "PNG_SIGNATURE"]

PngRenderer = Callable[[Any], bytes]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

_PNG_RENDERERS: dict[str, PngRenderer] = {}

# what "no OpenGL here" looks like: no context, a lost context, moderngl/glcontext missing
_UNAVAILABLE = (GLUnavailable, GLContextLost, ImportError)


def register_png_renderer(kind: str, renderer: PngRenderer | None) -> PngRenderer | None:
    """Install ``renderer`` (object -> PNG bytes) for ``kind`` (``"leaf"``, ``"scene"``), or remove
    it with None; returns the renderer it replaces (None if there was none)."""
    previous = _PNG_RENDERERS.pop(kind, None)
    if renderer is not None:
        _PNG_RENDERERS[kind] = renderer
    return previous


def png_of(kind: str, obj: object) -> bytes | None:
    """PNG bytes of ``obj`` from the renderer registered for ``kind``; None when none is
    registered or when OpenGL is unavailable (Jupyter then shows the text repr)."""
    renderer = _PNG_RENDERERS.get(kind)
    if renderer is None:
        return None
    try:
        return renderer(obj)
    except _UNAVAILABLE:
        return None
