// Lights: the environment map's sampling against its distribution (scalar
// references written here, separately from host/lights.cpp), delta lights,
// selection by power, Mitsuba emitter parsing, and analytic scenes rendered
// through the whole pipeline (psf::Renderer) under each kind of light.
// Under PSF_TEST_SMALL (psf::test::small_sizes(), set by scripts/oclgrind) the
// envmap chi-square test draws 2^16 samples instead of 2^18 (its bounds follow
// the count); the renders keep their paths, since their tolerances are set by
// that noise.
#include <stb_image_write.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <numeric>
#include <random>

#include "bvh.h"
#include "compare.h"
#include "image.h"
#include "lights.h"
#include "render.h"
#include "scene/loaders.h"
#include "scene/materials.h"
#include "scene/scene.h"
#include "support.h"

namespace fs = std::filesystem;

namespace {

constexpr double kPi = 3.14159265358979323846;

// A fresh directory under the system's temporary directory, removed at the end of the test.
class TempDir {
 public:
  TempDir() {
    static int counter = 0;
    path_ = fs::temp_directory_path() /
            ("psf-emitter-test-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  std::string write(const std::string& name, const std::string& text) const {
    fs::path p = path_ / name;
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
  }
  std::string path(const std::string& name) const { return (path_ / name).string(); }

 private:
  fs::path path_;
};

double lum(double r, double g, double b) { return 0.2126 * r + 0.7152 * g + 0.0722 * b; }

// A 16x8 test map: a smooth gradient, a bright spot, and a black block of texels.
psf::LightDesc test_envmap(int width = 16, int height = 8) {
  psf::LightDesc l;
  l.type = psf::LightType::Envmap;
  l.width = width;
  l.height = height;
  l.texels.resize(size_t(width) * height * 3);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      float* t = &l.texels[(size_t(y) * width + x) * 3];
      t[0] = 0.2f + 0.1f * float(x);
      t[1] = 0.5f + 0.3f * float(y);
      t[2] = 1.0f + 0.05f * float(x * y);
      if (x == 11 && y == 2) t[0] = t[1] = t[2] = 40.0f;  // a sun
      if (x >= 3 && x <= 5 && y >= 4 && y <= 5) t[0] = t[1] = t[2] = 0.0f;
    }
  return l;
}

// Rotation about +y by `degrees` (the living room's envmap is rotated by 90).
glm::mat3 rotation_y(float degrees) {
  float a = glm::radians(degrees), c = std::cos(a), s = std::sin(a);
  return glm::mat3(glm::vec3(c, 0, -s), glm::vec3(0, 1, 0), glm::vec3(s, 0, c));  // columns
}

// Mitsuba's lat-long coordinates (u, v) of a map-frame direction, and the cell
// of the W x H sampling grid holding them, written out here independently.
glm::dvec2 uv_of(const glm::dvec3& m) {
  double u = std::atan2(m.x, -m.z) / (2 * kPi);
  if (u < 0) u += 1;
  return {u, std::acos(std::clamp(m.y, -1.0, 1.0)) / kPi};
}
void texel_of(const glm::dvec3& m, int width, int height, int& x, int& y) {
  glm::dvec2 uv = uv_of(m);
  x = std::min(int(uv.x * width), width - 1);
  y = std::min(int(uv.y * height), height - 1);
}

// The map's RGB at (u, v) as Mitsuba 3's envmap reads it: bilinear, column x's
// centre at u = (x + 0.5) / W with the columns wrapping around, row y at
// v = y / (H - 1).
glm::dvec3 env_bilinear(const psf::LightDesc& env, double u, double v) {
  const int W = env.width, H = env.height;
  double fx = u * W - 0.5, fy = v * (H - 1);
  int x0 = int(std::floor(fx)), y0 = std::min(int(std::floor(fy)), H - 2);
  double tx = fx - x0, ty = fy - y0;
  auto at = [&](int x, int y) {
    x = ((x % W) + W) % W;
    const float* t = &env.texels[(size_t(y) * W + size_t(x)) * 3];
    return glm::dvec3(t[0], t[1], t[2]);
  };
  return (1 - ty) * ((1 - tx) * at(x0, y0) + tx * at(x0 + 1, y0)) + ty * ((1 - tx) * at(x0, y0 + 1) + tx * at(x0 + 1, y0 + 1));
}

// Midpoint sums over a fine grid of (u, v) points: `steps` per cell of the
// W x H grid along each axis; f(u, v, cell x, cell y, du dv) for each.
template <class F>
void for_fine_grid(const psf::LightDesc& env, int steps, F&& f) {
  const int W = env.width, H = env.height;
  const double du = 1.0 / (W * steps), dv = 1.0 / (H * steps);
  for (int j = 0; j < H * steps; ++j)
    for (int i = 0; i < W * steps; ++i) f((i + 0.5) * du, (j + 0.5) * dv, i / steps, j / steps, du * dv);
}

struct DeviceLights {
  cl::Buffer emitters, cdf, env_data;
  Environment env{};
  uint32_t count = 0;
};

DeviceLights upload(psf::Runtime& rt, const psf::LightTable& t) {
  DeviceLights d;
  d.emitters = rt.upload(t.emitters);
  d.cdf = rt.upload(t.cdf);
  d.env_data = rt.upload(t.env_data);
  d.env = t.env;
  d.count = uint32_t(t.emitters.size());
  return d;
}

struct Sample {
  glm::vec3 wi;
  float pdf;
  glm::vec3 radiance;
  float dist;
  bool delta;
};

// Light samples from point p for the given uniform triples, through the device's emitter_sample.
std::vector<Sample> sample_lights(psf::Runtime& rt, const DeviceLights& d, const glm::vec3& p,
                                  const std::vector<cl_float4>& u) {
  uint32_t n = uint32_t(u.size());
  cl::Buffer ub = rt.upload(u);
  cl::Buffer out = rt.buffer(CL_MEM_WRITE_ONLY, size_t(n) * 3 * sizeof(cl_float4));
  cl_float4 pp = {{p.x, p.y, p.z, 0}};
  rt.launch("light_sample_points", n, 64, n, d.emitters, d.cdf, d.count, d.env, d.env_data, pp, ub, out);
  auto raw = rt.download<cl_float4>(out, size_t(n) * 3);
  std::vector<Sample> s(n);
  for (uint32_t i = 0; i < n; ++i) {
    const cl_float4 &a = raw[3 * i], &b = raw[3 * i + 1], &c = raw[3 * i + 2];
    s[i] = {{a.s[0], a.s[1], a.s[2]}, a.s[3], {b.s[0], b.s[1], b.s[2]}, b.s[3], c.s[0] > 0.5f};
  }
  return s;
}

std::vector<cl_float4> uniform_triples(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(0.0f, 1.0f);
  std::vector<cl_float4> u(n);
  for (auto& v : u) v = {{U(rng), U(rng), U(rng), 0}};
  return u;
}

// Environment radiance and env_pdf along world directions, through the device.
std::vector<cl_float4> eval_env(psf::Runtime& rt, const DeviceLights& d, const std::vector<glm::vec3>& dirs) {
  std::vector<cl_float4> in(dirs.size());
  for (size_t i = 0; i < dirs.size(); ++i) in[i] = {{dirs[i].x, dirs[i].y, dirs[i].z, 0}};
  cl::Buffer b = rt.upload(in);
  cl::Buffer out = rt.buffer(CL_MEM_WRITE_ONLY, dirs.size() * sizeof(cl_float4));
  rt.launch("env_eval_points", dirs.size(), 64, uint32_t(dirs.size()), d.env, d.env_data, b, out);
  return rt.download<cl_float4>(out, dirs.size());
}

// --- scenes for the renders -----------------------------------------------------

// Appends the quad corner, corner + a, corner + a + b, corner + b (front: a x b).
void add_quad(psf::Scene& s, glm::vec3 corner, glm::vec3 a, glm::vec3 b, uint32_t material) {
  uint32_t base = uint32_t(s.positions.size());
  s.positions.insert(s.positions.end(), {corner, corner + a, corner + a + b, corner + b});
  s.triangles.push_back({base, base + 1, base + 2});
  s.triangles.push_back({base, base + 2, base + 3});
  s.tri_material.insert(s.tri_material.end(), 2, material);
}

// A scene of one quad (as add_quad) emitting radiance 1 and reflecting nothing.
psf::Scene emitting_quad(glm::vec3 corner, glm::vec3 a, glm::vec3 b) {
  psf::Scene s;
  Material light{};
  light.type = PSF_MATERIAL_DIFFUSE;
  light.emission = {{1, 1, 1, 0}};
  s.materials = {light};
  s.material_names = {"light"};
  add_quad(s, corner, a, b, 0);
  return s;
}

uint32_t add_material(psf::Scene& s, float albedo, bool two_sided = false) {
  Material m{};
  m.albedo = {{albedo, albedo, albedo, 0}};
  m.type = PSF_MATERIAL_DIFFUSE;
  m.two_sided = two_sided ? 1u : 0u;
  s.materials.push_back(m);
  s.material_names.push_back("diffuse");
  return uint32_t(s.materials.size() - 1);
}

// A constant environment of radiance `radiance`.
psf::LightDesc constant_sky(glm::vec3 radiance) {
  psf::LightDesc sky;
  sky.type = psf::LightType::Constant;
  sky.color = radiance;
  return sky;
}

psf::RenderResult render(const psf::Scene& s, int spp, int max_depth = -1) {
  psf::Renderer r(psf::test::runtime(), s);
  psf::RenderOptions o;
  o.spp = spp;
  o.max_depth = max_depth;
  o.filter.enabled = false;  // plain path tracing: the analytic answers are its expectations
  return r.render(o);
}

glm::dvec3 pixel(const psf::Image& img, int x, int y) {
  const float* p = &img.rgb[(size_t(y) * img.width + x) * 3];
  return {p[0], p[1], p[2]};
}

// The point of the plane z = 0 seen through film position (x, y) in pixels
// (kernels/camera.cl's pinhole); (x + 0.5, y + 0.5) is the centre of pixel (x, y).
glm::dvec3 plane_point(const psf::Scene& s, double x, double y) {
  Camera c = psf::make_camera(s.camera, s.width, s.height);
  glm::dvec3 o(c.origin.s[0], c.origin.s[1], c.origin.s[2]);
  glm::dvec3 f(c.forward.s[0], c.forward.s[1], c.forward.s[2]), r(c.right.s[0], c.right.s[1], c.right.s[2]),
      d(c.down.s[0], c.down.s[1], c.down.s[2]);
  double sx = x / s.width, sy = y / s.height;
  glm::dvec3 dir = f + (2 * sx - 1) * r + (2 * sy - 1) * d;
  return o + dir * (-o.z / dir.z);
}

// A diffuse plane z = 0 facing +z, seen from (0, 0, 4) straight down.
psf::Scene plane_scene(float albedo, int size) {
  psf::Scene s;
  uint32_t m = add_material(s, albedo);
  add_quad(s, {-20, -20, 0}, {40, 0, 0}, {0, 40, 0}, m);
  s.camera.origin = {0, 0, 4};
  s.camera.target = {0, 0, 0};
  s.camera.up = {0, 1, 0};
  s.camera.fov_degrees = 60;
  s.width = s.height = size;
  return s;
}

}  // namespace

// Samples of a width x height map against its distribution: chi-square over the
// texels, the pdf and radiance each sample carries, the integral estimate, env_pdf.
static void check_envmap_sampling(int width, int height) {
  INFO("envmap " << width << "x" << height);
  auto& rt = psf::test::runtime();
  psf::Scene scene;
  psf::LightDesc env = test_envmap(width, height);
  env.to_world = rotation_y(90.0f);
  env.color = glm::vec3(2.0f);
  scene.lights.push_back(env);
  psf::LightTable table = psf::build_light_table(scene);
  REQUIRE(table.emitters.size() == 1);
  REQUIRE(table.env.present == 1);
  DeviceLights d = upload(rt, table);

  // The scalar reference: P(cell) = mean of the bilinear luminance over the cell
  // times sin(theta at the row centre) / sum, the mean by a midpoint sum.
  const int W = env.width, H = env.height;
  std::vector<double> prob(size_t(W) * H, 0.0);
  for_fine_grid(env, 32, [&](double u, double v, int x, int y, double) {
    glm::dvec3 c = env_bilinear(env, u, v);
    prob[size_t(y) * W + x] += lum(c.x, c.y, c.z) * std::sin((y + 0.5) * kPi / H);
  });
  double sum = 0;
  for (double p : prob) sum += p;
  for (double& p : prob) p /= sum;

  const size_t n = size_t(1) << psf::test::pick(18, 16);
  std::vector<Sample> samples = sample_lights(rt, d, {0, 0, 0}, uniform_triples(n, 7));
  std::vector<double> count(prob.size(), 0.0);
  glm::dmat3 to_map = glm::transpose(glm::dmat3(env.to_world));
  double estimate = 0;  // of the integral of luminance over the sphere: mean of L / pdf
  size_t bad_pdf = 0, bad_radiance = 0;
  std::vector<glm::vec3> dirs;
  for (const Sample& s : samples) {
    REQUIRE(s.pdf > 0.0f);
    CHECK_FALSE(s.delta);
    CHECK(std::isinf(s.dist));
    glm::dvec3 m = to_map * glm::dvec3(s.wi);
    int x, y;
    texel_of(m, W, H, x, y);
    size_t t = size_t(y) * W + x;
    count[t] += 1;
    // Sample -> pdf: P(cell) W H / (2 pi^2 sin theta), theta of the sampled direction.
    double sin_theta = std::sqrt(m.x * m.x + m.z * m.z);
    double ref_pdf = prob[t] * W * H / (2 * kPi * kPi * sin_theta);
    if (std::abs(s.pdf - ref_pdf) > 2e-3 * ref_pdf) ++bad_pdf;
    glm::dvec2 uv = uv_of(m);
    glm::dvec3 ref = 2.0 * env_bilinear(env, uv.x, uv.y);
    if (std::abs(s.radiance.x - ref.x) > 1e-3 * (1 + ref.x) || std::abs(s.radiance.z - ref.z) > 1e-3 * (1 + ref.z))
      ++bad_radiance;
    estimate += lum(s.radiance.x, s.radiance.y, s.radiance.z) / s.pdf;
    if (dirs.size() < 4096) dirs.push_back(s.wi);
  }
  CHECK(bad_pdf == 0);
  CHECK(bad_radiance == 0);

  // Chi-square over the cells with P > 0; cells whose four corner texels are
  // all black get no samples.
  double chi2 = 0;
  int dof = -1;
  for (size_t t = 0; t < prob.size(); ++t) {
    if (prob[t] == 0) {
      CHECK(count[t] == 0);
      continue;
    }
    double e = prob[t] * double(n);
    chi2 += (count[t] - e) * (count[t] - e) / e;
    ++dof;
  }
  // Mean dof, standard deviation sqrt(2 dof): 6 sigma is a false alarm rate below 1e-6.
  INFO("chi2 " << chi2 << " with " << dof << " degrees of freedom");
  CHECK(chi2 < dof + 6 * std::sqrt(2.0 * dof));

  // The estimator of the integral of L over the sphere against a midpoint sum
  // of the bilinear luminance times the solid angle 2 pi^2 sin(theta) du dv.
  double reference = 0;
  for_fine_grid(env, 32, [&](double u, double v, int, int, double dudv) {
    glm::dvec3 c = 2.0 * env_bilinear(env, u, v);
    reference += lum(c.x, c.y, c.z) * 2 * kPi * kPi * std::sin(v * kPi) * dudv;
  });
  CHECK(estimate / double(n) == Approx(reference).epsilon(0.01));

  // env_pdf of the sampled directions is the pdf the sample carried.
  std::vector<cl_float4> eval = eval_env(rt, d, dirs);
  for (size_t i = 0; i < dirs.size(); ++i) REQUIRE(eval[i].s[3] == Approx(samples[i].pdf).epsilon(1e-3));
}

