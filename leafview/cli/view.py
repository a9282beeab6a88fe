"""``leafview view [PRESET] [--photo IMAGE]``: the interactive viewer window.

Bad input (an unknown preset, a malformed file, a bad ``--size`` or ``--screenshot`` name) is
reported before any window opens, with exit code 2; no display or no OpenGL 4.5 exits 1 with
what to install.
"""

from __future__ import annotations

import argparse

from leafview.app.photo_reference import is_photo_path, open_photo
from leafview.app.viewer import open_state
from leafview.app.window import ViewerWindow
from leafview.cli.args import (
    add_veins_argument,
    int_in_range,
    output_path,
    preset_file,
    refuse_directory,
    veins_off,
    window_size,
)
from leafview.core.params import LeafParams
from leafview.errors import UsageError
from leafview.export.images import format_of

__all__ = ["add_arguments", "run"]


def _frames(text: str) -> int:
    return int_in_range(text, lo=1, hi=None, what="frames", name="--frames")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``leafview view``."""
    parser.description = ("Edit a leaf live: every parameter on a slider, control points dragged in the "
                          "viewport, undo/redo, presets. H in the window shows the keys.")
    parser.add_argument("preset", nargs="?", default="ovate", metavar="PRESET",
                        help="a .toml/.json preset or a built-in name (default: ovate); a photo "
                             "(.png/.jpg/.tif) opens as --photo with the default leaf")
    parser.add_argument("--photo", default=None, metavar="IMAGE",
                        help="a leaf photo shown behind the leaf as a reference, placed by its detected base "
                             "and apex (opacity, markers and Fit on the panel's Reference photo section)")
    parser.add_argument("--size", type=window_size, default=(1280, 800), metavar="WxH",
                        help="window size (default 1280x800)")
    parser.add_argument("--frames", type=_frames, default=None, metavar="N",
                        help="run N frames and exit (scripted runs, CI); no unsaved-edit question")
    parser.add_argument("--screenshot", type=output_path, default=None, metavar="FILE",
                        help="after the last frame, write the whole window (scene and panel) as PNG/TIFF")
    parser.add_argument("--dev", action="store_true",
                        help="hot-reload shaders/ when the files change (errors shown, old shaders kept)")
    add_veins_argument(parser)
    parser.add_argument("--samples", type=int, choices=(0, 2, 4, 8), default=None,
                        help="multisampling of the scene (default 4; 0 on software renderers such as llvmpipe)")


def run(args: argparse.Namespace) -> int:
    """Open the viewer for parsed ``args``; returns the exit code."""
    photo = args.photo
    if photo is None and is_photo_path(args.preset):
        photo, args.preset = args.preset, "ovate"
    path = preset_file(args.preset)
    if args.screenshot is not None:
        if format_of(args.screenshot) not in ("png", "tif"):
            raise UsageError(f"--screenshot {args.screenshot}: use a .png or .tif file name")
        refuse_directory("--screenshot", args.screenshot)
    params = LeafParams.load(path)  # ParamError → exit 2, naming the file and field
    state = open_state(params, path)
    state.view.show_veins = not veins_off(args)   # the panel's veins checkbox
    if photo is not None and not open_photo(state, photo):
        raise UsageError(f"--photo: {state.error}")     # before any window opens: exit 2
    with ViewerWindow(state, args.size, dev=args.dev, samples=args.samples) as window:
        return window.run(frames=args.frames, screenshot=args.screenshot)
