#version 450
// Per-leaf constants of eqs 3-4, computed once per leaf instead of once per vertex: the axis
// points A(v̄_i) and the scaled in-plane normals x̄s_i n(v̄_i) (eq. 2). The vertex shader reads
// them from the same LeafData row, packed with the heights z̄f, z̄g, z̄s so that it reads six vec4s
// per vertex (see layout.py). numpy reference: leafview/model/leaf.py, axis_frames().
layout(local_size_x = 64) in;
#include "generated/leaf_block.glsl"
#include "bezier.glsl"

layout(std430, binding = 2) buffer Leaves { LeafData leaves[]; };
uniform uint count;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 a1 = leaves[i].a1.xyz, a2 = leaves[i].a2.xyz;
    for (int k = 0; k < 3; ++k) {
        float vb = leaves[i].vbar[k];
        vec3 p = cubic(LEAF_BASE, a1, a2, LEAF_APEX, vb);
        vec3 q = leaves[i].xs[k] * axis_normal(cubic_dt(LEAF_BASE, a1, a2, LEAF_APEX, vb));
        leaves[i].axis[k] = vec4(p, q.x);
        leaves[i].heights[k] = vec4(leaves[i].zf[k], leaves[i].zg[k], leaves[i].zs[k], q.y);
    }
}
