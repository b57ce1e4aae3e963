/* cell_ranges.cl: where each cell's tuples lie in sorted order.
 *
 * Reads: the sorted keys. Writes: ranges[key] = (first, one past the last) for
 * every key present, start and end side by side so a lookup touches one cache
 * line. The table is empty ((0, 0)) before: the host zeroes it once, and
 * clear_ranges empties again only the entries the previous batch wrote, from its
 * sorted keys (a batch's keys fill at most half the table). Keys of paths without a
 * vertex (>= 2^key_bits) get no range; they sort behind all others, and *valid
 * is set to the number of tuples before them (the later stages stop there).
 *
 * The first and the last tuple of a cell are found by different work-items, so
 * each writes its own 32-bit word: a component store to a uint2 (ranges[k].x)
 * may compile to a load and store of the whole pair, which loses the other
 * work-item's word (seen with NVIDIA's OpenCL). */

__kernel void clear_ranges(uint n, uint key_bits, __global const uint* keys, __global uint2* ranges) {
  uint i = get_global_id(0);
  if (i >= n) return;
  uint k = keys[i];
  if (k < (1u << key_bits) && (i == 0u || keys[i - 1u] != k)) ranges[k] = (uint2)(0u, 0u);
}

__kernel void cell_ranges(uint n, uint key_bits, __global const uint* keys, __global uint2* ranges,
                          __global uint* valid) {
  uint i = get_global_id(0);
  if (i >= n) return;
  uint k = keys[i], cells = 1u << key_bits;
  if (k >= cells) { /* one work-item writes *valid: the first without a vertex, or the last */
    if (i == 0u || keys[i - 1u] < cells) *valid = i;
    return;
  }
  if (i + 1u == n) *valid = n;
  __global uint* words = (__global uint*)ranges;  // ranges[k] = (words[2k], words[2k + 1])
  if (i == 0u || keys[i - 1u] != k) words[2u * k] = i;
  if (i + 1u == n || keys[i + 1u] != k) words[2u * k + 1u] = i + 1u;
}
