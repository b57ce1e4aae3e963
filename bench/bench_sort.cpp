// bench_sort: the sort stage of path space filtering alone: radix_sort
// (kernels/sort.cl, host/filter.cpp) of (key, index) pairs as the filter sorts
// them, against the C++ standard library's sorts of the same pairs on the host:
// std::sort and std::stable_sort on one thread, and libstdc++'s parallel mode
// (__gnu_parallel::sort, OpenMP) on as many threads as the device has compute
// units (every core when it is a GPU), where it was built with OpenMP.
//
// Pairs: n = 2^log2 (--log2, repeatable; default 20 and 22) keys of
// filter_key_bits(n) + 1 bits (the filter's: a table of 2n cells and the bit of
// paths without a vertex), uniformly random (fixed seed), with their indices.
// The peers sort 64-bit words key << 32 | index, which orders the pairs as a
// stable sort by key does; std::stable_sort sorts the pairs by key alone.
// Timing: one warm-up, then --trials sorts of fresh copies of the input; device
// time from the launches' profiling events (Runtime::stats), wall time from a
// steady clock around the launches and the queue's finish (uploads excluded).
// psf runs each of its kernel variants: per-work-item chunks with 4-bit and
// 8-bit digits, and per-work-group tiles with 4-bit digits (radix_kernels and
// radix_digit_bits say which this device uses by default). After timing every
// result is checked against std::sort's.
//
// Usage: bench_sort [benchmark flags] [--log2=N ...] [--trials=N] [--peer_trials=N]
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <vector>

#ifdef PSF_HAVE_PARALLEL_MODE
#include <omp.h>

#include <parallel/algorithm>
#endif

#include "bench_common.h"
#include "cl/runtime.h"
#include "filter.h"

