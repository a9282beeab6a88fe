"""The one declaration of the GPU data layouts: each block is a list of (name, GLSL type, count).

From it come the numpy structured dtype (what Python fills) and the GLSL struct text (what the
shaders see, served to the loader as ``#include "generated/<name>.glsl"``). Members are restricted
to ``vec4``/``ivec4``/``mat4`` (and arrays of them) so the std140 (uniform block) and std430
(storage buffer row) packings coincide with the dense numpy packing: no padding rules to drift.
A test checks each block against the size the linked program reflects.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.core.blade import APEX, BASE, JITTER_TABLE_SIZE, jitter_table
from leafview.core.params import MAX_SILHOUETTE_ROWS, LeafParams
from leafview.deform.beam import BEND_SAMPLES, bend_profile
from leafview.deform.fbm import RIPPLE_SAMPLES

__all__ = ["Block", "LEAF_BLOCK", "FRAME_BLOCK", "SPECIES_CULL_BLOCK", "DRAW_COMMAND_DTYPE", "LEAF_BINDING", "FRAME_BINDING", "LEAVES_BINDING", "pack_leaf", "pack_leaves", "ripple_keys", "feature_defines", "generated_sources"]

_TYPES = {"vec4": ("<f4", (4,)), "ivec4": ("<i4", (4,)), "mat4": ("<f4", (4, 4))}


@dataclass(frozen=True)
class Block:
    """A GLSL struct ``struct_name`` and the uniform block ``block_name`` that holds one of it."""

    struct_name: str
    block_name: str
    members: tuple[tuple[str, str, int], ...]
    doc: str = ""
    derived: tuple[str, ...] = ()  # members computed from the others (not parameters)

    @property
    def dtype(self) -> np.dtype:
        fields = []
        for name, glsl, count in self.members:
            base, shape = _TYPES[glsl]
            fields.append((name, base, shape if count == 1 else (count, *shape)))
        return np.dtype(fields)

    @property
    def nbytes(self) -> int:
        return self.dtype.itemsize

    @property
    def parameter_nbytes(self) -> int:
        """Bytes of the members that hold parameters (all but the derived ones)."""
        dt = self.dtype
        return sum(dt.fields[name][0].itemsize for name, _, _ in self.members if name not in self.derived)

    def struct_glsl(self) -> str:
        lines = [f"// generated from leafview/gpu/layout.py: {self.doc}", f"struct {self.struct_name} {{"]
        for name, glsl, count in self.members:
            lines.append(f"    {glsl} {name}{'' if count == 1 else f'[{count}]'};")
        return "\n".join(lines + ["};", ""])

    def glsl(self, binding: int) -> str:
        lines = [self.struct_glsl().rstrip("\n"), f"layout(std140, binding = {binding}) uniform {self.block_name} {{",
                  f"    {self.struct_name} {self.block_name.lower()};", "};", ""]
        return "\n".join(lines)

    def zeros(self) -> np.ndarray:
        return np.zeros((), dtype=self.dtype)


SIL_EXTRA_ROWS = MAX_SILHOUETTE_ROWS - 3   # silhouette rows beyond the paper's three
_PAIRS = lambda n: -(-n // 2)  # noqa: E731  (vec4s holding n xy pairs)

LEAF_BLOCK = Block(
    "LeafData", "Leaf",
    (
        ("a1", "vec4", 1),         # axis control point a1 (xyz)
        ("a2", "vec4", 1),         # axis control point a2 (xyz)
        ("vbar", "vec4", 1),       # v̄1..3
        ("xs", "vec4", 1),         # x̄s1..3
        ("zs", "vec4", 1),         # z̄s1..3
        ("zf", "vec4", 1),         # z̄f1..3
        ("zg", "vec4", 1),         # z̄g1..3
        ("jitter", "vec4", 1),     # amplitude (0 when off), density, table size, table row
        ("front", "vec4", 1),      # front rgb, translucency
        ("back", "vec4", 1),       # back rgb, drawn half (shape.half: 0 both, ±1 one half)
        ("model", "mat4", 1),      # leaf space -> world
        ("deform", "vec4", 1),     # ripple on (0/1), bend on (0/1), secondary veins, signal row
        ("ripple_l", "vec4", 1),   # P, λ, k, θ of eq. 5 for the u >= 0 half (left in the top view)
        ("ripple_r", "vec4", 1),   # P, λ, k, θ for the u < 0 half
        ("bend_axis", "vec4", 1),  # bend axis N (leaf space), twist at the apex (radians)
        # extended silhouette (leafview.core.params: N > 3 rows and/or tilted rows):
        ("tilt", "vec4", 1),       # φ_1..3 (radians); w: N when the leaf is extended, else 0
        ("sil_rows", "vec4", SIL_EXTRA_ROWS),  # rows 4..N: v̄_i, x̄s_i, z̄s_i, φ_i (radians)
        ("sil_fg", "vec4", _PAIRS(SIL_EXTRA_ROWS)),  # rows 4..N: (z̄f_i, z̄g_i) pairs
        # derived on the GPU by leaf_prepare.comp, packed so the vertex shader loads 6 vec4s:
        ("axis", "vec4", 3),       # xyz A(v̄_i), w (x̄s_i cos φ_i · n(v̄_i)).x
        ("heights", "vec4", 3),    # z̄f_i, z̄g_i, z̄s_i, (x̄s_i cos φ_i · n(v̄_i)).y   (n has no z, eq. 2)
        # the same for rows 4..N and the tilt offsets -x̄s_i sin φ_i t(v̄_i) (xy pairs, rows
        # 1..N), written only for extended leaves:
        ("sil_axis", "vec4", SIL_EXTRA_ROWS),
        ("sil_heights", "vec4", SIL_EXTRA_ROWS),
        ("sil_tilt", "vec4", _PAIRS(MAX_SILHOUETTE_ROWS)),
        # derived on the host by leafview.deform.beam.bend_profile (eq. 4 by Newton's method):
        ("bend", "vec4", BEND_SAMPLES),  # Δ_k (bent minus straight midrib), Φ_k at v = k/(K-1)
    ),
    "one leaf: Ω, jitter, material, transform, ripple and bend settings, then derived data",
    derived=("axis", "heights", "sil_axis", "sil_heights", "sil_tilt", "bend"),
)

FRAME_BLOCK = Block(
    "FrameData", "Frame",
    (
        ("view", "mat4", 1),
        ("proj", "mat4", 1),
        ("eye", "vec4", 1),        # camera position (w = 1 perspective, 0 orthographic: xyz = view dir)
        ("key", "vec4", 1),        # key light direction (towards the light), intensity
        ("fill", "vec4", 1),       # fill light direction, intensity
        ("ambient", "vec4", 1),    # ambient rgb, unused
        ("flags", "ivec4", 1),     # x: encode sRGB, y: lighting off (flat colour)
    ),
    "camera, lights and output flags of one frame",
)

SPECIES_CULL_BLOCK = Block(
    "SpeciesCull", "SpeciesCullBlock",
    (
        ("sphere", "vec4", 1),     # leaf-space bounding sphere of the species' leaves: centre, radius
        ("lod_error", "vec4", 1),  # outline error (leaf lengths) of level k's grid vs the surface; [0] = 0
    ),
    "one species of a scene: what the culling pass needs (leafview/gpu/scene.py)",
)

# glMultiDrawElementsIndirect's command, fixed by OpenGL (20 bytes, std430 array stride 20)
DRAW_COMMAND_DTYPE = np.dtype([("count", "<u4"), ("instance_count", "<u4"), ("first_index", "<u4"),
                               ("base_vertex", "<i4"), ("base_instance", "<u4")])
_DRAW_COMMAND_GLSL = ("struct DrawCommand { uint count; uint instance_count; uint first_index; "
                      "int base_vertex; uint base_instance; };\n")

LEAF_BINDING, FRAME_BINDING = 0, 1   # uniform blocks
LEAVES_BINDING = 2                   # storage buffer of LeafData rows (instancing, prepare pass)


def pack_leaf(params: LeafParams, out: np.ndarray | None = None, *, ripple_row: int = 0) -> np.ndarray:
    """Fill a LEAF_BLOCK record from ``params`` (float32, std140 = std430); ``ripple_row`` is the
    row of the ripple signal buffer holding this leaf's ``(seed, beta)`` signal."""
    rec = LEAF_BLOCK.zeros() if out is None else out
    s, j, m = params.shape, params.jitter, params.material
    rec["a1"][:3] = s.a1
    rec["a2"][:3] = s.a2
    rec["vbar"][:3] = s.vbar[:3]  # rows 1-3; rows 4..N of an extended silhouette: sil_rows
    rec["xs"][:3] = s.xs[:3]
    rec["zs"][:3] = s.zs[:3]
    rec["zf"][:3] = s.zf[:3]
    rec["zg"][:3] = s.zg[:3]
    if s.extended:
        phi = s.phi
        rec["tilt"] = (*phi[:3], float(s.rows))
        rows = np.asarray(s.silhouette, dtype=np.float64)
        extra = s.rows - 3
        rec["sil_rows"][:extra] = np.c_[rows[3:], phi[3:]]
        fg = np.zeros((2 * _PAIRS(SIL_EXTRA_ROWS), 2))
        fg[:extra] = np.c_[s.zf[3:], s.zg[3:]]
        rec["sil_fg"] = fg.reshape(-1, 4)
    else:
        rec["tilt"] = 0.0
        rec["sil_rows"] = 0.0
        rec["sil_fg"] = 0.0
    amp = j.amplitude if j.enabled else 0.0
    rec["jitter"] = (amp, j.density, JITTER_TABLE_SIZE, 0.0)
    rec["front"] = (*m.front, m.translucency)
    rec["back"] = (*m.back, float(params.shape.half))
    rec["model"] = params.transform.matrix().T  # column-major for GLSL
    rip, bend = params.ripple, params.bending
    rec["deform"] = (float(rip.enabled), float(bend.active), rip.veins, float(ripple_row))
    for name, side in (("ripple_l", 0), ("ripple_r", 1)):
        rec[name] = (rip.amplitude[side], rip.fluctuation[side], rip.interval[side], rip.phase[side])
    if bend.active:
        profile = bend_profile(params)
        rec["bend_axis"] = (*profile.axis, profile.twist)
        rec["bend"][:, :3] = profile.delta
        rec["bend"][:, 3] = profile.phi
    else:
        rec["bend_axis"] = (1.0, 0.0, 0.0, 0.0)
        rec["bend"] = 0.0
    return rec


