// Path space filtering stage, host side (Keller, Dahm, Binder, "Path Space
// Filtering", MCQMC 2014): cell keys -> radix sort -> cell ranges -> filter,
// over the tuples of one batch; kernels in kernels/{tuples,cell_keys,sort,
// cell_ranges,filter}.cl.
#pragma once
#include <cstdint>

#include "cl/runtime.h"
#include "psf_shared.h"

namespace psf {

// FilterOptions::visibility_ray chosen by the scene: a hemisphere ray where the only
// light is an environment, the light sample otherwise (--visibility-ray auto).
constexpr float kVisibilityRayAuto = -1.0f;
// FilterOptions::visibility_ray for no visibility test at all (--visibility-ray off).
constexpr float kVisibilityRayOff = -2.0f;

struct FilterOptions {
  bool enabled = true;            // --filter psf (true) or off
  float alpha = 0.25f;            // r(n) = r0 / n^alpha (--alpha)
  float r0 = 0.0f;                // global r0 (--r0); <= 0: per vertex from the footprint
  float footprint_pixels = 3.0f;  // r0_i covers this many pixels across (--footprint-pixels)
  // r0_i grows by 1 / sqrt(cos theta_i) at a vertex seen under the angle theta_i,
  // so that the ball holds the area of surface the footprint's pixels see
  // (--foreshortening; not with a global --r0; psf_shared.h PSF_FOOTPRINT_MIN_COS).
  bool foreshortening = true;
  int iterations = 1;             // averaging passes, each over the previous result (--iterations)
  float normal_cos = 0.95f;       // weights: <n_i, n_j> >= normal_cos (--normal-threshold)
  float albedo_tol = 0.05f;       // weights: |albedo_i - albedo_j| <= albedo_tol (--albedo-threshold)
  // Texture-preserving averaging (--demodulate): the filter averages c_j /
  // albedo_j and multiplies the mean by albedo_i (each channel at least
  // PSF_DEMODULATE_MIN), and similar vertices' albedos are compared as log2
  // ratios, |log2 albedo_i - log2 albedo_j| <= albedo_log2_tol, instead of by
  // albedo_tol: neighbours on a texture that varies by up to that ratio count,
  // and each keeps its own albedo.
  bool demodulate = false;
  float albedo_log2_tol = 1.0f;   // with demodulate (--albedo-threshold sets it then)
  bool cells27 = false;           // cells of size r (3x3 rows along x searched) instead of 2r (2x2 rows)
  // > 0: similar vertices agree on whether one hemisphere ray of this length (scene
  // units) hits something (kernels/visibility.cl); 0: on their light sample's
  // visibility; kVisibilityRayAuto: by the scene (Renderer::visibility_ray);
  // kVisibilityRayOff: similar vertices need not agree on visibility (shadows blur
  // over the ball, and penumbrae lose the noise of their light samples'
  // visibility, which the test keeps: each vertex averages only those that agree).
  float visibility_ray = kVisibilityRayAuto;
  // Filtering switches itself off for the rest of the render after a batch in
  // which it removed less than this fraction of the noise (render.h
  // NoiseMonitor; --min-removed; 0: only when no vertex has a neighbour). It pays
  // at equal time while (1 - removed) (1 + c) < 1, c its time relative to path
  // tracing: 0.2 is the break-even at c = 0.25, the most it is meant to cost.
  float min_removed = 0.2f;
};

// Bits of the cell keys for `count` tuples: a table of at least 2 * count cells.
uint32_t filter_key_bits(uint32_t count);

// How radix_sort's passes divide the pairs: each work-item a chunk (CPUs), or each
// work-group a tile ranked in local memory, 4-bit digits only (GPUs).
enum class RadixKernels { automatic, chunks, tiles };

// Sorts `n` (key, value) pairs by the low `bits` bits of the keys, stably, using
// `tmp_keys`/`tmp_values` of the same size; the handles are swapped as it goes,
// so afterwards `keys` and `values` name the buffers holding the sorted pairs.
// Each pass sorts by a digit of `digit_bits` (4 or 8) bits; with chunks, each
// work-item sorts `chunk` pairs. 0 and automatic pick this device's
// (radix_digit_bits, radix_chunk, radix_kernels).
// `scratch`, when given, keeps the table of counts and the scan's block sums
// between calls (grown as needed) instead of allocating them each time.
struct RadixScratch {
  cl::Buffer counts, sums;
  size_t counts_entries = 0, sums_entries = 0;
};
void radix_sort(Runtime& rt, cl::Buffer& keys, cl::Buffer& values, cl::Buffer& tmp_keys, cl::Buffer& tmp_values,
                uint32_t n, uint32_t bits, uint32_t chunk = 0, uint32_t digit_bits = 0,
                RadixKernels kernels = RadixKernels::automatic, RadixScratch* scratch = nullptr);

// The kernels radix_sort uses on this device: tiles on GPUs, chunks on CPUs.
RadixKernels radix_kernels(const Runtime& rt);

// The digit radix_sort uses on this device: 8 bits on CPUs, 4 on GPUs (whose
// 16 counters per work-item stay in registers).
uint32_t radix_digit_bits(const Runtime& rt);

// The pairs per work-item radix_sort uses on this device for `n` pairs: 16 per
// digit value or more on CPUs (a work-item is a loop there), 16 on GPUs.
uint32_t radix_chunk(const Runtime& rt, uint32_t n, uint32_t digit_bits);

// Replaces data[0, total) by its exclusive prefix sum, using `scratch` of at
// least scan_scratch_entries(total) uints.
void exclusive_scan(Runtime& rt, cl::Buffer& data, uint32_t total, cl::Buffer& scratch);
size_t scan_scratch_entries(uint32_t total);

class PathSpaceFilter {
 public:
  // Buffers for batches of up to `capacity` tuples. gather_lanes: paths per
  // work-item of cell_keys and gather_tuples, 1 or PSF_GATHER_LANES; 0 picks by
  // device kind (1 on GPUs, PSF_GATHER_LANES on CPUs). filter_queries: queries
  // per work-item of filter (>= 1); 0 picks by device kind (1 on GPUs,
  // PSF_FILTER_QUERIES on CPUs).
  PathSpaceFilter(Runtime& rt, uint32_t capacity, uint32_t gather_lanes = 0, uint32_t filter_queries = 0);

