// Helpers shared by the benchmarks: scene paths, summaries of timed trials,
// the report printed to stderr, and "--key=value" argument parsing.
#pragma once
#include <algorithm>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "cl/runtime.h"
#include "scene/scene.h"

namespace bench {

namespace fs = std::filesystem;

// Min and median of timed trials (seconds).
struct Timing {
  double min_s = 0, median_s = 0;  // over the trials
};

inline Timing summarize(std::vector<double> s) {
  std::sort(s.begin(), s.end());
  Timing t;
  if (s.empty()) return t;
  t.min_s = s.front();
  t.median_s = s.size() % 2 ? s[s.size() / 2] : 0.5 * (s[s.size() / 2 - 1] + s[s.size() / 2]);
  return t;
}

// Threads for a CPU peer (Embree, nanoflann): the device's compute units when psf
// runs on the CPU (the same cores), else every core of this machine.
inline unsigned peer_threads(const psf::DeviceInfo& dev) {
  return std::max(1u, dev.type == "CPU" ? dev.compute_units : std::thread::hardware_concurrency());
}

// A file of the shared data folder: $PSF_SHARED, else ../shared beside the source tree.
inline std::string shared_path(const std::string& rel) {
  if (const char* env = std::getenv("PSF_SHARED"); env && *env) return (fs::path(env) / rel).string();
  return (fs::path(PSF_SOURCE_DIR) / "../shared" / rel).lexically_normal().string();
}

// "living-room" for .../living-room/scene.xml, "cornell-box" for .../cornell-box.xml.
inline std::string scene_name(const std::string& path) {
  fs::path p(path);
  std::string stem = p.stem().string();
  if (stem == "scene" || stem == "sponza") stem = p.parent_path().filename().string();
  return stem;
}

inline void report(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
inline void report(const char* fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  std::vfprintf(stderr, fmt, ap);
  va_end(ap);
}

// Device time (ms) of the kernels in Runtime::stats() whose names start with one of `prefixes`.
// The scene at `path`, or nullopt after reporting why it is skipped (absent or unreadable).
inline std::optional<psf::Scene> load_bench_scene(const std::string& path) {
  if (!fs::exists(path)) {
    report("skipped %s: not found\n", path.c_str());
    return std::nullopt;
  }
  try {
    return psf::load_scene(path);
  } catch (const std::exception& e) {
    report("skipped %s: %s\n", path.c_str(), e.what());
    return std::nullopt;
  }
}

inline double kernel_ms(const std::map<std::string, psf::KernelTime>& stats, const std::vector<std::string>& prefixes) {
  double ms = 0;
  for (const auto& [name, t] : stats)
    for (const auto& p : prefixes)
      if (name.compare(0, p.size(), p) == 0) {
        ms += t.ms;
        break;
      }
  return ms;
}

// The path tracing stages of a batch (host/render.cpp) and the filter stages (host/filter.cpp).
inline const std::vector<std::string>& pathtrace_kernels() {
  static const std::vector<std::string> k = {"camera_rays",  "raycast_",   "shade",
                                             "trace_paths",  "trace_lanes", "store_tuples",
                                             "accumulate",   "cast_shadows_media"};
  return k;
}
// Where the only light is an environment: each filtering vertex's hemisphere ray
// (kernels/visibility.cl); the rays themselves are cast by raycast_any.
inline const std::vector<std::string>& visibility_kernels() {
  static const std::vector<std::string> k = {"visibility_"};
  return k;
}
inline const std::vector<std::string>& filter_kernels() {
  static const std::vector<std::string> k = {"cell_keys", "radix_",  "cell_ranges",
                                             "gather_tuples", "filter", "scatter_values"};
  return k;
}

// The number in --key=s; a malformed one is reported and exits with status 2.
template <class T>
T number(const char* program, const char* key, const std::string& s) {
  size_t used = 0;
  double v = 0;
  try {
    v = std::stod(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != s.size()) {
    std::fprintf(stderr, "%s: --%s=%s: expected a number\n", program, key, s.c_str());
    std::exit(2);
  }
  return T(v);
}

// "--key=value" arguments after Google Benchmark has taken its own.
class Args {
 public:
  Args(int argc, char** argv, const char* program) : program_(program) {
    for (int i = 1; i < argc; ++i) rest_.push_back(argv[i]);
  }
  // The value of --key=..., or nullptr; every match is consumed.
  bool take(const char* key, std::string& out) {
    bool found = false;
    std::string k = std::string("--") + key + "=";
    for (auto it = rest_.begin(); it != rest_.end();) {
      if (it->compare(0, k.size(), k) == 0) {
        out = it->substr(k.size());
        found = true;
        it = rest_.erase(it);
      } else {
        ++it;
      }
    }
    return found;
  }
  std::vector<std::string> take_all(const char* key) {
    std::vector<std::string> v;
    std::string k = std::string("--") + key + "=";
    for (auto it = rest_.begin(); it != rest_.end();) {
      if (it->compare(0, k.size(), k) == 0) {
        v.push_back(it->substr(k.size()));
        it = rest_.erase(it);
      } else {
        ++it;
      }
    }
    return v;
  }
  // A malformed number is reported and exits with status 2 (bench::number).
  template <class T>
  void take_number(const char* key, T& out) {
    std::string s;
    if (take(key, s)) out = number<T>(program_, key, s);
  }
  // Reports arguments nobody took; false if there were any.
  bool done() const {
    for (const auto& a : rest_) std::fprintf(stderr, "%s: unknown argument '%s'\n", program_, a.c_str());
    return rest_.empty();
  }

 private:
  const char* program_;
  std::vector<std::string> rest_;
};

}  // namespace bench
