"""The medial-axis skeleton of a lobed leaf's margin (Mündermann et al. 2003, sec. 3.2).

The margin (``Lobes.outline``, a closed uniform cubic B-spline, C(0) the base, clockwise) is
sampled densely by arc length; the Voronoi vertices of the samples that lie inside the margin,
joined by the Voronoi ridges between samples that are not neighbours along the margin,
approximate its medial axis (Blum's loci of maximal inscribed discs, which Mündermann et al.
compute with Fortune's sweep). The radius of a skeleton point is its distance to the nearest
margin sample.

Cleaning (our reading, written down because the paper leaves it to the reader):

* the graph is made a tree by its minimum spanning tree (near-co-circular samples leave tiny
  cycles of Voronoi vertices);
* pruning removes, one at a time and shortest first, a terminal branch (tip to nearest junction)
  whose length past the junction's disc, ``length - (r_junction - r_tip)``, is below
  ``lobes.prune`` leaf lengths: a hair that only reaches a margin wiggle is nearly as long as
  the radius it loses, a real lobe is much longer;
* degree-2 chains become one edge each, resampled by arc length and lightly smoothed (Mündermann
  et al. approximate the skeleton by splines; a few Laplacian passes with the ends held do the
  same job here and keep junctions shared);
* the root is the base b = C(0), joined by a straight edge to the nearest skeleton point, with
  distances stretched by 1 + 4 (1 - cos θ), θ the angle from the margin's inward normal at b
  (the point splits an edge there, or is snapped to a node
  within a few samples): at a cordate base the nearest point overall can lie off to one side, on
  a basal lobe's axis, and the root edge would then cut across the sweep's first segments.

Branches (numbered as ``Lobes.branches`` documents): branch 0 runs from the root to the terminal
whose tip anchor lies highest (+y); every other branch starts at a junction on a branch already
numbered and follows, at each junction, the child with the longest path to a tip; they are
numbered by the clockwise order of their tips around the margin from the base. Tip anchors are
where the skeleton's tangent at the tip, extended, meets the margin (Mündermann et al. 2003,
sec. 3.3), falling back to the nearest margin point.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from scipy.spatial import Voronoi, cKDTree

from leafview.core.bspline import derivative_closed, evaluate_closed
from leafview.core.lobes import Lobes
from leafview.errors import ParamError

__all__ = ["Margin", "Edge", "Skeleton", "margin_of", "skeleton", "build_skeleton", "ray_hit", "VORONOI_SAMPLES"]

VORONOI_SAMPLES = 1000     # margin samples for the Voronoi diagram
_TABLE_PER_CONTROL = 64    # dense arc-length table per control point
_MIN_GAP = 3               # ridges between samples closer than this along the margin are not medial
_SMOOTH_PASSES = 4
ROOT_SLANT = 4.0           # how much a slanting root edge counts longer (see _attach_root)


@dataclass(frozen=True, eq=False)
class Margin:
    """The margin with an arc-length table: ``w`` (n + 1,) arc-length fractions 0 … 1 at the
    B-spline parameters ``t`` (n + 1,), the dense points ``points`` (n, 2) at ``t[:-1]``."""

    ctrl: NDArray[np.float64]
    t: NDArray[np.float64]
    w: NDArray[np.float64]
    points: NDArray[np.float64]
    length: float

    def at(self, w: ArrayLike) -> NDArray[np.float64]:
        """Margin points at arc-length fractions ``w`` (0 and 1 are the base)."""
        w = np.asarray(w, dtype=np.float64)
        return evaluate_closed(self.ctrl, np.interp(w, self.w, self.t))

    def nearest(self, p: ArrayLike, lo: float = 0.0, hi: float = 1.0) -> float:
        """Arc-length fraction of the dense margin point nearest ``p`` with ``lo <= w <= hi``
        (``lo`` when the range holds no dense point)."""
        w = self.w[:-1]
        sel = np.nonzero((w >= lo) & (w <= hi))[0]
        if len(sel) == 0:
            return float(lo)
        d = np.sum((self.points[sel] - np.asarray(p, dtype=np.float64)) ** 2, axis=1)
        return float(w[sel[int(np.argmin(d))]])


@dataclass(frozen=True, eq=False)
class Edge:
    """One skeleton edge, oriented away from the root: polyline ``points`` (m, 2) from node
    ``start`` to node ``end`` (ends equal to the node positions), radii along it, its length,
    its branch and the branch's arc-length fraction ``s0`` … ``s1`` over it."""

    start: int
    end: int
    points: NDArray[np.float64]
    radii: NDArray[np.float64]
    length: float
    branch: int
    s0: float
    s1: float

    def arc(self) -> NDArray[np.float64]:
        """Cumulative arc length at each polyline point."""
        return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(self.points, axis=0), axis=1))])


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A rooted skeleton tree (see the module docstring). ``nodes`` (K, 2) and ``radii`` (K,) of
    the root, junctions and terminals; ``edges``; ``parent_edge[k]`` (-1 at the root);
    ``children[k]`` the child edges of node k in clockwise order; ``terminals`` the tips in
    clockwise order; ``tip_w[k]`` the tip anchor's arc-length fraction (NaN off tips);
    ``branches[b]`` the edges of branch b from its base to its tip."""

    margin: Margin
    nodes: NDArray[np.float64]
    radii: NDArray[np.float64]
    root: int
    edges: tuple[Edge, ...]
    parent_edge: tuple[int, ...]
    children: tuple[tuple[int, ...], ...]
    terminals: tuple[int, ...]
    tip_w: NDArray[np.float64]
    branches: tuple[tuple[int, ...], ...]
    size: float

    def degree(self, k: int) -> int:
        return len(self.children[k]) + (self.parent_edge[k] >= 0)


def _frozen(a: NDArray[np.float64]) -> NDArray[np.float64]:
    a = np.ascontiguousarray(a, dtype=np.float64)
    a.flags.writeable = False
    return a


@lru_cache(maxsize=32)
def _margin(outline: tuple[tuple[float, float], ...]) -> Margin:
    ctrl = np.asarray(outline, dtype=np.float64)
    n = max(4096, _TABLE_PER_CONTROL * len(ctrl))
    t = np.arange(n + 1) / n
    p = evaluate_closed(ctrl, t)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    total = float(cum[-1])
    return Margin(_frozen(ctrl), _frozen(t), _frozen(cum / total), _frozen(p[:-1]), total)


def margin_of(lobes: Lobes) -> Margin:
    """The margin of ``lobes`` with its arc-length table (cached)."""
    if not lobes.outline:
        raise ParamError("lobes.outline", "not a lobed leaf: the outline is empty")
    return _margin(lobes.outline)


def _medial_graph(margin: Margin, n: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Voronoi vertices inside the margin and the medial ridges between them (as a tree)."""
    samples = margin.at(np.arange(n) / n)
    vor = Voronoi(samples)
    poly = shapely.Polygon(margin.points)
    inside = shapely.contains_xy(poly, vor.vertices[:, 0], vor.vertices[:, 1])
    rp = np.asarray(vor.ridge_points)
    rv = np.asarray(vor.ridge_vertices)
    gap = np.abs(rp[:, 0] - rp[:, 1])
    gap = np.minimum(gap, n - gap)
    ok = (rv >= 0).all(axis=1) & (gap >= _MIN_GAP)
    ok[ok] &= inside[rv[ok, 0]] & inside[rv[ok, 1]]
    rv = rv[ok]
    used, inv = np.unique(rv.ravel(), return_inverse=True)
    pts = vor.vertices[used]
    e = inv.reshape(-1, 2)
    if len(e) == 0:
        raise ParamError("lobes.outline", "the margin has no medial axis (too thin or degenerate)")
    m = len(pts)
    lengths = np.linalg.norm(pts[e[:, 0]] - pts[e[:, 1]], axis=1) + 1e-12
    g = coo_matrix((lengths, (e[:, 0], e[:, 1])), shape=(m, m)).tocsr()
    ncomp, lab = connected_components(g, directed=False)
    if ncomp > 1:   # keep the component with the largest total length
        tot = np.bincount(lab[e[:, 0]], weights=lengths, minlength=ncomp)
        keep = lab == int(np.argmax(tot))
        sel = keep[e[:, 0]] & keep[e[:, 1]]
        e, lengths = e[sel], lengths[sel]
    tree = minimum_spanning_tree(coo_matrix((lengths, (e[:, 0], e[:, 1])), shape=(m, m)).tocsr()).tocoo()
    return pts, np.stack([tree.row, tree.col], axis=1).astype(np.int64)


