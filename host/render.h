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

namespace psf {

struct RenderOptions {
  int spp = 16;              // samples (paths) per pixel
  uint32_t seed = 0;         // scrambling seed: the render is a function of it
  int max_depth = -1;        // path segments, Mitsuba's convention; -1 unbounded
  int rr_depth = 5;          // Russian roulette from this many segments on
  int batch_log2 = 20;       // paths per batch: 2^batch_log2 (capped by device memory)
  FilterOptions filter;      // path space filtering (filter.enabled false: plain path tracing)
  bool keep_last_batch = false;  // return the last batch's tuples (tests)
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
  BatchTuples last_batch;         // with RenderOptions::keep_last_batch
  uint64_t paths = 0;             // paths traced
  uint64_t nonfinite = 0;         // paths with NaN/Inf radiance, left out of the image
  uint32_t batch_size = 0;        // paths per batch used
  double seconds = 0.0;           // wall time of the render, without the program build
};

class Renderer {
 public:
  Renderer(Runtime& rt, const Scene& scene);
  ~Renderer();
  RenderResult render(const RenderOptions& options);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace psf
