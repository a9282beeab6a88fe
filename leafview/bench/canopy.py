"""``leafview bench canopy``: what the canopy look costs and what it does, measured side by side.

* ``shadow_frame_ratio``: ms per frame of the 10⁵-leaf field (10⁴ in ``--quick``; the scene
  table's field, species and size) with the canopy look and the sun's shadows ÷ the same frame with
  ``shadows = false`` (sky, ground, tone map, culling and LOD the same in both): one
  :class:`~leafview.gpu.canopy.CanopyRenderer`, its light switched between frames, the two
  interleaved (median of the per-pair ratios), 4× MSAA, readback included; the worse of the
  ``three-quarter`` and ``ground`` cameras (goal ≤ 2; per camera in ``shadow_views``), with the
  default light, whose ``"auto"`` shadow filter is ``"fast"`` (one bilinear tap) on a CPU
  rasteriser and ``"soft"`` (3 × 3 percentage-closer) on a GPU (``shadow_filter``: the one used).
  ``shadow_frame_ratio_soft``: the same with ``shadow_filter = "soft"``, in its own interleaved
  pairs.
* ``shadow_darkened_fraction``: of the leaf pixels of a 3,000-leaf plant (``layout = "plant"``,
  ovate) seen from the default three-quarter camera under the default sun, the fraction that
  shadows make more than 20 % darker (luminance) than ``--shadows off`` (goal ≥ 0.15);
  1024×768, no MSAA, leaf pixels from a frame without sky and ground.
* ``wind_silhouette_change``: that plant's silhouette (leaf coverage, no sky, no ground) at wind
  speed 8, t = 0 against t = 0.7: pixels covered in one frame only ÷ pixels covered in either
  (goal between 0.02 and 0.60), with the leaves drawn in each frame (the same count is the goal);
  ``wind_frame_ratio``: the field's frame with that wind ÷ still, interleaved.

Nothing is asserted here; the tests check the same goals at small sizes.
"""

from __future__ import annotations

from typing import Any

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.bench.scene import SIZE, SPECIES, _spec
from leafview.bench.timing import Progress, bench_context, gl_info, interleaved, median_time
from leafview.core.params import LeafParams
from leafview.deform.wind import WindSettings
from leafview.gpu.canopy import CanopyRenderer, resolve_shadow_filter
from leafview.gpu.context import check_error
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.gpu.targets import RenderTarget
from leafview.resources import resolve_preset
from leafview.scene.camera import scene_camera
from leafview.scene.lighting import LightSettings
from leafview.scene.spec import Scene, SceneSpec, build_scene

__all__ = ["run", "format_table", "GOALS", "WIND_GOAL", "shadow_darkening", "wind_silhouette"]

GOALS: dict[str, float] = {"shadow_frame_ratio": 2.0, "shadow_darkened_fraction": 0.15}
WIND_GOAL = (0.02, 0.60)   # wind_silhouette_change between these
PLANT_SIZE = (1024, 768)
WIND = WindSettings(speed=8.0)
_LEAVES_ONLY = LightSettings(shadows=False, sky=False, ground=False)
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def plant(leaves: int = 3000) -> Scene:
    """The goals' plant: ``leaves`` ovate leaves on one plant (seed 0)."""
    return build_scene(SceneSpec(species=(LeafParams.load(resolve_preset("ovate")),), leaves=leaves, layout="plant"))


def shadow_darkening(canopy: CanopyRenderer, size: tuple[int, int] = PLANT_SIZE) -> dict[str, Any]:
    """Of the leaf pixels seen from the scene's default camera, the fraction shadows darken by more
    than 20 %, and the leaf fraction of the frame (the light is left at its default)."""
    camera = scene_camera(canopy.scene.scene, size)
    frames = {}
    for key, light in (("on", LightSettings()), ("off", LightSettings(shadows=False)), ("leaves", _LEAVES_ONLY)):
        canopy.set_light(light)
        frames[key] = canopy.render(camera, size, samples=0)
    canopy.set_light(LightSettings())
    leaves = frames["leaves"][..., 3] == 255
    on = frames["on"][..., :3].astype(np.float64) @ _LUMINANCE
    off = frames["off"][..., :3].astype(np.float64) @ _LUMINANCE
    return {"fraction": float(np.mean(on[leaves] < 0.8 * off[leaves])), "leaf_pixels": int(leaves.sum()),
            "brightened": int((on[leaves] > off[leaves] + 2).sum())}


