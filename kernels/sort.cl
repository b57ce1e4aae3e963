/* sort.cl: stable least-significant-digit radix sort of (key, value) pairs,
 * 4 bits a pass over only the bits the keys use (count, scan, scatter).
 *
 * Each of `items` work-items owns a contiguous chunk of the input: radix_count
 * counts its digits, radix_scan turns the digit-major table counts[d * items + t]
 * into exclusive offsets, radix_scatter moves its chunk in input order to those
 * offsets. Serial chunks make every pass stable without barriers, which suits
 * CPU devices (PoCL); the single-work-item scan is over 16 * items entries. */

#define PSF_RADIX_BITS 4u
#define PSF_RADIX_BINS 16u

__kernel void radix_count(__global const uint* keys, uint n, uint shift, uint items, uint chunk,
                          __global uint* counts) {
  uint t = get_global_id(0);
  if (t >= items) return;
  uint c[PSF_RADIX_BINS];
  for (uint d = 0u; d < PSF_RADIX_BINS; ++d) c[d] = 0u;
  uint begin = min(n, t * chunk), end = min(n, begin + chunk);
  for (uint i = begin; i < end; ++i) c[(keys[i] >> shift) & (PSF_RADIX_BINS - 1u)] += 1u;
  for (uint d = 0u; d < PSF_RADIX_BINS; ++d) counts[d * items + t] = c[d];
}

__kernel void radix_scan(__global uint* counts, uint total) {
  if (get_global_id(0) != 0) return;
  uint sum = 0u;
  for (uint i = 0u; i < total; ++i) {
    uint c = counts[i];
    counts[i] = sum;
    sum += c;
  }
}

__kernel void radix_scatter(__global const uint* keys_in, __global const uint* values_in, uint n, uint shift,
                            uint items, uint chunk, __global const uint* offsets, __global uint* keys_out,
                            __global uint* values_out) {
  uint t = get_global_id(0);
  if (t >= items) return;
  uint o[PSF_RADIX_BINS];
  for (uint d = 0u; d < PSF_RADIX_BINS; ++d) o[d] = offsets[d * items + t];
  uint begin = min(n, t * chunk), end = min(n, begin + chunk);
  for (uint i = begin; i < end; ++i) {
    uint k = keys_in[i];
    uint d = (k >> shift) & (PSF_RADIX_BINS - 1u);
    keys_out[o[d]] = k;
    values_out[o[d]] = values_in[i];
    o[d] += 1u;
  }
}
