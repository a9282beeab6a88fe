#version 450
// The ground under a canopy (leafview/gpu/sky.py GroundPass): the plane z = ground_z ray-cast per
// pixel (no edge: as far as the view reaches), its depth written so that leaves drawn later test
// against it (clamped to the far plane). Lambertian, albedo light.ground.rgb, lit by the sun (times
// its visibility from the shadow maps with LEAF_SHADOWS, leaf_shadow.glsl) and the sky's SH
// irradiance, both folded (leafview.scene.sky): L = ρ (E_s c_s max(s_z, 0) V A_sun + E(+z) A).
// A is the contact occlusion of the plants' bases, Π_i (1 − k e^{−2 r_i² / R_i²}) over the contacts
// binned in the pixel's grid cell (numpy: leafview.scene.sky.contact_occlusion, contact_grid); A_sun = A without shadow maps (a blob shadow), 1 with
// them. Far away the ground fades into the sky's radiance below the horizon (the haze of
// sky_model.glsl) between ground_fade.z and ground_fade.w from the scene's centre ground_fade.xy.
#include "generated/frame_block.glsl"
#include "sky_model.glsl"
#include "tonemap.glsl"
#ifdef LEAF_SHADOWS
#include "leaf_shadow.glsl"
#endif

uniform mat4 inv_view_proj;
uniform float ground_z;
uniform vec4 ground_fade;
uniform float contact_strength;
uniform vec4 contacts[GROUND_MAX_CONTACTS];   // xy, unused, radius
// the contacts binned on a GROUND_CONTACT_CELLS² grid (leafview.scene.sky.contact_grid): the
// lower corner and cells per world unit; per cell (j · cells + i) the start and count of its list
uniform vec4 contact_grid;
uniform ivec2 contact_cells[GROUND_CONTACT_CELLS * GROUND_CONTACT_CELLS];
uniform ivec4 contact_items[GROUND_CONTACT_ITEMS / 16];   // contact indices, a byte each
in vec2 v_ndc;
out vec4 frag_color;

float contact_occlusion(vec2 p) {
    vec2 g = (p - contact_grid.xy) * contact_grid.zw;
    if (any(lessThan(g, vec2(0.0))) || any(greaterThanEqual(g, vec2(float(GROUND_CONTACT_CELLS))))) return 1.0;
    ivec2 cell = ivec2(g);
    ivec2 range = contact_cells[cell.y * GROUND_CONTACT_CELLS + cell.x];
    float a = 1.0;
    for (int k = range.x; k < range.x + range.y; ++k) {
        vec4 c = contacts[(contact_items[k >> 4][(k >> 2) & 3] >> ((k & 3) * 8)) & 255];
        vec2 r = p - c.xy;
        float q = dot(r, r) / (c.w * c.w);
        if (q < GROUND_CONTACT_REACH * GROUND_CONTACT_REACH) a *= 1.0 - contact_strength * exp(-2.0 * q);
    }
    return a;
}

void main() {
    vec4 a = inv_view_proj * vec4(v_ndc, -1.0, 1.0);
    vec4 b = inv_view_proj * vec4(v_ndc, 1.0, 1.0);
    vec3 o = a.xyz / a.w;
    vec3 d = b.xyz / b.w - o;
    if (d.z >= 0.0) discard;           // looking up: no ground
    float t = (ground_z - o.z) / d.z;
    if (t < 0.0) discard;              // the ground is behind the near plane (or the eye under it)
    vec3 p = o + t * d;
    vec4 clip = frame.proj * (frame.view * vec4(p, 1.0));
    gl_FragDepth = clamp(0.5 * clip.z / clip.w + 0.5, 0.0, 1.0);

    const vec3 n = vec3(0.0, 0.0, 1.0);
    float ao = contact_occlusion(p.xy);
    float ao_sun = ao, visible = 1.0;
#ifdef LEAF_SHADOWS
    visible = sun_visibility(p, n, -(frame.view * vec4(p, 1.0)).z);
    ao_sun = 1.0;
#endif
    vec3 e = light.sun.w * light.sun_colour.rgb * max(light.sun.z, 0.0) * visible * ao_sun + sh_irradiance(n) * ao;
    vec3 colour = light.ground.rgb * e;
    float fade = smoothstep(ground_fade.z, ground_fade.w, length(p.xy - ground_fade.xy));
    if (fade > 0.0) colour = mix(colour, sky_radiance(normalize(d)), fade);
    frag_color = vec4(canopy_output(colour), 1.0);
}
