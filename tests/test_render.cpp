// The path tracing pipeline (camera, raycast, shade, accumulate) on scenes with
// analytic answers, and its determinism.
#include <catch2/catch.hpp>

#include <cmath>
#include <fstream>
#include <random>

#include "render.h"
#include "scene/scene.h"
#include "support.h"

namespace {

// A closed box [-1,1]^3 whose faces face inwards, every face emitting `le` and
// reflecting `albedo` (Lambertian), seen from its centre.
psf::Scene furnace_box(float le, float albedo, int size) {
  psf::Scene s;
  for (int i = 0; i < 8; ++i) s.positions.emplace_back(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1);
  // Quads listed counter-clockwise seen from outside; the triangles reverse them.
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (auto& q : quads) {
    s.triangles.emplace_back(q[0], q[2], q[1]);
    s.triangles.emplace_back(q[0], q[3], q[2]);
  }
  Material m{};
  m.albedo = {{albedo, albedo, albedo, 0}};
  m.emission = {{le, le, le, 0}};
  s.materials.push_back(m);
  s.tri_material.assign(s.triangles.size(), 0);
  s.camera.origin = {0.1f, 0.05f, 0.0f};
  s.camera.target = {0.1f, 0.05f, 1.0f};
  s.camera.fov_degrees = 90.0f;
  s.width = s.height = size;
  return s;
}

double mean(const psf::Image& img) {
  double sum = 0.0;
  for (float v : img.rgb) sum += v;
  return sum / double(img.rgb.size());
}

// A Mitsuba scene: the cube [-1, 1]^3 with `inside` (its BSDF and medium) under a
// constant white sky, seen along -z by an orthographic camera of size x size
// pixels that sees only the cube's middle, [-0.5, 0.5]^2.
std::string cube_under_sky(int size, const std::string& inside) {
  const std::string n = std::to_string(size);
  return R"(<scene version="3.0.0">
  <integrator type="volpath"/>
  <sensor type="orthographic">
    <transform name="to_world"><scale value="0.5"/><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm">
      <integer name="width" value=")" + n + R"("/><integer name="height" value=")" + n + R"("/>
    </film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
  <shape type="cube">
    )" + inside + R"(
  </shape>
</scene>
)";
}

// Renders the Mitsuba scene `xml` (written to a file `name`) with plain path
// tracing at `spp`, `max_depth` segments (-1 unbounded); it must load with
// `warnings` warnings.
psf::RenderResult render_xml(const std::string& name, const std::string& xml, int spp, int max_depth,
                             size_t warnings = 0, int per_path = -1) {
  const std::string path = psf::test::temp_dir("render-xml") + "/" + name;
  std::ofstream(path) << xml;
  psf::Scene s = psf::load_scene(path);
  CHECK(s.warnings.size() == warnings);
  psf::Renderer r(psf::test::runtime(), s);
  psf::RenderOptions o;
  o.filter.enabled = false;
  o.spp = spp;
  o.max_depth = max_depth;
  o.per_path = per_path;
  return r.render(o);
}

}  // namespace

TEST_CASE("Render: inward normals of the furnace box face its centre", "[render]") {
  psf::Scene s = furnace_box(1, 0.5f, 8);
  for (const auto& t : s.triangles) {
    glm::vec3 a = s.positions[t[0]], b = s.positions[t[1]], c = s.positions[t[2]];
    glm::vec3 n = glm::cross(b - a, c - a);
    CHECK(glm::dot(n, -(a + b + c) / 3.0f) > 0.0f);
  }
}

TEST_CASE("Render: closed emitting diffuse box gives Le/(1-albedo)", "[render]") {
  auto& rt = psf::test::runtime();
  const float le = 1.0f, albedo = 0.5f;
  psf::Scene s = furnace_box(le, albedo, 16);
  psf::Renderer r(rt, s);
  psf::RenderOptions o;
  o.filter.enabled = false;  // the plain path tracer; filtering keeps the mean too, tested in test_filter.cpp
  o.spp = 64;
  o.max_depth = -1;
  auto res = r.render(o);
  CHECK(res.nonfinite == 0);
  // Russian roulette and NEE are unbiased; 16384 paths of a geometric series with
  // ratio 1/2 give a standard error of about 0.3 % on the mean: allow 2 %.
  CHECK(mean(res.image) == Approx(le / (1.0f - albedo)).epsilon(0.02));

  // max_depth 2 (Mitsuba: emitters seen directly plus direct light): Le + albedo Le,
  // where NEE and BSDF-sampled emission combine by MIS; allow 2 % for noise.
  o.max_depth = 2;
  CHECK(mean(r.render(o).image) == Approx(le * (1.0f + albedo)).epsilon(0.02));
  // max_depth 1: only the emitters seen directly, exactly Le in every pixel.
  o.max_depth = 1;
  auto direct = r.render(o);
  for (float v : direct.image.rgb) REQUIRE(v == Approx(le).epsilon(1e-6));
}

