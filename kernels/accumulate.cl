/* accumulate.cl: adds each path's radiance to its pixel: the radiance gathered
 * before its filtering vertex plus alpha * c (Keller et al. 2016, Eq. 1), with c
 * the path's own (unfiltered) or the filtered value. The w channel sums the
 * number of tuples averaged (1 unfiltered), for the neighbour-count AOV.
 *
 * One work-item per pixel sums the batch's paths of that pixel in increasing
 * path index, so the image never depends on thread timing (no float atomics).
 * Path j of the batch belongs to pixel (first_path + j) mod (width * height).
 * Non-finite radiance never reaches the image: it is counted per pixel instead. */

__kernel void accumulate(FrameParams params, __global const PathState* states,
                         __global const PathVertex* vertices, __global const float4* values,
                         __global const uint* counts, __global float4* image, __global uint* nonfinite) {
  uint p = get_global_id(0);
  uint pixels = params.width * params.height;
  if (p >= pixels) return;
  ulong first = ((ulong)params.first_path_hi << 32) | (ulong)params.first_path_lo;
  uint j = (uint)(((ulong)p + (ulong)pixels - first % (ulong)pixels) % (ulong)pixels);
  float4 sum = image[p];
  uint bad = 0u;
  for (; j < params.batch_size; j += pixels) {
    PathState st = states[j];
    float3 c = st.radiance.xyz;
    if (st.flags & PSF_PATH_VERTEX) c += vertices[j].alpha.xyz * values[j].xyz;
    if (isfinite(c.x) && isfinite(c.y) && isfinite(c.z)) sum.xyz += c;
    else bad += 1u;
    sum.w += (float)counts[j];
  }
  image[p] = sum;
  if (bad) nonfinite[p] += bad;
}
