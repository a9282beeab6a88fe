"""Leaf image textures on the GPU: the files of a draw read into one mipmapped array texture.

A textured leaf (:class:`~leafview.core.texture.LeafTexture`) shows the texel of its front image
(back image on back faces, the front's when it has none) at the (u, v) of each fragment
(Mündermann et al. 2003, eq. 1: the blade's parameter domain is the image's), through the
convention of :func:`leafview.core.texture.texture_st`. What this module does:

* **Reading.** Every file through OpenImageIO, into 8-bit RGBA as stored (row 0 at the top): grey
  and grey-alpha files are spread to RGB, a missing alpha is opaque, 16-bit files are rounded to
  8 bits, and float files (OpenEXR), which hold linear values, are encoded to sRGB so that every
  layer is sRGB like a PNG or JPEG. Files are cached by (path, modification time, size), up to
  :data:`CACHE_BYTES`.
* **Errors.** A missing, unreadable or oversized file raises
  :class:`~leafview.errors.ParamError` naming the leaf and the field (``texture.front``), with
  the file as its source, before anything is uploaded or drawn.
* **Layers.** One layer per distinct file (:func:`leafview.gpu.layout.texture_keys`, the layers
  :func:`~leafview.gpu.layout.pack_leaves` writes into the records), all of one size: the largest
  width and the largest height among the files, each capped at :data:`MAX_LAYER_SIZE` (and at the
  context's ``GL_MAX_TEXTURE_SIZE``). Other files are resized to it (OpenImageIO's filtered
  resize; a layer covers s, t in [0, 1] whatever its pixel size, so the aspect ratio is the
  leaf's, not the file's). When the array with its mipmaps would exceed
  :data:`~leafview.gpu.limits.MAX_RESOURCE_BYTES`, the layer size is halved until it fits.
* **Sampling.** Linear filtering between texels and between mipmap levels (the mipmaps are built
  by the driver), clamped to the edge. ``leaf.frag`` decodes the filtered sRGB colour to linear
  and discards alpha < 0.5 (``shaders/leaf_texture.glsl``).

The numpy twins of the lookup (:func:`sample_layer`: bilinear, clamp to edge, level 0) and of
the decoding (:func:`srgb_to_linear`) are what the readback tests compare the shader with.
"""

from __future__ import annotations

import os
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import moderngl
import numpy as np
import OpenImageIO as oiio
from numpy.typing import ArrayLike, NDArray

from leafview.core.colour import linear_to_srgb, srgb_to_linear  # re-exported: the lookup's twins
from leafview.core.params import LeafParams
from leafview.core.texture import bilinear, texture_st
from leafview.errors import GpuLimitError, ParamError
from leafview.gpu.layout import TEXTURE_UNIT, texture_keys
from leafview.gpu.limits import MAX_RESOURCE_BYTES, gib

__all__ = ["MAX_LAYER_SIZE", "MAX_TEXTURE_PIXELS", "CACHE_BYTES", "TextureLayers", "LeafTextures", "read_texture",
           "load_layers", "check_textures", "layer_size", "sample_layer", "texture_lookup", "srgb_to_linear",
           "linear_to_srgb", "clear_cache", "TextureUnreadable"]

MAX_LAYER_SIZE = 2048
"""Largest side of a layer: larger files are resized down to it."""
MAX_TEXTURE_PIXELS = 64 << 20
"""Largest texture file, in pixels (a 50 MP photograph fits)."""
CACHE_BYTES = 512 << 20
"""Decoded RGBA8 images kept between draws."""

_Version = tuple[str, int, int]   # (path, mtime_ns, size)
_cache: OrderedDict[_Version, NDArray[np.uint8]] = OrderedDict()
_cached_bytes = 0


class TextureUnreadable(Exception):
    """A texture file that cannot be used; the message says why (without the path)."""


