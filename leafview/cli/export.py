"""``leafview export``: bake presets (or a scene file) into glTF, OBJ, PLY or USD files, or write
their compact parametric form.

``-o NAME.leaf.json`` writes one leaf in the compact form and ``-o NAME.leaves.json`` a leaf set
(every leaf of the presets, or every leaf of a scene as built), see
:mod:`leafview.core.compact`; ``--digits N`` rounds their numbers. One preset and ``-o FILE``
writes that file (a leaf set and ``-o FILE``: all its placed leaves in that file); several
presets write one file each into ``-o DIR`` (format from ``--format``, default glb); a scene
file (a TOML/JSON document with ``[[species]]``, see :mod:`leafview.scene.spec`) writes the
whole scene into ``-o FILE``.

``--mesh cdt`` exports presets as venation meshes instead of the (u, v) grid: a constrained
Delaunay triangulation with the veins of order <= 2 as edges (:mod:`leafview.export.cdt`;
``--max-area``, ``--min-angle``); a lobed leaf is refused (exit 2): it is exported on its own welded
grid (:mod:`leafview.export.mesh`). A compound (``lobed = 1``) file is accepted wherever a preset
is (:func:`leafview.cli.args.load_leaf_files`). Either mesh of a preset with its venation enabled carries the
leaf's baked vein textures (:mod:`leafview.export.vein_maps`: base colour and normal maps of both
sides, a photograph staying the base colour); ``--veins off`` leaves them out (the file is then
the one of a leaf without venation). Scene files and leaf sets into one file carry none.
Every input is validated before anything is baked; files are written atomically.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from leafview.atomic import check_target, outputs
from leafview.cli.args import (
    EXIT_OK,
    expand_presets,
    grid,
    int_in_range,
    load_leaf_files,
    output_directory,
    output_names,
    output_path,
    progress_bar,
    refuse_directory,
)
from leafview.core.io import read_document, save_leaves, save_params
from leafview.core.params import LeafParams
from leafview.errors import GLUnavailable, UsageError
from leafview.export import (
    DEFAULT_LENGTH_M,
    FORMATS,
    bake,
    export_scene,
    format_of,
    write,
)
from leafview.export.cdt import (
    DEFAULT_MAX_AREA,
    DEFAULT_MIN_ANGLE,
    bake_cdt,
    check_max_area,
    check_min_angle,
    check_not_lobed,
)
from leafview.export.gltf import BACK_FACES, INSTANCING_MODES
from leafview.export.mesh import BACKENDS, DEFAULT_RESOLUTION, check_resolution
from leafview.export.objply import UP_AXES
from leafview.export.scene import ExportScene
from leafview.export.textures import check_textures
from leafview.export.vein_maps import VeinMaps, bake_vein_maps, vein_scene
from leafview.scene.spec import build_scene, load_scene, scene_from_leaves

__all__ = ["add_arguments", "run"]

_FORMAT_NAMES = tuple(s.lstrip(".") for s in FORMATS)
MESHES = ("grid", "cdt")
VEINS = ("on", "off")


def _resolution(text: str) -> tuple[int, int]:
    nu, nv = grid(text)
    try:
        return check_resolution((nu, nv))
    except UsageError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _max_area(text: str) -> float:
    try:
        return check_max_area(text, "--max-area")
    except UsageError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _min_angle(text: str) -> float:
    try:
        return check_min_angle(text, "--min-angle")
    except UsageError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _length(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a length in metres, got {text!r}") from None
    if not (0.0 < value < float("inf")):
        raise argparse.ArgumentTypeError(f"length must be a positive number of metres, got {text}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``leafview export``."""
    parser.description = ("Bake leaves into meshes with normals and texture coordinates (jitter, ripples "
                          "and bending included; vertices read back from the rendering shader). "
                          "Formats: .glb/.gltf (glTF 2.0), .obj, .ply, .usda/.usdc. See docs/export.md.")
    parser.add_argument("inputs", nargs="+", metavar="PRESET|SCENE",
                        help="preset files, directories of presets, built-in names, or one scene file")
    parser.add_argument("-o", "--output", required=True, type=output_path, metavar="FILE|DIR")
    parser.add_argument("--format", choices=_FORMAT_NAMES, default=None,
                        help="file type for -o DIR (default glb), or to check -o FILE's suffix")
    parser.add_argument("--resolution", type=_resolution, default=None, metavar="NUxNV",
                        help="grid mesh: (u, v) samples across and along the blade (default 33x65)")
    parser.add_argument("--mesh", choices=MESHES, default="grid",
                        help="grid: the (u, v) grid the renderer draws (default); cdt: a constrained Delaunay "
                             "triangulation with the veins as edges, and baked vein textures (presets only)")
    parser.add_argument("--max-area", type=_max_area, default=None, metavar="A",
                        help=f"cdt: largest triangle area in leaf lengths² (default {DEFAULT_MAX_AREA:g})")
    parser.add_argument("--min-angle", type=_min_angle, default=None, metavar="DEG",
                        help=f"cdt: smallest angle away from sharper input angles (default {DEFAULT_MIN_ANGLE:g}; "
                             "at most 33)")
    parser.add_argument("--veins", choices=VEINS, default="on",
                        help="on: a preset with venation gets its baked vein textures, base colour and "
                             "normal maps (default); off: none")
    parser.add_argument("--backend", choices=BACKENDS, default="gpu",
                        help="gpu: vertices read back from the rendering shader (default); numpy: the "
                             "float64 reference (no OpenGL needed)")
    parser.add_argument("--length-m", type=_length, default=DEFAULT_LENGTH_M, metavar="M",
                        help=f"metres per leaf length (default {DEFAULT_LENGTH_M}: a 10 cm leaf)")
    parser.add_argument("--up", choices=UP_AXES, default="y", help="OBJ/PLY up axis (default y)")
    parser.add_argument("--back-faces", choices=BACK_FACES, default="primitive",
                        help="glTF/USD: the back colour as its own back-facing surface (default), or one "
                             "double-sided surface in the front colour")
    parser.add_argument("--instancing", choices=INSTANCING_MODES, default="auto",
                        help="glTF scenes: EXT_mesh_gpu_instancing for shapes with >= 16 copies (auto), "
                             "never (nodes) or always (ext)")
    parser.add_argument("--digits", type=_digits, default=None, metavar="N",
                        help="for .leaf.json/.leaves.json: round numbers to N significant digits "
                             "(default: exact, the shortest decimal of each float64)")
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")


