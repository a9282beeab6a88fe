"""The ``leafview`` command.

Exit codes: 0 success, 2 bad input (arguments, presets, paths), 1 a runtime failure (no OpenGL,
an image that could not be written). A failing run writes no file.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from leafview._version import __version__
from leafview.core.params import LeafParams, ParamError
from leafview.errors import UsageError

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2
_VIEWS = ("top", "front", "three-quarter", "side")

# Subcommands that live in their own modules: name -> (module, one-line help). Each module has
# ``add_arguments(parser)`` and ``run(args) -> int``; it raises UsageError / ParamError for bad
# input (exit 2) and writes no partial file.
COMMANDS: dict[str, tuple[str, str]] = {
    "export": ("leafview.cli.export", "bake leaves or a scene into .glb/.gltf/.obj/.ply/.usda/.usdc"),
    "morph": ("leafview.cli.morph", "morph one leaf shape into another: frames, contact sheet, smoothness"),
    "scene": ("leafview.cli.scene", "render, save, export or view a scene of many leaves"),
    "shapes": ("leafview.cli.shapes", "list or render the botanical shape catalogue, or a multilobed leaf"),
}


def int_in_range(text: str, *, lo: int, hi: int | None, what: str, name: str) -> int:
    """Parse a whole number in lo..hi (no upper bound when ``hi`` is None) for argparse:
    ``what`` names the unit in the type error, ``name`` the option in the range error."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of {what}, got {text!r}") from None
    if n < lo or (hi is not None and n > hi):
        bound = f"between {lo} and {hi}" if hi is not None else f"at least {lo}"
        raise argparse.ArgumentTypeError(f"{name} must be {bound} {what}, got {n}")
    return n


def _size(text: str) -> int:
    return int_in_range(text, lo=8, hi=8192, what="pixels", name="size")


def int_pair(text: str, *, lo: int, hi: int, what: str, example: str) -> tuple[int, int]:
    """Parse ``AxB`` (two whole numbers, each in lo..hi) for argparse, with a clear message."""
    try:
        a, b = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what} such as {example}, got {text!r}") from None
    if not (lo <= a <= hi and lo <= b <= hi):
        raise argparse.ArgumentTypeError(f"{a}x{b} outside {lo}..{hi} per side")
    return a, b


