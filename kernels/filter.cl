/* filter.cl: the weighted average of path space filtering (Keller et al. 2016,
 * Eq. 1-2, Sec. 2.1-2.2):
 *
 *   c-bar_i = sum_j chi(|x_j - x_i| < r_i) w_ij c_j / sum_j chi(|x_j - x_i| < r_i) w_ij
 *
 * over the tuples j of the batch, with binary weights w_ij = 1 iff
 * <n_i, n_j> >= normal_cos, |albedo_i - albedo_j| <= albedo_tol (Euclidean, RGB),
 * equal light-sample visibility, and the same grid level (cell_keys.cl); with
 * FilterParams.demodulate the albedo fields hold log2 albedo and the values
 * c / albedo (tuples.cl), so the same test compares ratios. The
 * centre tuple always counts, so the average is never empty; a non-finite c_j
 * of a neighbour is left out (the centre's own is kept and counted by accumulate).
 * Reads: the tuples' fields and values in cell order (tuples.cl), the cells'
 * starts (cell_ranges.cl). Writes, in cell order: c-bar_i and the number of
 * tuples averaged; filter_max_count then finds the batch's largest count.
 * Neighbour cells whose keys collide are visited once. */

#pragma OPENCL FP_CONTRACT OFF

/* Candidates are tested PSF_FILTER_LANES at a time, without branches: each field
 * is read as a vector from its sorted array (padded past the batch's end), and
 * the lanes that pass the ball and similarity tests are added under a mask into
 * per-lane sums, combined in a fixed order at the end. (Testing the ball first
 * and the few candidates inside it one by one cost a mispredicted branch per
 * candidate; on CPUs that was most of this kernel's time.) The host picks the
 * variant by device kind (host/cl/runtime.cpp): CPUs 8 lanes, GPUs 2 lanes with
 * PSF_FILTER_SKIP. */
#ifndef PSF_FILTER_LANES
#define PSF_FILTER_LANES 8
#endif
#if PSF_SORTED_PAD < PSF_FILTER_LANES - 1
#error "PSF_SORTED_PAD: a cell's last vector of candidates reads up to PSF_FILTER_LANES - 1 past its end"
#endif
/* 1: skip the similarity tests of a vector with no candidate in the ball. A
 * mispredicted branch on CPUs (slower there); on GPUs it saves the loads. */
#ifndef PSF_FILTER_SKIP
#define PSF_FILTER_SKIP 0
#endif
/* filter_queries' modes: search the cells (filter); search and record each
 * query's neighbours (filter_record); average over the recorded lists, and
 * search where one overflowed (filter_lists). */
#define PSF_FILTER_SEARCH 0u
#define PSF_FILTER_WRITE_LISTS 1u
#define PSF_FILTER_READ_LISTS 2u
#define PSF_CAT_(a, b) a##b
#define PSF_CAT(a, b) PSF_CAT_(a, b)
#define floatL PSF_CAT(float, PSF_FILTER_LANES)
#define intL PSF_CAT(int, PSF_FILTER_LANES)
#define vloadL PSF_CAT(vload, PSF_FILTER_LANES)
#define convert_intL PSF_CAT(convert_int, PSF_FILTER_LANES)
#if PSF_FILTER_LANES == 2
#define PSF_FILTER_LANE_INDEX ((int2)(0, 1))
#elif PSF_FILTER_LANES == 4
#define PSF_FILTER_LANE_INDEX ((int4)(0, 1, 2, 3))
#elif PSF_FILTER_LANES == 8
#define PSF_FILTER_LANE_INDEX ((int8)(0, 1, 2, 3, 4, 5, 6, 7))
#elif PSF_FILTER_LANES == 16
#define PSF_FILTER_LANE_INDEX ((int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15))
#else
#error "PSF_FILTER_LANES must be 2, 4, 8 or 16"
#endif
/* Sums of the lanes, pairwise in a fixed order. */
inline float filter_sum2(float2 v) { return v.s0 + v.s1; }
inline float filter_sum4(float4 v) { return filter_sum2(v.lo) + filter_sum2(v.hi); }
inline float filter_sum8(float8 v) { return filter_sum4(v.lo) + filter_sum4(v.hi); }
inline float filter_sum16(float16 v) { return filter_sum8(v.lo) + filter_sum8(v.hi); }
inline int filter_isum2(int2 v) { return v.s0 + v.s1; }
inline int filter_isum4(int4 v) { return filter_isum2(v.lo) + filter_isum2(v.hi); }
inline int filter_isum8(int8 v) { return filter_isum4(v.lo) + filter_isum4(v.hi); }
inline int filter_isum16(int16 v) { return filter_isum8(v.lo) + filter_isum8(v.hi); }
#define filter_lane_sum PSF_CAT(filter_sum, PSF_FILTER_LANES)
#define filter_lane_isum PSF_CAT(filter_isum, PSF_FILTER_LANES)

