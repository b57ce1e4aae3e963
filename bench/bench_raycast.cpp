// bench_raycast: closest-hit ray casting throughput of kernels/raycast.cl on
// incoherent diffuse rays (and any-hit on shadow rays, psf_any), against
// Embree 3 on the same rays with as many threads as the OpenCL device has
// compute units (every core when it is a GPU), twice:
// embree_raycast, one ray at a time (rtcIntersect1) through Embree's default
// (medium-quality) BVH; embree16_raycast, Embree as Mitsuba 3.6.4's llvm_ad_rgb
// runs it on an AVX-512 machine (`perf` of its renders: the spatial-split
// builder, Embree's high quality, and the hybrid traversal of packets of 16):
// RTC_BUILD_QUALITY_HIGH and rtcIntersect16 on 16 consecutive rays. The rays
// are incoherent either way. psf's BVH is the renderer's, with spatial splits
// (--spatial_splits=0: without); each scene's line gives its references.
//
// Rays: 2^21 (--rays_log2) area-uniform points on the scene's triangles, offset
// along the geometric normal by 1e-5 of the scene's bounding-box diagonal, with
// cosine-distributed directions about that normal; tmin 0, tmax infinity; fixed seed.
// After timing, a scalar host replica of the closest-hit traversal counts the
// wide nodes, leaves and triangle packs each ray visits (traversal_stats).
// Before timing, each scene's line gives its BVH's surface area heuristic in the
// terms of Embree's build statistics (sah_cost), which --embree_config=verbose=3
// makes Embree print for its own BVHs ("getAABBNodes" and "leaves": a leaf's
// blocks hold up to 4 triangles, psf's packs PSF_BVH_WIDTH).
// Timing: one warm-up launch, then --trials launches; the device time of each
// comes from its OpenCL profiling event (Runtime::stats), the wall time from a
// steady clock around enqueue + finish. Reported: min and median of both, Mrays/s
// of the median device time, and after timing the agreement of the hit triangles
// with Embree's. The ratios to Embree come twice: of the medians of each
// benchmark's own trials, and paired: each psf trial runs right after one pass
// of each Embree configuration (their scenes kept from their benchmarks), and
// the median of the trials' ratios is reported with their range, so that the
// machine's drift between benchmarks does not enter the ratio.
// psf_any/<scene>: shadow rays (any hit): segments between two sets of 2^21
// surface points (shadow_rays), psf's raycast_any paired trial by trial with
// Embree's rtcOccluded1 (default build) and rtcOccluded16 (high-quality build),
// their occlusion checked against rtcOccluded1's.
//
// Usage: bench_raycast [benchmark flags] [--scene=PATH ...] [--local=N] [--rays_log2=N]
//                      [--trials=N] [--embree_config=STRING] [--spatial_splits=0|1]
// Without --scene: scenes/cornell-box.xml of the source tree, Dabrovic Sponza and
// Bitterli's living room from $PSF_SHARED (else ../shared beside the source tree);
// absent ones are skipped.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdarg>
#include <cstring>
#include <memory>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <thread>
#include <vector>

#ifdef PSF_HAVE_EMBREE
#include <embree3/rtcore.h>
#endif

#include "bench_common.h"
#include "bvh.h"
#include "cl/runtime.h"
#include "scene/scene.h"

