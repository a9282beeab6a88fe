"""The ``--views`` options of ``leafview render`` and ``leafview scene`` and the run that writes them.

``--views N -o DIR`` renders ``N`` views on a ring around the geometry into ``DIR``: colour,
depth, instance ids, normals, cameras and the truth leaf set (:mod:`leafview.export.views`).
``--aov``, ``--elevation``, ``--depth-noise`` and ``--holes`` go with it. Kept apart from
:mod:`leafview.cli.render` so that ``leafview scene`` does not load what only the thumbnails
need (the sheets and, through them, the lobe-outline fit and its scipy modules).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from leafview.cli.args import count, progress_bar, report
from leafview.errors import UsageError
from leafview.export.images import format_of
from leafview.export.views import (
    MAX_VIEWS,
    VIEW_AOVS,
    VIEW_GRID,
    ViewsReport,
    check_aovs,
    check_views_folder,
    render_views,
)
from leafview.gpu import default_renderer
from leafview.scene.camera import MAX_RING_ELEVATION, RING_ELEVATIONS
from leafview.scene.spec import Scene

__all__ = ["add_views_arguments", "check_views_arguments", "write_views"]


def _views(text: str) -> int:
    return count(text, lo=1, hi=MAX_VIEWS, what="views", name="--views")


def _aovs(text: str) -> tuple[str, ...]:
    try:
        return check_aovs(a.strip() for a in text.split(",") if a.strip())
    except UsageError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _elevations(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(a) for a in text.split(",") if a.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected degrees such as 25,50, got {text[:40]!r}") from None
    if not values:
        raise argparse.ArgumentTypeError("give at least one elevation in degrees")
    for e in values:
        if not (math.isfinite(e) and abs(e) <= MAX_RING_ELEVATION):
            raise argparse.ArgumentTypeError(f"elevation {e:g} outside ±{MAX_RING_ELEVATION:g} degrees")
    return values


def _sigma(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of world units, got {text[:40]!r}") from None
    if not (math.isfinite(x) and x >= 0.0):
        raise argparse.ArgumentTypeError(f"must be a finite number ≥ 0, got {text[:40]!r}")
    return x


def add_views_arguments(p: argparse.ArgumentParser) -> None:
    """``--views`` and the options that go with it."""
    p.add_argument("--views", type=_views, metavar="N",
                   help=f"render N views (1..{MAX_VIEWS}) on a ring around the geometry into the folder -o DIR: "
                        "VIEW.color.png, VIEW.depth.npy, VIEW.instance.png, VIEW.normal.exr, VIEW.json (OpenCV "
                        "K and pose) per view, truth.leaves.json and views.json. DIR must be new, empty or a "
                        "previous views folder")
    p.add_argument("--aov", type=_aovs, metavar="LIST",
                   help=f"with --views: the images of each view, comma-separated from {','.join(VIEW_AOVS)} "
                        "(default all)")
    p.add_argument("--elevation", type=_elevations, metavar="DEG[,DEG...]",
                   help="with --views: camera elevations in degrees, taken in turn "
                        f"(default {','.join(f'{e:g}' for e in RING_ELEVATIONS)})")
    p.add_argument("--depth-noise", type=_sigma, metavar="SIGMA",
                   help="with --views: Gaussian depth noise, SIGMA world units at the distance of the centre, "
                        "growing with the square of the distance (default 0: exact depth)")
    p.add_argument("--holes", action="store_true",
                   help="with --views: drop depth where the surface is seen edge-on (75-85 degrees to the "
                        "view ray) and at 0.2%% of the pixels at random")


def check_views_arguments(args: argparse.Namespace, conflicts: dict[str, bool]) -> None:
    """UsageError for the views options without ``--views``, or ``--views`` with any option of
    ``conflicts`` (flag -> given); checks the output folder. Nothing is written."""
    if args.views is None:
        given = [flag for flag, on in (("--aov", args.aov is not None), ("--elevation", args.elevation is not None),
                                       ("--depth-noise", args.depth_noise is not None), ("--holes", args.holes),
                                       ("--seed", getattr(args, "views_seed", None) is not None)) if on]
        if given:
            raise UsageError(f"{', '.join(given)} go{'es' if len(given) == 1 else ''} with --views N")
        return
    clash = [flag for flag, on in conflicts.items() if on]
    if clash:
        raise UsageError(f"--views writes a views folder: {', '.join(clash)} cannot be used with it")
    if not args.output:
        raise UsageError("--views needs -o DIR, the folder of the views")
    aovs = args.aov if args.aov is not None else VIEW_AOVS
    if (args.depth_noise or args.holes) and "depth" not in aovs:
        raise UsageError("--depth-noise and --holes change the depth images: add depth to --aov")
    if format_of(args.output) is not None or Path(args.output).suffix.lower() in (".json", ".toml"):
        raise UsageError(f"-o {args.output}: with --views, -o names a folder, not a file")
    check_views_folder(args.output)


def write_views(args: argparse.Namespace, scene: Scene, *, size: tuple[int, int], seed: int,
                grid: tuple[int, int] = VIEW_GRID) -> ViewsReport:
    """Render ``args.views`` views of ``scene`` into ``args.output`` with a progress bar (stderr)
    and print the summary line (unless ``-q``)."""
    renderer = default_renderer()
    sigma = args.depth_noise or 0.0
    bar = progress_bar(total=args.views, unit="view", desc="rendering views", quiet=args.quiet, leave=False)
    try:
        rep = render_views(renderer.ctx, scene, Path(args.output), views=args.views, size=size,
                           aovs=args.aov if args.aov is not None else VIEW_AOVS,
                           depth_noise=sigma, holes=args.holes, seed=seed,
                           elevations=args.elevation or RING_ELEVATIONS, grid=grid, resources=renderer.resources,
                           progress=bar.update)
    finally:
        bar.close()
    noise = ", ".join([f"depth noise {sigma:g}"] * (sigma > 0) + ["holes"] * bool(args.holes))
    details = [", ".join(rep.aovs), noise or "exact depth"]
    if "instance" in rep.aovs:
        details.append(f"leaves in {rep.labelled:.0%} of the pixels")
    stale = f"; removed {len(rep.removed)} files of a previous run" if rep.removed else ""
    n = len(rep.views)
    report(args, f"wrote {n} view{'s' * (n != 1)} of {rep.leaves:,} lea{'f' if rep.leaves == 1 else 'ves'} to "
                 f"{rep.out}/ ({size[0]}×{size[1]}: {'; '.join(details)}), truth.leaves.json and views.json "
                 f"in {rep.seconds:.1f} s{stale} [{rep.gl_renderer}]")
    return rep
