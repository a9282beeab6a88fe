"""``leafview shapes``: list the botanical catalogue, render it through the shader path, or
render a multilobed leaf.

Examples::

    leafview shapes                                   # table: name, waist, base, apex, rows, fit error
    leafview shapes --sheet -o catalogue.png          # every shape, labelled
    leafview shapes --names cordate reniform -o dir/  # one image each
    leafview shapes --names cordate --seed 3 -o c.png # a random instance (Fig. 8), fitted now
    leafview shapes --sheet --margin -o margins.png   # the landmark margins themselves, nothing fitted
    leafview shapes --lobed maple -o maple.png        # a multilobed leaf (assets/compound/maple.toml)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from leafview.atomic import outputs
from leafview.botany.catalogue import landmark_leaf, random_instance
from leafview.botany.landmarks import margin_params
from leafview.botany.lobes import load_lobed_leaf
from leafview.botany.shapes import fit_info, shape_names, shapes_params
from leafview.cli.args import (
    EXIT_OK,
    VIEWS,
    output_directory,
    output_names,
    output_path,
    pixels,
    progress_bar,
    refuse_directory,
)
from leafview.core.defaults import DETAIL_GRID
from leafview.core.params import LeafParams
from leafview.errors import UsageError
from leafview.export.images import contact_sheet, format_of, write_image
from leafview.gpu import default_renderer
from leafview.gpu.sheets import render_lobed

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``leafview shapes``."""
    p.description = ("The unilobed leaf shapes (Garg & Leow 2011, Table 1, Fig. 5) fitted to the shader "
                     "model, and multilobed leaves (sec. 5). Without -o: list the shapes and their fit "
                     "errors. With -o: render them (all, or --names) through the shader path.")
    p.add_argument("-o", "--output", type=output_path, metavar="FILE|DIR",
                   help="image file (one shape, or --sheet) or directory")
    p.add_argument("--names", nargs="+", metavar="NAME", help="catalogue names (default: all); commas work too")
    p.add_argument("--sheet", action="store_true", help="one labelled contact sheet")
    p.add_argument("--size", type=pixels, default=128, help="pixels per image (default 128)")
    p.add_argument("--view", choices=VIEWS, default="top", help="camera (default top)")
    p.add_argument("--seed", type=int, help="render a random instance of each shape (±20 %%, Fig. 8), fitted now")
    p.add_argument("--margin", action="store_true",
                   help="draw each shape's landmark margin itself (exact, nothing fitted) instead of its Ω fit")
    p.add_argument("--lobed", metavar="NAME|FILE", help="render a multilobed leaf: a file or a built-in "
                   "(maple, oak, ...) from assets/compound")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")


def _names(args: argparse.Namespace) -> list[str]:
    if not args.names:
        return shape_names()
    names = [n for item in args.names for n in item.split(",") if n]
    for n in names:
        fit_info(n)  # ParamError naming the shape, with close matches
    return names


def _list(names: list[str]) -> int:
    print(f"{'name':28s} {'waist':9s} {'base':9s} {'apex':9s} {'rows':>4s} {'model':9s} {'fit error':>9s}")
    for name in names:
        f = fit_info(name)
        model = "quartic" if f.quartic else "tilted 4" if f.rows == 3 else f"degree {f.rows + 1}"
        print(f"{name:28s} {f.waist:9s} {f.base:9s} {f.apex:9s} {f.rows:4d} {model:9s} {100 * f.error:8.2f}%")
    worst = max(fit_info(n).error for n in names)
    print(f"{len(names)} shapes; fit error = Hausdorff(margin, outline) / leaf length; largest {100 * worst:.2f} %")
    return EXIT_OK


def _output(args: argparse.Namespace, count: int) -> tuple[str, Path]:
    out = Path(args.output)
    fmt = format_of(out)
    if args.sheet or (count == 1 and out.suffix):
        if fmt is None:
            raise UsageError(f"-o {out}: give an image file name (.png, .tif{'' if args.sheet else ', .exr'})")
        if args.sheet and fmt == "exr":
            raise UsageError("--sheet writes an 8-bit labelled image: use .png or .tif")
        refuse_directory("-o", out)
        return ("sheet" if args.sheet else "file"), out
    if fmt is not None:
        raise UsageError(f"{count} shapes need -o DIR (one image each) or --sheet, not the file {out}")
    return "dir", output_directory(out)


