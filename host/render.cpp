#include "render.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>

#include "bvh.h"
#include "lights.h"
#include "sampling.h"

namespace psf {

namespace {

psf_float4 f4(const glm::vec3& v, float w = 0.0f) { return {{v.x, v.y, v.z, w}}; }

// Host threads for a pass over a batch of n paths split into `parts` ranges:
// one per 65536 paths, at most 16 and the machine's.
uint64_t host_threads(uint64_t n, uint64_t parts) {
  return std::max<uint64_t>(1, std::min<uint64_t>({std::thread::hardware_concurrency(), 16, n >> 16, parts}));
}

// f(begin, end) over `threads` contiguous ranges of [0, count), the first on this thread.
template <typename F>
void in_parallel(uint64_t count, uint64_t threads, F&& f) {
  threads = std::max<uint64_t>(1, threads);
  std::vector<std::thread> pool;
  for (uint64_t t = 1; t < threads; ++t) pool.emplace_back(f, count * t / threads, count * (t + 1) / threads);
  f(0, count / threads);
  for (auto& t : pool) t.join();
}

// Whether trace_lanes (kernels/trace_lanes.cl) can render the scene: its device
// materials may have any BSDF, texture, bump map, blend or emission texture,
// but no medium or null boundary, and its camera sits in no medium.
bool lanes_materials_supported(const std::vector<Material>& materials) {
  for (const Material& m : materials)
    if ((m.flags & PSF_MATFLAG_NULL_BOUNDARY) != 0 || m.interior.s[3] > 0.0f || m.exterior != 0) return false;
  return true;
}
// Whether the lanes shade device material m in vectors (PSF_MATFLAG_LANES_VECTOR):
// diffuse, with a colour texture, an opacity mask, two sides and vertex normals
// allowed, nothing else that changes the frame or the BSDF.
bool lanes_vector_material(const Material& m) {
  return m.type == PSF_MATERIAL_DIFFUSE && m.blend == 0 &&
         (m.flags & ~(PSF_MATFLAG_NORMALS | PSF_MATFLAG_MASKED)) == 0 && m.tex_bump == PSF_NO_TEXTURE &&
         m.tex_alpha == PSF_NO_TEXTURE && m.tex_table == PSF_NO_TEXTURE && m.alpha_u == m.alpha_v;
}

}  // namespace

struct Renderer::Impl {
  Runtime& rt;
  const Scene& scene;
  Camera camera;
  std::unique_ptr<RayCaster> caster;
  BvhSummary bvh_summary;
  cl::Buffer sobol, tri_pos, tri_material, materials, emitters, emitter_cdf, tri_light_pdf;
  uint32_t num_emitters = 0;
  bool lanes = false;  // no camera medium, and lanes_materials_supported
  float auto_visibility_ray = 0.0f;  // visibility_ray(kVisibilityRayAuto)
  Environment env{};    // the environment (env.present 0: none), a kernel argument by value
  cl::Buffer env_data;  // its texels and cdfs (psf_shared.h Environment)
  cl::Buffer tri_attribs, textures, texels;  // shading normals and uvs, texture table and texels (psf_shared.h)

  Impl(Runtime& r, const Scene& s) : rt(r), scene(s) {
    camera = make_camera(scene.camera, scene.width, scene.height);
    std::vector<BvhSphere> spheres;
    for (const SphereShape& sp : scene.spheres) spheres.push_back({sp.center, sp.radius});
    Bvh bvh = build_bvh(scene.positions, scene.triangles, spheres);
    bvh_summary = {bvh.nodes.size(),
                   bvh.packs.size(),
                   bvh.nodes.size() * sizeof(BvhNode) + bvh.packs.size() * sizeof(BvhTriPack),
                   bvh.triangle_count + bvh.sphere_count,
                   bvh.references,
                   bvh.build_ms};
    // Mask materials and media's null boundaries: ray casts that test materials.
    bool masked = mark_masked(bvh, masked_prims(scene)) > 0;
    caster = std::make_unique<RayCaster>(rt, bvh);
    sobol = rt.upload(sobol_matrices());
    upload_geometry();
    upload_shading();
    if (masked) caster->enable_alpha({tri_material, materials, tri_attribs, textures, texels});
  }

