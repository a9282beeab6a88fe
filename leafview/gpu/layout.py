"""The one declaration of the GPU data layouts: every block, binding point and packed field.

* **Blocks**: each is a list of (name, GLSL type, count). From it come the numpy structured dtype
  (what Python fills) and the GLSL struct text (what the shaders see, served to the loader as
  ``#include "generated/<name>.glsl"``). Members are restricted to ``vec4``/``ivec4``/``mat4``
  (and arrays of them) so the std140 (uniform block) and std430 (storage buffer row) packings
  coincide with the dense numpy packing: no padding rules to drift. Small all-scalar structs
  (draw commands, fBm jobs) are generated from their numpy dtype the same way.
* **Binding points**: every uniform block, storage buffer and sampler unit of every program has
  its number here, once (:data:`BINDINGS`). The shader loader injects them into every program as
  ``#define LEAVES_BINDING 2`` etc., so GLSL writes ``layout(std430, binding = LEAVES_BINDING)``
  and Python binds with the same constant; no other file holds a binding number.
* **Packed fields**: spare vec4 components that hold a number of their own (the drawn half in
  ``back.w``, the signal row in ``deform.w``, the silhouette row count in ``tilt.w``...) are
  declared as :data:`LEAF_SLOTS`. GLSL reads them through generated accessors
  (``leaf_half(rec)``); Python writes and reads them through :func:`write_slot` /
  :func:`read_slot`, the numpy twins the readback test compares with.

Tests check each block against the size the linked program reflects, every program's reflected
bindings against :data:`BINDINGS`, and every accessor against its numpy twin.
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

__all__ = ["Block", "LEAF_BLOCK", "FRAME_BLOCK", "SPECIES_CULL_BLOCK", "DRAW_COMMAND_DTYPE", "FBM_JOB_DTYPE",
           "Binding", "BINDINGS", "binding_defines", "bindings_glsl",
           "LEAF_BINDING", "FRAME_BINDING", "LEAVES_BINDING", "SIGNALS_BINDING", "SPECIES_OF_BINDING",
           "SPECIES_BINDING", "COMMANDS_BINDING", "VISIBLE_BINDING", "FBM_JOBS_BINDING", "READBACK_BINDING",
           "JITTER_UNIT", "ATLAS_UNIT",
           "Slot", "LEAF_SLOTS", "PAIR_MEMBERS", "read_slot", "write_slot", "read_pair", "accessors_glsl",
           "struct_from_dtype", "pack_leaf", "pack_leaves", "ripple_keys", "feature_defines", "generated_sources",
           "AovOutput", "AOV_OUTPUTS", "LEAF_OFFSET_UNIFORM", "aov_outputs_glsl"]

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
        fields = self.dtype.fields
        assert fields is not None
        return sum(int(fields[name][0].itemsize) for name, _, _ in self.members if name not in self.derived)

    def struct_glsl(self) -> str:
        lines = [f"// generated from leafview/gpu/layout.py: {self.doc}", f"struct {self.struct_name} {{"]
        for name, glsl, count in self.members:
            lines.append(f"    {glsl} {name}{'' if count == 1 else f'[{count}]'};")
        return "\n".join(lines + ["};", ""])

    def glsl(self, binding: str | int) -> str:
        """The struct and its uniform block at ``binding`` (a define of :data:`BINDINGS`, e.g.
        ``"LEAF_BINDING"``)."""
        lines = [self.struct_glsl().rstrip("\n"), f"layout(std140, binding = {binding}) uniform {self.block_name} {{",
                  f"    {self.struct_name} {self.block_name.lower()};", "};", ""]
        return "\n".join(lines)

    def zeros(self) -> np.ndarray:
        return np.zeros((), dtype=self.dtype)


_SCALARS = {np.dtype("<u4"): "uint", np.dtype("<i4"): "int", np.dtype("<f4"): "float"}


def struct_from_dtype(name: str, dtype: np.dtype) -> str:
    """GLSL ``struct`` of a numpy dtype of 4-byte scalars (std430 packs them densely, as numpy)."""
    assert dtype.names is not None and dtype.fields is not None
    members = " ".join(f"{_SCALARS[dtype.fields[field][0]]} {field};" for field in dtype.names)
    return f"// generated from leafview/gpu/layout.py\nstruct {name} {{ {members} }};\n"


SIL_EXTRA_ROWS = MAX_SILHOUETTE_ROWS - 3   # silhouette rows beyond the paper's three
_PAIRS = lambda n: -(-n // 2)  # noqa: E731  (vec4s holding n xy pairs)

# Components that hold a number of their own (jitter.*, front.w, back.w, deform.*, bend_axis.w,
# tilt.w) are declared as LEAF_SLOTS below: GLSL and Python read and write them through it.
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
# one signal for fbm.comp to (re)compute: seed and β of Geng, Hu & Zhang 2014, eqs 1-2, its length
# and the float offset of its row in the signal buffer
FBM_JOB_DTYPE = np.dtype([("seed", "<u4"), ("beta", "<f4"), ("n", "<u4"), ("offset", "<u4")])


# -- binding points ---------------------------------------------------------------------------
# Every buffer block (uniform or storage) has a number of its own across all programs, and every
# sampler a texture unit of its own: a buffer bound for one pass can never alias another's.
LEAF_BINDING = 0         # uniform Leaf: one LeafData (single-leaf draws and capture)
FRAME_BINDING = 1        # uniform Frame: camera, lights and output flags
LEAVES_BINDING = 2       # storage Leaves: LeafData rows (instancing, scenes, the prepare pass)
SIGNALS_BINDING = 3      # storage Signals: fBm ripple signals, RIPPLE_SAMPLES floats a row
SPECIES_OF_BINDING = 4   # storage SpeciesOf: species index of each scene leaf
SPECIES_BINDING = 5      # storage Species: SpeciesCull rows
COMMANDS_BINDING = 6     # storage Commands: one DrawCommand per level of detail
VISIBLE_BINDING = 7      # storage Visible: visible leaf indices, one list per level
FBM_JOBS_BINDING = 8     # storage Jobs: the FbmJob rows of one synthesis dispatch
READBACK_BINDING = 9     # storage: output of readback probes (tests compare GLSL with numpy)
JITTER_UNIT = 0          # sampler jitter_table: jitter rows, one per seed
ATLAS_UNIT = 1           # sampler atlas: Dear ImGui's font atlas or user image


@dataclass(frozen=True)
class Binding:
    """One binding point: the GLSL define, its number, the kind of binding and the GLSL name of
    the block (or sampler uniform) bound there (empty: no program of the package declares it)."""

    define: str
    number: int
    kind: str   # "uniform", "storage" or "sampler"
    name: str
    doc: str = ""


BINDINGS: tuple[Binding, ...] = (
    Binding("LEAF_BINDING", LEAF_BINDING, "uniform", "Leaf", "one LeafData"),
    Binding("FRAME_BINDING", FRAME_BINDING, "uniform", "Frame", "camera, lights, output flags"),
    Binding("LEAVES_BINDING", LEAVES_BINDING, "storage", "Leaves", "LeafData rows"),
    Binding("SIGNALS_BINDING", SIGNALS_BINDING, "storage", "Signals", "fBm ripple signals"),
    Binding("SPECIES_OF_BINDING", SPECIES_OF_BINDING, "storage", "SpeciesOf", "species of each scene leaf"),
    Binding("SPECIES_BINDING", SPECIES_BINDING, "storage", "Species", "SpeciesCull rows"),
    Binding("COMMANDS_BINDING", COMMANDS_BINDING, "storage", "Commands", "indirect draw commands"),
    Binding("VISIBLE_BINDING", VISIBLE_BINDING, "storage", "Visible", "visible leaves per level"),
    Binding("FBM_JOBS_BINDING", FBM_JOBS_BINDING, "storage", "Jobs", "fBm synthesis jobs"),
    Binding("READBACK_BINDING", READBACK_BINDING, "storage", "", "readback probes (tests)"),
    Binding("JITTER_UNIT", JITTER_UNIT, "sampler", "jitter_table", "jitter rows"),
    Binding("ATLAS_UNIT", ATLAS_UNIT, "sampler", "atlas", "imgui texture"),
)


def _check_bindings(bindings: Iterable[Binding]) -> None:
    buffers: dict[int, str] = {}
    units: dict[int, str] = {}
    for b in bindings:
        seen = units if b.kind == "sampler" else buffers
        if b.number in seen:
            raise AssertionError(f"{b.define} = {b.number} is also {seen[b.number]}")
        seen[b.number] = b.define


_check_bindings(BINDINGS)


def binding_defines() -> dict[str, int]:
    """``{define: number}`` of every binding point, as the loader injects them into programs."""
    return {b.define: b.number for b in BINDINGS}


def bindings_glsl() -> str:
    """The ``#define`` lines of every binding point (inserted after ``#version`` by the loader)."""
    return "".join(f"#define {name} {number}\n" for name, number in binding_defines().items())