TEST_CASE("Emitter: envmap samples follow luminance x sin(theta) (chi-square)", "[emitter]") {
  // One block of PSF_ENV_BLOCK texels per row, and rows of three blocks, the last partial.
  check_envmap_sampling(16, 8);
  check_envmap_sampling(37, 9);
}

TEST_CASE("Emitter: guide tables lead to the cdf entry a bisection finds", "[emitter]") {
  // The kernel's search (emitter.cl sample_cdf_guided) in float arithmetic as
  // there, against std::upper_bound over the whole cdf (the first entry above u,
  // the last if none), for cdfs with flat runs, a jump over many buckets, many
  // entries within one bucket, and for u on and beside every bucket boundary.
  auto guided = [](const std::vector<float>& cdf, const std::vector<float>& guide, float u) {
    const uint32_t n = uint32_t(cdf.size());
    uint32_t i;
    std::memcpy(&i, &guide[std::min(uint32_t(u * float(n)), n - 1)], sizeof i);  // the index's bits
    while (i < n - 1 && cdf[i] <= u) ++i;
    return i;
  };
  std::mt19937 rng(7);
  std::vector<std::vector<float>> cdfs;
  for (size_t n : {1u, 2u, 3u, 7u, 64u, 1000u}) {
    std::vector<double> w(n);
    std::uniform_real_distribution<double> U(0.0, 1.0);
    for (double& x : w) x = U(rng) < 0.3 ? 0.0 : U(rng);      // flat runs
    if (n > 2) w[n / 2] = 1000.0 * double(n);                  // a jump over many buckets
    if (n > 8) std::fill(w.begin(), w.begin() + long(n / 4), 1e-7);  // many tiny entries in one bucket
    double total = 0, acc = 0;
    for (double x : w) total += x;
    std::vector<float> cdf(n);
    for (size_t i = 0; i < n; ++i) cdf[i] = float((acc += w[i]) / total);
    cdf[n - 1] = 1.0f;
    cdfs.push_back(cdf);
  }
  for (const auto& cdf : cdfs) {
    const size_t n = cdf.size();
    std::vector<float> guide;
    psf::cdf_guide_table(cdf.data(), n, guide);
    REQUIRE(guide.size() == n);
    std::vector<float> us;
    for (size_t k = 0; k <= n; ++k) {
      float b = float(double(k) / double(n));
      for (float u : {b, std::nextafter(b, 0.0f), std::nextafter(b, 1.0f)})
        if (u >= 0.0f && u < 1.0f) us.push_back(u);
    }
    for (float c : cdf)
      for (float u : {c, std::nextafter(c, 0.0f), std::nextafter(c, 1.0f)})
        if (u >= 0.0f && u < 1.0f) us.push_back(u);
    std::uniform_real_distribution<float> U(0.0f, 1.0f);
    for (int i = 0; i < 10000; ++i) us.push_back(U(rng));
    for (float u : us) {
      const uint32_t bisection =
          uint32_t(std::min<ptrdiff_t>(std::upper_bound(cdf.begin(), cdf.end(), u) - cdf.begin(), ptrdiff_t(n) - 1));
      INFO("n = " << n << ", u = " << u);
      REQUIRE(guided(cdf, guide, u) == bisection);
    }
  }
}

TEST_CASE("Emitter: envmap orientation follows Mitsuba's lat-long convention", "[emitter]") {
  auto& rt = psf::test::runtime();
  // Texel (x, y) holds x + 10 y + 1 in red: every texel is distinct.
  psf::LightDesc env;
  env.type = psf::LightType::Envmap;
  env.width = 8;
  env.height = 4;
  env.texels.assign(8 * 4 * 3, 0.0f);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 8; ++x) env.texels[(size_t(y) * 8 + x) * 3] = float(x + 10 * y + 1);
  auto red_of = [&](const glm::mat3& to_world, const glm::vec3& dir) {
    psf::Scene s;
    psf::LightDesc l = env;
    l.to_world = to_world;
    s.lights.push_back(l);
    DeviceLights d = upload(rt, psf::build_light_table(s));
    return eval_env(rt, d, {glm::normalize(dir)})[0].s[0];
  };
  // Mitsuba: u = atan2(d.x, -d.z) / 2 pi, v = acos(d.y) / pi. So -z is the map's
  // left edge (u = 0), +x a quarter across, +z the middle, -x three quarters;
  // +y the top row, -y the bottom row. Mitsuba 3 reads the map bilinearly with
  // column x's centre at u = (x + 0.5) / W and row y at v = y / (H - 1).
  auto dir = [](double u, double v) {
    double phi = 2 * kPi * u, theta = kPi * v;
    return glm::vec3(glm::dvec3(std::sin(phi) * std::sin(theta), std::cos(theta), -std::cos(phi) * std::sin(theta)));
  };
  auto centre = [&](int x, int y) { return dir((x + 0.5) / 8.0, y / 3.0); };
  glm::mat3 id(1.0f);
  CHECK(red_of(id, centre(2, 1)) == Approx(1 + 2 + 10 * 1).margin(1e-3));
  CHECK(red_of(id, centre(4, 1)) == Approx(1 + 4 + 10 * 1).margin(1e-3));
  CHECK(red_of(id, centre(6, 2)) == Approx(1 + 6 + 10 * 2).margin(1e-3));
  // Between centres: a quarter of the way to column 3, half way to row 2.
  CHECK(red_of(id, dir(2.75 / 8.0, 1.5 / 3.0)) == Approx(0.5 * (13.25 + 23.25)).margin(1e-3));
  // -z (u = 0) lies half way between the last column and the first.
  CHECK(red_of(id, dir(0.0, 1.0 / 3.0)) == Approx(0.5 * (18 + 11)).margin(1e-3));
  // The poles: rows 0 and 3.
  float top = red_of(id, {0.0f, 1.0f, 0.0f}), bottom = red_of(id, {0.0f, -1.0f, 0.0f});
  CHECK((top >= 1 && top <= 8));
  CHECK((bottom >= 31 && bottom <= 38));
  // to_world rotates the map: with the living room's rotation about +y by 90
  // degrees, the map's +z (u = 0.5) lies along world +x.
  glm::mat3 r = rotation_y(90.0f);
  CHECK(glm::length(r * glm::vec3(0, 0, 1) - glm::vec3(1, 0, 0)) < 1e-6f);
  CHECK(red_of(r, {1.0f, 0.3f, 0.05f}) == Approx(red_of(id, {-0.05f, 0.3f, 1.0f})).margin(1e-3));
}

TEST_CASE("Emitter: point, spot and directional samples", "[emitter]") {
  auto& rt = psf::test::runtime();
  psf::Scene s;
  psf::LightDesc point;
  point.type = psf::LightType::Point;
  point.position = {1, 2, 3};
  point.color = {2, 4, 6};
  s.lights = {point};
  {
    DeviceLights d = upload(rt, psf::build_light_table(s));
    Sample x = sample_lights(rt, d, {0, 0, 0}, {{{0.3f, 0.5f, 0.5f, 0}}})[0];
    CHECK(x.delta);
    CHECK(x.pdf == Approx(1.0f));
    CHECK(x.dist == Approx(std::sqrt(14.0f)));
    CHECK(glm::length(x.wi - glm::normalize(glm::vec3(1, 2, 3))) < 1e-6f);
    CHECK(x.radiance.x == Approx(2.0f / 14.0f));
    CHECK(x.radiance.z == Approx(6.0f / 14.0f));
  }

  // Spot at the origin along -z, cutoff 20, beam width 15 degrees: full intensity
  // inside 15 degrees, (20 - angle) / 5 between, nothing beyond 20.
  psf::LightDesc spot;
  spot.type = psf::LightType::Spot;
  spot.direction = {0, 0, -1};
  spot.color = glm::vec3(5.0f);
  spot.cutoff_angle = glm::radians(20.0f);
  spot.beam_width = glm::radians(15.0f);
  s.lights = {spot};
  {
    DeviceLights d = upload(rt, psf::build_light_table(s));
    for (float deg : {0.0f, 10.0f, 17.0f, 19.0f, 25.0f}) {
      float a = glm::radians(deg);
      glm::vec3 p = 2.0f * glm::vec3(std::sin(a), 0, -std::cos(a));
      Sample x = sample_lights(rt, d, p, {{{0.5f, 0.5f, 0.5f, 0}}})[0];
      float falloff = deg <= 15 ? 1.0f : deg >= 20 ? 0.0f : (20 - deg) / 5;
      INFO(deg << " degrees off the axis");
      CHECK(x.radiance.x == Approx(5.0f * falloff / 4.0f).margin(1e-5));
    }
  }

  psf::LightDesc sun;
  sun.type = psf::LightType::Directional;
  sun.direction = glm::normalize(glm::vec3(1, -2, 0));
  sun.color = glm::vec3(3.0f);
  s.lights = {sun};
  {
    DeviceLights d = upload(rt, psf::build_light_table(s));
    Sample x = sample_lights(rt, d, {5, 5, 5}, {{{0.9f, 0.1f, 0.1f, 0}}})[0];
    CHECK(x.delta);
    CHECK(std::isinf(x.dist));
    CHECK(glm::length(x.wi + sun.direction) < 1e-6f);
    CHECK(x.radiance.y == Approx(3.0f));
  }
}

TEST_CASE("Emitter: lights are chosen in proportion to their power", "[emitter]") {
  // A unit-luminance point light (power 4 pi), a directional light of irradiance
  // 1 over a scene of bounding radius R = sqrt(3) (power pi R^2 = 3 pi) and an
  // emissive triangle of area 2 and radiance 1 (power pi A = 2 pi).
  psf::Scene s;
  Material lamp{};
  lamp.emission = {{1, 1, 1, 0}};
  s.materials.push_back(lamp);
  s.positions = {{-1, -1, -1}, {1, -1, -1}, {1, 1, 1}};  // bounding box diagonal 2 sqrt(3)
  s.triangles = {{0, 1, 2}};
  s.tri_material = {0};
  float area = 0.5f * glm::length(glm::cross(s.positions[1] - s.positions[0], s.positions[2] - s.positions[0]));
  psf::LightDesc point, sun;
  point.type = psf::LightType::Point;
  sun.type = psf::LightType::Directional;
  s.lights = {point, sun};
  psf::LightTable t = psf::build_light_table(s);
  REQUIRE(t.emitters.size() == 3);
  double total = kPi * area + 4 * kPi + 3 * kPi;
  CHECK(t.emitters[0].type == PSF_EMITTER_TRIANGLE);
  CHECK(t.emitters[0].radiance.s[3] == Approx(kPi * area / total));
  CHECK(t.emitters[1].radiance.s[3] == Approx(4 * kPi / total));
  CHECK(t.emitters[2].radiance.s[3] == Approx(3 * kPi / total));
  REQUIRE(t.cdf.size() == 6);  // the cdf and its guide table
  CHECK(t.cdf[2] == 1.0f);
  CHECK(t.tri_light_pdf[0] == Approx(kPi * area / total / area));
  CHECK(t.env.present == 0);

  // A ground sphere of radius 1e5 makes the sun's power (pi R^2 E) 1e10 times
  // the lamp's: the lights at infinity keep at most 0.9 of the samples, and
  // the triangle and the point light share the rest in proportion.
  psf::Scene g = s;
  psf::SphereShape ground;
  ground.center = {0, -1e5f, 0};
  ground.radius = 1e5f;
  g.materials.push_back(Material{});  // not emissive
  ground.material = 1;
  g.spheres = {ground};
  psf::LightTable u = psf::build_light_table(g);
  REQUIRE(u.emitters.size() == 3);
  CHECK(u.emitters[2].type == PSF_EMITTER_DIRECTIONAL);
  CHECK(u.emitters[2].radiance.s[3] == Approx(0.9));
  CHECK(u.emitters[0].radiance.s[3] == Approx(0.1 * area / (area + 4)));
  CHECK(u.emitters[1].radiance.s[3] == Approx(0.1 * 4 / (area + 4)));
  CHECK(u.tri_light_pdf[0] == Approx(0.1 * area / (area + 4) / area));
  // Lights at infinity alone keep their proportions (no bound applies).
  g.triangles.clear();
  g.tri_material.clear();
  g.lights = {sun};
  psf::LightTable v = psf::build_light_table(g);
  REQUIRE(v.emitters.size() == 1);
  CHECK(v.emitters[0].radiance.s[3] == 1.0f);
}

