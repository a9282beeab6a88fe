"""``leafview scene``: build a scene of many leaves, render it offscreen, save it, or view it.

Images are drawn with the canopy look (:class:`~leafview.gpu.canopy.CanopyRenderer`: sun and
shadows, sky, ground, tone mapping; ``--shadows/--sun/--sky/--ground/--exposure/--ssao/--tone/--shadow-filter``
and the scene file's ``[light]`` table) in the wind of ``--wind/--wind-dir/--time`` (``[wind]``).

Examples::

    leafview scene --leaves 20000 --species ovate,lanceolate --seed 3 -o field.png
    leafview scene --layout plant --leaves 3000 --save tree.toml
    leafview scene tree.toml -o tree.png --camera ground --size 1280x720
    leafview scene tree.toml --view            # interactive window
    leafview scene tree.toml --sun 200,25 --exposure 0.5 -o dusk.png
    leafview scene tree.toml --wind 6 --frames 120 -o anim.mp4      # or anim.gif, or frames/
    leafview scene --leaves 40 --layout plant --views 8 --depth-noise 0.005 --holes -o views/

``--views N -o DIR`` writes synthetic RGB-D views with exact ground truth instead of one picture
(:mod:`leafview.export.views`; the options, :mod:`leafview.cli.views`, are shared with ``leafview
render``); it goes with none of the other outputs. The noise is seeded with the scene's ``--seed``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path
from typing import Any

from leafview.atomic import outputs
from leafview.botany.vein_shading import without_veins
from leafview.cli.args import (
    EXIT_OK,
    add_veins_argument,
    builtin_names,
    count,
    image_size,
    output_path,
    progress_bar,
    refuse_directory,
    veins_off,
)
from leafview.cli.scene_anim import (
    add_wind_arguments,
    animation_times,
    check_animation_output,
    wind_from_args,
    write_animation,
)
from leafview.cli.scene_look import add_light_arguments, light_from_args
from leafview.cli.views import add_views_arguments, check_views_arguments, write_views
from leafview.core.compact import is_compact
from leafview.core.io import leaves_from_document, read_document, save_leaves
from leafview.core.limits import MAX_PLANTS, MAX_VIEW_FRAMES
from leafview.core.params import LeafParams
from leafview.errors import UsageError
from leafview.export import export_scene
from leafview.export import format_of as mesh_format
from leafview.export.images import format_of, write_image
from leafview.gpu import default_renderer
from leafview.gpu.canopy import CanopyRenderer
from leafview.gpu.scene import LOD_GRIDS, CullSettings, SceneRenderer
from leafview.resources import builtin_presets, resolve_preset
from leafview.scene.camera import SCENE_VIEWS, box_camera
from leafview.scene.spec import (
    LAYOUTS,
    MAX_LEAVES,
    Scene,
    SceneSpec,
    build_scene,
    load_scene,
    save_scene,
    scene_from_leaves,
)

__all__ = ["add_arguments", "run", "spec_from_args"]

DEFAULT_CAMERA = "three-quarter"


def _count(text: str) -> int:
    """``--leaves``: 1..MAX_LEAVES (``1e6`` and ``10_000`` accepted; ``1e400`` refused, not an overflow)."""
    return count(text, lo=1, hi=MAX_LEAVES, what="leaves", name="leaf count")


def _plants(text: str) -> int:
    """``--plants``: 1..MAX_PLANTS."""
    return count(text, lo=1, hi=MAX_PLANTS, what="plants")


def _frames(text: str) -> int:
    """``--frames`` of a scripted view: 1..MAX_VIEW_FRAMES."""
    return count(text, lo=1, hi=MAX_VIEW_FRAMES, what="frames")


def _fraction(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0.0 <= x <= 0.5:
        raise argparse.ArgumentTypeError(f"must be in [0, 0.5], got {x}")
    return x


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``leafview scene``."""
    p.description = ("Build a scene of many leaves (one plant, a field or a hedge; species from presets, "
                     "each leaf varied), then render it offscreen with GPU culling and level of detail, "
                     "save it as a scene file, export it, or open it in a window.")
    p.add_argument("scene", nargs="?", metavar="SCENE", help="a scene file (.toml/.json) to load; "
                   "options given on the command line override its settings. A leaf set "
                   "(.leaves.json) is drawn as its explicit leaves")
    p.add_argument("--leaves", type=_count, help="number of leaves (default 10000, or the file's)")
    p.add_argument("--species", help="comma-separated presets (names or files), e.g. ovate,lanceolate")
    p.add_argument("--layout", choices=LAYOUTS, help="one plant, a field of plants or a hedge (default field)")
    p.add_argument("--seed", type=int, help="random seed (default 0): the same seed gives the same scene")
    p.add_argument("--plants", type=_plants, help=f"number of plants, at most {MAX_PLANTS:,} (default: from the "
                   "leaf count)")
    p.add_argument("--variation", type=_fraction, help="± fraction each leaf's shape varies (default 0.2)")
    p.add_argument("--no-stems", action="store_true", help="leaves only, no branches")
    p.add_argument("-o", "--output", type=output_path, metavar="IMAGE|DIR",
                   help="render to this image (.png, .tif, .exr); with --frames N, an animation (.mp4, .gif, "
                        "or a folder of PNG frames); with --views, the folder of the views")
    p.add_argument("--size", type=image_size, default=(1024, 768), metavar="WxH", help="image size (default 1024x768)")
    p.add_argument("--camera", choices=SCENE_VIEWS, default=None, help=f"camera (default {DEFAULT_CAMERA})")
    p.add_argument("--no-cull", action="store_true", help="draw every leaf (no frustum or size culling)")
    p.add_argument("--no-lod", action="store_true", help="every leaf at the finest grid")
    p.add_argument("--save", type=output_path, metavar="FILE",
                   help="write the scene file (.toml or .json), or every placed leaf as a leaf set (.leaves.json)")
    p.add_argument("--export", type=output_path, metavar="FILE",
                   help="bake the scene to a mesh file (.glb, .gltf, .usda, .usdc)")
    add_veins_argument(p)
    add_light_arguments(p)
    add_wind_arguments(p)
    p.add_argument("--view", action="store_true", help="open the scene in a window (orbit, culling/LOD panel)")
    p.add_argument("--frames", type=_frames, metavar="N",
                   help="with -o anim.mp4|anim.gif|DIR/: render N frames of the wind, --fps apart; with --view: "
                        "draw N frames, then close (scripted runs)")
    p.add_argument("--screenshot", type=output_path, metavar="IMAGE",
                   help="with --view: write the window after the last frame")
    add_views_arguments(p)
    p.add_argument("--allow-outside-presets", action="store_true",
                   help="let the scene file's [[species]] preset paths leave its folder (absolute paths, '..')")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")


