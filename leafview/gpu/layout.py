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
  ``back.w``, the signal row in ``deform.w``, the silhouette row count in ``tilt.w``, the texture
  layers in the model matrix's last row, a lobed leaf's sweep-table layer in ``vbar.w``...) are declared as :data:`LEAF_SLOTS`. GLSL reads them through generated accessors
  (``leaf_half(rec)``); Python writes and reads them through :func:`write_slot` /
  :func:`read_slot`, the numpy twins the readback test compares with.

* **Vertex attributes**: the members every vertex of a leaf reads (:data:`LEAF_VERTEX_BLOCK`) are
  fed to ``leaf.vert`` as per-instance vertex attributes (:data:`LEAF_ATTRIBUTES`), straight out
  of a buffer of LeafData rows or of the compact LeafVertex records a scene's culling writes;
  :func:`attribute_format` gives the moderngl format of either, :func:`attributes_glsl` the
  declarations. llvmpipe runs storage-buffer reads in the vertex stage as per-vertex gathers,
  while an instanced attribute is fetched once per instance.

Tests check each block against the size the linked program reflects, every program's reflected
bindings against :data:`BINDINGS`, and every accessor against its numpy twin.
"""

from __future__ import annotations

from collections.abc import Container, Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.botany.vein_shading import glsl_constants as vein_shading_glsl
from leafview.core.blade import APEX, BASE, JITTER_TABLE_SIZE, jitter_table
from leafview.core.margin import MARGIN_TEXELS, SIDE_TEXELS
from leafview.core.params import MAX_SILHOUETTE_ROWS, LeafParams
from leafview.core.texture import LeafTexture
from leafview.deform.beam import BEND_SAMPLES, bend_profile
from leafview.deform.fbm import RIPPLE_SAMPLES

__all__ = ["Block", "LEAF_BLOCK", "FRAME_BLOCK", "LIGHT_BLOCK", "SHADOW_BLOCK", "WIND_BLOCK",
           "LIGHT_BINDING", "SHADOW_BINDING", "WIND_BINDING", "SHADOW_UNIT", "SSAO_UNIT", "SSAO_DEPTH_UNIT", "SSAO_NORMAL_UNIT", "SPECIES_CULL_BLOCK", "DRAW_COMMAND_DTYPE", "FBM_JOB_DTYPE",
           "Binding", "BINDINGS", "binding_defines", "bindings_glsl",
           "LEAF_BINDING", "FRAME_BINDING", "LEAVES_BINDING", "SIGNALS_BINDING", "SPECIES_OF_BINDING",
           "SPECIES_BINDING", "COMMANDS_BINDING", "VISIBLE_BINDING", "FBM_JOBS_BINDING", "READBACK_BINDING",
           "VERTICES_BINDING", "JITTER_UNIT", "ATLAS_UNIT", "ROWS_UNIT", "TEXTURE_UNIT", "VEIN_FIELD_UNIT",
           "VEIN_GRID_UNIT", "VEIN_STYLE_UNIT", "VEIN_SEGMENTS_BINDING", "VEIN_TEXELS_BINDING",
           "VEIN_TILES_BINDING", "VEIN_FIELD_SAMPLER", "VEIN_GRID_SAMPLER", "LOBE_UNIT", "LOBE_SAMPLER",
           "Slot", "LEAF_SLOTS", "BRANCH_RIPPLE", "BRANCH_BEND", "BRANCH_ROWS", "BRANCH_LOBE", "branch_code", "branch_parts", "without_derived", "PAIR_MEMBERS", "read_slot", "write_slot", "read_pair", "accessors_glsl",
           "struct_from_dtype", "pack_leaf", "pack_leaves", "pack_colours", "ripple_keys", "feature_defines", "generated_sources",
           "texture_keys", "texture_layers", "write_texture_layers", "texture_defines", "PLAIN_DEFINES", "shadow_defines",
           "write_vein_layers", "vein_defines", "NO_VEIN_DEFINES", "VEIN_SKIN_DEFINES",
           "write_lobe_layers", "lobe_defines", "NO_LOBE_DEFINES", "LOBE_TABLE_ROWS",
           "AovOutput", "AOV_OUTPUTS", "LEAF_OFFSET_UNIFORM", "aov_outputs_glsl",
           "LEAF_VERTEX_BLOCK", "LeafAttribute", "LEAF_ATTRIBUTES", "MAX_VERTEX_ATTRIBUTES", "attribute_format",
           "attributes_glsl", "vertex_records", "ROW_TEXELS", "ROWS_PER_LINE", "MAX_TEXTURE_SIZE", "row_texture_size",
           "needs_row_texture", "row_glsl"]

_TYPES = {"vec4": ("<f4", (4,)), "ivec4": ("<i4", (4,)), "mat4": ("<f4", (4, 4))}


@dataclass(frozen=True)
class Block:
    """A GLSL struct ``struct_name`` and the uniform block ``block_name`` that holds one of it."""

    struct_name: str
    block_name: str
    members: tuple[tuple[str, str, int], ...]
    doc: str = ""
    derived: tuple[str, ...] = ()  # members computed from the others (not parameters)

    @cached_property
    def dtype(self) -> np.dtype:
        """The numpy record of one struct (built once: callers read it per draw)."""
        fields = []
        for name, glsl, count in self.members:
            base, shape = _TYPES[glsl]
            fields.append((name, base, shape if count == 1 else (count, *shape)))
        return np.dtype(fields)

    @cached_property
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
        ("flags", "ivec4", 1),     # x: encode sRGB, y: lighting off (flat colour), z: image height in
                                   # pixels (veins' level of detail; 0 unknown: full detail)
    ),
    "camera, lights and output flags of one frame",
)

# -- the canopy look (leafview/gpu/canopy.py): sun, sky, ground, tone; shadows; wind ---------------
LIGHT_BLOCK = Block(
    "LightData", "Light",
    (
        ("sun", "vec4", 1),          # xyz direction towards the sun (world, unit), w folded irradiance (E/π)
        ("sun_colour", "vec4", 1),   # rgb (luminance 1), w unused
        ("sky_zenith", "vec4", 1),   # zenith radiance rgb (L_z c_z, leafview.scene.sky eq. 2), w 1: sky drawn
        ("sky_horizon", "vec4", 1),  # horizon colour scale rgb (L_z c_h), w 1: ground drawn
        ("sky_perez", "vec4", 2),    # [0] Perez A, B, C, D; [1] E, 1/F(0, θs), horizon haze k, unused
        ("ground", "vec4", 1),       # ground albedo rgb, w the ground's height (world z)
        ("ground_radiance", "vec4", 1),  # radiance of the distant ground (sky eq. 3) rgb, w unused
        ("sky_sh", "vec4", 9),       # folded irradiance (E/π) of sky and ground: 9 spherical-harmonic rgb
                                     # coefficients, convolved (Â_l L_lm / π; sky_model.glsl sh_irradiance)
        ("tone", "vec4", 1),         # x 2^exposure, y tone map (0 linear, 1 filmic), z transmission, w gloss
        ("flags", "ivec4", 1),       # x shadows on, y ambient occlusion on, z alpha to coverage, w unused
    ),
    "sun, sky, ground and camera response of a canopy frame (leafview.scene.lighting)",
)

SHADOW_BLOCK = Block(
    "ShadowData", "Shadow",
    (
        ("matrices", "mat4", 4),     # world -> the sun's clip space, one per cascade
        ("splits", "vec4", 1),       # far end of each cascade (view-space distance along the optical axis)
        ("params", "vec4", 1),       # x cascades (0: no shadows), y depth bias, z normal offset (texels), w 1 / tile size
    ),
    "the sun's cascaded shadow maps (leafview/gpu/shadow.py)",
)

WIND_BLOCK = Block(
    "WindData", "Wind",
    (
        ("wind", "vec4", 1),         # xy direction the wind blows towards (world, unit), z speed, w time
        ("gust", "vec4", 1),         # x load P_w, y λ (eq. 5), z 1 / gust length, w the gust's phase (samples)
        ("flutter", "vec4", 1),      # x each leaf's sway phase, y flutter phase (samples), z flutter a_f, w unused
        ("ids", "ivec4", 1),         # x seed of the leaves' phase hash
        ("signal", "vec4", 64),      # the wind's fBm signal N (eqs 1-2), 256 samples, 4 a vec4
    ),
    "the wind of a frame (leafview.deform.wind)",
)

SPECIES_CULL_BLOCK = Block(
    "SpeciesCull", "SpeciesCullBlock",
    (
        ("sphere", "vec4", 1),     # leaf-space bounding sphere of the species' leaves: centre, radius
        # outline error (leaf lengths) of level k's grid vs the surface, k >= 1; [0] the species'
        # grid group (0 the level grids, 1 the lobed grids: leafview.gpu.scene.mark_lobed)
        ("lod_error", "vec4", 1),
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
LEAVES_BINDING = 2       # storage Leaves: LeafData rows (the prepare pass, a scene's culling passes)
SIGNALS_BINDING = 3      # storage Signals: fBm ripple signals, RIPPLE_SAMPLES floats a row
SPECIES_OF_BINDING = 4   # storage SpeciesOf: species index of each scene leaf
SPECIES_BINDING = 5      # storage Species: SpeciesCull rows
COMMANDS_BINDING = 6     # storage Commands: one DrawCommand per level of detail
VISIBLE_BINDING = 7      # storage Visible: visible leaf indices, one list per level
FBM_JOBS_BINDING = 8     # storage Jobs: the FbmJob rows of one synthesis dispatch
READBACK_BINDING = 9     # storage: output of readback probes (tests compare GLSL with numpy)
VERTICES_BINDING = 10    # storage Vertices: LeafVertex records of a scene's visible leaves
VEIN_SEGMENTS_BINDING = 11  # storage VeinSegments: half-width tables and vein segments (vein_field.comp)
VEIN_TEXELS_BINDING = 12    # storage VeinTexels: the vein field texels vein_field.comp writes
VEIN_TILES_BINDING = 13     # storage VeinTiles: the per-tile segment lists of vein_field.comp
JITTER_UNIT = 0          # sampler jitter_table: jitter rows, one per seed
ATLAS_UNIT = 1           # sampler atlas: Dear ImGui's font atlas or user image
ROWS_UNIT = 2            # sampler leaf_rows: LeafData rows as texels (the optional branches' members)
TEXTURE_UNIT = 3         # sampler leaf_textures: the leaves' image textures, one array layer per file
VEIN_FIELD_UNIT = 4      # sampler leaf_vein_field: the vein fields (distance, order, width), one layer per key
VEIN_GRID_UNIT = 5       # sampler leaf_vein_grid: the vein-shape grids (displacement, ripple coordinate)
VEIN_STYLE_UNIT = 6      # sampler leaf_vein_style: venation contrast and relief, one texel per vein layer
LOBE_UNIT = 7            # sampler leaf_lobe_table: the lobed leaves' sweep tables, one array layer per table
SHADOW_UNIT = 8          # sampler sun_shadow: the sun's shadow map cascades (one depth atlas texture, a tile per cascade)
SSAO_UNIT = 9            # sampler ambient_occlusion: the frame's screen-space ambient occlusion
SSAO_DEPTH_UNIT = 10     # sampler ssao_depth: the SSAO pass's view-space depth (its label pass)
SSAO_NORMAL_UNIT = 11    # sampler ssao_normal: the SSAO pass's world normals (its label pass)
LIGHT_BINDING = 14       # uniform Light: sun, sky, ground, tone (canopy frames)
SHADOW_BINDING = 15      # uniform Shadow: the sun's cascade matrices
WIND_BINDING = 16        # uniform Wind: the frame's wind
VEIN_FIELD_SAMPLER = "leaf_vein_field"
"""GLSL name of the ``sampler2DArray`` at :data:`VEIN_FIELD_UNIT` (``shaders/leaf_veins.glsl``)."""
VEIN_GRID_SAMPLER = "leaf_vein_grid"
"""GLSL name of the ``sampler2DArray`` at :data:`VEIN_GRID_UNIT` (``shaders/leaf_eval.glsl``)."""
LOBE_SAMPLER = "leaf_lobe_table"
"""GLSL name of the ``sampler2DArray`` at :data:`LOBE_UNIT` (``shaders/leaf_eval.glsl``): RGBA32F,
width N (the railroad ties of :mod:`leafview.deform.sweep`), :data:`LOBE_TABLE_ROWS` texel rows
(``table_texels``; row 2's spare w holds the table's cup), one layer per lobed table
(:mod:`leafview.gpu.lobe_tables`)."""
LOBE_TABLE_ROWS = 4


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
    Binding("VERTICES_BINDING", VERTICES_BINDING, "storage", "Vertices", "LeafVertex records of visible leaves"),
    Binding("VEIN_SEGMENTS_BINDING", VEIN_SEGMENTS_BINDING, "storage", "VeinSegments",
            "vein segments of a field dispatch (leafview/gpu/vein_field.py)"),
    Binding("VEIN_TEXELS_BINDING", VEIN_TEXELS_BINDING, "storage", "VeinTexels", "vein field texels written"),
    Binding("VEIN_TILES_BINDING", VEIN_TILES_BINDING, "storage", "VeinTiles", "per-tile vein segment lists"),
    Binding("JITTER_UNIT", JITTER_UNIT, "sampler", "jitter_table", "jitter rows"),
    Binding("ATLAS_UNIT", ATLAS_UNIT, "sampler", "atlas", "imgui texture"),
    Binding("ROWS_UNIT", ROWS_UNIT, "sampler", "leaf_rows", "LeafData rows as texels"),
    Binding("TEXTURE_UNIT", TEXTURE_UNIT, "sampler", "leaf_textures", "leaf image textures (leafview/gpu/textures.py)"),
    Binding("VEIN_FIELD_UNIT", VEIN_FIELD_UNIT, "sampler", VEIN_FIELD_SAMPLER, "vein fields (leafview/gpu/vein_field.py)"),
    Binding("VEIN_GRID_UNIT", VEIN_GRID_UNIT, "sampler", VEIN_GRID_SAMPLER, "vein-shape grids (leafview/gpu/vein_field.py)"),
    Binding("VEIN_STYLE_UNIT", VEIN_STYLE_UNIT, "sampler", "leaf_vein_style", "contrast, relief per vein layer"),
    Binding("LOBE_UNIT", LOBE_UNIT, "sampler", LOBE_SAMPLER, "lobed leaves' sweep tables (leafview/gpu/lobe_tables.py)"),
    Binding("SHADOW_UNIT", SHADOW_UNIT, "sampler", "sun_shadow", "the sun's shadow cascades (leafview/gpu/shadow.py)"),
    Binding("SSAO_UNIT", SSAO_UNIT, "sampler", "ambient_occlusion", "screen-space ambient occlusion (leafview/gpu/ssao.py)"),
    Binding("SSAO_DEPTH_UNIT", SSAO_DEPTH_UNIT, "sampler", "ssao_depth", "the SSAO pass's depth input (leafview/gpu/ssao.py)"),
    Binding("SSAO_NORMAL_UNIT", SSAO_NORMAL_UNIT, "sampler", "ssao_normal", "the SSAO pass's normal input (leafview/gpu/ssao.py)"),
    Binding("LIGHT_BINDING", LIGHT_BINDING, "uniform", "Light", "sun, sky, ground, tone (leafview/gpu/canopy.py)"),
    Binding("SHADOW_BINDING", SHADOW_BINDING, "uniform", "Shadow", "the sun's cascades (leafview/gpu/shadow.py)"),
    Binding("WIND_BINDING", WIND_BINDING, "uniform", "Wind", "the frame's wind (leafview/gpu/wind.py)"),
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
    """A number packed into one component of a LeafData member (of column ``column`` of a mat4
    member). GLSL reads it as ``accessor(rec)`` (a macro, so that reading one float of a
    storage-buffer row never copies the whole struct); ``kind`` is what it reads as: ``float``,
    ``int``, ``bool``, or ``layer``, an int stored plus one (-1, "none", is stored as 0)."""

    accessor: str
    member: str
    component: int
    kind: str
    doc: str = ""
    derived: bool = False  # written by a GPU pass (``set_<accessor>(rec, value)``), not by the packer
    column: int | None = None  # the column of a mat4 member

    @property
    def index(self) -> tuple[int, ...]:
        """Index of the component in the member's numpy field (after the record axes)."""
        return (self.component,) if self.column is None else (self.column, self.component)

    def view(self, records: Any) -> NDArray[Any]:
        """The component in ``records`` (one record or an array of them), as a writable view."""
        field = records[self.member]
        if self.column is None:
            return field[..., self.component]
        return field[..., self.column, self.component]

    def glsl(self) -> str:
        column = "" if self.column is None else f"[{self.column}]"
        read = f"(rec).{self.member}{column}.{'xyzw'[self.component]}"
        expr = {"float": read, "int": f"int({read})", "bool": f"({read} > 0.0)",
                "layer": f"(int({read}) - 1)"}[self.kind]
        line = f"#define {self.accessor}(rec) ({expr})  // {self.doc}"
        if self.derived:
            line += f"\n#define set_{self.accessor}(rec, value) ({read} = float(value))"
        return line

    def row_glsl(self) -> str:
        """``ROW_<accessor>``: the same number of the branch record (see :func:`row_glsl`)."""
        column = "" if self.column is None else f"[{self.column}]"
        read = f"ROW_{self.member}{column}.{'xyzw'[self.component]}"
        expr = {"float": read, "int": f"int({read})", "bool": f"({read} > 0.0)",
                "layer": f"(int({read}) - 1)"}[self.kind]
        return f"#define ROW_{self.accessor} ({expr})"


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
    # the last row of the affine model matrix (0, 0, 0, 1) has room for two: the image texture
    # layers of the two sides (leafview/gpu/textures.py), -1 untextured. Stored plus one, so that an
    # untextured leaf's matrix keeps its row (0, 0, 0, 1); leaf.vert multiplies by mat4x3(model).
    Slot("leaf_front_layer", "model", 3, "layer", "front texture layer, -1 untextured", column=0),
    Slot("leaf_back_layer", "model", 3, "layer", "back texture layer (the front's without a back image)",
         column=1),
    # and the third: the leaf's layer of the vein field and vein-shape grid arrays
    # (leafview/gpu/vein_field.py), -1 without veins, stored plus one like the texture layers
    Slot("leaf_vein_layer", "model", 3, "layer", "vein field / grid layer, -1 without veins", column=2),
    # a lobed leaf's layer of the sweep-table array (leafview/gpu/lobe_tables.py), -1 unlobed, in the
    # spare w of the silhouette feet (rows 1-3 use xyz). The vertex stage does not read vbar: the
    # prepare pass folds the layer into leaf_branches (BRANCH_LOBE), read as leaf_branch_lobe(rec).
    Slot("leaf_lobe_layer", "vbar", 3, "layer", "sweep-table layer of a lobed leaf, -1 unlobed"),
    # spare components of the members read as vertex attributes (LEAF_VERTEX_BLOCK), so that the
    # vertex stage learns which branches a leaf takes, and a scene's vertex record its row,
    # without reading the storage buffer:
    Slot("leaf_branches", "a1", 3, "int", "BRANCH_RIPPLE + BRANCH_BEND + BRANCH_ROWS * N + BRANCH_LOBE * "
         "(lobe layer + 1) (leaf_prepare.comp)", derived=True),
    Slot("leaf_vertex_row", "a2", 3, "int", "a scene's vertex record: the leaf's row in its batch (scene_compact.comp)",
         derived=True),
)
_SLOTS = {slot.accessor: slot for slot in LEAF_SLOTS}