def feature_defines(records: np.ndarray) -> dict[str, int]:
    """Shader permutation for a draw of ``records``: compile out jitter, ripples, bending, the
    extended silhouette or the one-sided half when no record uses them (llvmpipe runs vertex
    shaders on the CPU, where unused branches cost)."""
    recs = np.atleast_1d(records)
    defines = {}
    if not (recs["tilt"][:, 3] > 0).any():
        defines["LEAF_NO_EXTENDED"] = 1
    if not (recs["back"][:, 3] != 0).any():
        defines["LEAF_NO_HALF"] = 1
    if not (recs["jitter"][:, 0] > 0).any():
        defines["LEAF_NO_JITTER"] = 1
    if not (recs["deform"][:, 0] > 0).any():
        defines["LEAF_NO_RIPPLE"] = 1
    if not (recs["deform"][:, 1] > 0).any():
        defines["LEAF_NO_BEND"] = 1
    return defines


def ripple_keys(params: Iterable[LeafParams]) -> list[tuple[int, float]]:
    """The distinct ``(seed, beta)`` ripple signals of leaves with ripples on, in order of first
    use: row i of the signal buffer holds ``keys[i]`` (the rows :func:`pack_leaves` assigns)."""
    keys: dict[tuple[int, float], int] = {}
    for p in params:
        if p.ripple.enabled:
            keys.setdefault((p.ripple.seed, p.ripple.beta), len(keys))
    return list(keys)


