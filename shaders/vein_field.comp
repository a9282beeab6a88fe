#version 450
// The vein field (leafview/gpu/vein_field.py; numpy twin leafview/botany/vein_field.py:
// tile_lists and field_from_segments). Four stages of one file, VEIN_FIELD_STAGE:
//   0 BOUND: one invocation per segment and job (z). For each tile whose box B (holding all its
//     texels in q) meets the segment's box widened by VEIN_FIELD_REACH, the segment's distance
//     to B's farthest corner bounds the distance from every texel of the tile to its nearest
//     segment: atomicMin into the tile's bound (and into its order <= 2 bound for such a
//     segment). Both start at field_cap; any reach gives valid bounds.
//   1 REACH: one invocation per row of tiles: the largest bound of the row (of each kind), how
//     far the list stage has to look in that row.
//   2 LIST: the tiles whose box meets the segment's box widened by its row's reach (at most
//     field_cap); the segment joins a tile's list when its least distance to B is at most the
//     tile's bound (its order <= 2 bound for such a segment): only those can be nearest for one
//     of the tile's texels.
//   3 FIELD: a VEIN_FIELD_TILE-square tile per work group, an invocation per row of it: each
//     texel's point q = (u w(v), v) in vein space, (s, t) = ((i + 1/2) / size, (j + 1/2) / size),
//     u = 1 - 2 s, v = 1 - t, w linear in the job's half-width table; over the tile's list the
//     distance to segment q0 + h d,
//     h = clamp((q - q0).d / |d|^2, 0, 1), |q - q0 - h d|; writes (nearest distance, its order,
//     its width, nearest distance of order <= 2), distances capped at field_cap, order and width
//     0 when nothing is nearer. Ties go to the lower segment index, as numpy's argmin.
//
// VeinSegments, vec4s: job k's header at [2k] and [2k + 1] as uint bits: (half-width table,
// tile rows, tile boxes, segment records) as first vec4s, then (segment count, first word of
// its tile data in VeinTiles, first word of its lists there, first texel of its output). Tile
// rows: (w_lo, w_hi, v_lo, v_hi) per row of tiles; tile boxes: (x_lo, y_lo, x_hi, y_hi) per
// tile, row-major (tile_geometry in the twin); a record is two vec4s (q0, d), (1 / |d|^2 or 0,
// order, width, 0).
// VeinTiles, uint words: a job's tile data, bounds (2 per tile: all, order <= 2, float bits,
// set to field_cap by the caller), counts (1 per tile, set to 0) and reaches (2 per row of tiles,
// float bits); elsewhere its lists, list_capacity words a tile. The list stage counts every
// segment a tile keeps but stores list_capacity at most: the caller reads the counts back and,
// where one is larger, runs the list stage again with room for it (the field stage needs them
// whole).
#define STAGE_BOUND 0
#define STAGE_REACH 1
#define STAGE_LIST 2
#define STAGE_FIELD 3
#if VEIN_FIELD_TILE != 8
#error "the field stage holds a tile row's 8 texels in two vec4"
#endif

#if VEIN_FIELD_STAGE == STAGE_FIELD
layout(local_size_x = VEIN_FIELD_TILE) in;   // x: the row in the tile (llvmpipe packs x into SIMD lanes)
#else
layout(local_size_x = VEIN_FIELD_GROUP) in;
#endif

layout(std430, binding = VEIN_SEGMENTS_BINDING) readonly buffer VeinSegments { vec4 vein_data[]; };
#if VEIN_FIELD_STAGE == STAGE_FIELD
layout(std430, binding = VEIN_TILES_BINDING) readonly buffer VeinTiles { uint vein_tiles[]; };
layout(std430, binding = VEIN_TEXELS_BINDING) writeonly buffer VeinTexels { vec4 vein_texels[]; };
#else
layout(std430, binding = VEIN_TILES_BINDING) buffer VeinTiles { uint vein_tiles[]; };
#endif

