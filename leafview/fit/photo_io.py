"""Photographs and scans of leaves, read into one form: sRGB float32 pixels and the pixel scale.

:func:`read_photo` reads PNG, JPEG and TIFF (and whatever else OpenImageIO reads) of 8 or 16 bits
(or float), grey, grey + alpha, RGB or RGBA; :func:`as_photo` also takes an array already in
memory. What comes back is a :class:`Photo`:

* **Pixels** ``rgb`` (h, w, 3) float32 sRGB in [0, 1]: integers are divided by their maximum,
  grey is repeated into three channels, and an alpha channel is composited over white (a leaf cut
  out onto transparency then lies on white paper, as a scan would). Float files are taken as
  sRGB-encoded and clipped to [0, 1]. The EXIF ``Orientation`` of the file is applied, so that
  pixel (x, y) is where any image viewer shows it (the ``--base`` / ``--apex`` overrides are
  given in those pixels).
* **Scale** ``dpi``: from the file's ``XResolution`` and ``ResolutionUnit`` (inches, or
  centimetres converted to inches), ``None`` when the file has none or its unit is not a length
  (PNG's "unknown" unit states an aspect ratio only).

Refused, with a :class:`~leafview.errors.ParamError` whose message starts with the file: a path
that is not a regular file (a directory, FIFO or device is never opened, as in
:mod:`leafview.inputs`), a file OpenImageIO cannot decode, a file whose pixels cannot be read in
full (a truncated PNG, JPEG or TIFF: OpenImageIO's error flag is checked after the read, so a
half-decoded image never comes back), images of more than :data:`MAX_PHOTO_PIXELS` pixels (checked
from the header, before any pixel is read) and images with a side shorter than
:data:`MIN_PHOTO_SIDE` pixels.
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass
from typing import Any

import numpy as np
import OpenImageIO as oiio
from numpy.typing import NDArray

from leafview.errors import ParamError

__all__ = ["Photo", "read_photo", "as_photo", "MAX_PHOTO_PIXELS", "MIN_PHOTO_SIDE"]

MAX_PHOTO_PIXELS = 50_000_000     # 50 MP: width × height of the largest photo read
MIN_PHOTO_SIDE = 16               # pixels: a smaller image cannot show a leaf's outline
_CM_PER_INCH = 2.54


@dataclass(frozen=True, eq=False)
class Photo:
    """A leaf photograph: ``rgb`` (h, w, 3) float32 sRGB in [0, 1], row 0 at the top; ``dpi`` the
    pixels per inch from the file's resolution (``None`` when it has none); ``path`` the file it
    was read from (``''`` for an array given in memory)."""

    rgb: NDArray[np.float32]
    dpi: float | None
    path: str

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return int(self.rgb.shape[1]), int(self.rgb.shape[0])


def _fail(source: str, message: str) -> ParamError:
    """An error about the file ``source``, or about the ``image`` argument when it is ''."""
    return ParamError("" if source else "image", message, source or None)


def _check_size(width: int, height: int, source: str) -> None:
    if width * height > MAX_PHOTO_PIXELS:
        raise _fail(source, f"a {width}×{height} px image ({width * height / 1e6:.1f} MP) is larger than the "
                            f"{MAX_PHOTO_PIXELS / 1e6:.0f} MP a photo may have; scale it down first")
    if min(width, height) < MIN_PHOTO_SIDE:
        raise _fail(source, f"a {width}×{height} px image is too small to show a leaf (each side must be at "
                            f"least {MIN_PHOTO_SIDE} px)")


def _dpi(spec: Any) -> float | None:
    """Pixels per inch from the spec's ``XResolution`` / ``ResolutionUnit``, or None."""
    res = float(spec.get_float_attribute("XResolution", 0.0))
    unit = str(spec.get_string_attribute("ResolutionUnit", "")).strip().lower()
    if not (np.isfinite(res) and res > 0):
        return None
    if unit in ("in", "inch", "inches", "2"):
        return res
    if unit in ("cm", "centimeter", "centimetre", "3"):
        return res * _CM_PER_INCH
    return None


def _orient(px: NDArray[Any], orientation: int) -> NDArray[Any]:
    """Pixels turned as the EXIF ``Orientation`` tag (1-8) asks, so row 0 is the top seen."""
    table = {2: lambda a: a[:, ::-1], 3: lambda a: a[::-1, ::-1], 4: lambda a: a[::-1],
             5: lambda a: a.transpose(1, 0, 2), 6: lambda a: a.transpose(1, 0, 2)[:, ::-1],
             7: lambda a: a.transpose(1, 0, 2)[::-1, ::-1], 8: lambda a: a.transpose(1, 0, 2)[::-1]}
    turn = table.get(orientation)
    return px if turn is None else turn(px)


