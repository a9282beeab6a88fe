#version 450
// Baked-mesh vertex shader: the comparison path of the benchmark (leafview/gpu/instanced.py,
// BakedLeaves). Positions and normals arrive precomputed in world space, one vertex record per
// leaf vertex; it writes the same outputs as leaf.vert so leaf.frag shades both identically.
#include "generated/frame_block.glsl"
#ifndef LEAF_NO_VEINS
#include "leaf_vein_lod.glsl"
#endif

in vec3 in_position;   // world space
in vec3 in_normal;     // world space, unit, upper (front) side
in vec2 in_uv;
in vec4 in_front;      // rgb, translucency (normalised bytes)
in vec4 in_back;       // rgb, unused
#ifndef LEAF_NO_TEXTURE
in vec2 in_layers;     // front, back image texture layer + 1 as LEAF_SLOTS stores them (0: untextured;
                       // an unbound attribute reads 0)
#endif
#ifndef LEAF_NO_VEINS
in vec2 in_veins;      // vein layer + 1 (0: no veins; an unbound attribute reads 0), world scale
#endif

out vec3 v_world;
out vec3 v_normal;
out vec2 v_uv;
#ifdef LEAF_BAKED_RIB
in vec2 in_rib;   // the vein band's coordinates as leaf.vert computed them (thumbnails)
#endif
out vec2 v_rib;   // leaf.frag's vein band: in_rib, else (|u|, v) of the grid the leaf was baked on
#define LEAF_COLOURS_OUT
#include "leaf_colours.glsl"
flat out ivec2 v_layers;
#ifndef LEAF_NO_VEINS
flat out vec4 v_vein;
flat out vec2 v_vein_style;
#endif

void main() {
    v_world = in_position;
    v_normal = in_normal;
    v_uv = in_uv;
#ifdef LEAF_BAKED_RIB
    v_rib = in_rib;
#else
    v_rib = vec2(abs(in_uv.x), in_uv.y);
#endif
    v_colours = pack_colours(in_front, in_back.rgb);
#ifdef LEAF_NO_TEXTURE
    v_layers = ivec2(-1);
#else
    v_layers = ivec2(in_layers) - 1;
#endif
    gl_Position = frame.proj * frame.view * vec4(in_position, 1.0);
#ifndef LEAF_NO_VEINS
    vein_vertex(int(in_veins.x) - 1, in_veins.y, gl_Position.w, v_vein, v_vein_style);
#endif
}
