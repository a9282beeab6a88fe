"""Lobed species in scenes (issue 21): drawn in the same indirect multi-draws as the unlobed ones,
on their own level-of-detail grids, where the numpy reference puts them; culled and labelled
like the others; framed whole wherever a camera is fitted to a leaf."""

from __future__ import annotations

import moderngl
import numpy as np
import pytest
from scipy import ndimage
from skimage.draw import polygon

from leafview.botany import leaf_surface
from leafview.cli import main
from leafview.core.params import LeafParams, Transform
from leafview.deform.surface import grid_indices, grid_uv
from leafview.export.images import read_image
from leafview.gpu.aov import render_aovs
from leafview.gpu.instanced import OffscreenTarget
from leafview.gpu.morph import shared_camera
from leafview.gpu.scene import (
    LOD_GRIDS,
    CullSettings,
    SceneRenderer,
    cull_reference,
    lobed_levels,
    lobed_species,
    species_cull,
)
from leafview.resources import resolve_preset
from leafview.scene.camera import Camera, check_leaf_framable, scene_camera, top_down
from leafview.scene.spec import SceneSpec, build_scene, evaluate_leaf, save_scene, scene_from_leaves

FINE = ((33, 65), (9, 17), (3, 5))   # levels whose lobed grids differ: (8, 257), (2, 65)


def _preset(name: str) -> LeafParams:
    return LeafParams.load(resolve_preset(name))


@pytest.fixture(scope="module")
def maple() -> LeafParams:
    p = _preset("maple")
    assert p.lobes.enabled
    return p


@pytest.fixture(scope="module")
def row_scene(maple):
    """Six explicit leaves in a row, lobed and unlobed alternating, turned and scaled."""
    ovate = _preset("ovate")
    leaves = [(maple if k % 2 == 0 else ovate).replace(
        transform=Transform(translation=(1.2 * k, 0.3 * (k % 3), 0.0), rotation=(0.0, 0.0, 25.0 * k - 60.0),
                            scale=0.8 + 0.1 * k)) for k in range(6)]
    return scene_from_leaves(leaves)


@pytest.fixture(scope="module")
def mixed(maple):
    """A field of maple and ovate plants, varied."""
    spec = SceneSpec(species=(maple, _preset("ovate")), leaves=1500, seed=1, layout="field", variation=0.2, plants=6)
    scene = build_scene(spec)
    assert len(set(scene.species_id.tolist())) == 2
    return scene


@pytest.fixture
def ctx(gl):
    return gl.ctx


def _top_camera(scene, size) -> Camera:
    pts = np.concatenate([_world(scene, i, *_grid_of(scene, i)) for i in range(len(scene))])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    w, h = size
    ppu = 0.9 * min(w / (hi[0] - lo[0]), h / (hi[1] - lo[1]))
    return top_down((lo[:2] + hi[:2]) / 2, hi[2] + 1.0, w / (2 * ppu), h / (2 * ppu), hi[2] - lo[2] + 2.0)


def _grid_of(scene, i, level=0):
    sp = scene.species[int(scene.species_id[i])]
    return lobed_levels(LOD_GRIDS)[0] if sp.lobes.enabled else LOD_GRIDS[level]


def _world(scene, i, nu, nv):
    uv = grid_uv(nu, nv).astype(np.float64)
    local = evaluate_leaf(scene, i, uv[:, 0], uv[:, 1])
    m = scene.matrices[i]
    return local @ m[:3, :3].T + m[:3, 3]


def _raster(scene, camera, size, leaves=None):
    """Coverage mask of the numpy reference: each leaf's grid triangles, projected and filled."""
    w, h = size
    out = np.zeros((h, w), bool)
    for i in range(len(scene)) if leaves is None else leaves:
        nu, nv = _grid_of(scene, i)
        p = np.c_[_world(scene, i, nu, nv), np.ones(nu * nv)] @ (camera.proj @ camera.view).T
        x = (p[:, 0] / p[:, 3] + 1) / 2 * w - 0.5
        y = (1 - p[:, 1] / p[:, 3]) / 2 * h - 0.5
        for tri in grid_indices(nu, nv).reshape(-1, 3):
            rr, cc = polygon(y[tri], x[tri], (h, w))
            out[rr, cc] = True
    return out