def read_photo(path: str | os.PathLike[str]) -> Photo:
    """The photo in the image file ``path`` (see the module docstring for what is accepted and
    refused)."""
    src = os.fspath(path)
    try:
        st = os.stat(src)
    except FileNotFoundError:
        raise _fail(src, "no such file") from None
    except OSError as exc:
        raise _fail(src, f"cannot read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise _fail(src, "is not a regular file, expected an image file (PNG, JPEG or TIFF)")
    oiio.geterror()                                # drop an error left over from an earlier call
    inp = oiio.ImageInput.open(src)
    if inp is None:
        raise _fail(src, f"not an image OpenImageIO can read: {_first_line(oiio.geterror()) or 'unknown format'}")
    try:
        spec = inp.spec()
        if spec.deep:
            raise _fail(src, "a deep image (several samples per pixel) is not a photo")
        _check_size(spec.width, spec.height, src)
        if spec.nchannels < 1:
            raise _fail(src, "the image has no channels")
        nch = min(spec.nchannels, 4)
        fmt = spec.format.basetype
        want = "uint8" if fmt in (oiio.UINT8, oiio.INT8) else "uint16" if fmt in (oiio.UINT16, oiio.INT16) else "float"
        pixels = inp.read_image(0, 0, 0, nch, want)
        if pixels is None or inp.has_error:
            raise _fail(src, f"the pixels cannot be read in full (a truncated or damaged file?): "
                             f"{_first_line(inp.geterror()) or _first_line(oiio.geterror()) or 'read failed'}")
        dpi = _dpi(spec)
        orientation = int(spec.get_int_attribute("Orientation", 1))
    finally:
        inp.close()
    arr = np.asarray(pixels)
    arr = arr.reshape(spec.height, spec.width, nch)
    if nch == 2:                                    # grey + alpha
        arr = arr[:, :, [0, 0, 0, 1]]
    elif nch == 1:
        arr = arr[:, :, [0, 0, 0]]
    rgb = _to_rgb(_orient(arr, orientation), src)
    return Photo(rgb=rgb, dpi=dpi, path=src)


def _first_line(text: str) -> str:
    return text.strip().splitlines()[0] if text.strip() else ""


def _to_rgb(arr: NDArray[Any], source: str) -> NDArray[np.float32]:
    """(h, w, 3 or 4) integers or floats to (h, w, 3) float32 in [0, 1], alpha over white."""
    if arr.dtype == np.uint8:
        px = arr.astype(np.float32) * np.float32(1 / 255)
    elif arr.dtype == np.uint16:
        px = arr.astype(np.float32) * np.float32(1 / 65535)
    elif arr.dtype.kind == "f":
        px = arr.astype(np.float32)
        bad = ~np.isfinite(px)
        if bad.any():
            raise _fail(source, f"{int(bad.sum()):,} pixel values are not finite (NaN or Inf)")
        top = float(px.max()) if px.size else 0.0
        if top > 1.5 and not source:
            raise _fail(source, f"float pixels must lie in [0, 1], the largest is {top:g} (divide 8-bit values by 255)")
        np.clip(px, 0.0, 1.0, out=px)
    else:
        raise _fail(source, f"pixels of type {arr.dtype} are not supported: give uint8, uint16 or float in [0, 1]")
    if px.shape[2] == 4:
        alpha = px[:, :, 3:4]
        px = px[:, :, :3] * alpha + (np.float32(1) - alpha)
    return np.ascontiguousarray(px[:, :, :3], dtype=np.float32)


def as_photo(image_or_path: Photo | str | os.PathLike[str] | NDArray[Any]) -> Photo:
    """A :class:`Photo` from a path (:func:`read_photo`), a :class:`Photo` (returned as it is), or
    an array: (h, w) grey, (h, w, 3) RGB or (h, w, 4) RGBA, of uint8, uint16 or float in [0, 1]
    (sRGB). An array has no resolution (``dpi`` None) and an empty ``path``."""
    if isinstance(image_or_path, Photo):
        return image_or_path
    if isinstance(image_or_path, (str, os.PathLike)):
        return read_photo(image_or_path)
    if not isinstance(image_or_path, np.ndarray):
        raise ParamError("image", f"expected a path or an image array, got {type(image_or_path).__name__}")
    arr = image_or_path
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.ndim != 3 or arr.shape[2] not in (1, 3, 4):
        raise ParamError("image", f"expected an (h, w), (h, w, 3) or (h, w, 4) array, got shape {arr.shape}")
    _check_size(arr.shape[1], arr.shape[0], "")
    if arr.shape[2] == 1:
        arr = np.repeat(arr, 3, axis=2)
    if arr.dtype == bool or arr.dtype.kind not in "uf" or (arr.dtype.kind == "u" and arr.itemsize > 2):
        raise ParamError("image", f"pixels of type {arr.dtype} are not supported: give uint8, uint16 or float in [0, 1]")
    return Photo(rgb=_to_rgb(arr, ""), dpi=None, path="")
