// Shared by ssao.frag and ssao_blur.frag (leafview/gpu/ssao.py): the label pass's depth and normal
// images and step 1 of leafview/scene/ssao.py, the view-space position of a pixel from its depth.
layout(binding = SSAO_DEPTH_UNIT) uniform sampler2D ssao_depth;     // along the optical axis, 0 background
layout(binding = SSAO_NORMAL_UNIT) uniform sampler2D ssao_normal;   // world normal of the visible side

uniform mat3 view_rotation;    // world -> view rotation (the view matrix's upper 3x3)
uniform vec4 proj_terms;       // P00, P11, then P02, P12 (perspective) or P03, P13 (orthographic)
uniform bool perspective;

// the view-space position of the point at depth d seen through the window point `centre`
vec3 view_position(vec2 centre, float d, vec2 size) {
    vec2 q = centre / size * 2.0 - 1.0;
    if (perspective) return vec3((q + proj_terms.zw) * d / proj_terms.xy, -d);
    return vec3((q - proj_terms.zw) / proj_terms.xy, -d);
}

// the unit view-space normal of `pixel`, false where it has none
bool view_normal(ivec2 pixel, out vec3 m) {
    m = view_rotation * texelFetch(ssao_normal, pixel, 0).xyz;
    float len = length(m);
    if (len <= 1e-6) return false;
    m /= len;
    return true;
}
