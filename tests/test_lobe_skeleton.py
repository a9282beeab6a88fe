"""The medial-axis skeleton of a lobed margin (Mündermann et al. 2003, sec. 3.2): a rooted tree,
one tip per lobe, pruning of margin noise, branch numbering (Lobes.branches)."""

from __future__ import annotations

import tomllib
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import shapely
from shapely import affinity
from shapely.geometry import Point

from leafview.botany.lobe_skeleton import build_skeleton, margin_of, skeleton
from leafview.core.bspline import evaluate_closed, fit_closed, signed_area
from leafview.core.lobes import Lobes
from leafview.core.params import parse_params
from leafview.errors import ParamError

PRESETS = Path(__file__).resolve().parents[1] / "assets" / "presets"
PRESET_NAMES = ("maple", "oak", "bilobed")


def _ring(geom: shapely.Polygon, n: int = 600) -> np.ndarray:
    """The exterior of ``geom`` resampled by arc length, clockwise, from its bottom point near x = 0."""
    ring = np.asarray(geom.exterior.coords)
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ring, axis=0), axis=1))])
    s = np.linspace(0.0, cum[-1], n, endpoint=False)
    p = np.stack([np.interp(s, cum, ring[:, 0]), np.interp(s, cum, ring[:, 1])], axis=1)
    if signed_area(p) > 0:
        p = p[::-1]
    near = np.nonzero(np.abs(p[:, 0]) < 0.03)[0]
    return np.roll(p, -int(near[np.argmin(p[near, 1])]), axis=0)


@cache
def lobed_outline(n_lobes: int, spread: float, *, jitter: float = 0.0, seed: int = 0, prune: float = 0.06,
                  controls: int = 64) -> Lobes:
    """A palmate leaf of ``n_lobes`` elliptic lobes fanned over ``spread`` degrees around a disc,
    unioned with shapely, one leaf length tall, fitted with a closed B-spline; ``jitter`` adds
    normal noise (leaf lengths) to the margin before the fit."""
    parts = [Point(0.0, 0.3).buffer(0.22, 64)]
    for a in np.linspace(-spread / 2, spread / 2, n_lobes):
        t = np.radians(a)
        ln = 0.6 * (1.0 if abs(a) < 1 else 0.85)
        e = affinity.scale(Point(0.0, 0.0).buffer(1.0, 64), 0.17, 0.5 * ln + 0.085)
        e = affinity.rotate(e, -a, origin=(0, 0))
        parts.append(affinity.translate(e, 0.5 * ln * np.sin(t), 0.3 + 0.5 * ln * np.cos(t)))
    g = shapely.unary_union(parts).buffer(0.02).buffer(-0.02)
    g = affinity.translate(g, 0.0, -g.bounds[1])
    g = affinity.scale(g, 1 / g.bounds[3], 1 / g.bounds[3], origin=(0, 0))
    p = _ring(g)
    if jitter:
        rng = np.random.default_rng(seed)
        d = np.roll(p, -1, 0) - np.roll(p, 1, 0)
        nrm = np.stack([d[:, 1], -d[:, 0]], 1) / np.linalg.norm(d, axis=1, keepdims=True)
        p = p + nrm * rng.normal(0.0, jitter, len(p))[:, None]
    return Lobes(outline=tuple(map(tuple, fit_closed(p, controls).tolist())), prune=prune)


@cache
def ellipse_outline() -> Lobes:
    """An elliptic leaf, base at the origin, apex at (0, 1), clockwise."""
    t = np.linspace(0.0, 2.0 * np.pi, 400, endpoint=False)
    p = np.stack([-0.3 * np.sin(t), 0.5 - 0.5 * np.cos(t)], axis=1)
    return Lobes(outline=tuple(map(tuple, fit_closed(p, 16).tolist())))


def preset_lobes(name: str) -> Lobes | None:
    """The ``[lobes]`` of a built-in preset, or None while the preset does not exist."""
    path = PRESETS / f"{name}.toml"
    if not path.exists():
        return None
    return parse_params(tomllib.loads(path.read_text())).lobes


@cache
def outlines() -> dict[str, Lobes]:
    """The test outlines: synthetic ones, plus the lobed presets that exist."""
    out = {"ellipse": ellipse_outline(), "3-lobed": lobed_outline(3, 120.0), "5-lobed": lobed_outline(5, 140.0),
           "5-lobed-jittered": lobed_outline(5, 140.0, jitter=0.004)}
    for name in PRESET_NAMES:
        lobes = preset_lobes(name)
        if lobes is not None:
            out[name] = lobes
    return out


