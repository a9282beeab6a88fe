#version 450
// Per-leaf constants of eqs 3-4, computed once per leaf instead of once per vertex: the axis
// points A(v̄_i) and the scaled in-plane normals x̄s_i n(v̄_i) (eq. 2). The vertex shader reads
// them from the same LeafData row, packed with the heights z̄f, z̄g, z̄s so that it reads six vec4s
// per vertex (see layout.py). numpy reference: leafview/deform/surface.py, axis_frames().
// Extended silhouettes (leaf_rows = N > 0): rows may be tilted by φ_i, so the normal part is
// x̄s_i cos φ_i n(v̄_i) and a side-independent offset -x̄s_i sin φ_i t(v̄_i) (t the unit axis
// tangent) goes to sil_tilt; rows 4..N go to sil_axis / sil_heights. numpy reference:
// axis_frames() and tilt_offsets().
// It also writes the branch code leaf_branches (ripples, bending, N and a lobed leaf's sweep-table
// layer; leafview.gpu.layout.branch_code), so that the vertex stage knows the branches a leaf takes from the members it reads
// as vertex attributes.
layout(local_size_x = 64) in;
#include "generated/leaf_block.glsl"
#include "bezier.glsl"

layout(std430, binding = LEAVES_BINDING) buffer Leaves { LeafData leaves[]; };
uniform uint count;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 a1 = leaves[i].a1.xyz, a2 = leaves[i].a2.xyz;
    int rows = leaf_rows(leaves[i]);
    set_leaf_branches(leaves[i], (leaf_ripple_on(leaves[i]) ? LEAF_BRANCH_RIPPLE : 0)
                                 + (leaf_bend_on(leaves[i]) ? LEAF_BRANCH_BEND : 0) + LEAF_BRANCH_ROWS * rows
                                 + LEAF_BRANCH_LOBE * (leaf_lobe_layer(leaves[i]) + 1));
    if (rows <= LEAF_MARGIN_ROWS) {  // the paper's quartic (a landmark margin: its heights; the
                                     // margin's texels in the extended members stay as packed)
        for (int k = 0; k < 3; ++k) {
            float vb = leaves[i].vbar[k];
            vec3 p = cubic(LEAF_BASE, a1, a2, LEAF_APEX, vb);
            vec3 q = leaves[i].xs[k] * axis_normal(cubic_dt(LEAF_BASE, a1, a2, LEAF_APEX, vb));
            leaves[i].axis[k] = vec4(p, q.x);
            leaves[i].heights[k] = vec4(leaves[i].zf[k], leaves[i].zg[k], leaves[i].zs[k], q.y);
        }
        return;
    }
    for (int k = 0; k < rows; ++k) {
        float vb, xs, zs, phi, zf, zg;
        if (k < 3) {
            vb = leaves[i].vbar[k]; xs = leaves[i].xs[k]; zs = leaves[i].zs[k]; phi = leaves[i].tilt[k];
            zf = leaves[i].zf[k]; zg = leaves[i].zg[k];
        } else {
            vec4 r = leaves[i].sil_rows[k - 3];
            vec2 fg = leaf_sil_fg(leaves[i], k - 3);
            vb = r.x; xs = r.y; zs = r.z; phi = r.w;
            zf = fg.x;
            zg = fg.y;
        }
        vec3 p = cubic(LEAF_BASE, a1, a2, LEAF_APEX, vb);
        vec3 d = cubic_dt(LEAF_BASE, a1, a2, LEAF_APEX, vb);
        vec3 q = (xs * cos(phi)) * axis_normal(d);
        vec2 t = (-xs * sin(phi)) * normalize(d.xy);
        vec4 a = vec4(p, q.x), h = vec4(zf, zg, zs, q.y);
        if (k < 3) {
            leaves[i].axis[k] = a;
            leaves[i].heights[k] = h;
        } else {
            leaves[i].sil_axis[k - 3] = a;
            leaves[i].sil_heights[k - 3] = h;
        }
        if (k % 2 == 0) leaves[i].sil_tilt[k / 2].xy = t;
        else leaves[i].sil_tilt[k / 2].zw = t;
    }
}
