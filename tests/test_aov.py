"""Per-pixel ground truth (leafview.gpu.aov) against numpy: every labelled pixel's leaf, evaluated
at the read-back (u, v) with the numpy surface and placed by its matrix, must project into that
pixel with the OpenCV intrinsics, at the read depth, with the read normal; the ids are global
across batches; K agrees with the GL matrices."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import binary_erosion
from support.transforms import axis_rotation

from leafview.core.blade import normal_from
from leafview.core.params import Bending, LeafParams, Transform
from leafview.deform.beam import bend_profile
from leafview.deform.surface import drawn_uv, partials
from leafview.errors import GpuLimitError
from leafview.gpu.aov import AOV_NAMES, AovImages, render_aovs
from leafview.gpu.layout import LEAF_BLOCK, LEAF_OFFSET_UNIFORM
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.gpu.targets import AovTarget
from leafview.resources import builtin_presets
from leafview.scene.camera import Camera, intrinsics, look_at, scene_camera, top_down
from leafview.scene.spec import Scene, SceneSpec, evaluate_leaf

SIZE = (96, 72)
PIXEL_TOL = 0.75      # px from the pixel's centre, each axis
DEPTH_RTOL = 1e-3
NORMAL_TOL_DEG = 2.0
GRAZING_COS = 0.1     # normals are compared where the surface is not seen edge-on
RESOLVED_DEG = 4.0    # ... and, against the surface itself, where the grid resolves it


def _stem(a: np.ndarray, b: np.ndarray, radius: float, sides: int = 8):
    """A capless tube from ``a`` to ``b``: (positions, normals, triangles) as Scene.stems holds."""
    axis = (b - a) / np.linalg.norm(b - a)
    x = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(axis, x)
    t = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.cos(t)[:, None] * x + np.sin(t)[:, None] * y
    pos = np.concatenate([a + radius * ring, b + radius * ring]).astype(np.float32)
    nrm = np.concatenate([ring, ring]).astype(np.float32)
    k = np.arange(sides)
    k1 = (k + 1) % sides
    tris = np.concatenate([np.c_[k, k1, k + sides], np.c_[k1, k1 + sides, k + sides]]).astype(np.uint32)
    return pos, nrm, tris


@pytest.fixture(scope="module")
def scene() -> Scene:
    """Twelve overlapping leaves (ovate: flat; maize: rippled and bent), each with its own shape
    factors and tint, and a stem lying across them: large enough on a 96×72 image to test."""
    presets = {name: LeafParams.load(path) for name, path in builtin_presets().items()}
    species = tuple(presets[n].replace(transform=Transform()) for n in ("ovate", "maize"))
    n, variation = 12, 0.15
    spec = SceneSpec(species=species, leaves=n, variation=variation, colour_variation=0.1, stems=False)
    rng = np.random.default_rng(11)
    matrices = []
    for i in range(n):
        place = np.eye(4)
        place[:3, 3] = (0.55 * (i % 4), 0.6 * (i // 4), rng.uniform(0.0, 0.3))
        scale = np.diag([0.8, 0.8, 0.8, 1.0])
        matrices.append(place @ axis_rotation(2, rng.uniform(0, 2 * np.pi)) @ axis_rotation(0, rng.uniform(-0.6, 0.6))
                        @ scale)
    factors = (1.0 + variation * rng.uniform(-1.0, 1.0, (n, 21))).astype(np.float32)
    tint = (1.0 + 0.1 * rng.uniform(-1.0, 1.0, n)).astype(np.float32)
    stems = _stem(np.array([-0.5, 0.6, 0.5]), np.array([2.2, 0.6, 0.5]), 0.05)
    s = Scene(spec, species, (np.arange(n) % 2).astype(np.int32), factors, tint, np.stack(matrices), stems, None)
    assert s.varied
    return s


@pytest.fixture(scope="module")
def camera(scene) -> Camera:
    return scene_camera(scene, SIZE, "three-quarter")


@pytest.fixture
def renderer(gl, scene):
    with SceneRenderer(gl.ctx, scene) as r:
        yield r


def _leaf_partials(scene: Scene, i: int, u: np.ndarray, v: np.ndarray):
    """Partials of leaf ``i`` as the scene draws it (its own shape, the species' bend): the
    twin of :func:`leafview.scene.spec.evaluate_leaf` that also gives the normal."""
    own = scene.leaf(i)
    if not own.bending.active:
        return partials(own, u, v)
    sp = scene.species[int(scene.species_id[i])]
    return partials(own.replace(bending=Bending()), u, v, bend=bend_profile(sp))


def _project(camera: Camera, size: tuple[int, int], world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Image position (x right, y down, pixel (i, j) covering [i, i + 1) × [j, j + 1)) and depth
    along the optical axis of world points: with K for a perspective camera, with the GL
    matrices for an orthographic one."""
    if camera.perspective:
        k, world_from_camera = intrinsics(camera, size)
        cam = (world - world_from_camera[:3, 3]) @ world_from_camera[:3, :3]   # R^T (p - c)
        pix = cam @ k.T
        return pix[:, :2] / pix[:, 2:3] + 0.5, cam[:, 2]   # OpenCV puts pixel centres at integers
    w, h = size
    hom = np.c_[world, np.ones(len(world))]
    clip = hom @ (camera.proj @ camera.view).T
    ndc = clip[:, :3] / clip[:, 3:4]
    return np.c_[(ndc[:, 0] + 1) * w / 2, (1 - ndc[:, 1]) * h / 2], -(hom @ camera.view.T)[:, 2]


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.einsum("...j,...j->...", a, b), -1.0, 1.0)))


