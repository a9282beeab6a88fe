"""The leaf itself, with no GPU: parameters and their validation (:mod:`.params`), Bézier maths
(:mod:`.bezier`), the undeformed blade of Chaurasia & Beardsley 2017, eqs 1-6 (:mod:`.blade`),
files in full and compact form (:mod:`.io`, :mod:`.compact`, :mod:`.schema`) and the edits of
sec. 6 (:mod:`.edits`). numpy and the standard library only.
"""

from leafview.core import io  # registers the reader and writer behind LeafParams.load / save
from leafview.core.params import (
                                  Bending,
                                  FieldSpec,
                                  Jitter,
                                  LeafParams,
                                  Material,
                                  ParamError,
                                  Ripple,
                                  Shape,
                                  Transform,
                                  field_specs,
)

__all__ = ["io", "LeafParams", "Shape", "Jitter", "Material", "Transform", "Ripple", "Bending", "ParamError",
           "FieldSpec", "field_specs"]