def _digits(text: str) -> int:
    return int_in_range(text, lo=1, hi=17, what="digits", name="--digits")


_PARAMETRIC = (".leaf.json", ".leaves.json")


def _parametric(out: Path) -> str | None:
    name = out.name.lower()
    return next((s for s in _PARAMETRIC if name.endswith(s)), None)


def _run_parametric(args: argparse.Namespace, paths: list[Path], kind: str, started: float) -> int:
    """Write the compact form: one leaf (.leaf.json) or a leaf set (.leaves.json)."""
    out = Path(args.output)
    if args.format:
        raise UsageError(f"-o {out} is a parametric file: --format applies to meshes only")
    refuse_directory("-o", out)
    scenes = [p for p in paths if _is_scene(p)]
    if scenes:
        if len(paths) != 1 or kind != ".leaves.json":
            raise UsageError(f"{scenes[0]} is a scene file: write its leaves on their own with -o NAME.leaves.json")
        scene = build_scene(load_scene(scenes[0]))
        with progress_bar(total=len(scene), unit="leaf", desc="collecting", quiet=args.quiet) as bar:
            leaves = scene.placed_leaves(bar.update)   # unnamed: a leaf set names them <stem>-<i>
        what = f"{len(leaves):,} leaves of {scenes[0].name}"
    else:
        leaves = load_leaf_files(paths)
        what = leaves[0].name if len(leaves) == 1 else f"{len(leaves)} leaves"
    if kind == ".leaf.json":
        if len(leaves) != 1:
            source = ", ".join(str(p) for p in paths[:3]) + (", ..." if len(paths) > 3 else "")
            raise UsageError(f"{out}: {len(leaves)} leaves (from {source}) do not fit one .leaf.json: "
                             "use -o NAME.leaves.json")
        save_params(leaves[0], out, digits=args.digits)
    else:
        save_leaves(leaves, out, digits=args.digits)
    if not args.quiet:
        size = out.stat().st_size
        exact = "exact" if args.digits is None else f"{args.digits} significant digits"
        print(f"wrote {out} ({what}, {size:,} bytes, {size / len(leaves):,.0f} B/leaf, {exact}) "
              f"in {time.perf_counter() - started:.1f} s")
    return EXIT_OK


def _is_scene(path: Path) -> bool:
    if path.suffix.lower() not in (".toml", ".json") or not path.is_file():
        return False
    doc = read_document(path)
    return isinstance(doc, dict) and "species" in doc