namespace {

namespace fs = std::filesystem;

struct Options {
  std::vector<std::string> scenes;  // scene files; empty: the defaults
  size_t local = 64;                // work-group size of the launches
  int rays_log2 = 21;               // 2^rays_log2 rays per scene
  int trials = 7;                   // timed launches per scene
  std::string embree_config;        // rtcNewDevice's configuration string ("verbose=3": its BVH statistics)
  bool spatial_splits = true;       // psf's BVH with spatial splits (BvhParams), as the renderer builds it
};

using bench::summarize;
using bench::Timing;

struct Embree;

// A scene prepared for the benchmark: geometry, BVH and rays, and the results.
struct Bench {
  std::string name;                  // short name for the benchmark
  std::string path;                  // scene file
  std::vector<glm::vec3> positions;  // geometry
  std::vector<glm::uvec3> triangles;
  psf::Bvh bvh;                      // the wide BVH
  std::vector<Ray> rays;             // the incoherent rays
  std::vector<Ray> shadow;           // segments between two surface points (shadow_rays)
  std::vector<Hit> psf_hits;         // after timing, for the comparison
  std::vector<uint32_t> embree_prims;
  double embree_build_ms = 0;
  Timing embree;                     // wall time of one pass over all rays
  Timing embree16;                   // the same, high-quality build and packets of 16
  std::shared_ptr<Embree> embree1_scene, embree16_scene;  // kept for psf's paired trials
};

// Area-uniform surface points with cosine-distributed directions about the
// geometric normal (Pharr et al., PBR 4th ed., 13.6.3 cosine-weighted hemisphere).
std::vector<Ray> diffuse_rays(const std::vector<glm::vec3>& p, const std::vector<glm::uvec3>& tris, size_t count,
                              uint32_t seed) {
  std::vector<double> cdf;
  cdf.reserve(tris.size());
  double total = 0;
  glm::vec3 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
  for (const auto& t : tris) {
    glm::vec3 a = p[t.x], b = p[t.y], c = p[t.z];
    double area = 0.5 * glm::length(glm::cross(glm::dvec3(b - a), glm::dvec3(c - a)));
    total += std::isfinite(area) ? area : 0.0;
    cdf.push_back(total);
    lo = glm::min(lo, glm::min(a, glm::min(b, c)));
    hi = glm::max(hi, glm::max(a, glm::max(b, c)));
  }
  std::vector<Ray> rays;
  if (total <= 0) return rays;
  const float offset = 1e-5f * glm::length(hi - lo);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  rays.reserve(count);
  while (rays.size() < count) {
    size_t t = std::upper_bound(cdf.begin(), cdf.end(), u01(rng) * total) - cdf.begin();
    if (t >= tris.size()) continue;
    glm::vec3 a = p[tris[t].x], b = p[tris[t].y], c = p[tris[t].z];
    glm::vec3 n = glm::cross(b - a, c - a);
    if (!(glm::length(n) > 0)) continue;
    n = glm::normalize(n);
    double su = std::sqrt(u01(rng)), v = u01(rng);
    glm::vec3 x = a + float(su * (1 - v)) * (b - a) + float(su * v) * (c - a);
    // An orthonormal basis about n (Duff et al., JCGT 2017).
    float sign = std::copysign(1.0f, n.z);
    float q = -1.0f / (sign + n.z);
    float w = n.x * n.y * q;
    glm::vec3 tx(1.0f + sign * n.x * n.x * q, sign * w, -sign * n.x);
    glm::vec3 ty(w, sign + n.y * n.y * q, -n.y);
    double r2 = u01(rng), phi = 2 * M_PI * u01(rng);
    double r = std::sqrt(r2);
    glm::vec3 d = float(r * std::cos(phi)) * tx + float(r * std::sin(phi)) * ty + float(std::sqrt(1 - r2)) * n;
    glm::vec3 o = x + offset * n;
    Ray ray;
    ray.org = {{o.x, o.y, o.z, 0.0f}};
    ray.dir = {{d.x, d.y, d.z, std::numeric_limits<float>::infinity()}};
    rays.push_back(ray);
  }
  return rays;
}

// Shadow rays: from each ray's origin in `from` to the origin of the ray of the
// same index in `to` (another set of surface points, off their surfaces like
// these), tmin 0 and tmax 0.999 in units of the unnormalized direction: the
// segments of next-event estimation towards points on area lights.
std::vector<Ray> shadow_rays(const std::vector<Ray>& from, const std::vector<Ray>& to) {
  std::vector<Ray> rays(std::min(from.size(), to.size()));
  for (size_t i = 0; i < rays.size(); ++i) {
    rays[i].org = {{from[i].org.s[0], from[i].org.s[1], from[i].org.s[2], 0.0f}};
    rays[i].dir = {{to[i].org.s[0] - from[i].org.s[0], to[i].org.s[1] - from[i].org.s[1],
                    to[i].org.s[2] - from[i].org.s[2], 0.999f}};
  }
  return rays;
}

#ifdef PSF_HAVE_EMBREE
struct Embree {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  bool packets = false;  // rtcIntersect16 instead of rtcIntersect1

