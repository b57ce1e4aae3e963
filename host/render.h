// The render pipeline: the host calls the kernel stages in order for each batch
// of paths (camera rays -> closest hits -> shading -> shadow rays -> accumulate).
#pragma once
#include <cstdint>
#include <memory>
#include <string>

#include "cl/runtime.h"
#include "image.h"
#include "scene/scene.h"

namespace psf {

struct RenderOptions {
  int spp = 16;              // samples (paths) per pixel
  uint32_t seed = 0;         // scrambling seed: the render is a function of it
  int max_depth = -1;        // path segments, Mitsuba's convention; -1 unbounded
  int rr_depth = 5;          // Russian roulette from this many segments on
  int batch_log2 = 20;       // paths per batch: 2^batch_log2 (capped by device memory)
};

struct RenderResult {
  Image image;                    // the average radiance per pixel
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
