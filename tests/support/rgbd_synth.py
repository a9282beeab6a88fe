"""Synthetic RGB-D views of placed leaves, in numpy, for fast capture tests (no GPU).

Each leaf's surface (:func:`leafview.deform.surface.partials`, placed by its transform) is
sampled densely and splatted into a z-buffer per camera: the nearest sample wins a pixel, and its
depth is corrected to the pixel centre's ray through the sample's tangent plane, so a flat leaf
gets the exact depth of its plane. Colour is a per-leaf green, shaded by the normal, with noise;
the background has no depth. ``instance`` holds the truth (leaf index + 1).

:func:`cluttered_scene` builds the test case of the capture: leaves of mixed size and slant,
overlapping, a few pairs touching in one plane (conjoined), seen by a few cameras from above.
:func:`score` measures a capture against that truth; :func:`write_view` writes a view in the
layout :func:`leafview.fit.views.read_views` reads.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from leafview.core.params import LeafParams, Shape, Transform
from leafview.deform.surface import evaluate, grid_uv, normal_from, partials
from leafview.fit.views import View
from leafview.scene.camera import intrinsics, look_at

BACKGROUND = np.array([70, 60, 50], np.float64)
OVERLAP = (0.62, 0.0, 0.0)   # the side-by-side pairs: touching at their widest
MIN_GAP = 0.04      # leaves of the cluttered scene keep at least this far apart (world units), but for the pairs


@dataclass
class Surface:
    """Dense world samples of one leaf: points, unit normals, area weights."""

    points: NDArray[np.float64]
    normals: NDArray[np.float64]
    area: NDArray[np.float64]


@dataclass
class SynthScene:
    leaves: list[LeafParams]
    views: list[View]
    visible: NDArray[np.float64]          # per leaf: fraction of its area seen by at least one view
    surfaces: list[Surface] = field(repr=False, default_factory=list)
    conjoined: list[tuple[int, int]] = field(default_factory=list)


def camera(eye: Any, target: Any, size: tuple[int, int], fov_deg: float = 45.0
           ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(K, world_from_camera) of a pinhole at ``eye`` looking at ``target`` (+z up)."""
    cam = look_at(eye, target, size[0] / size[1], 0.05, 100.0, fov_deg=fov_deg)
    return intrinsics(cam, size)


def sample_surface(leaf: LeafParams, n: int, rng: np.random.Generator) -> Surface:
    """``n`` stratified random samples of ``leaf`` in world space."""
    side = max(int(np.sqrt(n / 2.0)), 4)
    g = grid_uv(side, 2 * side).astype(np.float64)
    du, dv = 2.0 / (side - 1), 1.0 / (2 * side - 1)
    u = np.clip(g[:, 0] + rng.uniform(-0.5, 0.5, len(g)) * du, -1.0, 1.0)
    v = np.clip(g[:, 1] + rng.uniform(-0.5, 0.5, len(g)) * dv, 0.0, 1.0)
    p = partials(leaf, u, v)
    m = leaf.transform.matrix()
    lin = m[:3, :3]
    pts = p.L @ lin.T + m[:3, 3]
    nrm = normal_from(p, v) @ (lin / leaf.transform.scale).T
    area = np.linalg.norm(np.cross(p.Lu @ lin.T, p.Lv @ lin.T), axis=1)
    return Surface(pts, nrm, area)


