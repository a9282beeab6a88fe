// A leaf's colours between the vertex shaders (leaf.vert, leaf_baked.vert) and leaf.frag: front
// rgb, translucency and back rgb as halves in one flat uvec4, one output slot instead of two.
// llvmpipe stores and emits every output slot of every vertex (15 M for a 10^5-leaf scene, most of
// whose triangles cover no pixel), about 9 % of such a frame a slot. A half keeps a colour to 2^-11
// of its value, under 0.02 of an 8-bit step. Numpy twin: leafview.gpu.layout.pack_colours.
#ifdef LEAF_COLOURS_OUT
flat out uvec4 v_colours;

uvec4 pack_colours(vec4 front, vec3 back) {
    return uvec4(packHalf2x16(front.rg), packHalf2x16(front.ba), packHalf2x16(back.rg), packHalf2x16(vec2(back.b, 0.0)));
}
#else
flat in uvec4 v_colours;
#define v_front vec4(unpackHalf2x16(v_colours.x), unpackHalf2x16(v_colours.y))
#define v_back vec3(unpackHalf2x16(v_colours.z), unpackHalf2x16(v_colours.w).x)
#endif
