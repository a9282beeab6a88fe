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
  trimmed so that every segment keeps some margin: the previous one :data:`GAP` of its edge's
  length, and so each segment still to come before that terminal, at least :data:`MIN_ARC` leaf
  sizes each (a zero-length edge still fans), at most a quarter of the arc per end. (Trimming by
  the junction's radius instead, as before, chained at maple's notched base: three junctions in a
  row took the trimmed end of their arcs, and the basal lobe's first ties crossed its own edge.)
  A user valley point (``lobes.valleys``) in that arc within twice the junction's radius replaces
  the nearest point.

Rows. An edge gets the same number n_e of rows on both traversals, a multiple of 4, and the n_e
over both traversals add up to the table's rows exactly (largest remainder, in proportion to
max(edge length, the longer of its two margin arcs)). Since every segment then starts at a
multiple of 4, the grids of rows/2 and rows/4 keep both the anchors and the pairing. The ties are
equally spaced by arc length on the edge (distal s = i/n_e from the start node, basal s = 1 - i/n_e)
and on the margin arc (blended with each foot's nearest margin point, made monotone, which keeps
ties from crossing where the arc is much longer than the edge). The two traversals of an edge read
their feet from one array of n_e + 1 samples, so paired feet are bitwise equal and the shader's
grid welds without cracks.