# -- packed fields ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Slot:
    """A number packed into one component of a LeafData member. GLSL reads it as
    ``accessor(rec)`` (a macro, so that reading one float of a storage-buffer row never copies
    the whole struct); ``kind`` is the GLSL type it reads as (``float``, ``int`` or ``bool``)."""

    accessor: str
    member: str
    component: int
    kind: str
    doc: str = ""

    def glsl(self) -> str:
        read = f"(rec).{self.member}.{'xyzw'[self.component]}"
        expr = {"float": read, "int": f"int({read})", "bool": f"({read} > 0.0)"}[self.kind]
        return f"#define {self.accessor}(rec) ({expr})  // {self.doc}"


LEAF_SLOTS: tuple[Slot, ...] = (
    Slot("leaf_jitter_amplitude", "jitter", 0, "float", "jitter amplitude, 0 when jitter is off"),
    Slot("leaf_jitter_density", "jitter", 1, "float", "jitter samples along the blade"),
    Slot("leaf_jitter_size", "jitter", 2, "int", "jitter table length"),
    Slot("leaf_jitter_row", "jitter", 3, "int", "row of the jitter texture holding the leaf's seed"),
    Slot("leaf_translucency", "front", 3, "float", "diffuse transmission"),
    Slot("leaf_half", "back", 3, "float", "drawn half: 0 both, +-1 one side (shape.half)"),
    Slot("leaf_ripple_on", "deform", 0, "bool", "ripples on"),
    Slot("leaf_bend_on", "deform", 1, "bool", "bending on"),
    Slot("leaf_veins", "deform", 2, "float", "secondary veins (ripple frequency)"),
    Slot("leaf_signal_row", "deform", 3, "int", "row of the ripple signal buffer"),
    Slot("leaf_twist", "bend_axis", 3, "float", "twist at the apex (radians)"),
    Slot("leaf_rows", "tilt", 3, "int", "silhouette rows N of an extended leaf, 0 otherwise"),
)
_SLOTS = {slot.accessor: slot for slot in LEAF_SLOTS}