uniform int field_size;
#if VEIN_FIELD_STAGE == STAGE_LIST || VEIN_FIELD_STAGE == STAGE_FIELD
uniform uint list_capacity;
#endif
const float field_cap = VEIN_FIELD_CAP;
const float SLACK = 1e-6;   // the twin's _SLACK: float32 rounding never drops a segment that can win
const float BIG = 1e30;

struct Job { uint table, rows, boxes, records, count, tiles, lists, texels; };

Job load_job(uint k) {
    uvec4 a = floatBitsToUint(vein_data[2u * k]);
    uvec4 b = floatBitsToUint(vein_data[2u * k + 1u]);
    return Job(a.x, a.y, a.z, a.w, b.x, b.y, b.z, b.w);
}

// where a job's tile data lie in VeinTiles
uint tiles_across() { return uint(field_size / VEIN_FIELD_TILE); }
uint bound_word(Job job, uint tile, bool major) { return job.tiles + 2u * tile + (major ? 1u : 0u); }
uint count_word(Job job, uint tile) { uint n = tiles_across(); return job.tiles + 2u * n * n + tile; }
uint reach_word(Job job, uint row, bool major) {
    uint n = tiles_across();
    return job.tiles + 3u * n * n + 2u * row + (major ? 1u : 0u);
}
#if VEIN_FIELD_STAGE == STAGE_LIST || VEIN_FIELD_STAGE == STAGE_FIELD
uint list_word(Job job, uint tile) { return job.lists + tile * list_capacity; }
#endif

float segment_distance(vec2 q, vec4 seg, float inv_len2) {
    vec2 e = q - seg.xy;
    float h = clamp(dot(e, seg.zw) * inv_len2, 0.0, 1.0);
    return length(e - h * seg.zw);
}

#if VEIN_FIELD_STAGE == STAGE_BOUND || VEIN_FIELD_STAGE == STAGE_LIST
// the largest distance from a point of the box (lo.xy, hi.zw) to the segment: at a corner, as
// the distance to a segment is convex (the twin's box_bounds)
float box_upper(vec4 box, vec4 seg, float inv_len2) {
    return max(max(segment_distance(box.xy, seg, inv_len2), segment_distance(box.zw, seg, inv_len2)),
               max(segment_distance(box.xw, seg, inv_len2), segment_distance(box.zy, seg, inv_len2)));
}

float point_box(vec2 p, vec4 box) {
    return length(max(max(box.xy - p, p - box.zw), 0.0));
}

// the least distance from a point of the box to the segment: 0 where it crosses the box
// (Liang-Barsky clipping of q0 + h d, h in [0, 1]), else between an end point and the box or a
// corner and the segment
float box_lower(vec4 box, vec4 seg, float inv_len2) {
    float t0 = 0.0, t1 = 1.0;
    for (int k = 0; k < 2; ++k) {
        float lo = box[k], hi = box[k + 2], p = seg[k], d = seg[k + 2];
        if (d == 0.0) {
            if (p < lo || p > hi) t0 = 2.0;
        } else {
            float ta = (lo - p) / d, tb = (hi - p) / d;
            t0 = max(t0, min(ta, tb));
            t1 = min(t1, max(ta, tb));
        }
    }
    if (t0 <= t1) return 0.0;
    float ends = min(point_box(seg.xy, box), point_box(seg.xy + seg.zw, box));
    float corners = min(min(segment_distance(box.xy, seg, inv_len2), segment_distance(box.zw, seg, inv_len2)),
                        min(segment_distance(box.xw, seg, inv_len2), segment_distance(box.zy, seg, inv_len2)));
    return min(ends, corners);
}

