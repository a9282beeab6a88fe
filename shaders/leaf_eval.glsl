// The leaf surface L_Ω(u, v) (Chaurasia & Beardsley 2017, sec. 3, eqs 2-6), its partial derivatives and normal,
// plus the jittered silhouette of sec. 6.
// Shader permutations: LEAF_NO_JITTER, LEAF_NO_RIPPLE, LEAF_NO_BEND and LEAF_NO_EXTENDED (and
// LEAF_NO_HALF in leaf.vert) compile the feature out when no leaf of a draw uses it
// (leafview.gpu.layout.feature_defines), and LEAF_NO_VEINS the vein-shape grid when no leaf has a
// vein layer (leafview.gpu.layout.vein_defines), and LEAF_NO_LOBES the swept surface of lobed
// leaves (lobe_eval) when no leaf of a draw is lobed (leafview.gpu.layout.lobe_defines); the results
// are the same for the leaves they are used with, to float rounding (the compiler may contract
// a multiply-add differently when more code shares the function: up to about 1e-7 apart).
// The including shader defines LEAF as the record every vertex reads (the Leaf uniform block, a
// LeafData row, or the LeafVertex made of instanced vertex attributes: only the LeafVertex members
// and the branch code are read through it). The members of the optional branches (ripples,
// bending, extended silhouettes) are read through the generated ROW_* macros: from the LeafData
// LEAF_ROW (default LEAF), or, with LEAF_ROW_TEXTURE, from row LEAF_ROW_INDEX of the leaf_rows
// texture. Fields are read where they are used, never copied as a whole struct: a copy makes the
// compiler load every field (and on llvmpipe each storage-buffer load is a per-vertex gather).
// Conventions and the numpy reference:
// leafview/deform/surface.py (a test compares positions read back from this code with it).
#ifndef LEAFVIEW_LEAF_EVAL_GLSL
#define LEAFVIEW_LEAF_EVAL_GLSL
#include "bezier.glsl"
#include "fbm.glsl"
#ifndef LEAF_ROW
#define LEAF_ROW LEAF
#endif
#include "generated/leaf_row.glsl"

// the ripple signals (fBm, one row of RIPPLE_SAMPLES per (seed, beta)), written by fbm.comp
layout(std430, binding = SIGNALS_BINDING) readonly buffer Signals { float signals[]; };

#ifndef LEAF_NO_VEINS
// the vein-shape grids (leafview/botany/vein_shape.py, vein_grid), one layer per (shape, venation):
// xyz the blade's displacement by its edited veins, w the ripple coordinate
layout(binding = VEIN_GRID_UNIT) uniform sampler2DArray leaf_vein_grid;
#endif

struct LeafEval {
    vec3 L;    // position (leaf space)
    vec3 Lu;   // dL/du
    vec3 Lv;   // dL/dv
    vec3 Luv;  // d2L/dudv
};



// tau(v) = 1 - (2v - 1)^4 (x) and its derivative (y): zero at base and apex
vec2 tip_taper(float v) {
    float w = 2.0 * v - 1.0;
    float w3 = w * w * w;
    return vec2(1.0 - w3 * w, -8.0 * w3);
}

