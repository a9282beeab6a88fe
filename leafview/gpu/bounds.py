"""Culling data of leaf records on the GPU: ``shaders/leaf_bounds.comp`` evaluates every record
at every level's (u, v) grid with the code the vertex shader draws with and writes one
:data:`~leafview.gpu.layout.SPECIES_CULL_BLOCK` row per record (a leaf-space bounding sphere and
the outline error of each coarser level), all records in one dispatch per chunk. Nothing per
record happens in Python.

Lobed records are evaluated on their swept surface (``lobe_eval``, the sweep tables bound at
``LOBE_UNIT`` by the caller) unless the features hold ``LEAF_NO_LOBES``; their grids are then the
lobed ones (:func:`leafview.gpu.scene.lobed_levels`): :class:`~leafview.gpu.scene.SceneRenderer`
runs lobed and unlobed records apart, each on its grids.

The numpy reference is :func:`leafview.gpu.scene.cull_rows_from_points` (through
:func:`leafview.gpu.scene.species_cull`, which evaluates lobed species with
:func:`leafview.botany.leaf_surface.evaluate`); tests compare the rows read back here with it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.gpu.layout import LEAF_BLOCK, LEAVES_BINDING, SPECIES_BINDING, SPECIES_CULL_BLOCK
from leafview.gpu.limits import MAX_RESOURCE_BYTES, ensure_alive
from leafview.gpu.owner import GLObjects
from leafview.gpu.prepare import LeafPrepare
from leafview.gpu.programs import ProgramCache

__all__ = ["LeafBounds", "MAX_COARSE_SAMPLES", "bounds_defines"]

MAX_COARSE_SAMPLES = 1024
"""The most grid samples kept per invocation (a local array): level 0 when the coarser levels'
samples are among its own (the default levels: 153), else the coarser levels' together. The
default levels are far below it."""

_LOCAL = 64


def bounds_defines(grids: Sequence[tuple[int, int]]) -> dict[str, int]:
    """The compile-time grid defines of ``leaf_bounds.comp`` for 1-4 levels ``grids`` (finest
    first); raises ValueError when neither level 0 nor the coarser levels together fit in
    :data:`MAX_COARSE_SAMPLES`."""
    if not 1 <= len(grids) <= 4:
        raise ValueError("between 1 and 4 levels of detail")
    levels = [(int(nu), int(nv)) for nu, nv in grids]
    padded = levels + [(2, 2)] * (4 - len(levels))
    fu, fv = levels[0]
    nested = fu * fv <= MAX_COARSE_SAMPLES and all((fu - 1) % (cu - 1) == 0 and (fv - 1) % (cv - 1) == 0
                                                   for cu, cv in levels[1:])
    defines = {"BOUNDS_LEVELS": len(levels), "BOUNDS_NESTED": int(nested)}
    offset = 0
    for k, (nu, nv) in enumerate(padded):
        defines[f"BOUNDS_NU{k}"], defines[f"BOUNDS_NV{k}"] = nu, nv
        if k:
            defines[f"BOUNDS_OFS{k}"] = offset
            defines[f"BOUNDS_SU{k}"] = (fu - 1) // (nu - 1) if nested and k < len(levels) else 1
            defines[f"BOUNDS_SV{k}"] = (fv - 1) // (nv - 1) if nested and k < len(levels) else 1
            if k < len(levels):
                offset += nu * nv
    if not nested and offset > MAX_COARSE_SAMPLES:
        raise ValueError(f"the coarser levels hold {offset} grid samples together, at most {MAX_COARSE_SAMPLES}")
    defines["BOUNDS_COARSE"] = max(offset, 1)
    return defines


class LeafBounds:
    """:meth:`run`: the culling rows of leaf records for the levels ``grids``, computed by
    ``leaf_bounds.comp`` (compiled once per grid set and feature permutation through
    ``programs``).

    The caller binds what leaf evaluation reads besides the rows (the jitter texture and the
    ripple signals) before :meth:`run`."""

    def __init__(self, ctx: moderngl.Context, programs: ProgramCache, prepare: LeafPrepare,
                 grids: Sequence[tuple[int, int]]) -> None:
        self.ctx, self.programs, self.prepare = ctx, programs, prepare
        self.grids = tuple((int(nu), int(nv)) for nu, nv in grids)
        self._grid_defines = bounds_defines(self.grids)

    def run(self, records: NDArray[Any], variation: float, features: Mapping[str, object] | None = None,
            *, block_limit: int = MAX_RESOURCE_BYTES) -> NDArray[Any]:
        """SPECIES_CULL_BLOCK rows of the LEAF_BLOCK ``records`` (their derived members are
        filled here by the prepare pass), for leaves varying by ± ``variation``. ``features``:
        the leaf program's feature defines (:func:`~leafview.gpu.layout.feature_defines`, and
        :func:`~leafview.gpu.layout.lobe_defines`: without ``LEAF_NO_LOBES`` lobed records are swept).
        Records go up in chunks of at most ``block_limit`` bytes."""
        out = np.zeros(len(records), SPECIES_CULL_BLOCK.dtype)
        if not len(records):
            return out
        shader = self.programs.compute("leaf_bounds.comp", defines={**(features or {}), **self._grid_defines})
        groups = int(self.ctx.info["GL_MAX_COMPUTE_WORK_GROUP_COUNT"][0])
        chunk = max(1, min(min(block_limit, MAX_RESOURCE_BYTES) // LEAF_BLOCK.nbytes, groups * _LOCAL))
        shader["variation"] = float(variation)
        for start in range(0, len(records), chunk):
            part = np.ascontiguousarray(records[start:start + chunk])
            n = len(part)
            ensure_alive(self.ctx, "measuring the leaves of a scene")
            local = GLObjects()
            try:
                rows = local.own(self.ctx.buffer(part))
                self.prepare.run(rows, n)
                cull = local.own(self.ctx.buffer(reserve=n * SPECIES_CULL_BLOCK.nbytes))
                rows.bind_to_storage_buffer(LEAVES_BINDING)
                cull.bind_to_storage_buffer(SPECIES_BINDING)
                shader["count"] = n
                shader.run(group_x=-(-n // _LOCAL))
                self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)
                out[start:start + n] = np.frombuffer(cull.read(), SPECIES_CULL_BLOCK.dtype)
            finally:
                local.release()
        return out
