#include "session.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

namespace psf {

namespace {

volatile std::sig_atomic_t g_signal = 0;
extern "C" void on_signal(int sig) { g_signal = sig; }

// Installs SIGINT/SIGTERM handlers for the session's lifetime.
struct SignalGuard {
  void (*old_int)(int);
  void (*old_term)(int);
  SignalGuard() {
    g_signal = 0;
    old_int = std::signal(SIGINT, on_signal);
    old_term = std::signal(SIGTERM, on_signal);
  }
  ~SignalGuard() {
    std::signal(SIGINT, old_int);
    std::signal(SIGTERM, old_term);
  }
};

uint64_t fnv1a(const void* data, size_t n, uint64_t h = 1469598103934665603ull) {
  const unsigned char* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

std::string options_text(const RenderOptions& o) {
  std::ostringstream s;
  s << "seed=" << o.seed << " max_depth=" << o.max_depth << " rr_depth=" << o.rr_depth
    << " filter=" << (o.filter.enabled ? "psf" : "off");
  if (o.emission_rays > 0) s << " emission_rays=" << o.emission_rays;
  if (o.filter.enabled)
    s << " alpha=" << o.filter.alpha << " r0=" << o.filter.r0 << " footprint=" << o.filter.footprint_pixels
      << " foreshortening=" << o.filter.foreshortening
      << " iterations=" << o.filter.iterations << " normal=" << o.filter.normal_cos << " albedo="
      << (o.filter.demodulate ? o.filter.albedo_log2_tol : o.filter.albedo_tol)
      << (o.filter.demodulate ? " demodulate=1" : "")
      << " cells27=" << o.filter.cells27 << " min_removed=" << o.filter.min_removed;
  if (o.filter.enabled) {
    s << " visibility_ray=";
    if (o.filter.visibility_ray == kVisibilityRayAuto) s << "auto";
    else if (o.filter.visibility_ray == kVisibilityRayOff) s << "off";
    else s << o.filter.visibility_ray;
  }
  s << " aovs=" << o.aovs;
  return s.str();
}

std::vector<DeviceInfo> session_devices(const std::string& spec) {
  if (spec == "all") return list_devices();
  std::vector<DeviceInfo> out;
  size_t b = 0;
  do {
    size_t e = spec.find(',', b);
    if (e == std::string::npos) e = spec.size();
    out.push_back(choose_device(spec.substr(b, e - b)));
    b = e + 1;
  } while (b <= spec.size() && spec.find(',') != std::string::npos);
  return out;
}

// The state layers: per-pixel sums of the batches in the state.
const char* kStateFiltered = "psf.state.filtered";
const char* kStateCounts = "psf.state.counts";
const char* kStateUnfiltered = "psf.state.unfiltered";
const char* kStateBad = "psf.state.bad";
const char* kStateBadUnfiltered = "psf.state.bad_unfiltered";
const char* kStateAov = "psf.state.aov";

std::vector<float> gather(const std::vector<float>& v, size_t stride, size_t offset, size_t count) {
  size_t n = v.size() / stride;
  std::vector<float> out(n * count);
  for (size_t i = 0; i < n; ++i)
    for (size_t c = 0; c < count; ++c) out[i * count + c] = v[i * stride + offset + c];
  return out;
}

std::vector<float> as_float(const std::vector<uint32_t>& v) { return std::vector<float>(v.begin(), v.end()); }

// The scene hash of `scene` as loaded from o.scene_path: its film size, and with a
// crop window the film's size and the window's corner too (--width and --height
// scale them, and two films may round to windows of one size).
std::string hash_of(const SessionOptions& o, const Scene& scene) {
  std::vector<std::pair<std::string, std::string>> params = o.params;
  const CameraDesc& c = scene.camera;
  if (c.film_width > 0)
    params.emplace_back("psf:film", std::to_string(c.film_width) + "x" + std::to_string(c.film_height) + "+" +
                                        std::to_string(c.crop_x) + "+" + std::to_string(c.crop_y));
  return scene_hash(o.scene_path, params, scene.width, scene.height);
}

class Writer {
 public:
  Writer(const SessionOptions& o, const Scene& scene, int batch_log2)
      : o_(o), batch_log2_(batch_log2), hash_(hash_of(o, scene)) {}

  // Writes the image of `shown` with the resume state of `state` (the batches
  // that a resumed render may continue from).
  void write(const Accumulator& shown, const Accumulator& state, uint64_t filter_off_after) const {
    Image img = shown.image();
    std::vector<ExrLayer> layers;
    if (o_.aov_unfiltered) layers.push_back({"unfiltered", 3, shown.unfiltered_image().rgb});
    if (o_.aov_neighbours) layers.push_back({"neighbours", 1, shown.neighbours()});
    if (o_.aov_albedo) layers.push_back({"albedo", 3, shown.aov_layer(0)});
    if (o_.aov_normal) layers.push_back({"normal", 3, shown.aov_layer(1)});
    if (o_.aov_depth) layers.push_back({"depth", 1, shown.aov_layer(2)});
    layers.push_back({kStateFiltered, 3, gather(state.filtered, 4, 0, 3)});
    layers.push_back({kStateCounts, 1, gather(state.filtered, 4, 3, 1)});
    layers.push_back({kStateUnfiltered, 3, gather(state.unfiltered, 4, 0, 3)});
    layers.push_back({kStateBad, 1, as_float(state.bad_filtered)});
    layers.push_back({kStateBadUnfiltered, 1, as_float(state.bad_unfiltered)});
    if (!state.aov.empty()) {
      layers.push_back({std::string(kStateAov) + "0", 3, gather(state.aov, 8, 0, 3)});
      layers.push_back({std::string(kStateAov) + "1", 1, gather(state.aov, 8, 3, 1)});
      layers.push_back({std::string(kStateAov) + "2", 3, gather(state.aov, 8, 4, 3)});
      layers.push_back({std::string(kStateAov) + "3", 1, gather(state.aov, 8, 7, 1)});
    }
    uint64_t pixels = uint64_t(shown.width) * shown.height;
    std::map<std::string, std::string> attrs = {
        {"psf:version", PSF_VERSION},
        {"psf:scene", o_.scene_path},
        {"psf:scene_hash", hash_},
        {"psf:options", options_text(o_.render)},
        {"psf:batch_log2", std::to_string(batch_log2_)},
        {"psf:state_batches", std::to_string(state.next_batch)},
        {"psf:state_paths", std::to_string(state.paths)},
        {"psf:paths", std::to_string(shown.paths)},
        {"psf:spp", std::to_string(double(shown.paths) / double(pixels))},
        {"psf:filter_off_after", std::to_string(filter_off_after)},
    };
    write_exr(o_.output, img, attrs, layers);
    if (!o_.png.empty()) write_png(o_.png, img);
  }

 private:
  const SessionOptions& o_;
  int batch_log2_;
  std::string hash_;
};

}  // namespace

// Loads the state of `path` into `acc` after checking it belongs to this render.
ResumeState load_state(const std::string& path, const std::string& hash, const std::string& options, Accumulator& acc) {
  ExrFile f = read_exr_file(path);
  auto attr = [&](const char* name) {
    auto it = f.attributes.find(name);
    if (it == f.attributes.end())
      throw std::invalid_argument("--resume " + path + ": not a psf render (no " + name + " attribute)");
    return it->second;
  };
  ResumeState st;
  // Another psf may render the same scene and options differently (a BSDF or
  // the filter's radius changed): its sums cannot be continued.
  const std::string version = attr("psf:version");
  if (version != PSF_VERSION)
    throw std::invalid_argument("--resume " + path + ": rendered by psf " + version + ", not by this psf " +
                                PSF_VERSION + ", whose images of the scene may differ");
  st.scene_hash = attr("psf:scene_hash");
  st.options = attr("psf:options");
  if (st.scene_hash != hash)
    throw std::invalid_argument("--resume " + path + ": rendered from another scene, parameters or film size");
  if (st.options != options)
    throw std::invalid_argument("--resume " + path + ": rendered with other options (" + st.options + "; now " +
                                options + ")");
  try {
    st.batch_log2 = std::stoi(attr("psf:batch_log2"));
    st.next_batch = std::stoull(attr("psf:state_batches"));
    st.filter_off_after = std::stoull(attr("psf:filter_off_after"));
    acc.paths = std::stoull(attr("psf:state_paths"));
    st.shown_paths = std::stoull(attr("psf:paths"));
  } catch (const std::logic_error&) {
    throw std::invalid_argument("--resume " + path + ": malformed state attributes");
  }
  if (f.width != acc.width || f.height != acc.height)
    throw std::invalid_argument("--resume " + path + ": another film size");
  auto channel = [&](const std::string& name) -> const std::vector<float>& {
    auto it = f.channels.find(name);
    if (it == f.channels.end()) throw std::invalid_argument("--resume " + path + ": no state channel " + name);
    return it->second;
  };
  const size_t n = size_t(acc.width) * acc.height;
  const uint64_t pixels = n;
  for (size_t i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) {
      const char* rgb = c == 0 ? ".R" : c == 1 ? ".G" : ".B";
      acc.filtered[i * 4 + c] = channel(std::string(kStateFiltered) + rgb)[i];
      acc.unfiltered[i * 4 + c] = channel(std::string(kStateUnfiltered) + rgb)[i];
    }
    acc.filtered[i * 4 + 3] = channel(std::string(kStateCounts) + ".Y")[i];
    acc.unfiltered[i * 4 + 3] = float(acc.paths / pixels + (i < acc.paths % pixels ? 1 : 0));
    acc.bad_filtered[i] = uint32_t(channel(std::string(kStateBad) + ".Y")[i]);
    acc.bad_unfiltered[i] = uint32_t(channel(std::string(kStateBadUnfiltered) + ".Y")[i]);
    if (!acc.aov.empty()) {
      const char* rgb[3] = {".R", ".G", ".B"};
      for (int c = 0; c < 3; ++c) {
        acc.aov[i * 8 + c] = channel(std::string(kStateAov) + "0" + rgb[c])[i];
        acc.aov[i * 8 + 4 + c] = channel(std::string(kStateAov) + "2" + rgb[c])[i];
      }
      acc.aov[i * 8 + 3] = channel(std::string(kStateAov) + "1.Y")[i];
      acc.aov[i * 8 + 7] = channel(std::string(kStateAov) + "3.Y")[i];
    }
  }
  acc.next_batch = st.next_batch;
  return st;
}

namespace {

std::string clock_text(double s) {
  char buf[32];
  int t = int(s + 0.5);
  std::snprintf(buf, sizeof buf, "%02d:%02d:%02d", t / 3600, t / 60 % 60, t % 60);
  return buf;
}

}  // namespace

std::string scene_hash(const std::string& path, const std::vector<std::pair<std::string, std::string>>& params,
                       int width, int height) {
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  uint64_t h = fnv1a(bytes.data(), bytes.size());
  for (const auto& [k, v] : params) {
    h = fnv1a(k.data(), k.size(), h);
    h = fnv1a("=", 1, h);
    h = fnv1a(v.data(), v.size(), h);
  }
  int size[2] = {width, height};
  h = fnv1a(size, sizeof size, h);
  char buf[24];
  std::snprintf(buf, sizeof buf, "%016llx", (unsigned long long)h);
  return buf;
}

SessionResult run_session(const Scene& scene, const SessionOptions& o) {
  SessionResult result;
  const uint64_t pixels = uint64_t(scene.width) * scene.height;
  const bool time_only = o.time_limit > 0 && o.render.spp <= 0;
  const uint64_t spp = time_only ? (uint64_t(1) << 24) : uint64_t(std::max(o.render.spp, 1));
  const uint64_t total = pixels * spp;
  RenderOptions ro = o.render;
  ro.aovs = o.aov_albedo || o.aov_normal || o.aov_depth;

  // Devices: one runtime and renderer each.
  std::vector<DeviceInfo> infos = session_devices(o.device);
  std::vector<std::unique_ptr<Runtime>> runtimes;
  std::vector<std::unique_ptr<Renderer>> renderers;
  for (const auto& d : infos) {
    runtimes.push_back(std::make_unique<Runtime>(d));
    renderers.push_back(std::make_unique<Renderer>(*runtimes.back(), scene));
    if (!o.quiet)
      std::cerr << "psf: device " << d.index << ": " << d.name << " (" << d.platform << "), "
                << format_bytes(d.global_mem) << ", program built in " << runtimes.back()->build_seconds() << " s\n";
  }

  // State: a fresh accumulator or the one a previous run left in --resume.
  Accumulator acc;
  acc.reset(scene.width, scene.height, ro.aovs);
  ResumeState resumed;
  const std::string hash = hash_of(o, scene);
  if (!o.resume.empty()) {
    resumed = load_state(o.resume, hash, options_text(ro), acc);
    // Its image may hold more paths than its state (a last batch cut short by
    // --spp): a render to fewer would replace a better image by a worse one.
    const uint64_t held = std::max(acc.paths, resumed.shown_paths);
    if (held > total)
      throw std::invalid_argument("--resume " + o.resume + ": it already holds " + std::to_string(held / pixels) +
                                  " spp, more than --spp " + std::to_string(spp));
  }

  // Batch size: the largest 2^m every device holds (or the resumed run's).
  uint64_t global_mem = UINT64_MAX, max_alloc = UINT64_MAX;
  for (const auto& d : infos) {
    global_mem = std::min(global_mem, d.global_mem);
    max_alloc = std::min(max_alloc, d.max_alloc);
  }
  const auto needs = Renderer::batch_needs(ro.filter.enabled, ro.aovs, ro.filter.iterations);
  BatchPlan plan;
  try {
    const int most_default = o.max_batch_log2 > 0 ? o.max_batch_log2
                                                  : default_batch_log2(uint64_t(scene.width) * scene.height);
    int most = o.resume.empty() ? most_default : resumed.batch_log2;
    int least = o.resume.empty() ? 6 : resumed.batch_log2;
    plan = plan_batch(needs, renderers[0]->fixed_bytes(), global_mem, max_alloc, o.memory_budget, most, least);
  } catch (const std::runtime_error& e) {
    if (o.memory_budget) throw std::invalid_argument(std::string("--memory-budget: ") + e.what());
    throw;
  }
  for (;;) {
    try {
      for (auto& r : renderers) r->prepare(ro, plan.log2, time_only ? 0 : total);
      break;
    } catch (const ClError& e) {
      bool memory = e.code() == CL_MEM_OBJECT_ALLOCATION_FAILURE || e.code() == CL_OUT_OF_RESOURCES ||
                    e.code() == CL_OUT_OF_HOST_MEMORY;
      if (!memory || plan.log2 <= 6 || !o.resume.empty()) throw;
      if (!o.quiet) std::cerr << "psf: " << e.what() << ": halving the batch to 2^" << plan.log2 - 1 << " paths\n";
      plan.log2 -= 1;
    }
  }
  const uint64_t batch = uint64_t(1) << plan.log2;
  result.batch_log2 = plan.log2;
  if (!o.quiet)
    std::cerr << "psf: " << scene.triangles.size() << " triangles, "
              << (scene.spheres.empty() ? std::string() : std::to_string(scene.spheres.size()) + " spheres, ")
              << scene.width << "x" << scene.height << ", "
              << (time_only ? std::string("until --time") : std::to_string(spp) + " spp") << "; batches of 2^"
              << plan.log2 << " = " << batch << " paths, "
              << (!time_only && total < batch ? "buffers for the " + std::to_string(total) + " it traces"
                                              : format_bytes(plan.bytes) + " of batch buffers")
              << "\n";
  if (!o.quiet) {
    const BvhSummary& b = renderers[0]->bvh_summary();
    char added[64] = "";
    if (b.references > b.primitives)
      std::snprintf(added, sizeof added, " (+%.1f %% by spatial splits)",
                    100.0 * (b.references - b.primitives) / std::max(1u, b.primitives));
    std::cerr << "psf: BVH: " << b.references << " references to " << b.primitives << " primitives" << added << ", "
              << b.nodes << " nodes and " << b.packs << " packs, " << format_bytes(b.bytes) << ", built in "
              << std::lround(b.build_ms) << " ms\n";
  }

  // Batches are handed to the devices round-robin and added in index order.
  const uint64_t batches = (total + batch - 1) / batch;
  const uint64_t first_batch = acc.next_batch;
  std::atomic<bool> stop{false};
  std::atomic<bool> filter_off{resumed.filter_off_after > 0};
  uint64_t filter_off_after = resumed.filter_off_after;
  std::mutex mu;
  std::condition_variable cv;
  std::map<uint64_t, BatchImages> done;
  std::exception_ptr failure;
  const size_t D = renderers.size();
  auto worker = [&](size_t d) {
    try {
      for (uint64_t b = first_batch + d; b < batches && !stop; b += D) {
        {
          std::unique_lock<std::mutex> lock(mu);  // stay at most 2 batches per device ahead
          cv.wait(lock, [&] { return stop || b < acc.next_batch + 2 * D; });
          if (stop) return;
        }
        BatchImages img = renderers[d]->trace_batch(b, total, ro.filter.enabled && !filter_off);
        std::lock_guard<std::mutex> lock(mu);
        done.emplace(b, std::move(img));
        cv.notify_all();
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(mu);
      if (!failure) failure = std::current_exception();
      stop = true;
      cv.notify_all();
    }
  };

  SignalGuard signals;
  Writer writer(o, scene, plan.log2);
  Accumulator state;  // the resume state when the last batch is partial
  bool state_saved = false;
  const bool bar = o.progress && !o.quiet && isatty(STDERR_FILENO);
  const auto t0 = std::chrono::steady_clock::now();
  auto last_checkpoint = t0;
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  const uint64_t start_paths = acc.paths;
  // Filtering's share of the noise, batch by batch (render.h); after a resume it
  // starts again from the batches rendered since.
  NoiseMonitor monitor;
  const bool monitor_on = ro.filter.enabled && !filter_off && ro.filter.min_removed > 0.0f;
  if (monitor_on) monitor.reset(uint64_t(scene.width) * scene.height);

  std::vector<std::thread> threads;
  for (size_t d = 0; d < D; ++d) threads.emplace_back(worker, d);
  while (acc.next_batch < batches) {
    BatchImages img;
    {
      std::unique_lock<std::mutex> lock(mu);
      cv.wait_for(lock, std::chrono::milliseconds(200), [&] { return failure || done.count(acc.next_batch); });
      if (failure) break;
      if (g_signal && !stop) stop = true;
      auto it = done.find(acc.next_batch);
      if (it == done.end()) {
        if (stop) break;
        continue;
      }
      img = std::move(it->second);
      done.erase(it);
    }
    // A batch filtered on a device that had not yet heard of the switch-off is
    // added unfiltered, so the image does not depend on the devices' timing.
    if (filter_off) img.filtered.clear();  // empty: add the unfiltered contributions
    if (img.unfiltered.size() < batch && !state_saved) {  // the last, partial batch
      state = acc;
      state_saved = true;
    }
    {
      std::lock_guard<std::mutex> lock(mu);  // workers read acc.next_batch
      acc.add(img);
    }
    cv.notify_all();
    if (ro.filter.enabled && !filter_off) {
      const double removed = monitor_on ? monitor.add(img) : std::nan("");
      if (img.max_count <= 1 || removed < ro.filter.min_removed) {
        filter_off = true;
        filter_off_after = acc.paths;
        if (!o.quiet) {
          std::cerr << (bar ? "\n" : "") << "psf: path space filtering switched itself off after " << acc.paths
                    << " paths (" << acc.paths / (uint64_t(scene.width) * scene.height) << " spp): ";
          if (img.max_count <= 1)
            std::cerr << "no vertex had a neighbour any more\n";
          else {
            char text[96];  // formatted apart: a precision set on std::cerr would outlive this line
            std::snprintf(text, sizeof(text), "%.1f %% of the noise, less than --min-removed %g (%.1f %%)",
                          100.0 * removed, double(ro.filter.min_removed), 100.0 * ro.filter.min_removed);
            std::cerr << "its last batch removed " << text << "\n";
          }
        }
      }
    }
    renderers[(img.index - first_batch) % D]->recycle(std::move(img));
    double t = elapsed();
    if (bar) {
      double done_frac = time_only ? std::min(1.0, t / o.time_limit)
                                   : double(acc.paths - start_paths) / double(total - start_paths);
      int w = 30, fill = int(done_frac * w);
      double rate = double(acc.paths - start_paths) / std::max(t, 1e-9);
      double eta = done_frac > 0 ? t / done_frac - t : 0;
      std::fprintf(stderr, "\r[%s%s] batch %llu/%llu  %.2f M paths/s  %s elapsed  ETA %s ",
                   std::string(fill, '=').c_str(), std::string(w - fill, ' ').c_str(),
                   (unsigned long long)acc.next_batch, (unsigned long long)batches, rate / 1e6, clock_text(t).c_str(),
                   clock_text(eta).c_str());
      std::fflush(stderr);
    }
    if (g_signal) stop = true;
    if (o.time_limit > 0 && t >= o.time_limit) stop = true;
    if (stop) break;
    if (o.checkpoint_seconds > 0 &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - last_checkpoint).count() >=
            o.checkpoint_seconds) {
      writer.write(acc, state_saved ? state : acc, filter_off_after);
      last_checkpoint = std::chrono::steady_clock::now();
    }
  }
  stop = true;
  cv.notify_all();
  for (auto& t : threads) t.join();
  if (bar) std::fputc('\n', stderr);
  if (failure) std::rethrow_exception(failure);

  result.seconds = elapsed();
  writer.write(acc, state_saved ? state : acc, filter_off_after);
  result.paths = acc.paths;
  result.nonfinite = acc.nonfinite();
  result.interrupted = g_signal != 0;
  result.signal = g_signal;
  result.filter_off_after = filter_off_after;
  for (auto& rt : runtimes)
    for (const auto& [name, t] : rt->stats()) {
      bool filter_stage = name == "cell_keys" || name.rfind("radix_", 0) == 0 || name.rfind("cell_ranges", 0) == 0 ||
                          name == "gather_tuples" || name.rfind("filter", 0) == 0 || name == "scatter_values";
      (filter_stage ? result.filter_ms : result.trace_ms) += t.ms;
    }
  if (o.stats) {
    std::map<std::string, KernelTime> all;
    for (auto& rt : runtimes)
      for (const auto& [name, t] : rt->stats()) {
        all[name].launches += t.launches;
        all[name].ms += t.ms;
      }
    std::printf("%-24s %10s %12s %12s\n", "kernel", "launches", "total ms", "ms/launch");
    for (const auto& [name, t] : all)
      std::printf("%-24s %10llu %12.3f %12.4f\n", name.c_str(), (unsigned long long)t.launches, t.ms,
                  t.ms / double(t.launches));
  }
  return result;
}

}  // namespace psf