# -- numpy side ------------------------------------------------------------------------------------
def test_lobed_leaves_keep_their_species_shape_under_variation(mixed):
    lobed = lobed_species(mixed)[mixed.species_id]
    assert lobed.any() and (~lobed).any()
    assert (mixed.factors[lobed] == 1.0).all()            # no meaningless Ω factors
    assert not (mixed.factors[~lobed] == 1.0).all()       # the others still vary
    i = int(np.flatnonzero(lobed)[0])
    assert mixed.leaf(i).shape == mixed.species[int(mixed.species_id[i])].shape
    assert mixed.leaf(i).material != mixed.species[int(mixed.species_id[i])].material or mixed.tint[i] == 1.0


def test_lobed_levels_follow_the_level_grids():
    assert lobed_levels(LOD_GRIDS) == ((2, 65),)
    assert lobed_levels(FINE) == ((8, 257), (2, 65))


def test_leaf_framing_checks_the_swept_surface(maple):
    check_leaf_framable(maple)
    far = maple.replace(transform=Transform(translation=(4.9, 4.9, 4.9), scale=0.05))
    check_leaf_framable(far)


def test_shared_camera_frames_the_whole_lobed_leaf(maple):
    cam = shared_camera([maple], "top", (128, 128))
    pts = leaf_surface.grid_points(maple, (33, 129))
    p = np.c_[pts, np.ones(len(pts))] @ (cam.proj @ cam.view).T
    ndc = p[:, :2] / p[:, 3:]
    assert (np.abs(ndc) < 1.0).all()
    assert pts[:, 1].min() < -0.05   # maple's basal lobes reach below its base: what Ω misses


# -- GPU -------------------------------------------------------------------------------------------
def test_mixed_scene_is_one_multi_draw_per_batch(ctx, mixed, monkeypatch):
    calls = []
    original = moderngl.VertexArray.render_indirect

    def counting(self, buffer, mode=None, count=-1, *, first=0):
        calls.append((count, first))
        return original(self, buffer, mode, count=count, first=first)

    with SceneRenderer(ctx, mixed, veins=False) as r, OffscreenTarget(ctx, (320, 200)) as target:
        assert r.lobed_grids == ((2, 65),) and r.command_grids == LOD_GRIDS + ((2, 65),)
        target.use()
        r.set_camera(scene_camera(mixed, (320, 200), "three-quarter"), (320, 200))
        monkeypatch.setattr(moderngl.VertexArray, "render_indirect", counting)
        r.draw(CullSettings(cull=False))
        monkeypatch.undo()
        counts = r.level_counts()
        assert calls == [(len(r.command_grids), 0)] * len(r.batches)
        lobed = lobed_species(mixed)[mixed.species_id]
        assert counts[len(LOD_GRIDS):].sum() == lobed.sum()        # every lobed leaf on its own grid
        assert counts[:len(LOD_GRIDS)].sum() == (~lobed).sum()
        assert r.triangles(counts) == int(counts @ [2 * (a - 1) * (b - 1) for a, b in r.command_grids])
    assert ctx.error == "GL_NO_ERROR"


def test_scene_without_lobed_species_has_no_lobe_branch(ctx, mixed):
    plain = build_scene(SceneSpec(species=(_preset("ovate"),), leaves=200, seed=1, layout="field"))
    with SceneRenderer(ctx, plain) as r:
        assert r._defines().get("LEAF_NO_LOBES") == 1 and r.lobed_grids == ()
        assert "leaf_lobe_table" not in r.program and not r.lobes.active
    with SceneRenderer(ctx, mixed) as r:
        assert "LEAF_NO_LOBES" not in r._defines()
        assert "leaf_lobe_table" in r.program and r.lobes.active


@pytest.mark.parametrize("grids", [LOD_GRIDS, FINE])
def test_culling_rows_and_levels_equal_numpy(ctx, mixed, grids):
    lobed = lobed_species(mixed)
    with SceneRenderer(ctx, mixed, grids=grids) as r, OffscreenTarget(ctx, (64, 64)) as target:
        target.use()
        ref = species_cull(mixed, grids)
        assert np.allclose(r.cull_rows["sphere"], ref["sphere"], atol=2e-5)
        assert np.allclose(r.cull_rows["lod_error"], ref["lod_error"], rtol=1e-5, atol=2e-5)
        assert (r.cull_rows["lod_error"][lobed, 0] == 1).all() and (r.cull_rows["lod_error"][~lobed, 0] == 0).all()
        seen = set()
        size = (640, 360)
        for view in ("ground", "three-quarter"):
            cam = scene_camera(mixed, size, view)
            for settings in (CullSettings(), CullSettings(max_error_px=0.2, min_pixels=4.0), CullSettings(level=2),
                             CullSettings(lod=False)):
                r.set_camera(cam, size)
                r.draw(settings)
                got = r.levels()
                want = cull_reference(mixed, r.cull_rows, cam, size, settings, len(grids), len(r.lobed_grids))
                assert np.array_equal(got, want), (view, settings, np.flatnonzero(got != want)[:5])
                seen |= set(got[lobed[mixed.species_id] & (got >= 0)].tolist())
        assert seen == set(range(len(r.lobed_grids)))   # FINE: lobed leaves at both of their levels


