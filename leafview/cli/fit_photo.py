"""``leafview fit PHOTO -o NAME.leaf.json`` and ``leafview fit DIR -o OUTDIR``: leaves fitted to
photographs and scans (:func:`leafview.fit.photo.fit_image`), called by :mod:`leafview.cli.fit`
for an image file or a folder.

One photo writes the leaf and its front texture ``NAME.front.png`` (8-bit RGBA, alpha from the
leaf's mask) beside it, named in the leaf's ``texture`` by its relative path, both or neither.
``--back BACK.jpg`` (a photo of the same leaf turned over; :func:`leafview.fit.photo_back.back_fit`)
adds its back texture ``NAME.back.png``, named as the texture's ``back``; a back photo that shows
another leaf is refused before anything is written. ``--back-base`` / ``--back-apex`` replace the
landmarks found in the back photo.
``-o NAME.leaf.json`` (or ``.json``, ``.toml``) always writes one symmetric leaf, with a warning
when the sides differ enough for two halves; ``-o NAME.leaves.json`` writes a leaf set holding the
two one-sided halves of an asymmetric leaf (or the one leaf of a symmetric one).

A folder fits every image in it (``.png``, ``.jpg``, ``.jpeg``, ``.tif``, ``.tiff``, not its
sub-folders) with a progress bar, and writes per photo ``NAME.leaf.json`` (``NAME.leaves.json``
for an asymmetric leaf) and ``NAME.front.png`` into ``OUTDIR``, ``report.json`` (per photo the fit's
measures, or the error that stopped it) and ``contact.png`` (per photo: the photo, the fit drawn
over it, the fitted leaf rendered with its texture). A photo that fails does not stop the others;
the exit code is then 1.

Bad input (no leaf, two touching leaves, a tiny or truncated image, an option that does not apply)
is one line naming the file, exit 2, and nothing written. Warnings (a leaf cut by the border, no
resolution in the file) go to stderr.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from leafview.atomic import outputs, safe_component, write_text
from leafview.bench.fit_photo import fit_cells, fit_label
from leafview.cli.args import (
    EXIT_FAILURE,
    EXIT_OK,
    int_in_range,
    output_directory,
    output_names,
    progress_bar,
    refuse_directory,
    report,
)
from leafview.core.io import save_leaves, save_params
from leafview.core.params import LeafParams
from leafview.core.texture import LeafTexture, with_folder
from leafview.errors import GLUnavailable, UsageError, one_line
from leafview.export.images import contact_sheet, write_image
from leafview.fit.photo import DPI_RANGE, ImageFit, fit_image
from leafview.fit.photo_back import BackFit, back_fit
from leafview.fit.photo_batch import MAX_JOBS, default_jobs, fit_photos
from leafview.fit.photo_face import FACES
from leafview.fit.photo_lobed import LOBED_MODES
from leafview.fit.photo_texture import MAX_TEXTURE_SIZE, MIN_TEXTURE_SIZE, texture_uint8
from leafview.gpu import default_renderer
from leafview.gpu.renderer import LeafRenderer

__all__ = ["PHOTO_SUFFIXES", "add_arguments", "run", "is_photo_input", "leaf_name", "write_fit", "refuse_photo_options"]

PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff")
SHEET_WIDTH = 2048          # the contact sheet's width at most, in pixels
_CELL = 224                 # a contact sheet tile's side for up to _FULL_CELLS photos
_FULL_CELLS = 60
_CLOUD_OPTIONS = (("scanlines", "--scanlines"), ("iterations", "--iterations"), ("keep_unexplained", "--keep-unexplained"))
_PHOTO_OPTIONS = (("base", "--base"), ("apex", "--apex"), ("dpi", "--dpi"), ("texture_size", "--texture-size"),
                  ("jobs", "--jobs"), ("lobed", "--lobed"), ("face", "--face"), ("back", "--back"), ("back_base", "--back-base"),
                  ("back_apex", "--back-apex"))


# -- options -------------------------------------------------------------------------------------------
def _point(text: str) -> tuple[float, float]:
    try:
        if len(text) > 60:
            raise ValueError(text)
        x, y = (float(c) for c in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y in pixels such as 412,880, got {text[:60]!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise argparse.ArgumentTypeError(f"expected finite pixel coordinates, got {text[:60]!r}")
    return x, y


def _dpi(text: str) -> float:
    try:
        value = float(text) if len(text) <= 40 else math.nan
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and DPI_RANGE[0] <= value <= DPI_RANGE[1]):
        raise argparse.ArgumentTypeError(f"expected dots per inch in {DPI_RANGE[0]:g}..{DPI_RANGE[1]:g}, "
                                         f"got {text[:40]!r}")
    return value


def _jobs(text: str) -> int:
    return int_in_range(text, lo=1, hi=MAX_JOBS, what="worker processes", name="--jobs")


def _texture_size(text: str) -> int:
    return int_in_range(text, lo=MIN_TEXTURE_SIZE, hi=MAX_TEXTURE_SIZE, what="texels", name="--texture-size")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The photo options of ``leafview fit`` (the command's other options are in :mod:`leafview.cli.fit`)."""
    p.add_argument("--base", type=_point, default=None, metavar="X,Y",
                   help="photos: the blade's base in image pixels (x right, y down), replacing the one found")
    p.add_argument("--apex", type=_point, default=None, metavar="X,Y", help="photos: the blade's apex in image pixels")
    p.add_argument("--dpi", type=_dpi, default=None,
                   help="photos: dots per inch, replacing the file's resolution (the leaf's scale becomes metres)")
    p.add_argument("--texture-size", type=_texture_size, default=None, metavar="N",
                   help="photos: side of the square front (and back) texture in texels (default 512)")
    p.add_argument("--lobed", choices=LOBED_MODES, default=None,
                   help="photos: fit a lobed leaf (its closed margin): auto (when the outline looks lobed; "
                        "the default), on, or off (always the unilobed model)")
    p.add_argument("--face", choices=FACES, default=None,
                   help="photos: which side of the leaf faces the camera: auto (the default: face down where the "
                        "veins show light/dark pairs of raised veins lit from one side, else face up), up, or down "
                        "(the leaf is fitted mirrored about its midrib and the photo becomes its back texture "
                        "NAME.back.png as well); with --back, PHOTO is taken as face up")
    p.add_argument("--back", default=None, metavar="PHOTO",
                   help="one photo: a photo of the same leaf turned over (face down), made into its back texture "
                        "NAME.back.png")
    p.add_argument("--back-base", type=_point, default=None, metavar="X,Y",
                   help="with --back: the blade's base in the back photo's pixels, replacing the one found")
    p.add_argument("--back-apex", type=_point, default=None, metavar="X,Y",
                   help="with --back: the blade's apex in the back photo's pixels")
    p.add_argument("--jobs", type=_jobs, default=None, metavar="N",
                   help=f"a folder of photos: worker processes (default: one per core, at most {MAX_JOBS})")


