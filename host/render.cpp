#include "render.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "bvh.h"
#include "sampling.h"

namespace psf {

namespace {

float luminance(const glm::vec3& c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

psf_float4 f4(const glm::vec3& v, float w = 0.0f) { return {{v.x, v.y, v.z, w}}; }

}  // namespace

struct Renderer::Impl {
  Runtime& rt;
  const Scene& scene;
  Camera camera;
  std::unique_ptr<RayCaster> caster;
  cl::Buffer sobol, tri_pos, tri_material, materials, emitters, emitter_cdf, tri_light_pdf;
  uint32_t num_emitters = 0;

  Impl(Runtime& r, const Scene& s) : rt(r), scene(s) {
    camera = make_camera(scene.camera, scene.width, scene.height);
    caster = std::make_unique<RayCaster>(rt, build_bvh(scene.positions, scene.triangles));
    sobol = rt.upload(sobol_matrices());
    upload_geometry();
  }

  void upload_geometry() {
    std::vector<psf_float4> pos;
    pos.reserve(scene.triangles.size() * 3);
    for (const auto& t : scene.triangles)
      for (int k = 0; k < 3; ++k) pos.push_back(f4(scene.positions[t[k]]));
    tri_pos = rt.upload(pos);
    tri_material = rt.upload(scene.tri_material);
    materials = rt.upload(scene.materials);

    // Emitters: every triangle of an emissive material, chosen in proportion to its power.
    std::vector<Emitter> em;
    std::vector<float> power;
    for (size_t i = 0; i < scene.triangles.size(); ++i) {
      const Material& m = scene.materials[scene.tri_material[i]];
      glm::vec3 le(m.emission.s[0], m.emission.s[1], m.emission.s[2]);
      if (luminance(le) <= 0.0f) continue;
      const auto& t = scene.triangles[i];
      glm::vec3 a = scene.positions[t[0]], b = scene.positions[t[1]], c = scene.positions[t[2]];
      float area = 0.5f * glm::length(glm::cross(b - a, c - a));
      if (!(area > 0.0f) || !std::isfinite(area)) continue;
      Emitter e{};
      e.v0 = f4(a, area);
      e.e1 = f4(b - a);
      e.e2 = f4(c - a);
      e.radiance = f4(le);
      e.prim = uint32_t(i);
      e.two_sided = m.two_sided;
      em.push_back(e);
      power.push_back(area * luminance(le) * (m.two_sided ? 2.0f : 1.0f));
    }
    double total = 0.0;
    for (float p : power) total += p;
    std::vector<float> cdf(em.size());
    std::vector<float> light_pdf(scene.triangles.size(), 0.0f);
    double run = 0.0;
    for (size_t i = 0; i < em.size(); ++i) {
      float pmf = float(power[i] / total);
      em[i].radiance.s[3] = pmf;
      run += power[i];
      cdf[i] = float(run / total);
      light_pdf[em[i].prim] = pmf / em[i].v0.s[3];
    }
    if (!cdf.empty()) cdf.back() = 1.0f;
    num_emitters = uint32_t(em.size());
    emitters = rt.upload(em);
    emitter_cdf = rt.upload(cdf);
    tri_light_pdf = rt.upload(light_pdf);
  }
};

Renderer::Renderer(Runtime& rt, const Scene& scene) : impl_(std::make_unique<Impl>(rt, scene)) {}
Renderer::~Renderer() = default;

RenderResult Renderer::render(const RenderOptions& o) {
  Impl& s = *impl_;
  Runtime& rt = s.rt;
  const uint32_t width = uint32_t(s.scene.width), height = uint32_t(s.scene.height);
  const uint64_t pixels = uint64_t(width) * height;
  const uint64_t total = pixels * uint64_t(std::max(o.spp, 0));

  // Batch of 2^m paths: bounded by --batch and by the device's allocation limit.
  const size_t bytes_per_path = sizeof(PathState) + sizeof(PathVertex) + 2 * sizeof(Ray) + 2 * sizeof(Hit);
  int m = o.batch_log2;
  while (m > 8 && ((size_t(1) << m) * sizeof(PathState) > rt.device().max_alloc ||
                   (size_t(1) << m) * bytes_per_path > rt.device().global_mem / 2))
    --m;
  const uint32_t batch = uint32_t(1) << m;

  cl::Buffer states = rt.buffer(CL_MEM_READ_WRITE, size_t(batch) * sizeof(PathState));
  cl::Buffer vertices = rt.buffer(CL_MEM_READ_WRITE, size_t(batch) * sizeof(PathVertex));
  cl::Buffer rays = rt.buffer(CL_MEM_READ_WRITE, size_t(batch) * sizeof(Ray));
  cl::Buffer hits = rt.buffer(CL_MEM_READ_WRITE, size_t(batch) * sizeof(Hit));
  cl::Buffer shadow_rays = rt.buffer(CL_MEM_READ_WRITE, size_t(batch) * sizeof(Ray));
  cl::Buffer shadow_hits = rt.buffer(CL_MEM_READ_WRITE, size_t(batch) * sizeof(Hit));
  std::vector<psf_float4> zero_image(pixels, psf_float4{{0, 0, 0, 0}});
  cl::Buffer image = rt.upload(zero_image, CL_MEM_READ_WRITE);
  cl::Buffer nonfinite = rt.upload(std::vector<uint32_t>(pixels, 0u), CL_MEM_READ_WRITE);
  cl::Buffer alive = rt.buffer(CL_MEM_READ_WRITE, sizeof(uint32_t));

  const size_t L = Runtime::kDefaultLocal;
  auto t0 = std::chrono::steady_clock::now();
  for (uint64_t first = 0; first < total; first += batch) {
    FrameParams p{};
    p.width = width;
    p.height = height;
    p.seed = o.seed;
    p.max_depth = uint32_t(o.max_depth);
    p.first_path_lo = uint32_t(first);
    p.first_path_hi = uint32_t(first >> 32);
    p.batch_size = uint32_t(std::min<uint64_t>(batch, total - first));
    p.num_emitters = s.num_emitters;
    p.rr_depth = uint32_t(std::max(o.rr_depth, 1));

    rt.launch("camera_rays", p.batch_size, L, p, s.camera, s.sobol, states, vertices, rays);
    for (int depth = 0; o.max_depth < 0 || depth < o.max_depth; ++depth) {
      s.caster->closest(rays, hits, p.batch_size);
      uint32_t zero = 0;
      rt.write(alive, &zero, sizeof(zero));
      rt.launch("shade", p.batch_size, L, p, s.sobol, s.tri_pos, s.tri_material, s.materials, s.emitters,
                s.emitter_cdf, s.tri_light_pdf, hits, rays, states, vertices, shadow_rays, alive);
      s.caster->any(shadow_rays, shadow_hits, p.batch_size);
      rt.launch("shade_shadows", p.batch_size, L, p.batch_size, shadow_hits, states, vertices);
      uint32_t n_alive = 0;
      rt.read(alive, &n_alive, sizeof(n_alive));
      if (n_alive == 0) break;
    }
    rt.launch("accumulate", pixels, L, p, states, vertices, image, nonfinite);
    rt.finish();
  }
  RenderResult r;
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.paths = total;
  r.batch_size = batch;
  auto sums = rt.download<psf_float4>(image, pixels);
  auto bad = rt.download<uint32_t>(nonfinite, pixels);
  r.image.width = int(width);
  r.image.height = int(height);
  r.image.rgb.resize(pixels * 3);
  for (uint64_t i = 0; i < pixels; ++i) {
    // Paths of pixel i: indices i, i + pixels, ... below total, less the non-finite ones.
    uint64_t n = total / pixels + (i < total % pixels ? 1 : 0) - bad[i];
    r.nonfinite += bad[i];
    for (int c = 0; c < 3; ++c) r.image.rgb[i * 3 + c] = n ? sums[i].s[c] / float(n) : 0.0f;
  }
  return r;
}

}  // namespace psf