def test_captured_lobed_leaves_are_the_swept_surface(ctx, row_scene):
    with SceneRenderer(ctx, row_scene) as r:
        lobed = np.flatnonzero(lobed_species(row_scene)[row_scene.species_id])
        assert r.capture_grid(lobed) == (2, 65)
        got = r.capture(lobed)
        uv = grid_uv(2, 65).astype(np.float64)
        for k, i in enumerate(lobed):
            want = leaf_surface.evaluate(row_scene.leaf(int(i)), uv[:, 0], uv[:, 1])
            np.testing.assert_allclose(got[k], want, atol=2e-5)
        with pytest.raises(ValueError, match="lobed and unlobed"):
            r.capture([0, 1])


def test_flat_render_covers_the_numpy_reference(ctx, row_scene):
    size = (480, 200)
    cam = _top_camera(row_scene, size)
    with SceneRenderer(ctx, row_scene) as r:
        img = r.render(cam, size, CullSettings(lod=False), samples=0, flat=True)
        assert ctx.error == "GL_NO_ERROR"
    got = img[..., 3] > 127
    want = _raster(row_scene, cam, size)
    # pixel-centre coverage differs from the reference only on the outline
    edge = ndimage.binary_dilation(want, iterations=1) & ~ndimage.binary_erosion(want, iterations=1)
    assert not ((got ^ want) & ~edge).any()
    assert (got ^ want).sum() < 0.005 * want.sum()
    # each lobed leaf where the reference puts it: its own reference mask is covered
    lobed = np.flatnonzero(lobed_species(row_scene)[row_scene.species_id])
    one = _raster(row_scene, cam, size, [int(lobed[1])])
    inner = ndimage.binary_erosion(one, iterations=1)
    assert inner.sum() > 200 and got[inner].all()


def test_aov_labels_lobed_instances(ctx, row_scene):
    size = (480, 200)
    cam = _top_camera(row_scene, size)
    lobed = np.flatnonzero(lobed_species(row_scene)[row_scene.species_id])
    with SceneRenderer(ctx, row_scene) as r:
        out = render_aovs(r, cam, size, ("instance", "depth"), settings=CullSettings(lod=False))
    for i in lobed:
        label = out.instance == i + 1
        mask = _raster(row_scene, cam, size, [int(i)])
        assert label.sum() > 0.9 * mask.sum()                          # its pixels are its own ...
        assert not (label & ~ndimage.binary_dilation(mask, iterations=1)).any()   # ... and only inside it
    assert ctx.error == "GL_NO_ERROR"


def test_scene_cli_with_a_lobed_species(tmp_path, capsys, gl, maple):
    path = tmp_path / "mixed.toml"
    save_scene(SceneSpec(species=(maple, _preset("ovate")), leaves=400, seed=1, layout="field", plants=4), path)
    out = tmp_path / "mixed.png"
    rc = main(["scene", str(path), "--size", "160x120", "-o", str(out)])
    assert rc == 0, capsys.readouterr().err
    image, _ = read_image(out)
    assert image.shape == (120, 160, 4) and (image[..., 3] > 0).mean() > 0.01


@pytest.mark.parametrize("view", ["top", "three-quarter"])
def test_render_maple_frames_the_whole_leaf(tmp_path, capsys, gl, view):
    out = tmp_path / f"maple_{view}.png"
    rc = main(["render", "maple", "--view", view, "-o", str(out)])
    assert rc == 0, capsys.readouterr().err
    image, _ = read_image(out)
    alpha = image[..., 3] > 0
    assert alpha.mean() > 0.15
    assert not (alpha[0].any() or alpha[-1].any() or alpha[:, 0].any() or alpha[:, -1].any())