// Rippled margin (Geng, Hu & Zhang 2014, eq. 5): D = tau(v) r(w) c(|u|) z, r = P [lambda + (1 - lambda) N(k veins w
// + theta)], c(s) = s^2 (3 - s) / 2 the small-deflection shape of a tip-loaded cantilever (the
// secondary vein from the midrib). wc = (w, dw/du, dw/dv, d2w/dudv): the ripple coordinate, v
// itself without veins, else the vein grid's w (constant along each secondary vein, so that the
// veins are the beams; the d2L/dudv term tau r''(w) w_u w_v c is left out: zero where d2L/dudv is
// used, at the pinched ends). numpy reference: leafview/deform/surface.py, _add_ripple.
void add_ripple(float sigma, float s, float v, vec4 wc, inout LeafEval e) {
    vec4 rp = sigma > 0.0 ? ROW_ripple_l : ROW_ripple_r;  // P, lambda, k, theta
    int base = ROW_leaf_signal_row * RIPPLE_SAMPLES;
    float veins = ROW_leaf_veins;
    float t = rp.z * veins * wc.x + rp.w;
    vec2 n;
    FBM_SAMPLE_PERIODIC(signals, base, RIPPLE_SAMPLES, t, n);
    float r = rp.x * (rp.y + (1.0 - rp.y) * n.x);
    float dr = rp.x * (1.0 - rp.y) * n.y * rp.z * veins;  // dr/dw
    vec2 tau = tip_taper(v);
    float c = 0.5 * s * s * (3.0 - s);
    float dc = 3.0 * s - 1.5 * s * s;
    float ru = dr * wc.y;
    float g = tau.y * r + tau.x * (dr * wc.z);
    e.L.z += tau.x * r * c;
    e.Lu.z += sigma * tau.x * r * dc + tau.x * ru * c;
    e.Lv.z += c * g;
    e.Luv.z += sigma * dc * g + c * (tau.y * ru + tau.x * dr * wc.w);
}

#ifndef LEAF_NO_VEINS
// row j of grid layer `layer` at column position i0 + fx (value r, d/dx rx; wx = 0 where x is
// clamped); rows -1 and nv are the pinned rows past the texel centres: (0, 0, 0, 1) at the apex,
// 0 at the base
void vein_grid_row(int layer, int j, int nv, int i0, float fx, float wx, out vec4 r, out vec4 rx) {
    if (j < 0 || j >= nv) {
        r = j < 0 ? vec4(0.0, 0.0, 0.0, 1.0) : vec4(0.0);
        rx = vec4(0.0);
        return;
    }
    vec4 a = texelFetch(leaf_vein_grid, ivec3(i0, j, layer), 0);
    vec4 b = texelFetch(leaf_vein_grid, ivec3(i0 + 1, j, layer), 0);
    r = a + (b - a) * fx;
    rx = (b - a) * wx;
}

// The vein-shape grid at uv and its partials (g, dg/du, dg/dv, d2g/dudv): bilinear between texel
// centres at (s, t) = ((1 - u) / 2, 1 - v) (leafview/core/texture.py), clamped across u, pinned
// along v (the rows above). numpy reference: leafview/deform/surface.py, sample_vein_grid.
void vein_grid_eval(int layer, vec2 uv, out vec4 g, out vec4 gu, out vec4 gv, out vec4 guv) {
    ivec3 size = textureSize(leaf_vein_grid, 0);
    int nu = size.x, nv = size.y;
    float x = 0.5 * (1.0 - uv.x) * float(nu) - 0.5;
    float wx = (x > 0.0 && x < float(nu - 1)) ? 1.0 : 0.0;
    x = clamp(x, 0.0, float(nu - 1));
    int i0 = min(int(floor(x)), nu - 2);
    float fx = x - float(i0);
    float y = (1.0 - uv.y) * float(nv) - 0.5;
    int j = clamp(int(floor(y)), -1, nv - 1);
    float y0 = max(float(j), -0.5);
    float y1 = min(float(j + 1), float(nv) - 0.5);
    vec4 r0, r0x, r1, r1x;
    vein_grid_row(layer, j, nv, i0, fx, wx, r0, r0x);
    vein_grid_row(layer, j + 1, nv, i0, fx, wx, r1, r1x);
    float h = 1.0 / (y1 - y0);
    float fy = (y - y0) * h;
    g = r0 + (r1 - r0) * fy;
    gu = (r0x + (r1x - r0x) * fy) * (-0.5 * float(nu));
    gv = (r1 - r0) * (h * -float(nv));
    guv = (r1x - r0x) * (h * (0.5 * float(nu) * float(nv)));
}
#endif

mat3 cross_matrix(vec3 a) {
    return mat3(0.0, a.z, -a.y, -a.z, 0.0, a.x, a.y, -a.x, 0.0);  // columns
}

// rotation about unit axis a by angle t (Rodrigues)
mat3 axis_rotation(vec3 a, float t) {
    float c = cos(t), s = sin(t);
    return c * mat3(1.0) + s * cross_matrix(a) + (1.0 - c) * outerProduct(a, a);
}

