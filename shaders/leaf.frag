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
#include "generated/frame_block.glsl"
#include "color.glsl"

in vec3 v_world;
in vec3 v_normal;
in vec2 v_uv;
in vec2 v_rib;   // distance from the midrib (or a lobed leaf's skeleton) in half-widths, fade (leaf.vert)
flat in vec4 v_front;
flat in vec3 v_back;
flat in ivec2 v_layers;
#ifndef LEAF_NO_TEXTURE
#include "leaf_texture.glsl"
#endif
#ifndef LEAF_NO_VEINS
flat in vec4 v_vein;        // vein layer (-1: no veins), world scale, detail, contrast (leaf_vein_lod.glsl)
flat in vec2 v_vein_style;  // relief, major veins' width
#include "leaf_veins.glsl"
#endif

#ifdef LEAF_AOV
#ifndef LEAF_STEMS
flat in uint v_leaf;
#endif
#include "generated/aov_outputs.glsl"
#elif !defined(LEAF_DEPTH)
out vec4 frag_color;
#endif

// the unit normal of the side the camera sees (front faces show the upper side)
vec3 visible_normal() {
    return normalize(v_normal) * (gl_FrontFacing ? 1.0 : -1.0);
}

// the specular lobe: 0 the plain leaf's, 1 a veined leaf's sunny upper side (narrow gloss), 2 its
// shadow lower side (broad sheen); constant exponents (a variable one costs llvmpipe exp2(log2()))
float spec_lobe(float c, int lobe) {
    return lobe == 0 ? pow(c, 40.0) : (lobe == 1 ? pow(c, 60.0) : pow(c, 8.0));
}

vec3 light_term(vec3 n, vec3 view_dir, vec4 light, vec3 albedo, float translucency, float sheen, int lobe) {
    vec3 l = normalize(light.xyz);
    float diffuse = max(dot(n, l), 0.0);
    float through = translucency * max(dot(-n, l), 0.0);
    vec3 h = normalize(l + view_dir);
    float spec = sheen * spec_lobe(max(dot(n, h), 0.0), lobe) * step(0.0, dot(n, l));
    return light.w * ((diffuse + through) * albedo + vec3(spec));
}

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
        return texel.a >= 0.5;
    }
#endif
    albedo = front ? v_front.rgb : v_back;
    if (veined) return true;
    // midrib (a lobed leaf: its skeleton): a narrow lighter band, fading toward the apex
    float rib = (1.0 - smoothstep(0.012, 0.035, v_rib.x)) * (1.0 - 0.6 * v_rib.y);
    albedo = mix(albedo, albedo * 1.35 + vec3(0.05), 0.6 * rib);
    return true;
}

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

    vec3 view_dir = frame.eye.w > 0.5 ? normalize(frame.eye.xyz - v_world) : -normalize(frame.eye.xyz);
    vec3 color = frame.ambient.rgb * albedo;
    if (frame.flags.y != 0) {
        color = albedo;
    } else {
        color += light_term(n, view_dir, frame.key, albedo, translucency, sheen, lobe);
        color += light_term(n, view_dir, frame.fill, albedo, translucency, 0.0, lobe);
    }
    frag_color = vec4(frame.flags.x != 0 ? linear_to_srgb(color) : color, 1.0);
}
#endif
