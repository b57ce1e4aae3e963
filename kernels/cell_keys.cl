/* cell_keys.cl: the first stage of the neighbour search (Keller et al. 2016,
 * Sec. 2.2; sorted-cell search as in SPH codes).
 *
 * Reads: each path's filtering vertex. Writes: its query radius and grid level
 * into a FilterTuple, and the key of its cell with the path index, to be sorted.
 * Radius: r_i = r0_i / n^alpha, with r0_i = d_i sqrt(dOmega / pi) (the footprint
 * of a few pixels at the camera path length d_i) or a global r0. Vertices are
 * binned by level l_i = ceil(log2 r_i) into grids of cell size 2^l (27 cells
 * searched) or 2^(l+1) (8 cells searched), so a cell is never smaller than the
 * query radius; only vertices of one level are neighbours. Keys map (level,
 * cell) into [0, 2^key_bits) in Morton order (cell_key); paths without a vertex
 * get the key 2^key_bits and sort behind all others. Shared keys only cost time:
 * filter.cl tests distances and levels. */

#pragma OPENCL FP_CONTRACT OFF

/* ceil(log2(r)) for r > 0, exactly (no rounding of log2). */
inline int grid_level(float r) {
  int e;
  float m = frexp(r, &e); /* r = m 2^e, m in [0.5, 1) */
  return m == 0.5f ? e - 1 : e;
}

/* Edge length of the cells of a level. */
inline float cell_size(int level, uint cells27) { return ldexp(1.0f, cells27 ? level : level + 1); }

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
 * tuples in cache; XORed with a hash of the level. Cells whose coordinates differ
 * by a multiple of the period share a key; filter.cl's distance and level tests
 * keep them apart. */
inline uint cell_key(int level, int3 c, uint key_bits) {
  uint per_axis = min(key_bits / 3u, 10u);
  uint mask = (1u << per_axis) - 1u;
  uint morton = spread_bits3((uint)c.x & mask) | (spread_bits3((uint)c.y & mask) << 1) |
                (spread_bits3((uint)c.z & mask) << 2);
  return (morton ^ psf_hash((uint)level)) & ((1u << key_bits) - 1u);
}

__kernel void cell_keys(FilterParams p, __global const PathVertex* vertices, __global FilterTuple* tuples,
                        __global uint* keys, __global uint* indices) {
  uint i = get_global_id(0);
  if (i >= p.count) return;
  PathVertex v = vertices[i];
  FilterTuple t;
  t.normal = v.normal;
  t.albedo = v.albedo;
  indices[i] = i;
  if (v.albedo.w == 0.0f) {
    t.position = (float4)(v.position.xyz, 0.0f);
    t.albedo.w = 0.0f;
    tuples[i] = t;
    keys[i] = 1u << p.key_bits;
    return;
  }
  float r0 = p.r0 > 0.0f ? p.r0 : v.position.w * p.footprint;
  float r = r0 * p.n_scale;
  int level = grid_level(fmax(r, 1e-30f));
  t.position = (float4)(v.position.xyz, r);
  t.albedo.w = (float)level;
  tuples[i] = t;
  keys[i] = cell_key(level, cell_of(v.position.xyz, cell_size(level, p.cells27)), p.key_bits);
}