  // Filters `params.count` tuples: `vertices` (PathVertex, path order) and their
  // values c (float4, path order) into `filtered` (c-bar, path order) and `counts`
  // (tuples averaged, path order), `iterations` times. Returns the largest count.
  // With iterations > 1 the first pass records where each query's neighbours lie
  // in cell order (up to PSF_FILTER_LIST vectors of candidates) and the later
  // passes sum those again, bit for bit a search's sums; a query whose
  // neighbours lie in more vectors searches its cells again.
  uint32_t run(const FilterParams& params, int iterations, const cl::Buffer& vertices, const cl::Buffer& values,
               const cl::Buffer& filtered, const cl::Buffer& counts);

  // The stages' intermediate results of the last run, for tests.
  const cl::Buffer& sorted_keys() const { return keys_; }
  const cl::Buffer& sorted_indices() const { return indices_; }
  // uint per key k <= 2^key_bits: the tuples of keys below k; cell k is [starts[k], starts[k + 1]).
  const cl::Buffer& cell_starts() const { return starts_; }
  const cl::Buffer& valid_count() const { return valid_; }   // uint: tuples with a vertex

  // Bytes of device memory per tuple of capacity (for batch sizing); with more
  // than one iteration, the neighbour lists too.
  static size_t bytes_per_tuple(int iterations = 1);

 private:
  Runtime& rt_;
  uint32_t capacity_;
  uint32_t stride_;        // floats between two fields of sorted_ (capacity + padding)
  uint32_t gather_lanes_;  // paths per work-item of cell_keys and gather_tuples
  uint32_t filter_queries_;  // queries per work-item of filter (1 on GPUs, PSF_FILTER_QUERIES on CPUs)
  cl::Buffer sorted_;
  cl::Buffer keys_, indices_, tmp_keys_, tmp_indices_;
  cl::Buffer values_a_, values_b_, sorted_counts_, starts_, max_count_, valid_;
  cl::Buffer lists_;  // each query's records (PSF_FILTER_LIST_WORDS uints), allocated by a run with iterations > 1
  RadixScratch sort_scratch_;
};

}  // namespace psf
