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
 * binned by level l_i = ceil(log2 r_i) into grids of cubes of 2^l (27 cells
 * searched) or of cells 2^(l+1) along y and z and a quarter of that along x (8
 * cells' rows searched), so a cell is never smaller than the query radius along
 * y and z; only vertices of one level are neighbours. Keys map (class, cell)
 * into [0, 2^key_bits) in rows along x (cell_key), the class being 2 level
 * + light-sample visibility: vertices that disagree on either are never
 * neighbours, so each class's vertices get cells of their own and a query scans
 * only its own class's (Sponza, lit by the default sky, whose vertices compare
 * hemisphere rays: 11.6 vectors of 8 candidates per query where the level alone
 * gave 13.0). Paths without a vertex get the key 2^key_bits and sort behind all
 * others. Shared keys only cost time: filter.cl tests distances, levels and
 * visibility. */

#pragma OPENCL FP_CONTRACT OFF

/* The functions of a vertex's cell key are defined for one vertex (float, int,
 * uint) and for eight (float8, int8, uint8: cell_keys on CPUs, eight paths per
 * work-item in vector arithmetic, where PoCL runs the one-path kernel as a
 * scalar loop over work-items; Sponza's 2^20 paths 8.6-8.9 -> 3.0-3.3 ms) from
 * one body each, so that both give the same keys bit for bit (filter.cl looks
 * the cells up with the scalar ones). In the vector forms a comparison is -1 or
 * 0 per lane and ?: selects per lane. */
#define PSF_DEFINE_CELL_KEY(S)                                                                                     \
  /* ceil(log2(r)) for a normal float r > 0, exactly (no rounding of log2): with  */                               \
  /* r = m 2^e, m in [0.5, 1), from the exponent bits; e - 1 where m = 0.5. */                                     \
  inline int##S grid_level##S(float##S r) {                                                                        \
    uint##S b = as_uint##S(r);                                                                                     \
    int##S e = as_int##S((b >> 23) & 0xFFu) - 126;                                                                \
    return (b & 0x7FFFFFu) == 0u ? e - 1 : e;                                                                      \
  }                                                                                                                \
  /* 2^e exactly, from the exponent bits, for e in [-126, 127]; 0 below (the radii */                              \
  /* are at least 1e-30: levels from -99) and infinity above. */                                                   \
  inline float##S pow2i##S(int##S e) {                                                                             \
    return e > 127 ? (float##S)(INFINITY) : e < -126 ? (float##S)(0.0f) : as_float##S((e + 127) << 23);          \
  }                                                                                                                \
  /* Edge length of the cells of a level along y and z; along x it is cell_x_split times less. */                 \
  inline float##S cell_size##S(int##S level, uint cells27) { return pow2i##S(level + (cells27 ? 0 : 1)); }         \
  /* A coordinate's cell along one axis; inv = 1 / size, exact: size is a power of two. */                         \
  inline int##S cell_coord##S(float##S x, float##S inv) { return convert_int##S(floor(x * inv)); }                 \
  /* Spreads the low 10 bits of v to every other bit (Morton order of two axes). */                                 \
  inline uint##S spread_bits2##S(uint##S v) {                                                                      \
    v &= 0x3FFu;                                                                                                   \
    v = (v | (v << 8)) & 0x00FF00FFu;                                                                              \
    v = (v | (v << 4)) & 0x0F0F0F0Fu;                                                                              \
    v = (v | (v << 2)) & 0x33333333u;                                                                              \
    v = (v | (v << 1)) & 0x55555555u;                                                                              \
    return v;                                                                                                      \
  }                                                                                                                \
  inline int##S cell_offset##S(int##S c, uint axis) { return c + (axis == 0u ? 1237 : axis == 1u ? 2741 : 3593); } \
  /* x's low bits as they are, y's and z's in Morton order above them. */                                           \
  inline uint##S cell_morton_part##S(int##S c, uint axis, uint layout) {                                           \
    const uint bits = cell_axis_bits(axis, layout);                                                                \
    uint##S low = as_uint##S(cell_offset##S(c, axis)) & ((1u << bits) - 1u);                                      \
    return axis == 0u ? low : spread_bits2##S(low) << (cell_axis_bits(0u, layout) + axis - 1u);                   \
  }                                                                                                                \
  inline uint##S cell_block_part##S(int##S c, uint axis, uint layout) {                                            \
    const uint prime = axis == 0u ? 73856093u : axis == 1u ? 19349663u : 83492791u;                               \
    return as_uint##S(cell_offset##S(c, axis) >> (int)cell_axis_bits(axis, layout)) * prime;                      \
  }                                                                                                                \
  inline uint##S cell_class_part##S(int##S key_class) { return as_uint##S(key_class) * 2654435761u; }             \
  inline uint##S cell_key_of_parts##S(uint##S morton, uint##S blocks, uint key_bits) {                            \
    return (morton + psf_hash##S(blocks)) & ((1u << key_bits) - 1u);                                              \
  }                                                                                                                \
  inline uint##S cell_key##S(int##S key_class, int##S cx, int##S cy, int##S cz, uint layout, uint key_bits) {     \
    uint##S morton = cell_morton_part##S(cx, 0u, layout) | cell_morton_part##S(cy, 1u, layout) |                  \
                     cell_morton_part##S(cz, 2u, layout);                                                         \
    uint##S blocks = cell_block_part##S(cx, 0u, layout) ^ cell_block_part##S(cy, 1u, layout) ^                    \
                     cell_block_part##S(cz, 2u, layout) ^ cell_class_part##S(key_class);                          \
    return cell_key_of_parts##S(morton, blocks, key_bits);                                                        \
  }                                                                                                                \
  /* The query radius of a path's filtering vertex from its camera path length d */                                \
  /* (position.w) and footprint stretch s (albedo.w, 0: no vertex); 0 without one. */                              \
  inline float##S vertex_radius##S(FilterParams p, float##S d, float##S s) {                                       \
    float##S r0 = p.r0 > 0.0f ? (float##S)(p.r0) : d * p.footprint;                                              \
    if (p.stretch) r0 *= s;                                                                                        \
    return s == 0.0f ? (float##S)(0.0f) : r0 * p.n_scale;                                                          \
  }                                                                                                                \
  inline int##S vertex_level##S(float##S r) { return grid_level##S(fmax(r, 1e-30f)); }