def _check_slots(slots: Iterable[Slot]) -> None:
    places: dict[tuple[str, int], str] = {}
    members = {name: glsl for name, glsl, _ in LEAF_BLOCK.members}
    for slot in slots:
        if members.get(slot.member) != "vec4" or not 0 <= slot.component < 4:
            raise AssertionError(f"{slot.accessor}: no vec4 member {slot.member!r} component {slot.component}")
        if (slot.member, slot.component) in places:
            raise AssertionError(f"{slot.accessor} and {places[slot.member, slot.component]} share a component")
        places[slot.member, slot.component] = slot.accessor


_check_slots(LEAF_SLOTS)

# members holding xy pairs two to a vec4: pair j sits in element j / 2, xy for even j, zw for odd
PAIR_MEMBERS = {
    "leaf_sil_fg": "sil_fg",      # (z̄f_i, z̄g_i) of silhouette row i = 4 + j (extended leaves)
    "leaf_sil_tilt": "sil_tilt",  # tilt offset -x̄s_i sin φ_i t(v̄_i) of row i = 1 + j
}


def read_slot(records: np.ndarray, accessor: str) -> NDArray[Any]:
    """What the GLSL accessor ``accessor(rec)`` reads, for one record or an array of them."""
    slot = _SLOTS[accessor]
    raw = np.asarray(records[slot.member])[..., slot.component]
    if slot.kind == "int":
        return raw.astype(np.int32)   # GLSL int(): truncation towards zero
    if slot.kind == "bool":
        return raw > 0.0
    return raw