def _reference(scene: Scene, camera: Camera, size: tuple[int, int], out: AovImages,
               levels: np.ndarray, grids) -> dict[str, np.ndarray]:
    """Numpy twins of every leaf pixel's labels, from the leaf of its instance id at its (u, v):

    * ``surface``: the numpy surface at (u, v), placed by ``scene.matrices`` and projected:
      ``px`` (offset from the pixel's centre, each axis), ``depth`` (relative error), ``normal``
      (degrees to the read normal). The drawn triangles are chords of the surface, so these hold
      to a pixel fraction at the finest grid; the normal only where the grid resolves the surface
      (``resolved``: the drawn triangle's vertex normals within RESOLVED_DEG of each other; the
      normals are interpolated over the triangle, and the default grids resolve neither the midrib
      crease nor the ripples, which can fall between the vertices: rippled leaves are left out).
    * ``drawn``: the same from the drawn triangle (the leaf's level's grid, the triangle holding
      (u, v), its numpy vertices and vertex normals interpolated with the fragment's barycentric
      coordinates, which (u, v) gives): what the GPU interpolates, so it holds tightly at every
      level of detail.

    The visible side is the drawn triangle's (front when its world-space winding faces the camera)."""
    assert out.instance is not None and out.uv is not None and out.depth is not None and out.normal is not None
    rows, cols = np.nonzero(out.instance)
    ids = out.instance[rows, cols].astype(np.int64) - 1
    centre = np.c_[cols + 0.5, rows + 0.5]
    got_depth = out.depth[rows, cols].astype(np.float64)
    got_normal = out.normal[rows, cols].astype(np.float64)
    res = {key: np.empty(ids.size) for key in ("surface_px", "surface_depth", "surface_normal", "drawn_px",
                                               "drawn_depth", "drawn_normal", "facing")}
    res["resolved"] = np.zeros(ids.size, bool)
    eye_dir = np.linalg.inv(camera.view)[:3, 2]        # towards the camera (orthographic)
    for i in np.unique(ids):
        sel = np.flatnonzero(ids == i)
        leaf = scene.leaf(int(i))
        m = scene.matrices[i]
        uv = out.uv[rows[sel], cols[sel]].astype(np.float64)
        # the numpy surface at (u, v)
        p = _leaf_partials(scene, int(i), uv[:, 0], uv[:, 1])
        assert np.allclose(p.L, evaluate_leaf(scene, int(i), uv[:, 0], uv[:, 1]))
        world = p.L @ m[:3, :3].T + m[:3, 3]
        xy, z = _project(camera, size, world)
        res["surface_px"][sel] = np.abs(xy - centre[sel]).max(axis=1)
        res["surface_depth"][sel] = np.abs(got_depth[sel] - z) / z
        surface_normal = normal_from(p, uv[:, 1]) @ m[:3, :3].T
        # the drawn triangle: grid cell and half of the grid's (u, v) (before the one-sided map)
        nu, nv = grids[int(levels[i])]
        gu = 2.0 * uv[:, 0] - leaf.shape.half if leaf.shape.half else uv[:, 0]
        x = np.clip((gu + 1.0) / 2.0 * (nu - 1), 0, nu - 1)
        y = np.clip(uv[:, 1] * (nv - 1), 0, nv - 1)
        ci = np.minimum(x.astype(int), nu - 2)
        cj = np.minimum(y.astype(int), nv - 2)
        a, b = x - ci, y - cj
        lower = a + b <= 1.0        # grid_indices: (p00, p01, p10) and (p10, p01, p11)
        corners = np.where(lower[:, None, None], np.stack([np.c_[ci, cj], np.c_[ci, cj + 1], np.c_[ci + 1, cj]], 1),
                           np.stack([np.c_[ci + 1, cj], np.c_[ci, cj + 1], np.c_[ci + 1, cj + 1]], 1))
        weights = np.where(lower[:, None], np.c_[1 - a - b, b, a], np.c_[1 - b, 1 - a, a + b - 1])
        grid_u = corners[..., 0] / (nu - 1) * 2.0 - 1.0
        vert_uv = np.stack([grid_u, corners[..., 1] / (nv - 1)], -1).reshape(-1, 2)
        vert_uv = drawn_uv(leaf, vert_uv)
        vp = _leaf_partials(scene, int(i), vert_uv[:, 0], vert_uv[:, 1])
        vpos = (vp.L @ m[:3, :3].T + m[:3, 3]).reshape(-1, 3, 3)
        vnrm = (normal_from(vp, vert_uv[:, 1]) @ m[:3, :3].T).reshape(-1, 3, 3)
        vnrm /= np.linalg.norm(vnrm, axis=-1, keepdims=True)
        drawn = np.einsum("nk,nkj->nj", weights, vpos)
        xy, z = _project(camera, size, drawn)
        res["drawn_px"][sel] = np.abs(xy - centre[sel]).max(axis=1)
        res["drawn_depth"][sel] = np.abs(got_depth[sel] - z) / z
        to_eye = camera.eye[:3] - drawn if camera.perspective else np.broadcast_to(eye_dir, drawn.shape)
        face = np.cross(vpos[:, 1] - vpos[:, 0], vpos[:, 2] - vpos[:, 0])
        side = np.where(np.einsum("ij,ij->i", face, to_eye) >= 0, 1.0, -1.0)[:, None]
        res["drawn_normal"][sel] = _angle(side * np.einsum("nk,nkj->nj", weights, vnrm), got_normal[sel])
        res["surface_normal"][sel] = _angle(side * surface_normal, got_normal[sel])
        spread = np.maximum.reduce([_angle(vnrm[:, 0], vnrm[:, 1]), _angle(vnrm[:, 1], vnrm[:, 2]),
                                    _angle(vnrm[:, 0], vnrm[:, 2])])
        res["resolved"][sel] = (spread < RESOLVED_DEG) & (not leaf.ripple.enabled)
        e = to_eye / np.linalg.norm(to_eye, axis=1, keepdims=True)
        res["facing"][sel] = np.abs(np.einsum("ij,ij->i", surface_normal / np.linalg.norm(surface_normal, axis=1,
                                                                                          keepdims=True), e))
    return res