def _options(args: argparse.Namespace, fmt: str) -> dict[str, Any]:
    opts: dict[str, Any] = {}
    if fmt in ("obj", "ply"):
        opts["up"] = args.up
    if fmt in ("glb", "gltf", "usda", "usdc"):
        opts["back_faces"] = args.back_faces
    if fmt in ("glb", "gltf"):
        opts["instancing"] = args.instancing
    return opts


def _target(args: argparse.Namespace, count: int) -> tuple[str, Path, str]:
    """('file' | 'dir', path, format)."""
    out = Path(args.output)
    if count == 1 and out.suffix:
        fmt = format_of(out)
        if args.format and args.format != out.suffix.lower().lstrip("."):
            raise UsageError(f"-o {out} is a {out.suffix} file but --format {args.format} was given")
        refuse_directory("-o", out)
        return "file", out, fmt
    if out.suffix and out.suffix.lower() in FORMATS:
        raise UsageError(f"{count} presets need -o DIR (one file each), not the file {out}")
    fmt = args.format or "glb"
    return "dir", output_directory(out), FORMATS["." + fmt]


def _file_size(path: Path) -> str:
    n = path.stat().st_size
    return f"{n / 1e6:.1f} MB" if n >= 1e6 else f"{n / 1e3:.0f} kB"


def run(args: argparse.Namespace) -> int:
    """Export the inputs of ``args``; returns the exit code."""
    try:
        return _run(args)
    except GLUnavailable as exc:
        raise GLUnavailable(f"{exc}\n  export without OpenGL: --backend numpy (the float64 reference)") from None


def _check_mesh_options(args: argparse.Namespace) -> None:
    """Refuse the options of the other mesh kind."""
    if args.mesh == "cdt":
        if args.resolution is not None:
            raise UsageError("--resolution applies to --mesh grid; --mesh cdt takes --max-area and --min-angle")
    else:
        for flag, value in (("--max-area", args.max_area), ("--min-angle", args.min_angle)):
            if value is not None:
                raise UsageError(f"{flag} applies to --mesh cdt only")
    if args.resolution is None:
        args.resolution = DEFAULT_RESOLUTION