def write_slot(record: np.ndarray, accessor: str, value: float) -> None:
    """Store ``value`` where the GLSL accessor ``accessor(rec)`` reads it (one record)."""
    slot = _SLOTS[accessor]
    record[slot.member][slot.component] = value


def read_pair(records: np.ndarray, accessor: str, j: int) -> NDArray[np.float32]:
    """What ``accessor(rec, j)`` of :data:`PAIR_MEMBERS` reads: pair ``j`` (..., 2)."""
    half = 2 * (j % 2)
    return np.asarray(records[PAIR_MEMBERS[accessor]])[..., j // 2, half:half + 2]


def accessors_glsl() -> str:
    """GLSL accessor macros of :data:`LEAF_SLOTS` and :data:`PAIR_MEMBERS`."""
    lines = ["// generated from leafview/gpu/layout.py: packed fields of LeafData"]
    lines += [slot.glsl() for slot in LEAF_SLOTS]
    # one vec4 load per pair: the element is passed by value to a helper that picks its half (a
    # macro that indexed the member in both branches made llvmpipe gather the element twice)
    lines.append("vec2 leafview_pair_half(vec4 element, int j) { return (j % 2 == 0) ? element.xy : element.zw; }")
    for accessor, member in PAIR_MEMBERS.items():
        lines.append(f"#define {accessor}(rec, j) leafview_pair_half((rec).{member}[(j) / 2], (j))")
    return "\n".join(lines) + "\n"


def pack_leaf(params: LeafParams, out: np.ndarray | None = None, *, ripple_row: int = 0) -> np.ndarray:
    """Fill a LEAF_BLOCK record from ``params`` (float32, std140 = std430); ``ripple_row`` is the
    row of the ripple signal buffer holding this leaf's ``(seed, beta)`` signal. Packed fields
    are written through :func:`write_slot` (the GLSL side reads them with the accessors)."""
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
        rec["tilt"][:3] = phi[:3]
        write_slot(rec, "leaf_rows", float(s.rows))
        rows = np.asarray(s.silhouette, dtype=np.float64)
        extra = s.rows - 3
        rec["sil_rows"][:extra] = np.c_[rows[3:], phi[3:]]
        fg = np.zeros((2 * _PAIRS(SIL_EXTRA_ROWS), 2))
        fg[:extra] = np.c_[s.zf[3:], s.zg[3:]]
        rec["sil_fg"] = fg.reshape(-1, 4)  # pair j in element j // 2 (see read_pair)
    else:
        rec["tilt"] = 0.0
        rec["sil_rows"] = 0.0
        rec["sil_fg"] = 0.0
    write_slot(rec, "leaf_jitter_amplitude", j.amplitude if j.enabled else 0.0)
    write_slot(rec, "leaf_jitter_density", j.density)
    write_slot(rec, "leaf_jitter_size", JITTER_TABLE_SIZE)
    write_slot(rec, "leaf_jitter_row", 0.0)
    rec["front"][:3] = m.front
    write_slot(rec, "leaf_translucency", m.translucency)
    rec["back"][:3] = m.back
    write_slot(rec, "leaf_half", float(params.shape.half))
    rec["model"] = params.transform.matrix().T  # column-major for GLSL
    rip, bend = params.ripple, params.bending
    write_slot(rec, "leaf_ripple_on", float(rip.enabled))
    write_slot(rec, "leaf_bend_on", float(bend.active))
    write_slot(rec, "leaf_veins", rip.veins)
    write_slot(rec, "leaf_signal_row", float(ripple_row))
    for name, side in (("ripple_l", 0), ("ripple_r", 1)):
        rec[name] = (rip.amplitude[side], rip.fluctuation[side], rip.interval[side], rip.phase[side])
    if bend.active:
        profile = bend_profile(params)
        rec["bend_axis"][:3] = profile.axis
        write_slot(rec, "leaf_twist", profile.twist)
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
    if not (read_slot(recs, "leaf_rows") > 0).any():
        defines["LEAF_NO_EXTENDED"] = 1
    if not (read_slot(recs, "leaf_half") != 0).any():
        defines["LEAF_NO_HALF"] = 1
    if not (read_slot(recs, "leaf_jitter_amplitude") > 0).any():
        defines["LEAF_NO_JITTER"] = 1
    if not read_slot(recs, "leaf_ripple_on").any():
        defines["LEAF_NO_RIPPLE"] = 1
    if not read_slot(recs, "leaf_bend_on").any():
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
    row). ``leaf_jitter_row`` of each record is its row."""
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
            write_slot(recs[i], "leaf_jitter_row", float(row))
    table = np.stack(tables) if tables else np.zeros((1, JITTER_TABLE_SIZE), np.float32)
    return recs, table.astype(np.float32)


# -- per-pixel label outputs (leafview/gpu/aov.py) ----------------------------------------------
@dataclass(frozen=True)
class AovOutput:
    """One colour attachment of the label pass (``LEAF_AOV``): the AOV ``name``, the GLSL type of
    the fragment output ``aov_<name>``, the attachment's components and moderngl dtype, and its
    location (= colour attachment index)."""

    name: str
    glsl: str
    components: int
    dtype: str
    location: int
    doc: str = ""

    @property
    def nbytes(self) -> int:
        """Bytes a pixel of this attachment takes."""
        return 4 * self.components


AOV_OUTPUTS: tuple[AovOutput, ...] = (
    AovOutput("instance", "uint", 1, "u4", 0, "R32UI: global leaf index + 1, 0 background and stems"),
    AovOutput("depth", "float", 1, "f4", 1, "R32F: -z in view space (along the optical axis)"),
    # RGB32F is not required to be colour-renderable: RGBA32F, w unused (0)
    AovOutput("normal", "vec4", 4, "f4", 2, "RGBA32F: world-space unit normal of the visible side"),
    AovOutput("uv", "vec2", 2, "f4", 3, "RG32F: the leaf's (u, v) as leaf.vert gives v_uv"),
)
LEAF_OFFSET_UNIFORM = "leaf_offset"
"""``uint`` uniform of ``leaf.vert`` (``LEAF_AOV`` with ``LEAF_INDIRECT``): the first leaf of the
batch being drawn, so that ``v_leaf = leaf_offset + in_leaf`` is the scene's leaf index."""


