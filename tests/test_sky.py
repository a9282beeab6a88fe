"""The sky, ground and tone map of a canopy frame: the numpy model (leafview.scene.sky) against its
own definitions (SH irradiance of Ramamoorthi & Hanrahan 2001 against brute-force cosine
integration, the tone curve of Narkowicz 2015), and the shaders (sky_model.glsl, tonemap.glsl,
sky.frag, ground.frag) read back against the numpy twins."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyrr
import pytest

from leafview.errors import ParamError
from leafview.scene import sky
from leafview.scene.camera import Camera, look_at, top_down
from leafview.scene.lighting import LightSettings
from tests.conftest import assert_matches_reference

ROOT = Path(__file__).resolve().parent.parent
TOL = 2   # /255, GL against numpy


def _normals(n: int, seed: int = 7) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


# -- numpy ------------------------------------------------------------------------------------------
def test_constant_sky_gives_pi_l():
    dirs, w = sky.sphere_quadrature(64, 128)
    radiance = np.tile([0.3, 0.5, 0.9], (len(dirs), 1))
    sh = sky.project_sh(radiance, dirs, w)
    e = sky.irradiance(_normals(20), sh)
    np.testing.assert_allclose(e, np.broadcast_to(math.pi * np.array([0.3, 0.5, 0.9]), e.shape), rtol=1e-6)
    # a sky lit only from above: E(+z) = π L / 2 · 2 = π L (full hemisphere), E(−z) ≈ 0
    half = np.where(dirs[:, 2:3] > 0, 1.0, 0.0) * np.ones((1, 3))
    e = sky.irradiance(np.array([[0, 0, 1.0], [0, 0, -1.0]]), sky.project_sh(half, dirs, w))
    assert abs(e[0, 0] - math.pi) < 0.15 and abs(e[1, 0]) < 0.15


@pytest.mark.parametrize("elevation", [50.0, 30.0, 75.0])
def test_sh_irradiance_matches_brute_force(elevation):
    model = sky.sky_model(LightSettings(sun=(135.0, elevation)))
    dirs, w = sky.sphere_quadrature(160, 320)
    radiance = sky.sky_radiance(model, dirs)
    n = _normals(20)
    brute = np.einsum("kd,nk->nd", radiance * w[:, None], np.maximum(n @ dirs.T, 0.0))
    rel = np.abs(sky.irradiance(n, model.sh) - brute) / brute
    assert rel.max() < 0.05, rel.max()
    np.testing.assert_allclose(sky.sh_irradiance(model, n), sky.irradiance(n, model.sh) / math.pi)


def test_sky_model_shape():
    high, low = sky.sky_model(LightSettings(sun=(0.0, 60.0))), sky.sky_model(LightSettings(sun=(0.0, 5.0)))
    # the sun reddens towards the horizon; the sky brightens near the sun and towards the horizon
    assert low.sun_colour[0] / low.sun_colour[2] > 1.5 > high.sun_colour[0] / high.sun_colour[2]
    at = lambda m, d: sky.sky_radiance(m, np.array(d, float))  # noqa: E731
    assert at(high, high.sun)[2] > at(high, [-high.sun[0], 0, high.sun[2]])[2]
    assert at(high, [-1, 0, 0.05]).sum() > at(high, [-0.5, 0, 0.87]).sum()
    assert high.zenith.sum() > low.zenith.sum()
    # continuous across the horizon; far below it the ground of eq. (3)
    d = np.array([[0.6, 0.8, 1e-6], [0.6, 0.8, -1e-6]])
    r = sky.sky_radiance(high, d)
    np.testing.assert_allclose(r[0], r[1], rtol=1e-4)
    g = high.ground_albedo * (math.pi * high.sun_irradiance * high.sun_colour * high.sun[2]
                              + _sky_up(high)) / math.pi
    np.testing.assert_allclose(high.ground_radiance, g, rtol=1e-3)
    np.testing.assert_allclose(sky.sky_radiance(high, [0, 0, -1.0]), g, rtol=1e-3)


def _sky_up(model: sky.SkyModel) -> np.ndarray:
    dirs, w = sky.sphere_quadrature(200, 400)
    up = dirs[dirs[:, 2] > 0]
    return (sky.sky_radiance(model, up) * (up[:, 2] * w[dirs[:, 2] > 0])[:, None]).sum(axis=0)


@pytest.mark.parametrize("kind", ["filmic", "linear"])
def test_tone_map(kind):
    x = np.linspace(0.0, 50.0, 5001)
    y = sky.tone_map(x, 0.0, kind)
    assert y[0] == 0.0 and np.all(np.diff(y) >= 0.0) and y.max() <= 1.0
    assert sky.tone_map(np.array(-1.0), 0.0, kind) == 0.0
    np.testing.assert_allclose(sky.tone_map(x, 1.0, kind, srgb=False), sky.tone_map(2 * x, 0.0, kind, srgb=False))
    if kind == "filmic":   # Narkowicz's curve at 0.18 and its shoulder
        np.testing.assert_allclose(sky.tone_map(0.18, 0.0, kind, srgb=False), 0.18 * 0.4818 / (0.18 * 1.0274 + 0.14),
                                   rtol=1e-9)
        assert sky.tone_map(4.0, 0.0, kind, srgb=False) < 1.0
    with pytest.raises(ParamError, match="light.tone"):
        sky.tone_map(x, 0.0, "agx")


def test_sky_model_refuses_bad_input():
    with pytest.raises(ParamError, match="light.ground_albedo"):
        sky.sky_model(LightSettings(), ground_albedo=(0.2, 2.0, 0.1))


def test_contacts_of_a_field(presets):
    from leafview.scene.spec import SceneSpec, build_scene

    scene = build_scene(SceneSpec(species=(presets["ovate"],), layout="field", leaves=300, plants=6, seed=3))
    pts, radii = sky.contacts_of(scene)
    assert len(pts) == 6 and np.all(np.diff(radii) <= 0) and np.all(radii > 0)
    np.testing.assert_allclose(np.sort(pts[:, 0]), np.sort(scene.placement.plant_origins[:, 0]))
    assert len(sky.contacts_of(scene, limit=2)[0]) == 2
    assert sky.ground_height(scene) == pytest.approx(float(scene.placement.plant_origins[:, 2].min()))
    a = sky.contact_occlusion(np.array([pts[0], pts[0] + [100.0, 0, 0]]), pts, radii)
    assert a[0] < 0.5 and a[1] == pytest.approx(1.0)


def test_contact_grid_lists_every_near_contact():
    """The product over a pixel's grid cell equals the product over every contact."""
    rng = np.random.default_rng(4)
    pts = np.c_[rng.uniform(-5, 5, (120, 2)), np.zeros(120)]
    radii = rng.uniform(0.1, 0.6, 120)
    grid = sky.contact_grid(pts, radii)
    assert grid.kept.all() and grid.count.sum() <= sky.CONTACT_ITEMS
    p = np.c_[rng.uniform(-7, 7, (2000, 2)), np.zeros(2000)]
    cell = np.floor((p[:, :2] - grid.origin) * grid.inv_cell).astype(int)
    inside = ((cell >= 0) & (cell < sky.CONTACT_CELLS)).all(axis=1)
    full = sky.contact_occlusion(p, pts, radii)
    assert (full[~inside] == 1.0).all() and (full[inside] < 1.0).mean() > 0.3
    for q, (i, j) in zip(p[inside], cell[inside]):
        c = j * sky.CONTACT_CELLS + i
        mine = grid.items[grid.start[c]: grid.start[c] + grid.count[c]]
        assert sky.contact_occlusion(q, pts[mine], radii[mine]) == pytest.approx(sky.contact_occlusion(q, pts, radii))
    # a full list drops the later (smaller) contacts, never the first
    small = sky.contact_grid(pts, radii, capacity=64)
    assert small.kept[0] and not small.kept.all() and small.count.sum() <= 64


