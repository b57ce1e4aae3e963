// The render pipeline: the host calls the kernel stages in order for each batch
// of paths (camera rays -> closest hits -> shading -> shadow rays -> accumulate).
#pragma once
#include <cstdint>
#include <memory>
#include <string>

#include "cl/runtime.h"
#include "filter.h"
#include "image.h"
#include "scene/scene.h"
#include "scheduler.h"

namespace psf {

// Scenes of at most this many primitives (triangles and spheres), or whose BVH
// is one node of leaves, have trace_lanes cast without the BVH
// (RenderOptions.flat_casts; render.cpp has the measurements behind it).
constexpr uint32_t kLanesFlatPrims = 48;

struct RenderOptions {
  int spp = 16;              // samples (paths) per pixel (the target of a progressive render)
  uint32_t seed = 0;         // scrambling seed: the render is a function of it
  int max_depth = -1;        // path segments, Mitsuba's convention; -1 unbounded
  int rr_depth = 5;          // Russian roulette from this many segments on
  int batch_log2 = 0;        // paths per batch: 2^batch_log2 (capped by device memory); 0: default_batch_log2
  int per_path = -1;         // 1: each path in one work-item (trace_paths); 0: the wavefront; -1: per path
                             // on CPU devices for scenes without an environment map, else the wavefront.
                             // The image is the same either way.
  int lanes = -1;            // scenes of the lanes' class (render.cpp lanes_materials_supported), unless per_path 0: 1
                             // eight paths per work-item in vector lanes (kernels/trace_lanes.cl), 0 none (per_path
                             // decides), -1 lanes on CPU devices for scenes without principled or pplastic
                             // materials. The image is the same up to float rounding.
  int64_t tail_paths = -1;   // the wavefront hands its live paths to one trace_paths launch once at most this
                             // many are left (0: never; -1: by device kind, 1/16 of the batch on GPUs, never
                             // on CPUs). The image is the same either way.
  FilterOptions filter;      // path space filtering (filter.enabled false: plain path tracing)
  int emission_rays = 0;     // more camera rays per path for the emission seen directly (kernels/emission.cl;
                             // none where the camera sits in a medium)
  int flat_casts = -1;       // trace_lanes' casts in a scene of few primitives (flat_packs): -1 or 1 each
                             // primitive against eight rays at once, without the BVH; 0 through the BVH (tests).
                             // The image is the same up to float rounding.
  bool emission_recast = false;  // tests: cast each path's own camera ray again instead of taking the
                                 // emission it found from its state (the same image)
  bool keep_last_batch = false;  // return the last batch's tuples (tests)
  bool aovs = false;         // also accumulate albedo, normal and depth of the filtering vertices
};

// The contributions of one batch's paths (Renderer::trace_batch), in path order,
// added to an Accumulator in batch order so that the image never depends on the
// batch size or on which device rendered which batch.
struct BatchImages {
  uint64_t index = 0;                 // batch number
  uint64_t first = 0;                 // global index of its first path
  std::vector<cl_float4> filtered;    // per path: prefix + alpha c-bar, w: tuples averaged; empty
                                      // when the batch was not filtered: the same as `unfiltered`
  std::vector<cl_float4> unfiltered;  // per path: prefix + alpha c, w: 1
  std::vector<PathVertex> vertices;   // with RenderOptions::aovs: the filtering vertices
  uint32_t max_count = 0;             // largest number of tuples averaged (0: not filtered)
  FilterParams params{};              // the filter's parameters (when filtered)
  double trace_seconds = 0.0;         // wall time of trace_batch up to its kernels' end (launches included)
  double download_seconds = 0.0;      // then the downloads of the contributions
};

// Per-pixel sums of a render in progress: what an image, a checkpoint and a
// resumed render are made of.
struct Accumulator {
  int width = 0, height = 0;          // film
  std::vector<float> filtered;        // 4 per pixel: RGB sums, then the sum of tuples averaged
  std::vector<float> unfiltered;      // 4 per pixel: RGB sums, then the number of paths
  std::vector<uint32_t> bad_filtered, bad_unfiltered;  // non-finite paths per pixel
  std::vector<float> aov;             // 8 per pixel when AOVs are kept (BatchImages::aov)
  uint64_t paths = 0;                 // paths accumulated
  uint64_t next_batch = 0;            // the batch to add next

  void reset(int width, int height, bool aovs);
  void add(const BatchImages& b);     // b.index must equal next_batch
  Image image() const;                // filtered average
  Image unfiltered_image() const;     // unfiltered average
  std::vector<float> neighbours() const;  // mean tuples averaged per pixel
  std::vector<float> aov_layer(int which) const;  // 0 albedo (3), 1 normal (3), 2 depth (1)
  uint64_t nonfinite() const;         // paths left out of the filtered image
};

// How much of a batch's noise the filter removed, for switching it off once it
// no longer pays for its time. For each pixel p with b_p paths in the batch,
// d_p = (mean filtered - mean unfiltered luminance of those paths)^2 is set
// against the variance of the unfiltered mean, s_p^2 / b_p, where s_p^2 is the
// variance of p's path luminances over all unfiltered paths so far; both are
// weighted by 1 / (m_p^2 + 0.01), m_p the pixel's mean so far (relMSE's weights):
//   removed = sum_p w_p d_p / sum_p w_p s_p^2 / b_p.
// For an average over neighbours E[d_p] = Var(unfiltered) - Var(filtered) + bias^2,
// so `removed` estimates the fraction of the batch's noise the filter took away.
// Filtering a batch pays at equal time while (1 - removed) (1 + c) < 1, c the
// filter's time relative to path tracing (FilterOptions::min_removed).
class NoiseMonitor {
 public:
  void reset(uint64_t pixels);
  // Adds the batch's unfiltered paths (path j in pixel (b.first + j) mod pixels)
  // to the pixels' statistics and returns `removed` for it: NaN when the batch
  // was not filtered or no pixel had two paths before it.
  double add(const BatchImages& b);

