"""A leaf photograph resampled into the fitted leaf's front texture.

The texture is addressed by the leaf's own surface parameters (u, v) (Mündermann et al. 2003,
eq. 1), through the one convention of :func:`leafview.core.texture.texture_st`. For every texel
centre (s, t) this module takes (u, v) = :func:`~leafview.core.texture.uv_of_st` (s, t), the point
of the fitted, flat blade at (u, v) seen from above (:func:`leafview.deform.surface.evaluate` with
ripples and bending off: Chaurasia & Beardsley 2017, eq. 6), the photo pixel at that point (the
inverse of the fit's similarity ``leaf_from_pixel``), and samples the photo there bilinearly. So
the surface point (u, v) of the drawn leaf shows the photo's pixel at the same place on the leaf,
whatever ripples, bending or wind later do to the surface.

* **Alpha** is the traced leaf mask sampled the same way, so margin detail finer than the model
  (teeth, nibbles, holes) survives as transparency.
* **Two halves** (an asymmetric leaf drawn as two one-sided leaves, ``shape.half = ∓1``): the
  texels of u < 0 come from the right half's surface, those of u ≥ 0 from the left half's; both
  halves share one texture.
* **Speed**: the top-view map is smooth within each half (eq. 6 is polynomial in v and in |u|),
  so the surface is evaluated on a coarse (u, v) grid with a node on the midrib u = 0, and the
  pixel positions of the texels are its bilinear interpolation (two small matrix products); the
  photo is sampled bilinearly, all three channels and the mask in one pass.
* **Margin colour**: texels that are not wholly inside the mask take the colour of the nearest
  texel that is (a Euclidean distance transform), so bilinear filtering and mip-mapping at the
  cut-out margin blend leaf colours, never the paper's.

Colours stay as the photo stores them (sRGB-encoded, in [0, 1]); the result is float32 RGBA.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from leafview.core.params import Bending, LeafParams, ParamError
from leafview.core.texture import uv_of_st
from leafview.deform.surface import evaluate
from leafview.deform.sweep import flat_of_uv

__all__ = ["leaf_texture", "lobed_texture", "texture_uint8", "pixel_positions", "flat_top_view", "texel_uv", "MIN_TEXTURE_SIZE",
           "MAX_TEXTURE_SIZE", "GRID"]

MIN_TEXTURE_SIZE = 16
MAX_TEXTURE_SIZE = 8192
GRID = (33, 129)       # coarse grid nodes per half in u (midrib to margin) and along v
_SOLID = 1.0 - 1e-4    # sampled mask at least this: the texel lies wholly among leaf pixels

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]


def flat_top_view(params: LeafParams) -> LeafParams:
    """``params`` with ripples and bending (and the petiole) off: the blade as it lay flat on the
    paper, whose top view the photo shows."""
    return params.replace(ripple=replace(params.ripple, enabled=False), bending=Bending())


def texel_uv(size: int) -> tuple[F64, F64]:
    """(u of each texel column, v of each texel row) of a ``size`` × ``size`` texture, at the texel
    centres. In the convention of :func:`~leafview.core.texture.texture_st`, u depends on s alone
    and v on t alone."""
    centres = (np.arange(size, dtype=np.float64) + 0.5) / size
    u, _ = uv_of_st(centres, np.zeros(size))
    _, v = uv_of_st(np.zeros(size), centres)
    return u, v


def _weights(x: F64, nodes: F64) -> F64:
    """(len(x), len(nodes)) linear interpolation weights of the points ``x`` between the
    increasing ``nodes`` (clamped at the ends): two non-zeros per row."""
    k = np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, len(nodes) - 2)
    f = np.clip((x - nodes[k]) / (nodes[k + 1] - nodes[k]), 0.0, 1.0)
    w = np.zeros((len(x), len(nodes)))
    rows = np.arange(len(x))
    w[rows, k] = 1.0 - f
    w[rows, k + 1] = f
    return w


def _part_for(parts: Sequence[LeafParams]) -> tuple[LeafParams, LeafParams]:
    """(the leaf drawing u < 0, the leaf drawing u ≥ 0) of one whole leaf or two halves."""
    if len(parts) == 1:
        return parts[0], parts[0]
    if len(parts) != 2:
        raise ParamError("parts", f"expected one leaf or two halves, got {len(parts)}")
    by_half = {p.shape.half: p for p in parts}
    if set(by_half) != {-1, 1}:
        raise ParamError("parts", "two parts must be the halves u < 0 (half -1) and u >= 0 (half +1)")
    return by_half[-1], by_half[1]


def pixel_positions(parts: Sequence[LeafParams], pixel_from_leaf: ArrayLike, u: ArrayLike, v: ArrayLike,
                    grid: tuple[int, int] = GRID) -> tuple[F64, F64]:
    """Photo pixel coordinates (x, y), each (len(v), len(u)), of the flat top view of ``parts`` at
    the separable parameters ``u`` (columns) and ``v`` (rows): the surface evaluated on a coarse
    grid (``grid`` nodes per half in u, and in v) and interpolated bilinearly in between."""
    m = np.asarray(pixel_from_leaf, np.float64)
    uu, vv = np.asarray(u, np.float64), np.asarray(v, np.float64)
    nu, nv = grid
    half = np.linspace(0.0, 1.0, nu)
    u_nodes = np.concatenate([-half[:0:-1], half])     # -1 .. 0 .. 1, a node on the midrib
    v_nodes = np.linspace(0.0, 1.0, nv)
    negative, positive = (flat_top_view(p) for p in _part_for(parts))
    gu, gv = np.meshgrid(u_nodes[:nu - 1], v_nodes)
    left_u, left_v = np.meshgrid(u_nodes[nu - 1:], v_nodes)
    xy = np.concatenate([evaluate(negative, gu.ravel(), gv.ravel())[:, :2].reshape(nv, nu - 1, 2),
                         evaluate(positive, left_u.ravel(), left_v.ravel())[:, :2].reshape(nv, nu, 2)], axis=1)
    px = xy @ m[:2, :2].T + m[:2, 2]                   # (nv, 2 nu - 1, 2)
    wu, wv = _weights(uu, u_nodes), _weights(vv, v_nodes)
    return wv @ px[..., 0] @ wu.T, wv @ px[..., 1] @ wu.T


def _sample(image: NDArray[np.floating], mask: NDArray[np.bool_], x: F64, y: F64) -> tuple[F32, F32]:
    """Bilinear samples (rows, cols, 3) of ``image`` and (rows, cols) of ``mask`` at pixel
    coordinates (x, y) (pixel centres at integers): the colour clamped at the image's edge, the
    mask 0 outside the image (what :func:`scipy.ndimage.map_coordinates` gives with order 1, from
    four gathers of whole RGBA pixels)."""
    h, w = mask.shape
    # only the part of the photo the texels reach is converted, padded by one pixel before and
    # two after (colour repeated, mask 0), so that every bilinear neighbour is inside the array
    c0 = int(np.clip(np.floor(x.min()), 0, w - 1))
    c1 = int(np.clip(np.ceil(x.max()) + 2, c0 + 1, w))
    r0 = int(np.clip(np.floor(y.min()), 0, h - 1))
    r1 = int(np.clip(np.ceil(y.max()) + 2, r0 + 1, h))
    ch, cw = r1 - r0, c1 - c0
    rgba = np.empty((ch + 3, cw + 3, 4), np.float32)
    rgba[..., :3] = np.pad(np.asarray(image[r0:r1, c0:c1], np.float32), ((1, 2), (1, 2), (0, 0)), mode="edge")
    rgba[..., 3] = np.pad(mask[r0:r1, c0:c1], ((1, 2), (1, 2)))
    flat = rgba.reshape(-1, 4)
    xs = np.clip(x.ravel() - (c0 - 1), 0.0, cw + 1.0)
    ys = np.clip(y.ravel() - (r0 - 1), 0.0, ch + 1.0)
    ix, iy = np.floor(xs).astype(np.intp), np.floor(ys).astype(np.intp)
    fx, fy = (xs - ix).astype(np.float32)[:, None], (ys - iy).astype(np.float32)[:, None]
    i00 = iy * (cw + 3) + ix
    top = np.take(flat, i00, axis=0)
    top += (np.take(flat, i00 + 1, axis=0) - top) * fx
    bottom = np.take(flat, i00 + cw + 3, axis=0)
    bottom += (np.take(flat, i00 + cw + 4, axis=0) - bottom) * fx
    top += (bottom - top) * fy
    out = top.reshape(*x.shape, 4)
    return out[..., :3], out[..., 3]


def _extend_colour(rgb: F32, alpha: F32) -> F32:
    """``rgb`` with every texel not wholly inside the mask given the colour of the nearest texel
    that is (where none is wholly inside: the texels with the most alpha)."""
    solid = alpha >= _SOLID
    if not solid.any():
        if alpha.max() <= 0.0:
            return rgb
        solid = alpha >= alpha.max() - 1e-6
    if solid.all():
        return rgb
    idx = ndimage.distance_transform_edt(~solid, return_distances=False, return_indices=True)
    out: F32 = rgb[idx[0], idx[1]]
    return out


def _checked(rgb: NDArray[np.floating], mask: NDArray[np.bool_], size: int
             ) -> tuple[NDArray[np.floating], NDArray[np.bool_]]:
    """The photo and mask as arrays, checked against each other, and ``size`` checked."""
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or not MIN_TEXTURE_SIZE <= size <= MAX_TEXTURE_SIZE:
        raise ParamError("texture_size", f"must be a whole number in {MIN_TEXTURE_SIZE}..{MAX_TEXTURE_SIZE}, "
                                         f"got {size!r}")
    img = np.asarray(rgb)
    msk = np.asarray(mask, dtype=bool)
    if img.ndim != 3 or img.shape[2] != 3 or msk.shape != img.shape[:2]:
        raise ParamError("image", f"expected (h, w, 3) pixels and an (h, w) mask, got {img.shape} and {msk.shape}")
    return img, msk


def _texture(img: NDArray[np.floating], msk: NDArray[np.bool_], x: F64, y: F64, size: int) -> F32:
    """The (size, size, 4) texture whose texel (i, j) shows photo pixel (x[j, i], y[j, i]): the
    colour extended past the margin, alpha from the mask."""
    colour, alpha = _sample(img, msk, x, y)
    out = np.empty((size, size, 4), np.float32)
    out[..., :3] = _extend_colour(colour, alpha)
    out[..., 3] = alpha
    np.clip(out, 0.0, 1.0, out=out)
    return out


def leaf_texture(rgb: NDArray[np.floating], mask: NDArray[np.bool_], parts: Sequence[LeafParams],
                 pixel_from_leaf: ArrayLike, size: int = 512, *, grid: tuple[int, int] = GRID) -> F32:
    """The front texture (size, size, 4) float32 RGBA of the leaf ``parts`` (one leaf, or the two
    halves of an asymmetric one) cut from the photo ``rgb`` (h, w, 3) with the leaf ``mask``
    (h, w), where ``pixel_from_leaf`` (3 × 3) maps leaf-space (x, y) to photo pixels (x right,
    y down). Rows and columns follow :func:`~leafview.core.texture.texture_st` (row 0 at t = 0)."""
    img, msk = _checked(rgb, mask, size)
    u, v = texel_uv(int(size))
    x, y = pixel_positions(parts, pixel_from_leaf, u, v, grid)
    return _texture(img, msk, x, y, size)


def texture_uint8(texture: NDArray[np.floating]) -> NDArray[np.uint8]:
    """A float texture in [0, 1] as the 8-bit pixels of its image file (rounded, straight alpha)."""
    return np.asarray(np.clip(np.rint(np.asarray(texture, np.float32) * 255.0), 0, 255), np.uint8)


def lobed_texture(rgb: NDArray[np.floating], mask: NDArray[np.bool_], pixel_from_leaf: ArrayLike,
                  window: tuple[float, float, float, float], size: int = 512) -> F32:
    """The front texture (size, size, 4) of a lobed leaf: its texture coordinates are its flat
    position in the sweep's texture ``window`` (Mündermann et al. 2003, eq. 1;
    :func:`leafview.deform.sweep.texture_uv`), so texel (s, t) shows the photo at the leaf point
    :func:`~leafview.deform.sweep.flat_of_uv` (:func:`~leafview.core.texture.uv_of_st` (s, t))
    mapped by ``pixel_from_leaf``; alpha from ``mask``, the colour extended past the margin as
    :func:`leaf_texture` does."""
    img, msk = _checked(rgb, mask, size)
    m = np.asarray(pixel_from_leaf, np.float64)
    us, vs = texel_uv(int(size))                   # u of each column, v of each row
    xs, ys = flat_of_uv(us, vs, window)            # their flat x and y
    x = m[0, 0] * xs[None, :] + m[0, 1] * ys[:, None] + m[0, 2]
    y = m[1, 0] * xs[None, :] + m[1, 1] * ys[:, None] + m[1, 2]
    return _texture(img, msk, x, y, size)
