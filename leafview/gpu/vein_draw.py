"""The veins of one draw: vein fields, vein-shape grids and the shading's style rows, bound together.

Every renderer (:class:`~leafview.gpu.renderer.LeafRenderer`, :class:`~leafview.gpu.instanced.
InstancedLeaves`, :class:`~leafview.gpu.scene.SceneRenderer`, the viewers) owns one
:class:`VeinDraw`. :meth:`VeinDraw.update` with the draw's leaves returns each leaf's vein layer
(-1 without veins), to be packed into the records (``pack_leaves(..., vein_layers=layers)``,
:func:`~leafview.gpu.layout.write_vein_layers`); it builds:

* the fields and grids of the leaves whose venation is enabled
  (:class:`leafview.gpu.vein_field.VeinFields`: one array layer per distinct (shape, venation)
  key, only new keys computed; at most :data:`MAX_VEIN_LAYERS`, beyond which leaves share:
  :func:`field_leaves`), bound at ``VEIN_FIELD_UNIT`` and ``VEIN_GRID_UNIT``;
* the style rows ``leaf.frag`` reads per layer (``shaders/leaf_veins.glsl``): venation contrast,
  relief and the major veins' width (:func:`leafview.botany.vein_shading.major_width`), an
  RGBA32F texture one texel per layer at ``VEIN_STYLE_UNIT``.

With ``enabled=False`` (``--veins off``, the viewer's checkbox) or without a veined leaf it holds
nothing, every layer is -1 and the draw's programs are built with ``LEAF_NO_VEINS``
(:func:`~leafview.gpu.layout.vein_defines`): a draw without veins pays nothing for them.
"""

from __future__ import annotations

from collections.abc import Sequence

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.botany.vein_field import vein_keys, vein_layers
from leafview.botany.vein_shading import major_width
from leafview.core.params import LeafParams
from leafview.core.venation import Venation
from leafview.gpu.layout import VEIN_STYLE_UNIT
from leafview.gpu.programs import ProgramCache
from leafview.gpu.vein_field import VeinFields

__all__ = ["VeinDraw", "style_rows", "MAX_VEIN_LAYERS", "field_leaves", "fresh_layers"]

MAX_VEIN_LAYERS = 64
"""Most vein fields one draw holds (a 256² RGBA32F field is 1 MiB): beyond that, leaves share."""


def field_leaves(leaves: Sequence[LeafParams], budget: int = MAX_VEIN_LAYERS) -> list[LeafParams]:
    """The leaf whose field and vein grid each leaf is drawn with: itself while the draw has at
    most ``budget`` distinct (shape, venation) keys. Beyond that (a leaf set of varied leaves, each
    a shape of its own), leaves of one venation share the field of the first of them (the vein
    tree lives in (u, v); the shape only scales its metric), and venations beyond ``budget``
    borrow the first kept one of the same pattern (else the first kept one)."""
    leaves = list(leaves)
    if len(vein_keys(leaves)) <= budget:
        return leaves
    first: dict[Venation, LeafParams] = {}
    by_pattern: dict[str, LeafParams] = {}
    out: list[LeafParams] = []
    for p in leaves:
        v = p.venation
        if not v.enabled:
            out.append(p)
            continue
        rep = first.get(v)
        if rep is None:
            if len(first) < budget:
                rep = first[v] = p
                by_pattern.setdefault(v.pattern, p)
            else:
                rep = by_pattern.get(v.pattern, next(iter(first.values())))
        out.append(rep)
    return out


def fresh_layers(leaves: Sequence[LeafParams], budget: int = MAX_VEIN_LAYERS) -> NDArray[np.int32]:
    """Each leaf's layer in a field array built fresh for ``leaves`` by :meth:`VeinDraw.update`
    (-1 without veins): the numpy twin of its layer assignment."""
    return vein_layers(field_leaves(leaves, budget))


def style_rows(leaves: Sequence[LeafParams], layers: NDArray[np.int32], count: int) -> NDArray[np.float32]:
    """(count, 4) float32 style row of each layer: contrast, relief, major veins' width, 0 (from the
    first leaf of ``leaves`` on that layer; leaves sharing a layer share their venation)."""
    rows = np.zeros((max(count, 1), 4), np.float32)
    for p, layer in zip(leaves, np.asarray(layers).tolist()):
        if layer >= 0:
            v = p.venation
            rows[layer] = (v.contrast, v.relief, major_width(v), 0.0)
    return rows


class VeinDraw:
    """The vein textures of a draw (see the module docstring); release with :meth:`release`.
    ``programs``: the shared program cache the field pass is compiled in."""

    def __init__(self, ctx: moderngl.Context, programs: ProgramCache | None = None) -> None:
        self.ctx = ctx
        self.programs = programs
        self.fields: VeinFields | None = None
        self.style: moderngl.Texture | None = None
        self._rows: bytes = b""

    @property
    def active(self) -> bool:
        """Whether a veined leaf is drawn (the fields are bound)."""
        return self.fields is not None

    def update(self, leaves: Sequence[LeafParams], *, enabled: bool = True, shading: bool = True) -> NDArray[np.int32]:
        """Make the textures hold ``leaves``' veins (none when ``enabled`` is false); returns each
        leaf's layer (-1: no veins). Only fields of keys not held yet are computed (a field is
        kept while a leaf of the update has its key); the style rows are rewritten when they change.
        ``shading=False``: the vein grids only (geometry), see :meth:`VeinFields.update
        <leafview.gpu.vein_field.VeinFields.update>`."""
        if not enabled or not any(p.venation.enabled for p in leaves):
            self.release()
            return np.full(len(leaves), -1, np.int32)
        if self.fields is None:
            self.fields = VeinFields(self.ctx, programs=self.programs)
        drawn = field_leaves(leaves)
        self.fields.update(drawn, shading=shading)
        layers = np.asarray(self.fields.layers, np.int32).reshape(-1)
        rows = style_rows(drawn, layers, self.fields.capacity)
        data = rows.tobytes()
        if self.style is None or self.style.width != rows.shape[0]:
            if self.style is not None:
                self.style.release()
            self.style = self.ctx.texture((rows.shape[0], 1), 4, data, dtype="f4")
            self.style.filter = (moderngl.NEAREST, moderngl.NEAREST)
        elif data != self._rows:
            self.style.write(data)
        self._rows = data
        return layers

    def use(self) -> None:
        """Bind the fields, grids and style rows (nothing without veins)."""
        if self.fields is not None and self.style is not None:
            self.fields.use()
            self.style.use(location=VEIN_STYLE_UNIT)

    def release(self) -> None:
        """Release every texture (idempotent)."""
        if self.fields is not None:
            self.fields.release()
            self.fields = None
        if self.style is not None:
            self.style.release()
            self.style = None
        self._rows = b""
