"""leafview: parametric plant leaves evaluated on the GPU.

The model (``LeafParams``, ``evaluate``, ``tessellate``) is pure numpy; ``render`` and ``gpu``
load OpenGL on first use.
"""

from __future__ import annotations

from typing import Any

from .model import (FieldSpec, Jitter, LeafParams, Material, Mesh, ParamError, Shape, Transform,
                    evaluate, field_specs, normals, partials, tessellate)

__version__ = "0.1.0"

__all__ = ["LeafParams", "Shape", "Jitter", "Material", "Transform", "ParamError", "FieldSpec",
           "field_specs", "evaluate", "normals", "partials", "tessellate", "Mesh", "render", "gpu",
           "edits", "beam", "fbm_noise", "__version__"]


def __getattr__(name: str) -> Any:
    import importlib

    if name == "gpu":
        return importlib.import_module(".gpu", __name__)
    if name == "render":
        return importlib.import_module(".gpu", __name__).render
    if name == "edits":
        return importlib.import_module(".model.edits", __name__)
    if name == "beam":
        return importlib.import_module(".beam", __name__)
    if name == "shapes_params":
        return importlib.import_module(".shapes", __name__).shapes_params
    if name == "fbm_noise":
        return importlib.import_module(".model.fbm", __name__).fbm_noise
    raise AttributeError(f"module 'leafview' has no attribute {name!r}")
