// Path space filtering stages (kernels/{cell_keys,sort,cell_ranges,filter}.cl)
// against scalar references: std::stable_sort, a plain scan for cell ranges, and
// a brute-force all-pairs evaluation of Keller et al. 2016, Eq. 1-2.
// Under PSF_TEST_SMALL (psf::test::small_sizes(), set by scripts/oclgrind) the
// same checks run on fewer tuples, pixels and samples.
#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numeric>
#include <random>
#include <set>

#include "filter.h"
#include "render.h"
#include "scene/scene.h"
#include "support.h"

namespace {

struct Reference {
  std::vector<uint32_t> counts;    // tuples averaged per tuple
  std::vector<cl_float4> values;   // c-bar per tuple
  int iterations = 1;              // passes of averaging
};

// Brute force over all pairs, written from the definition: radius r_i =
// (r0 > 0 ? r0 : d_i footprint) (stretch ? s_i : 1) n_scale, s_i the vertex's
// footprint stretch (albedo.w); the grid level ceil(log2 r_i) must
// match; |x_j - x_i| < r_i; <n_i, n_j> >= cos; |albedo_i - albedo_j| <= tol;
// equal visibility (unless p.ignore_visibility); finite c_j; the centre always counts. With p.demodulate:
// m = max(albedo, 0.01) per channel; the average is of c_j / m_j, times m_i at
// the end, and |log2 m_i - log2 m_j| <= tol replaces the albedo test.
Reference brute_force(const std::vector<PathVertex>& v, const std::vector<cl_float4>& c, const FilterParams& p,
                      int iterations) {
  size_t n = v.size();
  std::vector<float> r(n, 0.0f);
  std::vector<int> level(n, 0);
  for (size_t i = 0; i < n; ++i) {
    if (v[i].albedo.s[3] == 0.0f) continue;
    float r0 = p.r0 > 0.0f ? p.r0 : v[i].position.s[3] * p.footprint;
    if (p.stretch) r0 = r0 * v[i].albedo.s[3];
    r[i] = r0 * p.n_scale;
    level[i] = int(std::ceil(std::log2(double(std::max(r[i], 1e-30f)))));
  }
  Reference ref;
  ref.iterations = iterations;
  ref.values = c;
  ref.counts.assign(n, 1);
  std::vector<cl_float4> m(n);  // the albedo divided out (demodulate), else unused
  for (size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      m[i].s[k] = std::max(v[i].albedo.s[k], 0.01f);
      if (p.demodulate && v[i].albedo.s[3] != 0.0f) ref.values[i].s[k] = c[i].s[k] / m[i].s[k];
    }
  for (int it = 0; it < iterations; ++it) {
    std::vector<cl_float4> next = ref.values;
    for (size_t i = 0; i < n; ++i) {
      if (v[i].albedo.s[3] == 0.0f) continue;
      double sum[3] = {0, 0, 0};
      uint32_t count = 0;
      for (size_t j = 0; j < n; ++j) {
        bool use = j == i;
        if (!use && v[j].albedo.s[3] != 0.0f && level[j] == level[i]) {
          float d2 = 0, n_dot = 0, a2 = 0;
          for (int k = 0; k < 3; ++k) {
            float d = v[j].position.s[k] - v[i].position.s[k];
            d2 = d2 + d * d;
            n_dot = n_dot + v[j].normal.s[k] * v[i].normal.s[k];
            float a = p.demodulate ? float(std::log2(double(m[j].s[k])) - std::log2(double(m[i].s[k])))
                                   : v[j].albedo.s[k] - v[i].albedo.s[k];
            a2 = a2 + a * a;
          }
          bool finite = std::isfinite(ref.values[j].s[0]) && std::isfinite(ref.values[j].s[1]) &&
                        std::isfinite(ref.values[j].s[2]);
          use = d2 < r[i] * r[i] && n_dot >= p.normal_cos && a2 <= p.albedo_tol * p.albedo_tol &&
                (p.ignore_visibility || v[j].normal.s[3] == v[i].normal.s[3]) && finite;
        }
        if (use) {
          for (int k = 0; k < 3; ++k) sum[k] += ref.values[j].s[k];
          ++count;
        }
      }
      for (int k = 0; k < 3; ++k) next[i].s[k] = float(sum[k] / count);
      ref.counts[i] = count;
    }
    ref.values = next;
  }
  if (p.demodulate)
    for (size_t i = 0; i < n; ++i)
      if (v[i].albedo.s[3] != 0.0f)
        for (int k = 0; k < 3; ++k) ref.values[i].s[k] *= m[i].s[k];
  return ref;
}

struct DeviceResult {
  std::vector<uint32_t> counts;
  std::vector<cl_float4> values;
  uint32_t max_count = 0;
};

// Runs `filter` (of capacity >= v.size()) on the tuples and downloads its results.
DeviceResult run_with(psf::Runtime& rt, psf::PathSpaceFilter& filter, const std::vector<PathVertex>& v,
                      const std::vector<cl_float4>& c, FilterParams p, int iterations) {
  uint32_t n = uint32_t(v.size());
  cl::Buffer vb = rt.upload(v), cb = rt.upload(c);
  cl::Buffer out = rt.buffer(CL_MEM_READ_WRITE, std::max<size_t>(n, 1) * sizeof(cl_float4));
  cl::Buffer counts = rt.buffer(CL_MEM_READ_WRITE, std::max<size_t>(n, 1) * sizeof(uint32_t));
  p.count = n;
  DeviceResult d;
  d.max_count = filter.run(p, iterations, vb, cb, out, counts);
  d.values = rt.download<cl_float4>(out, n);
  d.counts = rt.download<uint32_t>(counts, n);
  return d;
}

DeviceResult run_filter(const std::vector<PathVertex>& v, const std::vector<cl_float4>& c, FilterParams p,
                        int iterations, psf::Runtime& rt = psf::test::runtime(), uint32_t gather_lanes = 0,
                        uint32_t filter_queries = 0) {
  psf::PathSpaceFilter filter(rt, uint32_t(v.size()), gather_lanes, filter_queries);
  return run_with(rt, filter, v, c, p, iterations);
}

// Tuples scattered over a few planes (so normals repeat), with some albedo and
// visibility variety and a share of paths without a vertex.
std::vector<PathVertex> random_tuples(size_t n, uint32_t seed, float extent) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<PathVertex> v(n);
  const float normals[3][3] = {{0, 1, 0}, {1, 0, 0}, {0.6f, 0.8f, 0}};
  for (auto& t : v) {
    int plane = int(u(rng) * 3) % 3;
    t.position = {{u(rng) * extent, u(rng) * extent, u(rng) * extent * 0.1f, 1.0f + 4.0f * u(rng)}};
    t.normal = {{normals[plane][0], normals[plane][1], normals[plane][2], u(rng) < 0.8f ? 1.0f : 0.0f}};
    float a = u(rng) < 0.7f ? 0.5f : 0.5f + 0.2f * u(rng);
    t.albedo = {{a, a, 0.3f, u(rng) < 0.95f ? 1.0f : 0.0f}};
    t.alpha = {{1, 1, 1, 0}};
    // The footprint stretch of a vertex seen at an angle: 1 (facing the camera)
    // to 2 (PSF_FOOTPRINT_MIN_COS), used where FilterParams.stretch is set.
    float s = 1.0f + u(rng);
    if (t.albedo.s[3] != 0.0f && s > 1.5f) t.albedo.s[3] = std::min(s, 2.0f);
  }
  return v;
}