def _leaves(names: list[str], seed: int | None, quiet: bool, margin: bool = False) -> list[LeafParams]:
    if margin:   # the landmark margins drawn as they are: no fit, no progress to show
        leaves = [landmark_leaf(n) if seed is None else random_instance(landmark_leaf(n), seed) for n in names]
        params = margin_params(leaves)
        return params if seed is None else [p.replace(name=f"{n}#{seed}") for p, n in zip(params, names)]
    if seed is None:
        return [shapes_params(n) for n in names]
    bar = progress_bar(names, unit="fit", desc="fitting instances", quiet=quiet)
    return [shapes_params(n, seed) for n in bar]


def _render_shapes(args: argparse.Namespace, names: list[str]) -> int:
    t0 = time.perf_counter()
    mode, out = _output(args, len(names))
    leaves = _leaves(names, args.seed, args.quiet, args.margin)
    renderer = default_renderer()
    images: list[Any] = []
    with progress_bar(total=len(leaves), unit="leaf", desc="rendering", quiet=args.quiet) as bar:
        for start in range(0, len(leaves), 16):
            batch = leaves[start:start + 16]
            images += renderer.render_many(batch, (args.size, args.size), args.view, grid=DETAIL_GRID)
            bar.update(len(batch))
    labels = [leaf.name or n for leaf, n in zip(leaves, names)]
    if mode == "sheet":
        write_image(out, contact_sheet(images, labels), description=f"leafview shapes: {', '.join(labels)}")
        print(f"wrote {out}: contact sheet of {len(images)} shapes ({args.view} view) in "
              f"{time.perf_counter() - t0:.1f} s")
    elif mode == "file":
        write_image(out, images[0], params=leaves[0])
        print(f"wrote {out} ({args.size}×{args.size}, {args.view} view, {labels[0]})")
    else:
        files = output_names([label.replace("#", "-") for label in labels], fallback="shape", quiet=args.quiet)
        with outputs():   # every image or none
            for img, leaf, name in zip(images, leaves, files):
                write_image(out / f"{name}.png", img, params=leaf)
        print(f"wrote {len(images)} png images ({args.size}×{args.size}, {args.view} view) to {out}/ "
              f"in {time.perf_counter() - t0:.1f} s")
    return EXIT_OK


def _render_lobed(args: argparse.Namespace) -> int:
    if args.names or args.sheet or args.seed is not None or args.margin:
        raise UsageError("--lobed renders one multilobed leaf: drop --names, --sheet, --seed and --margin")
    lobed = load_lobed_leaf(args.lobed)
    if args.output is None:
        print(lobed.describe())
        return EXIT_OK
    out = Path(args.output)
    if format_of(out) is None:
        raise UsageError(f"-o {out}: give an image file name (.png, .exr or .tif)")
    refuse_directory("-o", out)
    t0 = time.perf_counter()
    img = render_lobed(lobed, (args.size, args.size), args.view)
    write_image(out, img, description=f"leafview multilobed leaf: {lobed.name}")
    lateral = sum(p.role == "lateral" for p in lobed.lobes())
    print(f"wrote {out} ({args.size}×{args.size}, {args.view} view, {lobed.name}: {lateral} lateral lobes, one margin) "
          f"in {time.perf_counter() - t0:.1f} s")
    return EXIT_OK


def run(args: argparse.Namespace) -> int:
    """List or render the catalogue shapes, or render a multilobed leaf; returns the exit code."""
    if args.lobed:
        return _render_lobed(args)
    names = _names(args)
    if args.output is None:
        if args.sheet or args.seed is not None or args.margin:
            raise UsageError("--sheet, --seed and --margin render images: give -o FILE or -o DIR")
        return _list(names)
    return _render_shapes(args, names)
