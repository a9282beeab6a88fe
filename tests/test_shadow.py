"""The sun's cascaded shadow maps: splits and cascade cameras (numpy), the depth atlas the GPU
draws against the leaves rasterised in numpy, ``sun_visibility`` of shaders/leaf_shadow.glsl
read back from a compute probe against :func:`leafview.scene.sun.visibility`, a leaf shadowing
the leaf below it, and no acne on a flat leaf lit at 45°."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from leafview.core.params import LeafParams, Transform
from leafview.errors import ParamError
from leafview.gpu.aov import render_aovs
from leafview.gpu.layout import READBACK_BINDING, SHADOW_BINDING, SHADOW_BLOCK, SHADOW_UNIT, shadow_defines
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.gpu.shaders import preprocess
from leafview.gpu.shadow import ShadowPass, shadow_record
from leafview.resources import resolve_preset
from leafview.scene import sun
from leafview.scene.camera import Camera, intrinsics, look_at, scene_camera
from leafview.scene.lighting import LightSettings
from leafview.scene.spec import Scene, SceneSpec, build_scene, scene_from_leaves

SIZE = (160, 120)
PROBE = """#version 450
layout(local_size_x = 64) in;
#include "generated/frame_block.glsl"
#include "leaf_shadow.glsl"
layout(std430, binding = READBACK_BINDING) buffer Probe { vec4 data[]; };
uniform uint count;
void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec4 p = data[2u * i];
    data[2u * i + 1u].w = sun_visibility(p.xyz, data[2u * i + 1u].xyz, p.w);
}
"""


def _ovate() -> LeafParams:
    return LeafParams.load(resolve_preset("ovate"))


def _view_depth(camera: Camera, pts: np.ndarray) -> np.ndarray:
    return -(pts @ camera.view[:3, :3].T + camera.view[:3, 3])[:, 2]


def _probe(ctx, pts: np.ndarray, normals: np.ndarray, depth: np.ndarray, shadow_filter: str = "soft") -> np.ndarray:
    """sun_visibility() of the bound shadow maps at the points, from a compute shader reading them
    with ``shadow_filter``."""
    defines = {k: v for k, v in shadow_defines(True, shadow_filter).items() if k != "LEAF_SHADOWS"}
    shader = ctx.compute_shader(preprocess("shadow_probe.comp", defines=defines,
                                           extra={"shadow_probe.comp": PROBE}).text)
    data = np.zeros((len(pts), 2, 4), np.float32)
    data[:, 0, :3], data[:, 0, 3], data[:, 1, :3] = pts, depth, normals
    buf = ctx.buffer(data.tobytes())
    try:
        buf.bind_to_storage_buffer(READBACK_BINDING)
        shader["count"] = len(pts)
        shader.run(group_x=-(-len(pts) // 64))
        ctx.memory_barrier()
        return np.frombuffer(buf.read(), np.float32).reshape(-1, 2, 4)[:, 1, 3].astype(np.float64)
    finally:
        buf.release()
        shader.release()


def _world_points(r: SceneRenderer, scene: Scene) -> np.ndarray:
    """(N, nverts, 3) world positions of every leaf's level-0 grid, as leaf.vert computes them."""
    local = r.capture(range(len(scene))).astype(np.float64)
    m = scene.matrices
    return np.einsum("nij,nvj->nvi", m[:, :3, :3], local) + m[:, None, :3, 3]


# -- numpy: splits and cascade cameras ------------------------------------------------------------
def test_practical_splits_blend_log_and_uniform():
    uniform = sun.cascade_splits(1.0, 101.0, 4, blend=0.0)
    log = sun.cascade_splits(1.0, 101.0, 4, blend=1.0)
    mixed = sun.cascade_splits(1.0, 101.0, 4)
    assert np.allclose(uniform, [1, 26, 51, 76, 101])
    assert np.allclose(log, 101.0 ** (np.arange(5) / 4))
    assert np.allclose(mixed, 0.75 * log + 0.25 * uniform)
    assert np.all(np.diff(mixed) > 0) and mixed[0] == 1.0 and mixed[-1] == 101.0