def spec_from_args(args: argparse.Namespace) -> SceneSpec:
    """The scene recipe: the file's (if any) with command-line overrides; raises ParamError."""
    if args.scene:
        spec = load_scene(args.scene, allow_outside_presets=args.allow_outside_presets)
    else:
        spec = SceneSpec(species=(LeafParams.load(builtin_presets()["ovate"]),), name="scene")
    changes: dict[str, Any] = {}
    if args.species:
        species = []
        for name in (s.strip() for s in args.species.split(",")):
            path = resolve_preset(name)
            if not name or not path.exists():
                raise UsageError(f"--species: {name!r} is not a preset file or built-in name "
                                 f"(built-in: {builtin_names()})")
            species.append(LeafParams.load(path))
        changes.update(species=tuple(species), weights=(), varieties=())
    for key in ("leaves", "layout", "seed", "plants", "variation"):
        value = getattr(args, key)
        if value is not None:
            changes[key] = value
    if args.no_stems:
        changes["stems"] = False
    spec = spec.replace(**changes) if changes else spec
    return with_look(spec, args)


def with_look(spec: SceneSpec, args: argparse.Namespace) -> SceneSpec:
    """``spec`` with the light and wind options of ``args`` over its ``[light]`` and ``[wind]``."""
    light, wind = light_from_args(args, spec.light), wind_from_args(args, spec.wind)
    return spec if (light, wind) == (spec.light, spec.wind) else spec.replace(light=light, wind=wind)