TEST_CASE("Emitter: Mitsuba 0.5 and 3 emitter parameters", "[emitter]") {
  TempDir dir;
  // A 4x2 Radiance HDR map and a 4x2 OpenEXR map.
  std::vector<float> px(4 * 2 * 3);
  for (size_t i = 0; i < px.size(); ++i) px[i] = 0.25f * float(i % 7 + 1);
  REQUIRE(stbi_write_hdr(dir.path("sky.hdr").c_str(), 4, 2, 3, px.data()) != 0);
  psf::Image exr;
  exr.width = 4;
  exr.height = 2;
  exr.rgb = px;
  psf::write_exr(dir.path("sky.exr"), exr);

  auto load = [&](const std::string& version, const std::string& body) {
    return psf::load_scene(dir.write("scene.xml", "<scene version=\"" + version + "\">\n" + body + "</scene>\n"));
  };
  SECTION("Mitsuba 0.5 camelCase") {
    psf::Scene s = load("0.5.0",
                        "<emitter type=\"point\"><point name=\"position\" x=\"1\" y=\"2\" z=\"3\"/>"
                        "<spectrum name=\"intensity\" value=\"5\"/></emitter>\n"
                        "<emitter type=\"spot\"><float name=\"cutoffAngle\" value=\"30\"/><float name=\"beamWidth\" value=\"10\"/>"
                        "<rgb name=\"intensity\" value=\"1 2 3\"/><transform name=\"toWorld\">"
                        "<lookat origin=\"0 5 0\" target=\"0 0 0\" up=\"0 0 1\"/></transform></emitter>\n"
                        "<emitter type=\"directional\"><vector name=\"direction\" x=\"0\" y=\"-2\" z=\"0\"/>"
                        "<rgb name=\"irradiance\" value=\"4\"/></emitter>\n"
                        "<emitter type=\"envmap\"><string name=\"filename\" value=\"sky.hdr\"/><float name=\"scale\" value=\"3\"/>"
                        "<transform name=\"toWorld\"><rotate y=\"1\" angle=\"90\"/></transform></emitter>\n");
    REQUIRE(s.lights.size() == 4);
    const psf::LightDesc &p = s.lights[0], &sp = s.lights[1], &d = s.lights[2], &e = s.lights[3];
    CHECK(p.type == psf::LightType::Point);
    CHECK(p.position == glm::vec3(1, 2, 3));
    CHECK(p.color.x == Approx(5.0f));  // a uniform spectrum in Mitsuba 0.5 is the value itself
    CHECK(sp.type == psf::LightType::Spot);
    CHECK(glm::length(sp.position - glm::vec3(0, 5, 0)) < 1e-5f);
    CHECK(glm::length(sp.direction - glm::vec3(0, -1, 0)) < 1e-5f);
    CHECK(sp.cutoff_angle == Approx(glm::radians(30.0f)));
    CHECK(sp.beam_width == Approx(glm::radians(10.0f)));
    CHECK(sp.color == glm::vec3(1, 2, 3));
    CHECK(d.type == psf::LightType::Directional);
    CHECK(glm::length(d.direction - glm::vec3(0, -1, 0)) < 1e-6f);
    CHECK(d.color == glm::vec3(4.0f));
    CHECK(e.type == psf::LightType::Envmap);
    CHECK(e.width == 4);
    CHECK(e.height == 2);
    CHECK(e.color == glm::vec3(3.0f));
    CHECK(e.texels[5] == Approx(px[5]).epsilon(0.01));  // RGBE keeps 8 bits of mantissa
    CHECK(glm::length(e.to_world * glm::vec3(0, 0, 1) - glm::vec3(1, 0, 0)) < 1e-5f);
    CHECK(e.source.find("scene.xml:5") != std::string::npos);
  }
  SECTION("Mitsuba 3 snake_case, defaults and warnings") {
    psf::Scene s = load("3.0.0",
                        "<emitter type=\"spot\"><float name=\"cutoff_angle\" value=\"40\"/>"
                        "<transform name=\"to_world\"><translate x=\"1\"/></transform></emitter>\n"
                        "<emitter type=\"point\"><transform name=\"to_world\"><translate y=\"7\"/></transform>"
                        "<float name=\"sampling_weight\" value=\"2\"/><float name=\"mystery\" value=\"1\"/></emitter>\n"
                        "<emitter type=\"envmap\"><string name=\"filename\" value=\"sky.exr\"/></emitter>\n"
                        "<emitter type=\"constant\"><rgb name=\"radiance\" value=\"1\"/></emitter>\n"
                        "<emitter type=\"sunsky\"/>\n");
    REQUIRE(s.lights.size() == 3);
    CHECK(s.lights[0].beam_width == Approx(glm::radians(30.0f)));  // 3/4 of the cutoff angle
    CHECK(s.lights[0].position == glm::vec3(1, 0, 0));
    CHECK(glm::length(s.lights[0].direction - glm::vec3(0, 0, 1)) < 1e-6f);
    CHECK(s.lights[1].position == glm::vec3(0, 7, 0));
    CHECK(s.lights[2].type == psf::LightType::Envmap);
    CHECK(s.lights[2].texels[4] == Approx(px[4]).epsilon(1e-3));  // written as float, read back as half
    auto count = [&](const std::string& text) {
      return std::count_if(s.warnings.begin(), s.warnings.end(),
                           [&](const std::string& w) { return w.find(text) != std::string::npos; });
    };
    CHECK(count(":3: property 'mystery' of emitter 'point'") == 1);
    CHECK(count("sampling_weight") == 0);
    CHECK(count(":5: only one environment emitter") == 1);
    CHECK(count(":6: emitter 'sunsky' is not supported") == 1);
  }
  SECTION("an area emitter's radiance texture") {
    const unsigned char glow[] = {255, 128, 0};
    REQUIRE(stbi_write_png(dir.path("glow.png").c_str(), 1, 1, 3, glow, 3) != 0);
    psf::Scene s = load("3.0.0",
                        "<shape type=\"rectangle\"><emitter type=\"area\"><texture name=\"radiance\" "
                        "type=\"bitmap\"><string name=\"filename\" value=\"glow.png\"/></texture></emitter></shape>\n");
    REQUIRE(s.materials.size() == 1);
    const Material& m = s.materials[0];
    CHECK(m.emission.s[0] == 1.0f);
    REQUIRE(m.tex_emission != PSF_NO_TEXTURE);
    CHECK(s.textures.at(m.tex_emission).width == 1u);
    psf::LightTable t = psf::build_light_table(s);
    REQUIRE(t.emitters.size() == 2);  // the rectangle's two triangles
    CHECK(t.emitters[0].tex_emission == m.tex_emission);
  }
  SECTION("negative texels are set to 0 with a warning") {
    psf::Image neg = exr;
    neg.rgb[4] = -2.0f;
    psf::write_exr(dir.path("neg.exr"), neg);
    psf::Scene s = load("3.0.0", "<emitter type=\"envmap\"><string name=\"filename\" value=\"neg.exr\"/></emitter>\n");
    REQUIRE(s.lights.size() == 1);
    CHECK(s.lights[0].texels[4] == 0.0f);
    CHECK(std::count_if(s.warnings.begin(), s.warnings.end(), [](const std::string& w) {
            return w.find(":2: 1 negative values") != std::string::npos;
          }) == 1);
  }
  SECTION("errors name the file and line") {
    try {
      load("3.0.0", "<emitter type=\"envmap\">\n<string name=\"filename\" value=\"gone.exr\"/></emitter>\n");
      FAIL("no error");
    } catch (const psf::SceneError& e) {
      CHECK(e.line() == 3);
      CHECK(std::string(e.what()).find("gone.exr") != std::string::npos);
    }
    CHECK_THROWS_AS(load("3.0.0", "<emitter type=\"point\"><rgb name=\"intensity\" value=\"-1\"/></emitter>\n"),
                    psf::SceneError);
    CHECK_THROWS_AS(load("3.0.0", "<emitter type=\"directional\"><vector name=\"direction\" value=\"0 0 0\"/></emitter>\n"),
                    psf::SceneError);
  }
}

TEST_CASE("Render: a diffuse quad under a constant environment shows albedo x L", "[emitter]") {
  // Nothing occludes the quad's upper hemisphere: irradiance pi L, outgoing rho L.
  psf::Scene s;
  uint32_t m = add_material(s, 0.6f);
  add_quad(s, {-1, -1, 0}, {2, 0, 0}, {0, 2, 0}, m);
  s.camera.origin = {0, 0, 2};
  s.camera.target = {0, 0, 0};
  s.camera.fov_degrees = 30;  // sees [-0.54, 0.54]^2 of the quad
  s.width = s.height = 16;
  s.lights = {constant_sky(glm::vec3(1.0f, 0.5f, 0.25f))};
  psf::RenderResult r = render(s, 64);
  CHECK(r.nonfinite == 0);
  glm::dvec3 mean(0.0);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) mean += pixel(r.image, x, y) / 256.0;
  // The estimate combines the environment sample and the escaped BSDF ray by
  // MIS; 16384 paths leave about 0.5 % noise: allow 2 %.
  CHECK(mean.x == Approx(0.6).epsilon(0.02));
  CHECK(mean.y == Approx(0.3).epsilon(0.02));
  CHECK(mean.z == Approx(0.15).epsilon(0.02));

  // Camera rays that miss see the environment itself, exactly.
  s.camera.fov_degrees = 120;
  psf::RenderResult wide = render(s, 4);
  glm::dvec3 corner = pixel(wide.image, 0, 0);
  CHECK(corner.x == Approx(1.0).epsilon(1e-6));
  CHECK(corner.z == Approx(0.25).epsilon(1e-6));

  // Mitsuba's hide_emitters: camera rays that miss see black; the quad is lit as before.
  s.hide = PSF_HIDE_ENVIRONMENT;
  psf::RenderResult hidden = render(s, 4);
  CHECK(pixel(hidden.image, 0, 0) == glm::dvec3(0.0));
  CHECK(pixel(hidden.image, 8, 8) == pixel(wide.image, 8, 8));  // the quad, bit for bit
}

TEST_CASE("Render: hide_emitters hides an area emitter from camera rays only as Mitsuba 0.5 does", "[emitter]") {
  // An emitting quad (radiance 1) above a diffuse floor (albedo 0.5), seen from
  // below the lamp: the lamp's pixels show 1 unless hidden; the floor is lit the same either way.
  psf::Scene s;
  Material light{};
  light.type = PSF_MATERIAL_DIFFUSE;
  light.emission = {{1, 1, 1, 0}};
  s.materials = {light};
  s.material_names = {"light"};
  add_quad(s, {-0.5f, -0.5f, 2}, {0, 1, 0}, {1, 0, 0}, 0);  // facing -z
  uint32_t floor = add_material(s, 0.5f);
  add_quad(s, {-4, -4, 0}, {8, 0, 0}, {0, 8, 0}, floor);
  s.camera.origin = {0, -1.5f, 1};
  s.camera.target = {0, 0, 1.5f};
  s.camera.up = {0, 0, 1};
  s.camera.fov_degrees = 90;
  s.width = s.height = 16;
  psf::RenderResult shown = render(s, 16);
  s.hide = PSF_HIDE_AREA;
  psf::RenderResult hidden = render(s, 16);
  // Pixels wholly on the lamp turn black; the others keep their value bit for
  // bit (the floor's light arrives after a bounce), except at the lamp's edge,
  // where they lose the samples that hit it.
  size_t lamp = 0, unchanged = 0;
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) {
      glm::dvec3 a = pixel(shown.image, x, y), b = pixel(hidden.image, x, y);
      if (a == glm::dvec3(1.0)) {
        ++lamp;
        CHECK(b == glm::dvec3(0.0));
      } else if (b == a) {
        ++unchanged;
      } else {
        CHECK(b.x < a.x);
      }
    }
  CHECK(lamp >= 4);
  CHECK(unchanged >= 150);
}

// The quad [-1, 1]^2 at z = 0 (facing +z) with material 0 of `materials`, seen
// from (0, 0, camera_z) at 16x16 under a constant sky of 1 that reaches both sides.
static psf::Scene quad_under_sky(const std::vector<Material>& materials, float camera_z) {
  psf::Scene s;
  s.materials = materials;
  s.material_names.assign(materials.size(), "m");
  add_quad(s, {-1, -1, 0}, {2, 0, 0}, {0, 2, 0}, 0);
  s.camera.origin = {0, 0, camera_z};
  s.camera.target = {0, 0, 0};
  s.camera.fov_degrees = 30;
  s.width = s.height = 16;
  s.lights = {constant_sky(glm::vec3(1.0f))};
  return s;
}

TEST_CASE("Render: a dielectric's textured transmittance tints what passes, not what it reflects", "[emitter]") {
  // A thin glass quad (eta 1.5) whose specular_transmittance is a texture of
  // (0.2, 0.5, 0.8), under a sky of 1 on both sides, seen head-on: it reflects
  // R = F + (1 - F)^2 F / (1 - F^2) of the sky (F = 0.04: R = 0.0769) and
  // transmits (1 - R) t, so each channel reads R + (1 - R) t.
  Material m{};
  m.type = PSF_MATERIAL_THIN_DIELECTRIC;
  m.eta = {{1.5f, 1 / 2.25f, 0, 0}};
  m.specular = m.transmittance = {{1, 1, 1, 0}};
  psf::Scene s = quad_under_sky({m}, 2.0f);
  psf::detail::TextureStore store(s);
  psf::detail::TextureDesc flat;
  s.materials[0].tex_color = store.pixels(flat, 1, 1, {0.2f, 0.5f, 0.8f, 1});
  s.materials[0].flags |= PSF_MATFLAG_TEX_TRANSMITTANCE;
  psf::RenderResult r = render(s, 256);
  glm::dvec3 sum(0.0);
  for (int y = 4; y < 12; ++y)
    for (int x = 4; x < 12; ++x) sum += pixel(r.image, x, y);
  const double F = 0.04, R = F + (1 - F) * (1 - F) * F / (1 - F * F);
  for (int c = 0; c < 3; ++c) CHECK(sum[c] / 64 == Approx(R + (1 - R) * glm::dvec3(0.2, 0.5, 0.8)[c]).epsilon(0.01));
}

TEST_CASE("Render: a normal map lets no light through the surface (Mitsuba 3's side rule)", "[emitter]") {
  // A diffuse quad of albedo 0.8 whose normal map tilts the normal by 60 degrees
  // towards dp/du, under a sky of 1 that reaches both sides, seen from above.
  // Only directions above both the quad and the tilted normal scatter (Mitsuba
  // 3's normalmap): the radiance is 0.8 / pi times the tilted cosine integrated
  // over the two hemispheres' intersection, (pi / 2)(1 + cos 60), so 0.6; letting
  // directions through the quad, as before, gave the whole hemisphere's 0.8.
  Material m{};
  m.type = PSF_MATERIAL_DIFFUSE;
  m.albedo = {{0.8f, 0.8f, 0.8f, 0}};
  psf::Scene s = quad_under_sky({m}, 2.0f);
  psf::detail::TextureStore store(s);
  psf::detail::TextureDesc flat;
  const float t = std::sin(3.14159265f / 3), c = std::cos(3.14159265f / 3);
  s.materials[0].tex_bump = store.pixels(flat, 1, 1, {0.5f * t + 0.5f, 0.5f, 0.5f * c + 0.5f, 1});
  s.materials[0].bump_scale = 1.0f;
  s.materials[0].flags |= PSF_MATFLAG_NORMALMAP;
  psf::RenderResult r = render(s, 256);
  double sum = 0;
  for (int y = 4; y < 12; ++y)
    for (int x = 4; x < 12; ++x) sum += pixel(r.image, x, y).y;
  CHECK(sum / 64 == Approx(0.8 * 0.75).epsilon(0.01));  // 64 pixels x 256 paths
}

TEST_CASE("Render: vertex colours multiply a diffuse quad's albedo, interpolated across each triangle", "[emitter]") {
  // Under a constant sky of 1 an unoccluded diffuse surface shows its albedo:
  // here white times the colour interpolated (barycentrically, in each of the
  // quad's two triangles) from red, green, blue and yellow corners.
  Material white{};
  white.type = PSF_MATERIAL_DIFFUSE;
  white.albedo = {{1, 1, 1, 0}};
  white.flags = PSF_MATFLAG_VERTEX_COLOR;  // the loaders' mark: this material's colour term reads them
  psf::Scene s = quad_under_sky({white}, 2.0f);
  const glm::dvec3 corner[4] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 0}};
  s.colors = {glm::vec3(corner[0]), glm::vec3(corner[1]), glm::vec3(corner[2]), glm::vec3(corner[3])};
  psf::RenderResult r = render(s, 64);
  // The expected colour at each pixel centre; the rendered and expected means
  // over each quarter of the image (64 pixels x 64 paths: about 0.6 % noise).
  auto expected = [&](double x, double y) {
    glm::dvec3 p = plane_point(s, x, y);
    glm::dvec3 q[4] = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
    // Triangle (0, 1, 2) below the diagonal y = x, (0, 2, 3) above it.
    const int a = 0, b = p.y <= p.x ? 1 : 2, c = p.y <= p.x ? 2 : 3;
    glm::dvec3 e1 = q[b] - q[a], e2 = q[c] - q[a], d = p - q[a];
    double det = e1.x * e2.y - e1.y * e2.x;
    double u = (d.x * e2.y - d.y * e2.x) / det, v = (e1.x * d.y - e1.y * d.x) / det;
    return (1 - u - v) * corner[a] + u * corner[b] + v * corner[c];
  };
  for (int qy = 0; qy < 2; ++qy)
    for (int qx = 0; qx < 2; ++qx) {
      glm::dvec3 got(0.0), want(0.0);
      for (int y = 8 * qy; y < 8 * qy + 8; ++y)
        for (int x = 8 * qx; x < 8 * qx + 8; ++x) {
          got += pixel(r.image, x, y) / 64.0;
          want += expected(x + 0.5, y + 0.5) / 64.0;
        }
      INFO("quarter " << qx << ", " << qy << ": got " << got.x << " " << got.y << " " << got.z << ", want " << want.x
                      << " " << want.y << " " << want.z);
      for (int k = 0; k < 3; ++k) CHECK(std::fabs(got[k] - want[k]) < 0.02 * std::max(want[k], 0.1));
    }
  // Without the mark the same triangles show the white albedo (a blend part
  // that does not read the colours is not tinted by them).
  s.materials[0].flags = 0;
  psf::RenderResult plain = render(s, 64);
  glm::dvec3 mean(0.0);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) mean += pixel(plain.image, x, y) / 256.0;
  for (int k = 0; k < 3; ++k) CHECK(mean[k] == Approx(1.0).epsilon(0.02));
}