def test_cascade_count_automatic_and_checked():
    assert sun.cascade_count(10.0, 20.0) == 1
    assert sun.cascade_count(1.0, 30.0) == 2
    assert sun.cascade_count(0.1, 1000.0) == 4
    assert sun.cascade_count(10.0, 20.0, 3) == 3
    with pytest.raises(ParamError, match="light.cascades"):
        sun.cascade_count(1.0, 2.0, 5)


def _walker(bounds, size=(320, 240)) -> Camera:
    lo, hi = bounds
    c, e = (lo + hi) / 2, hi - lo
    return look_at((c[0], lo[1] - 0.1 * e[1], lo[2] + 0.3 * e[2]), (c[0], c[1], lo[2] + 0.2 * e[2]),
                   size[0] / size[1], 0.05, 4.0 * float(np.linalg.norm(e)), fov_deg=50.0)


BOX = (np.array([-10.0, -10.0, 0.0]), np.array([10.0, 10.0, 3.0]))
SUN = LightSettings().direction


@pytest.mark.parametrize("count", [0, 1, 2, 4])
def test_cascades_hold_the_scene(count):
    """Every cascade spans the whole receiver box in depth (every caster toward the sun is drawn),
    and covers in its square every scene point of its slice of the camera frustum."""
    cam = _walker(BOX)
    cas = sun.shadow_cascades(cam, BOX, SUN, 1024, count)
    assert cas.count == count if count else cas.count >= 3   # a walker's view: far / near > 100
    rlo, rhi = sun.receiver_bounds(BOX, SUN)
    corners = np.array([[x, y, z] for x in (rlo[0], rhi[0]) for y in (rlo[1], rhi[1]) for z in (rlo[2], rhi[2])])
    rng = np.random.default_rng(3)
    pts = rng.uniform(BOX[0], BOX[1], (20000, 3))
    clip_cam = pts @ (cam.proj @ cam.view)[:3, :3].T + (cam.proj @ cam.view)[:3, 3]
    w = -(pts @ cam.view[:3, :3].T + cam.view[:3, 3])[:, 2]
    in_view = np.all(np.abs(clip_cam[:, :2] / w[:, None]) <= 1.0, axis=1) & (w > 0)
    depth = _view_depth(cam, pts)
    starts = np.concatenate([[cas.near], cas.splits[:-1]])
    for k in range(cas.count):
        m = cas.matrices[k]
        z = (corners @ m[:3, :3].T + m[:3, 3])[:, 2]
        assert np.all(np.abs(z) <= 1.0), k
        mine = in_view & (depth >= starts[k]) & (depth <= cas.splits[k])
        c = pts[mine] @ m[:3, :3].T + m[:3, 3]
        assert np.all(np.abs(c[:, :2]) <= 1.0 + 1e-9), k
    # a view of the whole scene: one cascade, the whole scene box in its square
    whole = scene_camera(type("B", (), {"bounds": lambda self: BOX})(), (320, 240))
    one = sun.shadow_cascades(whole, BOX, SUN, 1024)
    assert one.count == 1
    c = corners @ one.matrices[0][:3, :3].T + one.matrices[0][:3, 3]
    assert np.all(np.abs(c) <= 1.0)


def test_texel_snapping_keeps_the_texels_in_place():
    """A small camera move keeps each cascade's size and moves its square by whole texels."""
    cam = _walker(BOX)
    a = sun.shadow_cascades(cam, BOX, SUN, 1024, 3)
    moved = look_at(np.linalg.inv(cam.view)[:3, 3] + (0.013, 0.021, 0.0),
                    np.linalg.inv(cam.view)[:3, 3] + (0.013, 0.021, 0.0) - np.linalg.inv(cam.view)[:3, 2],
                    320 / 240, 0.05, 4.0 * float(np.linalg.norm(BOX[1] - BOX[0])), fov_deg=50.0)
    b = sun.shadow_cascades(moved, BOX, SUN, 1024, 3)
    assert np.allclose(a.radii, b.radii)
    origin = np.array([0.0, 0.0, 0.0, 1.0])
    moved_any = False
    for k in range(3):
        ta, tb = ((m @ origin)[:2] * 0.5 * 1024 for m in (a.matrices[k], b.matrices[k]))
        shift = tb - ta
        assert np.allclose(shift, np.round(shift), atol=1e-6), (k, shift)
        moved_any |= bool(np.any(np.round(shift) != 0))
        assert np.allclose(a.matrices[k][:3, :3], b.matrices[k][:3, :3])
    assert moved_any   # the move was large enough to shift some cascade


