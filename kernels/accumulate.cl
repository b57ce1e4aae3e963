/* accumulate.cl: each path's contribution to its pixel: the radiance gathered
 * before its filtering vertex plus alpha * c (Keller et al. 2016, Eq. 1), with c
 * the path's own (the unfiltered image, always) and, when the batch was
 * filtered, the filtered value c-bar as well; w carries the number of tuples
 * averaged (1 unfiltered), for the neighbour-count AOV. Both from one read of
 * the path's state: the unfiltered c comes from the state itself, so a plain
 * render needs no tuple store (tuples.cl store_tuples).
 *
 * The host adds the contributions to the pixels in increasing path index
 * (host/render.cpp, Accumulator), so the image depends neither on thread timing
 * (no float atomics) nor on the batch size or the devices that computed it.
 * Non-finite contributions are left out there and counted.
 *
 * accumulate_tuples: the same sums where trace_lanes stored the tuples itself
 * (PSF_LANES_STORE_TUPLES) instead of the states. */

__kernel void accumulate(uint count, uint filtered_too, __global const PathState* states,
                         __global const PathVertex* vertices, __global const float4* filtered,
                         __global const uint* counts, __global float4* out_unfiltered, __global float4* out) {
  uint j = get_global_id(0);
  if (j >= count) return;
  const float3 prefix = states[j].radiance.xyz;
  const bool vertex = (states[j].flags & PSF_PATH_VERTEX) != 0u;
  const float3 alpha = vertex ? vertices[j].alpha.xyz : (float3)(0.0f);
  float3 c = prefix;
  if (vertex) c += alpha * states[j].vertex_radiance.xyz;
  out_unfiltered[j] = (float4)(c, 1.0f);
  if (!filtered_too) return;
  float3 f = prefix;
  if (vertex) f += alpha * filtered[j].xyz;
  out[j] = (float4)(f, (float)counts[j]);
}

/* accumulate after trace_lanes stored tuples (PSF_LANES_STORE_TUPLES): the
 * radiance before the filtering vertex in inout_unfiltered (replaced by the
 * unfiltered contribution), c in values, zero where the path has no vertex
 * (as its vertex's alpha is). */
__kernel void accumulate_tuples(uint count, uint filtered_too, __global const PathVertex* vertices,
                                __global const float4* values, __global const float4* filtered,
                                __global const uint* counts, __global float4* inout_unfiltered,
                                __global float4* out) {
  uint j = get_global_id(0);
  if (j >= count) return;
  const float3 prefix = inout_unfiltered[j].xyz;
  const float3 alpha = vertices[j].alpha.xyz;
  inout_unfiltered[j] = (float4)(prefix + alpha * values[j].xyz, 1.0f);
  if (!filtered_too) return;
  out[j] = (float4)(prefix + alpha * filtered[j].xyz, (float)counts[j]);
}