def _grid(text: str) -> tuple[int, int]:
    return int_pair(text, lo=2, hi=1025, what="NUxNV", example="33x65")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="leafview", description="Parametric plant leaves evaluated on the GPU.")
    parser.add_argument("--version", action="version", version=f"leafview {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    r = sub.add_parser("render", help="render thumbnails of presets offscreen",
                       description="Render presets (files, directories of presets, or built-in names such "
                                   "as 'ovate') to images. One preset and -o FILE writes that file; several "
                                   "presets write one image each into -o DIR; --sheet writes one labelled "
                                   "contact sheet to -o FILE.")
    r.add_argument("presets", nargs="+", metavar="PRESET")
    r.add_argument("-o", "--output", required=True, metavar="FILE|DIR")
    r.add_argument("--size", type=_size, default=256, help="image width and height in pixels (default 256)")
    r.add_argument("--view", choices=_VIEWS, default="top", help="camera (default top)")
    r.add_argument("--format", choices=("png", "exr", "tif"), default=None,
                   help="image type (default: from the -o suffix, else png)")
    r.add_argument("--sheet", action="store_true", help="one labelled contact sheet instead of one image each")
    r.add_argument("--grid", type=_grid, default=None, metavar="NUxNV", help="(u, v) samples (default 33x65)")
    r.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")

    sub.add_parser("presets", help="list the built-in presets")

    from leafview.cli.view import add_arguments as add_view_arguments

    v = sub.add_parser("view", help="open the interactive viewer window",
                       description="Edit a leaf live: every parameter on a slider, control points "
                                   "dragged in the viewport, undo/redo, presets. H in the window "
                                   "shows the keys.")
    add_view_arguments(v)

    from leafview.bench.core import add_arguments as add_bench_arguments

    b = sub.add_parser("bench", help="measure rendering speed (prints GL_RENDERER and ratios)")
    add_bench_arguments(b)

    for name, (module, text) in COMMANDS.items():
        p = sub.add_parser(name, help=text, description=text)
        importlib.import_module(module).add_arguments(p)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == "render":
            return _render(args)
        if args.command == "presets":
            return _presets()
        if args.command == "view":
            from leafview.cli.view import view_main

            return view_main(args)
        if args.command == "bench":
            from leafview.bench.core import run_args

            return run_args(args)
        if args.command in COMMANDS:
            return importlib.import_module(COMMANDS[args.command][0]).run(args)
    except (UsageError, ParamError) as exc:
        print(f"leafview {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("leafview: interrupted; no partial files were left", file=sys.stderr)
        return 130
    except Exception as exc:  # GL unavailable, OIIO failures: a message, not a traceback
        from leafview.export.images import ImageWriteError
        from leafview.gpu.context import GLUnavailable

        if isinstance(exc, (GLUnavailable, ImageWriteError)):
            print(f"leafview {args.command}: {exc}", file=sys.stderr)
            return EXIT_FAILURE
        raise
    return EXIT_FAILURE


# -- render ------------------------------------------------------------------------------------
def _expand(specs: Sequence[str]) -> list[Path]:
    from leafview.resources import builtin_presets, resolve_preset

    paths: list[Path] = []
    for spec in specs:
        path = resolve_preset(spec)
        if not path.exists() and not path.suffix:
            raise UsageError(f"{spec}: no such file, directory or built-in preset "
                             f"(built-in: {', '.join(builtin_presets())})")
        if path.is_dir():
            found = sorted([*path.glob("*.toml"), *path.glob("*.json")])
            if not found:
                raise UsageError(f"{path}: directory holds no .toml or .json presets")
            paths.extend(found)
        else:
            paths.append(path)
    return paths


def load_leaf_files(paths: Sequence[Path]) -> list[LeafParams]:
    """Every leaf of the given files, in order: a leaf set (``*.leaves.json``) gives all of its
    leaves, any other preset file one. Each leaf is named (its file's stem when unnamed)."""
    from leafview.core.io import load_leaves

    return [leaf for path in paths for leaf in load_leaves(path)]


def _plan(args: argparse.Namespace, count: int) -> tuple[str, Path, str]:
    """(mode, output path, format) with mode 'file', 'dir' or 'sheet'; raises UsageError."""
    from leafview.export.images import format_of

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
        if out.is_dir():
            raise UsageError(f"-o {out} is a directory; give a file name")
        if args.sheet and fmt == "exr":
            raise UsageError("--sheet writes an 8-bit labelled image: use .png or .tif")
        return ("sheet" if args.sheet else "file"), out, fmt
    if suffix_fmt is not None:
        raise UsageError(f"{count} presets need -o DIR (one image each) or --sheet, not the file {out}")
    if out.exists() and not out.is_dir():
        raise UsageError(f"-o {out} exists and is not a directory")
    return "dir", out, args.format or "png"


def _render(args: argparse.Namespace) -> int:
    from leafview.export.images import FORMATS, contact_sheet, write_image

    leaves = load_leaf_files(_expand(args.presets))  # validate everything before writing anything
    mode, out, fmt = _plan(args, len(leaves))
    names = [leaf.name for leaf in leaves]
    if mode == "dir" and len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise UsageError(f"several presets are named {', '.join(dup)}: their images would overwrite each other")

    from leafview.gpu import default_renderer

    renderer = default_renderer()
    kwargs = {"grid": args.grid} if args.grid else {}
    linear = fmt == "exr"
    started = time.perf_counter()

    def draw_all(batch: list[LeafParams]) -> list:
        return renderer.render_many(batch, (args.size, args.size), args.view, linear=linear, **kwargs)

    if mode == "file":
        image = draw_all(leaves[:1])[0]
        write_image(out, image, params=leaves[0], description=_describe(leaves[0], args))
        _report(args, f"wrote {out} ({args.size}×{args.size}, {args.view} view, {names[0]})")
        return EXIT_OK

    from tqdm import tqdm

    from leafview.gpu.renderer import BATCH

    bar = tqdm(total=len(leaves), unit="leaf", disable=None if not args.quiet else True, file=sys.stderr,
               desc="rendering")
    written: list[Path] = []
    images = []
    try:
        for start in range(0, len(leaves), BATCH):
            chunk = leaves[start:start + BATCH]
            rendered = draw_all(chunk)
            if mode == "sheet":
                images += rendered
            else:
                for leaf, name, image in zip(chunk, names[start:start + BATCH], rendered):
                    written.append(write_image(out / f"{name}{FORMATS[fmt]}", image, params=leaf,
                                               description=_describe(leaf, args)))
            bar.update(len(chunk))
    except BaseException:
        for path in written:  # a failed batch leaves no half-finished directory behind
            path.unlink(missing_ok=True)
        raise
    finally:
        bar.close()
    seconds = time.perf_counter() - started
    if mode == "sheet":
        write_image(out, contact_sheet(images, names), description=f"leafview contact sheet: {', '.join(names)}")
        _report(args, f"wrote {out}: contact sheet of {len(leaves)} leaves ({args.view} view) in {seconds:.1f} s")
    else:
        _report(args, f"wrote {len(written)} {fmt} thumbnails ({args.size}×{args.size}, {args.view} view) "
                      f"to {out}/ in {seconds:.1f} s")
    return EXIT_OK


def _describe(leaf: LeafParams, args: argparse.Namespace) -> str:
    return f"leafview {__version__}: {leaf.name or 'leaf'}, {args.view} view"


def _report(args: argparse.Namespace, text: str) -> None:
    if not args.quiet:
        print(text)


def _presets() -> int:
    from leafview.resources import builtin_presets

    for name, path in builtin_presets().items():
        print(f"{name:14s} {path}")
    return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
