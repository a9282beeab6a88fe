"""The image textures of exported leaves: each distinct file read once, checked, stored as PNG or JPEG
and given a safe file name for the folder of the export.

A textured leaf (:class:`leafview.core.texture.LeafTexture`) names a front image and optionally a
back image beside its leaf file. The writers receive them from here:

* **Checked before anything is written.** :func:`check_textures` (before the bake) finds every
  file, and :func:`load_textures` (in each writer, before its first file) reads and decodes it;
  a file that is missing, not a regular file, too large, outside the leaf file's folder or not a
  readable image is a :class:`~leafview.errors.ParamError` naming the field
  (``texture.front``/``texture.back``), the leaf and the file.
* **Once per file.** Leaves and shapes naming the same file (the leaves of a textured species,
  or a leaf set whose leaves share an image) share one :class:`TextureImage`: one image in a
  glTF, one file beside an OBJ, PLY or USD export, one material per side.
* **PNG or JPEG.** What glTF allows, and what every OBJ and USD importer reads: a PNG or JPEG
  file (by its content, not its suffix) is kept byte for byte; any other image (TIFF, OpenEXR)
  is stored as the 8-bit sRGB RGBA PNG of the pixels the renderer draws
  (:func:`leafview.gpu.textures.read_texture`: float files are linear and get sRGB-encoded).
  Every file is decoded in full first, so a truncated or unreadable image is refused.
* **Names from the texture file, never from a leaf.** The file name beside the export is the
  image's own name made one safe path component (:func:`leafview.atomic.safe_component`, then
  blanks and non-ASCII characters as ``_``, which ``.mtl`` files and PLY headers need), with
  ``.png``/``.jpg`` for its content, and unique within the export (``front.png``,
  ``front-2.png``). :func:`write_images` also keeps two exports of one run
  (``leafview export A B -o DIR``) from writing different images under one name.

The texture coordinates that address these images are :func:`leafview.core.texture.texture_st`
of each vertex's (u, v); the writers take them from there.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from leafview.atomic import UniqueNames, outputs, safe_component, write_bytes
from leafview.core.texture import LeafTexture
from leafview.errors import ParamError
from leafview.export.images import png_bytes
from leafview.gpu.textures import TextureUnreadable as Unreadable  # its reason for a file it cannot decode
from leafview.gpu.textures import read_texture
from leafview.inputs import read_bytes

__all__ = ["TextureImage", "SceneTextures", "check_textures", "load_textures", "write_images", "PNG", "JPEG"]

PNG, JPEG = "image/png", "image/jpeg"
_MAGIC = {PNG: b"\x89PNG\r\n\x1a\n", JPEG: b"\xff\xd8\xff"}
_SUFFIX = {PNG: ".png", JPEG: ".jpg"}
_SIDES = ("front", "back")

TexturedLeaf = tuple[str, LeafTexture | None]   # (the leaf's name for messages, its texture)


@dataclass(frozen=True, eq=False)
class TextureImage:
    """One image of an export: ``data`` (PNG or JPEG bytes, ``mime``), read from ``source``, to
    be stored as ``name`` (a safe file name, unique within the export)."""

    source: Path
    data: bytes = field(repr=False)
    mime: str
    name: str


@dataclass
class SceneTextures:
    """The images of one export: ``images`` in first-use order, and per textured part (its index
    in the sequence given to :func:`load_textures`) its front and back image (the front one when
    the leaf has no back image)."""

    images: list[TextureImage] = field(default_factory=list)
    sides: dict[int, tuple[TextureImage, TextureImage]] = field(default_factory=dict)

    def of(self, index: int) -> tuple[TextureImage, TextureImage] | None:
        return self.sides.get(index)

    def front_only(self) -> SceneTextures:
        """The front images alone, for one-sided formats (OBJ, PLY)."""
        sides = {k: (front, front) for k, (front, _) in self.sides.items()}
        used = {front for front, _ in sides.values()}
        return SceneTextures([image for image in self.images if image in used], sides)

    def __bool__(self) -> bool:
        return bool(self.images)


def _source(label: str, texture: LeafTexture, which: str) -> Path:
    """The resolved file of ``texture.<which>``, or a ParamError naming the leaf and the file."""
    try:
        path = texture.resolve(which)
    except ParamError as exc:
        raise ParamError(exc.path, f"leaf {label!r}: {exc.message}") from None
    try:
        st = os.stat(path)
    except OSError as exc:
        why = "no such file" if isinstance(exc, FileNotFoundError) else (exc.strerror or str(exc))
        raise ParamError(f"texture.{which}", f"leaf {label!r}: {path}: {why}") from None
    if not stat.S_ISREG(st.st_mode):
        raise ParamError(f"texture.{which}", f"leaf {label!r}: {path}: not a regular file")
    return path


def _keys(texture: LeafTexture) -> tuple[str, str, str]:
    return texture.folder, texture.front, texture.back


def check_textures(leaves: Iterable[TexturedLeaf]) -> None:
    """Find every texture file of ``leaves`` (``(name, texture)`` pairs) before any work: the
    ParamError of a missing or unsafe one names the leaf and the file."""
    seen: set[tuple[str, str, str]] = set()
    for label, texture in leaves:
        if texture is None or _keys(texture) in seen:
            continue
        seen.add(_keys(texture))
        for which in _SIDES:
            if getattr(texture, which):
                _source(label, texture, which)


def _read(path: Path, label: str, which: str) -> tuple[bytes, str]:
    """PNG or JPEG bytes of the image ``path`` (checked to decode in full) and their MIME type."""
    try:
        data = read_bytes(path, what="image")
        pixels = read_texture(path)        # decodes in full, as the renderer reads it (and caches it)
    except ParamError as exc:
        raise ParamError(f"texture.{which}", f"leaf {label!r}: {path}: {exc.message}") from None
    except Unreadable as exc:
        raise ParamError(f"texture.{which}", f"leaf {label!r}: {path}: {exc}") from None
    for mime, magic in _MAGIC.items():
        if data.startswith(magic):
            return data, mime
    return png_bytes(np.asarray(pixels)), PNG


def _file_name(source: Path, mime: str) -> tuple[str, str]:
    """(stem, suffix) of the file name ``source`` gets beside an export: one safe component, in
    ASCII without blanks (``.mtl`` and PLY headers split on blanks and are ASCII)."""
    stem = safe_component(source.stem, fallback="texture")
    return "".join(c if c.isascii() and not c.isspace() else "_" for c in stem), _SUFFIX[mime]


def load_textures(parts: Sequence[TexturedLeaf]) -> SceneTextures:
    """Read the images of ``parts`` (``(name, texture)`` per part, in the writer's part order),
    each distinct file once; ParamError naming the leaf and the file on any failure."""
    out = SceneTextures()
    by_source: dict[Path, TextureImage] = {}
    by_texture: dict[tuple[str, str, str], tuple[TextureImage, TextureImage]] = {}
    names = UniqueNames(fallback="texture")
    for index, (label, texture) in enumerate(parts):
        if texture is None:
            continue
        key = _keys(texture)
        if key not in by_texture:
            images = []
            for which in _SIDES:
                if not getattr(texture, which):
                    continue
                source = _source(label, texture, which)
                if source not in by_source:
                    data, mime = _read(source, label, which)
                    stem, suffix = _file_name(source, mime)
                    by_source[source] = TextureImage(source, data, mime, names(stem) + suffix)
                    out.images.append(by_source[source])
                images.append(by_source[source])
            by_texture[key] = (images[0], images[-1])
        out.sides[index] = by_texture[key]
    return out


def write_images(textures: SceneTextures, folder: Path) -> dict[TextureImage, str]:
    """Write every image of ``textures`` into ``folder`` (atomically, in the open
    :func:`~leafview.atomic.outputs` transaction if there is one) and return the file name each
    got: its own name, or a numbered one when another export of the same transaction already
    staged a different image under that name."""
    written: dict[TextureImage, str] = {}
    taken: set[str] = set()
    with outputs() as tx:
        for image in textures.images:
            stem, suffix = os.path.splitext(image.name)
            name, k = image.name, 1
            while True:
                staged = tx.staged(folder / name)
                if name.casefold() not in taken and (staged is None or staged.read_bytes() == image.data):
                    break
                k += 1
                name = f"{stem}-{k}{suffix}"
            taken.add(name.casefold())
            write_bytes(folder / name, image.data)
            written[image] = name
    return written
