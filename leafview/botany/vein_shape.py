"""Veins carry the shape (Hong 2005, ch. 7.1-7.2 and App. B; Geng, Hu & Zhang 2014, sec. 5.2.3).

**Edits** (Hong 2005, ch. 7.1): :func:`leafview.botany.vein_edits.edited_points`, where every
vein of order ≤ 2 goes on the flat blade (no jitter, ripple or bending; leaf space); its material
points (its original (u, v)) move by ``new - old``.

**Laplace interpolation** (Hong 2005, ch. 7.2, App. B; :mod:`leafview.botany.laplace`). The
displacement ``d(u, v)`` of the flat blade solves ``Δd = 0`` in vein space q = (u · w(v), v)
(:func:`leafview.botany.vein_field.vein_space`, where a step is about the same length on the leaf
in either direction), with Dirichlet conditions on the veins (``d`` = new - old position along each
moved vein, 0 along every other vein of order ≤ 2, the midrib included) and the free margin as a
Neumann condition (``∂d/∂n = 0``). The veins are rasterised onto the nodes of a regular (nu + 1) ×
(nv + 1) grid over (u, v) ∈ [-1, 1] × [0, 1] (each node takes the nearest vein sample within half
a cell); the pinched base and apex rows are one node each, held at 0.

**Ripple coordinate** (Geng, Hu & Zhang 2014, sec. 5.2.3 and eq. 5). Geng et al. load each secondary
vein as a cantilever from the midrib. With veins, the load ``N(k · veins · w + θ)`` indexes the
secondary through the point rather than the cross-section: ``w(u, v)`` is the v at which the
secondary vein through (u, v) leaves its parent, Laplace-interpolated between neighbouring
secondaries (Dirichlet: w = junction v along each secondary, w = v along the midrib and the
primaries; same operator and margin as ``d``), so the ripple is constant along each secondary and
the veins become the load-bearing beams. A parallel (grass) venation has no transverse beams:
there w = v, as without venation.

**Folding is refused, not clamped.** An edit that would fold the blade through itself raises
:class:`~leafview.errors.ParamError` naming ``venation.edits[i].angle`` (``.bulge`` for a pure
bulge) of the first edit ``i`` with which the fold appears. A fold is a moved vein crossing another
vein of order ≤ 2 in the leaf plane, or a leaf-plane Jacobian determinant of the displaced blade
as drawn (flat blade plus the grid's bilinear displacement) that falls to :data:`MIN_JACOBIAN` of
the flat blade's or below anywhere (:func:`jacobian_ratio`): ≤ 0 is a fold, the margin above 0
catches the creases just short of one, and folds between the sample points.

**The grid** (:func:`vein_grid`): (nv, nu, 4) float32 at the texel centres of
:func:`leafview.deform.surface.vein_grid_uv` (the image textures' (s, t) convention): xyz the
displacement (leaf space, added to the blade before ripples and bending), w the ripple coordinate.
Each texel is the mean of the four solve-grid nodes around its centre. The shader and
:func:`leafview.deform.surface.sample_vein_grid` read it bilinearly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from leafview.botany.laplace import GridMesh, grid_mesh, solve_dirichlet, stiffness
from leafview.botany.vein_edits import edited_points, flat_blade
from leafview.botany.vein_field import halfwidth_table, vein_space_of
from leafview.botany.venation import Vein, edit_slots, vein_tree
from leafview.core.blade import blade_partials
from leafview.core.params import LeafParams
from leafview.core.venation import VeinEdit
from leafview.deform.surface import evaluate, sample_vein_grid, vein_grid_uv
from leafview.errors import ParamError

__all__ = ["GRID_N", "MIN_JACOBIAN", "VeinShape", "solve_shape", "jacobian_ratio", "vein_grid",
           "shape_grid", "veins"]

GRID_N = 64
"""Texels per side of :func:`vein_grid` (the solve grid has one node more per side)."""
MIN_JACOBIAN = 0.05
"""The displaced blade folds (or creases) where its leaf-plane Jacobian determinant falls to this
fraction of the flat blade's (:func:`jacobian_ratio`)."""
_SAMPLE_STEP = 0.25  # vein samples per solve-grid cell (in cells) when rasterising