std::vector<cl_float4> random_values(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 2.0f);
  std::vector<cl_float4> c(n);
  for (auto& x : c) x = {{u(rng), u(rng), u(rng), 0}};
  return c;
}

FilterParams default_params() {
  FilterParams p{};
  p.r0 = 0.0f;
  p.footprint = 0.02f;
  p.n_scale = 1.0f;
  p.normal_cos = 0.95f;
  p.albedo_tol = 0.05f;
  return p;
}

// Counts exactly; averages within float rounding. The device sums a tuple's
// neighbours in another order than the double reference: a float sum of n
// positive terms is within (n - 1) 2^-24 of its value, so a mean (two sums) is
// within 2 n 2^-24, and each later pass adds as much again (its inputs' errors
// stay within the same bound, a mean being a convex combination). The tolerance
// is that bound, and at least 1e-5 (a few hundred terms: what most cases hold).
// A tuple whose neighbours differ shows in the counts.
void check_same(const Reference& ref, const DeviceResult& dev) {
  REQUIRE(ref.counts.size() == dev.counts.size());
  size_t count_mismatch = 0, value_mismatch = 0;
  double worst = 0;  // the largest error in units of its tolerance
  for (size_t i = 0; i < ref.counts.size(); ++i) {
    if (ref.counts[i] != dev.counts[i]) ++count_mismatch;
    const float tol = std::max(1e-5f, 2.0f * ref.iterations * float(ref.counts[i]) * 0x1p-24f);
    for (int k = 0; k < 3; ++k) {
      const float err =
          std::fabs(ref.values[i].s[k] - dev.values[i].s[k]) / std::max(1.0f, std::fabs(ref.values[i].s[k]));
      if (err > tol) ++value_mismatch;  // NaN where both are NaN: not counted
      worst = std::max(worst, double(err / tol));
    }
  }
  INFO("largest error " << worst << " of its tolerance");
  CHECK(count_mismatch == 0);
  CHECK(value_mismatch == 0);
  uint32_t max_ref = ref.counts.empty() ? 0 : *std::max_element(ref.counts.begin(), ref.counts.end());
  CHECK(dev.max_count == max_ref);
}

}  // namespace

TEST_CASE("Sort: the scan of the digit counts equals std::exclusive_scan", "[filter]") {
  auto& rt = psf::test::runtime();
  std::mt19937 rng(11);
  // One block, a block and a tail, and (normal sizes) three levels of block sums.
  const std::vector<uint32_t> sizes = psf::test::pick<std::vector<uint32_t>>(
      {1, 2, 255, 1023, 1024, 1025, 4096 + 7, 1048576 + 1029}, {1, 2, 255, 1023, 1024, 1025, 4096 + 7});
  for (uint32_t n : sizes) {
    std::vector<uint32_t> v(n), ref(n);
    for (auto& x : v) x = rng() % 17;  // digit counts: small, zeros among them
    std::exclusive_scan(v.begin(), v.end(), ref.begin(), 0u);
    cl::Buffer data = rt.upload(v, CL_MEM_READ_WRITE);
    cl::Buffer scratch = rt.buffer(CL_MEM_READ_WRITE, sizeof(uint32_t) * psf::scan_scratch_entries(n));
    psf::exclusive_scan(rt, data, n, scratch);
    auto got = rt.download<uint32_t>(data, n);
    INFO("n " << n);
    size_t wrong = 0;
    for (uint32_t i = 0; i < n; ++i) wrong += got[i] != ref[i];
    CHECK(wrong == 0);
  }
}

TEST_CASE("Sort: radix sort equals std::stable_sort", "[filter]") {
  auto& rt = psf::test::runtime();
  std::mt19937 rng(5);
  // Small keeps 65537 (257 work-items of 256 pairs: several work-groups and a
  // tail; 33 tiles of 2048, the last of one pair), for 13 and 32 bits, and drops
  // only 300001 (the 1024 work-item cap). Every variant runs on any device: chunks with 4-bit
  // and 8-bit digits, chunk 0 this device's choice (radix_chunk) and 16 what
  // GPUs used before tiles; tiles (GPUs) with 4-bit digits. Keys have random
  // bits above the `bits` sorted by, which the sort must ignore (the reference
  // compares the low bits only).
  struct Variant {
    psf::RadixKernels kernels;
    uint32_t digit, chunk;
  };
  const Variant variants[] = {{psf::RadixKernels::chunks, 4, 0},
                              {psf::RadixKernels::chunks, 4, 16},
                              {psf::RadixKernels::chunks, 8, 0},
                              {psf::RadixKernels::chunks, 8, 16},
                              {psf::RadixKernels::tiles, 4, 0}};
  const std::vector<uint32_t> sizes = psf::test::pick<std::vector<uint32_t>>(
      {0, 1, 2, 63, 1000, 2048, 65537, 300001}, {0, 1, 2, 63, 1000, 2048, 4097, 65537});
  for (uint32_t n : sizes) {
    for (uint32_t bits : {1u, 4u, 13u, 22u, 32u}) {
      // Small: 65537 with a partial last digit and with every digit only (10 of
      // the tag's 19 minutes under Oclgrind went to its 25 sorts of 65537).
      if (psf::test::small_sizes() && n > 4097 && bits != 13u && bits != 32u) continue;
      for (const Variant& v : variants) {
        std::vector<uint32_t> keys(n), idx(n);
        uint64_t mask = bits == 32 ? 0xFFFFFFFFull : ((1ull << bits) - 1);
        for (auto& k : keys) k = uint32_t(rng());
        std::iota(idx.begin(), idx.end(), 0u);
        std::vector<std::pair<uint32_t, uint32_t>> ref(n);
        for (uint32_t i = 0; i < n; ++i) ref[i] = {keys[i], i};
        std::stable_sort(ref.begin(), ref.end(), [&](auto& a, auto& b) { return (a.first & mask) < (b.first & mask); });
        cl::Buffer kb = rt.upload(keys, CL_MEM_READ_WRITE), vb = rt.upload(idx, CL_MEM_READ_WRITE);
        cl::Buffer tk = rt.buffer(CL_MEM_READ_WRITE, n * 4), tv = rt.buffer(CL_MEM_READ_WRITE, n * 4);
        psf::radix_sort(rt, kb, vb, tk, tv, n, bits, v.chunk, v.digit, v.kernels);
        auto sk = rt.download<uint32_t>(kb, n), sv = rt.download<uint32_t>(vb, n);
        INFO("n " << n << " bits " << bits << " digit " << v.digit << " chunk " << v.chunk << " tiles "
                  << (v.kernels == psf::RadixKernels::tiles));
        size_t wrong = 0;
        for (uint32_t i = 0; i < n; ++i) wrong += sk[i] != ref[i].first || sv[i] != ref[i].second;
        CHECK(wrong == 0);
      }
    }
  }
}