TEST_CASE("Render: an OBJ light (Ke) emits from its front only, as Mitsuba's area lights", "[emitter]") {
  // A lamp quad facing -z (clockwise seen from +z) and nothing else: from below
  // the camera sees its Ke; from above its back, which neither emits nor has
  // anything to reflect. Emitting from both sides, a panel just below a ceiling
  // (McGuire's Cornell boxes) lit the ceiling through the gap: fireflies.
  namespace fs = std::filesystem;
  fs::path dir = psf::test::temp_dir("psf-obj-lamp");
  std::ofstream(dir / "lamp.mtl") << "newmtl lamp\nKd 0.5 0.5 0.5\nKe 1 0.5 0.25\nnewmtl wall\nKd 0.5 0.5 0.5\n";
  std::ofstream(dir / "lamp.obj") << "mtllib lamp.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
                                     "usemtl lamp\nf 1 4 3 2\n"
                                     "v 5 5 0\nv 6 5 0\nv 6 6 0\nusemtl wall\nf 5 6 7\n";
  psf::Scene s = psf::load_scene((dir / "lamp.obj").string());
  REQUIRE(s.materials.size() == 2);
  CHECK(s.materials[0].two_sided == 0u);  // the lamp
  CHECK(s.materials[1].two_sided == 1u);  // the wall scatters on both sides
  psf::test::look_at(s, {0, 0, -2}, {0, 0, 0}, {0, 1, 0}, 30, 8);
  psf::Image below = render(s, 4).image;
  psf::test::look_at(s, {0, 0, 2}, {0, 0, 0}, {0, 1, 0}, 30, 8);
  psf::Image above = render(s, 4).image;
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) {
      INFO("pixel " << x << ", " << y);
      glm::dvec3 front = pixel(below, x, y), back = pixel(above, x, y);
      CHECK(front.x == Approx(1.0).epsilon(1e-6));
      CHECK(front.z == Approx(0.25).epsilon(1e-6));
      CHECK(back.x == 0.0);
      CHECK(back.y == 0.0);
    }
}

TEST_CASE("Render: an OBJ mirror model (illum 3, 5, 8) reflects Ks + (1 - max Ks) Kd", "[emitter]") {
  // MTL's reflection models weight a mirror reflection by Ks: psf blends a
  // conductor reflecting Ks / max(Ks) (probability max(Ks)) with diffuse Kd.
  // Under a constant sky of 1 both parts reflect their colour, so the quad shows
  // Ks + (1 - max Ks) Kd; illum 2 (a highlight, no mirror) stays a plastic.
  namespace fs = std::filesystem;
  fs::path dir = psf::test::temp_dir("psf-obj-mirror");
  std::ofstream(dir / "m.mtl") << "newmtl mirror\nKd 0.5 0.25 0.1\nKs 0.4 0.2 0.1\nNs 10000000\nillum 5\n"
                                  "newmtl rough\nKd 0.5 0.25 0.1\nKs 0.4 0.2 0.1\nNs 100\nillum 3\n"
                                  "newmtl plastic\nKd 0.5 0.25 0.1\nKs 0.4 0.2 0.1\nNs 100\nillum 2\n";
  for (const char* name : {"mirror", "rough", "plastic"}) {
    std::ofstream(dir / "m.obj") << "mtllib m.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nusemtl " << name
                                 << "\nf 1 2 3 4\n";
    psf::Scene s = psf::load_scene((dir / "m.obj").string());
    INFO(name);
    const Material& top = s.materials[s.tri_material[0]];
    if (std::string(name) == "plastic") {
      CHECK(top.type == PSF_MATERIAL_ROUGH_PLASTIC);
      CHECK(top.blend == 0u);
      continue;
    }
    REQUIRE(top.blend != 0u);
    const Material& part = s.materials[top.blend - 1];
    CHECK(top.type == PSF_MATERIAL_DIFFUSE);
    CHECK(part.type == (std::string(name) == "mirror" ? PSF_MATERIAL_CONDUCTOR : PSF_MATERIAL_ROUGH_CONDUCTOR));
    CHECK(top.blend_weight == Approx(0.4f));
    CHECK(s.material_names[top.blend - 1] == std::string(name) + " (mirror)");
    if (std::string(name) == "rough") continue;  // a rough conductor loses energy to its microfacets' shadowing
    psf::test::look_at(s, {0, 0, 2}, {0, 0, 0}, {0, 1, 0}, 30, 16);
    s.lights = {constant_sky(glm::vec3(1.0f))};
    psf::RenderResult r = render(s, 64);
    glm::dvec3 mean(0.0);
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) mean += pixel(r.image, x, y) / 256.0;
    // 16384 paths; the sky's and the blend's noise about 1 %: allow 2 %.
    CHECK(mean.x == Approx(0.4 + 0.6 * 0.5).epsilon(0.02));
    CHECK(mean.y == Approx(0.2 + 0.6 * 0.25).epsilon(0.02));
    CHECK(mean.z == Approx(0.1 + 0.6 * 0.1).epsilon(0.02));
  }
}

TEST_CASE("Render: the pixel filter spreads a step edge as its cdf", "[emitter]") {
  // An emitting half-plane x > 0 (radiance 1, nothing else, max depth 1) seen
  // square-on: its edge falls on the boundary between pixels 7 and 8 of 16. A
  // pixel k's value is the chance that a sample at k + 0.5 + X lies right of the
  // edge, P(X > 7.5 - k) for the filter's offset X, computed here from each
  // filter's own formula: box of half-width 0.5, tent of radius r (a triangle),
  // Gaussian of stddev 0.5 cut off at 4 stddev (Mitsuba's), Phi its normal cdf.
  psf::Scene s = emitting_quad({0, -50, 0}, {50, 0, 0}, {0, 100, 0});
  psf::test::look_at(s, {0, 0, 4}, {0, 0, 0}, {0, 1, 0}, 40, 16);
  s.height = 4;
  s.camera.fov_axis = "x";
  auto phi = [](double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); };
  struct Case {
    const char* filter;
    float radius;
    std::function<double(double)> above;  // P(X > a)
  };
  const std::vector<Case> cases = {
      {"box", 1.0f, [](double a) { return std::clamp(0.5 - a, 0.0, 1.0); }},
      {"tent", 1.0f, [](double a) { return a >= 1 ? 0.0 : a <= -1 ? 1.0 : a >= 0 ? 0.5 * (1 - a) * (1 - a)
                                                                                 : 1 - 0.5 * (1 + a) * (1 + a); }},
      {"tent", 2.0f, [](double a) { return a >= 2 ? 0.0 : a <= -2 ? 1.0 : a >= 0 ? (2 - a) * (2 - a) / 8
                                                                                 : 1 - (2 + a) * (2 + a) / 8; }},
      {"gaussian", 1.0f, [&](double a) {
         const double cut = phi(4.0) - phi(-4.0);
         return a >= 2 ? 0.0 : a <= -2 ? 1.0 : (phi(4.0) - phi(a / 0.5)) / cut;
       }}};
  for (const Case& c : cases) {
    INFO(c.filter << " of radius " << c.radius);
    s.camera.pixel_filter = c.filter;
    s.camera.filter_radius = c.radius;
    s.camera.filter_stddev = 0.5f;
    psf::RenderResult r = render(s, 256, 1);
    for (int k = 4; k < 12; ++k) {
      INFO("pixel " << k);
      double mean = 0;
      for (int y = 0; y < 4; ++y) mean += pixel(r.image, k, y).x / 4.0;
      // 1024 stratified samples a column: the fraction is within about 1/1024.
      CHECK(mean == Approx(c.above(7.5 - k)).margin(0.006));
    }
  }
}

TEST_CASE("Render: a blended material scatters as the weighted sum of its two BSDFs", "[emitter]") {
  // The quad under a constant sky of 1 (above): each material alone shows its
  // albedo; a blend with weight w shows (1 - w) rho_a + w rho_b. The choice is
  // per shading point, so w = 0 and w = 1 give the two materials' own images.
  auto scene = [](float weight, uint32_t texture, std::vector<float> texel) {
    Material a{}, b{};
    a.type = b.type = PSF_MATERIAL_DIFFUSE;
    a.albedo = {{0.2f, 0.6f, 0.1f, 0}};
    b.albedo = {{0.8f, 0.1f, 0.5f, 0}};
    a.blend = 2;  // 1 + the index of b
    a.blend_weight = weight;
    psf::Scene s = quad_under_sky({a, b}, 2.0f);
    if (texture) {
      psf::detail::TextureStore store(s);
      psf::detail::TextureDesc nearest;
      nearest.bilinear = false;
      s.materials[0].tex_blend = store.pixels(nearest, 1, 1, texel);
    }
    return s;
  };
  auto mean_of = [](const psf::RenderResult& r) {
    glm::dvec3 mean(0.0);
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) mean += pixel(r.image, x, y) / 256.0;
    return mean;
  };
  const glm::dvec3 expected = 0.75 * glm::dvec3(0.2, 0.6, 0.1) + 0.25 * glm::dvec3(0.8, 0.1, 0.5);
  // A constant weight, and a texture's x channel (0.5, the other channels 0) times 0.5.
  for (auto [weight, texture] : {std::pair{0.25f, 0u}, std::pair{0.5f, 1u}}) {
    INFO("weight " << weight << (texture ? " times a texture of 0.5" : ""));
    glm::dvec3 mean = mean_of(render(scene(weight, texture, {0.5f, 0.0f, 0.0f, 1.0f}), 64));
    // 16384 paths; the choice adds about 0.6 % noise to the 0.5 % of the sky's: 2 %.
    CHECK(mean.x == Approx(expected.x).epsilon(0.02));
    CHECK(mean.y == Approx(expected.y).epsilon(0.02));
    CHECK(mean.z == Approx(expected.z).epsilon(0.02));
  }
  // A chain: b blends in turn with c (weight 0.5): a 0.75, b 0.125, c 0.125.
  psf::Scene chain = scene(0.25f, 0u, {});
  Material c{};
  c.type = PSF_MATERIAL_DIFFUSE;
  c.albedo = {{0.4f, 0.9f, 0.0f, 0}};
  chain.materials.push_back(c);
  chain.material_names.push_back("c");
  chain.materials[1].blend = 3;
  chain.materials[1].blend_weight = 0.5f;
  glm::dvec3 mean = mean_of(render(chain, 64));
  const glm::dvec3 chained = 0.75 * glm::dvec3(0.2, 0.6, 0.1) + 0.125 * glm::dvec3(0.8, 0.1, 0.5) +
                             0.125 * glm::dvec3(0.4, 0.9, 0.0);
  CHECK(mean.x == Approx(chained.x).epsilon(0.02));
  CHECK(mean.y == Approx(chained.y).epsilon(0.02));
  CHECK(mean.z == Approx(chained.z).epsilon(0.02));
  // A partner outside the material table is dropped before upload.
  psf::Scene bad = scene(0.5f, 0u, {});
  bad.materials[0].blend = 3;
  CHECK(psf::device_materials(bad, psf::triangle_attributes(bad))[0].blend == 0);
  CHECK(psf::device_materials(chain, psf::triangle_attributes(chain))[1].blend == 3);
  for (float weight : {0.0f, 1.0f}) {
    INFO("weight " << weight);
    psf::Scene alone = scene(0.0f, 0u, {});
    if (weight == 1.0f) alone.materials[0] = alone.materials[1];
    alone.materials[0].blend = 0;
    CHECK(render(scene(weight, 0u, {}), 4).image.rgb == render(alone, 4).image.rgb);
  }
}

TEST_CASE("Render: a two-sided material with a back BSDF shows each side's own", "[emitter]") {
  // Mitsuba's twosided with two BSDFs: diffuse 0.2 in front (+z, the quad's
  // winding), 0.8 behind, under a constant sky of 1 that reaches both sides.
  auto view = [](float z) {
    Material front{}, back{};
    front.type = back.type = PSF_MATERIAL_DIFFUSE;
    front.albedo = {{0.2f, 0.2f, 0.2f, 0}};
    back.albedo = {{0.8f, 0.8f, 0.8f, 0}};
    front.two_sided = back.two_sided = 1;
    front.blend = 2;
    front.flags = PSF_MATFLAG_BACK_PARTNER;
    psf::RenderResult r = render(quad_under_sky({front, back}, z), 16);
    double mean = 0;
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) mean += pixel(r.image, x, y).y / 256.0;
    return mean;
  };
  // 4096 paths each, no choice noise (the side decides): 2 %.
  CHECK(view(2.0f) == Approx(0.2).epsilon(0.02));
  CHECK(view(-2.0f) == Approx(0.8).epsilon(0.02));
}

// An emitting square of radiance 1 and side 1 at z = 0 facing +z, seen from
// (0, 0, camera_z) at 32x32.
static psf::Scene emitting_square(float camera_z) {
  psf::Scene s = emitting_quad({-0.5f, -0.5f, 0}, {1, 0, 0}, {0, 1, 0});
  s.camera.origin = {0, 0, camera_z};
  s.camera.target = {0, 0, 0};
  s.width = s.height = 32;
  return s;
}

TEST_CASE("Render: a thin lens images its focal plane as a pinhole does and blurs the rest", "[emitter]") {
  // An emitting square of radiance 1 (side 1) 4 units in front of the camera,
  // emission only (max depth 1). Focused on it, every lens ray of a film point
  // meets the point the pinhole ray meets, so the image is the pinhole's;
  // focused at 2 units, its edges spread over many more pixels.
  auto image = [](float aperture, float focus) {
    psf::Scene s = emitting_square(4.0f);
    s.camera.fov_degrees = 30;
    s.camera.aperture_radius = aperture;
    s.camera.focus_distance = focus;
    return render(s, 64, 1).image;
  };
  psf::Image pinhole = image(0.0f, 1e4f), focused = image(0.2f, 4.0f), blurred = image(0.2f, 2.0f);
  auto partial = [](const psf::Image& im) {  // pixels neither empty nor full
    int n = 0;
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 32; ++x) {
        double v = pixel(im, x, y).x;
        n += v > 0.02 && v < 0.98;
      }
    return n;
  };
  auto total = [](const psf::Image& im) {
    double t = 0;
    for (float v : im.rgb) t += v;
    return t;
  };
  size_t differ = 0;
  for (size_t i = 0; i < pinhole.rgb.size(); ++i) differ += std::fabs(pinhole.rgb[i] - focused.rgb[i]) > 1e-3f;
  CHECK(differ == 0);
  INFO("partial pixels: pinhole " << partial(pinhole) << ", defocused " << partial(blurred));
  CHECK(partial(blurred) > 3 * partial(pinhole));
  CHECK(total(blurred) == Approx(total(pinhole)).epsilon(0.03));  // the lens moves light, it does not lose it
}

TEST_CASE("Render: near and far clip planes lie perpendicular to the view direction", "[emitter]") {
  // An emitting plane z = 0 that fills the view (60 degrees) from 4 units away:
  // corner rays meet it 5.2 units from the camera. Clip planes at 3.9 and 4.1
  // along the view direction keep it whole or hide it whole.
  auto lit = [](bool ortho, float near_clip, float far_clip) {
    psf::Scene s = emitting_quad({-4, -4, 0}, {8, 0, 0}, {0, 8, 0});
    s.camera.origin = {0, 0, 4};
    s.camera.target = {0, 0, 0};
    s.camera.fov_degrees = 60;
    s.camera.orthographic = ortho;
    s.camera.near_clip = near_clip;
    s.camera.far_clip = far_clip;
    s.width = s.height = 16;
    psf::Image im = render(s, 1, 1).image;
    size_t n = 0;
    for (size_t i = 0; i < im.rgb.size(); i += 3) n += im.rgb[i] == 1.0f;
    return n;
  };
  for (bool ortho : {false, true}) {
    INFO((ortho ? "orthographic" : "perspective"));
    CHECK(lit(ortho, 0.0f, INFINITY) == 256u);
    CHECK(lit(ortho, 3.9f, 4.1f) == 256u);
    CHECK(lit(ortho, 4.1f, 100.0f) == 0u);
    CHECK(lit(ortho, 0.0f, 3.9f) == 0u);
  }
}

