"""The ``leafview`` command.

One module per sub-command (listed in :data:`COMMANDS`), each with ``add_arguments(parser)`` and
``run(args) -> int``; what they share is in :mod:`leafview.cli.args`. Only the chosen command's
module is imported, so ``leafview --help`` loads no OpenGL, window or UI library.

Exit codes: 0 success, 2 bad input (arguments, presets, paths), 1 a runtime failure (no OpenGL,
an image that could not be written, a full disk, no permission), 128 + N after signal N (SIGINT
130, SIGTERM 143) while writing. A failing run writes no file.
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
from collections.abc import Sequence

from leafview._version import __version__
from leafview.atomic import Terminated
from leafview.cli.args import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_USAGE
from leafview.errors import (
    GLContextLost,
    GLUnavailable,
    ImageWriteError,
    OutputError,
    ParamError,
    SceneLimitError,
    UsageError,
    one_line,
)

__all__ = ["COMMANDS", "build_parser", "main"]

# name -> (module, one-line help), in the order ``leafview --help`` lists them. A command raises
# UsageError / ParamError for bad input (exit 2) and writes no partial file.
COMMANDS: dict[str, tuple[str, str]] = {
    "render": ("leafview.cli.render", "render thumbnails of presets offscreen"),
    "presets": ("leafview.cli.presets", "list the built-in presets"),
    "view": ("leafview.cli.view", "open the interactive viewer window"),
    "bench": ("leafview.cli.bench", "measure rendering speed (prints GL_RENDERER and ratios)"),
    "export": ("leafview.cli.export", "bake leaves or a scene into .glb/.gltf/.obj/.ply/.usda/.usdc"),
    "morph": ("leafview.cli.morph", "morph one leaf shape into another: frames, contact sheet, smoothness"),
    "scene": ("leafview.cli.scene", "render, save, export or view a scene of many leaves"),
    "shapes": ("leafview.cli.shapes", "list or render the botanical shape catalogue, or a multilobed leaf"),
    "dataset": ("leafview.cli.dataset", "render a synthetic dataset with exact labels (COCO, depth, normals, uv)"),
    "fit": ("leafview.cli.fit", "fit one leaf to a point cloud (PLY, XYZ/CSV, .npy) or to photos (PNG, JPEG, TIFF, or a folder of them)"),
    "capture": ("leafview.cli.capture", "segment and fit the leaves of dense foliage from RGB-D views"),
    "eval-capture": ("leafview.cli.eval_capture", "score a capture against the truth its views were rendered from"),
}


class _CommandListFormatter(argparse.HelpFormatter):
    """argparse's formatter, with the command list's help column far enough right for the
    longest command name (argparse measures sub-commands without their indentation, so
    ``eval-capture`` would otherwise push its help onto the next line)."""

    def add_argument(self, action: argparse.Action) -> None:
        super().add_argument(action)
        if isinstance(action, argparse._SubParsersAction) and action.help is not argparse.SUPPRESS:
            self._action_max_length += self._indent_increment


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``leafview`` parser: every command with its one-line help, and the options of
    ``command`` (whose module is imported here; the others are not)."""
    parser = argparse.ArgumentParser(prog="leafview", description="Parametric plant leaves evaluated on the GPU.",
                                     formatter_class=_CommandListFormatter)
    parser.add_argument("--version", action="version", version=f"leafview {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (module, text) in COMMANDS.items():
        p = sub.add_parser(name, help=text, description=text)
        if name == command:
            importlib.import_module(module).add_arguments(p)   # the one lazy import: the chosen command
    return parser


def _chosen(argv: Sequence[str]) -> str | None:
    """The command named in ``argv``: the first word that is not an option (``leafview`` itself
    has only --help and --version, which take no value)."""
    return next((a for a in argv if not a.startswith("-")), None)


_NEGATIVE_LIST = re.compile(r"-[0-9.][0-9.eE+-]*(,[-+]?[0-9.][0-9.eE+-]*)+")


def _attach_negative_lists(argv: list[str]) -> list[str]:
    """``--opt -180,90`` as ``--opt=-180,90``: argparse takes a value that starts with '-' for an
    option unless it reads as one negative number, which a comma-separated list does not."""
    out: list[str] = []
    for arg in argv:
        if out and out[-1].startswith("--") and "=" not in out[-1] and _NEGATIVE_LIST.fullmatch(arg):
            out[-1] = f"{out[-1]}={arg}"
        else:
            out.append(arg)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``leafview`` with ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    argv = _attach_negative_lists(list(sys.argv[1:] if argv is None else argv))
    command = _chosen(argv)
    args = build_parser(command if command in COMMANDS else None).parse_args(argv)
    try:
        code: int = importlib.import_module(COMMANDS[args.command][0]).run(args)
        return code
    except (UsageError, ParamError, SceneLimitError) as exc:
        print(f"leafview {args.command}: error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("leafview: interrupted; no partial files were left", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Terminated as exc:   # SIGTERM/SIGHUP while writing: temporary files removed
        print(f"leafview: {one_line(str(exc))}; no partial files were left", file=sys.stderr)
        return int(exc.code) if isinstance(exc.code, int) else EXIT_FAILURE
    except (GLUnavailable, GLContextLost, ImageWriteError, OutputError) as exc:   # a message, not a traceback
        print(f"leafview {args.command}: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_FAILURE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
