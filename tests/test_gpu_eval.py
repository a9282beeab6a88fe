"""The rendering vertex shader, read back through transform feedback, against the numpy
reference; the parameter layout against the linked program's reflection."""

import dataclasses

import numpy as np
import pytest

import leafview
from leafview.botany.catalogue import landmark_leaf
from leafview.botany.landmarks import margin_params
from leafview.core.params import Jitter
from leafview.deform.surface import grid_uv
from leafview.gpu.layout import (
    FRAME_BLOCK,
    LEAF_BINDING,
    LEAF_BLOCK,
    LEAVES_BINDING,
    READBACK_BINDING,
    branch_code,
    pack_leaf,
    read_slot,
    without_derived,
)
from tests.conftest import random_params, run_prepare

pytestmark = pytest.mark.gl
TOL = 2e-5


@pytest.mark.parametrize("jitter", [False, True], ids=["jitter-off", "jitter-on"])
def test_readback_matches_reference_on_random_leaves(gl, jitter):
    rng = np.random.default_rng(100 + jitter)
    worst = 0.0
    for _ in range(60):
        params = random_params(rng, jitter=jitter)
        u = np.r_[rng.uniform(-1, 1, 400), -1, 1, 0, 0.5]
        v = np.r_[rng.uniform(0, 1, 400), 0.5, 0.5, 1, 0]
        gpu = leafview.gpu.evaluate(params, u, v)
        assert gpu.dtype == np.float32 and gpu.shape == (404, 3)
        worst = max(worst, float(np.abs(gpu - leafview.evaluate(params, u, v)).max()))
    assert worst <= TOL, f"largest GPU/CPU difference {worst:.3g} > {TOL}"


def test_readback_on_the_render_grid_and_normals(gl, presets):
    uv = grid_uv(33, 65)
    for name, params in presets.items():
        pos, nrm = gl.capture(params, uv[:, 0], uv[:, 1])
        np.testing.assert_allclose(pos, leafview.evaluate(params, uv[:, 0], uv[:, 1]), atol=TOL, err_msg=name)
        ref = leafview.normals(params, uv[:, 0], uv[:, 1])
        cos = np.sum(nrm * ref, axis=1)
        assert cos.min() > 1 - 1e-4, f"{name}: normal off by {np.degrees(np.arccos(cos.min())):.3f}°"


@pytest.mark.parametrize("half", [-1, 1])
def test_one_sided_leaf_spreads_the_grid_over_its_half(gl, presets, half):
    """shape.half = ±1 (the sides of an asymmetric leaf): the shader evaluates the surface at
    drawn_uv of the grid, the reference of leafview.deform.surface; positions, normals and the
    tessellated mesh agree, and every vertex lies on the chosen half."""
    from dataclasses import replace

    from leafview.deform.surface import drawn_uv, tessellate

    uv = grid_uv(33, 65)
    for name in ("ovate", "asymmetric", "maize", "serrate"):
        params = presets[name]
        params = params.replace(shape=replace(params.shape, half=half))
        drawn = drawn_uv(params, uv)
        assert (half * drawn[:, 0] >= 0).all() and np.ptp(drawn[:, 0]) == 1.0
        pos, nrm = gl.capture(params, uv[:, 0], uv[:, 1])
        np.testing.assert_allclose(pos, leafview.evaluate(params, drawn[:, 0], drawn[:, 1]), atol=TOL, err_msg=name)
        cos = np.sum(nrm * leafview.normals(params, drawn[:, 0], drawn[:, 1]), axis=1)
        assert cos.min() > 1 - 1e-4, name
        np.testing.assert_allclose(pos, tessellate(params, 33, 65).vertices, atol=TOL, err_msg=name)


def test_jitter_changes_reach_the_shader(gl):
    base = leafview.LeafParams()
    u, v = np.ones(50), np.linspace(0.1, 0.9, 50)
    a = leafview.gpu.evaluate(base.replace(jitter=Jitter(enabled=True, amplitude=0.05, seed=1)), u, v)
    b = leafview.gpu.evaluate(base.replace(jitter=Jitter(enabled=True, amplitude=0.05, seed=2)), u, v)
    c = leafview.gpu.evaluate(base.replace(jitter=Jitter(enabled=True, amplitude=0.02, seed=2)), u, v)
    assert np.abs(a - b).max() > 1e-3 and np.abs(b - c).max() > 1e-3


def test_amplitude_and_density_update_only_the_uniform_block(gl):
    p = leafview.LeafParams().replace(jitter=Jitter(enabled=True, seed=42))
    gl.set_leaf(p)
    before = gl.uploads
    for amp, dens in ((0.01, 10.0), (0.05, 80.0), (0.03, 33.0)):
        gl.set_leaf(p.replace(jitter=Jitter(enabled=True, seed=42, amplitude=amp, density=dens)))
    assert gl.uploads - before == 3 * LEAF_BLOCK.nbytes  # no texture, no geometry re-uploaded
    assert LEAF_BLOCK.nbytes < 1024


