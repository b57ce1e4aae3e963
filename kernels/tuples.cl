/* tuples.cl: the tuple store between path tracing and filtering.
 *
 * store_tuples: c_i of every path (the radiance scattered at its filtering vertex
 * towards the camera, relative to alpha_i) into a compact array in path order.
 * gather_tuples: tuples and values in sorted (cell) order, so the filter reads
 * neighbours from contiguous memory; positions apart from the other fields, as
 * most candidates are rejected by their distance alone (x, y, z also as separate
 * arrays, which filter.cl reads eight candidates at a time). scatter_values: filtered values and
 * neighbour counts back to path order. */

__kernel void store_tuples(uint count, __global const PathState* states, __global float4* values) {
  uint i = get_global_id(0);
  if (i >= count) return;
  values[i] = (float4)(states[i].vertex_radiance.xyz, 0.0f);
}

__kernel void gather_tuples(uint count, __global const uint* order, __global const FilterTuple* tuples,
                            __global const float4* values, __global float4* sorted_position,
                            __global float* sorted_x, __global float* sorted_y, __global float* sorted_z,
                            __global float4* sorted_normal, __global float4* sorted_albedo,
                            __global float4* sorted_values) {
  uint i = get_global_id(0);
  if (i >= count) return;
  uint j = order[i];
  FilterTuple t = tuples[j];
  sorted_position[i] = t.position;
  sorted_x[i] = t.position.x;
  sorted_y[i] = t.position.y;
  sorted_z[i] = t.position.z;
  sorted_normal[i] = t.normal;
  sorted_albedo[i] = t.albedo;
  sorted_values[i] = values[j];
}

__kernel void scatter_values(uint count, __global const uint* order, __global const float4* sorted_values,
                             __global const uint* sorted_counts, __global float4* values, __global uint* counts) {
  uint i = get_global_id(0);
  if (i >= count) return;
  uint j = order[i];
  values[j] = sorted_values[i];
  counts[j] = sorted_counts[i];
}
