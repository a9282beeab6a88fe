"""The canopy look (leafview.gpu.canopy, leaf.frag's LEAF_CANOPY): the pixels of a flat leaf, lit
from the front and from behind, are the numpy twin's (leafview.scene.leaf_light, tone mapped by
leafview.scene.sky); shadows darken a plant; alpha to coverage softens a textured leaf's margin;
the light options of ``leafview scene`` are checked while the command line is parsed."""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from leafview.botany import leaf_surface
from leafview.botany.vein_shading import without_veins
from leafview.cli.scene_look import add_light_arguments, light_from_args
from leafview.core.defaults import DEFAULT_GRID
from leafview.core.params import LeafParams, Transform
from leafview.core.texture import LeafTexture, with_folder
from leafview.deform.wind import WindSettings
from leafview.export.images import write_image
from leafview.gpu.canopy import CanopyRenderer, canopy_defines, resolve_shadow_filter
from leafview.gpu.scene import CullSettings, SceneRenderer, single_leaf_scene
from leafview.gpu.targets import RenderTarget
from leafview.resources import builtin_presets
from leafview.scene.camera import Camera, scene_camera, top_down
from leafview.scene.leaf_light import LUMINANCE, backlight_tint, canopy_radiance
from leafview.scene.lighting import LightSettings
from leafview.scene.sky import sh_irradiance, sky_model, tone_map
from leafview.scene.spec import SceneSpec, build_scene
from tests.conftest import assert_matches_reference

LEVEL0 = CullSettings(cull=False, lod=False)
SIZE = (96, 72)
TOL = 3            # /255 after the tone map (llvmpipe's rounding and the 8-bit target)
PLAIN = LightSettings(shadows=False, sky=False, ground=False, ssao=False)


