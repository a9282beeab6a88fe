"""The sun's cascaded shadow maps, in numpy: where the cascades split the camera's depth range, the
sun's orthographic camera of each cascade, and the visibility a fragment gets from the maps
(the twin of ``shaders/leaf_shadow.glsl``; the GPU pass is :mod:`leafview.gpu.shadow`).

Splits. The camera's depth range (its clip planes, clipped to the depths of the receiver box) is
cut by the *practical split scheme* of Zhang, Sun, Xu & Lee (2006, "Parallel-split shadow maps",
eq. 6): ``s_i = λ n (f/n)^(i/N) + (1 - λ)(n + (f - n) i/N)``, a blend of the logarithmic split
(the same texel density on screen at every depth) and the uniform one, with ``λ =``
:data:`SPLIT_BLEND`.

Cascade cameras. The sun camera looks along ``-sun`` with a fixed rotation (:func:`light_rotation`),
so a camera move only translates the cascades. Each cascade's square covers the bounding sphere of
its slice of the camera frustum (or, when smaller, the square around that slice's box intersected
with the receiver box, in the sun's axes: the whole scene when it fits in the slice); the radius is rounded up to a step of 2^(1/8) and the centre snapped to whole
texels, so that small camera moves keep the shadow texels where they were in the world (no
shimmering). In depth every cascade spans the receiver box (the scene box and the box's shadow on
the ground), padded by :data:`DEPTH_MARGIN` toward the sun: every leaf between the sun and any
receiver is in the map, seen or not.

Atlas. The cascades are tiles of one depth texture: one tile for one cascade, 2 × 1 for two, 2 × 2
for three or four (:func:`atlas_layout`); cascade ``k`` sits at column ``k % 2``, row ``k // 2``.

Visibility (:func:`visibility`, exactly ``sun_visibility`` of the shader): the cascade is the
first whose split lies beyond the fragment's view depth, or a later one if its square does not
cover the fragment; over the last :data:`FADE` of a cascade's range it cross-fades into the next.
The fragment is moved along its normal (turned toward the sun: leaves are two-sided sheets) by
``normal_offset`` texels times ``sin θ`` (normal-offset shadows, Holbert 2011; θ the angle between
normal and sun), and toward the sun by ``depth_bias`` texels, then compared with 3 × 3 bilinear
depth-compare taps one texel apart (percentage-closer filtering, Reeves, Salesin & Cook 1987):
a 4 × 4-texel footprint weighted ``(1 - f, 1, 1, f) / 3`` per axis (``f`` the bilinear fraction),
which the shader reads as four depth-compare gathers; the footprint stays inside the cascade's
tile (the point clamped 1.5 texels inside its edges). The ``"fast"`` filter
(:data:`~leafview.scene.lighting.SHADOW_FILTERS`) takes the one bilinear tap at the point instead
(texels ``c … c + 1``, weights ``1 - f, f`` per axis: the hardware's depth-compare filtering),
which costs the shader one texture read instead of four.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.errors import ParamError
from leafview.scene.camera import Camera
from leafview.scene.lighting import SHADOW_FILTERS

__all__ = ["MAX_CASCADES", "SPLIT_BLEND", "FADE", "DEPTH_BIAS", "NORMAL_OFFSET", "DEPTH_MARGIN", "Cascades",
           "clip_planes", "depth_range", "cascade_count", "cascade_splits", "atlas_layout", "tile_origin",
           "light_rotation", "receiver_bounds", "shadow_cascades", "visibility"]

MAX_CASCADES = 4
SPLIT_BLEND = 0.75       # λ of the practical split scheme
FADE = 0.1               # fraction of a cascade's range (from the previous split, or 0) cross-faded into the next
DEPTH_BIAS = 2.0         # texels toward the sun (covers the shadow pass's coarser level of detail, 2 texels)
NORMAL_OFFSET = 2.5      # texels along the normal, times sin θ (the 3 × 3 bilinear kernel reaches 2 texels)
DEPTH_MARGIN = 0.05      # of the receiver box's depth, added toward the sun (and 0.01 away from it)
AUTO_RATIO = 6.0         # automatic count: one cascade per factor AUTO_RATIO of far / near
MAX_SHADOW_LENGTH = 2.0  # the box's ground shadow reaches at most this many box diagonals
_RADIUS_STEPS = 8        # the cascade radius rounds up to a power of 2^(1/_RADIUS_STEPS)


@dataclass(frozen=True)
class Cascades:
    """The sun's cascades for one camera.

    ``cameras``: orthographic :class:`Camera` of each cascade (``set_camera`` of a scene draws its
    tile). ``matrices``: (count, 4, 4) world → the sun's clip space (``proj @ view``, column
    vectors). ``splits``: (count,) far end of each cascade (view depth). ``radii``: (count,)
    half-size of each square (world). ``tile``: texels per tile side. ``near``: the view depth the
    first cascade starts at."""

    cameras: tuple[Camera, ...]
    matrices: NDArray[np.float64]
    splits: NDArray[np.float64]
    radii: NDArray[np.float64]
    tile: int
    near: float

    @property
    def count(self) -> int:
        return len(self.cameras)

    @property
    def atlas_size(self) -> tuple[int, int]:
        """(width, height) of the depth texture in texels."""
        cols, rows = atlas_layout(self.count)
        return cols * self.tile, rows * self.tile

    @property
    def texels(self) -> NDArray[np.float64]:
        """(count,) world size of a texel of each cascade."""
        return 2.0 * self.radii / self.tile


def clip_planes(camera: Camera) -> tuple[float, float]:
    """(near, far) distances along the optical axis of a perspective or orthographic ``camera``."""
    p = np.asarray(camera.proj, np.float64)
    if camera.perspective:
        return float(p[2, 3] / (p[2, 2] - 1.0)), float(p[2, 3] / (p[2, 2] + 1.0))
    return float((p[2, 3] + 1.0) / p[2, 2]), float((p[2, 3] - 1.0) / p[2, 2])


def _corners(lo: ArrayLike, hi: ArrayLike) -> NDArray[np.float64]:
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def depth_range(camera: Camera, bounds: tuple[ArrayLike, ArrayLike]) -> tuple[float, float]:
    """The camera's clip range clipped to the view depths of the box ``bounds``' corners (the
    whole clip range when the box lies outside it)."""
    near, far = clip_planes(camera)
    c = _corners(*bounds)
    d = -(c @ np.asarray(camera.view, np.float64)[:3, :3].T + camera.view[:3, 3])[:, 2]
    lo, hi = max(near, float(d.min())), min(far, float(d.max()))
    return (lo, hi) if hi > lo else (near, far)


def cascade_count(near: float, far: float, requested: int = 0) -> int:
    """``requested`` (1-4), or for 0 one cascade per factor :data:`AUTO_RATIO` of ``far / near``
    (a scene framed whole needs one, a walker's view across a field four)."""
    if not 0 <= int(requested) <= MAX_CASCADES:
        raise ParamError("light.cascades", f"{requested!r} must lie in [0, {MAX_CASCADES}] (0: automatic)")
    if requested:
        return int(requested)
    ratio = max(far / max(near, 1e-9), 1.0)
    return int(np.clip(np.ceil(np.log(ratio) / np.log(AUTO_RATIO) - 1e-9), 1, MAX_CASCADES))


def cascade_splits(near: float, far: float, count: int, blend: float = SPLIT_BLEND) -> NDArray[np.float64]:
    """(count + 1,) view depths ``near = s_0 < … < s_count = far`` of the practical split scheme
    (Zhang et al. 2006, eq. 6): ``λ n (f/n)^(i/N) + (1 - λ)(n + (f - n) i/N)``."""
    if not 0.0 < near < far:
        raise ValueError(f"cascade splits need 0 < near < far, got {near}, {far}")
    i = np.arange(count + 1) / count
    s = blend * near * (far / near) ** i + (1.0 - blend) * (near + (far - near) * i)
    s[0], s[-1] = near, far
    return s


def atlas_layout(count: int) -> tuple[int, int]:
    """(columns, rows) of tiles in the atlas of ``count`` cascades."""
    return (1, 1) if count <= 1 else ((2, 1) if count == 2 else (2, 2))


def tile_origin(k: int) -> tuple[int, int]:
    """(column, row) of cascade ``k``'s tile (row 0 at texture v = 0)."""
    return k % 2, k // 2


def light_rotation(sun: ArrayLike) -> NDArray[np.float64]:
    """3 × 3 rotation whose rows are the sun camera's right, up and backward (= ``sun``, towards
    the sun) axes; fixed for a sun direction, whatever the camera."""
    back = np.asarray(sun, np.float64)
    back = back / np.linalg.norm(back)
    ref = np.array([0.0, 1.0, 0.0]) if abs(back[2]) > 0.99 else np.array([0.0, 0.0, 1.0])
    right = np.cross(ref, back)
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(back, right), back])