TEST_CASE("Render: the image is a function of the seed alone, not of the batch size", "[render]") {
  auto& rt = psf::test::runtime();
  psf::Scene s = furnace_box(1.0f, 0.7f, 13);  // 169 pixels: batches wrap around the image
  psf::Renderer r(rt, s);
  psf::RenderOptions o;
  o.filter.enabled = false;  // filtering averages within a batch, so it depends on the batch size
  o.spp = 5;
  o.seed = 3;
  o.batch_log2 = 9;
  auto a = r.render(o);
  o.batch_log2 = 6;
  auto b = r.render(o);
  REQUIRE(a.image.rgb.size() == b.image.rgb.size());
  CHECK(a.image.rgb == b.image.rgb);
  o.seed = 4;
  auto c = r.render(o);
  CHECK(c.image.rgb != a.image.rgb);
  // Filtered: the same options give the same image, and the unfiltered layer is
  // the plain path tracer's whatever the batch size.
  o.seed = 3;
  o.filter.enabled = true;
  auto f1 = r.render(o);
  auto f2 = r.render(o);
  CHECK(f1.image.rgb == f2.image.rgb);
  CHECK(f1.unfiltered.rgb == a.image.rgb);
  // A render keeps the buffers of the one before it (Renderer::prepare): a fresh
  // renderer gives the same images.
  psf::Renderer fresh(rt, s);
  CHECK(fresh.render(o).image.rgb == f2.image.rgb);
  o.filter.enabled = false;
  CHECK(fresh.render(o).image.rgb == a.image.rgb);
  // A render of fewer paths than a batch gets buffers for those alone; a later,
  // longer render on the same renderer needs larger ones: the same images as a
  // renderer that never rendered the short one, filtered and not.
  o.batch_log2 = 12;  // 4096 paths: both renders are one batch
  o.filter.enabled = true;
  o.spp = 1;  // 169 paths
  psf::Renderer reused(rt, s);
  REQUIRE(reused.render(o).paths == 169);
  o.spp = 20;  // 3380 paths
  const psf::RenderResult longer = reused.render(o);
  psf::Renderer once(rt, s);
  const psf::RenderResult direct = once.render(o);
  CHECK(longer.batch_size == 4096);
  CHECK(longer.image.rgb == direct.image.rgb);
  CHECK(longer.unfiltered.rgb == direct.unfiltered.rgb);
}

