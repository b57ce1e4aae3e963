// bench_render: paths per second of the whole renderer (psf::Renderer, plain path
// tracing; with path space filtering as a second figure), against Mitsuba 3
// rendering the same scene file at the same resolution and spp on the same cores.
//
// psf_render/<scene>: Renderer::render with --filter off, the scene's film, max
//   depth and the given spp; one warm-up render (first launches), --trials timed.
//   Time: RenderResult::seconds, the wall time of the batch loop (from the first
//   kernel to the last finish; not the program build, BVH build, scene upload or
//   the final image download). Also the summed device time of all kernels.
// psf_render_filtered/<scene>: the same with path space filtering (defaults).
// The peer, Mitsuba 3, in psf_render/<scene>'s trials: before each of psf's
//   timed renders, a process of bench/mitsuba_render.py (Mitsuba 3, llvm_ad_rgb
//   where it runs, else scalar_rgb; as many Dr.Jit threads as the device has
//   compute units) loads the scene, renders it once untimed (JIT compilation) and
//   once timed: mi.render(scene, spp) up to the developed film as a NumPy array
//   (without numpy: the evaluated Dr.Jit tensor);
//   scene load and Python start-up are not timed. Each psf trial thus follows
//   one of Mitsuba's by seconds, so that the machine's drift (10-30 % within
//   minutes here) falls on both of a pair. Mitsuba 0.5 scenes are upgraded by
//   Mitsuba 3's loader; properties it rejects are removed from a temporary copy
//   and listed.
//   The interpreter: $PSF_PYTHON, else <build>/venv/bin/python3, else
//   <source>/build/venv/bin/python3, else python3; without `import mitsuba` the peer
//   is skipped with a message (python3 -m venv build/venv && build/venv/bin/pip
//   install mitsuba==3.6.4 numpy).
// Ratios printed: psf paths/s / Mitsuba paths/s of the medians, and of each
// trial's pair with their median, which the goal (>= 1) is judged by; the
// filtered render against the plain trials' Mitsuba median.
//
// On a GPU device the peer is Mitsuba's cuda_ad_rgb variant (--peer_variant=NAME
// picks another).
//
// Usage: bench_render [benchmark flags] [--scene=PATH ...] [--spp=N] [--trials=N] [--no_filtered=1]
//                     [--peer_variant=NAME] [--tail_paths=N]
// --tail_paths: RenderOptions::tail_paths (-1, the default: by device kind).
// Without --scene: the living-room (1 spp, its 1280x720 film) and Mitsuba's cbox
// (4 spp, 500x500) from $PSF_SHARED (else ../shared beside the source tree) and
// scenes/cornell-box.xml (16 spp, 256x256); absent ones are skipped.
#include <benchmark/benchmark.h>

#include <array>
#include <optional>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>

#include "bench_common.h"
#include "render.h"
#include "scene/scene.h"

