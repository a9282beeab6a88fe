#version 450
// Two-sided leaf shading: front (upper, +z side) and back colours, a key and a fill light,
// diffuse transmission ("translucency") for light arriving from the other side, a faint
// specular sheen on the upper side and a lighter midrib.
//
// A textured leaf (v_layers >= 0; leaf_texture.glsl) takes its albedo from its image instead: the
// texel decoded from sRGB, nothing else (no midrib), and its texels with alpha < 0.5 (the mask's
// teeth and holes) are discarded, in the label pass too, so labels match the picture.
// LEAF_NO_TEXTURE (a draw without textured leaves) compiles all of it out.
//
// A veined leaf (v_vein.x >= 0, leaf_veins.glsl) is shaded from its vein field instead of the
// midrib band: skin and vein colour (untextured leaves only: a photograph has its own), relief
// (a perturbed normal) and reduced transmission along veins, and its sides differ in gloss (Hong
// 2005, ch. 8: a narrow gloss on the sunny upper side, a broad dim sheen on the shadow lower side).
// LEAF_NO_VEINS (a draw without veined leaves) compiles all of it out, LEAF_VEIN_SKIN (leaves too
// far for their veins: a scene's coarser levels) the vein field only.
//
// LEAF_AOV: the label pass of leafview/gpu/aov.py instead of a colour: one output per
// AOV_OUTPUTS entry of leafview/gpu/layout.py (leaf index + 1, view-space depth, world normal of
// the visible side, (u, v)); LEAF_STEMS marks the stem program (leaf_baked.vert, no leaf index):
// instance 0 and (u, v) 0, depth and normal written. Labels take the geometric normal (no relief).
//
// LEAF_CANOPY: the canopy look of leafview/gpu/canopy.py instead of the key + fill lights (numpy
// twin: leafview/scene/leaf_light.py, which states the equations). The Light block's sun (with
// LEAF_SHADOWS its visibility from the shadow maps, leaf_shadow.glsl) lights the side facing it and
// shines through to the other side, tinted by the leaf (a back-lit leaf glows through its texture
// and veins); the sky's spherical-harmonic irradiance (sky_model.glsl) is the ambient, from both
// sides likewise (with LEAF_SSAO times the screen-space occlusion); the cuticle's gloss is the
// specular lobe above, scaled by the Light block's gloss; tonemap.glsl encodes the result. With
// alpha to coverage (light.flags.z, set on multisampled targets only) a textured leaf's alpha
// becomes a one-pixel ramp around 0.5 (fwidth) written as the sample mask instead of a discard.
#include "generated/frame_block.glsl"
#include "color.glsl"

in vec3 v_world;
in vec3 v_normal;
in vec2 v_uv;
in vec2 v_rib;   // distance from the midrib (or a lobed leaf's skeleton) in half-widths, fade (leaf.vert)
// v_front, v_back: one flat slot of halves (leaf_colours.glsl)
#include "leaf_colours.glsl"
flat in ivec2 v_layers;
#ifndef LEAF_NO_TEXTURE
#include "leaf_texture.glsl"
#endif
#ifndef LEAF_NO_VEINS
flat in vec4 v_vein;        // vein layer (-1: no veins), world scale, detail, contrast (leaf_vein_lod.glsl)
flat in vec2 v_vein_style;  // relief, major veins' width
#include "leaf_veins.glsl"
#endif
#if defined(LEAF_CANOPY) && !defined(LEAF_AOV) && !defined(LEAF_DEPTH)
#include "sky_model.glsl"
#include "tonemap.glsl"
#ifdef LEAF_SHADOWS
#include "leaf_shadow.glsl"
#endif
#ifdef LEAF_SSAO
layout(binding = SSAO_UNIT) uniform sampler2D ambient_occlusion;
#endif
float leaf_alpha = 1.0;   // the visible side's texture alpha (1: untextured), set by leaf_albedo
#endif

