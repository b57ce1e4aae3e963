#include "render.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "bvh.h"
#include "lights.h"
#include "sampling.h"

namespace psf {

namespace {

psf_float4 f4(const glm::vec3& v, float w = 0.0f) { return {{v.x, v.y, v.z, w}}; }

}  // namespace

struct Renderer::Impl {
  Runtime& rt;
  const Scene& scene;
  Camera camera;
  std::unique_ptr<RayCaster> caster;
  cl::Buffer sobol, tri_pos, tri_material, materials, emitters, emitter_cdf, tri_light_pdf;
  uint32_t num_emitters = 0;
  Environment env{};    // the environment (env.present 0: none), a kernel argument by value
  cl::Buffer env_data;  // its texels and cdfs (psf_shared.h Environment)
  cl::Buffer tri_attribs, textures, texels;  // shading normals and uvs, texture table and texels (psf_shared.h)

  Impl(Runtime& r, const Scene& s) : rt(r), scene(s) {
    camera = make_camera(scene.camera, scene.width, scene.height);
    Bvh bvh = build_bvh(scene.positions, scene.triangles);
    bool masked = mark_masked(bvh, masked_triangles(scene)) > 0;  // mask materials: alpha-tested ray casts
    caster = std::make_unique<RayCaster>(rt, bvh);
    sobol = rt.upload(sobol_matrices());
    upload_geometry();
    upload_shading();
    if (masked) caster->enable_alpha({tri_material, materials, tri_attribs, textures, texels});
  }

  // Shading attributes and textures (replacing `materials` by device_materials);
  // a scene without textures gets the placeholder entry 0 (one white texel).
  void upload_shading() {
    std::vector<TriAttrib> attributes = triangle_attributes(scene);
    tri_attribs = rt.upload(attributes);
    materials = rt.upload(device_materials(scene, attributes));  // with PSF_MATFLAG_NORMALS
    if (!scene.textures.empty()) {
      textures = rt.upload(scene.textures);
      texels = rt.upload(scene.texels);
      return;
    }
    TextureInfo t{};
    t.uv_u = {{1, 0, 0, 0}};
    t.uv_v = {{0, 1, 0, 0}};
    t.width = t.height = 1;
    textures = rt.upload(std::vector<TextureInfo>{t});
    texels = rt.upload(std::vector<uint16_t>(4, uint16_t(0x3C00)));  // 1.0 as a half
  }

  void upload_geometry() {
    std::vector<psf_float4> pos;
    pos.reserve(scene.triangles.size() * 3);
    for (const auto& t : scene.triangles)
      for (int k = 0; k < 3; ++k) pos.push_back(f4(scene.positions[t[k]]));
    tri_pos = rt.upload(pos);
    tri_material = rt.upload(scene.tri_material);
    materials = rt.upload(scene.materials);

    // Lights: emissive triangles, delta lights and the environment, chosen by power (host/lights.cpp).
    LightTable lights = build_light_table(scene);
    num_emitters = uint32_t(lights.emitters.size());
    emitters = rt.upload(lights.emitters);
    emitter_cdf = rt.upload(lights.cdf);
    tri_light_pdf = rt.upload(lights.tri_light_pdf);
    env = lights.env;
    env_data = rt.upload(lights.env_data);
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
  cl::Buffer values = rt.buffer(CL_MEM_READ_WRITE, size_t(batch) * sizeof(cl_float4));
  cl::Buffer filtered = rt.buffer(CL_MEM_READ_WRITE, size_t(batch) * sizeof(cl_float4));
  cl::Buffer counts = rt.buffer(CL_MEM_READ_WRITE, size_t(batch) * sizeof(uint32_t));
  cl::Buffer ones = rt.upload(std::vector<uint32_t>(batch, 1u));
  std::vector<psf_float4> zero_image(pixels, psf_float4{{0, 0, 0, 0}});
  cl::Buffer image = rt.upload(zero_image, CL_MEM_READ_WRITE);
  cl::Buffer unfiltered = rt.upload(zero_image, CL_MEM_READ_WRITE);
  bool filtering = o.filter.enabled;
  std::unique_ptr<PathSpaceFilter> filter;
  if (filtering) filter = std::make_unique<PathSpaceFilter>(rt, batch);
  // r0_i = d_i sqrt(dOmega / pi), dOmega the solid angle of footprint_pixels^2
  // pixels at the image centre.
  const float pixel_w = 2.0f * glm::length(glm::vec3(s.camera.right.s[0], s.camera.right.s[1], s.camera.right.s[2])) / width;
  const float pixel_h = 2.0f * glm::length(glm::vec3(s.camera.down.s[0], s.camera.down.s[1], s.camera.down.s[2])) / height;
  const float footprint = o.filter.footprint_pixels * std::sqrt(pixel_w * pixel_h / float(M_PI));
  RenderResult r;
  cl::Buffer nonfinite = rt.upload(std::vector<uint32_t>(pixels, 0u), CL_MEM_READ_WRITE);
  cl::Buffer nonfinite_filtered = rt.upload(std::vector<uint32_t>(pixels, 0u), CL_MEM_READ_WRITE);
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
                s.emitter_cdf, s.tri_light_pdf, s.env, s.env_data, hits, rays, states, vertices, shadow_rays, alive,
                s.tri_attribs, s.textures, s.texels);
      s.caster->any(shadow_rays, shadow_hits, p.batch_size);
      rt.launch("shade_shadows", p.batch_size, L, p.batch_size, shadow_hits, states, vertices);
      uint32_t n_alive = 0;
      rt.read(alive, &n_alive, sizeof(n_alive));
      if (n_alive == 0) break;
    }