/* Tests the candidates [range.x, range.y) against query i (the centre x, ni, ai,
 * tag, r2) PSF_FILTER_LANES at a time and adds those taken to sr, sg, sb and
 * taken. MEMBER: an intL expression of the candidates' index j, true for those
 * that count in this run (the cell-by-cell scans take only their cell's). */
#define PSF_FILTER_SCAN(range, MEMBER)                                                                            \
  for (uint j = (range).x; j < (range).y; j += PSF_FILTER_LANES) {                                                \
    intL idx = (intL)((int)j) + PSF_FILTER_LANE_INDEX;                                                             \
    floatL dx = vloadL(0, xs + j) - (floatL)(x.x);                                                                 \
    floatL dy = vloadL(0, ys + j) - (floatL)(x.y);                                                                 \
    floatL dz = vloadL(0, zs + j) - (floatL)(x.z);                                                                 \
    intL in = dx * dx + dy * dy + dz * dz < (floatL)(r2);                                                          \
    PSF_FILTER_SKIP_TEST                                                                                           \
    floatL dot = vloadL(0, nxs + j) * ni.x + vloadL(0, nys + j) * ni.y + vloadL(0, nzs + j) * ni.z;              \
    floatL dar = vloadL(0, ars + j) - (floatL)(ai.x);                                                              \
    floatL dag = vloadL(0, ags + j) - (floatL)(ai.y);                                                              \
    floatL dab = vloadL(0, abs_ + j) - (floatL)(ai.z);                                                             \
    intL similar = (vloadL(0, tags + j) == (intL)(tag)) & (dot >= (floatL)(p.normal_cos)) &                        \
                   (dar * dar + dag * dag + dab * dab <= (floatL)(tol2));                                          \
    floatL cr = vloadL(0, vr + j), cg = vloadL(0, vg + j), cb = vloadL(0, vb + j);                                 \
    intL take = (idx < (intL)((int)(range).y)) & ((idx == (intL)((int)i)) | (in & similar)) & (MEMBER);            \
    sr = select(sr, sr + cr, take); /* an add under the mask: the values' loads need not wait for it */            \
    sg = select(sg, sg + cg, take);                                                                                \
    sb = select(sb, sb + cb, take);                                                                                \
    taken -= take; /* take is -1 where true */                                                                     \
    if (mode == PSF_FILTER_WRITE_LISTS) { /* record (j - i, lanes taken) where any is; past the end: the sink */  \
      uint m = (uint)filter_lane_isum(take & ((intL)(1) << PSF_FILTER_LANE_INDEX));                                \
      int offset = (int)j - (int)i;                                                                                \
      list[1u + min(listed, PSF_FILTER_LIST)] = filter_record_of(offset, m);                                       \
      listed += m != 0u ? 1u : 0u;                                                                                 \
      far |= m != 0u && (offset < -PSF_FILTER_OFFSET_LIMIT || offset >= PSF_FILTER_OFFSET_LIMIT);                  \
    }                                                                                                              \
  }