def test_light_rotation_looks_down_the_sun():
    for s in (SUN, np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])):
        r = sun.light_rotation(s)
        assert np.allclose(r @ r.T, np.eye(3)) and np.isclose(np.linalg.det(r), 1.0)
        assert np.allclose(r[2], s / np.linalg.norm(s))


def test_shadow_record_layout():
    assert shadow_record(None)["params"][0] == 0.0
    cas = sun.shadow_cascades(_walker(BOX), BOX, SUN, 512, 2)
    rec = shadow_record(cas)
    assert rec.dtype == SHADOW_BLOCK.dtype
    assert np.allclose(rec["matrices"][1].T, cas.matrices[1]) and np.allclose(rec["matrices"][3].T, cas.matrices[1])
    assert np.allclose(rec["splits"], [*cas.splits, cas.splits[-1], cas.splits[-1]])
    assert np.allclose(rec["params"], (2, sun.DEPTH_BIAS, sun.NORMAL_OFFSET, 1 / 512))


# -- GL ------------------------------------------------------------------------------------------
@pytest.fixture
def plant(gl):
    spec = SceneSpec(species=(_ovate(),), leaves=50, layout="plant", seed=1, stems=False)
    scene = build_scene(spec)
    r = SceneRenderer(gl.ctx, scene, resources=gl.resources)
    yield scene, r
    r.release()


def _rasterise(world: np.ndarray, m: np.ndarray, tile: int, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest depth and leaf id at each texel centre of a tile from the leaves' triangles."""
    depth = np.full((tile, tile), np.inf)
    ids = np.full((tile, tile), -1)
    c = world @ m[:3, :3].T + m[:3, 3]
    xy = (c[..., :2] * 0.5 + 0.5) * tile - 0.5
    z = c[..., 2] * 0.5 + 0.5
    for leaf in range(len(world)):
        for t in tris:
            p, d = xy[leaf, t], z[leaf, t]
            x0, y0 = np.maximum(np.ceil(p.min(axis=0)).astype(int), 0)
            x1, y1 = np.minimum(np.floor(p.max(axis=0)).astype(int), tile - 1)
            if x1 < x0 or y1 < y0:
                continue
            gx, gy = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))
            (ax, ay), (bx, by), (cx, cy) = p
            area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
            if abs(area) < 1e-12:
                continue
            w1 = ((cx - bx) * (gy - by) - (cy - by) * (gx - bx)) / area
            w2 = ((ax - cx) * (gy - cy) - (ay - cy) * (gx - cx)) / area
            w3 = 1.0 - w1 - w2
            inside = (w1 >= 0) & (w2 >= 0) & (w3 >= 0)
            zz = w1 * d[0] + w2 * d[1] + w3 * d[2]
            sub = depth[y0:y1 + 1, x0:x1 + 1]
            near = inside & (zz < sub)
            sub[near] = zz[near]
            ids[y0:y1 + 1, x0:x1 + 1][near] = leaf
    return depth, ids


@pytest.mark.gl
def test_depth_atlas_matches_the_leaves(gl, plant):
    scene, r = plant
    from leafview.deform.surface import grid_indices

    sp = ShadowPass(gl.ctx)
    try:
        sp.settings = CullSettings(level=0)   # the grid the capture evaluates
        cam = scene_camera(scene, SIZE)
        sp.render(r, cam, SIZE, LightSettings(shadow_size=512, cascades=2))
        atlas = sp.read_depth()
        cas = sp.cascades
        assert cas is not None and atlas.shape == (512, 1024)
        world = _world_points(r, scene)
        tris = grid_indices(*r.grids[0]).reshape(-1, 3)
        for k in range(2):
            ref, ids = _rasterise(world, cas.matrices[k], 512, tris)
            got = atlas[:, 512 * k:512 * (k + 1)]
            # texels inside one leaf's footprint (edges follow GL's fill rules, not these)
            same = np.ones_like(ids, bool)
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    same &= np.roll(ids, (dy, dx), axis=(0, 1)) == ids
            interior = same & (ids >= 0)
            assert interior.sum() > 300, k
            err = np.abs(got[interior] - ref[interior])
            assert np.mean(err < 1e-4) > 0.99, (k, np.percentile(err, 99))
            assert np.all(got[ids < 0][::7] > 0.0)
            # nothing drawn where no leaf is, except at leaf edges
            empty = (ids < 0)
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    empty &= np.roll(ids, (dy, dx), axis=(0, 1)) < 0
            assert np.mean(got[empty] == 1.0) > 0.999, k
    finally:
        sp.release()