def _chains(m: int, edges: NDArray[np.int64]) -> list[list[int]]:
    """Split a tree (m nodes, edge list) into chains between nodes of degree != 2."""
    adj: list[list[int]] = [[] for _ in range(m)]
    for a, b in edges:
        adj[a].append(int(b))
        adj[b].append(int(a))
    deg = np.array([len(a) for a in adj])
    out, seen = [], set()
    for s in np.nonzero((deg > 0) & (deg != 2))[0]:
        for nb in adj[s]:
            if (s, nb) in seen:
                continue
            chain, prev, cur = [int(s)], int(s), nb
            while True:
                chain.append(cur)
                if deg[cur] != 2:
                    break
                nxt = adj[cur][0] if adj[cur][0] != prev else adj[cur][1]
                prev, cur = cur, nxt
            seen.add((chain[-1], chain[-2]))
            seen.add((chain[0], chain[1]))
            out.append(chain)
    return out


def _polylen(p: NDArray[np.float64]) -> float:
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def _prune(chains: list[list[int]], pts: NDArray[np.float64], rad: NDArray[np.float64], prune: float
           ) -> list[list[int]]:
    """Remove short terminal branches one at a time (shortest first), merging degree-2 joins."""
    table = dict(enumerate(chains))
    at: dict[int, set[int]] = {}
    for i, c in table.items():
        at.setdefault(c[0], set()).add(i)
        at.setdefault(c[-1], set()).add(i)
    nxt = len(table)
    while len(table) > 1:
        best, best_score = None, np.inf
        for i, c in table.items():
            for tip, junction in ((c[0], c[-1]), (c[-1], c[0])):
                if len(at[tip]) == 1 and len(at[junction]) >= 3:
                    score = _polylen(pts[c]) - (rad[junction] - rad[tip])
                    if score < best_score:
                        best, best_score = (i, tip, junction), score
        if best is None or best_score >= prune:
            break
        i, tip, junction = best
        del table[i]
        at[junction].discard(i)
        del at[tip]
        if len(at[junction]) == 2:
            a, b = sorted(at[junction])
            ca, cb = table.pop(a), table.pop(b)
            ca = ca if ca[-1] == junction else ca[::-1]
            cb = cb if cb[0] == junction else cb[::-1]
            merged = ca + cb[1:]
            for end in (ca[0], cb[-1]):
                at[end].discard(a if end == ca[0] else b)
                at[end].add(nxt)
            del at[junction]
            table[nxt] = merged
            nxt += 1
    return list(table.values())