def _check_slots(slots: Iterable[Slot]) -> None:
    places: dict[tuple[str, tuple[int, ...]], str] = {}
    members = {name: glsl for name, glsl, _ in LEAF_BLOCK.members}
    for slot in slots:
        kind = "vec4" if slot.column is None else "mat4"
        if (members.get(slot.member) != kind or not 0 <= slot.component < 4
                or not 0 <= (slot.column or 0) < 4 or slot.kind not in ("float", "int", "bool", "layer")):
            raise AssertionError(f"{slot.accessor}: no {kind} member {slot.member!r} component {slot.index}")
        if slot.column is not None and (slot.column == 3 or slot.component != 3):
            raise AssertionError(f"{slot.accessor}: only the last row of a matrix, left of its corner, is spare")
        if (slot.member, slot.index) in places:
            raise AssertionError(f"{slot.accessor} and {places[slot.member, slot.index]} share a component")
        places[slot.member, slot.index] = slot.accessor


_check_slots(LEAF_SLOTS)

# members holding xy pairs two to a vec4: pair j sits in element j / 2, xy for even j, zw for odd
PAIR_MEMBERS = {
    "leaf_sil_fg": "sil_fg",      # (z̄f_i, z̄g_i) of silhouette row i = 4 + j (extended leaves)
    "leaf_sil_tilt": "sil_tilt",  # tilt offset -x̄s_i sin φ_i t(v̄_i) of row i = 1 + j
}