  // packets16: Mitsuba 3's configuration (RTC_BUILD_QUALITY_HIGH, packets of 16).
  Embree(const Bench& b, bool packets16, const std::string& config) : packets(packets16) {
    device = rtcNewDevice(config.empty() ? nullptr : config.c_str());
    auto t0 = std::chrono::steady_clock::now();
    scene = rtcNewScene(device);
    if (packets16) rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    if (packets16) rtcSetGeometryBuildQuality(geom, RTC_BUILD_QUALITY_HIGH);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                          3 * sizeof(float), b.positions.size()));
    for (size_t i = 0; i < b.positions.size(); ++i)
      for (int k = 0; k < 3; ++k) v[3 * i + k] = b.positions[i][k];
    auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                               3 * sizeof(uint32_t), b.triangles.size()));
    for (size_t i = 0; i < b.triangles.size(); ++i)
      for (int k = 0; k < 3; ++k) idx[3 * i + k] = b.triangles[i][k];
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(scene);
    build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  }
  ~Embree() {
    rtcReleaseScene(scene);
    rtcReleaseDevice(device);
  }

  // psf's ray as Embree's, one ray or lane k of a packet of 16.
  static void set_ray(RTCRay& ray, const Ray& r) {
    ray.org_x = r.org.s[0];
    ray.org_y = r.org.s[1];
    ray.org_z = r.org.s[2];
    ray.tnear = r.org.s[3];
    ray.dir_x = r.dir.s[0];
    ray.dir_y = r.dir.s[1];
    ray.dir_z = r.dir.s[2];
    ray.tfar = r.dir.s[3];
    ray.time = 0.0f;
    ray.mask = 0xFFFFFFFFu;
    ray.id = 0;
    ray.flags = 0;
  }
  static void set_ray(RTCRay16& ray, int k, const Ray& r) {
    ray.org_x[k] = r.org.s[0];
    ray.org_y[k] = r.org.s[1];
    ray.org_z[k] = r.org.s[2];
    ray.tnear[k] = r.org.s[3];
    ray.dir_x[k] = r.dir.s[0];
    ray.dir_y[k] = r.dir.s[1];
    ray.dir_z[k] = r.dir.s[2];
    ray.tfar[k] = r.dir.s[3];
    ray.time[k] = 0.0f;
    ray.mask[k] = 0xFFFFFFFFu;
    ray.id[k] = 0;
    ray.flags[k] = 0;
  }
  // Packet i0's 16 rays from [i0, end) (the rays past end repeat the last, invalid).
  static void set_packet(RTCRay16& ray, int* valid, const std::vector<Ray>& rays, size_t i0, size_t end) {
    for (int k = 0; k < 16; ++k) {
      valid[k] = i0 + k < end ? -1 : 0;
      set_ray(ray, k, rays[std::min(i0 + k, end - 1)]);
    }
  }
  // f(begin, end) over `threads` contiguous chunks of [0, n), one thread each.
  template <typename F>
  static void in_chunks(size_t n, unsigned threads, F f) {
    std::vector<std::thread> pool;
    const size_t chunk = (n + threads - 1) / threads;
    for (unsigned t = 0; t < threads; ++t) {
      const size_t begin = std::min(n, t * chunk), end = std::min(n, begin + chunk);
      pool.emplace_back([&f, begin, end] { f(begin, end); });
    }
    for (auto& th : pool) th.join();
  }

  // Closest hits of rays [begin, end): the hit triangle or PSF_NO_HIT; one at a
  // time, or in packets of 16 consecutive rays (the last one partly valid).
  void trace(const std::vector<Ray>& rays, size_t begin, size_t end, uint32_t* prims) const {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    if (!packets) {
      for (size_t i = begin; i < end; ++i) {
        RTCRayHit rh;
        set_ray(rh.ray, rays[i]);
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(scene, &ctx, &rh);
        prims[i] = rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? PSF_NO_HIT : rh.hit.primID;
      }
      return;
    }
    for (size_t i0 = begin; i0 < end; i0 += 16) {
      alignas(64) RTCRayHit16 rh;
      alignas(64) int valid[16];
      set_packet(rh.ray, valid, rays, i0, end);
      for (int k = 0; k < 16; ++k) rh.hit.geomID[k] = rh.hit.primID[k] = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect16(valid, scene, &ctx, &rh);
      for (int k = 0; k < 16 && i0 + k < end; ++k)
        prims[i0 + k] = rh.hit.geomID[k] == RTC_INVALID_GEOMETRY_ID ? PSF_NO_HIT : rh.hit.primID[k];
    }
  }

  // All rays on `threads` threads, each a contiguous chunk.
  void trace_all(const std::vector<Ray>& rays, unsigned threads, std::vector<uint32_t>& prims) const {
    prims.resize(rays.size());
    in_chunks(rays.size(), threads, [&](size_t begin, size_t end) { trace(rays, begin, end, prims.data()); });
  }

  // Occlusion of rays [begin, end): 1 where something lies within (tnear, tfar)
  // (Embree sets tfar to -inf on a hit).
  void occlude(const std::vector<Ray>& rays, size_t begin, size_t end, uint8_t* out) const {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    if (!packets) {
      for (size_t i = begin; i < end; ++i) {
        RTCRay ray;
        set_ray(ray, rays[i]);
        rtcOccluded1(scene, &ctx, &ray);
        out[i] = ray.tfar < 0.0f ? 1 : 0;
      }
      return;
    }
    for (size_t i0 = begin; i0 < end; i0 += 16) {
      alignas(64) RTCRay16 ray;
      alignas(64) int valid[16];
      set_packet(ray, valid, rays, i0, end);
      rtcOccluded16(valid, scene, &ctx, &ray);
      for (int k = 0; k < 16 && i0 + k < end; ++k) out[i0 + k] = ray.tfar[k] < 0.0f ? 1 : 0;
    }
  }
  void occlude_all(const std::vector<Ray>& rays, unsigned threads, std::vector<uint8_t>& out) const {
    out.resize(rays.size());
    in_chunks(rays.size(), threads, [&](size_t begin, size_t end) { occlude(rays, begin, end, out.data()); });
  }

  double build_ms = 0;
};
#endif

// A scene of the shared data: $PSF_SHARED, else ../shared beside the source tree.
std::string shared_path(const char* relative) {
  if (const char* env = std::getenv("PSF_SHARED"); env && *env) return (fs::path(env) / relative).string();
  return (fs::path(PSF_SOURCE_DIR) / "../shared" / relative).string();
}

