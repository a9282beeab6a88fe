"""The leaf record as per-instance vertex attributes: the layout's attribute formats, the branch
code of the prepare pass, the scene's vertex records (scene_compact.comp) against their numpy
twin, and positions read back from one instanced draw and one scene draw of plain, jittered,
rippled, bent, extended and one-sided leaves against the numpy reference."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from leafview.botany.catalogue import landmark_leaf, random_instance
from leafview.botany.landmarks import margin_params
from leafview.core.params import Bending, Jitter, Transform
from leafview.deform.surface import drawn_uv, grid_uv, tessellate
from leafview.gpu.instanced import InstancedLeaves, OffscreenTarget
from leafview.gpu.layout import (
    DRAW_COMMAND_DTYPE,
    LEAF_ATTRIBUTES,
    LEAF_BLOCK,
    LEAF_VERTEX_BLOCK,
    MARGIN_ROWS,
    MAX_VERTEX_ATTRIBUTES,
    ROW_TEXELS,
    ROWS_PER_LINE,
    attribute_format,
    branch_code,
    feature_defines,
    pack_leaves,
    read_slot,
    ripple_keys,
    vertex_records,
)
from leafview.gpu.scene import CullSettings, SceneRenderer, cull_reference
from leafview.scene.camera import scene_camera
from leafview.scene.spec import SceneSpec, build_scene, evaluate_leaf
from leafview.shapes import shapes_params
from tests.conftest import run_prepare

TOL = 2e-5     # leaf space, as the other readback tests
WORLD_TOL = 1e-4


def _mixed(presets) -> dict:
    """One leaf of each kind the vertex stage branches on."""
    ovate = presets["ovate"]
    extended = shapes_params("elliptic-concave-extended", polish=False)
    rip = presets["maize"].ripple
    cordate = random_instance(landmark_leaf("cordate"), seed=5, amount=0.2)
    margin = margin_params([cordate], ovate.replace(shape=dataclasses.replace(ovate.shape, half=0)))[0]
    return {
        "plain": ovate,
        "jittered": presets["serrate"].replace(jitter=Jitter(enabled=True, seed=4, amplitude=0.05, density=20.0)),
        "rippled": ovate.replace(ripple=dataclasses.replace(rip, enabled=True, seed=7)),
        "bent": ovate.replace(bending=Bending(load=6, twist=25)),
        "rippled and bent": presets["maize"],
        "extended": extended,
        "one-sided": ovate.replace(shape=dataclasses.replace(ovate.shape, half=-1)),
        "extended, jittered": extended.replace(jitter=Jitter(enabled=True, seed=9, amplitude=0.03, density=14.0)),
        "landmark margin": margin,
        "landmark margin, rippled and bent": margin.replace(ripple=presets["maize"].ripple, bending=Bending(load=4, twist=-20)),
    }


def _offsets(fmt: str) -> tuple[list[int], int]:
    """Byte offsets of the ``4f`` entries of a moderngl format, and its stride."""
    assert fmt.endswith("/i")
    at, offsets = 0, []
    for part in fmt[:-2].split():
        m = re.fullmatch(r"(\d*)([fx])", part.replace("4f", "f"))
        assert m, part
        if m.group(2) == "f":
            offsets.append(at)
            at += 16
        else:
            at += int(m.group(1))
    return offsets, at


# -- layout (no GL) ---------------------------------------------------------------------------------
def test_attributes_cover_the_vertex_block_and_fit_the_attribute_limit():
    assert len(LEAF_ATTRIBUTES) + 1 <= MAX_VERTEX_ATTRIBUTES          # + in_uv
    assert len(LEAF_ATTRIBUTES) * 16 == LEAF_VERTEX_BLOCK.nbytes      # every vec4 of the record, once
    names = {name for name, _, _ in LEAF_VERTEX_BLOCK.members}
    assert names <= {name for name, _, _ in LEAF_BLOCK.members}
    # the members only the optional branches read stay out of the attributes
    assert names.isdisjoint({"deform", "ripple_l", "ripple_r", "bend_axis", "bend", "tilt", "sil_rows", "sil_axis"})


@pytest.mark.parametrize("block", [LEAF_BLOCK, LEAF_VERTEX_BLOCK], ids=["in place", "compact"])
def test_attribute_format_reads_each_member_where_the_block_holds_it(block):
    fmt, names = attribute_format(block)
    offsets, stride = _offsets(fmt)
    assert stride == block.nbytes
    assert names == tuple(a.name for a in LEAF_ATTRIBUTES)
    # numpy: the float32s at each offset are the member's element the attribute names
    rows = np.zeros(2, block.dtype)
    rows.view(np.float32)[:] = np.arange(rows.nbytes // 4, dtype=np.float32)
    flat = rows.view(np.float32).reshape(2, -1)
    for attr, offset in zip(LEAF_ATTRIBUTES, offsets):
        element = rows[attr.member][1].reshape(-1, 4)[attr.element]   # a mat4's numpy row is GLSL's column
        np.testing.assert_array_equal(flat[1, offset // 4:offset // 4 + 4], element, err_msg=attr.name)
    # attributes a program compiled out become padding: the others keep their offsets
    kept = [a.name for a in LEAF_ATTRIBUTES if "jitter" not in a.name and "a2" not in a.name]
    fmt2, names2 = attribute_format(block, present=set(kept))
    offsets2, stride2 = _offsets(fmt2)
    assert names2 == tuple(kept) and stride2 == block.nbytes
    assert offsets2 == [o for a, o in zip(LEAF_ATTRIBUTES, offsets) if a.name in kept]


# -- GL -------------------------------------------------------------------------------------------
@pytest.mark.gl
def test_prepare_pass_writes_the_branch_code(gl, presets):
    leaves = list(_mixed(presets).values())
    records, _ = pack_leaves(leaves)
    code = branch_code(records)
    rows = [MARGIN_ROWS if p.margin is not None else p.shape.rows if p.shape.extended else 0 for p in leaves]
    assert code.tolist() == [int(p.ripple.enabled) + 2 * int(p.bending.active) + 4 * n for p, n in zip(leaves, rows)]
    assert {0, 1, 2, 3} < set(code.tolist()) and max(rows) > 3
    out = run_prepare(gl, records)
    np.testing.assert_array_equal(read_slot(out, "leaf_branches"), code)


@pytest.mark.gl
def test_one_instanced_draw_of_every_kind_matches_numpy(gl, presets):
    kinds = list(_mixed(presets).items())
    n = ROWS_PER_LINE + 2 * len(kinds)   # the row texture's second line is read too
    # each kind turned its own way (bending follows gravity), each leaf moved to its own place
    leaves = [kinds[i % len(kinds)][1].replace(transform=Transform(
        translation=(0.3 * i, -0.1 * i, 0.05 * i), rotation=(10.0 * (i % len(kinds)), -15.0, 40.0 * (i % len(kinds))),
        scale=0.6)) for i in range(n)]
    records, tables = pack_leaves(leaves)
    assert feature_defines(records) == {}   # one program with every branch, one draw for all

    grid = (9, 15)
    with OffscreenTarget(gl.ctx, (1, 1)) as target, \
            InstancedLeaves(gl.ctx, records, grid, jitter_tables=tables, ripple_signals=ripple_keys(leaves),
                            resources=gl.resources) as inst:
        target.use()
        pos, nrm = inst.capture()
    assert gl.ctx.error == "GL_NO_ERROR"
    meshes = {name: tessellate(leaves[k], *grid) for k, (name, _) in enumerate(kinds)}
    for i in list(range(len(kinds))) + list(range(n - len(kinds), n)):
        name, p = kinds[i % len(kinds)][0], leaves[i]
        mesh = meshes[name]
        m = p.transform.matrix()
        ref = mesh.vertices @ m[:3, :3].T + m[:3, 3]
        assert np.abs(pos[i] - ref).max() < WORLD_TOL, (name, np.abs(pos[i] - ref).max())
        ref_n = mesh.normals @ m[:3, :3].T
        ref_n /= np.linalg.norm(ref_n, axis=1, keepdims=True)
        assert np.abs(nrm[i] - ref_n).max() < 2e-3, (name, np.abs(nrm[i] - ref_n).max())


@pytest.fixture(scope="module")
def mixed_scene(presets):
    species = tuple(_mixed(presets).values())
    return build_scene(SceneSpec(species=species, leaves=200, seed=3, plants=30))  # every species appears


@pytest.mark.gl
def test_scene_draw_reads_every_kind_as_numpy(gl, mixed_scene):
    """Capture through the vertex records of scene_compact.comp and the draw program, two levels,
    leaves spread over three batches (the row of a record is batch-local)."""
    scene = mixed_scene
    kinds = len(scene.species)
    picks = [int(i) for k in range(kinds) for i in np.flatnonzero(scene.species_id == k)[-2:]]
    assert len(picks) == 2 * kinds
    with SceneRenderer(gl.ctx, scene, max_block_bytes=80 * LEAF_BLOCK.nbytes, resources=gl.resources) as r:
        assert len(r.batches) == 3
        for level in (0, 2):
            got = r.capture(picks, level)
            uv = grid_uv(*r.grids[level]).astype(np.float64)
            for row, i in zip(got, picks):
                duv = drawn_uv(scene.leaf(i), uv)
                ref = evaluate_leaf(scene, i, duv[:, 0], duv[:, 1])
                err = np.abs(row - ref).max()
                assert err <= TOL, (i, int(scene.species_id[i]), level, err)
    assert gl.ctx.error == "GL_NO_ERROR"


@pytest.mark.gl
def test_vertex_records_of_a_frame_equal_numpy(gl, mixed_scene):
    """After a draw, each level's records start at its command's baseInstance, hold exactly the
    leaves of that level, and are the rows' LeafVertex members with the row in leaf_vertex_row.
    The batches share one record buffer, each batch's culling pass overwriting it just before its
    draw: after a frame it holds the last batch's records, so each batch is also drawn alone and its
    records read then (the levels must not change by that)."""
    scene = mixed_scene
    size = (96, 64)
    cam = scene_camera(scene, size, "three-quarter")
    cam = type(cam)(cam.view, cam.proj @ np.diag([2.0, 2.0, 1.0, 1.0]), cam.eye, cam.perspective)  # some culled
    settings = CullSettings(max_error_px=0.3)
    with SceneRenderer(gl.ctx, scene, max_block_bytes=100 * LEAF_BLOCK.nbytes, resources=gl.resources) as r, \
            OffscreenTarget(gl.ctx, size) as target:
        assert len(r.batches) >= 2 and all(b.vertices is r.vertices for b in r.batches)
        target.use()
        r.set_camera(cam, size)
        r.draw(settings)
        levels = r.levels()
        last = np.frombuffer(r.vertices.read(), LEAF_VERTEX_BLOCK.dtype)
        for i, b in enumerate(r.batches):
            r.draw(settings, batches=[i])
            rows = np.frombuffer(b.rows.read(), LEAF_BLOCK.dtype)
            commands = np.frombuffer(b.commands.read(), DRAW_COMMAND_DTYPE)
            records = np.frombuffer(r.vertices.read(), LEAF_VERTEX_BLOCK.dtype)
            counts = commands["instance_count"].astype(int)
            if i == len(r.batches) - 1:   # the frame left its last batch's records, the same ones
                n = int(counts.sum())
                assert sorted(x.tobytes() for x in last[:n]) == sorted(x.tobytes() for x in records[:n])
            assert list(commands["base_instance"]) == list(np.r_[0, np.cumsum(counts)[:-1]])
            for k, (first, n) in enumerate(zip(commands["base_instance"], counts)):
                got = records[first:first + n]
                row = read_slot(got, "leaf_vertex_row")
                assert sorted(row.tolist()) == np.flatnonzero(levels[b.start:b.start + b.count] == k).tolist()
                want = vertex_records(rows, row)
                assert got.tobytes() == want.tobytes(), (b.start, k)
        assert np.array_equal(r.levels(), levels)
    ref = cull_reference(scene, r.cull_rows, cam, size, CullSettings(max_error_px=0.3))
    assert np.array_equal(levels, ref)
    assert (levels == -1).any() and len(set(levels.tolist()) - {-1}) >= 2
    assert gl.ctx.error == "GL_NO_ERROR"


@pytest.mark.gl
def test_row_texture_holds_the_rows_texel_for_texel(gl):
    from leafview.gpu.resources import RowTexture

    n = ROWS_PER_LINE + 5
    rows = np.random.default_rng(2).normal(size=(n, ROW_TEXELS * 4)).astype(np.float32)
    buf = gl.ctx.buffer(rows.tobytes())
    try:
        tex = RowTexture(gl.ctx, buf, n)
        try:
            width, height = tex.texture.size
            got = np.frombuffer(tex.texture.read(), np.float32).reshape(height, width // ROW_TEXELS, ROW_TEXELS * 4)
        finally:
            tex.release()
    finally:
        buf.release()
    assert (width, height) == (ROWS_PER_LINE * ROW_TEXELS, 2)
    np.testing.assert_array_equal(got.reshape(-1, ROW_TEXELS * 4)[:n], rows)   # row r: line r // ROWS_PER_LINE
