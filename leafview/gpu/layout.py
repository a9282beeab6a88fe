"""The one declaration of the GPU data layouts: each block is a list of (name, GLSL type, count).

From it come the numpy structured dtype (what Python fills) and the GLSL struct text (what the
shaders see, served to the loader as ``#include "generated/<name>.glsl"``). Members are restricted
to ``vec4``/``ivec4``/``mat4`` (and arrays of them) so the std140 (uniform block) and std430
(storage buffer row) packings coincide with the dense numpy packing: no padding rules to drift.
A test checks each block against the size the linked program reflects.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from typing import Any, Iterable

from numpy.typing import NDArray

from ..model.leaf import JITTER_TABLE_SIZE, jitter_table
from ..model.params import LeafParams

__all__ = ["Block", "LEAF_BLOCK", "FRAME_BLOCK", "LEAF_BINDING", "FRAME_BINDING", "LEAVES_BINDING", "pack_leaf", "pack_leaves", "generated_sources"]

_TYPES = {"vec4": ("<f4", (4,)), "ivec4": ("<i4", (4,)), "mat4": ("<f4", (4, 4))}


@dataclass(frozen=True)
class Block:
    """A GLSL struct ``struct_name`` and the uniform block ``block_name`` that holds one of it."""

    struct_name: str
    block_name: str
    members: tuple[tuple[str, str, int], ...]
    doc: str = ""

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

    def glsl(self, binding: int) -> str:
        lines = [f"// generated from leafview/gpu/layout.py: {self.doc}", f"struct {self.struct_name} {{"]
        for name, glsl, count in self.members:
            lines.append(f"    {glsl} {name}{'' if count == 1 else f'[{count}]'};")
        lines += ["};", f"layout(std140, binding = {binding}) uniform {self.block_name} {{",
                  f"    {self.struct_name} {self.block_name.lower()};", "};", ""]
        return "\n".join(lines)

    def zeros(self) -> np.ndarray:
        return np.zeros((), dtype=self.dtype)


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
        ("back", "vec4", 1),       # back rgb, unused
        ("model", "mat4", 1),      # leaf space -> world
        # derived on the GPU by leaf_prepare.comp, packed so the vertex shader loads 6 vec4s:
        ("axis", "vec4", 3),       # xyz A(v̄_i), w (x̄s_i · n(v̄_i)).x
        ("heights", "vec4", 3),    # z̄f_i, z̄g_i, z̄s_i, (x̄s_i · n(v̄_i)).y   (n has no z, eq. 2)
    ),
    "one leaf: Ω, jitter, material, world transform; axis/heights written by leaf_prepare.comp",
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

LEAF_BINDING, FRAME_BINDING = 0, 1   # uniform blocks
LEAVES_BINDING = 2                   # storage buffer of LeafData rows (instancing, prepare pass)


def pack_leaf(params: LeafParams, out: np.ndarray | None = None) -> np.ndarray:
    """Fill a LEAF_BLOCK record from ``params`` (float32, std140 = std430)."""
    rec = LEAF_BLOCK.zeros() if out is None else out
    s, j, m = params.shape, params.jitter, params.material
    rec["a1"][:3] = s.a1
    rec["a2"][:3] = s.a2
    rec["vbar"][:3] = s.vbar
    rec["xs"][:3] = s.xs
    rec["zs"][:3] = s.zs
    rec["zf"][:3] = s.zf
    rec["zg"][:3] = s.zg
    amp = j.amplitude if j.enabled else 0.0
    rec["jitter"] = (amp, j.density, JITTER_TABLE_SIZE, 0.0)
    rec["front"] = (*m.front, m.translucency)
    rec["back"] = (*m.back, 0.0)
    rec["model"] = params.transform.matrix().T  # column-major for GLSL
    return rec


def pack_leaves(params: Iterable[LeafParams]) -> tuple[NDArray[Any], NDArray[np.float32]]:
    """LEAF_BLOCK records (N,) for ``params`` and the jitter table rows they index: one row of
    :data:`JITTER_TABLE_SIZE` values per distinct seed among leaves with jitter on (at least one
    row). ``record["jitter"][3]`` is the row."""
    params = list(params)
    recs = np.zeros(len(params), dtype=LEAF_BLOCK.dtype)
    rows: dict[int, int] = {}
    tables: list[NDArray[np.float32]] = []
    for i, p in enumerate(params):
        pack_leaf(p, recs[i])
        if p.jitter.enabled:
            row = rows.get(p.jitter.seed)
            if row is None:
                row = rows[p.jitter.seed] = len(tables)
                tables.append(jitter_table(p.jitter))
            recs[i]["jitter"][3] = float(row)
    table = np.stack(tables) if tables else np.zeros((1, JITTER_TABLE_SIZE), np.float32)
    return recs, table.astype(np.float32)


def generated_sources() -> dict[str, str]:
    """Virtual include files produced from the declarations above."""
    return {
        "generated/leaf_block.glsl": LEAF_BLOCK.glsl(LEAF_BINDING),
        "generated/frame_block.glsl": FRAME_BLOCK.glsl(FRAME_BINDING),
    }