/* A record's offset j - i, signed, in the bits above the lanes (a test gives it
 * fewer, to reach the limit with few tuples). */
#ifndef PSF_FILTER_OFFSET_BITS
#define PSF_FILTER_OFFSET_BITS (32 - PSF_FILTER_LANES)
#endif
#define PSF_FILTER_OFFSET_LIMIT (1 << (PSF_FILTER_OFFSET_BITS - 1))
inline uint filter_record_of(int offset, uint lanes) {
  return (((uint)offset & ((1u << PSF_FILTER_OFFSET_BITS) - 1u)) << PSF_FILTER_LANES) | lanes;
}
inline int filter_record_offset(uint record) {
  return (as_int(record) << (32 - PSF_FILTER_LANES - PSF_FILTER_OFFSET_BITS)) >> (32 - PSF_FILTER_OFFSET_BITS);
}
#if PSF_FILTER_SKIP
#define PSF_FILTER_SKIP_TEST \
  if (!any(in | (idx == (intL)((int)i)))) continue;
#else
#define PSF_FILTER_SKIP_TEST
#endif

/* A query's cell and the cells around it that the ball can reach (filter_queries):
 * its cell c, and along y and z the rows lo..hi of c - 1 .. c + 1, along x from
 * `left` cells below c to `right` above, packed into `reach` (lo_y | hi_y << 2 |
 * lo_z << 4 | hi_z << 6 | left << 8 | right << 20). With a margin for rounding:
 * visiting a cell too many never changes the result. The distances to the faces
 * are exact (c times a power of two, subtracted from a nearby x). */
#define PSF_FILTER_REACH_LEFT(v) (((v) >> 8) & 0xFFFu)
#define PSF_FILTER_REACH_RIGHT(v) ((v) >> 20)
inline uint filter_reach_of(int lo_y, int hi_y, int lo_z, int hi_z, int left, int right) {
  return (uint)lo_y | (uint)hi_y << 2 | (uint)lo_z << 4 | (uint)hi_z << 6 | (uint)clamp(left, 0, 0xFFF) << 8 |
         (uint)clamp(right, 0, 0xFFF) << 20;
}
inline int3 filter_cell(float3 x, float r, int level, uint cells27, uint* reach_out) {
  const float split = cell_x_split(cells27), size = cell_size(level, cells27), inv_x = 1.0f / size * split;
  const int3 c = cell_of(x, size, split);
  const float3 edge = (float3)(size / split, size, size);
  const float3 below = x - convert_float3(c) * edge;             /* distance to the lower face */
  const float3 above = convert_float3(c + (int3)(1)) * edge - x; /* to the upper face */
  const float reach = r * 1.0001f;
  *reach_out = filter_reach_of(below.y < reach ? 0 : 1, above.y < reach ? 2 : 1, below.z < reach ? 0 : 1,
                               above.z < reach ? 2 : 1,
                               below.x < reach ? convert_int(floor((reach - below.x) * inv_x)) + 1 : 0,
                               above.x < reach ? convert_int(floor((reach - above.x) * inv_x)) + 1 : 0);
  return c;
}
/* filter_cell of the eight queries i .. i + 7 at once (the arrays are padded
 * past the batch's end), the same arithmetic in 8-wide vectors: PoCL runs the
 * filter's work-items one by one, and the scalar floors and selects of each
 * query's own were a quarter of the kernel's time. */