def wind_silhouette(canopy: CanopyRenderer, size: tuple[int, int] = PLANT_SIZE, wind: WindSettings = WIND,
                    times: tuple[float, float] = (0.0, 0.7)) -> dict[str, Any]:
    """The silhouette change between two instants of ``wind`` (XOR over union of the coverage
    masks) and the leaves drawn in each frame."""
    camera = scene_camera(canopy.scene.scene, size)
    canopy.set_light(_LEAVES_ONLY)
    masks: list[NDArray[np.bool_]] = []
    drawn: list[int] = []
    for t in times:
        masks.append(canopy.render(camera, size, samples=0, wind=wind.replace(time=t))[..., 3] > 127)
        drawn.append(int(canopy.scene.level_counts().sum()))
    canopy.set_light(LightSettings())
    canopy.set_wind(WindSettings())
    a, b = masks
    return {"change": float((a ^ b).sum() / max(int((a | b).sum()), 1)), "drawn": drawn}


def _ratio(ctx: moderngl.Context, canopy: CanopyRenderer, target: RenderTarget, camera: Any, rounds: int,
           base: dict[str, Any], other: dict[str, Any]) -> dict[str, Any]:
    """Interleaved frames of two settings (``{"light": ..., "wind": ...}``): ms of each (median) and
    the median of the per-pair ratios other ÷ base."""
    def frame(s: dict[str, Any]) -> None:
        canopy.set_light(s["light"])
        canopy.set_wind(s["wind"])
        canopy.draw(camera, SIZE, CullSettings(), framebuffer=target.fbo)
        target.read()

    return interleaved(lambda: frame(base), lambda: frame(other), rounds, ctx.finish)


def _shadow_pass_profile(ctx: moderngl.Context, canopy: CanopyRenderer, camera: Any, rounds: int) -> dict[str, Any]:
    """The shadow maps alone (:meth:`ShadowPass.render <leafview.gpu.shadow.ShadowPass.render>`
    for ``camera`` at the default light, ms, median; the rest of the shadowed frame's extra time is
    the lookups of leaves and ground), their cascade count and the leaves each cascade drew per
    level."""
    light = LightSettings()
    shadow, scene = canopy.shadow, canopy.scene
    ms = 1e3 * median_time(lambda: shadow.render(scene, camera, SIZE, light), max(rounds, 1), ctx.finish)
    cascades = shadow.cascades
    drawn: list[list[int]] = []
    if cascades is not None:
        for cam in cascades.cameras:
            scene.set_camera(cam, (cascades.tile, cascades.tile))
            scene.draw(shadow.settings, defines={"LEAF_DEPTH": 1})
            drawn.append([int(x) for x in scene.level_counts()])
    return {"shadow_pass_ms": ms, "cascades": len(drawn), "cascade_leaves": drawn}


def run(quick: bool = False, ctx: moderngl.Context | None = None) -> dict[str, Any]:
    """Run the canopy benchmarks on ``ctx`` (default a new headless context); see the module."""
    n = 10_000 if quick else 100_000
    rounds = 2 if quick else 5
    still = {"light": LightSettings(shadows=False), "wind": WindSettings()}
    shadowed = {"light": LightSettings(), "wind": WindSettings()}
    soft = {"light": LightSettings(shadow_filter="soft"), "wind": WindSettings()}
    windy = {"light": LightSettings(shadows=False), "wind": WIND.replace(time=0.35)}
    with bench_context(ctx) as ctx, Progress(4) as progress:
        res: dict[str, Any] = {**gl_info(ctx), "size": list(SIZE), "quick": quick, "species": list(SPECIES),
                               "field_leaves": n, "plant_size": list(PLANT_SIZE), "samples": 4}
        progress.step(f"{n:,}-leaf field, shadows on and off")
        scene = build_scene(_spec(n))
        with SceneRenderer(ctx, scene) as r, CanopyRenderer(r) as canopy, RenderTarget(ctx, SIZE, 4) as target:
            views: dict[str, Any] = {}
            for view in ("three-quarter", "ground"):
                camera = scene_camera(scene, SIZE, view)
                views[view] = _ratio(ctx, canopy, target, camera, rounds, still, shadowed)
                views[view].update(_shadow_pass_profile(ctx, canopy, camera, rounds))
                views[view]["soft"] = _ratio(ctx, canopy, target, camera, rounds, still, soft)
            res["shadow_views"] = views
            res["shadow_filter"] = resolve_shadow_filter(LightSettings().shadow_filter, res["gl_renderer"])
            res["shadow_frame_ratio"] = max(v["ratio"] for v in views.values())
            res["shadow_frame_ratio_soft"] = max(v["soft"]["ratio"] for v in views.values())
            progress.step(f"{n:,}-leaf field, wind and still")
            res["wind_frame"] = _ratio(ctx, canopy, target, scene_camera(scene, SIZE, "three-quarter"), rounds,
                                       still, windy)
            res["wind_frame_ratio"] = res["wind_frame"]["ratio"]
            check_error(ctx, "canopy field frames")
        progress.step("3,000-leaf plant: shadows")
        p = plant(1000 if quick else 3000)
        res["plant_leaves"] = len(p)
        with SceneRenderer(ctx, p) as r, CanopyRenderer(r) as canopy:
            dark = shadow_darkening(canopy)
            res["shadow_darkened_fraction"] = dark["fraction"]
            res["shadow_leaf_pixels"] = dark["leaf_pixels"]
            res["shadow_brightened_pixels"] = dark["brightened"]
            progress.step("3,000-leaf plant: wind")
            wind = wind_silhouette(canopy)
            res["wind_silhouette_change"] = wind["change"]
            res["wind_drawn"] = wind["drawn"]
            check_error(ctx, "canopy plant frames")
    return res


