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
