"""Wind (leafview.deform.wind, shaders/leaf_wind.glsl, leafview.gpu.wind, leafview.cli.scene_anim):
the numpy twin's properties (still air moves nothing, the load grows with speed, the base stays,
the leaf keeps its length, leaves have their own phases, gusts travel downwind), the vertex
shader read back against the twin, the issue's silhouette goal, the culling padding, and the
animation writer."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
import pytest

from leafview.botany import leaf_surface
from leafview.cli.scene_anim import (
    add_wind_arguments,
    animation_kind,
    check_animation_output,
    wind_from_args,
    write_animation,
)
from leafview.core.params import Transform
from leafview.deform.surface import grid_uv
from leafview.deform.wind import (
    WindSettings,
    cull_bounds,
    displace,
    gust,
    leaf_load,
    leaf_phase,
    petiole_angle,
    wind_frame,
)
from leafview.errors import OutputPathError, ParamError, UsageError
from leafview.scene.spec import SceneSpec, build_scene
from tests.conftest import assert_matches_reference, require_or_skip

WINDY = WindSettings(speed=8.0, time=0.3, direction=30.0)


def _leaf(presets, name="ovate", n=(9, 17)):
    params = presets[name]
    uv = grid_uv(*n).astype(np.float64)
    return (leaf_surface.evaluate(params, uv[:, 0], uv[:, 1]),
            leaf_surface.normals(params, uv[:, 0], uv[:, 1]), uv)


def _models(k: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out = np.tile(np.eye(4), (k, 1, 1))
    for i in range(k):
        t = Transform(translation=tuple(rng.uniform(-3, 3, 3)), rotation=tuple(rng.uniform(-90, 90, 3)),
                      scale=float(rng.uniform(0.5, 2.0)))
        out[i] = t.matrix()
    return out


# -- numpy twin ---------------------------------------------------------------------------------
def test_settings_round_trip_and_bad_values():
    w = WindSettings(speed=6.0, direction=-45.0, time=2.5, beta=2.0, gust_length=3.0)
    assert WindSettings.from_dict(w.to_dict()) == w
    assert WindSettings.from_dict({}) == WindSettings()
    for key, value in (("speed", -1.0), ("speed", 61.0), ("time", float("nan")), ("gust_length", 0.0)):
        with pytest.raises(ParamError, match=f"wind.{key}"):
            WindSettings.from_dict({key: value})


def test_petiole_solves_eq4():
    rng = np.random.default_rng(0)
    a, th = rng.uniform(0, 40, 20000), rng.uniform(0, np.pi, 20000)
    phi = petiole_angle(a, th)
    assert np.abs(a * np.sin(th - phi) - phi).max() < 1e-9
    assert (phi >= 0).all() and (phi <= th).all()
    assert petiole_angle(0.0, 1.0) == 0.0


def test_still_air_moves_nothing_and_the_base_stays(presets):
    p, n, _ = _leaf(presets)
    models = _models(3)
    q, m = displace(np.stack([p] * 3), np.stack([n] * 3), models, [0, 1, 2], WindSettings(time=4.0))
    assert np.array_equal(q[0], p) and np.array_equal(m[0], n)
    base = np.flatnonzero(np.linalg.norm(p, axis=1) < 1e-12)
    assert base.size
    for speed in (2.0, 8.0, 30.0):
        q, _ = displace(np.stack([p] * 3), np.stack([n] * 3), models, [0, 1, 2], WINDY.replace(speed=speed))
        assert np.abs(q[:, base]).max() < 1e-12
        assert np.abs(q - p).max() > 1e-3


def test_displacement_grows_with_speed(presets):
    p, n, _ = _leaf(presets)
    k = 40
    models = _models(k, 1)
    mean = []
    for speed in (1.0, 2.0, 4.0, 8.0, 16.0):
        q, _ = displace(np.stack([p] * k), np.stack([n] * k), models, np.arange(k), WINDY.replace(speed=speed))
        mean.append(float(np.linalg.norm(q - p, axis=-1).mean()))
    assert all(b > a for a, b in zip(mean, mean[1:])), mean
    assert mean[0] < 0.02 and mean[3] > 0.1, mean


@pytest.mark.parametrize("name", ["ovate", "willow", "maize", "curled"])
def test_leaf_keeps_its_length(presets, name):
    v = np.linspace(0.0, 1.0, 81)
    u = np.zeros_like(v)
    params = presets[name]
    mid, nrm = leaf_surface.evaluate(params, u, v), leaf_surface.normals(params, u, v)
    length = np.linalg.norm(np.diff(mid, axis=0), axis=1).sum()
    k = 30
    models = _models(k, 2)
    for speed in (8.0, 20.0):
        for t in (0.0, 0.7, 13.0):
            q, _ = displace(np.stack([mid] * k), np.stack([nrm] * k), models, np.arange(k),
                            WINDY.replace(speed=speed, time=t))
            lengths = np.linalg.norm(np.diff(q, axis=1), axis=2).sum(axis=1)
            assert np.abs(lengths / length - 1).max() < 0.02, (name, speed, t)


def test_normals_follow_the_moved_surface(presets):
    """The twin's normals are those of its moved points: perpendicular to the moved grid's
    finite-difference tangents (up to the flutter's neglected curvature term)."""
    nu, nv = 41, 81
    p, n, _ = _leaf(presets, "ovate", (nu, nv))
    q, m = displace(p[None], n[None], _models(1, 3), [7], WINDY.replace(speed=12.0))
    def fd_normals(pts):
        g = pts.reshape(nv, nu, 3)
        fd = np.cross(g[1:-1, 2:] - g[1:-1, :-2], g[2:, 1:-1] - g[:-2, 1:-1])
        return fd / np.linalg.norm(fd, axis=-1, keepdims=True)

    inner = lambda a: a.reshape(nv, nu, 3)[1:-1, 1:-1]  # noqa: E731
    orient = np.sign(np.median(np.sum(fd_normals(p) * inner(n), axis=-1)))   # the grid's winding
    cos = orient * np.sum(fd_normals(q[0]) * inner(m[0]), axis=-1)
    assert np.median(cos) > 0.9999 and cos.min() > 0.98, (np.median(cos), cos.min())


def test_each_leaf_has_its_own_phase():
    f = wind_frame(WINDY)
    phases = leaf_phase(f, np.arange(1000))
    assert len(np.unique(np.round(phases, 6))) == 1000
    # two leaves at the same place (opposite leaves of a node) still move apart
    bases = np.zeros((2, 3))
    loads = np.array([leaf_load(WINDY.replace(time=t), bases, [4, 5]) for t in np.linspace(0, 5, 50)])
    assert np.abs(loads[:, 0] - loads[:, 1]).max() > 0.05


def test_a_gust_arrives_later_downwind():
    w = WindSettings(speed=8.0, direction=30.0, gust_length=2.0)
    heading = w.heading
    x0 = np.array([0.4, -0.3, 1.0])
    d = 5.0
    times = np.linspace(0.0, 4.0, 81)
    here = np.array([gust(w.replace(time=t), x0) for t in times])
    there = np.array([gust(w.replace(time=t + d / w.speed), x0 + d * heading) for t in times])
    assert np.allclose(here, there, atol=1e-9)           # the same gust, d / speed later
    across = np.array([gust(w.replace(time=t), x0 + d * np.array([-heading[1], heading[0], 0.0])) for t in times])
    assert np.allclose(here, across, atol=1e-9)          # a gust front is straight across the wind
    assert np.ptp(here) > 0.5                            # and it does vary


def test_cull_bounds_cover_the_motion(presets):
    p, n, _ = _leaf(presets)
    k = 60
    models = _models(k, 4)
    for w in (WINDY, WINDY.replace(speed=40.0, gust=2.0)):
        phi, km, fl = cull_bounds(w)
        s = np.linalg.norm(p, axis=1)
        psi = np.minimum(phi + km * s * (6 - 4 * s + s * s), np.pi)
        a = 3 * fl * s * s * (0.5 + s)
        bound = 2 * (s + a) * np.sin(psi / 2) + a
        for t in np.linspace(0, 30, 7):
            q, _ = displace(np.stack([p] * k), np.stack([n] * k), models, np.arange(k), w.replace(time=t))
            assert (np.linalg.norm(q - p, axis=-1) <= bound + 1e-9).all()
    assert cull_bounds(WindSettings()) == (0.0, 0.0, 0.0)


# -- the vertex shader, read back -------------------------------------------------------------------
@pytest.fixture(scope="module")
def windy_scene(_session_renderer):
    """A small two-species scene in three batches, with its own resources, and a WindUniforms."""
    from leafview.gpu.layout import LEAF_BLOCK
    from leafview.gpu.scene import SceneRenderer
    from leafview.gpu.wind import WindUniforms

    if isinstance(_session_renderer, str):
        require_or_skip(f"OpenGL 4.5 through EGL is unavailable: {_session_renderer}")
    from leafview.core.params import LeafParams
    from leafview.resources import resolve_preset

    species = tuple(LeafParams.load(resolve_preset(name)) for name in ("ovate", "maize"))
    scene = build_scene(SceneSpec(species=species, leaves=300, seed=3, plants=2))
    ctx = _session_renderer.ctx
    with SceneRenderer(ctx, scene, max_block_bytes=LEAF_BLOCK.nbytes * 128) as r:
        wind = WindUniforms(ctx)
        try:
            yield scene, r, wind
        finally:
            wind.release()


def test_single_leaf_readback_matches_the_twin(gl, presets):
    from leafview.gpu.wind import WindUniforms, wind_defines

    params = presets["ovate"].replace(transform=Transform(translation=(0.3, -0.2, 0.5), rotation=(20.0, 35.0, -60.0),
                                                          scale=1.7))
    uv = grid_uv(9, 17).astype(np.float64)
    wind = WindUniforms(gl.ctx)
    try:
        wind.set(WINDY)
        wind.bind()
        p0, n0 = gl.capture(params, uv[:, 0], uv[:, 1])
        p1, n1 = gl.capture(params, uv[:, 0], uv[:, 1], defines=wind_defines(WINDY))
        wind.set(WindSettings(time=0.3))
        wind.bind()
        p2, n2 = gl.capture(params, uv[:, 0], uv[:, 1], defines={"LEAF_WIND": 1})
    finally:
        wind.release()
    ref_p, ref_n = displace(p0[None], n0[None], params.transform.matrix().astype(np.float32)[None], [0], WINDY)
    assert np.abs(p1 - p0).max() > 0.05
    assert np.abs(p1 - ref_p[0]).max() < 1e-4
    assert np.abs(n1 - ref_n[0]).max() < 1e-4
    assert np.array_equal(p2, p0) and np.array_equal(n2, n0)   # still air: the variant moves nothing


def test_scene_readback_matches_the_twin(windy_scene):
    """Leaves of three batches (each leaf's phase from its scene index) at t = 0.3: the LEAF_WIND
    variant's transform feedback against the twin, within 1e-4 leaf lengths."""
    from leafview.gpu.wind import wind_defines

    scene, r, wind = windy_scene
    wind.set(WINDY)
    wind.bind(r)
    picks = [0, 5, 130, 200, 299]
    assert len({r.batches.index(b) for b in r.batches for i in picks if b.start <= i < b.start + b.count}) == 3
    still = r.capture(picks)
    moved = r.capture(picks, defines=wind_defines(WINDY))
    uv = grid_uv(*r.capture_grid(picks)).astype(np.float64)
    normals = np.stack([leaf_surface.normals(scene.leaf(i), uv[:, 0], uv[:, 1]) for i in picks])
    ref, _ = displace(still, normals, scene.matrices[picks].astype(np.float32), picks, WINDY)
    assert np.abs(moved - still).max() > 0.05
    err = np.abs(moved - ref).max()
    print(f"\nwind readback: largest difference {err:.2e} leaf lengths")
    assert err < 1e-4


def _frame(r, wind, camera, size, w):
    from leafview.gpu.scene import CullSettings
    from leafview.gpu.wind import wind_defines

    wind.set(w)
    wind.bind(r)
    target = r.resources.target(size, 0)
    target.use()
    r.ctx.viewport = (0, 0, *size)
    target.clear((0.0, 0.0, 0.0, 0.0))
    r.set_camera(camera, size)
    r.draw(CullSettings(), defines=wind_defines(w))
    return target.read(), int(r.level_counts().sum())


def test_wind_changes_the_silhouette(gl):
    """The issue's goal: wind at speed 8 between t = 0 and t = 0.7 changes 2-60 % of a plant's
    silhouette (XOR of the coverage masks over their union), with the same leaf count drawn."""
    from leafview.core.params import LeafParams
    from leafview.gpu.scene import SceneRenderer
    from leafview.gpu.wind import WindUniforms, set_cull_padding
    from leafview.resources import resolve_preset
    from leafview.scene.camera import scene_camera

    ctx = gl.ctx
    scene = build_scene(SceneSpec(species=(LeafParams.load(resolve_preset("ovate")),), leaves=600, seed=1,
                                  layout="plant"))
    size = (160, 160)
    camera = scene_camera(scene, size)
    with SceneRenderer(ctx, scene) as r:
        wind = WindUniforms(ctx)
        try:
            still, n_still = _frame(r, wind, camera, size, WindSettings())
            a, n_a = _frame(r, wind, camera, size, WindSettings(speed=8.0, time=0.0))
            b, n_b = _frame(r, wind, camera, size, WindSettings(speed=8.0, time=0.7))
            again, _ = _frame(r, wind, camera, size, WindSettings())
            set_cull_padding(r, None)
        finally:
            wind.release()
    ma, mb = a[..., 3] > 127, b[..., 3] > 127
    changed = float((ma ^ mb).sum() / (ma | mb).sum())
    print(f"\nwind 8, t = 0 -> 0.7: {changed:.1%} of the silhouette changes ({n_a} leaves drawn)")
    assert n_a == n_b == n_still == len(scene)
    assert 0.02 <= changed <= 0.60
    assert np.array_equal(still, again)


def test_reference_wind_frame(gl, request):
    """A plant in the wind at t = 0.3 (speed 8), 128 px: the wind frame's reference image."""
    from leafview.core.params import LeafParams
    from leafview.gpu.scene import SceneRenderer
    from leafview.gpu.wind import WindUniforms, set_cull_padding
    from leafview.resources import resolve_preset
    from leafview.scene.camera import scene_camera

    scene = build_scene(SceneSpec(species=(LeafParams.load(resolve_preset("beech")),), leaves=300, seed=4,
                                  layout="plant"))
    size = (128, 128)
    with SceneRenderer(gl.ctx, scene, veins=False) as r:
        wind = WindUniforms(gl.ctx)
        try:
            image, _ = _frame(r, wind, scene_camera(scene, size), size, WINDY)
            set_cull_padding(r, None)
        finally:
            wind.release()
    assert_matches_reference(image, "wind_plant", request)


def test_culling_pads_for_the_wind(windy_scene):
    from leafview.gpu.scene import CullSettings
    from leafview.gpu.wind import set_cull_padding
    from leafview.scene.camera import top_down

    scene, r, wind = windy_scene
    size = (96, 96)
    lo, hi = scene.bounds()
    # a window over the middle third of the scene: many leaves straddle its edges
    mid = (lo + hi) / 2
    camera = top_down(mid[:2], hi[2] + 1.0, (hi[0] - lo[0]) / 6, (hi[1] - lo[1]) / 6, hi[2] - lo[2] + 2.0)
    target = r.resources.target(size, 0)   # a framebuffer to draw into (EGL has no default one)
    target.use()
    r.set_camera(camera, size)
    try:
        set_cull_padding(r, None)
        r.draw(CullSettings())
        plain = r.levels()
        set_cull_padding(r, WindSettings(speed=20.0))
        r.draw(CullSettings())
        padded = r.levels()
    finally:
        set_cull_padding(r, None)
    r.draw(CullSettings())
    assert np.array_equal(r.levels(), plain)                 # no wind: the still culling, unchanged
    assert ((plain >= 0) <= (padded >= 0)).all()             # padding only adds leaves
    assert np.array_equal(padded[plain >= 0], plain[plain >= 0])   # and keeps their levels
    assert (padded >= 0).sum() > (plain >= 0).sum() > 0
    assert r.ctx.error == "GL_NO_ERROR"


# -- the command line and the animation writer ---------------------------------------------------
def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(exit_on_error=True)
    add_wind_arguments(p)
    return p


def test_wind_arguments():
    args = _parser().parse_args(["--wind", "6", "--wind-dir", "90", "--time", "1.5"])
    w = wind_from_args(args, WindSettings(gust=0.3))
    assert (w.speed, w.direction, w.time, w.gust) == (6.0, 90.0, 1.5, 0.3)
    assert args.fps == 30.0
    assert wind_from_args(_parser().parse_args([]), WindSettings(speed=2.0)) == WindSettings(speed=2.0)
    for bad in (["--wind", "-1"], ["--wind", "nan"], ["--wind", "100"], ["--time", "-2"], ["--fps", "0"],
                ["--wind-dir", "x"]):
        with pytest.raises(SystemExit) as info:
            _parser().parse_args(bad)
        assert info.value.code == 2


def test_animation_outputs_are_checked_first(tmp_path):
    assert animation_kind(tmp_path / "a.mp4") == "mp4"
    assert animation_kind(tmp_path / "a.GIF") == "gif"
    assert animation_kind(str(tmp_path / "frames") + "/") == "frames"
    assert animation_kind(tmp_path) == "frames"
    with pytest.raises(UsageError, match="unknown animation type"):
        check_animation_output(tmp_path / "a.avi", 10)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    for bad in (blocker / "a.mp4", blocker / "frames"):
        with pytest.raises(OutputPathError):
            check_animation_output(bad, 10)
    calls = []
    with pytest.raises(UsageError):
        write_animation(tmp_path / "a.webm", 3, 30.0, lambda t: calls.append(t), [0.0, 0.1, 0.2], None)
    assert calls == []                                        # refused before any frame renders
    if os.geteuid() != 0:
        locked = tmp_path / "locked"
        locked.mkdir(0o500)
        with pytest.raises(OutputPathError):
            check_animation_output(locked / "a.mp4", 2)


def _fake(t: float) -> np.ndarray:
    img = np.zeros((36, 50, 4), np.uint8)
    img[..., 3] = 255
    img[..., 0] = int(t * 200) % 256
    x = int(t * 300) % 40
    img[8:20, x:x + 6, 1] = 255
    return img


@pytest.mark.parametrize("name", ["anim.mp4", "anim.gif", "frames/"])
def test_write_animation(tmp_path, name):
    import imageio_ffmpeg  # a dependency of the package (pyproject): never skipped
    out = str(tmp_path / name)
    times = [i / 24 for i in range(10)]
    ticks = []
    write_animation(out, 10, 24.0, _fake, times, ticks.append)
    assert sum(ticks) == 10
    if name.endswith("/"):
        files = sorted(os.listdir(out))
        assert files == [f"frame_{i:04d}.png" for i in range(10)]
        from leafview.export.images import read_image

        img, _ = read_image(Path(out) / "frame_0003.png")
        assert np.array_equal(img, _fake(times[3]))
    else:
        gen = imageio_ffmpeg.read_frames(out)
        meta = next(gen)
        frames = [np.frombuffer(f, np.uint8).reshape(36, 50, 3) for f in gen]
        assert tuple(meta["size"]) == (50, 36) and len(frames) == 10
        # the moving green bar is where it was drawn (lossy: a tolerance)
        assert frames[3][8:20, int(times[3] * 300) % 40 + 1:int(times[3] * 300) % 40 + 5, 1].mean() > 180
    assert [p for p in os.listdir(tmp_path) if ".part" in p] == []


@pytest.mark.parametrize("name", ["anim.mp4", "frames/"])
def test_a_failed_animation_leaves_nothing(tmp_path, name):
    def broken(t: float) -> np.ndarray:
        if t > 0.2:
            raise RuntimeError("render failed")
        return _fake(t)

    with pytest.raises(RuntimeError, match="render failed"):
        write_animation(str(tmp_path / name), 8, 10.0, broken, [i / 10 for i in range(8)], None)
    assert os.listdir(tmp_path) == []
