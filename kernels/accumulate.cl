/* accumulate.cl: each path's contribution to its pixel: the radiance gathered
 * before its filtering vertex plus alpha * c (Keller et al. 2016, Eq. 1), with c
 * the path's own (unfiltered) or the filtered value; w carries the number of
 * tuples averaged (1 unfiltered), for the neighbour-count AOV.
 *
 * The host adds the contributions to the pixels in increasing path index
 * (host/render.cpp, Accumulator), so the image depends neither on thread timing
 * (no float atomics) nor on the batch size or the devices that computed it.
 * Non-finite contributions are left out there and counted. */

__kernel void accumulate(uint count, __global const PathState* states, __global const PathVertex* vertices,
                         __global const float4* values, __global const uint* counts, __global float4* out) {
  uint j = get_global_id(0);
  if (j >= count) return;
  PathState st = states[j];
  float3 c = st.radiance.xyz;
  if (st.flags & PSF_PATH_VERTEX) c += vertices[j].alpha.xyz * values[j].xyz;
  out[j] = (float4)(c, (float)counts[j]);
}