# -- the command line ---------------------------------------------------------------------------
def _parse(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser(exit_on_error=False)
    add_light_arguments(p)
    return p.parse_args(list(argv))


def test_light_options_override_the_file():
    base = LightSettings(sun=(10.0, 20.0), exposure=1.0, sky=False)
    light = light_from_args(_parse("--sun", "200,35.5", "--shadows", "off", "--tone", "linear"), base)
    assert light.sun == (200.0, 35.5) and not light.shadows and light.tone == "linear"
    assert light.exposure == 1.0 and not light.sky          # not given: the file's
    assert light_from_args(_parse(), base) == base
    assert light_from_args(_parse("--sky", "on", "--ssao", "on", "--exposure", "-1.5"), None) == \
        LightSettings(ssao=True, exposure=-1.5)
    assert light_from_args(_parse("--shadow-filter", "fast"), base) == base.replace(shadow_filter="fast")


@pytest.mark.parametrize("argv, says", [
    (("--sun", "10,95"), "light.sun[1]"), (("--sun", "10,-5"), "light.sun[1]"),
    (("--sun", "abc"), "AZ,EL"), (("--sun", "1,2,3"), "AZ,EL"), (("--sun", "nan,40"), "finite"),
    (("--sun", "400,40"), "light.sun[0]"), (("--exposure", "nan"), "light.exposure"),
    (("--exposure", "1e400"), "light.exposure"), (("--exposure", "11"), "light.exposure"),
    (("--exposure", "bright"), "stops"), (("--shadows", "yes"), "invalid choice"),
    (("--tone", "aces"), "invalid choice"), (("--shadow-filter", "pcf"), "invalid choice"),
])
def test_bad_light_options_exit_2(argv, says, capsys):
    p = argparse.ArgumentParser(prog="leafview scene")
    add_light_arguments(p)
    with pytest.raises(SystemExit) as exc:
        p.parse_args(list(argv))
    assert exc.value.code == 2
    assert says in capsys.readouterr().err


# -- a flat leaf against the twin ---------------------------------------------------------------
def _flat_leaf() -> LeafParams:
    """The ovate preset's outline and colours, flat (no cupping, ripple, bending or veins)."""
    base = without_veins([LeafParams.load(builtin_presets()["ovate"])])[0]
    shape = dataclasses.replace(base.shape, zf=(0.0, 0.0, 0.0), zg=(0.0, 0.0, 0.0))
    return base.replace(shape=shape, ripple=dataclasses.replace(base.ripple, enabled=False), transform=Transform())


def _leaf_camera(params: LeafParams, size: tuple[int, int], below: bool = False) -> Camera:
    """Orthographic camera framing a leaf lying near z = 0: from above (looking down -z), or from
    below (turned over, looking up +z; the image is mirrored top to bottom)."""
    pts = leaf_surface.grid_points(params, DEFAULT_GRID)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    half = 0.55 * max(hi[1] - lo[1], (hi[0] - lo[0]) * size[1] / size[0])
    top = top_down((lo[:2] + hi[:2]) / 2, 1.0, half * size[0] / size[1], half, 2.0)
    if not below:
        return top
    view = top.view.copy()
    view[2, 3] = 1.0   # the eye at z = -1
    return Camera(np.diag([1.0, -1.0, -1.0, 1.0]) @ view, top.proj, np.array([0.0, 0.0, 1.0, 0.0]), False)


def _interior(gl, scene, camera) -> np.ndarray:
    """Pixels of the leaf's plain colour (not its midrib band, not an edge): from the unlit picture."""
    with SceneRenderer(gl.ctx, scene, resources=gl.resources) as r:
        flat = r.render(camera, SIZE, LEVEL0, samples=0, flat=True)
    inside = binary_erosion(flat[..., 3] == 255, iterations=3)
    rgb = flat[..., :3].reshape(-1, 3)
    values, counts = np.unique(rgb[inside.ravel()], axis=0, return_counts=True)
    mode = values[np.argmax(counts)]
    return inside & (np.abs(flat[..., :3].astype(int) - mode).max(axis=-1) <= 1)


@pytest.mark.parametrize("side, sun, tone", [("front", (135.0, 50.0), "filmic"), ("front", (300.0, 20.0), "linear"),
                                             ("back", (135.0, 50.0), "filmic"), ("back", (60.0, 75.0), "linear")])
def test_flat_leaf_matches_twin(gl, side, sun, tone):
    params = _flat_leaf()
    scene = single_leaf_scene(params)
    camera = _leaf_camera(params, SIZE, below=side == "back")
    light = PLAIN.replace(sun=sun, tone=tone, exposure=0.5)
    keep = _interior(gl, scene, camera)
    assert keep.sum() > 300
    with SceneRenderer(gl.ctx, scene, resources=gl.resources) as r, CanopyRenderer(r, light) as c:
        image = c.render(camera, SIZE, LEVEL0, samples=0)
    model = sky_model(light)
    n = np.array([0.0, 0.0, 1.0 if side == "front" else -1.0])
    albedo = np.asarray(params.material.front if side == "front" else params.material.back)
    linear = canopy_radiance(albedo, n, n, sun=model.sun, sun_irradiance=model.sun_irradiance,
                             sun_colour=model.sun_colour, sky_front=sh_irradiance(model, n),
                             sky_back=sh_irradiance(model, -n), translucency=params.material.translucency,
                             front=side == "front")
    want = tone_map(linear, light.exposure, tone) * 255.0
    got = image[keep][:, :3].astype(float)
    assert np.abs(got - want).max() <= TOL, (got.mean(axis=0), want)
    assert (image[keep][:, 3] == 255).all()


def test_backlight_glows_through_veins(gl):
    """From below, against the sun, a veined leaf shows its transmitted light, darker along veins."""
    params = LeafParams.load(builtin_presets()["ovate"])
    params = params.replace(ripple=dataclasses.replace(params.ripple, enabled=False), transform=Transform())
    scene = single_leaf_scene(params)
    size = (192, 144)
    camera = _leaf_camera(params, size, below=True)
    with SceneRenderer(gl.ctx, scene, resources=gl.resources) as r:
        lit = {}
        for t in (0.0, 1.0):
            with CanopyRenderer(r, PLAIN.replace(transmission=t, sun=(0.0, 90.0))) as c:
                lit[t] = c.render(camera, size, LEVEL0, samples=0).astype(float)
    mask = binary_erosion(lit[1.0][..., 3] == 255, iterations=3)
    gain = (lit[1.0] - lit[0.0])[mask][:, :3]
    assert gain[:, 1].mean() > 40                          # the sun shines through
    assert gain[:, 1].mean() > 1.8 * gain[:, 0].mean()     # ... green (the tint of eq. 1)
    assert np.percentile(gain[:, 1], 5) < 0.85 * np.percentile(gain[:, 1], 60)   # veins transmit less


def test_backlight_tint():
    rho = np.array([0.1, 0.3, 0.05])
    t = backlight_tint(rho)
    assert t @ LUMINANCE == pytest.approx(rho @ LUMINANCE)     # as bright as the reflection
    assert t[0] / t[1] < rho[0] / rho[1] and t[2] / t[1] < rho[2] / rho[1]   # deeper in colour
    assert np.allclose(backlight_tint(np.zeros(3)), 0.0)
    assert np.allclose(backlight_tint(np.full(3, 0.4)), 0.4)   # grey stays grey
    assert backlight_tint(np.array([1.0, 0.01, 0.01])).max() <= 1.0


# -- alpha to coverage --------------------------------------------------------------------------
def _teeth(n: int = 32) -> np.ndarray:
    yy, xx = np.mgrid[0:n, 0:n]
    img = np.zeros((n, n, 4), np.uint8)
    img[..., :3] = (60, 140, 40)
    s, t = (xx + 0.5) / n, (yy + 0.5) / n
    img[..., 3] = np.where(np.abs(s - 0.5) < 0.18 + 0.12 * np.abs(((t * 5) % 1.0) - 0.5), 255, 0)
    return img


def test_alpha_to_coverage_softens_texture_margins(gl, tmp_path):
    write_image(tmp_path / "teeth.png", _teeth())
    params = _flat_leaf().replace(texture=with_folder(LeafTexture("teeth.png", ""), tmp_path))
    scene = single_leaf_scene(params)
    camera = _leaf_camera(params, SIZE)
    partial = {}
    with SceneRenderer(gl.ctx, scene, resources=gl.resources) as r:
        for a2c in (False, True):
            with CanopyRenderer(r, PLAIN.replace(alpha_to_coverage=a2c)) as c:
                alpha = c.render(camera, SIZE, LEVEL0, samples=4)[..., 3]
            partial[a2c] = int(((alpha > 20) & (alpha < 235)).sum())
            covered = int((alpha > 127).sum())
            partial.setdefault("covered", covered)
            assert abs(covered - partial["covered"]) < 0.05 * covered   # the same leaf, the same area
    # without it only the geometric outline is antialiased; with it the texture's teeth are too
    assert partial[True] > 1.5 * partial[False], partial


# -- shadows on a plant -------------------------------------------------------------------------
def test_shadows_darken_a_plant(gl):
    """The issue's goal: in a 3,000-leaf plant seen from the default three-quarter camera under the
    default sun, shadows darken by more than 20 % at least 15 % of the leaf pixels."""
    scene = build_scene(SceneSpec(species=(LeafParams.load(builtin_presets()["ovate"]),), leaves=3000,
                                  layout="plant"))
    size = (256, 192)
    camera = scene_camera(scene, size)
    with SceneRenderer(gl.ctx, scene, resources=gl.resources) as r, CanopyRenderer(r) as c:
        shadowed = c.render(camera, size, samples=0)
        c.set_light(LightSettings(shadows=False))
        plain = c.render(camera, size, samples=0)
        c.set_light(PLAIN)
        leaves = c.render(camera, size, samples=0)[..., 3] == 255   # no sky, no ground: the leaves' mask
        c.set_light(LightSettings())
        again = c.render(camera, size, samples=0)
    assert np.array_equal(shadowed, again)
    with SceneRenderer(gl.ctx, scene, resources=gl.resources) as r, CanopyRenderer(r) as c, \
            RenderTarget(gl.ctx, size) as target:   # the viewer's path: into a bound framebuffer
        target.fbo.use()
        c.draw(camera, size)
        assert np.array_equal(target.read(), shadowed)
    assert (shadowed[..., 3] == 255).all()                  # sky and ground behind everything
    lum = lambda im: im[..., :3].astype(float) @ [0.2126, 0.7152, 0.0722]   # noqa: E731
    a, b = lum(shadowed)[leaves], lum(plain)[leaves]
    assert leaves.mean() > 0.05
    assert np.mean(a < 0.8 * b) >= 0.15
    assert (a <= b + 2).all()                               # shadows never brighten


def test_ambient_occlusion_only_darkens(gl):
    scene = build_scene(SceneSpec(species=(LeafParams.load(builtin_presets()["ovate"]),), leaves=1000,
                                  layout="plant", seed=2))
    size = (128, 96)
    camera = scene_camera(scene, size)
    with SceneRenderer(gl.ctx, scene, resources=gl.resources) as r, CanopyRenderer(r, PLAIN) as c:
        plain = c.render(camera, size, samples=0).astype(int)
        c.set_light(PLAIN.replace(ssao=True))
        occluded = c.render(camera, size, samples=0).astype(int)
    leaves = plain[..., 3] == 255
    assert np.array_equal(leaves, occluded[..., 3] == 255)
    drop = (plain - occluded)[..., :3].max(axis=-1)[leaves]
    assert (drop >= -2).all()              # the ambient term only loses light
    assert (drop > 3).mean() > 0.01        # ... somewhere


# -- reference images ---------------------------------------------------------------------------
@pytest.mark.parametrize("shadow_filter", ["soft", "fast"])
def test_reference_sun_and_shadow(gl, request, shadow_filter):
    """A 300-leaf plant in the default light: sun, shadows, sky and ground (looked at), with each
    shadow filter (the default "auto" is one or the other by renderer)."""
    scene = build_scene(SceneSpec(species=(LeafParams.load(builtin_presets()["ovate"]),), leaves=300,
                                  layout="plant", seed=4))
    size = (128, 96)
    with SceneRenderer(gl.ctx, scene, resources=gl.resources) as r, \
            CanopyRenderer(r, LightSettings(shadow_filter=shadow_filter)) as c:
        image = c.render(scene_camera(scene, size), size, samples=4)
    assert_matches_reference(image, "canopy_sun_shadow" + ("_fast" if shadow_filter == "fast" else ""), request)


def test_auto_shadow_filter_is_fast_on_a_cpu_rasteriser_only():
    cpu, gpu = "llvmpipe (LLVM 15.0.6, 256 bits)", "NVIDIA H200/PCIe/SSE2"
    assert resolve_shadow_filter("auto", cpu) == "fast" and resolve_shadow_filter("auto", gpu) == "soft"
    assert resolve_shadow_filter("soft", cpu) == "soft" and resolve_shadow_filter("fast", gpu) == "fast"
    auto = canopy_defines(LightSettings(), WindSettings(), cpu)
    assert auto == canopy_defines(LightSettings(shadow_filter="fast"), WindSettings(), gpu)
    assert auto["SHADOW_FAST"] == 1 and "SHADOW_FAST" not in canopy_defines(LightSettings(), WindSettings(), gpu)
    assert "SHADOW_FAST" not in canopy_defines(LightSettings(shadows=False), WindSettings(), cpu)


def test_reference_back_light(gl, request):
    """A veined leaf seen from below against a low sun: it glows, its veins dark (looked at)."""
    params = LeafParams.load(builtin_presets()["beech"])
    params = params.replace(ripple=dataclasses.replace(params.ripple, enabled=False), transform=Transform())
    size = (128, 96)
    with SceneRenderer(gl.ctx, single_leaf_scene(params), resources=gl.resources) as r, \
            CanopyRenderer(r, PLAIN.replace(sun=(90.0, 35.0), sky=True)) as c:
        image = c.render(_leaf_camera(params, size, below=True), size, LEVEL0, samples=4)
    assert_matches_reference(image, "canopy_back_light", request)