def is_photo_input(path: str | Path) -> bool:
    """Whether ``leafview fit`` takes ``path`` as photos: an image file (by its suffix) or a folder."""
    p = Path(path)
    return p.suffix.lower() in PHOTO_SUFFIXES or p.is_dir()


def refuse_photo_options(args: argparse.Namespace) -> None:
    """UsageError for a photo option given with a point cloud."""
    for attr, flag in _PHOTO_OPTIONS:
        if getattr(args, attr, None) is not None:
            raise UsageError(f"{flag} applies to photos (.png, .jpg, .jpeg, .tif, .tiff), not to the point cloud "
                             f"{args.input}")


def _refuse_cloud_options(args: argparse.Namespace) -> None:
    for attr, flag in _CLOUD_OPTIONS:
        if getattr(args, attr, None) not in (None, False):
            raise UsageError(f"{flag} applies to point clouds, not to the photo input {args.input}")


def leaf_name(path: Path) -> str:
    """The leaf's name from its output file: ``NAME`` of ``NAME.leaf.json``, ``.leaves.json``,
    ``.json`` or ``.toml``."""
    name = path.name
    for suffix in (".leaf.json", ".leaves.json", ".json", ".toml"):
        if name.lower().endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return path.stem


# -- writing -------------------------------------------------------------------------------------------
def write_fit(fit: ImageFit, out: Path, *, leaf_set: bool,
              back: BackFit | None = None) -> tuple[Path, tuple[LeafParams, ...]]:
    """Write the leaf (``leaf_set``: the parts as a leaf set) to ``out`` and its texture
    ``NAME.front.png`` beside it (with ``back``, or a leaf fitted face down: and ``NAME.back.png``,
    from ``back`` where given, else from the photo itself), all or none; returns the
    front texture's path and the parts as written (their texture resolving against ``out``'s
    folder)."""
    stem = safe_component(leaf_name(out), fallback="leaf")
    texture_name = f"{stem}.front.png"
    back_image = back.texture if back is not None else fit.back_texture
    back_name = f"{stem}.back.png" if back_image is not None else ""
    texture = LeafTexture(texture_name, back_name)
    parts = tuple(p.replace(texture=texture) for p in fit.parts)
    target = out.parent / texture_name
    with outputs():
        write_image(target, texture_uint8(fit.texture),
                    description=f"leafview front texture of {parts[0].name}, fitted to {Path(fit.photo.path).name}")
        if back_image is not None:
            source = back.photo.path if back is not None else fit.photo.path
            write_image(out.parent / back_name, texture_uint8(back_image),
                        description=f"leafview back texture of {parts[0].name}, from {Path(source).name}")
        if leaf_set:
            save_leaves(list(parts), out)
        else:
            save_params(parts[0], out)
    folder = with_folder(texture, out.parent)
    return target, tuple(p.replace(texture=folder) for p in parts)


