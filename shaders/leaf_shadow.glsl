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
// params.y texels, then the mean of 3 x 3 bilinear depth-compare taps one texel apart is taken
// (percentage-closer filtering): a 4 x 4-texel footprint with separable weights (1 - f, 1, 1, f) / 3
// per axis (f the point's bilinear fraction), read as four textureGather compares (16 texels, the
// same values as nine bilinear taps' 36 fetches). The footprint is kept inside the cascade's tile
// (the point clamped 1.5 texels inside). With SHADOW_FAST (the "fast" shadow filter) the one
// bilinear depth-compare tap at the point replaces the 3 x 3: the hardware's filtering of texels
// c..c+1, a quarter of the texture reads. Without cascades (params.x = 0) all is lit.
#include "generated/shadow_block.glsl"

layout(binding = SHADOW_UNIT) uniform sampler2DShadow sun_shadow;

const float SHADOW_FADE = 0.1;

// row r (xyz) of cascade k's matrix: row 0 is right / radius, row 2 is -2 sun / depth range
vec3 shadow_row(int k, int r) {
    mat4 m = shadow.matrices[k];
    return vec3(m[0][r], m[1][r], m[2][r]);
}

// cascade k's shadow coordinates of the point: xy in the square (0..1 where covered), z its depth
vec3 shadow_coords(int k, vec3 world, vec3 n, float sin_l, out float texel) {
    texel = 2.0 * shadow.params.w / length(shadow_row(k, 0));
    vec3 p = world + n * (shadow.params.z * texel * sin_l);
    return (shadow.matrices[k] * vec4(p, 1.0)).xyz * 0.5 + 0.5;
}

bool shadow_covers(vec3 s) {
    return all(greaterThanEqual(s.xy, vec2(0.0))) && all(lessThanEqual(s.xy, vec2(1.0)));
}

// visibility in cascade k of a point it covers, at shadow coordinates s
float shadow_lookup(int k, vec3 s, float texel) {
    float tile = 1.0 / shadow.params.w;
    float ref = clamp(s.z - shadow.params.y * texel * 0.5 * length(shadow_row(k, 2)), 0.0, 1.0);
    // atlas texel coordinates (texel centres at integers), the 4 x 4 footprint kept inside the tile
    vec2 origin = vec2(float(k % 2), float(k / 2)) * tile;
    vec2 t = clamp(origin + s.xy * tile - 0.5, origin + 1.0, origin + (tile - 2.0));
    vec2 inv = 1.0 / vec2(textureSize(sun_shadow, 0));
#ifdef SHADOW_FAST
    return texture(sun_shadow, vec3((t + 0.5) * inv, ref));   // one bilinear tap: texels floor(t)..+1
#else
    vec2 c = floor(t), f = t - c, g = 1.0 - f;
    // four depth-compare gathers (texels c-1..c and c+1..c+2 per axis; components (0,1) (1,1) (1,0)
    // (0,0)) weighted by the nine bilinear taps' sums: g, 1, 1, f per axis
    vec4 a = textureGather(sun_shadow, c * inv, ref);
    vec4 b = textureGather(sun_shadow, (c + vec2(2.0, 0.0)) * inv, ref);
    vec4 d = textureGather(sun_shadow, (c + vec2(0.0, 2.0)) * inv, ref);
    vec4 e = textureGather(sun_shadow, (c + 2.0) * inv, ref);
    float total = dot(a, vec4(g.x, 1.0, g.y, g.x * g.y)) + dot(b, vec4(1.0, f.x, f.x * g.y, g.y))
                + dot(d, vec4(g.x * f.y, f.y, 1.0, g.x)) + dot(e, vec4(f.y, f.x * f.y, f.x, 1.0));
    return total / 9.0;
#endif
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
    // On llvmpipe the body of an `if` runs for every lane of a vector (masked), a loop's next
    // iteration only while some lane goes on: the cascade is found first without a lookup, and
    // the one lookup (plus the cross-fade's second, for the lanes in a fade band) sits in a loop.
    float texel;
    vec3 s;
    for (; k < count; ++k) {
        s = shadow_coords(k, world, n, sin_l, texel);
        if (shadow_covers(s)) break;
    }
    if (k >= count) return 1.0;   // no cascade covers the point
    float v = 1.0, t = 0.0;
    bool fading = false;
    for (; k < count; ++k) {
        if (fading) {   // the next cascade, in the fade band of the one before
            s = shadow_coords(k, world, n, sin_l, texel);
            if (shadow_covers(s)) v = mix(v, shadow_lookup(k, s, texel), t);
            break;
        }
        v = shadow_lookup(k, s, texel);
        if (k + 1 >= count) break;
        float start = k > 0 ? shadow.splits[k - 1] : 0.0;
        float width = SHADOW_FADE * (shadow.splits[k] - start);
        t = (view_depth - (shadow.splits[k] - width)) / width;
        if (t <= 0.0) break;
        t = min(t, 1.0);
        fading = true;
    }
    return v;
}
