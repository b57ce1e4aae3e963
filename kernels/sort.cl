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
 * off the bits above those being sorted.
 *
 * GPUs use the tiles below instead (radix_tile_count4, radix_tile_scatter4): a
 * work-group ranks a tile of PSF_TILE pairs by digit in local memory and writes
 * each digit's run of the tile to consecutive addresses, so that the stores
 * coalesce (chunks per work-item scatter every pair to its own address), and the
 * table of counts has 16 entries a tile instead of 16 a work-item. */

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

/* Tiles: pair i of tile g is input g * PSF_TILE + i. The table holds the tiles'
 * digit counts digit-major, counts[d * tiles + g], and after the scan their
 * exclusive offsets in the output. */
__kernel __attribute__((reqd_work_group_size(PSF_TILE_LOCAL, 1, 1))) void radix_tile_count4(
    __global const uint* keys, uint n, uint shift, uint mask, uint tiles, __global uint* counts) {
  __local uint hist[16];
  uint l = get_local_id(0), g = get_group_id(0);
  if (l < 16u) hist[l] = 0u;
  barrier(CLK_LOCAL_MEM_FENCE);
  uint base = g * PSF_TILE;
  for (uint k = 0u; k < PSF_TILE_PER_ITEM; ++k) { /* order does not matter: coalesced */
    uint i = base + k * PSF_TILE_LOCAL + l;
    if (i < n) atomic_inc(&hist[(keys[i] >> shift) & mask]);
  }
  barrier(CLK_LOCAL_MEM_FENCE);
  if (l < 16u) counts[l * tiles + g] = hist[l];
}

/* The ranks table: (digit, work-item) counts, digit-major, one word of padding
 * every 16 so that work-item l's 16 consecutive entries do not share a bank. */
#define PSF_TILE_PAD(i) ((i) + ((i) >> 4)) /* PSF_TILE_PAD(16 * PSF_TILE_LOCAL) = PSF_TILE_RANKS_PADDED */

__kernel __attribute__((reqd_work_group_size(PSF_TILE_LOCAL, 1, 1))) void radix_tile_scatter4(
    __global const uint* keys_in, __global const uint* values_in, uint n, uint shift, uint mask, uint tiles,
    __global const uint* offsets, __global uint* keys_out, __global uint* values_out) {
  /* 26.1 KiB of local memory in all (OpenCL 1.2 devices have at least 32): the
   * tile's values reuse the ranks table once every work-item has read its ranks. */
  __local uint ranks[PSF_TILE_RANKS_PADDED];
  __local uint part[PSF_TILE_LOCAL];
  __local uint tile_keys[PSF_TILE];
  __local uint start[16], dest[16];
  __local uint* tile_values = ranks; /* PSF_TILE_RANKS_PADDED >= PSF_TILE */
  uint l = get_local_id(0), g = get_group_id(0);
  uint base = g * PSF_TILE, count = min(n - base, PSF_TILE);
  /* 1. Work-item l's pairs are the tile's l * PER_ITEM, ... in input order: its
   * digit counts, into the ranks table. */
  uint key[PSF_TILE_PER_ITEM], c[16];
  for (uint d = 0u; d < 16u; ++d) c[d] = 0u;
  for (uint k = 0u; k < PSF_TILE_PER_ITEM; ++k) {
    uint t = l * PSF_TILE_PER_ITEM + k;
    key[k] = t < count ? keys_in[base + t] : 0u;
    if (t < count) c[(key[k] >> shift) & mask] += 1u;
  }
  for (uint d = 0u; d < 16u; ++d) ranks[PSF_TILE_PAD(d * PSF_TILE_LOCAL + l)] = c[d];
  if (l < 16u) dest[l] = offsets[l * tiles + g];
  barrier(CLK_LOCAL_MEM_FENCE);
  /* 2. Exclusive scan of the table in place: each work-item its 16 consecutive
   * entries, the work-items' sums across the group, then added back. Entry
   * (d, l) becomes the tile position of work-item l's first pair of digit d. */
  uint own = 0u;
  for (uint k = 0u; k < 16u; ++k) own += ranks[PSF_TILE_PAD(l * 16u + k)];
  part[l] = own;
  barrier(CLK_LOCAL_MEM_FENCE);
  for (uint off = 1u; off < PSF_TILE_LOCAL; off <<= 1) {
    uint add = l >= off ? part[l - off] : 0u;
    barrier(CLK_LOCAL_MEM_FENCE);
    part[l] += add;
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  uint run = part[l] - own;
  for (uint k = 0u; k < 16u; ++k) {
    uint v = ranks[PSF_TILE_PAD(l * 16u + k)];
    ranks[PSF_TILE_PAD(l * 16u + k)] = run;
    run += v;
  }
  barrier(CLK_LOCAL_MEM_FENCE);
  /* 3. Each pair to its place in the tile, sorted by digit and stable. */
  if (l < 16u) start[l] = ranks[PSF_TILE_PAD(l * PSF_TILE_LOCAL)];
  for (uint d = 0u; d < 16u; ++d) c[d] = ranks[PSF_TILE_PAD(d * PSF_TILE_LOCAL + l)];
  barrier(CLK_LOCAL_MEM_FENCE); /* the ranks are read: their memory takes the values */
  for (uint k = 0u; k < PSF_TILE_PER_ITEM; ++k) {
    uint t = l * PSF_TILE_PER_ITEM + k;
    if (t >= count) break;
    uint d = (key[k] >> shift) & mask;
    tile_keys[c[d]] = key[k];
    tile_values[c[d]] = values_in[base + t];
    c[d] += 1u;
  }
  barrier(CLK_LOCAL_MEM_FENCE);
  /* 4. Tile position t, digit d, goes to the tile's offset for d plus its rank
   * among the tile's pairs of d: consecutive work-items, consecutive addresses. */
  for (uint k = 0u; k < PSF_TILE_PER_ITEM; ++k) {
    uint t = k * PSF_TILE_LOCAL + l;
    if (t >= count) break;
    uint kv = tile_keys[t], d = (kv >> shift) & mask;
    uint o = dest[d] + (t - start[d]);
    keys_out[o] = kv;
    values_out[o] = tile_values[t];
  }
}
