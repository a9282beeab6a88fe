#version 450
// Screen-space ambient occlusion, unblurred (leafview/gpu/ssao.py; numpy reference and the
// equations, steps 1-4: leafview/scene/ssao.py). Inputs are the label pass's view-space depth
// (0: background) and world normal of the visible side; output 1 = unoccluded.
#include "ssao_view.glsl"

uniform float radius;          // rho, world units
uniform float bias;            // beta, world units
uniform float strength;
uniform int samples;
uniform vec3 kernel[SSAO_MAX_SAMPLES];
uniform vec2 rotations[16];    // 4 x 4 tile, index 4 * (y mod 4) + (x mod 4)

layout(location = 0) out float ao_raw;

void main() {
    ivec2 pixel = ivec2(gl_FragCoord.xy);
    vec2 size = vec2(textureSize(ssao_depth, 0));
    float d = texelFetch(ssao_depth, pixel, 0).r;
    vec3 m;
    if (d <= 0.0 || !view_normal(pixel, m)) {   // background (or a pixel without a normal): open
        ao_raw = 1.0;
        return;
    }
    vec3 p = view_position(vec2(pixel) + 0.5, d, size);
    // step 3: the sample frame, the kernel turned by the pixel's rotation about the normal
    vec3 r = vec3(rotations[4 * (pixel.y & 3) + (pixel.x & 3)], 0.0);
    vec3 t = r - m * dot(r, m);
    if (dot(t, t) < 1e-6) t = vec3(0.0, 0.0, 1.0) - m * m.z;
    t = normalize(t);
    vec3 b = cross(m, t);
    float rho2 = radius * radius;
    float total = 0.0;
    for (int i = 0; i < samples; ++i) {
        vec3 k = kernel[i];
        vec3 s = p + radius * (k.x * t + k.y * b + k.z * m);
        // step 4: the pixel the sample projects to, and the surface seen there
        vec2 q;
        if (perspective) {
            if (s.z >= 0.0) continue;
            q = (proj_terms.xy * s.xy + proj_terms.zw * s.z) / -s.z;
        } else {
            q = proj_terms.xy * s.xy + proj_terms.zw;
        }
        vec2 f = floor((q * 0.5 + 0.5) * size);
        if (f.x < 0.0 || f.y < 0.0 || f.x >= size.x || f.y >= size.y) continue;
        float ds = texelFetch(ssao_depth, ivec2(f), 0).r;
        if (ds <= 0.0) continue;
        vec3 v = view_position(f + 0.5, ds, size) - p;
        float vv = dot(v, v);
        float rise = min(radius * max(dot(v, m) - bias, 0.0) / (vv + SSAO_EPS * rho2), 1.0);
        total += rise * clamp(1.0 - vv / rho2, 0.0, 1.0);
    }
    ao_raw = clamp(1.0 - strength * total / float(samples), 0.0, 1.0);
}
