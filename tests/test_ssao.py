"""Screen-space ambient occlusion (leafview.gpu.ssao against leafview.scene.ssao): the reconstruction
of view positions inverts the projection, the kernel is seeded, the GPU's occlusion equals the
numpy reference computed from the depth and normal images the pass drew, pixel for pixel, and the
occlusion behaves physically (an overlapped leaf darkens near the leaf above it, an isolated leaf
and an open plane do not)."""

from __future__ import annotations

import dataclasses

import moderngl
import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from leafview.core.params import LeafParams, Transform
from leafview.errors import ParamError
from leafview.gpu.aov import render_aovs
from leafview.gpu.scene import SceneRenderer
from leafview.gpu.shaders import build_program
from leafview.gpu.ssao import SsaoPass
from leafview.resources import resolve_preset
from leafview.scene.camera import Camera, look_at, scene_camera, top_down
from leafview.scene.spec import Scene, SceneSpec, build_scene, scene_from_leaves
from leafview.scene.ssao import (
    MAX_SAMPLES,
    SsaoSettings,
    ambient_occlusion,
    default_radius,
    ssao_kernel,
    view_positions,
)

SIZE = (160, 120)
AO_TOL = 0.02          # |GPU - numpy| per pixel (the texture is R16F: 2⁻¹¹ steps near 1) ...
AO_FRACTION = 0.995    # ... on at least this fraction of the drawn pixels (the background is exactly 1)
AO_TIGHT = 0.002       # 99th percentile of |GPU - numpy| over the drawn pixels


def _ovate() -> LeafParams:
    return LeafParams.load(resolve_preset("ovate"))