def _warn(source: str | Path, fit: ImageFit, leaf_set: bool, out: Path) -> None:
    for line in fit.warnings:
        print(f"leafview fit: warning: {source}: {one_line(line)}", file=sys.stderr)
    if fit.report["sides_differ"] and not leaf_set:
        print(f"leafview fit: warning: {source}: wrote the symmetric fit; -o {leaf_name(out)}.leaves.json keeps "
              "both one-sided halves", file=sys.stderr)


def _options(args: argparse.Namespace) -> dict[str, Any]:
    return {"dpi": args.dpi, "texture_size": args.texture_size or 512, "lobed": args.lobed or "auto",
            "face": getattr(args, "face", None) or "auto"}


# -- one photo -------------------------------------------------------------------------------------------
def run(args: argparse.Namespace) -> int:
    """``leafview fit`` for a photo or a folder of photos."""
    _refuse_cloud_options(args)
    src = Path(args.input)
    if src.is_dir():
        return _run_folder(args, src)
    if args.jobs is not None:
        raise UsageError(f"--jobs applies to a folder of photos, not to the one photo {src}")
    out = refuse_directory("-o", args.output)
    name = out.name.lower()
    leaf_set = name.endswith(".leaves.json")
    if out.suffix.lower() not in (".json", ".toml"):
        raise UsageError(f"-o {args.output}: a leaf fitted to a photo is written as NAME.leaf.json (or .json, .toml), "
                         "or NAME.leaves.json for both halves of an asymmetric leaf")
    back_photo = getattr(args, "back", None)
    for attr, flag in (("back_base", "--back-base"), ("back_apex", "--back-apex")):
        if getattr(args, attr, None) is not None and back_photo is None:
            raise UsageError(f"{flag} applies with --back BACK_PHOTO, a photo of the leaf turned over")
    if back_photo is not None and not Path(back_photo).is_file():
        raise UsageError(f"--back {back_photo}: no such photo file")
    options = _options(args)
    if back_photo is not None:
        # with a photo of the leaf turned over, PHOTO shows the upper side: it is fitted face up
        if getattr(args, "face", None) == "down":
            raise UsageError(f"--face down with --back {back_photo}: PHOTO must show the leaf's upper side and --back "
                             "its underside; give the face-up photo as PHOTO, or leave out --back")
        options["face"] = "up"
    fit = fit_image(src, base=args.base, apex=args.apex, name=leaf_name(out), halves=leaf_set, **options)
    back = (back_fit(fit, back_photo, base=args.back_base, apex=args.back_apex) if back_photo is not None
            else None)
    _warn(src, fit, leaf_set, out)
    texture, _ = write_fit(fit, out, leaf_set=leaf_set, back=back)
    r = fit.report
    scale = f"{r['scale']:.4g} m ({r['dpi']:g} dpi)" if r["dpi"] else "1 (no resolution)"
    model = (f"a lobed margin of {r['controls']} control points" if r["lobed"] else
             f"{'/'.join(str(n) for n in r['rows'])} silhouette rows")
    textures = (f"{texture.name} and {texture.name.removesuffix('.front.png')}.back.png"
                if back is not None or fit.back_texture is not None else texture.name)
    back_note = f"back photo IoU {back.iou:.3f} with the turned-over fit, " if back is not None else ""
    report(args, f"wrote {out} and {textures}: IoU {r['iou']:.3f} with the traced leaf, Hausdorff "
                 f"{r['hausdorff_pct']:.2f} % of the length, {model}"
                 f"{', two halves' if fit.asymmetric else ''}, petiole {r['petiole_length']:.3f}, scale {scale}, "
                 f"face {r['face']} (found {r['face_detected']}), {back_note}in {r['seconds']:.2f} s")
    return EXIT_OK


