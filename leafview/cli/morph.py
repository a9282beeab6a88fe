"""``leafview morph``: a frame sequence morphing one leaf shape into another (Garg & Leow 2011, sec. 6).

Examples::

    leafview morph lanceolate reniform --frames 24 -o morph/
    leafview morph assets/landmarks/asymmetric.toml cordate --ref obcordate:2 --ref oblong:1 -o m/
    leafview morph elliptic deltoid --ref elliptic-extended-extended:4 --method keyframe -o key/
    leafview morph ovate maple --steps 8 -o frames/             # unilobed to lobed (Fig. 13)
    leafview morph ovate-drip cordate --sizes 0.3,1 -o grow/    # growth with size (Figs 12-13)

A lobed preset (``maple``, ``oak``, ``bilobed`` or a preset file with a ``[lobes]`` table) among
A, B and the references switches to the margin-space morph of :mod:`leafview.botany.lobe_morph`:
every frame is a lobed leaf (``lobes.outline``), the other keys' margins are written the same
way. ``--sizes`` gives a leaf length per key shape (A, references..., B), carried along the path
into each frame's ``transform.scale``.

Writes ``DIR/frame_000.png`` … (one shared camera), ``DIR/sheet.png`` (labelled contact sheet),
``DIR/morph.json`` (each frame's leaf-space vector and fit error, the path's smoothness beside
linear key-framing through the same references) and, with ``--presets``, each frame's Ω preset
(an asymmetric frame is two one-sided leaves: ``frame_NNN.right.toml`` and ``.left.toml``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from leafview.atomic import outputs, write_text
from leafview.botany.lobe_morph import is_lobed, load_key_shape, lobe_morph_path
from leafview.botany.morph import key_sizes, keyframe_path, morph_path, smoothness
from leafview.botany.shapes import INSTANCE_TARGET
from leafview.cli.args import EXIT_OK, VIEWS, output_directory, output_path, pixels, progress_bar
from leafview.core.io import dumps_toml
from leafview.core.limits import MAX_MORPH_FRAMES
from leafview.core.params import LeafParams, ParamError
from leafview.errors import UsageError
from leafview.export.images import contact_sheet, write_image
from leafview.gpu.morph import MorphSequence, load_morph_leaf, morph_sequence, parse_ref, render_sequence

__all__ = ["add_arguments", "run", "MAX_FRAMES"]

MAX_FRAMES = MAX_MORPH_FRAMES


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``leafview morph``."""
    p.description = ("Morph leaf shape A into B along the NURBS path (Garg & Leow 2011, eq. 11), pulled "
                     "towards weighted reference shapes; each frame is fitted to the shader model and "
                     "rendered. A, B and references are landmark leaf files (`landmarks = 1`, e.g. "
                     "assets/landmarks/*.toml) or catalogue names (`leafview shapes` lists them).")
    p.add_argument("source", metavar="A", help="source shape: landmark file or catalogue name")
    p.add_argument("target", metavar="B", help="target shape: landmark file or catalogue name")
    p.add_argument("--ref", action="append", default=[], metavar="C[:W]",
                   help="reference shape with weight W >= 0 (default 1), in path order; repeatable")
    p.add_argument("--frames", "--steps", dest="frames", type=int, default=24,
                   help="number of frames, ends included (default 24)")
    p.add_argument("--sizes", metavar="A,B[,...]", help="growth with size (Figs 12-13): a leaf length > 0 per "
                   "key shape (A, each --ref in order, B), interpolated along the path into transform.scale")
    p.add_argument("-o", "--output", required=True, type=output_path, metavar="DIR", help="output directory")
    p.add_argument("--size", type=pixels, default=192, help="pixels per frame (default 192)")
    p.add_argument("--view", choices=VIEWS, default="top", help="camera (default top)")
    p.add_argument("--method", choices=("nurbs", "keyframe"), default="nurbs",
                   help="nurbs: eq. 11, frames evenly spaced along the path (default); keyframe: linear "
                        "key-framing through the references (for comparison)")
    p.add_argument("--fast", action="store_true", help="linear fit only (about 10x faster, a few %% off)")
    p.add_argument("--margin", action="store_true",
                   help="draw each frame's landmark margin itself: exact, nothing fitted, one leaf a frame")
    p.add_argument("--presets", action="store_true", help="also write each frame's Ω preset (frame_NNN.toml)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")


def _output_dir(text: str) -> Path:
    out = Path(text)
    if out.suffix.lower() in (".png", ".tif", ".tiff", ".exr", ".jpg"):
        raise UsageError(f"-o {out}: morph writes a directory of frames; give a directory name")
    return output_directory(out)


def _warn_loose_fits(seq: MorphSequence) -> None:
    """Say which frames the shader model follows less closely than 1 % of the leaf length."""
    loose = [i for i, e in enumerate(seq.errors) if e > INSTANCE_TARGET]
    if not loose:
        return
    worst = max(seq.errors[i] for i in loose)
    print(f"note: {len(loose)} frame(s) ({', '.join(map(str, loose[:8]))}{' ...' if len(loose) > 8 else ''}) "
          f"fit the shader model to {100 * worst:.2f} % of the leaf length, above the {100 * INSTANCE_TARGET:g} % "
          f"goal (--fast fits are looser)", file=sys.stderr)