inline void filter_cells8(__global const float* xs, __global const float* ys, __global const float* zs,
                          __global const float* rs, __global const int* tags, uint i, uint cells27, int* cx, int* cy,
                          int* cz, uint* reach_out) {
  const float8 x = vload8(0, xs + i), y = vload8(0, ys + i), z = vload8(0, zs + i);
  const int8 level = (vload8(0, tags + i) | 1) >> 2;
  const float split = cell_x_split(cells27);
  const float8 size = cell_size8(level, cells27), inv = 1.0f / size, inv_x = inv * split;
  const int8 c_x = cell_coord8(x, inv_x), c_y = cell_coord8(y, inv), c_z = cell_coord8(z, inv);
  const float8 edge_x = size / split;
  const float8 below_x = x - convert_float8(c_x) * edge_x, above_x = convert_float8(c_x + 1) * edge_x - x;
  const float8 below_y = y - convert_float8(c_y) * size, above_y = convert_float8(c_y + 1) * size - y;
  const float8 below_z = z - convert_float8(c_z) * size, above_z = convert_float8(c_z + 1) * size - z;
  const float8 reach = vload8(0, rs + i) * 1.0001f;
  const int8 left = select((int8)(0), convert_int8(floor((reach - below_x) * inv_x)) + 1, below_x < reach);
  const int8 right = select((int8)(0), convert_int8(floor((reach - above_x) * inv_x)) + 1, above_x < reach);
  const uint8 packed = as_uint8(select((int8)(1), (int8)(0), below_y < reach)) |
                       as_uint8(select((int8)(1), (int8)(2), above_y < reach)) << 2 |
                       as_uint8(select((int8)(1), (int8)(0), below_z < reach)) << 4 |
                       as_uint8(select((int8)(1), (int8)(2), above_z < reach)) << 6 |
                       as_uint8(clamp(left, (int8)(0), (int8)(0xFFF))) << 8 |
                       as_uint8(clamp(right, (int8)(0), (int8)(0xFFF))) << 20;
  vstore8(c_x, 0, cx);
  vstore8(c_y, 0, cy);
  vstore8(c_z, 0, cz);
  vstore8(packed, 0, reach_out);
}

/* sorted: the PSF_SORTED_* fields of the tuples in cell order, `stride` floats
 * apart; values and filtered: r, g, b arrays `stride` apart; starts: where each
 * key's tuples start in cell order (2^key_bits + 1 entries). queries: the
 * consecutive tuples (in cell order) each work-item averages, 1 (GPUs) or
 * PSF_FILTER_QUERIES (CPUs); consecutive tuples mostly share a row of cells, and a
 * work-item keeps the last one's key parts for the next. */