@pytest.mark.gl
@pytest.mark.parametrize("cascades,shadow_filter", [(1, "soft"), (3, "soft"), (3, "fast")])
def test_sun_visibility_matches_reference(gl, plant, cascades, shadow_filter):
    scene, r = plant
    sp = ShadowPass(gl.ctx)
    try:
        cam = scene_camera(scene, SIZE)
        sp.render(r, cam, SIZE, LightSettings(shadow_size=256, cascades=cascades))
        atlas = sp.read_depth()
        cas = sp.cascades
        assert cas is not None
        rng = np.random.default_rng(7)
        world = _world_points(r, scene).reshape(-1, 3)
        lo, hi = sun.receiver_bounds(scene.bounds(), LightSettings().direction)
        pts = np.vstack([world[rng.choice(len(world), 3000)] + rng.normal(0, 0.02, (3000, 3)),
                         rng.uniform(lo, hi, (2000, 3))])
        normals = rng.normal(size=pts.shape)
        depth = _view_depth(cam, pts)
        if cascades > 1:   # spread over every cascade and its fade
            depth = rng.uniform(cas.near, cas.splits[-1] * 1.05, len(pts))
        got = _probe(gl.ctx, pts, normals, depth, shadow_filter)
        ref = sun.visibility(pts, normals, depth, atlas, cas.matrices, cas.splits, cas.tile,
                             shadow_filter=shadow_filter)
        assert np.mean(ref < 0.5) > 0.02 and np.mean(ref > 0.99) > 0.3   # shadow and light to compare
        assert 0.02 < np.mean((ref > 0.01) & (ref < 0.99))   # and penumbrae
        err = np.abs(got - ref)
        assert np.mean(err < 1e-3) > 0.99, np.percentile(err, 99)
        # at most one tap of nine flips (float32 against float64); for "fast" one texel of four
        assert err.max() < (0.12 if shadow_filter == "soft" else 0.5), err.max()
        if shadow_filter == "fast":   # not the soft filter's values: the test tells them apart
            soft = sun.visibility(pts, normals, depth, atlas, cas.matrices, cas.splits, cas.tile)
            assert np.mean(np.abs(soft - ref) > 0.05) > 0.01
    finally:
        sp.release()


@pytest.mark.gl
def test_shadows_off_light_everything(gl, plant):
    scene, r = plant
    sp = ShadowPass(gl.ctx)
    try:
        cam = scene_camera(scene, SIZE)
        sp.render(r, cam, SIZE, LightSettings(shadows=False))
        pts = _world_points(r, scene).reshape(-1, 3)[::5]
        vis = _probe(gl.ctx, pts, np.tile((0.0, 0.0, 1.0), (len(pts), 1)), _view_depth(cam, pts))
        assert np.all(vis == 1.0)
    finally:
        sp.release()