std::string scene_name(const std::string& path) {
  fs::path p(path);
  std::string stem = p.stem().string();
  if (stem == "scene" || stem == "sponza") stem = p.parent_path().filename().string();
  return stem;
}

// Traversal statistics of psf's BVH (a scalar host replica of raycast.cl's
// closest-hit traversal: its slab test and near-first order and culling, and
// Moller-Trumbore with a fixed 1e-6 tolerance where the kernel's grows with
// distance): wide nodes visited and triangle packs tested
// per ray, for comparing BVH builds by the work a ray does rather than by time.
struct TraversalStats {
  double nodes = 0, packs = 0, leaves = 0;  // per ray
  size_t agree = 0;                         // rays whose hit triangle equals `hits`'
};

TraversalStats traversal_stats(const psf::Bvh& bvh, const std::vector<Ray>& rays, const std::vector<Hit>& hits) {
  TraversalStats st;
  uint64_t nodes = 0, packs = 0, leaves = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Ray& r = rays[i];
    const glm::vec3 o(r.org.s[0], r.org.s[1], r.org.s[2]), d(r.dir.s[0], r.dir.s[1], r.dir.s[2]);
    glm::vec3 inv;
    for (int k = 0; k < 3; ++k) inv[k] = 1.0f / (std::fabs(d[k]) < 1e-12f ? std::copysign(1e-12f, d[k]) : d[k]);
    float tmin = r.org.s[3], tmax = r.dir.s[3];
    uint32_t prim = PSF_NO_HIT;
    std::vector<std::pair<float, uint32_t>> stack;  // (entry distance, child reference)
    std::vector<std::pair<float, uint32_t>> hit;    // a node's children hit, reused
    stack.push_back({tmin, 0u});
    while (!stack.empty()) {
      auto [tn, ref] = stack.back();
      stack.pop_back();
      if (tn > tmax) continue;
      if (ref & PSF_LEAF_BIT) {
        ++leaves;
        const uint32_t first = psf::leaf_first(ref), count = psf::leaf_count(ref);
        for (uint32_t k = first; k < first + count; ++k) {
          ++packs;
          const BvhTriPack& p = bvh.packs[k];
          for (int l = 0; l < PSF_BVH_WIDTH; ++l) {
            if (p.prim[l] == PSF_NO_HIT) continue;
            glm::vec3 v0(p.v0_x[l], p.v0_y[l], p.v0_z[l]), e1(p.e1_x[l], p.e1_y[l], p.e1_z[l]),
                e2(p.e2_x[l], p.e2_y[l], p.e2_z[l]);
            glm::vec3 pv = glm::cross(d, e2);
            float det = glm::dot(e1, pv);
            if (det == 0.0f) continue;
            float inv_det = 1.0f / det;
            glm::vec3 s = o - v0;
            float u = glm::dot(s, pv) * inv_det;
            glm::vec3 q = glm::cross(s, e1);
            float v = glm::dot(d, q) * inv_det, t = glm::dot(e2, q) * inv_det;
            if (u >= -1e-6f && v >= -1e-6f && u + v <= 1.0f + 1e-6f && t > tmin && t < tmax) {
              tmax = t;
              prim = p.prim[l] & ~(PSF_PRIM_MASKED | PSF_PRIM_SPHERE);
            }
          }
        }
        continue;
      }
      ++nodes;
      const BvhNode& n = bvh.nodes[ref];
      hit.clear();
      for (int c = 0; c < PSF_BVH_WIDTH; ++c) {
        if (n.child[c] == PSF_EMPTY_CHILD) continue;
        float t0 = tmin, t1 = tmax;
        const float lo[3] = {n.min_x[c], n.min_y[c], n.min_z[c]}, hi[3] = {n.max_x[c], n.max_y[c], n.max_z[c]};
        for (int k = 0; k < 3; ++k) {
          float a = (lo[k] - o[k]) * inv[k], b = (hi[k] - o[k]) * inv[k];
          t0 = std::max(t0, std::min(a, b));
          t1 = std::min(t1, std::max(a, b));
        }
        if (t0 <= t1 * 1.0000004f) hit.push_back({t0, n.child[c]});
      }
      std::sort(hit.begin(), hit.end(), [](auto& a, auto& b) { return a.first > b.first; });
      for (auto& h : hit) stack.push_back(h);
    }
    st.agree += i < hits.size() && hits[i].prim == prim;
  }
  st.nodes = double(nodes) / rays.size();
  st.packs = double(packs) / rays.size();
  st.leaves = double(leaves) / rays.size();
  return st;
}

// The BVH's surface area heuristic as Embree's statistics state it (its verbose
// build output): for a random line through the root's box, the expected number
// of wide nodes tested (each node's box area over the root's, the root 1) and of
// packs tested (each leaf's area times its packs), and of triangles in them.
struct SahCost {
  double nodes = 0, packs = 0, triangles = 0;
};

