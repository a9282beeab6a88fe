"""The railroad ties of a lobed leaf (Mündermann et al. 2003, secs 3.3-4): the
:class:`~leafview.deform.sweep.SweepTable` built from a :class:`~leafview.core.lobes.Lobes` group.

Tour. From the root b = C(0) the skeleton tree (:mod:`leafview.botany.lobe_skeleton`) is walked
depth first, the children of each node in clockwise order; every edge is traversed twice, distally
(its ties on the side the clockwise margin reaches first) and basally. One *segment* is one
traversal of one edge (Mündermann et al. split at branching points too; our edges already end
there): its ties run from the traversal's start node and start anchor to its end node and end
anchor. Anchors, one per node visit:

* the root: b, margin fraction 0 at the start of the tour and 1 at its end;
* a terminal k_T: where the skeleton's tangent at k_T, extended, meets the margin (sec. 3.3);
* a junction k_J: the margin point nearest k_J within the arc from the previous anchor to the next
  terminal's anchor (sec. 3.3, "the point of the segment [s, s_T] closest to k_J"), the arc's ends
  trimmed by the junction's radius (at most a quarter of the arc each): where the junction's disc
  touches the previous anchor, as at a pointed base, the segment would otherwise collapse onto the
  skeleton; a user valley point (``lobes.valleys``) in that arc within twice the junction's radius
  replaces it.

Rows. An edge gets the same number n_e of rows on both traversals, a multiple of 4, and the n_e
over both traversals add up to the table's rows exactly (largest remainder, in proportion to
max(edge length, the longer of its two margin arcs)). Since every segment then starts at a
multiple of 4, the grids of rows/2 and rows/4 keep both the anchors and the pairing. The ties are
equally spaced by arc length on the edge (distal s = i/n_e from the start node, basal s = 1 - i/n_e)
and on the margin arc (blended with each foot's nearest margin point, made monotone, which keeps
ties from crossing where the arc is much longer than the edge). The two traversals of an edge read
their feet from one array of n_e + 1 samples, so paired feet are bitwise equal and the shader's
grid welds without cracks.

Turtle (sec. 4, eqs 2-3 and the per-branch functions). Walking each edge in small steps, the flat
heading H is the skeleton's direction, U = +z, L = U × H; the extra rotation rates of
``lobes.branches`` (bend about L lifting H towards U, twist about H, turn about U, degrees per
leaf length, linear between the knots at s = 0, 1/3, 2/3, 1 of the branch) accumulate into a
rotation Q (world = Q · flat): Q ← Q F R F^T with F = [H L U]. The foot moves by Q ΔK, so
X(s) = X(0) + ∫ Q H ds, kept as K + D with D = ∫ (Q - I) H ds: without edits D = 0 and Q = I
exactly, and a branch without edited ancestors is bit-for-bit the flat leaf. A child branch
starts from its parent's X and Q at the junction. Per tie: origin X_j, rim X_j + Q_j (s_j - k_j),
up Q_j ẑ, length |s_j - k_j|, flat (k_j, s_j), margin w_j. Edits on branches the skeleton does
not have are ignored (pruning changes the count).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.botany.lobe_skeleton import Edge, Skeleton, skeleton
from leafview.core.blade import grid_indices
from leafview.core.lobes import TURTLE_KNOTS, BranchTurtle, Lobes
from leafview.deform.sweep import SWEEP_ROWS, SweepTable
from leafview.errors import ParamError

__all__ = ["sweep_table", "build_sweep", "tour", "anchors", "edge_rows", "weld_grid", "VALLEY_REACH", "BLEND"]

VALLEY_REACH = 2.0    # a valley point replaces a junction's anchor within this many radii
BLEND = 0.15          # weight of the nearest-point correspondence in the margin spacing
_KNOTS = np.linspace(0.0, 1.0, TURTLE_KNOTS)


def tour(sk: Skeleton) -> list[tuple[int, int]]:
    """The traversals (edge, +1 distal / -1 basal) of the depth-first, clockwise tour."""
    out: list[tuple[int, int]] = []
    stack: list[tuple[int, int]] = [(e, 1) for e in reversed(sk.children[sk.root])]
    while stack:
        e, d = stack.pop()
        out.append((e, d))
        if d > 0:
            stack.append((e, -1))
            stack.extend((c, 1) for c in reversed(sk.children[sk.edges[e].end]))
    return out


def _visit_node(sk: Skeleton, trav: tuple[int, int]) -> int:
    e, d = trav
    return sk.edges[e].start if d > 0 else sk.edges[e].end


def anchors(sk: Skeleton, trips: list[tuple[int, int]], valleys: tuple[tuple[float, float], ...] = ()
            ) -> NDArray[np.float64]:
    """Margin fractions of the anchors at the start of each traversal, plus 1 (the root again)."""
    m = len(trips)
    nodes = [_visit_node(sk, t) for t in trips]
    w = np.zeros(m + 1)
    w[m] = 1.0
    nxt = np.ones(m + 1)   # the next terminal's anchor after visit k
    for k in range(m - 1, -1, -1):
        nxt[k] = nxt[k + 1] if k + 1 > m - 1 or not np.isfinite(sk.tip_w[nodes[k + 1]]) else sk.tip_w[nodes[k + 1]]
    vw = [sk.margin.nearest(v) for v in valleys]
    for k in range(1, m):
        n = nodes[k]
        if np.isfinite(sk.tip_w[n]):
            w[k] = max(sk.tip_w[n], w[k - 1])
            continue
        lo, hi = w[k - 1], max(nxt[k], w[k - 1])
        # keep clear of the arc's ends by the junction's radius (at most a quarter of the arc): where
        # the junction's disc touches the previous anchor (a pointed base) the segment would collapse
        cut = min(0.25 * (hi - lo), sk.radii[n] / sk.margin.length)
        lo, hi = lo + cut, hi - cut
        p = sk.nodes[n]
        near = [(float(np.linalg.norm(np.asarray(v) - p)), x) for v, x in zip(valleys, vw)
                if lo < x < hi and np.linalg.norm(np.asarray(v) - p) <= VALLEY_REACH * sk.radii[n]]
        w[k] = min(near)[1] if near else sk.margin.nearest(p, lo, hi)
    return w


def edge_rows(sk: Skeleton, trips: list[tuple[int, int]], w: NDArray[np.float64], rows: int) -> NDArray[np.int64]:
    """Rows n_e per edge (each traversal): multiples of 4 whose double sum is ``rows``."""
    ne = len(sk.edges)
    units = rows // 8
    if rows % 8 or rows < 8:
        raise ParamError("rows", f"{rows} ties: the sweep needs a multiple of 8")
    if ne > units:
        raise ParamError("lobes.prune", f"the skeleton has {ne} edges but {rows} ties hold at most {units}: "
                                        f"raise lobes.prune")
    arc = np.zeros(ne)
    for k, (e, _) in enumerate(trips):
        arc[e] = max(arc[e], (w[k + 1] - w[k]) * sk.margin.length)
    weight = np.maximum(np.array([e.length for e in sk.edges]), arc) + 1e-12
    ideal = units * weight / weight.sum()
    u = np.maximum(1, np.floor(ideal)).astype(np.int64)
    while u.sum() < units:
        u[int(np.argmax(ideal - u))] += 1
    while u.sum() > units:
        free = np.where(u > 1, ideal - u, np.inf)
        u[int(np.argmin(free))] -= 1
    return 4 * u


def _along(edge: Edge, s: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points of the edge polyline at arc lengths ``s``."""
    cum = edge.arc()
    return np.stack([np.interp(s, cum, edge.points[:, 0]), np.interp(s, cum, edge.points[:, 1])], axis=1)