def render(leaves: list[LeafParams], cameras: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
           size: tuple[int, int], *, seed: int = 0, depth_noise: float = 0.0, color_noise: float = 4.0,
           density: float = 5.0) -> tuple[list[View], list[Surface], NDArray[np.float64]]:
    """Views of ``leaves`` from ``cameras`` ((K, world_from_camera) pairs): (views, surfaces,
    visible fraction per leaf). ``density`` is samples per pixel of a leaf's projected area;
    ``depth_noise`` a relative Gaussian noise on depth."""
    rng = np.random.default_rng(seed)
    w, h = size
    eyes = [m[:3, 3] for _, m in cameras]
    f = max(k[0, 0] for k, _ in cameras)
    surfaces = []
    for leaf in leaves:
        centre = leaf.transform.matrix() @ np.array([0.0, 0.5, 0.0, 1.0])
        near = min(float(np.linalg.norm(centre[:3] - e)) for e in eyes)
        px = leaf.transform.scale * f / near
        surfaces.append(sample_surface(leaf, int(density * 0.5 * px * px) + 400, rng))
    greens = rng.uniform([0.20, 0.42, 0.08], [0.40, 0.70, 0.22], (len(leaves), 3)) * 255
    pts = np.concatenate([s.points for s in surfaces])
    nrm = np.concatenate([s.normals for s in surfaces])
    owner = np.concatenate([np.full(len(s.points), i) for i, s in enumerate(surfaces)])
    seen = np.zeros(len(pts), bool)
    light = np.array([0.3, -0.4, 0.87])
    views = []
    for vi, (k, m) in enumerate(cameras):
        cam = (pts - m[:3, 3]) @ m[:3, :3]
        cn = nrm @ m[:3, :3]
        z = cam[:, 2]
        ok = z > 1e-3
        x = np.full(len(z), -1.0)
        y = np.full(len(z), -1.0)
        x[ok] = k[0, 0] * cam[ok, 0] / z[ok] + k[0, 2]
        y[ok] = k[1, 1] * cam[ok, 1] / z[ok] + k[1, 2]
        col, row = np.rint(x).astype(np.int64), np.rint(y).astype(np.int64)
        ok &= (col >= 0) & (col < w) & (row >= 0) & (row < h)
        idx = np.flatnonzero(ok)
        pix = row[idx] * w + col[idx]
        order = np.lexsort((z[idx], pix))
        pix_sorted = pix[order]
        first = np.r_[True, pix_sorted[1:] != pix_sorted[:-1]]
        win = idx[order[first]]
        wpix = pix_sorted[first]
        # visibility of every sample: within a small depth margin of its pixel's winner
        zbuf = np.full(w * h, np.inf)
        zbuf[wpix] = z[win]
        tol = 0.01 * z[idx] + 4.0 * z[idx] / k[0, 0]
        seen[idx[z[idx] <= zbuf[pix] + tol]] = True
        # depth at the pixel centre through the winner's tangent plane
        rr, cc = np.divmod(wpix, w)
        ray = np.stack([(cc - k[0, 2]) / k[0, 0], (rr - k[1, 2]) / k[1, 1], np.ones(len(wpix))], axis=1)
        n_c = cn[win]
        denom = np.sum(n_c * ray, axis=1)
        t = np.sum(n_c * cam[win], axis=1) / np.where(np.abs(denom) > 0.2, denom, 1.0)
        dz = np.where((np.abs(denom) > 0.2) & (np.abs(t - z[win]) < 0.02 * z[win]), t, z[win])
        if depth_noise:
            dz = dz * (1.0 + rng.normal(0.0, depth_noise, len(dz)))
        depth = np.zeros(w * h, np.float32)
        depth[wpix] = dz
        instance = np.zeros(w * h, np.uint32)
        instance[wpix] = owner[win] + 1
        shade = 0.55 + 0.45 * np.abs(nrm[win] @ light)
        color = np.tile(BACKGROUND, (w * h, 1))
        color[wpix] = greens[owner[win]] * shade[:, None]
        color += rng.normal(0.0, color_noise, color.shape)
        color8 = np.clip(np.rint(color), 0, 255).astype(np.uint8).reshape(h, w, 3)
        views.append(View(f"view{vi:02d}", color8, depth.reshape(h, w), k, m, instance.reshape(h, w)))
    area = np.bincount(owner, np.concatenate([s.area for s in surfaces]), len(leaves))
    vis = np.bincount(owner[seen], np.concatenate([s.area for s in surfaces])[seen], len(leaves))
    return views, surfaces, vis / np.maximum(area, 1e-12)


def random_leaf(rng: np.random.Generator, length: float, position: Any, yaw: float, slant: float,
                name: str = "") -> LeafParams:
    """An ovate-to-lanceolate leaf of ``length`` whose centre is at ``position``, its midrib
    turned ``yaw`` degrees about +z and lifted ``slant`` degrees out of the horizontal, gently
    curved."""
    w = rng.uniform(0.26, 0.42)
    shape = Shape(a1=(0.0, 1 / 3, rng.uniform(-0.03, 0.03)), a2=(0.0, 2 / 3, rng.uniform(-0.03, 0.03)),
                  silhouette=((0.25, w * rng.uniform(0.8, 0.95), 0.0), (0.5, w, 0.0), (0.75, w * 0.65, 0.0)),
                  zf=tuple(rng.uniform(-0.02, 0.02, 3)), zg=tuple(rng.uniform(-0.02, 0.02, 3)))
    roll = rng.uniform(-20.0, 20.0)
    t = Transform(rotation=(slant, roll, yaw), scale=length)
    centre = t.matrix()[:3, :3] @ np.array([0.0, 0.5, 0.0])
    t = Transform(translation=tuple(float(c) for c in np.asarray(position) - centre), rotation=(slant, roll, yaw),
                  scale=length)
    return LeafParams(shape=shape, transform=t, name=name)


