// The camera response shared by every canopy shader (numpy twin: leafview.scene.sky.tone_map):
// canopy_output(linear) = the linear radiance times 2^exposure (light.tone.x), then the ACES filmic
// fit of Narkowicz (2015) (light.tone.y = 1) or a clamp (0), then sRGB encoded when the frame asks
// for it (frame.flags.x; color.glsl's linear_to_srgb). Include after "generated/frame_block.glsl"; the Light block comes
// from here (guarded, shared with sky_model.glsl).
#ifndef LEAFVIEW_TONEMAP_GLSL
#define LEAFVIEW_TONEMAP_GLSL
#ifndef LEAFVIEW_LIGHT_BLOCK
#define LEAFVIEW_LIGHT_BLOCK
#include "generated/light_block.glsl"
#endif
#include "color.glsl"

// The fit's three quotients with one division (llvmpipe's divisions are among its slowest
// instructions): 1/d_i = (product of the other two) / (d_0 d_1 d_2). x is capped at 64 first, which
// keeps the product of the denominators below 1e12; the fit is clamped to 1 from x = 7.3 on, so the
// cap changes nothing.
vec3 aces_narkowicz(vec3 x) {
    x = min(x, vec3(64.0));
    vec3 d = x * (2.43 * x + 0.59) + 0.14;
    vec3 others = vec3(d.y * d.z, d.x * d.z, d.x * d.y);
    return clamp(x * (2.51 * x + 0.03) * others * (1.0 / (d.x * others.x)), 0.0, 1.0);
}

vec3 canopy_output(vec3 linear) {
    vec3 x = max(linear, vec3(0.0)) * light.tone.x;
    x = light.tone.y > 0.5 ? aces_narkowicz(x) : clamp(x, 0.0, 1.0);
    return frame.flags.x != 0 ? linear_to_srgb(x) : x;
}
#endif