# -- GL -----------------------------------------------------------------------------------------
def _ortho_side(size) -> Camera:
    """An orthographic camera looking along +y, slightly down (sky and ground in view)."""
    base = look_at([0, -10, 1.5], [0, 0, 1.0], 1.0, 0.1, 50.0)
    proj = pyrr.matrix44.create_orthogonal_projection(-2.0, 2.0, -2.0 * size[1] / size[0], 2.0 * size[1] / size[0],
                                                      0.1, 50.0, dtype=np.float64).T
    fwd = -np.linalg.inv(base.view)[:3, 2]
    return Camera(base.view, proj, np.array([*fwd, 0.0]), False)


@pytest.fixture
def canopy_gl(gl):
    from leafview.gpu.light import LightUniforms
    from leafview.gpu.sky import GroundPass, SkyPass

    ctx = gl.ctx
    with LightUniforms(ctx) as light, SkyPass(ctx) as sky_pass, GroundPass(ctx) as ground:
        yield ctx, light, sky_pass, ground
    assert ctx.error == "GL_NO_ERROR"


def test_light_block_is_what_the_program_reflects(canopy_gl):
    from leafview.gpu.layout import LIGHT_BLOCK

    ctx, light, sky_pass, ground = canopy_gl
    for prog in (sky_pass.program, ground.program):
        assert prog["Light"].size == LIGHT_BLOCK.nbytes == len(light.buffer.read())
    settings = LightSettings(sun=(200.0, 30.0), sun_intensity=2.0, exposure=1.5, tone="linear", ssao=True,
                             transmission=0.5, gloss=1.5, sky=False)
    light.set(settings)
    light.set_ground_height(-0.25)
    rec = np.frombuffer(light.buffer.read(), LIGHT_BLOCK.dtype)[0]
    np.testing.assert_allclose(rec["sun"][:3], settings.direction, atol=1e-6)
    assert rec["sun"][3] == 2.0 and rec["ground"][3] == -0.25
    np.testing.assert_allclose(rec["tone"], (2 ** 1.5, 0.0, 0.5, 1.5))
    assert tuple(rec["flags"]) == (1, 1, 1, 0) and rec["sky_zenith"][3] == 0.0 and rec["sky_horizon"][3] == 1.0
    with pytest.raises(ParamError):
        light.set_ground_height(float("nan"))


