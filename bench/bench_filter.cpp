// bench_filter: the neighbour search + averaging of path space filtering
// (host/filter.cpp: cell_keys -> radix sort -> cell ranges -> gather -> filter ->
// scatter) on the 2^20 tuples of one rendered batch, against the path tracing
// time of that batch and against nanoflann's kd-tree radius search over the same
// points, radii and thread count.
//
// Tuples: one batch of 2^20 paths rendered by psf::Renderer (1024x1024 at 1 spp,
// --width/--height/--spp), path space filtering on with the default options, so
// RenderResult::last_batch carries the vertices, values and the FilterParams the
// renderer used (n = 1: r_i = r0_i).
// psf_pathtrace/<scene>: that render, one warm-up and --pt_trials timed; the
//   device time of the path tracing kernels (camera_rays, raycast_*, shade*,
//   store_tuples, accumulate) from Runtime::stats().
// nanoflann_radius/<scene>: nanoflann 1.4 kd-tree (leaf size 10) over the valid
//   vertices (albedo.w != 0), then one radius query per valid vertex with its own
//   r_i = (r0 > 0 ? r0 : d_i footprint) n_scale (as kernels/cell_keys.cl), unsorted
//   results, over as many std::threads as the device has compute units (on a GPU
//   device: as the machine has cores; chunks of 1024 queries from an atomic counter). Timed: build + queries, wall clock; one
//   warm-up, --nf_trials timed.
// psf_filter/<scene>/cells8 and /cells27: PathSpaceFilter::run over the same
//   tuples (1 iteration; --iterations), one warm-up, --trials timed; device time =
//   the filter stage kernels' events, wall = enqueue..finish.
// After timing, psf's output is checked against an independent host evaluation of
// Eq. 1 of the paper built on nanoflann's neighbour lists: for every tuple the
// number averaged must match exactly and c-bar within 1e-4 (relative, float sums
// in another order); >= 99.9% must agree (float rounding at the ball's boundary).
//
// Neighbour counts: nanoflann's is the plain ball count |{j : |x_j - x_i| < r_i}|
// (all levels); "same-level ball" is the part of it psf's distance test admits
// (the same grid level, cell_keys.cl) before the similarity test; psf's count is
// after similarity (normal, albedo, visibility, finite c_j), the centre included.
//
// Usage: bench_filter [benchmark flags] [--scene=PATH ...] [--width=N --height=N --spp=N]
//                     [--trials=N] [--nf_trials=N] [--pt_trials=N] [--iterations=N] [--foreshortening=0|1]
// Without --scene: Dabrovic Sponza and the living-room from $PSF_SHARED (else
// ../shared beside the source tree), and scenes/cornell-box.xml; absent ones are skipped.
#include <benchmark/benchmark.h>

#include <nanoflann.hpp>

#include <array>
#include <atomic>
#include <optional>
#include <chrono>
#include <cmath>
#include <memory>
#include <thread>

#include "bench_common.h"
#include "render.h"
#include "scene/scene.h"

