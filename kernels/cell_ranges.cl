/* cell_ranges.cl: where each cell's tuples lie in sorted order.
 *
 * Reads: the sorted keys. Writes: starts[k] for every k in [0, 2^key_bits]: the
 * number of tuples whose key is below k (a lower bound), so that the tuples of
 * cell k are [starts[k], starts[k + 1]), and those of the cells with keys k..m
 * (a row of cells along x within a key block, whose keys are consecutive:
 * cell_keys.cl) are the one run [starts[k], starts[m + 1]). Work-item i writes
 * the entries from its predecessor's key + 1 up to its own key, and work-item n
 * those past the last key, so every entry is written by exactly one work-item
 * each batch and nothing needs emptying between batches. Keys of paths without a
 * vertex (2^key_bits) sort behind all others; *valid = starts[2^key_bits], the
 * number of tuples before them (the later stages stop there). */

__kernel void cell_ranges(uint n, uint key_bits, __global const uint* keys, __global uint* starts,
                          __global uint* valid) {
  uint i = get_global_id(0);
  if (i > n) return;
  uint cells = 1u << key_bits;
  uint first = i == 0u ? 0u : min(keys[i - 1u], cells) + 1u;
  uint last = i < n ? min(keys[i], cells) : cells;
  for (uint k = first; k <= last; ++k) starts[k] = i;
  if (first <= cells && cells <= last) *valid = i;
}

/* The same starts, one work-item per entry k in [0, 2^key_bits]: the number of
 * keys below k by binary search (GPUs). Keys hashed by blocks (cell_keys.cl)
 * leave long runs of entries between a scene's blocks, which cell_ranges writes
 * one work-item each: Sponza's 2^20 paths on an H200 took 1.86 ms in cell_ranges,
 * most of the filter's 2.3. Neighbouring entries search the same path through
 * the keys, so their loads coalesce. CPUs keep cell_ranges, whose loops are
 * stores in a row. */
__kernel void cell_ranges_search(uint n, uint key_bits, __global const uint* keys, __global uint* starts,
                                 __global uint* valid) {
  uint k = get_global_id(0);
  uint cells = 1u << key_bits;
  if (k > cells) return;
  uint lo = 0u, hi = n;  // the first key >= k lies in [lo, hi]
  while (lo < hi) {
    uint mid = lo + (hi - lo) / 2u;
    if (min(keys[mid], cells) < k)
      lo = mid + 1u;
    else
      hi = mid;
  }
  starts[k] = lo;
  if (k == cells) *valid = lo;
}