void main() {
    Job job = load_job(gl_WorkGroupID.z);
    uint m = gl_GlobalInvocationID.x;
    if (m >= job.count) return;
    vec4 a = vein_data[job.records + 2u * m];
    vec4 b = vein_data[job.records + 2u * m + 1u];
    bool major = b.y <= 2.0;
    vec2 seg_lo = min(a.xy, a.xy + a.zw), seg_hi = max(a.xy, a.xy + a.zw);
#if VEIN_FIELD_STAGE == STAGE_BOUND
    float most = VEIN_FIELD_REACH;
#else
    float most = field_cap;
#endif
    int tiles = int(tiles_across());
    float size = float(field_size), t = float(VEIN_FIELD_TILE);
    // the rows of tiles whose v range can meet [lo.y, hi.y] (tile row ty holds texel rows ty T ..
    // ty T + T - 1, v = 1 - (j + 1/2) / size), one row of margin each side
    int ty_lo = max(int(ceil(((1.0 - min(seg_hi.y + most, 2.0)) * size + 0.5) / t - 1.0)) - 1, 0);
    int ty_hi = min(int(floor(((1.0 - max(seg_lo.y - most, -1.0)) * size - 0.5) / t)) + 1, tiles - 1);
    for (int ty = ty_lo; ty <= ty_hi; ++ty) {
#if VEIN_FIELD_STAGE == STAGE_BOUND
        float reach = most;
#else
        float reach = uintBitsToFloat(vein_tiles[reach_word(job, uint(ty), major)]) + SLACK;
#endif
        vec2 lo = seg_lo - reach, hi = seg_hi + reach;
        vec4 row = vein_data[job.rows + uint(ty)];   // w_lo, w_hi, v_lo, v_hi
        if (row.z > hi.y || row.w < lo.y) continue;
        // the tiles whose x extent [x_lo, x_hi] can meet [lo.x, hi.x]: x = u w is bilinear in
        // (u, w), so x_hi = u_hi (w_hi or w_lo) and x_lo = u_lo (w_lo or w_hi) by the sign of u,
        // both falling with tx as u does; solved for tx, one tile of margin each side
        float ua = lo.x > 0.0 ? (row.y > 0.0 ? lo.x / row.y : BIG) : (row.x > 0.0 ? lo.x / row.x : -BIG);
        float ub = hi.x < 0.0 ? (row.y > 0.0 ? hi.x / row.y : -BIG) : (row.x > 0.0 ? hi.x / row.x : BIG);
        float last = ((1.0 - clamp(ua, -2.0, 2.0)) * 0.5 * size - 0.5) / t;
        float first = ((1.0 - clamp(ub, -2.0, 2.0)) * 0.5 * size + 0.5) / t - 1.0;
        int tx_hi = min(int(floor(last)) + 1, tiles - 1);
        int tx_lo = max(int(ceil(first)) - 1, 0);
        for (int tx = tx_lo; tx <= tx_hi; ++tx) {
            uint tile = uint(ty * tiles + tx);
            vec4 box = vein_data[job.boxes + tile];
            if (box.y > hi.y || box.w < lo.y || box.x > hi.x || box.z < lo.x) continue;   // the boxes do not meet
            // the gap between the segment's box and the tile's: a cheap lower bound that skips
            // the tiles the segment cannot matter to (no change to what the stages decide)
            vec2 gap = max(max(box.xy - seg_hi, seg_lo - box.zw), 0.0);
            float limit = uintBitsToFloat(vein_tiles[bound_word(job, tile, major)]);
            if (length(gap) > limit + SLACK) continue;
#if VEIN_FIELD_STAGE == STAGE_BOUND
            // atomics only where they lower a bound (plain reads are cheaper)
            uint upper = floatBitsToUint(box_upper(box, a, b.x));
            if (upper < vein_tiles[bound_word(job, tile, false)]) atomicMin(vein_tiles[bound_word(job, tile, false)], upper);
            if (major && upper < vein_tiles[bound_word(job, tile, true)]) atomicMin(vein_tiles[bound_word(job, tile, true)], upper);
#else
            if (box_lower(box, a, b.x) > limit + SLACK) continue;
            uint slot = atomicAdd(vein_tiles[count_word(job, tile)], 1u);
            if (slot < list_capacity) vein_tiles[list_word(job, tile) + slot] = m;
#endif
        }
    }
}

#elif VEIN_FIELD_STAGE == STAGE_REACH
void main() {
    Job job = load_job(gl_WorkGroupID.z);
    uint row = gl_GlobalInvocationID.x, n = tiles_across();
    if (row >= n) return;
    uint most = 0u, most_major = 0u;   // float bits of non-negative floats order as uints
    for (uint tx = 0u; tx < n; ++tx) {
        most = max(most, vein_tiles[bound_word(job, row * n + tx, false)]);
        most_major = max(most_major, vein_tiles[bound_word(job, row * n + tx, true)]);
    }
    vein_tiles[reach_word(job, row, false)] = most;
    vein_tiles[reach_word(job, row, true)] = most_major;
}

