"""``leafview dataset``: synthetic leaf images with exact labels (a thin command over
:func:`leafview.dataset.make_dataset`; see docs/dataset.md).

Examples::

    leafview dataset -o leaves_ds --count 1000 --leaves 100 --layout tray
    leafview dataset -o leaves_ds --count 1000 --workers 2                  # the same bytes, faster
    leafview dataset -o leaves_ds --count 100000 --engine ray --address HEAD:6379 --workers 8 --gpus-per-worker 1
"""

from __future__ import annotations

import argparse
import sys

from leafview.cli.args import EXIT_FAILURE, EXIT_OK, count, image_size, output_path, report
from leafview.dataset import LAYOUTS, DatasetError, make_dataset
from leafview.dataset.engines import ENGINES
from leafview.dataset.recipe import (
    DEFAULT_RANGES,
    DEFAULT_SPECIES,
    MAX_COUNT,
    MAX_LEAVES_PER_IMAGE,
    MAX_SHARD,
    parse_range,
    parse_split,
)
from leafview.errors import one_line

__all__ = ["add_arguments", "run"]

_RANGES = (("elevation", "camera elevation in degrees above the horizon (default by layout: plant 5,45; "
                         "field 20,60; tray 50,90)", 0.0, 90.0),
           ("azimuth", "camera azimuth in degrees around +z (default 0,360)", -720.0, 720.0),
           ("distance", "camera distance relative to the framing distance, where 1 just fits the leaves' bounding "
                        "sphere (default 0.6,1.0)", 0.05, 100.0),
           ("sun_elevation", "key light elevation in degrees (default 25,75; its azimuth is uniform)", 0.0, 90.0),
           ("light_intensity", "key light strength (default 0.7,1.3; the renderer's default is 1.05)", 0.0, 10.0))


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``leafview dataset``."""
    p.description = ("Render a synthetic dataset of leaf images with exact labels: RGB, 16-bit instance ids, "
                     "depth, normals and (u, v) per pixel, COCO instance annotations (RLE masks, boxes, visible "
                     "fraction), per-image cameras (OpenCV K and pose) and leaf sets. The same arguments give "
                     "byte-identical files on any engine and number of workers; a rerun skips finished shards.")
    p.add_argument("-o", "--output", type=output_path, required=True, metavar="DIR",
                   help="output folder (created if needed)")
    p.add_argument("--count", required=True, metavar="N",
                   type=lambda t: count(t, lo=1, hi=MAX_COUNT, what="images", name="--count"),
                   help=f"number of images (at most {MAX_COUNT:,})")
    p.add_argument("--leaves", default=100, metavar="M",
                   type=lambda t: count(t, lo=1, hi=MAX_LEAVES_PER_IMAGE, what="leaves", name="--leaves"),
                   help="leaves per image (default 100)")
    p.add_argument("--layout", choices=LAYOUTS, default="plant",
                   help="one plant, a field of shrubs, or a cluttered tray of loose leaves (default plant)")
    p.add_argument("--species", metavar="A,B,...",
                   help=f"comma-separated presets, one COCO category each (default {','.join(DEFAULT_SPECIES)})")
    p.add_argument("--size", type=image_size, default=(640, 480), metavar="WxH", help="image size (default 640x480)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    for name, text, _, _ in _RANGES:
        p.add_argument(f"--{name.replace('_', '-')}", metavar="LO,HI", help=text)
    p.add_argument("--split", default="train=0.8,val=0.2", metavar="NAME=F,...",
                   help="splits and their fractions, summing to 1 (default train=0.8,val=0.2)")
    p.add_argument("--shard-size", default=16, metavar="N",
                   type=lambda t: count(t, lo=1, hi=MAX_SHARD, what="images", name="--shard-size"),
                   help="images per shard: the unit of work, resuming and retrying (default 16)")
    p.add_argument("--engine", choices=ENGINES, default="local",
                   help="local worker processes, or Ray actors (pip install \"leafview[ray]\") (default local)")
    p.add_argument("--workers", default=1, metavar="K",
                   type=lambda t: count(t, lo=1, hi=1024, what="workers", name="--workers"),
                   help="worker processes or Ray actors, each with its own GL context (default 1)")
    p.add_argument("--address", metavar="ADDR", help="with --engine ray: the cluster (HOST:PORT, ray://HOST:PORT "
                   "or auto); default a local Ray started for the run")
    p.add_argument("--gpus-per-worker", type=float, default=0.0, metavar="G",
                   help="with --engine ray: GPUs per actor (1 on a GPU cluster: one actor per GPU)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar, print nothing on success")


def run(args: argparse.Namespace) -> int:
    """Make the dataset of ``args``; exit 0, 2 (bad input, nothing written) or 1 (a failed worker,
    an unreachable Ray cluster, an unwritable folder)."""
    ranges: dict[str, tuple[float, float]] = {name: parse_range(getattr(args, name), f"--{name.replace('_', '-')}", lo, hi)
              for name, _, lo, hi in _RANGES if getattr(args, name) is not None}
    split = parse_split(args.split)
    try:
        rep = make_dataset(args.output, args.count, leaves=args.leaves, layout=args.layout, species=args.species,
                           size=args.size, seed=args.seed, split=split, shard_size=args.shard_size,
                           engine=args.engine, workers=args.workers, address=args.address,
                           gpus_per_worker=args.gpus_per_worker, progress=not args.quiet,
                           elevation=ranges.get("elevation"),
                           azimuth=ranges.get("azimuth", DEFAULT_RANGES["azimuth"]),
                           distance=ranges.get("distance", DEFAULT_RANGES["distance"]),
                           sun_elevation=ranges.get("sun_elevation", DEFAULT_RANGES["sun_elevation"]),
                           light_intensity=ranges.get("light_intensity", DEFAULT_RANGES["light_intensity"]))
    except DatasetError as exc:
        print(f"leafview dataset: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_FAILURE
    splits = ", ".join(f"{k} {v}" for k, v in rep.splits.items())
    rate = f", {rep.images_per_s:.2f} images/s" if rep.images_rendered else ""
    report(args, f"wrote {rep.images:,} images ({args.size[0]}×{args.size[1]}, {args.layout}) to {rep.out}: "
                 f"{rep.annotations:,} annotations; splits {splits}; rendered {rep.images_rendered:,} images in "
                 f"{len(rep.rendered_shards)} shards, {len(rep.skipped_shards)} shards already done "
                 f"({rep.engine}, {rep.workers} worker{'s' if rep.workers != 1 else ''}{rate})"
                 + (f" [{rep.gl_renderer}]" if rep.gl_renderer else ""))
    return EXIT_OK