def _resample(p: NDArray[np.float64], h: float) -> NDArray[np.float64]:
    """Resample a polyline by arc length at about ``h``, then smooth it with the ends held."""
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    n = max(2, int(np.ceil(cum[-1] / h)) + 1)
    s = np.linspace(0.0, cum[-1], n)
    q = np.stack([np.interp(s, cum, p[:, 0]), np.interp(s, cum, p[:, 1])], axis=1)
    q[0], q[-1] = p[0], p[-1]
    for _ in range(_SMOOTH_PASSES):
        q[1:-1] = 0.25 * q[:-2] + 0.5 * q[1:-1] + 0.25 * q[2:]
    return q


def ray_hit(margin: Margin, p: NDArray[np.float64], d: NDArray[np.float64]) -> float | None:
    """Arc-length fraction where the ray p + λ d (λ > 0) first meets the margin, or None."""
    a = margin.points
    b = np.roll(a, -1, axis=0)
    e = b - a
    den = d[0] * e[:, 1] - d[1] * e[:, 0]
    r = a - p
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (r[:, 0] * e[:, 1] - r[:, 1] * e[:, 0]) / den
        mu = (r[:, 0] * d[1] - r[:, 1] * d[0]) / den
    hit = (np.abs(den) > 1e-18) & (lam > 0) & (mu >= 0) & (mu <= 1)
    if not hit.any():
        return None
    k = np.nonzero(hit)[0][int(np.argmin(lam[hit]))]
    w = margin.w
    return float(w[k] + mu[k] * (w[k + 1] - w[k]))