#ifdef LEAF_AOV
#ifndef LEAF_STEMS
flat in uint v_leaf;
#endif
#include "generated/aov_outputs.glsl"
#elif !defined(LEAF_DEPTH)
out vec4 frag_color;
#endif

// The Frame block's output flags and eye, fixed when the program is compiled where the caller
// knows them (render_many's thumbnails: LEAF_FRAME_SRGB, LEAF_FRAME_FLAT 0 or 1, LEAF_EYE_POINT 1 a
// perspective eye, 0 an orthographic one), else read from the block. llvmpipe evaluates both arms
// of a select on a uniform for every fragment: fixed, the unused arm is compiled out (3-6 % of a
// thumbnail's rasterisation there; the same values, so the same pixels).
#ifdef LEAF_FRAME_SRGB
#define FRAME_SRGB (LEAF_FRAME_SRGB != 0)
#else
#define FRAME_SRGB (frame.flags.x != 0)
#endif
#ifdef LEAF_FRAME_FLAT
#define FRAME_FLAT (LEAF_FRAME_FLAT != 0)
#else
#define FRAME_FLAT (frame.flags.y != 0)
#endif

// the unit normal of the side the camera sees (front faces show the upper side)
vec3 visible_normal() {
    return normalize(v_normal) * (gl_FrontFacing ? 1.0 : -1.0);
}

// the specular lobe of c = max(n·h, 0) from its square c2 = c² (no square root is needed for it):
// 0 the plain leaf's (c^40), 1 a veined leaf's sunny upper side (narrow gloss, c^60), 2 its shadow
// lower side (broad sheen, c^8). Constant exponents by repeated squaring: pow() is exp2(log2()) on
// llvmpipe, and this lobe was a fifth of a multisampled thumbnail's time there
// (docs/benchmarks.md); the products equal pow() to float rounding.
float spec_lobe_sq(float c2, int lobe) {
    float c4 = c2 * c2, c8 = c4 * c4, c16 = c8 * c8, c32 = c16 * c16;
    return lobe == 0 ? c32 * c8 : (lobe == 1 ? (c32 * c16) * (c8 * c4) : c8);
}

// The direction towards a light of the Frame block, a unit vector as fill_frame writes it
// (leafview/gpu/frame.py): normalising it here would cost a square root and a division for every
// fragment on llvmpipe, which does not hoist work on uniforms out of the fragment loop.
#define LIGHT_DIR(light) ((light).xyz)

// The key and the fill light: each light's diffuse reflection and transmission, and the key's
// specular lobe (the sheen; the fill light has none). N, the visible side's normal, and V, the
// vector towards the eye, need not be unit: the lengths are divided out here with two square
// roots and one division a fragment, where normalize(N), normalize(V) and the half vector's
// normalize(l + v) took three of each; on llvmpipe a square root and a division are the slowest
// instructions of this shader (docs/benchmarks.md). With n = N/|N|, v = V/|V| and unit l:
// |l + v|² = 2 (1 + l·v), so n·h = (|V| n·l + n·V) / sqrt(den) with den = 2 |V| (|V| + l·V), and
// the lobe takes (n·h)² = (max(n·h, 0))² = num²/den: the same Blinn-Phong term, no second root.
vec3 key_fill(vec3 N, vec3 V, vec3 albedo, float translucency, float sheen, int lobe) {
    vec3 lk = LIGHT_DIR(frame.key), lf = LIGHT_DIR(frame.fill);
    float sn = sqrt(dot(N, N)), sv = sqrt(dot(V, V));
    float den = max(2.0 * sv * (sv + dot(lk, V)), 1e-30);   // |V|² |l + v|²
    float inv = 1.0 / (sn * sv * den);
    float inv_n = inv * (sv * den);                           // 1 / |N|
    float ndk = dot(N, lk) * inv_n, ndf = dot(N, lf) * inv_n;
    float num = max(ndk * sv + dot(N, V) * inv_n, 0.0);      // sqrt(den) · max(n·h, 0)
    float spec = sheen * spec_lobe_sq(num * num * (inv * (sn * sv)), lobe) * step(0.0, ndk);
    vec3 key = frame.key.w * ((max(ndk, 0.0) + translucency * max(-ndk, 0.0)) * albedo + vec3(spec));
    return key + frame.fill.w * ((max(ndf, 0.0) + translucency * max(-ndf, 0.0)) * albedo);
}

