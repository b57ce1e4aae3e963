// Sobol sampling kernel (kernels/sampling.cl) against the textbook Gray-code
// generator, and the (0,m,2)-net property of its scrambled and unscrambled points.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <set>
#include <sstream>

#include "psf_shared.h"
#include "sampling.h"
#include "support.h"

namespace {

// Direction numbers v_1..v_32 (scaled to 32 bits) of 1-based dimension d, from
// Joe & Kuo's published C++ program (2008), written out again here.
std::vector<uint32_t> reference_directions(int d) {
  std::vector<uint32_t> V(33);
  if (d == 1) {
    for (int i = 1; i <= 32; ++i) V[i] = 1u << (32 - i);
    return V;
  }
  const psf::JoeKuoRow& r = psf::joe_kuo_rows().at(d - 2);
  unsigned s = unsigned(r.s);
  if (32 <= s) {
    for (unsigned i = 1; i <= 32; ++i) V[i] = r.m[i - 1] << (32 - i);
  } else {
    for (unsigned i = 1; i <= s; ++i) V[i] = r.m[i - 1] << (32 - i);
    for (unsigned i = s + 1; i <= 32; ++i) {
      V[i] = V[i - s] ^ (V[i - s] >> s);
      for (unsigned k = 1; k <= s - 1; ++k) V[i] ^= (((r.a >> (s - 1 - k)) & 1u) * V[i - k]);
    }
  }
  return V;
}

// The first n points in Gray-code order: X_0 = 0, X_i = X_{i-1} ^ v_c, c the
// position of the rightmost zero bit of i-1 (Antonov & Saleev 1979).
std::vector<std::vector<uint32_t>> reference_gray(int dims, uint32_t n) {
  std::vector<std::vector<uint32_t>> x(n, std::vector<uint32_t>(dims));
  for (int d = 0; d < dims; ++d) {
    auto V = reference_directions(d + 1);
    uint32_t X = 0;
    x[0][d] = 0;
    for (uint32_t i = 1; i < n; ++i) {
      uint32_t c = 1, value = i - 1;
      while (value & 1u) {
        value >>= 1;
        ++c;
      }
      X ^= V[c];
      x[i][d] = X;
    }
  }
  return x;
}

// scramble: 0 none, 1 scrambled one dimension at a time, 2 eight at a time (a bounce's).
std::vector<uint32_t> device_points(uint32_t first, uint32_t count, uint32_t dims, uint32_t scramble, uint32_t seed,
                                    uint32_t pixel, size_t local = 64) {
  auto& rt = psf::test::runtime();
  cl::Buffer sobol = rt.upload(psf::sobol_matrices());
  cl::Buffer out = rt.buffer(CL_MEM_WRITE_ONLY, size_t(count) * dims * sizeof(uint32_t));
  rt.launch("sobol_points", count, local, sobol, first, count, dims, scramble, seed, pixel, out);
  return rt.download<uint32_t>(out, size_t(count) * dims);
}

// True if every elementary interval of volume 2^-m (splits 2^a x 2^(m-a)) of the
// projection onto dimensions (d0, d1) holds exactly one of the first 2^m points.
bool is_0m2_net(const std::vector<uint32_t>& pts, uint32_t dims, int m, uint32_t d0, uint32_t d1) {
  uint32_t n = 1u << m;
  for (int a = 0; a <= m; ++a) {
    std::vector<int> count(n, 0);
    for (uint32_t i = 0; i < n; ++i) {
      uint64_t x = pts[size_t(i) * dims + d0], y = pts[size_t(i) * dims + d1];
      uint64_t cx = a ? x >> (32 - a) : 0, cy = (m - a) ? y >> (32 - (m - a)) : 0;
      count[(cx << (m - a)) | cy] += 1;
    }
    for (int c : count)
      if (c != 1) return false;
  }
  return true;
}

}  // namespace