def beside(leaf: LeafParams, offset: tuple[float, float, float], rng: np.random.Generator,
           name: str = "") -> LeafParams:
    """A flat leaf parallel to ``leaf``, shifted by ``offset`` (x, y, z) in its leaf space (leaf
    lengths): touching it side by side, or lying on it with a small overlap, or tip to base."""
    w = rng.uniform(0.28, 0.4)
    shape = Shape(silhouette=((0.25, w * 0.9, 0.0), (0.5, w, 0.0), (0.75, w * 0.65, 0.0)))
    m = leaf.transform.matrix()
    shift = np.eye(4)
    shift[:3, 3] = offset
    return LeafParams(shape=shape, transform=Transform.from_matrix(m @ shift), name=name)


def flat(leaf: LeafParams) -> LeafParams:
    s = leaf.shape
    return LeafParams(shape=Shape(silhouette=tuple((r[0], r[1], 0.0) for r in s.silhouette)), transform=leaf.transform,
                      name=leaf.name)


def cluttered_scene(n_leaves: int = 30, n_views: int = 3, size: tuple[int, int] = (400, 300), *, seed: int = 0,
                    conjoined: int = 3, depth_noise: float = 0.0) -> SynthScene:
    """``n_leaves`` leaves (lengths 0.6-1.4) spread over a dome of radius 2.2 √(n_leaves / 30),
    slanted 0-45°, overlapping but never closer than :data:`MIN_GAP`; ``conjoined`` of them are
    pairs touching in one plane (side by side and tip to base alternately). ``n_views`` cameras
    from 55° above, around the dome."""
    rng = np.random.default_rng(seed)
    k = np.sqrt(n_leaves / 30.0)       # the dome grows with the number of leaves, the cameras back off
    leaves: list[LeafParams] = []
    pairs: list[tuple[int, int]] = []
    n_single = n_leaves - 2 * conjoined
    probes: list[cKDTree] = []
    i = 0
    while i < n_single + conjoined:
        r = 2.2 * k * np.sqrt(rng.uniform(0.0, 1.0))
        a = rng.uniform(0.0, 2 * np.pi)
        pos = (r * np.cos(a), r * np.sin(a), 1.2 * k - 0.18 * r * r / k + rng.uniform(-0.25, 0.25))
        length = rng.uniform(0.6, 1.4)
        leaf = random_leaf(rng, length, pos, np.degrees(a) - 90 + rng.uniform(-40, 40), rng.uniform(0, 45))
        group = [leaf]
        if i >= n_single:
            group = [flat(leaf)]
            side = (i - n_single) % 2 == 0
            group.append(beside(group[0], OVERLAP if side else (0.0, 0.97, 0.0), rng))
        coarse = [sample_surface(lf, 1500, rng).points for lf in group]
        if any(t.query(c, distance_upper_bound=MIN_GAP)[0].min() < MIN_GAP for t in probes for c in coarse):
            continue                     # leaves do not pass through each other: draw again
        probes += [cKDTree(c) for c in coarse]
        if len(group) == 2:
            pairs.append((len(leaves), len(leaves) + 1))
        leaves += group
        i += 1
    leaves = [LeafParams(shape=lf.shape, transform=lf.transform, name=f"truth_{i:03d}") for i, lf in enumerate(leaves)]
    cams = []
    for v in range(n_views):
        az = 2 * np.pi * v / n_views + 0.3
        d = 5.8 * k
        eye = (d * np.cos(az) * np.cos(np.radians(55)), d * np.sin(az) * np.cos(np.radians(55)),
               0.7 * k + d * np.sin(np.radians(55)))
        cams.append(camera(eye, (0.0, 0.0, 0.7 * k), size))
    views, surfaces, visible = render(leaves, cams, size, seed=seed, depth_noise=depth_noise)
    return SynthScene(leaves, views, visible, surfaces, pairs)