def _read_sky(ctx, light, sky_pass, camera, size, settings):
    from leafview.gpu.targets import RenderTarget

    light.set(settings)
    light.bind()
    with RenderTarget(ctx, size) as target:
        target.use()
        target.clear()
        sky_pass.draw(camera, size)
        return target.read()


@pytest.mark.parametrize("view", ["perspective", "orthographic", "sunset"])
def test_sky_pass_matches_numpy(canopy_gl, view):
    from leafview.gpu.sky import view_rays

    ctx, light, sky_pass, _ = canopy_gl
    size = (64, 48)
    settings = LightSettings(sun=(135.0, 40.0), exposure=0.5)
    if view == "orthographic":
        camera = _ortho_side(size)
        settings = LightSettings(sun=(100.0, 10.0), tone="linear")
    elif view == "sunset":   # the sun's disc in view
        settings = LightSettings(sun=(90.0, 6.0), exposure=-1.0)
        camera = look_at([0, 0, 1], [0, 10, 1.6], size[0] / size[1], 0.1, 50, fov_deg=40)
    else:
        camera = look_at([3, -4, 1.0], [0, 0, 1.4], size[0] / size[1], 0.1, 50, fov_deg=70)
    img = _read_sky(ctx, light, sky_pass, camera, size, settings)
    _, d = view_rays(camera, size)
    model = sky.sky_model(settings)
    ref = np.round(255 * sky.tone_map(sky.sky_radiance(model, d, disc=True), settings.exposure, settings.tone))
    diff = np.abs(img[..., :3].astype(float) - ref).max(axis=-1)
    assert (img[..., 3] == 255).all()
    assert diff.max() <= TOL, (diff.max(), np.unravel_index(diff.argmax(), diff.shape))
    assert img[..., :3].std() > 3   # not a flat colour: a gradient (and, at sunset, the sun)
    if view == "sunset":
        assert (img[..., :3] >= 250).all(axis=-1).any()


def test_sh_irradiance_in_glsl(gl):
    """sky_model.glsl's sh_irradiance(n) written by a fragment shader for 16 × 8 normals, against numpy."""
    from leafview.gpu.light import LightUniforms
    from leafview.gpu.shaders import preprocess
    from leafview.gpu.targets import RenderTarget

    frag = """#version 450
#include "sky_model.glsl"
out vec4 frag_color;
void main() {
    float theta = gl_FragCoord.y / 8.0 * 3.14159265, phi = gl_FragCoord.x / 16.0 * 6.28318531;
    vec3 n = vec3(sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta));
    frag_color = vec4(sh_irradiance(n), 1.0);
}"""
    ctx = gl.ctx
    prog = ctx.program(vertex_shader=preprocess("sky.vert").text,
                       fragment_shader=preprocess("t.frag", extra={"t.frag": frag}).text)
    vao = ctx.vertex_array(prog, [])
    settings = LightSettings(sun=(60.0, 35.0))
    try:
        with LightUniforms(ctx) as light, RenderTarget(ctx, (16, 8), linear=True) as target:
            light.set(settings)
            light.bind()
            target.use()
            ctx.enable_only(0)
            vao.render(vertices=3)
            got = target.read()[::-1, :, :3]   # row 0 at the bottom, as gl_FragCoord
    finally:
        vao.release()
        prog.release()
    j, i = np.meshgrid(np.arange(8) + 0.5, np.arange(16) + 0.5, indexing="ij")
    theta, phi = j / 8 * math.pi, i / 16 * 2 * math.pi
    n = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)
    ref = sky.sh_irradiance(sky.sky_model(settings), n)
    np.testing.assert_allclose(got, np.maximum(ref, 0.0), rtol=1e-4, atol=1e-5)