#else
// A tile row's 8 texels as two vec4 of x (their y is the row's v): squared distances, the
// nearest so far and its segment index, all in registers. Each segment read serves 8 texels.
// No shared memory and no barrier: llvmpipe runs work groups with barriers as coroutines, which
// costs more than the reads they would save.
vec4 qx[2];
float qy;
vec4 best[2], best_major[2];   // squared distances
uvec4 pick[2];

float halfwidth(uint table, float v) {
    float x = clamp(v, 0.0, 1.0) * float(VEIN_FIELD_HALFWIDTH - 1);
    int k = min(int(x), VEIN_FIELD_HALFWIDTH - 2);
    float a = vein_data[table + uint(k) / 4u][k % 4];
    float b = vein_data[table + uint(k + 1) / 4u][(k + 1) % 4];
    return a + (b - a) * (x - float(k));
}

// segment m, (q0, d) and (1 / |d|^2, order, ...): where it is nearer than the nearest so far, or
// as near with a lower index (as numpy's argmin), it is picked (segment_distance for four texels
// at once, squared)
void visit(vec4 a, vec4 b, uint m) {
    bool major = b.y <= 2.0;   // the same in every lane
    float ey = qy - a.y;
    for (int k = 0; k < 2; ++k) {
        vec4 ex = qx[k] - a.x;
        vec4 h = clamp((ex * a.z + ey * a.w) * b.x, 0.0, 1.0);
        vec4 fx = ex - h * a.z, fy = ey - h * a.w;
        vec4 d2 = fx * fx + fy * fy;
        bvec4 nearer = bvec4(uvec4(lessThan(d2, best[k])) | (uvec4(equal(d2, best[k])) & uvec4(lessThan(uvec4(m), pick[k]))));
        best[k] = mix(best[k], d2, nearer);
        pick[k] = mix(pick[k], uvec4(m), nearer);
        if (major) best_major[k] = min(best_major[k], d2);
    }
}

void main() {
    Job job = load_job(gl_WorkGroupID.z);
    uint tile = gl_WorkGroupID.y * tiles_across() + gl_WorkGroupID.x;
    int i0 = int(gl_WorkGroupID.x) * VEIN_FIELD_TILE;
    int j = int(gl_WorkGroupID.y) * VEIN_FIELD_TILE + int(gl_LocalInvocationID.x);
    float v = 1.0 - (float(j) + 0.5) / float(field_size);
    float w = halfwidth(job.table, v);
    vec4 cols = vec4(0.5, 1.5, 2.5, 3.5) + float(i0);
    qx[0] = (1.0 - 2.0 * cols / float(field_size)) * w;
    qx[1] = (1.0 - 2.0 * (cols + 4.0) / float(field_size)) * w;
    qy = v;
    float cap2 = field_cap * field_cap;
    best[0] = best[1] = best_major[0] = best_major[1] = vec4(cap2);
    pick[0] = pick[1] = uvec4(0xffffffffu);
    uint n = min(vein_tiles[count_word(job, tile)], list_capacity);   // (never more: see above)
    uint list = list_word(job, tile);
    for (uint k = 0u; k < n; ++k) {
        uint m = vein_tiles[list + k];
        visit(vein_data[job.records + 2u * m], vein_data[job.records + 2u * m + 1u], m);
    }
    uint at = job.texels + uint(j * field_size + i0);
    for (int c = 0; c < 8; ++c) {
        float d2 = best[c / 4][c % 4];
        vec2 payload = d2 < cap2 ? vein_data[job.records + 2u * pick[c / 4][c % 4] + 1u].yz : vec2(0.0);
        vein_texels[at + uint(c)] = vec4(d2 < cap2 ? sqrt(d2) : field_cap, payload,
                                         min(sqrt(best_major[c / 4][c % 4]), field_cap));
    }
}
#endif
