"""``leafview capture DIR -o plant.leaves.json``: the leaves of dense foliage from RGB-D views
(Chaurasia & Beardsley 2017, sec. 4, then sec. 5 per leaf; :func:`leafview.fit.capture.capture`).

DIR holds views in the layout of :mod:`leafview.fit.views`: ``NAME.color.png``, ``NAME.depth.npy``
(or ``.exr``) and ``NAME.json`` per view, as ``leafview scene … --views N -o DIR`` writes them and
any RGB-D sensor or multi-view stereo can. The leaf set it writes is what ``render``, ``scene``,
``view`` and ``export`` read.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from typing import Any

from leafview.atomic import outputs, write_text
from leafview.cli.args import EXIT_FAILURE, EXIT_OK, output_path, progress_bar, refuse_directory, report
from leafview.core.io import save_leaves
from leafview.errors import UsageError
from leafview.fit.capture import capture
from leafview.fit.views import read_views

__all__ = ["add_arguments", "run", "positive_float", "capture_summary"]


def positive_float(text: str) -> float:
    """A finite number > 0 for argparse."""
    try:
        x = float(text) if len(text) <= 40 else float("nan")
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text[:40]!r}") from None
    if not (x > 0.0 and x < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text[:40]!r}")
    return x


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("directory", metavar="DIR", help="a folder of views: NAME.color.png, NAME.depth.npy (or .exr), "
                                                    "NAME.json")
    p.add_argument("-o", "--output", type=output_path, required=True, metavar="FILE",
                   help="the leaf set to write (NAME.leaves.json)")
    p.add_argument("--delta-plane", type=positive_float, metavar="D",
                   help="plane-fit threshold δ_plane in world units (sec. 4.1; default: from the data)")
    p.add_argument("--report", type=output_path, metavar="FILE",
                   help="also write a JSON report: candidates, rejected leaves and why, timings")
    p.add_argument("--seed", type=int, default=0, help="seed of RANSAC and subsampling (default 0)")
    p.add_argument("--any-colour", action="store_true",
                   help="use every pixel, not only those whose green is the largest channel (autumn leaves)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar and no summary")


def capture_summary(result: Any, views: int, seconds: float) -> str:
    """One line: views, candidates, leaves kept and rejected (by reason), time."""
    reasons = Counter(r[0] if isinstance(r, tuple) else str(getattr(r, "reason", r)) for r in result.rejected)
    why = ", ".join(f"{n} {reason}" for reason, n in reasons.most_common())
    return (f"{views} views: {len(result.candidates):,} candidates, {len(result.leaves):,} leaves kept, "
            f"{len(result.rejected):,} rejected{f' ({why})' if why else ''} in {seconds:.1f} s "
            f"(δ_plane {result.delta_plane:.4g})")


def run(args: argparse.Namespace) -> int:

    out = refuse_directory("-o", args.output)
    if not out.name.lower().endswith(".json"):
        raise UsageError(f"-o {args.output}: a leaf set is JSON; give a NAME.leaves.json file name")
    report_path = refuse_directory("--report", args.report) if args.report else None
    if report_path is not None and report_path.suffix.lower() != ".json":
        raise UsageError(f"--report {args.report}: the report is JSON; give a .json file name")
    t0 = time.perf_counter()
    views = read_views(args.directory)
    bar = progress_bar(quiet=args.quiet, total=0, unit="step", leave=False)
    stage = {"name": ""}

    def progress(name: str, done: int, total: int) -> None:
        if name != stage["name"]:
            stage["name"] = name
            bar.reset(total=total)
            bar.set_description(name)
        bar.n = done
        bar.refresh()

    try:
        result = capture(views, delta_plane=args.delta_plane, progress=progress, seed=args.seed,
                         leaf_colour=None if args.any_colour else "green")
    finally:
        bar.close()
    seconds = time.perf_counter() - t0
    if not result.leaves:
        print(f"leafview capture: {args.directory}: no leaf could be fitted ({capture_summary(result, len(views), seconds)}); "
              "nothing written", file=sys.stderr)
        return EXIT_FAILURE
    with outputs():
        save_leaves(list(result.leaves), out)
        if report_path is not None:
            write_text(report_path, json.dumps(result.to_dict(), indent=1) + "\n")
    report(args, f"wrote {out}: {capture_summary(result, len(views), seconds)}")
    return EXIT_OK