def _flat(scale: float = 1.0, at: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> LeafParams:
    """The ovate leaf with a flat cross-section and a flat axis, placed at ``at``."""
    base = _ovate()
    shape = dataclasses.replace(base.shape, zf=(0.0, 0.0, 0.0), zg=(0.0, 0.0, 0.0))
    return base.replace(shape=shape, transform=Transform(translation=at, scale=scale))


@pytest.fixture(scope="module")
def plant() -> Scene:
    return build_scene(SceneSpec(species=(_ovate(),), leaves=200, layout="plant"))


# -- the numpy reference ------------------------------------------------------------------------
def test_kernel_is_seeded_and_in_the_hemisphere():
    k, r = ssao_kernel(16, 7)
    k2, r2 = ssao_kernel(16, 7)
    np.testing.assert_array_equal(k, k2)
    np.testing.assert_array_equal(r, r2)
    assert not np.allclose(ssao_kernel(16, 8)[0], k)
    assert k.shape == (16, 3) and r.shape == (16, 2)
    lengths = np.linalg.norm(k, axis=1)
    assert (k[:, 2] > 0).all() and (lengths <= 1.0 + 1e-6).all() and lengths.max() > 0.8
    # one length per stratum of [0.1, 1]: the samples reach across the whole radius
    strata = np.floor((lengths - 0.1) / 0.9 * 16).astype(int)
    assert sorted(strata.tolist()) == list(range(16))
    np.testing.assert_allclose(np.linalg.norm(r, axis=1), 1.0, atol=1e-6)


@pytest.mark.parametrize("camera", [
    look_at((3.0, -4.0, 2.5), (0.2, 0.1, 0.3), 4 / 3, 0.5, 20.0),
    top_down((0.3, -0.2), 2.0, 1.6, 1.2, 4.0),
], ids=["perspective", "orthographic"])
def test_reconstruction_inverts_the_projection(camera: Camera):
    """Step 1: the view position rebuilt from a pixel's depth projects back to the pixel's centre,
    at that depth, with the camera's own matrices."""
    if camera.perspective:   # an off-centre frustum: the principal point moves
        camera = dataclasses.replace(camera, proj=camera.proj.copy())
        camera.proj[0, 2], camera.proj[1, 2] = 0.07, -0.05
    w, h = 40, 30
    rng = np.random.default_rng(3)
    depth = rng.uniform(1.0, 3.0, (h, w))
    pos = view_positions(depth, camera)
    clip = np.concatenate([pos, np.ones((h, w, 1))], axis=-1) @ camera.proj.T
    ndc = clip[..., :2] / clip[..., 3:]
    window = (ndc * 0.5 + 0.5) * (w, h)
    ys, xs = np.mgrid[0:h, 0:w]
    np.testing.assert_allclose(window[..., 0], xs + 0.5, atol=1e-9)
    np.testing.assert_allclose(window[..., 1], ys + 0.5, atol=1e-9)
    np.testing.assert_allclose(-pos[..., 2], depth)


@pytest.mark.parametrize("field, value", [("radius", 0.0), ("radius", float("nan")), ("samples", 0),
                                          ("samples", MAX_SAMPLES + 1), ("samples", 2.5), ("seed", -1),
                                          ("bias", 2.0), ("strength", float("inf"))])
def test_settings_refuse_bad_values(field, value):
    with pytest.raises(ParamError, match=rf"^ssao\.{field}: "):
        SsaoSettings(**{field: value})


def test_default_radius_is_half_the_median_leaf_length():
    m = np.repeat(np.eye(4)[None], 5, axis=0)
    for i, s in enumerate((0.5, 1.0, 2.0, 3.0, 40.0)):
        m[i, :3, :3] *= s
    assert default_radius(m) == pytest.approx(1.0)
    with pytest.raises(ValueError):
        default_radius(np.zeros((0, 4, 4)))


# -- the GPU pass against the reference ---------------------------------------------------------
@pytest.mark.gl
@pytest.mark.parametrize("view", ["three-quarter", "top"])
def test_gpu_matches_the_numpy_reference(gl, plant, view):
    """The AO texture is the frame's size and, from the depth and normal images the pass drew,
    equals :func:`ambient_occlusion` within 0.02 on at least 99.5 % of the drawn pixels, and within
    0.002 on 99 % of them; the background is exactly 1 (perspective: three-quarter; orthographic:
    top). The images are those of the label pass of leafview.gpu.aov."""
    camera = scene_camera(plant, SIZE, view)
    with SceneRenderer(gl.ctx, plant) as scene, SsaoPass(gl.ctx) as ssao:
        ssao.run(scene, camera, SIZE)
        assert ssao.texture is not None and ssao.texture.size == SIZE
        ao, depth, normal = ssao.read(), ssao.read_depth(), ssao.read_normal()
        labels = render_aovs(scene, camera, SIZE, ("depth", "normal"))
    np.testing.assert_array_equal(depth, labels.depth)
    np.testing.assert_array_equal(normal, labels.normal)
    assert ssao.radius == pytest.approx(default_radius(plant.matrices))
    reference = ambient_occlusion(depth, normal, camera, ssao.radius)
    drawn = depth > 0
    assert drawn.mean() > 0.05
    # the comparison means something: the plant occludes itself, the background is open
    assert (reference[drawn] < 0.8).sum() > 20 and (ao[~drawn] == 1.0).all()
    diff = np.abs(ao - reference)[drawn]
    close = diff <= AO_TOL
    assert close.mean() >= AO_FRACTION, f"{1 - close.mean():.2%} of leaf pixels differ by more than {AO_TOL}"
    # tighter than the brief's bound: all but 1 % within a few R16F steps (a 5 % change of the
    # strength or of the bias already fails this)
    assert np.percentile(diff, 99) <= AO_TIGHT, np.percentile(diff, 99)


# -- physical sanity ------------------------------------------------------------------------------
@pytest.mark.gl
def test_an_overlapped_leaf_darkens_near_the_leaf_above_it(gl):
    """Two flat leaves, one 0.05 (a tenth of the radius) above the other and overlapping it, and a
    third far from both, seen from above: the lower leaf's pixels within 2 px (one gap) of the upper
    leaf have a median AO below 0.8; the isolated and the upper leaf stay above 0.95."""
    gap = 0.05
    scene = scene_from_leaves([_flat(at=(0.0, 0.0, 0.0)), _flat(at=(0.35, 0.25, gap)), _flat(at=(2.0, 0.0, 0.0))])
    size = (128, 64)
    camera = top_down((1.2, 0.5), 1.0, 1.6, 0.8, 2.0)   # 0.025 world units per pixel
    with SceneRenderer(gl.ctx, scene) as renderer, SsaoPass(gl.ctx) as ssao:
        ssao.run(renderer, camera, size)
        ao = ssao.read()
        instance = render_aovs(renderer, camera, size, ("instance",)).instance
    assert ssao.radius == pytest.approx(0.5)
    lower, upper, isolated = (instance == k for k in (1, 2, 3))
    assert min(lower.sum(), upper.sum(), isolated.sum()) > 300
    near = lower & (distance_transform_edt(~upper) <= 2.0)
    assert near.sum() > 30
    assert np.median(ao[near]) < 0.8, np.median(ao[near])
    assert ao[isolated].min() > 0.95 and np.percentile(ao[upper], 1) > 0.95


@pytest.mark.gl
def test_an_open_plane_is_unoccluded(gl):
    """One large flat leaf seen obliquely in perspective (the reconstruction's slopes change across
    the image): AO ≥ 0.99 everywhere."""
    scene = scene_from_leaves([_flat(scale=6.0)])
    camera = look_at((0.0, -5.0, 4.0), (0.0, 3.0, 0.0), SIZE[0] / SIZE[1], 0.5, 30.0)
    with SceneRenderer(gl.ctx, scene) as renderer, SsaoPass(gl.ctx) as ssao:
        ssao.run(renderer, camera, SIZE)
        ao, depth = ssao.read(), ssao.read_depth()
    drawn = depth > 0
    assert drawn.mean() > 0.3 and np.ptp(depth[drawn]) > 3.0
    assert ao.min() >= 0.99, ao.min()


# -- binding, defines, resources ----------------------------------------------------------------
_PROBE_VERT = """#version 450
void main() {
    vec2 corner = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(corner * 2.0 - 1.0, 0.0, 1.0);
}
"""
_PROBE_FRAG = """#version 450
layout(binding = SSAO_UNIT) uniform sampler2D ambient_occlusion;
layout(location = 0) out float seen;
void main() { seen = texelFetch(ambient_occlusion, ivec2(gl_FragCoord.xy), 0).r; }
"""


@pytest.mark.gl
def test_the_result_is_bound_at_the_ssao_unit_pixel_for_pixel(gl, plant, tmp_path):
    """What leaf.frag's LEAF_SSAO reads (texelFetch at gl_FragCoord from the sampler at SSAO_UNIT)
    is the pass's result, pixel for pixel; the caller's framebuffer and viewport are bound again."""
    (tmp_path / "probe.vert").write_text(_PROBE_VERT)
    (tmp_path / "probe.frag").write_text(_PROBE_FRAG)
    ctx = gl.ctx
    camera = scene_camera(plant, SIZE, "three-quarter")
    prog = build_program(ctx, "probe.vert", "probe.frag", root=tmp_path)
    out = ctx.texture(SIZE, 1, dtype="f4")
    fbo = ctx.framebuffer([out])
    vao = ctx.vertex_array(prog, [])
    try:
        with SceneRenderer(ctx, plant) as scene, SsaoPass(ctx) as ssao:
            fbo.use()
            ctx.viewport = (0, 0, 50, 40)
            ssao.run(scene, camera, SIZE)
            assert ctx.fbo is fbo and tuple(ctx.viewport) == (0, 0, 50, 40)
            ctx.viewport = (0, 0, *SIZE)
            ctx.enable_only(moderngl.NOTHING)
            vao.render(moderngl.TRIANGLES, vertices=3)
            seen = np.frombuffer(out.read(), np.float32).reshape(SIZE[1], SIZE[0])[::-1]
            ao = ssao.read()
        assert ao.min() < 0.8
        np.testing.assert_array_equal(seen, ao)
    finally:
        for obj in (vao, fbo, out, prog):
            obj.release()
        ctx.detect_framebuffer(0).use()


@pytest.mark.gl
def test_extra_defines_reach_the_label_pass_and_release_is_clean(gl, plant, monkeypatch):
    """The caller's defines (e.g. LEAF_WIND) are merged into the label pass's; a new size remakes
    the images; release() frees them (twice is harmless) and reading afterwards is refused."""
    camera = scene_camera(plant, SIZE, "three-quarter")
    seen: list[dict] = []
    with SceneRenderer(gl.ctx, plant) as scene:
        draw = scene.draw

        def spy(settings=None, *, defines=None):
            seen.append(dict(defines or {}))
            return draw(settings, defines=defines)

        monkeypatch.setattr(scene, "draw", spy)
        ssao = SsaoPass(gl.ctx, SsaoSettings(radius=0.2, samples=8, seed=3))
        try:
            ssao.run(scene, camera, SIZE, {"LEAF_SSAO_PROBE_DEFINE": 1})
            assert seen == [{"LEAF_AOV": 1, "LEAF_SSAO_PROBE_DEFINE": 1}]
            assert ssao.radius == 0.2
            ssao.run(scene, camera, (64, 48))
            assert ssao.texture is not None and ssao.texture.size == (64, 48) and ssao.read().shape == (48, 64)
        finally:
            ssao.release()
            ssao.release()
    assert ssao.texture is None
    with pytest.raises(RuntimeError, match="nothing was run"):
        ssao.read()