def read_slot(records: np.ndarray, accessor: str) -> NDArray[Any]:
    """What the GLSL accessor ``accessor(rec)`` reads, for one record or an array of them."""
    slot = _SLOTS[accessor]
    raw = np.asarray(slot.view(records))
    if slot.kind == "int":
        return raw.astype(np.int32)   # GLSL int(): truncation towards zero
    if slot.kind == "layer":
        return raw.astype(np.int32) - 1
    if slot.kind == "bool":
        return raw > 0.0
    return raw


def write_slot(record: np.ndarray, accessor: str, value: ArrayLike) -> None:
    """Store ``value`` where the GLSL accessor ``accessor(rec)`` reads it (one record, or an
    array of records and one value each)."""
    slot = _SLOTS[accessor]
    stored = np.asarray(value, np.float64) + (1.0 if slot.kind == "layer" else 0.0)
    slot.view(record)[...] = stored


# the branch code (leaf_branches): which optional parts of leaf_eval.glsl a leaf takes
BRANCH_RIPPLE = 1   # ripples on (leaf_ripple_on)
BRANCH_BEND = 2     # bending on (leaf_bend_on)
BRANCH_ROWS = 4     # times the silhouette rows N of an extended leaf (leaf_rows), 0 otherwise
BRANCH_LOBE = BRANCH_ROWS * (MAX_SILHOUETTE_ROWS + 1)   # times the lobe layer + 1 (leaf_lobe_layer), 0 unlobed
MARGIN_ROWS = 1     # leaf_rows of a leaf with a landmark margin (leafview.core.margin): no extended
                    # silhouette has 1 row, so the code is free; the shader takes margin_silhouette
