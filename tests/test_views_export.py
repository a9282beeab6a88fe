"""Synthetic RGB-D views (leafview.export.views, ``--views``): the folder layout, depth that
back-projects with the written K and pose onto the truth leaf of each pixel's instance, the ring
of cameras, the seeded sensor noise (numpy statistics, depth file only, holes only where the
surface is seen edge-on), replacing a previous views folder, and the command line (exit 2 and
nothing written on bad input)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from scipy.ndimage import binary_erosion
from scipy.spatial import cKDTree
from support.transforms import axis_rotation

from leafview._version import __version__
from leafview.cli import main
from leafview.core.io import load_leaves
from leafview.core.params import LeafParams, Transform
from leafview.deform.surface import evaluate, grid_uv, normals
from leafview.errors import UsageError
from leafview.export import views as views_module
from leafview.export.views import (
    BACKGROUND,
    DROPOUT,
    GRAZING_DEG,
    MANIFEST,
    SUFFIXES,
    TRUTH,
    VIEW_AOVS,
    add_sensor_noise,
    grazing_angles,
    render_instance_ids,
    render_views,
)
from leafview.resources import builtin_presets
from leafview.scene.camera import RING_FOV_DEG, intrinsics, orbit_cameras, ring_angles
from leafview.scene.spec import Scene, SceneSpec
from tests.conftest import require_or_skip

pytestmark = pytest.mark.filterwarnings("ignore:__array__ implementation:DeprecationWarning")

SIZE = (96, 72)
VIEWS = 3
NEAR_FRACTION = 0.01     # of a leaf's length: a back-projected pixel this close to its truth leaf is "on" it


def make_scene(n: int = 12, seed: int = 11) -> Scene:
    """Twelve varied, overlapping leaves of four species (flat, curled, rippled), no stems and no
    bending (so the truth leaf set draws exactly as the scene does)."""
    presets = {name: LeafParams.load(path) for name, path in builtin_presets().items()}
    species = tuple(presets[s].replace(transform=Transform()) for s in ("ovate", "curled", "lanceolate", "beech"))
    variation = 0.15
    spec = SceneSpec(species=species, leaves=n, variation=variation, colour_variation=0.1, stems=False)
    rng = np.random.default_rng(seed)
    matrices = []
    for i in range(n):
        place = np.eye(4)
        place[:3, 3] = (0.55 * (i % 4), 0.6 * (i // 4), rng.uniform(0.0, 0.3))
        matrices.append(place @ axis_rotation(2, rng.uniform(0, 2 * np.pi)) @ axis_rotation(0, rng.uniform(-0.6, 0.6))
                        @ np.diag([0.8, 0.8, 0.8, 1.0]))
    factors = (1.0 + variation * rng.uniform(-1.0, 1.0, (n, 21))).astype(np.float32)
    tint = (1.0 + 0.1 * rng.uniform(-1.0, 1.0, n)).astype(np.float32)
    return Scene(spec, species, (np.arange(n) % len(species)).astype(np.int32), factors, tint, np.stack(matrices),
                 None, None)


def read_image(path: Path) -> np.ndarray:
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    try:
        return inp.read_image(inp.spec().format)
    finally:
        inp.close()


def read_view(folder: Path, name: str) -> dict[str, np.ndarray | dict]:
    doc = json.loads((folder / f"{name}.json").read_text())
    out: dict[str, np.ndarray | dict] = {"json": doc}
    for aov, rel in doc["files"].items():
        path = folder / rel
        out[aov] = np.load(path) if path.suffix == ".npy" else read_image(path)
    return out


def back_project(depth: np.ndarray, k: np.ndarray, world_from_camera: np.ndarray) -> np.ndarray:
    """(h, w, 3) world points of every pixel centre at its depth (OpenCV: centre of (i, j) at (i, j))."""
    h, w = depth.shape
    jj, ii = np.mgrid[0:h, 0:w].astype(np.float64)
    rays = np.stack([ii, jj, np.ones_like(ii)], -1) @ np.linalg.inv(k).T
    cam = rays * depth[..., None]
    return cam @ world_from_camera[:3, :3].T + world_from_camera[:3, 3]


def digests(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def ctx_resources(_session_renderer):
    if isinstance(_session_renderer, str):
        require_or_skip(f"OpenGL 4.5 through EGL is unavailable: {_session_renderer}")
    return _session_renderer.ctx, _session_renderer.resources


@pytest.fixture(scope="module")
def scene() -> Scene:
    return make_scene()


@pytest.fixture(scope="module")
def exact(ctx_resources, scene, tmp_path_factory):
    ctx, resources = ctx_resources
    out = tmp_path_factory.mktemp("views") / "exact"
    report = render_views(ctx, scene, out, views=VIEWS, size=SIZE, resources=resources)
    return out, report


@pytest.fixture(scope="module")
def noisy(ctx_resources, scene, tmp_path_factory):
    """The same views with depth noise and holes, twice with one seed and once with another."""
    ctx, resources = ctx_resources
    base = tmp_path_factory.mktemp("noisy")
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        render_views(ctx, scene, base / name, views=VIEWS, size=SIZE, depth_noise=0.01, holes=True, seed=seed,
                     resources=resources)
    return base


# -- files ----------------------------------------------------------------------------------------
def test_every_file_with_its_type_shape_and_manifest(gl, exact, scene):
    out, report = exact
    w, h = SIZE
    names = [f"view_{i:03d}" for i in range(VIEWS)]
    assert report.views == names and report.leaves == len(scene) and report.aovs == VIEW_AOVS
    expected = {TRUTH, MANIFEST} | {f"{n}{s}" for n in names for s in (*SUFFIXES.values(), ".json")}
    assert {p.name for p in out.iterdir()} == expected
    assert {p.name for p in report.files} == expected
    for name in names:
        v = read_view(out, name)
        assert v["rgb"].dtype == np.uint8 and v["rgb"].shape == (h, w, 3)
        assert v["depth"].dtype == np.float32 and v["depth"].shape == (h, w)
        assert v["instance"].dtype == np.uint16 and v["instance"].shape == (h, w, 1)
        assert v["normal"].dtype == np.float32 and v["normal"].shape == (h, w, 3)
        doc = v["json"]
        assert (doc["width"], doc["height"], doc["convention"], doc["name"]) == (w, h, "opencv", name)
        assert np.asarray(doc["K"]).shape == (3, 3) and np.asarray(doc["world_from_camera"]).shape == (4, 4)
        assert 0 < doc["near"] < doc["far"]
        ids, depth, normal = v["instance"][..., 0], v["depth"], v["normal"]
        assert ids.max() <= len(scene) and (ids > 0).mean() > 0.05, "too few leaf pixels to test"
        # no stems in this scene: depth exactly where a leaf is, within the clip planes
        assert np.array_equal(ids > 0, depth > 0)
        assert doc["near"] < depth[depth > 0].min() and depth.max() < doc["far"]
        assert np.allclose(np.linalg.norm(normal[ids > 0], axis=-1), 1.0, atol=1e-4)
        assert (normal[ids == 0] == 0).all()
        # the opaque background, in the PNG as the sRGB bytes of BACKGROUND
        background = binary_erosion(ids == 0, iterations=2)
        assert background.any()
        assert (v["rgb"][background] == np.round(np.array(BACKGROUND) * 255)).all()
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["views"] == names and (manifest["width"], manifest["height"]) == SIZE
    assert manifest["leafview"] == __version__ and manifest["gl_renderer"] == report.gl_renderer
    assert manifest["noise"]["depth_sigma"] == 0.0 and manifest["noise"]["holes"] is False
    assert manifest["seed"] == 0 and manifest["truth"] == TRUTH and manifest["leaves"] == len(scene)
    truth = load_leaves(out / TRUTH)
    assert len(truth) == len(scene)
    assert np.allclose([t.transform.matrix() for t in truth], scene.matrices, atol=1e-5)


def test_back_projected_depth_lies_on_the_truth_leaf_of_its_instance(gl, exact, capsys):
    """Every leaf pixel, back-projected with the JSON's K and world_from_camera, lies on the truth
    leaf its instance id names (numpy surface on a fine grid, placed by the leaf's transform):
    ``near``, the distance to the nearest grid point (an upper bound), and ``plane``, the distance
    to the tangent plane there (what is left of the grid's own spacing)."""
    out, _ = exact
    truth = load_leaves(out / TRUTH)
    uv = grid_uv(129, 257).astype(np.float64)
    surfaces = []
    for leaf in truth:
        m = leaf.transform.matrix()
        pts = evaluate(leaf, uv[:, 0], uv[:, 1]) @ m[:3, :3].T + m[:3, 3]
        nrm = normals(leaf, uv[:, 0], uv[:, 1]) @ m[:3, :3].T
        ends = evaluate(leaf, np.zeros(2), np.array([0.0, 1.0])) @ m[:3, :3].T
        surfaces.append((cKDTree(pts), pts, nrm / np.linalg.norm(nrm, axis=1, keepdims=True),
                         float(np.linalg.norm(ends[1] - ends[0]))))
    near, plane, wrong_leaf = [], [], 0
    for i in range(VIEWS):
        v = read_view(out, f"view_{i:03d}")
        doc = v["json"]
        world = back_project(v["depth"].astype(np.float64), np.asarray(doc["K"]), np.asarray(doc["world_from_camera"]))
        ids = v["instance"][..., 0].astype(np.int64)
        for leaf_id in np.unique(ids[ids > 0]):
            tree, pts, nrm, length = surfaces[leaf_id - 1]
            p = world[ids == leaf_id]
            dist, j = tree.query(p)
            near.append(dist / length)
            plane.append(np.abs(np.einsum("ij,ij->i", p - pts[j], nrm[j])) / length)
            others = np.min([s[0].query(p)[0] for k, s in enumerate(surfaces) if k != leaf_id - 1], axis=0)
            wrong_leaf += int(np.sum(others < dist))
    d, e = np.concatenate(near), np.concatenate(plane)
    assert d.size > 500
    on = float(np.mean(d < NEAR_FRACTION))
    with capsys.disabled():
        print(f"\nviews: {d.size} leaf pixels back-projected onto their truth leaf (leaf lengths): nearest grid "
              f"point median {np.median(d):.1e}, 99 % {np.quantile(d, 0.99):.1e}, {on:.2%} within "
              f"{NEAR_FRACTION:.0%}; tangent plane median {np.median(e):.1e}, 99 % {np.quantile(e, 0.99):.1e}, "
              f"max {e.max():.1e}; {wrong_leaf} pixels nearer another leaf")
    assert on > 0.99
    assert np.median(e) < 5e-4 and np.quantile(e, 0.99) < 3e-3
    assert wrong_leaf <= 0.005 * d.size


def test_the_written_cameras_draw_the_truth_again(gl, exact, ctx_resources):
    """render_instance_ids with the JSON's K and pose and the truth leaf set gives the instance image."""
    ctx, resources = ctx_resources
    out, _ = exact
    truth = load_leaves(out / TRUTH)
    for i in range(VIEWS):
        v = read_view(out, f"view_{i:03d}")
        doc = v["json"]
        again = render_instance_ids(ctx, truth, doc["K"], doc["world_from_camera"], SIZE, resources=resources)
        assert again.dtype == np.uint32 and again.shape == SIZE[::-1]
        assert np.mean(again == v["instance"][..., 0]) > 0.998
    # nothing in front of the camera: an empty image, nothing drawn
    doc = read_view(out, "view_000")["json"]
    turned = np.asarray(doc["world_from_camera"]) @ np.diag([-1.0, 1.0, -1.0, 1.0])
    assert not render_instance_ids(ctx, truth, doc["K"], turned, SIZE, resources=resources).any()
    assert not render_instance_ids(ctx, [], doc["K"], doc["world_from_camera"], SIZE).any()
    assert ctx.error == "GL_NO_ERROR"


# -- cameras (numpy) ------------------------------------------------------------------------------
def test_ring_cameras_frame_the_sphere_evenly_and_deterministically():
    centre, radius = np.array([1.0, -2.0, 3.0]), 2.5
    size = (120, 80)
    cams = orbit_cameras((centre, radius), 6, size, (20.0, 45.0))
    assert all(np.array_equal(a.view, b.view) for a, b in zip(cams, orbit_cameras((centre, radius), 6, size,
                                                                                 (20.0, 45.0))))
    angles = ring_angles(6, (20.0, 45.0))
    assert [a for a, _ in angles] == pytest.approx([0, 60, 120, 180, 240, 300])
    assert [e for _, e in angles] == [20.0, 45.0] * 3
    # points on the sphere project inside the image, and the sphere touches the narrower side
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(4000, 3))
    pts = centre + radius * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    dists = []
    for cam, (az, el) in zip(cams, angles):
        k, m = intrinsics(cam, size)
        assert np.isclose(np.degrees(2 * np.arctan(size[1] / 2 / k[1, 1])), RING_FOV_DEG)
        cam_pts = (pts - m[:3, 3]) @ m[:3, :3]
        assert cam_pts[:, 2].min() > 0
        xy = cam_pts @ k.T
        xy = xy[:, :2] / xy[:, 2:]
        assert xy[:, 0].min() > -0.5 and xy[:, 0].max() < size[0] - 0.5
        assert xy[:, 1].min() > -0.5 and xy[:, 1].max() < size[1] - 0.5
        assert (xy[:, 1].max() - xy[:, 1].min()) > 0.97 * size[1]      # fits the narrower (vertical) side
        rel = m[:3, 3] - centre
        dists.append(np.linalg.norm(rel))
        assert np.degrees(np.arcsin(rel[2] / np.linalg.norm(rel))) == pytest.approx(el)
        assert np.degrees(np.arctan2(rel[0], -rel[1])) % 360 == pytest.approx(az, abs=1e-9)
        assert np.allclose(m[:3, 2], -rel / np.linalg.norm(rel))        # aimed at the centre
    assert np.allclose(dists, dists[0])
    with pytest.raises(ValueError, match="elevation"):
        ring_angles(2, (90.0,))
    with pytest.raises(ValueError, match="radius"):
        orbit_cameras((centre, 0.0), 2, size)


# -- sensor noise (numpy) -------------------------------------------------------------------------
def _camera(w: int = 200, h: int = 150) -> tuple[np.ndarray, np.ndarray]:
    k = np.array([[150.0, 0.0, (w - 1) / 2], [0.0, 150.0, (h - 1) / 2], [0.0, 0.0, 1.0]])
    m = np.eye(4)
    m[:3, :3] = axis_rotation(2, 0.7)[:3, :3] @ axis_rotation(0, 2.0)[:3, :3]
    m[:3, 3] = (1.0, 2.0, 3.0)
    return k, m


def _rays(k: np.ndarray, m: np.ndarray, h: int, w: int) -> np.ndarray:
    jj, ii = np.mgrid[0:h, 0:w].astype(np.float64)
    rays = np.stack([ii, jj, np.ones_like(ii)], -1) @ np.linalg.inv(k).T @ m[:3, :3].T
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


def test_depth_noise_grows_with_the_square_of_the_distance():
    k, m = _camera()
    h, w = 150, 200
    depth = np.repeat(np.array([1.0, 2.0, 4.0]), [50, 50, 50])[:, None] * np.ones((1, w))
    facing = -_rays(k, m, h, w)
    noisy = add_sensor_noise(depth, facing, k, m, sigma=0.01, holes=False, rng=np.random.default_rng(1), z_ref=2.0)
    assert noisy.dtype == np.float32 and (noisy > 0).all()
    for z in (1.0, 2.0, 4.0):
        band = depth == z
        err = noisy[band] - z
        assert abs(err.mean()) < 4 * 0.01 * (z / 2) ** 2 / np.sqrt(band.sum())
        assert err.std() == pytest.approx(0.01 * (z / 2.0) ** 2, rel=0.05)
    again = add_sensor_noise(depth, facing, k, m, sigma=0.01, holes=False, rng=np.random.default_rng(1), z_ref=2.0)
    assert np.array_equal(noisy, again)
    # off: the depth itself; no data stays no data
    depth[:10] = 0.0
    assert np.array_equal(add_sensor_noise(depth, facing, k, m, sigma=0.0, holes=False, rng=np.random.default_rng(2)),
                          depth.astype(np.float32))
    assert (add_sensor_noise(depth, facing, k, m, sigma=0.05, holes=True, rng=np.random.default_rng(3))[:10] == 0).all()
    with pytest.raises(ValueError, match="noise"):
        add_sensor_noise(depth, facing, k, m, sigma=-1.0, holes=False, rng=np.random.default_rng(0))


def test_holes_fall_where_the_surface_is_seen_edge_on():
    """Normals turned from the view ray by 0..90° across the image: nothing below 75° drops but the
    random dropouts, everything beyond 85° drops, the ramp between."""
    k, m = _camera()
    h, w = 150, 200
    rays = _rays(k, m, h, w)
    side = np.cross(rays, [0.3, 0.5, 0.8])
    side /= np.linalg.norm(side, axis=-1, keepdims=True)
    theta = np.radians(np.linspace(0.0, 90.0, w))[None, :, None]
    normal = -np.cos(theta) * rays + np.sin(theta) * side
    got = grazing_angles(normal, k, m)
    assert np.allclose(got, np.degrees(theta[..., 0]) * np.ones((h, 1)), atol=1e-6)
    depth = np.full((h, w), 3.0)
    dropped = add_sensor_noise(depth, normal, k, m, sigma=0.0, holes=True, rng=np.random.default_rng(4)) == 0
    lo, hi = GRAZING_DEG
    head_on = got < lo
    assert dropped[head_on].mean() < 3 * DROPOUT and dropped[head_on].sum() > 0     # a few random dropouts
    assert dropped[got > hi].all()
    ramp = (got > lo + 1) & (got < hi - 1)
    expected = np.clip((got[ramp] - lo) / (hi - lo), 0, 1).mean()
    assert dropped[ramp].mean() == pytest.approx(expected, abs=0.05)
    # without normals (background) no angle: only the random dropouts
    assert np.isnan(grazing_angles(np.zeros((2, 2, 3)), k, m)).all()


# -- noise in the written views -------------------------------------------------------------------
def test_noise_is_seeded_changes_only_the_depth_and_holes_are_grazing(gl, exact, noisy):
    out, _ = exact
    a, b, c = (digests(noisy / n) for n in "abc")
    assert a == b, "the same seed must give the same files"
    depth_files = {n for n in a if n.endswith(".depth.npy")}
    assert all(a[n] != c[n] for n in depth_files), "another seed must give other noise"
    clean = digests(out)
    for name in a:
        if name.endswith((".color.png", ".instance.png", ".normal.exr", ".leaves.json")):
            assert a[name] == clean[name], f"{name}: noise must change the depth only"
    manifest = json.loads((noisy / "a" / MANIFEST).read_text())
    assert manifest["seed"] == 5 and manifest["noise"]["depth_sigma"] == 0.01 and manifest["noise"]["holes"]
    assert manifest["noise"]["grazing_deg"] == list(GRAZING_DEG) and manifest["noise"]["z_ref"] > 0
    dropped_total = grazing_total = head_on_total = head_on_dropped = 0
    for i in range(VIEWS):
        truth, got = read_view(out, f"view_{i:03d}"), read_view(noisy / "a", f"view_{i:03d}")
        doc = truth["json"]
        theta = grazing_angles(truth["normal"], np.asarray(doc["K"]), np.asarray(doc["world_from_camera"]))
        leaf = truth["depth"] > 0
        dropped = leaf & (got["depth"] == 0)
        assert not (got["depth"][~leaf]).any(), "no depth appears where there was none"
        dropped_total += int(dropped.sum())
        grazing_total += int((leaf & (theta > GRAZING_DEG[1])).sum())
        assert dropped[leaf & (theta > GRAZING_DEG[1])].all()
        head_on = leaf & (theta < GRAZING_DEG[0])
        head_on_total += int(head_on.sum())
        head_on_dropped += int(dropped[head_on].sum())
        kept = leaf & ~dropped
        assert not np.array_equal(got["depth"][kept], truth["depth"][kept])
        err = got["depth"][kept] - truth["depth"][kept]
        z_ref = manifest["noise"]["z_ref"]
        assert np.abs(err / (0.01 * (truth["depth"][kept] / z_ref) ** 2)).max() < 6   # Gaussian, 6 σ
    assert dropped_total >= grazing_total > 0
    assert head_on_dropped <= max(3, 3 * DROPOUT * head_on_total)


# -- the output folder ----------------------------------------------------------------------------
def test_a_previous_views_folder_is_replaced_and_matches_its_manifest(gl, ctx_resources, scene, tmp_path):
    ctx, resources = ctx_resources
    out = tmp_path / "v"
    render_views(ctx, scene, out, views=3, size=(48, 32), resources=resources)
    report = render_views(ctx, scene, out, views=2, size=(48, 32), aovs=("depth",), resources=resources)
    assert {p.name for p in out.iterdir()} == {TRUTH, MANIFEST, "view_000.json", "view_001.json",
                                               "view_000.depth.npy", "view_001.depth.npy"}
    assert len(report.removed) == 3 * 4 + 1 - 2     # 3 views × (rgb, instance, normal, json) + view_002's depth
    assert json.loads((out / MANIFEST).read_text())["views"] == ["view_000", "view_001"]


def test_bad_folders_and_a_failure_midway_leave_nothing(gl, ctx_resources, scene, tmp_path, monkeypatch):
    ctx, resources = ctx_resources
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "notes.txt").write_text("mine")
    with pytest.raises(UsageError, match="not a previous views folder"):
        render_views(ctx, scene, busy, views=1, size=(48, 32), resources=resources)
    assert [p.name for p in busy.iterdir()] == ["notes.txt"]
    afile = tmp_path / "file"
    afile.write_text("x")
    with pytest.raises(UsageError, match="not a directory"):
        render_views(ctx, scene, afile, views=1, size=(48, 32), resources=resources)
    with pytest.raises(UsageError, match="unknown AOV 'albedo'"):
        render_views(ctx, scene, tmp_path / "new", views=1, size=(48, 32), aovs=("rgb", "albedo"))
    calls = []
    real = views_module.render_aovs

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("the GPU fell over")
        return real(*args, **kwargs)

    monkeypatch.setattr(views_module, "render_aovs", failing)
    with pytest.raises(RuntimeError, match="fell over"):
        render_views(ctx, scene, tmp_path / "half" / "views", views=3, size=(48, 32), resources=resources)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["busy", "file"]


