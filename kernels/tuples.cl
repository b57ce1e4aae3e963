/* tuples.cl: the tuple store between path tracing and filtering.
 *
 * store_tuples: c_i of every path (the radiance scattered at its filtering vertex
 * towards the camera, relative to alpha_i) into a compact array in path order.
 * gather_tuples: tuples and values in sorted (cell) order, so the filter reads
 * neighbours from contiguous memory, each field as its own array (PSF_SORTED_*
 * fields of `stride` floats; values: r, g, b arrays), which filter.cl reads
 * PSF_FILTER_LANES candidates at a time. Only the tuples with a filtering vertex
 * (the first *valid of the sorted order) are gathered and filtered. scatter_values:
 * filtered values and neighbour counts back to path order, the others' own values
 * with a count of 1. With FilterParams.demodulate the values gathered are c_j /
 * albedo_j and the albedo fields log2 albedo_j (filter.cl then compares albedos
 * as ratios), and scatter_values multiplies each mean by its vertex's albedo. */

__kernel void store_tuples(uint count, __global const PathState* states, __global float4* values) {
  uint i = get_global_id(0);
  if (i >= count) return;
  values[i] = (float4)(states[i].vertex_radiance.xyz, 0.0f);
}

/* The albedo a demodulated tuple's value is divided by, and multiplied by again
 * after averaging (scatter_values): each channel at least PSF_DEMODULATE_MIN. */
inline float3 demodulation_albedo(float4 a) { return fmax(a.xyz, (float3)(PSF_DEMODULATE_MIN)); }

/* FilterParams.demodulate: c_j / albedo_j is averaged, and albedos are compared
 * as log2 ratios (the albedo fields hold log2 of each channel). */
inline void demodulate_tuple(float4* a, float4* c) {
  float3 m = demodulation_albedo(*a);
  (*c).xyz = (*c).xyz / m;
  (*a).xyz = log2(m);
}

/* On CPUs (lanes == PSF_GATHER_LANES) each work-item gathers that many consecutive
 * tuples of the sorted order and stores each field as one vector: one scalar
 * store per field and tuple filled the store buffer and stalled the random reads
 * behind it. On GPUs (lanes == 1) each work-item gathers one. Lanes past
 * the valid tuples repeat the last one into the slots after it (those of tuples
 * without a vertex, or the arrays' padding, PSF_SORTED_PAD), which the filter
 * reads only in masked lanes. The tag gains a bit for a finite c_j (filter.cl). */