TEST_CASE("Render: the accumulator's threads add each pixel's paths in path order", "[render]") {
  // Batches of 2^20 paths with NaNs, an unfiltered batch and AOV vertices: the
  // sums must equal, bit for bit, one loop adding the paths in order. Over
  // 300x200 pixels (17.5 rounds a batch, so batches start mid-round), and over
  // 1500x1000, more pixels than a batch has paths (each batch covers part of the
  // film; the second wraps around its end).
  for (auto [w, h] : {std::pair{300, 200}, std::pair{1500, 1000}}) {
    INFO(w << "x" << h);
    const uint64_t pixels = uint64_t(w) * h, n = uint64_t(1) << 20;
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(0.0f, 2.0f);
    psf::Accumulator acc;
    acc.reset(w, h, true);
    std::vector<float> sum_f(pixels * 4, 0.0f), sum_u(pixels * 4, 0.0f), aov(pixels * 8, 0.0f);
    std::vector<uint32_t> bad_f(pixels, 0);
    auto add = [](float* s, uint32_t* bad, const cl_float4& c) {
      bool finite = std::isfinite(c.s[0]) && std::isfinite(c.s[1]) && std::isfinite(c.s[2]);
      if (finite)
        for (int k = 0; k < 3; ++k) s[k] += c.s[k];
      else if (bad)
        *bad += 1;
      s[3] += c.s[3];
    };
    for (uint64_t index = 0; index < 3; ++index) {
      psf::BatchImages b;
      b.index = index;
      b.first = index * n;
      b.unfiltered.resize(n);
      b.vertices.resize(n);
      if (index != 1) b.filtered.resize(n);  // batch 1: not filtered
      for (uint64_t j = 0; j < n; ++j) {
        b.unfiltered[j] = {{u(rng), u(rng), u(rng), 1.0f}};
        if (index != 1) b.filtered[j] = {{u(rng), j % 1000 == 7 ? NAN : u(rng), u(rng), u(rng)}};
        PathVertex& v = b.vertices[j];
        v.albedo = {{u(rng), u(rng), u(rng), j % 3 == 0 ? 0.0f : 1.0f}};
        v.normal = {{u(rng), u(rng), u(rng), 0.0f}};
        v.position = {{0.0f, 0.0f, 0.0f, u(rng)}};
      }
      for (uint64_t j = 0; j < n; ++j) {  // the reference: one loop, in path order
        uint64_t p = (b.first + j) % pixels;
        add(&sum_f[p * 4], &bad_f[p], b.filtered.empty() ? b.unfiltered[j] : b.filtered[j]);
        add(&sum_u[p * 4], nullptr, b.unfiltered[j]);
        const PathVertex& v = b.vertices[j];
        if (v.albedo.s[3] == 0.0f) continue;
        for (int k = 0; k < 3; ++k) {
          aov[p * 8 + k] += v.albedo.s[k];
          aov[p * 8 + 4 + k] += v.normal.s[k];
        }
        aov[p * 8 + 3] += v.position.s[3];
        aov[p * 8 + 7] += 1.0f;
      }
      acc.add(b);
    }
    CHECK(acc.paths == 3 * n);
    CHECK(acc.filtered == sum_f);
    CHECK(acc.unfiltered == sum_u);
    CHECK(acc.bad_filtered == bad_f);
    CHECK(acc.aov == aov);
  }
}

TEST_CASE("Render: an absorbing interior medium attenuates by exp(-sigma_t d) (Beer's law)", "[render]") {
  // A dielectric cube [-1, 1]^3 of index 1 in air (1.000277: it reflects 2e-8 at
  // normal incidence) holding a medium that only absorbs, seen along -z by an
  // orthographic camera against a constant white sky: every ray crosses the cube
  // straight through, 2 units of the medium, so every pixel reads exp(-2 sigma_t).
  const psf::Image img = render_xml("absorb.xml", cube_under_sky(8, R"(
    <bsdf type="dielectric"><float name="int_ior" value="1"/></bsdf>
    <medium type="homogeneous" name="interior">
      <rgb name="sigma_t" value="0.1, 0.5, 1"/><float name="albedo" value="0"/>
    </medium>)"), 4, -1).image;
  REQUIRE(img.rgb.size() == 8 * 8 * 3);
  const float want[3] = {std::exp(-0.2f), std::exp(-1.0f), std::exp(-2.0f)};
  // Each crossing starts its ray PSF_RAY_EPS (relative) off the surface: the
  // path inside is short by about 1e-4, exp(-sigma_t d) off by sigma_t 1e-4.
  for (size_t i = 0; i < img.rgb.size(); ++i) REQUIRE(img.rgb[i] == Approx(want[i % 3]).epsilon(3e-4));
}

TEST_CASE("Render: a medium that scatters without absorbing leaves a furnace as bright as its sky", "[render]") {
  // A glass cube (index 1.5) holding a medium of optical depth 4 across that
  // scatters all it meets (albedo 1, Henyey-Greenstein g = 0.5, or isotropic in an
  // index-matched cube), under a constant white sky and nothing else: light is
  // neither lost nor made, so every pixel's expectation is the sky's 1. Each path's
  // weight is exactly 1 (free-flight sampling, the phase function and the
  // dielectric are sampled exactly; a grey medium's spectral MIS is 1) until
  // Russian roulette's 1/q: the mean of 16,384 paths lies within 2 %. A medium
  // whose events were not sampled by their pdfs, or a phase function that lost
  // energy, would not.
  // Behind a null boundary (a cube, an analytic sphere of radius 1.2), the sky
  // comes into the fog by light samples, which pass the boundary with the
  // transmittance of the fog on their way out, and by phase samples that leave,
  // weighted against them by MIS from the last scattering event: a light sample
  // that ignored the fog behind it, or an MIS weight taken at the boundary, would
  // make the furnace brighter than its sky.
  const std::string fog = R"(<medium type="homogeneous" name="interior">
      <float name="sigma_t" value="2"/><float name="albedo" value="1"/>)";
  const std::string hg = R"(<phase type="hg"><float name="g" value="0.5"/></phase>)";
  const std::vector<std::pair<std::string, std::string>> shapes = {
      {"glass", R"(<shape type="cube"><bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf>)" + fog + hg +
                    "</medium></shape>"},
      {"index-matched", R"(<shape type="cube"><bsdf type="dielectric"><float name="int_ior" value="1"/></bsdf>)" +
                            fog + "</medium></shape>"},
      {"null cube", R"(<shape type="cube"><bsdf type="null"/>)" + fog + hg + "</medium></shape>"},
      {"null sphere", R"(<shape type="sphere"><float name="radius" value="1.2"/><bsdf type="null"/>)" + fog +
                          "</medium></shape>"}};
  for (const auto& [name, shape] : shapes) {
    INFO(name);
    const psf::RenderResult res = render_xml("furnace-medium.xml", R"(<scene version="3.0.0">
  <integrator type="volpath"/>
  <sensor type="perspective"><float name="fov" value="60"/>
    <transform name="to_world"><lookat origin="0.3, 0.5, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
  )" + shape + R"(
</scene>
)", 64, -1);
    CHECK(res.nonfinite == 0);
    CHECK(mean(res.image) == Approx(1.0).epsilon(0.02));
  }
}