const float RIB_SCALE = 1.0 / (0.035 - 0.012);   // the midrib band's smoothstep edges

// The albedo of the visible side; false where a textured leaf's image is transparent (alpha < 0.5).
// `textured`: the albedo is an image's; `veined`: no midrib band (the vein field draws the veins).
bool leaf_albedo(out vec3 albedo, out bool textured, bool veined) {
    bool front = gl_FrontFacing;
    textured = false;
#ifndef LEAF_NO_TEXTURE
    vec2 st = leaf_texture_st(v_uv);
    vec2 st_dx = dFdx(st), st_dy = dFdy(st);   // before the branch: the mip level needs the whole quad
    int layer = front ? v_layers.x : v_layers.y;
    if (layer >= 0) {   // flat per leaf: untextured leaves never sample
        vec4 texel = textureGrad(leaf_textures, vec3(st, float(layer)), st_dx, st_dy);
        albedo = srgb_to_linear(texel.rgb);
        textured = true;
#if defined(LEAF_CANOPY) && !defined(LEAF_AOV) && !defined(LEAF_DEPTH)
        leaf_alpha = texel.a;
#endif
        return texel.a >= 0.5;
    }
#endif
    albedo = front ? v_front.rgb : v_back;
    if (veined) return true;
    // midrib (a lobed leaf: its skeleton): a narrow lighter band, fading toward the apex
    // smoothstep(0.012, 0.035, x) written out with a multiplication: the built-in divides by
    // (0.035 - 0.012) for every fragment, and a division is among llvmpipe's slowest instructions
    float t = clamp((v_rib.x - 0.012) * RIB_SCALE, 0.0, 1.0);
    float rib = (1.0 - t * t * (3.0 - 2.0 * t)) * (1.0 - 0.6 * v_rib.y);
    albedo = mix(albedo, albedo * 1.35 + vec3(0.05), 0.6 * rib);
    return true;
}

#if defined(LEAF_CANOPY) && !defined(LEAF_AOV) && !defined(LEAF_DEPTH)
// The tint of light that went through the leaf: albedo² scaled to the albedo's luminance (Rec. 709):
// as bright as the light the leaf reflects (a leaf transmits about as much as it reflects in the
// visible), deeper in colour (it crossed the pigments twice over); at most 1. canopy_color computes
// it with its one division (backlight_tint(albedo) = min(sq · dot(albedo, lum) / backlight_norm, 1)).
const vec3 BACKLIGHT_LUM = vec3(0.2126, 0.7152, 0.0722);
float backlight_norm(vec3 sq) {
    return max(dot(sq, BACKLIGHT_LUM), 1e-8);
}

// The sample mask of a fragment whose coverage is `coverage` (0..1): round(coverage × samples + dither)
// samples, starting at a per-pixel rotation so that neighbouring pixels cover different samples
// (alpha to coverage written by the shader: moderngl has no SAMPLE_ALPHA_TO_COVERAGE switch, and
// a mask works the same on every OpenGL 4.5 driver).
int coverage_mask(float coverage) {
    int n = clamp(gl_NumSamples, 1, 31);
    uint h = uint(gl_FragCoord.x) * 73856093u ^ uint(gl_FragCoord.y) * 19349663u;
    h = (h ^ (h >> 13u)) * 0x5bd1e995u;
    h ^= h >> 15u;
    float dither = float(h & 255u) / 256.0;   // stochastic rounding: unbiased over pixels
    int k = clamp(int(floor(coverage * float(n) + dither)), 0, n);
    int bits = (1 << k) - 1;
    int r = int((h >> 8u) % uint(n));
    int rotated = r == 0 ? bits : (bits << r) | (bits >> (n - r));
    return rotated & ((1 << n) - 1);
}