/* The key of a cell. With cells of 2r, cells are 4 times narrower along x than
 * along y and z (cell_x_split), and keys come in blocks of 2^(per_axis + 2) x
 * 2^(per_axis - 1) x 2^(per_axis - 1) cells (per_axis: the key's bits / 3; cubes
 * of r: 2^per_axis per axis, cell_key_layout). Within a block a
 * cell's key is the low bits of its x coordinate with the Morton code of y's and
 * z's above them, plus a hash of the class and of the block (modulo the table's
 * size). So the cells of a row along x within a block have consecutive keys
 * (wrapping at most once at the table's end), and their tuples are one run in
 * sorted order, which the filter scans at once: the row is cut to the ball's
 * reach along x at a quarter of a cell (Sponza's queries scan 6.7 vectors of 8
 * candidates where whole cells of 2r gave 11.6), and rows near each other in y
 * and z are near each other in memory, where the filter finds them in cache.
 * The hash is added, not XORed into the bits above x's: cells on a plane of
 * constant x share x's low bits, and would have been confined to 1/2^(per_axis +
 * 2) of the table (the Cornell box's side walls: 75 cells per key). Without the
 * block's hash, cells a period apart shared a key: in Sponza (about 240 cells
 * across at its 2^20 tuples' levels, a period of 128) a key held 38 tuples where
 * a cell holds 26, and the filter scanned the others' too. Keys may still
 * collide by chance (a table of 2 keys per tuple); filter.cl's distance and
 * level tests keep such cells apart, and a query whose cells span two blocks
 * visits them cell by cell, taking from each only the tuples inside it.
 *
 * A key is built from per-axis parts, so that the filter computes each
 * coordinate's once for all the cells it visits: the coordinate's low bits (x's
 * as they are, y's and z's spread to every other bit by spread_bits2 and
 * shifted above x's), and its block (an arithmetic shift: the floor) times a
 * large odd constant of the axis (Teschner et al.'s spatial hash); the class's
 * part is its own such product.
 * key = (x bits | y, z Morton bits) + lowbias32(x ^ y ^ z blocks ^ class part).
 * The coordinates are offset first (cell_offset), so that block boundaries do
 * not fall on the planes scenes are built on (a floor at y = 0 lay on one, and
 * the filter's queries there visited cells of two blocks cell by cell). */
inline uint cell_key_bits_per_axis(uint key_bits) { return min(key_bits / 3u, 10u); }

/* With cells of 2r (the default), cells are 4 times narrower along x than along
 * y and z, and x's part of a key has 2 bits more than the key's per-axis share,
 * y's and z's one bit less each. Cells of r (cells27) are cubes: split along x
 * as well, they saved few candidates (Sponza, living room, Cornell box: 5.9,
 * 11.1 and 8.3 vectors of 8 per query against 6.4, 11.0 and 7.1 as cubes) for
 * rows up to 11 cells long that crowd the key table. The layout of a batch's
 * keys: per_axis | x's extra bits << 8. */