TEST_CASE("Cell ranges: start and end of every key in sorted order", "[filter]") {
  auto& rt = psf::test::runtime();
  std::vector<PathVertex> v = random_tuples(psf::test::pick(20001, 2001), 3, 1.0f);
  FilterParams p = default_params();
  p.footprint = 0.05f;
  uint32_t n = uint32_t(v.size());
  psf::PathSpaceFilter filter(rt, n);
  cl::Buffer vb = rt.upload(v), cb = rt.upload(random_values(n, 4));
  cl::Buffer out = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(cl_float4)), counts = rt.buffer(CL_MEM_READ_WRITE, n * 4);
  // A batch of other tuples and radii first: the starts it wrote must not outlive it.
  p.count = n;
  p.footprint = 0.03f;
  cl::Buffer other = rt.upload(random_tuples(n, 9, 1.0f));
  filter.run(p, 1, other, cb, out, counts);
  p.footprint = 0.05f;
  filter.run(p, 1, vb, cb, out, counts);
  uint32_t bits = psf::filter_key_bits(n), cells = 1u << bits;
  auto keys = rt.download<uint32_t>(filter.sorted_keys(), n);
  auto order = rt.download<uint32_t>(filter.sorted_indices(), n);
  auto starts = rt.download<uint32_t>(filter.cell_starts(), cells + 1);
  CHECK(std::is_sorted(keys.begin(), keys.end()));
  std::vector<uint32_t> perm = order;
  std::sort(perm.begin(), perm.end());
  for (uint32_t i = 0; i < n; ++i) REQUIRE(perm[i] == i);  // a permutation
  // Plain scan: every present key's first and one-past-last position; an absent
  // key's start is where it would be inserted, its end the same (empty).
  std::vector<uint32_t> ref_start(cells + 1, n), ref_end(cells, 0);
  std::vector<bool> present(cells, false);
  size_t invalid = 0;
  for (uint32_t i = n; i-- > 0;) {
    const uint32_t k = std::min(keys[i], cells);
    if (k == cells) ++invalid;
    for (uint32_t e = i == 0 ? 0 : std::min(keys[i - 1], cells) + 1; e <= k; ++e) ref_start[e] = i;
  }
  for (uint32_t i = 0; i < n; ++i)
    if (keys[i] < cells) {
      present[keys[i]] = true;
      ref_end[keys[i]] = i + 1;
    }
  size_t wrong = 0, empty_wrong = 0;
  for (uint32_t k = 0; k < cells; ++k) {
    wrong += starts[k] != ref_start[k];
    if (present[k]) wrong += starts[k + 1] != ref_end[k];
    else empty_wrong += starts[k + 1] != starts[k];
  }
  CHECK(wrong == 0);
  CHECK(empty_wrong == 0);
  CHECK(starts[cells] == n - invalid);
  size_t expect_invalid = std::count_if(v.begin(), v.end(), [](auto& t) { return t.albedo.s[3] == 0.0f; });
  CHECK(invalid == expect_invalid);
  CHECK(rt.download<uint32_t>(filter.valid_count(), 1)[0] == n - invalid);
}

TEST_CASE("Cell ranges: both kernels give each entry the number of keys below it (std::lower_bound)", "[filter]") {
  // cell_ranges (a work-item per tuple, CPUs) and cell_ranges_search (a work-item
  // per entry, GPUs) on sorted keys the filter can produce: dense runs in a few
  // blocks far apart (block-hashed cells), a first key far from 0, duplicates,
  // paths without a vertex (the key 2^key_bits) behind them, or only those.
  auto& rt = psf::test::runtime();
  std::mt19937 rng(61);
  const uint32_t n_big = psf::test::pick(100000u, 5000u);
  struct Case {
    const char* name;
    std::vector<uint32_t> keys;
  };
  std::vector<Case> cases;
  const uint32_t big_cells = 1u << psf::filter_key_bits(n_big);
  {
    std::vector<uint32_t> k;  // three blocks of 4096 entries, a tenth of the paths without a vertex
    for (uint32_t i = 0; i < n_big; ++i) {
      const uint32_t block = std::array<uint32_t, 3>{big_cells / 7, big_cells / 2, big_cells - 4096}[rng() % 3];
      k.push_back(rng() % 10 == 0 ? big_cells : block + rng() % 4096);
    }
    cases.push_back({"three blocks, paths without a vertex", k});
  }
  {
    std::vector<uint32_t> k;  // uniform, many duplicates, every path with a vertex
    for (uint32_t i = 0; i < n_big; ++i) k.push_back(rng() % (n_big / 8));
    cases.push_back({"uniform, duplicates", k});
  }
  cases.push_back({"one key", {12345u % (1u << psf::filter_key_bits(1))}});
  cases.push_back({"one path without a vertex", {1u << psf::filter_key_bits(1)}});
  cases.push_back({"only paths without a vertex", std::vector<uint32_t>(777, 1u << psf::filter_key_bits(777))});
  for (auto& c : cases) {
    INFO(c.name);
    std::sort(c.keys.begin(), c.keys.end());
    const uint32_t n = uint32_t(c.keys.size()), bits = psf::filter_key_bits(n), cells = 1u << bits;
    REQUIRE(c.keys.back() <= cells);
    std::vector<uint32_t> ref(cells + 1);
    for (uint32_t e = 0; e <= cells; ++e)
      ref[e] = uint32_t(std::lower_bound(c.keys.begin(), c.keys.end(), e) - c.keys.begin());
    cl::Buffer keys = rt.upload(c.keys);
    for (const char* kernel : {"cell_ranges", "cell_ranges_search"}) {
      INFO(kernel);
      cl::Buffer starts = rt.upload(std::vector<uint32_t>(cells + 1, 0xDEADBEEFu), CL_MEM_READ_WRITE);
      cl::Buffer valid = rt.upload(std::vector<uint32_t>(1, 0xDEADBEEFu), CL_MEM_READ_WRITE);
      const size_t items = std::string(kernel) == "cell_ranges" ? size_t(n) + 1 : size_t(cells) + 1;
      rt.launch(kernel, items, 64, n, bits, keys, starts, valid);
      const auto got = rt.download<uint32_t>(starts, cells + 1);
      size_t wrong = 0;
      for (uint32_t e = 0; e <= cells; ++e) wrong += got[e] != ref[e];
      CHECK(wrong == 0);
      CHECK(rt.download<uint32_t>(valid, 1)[0] == ref[cells]);
    }
  }
}