def aov_outputs_glsl() -> str:
    """The fragment outputs of the label pass, one per :data:`AOV_OUTPUTS` entry."""
    lines = ["// generated from leafview/gpu/layout.py: the label pass's outputs (AOV_OUTPUTS)"]
    lines += [f"layout(location = {o.location}) out {o.glsl} aov_{o.name};  // {o.doc}" for o in AOV_OUTPUTS]
    return "\n".join(lines) + "\n"


def _check_aov_outputs(outputs: Iterable[AovOutput]) -> None:
    locations = [o.location for o in outputs]
    if locations != list(range(len(locations))):
        raise AssertionError(f"AOV output locations must be 0..n-1 in order, got {locations}")


_check_aov_outputs(AOV_OUTPUTS)


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
        "generated/leaf_block.glsl": ("#include \"generated/constants.glsl\"\n" + LEAF_BLOCK.glsl("LEAF_BINDING")
                                      + accessors_glsl()),
        "generated/frame_block.glsl": FRAME_BLOCK.glsl("FRAME_BINDING"),
        "generated/scene_blocks.glsl": (SPECIES_CULL_BLOCK.struct_glsl()
                                        + struct_from_dtype("DrawCommand", DRAW_COMMAND_DTYPE)),
        "generated/fbm_job.glsl": struct_from_dtype("FbmJob", FBM_JOB_DTYPE),
        "generated/aov_outputs.glsl": aov_outputs_glsl(),
        "generated/aov_vertex.glsl": (f"// generated from leafview/gpu/layout.py: first leaf of the drawn batch\n"
                                      f"uniform uint {LEAF_OFFSET_UNIFORM};\n"),
    }
