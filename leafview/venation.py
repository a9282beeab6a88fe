"""``leafview.venation``: vein trees and what they do to a leaf (Hong 2005, ch. 6-7; Geng, Hu & Zhang
2014, sec. 5.2.3).

* :func:`veins` (``params -> list[Vein]``): the leaf's vein tree with its edits applied, each vein a
  polyline on the surface (``.points``), its (u, v) (``.uv``), ``.order`` (1 midrib and primaries,
  2 secondaries, 3 and 4 the reticulate network), ``.parent`` and ``.width``;
  :func:`vein_tree` is the same tree before edits.
* :func:`vein_field`: the (u, v) field the shader reads (distance to the nearest vein, its order
  and width); :func:`vein_grid`: the displacement the veins give the blade (Laplace interpolation,
  Hong 2005, App. B) and the ripple coordinate along the secondaries.

The implementation is :mod:`leafview.botany.venation`, :mod:`leafview.botany.vein_field` and
:mod:`leafview.botany.vein_shape`; the parameters are :class:`leafview.core.venation.Venation`.
"""

from leafview.botany.vein_field import halfwidth_table, vein_field, vein_space
from leafview.botany.vein_shape import shape_grid, vein_grid, veins
from leafview.botany.venation import Vein, VeinSegments, check_veins, vein_segments, vein_tree
from leafview.core.venation import PATTERNS, VeinEdit, Venation

__all__ = ["veins", "vein_tree", "vein_segments", "check_veins", "Vein", "VeinSegments", "vein_field", "vein_grid",
           "shape_grid", "halfwidth_table", "vein_space", "Venation", "VeinEdit", "PATTERNS"]