TEST_CASE("Render: single scattering of a point light inside a medium matches its integral", "[render]") {
  // A cube [-1, 1]^3 of fog (sigma_t 0.8, albedo 0.7, isotropic) behind a null
  // boundary, a point light of intensity 1 at its centre or above it at (0, ly, 0)
  // = (0, 3, 0), no other light, seen along -z by an orthographic camera whose
  // 4 x 4 pixels all look near (x0, y0). With 2 segments at most (camera to a
  // scattering event, a light sample from there; crossing the null boundary counts
  // for nothing, as in Mitsuba) the image is single scattering alone:
  //   L = integral over z in [-1, 1] of albedo sigma_t exp(-sigma_t (1 - z))
  //       (1 / 4 pi) exp(-sigma_t s) / r^2 dz,   r = |(x0, y0, z) - light|,
  // s the length of the light's segment inside the fog: r from the centre, r (1 -
  // y0) / (ly - y0) from above (it leaves through the top face), which a
  // midpoint rule gives. Each pixel's paths sample where they scatter (free
  // flight) and take a light sample there, which passes the null boundary with
  // the transmittance of the fog behind it: 16 x 1024 paths, 3 %, in both path
  // kernels (the wavefront casts its shadow rays in a kernel of its own).
  const float x0 = 0.5f, y0 = 0.3f, sigma = 0.8f, albedo = 0.7f;
  for (const float ly : {0.0f, 3.0f})
    for (int per_path : {1, 0}) {
      INFO("light at y " << ly << ", per_path " << per_path);
      const psf::Image img = render_xml("single.xml", R"(<scene version="3.0.0">
  <integrator type="volpath"/>
  <sensor type="orthographic">
    <transform name="to_world">
      <scale value="0.02"/><lookat origin="0.5, 0.3, 5" target="0.5, 0.3, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film>
  </sensor>
  <emitter type="point"><point name="position" x="0" y=")" + std::to_string(ly) + R"(" z="0"/>
    <rgb name="intensity" value="1, 1, 1"/></emitter>
  <shape type="cube">
    <bsdf type="null"/>
    <medium type="homogeneous" name="interior">
      <float name="sigma_t" value="0.8"/><float name="albedo" value="0.7"/>
    </medium>
  </shape>
</scene>
)", 1024, 2, 0, per_path).image;
      double want = 0.0;
      const int steps = 100000;
      for (int i = 0; i < steps; ++i) {
        const double z = -1.0 + 2.0 * (i + 0.5) / steps, r2 = x0 * x0 + (y0 - ly) * (y0 - ly) + z * z;
        const double inside = ly > 1.0f ? (1.0 - y0) / (ly - y0) : 1.0;
        want += albedo * sigma * std::exp(-sigma * (1.0 - z)) / (4.0 * M_PI) *
                std::exp(-sigma * std::sqrt(r2) * inside) / r2;
      }
      want *= 2.0 / steps;
      CHECK(mean(img) == Approx(want).epsilon(0.03));
    }
}