  // Shading attributes and textures (replacing `materials` by device_materials);
  // a scene without textures gets the placeholder entry 0 (one white texel).
  void upload_shading() {
    // A path names its medium by 1 + a material index in the bits of
    // PathState.flags above PSF_PATH_MEDIUM_SHIFT.
    if (scene.materials.size() >= (size_t(1) << (32 - PSF_PATH_MEDIUM_SHIFT)))
      throw std::invalid_argument("the scene has " + std::to_string(scene.materials.size()) +
                                  " materials; at most " + std::to_string((1u << (32 - PSF_PATH_MEDIUM_SHIFT)) - 1) +
                                  " are supported");
    std::vector<TriAttrib> attributes = triangle_attributes(scene);
    tri_attribs = rt.upload(attributes);
    std::vector<Material> device = device_materials(scene, attributes);  // with PSF_MATFLAG_NORMALS
    for (Material& m : device)
      if (lanes_vector_material(m)) m.flags |= PSF_MATFLAG_LANES_VECTOR;
    materials = rt.upload(device);
    lanes = scene.camera_medium == 0 && lanes_materials_supported(device);
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
    pos.reserve((scene.triangles.size() + scene.spheres.size()) * 3);
    for (const auto& t : scene.triangles)
      for (int k = 0; k < 3; ++k) pos.push_back(f4(scene.positions[t[k]]));
    // A sphere's three entries (shade.cl): centre and radius, its local x axis
    // and the normal's sign (-1: flip_normals), its local y axis.
    std::vector<uint32_t> prim_material = scene.tri_material;
    for (const SphereShape& sp : scene.spheres) {
      pos.push_back(f4(sp.center, sp.radius));
      pos.push_back(f4(sp.axis_x, sp.flip ? -1.0f : 1.0f));
      pos.push_back(f4(sp.axis_y));
      prim_material.push_back(sp.material);
    }
    if (pos.empty()) pos.push_back(f4(glm::vec3(0.0f)));  // no zero-size buffers
    tri_pos = rt.upload(pos);
    tri_material = rt.upload(prim_material);
    materials = rt.upload(scene.materials);

    // Lights: emissive triangles, delta lights and the environment, chosen by power (host/lights.cpp).
    LightTable lights = build_light_table(scene);
    num_emitters = uint32_t(lights.emitters.size());
    bool environment_only = num_emitters > 0;
    for (const Emitter& e : lights.emitters) environment_only = environment_only && e.type == PSF_EMITTER_ENVIRONMENT;
    if (environment_only) {
      glm::vec3 lo, hi;
      scene_bounds(scene, lo, hi);
      if (lo.x <= hi.x) auto_visibility_ray = 0.01f * glm::length(hi - lo);
    }
    emitters = rt.upload(lights.emitters);
    emitter_cdf = rt.upload(lights.cdf);
    tri_light_pdf = rt.upload(lights.tri_light_pdf);
    env = lights.env;
    env_data = rt.upload(lights.env_data);
  }
};

void Accumulator::reset(int w, int h, bool aovs) {
  width = w;
  height = h;
  size_t n = size_t(w) * h;
  filtered.assign(n * 4, 0.0f);
  unfiltered.assign(n * 4, 0.0f);
  bad_filtered.assign(n, 0);
  bad_unfiltered.assign(n, 0);
  aov.assign(aovs ? n * 8 : 0, 0.0f);
  paths = 0;
  next_batch = 0;
}

void Accumulator::add(const BatchImages& b) {
  if (b.index != next_batch) throw std::logic_error("batches must be accumulated in order");
  const uint64_t pixels = uint64_t(width) * height;
  const uint64_t n = b.unfiltered.size(), offset = b.first % pixels;
  const std::vector<cl_float4>& f = b.filtered.empty() ? b.unfiltered : b.filtered;
  auto add_one = [](float* sums, uint32_t& bad, const cl_float4& c) {
    if (std::isfinite(c.s[0]) && std::isfinite(c.s[1]) && std::isfinite(c.s[2])) {
      for (int k = 0; k < 3; ++k) sums[k] += c.s[k];
    } else {
      bad += 1;
    }
    sums[3] += c.s[3];
  };
  // Path j belongs to pixel (first + j) mod pixels: the batch covers the pixels
  // first + k, k < min(n, pixels) (wrapping), pixel first + k has the paths k,
  // k + pixels, ... Threads take disjoint ranges of k and add each pixel's paths
  // in path order: the sums are the same, bit for bit, as one thread adding the
  // paths in order. A batch smaller than the film touches only its own pixels.
  const uint64_t covered = std::min(n, pixels);
  auto add_pixels = [&](uint64_t k0, uint64_t k1) {
    for (uint64_t round = 0; round * pixels < n; ++round) {
      for (uint64_t k = k0; k < k1; ++k) {
        const uint64_t j = k + round * pixels;
        if (j >= n) break;  // and so for every later k of this round
        const uint64_t p = offset + k < pixels ? offset + k : offset + k - pixels;
        add_one(&filtered[p * 4], bad_filtered[p], f[j]);
        add_one(&unfiltered[p * 4], bad_unfiltered[p], b.unfiltered[j]);
        if (aov.empty() || j >= b.vertices.size()) continue;
        const PathVertex& v = b.vertices[j];
        if (v.albedo.s[3] == 0.0f) continue;
        float* a = &aov[p * 8];  // albedo rgb, depth, normal xyz, vertices
        for (int c = 0; c < 3; ++c) {
          a[c] += v.albedo.s[c];
          a[4 + c] += v.normal.s[c];
        }
        a[3] += v.position.s[3];
        a[7] += 1.0f;
      }
    }
  };
  in_parallel(covered, host_threads(n, covered >> 10), add_pixels);
  paths += n;
  next_batch += 1;
}

void NoiseMonitor::reset(uint64_t pixels) {
  sum_.assign(pixels, 0.0);
  sum2_.assign(pixels, 0.0);
  count_.assign(pixels, 0);
}

double NoiseMonitor::add(const BatchImages& b) {
  const uint64_t pixels = sum_.size();
  if (pixels == 0) throw std::logic_error("NoiseMonitor::add before reset");
  auto lum = [](const cl_float4& c) { return 0.2126 * c.s[0] + 0.7152 * c.s[1] + 0.0722 * c.s[2]; };
  const bool filtered = !b.filtered.empty();
  const uint64_t n = b.unfiltered.size(), offset = b.first % pixels;
  // Pixel by pixel over the pixel's paths of the batch (the batch covers pixels
  // first + k, k < min(n, pixels), wrapping; pixel first + k has the paths k,
  // k + pixels, ...), in blocks of kBlock values of k whose partial sums are
  // added in block order: the figure does not depend on the number of threads.
  constexpr uint64_t kBlock = 4096;
  const uint64_t covered = std::min(n, pixels);
  const uint64_t blocks = (covered + kBlock - 1) / kBlock;
  std::vector<double> part_removed(blocks, 0.0), part_noise(blocks, 0.0);
  auto run = [&](uint64_t b0, uint64_t b1) {
    for (uint64_t blk = b0; blk < b1; ++blk) {
      double removed = 0.0, noise = 0.0;
      for (uint64_t k = blk * kBlock; k < std::min(covered, (blk + 1) * kBlock); ++k) {
        const uint64_t p = offset + k < pixels ? offset + k : offset + k - pixels;
        double su = 0.0, su2 = 0.0, sf = 0.0;
        uint32_t cnt = 0;
        for (uint64_t j = k; j < n; j += pixels) {
          const double u = lum(b.unfiltered[j]), f = filtered ? lum(b.filtered[j]) : u;
          if (!std::isfinite(u) || !std::isfinite(f)) continue;
          su += u;
          su2 += u * u;
          sf += f;
          cnt += 1;
        }
        if (cnt == 0) continue;
        // The batch is set against the variances before it, so that its own
        // noise does not enter both sides; then its sums join the pixel's.
        if (filtered && count_[p] >= 2) {
          const double m = sum_[p] / count_[p];
          const double var = std::max(0.0, (sum2_[p] - m * sum_[p]) / double(count_[p] - 1));
          const double w = 1.0 / (m * m + 0.01), d = (sf - su) / cnt;
          removed += w * d * d;
          noise += w * var / cnt;
        }
        sum_[p] += su;
        sum2_[p] += su2;
        count_[p] += cnt;
      }
      part_removed[blk] = removed;
      part_noise[blk] = noise;
    }
  };
  in_parallel(blocks, host_threads(n, blocks), run);
  double removed = 0.0, noise = 0.0;
  for (uint64_t blk = 0; blk < blocks; ++blk) {
    removed += part_removed[blk];
    noise += part_noise[blk];
  }
  return noise > 0.0 ? removed / noise : std::numeric_limits<double>::quiet_NaN();
}

namespace {

// Whether the scene's environment is a map whose light samples the wavefront draws
// in kernels of their own (shade_env_samples, shade_env_blocks, shade_env_cells, shade_env_texels).
bool env_map_sampled(const Environment& env) { return env.present && env.width > 0; }

// Paths of pixel i among the first `paths` paths of a render: i, i + pixels, ...
uint64_t pixel_paths(uint64_t i, uint64_t pixels, uint64_t paths) {
  return paths / pixels + (i < paths % pixels ? 1 : 0);
}

Image average(const std::vector<float>& sums, const std::vector<uint32_t>& bad, int w, int h, uint64_t paths) {
  Image img;
  img.width = w;
  img.height = h;
  uint64_t pixels = uint64_t(w) * h;
  img.rgb.resize(pixels * 3);
  for (uint64_t i = 0; i < pixels; ++i) {
    uint64_t n = pixel_paths(i, pixels, paths) - bad[i];
    for (int c = 0; c < 3; ++c) img.rgb[i * 3 + c] = n ? sums[i * 4 + c] / float(n) : 0.0f;
  }
  return img;
}

}  // namespace

Image Accumulator::image() const { return average(filtered, bad_filtered, width, height, paths); }
Image Accumulator::unfiltered_image() const { return average(unfiltered, bad_unfiltered, width, height, paths); }

std::vector<float> Accumulator::neighbours() const {
  uint64_t pixels = uint64_t(width) * height;
  std::vector<float> out(pixels);
  for (uint64_t i = 0; i < pixels; ++i) {
    uint64_t n = pixel_paths(i, pixels, paths);
    out[i] = n ? filtered[i * 4 + 3] / float(n) : 0.0f;
  }
  return out;
}

std::vector<float> Accumulator::aov_layer(int which) const {
  uint64_t pixels = uint64_t(width) * height;
  int channels = which == 2 ? 1 : 3;
  std::vector<float> out(pixels * channels, 0.0f);
  if (aov.empty()) return out;
  for (uint64_t i = 0; i < pixels; ++i) {
    float vertices = aov[i * 8 + 7];  // paths of the pixel that have a filtering vertex
    if (vertices <= 0) continue;
    const float* a = &aov[i * 8];     // albedo rgb, depth, normal xyz, vertices
    if (which == 0)
      for (int c = 0; c < 3; ++c) out[i * 3 + c] = a[c] / vertices;
    else if (which == 1)
      for (int c = 0; c < 3; ++c) out[i * 3 + c] = a[4 + c] / vertices;
    else
      out[i] = a[3] / vertices;
  }
  return out;
}

uint64_t Accumulator::nonfinite() const {
  uint64_t n = 0;
  for (uint32_t b : bad_filtered) n += b;
  return n;
}

struct Renderer::Batch {
  RenderOptions o;       // the options prepare() was given
  uint32_t size = 0;      // paths per batch
  uint32_t capacity = 0;  // paths the buffers hold: size, or fewer where the render traces fewer
  cl::Buffer states, vertices, hits, shadow_rays, shadow_hits, values, filtered, counts;
  cl::Buffer rays[2], queue[2];  // the live paths' rays and path indices, this bounce and the next
  cl::Buffer env_samples;        // environment light samples drawn ahead of shade (PSF_ENV_RECORD float4 per path)
  cl::Buffer contrib, contrib_unfiltered, alive;
  std::unique_ptr<PathSpaceFilter> filter;
  float footprint = 0;   // sqrt(dOmega / pi) of the footprint
  std::mutex spare_mu;   // recycle() runs on the thread that accumulates
  std::vector<std::vector<cl_float4>> spare;  // download vectors handed back by recycle()

