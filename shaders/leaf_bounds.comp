#version 450
// What the culling pass needs of each leaf record (leafview/gpu/bounds.py): a leaf-space bounding
// sphere and the outline error of every coarser level of detail, one invocation per record. The
// leaf is evaluated with leaf_eval.glsl, the code leaf.vert draws with, at each level's (u, v)
// grid (the drawn half of a one-sided leaf, as leaf.vert maps it; a lobed leaf's swept surface,
// lobe_eval, unless LEAF_NO_LOBES: the grids are then its lobed grids, leafview/gpu/scene.py
// lobed_levels, and the sweep tables are bound at LOBE_UNIT):
//   * centre: the middle of the box of the coarsest level's points;
//   * radius: distance from the centre to the farthest point of any level, plus
//     variation · (largest |point|) + 1e-3 (leaves of a scene vary their control points by
//     ± variation around the record's);
//   * lod_error[k]: largest distance between a level-0 point and the bilinear surface through
//     level k's points, times 1 + 2 variation.
// The grids are compile-time defines: BOUNDS_LEVELS levels, level k (nu, nv) = (BOUNDS_NU<k>,
// BOUNDS_NV<k>). With BOUNDS_NESTED every coarser level's samples are among level 0's (every
// BOUNDS_SU<k>-th column and BOUNDS_SV<k>-th row): level 0 is evaluated once into a local array
// and the coarser levels are read out of it. Otherwise the coarser levels are evaluated into one
// local array (BOUNDS_COARSE points, level k from BOUNDS_OFS<k>) and level 0 is evaluated as it
// is used. numpy reference: leafview/gpu/scene.py, cull_rows_from_points() and species_cull().
layout(local_size_x = 64) in;
#include "generated/leaf_block.glsl"
#include "generated/scene_blocks.glsl"

layout(std430, binding = LEAVES_BINDING) readonly buffer Leaves { LeafData leaves[]; };
layout(std430, binding = SPECIES_BINDING) writeonly buffer Species { SpeciesCull species[]; };

// the invocation's record, loaded once: each evaluation reads its fields many times over, and on
// llvmpipe every storage-buffer read is a gather
LeafData rec;
#define LEAF rec
#include "leaf_eval.glsl"

layout(binding = JITTER_UNIT) uniform sampler2D jitter_table;

uniform uint count;
uniform float variation;

const int NU[4] = int[4](BOUNDS_NU0, BOUNDS_NU1, BOUNDS_NU2, BOUNDS_NU3);
const int NV[4] = int[4](BOUNDS_NV0, BOUNDS_NV1, BOUNDS_NV2, BOUNDS_NV3);
const int LAST = BOUNDS_LEVELS - 1;

#if BOUNDS_NESTED
const int SU[4] = int[4](1, BOUNDS_SU1, BOUNDS_SU2, BOUNDS_SU3);
const int SV[4] = int[4](1, BOUNDS_SV1, BOUNDS_SV2, BOUNDS_SV3);
vec3 pts[BOUNDS_NU0 * BOUNDS_NV0];   // level 0
#define COARSE(k, ci, cj) pts[(cj) * SV[k] * NU[0] + (ci) * SU[k]]
#else
const int OFS[4] = int[4](0, BOUNDS_OFS1, BOUNDS_OFS2, BOUNDS_OFS3);
vec3 pts[BOUNDS_COARSE];             // levels 1 and up
#define COARSE(k, ci, cj) pts[OFS[k] + (cj) * NU[k] + (ci)]
#endif

// the point of grid sample (i, j) of a (nu × nv) grid: u = -1 + 2 i / (nu - 1), v = j / (nv - 1)
vec3 grid_point(int i, int j, int nu, int nv) {
    vec2 uv = vec2(-1.0 + 2.0 * float(i) / float(nu - 1), float(j) / float(nv - 1));
#ifndef LEAF_NO_LOBES
    int lobe_layer = leaf_branch_lobe(LEAF);
    if (lobe_layer >= 0) return lobe_eval(lobe_layer, uv).L;
#endif
#ifndef LEAF_NO_HALF
    float half_side = leaf_half(LEAF);
    if (half_side != 0.0) uv.x = 0.5 * (uv.x + half_side);
#endif
    return leaf_eval(jitter_table, uv).L;
}

void main() {
    uint n = gl_GlobalInvocationID.x;
    if (n >= count) return;
    rec = leaves[n];
    vec3 lo = vec3(1e30), hi = vec3(-1e30);
#if BOUNDS_NESTED
    for (int j = 0; j < NV[0]; ++j)
        for (int i = 0; i < NU[0]; ++i)
            pts[j * NU[0] + i] = grid_point(i, j, NU[0], NV[0]);
#else
    for (int k = 1; k <= LAST; ++k)
        for (int j = 0; j < NV[k]; ++j)
            for (int i = 0; i < NU[k]; ++i)
                COARSE(k, i, j) = grid_point(i, j, NU[k], NV[k]);
    if (LAST == 0) {   // one level, not kept: its box takes a pass of its own
        for (int j = 0; j < NV[0]; ++j)
            for (int i = 0; i < NU[0]; ++i) {
                vec3 p = grid_point(i, j, NU[0], NV[0]);
                lo = min(lo, p);
                hi = max(hi, p);
            }
    }
#endif
    for (int j = 0; j < NV[LAST] && (LAST > 0 || BOUNDS_NESTED != 0); ++j)
        for (int i = 0; i < NU[LAST]; ++i) {
            vec3 p = COARSE(LAST, i, j);
            lo = min(lo, p);
            hi = max(hi, p);
        }
    vec3 c = 0.5 * (lo + hi);
    float r2 = 0.0, norm2 = 0.0;
#if !BOUNDS_NESTED
    for (int m = 0; m < BOUNDS_COARSE && LAST > 0; ++m) {
        r2 = max(r2, dot(pts[m] - c, pts[m] - c));
        norm2 = max(norm2, dot(pts[m], pts[m]));
    }
#endif
    vec4 err = vec4(0.0);
    for (int j = 0; j < NV[0]; ++j) {
        for (int i = 0; i < NU[0]; ++i) {
#if BOUNDS_NESTED
            vec3 p = pts[j * NU[0] + i];
#else
            vec3 p = grid_point(i, j, NU[0], NV[0]);
#endif
            r2 = max(r2, dot(p - c, p - c));
            norm2 = max(norm2, dot(p, p));
            for (int k = 1; k <= LAST; ++k) {
                int cu = NU[k], cv = NV[k];
                // the sample's position in level k's cells (exact for nested grids)
                float x = float(i * (cu - 1)) / float(NU[0] - 1);
                float y = float(j * (cv - 1)) / float(NV[0] - 1);
                int ci = min(int(x), cu - 2), cj = min(int(y), cv - 2);
                float a = x - float(ci), b = y - float(cj);
                vec3 q = (1.0 - a) * (1.0 - b) * COARSE(k, ci, cj) + a * (1.0 - b) * COARSE(k, ci + 1, cj)
                         + (1.0 - a) * b * COARSE(k, ci, cj + 1) + a * b * COARSE(k, ci + 1, cj + 1);
                err[k] = max(err[k], distance(p, q));
            }
        }
    }
    float radius = sqrt(r2) + variation * sqrt(norm2) + 1e-3;
    species[n].sphere = vec4(c, radius);
    species[n].lod_error = err * (1.0 + 2.0 * variation);
}
