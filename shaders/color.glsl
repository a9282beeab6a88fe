// sRGB transfer function (IEC 61966-2-1), used when the target is 8-bit sRGB.
#ifndef LEAFVIEW_COLOR_GLSL
#define LEAFVIEW_COLOR_GLSL
vec3 linear_to_srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    vec3 lo = 12.92 * c;
    vec3 hi = 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055;
    return mix(lo, hi, step(vec3(0.0031308), c));
}
#endif