Arr = NDArray[np.float64]


# -- Laplace interpolation (Hong 2005, ch. 7.2, App. B) ----------------------------------------------
def _rasterise(mesh: GridMesh, nu: int, nv: int, lines: Sequence[Arr],
               values: Sequence[Arr]) -> tuple[NDArray[np.bool_], Arr]:
    """Dirichlet nodes and values from polylines ``lines`` ((N, 2) uv) carrying ``values`` ((N, c)
    per point, linear in between): each node within half a cell of a line takes the value of the
    line sample nearest to it."""
    idx: list[Arr] = []
    vals: list[Arr] = []
    for uv, val in zip(lines, values):
        g = np.stack([(uv[:, 0] + 1.0) * 0.5 * nu, uv[:, 1] * nv], -1)     # node-index space
        if len(g) == 1:
            idx.append(g)
            vals.append(val)
            continue
        m = np.maximum(np.ceil(np.linalg.norm(np.diff(g, axis=0), axis=1) / _SAMPLE_STEP), 1).astype(np.int64)
        seg = np.append(np.repeat(np.arange(len(m)), m), len(m) - 1)
        frac = np.append((np.arange(m.sum()) - np.repeat(np.cumsum(m) - m, m)) / np.repeat(m, m), 1.0)
        idx.append(g[seg] + frac[:, None] * (g[seg + 1] - g[seg]))
        vals.append(val[seg] + frac[:, None] * (val[seg + 1] - val[seg]))
    pos = np.concatenate(idx)
    val = np.concatenate(vals)
    ij = np.rint(pos).astype(np.int64)
    ij[:, 0] = np.clip(ij[:, 0], 0, nu)
    ij[:, 1] = np.clip(ij[:, 1], 0, nv)
    dist = np.max(np.abs(pos - ij), axis=1)
    keep = dist <= 0.5 + 1e-9
    node = mesh.index[ij[keep, 1], ij[keep, 0]]
    dist, val = dist[keep], val[keep]
    order = np.lexsort((dist, node))                   # by node, nearest sample first
    first = order[np.r_[True, node[order][1:] != node[order][:-1]]]
    fixed = np.zeros(mesh.size, bool)
    out = np.zeros((mesh.size, val.shape[1]))
    fixed[node[first]] = True
    out[node[first]] = val[first]
    return fixed, out


class VeinShape(NamedTuple):
    """What :func:`solve_shape` finds: ``values`` (nv + 1, nu + 1, 4) (dx, dy, dz, w) at the solve
    grid's nodes (row 0 at v = 0, column 0 at u = -1), the vein ``tree``, every vein's flat-blade
    points ``old`` and ``new`` and which veins ``moved`` (:func:`edited_points`)."""

    values: Arr
    tree: Sequence[Vein]
    old: list[Arr]
    new: list[Arr]
    moved: NDArray[np.bool_]

    def texels(self) -> NDArray[np.float32]:
        """The (nv, nu, 4) float32 grid: each texel the mean of the four nodes around its centre,
        row 0 at the apex and column 0 at u = +1 (:func:`leafview.deform.surface.vein_grid_uv`)."""
        n = self.values
        cells = 0.25 * (n[:-1, :-1] + n[1:, :-1] + n[:-1, 1:] + n[1:, 1:])
        return np.ascontiguousarray(cells[::-1, ::-1], np.float32)