# -- the command ----------------------------------------------------------------------------------
def test_cli_render_views_of_one_leaf(gl, ctx_resources, tmp_path, capsys):
    out = tmp_path / "ovate-views"
    assert main(["render", "ovate", "--views", "2", "--size", "64", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert text.startswith("wrote 2 views of 1 leaf to") and f"[{ctx_resources[0].info['GL_RENDERER']}]" in text
    v = read_view(out, "view_001")
    assert v["rgb"].shape == (64, 64, 3) and set(np.unique(v["instance"])) == {0, 1}
    assert load_leaves(out / TRUTH)[0].shape == LeafParams.load(builtin_presets()["ovate"]).shape
    # a scene, with noise and only some AOVs, seeded by the scene's seed
    out2 = tmp_path / "scene-views"
    assert main(["scene", "--leaves", "30", "--seed", "3", "--views", "2", "--size", "64x48", "--aov",
                 "depth,instance", "--depth-noise", "0.01", "--holes", "-q", "-o", str(out2)]) == 0
    assert capsys.readouterr().out == ""
    manifest = json.loads((out2 / MANIFEST).read_text())
    assert manifest["aovs"] == ["depth", "instance"] and manifest["seed"] == 3 and manifest["leaves"] == 30
    assert not (out2 / "view_000.color.png").exists() and (out2 / "view_000.depth.npy").exists()


@pytest.mark.parametrize("argv, message", [
    (["render", "ovate", "--views", "0"], "--views must be in 1..1,000"),
    (["render", "ovate", "--views", "2", "--aov", "depth,albedo"], "'albedo'"),
    (["render", "ovate", "--aov", "depth"], "--aov goes with --views"),
    (["render", "ovate", "--views", "2", "--view", "top"], "--view cannot be used"),
    (["render", "ovate", "lanceolate", "--views", "2"], "give one PRESET"),
    (["render", "ovate", "--views", "2", "--aov", "rgb", "--holes"], "add depth to --aov"),
    (["render", "ovate", "--views", "2", "--elevation", "90"], "outside ±85"),
    (["render", "ovate", "--views", "2", "--depth-noise", "nan"], "finite"),
    (["render", "ovate", "--views", "2", "--seed", "-1"], "--seed must be in 0.."),
    (["render", "ovate", "--seed", "4"], "--seed goes with --views"),
    (["scene", "--leaves", "5", "--views", "2", "--export", "x.glb"], "--export cannot be used"),
    (["scene", "--leaves", "5", "--holes"], "--holes goes with --views"),
    (["scene", "--leaves", "5", "--views", "2", "--camera", "top"], "--camera cannot be used"),
])
def test_cli_bad_input_exits_2_and_writes_nothing(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    try:
        rc = main([*argv, "-o", "out"])
    except SystemExit as exc:      # argparse type errors
        rc = exc.code
    assert rc == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_cli_refuses_a_file_or_a_foreign_folder_as_the_views_folder(tmp_path, capsys):
    afile = tmp_path / "views.png"
    afile.write_bytes(b"not mine")
    assert main(["render", "ovate", "--views", "2", "-o", str(afile)]) == 2
    assert "names a folder" in capsys.readouterr().err
    plain = tmp_path / "plain"
    plain.write_text("x")
    assert main(["render", "ovate", "--views", "2", "-o", str(plain)]) == 2
    assert "not a directory" in capsys.readouterr().err
    assert afile.read_bytes() == b"not mine" and plain.read_text() == "x"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain", "views.png"]