TEST_CASE("Filter: neighbour counts and averages equal the brute-force equation", "[filter]") {
  for (bool cells27 : {false, true}) {
    SECTION(cells27 ? "27 cells of size r" : "8 cells of size 2r") {
      FilterParams p = default_params();
      p.cells27 = cells27;
      // Radii stretched by the vertices' footprint stretch (--foreshortening) or not.
      for (uint32_t stretch : {0u, 1u}) {
        p.stretch = stretch;
        // n = 6: keys of 4 bits, so neighbouring cells share keys (cell_key) and the
        // filter must visit each shared one once.
        for (auto [n, extent, footprint] : {std::tuple{3001, 1.0f, 0.02f}, std::tuple{777, 0.2f, 0.01f},
                                            std::tuple{1, 1.0f, 0.02f}, std::tuple{64, 1.0f, 0.02f},
                                            std::tuple{6, 0.05f, 0.02f}}) {
          INFO("n " << n << " extent " << extent << " stretch " << stretch);
          auto v = random_tuples(n, 11 + n, extent);
          auto c = random_values(n, 12 + n);
          p.footprint = footprint;
          check_same(brute_force(v, c, p, 1), run_filter(v, c, p, 1));
        }
      }
    }
  }
}

TEST_CASE("Filter: without the visibility test (--visibility-ray off) averages equal the brute-force equation",
          "[filter]") {
  // A fifth of random_tuples' vertices do not see their light: with the test off
  // they count as neighbours of those that do, and the counts grow.
  FilterParams p = default_params();
  p.ignore_visibility = 1;
  for (int iterations : {1, 3}) {
    for (auto [n, seed] : {std::pair{3001, 41u}, std::pair{1, 42u}, std::pair{200, 43u}}) {
      INFO("n " << n << " iterations " << iterations);
      auto v = random_tuples(n, seed, 1.0f);
      auto c = random_values(n, seed + 100);
      const Reference ref = brute_force(v, c, p, iterations);
      check_same(ref, run_filter(v, c, p, iterations));
      if (n > 1000) {
        FilterParams with_test = p;
        with_test.ignore_visibility = 0;
        const Reference r = brute_force(v, c, with_test, iterations);
        CHECK(std::accumulate(ref.counts.begin(), ref.counts.end(), size_t(0)) >
              std::accumulate(r.counts.begin(), r.counts.end(), size_t(0)) * 11 / 10);
      }
    }
  }
}

TEST_CASE("Filter: demodulated averages (--demodulate) equal the brute-force equation", "[filter]") {
  // Albedos from a few textures' texels: ratios of 1.1-1.5 within a texture,
  // 2-8 between them, dark channels (below the 0.01 floor) and channels that
  // differ in one channel only, so that the log2 distances lie far from the
  // threshold of 0.8 (no count depends on a rounding of log2).
  const float texels[][3] = {{0.5f, 0.4f, 0.3f},   {0.6f, 0.45f, 0.35f}, {0.7f, 0.5f, 0.4f},
                             {0.1f, 0.1f, 0.1f},   {0.12f, 0.11f, 0.1f}, {0.8f, 0.0f, 0.0f},
                             {0.85f, 0.005f, 0.0f}, {0.5f, 0.4f, 0.05f}, {0.0f, 0.0f, 0.0f}};
  FilterParams p = default_params();
  p.demodulate = 1;
  p.albedo_tol = 0.8f;
  for (int iterations : {1, 2}) {
    for (auto [n, seed] : {std::pair{2001, 31u}, std::pair{1, 32u}, std::pair{130, 33u}}) {
      INFO("n " << n << " iterations " << iterations);
      auto v = random_tuples(n, seed, 1.0f);
      std::mt19937 rng(seed);
      for (auto& t : v) {
        const float* a = texels[rng() % 9];
        for (int k = 0; k < 3; ++k) t.albedo.s[k] = a[k];
      }
      auto c = random_values(n, seed + 100);
      const Reference ref = brute_force(v, c, p, iterations);
      check_same(ref, run_filter(v, c, p, iterations));
      if (n > 1000) {  // the albedo's ratio test takes neighbours an absolute test of 0.05 leaves out
        FilterParams plain = p;
        plain.demodulate = 0;
        plain.albedo_tol = 0.05f;
        const Reference r = brute_force(v, c, plain, iterations);
        CHECK(std::accumulate(ref.counts.begin(), ref.counts.end(), size_t(0)) >
              std::accumulate(r.counts.begin(), r.counts.end(), size_t(0)));
      }
    }
  }
}

// The cell key of kernels/cell_keys.cl, written again: per axis the coordinate
// (x's in cells 4 times narrower with cells of 2r) plus an offset, split into
// its low bits (with cells of 2r x: the key's per-axis share + 2, y and z: the
// share - 1; cubes of r: the share each) and its block (the rest); the low bits
// of x as they are, those of y and z interleaved above them; the blocks times a
// constant per axis, XORed with the class's (2 level + light-sample visibility)
// product, hashed (lowbias32) and added (modulo the table's size).
uint32_t host_cell_key(int key_class, const int c[3], uint32_t key_bits, bool cells27 = false) {
  auto lowbias32 = [](uint32_t x) {
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
  };
  const int offset[3] = {1237, 2741, 3593};
  const uint32_t prime[3] = {73856093u, 19349663u, 83492791u};
  const uint32_t per_axis = std::min(key_bits / 3, 10u);
  const uint32_t yz = cells27 ? per_axis : std::max(per_axis, 1u) - 1;
  const uint32_t bits[3] = {cells27 ? per_axis : per_axis + 2, yz, yz};
  uint32_t low[3], blocks = uint32_t(key_class) * 2654435761u;
  for (int a = 0; a < 3; ++a) {
    int o = c[a] + offset[a];
    low[a] = uint32_t(o) & ((1u << bits[a]) - 1u);
    blocks ^= uint32_t(o >> bits[a]) * prime[a];  // arithmetic shift: the floor
  }
  uint32_t key = low[0];
  for (uint32_t b = 0; b < bits[1]; ++b)
    key |= (((low[1] >> b) & 1u) << (bits[0] + 2 * b)) | (((low[2] >> b) & 1u) << (bits[0] + 2 * b + 1));
  return (key + lowbias32(blocks)) & ((1u << key_bits) - 1u);
}

