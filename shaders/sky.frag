#version 450
// The analytic sky behind a canopy (leafview/gpu/sky.py SkyPass): the view ray of each pixel from
// the inverse of proj · view (perspective or orthographic: the ray between the pixel's points on
// the near and far planes), the sky's radiance along it (sky_model.glsl) plus the sun's disc,
// tone mapped like the leaves (tonemap.glsl). Numpy twin: leafview.scene.sky.
#include "generated/frame_block.glsl"
#include "sky_model.glsl"
#include "tonemap.glsl"

uniform mat4 inv_view_proj;
in vec2 v_ndc;
out vec4 frag_color;

void main() {
    vec4 a = inv_view_proj * vec4(v_ndc, -1.0, 1.0);
    vec4 b = inv_view_proj * vec4(v_ndc, 1.0, 1.0);
    vec3 d = normalize(b.xyz / b.w - a.xyz / a.w);
    frag_color = vec4(canopy_output(sky_radiance(d) + sun_disc(d)), 1.0);
}