namespace {

using bench::report;
using bench::Timing;

struct Options {
  std::vector<std::string> scenes;  // scene files; empty: the defaults
  int width = 1024, height = 1024;  // film of the batch
  int spp = 1;                      // width * height * spp paths: one batch of 2^20
  int trials = 9;                   // timed filter runs
  int nf_trials = 3;                // timed nanoflann runs
  int pt_trials = 3;                // timed renders
  int iterations = 1;               // averaging passes of the filter
  int foreshortening = 1;           // 1: radii stretched by 1 / sqrt(cos theta) (psf's default), 0: not
};

// What one tuple of the batch should get, from the host evaluation on nanoflann's lists.
struct Expected {
  uint32_t ball = 0;        // |x_j - x_i| < r_i, any level (nanoflann's count)
  uint32_t same_level = 0;  // ... and the same grid level: psf's distance-test candidates
  uint32_t count = 0;       // ... and similar and finite (or j == i): tuples averaged
  cl_float4 value{};        // c-bar_i
  float scale = 0;          // mean |c_j| over the averaged ones, for the tolerance
};

struct Bench {
  std::string name, path;
  psf::Scene scene;
  psf::BatchTuples batch;          // the tuples of the rendered batch
  std::vector<uint32_t> valid;     // indices of tuples with a filtering vertex
  std::vector<float> radius;       // r_i per tuple (0: none)
  Timing pt_device, pt_wall;       // path tracing of the batch
  Timing nf;                       // nanoflann build + queries
  double nf_build_ms = 0, nf_query_ms = 0;  // of the median trial
  double nf_mean_ball = 0;         // mean nanoflann neighbours per valid vertex
  std::vector<Expected> expected;  // host evaluation (after the nanoflann timing)
};

// ceil(log2(r)) for r > 0, exactly, as grid_level() in kernels/cell_keys.cl.
int grid_level(float r) {
  int e;
  float m = std::frexp(r, &e);
  return m == 0.5f ? e - 1 : e;
}

// r_i = (r0 > 0 ? r0 : d_i footprint) (stretch ? s_i : 1) n_scale, as
// kernels/cell_keys.cl computes it (s_i the vertex's footprint stretch).
float query_radius(const FilterParams& p, const PathVertex& v) {
  float r0 = p.r0 > 0.0f ? p.r0 : v.position.s[3] * p.footprint;
  if (p.stretch) r0 *= v.albedo.s[3];
  return r0 * p.n_scale;
}

// nanoflann's dataset adaptor over the valid vertices.
struct Points {
  const std::vector<PathVertex>* vertices;
  const std::vector<uint32_t>* valid;
  size_t kdtree_get_point_count() const { return valid->size(); }
  float kdtree_get_pt(uint32_t idx, size_t dim) const { return (*vertices)[(*valid)[idx]].position.s[dim]; }
  template <class BBox>
  bool kdtree_get_bbox(BBox&) const {
    return false;
  }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, Points>, Points, 3, uint32_t>;

// Runs body(query index in valid, results) for every valid vertex over `threads`
// threads, chunks of 1024 queries taken from an atomic counter.
template <class Body>
void for_all_queries(const KdTree& tree, const Bench& b, unsigned threads, Body body) {
  std::atomic<size_t> next{0};
  const size_t n = b.valid.size(), chunk = 1024;
  auto work = [&] {
    std::vector<std::pair<uint32_t, float>> matches;
    matches.reserve(256);
    const nanoflann::SearchParams params(32, 0.0f, false);
    for (size_t begin; (begin = next.fetch_add(chunk)) < n;) {
      for (size_t q = begin; q < std::min(n, begin + chunk); ++q) {
        uint32_t i = b.valid[q];
        float r = b.radius[i];
        tree.radiusSearch(b.batch.vertices[i].position.s, r * r, matches, params);
        body(q, matches);
      }
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (auto& th : pool) th.join();
}

// The host evaluation of Eq. 1 with kernels/filter.cl's weights, on nanoflann's ball lists.
void evaluate_on_host(Bench& b, unsigned threads) {
  const auto& V = b.batch.vertices;
  const auto& C = b.batch.values;
  const FilterParams& p = b.batch.params;
  b.expected.assign(V.size(), Expected{});
  for (size_t i = 0; i < V.size(); ++i) {  // tuples without a vertex keep their own c
    b.expected[i].count = 1;
    b.expected[i].value = C[i];
    b.expected[i].value.s[3] = 0.0f;
    b.expected[i].scale = std::abs(C[i].s[0]) + std::abs(C[i].s[1]) + std::abs(C[i].s[2]);
  }
  std::vector<int> level(V.size(), 0);
  for (uint32_t i : b.valid) level[i] = grid_level(std::fmax(b.radius[i], 1e-30f));
  Points pts{&V, &b.valid};
  KdTree tree(3, pts, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  for_all_queries(tree, b, threads, [&](size_t q, const std::vector<std::pair<uint32_t, float>>& m) {
    uint32_t i = b.valid[q];
    const PathVertex& t = V[i];
    Expected e;
    double sum[3] = {0, 0, 0}, mag = 0;
    bool self = false;
    for (const auto& [qj, d2] : m) {
      uint32_t j = b.valid[qj];
      const PathVertex& u = V[j];
      e.ball++;
      if (level[j] != level[i]) continue;
      e.same_level++;
      float da[3] = {u.albedo.s[0] - t.albedo.s[0], u.albedo.s[1] - t.albedo.s[1], u.albedo.s[2] - t.albedo.s[2]};
      bool similar = u.normal.s[0] * t.normal.s[0] + u.normal.s[1] * t.normal.s[1] + u.normal.s[2] * t.normal.s[2] >=
                         p.normal_cos &&
                     da[0] * da[0] + da[1] * da[1] + da[2] * da[2] <= p.albedo_tol * p.albedo_tol &&
                     u.normal.s[3] == t.normal.s[3];
      bool finite = std::isfinite(C[j].s[0]) && std::isfinite(C[j].s[1]) && std::isfinite(C[j].s[2]);
      if (j == i || (similar && finite)) {
        self |= j == i;
        for (int c = 0; c < 3; ++c) sum[c] += C[j].s[c];
        mag += std::abs(C[j].s[0]) + std::abs(C[j].s[1]) + std::abs(C[j].s[2]);
        e.count++;
      }
    }
    if (!self) {  // the centre always counts (r_i 0 or rounding): as the kernel does
      for (int c = 0; c < 3; ++c) sum[c] += C[i].s[c];
      mag += std::abs(C[i].s[0]) + std::abs(C[i].s[1]) + std::abs(C[i].s[2]);
      e.count++;
    }
    for (int c = 0; c < 3; ++c) e.value.s[c] = float(sum[c] / e.count);
    e.scale = float(mag / e.count);
    b.expected[i] = e;
  });
}

std::vector<std::string> default_scenes() {
  return {bench::shared_path("scenes/sponza-dabrovic/sponza.obj"), bench::shared_path("scenes/living-room/scene.xml"),
          (bench::fs::path(PSF_SOURCE_DIR) / "scenes/cornell-box.xml").string()};
}

psf::RenderOptions batch_options(const Options& opt) {
  psf::RenderOptions o;
  o.spp = opt.spp;
  o.seed = 0;
  o.batch_log2 = 20;
  o.keep_last_batch = true;
  o.filter.enabled = true;  // so the renderer hands back the FilterParams of the batch
  o.filter.foreshortening = opt.foreshortening != 0;
  return o;
}

// One render of the batch; returns (path tracing device s, render wall s).
std::pair<double, double> render_batch(psf::Runtime& rt, psf::Renderer& renderer, Bench& b, const Options& opt,
                                       bool keep) {
  rt.reset_stats();
  psf::RenderResult r = renderer.render(batch_options(opt));
  rt.finish();
  double pt = bench::kernel_ms(rt.stats(), bench::pathtrace_kernels()) * 1e-3;
  if (keep) {
    b.batch = std::move(r.last_batch);
    b.valid.clear();
    b.radius.assign(b.batch.vertices.size(), 0.0f);
    for (uint32_t i = 0; i < b.batch.vertices.size(); ++i)
      if (b.batch.vertices[i].albedo.s[3] != 0.0f) {
        b.valid.push_back(i);
        b.radius[i] = query_radius(b.batch.params, b.batch.vertices[i]);
      }
    double other = 0;
    std::string names;
    for (const auto& [name, t] : rt.stats()) {
      bool known = bench::kernel_ms({{name, t}}, bench::pathtrace_kernels()) > 0 ||
                   bench::kernel_ms({{name, t}}, bench::filter_kernels()) > 0 ||
                   bench::kernel_ms({{name, t}}, bench::visibility_kernels()) > 0;
      if (!known && t.ms > 0) {
        other += t.ms;
        names += " " + name;
      }
    }
    if (!names.empty()) report("%s: kernels counted in neither stage (%.1f ms):%s\n", b.name.c_str(), other, names.c_str());
    const double visibility = bench::kernel_ms(rt.stats(), bench::visibility_kernels());
    if (visibility > 0)
      report("%s: hemisphere-ray visibility (the scene's only light is an environment): its kernels %.1f ms, "
             "its any-hit rays counted with path tracing\n",
             b.name.c_str(), visibility);
  }
  return {pt, r.seconds};
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  Options opt;
  bench::Args args(argc, argv, "bench_filter");
  opt.scenes = args.take_all("scene");
  args.take_number("width", opt.width);
  args.take_number("height", opt.height);
  args.take_number("spp", opt.spp);
  args.take_number("trials", opt.trials);
  args.take_number("nf_trials", opt.nf_trials);
  args.take_number("pt_trials", opt.pt_trials);
  args.take_number("iterations", opt.iterations);
  args.take_number("foreshortening", opt.foreshortening);
  if (!args.done()) return 2;
  if (opt.scenes.empty()) opt.scenes = default_scenes();
  opt.trials = std::max(1, opt.trials);
  opt.nf_trials = std::max(1, opt.nf_trials);
  opt.pt_trials = std::max(1, opt.pt_trials);

  psf::DeviceInfo dev = psf::choose_device(std::getenv("PSF_DEVICE") ? std::getenv("PSF_DEVICE") : "");
  // PSF_BUILD_OPTIONS: extra OpenCL build options, to compare kernel variants
  // (e.g. "-DPSF_FILTER_LANES=8 -DPSF_FILTER_SKIP=0 -DPSF_FILTER_QUERIES=1").
  const std::string build_options = std::getenv("PSF_BUILD_OPTIONS") ? std::getenv("PSF_BUILD_OPTIONS") : "";
  psf::Runtime rt(dev, build_options);
  const unsigned threads = bench::peer_threads(dev);
  const uint64_t paths = uint64_t(opt.width) * opt.height * opt.spp;
  benchmark::AddCustomContext("psf_device", dev.platform + " / " + dev.name);
  benchmark::AddCustomContext("psf_driver", dev.driver + " (" + dev.version + ")");
  benchmark::AddCustomContext("psf_build_options", "-cl-std=CL1.2 -DPSF_BVH_WIDTH=" + std::to_string(PSF_BVH_WIDTH) +
                                                        (build_options.empty() ? "" : " " + build_options));
  benchmark::AddCustomContext("psf_compute_units", std::to_string(dev.compute_units));
  benchmark::AddCustomContext("psf_batch", std::to_string(opt.width) + "x" + std::to_string(opt.height) + " at " +
                                               std::to_string(opt.spp) + " spp = " + std::to_string(paths) + " paths");
  benchmark::AddCustomContext("psf_local_size", std::to_string(psf::Runtime::kDefaultLocal));
  benchmark::AddCustomContext("peer", "nanoflann " + std::to_string(NANOFLANN_VERSION >> 8) + "." +
                                          std::to_string((NANOFLANN_VERSION >> 4) & 0xf) + "." +
                                          std::to_string(NANOFLANN_VERSION & 0xf) + ", " + std::to_string(threads) +
                                          " threads");
  report("device: %s / %s, driver %s, %s, %u compute units\n", dev.platform.c_str(), dev.name.c_str(),
         dev.driver.c_str(), dev.version.c_str(), dev.compute_units);
  report("batch: %dx%d at %d spp = %llu paths; local size %zu; filter trials %d, nanoflann trials %d, render "
         "trials %d; %d filter iteration(s); foreshortening %s\n",
         opt.width, opt.height, opt.spp, (unsigned long long)paths, psf::Runtime::kDefaultLocal, opt.trials,
         opt.nf_trials, opt.pt_trials, opt.iterations, opt.foreshortening ? "on" : "off");
  if (paths > (uint64_t(1) << 20))
    report("note: %llu paths are more than one batch of 2^20; the last batch is used\n", (unsigned long long)paths);

  std::vector<std::unique_ptr<Bench>> benches;
  for (const std::string& path : opt.scenes) {
    std::optional<psf::Scene> scene = bench::load_bench_scene(path);
    if (!scene) continue;
    auto b = std::make_unique<Bench>();
    b->path = path;
    b->name = bench::scene_name(path);
    b->scene = std::move(*scene);
    b->scene.width = opt.width;
    b->scene.height = opt.height;
    report("%s: %zu triangles, %zu scene warnings\n", b->name.c_str(), b->scene.triangles.size(),
           b->scene.warnings.size());
    benches.push_back(std::move(b));
  }

  for (auto& bp : benches) {
    Bench* b = bp.get();
    benchmark::RegisterBenchmark(("psf_pathtrace/" + b->name).c_str(), [b, &rt, &opt](benchmark::State& state) {
      psf::Renderer renderer(rt, b->scene);
      render_batch(rt, renderer, *b, opt, false);  // warm-up: program and first launches
      std::vector<double> device, wall;
      for (auto _ : state) {
        auto [pt, w] = render_batch(rt, renderer, *b, opt, true);
        state.SetIterationTime(pt);
        device.push_back(pt);
        wall.push_back(w);
      }
      b->pt_device = bench::summarize(device);
      b->pt_wall = bench::summarize(wall);
      state.counters["pathtrace_ms_median"] = b->pt_device.median_s * 1e3;
      state.counters["pathtrace_ms_min"] = b->pt_device.min_s * 1e3;
      state.counters["render_wall_ms_median"] = b->pt_wall.median_s * 1e3;
      state.counters["tuples"] = double(b->batch.vertices.size());
      state.counters["valid_tuples"] = double(b->valid.size());
      report("%s: path tracing of the batch: device median %.1f ms, min %.1f ms (render wall incl. filter %.1f "
             "ms); %zu tuples, %zu with a filtering vertex; footprint %.3g, n_scale %.3g\n",
             b->name.c_str(), b->pt_device.median_s * 1e3, b->pt_device.min_s * 1e3, b->pt_wall.median_s * 1e3,
             b->batch.vertices.size(), b->valid.size(), b->batch.params.footprint, b->batch.params.n_scale);
    })->UseManualTime()->Iterations(opt.pt_trials)->Unit(benchmark::kMillisecond);

    benchmark::RegisterBenchmark(("nanoflann_radius/" + b->name).c_str(), [b, &rt, &opt, threads](
                                                                             benchmark::State& state) {
      if (b->batch.vertices.empty()) {
        psf::Renderer renderer(rt, b->scene);
        render_batch(rt, renderer, *b, opt, true);
      }
      Points pts{&b->batch.vertices, &b->valid};
      std::vector<uint32_t> counts(b->valid.size());
      auto once = [&](double& build_s, double& query_s) {
        auto t0 = std::chrono::steady_clock::now();
        KdTree tree(3, pts, nanoflann::KDTreeSingleIndexAdaptorParams(10));
        tree.buildIndex();
        auto t1 = std::chrono::steady_clock::now();
        for_all_queries(tree, *b, threads, [&](size_t q, const std::vector<std::pair<uint32_t, float>>& m) {
          counts[q] = uint32_t(m.size());
        });
        auto t2 = std::chrono::steady_clock::now();
        build_s = std::chrono::duration<double>(t1 - t0).count();
        query_s = std::chrono::duration<double>(t2 - t1).count();
      };
      double bs, qs;
      once(bs, qs);  // warm-up
      std::vector<double> total;
      std::vector<std::pair<double, std::pair<double, double>>> parts;
      for (auto _ : state) {
        once(bs, qs);
        state.SetIterationTime(bs + qs);
        total.push_back(bs + qs);
        parts.push_back({bs + qs, {bs, qs}});
      }
      b->nf = bench::summarize(total);
      std::sort(parts.begin(), parts.end());
      b->nf_build_ms = parts[parts.size() / 2].second.first * 1e3;
      b->nf_query_ms = parts[parts.size() / 2].second.second * 1e3;
      double sum = 0;
      for (uint32_t c : counts) sum += c;
      b->nf_mean_ball = counts.empty() ? 0 : sum / counts.size();
      state.counters["build_ms"] = b->nf_build_ms;
      state.counters["query_ms"] = b->nf_query_ms;
      state.counters["Mqueries_per_s"] = b->valid.size() / b->nf.median_s * 1e-6;
      state.counters["mean_neighbours_ball"] = b->nf_mean_ball;
      state.counters["threads"] = threads;
      report("%s: nanoflann %u threads: median %.1f ms (build %.1f + queries %.1f), min %.1f ms; %.2f M queries/s; "
             "mean ball neighbours %.2f\n",
             b->name.c_str(), threads, b->nf.median_s * 1e3, b->nf_build_ms, b->nf_query_ms, b->nf.min_s * 1e3,
             b->valid.size() / b->nf.median_s * 1e-6, b->nf_mean_ball);
      evaluate_on_host(*b, threads);  // the reference for the psf check, untimed
    })->UseManualTime()->Iterations(opt.nf_trials)->Unit(benchmark::kMillisecond);

    for (int cells27 = 0; cells27 <= 1; ++cells27) {
      std::string bname = "psf_filter/" + b->name + (cells27 ? "/cells27" : "/cells8");
      benchmark::RegisterBenchmark(bname.c_str(), [b, &rt, &opt, cells27, bname](benchmark::State& state) {
        if (b->batch.vertices.empty()) {
          psf::Renderer renderer(rt, b->scene);
          render_batch(rt, renderer, *b, opt, true);
        }
        const uint32_t n = uint32_t(b->batch.vertices.size());
        FilterParams p = b->batch.params;
        p.cells27 = uint32_t(cells27);
        p.count = n;
        cl::Buffer vertices = rt.upload(b->batch.vertices);
        cl::Buffer values = rt.upload(b->batch.values);
        cl::Buffer filtered = rt.buffer(CL_MEM_READ_WRITE, size_t(n) * sizeof(cl_float4));
        cl::Buffer counts = rt.buffer(CL_MEM_READ_WRITE, size_t(n) * sizeof(uint32_t));
        psf::PathSpaceFilter filter(rt, n);
        filter.run(p, opt.iterations, vertices, values, filtered, counts);  // warm-up
        rt.finish();
        std::vector<double> device, wall, search, average;
        // Device time per stage (host/filter.cpp's order), for the breakdown.
        const std::vector<std::pair<const char*, std::vector<std::string>>> stages = {
            {"keys", {"cell_keys"}},
            {"sort", {"radix_"}},
            {"ranges", {"cell_ranges"}},
            {"gather", {"gather_tuples"}},
            {"filter", {"filter"}},
            {"scatter", {"scatter_values"}}};
        std::vector<std::vector<double>> stage_s(stages.size());
        for (auto _ : state) {
          rt.reset_stats();
          auto t0 = std::chrono::steady_clock::now();
          filter.run(p, opt.iterations, vertices, values, filtered, counts);
          rt.finish();
          double w = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          double d = bench::kernel_ms(rt.stats(), bench::filter_kernels()) * 1e-3;
          state.SetIterationTime(d);
          device.push_back(d);
          wall.push_back(w);
          average.push_back(bench::kernel_ms(rt.stats(), {"filter"}) * 1e-3);
          search.push_back(d - average.back());
          for (size_t k = 0; k < stages.size(); ++k)
            stage_s[k].push_back(bench::kernel_ms(rt.stats(), stages[k].second) * 1e-3);
        }
        Timing dt = bench::summarize(device), wt = bench::summarize(wall);
        Timing st = bench::summarize(search), at = bench::summarize(average);

        // Check the output after timing.
        auto out_counts = rt.download<uint32_t>(counts, n);
        auto out_values = rt.download<cl_float4>(filtered, n);
        double mean_count = 0;
        size_t bad = 0;
        for (uint32_t i : b->valid) mean_count += out_counts[i];
        for (uint32_t i = 0; i < n; ++i) bad += out_counts[i] == 0;
        mean_count = b->valid.empty() ? 0 : mean_count / b->valid.size();
        double ms = dt.median_s * 1e3;
        double ratio_pt = b->pt_device.median_s > 0 ? dt.median_s / b->pt_device.median_s : 0;
        state.counters["device_ms_median"] = ms;
        state.counters["device_ms_min"] = dt.min_s * 1e3;
        state.counters["wall_ms_median"] = wt.median_s * 1e3;
        state.counters["wall_ms_min"] = wt.min_s * 1e3;
        state.counters["search_ms_median"] = st.median_s * 1e3;
        state.counters["filter_kernel_ms_median"] = at.median_s * 1e3;
        state.counters["mean_neighbours"] = mean_count;
        state.counters["Mtuples_per_s"] = n / dt.median_s * 1e-6;
        report("%s: psf %s: device median %.1f ms, min %.1f ms (search: keys+sort+ranges+gather+scatter %.1f ms, "
               "filter kernel %.1f ms); wall median %.1f ms, min %.1f ms; mean neighbours averaged %.2f\n",
               bname.c_str(), cells27 ? "27 cells of size r" : "8 cells of size 2r", ms, dt.min_s * 1e3,
               st.median_s * 1e3, at.median_s * 1e3, wt.median_s * 1e3, wt.min_s * 1e3, mean_count);
        report("%s: stages, device medians:", bname.c_str());
        for (size_t k = 0; k < stages.size(); ++k) {
          const double stage_ms = bench::summarize(stage_s[k]).median_s * 1e3;
          state.counters[std::string("stage_") + stages[k].first + "_ms"] = stage_ms;
          report(" %s %.2f ms%s", stages[k].first, stage_ms, k + 1 < stages.size() ? "," : "\n");
        }
        if (ratio_pt > 0) {
          state.counters["ratio_filter_pathtrace"] = ratio_pt;
          report("%s: filter / path tracing of the batch = %.1f / %.1f ms = %.3f (goal <= 0.25: %s)\n", bname.c_str(),
                 ms, b->pt_device.median_s * 1e3, ratio_pt, ratio_pt <= 0.25 ? "met" : "NOT met");
        }
        if (b->nf.median_s > 0) {
          double speedup_wall = b->nf.median_s / wt.median_s, speedup_dev = b->nf.median_s / dt.median_s;
          state.counters["speedup_vs_nanoflann"] = speedup_wall;
          state.counters["speedup_vs_nanoflann_device"] = speedup_dev;
          report("%s: nanoflann (build + search only) / psf (search + averaging) = %.1f / %.1f ms wall = %.2fx "
                 "(device time: %.2fx) (goal >= 5x: %s)\n",
                 bname.c_str(), b->nf.median_s * 1e3, wt.median_s * 1e3, speedup_wall, speedup_dev,
                 speedup_wall >= 5 ? "met" : "NOT met");
        }
        if (bad) state.SkipWithError("a tuple averaged 0 tuples");
        if (b->expected.size() == n && opt.iterations == 1) {
          size_t count_ok = 0, value_ok = 0;
          double mean_ball = 0, mean_level = 0, mean_expected = 0;
          for (uint32_t i = 0; i < n; ++i) {
            const Expected& e = b->expected[i];
            count_ok += out_counts[i] == e.count;
            bool ok = true;
            for (int c = 0; c < 3; ++c) {
              float x = out_values[i].s[c], y = e.value.s[c];
              ok = ok && (x == y || (std::isnan(x) && std::isnan(y)) || std::abs(x - y) <= 1e-4f * e.scale + 1e-7f);
            }
            value_ok += ok;
          }
          for (uint32_t i : b->valid) {
            mean_ball += b->expected[i].ball;
            mean_level += b->expected[i].same_level;
            mean_expected += b->expected[i].count;
          }
          double nv = std::max<size_t>(1, b->valid.size());
          double agree_c = double(count_ok) / n, agree_v = double(value_ok) / n;
          state.counters["mean_ball_same_level"] = mean_level / nv;
          state.counters["count_agreement"] = agree_c;
          state.counters["value_agreement"] = agree_v;
          report("%s: mean neighbours: nanoflann ball %.2f, same-level ball (psf's candidates before similarity) "
                 "%.2f, after similarity %.2f (host) / %.2f (psf); counts agree for %.4f%%, c-bar for %.4f%% of "
                 "tuples%s\n",
                 bname.c_str(), mean_ball / nv, mean_level / nv, mean_expected / nv, mean_count, 100 * agree_c,
                 100 * agree_v, agree_c > 0.999 && agree_v > 0.999 ? "" : " (BELOW 99.9%)");
          if (agree_c <= 0.999 || agree_v <= 0.999)
            state.SkipWithError("psf's averages disagree with the host evaluation for >= 0.1% of tuples");
        } else {
          report("%s: output not checked against the host evaluation (%s)\n", bname.c_str(),
                 opt.iterations == 1 ? "nanoflann_radius not run" : "it covers 1 iteration");
        }
      })->UseManualTime()->Iterations(opt.trials)->Unit(benchmark::kMillisecond);
    }
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