// the four bend samples i - 1 .. i + 2 around the interval i (0 <= i <= BEND_SAMPLES - 2); the ones
// past either end are extrapolated linearly from the two end samples (four reads)
void bend_samples(int i, out vec4 p0, out vec4 p1, out vec4 p2, out vec4 p3) {
    p1 = ROW_bend(i);
    p2 = ROW_bend(i + 1);
    p0 = i > 0 ? ROW_bend(max(i - 1, 0)) : 2.0 * p1 - p2;
    p3 = i + 2 < BEND_SAMPLES ? ROW_bend(min(i + 2, BEND_SAMPLES - 1)) : 2.0 * p2 - p1;
}

// Midrib bend and twist (Geng, Hu & Zhang 2014, secs 4, 5.2.2): p' = A + Delta(v) + R(v) (p - A), R = R_N(Phi(v))
// R_y(alpha v), Delta and Phi Catmull-Rom through the host's bend samples. numpy reference:
// leafview/deform/surface.py, _bend, and leafview/deform/beam.py, sample_clamped.
void apply_bend(float v, vec3 Av, vec3 dAv, inout LeafEval e) {
    float t = clamp(v, 0.0, 1.0) * float(BEND_SAMPLES - 1);
    int i = min(int(floor(t)), BEND_SAMPLES - 2);
    float x = t - float(i);
    vec4 p0, p1, p2, p3;
    bend_samples(i, p0, p1, p2, p3);
    vec4 c1 = 0.5 * (p2 - p0);
    vec4 c2 = p0 - 2.5 * p1 + 2.0 * p2 - 0.5 * p3;
    vec4 c3 = 0.5 * (p3 - p0) + 1.5 * (p1 - p2);
    vec4 val = ((c3 * x + c2) * x + c1) * x + p1;                        // Delta.xyz, Phi
    vec4 slope = ((3.0 * c3 * x + 2.0 * c2) * x + c1) * float(BEND_SAMPLES - 1);

    vec3 axis = ROW_bend_axis.xyz;
    float alpha = ROW_leaf_twist;
    const vec3 Y = vec3(0.0, 1.0, 0.0);
    mat3 rn = axis_rotation(axis, val.w);
    mat3 ry = axis_rotation(Y, alpha * v);
    mat3 r = rn * ry;
    mat3 dr = slope.w * (cross_matrix(axis) * r) + alpha * (rn * (cross_matrix(Y) * ry));
    vec3 rel = e.L - Av;
    vec3 Luv = dr * e.Lu + r * e.Luv;
    vec3 Lv = dAv + slope.xyz + dr * rel + r * (e.Lv - dAv);
    e.L = Av + val.xyz + r * rel;
    e.Lu = r * e.Lu;
    e.Lv = Lv;
    e.Luv = Luv;
}