TEST_CASE("Render: an orthographic camera images a square at the same size at any distance", "[emitter]") {
  // The film spans [-1, 1]^2 (a square film, scale 1); an emitting square of
  // side 1 covers a quarter of it whether 2 or 6 units away.
  auto image = [](float distance) {
    psf::Scene s = emitting_square(distance);
    s.camera.orthographic = true;
    return render(s, 16, 1).image;
  };
  psf::Image near_image = image(2.0f), far_image = image(6.0f);
  CHECK(near_image.rgb == far_image.rgb);
  double lit = 0;
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) lit += pixel(near_image, x, y).x / (32.0 * 32.0);
  CHECK(lit == Approx(0.25).epsilon(0.01));
  CHECK(pixel(near_image, 16, 16).x == Approx(1.0));  // the centre is lit, the corner is not
  CHECK(pixel(near_image, 1, 1).x == 0.0);
}

using NamedScenes = std::vector<std::pair<std::string, psf::Scene>>;

// Adds ../shared's living room, unless it is absent or PSF_TEST_SMALL is set.
static void add_living_room(NamedScenes& scenes) {
  if (auto shared = psf::test::shared_dir(); shared && !psf::test::small_sizes())
    scenes.emplace_back("living room", psf::load_scene(*shared + "/scenes/living-room/scene.xml"));
  else
    WARN("the living room is left out (../shared not found, or PSF_TEST_SMALL)");
}

// Shrinks the film to at most 64x48 pixels; options for 4 spp at the scene's max depth.
static psf::RenderOptions small_render(psf::Scene& s) {
  s.width = std::min(s.width, 64);
  s.height = std::min(s.height, 48);
  psf::RenderOptions o;
  o.spp = 4;
  o.max_depth = s.max_depth;
  return o;
}

// A diffuse floor (y = 0, albedo 0.5) seen from above under test_envmap(), 16x16.
static psf::Scene envmap_floor() {
  psf::Scene s;
  uint32_t m = add_material(s, 0.5f);
  add_quad(s, {-1, 0, -1}, {0, 0, 2}, {2, 0, 0}, m);
  s.camera.origin = {0, 2, 0};
  s.camera.target = {0, 0, 0};
  s.camera.up = {0, 0, -1};
  s.camera.fov_degrees = 30;
  s.width = s.height = 16;
  s.lights = {test_envmap()};
  return s;
}

TEST_CASE("Render: --visibility-ray marks a vertex occluded where its hemisphere ray hits within the length",
          "[emitter]") {
  // A floor under a ceiling h = 1 above it that reaches 100 units every way. A
  // cosine-distributed ray at angle theta from the normal meets the ceiling at
  // h / cos(theta): within length R iff cos(theta) >= h / R, which a cosine
  // distribution gives with probability 1 - (h / R)^2 (R > h), and never for R < h.
  psf::Scene s;
  uint32_t m = add_material(s, 0.5f);
  add_quad(s, {-1, -1, 0}, {2, 0, 0}, {0, 2, 0}, m);            // floor, facing +z
  add_quad(s, {-100, -100, 1}, {0, 200, 0}, {200, 0, 0}, m);    // ceiling, facing -z
  s.camera.origin = {0, 0, 0.5f};
  s.camera.target = {0, 0, 0};
  s.camera.fov_degrees = 60;
  s.width = s.height = 32;
  s.lights = {constant_sky(glm::vec3(1.0f))};
  psf::Renderer renderer(psf::test::runtime(), s);
  psf::RenderOptions o;
  o.spp = 4;  // 4096 vertices, one batch
  o.keep_last_batch = true;
  o.filter.min_removed = 0.0f;
  auto run = [&](float length) {
    o.filter.visibility_ray = length;
    psf::RenderResult r = renderer.render(o);
    size_t open = 0, total = 0;
    for (const PathVertex& v : r.last_batch.vertices) {
      if (v.albedo.s[3] == 0.0f) continue;
      ++total;
      if (v.normal.s[3] == 1.0f) ++open;
      else REQUIRE(v.normal.s[3] == 0.0f);
    }
    REQUIRE(total == 4096u);  // every camera ray meets the floor
    return std::make_pair(double(total - open) / double(total), r);
  };
  auto [none, short_run] = run(0.5f);
  CHECK(none == 0.0);
  // auto: the sky is the only light, so a ray of 1 % of the bounds' diagonal.
  CHECK(renderer.visibility_ray(psf::kVisibilityRayAuto) == Approx(0.01 * std::sqrt(2.0 * 200.0 * 200.0 + 1.0)));
  CHECK(renderer.visibility_ray(0.0f) == 0.0f);
  psf::Scene lamp = s;
  lamp.lights.push_back(psf::LightDesc{});  // a point light as well: the light sample decides
  lamp.lights.back().position = {0, 0, 0.9f};
  CHECK(psf::Renderer(psf::test::runtime(), lamp).visibility_ray(psf::kVisibilityRayAuto) == 0.0f);
  for (float length : {2.0f, 4.0f}) {
    auto [occluded, r] = run(length);
    const double p = 1.0 - 1.0 / (double(length) * length);
    const double sigma = std::sqrt(p * (1.0 - p) / 4096.0);
    INFO("R = " << length << ": occluded " << occluded << ", expected " << p << " +- " << sigma);
    CHECK(std::fabs(occluded - p) < 4.0 * sigma);
    // The flag reaches the filter: a vertex averages only with those of its own
    // flag, independent of position, so of the others it averages when all share
    // one flag, q = (1 - p)^2 + p^2 remain, and itself (3 %: the counts' noise is
    // about 1 %).
    double mean_r = 0, mean_short = 0;
    for (size_t i = 0; i < r.neighbours.size(); ++i) {
      mean_r += r.neighbours[i] / double(r.neighbours.size());
      mean_short += short_run.neighbours[i] / double(r.neighbours.size());
    }
    const double q = p * p + (1.0 - p) * (1.0 - p);
    CHECK(mean_r == Approx(1.0 + q * (mean_short - 1.0)).epsilon(0.03));
    // The unfiltered image is that of plain path tracing.
    psf::RenderOptions off = o;
    off.filter.enabled = false;
    CHECK(r.unfiltered.rgb == renderer.render(off).image.rgb);
  }
}

TEST_CASE("Render: a light sample that could not light the vertex does not count as shadowed", "[emitter]") {
  // A floor (z = 0, facing +z) lit by an upright emitting quad at x = 2 facing it.
  // Where the quad reaches below the floor's plane, the light samples there lie
  // behind the floor: they contribute nothing whether or not anything blocks
  // them, so they must not split the vertices into shadowed and unshadowed (the
  // filter would then average each with half its neighbours). A wall at x = 1
  // that blocks every sample above the plane makes the vertices shadowed.
  auto flags = [](float light_bottom, bool wall) {
    psf::Scene s;
    uint32_t floor = add_material(s, 0.5f);
    add_quad(s, {-1, -1, 0}, {2, 0, 0}, {0, 2, 0}, floor);
    Material light{};
    light.type = PSF_MATERIAL_DIFFUSE;
    light.emission = {{1, 1, 1, 0}};
    s.materials.push_back(light);
    s.material_names.push_back("light");
    add_quad(s, {2, -1, light_bottom}, {0, 0, 1.5f - light_bottom}, {0, 2, 0},
             uint32_t(s.materials.size() - 1));  // faces -x
    if (wall) add_quad(s, {1, -5, 0}, {0, 0, 5}, {0, 10, 0}, floor);
    s.camera.origin = {0, 0, 0.5f};
    s.camera.target = {0, 0, 0};
    s.camera.up = {0, 1, 0};
    s.camera.fov_degrees = 60;
    s.width = s.height = 32;
    psf::Renderer renderer(psf::test::runtime(), s);
    psf::RenderOptions o;
    o.spp = 4;
    o.keep_last_batch = true;
    o.filter.min_removed = 0.0f;
    psf::RenderResult r = renderer.render(o);
    size_t unshadowed = 0, total = 0;
    for (const PathVertex& v : r.last_batch.vertices) {
      if (v.albedo.s[3] == 0.0f) continue;
      ++total;
      unshadowed += v.normal.s[3] == 1.0f ? 1 : 0;
    }
    REQUIRE(total == 4096u);  // every camera ray meets the floor
    return double(unshadowed) / double(total);
  };
  CHECK(flags(0.5f, false) == 1.0);   // the light above the plane
  CHECK(flags(-1.0f, false) == 1.0);  // the light straddling it: 40 % of its samples behind the floor
  CHECK(flags(0.5f, true) == 0.0);    // every sample blocked
}

TEST_CASE("Render: a crop window renders the film's pixels as the whole film's render does", "[emitter]") {
  // The envmap floor (a textured sky, a bounce and light samples): a 16x16 film,
  // and the window of 7x5 pixels from (6, 9), bit for bit.
  psf::Scene full = envmap_floor();
  psf::Scene crop = full;
  crop.camera.film_width = crop.camera.film_height = 16;
  crop.camera.crop_x = 6;
  crop.camera.crop_y = 9;
  crop.width = 7;
  crop.height = 5;
  const psf::Image a = render(full, 8).image, b = render(crop, 8).image;
  REQUIRE(b.width == 7);
  REQUIRE(b.height == 5);
  size_t differ = 0;
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 7; ++x) differ += pixel(b, x, y) != pixel(a, x + 6, y + 9);
  CHECK(differ == 0);
  // --width and --height scale the film and the window with it.
  psf::set_film_size(crop, 32, 8);
  CHECK(crop.camera.film_width == 32);
  CHECK(crop.camera.film_height == 8);
  CHECK(crop.camera.crop_x == 12);
  CHECK(crop.width == 14);
  CHECK(crop.camera.crop_y == 5);  // rows 9..14 of 16 -> 4.5..7 of 8, rounded
  CHECK(crop.height == 2);
}

TEST_CASE("Render: a diffuse floor under an envmap matches the map's cosine-weighted integral", "[emitter]") {
  // Floor y = 0 facing +y, seen from above; the map is not rotated, so the
  // floor's normal is the map's +y and cos(theta) the map's cos(theta). Reference:
  // L_o = rho / pi * the integral over the upper hemisphere of L cos(theta), a
  // midpoint sum of the map's bilinear radiance times cos(theta) 2 pi^2 sin(theta) du dv.
  psf::Scene s = envmap_floor();
  const psf::LightDesc& env = s.lights[0];
  glm::dvec3 integral(0.0);
  for_fine_grid(env, 32, [&](double u, double v, int, int, double dudv) {
    if (v < 0.5) integral += env_bilinear(env, u, v) * (std::cos(v * kPi) * 2 * kPi * kPi * std::sin(v * kPi) * dudv);
  });
  glm::dvec3 expected = 0.5 / kPi * integral;
  psf::RenderResult r = render(s, 256);
  glm::dvec3 mean(0.0);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) mean += pixel(r.image, x, y) / 256.0;
  // 65536 paths; the bright texel makes this the noisiest of the estimates: 2 %.
  CHECK(mean.x == Approx(expected.x).epsilon(0.02));
  CHECK(mean.y == Approx(expected.y).epsilon(0.02));
  CHECK(mean.z == Approx(expected.z).epsilon(0.02));
}

TEST_CASE("Render: inside a closed emitting diffuse sphere the image is Le/(1-albedo)", "[emitter]") {
  // Mitsuba's sphere with flip_normals: the emitter faces inwards.
  TempDir dir;
  std::string path = dir.write("sphere.xml",
                               "<scene version=\"3.0.0\">\n"
                               "<sensor type=\"perspective\"><float name=\"fov\" value=\"90\"/>"
                               "<transform name=\"to_world\"><lookat origin=\"0.1 0 0\" target=\"1 0.2 0.1\" up=\"0 1 0\"/></transform>"
                               "<film type=\"hdrfilm\"><integer name=\"width\" value=\"16\"/><integer name=\"height\" value=\"16\"/></film>"
                               "</sensor>\n"
                               "<shape type=\"sphere\"><float name=\"radius\" value=\"2\"/><boolean name=\"flip_normals\" value=\"true\"/>"
                               "<bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0.5\"/></bsdf>"
                               "<emitter type=\"area\"><rgb name=\"radiance\" value=\"1\"/></emitter></shape>\n"
                               "</scene>\n");
  psf::Scene s = psf::load_scene(path);
  psf::RenderResult r = render(s, 64);
  double mean = 0;
  for (float v : r.image.rgb) mean += v / double(r.image.rgb.size());
  // A geometric series with ratio 1/2 over 16384 paths: about 0.3 % noise; allow 2 %.
  CHECK(mean == Approx(2.0).epsilon(0.02));
}

TEST_CASE("Render: an analytic sphere light gives pi L r^2 cos(theta) / D^2 x albedo / pi on a plane", "[emitter]") {
  // A sphere of radius r whose whole surface is above the plane irradiates a point
  // at distance D from its centre as a point of intensity pi L r^2 would (Lambert).
  // Light sampling (the cone the sphere subtends) and BSDF-sampled hits (MIS)
  // both find it; the sphere is black, so nothing else reaches the plane.
  const float albedo = 0.5f, radius = 0.4f, L = 2.0f;
  const glm::dvec3 c(0.6, 0.3, 1.0);
  psf::Scene s = plane_scene(albedo, 16);
  uint32_t m = add_material(s, 0.0f);
  s.materials[m].emission = {{L, L, L, 0}};
  psf::SphereShape sp;
  sp.center = glm::vec3(c);
  sp.radius = radius;
  sp.material = m;
  s.spheres = {sp};
  psf::RenderResult r = render(s, 256);
  Camera cam = psf::make_camera(s.camera, s.width, s.height);
  const glm::dvec3 o(cam.origin.s[0], cam.origin.s[1], cam.origin.s[2]);
  int seen = 0, lit = 0;
  double err2 = 0;
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      // The pixel's corners: all on the sphere's disc (radiance L), all off it
      // (the plane), or straddling (skipped).
      int on = 0;
      for (double fx : {0.0, 1.0})
        for (double fy : {0.0, 1.0}) {
          glm::dvec3 d = glm::normalize(plane_point(s, x + fx, y + fy) - o), f = o - c;
          double b = glm::dot(f, d);
          on += b * b - (glm::dot(f, f) - double(radius) * radius) > 0 ? 1 : 0;
        }
      INFO("pixel " << x << ", " << y);
      if (on == 4) {
        ++seen;
        CHECK(pixel(r.image, x, y).x == Approx(L).epsilon(1e-5));
        continue;
      }
      if (on > 0) continue;
      double expected = 0;
      for (int i = 0; i < 8; ++i)
        for (int k = 0; k < 8; ++k) {
          glm::dvec3 q = plane_point(s, x + (i + 0.5) / 8, y + (k + 0.5) / 8);
          double D2 = glm::dot(c - q, c - q);
          expected += albedo / kPi * kPi * L * radius * radius * (c.z / std::sqrt(D2)) / D2 / 64.0;
        }
      ++lit;
      double got = pixel(r.image, x, y).x;
      err2 += (got - expected) * (got - expected) / (expected * expected);
      CHECK(got == Approx(expected).epsilon(0.01));
    }
  CHECK(seen >= 4);
  CHECK(lit > 200);
  // The rms relative error over the image: the noise of 256 spp, 0.047 % here
  // (0.95 % with the sphere sampled uniformly by area).
  INFO("rms relative error " << std::sqrt(err2 / lit));
  CHECK(std::sqrt(err2 / lit) < 0.003);
}