@pytest.mark.gl
@pytest.mark.parametrize("view", ["whole", "below"])
def test_leaf_shadows_the_leaf_below(gl, view):
    """Sun overhead, a leaf 0.3 above another and across it: the lower leaf's centre is in shadow,
    its tip in the sun; also seen from between the leaves, where the upper leaf is out of view
    (the sun's frustum, not the camera's, decides what casts)."""
    lower = _ovate()
    upper = lower.replace(transform=Transform(translation=(0.5, 0.45, 0.3), rotation=(0.0, 0.0, 90.0)))
    scene = scene_from_leaves([lower, upper])
    sp = ShadowPass(gl.ctx)
    try:
        with SceneRenderer(gl.ctx, scene, resources=gl.resources) as r:
            world = _world_points(r, scene)
            if view == "whole":
                cam = scene_camera(scene, SIZE)
            else:
                cam = look_at((0.0, 0.0, 0.12), (0.0, 0.45, 0.0), SIZE[0] / SIZE[1], 0.01, 3.0)
                clip = world[1] @ (cam.proj @ cam.view)[:3, :3].T + (cam.proj @ cam.view)[:3, 3]
                w = -(world[1] @ cam.view[:3, :3].T + cam.view[:3, 3])[:, 2]
                assert np.all((w <= 0) | np.any(np.abs(clip[:, :2]) > w[:, None], axis=1))   # out of view
            sp.render(r, cam, SIZE, LightSettings(sun=(0.0, 90.0), shadow_size=512))
            centre = world[0][np.argmin(np.linalg.norm(world[0][:, :2] - (0.0, 0.45), axis=1))]
            tip = world[0][np.argmin(np.linalg.norm(world[0][:, :2] - (0.0, 0.9), axis=1))]
            pts = np.array([centre, tip])
            vis = _probe(gl.ctx, pts, np.array([[0.0, 0.0, 1.0]] * 2), _view_depth(cam, pts))
        assert vis[0] < 0.2 and vis[1] > 0.99, vis
    finally:
        sp.release()


@pytest.mark.gl
def test_leaf_shadow_glsl_compiles_in_a_fragment_shader(gl):
    """leaf_shadow.glsl after the Frame block, in a fragment shader: its block and sampler sit at
    SHADOW_BINDING and SHADOW_UNIT."""
    vert = "#version 450\nin vec3 pos;\nvoid main() { gl_Position = vec4(pos, 1.0); }\n"
    frag = ("#version 450\n#include \"generated/frame_block.glsl\"\n#include \"leaf_shadow.glsl\"\nin vec3 v;\n"
            "out vec4 colour;\nvoid main() { colour = vec4(sun_visibility(v, vec3(0.0, 0.0, 1.0), "
            "-(frame.view * vec4(v, 1.0)).z)); }\n")
    vert = vert.replace("in vec3 pos;", "in vec3 pos;\nout vec3 v;").replace("gl_Position", "v = pos; gl_Position")
    prog = gl.ctx.program(vertex_shader=preprocess("v.vert", extra={"v.vert": vert}).text,
                          fragment_shader=preprocess("f.frag", extra={"f.frag": frag}).text)
    try:
        assert prog["Shadow"].binding == SHADOW_BINDING
        assert prog["sun_shadow"].value == SHADOW_UNIT
    finally:
        prog.release()


@pytest.mark.gl
@pytest.mark.parametrize("flat", [True, False])
def test_no_acne_on_a_leaf_lit_at_45_degrees(gl, flat):
    """Every pixel a lone leaf shows, lit by a sun 45° up, is lit: the bias and normal offset keep
    the leaf from shadowing itself (a flat leaf, and the ovate preset's slight curvature)."""
    leaf = _ovate()
    if flat:
        leaf = leaf.replace(shape=dataclasses.replace(leaf.shape, zf=(0.0, 0.0, 0.0), zg=(0.0, 0.0, 0.0)))
    scene = scene_from_leaves([leaf])
    sp = ShadowPass(gl.ctx)
    try:
        with SceneRenderer(gl.ctx, scene, resources=gl.resources) as r:
            cam = look_at((1.2, -1.0, 1.6), (0.0, 0.5, 0.0), 1.0, 0.5, 6.0)
            sp.render(r, cam, (200, 200), LightSettings(sun=(30.0, 45.0), shadow_size=512))
            aov = render_aovs(r, cam, (200, 200), ("depth", "normal"))
            mask = aov.depth > 0
            assert mask.sum() > 3000
            k, world_from_camera = intrinsics(cam, (200, 200))
            j, i = np.nonzero(mask)
            d = aov.depth[mask].astype(np.float64)
            x = np.linalg.solve(k, np.stack([i, j, np.ones_like(i)]).astype(np.float64)) * d
            pts = x.T @ world_from_camera[:3, :3].T + world_from_camera[:3, 3]
            vis = _probe(gl.ctx, pts, aov.normal[mask].astype(np.float64), d)
        assert np.mean(vis >= 0.99) >= 0.99, np.mean(vis >= 0.99)
    finally:
        sp.release()