def pack_leaves(params: Iterable[LeafParams]) -> tuple[NDArray[Any], NDArray[np.float32]]:
    """LEAF_BLOCK records (N,) for ``params`` and the jitter table rows they index: one row of
    :data:`JITTER_TABLE_SIZE` values per distinct seed among leaves with jitter on (at least one
    row). ``record["jitter"][3]`` is the row."""
    params = list(params)
    recs = np.zeros(len(params), dtype=LEAF_BLOCK.dtype)
    rows: dict[int, int] = {}
    tables: list[NDArray[np.float32]] = []
    ripple_rows = {key: row for row, key in enumerate(ripple_keys(params))}
    for i, p in enumerate(params):
        pack_leaf(p, recs[i], ripple_row=ripple_rows.get((p.ripple.seed, p.ripple.beta), 0))
        if p.jitter.enabled:
            row = rows.get(p.jitter.seed)
            if row is None:
                row = rows[p.jitter.seed] = len(tables)
                tables.append(jitter_table(p.jitter))
            recs[i]["jitter"][3] = float(row)
    table = np.stack(tables) if tables else np.zeros((1, JITTER_TABLE_SIZE), np.float32)
    return recs, table.astype(np.float32)


def _vec(v: Any) -> str:
    return ", ".join(f"{float(x):.1f}" for x in v)


def generated_sources() -> dict[str, str]:
    """Virtual include files produced from the declarations above."""
    return {
        "generated/constants.glsl": (f"#define RIPPLE_SAMPLES {RIPPLE_SAMPLES}\n"
                                     f"#define BEND_SAMPLES {BEND_SAMPLES}\n"
                                     f"#define SIL_MAX_ROWS {MAX_SILHOUETTE_ROWS}\n"
                                     f"const vec3 LEAF_BASE = vec3({_vec(BASE)});\n"
                                     f"const vec3 LEAF_APEX = vec3({_vec(APEX)});\n"),
        "generated/leaf_block.glsl": "#include \"generated/constants.glsl\"\n" + LEAF_BLOCK.glsl(LEAF_BINDING),
        "generated/frame_block.glsl": FRAME_BLOCK.glsl(FRAME_BINDING),
        "generated/scene_blocks.glsl": SPECIES_CULL_BLOCK.struct_glsl() + _DRAW_COMMAND_GLSL,
    }