TEST_CASE("Render: analytic spheres shade as their fine tessellation does", "[emitter]") {
  // Under a constant sky and an area light: a turned sphere with a checkerboard
  // (its uv and frame), an anisotropic rough conductor (dp/du, the tangent), a
  // rough dielectric (the ray starting inside) and an emitting sphere (light
  // sampling). The same scene with each sphere replaced by 128 x 256 triangles
  // (make_sphere, Mitsuba's uv) must match up to noise and the facets.
  TempDir dir;
  std::string path = dir.write(
      "spheres.xml",
      "<scene version=\"3.0.0\">\n"
      "<sensor type=\"perspective\"><float name=\"fov\" value=\"40\"/>"
      "<transform name=\"to_world\"><lookat origin=\"0 1 9\" target=\"0 0 0\" up=\"0 1 0\"/></transform>"
      "<film type=\"hdrfilm\"><integer name=\"width\" value=\"96\"/><integer name=\"height\" value=\"48\"/></film>"
      "</sensor>\n"
      "<emitter type=\"constant\"><rgb name=\"radiance\" value=\"0.3\"/></emitter>\n"
      "<shape type=\"sphere\"><point name=\"center\" x=\"-2.2\" y=\"0\" z=\"0\"/>"
      "<transform name=\"to_world\"><rotate x=\"1\" angle=\"70\"/><rotate y=\"1\" angle=\"30\"/></transform>"
      "<bsdf type=\"diffuse\"><texture type=\"checkerboard\" name=\"reflectance\">"
      "<rgb name=\"color0\" value=\"0.9\"/><rgb name=\"color1\" value=\"0.1\"/>"
      "<transform name=\"to_uv\"><scale x=\"6\" y=\"4\"/></transform></texture></bsdf></shape>\n"
      "<shape type=\"sphere\"><point name=\"center\" x=\"0\" y=\"0\" z=\"0\"/>"
      "<transform name=\"to_world\"><rotate z=\"1\" angle=\"40\"/></transform>"
      "<bsdf type=\"roughconductor\"><string name=\"material\" value=\"Au\"/>"
      "<float name=\"alpha_u\" value=\"0.03\"/><float name=\"alpha_v\" value=\"0.4\"/></bsdf></shape>\n"
      "<shape type=\"sphere\"><point name=\"center\" x=\"2.2\" y=\"0\" z=\"0\"/>"
      "<bsdf type=\"roughdielectric\"><float name=\"alpha\" value=\"0.1\"/></bsdf></shape>\n"
      "<shape type=\"sphere\"><point name=\"center\" x=\"1\" y=\"3\" z=\"3\"/><float name=\"radius\" value=\"0.5\"/>"
      "<emitter type=\"area\"><rgb name=\"radiance\" value=\"8\"/></emitter></shape>\n"
      "<shape type=\"rectangle\"><transform name=\"to_world\"><scale value=\"10\"/><rotate x=\"1\" angle=\"-90\"/>"
      "<translate y=\"-1\"/></transform><bsdf type=\"diffuse\"/></shape>\n"
      "</scene>\n");
  psf::Scene analytic = psf::load_scene(path);
  REQUIRE(analytic.spheres.size() == 4);
  psf::Scene tess = analytic;
  tess.spheres.clear();
  for (const psf::SphereShape& sp : analytic.spheres) {
    glm::mat4 m(1.0f);
    m[0] = glm::vec4(sp.axis_x * sp.radius, 0);
    m[1] = glm::vec4(sp.axis_y * sp.radius, 0);
    m[2] = glm::vec4(glm::cross(sp.axis_x, sp.axis_y) * sp.radius, 0);
    m[3] = glm::vec4(sp.center, 1);
    psf::detail::append_mesh(tess, psf::detail::make_sphere(glm::vec3(0.0f), 1.0f, 128, 256), m, sp.material, sp.flip, "test", 0);
  }
  psf::RenderResult a = render(analytic, 256), t = render(tess, 256);
  psf::BlockStats b = psf::block_stats(a.image, t.image, 12, 6);
  INFO("mean block error " << b.mean_rel_error << ", worst " << b.worst_rel_error << " at " << b.worst_block
                           << ", overall " << b.overall_rel_error);
  CHECK(std::fabs(b.overall_rel_error) < 0.01);
  CHECK(b.mean_rel_error < 0.02);
  CHECK(b.worst_rel_error < 0.08);  // 0.35 % and 1.5 % here; a mirrored u gave 4.1 % and 34 %
}

TEST_CASE("Render: point and spot lights give I cos(theta) / r^2 x albedo / pi on a plane", "[emitter]") {
  const float albedo = 0.5f, h = 1.0f;
  psf::Scene s = plane_scene(albedo, 24);
  psf::LightDesc point;
  point.type = psf::LightType::Point;
  point.position = {0, 0, h};
  point.color = glm::vec3(3.0f);
  s.lights = {point};
  psf::RenderResult r = render(s, 16, 2);
  // The light is a delta: every path adds the same NEE value, up to the pixel
  // jitter; the pixel mean against its centre's value differs by the function's
  // curvature over a pixel (below 0.5 %): allow 1 %.
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      glm::dvec3 p = plane_point(s, x + 0.5, y + 0.5);
      double r2 = p.x * p.x + p.y * p.y + h * h;
      double expected = albedo / kPi * 3.0 * (h / std::sqrt(r2)) / r2;
      INFO("pixel " << x << ", " << y);
      REQUIRE(pixel(r.image, x, y).x == Approx(expected).epsilon(0.01));
    }

  // A spot pointing down, cutoff 30 and beam width 20 degrees, seen closer up.
  s.camera.fov_degrees = 30;
  s.width = s.height = 32;
  psf::LightDesc spot = point;
  spot.type = psf::LightType::Spot;
  spot.direction = {0, 0, -1};
  spot.cutoff_angle = glm::radians(30.0f);
  spot.beam_width = glm::radians(20.0f);
  s.lights = {spot};
  psf::RenderResult rs = render(s, 16, 2);
  int inside = 0, outside = 0;
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      auto angle_at = [&](double fx, double fy) {
        glm::dvec3 q = plane_point(s, x + fx, y + fy);
        return glm::degrees(std::atan(std::sqrt(q.x * q.x + q.y * q.y) / h));
      };
      double angle = angle_at(0.5, 0.5);
      // Pixels straddling the beam width or the cutoff average a kinked function: skipped.
      double lo = 90, hi = 0;
      for (double fx : {0.0, 1.0})
        for (double fy : {0.0, 1.0}) lo = std::min(lo, angle_at(fx, fy)), hi = std::max(hi, angle_at(fx, fy));
      if ((lo <= 20 && hi >= 20) || (lo <= 30 && hi >= 30)) continue;
      // The pixel's mean (box filter) of falloff(angle) I cos / r^2 rho / pi, on a 16 x 16 grid.
      double expected = 0;
      for (int i = 0; i < 16; ++i)
        for (int k = 0; k < 16; ++k) {
          glm::dvec3 q = plane_point(s, x + (i + 0.5) / 16, y + (k + 0.5) / 16);
          double q2 = q.x * q.x + q.y * q.y + h * h;
          double a = angle_at((i + 0.5) / 16, (k + 0.5) / 16);
          double falloff = a <= 20 ? 1.0 : a >= 30 ? 0.0 : (30 - a) / 10;
          expected += albedo / kPi * 3.0 * falloff * (h / std::sqrt(q2)) / q2 / 256.0;
        }
      (expected > 0 ? inside : outside)++;
      INFO("pixel " << x << ", " << y << " at " << angle << " degrees");
      REQUIRE(pixel(rs.image, x, y).x == Approx(expected).epsilon(0.02).margin(1e-6));
    }
  CHECK(inside > 20);
  CHECK(outside > 20);
}

TEST_CASE("Render: a directional light gives E cos(theta) x albedo / pi", "[emitter]") {
  const float albedo = 0.7f;
  psf::Scene s = plane_scene(albedo, 8);
  psf::LightDesc sun;
  sun.type = psf::LightType::Directional;
  sun.direction = glm::normalize(glm::vec3(1, 0, -2));  // travelling down at cos(theta) = 2 / sqrt(5)
  sun.color = glm::vec3(2.0f);
  s.lights = {sun};
  psf::RenderResult r = render(s, 4);
  double expected = albedo / kPi * 2.0 * 2.0 / std::sqrt(5.0);
  // Every path adds the same value: float rounding only.
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) REQUIRE(pixel(r.image, x, y).x == Approx(expected).epsilon(1e-4));
}

// A diffuse floor z = 0 (albedo 0.5) lit only by a quad facing down at z = 1
// over [-0.5, 0.5]^2 (material `light`), seen from (0, 0, 0.8) below the light.
static psf::Scene lit_floor(const Material& light) {
  psf::Scene s;
  uint32_t floor = add_material(s, 0.5f);
  add_quad(s, {-2, -2, 0}, {4, 0, 0}, {0, 4, 0}, floor);
  s.materials.push_back(light);
  s.material_names.push_back("light");
  add_quad(s, {-0.5f, -0.5f, 1}, {0, 1, 0}, {1, 0, 0}, uint32_t(s.materials.size() - 1));
  psf::test::look_at(s, {0, 0, 0.8f}, {0, 0, 0}, {0, 1, 0}, 90, 32);
  return s;
}

TEST_CASE("Render: an emission texture multiplies the emission where it is hit and where it is sampled", "[emitter]") {
  Material light{};
  light.type = PSF_MATERIAL_DIFFUSE;
  light.emission = {{2.0f, 2.0f, 2.0f, 0}};
  psf::detail::TextureDesc nearest;
  nearest.bilinear = false;
  nearest.wrap = PSF_TEX_CLAMP;
  SECTION("a constant texture is the emission scaled, to float rounding") {
    psf::Scene textured = lit_floor(light);
    psf::detail::TextureStore store(textured);
    uint32_t t = store.pixels(nearest, 1, 1, {0.5f, 0.25f, 1.0f, 1.0f});  // exact in half precision
    textured.materials[1].tex_emission = t;
    Material scaled = light;
    scaled.emission = {{1.0f, 0.5f, 2.0f, 0}};
    psf::RenderResult a = render(textured, 16, 3), b = render(lit_floor(scaled), 16, 3);
    size_t bad = 0;
    double total = 0;
    for (size_t i = 0; i < a.image.rgb.size(); ++i) {
      bad += std::fabs(a.image.rgb[i] - b.image.rgb[i]) > 1e-5f * std::max(1.0f, std::fabs(b.image.rgb[i]));
      total += b.image.rgb[i];
    }
    CHECK(total > 0.0);
    CHECK(bad == 0);
  }
  SECTION("a texture lit in one part equals that part as its own light") {
    // Triangles without uvs take their barycentrics (b1, b2) as uv: the texel
    // u >= 1/2, v < 1/2 (nearest) lights b1 in [1/2, 1], b2 in [0, 1 - b1] of each
    // triangle, the triangle (1/2, 0), (1, 0), (1/2, 1/2) in barycentrics.
    psf::Scene textured = lit_floor(light);
    psf::detail::TextureStore store(textured);
    textured.materials[1].tex_emission = store.pixels(nearest, 2, 2, {0, 0, 0, 1, 1, 1, 1, 1, 0, 0, 0, 1, 0, 0, 0, 1});
    psf::Scene parts = lit_floor(light);
    const size_t quad = parts.triangles.size() - 2;
    for (size_t k = 0; k < 2; ++k) {  // each of the light's triangles becomes its lit part
      glm::uvec3 t = parts.triangles[quad + k];
      glm::vec3 p0 = parts.positions[t.x], p1 = parts.positions[t.y], p2 = parts.positions[t.z];
      auto at = [&](float b1, float b2) { return (1 - b1 - b2) * p0 + b1 * p1 + b2 * p2; };
      uint32_t base = uint32_t(parts.positions.size());
      parts.positions.insert(parts.positions.end(), {at(0.5f, 0), at(1, 0), at(0.5f, 0.5f)});
      parts.triangles[quad + k] = {base, base + 1, base + 2};
    }
    psf::RenderResult a = render(textured, 256, 3), b = render(parts, 256, 3);
    // Quadrants of the image: their means agree within the noise (about 1 %).
    for (int q = 0; q < 4; ++q) {
      glm::dvec3 ma(0.0), mb(0.0);
      for (int y = 0; y < 16; ++y)
        for (int x = 0; x < 16; ++x) {
          int px = x + 16 * (q % 2), py = y + 16 * (q / 2);
          ma += pixel(a.image, px, py);
          mb += pixel(b.image, px, py);
        }
      INFO("quadrant " << q << ": textured " << ma.x / 256 << ", its lit part alone " << mb.x / 256);
      CHECK(mb.x > 0.0);
      CHECK(ma.x == Approx(mb.x).epsilon(0.04));
    }
  }
}

