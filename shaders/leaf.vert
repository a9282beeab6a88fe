#version 450
// Leaf vertex shader: turns each (u, v) of a fixed grid into the leaf's position and normal
// from the Leaf uniform block (or, with LEAF_INSTANCED / LEAF_INDIRECT, one row of the Leaves
// storage buffer).
// The same program is used with transform feedback (v_object, v_object_normal) by
// leafview.gpu.evaluate, so what is tested is what is drawn.
#include "generated/leaf_block.glsl"
#include "generated/frame_block.glsl"
#if defined(LEAF_INDIRECT)
// scenes: the culling pass lists visible leaves per level of detail; each draw command's
// baseInstance points at its level's list, read as a per-instance attribute
layout(std430, binding = LEAVES_BINDING) readonly buffer Leaves { LeafData leaves[]; };
in uint in_leaf;
#define LEAF leaves[in_leaf]
#elif defined(LEAF_INSTANCED)
layout(std430, binding = LEAVES_BINDING) readonly buffer Leaves { LeafData leaves[]; };
#define LEAF leaves[gl_InstanceID]
#else
#define LEAF leaf
#endif
#include "leaf_eval.glsl"

// jitter tables, one row per seed (moderngl has no 1D textures; a 2D texture of 1D rows)
layout(binding = JITTER_UNIT) uniform sampler2D jitter_table;

in vec2 in_uv;

out vec3 v_object;          // leaf-space position (captured for tests and export)
out vec3 v_object_normal;   // leaf-space upper-side normal
out vec3 v_world;
out vec3 v_normal;
out vec2 v_uv;
flat out vec4 v_front;      // rgb, translucency
flat out vec3 v_back;
#ifdef LEAF_AOV
// label pass (leafview/gpu/aov.py): the scene's index of the leaf, for the instance output
flat out uint v_leaf;
#if defined(LEAF_INDIRECT)
#include "generated/aov_vertex.glsl"
#define LEAF_INDEX (leaf_offset + in_leaf)   // in_leaf counts within the batch
#elif defined(LEAF_INSTANCED)
#define LEAF_INDEX uint(gl_InstanceID)
#else
#define LEAF_INDEX 0u
#endif
#endif

void main() {
    // one half only (shape.half = ±1, e.g. each side of an asymmetric leaf): the grid's u in
    // [-1, 1] spreads over [0, 1] or [-1, 0], u' = (u + half) / 2 (leafview.deform.surface.drawn_uv)
    vec2 uv = in_uv;
#ifndef LEAF_NO_HALF
    float half_side = leaf_half(LEAF);
    if (half_side != 0.0) uv.x = 0.5 * (uv.x + half_side);  // keeps the winding (front faces)
#endif
    LeafEval e = leaf_eval(jitter_table, uv);
    vec3 n = leaf_normal(e, uv.y);
    v_object = e.L;
    v_object_normal = n;
    vec4 world = LEAF.model * vec4(e.L, 1.0);
    v_world = world.xyz;
    v_normal = normalize(mat3(LEAF.model) * n);  // rotation and uniform scale only
    v_uv = uv;
    v_front = LEAF.front;
    v_back = LEAF.back.rgb;
#ifdef LEAF_AOV
    v_leaf = LEAF_INDEX;
#endif
    gl_Position = frame.proj * frame.view * world;
}
