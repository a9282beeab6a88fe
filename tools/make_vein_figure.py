"""Regenerate docs/images/veins.png: four presets close up (pinnate beech, looping elliptic, palmate
orbicular, parallel maize), top row without veins (``--veins off``, as leafview drew every leaf
before venation), bottom row with their vein field, relief and vein geometry (Hong 2005, ch. 6.1
and 8). Drawn through LeafRenderer.draw, the viewer's path, so the veins that are wide enough on
screen are tubes. Run from the repository root."""

import numpy as np

import leafview
from leafview.export.images import contact_sheet, write_image
from leafview.gpu.targets import RenderTarget
from leafview.resources import builtin_presets
from leafview.scene.camera import look_at

SIZE = (256, 256)
NAMES = ("beech", "elliptic", "orbicular", "maize")
# a close-up of the right half, from the midrib to the margin, seen from above and towards the base
VIEWS = {"beech": ((-0.45, 0.5), 0.6), "elliptic": ((-0.5, 0.5), 0.5),
         "orbicular": ((-0.45, 0.45), 0.75), "maize": ((-0.5, 0.5), 0.3)}


def close_up(renderer: leafview.gpu.LeafRenderer, leaf: leafview.LeafParams, veins: bool) -> np.ndarray:
    (u, v), dist = VIEWS[leaf.name]
    centre = leafview.evaluate(leaf, [u], [v])[0] @ leaf.transform.matrix()[:3, :3].T + leaf.transform.matrix()[:3, 3]
    renderer.veins = veins
    renderer.set_leaf(leaf)
    eye = centre + dist * np.array([0.25, -0.55, 0.8])
    renderer.set_camera(look_at(eye, centre, SIZE[0] / SIZE[1], 0.01, 10.0), srgb=True, size=SIZE)
    with RenderTarget(renderer.ctx, SIZE, samples=4) as target:
        target.use()
        target.clear((1.0, 1.0, 1.0, 1.0))
        renderer.draw()
        return target.read()


def main() -> None:
    presets = builtin_presets()
    leaves = [leafview.LeafParams.load(presets[name]).replace(name=name) for name in NAMES]
    renderer = leafview.gpu.default_renderer()
    images = [close_up(renderer, leaf, False) for leaf in leaves] + [close_up(renderer, leaf, True) for leaf in leaves]
    labels = [f"{n}, veins off" for n in NAMES] + [f"{n}, veins on" for n in NAMES]
    sheet = contact_sheet(images, labels, columns=4)
    write_image("docs/images/veins.png", sheet)
    print("wrote docs/images/veins.png", sheet.shape, "GL_RENDERER", renderer.gl_renderer)


if __name__ == "__main__":
    main()