def _rotation(bend: float, twist: float, turn: float) -> NDArray[np.float64]:
    """Body-frame rotation (basis H, L, U) of the turn about U, bend of H towards U, twist about H."""
    c, s = np.cos(turn), np.sin(turn)
    ru = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    c, s = np.cos(bend), np.sin(bend)
    rl = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    c, s = np.cos(twist), np.sin(twist)
    rh = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return ru @ rl @ rh


def _turtle_edge(edge: Edge, ts: NDArray[np.float64], feet: NDArray[np.float64], d0: NDArray[np.float64],
                 q0: NDArray[np.float64], edit: BranchTurtle | None
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """D (n, 3) and Q (n, 3, 3) at the tie samples (arc lengths ``ts``, points ``feet``)."""
    n = len(ts)
    if edit is None:    # Q constant along the edge: D grows by (Q - I) ΔK
        qi = q0 - np.eye(3)
        dk = np.zeros((n, 3))
        dk[:, :2] = feet - feet[0]
        d = d0 + dk @ qi.T if np.any(qi) else np.repeat(d0[None], n, axis=0)
        d[0] = d0
        return d, np.repeat(q0[None], n, axis=0)
    cum = edge.arc()
    fine, idx = np.unique(np.concatenate([ts, cum]), return_inverse=True)
    pts = _along(edge, fine)
    pts[idx[:n]] = feet
    rates = np.radians(np.stack([np.interp(edge.s0 + (edge.s1 - edge.s0) * fine / max(edge.length, 1e-30),
                                           _KNOTS, k) for k in (edit.bend, edit.twist, edit.turn)], axis=1))
    ds_all, qs = np.zeros((len(fine), 3)), np.zeros((len(fine), 3, 3))
    d, q = d0.copy(), q0.copy()
    eye = np.eye(3)
    for i in range(len(fine)):
        ds_all[i], qs[i] = d, q
        if i + 1 == len(fine):
            break
        dk = np.array([pts[i + 1, 0] - pts[i, 0], pts[i + 1, 1] - pts[i, 1], 0.0])
        step = float(np.hypot(dk[0], dk[1]))
        if step <= 0.0:
            continue
        d = d + (q - eye) @ dk
        ang = 0.5 * (rates[i] + rates[i + 1]) * step
        if np.any(ang):
            h = dk / step
            f = np.array([h, [-h[1], h[0], 0.0], [0.0, 0.0, 1.0]]).T
            q = q @ f @ _rotation(*ang) @ f.T
    return ds_all[idx[:n]], qs[idx[:n]]


def build_sweep(lobes: Lobes, rows: int = SWEEP_ROWS, blend: float = BLEND) -> SweepTable:
    """The sweep table of ``lobes`` (see the module docstring); uncached."""
    sk = skeleton(lobes)
    trips = tour(sk)
    w = anchors(sk, trips, lobes.valleys)
    n_e = edge_rows(sk, trips, w, rows)
    edits = {b.branch: b for b in lobes.branches}

    # per edge, once: feet at s = i / n_e, then D and Q along the tree from the root
    feet: dict[int, NDArray[np.float64]] = {}
    dd: dict[int, NDArray[np.float64]] = {}
    qq: dict[int, NDArray[np.float64]] = {}
    for ei, edge in enumerate(sk.edges):    # breadth first: parents before children
        n = int(n_e[ei])
        ts = edge.length * np.arange(n + 1) / n
        f = _along(edge, ts)
        f[0], f[-1] = sk.nodes[edge.start], sk.nodes[edge.end]
        pe = sk.parent_edge[edge.start]
        if pe < 0:
            d0, q0 = np.zeros(3), np.eye(3)
        else:
            d0, q0 = dd[pe][-1], qq[pe][-1]
        d, q = _turtle_edge(edge, ts, f, d0, q0, edits.get(edge.branch))
        if pe >= 0:
            f[0] = feet[pe][-1]
            d[0], q[0] = dd[pe][-1], qq[pe][-1]
        feet[ei], dd[ei], qq[ei] = f, d, q

    d_rows, w_rows = [], []
    pts, wd = sk.margin.points, sk.margin.w[:-1]
    for k, (e, direction) in enumerate(trips):
        n = int(n_e[e])
        i = np.arange(n)
        idx = i if direction > 0 else n - i
        wa, wb = w[k], w[k + 1]
        g = i / n
        if blend > 0.0 and wb - wa > 1e-12:
            sel = np.nonzero((wd >= wa) & (wd <= wb))[0]
            if len(sel):
                f = feet[e][idx]
                near = np.argmin(np.sum((f[:, None, :] - pts[sel][None]) ** 2, axis=2), axis=1)
                gn = np.maximum.accumulate((wd[sel][near] - wa) / (wb - wa))
                gn[0] = 0.0
                g = (1.0 - blend) * g + blend * np.clip(gn, 0.0, 1.0)
        w_rows.append(wa + (wb - wa) * g)
        d_rows.append((e, idx))
    wj = np.concatenate(w_rows)
    s2 = sk.margin.at(wj)
    s2[0] = sk.margin.at(0.0)
    kj = np.concatenate([feet[e][idx] for e, idx in d_rows])
    dj = np.concatenate([dd[e][idx] for e, idx in d_rows])
    qj = np.concatenate([qq[e][idx] for e, idx in d_rows])
    k3 = np.zeros((len(kj), 3))
    k3[:, :2] = kj
    s3 = np.zeros_like(k3)
    s3[:, :2] = s2
    qi = qj - np.eye(3)
    origin = k3 + dj
    rim = s3 + dj + np.einsum("nij,nj->ni", qi, s3 - k3)
    up = np.ascontiguousarray(qj[:, :, 2])
    length = np.linalg.norm(s2 - kj, axis=1)
    flat = np.concatenate([kj, s2], axis=1)
    arrays = [origin, rim, up, length, flat, wj]
    for a in arrays:
        a.flags.writeable = False
    return SweepTable(origin, rim, up, length, flat, wj, cup=float(lobes.cup))


@lru_cache(maxsize=32)
def sweep_table(lobes: Lobes, rows: int = SWEEP_ROWS) -> SweepTable:
    """The sweep table of ``lobes`` with ``rows`` ties (cached on the hashable ``lobes``)."""
    return build_sweep(lobes, rows)


def weld_grid(positions: ArrayLike, nu: int, nv: int, tol: float = 1e-9
              ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The grid mesh of ``positions`` (nu·nv, 3), u fastest, triangles in
    :func:`leafview.core.blade.grid_indices` order, with vertices that agree to ``tol`` of the
    mesh's size merged, and the triangles that merging collapses (two corners welded: zero area)
    dropped: ``(vertices, faces)``. Collinear triangles with three distinct corners stay: at a
    skeleton tip the tie runs on along the skeleton's tangent, and dropping that sliver would
    open a slit in the sheet."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(p) != nu * nv:
        raise ValueError(f"{len(p)} positions for a {nu}×{nv} grid")
    size = float(np.max(np.ptp(p, axis=0))) or 1.0
    key = np.round(p / (tol * size)).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)          # keep the vertices in grid order
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    verts = p[first[order]]
    faces = rank[inv.ravel()][grid_indices(nu, nv).astype(np.int64)]
    distinct = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return verts, faces[distinct]