def _check_against_numpy(scene, camera, size, out, renderer, *, surface: bool) -> dict[str, float]:
    """Assert the tolerances; ``surface``: also against the numpy surface itself (finest grid)."""
    r = _reference(scene, camera, size, out, renderer.levels(), renderer.grids)
    assert r["drawn_px"].size > 150, "too few leaf pixels to test"
    errors = {key: float(r[key].max()) for key in ("drawn_px", "drawn_depth", "drawn_normal")}
    assert errors["drawn_px"] <= PIXEL_TOL, errors
    assert errors["drawn_depth"] <= DEPTH_RTOL, errors
    assert errors["drawn_normal"] <= NORMAL_TOL_DEG, errors
    if surface:
        resolved = r["resolved"] & (r["facing"] > GRAZING_COS)
        assert resolved.mean() > 0.2, resolved.mean()
        errors.update(surface_px=float(r["surface_px"].max()), surface_depth=float(r["surface_depth"].max()),
                      surface_normal=float(r["surface_normal"][resolved].max()),
                      resolved=float(resolved.mean()))
        assert errors["surface_px"] <= PIXEL_TOL, errors
        assert errors["surface_depth"] <= DEPTH_RTOL, errors
        assert errors["surface_normal"] <= NORMAL_TOL_DEG, errors
    return errors