SahCost sah_cost(const psf::Bvh& bvh) {
  auto half_area = [](const BvhNode& n, int c) {
    const float dx = n.max_x[c] - n.min_x[c], dy = n.max_y[c] - n.min_y[c], dz = n.max_z[c] - n.min_z[c];
    return double(dx) * dy + double(dy) * dz + double(dz) * dx;
  };
  SahCost cost;
  const BvhNode& root = bvh.nodes[0];
  BvhNode box{};  // the root's bounds, as a one-child node
  box.min_x[0] = box.min_y[0] = box.min_z[0] = std::numeric_limits<float>::infinity();
  box.max_x[0] = box.max_y[0] = box.max_z[0] = -std::numeric_limits<float>::infinity();
  for (int c = 0; c < PSF_BVH_WIDTH; ++c) {
    if (root.child[c] == PSF_EMPTY_CHILD) continue;
    box.min_x[0] = std::min(box.min_x[0], root.min_x[c]);
    box.min_y[0] = std::min(box.min_y[0], root.min_y[c]);
    box.min_z[0] = std::min(box.min_z[0], root.min_z[c]);
    box.max_x[0] = std::max(box.max_x[0], root.max_x[c]);
    box.max_y[0] = std::max(box.max_y[0], root.max_y[c]);
    box.max_z[0] = std::max(box.max_z[0], root.max_z[c]);
  }
  const double root_area = half_area(box, 0);
  if (!(root_area > 0.0)) return cost;
  cost.nodes = 1.0;
  for (const BvhNode& n : bvh.nodes)
    for (int c = 0; c < PSF_BVH_WIDTH; ++c) {
      const uint32_t child = n.child[c];
      if (child == PSF_EMPTY_CHILD) continue;
      const double p = half_area(n, c) / root_area;
      if (!psf::is_leaf(child)) {
        cost.nodes += p;
        continue;
      }
      const uint32_t first = psf::leaf_first(child), count = psf::leaf_count(child);
      cost.packs += p * count;
      for (uint32_t k = first; k < first + count; ++k)
        for (int l = 0; l < PSF_BVH_WIDTH; ++l) cost.triangles += p * (bvh.packs[k].prim[l] != PSF_NO_HIT);
    }
  return cost;
}

// The median of paired trials' ratios (0 without trials), and their range as text.
double paired_median(const std::vector<double>& r) { return r.empty() ? 0.0 : summarize(r).median_s; }
std::string paired_range(const std::vector<double>& r) {
  if (r.empty()) return "-";
  const auto [lo, hi] = std::minmax_element(r.begin(), r.end());
  char text[32];
  std::snprintf(text, sizeof text, "%.2f-%.2f", *lo, *hi);
  return text;
}

