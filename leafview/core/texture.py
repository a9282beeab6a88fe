"""A leaf's image textures: files beside the leaf file, addressed by the leaf's own (u, v).

A textured leaf (``LeafParams.texture``) names a front image and optionally a back image. The
surface point at (u, v) (Mündermann et al. 2003, eq. 1: the parameter domain of the blade is
the texture's domain) shows the texel at :func:`texture_st`. This module is the one place for:

* **The convention.** ``s = (1 - u) / 2`` and ``t = 1 - v`` in image coordinates (s to the right,
  t down, row 0 at the top): a stored texture shows the blade as seen from above (the front),
  apex up, base down, the u = +1 side (leaf x < 0) on the left. OpenGL samples the rows as stored
  (row 0 at t = 0), glTF uses (s, t) as they are, and OBJ and USD, whose texture origin is the
  bottom-left corner, use (s, 1 - t) = ((1 - u) / 2, v).
* **The paths.** Relative POSIX paths (``NAME.front.png``), resolved against the folder of the
  leaf file that names them (``LeafTexture.folder``, set by the loader; the current folder for a
  leaf built in memory). Absolute paths, drive letters, backslashes, empty segments and paths that
  leave the folder (``..`` or a symbolic link pointing out of it) are refused, naming the field.
* **The formats.** PNG, JPEG, TIFF and OpenEXR (by suffix).

Reading the pixels is the GPU layer's business (:mod:`leafview.gpu.textures`); this module does
not open the files.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.errors import ParamError

__all__ = ["LeafTexture", "TEXTURE_SUFFIXES", "MAX_TEXTURE_PATH", "parse_texture", "check_texture_path",
           "texture_st", "uv_of_st", "with_folder", "bilinear"]

TEXTURE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr")
MAX_TEXTURE_PATH = 255          # characters of a texture path as written in the leaf file
_KEYS = ("front", "back")


def check_texture_path(value: Any, path: str) -> str:
    """``value`` when it is a safe relative texture path (see the module docstring), else a
    :class:`ParamError` naming ``path`` (the field, e.g. ``texture.front``)."""
    if not isinstance(value, str):
        raise ParamError(path, f"expected a relative file path (a string), got {type(value).__name__}")
    if not value:
        raise ParamError(path, "empty path: name an image file beside the leaf file")
    if len(value) > MAX_TEXTURE_PATH:
        raise ParamError(path, f"{len(value):,} characters; at most {MAX_TEXTURE_PATH} are accepted")
    if any(ord(ch) < 32 or ch == "\x7f" for ch in value):
        raise ParamError(path, "control characters in the path")
    if "\\" in value or (len(value) >= 2 and value[1] == ":"):
        raise ParamError(path, f"{value!r}: write the path with '/' and without a drive letter, relative "
                               "to the leaf file's folder")
    p = PurePosixPath(value)
    if p.is_absolute():
        raise ParamError(path, f"{value!r} is absolute: texture paths are relative to the leaf file's folder")
    parts = value.split("/")
    if any(part in ("", ".", "..") for part in parts):
        raise ParamError(path, f"{value!r} leaves the leaf file's folder or has an empty segment: name a "
                               "file in that folder or below it")
    if p.suffix.lower() not in TEXTURE_SUFFIXES:
        raise ParamError(path, f"{value!r}: a texture is an image file ({', '.join(TEXTURE_SUFFIXES)})")
    return value


@dataclass(frozen=True)
class LeafTexture:
    """The front image and the optional back image of a leaf (relative paths, see the module
    docstring); ``folder`` is the absolute folder they resolve against ('' = the current folder).
    ``folder`` is where the leaf was read from, not part of the leaf: it is not saved and does
    not take part in comparisons."""

    front: str
    back: str = ""
    folder: str = field(default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        check_texture_path(self.front, "texture.front")
        if self.back:
            check_texture_path(self.back, "texture.back")

    def to_dict(self) -> dict[str, str]:
        return {"front": self.front, **({"back": self.back} if self.back else {})}

    def resolve(self, which: str = "front") -> Path:
        """The file of ``which`` ('front' or 'back'), checked to stay inside :attr:`folder` once
        symbolic links are followed; raises :class:`ParamError` naming ``texture.<which>``."""
        rel = getattr(self, which)
        if which not in _KEYS or not rel:
            raise ParamError(f"texture.{which}", "no such texture on this leaf")
        root = Path(self.folder) if self.folder else Path.cwd()
        target = (root / rel).resolve()
        if not target.is_relative_to(root.resolve()):
            raise ParamError(f"texture.{which}", f"{rel!r} resolves to {target}, outside the leaf file's folder "
                                                 f"{root}: texture paths may not leave it (symbolic link?)")
        return target

    def paths(self) -> tuple[Path, Path | None]:
        """The resolved front and back files (back None when there is none)."""
        return self.resolve("front"), (self.resolve("back") if self.back else None)


def parse_texture(value: Any, path: str = "texture") -> LeafTexture:
    """Validate the ``texture`` table of a leaf document (``{"front": ..., "back": ...}``)."""
    if not isinstance(value, Mapping):
        raise ParamError(path, f"expected a table with 'front' (and optionally 'back'), got {type(value).__name__}")
    for key in value:
        if key not in _KEYS:
            raise ParamError(f"{path}.{key}", f"unknown key (known: {', '.join(_KEYS)})")
    if "front" not in value:
        raise ParamError(f"{path}.front", "missing field: the front image's path")
    front = check_texture_path(value["front"], f"{path}.front")
    back = check_texture_path(value["back"], f"{path}.back") if "back" in value else ""
    return LeafTexture(front, back)


def with_folder(texture: LeafTexture | None, folder: str | os.PathLike[str]) -> LeafTexture | None:
    """``texture`` resolving against ``folder`` (made absolute), None stays None."""
    if texture is None:
        return None
    return LeafTexture(texture.front, texture.back, str(Path(folder).resolve()))


def texture_st(u: ArrayLike, v: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Image coordinates (s right, t down, both in [0, 1]) of the leaf point (u, v)."""
    uu = np.asarray(u, np.float64)
    vv = np.asarray(v, np.float64)
    return 0.5 * (1.0 - uu), 1.0 - vv


def uv_of_st(s: ArrayLike, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The inverse of :func:`texture_st`: (u, v) of the image point (s, t)."""
    ss = np.asarray(s, np.float64)
    tt = np.asarray(t, np.float64)
    return 1.0 - 2.0 * ss, 1.0 - tt


def bilinear(image: ArrayLike, s: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """GL's linear filtering of ``image`` (h, w, C) at image coordinates (s, t), level 0, clamped to
    the edge: texel (i, j) (column, row) is centred at ((i + 0.5) / w, (j + 0.5) / h), row 0 at
    t = 0. The numpy twin of a ``texture()`` lookup (image textures, vein fields)."""
    img = np.asarray(image, np.float64)
    h, w = img.shape[:2]
    x = np.asarray(s, np.float64) * w - 0.5
    y = np.asarray(t, np.float64) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    i0 = np.clip(x0.astype(np.int64), 0, w - 1)
    i1 = np.clip(x0.astype(np.int64) + 1, 0, w - 1)
    j0 = np.clip(y0.astype(np.int64), 0, h - 1)
    j1 = np.clip(y0.astype(np.int64) + 1, 0, h - 1)
    top = img[j0, i0] * (1.0 - fx) + img[j0, i1] * fx
    bottom = img[j1, i0] * (1.0 - fx) + img[j1, i1] * fx
    out: NDArray[np.float64] = top * (1.0 - fy) + bottom * fy
    return out