  // n contributions from `buf`, into a recycled vector where there is one.
  std::vector<cl_float4> download(Runtime& rt, const cl::Buffer& buf, size_t n) {
    std::vector<cl_float4> v;
    {
      std::lock_guard<std::mutex> lock(spare_mu);
      if (!spare.empty()) {
        v = std::move(spare.back());
        spare.pop_back();
      }
    }
    v.reserve(size);  // a whole batch's, so that recycle() keeps it after a smaller batch too
    v.resize(n);
    rt.read(buf, v.data(), n * sizeof(cl_float4));
    return v;
  }
};

Renderer::Renderer(Runtime& rt, const Scene& scene) : impl_(std::make_unique<Impl>(rt, scene)) {}
Renderer::~Renderer() = default;
Runtime& Renderer::runtime() { return impl_->rt; }
uint32_t Renderer::batch_size() const { return batch_ ? batch_->size : 0; }

std::vector<BufferNeed> Renderer::batch_needs(bool filtering, bool aovs, int iterations) {
  std::vector<BufferNeed> needs = {
      {"path states", sizeof(PathState)}, {"filtering vertices", sizeof(PathVertex)},
      {"rays (two queues)", 2 * sizeof(Ray)}, {"hits", sizeof(Hit)},
      {"path queues", 2 * sizeof(uint32_t)},      {"environment samples", PSF_ENV_RECORD * sizeof(cl_float4)},
      {"shadow rays", sizeof(Ray)},       {"shadow hits", sizeof(Hit)},
      {"values c", sizeof(cl_float4)},    {"counts", sizeof(uint32_t)},
      {"contributions", 2 * sizeof(cl_float4)},
  };
  if (filtering) {
    needs.push_back({"filtered values", sizeof(cl_float4)});
    needs.push_back({"filter tuples, keys, sort and cell ranges", double(PathSpaceFilter::bytes_per_tuple(iterations))});
  }
  (void)aovs;  // AOV images are per pixel: fixed_bytes()
  return needs;
}

uint64_t Renderer::fixed_bytes() const {
  const Scene& s = impl_->scene;
  uint64_t pixels = uint64_t(s.width) * s.height;
  // Scene: triangles (positions, BVH, attributes, materials) with generous slack,
  // textures and the environment; the image lives on the host.
  (void)pixels;
  return uint64_t(s.triangles.size()) * 256 + uint64_t(s.texels.size()) * 2 + (64u << 20);
}

void Renderer::prepare(const RenderOptions& o, int batch_log2, uint64_t paths) {
  Runtime& rt = impl_->rt;
  // Buffers for at most the paths the render traces: an 8x8 preview does not
  // allocate (and zero) those of 2^20 paths. The batch size stays 2^batch_log2.
  const uint32_t size = uint32_t(1) << batch_log2;
  const uint32_t capacity = paths > 0 && paths < size ? uint32_t(paths) : size;
  // A later render of the same batch size keeps the buffers: a new buffer on a
  // CPU device is new memory, whose first touch by the kernels faults in and
  // zeroes every page (about 400 MB at 2^20 paths, a tenth of a 4-batch render
  // of Mitsuba's cbox in `perf`). The kernels write every buffer before reading
  // it within a batch, so nothing carries over from the last render.
  if (batch_ && batch_->size == size && batch_->capacity >= capacity) {
    batch_->o = o;
    if (o.filter.enabled && !batch_->filter) batch_->filter = std::make_unique<PathSpaceFilter>(rt, batch_->capacity);
    batch_->footprint = footprint(o);
    return;
  }
  auto b = std::make_unique<Batch>();
  if (batch_) b->spare = std::move(batch_->spare);  // download vectors already paged in, for the next render
  batch_.reset();
  b->o = o;
  b->size = size;
  b->capacity = capacity;
  const size_t n = capacity;
  b->states = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(PathState));
  b->vertices = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(PathVertex));
  for (int q = 0; q < 2; ++q) {
    b->rays[q] = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(Ray));
    b->queue[q] = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(uint32_t));
  }
  b->hits = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(Hit));
  b->shadow_rays = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(Ray));
  const bool env_map = env_map_sampled(impl_->env);
  b->env_samples = rt.buffer(CL_MEM_READ_WRITE, (env_map ? n : 1) * PSF_ENV_RECORD * sizeof(cl_float4));
  b->shadow_hits = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(Hit));
  b->values = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(cl_float4));
  b->filtered = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(cl_float4));
  b->counts = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(uint32_t));
  b->contrib = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(cl_float4));
  b->contrib_unfiltered = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(cl_float4));
  b->alive = rt.buffer(CL_MEM_READ_WRITE, sizeof(uint32_t));
  if (o.filter.enabled) b->filter = std::make_unique<PathSpaceFilter>(rt, b->capacity);
  b->footprint = footprint(o);
  rt.finish();  // surfaces allocation failures here
  batch_ = std::move(b);
}

