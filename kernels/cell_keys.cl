/* cell_keys.cl: the first stage of the neighbour search (Keller et al. 2016,
 * Sec. 2.2; sorted-cell search as in SPH codes).
 *
 * Reads: each path's filtering vertex. Writes: the key of its cell with the path
 * index, to be sorted. gather_tuples (tuples.cl) computes the radius and the tag
 * (4 level + 2 light-sample visibility) again with the same functions, which is
 * cheaper than storing them in path order and reading them back at random; the
 * visibility is 0 or 1 (shade.cl), and any nonzero value counts as 1.
 * Radius: r_i = r0_i / n^alpha, with r0_i = d_i sqrt(dOmega / pi) (the footprint
 * of a few pixels at the camera path length d_i) or a global r0; with
 * FilterParams.stretch times the vertex's 1 / sqrt(cos theta_i), so that the
 * ball holds the area of surface those pixels see (psf_shared.h). Vertices are
 * binned by level l_i = ceil(log2 r_i) into grids of cell size 2^l (27 cells
 * searched) or 2^(l+1) (8 cells searched), so a cell is never smaller than the
 * query radius; only vertices of one level are neighbours. Keys map (level,
 * cell) into [0, 2^key_bits) in Morton order (cell_key); paths without a vertex
 * get the key 2^key_bits and sort behind all others. Shared keys only cost time:
 * filter.cl tests distances and levels. */

#pragma OPENCL FP_CONTRACT OFF

/* ceil(log2(r)) for a normal float r > 0, exactly (no rounding of log2): with
 * r = m 2^e, m in [0.5, 1), from the exponent bits; e - 1 where m = 0.5. */
inline int grid_level(float r) {
  uint b = as_uint(r);
  int e = (int)((b >> 23) & 0xFFu) - 126;
  return (b & 0x7FFFFFu) == 0u ? e - 1 : e;
}

/* 2^e exactly, from the exponent bits where 2^e is a normal float (PoCL's
 * ldexp multiplies in a loop). */
inline float pow2i(int e) { return e >= -126 && e <= 127 ? as_float((e + 127) << 23) : ldexp(1.0f, e); }

/* Edge length of the cells of a level. */
inline float cell_size(int level, uint cells27) { return pow2i(cells27 ? level : level + 1); }

inline int3 cell_of(float3 x, float size) {
  float inv = 1.0f / size; /* exact: size is a power of two */
  return (int3)((int)floor(x.x * inv), (int)floor(x.y * inv), (int)floor(x.z * inv));
}

/* Spreads the low 10 bits of v to every third bit (Morton order). */
inline uint spread_bits3(uint v) {
  v &= 0x3FFu;
  v = (v | (v << 16)) & 0x030000FFu;
  v = (v | (v << 8)) & 0x0300F00Fu;
  v = (v | (v << 4)) & 0x030C30C3u;
  v = (v | (v << 2)) & 0x09249249u;
  return v;
}

/* The key of a cell: the Morton code of its coordinates' low bits (as many per
 * axis as the key has bits for), so that the sort puts cells near each other in
 * space near each other in memory and the filter finds its neighbours' ranges and
 * tuples in cache; XORed with a hash of the level and of the block of 2^per_axis
 * cells per axis that holds the cell. Inside a block the XOR is one constant,
 * which maps aligned runs of Morton codes onto aligned runs and so keeps the
 * order's locality. Without the block's hash, cells a period apart shared a key:
 * in Sponza (about 240 cells across at its 2^20 tuples' levels, a period of 128)
 * a key held 38 tuples where a cell holds 26, and the filter scanned the others'
 * too. Keys may still collide by chance (a table of 2 keys per tuple);
 * filter.cl's distance and level tests keep such cells apart, and it visits a key
 * shared by two of a query's cells once. */
inline uint cell_key_bits_per_axis(uint key_bits) { return min(key_bits / 3u, 10u); }

/* A key is built from per-axis parts, so that the filter computes each
 * coordinate's once for all the cells it visits: the coordinate's Morton bits
 * (spread_bits3 of its low per_axis bits, shifted by the axis), and its block
 * (the floor of c / 2^per_axis, an arithmetic shift) times a large odd constant
 * of the axis (Teschner et al.'s spatial hash); the level's part is its own such
 * product. key = (x | y | z Morton bits) ^ lowbias32(x ^ y ^ z ^ level blocks).
 * The coordinates are offset first, so that block boundaries do not fall on
 * the planes scenes are built on (a floor at y = 0 lay on one, and the filter's
 * queries there visited cells of two blocks, whose keys it must compare). */
inline int cell_offset(int c, uint axis) { return c + (axis == 0u ? 1237 : axis == 1u ? 2741 : 3593); }

inline uint cell_morton_part(int c, uint axis, uint per_axis) {
  return spread_bits3((uint)cell_offset(c, axis) & ((1u << per_axis) - 1u)) << axis;
}

inline uint cell_block_part(int c, uint axis, uint per_axis) {
  const uint prime = axis == 0u ? 73856093u : axis == 1u ? 19349663u : 83492791u;
  return (uint)(cell_offset(c, axis) >> (int)per_axis) * prime;
}

inline uint cell_level_part(int level) { return (uint)level * 2654435761u; }

inline uint cell_key_of_parts(uint morton, uint blocks, uint key_bits) {
  return (morton ^ psf_hash(blocks)) & ((1u << key_bits) - 1u);
}

inline uint cell_key(int level, int3 c, uint key_bits) {
  uint per_axis = cell_key_bits_per_axis(key_bits);
  uint morton = cell_morton_part(c.x, 0u, per_axis) | cell_morton_part(c.y, 1u, per_axis) |
                cell_morton_part(c.z, 2u, per_axis);
  uint blocks = cell_block_part(c.x, 0u, per_axis) ^ cell_block_part(c.y, 1u, per_axis) ^
                cell_block_part(c.z, 2u, per_axis) ^ cell_level_part(level);
  return cell_key_of_parts(morton, blocks, key_bits);
}

/* The query radius of a path's filtering vertex, 0 for a path without one. */
inline float vertex_radius(FilterParams p, float4 position, float4 albedo) {
  if (albedo.w == 0.0f) return 0.0f;
  float r0 = p.r0 > 0.0f ? p.r0 : position.w * p.footprint;
  if (p.stretch) r0 *= albedo.w;
  return r0 * p.n_scale;
}

inline int vertex_level(float r) { return grid_level(fmax(r, 1e-30f)); }

/* The filter's tag of a vertex with radius r > 0: 4 level + 2 light-sample
 * visibility (filter.cl adds the bit of a finite value). */
inline int vertex_tag(float r, float4 normal) { return 4 * vertex_level(r) + (normal.w != 0.0f ? 2 : 0); }

__kernel void cell_keys(FilterParams p, __global const PathVertex* vertices, __global uint* keys,
                        __global uint* indices) {
  uint i = get_global_id(0);
  if (i >= p.count) return;
  float4 x = vertices[i].position, a = vertices[i].albedo;
  indices[i] = i;
  float r = vertex_radius(p, x, a);
  if (r == 0.0f) {
    keys[i] = 1u << p.key_bits;
    return;
  }
  int level = vertex_level(r);
  keys[i] = cell_key(level, cell_of(x.xyz, cell_size(level, p.cells27)), p.key_bits);
}