def parse_sizes(text: str | None) -> list[float] | None:
    """``--sizes 0.3,0.6,1``: finite numbers > 0 (the count is checked against the key shapes)."""
    if text is None:
        return None
    out = []
    for i, item in enumerate(text.split(",")):
        try:
            value = float(item)
        except ValueError:
            raise ParamError(f"--sizes[{i}]", f"expected a number, got {item!r}") from None
        if not (value > 0.0 and value < float("inf")):
            raise ParamError(f"--sizes[{i}]", f"a leaf size must be a finite number > 0, got {item}")
        out.append(value)
    return out


def _load_keys(args: argparse.Namespace) -> tuple[list[Any], list[float]]:
    """Source, references and target, and the references' weights: landmark leaves, or (when
    one of them is a lobed preset) whatever :func:`load_key_shape` reads."""
    specs = [(args.source, "A")] + [(parse_ref(t).spec, f"--ref {t}") for t in args.ref] + [(args.target, "B")]
    weights = [parse_ref(t).weight for t in args.ref]
    keys: list[Any] = []
    errors: list[ParamError | None] = []
    for spec, what in specs:
        try:
            keys.append(load_morph_leaf(spec, what))
            errors.append(None)
        except ParamError as exc:
            try:
                keys.append(load_key_shape(spec, what))
            except ParamError:
                keys.append(None)
            errors.append(exc)
    lobed = any(is_lobed(k) for k in keys)
    for key, err in zip(keys, errors):
        if err is not None and (not lobed or key is None):
            raise err
    return keys, weights


def _scaled(seq: MorphSequence, sizes: Any) -> None:
    """Give each frame's leaves the size the path carries to it (``transform.scale``)."""
    for i, s in enumerate(sizes):
        seq.parts[i] = tuple(p.replace(transform=replace(p.transform, scale=float(s))) for p in seq.parts[i])


def run(args: argparse.Namespace) -> int:
    """Fit, render and write the morph of ``args``; returns the exit code."""
    if not 2 <= args.frames <= MAX_FRAMES:
        raise UsageError(f"--frames must be between 2 and {MAX_FRAMES}, got {args.frames}")
    out = _output_dir(args.output)
    sizes = parse_sizes(args.sizes)
    keys, weights = _load_keys(args)
    if sizes is not None:
        key_sizes(sizes, weights, "--sizes")
    if args.margin and args.fast:
        raise UsageError("--margin draws the frames without a fit: drop --fast")
    if any(is_lobed(k) for k in keys):
        if args.margin:
            raise UsageError("--margin draws landmark margins; a lobed leaf has its own: drop --margin")
        return _run_lobed(args, out, keys, weights, sizes)
    source, target = keys[0], keys[-1]
    refs = list(zip(keys[1:-1], weights))

    t0 = time.perf_counter()
    with progress_bar(total=args.frames, unit="frame", desc="margins" if args.margin else "fitting frames",
                      quiet=args.quiet) as bar:
        seq = morph_sequence(source, target, refs, args.frames, method=args.method, polish=not args.fast,
                             margin=args.margin, progress=bar.update)
    t_fit = time.perf_counter() - t0
    if sizes is not None:
        path = morph_path(source, target, refs) if args.method == "nurbs" else keyframe_path(source, target, refs)
        _scaled(seq, path.values_at(key_sizes(sizes, weights, "--sizes"), path.parameter(seq.t, seq.by)))
    with progress_bar(total=args.frames, unit="frame", desc="rendering", quiet=args.quiet) as bar:
        images = render_sequence(seq.parts, args.size, args.view, progress=bar.update)
    width = len(str(args.frames - 1))
    labels = [f"{i:0{width}d}  t={t:.2f}" for i, t in enumerate(seq.t)]
    sheet = contact_sheet(images, labels, columns=min(8, args.frames))

    summary = seq.summary() | {"source": args.source, "target": args.target,
                               "refs": [{"spec": parse_ref(r).spec, "weight": parse_ref(r).weight} for r in args.ref]}
    if sizes is not None:
        summary["sizes"] = sizes
        for frame, parts in zip(summary["frame"], seq.parts):
            frame["size"] = parts[0].transform.scale
    with outputs():   # frames, presets, sheet and morph.json together, or none of them
        for i, (img, parts) in enumerate(zip(images, seq.parts)):
            stem = f"frame_{i:0{width}d}"   # file names from the frame number only, never from input
            if len(parts) == 1:
                write_image(out / f"{stem}.png", img, params=parts[0])
            else:
                write_image(out / f"{stem}.png", img, description=f"leafview morph frame {i}: asymmetric, "
                            f"drawn as two one-sided leaves ({stem}.right.toml, {stem}.left.toml with --presets)")
            if args.presets:
                names = [f"{stem}.toml"] if len(parts) == 1 else [f"{stem}.right.toml", f"{stem}.left.toml"]
                for fname, params in zip(names, parts):
                    write_text(out / fname, dumps_toml(params))
        write_image(out / "sheet.png", sheet,
                    description=f"leafview morph {args.source} -> {args.target} ({args.method}, {args.frames} frames)")
        write_text(out / "morph.json", json.dumps(summary, indent=1) + "\n")

    s, k = seq.smoothness, seq.keyframe_smoothness
    print(f"wrote {args.frames} frames ({args.size}×{args.size}, {args.view} view), sheet.png and morph.json "
          f"to {out}/ in {time.perf_counter() - t0:.1f} s ({'margins' if args.margin else 'fits'} {t_fit:.1f} s)")
    asym = sum(len(p) > 1 for p in seq.parts)
    halves = f"; {asym} asymmetric frame(s) drawn as two one-sided leaves" if asym else ""
    if args.margin:
        print(f"leaf space: {len(seq.space_names)} dimensions; frames drawn from their landmark margins "
              "(no fit, exact)")
    else:
        print(f"leaf space: {len(seq.space_names)} dimensions{halves}; frame fit error: largest "
              f"{100 * max(seq.errors):.2f} %, median {100 * sorted(seq.errors)[len(seq.errors) // 2]:.2f} % "
              f"of the leaf length")
    print(f"{'smoothness over ' + str(args.frames) + ' frames':34s} {'max step':>9s} {'step max/mean':>14s} "
          f"{'max turn (rad)':>15s}")
    print(f"{'NURBS path (eq. 11, arc length)':34s} {s['max_step']:9.4f} {s['step_ratio']:14.3f} {s['max_turn']:15.3f}")
    print(f"{'linear key-framing (same refs)':34s} {k['max_step']:9.4f} {k['step_ratio']:14.3f} {k['max_turn']:15.3f}")
    _warn_loose_fits(seq)
    if seq.reference_distances:
        d = ", ".join(f"{x:.3f}" for x in seq.reference_distances)
        print(f"distance from the path to each reference (leaf space): {d}")
    return EXIT_OK