_MAX_BRANCH_CODE = 1 << 24   # the code is a float32 component: exact integers up to 2^24


def branch_code(records: np.ndarray) -> NDArray[np.int32]:
    """What ``leaf_prepare.comp`` writes to ``leaf_branches`` of each record (the numpy twin)."""
    code = (BRANCH_RIPPLE * read_slot(records, "leaf_ripple_on").astype(np.int32)
            + BRANCH_BEND * read_slot(records, "leaf_bend_on").astype(np.int32)
            + BRANCH_ROWS * read_slot(records, "leaf_rows")
            + BRANCH_LOBE * (read_slot(records, "leaf_lobe_layer") + 1))
    return np.asarray(code, np.int32)


def branch_parts(code: ArrayLike) -> dict[str, NDArray[np.int32]]:
    """The branch code decoded as the generated GLSL macros decode it (``leaf_has_ripple``,
    ``leaf_has_bend``, ``leaf_branch_rows``, ``leaf_branch_lobe``): the numpy twin of the decoding."""
    c = np.asarray(code, np.int32)
    return {"ripple": (c & BRANCH_RIPPLE != 0).astype(np.int32), "bend": (c & BRANCH_BEND != 0).astype(np.int32),
            "rows": (c % BRANCH_LOBE) // BRANCH_ROWS, "lobe": c // BRANCH_LOBE - 1}


def without_derived(records: np.ndarray) -> NDArray[Any]:
    """A copy of LeafData ``records`` with every derived member and derived slot zeroed: what the
    packer wrote, whether or not the prepare pass has run since."""
    out = np.array(records, copy=True)
    flat = out.reshape(-1)
    margin = np.atleast_1d(read_slot(flat, "leaf_rows") == MARGIN_ROWS)
    kept = read_margin(flat[margin])              # a margin leaf's texels live in derived members
    for name in LEAF_BLOCK.derived:
        out[name] = 0
    for slot in LEAF_SLOTS:
        if slot.derived:
            slot.view(out)[...] = 0
    if margin.any():
        sub = flat[margin]
        write_margin(sub, kept)
        flat[margin] = sub
    return out


def read_pair(records: np.ndarray, accessor: str, j: int) -> NDArray[np.float32]:
    """What ``accessor(rec, j)`` of :data:`PAIR_MEMBERS` reads: pair ``j`` (..., 2)."""
    half = 2 * (j % 2)
    return np.asarray(records[PAIR_MEMBERS[accessor]])[..., j // 2, half:half + 2]


def accessors_glsl() -> str:
    """GLSL accessor macros of :data:`LEAF_SLOTS` and :data:`PAIR_MEMBERS`."""
    lines = ["// generated from leafview/gpu/layout.py: packed fields of LeafData"]
    lines += [slot.glsl() for slot in LEAF_SLOTS]
    lines += [f"#define LEAF_BRANCH_RIPPLE {BRANCH_RIPPLE}", f"#define LEAF_BRANCH_BEND {BRANCH_BEND}",
              f"#define LEAF_BRANCH_ROWS {BRANCH_ROWS}", f"#define LEAF_BRANCH_LOBE {BRANCH_LOBE}",
              f"#define LEAF_MARGIN_ROWS {MARGIN_ROWS}", f"#define MARGIN_SIDE_TEXELS {SIDE_TEXELS}",
              "#define leaf_has_ripple(rec) ((leaf_branches(rec) & LEAF_BRANCH_RIPPLE) != 0)",
              "#define leaf_has_bend(rec) ((leaf_branches(rec) & LEAF_BRANCH_BEND) != 0)",
              "#define leaf_branch_rows(rec) ((leaf_branches(rec) % LEAF_BRANCH_LOBE) / LEAF_BRANCH_ROWS)",
              "#define leaf_branch_lobe(rec) (leaf_branches(rec) / LEAF_BRANCH_LOBE - 1)"]
    # one vec4 load per pair: the element is passed by value to a helper that picks its half (a
    # macro that indexed the member in both branches made llvmpipe gather the element twice)
    lines.append("vec2 leafview_pair_half(vec4 element, int j) { return (j % 2 == 0) ? element.xy : element.zw; }")
    for accessor, member in PAIR_MEMBERS.items():
        lines.append(f"#define {accessor}(rec, j) leafview_pair_half((rec).{member}[(j) / 2], (j))")
    return "\n".join(lines) + "\n"


# A leaf with a landmark margin (leaf_rows = MARGIN_ROWS) has no extended silhouette: the extended
# members hold its MARGIN_TEXELS margin texels instead (leafview.core.margin, Margin.texels), in this
# order. The prepare pass writes none of them for such a leaf (it takes the quartic path).
MARGIN_MEMBERS = (("sil_rows", SIL_EXTRA_ROWS), ("sil_fg", _PAIRS(SIL_EXTRA_ROWS)), ("sil_axis", SIL_EXTRA_ROWS),
                  ("sil_heights", SIL_EXTRA_ROWS), ("sil_tilt", _PAIRS(MAX_SILHOUETTE_ROWS)))
assert sum(n for _, n in MARGIN_MEMBERS) == MARGIN_TEXELS, "the margin texels must fill the extended members"


def write_margin(records: np.ndarray, texels: ArrayLike) -> None:
    """Mark ``records`` (one or (N,)) as landmark-margin leaves and store their margin texels
    ((MARGIN_TEXELS, 4) or (N, MARGIN_TEXELS, 4)) in :data:`MARGIN_MEMBERS`."""
    t = np.asarray(texels, np.float32)
    write_slot(records, "leaf_rows", float(MARGIN_ROWS))
    k = 0
    for name, n in MARGIN_MEMBERS:
        records[name] = t[..., k:k + n, :]
        k += n


def read_margin(records: np.ndarray) -> NDArray[np.float32]:
    """The margin texels stored by :func:`write_margin`, (..., MARGIN_TEXELS, 4)."""
    return np.concatenate([np.asarray(records[name], np.float32) for name, _ in MARGIN_MEMBERS], axis=-2)


def pack_leaf(params: LeafParams, out: np.ndarray | None = None, *, ripple_row: int = 0,
              layers: tuple[int, int] = (-1, -1), vein_layer: int = -1, lobe_layer: int = -1) -> np.ndarray:
    """Fill a LEAF_BLOCK record from ``params`` (float32, std140 = std430); ``ripple_row`` is the
    row of the ripple signal buffer holding this leaf's ``(seed, beta)`` signal, ``layers`` the
    layers of its front and back images in the draw's array texture (-1: untextured; see
    :func:`texture_layers`), ``vein_layer`` its layer of the draw's vein field and grid arrays
    (-1: no veins; ``VeinFields.layers`` of leafview.gpu.vein_field), ``lobe_layer`` its layer of the
    draw's sweep-table array (-1: drawn as an unlobed leaf; ``LobeTables.update`` of
    leafview.gpu.lobe_tables). Packed fields are written through :func:`write_slot` (the GLSL side
    reads them with the accessors)."""
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
    if params.margin is not None:
        write_margin(rec, params.margin.texels())
    write_slot(rec, "leaf_jitter_amplitude", j.amplitude if j.enabled else 0.0)
    write_slot(rec, "leaf_jitter_density", j.density)
    write_slot(rec, "leaf_jitter_size", JITTER_TABLE_SIZE)
    write_slot(rec, "leaf_jitter_row", 0.0)
    rec["front"][:3] = m.front
    write_slot(rec, "leaf_translucency", m.translucency)
    rec["back"][:3] = m.back
    write_slot(rec, "leaf_half", float(params.shape.half))
    rec["model"] = params.transform.matrix().T  # column-major for GLSL
    write_texture_layers(rec, layers)           # the matrix's last row (after the matrix itself)
    write_vein_layers(rec, vein_layer)
    write_lobe_layers(rec, lobe_layer)
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
    row data (``LEAF_NO_EXTENDED``; or, of its two kinds, the landmark margin ``LEAF_NO_MARGIN`` or
    the extended silhouette ``LEAF_NO_SIL_ROWS``) or the one-sided half when no record uses them
    (llvmpipe runs vertex shaders on the CPU, where unused branches cost)."""
    recs = np.atleast_1d(records)
    defines = {}
    rows = read_slot(recs, "leaf_rows")
    if not (rows > 0).any():
        defines["LEAF_NO_EXTENDED"] = 1
    else:   # the two kinds that use the row data: landmark margins and extended silhouettes
        if not (rows == MARGIN_ROWS).any():
            defines["LEAF_NO_MARGIN"] = 1
        if not (rows > MARGIN_ROWS).any():
            defines["LEAF_NO_SIL_ROWS"] = 1
    if not (read_slot(recs, "leaf_half") != 0).any():
        defines["LEAF_NO_HALF"] = 1
    if not (read_slot(recs, "leaf_jitter_amplitude") > 0).any():
        defines["LEAF_NO_JITTER"] = 1
    if not read_slot(recs, "leaf_ripple_on").any():
        defines["LEAF_NO_RIPPLE"] = 1
    if not read_slot(recs, "leaf_bend_on").any():
        defines["LEAF_NO_BEND"] = 1
    return defines


def vein_defines(records: np.ndarray) -> dict[str, int]:
    """``LEAF_NO_VEINS`` when no record of a draw has a vein layer: ``leaf.frag`` then reads no vein
    field (and ``leaf_eval.glsl`` no vein grid), so a draw without veins pays nothing for them."""
    recs = np.atleast_1d(records)
    return {} if (read_slot(recs, "leaf_vein_layer") >= 0).any() else dict(NO_VEIN_DEFINES)


def lobe_defines(records: np.ndarray) -> dict[str, int]:
    """``LEAF_NO_LOBES`` when no record of a draw is lobed (no ``leaf_lobe_layer``): the vertex stage
    then has no sweep branch and reads no sweep table. Apart from :func:`feature_defines` (whose
    permutations the full program is compared with): every program without it keeps the branch."""
    recs = np.atleast_1d(records)
    return {} if (read_slot(recs, "leaf_lobe_layer") >= 0).any() else dict(NO_LOBE_DEFINES)


NO_LOBE_DEFINES: Mapping[str, int] = MappingProxyType({"LEAF_NO_LOBES": 1})
"""The define of a draw without lobed leaves (no sweep table bound)."""

NO_VEIN_DEFINES: Mapping[str, int] = MappingProxyType({"LEAF_NO_VEINS": 1})
"""The define of a draw with no vein field bound (stems, baked leaves, ``--veins off``)."""

VEIN_SKIN_DEFINES: Mapping[str, int] = MappingProxyType({"LEAF_VEIN_SKIN": 1})
"""The define of a draw of veined leaves too far for their veins (a scene's coarser levels of
detail): their skin and sides, no vein field read. llvmpipe runs both sides of a branch, so a
per-triangle level of detail in ``leaf.frag`` alone would still cost every fragment the field."""


def texture_defines(records: np.ndarray) -> dict[str, int]:
    """``LEAF_NO_TEXTURE`` when no record of a draw is textured: ``leaf.frag`` then has no texture
    lookup and no ``discard`` (which would cost llvmpipe its early depth test). Apart from
    :func:`feature_defines`, whose permutations cover the vertex stage only."""
    recs = np.atleast_1d(records)
    return {} if (read_slot(recs, "leaf_front_layer") >= 0).any() else dict(PLAIN_DEFINES)


def shadow_defines(shadows: bool, shadow_filter: str = "soft") -> dict[str, int]:
    """The defines of a program that reads the sun's shadow maps (``leaf_shadow.glsl``):
    ``LEAF_SHADOWS``, with ``SHADOW_FAST`` for the ``"fast"`` filter (one bilinear tap instead of
    the 3 × 3 percentage-closer filter; :data:`leafview.scene.lighting.SHADOW_FILTERS`, ``"auto"``
    resolved by the caller: :func:`leafview.gpu.canopy.resolve_shadow_filter`). None without
    shadows."""
    if shadow_filter not in ("soft", "fast"):
        raise ValueError(f"shadow_filter {shadow_filter!r}: 'soft' or 'fast' ('auto' is resolved by the renderer)")
    if not shadows:
        return {}
    return {"LEAF_SHADOWS": 1, **({"SHADOW_FAST": 1} if shadow_filter == "fast" else {})}


PLAIN_DEFINES: Mapping[str, int] = MappingProxyType({"LEAF_NO_TEXTURE": 1})
"""The define of a draw with no image texture bound (baked leaves, stems, batches given none)."""


def texture_keys(params: Iterable[LeafParams]) -> list[str]:
    """The distinct image files (resolved paths) of the textured leaves among ``params``, front
    before back, in order of first use: layer i of their array texture holds ``keys[i]`` (the
    layers :func:`texture_layers` and :func:`pack_leaves` assign). Resolving can raise
    :class:`~leafview.errors.ParamError` (a path leaving its folder);
    :mod:`leafview.gpu.textures` checks the files first, naming the leaf."""
    keys: dict[str, int] = {}
    memo: dict[tuple[str, str, str], tuple[str, str | None]] = {}
    for p in params:
        if p.texture is not None:
            for path in _texture_files(p.texture, memo):
                if path is not None:
                    keys.setdefault(path, len(keys))
    return list(keys)


def _texture_files(texture: LeafTexture, memo: dict[tuple[str, str, str], tuple[str, str | None]]
                   ) -> tuple[str, str | None]:
    """The resolved front and back files of ``texture`` (resolved once per folder and paths in
    ``memo``: the leaves of a leaf set often share them)."""
    key = (texture.folder, texture.front, texture.back)
    found = memo.get(key)
    if found is None:
        front, back = texture.paths()
        found = memo[key] = (str(front), None if back is None else str(back))
    return found


def texture_layers(params: Sequence[LeafParams], keys: Sequence[str] | None = None) -> NDArray[np.int32]:
    """(N, 2) front and back layer of each leaf in an array texture holding ``keys`` (default
    :func:`texture_keys` of ``params``): -1 for an untextured leaf; the front's layer for the back
    of a leaf without a back image."""
    index = {key: i for i, key in enumerate(texture_keys(params) if keys is None else keys)}
    out = np.full((len(params), 2), -1, np.int32)
    memo: dict[tuple[str, str, str], tuple[str, str | None]] = {}
    for i, p in enumerate(params):
        if p.texture is not None:
            front, back = _texture_files(p.texture, memo)
            out[i, 0] = index[front]
            out[i, 1] = out[i, 0] if back is None else index[back]
    return out


def write_texture_layers(records: np.ndarray, layers: ArrayLike) -> None:
    """Store (front, back) ``layers`` (one pair, or (N, 2) for N records) in the records' slots."""
    pairs = np.asarray(layers, np.int32)
    write_slot(records, "leaf_front_layer", pairs[..., 0])
    write_slot(records, "leaf_back_layer", pairs[..., 1])


def write_vein_layers(records: np.ndarray, layers: ArrayLike) -> None:
    """Store vein ``layers`` (one int, or (N,) for N records; -1 no veins) in the records'
    ``leaf_vein_layer`` slot."""
    write_slot(records, "leaf_vein_layer", np.asarray(layers, np.int32))


def write_lobe_layers(records: np.ndarray, layers: ArrayLike) -> None:
    """Store sweep-table ``layers`` (one int, or (N,) for N records; -1 unlobed) in the records'
    ``leaf_lobe_layer`` slot; the prepare pass folds them into ``leaf_branches``."""
    lobes = np.asarray(layers, np.int32)
    if (lobes >= 0).any() and int(lobes.max() + 1) * BRANCH_LOBE >= _MAX_BRANCH_CODE:
        raise ValueError(f"lobe layer {int(lobes.max())} does not fit the branch code")
    write_slot(records, "leaf_lobe_layer", lobes)


def ripple_keys(params: Iterable[LeafParams]) -> list[tuple[int, float]]:
    """The distinct ``(seed, beta)`` ripple signals of leaves with ripples on, in order of first
    use: row i of the signal buffer holds ``keys[i]`` (the rows :func:`pack_leaves` assigns)."""
    keys: dict[tuple[int, float], int] = {}
    for p in params:
        if p.ripple.enabled:
            keys.setdefault((p.ripple.seed, p.ripple.beta), len(keys))
    return list(keys)


def pack_leaves(params: Iterable[LeafParams], *, textures: Sequence[str] | None = None,
                vein_layers: ArrayLike | None = None, lobe_layers: ArrayLike | None = None
                ) -> tuple[NDArray[Any], NDArray[np.float32]]:
    """LEAF_BLOCK records (N,) for ``params`` and the jitter table rows they index: one row of
    :data:`JITTER_TABLE_SIZE` values per distinct seed among leaves with jitter on (at least one
    row). ``leaf_jitter_row`` of each record is its row; the texture layers are those of an array
    texture holding ``textures`` (default :func:`texture_keys` of ``params``), the vein layers
    ``vein_layers`` ((N,) or one int; default -1, no veins: ``VeinFields.layers``), the sweep-table
    layers ``lobe_layers`` ((N,) or one int; default -1, every leaf unlobed: ``LobeTables.update``)."""
    params = list(params)
    recs = np.zeros(len(params), dtype=LEAF_BLOCK.dtype)
    rows: dict[int, int] = {}
    tables: list[NDArray[np.float32]] = []
    ripple_rows = {key: row for row, key in enumerate(ripple_keys(params))}
    layers = texture_layers(params, textures)
    for i, p in enumerate(params):
        pack_leaf(p, recs[i], ripple_row=ripple_rows.get((p.ripple.seed, p.ripple.beta), 0),
                  layers=(int(layers[i, 0]), int(layers[i, 1])))
        if p.jitter.enabled:
            row = rows.get(p.jitter.seed)
            if row is None:
                row = rows[p.jitter.seed] = len(tables)
                tables.append(jitter_table(p.jitter))
            write_slot(recs[i], "leaf_jitter_row", float(row))
    if vein_layers is not None:
        write_vein_layers(recs, np.broadcast_to(np.asarray(vein_layers, np.int32), (len(params),)))
    if lobe_layers is not None:
        write_lobe_layers(recs, np.broadcast_to(np.asarray(lobe_layers, np.int32), (len(params),)))
    table = np.stack(tables) if tables else np.zeros((1, JITTER_TABLE_SIZE), np.float32)
    return recs, table.astype(np.float32)


# -- per-instance vertex attributes (leaf.vert with LEAF_INSTANCED or LEAF_INDIRECT) ----------------
# The members every vertex reads: Ω's axis (a1, a2, with the branch code and a scene record's row in
# their spare w), jitter, colours, the model matrix and the prepare pass's per-row constants. The
# members only ripples, bends and extended silhouettes need stay in the storage buffer, read in
# those branches only.
LEAF_VERTEX_BLOCK = Block(
    "LeafVertex", "LeafVertexBlock",
    tuple(m for m in LEAF_BLOCK.members
          if m[0] in ("a1", "a2", "jitter", "front", "back", "model", "axis", "heights")),
    "what every vertex of a leaf reads, as instanced vertex attributes (a subset of LeafData)",
)
MAX_VERTEX_ATTRIBUTES = 16
"""GL_MAX_VERTEX_ATTRIBS that OpenGL guarantees (llvmpipe offers no more): the record's
attributes plus ``in_uv`` must fit."""
MAX_ATTRIBUTE_STRIDE = 2048
"""GL_MAX_VERTEX_ATTRIB_STRIDE that OpenGL 4.4 guarantees: a LeafData row is read in place."""


@dataclass(frozen=True)
class LeafAttribute:
    """One vec4 vertex input of ``leaf.vert``: element ``element`` of LeafData member ``member``
    (a mat4's column, an array's entry; 0 for a vec4)."""

    name: str
    member: str
    element: int

    def offset(self, block: Block) -> int:
        """Byte offset of this vec4 in a row of ``block``."""
        fields = block.dtype.fields
        assert fields is not None
        return int(fields[self.member][1]) + 16 * self.element


def _leaf_attributes(block: Block) -> tuple[LeafAttribute, ...]:
    out: list[LeafAttribute] = []
    for name, glsl, count in block.members:
        if glsl not in ("vec4", "mat4"):
            raise AssertionError(f"{name}: only float members can be vertex attributes")
        n = count * (4 if glsl == "mat4" else 1)
        out += [LeafAttribute(f"in_leaf_{name}" + (str(k) if n > 1 else ""), name, k) for k in range(n)]
    if len(out) + 1 > MAX_VERTEX_ATTRIBUTES:
        raise AssertionError(f"{len(out)} record attributes and in_uv exceed {MAX_VERTEX_ATTRIBUTES}")
    if LEAF_BLOCK.nbytes > MAX_ATTRIBUTE_STRIDE:
        raise AssertionError(f"a {LEAF_BLOCK.nbytes}-byte LeafData row exceeds the vertex stride limit")
    return tuple(out)


LEAF_ATTRIBUTES = _leaf_attributes(LEAF_VERTEX_BLOCK)


def attribute_format(block: Block, present: Container[str] | None = None) -> tuple[str, tuple[str, ...]]:
    """moderngl buffer format (one row per instance, ``/i``) and attribute names that read
    :data:`LEAF_ATTRIBUTES` from a buffer of ``block`` rows: :data:`LEAF_BLOCK` (the leaves'
    storage buffer itself, nothing copied) or :data:`LEAF_VERTEX_BLOCK` (compact records).
    Attributes not in ``present`` (e.g. a program that compiled them out) become padding."""
    parts: list[str] = []
    names: list[str] = []
    at = 0
    for attr in sorted(LEAF_ATTRIBUTES, key=lambda a: a.offset(block)):
        if present is not None and attr.name not in present:
            continue
        offset = attr.offset(block)
        if offset > at:
            parts.append(f"{offset - at}x")
        parts.append("4f")
        names.append(attr.name)
        at = offset + 16
    if block.nbytes > at:
        parts.append(f"{block.nbytes - at}x")
    return " ".join(parts) + "/i", tuple(names)


def pack_colours(front: ArrayLike, back: ArrayLike) -> NDArray[np.uint32]:
    """The numpy twin of ``pack_colours`` in ``shaders/leaf_colours.glsl``: a leaf's front rgb and
    translucency (N, 4) and back rgb (N, 3) as the (N, 4) uint32 of ``v_colours``, two IEEE halves
    each (round to nearest even), the first in the low 16 bits as ``packHalf2x16`` puts it."""
    f = np.asarray(front, np.float32).reshape(-1, 4)
    b = np.asarray(back, np.float32).reshape(-1, 3)
    values = np.concatenate([f, b, np.zeros((f.shape[0], 1), np.float32)], axis=1)
    halves = values.astype(np.float16).view(np.uint16).astype(np.uint32)
    out: NDArray[np.uint32] = halves[:, 0::2] | (halves[:, 1::2] << np.uint32(16))
    return out


def vertex_records(rows: np.ndarray, picks: ArrayLike) -> NDArray[Any]:
    """The LEAF_VERTEX_BLOCK records of LeafData ``rows[picks]``, each with its row in
    ``leaf_vertex_row``: what ``scene_compact.comp`` writes for a list of visible leaves (the numpy
    twin of ``LEAF_VERTEX_OF`` and ``set_leaf_vertex_row``)."""
    idx = np.asarray(picks, np.int64).reshape(-1)
    out = np.zeros(idx.size, LEAF_VERTEX_BLOCK.dtype)
    for name, _, _ in LEAF_VERTEX_BLOCK.members:
        out[name] = rows[name][idx]
    write = _SLOTS["leaf_vertex_row"]
    out[write.member][:, write.component] = idx
    return out


def _vertex_glsl() -> str:
    """The LeafVertex struct and ``LEAF_VERTEX_OF(rec)``, its fields of a LeafData ``rec``."""
    members = ", ".join(f"(rec).{name}" for name, _, _ in LEAF_VERTEX_BLOCK.members)
    return (LEAF_VERTEX_BLOCK.struct_glsl()
            + f"#define LEAF_VERTEX_OF(rec) {LEAF_VERTEX_BLOCK.struct_name}({members})\n")


def attributes_glsl() -> str:
    """The vertex inputs of :data:`LEAF_ATTRIBUTES` and ``leaf_vertex_attributes()``, the
    LeafVertex they make up (after ``generated/leaf_vertex.glsl``)."""
    lines = ["// generated from leafview/gpu/layout.py: LEAF_ATTRIBUTES, one row per instance"]
    lines += [f"in vec4 {a.name};" for a in LEAF_ATTRIBUTES]
    args = []
    for name, glsl, count in LEAF_VERTEX_BLOCK.members:
        cols = [a.name for a in LEAF_ATTRIBUTES if a.member == name]
        if glsl == "mat4":
            args.append(f"mat4({', '.join(cols)})")
        elif count > 1:
            args.append(f"vec4[{count}]({', '.join(cols)})")
        else:
            args.append(cols[0])
    lines.append(f"{LEAF_VERTEX_BLOCK.struct_name} leaf_vertex_attributes() {{\n"
                 f"    return {LEAF_VERTEX_BLOCK.struct_name}({', '.join(args)});\n}}")
    return "\n".join(lines) + "\n"


# -- the members of the optional branches as a texture (leaf.vert with LEAF_ROW_TEXTURE) ------------
# Ripples, bends and extended silhouettes read members outside LEAF_VERTEX_BLOCK. The instanced and
# scene paths read them from an RGBA32F texture holding the LeafData rows texel for texel (a copy of
# the storage buffer, ROWS_PER_LINE rows per texture line): llvmpipe fetches texels faster than it
# gathers storage-buffer reads.
ROW_TEXELS = LEAF_BLOCK.nbytes // 16
MAX_TEXTURE_SIZE = 16384
"""GL_MAX_TEXTURE_SIZE that OpenGL 4.5 guarantees."""
ROWS_PER_LINE = MAX_TEXTURE_SIZE // ROW_TEXELS


def row_texture_size(count: int) -> tuple[int, int]:
    """(width, height) of the row texture of ``count`` rows (at least one line); rows fill the lines
    in order, so a buffer of rows maps onto the texture byte for byte."""
    lines = max(1, -(-int(count) // ROWS_PER_LINE))
    return ROWS_PER_LINE * ROW_TEXELS, lines


def needs_row_texture(records: np.ndarray) -> bool:
    """Whether a draw of ``records`` takes a branch that reads the row texture (ripples, bending or
    an extended silhouette): without one, no program variant of the draw samples it."""
    recs = np.atleast_1d(records)
    return bool(read_slot(recs, "leaf_ripple_on").any() or read_slot(recs, "leaf_bend_on").any()
                or (read_slot(recs, "leaf_rows") > 0).any())


def row_glsl() -> str:
    """``ROW_<member>`` (``ROW_<member>(i)`` for arrays) and ``ROW_<accessor>`` of every LeafData
    member outside LEAF_VERTEX_BLOCK, the members of the optional branches: texels of row
    ``LEAF_ROW_INDEX`` of the ``leaf_rows`` texture when ``LEAF_ROW_TEXTURE`` is defined, else the
    members of the struct ``LEAF_ROW``. Each is read where it is used."""
    fields = LEAF_BLOCK.dtype.fields
    assert fields is not None
    vertex = {name for name, _, _ in LEAF_VERTEX_BLOCK.members}
    members = [(name, count) for name, _, count in LEAF_BLOCK.members if name not in vertex]
    lines = ["// generated from leafview/gpu/layout.py: the optional branches' members (row_glsl)",
             "#ifdef LEAF_ROW_TEXTURE",
             "layout(binding = ROWS_UNIT) uniform sampler2D leaf_rows;",
             "vec4 leaf_row_texel(int k) {",
             f"    int row = int(LEAF_ROW_INDEX), line = row / {ROWS_PER_LINE};",
             f"    return texelFetch(leaf_rows, ivec2((row - line * {ROWS_PER_LINE}) * {ROW_TEXELS} + k, line), 0);",
             "}"]
    for name, count in members:
        first = int(fields[name][1]) // 16
        lines.append(f"#define ROW_{name}(i) leaf_row_texel({first} + (i))" if count > 1
                     else f"#define ROW_{name} leaf_row_texel({first})")
    # ROW_margin(k): texel k of a landmark-margin leaf (MARGIN_MEMBERS, in order)
    offsets = [int(fields[name][1]) // 16 for name, _ in MARGIN_MEMBERS]
    runs: list[tuple[int, int, int]] = []      # (first k, first texel, count) of contiguous texels
    k = 0
    for (_name, n), first in zip(MARGIN_MEMBERS, offsets):
        if runs and runs[-1][1] + runs[-1][2] == first:
            runs[-1] = (runs[-1][0], runs[-1][1], runs[-1][2] + n)
        else:
            runs.append((k, first, n))
        k += n
    expr = f"{runs[-1][1] - runs[-1][0]} + (k)"
    for k0, first, n in reversed(runs[:-1]):
        expr = f"(k) < {k0 + n} ? {first - k0} + (k) : {expr}"
    lines.append(f"#define ROW_margin(k) leaf_row_texel({expr})")
    lines.append("#else")
    for name, count in members:
        lines.append(f"#define ROW_{name}(i) (LEAF_ROW.{name}[i])" if count > 1 else f"#define ROW_{name} (LEAF_ROW.{name})")
    cases, k = [], 0
    for name, n in MARGIN_MEMBERS:
        cases.append((k + n, f"LEAF_ROW.{name}[clamp((k) - {k}, 0, {n - 1})]"))
        k += n
    expr = cases[-1][1]
    for limit, pick in reversed(cases[:-1]):
        expr = f"((k) < {limit} ? {pick} : {expr})"
    lines.append(f"#define ROW_margin(k) {expr}")
    lines.append("#endif")
    lines += [slot.row_glsl() for slot in LEAF_SLOTS if slot.member not in vertex]
    for accessor, member in PAIR_MEMBERS.items():
        lines.append(f"#define ROW_{accessor}(j) leafview_pair_half(ROW_{member}((j) / 2), (j))")
    return "\n".join(lines) + "\n"


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
        "generated/leaf_vertex.glsl": _vertex_glsl(),
        "generated/leaf_attributes.glsl": attributes_glsl(),
        "generated/leaf_row.glsl": row_glsl(),
        "generated/frame_block.glsl": FRAME_BLOCK.glsl("FRAME_BINDING"),
        "generated/light_block.glsl": LIGHT_BLOCK.glsl("LIGHT_BINDING"),
        "generated/shadow_block.glsl": SHADOW_BLOCK.glsl("SHADOW_BINDING"),
        "generated/wind_block.glsl": WIND_BLOCK.glsl("WIND_BINDING"),
        "generated/scene_blocks.glsl": (SPECIES_CULL_BLOCK.struct_glsl()
                                        + struct_from_dtype("DrawCommand", DRAW_COMMAND_DTYPE)),
        "generated/fbm_job.glsl": struct_from_dtype("FbmJob", FBM_JOB_DTYPE),
        "generated/aov_outputs.glsl": aov_outputs_glsl(),
        "generated/vein_shading.glsl": vein_shading_glsl(),
        "generated/aov_vertex.glsl": (f"// generated from leafview/gpu/layout.py: first leaf of the drawn batch\n"
                                      f"uniform uint {LEAF_OFFSET_UNIFORM};\n"),
    }
