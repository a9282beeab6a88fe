#version 450
// Vein tube shading (vein_tube.vert): the blade's front colour on the tube's upper half and its
// back colour on the lower half (blended across the blade plane), lightened toward the pale
// tissue of a vein by TUBE_TINT, lit by the Frame block's key and fill lights and ambient like
// the blade (diffuse and a faint sheen, no transmission: a vein is opaque). Tubes are closed, so
// only front faces are seen.
#include "generated/frame_block.glsl"
#include "color.glsl"

in vec3 v_world;
in vec3 v_normal;
in float v_upper;
flat in vec4 v_front;
flat in vec3 v_back;

out vec4 frag_color;

vec3 lit(vec3 n, vec3 view_dir, vec4 light, vec3 albedo, float sheen) {
    vec3 l = normalize(light.xyz);
    float diffuse = max(dot(n, l), 0.0);
    vec3 h = normalize(l + view_dir);
    float spec = sheen * pow(max(dot(n, h), 0.0), 24.0) * step(0.0, dot(n, l));
    return light.w * (diffuse * albedo + vec3(spec));
}

void main() {
    vec3 n = normalize(v_normal) * (gl_FrontFacing ? 1.0 : -1.0);
    vec3 base = mix(v_back, v_front.rgb, smoothstep(-0.25, 0.25, v_upper));
    vec3 albedo = mix(base, base * 1.35 + vec3(0.05), TUBE_TINT);
    vec3 color;
    if (frame.flags.y != 0) {
        color = albedo;
    } else {
        vec3 view_dir = frame.eye.w > 0.5 ? normalize(frame.eye.xyz - v_world) : -normalize(frame.eye.xyz);
        color = frame.ambient.rgb * albedo;
        color += lit(n, view_dir, frame.key, albedo, 0.08);
        color += lit(n, view_dir, frame.fill, albedo, 0.0);
    }
    frag_color = vec4(frame.flags.x != 0 ? linear_to_srgb(color) : color, 1.0);
}
