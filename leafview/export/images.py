"""Writing images through OpenImageIO: PNG/TIFF 8-bit tagged sRGB, EXR half-float linear, the
leaf's parameters embedded as metadata, every OIIO call checked, output written atomically
through :mod:`leafview.atomic`. OpenImageIO (libpng in particular) can report success for a file
the disk did not take whole, so every image is read back before it replaces the target: the PNG
trailer, the header and all the pixels. Also the labelled contact sheet."""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio
from numpy.typing import NDArray

from leafview._version import __version__
from leafview.atomic import atomic_output, brief, check_target, failed_write, uninterruptible
from leafview.core.params import LeafParams
from leafview.errors import ImageWriteError

__all__ = ["FORMATS", "ImageWriteError", "format_of", "write_image", "png_bytes", "read_image", "contact_sheet",
           "PARAMS_ATTRIBUTE"]

FORMATS = {"png": ".png", "exr": ".exr", "tif": ".tif"}
_SUFFIXES = {".png": "png", ".exr": "exr", ".tif": "tif", ".tiff": "tif"}
PARAMS_ATTRIBUTE = "leafview:params"


def format_of(path: str | os.PathLike[str]) -> str | None:
    """``png``/``exr``/``tif`` from a file name, or None if the suffix is not an image type."""
    return _SUFFIXES.get(Path(path).suffix.lower())


_PNG_END = b"\0\0\0\0IEND\xaeB`\x82"   # the last chunk of every complete PNG


def _oiio_error(what: str, obj: Any = None) -> ImageWriteError:
    msg = (obj.geterror() if obj is not None else "") or oiio.geterror() or "unknown OpenImageIO error"
    return ImageWriteError(f"{what}: {msg}")


def _has_error(obj: Any) -> bool:
    """OpenImageIO's pending-error flag (a property in its Python bindings, a method in C++)."""
    flag = getattr(obj, "has_error", False)
    return bool(flag() if callable(flag) else flag)


def _write_failure(target: Path, what: str, detail: str) -> Exception:
    """OutputError when the file system explains the failure (full, read-only, no permission),
    else ImageWriteError with OpenImageIO's own text."""
    detail = detail or "unknown OpenImageIO error"
    return failed_write(target, f"{what}: {detail}") or ImageWriteError(f"{target}: {what}: {brief(detail, 300)}")


def _verify_image(tmp: Path, target: Path, fmt: str, shape: tuple[int, ...]) -> None:
    """Read the written file back: a complete PNG ends in IEND, and every format must open with
    the size written and give all its pixels."""
    if fmt == "png":
        with open(tmp, "rb") as fh:
            fh.seek(max(0, os.fstat(fh.fileno()).st_size - len(_PNG_END)))
            if fh.read() != _PNG_END:
                raise _write_failure(target, "the written PNG is incomplete", "no IEND chunk at its end")
    inp = oiio.ImageInput.open(str(tmp))
    if inp is None:
        raise _write_failure(target, "the written image cannot be read back", oiio.geterror())
    try:
        spec = inp.spec()
        if (spec.height, spec.width, spec.nchannels) != shape:
            raise _write_failure(target, "the written image reads back with another size",
                                 f"{spec.width}x{spec.height}x{spec.nchannels}")
        back = inp.read_image(spec.format)
        if back is None or _has_error(inp):
            raise _write_failure(target, "the written image is incomplete", inp.geterror())
    finally:
        inp.close()


def write_image(path: str | os.PathLike[str], pixels: NDArray[Any], *, params: LeafParams | None = None,
                description: str = "") -> Path:
    """Write (h, w, 4) pixels: uint8 sRGB for PNG/TIFF, float linear (stored as half) for EXR.

    The parameters (``params.to_dict()`` as JSON) go into the ``leafview:params`` attribute, which
    PNG keeps as a text chunk, TIFF and EXR as header metadata.
    """
    target = Path(path)
    fmt = format_of(target)
    if fmt is None:
        raise ImageWriteError(f"{target}: unknown image type {target.suffix!r} (use .png, .exr or .tif)")
    check_target(target)   # before any encoding: a one-line error naming the path
    h, w, c = pixels.shape
    if fmt == "exr":
        data = np.ascontiguousarray(pixels, dtype=np.float32)
        spec = oiio.ImageSpec(w, h, c, "half")
        spec.attribute("oiio:ColorSpace", "lin_rec709")
        spec.attribute("compression", "zip")
    else:
        if pixels.dtype != np.uint8:
            raise ImageWriteError(f"{target}: {fmt} expects uint8 sRGB pixels, got {pixels.dtype}")
        data = np.ascontiguousarray(pixels)
        spec = oiio.ImageSpec(w, h, c, "uint8")
        spec.attribute("oiio:ColorSpace", "sRGB")
        spec.attribute("oiio:UnassociatedAlpha", 1)  # our 8-bit pixels carry straight alpha
    spec.attribute("Software", f"leafview {__version__}")
    if description:
        spec.attribute("ImageDescription", description)
    if params is not None:
        text = json.dumps(params.to_dict(), separators=(",", ":"))
        spec.attribute(PARAMS_ATTRIBUTE, text)
        if fmt == "tif":  # TIFF keeps only its own tags: the JSON goes in ImageDescription
            spec.attribute("ImageDescription", text)

    kind: str = fmt

    def verify(tmp: Path) -> None:
        _verify_image(tmp, target, kind, (h, w, c))

    with atomic_output(target, verify=verify) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise _oiio_error(f"{target}: cannot create a {fmt} writer")
        failure, detail = "", ""
        with uninterruptible():   # open, pixels and close as one step: a signal waits for the close
            if not out.open(str(tmp), spec):
                failure, detail = "cannot open for writing", out.geterror()
            elif not out.write_image(data):
                failure, detail = "writing pixels failed", out.geterror()
            closed = out.close()
        if not failure and (not closed or _has_error(out)):
            failure, detail = "closing failed", out.geterror()
        if failure:
            raise _write_failure(target, failure, detail)
    return target


