/* sort.cl: stable least-significant-digit radix sort of (key, value) pairs,
 * 4 or 8 bits a pass over only the bits the keys use (count, scan, scatter).
 *
 * Each of `items` work-items owns a contiguous chunk of the input: radix_count
 * counts its digits, radix_scan_blocks and radix_scan_add turn the digit-major
 * table counts[d * items + t] into exclusive offsets, radix_scatter moves its
 * chunk in input order to those offsets. Serial chunks make every pass stable
 * without barriers. The host picks the digit and the chunk by device kind
 * (host/filter.cpp): on CPU devices (PoCL), where a work-item is a loop, 8-bit
 * digits (half the passes of 4) over chunks of thousands of pairs; on GPUs 4-bit
 * digits, whose 16 counters stay in registers, over 16 pairs per work-item, where
 * the table of 16 * items counts is then as long as the input and the scan must
 * be parallel. The digit of a pass is (key >> shift) & mask: the last pass masks
 * off the bits above those being sorted. */

inline void radix_count_chunk(__global const uint* keys, uint n, uint shift, uint mask, uint items, uint chunk,
                              __global uint* counts, uint* c, uint bins) {
  uint t = get_global_id(0);
  if (t >= items) return;
  for (uint d = 0u; d < bins; ++d) c[d] = 0u;
  uint begin = min(n, t * chunk), end = min(n, begin + chunk);
  for (uint i = begin; i < end; ++i) c[(keys[i] >> shift) & mask] += 1u;
  for (uint d = 0u; d < bins; ++d) counts[d * items + t] = c[d];
}

__kernel void radix_count4(__global const uint* keys, uint n, uint shift, uint mask, uint items, uint chunk,
                           __global uint* counts) {
  uint c[16];
  radix_count_chunk(keys, n, shift, mask, items, chunk, counts, c, 16u);
}

__kernel void radix_count8(__global const uint* keys, uint n, uint shift, uint mask, uint items, uint chunk,
                           __global uint* counts) {
  uint c[256];
  radix_count_chunk(keys, n, shift, mask, items, chunk, counts, c, 256u);
}

#define PSF_SCAN_PER_ITEM (PSF_SCAN_BLOCK / PSF_SCAN_LOCAL)

/* Exclusive scan of each block of PSF_SCAN_BLOCK entries of data[0, total), in
 * place, by one work-group of PSF_SCAN_LOCAL; the block's sum goes to
 * sums[group]. Scanning `sums` the same way and adding it back (radix_scan_add)
 * gives the scan of the whole array. The offsets let the levels share a buffer. */
__kernel __attribute__((reqd_work_group_size(PSF_SCAN_LOCAL, 1, 1))) void radix_scan_blocks(
    __global uint* data, uint data_offset, uint total, __global uint* sums, uint sums_offset) {
  __local uint part[PSF_SCAN_LOCAL];
  data += data_offset;
  sums += sums_offset;
  uint l = get_local_id(0), g = get_group_id(0);
  uint base = g * PSF_SCAN_BLOCK + l * PSF_SCAN_PER_ITEM;
  uint v[PSF_SCAN_PER_ITEM];
  uint own = 0u;
  for (uint k = 0u; k < PSF_SCAN_PER_ITEM; ++k) {
    v[k] = base + k < total ? data[base + k] : 0u;
    own += v[k];
  }
  part[l] = own;
  barrier(CLK_LOCAL_MEM_FENCE);
  for (uint off = 1u; off < PSF_SCAN_LOCAL; off <<= 1) {  // inclusive scan of the work-items' sums
    uint add = l >= off ? part[l - off] : 0u;
    barrier(CLK_LOCAL_MEM_FENCE);
    part[l] += add;
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  uint run = part[l] - own;
  for (uint k = 0u; k < PSF_SCAN_PER_ITEM; ++k) {
    if (base + k < total) data[base + k] = run;
    run += v[k];
  }
  if (l == PSF_SCAN_LOCAL - 1u) sums[g] = part[l];
}

/* data[i] += offsets[i / PSF_SCAN_BLOCK]: the scanned block sums, added back. */
__kernel void radix_scan_add(__global uint* data, uint data_offset, uint total, __global const uint* offsets,
                             uint offsets_offset) {
  uint i = get_global_id(0);
  if (i >= total) return;
  data[data_offset + i] += offsets[offsets_offset + i / PSF_SCAN_BLOCK];
}

inline void radix_scatter_chunk(__global const uint* keys_in, __global const uint* values_in, uint n, uint shift,
                                uint mask, uint items, uint chunk, __global const uint* offsets,
                                __global uint* keys_out, __global uint* values_out, uint* o, uint bins) {
  uint t = get_global_id(0);
  if (t >= items) return;
  for (uint d = 0u; d < bins; ++d) o[d] = offsets[d * items + t];
  uint begin = min(n, t * chunk), end = min(n, begin + chunk);
  for (uint i = begin; i < end; ++i) {
    uint k = keys_in[i];
    uint d = (k >> shift) & mask;
    keys_out[o[d]] = k;
    values_out[o[d]] = values_in[i];
    o[d] += 1u;
  }
}

__kernel void radix_scatter4(__global const uint* keys_in, __global const uint* values_in, uint n, uint shift,
                             uint mask, uint items, uint chunk, __global const uint* offsets, __global uint* keys_out,
                             __global uint* values_out) {
  uint o[16];
  radix_scatter_chunk(keys_in, values_in, n, shift, mask, items, chunk, offsets, keys_out, values_out, o, 16u);
}

__kernel void radix_scatter8(__global const uint* keys_in, __global const uint* values_in, uint n, uint shift,
                             uint mask, uint items, uint chunk, __global const uint* offsets, __global uint* keys_out,
                             __global uint* values_out) {
  uint o[256];
  radix_scatter_chunk(keys_in, values_in, n, shift, mask, items, chunk, offsets, keys_out, values_out, o, 256u);
}
