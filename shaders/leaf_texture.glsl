// Leaf image textures (leafview/gpu/textures.py): every image file of a draw is one layer of the
// sampler2DArray at TEXTURE_UNIT (8-bit RGBA, mipmapped, clamped to the edge); leaf.vert passes
// each side's layer as v_layers.
//
// The (u, v) -> image convention is the one of leafview/core/texture.py (texture_st): s = (1 - u) / 2,
// t = 1 - v, image row 0 at the top; the rows are uploaded as stored, so row 0 sits at t = 0 (the
// apex, v = 1). The back face sees the leaf from below and reads its layer at the same (u, v).
// numpy twins: leafview.gpu.textures.sample_layer (bilinear, clamp to edge, level 0) and
// srgb_to_linear.
#ifndef LEAFVIEW_LEAF_TEXTURE_GLSL
#define LEAFVIEW_LEAF_TEXTURE_GLSL
layout(binding = TEXTURE_UNIT) uniform sampler2DArray leaf_textures;

vec2 leaf_texture_st(vec2 uv) {
    return vec2(0.5 * (1.0 - uv.x), 1.0 - uv.y);
}

// the sRGB decoding (IEC 61966-2-1): texture files hold sRGB, the material colours are linear
vec3 srgb_to_linear(vec3 c) {
    vec3 lo = c / 12.92;
    vec3 hi = pow((c + 0.055) / 1.055, vec3(2.4));
    return mix(lo, hi, step(vec3(0.04045), c));
}
#endif
