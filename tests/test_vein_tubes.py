"""Vein tubes (leafview.botany.vein_tubes, leafview.gpu.vein_tubes, shaders/vein_tube.vert): the
tubes swept in the vertex shader, read back through transform feedback, against the numpy twin on
a rippled, bent leaf with its vein-shape grid, and on a leaf folded along its midrib; the frame,
cap, taper and winding of the twin; the level of detail; and a close-up picture."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from leafview.botany.vein_tubes import (
    OFFSET,
    SIDE_BUCKETS,
    TubeSegments,
    ring_sides,
    strip_vertices,
    tube_lod,
    tube_radii,
    tube_segments,
    tube_vertices,
)
from leafview.botany.venation import vein_tree
from leafview.core.params import Bending, LeafParams
from leafview.core.venation import Venation
from leafview.deform.surface import evaluate, normals
from leafview.gpu.vein_tubes import VeinTubes
from leafview.scene.camera import Camera, look_at, top_down
from tests.conftest import assert_matches_reference

POS_TOL = 2e-5            # leaf lengths: float32 evaluation of the blade (tests/test_gpu_eval.py)
VENATION = Venation(enabled=True, secondaries=6, tertiary=8.0, midrib_width=0.02)
NO_VEINS = Venation()     # disabled: the blade without a vein-shape grid or vein shading


@dataclasses.dataclass(frozen=True)
class Curve:
    """A hand-made vein."""

    uv: np.ndarray
    points: np.ndarray
    order: int
    width: float


def _curve(params: LeafParams, uv: np.ndarray, order: int, width: float) -> Curve:
    return Curve(uv, evaluate(params, uv[:, 0], uv[:, 1]), order, width)


def _hand_veins(params: LeafParams) -> list[Curve]:
    """A midrib and three curved secondaries a side."""
    v = np.linspace(0.0, 1.0, 40)
    veins = [_curve(params, np.stack([np.zeros_like(v), v], 1), 1, 0.024)]
    t = np.linspace(0.0, 1.0, 20)
    for v0 in (0.25, 0.45, 0.65):
        for side in (1.0, -1.0):
            uv = np.stack([side * 0.8 * t, v0 + 0.22 * t ** 1.4 * (1.0 - v0)], 1)
            veins.append(_curve(params, uv, 2, 0.01))
    return veins


def _rippled_bent(presets) -> LeafParams:
    """The willow preset (rippled, bent) with a twist, and veins on."""
    p = presets["willow"]
    assert p.ripple.enabled
    bend = dataclasses.replace(p.bending, twist=0.4) if p.bending.active else Bending(load=0.4, twist=0.4)
    return p.replace(bending=bend, venation=VENATION)


def _bind_leaf(gl, params: LeafParams) -> None:
    """The leaf's state bound as LeafRenderer.draw leaves it (one tiny draw binds it)."""
    gl.set_leaf(params)
    gl.set_camera(top_down((0.0, 0.5), 2.0, 1.0, 1.0, 4.0), srgb=True)
    gl.resources.target((4, 4)).use()
    gl.draw((3, 3))


def _grid(gl) -> np.ndarray:
    """The vein-shape grid the GPU evaluated the single leaf with (its layer), for the twin."""
    fields = gl.leaf_veins.fields
    assert fields is not None and fields.grid is not None
    layer = int(np.asarray(fields.layers).reshape(-1)[0])
    g = fields.grid
    raw = np.frombuffer(g.read(), np.float32).reshape(g.layers, g.height, g.width, 4)
    return raw[layer].astype(np.float64)