TEST_CASE("Filter: a key shared by two of a query's cells (of different key blocks) is visited once", "[filter]") {
  // Cells of one block of 2^(key bits / 3) cells per axis have distinct keys;
  // cells of neighbouring blocks can share one by chance, and the filter must
  // then scan it once. With 300 tuples (keys of 10 bits: blocks of 4 cells
  // along y and z, 1024 keys) and a global radius of 0.02 (cells of 1/16, 1/64
  // along x), the key written again here finds two cells side by side along y,
  // in different blocks, with one key (neighbours along x never share one: x's
  // low bits are the key's); the tuples lie on a plane through both, within two
  // cells of their common face, so that the queries near it visit both cells.
  // Counting a tuple of either cell twice would change counts and averages.
  FilterParams p = default_params();
  p.r0 = 0.02f;
  const uint32_t n = 300, key_bits = psf::filter_key_bits(n);
  REQUIRE(key_bits == 10);
  const int level = int(std::ceil(std::log2(double(p.r0))));
  const float size = std::ldexp(1.0f, level + 1);
  int pair[3] = {0, 0, 0};
  bool found = false;
  for (int z = 0; z < 64 && !found; ++z)
    for (int y = -64; y < 64 && !found; ++y)
      for (int x = -64; x < 64 && !found; ++x) {
        const int a[3] = {x, y, z}, b[3] = {x, y + 1, z};
        // The tuples below see their light (normal.w = 1): class 2 level + 1.
        if ((y + 1 + 2741) % 4 == 0 &&
            host_cell_key(2 * level + 1, a, key_bits) == host_cell_key(2 * level + 1, b, key_bits)) {
          std::copy(a, a + 3, pair);
          found = true;
        }
      }
  REQUIRE(found);
  INFO("cells (" << pair[0] << ", " << pair[1] << ", " << pair[2] << ") and the next along y share a key");
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<PathVertex> v(n);
  const float face = float(pair[1] + 1) * size;
  for (auto& t : v) {
    t.position = {{(float(pair[0]) + u(rng)) * size / 4.0f, face + (u(rng) - 0.5f) * 4.0f * size,
                   (float(pair[2]) + 0.5f) * size, 1.0f}};
    t.normal = {{0, 0, 1, 1}};
    t.albedo = {{0.5f, 0.5f, 0.5f, 1}};
    t.alpha = {{1, 1, 1, 0}};
  }
  auto c = random_values(n, 5);
  Reference ref = brute_force(v, c, p, 1);
  CHECK(*std::max_element(ref.counts.begin(), ref.counts.end()) > 3);  // the balls hold neighbours
  auto& rt = psf::test::runtime();
  psf::PathSpaceFilter filter(rt, n);
  check_same(ref, run_with(rt, filter, v, c, p, 1));
  // The device keyed both cells alike (else this test would not test the repeat).
  auto keys = rt.download<uint32_t>(filter.sorted_keys(), n);
  auto order = rt.download<uint32_t>(filter.sorted_indices(), n);
  std::set<uint32_t> left, right;
  for (uint32_t k = 0; k < n; ++k) {
    const float y = v[order[k]].position.s[1];  // the two cells: within one cell of the face
    if (y >= face - size && y < face) left.insert(keys[k]);
    if (y >= face && y < face + size) right.insert(keys[k]);
  }
  CHECK(left.size() == 1);
  CHECK(left == right);
}

TEST_CASE("Filter: edge cases: one cell, empty cells, global r0, NaN values, iterations", "[filter]") {
  FilterParams p = default_params();
  SECTION("all points in one cell") {
    auto v = random_tuples(500, 21, 0.01f);  // extent far below the 0.1..0.5 radii
    for (auto& t : v) t.position.s[3] = 10.0f;
    p.footprint = 0.01f;
    check_same(brute_force(v, random_values(500, 22), p, 1), run_filter(v, random_values(500, 22), p, 1));
  }
  SECTION("sparse points: mostly empty cells, every vertex alone") {
    auto v = random_tuples(300, 23, 100.0f);
    p.footprint = 0.001f;
    auto c = random_values(300, 24);
    auto dev = run_filter(v, c, p, 1);
    check_same(brute_force(v, c, p, 1), dev);
    CHECK(dev.max_count == 1);
  }
  SECTION("a global r0 and a shrinking n_scale") {
    auto v = random_tuples(2000, 25, 1.0f);
    auto c = random_values(2000, 26);
    p.r0 = 0.05f;
    p.n_scale = std::pow(16.0f, -0.25f);
    check_same(brute_force(v, c, p, 1), run_filter(v, c, p, 1));
  }
  SECTION("non-finite values never spread to neighbours") {
    auto v = random_tuples(1500, 27, 0.5f);
    auto c = random_values(1500, 28);
    for (size_t i = 0; i < c.size(); i += 37) c[i].s[1] = std::nanf("");
    for (size_t i = 5; i < c.size(); i += 41) c[i].s[0] = INFINITY;
    auto dev = run_filter(v, c, p, 1);
    auto ref = brute_force(v, c, p, 1);
    for (size_t i = 0; i < c.size(); ++i) {
      bool own_finite = std::isfinite(c[i].s[0]) && std::isfinite(c[i].s[1]) && std::isfinite(c[i].s[2]);
      if (own_finite) {
        INFO("tuple " << i);
        REQUIRE(std::isfinite(dev.values[i].s[0] + dev.values[i].s[1] + dev.values[i].s[2]));
        REQUIRE(dev.counts[i] == ref.counts[i]);
      }
    }
  }
  SECTION("no path has a filtering vertex") {
    auto v = random_tuples(700, 41, 1.0f);
    for (auto& t : v) t.albedo.s[3] = 0.0f;
    auto c = random_values(700, 42);
    auto dev = run_filter(v, c, p, 2);
    check_same(brute_force(v, c, p, 2), dev);
    CHECK(dev.max_count == 1);
  }
  SECTION("positive grid levels (radii of 0.5 to 2.5)") {
    auto v = random_tuples(2000, 43, 40.0f);
    auto c = random_values(2000, 44);
    p.footprint = 0.5f;
    check_same(brute_force(v, c, p, 1), run_filter(v, c, p, 1));
  }
  SECTION("one filter, a batch and then a smaller one (the last batch of a render)") {
    auto& rt = psf::test::runtime();
    psf::PathSpaceFilter filter(rt, 3000);
    for (uint32_t n : {3000u, 1234u}) {
      INFO("n " << n);
      auto v = random_tuples(n, 45 + n, 1.0f);
      auto c = random_values(n, 46 + n);
      check_same(brute_force(v, c, p, 2), run_with(rt, filter, v, c, p, 2));
    }
  }
  SECTION("two iterations average the averages") {
    auto v = random_tuples(2500, 29, 1.0f);
    auto c = random_values(2500, 30);
    check_same(brute_force(v, c, p, 2), run_filter(v, c, p, 2));
  }
  SECTION("later iterations: the recorded neighbour lists, and a search again where a list overflowed") {
    // A dense cluster (all in one cell: more neighbours than PSF_FILTER_LIST
    // vectors of candidates hold, so those search again) beside spread tuples
    // (a few neighbours: recorded); four passes over both.
    auto v = random_tuples(2000, 47, 1.0f);
    // Under Oclgrind (small sizes) fewer, which each pass tests in pairs, all of
    // one normal, albedo and visibility, so that as many lists overflow.
    const bool small = psf::test::small_sizes();
    auto dense = random_tuples(small ? 3000 : 10000, 48, 0.01f);
    for (auto& t : dense) {
      t.position.s[0] += 2.0f;
      if (small) {
        t.normal = {{0, 1, 0, 1}};
        t.albedo.s[0] = t.albedo.s[1] = 0.5f;
      }
    }
    v.insert(v.end(), dense.begin(), dense.end());
    auto c = random_values(v.size(), 49);
    auto ref = brute_force(v, c, p, 4);
    size_t overflowed = 0, recorded = 0;
    for (uint32_t n : ref.counts) {
      overflowed += n > PSF_FILTER_LIST * 8 ? 1 : 0;  // more vectors (of at most 8 lanes) than a list holds
      recorded += n > 1 && n <= PSF_FILTER_LIST ? 1 : 0;               // at most one vector each
    }
    CHECK(overflowed > 150);
    CHECK(recorded > 500);
    check_same(ref, run_filter(v, c, p, 4));
  }
}

