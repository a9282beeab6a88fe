"""Pure numpy model of the leaf: parameters, Bézier maths, reference evaluation, edits.

Never imports moderngl, glfw or imgui (a test enforces it).
"""

from .leaf import Mesh, evaluate, grid_indices, grid_uv, jitter_table, normals, partials, tessellate
from .params import (Bending, FieldSpec, Jitter, LeafParams, Material, ParamError, Ripple, Shape, Transform,
                     field_specs)

__all__ = [
    "LeafParams", "Shape", "Jitter", "Material", "Transform", "Ripple", "Bending", "ParamError", "FieldSpec", "field_specs",
    "evaluate", "normals", "partials", "tessellate", "Mesh", "grid_uv", "grid_indices", "jitter_table",
]