#if PSF_GATHER_LANES != 8
#error "gather_tuples is written for PSF_GATHER_LANES == 8"
#endif
#define PSF_GATHER_LANE(k)                                                               \
  {                                                                                      \
    uint j = order[min(i0 + k##u, last)];                                                \
    float4 xj = vertices[j].position, nj = vertices[j].normal, aj = vertices[j].albedo; \
    float rj = vertex_radius(p, xj.w, aj.w);                                             \
    float4 cj = values[j];                                                               \
    if (p.demodulate) demodulate_tuple(&aj, &cj);                                        \
    int finite = isfinite(cj.x) && isfinite(cj.y) && isfinite(cj.z) ? 1 : 0;             \
    x.s##k = xj.x;                                                                       \
    y.s##k = xj.y;                                                                       \
    z.s##k = xj.z;                                                                       \
    nx.s##k = nj.x;                                                                      \
    ny.s##k = nj.y;                                                                      \
    nz.s##k = nj.z;                                                                      \
    ar.s##k = aj.x;                                                                      \
    ag.s##k = aj.y;                                                                      \
    ab.s##k = aj.z;                                                                      \
    r.s##k = rj;                                                                         \
    tag.s##k = vertex_tag(p, rj, nj) | finite;                                           \
    cr.s##k = cj.x;                                                                      \
    cg.s##k = cj.y;                                                                      \
    cb.s##k = cj.z;                                                                      \
  }

__kernel void gather_tuples(FilterParams p, uint stride, uint lanes, __global const uint* order,
                            __global const PathVertex* vertices, __global const float4* values, __global const uint* valid, __global float* sorted,
                            __global float* sorted_values) {
  uint v = *valid;
  __global int* sorted_tags = (__global int*)(sorted + PSF_SORTED_TAG * stride); /* an int field */
  if (lanes == 1u) { /* one tuple per work-item (GPUs: neighbouring work-items' stores coalesce) */
    uint i = get_global_id(0);
    if (i >= v) return;
    uint j = order[i];
    float4 xj = vertices[j].position, nj = vertices[j].normal, aj = vertices[j].albedo;
    float rj = vertex_radius(p, xj.w, aj.w);
    float4 cj = values[j];
    if (p.demodulate) demodulate_tuple(&aj, &cj); /* before the finiteness: c / 0.01 may overflow */
    int finite = isfinite(cj.x) && isfinite(cj.y) && isfinite(cj.z) ? 1 : 0;
    sorted[PSF_SORTED_X * stride + i] = xj.x;
    sorted[PSF_SORTED_Y * stride + i] = xj.y;
    sorted[PSF_SORTED_Z * stride + i] = xj.z;
    sorted[PSF_SORTED_NX * stride + i] = nj.x;
    sorted[PSF_SORTED_NY * stride + i] = nj.y;
    sorted[PSF_SORTED_NZ * stride + i] = nj.z;
    sorted[PSF_SORTED_AR * stride + i] = aj.x;
    sorted[PSF_SORTED_AG * stride + i] = aj.y;
    sorted[PSF_SORTED_AB * stride + i] = aj.z;
    sorted_tags[i] = vertex_tag(p, rj, nj) | finite;
    sorted[PSF_SORTED_R * stride + i] = rj;
    sorted_values[i] = cj.x;
    sorted_values[stride + i] = cj.y;
    sorted_values[2 * stride + i] = cj.z;
    return;
  }
  uint i0 = get_global_id(0) * PSF_GATHER_LANES;
  if (i0 >= v) return; /* tuples without a vertex are not filtered (scatter_values) */
  uint last = v - 1u;
  if (PSF_PREFETCH) /* the vertices and values of the tuples PSF_PREFETCH_AHEAD on (program.cl) */
    for (uint k = 0u; k < PSF_GATHER_LANES; ++k) {
      uint a = i0 + PSF_PREFETCH_AHEAD + k;
      if (a < v) {
        uint j = order[a];
        psf_prefetch(vertices + j);
        psf_prefetch(values + j);
      }
    }
  float8 x, y, z, nx, ny, nz, ar, ag, ab, r, cr, cg, cb;
  int8 tag;
  PSF_GATHER_LANE(0)
  PSF_GATHER_LANE(1)
  PSF_GATHER_LANE(2)
  PSF_GATHER_LANE(3)
  PSF_GATHER_LANE(4)
  PSF_GATHER_LANE(5)
  PSF_GATHER_LANE(6)
  PSF_GATHER_LANE(7)
  vstore8(x, 0, sorted + PSF_SORTED_X * stride + i0);
  vstore8(y, 0, sorted + PSF_SORTED_Y * stride + i0);
  vstore8(z, 0, sorted + PSF_SORTED_Z * stride + i0);
  vstore8(nx, 0, sorted + PSF_SORTED_NX * stride + i0);
  vstore8(ny, 0, sorted + PSF_SORTED_NY * stride + i0);
  vstore8(nz, 0, sorted + PSF_SORTED_NZ * stride + i0);
  vstore8(ar, 0, sorted + PSF_SORTED_AR * stride + i0);
  vstore8(ag, 0, sorted + PSF_SORTED_AG * stride + i0);
  vstore8(ab, 0, sorted + PSF_SORTED_AB * stride + i0);
  vstore8(tag, 0, sorted_tags + i0);
  vstore8(r, 0, sorted + PSF_SORTED_R * stride + i0);
  vstore8(cr, 0, sorted_values + i0);
  vstore8(cg, 0, sorted_values + stride + i0);
  vstore8(cb, 0, sorted_values + 2 * stride + i0);
}

__kernel void scatter_values(uint count, uint stride, uint demodulate, __global const uint* order,
                             __global const uint* valid, __global const PathVertex* vertices,
                             __global const float* sorted_values, __global const uint* sorted_counts,
                             __global const float4* unfiltered, __global float4* values, __global uint* counts) {
  uint i = get_global_id(0);
  if (i >= count) return;
  if (PSF_PREFETCH && i + PSF_PREFETCH_AHEAD < count) { /* the lines the path 16 on writes (program.cl) */
    uint a = order[i + PSF_PREFETCH_AHEAD];
    psf_prefetch_write(values + a);
    psf_prefetch_write(counts + a);
  }
  uint j = order[i];
  if (i >= *valid) { /* no filtering vertex: its own value */
    values[j] = unfiltered[j];
    counts[j] = 1u;
    return;
  }
  float3 mean = (float3)(sorted_values[i], sorted_values[stride + i], sorted_values[2 * stride + i]);
  if (demodulate) mean *= demodulation_albedo(vertices[j].albedo);
  values[j] = (float4)(mean, 0.0f);
  counts[j] = sorted_counts[i];
}