// The filter's variant that the test device does not use by default (Runtime:
// CPUs 8 lanes without branches, GPUs 2 lanes skipping empty vectors; gather_tuples:
// CPUs 8 tuples per work-item, GPUs 1), with the second pass over the first's
// lists. Their records' offsets in cell order have 7 bits here, +-64 (24 bits with
// 8 lanes): the queries with a record further away search again.
TEST_CASE("Filter: the other device kind's kernel variant equals the brute-force equation", "[filter]") {
  auto& shared = psf::test::runtime();
  const bool gpu = shared.device().type == "GPU";
  psf::Runtime rt(shared.device(), gpu ? "-DPSF_FILTER_LANES=8 -DPSF_FILTER_SKIP=0 -DPSF_FILTER_OFFSET_BITS=7"
                                       : "-DPSF_FILTER_LANES=2 -DPSF_FILTER_SKIP=1 -DPSF_FILTER_OFFSET_BITS=7");
  FilterParams p = default_params();
  for (bool cells27 : {false, true}) {
    p.cells27 = cells27;
    for (auto [n, extent, footprint] : {std::tuple{3001, 1.0f, 0.02f}, std::tuple{777, 0.2f, 0.01f},
                                        std::tuple{1, 1.0f, 0.02f}}) {
      INFO("n " << n << " extent " << extent << " cells27 " << cells27);
      auto v = random_tuples(n, 31 + n, extent);
      auto c = random_values(n, 32 + n);
      for (size_t i = 0; i < c.size(); i += 53) c[i].s[2] = std::nanf("");
      p.footprint = footprint;
      auto dev = run_filter(v, c, p, 2, rt, gpu ? PSF_GATHER_LANES : 1, gpu ? PSF_FILTER_QUERIES : 1);
      auto ref = brute_force(v, c, p, 2);
      size_t wrong = 0;
      for (size_t i = 0; i < c.size(); ++i) {
        bool own_finite = std::isfinite(c[i].s[0]) && std::isfinite(c[i].s[1]) && std::isfinite(c[i].s[2]);
        if (dev.counts[i] != ref.counts[i]) ++wrong;
        for (int k = 0; k < 3 && own_finite; ++k)
          if (std::fabs(ref.values[i].s[k] - dev.values[i].s[k]) > 1e-5f * std::max(1.0f, std::fabs(ref.values[i].s[k])))
            ++wrong;
      }
      CHECK(wrong == 0);
      CHECK(dev.max_count == *std::max_element(ref.counts.begin(), ref.counts.end()));
    }
  }
}

// filter_cells8 (eight queries' cells and reach in vectors, CPUs) against
// filter_cell (one query, GPUs and the later passes) bit for bit, and both
// against the geometry: the cell is floor(x / edge) per axis, and the cells
// visited cover [x - r, x + r], none of them wholly outside it by more than
// 0.1 % of r (the reach has a margin of 1e-4 r for rounding).
TEST_CASE("Filter: the vector cell search equals the scalar one and covers each query's ball", "[filter]") {
  auto& rt = psf::test::runtime();
  const uint32_t n = 4096;  // a multiple of 8
  std::mt19937 rng(77);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<float> xs(n), ys(n), zs(n), rs(n);
  std::vector<int32_t> tags(n);
  std::vector<int> levels(n);
  for (uint32_t i = 0; i < n; ++i) {
    int level = int(u(rng) * 12) - 8;  // cells of 2^-8 .. 2^3 (and twice that with 8 cells)
    float cell = std::ldexp(1.0f, level);
    float r = cell * (0.5f + 0.5f * u(rng));  // r in (2^(level-1), 2^level]
    if (i % 7 == 0) r = cell;                 // the largest radius of the level
    auto coord = [&](int k) {
      float x = (u(rng) - 0.5f) * 40.0f;
      if ((i + k) % 5 == 0) x = std::floor(x / cell) * cell;  // on a face (of the coarser grid too)
      if ((i + k) % 11 == 0) x = std::floor(x / cell) * cell + r * (k ? 0.999999f : 1.0f);  // r from a face
      return x;
    };
    xs[i] = coord(0), ys[i] = coord(1), zs[i] = coord(2), rs[i] = r;
    levels[i] = level;
    tags[i] = level * 4 + int(i % 4);  // the visibility and finiteness bits below the level
  }
  // filter_cells8 loads eight values from each query's index on.
  for (auto* a : {&xs, &ys, &zs, &rs}) a->resize(n + 8, 0.0f);
  tags.resize(n + 8, 0);
  cl::Buffer bx = rt.upload(xs), by = rt.upload(ys), bz = rt.upload(zs), br = rt.upload(rs), bt = rt.upload(tags);
  cl::Buffer vec = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(cl_int4)),
             sca = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(cl_int4));
  for (uint32_t cells27 : {0u, 1u}) {
    INFO("cells27 " << cells27);
    rt.launch("filter_test_cells", n / 8, 1, bx, by, bz, br, bt, cells27, vec, sca);
    auto v = rt.download<cl_int4>(vec, n), s = rt.download<cl_int4>(sca, n);
    size_t differ = 0, wrong_cell = 0, uncovered = 0, too_wide = 0;
    for (uint32_t i = 0; i < n; ++i) {
      if (std::memcmp(&v[i], &s[i], sizeof(cl_int4)) != 0) ++differ;
      // Edges: 2^level (27 cells) or 2^(level+1) (8 cells) along y and z, a quarter of that along x with 8 cells.
      const double size = std::ldexp(1.0, levels[i] + (cells27 ? 0 : 1)),
                   edge[3] = {cells27 ? size : size / 4, size, size};
      const double x[3] = {xs[i], ys[i], zs[i]}, r = rs[i];
      const uint32_t reach = uint32_t(s[i].s[3]);
      const int lo[3] = {-int((reach >> 8) & 0xFFF), int(reach & 3) - 1, int((reach >> 4) & 3) - 1};
      const int hi[3] = {int(reach >> 20), int((reach >> 2) & 3) - 1, int((reach >> 6) & 3) - 1};
      for (int a = 0; a < 3; ++a) {
        const int c = s[i].s[a];
        if (double(c) != std::floor(x[a] / edge[a])) ++wrong_cell;
        const double first = (c + lo[a]) * edge[a], end = (c + hi[a] + 1) * edge[a];
        if (first > x[a] - r || end < x[a] + r) ++uncovered;
        if (first + edge[a] <= x[a] - r * 1.001 || end - edge[a] >= x[a] + r * 1.001) ++too_wide;
      }
    }
    CHECK(differ == 0);
    CHECK(wrong_cell == 0);
    CHECK(uncovered == 0);
    CHECK(too_wide == 0);
  }
}

