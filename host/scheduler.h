// Host scheduler: sizes batches of 2^m paths from the device's memory limits.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace psf {

// "256M", "2G", "512k", "1048576" (bytes; K/M/G/T are powers of 1024, an optional
// trailing B or iB is accepted). Throws std::invalid_argument on anything else.
uint64_t parse_bytes(const std::string& text);

// Human-readable bytes: "1.50 GiB".
std::string format_bytes(uint64_t bytes);

// One kind of device buffer the batch needs.
struct BufferNeed {
  const char* name;    // for messages
  double bytes_per_path;  // bytes per path of the batch (may be fractional for tables)
};

struct BatchPlan {
  int log2 = 0;             // m: the batch holds 2^m paths
  uint64_t bytes = 0;       // device memory of all batch buffers at that size
  uint64_t largest = 0;     // the largest single buffer
};

// The largest m <= max_log2 such that the buffers of 2^m paths together fit in
// min(global_mem, budget) less `fixed` bytes (scene, image), and no single buffer
// exceeds max_alloc. budget 0: none. Throws std::runtime_error when not even
// m = min_log2 fits, naming the limit.
BatchPlan plan_batch(const std::vector<BufferNeed>& needs, uint64_t fixed, uint64_t global_mem, uint64_t max_alloc,
                     uint64_t budget, int max_log2, int min_log2 = 6);

// The default largest batch for an image of `pixels`: the smallest 2^m holding
// kDefaultBatchSpp paths per pixel, at least 2^20 and at most 2^22 (plan_batch
// then lowers it where the device's memory is short). Path space filtering
// finds a vertex's neighbours within its batch, so the batch sets how many it
// finds. Measured (bench_quality, relMSE at equal spp, means of 3 seeds): the
// living room at 1280x720 in batches of 2^22 (4.5 spp) against 2^20 (1.1 spp):
// 0.33 against 0.44 at 4 spp, 0.118 against 0.162 at 16; the Cornell box at
// 256x256 did best in batches of 2^20 (16 spp) from 64 spp on: 2^18 (4 spp) and
// 2^22 (64 spp) read 0.00051 and 0.00052 against 0.00046 at 64 spp.
constexpr int kDefaultBatchSpp = 4;
int default_batch_log2(uint64_t pixels);

}  // namespace psf