def _attach_root(polys: list[NDArray[np.float64]], b: NDArray[np.float64], inward: NDArray[np.float64], snap: float,
                 h: float) -> list[NDArray[np.float64]]:
    """Join the base ``b`` to the skeleton point nearest to it, distances stretched by
    1 + ROOT_SLANT (1 - cos θ) with θ the angle from the margin's inward normal ``inward`` at b:
    split that polyline there (or snap to its end) and add a straight root edge. The root
    polyline comes first, from b."""
    best: tuple[float, int, int] = (np.inf, 0, 0)
    for i, p in enumerate(polys):
        d = p - b
        dist = np.maximum(np.linalg.norm(d, axis=1), 1e-30)
        cos = (d @ inward) / dist
        score = dist * (1.0 + ROOT_SLANT * (1.0 - cos))
        k = int(np.argmin(score))
        best = min(best, (float(score[k]), i, k))
    _, i, k = best
    p = polys[i]
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    out = [q for j, q in enumerate(polys) if j != i]
    if cum[k] <= snap:
        joint = p[0]
        out.append(p)
    elif cum[k] >= cum[-1] - snap:
        joint = p[-1]
        out.append(p)
    else:
        joint = p[k]
        out.append(p[:k + 1])
        out.append(p[k:])
    n = max(2, int(np.ceil(np.linalg.norm(joint - b) / h)) + 1)
    root = b + np.linspace(0.0, 1.0, n)[:, None] * (joint - b)
    root[-1] = joint
    return [root] + out


def _key(p: NDArray[np.float64]) -> tuple[float, float]:
    return (float(p[0]), float(p[1]))


def _merge_degree_two(polys: list[NDArray[np.float64]], root: tuple[float, float]) -> list[NDArray[np.float64]]:
    """Join polylines that meet at a node of degree 2 (other than the root)."""
    while True:
        count: dict[tuple[float, float], list[int]] = {}
        for i, p in enumerate(polys):
            count.setdefault(_key(p[0]), []).append(i)
            count.setdefault(_key(p[-1]), []).append(i)
        two = [k for k, v in count.items() if len(v) == 2 and k != root and v[0] != v[1]]
        if not two:
            return polys
        k = two[0]
        i, j = count[k]
        a, c = polys[i], polys[j]
        a = a if _key(a[-1]) == k else a[::-1]
        c = c if _key(c[0]) == k else c[::-1]
        polys = [p for n, p in enumerate(polys) if n not in (i, j)] + [np.vstack([a, c[1:]])]