@dataclass
class Score:
    recall: float            # of leaves ≥ 50 % visible: found as one pure leaf (the largest piece covers half)
    precision: float         # of retained leaves: pure (≥ 80 % one truth leaf) and not a duplicate piece
    found: NDArray[np.bool_]
    eligible: NDArray[np.bool_]
    purity: NDArray[np.float64]
    truth_of: NDArray[np.int64]
    distance: NDArray[np.float64]   # per retained leaf: median surface distance to its truth leaf / truth length


def score(scene: SynthScene, views: list[View], leaves: list[LeafParams],
          points_of: list[tuple[NDArray[np.int64], NDArray[np.int64]]], *, min_purity: float = 0.8) -> Score:
    """Match retained leaves to the truth through the instance images of the pixels each leaf
    took (``points_of``: (view indices, flat pixel indices) per leaf)."""
    n_truth = len(scene.leaves)
    inst = [v.instance.reshape(-1) for v in views if v.instance is not None]
    seen_px = np.zeros(n_truth + 1)
    for a in inst:
        seen_px += np.bincount(a, minlength=n_truth + 1)[: n_truth + 1]
    truth_of = np.full(len(leaves), -1)
    purity = np.zeros(len(leaves))
    covers = np.zeros(len(leaves))
    for i, (vi, px) in enumerate(points_of):
        labels = np.concatenate([inst[v][px[vi == v]] for v in np.unique(vi)]) if len(px) else np.zeros(0, np.int64)
        counts = np.bincount(labels.astype(np.int64), minlength=n_truth + 1)
        counts[0] = 0
        t = int(np.argmax(counts))
        if counts[t] == 0:
            continue
        truth_of[i] = t - 1
        purity[i] = counts[t] / max(len(labels), 1)
        covers[i] = counts[t] / max(seen_px[t], 1)
    eligible = scene.visible >= 0.5
    found = np.zeros(n_truth, bool)
    good = np.zeros(len(leaves), bool)
    for t in range(n_truth):
        mine = np.flatnonzero((truth_of == t) & (purity >= min_purity))
        if len(mine):
            best = mine[np.argmax(covers[mine])]
            good[best] = True
            found[t] = covers[best] >= 0.5
    distance = np.full(len(leaves), np.inf)
    trees: dict[int, cKDTree] = {}
    uv = grid_uv(9, 17).astype(np.float64)
    for i, leaf in enumerate(leaves):
        t = int(truth_of[i])
        if t < 0:
            continue
        if t not in trees:
            trees[t] = cKDTree(scene.surfaces[t].points)
        m = leaf.transform.matrix()
        pts = evaluate(leaf, uv[:, 0], uv[:, 1]) @ m[:3, :3].T + m[:3, 3]
        d, _ = trees[t].query(pts)
        distance[i] = float(np.median(d)) / scene.leaves[t].transform.scale
    recall = float(found[eligible].mean()) if eligible.any() else 1.0
    precision = float(good.mean()) if len(leaves) else 0.0
    return Score(recall, precision, found, eligible, purity, truth_of, distance)


def _write_image(path: Path, pixels: NDArray[Any], fmt: str) -> None:
    data = pixels[:, :, None] if pixels.ndim == 2 else pixels       # OpenImageIO wants (h, w, c)
    h, w, c = data.shape
    out = oiio.ImageOutput.create(str(path))
    assert out is not None, oiio.geterror()
    assert out.open(str(path), oiio.ImageSpec(w, h, c, fmt)), out.geterror()
    assert out.write_image(np.ascontiguousarray(data)), out.geterror()
    out.close()


def write_view(folder: Path, view: View, *, depth: str = "npy") -> None:
    """Write ``view`` in the layout :func:`leafview.fit.views.read_view` reads (``depth``: "npy" or
    "exr")."""
    folder.mkdir(parents=True, exist_ok=True)
    h, w = view.depth.shape
    doc = {"width": w, "height": h, "K": view.k.tolist(), "world_from_camera": view.world_from_camera.tolist()}
    (folder / f"{view.name}.json").write_text(json.dumps(doc, indent=1))
    _write_image(folder / f"{view.name}.color.png", view.color, "uint8")
    if depth == "npy":
        np.save(folder / f"{view.name}.depth.npy", view.depth.astype(np.float32), allow_pickle=False)
    else:
        _write_image(folder / f"{view.name}.depth.exr", view.depth.astype(np.float32), "float")
    if view.instance is not None:
        _write_image(folder / f"{view.name}.instance.png", view.instance.astype(np.uint16), "uint16")