def test_labels_match_the_numpy_surface(gl, renderer, scene, camera, capsys):
    """Finest grid: every leaf pixel's (u, v) on its leaf is inside the pixel, at the read depth,
    with the read normal, against the numpy surface itself and against the drawn triangle."""
    out = render_aovs(renderer, camera, SIZE, settings=CullSettings(lod=False))
    assert gl.ctx.error == "GL_NO_ERROR"
    errors = _check_against_numpy(scene, camera, SIZE, out, renderer, surface=True)
    with capsys.disabled():
        print(f"\nAOV vs numpy, perspective, finest grid: { {k: float(f'{v:.3g}') for k, v in errors.items()} }")


def test_labels_match_the_drawn_triangles_at_every_level_of_detail(gl, renderer, scene, camera, capsys):
    """Culling and LOD on (the levels the scene picks), then every level forced in turn: the
    labels are those of the drawn triangle (coarser grids are chords further from the surface)."""
    worst: dict[str, float] = {}
    for settings in (CullSettings(), *(CullSettings(level=k) for k in range(len(renderer.grids)))):
        out = render_aovs(renderer, camera, SIZE, ("instance", "depth", "normal", "uv"), settings=settings)
        assert gl.ctx.error == "GL_NO_ERROR"
        for key, value in _check_against_numpy(scene, camera, SIZE, out, renderer, surface=False).items():
            worst[key] = max(worst.get(key, 0.0), value)
    levels = renderer.levels()
    assert set(levels[levels >= 0].tolist()) == {len(renderer.grids) - 1}   # the last one forced
    with capsys.disabled():
        print(f"\nAOV vs drawn triangles, every level: { {k: float(f'{v:.3g}') for k, v in worst.items()} }")


def test_orthographic_depth_is_the_distance_from_the_camera_plane(gl, renderer, scene):
    lo, hi = scene.bounds()
    half = float(np.max(hi[:2] - lo[:2])) / 2 * 1.05
    z_top = hi[2] + 10.0   # the chords' depth error is absolute: relative 1e-3 needs some distance
    cam = top_down((lo[:2] + hi[:2]) / 2, z_top, half * SIZE[0] / SIZE[1], half, hi[2] - lo[2] + 20.0)
    out = render_aovs(renderer, cam, SIZE, ("instance", "depth", "normal", "uv"), settings=CullSettings(lod=False))
    assert gl.ctx.error == "GL_NO_ERROR"
    _check_against_numpy(scene, cam, SIZE, out, renderer, surface=True)
    # looking down -z from z_top: depth = z_top - world z
    leaf = out.instance > 0
    assert out.depth[leaf].min() > z_top - hi[2] - 0.5 and out.depth[leaf].max() < z_top - lo[2]