// Extended silhouette (leafview/core/params.py): N rows, S, F and G of degree n = N + 1, rows
// possibly tilted. Same rearrangement as below with degree-n Bernstein weights, plus the tilt
// curve T(v) = sum_i w_i T_i (T_i = -x̄s_i sin φ_i t(v̄_i), side-independent), which the cubic
// cross-section's linear precision turns into + |u| T(v). Rows 1-3 are read from axis/heights,
// rows 4..N from sil_axis/sil_heights, the T_i from sil_tilt (all written by leaf_prepare.comp).
void ext_silhouette(int rows, float v, out vec3 Pv, out vec3 Qv, out vec3 dPv, out vec3 dQv,
                    out vec3 z, out vec3 dz, out vec2 Tv, out vec2 dTv) {
    int n = rows + 1;
    float t = 1.0 - v;
    float pv[SIL_MAX_ROWS + 2], pt[SIL_MAX_ROWS + 2];  // v^k and (1 - v)^k, k = 0..n
    pv[0] = 1.0;
    pt[0] = 1.0;
    for (int k = 1; k <= n; ++k) {
        pv[k] = pv[k - 1] * v;
        pt[k] = pt[k - 1] * t;
    }
    Pv = pv[n] * LEAF_APEX;
    dPv = float(n) * pv[n - 1] * LEAF_APEX;
    Qv = vec3(0.0); dQv = vec3(0.0); z = vec3(0.0); dz = vec3(0.0); Tv = vec2(0.0); dTv = vec2(0.0);
    int c = 1;   // C(n, i)
    int cm = 1;  // C(n - 1, i - 1)
    for (int i = 1; i < n; ++i) {
        c = c * (n - i + 1) / i;
        int cn = cm * (n - i) / i;  // C(n - 1, i)
        float w = float(c) * pv[i] * pt[n - i];
        // d/dv of the degree-n Bernstein weight: n (B^{n-1}_{i-1} - B^{n-1}_i)
        float dw = float(n) * (float(cm) * pv[i - 1] * pt[n - i] - float(cn) * pv[i] * pt[n - 1 - i]);
        cm = cn;
        int k = i - 1;  // row index
        vec4 ka, kh;
        if (k < 3) {
            ka = LEAF.axis[min(k, 2)];
            kh = LEAF.heights[min(k, 2)];
        } else {
            ka = ROW_sil_axis(max(k - 3, 0));
            kh = ROW_sil_heights(max(k - 3, 0));
        }
        vec2 T = ROW_leaf_sil_tilt(k);
        vec3 Q = vec3(ka.w, kh.w, 0.0);
        Pv += w * ka.xyz;
        dPv += dw * ka.xyz;
        Qv += w * Q;
        dQv += dw * Q;
        z += w * kh.xyz;
        dz += dw * kh.xyz;
        Tv += w * T;
        dTv += dw * T;
    }
}

// Landmark margin (leafview/core/margin.py; Garg & Leow 2011, eqs 2-6), leaf_rows = LEAF_MARGIN_ROWS:
// side sigma's quadratic B-spline (x, y)(v), written in the side's own frame, is placed on the
// midrib at the height y: P = A(y), Q = x n(y) (n the in-plane normal of eq. 2), and their
// v-derivatives. A side is MARGIN_SIDE_TEXELS texels of ROW_margin: the inner knots (w: the gaps),
// then per gap (p_g, a_g) and (b_g, p_{g+1}); the gap's two spans meet at m = (a_g + b_g) / 2.
// numpy reference: leafview/core/margin.py, side_points and margin_frame.
void margin_silhouette(float sigma, float v, vec3 a1, vec3 a2, out vec3 Pv, out vec3 Qv, out vec3 dPv,
                       out vec3 dQv) {
    int base = sigma > 0.0 ? 0 : MARGIN_SIDE_TEXELS;
    vec4 kt = ROW_margin(base);
    int gaps = int(kt.w);
    int g = min(int(v >= kt.x) + int(v >= kt.y) + int(v >= kt.z), gaps - 1);
    float lo = g == 0 ? 0.0 : kt[max(g - 1, 0)];
    float hi = g == gaps - 1 ? 1.0 : kt[min(g, 3)];
    vec4 t0 = ROW_margin(base + 1 + 2 * g);  // p_g, a_g
    vec4 t1 = ROW_margin(base + 2 + 2 * g);  // b_g, p_{g+1}
    float h = hi - lo;
    float f = (v - lo) / h;
    vec2 m = 0.5 * (t0.zw + t1.xy);
    bool first = f < 0.5;
    float t = first ? 2.0 * f : 2.0 * f - 1.0;
    vec2 c0 = first ? t0.xy : m;
    vec2 c1 = first ? t0.zw : t1.xy;
    vec2 c2 = first ? m : t1.zw;
    float r = 1.0 - t;
    vec2 p = r * r * c0 + 2.0 * r * t * c1 + t * t * c2;
    vec2 dp = (4.0 / h) * (r * (c1 - c0) + t * (c2 - c1));
    vec3 dA = cubic_dt(LEAF_BASE, a1, a2, LEAF_APEX, p.y);
    vec3 ddA = cubic_dt2(LEAF_BASE, a1, a2, LEAF_APEX, p.y);
    vec3 n, dn;
    in_plane_normal(dA, ddA, p.y, n, dn);
    Pv = cubic(LEAF_BASE, a1, a2, LEAF_APEX, p.y);
    Qv = p.x * n;
    dPv = dA * dp.y;
    dQv = dp.x * n + (p.x * dp.y) * dn;
}