# -- the numpy twin ------------------------------------------------------------------------------
def test_segments_cap_each_vein_and_taper_it_shut(presets):
    veins = _hand_veins(presets["ovate"])
    seg = tube_segments(veins)
    assert len(seg) == sum(len(v.uv) for v in veins)           # a cap, then one per step
    first = np.r_[0, np.cumsum([len(v.uv) for v in veins])[:-1]]
    np.testing.assert_array_equal(seg.a[first], seg.b[first])  # the cap: zero length ...
    assert (seg.r[first, 0] == 0.0).all()                       # ... from a zero-radius ring
    np.testing.assert_allclose(seg.r[first, 1], [v.width / 2 for v in veins], rtol=1e-6)
    last = np.r_[first[1:], len(seg)] - 1
    assert (seg.r[last, 1] == 0.0).all()                        # closed at the far end
    np.testing.assert_array_equal(seg.a[1:, :2][seg.vein[1:] == seg.vein[:-1]],
                                  seg.b[:-1, :2][seg.vein[1:] == seg.vein[:-1]])
    r = tube_radii(veins[0])
    assert (np.diff(r) <= 0).all() and r[0] == pytest.approx(0.012)
    assert seg.records().shape == (len(seg), 12)
    np.testing.assert_array_equal(seg.points, np.concatenate([v.points for v in veins]))
    np.testing.assert_allclose(seg.r[:, 1], np.concatenate([tube_radii(v) for v in veins]), rtol=1e-6)
    two = tube_segments([_curve(presets["ovate"], np.array([[0.0, 0.2], [0.3, 0.4]]), 2, 0.01)])
    d = np.array([0.3, 0.2]) / np.hypot(0.3, 0.2)
    np.testing.assert_allclose(two.b[:, 2:], [d, d], rtol=1e-6)
    assert len(tube_segments([_curve(presets["ovate"], np.array([[0.0, 0.2]]), 2, 0.01)])) == 0


def test_strip_faces_point_out_of_the_tube(presets):
    """Triangle-strip winding: every triangle's normal (alternate ones flipped, as GL does) points
    along the outward normals of its vertices, and the start caps face back along the vein: front
    faces are the outside."""
    params = presets["beech"]
    seg = tube_segments(_hand_veins(params)[:3])
    cap = seg.r[:, 0] == 0.0
    for sides in (3, 8):
        pos, nrm = tube_vertices(params, seg, sides)
        per = strip_vertices(sides)
        pos, nrm = pos.reshape(len(seg), per, 3), nrm.reshape(len(seg), per, 3)
        a, b, c = pos[:, :-2], pos[:, 1:-1], pos[:, 2:]
        face = np.cross(b - a, c - a)
        face[:, 1::2] *= -1.0
        real = np.linalg.norm(face, axis=-1) > 1e-12   # not the collapsed triangles at caps and tips
        outward = np.sum(face * (nrm[:, :-2] + nrm[:, 1:-1] + nrm[:, 2:]), axis=-1)
        body = ~cap & (seg.r[:, 1] > 0.0)
        assert real[body].all() and (outward[body] > 0).all()
        tip = seg.r[:, 1] == 0.0
        assert (outward[tip][real[tip]] > 0).all() and real[tip].any()
        ahead = pos[cap, 1::2].mean(axis=1) - pos[cap.nonzero()[0] + 1, 1::2].mean(axis=1)  # back along the vein
        back = np.einsum("nkd,nd->nk", face[cap], ahead)
        assert (back[real[cap]] > 0).all() and real[cap].any()
        np.testing.assert_allclose(np.linalg.norm(nrm, axis=-1), 1.0, atol=1e-12)


