#version 450
// Second pass of a scene's culling (leafview/gpu/scene.py): the vertex records of the visible
// leaves. scene_cull.comp appended each visible leaf's row to its level's list (level k's list
// starts at k * stride) and counted it in the level's draw command. One invocation per list entry,
// level after level: the LeafVertex members of the leaf's row (what every vertex reads) go to one
// compact array, with the row in leaf_vertex_row, so that leaf.vert (LEAF_INDIRECT) reads them as
// per-instance vertex attributes; invocation 0 points each command's baseInstance at its level's
// first record. numpy reference: leafview/gpu/layout.py, vertex_records().
layout(local_size_x = 64) in;
#include "generated/leaf_block.glsl"
#include "generated/leaf_vertex.glsl"
#include "generated/scene_blocks.glsl"

layout(std430, binding = LEAVES_BINDING) readonly buffer Leaves { LeafData leaves[]; };
layout(std430, binding = COMMANDS_BINDING) buffer Commands { DrawCommand commands[]; };
layout(std430, binding = VISIBLE_BINDING) readonly buffer Visible { uint visible[]; };
layout(std430, binding = VERTICES_BINDING) writeonly buffer Vertices { LeafVertex vertices[]; };

uniform uint stride;   // entries of each level's list (the batch's leaf count)
uniform int levels;    // number of levels (draw commands)

void main() {
    uint j = gl_GlobalInvocationID.x;
    uint first = 0u;   // records of the levels before k
    for (int k = 0; k < levels; ++k) {
        uint n = commands[k].instance_count;   // final: the culling pass is done
        if (j == 0u) commands[k].base_instance = first;
        if (j >= first && j < first + n) {
            uint row = visible[uint(k) * stride + (j - first)];
            LeafVertex rec = LEAF_VERTEX_OF(leaves[row]);
            set_leaf_vertex_row(rec, row);
            vertices[j] = rec;
        }
        first += n;
    }
}