def test_blocks_match_reflection(gl):
    assert gl.program["Leaf"].size == LEAF_BLOCK.nbytes
    assert gl.program["Frame"].size == FRAME_BLOCK.nbytes


def _flatten_glsl(var: str) -> str:
    """GLSL that writes every member of ``var`` (a LeafData) to data[] in declaration order."""
    lines, k = [], 1
    for name, glsl, count in LEAF_BLOCK.members:
        idx = [f"[{i}]" for i in range(4)] if glsl != "mat4" else [f"[{c}][{r}]" for c in range(4) for r in range(4)]
        if count > 1:
            idx = [f"[{k}]{i}" for k in range(count) for i in idx]
        for i in idx:
            lines.append(f"data[OFS + {k}] = float({var}.{name}{i});")
            k += 1
    return "\n".join(lines)


def test_every_member_offset_matches_std140_and_std430(gl, tmp_path):
    """A compute shader copies each member of the uniform block and of storage row 1 out; the
    floats must come back in exactly the order of the numpy dtype (so every offset agrees)."""
    from leafview.gpu.shaders import build_compute

    n_floats = LEAF_BLOCK.nbytes // 4
    (tmp_path / "probe.comp").write_text(
        "#version 450\nlayout(local_size_x = 1) in;\n#include \"generated/leaf_block.glsl\"\n"
        "layout(std430, binding = LEAVES_BINDING) readonly buffer Leaves { LeafData leaves[]; };\n"
        "layout(std430, binding = READBACK_BINDING) writeonly buffer Out { float data[]; };\n"
        "void main() {\n  data[0] = float(leaves.length());\n"
        f"#define OFS 0\n{_flatten_glsl('leaf')}\n#undef OFS\n#define OFS {n_floats}\n{_flatten_glsl('leaves[1]')}\n}}\n")
    rng = np.random.default_rng(9)
    rows = np.zeros(3, dtype=LEAF_BLOCK.dtype)
    rows.view(np.float32)[:] = rng.normal(size=3 * n_floats).astype(np.float32)
    ubo_rec = pack_leaf(random_params(rng, jitter=True))
    shader = build_compute(gl.ctx, "probe.comp", root=tmp_path)
    ubo = gl.ctx.buffer(ubo_rec.tobytes())
    ssbo = gl.ctx.buffer(rows.tobytes())
    out = gl.ctx.buffer(reserve=4 * (1 + 2 * n_floats))
    try:
        ubo.bind_to_uniform_block(LEAF_BINDING)
        ssbo.bind_to_storage_buffer(LEAVES_BINDING)
        out.bind_to_storage_buffer(READBACK_BINDING)
        shader.run(1)
        data = np.frombuffer(out.read(), dtype=np.float32)
    finally:
        for obj in (shader, ubo, ssbo, out):
            obj.release()
    assert data[0] == 3  # leaves.length() = buffer bytes / row stride: stride == LEAF_BLOCK.nbytes
    np.testing.assert_array_equal(data[1:1 + n_floats], np.frombuffer(ubo_rec.tobytes(), np.float32))
    np.testing.assert_array_equal(data[1 + n_floats:], rows[1:2].view(np.float32))


def test_prepare_pass_matches_reference(gl):
    """leaf_prepare.comp writes A(v̄_i), x̄s_i n(v̄_i) (eqs 2-4) and the heights into each row."""
    from leafview.deform.surface import axis_frames
    from leafview.gpu.layout import pack_leaves

    rng = np.random.default_rng(21)
    leaves = [random_params(rng) for _ in range(70)]  # more than one 64-wide work group
    records, _ = pack_leaves(leaves)
    assert not records["axis"].any() and not records["heights"].any()  # the GPU fills them
    out = run_prepare(gl, records)
    for rec, leaf in zip(out, leaves):
        p, q = axis_frames(leaf)
        np.testing.assert_allclose(rec["axis"][:, :3], p, atol=2e-6)
        np.testing.assert_allclose(rec["axis"][:, 3], q[:, 0], atol=2e-6)
        np.testing.assert_allclose(rec["heights"][:, 3], q[:, 1], atol=2e-6)
        assert not q[:, 2].any()  # the in-plane normal has no z (eq. 2): two numbers suffice
        s = leaf.shape
        np.testing.assert_array_equal(rec["heights"][:, :3], np.float32(np.c_[s.zf, s.zg, s.zs]))
    rest = [name for name, _, _ in LEAF_BLOCK.members if name not in ("axis", "heights")]
    host = without_derived(out)
    for name in rest:  # and touches nothing else but the derived slots
        np.testing.assert_array_equal(host[name], records[name])
    np.testing.assert_array_equal(read_slot(out, "leaf_branches"), branch_code(records))


