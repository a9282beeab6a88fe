"""Binding points and packed fields are declared once, in leafview/gpu/layout.py: no literal
binding number in shaders/ or in the package's Python, every program's reflected blocks and
samplers sit where the layout says (one buffer per binding), the defines the loader injects are
the Python constants, and every packed-field accessor reads what the packer wrote."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import moderngl
import numpy as np
import pytest

from leafview.app import hotreload
from leafview.botany.catalogue import landmark_leaf
from leafview.botany.landmarks import margin_params
from leafview.core.params import Bending, Jitter
from leafview.deform.wind import WindSettings
from leafview.gpu import layout
from leafview.gpu.canopy import CanopyRenderer
from leafview.gpu.instanced import BakedLeaves, InstancedLeaves
from leafview.gpu.layout import (
    BINDINGS,
    LEAF_BINDING,
    LEAF_BLOCK,
    LEAF_SLOTS,
    LEAVES_BINDING,
    PAIR_MEMBERS,
    READBACK_BINDING,
    binding_defines,
    pack_leaf,
    pack_leaves,
    read_pair,
    read_slot,
    ripple_keys,
)
from leafview.gpu.renderer import LeafRenderer
from leafview.gpu.resources import GpuResources
from leafview.gpu.scene import SceneRenderer
from leafview.gpu.shaders import build_compute, preprocess
from leafview.resources import shader_dir
from leafview.scene.camera import scene_camera
from leafview.scene.lighting import LightSettings
from leafview.scene.spec import SceneSpec, build_scene
from leafview.shapes import shapes_params

ROOT = Path(__file__).resolve().parent.parent
SHADER_SUFFIXES = {".glsl", ".vert", ".frag", ".comp", ".geom"}
_LITERAL_GLSL = re.compile(r"\bbinding\s*=\s*\d")
# Python: a number passed where a binding point goes, or a binding constant defined outside layout.py
_LITERAL_PY = (re.compile(r"bind_to_(?:storage_buffer|uniform_block)\(\s*\d"),
               re.compile(r"\.use\(\s*(?:location\s*=\s*)?\d"),
               re.compile(r"\.binding\s*=\s*\d"),
               re.compile(r"\b[A-Z_]*(?:BINDING|_UNIT)\s*(?:,\s*[A-Z_]+\s*)*=\s*\d"))
# GL sampler types (glGetActiveUniform): sampler1D..2DShadow, arrays, integer samplers, MS
_SAMPLER_TYPES = {0x8B5D, 0x8B5E, 0x8B5F, 0x8B60, 0x8B61, 0x8B62, 0x8DC0, 0x8DC1, 0x8DC4, 0x8DC5, 0x8DC9,
                  0x8DCA, 0x8DCB, 0x8DCC, 0x8DD1, 0x8DD2, 0x8DD3, 0x8DD4, 0x9108, 0x9109, 0x910A, 0x910B}


# -- (a) no literal binding numbers ---------------------------------------------------------------
def test_no_literal_binding_number_in_shaders():
    files = [p for p in sorted(shader_dir().rglob("*")) if p.suffix in SHADER_SUFFIXES]
    assert len(files) >= 10
    bad = [f"{p.relative_to(shader_dir())}:{n}: {line.strip()}"
           for p in files for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
           if _LITERAL_GLSL.search(line)]
    assert bad == [], "binding numbers belong in leafview/gpu/layout.py (use its defines):\n" + "\n".join(bad)


def test_no_literal_binding_number_in_python():
    bad = []
    for path in sorted((ROOT / "leafview").rglob("*.py")):
        if path.name == "layout.py" and path.parent.name == "gpu":
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if any(rx.search(line) for rx in _LITERAL_PY):
                bad.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    assert bad == [], "binding numbers belong in leafview/gpu/layout.py:\n" + "\n".join(bad)


def test_shaders_read_packed_fields_through_their_accessors():
    """A raw ``.back.w`` (or any other slot's member and component) in a shader bypasses the one
    declaration of what the slot holds."""
    raw = [re.compile(rf"\.{slot.member}\.{'xyzw'[slot.component]}\b|\.{slot.member}\.{'rgba'[slot.component]}\b")
           for slot in LEAF_SLOTS]
    raw += [re.compile(rf"\.{member}\[") for member in PAIR_MEMBERS.values()]
    bad = []
    for path in sorted(shader_dir().rglob("*")):
        if path.suffix not in SHADER_SUFFIXES:
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            code = line.split("//", 1)[0]
            if any(rx.search(code) for rx in raw) and "sil_tilt[k / 2]." not in code:  # the prepare pass writes
                bad.append(f"{path.name}:{n}: {line.strip()}")
    assert bad == [], "read packed fields with the generated accessors:\n" + "\n".join(bad)


# -- (c) the generated defines are the Python constants --------------------------------------------
def test_binding_table_and_constants_agree():
    defines = binding_defines()
    assert defines == {b.define: b.number for b in BINDINGS}
    for name, number in defines.items():
        assert getattr(layout, name) == number, name
        assert name in layout.__all__, name
    buffers = [b.number for b in BINDINGS if b.kind != "sampler"]
    units = [b.number for b in BINDINGS if b.kind == "sampler"]
    assert len(set(buffers)) == len(buffers) and len(set(units)) == len(units)
    assert {b.kind for b in BINDINGS} == {"uniform", "storage", "sampler"}


def test_loader_injects_the_defines_into_every_program():
    for name in ("leaf.vert", "leaf.frag", "leaf_baked.vert", "fbm.comp", "leaf_prepare.comp", "scene_cull.comp",
                 "overlay.vert", "overlay_imgui.frag"):
        text = preprocess(name).text
        lines = text.splitlines()
        assert lines[0].startswith("#version")
        for define, number in binding_defines().items():
            assert f"#define {define} {number}" in lines[:len(BINDINGS) + 2], (name, define)
    with pytest.raises(ValueError, match="LEAVES_BINDING"):
        preprocess("leaf.vert", defines={"LEAVES_BINDING": 7})


def _run_probe(gl, tmp_path, body: str, n_out: int, bind=()) -> np.ndarray:
    """Run a one-invocation compute shader with ``body`` writing ``data[]`` (the readback buffer);
    ``bind`` lists (buffer, kind, binding) to bind first."""
    (tmp_path / "probe.comp").write_text(
        "#version 450\nlayout(local_size_x = 1) in;\n#include \"generated/leaf_block.glsl\"\n"
        "layout(std430, binding = LEAVES_BINDING) readonly buffer Leaves { LeafData leaves[]; };\n"
        "layout(std430, binding = READBACK_BINDING) writeonly buffer Out { float data[]; };\n"
        f"void main() {{\n{body}\n}}\n")
    shader = build_compute(gl.ctx, "probe.comp", root=tmp_path)
    out = gl.ctx.buffer(reserve=4 * n_out)
    try:
        for buf, kind, binding in bind:
            (buf.bind_to_uniform_block if kind == "uniform" else buf.bind_to_storage_buffer)(binding)
        out.bind_to_storage_buffer(READBACK_BINDING)
        shader.run(1)
        gl.ctx.memory_barrier()
        return np.frombuffer(out.read(), np.float32).copy()
    finally:
        shader.release()
        out.release()


@pytest.mark.gl
def test_glsl_sees_the_python_binding_numbers(gl, tmp_path):
    names = list(binding_defines())
    body = "\n".join(f"data[{i}] = float({name});" for i, name in enumerate(names))
    data = _run_probe(gl, tmp_path, body, len(names))
    assert data.tolist() == [float(getattr(layout, name)) for name in names]


# -- (d) the accessors read what the packer wrote ---------------------------------------------------
def _packed_leaves(presets):
    """Leaves that put a non-default value in every slot: one-sided halves, an extended
    silhouette (pairs in sil_fg and sil_tilt), several jitter seeds and ripple signals (rows > 0),
    bending with twist."""
    extended = shapes_params("elliptic-concave-extended", polish=False)
    base = presets["ovate"]
    rip = presets["maize"].ripple
    leaves = [
        base,
        base.replace(shape=dataclasses.replace(base.shape, half=-1),
                     jitter=Jitter(enabled=True, seed=3, amplitude=0.04, density=31.0)),
        extended.replace(shape=dataclasses.replace(extended.shape, half=1),
                         jitter=Jitter(enabled=True, seed=5, amplitude=0.02, density=12.5)),
        presets["maize"].replace(bending=Bending(load=8, twist=35)),
        base.replace(ripple=dataclasses.replace(rip, enabled=True, seed=11, veins=44.0),
                     bending=Bending(load=3, twist=-20)),
        extended.replace(ripple=dataclasses.replace(rip, enabled=True, seed=12)),
    ]
    assert any(p.shape.extended for p in leaves)
    return leaves


def _accessor_probe(var: str, pair_counts: dict[str, int]) -> tuple[str, int]:
    lines, k = [], 0
    for slot in LEAF_SLOTS:
        lines.append(f"data[OFS + {k}] = float({slot.accessor}({var}));")
        k += 1
    for accessor, count in pair_counts.items():
        for j in range(count):
            lines.append(f"data[OFS + {k}] = {accessor}({var}, {j}).x; data[OFS + {k + 1}] = {accessor}({var}, {j}).y;")
            k += 2
    return "\n".join(lines), k


def _expected(records: np.ndarray, pair_counts: dict[str, int]) -> np.ndarray:
    cols = [read_slot(records, slot.accessor).astype(np.float32) for slot in LEAF_SLOTS]
    for accessor, count in pair_counts.items():
        for j in range(count):
            pair = read_pair(records, accessor, j)
            cols += [pair[..., 0], pair[..., 1]]
    return np.stack(cols, axis=-1).astype(np.float32)


@pytest.mark.gl
def test_accessors_read_what_the_packer_wrote(gl, tmp_path, presets):
    leaves = _packed_leaves(presets)
    records, _ = pack_leaves(leaves)
    # the packer really filled the slots this test is about
    assert set(read_slot(records, "leaf_half").tolist()) == {-1.0, 0.0, 1.0}
    assert read_slot(records, "leaf_rows").max() > 3 and read_slot(records, "leaf_jitter_row").max() == 1
    assert read_slot(records, "leaf_signal_row").max() == len(ripple_keys(leaves)) - 1 > 0
    assert read_slot(records, "leaf_bend_on").any() and (read_slot(records, "leaf_twist") != 0).any()
    pair_counts = {acc: LEAF_BLOCK.dtype.fields[m][0].shape[0] * 2 for acc, m in PAIR_MEMBERS.items()}
    rng = np.random.default_rng(3)  # the prepare pass writes sil_tilt: give it distinct values here
    records["sil_tilt"] = rng.normal(size=records["sil_tilt"].shape).astype(np.float32)
    n = len(records)
    single = pack_leaf(leaves[2], ripple_row=2)
    ubo_code, k = _accessor_probe("leaf", pair_counts)
    rows_code = "\n".join(_accessor_probe(f"leaves[{i}]", pair_counts)[0].replace("OFS", f"({(i + 1) * k})")
                          for i in range(n))
    body = ubo_code.replace("OFS", "0") + "\n" + rows_code
    ssbo = gl.ctx.buffer(records.tobytes())
    ubo = gl.ctx.buffer(single.tobytes())
    try:
        data = _run_probe(gl, tmp_path, body, (n + 1) * k,
                          bind=[(ubo, "uniform", LEAF_BINDING), (ssbo, "storage", LEAVES_BINDING)])
    finally:
        ssbo.release()
        ubo.release()
    got = data.reshape(n + 1, k)
    np.testing.assert_array_equal(got[0], _expected(single, pair_counts))
    np.testing.assert_array_equal(got[1:], _expected(records, pair_counts))


def test_feature_defines_follow_the_slots(presets):
    leaves = _packed_leaves(presets)
    records, _ = pack_leaves(leaves)
    assert layout.feature_defines(records) == {"LEAF_NO_MARGIN": 1}   # every kind but a landmark margin
    with_margin, _ = pack_leaves([*leaves, margin_params([landmark_leaf("cordate")])[0]])
    assert layout.feature_defines(with_margin) == {}
    assert set(layout.feature_defines(records[:1])) == {"LEAF_NO_EXTENDED", "LEAF_NO_HALF", "LEAF_NO_JITTER",
                                                        "LEAF_NO_RIPPLE", "LEAF_NO_BEND"}


# -- (b) every program the package builds: one buffer per binding, where the layout says ----------
def _without_defines(source: str) -> str:
    """GLSL text without its ``#define`` lines: what differs between permutations of one file."""
    return "\n".join(line for line in source.splitlines() if not line.startswith("#define "))


@pytest.fixture
def built_programs(gl, presets, monkeypatch):
    """(GLSL sources, reflection) of every program and compute shader the package's renderers
    (and the viewer's hot-reload check) build, on a fresh resource set so that nothing comes
    from a cache; each is reflected as soon as it is linked."""
    built: list[tuple[tuple[str, ...], tuple[dict, dict]]] = []
    original_program, original_compute = moderngl.Context.program, moderngl.Context.compute_shader

    def program(self, *, vertex_shader, fragment_shader=None, **kwargs):
        prog = original_program(self, vertex_shader=vertex_shader, fragment_shader=fragment_shader, **kwargs)
        built.append(((vertex_shader, fragment_shader or ""), _reflect(prog)))
        return prog

    def compute_shader(self, source, *args, **kwargs):
        shader = original_compute(self, source, *args, **kwargs)
        built.append(((source,), _reflect(shader)))
        return shader

    monkeypatch.setattr(moderngl.Context, "program", program)
    monkeypatch.setattr(moderngl.Context, "compute_shader", compute_shader)
    ctx = gl.ctx
    leaves = _packed_leaves(presets)
    with GpuResources(ctx) as res:
        with LeafRenderer(ctx, resources=res) as r:
            r.render_many(leaves, (32, 32), "three-quarter")
            r.capture(leaves[2], [0.5], [0.5])
            r.set_leaf(presets["beech"])   # draw's close-up veins: both vein tube programs
            assert r.vein_tubes.program is not None and r.vein_tubes.frame_program is not None
        records, tables = pack_leaves(leaves)
        with InstancedLeaves(ctx, records, (5, 9), jitter_tables=tables, ripple_signals=ripple_keys(leaves),
                             resources=res) as inst, BakedLeaves.from_instanced(inst, resources=res):
            pass
        scene = build_scene(SceneSpec(species=(presets["ovate"], presets["maize"]), leaves=40, seed=2, plants=2))
        assert scene.stems is not None
        with SceneRenderer(ctx, scene, resources=res) as s:
            s.render(scene_camera(scene, (32, 32)), (32, 32), samples=0)
            # the canopy look: shadows, sky, ground, occlusion, wind (and the shadowed ground variant)
            with CanopyRenderer(s, LightSettings(ssao=True), WindSettings(speed=4.0)) as c:
                c.render(scene_camera(scene, (32, 32)), (32, 32), samples=0)
            s.capture([0], defines={"LEAF_WIND": 1})
        hotreload.compile_check(ctx)   # the viewer's programs: leaf, overlay, imgui, reference photo (built and released)
        monkeypatch.undo()
        yield built
    assert ctx.error == "GL_NO_ERROR"


def _reflect(prog) -> tuple[dict[str, tuple[str, int]], dict[str, int]]:
    """({block name: (kind, binding)}, {sampler name: unit}) of a linked program."""
    blocks, samplers = {}, {}
    for name in prog:
        member = prog[name]
        if isinstance(member, moderngl.UniformBlock):
            blocks[name] = ("uniform", member.binding)
        elif isinstance(member, moderngl.StorageBlock):
            blocks[name] = ("storage", member.binding)
        elif isinstance(member, moderngl.Uniform) and member.gl_type in _SAMPLER_TYPES:
            samplers[name] = member.value
    return blocks, samplers


@pytest.mark.gl
def test_every_program_binds_each_buffer_where_the_layout_says(built_programs):
    by_name = {b.name: b for b in BINDINGS if b.name}
    assert len(built_programs) >= 10
    seen = set()
    for _, (blocks, samplers) in built_programs:
        buffers: dict[int, str] = {}
        for name, (kind, binding) in blocks.items():
            assert name in by_name, f"block {name} is not declared in layout.BINDINGS"
            assert (kind, binding) == (by_name[name].kind, by_name[name].number), name
            assert binding not in buffers, f"{name} and {buffers[binding]} share binding {binding}"
            buffers[binding] = name
            seen.add(name)
        units: dict[int, str] = {}
        for name, unit in samplers.items():
            assert name in by_name and by_name[name].kind == "sampler", f"sampler {name} is not in layout.BINDINGS"
            assert unit == by_name[name].number, name
            assert unit not in units, f"samplers {name} and {units[unit]} share unit {unit}"
            units[unit] = name
            seen.add(name)
    # every block and sampler the layout names is used by some program (no stale declarations)
    assert seen == set(by_name)


@pytest.mark.gl
def test_the_workload_builds_every_shader_entry_point(built_programs):
    """Each shader file with a ``#version`` line is part of some program built above, so the
    binding test sees every program (a new shader must be added to the workload)."""
    entries = sorted(p.name for p in shader_dir().iterdir()
                     if p.suffix in SHADER_SUFFIXES
                     and re.search(r"^\s*#\s*version", p.read_text(encoding="utf-8"), re.M))
    sources = {_without_defines(src) for srcs, _ in built_programs for src in srcs if src}
    missing = [name for name in entries if _without_defines(preprocess(name).text) not in sources]
    assert missing == [], f"shaders built by no renderer of the workload: {missing}"
