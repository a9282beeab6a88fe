"""The thumbnails' framing of a whole chunk in one numpy pass (frame_view_arrays) against the
framing of one point set at a time, and look_at_arrays (every perspective camera, look_at
included) against pyrr's look-at and perspective matrices, the arithmetic it restates."""

import numpy as np
import pyrr
import pytest

from leafview.scene.camera import (
    _ORBITS,
    FOV_DEG,
    VIEWS,
    Camera,
    _orbit_axes,
    frame_view,
    frame_view_arrays,
    frame_views,
    look_at,
    look_at_arrays,
)


def _pyrr_camera(eye, target, aspect, near, far, fov_deg=FOV_DEG) -> Camera:
    """The perspective camera as pyrr makes it (float64), the reference for look_at_arrays."""
    eye = np.asarray(eye, np.float64)
    view = pyrr.matrix44.create_look_at(eye, np.asarray(target, np.float64), np.array([0.0, 0.0, 1.0]),
                                        dtype=np.float64).T
    proj = pyrr.matrix44.create_perspective_projection(fov_deg, aspect, near, far, dtype=np.float64).T
    return Camera(view, proj, np.array([*eye, 1.0]), True)


def _one_at_a_time(view: str, pts: np.ndarray, size: tuple[int, int]) -> Camera:
    """The orbit framing of one point set as leafview computed it before the batch pass: the
    (N, 3) @ basis.T projection, three re-aims, then pyrr's matrices for the single camera."""
    w, h = size
    basis, tan_x, tan_y = _orbit_axes(*_ORBITS[view], w, h)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    center = (lo + hi) / 2
    cam = (pts - center) @ basis.T
    x, y, z = cam[:, 0], cam[:, 1], cam[:, 2]
    sx_, sy_ = 0.0, 0.0
    for _ in range(3):
        xs, ys = x - sx_, y - sy_
        dist = max(float(np.max(z + np.maximum(np.abs(xs) / tan_x, np.abs(ys) / tan_y))), 1e-6)
        depth = dist - z
        sx, sy = xs / depth, ys / depth
        sx_ += dist * (sx.max() + sx.min()) / 2
        sy_ += dist * (sy.max() + sy.min()) / 2
    xs, ys = x - sx_, y - sy_
    dist = max(float(np.max(z + np.maximum(np.abs(xs) / tan_x, np.abs(ys) / tan_y))), 1e-6)
    center = center + basis[0] * sx_ + basis[1] * sy_
    zmax = float(np.abs(z).max())
    eye = center + dist * basis[2]
    near, far = max(dist - zmax * 1.5 - 1e-3, dist * 1e-3), dist + zmax * 1.5 + 1e-3
    return _pyrr_camera(eye, center, w / h, near, far)


def test_look_at_is_pyrrs_camera():
    """look_at and look_at_arrays give pyrr's matrices to float64 rounding (the view's translation
    summed left to right, not by np.dot), the same float32 values, for cameras near and far."""
    rng = np.random.default_rng(5)
    eyes = rng.normal(size=(300, 3)) * rng.uniform(0.05, 80.0, size=(300, 1))
    targets = rng.normal(size=(300, 3))
    near, far = rng.uniform(1e-3, 0.5, 300), rng.uniform(5.0, 500.0, 300)
    for fov in (FOV_DEG, 50.0):
        views, projs, eyes4 = look_at_arrays(eyes, targets, 1.5, near, far, fov)
        for k in range(len(eyes)):
            ref = _pyrr_camera(eyes[k], targets[k], 1.5, near[k], far[k], fov)
            one = look_at(eyes[k], targets[k], 1.5, near[k], far[k], fov)
            for got, want in ((views[k], ref.view), (projs[k], ref.proj), (one.view, ref.view), (one.proj, ref.proj)):
                np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())
            np.testing.assert_array_equal(one.view, views[k])   # one camera or many: the same bits
            np.testing.assert_array_equal(eyes4[k], ref.eye)
            assert one.perspective


@pytest.mark.parametrize("view", [v for v in VIEWS if v != "top"])
def test_batch_cameras_are_look_at_cameras(view):
    """Each camera of the batch pass equals the one-at-a-time framing to float64 rounding, and
    what the GPU gets (float32 matrices and eye) is the same to a float32 step."""
    rng = np.random.default_rng(7)
    pts = (rng.normal(size=(11, 500, 3)) * rng.uniform(0.01, 2.0, size=(11, 1, 3))
           + rng.normal(size=(11, 1, 3))).astype(np.float32)   # float32, as the capture records them
    size = (96, 64)
    views, projs, eyes = frame_view_arrays(view, pts, size)
    assert views.shape == projs.shape == (11, 4, 4) and eyes.shape == (11, 4)
    for k in range(len(pts)):
        ref = _one_at_a_time(view, pts[k].astype(np.float64), size)
        for got, want in ((views[k], ref.view), (projs[k], ref.proj), (eyes[k], ref.eye)):
            np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())
            np.testing.assert_allclose(got.astype(np.float32), want.astype(np.float32), rtol=1.2e-7, atol=0)
        one = frame_view(view, pts[k], size)   # frame_view is the batch pass for one set
        np.testing.assert_array_equal(one.view, views[k])
        np.testing.assert_array_equal(one.proj, projs[k])


def test_batch_cameras_see_every_point():
    """Every point lands inside the image (clip space within ±1 and between the clip planes)."""
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(5, 400, 3)) * [1.0, 0.3, 0.05]
    views, projs, _ = frame_view_arrays("three-quarter", pts, (128, 128))
    for k in range(5):
        clip = np.c_[pts[k], np.ones(len(pts[k]))] @ (projs[k] @ views[k]).T
        ndc = clip[:, :3] / clip[:, 3:]
        assert np.abs(ndc).max() <= 1.0


def test_top_view_arrays_are_its_cameras():
    """The orthographic view's arrays are those of its cameras, one per set, and frame_views
    makes orthographic cameras of them."""
    pts = np.random.default_rng(1).normal(size=(3, 50, 3))
    views, projs, eyes = frame_view_arrays("top", pts, (64, 64))
    cams = frame_views("top", pts, (64, 64))
    assert views.shape == projs.shape == (3, 4, 4) and eyes.shape == (3, 4)
    for k, cam in enumerate(cams):
        assert not cam.perspective
        assert np.array_equal(cam.view, views[k]) and np.array_equal(cam.proj, projs[k])
        np.testing.assert_array_equal(cam.eye, [0.0, 0.0, -1.0, 0.0])
        ref = frame_view("top", pts[k], (64, 64))
        np.testing.assert_array_equal(ref.proj, projs[k])
    assert frame_view_arrays("top", pts[:0], (64, 64))[0].shape == (0, 4, 4)