// r0_i = d_i sqrt(dOmega / pi), dOmega the solid angle of footprint_pixels^2
// pixels at the image centre (orthographic: the radius of their area); with
// --foreshortening the kernels stretch it by the vertex's 1 / sqrt(cos theta).
float Renderer::footprint(const RenderOptions& o) const {
  const Camera& cam = impl_->camera;
  const float pixel_w = 2.0f * glm::length(glm::vec3(cam.right.s[0], cam.right.s[1], cam.right.s[2])) / cam.width;
  const float pixel_h = 2.0f * glm::length(glm::vec3(cam.down.s[0], cam.down.s[1], cam.down.s[2])) / cam.height;
  return o.filter.footprint_pixels * std::sqrt(pixel_w * pixel_h / float(M_PI));
}

float Renderer::visibility_ray(float option) const {
  return option == kVisibilityRayAuto ? impl_->auto_visibility_ray : option;
}

// trace_lanes' casts in a scene of a few primitives: each against the eight
// lanes' rays at once, without the BVH (kernels/trace_lanes.cl, flat_closest8).
// PoCL on 2 cores (AMD EPYC, AVX-512), tracing times at 8-64 spp, flat / BVH:
// sphere-light (5 primitives) 0.58, sphere-ground (3) 0.63, our Cornell box
// (36) 0.72, Mitsuba's cbox (38) 0.76; that cbox with cubes of 12 triangles
// added: 50 primitives 0.90, 62 1.02, 74 1.11, 86 1.22, 110 1.36 (each pack
// tested). Since the flat casts of a BVH that is one node of leaves skip the
// leaves whose boxes no ray of the eight meets: our Cornell box 0.97-0.99 and
// the cbox 0.96-0.97 of the time without, and our Cornell box with two cubes
// (60 primitives, one node, 10 packs) 0.78 of the BVH's; with four (84, two
// nodes, no boxes to skip by) 1.22. Hence flat casts at most kLanesFlatPrims
// primitives or a BVH of one node. Not where primitives are alpha-tested (these
// casts have no alpha test).
const BvhSummary& Renderer::bvh_summary() const { return impl_->bvh_summary; }

