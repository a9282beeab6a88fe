"""Regenerate the canopy-look figures of docs/canopy.md and the README (run from the repository root):

* docs/images/canopy_before_after.png: one small field of four plants drawn with the old look
  (:meth:`leafview.gpu.scene.SceneRenderer.render`: a white page, the fixed light) and with the
  canopy look (:class:`leafview.gpu.canopy.CanopyRenderer`, the default ``[light]``), side by side;
* docs/images/canopy_sun.png: one plant under a morning, a noon and an evening sun;
* docs/images/canopy_wind.png: four frames of that plant in a wind of speed 8 (t = 0, 0.25, 0.5, 0.75 s);
* docs/images/canopy_ssao.png: the plant's crown from near, without and with screen-space ambient
  occlusion (a crop where the two differ most).

Every scene is seeded, so the images are the same from run to run on one renderer. Labels are
drawn with Pillow's built-in bitmap font (no font file needed).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw, ImageFont

from leafview.core.params import LeafParams
from leafview.deform.wind import WindSettings
from leafview.gpu import default_renderer
from leafview.gpu.canopy import CanopyRenderer
from leafview.gpu.scene import SceneRenderer
from leafview.resources import builtin_presets
from leafview.scene.camera import Camera, look_at
from leafview.scene.lighting import LightSettings
from leafview.scene.spec import Scene, SceneSpec, build_scene

OUT = Path("docs/images")
Image8 = NDArray[np.uint8]


def field_scene() -> Scene:
    """Four plants of two species (a field of 3,000 leaves), seeded."""
    species = tuple(LeafParams.load(builtin_presets()[n]) for n in ("beech", "ovate"))
    return build_scene(SceneSpec(species=species, layout="field", leaves=3000, plants=4, seed=7))


def plant_scene() -> Scene:
    """One plant of 3,000 leaves, seeded."""
    species = (LeafParams.load(builtin_presets()["beech"]),)
    return build_scene(SceneSpec(species=species, layout="plant", leaves=3000, seed=3))


def view_of(scene: Scene, size: tuple[int, int], *, azimuth: float = -60.0, elevation: float = 18.0,
            fill: float = 0.9, ground: float = 0.25, zoom: float = 1.0, fov: float = 35.0) -> Camera:
    """A camera ``elevation`` degrees above the horizon looking from ``azimuth`` (degrees
    counter-clockwise from +x) at the scene's middle, as close as it can stand while the scene's box,
    widened by ``ground`` × its size on the ground (room for the shadows), fills at most ``fill`` of
    the image; ``zoom`` > 1 comes closer than that."""
    lo, hi = scene.bounds()
    pad = ground * np.array([hi[0] - lo[0], hi[1] - lo[1], 0.0])
    lo_g, hi_g = lo - pad, hi + pad
    corners = np.array([[x, y, z] for x in (lo_g[0], hi_g[0]) for y in (lo_g[1], hi_g[1]) for z in (lo[2], hi[2])])
    target = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2])
    a, e = np.radians(azimuth), np.radians(elevation)
    direction = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    extent = float(np.linalg.norm(hi_g - lo_g))

    def camera(goal: NDArray[np.float64], d: float) -> Camera:
        return look_at(goal + d * direction, goal, size[0] / size[1], 0.02 * extent, 50.0 * extent, fov_deg=fov)

    def ndc(goal: NDArray[np.float64], d: float) -> NDArray[np.float64]:
        cam = camera(goal, d)
        clip = np.c_[corners, np.ones(len(corners))] @ (cam.proj @ cam.view).T
        return clip[:, :2] / clip[:, 3:4] if (clip[:, 3] > 0).all() else np.full((1, 2), np.inf)

    def reach(goal: NDArray[np.float64], d: float) -> float:
        return float(np.abs(ndc(goal, d)).max())

    def fit(goal: NDArray[np.float64]) -> float:
        near, far = 0.1 * extent, 20.0 * extent   # the distance where the box just fills the image
        for _ in range(50):
            mid = (near + far) / 2
            near, far = (near, mid) if reach(goal, mid) <= fill else (mid, far)
        return far

    up = np.cross(np.cross(-direction, [0.0, 0.0, 1.0]), -direction)
    up /= np.linalg.norm(up)
    for _ in range(4):   # aim so the box's top and bottom lie as far from the image's edges
        d = fit(target)
        y = ndc(target, d)[:, 1]
        target = target + up * (y.max() + y.min()) / 2 * d * np.tan(np.radians(fov) / 2)
    return camera(target, fit(target) / zoom)


def label(image: Image8, text: str, *, scale: int = 2) -> Image8:
    """``image`` (RGB or RGBA) as RGB with ``text`` in a white box at its top-left corner."""
    rgb = Image.fromarray(np.ascontiguousarray(_on_white(image)))
    font = ImageFont.load_default()
    box = ImageDraw.Draw(rgb).textbbox((0, 0), text, font=font)
    w, h = int(box[2] - box[0]) + 6, int(box[3] - box[1]) + 6
    tag = Image.new("RGB", (w, h), "white")
    ImageDraw.Draw(tag).text((3 - box[0], 3 - box[1]), text, fill="black", font=font)
    tag = tag.resize((w * scale, h * scale), Image.Resampling.NEAREST)
    rgb.paste(tag, (8, 8))
    return np.asarray(rgb)


def _on_white(image: Image8) -> Image8:
    img = np.asarray(image)
    if img.shape[2] == 3:
        return img
    a = img[..., 3:4].astype(np.float32) / 255.0
    return np.rint(img[..., :3] * a + 255.0 * (1.0 - a)).astype(np.uint8)


def row(images: Sequence[Image8], gap: int = 6) -> Image8:
    """Images of one height side by side, ``gap`` white pixels apart."""
    h = images[0].shape[0]
    parts: list[Image8] = []
    for i, img in enumerate(images):
        if i:
            parts.append(np.full((h, gap, 3), 255, np.uint8))
        parts.append(_on_white(img))
    return np.concatenate(parts, axis=1)


def crop_box(a: Image8, b: Image8, size: tuple[int, int]) -> tuple[slice, slice]:
    """Rows and columns of a ``size`` (w, h) window of two frames centred on the pixels where
    they differ most (kept inside the frames)."""
    d = np.abs(a[..., :3].astype(np.int16) - b[..., :3].astype(np.int16)).sum(axis=-1).astype(np.float64)
    ys, xs = np.nonzero(d > np.percentile(d, 90))
    cy, cx = int(np.median(ys)), int(np.median(xs))
    h, w = a.shape[:2]
    y0 = min(max(cy - size[1] // 2, 0), h - size[1])
    x0 = min(max(cx - size[0] // 2, 0), w - size[0])
    return slice(y0, y0 + size[1]), slice(x0, x0 + size[0])


def save(image: Image8, name: str) -> None:
    path = OUT / name
    Image.fromarray(image).save(path, optimize=True)
    print(f"wrote {path} ({image.shape[1]}×{image.shape[0]}, {path.stat().st_size / 1024:.0f} KB)")


def before_after() -> None:
    scene = field_scene()
    size = (680, 480)
    renderer = SceneRenderer(default_renderer().ctx, scene)
    try:
        camera = view_of(scene, size, azimuth=0.0, elevation=15.0, ground=0.2, fill=0.95)
        before = renderer.render(camera, size, background=(1.0, 1.0, 1.0, 1.0))
        with CanopyRenderer(renderer) as canopy:
            after = canopy.render(camera, size)
    finally:
        renderer.release()
    save(row([label(before, "before"), label(after, "after")]), "canopy_before_after.png")


def sun_and_wind() -> None:
    scene = plant_scene()
    size = (440, 440)
    renderer = SceneRenderer(default_renderer().ctx, scene)
    try:
        camera = view_of(scene, size, elevation=15.0, ground=0.3)
        with CanopyRenderer(renderer) as canopy:
            suns = []
            for name, sun in (("morning", (0.0, 28.0)), ("noon", (120.0, 65.0)), ("evening", (240.0, 28.0))):
                canopy.set_light(LightSettings(sun=sun))
                suns.append(label(canopy.render(camera, size), f"{name}: --sun {sun[0]:g},{sun[1]:g}"))
            canopy.set_light(LightSettings())
            small = (330, 330)
            cam = view_of(scene, small, elevation=12.0, ground=0.05, fill=0.95)
            frames = [label(canopy.render(cam, small, wind=WindSettings(speed=8.0, time=t)), f"t = {t:g} s")
                      for t in (0.0, 0.25, 0.5, 0.75)]
            canopy.set_wind(WindSettings())   # still air again
            size = (560, 560)   # the dense crown from near, without and with occlusion
            near = view_of(scene, size, azimuth=0.0, elevation=12.0, ground=0.0, zoom=1.3)
            off = canopy.render(near, size)
            canopy.set_light(LightSettings(ssao=True))
            on = canopy.render(near, size)
    finally:
        renderer.release()
    y, x = crop_box(off, on, (400, 400))
    save(row([label(off[y, x], "--ssao off"), label(on[y, x], "--ssao on")]), "canopy_ssao.png")
    save(row(suns), "canopy_sun.png")
    save(row(frames), "canopy_wind.png")


def main(argv: Sequence[str]) -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    before_after()
    sun_and_wind()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
