# example: run
"""A plant in the canopy look: scene-wide edits with undo, the sun moved, a frame in the wind, the
edited scene saved with its light and wind.

    python examples/canopy_edits.py [OUT_DIR] [--leaves N] [--size WxH]

Writes ``OUT_DIR/plant_noon.png``, ``OUT_DIR/plant_evening_wind.png`` and ``OUT_DIR/plant.toml``
and prints what it did.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import leafview
from leafview.deform.wind import WindSettings
from leafview.export.images import write_image
from leafview.gpu.canopy import CanopyRenderer
from leafview.gpu.scene import SceneRenderer
from leafview.gpu.scene_edits import update_rows
from leafview.resources import resolve_preset
from leafview.scene.camera import scene_camera
from leafview.scene.lighting import LightSettings
from leafview.scene.scene_edits import SceneEditor
from leafview.scene.spec import SceneSpec, build_scene, save_scene
from leafview.scene.variety import Variety


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="out", type=Path)
    parser.add_argument("--leaves", type=int, default=2000)
    parser.add_argument("--size", default="640x480")
    args = parser.parse_args()
    size = tuple(int(x) for x in args.size.split("x"))

    ovate = leafview.LeafParams.load(resolve_preset("ovate"))
    # every leaf its own ripple phase and bend load, drawn from the species' ranges
    spec = SceneSpec(species=(ovate,), layout="plant", leaves=args.leaves, seed=3,
                     varieties=(Variety(ripple_phase=(0.0, 32.0), bend_load=(0.7, 1.3)),))
    scene = build_scene(spec)
    ctx = leafview.gpu.default_renderer().ctx          # the shared headless (EGL) context
    with SceneRenderer(ctx, scene) as renderer, CanopyRenderer(renderer) as canopy:
        editor = SceneEditor(scene)
        editor.select()                                   # every leaf: 20 % wider
        writes = update_rows(renderer, editor.apply("width", 1.2))
        editor.select(leaves=range(0, len(scene), 2))     # every other leaf: skewed, then taken back
        update_rows(renderer, editor.apply("asymmetry", 0.08))
        update_rows(renderer, editor.undo())
        camera = scene_camera(scene, size)
        args.out.mkdir(parents=True, exist_ok=True)
        noon = write_image(args.out / "plant_noon.png", canopy.render(camera, size))
        canopy.set_light(LightSettings(sun=(200.0, 18.0)))
        wind = WindSettings(speed=6.0, time=0.4)
        evening = write_image(args.out / "plant_evening_wind.png", canopy.render(camera, size, wind=wind))
        saved = args.out / "plant.toml"
        save_scene(scene.spec.replace(edits=editor.edits, light=canopy.light, wind=wind), saved)
    print(f"wrote {noon} and {evening}: {len(scene):,} leaves, edits {[e.op for e in editor.edits]} "
          f"({writes} buffer write(s) for the width edit); wrote {saved} [{ctx.info['GL_RENDERER']}]")


if __name__ == "__main__":
    main()