def receiver_bounds(bounds: tuple[ArrayLike, ArrayLike], sun: ArrayLike) -> tuple[NDArray[np.float64],
                                                                                 NDArray[np.float64]]:
    """The box ``bounds`` grown by its shadow on the ground plane ``z = lo.z`` (the box's corners
    moved along ``-sun`` down to the ground, at most :data:`MAX_SHADOW_LENGTH` diagonals away)."""
    lo, hi = np.asarray(bounds[0], np.float64), np.asarray(bounds[1], np.float64)
    s = np.asarray(sun, np.float64) / np.linalg.norm(sun)
    c = _corners(lo, hi)
    reach = MAX_SHADOW_LENGTH * float(np.linalg.norm(hi - lo))
    t = np.minimum((c[:, 2] - lo[2]) / max(s[2], 1e-6), reach)
    ground = c - t[:, None] * s
    every = np.vstack([c, ground])
    return every.min(axis=0), every.max(axis=0)


def _ortho(r: float, depth: float) -> NDArray[np.float64]:
    p = np.eye(4)
    p[0, 0] = p[1, 1] = 1.0 / r
    p[2, 2] = -2.0 / depth
    p[2, 3] = -1.0
    return p


def shadow_cascades(camera: Camera, bounds: tuple[ArrayLike, ArrayLike], sun: ArrayLike, tile: int,
                    count: int = 0, blend: float = SPLIT_BLEND) -> Cascades:
    """The sun's cascades for ``camera`` over a scene in the box ``bounds`` (world), the sun
    towards ``sun``, ``tile`` texels a side per cascade, ``count`` cascades (0: automatic,
    :func:`cascade_count`)."""
    sun = np.asarray(sun, np.float64) / np.linalg.norm(sun)
    rlo, rhi = receiver_bounds(bounds, sun)
    near, far = depth_range(camera, (rlo, rhi))
    n = cascade_count(near, far, count)
    s = cascade_splits(near, far, n, blend)
    rot = light_rotation(sun)
    box = _corners(rlo, rhi) @ rot.T
    zlo, zhi = float(box[:, 2].min()), float(box[:, 2].max())
    pad = max(zhi - zlo, 1e-6)
    top, bottom = zhi + DEPTH_MARGIN * pad, zlo - 0.01 * pad
    # the camera frustum's near- and far-plane corners (view space): a point at depth d on an edge
    # is near + (far - near)(d - n)/(f - n), perspective or not
    ndc = np.array([[x, y, z, 1.0] for z in (-1.0, 1.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)])
    v = ndc @ np.linalg.inv(np.asarray(camera.proj, np.float64)).T
    v = v[:, :3] / v[:, 3:]
    cn, cf = v[:4], v[4:]
    n_clip, f_clip = clip_planes(camera)
    world_from_view = np.linalg.inv(np.asarray(camera.view, np.float64))
    cameras, mats, radii = [], [], []
    for k in range(n):
        start = s[k]
        if k > 0:   # cover the previous cascade's fade region too
            prev = s[k - 1] if k > 1 else 0.0
            start = s[k] - FADE * (s[k] - prev)
        pts = []
        for d in (max(start, n_clip), s[k + 1]):
            t = (d - n_clip) / (f_clip - n_clip)
            pts.append(cn + (cf - cn) * t)
        slice_v = np.vstack(pts)
        slice_w = slice_v @ world_from_view[:3, :3].T + world_from_view[:3, 3]
        centre = slice_w.mean(axis=0)
        radius = float(np.linalg.norm(slice_w - centre, axis=1).max())
        cl = rot @ centre
        # the slice's box clipped to the receiver box, squared in the sun's axes: smaller when the
        # scene is smaller than the slice (and then independent of the camera)
        blo, bhi = np.maximum(slice_w.min(axis=0), rlo), np.minimum(slice_w.max(axis=0), rhi)
        if np.all(bhi >= blo):
            sq = _corners(blo, bhi) @ rot.T
            half = float(np.max(sq.max(axis=0)[:2] - sq.min(axis=0)[:2])) / 2.0
            if half < radius:
                cl, radius = (sq.min(axis=0) + sq.max(axis=0)) / 2.0, half
        radius = max(radius, 1e-6)
        radius = float(2.0 ** (np.ceil(np.log2(radius) * _RADIUS_STEPS) / _RADIUS_STEPS))
        texel = 2.0 * radius / tile
        cx, cy = np.round(cl[0] / texel) * texel, np.round(cl[1] / texel) * texel
        view = np.eye(4)
        view[:3, :3] = rot
        view[:3, 3] = (-cx, -cy, -top)
        proj = _ortho(radius, top - bottom)
        cameras.append(Camera(view, proj, np.array([*(-sun), 0.0]), False))
        mats.append(proj @ view)
        radii.append(radius)
    return Cascades(tuple(cameras), np.array(mats), s[1:].copy(), np.array(radii), int(tile), float(near))