TEST_CASE("Render: trace_lanes gives trace_paths' image up to float rounding", "[emitter]") {
  // trace_lanes (kernels/trace_lanes.cl) shades eight paths at a time with
  // vector arithmetic written as shade.cl writes it for diffuse surfaces and
  // triangle lights, from the same samples; a different order of instructions
  // rounds differently (and may, rarely, flip a Russian roulette decision or a
  // choice between reflection and refraction, which sends a path elsewhere), so
  // the images agree to float rounding once the 0.1 % of values that differ most
  // are left out: relMSE below 1e-6 (the two Cornell boxes read 1e-9 at 64 spp),
  // the means to 1e-4 (the vertex-normal box: 1.4e-5 from the 15 of 9216 values
  // that differ by more than 0.1 %; through NVIDIA's OpenCL on an H200, the box of
  // every other BSDF read 3e-6 and 1.4e-4 over all values), filtered (the
  // filtering vertices are the kernel's too) and not. Scenes: our Cornell box (vertex normals
  // none), with max depth 3 (the depth test), with white walls and paths of
  // any depth (the samples past the Sobol table), a two-sided box with vertex
  // normals and hidden lights, an environment map (a floor, then with an
  // occluder), a textured floor with an alpha-masked leaf and a point light,
  // the Cornell box with a BSDF of every
  // other kind, nine scenes of analytic spheres (a sphere light, also with
  // a GGX conductor sphere, an anisotropic one, rough glass, a thin
  // dielectric, and a large sphere tested in double), principledthin sheets,
  // an emission texture, three cameras (thin lens and Gaussian filter, tent
  // filter and crop window, orthographic), whose rays the lanes draw
  // themselves; and a scene outside the class (media), which must fall back to
  // trace_paths bit for bit. Scenes of at most kLanesFlatPrims primitives
  // or a BVH of one node (the Cornell box with 13 lights), none alpha-tested,
  // render twice: with the lanes' default casts, which test every primitive
  // against eight rays without the BVH (but for the root's boxes), and through
  // the BVH (RenderOptions.flat_casts 0).
  auto& rt = psf::test::runtime();
  struct Case {
    std::string name;
    psf::Scene scene;
    bool lanes;        // in the class
    bool flat = true;  // few primitives, none alpha-tested: the lanes cast without the BVH by default
  };
  std::vector<Case> cases;
  cases.push_back({"cornell-box", psf::load_scene(psf::test::source_path("scenes/cornell-box.xml")), true});
  cases.push_back({"cornell-box, max depth 3", cases.back().scene, true});
  cases.back().scene.max_depth = 3;
  {
    // Two-sided walls with smooth vertex normals (each vertex the mean of its
    // triangles' normals, so the shading normals bend at the box's edges), and
    // the lights hidden from the camera.
    psf::Scene t = cases.front().scene;
    std::vector<glm::vec3> normals(t.positions.size(), glm::vec3(0.0f));
    for (const auto& tri : t.triangles) {
      const glm::vec3 n = glm::cross(t.positions[tri[1]] - t.positions[tri[0]], t.positions[tri[2]] - t.positions[tri[0]]);
      for (int k = 0; k < 3; ++k) normals[tri[k]] += n;
    }
    for (auto& n : normals) n = glm::length(n) > 0.0f ? glm::normalize(n) : glm::vec3(0, 1, 0);
    t.normals = normals;
    for (auto& m : t.materials) m.two_sided = 1;
    t.hide = PSF_HIDE_AREA;
    cases.push_back({"two-sided, vertex normals, hidden lights", t, true});
  }
  {
    // White walls and no depth limit: paths past depth 35 draw dimensions past
    // the Sobol table, which trace_lanes takes lane by lane.
    psf::Scene t = cases.front().scene;
    for (auto& m : t.materials) m.albedo = {{0.97f, 0.97f, 0.97f, 0.0f}};
    t.max_depth = -1;
    cases.push_back({"cornell-box, white walls, unbounded depth", t, true});
  }
  cases.push_back({"envmap floor", envmap_floor(), true});
  {
    // The map's light samples decide shadows: a quad over a quarter of the floor.
    psf::Scene t = envmap_floor();
    add_quad(t, {-1, 0.5f, -1}, {0, 0, 1}, {1, 0, 0}, t.tri_material[0]);
    cases.push_back({"envmap floor, occluder", t, true});
    // Nine small lights facing the floor beside the map: 19 lights, more than
    // the lanes choose among by counting cdf entries, so the lanes that chose
    // the map are found through the guided cdf before their casts (EnvLanes).
    Material light{};
    light.type = PSF_MATERIAL_DIFFUSE;
    light.emission = {{1.5f, 1.0f, 0.5f, 0}};
    t.materials.push_back(light);
    t.material_names.push_back("light");
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        add_quad(t, {-0.9f + 0.7f * i, 0.9f, -0.9f + 0.7f * j}, {0.1f, 0, 0}, {0, 0, 0.1f},
                 uint32_t(t.materials.size() - 1));
    cases.push_back({"envmap floor, occluder, 18 light triangles", t, true});
  }
  {
    // A textured floor under an area light and a point light, with a leaf
    // between them whose opacity texture cuts out half of it (alpha-tested casts).
    Material light{};
    light.type = PSF_MATERIAL_DIFFUSE;
    light.emission = {{2.0f, 2.0f, 2.0f, 0}};
    psf::Scene t = lit_floor(light);
    psf::detail::TextureStore store(t);
    std::vector<float> texels;
    for (int i = 0; i < 16; ++i) texels.insert(texels.end(), {0.1f + 0.05f * i, 0.8f - 0.04f * i, 0.5f, 1.0f});
    t.materials[0].tex_color = store.pixels(psf::detail::TextureDesc{}, 4, 4, texels);
    psf::detail::TextureDesc nearest;
    nearest.bilinear = false;
    Material leaf{};
    leaf.type = PSF_MATERIAL_DIFFUSE;
    leaf.albedo = {{0.3f, 0.7f, 0.2f, 0}};
    leaf.opacity = 1.0f;
    leaf.tex_opacity = store.pixels(nearest, 2, 2, {1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1});
    leaf.flags = PSF_MATFLAG_MASKED;
    t.materials.push_back(leaf);
    t.material_names.push_back("leaf");
    add_quad(t, {-0.7f, -0.7f, 0.4f}, {1.4f, 0, 0}, {0, 1.4f, 0}, uint32_t(t.materials.size() - 1));
    psf::LightDesc point;
    point.type = psf::LightType::Point;
    point.position = {0.6f, -0.3f, 0.7f};
    point.color = {0.3f, 0.2f, 0.1f};
    t.lights = {point};
    cases.push_back({"textured floor, masked leaf, area and point lights", t, true, false});
  }
  {
    // Our Cornell box with a BSDF of every other kind, which the lanes shade
    // lane by lane with bsdf.cl's functions, but for the textured roughplastic
    // floor (GGX, nonlinear) and the rough conductors, which they shade in
    // vectors (Plastic8, Conductor8): a bump-mapped ceiling, a smooth plastic
    // back wall, a gold mirror and a rough Beckmann conductor for the side
    // walls, a glass box, and a blend of diffuse and rough Beckmann conductor
    // for the tall box.
    std::ifstream in(psf::test::source_path("scenes/cornell-box.xml"));
    std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    for (const char* id : {"floor", "ceiling", "back", "short", "tall"}) {
      const size_t at = xml.find("<ref id=\"white\"/>");
      REQUIRE(at != std::string::npos);
      xml.replace(at, 17, std::string("<ref id=\"") + id + "\"/>");
    }
    const auto checker = [](const std::string& name) {
      return "<texture " + name +
             R"( type="checkerboard"><rgb name="color0" value="0.8, 0.7, 0.3"/>)"
             R"(<rgb name="color1" value="0.2, 0.3, 0.6"/><transform name="to_uv"><scale x="4" y="4"/></transform>)"
             R"(</texture>)";
    };
    const std::string bsdfs =
        R"(<bsdf type="roughplastic" id="floor"><float name="alpha" value="0.2"/>)"
        R"(<string name="distribution" value="ggx"/><boolean name="nonlinear" value="true"/>)" +
        checker(R"(name="diffuse_reflectance")") +
        R"(</bsdf>)"
        R"(<bsdf type="bumpmap" id="ceiling"><float name="scale" value="0.5"/>)" +
        checker("") +
        R"(<bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.7, 0.7"/></bsdf></bsdf>)"
        R"(<bsdf type="plastic" id="back"><rgb name="diffuse_reflectance" value="0.4, 0.5, 0.6"/></bsdf>)"
        R"(<bsdf type="roughconductor" id="green"><string name="distribution" value="beckmann"/>)"
        R"(<float name="alpha" value="0.15"/><string name="material" value="Cu"/></bsdf>)"
        R"(<bsdf type="dielectric" id="short"/>)"
        R"(<bsdf type="blendbsdf" id="tall"><float name="weight" value="0.4"/>)"
        R"(<bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.7, 0.7"/></bsdf>)"
        R"(<bsdf type="roughconductor"><float name="alpha" value="0.3"/></bsdf></bsdf>)"
        R"(<bsdf type="conductor" id="red"><string name="material" value="Au"/></bsdf>)";
    for (const char* id : {"red", "green"}) {
      const size_t from = xml.find(std::string("<bsdf type=\"diffuse\" id=\"") + id + "\">");
      REQUIRE(from != std::string::npos);
      xml.erase(from, xml.find("</bsdf>", from) + 7 - from);
    }
    xml.insert(xml.find("<bsdf type=\"diffuse\" id=\"light\">"), bsdfs);
    const std::string path = psf::test::temp_dir("lanes-materials") + "/box.xml";
    std::ofstream(path) << xml;
    cases.push_back({"cornell-box, every other BSDF", psf::load_scene(path), true});
  }
  {
    // Our Cornell box with 12 small lights of different colours beside its own:
    // 26 light triangles, more than the lanes choose among by counting cdf
    // entries (PSF_LANES_FEW_LIGHTS), so they search the guided cdf.
    std::ifstream in(psf::test::source_path("scenes/cornell-box.xml"));
    std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::string lights;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 3; ++j)
        lights += "<shape type=\"rectangle\"><transform name=\"to_world\"><scale x=\"12\" y=\"12\" z=\"1\"/>"
                  "<rotate x=\"1\" angle=\"90\"/><translate x=\"" + std::to_string(80 + 130 * i) +
                  "\" y=\"540\" z=\"" + std::to_string(100 + 180 * j) + "\"/></transform><ref id=\"light\"/>"
                  "<emitter type=\"area\"><rgb name=\"radiance\" value=\"" + std::to_string(2 + i) + ", " +
                  std::to_string(1 + j) + ", 3\"/></emitter></shape>";
    xml.insert(xml.rfind("</scene>"), lights);
    const std::string path = psf::test::temp_dir("lanes-lights") + "/box.xml";
    std::ofstream(path) << xml;
    // 60 triangles, more than kLanesFlatPrims: flat casts (that skip leaves by
    // their boxes) where the BVH is one node, as with 8-wide nodes; through
    // the BVH in builds of 4-wide nodes (PSF_BVH_WIDTH).
    psf::Scene t = psf::load_scene(path);
    REQUIRE(t.triangles.size() > psf::kLanesFlatPrims);
    const bool one_node = psf::build_bvh(t.positions, t.triangles).nodes.size() == 1;
    CHECK((one_node || PSF_BVH_WIDTH != 8));
    cases.push_back({"cornell-box, 13 lights", t, true, one_node});
  }
  // Analytic spheres: a sphere light over a rough conductor sphere, a glass
  // sphere on a sphere ground under a constant sky, principled spheres,
  // pplastic spheres (GGX, Beckmann, anisotropic, textured).
  for (const char* name :
       {"sphere-light", "sphere-ground", "principled-spheres", "pplastic-spheres", "principledthin-sheets"})
    cases.push_back({name, psf::load_scene(psf::test::source_path(std::string("scenes/") + name + ".xml")), true});
  {
    // Our Cornell box in Mitsuba's default roughplastic (Beckmann, alpha 0.1).
    std::ifstream in(psf::test::source_path("scenes/cornell-box.xml"));
    std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const auto replace_all = [&xml](const std::string& from, const std::string& to) {
      for (size_t at = 0; (at = xml.find(from, at)) != std::string::npos; at += to.size()) xml.replace(at, from.size(), to);
    };
    replace_all("bsdf type=\"diffuse\"", "bsdf type=\"roughplastic\"");
    replace_all("name=\"reflectance\"", "name=\"diffuse_reflectance\"");
    const std::string path = psf::test::temp_dir("lanes-beckmann-plastic") + "/box.xml";
    std::ofstream(path) << xml;
    cases.push_back({"cornell-box, Beckmann rough plastics", psf::load_scene(path), true});
    // The same with a normal map that tilts every normal by 60 degrees, so that
    // many directions fall between the surface and the tilted normal, where
    // Mitsuba 3's side rule (surface_side_agrees) lets nothing through.
    psf::Scene t = cases.back().scene;
    psf::detail::TextureStore store(t);
    const float st = std::sin(3.14159265f / 3), ct = std::cos(3.14159265f / 3);
    const uint32_t tilt = store.pixels(psf::detail::TextureDesc{}, 1, 1, {0.5f * st + 0.5f, 0.5f, 0.5f * ct + 0.5f, 1});
    for (auto& m : t.materials) {
      m.tex_bump = tilt;
      m.bump_scale = 1.0f;
      m.flags |= PSF_MATFLAG_NORMALMAP;
    }
    cases.push_back({"cornell-box, Beckmann rough plastics, normal map", t, true});
  }
  {
    // The sphere light's scene with a GGX copper sphere (the file's is
    // Beckmann's, Mitsuba's default): the lanes' Conductor8 takes both.
    std::ifstream in(psf::test::source_path("scenes/sphere-light.xml"));
    std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string cu = R"(<string name="material" value="Cu"/>)";
    const size_t at = xml.find(cu);
    REQUIRE(at != std::string::npos);
    xml.insert(at + cu.size(), R"(<string name="distribution" value="ggx"/>)");
    const std::string path = psf::test::temp_dir("lanes-ggx") + "/sphere-light.xml";
    std::ofstream(path) << xml;
    cases.push_back({"sphere-light, GGX copper", psf::load_scene(path), true});
    {  // anisotropic (Conductor8's alpha_u and alpha_v; the sphere's tangents give its frame)
      std::string aniso = xml;
      const std::string alpha = R"(<float name="alpha" value="0.2"/>)";
      const size_t a = aniso.find(alpha, at);
      REQUIRE(a != std::string::npos);
      aniso.replace(a, alpha.size(), R"(<float name="alpha_u" value="0.05"/><float name="alpha_v" value="0.4"/>)");
      const std::string p = psf::test::temp_dir("lanes-aniso") + "/sphere-light.xml";
      std::ofstream(p) << aniso;
      cases.push_back({"sphere-light, anisotropic GGX copper", psf::load_scene(p), true});
    }
    // And with the diffuse sphere turned into rough glass (Beckmann, Mitsuba's
    // default), which reflects and refracts from both sides.
    const std::string blue = R"(<bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.5, 0.8"/></bsdf>)";
    const size_t b = xml.find(blue);
    REQUIRE(b != std::string::npos);
    xml.replace(b, blue.size(), R"(<bsdf type="roughdielectric"><float name="alpha" value="0.2"/></bsdf>)");
    const std::string glass = psf::test::temp_dir("lanes-rough-glass") + "/sphere-light.xml";
    std::ofstream(glass) << xml;
    cases.push_back({"sphere-light, GGX copper, rough glass", psf::load_scene(glass), true});
    {  // and a thin dielectric in its place (Delta8's thin sheets)
      std::string thin = xml;
      const std::string rough = R"(<bsdf type="roughdielectric"><float name="alpha" value="0.2"/></bsdf>)";
      const size_t at = thin.find(rough);
      REQUIRE(at != std::string::npos);
      thin.replace(at, rough.size(), R"(<bsdf type="thindielectric"/>)");
      const std::string path = psf::test::temp_dir("lanes-thin-dielectric") + "/sphere-light.xml";
      std::ofstream(path) << thin;
      cases.push_back({"sphere-light, GGX copper, thin dielectric", psf::load_scene(path), true});
    }
    // And with a large diffuse sphere beside the others, between part of the
    // floor and the light: the casts test it in double (radius 4.5 above 4 and
    // above half its centre's distance 7), shadow rays too.
    xml.insert(xml.rfind("</scene>"), R"(<shape type="sphere"><point name="center" x="-6" y="3" z="-2"/>)"
                                      R"(<float name="radius" value="4.5"/><bsdf type="diffuse"/></shape>)");
    const std::string large = psf::test::temp_dir("lanes-large-sphere") + "/sphere-light.xml";
    std::ofstream(large) << xml;
    cases.push_back({"sphere-light, GGX copper, rough glass, a large sphere", psf::load_scene(large), true});
  }
  cases.push_back({"fog lights", psf::load_scene(psf::test::source_path("scenes/fog-lights.xml")), false});
  {
    // An emission texture, where it is hit and where a light sample lands.
    Material light{};
    light.type = PSF_MATERIAL_DIFFUSE;
    light.emission = {{2.0f, 2.0f, 2.0f, 0}};
    psf::Scene t = lit_floor(light);
    psf::detail::TextureStore store(t);
    t.materials[1].tex_emission = store.pixels(psf::detail::TextureDesc{}, 2, 2, {1, 0.5f, 0.25f, 1, 0.5f, 1, 0.5f, 1,
                                                                                  0.25f, 0.5f, 1, 1, 1, 1, 1, 1});
    cases.push_back({"emission texture", t, true});
  }
  {
    // The cameras: trace_lanes draws the camera rays of eight paths in vectors
    // (camera_rays8), lane by lane for an image narrower than the lanes.
    const psf::Scene box = cases.front().scene;
    psf::Scene t = box;  // a thin lens focused on the box's back wall, a Gaussian filter, and an image of
    t.width = 13;        // 143 pixels, so that groups of eight paths pass the image's end (two sample numbers)
    t.height = 11;
    t.camera.aperture_radius = 20.0f;
    t.camera.focus_distance = 1350.0f;
    t.camera.pixel_filter = "gaussian";
    cases.push_back({"thin lens, Gaussian filter, 13x11", t, true});
    t = box;  // a tent filter and a crop window
    t.camera.pixel_filter = "tent";
    t.camera.film_width = 64;
    t.camera.film_height = 48;
    t.camera.crop_x = 21;
    t.camera.crop_y = 9;
    t.width = 27;
    t.height = 19;
    cases.push_back({"tent filter, crop window", t, true});
    t = box;  // an orthographic camera, an image narrower than the lanes
    t.camera.orthographic = true;
    t.camera.ortho_scale = {300.0f, 300.0f};
    t.width = 5;
    t.height = 9;
    cases.push_back({"orthographic, 5x9", t, true});
  }
  for (auto& c : cases) {
    INFO(c.name);
    psf::Scene& s = c.scene;
    s.width = std::min(s.width, psf::test::pick(64, 16));
    s.height = std::min(s.height, psf::test::pick(48, 12));
    psf::Renderer r(rt, s);
    psf::RenderOptions o;
    o.spp = psf::test::pick(16, 4);
    o.max_depth = s.max_depth;
    o.per_path = 1;
    o.lanes = 0;
    psf::RenderResult per = r.render(o);
    rt.finish();
    if (c.lanes) CHECK((r.flat_packs(-1) > 0) == c.flat);
    CHECK(r.flat_packs(0) == 0);
    for (int flat : {-1, 0}) {
      INFO((flat ? "casts by default (without the BVH where flat)" : "casts through the BVH"));
      if (flat == 0 && !c.flat) continue;  // the same casts again
      rt.reset_stats();
      o.lanes = 1;
      o.flat_casts = flat;
      psf::RenderResult lanes = r.render(o);
      rt.finish();
      CHECK((rt.stats().count("trace_lanes") == 1) == c.lanes);
      if (!c.lanes) {
        CHECK(lanes.image.rgb == per.image.rgb);
        break;
      }
      for (auto [a, b] : {std::pair{&lanes.image, &per.image}, std::pair{&lanes.unfiltered, &per.unfiltered}}) {
        // Leave out the values that differ most, one in a thousand (none in
        // images of fewer than 1000 values): the pixels of paths that a rounding
        // sent elsewhere, which differ by a whole path.
        const size_t n = a->rgb.size();
        std::vector<double> d2(n);
        for (size_t i = 0; i < n; ++i) d2[i] = (double(a->rgb[i]) - b->rgb[i]) * (double(a->rgb[i]) - b->rgb[i]);
        std::vector<size_t> order(n);
        std::iota(order.begin(), order.end(), size_t(0));
        const size_t left_out = n / 1000;
        std::partial_sort(order.begin(), order.begin() + left_out, order.end(),
                          [&](size_t i, size_t j) { return d2[i] > d2[j]; });
        std::vector<char> kept(n, 1);
        for (size_t k = 0; k < left_out; ++k) kept[order[k]] = 0;
        double se = 0, ref2 = 0, sa = 0, sb = 0;
        size_t over = 0;  // values that differ by more than 0.1 %
        for (size_t i = 0; i < n; ++i) {
          ref2 += double(b->rgb[i]) * b->rgb[i];
          over += std::fabs(double(a->rgb[i]) - b->rgb[i]) > 1e-3 * std::max(1e-3, std::fabs(double(b->rgb[i])));
          if (!kept[i]) continue;
          se += d2[i];
          sa += a->rgb[i];
          sb += b->rgb[i];
        }
        INFO("squared error " << se << " of " << ref2 << "; sums " << sa << ", " << sb << "; " << over << " of " << n
                              << " values differ by more than 0.1 %; " << left_out << " left out, the largest "
                              << (left_out ? std::sqrt(d2[order[0]]) : 0.0));
        CHECK(sb > 0);
        CHECK(se <= 1e-6 * ref2);
        CHECK(sa == Approx(sb).epsilon(1e-4));
      }
    }
  }
}