namespace {

using bench::report;
using bench::Timing;

struct Options {
  std::vector<std::string> scenes;  // scene files; empty: the defaults
  int spp = 0;                      // 0: per scene (living-room 1, cbox 4, cornell-box 16, others 1)
  int trials = 3;                   // timed renders
  bool filtered = true;             // also time psf with path space filtering
  int64_t tail_paths = -1;          // RenderOptions::tail_paths
};

struct Bench {
  std::string name, path;
  psf::Scene scene;
  int spp = 1;
  uint64_t paths = 0;
  double mitsuba_paths_per_s = 0;  // median, 0 when the peer did not run
  std::string mitsuba_variant;
};

// Minimal readers for the flat JSON line of mitsuba_render.py.
std::string json_raw(const std::string& s, const std::string& key) {
  size_t k = s.find("\"" + key + "\":");
  if (k == std::string::npos) return "";
  size_t i = k + key.size() + 3;
  while (i < s.size() && s[i] == ' ') ++i;
  size_t j = i;
  if (j < s.size() && (s[j] == '[' || s[j] == '{')) {
    int depth = 0;
    bool str = false;
    for (; j < s.size(); ++j) {
      char c = s[j];
      if (str) {
        if (c == '\\') ++j;
        else if (c == '"') str = false;
      } else if (c == '"') {
        str = true;
      } else if (c == '[' || c == '{') {
        ++depth;
      } else if ((c == ']' || c == '}') && --depth == 0) {
        return s.substr(i, j + 1 - i);
      }
    }
    return s.substr(i);
  }
  if (j < s.size() && s[j] == '"') {
    std::string out;
    for (++j; j < s.size() && s[j] != '"'; ++j) {
      if (s[j] == '\\' && j + 1 < s.size()) ++j;
      out += s[j];
    }
    return out;
  }
  while (j < s.size() && s[j] != ',' && s[j] != '}') ++j;
  return s.substr(i, j - i);
}
double json_number(const std::string& s, const std::string& key) {
  std::string v = json_raw(s, key);
  return v.empty() ? 0.0 : std::atof(v.c_str());
}
std::vector<double> json_numbers(const std::string& s, const std::string& key) {
  std::string v = json_raw(s, key);
  std::vector<double> out;
  if (v.size() < 2) return out;
  std::stringstream in(v.substr(1, v.size() - 2));
  std::string item;
  while (std::getline(in, item, ',')) out.push_back(std::atof(item.c_str()));
  return out;
}

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// Output (stdout) and exit status of a shell command.
std::pair<std::string, int> run_command(const std::string& cmd) {
  std::string out;
  FILE* f = popen(cmd.c_str(), "r");
  if (!f) return {"", -1};
  std::array<char, 4096> buf;
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), f)) > 0) out.append(buf.data(), n);
  int status = pclose(f);
  return {out, status};
}

std::string find_python() {
  if (const char* env = std::getenv("PSF_PYTHON"); env && *env) return env;
  for (const std::string& p : {std::string(PSF_BINARY_DIR) + "/venv/bin/python3",
                               std::string(PSF_SOURCE_DIR) + "/build/venv/bin/python3"})
    if (bench::fs::exists(p)) return p;
  return "python3";
}

int default_spp(const std::string& name) {
  if (name == "cornell-box") return 16;
  if (name == "cbox") return 4;
  return 1;
}

psf::RenderOptions render_options(const Bench& b, bool filter, int64_t tail_paths) {
  psf::RenderOptions o;
  o.tail_paths = tail_paths;
  o.spp = b.spp;
  o.seed = 0;
  o.max_depth = b.scene.max_depth;
  o.rr_depth = b.scene.rr_depth;
  o.filter.enabled = filter;
  return o;
}