TEST_CASE("Sampling: embedded Joe-Kuo rows equal the published file", "[sampling]") {
  auto shared = psf::test::shared_dir();
  if (!shared) {
    WARN("../shared not found (set PSF_SHARED): skipping the comparison with new-joe-kuo-6.21201");
    return;
  }
  std::ifstream in(*shared + "/data/sobol/new-joe-kuo-6.21201");
  if (!in) {
    WARN(*shared << "/data/sobol/new-joe-kuo-6.21201 not found: skipping the comparison");
    return;
  }
  std::string line;
  std::getline(in, line);
  const auto& rows = psf::joe_kuo_rows();
  REQUIRE(rows.size() == PSF_SOBOL_DIMS - 1);
  for (const auto& r : rows) {
    REQUIRE(std::getline(in, line));
    std::istringstream ls(line);
    int d, s;
    uint32_t a;
    ls >> d >> s >> a;
    CHECK(d == r.d);
    CHECK(s == r.s);
    CHECK(a == r.a);
    for (int i = 0; i < s; ++i) {
      uint32_t m;
      ls >> m;
      CHECK(m == r.m[i]);
    }
  }
}

TEST_CASE("Sampling: unscrambled points equal the Gray-code generator bit for bit", "[sampling]") {
  const uint32_t n = 4096, dims = PSF_SOBOL_DIMS;
  auto ref = reference_gray(dims, n);
  auto dev = device_points(0, n, dims, false, 0, 0);
  // Gray-code point i is natural-order point i ^ (i >> 1).
  size_t mismatches = 0;
  for (uint32_t i = 0; i < n; ++i)
    for (uint32_t d = 0; d < dims; ++d)
      if (dev[size_t(i ^ (i >> 1)) * dims + d] != ref[i][d]) ++mismatches;
  CHECK(mismatches == 0);
  // Known leading points of the first two dimensions in natural order:
  // (0,0) (.5,.5) (.25,.75) (.75,.25) (in Gray-code order the last two swap).
  const double expect[4][2] = {{0, 0}, {0.5, 0.5}, {0.25, 0.75}, {0.75, 0.25}};
  for (int i = 0; i < 4; ++i)
    for (int d = 0; d < 2; ++d) CHECK(dev[size_t(i) * dims + d] / 4294967296.0 == expect[i][d]);
}

// Only the first two dimensions of the Sobol sequence form a (0,2)-sequence in
// base 2, so that is the projection tested for the t = 0 net property.
TEST_CASE("Sampling: first 2^m points form (0,m,2)-nets, scrambled and unscrambled", "[sampling]") {
  const uint32_t dims = 2;
  for (bool scramble : {false, true}) {
    for (uint32_t seed : {0u, 7u, 123456789u}) {
      if (!scramble && seed) continue;
      auto pts = device_points(0, 1u << 14, dims, scramble, seed, /*pixel=*/seed * 31u);
      for (int m : {1, 4, 7, 10, 12, 14}) {
        INFO("scramble " << scramble << " seed " << seed << " m " << m);
        CHECK(is_0m2_net(pts, dims, m, 0, 1));
      }
    }
  }
}

TEST_CASE("Sampling: every dimension is stratified in 1D, scrambled", "[sampling]") {
  const uint32_t dims = PSF_SOBOL_DIMS, m = 10, n = 1u << m;
  auto pts = device_points(0, n, dims, true, 42, 5);
  for (uint32_t d = 0; d < dims; ++d) {
    std::set<uint32_t> cells;
    for (uint32_t i = 0; i < n; ++i) cells.insert(pts[size_t(i) * dims + d] >> (32 - m));
    INFO("dimension " << d);
    CHECK(cells.size() == n);
  }
}

TEST_CASE("Sampling: a sample depends only on (seed, pixel, index, dimension)", "[sampling]") {
  const uint32_t dims = PSF_SOBOL_DIMS + 4;  // includes hashed dimensions past the table
  auto whole = device_points(0, 1000, dims, true, 9, 77, 64);
  auto tail = device_points(333, 667, dims, true, 9, 77, 7);  // another offset and work-group size
  for (uint32_t i = 0; i < 667; ++i)
    for (uint32_t d = 0; d < dims; ++d) REQUIRE(tail[size_t(i) * dims + d] == whole[size_t(i + 333) * dims + d]);
  // Another seed or pixel changes the points.
  auto other_seed = device_points(0, 1000, dims, true, 10, 77);
  auto other_pixel = device_points(0, 1000, dims, true, 9, 78);
  size_t same_seed = 0, same_pixel = 0;
  for (size_t k = 0; k < whole.size(); ++k) {
    same_seed += whole[k] == other_seed[k];
    same_pixel += whole[k] == other_pixel[k];
  }
  CHECK(same_seed < whole.size() / 100);
  CHECK(same_pixel < whole.size() / 100);
}

