// Veins and leaf tissue in leaf.frag (not with LEAF_NO_VEINS): the vein field of the leaf's layer
// (leafview/gpu/vein_field.py; RGBA32F, R distance to the nearest vein's centre line, G its
// order, B its full width, leaf lengths) read at the fragment's (u, v) through the texture
// convention (leaf_texture_st), level 0, bilinear; the leaf's venation contrast and relief and its
// level of detail come flat from the vertex stage (leaf_vein_lod.glsl). The field's A (distance to
// the nearest vein of order <= 2) keeps the major veins whole where tertiaries meet them.
//
// * colour (untextured leaves): skin, the chlorophyll gradient and margin tint (Hong 2005, ch. 8),
//   then the veins lighter and yellower than the lamina by contrast x order weight x antialiased
//   coverage; numpy twin: leafview/botany/vein_shading.py (vein_albedo), whose constants these are;
// * relief: the normal perturbed by the gradient of the vein height profile, from screen-space
//   derivatives (Mikkelsen 2010, "Bump mapping unparametrized surfaces on the GPU": no tangents);
// * transmission: reduced along veins (VEIN_OPACITY) for light from the other side;
// * level of detail: a triangle whose major veins are narrower than VEIN_LOD_NONE pixels reads no
//   field (leaf_vein_lod.glsl): far leaves of a scene pay for their skin only.
#ifndef LEAFVIEW_LEAF_VEINS_GLSL
#define LEAFVIEW_LEAF_VEINS_GLSL
#include "leaf_texture.glsl"
#include "generated/vein_shading.glsl"

layout(binding = VEIN_FIELD_UNIT) uniform sampler2DArray leaf_vein_field;

// what the field says at one fragment
struct VeinSample {
    float coverage;   // vein strength: antialiased coverage x order weight, in [0, 1]
    float height;     // relief height in world units (0 with relief off)
};

float vein_order_weight(float order) {
    return clamp(1.0 - ORDER_WEIGHT_SLOPE * (order - 1.0), ORDER_WEIGHT_MIN, 1.0);
}

// coverage of a vein of full width w at distance d, over a pixel footprint fw of d (vein_coverage)
float vein_coverage(float d, float w, float fw) {
    float r = 0.5 * w, aa = 0.5 * fw;
    float hw = max(max(r, aa), 1e-7);
    return (1.0 - smoothstep(hw - aa, hw + aa, d)) * (r / hw);
}

// height of the profile (1 - x^2)^2 of half width r (vein_height), relief x r at the centre line,
// spread over at least VEIN_BUMP_PIXELS pixel footprints fw of d (the same height, a gentler slope)
// and faded out as the vein narrows below VEIN_BUMP_FULL pixels of half width (gone at
// VEIN_BUMP_NONE): a bump about a pixel wide would alias into dots (the derivatives are taken per
// 2x2 quad), and the slopes of a vein smaller than a pixel average out over it
float vein_height(float d, float w, float relief, float fw) {
    float r = max(0.5 * w, 1e-7);
    float x = clamp(d / max(r, VEIN_BUMP_PIXELS * fw), 0.0, 1.0);
    float y = 1.0 - x * x;
    float fade = clamp((r / max(fw, 1e-12) - VEIN_BUMP_NONE) / (VEIN_BUMP_FULL - VEIN_BUMP_NONE), 0.0, 1.0);
    return relief * r * y * y * fade;
}

// the field at uv for a leaf of world scale `scale` at level of detail `detail` (> 0; vein_vertex)
// with style (relief, major veins' width): vein_strength, and the height the larger of the nearest
// vein's and the nearest major vein's profiles, both times `detail`. Uses derivatives: call it in
// uniform control flow (its inputs are flat: per triangle).
VeinSample vein_sample(vec2 uv, int layer, float scale, float detail, vec2 style, bool front) {
    VeinSample s;
    vec4 f = textureLod(leaf_vein_field, vec3(leaf_texture_st(uv), float(layer)), 0.0);
    vec2 fw = fwidth(f.ra);
    float near = vein_order_weight(f.g) * vein_coverage(f.r, f.b, fw.x);
    float major = vein_order_weight(2.0) * vein_coverage(f.a, style.y, fw.y);
    s.coverage = max(near, major) * detail;
    s.height = max(vein_height(f.r, f.b, style.x, fw.x), vein_height(f.a, style.y, style.x, fw.y))
               * scale * detail * (front ? 1.0 : RELIEF_BACK);
    return s;
}

// the skin (chlorophyll gradient, then margin tint) of the material colour at (u, v) (skin_albedo)
vec3 skin_albedo(vec3 base, vec2 uv) {
    float t = CHLOROPHYLL_V * uv.y + (1.0 - CHLOROPHYLL_V) * abs(uv.x);
    vec3 a = base * (1.0 + CHLOROPHYLL_GAIN * (0.5 - t));
    float m = MARGIN_STRENGTH * smoothstep(MARGIN_START, 1.0, abs(uv.x));
    return a + (a * MARGIN_GAIN + MARGIN_LIFT - a) * m;
}

// the vein colour over the skin `lamina` of an untextured leaf's side (vein_albedo)
vec3 vein_colour(vec3 lamina, VeinSample s, float contrast, bool front) {
    float k = clamp(contrast * s.coverage * (front ? 1.0 : VEIN_BACK_STRENGTH), 0.0, 1.0);
    vec3 vein = min(lamina * VEIN_GAIN + VEIN_LIFT, vec3(1.0));
    return lamina + (vein - lamina) * k;
}

// the unit normal n perturbed by the height h (world units) over the surface at world position p,
// from screen-space derivatives (Mikkelsen 2010, eq. 2-4); n unchanged where the derivatives vanish
vec3 vein_bump(vec3 n, vec3 p, float h) {
    vec3 sx = dFdx(p), sy = dFdy(p);
    float hx = dFdx(h), hy = dFdy(h);
    vec3 r1 = cross(sy, n), r2 = cross(n, sx);
    float det = dot(sx, r1);
    vec3 grad = sign(det) * (hx * r1 + hy * r2);
    vec3 bent = abs(det) * n - grad;
    float len = length(bent);
    return len > 1e-20 ? bent / len : n;
}
#endif
