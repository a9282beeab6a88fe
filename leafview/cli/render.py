"""``leafview render``: thumbnails of presets, offscreen.

One preset and ``-o FILE`` writes that file; several presets write one image each into
``-o DIR``; ``--sheet`` writes one labelled contact sheet to ``-o FILE``. Every preset is loaded
and checked before anything is drawn; a failed batch leaves no half-finished directory behind.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from leafview._version import __version__
from leafview.atomic import outputs
from leafview.cli.args import (
    EXIT_OK,
    VIEWS,
    expand_presets,
    grid,
    load_leaf_files,
    output_directory,
    output_names,
    output_path,
    pixels,
    progress_bar,
    refuse_directory,
    report,
)
from leafview.core.params import LeafParams
from leafview.errors import UsageError
from leafview.export.images import FORMATS, contact_sheet, format_of, write_image
from leafview.gpu import default_renderer
from leafview.gpu.renderer import BATCH
from leafview.scene.camera import check_leaf_framable

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``leafview render``."""
    parser.description = ("Render presets (files, directories of presets, or built-in names such as 'ovate') "
                          "to images. One preset and -o FILE writes that file; several presets write one "
                          "image each into -o DIR; --sheet writes one labelled contact sheet to -o FILE.")
    parser.add_argument("presets", nargs="+", metavar="PRESET")
    parser.add_argument("-o", "--output", required=True, type=output_path, metavar="FILE|DIR")
    parser.add_argument("--size", type=pixels, default=256, help="image width and height in pixels (default 256)")
    parser.add_argument("--view", choices=VIEWS, default="top", help="camera (default top)")
    parser.add_argument("--format", choices=("png", "exr", "tif"), default=None,
                        help="image type (default: from the -o suffix, else png)")
    parser.add_argument("--sheet", action="store_true", help="one labelled contact sheet instead of one image each")
    parser.add_argument("--grid", type=grid, default=None, metavar="NUxNV", help="(u, v) samples (default 33x65)")
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")


def _plan(args: argparse.Namespace, count: int) -> tuple[str, Path, str]:
    """(mode, output path, format) with mode 'file', 'dir' or 'sheet'; raises UsageError."""
    out = Path(args.output)
    suffix_fmt = format_of(out)
    if args.sheet or count == 1 and out.suffix:
        if out.suffix and suffix_fmt is None:
            raise UsageError(f"-o {out}: unknown image type {out.suffix!r} (use .png, .exr or .tif)")
        if args.format and suffix_fmt and args.format != suffix_fmt:
            raise UsageError(f"-o {out} is a .{suffix_fmt} file but --format {args.format} was given")
        fmt = args.format or suffix_fmt or "png"
        if not out.suffix:
            out = out.with_suffix("." + fmt)
        refuse_directory("-o", out)
        if args.sheet and fmt == "exr":
            raise UsageError("--sheet writes an 8-bit labelled image: use .png or .tif")
        return ("sheet" if args.sheet else "file"), out, fmt
    if suffix_fmt is not None:
        raise UsageError(f"{count} presets need -o DIR (one image each) or --sheet, not the file {out}")
    return "dir", output_directory(out), args.format or "png"


def _describe(leaf: LeafParams, args: argparse.Namespace) -> str:
    return f"leafview {__version__}: {leaf.name or 'leaf'}, {args.view} view"


def run(args: argparse.Namespace) -> int:
    """Render the presets of ``args``; returns the exit code."""
    leaves = load_leaf_files(expand_presets(args.presets))  # validate everything before writing anything
    for leaf in leaves:
        check_leaf_framable(leaf)   # finite and within what float32 can frame, or exit 2 naming the leaf
    mode, out, fmt = _plan(args, len(leaves))
    names = [leaf.name for leaf in leaves]
    # one safe, unique file name per leaf: never outside -o DIR, never one over another
    files = output_names(names, quiet=args.quiet) if mode == "dir" else names

    renderer = default_renderer()
    kwargs = {"grid": args.grid} if args.grid else {}
    linear = fmt == "exr"
    started = time.perf_counter()

    def draw_all(batch: list[LeafParams]) -> list[Any]:
        images: list[Any] = renderer.render_many(batch, (args.size, args.size), args.view, linear=linear, **kwargs)
        return images

    if mode == "file":
        image = draw_all(leaves[:1])[0]
        write_image(out, image, params=leaves[0], description=_describe(leaves[0], args))
        report(args, f"wrote {out} ({args.size}×{args.size}, {args.view} view, {names[0]})")
        return EXIT_OK

    bar = progress_bar(total=len(leaves), unit="leaf", desc="rendering", quiet=args.quiet)
    written: list[Path] = []
    images: list[Any] = []
    try:
        with outputs():   # every image of the batch, or none: a failure leaves no half-finished directory
            for start in range(0, len(leaves), BATCH):
                chunk = leaves[start:start + BATCH]
                rendered = draw_all(chunk)
                if mode == "sheet":
                    images += rendered
                else:
                    for leaf, name, image in zip(chunk, files[start:start + BATCH], rendered):
                        written.append(write_image(out / f"{name}{FORMATS[fmt]}", image, params=leaf,
                                                   description=_describe(leaf, args)))
                bar.update(len(chunk))
            if mode == "sheet":
                write_image(out, contact_sheet(images, names),
                            description=f"leafview contact sheet: {', '.join(names)}")
    finally:
        bar.close()
    seconds = time.perf_counter() - started
    if mode == "sheet":
        report(args, f"wrote {out}: contact sheet of {len(leaves)} leaves ({args.view} view) in {seconds:.1f} s")
    else:
        report(args, f"wrote {len(written)} {fmt} thumbnails ({args.size}×{args.size}, {args.view} view) "
                     f"to {out}/ in {seconds:.1f} s")
    return EXIT_OK