inline float cell_x_split(uint cells27) { return cells27 ? 1.0f : 4.0f; }
inline uint cell_key_layout(uint key_bits, uint cells27) {
  return cell_key_bits_per_axis(key_bits) | (cells27 ? 0u : 2u << 8);
}
inline uint cell_layout_per_axis(uint layout) { return layout & 0xFFu; }
inline uint cell_axis_bits(uint axis, uint layout) {
  const uint per_axis = cell_layout_per_axis(layout), extra = layout >> 8;
  return axis == 0u ? per_axis + extra : max(per_axis, extra >> 1) - (extra >> 1);
}

PSF_DEFINE_CELL_KEY()
PSF_DEFINE_CELL_KEY(8)

/* The cell of x in the grid whose cells are `size` along y and z (cell_size) and
 * size / split along x (cell_x_split). */
inline int3 cell_of(float3 x, float size, float split) {
  float inv = 1.0f / size;
  return (int3)(cell_coord(x.x, inv * split), cell_coord(x.y, inv), cell_coord(x.z, inv));
}

/* The filter's tag of a vertex with radius r > 0: 4 level + 2 light-sample
 * visibility (filter.cl adds the bit of a finite value); the visibility counts
 * as 0 for all with FilterParams.ignore_visibility. */
inline int vertex_tag(FilterParams p, float r, float4 normal) {
  return 4 * vertex_level(r) + (normal.w != 0.0f && !p.ignore_visibility ? 2 : 0);
}

/* The key's class of a vertex: 2 level + visibility, the tag's upper bits. */
inline int tag_key_class(int tag) { return tag >> 1; }

/* One lane of an eight-path work-item: path min(i0 + k, last). */
#define PSF_KEY_LANE(k)                                     \
  {                                                         \
    uint j = min(i0 + k##u, last);                          \
    float4 xj = vertices[j].position;                       \
    x.s##k = xj.x;                                          \
    y.s##k = xj.y;                                          \
    z.s##k = xj.z;                                          \
    d.s##k = xj.w;                                          \
    s.s##k = vertices[j].albedo.w;                          \
    v.s##k = vertices[j].normal.w;                          \
  }

/* lanes: paths per work-item, 1 (GPUs) or PSF_GATHER_LANES (CPUs: the vector
 * forms of the key's functions; 2^20 paths of the Cornell box took 15 ms one by
 * one). */
__kernel void cell_keys(FilterParams p, uint lanes, __global const PathVertex* vertices, __global uint* keys,
                        __global uint* indices) {
  if (lanes == 1u) {
    uint i = get_global_id(0);
    if (i >= p.count) return;
    float4 x = vertices[i].position;
    indices[i] = i;
    float r = vertex_radius(p, x.w, vertices[i].albedo.w);
    if (r == 0.0f) {
      keys[i] = 1u << p.key_bits;
      return;
    }
    int level = vertex_level(r);
    int3 c = cell_of(x.xyz, cell_size(level, p.cells27), cell_x_split(p.cells27));
    keys[i] = cell_key(tag_key_class(vertex_tag(p, r, vertices[i].normal)), c.x, c.y, c.z,
                       cell_key_layout(p.key_bits, p.cells27), p.key_bits);
    return;
  }
  uint i0 = get_global_id(0) * PSF_GATHER_LANES;
  if (i0 >= p.count) return;
  uint last = p.count - 1u;
  float8 x, y, z, d, s, v;
  PSF_KEY_LANE(0)
  PSF_KEY_LANE(1)
  PSF_KEY_LANE(2)
  PSF_KEY_LANE(3)
  PSF_KEY_LANE(4)
  PSF_KEY_LANE(5)
  PSF_KEY_LANE(6)
  PSF_KEY_LANE(7)
  float8 r = vertex_radius8(p, d, s);
  int8 level = vertex_level8(r);
  float8 inv = 1.0f / cell_size8(level, p.cells27);
  int8 key_class = 2 * level + (p.ignore_visibility ? (int8)(0) : (v != 0.0f ? 1 : 0)); /* tag_key_class */
  uint8 key = cell_key8(key_class, cell_coord8(x, inv * cell_x_split(p.cells27)), cell_coord8(y, inv),
                        cell_coord8(z, inv), cell_key_layout(p.key_bits, p.cells27), p.key_bits);
  key = r == 0.0f ? (uint8)(1u << p.key_bits) : key;
  uint8 index = (uint8)(i0) + (uint8)(0u, 1u, 2u, 3u, 4u, 5u, 6u, 7u);
  if (i0 + PSF_GATHER_LANES - 1u <= last) {
    vstore8(key, 0, keys + i0);
    vstore8(index, 0, indices + i0);
    return;
  }
  uint kk[8];
  vstore8(key, 0, kk);
  for (uint k = 0u; i0 + k <= last; ++k) {
    keys[i0 + k] = kk[k];
    indices[i0 + k] = i0 + k;
  }
}
