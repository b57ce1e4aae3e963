// Host scheduler, the render session: batches sized from device memory, run on one
// or several devices, accumulated in batch order, progressive until --spp or
// --time, checkpointed atomically to OpenEXR, interruptible (SIGINT/SIGTERM) and
// resumable from the state the EXR carries.
#pragma once
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "render.h"

namespace psf {

struct SessionOptions {
  RenderOptions render;            // spp: the target; seed, depth, filter, aovs
  std::string scene_path;          // for the state's scene hash
  std::vector<std::pair<std::string, std::string>> params;  // -D parameters (part of the scene hash)
  std::string device;              // "", an index, a name, "all", or a comma-separated list
  double time_limit = 0;           // --time: stop after the batch that reaches it (0: none)
  double checkpoint_seconds = 30;  // --checkpoint-seconds: rewrite the output this often (0: only at the end)
  uint64_t memory_budget = 0;      // --memory-budget in bytes (0: the device's memory)
  int max_batch_log2 = 0;          // largest batch: 2^N paths (0: default_batch_log2 of the image)
  std::string output;              // the EXR
  std::string png;                 // the PNG preview ("" none)
  std::string resume;              // --resume: an EXR written by an earlier run
  bool aov_unfiltered = false, aov_neighbours = false, aov_albedo = false, aov_normal = false, aov_depth = false;
  bool quiet = false;              // no messages
  bool progress = true;            // a progress bar (on a terminal only)
  bool stats = false;              // device time per kernel at the end
};

struct SessionResult {
  uint64_t paths = 0;              // paths in the image
  uint64_t nonfinite = 0;          // left out
  double seconds = 0;              // wall time of the batches
  double trace_ms = 0, filter_ms = 0;  // device time in path tracing and in filtering
  bool interrupted = false;        // stopped by SIGINT/SIGTERM
  int signal = 0;                  // which
  uint64_t filter_off_after = 0;   // paths after which filtering switched itself off
  int batch_log2 = 0;              // the batch size used
};

// The state a resumable EXR carries (header attributes).
struct ResumeState {
  std::string scene_hash;     // of the scene file's bytes, -D parameters and film size
  std::string options;        // every option the image depends on, as text
  int batch_log2 = 0;         // batch size of the run
  uint64_t next_batch = 0;    // batches in the state
  uint64_t filter_off_after = 0;
  uint64_t shown_paths = 0;   // paths in the file's image (more than in the state when its last batch was partial)
};

// Hash of the scene file's bytes, the parameters and the film size (hex).
std::string scene_hash(const std::string& path, const std::vector<std::pair<std::string, std::string>>& params,
                       int width, int height);

// Loads the resume state of the EXR at `path` into `acc` (already reset to the
// film size) after checking its scene hash and options. Throws
// std::invalid_argument (wrong render, malformed state) or std::runtime_error
// (not a readable OpenEXR file), each naming the path.
ResumeState load_state(const std::string& path, const std::string& hash, const std::string& options,
                       Accumulator& acc);

// Runs the session, writing the output as it goes. Throws SceneError-free errors:
// std::invalid_argument for an incompatible --resume, ClError, std::runtime_error.
SessionResult run_session(const Scene& scene, const SessionOptions& options);

}  // namespace psf