 private:
  std::vector<double> sum_, sum2_;  // per pixel: luminance sums over the render
  std::vector<uint32_t> count_;
};

// The tuples of one batch, in path order (RenderOptions::keep_last_batch).
struct BatchTuples {
  std::vector<PathVertex> vertices;  // filtering vertices (albedo.w 0: none)
  std::vector<cl_float4> values;     // c_i, unfiltered
  FilterParams params{};             // the filter's parameters for this batch
};

struct RenderResult {
  Image image;                    // the average radiance per pixel (filtered when filtering)
  Image unfiltered;               // the same paths without filtering (the image itself when not filtering)
  std::vector<float> neighbours;  // per pixel: mean number of tuples averaged (1 when not filtering)
  uint64_t filter_off_after = 0;  // paths after which filtering switched itself off (0: never)
  double filter_removed = 0.0;    // then: the last batch's NoiseMonitor estimate (NaN: no neighbours)
  BatchTuples last_batch;         // with RenderOptions::keep_last_batch
  uint64_t paths = 0;             // paths traced
  uint64_t nonfinite = 0;         // paths with NaN/Inf radiance, left out of the image
  uint32_t batch_size = 0;        // paths per batch used
  double seconds = 0.0;           // wall time of the render, without the program build
  // Where `seconds` went, summed over the batches: tracing and filtering up to
  // the kernels' end, downloading the contributions, adding them on the host
  // (Accumulator and NoiseMonitor).
  double trace_seconds = 0.0, download_seconds = 0.0, add_seconds = 0.0;
};

// The scene's BVH as built (host/bvh.h Bvh), for the log.
struct BvhSummary {
  size_t nodes = 0, packs = 0;  // wide nodes, triangle and sphere packs
  uint64_t bytes = 0;           // of both
  uint32_t primitives = 0;      // triangles and spheres in it
  uint32_t references = 0;      // their leaf references (more with spatial splits)
  double build_ms = 0.0;
};

class Renderer {
 public:
  Renderer(Runtime& rt, const Scene& scene);
  ~Renderer();

  // The whole render in one call: prepare, every batch in order, accumulate.
  RenderResult render(const RenderOptions& options);

  // Allocates the buffers for batches of 2^batch_log2 paths (throws ClError, e.g.
  // CL_MEM_OBJECT_ALLOCATION_FAILURE, when the device cannot hold them); `paths`
  // > 0: the render traces no more than that many, and the buffers hold no more
  // (the batches are still of 2^batch_log2 paths).
  void prepare(const RenderOptions& options, int batch_log2, uint64_t paths = 0);
  // Device bytes per path of a batch, and bytes independent of the batch (scene, image).
  static std::vector<BufferNeed> batch_needs(bool filtering, bool aovs, int iterations = 1);
  uint64_t fixed_bytes() const;
  // Traces batch `index` of a render of `total` paths (its paths are index * 2^m up
  // to the next multiple or total), filters it when `filtering`, and returns its sums.
  BatchImages trace_batch(uint64_t index, uint64_t total, bool filtering);
  // Takes a batch's vectors back once it is added, so that later batches download
  // into memory already paged in (a fresh 16 MiB vector costs more than the copy).
  void recycle(BatchImages&& batch);
  uint32_t batch_size() const;
  Runtime& runtime();
  // The length of the filtering vertices' hemisphere ray for FilterOptions::
  // visibility_ray = `option` (0: none, the light sample decides): the option
  // when it is not kVisibilityRayAuto; for auto, 1 % of the diagonal of the
  // scene's bounds when its only light is an environment (envmap or constant:
  // there a light sample's visibility is a coin toss wherever part of the sky is
  // hidden), else 0.
  float visibility_ray(float option) const;
  // The packs that trace_lanes tests each ray against without the BVH
  // (FrameParams.flat_packs) under RenderOptions::flat_casts = `option`: all of
  // them where the scene has at most kLanesFlatPrims primitives or a BVH of one
  // node, and none is alpha-tested, unless `option` is 0; else 0, casts through
  // the BVH.
  uint32_t flat_packs(int option) const;
  const BvhSummary& bvh_summary() const;

 private:
  float footprint(const RenderOptions& o) const;  // sqrt(dOmega / pi) of the footprint's solid angle

  struct Impl;
  struct Batch;
  std::unique_ptr<Impl> impl_;
  std::unique_ptr<Batch> batch_;
};

}  // namespace psf