def build_skeleton(outline: tuple[tuple[float, float], ...], prune: float, samples: int = VORONOI_SAMPLES
                   ) -> Skeleton:
    """The rooted, pruned, numbered skeleton of a margin (see the module docstring)."""
    margin = _margin(outline)
    size = float(np.max(np.ptp(margin.points, axis=0)))
    tree_pts, tree_edges = _medial_graph(margin, samples)
    kd = cKDTree(margin.points)
    rad = kd.query(tree_pts)[0]
    chains = _prune(_chains(len(tree_pts), tree_edges), tree_pts, rad, prune * size)
    h = margin.length / samples
    polys = [_resample(tree_pts[c], h) for c in chains]
    b = np.asarray(margin.at(0.0), dtype=np.float64)
    tangent = derivative_closed(margin.ctrl, 0.0)
    inward = np.array([tangent[1], -tangent[0]]) / max(float(np.linalg.norm(tangent)), 1e-30)  # clockwise: right
    polys = _attach_root(polys, b, inward, 3.0 * h, h)
    root_key = _key(polys[0][0])
    polys = _merge_degree_two(polys, root_key)

    # nodes and orientation from the root (breadth first)
    ids: dict[tuple[float, float], int] = {}
    node_pts: list[NDArray[np.float64]] = []
    ends = []
    for p in polys:
        pair = []
        for q in (p[0], p[-1]):
            key = _key(q)
            if key not in ids:
                ids[key] = len(node_pts)
                node_pts.append(q.copy())
            pair.append(ids[key])
        ends.append(pair)
    nodes = np.array(node_pts)
    root = ids[root_key]
    inc: dict[int, list[int]] = {}
    for i, (a, c) in enumerate(ends):
        inc.setdefault(a, []).append(i)
        inc.setdefault(c, []).append(i)
    parent_edge = [-1] * len(nodes)
    oriented: list[tuple[int, int, NDArray[np.float64]]] = []
    order, seen = [root], {root}
    while order:
        n = order.pop(0)
        for i in inc.get(n, []):
            a, c = ends[i]
            other = c if a == n else a
            if other in seen:
                continue
            p = polys[i] if a == n else polys[i][::-1]
            seen.add(other)
            parent_edge[other] = len(oriented)
            oriented.append((n, other, p))
            order.append(other)
    kids: list[list[int]] = [[] for _ in nodes]
    for i, (a, _, _) in enumerate(oriented):
        kids[a].append(i)
    terminals = [k for k in range(len(nodes)) if k != root and not kids[k]]

    # tip anchors: the skeleton's tangent at the tip, extended to the margin
    tip_w = np.full(len(nodes), np.nan)
    for k in terminals:
        p = oriented[parent_edge[k]][2]
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        back = cum[-1] - min(0.25 * cum[-1], 0.02 * size)
        q = np.array([np.interp(back, cum, p[:, 0]), np.interp(back, cum, p[:, 1])])
        d = p[-1] - q
        w = ray_hit(margin, p[-1], d) if np.linalg.norm(d) > 1e-12 else None
        tip_w[k] = margin.nearest(p[-1]) if w is None else w
    tip_w = np.where(np.isnan(tip_w), np.nan, np.clip(tip_w, 1e-9, 1.0 - 1e-9))

    # children in clockwise order (their subtrees' first tip), subtree heights
    first = np.full(len(nodes), np.inf)
    height = np.zeros(len(nodes))
    for i in reversed(range(len(oriented))):   # BFS order reversed: children before parents
        a, c, p = oriented[i]
        if c in terminals:
            first[c] = tip_w[c]
        first[a] = min(first[a], first[c])
        height[a] = max(height[a], height[c] + _polylen(p))
    children = [tuple(sorted(kids[k], key=lambda e: first[oriented[e][1]])) for k in range(len(nodes))]

    # branches: 0 from the root to the highest tip; then the longest path from each numbered node
    apex = max(terminals, key=lambda k: (float(margin.at(tip_w[k])[1]), -k))
    branch_of = [-1] * len(oriented)
    main: list[int] = []
    k = apex
    while k != root:
        main.append(parent_edge[k])
        k = oriented[parent_edge[k]][0]
    paths = [main[::-1]]
    for e in paths[0]:
        branch_of[e] = 0
    others: list[list[int]] = []
    def _open(e: int) -> bool:
        a = oriented[e][0]
        return branch_of[e] < 0 and (a == root or branch_of[parent_edge[a]] >= 0)

    frontier = [e for e in range(len(oriented)) if _open(e)]
    while frontier:
        new: list[list[int]] = []
        for e in frontier:
            path = [e]
            while children[oriented[path[-1]][1]]:
                c = oriented[path[-1]][1]
                path.append(max(children[c], key=lambda x: height[oriented[x][1]] + _polylen(oriented[x][2])))
            for x in path:
                branch_of[x] = len(paths) + len(others) + len(new)
            new.append(path)
        others.extend(new)
        frontier = [e for e in range(len(oriented)) if _open(e)]
    others.sort(key=lambda path: tip_w[oriented[path[-1]][1]])
    paths.extend(others)
    edges: list[Edge | None] = [None] * len(oriented)
    for bi, path in enumerate(paths):
        lens = np.array([_polylen(oriented[e][2]) for e in path])
        cum = np.concatenate([[0.0], np.cumsum(lens)]) / max(float(lens.sum()), 1e-30)
        for j, e in enumerate(path):
            a, c, p = oriented[e]
            edges[e] = Edge(a, c, _frozen(p), _frozen(kd.query(p)[0]), float(lens[j]), bi, float(cum[j]),
                            float(cum[j + 1]))
    ordered_terms = tuple(sorted(terminals, key=lambda k: tip_w[k]))
    return Skeleton(margin, _frozen(nodes), _frozen(kd.query(nodes)[0]), root, tuple(edges),  # type: ignore[arg-type]
                    tuple(parent_edge), tuple(children), ordered_terms, _frozen(tip_w),
                    tuple(tuple(p) for p in paths), size)


@lru_cache(maxsize=32)
def _skeleton(outline: tuple[tuple[float, float], ...], prune: float) -> Skeleton:
    return build_skeleton(outline, prune)


def skeleton(lobes: Lobes) -> Skeleton:
    """The skeleton of ``lobes`` (cached on its outline and ``prune``)."""
    if not lobes.outline:
        raise ParamError("lobes.outline", "not a lobed leaf: the outline is empty")
    return _skeleton(lobes.outline, float(lobes.prune))