def solve_shape(params: LeafParams, nu: int = GRID_N, nv: int = GRID_N, *,
                edits: Sequence[VeinEdit] | None = None, tree: Sequence[Vein] | None = None) -> VeinShape:
    """Solve the displacement and the ripple coordinate on the (nv + 1) × (nu + 1) node grid of
    a (nv, nu) vein grid (see the module docstring), for ``edits`` (default: the leaf's). No fold
    check (:func:`vein_grid` does it)."""
    tree = vein_tree(params) if tree is None else tree
    old, new, moved = edited_points(params, tree, edits)
    uu, vv = np.meshgrid(np.linspace(-1.0, 1.0, nu + 1), np.linspace(0.0, 1.0, nv + 1))
    mesh = grid_mesh(vein_space_of(halfwidth_table(params), np.stack([uu, vv], -1)))
    parallel = params.venation.pattern == "parallel"
    lines, values = [], []
    for k, vein in enumerate(tree):
        if vein.order <= 2:
            w = vein.uv[:, 1] if vein.order == 1 or parallel else np.full(len(vein.uv), vein.uv[0, 1])
            lines.append(np.asarray(vein.uv, np.float64))
            values.append(np.concatenate([new[k] - old[k], np.asarray(w, np.float64)[:, None]], axis=1))
    for end in (0.0, 1.0):   # the pinched base and apex: held, w = v
        lines.append(np.stack([np.linspace(-1.0, 1.0, nu + 1), np.full(nu + 1, end)], -1))
        values.append(np.tile([0.0, 0.0, 0.0, end], (nu + 1, 1)))
    fixed, data = _rasterise(mesh, nu, nv, lines, values)
    sol = solve_dirichlet(stiffness(mesh), fixed, data)[mesh.index]
    if parallel:
        sol[..., 3] = vv
    return VeinShape(sol, tree, old, new, moved)


# -- folds ---------------------------------------------------------------------------------------------
def _crossing(shape: VeinShape) -> tuple[int, int] | None:
    """A moved vein of order ≤ 2 crossing another one (not its parent or child) in the leaf plane
    away from both veins' ends where the two did not cross before, as (moved vein, other vein);
    None if there is none."""
    tree, old, new = shape.tree, shape.old, shape.new
    major = [k for k, vein in enumerate(tree) if vein.order <= 2]
    for a in np.flatnonzero(shape.moved).tolist():
        for b in major:
            if b == a or tree[a].parent == b or tree[b].parent == a:
                continue
            if _polylines_cross(new[a][:, :2], new[b][:, :2]) and not _polylines_cross(old[a][:, :2], old[b][:, :2]):
                return int(a), int(b)
    return None


def _polylines_cross(p: Arr, q: Arr, eps: float = 1e-6) -> bool:
    a, b = p[:-1, None], p[1:, None]          # (P, 1, 2)
    c, d = q[None, :-1], q[None, 1:]          # (1, Q, 2)
    r, s = b - a, d - c
    den = r[..., 0] * s[..., 1] - r[..., 1] * s[..., 0]
    ca = c - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ca[..., 0] * s[..., 1] - ca[..., 1] * s[..., 0]) / den
        u = (ca[..., 0] * r[..., 1] - ca[..., 1] * r[..., 0]) / den
    tp = np.arange(len(p) - 1)[:, None] + t     # position along each polyline, in segments
    uq = np.arange(len(q) - 1)[None, :] + u
    hit = ((den != 0) & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
           & (tp > eps) & (tp < len(p) - 1 - eps) & (uq > eps) & (uq < len(q) - 1 - eps))
    return bool(hit.any())


def jacobian_ratio(params: LeafParams, grid: NDArray[np.float32]) -> tuple[float, float, float]:
    """The smallest ratio of the leaf-plane Jacobian determinant of the displaced flat blade (the
    blade plus the grid's displacement, as drawn) to the flat blade's, over the texel centres and
    corners of ``grid`` (the base and apex rows left out: both determinants vanish there), and
    the (u, v) where it is smallest."""
    nv, nu = grid.shape[:2]
    uu, vv = np.meshgrid(np.linspace(-1.0, 1.0, 2 * nu + 1), np.linspace(0.0, 1.0, 2 * nv + 1)[1:-1])
    u, v = uu.ravel(), vv.ravel()
    flat = blade_partials(flat_blade(params), u, v)[0]
    _, du, dv, _ = sample_vein_grid(grid, u, v)
    a, b = flat.Lu[:, :2], flat.Lv[:, :2]
    det0 = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    a, b = a + du[:, :2], b + dv[:, :2]
    det1 = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    ok = np.abs(det0) > 1e-12
    ratio = np.where(ok, det1 / np.where(ok, det0, 1.0), np.inf)
    k = int(np.argmin(ratio))
    return float(ratio[k]), float(u[k]), float(v[k])