def test_tubes_sit_mostly_below_the_blade(presets):
    """Centre OFFSET radii below the blade along its normal (Hong 2005, ch. 6.1: veins protrude
    from the lower side): the ring reaches (1 - OFFSET) r above and (1 + OFFSET) r below."""
    params = presets["ovate"]
    veins = _hand_veins(params)
    seg = tube_segments(veins)
    sides = 12
    pos, _ = tube_vertices(params, seg, sides)
    pos = pos.reshape(len(seg), strip_vertices(sides), 3)[:, 1::2]   # the rings at each b point
    inner = seg.r[:, 1] > 0
    uv = seg.b[inner, :2].astype(np.float64)
    off = uv[:, 0] != 0.0                                             # away from the midrib crease
    L = evaluate(params, uv[off, 0], uv[off, 1])
    n = normals(params, uv[off, 0], uv[off, 1])
    height = np.einsum("nkd,nd->nk", pos[inner][off] - L[:, None, :], n)
    r = seg.r[inner, 1][off].astype(np.float64)
    top, bottom = height.max(axis=1) / r, -height.min(axis=1) / r
    reach = np.cos(np.pi / sides)              # a face, not a vertex, is centred on top and bottom
    np.testing.assert_allclose(top, reach - OFFSET, atol=1e-6)
    np.testing.assert_allclose(bottom, reach + OFFSET, atol=1e-6)


def test_midrib_frame_bisects_the_crease(presets):
    """The blade folds at the midrib (one-sided normals 40-50° apart on the 'linear' preset); the
    midrib tube's up direction is the bisector, so a symmetric leaf gets a symmetric midrib."""
    params = presets["linear"]
    v = np.linspace(0.2, 0.8, 13)
    plus, minus = normals(params, np.zeros_like(v), v), normals(params, np.full_like(v, -1e-30), v)
    assert np.degrees(np.arccos(np.clip(np.sum(plus * minus, 1), -1, 1))).max() > 20.0
    uv = np.stack([np.zeros_like(v), v], 1)
    seg = tube_segments([_curve(params, uv, 1, 0.02)])
    pos, _ = tube_vertices(params, seg, 4)
    rings = pos.reshape(len(seg), strip_vertices(4), 3)[1:-1, 1:-2:2]  # the four vertices at each b
    centre = rings.mean(axis=1)                                         # = L - OFFSET r n
    L = evaluate(params, seg.b[1:-1, 0], seg.b[1:-1, 1])
    up = (L - centre) / (OFFSET * seg.r[1:-1, 1:2].astype(np.float64))
    np.testing.assert_allclose(np.linalg.norm(up, axis=1), 1.0, atol=1e-9)
    assert np.abs(up[:, 0]).max() < 1e-9                                # no lean to either side


def test_ring_sides_follow_the_projected_width():
    assert list(ring_sides([0.5, 1.0, 2.0, 4.0, 6.0, 9.0, 15.0, 1000.0])) == [3, 3, 3, 4, 6, 8, 12, 12]
    assert set(ring_sides(np.linspace(0, 100, 50)).tolist()) <= set(SIDE_BUCKETS)


def test_lod_by_distance_detail_and_view(presets):
    params = presets["ovate"].replace(venation=VENATION)
    veins = vein_tree(params)
    pts = np.concatenate([v.points for v in veins])
    rad = np.concatenate([tube_radii(v) for v in veins])
    owner = np.concatenate([np.full(len(v.points), i) for i, v in enumerate(veins)])
    orders = np.array([v.order for v in veins])

    def sides(cam: Camera, size=(400, 300), detail=1.0) -> np.ndarray:
        return tube_lod(pts, rad, owner, len(veins), cam.proj @ cam.view, size, detail=detail)

    centre = evaluate(params, [0.0], [0.5])[0]
    far = sides(look_at(centre + [0, -3.0, 3.0], centre, 4 / 3, 0.1, 20.0))
    near = sides(look_at(centre + [0, -0.3, 0.3], centre, 4 / 3, 0.01, 20.0))
    fine = sides(look_at(centre + [0, -0.3, 0.3], centre, 4 / 3, 0.01, 20.0), detail=4.0)
    assert far[orders == 1].all() and not far[orders >= 3].any()      # the midrib only, from afar
    seen = near > 0                     # a close-up shows part of the leaf, finer
    assert (near[seen] >= far[seen]).all() and near[0] > far[0] and (seen & (orders >= 3)).any()
    assert not seen.all()
    assert (fine >= near).all() and fine.max() == SIDE_BUCKETS[-1]
    away = sides(look_at(centre + [0, -0.3, 0.3], centre + [5.0, 0, 0], 4 / 3, 0.01, 20.0))
    assert not away.any()                                               # looking elsewhere: nothing
    behind = sides(look_at(centre + [0, -0.3, 0.3], centre + [0, -1.0, 1.0], 4 / 3, 0.01, 20.0))
    assert not behind.any()
    ortho = sides(top_down(centre, 2.0, 0.6, 0.45, 4.0), (800, 600))
    assert ortho[orders == 1].all()