def _pcf(atlas: NDArray[np.float64], t: NDArray[np.float64], ref: NDArray[np.float64]) -> NDArray[np.float64]:
    """The mean of 3 × 3 bilinear ``ref <= depth`` taps one texel apart around the atlas texel
    coordinates ``t`` (N, 2; texel centres at integers): texels ``c - 1 … c + 2`` per axis
    (``c = floor(t)``, ``f = t - c``) weighted ``(1 - f, 1, 1, f) / 3`` per axis, as the shader's
    four depth-compare gathers read them (texels past the atlas clamp to its edge)."""
    h, w = atlas.shape
    c = np.floor(t)
    f = t - c
    ci = c.astype(np.int64)
    one = np.ones(len(t))
    wx = np.stack([1.0 - f[:, 0], one, one, f[:, 0]])
    wy = np.stack([1.0 - f[:, 1], one, one, f[:, 1]])
    total = np.zeros(len(t))
    for dj in range(4):
        y = np.clip(ci[:, 1] - 1 + dj, 0, h - 1)
        for di in range(4):
            d = atlas[y, np.clip(ci[:, 0] - 1 + di, 0, w - 1)]
            total += wx[di] * wy[dj] * (ref <= d)
    return total / 9.0


def _bilinear(atlas: NDArray[np.float64], t: NDArray[np.float64], ref: NDArray[np.float64]) -> NDArray[np.float64]:
    """One bilinear ``ref <= depth`` tap at the atlas texel coordinates ``t`` (N, 2; texel centres at
    integers): texels ``c … c + 1`` per axis weighted ``1 - f, f``, as the shader's depth-compare
    ``texture()`` filters them."""
    h, w = atlas.shape
    c = np.floor(t)
    f = t - c
    ci = c.astype(np.int64)
    total = np.zeros(len(t))
    for dj in range(2):
        y = np.clip(ci[:, 1] + dj, 0, h - 1)
        wy = f[:, 1] if dj else 1.0 - f[:, 1]
        for di in range(2):
            wx = f[:, 0] if di else 1.0 - f[:, 0]
            total += wx * wy * (ref <= atlas[y, np.clip(ci[:, 0] + di, 0, w - 1)])
    return total


