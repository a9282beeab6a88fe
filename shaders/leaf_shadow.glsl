// The sun's visibility from its cascaded shadow maps (leafview/gpu/shadow.py draws them; the numpy
// twin, line for line, is leafview/scene/sun.py, visibility()). Include after
// "generated/frame_block.glsl"; call sun_visibility(world, world normal, view depth), where
// view_depth = -(frame.view * vec4(world, 1)).z.
//
// The cascades are tiles of one depth texture (1 x 1, 2 x 1 or 2 x 2; cascade k at column k % 2,
// row k / 2), sampled with hardware depth compare (LEQUAL) and bilinear filtering. The cascade is
// the first whose split lies beyond view_depth, or a later one where its square does not cover the
// point; over the last SHADOW_FADE of a cascade's range (from the previous split, or 0) it fades
// into the next. The point moves along its normal, turned toward the sun (leaves are two-sided), by
// params.z texels times sin(angle to the sun) (normal-offset shadows), and toward the sun by
// params.y texels, then 3 x 3 bilinear taps one texel apart are averaged (percentage-closer
// filtering), each clamped half a texel inside its tile. Without cascades (params.x = 0) all is lit.
#include "generated/shadow_block.glsl"

layout(binding = SHADOW_UNIT) uniform sampler2DShadow sun_shadow;

const float SHADOW_FADE = 0.1;

// row r (xyz) of cascade k's matrix: row 0 is right / radius, row 2 is -2 sun / depth range
vec3 shadow_row(int k, int r) {
    mat4 m = shadow.matrices[k];
    return vec3(m[0][r], m[1][r], m[2][r]);
}

// visibility in cascade k, -1 where its square does not cover the point
float shadow_cascade(int k, int count, vec3 world, vec3 n, float sin_l) {
    float tile = 1.0 / shadow.params.w;
    float texel = 2.0 / (length(shadow_row(k, 0)) * tile);
    vec3 p = world + n * (shadow.params.z * texel * sin_l);
    vec3 s = (shadow.matrices[k] * vec4(p, 1.0)).xyz * 0.5 + 0.5;
    if (any(lessThan(s.xy, vec2(0.0))) || any(greaterThan(s.xy, vec2(1.0)))) return -1.0;
    float ref = clamp(s.z - shadow.params.y * texel * 0.5 * length(shadow_row(k, 2)), 0.0, 1.0);
    vec2 size = count <= 1 ? vec2(1.0) : (count == 2 ? vec2(0.5, 1.0) : vec2(0.5));
    vec2 origin = vec2(float(k % 2), float(k / 2)) * size;
    vec2 half_texel = 0.5 / vec2(textureSize(sun_shadow, 0));
    vec2 lo = origin + half_texel, hi = origin + size - half_texel;
    float total = 0.0;
    for (int j = -1; j <= 1; ++j)
        for (int i = -1; i <= 1; ++i) {
            vec2 uv = origin + (s.xy + vec2(float(i), float(j)) * shadow.params.w) * size;
            total += textureLod(sun_shadow, vec3(clamp(uv, lo, hi), ref), 0.0);   // no mipmaps: any control flow
        }
    return total / 9.0;
}

float sun_visibility(vec3 world, vec3 world_normal, float view_depth) {
    int count = int(shadow.params.x);
    if (count <= 0) return 1.0;
    vec3 light = -normalize(shadow_row(0, 2));
    float len = length(world_normal);
    vec3 n = len > 0.0 ? world_normal / len : vec3(0.0);
    float cos_l = dot(n, light);
    if (cos_l < 0.0) {
        n = -n;
        cos_l = -cos_l;
    }
    float sin_l = sqrt(max(1.0 - cos_l * cos_l, 0.0));
    int k = 0;
    while (k < count - 1 && view_depth > shadow.splits[k]) ++k;
    float v = -1.0;
    for (; k < count; ++k) {
        v = shadow_cascade(k, count, world, n, sin_l);
        if (v >= 0.0) break;
    }
    if (v < 0.0) return 1.0;
    if (k + 1 < count) {
        float start = k > 0 ? shadow.splits[k - 1] : 0.0;
        float width = SHADOW_FADE * (shadow.splits[k] - start);
        float t = (view_depth - (shadow.splits[k] - width)) / width;
        if (t > 0.0) {
            float next = shadow_cascade(k + 1, count, world, n, sin_l);
            if (next >= 0.0) v = mix(v, next, clamp(t, 0.0, 1.0));
        }
    }
    return v;
}
