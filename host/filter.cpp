#include "filter.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace psf {

namespace {
constexpr size_t kLocal = Runtime::kDefaultLocal;

// Scans data[data_offset, + total) with its block sums in scratch from scratch_offset on.
void scan_level(Runtime& rt, cl::Buffer& data, uint32_t data_offset, uint32_t total, cl::Buffer& scratch,
                uint32_t scratch_offset) {
  const uint32_t blocks = (total + PSF_SCAN_BLOCK - 1) / PSF_SCAN_BLOCK;
  rt.launch("radix_scan_blocks", size_t(blocks) * PSF_SCAN_LOCAL, PSF_SCAN_LOCAL, data, data_offset, total, scratch,
            scratch_offset);
  if (blocks == 1) return;
  scan_level(rt, scratch, scratch_offset, blocks, scratch, scratch_offset + blocks);
  rt.launch("radix_scan_add", total, kLocal, data, data_offset, total, scratch, scratch_offset);
}
}  // namespace

uint32_t filter_key_bits(uint32_t count) {
  uint32_t bits = 1;
  while (bits < 30 && (uint64_t(1) << bits) < 2 * uint64_t(std::max(count, 1u))) ++bits;
  return bits;
}

size_t scan_scratch_entries(uint32_t total) {
  size_t entries = 0;
  for (size_t t = total; t > PSF_SCAN_BLOCK; t = (t + PSF_SCAN_BLOCK - 1) / PSF_SCAN_BLOCK)
    entries += (t + PSF_SCAN_BLOCK - 1) / PSF_SCAN_BLOCK;
  return entries + 1;  // the last level's single block sum
}

void exclusive_scan(Runtime& rt, cl::Buffer& data, uint32_t total, cl::Buffer& scratch) {
  // Scan each block in place, then the block sums (the next level, recursively),
  // then add each block's offset back.
  if (total > 0) scan_level(rt, data, 0, total, scratch, 0);
}

uint32_t radix_digit_bits(const Runtime& rt) { return rt.device().type == "GPU" ? 4 : 8; }

uint32_t radix_chunk(const Runtime& rt, uint32_t n, uint32_t digit_bits) {
  // GPUs: short chunks, so that enough work-items run; at most 65536 of them.
  if (rt.device().type == "GPU") return std::max(16u, (n + 65535) / 65536);
  // CPUs: chunks of at least 16 pairs per digit value (256 pairs for 4-bit
  // digits, 4096 for 8-bit ones), so that the table of counts stays a small part
  // of the input; at most 1024 work-items.
  const uint32_t least = 16u << digit_bits;
  const uint32_t items = std::max(1u, std::min(1024u, (n + least - 1) / least));
  return (n + items - 1) / items;
}

RadixKernels radix_kernels(const Runtime& rt) {
  // The tiles' kernel holds a table of ranks, the tile's keys and a little more
  // in local memory (kernels/sort.cl): 26.1 KiB, where OpenCL 1.2 promises 32.
  constexpr uint64_t kTileLocalBytes = 4u * ((PSF_TILE_RANKS_PADDED) + PSF_TILE_LOCAL + PSF_TILE + 32u);
  return rt.device().type == "GPU" && rt.device().local_mem >= kTileLocalBytes ? RadixKernels::tiles
                                                                              : RadixKernels::chunks;
}

