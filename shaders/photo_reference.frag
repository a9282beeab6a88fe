#version 450
// Reference photo: the photo's sRGB colour as stored (the target is 8-bit sRGB, like the overlays),
// with alpha = the chosen opacity, blended over what is behind it.
layout(binding = ATLAS_UNIT) uniform sampler2D atlas;   // the photo, on the overlays' image unit
uniform float opacity;

in vec2 v_st;

out vec4 frag_color;

void main() {
    frag_color = vec4(texture(atlas, v_st).rgb, opacity);
}