def _ground_reference(model, points, contacts, radii, strength):
    a = sky.contact_occlusion(points, contacts, radii, strength)[..., None]
    e = model.sun_irradiance * model.sun_colour * max(model.sun[2], 0.0) + sky.sh_irradiance(model, [0, 0, 1.0])
    return model.ground_albedo * e * a


def test_ground_pass_top_view(canopy_gl):
    from leafview.gpu.sky import CONTACT_STRENGTH
    from leafview.gpu.targets import RenderTarget

    ctx, light, sky_pass, ground = canopy_gl
    size = (64, 64)
    settings = LightSettings(sun=(30.0, 55.0))
    light.set(settings)
    light.bind()
    rng = np.random.default_rng(2)
    others = np.c_[rng.uniform(-3, 0, (40, 2)), np.full(40, 0.2)]
    contacts = np.r_[[[0.5, -0.5, 0.2]], others]
    radii = np.r_[0.4, rng.uniform(0.05, 0.2, 40)]
    ground.set_contacts(contacts, radii)
    assert len(ground.contacts) == 41
    camera = top_down([0, 0], 5.0, 2.0, 2.0, 10.0)
    with RenderTarget(ctx, size) as target:
        target.use()
        target.clear()
        sky_pass.draw(camera, size)
        ground.draw(camera, ([-1, -1, 0.2], [1, 1, 2.0]))
        img = target.read()[..., :3].astype(float)
    ground.set_contacts(np.zeros((0, 3)), 1.0)
    with pytest.raises(ParamError, match="ground.contacts"):
        ground.set_contacts([[0, 0, 0]], [0.0])
    with pytest.raises(ParamError, match="ground.bounds"):
        ground.draw(camera, ([-1, -1, np.nan], [1, 1, 2.0]))
    xs = (np.arange(64) + 0.5) / 64 * 4 - 2
    points = np.stack([*np.meshgrid(xs, xs[::-1]), np.full((64, 64), 0.2)], axis=-1)
    model = sky.sky_model(settings)
    ref = 255 * sky.tone_map(_ground_reference(model, points, contacts, radii, CONTACT_STRENGTH))
    assert np.abs(img - np.round(ref)).max() <= TOL
    near = img[int((2 + 0.5) / 4 * 64), int((2 + 0.5) / 4 * 64)]   # under the contact (x 0.5, y −0.5)
    far = img[4, -4]
    assert near.mean() < 0.75 * far.mean()


def test_ground_writes_depth(canopy_gl):
    """The ground's depth is that of the plane z = h seen by the camera (clamped at the far plane)."""
    ctx, light, _, ground = canopy_gl
    size = (48, 32)
    camera = look_at([4, -6, 2.0], [0, 0, 0.5], size[0] / size[1], 0.5, 20.0)
    light.bind()
    depth = ctx.depth_texture(size)
    colour = ctx.renderbuffer(size, 4)
    fbo = ctx.framebuffer([colour], depth)
    try:
        fbo.use()
        fbo.clear(depth=1.0)
        ground.draw(camera, ([-1, -1, 0.0], [1, 1, 1.0]), size=size)
        got = np.frombuffer(depth.read(), np.float32).reshape(size[1], size[0])[::-1]
    finally:
        ctx.detect_framebuffer(0).use()
        fbo.release()
        colour.release()
        depth.release()
    from leafview.gpu.sky import view_rays

    o, d = view_rays(camera, size)
    t = (0.0 - o[..., 2]) / d[..., 2]
    hit = (d[..., 2] < 0) & (t > 0)
    p = o + t[..., None] * d
    clip = np.concatenate([p, np.ones(p.shape[:2] + (1,))], axis=-1) @ (camera.proj @ camera.view).T
    ref = np.clip(0.5 * clip[..., 2] / clip[..., 3] + 0.5, 0.0, 1.0)
    assert hit.mean() > 0.3 and (~hit).any()
    np.testing.assert_allclose(got[hit], ref[hit], atol=2e-4)
    assert (got[~hit] == 1.0).all()


