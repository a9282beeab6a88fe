#version 450
// Vein tubes, pass 1 of 2 (Hong 2005, ch. 6.1): the frame at both ends of each tube segment,
// captured with transform feedback (one POINTS vertex per segment) for vein_tube.vert to sweep
// its rings from. The segment's ends are (u, v) points, not positions: the blade is evaluated
// there with the same code and the same Leaf record as leaf.vert (leaf_eval.glsl), so the tubes
// follow ripples, bending, the vein-shape grid and every other deformation. Twice per segment
// instead of once per ring vertex: the ring vertices of pass 2 only add r (cos t b + sin t n).
// Frame, offset and the numpy twin: leafview/botany/vein_tubes.py (a test compares the vertices
// read back from both passes with it). TUBE_OFFSET and TUBE_CREASE_U come from that module
// (leafview.gpu.vein_tubes.tube_defines).
#include "generated/leaf_block.glsl"
#define LEAF leaf
#define LEAF_ROW leaf
#include "leaf_eval.glsl"

layout(binding = JITTER_UNIT) uniform sampler2D jitter_table;

in vec4 in_a;   // first point (u, v, du, dv)
in vec4 in_b;   // second point (u, v, du, dv)
in vec4 in_r;   // radius at a, radius at b, vein order, 0

out vec4 t_ca;  // ring centre at a (leaf space), radius at a
out vec3 t_na;  // normal at a: the blade's upper normal, orthogonal to the tangent
out vec3 t_ba;  // binormal at a: tangent x normal, across the vein in the blade's plane
out vec4 t_cb;  // the same at b
out vec3 t_nb;
out vec3 t_bb;

// centre-line point L, normal n and binormal b at (u, v) heading (du, dv)
void tube_frame(vec4 p, out vec3 L, out vec3 n, out vec3 b) {
    LeafEval e = leaf_eval(jitter_table, p.xy);
    vec3 lu = e.Lu;
    vec3 nrm = leaf_normal(e, p.y);
    float half_side = leaf_half(LEAF);
    if (p.x == 0.0 && half_side <= 0.0) {   // the midrib crease: the u < 0 side too
        LeafEval m = leaf_eval(jitter_table, vec2(TUBE_CREASE_U, p.y));
        vec3 nm = leaf_normal(m, p.y);
        if (half_side < 0.0) {
            lu = m.Lu;
            nrm = nm;
        } else {
            nrm = normalize(nrm + nm);
            if (p.z < 0.0) lu = m.Lu;
        }
    }
    vec3 t = normalize(lu * p.z + e.Lv * p.w);
    n = normalize(nrm - dot(nrm, t) * t);
    b = cross(t, n);
    L = e.L;
}

void main() {
    vec3 L, n, b;
    tube_frame(in_a, L, n, b);
    t_ca = vec4(L - (TUBE_OFFSET * in_r.x) * n, in_r.x);
    t_na = n;
    t_ba = b;
    tube_frame(in_b, L, n, b);
    t_cb = vec4(L - (TUBE_OFFSET * in_r.y) * n, in_r.y);
    t_nb = n;
    t_bb = b;
    gl_Position = vec4(0.0, 0.0, 0.0, 1.0);
}