# -- the shader against the twin -----------------------------------------------------------------
@pytest.mark.gl
@pytest.mark.parametrize("sides", [3, 12])
def test_readback_matches_the_twin_on_a_rippled_bent_leaf(gl, presets, sides):
    params = _rippled_bent(presets)
    with VeinTubes(gl.ctx, params, resources=gl.resources) as tubes:
        _bind_leaf(gl, params)
        pos, nrm = tubes.capture(sides)
        ref_pos, ref_nrm = tube_vertices(params, tubes.segments, sides, vein_grid=_grid(gl))
    assert pos.dtype == np.float32 and pos.shape == (len(tubes.segments) * strip_vertices(sides), 3)
    np.testing.assert_allclose(pos, ref_pos, atol=POS_TOL)
    assert np.sum(nrm * ref_nrm, axis=1).min() > 1 - 1e-4
    # the tubes follow the deformation: the same veins on the flat, unbent leaf lie elsewhere
    flat = params.replace(ripple=dataclasses.replace(params.ripple, enabled=False), bending=Bending())
    moved = np.abs(tube_vertices(flat, tubes.segments, sides)[0] - ref_pos).max()
    assert moved > 100 * POS_TOL


@pytest.mark.gl
def test_readback_on_the_midrib_crease_and_one_sided_leaves(gl, presets):
    """u = 0 exactly: the second evaluation at the u < 0 side in GLSL as in the twin; a one-sided
    leaf (shape.half = ±1) keeps to its own side."""
    base = presets["linear"].replace(venation=NO_VEINS)
    for half in (0, 1, -1):
        params = base.replace(shape=dataclasses.replace(base.shape, half=half))
        v = np.linspace(0.0, 1.0, 25)
        t = np.linspace(0.0, 1.0, 9)
        side = -1.0 if half < 0 else 1.0
        veins = [_curve(params, np.stack([np.zeros_like(v), v], 1), 1, 0.02),
                 _curve(params, np.stack([side * 0.7 * t, 0.3 + 0.2 * t], 1), 2, 0.01),
                 _curve(params, np.stack([-side * 0.7 * t, 0.5 + 0.2 * t], 1), 2, 0.01)]
        with VeinTubes(gl.ctx, params, veins, resources=gl.resources) as tubes:
            _bind_leaf(gl, params)
            pos, nrm = tubes.capture(6)
            ref_pos, ref_nrm = tube_vertices(params, tubes.segments, 6)
        np.testing.assert_allclose(pos, ref_pos, atol=POS_TOL, err_msg=f"half {half}")
        assert np.sum(nrm * ref_nrm, axis=1).min() > 1 - 1e-4, f"half {half}"


# -- drawing -------------------------------------------------------------------------------------
def _closeup(params: LeafParams, size: tuple[int, int]) -> Camera:
    c = evaluate(params, [0.12], [0.5])[0]
    return look_at(c + np.array([0.2, -0.22, 0.22]), c, size[0] / size[1], 0.01, 5.0)


