"""Scene-wide edits (Chaurasia & Beardsley 2017, sec. 6 applied to whole scenes): each edit equals
the single-leaf edit of leafview.core.edits on the leaves it targets and leaves the others alone,
undo restores the arrays bit for bit, edits survive a save and load, the GPU rows follow with one
buffer write per batch, and picking by click and by box returns the leaves drawn there."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from leafview.core import edits as core
from leafview.core.params import Bending, LeafParams, ParamError
from leafview.scene.scene_edits import SceneEdit, SceneEditor, apply_edits, leaf_omega, parse_edits
from leafview.scene.spec import VARIED, Scene, SceneSpec, build_scene, load_scene


def _omega(p: LeafParams) -> np.ndarray:
    s = p.shape
    return np.array([*s.a1, *s.a2, *(c for r in s.silhouette[:3] for c in r), *s.zf[:3], *s.zg[:3]])


def _scene(presets, n=80, **kw) -> Scene:
    species = (presets["ovate"].replace(bending=Bending()), presets["lanceolate"].replace(bending=Bending()))
    return build_scene(SceneSpec(species=species, layout="field", leaves=n, plants=6, seed=3, variation=0.1, **kw))


def test_columns_follow_varied():
    from leafview.scene.scene_edits import _COL

    for name, cols in _COL.items():
        names = [VARIED[c] for c in cols]
        want = [name] if "." in name else [f"{name}{k}" for k in (1, 2, 3)]
        assert names == want, (name, names)


@pytest.mark.parametrize(("table", "field"), [
    ({"op": "stretch", "value": 1}, "edits[1].op"),
    ({"op": "width", "value": -1.0}, "edits[1].value"),
    ({"op": "width", "value": float("nan")}, "edits[1].value"),
    ({"op": "width"}, "edits[1].value"),
    ({"op": "width", "value": 1.2, "target": "some"}, "edits[1].target"),
    ({"op": "width", "value": 1.2, "target": "leaves"}, "edits[1].leaves"),
    ({"op": "width", "value": 1.2, "target": "leaves", "leaves": [1, -2]}, "edits[1].leaves[1]"),
    ({"op": "silhouette", "value": 0.1, "row": 3}, "edits[1].row"),
    ({"op": "curvature", "value": 0.1, "curve": "H"}, "edits[1].curve"),
    ({"op": "width", "value": 1.2, "colour": 1}, "edits[1].colour"),
    ({"op": "width", "value": 1.2, "species": True}, "edits[1].species"),
])
def test_parse_errors_name_the_field(table, field):
    with pytest.raises(ParamError) as exc:
        parse_edits([{"op": "width", "value": 1.1}, table])
    assert exc.value.path == field


def test_spec_and_file_errors_name_the_edit(presets, tmp_path):
    ok = SceneEdit("width", 1.1)
    for bad, field in ((SceneEdit("width", 1.1, "species", species=4), "edits[1].species"),
                       (SceneEdit("width", 1.1, "leaves", leaves=(3, 20)), "edits[1].leaves")):
        with pytest.raises(ParamError) as exc:
            SceneSpec(species=(presets["ovate"],), leaves=20, edits=(ok, bad))
        assert exc.value.path == field
    spec = SceneSpec(species=(presets["ovate"],), leaves=20, edits=(ok,))
    path = tmp_path / "scene.toml"
    from leafview.scene.spec import save_scene

    save_scene(spec, path)
    text = path.read_text()
    assert load_scene(path).edits == (ok,) and "value = 1.1" in text
    path.write_text(text.replace("value = 1.1", "value = 0.0"))
    with pytest.raises(ParamError) as exc:
        load_scene(path)
    assert exc.value.path == "edits[0].value" and str(path) in str(exc.value)


def _reference(p: LeafParams, e: SceneEdit) -> LeafParams:
    """The single-leaf edit of leafview.core.edits that ``e`` makes of leaf ``p``."""
    s = p.shape
    if e.op == "width":
        return core.scale_width(p, e.value)
    if e.op == "asymmetry":
        return core.skew_axis(p, e.value)
    if e.op == "silhouette":
        v, x, _ = s.silhouette[e.row]
        return core.set_silhouette_point(p, e.row, v=v + e.v, x=x + e.value)
    if e.curve == "axis":
        return core.curve_axis(p, s.a1[2] + e.value, s.a2[2] + e.value)
    # per-row lift of S, F or G (curve_longitudinal sets one z for every row; here each row keeps its own)
    if e.curve == "S":
        return p.replace(shape=replace(s, silhouette=tuple((v, x, z + e.value) for v, x, z in s.silhouette)))
    key = e.curve.lower()
    zs = tuple(z + e.value for z in getattr(s, f"z{key}"))
    return p.replace(shape=replace(s, **{f"z{key}": zs}))


EDITS = [SceneEdit("width", 1.3, "all"), SceneEdit("asymmetry", 0.05, "species", species=1),
         SceneEdit("silhouette", 0.04, "leaves", leaves=(2, 7, 30), row=1, v=0.03),
         SceneEdit("curvature", 0.06, "all", curve="axis"), SceneEdit("curvature", -0.05, "species", curve="F"),
         SceneEdit("curvature", 0.02, "leaves", leaves=(5,), curve="S"), SceneEdit("curvature", 0.03, curve="G")]


@pytest.mark.parametrize("edit", EDITS, ids=lambda e: f"{e.op}-{e.target}-{e.curve}")
def test_each_edit_equals_the_single_leaf_edit(presets, edit):
    scene = _scene(presets)
    before = scene.factors.copy()
    apply_edits(scene, [SceneEdit("asymmetry", -0.02, "leaves", leaves=(2, 3))])   # offsets already there
    base = [leaf_omega(scene, i)[0] for i in range(len(scene))]
    expect_leaves = [scene.leaf(i) for i in range(len(scene))]
    changed = apply_edits(scene, [edit])
    if edit.target == "all":
        want = np.arange(len(scene))
    elif edit.target == "species":
        want = np.flatnonzero(scene.species_id == edit.species)
    else:
        want = np.array(edit.leaves)
    assert np.array_equal(changed, want) and 0 < len(changed)
    for i in range(len(scene)):
        got = leaf_omega(scene, i)[0]
        if i in set(changed.tolist()):
            # the single-leaf edit, applied to the leaf's Ω before (offsets included)
            p = expect_leaves[i]
            omega_p = _omega(p)
            shifted = base[i] - omega_p      # the offsets (and v̄ clamping) the leaf had, unchanged by the edit
            ref = _omega(_reference(p, edit)) + shifted
            assert np.allclose(got, ref, atol=2e-6), (i, got - ref)
            assert not np.allclose(got, base[i])
        else:
            assert np.array_equal(got, base[i])
    assert scene.factors.shape == before.shape


def test_undo_redo_bit_for_bit(presets):
    scene = _scene(presets)
    f0 = scene.factors.copy()
    ed = SceneEditor(scene)
    ed.select(species=0)
    a = ed.apply("width", 1.25)
    ed.select([1, 2, 3])
    ed.select([40], add=True)
    b = ed.apply("asymmetry", 0.1)
    assert np.array_equal(b, [1, 2, 3, 40])
    f1, o1 = scene.factors.copy(), scene.offsets.copy()
    assert np.array_equal(ed.undo(), b)
    assert np.array_equal(ed.undo(), a)
    assert ed.undo() is None
    assert np.array_equal(scene.factors, f0) and scene.offsets is None
    ed.redo()
    ed.redo()
    assert ed.redo() is None
    assert np.array_equal(scene.factors, f1) and np.array_equal(scene.offsets, o1)
    assert [e.op for e in ed.history] == ["width", "asymmetry"]
    ed.undo()
    ed.select()        # every leaf
    ed.apply("curvature", 0.05, curve="G")
    assert [e.op for e in ed.history] == ["width", "curvature"] and ed.redo() is None
    with pytest.raises(ParamError):   # a value beyond the limits changes nothing
        ed.apply("width", 11.0)
    with pytest.raises(ParamError):
        ed.select([10_000])


def test_save_load_build(presets, tmp_path):
    scene = _scene(presets)
    ed = SceneEditor(scene)
    ed.select(species=1)
    ed.apply("width", 0.8)
    ed.select([4, 9])
    ed.apply("silhouette", -0.03, row=2, v=-0.02)
    ed.apply("curvature", 0.04, curve="axis")
    for ext in ("toml", "json"):
        path = tmp_path / f"edited.{ext}"
        ed.save(path)
        spec = load_scene(path)
        assert spec.edits == ed.edits and len(spec.edits) == 3
        again = build_scene(spec)
        assert np.array_equal(again.factors, scene.factors)
        assert np.array_equal(again.offsets, scene.offsets)
    # a file's edits come first in the next session's list
    ed2 = SceneEditor(again)
    ed2.apply("width", 1.1)
    assert len(ed2.edits) == 4


# -- GPU -------------------------------------------------------------------------------------------
@pytest.mark.gl
@pytest.mark.parametrize(("mode", "leaves", "batches"), [("span", [3, 12, 57, 58], 2),
                                                         ("staged", [3, 40, 57, 58, 110], 3)])
def test_update_rows_one_write_per_batch(gl, presets, monkeypatch, mode, leaves, batches):
    import moderngl

    import leafview.gpu.scene_edits as gpu_edits
    from leafview.deform.surface import grid_uv
    from leafview.gpu.layout import LEAF_BLOCK
    from leafview.gpu.scene import SceneRenderer
    from leafview.scene.spec import evaluate_leaf

    if mode == "staged":   # every batch through the staging buffer and GPU copies
        monkeypatch.setattr(gpu_edits, "SPAN_SLACK", 0)
        monkeypatch.setattr(gpu_edits, "SPAN_ROWS", 0)
    scene = _scene(presets, n=120)
    with SceneRenderer(gl.ctx, scene, max_block_bytes=50 * LEAF_BLOCK.nbytes) as r:
        assert len(r.batches) == 3
        uv = grid_uv(*r.grids[0]).astype(np.float64)
        picks = [*leaves, 10]
        before = r.capture(picks)
        writes: list[object] = []
        real_write = moderngl.Buffer.write

        def counted(buf, data, offset=0):
            writes.append(buf)
            return real_write(buf, data, offset=offset)
        monkeypatch.setattr(moderngl.Buffer, "write", counted)
        rebuilt: list[int] = []
        monkeypatch.setattr(SceneRenderer, "__init__", lambda *a, **k: rebuilt.append(1))
        batches_before = list(r.batches)
        rows = {id(b.rows) for b in r.batches}
        ed = SceneEditor(scene)
        for op, value, kw in (("width", 1.6, {}), ("asymmetry", 0.08, {}), ("curvature", 0.1, {"curve": "axis"}),
                              ("silhouette", 0.05, {"row": 0})):
            writes.clear()
            ed.select(leaves)
            gpu_edits.update_rows(r, ed.apply(op, value, **kw))
            # one upload per batch touched; only a cull row grows besides (a width edit's sphere)
            uploads = [w for w in writes if w is not r.species_ssbo]
            assert len(uploads) == batches, (op, len(uploads))
            assert all((id(w) in rows) == (mode == "span") for w in uploads)
            assert len(writes) - len(uploads) <= 1
            got = r.capture(picks)
            for row, i in zip(got, picks):
                assert np.abs(row - evaluate_leaf(scene, i, uv[:, 0], uv[:, 1])).max() <= 2e-5, (op, i)
            assert np.array_equal(got[-1], before[-1])          # leaf 10: untouched
            assert not np.allclose(got[0], before[0])
        assert r.batches == batches_before and not rebuilt     # nothing rebuilt
        # undo back to the start: the captures are the first ones again
        while (ids := ed.undo()) is not None:
            gpu_edits.update_rows(r, ids)
        assert np.allclose(r.capture(picks), before, atol=1e-6)
        assert gl.ctx.error == "GL_NO_ERROR"


@pytest.mark.gl
def test_width_grows_the_culling_sphere(gl, presets):
    from leafview.gpu.scene import SceneRenderer
    from leafview.gpu.scene_edits import update_rows

    scene = _scene(presets, n=40)
    with SceneRenderer(gl.ctx, scene) as r:
        r0 = r.cull_rows["sphere"][:, 3].copy()
        ed = SceneEditor(scene)
        ed.select(species=0)
        update_rows(r, ed.apply("width", 3.0))
        grown = r.cull_rows["sphere"][:, 3]
        assert grown[0] > r0[0] and grown[1] == r0[1]
        # the sphere holds every drawn vertex of the widened leaves
        ids = np.flatnonzero(scene.species_id == 0)[:5]
        pts = r.capture(ids)
        c = r.cull_rows["sphere"][0, :3]
        assert (np.linalg.norm(pts - c, axis=2).max() <= grown[0])


@pytest.mark.gl
def test_picking(gl, presets):
    from leafview.gpu.picking import pick, pick_box, pick_box_centres, project
    from leafview.gpu.scene import SceneRenderer
    from leafview.scene.camera import scene_camera

    scene = _scene(presets, n=30)
    size = (160, 120)
    cam = scene_camera(scene, size, "top")
    with SceneRenderer(gl.ctx, scene) as r:
        from leafview.gpu.picking import instance_image

        inst = instance_image(r, cam, size)
        visible = np.unique(inst[inst > 0]) - 1
        assert visible.size >= 10
        # a pixel inside a known leaf's own footprint: the middle pixel of its labelled area
        k = int(visible[len(visible) // 2])
        js, is_ = np.nonzero(inst == k + 1)
        m = len(js) // 2
        assert pick(r, cam, size, is_[m] + 0.5, js[m] + 0.5) == k
        bj, bi = np.nonzero(inst == 0)
        assert pick(r, cam, size, bi[0] + 0.5, bj[0] + 0.5) is None
        assert pick(r, cam, size, -5, 3) is None
        box = (0, 0, size[0] // 2 - 1, size[1] - 1)
        got = pick_box(r, cam, size, box)
        assert np.array_equal(got, np.unique(inst[:, : size[0] // 2][inst[:, : size[0] // 2] > 0]) - 1)
        assert 0 < got.size < visible.size
        # centres: every leaf whose base projects into the box, hidden or not
        xy, ok = project(cam, scene.matrices[:, :3, 3], size)
        cen = pick_box_centres(scene, cam, size, box)
        assert np.array_equal(cen, np.flatnonzero(ok & (xy[:, 0] < size[0] // 2)))
        assert np.array_equal(pick_box_centres(scene, cam, size, (0, 0, size[0] - 1, size[1] - 1)),
                              np.flatnonzero(ok & (xy[:, 0] < size[0]) & (xy[:, 1] < size[1])))


def _interior(inst: np.ndarray, label: int) -> tuple[int, int]:
    """A pixel (x, y) of ``label`` whose 5×5 neighbourhood is all ``label``."""
    m = inst == label
    core_ = m.copy()
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            core_ &= np.roll(np.roll(m, dy, 0), dx, 1)
    js, is_ = np.nonzero(core_)
    assert js.size, "no interior pixel"
    return int(is_[js.size // 2]), int(js[js.size // 2])


@pytest.mark.gl
def test_viewer_click_selects_and_edit_undo_round_trips(gl, presets, tmp_path):
    from imgui_bundle import imgui

    from leafview.app.scene_view import PANEL_WIDTH, SceneView
    from leafview.gpu.picking import instance_image

    scene = _scene(presets, n=60)
    view = SceneView(gl.ctx, scene, path=tmp_path / "edited.toml")
    try:
        size = (640, 400)
        view.frame(size)
        px = (size[0] - PANEL_WIDTH, size[1])
        inst = instance_image(view.renderer, view.camera.camera(*px), px)
        labels, counts = np.unique(inst[inst > 0], return_counts=True)
        k = int(labels[np.argmax(counts)]) - 1          # the leaf with the most pixels
        x, y = _interior(inst, k + 1)
        io = imgui.get_io()
        io.add_mouse_pos_event(x + 0.5, y + 0.5)
        view.frame(size)
        io.add_mouse_button_event(0, True)
        view.frame(size)
        io.add_mouse_button_event(0, False)
        view.frame(size)
        assert view.editor.selection.tolist() == [k] and view.edit_panel.target == 2
        f0 = scene.factors.copy()
        before = view.renderer.capture([k, (k + 1) % len(scene)])
        view.edit_panel.width = 1.5
        assert np.array_equal(view.edit_panel.apply(), [k])
        changed = np.flatnonzero((scene.factors != f0).any(axis=1))
        assert changed.tolist() == [k]
        after = view.renderer.capture([k, (k + 1) % len(scene)])
        assert not np.allclose(after[0], before[0]) and np.array_equal(after[1], before[1])
        view.frame(size)
        assert view.edit_panel.save() and load_scene(tmp_path / "edited.toml").edits == view.editor.edits
        # Ctrl+Z: the factors and the drawn leaf as they were
        io.add_key_event(imgui.Key.left_ctrl, True)
        io.add_key_event(imgui.Key.mod_ctrl, True)
        io.add_key_event(imgui.Key.z, True)
        view.frame(size)
        io.add_key_event(imgui.Key.z, False)
        io.add_key_event(imgui.Key.mod_ctrl, False)
        io.add_key_event(imgui.Key.left_ctrl, False)
        view.frame(size)
        assert np.array_equal(scene.factors, f0) and scene.offsets is None
        assert np.allclose(view.renderer.capture([k]), before[:1], atol=1e-6)
        assert not view.gl_errors
        # a box drawn with the right button selects the leaves drawn inside it
        io.add_mouse_pos_event(5, 5)
        view.frame(size)
        io.add_mouse_button_event(1, True)
        view.frame(size)
        io.add_mouse_pos_event(px[0] - 1, px[1] - 1)
        view.frame(size)
        io.add_mouse_button_event(1, False)
        view.frame(size)
        sel = view.editor.selection
        assert sel.size >= 5 and k in sel.tolist()
    finally:
        view.release()
    assert gl.ctx.error == "GL_NO_ERROR"


@pytest.mark.gl
def test_update_rows_with_row_texture_and_lobed(gl, presets):
    """Ripples and bending read the row texture: it follows the edited rows; lobed leaves are left alone."""
    from leafview.deform.surface import grid_uv
    from leafview.gpu.layout import LEAF_BLOCK
    from leafview.gpu.scene import SceneRenderer
    from leafview.gpu.scene_edits import update_rows
    from leafview.scene.spec import evaluate_leaf

    tilted = LeafParams().replace(shape=replace(LeafParams().shape, tilt=(10.0, 0.0, -25.5)))   # extended
    species = (presets["beech"], tilted, presets["maple"], presets["maize"])
    scene = build_scene(SceneSpec(species=species, layout="field", leaves=120, plants=12, seed=4, variation=0.1))
    lobed = np.flatnonzero(scene.species_id == 2)
    assert lobed.size and np.unique(scene.species_id).size == 4
    with SceneRenderer(gl.ctx, scene, max_block_bytes=40 * LEAF_BLOCK.nbytes) as r:
        assert all(b.row_texture is not None for b in r.batches)
        ids = apply_edits(scene, [SceneEdit("width", 1.4)])
        assert not set(ids.tolist()) & set(lobed.tolist()) and ids.size == len(scene) - lobed.size
        update_rows(r, ids)
        uv = grid_uv(*r.grids[0]).astype(np.float64)
        for s in (0, 1, 3):
            picks = np.flatnonzero(scene.species_id == s)[[0, -1]]
            for row, i in zip(r.capture(picks), picks):
                assert np.abs(row - evaluate_leaf(scene, int(i), uv[:, 0], uv[:, 1])).max() <= 5e-5, (s, i)


@pytest.mark.gl
def test_pick_at_a_leafs_projected_centre(gl, presets):
    """Three flat leaves seen from above: a click at the projection of a leaf's midpoint picks it;
    a box around one midpoint selects that leaf; the gap between them is background."""
    from leafview.core.params import Transform
    from leafview.gpu.picking import pick, pick_box, pick_box_centres, project
    from leafview.gpu.scene import SceneRenderer
    from leafview.scene.camera import top_down
    from leafview.scene.spec import evaluate_leaf, scene_from_leaves

    base = presets["ovate"].replace(bending=Bending())
    leaves = [base.replace(transform=Transform(translation=(x, 0.0, 0.0))) for x in (-1.5, 0.0, 1.5)]
    scene = scene_from_leaves(leaves)
    size = (200, 100)
    cam = top_down((0.0, 0.5), 2.0, 2.4, 1.2, 4.0)
    mid = np.array([(scene.matrices[i] @ [*evaluate_leaf(scene, i, np.array([0.0]), np.array([0.5]))[0], 1.0])[:3]
                    for i in range(3)])
    xy, ok = project(cam, mid, size)
    assert ok.all()
    with SceneRenderer(gl.ctx, scene) as r:
        for i in range(3):
            assert pick(r, cam, size, *xy[i]) == i
        gap = (xy[0] + xy[1]) / 2
        assert pick(r, cam, size, *gap) is None
        x, y = xy[2]
        assert pick_box(r, cam, size, (x - 3, y - 3, x + 3, y + 3)).tolist() == [2]
        assert pick_box(r, cam, size, (0, 0, size[0] - 1, size[1] - 1)).tolist() == [0, 1, 2]
        assert pick_box_centres(scene, cam, size, (0, 0, xy[1][0] + 1, size[1] - 1)).tolist() == [0, 1]