def test_shadowed_ground_matches_numpy(canopy_gl, presets):
    """GroundPass(shadows=True): the sun's term times sun_visibility of leaf_shadow.glsl (its numpy
    twin leafview.scene.sun.visibility on the same depth atlas), the contacts on the ambient only."""
    from leafview.gpu.scene import SceneRenderer
    from leafview.gpu.shadow import ShadowPass
    from leafview.gpu.sky import CONTACT_STRENGTH, GroundPass
    from leafview.gpu.targets import RenderTarget
    from leafview.scene import sun
    from leafview.scene.spec import SceneSpec, build_scene

    ctx, light, _, _ = canopy_gl
    scene = build_scene(SceneSpec(species=(presets["ovate"],), leaves=400, seed=5))
    lo, hi = scene.bounds()
    z0 = sky.ground_height(scene)
    half = 0.5 * float(np.max(hi[:2] - lo[:2])) + 0.3
    centre = (lo[:2] + hi[:2]) / 2
    size = (64, 64)
    camera = top_down(centre, hi[2] + 1.0, half, half, hi[2] - z0 + 2.0)
    settings = LightSettings(sun=(120.0, 65.0), shadow_size=512, cascades=1)
    contacts, radii = sky.contacts_of(scene)
    shadows = ShadowPass(ctx)
    try:
        with SceneRenderer(ctx, scene) as r, GroundPass(ctx, shadows=True) as ground, \
                RenderTarget(ctx, size) as target:
            shadows.render(r, camera, size, settings)
            light.set(settings)
            light.bind()
            ground.set_contacts(contacts, radii)
            target.use()
            target.clear()
            ground.draw(camera, (lo, hi), height=z0, size=size)
            img = target.read()[..., :3].astype(float)
            atlas, cas = shadows.read_depth(), shadows.cascades
    finally:
        shadows.release()
    assert cas is not None
    xs = centre[0] + ((np.arange(64) + 0.5) / 64 * 2 - 1) * half
    ys = centre[1] + (1 - (np.arange(64) + 0.5) / 64 * 2) * half
    pts = np.stack([*np.meshgrid(xs, ys), np.full((64, 64), z0)], axis=-1).reshape(-1, 3)
    depth = hi[2] + 1.0 - z0
    vis = sun.visibility(pts, np.tile([0, 0, 1.0], (len(pts), 1)), np.full(len(pts), depth), atlas,
                         cas.matrices, cas.splits, cas.tile).reshape(64, 64, 1)
    model = sky.sky_model(settings)
    a = sky.contact_occlusion(pts, contacts, radii, CONTACT_STRENGTH).reshape(64, 64, 1)
    e = model.sun_irradiance * model.sun_colour * model.sun[2] * vis + sky.sh_irradiance(model, [0, 0, 1.0]) * a
    ref = np.round(255 * sky.tone_map(model.ground_albedo * e))
    assert np.mean(vis < 0.5) > 0.05 and np.mean(vis > 0.99) > 0.3   # shadow and light
    err = np.abs(img - ref).max(axis=-1)
    assert np.mean(err <= TOL) > 0.98, np.percentile(err, 99)
    shade, lit = img[vis[..., 0] < 0.2].mean(), img[(vis[..., 0] > 0.99) & (a[..., 0] > 0.99)].mean()
    assert shade < 0.8 * lit


def test_sky_and_ground_reference_image(canopy_gl, request):
    from leafview.gpu.targets import RenderTarget

    ctx, light, sky_pass, ground = canopy_gl
    size = (128, 96)
    light.set(LightSettings(sun=(-40.0, 35.0)))   # behind the camera: the blue side of the sky
    light.bind()
    ground.set_contacts([[0, 0, 0], [1.2, 0.6, 0]], [0.5, 0.35])
    camera = look_at([5, -7, 2.4], [0, 0, 0.6], size[0] / size[1], 0.1, 40.0, fov_deg=45)
    with RenderTarget(ctx, size) as target:
        target.use()
        target.clear()
        sky_pass.draw(camera, size)
        ground.draw(camera, ([-1, -1, 0], [1, 1, 1.5]), size=size)
        img = target.read()
    ground.set_contacts(np.zeros((0, 3)), 1.0)
    assert_matches_reference(img, "sky_ground_three-quarter", request)