def _check_outputs(args: argparse.Namespace) -> None:
    check_views_arguments(args, {"--view": args.view, "--frames": args.frames is not None,
                                 "--screenshot": bool(args.screenshot), "--export": bool(args.export),
                                 "--save": bool(args.save), "--camera": args.camera is not None,
                                 "--no-cull": args.no_cull, "--no-lod": args.no_lod})
    if args.views is not None:
        return
    args.camera = args.camera or DEFAULT_CAMERA
    if not (args.output or args.save or args.export or args.view):
        raise UsageError("nothing to do: give -o IMAGE, --save FILE, --export FILE, --view or --views N -o DIR")
    if args.screenshot and not args.view:
        raise UsageError("--screenshot goes with --view")
    if args.frames is not None and not (args.view or args.output):
        raise UsageError("--frames goes with -o anim.mp4|anim.gif|DIR/ (an animation) or with --view")
    if args.frames is not None and args.frames < 1:
        raise UsageError(f"--frames must be at least 1, got {args.frames}")
    if args.output and args.frames is not None and not args.view:
        check_animation_output(args.output, args.frames)   # unknown type or unwritable place: exit 2 now
    elif args.output and format_of(Path(args.output)) is None:
        raise UsageError(f"-o {args.output}: unknown image type (use .png, .tif or .exr; with --frames N, "
                         ".mp4, .gif or a folder)")
    if args.save and Path(args.save).suffix.lower() not in (".toml", ".json"):
        raise UsageError(f"--save {args.save}: use a .toml or .json file name")
    if args.export:
        mesh_format(args.export)
    seen: dict[str, str] = {}
    for flag, value in (("-o", args.output), ("--save", args.save), ("--export", args.export),
                        ("--screenshot", args.screenshot)):
        if value and not (flag == "-o" and args.frames is not None and not args.view):
            refuse_directory(flag, value)   # every target checked before any work
            key = os.path.abspath(value)
            if key in seen:
                raise UsageError(f"{seen[key]} and {flag} name the same file {value}")
            seen[key] = flag


def _leaf_set(args: argparse.Namespace) -> list[LeafParams] | None:
    """The leaves of ``SCENE`` when it is a leaf set (``{"leafview": 1, "leaves": [...]}``), else None."""
    if not args.scene or Path(args.scene).suffix.lower() != ".json":
        return None
    doc = read_document(args.scene)
    if not is_compact(doc):
        return None
    overrides = [f"--{k.replace('_', '-')}" for k in ("leaves", "species", "layout", "seed", "plants", "variation")
                 if getattr(args, k) is not None] + (["--no-stems"] if args.no_stems else [])
    if overrides:
        raise UsageError(f"{args.scene} is a leaf set of explicit leaves: {', '.join(overrides)} "
                         "apply to scene recipes only")
    return leaves_from_document(doc, args.scene)


def _save(scene: Scene, spec: SceneSpec, path: str, explicit: bool) -> None:
    """--save: a recipe as .toml/.json, or every placed leaf as a leaf set (.leaves.json)."""
    if path.lower().endswith(".leaves.json"):
        save_leaves(scene.placed_leaves(), path)
    elif explicit:
        raise UsageError(f"--save {path}: a leaf set has no recipe; save it as NAME.leaves.json")
    else:
        save_scene(spec, path)


def run(args: argparse.Namespace) -> int:
    """Build, save, export, render and/or view the scene of ``args``; returns the exit code."""
    _check_outputs(args)
    say = (lambda text: None) if args.quiet else print
    t0 = time.perf_counter()
    leaves = _leaf_set(args)
    if leaves is not None:            # a leaf set: explicit placed leaves, drawn as they are
        scene = scene_from_leaves(leaves, name=Path(args.scene).name)
        spec = with_look(scene.spec, args)
        scene = dataclasses.replace(scene, spec=spec)
    else:
        spec = spec_from_args(args)   # every input is validated before anything is written
        scene = build_scene(spec)
    t_build = time.perf_counter() - t0
    if veins_off(args):   # drawn, exported and viewed without veins; --save keeps the recipe as it is
        drawn = dataclasses.replace(scene, species=tuple(without_veins(scene.species)))
        scene, saved = drawn, scene
    else:
        saved = scene
    if args.views is not None:
        write_views(args, scene, size=args.size, seed=spec.seed)
        return EXIT_OK
    wrote: list[str] = []
    with outputs():   # --save, --export and -o are written together, or none of them
        _write_outputs(args, scene, saved, spec, leaves is not None, t_build, wrote)
    for line in wrote:
        say(line)
    if args.view:
        # the edit panel's Save writes the recipe: to --save's file, else back to the scene file opened
        recipe = None if leaves is not None else (args.save if args.save and not args.save.lower().endswith(
            ".leaves.json") else args.scene)
        # the window (imgui, the viewer's panels: 0.5-0.7 s of imports) only for --view, not offscreen
        from leafview.app.scene_view import view_scene
        return view_scene(saved, size=args.size, frames=args.frames, screenshot=args.screenshot,
                          veins=not veins_off(args), path=recipe)
    return EXIT_OK