def test_instance_ids_stems_and_background(gl, renderer, scene, camera):
    out = render_aovs(renderer, camera, SIZE)
    assert out.rgb is not None and out.instance is not None and out.depth is not None
    assert out.rgb.shape == (*SIZE[::-1], 4) and out.rgb.dtype == np.uint8
    assert out.instance.shape == SIZE[::-1] and out.instance.dtype == np.uint32
    assert out.depth.dtype == np.float32 and out.normal.shape == (*SIZE[::-1], 3) and out.uv.shape == (*SIZE[::-1], 2)
    n = len(scene)
    ids = set(np.unique(out.instance).tolist()) - {0}
    assert ids and max(ids) <= n
    # every id is a leaf the culling pass drew
    drawn = set((np.flatnonzero(renderer.levels() >= 0) + 1).tolist())
    assert ids <= drawn
    leaf = out.instance > 0
    stem = (out.instance == 0) & (out.depth > 0)
    background = out.depth == 0
    assert stem.sum() > 20, "the stems should be labelled: depth, instance 0"
    assert not (background & leaf).any()
    assert (out.uv[~leaf] == 0).all() and (out.normal[background] == 0).all()
    assert np.allclose(np.linalg.norm(out.normal[~background], axis=-1), 1.0, atol=1e-5)
    # the picture and the labels cover the same pixels, edges aside (the MSAA samples are not at
    # the pixel's centre): labelled pixels away from an edge are drawn, fully covered pixels are
    # labelled, and off the labels at most a sample or two of thin slivers is covered
    alpha = out.rgb[..., 3]
    assert (alpha[binary_erosion(leaf | stem)] == 255).all()
    assert (~background)[alpha == 255].all()
    assert (alpha[binary_erosion(background)] <= 128).all()
    # the rgb is SceneRenderer.render's picture
    assert np.array_equal(out.rgb, renderer.render(camera, SIZE))
    assert gl.ctx.error == "GL_NO_ERROR"