uint32_t Renderer::flat_packs(int option) const {
  const RayCaster& c = *impl_->caster;
  const bool few = c.prim_count() <= kLanesFlatPrims || c.root_of_leaves();
  return option != 0 && !c.masked() && few ? c.pack_count() : 0u;
}

BatchImages Renderer::trace_batch(uint64_t index, uint64_t total, bool filtering) {
  Impl& s = *impl_;
  Runtime& rt = s.rt;
  Batch& b = *batch_;
  const RenderOptions& o = b.o;
  const uint32_t width = uint32_t(s.scene.width), height = uint32_t(s.scene.height);
  const uint64_t pixels = uint64_t(width) * height;
  const uint64_t first = index * b.size;
  const size_t L = Runtime::kDefaultLocal;
  filtering = filtering && b.filter;
  const auto t0 = std::chrono::steady_clock::now();

  FrameParams p{};
  p.width = width;
  p.height = height;
  p.seed = o.seed;
  p.max_depth = uint32_t(o.max_depth);
  p.first_path_lo = uint32_t(first);
  p.first_path_hi = uint32_t(first >> 32);
  p.batch_size = uint32_t(std::min<uint64_t>(b.size, total - first));
  if (p.batch_size > b.capacity)  // prepare() was told the render traces fewer paths
    throw std::logic_error("batch of " + std::to_string(p.batch_size) + " paths in buffers for " +
                           std::to_string(b.capacity));
  p.num_emitters = s.num_emitters;
  p.rr_depth = uint32_t(std::max(o.rr_depth, 1));
  p.dim_bounce0 = s.camera.aperture > 0.0f ? PSF_DIM_BOUNCE0_LENS : PSF_DIM_BOUNCE0;
  p.hide = s.scene.hide;
  p.first_sphere = uint32_t(s.scene.triangles.size());
  p.spheres = s.caster->sphere_mode();
  p.flat_packs = flat_packs(o.flat_casts);
  p.camera_medium = s.scene.camera_medium;
  p.max_rounds = p.max_depth;
  for (const Material& m : s.scene.materials)
    if (m.flags & PSF_MATFLAG_NULL_BOUNDARY) {
      p.max_rounds = uint32_t(-1);
      p.null_media = 1;
    }
  auto& states = b.states;
  auto& vertices = b.vertices;
  auto& hits = b.hits;
  auto& shadow_rays = b.shadow_rays;
  auto& shadow_hits = b.shadow_hits;
  auto& alive = b.alive;

  const uint32_t env_presampled = env_map_sampled(s.env) ? 1u : 0u;
  // On CPU devices each path runs whole in one work-item (kernels/shade.cl,
  // trace_paths): its state stays in the core's cache between bounces. Not for
  // scenes lit by an environment map: there the wavefront's short sampling
  // kernels overlap the map's cache misses across paths, which one long kernel
  // per path cannot (PoCL, living room: 35 % slower per path; Cornell boxes:
  // 8-13 % faster).
  const bool per_path = o.per_path > 0 || (o.per_path < 0 && rt.device().type == "CPU" && !env_presampled);
  // Eight paths per work-item in the lanes of vectors (kernels/trace_lanes.cl),
  // each work-item over a run of kLanesRun paths, for scenes of the lanes' class
  // (Impl::lanes); by default on CPUs. Medians of alternating
  // renders in one process (PoCL, 2 cores), lanes / per path: staircase 1988 /
  // 2104 ms and 2011 / 2232 (1 spp), sphere light 222 / 234, glass sphere on a
  // ground 163 / 160, McGuire's glossy Cornell box 778 / 895, water 775 / 772
  // (256x256, 16 spp); with an environment map the lanes draw its light samples
  // with their cache misses overlapped as the wavefront does (living room 1400
  // against 1408 ms for the wavefront, Sponza 214 against 246, before the lanes
  // shaded rough plastics in vectors). Scenes of thin principled materials went
  // per path before (the lanes were 3 % slower: thin principled sheets 0.899 /
  // 0.876 s at 32 spp); at fc7bcc4, whose lanes sample the sheets' sphere light
  // and constant sky in vectors, 0.49 / 0.64 s (0.50 / 0.65 without the sky).
  const bool lanes = s.lanes && o.per_path != 0 &&
                     (o.lanes > 0 || (o.lanes < 0 && rt.device().type == "CPU"));
  // The lanes write each path's contribution themselves where nothing after the
  // trace reads the states and vertices: no filter, tuple store, AOVs or
  // emission rays (kernels/trace_lanes.cl `direct`). The same image up to the
  // rounding of alpha * c; 160 bytes a path less written, and no accumulate
  // pass (Mitsuba's cbox, warm renders: 2-4 % faster; a render's first batch
  // no longer pages in the states and vertices, a quarter of a one-batch
  // render's device time there).
  const bool emission_rays = o.emission_rays > 0 && !p.camera_medium;
  const bool direct = lanes && !filtering && !o.keep_last_batch && !o.aovs && !emission_rays;
  // Where the filter (or a test) reads the tuples but nothing else of the
  // states (no emission rays, which add to them), the lanes write the tuple
  // store's values and the radiance before each vertex themselves
  // (PSF_LANES_STORE_TUPLES) for accumulate_tuples: 32 bytes a path instead
  // of the states' 96, no store_tuples pass.
  const bool tuples = lanes && !direct && !emission_rays;
  // The lanes draw their camera rays themselves (camera_rays' rays, from the
  // same samples): a camera_rays pass wrote 196 bytes per path that the lanes
  // read back, 7 % of the device time of the Cornell boxes.
  if (!lanes)
    rt.launch("camera_rays", p.batch_size, L, p, s.camera, s.sobol, states, vertices, b.rays[0], b.queue[0]);
  if (lanes) {
    // Each work-item runs 128 paths through its eight lanes: the lanes idle in
    // part once fewer than eight of its paths are left, a smaller share of
    // the work the longer the run (Mitsuba's cbox, 12 alternating renders:
    // medians 523 ms against 542 with runs of 32, 528 with 512; living room
    // 2085 against 2124 ms).
    constexpr uint32_t kLanesRun = 128;
    // Work-groups of one work-item on CPUs: PoCL runs a work-group's items as a
    // loop whose frame holds each item's private arrays (the lanes' materials
    // among them): 82 KiB of stack for eight, 12 KiB for one. Medians of
    // alternating renders, groups of 1 against 8: our Cornell box 490 against
    // 515 ms, living room 1670 and 1720 against 1733 and 1761, Mitsuba's cbox
    // 403 and 408 against 436 and 409.
    const size_t lanes_local = rt.device().type == "CPU" ? 1 : 8;
    rt.launch("trace_lanes", (p.batch_size + kLanesRun - 1) / kLanesRun, lanes_local, p, s.sobol, s.tri_pos,
              s.tri_material, s.materials, s.emitters, s.emitter_cdf, s.tri_light_pdf, s.caster->nodes(),
              s.caster->packs(), s.camera, states, vertices, s.tri_attribs, s.textures, s.texels, s.env, s.env_data,
              cl_uint(s.caster->masked() ? 1 : 0), p.batch_size, kLanesRun,
              cl_uint(direct   ? 1
                      : tuples ? 2
                               : 0),  // trace_lanes.cl PSF_LANES_STORE_*
              b.contrib_unfiltered, b.values);
  } else if (per_path) {
    rt.launch("trace_paths", p.batch_size, L, p, s.sobol, s.tri_pos, s.tri_material, s.materials, s.emitters,
              s.emitter_cdf, s.tri_light_pdf, s.env, s.env_data, s.caster->nodes(), s.caster->packs(),
              cl_uint(s.caster->masked() ? 1 : 0), b.rays[0], hits, states, vertices, shadow_rays, shadow_hits,
              s.tri_attribs, s.textures, s.texels, env_presampled, b.env_samples, p.batch_size, b.queue[0]);
  } else {
    // A compacted wavefront: each bounce launches only the paths still alive. The
    // queue holds their path indices (in any order: a path's result does not
    // depend on its slot), rays[in] their rays; shade appends the survivors to the
    // other queue. Path states and filtering vertices stay indexed by path.
    uint32_t n_live = p.batch_size;
    int in = 0;
    const uint64_t tail = o.tail_paths >= 0 ? uint64_t(o.tail_paths)
                          : rt.device().type == "GPU" ? uint64_t(b.size / 16) : 0;
    // Rounds until no path is left: shade ends each path at the maximum depth,
    // and a medium's null boundary, crossed without counting, takes a round too.
    while (n_live > 0) {
      s.caster->closest(b.rays[in], hits, n_live);
      rt.zero(alive, sizeof(uint32_t));
      if (env_presampled) {  // environment light samples ahead of shade (kernels/shade.cl)
        rt.launch("shade_env_samples", n_live, L, p, s.sobol, s.emitters, s.emitter_cdf, s.env, s.env_data, n_live,
                  b.queue[in], states, b.env_samples);
        rt.launch("shade_env_blocks", n_live, L, s.env, s.env_data, n_live, b.env_samples);
        rt.launch("shade_env_cells", n_live, L, s.env, s.env_data, n_live, b.env_samples);
        rt.launch("shade_env_texels", n_live, L, s.env, s.env_data, n_live, b.env_samples);
      }
      rt.launch("shade", n_live, L, p, s.sobol, s.tri_pos, s.tri_material, s.materials, s.emitters, s.emitter_cdf,
                s.tri_light_pdf, s.env, s.env_data, n_live, b.queue[in], hits, b.rays[in], states, vertices,
                shadow_rays, alive, b.queue[1 - in], b.rays[1 - in], s.tri_attribs, s.textures, s.texels,
                env_presampled, b.env_samples);
      if (p.null_media)  // shadow rays through null boundaries, with the media's transmittance
        rt.launch("cast_shadows_media", n_live, L, s.caster->nodes(), s.caster->packs(), n_live, b.queue[in],
                  shadow_rays, shadow_hits, states, s.tri_material, s.materials, s.tri_attribs, s.textures, s.texels);
      else
        s.caster->any(shadow_rays, shadow_hits, n_live);
      rt.launch("shade_shadows", n_live, L, n_live, b.queue[in], shadow_hits, states, vertices, p.null_media);
      rt.read(alive, &n_live, sizeof(n_live));
      in = 1 - in;
      // The last few live paths: the rest of each in one launch (trace_paths
      // over the queue) instead of a round of launches and a read of the count
      // per bounce.
      if (n_live > 0 && n_live <= tail) {
        rt.launch("trace_paths", n_live, L, p, s.sobol, s.tri_pos, s.tri_material, s.materials, s.emitters,
                  s.emitter_cdf, s.tri_light_pdf, s.env, s.env_data, s.caster->nodes(), s.caster->packs(),
                  cl_uint(s.caster->masked() ? 1 : 0), b.rays[in], hits, states, vertices, shadow_rays, shadow_hits,
                  s.tri_attribs, s.textures, s.texels, env_presampled, b.env_samples, n_live, b.queue[in]);
        break;
      }
    }
  }

  // The emission seen directly, from K + 1 camera rays per path (kernels/emission.cl):
  // ray 0 (the path's own) weighs -K / (K + 1), the others 1 / (K + 1).
  if (emission_rays) {
    const uint32_t k = uint32_t(o.emission_rays);
    rt.launch("emission_own", p.batch_size, L, p, s.camera, s.sobol, k,
              cl_uint(o.emission_recast || p.null_media ? 0 : 1), s.tri_pos, s.tri_material, s.materials, s.env,
              s.env_data, s.caster->nodes(), s.caster->packs(), cl_uint(s.caster->masked() ? 1 : 0), s.tri_attribs,
              s.textures, s.texels, states);
    const float weight = 1.0f / float(k + 1);
    for (uint32_t m = 1; m <= k; ++m) {
      rt.launch("emission_rays", p.batch_size, L, p, s.camera, s.sobol, m, k, b.rays[0]);
      s.caster->closest(b.rays[0], hits, p.batch_size);
      rt.launch("emission_add", p.batch_size, L, p, weight, s.tri_pos, s.tri_material, s.materials, s.env,
                s.env_data, s.tri_attribs, s.textures, s.texels, b.rays[0], hits, states);
    }
  }

  // Path space filtering of the batch's c_i, then each path's contribution,
  // unfiltered and (where filtered) filtered, for the host to add in path order.
  BatchImages out;
  out.index = index;
  out.first = first;
  // The tuple store for the filter (and a test's look at the last batch).
  if ((filtering || o.keep_last_batch) && !tuples)
    rt.launch("store_tuples", p.batch_size, L, p.batch_size, states, b.values);
  const float visibility_ray = this->visibility_ray(o.filter.visibility_ray);
  if (filtering && visibility_ray > 0.0f) {
    // Each vertex's visibility from one hemisphere ray instead of its light
    // sample (kernels/visibility.cl); the camera rays' buffer is free by now.
    rt.launch("visibility_rays", p.batch_size, L, p, visibility_ray, vertices, b.rays[0]);
    if (p.null_media)  // through null boundaries, as light samples go
      rt.launch("visibility_cast_media", p.batch_size, L, s.caster->nodes(), s.caster->packs(), p.batch_size,
                b.rays[0], shadow_hits, s.tri_material, s.materials, s.tri_attribs, s.textures, s.texels);
    else
      s.caster->any(b.rays[0], shadow_hits, p.batch_size);
    rt.launch("visibility_store", p.batch_size, L, p.batch_size, shadow_hits, vertices);
  }
  if (filtering) {
    FilterParams fp{};
    // An orthographic camera's pixels have one world-space size: the footprint
    // is then a global r0 (unless --r0 gives one).
    fp.r0 = o.filter.r0 > 0.0f || !impl_->camera.orthographic ? o.filter.r0 : b.footprint;
    fp.footprint = b.footprint;
    // n: paths per pixel so far, so r0 is the radius of the first pass.
    double n = std::max(1.0, double(first + p.batch_size) / double(pixels));
    fp.n_scale = float(std::pow(n, -double(o.filter.alpha)));
    fp.normal_cos = o.filter.normal_cos;
    fp.albedo_tol = o.filter.demodulate ? o.filter.albedo_log2_tol : o.filter.albedo_tol;
    fp.demodulate = o.filter.demodulate ? 1u : 0u;
    fp.count = p.batch_size;
    fp.cells27 = o.filter.cells27 ? 1u : 0u;
    fp.stretch = o.filter.foreshortening && !(o.filter.r0 > 0.0f) ? 1u : 0u;
    fp.ignore_visibility = o.filter.visibility_ray == kVisibilityRayOff ? 1u : 0u;
    out.max_count = b.filter->run(fp, o.filter.iterations, vertices, b.values, b.filtered, b.counts);
    out.params = fp;
  }
  if (tuples)
    rt.launch("accumulate_tuples", p.batch_size, L, p.batch_size, cl_uint(filtering ? 1 : 0), vertices, b.values,
              b.filtered, b.counts, b.contrib_unfiltered, b.contrib);
  else if (!direct)
    rt.launch("accumulate", p.batch_size, L, p.batch_size, cl_uint(filtering ? 1 : 0), states, vertices,
              b.filtered, b.counts, b.contrib_unfiltered, b.contrib);
  rt.finish();
  const auto t1 = std::chrono::steady_clock::now();
  out.trace_seconds = std::chrono::duration<double>(t1 - t0).count();
  if (filtering) out.filtered = b.download(rt, b.contrib, p.batch_size);
  out.unfiltered = b.download(rt, b.contrib_unfiltered, p.batch_size);
  if (o.aovs) out.vertices = rt.download<PathVertex>(vertices, p.batch_size);
  rt.finish();
  out.download_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
  return out;
}