PSF_FORCE_INLINE void filter_queries(FilterParams p, uint stride, uint queries,
                                                          __global const uint* valid, __global const float* sorted,
                                                          __global const float* values,
                                                          __global const uint* starts, __global float* filtered,
                                                          __global uint* counts, const uint mode,
                                                          __global uint* lists) {
  const uint nvalid = *valid; /* tuples with a vertex come first in cell order (cell_ranges.cl) */
  const uint i0 = get_global_id(0) * queries;
  if (i0 >= nvalid) return;
  const uint i1 = min(nvalid, i0 + queries);
  __global const float* xs = sorted + PSF_SORTED_X * stride;
  __global const float* ys = sorted + PSF_SORTED_Y * stride;
  __global const float* zs = sorted + PSF_SORTED_Z * stride;
  __global const float* nxs = sorted + PSF_SORTED_NX * stride;
  __global const float* nys = sorted + PSF_SORTED_NY * stride;
  __global const float* nzs = sorted + PSF_SORTED_NZ * stride;
  __global const float* ars = sorted + PSF_SORTED_AR * stride;
  __global const float* ags = sorted + PSF_SORTED_AG * stride;
  __global const float* abs_ = sorted + PSF_SORTED_AB * stride;
  __global const int* tags = (__global const int*)(sorted + PSF_SORTED_TAG * stride); /* an int field */
  __global const float* vr = values;
  __global const float* vg = values + stride;
  __global const float* vb = values + 2 * stride;
  const uint layout = cell_key_layout(p.key_bits, p.cells27);
  const float split = cell_x_split(p.cells27); /* cells are this many times narrower along x */
  const float tol2 = p.albedo_tol * p.albedo_tol;
  const uint cells = 1u << p.key_bits; /* keys: [0, cells) */
  /* The cached row: the y and z coordinates and class of the last query's cell,
   * and the keys' parts of the coordinates -1, 0, +1 around them (cell_keys.cl). */
  int cy = 0, cz = 0, cclass = 0;
  bool cached = false;
  uint my[3], mz[3], by[3], bz[3];
#if PSF_FILTER_LANES >= 8
  /* The work-item's queries' cells, eight at a time, where they fit the arrays
   * (the CPU variant); not in the later passes, where most queries replay their lists. */
  int q_cx[PSF_FILTER_QUERIES], q_cy[PSF_FILTER_QUERIES], q_cz[PSF_FILTER_QUERIES];
  uint q_reach[PSF_FILTER_QUERIES];
  const bool vector_cells = mode != PSF_FILTER_READ_LISTS && queries <= PSF_FILTER_QUERIES && queries % 8u == 0u;
  if (vector_cells)
    for (uint k = 0u; k < i1 - i0; k += 8u)
      filter_cells8(xs, ys, zs, sorted + PSF_SORTED_R * stride, tags, i0 + k, p.cells27, q_cx + k, q_cy + k, q_cz + k,
                    q_reach + k);
#endif
  for (uint i = i0; i < i1; ++i) {
    __global uint* list = mode == PSF_FILTER_SEARCH ? lists : lists + (size_t)i * PSF_FILTER_LIST_WORDS;
    if (mode == PSF_FILTER_READ_LISTS && list[0] <= PSF_FILTER_LIST) {
      /* The vectors of candidates the first pass took any from, with the lanes
       * it took (the ball, the weights and the finiteness tags do not change
       * between passes): the same sums, lane by lane in the same order, as a
       * search (the vectors it took none from only added zeros). */
      const uint records = list[0];
      floatL sr = (floatL)(0.0f), sg = (floatL)(0.0f), sb = (floatL)(0.0f);
      for (uint k = 1u; k <= records; ++k) {
        const uint e = list[k];
        const uint j = (uint)((int)i + filter_record_offset(e));
        const intL take = -(((intL)(as_int(e)) >> PSF_FILTER_LANE_INDEX) & (intL)(1));
        sr = select(sr, sr + vloadL(0, vr + j), take);
        sg = select(sg, sg + vloadL(0, vg + j), take);
        sb = select(sb, sb + vloadL(0, vb + j), take);
      }
      const float3 mean =
          (float3)(filter_lane_sum(sr), filter_lane_sum(sg), filter_lane_sum(sb)) / (float)counts[i];
      filtered[i] = mean.x;
      filtered[stride + i] = mean.y;
      filtered[2 * stride + i] = mean.z;
      continue;
    }
    uint listed = 0u;
    bool far = false; /* a record's offset does not fit: the later passes search again */
    float r = sorted[PSF_SORTED_R * stride + i];
    float3 x = (float3)(xs[i], ys[i], zs[i]);
    float3 ni = (float3)(nxs[i], nys[i], nzs[i]);
    float3 ai = (float3)(ars[i], ags[i], abs_[i]);
    /* tag = 4 level + 2 visibility + finite: a neighbour must match the centre's
     * level and visibility and have a finite c_j (a NaN/Inf never spreads; the
     * centre's own always counts). Finiteness is that of the values gathered:
     * later iterations' averages are finite wherever those were (barring a sum
     * that overflows). */
    int tag = tags[i] | 1;
    int level = tag >> 2;
    float inv = 1.0f / cell_size(level, p.cells27), inv_x = inv * split;
    /* The cells that can hold points within r (filter_cell). Along y and z: c,
     * and the neighbour across a face nearer to x than r (cells of size >= r (27)
     * or >= 2r (8) make that at most 3 or 2), as offsets lo_*, hi_* from c - 1.
     * Along x, where cells are `split` times narrower (with cells of 2r): from
     * `left` cells below c to `right` above, as many as the ball reaches. */
    int3 c;
    uint reach;
#if PSF_FILTER_LANES >= 8
    if (vector_cells) {
      c = (int3)(q_cx[i - i0], q_cy[i - i0], q_cz[i - i0]);
      reach = q_reach[i - i0];
    } else
#endif
      c = filter_cell(x, r, level, p.cells27, &reach);
    const int lo_y = reach & 3u, hi_y = (reach >> 2) & 3u, lo_z = (reach >> 4) & 3u, hi_z = (reach >> 6) & 3u;
    const int left = PSF_FILTER_REACH_LEFT(reach), right = PSF_FILTER_REACH_RIGHT(reach);
    int key_class = tag_key_class(tag);
    if (!cached || c.y != cy || c.z != cz || key_class != cclass) {
      cached = true;
      cy = c.y;
      cz = c.z;
      cclass = key_class;
      for (int k = 0; k < 3; ++k) {
        my[k] = cell_morton_part(c.y - 1 + k, 1u, layout);
        mz[k] = cell_morton_part(c.z - 1 + k, 2u, layout);
        by[k] = cell_block_part(c.y - 1 + k, 1u, layout);
        bz[k] = cell_block_part(c.z - 1 + k, 2u, layout) ^ cell_class_part(key_class);
      }
    }
    const uint mx_lo = cell_morton_part(c.x - left, 0u, layout);
    const uint bx_lo = cell_block_part(c.x - left, 0u, layout);
    float r2 = r * r;
    floatL sr = (floatL)(0.0f), sg = (floatL)(0.0f), sb = (floatL)(0.0f);
    intL taken = (intL)(0);
    /* Cells of one block have distinct keys where a key has at least 2 bits per
     * axis, and the cells of a row along x have consecutive keys (cell_keys.cl):
     * each row's tuples are one run in cell order, from its first cell's start to
     * its last one's end. A query whose cells span two blocks (whose keys another
     * of its cells may share) visits them cell by cell instead, and takes from
     * each only the tuples that lie in it, so that none counts twice. */
    const bool one_block = cell_layout_per_axis(layout) >= 2u &&
                           bx_lo == cell_block_part(c.x + right, 0u, layout) && by[lo_y] == by[hi_y] &&
                           bz[lo_z] == bz[hi_z];
    if (one_block) {
      /* A row's keys, key .. end - 1, wrap around the table's end at most
       * once: two runs. On CPUs (8 lanes) the rows' runs are read first, then
       * scanned, so that the table's loads need not wait behind a scan (the
       * filter kernel 0.92 of its time); GPUs keep each row's run beside its
       * scan rather than an indexed array of 18 per work-item. */
#if PSF_FILTER_LANES >= 8
      uint2 runs[18];
      uint nruns = 0u;
#endif
      for (int kz = lo_z; kz <= hi_z; ++kz)
        for (int ky = lo_y; ky <= hi_y; ++ky) {
          uint key = cell_key_of_parts(mx_lo | my[ky] | mz[kz], bx_lo ^ by[ky] ^ bz[kz], p.key_bits);
          uint end = key + (uint)(left + right) + 1u;
          uint wrap = end > cells ? end - cells : 0u;
#if PSF_FILTER_LANES >= 8
          runs[nruns++] = (uint2)(starts[key], starts[end - wrap]);
          if (wrap > 0u) runs[nruns++] = (uint2)(starts[0], starts[wrap]);
        }
      for (uint k = 0u; k < nruns; ++k) {
        const uint2 range = runs[k];
        PSF_FILTER_SCAN(range, (intL)(-1))
      }
#else
          uint2 range = (uint2)(starts[key], starts[end - wrap]);
          for (int part = 0; part < (wrap > 0u ? 2 : 1); ++part) {
            PSF_FILTER_SCAN(range, (intL)(-1))
            range = (uint2)(starts[0], starts[wrap]);
          }
        }
#endif
    }
    /* Else cell by cell, taking from each only the tuples inside it. */
    for (int kz = lo_z; kz <= hi_z && !one_block; ++kz)
      for (int ky = lo_y; ky <= hi_y; ++ky)
        for (int kx = -left; kx <= right; ++kx) {
          uint key = cell_key_of_parts(cell_morton_part(c.x + kx, 0u, layout) | my[ky] | mz[kz],
                                       cell_block_part(c.x + kx, 0u, layout) ^ by[ky] ^ bz[kz], p.key_bits);
          uint2 range = (uint2)(starts[key], starts[key + 1u]);
          PSF_FILTER_SCAN(range, (convert_intL(floor(vloadL(0, xs + j) * inv_x)) == (intL)(c.x + kx)) &
                                     (convert_intL(floor(vloadL(0, ys + j) * inv)) == (intL)(c.y - 1 + ky)) &
                                     (convert_intL(floor(vloadL(0, zs + j) * inv)) == (intL)(c.z - 1 + kz)))
        }
    uint n = (uint)filter_lane_isum(taken);
    float3 sum = (float3)(filter_lane_sum(sr), filter_lane_sum(sg), filter_lane_sum(sb));
    if (n == 0u) { /* the centre lies in a cell it was not keyed to: cannot happen, but never divide by 0 */
      sum = (float3)(vr[i], vg[i], vb[i]);
      n = 1u;
      listed = PSF_FILTER_LIST + 1u; /* the later passes search again */
    }
    if (mode == PSF_FILTER_WRITE_LISTS) list[0] = far ? PSF_FILTER_LIST + 1u : listed;
    float3 mean = sum / (float)n;
    filtered[i] = mean.x;
    filtered[stride + i] = mean.y;
    filtered[2 * stride + i] = mean.z;
    counts[i] = n;
  }
}