def _vein_name(params: LeafParams, tree: Sequence[Vein], k: int) -> str:
    """How an edit names vein ``k`` (vein n of side s), else through its parent, else its index."""
    slots = edit_slots(params)
    for side, ks in slots.items():
        if k in ks:
            return f"vein {ks.index(k)} of side {side:+d}"
    parent = tree[k].parent
    for side, ks in slots.items():
        if parent in ks:
            return f"a secondary of vein {ks.index(parent)} of side {side:+d}"
    return "the midrib" if k == 0 else f"vein {k} of the vein tree"


def _fold(params: LeafParams, shape: VeinShape, grid: NDArray[np.float32]) -> str | None:
    cross = _crossing(shape)
    if cross is not None:
        a, b = (_vein_name(params, shape.tree, k) for k in cross)
        return f"{a} would cross {b}"
    ratio, u, v = jacobian_ratio(params, grid)
    if ratio <= MIN_JACOBIAN:
        return (f"the blade near (u, v) = ({u:.2f}, {v:.2f}) would be squeezed to {max(ratio, 0.0):.0%} of its "
                f"area{' and turned over' if ratio <= 0 else ''}")
    return None


def _refuse_folds(params: LeafParams, shape: VeinShape, grid: NDArray[np.float32]) -> None:
    """Raise ParamError naming the first edit with which the blade folds (module docstring)."""
    reason = _fold(params, shape, grid)
    if reason is None:
        return
    edits = params.venation.edits
    nv, nu = grid.shape[:2]
    for i in range(len(edits)):
        why: str | None = reason
        if i < len(edits) - 1:
            part = solve_shape(params, nu, nv, edits=edits[:i + 1], tree=shape.tree)
            why = _fold(params, part, part.texels())
        if why is not None:
            e = edits[i]
            field = "angle" if e.angle != 0.0 or e.bulge == 0.0 else "bulge"
            what = f"turning vein {e.vein} by {e.angle:g}°" if field == "angle" else f"bowing vein {e.vein} by {e.bulge:g}"
            raise ParamError(f"venation.edits[{i}].{field}",
                             f"{what} folds the blade through itself ({why}): use a smaller {field}")


# -- public --------------------------------------------------------------------------------------------
_CACHE: dict[tuple[Any, ...], NDArray[np.float32]] = {}
_CACHE_SIZE = 64


def vein_grid(params: LeafParams, nu: int = GRID_N, nv: int = GRID_N) -> NDArray[np.float32]:
    """The vein-shape grid (nv, nu, 4) float32 of the leaf (see the module docstring): xyz the
    displacement of the flat blade by its edited veins, w the ripple coordinate; w = v and no
    displacement without venation. Edits that fold the blade raise ParamError. Cached by (shape,
    venation, nu, nv); the result is read-only."""
    if nu < 2 or nv < 2:
        raise ValueError(f"a vein grid needs at least 2×2 texels, got {nu}×{nv}")
    key = (params.shape, params.venation, int(nu), int(nv))
    hit = _CACHE.get(key)
    if hit is not None:
        return hit
    if not params.venation.enabled:
        grid = np.zeros((nv, nu, 4), np.float32)
        grid[..., 3] = vein_grid_uv(nu, nv)[1]           # w = v at the texel centres
    else:
        shape = solve_shape(params, nu, nv)
        grid = shape.texels()
        if params.venation.edits:
            _refuse_folds(params, shape, grid)
    grid.setflags(write=False)
    if len(_CACHE) >= _CACHE_SIZE:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = grid
    return grid


def shape_grid(params: LeafParams) -> NDArray[np.float32] | None:
    """The leaf's :func:`vein_grid` when its venation is enabled (what the shader reads for it),
    else None: the ``vein_grid`` argument of :func:`leafview.deform.surface.evaluate` and the rest
    that makes them the twin of the drawn leaf."""
    return vein_grid(params) if params.venation.enabled else None


def veins(params: LeafParams) -> list[Vein]:
    """:func:`leafview.botany.venation.vein_tree` with the edits applied: every vein's points on
    the final surface (blade, vein-driven displacement, ripples, bending), leaf space."""
    tree = vein_tree(params)
    grid = vein_grid(params)
    return [replace(vein, points=evaluate(params, vein.uv[:, 0], vein.uv[:, 1], vein_grid=grid)) for vein in tree]