def png_bytes(pixels: NDArray[np.uint8]) -> bytes:
    """(h, w, c) uint8 sRGB pixels (c = 1, 3 or 4; row 0 at the top) as the bytes of a PNG file, for
    in-memory uses such as Jupyter's ``_repr_png_``: encoded by :func:`write_image` into a private
    temporary folder that is removed before returning."""
    image = np.asarray(pixels)
    if image.ndim == 2:
        image = image[:, :, None]
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (1, 3, 4):
        raise ImageWriteError(f"png_bytes expects (h, w, 1|3|4) uint8 pixels, got {image.dtype} {image.shape}")
    with tempfile.TemporaryDirectory(prefix="leafview-png-") as folder:
        path = Path(folder) / "image.png"
        write_image(path, image)
        return path.read_bytes()


def read_image(path: str | os.PathLike[str]) -> tuple[NDArray[Any], dict[str, Any]]:
    """Read pixels (native type) and the metadata that leafview writes (for tests and tools)."""
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # keep PNG/TIFF straight alpha as written
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise ImageWriteError(f"{path}: cannot open: {oiio.geterror()}")
    try:
        spec = inp.spec()
        pixels = inp.read_image(spec.format)
        if pixels is None:
            raise ImageWriteError(f"{path}: cannot read pixels: {inp.geterror()}")
        meta = {a.name: a.value for a in spec.extra_attribs}
        meta["format"] = str(spec.format)
        if PARAMS_ATTRIBUTE not in meta and str(meta.get("ImageDescription", "")).startswith('{"schema"'):
            meta[PARAMS_ATTRIBUTE] = meta["ImageDescription"]
    finally:
        inp.close()
    return pixels, meta


def contact_sheet(images: Sequence[NDArray[np.uint8]], labels: Sequence[str], *, columns: int | None = None,
                  background: tuple[float, float, float] = (0.965, 0.965, 0.955)) -> NDArray[np.uint8]:
    """Lay out uint8 RGBA thumbnails (all the same size) in a grid, each with its label below.

    Returns an opaque (H, W, 4) uint8 sRGB image.
    """
    if not images:
        raise ValueError("contact sheet needs at least one image")
    th, tw = images[0].shape[:2]
    n = len(images)
    cols = columns or min(n, max(1, int(np.ceil(np.sqrt(n * 1.6)))))
    rows = (n + cols - 1) // cols
    font = max(10, min(tw, 2 * th) // 12)
    label_h = int(font * 1.7)
    canvas = np.empty((rows * (th + label_h), cols * tw, 3), dtype=np.float32)
    canvas[:] = background
    for i, img in enumerate(images):
        if img.shape[:2] != (th, tw):
            raise ValueError(f"contact sheet images differ in size: {img.shape[:2]} vs {(th, tw)}")
        x, y = (i % cols) * tw, (i // cols) * (th + label_h)
        rgba = img.astype(np.float32) / 255.0
        a = rgba[..., 3:4]
        cell = canvas[y:y + th, x:x + tw]
        cell[:] = rgba[..., :3] * a + cell * (1.0 - a)  # "over", unassociated alpha, in sRGB
    sheet = oiio.ImageBuf(np.ascontiguousarray(np.concatenate(
        [canvas, np.ones(canvas.shape[:2] + (1,), np.float32)], axis=-1)))
    for i, label in enumerate(labels):
        x, y = (i % cols) * tw, (i // cols) * (th + label_h)
        if not oiio.ImageBufAlgo.render_text(sheet, x + tw // 2, y + th + int(font * 1.15), label,
                                             font, "DroidSans", [0.15, 0.17, 0.15, 1.0], "center"):
            raise _oiio_error("contact sheet label", sheet)
    pixels: NDArray[np.uint8] | None = sheet.get_pixels(oiio.UINT8)
    if pixels is None:
        raise _oiio_error("contact sheet pixels", sheet)
    return pixels