def test_pack_leaf_fields():
    p = leafview.LeafParams().replace(jitter=Jitter(enabled=False, amplitude=0.05))
    rec = pack_leaf(p)
    assert rec.dtype.itemsize == LEAF_BLOCK.nbytes
    assert rec["jitter"][0] == 0.0  # jitter off means amplitude 0 on the GPU
    np.testing.assert_allclose(rec["vbar"][:3], p.shape.vbar, atol=1e-7)
    np.testing.assert_allclose(rec["model"].T, p.transform.matrix(), atol=1e-7)


def test_generated_glsl_declares_every_member():
    text = LEAF_BLOCK.glsl(0)
    for name, glsl, count in LEAF_BLOCK.members:
        assert f"{glsl} {name}{'' if count == 1 else f'[{count}]'};" in text


def test_single_leaf_jitter_after_a_multi_seed_batch(gl, presets):
    """A batch with several seeds grows the jitter texture; single-leaf edits still upload and
    read their own row afterwards."""
    seeds = [presets["ovate"].replace(jitter=Jitter(enabled=True, seed=s)) for s in range(5)]
    gl.render_many(seeds, (24, 24))
    one = presets["ovate"].replace(jitter=Jitter(enabled=True, seed=77, amplitude=0.05))
    u, v = np.ones(64), np.linspace(0.05, 0.95, 64)
    np.testing.assert_allclose(leafview.gpu.evaluate(one, u, v), leafview.evaluate(one, u, v), atol=TOL)


def test_parameter_bytes_exclude_exactly_the_derived_members():
    names = [name for name, _, _ in LEAF_BLOCK.members]
    assert set(LEAF_BLOCK.derived) <= set(names)
    derived = sum(LEAF_BLOCK.dtype.fields[n][0].itemsize for n in LEAF_BLOCK.derived)
    assert LEAF_BLOCK.parameter_nbytes + derived == LEAF_BLOCK.nbytes
    assert LEAF_BLOCK.nbytes <= 1024  # one leaf's uniform block stays well under 1 KiB


def test_shader_permutations_match_the_full_program(gl, presets):
    """For every preset, the variant compiled for its features (see feature_defines) captures
    the full program's vertices and normals, to float rounding: the same equations, but the
    compiler may contract a multiply-add differently in the larger program (up to 7.5e-8 seen)."""
    from leafview.gpu.layout import feature_defines, pack_leaf
    from leafview.shapes import shapes_params

    plain = {"LEAF_NO_EXTENDED", "LEAF_NO_HALF"}
    assert set(feature_defines(pack_leaf(presets["ovate"]))) == {"LEAF_NO_JITTER", "LEAF_NO_RIPPLE", "LEAF_NO_BEND",
                                                                  *plain}
    assert set(feature_defines(pack_leaf(presets["willow"]))) == {"LEAF_NO_JITTER", *plain}
    assert "LEAF_NO_JITTER" not in feature_defines(pack_leaf(presets["serrate"]))
    extended = shapes_params("elliptic-concave-extended", polish=False)
    one_side = presets["ovate"].replace(shape=dataclasses.replace(presets["ovate"].shape, half=-1))
    bent = dataclasses.replace(presets["ovate"].shape, a1=(0.06, 0.3, 0.02), a2=(-0.05, 0.72, 0.05))
    margin = margin_params([landmark_leaf("cordate")], presets["ovate"].replace(shape=bent))[0]
    assert "LEAF_NO_EXTENDED" not in feature_defines(pack_leaf(extended))
    assert {"LEAF_NO_MARGIN"} <= set(feature_defines(pack_leaf(extended))) - {"LEAF_NO_SIL_ROWS"}
    assert {"LEAF_NO_SIL_ROWS"} <= set(feature_defines(pack_leaf(margin))) - {"LEAF_NO_MARGIN"}
    both = np.concatenate([pack_leaf(extended)[None], pack_leaf(margin)[None]])
    assert not {"LEAF_NO_EXTENDED", "LEAF_NO_MARGIN", "LEAF_NO_SIL_ROWS"} & set(feature_defines(both))
    assert "LEAF_NO_HALF" not in feature_defines(pack_leaf(one_side))
    leaves = {**presets, "extended": extended, "one side": one_side, "margin": margin,
              "extended, one side": extended.replace(shape=dataclasses.replace(extended.shape, half=1))}
    uv = leafview.deform.surface.grid_uv(9, 15)
    for name, leaf in leaves.items():
        outs = [np.concatenate(gl.capture(leaf, uv[:, 0], uv[:, 1], defines=defines), axis=1)
                for defines in (None, feature_defines(pack_leaf(leaf)))]  # None: the full program
        np.testing.assert_allclose(outs[0], outs[1], rtol=0, atol=2e-7, err_msg=name)
