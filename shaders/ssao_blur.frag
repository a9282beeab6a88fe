#version 450
// Surface-aware 4 x 4 blur of the raw ambient occlusion (leafview/gpu/ssao.py; numpy reference,
// step 5: leafview/scene/ssao.py): the box x-2..x+1, y-2..y+1 (one tile of the kernel rotations)
// over drawn pixels within `plane_tolerance` of the pixel's tangent plane; background 1.
#include "ssao_view.glsl"
layout(binding = SSAO_UNIT) uniform sampler2D ambient_occlusion;   // the raw AO (ssao.frag)

uniform float plane_tolerance;   // world units

layout(location = 0) out float ao;

void main() {
    ivec2 pixel = ivec2(gl_FragCoord.xy);
    ivec2 isize = textureSize(ssao_depth, 0);
    vec2 size = vec2(isize);
    float d = texelFetch(ssao_depth, pixel, 0).r;
    vec3 m;
    if (d <= 0.0 || !view_normal(pixel, m)) {
        ao = 1.0;
        return;
    }
    vec3 p = view_position(vec2(pixel) + 0.5, d, size);
    float total = 0.0;
    float count = 0.0;
    for (int dy = -2; dy < 2; ++dy) {
        for (int dx = -2; dx < 2; ++dx) {
            ivec2 q = pixel + ivec2(dx, dy);
            if (q.x < 0 || q.y < 0 || q.x >= isize.x || q.y >= isize.y) continue;
            float dq = texelFetch(ssao_depth, q, 0).r;
            if (dq <= 0.0 || abs(dot(view_position(vec2(q) + 0.5, dq, size) - p, m)) > plane_tolerance) continue;
            total += texelFetch(ambient_occlusion, q, 0).r;
            count += 1.0;
        }
    }
    ao = total / max(count, 1.0);
}
