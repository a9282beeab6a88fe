"""leafview in Jupyter notebooks.

* :class:`LeafWidget` (:mod:`.widget`, needs the ``notebook`` extra: jupyter_rfb and ipywidgets):
  a live, orbitable leaf with sliders for its main parameters, or a scene;
* :mod:`.thumbnails`: the PNG thumbnails behind ``LeafParams._repr_png_`` and
  ``Scene._repr_png_`` (registered by ``import leafview``; OpenGL only, no notebook package).

``LeafWidget`` loads on first use, so the thumbnails work without the ``notebook`` extra.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from leafview.notebook.thumbnails import leaf_png, leaf_thumbnail, scene_png, scene_thumbnail

if TYPE_CHECKING:
    from leafview.notebook.widget import KNOBS, Knob, LeafWidget

__all__ = ["LeafWidget", "Knob", "KNOBS", "leaf_thumbnail", "scene_thumbnail", "leaf_png", "scene_png"]

_WIDGET_NAMES = {"LeafWidget", "Knob", "KNOBS"}


def __getattr__(name: str) -> Any:
    if name in _WIDGET_NAMES:   # jupyter_rfb and ipywidgets load here, on first use
        return getattr(importlib.import_module("leafview.notebook.widget"), name)
    raise AttributeError(f"module 'leafview.notebook' has no attribute {name!r}")
