#version 450
// GPU-driven culling and level of detail for scenes (leafview/gpu/scene.py). One invocation per
// leaf: the leaf's bounding sphere (its species' leaf-space sphere, placed by the leaf's model
// matrix) is tested against the six frustum planes and against a minimum projected size; a
// visible leaf gets the coarsest (u, v) grid whose outline error stays under max_error_px pixels
// and is appended to that level's list, whose draw command counts it. Species come in grid groups
// (the species' lod_error[0], unused as an error: 0 the levels' grids, 1 a lobed species' own grids,
// leafview/gpu/scene.py, lobed_levels); group g has group_levels[g] levels, whose draw commands start
// at group_first[g]. numpy reference: leafview/gpu/scene.py, cull_reference().
layout(local_size_x = 64) in;
#include "generated/leaf_block.glsl"
#include "generated/scene_blocks.glsl"

layout(std430, binding = LEAVES_BINDING) readonly buffer Leaves { LeafData leaves[]; };
layout(std430, binding = SPECIES_OF_BINDING) readonly buffer SpeciesOf { uint species_of[]; };
layout(std430, binding = SPECIES_BINDING) readonly buffer Species { SpeciesCull species[]; };
layout(std430, binding = COMMANDS_BINDING) buffer Commands { DrawCommand commands[]; };
layout(std430, binding = VISIBLE_BINDING) writeonly buffer Visible { uint visible[]; };

uniform uint count;
uniform vec4 planes[6];       // world-space planes, inside where dot(n, p) + d >= 0
uniform vec4 eye;             // xyz camera position (w = 1) or view direction (w = 0, orthographic)
uniform float pixel_scale;    // pixels per world unit at distance 1 (perspective) or anywhere (ortho)
uniform float min_pixels;     // leaves whose sphere spans fewer pixels are dropped
uniform float max_error_px;   // largest outline error allowed for a coarser level
uniform ivec2 group_levels;   // levels of detail (grids) of each grid group
uniform ivec2 group_first;    // the draw command of each group's finest level
uniform int forced_level;     // >= 0: every visible leaf at this level (LOD off; the group's last at most)
uniform bool frustum;         // false: no frustum or size test (culling off)
// wind (leafview/gpu/wind.py, set_cull_padding; 0: still): the largest petiole turn phi, midrib
// coefficient k and flutter factor f of leafview.deform.wind.cull_bounds. A point within s leaf
// lengths of its base flutters by at most a = 3 f s^2 (1/2 + s), then turns about the base by at
// most psi = min(phi + k s (6 - 4 s + s^2), pi): the frustum test (not the size test, nor the
// level of detail) pads the sphere by a + 2 (s + a) sin(psi / 2)
uniform vec3 wind_pad;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    SpeciesCull sc = species[species_of[i]];
    mat4 m = leaves[i].model;
    vec3 center = (m * vec4(sc.sphere.xyz, 1.0)).xyz;
    float scale = length(m[0].xyz);
    float radius = sc.sphere.w * scale;
    float ppu = pixel_scale;
    if (eye.w > 0.5) ppu = pixel_scale / max(distance(center, eye.xyz) - radius, 1e-4);
    if (frustum) {
        float reach = radius;
        if (wind_pad != vec3(0.0)) {
            float s = length(sc.sphere.xyz) + sc.sphere.w;
            float psi = min(wind_pad.x + wind_pad.y * s * (6.0 - 4.0 * s + s * s), 3.14159265);
            float flutter = 3.0 * wind_pad.z * s * s * (0.5 + s);
            reach += scale * (2.0 * (s + flutter) * sin(0.5 * psi) + flutter);
        }
        for (int k = 0; k < 6; ++k)
            if (dot(planes[k].xyz, center) + planes[k].w < -reach) return;
        if (2.0 * radius * ppu < min_pixels) return;
    }
    int group = sc.lod_error[0] >= 1.0 ? 1 : 0;
    int levels = group_levels[group];
    int level = min(forced_level, levels - 1);
    if (forced_level < 0) {
        level = 0;
        while (level + 1 < levels && sc.lod_error[level + 1] * scale * ppu <= max_error_px) ++level;
    }
    int command = group_first[group] + level;
    uint slot = atomicAdd(commands[command].instance_count, 1u);
    visible[commands[command].base_instance + slot] = i;
}