namespace {

using Clock = std::chrono::steady_clock;

struct Options {
  std::vector<int> log2s;  // batch sizes 2^log2; empty: 20 and 22
  int trials = 9;          // timed psf sorts per size and digit width
  int peer_trials = 3;     // timed sorts per peer and size
};

// One size: the input and what was measured.
struct Bench {
  uint32_t n = 0, bits = 0;
  std::vector<uint32_t> keys;
  std::vector<uint64_t> expected;  // key << 32 | index, sorted
  double std_sort_ms = 0, parallel_ms = 0;
};

double since_ms(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

std::vector<uint64_t> packed(const std::vector<uint32_t>& keys) {
  std::vector<uint64_t> v(keys.size());
  for (size_t i = 0; i < keys.size(); ++i) v[i] = uint64_t(keys[i]) << 32 | i;
  return v;
}

// Median wall time of `trials` runs of `sort` over fresh copies of the packed
// input.
template <class Sort>
double time_peer(const std::vector<uint32_t>& keys, int trials, Sort sort) {
  std::vector<double> ms;
  for (int t = 0; t < trials; ++t) {
    std::vector<uint64_t> v = packed(keys);
    auto t0 = Clock::now();
    sort(v);
    ms.push_back(since_ms(t0));
    benchmark::DoNotOptimize(v.data());
  }
  return bench::summarize(ms).median_s;
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  Options opt;
  bench::Args args(argc, argv, "bench_sort");
  for (const std::string& s : args.take_all("log2")) opt.log2s.push_back(bench::number<int>("bench_sort", "log2", s));
  args.take_number("trials", opt.trials);
  args.take_number("peer_trials", opt.peer_trials);
  if (!args.done()) return 2;
  if (opt.log2s.empty()) opt.log2s = {20, 22};
  opt.trials = std::max(1, opt.trials);
  opt.peer_trials = std::max(1, opt.peer_trials);
  for (int l : opt.log2s)
    if (l < 1 || l > 28) {
      bench::report("bench_sort: --log2=%d is outside [1, 28]\n", l);
      return 2;
    }

  psf::DeviceInfo dev = psf::choose_device(std::getenv("PSF_DEVICE") ? std::getenv("PSF_DEVICE") : "");
  psf::Runtime rt(dev);
  const unsigned threads = bench::peer_threads(dev);
  const bool own_tiles = psf::radix_kernels(rt) == psf::RadixKernels::tiles;
  const uint32_t own_digit = own_tiles ? 4 : psf::radix_digit_bits(rt);
  const std::string own_variant = (own_tiles ? "tiles" : "chunks") + std::to_string(own_digit);
  benchmark::AddCustomContext("psf_device", dev.platform + " / " + dev.name);
  benchmark::AddCustomContext("psf_driver", dev.driver + " (" + dev.version + ")");
  benchmark::AddCustomContext("psf_compute_units", std::to_string(dev.compute_units));
  benchmark::AddCustomContext("psf_sort_kernels", own_variant);
#ifdef PSF_HAVE_PARALLEL_MODE
  benchmark::AddCustomContext(
      "peer", "std::sort, std::stable_sort (1 thread); __gnu_parallel::sort (" + std::to_string(threads) + " threads)");
#else
  benchmark::AddCustomContext("peer",
                              "std::sort, std::stable_sort (1 thread); no "
                              "parallel mode (built without OpenMP)");
#endif
  bench::report("device: %s / %s, driver %s, %s, %u compute units\n", dev.platform.c_str(), dev.name.c_str(),
                dev.driver.c_str(), dev.version.c_str(), dev.compute_units);
  bench::report("psf: %s on this device (and the other variants for comparison); trials %d, peer trials %d\n",
                own_variant.c_str(), opt.trials, opt.peer_trials);

  std::vector<std::unique_ptr<Bench>> benches;
  for (int l : opt.log2s) {
    auto b = std::make_unique<Bench>();
    b->n = 1u << l;
    b->bits = psf::filter_key_bits(b->n) + 1;
    std::mt19937 rng{uint32_t(l)};
    b->keys.resize(b->n);
    const uint32_t mask = b->bits >= 32 ? 0xFFFFFFFFu : (1u << b->bits) - 1u;
    for (auto& k : b->keys) k = rng() & mask;
    b->expected = packed(b->keys);
    std::sort(b->expected.begin(), b->expected.end());
    benches.push_back(std::move(b));
  }

  for (auto& bp : benches) {
    Bench* b = bp.get();
    const std::string size = "2^" + std::to_string(__builtin_ctz(b->n));
    benchmark::RegisterBenchmark(
        ("std_sort/" + size).c_str(),
        [b, &opt, size](benchmark::State& state) {
          for (auto _ : state) {
            b->std_sort_ms =
                time_peer(b->keys, opt.peer_trials, [](std::vector<uint64_t>& v) { std::sort(v.begin(), v.end()); });
            state.SetIterationTime(b->std_sort_ms * 1e-3);
          }
          double stable_ms = time_peer(b->keys, opt.peer_trials, [](std::vector<uint64_t>& v) {
            std::stable_sort(v.begin(), v.end(), [](uint64_t a, uint64_t c) { return (a >> 32) < (c >> 32); });
          });
          state.counters["std_sort_ms"] = b->std_sort_ms;
          state.counters["std_stable_sort_ms"] = stable_ms;
          bench::report(
              "%s pairs, %u-bit keys: std::sort %.1f ms, "
              "std::stable_sort %.1f ms (1 thread)\n",
              size.c_str(), b->bits, b->std_sort_ms, stable_ms);
        })
        ->UseManualTime()
        ->Iterations(1)
        ->Unit(benchmark::kMillisecond);

#ifdef PSF_HAVE_PARALLEL_MODE
    benchmark::RegisterBenchmark(("gnu_parallel_sort/" + size).c_str(),
                                 [b, &opt, threads, size](benchmark::State& state) {
                                   omp_set_num_threads(int(threads));
                                   for (auto _ : state) {
                                     b->parallel_ms = time_peer(b->keys, opt.peer_trials, [](std::vector<uint64_t>& v) {
                                       __gnu_parallel::sort(v.begin(), v.end());
                                     });
                                     state.SetIterationTime(b->parallel_ms * 1e-3);
                                   }
                                   state.counters["threads"] = threads;
                                   bench::report("%s pairs: __gnu_parallel::sort %.1f ms on %u threads\n", size.c_str(),
                                                 b->parallel_ms, threads);
                                 })
        ->UseManualTime()
        ->Iterations(1)
        ->Unit(benchmark::kMillisecond);
#endif

    for (const char* variant : {"chunks4", "chunks8", "tiles4"}) {
      const bool tiles = variant[0] == 't';
      const uint32_t digit = tiles ? 4 : variant[6] == '4' ? 4 : 8;
      const bool own = variant == own_variant;
      const std::string name = "psf_radix_sort/" + size + "/" + variant;
      benchmark::RegisterBenchmark(
          name.c_str(),
          [b, &rt, &opt, digit, tiles, own, name](benchmark::State& state) {
            cl::Buffer keys = rt.buffer(CL_MEM_READ_WRITE, b->n * sizeof(uint32_t));
            cl::Buffer values = rt.buffer(CL_MEM_READ_WRITE, b->n * sizeof(uint32_t));
            cl::Buffer tmp_keys = rt.buffer(CL_MEM_READ_WRITE, b->n * sizeof(uint32_t));
            cl::Buffer tmp_values = rt.buffer(CL_MEM_READ_WRITE, b->n * sizeof(uint32_t));
            std::vector<uint32_t> index(b->n);
            for (uint32_t i = 0; i < b->n; ++i) index[i] = i;
            auto sort_once = [&](bool timed) {
              rt.write(keys, b->keys.data(), b->n * sizeof(uint32_t));
              rt.write(values, index.data(), b->n * sizeof(uint32_t));
              rt.finish();
              rt.reset_stats();
              auto t0 = Clock::now();
              psf::radix_sort(rt, keys, values, tmp_keys, tmp_values, b->n, b->bits, 0, digit,
                              tiles ? psf::RadixKernels::tiles : psf::RadixKernels::chunks);
              rt.finish();
              double wall = since_ms(t0);
              return std::make_pair(timed ? bench::kernel_ms(rt.stats(), {"radix_"}) : 0.0, wall);
            };
            sort_once(false);  // warm-up
            std::vector<double> device, wall;
            for (auto _ : state) {
              for (int t = 0; t < opt.trials; ++t) {
                auto [d, w] = sort_once(true);
                device.push_back(d * 1e-3);
                wall.push_back(w * 1e-3);
              }
              state.SetIterationTime(bench::summarize(device).median_s);
            }
            auto sk = rt.download<uint32_t>(keys, b->n), sv = rt.download<uint32_t>(values, b->n);
            size_t wrong = 0;
            for (uint32_t i = 0; i < b->n; ++i) wrong += (uint64_t(sk[i]) << 32 | sv[i]) != b->expected[i];
            const bench::Timing dt = bench::summarize(device), wt = bench::summarize(wall);
            const double ms = dt.median_s * 1e3, wall_ms = wt.median_s * 1e3;
            state.counters["device_ms_median"] = ms;
            state.counters["device_ms_min"] = dt.min_s * 1e3;
            state.counters["wall_ms_median"] = wall_ms;
            state.counters["Mpairs_per_s"] = b->n / dt.median_s * 1e-6;
            state.counters["passes"] = double((b->bits + digit - 1) / digit);
            state.counters["wrong"] = double(wrong);
            if (b->std_sort_ms > 0) state.counters["speedup_vs_std_sort"] = b->std_sort_ms / wall_ms;
            if (b->parallel_ms > 0) state.counters["speedup_vs_parallel_sort"] = b->parallel_ms / wall_ms;
            bench::report(
                "%s: %u passes of %u bits%s: device median %.2f ms, "
                "min %.2f ms; wall median %.2f ms; %.0f M "
                "pairs/s; %zu pairs out of place\n",
                name.c_str(), (b->bits + digit - 1) / digit, digit, own ? " (this device's)" : "", ms,
                dt.min_s * 1e3, wall_ms, b->n / dt.median_s * 1e-6, wrong);
            if (b->std_sort_ms > 0)
              bench::report("%s: std::sort / psf = %.1f / %.2f ms wall = %.2fx", name.c_str(), b->std_sort_ms, wall_ms,
                            b->std_sort_ms / wall_ms);
            if (b->parallel_ms > 0)
              bench::report("; __gnu_parallel::sort / psf = %.1f / %.2f ms = %.2fx", b->parallel_ms, wall_ms,
                            b->parallel_ms / wall_ms);
            bench::report("\n");
          })
          ->UseManualTime()
          ->Iterations(1)
          ->Unit(benchmark::kMillisecond);
    }
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