// Evaluation strategy (exactly eqs 3-6, rearranged; the numpy reference in leafview/deform/surface.py
// implements the equations literally and the readback test compares the two):
// S, F and G for side sigma share the axis points A(v̄_i) and differ only in the fraction of
// x̄_i n(v̄_i) (1, 1/3, 2/3) and in their heights. With P the quartic through (0, A(v̄_1..3), apex),
// Q the quartic through (0, x̄_i n(v̄_i), 0) and zS, zF, zG the scalar quartics of the heights:
//   S = P + sigma Q + zS z,  F = P + sigma Q / 3 + zF z,  G = P + 2 sigma Q / 3 + zG z.
// The cubic Bernstein basis has linear precision, sum_k (k/3) B_k(s) = s, so eq. 6 becomes
//   L(u, v) = B_0(s) A(v) + (1 - B_0(s)) P(v) + u Q(v) + (B_1 zF + B_2 zG + B_3 zS) z
// two vector quartics per vertex instead of six.
LeafEval leaf_eval(sampler2D jitter_tex, vec2 uv) {
    float u = uv.x, v = uv.y;
    float sigma = u >= 0.0 ? 1.0 : -1.0;
    float s = abs(u);
    vec3 a1 = LEAF.a1.xyz, a2 = LEAF.a2.xyz;

    // the axis points A(v̄_i) and scaled in-plane normals x̄s_i n(v̄_i) of eqs 3-4: per-leaf
    // constants, filled in by leaf_prepare.comp before any draw
    vec4 k1 = LEAF.axis[0], k2 = LEAF.axis[1], k3 = LEAF.axis[2];
    vec4 h1 = LEAF.heights[0], h2 = LEAF.heights[1], h3 = LEAF.heights[2];
    vec3 P1 = k1.xyz, P2 = k2.xyz, P3 = k3.xyz;
    vec3 Q1 = vec3(k1.w, h1.w, 0.0), Q2 = vec3(k2.w, h2.w, 0.0), Q3 = vec3(k3.w, h3.w, 0.0);
    vec3 zf = vec3(h1.x, h2.x, h3.x), zg = vec3(h1.y, h2.y, h3.y), zs = vec3(h1.z, h2.z, h3.z);

    vec3 Pv, Qv, dPv, dQv, z, dz;
    vec2 Tv, dTv;
#ifdef LEAF_NO_EXTENDED
    const int rows = 0;           // no leaf of this draw is extended: the branches below fold away
#else
    int rows = leaf_branch_rows(LEAF);  // 0: the paper's quartic; LEAF_MARGIN_ROWS: a landmark
                                         // margin; N > 1: an extended silhouette of N rows
#endif
    Tv = vec2(0.0);
    dTv = vec2(0.0);
    // the paper's quartic (rows 0) and a landmark margin share the heights of the three rows
    // (degree 4); LEAF_NO_MARGIN / LEAF_NO_SIL_ROWS compile out the branches no leaf of a draw takes
#if defined(LEAF_NO_EXTENDED)
    const bool quartic_heights = true;
#elif defined(LEAF_NO_SIL_ROWS)
    const bool quartic_heights = true;   // rows is 0 or LEAF_MARGIN_ROWS
#else
    bool quartic_heights = rows == 0 || rows == LEAF_MARGIN_ROWS;
#endif
    if (quartic_heights) {
        // quartic weights at v for the inner points (the base is the origin, so it drops out) and
        // the apex, and their v-derivatives
        float t = 1.0 - v, v2 = v * v, t2 = t * t;
        vec3 w = vec3(4.0 * t2 * t * v, 6.0 * t2 * v2, 4.0 * t * v2 * v);
        float w_apex = v2 * v2;
        vec4 b3 = bernstein3(v);  // quartic derivative weights: 4 (B3_{i-1} - B3_i)
        vec3 dw = 4.0 * (b3.xyz - b3.yzw);
        float dw_apex = 4.0 * b3.w;
        z = vec3(dot(w, zf), dot(w, zg), dot(w, zs));      // zF, zG, zS at v
        dz = vec3(dot(dw, zf), dot(dw, zg), dot(dw, zs));
#if !defined(LEAF_NO_EXTENDED) && !defined(LEAF_NO_MARGIN)
        if (rows == LEAF_MARGIN_ROWS) {
            // the side's B-spline on the midrib replaces P and Q; no tilts
            margin_silhouette(sigma, v, a1, a2, Pv, Qv, dPv, dQv);
        } else
#endif
        {
            Pv = w.x * P1 + w.y * P2 + w.z * P3 + w_apex * LEAF_APEX;
            Qv = w.x * Q1 + w.y * Q2 + w.z * Q3;
            dPv = dw.x * P1 + dw.y * P2 + dw.z * P3 + dw_apex * LEAF_APEX;
            dQv = dw.x * Q1 + dw.y * Q2 + dw.z * Q3;
        }
    }
#if !defined(LEAF_NO_EXTENDED) && !defined(LEAF_NO_SIL_ROWS)
    else {
        ext_silhouette(rows, v, Pv, Qv, dPv, dQv, z, dz, Tv, dTv);
    }
#endif

    vec3 Av = cubic(LEAF_BASE, a1, a2, LEAF_APEX, v);
    vec3 dAv = cubic_dt(LEAF_BASE, a1, a2, LEAF_APEX, v);

    // cross-section cubic at s = |u| (eqs 5-6), rearranged as above
    vec4 b = bernstein3(s);
    vec4 db = bernstein3_dt(s);
    LeafEval e;
    e.L = b.x * Av + (1.0 - b.x) * Pv + u * Qv + vec3(0.0, 0.0, dot(b.yzw, z));
    e.Lu = sigma * db.x * (Av - Pv) + Qv + vec3(0.0, 0.0, sigma * dot(db.yzw, z));
    e.Lv = b.x * dAv + (1.0 - b.x) * dPv + u * dQv + vec3(0.0, 0.0, dot(b.yzw, dz));
    e.Luv = sigma * db.x * (dAv - dPv) + dQv + vec3(0.0, 0.0, sigma * dot(db.yzw, dz));
#if !defined(LEAF_NO_EXTENDED) && !defined(LEAF_NO_SIL_ROWS)
    if (rows > LEAF_MARGIN_ROWS) {  // tilted rows: + |u| T(v), T the side-independent tilt offsets
        e.L.xy += s * Tv;
        e.Lu.xy += sigma * Tv;
        e.Lv.xy += s * dTv;
        e.Luv.xy += sigma * dTv;
    }
#endif

    // jittered silhouette (sec. 6): D = amp j(v) s^2 tau(v) sigma n(v)
#ifndef LEAF_NO_JITTER
    float amp = leaf_jitter_amplitude(LEAF);
    if (amp > 0.0) {
        int size = leaf_jitter_size(LEAF);
        float density = leaf_jitter_density(LEAF);
        int row = leaf_jitter_row(LEAF);
        float t = v * density;
        float fi = floor(t);
        float fr = t - fi;
        int i0 = int(mod(fi, float(size)));
        int i1 = (i0 + 1) % size;
        float j0 = texelFetch(jitter_tex, ivec2(i0, row), 0).r;
        float j1 = texelFetch(jitter_tex, ivec2(i1, row), 0).r;
        float j = j0 + (j1 - j0) * fr;
        float dj = (j1 - j0) * density;
        vec2 taper = tip_taper(v);
        float tau = taper.x, dtau = taper.y;

        vec3 n, dn;
        in_plane_normal(dAv, cubic_dt2(LEAF_BASE, a1, a2, LEAF_APEX, v), v, n, dn);

        vec3 g = (j * tau) * n;
        vec3 dg = (dj * tau + j * dtau) * n + (j * tau) * dn;
        e.L += (amp * s * s * sigma) * g;
        e.Lu += (amp * 2.0 * s) * g;
        e.Lv += (amp * s * s * sigma) * dg;
        e.Luv += (amp * 2.0 * s) * dg;
    }
#endif
    // vein-driven shape (Hong 2005, ch. 7.2): the blade displaced by its edited veins, and the
    // ripple coordinate w (v without veins)
    vec4 wc = vec4(v, 0.0, 1.0, 0.0);
#ifndef LEAF_NO_VEINS
    int vein_layer = leaf_vein_layer(LEAF);
    if (vein_layer >= 0) {
        vec4 g, gu, gv, guv;
        vein_grid_eval(vein_layer, uv, g, gu, gv, guv);
        e.L += g.xyz;
        e.Lu += gu.xyz;
        e.Lv += gv.xyz;
        e.Luv += guv.xyz;
        wc = vec4(g.w, gu.w, gv.w, guv.w);
    }
#endif
#ifndef LEAF_NO_RIPPLE
    if (leaf_has_ripple(LEAF)) {
        add_ripple(sigma, s, v, wc, e);
    }
#endif
#ifndef LEAF_NO_BEND
    if (leaf_has_bend(LEAF)) {
        apply_bend(v, Av, dAv, e);
    }
#endif
    return e;
}