def _run(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    _check_mesh_options(args)
    paths = expand_presets(args.inputs)
    kind = _parametric(Path(args.output))
    if kind:
        return _run_parametric(args, paths, kind, started)
    if args.digits is not None:
        raise UsageError("--digits applies to .leaf.json/.leaves.json outputs only")
    scenes = [p for p in paths if _is_scene(p)]
    if scenes:
        if len(paths) != 1:
            raise UsageError(f"{scenes[0]} is a scene file: export it on its own")
        if args.mesh == "cdt":
            raise UsageError(f"{scenes[0]} is a scene file: --mesh cdt exports presets (one leaf a file)")
        return _run_scene(args, scenes[0], started)
    leaves = load_leaf_files(paths)                       # validate everything first
    if args.mesh == "cdt":
        return _run_cdt(args, paths, leaves, started)
    if len(paths) == 1 and len(leaves) > 1 and Path(args.output).suffix.lower() in FORMATS:
        return _run_scene(args, paths[0], started, leaves=leaves)   # a leaf set into one file
    mode, out, fmt = _target(args, len(leaves))
    names = [leaf.name for leaf in leaves]
    # one safe, unique file name per leaf: never outside -o DIR, never one over another
    files = output_names(names, quiet=args.quiet) if mode == "dir" else names
    opts = _options(args, fmt)
    suffix = next(s for s, f in FORMATS.items() if f == fmt)
    targets = [out] if mode == "file" else [out / f"{name}{suffix}" for name in files]
    for target in targets:
        check_target(target)                                  # a folder that cannot take it: before the bake
    check_textures([(name or "leaf", leaf.texture) for name, leaf in zip(names, leaves)])   # a missing image too
    if mode == "file":
        scene = _grid_scene(args, leaves[0])
        write(scene, out, **opts)
        if not args.quiet:
            mesh, maps = scene.parts[0].mesh, scene.parts[0].vein_maps
            textures = "" if maps is None else f", {len(maps.images)} vein textures"
            print(f"wrote {out} ({names[0]}, {mesh.n_vertices} vertices, {mesh.n_triangles} triangles{textures}, "
                  f"{_file_size(out)}) in {time.perf_counter() - started:.1f} s")
        return EXIT_OK
    with progress_bar(total=len(leaves), unit="leaf", desc="baking", quiet=args.quiet) as bar:
        baked = []
        for leaf in leaves:    # everything baked (PNGs encoded) before the transaction stages a file
            baked.append(_grid_scene(args, leaf))
            bar.update(1)
    with outputs():            # every file or none: a failure leaves no half-finished directory behind
        for part, target in zip(baked, targets):
            write(part, target, **opts)
    if not args.quiet:
        print(f"wrote {len(targets)} {fmt} files to {out}/ in {time.perf_counter() - started:.1f} s")
    return EXIT_OK


def _maps(args: argparse.Namespace, leaf: LeafParams) -> VeinMaps | None:
    """The leaf's baked vein textures, or None (``--veins off``, or its venation is off)."""
    return bake_vein_maps(leaf) if args.veins == "on" else None


def _grid_scene(args: argparse.Namespace, leaf: LeafParams) -> ExportScene:
    """One leaf's (u, v) grid mesh and vein textures, placed by its transform (PNGs encoded here,
    before the writer stages a file)."""
    mesh = bake(leaf, args.resolution, backend=args.backend)
    return vein_scene(leaf, mesh, _maps(args, leaf), length_m=args.length_m)


def _run_scene(args: argparse.Namespace, path: Path, started: float,
               leaves: list[LeafParams] | None = None) -> int:
    """One file for a scene recipe, or for the placed leaves of a leaf set (``leaves``)."""
    out = Path(args.output)
    fmt = format_of(out)
    if args.format and args.format != out.suffix.lower().lstrip("."):
        raise UsageError(f"-o {out} is a {out.suffix} file but --format {args.format} was given")
    refuse_directory("-o", out)   # before the scene is built and baked
    scene = build_scene(load_scene(path)) if leaves is None else scene_from_leaves(leaves, name=path.name)
    shapes = len(np.unique(scene.shape_ids)) if len(scene) else 0
    bar = progress_bar(total=shapes, unit="shape", desc="baking", quiet=args.quiet)
    try:
        export_scene(scene, out, resolution=args.resolution, backend=args.backend, length_m=args.length_m,
                     progress=bar.update, name=out.stem, **_options(args, fmt))
    finally:
        bar.close()
    if not args.quiet:
        print(f"wrote {out} ({len(scene)} leaves, {shapes} distinct shapes, {_file_size(out)}) "
              f"in {time.perf_counter() - started:.1f} s")
    return EXIT_OK


def _run_cdt(args: argparse.Namespace, paths: list[Path], leaves: list[LeafParams], started: float) -> int:
    """``--mesh cdt``: each leaf's venation mesh and vein textures, one file each (a lobed leaf is
    refused, naming ``--mesh``)."""
    for leaf in leaves:
        check_not_lobed(leaf)
    if len(paths) == 1 and len(leaves) > 1 and Path(args.output).suffix.lower() in FORMATS:
        raise UsageError(f"{paths[0]} is a leaf set: --mesh cdt writes one leaf a file (use -o DIR)")
    mode, out, fmt = _target(args, len(leaves))
    names = [leaf.name for leaf in leaves]
    files = output_names(names, quiet=args.quiet) if mode == "dir" else names
    suffix = next(s for s, f in FORMATS.items() if f == fmt)
    targets = [out] if mode == "file" else [out / f"{name}{suffix}" for name in files]
    for target in targets:
        check_target(target)                                  # a folder that cannot take it: before the bake
    check_textures([(name or "leaf", leaf.texture) for name, leaf in zip(names, leaves)])
    area = DEFAULT_MAX_AREA if args.max_area is None else args.max_area
    angle = DEFAULT_MIN_ANGLE if args.min_angle is None else args.min_angle
    opts = _options(args, fmt)
    baked = []
    with progress_bar(total=len(leaves), unit="leaf", desc="meshing", quiet=args.quiet or mode == "file") as bar:
        for leaf in leaves:     # everything baked (PNGs encoded) before the transaction stages a file
            baked.append((bake_cdt(leaf, max_area=area, min_angle=angle, backend=args.backend), _maps(args, leaf)))
            bar.update(1)
    with outputs():             # every file or none
        for leaf, target, (cdt, maps) in zip(leaves, targets, baked):
            write(vein_scene(leaf, cdt.mesh, maps, length_m=args.length_m), target, **opts)
    if not args.quiet and mode == "file":
        cdt, maps = baked[0]
        textures = "" if maps is None else f", {len(maps.images)} vein textures"
        print(f"wrote {out} ({names[0] or 'leaf'}: {cdt.quality}{textures}, {_file_size(out)}) "
              f"in {time.perf_counter() - started:.1f} s")
    if not args.quiet and mode == "dir":
        print(f"wrote {len(targets)} {fmt} venation meshes to {out}/ in {time.perf_counter() - started:.1f} s")
    return EXIT_OK
