"""Any leaf's surface as the vertex shader draws it, in one place: a unilobed leaf is Ω with the
shape its veins give it (Chaurasia & Beardsley 2017, eqs 2-6; Hong 2005, ch. 7.2), a lobed leaf
the railroad ties swept between its skeleton and its margin (Mündermann et al. 2003, secs 3.3-4).

:mod:`leafview.deform.surface` evaluates Ω and refuses a lobed leaf (the sweep table is built
here, a layer above it); the functions below take any :class:`LeafParams` and are what the
top-level ``leafview.evaluate``, ``normals``, ``partials`` and ``tessellate`` call, and what framing,
culling and export use where they need the drawn surface in numpy.

A lobed leaf is drawn on :func:`leafview.deform.sweep.lobed_grid` of the grid asked for (u along
each tie, v along the tour of ties), and its :func:`tessellate` mesh is that grid with the
coincident vertices of paired ties welded: one sheet, one boundary loop, (u, v) the texture coordinates: the flat
leaf's position in its texture window (Mündermann et al. 2003, eq. 1; deform.sweep.texture_uv).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.botany.lobe_sweep import sweep_table, weld_grid
from leafview.botany.vein_shape import shape_grid
from leafview.core.blade import Mesh, Partials, grid_uv, uv_arrays
from leafview.core.defaults import DEFAULT_GRID
from leafview.core.params import LeafParams
from leafview.deform import surface as _surface
from leafview.deform.sweep import SweepEval, SweepTable, lobed_grid, sweep_eval

__all__ = ["lobe_table", "sweep_of", "partials", "evaluate", "normals", "tessellate", "drawn_grid", "grid_points"]


def lobe_table(params: LeafParams) -> SweepTable | None:
    """The sweep table of a lobed leaf (None for a unilobed one)."""
    return sweep_table(params.lobes) if params.lobes.enabled else None


def sweep_of(params: LeafParams, uv: ArrayLike) -> SweepEval:
    """The lobed leaf ``params`` at grid coordinates ``uv`` (n, 2), ripples included."""
    table = sweep_table(params.lobes)
    return sweep_eval(table, uv, params.ripple if params.ripple.enabled else None)


def partials(params: LeafParams, u: ArrayLike, v: ArrayLike) -> Partials:
    """Position and first derivatives at (u, v); d²L/dudv of a lobed leaf is not needed (its
    normal has no pinched rows) and is returned as zeros."""
    if not params.lobes.enabled:
        return _surface.partials(params, u, v, vein_grid=shape_grid(params))
    uu, vv = uv_arrays(u, v)
    e = sweep_of(params, np.stack([uu, vv], axis=-1))
    return Partials(e.L, e.Lu, e.Lv, np.zeros_like(e.L))


def evaluate(params: LeafParams, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """Leaf-space points at (u, v)."""
    return partials(params, u, v).L


def normals(params: LeafParams, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """Upper-side unit normals at (u, v)."""
    if not params.lobes.enabled:
        return _surface.normals(params, u, v, vein_grid=shape_grid(params))
    uu, vv = uv_arrays(u, v)
    return sweep_of(params, np.stack([uu, vv], axis=-1)).normal


def drawn_grid(params: LeafParams, grid: tuple[int, int] = DEFAULT_GRID) -> tuple[int, int]:
    """The grid ``params`` is drawn on when ``grid`` is asked for (a lobed leaf's own rows)."""
    return lobed_grid(grid) if params.lobes.enabled else (int(grid[0]), int(grid[1]))


def grid_points(params: LeafParams, grid: tuple[int, int] = DEFAULT_GRID) -> NDArray[np.float64]:
    """Leaf-space points of the grid the leaf is drawn on (for framing and bounds)."""
    nu, nv = drawn_grid(params, grid)
    uv = _surface.drawn_uv(params, grid_uv(nu, nv)).astype(np.float64)
    return evaluate(params, uv[:, 0], uv[:, 1])


def tessellate(params: LeafParams, nu: int = DEFAULT_GRID[0], nv: int = DEFAULT_GRID[1]) -> Mesh:
    """The leaf as a mesh: the (nu × nv) grid of a unilobed leaf, or the welded grid of a lobed
    one (see the module docstring)."""
    if not params.lobes.enabled:
        return _surface.tessellate(params, nu, nv, vein_grid=shape_grid(params))
    gu, gv = lobed_grid((nu, nv))
    uv = grid_uv(gu, gv).astype(np.float64)
    e = sweep_of(params, uv)
    verts, faces = weld_grid(e.L, gu, gv)
    # the welded vertices keep their first grid sample's normal and flat position
    key = {tuple(p): i for i, p in reversed(list(enumerate(e.L.tolist())))}
    first = np.array([key[tuple(p)] for p in verts.tolist()], dtype=np.int64)
    return Mesh(verts, e.normal[first], e.uv[first], faces.astype(np.uint32))