// One run of bench/mitsuba_render.py (load, an untimed warm-up, `repeat` timed
// renders): its JSON line, empty with the exit status where it printed none.
struct PeerRun {
  bool ok = false;
  std::string line;
  int status = 0;
  std::vector<double> times;
};
PeerRun run_peer(const Bench& b, const std::string& python, const std::string& script, const std::string& variant,
                 unsigned threads, int repeat) {
  std::string cmd = quote(python) + " " + quote(script) + " --scene " + quote(b.path) + " --spp " +
                    std::to_string(b.spp) + " --repeat " + std::to_string(repeat) + " --threads " +
                    std::to_string(threads) + " --variant " + quote(variant);
  auto [out, status] = run_command(cmd);
  PeerRun r;
  r.status = status;
  for (std::stringstream in(out); std::getline(in, r.line);)
    if (!r.line.empty() && r.line[0] == '{') break;
  if (r.line.empty() || r.line[0] != '{') r.line.clear();
  r.times = json_numbers(r.line, "times_s");
  r.ok = json_raw(r.line, "ok") == "true" && r.times.size() == size_t(repeat);
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  Options opt;
  bench::Args args(argc, argv, "bench_render");
  opt.scenes = args.take_all("scene");
  args.take_number("spp", opt.spp);
  args.take_number("trials", opt.trials);
  args.take_number("tail_paths", opt.tail_paths);
  int no_filtered = 0;
  args.take_number("no_filtered", no_filtered);
  std::string peer_variant;  // Mitsuba 3 variant; default: auto on CPUs, cuda_ad_rgb on GPUs
  args.take("peer_variant", peer_variant);
  opt.filtered = !no_filtered;
  if (!args.done()) return 2;
  opt.trials = std::max(1, opt.trials);
  if (opt.scenes.empty())
    opt.scenes = {bench::shared_path("scenes/living-room/scene.xml"),
                  (bench::fs::path(PSF_SOURCE_DIR) / "scenes/cornell-box.xml").string(),
                  bench::shared_path("scenes/cbox/scene.xml")};

  psf::DeviceInfo dev = psf::choose_device(std::getenv("PSF_DEVICE") ? std::getenv("PSF_DEVICE") : "");
  psf::Runtime rt(dev);
  // The peer: on a CPU device, as many Dr.Jit threads as it has compute units and
  // Mitsuba's CPU variants; on a GPU, Mitsuba's CUDA variant (and every core).
  const bool gpu = dev.type == "GPU";
  const unsigned threads = gpu ? 0u : std::max(1u, dev.compute_units);
  if (peer_variant.empty()) peer_variant = gpu ? "cuda_ad_rgb" : "auto";
  benchmark::AddCustomContext("psf_device", dev.platform + " / " + dev.name);
  benchmark::AddCustomContext("psf_driver", dev.driver + " (" + dev.version + ")");
  benchmark::AddCustomContext("psf_build_options", "-cl-std=CL1.2 -DPSF_BVH_WIDTH=" + std::to_string(PSF_BVH_WIDTH));
  benchmark::AddCustomContext("psf_compute_units", std::to_string(dev.compute_units));
  benchmark::AddCustomContext("psf_local_size", std::to_string(psf::Runtime::kDefaultLocal));
  report("device: %s / %s, driver %s, %s, %u compute units; %d timed renders after a warm-up\n",
         dev.platform.c_str(), dev.name.c_str(), dev.driver.c_str(), dev.version.c_str(), dev.compute_units,
         opt.trials);

  // The peer: is Mitsuba 3 importable?
  const std::string python = find_python();
  const std::string script = (bench::fs::path(PSF_SOURCE_DIR) / "bench/mitsuba_render.py").string();
  auto [version, rc] = run_command(quote(python) + " -c 'import mitsuba, drjit; print(\"mitsuba\", "
                                                   "mitsuba.__version__ + \", drjit\", drjit.__version__)' 2>/dev/null");
  const bool have_mitsuba = rc == 0 && !version.empty();
  if (have_mitsuba) {
    while (!version.empty() && (version.back() == '\n' || version.back() == ' ')) version.pop_back();
    report("peer: Mitsuba 3 (%s) via %s\n", version.c_str(), python.c_str());
    benchmark::AddCustomContext("peer", "Mitsuba 3 (" + version + "), " + peer_variant +
                                            (gpu ? "" : ", " + std::to_string(threads) + " threads"));
  } else {
    report("peer skipped: `import mitsuba` fails with %s (python3 -m venv build/venv && build/venv/bin/pip "
           "install mitsuba==3.6.4 numpy, or set PSF_PYTHON)\n",
           python.c_str());
  }

  std::vector<std::unique_ptr<Bench>> benches;
  for (const std::string& path : opt.scenes) {
    std::optional<psf::Scene> scene = bench::load_bench_scene(path);
    if (!scene) continue;
    auto b = std::make_unique<Bench>();
    b->path = path;
    b->name = bench::scene_name(path);
    b->scene = std::move(*scene);
    b->spp = opt.spp > 0 ? opt.spp : default_spp(b->name);
    b->paths = uint64_t(b->scene.width) * b->scene.height * b->spp;
    report("%s: %zu triangles, %dx%d, %d spp = %llu paths, max depth %d; psf loader: %zu warnings%s\n",
           b->name.c_str(), b->scene.triangles.size(), b->scene.width, b->scene.height, b->spp,
           (unsigned long long)b->paths, b->scene.max_depth, b->scene.warnings.size(),
           b->scene.warnings.empty() ? "" : " (features approximated or ignored: not the same image as Mitsuba's)");
    for (const auto& w : b->scene.warnings) report("  %s\n", w.c_str());
    benchmark::AddCustomContext("scene_" + b->name, path + ", " + std::to_string(b->scene.width) + "x" +
                                                        std::to_string(b->scene.height) + ", " +
                                                        std::to_string(b->spp) + " spp");
    benches.push_back(std::move(b));
  }

  for (auto& bp : benches) {
    Bench* b = bp.get();
    for (int filter = 0; filter <= (opt.filtered ? 1 : 0); ++filter) {
      std::string bname = (filter ? "psf_render_filtered/" : "psf_render/") + b->name;
      const bool paired = have_mitsuba && !filter;
      benchmark::RegisterBenchmark(bname.c_str(), [b, &rt, &opt, filter, bname, paired, python, script,
                                                   peer_variant, threads](benchmark::State& state) {
        psf::Renderer renderer(rt, b->scene);
        renderer.render(render_options(*b, filter, opt.tail_paths));  // warm-up
        rt.finish();
        std::vector<double> wall, device, trace, download, add, peer;
        PeerRun first;  // the peer's first run, for its report
        bool peer_failed = false;
        double mean = 0;
        size_t nonfinite = 0;
        for (auto _ : state) {
          if (paired && !peer_failed) {  // the peer's render just before psf's
            PeerRun m = run_peer(*b, python, script, peer_variant, threads, 1);
            if (m.ok) {
              peer.push_back(m.times[0]);
              if (first.line.empty()) first = m;
            } else {
              peer_failed = true;
              report("%s: Mitsuba 3 failed: %s; tried: %s\n", b->name.c_str(),
                     m.line.empty() ? ("exit status " + std::to_string(m.status)).c_str()
                                    : json_raw(m.line, "error").c_str(),
                     json_raw(m.line, "tried").c_str());
            }
          }
          rt.reset_stats();
          psf::RenderResult r = renderer.render(render_options(*b, filter, opt.tail_paths));
          rt.finish();
          state.SetIterationTime(r.seconds);
          wall.push_back(r.seconds);
          trace.push_back(r.trace_seconds);
          download.push_back(r.download_seconds);
          add.push_back(r.add_seconds);
          double d = 0;
          for (const auto& [name, t] : rt.stats()) d += t.ms;
          device.push_back(d * 1e-3);
          double s = 0;
          for (float v : r.image.rgb) s += std::isfinite(v) ? v : 0.0;
          mean = r.image.rgb.empty() ? 0 : s / r.image.rgb.size();
          nonfinite = r.nonfinite;
        }
        Timing t = bench::summarize(wall), d = bench::summarize(device);
        double pps = b->paths / t.median_s;
        state.counters["Mpaths_per_s"] = pps * 1e-6;
        state.counters["Mpaths_per_s_best"] = b->paths / t.min_s * 1e-6;
        state.counters["device_ms_median"] = d.median_s * 1e3;
        report("%s: %dx%d %d spp: median %.1f ms, min %.1f ms, %.3f M paths/s (device time of all kernels %.1f "
               "ms); mean pixel %.4g\n",
               bname.c_str(), b->scene.width, b->scene.height, b->spp, t.median_s * 1e3, t.min_s * 1e3, pps * 1e-6,
               d.median_s * 1e3, mean);
        report("%s: wall by phase (medians): tracing%s to the kernels' end %.1f ms, downloads %.1f ms, host "
               "additions %.1f ms\n",
               bname.c_str(), filter ? " and filtering" : "", bench::summarize(trace).median_s * 1e3,
               bench::summarize(download).median_s * 1e3, bench::summarize(add).median_s * 1e3);
        if (nonfinite) report("%s: %zu paths with NaN/Inf radiance\n", bname.c_str(), nonfinite);
        std::vector<double> pair_ratios;  // psf / Mitsuba 3 per trial, each pair rendered back to back
        if (paired && !peer_failed && peer.size() == wall.size()) {
          const std::string& line = first.line;
          int w = int(json_number(line, "width")), h = int(json_number(line, "height"));
          const uint64_t peer_paths = uint64_t(w) * h * b->spp;
          Timing m = bench::summarize(peer);
          b->mitsuba_paths_per_s = peer_paths / m.median_s;
          b->mitsuba_variant = json_raw(line, "variant");
          for (size_t k = 0; k < wall.size(); ++k) pair_ratios.push_back((b->paths / wall[k]) / (peer_paths / peer[k]));
          state.counters["mitsuba_Mpaths_per_s"] = b->mitsuba_paths_per_s * 1e-6;
          state.counters["mitsuba_Mpaths_per_s_best"] = peer_paths / m.min_s * 1e-6;
          std::string removed = json_raw(line, "removed_properties");
          report("%s: Mitsuba %s %s, %s, %.0f threads: %dx%d %d spp: median %.1f ms, min %.1f ms, %.3f M paths/s "
                 "(each trial a process of its own, before psf's: load %.2f s, warm-up render %.2f s, not timed); "
                 "mean pixel %.4g%s%s%s\n",
                 b->name.c_str(), json_raw(line, "mitsuba").c_str(), b->mitsuba_variant.c_str(),
                 json_raw(line, "integrator").c_str(), json_number(line, "threads"), w, h, b->spp, m.median_s * 1e3,
                 m.min_s * 1e3, b->mitsuba_paths_per_s * 1e-6, json_number(line, "load_s"),
                 json_number(line, "warmup_s"), json_number(line, "mean"),
                 removed == "[]" ? "" : "; loaded after removing the properties Mitsuba 3 rejects: ",
                 removed == "[]" ? "" : removed.c_str(),
                 json_raw(line, "tried") == "[]" || json_raw(line, "tried").empty()
                     ? ""
                     : ("; failed before: " + json_raw(line, "tried")).c_str());
          if (w != b->scene.width || h != b->scene.height)
            report("%s: WARNING: Mitsuba's film is %dx%d, psf's %dx%d: compared per path\n", b->name.c_str(), w, h,
                   b->scene.width, b->scene.height);
        }
        if (b->mitsuba_paths_per_s > 0) {
          double ratio = pps / b->mitsuba_paths_per_s;
          state.counters["ratio_psf_mitsuba"] = ratio;
          std::string pairs;
          if (!pair_ratios.empty()) {
            const double paired_median = bench::summarize(pair_ratios).median_s;
            state.counters["ratio_paired_median"] = paired_median;
            char buf[64];
            for (double r : pair_ratios) {
              std::snprintf(buf, sizeof buf, "%s%.2f", pairs.empty() ? "" : ", ", r);
              pairs += buf;
            }
            std::snprintf(buf, sizeof buf, " (median %.2f)", paired_median);
            pairs = "; trial by trial " + pairs + buf;
            ratio = paired_median;  // the goal's figure: drift between the two runs cancels in each pair
          }
          report("%s: psf / Mitsuba 3 (%s) = %.3f / %.3f M paths/s = %.2f%s%s\n", bname.c_str(),
                 b->mitsuba_variant.c_str(), pps * 1e-6, b->mitsuba_paths_per_s * 1e-6,
                 pps / b->mitsuba_paths_per_s, pairs.c_str(),
                 filter ? "" : (ratio >= 1 ? " (goal >= 1: met)" : " (goal >= 1: NOT met)"));
        }
      })->UseManualTime()->Iterations(opt.trials)->Unit(benchmark::kMillisecond);
    }
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