def _cascade_visibility(k: int, count: int, world: NDArray[np.float64], n: NDArray[np.float64],
                        cos_l: NDArray[np.float64], atlas: NDArray[np.float64], matrices: NDArray[np.float64],
                        tile: int, depth_bias: float, normal_offset: float, fast: bool) -> NDArray[np.float64]:
    """Visibility in cascade ``k`` (-1 where its square does not cover the point)."""
    m = matrices[k]
    texel = 2.0 / (np.linalg.norm(m[0, :3]) * tile)
    sin_l = np.sqrt(np.maximum(1.0 - cos_l * cos_l, 0.0))
    p = world + n * (normal_offset * texel * sin_l)[:, None]
    c = p @ m[:3, :3].T + m[:3, 3]
    s = c * 0.5 + 0.5
    covered = np.all((s[:, :2] >= 0.0) & (s[:, :2] <= 1.0), axis=1)
    ref = np.clip(s[:, 2] - depth_bias * texel * 0.5 * np.linalg.norm(m[2, :3]), 0.0, 1.0)
    origin = np.array(tile_origin(k), np.float64) * tile
    t = np.clip(origin + s[:, :2] * tile - 0.5, origin + 1.0, origin + (tile - 2.0))
    total = _bilinear(atlas, t, ref) if fast else _pcf(atlas, t, ref)
    return np.where(covered, total, -1.0)