def test_ids_are_global_across_batches(gl, scene, camera):
    """Four leaves a batch: in_leaf restarts at 0 in each, the ids must not."""
    with SceneRenderer(gl.ctx, scene) as one, \
            SceneRenderer(gl.ctx, scene, max_block_bytes=4 * LEAF_BLOCK.nbytes) as many:
        assert len(many.batches) == -(-len(scene) // 4) >= 3
        a = render_aovs(one, camera, SIZE, ("instance", "depth", "uv"))
        b = render_aovs(many, camera, SIZE, ("instance", "depth", "normal", "uv"))
        assert gl.ctx.error == "GL_NO_ERROR"
        assert np.array_equal(a.instance, b.instance)
        assert np.array_equal(a.depth, b.depth)
        ids = set(np.unique(b.instance).tolist()) - {0}
        assert any(k - 1 >= 8 for k in ids), "no leaf of the last batch is visible"
        _check_against_numpy(scene, camera, SIZE, b, many, surface=False)


def test_only_what_is_asked_for(gl, renderer, camera):
    out = render_aovs(renderer, camera, SIZE, ["instance"])
    assert out.instance is not None and out.rgb is out.depth is out.normal is out.uv is None
    out = render_aovs(renderer, camera, SIZE, ("rgb",), samples=0)
    assert out.rgb is not None and out.instance is None
    assert gl.ctx.error == "GL_NO_ERROR"


def test_unknown_aov_names_the_bad_name_and_the_valid_ones(gl, renderer, camera):
    with pytest.raises(ValueError) as info:
        render_aovs(renderer, camera, SIZE, ("depth", "albedo"))
    assert "'albedo'" in str(info.value)
    assert all(name in str(info.value) for name in AOV_NAMES)
    assert gl.ctx.error == "GL_NO_ERROR"


def test_every_leaf_program_variant_builds_with_the_label_outputs(gl):
    """Single leaf (v_leaf = 0), instanced (gl_InstanceID) and scene (batch offset + in_leaf)."""
    for defines in ({}, {"LEAF_INSTANCED": 1}, {"LEAF_INDIRECT": 1}):
        prog = gl.resources.leaf_program({"LEAF_AOV": 1, **defines})
        assert (LEAF_OFFSET_UNIFORM in list(prog)) == ("LEAF_INDIRECT" in defines)
    assert gl.ctx.error == "GL_NO_ERROR"


def test_label_target_sizes_are_checked_before_allocating(gl):
    with pytest.raises(GpuLimitError, match="size"):
        AovTarget(gl.ctx, (10**6, 8))
    with AovTarget(gl.ctx, (8, 4)) as target:
        target.use()
        target.clear()
        assert target.read("instance").shape == (4, 8) and target.read("normal").shape == (4, 8, 4)
        with pytest.raises(ValueError, match="rgb"):
            target.read("rgb")
    assert gl.ctx.error == "GL_NO_ERROR"


# -- intrinsics (numpy) ------------------------------------------------------------------------
@pytest.mark.parametrize("size", [(96, 72), (64, 128), (33, 17)])
def test_intrinsics_project_like_the_gl_matrices(scene, size):
    for view in ("three-quarter", "ground", "front"):
        cam = scene_camera(scene, size, view)
        k, world_from_camera = intrinsics(cam, size)
        assert k.dtype == world_from_camera.dtype == np.float64
        assert k[0, 1] == 0 and np.array_equal(k[2], [0, 0, 1])
        assert np.isclose(k[0, 2], (size[0] - 1) / 2) and np.isclose(k[1, 2], (size[1] - 1) / 2)   # centred
        r = world_from_camera[:3, :3]
        assert np.allclose(r.T @ r, np.eye(3)) and np.isclose(np.linalg.det(r), 1.0)
        assert np.allclose(world_from_camera[:3, 3], cam.eye[:3])
        rng = np.random.default_rng(7)
        lo, hi = scene.bounds()
        pts = rng.uniform(lo, hi, (200, 3))
        cam_pts = (pts - world_from_camera[:3, 3]) @ r
        pts = pts[cam_pts[:, 2] > 1e-3]
        cam_pts = cam_pts[cam_pts[:, 2] > 1e-3]
        pix = cam_pts @ k.T
        xy = pix[:, :2] / pix[:, 2:3] + 0.5   # OpenCV: pixel centres at integers; GL: at i + 0.5
        clip = np.c_[pts, np.ones(len(pts))] @ (cam.proj @ cam.view).T
        ndc = clip[:, :2] / clip[:, 3:4]
        gl_xy = np.c_[(ndc[:, 0] + 1) * size[0] / 2, (1 - ndc[:, 1]) * size[1] / 2]
        assert np.allclose(xy, gl_xy, rtol=0, atol=1e-9 * max(size))
        # z of the camera coordinates is -z in view space (the depth AOV)
        view_z = (np.c_[pts, np.ones(len(pts))] @ cam.view.T)[:, 2]
        assert np.allclose(cam_pts[:, 2], -view_z)


def test_intrinsics_of_an_off_centre_projection():
    cam = look_at((0.0, -3.0, 1.0), (0.0, 0.0, 0.0), 4 / 3, 0.1, 10.0)
    shifted = Camera(cam.view, np.array([[1.0, 0, 0, 0.2], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) @ cam.proj,
                     cam.eye, True)
    k, _ = intrinsics(shifted, (80, 60))
    assert np.isclose(k[0, 2], (1 - shifted.proj[0, 2]) * 40 - 0.5) and not np.isclose(k[0, 2], 39.5)


def test_intrinsics_refuses_an_orthographic_camera():
    with pytest.raises(ValueError, match="orthographic"):
        intrinsics(top_down((0, 0), 1.0, 1.0, 1.0, 2.0), (32, 32))