TEST_CASE("Render: a medium's null boundary costs no depth, in either path kernel", "[render]") {
  // A cube of absorbing fog behind a null boundary before a white sky, at a
  // maximum depth of 1 (only what the camera sees directly): as in Mitsuba, the
  // boundary's two crossings are null interactions, so the sky shows through the
  // fog, exp(-2 sigma_t), in the per-path kernel and in the wavefront alike
  // (whose rounds, one per crossing, outnumber the depth).
  for (int per_path : {1, 0}) {
    INFO("per_path " << per_path);
    const psf::Image img = render_xml("null-depth.xml", cube_under_sky(4, R"(<bsdf type="null"/>
    <medium type="homogeneous" name="interior">
      <float name="sigma_t" value="0.5"/><float name="albedo" value="0"/>
    </medium>)"),
                                      4, 1, 0, per_path).image;
    for (float v : img.rgb) REQUIRE(v == Approx(std::exp(-1.0f)).epsilon(1e-3));
  }
}

TEST_CASE("Render: a shape's exterior medium is where paths go when they leave it", "[render]") {
  // A null cube [-1, 1]^3 of absorbing fog (sigma_t 0.5) holds an index-matched
  // dielectric cube [-0.7, 0.7]^3 whose exterior is the fog (Mitsuba's
  // medium transition): inside it nothing, or ink (sigma_t 2). An orthographic
  // camera looks along -z at the white sky through both (its view 0.6 wide, and
  // the gaussian pixel filter's reach, stay within the inner cube): 0.6 of fog
  // and 1.4 of the inner cube, exp(-0.3) or exp(-0.3 - 2.8), in both path kernels. A path
  // that kept the fog inside the inner cube would read exp(-1); one that left
  // the inner cube into no medium, exp(-0.45).
  for (const bool ink : {false, true})
    for (int per_path : {1, 0}) {
      INFO((ink ? "ink" : "nothing") << " inside, per_path " << per_path);
      const psf::Image img = render_xml("exterior.xml", std::string(R"(<scene version="3.0.0">
  <integrator type="volpath"/>
  <medium type="homogeneous" id="fog"><float name="sigma_t" value="0.5"/><float name="albedo" value="0"/></medium>
  <sensor type="orthographic">
    <transform name="to_world"><scale value="0.3"/><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
  <shape type="cube"><bsdf type="null"/><ref name="interior" id="fog"/></shape>
  <shape type="cube">
    <transform name="to_world"><scale value="0.7"/></transform>
    <bsdf type="dielectric"><float name="int_ior" value="1"/></bsdf>
    <ref name="exterior" id="fog"/>)") + (ink ? R"(
    <medium type="homogeneous" name="interior">
      <float name="sigma_t" value="2"/><float name="albedo" value="0"/>
    </medium>)"
                                                : "") + R"(
  </shape>
</scene>
)", 4, -1, 0, per_path).image;
      const float want = std::exp(-0.3f - (ink ? 2.8f : 0.0f));
      for (float v : img.rgb) REQUIRE(v == Approx(want).epsilon(1e-3));
    }
}

TEST_CASE("Render: a camera inside a medium sees through it", "[render]") {
  // The sensor's medium (Mitsuba 3's `medium`) is the interior of a null-bounded
  // cube [-1, 1]^3 of absorbing fog; an orthographic camera at z = 0.5 inside it
  // looks along -z at the white sky through 1.5 units of it: exp(-0.75) per pixel
  // (Mitsuba 3's volpath, 16 spp: mean 0.4731 against psf's 0.4724).
  const psf::Image img = render_xml("camera-medium.xml", R"(<scene version="3.0.0">
  <integrator type="volpath"/>
  <medium type="homogeneous" id="fog"><float name="sigma_t" value="0.5"/><float name="albedo" value="0"/></medium>
  <sensor type="orthographic">
    <transform name="to_world">
      <scale value="0.5"/><lookat origin="0, 0, 0.5" target="0, 0, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    <ref id="fog" name="medium"/>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
  <shape type="cube"><bsdf type="null"/><ref id="fog" name="interior"/></shape>
</scene>
)", 4, -1).image;
  for (float v : img.rgb) REQUIRE(v == Approx(std::exp(-0.75f)).epsilon(1e-3));
}

