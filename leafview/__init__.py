"""leafview: parametric plant leaves evaluated on the GPU.

The model (``LeafParams``, ``evaluate``, ``tessellate``) is pure numpy and loads with the package.
The other public modules load on first use, so ``import leafview`` stays light: ``landmarks``,
``shapes``, ``beam``, ``venation`` and ``edits`` (numpy/scipy), ``gpu`` and ``render`` (OpenGL).

``evaluate``, ``normals``, ``partials`` and ``tessellate`` give the leaf as the shader draws it: a leaf
whose venation is on carries the shape its veins give it (Hong 2005, ch. 7; the grid of
:func:`leafview.venation.vein_grid`), and a lobed leaf is swept between its skeleton and its margin
(Mündermann et al. 2003); both load scipy on first use.
"""

from __future__ import annotations

import importlib
from typing import Any

from numpy.typing import NDArray

from leafview._version import __version__
from leafview.core import FieldSpec, Jitter, LeafParams, Material, ParamError, Shape, Transform, field_specs
from leafview.core.display import register_png_renderer
from leafview.deform import surface as _surface
from leafview.deform.fbm import check_signal_args, fbm_signal
from leafview.deform.surface import Mesh
from leafview.errors import LeafviewError

__all__ = ["LeafParams", "Shape", "Jitter", "Material", "Transform", "ParamError", "LeafviewError", "FieldSpec",
           "field_specs", "evaluate", "normals", "partials", "tessellate", "Mesh", "render", "gpu",
           "edits", "beam", "landmarks", "shapes", "venation", "fbm_noise", "__version__"]

# public modules loaded on first attribute access: name -> module
_LAZY_MODULES = {
    "gpu": "leafview.gpu",
    "edits": "leafview.core.edits",
    "beam": "leafview.beam",
    "landmarks": "leafview.landmarks",
    "shapes": "leafview.shapes",
    "venation": "leafview.venation",
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


def _leaf_surface() -> Any:
    """:mod:`leafview.botany.leaf_surface` (scipy), loaded on the first evaluation."""
    return importlib.import_module("leafview.botany.leaf_surface")


def evaluate(params: LeafParams, u: Any, v: Any) -> NDArray[Any]:
    """Leaf-space points at (u, v) as the shader draws them: veins' shape included, and a lobed
    leaf swept from its skeleton (:mod:`leafview.botany.leaf_surface`)."""
    out: NDArray[Any] = _leaf_surface().evaluate(params, u, v)
    return out


def normals(params: LeafParams, u: Any, v: Any) -> NDArray[Any]:
    """Unit upper-side normals at (u, v) (see :func:`evaluate`)."""
    out: NDArray[Any] = _leaf_surface().normals(params, u, v)
    return out


def partials(params: LeafParams, u: Any, v: Any) -> _surface.Partials:
    """Position and derivatives at (u, v) (see :func:`evaluate`)."""
    out: _surface.Partials = _leaf_surface().partials(params, u, v)
    return out


def tessellate(params: LeafParams, nu: int = _surface.DEFAULT_GRID[0], nv: int = _surface.DEFAULT_GRID[1]) -> Mesh:
    """The leaf as a mesh: a unilobed leaf on the (nu × nv) grid, a lobed one on its own grid
    with the paired ties welded (see :func:`evaluate`)."""
    out: Mesh = _leaf_surface().tessellate(params, nu, nv)
    return out
