/* filter_test.cl: a kernel exposing filter.cl's cell search to tests/test_filter.cpp.
 * Not used by the renderer. */

/* Work-item k: queries 8k .. 8k + 7 of the arrays (padded to a multiple of 8),
 * their cells and reach from filter_cells8 (vector) and from filter_cell, one by
 * one (scalar): (cx, cy, cz, reach) each. */
__kernel void filter_test_cells(__global const float* xs, __global const float* ys, __global const float* zs,
                                __global const float* rs, __global const int* tags, uint cells27,
                                __global int4* vector, __global int4* scalar) {
  const uint i = get_global_id(0) * 8u;
  int cx[8], cy[8], cz[8];
  uint reach[8];
  filter_cells8(xs, ys, zs, rs, tags, i, cells27, cx, cy, cz, reach);
  for (uint k = 0u; k < 8u; ++k) {
    vector[i + k] = (int4)(cx[k], cy[k], cz[k], as_int(reach[k]));
    uint r;
    const int3 c = filter_cell((float3)(xs[i + k], ys[i + k], zs[i + k]), rs[i + k], tags[i + k] >> 2, cells27, &r);
    scalar[i + k] = (int4)(c, as_int(r));
  }
}