    // The tuple store, then path space filtering of the batch's c_i.
    rt.launch("store_tuples", p.batch_size, L, p.batch_size, states, values);
    rt.launch("accumulate", pixels, L, p, states, vertices, values, ones, unfiltered, nonfinite);
    if (filtering) {
      FilterParams fp{};
      fp.r0 = o.filter.r0;
      fp.footprint = footprint;
      // n: paths per pixel so far, so r0 is the radius of the first pass.
      double n = std::max(1.0, double(first + p.batch_size) / double(pixels));
      fp.n_scale = float(std::pow(n, -double(o.filter.alpha)));
      fp.normal_cos = o.filter.normal_cos;
      fp.albedo_tol = o.filter.albedo_tol;
      fp.count = p.batch_size;
      fp.cells27 = o.filter.cells27 ? 1u : 0u;
      uint32_t max_count = filter->run(fp, o.filter.iterations, vertices, values, filtered, counts);
      rt.launch("accumulate", pixels, L, p, states, vertices, filtered, counts, image, nonfinite_filtered);
      if (o.keep_last_batch && first + batch >= total) r.last_batch.params = fp;
      if (max_count <= 1) {
        filtering = false;
        r.filter_off_after = first + p.batch_size;
      }
    } else {
      rt.launch("accumulate", pixels, L, p, states, vertices, values, ones, image, nonfinite_filtered);
    }
    if (o.keep_last_batch && first + batch >= total) {
      r.last_batch.vertices = rt.download<PathVertex>(vertices, p.batch_size);
      r.last_batch.values = rt.download<cl_float4>(values, p.batch_size);
    }
    rt.finish();
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.paths = total;
  r.batch_size = batch;
  auto resolve = [&](const cl::Buffer& sums_buf, const cl::Buffer& bad_buf, Image& out, bool neighbours) {
    auto sums = rt.download<psf_float4>(sums_buf, pixels);
    auto bad = rt.download<uint32_t>(bad_buf, pixels);
    out.width = int(width);
    out.height = int(height);
    out.rgb.resize(pixels * 3);
    if (neighbours) r.neighbours.resize(pixels);
    uint64_t nonfinite = 0;
    for (uint64_t i = 0; i < pixels; ++i) {
      // Paths of pixel i: indices i, i + pixels, ... below total, less the non-finite ones.
      uint64_t all = total / pixels + (i < total % pixels ? 1 : 0);
      uint64_t n = all - bad[i];
      nonfinite += bad[i];
      for (int c = 0; c < 3; ++c) out.rgb[i * 3 + c] = n ? sums[i].s[c] / float(n) : 0.0f;
      if (neighbours) r.neighbours[i] = all ? sums[i].s[3] / float(all) : 0.0f;
    }
    return nonfinite;
  };
  r.nonfinite = resolve(image, nonfinite_filtered, r.image, true);
  resolve(unfiltered, nonfinite, r.unfiltered, false);
  return r;
}

}  // namespace psf