#ifndef LEAF_NO_LOBES
// The swept surface of a lobed leaf (Mündermann et al. 2003, secs 3.3-4): railroad ties between the
// skeleton and the margin, one per texel column of layer `layer` of leaf_lobe_table, in tour order,
// four texel rows (leafview/deform/sweep.py, table_texels; leafview/gpu/lobe_tables.py):
// r0 (origin O, margin w), r1 (rim E, length l), r2 (up U; w: tie 0 the cup, ties 1-4 the texture
// window), r3 (flat foot k, flat end s).
// numpy reference: leafview/deform/sweep.py, sweep_eval (a readback test compares the two).
layout(binding = LOBE_UNIT) uniform sampler2DArray leaf_lobe_table;

struct LobeEval {
    vec3 L;     // position (leaf space)
    vec3 Lu;    // dL/du
    vec3 Lv;    // dL/dv
    vec3 N;     // upper-side unit normal
    vec2 flat_xy;  // position on the flat leaf (leaf lengths)
    vec2 uv;       // texture coordinates: flat_xy in the table's texture window (u in [-1, 1], v in [0, 1])
    float rib;     // distance from the skeleton along the tie, t l (leaf lengths): the lighter vein band
};

// the periodic Catmull-Rom of texel row `row` at x = j + f (value q, d/dx dq); past either end of the
// N ties the row wraps, the margin coordinate (r0.w) gaining 1 per wrap
void lobe_spline(int layer, int row, int j, float f, int n, out vec4 q, out vec4 dq) {
    vec4 p[4];
    for (int k = 0; k < 4; ++k) {
        int idx = j - 1 + k + n;          // j >= 0: idx >= n - 1 >= 0
        int wraps = idx / n - 1;
        p[k] = texelFetch(leaf_lobe_table, ivec3(idx - (idx / n) * n, row, layer), 0);
        if (row == 0) p[k].w += float(wraps);
    }
    vec4 c1 = 0.5 * (p[2] - p[0]);
    vec4 c2 = p[0] - 2.5 * p[1] + 2.0 * p[2] - 0.5 * p[3];
    vec4 c3 = 0.5 * (p[3] - p[0]) + 1.5 * (p[1] - p[2]);
    q = ((c3 * f + c2) * f + c1) * f + p[1];
    dq = (3.0 * c3 * f + 2.0 * c2) * f + c1;
}