def _picture(gl, params: LeafParams, tubes: VeinTubes, cam: Camera, size: tuple[int, int], *,
             lod: float = 1.0) -> tuple[np.ndarray, int]:
    """The tubes alone, hidden where the blade (drawn into depth only) covers them."""
    gl.set_leaf(params)
    gl.set_camera(cam, srgb=True)
    target = gl.resources.target(size, 4)
    target.use()
    target.clear((0.0, 0.0, 0.0, 0.0))
    fbo = gl.ctx.fbo
    fbo.color_mask = (False, False, False, False)
    fbo.use()                     # moderngl applies the mask when the framebuffer is bound
    try:
        gl.draw((65, 129))
    finally:
        fbo.color_mask = (True, True, True, True)
        fbo.use()
    drawn = tubes.draw(gl.frame, lod=lod)
    return target.read(), drawn


@pytest.mark.gl
def test_closeup_picture(gl, presets, request):
    params = presets["beech"].replace(venation=NO_VEINS)   # hand-made veins on the plain blade
    size = (192, 144)
    with VeinTubes(gl.ctx, params, _hand_veins(params), resources=gl.resources) as tubes:
        img, drawn = _picture(gl, params, tubes, _closeup(params, size), size)
        assert drawn > 0 and tubes.buckets
        covered = img[..., 3] > 0
        assert 0.05 < covered.mean() < 0.6
        assert_matches_reference(img, "vein_tubes_closeup", request)


@pytest.mark.gl
def test_draws_fewer_vertices_further_away(gl, presets):
    """Whole-leaf views: fewer veins with fewer sides as the leaf shrinks, none at a few pixels;
    a close-up draws only what it sees, with finer rings."""
    params = presets["ovate"].replace(venation=VENATION)
    size = (160, 120)
    c = evaluate(params, [0.0], [0.5])[0]
    counts, buckets = [], []
    with VeinTubes(gl.ctx, params, resources=gl.resources) as tubes:
        for d in (0.25, 1.0, 4.0, 40.0):
            cam = look_at(c + d * np.array([0.0, -0.7, 0.7]), c, 4 / 3, 0.01, 100.0)
            img, drawn = _picture(gl, params, tubes, cam, size)
            assert drawn == sum(strip_vertices(s) * n for s, n in tubes.buckets.items())
            counts.append(drawn)
            buckets.append(dict(tubes.buckets))
        assert counts[1] > counts[2] > counts[3] == 0, counts
        assert max(buckets[0]) == SIDE_BUCKETS[-1] and max(buckets[0]) >= max(buckets[1]) > max(buckets[2])
        assert sum(buckets[0].values()) < sum(buckets[1].values())     # off-screen veins skipped
        assert gl.ctx.error == "GL_NO_ERROR"
    tubes.release()   # idempotent


@pytest.mark.gl
def test_empty_and_rebuilt(gl, presets):
    params = presets["ovate"].replace(venation=NO_VEINS)
    with VeinTubes(gl.ctx, params, [], resources=gl.resources) as tubes:
        assert len(tubes.segments) == 0
        assert tubes.capture(3)[0].shape == (0, 3)
        assert tubes.draw(_closeup(params, (64, 48)), size=(64, 48)) == 0
        tubes.set_veins(params, _hand_veins(params))
        assert isinstance(tubes.segments, TubeSegments) and len(tubes.segments) == 40 + 6 * 20
        tubes.update(params)                    # unchanged: kept
        assert len(tubes.segments) == 160
        veined = params.replace(venation=VENATION)
        tubes.update(veined)                    # changed: its own vein tree
        assert len(tubes.segments) == sum(len(v.uv) for v in vein_tree(veined))
        tubes.update(None)                      # veins switched off
        assert len(tubes.segments) == 0 and tubes.draw(_closeup(params, (64, 48)), size=(64, 48)) == 0
        tubes.update(params)                    # venation disabled: no tubes
        assert len(tubes.segments) == 0
    with VeinTubes(gl.ctx, resources=gl.resources) as tubes:   # as a renderer makes it, before a leaf
        assert tubes.leaf is None and len(tubes.segments) == 0