// Each pass swaps the buffer handles, so `keys`/`values` name the result.
void radix_sort(Runtime& rt, cl::Buffer& keys, cl::Buffer& values, cl::Buffer& tmp_keys, cl::Buffer& tmp_values,
                uint32_t n, uint32_t bits, uint32_t chunk, uint32_t digit_bits, RadixKernels kernels,
                RadixScratch* scratch) {
  if (n <= 1 || bits == 0) return;
  if (kernels == RadixKernels::automatic) kernels = radix_kernels(rt);
  const bool tiles = kernels == RadixKernels::tiles;
  if (digit_bits == 0) digit_bits = tiles ? 4 : radix_digit_bits(rt);
  if (digit_bits != 4 && digit_bits != 8) throw std::invalid_argument("radix_sort: digits of 4 or 8 bits");
  if (tiles && digit_bits != 4) throw std::invalid_argument("radix_sort: tiles sort 4-bit digits");
  bits = std::min(bits, 32u);
  if (chunk == 0) chunk = radix_chunk(rt, n, digit_bits);
  // Chunks: one work-item each. Tiles: PSF_TILE pairs a work-group.
  const uint32_t items = tiles ? (n + PSF_TILE - 1) / PSF_TILE : (n + chunk - 1) / chunk;
  const uint32_t table = (1u << digit_bits) * items;  // digit-major counts, then their scan
  // CPUs run a work-group on one thread: groups small enough that every compute
  // unit gets several.
  const size_t local =
      rt.device().type == "GPU" ? kLocal
                                : std::clamp<size_t>(items / (4 * std::max(rt.device().compute_units, 1u)), 1, kLocal);
  const std::string count = tiles ? "radix_tile_count4" : "radix_count" + std::to_string(digit_bits);
  const std::string scatter = tiles ? "radix_tile_scatter4" : "radix_scatter" + std::to_string(digit_bits);
  RadixScratch own;
  RadixScratch& tmp = scratch ? *scratch : own;
  if (tmp.counts_entries < table) {
    tmp.counts = rt.buffer(CL_MEM_READ_WRITE, sizeof(uint32_t) * table);
    tmp.counts_entries = table;
  }
  if (tmp.sums_entries < scan_scratch_entries(table)) {
    tmp.sums = rt.buffer(CL_MEM_READ_WRITE, sizeof(uint32_t) * scan_scratch_entries(table));
    tmp.sums_entries = scan_scratch_entries(table);
  }
  cl::Buffer& counts = tmp.counts;
  for (uint32_t shift = 0; shift < bits; shift += digit_bits) {
    const uint32_t width = std::min(digit_bits, bits - shift);
    const uint32_t mask = (1u << width) - 1u;
    if (tiles) {
      const size_t global = size_t(items) * PSF_TILE_LOCAL;
      rt.launch(count, global, PSF_TILE_LOCAL, keys, n, shift, mask, items, counts);
      exclusive_scan(rt, counts, table, tmp.sums);
      rt.launch(scatter, global, PSF_TILE_LOCAL, keys, values, n, shift, mask, items, counts, tmp_keys, tmp_values);
    } else {
      rt.launch(count, items, local, keys, n, shift, mask, items, chunk, counts);
      exclusive_scan(rt, counts, table, tmp.sums);
      rt.launch(scatter, items, local, keys, values, n, shift, mask, items, chunk, counts, tmp_keys, tmp_values);
    }
    std::swap(keys, tmp_keys);
    std::swap(values, tmp_values);
  }
}

size_t PathSpaceFilter::bytes_per_tuple(int iterations) {
  // sorted tuples (PSF_SORTED_FIELDS arrays), keys and indices (2x each),
  // values (2x, as r, g, b arrays), counts, cell starts (a uint for each of up to
  // 4 keys per tuple), and for more than one pass the neighbour lists. The
  // arrays' padding is per batch, not per tuple.
  return PSF_SORTED_FIELDS * sizeof(float) + 4 * sizeof(uint32_t) + 2 * 3 * sizeof(float) + sizeof(uint32_t) +
         4 * sizeof(uint32_t) + (iterations > 1 ? PSF_FILTER_LIST_WORDS * sizeof(uint32_t) : 0);
}

PathSpaceFilter::PathSpaceFilter(Runtime& rt, uint32_t capacity, uint32_t gather_lanes, uint32_t filter_queries)
    : rt_(rt),
      capacity_(capacity),
      stride_(std::max(capacity, 1u) + PSF_SORTED_PAD),
      gather_lanes_(gather_lanes ? gather_lanes : rt.device().type == "GPU" ? 1 : PSF_GATHER_LANES),
      filter_queries_(filter_queries ? filter_queries : rt.device().type == "GPU" ? 1 : PSF_FILTER_QUERIES) {
  if (gather_lanes_ != 1 && gather_lanes_ != PSF_GATHER_LANES)
    throw std::invalid_argument("PathSpaceFilter: gather_tuples takes 1 or PSF_GATHER_LANES tuples per work-item");
  size_t n = std::max(capacity, 1u);
  size_t cells = size_t(1) << filter_key_bits(capacity);
  sorted_ = rt.buffer(CL_MEM_READ_WRITE, size_t(PSF_SORTED_FIELDS) * stride_ * sizeof(float));
  keys_ = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(uint32_t));
  indices_ = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(uint32_t));
  tmp_keys_ = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(uint32_t));
  tmp_indices_ = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(uint32_t));
  values_a_ = rt.buffer(CL_MEM_READ_WRITE, 3 * size_t(stride_) * sizeof(float));
  values_b_ = rt.buffer(CL_MEM_READ_WRITE, 3 * size_t(stride_) * sizeof(float));
  sorted_counts_ = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(uint32_t));
  starts_ = rt.buffer(CL_MEM_READ_WRITE, (cells + 1) * sizeof(uint32_t));
  max_count_ = rt.buffer(CL_MEM_READ_WRITE, sizeof(uint32_t));
  valid_ = rt.buffer(CL_MEM_READ_WRITE, sizeof(uint32_t));
  // The arrays' padding is read (and ignored) by filter.cl: give it values.
  rt.zero(sorted_, size_t(PSF_SORTED_FIELDS) * stride_ * sizeof(float));
  rt.zero(values_a_, 3 * size_t(stride_) * sizeof(float));
  rt.zero(values_b_, 3 * size_t(stride_) * sizeof(float));
}

