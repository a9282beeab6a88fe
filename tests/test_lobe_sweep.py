"""The railroad ties of a lobed leaf (Mündermann et al. 2003, secs 3.3-4): the SweepTable built
from a Lobes group, evaluated with deform.sweep.sweep_eval, welded into one sheet; turtle edits."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import shapely
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from test_lobe_skeleton import lobed_outline, outlines

from leafview.botany.lobe_skeleton import skeleton
from leafview.botany.lobe_sweep import anchors, edge_rows, sweep_table, tour, weld_grid
from leafview.core.blade import grid_indices, grid_uv
from leafview.core.lobes import BranchTurtle, outline_samples
from leafview.deform.sweep import sweep_eval
from leafview.errors import ParamError

GRIDS = ((9, 1), (5, 2), (3, 4))     # (nu, row step): (9, 257), (5, 129), (3, 65) for 256 ties
HAUSDORFF = {1: 0.01, 2: 0.01, 4: 0.02}  # the 65-row grid draws the margin with 64 chords


def _rows(lobes):
    """Per table row: (edge, sample index, direction) in the tour."""
    sk = skeleton(lobes)
    trips = tour(sk)
    n_e = edge_rows(sk, trips, anchors(sk, trips, lobes.valleys), 256)
    out = []
    for e, d in trips:
        n = int(n_e[e])
        out.extend((e, i if d > 0 else n - i, d) for i in range(n))
    return sk, n_e, out


def _signed(tri):
    return ((tri[:, 1, 0] - tri[:, 0, 0]) * (tri[:, 2, 1] - tri[:, 0, 1])
            - (tri[:, 2, 0] - tri[:, 0, 0]) * (tri[:, 1, 1] - tri[:, 0, 1]))


def _topology(v, f):
    """(connected components, edge-manifold, boundary loops, each boundary vertex of degree 2)."""
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uniq, cnt = np.unique(e, axis=0, return_counts=True)
    bnd = uniq[cnt == 1]
    used = np.unique(bnd)
    g = coo_matrix((np.ones(len(bnd)), (bnd[:, 0], bnd[:, 1])), shape=(len(v), len(v)))
    loops = len(np.unique(connected_components(g, directed=False)[1][used]))
    deg = np.bincount(bnd.ravel(), minlength=len(v))
    ff = coo_matrix((np.ones(2 * len(f)), (np.r_[f[:, 0], f[:, 1]], np.r_[f[:, 1], f[:, 2]])), shape=(len(v), len(v)))
    comps = len(np.unique(connected_components(ff, directed=False)[1][np.unique(f)]))
    return comps, bool(cnt.max() <= 2), loops, bool(np.all(deg[used] == 2)), bnd


def _loop(bnd):
    adj: dict[int, list[int]] = {}
    for a, b in bnd:
        adj.setdefault(int(a), []).append(int(b))
        adj.setdefault(int(b), []).append(int(a))
    start = int(bnd[0, 0])
    loop, prev, cur = [start], -1, start
    while True:
        nxt = adj[cur][0] if adj[cur][0] != prev else adj[cur][1]
        if nxt == start:
            return loop
        loop.append(nxt)
        prev, cur = cur, nxt


def _sheet(table, nu, step):
    nv = table.rows // step + 1
    ev = sweep_eval(table, grid_uv(nu, nv))
    return ev, weld_grid(ev.L, nu, nv)


def test_table_rows_and_margin_order():
    lobes = lobed_outline(5, 140.0)
    table = sweep_table(lobes)
    assert table.rows == 256 and sweep_table(lobes) is table
    assert table.margin[0] == 0.0 and np.all(np.diff(table.margin) > 0) and table.margin[-1] < 1.0
    sk, n_e, rows = _rows(lobes)
    assert np.all(n_e % 4 == 0) and np.all(n_e >= 4) and 2 * n_e.sum() == 256
    # margin ends on the B-spline, the root tie is b → b
    assert np.array_equal(table.flat[0, :2], table.flat[0, 2:])
    assert np.array_equal(table.flat[0, :2], sk.nodes[sk.root])


def test_paired_feet_are_bitwise_equal():
    lobes = lobed_outline(5, 140.0)
    table = sweep_table(lobes)
    sk, n_e, rows = _rows(lobes)
    where: dict[tuple[int, int], list[int]] = {}
    for j, (e, i, _) in enumerate(rows):
        where.setdefault((e, i), []).append(j)
    paired = [js for (e, i), js in where.items() if 0 < i < n_e[e]]
    assert paired and all(len(js) == 2 for js in paired)
    for a, b in paired:
        assert np.array_equal(table.origin[a], table.origin[b])
        assert np.array_equal(table.flat[a, :2], table.flat[b, :2])
    for n in range(len(sk.nodes)):               # every visit of a node reads the same position
        hits = [j for j, (e, i, _) in enumerate(rows)
                if (i == 0 and sk.edges[e].start == n) or (i == n_e[e] and sk.edges[e].end == n)]
        assert len(hits) == sk.degree(n)
        assert all(np.array_equal(table.origin[hits[0]], table.origin[j]) for j in hits)


def _tip_rows(lobes):
    """Table rows of the tip ties (a basal traversal's first row at a terminal)."""
    sk, n_e, rows = _rows(lobes)
    return sk, {j for j, (e, i, d) in enumerate(rows) if d < 0 and i == n_e[e] and np.isfinite(sk.tip_w[sk.edges[e].end])}


@pytest.mark.parametrize("name", list(outlines()))
def test_flat_ties_do_not_cross(name):
    """No triangle of the flat (9, 257) grid turns clockwise. A tip's tie runs on along the
    skeleton's last step, so the first triangle from it to the next tie is collinear: those slivers
    (zero area to rounding, at most one per tip) are counted apart; every other triangle has area."""
    lobes = outlines()[name]
    table = sweep_table(lobes)
    ev = sweep_eval(table, grid_uv(9, table.rows + 1))
    area = _signed(ev.flat[grid_indices(9, table.rows + 1).astype(np.int64)])
    size = np.ptp(ev.flat, axis=0).max()
    zero = 1e-12 * size * size
    nt = len(area) // 2
    sk, tips = _tip_rows(lobes)
    assert len(tips) == len(sk.terminals)         # every tip's tie lies on its ray
    sliver = np.zeros(len(area), dtype=bool)
    sliver[[8 * j for j in tips]] = True          # the first triangle (k_tip, k_next, tie point)
    wrong = np.nonzero(area < -zero)[0]
    assert len(wrong) == 0, (name, len(wrong), sorted({(b % nt) // 8 for b in wrong}))
    assert np.all(np.abs(area[sliver]) <= zero)
    flat_ones = np.nonzero(np.abs(area) <= zero)[0]
    root = {b for b in flat_ones if (b % nt) // 8 in (0, table.rows - 1)}   # the root's zero-length tie
    assert set(flat_ones) - root <= set(np.nonzero(sliver)[0]), (name, sorted(set(flat_ones) - root))


@pytest.mark.parametrize("name", list(outlines()))
@pytest.mark.parametrize("grid", [(9, 257), (2, 65)])
def test_flat_normals_point_up(name, grid):
    """No normal of a flat lobed sheet points down (back faces would z-fight in renders): the
    central differences along the tour keep every tie's side, and a tip's zero difference falls
    back to the turtle's up axis."""
    ev = sweep_eval(sweep_table(outlines()[name]), grid_uv(*grid))
    assert np.all(ev.normal[:, 2] > 0.0), int(np.sum(ev.normal[:, 2] <= 0.0))


@pytest.mark.parametrize("name", list(outlines()))
@pytest.mark.parametrize("nu, step", GRIDS)
def test_one_welded_sheet_matching_the_margin(name, nu, step, request):
    if name == "oak" and step > 1:   # 9 tips, 17 edges: 128 or 64 chords miss the lobe tips by 1.5-2.6 %
        request.applymarker(pytest.mark.xfail(reason="oak margin too coarse on the 129 and 65 row grids",
                                              strict=False))
    lobes = outlines()[name]
    table = sweep_table(lobes)
    ev, (v, f) = _sheet(table, nu, step)
    comps, manifold, loops, simple, _ = _topology(v, f)
    assert (comps, manifold, loops, simple) == (1, True, 1, True)
    flat = np.zeros((len(ev.flat), 3))
    flat[:, :2] = ev.flat
    fv, ff = weld_grid(flat, nu, table.rows // step + 1)
    tri = fv[ff][:, :, :2]
    union = shapely.unary_union(shapely.polygons(tri), grid_size=1e-10)
    ratio = float(np.sum(np.abs(_signed(tri))) / 2.0 / union.area)
    assert ratio <= 1.05
    comps, manifold, loops, simple, bnd = _topology(fv, ff)
    assert loops == 1
    ref = outline_samples(lobes.outline, 64)
    length = np.ptp(ref[:, 1])
    haus = shapely.hausdorff_distance(shapely.LinearRing(fv[_loop(bnd), :2]), shapely.LinearRing(ref), densify=0.05)
    assert haus <= HAUSDORFF[step] * length


def test_no_edits_is_the_flat_leaf_exactly():
    table = sweep_table(lobed_outline(3, 120.0))
    assert np.array_equal(table.origin[:, :2], table.flat[:, :2]) and not table.origin[:, 2].any()
    assert np.array_equal(table.rim[:, :2], table.flat[:, 2:]) and not table.rim[:, 2].any()
    assert np.array_equal(table.up, np.tile([0.0, 0.0, 1.0], (table.rows, 1)))
    assert np.allclose(table.length, np.linalg.norm(table.flat[:, 2:] - table.flat[:, :2], axis=1))


def _affected(sk, branch):
    """Edges on ``branch`` or below it."""
    out = set()
    for i in range(len(sk.edges)):
        e = i
        while e >= 0:
            if sk.edges[e].branch == branch:
                out.add(i)
                break
            e = sk.parent_edge[sk.edges[e].start]
    return out


@pytest.mark.parametrize("branch", [0, 2])
def test_bend_lifts_only_its_branch_and_descendants(branch):
    lobes = lobed_outline(5, 140.0)
    flat = sweep_table(lobes)
    bent = sweep_table(dataclasses.replace(lobes, branches=(BranchTurtle(branch=branch, bend=(40.0,) * 4),)))
    sk, n_e, rows = _rows(lobes)
    hit = _affected(sk, branch)
    # a child branch's first foot is its parent's junction: unchanged unless the parent moved
    on = np.array([e in hit and not (i == 0 and sk.parent_edge[sk.edges[e].start] not in hit) for e, i, _ in rows])
    for a in ("origin", "rim", "up"):
        assert np.array_equal(getattr(bent, a)[~on], getattr(flat, a)[~on])
    assert np.all(bent.origin[on, 2] >= 0.0) and bent.origin[on, 2].max() > 0.02
    assert np.all(bent.up[on, 2] < 1.0)
    assert np.array_equal(bent.flat, flat.flat) and np.array_equal(bent.length, flat.length)


def test_twist_turns_the_ties_about_the_branch():
    lobes = lobed_outline(3, 120.0)
    sk, n_e, rows = _rows(lobes)
    branch = sk.edges[sk.branches[1][0]].branch
    table = sweep_table(dataclasses.replace(lobes, branches=(BranchTurtle(branch=branch, twist=(60.0,) * 4),)))
    on = [(j, d) for j, (e, i, d) in enumerate(rows) if sk.edges[e].branch == branch and 0 < i < 0.75 * n_e[e]]
    rise = np.array([table.rim[j, 2] - table.origin[j, 2] for j, _ in on])
    side = np.array([d for _, d in on])
    # right-handed twist about the heading: the left (distal) ties rise, the right (basal) ones sink
    assert np.all(rise[side > 0] > 0) and np.all(rise[side < 0] < 0)
    ties = table.rim - table.origin
    flat_ties = np.zeros_like(ties)
    flat_ties[:, :2] = table.flat[:, 2:] - table.flat[:, :2]
    assert np.allclose(np.linalg.norm(ties, axis=1), np.linalg.norm(flat_ties, axis=1))   # rotated, not stretched


def test_edited_sheet_still_welds():
    lobes = lobed_outline(5, 140.0)
    edits = (BranchTurtle(branch=0, bend=(20.0, 40.0, 0.0, -30.0), turn=(10.0,) * 4),
             BranchTurtle(branch=1, twist=(-45.0,) * 4), BranchTurtle(branch=3, bend=(60.0,) * 4),
             BranchTurtle(branch=40, bend=(90.0,) * 4))        # a branch the skeleton lacks: ignored
    table = sweep_table(dataclasses.replace(lobes, branches=edits, cup=0.2))
    sk, n_e, rows = _rows(lobes)
    where: dict[tuple[int, int], list[int]] = {}
    for j, (e, i, _) in enumerate(rows):
        where.setdefault((e, i), []).append(j)
    for js in where.values():
        assert all(np.array_equal(table.origin[js[0]], table.origin[j]) for j in js)
    for nu, step in GRIDS:
        _, (v, f) = _sheet(table, nu, step)
        comps, manifold, loops, simple, _ = _topology(v, f)
        assert (comps, manifold, loops, simple) == (1, True, 1, True)


def test_weld_grid_merges_and_drops_collapsed_triangles():
    p = np.zeros((3, 3, 3))
    p[:, :, 0] = np.linspace(0.0, 1.0, 3)[None, :]
    p[:, :, 1] = np.linspace(0.0, 1.0, 3)[:, None]
    p[0] = 0.0                                   # the first row collapses to one point
    v, f = weld_grid(p.reshape(-1, 3), 3, 3)
    assert len(v) == 7 and len(f) == 8 - 2
    assert np.all((f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2]))


def test_too_many_edges_for_the_rows():
    with pytest.raises(ParamError) as err:
        sweep_table(lobed_outline(5, 140.0), rows=16)
    assert err.value.path == "lobes.prune"
