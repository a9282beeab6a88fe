// The analytic sky of the Light block and its spherical-harmonic irradiance (numpy twin and
// equations: leafview/scene/sky.py). sky_radiance(dir): Perez et al. (1993) luminance distribution
// with Preetham et al.'s (1999) clear-sky coefficients (sky.py eqs. 1-2) above the horizon, the
// hazy ground (eq. 3) below it; sun_disc(dir) the sun's disc the sky pass adds; sh_irradiance(n):
// the folded irradiance E(n)/π of Ramamoorthi & Hanrahan (2001, eq. 13), what an albedo multiplies.
// The Light block comes from here (guarded: include it through this file or tonemap.glsl only).
#ifndef LEAFVIEW_SKY_MODEL_GLSL
#define LEAFVIEW_SKY_MODEL_GLSL
#ifndef LEAFVIEW_LIGHT_BLOCK
#define LEAFVIEW_LIGHT_BLOCK
#include "generated/light_block.glsl"
#endif

const vec3 SKY_LUMINANCE = vec3(0.2126, 0.7152, 0.0722);
const float SKY_SUN_RADIUS = 0.0093;   // leafview.scene.sky.SUN_RADIUS
const float SKY_SUN_DISC = 60.0;       // leafview.scene.sky.SUN_DISC

// eq. (2) for a direction with d.z >= 0 (d.z below 0 is taken as 0)
vec3 sky_upper(vec3 d) {
    vec4 p = light.sky_perez[0];
    vec4 q = light.sky_perez[1];
    float cos_t = max(d.z, 0.0);
    float cg = clamp(dot(d, light.sun.xyz), -1.0, 1.0);   // cos(gamma), no cos(acos())
    float gamma = acos(cg);
    float glow = p.z * exp(p.w * gamma);
    float g = 0.5 * glow / (1.0 + glow + q.x * cg * cg);
    float h = 1.0 - cos_t;
    vec3 chroma = mix(light.sky_zenith.rgb, light.sky_horizon.rgb, h * h * h);
    vec3 tinted = chroma + g * (dot(chroma, SKY_LUMINANCE) * light.sun_colour.rgb - chroma);
    float f = (1.0 + p.x * exp(p.y / max(cos_t, 1e-4))) * (1.0 + glow + q.x * cg * cg);
    return f * q.y * tinted;
}

// radiance seen along the unit direction d: the sky above the horizon, the hazy ground below
vec3 sky_radiance(vec3 d) {
    if (d.z >= 0.0) return sky_upper(d);
    vec2 xy = d.xy / max(length(d.xy), 1e-6);
    float haze = exp(-light.sky_perez[1].z * abs(d.z));
    return mix(light.ground_radiance.rgb, sky_upper(vec3(xy, 0.0)), haze);
}

// the sun's disc (added by the sky pass only: the ambient leaves the sun out)
vec3 sun_disc(vec3 d) {
    float angle = acos(clamp(dot(d, light.sun.xyz), -1.0, 1.0));
    float t = clamp((angle - 0.8 * SKY_SUN_RADIUS) / (0.4 * SKY_SUN_RADIUS), 0.0, 1.0);
    return (1.0 - t * t * (3.0 - 2.0 * t)) * SKY_SUN_DISC * light.sun.w * light.sun_colour.rgb;
}

// the two halves of sh_irradiance: the even bands' terms (l = 0, 2), the same for n and -n, and
// the odd band's (l = 1), which changes sign with n
void sh_parts(vec3 n, out vec3 even, out vec3 odd) {
    even = light.sky_sh[0].rgb * 0.28209479
         + light.sky_sh[4].rgb * (1.09254843 * n.x * n.y)
         + light.sky_sh[5].rgb * (1.09254843 * n.y * n.z)
         + light.sky_sh[6].rgb * (0.31539157 * (3.0 * n.z * n.z - 1.0))
         + light.sky_sh[7].rgb * (1.09254843 * n.x * n.z)
         + light.sky_sh[8].rgb * (0.54627422 * (n.x * n.x - n.y * n.y));
    odd = light.sky_sh[1].rgb * (0.48860251 * n.y)
        + light.sky_sh[2].rgb * (0.48860251 * n.z)
        + light.sky_sh[3].rgb * (0.48860251 * n.x);
}

// folded irradiance E(n)/π of the unit normal n from the nine convolved coefficients
vec3 sh_irradiance(vec3 n) {
    vec3 even, odd;
    sh_parts(n, even, odd);
    return max(even + odd, vec3(0.0));
}

// sh_irradiance(n) and sh_irradiance(-n) (a two-sided leaf's two faces) from one evaluation
void sh_irradiance_both(vec3 n, out vec3 front, out vec3 back) {
    vec3 even, odd;
    sh_parts(n, even, odd);
    front = max(even + odd, vec3(0.0));
    back = max(even - odd, vec3(0.0));
}
#endif