def _pass_note(view: dict[str, Any]) -> str:
    if "shadow_pass_ms" not in view:
        return ""
    n = view["cascades"]
    return f"; shadow maps alone {view['shadow_pass_ms']:.0f} ms, {n} cascade{'s' if n != 1 else ''}"


def format_table(res: dict[str, Any]) -> str:
    """The readable report printed by ``leafview bench canopy``."""
    lo, hi = WIND_GOAL
    ratio_ok = res["shadow_frame_ratio"] <= GOALS["shadow_frame_ratio"]
    dark_ok = res["shadow_darkened_fraction"] >= GOALS["shadow_darkened_fraction"]
    wind_ok = lo <= res["wind_silhouette_change"] <= hi and len(set(res["wind_drawn"])) == 1
    lines = [f"leafview canopy benchmark{' (quick)' if res['quick'] else ''}: {res['gl_renderer']} "
             f"({res['gl_version']}), {res['size'][0]}×{res['size'][1]}, {res['samples']}× MSAA"]
    views = "; ".join(f"{v} {r['ratio']:.2f}× ({r['other_ms']:.0f} vs {r['base_ms']:.0f} ms, rounds "
                      f"{r['range'][0]:.2f}-{r['range'][1]:.2f}{_pass_note(r)})" for v, r in res["shadow_views"].items())
    lines.append(f"shadow_frame_ratio       {res['shadow_frame_ratio']:.2f}×  (goal ≤ {GOALS['shadow_frame_ratio']:g}: "
                 f"{'met' if ratio_ok else 'NOT met'}; {res['field_leaves']:,}-leaf field, shadows on "
                 f"(\"auto\" filter: {res['shadow_filter']}) ÷ off, "
                 f"worst camera; {views})")
    soft = "; ".join(f"{v} {r['soft']['ratio']:.2f}× ({r['soft']['other_ms']:.0f} vs {r['soft']['base_ms']:.0f} ms, "
                     f"rounds {r['soft']['range'][0]:.2f}-{r['soft']['range'][1]:.2f})"
                     for v, r in res["shadow_views"].items())
    lines.append(f"shadow_frame_ratio_soft  {res['shadow_frame_ratio_soft']:.2f}×  (shadow_filter = \"soft\", the 3 × 3 "
                 f"filter; worst camera; {soft})")
    lines.append(f"shadow_darkened_fraction {res['shadow_darkened_fraction']:.1%}  (goal ≥ "
                 f"{GOALS['shadow_darkened_fraction']:.0%}: {'met' if dark_ok else 'NOT met'}; leaf pixels > 20 % "
                 f"darker, {res['plant_leaves']:,}-leaf plant, {res['plant_size'][0]}×{res['plant_size'][1]}, "
                 f"{res['shadow_leaf_pixels']:,} leaf pixels, {res['shadow_brightened_pixels']} brighter)")
    lines.append(f"wind_silhouette_change   {res['wind_silhouette_change']:.1%}  (goal {lo:.0%}-{hi:.0%} with the same "
                 f"leaf count: {'met' if wind_ok else 'NOT met'}; speed 8, t = 0 against 0.7, drawn "
                 f"{' / '.join(f'{d:,}' for d in res['wind_drawn'])})")
    w = res["wind_frame"]
    lines.append(f"wind_frame_ratio         {res['wind_frame_ratio']:.2f}×  (wind 8 ÷ still, {w['other_ms']:.0f} vs "
                 f"{w['base_ms']:.0f} ms, shadows off)")
    return "\n".join(lines)
