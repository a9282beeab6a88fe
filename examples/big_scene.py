# example: run
"""A field of 10⁵ leaves: every leaf its own shape, colour and placement, one storage-buffer row
each, culled and level-of-detailed by a compute pass, drawn with indirect draws.

    python examples/big_scene.py [OUT_DIR] [--leaves N] [--size WxH]

Writes ``OUT_DIR/field.png`` and prints what was drawn.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import leafview
from leafview.export.images import write_image
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.resources import resolve_preset
from leafview.scene.camera import scene_camera
from leafview.scene.spec import SceneSpec, build_scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="out", type=Path)
    parser.add_argument("--leaves", type=int, default=100_000)
    parser.add_argument("--size", default="960x540")
    args = parser.parse_args()
    size = tuple(int(x) for x in args.size.split("x"))

    species = tuple(leafview.LeafParams.load(resolve_preset(name))
                    for name in ("ovate", "lanceolate", "elliptic"))
    t0 = time.perf_counter()
    scene = build_scene(SceneSpec(layout="field", leaves=args.leaves, seed=1, species=species))
    t1 = time.perf_counter()
    ctx = leafview.gpu.default_renderer().ctx          # the shared headless (EGL) context
    renderer = SceneRenderer(ctx, scene)
    try:
        image = renderer.render(scene_camera(scene, size, "ground"), size, CullSettings())
        counts = renderer.level_counts()
    finally:
        renderer.release()
    t2 = time.perf_counter()
    args.out.mkdir(parents=True, exist_ok=True)
    path = write_image(args.out / "field.png", image)
    print(f"wrote {path}: {len(scene):,} leaves, {int(counts.sum()):,} drawn "
          f"(levels {'/'.join(str(int(c)) for c in counts)}); build {t1 - t0:.1f} s, "
          f"upload and frame {t2 - t1:.1f} s [{ctx.info['GL_RENDERER']}]")


if __name__ == "__main__":
    main()