// Every value of `test` within 1e-5 of `ref`'s, relative (1e-3 absolute near
// zero), and `ref` not black.
static void check_within_1e5(const psf::Image& test, const psf::Image& ref) {
  REQUIRE(test.rgb.size() == ref.rgb.size());
  double worst = 0.0, sum = 0.0;
  for (size_t i = 0; i < ref.rgb.size(); ++i) {
    const double a = test.rgb[i], b = ref.rgb[i];
    worst = std::max(worst, std::abs(a - b) / std::max(1e-3, std::abs(b)));
    sum += b;
  }
  INFO("largest relative difference " << worst << ", image sum " << sum);
  CHECK(sum > 0.0);
  CHECK(worst <= 1e-5);
}

TEST_CASE("Render: the lanes' own contributions equal accumulate's from their tuples", "[emitter]") {
  // Unfiltered, without tuples, AOVs or emission rays, trace_lanes writes each
  // path's contribution itself (radiance before the filtering vertex plus
  // alpha * c) and no state or vertex; keeping the last batch's tuples makes
  // it store the vertices, the values c and the radiance before each vertex
  // for accumulate_tuples instead (as when filtering; the filtered lanes
  // against trace_paths' states: "trace_lanes gives trace_paths' image"). The
  // two images must agree to the rounding of alpha * c, and the kept tuples'
  // values are the paths' c: zero where a path has no vertex, and where it
  // has one, (contribution - radiance before) / alpha, which the test cannot
  // separate, so at least finite. Scenes: area light (alpha 1 at a diffuse first hit),
  // rough conductor spheres (filtering vertices behind glossy bounces, alpha < 1),
  // an environment map, and with ../shared the living room.
  auto& rt = psf::test::runtime();
  NamedScenes scenes;
  scenes.emplace_back("cornell-box", psf::load_scene(psf::test::source_path("scenes/cornell-box.xml")));
  scenes.emplace_back("sphere light", psf::load_scene(psf::test::source_path("scenes/sphere-light.xml")));
  scenes.emplace_back("envmap floor", envmap_floor());
  add_living_room(scenes);
  for (auto& [name, s] : scenes) {
    INFO(name);
    psf::RenderOptions o = small_render(s);
    psf::Renderer r(rt, s);
    o.filter.enabled = false;
    o.lanes = 1;
    rt.finish();
    rt.reset_stats();
    psf::RenderResult direct = r.render(o);
    rt.finish();
    CHECK(rt.stats().count("trace_lanes") == 1);
    CHECK(rt.stats().count("accumulate") == 0);
    o.keep_last_batch = true;
    rt.reset_stats();
    psf::RenderResult stored = r.render(o);
    rt.finish();
    CHECK(rt.stats().count("accumulate_tuples") == 1);
    CHECK(rt.stats().count("store_tuples") == 0);
    check_within_1e5(direct.image, stored.image);
    size_t with_vertex = 0;
    REQUIRE(stored.last_batch.values.size() == stored.last_batch.vertices.size());
    for (size_t j = 0; j < stored.last_batch.values.size(); ++j) {
      const cl_float4& c = stored.last_batch.values[j];
      const cl_float4& a = stored.last_batch.vertices[j].alpha;
      const bool vertex = a.s[0] != 0.0f || a.s[1] != 0.0f || a.s[2] != 0.0f;
      with_vertex += vertex;
      if (!vertex)
        CHECK((c.s[0] == 0.0f && c.s[1] == 0.0f && c.s[2] == 0.0f));
      else
        CHECK((std::isfinite(c.s[0]) && std::isfinite(c.s[1]) && std::isfinite(c.s[2])));
    }
    CHECK(with_vertex > 0);
  }
}

TEST_CASE("Render: the program as GPUs build it renders on PoCL as the CPU build does", "[emitter]") {
  // GPUs build kernels/program.cl without PSF_CPU_DEVICE and PSF_PREFETCH (the
  // host sets both for CPUs): the sphere test inlined, the guided cdf search as
  // a loop, no prefetches; and lane masks by multiplication, as targets without
  // AVX take them (PSF_PORTABLE_LANES). Those branches otherwise compile only where a GPU
  // is; here PoCL builds them too, and each path kernel (the wavefront GPUs
  // use, one path per work-item, the lanes) renders with both builds. The same
  // samples and arithmetic, so the images must agree to float rounding (the
  // compiler may contract other multiply-adds once the sphere test is
  // inlined): every value within 1e-5 relative (1e-3 absolute near zero;
  // PoCL 3.1 gives the same images bit for bit).
  // Scenes: a triangle-lit box, spheres with a sphere light, an environment map
  // (the cdf searches) with an occluder.
  auto& rt = psf::test::runtime();
  if (rt.device().type != "CPU") {
    WARN("the test device is no CPU: its default build is the GPU one (skipped)");
    return;
  }
  psf::Runtime gpu_build(rt.device(), "-DPSF_CPU_DEVICE=0 -DPSF_PREFETCH=0 -DPSF_PORTABLE_LANES=1");
  NamedScenes scenes;
  scenes.emplace_back("cornell-box", psf::load_scene(psf::test::source_path("scenes/cornell-box.xml")));
  scenes.emplace_back("sphere light", psf::load_scene(psf::test::source_path("scenes/sphere-light.xml")));
  scenes.emplace_back("envmap floor, occluder", envmap_floor());
  add_quad(scenes.back().second, {-1, 0.5f, -1}, {0, 0, 1}, {1, 0, 0}, scenes.back().second.tri_material[0]);
  for (auto& [name, s] : scenes) {
    psf::RenderOptions o = small_render(s);
    o.filter.enabled = false;
    psf::Renderer cpu_r(rt, s), gpu_r(gpu_build, s);
    for (int mode = 0; mode < 3; ++mode) {
      INFO(name << ", " << (mode == 0 ? "wavefront" : mode == 1 ? "per path" : "lanes"));
      o.per_path = mode == 1 ? 1 : 0;
      o.lanes = mode == 2 ? 1 : 0;
      check_within_1e5(gpu_r.render(o).image, cpu_r.render(o).image);
    }
  }
}

TEST_CASE("Render: on CPUs the lanes are the default; GPUs keep the wavefront", "[emitter]") {
  // host/render.cpp: with RenderOptions' defaults a CPU device renders the
  // lanes' class with trace_lanes (thin principled materials too, since the
  // lanes sample their scene's lights in vectors) and a scene with media per
  // path without an environment map; other devices (GPUs) render every scene
  // with the wavefront.
  auto& rt = psf::test::runtime();
  const bool cpu = rt.device().type == "CPU";
  psf::Scene glossy_under_map = envmap_floor();
  glossy_under_map.materials[0].type = PSF_MATERIAL_ROUGH_CONDUCTOR;
  glossy_under_map.materials[0].specular = {{0.9f, 0.8f, 0.7f, 0.0f}};
  glossy_under_map.materials[0].alpha_u = glossy_under_map.materials[0].alpha_v = 0.3f;
  psf::Scene principled_under_map = envmap_floor();
  principled_under_map.materials[0].type = PSF_MATERIAL_PRINCIPLED;
  principled_under_map.materials[0].alpha_u = principled_under_map.materials[0].alpha_v = 0.3f;
  psf::Scene thin_under_map = principled_under_map;
  thin_under_map.materials[0].type = PSF_MATERIAL_PRINCIPLED_THIN;
  struct Case {
    const char* name;
    psf::Scene scene;
    const char* kernel;
  } cases[] = {
      {"diffuse, area light", psf::load_scene(psf::test::source_path("scenes/cornell-box.xml")), "trace_lanes"},
      {"diffuse, map", envmap_floor(), "trace_lanes"},
      {"rough conductor, map", glossy_under_map, "trace_lanes"},
      {"spheres, rough conductor, area light", psf::load_scene(psf::test::source_path("scenes/sphere-light.xml")),
       "trace_lanes"},
      {"principled spheres, area light and constant sky",
       psf::load_scene(psf::test::source_path("scenes/principled-spheres.xml")), "trace_lanes"},
      {"pplastic spheres", psf::load_scene(psf::test::source_path("scenes/pplastic-spheres.xml")), "trace_lanes"},
      {"principled, map", principled_under_map, "trace_lanes"},
      {"thin principled sheets, sphere light",
       psf::load_scene(psf::test::source_path("scenes/principledthin-sheets.xml")), "trace_lanes"},
      {"thin principled, map", thin_under_map, "trace_lanes"},
      {"media, no map", psf::load_scene(psf::test::source_path("scenes/fog-box.xml")), "trace_paths"},
  };
  for (auto& c : cases) {
    INFO(c.name);
    c.scene.width = c.scene.height = 16;
    psf::Renderer r(rt, c.scene);
    psf::RenderOptions o;
    o.spp = 1;
    o.filter.enabled = false;
    rt.finish();
    rt.reset_stats();
    r.render(o);
    rt.finish();
    const auto stats = rt.stats();
    if (cpu) {
      CHECK(stats.count(c.kernel) == 1);
      CHECK(stats.count("trace_lanes") + stats.count("trace_paths") + stats.count("shade") == 1);
    } else {
      CHECK(stats.count("shade") == 1);
      CHECK(stats.count("trace_lanes") == 0);
    }
  }
}

TEST_CASE("Render: per-path kernels give the wavefront's image bit for bit", "[emitter]") {
  // trace_paths (over the whole batch, or the rest of the wavefront's last live
  // paths) runs the wavefront's stages on each path's own slot; a path's
  // samples depend on its pixel, sample and depth alone, so the images must be
  // identical, filtered or not: area lights (our Cornell box), an environment map
  // (the floor scene), fog behind a null boundary lit by a spot and a point light
  // outside it (the wavefront's shadow rays in cast_shadows_media), and with
  // ../shared the living room (envmap, textures, alpha-masked leaves, glass, max
  // depth 65).
  auto& rt = psf::test::runtime();
  NamedScenes scenes;
  scenes.emplace_back("cornell-box", psf::load_scene(psf::test::source_path("scenes/cornell-box.xml")));
  scenes.emplace_back("envmap floor", envmap_floor());
  scenes.emplace_back("cornell-box, max depth 3", psf::load_scene(psf::test::source_path("scenes/cornell-box.xml")));
  scenes.back().second.max_depth = 3;  // where the tail starts counting its bounces matters
  scenes.emplace_back("fog lights", psf::load_scene(psf::test::source_path("scenes/fog-lights.xml")));
  add_living_room(scenes);
  for (auto& [name, s] : scenes) {
    INFO(name);
    psf::RenderOptions o = small_render(s);
    psf::Renderer r(rt, s);
    o.per_path = 0;
    o.tail_paths = 0;
    psf::RenderResult wave = r.render(o);
    o.per_path = 1;
    o.lanes = 0;  // trace_paths itself (trace_lanes: the next test)
    psf::RenderResult per = r.render(o);
    CHECK(per.image.rgb == wave.image.rgb);
    CHECK(per.unfiltered.rgb == wave.unfiltered.rgb);
    // The wavefront handing its live paths to trace_paths: after the first
    // bounce (every path), and once a tenth of the batch is left.
    o.per_path = 0;
    for (int64_t tail : {int64_t(s.width) * s.height * o.spp, int64_t(s.width) * s.height * o.spp / 10}) {
      INFO("tail " << tail);
      o.tail_paths = tail;
      psf::RenderResult handed = r.render(o);
      CHECK(handed.image.rgb == wave.image.rgb);
      CHECK(handed.unfiltered.rgb == wave.unfiltered.rgb);
    }
    double sum = 0;
    for (float v : wave.unfiltered.rgb) sum += v;
    CHECK(sum > 0);  // something was lit
  }
}