uint32_t PathSpaceFilter::run(const FilterParams& params, int iterations, const cl::Buffer& vertices,
                              const cl::Buffer& values, const cl::Buffer& filtered, const cl::Buffer& counts) {
  FilterParams p = params;
  const uint32_t n = p.count;
  if (n == 0) return 0;
  if (n > capacity_) throw std::invalid_argument("PathSpaceFilter: batch larger than its capacity");
  p.key_bits = filter_key_bits(n);

  // Cell keys, then the (key, path index) pairs sorted by key: key_bits + 1 bits,
  // since paths without a vertex have the key 2^key_bits.
  const uint32_t lane_items = (n + gather_lanes_ - 1) / gather_lanes_;  // cell_keys and gather_tuples
  rt_.launch("cell_keys", lane_items, kLocal, p, gather_lanes_, vertices, keys_, indices_);
  radix_sort(rt_, keys_, indices_, tmp_keys_, tmp_indices_, n, p.key_bits + 1, 0, 0, RadixKernels::automatic,
             &sort_scratch_);
  // Each cell's start: on GPUs one work-item per entry (a binary search), on CPUs
  // one per tuple writing the entries up to its key (kernels/cell_ranges.cl).
  if (rt_.device().type == "GPU")
    rt_.launch("cell_ranges_search", (size_t(1) << p.key_bits) + 1, kLocal, n, p.key_bits, keys_, starts_, valid_);
  else
    rt_.launch("cell_ranges", n + 1, kLocal, n, p.key_bits, keys_, starts_, valid_);
  rt_.launch("gather_tuples", lane_items, kLocal, p, stride_, gather_lanes_, indices_, vertices, values, valid_,
             sorted_, values_a_);

  // Averaging, each iteration over the previous one's result (Fig. 2 of the paper);
  // every iteration averages the same tuples, so the counts are those of any, and
  // the passes after the first average over the lists the first one recorded.
  if (iterations > 1 && !lists_())
    lists_ = rt_.buffer(CL_MEM_READ_WRITE, size_t(std::max(capacity_, 1u)) * PSF_FILTER_LIST_WORDS * sizeof(uint32_t));
  const size_t items = (n + filter_queries_ - 1) / filter_queries_;
  for (int it = 0; it < std::max(iterations, 1); ++it) {
    if (iterations <= 1)
      rt_.launch("filter", items, kLocal, p, stride_, filter_queries_, valid_, sorted_, values_a_, starts_, values_b_,
                 sorted_counts_);
    else
      rt_.launch(it == 0 ? "filter_record" : "filter_lists", items, kLocal, p, stride_, filter_queries_, valid_,
                 sorted_, values_a_, starts_, values_b_, sorted_counts_, lists_);
    std::swap(values_a_, values_b_);
  }
  rt_.zero(max_count_, sizeof(uint32_t));
  const uint32_t count_items = (n + PSF_MAX_COUNT_CHUNK - 1) / PSF_MAX_COUNT_CHUNK;
  rt_.launch("filter_max_count", count_items, kLocal, n, valid_, sorted_counts_, max_count_);
  rt_.launch("scatter_values", n, kLocal, n, stride_, p.demodulate, indices_, valid_, vertices, values_a_,
             sorted_counts_, values, filtered, counts);
  uint32_t max_count = 0;
  rt_.read(max_count_, &max_count, sizeof(max_count));
  return max_count;
}

}  // namespace psf
