"""leafview: parametric plant leaves evaluated on the GPU.

The model (``LeafParams``, ``evaluate``, ``tessellate``) is pure numpy and loads with the package.
The other public modules load on first use, so ``import leafview`` stays light: ``landmarks``,
``shapes``, ``beam`` and ``edits`` (numpy/scipy), ``gpu`` and ``render`` (OpenGL).
"""

from __future__ import annotations

import importlib
from typing import Any

from numpy.typing import NDArray

from leafview._version import __version__
from leafview.core import FieldSpec, Jitter, LeafParams, Material, ParamError, Shape, Transform, field_specs
from leafview.core.display import register_png_renderer
from leafview.deform.fbm import check_signal_args, fbm_signal
from leafview.deform.surface import Mesh, evaluate, normals, partials, tessellate
from leafview.errors import LeafviewError

__all__ = ["LeafParams", "Shape", "Jitter", "Material", "Transform", "ParamError", "LeafviewError", "FieldSpec",
           "field_specs", "evaluate", "normals", "partials", "tessellate", "Mesh", "render", "gpu",
           "edits", "beam", "landmarks", "shapes", "fbm_noise", "__version__"]

# public modules loaded on first attribute access: name -> module
_LAZY_MODULES = {
    "gpu": "leafview.gpu",
    "edits": "leafview.core.edits",
    "beam": "leafview.beam",
    "landmarks": "leafview.landmarks",
    "shapes": "leafview.shapes",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY_MODULES:
        return importlib.import_module(_LAZY_MODULES[name])
    if name == "render":
        return importlib.import_module("leafview.gpu").render
    raise AttributeError(f"module 'leafview' has no attribute {name!r}")


def _thumbnail_png(kind: str, obj: object) -> bytes:
    """PNG bytes of a leaf or scene thumbnail; the GL code loads on the first thumbnail."""
    thumbnails = importlib.import_module("leafview.notebook.thumbnails")
    png: bytes = getattr(thumbnails, f"{kind}_png")(obj)
    return png


# what a notebook cell ending with a leaf or a scene shows (LeafParams/Scene._repr_png_)
register_png_renderer("leaf", lambda obj: _thumbnail_png("leaf", obj))
register_png_renderer("scene", lambda obj: _thumbnail_png("scene", obj))


def fbm_noise(n: int, beta: float, seed: int, backend: str = "cpu") -> NDArray[Any]:
    """fBm noise of Geng, Hu & Zhang 2014, eqs 1-2: ``backend="cpu"`` (numpy, float64) or ``"gpu"``
    (compute shader, float32, same random numbers; agrees within 1e-4 of the signal's std)."""
    if backend == "cpu":
        return fbm_signal(n, beta, seed)
    if backend == "gpu":
        check_signal_args(n, beta)
        gpu = importlib.import_module("leafview.gpu")   # GL only when asked for
        result: NDArray[Any] = gpu.gpu_fbm_noise(n, beta, seed)
        return result
    raise ValueError(f"backend must be 'cpu' or 'gpu', got {backend!r}")
