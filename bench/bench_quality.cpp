// bench_quality: equal-time image quality of plain path tracing (pt), path space
// filtering (psf, 1 averaging pass) and path space filtering with 2, 4 and 8 passes (psf2,
// psf4, psf8), and any --method's, as relMSE against a reference.
//
// relMSE = mean over pixels and channels of (x - y)^2 / (y^2 + 0.01) (x the
// render, y the reference).
// Reference: for the living-room, Tungsten's TungstenRender.exr (same camera and
//   film; psf still approximates some of its materials, so a bias remains); for
//   other scenes a long plain path tracing render of psf itself (--ref_spp, default
//   4096, with another seed than the measured renders so their errors are
//   independent), cached as <build>/quality/<scene>_ref_<spp>spp_<w>x<h>.exr
//   (--ref_refresh=1 renders it again; delete it after renderer changes).
// quality/<scene>/<method>/spp:<N>: one render of N spp (N = 1, 2, 4, ... up to
//   the scene's maximum: --max_spp, default 1024, living-room 16), its wall time
//   (RenderResult::seconds, median of --repeats renders for N <= 64; also the process's
//   CPU time, which shows contention) and relMSE (the mean over the renders,
//   each with its own seed, and their range): the convergence curve
//   (bench/plot_quality.py plots it).
//   The curve is measured interleaved (every method at 1 spp, then at 2, ...).
// equal_time/<scene>/spp:<N> for N in --equal (default 4,16,64,1024): the wall
//   time t of pt at N spp (the fastest repeat); the filtered methods get the largest spp
//   count s whose time stays within 1.1 t (first guess s = N t / t_method(N), then
//   refined by measured times, up to 5 renders; 1 spp if even that takes longer);
//   reported: s, the actual times, relMSE and relMSE(pt) / relMSE(method).
//   --time=cpu compares the process's CPU time instead of wall time: on a machine
//   shared with other work, wall time depends on their load, CPU time much less.
// Goals: >= 10x lower relMSE than pt at equal time at 4 spp; never worse at 1024.
// Side-by-side images (pt | psf | psf2 | reference, the whole image or a crop)
// at the --crops spp counts (--crops= for none) go to --images (default <build>/quality).
//
// A scene is skipped when it has no light (e.g. the living-room while its envmap
// is not supported) or no reference.
//
// Usage: bench_quality [benchmark flags] [--scene=PATH ...] [--equal=4,16,64,1024] [--max_spp=N]
//                      [--ref_spp=N] [--ref_refresh=1] [--images=DIR] [--crops=4,64] [--time=wall|cpu]
//                      [--method=NAME:PASSES[:demodulate][:batch=N][:visibility=off][:emission=K] ...]
//                      [--methods=psf,psf2,...]
//                      [--repeats=N]
// --methods keeps only the named ones of the default filtered methods (psf, psf2,
// psf4, psf8; pt always runs); --repeats sets the renders per point up to 64 spp
// (default 3; one above): the living room at 64 spp takes minutes per render.
// Repeat k renders with --seed k, and a point's relMSE is the mean over its
// repeats: a filtered render's relMSE at a few spp varies by up to 1.5x from seed
// to seed (the Cornell box's 16 passes at 3 spp: 0.0031-0.0045 over 8 seeds),
// plain path tracing's by a few per cent.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <algorithm>
#include <cctype>
#include <optional>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <set>
#include <sstream>

#include "bench_common.h"
#include "image.h"
#include "render.h"
#include "scene/scene.h"