void Renderer::recycle(BatchImages&& done) {
  if (!batch_) return;
  std::lock_guard<std::mutex> lock(batch_->spare_mu);
  for (auto* v : {&done.filtered, &done.unfiltered})
    if (v->capacity() >= batch_->capacity && batch_->spare.size() < 8) batch_->spare.push_back(std::move(*v));
}

RenderResult Renderer::render(const RenderOptions& o) {
  Runtime& rt = impl_->rt;
  const Scene& scene = impl_->scene;
  const uint64_t pixels = uint64_t(scene.width) * scene.height;
  const uint64_t total = pixels * uint64_t(std::max(o.spp, 0));
  bool filtering = o.filter.enabled;
  const int batch_log2 = o.batch_log2 > 0 ? o.batch_log2 : default_batch_log2(pixels);
  BatchPlan plan = plan_batch(batch_needs(filtering, o.aovs, o.filter.iterations), fixed_bytes(), rt.device().global_mem,
                              rt.device().max_alloc, 0, batch_log2, std::min(batch_log2, 6));
  prepare(o, plan.log2, total);
  RenderResult r;
  Accumulator acc;
  acc.reset(scene.width, scene.height, o.aovs);
  auto t0 = std::chrono::steady_clock::now();
  const uint64_t batches = (total + batch_size() - 1) / batch_size();
  NoiseMonitor monitor;
  // The estimate decides for the batches after the one it is made for: a render
  // of one batch needs none.
  const bool monitoring = filtering && o.filter.min_removed > 0.0f && batches > 1;
  if (monitoring) monitor.reset(pixels);
  for (uint64_t index = 0; index < batches; ++index) {
    BatchImages b = trace_batch(index, total, filtering);
    const auto added = std::chrono::steady_clock::now();
    r.trace_seconds += b.trace_seconds;
    r.download_seconds += b.download_seconds;
    acc.add(b);
    const double removed = monitoring && filtering && index + 1 < batches ? monitor.add(b) : std::nan("");
    r.add_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - added).count();
    if (filtering && (b.max_count <= 1 || removed < o.filter.min_removed)) {
      filtering = false;
      r.filter_off_after = acc.paths;
      r.filter_removed = removed;
    }
    if (o.keep_last_batch && index + 1 == batches) {
      r.last_batch.params = b.params;
      r.last_batch.vertices = rt.download<PathVertex>(batch_->vertices, b.unfiltered.size());
      r.last_batch.values = rt.download<cl_float4>(batch_->values, b.unfiltered.size());
    }
    recycle(std::move(b));
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.paths = total;
  r.batch_size = batch_size();
  r.image = acc.image();
  r.unfiltered = acc.unfiltered_image();
  r.neighbours = acc.neighbours();
  r.nonfinite = acc.nonfinite();
  return r;
}

}  // namespace psf
