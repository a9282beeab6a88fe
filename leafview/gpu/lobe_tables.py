"""The sweep tables of a draw's lobed leaves, bound together as one array texture.

A lobed leaf (``LeafParams.lobes`` with an outline, :mod:`leafview.core.lobes`) is drawn by the
same ``leaf.vert`` as every other leaf: its surface is swept between the medial-axis skeleton and
the margin (Mündermann et al. 2003, secs 3.3-4), from a :class:`~leafview.deform.sweep.SweepTable`
of railroad ties that ``shaders/leaf_eval.glsl`` (``lobe_eval``) interpolates exactly as
:func:`~leafview.deform.sweep.sweep_eval` does. :class:`LobeTables` holds those tables: one layer of
an RGBA32F ``sampler2DArray`` (``leaf_lobe_table`` at ``LOBE_UNIT``) per distinct
:class:`~leafview.core.lobes.Lobes` value, N texels wide (the ties) and four texel rows high
(:func:`~leafview.deform.sweep.table_texels`). :meth:`LobeTables.update` returns each leaf's layer (-1 unlobed), to be
packed into the records (``pack_leaves(..., lobe_layers=layers)``); the prepare pass folds it into
the branch code the vertex stage reads.

A lobed leaf is drawn on a grid of its own (:func:`~leafview.deform.sweep.lobed_grid`): its rows must land on the ties,
so that the two sides of each skeleton edge, whose ties the table pairs, meet without a crack.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.botany.lobe_sweep import sweep_table
from leafview.core.lobes import Lobes
from leafview.core.params import LeafParams
from leafview.deform.sweep import ROW_STEPS, SWEEP_ROWS, SweepTable, lobed_grid, table_texels
from leafview.errors import GpuLimitError, ParamError
from leafview.gpu.layout import LOBE_TABLE_ROWS, LOBE_UNIT

__all__ = ["LobeTables", "lobe_keys", "lobed_grid", "ROW_STEPS"]

def lobe_keys(leaves: Sequence[LeafParams]) -> list[Lobes]:
    """The distinct :class:`Lobes` of the lobed leaves among ``leaves``, in order of first use:
    layer i of the array holds ``keys[i]`` (the layers :meth:`LobeTables.update` returns)."""
    keys: dict[Lobes, int] = {}
    for p in leaves:
        if p.lobes.enabled:
            keys.setdefault(p.lobes, len(keys))
    return list(keys)


class LobeTables:
    """The sweep-table array of a draw (see the module docstring); release with :meth:`release`.

    ``table_of`` builds a leaf's table from its :class:`Lobes` (default
    :func:`leafview.botany.lobe_sweep.sweep_table`); tables are built once per key and kept while
    an update still has the key."""

    def __init__(self, ctx: moderngl.Context,
                 table_of: Callable[[Lobes], SweepTable] = sweep_table) -> None:
        self.ctx = ctx
        self.table_of = table_of
        self.texture: moderngl.TextureArray | None = None
        self.keys: list[Lobes] = []
        self._texels: dict[Lobes, NDArray[np.float32]] = {}
        self.uploads = 0   # bytes written to the texture (edit-cost tests)

    @property
    def active(self) -> bool:
        """Whether a lobed leaf is held (the texture exists)."""
        return self.texture is not None

    def texels(self, key: Lobes) -> NDArray[np.float32]:
        """The texels of ``key``'s table (built and checked on first use)."""
        found = self._texels.get(key)
        if found is None:
            table = self.table_of(key)
            if table.rows != SWEEP_ROWS:
                raise ParamError("lobes", f"a sweep table of {table.rows} ties; the GPU path draws {SWEEP_ROWS}")
            found = table_texels(table)
            if not np.isfinite(found).all():
                raise ParamError("lobes", "the sweep table holds a non-finite value")
            self._texels[key] = found
        return found

    def update(self, leaves: Sequence[LeafParams]) -> NDArray[np.int32]:
        """Make the array hold the tables of ``leaves``' lobes; returns each leaf's layer (-1:
        unlobed). Tables of keys not held yet are built; the texture is written only when the
        keys changed."""
        keys = lobe_keys(leaves)
        if not keys:
            self.release()
            return np.full(len(leaves), -1, np.int32)
        limit = int(self.ctx.info.get("GL_MAX_ARRAY_TEXTURE_LAYERS", 2048))
        if len(keys) > limit:
            raise GpuLimitError("lobes", f"{len(keys):,} distinct lobed leaves need as many texture layers, above "
                                f"this driver's GL_MAX_ARRAY_TEXTURE_LAYERS = {limit}")
        layers = [self.texels(k) for k in keys]         # every table first: a bad one changes nothing
        self._texels = {k: t for k, t in zip(keys, layers)}
        if keys != self.keys or self.texture is None:
            data = np.ascontiguousarray(np.stack(layers), np.float32)   # (layers, 4 rows, N, 4)
            if self.texture is None or self.texture.size != (SWEEP_ROWS, LOBE_TABLE_ROWS, len(keys)):
                if self.texture is not None:
                    self.texture.release()
                    self.texture = None
                self.texture = self.ctx.texture_array((SWEEP_ROWS, LOBE_TABLE_ROWS, len(keys)), 4, dtype="f4")
                self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self.texture.write(data.tobytes())
            self.uploads += int(data.nbytes)
            self.keys = keys
        index = {k: i for i, k in enumerate(keys)}
        return np.array([index[p.lobes] if p.lobes.enabled else -1 for p in leaves], np.int32)

    def use(self) -> None:
        """Bind the array at ``LOBE_UNIT`` (nothing without lobed leaves)."""
        if self.texture is not None:
            self.texture.use(location=LOBE_UNIT)

    bind = use

    def release(self) -> None:
        """Release the texture (idempotent); built tables are forgotten too."""
        if self.texture is not None:
            self.texture.release()
            self.texture = None
        self.keys = []
        self._texels = {}