def visibility(world: ArrayLike, normals: ArrayLike, view_depth: ArrayLike, atlas: ArrayLike,
               matrices: ArrayLike, splits: ArrayLike, tile: int, *, depth_bias: float = DEPTH_BIAS,
               normal_offset: float = NORMAL_OFFSET, shadow_filter: str = "soft") -> NDArray[np.float64]:
    """(N,) sun visibility, 0 shadowed … 1 lit, of fragments at ``world`` (N, 3) with
    ``normals`` (N, 3) at view depths ``view_depth`` (N,), from the depth ``atlas`` (H, W; row 0
    at texture v = 0, as a depth texture reads back) of the cascades' ``matrices`` (count, 4, 4)
    and ``splits`` (count,), filtered by ``shadow_filter`` (``"soft"`` or ``"fast"``): what
    ``sun_visibility`` of ``shaders/leaf_shadow.glsl`` returns (see the module docstring). No
    cascade: everything lit."""
    if shadow_filter not in SHADOW_FILTERS[1:]:
        raise ValueError(f"shadow_filter {shadow_filter!r}: choose from {', '.join(SHADOW_FILTERS[1:])} "
                         "(a renderer resolves 'auto')")
    world = np.asarray(world, np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, np.float64).reshape(-1, 3)
    depth = np.asarray(view_depth, np.float64).reshape(-1)
    mats = np.asarray(matrices, np.float64)
    spl = np.asarray(splits, np.float64)
    atl = np.asarray(atlas, np.float64)
    count = len(mats)
    out = np.ones(len(world))
    if count == 0:
        return out
    light = -mats[0, 2, :3] / np.linalg.norm(mats[0, 2, :3])
    nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
    cos_l = nrm @ light
    nrm = np.where((cos_l < 0.0)[:, None], -nrm, nrm)
    cos_l = np.abs(cos_l)
    first = np.minimum(np.searchsorted(spl[:count - 1], depth, side="left"), count - 1)
    vis = [_cascade_visibility(k, count, world, nrm, cos_l, atl, mats, tile, depth_bias, normal_offset,
                               shadow_filter == "fast") for k in range(count)]
    chosen = np.full(len(world), -1, np.int64)
    for k in range(count):
        pick = (chosen < 0) & (k >= first) & (vis[k] >= 0.0)
        chosen[pick] = k
    for k in range(count):
        mine = chosen == k
        v = vis[k][mine]
        if k + 1 < count:
            start = spl[k - 1] if k > 0 else 0.0
            width = FADE * (spl[k] - start)
            t = (depth[mine] - (spl[k] - width)) / width
            nxt = vis[k + 1][mine]
            blend = (t > 0.0) & (nxt >= 0.0)
            v = np.where(blend, v + (nxt - v) * np.clip(t, 0.0, 1.0), v)
        out[mine] = v
    return out