def _run_lobed(args: argparse.Namespace, out: Path, keys: list[Any], weights: list[float],
               sizes: list[float] | None) -> int:
    """The margin-space morph (:mod:`leafview.botany.lobe_morph`): a lobed key shape is involved."""
    if args.method != "nurbs":
        raise UsageError("--method keyframe: a morph with a lobed leaf follows the NURBS path only")
    t0 = time.perf_counter()
    path = lobe_morph_path(keys[0], keys[-1], references=keys[1:-1], weights=weights, sizes=sizes)
    frames: list[LeafParams] = path.frames(args.frames)
    t = [float(x) for x in np.linspace(0.0, 1.0, args.frames)]
    with progress_bar(total=args.frames, unit="frame", desc="rendering", quiet=args.quiet) as bar:
        images = render_sequence([(p,) for p in frames], args.size, args.view, progress=bar.update)
    width = len(str(args.frames - 1))
    labels = [f"{i:0{width}d}  t={x:.2f}" for i, x in enumerate(t)]
    sheet = contact_sheet(images, labels, columns=min(8, args.frames))
    vectors = path.frame_vectors(args.frames)
    smooth = smoothness(vectors)
    refs = [{"spec": parse_ref(r).spec, "weight": parse_ref(r).weight} for r in args.ref]
    summary = {"method": "nurbs", "space": "margin", "by": "arclength", "frames": args.frames,
               "controls": path.controls, "source": args.source, "target": args.target, "refs": refs,
               "sizes": sizes, "smoothness": smooth,
               "reference_distances": [path.distance_to(v) for v in path.keys[1:-1]],
               "frame": [{"t": x, "size": p.transform.scale, "leaves": [p.name]} for x, p in zip(t, frames)]}
    with outputs():   # frames, presets, sheet and morph.json together, or none of them
        for i, (img, params) in enumerate(zip(images, frames)):
            stem = f"frame_{i:0{width}d}"
            write_image(out / f"{stem}.png", img, params=params)
            if args.presets:
                write_text(out / f"{stem}.toml", dumps_toml(params))
        write_image(out / "sheet.png", sheet,
                    description=f"leafview morph {args.source} -> {args.target} (lobed, {args.frames} frames)")
        write_text(out / "morph.json", json.dumps(summary, indent=1) + "\n")
    print(f"wrote {args.frames} lobed frames ({args.size}×{args.size}, {args.view} view), sheet.png and morph.json "
          f"to {out}/ in {time.perf_counter() - t0:.1f} s")
    print(f"margin space: {path.controls} control points (closed B-spline, by arc length from the base); "
          f"max step {smooth['max_step']:.4f}, step max/mean {smooth['step_ratio']:.3f}, "
          f"max turn {smooth['max_turn']:.3f} rad")
    if sizes is not None:
        print(f"sizes {frames[0].transform.scale:.3g} -> {frames[-1].transform.scale:.3g} (transform.scale)")
    return EXIT_OK