TEST_CASE("Sampling: eight dimensions at once equal the dimensions one at a time", "[sampling]") {
  // Exactly: the path tracer draws a bounce's dimensions together, and the
  // image must not depend on that. Mode 2 draws them as the bounces do, from
  // dimension 2 on in groups starting 7 apart (unaligned vector reads); the
  // dimensions past the table (hashed) and a group straddling its end are included.
  const uint32_t dims = PSF_SOBOL_DIMS + 12;
  for (uint32_t first : {0u, 1000u, 123457u}) {
    auto one = device_points(first, 300, dims, 1, 3, 11);
    auto eight = device_points(first, 300, dims, 2, 3, 11);
    size_t differ = 0;
    for (size_t k = 0; k < one.size(); ++k) differ += one[k] != eight[k];
    INFO("first " << first);
    REQUIRE(differ == 0);
  }
}

TEST_CASE("Sampling: psf_atan2 matches atan2 in double precision", "[sampling]") {
  // Directions all round the circle at radii from 1e-6 to 1e6, random pairs,
  // the axes and the origin (0 by definition). Tolerance 4e-7 absolute: about 1
  // ulp of pi, what float atan2 gives.
  auto& rt = psf::test::runtime();
  std::vector<cl_float2> yx;
  for (int i = 0; i < 20000; ++i) {
    double a = -M_PI + 2.0 * M_PI * (i + 0.5) / 20000.0;
    for (double r : {1e-6, 1.0, 1e6}) yx.push_back({{float(r * std::sin(a)), float(r * std::cos(a))}});
  }
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int i = 0; i < 20000; ++i) yx.push_back({{u(rng), u(rng)}});
  for (float v : {1.0f, -1.0f, 0.5f}) {
    yx.push_back({{v, 0.0f}});
    yx.push_back({{0.0f, v}});
    yx.push_back({{v, v}});
    yx.push_back({{v, -v}});
  }
  cl::Buffer in = rt.upload(yx), out = rt.buffer(CL_MEM_WRITE_ONLY, (yx.size() + 1) * sizeof(float));
  rt.launch("atan2_values", yx.size(), 64, in, cl_uint(yx.size()), out);
  auto got = rt.download<float>(out, yx.size());
  double worst = 0;
  size_t bad = 0;
  for (size_t i = 0; i < yx.size(); ++i) {
    double e = std::abs(got[i] - std::atan2(double(yx[i].s[0]), double(yx[i].s[1])));
    worst = std::max(worst, e);
    bad += e > 4e-7 || !std::isfinite(got[i]);
  }
  INFO("largest error " << worst);
  CHECK(bad == 0);
  cl::Buffer origin = rt.upload(std::vector<cl_float2>{{{0.0f, 0.0f}}});
  rt.launch("atan2_values", 1, 64, origin, cl_uint(1), out);
  CHECK(rt.download<float>(out, 1)[0] == 0.0f);
}

TEST_CASE("Sampling: psf_sincos matches sin and cos in double precision", "[sampling]") {
  // The warps' angles lie in [-pi, 2 pi]; the reduction holds to |x| <= 8192.
  // Tolerance 3e-7 absolute: about 2.5 ulp of 1, what float sincos gives.
  auto& rt = psf::test::runtime();
  std::vector<float> x;
  for (int i = -20000; i <= 20000; ++i) x.push_back(float(i) * float(2.0 * M_PI / 10000.0));  // [-4 pi, 4 pi]
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> wide(-8192.0f, 8192.0f);
  for (int i = 0; i < 20000; ++i) x.push_back(wide(rng));
  for (float v : {0.0f, -0.0f, 1e-30f, -1e-30f, float(M_PI / 4), float(M_PI / 2), float(M_PI), float(2 * M_PI)})
    x.push_back(v);
  cl::Buffer xb = rt.upload(x), ob = rt.buffer(CL_MEM_WRITE_ONLY, x.size() * sizeof(cl_float2));
  rt.launch("sincos_values", x.size(), 64, xb, cl_uint(x.size()), ob);
  auto got = rt.download<cl_float2>(ob, x.size());
  double worst = 0;
  size_t bad = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    double es = std::abs(got[i].s[0] - std::sin(double(x[i]))), ec = std::abs(got[i].s[1] - std::cos(double(x[i])));
    worst = std::max({worst, es, ec});
    bad += es > 3e-7 || ec > 3e-7 || !std::isfinite(got[i].s[0]) || !std::isfinite(got[i].s[1]);
  }
  INFO("largest error " << worst);
  CHECK(bad == 0);
}
