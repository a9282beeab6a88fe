// The veins of a leaf per triangle (leaf.vert, leaf_baked.vert): its style row (contrast, relief,
// the major veins' width; leafview/gpu/vein_draw.py) and its level of detail, both passed flat to
// leaf.frag, which therefore branches per triangle and reads no style texel per fragment.
//
// Level of detail: how many pixels one leaf length spans at the vertex, from the frame's image
// height (frame.flags.z; 0: unknown, full detail) and the vertex's clip-space w (1 for
// orthographic cameras); the veins show in full while their major veins are at least
// VEIN_LOD_FULL pixels wide and fade out to none at VEIN_LOD_NONE (narrower veins average into
// the lamina's colour): a far leaf of a scene reads no vein field (leaf_veins.glsl).
#ifndef LEAFVIEW_LEAF_VEIN_LOD_GLSL
#define LEAFVIEW_LEAF_VEIN_LOD_GLSL
#include "generated/vein_shading.glsl"

layout(binding = VEIN_STYLE_UNIT) uniform sampler2D leaf_vein_style;

// pixels per leaf length of a leaf of world scale `scale` at a vertex of clip-space w `clip_w`
float vein_pixels_per_length(float scale, float clip_w) {
    if (frame.flags.z <= 0) return 1e30;
    return 0.5 * float(frame.flags.z) * abs(frame.proj[1][1]) * scale / max(abs(clip_w), 1e-12);
}

// (layer, world scale, detail in [0, 1], contrast) and (relief, major veins' width) of a leaf on
// vein layer `layer` (-1: none; detail 0)
void vein_vertex(int layer, float scale, float clip_w, out vec4 vein, out vec2 style) {
    vein = vec4(float(layer), scale, 0.0, 0.0);
    style = vec2(0.0);
    if (layer >= 0) {
        vec3 row = texelFetch(leaf_vein_style, ivec2(layer, 0), 0).xyz;
        float px = vein_pixels_per_length(scale, clip_w) * row.z;
        vein.z = clamp((px - VEIN_LOD_NONE) / (VEIN_LOD_FULL - VEIN_LOD_NONE), 0.0, 1.0);
        vein.w = row.x;
        style = row.yz;
    }
}
#endif