/* One pass of the average (mode PSF_FILTER_SEARCH; the only pass), the first of
 * several (filter_record: also records, for each query, a list of
 * PSF_FILTER_LIST_WORDS uints in lists: the number of vectors of candidates it
 * took any from, then for each the offset of its first index from the query's
 * and the lanes taken), or a later one (filter_lists: sums those vectors' lanes
 * again, bit for bit the search's sums, and searches again where the records
 * overflowed). One body, specialised by the constant mode. */
__kernel void filter(FilterParams p, uint stride, uint queries, __global const uint* valid,
                     __global const float* sorted, __global const float* values, __global const uint* starts,
                     __global float* filtered, __global uint* counts) {
  filter_queries(p, stride, queries, valid, sorted, values, starts, filtered, counts, PSF_FILTER_SEARCH, 0);
}

__kernel void filter_record(FilterParams p, uint stride, uint queries, __global const uint* valid,
                            __global const float* sorted, __global const float* values,
                            __global const uint* starts, __global float* filtered, __global uint* counts,
                            __global uint* lists) {
  filter_queries(p, stride, queries, valid, sorted, values, starts, filtered, counts, PSF_FILTER_WRITE_LISTS,
                 lists);
}

__kernel void filter_lists(FilterParams p, uint stride, uint queries, __global const uint* valid,
                           __global const float* sorted, __global const float* values, __global const uint* starts,
                           __global float* filtered, __global uint* counts, __global uint* lists) {
  filter_queries(p, stride, queries, valid, sorted, values, starts, filtered, counts, PSF_FILTER_READ_LISTS, lists);
}

/* The largest count of the n tuples into *max_count (zero before the launch):
 * counts[0, *valid), and 1 for each tuple without a vertex. Each
 * work-item takes the largest of PSF_MAX_COUNT_CHUNK consecutive counts, then one
 * atomic_max. An atomic per tuple in the filter kernel contended for one cache
 * line across the cores: a tenth of that kernel's time on PoCL. */
__kernel void filter_max_count(uint n, __global const uint* valid, __global const uint* counts,
                               __global uint* max_count) {
  uint begin = get_global_id(0) * PSF_MAX_COUNT_CHUNK;
  if (begin >= n) return;
  uint end = min(n, begin + PSF_MAX_COUNT_CHUNK), v = min(end, *valid), m = v < end ? 1u : 0u;
  for (uint i = begin; i < v; ++i) m = max(m, counts[i]);
  atomic_max(max_count, m);
}
