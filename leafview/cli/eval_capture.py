"""``leafview eval-capture DIR``: a capture scored against the truth its views were rendered from
(:func:`leafview.fit.evaluate.evaluate_capture`).

DIR is a views folder written by ``leafview scene … --views N -o DIR`` (or ``render``): it holds
the truth (``truth.leaves.json`` and each view's ``NAME.instance.png``). The capture is
``--capture FILE`` (a leaf set from ``leafview capture``) or, by default, made now from the same
views. The captured leaves are drawn from every view's camera on the GPU (their instance ids),
matched to the truth by mask IoU ≥ 0.5 in the best view, and their surfaces compared.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from leafview.atomic import write_text
from leafview.cli.args import EXIT_OK, output_path, progress_bar, refuse_directory, report
from leafview.cli.capture import capture_summary
from leafview.core.io import load_leaves
from leafview.errors import UsageError
from leafview.export.views import render_instance_ids
from leafview.fit.capture import capture
from leafview.fit.evaluate import evaluate_capture
from leafview.fit.views import read_views
from leafview.gpu.context import create_headless_context
from leafview.gpu.resources import GpuResources

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("directory", metavar="DIR", help="a views folder with the truth (truth.leaves.json, "
                                                    "NAME.instance.png)")
    p.add_argument("--capture", metavar="FILE", help="the captured leaf set (default: capture DIR now)")
    p.add_argument("--truth", metavar="FILE", help="the truth leaf set (default DIR/truth.leaves.json)")
    p.add_argument("--json", type=output_path, metavar="FILE", help="also write the figures as JSON")
    p.add_argument("--seed", type=int, default=0, help="seed of the capture made here (default 0)")
    p.add_argument("--any-colour", action="store_true", help="the capture made here uses every pixel's colour")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar and no table")


def run(args: argparse.Namespace) -> int:

    json_path = refuse_directory("--json", args.json) if args.json else None
    directory = Path(args.directory)
    views = read_views(directory)   # checks the folder first
    truth_path = Path(args.truth) if args.truth else directory / "truth.leaves.json"
    if not args.truth and not (directory / "truth.leaves.json").is_file():
        raise UsageError(f"{truth_path}: no truth leaf set (views written by `leafview scene … --views N` have one; "
                         "or pass --truth FILE)")
    truth = load_leaves(truth_path)
    missing = [v.name for v in views if v.instance is None]
    if missing:
        raise UsageError(f"{directory / (missing[0] + '.instance.png')}: missing; the evaluation needs the truth "
                         f"instance image of every view ({len(missing)} of {len(views)} missing)")
    t0 = time.perf_counter()
    seconds = 0.0
    if args.capture:
        captured = load_leaves(args.capture)
        source = str(args.capture)
    else:
        result = capture(views, seed=args.seed, leaf_colour=None if args.any_colour else "green")
        seconds = time.perf_counter() - t0
        captured = list(result.leaves)
        source = f"captured now: {capture_summary(result, len(views), seconds)}"
    cameras = []
    for view in views:
        assert view.instance is not None   # checked above
        cameras.append((view.k, view.world_from_camera, view.instance))
    ctx = create_headless_context()
    resources = GpuResources(ctx)
    try:
        renderer = str(ctx.info["GL_RENDERER"])
        predicted = [render_instance_ids(ctx, captured, view.k, view.world_from_camera,
                                         (view.depth.shape[1], view.depth.shape[0]), resources=resources)
                     for view in progress_bar(views, quiet=args.quiet, unit="view", desc="drawing the capture",
                                              leave=False)]
    finally:
        resources.release()
        ctx.release()
    ev = evaluate_capture(truth, captured, cameras, predicted)
    if json_path is not None:
        doc = {"directory": str(directory), "capture": source, "capture_seconds": seconds, "renderer": renderer,
               **ev.to_dict()}
        write_text(json_path, json.dumps(doc, indent=1) + "\n")
    report(args, f"{len(truth):,} truth leaves, {len(captured):,} captured ({source}) [{renderer}]")
    report(args, ev.table())
    return EXIT_OK
