"""``leafview export``: bake presets (or a scene file) into glTF, OBJ, PLY or USD files.

One preset and ``-o FILE`` writes that file; several presets write one file each into
``-o DIR`` (format from ``--format``, default glb); a scene file (a TOML/JSON document with
``[[species]]``, see :mod:`leafview.model.scene`) writes the whole scene into ``-o FILE``.
Every input is validated before anything is baked; files are written atomically.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..cli import _expand, int_pair
from ..errors import UsageError
from ..model.params import LeafParams
from . import (
    DEFAULT_LENGTH_M,
    FORMATS,
    bake,
    export_leaf,
    export_scene,
    format_of,
    write,
)
from .gltf import BACK_FACES, INSTANCING_MODES
from .mesh import BACKENDS, DEFAULT_RESOLUTION, check_resolution
from .objply import UP_AXES
from .scene import leaf_scene

__all__ = ["add_arguments", "run"]

_FORMAT_NAMES = tuple(s.lstrip(".") for s in FORMATS)


def _resolution(text: str) -> tuple[int, int]:
    nu, nv = int_pair(text, lo=2, hi=1025, what="NUxNV", example="33x65")
    try:
        return check_resolution((nu, nv))
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
    parser.description = ("Bake leaves into meshes with normals and texture coordinates (jitter, ripples "
                          "and bending included; vertices read back from the rendering shader). "
                          "Formats: .glb/.gltf (glTF 2.0), .obj, .ply, .usda/.usdc. See docs/export.md.")
    parser.add_argument("inputs", nargs="+", metavar="PRESET|SCENE",
                        help="preset files, directories of presets, built-in names, or one scene file")
    parser.add_argument("-o", "--output", required=True, metavar="FILE|DIR")
    parser.add_argument("--format", choices=_FORMAT_NAMES, default=None,
                        help="file type for -o DIR (default glb), or to check -o FILE's suffix")
    parser.add_argument("--resolution", type=_resolution, default=DEFAULT_RESOLUTION, metavar="NUxNV",
                        help="(u, v) samples across and along the blade (default 33x65)")
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
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")


def _is_scene(path: Path) -> bool:
    if path.suffix.lower() not in (".toml", ".json") or not path.is_file():
        return False
    from ..model.io import read_document

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
        if out.is_dir():
            raise UsageError(f"-o {out} is a directory; give a file name")
        return "file", out, fmt
    if out.suffix and out.suffix.lower() in FORMATS:
        raise UsageError(f"{count} presets need -o DIR (one file each), not the file {out}")
    if out.exists() and not out.is_dir():
        raise UsageError(f"-o {out} exists and is not a directory")
    fmt = args.format or "glb"
    return "dir", out, FORMATS["." + fmt]


def _size(path: Path) -> str:
    n = path.stat().st_size
    return f"{n / 1e6:.1f} MB" if n >= 1e6 else f"{n / 1e3:.0f} kB"


def run(args: argparse.Namespace) -> int:
    from ..gpu.context import GLUnavailable

    try:
        return _run(args)
    except GLUnavailable as exc:
        raise GLUnavailable(f"{exc}\n  export without OpenGL: --backend numpy (the float64 reference)") from None


def _run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    started = time.perf_counter()
    paths = _expand(args.inputs)
    scenes = [p for p in paths if _is_scene(p)]
    if scenes:
        if len(paths) != 1:
            raise UsageError(f"{scenes[0]} is a scene file: export it on its own")
        return _run_scene(args, scenes[0], started)
    mode, out, fmt = _target(args, len(paths))
    leaves = [LeafParams.load(p) for p in paths]          # validate everything first
    names = [leaf.name or p.stem for leaf, p in zip(leaves, paths)]
    if mode == "dir" and len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise UsageError(f"several presets are named {', '.join(dup)}: their files would overwrite each other")
    opts = _options(args, fmt)
    common = {"resolution": args.resolution, "backend": args.backend, "length_m": args.length_m}
    if mode == "file":
        mesh = bake(leaves[0], args.resolution, backend=args.backend)
        write(leaf_scene(leaves[0], mesh, length_m=args.length_m), out, **opts)
        if not args.quiet:
            print(f"wrote {out} ({names[0]}, {mesh.n_vertices} vertices, {mesh.n_triangles} triangles, "
                  f"{_size(out)}) in {time.perf_counter() - started:.1f} s")
        return 0
    suffix = next(s for s, f in FORMATS.items() if f == fmt)
    written: list[Path] = []
    bar = tqdm(total=len(leaves), unit="leaf", desc="exporting", file=sys.stderr,
               disable=True if args.quiet else None)
    try:
        for leaf, name in zip(leaves, names):
            written.append(export_leaf(leaf, out / f"{name}{suffix}", **common, **opts))
            bar.update(1)
    except BaseException:
        for p in written:      # a failure leaves no half-finished directory behind
            p.unlink(missing_ok=True)
        raise
    finally:
        bar.close()
    if not args.quiet:
        print(f"wrote {len(written)} {fmt} files to {out}/ in {time.perf_counter() - started:.1f} s")
    return 0


def _run_scene(args: argparse.Namespace, path: Path, started: float) -> int:
    from tqdm import tqdm

    out = Path(args.output)
    fmt = format_of(out)
    if args.format and args.format != out.suffix.lower().lstrip("."):
        raise UsageError(f"-o {out} is a {out.suffix} file but --format {args.format} was given")
    try:
        from ..model.scene import build_scene, load_scene
    except ImportError as exc:
        raise UsageError(f"{path}: scene files need leafview.model.scene ({exc})") from None
    scene = build_scene(load_scene(path))
    shapes = len(np.unique(scene.shape_ids)) if len(scene) else 0
    bar = tqdm(total=shapes, unit="shape", desc="baking", file=sys.stderr, disable=True if args.quiet else None)
    try:
        export_scene(scene, out, resolution=args.resolution, backend=args.backend, length_m=args.length_m,
                     progress=bar.update, name=out.stem, **_options(args, fmt))
    finally:
        bar.close()
    if not args.quiet:
        print(f"wrote {out} ({len(scene)} leaves, {shapes} distinct shapes, {_size(out)}) "
              f"in {time.perf_counter() - started:.1f} s")
    return 0
