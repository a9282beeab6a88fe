"""``leafview bench [core|scene|canopy|export|shapes|dataset|capture|fit|veins|peers|all] [--json] [--quick]``: the benchmark
tables of :mod:`leafview.bench`, measured in this process (also run by ``python bench/run_bench.py``);
``peers`` draws the same leaves with PyVista and pygfx as well (optional: ``leafview[peers]``), each
in a worker process of its own, and is left out of ``all``.

Each table module has ``run(quick, ctx) -> dict`` (JSON-able, with ``gl_renderer``) and
``format_table(res) -> str``; only the chosen tables' modules are imported. Nothing is asserted:
the figures are timings on this machine, next to the GL renderer that produced them.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from typing import Any

from leafview.cli.args import EXIT_OK, EXIT_USAGE
from leafview.errors import GLUnavailable, one_line

__all__ = ["SUITES", "ALL", "add_arguments", "run"]

# table name -> its module; "all" runs them in this order
SUITES: dict[str, str] = {
    "core": "leafview.bench.core",       # thumbnails, instancing, ripples, viewer edit latency
    "export": "leafview.bench.export",   # export time and file size per leaf
    "scene": "leafview.bench.scene",     # large scenes: frame times, culling and level of detail
    "canopy": "leafview.bench.canopy",   # the canopy look: shadows' cost and effect, wind
    "shapes": "leafview.bench.shapes",   # botanical leaves generated, fitted and drawn per second
    "dataset": "leafview.bench.dataset", # dataset images per second, 1 worker against 2 (local engine)
    "capture": "leafview.bench.capture", # fitting point clouds and capturing a plant from RGB-D views
    "fit": "leafview.bench.fit_photo",   # leaves fitted to synthetic photos: IoU, base/apex, photos per second
    "veins": "leafview.bench.veins",     # the vein field of a new species, GPU against its numpy twin
    "peers": "leafview.bench.peers",     # the same leaves drawn by PyVista/VTK and pygfx (leafview[peers])
}
# what "all" runs: every table but the side-by-side with other renderers (optional, minutes long)
ALL = tuple(name for name in SUITES if name != "peers")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``leafview bench`` (also used by ``bench/run_bench.py``)."""
    parser.add_argument("suite", nargs="?", default="core", choices=[*SUITES, "all"],
                        help="which benchmarks (default core: thumbnails, instancing, ripples, viewer)")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.add_argument("--quick", action="store_true", help="small counts: a smoke run, not a measurement")


def run(args: argparse.Namespace) -> int:
    """Run the suite(s) named in ``args``; exit code 2 when GL or a baseline is missing."""
    names = list(ALL) if args.suite == "all" else [args.suite]
    if "core" in names:
        try:
            import matplotlib  # noqa: F401  (the thumbnail baseline: optional, leafview[bench])
        except ImportError:
            print("leafview bench: matplotlib is needed for the baseline: pip install 'leafview[bench]'",
                  file=sys.stderr)
            return EXIT_USAGE
    results: dict[str, Any] = {}
    try:
        for name in names:
            table = importlib.import_module(SUITES[name])   # only the tables asked for
            res = table.run(quick=args.quick)
            results[name] = res
            if not args.json:
                print(table.format_table(res), flush=True)
    except GLUnavailable as exc:
        print(f"leafview bench: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_USAGE
    if args.json:
        print(json.dumps(results[names[0]] if len(names) == 1 else results, indent=2, allow_nan=False))
    return EXIT_OK
