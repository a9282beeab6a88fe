#version 450
// Leaf vertex shader: turns each (u, v) of a fixed grid into the leaf's position and normal
// from the leaf's record (leafview/gpu/layout.py):
// * default: one LeafData in the Leaf uniform block (single leaves);
// * LEAF_INSTANCED: the LeafVertex members of row gl_InstanceID as per-instance vertex attributes,
//   read in place from the buffer of LeafData rows (InstancedLeaves);
// * LEAF_INDIRECT: the same attributes from the compact LeafVertex records of the visible leaves
//   that scene_compact.comp writes (scenes; each draw command's baseInstance selects its level's
//   records, the record's leaf_vertex_row names the row).
// In both, the members only ripples, bends and extended silhouettes need are texels of the row in
// the leaf_rows texture (LEAF_ROW_TEXTURE), fetched in those branches only. llvmpipe runs
// storage-buffer reads as per-vertex gathers; an instanced attribute costs a fraction of that and
// a texel fetch about half (docs/benchmarks.md).
// A lobed leaf (leafview.core.lobes) takes the swept surface of leaf_eval.glsl's lobe_eval instead
// of L_Ω, its v_uv the flat position in its texture window (u in [-1, 1], v in [0, 1]), a vein band
// along its skeleton and no vein field.
// The same program is used with transform feedback (v_object, v_object_normal) by
// leafview.gpu.evaluate, so what is tested is what is drawn.
#include "generated/leaf_block.glsl"
#include "generated/frame_block.glsl"
#if defined(LEAF_INSTANCED) || defined(LEAF_INDIRECT)
#include "generated/leaf_vertex.glsl"
#include "generated/leaf_attributes.glsl"
LeafVertex leaf_vertex;   // this vertex's leaf, made of the attributes first thing in main()
#define LEAF leaf_vertex
#if defined(LEAF_INDIRECT)
#define LEAF_ROW_INDEX uint(leaf_vertex_row(leaf_vertex))
#else
#define LEAF_ROW_INDEX uint(gl_InstanceID)
#endif
#define LEAF_ROW_TEXTURE
#else
#define LEAF leaf
#define LEAF_ROW leaf
#endif
#include "leaf_eval.glsl"
#ifndef LEAF_NO_VEINS
#include "leaf_vein_lod.glsl"
#endif

// jitter tables, one row per seed (moderngl has no 1D textures; a 2D texture of 1D rows)
layout(binding = JITTER_UNIT) uniform sampler2D jitter_table;

in vec2 in_uv;
const float LOBE_RIB_HALFWIDTH = 0.3;   // leaf lengths: a lobed leaf's vein band is as wide as on such a blade

out vec3 v_object;          // leaf-space position (captured for tests and export)
out vec3 v_object_normal;   // leaf-space upper-side normal
out vec3 v_world;
out vec3 v_normal;
out vec2 v_uv;
out vec2 v_rib;             // the lighter vein band of leaf.frag: (distance from it in half-widths, fade)
#define LEAF_COLOURS_OUT
#include "leaf_colours.glsl"
flat out ivec2 v_layers;    // front, back image texture layer, -1 untextured (leaf.frag)
#ifndef LEAF_NO_VEINS
flat out vec4 v_vein;       // vein layer (-1: no veins), world scale, detail, contrast (leaf_vein_lod.glsl)
flat out vec2 v_vein_style; // relief, major veins' width
#endif
#ifdef LEAF_AOV
// label pass (leafview/gpu/aov.py): the scene's index of the leaf, for the instance output
flat out uint v_leaf;
#if defined(LEAF_INDIRECT)
#include "generated/aov_vertex.glsl"
#define LEAF_INDEX (leaf_offset + LEAF_ROW_INDEX)   // the row counts within the batch
#elif defined(LEAF_INSTANCED)
#define LEAF_INDEX uint(gl_InstanceID)
#else
#define LEAF_INDEX 0u
#endif
#endif
#ifdef LEAF_WIND
// wind (leaf_wind.glsl, the Wind block of leafview/gpu/wind.py): the leaf moved in leaf space, so
// v_object and v_object_normal (transform feedback) include it; each leaf's phase comes from its
// index in the scene
#include "leaf_wind.glsl"
#if defined(LEAF_INDIRECT)
#ifndef LEAF_AOV
#include "generated/aov_vertex.glsl"
#endif
#define WIND_LEAF_INDEX (leaf_offset + LEAF_ROW_INDEX)
#elif defined(LEAF_INSTANCED)
#define WIND_LEAF_INDEX uint(gl_InstanceID)
#else
#define WIND_LEAF_INDEX 0u
#endif
#endif

void main() {
#if defined(LEAF_INSTANCED) || defined(LEAF_INDIRECT)
    leaf_vertex = leaf_vertex_attributes();
#endif
    // one half only (shape.half = ±1, e.g. each side of an asymmetric leaf): the grid's u in
    // [-1, 1] spreads over [0, 1] or [-1, 0], u' = (u + half) / 2 (leafview.deform.surface.drawn_uv)
    vec2 uv = in_uv;
    vec3 L, n;
    // a lobed leaf (its sweep-table layer in the branch code): the swept surface on its own grid
    // (leafview.core.defaults.lobed_grid), shaded at its flat position (x, y in leaf lengths), no veins
#ifndef LEAF_NO_LOBES
    int lobe_layer = leaf_branch_lobe(LEAF);
    if (lobe_layer >= 0) {
        LobeEval le = lobe_eval(lobe_layer, uv);
        L = le.L;
        n = le.N;
        uv = le.uv;   // the flat position in the texture window (leafview/deform/sweep.py, texture_uv)
        // the skeleton is the lobed leaf's primary veins (Mündermann et al. 2003, sec. 3.2): the band
        // follows it, its width as on a leaf of half-width LOBE_RIB_HALFWIDTH
        v_rib = vec2(le.rib / LOBE_RIB_HALFWIDTH, 0.0);
    } else
#else
    const int lobe_layer = -1;
#endif
    {
#ifndef LEAF_NO_HALF
        float half_side = leaf_half(LEAF);
        if (half_side != 0.0) uv.x = 0.5 * (uv.x + half_side);  // keeps the winding (front faces)
#endif
        LeafEval e = leaf_eval(jitter_table, uv);
        L = e.L;
        n = leaf_normal(e, uv.y);
        v_rib = vec2(abs(uv.x), uv.y);   // the midrib, fading toward the apex
    }
#ifdef LEAF_WIND
    wind_displace(L, n, LEAF.model, WIND_LEAF_INDEX);
#endif
    v_object = L;
    v_object_normal = n;
    // mat4x3: the model matrix's last row holds the texture layers (leafview/gpu/layout.py, LEAF_SLOTS)
    vec4 world = vec4(mat4x3(LEAF.model) * vec4(L, 1.0), 1.0);
    v_world = world.xyz;
    v_normal = normalize(mat3(LEAF.model) * n);  // rotation and uniform scale only
    v_uv = uv;
    v_colours = pack_colours(LEAF.front, LEAF.back.rgb);
    v_layers = ivec2(leaf_front_layer(LEAF), leaf_back_layer(LEAF));
#ifdef LEAF_AOV
    v_leaf = LEAF_INDEX;
#endif
    gl_Position = frame.proj * (frame.view * world);   // two matrix-vector products, no matrix product a vertex
#ifndef LEAF_NO_VEINS
    vein_vertex(lobe_layer >= 0 ? -1 : leaf_vein_layer(LEAF), length(LEAF.model[0].xyz), gl_Position.w, v_vein, v_vein_style);
#endif
}
