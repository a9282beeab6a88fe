// The leaf surface L_Ω(u, v) of seed 004 sec. 3 (eqs 2-6), its partial derivatives and normal,
// plus the jittered silhouette of sec. 6. Conventions and the numpy reference:
// leafview/model/leaf.py (a test compares positions read back from this code with it).
#ifndef LEAFVIEW_LEAF_EVAL_GLSL
#define LEAFVIEW_LEAF_EVAL_GLSL
#include "bezier.glsl"

struct LeafEval {
    vec3 L;    // position (leaf space)
    vec3 Lu;   // dL/du
    vec3 Lv;   // dL/dv
    vec3 Luv;  // d2L/dudv
};

const vec3 LEAF_BASE = vec3(0.0);
const vec3 LEAF_APEX = vec3(0.0, 1.0, 0.0);

// eq. 2: the axis tangent rotated +90 degrees in the xy plane, z dropped, normalised
vec3 axis_normal(vec3 d) {
    vec3 m = vec3(-d.y, d.x, 0.0);
    return m / length(m);
}

LeafEval leaf_eval(LeafData d, sampler2D jitter_tex, vec2 uv) {
    float u = uv.x, v = uv.y;
    float sigma = u >= 0.0 ? 1.0 : -1.0;
    float s = abs(u);
    vec3 a1 = d.a1.xyz, a2 = d.a2.xyz;

    // control points of S, F, G for this side (eqs 3, 4a, 4b)
    vec3 S[3], F[3], G[3];
    for (int i = 0; i < 3; ++i) {
        float vb = d.vbar[i];
        vec3 A = cubic(LEAF_BASE, a1, a2, LEAF_APEX, vb);
        vec3 n = axis_normal(cubic_dt(LEAF_BASE, a1, a2, LEAF_APEX, vb));
        float x = sigma * d.xs[i];
        S[i] = A + x * n + vec3(0.0, 0.0, d.zs[i]);
        F[i] = A + (1.0 / 3.0) * x * n + vec3(0.0, 0.0, d.zf[i]);
        G[i] = A + (2.0 / 3.0) * x * n + vec3(0.0, 0.0, d.zg[i]);
    }

    // the four longitudinal curves at v (eq. 5) and their v-derivatives
    vec3 c0 = cubic(LEAF_BASE, a1, a2, LEAF_APEX, v);
    vec3 c1 = quartic(LEAF_BASE, F[0], F[1], F[2], LEAF_APEX, v);
    vec3 c2 = quartic(LEAF_BASE, G[0], G[1], G[2], LEAF_APEX, v);
    vec3 c3 = quartic(LEAF_BASE, S[0], S[1], S[2], LEAF_APEX, v);
    vec3 d0 = cubic_dt(LEAF_BASE, a1, a2, LEAF_APEX, v);
    vec3 d1 = quartic_dt(LEAF_BASE, F[0], F[1], F[2], LEAF_APEX, v);
    vec3 d2 = quartic_dt(LEAF_BASE, G[0], G[1], G[2], LEAF_APEX, v);
    vec3 d3 = quartic_dt(LEAF_BASE, S[0], S[1], S[2], LEAF_APEX, v);

    // cross-section cubic C_v sampled at s = |u| (eq. 6)
    vec4 b = bernstein3(s);
    vec4 db = bernstein3_dt(s);
    LeafEval e;
    e.L = b.x * c0 + b.y * c1 + b.z * c2 + b.w * c3;
    e.Lu = sigma * (db.x * c0 + db.y * c1 + db.z * c2 + db.w * c3);
    e.Lv = b.x * d0 + b.y * d1 + b.z * d2 + b.w * d3;
    e.Luv = sigma * (db.x * d0 + db.y * d1 + db.z * d2 + db.w * d3);

    // jittered silhouette (sec. 6): D = amp j(v) s^2 tau(v) sigma n(v)
    float amp = d.jitter.x;
    if (amp > 0.0) {
        int size = int(d.jitter.z);
        float t = v * d.jitter.y;
        float fi = floor(t);
        float fr = t - fi;
        int i0 = int(mod(fi, float(size)));
        int i1 = (i0 + 1) % size;
        float j0 = texelFetch(jitter_tex, ivec2(i0, int(d.jitter.w)), 0).r;
        float j1 = texelFetch(jitter_tex, ivec2(i1, int(d.jitter.w)), 0).r;
        float j = j0 + (j1 - j0) * fr;
        float dj = (j1 - j0) * d.jitter.y;
        float w = 2.0 * v - 1.0;
        float w3 = w * w * w;
        float tau = 1.0 - w3 * w, dtau = -8.0 * w3;

        vec3 m = vec3(-d0.y, d0.x, 0.0);
        vec3 a_dd = cubic_dt2(LEAF_BASE, a1, a2, LEAF_APEX, v);
        vec3 dm = vec3(-a_dd.y, a_dd.x, 0.0);
        float mlen = length(m);
        vec3 n = m / mlen;
        vec3 dn = (dm - n * dot(n, dm)) / mlen;

        vec3 g = (j * tau) * n;
        vec3 dg = (dj * tau + j * dtau) * n + (j * tau) * dn;
        e.L += (amp * s * s * sigma) * g;
        e.Lu += (amp * 2.0 * s) * g;
        e.Lv += (amp * s * s * sigma) * dg;
        e.Luv += (amp * 2.0 * s) * dg;
    }
    return e;
}

// Upper-side unit normal normalize(Lv x Lu); at the pinched base/apex Lu vanishes and its limit
// direction +-Luv is used instead (leafview/model/leaf.py, _normal_from).
vec3 leaf_normal(LeafEval e, float v) {
    vec3 lu = v <= 0.0 ? e.Luv : (v >= 1.0 ? -e.Luv : e.Lu);
    vec3 n = cross(e.Lv, lu);
    float len = length(n);
    return len > 0.0 ? n / len : vec3(0.0, 0.0, 1.0);
}

#endif