def _write_outputs(args: argparse.Namespace, scene: Scene, saved: Scene, spec: SceneSpec, explicit: bool,
                   t_build: float, wrote: list[str]) -> None:
    """--save (``saved``: the scene as built), --export and -o (``scene``: as drawn) staged in the
    caller's transaction; ``wrote`` gets a line each."""
    say = wrote.append
    if args.save:
        _save(saved, spec, args.save, explicit)
        say(f"wrote {args.save}: {len(scene):,} leaves, {len(spec.species)} species, seed {spec.seed}")
    if args.export:
        # the grid the scene is drawn with up close, not the single-leaf default (33×65 would
        # make 10⁴ varied leaves a 1.4 GB file)
        with progress_bar(total=len(scene) if scene.varied else len(scene.species), unit="shape", desc="baking",
                          quiet=args.quiet, leave=False) as bar:
            export_scene(scene, args.export, resolution=LOD_GRIDS[0], progress=bar.update)
        say(f"wrote {args.export}: {len(scene):,} leaves baked at {LOD_GRIDS[0][0]}×{LOD_GRIDS[0][1]}")
    if args.output:
        ctx = default_renderer().ctx
        bar = progress_bar(total=len(scene), unit="leaf", unit_scale=True, desc="uploading", quiet=args.quiet,
                           leave=False)
        t1 = time.perf_counter()
        try:
            renderer = SceneRenderer(ctx, scene, progress=bar.update)
        finally:
            bar.close()
        camera = box_camera(*renderer.bounds, args.size, args.camera)   # Scene.bounds once, not twice
        animation = args.frames is not None and not args.view
        try:
            t_upload = time.perf_counter() - t1
            settings = CullSettings(cull=not args.no_cull, lod=not args.no_lod)
            t2 = time.perf_counter()
            with CanopyRenderer(renderer, spec.light, spec.wind) as canopy:
                if animation:
                    _animate(args, canopy, camera, settings, spec)
                else:
                    image = canopy.render(camera, args.size, settings)
            t_frame = time.perf_counter() - t2
            counts = renderer.level_counts()
            tris = renderer.triangles(counts)
        finally:
            renderer.release()
        drawn = int(counts.sum())
        if animation:
            say(f"wrote {args.output} ({args.size[0]}×{args.size[1]}, {args.frames} frames at {args.fps:g} fps, "
                f"wind {spec.wind.speed:g}): {len(scene):,} leaves, {drawn:,} drawn in the last frame; "
                f"build {t_build:.1f} s, upload {t_upload:.1f} s, frames {t_frame:.1f} s "
                f"[{ctx.info['GL_RENDERER']}]")
            return
        write_image(args.output, image, description=f"leafview scene: {len(scene):,} leaves, seed {spec.seed}")
        say(f"wrote {args.output} ({args.size[0]}×{args.size[1]}, {args.camera} camera): {len(scene):,} leaves, "
            f"{drawn:,} drawn (levels {'/'.join(str(int(c)) for c in counts)}), {tris:,} triangles; "
            f"build {t_build:.1f} s, upload {t_upload:.1f} s, frame {t_frame:.2f} s "
            f"[{ctx.info['GL_RENDERER']}]")


def _animate(args: argparse.Namespace, canopy: CanopyRenderer, camera: Any, settings: CullSettings,
             spec: SceneSpec) -> None:
    """``--frames N -o anim.mp4|anim.gif|DIR/``: N frames of the scene's wind from ``--time``,
    ``1 / --fps`` apart, with a progress bar."""
    wind = spec.wind
    times = animation_times(wind.time, args.frames, args.fps)
    with progress_bar(total=args.frames, unit="frame", desc="rendering", quiet=args.quiet, leave=False) as bar:
        write_animation(args.output, args.frames, args.fps,
                        lambda t: canopy.render(camera, args.size, settings, wind=wind.replace(time=t)),
                        times=times, progress=bar.update)