namespace {

using bench::report;

struct Options {
  std::vector<std::string> scenes;              // scene files; empty: the defaults
  std::vector<int> equal = {4, 16, 64, 1024};   // pt spp counts of the equal-time rows
  std::vector<int> crops = {4, 64};             // rows that get side-by-side images
  int max_spp = 0;                              // 0: per scene (living-room 16, others 1024)
  int ref_spp = 4096;                           // spp of a rendered reference
  bool ref_refresh = false;                     // render the reference even when cached
  std::string images;                           // folder of the PNGs
};

struct Method {
  std::string name;         // pt, psf, psf2, psf4, psf8, or a --method's
  bool filter;              // path space filtering on
  int iterations;           // averaging passes
  bool demodulate = false;  // --demodulate
  int batch_log2 = 0;       // --batch-log2; 0: the renderer's default
  bool visibility_off = false;  // --visibility-ray off
  int emission_rays = 0;        // --emission-rays
};
// psf4, psf8: 4 and 8 passes, since the passes after the first average over the
// first's records instead of searching (filter.cl filter_lists) and cost a fraction of it.
// --method=NAME:PASSES[:demodulate][:batch=N][:visibility=off][:emission=K] adds a
// method with those options (batch=N: batches of 2^N paths, --batch-log2 N;
// emission=K: --emission-rays K); 0 passes: plain path tracing with them.
std::vector<Method> g_methods = {{"pt", false, 1}, {"psf", true, 1}, {"psf2", true, 2}, {"psf4", true, 4}, {"psf8", true, 8}};

// A whole decimal number of at most `digits` digits, or -1.
int whole_number(const std::string& t, size_t digits) {
  if (t.empty() || t.size() > digits || t.find_first_not_of("0123456789") != std::string::npos) return -1;
  return std::stoi(t);
}

// Parses --method's value; false (with a message) when it is malformed.
bool parse_method(const std::string& spec, Method& m) {
  std::vector<std::string> parts;
  std::stringstream in(spec);
  std::string item;
  while (std::getline(in, item, ':')) parts.push_back(item);
  m = {"", true, 1};
  auto number = [](const std::string& t) { return whole_number(t, 3); };
  // Names are letters and digits (they become parts of benchmark and counter
  // names) and differ from every other method's: a shared name would mix their results.
  bool ok = parts.size() >= 2 && !parts[0].empty() &&
            std::all_of(parts[0].begin(), parts[0].end(), [](unsigned char c) { return std::isalnum(c) != 0; }) &&
            std::none_of(g_methods.begin(), g_methods.end(), [&](const Method& o) { return o.name == parts[0]; });
  if (ok) m.name = parts[0], m.iterations = number(parts[1]);
  for (size_t k = 2; ok && k < parts.size(); ++k) {
    if (parts[k] == "demodulate") m.demodulate = true;
    else if (parts[k].rfind("batch=", 0) == 0) ok = (m.batch_log2 = number(parts[k].substr(6))) >= 6 && m.batch_log2 <= 26;
    else if (parts[k] == "visibility=off") m.visibility_off = true;
    else if (parts[k].rfind("emission=", 0) == 0) ok = (m.emission_rays = number(parts[k].substr(9))) >= 1 && m.emission_rays <= 64;
    else ok = false;
  }
  ok = ok && m.iterations >= 0 && m.iterations <= 64;
  m.filter = m.iterations > 0;
  m.iterations = std::max(m.iterations, 1);
  if (!ok)
    std::fprintf(stderr,
                 "bench_quality: --method=%s: expected NAME:PASSES[:demodulate][:batch=N][:visibility=off][:emission=K], "
                 "NAME letters and digits "
                 "and not another method's, PASSES 0-64 (0: plain path tracing), batches of 2^N paths with N 6-26, K 1-64\n",
                 spec.c_str());
  return ok;
}

// --time=cpu: equal time means equal CPU time of the process instead of wall time.
bool g_cpu_time = false;

struct Point {
  int spp = 0;
  double seconds = 0;      // wall time of the render (median of the repeats)
  double min_seconds = 0;  // wall time, the fastest repeat
  double cpu_seconds = 0;  // CPU time of this process (all threads), the least of the repeats: less
                           // sensitive to other processes on the machine (contention shows as cpu << wall * cores)
  double cost = 0;         // what equal time compares: min_seconds, or cpu_seconds with --time=cpu
  double relmse = 0;      // mean over the repeats (seeds 0, 1, ...)
  double relmse_min = 0, relmse_max = 0;  // the repeats' least and largest
  psf::Image image;       // seed 0's
};

struct Bench {
  std::string name, path;
  psf::Scene scene;
  psf::Image reference;
  std::string reference_source;
  int max_spp = 1024;
  std::unique_ptr<psf::Renderer> renderer;
  std::map<std::string, std::map<int, Point>> points;  // method -> spp -> result
};

double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double relmse(const psf::Image& x, const psf::Image& y) {
  double sum = 0;
  for (size_t i = 0; i < x.rgb.size(); ++i) {
    double d = double(x.rgb[i]) - y.rgb[i];
    sum += d * d / (double(y.rgb[i]) * y.rgb[i] + 0.01);
  }
  return x.rgb.empty() ? 0 : sum / x.rgb.size();
}

// A comma-separated list of spp counts (--equal, --crops); a malformed one exits with status 2.
std::vector<int> parse_list(const char* key, const std::string& s) {
  std::vector<int> v;
  std::stringstream in(s);
  std::string item;
  while (std::getline(in, item, ',')) {
    if (item.empty()) continue;
    const int n = whole_number(item, 9);
    if (n < 1) {
      std::fprintf(stderr, "bench_quality: --%s=%s: expected spp counts (1 or more) separated by commas\n", key,
                   s.c_str());
      std::exit(2);
    }
    v.push_back(n);
  }
  return v;
}

psf::RenderOptions options(const Bench& b, const Method& m, int spp, uint32_t seed = 0) {
  psf::RenderOptions o;
  o.spp = spp;
  o.seed = seed;
  o.max_depth = b.scene.max_depth;
  o.rr_depth = b.scene.rr_depth;
  o.filter.enabled = m.filter;
  o.filter.iterations = m.iterations;
  o.filter.demodulate = m.demodulate;
  if (m.batch_log2 > 0) o.batch_log2 = m.batch_log2;
  if (m.visibility_off) o.filter.visibility_ray = psf::kVisibilityRayOff;
  o.emission_rays = m.emission_rays;
  return o;
}

// Renders `spp` with method m `repeats` times, repeat k with seed k: the median
// and least times, and the mean relMSE.
Point render(psf::Runtime& rt, Bench& b, const Method& m, int spp, int repeats) {
  std::vector<std::pair<double, double>> t;  // (wall, cpu)
  Point p;
  p.spp = spp;
  double sum = 0;
  for (int k = 0; k < repeats; ++k) {
    double c0 = cpu_seconds();
    psf::RenderResult r = b.renderer->render(options(b, m, spp, uint32_t(k)));
    rt.finish();
    t.push_back({r.seconds, cpu_seconds() - c0});
    const double e = relmse(r.image, b.reference);
    sum += e;
    p.relmse_min = k == 0 ? e : std::min(p.relmse_min, e);
    p.relmse_max = k == 0 ? e : std::max(p.relmse_max, e);
    if (k == 0) p.image = std::move(r.image);
  }
  p.relmse = sum / repeats;
  std::sort(t.begin(), t.end());
  p.seconds = t[t.size() / 2].first;
  p.min_seconds = t.front().first;
  p.cpu_seconds = t.front().second;
  for (const auto& w : t) p.cpu_seconds = std::min(p.cpu_seconds, w.second);
  p.cost = g_cpu_time ? p.cpu_seconds : p.min_seconds;
  return p;
}

int g_repeats = 3;  // --repeats: renders per point up to 64 spp

int repeats_for(int spp) { return spp <= 64 ? g_repeats : 1; }

// Side by side, 4 px white gaps: pt | psf | psf2 | reference (by default), the whole image when
// it is at most 320 px wide, else a 320 x 240 crop about the centre.
void write_side_by_side(const std::string& path, const std::vector<const psf::Image*>& images) {
  const psf::Image& first = *images.front();
  int cw = std::min(first.width, 320), ch = std::min(first.height, first.width <= 320 ? first.height : 240);
  int x0 = (first.width - cw) / 2, y0 = (first.height - ch) / 2;
  const int gap = 4;
  psf::Image out;
  out.width = int(images.size()) * cw + (int(images.size()) - 1) * gap;
  out.height = ch;
  out.rgb.assign(size_t(out.width) * out.height * 3, 1.0f);
  for (size_t k = 0; k < images.size(); ++k)
    for (int y = 0; y < ch; ++y)
      for (int x = 0; x < cw; ++x)
        for (int c = 0; c < 3; ++c)
          out.rgb[(size_t(y) * out.width + k * (cw + gap) + x) * 3 + c] =
              images[k]->rgb[(size_t(y0 + y) * images[k]->width + x0 + x) * 3 + c];
  psf::write_png(path, out);
}

bool has_light(const psf::Scene& s) {
  if (!s.lights.empty()) return true;
  for (const auto& m : s.materials)
    if (m.emission.s[0] > 0 || m.emission.s[1] > 0 || m.emission.s[2] > 0) return true;
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  Options opt;
  bench::Args args(argc, argv, "bench_quality");
  opt.scenes = args.take_all("scene");
  std::string s;
  if (args.take("equal", s)) opt.equal = parse_list("equal", s);
  if (args.take("crops", s)) opt.crops = parse_list("crops", s);
  args.take_number("max_spp", opt.max_spp);
  args.take_number("ref_spp", opt.ref_spp);
  int refresh = 0;
  args.take_number("ref_refresh", refresh);
  opt.ref_refresh = refresh != 0;
  opt.images = (bench::fs::path(PSF_BINARY_DIR) / "quality").string();
  args.take("images", opt.images);
  if (args.take("methods", s)) {
    // The default filtered methods to keep (pt always runs).
    std::set<std::string> keep;
    for (std::stringstream in(s); std::getline(in, s, ',');)
      if (!s.empty()) keep.insert(s);
    for (const std::string& name : keep)
      if (name == "pt" || std::none_of(g_methods.begin(), g_methods.end(), [&](const Method& m) { return m.name == name; })) {
        std::fprintf(stderr, "bench_quality: --methods: %s is not one of psf, psf2, psf4, psf8\n", name.c_str());
        return 2;
      }
    g_methods.erase(std::remove_if(g_methods.begin() + 1, g_methods.end(),
                                   [&](const Method& m) { return !keep.count(m.name); }),
                    g_methods.end());
  }
  args.take_number("repeats", g_repeats);
  if (g_repeats < 1) {
    std::fprintf(stderr, "bench_quality: --repeats=%d: expected at least 1\n", g_repeats);
    return 2;
  }
  benchmark::AddCustomContext("repeats", std::to_string(g_repeats) +
                                             " render(s) per point up to 64 spp (seeds 0, 1, ...; relMSE their mean), "
                                             "1 above");
  for (const std::string& spec : args.take_all("method")) {
    Method m;
    if (!parse_method(spec, m)) return 2;
    g_methods.push_back(m);
    benchmark::AddCustomContext("method_" + m.name, (m.filter ? std::to_string(m.iterations) + " passes" : "plain") +
                                                        (m.demodulate ? ", --demodulate" : "") +
                                                        (m.batch_log2 ? ", batches of 2^" + std::to_string(m.batch_log2) : "") +
                                                        (m.visibility_off ? ", --visibility-ray off" : "") +
                                                        (m.emission_rays ? ", --emission-rays " + std::to_string(m.emission_rays) : ""));
  }
  if (args.take("time", s)) {
    if (s != "wall" && s != "cpu") {
      std::fprintf(stderr, "bench_quality: --time=%s: expected wall or cpu\n", s.c_str());
      return 2;
    }
    g_cpu_time = s == "cpu";
  }
  if (!args.done()) return 2;
  if (opt.scenes.empty())
    opt.scenes = {(bench::fs::path(PSF_SOURCE_DIR) / "scenes/cornell-box.xml").string(),
                  bench::shared_path("scenes/living-room/scene.xml")};
  const std::string cache = (bench::fs::path(PSF_BINARY_DIR) / "quality").string();
  bench::fs::create_directories(cache);
  bench::fs::create_directories(opt.images);

  psf::DeviceInfo dev = psf::choose_device(std::getenv("PSF_DEVICE") ? std::getenv("PSF_DEVICE") : "");
  psf::Runtime rt(dev);
  benchmark::AddCustomContext("psf_device", dev.platform + " / " + dev.name);
  benchmark::AddCustomContext("psf_driver", dev.driver + " (" + dev.version + ")");
  benchmark::AddCustomContext("psf_compute_units", std::to_string(dev.compute_units));
  benchmark::AddCustomContext("relMSE", "mean over pixels and channels of (x - y)^2 / (y^2 + 0.01)");
  benchmark::AddCustomContext("equal_time", g_cpu_time ? "CPU time of the process (least of the repeats)"
                                                       : "wall time (fastest of the repeats)");
  report("device: %s / %s, driver %s, %s, %u compute units\n", dev.platform.c_str(), dev.name.c_str(),
         dev.driver.c_str(), dev.version.c_str(), dev.compute_units);

  std::vector<std::unique_ptr<Bench>> benches;
  for (const std::string& path : opt.scenes) {
    std::optional<psf::Scene> scene = bench::load_bench_scene(path);
    if (!scene) continue;
    auto b = std::make_unique<Bench>();
    b->path = path;
    b->name = bench::scene_name(path);
    b->scene = std::move(*scene);
    if (!has_light(b->scene)) {
      report("skipped %s: no light psf can render (%zu loader warnings%s)\n", path.c_str(), b->scene.warnings.size(),
             b->name == "living-room" ? "; its envmap is not supported yet" : "");
      continue;
    }
    b->max_spp = opt.max_spp > 0 ? opt.max_spp : (b->name == "living-room" ? 16 : 1024);
    b->renderer = std::make_unique<psf::Renderer>(rt, b->scene);
    // The reference.
    bench::fs::path tungsten = bench::fs::path(path).parent_path() / "TungstenRender.exr";
    if (bench::fs::exists(tungsten)) {
      b->reference = psf::read_exr(tungsten.string());
      b->reference_source = tungsten.string() + " (Tungsten)";
    } else {
      std::string ref = cache + "/" + b->name + "_ref_" + std::to_string(opt.ref_spp) + "spp_" +
                        std::to_string(b->scene.width) + "x" + std::to_string(b->scene.height) + ".exr";
      if (bench::fs::exists(ref) && !opt.ref_refresh) {
        b->reference = psf::read_exr(ref);
        b->reference_source = ref + " (cached)";
      } else {
        report("%s: rendering the reference, %d spp plain path tracing...\n", b->name.c_str(), opt.ref_spp);
        psf::RenderResult r = b->renderer->render(options(*b, g_methods[0], opt.ref_spp, 0x5eed1234u));
        rt.finish();
        psf::write_exr(ref, r.image, {{"psf:spp", std::to_string(opt.ref_spp)}, {"psf:seed", "0x5eed1234"}});
        b->reference = std::move(r.image);
        b->reference_source = ref + " (rendered in " + std::to_string(r.seconds) + " s)";
      }
    }
    if (b->reference.width != b->scene.width || b->reference.height != b->scene.height) {
      report("skipped %s: the reference is %dx%d, the film %dx%d\n", path.c_str(), b->reference.width,
             b->reference.height, b->scene.width, b->scene.height);
      continue;
    }
    report("%s: %dx%d, max depth %d, %zu loader warnings; reference %s; curve up to %d spp\n", b->name.c_str(),
           b->scene.width, b->scene.height, b->scene.max_depth, b->scene.warnings.size(),
           b->reference_source.c_str(), b->max_spp);
    benchmark::AddCustomContext("reference_" + b->name, b->reference_source);
    // Warm-up: first launches of every kernel.
    for (const Method& m : g_methods) b->renderer->render(options(*b, m, 1));
    rt.finish();
    benches.push_back(std::move(b));
  }

  for (auto& bp : benches) {
    Bench* b = bp.get();
    // Interleaved (1 spp of every method, then 2, ...), so load from other processes
    // on the machine falls on all methods alike.
    for (int spp = 1; spp <= b->max_spp; spp *= 2)
      for (const Method& m : g_methods) {
        std::string bname = "quality/" + b->name + "/" + m.name + "/spp:" + std::to_string(spp);
        benchmark::RegisterBenchmark(bname.c_str(), [b, &rt, m, spp, bname](benchmark::State& state) {
          Point p;
          for (auto _ : state) {
            p = render(rt, *b, m, spp, repeats_for(spp));
            state.SetIterationTime(p.seconds);
          }
          state.counters["spp"] = spp;
          state.counters["seconds"] = p.seconds;
          state.counters["relMSE"] = p.relmse;
          state.counters["min_seconds"] = p.min_seconds;
          state.counters["cpu_seconds"] = p.cpu_seconds;
          state.counters["relMSE_min"] = p.relmse_min;
          state.counters["relMSE_max"] = p.relmse_max;
          report("%s: wall %.3f s (min %.3f s), CPU %.3f s, relMSE %.5g (seeds: %.5g-%.5g)\n", bname.c_str(),
                 p.seconds, p.min_seconds, p.cpu_seconds, p.relmse, p.relmse_min, p.relmse_max);
          b->points[m.name][spp] = std::move(p);
        })->UseManualTime()->Iterations(1)->Unit(benchmark::kMillisecond);
      }

    for (int n : opt.equal) {
      if (n > b->max_spp) continue;
      std::string bname = "equal_time/" + b->name + "/spp:" + std::to_string(n);
      benchmark::RegisterBenchmark(bname.c_str(), [b, &rt, &opt, n, bname](benchmark::State& state) {
        auto& pts = b->points;
        if (!pts["pt"].count(n)) pts["pt"][n] = render(rt, *b, g_methods[0], n, repeats_for(n));
        const Point& pt = pts["pt"][n];
        std::map<std::string, Point> best;
        for (auto _ : state) {
          for (const Method& m : g_methods) {
            if (m.name == "pt") continue;  // the baseline
            auto& mp = pts[m.name];
            if (!mp.count(n)) mp[n] = render(rt, *b, m, n, repeats_for(n));
            // s: the largest spp count whose wall time stays within 1.1x pt's (at
            // least 1 spp), from the time per spp at N, then refined by measuring.
            double per_spp = mp[n].cost / n;
            int s = std::max(1, int(std::lround(pt.cost / per_spp)));
            std::set<int> visited;
            for (int tries = 0; tries < 5 && visited.insert(s).second; ++tries) {
              if (!mp.count(s)) mp[s] = render(rt, *b, m, s, repeats_for(s));
              double ratio = mp[s].cost / pt.cost;
              if (ratio > 1.1) s = std::min(s - 1, int(std::lround(s / ratio)));
              else if (ratio < 0.9) s = std::max(s + 1, int(std::lround(s / ratio)));
              else break;
              if (s < 1) break;
            }
            // Among every render of this method so far (the curve's included).
            int chosen = 0;
            for (const auto& [spp, q] : mp)
              if (q.cost <= 1.1 * pt.cost) chosen = std::max(chosen, spp);
            if (chosen == 0) chosen = mp.begin()->first;  // even 1 spp takes longer than pt
            best[m.name] = mp[chosen];
          }
          state.SetIterationTime(pt.min_seconds);
        }
        state.counters["pt_spp"] = n;
        state.counters["pt_seconds"] = pt.min_seconds;
        state.counters["pt_relMSE"] = pt.relmse;
        state.counters["pt_cpu_seconds"] = pt.cpu_seconds;
        std::string line;
        char buf[256];
        for (const Method& m : g_methods) {
          if (m.name == "pt") continue;
          const Point& q = best[m.name];
          std::string k = m.name;
          double gain = q.relmse > 0 ? pt.relmse / q.relmse : 0;
          state.counters[k + "_spp"] = q.spp;
          state.counters[k + "_seconds"] = q.min_seconds;
          state.counters[k + "_relMSE"] = q.relmse;
          state.counters[k + "_cpu_seconds"] = q.cpu_seconds;
          state.counters[k + "_gain"] = gain;
          std::snprintf(buf, sizeof buf, "; %s %d spp %.3f s (CPU %.3f s) relMSE %.5g (%.2fx lower)", m.name.c_str(), q.spp,
                        q.min_seconds, q.cpu_seconds, q.relmse, gain);
          line += buf;
        }
        report("%s: pt %d spp %.3f s (CPU %.3f s) relMSE %.5g%s\n", bname.c_str(), n, pt.min_seconds, pt.cpu_seconds,
               pt.relmse, line.c_str());
        auto goal = [&](const char* what, double target) {
          std::string verdicts;
          for (const Method& m : g_methods)
            if (m.name != "pt")
              verdicts += std::string(verdicts.empty() ? " " : ", ") + m.name +
                          (state.counters[m.name + "_gain"] >= target ? " met" : " NOT met");
          report("%s: goal %s:%s\n", bname.c_str(), what, verdicts.c_str());
        };
        if (n == 4) goal(">= 10x lower relMSE at 4 spp", 10);
        if (n == 1024) goal("never worse at 1024 spp", 1);
        if (std::find(opt.crops.begin(), opt.crops.end(), n) != opt.crops.end()) {
          std::string png = opt.images + "/quality_" + b->name + "_" + std::to_string(n) + "spp" +
                            (g_cpu_time ? "_cputime" : "") + ".png";
          // pt, the first two filtered methods (psf and psf2 unless --methods drops them), the reference.
          std::vector<const psf::Image*> images = {&pt.image};
          std::string names = "pt " + std::to_string(n) + " spp";
          for (const Method& m : g_methods)
            if (m.filter && images.size() < 3) {
              images.push_back(&best[m.name].image);
              names += " | " + m.name + " " + std::to_string(best[m.name].spp) + " spp";
            }
          images.push_back(&b->reference);
          write_side_by_side(png, images);
          report("%s: wrote %s (%s | reference)\n", bname.c_str(), png.c_str(), names.c_str());
        }
      })->UseManualTime()->Iterations(1)->Unit(benchmark::kMillisecond);
    }
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