TEST_CASE("Filter: Cornell box tuples equal the brute-force equation", "[filter]") {
  auto& rt = psf::test::runtime();
  const int res = psf::test::pick(48, 32);
  psf::Scene scene = psf::load_scene(psf::test::source_path("scenes/cornell-box.xml"), {{"res", std::to_string(res)}});
  psf::Renderer renderer(rt, scene);
  psf::RenderOptions o;
  o.spp = 2;
  o.batch_log2 = psf::test::pick(20, 11);  // one batch either way; small: smaller buffers
  o.keep_last_batch = true;
  auto r = renderer.render(o);
  const auto& b = r.last_batch;
  REQUIRE(b.vertices.size() == size_t(res) * res * 2u);
  size_t with_vertex = std::count_if(b.vertices.begin(), b.vertices.end(), [](auto& t) { return t.albedo.s[3] != 0; });
  CHECK(with_vertex > b.vertices.size() * 9 / 10);
  auto dev = run_filter(b.vertices, b.values, b.params, 1);
  check_same(brute_force(b.vertices, b.values, b.params, 1), dev);
  CHECK(dev.max_count > 1);
}

TEST_CASE("Filter: a plane seen at 60 degrees averages as many paths as one facing the camera (foreshortening)",
          "[filter]") {
  // The pixels' footprint on a plane seen at theta has 1 / cos theta of the area
  // it has facing the camera. A ball of the solid angle's radius holds cos theta
  // of the paths (1/2 at 60 degrees); stretched by 1 / sqrt(cos theta) it holds
  // as many as facing. A large white plane under a constant sky (every vertex
  // alike: one normal, one albedo, an open hemisphere), a narrow field of view so
  // that distance and angle barely change across the image.
  const std::string dir = psf::test::temp_dir("psf-filter-foreshortening");
  const std::string path = dir + "/plane.xml";
  {
    std::ofstream f(path);
    f << "<scene version=\"3.0.0\">\n"
         "  <shape type=\"rectangle\"><transform name=\"to_world\"><scale value=\"100\"/></transform>\n"
         "    <bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0.5\"/></bsdf></shape>\n"
         "  <emitter type=\"constant\"/>\n"
         "</scene>\n";
  }
  const int res = psf::test::pick(64, 24);
  auto mean_neighbours = [&](float degrees, bool foreshortening) {
    psf::Scene scene = psf::load_scene(path);
    const float t = glm::radians(degrees);
    psf::test::look_at(scene, {0, -10 * std::sin(t), 10 * std::cos(t)}, {0, 0, 0}, {0, 1, 0}, 8, res);
    psf::Renderer renderer(psf::test::runtime(), scene);
    psf::RenderOptions o;
    o.spp = 4;
    o.max_depth = 2;
    o.filter.foreshortening = foreshortening;
    o.filter.min_removed = 0.0f;
    auto r = renderer.render(o);
    double sum = 0;
    for (float n : r.neighbours) sum += n;
    return sum / r.neighbours.size();
  };
  const double facing = mean_neighbours(0, true), facing_off = mean_neighbours(0, false);
  const double tilted = mean_neighbours(60, true), tilted_off = mean_neighbours(60, false);
  INFO("mean paths averaged: facing " << facing << " (off " << facing_off << "), at 60 degrees " << tilted
                                      << " (off " << tilted_off << ")");
  CHECK(facing > 10);                    // 3 x 3 pixels of 4 paths, the ball shrunk by 4^(-1/4): 18
  CHECK(facing == Approx(facing_off).epsilon(0.01));  // cos ~ 1 (at most 4 degrees off axis): nothing to stretch
  CHECK(tilted / facing == Approx(1.0).margin(0.1));
  CHECK(tilted_off / facing == Approx(0.5).margin(0.07));
}

TEST_CASE("Filter: the unfiltered image of a filtered run equals --filter off bit for bit", "[filter]") {
  auto& rt = psf::test::runtime();
  // Small: 576 pixels, batches of 2048 paths.
  const int res = psf::test::pick(40, 24);
  psf::Scene scene = psf::load_scene(psf::test::source_path("scenes/cornell-box.xml"), {{"res", std::to_string(res)}});
  psf::Renderer renderer(rt, scene);
  psf::RenderOptions o;
  o.spp = 6;
  o.batch_log2 = psf::test::pick(12, 11);  // several batches, wrapping around the image
  auto filtered = renderer.render(o);
  o.filter.enabled = false;
  auto off = renderer.render(o);
  CHECK(filtered.unfiltered.rgb == off.image.rgb);
  CHECK(filtered.image.rgb != off.image.rgb);
  for (float n : off.neighbours) REQUIRE(n == 1.0f);
}