// The canopy look of the visible side (leaf_light.py: canopy_radiance): linear radiance before the
// tone map. N the visible side's shading normal and V the vector towards the eye, neither of them
// unit: as key_fill, the lengths are divided out with two square roots, and with the same one
// division as backlight_tint's, where normalize(N), normalize(V), the half vector's normalize and the
// tint's quotient took four of each on llvmpipe. n = N/|N|, v = V/|V|, unit l: |V|² |l + v|² =
// den = 2 |V| (|V| + l·V), and (max(n·h, 0))² = num²/den with num = max(|V| n·l + n·V, 0). `geo`:
// the visible side's unit geometric normal (the shadow maps' offset), or, with geo_is_n, n itself.
vec3 canopy_color(vec3 N, vec3 V, vec3 geo, bool geo_is_n, vec3 albedo, float translucency, float sheen,
                  int lobe) {
    vec3 l = light.sun.xyz;
    vec3 sq = albedo * albedo;
    float norm = backlight_norm(sq);
    float sn = sqrt(dot(N, N)), sv = sqrt(dot(V, V));
    float den = max(2.0 * sv * (sv + dot(l, V)), 1e-20);
    float inv = 1.0 / (sn * sv * den * norm);
    vec3 n = N * (inv * (sv * den * norm));                            // N / |N|
    float ndl = dot(n, l);
    float num = max(ndl * sv + dot(n, V), 0.0);                        // sqrt(den) · max(n·h, 0)
    float spec = light.tone.w * sheen * spec_lobe_sq(num * num * (inv * (sn * sv * norm)), lobe) * step(0.0, ndl);
    vec3 tint = min(sq * (dot(albedo, BACKLIGHT_LUM) * (inv * (sn * sv * den))), vec3(1.0));
    float through = light.tone.z * translucency;
    vec3 sun = max(ndl, 0.0) * albedo + through * max(-ndl, 0.0) * tint + vec3(spec);
    float visible = 1.0;
#ifdef LEAF_SHADOWS
    // sun_visibility turns the normal to the side that faces the sun (the offset moves toward it)
    float depth = -(frame.view * vec4(v_world, 1.0)).z;
    visible = sun_visibility(v_world, geo_is_n ? n : geo, depth);
#endif
    float ao = 1.0;
#ifdef LEAF_SSAO
    ao = texelFetch(ambient_occlusion, ivec2(gl_FragCoord.xy), 0).r;
#endif
    vec3 sky_front, sky_back;
    sh_irradiance_both(n, sky_front, sky_back);
    vec3 ambient = sky_front * albedo + through * sky_back * tint;
    return light.sun.w * light.sun_colour.rgb * visible * sun + ao * ambient;
}
#endif