Folds. A tip's tie runs on along the skeleton's last step (from the foot before the tip through
the tip to the margin), so the first flat triangle from it to the next tie, whose foot is that same
foot before the tip, is collinear: a sliver of zero area, whose normal sweep_eval takes from the
turtle (the paired feet make the tour's central difference zero there). Then :func:`_unfold` moves
the other ties' margin points, one at a time and in order along the margin, until no flat
triangle of the finest grid (``STRIP`` + 1 samples per tie) turns clockwise and no grid normal
(whose tour tangent is the Catmull-Rom central difference) points down; the root's tie and the tip
ties stay.

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

from leafview.botany.lobe_skeleton import Edge, Skeleton, ray_hit, skeleton
from leafview.core.blade import grid_indices
from leafview.core.lobes import TURTLE_KNOTS, BranchTurtle, Lobes
from leafview.deform.sweep import SWEEP_ROWS, SweepTable
from leafview.errors import ParamError

__all__ = ["sweep_table", "build_sweep", "tour", "anchors", "edge_rows", "weld_grid", "VALLEY_REACH", "BLEND"]

VALLEY_REACH = 2.0    # a valley point replaces a junction's anchor within this many radii
BLEND = 0.15          # weight of the nearest-point correspondence in the margin spacing
STRIP = 8             # samples along a tie checked for folds (the finest grid: 9)
UNFOLD_TRIES = 32     # values tried per tie when unfolding
UNFOLD_PASSES = 40    # sweeps of the local search, at most
GAP = 0.25            # a junction's segments keep at least this share of their edge's length as arc ...
MIN_ARC = 0.04        # ... and at least this many leaf sizes (a zero-length edge still fans)
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
        # every segment keeps some arc (GAP of its edge's length, at least MIN_ARC leaf sizes, at most a
        # quarter of what is left), and so do the segments still to come before the next tip
        rest = [sk.edges[trips[j][0]].length for j in range(k, m) if nxt[j] == nxt[k]]
        least = MIN_ARC * sk.size
        span = hi - lo
        lo += min(0.25 * span, max(GAP * sk.edges[trips[k - 1][0]].length, least) / sk.margin.length)
        hi -= min(0.25 * span, (GAP * sum(rest) + least * len(rest)) / sk.margin.length)
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


def _cross(p: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    return p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0]


def _strip_areas(k0: NDArray[np.float64], s0: NDArray[np.float64], k1: NDArray[np.float64], s1: NDArray[np.float64]
                 ) -> NDArray[np.float64]:
    """Signed doubled areas (q, 2 STRIP) of the flat triangles between ties (k0, s0) and (k1, s1),
    each cut at t = i / STRIP, in :func:`leafview.core.blade.grid_indices` order: (A_i, B_i, A_i+1)
    then (A_i+1, B_i, B_i+1), A on the first tie, B on the second."""
    t = np.arange(STRIP + 1) / STRIP
    a = k0[:, None] + t[None, :, None] * (s0 - k0)[:, None]
    b = k1[:, None] + t[None, :, None] * (s1 - k1)[:, None]
    first = _cross(b[:, :-1] - a[:, :-1], a[:, 1:] - a[:, :-1])
    second = _cross(b[:, :-1] - a[:, 1:], b[:, 1:] - a[:, 1:])
    return np.concatenate([first, second], axis=1)


def _window_cost(k: NDArray[np.float64], s: NDArray[np.float64], sliver: NDArray[np.bool_], eps: float
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Defects around the middle tie of m windows of five consecutive ties, feet ``k`` and rims
    ``s`` (m, 5, 2) (k may broadcast): (count, size) of the wrong-way flat triangles of the two quads
    that touch the middle tie (``sliver`` (m, 2) or (2,): skip the quad's first triangle, a tip's
    collinear sliver) plus the downward normals of ties 1-3. The normal of tie i is the sign of
    D(t) × (s_i - k_i), D(t) = (k_i+1 - k_i-1) + t ((s_i+1 - s_i-1) - (k_i+1 - k_i-1)) the central
    difference the Catmull-Rom spline takes at a grid row (:func:`leafview.deform.sweep.sweep_eval`),
    linear in t: checked at t = 0 and 1. A zero difference (the paired feet around a tip) makes
    sweep_eval fall back to the turtle's up axis, so it is no defect."""
    m = len(s)
    kk = np.broadcast_to(k, s.shape)
    count = np.zeros(m)
    size = np.zeros(m)
    for q in range(2):
        ar = _strip_areas(kk[:, 1 + q], s[:, 1 + q], kk[:, 2 + q], s[:, 2 + q])
        ar[:, 0] = np.where(np.broadcast_to(sliver, (m, 2))[:, q], 0.0, ar[:, 0])
        count += np.sum(ar < -eps, axis=1)
        size += np.sum(np.maximum(-ar, 0.0), axis=1)
    for i in (1, 2, 3):
        tie = s[:, i] - kk[:, i]
        for d in (kk[:, i + 1] - kk[:, i - 1], s[:, i + 1] - s[:, i - 1]):
            z = _cross(d, tie)
            scale = np.linalg.norm(d, axis=1) * np.linalg.norm(tie, axis=1)
            bad = z < -1e-9 * scale
            count += bad
            size += np.where(bad, -z, 0.0)
    return count, size


def _unfold(sk: Skeleton, kj: NDArray[np.float64], wj: NDArray[np.float64], tips: NDArray[np.bool_]
            ) -> NDArray[np.float64]:
    """Move margin fractions ``wj`` (one per tie; the root's stays 0) so that no flat triangle between
    consecutive ties turns the wrong way and no grid normal points down: a local search, one tie at
    a time, over UNFOLD_TRIES values between its neighbours' fractions (the ties keep their order
    along the margin), taking the value nearest the old one among those with the fewest defects
    (:func:`_window_cost`). Only ties next to a defect move, so a fold-free sweep is unchanged.
    ``tips`` marks the tip ties (their first triangle towards the next tie is a collinear sliver)."""
    n = len(wj)
    w = wj.copy()
    eps = 1e-12 * sk.size * sk.size
    s = sk.margin.at(w)
    s[0] = kj[0]

    def cost(j: int, cand: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        win = (j + np.arange(-2, 3)) % n
        ss = np.repeat(s[win][None], len(cand), axis=0)
        ss[:, 2] = sk.margin.at(np.mod(cand, 1.0))
        return _window_cost(kj[win], ss, tips[win[1:3]], eps)

    win = (np.arange(n)[:, None] + np.arange(-2, 3)[None]) % n
    for _ in range(UNFOLD_PASSES):
        moved = False
        todo = np.nonzero(_window_cost(kj[win], s[win], tips[win[:, 1:3]], eps)[0])[0]
        for j in todo[todo > 0]:
            if cost(j, np.array([w[j]]))[0][0] == 0:
                continue
            if tips[j]:
                continue
            lo, hi = w[j - 1], (w[j + 1] if j + 1 < n else 1.0)
            cand = np.concatenate([[w[j]], lo + (hi - lo) * (np.arange(1, UNFOLD_TRIES) / UNFOLD_TRIES)])
            c, z = cost(j, cand)
            i = int(np.lexsort((np.abs(cand - w[j]), z, c))[0])
            if (c[i], z[i]) < (c[0], z[0]):
                w[j] = cand[i]
                s[j] = sk.margin.at(w[j])
                moved = True
        if not moved:
            break
    return w


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
    kj = np.concatenate([feet[e][idx] for e, idx in d_rows])
    # a tip's tie runs on along the skeleton's last step: the ray from the foot before the tip
    # through the tip meets the margin at the tie's rim, so the first triangle towards the next tie
    # (k_tip, k_before, a point of the tip's tie) is collinear, exactly zero area (a sliver)
    tips = np.zeros(len(wj), dtype=bool)
    ray = np.zeros((len(wj), 2))
    start = 0
    for (e, direction), (_, idx) in zip(trips, d_rows):
        n = int(n_e[e])
        if direction < 0 and np.isfinite(sk.tip_w[sk.edges[e].end]):
            d = feet[e][n] - feet[e][n - 1]
            hit = ray_hit(sk.margin, feet[e][n], d) if np.linalg.norm(d) > 0.0 else None
            before, after = wj[start - 1], wj[start + 1] if start + 1 < len(wj) else 1.0
            if hit is not None and before < hit < after:
                wj[start], tips[start], ray[start] = hit, True, d / np.linalg.norm(d)
        start += len(idx)
    wj = _unfold(sk, kj, wj, tips)
    s2 = sk.margin.at(wj)
    s2[0] = sk.margin.at(0.0)
    along = np.sum((s2[tips] - kj[tips]) * ray[tips], axis=1)
    s2[tips] = kj[tips] + along[:, None] * ray[tips]     # on the ray to rounding (the chord's sag off)
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
