"""``leafview render``: thumbnails of presets, offscreen, or synthetic RGB-D views of one leaf.

One preset and ``-o FILE`` writes that file; several presets write one image each into
``-o DIR``; ``--sheet`` writes one labelled contact sheet to ``-o FILE``. Every preset is loaded
and checked before anything is drawn; a failed batch leaves no half-finished directory behind.

``--views N -o DIR`` draws one leaf (or one leaf set, every leaf at its transform) from ``N``
cameras on a ring and writes colour, depth, instance ids, normals, cameras and the truth leaf set
into ``DIR`` (:mod:`leafview.export.views`). The options of the views (``--views``, ``--aov``,
``--elevation``, ``--depth-noise``, ``--holes``) and the run that writes them are shared with
``leafview scene`` (:mod:`leafview.cli.views`).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from leafview._version import __version__
from leafview.atomic import outputs
from leafview.botany.vein_shading import without_veins
from leafview.cli.args import (
    EXIT_OK,
    VIEWS,
    add_veins_argument,
    count,
    expand_presets,
    grid,
    load_framable_leaves,
    output_directory,
    output_names,
    output_path,
    pixels,
    preset_file,
    progress_bar,
    refuse_directory,
    report,
    veins_off,
)
from leafview.cli.views import add_views_arguments, check_views_arguments, write_views
from leafview.core.params import LeafParams
from leafview.errors import UsageError
from leafview.export.images import FORMATS, contact_sheet, format_of, write_image
from leafview.export.views import VIEW_GRID
from leafview.gpu import default_renderer
from leafview.gpu.renderer import BATCH
from leafview.gpu.sheets import render_leaves
from leafview.scene.spec import scene_from_leaves

__all__ = ["add_arguments", "run"]

DEFAULT_VIEW = "top"


def _seed(text: str) -> int:
    return count(text, lo=0, hi=2**63 - 1, what="seed", name="--seed")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``leafview render``."""
    parser.description = ("Render presets (files, directories of presets, or built-in names such as 'ovate') "
                          "to images. One preset and -o FILE writes that file; several presets write one "
                          "image each into -o DIR; --sheet writes one labelled contact sheet to -o FILE; "
                          "--views N -o DIR writes N synthetic RGB-D views of one leaf or leaf set with "
                          "exact ground truth.")
    parser.add_argument("presets", nargs="+", metavar="PRESET")
    parser.add_argument("-o", "--output", required=True, type=output_path, metavar="FILE|DIR")
    parser.add_argument("--size", type=pixels, default=256, help="image width and height in pixels (default 256)")
    parser.add_argument("--view", choices=VIEWS, default=None, help=f"camera (default {DEFAULT_VIEW})")
    parser.add_argument("--format", choices=("png", "exr", "tif"), default=None,
                        help="image type (default: from the -o suffix, else png)")
    parser.add_argument("--sheet", action="store_true", help="one labelled contact sheet instead of one image each")
    parser.add_argument("--together", action="store_true",
                        help="one image of all the leaves as placed (e.g. the two halves of an asymmetric leaf "
                             "in a .leaves.json; such a pair alone is drawn together without it)")
    parser.add_argument("--grid", type=grid, default=None, metavar="NUxNV",
                        help=f"(u, v) samples (default 33x65; with --views {VIEW_GRID[0]}x{VIEW_GRID[1]})")
    add_veins_argument(parser)
    add_views_arguments(parser)
    parser.add_argument("--seed", dest="views_seed", type=_seed, default=None, metavar="N",
                        help="with --views: seed of the depth noise and holes (default 0)")
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")


def _plan(args: argparse.Namespace, count: int) -> tuple[str, Path, str]:
    """(mode, output path, format) with mode 'file', 'dir', 'sheet' or 'together'; raises UsageError."""
    out = Path(args.output)
    suffix_fmt = format_of(out)
    if args.together and args.sheet:
        raise UsageError("--together and --sheet: choose one image of all the leaves or a sheet of each")
    if args.together or args.sheet or count == 1 and out.suffix:
        mode = "together" if args.together else "sheet" if args.sheet else "file"
        if out.suffix and suffix_fmt is None:
            raise UsageError(f"-o {out}: unknown image type {out.suffix!r} (use .png, .exr or .tif)")
        if args.format and suffix_fmt and args.format != suffix_fmt:
            raise UsageError(f"-o {out} is a .{suffix_fmt} file but --format {args.format} was given")
        fmt = args.format or suffix_fmt or "png"
        if not out.suffix:
            out = out.with_suffix("." + fmt)
        refuse_directory("-o", out)
        if mode != "file" and fmt == "exr":
            raise UsageError(f"--{mode} writes an 8-bit image: use .png or .tif")
        return mode, out, fmt
    if suffix_fmt is not None:
        raise UsageError(f"{count} presets need -o DIR (one image each), --sheet or --together, not the file {out}")
    return "dir", output_directory(out), args.format or "png"


def is_half_pair(leaves: Sequence[LeafParams]) -> bool:
    """Whether ``leaves`` are the two one-sided halves of one leaf (``shape.half`` -1 and +1, one
    placement), as ``leafview fit PHOTO -o NAME.leaves.json`` writes an asymmetric leaf."""
    return (len(leaves) == 2 and sorted(leaf.shape.half for leaf in leaves) == [-1, 1]
            and leaves[0].transform == leaves[1].transform)


def _describe(leaf: LeafParams, args: argparse.Namespace) -> str:
    return f"leafview {__version__}: {leaf.name or 'leaf'}, {args.view} view"


def _run_views(args: argparse.Namespace) -> int:
    """``--views``: one preset (a leaf, or a leaf set drawn as its placed leaves) into -o DIR."""
    check_views_arguments(args, {"--view": args.view is not None, "--sheet": args.sheet,
                                 "--format": args.format is not None})
    if len(args.presets) != 1:
        raise UsageError(f"--views draws one leaf or one leaf set: give one PRESET, not {len(args.presets)}")
    path = preset_file(args.presets[0])
    leaves = load_framable_leaves([path])
    if veins_off(args):
        leaves = without_veins(leaves)
    scene = scene_from_leaves(leaves, name=path.name)
    write_views(args, scene, size=(args.size, args.size), seed=args.views_seed or 0, grid=args.grid or VIEW_GRID)
    return EXIT_OK


def run(args: argparse.Namespace) -> int:
    """Render the presets of ``args``; returns the exit code."""
    if args.views is not None:
        return _run_views(args)
    check_views_arguments(args, {})
    args.view = args.view or DEFAULT_VIEW
    # validate everything before writing anything: finite and within what float32 can frame, or exit 2
    # naming the file, the leaf and the field
    leaves = load_framable_leaves(expand_presets(args.presets))
    if veins_off(args):
        leaves = without_veins(leaves)
    args.together = args.together or (len(args.presets) == 1 and not args.sheet and is_half_pair(leaves))
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

    if mode == "together":
        image = render_leaves(leaves, (args.size, args.size), args.view, samples=None, **kwargs)
        write_image(out, image, description=f"leafview {__version__}: {len(leaves)} leaves together, {args.view} view")
        report(args, f"wrote {out} ({args.size}×{args.size}, {args.view} view, {len(leaves)} leaves together)")
        return EXIT_OK
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
