"""``leafview fit INPUT -o NAME.leaf.json``: one leaf's Ω and placement from a point cloud
(Chaurasia & Beardsley 2017, sec. 5, eqs 9-11; :func:`leafview.fit.cloud.fit_cloud`), or, for a
photo or a folder of photos (an image suffix, or a folder), Ω, scale and texture from the photo
(:mod:`leafview.cli.fit_photo`).

The cloud is PLY (ascii or binary), XYZ/CSV text or ``.npy`` (N×3, metres or any unit: the unit
becomes the leaf's transform scale). A fit whose median residual exceeds
:data:`~leafview.fit.cloud.EXPLAINED_LIMIT` of the leaf length does not explain the cloud: it is
reported and nothing is written (exit 1) unless ``--keep-unexplained`` is given.
"""

from __future__ import annotations

import argparse
import sys
import time

from leafview.cli import fit_photo
from leafview.cli.args import EXIT_FAILURE, EXIT_OK, int_in_range, output_path, refuse_directory, report
from leafview.core.io import save_params
from leafview.errors import UsageError
from leafview.fit.cloud import EXPLAINED_LIMIT, fit_cloud
from leafview.fit.cloud_io import read_cloud

__all__ = ["add_arguments", "run"]


def _scanlines(text: str) -> int:
    return int_in_range(text, lo=4, hi=512, what="scanlines", name="--scanlines")


def _iterations(text: str) -> int:
    return int_in_range(text, lo=1, hi=200, what="iterations", name="--iterations")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="INPUT",
                   help="one leaf's point cloud: .ply (ascii/binary), .xyz/.txt/.csv/.pts text or .npy (N×3); or a "
                        "photo or scan of one leaf: .png, .jpg/.jpeg, .tif/.tiff; or a folder of such photos")
    p.add_argument("-o", "--output", type=output_path, required=True, metavar="FILE",
                   help="the fitted leaf: NAME.leaf.json (compact), .json or .toml; from a photo also "
                        "NAME.leaves.json (both halves of an asymmetric leaf), with NAME.front.png beside it; "
                        "from a folder of photos, the folder to write into")
    p.add_argument("--scanlines", type=_scanlines, default=None,
                   help="point clouds: scanlines of the UV mapping (sec. 5; default 24)")
    p.add_argument("--iterations", type=_iterations, default=None,
                   help="point clouds: most alternations of Levenberg-Marquardt and UV update (default 15)")
    p.add_argument("--keep-unexplained", action="store_true",
                   help="point clouds: write the leaf even when the fit does not explain the cloud")
    fit_photo.add_arguments(p)
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")


def run(args: argparse.Namespace) -> int:
    if fit_photo.is_photo_input(args.input):
        return fit_photo.run(args)
    fit_photo.refuse_photo_options(args)
    out = refuse_directory("-o", args.output)
    if out.suffix.lower() not in (".json", ".toml"):
        raise UsageError(f"-o {args.output}: a leaf file is .leaf.json, .json or .toml")
    points = read_cloud(args.input)
    options = {}
    if args.scanlines is not None:
        options["scanlines"] = args.scanlines
    if args.iterations is not None:
        options["max_iterations"] = args.iterations
    t0 = time.perf_counter()
    fit = fit_cloud(points, name=fit_photo.leaf_name(out), **options)
    seconds = time.perf_counter() - t0
    summary = (f"{len(points):,} points: length {fit.length:.4g}, median residual {100 * fit.median:.2f} % of the "
               f"length (rms {100 * fit.rms:.2f} %), {fit.iterations} iterations in {seconds:.2f} s")
    if not fit.explained and not args.keep_unexplained:
        print(f"leafview fit: {args.input}: the fit does not explain the cloud ({summary}; the limit is a median of "
              f"{100 * EXPLAINED_LIMIT:g} %); nothing written (--keep-unexplained writes it anyway)", file=sys.stderr)
        return EXIT_FAILURE
    save_params(fit.params, out)
    note = "" if fit.explained else " (not explained: kept by --keep-unexplained)"
    report(args, f"wrote {out}: {summary}{note}")
    return EXIT_OK