TEST_CASE("Render: --emission-rays: the emission seen directly from more camera rays, unbiased", "[render]") {
  // An emitting square [-1, 1]^2 (Le = 4) facing a pinhole camera 5 units away
  // whose 30 degree field of view spans 2 * 5 tan(15 deg) = 2.679 units: the
  // square covers (2 / 2.679)^2 = 0.5572 of the film, nothing else is there, and
  // the box filter keeps each sample in its pixel, so the image's mean is 4 x
  // that. Its edges cross pixels at fractions of their width.
  const std::string path = psf::test::temp_dir("render-xml") + "/emission-rays.xml";
  std::ofstream(path) << R"(<scene version="3.0.0">
  <sensor type="perspective">
    <float name="fov" value="30"/>
    <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/>
      <rfilter type="box"/></film>
  </sensor>
  <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="4, 4, 4"/></emitter></shape>
</scene>
)";
  psf::Scene s = psf::load_scene(path);
  psf::Renderer r(psf::test::runtime(), s);
  psf::RenderOptions o;
  o.filter.enabled = false;
  const double covered = std::pow(2.0 / (10.0 * std::tan(15.0 * M_PI / 180.0)), 2.0);

  // K = 1 at 1 spp: a path's emission is the mean of its own ray's and one more
  // ray's, so every pixel is 0, 2 or 4; a value between would mean ray 0 was not
  // the ray the path traced (delta would not cancel its emission).
  o.spp = 1;
  o.emission_rays = 1;
  size_t halves = 0;
  for (float v : r.render(o).image.rgb) {
    const bool allowed = std::fabs(v) < 1e-5f || std::fabs(v - 2.0f) < 1e-5f || std::fabs(v - 4.0f) < 1e-5f;
    REQUIRE(allowed);
    halves += std::fabs(v - 2.0f) < 1e-5f ? 1 : 0;
  }
  CHECK(halves > 0);  // some edge pixel's two rays disagree

  // The reference: 1024 plain samples per pixel; its mean is the covered area's.
  o.emission_rays = 0;
  o.spp = 1024;
  const psf::Image ref = r.render(o).image;
  CHECK(mean(ref) == Approx(4.0 * covered).epsilon(1e-3));
  // At 4 spp, 3 more rays per path: the same mean (unbiased), and the edge
  // pixels' squared error against the reference much lower than plain 4 spp's.
  o.spp = 4;
  auto squared_error = [&](const psf::Image& img) {
    double e = 0.0;
    for (size_t i = 0; i < img.rgb.size(); ++i) e += (img.rgb[i] - ref.rgb[i]) * (img.rgb[i] - ref.rgb[i]);
    return e;
  };
  const psf::Image plain = r.render(o).image;
  o.emission_rays = 3;
  const psf::RenderResult more = r.render(o);
  CHECK(mean(more.image) == Approx(4.0 * covered).epsilon(5e-3));
  INFO("squared error, 4 spp: plain " << squared_error(plain) << ", 3 more rays " << squared_error(more.image));
  CHECK(squared_error(more.image) < 0.4 * squared_error(plain));
  // Ray 0's emission taken from the path's state is what casting it again finds,
  // bit for bit (shade.cl and emission.cl agree on hits, front faces and values).
  o.emission_recast = true;
  CHECK(r.render(o).image.rgb == more.image.rgb);
  o.emission_recast = false;
  // Filtered, the unfiltered layer is the plain render's with the same rays.
  o.filter.enabled = true;
  CHECK(r.render(o).unfiltered.rgb == more.image.rgb);
  // So also in the Cornell box (its light's edge, paths that add more than the
  // light they see), filtered.
  psf::Scene box =
      psf::load_scene(psf::test::source_path("scenes/cornell-box.xml"), {{"res", "32"}, {"spp", "4"}});
  psf::Renderer rb(psf::test::runtime(), box);
  const psf::RenderResult from_state = rb.render(o);
  o.emission_recast = true;
  const psf::RenderResult cast_again = rb.render(o);
  CHECK(from_state.image.rgb == cast_again.image.rgb);
  o.emission_rays = 0;
  CHECK(rb.render(o).image.rgb != cast_again.image.rgb);
}