def _check_tree(sk) -> None:
    k = len(sk.nodes)
    assert len(sk.edges) == k - 1
    assert sk.parent_edge[sk.root] == -1 and sk.degree(sk.root) == 1
    for n in range(k):                         # every node reaches the root through parents
        seen, m = 0, n
        while m != sk.root:
            m = sk.edges[sk.parent_edge[m]].start
            seen += 1
            assert seen <= k
    for i, e in enumerate(sk.edges):
        assert sk.parent_edge[e.end] == i
        assert np.array_equal(e.points[0], sk.nodes[e.start]) and np.array_equal(e.points[-1], sk.nodes[e.end])
    for n in range(k):
        assert sk.degree(n) != 2 or n == sk.root


@pytest.mark.parametrize("name", list(outlines()))
def test_skeleton_is_a_rooted_tree_inside_the_margin(name):
    lobes = outlines()[name]
    sk = skeleton(lobes)
    _check_tree(sk)
    assert np.array_equal(sk.nodes[sk.root], evaluate_closed(np.asarray(lobes.outline), 0.0))
    poly = shapely.Polygon(margin_of(lobes).points).buffer(1e-6)
    for e in sk.edges:
        assert shapely.contains_xy(poly, e.points[:, 0], e.points[:, 1]).all()
        assert np.all(e.radii >= 0)
    assert skeleton(lobes) is sk                 # cached on the hashable Lobes value


@pytest.mark.parametrize("n_lobes, spread", [(3, 120.0), (5, 140.0)])
def test_one_tip_per_lobe(n_lobes, spread):
    sk = skeleton(lobed_outline(n_lobes, spread))
    assert len(sk.terminals) == n_lobes
    assert sum(sk.degree(n) == 1 for n in range(len(sk.nodes))) == n_lobes + 1   # tips and the root
    # the tip anchors come clockwise: left lobes first, the apex lobe in the middle
    w = sk.tip_w[list(sk.terminals)]
    assert np.all(np.diff(w) > 0) and np.all((w > 0) & (w < 1))
    xs = margin_of(lobed_outline(n_lobes, spread)).at(w)[:, 0]
    assert np.all(np.diff(xs) > 0)


def test_ellipse_has_a_single_branch():
    sk = skeleton(ellipse_outline())
    assert len(sk.edges) == 1 and len(sk.terminals) == 1
    assert sk.nodes[sk.terminals[0]][1] > 0.7


def test_prune_removes_margin_noise():
    noisy = lobed_outline(5, 140.0, jitter=0.004, seed=3)
    raw = build_skeleton(noisy.outline, 0.0)
    kept = skeleton(noisy)
    assert len(raw.terminals) > 5 + 3           # hairs to every wiggle
    assert len(kept.terminals) == 5
    _check_tree(kept)


def test_branch_numbering():
    lobes = lobed_outline(5, 140.0)
    sk = skeleton(lobes)
    assert sorted(e for b in sk.branches for e in b) == list(range(len(sk.edges)))
    for bi, path in enumerate(sk.branches):
        assert all(sk.edges[e].branch == bi for e in path)
        assert sk.edges[path[0]].s0 == 0.0 and sk.edges[path[-1]].s1 == pytest.approx(1.0)
        for a, b in zip(path, path[1:]):        # contiguous, s increasing
            assert sk.edges[a].end == sk.edges[b].start and sk.edges[a].s1 == sk.edges[b].s0
        assert sk.edges[path[-1]].end in sk.terminals
    main = sk.branches[0]
    assert sk.edges[main[0]].start == sk.root
    tip_y = {t: margin_of(lobes).at(sk.tip_w[t])[1] for t in sk.terminals}
    assert sk.edges[main[-1]].end == max(tip_y, key=tip_y.get)
    tips = [sk.tip_w[sk.edges[p[-1]].end] for p in sk.branches[1:]]
    assert tips == sorted(tips)                 # clockwise from the base
    for path in sk.branches[1:]:                # each starts at a junction on another branch
        start = sk.edges[path[0]].start
        assert sk.degree(start) >= 3 and sk.edges[sk.parent_edge[start]].branch != sk.edges[path[0]].branch


def test_not_lobed_is_a_param_error():
    with pytest.raises(ParamError) as err:
        skeleton(Lobes())
    assert err.value.path == "lobes.outline"