# -- a folder of photos --------------------------------------------------------------------------------------
def _cell(count: int) -> int:
    return _CELL if count <= _FULL_CELLS else max(64, int(_CELL * math.sqrt(_FULL_CELLS / count)))


def _entry(photo: Path, leaf: Path, texture: Path, fit: ImageFit) -> dict[str, Any]:
    r = fit.report
    keys = ("iou", "hausdorff_pct", "rows", "row_residuals", "asymmetric", "sides_differ", "petiole_length", "scale",
            "dpi", "base_px", "apex_px", "length_px", "cut_sides", "warnings", "seconds", "lobed")
    return {"photo": photo.name, "leaf": leaf.name, "texture": texture.name, **{k: r[k] for k in keys}}


def _renderer(quiet: bool) -> LeafRenderer | None:
    try:
        return default_renderer()
    except GLUnavailable as exc:
        if not quiet:
            print(f"leafview fit: note: no OpenGL, the contact sheet's render column stays empty: {one_line(str(exc))}",
                  file=sys.stderr)
        return None


def _run_folder(args: argparse.Namespace, src: Path) -> int:
    for attr, flag in (("base", "--base"), ("apex", "--apex"), ("back", "--back"), ("back_base", "--back-base"),
                       ("back_apex", "--back-apex")):
        if getattr(args, attr, None) is not None:
            raise UsageError(f"{flag} applies to one photo, not to the folder {src}")
    out = output_directory(Path(args.output))
    photos = sorted(p for p in src.iterdir() if p.suffix.lower() in PHOTO_SUFFIXES and p.is_file())
    if not photos:
        raise UsageError(f"{src}: no photos in this folder (.png, .jpg, .jpeg, .tif, .tiff)")
    names = output_names([p.stem for p in photos], quiet=args.quiet)
    cell = _cell(len(photos))
    renderer = _renderer(args.quiet)
    entries: list[dict[str, Any]] = []
    tiles: list[np.ndarray] = []
    labels: list[str] = []
    started = time.perf_counter()
    bar = progress_bar(total=len(photos), unit="photo", desc="fitting", quiet=args.quiet)
    jobs = args.jobs or default_jobs()
    try:
        for photo, name, fit in zip(photos, names, fit_photos(photos, names, jobs=jobs, **_options(args))):
            if isinstance(fit, str):     # one photo's failure is reported, and the batch goes on
                entries.append({"photo": photo.name, "error": fit})
                bar.update(1)
                continue
            leaf = out / f"{name}.leaves.json" if fit.asymmetric else out / f"{name}.leaf.json"
            _warn(photo, fit, True, leaf)
            texture, parts = write_fit(fit, leaf, leaf_set=fit.asymmetric)
            entries.append(_entry(photo, leaf, texture, fit))
            tiles += fit_cells(fit, cell, renderer, parts)
            labels += [photo.name, fit_label(fit), leaf.name]
            bar.update(1)
    finally:
        bar.close()
    failed = sum(1 for e in entries if "error" in e)
    summary = {"input": str(src), "photos": len(photos), "fitted": len(photos) - failed, "failed": failed,
               "leaves": entries}
    with outputs():
        write_text(out / "report.json", json.dumps(summary, indent=2, allow_nan=False) + "\n")
        if tiles:
            per_row = max(1, min(len(tiles) // 3, SHEET_WIDTH // (3 * cell)))
            write_image(out / "contact.png", contact_sheet(tiles, labels, columns=3 * per_row),
                        description=f"leafview fit: {len(tiles) // 3} photos and their fits")
    for e in entries:
        if "error" in e:
            print(f"leafview fit: failed: {e['error']}", file=sys.stderr)
    report(args, f"fitted {len(photos) - failed} of {len(photos)} photos into {out}/ in "
                 f"{time.perf_counter() - started:.1f} s" + (f"; {failed} failed (see report.json)" if failed else ""))
    return EXIT_FAILURE if failed else EXIT_OK