# -- numpy twins -------------------------------------------------------------------------------------
def sample_layer(layer: NDArray[np.uint8], s: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """GL's linear filtering of one RGBA8 layer (h, w, 4) at image coordinates (s, t), level 0,
    clamped to the edge: (..., 4) in [0, 1] (rgb still sRGB-encoded). Texel (i, j) (column, row)
    is centred at ((i + 0.5) / w, (j + 0.5) / h); row 0 at t = 0."""
    return bilinear(np.asarray(layer, np.float64) / 255.0, s, t)


def texture_lookup(layer: NDArray[np.uint8], u: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """What ``leaf.frag`` makes of a textured leaf's point (u, v) read from ``layer``: the linear
    albedo (..., 3) and whether the fragment is kept (alpha >= 0.5), at level 0."""
    s, t = texture_st(u, v)
    texel = sample_layer(layer, s, t)
    return srgb_to_linear(texel[..., :3]), texel[..., 3] >= 0.5


# -- reading ------------------------------------------------------------------------------------------
def clear_cache() -> None:
    """Forget every decoded image."""
    global _cached_bytes
    _cache.clear()
    _cached_bytes = 0


def _version(path: Path) -> _Version:
    try:
        st = path.stat()
    except FileNotFoundError:
        raise TextureUnreadable("no such file") from None
    except OSError as exc:
        raise TextureUnreadable(f"cannot open it: {exc.strerror or exc}") from None
    if not path.is_file():
        raise TextureUnreadable("not a regular file")
    return str(path), int(st.st_mtime_ns), int(st.st_size)


def _decode(path: Path) -> NDArray[np.uint8]:
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)   # PNG/TIFF alpha as stored, not premultiplied
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise TextureUnreadable(f"cannot read the image: {oiio.geterror() or 'not an image OpenImageIO reads'}")
    try:
        spec = inp.spec()
        w, h, c = int(spec.width), int(spec.height), int(spec.nchannels)
        if w < 1 or h < 1 or c < 1:
            raise TextureUnreadable(f"an empty image ({w}×{h}, {c} channels)")
        if w * h > MAX_TEXTURE_PIXELS:
            raise TextureUnreadable(f"{w}×{h} pixels is above the {MAX_TEXTURE_PIXELS:,} a texture may have")
        linear = spec.format.basetype in (oiio.FLOAT, oiio.HALF, oiio.DOUBLE)
        pixels = inp.read_image(0, 0, 0, min(c, 4), oiio.FLOAT if linear else oiio.UINT8)
        error = inp.geterror()
        if pixels is None or error:
            raise TextureUnreadable(f"cannot read the image's pixels: {error or oiio.geterror() or 'truncated?'}")
    finally:
        inp.close()
    px = np.asarray(pixels).reshape(h, w, -1)
    if linear:   # OpenEXR and other float files hold linear values: encode them like an 8-bit file
        enc = px.astype(np.float64)
        colour = min(enc.shape[2], 3) if enc.shape[2] != 2 else 1
        enc[..., :colour] = linear_to_srgb(enc[..., :colour])
        px = np.rint(np.clip(np.nan_to_num(enc), 0.0, 1.0) * 255.0).astype(np.uint8)
    rgba = np.empty((h, w, 4), np.uint8)
    n = px.shape[2]
    if n <= 2:   # grey, grey + alpha
        rgba[..., :3] = px[..., :1]
    else:
        rgba[..., :3] = px[..., :3]
    rgba[..., 3] = px[..., 1] if n == 2 else (px[..., 3] if n >= 4 else 255)
    return rgba


def read_texture(path: str | os.PathLike[str]) -> NDArray[np.uint8]:
    """The file's pixels as (h, w, 4) uint8 RGBA, row 0 at the top (cached; do not modify).
    Raises ``TextureUnreadable`` with the reason; :func:`load_layers` turns it into a ParamError."""
    global _cached_bytes
    p = Path(path)
    key = _version(p)
    found = _cache.get(key)
    if found is not None:
        _cache.move_to_end(key)
        return found
    rgba = _decode(p)
    rgba.setflags(write=False)
    _cache[key] = rgba
    _cached_bytes += rgba.nbytes
    while _cached_bytes > CACHE_BYTES and len(_cache) > 1:
        _, old = _cache.popitem(last=False)
        _cached_bytes -= old.nbytes
    return rgba


def _label(p: LeafParams, i: int) -> str:
    return f"leaf {p.name!r}" if p.name else f"leaf {i + 1}"


def _resolved(params: Sequence[LeafParams]) -> dict[str, tuple[str, str, str]]:
    """Each distinct file -> (leaf label, field, path as written) of its first use; resolving
    errors (a path leaving its folder) name the leaf."""
    users: dict[str, tuple[str, str, str]] = {}
    seen: set[tuple[str, str, str]] = set()   # the leaves of a leaf set often share their files
    for i, p in enumerate(params):
        tex = p.texture
        if tex is None or (tex.folder, tex.front, tex.back) in seen:
            continue
        seen.add((tex.folder, tex.front, tex.back))
        for which in ("front", "back"):
            rel = getattr(tex, which)
            if not rel:
                continue
            try:
                path = tex.resolve(which)
            except ParamError as exc:
                where = str(Path(tex.folder or Path.cwd()) / rel)
                raise ParamError(exc.path, f"{_label(p, i)}: {exc.message}", exc.source or where) from None
            users.setdefault(str(path), (_label(p, i), f"texture.{which}", rel))
    return users


def _read_all(params: Sequence[LeafParams]) -> tuple[list[str], list[NDArray[np.uint8]], list[_Version]]:
    users = _resolved(params)
    keys = texture_keys(params)
    images, versions = [], []
    for key in keys:
        label, field, rel = users[key]
        try:
            versions.append(_version(Path(key)))
            images.append(read_texture(key))
        except TextureUnreadable as exc:
            raise ParamError(field, f"{label}: texture {rel!r}: {exc}", source=key) from None
    return keys, images, versions


def check_textures(params: Sequence[LeafParams]) -> None:
    """Read every texture file of ``params`` (into the cache): the errors of :func:`load_layers`,
    before a draw that uploads them in parts."""
    _read_all(params)


def layer_size(shapes: Sequence[tuple[int, ...]], cap: int = MAX_LAYER_SIZE) -> tuple[int, int]:
    """(width, height) of the layers of images of ``shapes`` ((h, w, ...) each): the largest
    width and the largest height, each at most ``cap``."""
    if not shapes:
        return 0, 0
    return min(max(int(s[1]) for s in shapes), cap), min(max(int(s[0]) for s in shapes), cap)


def _array_bytes(layers: int, w: int, h: int) -> int:
    total, a, b = 0, w, h
    while True:
        total += layers * a * b * 4
        if a == 1 and b == 1:
            return total
        a, b = max(1, a // 2), max(1, b // 2)


def _resize(img: NDArray[np.uint8], size: tuple[int, int]) -> NDArray[np.uint8]:
    w, h = size
    if img.shape[1] == w and img.shape[0] == h:
        return img
    out = oiio.ImageBufAlgo.resize(oiio.ImageBuf(np.ascontiguousarray(img)), roi=oiio.ROI(0, w, 0, h, 0, 1, 0, 4))
    pixels = out.get_pixels(oiio.UINT8)
    if out.has_error or pixels is None:
        raise RuntimeError(f"resizing a texture to {w}×{h} failed: {out.geterror()}")
    return np.asarray(pixels, np.uint8).reshape(h, w, 4)


@dataclass(frozen=True)
class TextureLayers:
    """The layers of one array texture: ``keys[i]`` (a resolved file) is ``images[i]``
    ((L, h, w, 4) uint8 RGBA, row 0 at the top = t 0); ``versions`` identify the files read."""

    keys: tuple[str, ...]
    images: NDArray[np.uint8]
    versions: tuple[_Version, ...]

    @property
    def size(self) -> tuple[int, int]:
        return int(self.images.shape[2]), int(self.images.shape[1])


def load_layers(params: Sequence[LeafParams], *, max_side: int = MAX_LAYER_SIZE,
                max_layers: int = 2048) -> TextureLayers:
    """The layers of ``params``' texture files (see the module docstring: one per distinct file,
    in :func:`~leafview.gpu.layout.texture_keys` order, resized to one size). Raises
    :class:`ParamError` for a file that cannot be used and :class:`GpuLimitError` beyond
    ``max_layers`` (``GL_MAX_ARRAY_TEXTURE_LAYERS``)."""
    return _stack(*_read_all(params), max_side=max_side, max_layers=max_layers)


def _stack(keys: list[str], images: list[NDArray[np.uint8]], versions: list[_Version], *, max_side: int,
           max_layers: int) -> TextureLayers:
    if len(keys) > max_layers:
        raise GpuLimitError("texture", f"{len(keys):,} distinct texture files in one draw, above this driver's "
                                       f"GL_MAX_ARRAY_TEXTURE_LAYERS = {max_layers:,}")
    w, h = layer_size([im.shape for im in images], min(MAX_LAYER_SIZE, max_side))
    while keys and _array_bytes(len(keys), w, h) > MAX_RESOURCE_BYTES and max(w, h) > 1:
        w, h = max(1, w // 2), max(1, h // 2)
    stack = np.empty((len(keys), h, w, 4), np.uint8)
    for i, im in enumerate(images):
        stack[i] = _resize(im, (w, h))
    return TextureLayers(tuple(keys), stack, tuple(versions))


# -- GL ----------------------------------------------------------------------------------------------
class LeafTextures:
    """The array texture of the textured leaves of one draw, bound at ``TEXTURE_UNIT``.

    :meth:`update` with the draw's leaves returns the layer keys to pack the records with
    (``pack_leaves(..., textures=keys)``); it reads the files (cached) and rebuilds the texture
    only when the files or their versions changed. No textured leaf: no texture at all."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.texture: moderngl.TextureArray | None = None
        self._versions: tuple[tuple[_Version, ...], tuple[int, int]] | None = None
        info = ctx.info
        self.max_side = int(info.get("GL_MAX_TEXTURE_SIZE", MAX_LAYER_SIZE))
        self.max_layers = int(info.get("GL_MAX_ARRAY_TEXTURE_LAYERS", 256))
        self.uploads = 0   # bytes uploaded (level 0), for tests

    @property
    def layers(self) -> int:
        return 0 if self.texture is None else int(self.texture.layers)

    def update(self, params: Sequence[LeafParams]) -> list[str]:
        """Make the texture hold ``params``' files (errors before anything is uploaded); returns
        the keys, layer i holding ``keys[i]``."""
        if all(p.texture is None for p in params):
            self.release()   # nothing samples it: free it
            return []
        keys, images, versions = _read_all(params)
        signature = (tuple(versions), (self.max_side, self.max_layers))
        if signature == self._versions and self.texture is not None:
            return keys
        data = _stack(keys, images, versions, max_side=self.max_side, max_layers=self.max_layers)
        self._upload(data)
        self._versions = signature
        return list(data.keys)

    def _upload(self, data: TextureLayers) -> None:
        w, h = data.size
        n = len(data.keys)
        if self.texture is not None:
            self.texture.release()
            self.texture = None
        tex = self.ctx.texture_array((w, h, n), 4, np.ascontiguousarray(data.images).tobytes(), dtype="f1")
        try:
            tex.repeat_x = tex.repeat_y = False   # clamp to edge
            tex.build_mipmaps()
            tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        except BaseException:
            tex.release()
            raise
        self.texture = tex
        self.uploads += int(data.images.nbytes)

    def use(self) -> None:
        """Bind the texture (if any leaf is textured) at ``TEXTURE_UNIT``."""
        if self.texture is not None:
            self.texture.use(location=TEXTURE_UNIT)

    def release(self) -> None:
        if self.texture is not None:
            self.texture.release()
            self.texture = None
        self._versions = None

    def describe(self) -> dict[str, Any]:
        """Layers, layer size and bytes (with mipmaps), for logs and benchmarks."""
        if self.texture is None:
            return {"layers": 0, "size": (0, 0), "bytes": 0}
        w, h = self.texture.width, self.texture.height
        nbytes = _array_bytes(self.layers, w, h)
        return {"layers": self.layers, "size": (w, h), "bytes": nbytes, "readable": gib(nbytes)}
