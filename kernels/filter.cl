/* filter.cl: the weighted average of path space filtering (Keller et al. 2016,
 * Eq. 1-2, Sec. 2.1-2.2):
 *
 *   c-bar_i = sum_j chi(|x_j - x_i| < r_i) w_ij c_j / sum_j chi(|x_j - x_i| < r_i) w_ij
 *
 * over the tuples j of the batch, with binary weights w_ij = 1 iff
 * <n_i, n_j> >= normal_cos, |albedo_i - albedo_j| <= albedo_tol (Euclidean, RGB),
 * equal light-sample visibility, and the same grid level (cell_keys.cl). The
 * centre tuple always counts, so the average is never empty; a non-finite c_j
 * of a neighbour is left out (the centre's own is kept and counted by accumulate).
 * Reads: tuples (positions, normals, albedos) and values in cell order, the cell ranges. Writes, in cell
 * order: c-bar_i and the number of tuples averaged; filter_max_count then finds
 * the batch's largest count.
 * Neighbour cells whose keys collide are visited once. */

#pragma OPENCL FP_CONTRACT OFF

/* Candidates are scanned PSF_FILTER_LANES at a time: their coordinates are read
 * as vectors from the sorted x, y, z arrays (padded by PSF_FILTER_LANES entries)
 * and tested against the ball at once; the few inside get the scalar tests. */
#define PSF_FILTER_LANES 8

inline void filter_candidate(uint i, uint j, int level, float4 ni, float4 ai, float normal_cos, float albedo_tol,
                             __global const float4* normals, __global const float4* albedos,
                             __global const float4* values, float3* sum, uint* n) {
  float4 nj = normals[j], aj = albedos[j];
  float3 da = aj.xyz - ai.xyz;
  bool similar = (int)aj.w == level && nj.x * ni.x + nj.y * ni.y + nj.z * ni.z >= normal_cos &&
                 da.x * da.x + da.y * da.y + da.z * da.z <= albedo_tol * albedo_tol && nj.w == ni.w;
  float3 cj = values[j].xyz;
  bool finite = isfinite(cj.x) && isfinite(cj.y) && isfinite(cj.z);
  if (j == i || (similar && finite)) { /* a NaN/Inf neighbour never spreads */
    *sum += cj;
    *n += 1u;
  }
}

__kernel void filter(FilterParams p, __global const float4* positions, __global const float* xs,
                     __global const float* ys, __global const float* zs, __global const float4* normals,
                     __global const float4* albedos, __global const float4* values, __global const uint2* ranges,
                     __global float4* filtered, __global uint* counts) {
  uint i = get_global_id(0);
  if (i >= p.count) return;
  float4 xi = positions[i];
  float r = xi.w;
  if (!(r > 0.0f)) { /* no filtering vertex */
    filtered[i] = values[i];
    counts[i] = 1u;
    return;
  }
  float4 ni = normals[i], ai = albedos[i];
  int level = (int)ai.w;
  float3 x = xi.xyz;
  float size = cell_size(level, p.cells27);
  int3 c = cell_of(x, size);
  /* The cells that can hold points within r: c, and along each axis the
   * neighbour across a face nearer to x than r (with a margin for rounding:
   * visiting a cell too many never changes the result). Cells of size >= r (27)
   * or >= 2r (8) make that at most 3 or 2 cells per axis. */
  float3 below = x - convert_float3(c) * size;        /* distance to the lower face */
  float3 above = convert_float3(c + (int3)(1)) * size - x;  /* to the upper face */
  float reach = r * 1.0001f;
  int3 lo = c - (int3)(below.x < reach ? 1 : 0, below.y < reach ? 1 : 0, below.z < reach ? 1 : 0);
  int3 hi = c + (int3)(above.x < reach ? 1 : 0, above.y < reach ? 1 : 0, above.z < reach ? 1 : 0);
  float r2 = r * r;
  float3 sum = (float3)(0.0f);
  uint n = 0u;
  uint seen[27];
  uint nseen = 0u;
  const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
  for (int cz = lo.z; cz <= hi.z; ++cz)
    for (int cy = lo.y; cy <= hi.y; ++cy)
      for (int cx = lo.x; cx <= hi.x; ++cx) {
        uint key = cell_key(level, (int3)(cx, cy, cz), p.key_bits);
        uint2 range = ranges[key];
        if (range.x >= range.y) continue;
        bool dup = false;
        for (uint s = 0u; s < nseen; ++s) dup = dup || seen[s] == key;
        if (dup) continue;
        seen[nseen++] = key;
        for (uint j = range.x; j < range.y; j += PSF_FILTER_LANES) {
          float8 dx = vload8(0, xs + j) - (float8)(x.x);
          float8 dy = vload8(0, ys + j) - (float8)(x.y);
          float8 dz = vload8(0, zs + j) - (float8)(x.z);
          int8 in = (dx * dx + dy * dy + dz * dz < (float8)(r2)) | ((int8)(j) + lane == (int8)(i));
          in &= ((int8)(j) + lane) < (int8)(range.y);
          /* The lanes inside as a bit mask, visited lowest first. */
          int8 bits = in & (int8)(1, 2, 4, 8, 16, 32, 64, 128);
          int4 b4 = bits.lo | bits.hi;
          int2 b2 = b4.lo | b4.hi;
          uint mask = (uint)(b2.x | b2.y);
          while (mask != 0u) {
            uint k = 31u - clz(mask & (0u - mask));
            mask &= mask - 1u;
            filter_candidate(i, j + k, level, ni, ai, p.normal_cos, p.albedo_tol, normals, albedos, values, &sum, &n);
          }
        }
      }
  if (n == 0u) { /* the centre lies in a cell it was not keyed to: cannot happen, but never divide by 0 */
    sum = values[i].xyz;
    n = 1u;
  }
  filtered[i] = (float4)(sum / (float)n, 0.0f);
  counts[i] = n;
}

/* The largest of counts[0, n) into *max_count (zero before the launch): each
 * work-item takes the largest of PSF_MAX_COUNT_CHUNK consecutive counts, then one
 * atomic_max. An atomic per tuple in the filter kernel contended for one cache
 * line across the cores: a tenth of that kernel's time on PoCL. */
__kernel void filter_max_count(uint n, __global const uint* counts, __global uint* max_count) {
  uint begin = get_global_id(0) * PSF_MAX_COUNT_CHUNK;
  if (begin >= n) return;
  uint end = min(n, begin + PSF_MAX_COUNT_CHUNK), m = 0u;
  for (uint i = begin; i < end; ++i) m = max(m, counts[i]);
  atomic_max(max_count, m);
}