TEST_CASE("Filter: the filtered image approaches the unfiltered one as n grows", "[filter]") {
  auto& rt = psf::test::runtime();
  // Small: 16 x 16 pixels at 1, 8 and 64 spp (a factor 8 between the steps, r
  // shrinking by 8^(1/4)): the filter's work grows with pixels x spp^2, and 256 spp
  // take Oclgrind too long. Natively the ratios are then 0.50 and 0.33.
  const int res = psf::test::pick(32, 16);
  psf::Scene scene = psf::load_scene(psf::test::source_path("scenes/cornell-box.xml"), {{"res", std::to_string(res)}});
  psf::Renderer renderer(rt, scene);
  // The mean absolute difference between the filtered and unfiltered images of
  // the same paths: bias and the noise the filter removes, both shrinking with
  // r(n) = r0 / n^(1/4). A large r0 makes the effect visible at small n.
  auto difference = [&](int spp) {
    psf::RenderOptions o;
    o.spp = spp;
    o.batch_log2 = psf::test::pick(20, 14);  // one batch either way; small: smaller buffers
    o.filter.footprint_pixels = 8.0f;
    auto r = renderer.render(o);
    double sum = 0;
    for (size_t i = 0; i < r.image.rgb.size(); ++i) sum += std::fabs(r.image.rgb[i] - r.unfiltered.rgb[i]);
    return sum / r.image.rgb.size();
  };
  const int spp0 = psf::test::pick(4, 1), step = psf::test::pick(16, 8), spp1 = step * spp0, spp2 = step * spp1;
  double d0 = difference(spp0), d1 = difference(spp1), d2 = difference(spp2);
  INFO("mean |filtered - unfiltered|: " << spp0 << " spp " << d0 << ", " << spp1 << " spp " << d1 << ", " << spp2
                                        << " spp " << d2);
  CHECK(d1 < 0.7 * d0);
  CHECK(d2 < 0.7 * d1);
}

TEST_CASE("Filter: the noise monitor estimates the fraction of a batch's noise the filter removed", "[filter]") {
  // Synthetic batches of grey paths: pixel p's paths have mean m_p and standard
  // deviation sigma_p (unfiltered). The filtered values are the unfiltered ones
  // (nothing removed), the pixel means (all removed), or the mean of the path and
  // one independent path of the same pixel (half the variance removed).
  const uint64_t pixels = 4096, per_pixel = 2;
  std::mt19937 rng(11);
  std::normal_distribution<float> gauss(0.0f, 1.0f);
  auto mean = [](uint64_t p) { return 0.2f + 0.8f * float(p % 7) / 6.0f; };
  auto sigma = [](uint64_t p) { return 0.05f + 0.3f * float(p % 5) / 4.0f; };
  auto grey = [](float v, float w) { return cl_float4{{v, v, v, w}}; };
  auto batch_of = [&](uint64_t index, int mode, uint64_t n) {
    psf::BatchImages b;
    b.index = index;
    b.first = index * n;
    for (uint64_t j = 0; j < n; ++j) {
      const uint64_t p = (b.first + j) % pixels;
      const float u = mean(p) + sigma(p) * gauss(rng), other = mean(p) + sigma(p) * gauss(rng);
      b.unfiltered.push_back(grey(u, 1.0f));
      if (mode == 1) b.filtered.push_back(grey(u, 1.0f));
      if (mode == 2) b.filtered.push_back(grey(mean(p), 8.0f));
      if (mode == 3) b.filtered.push_back(grey(0.5f * (u + other), 2.0f));
    }
    b.max_count = mode == 0 ? 0 : 8;
    return b;
  };
  auto batch = [&](uint64_t index, int mode) { return batch_of(index, mode, pixels * per_pixel); };
  psf::NoiseMonitor m;
  m.reset(pixels);
  CHECK(std::isnan(m.add(batch(0, 1))));  // no variance known before the first batch
  CHECK(std::isnan(m.add(batch(1, 0))));  // not filtered
  for (int k = 2; k < 8; ++k) m.add(batch(k, 0));
  CHECK(m.add(batch(8, 1)) == 0.0);
  // With 16 paths per pixel known, the variance estimate's own scatter is about
  // 1/sqrt(pixels * 15 / 2); the batch's d_p scatter about 1/sqrt(pixels / 2).
  CHECK(m.add(batch(9, 2)) == Approx(1.0).margin(0.06));
  CHECK(m.add(batch(10, 3)) == Approx(0.5).margin(0.04));
  // A path with a non-finite value is left out on both sides.
  psf::BatchImages bad = batch(11, 2);
  bad.unfiltered[5].s[0] = NAN;
  CHECK(m.add(bad) == Approx(1.0).margin(0.06));
  // Batches of 3/4 of the pixels' count: each covers part of the film, and
  // every fourth wraps around its end (the monitor visits only the pixels a
  // batch covers). 24 batches give each pixel 18 paths before the test.
  const uint64_t part = pixels * 3 / 4;
  psf::NoiseMonitor q;
  q.reset(pixels);
  for (int k = 0; k < 24; ++k) q.add(batch_of(k, 0, part));
  CHECK(q.add(batch_of(24, 1, part)) == 0.0);
  CHECK(q.add(batch_of(25, 2, part)) == Approx(1.0).margin(0.07));
  CHECK(q.add(batch_of(26, 3, part)) == Approx(0.5).margin(0.05));
}

TEST_CASE("Filter: switches itself off when it removes less than --min-removed of the noise", "[filter]") {
  auto& rt = psf::test::runtime();
  psf::Scene scene = psf::load_scene(psf::test::source_path("scenes/cornell-box.xml"), {{"res", "24"}});
  psf::Renderer renderer(rt, scene);
  psf::RenderOptions o;
  o.spp = 16;
  o.batch_log2 = 10;  // 1.8 spp per batch: after the first, most pixels have two paths
  o.filter.min_removed = 0.0f;
  auto always = renderer.render(o);
  CHECK(always.filter_off_after == 0);
  o.filter.min_removed = 1.0f;  // the filter never removes all of the noise
  auto off = renderer.render(o);
  CHECK(off.filter_off_after == 2 * 1024);  // the first estimate comes with the second batch
  CHECK(off.filter_removed > 0.0);
  CHECK(off.filter_removed < 1.0);
  // The batches before the switch are filtered as before, the rest not at all.
  CHECK(off.unfiltered.rgb == always.unfiltered.rgb);
  CHECK(off.image.rgb != always.image.rgb);
  CHECK(off.image.rgb != off.unfiltered.rgb);
}

TEST_CASE("Filter: switches itself off when no vertex has a neighbour any more", "[filter]") {
  auto& rt = psf::test::runtime();
  psf::Scene scene = psf::load_scene(psf::test::source_path("scenes/cornell-box.xml"), {{"res", "24"}});
  psf::Renderer renderer(rt, scene);
  psf::RenderOptions o;
  o.spp = 4;
  o.batch_log2 = 10;
  o.filter.r0 = 1e-6f;  // far below the distance between any two vertices
  auto r = renderer.render(o);
  CHECK(r.filter_off_after == 1024);
  CHECK(r.image.rgb == r.unfiltered.rgb);
}
