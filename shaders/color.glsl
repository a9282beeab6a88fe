// sRGB transfer function (IEC 61966-2-1), used when the target is 8-bit sRGB; numpy twin:
// leafview.core.colour.linear_to_srgb, readback test: tests/test_leaf_srgb.py (within 1e-6, the
// same 8-bit code as pow() but on about 1e-5 of the values, by one).
// c^(5/12) = m^(5/12) · 2^(5e/12) with c = m · 2^e, m in [0.5, 1) (frexp): the mantissa's power is
// a degree-7 polynomial (a Chebyshev fit on [0.5, 1], monomial coefficients, Horner's scheme;
// error 6e-7 in float32), the exponent's an exp2 of an exact multiple of 5/12. On llvmpipe
// pow(c, 1/2.4) is a log2 and an exp2 approximation each, three times a fragment: this costs
// about half as much.
#ifndef LEAFVIEW_COLOR_GLSL
#define LEAFVIEW_COLOR_GLSL
vec3 linear_to_srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    ivec3 e;
    vec3 m = frexp(max(c, vec3(1e-30)), e);   // the linear segment below the knee takes c = 0
    vec3 p = ((((((0.14245283603668213 * m - 0.8781032562255859) * m + 2.378694772720337) * m
                 - 3.730001211166382) * m + 3.7761647701263428) * m - 2.6767258644104004) * m
              + 1.739610195159912) * m + 0.24790766835212708;
    vec3 hi = 1.055 * (p * exp2(vec3(e) * (5.0 / 12.0))) - 0.055;
    return mix(12.92 * c, hi, step(vec3(0.0031308), c));
}
#endif