void report(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
void report(const char* fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  std::vfprintf(stderr, fmt, ap);
  va_end(ap);
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  Options opt;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto value = [&](const char* key) -> const char* {
      size_t n = std::strlen(key);
      return a.compare(0, n, key) == 0 ? a.c_str() + n : nullptr;
    };
    if (const char* v = value("--scene=")) {
      opt.scenes.push_back(v);
    } else if (const char* v = value("--local=")) {
      opt.local = bench::number<size_t>("bench_raycast", "local", v);
    } else if (const char* v = value("--rays_log2=")) {
      opt.rays_log2 = bench::number<int>("bench_raycast", "rays_log2", v);
    } else if (const char* v = value("--trials=")) {
      opt.trials = std::max(1, bench::number<int>("bench_raycast", "trials", v));
    } else if (const char* v = value("--embree_config=")) {
      opt.embree_config = v;
    } else if (const char* v = value("--spatial_splits=")) {
      opt.spatial_splits = bench::number<int>("bench_raycast", "spatial_splits", v) != 0;
    } else {
      std::fprintf(stderr, "bench_raycast: unknown argument '%s'\n", a.c_str());
      return 2;
    }
  }
  if (opt.scenes.empty()) {
    opt.scenes.push_back((fs::path(PSF_SOURCE_DIR) / "scenes/cornell-box.xml").string());
    opt.scenes.push_back(shared_path("scenes/sponza-dabrovic/sponza.obj"));
    opt.scenes.push_back(shared_path("scenes/living-room/scene.xml"));
  }

  psf::DeviceInfo dev = psf::choose_device(std::getenv("PSF_DEVICE") ? std::getenv("PSF_DEVICE") : "");
  psf::Runtime rt(dev);
  const std::string build_options = "-cl-std=CL1.2 -DPSF_BVH_WIDTH=" + std::to_string(PSF_BVH_WIDTH);
  const unsigned threads = bench::peer_threads(dev);
  const size_t num_rays = size_t(1) << opt.rays_log2;
  benchmark::AddCustomContext("psf_device", dev.platform + " / " + dev.name);
  benchmark::AddCustomContext("psf_driver", dev.driver + " (" + dev.version + ")");
  benchmark::AddCustomContext("psf_build_options", build_options);
  benchmark::AddCustomContext("psf_spatial_splits", opt.spatial_splits ? "on" : "off");
  benchmark::AddCustomContext("psf_compute_units", std::to_string(dev.compute_units));
  benchmark::AddCustomContext("psf_rays", std::to_string(num_rays));
  benchmark::AddCustomContext("psf_local_size", std::to_string(opt.local));
  report("device: %s / %s, driver %s, %s, %u compute units\n", dev.platform.c_str(), dev.name.c_str(),
         dev.driver.c_str(), dev.version.c_str(), dev.compute_units);
  report("build options: %s; rays: %zu; local size: %zu; trials: %d\n", build_options.c_str(), num_rays, opt.local,
         opt.trials);

  std::vector<std::unique_ptr<Bench>> benches;
  for (const std::string& path : opt.scenes) {
    if (!fs::exists(path)) {
      report("skipped %s: not found\n", path.c_str());
      continue;
    }
    auto b = std::make_unique<Bench>();
    b->path = path;
    b->name = scene_name(path);
    try {
      psf::Scene scene = psf::load_scene(path);
      b->positions = std::move(scene.positions);
      b->triangles = std::move(scene.triangles);
    } catch (const std::exception& e) {
      report("skipped %s: %s\n", path.c_str(), e.what());
      continue;
    }
    psf::BvhParams bvh_params;
    bvh_params.spatial_splits = opt.spatial_splits;
    b->bvh = psf::build_bvh(b->positions, b->triangles, bvh_params);
    b->rays = diffuse_rays(b->positions, b->triangles, num_rays, 1234567u);
    b->shadow = shadow_rays(b->rays, diffuse_rays(b->positions, b->triangles, num_rays, 7654321u));
    report(
        "%s: %zu triangles, BVH build %.1f ms (spatial splits %s: %u references, +%.1f %%), %zu nodes and %zu "
        "triangle packs (%.1f MiB), depth %d, %u triangles left out\n",
        b->name.c_str(), b->triangles.size(), b->bvh.build_ms, opt.spatial_splits ? "on" : "off", b->bvh.references,
        100.0 * (double(b->bvh.references) / std::max(1u, b->bvh.triangle_count) - 1.0), b->bvh.nodes.size(),
        b->bvh.packs.size(),
        (b->bvh.nodes.size() * sizeof(BvhNode) + b->bvh.packs.size() * sizeof(BvhTriPack)) / 1048576.0, b->bvh.depth,
        b->bvh.skipped);
    const SahCost sah = sah_cost(b->bvh);
    report("%s: SAH of a random line through the root's box (Embree's statistics): %.2f nodes, %.2f packs, %.1f "
           "triangles\n",
           b->name.c_str(), sah.nodes, sah.packs, sah.triangles);
    if (b->rays.empty()) {
      report("skipped %s: no surface to start rays from\n", path.c_str());
      continue;
    }
    benches.push_back(std::move(b));
  }

  for (auto& bp : benches) {
    Bench* b = bp.get();
#ifdef PSF_HAVE_EMBREE
    // Embree first, so the psf benchmark can report the ratios and the agreement.
    for (bool packets : {false, true}) {
      const std::string bench_name = std::string(packets ? "embree16_raycast/" : "embree_raycast/") + b->name;
      benchmark::RegisterBenchmark(bench_name.c_str(), [b, threads, packets, &opt](benchmark::State& state) {
        auto scene = std::make_shared<Embree>(*b, packets, opt.embree_config);
        (packets ? b->embree16_scene : b->embree1_scene) = scene;
        const Embree& e = *scene;
        if (!packets) b->embree_build_ms = e.build_ms;
        std::vector<uint32_t> packet_prims;
        std::vector<uint32_t>& prims = packets ? packet_prims : b->embree_prims;
        std::vector<double> wall;
        e.trace_all(b->rays, threads, prims);  // warm-up
        for (auto _ : state) {
          auto t0 = std::chrono::steady_clock::now();
          e.trace_all(b->rays, threads, prims);
          double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          state.SetIterationTime(s);
          wall.push_back(s);
        }
        Timing& t = packets ? b->embree16 : b->embree;
        t = summarize(wall);
        state.counters["Mrays_per_s"] = b->rays.size() / t.median_s * 1e-6;
        state.counters["Mrays_per_s_best"] = b->rays.size() / t.min_s * 1e-6;
        state.counters["build_ms"] = e.build_ms;
        state.counters["threads"] = threads;
        std::string agreement;
        if (packets && b->embree_prims.size() == prims.size()) {
          size_t agree = 0;
          for (size_t i = 0; i < prims.size(); ++i) agree += prims[i] == b->embree_prims[i];
          state.counters["agreement_embree1"] = double(agree) / prims.size();
          agreement = "; hit triangles agree with rtcIntersect1's for " +
                      std::to_string(100.0 * agree / prims.size()) + "% of rays";
        }
        report("%s: embree%s %u threads: build %.1f ms, %.2f Mrays/s (median %.1f ms, min %.1f ms)%s\n",
               b->name.c_str(), packets ? " (high-quality build, packets of 16)" : "", threads, e.build_ms,
               b->rays.size() / t.median_s * 1e-6, t.median_s * 1e3, t.min_s * 1e3, agreement.c_str());
      })->UseManualTime()->Iterations(opt.trials)->Unit(benchmark::kMillisecond);
    }
#endif
    benchmark::RegisterBenchmark(("psf_raycast/" + b->name).c_str(), [b, &rt, &opt, threads](benchmark::State& state) {
      psf::RayCaster caster(rt, b->bvh);
      caster.local_size = opt.local;
      const uint32_t n = static_cast<uint32_t>(b->rays.size());
      cl::Buffer rays = rt.upload(b->rays);
      cl::Buffer hits = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(Hit));
      caster.closest(rays, hits, n);  // warm-up: first launch with this local size
      rt.finish();
      std::vector<double> device, wall, paired1, paired16;
      for (auto _ : state) {
#ifdef PSF_HAVE_EMBREE
        // Each trial right after a pass of each Embree configuration, so that
        // the machine's drift falls on both sides of a trial's ratios.
        double e1 = 0.0, e16 = 0.0;
        {
          std::vector<uint32_t> scratch;
          auto timed = [&](const std::shared_ptr<Embree>& e) {
            if (!e) return 0.0;
            auto s0 = std::chrono::steady_clock::now();
            e->trace_all(b->rays, threads, scratch);
            return std::chrono::duration<double>(std::chrono::steady_clock::now() - s0).count();
          };
          e1 = timed(b->embree1_scene);
          e16 = timed(b->embree16_scene);
        }
#endif
        rt.reset_stats();
        auto t0 = std::chrono::steady_clock::now();
        caster.closest(rays, hits, n);
        rt.finish();
        double w = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        double d = rt.stats().at("raycast_closest").ms * 1e-3;
        state.SetIterationTime(d);
        device.push_back(d);
        wall.push_back(w);
#ifdef PSF_HAVE_EMBREE
        if (e1 > 0.0) paired1.push_back(e1 / d);
        if (e16 > 0.0) paired16.push_back(e16 / d);
#endif
      }
      Timing dt = summarize(device), wt = summarize(wall);
      // Check the output after timing: NaN-free, and against Embree where present.
      b->psf_hits = rt.download<Hit>(hits, n);
      size_t nan = 0, hit = 0;
      for (const Hit& h : b->psf_hits) {
        nan += std::isnan(h.t) || std::isnan(h.u) || std::isnan(h.v);
        hit += h.prim != PSF_NO_HIT;
      }
      double mrays = n / dt.median_s * 1e-6;
      state.counters["Mrays_per_s"] = mrays;
      state.counters["Mrays_per_s_best"] = n / dt.min_s * 1e-6;
      state.counters["wall_ms_median"] = wt.median_s * 1e3;
      state.counters["wall_ms_min"] = wt.min_s * 1e3;
      state.counters["build_ms"] = b->bvh.build_ms;
      state.counters["hit_fraction"] = double(hit) / n;
      state.counters["local_size"] = double(opt.local);
      report("%s: psf W=%d local %zu: build %.1f ms, %.2f Mrays/s (device median %.1f ms, min %.1f ms; wall median "
             "%.1f ms, min %.1f ms), %.1f%% hit\n",
             b->name.c_str(), PSF_BVH_WIDTH, opt.local, b->bvh.build_ms, mrays, dt.median_s * 1e3, dt.min_s * 1e3,
             wt.median_s * 1e3, wt.min_s * 1e3, 100.0 * hit / n);
      if (nan) state.SkipWithError("NaN in the hits");
      {
        TraversalStats ts = traversal_stats(b->bvh, b->rays, b->psf_hits);
        state.counters["nodes_per_ray"] = ts.nodes;
        state.counters["packs_per_ray"] = ts.packs;
        state.counters["leaves_per_ray"] = ts.leaves;
        report("%s: per ray %.2f wide nodes, %.2f leaves, %.2f packs tested (host replica; its hits equal the "
               "kernel's for %.3f%% of rays)\n",
               b->name.c_str(), ts.nodes, ts.leaves, ts.packs, 100.0 * ts.agree / n);
      }
#ifdef PSF_HAVE_EMBREE
      if (b->embree_prims.size() == n) {
        size_t agree = 0;
        for (uint32_t i = 0; i < n; ++i) agree += b->psf_hits[i].prim == b->embree_prims[i];
        double agreement = double(agree) / n;
        double ratio = mrays / (n / b->embree.median_s * 1e-6);
        double ratio16 = b->embree16.median_s > 0 ? mrays / (n / b->embree16.median_s * 1e-6) : 0.0;
        state.counters["agreement"] = agreement;
        state.counters["ratio_psf_embree"] = ratio;
        if (ratio16 > 0) state.counters["ratio_psf_embree16"] = ratio16;
        report("%s: psf/embree = %.2f, psf/embree (high-quality build, packets of 16) = %.2f; hit triangles agree for "
               "%.4f%% of rays%s\n",
               b->name.c_str(), ratio, ratio16, 100.0 * agreement, agreement > 0.999 ? "" : " (BELOW 99.9%)");
        const double p1 = paired_median(paired1), p16 = paired_median(paired16);
        state.counters["ratio_paired_embree"] = p1;
        if (p16 > 0) state.counters["ratio_paired_embree16"] = p16;
        report("%s: paired trials (each psf launch right after a pass of each Embree): psf/embree median %.2f (%s), "
               "psf/embree (high-quality build, packets of 16) median %.2f (%s)\n",
               b->name.c_str(), p1, paired_range(paired1).c_str(), p16, paired_range(paired16).c_str());
        if (agreement <= 0.999) state.SkipWithError("hit triangles agree with Embree for <= 99.9% of rays");
      }
#endif
    })->UseManualTime()->Iterations(opt.trials)->Unit(benchmark::kMillisecond);
    // Shadow rays (any hit), paired trial by trial with Embree's rtcOccluded1 and,
    // as Mitsuba 3 runs it, rtcOccluded16 on the high-quality build.
    benchmark::RegisterBenchmark(("psf_any/" + b->name).c_str(), [b, &rt, &opt, threads](benchmark::State& state) {
      psf::RayCaster caster(rt, b->bvh);
      caster.local_size = opt.local;
      const uint32_t n = static_cast<uint32_t>(b->shadow.size());
      cl::Buffer rays = rt.upload(b->shadow);
      cl::Buffer hits = rt.buffer(CL_MEM_READ_WRITE, n * sizeof(Hit));
      caster.any(rays, hits, n);
      rt.finish();
#ifdef PSF_HAVE_EMBREE
      if (!b->embree1_scene) b->embree1_scene = std::make_shared<Embree>(*b, false, opt.embree_config);
      if (!b->embree16_scene) b->embree16_scene = std::make_shared<Embree>(*b, true, opt.embree_config);
      std::vector<uint8_t> occluded1, occluded16;
      b->embree1_scene->occlude_all(b->shadow, threads, occluded1);  // warm-up, and the reference
      b->embree16_scene->occlude_all(b->shadow, threads, occluded16);
#endif
      std::vector<double> device, e1_times, e16_times, paired1, paired16;
      for (auto _ : state) {
#ifdef PSF_HAVE_EMBREE
        auto timed = [&](const Embree& e, std::vector<uint8_t>& out) {
          auto s0 = std::chrono::steady_clock::now();
          e.occlude_all(b->shadow, threads, out);
          return std::chrono::duration<double>(std::chrono::steady_clock::now() - s0).count();
        };
        const double e1 = timed(*b->embree1_scene, occluded1), e16 = timed(*b->embree16_scene, occluded16);
#endif
        rt.reset_stats();
        caster.any(rays, hits, n);
        rt.finish();
        const double d = rt.stats().at("raycast_any").ms * 1e-3;
        state.SetIterationTime(d);
        device.push_back(d);
#ifdef PSF_HAVE_EMBREE
        e1_times.push_back(e1);
        e16_times.push_back(e16);
        paired1.push_back(e1 / d);
        paired16.push_back(e16 / d);
#endif
      }
      const std::vector<Hit> out = rt.download<Hit>(hits, n);
      size_t blocked = 0;
      for (const Hit& h : out) blocked += h.prim != PSF_NO_HIT;
      const Timing dt = summarize(device);
      state.counters["Mrays_per_s"] = n / dt.median_s * 1e-6;
      state.counters["occluded_fraction"] = double(blocked) / n;
      report("%s: psf any hit, %u shadow rays between surface points: %.2f Mrays/s (device median %.1f ms), %.1f%% "
             "occluded\n",
             b->name.c_str(), n, n / dt.median_s * 1e-6, dt.median_s * 1e3, 100.0 * blocked / n);
#ifdef PSF_HAVE_EMBREE
      size_t agree = 0;
      for (uint32_t i = 0; i < n; ++i) agree += (out[i].prim != PSF_NO_HIT) == (occluded1[i] != 0);
      const double agreement = double(agree) / n;
      const double p1 = paired_median(paired1), p16 = paired_median(paired16);
      state.counters["agreement"] = agreement;
      state.counters["ratio_paired_embree"] = p1;
      state.counters["ratio_paired_embree16"] = p16;
      report("%s: embree rtcOccluded1 %.2f Mrays/s, rtcOccluded16 (high-quality build) %.2f Mrays/s (medians of the "
             "passes before psf's); paired psf/embree median %.2f (%s), psf/embree16 median %.2f (%s); "
             "occlusion agrees with rtcOccluded1's for %.4f%% of rays%s\n",
             b->name.c_str(), n / summarize(e1_times).median_s * 1e-6, n / summarize(e16_times).median_s * 1e-6, p1,
             paired_range(paired1).c_str(), p16, paired_range(paired16).c_str(), 100.0 * agreement,
             agreement > 0.999 ? "" : " (BELOW 99.9%)");
      if (agreement <= 0.999) state.SkipWithError("occlusion agrees with Embree for <= 99.9% of rays");
#endif
    })->UseManualTime()->Iterations(opt.trials)->Unit(benchmark::kMillisecond);
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