#ifdef LEAF_AOV
void main() {
#ifdef LEAF_STEMS
    aov_instance = 0u;
    aov_uv = vec2(0.0);
#else
#ifndef LEAF_NO_TEXTURE
    vec3 albedo;
    bool textured;
    if (!leaf_albedo(albedo, textured, true)) discard;
#endif
    aov_instance = v_leaf + 1u;
    aov_uv = v_uv;
#endif
    aov_depth = -(frame.view * vec4(v_world, 1.0)).z;   // along the optical axis, perspective or not
    aov_normal = vec4(visible_normal(), 0.0);
}
#elif defined(LEAF_DEPTH)
// depth only (the sun's shadow maps, leafview/gpu/shadow.py): a textured leaf's transparent texels
// cast no shadow
void main() {
#if !defined(LEAF_NO_TEXTURE) && !defined(LEAF_STEMS)
    vec3 albedo;
    bool textured;
    if (!leaf_albedo(albedo, textured, true)) discard;
#endif
}
#else
void main() {
    bool front = gl_FrontFacing;
    vec3 n = visible_normal();
    vec3 albedo;
    bool textured;
#ifdef LEAF_NO_VEINS
    bool veined = false;
#else
    int vein_layer = int(v_vein.x);
    bool veined = vein_layer >= 0;
#endif
#ifdef LEAF_NO_TEXTURE
    leaf_albedo(albedo, textured, veined);
#elif defined(LEAF_CANOPY)
    bool opaque = leaf_albedo(albedo, textured, veined);
    // a one-pixel ramp of the alpha around 0.5 (fwidth before any discard: the whole quad runs it)
    float coverage = clamp((leaf_alpha - 0.5) / max(fwidth(leaf_alpha), 1e-4) + 0.5, 0.0, 1.0);
    // every invocation writes the mask (an unwritten one is undefined once the shader assigns it)
    int mask = -1;
    if (light.flags.z != 0 && textured) {
        mask = coverage_mask(coverage);
        if (mask == 0) discard;
    } else if (!opaque) {
        discard;
    }
    gl_SampleMask[0] = mask;
#else
    if (!leaf_albedo(albedo, textured, veined)) discard;
#endif
    float translucency = v_front.a;
    float sheen = front ? 0.12 : 0.03;
    int lobe = 0;
#ifndef LEAF_NO_VEINS
    if (veined) {
        if (!textured) albedo = skin_albedo(albedo, v_uv);
#ifndef LEAF_VEIN_SKIN
        if (v_vein.z > 0.0) {   // flat per triangle: uniform over each quad, derivatives are defined
            VeinSample vs = vein_sample(v_uv, vein_layer, v_vein.y, v_vein.z, v_vein_style, front);
            if (!textured) albedo = vein_colour(albedo, vs, v_vein.w, front);
            translucency *= 1.0 - VEIN_OPACITY * vs.coverage;
            n = vein_bump(n, v_world, vs.height);
        }
#endif
        sheen = front ? 0.14 : 0.05;
        lobe = front ? 1 : 2;
    }
#endif

    // towards the eye, not unit (llvmpipe evaluates both arms of a ?:)
#ifndef LEAF_EYE_POINT
    vec3 view = frame.eye.w > 0.5 ? frame.eye.xyz - v_world : -frame.eye.xyz;
#elif LEAF_EYE_POINT
    vec3 view = frame.eye.xyz - v_world;
#else
    vec3 view = -frame.eye.xyz;
#endif
#ifdef LEAF_CANOPY
#ifdef LEAF_STEMS
    sheen = 0.02;   // bark: a faint broad sheen
    lobe = 2;
#endif
#if defined(LEAF_NO_VEINS) || defined(LEAF_VEIN_SKIN)
    // no relief: the interpolated normal as it is (canopy_color divides by its length), also the
    // geometric one
    vec3 shading = v_normal * (front ? 1.0 : -1.0);
    vec3 color = canopy_color(shading, view, shading, true, albedo, translucency, sheen, lobe);
#else
    vec3 color = canopy_color(n, view, visible_normal(), false, albedo, translucency, sheen, lobe);
#endif
    frag_color = vec4(canopy_output(color), 1.0);
#else
    vec3 color = frame.ambient.rgb * albedo;
    if (FRAME_FLAT) {
        color = albedo;
    } else {
#ifdef LEAF_NO_VEINS
        // the interpolated normal as it is: key_fill divides by its length (no normalize)
        color += key_fill(v_normal * (front ? 1.0 : -1.0), view, albedo, translucency, sheen, lobe);
#else
        color += key_fill(n, view, albedo, translucency, sheen, lobe);
#endif
    }
    frag_color = vec4(FRAME_SRGB ? linear_to_srgb(color) : color, 1.0);
#endif
}
#endif