// P(t, x) = O(x) + t (E(x) - O(x)) + cup l(x) t^2 U(x), t = (u + 1) / 2, x = v N; with the leaf's
// ripple on, + r(w) c(t) U(x) (Geng, Hu & Zhang 2014, eq. 5 along the margin: the left-side
// settings, the signal sampled as add_ripple does, tapered on short ties). Normal normalize(Lv x Lu), or U
// where the tie has no extent.
LobeEval lobe_eval(int layer, vec2 uv) {
    int n = textureSize(leaf_lobe_table, 0).x;
    float t = 0.5 * (uv.x + 1.0);
    float x = clamp(uv.y, 0.0, 1.0) * float(n);
    int j = int(floor(x));
    float f = x - float(j);
    vec4 o, d_o, e, d_e, up, d_up, fl, d_fl;
    lobe_spline(layer, 0, j, f, n, o, d_o);
    lobe_spline(layer, 1, j, f, n, e, d_e);
    lobe_spline(layer, 2, j, f, n, up, d_up);
    lobe_spline(layer, 3, j, f, n, fl, d_fl);
    float cup = texelFetch(leaf_lobe_table, ivec3(0, 2, layer), 0).w;
    float ln = e.w, dln = d_e.w;
    LobeEval r;
    r.L = o.xyz + t * (e.xyz - o.xyz) + (cup * ln * t * t) * up.xyz;
    r.Lu = 0.5 * ((e.xyz - o.xyz) + (2.0 * cup * ln * t) * up.xyz);
    r.Lv = float(n) * (d_o.xyz + t * (d_e.xyz - d_o.xyz) + (cup * t * t) * (dln * up.xyz + ln * d_up.xyz));
#ifndef LEAF_NO_RIPPLE
    if (leaf_has_ripple(LEAF)) {
        vec4 rp = ROW_ripple_l;  // P, lambda, k, theta
        float veins = ROW_leaf_veins;
        int base = ROW_leaf_signal_row * RIPPLE_SAMPLES;
        float s = rp.z * veins * o.w + rp.w;
        vec2 sig;
        FBM_SAMPLE_PERIODIC(signals, base, RIPPLE_SAMPLES, s, sig);
        float rw = rp.x * (rp.y + (1.0 - rp.y) * sig.x);
        float drw = rp.x * (1.0 - rp.y) * sig.y * rp.z * veins;   // dr/dw
        // the short ties near the base and the tips ripple less: rho(l) = l^2 / (l^2 + l0^2), so a
        // zero-length tie (the base's) stays flat and the tour closes without a seam
        const float l0 = 0.05;   // leafview/deform/sweep.py, RIPPLE_TIE
        float den = ln * ln + l0 * l0;
        float rho = ln * ln / den;
        float drho = 2.0 * ln * l0 * l0 / (den * den) * dln;   // d rho / dx
        float c = 0.5 * t * t * (3.0 - t);
        float dc = 3.0 * t - 1.5 * t * t;
        r.L += (rw * c * rho) * up.xyz;
        r.Lu += (0.5 * rw * dc * rho) * up.xyz;
        r.Lv += float(n) * ((drw * d_o.w * c * rho + rw * c * drho) * up.xyz + (rw * c * rho) * d_up.xyz);
    }
#endif
    vec3 nrm = cross(r.Lv, r.Lu);
    float size = length(nrm);
    float scale = max(length(r.Lu) * length(r.Lv), 1e-30);
    vec3 upn = up.xyz / max(length(up.xyz), 1e-30);
    r.N = size > 1e-6 * scale ? nrm / size : upn;
    r.flat_xy = fl.xy + t * (fl.zw - fl.xy);
    // the texture window (x_c, w, y_0, h) in the w of texel row 2, ties 1-4 (sweep.py, texture_uv)
    vec4 win = vec4(texelFetch(leaf_lobe_table, ivec3(1, 2, layer), 0).w, texelFetch(leaf_lobe_table, ivec3(2, 2, layer), 0).w,
                    texelFetch(leaf_lobe_table, ivec3(3, 2, layer), 0).w, texelFetch(leaf_lobe_table, ivec3(4, 2, layer), 0).w);
    r.uv = vec2((r.flat_xy.x - win.x) / win.y, (r.flat_xy.y - win.z) / win.w);
    r.rib = t * ln;
    return r;
}
#endif

// Upper-side unit normal normalize(Lv x Lu); at the pinched base/apex Lu vanishes and its limit
// direction +-Luv is used instead (leafview/deform/surface.py, _normal_from).
vec3 leaf_normal(LeafEval e, float v) {
    vec3 lu = v <= 0.0 ? e.Luv : (v >= 1.0 ? -e.Luv : e.Lu);
    vec3 n = cross(e.Lv, lu);
    float len = length(n);
    return len > 0.0 ? n / len : vec3(0.0, 0.0, 1.0);
}

#endif
