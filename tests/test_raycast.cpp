// Ray casting (kernels/raycast.cl, host/bvh.cpp) against an independent brute-force
// reference: Moller-Trumbore in double precision over every triangle of the scene.
//
// Tolerance. The kernel works in float (about 6e-8 relative error per operation);
// Moller-Trumbore amplifies rounding by cond = |d||e1||e2| / |det|
// = 1 / (sin(angle of the triangle) * |cos(angle of incidence)|), and its
// barycentrics further by 1 + distance / size (size = sqrt(|e1 x e2|)). We allow
// kSlack = 1e-5 (about 170 ulps) times these: a hit is accepted when the reference
// puts the reported triangle within kSlack * cond * (1 + distance / size) of its
// barycentric bounds and at the same t within kSlack * cond * (|t| + |org| / |dir| + 1),
// and when no triangle is hit clearly (by that margin) closer. A miss is accepted when no
// triangle is hit clearly. So where two triangles are within tolerance of each
// other (shared edges, coplanar overlaps) either is accepted. On top of that, the
// exact triangle of the reference (or one at the very same t: coplanar overlaps)
// must be reported for at least 99% of the rays, so a loose tolerance cannot hide
// a systematic error.
#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <optional>
#include <random>
#include <vector>

#include <tiny_obj_loader.h>

#include "bvh.h"
#include "support.h"

namespace {

using glm::dmat3;
using glm::dvec3;
using glm::uvec3;
using glm::vec3;

constexpr double kSlack = 1e-5;

struct Mesh {
  std::vector<vec3> positions;
  std::vector<uvec3> triangles;

  void add_triangle(vec3 a, vec3 b, vec3 c) {
    uint32_t i = static_cast<uint32_t>(positions.size());
    for (vec3 p : {a, b, c}) positions.push_back(p);  // (insert of a list: GCC 12 warns falsely)
    triangles.push_back({i, i + 1, i + 2});
  }
  // Quad a b c d (in order around it) as the triangles (a b c) and (a c d).
  void add_quad(vec3 a, vec3 b, vec3 c, vec3 d) {
    uint32_t i = static_cast<uint32_t>(positions.size());
    positions.insert(positions.end(), {a, b, c, d});
    triangles.push_back({i, i + 1, i + 2});
    triangles.push_back({i, i + 2, i + 3});
  }
};

Ray make_ray(vec3 org, vec3 dir, float tmin, float tmax) {
  Ray r;
  r.org = {{org.x, org.y, org.z, tmin}};
  r.dir = {{dir.x, dir.y, dir.z, tmax}};
  return r;
}

// The reference: the line org + t dir against one triangle, in double.
struct RefIsect {
  bool valid = false;  // false when the ray is parallel to the (possibly degenerate) triangle
  double t = 0, u = 0, v = 0;
  double cond = 0;  // |d||e1||e2| / |det|
  double bary_tol = 0;  // kSlack * cond * (1 + distance / size): the barycentric tolerance
};

RefIsect ref_isect(const Mesh& m, uint32_t tri, const Ray& ray) {
  dvec3 a(m.positions[m.triangles[tri].x]), b(m.positions[m.triangles[tri].y]), c(m.positions[m.triangles[tri].z]);
  dvec3 o(ray.org.s[0], ray.org.s[1], ray.org.s[2]), d(ray.dir.s[0], ray.dir.s[1], ray.dir.s[2]);
  dvec3 e1 = b - a, e2 = c - a;
  dvec3 p = glm::cross(d, e2);
  double det = glm::dot(e1, p);
  double scale = glm::length(d) * glm::length(e1) * glm::length(e2);
  RefIsect r;
  if (!(std::abs(det) > 1e-12 * scale)) return r;
  dvec3 s = o - a;
  dvec3 q = glm::cross(s, e1);
  r.valid = true;
  r.u = glm::dot(s, p) / det;
  r.v = glm::dot(d, q) / det;
  r.t = glm::dot(e2, q) / det;
  r.cond = scale / std::abs(det);
  double size = std::sqrt(glm::length(glm::cross(e1, e2)));
  r.bary_tol = kSlack * r.cond * (1.0 + std::abs(r.t) * glm::length(d) / size);
  return r;
}

// Whether the intersection lies inside the triangle widened (margin > 0) or shrunk
// (margin < 0) by `margin` in barycentric terms, at a t inside (tmin, tmax) widened
// or shrunk by `tmargin`.
bool ref_inside(const RefIsect& r, double margin, double tmargin, const Ray& ray) {
  return r.valid && r.u >= -margin && r.v >= -margin && r.u + r.v <= 1 + margin &&
         r.t > ray.org.s[3] - tmargin && r.t < ray.dir.s[3] + tmargin;
}

double t_tolerance(const RefIsect& r, const Ray& ray) {
  dvec3 o(ray.org.s[0], ray.org.s[1], ray.org.s[2]), d(ray.dir.s[0], ray.dir.s[1], ray.dir.s[2]);
  return kSlack * r.cond * (std::abs(r.t) + glm::length(o) / glm::length(d) + 1.0);
}

struct Verdict {
  bool ok = true;          // the device result is acceptable
  bool exact = true;       // the device reports the reference's own closest triangle (or both miss)
  std::string why;         // the reason when not ok
};

// Judges a device result for `ray` against the brute-force reference. `any`: the
// device result came from the any-hit kernel (any triangle within range will do).
Verdict judge(const Mesh& m, const Ray& ray, const Hit& hit, bool any) {
  Verdict v;
  uint32_t strict_prim = PSF_NO_HIT;
  double strict_t = std::numeric_limits<double>::infinity();
  double clear_t = std::numeric_limits<double>::infinity();  // closest hit beyond any doubt
  for (uint32_t i = 0; i < m.triangles.size(); ++i) {
    RefIsect r = ref_isect(m, i, ray);
    if (ref_inside(r, 0.0, 0.0, ray) && r.t < strict_t) {
      strict_t = r.t;
      strict_prim = i;
    }
    if (r.valid) {
      double tt = t_tolerance(r, ray);
      if (ref_inside(r, -r.bary_tol, -tt, ray)) clear_t = std::min(clear_t, r.t + tt);
    }
  }
  if (std::isnan(hit.t) || std::isnan(hit.u) || std::isnan(hit.v)) {
    v.ok = false;
    v.why = "NaN in the hit";
    return v;
  }
  if (hit.prim == PSF_NO_HIT) {
    v.exact = strict_prim == PSF_NO_HIT;
    if (clear_t < std::numeric_limits<double>::infinity()) {
      v.ok = false;
      v.why = "device misses, reference hits triangle " + std::to_string(strict_prim) + " at t " +
              std::to_string(strict_t);
    } else if (!any && hit.t != ray.dir.s[3]) {
      v.ok = false;
      v.why = "a miss must report t = tmax";
    }
    return v;
  }
  if (hit.prim >= m.triangles.size()) {
    v.ok = false;
    v.why = "device reports triangle " + std::to_string(hit.prim) + " out of range";
    return v;
  }
  RefIsect r = ref_isect(m, hit.prim, ray);
  double tt = r.valid ? t_tolerance(r, ray) : 0.0;
  // Exact: the reference's own closest triangle, or one it hits at the very same t (a tie).
  bool tie = ref_inside(r, 0.0, 0.0, ray) && std::abs(r.t - strict_t) <= 1e-6 * std::max(1.0, std::abs(strict_t));
  v.exact = any ? strict_prim != PSF_NO_HIT : hit.prim == strict_prim || tie;
  if (!ref_inside(r, r.bary_tol, tt, ray)) {
    v.ok = false;
    v.why = "device reports triangle " + std::to_string(hit.prim) + " which the reference does not hit";
  } else if (std::abs(hit.t - r.t) > tt) {
    v.ok = false;
    v.why = "t " + std::to_string(hit.t) + " differs from the reference's " + std::to_string(r.t);
  } else if (std::abs(hit.u - r.u) > r.bary_tol || std::abs(hit.v - r.v) > r.bary_tol) {
    v.ok = false;
    v.why = "barycentrics differ from the reference";
  } else if (!any && hit.t > clear_t) {
    v.ok = false;
    v.why = "triangle " + std::to_string(strict_prim) + " is clearly closer (t " + std::to_string(strict_t) + ")";
  }
  return v;
}

// Whether trace_lanes' flat casts skip leaves by the root's boxes in this BVH
// (kernels/trace_lanes.cl flat_root_leaves): one node, children all leaves or
// empty, at least 4 packs.
bool flat_boxes_apply(const psf::Bvh& bvh) {
  if (bvh.nodes.size() != 1 || bvh.packs.size() < 4) return false;
  for (uint32_t c : bvh.nodes[0].child)
    if (c != PSF_EMPTY_CHILD && !psf::is_leaf(c)) return false;
  return true;
}

// The hits of trace_lanes' flat casts (every pack against eight rays at once,
// without the BVH: lanes_test_casts; with `boxes`, skipping the root's leaves
// whose boxes no ray of the eight meets, where flat_boxes_apply), closest (any
// false) or any-hit.
std::vector<Hit> cast_flat(const psf::Bvh& bvh, const std::vector<Ray>& rays, bool any, bool boxes) {
  auto& rt = psf::test::runtime();
  const uint32_t n = static_cast<uint32_t>(rays.size());
  std::vector<BvhTriPack> packs = bvh.packs;
  if (packs.empty()) packs.resize(1);  // no zero-sized buffer; pack_count 0 tests none
  std::vector<BvhNode> nodes = bvh.nodes;
  if (nodes.empty()) nodes.resize(1);
  cl::Buffer pb = rt.upload(packs), nb = rt.upload(nodes), rb = rt.upload(rays);
  cl::Buffer cb = rt.buffer(CL_MEM_WRITE_ONLY, rays.size() * sizeof(Hit));
  cl::Buffer ab = rt.buffer(CL_MEM_WRITE_ONLY, rays.size() * sizeof(Hit));
  rt.launch("lanes_test_casts", (n + 7) / 8, 8, pb, cl_uint(bvh.packs.size()), cl_uint(bvh.sphere_count > 0), nb,
            cl_uint(boxes && !bvh.nodes.empty() ? 1 : 0), rb, cb, ab, n);
  rt.finish();
  return rt.download<Hit>(any ? ab : cb, rays.size());
}

// How check_casts casts: through the BVH, as trace_lanes' flat casts test every
// pack, or as they skip the root's leaves by their boxes.
enum class CastMode { bvh, flat, flat_boxes };

constexpr CastMode kCastModes[] = {CastMode::bvh, CastMode::flat, CastMode::flat_boxes};

// The ways of casting that differ for this BVH: flat_boxes only where it applies.
std::vector<CastMode> cast_modes(const psf::Bvh& bvh) {
  std::vector<CastMode> modes = {CastMode::bvh, CastMode::flat};
  if (flat_boxes_apply(bvh)) modes.push_back(CastMode::flat_boxes);
  return modes;
}

const char* cast_mode_name(CastMode mode) {
  return mode == CastMode::bvh    ? "through the BVH"
         : mode == CastMode::flat ? "flat casts (lanes_test_casts)"
                                  : "flat casts skipping leaves by the root's boxes";
}

// The hits of the BVH's casts (RayCaster), or of trace_lanes' flat casts.
std::vector<Hit> cast(const psf::Bvh& bvh, const std::vector<Ray>& rays, bool any, CastMode mode = CastMode::bvh) {
  if (mode != CastMode::bvh) return cast_flat(bvh, rays, any, mode == CastMode::flat_boxes);
  auto& rt = psf::test::runtime();
  psf::RayCaster caster(rt, bvh);
  cl::Buffer rb = rt.upload(rays);
  cl::Buffer hb = rt.buffer(CL_MEM_WRITE_ONLY, rays.size() * sizeof(Hit));
  if (any)
    caster.any(rb, hb, static_cast<uint32_t>(rays.size()));
  else
    caster.closest(rb, hb, static_cast<uint32_t>(rays.size()));
  rt.finish();
  return rt.download<Hit>(hb, rays.size());
}

// Counts ray i's failure, if its closest or any-hit verdict failed, and shows
// the first few.
void report(size_t i, const Ray& ray, const Hit& closest, const Verdict& c, const Hit& any, const Verdict& a,
            size_t& failures) {
  if ((c.ok && a.ok) || ++failures > 5) return;
  INFO("ray " << i << " org " << ray.org.s[0] << " " << ray.org.s[1] << " " << ray.org.s[2] << " dir " << ray.dir.s[0]
              << " " << ray.dir.s[1] << " " << ray.dir.s[2] << " t [" << ray.org.s[3] << ", " << ray.dir.s[3] << "]");
  INFO("closest: prim " << closest.prim << " t " << closest.t << ": " << c.why);
  INFO("any: prim " << any.prim << " t " << any.t << ": " << a.why);
  CHECK((c.ok && a.ok));
}

// Casts closest and any-hit rays through `bvh` every way (through the BVH, as
// trace_lanes' flat casts test every pack, and, where flat_boxes_apply, as they
// skip leaves by the root's boxes) and checks every result with
// judge(ray, hit, any): none fails, at least min_exact of the closest hits are
// exactly the reference's prim. Returns how many closest hits counts(hit) takes.
template <class Judge, class Counts>
size_t check_casts(const psf::Bvh& bvh, const std::vector<Ray>& rays, double min_exact, const Judge& judge,
                   const Counts& counts) {
  size_t hits = 0;
  for (CastMode mode : cast_modes(bvh)) {
    INFO(cast_mode_name(mode));
    std::vector<Hit> closest = cast(bvh, rays, false, mode);
    std::vector<Hit> any = cast(bvh, rays, true, mode);
    size_t exact = 0, failures = 0;
    hits = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      Verdict c = judge(rays[i], closest[i], false);
      Verdict a = judge(rays[i], any[i], true);
      exact += c.exact;
      hits += counts(closest[i]);
      report(i, rays[i], closest[i], c, any[i], a, failures);
    }
    INFO(failures << " of " << rays.size() << " rays fail");
    CHECK(failures == 0);
    INFO(exact << " of " << rays.size() << " rays report exactly the reference's prim");
    CHECK(double(exact) >= min_exact * double(rays.size()));
  }
  return hits;
}

// Casts closest and any-hit rays and checks every result against the reference.
// Returns the number of rays whose closest hit was a triangle.
size_t check_scene(const Mesh& m, const std::vector<Ray>& rays, double min_exact = 0.99) {
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles);
  return check_casts(
      bvh, rays, min_exact, [&](const Ray& r, const Hit& h, bool any) { return judge(m, r, h, any); },
      [](const Hit& h) { return h.prim != PSF_NO_HIT; });
}

vec3 uniform_sphere(std::mt19937& rng) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (;;) {
    vec3 d(u(rng), u(rng), u(rng));
    float l = glm::dot(d, d);
    if (l > 1e-4f && l <= 1.0f) return d / std::sqrt(l);
  }
}

Mesh random_soup(uint32_t seed, size_t count, float size) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  Mesh m;
  for (size_t i = 0; i < count; ++i) {
    vec3 c(u01(rng), u01(rng), u01(rng));
    m.add_triangle(c + size * uniform_sphere(rng), c + size * uniform_sphere(rng), c + size * uniform_sphere(rng));
  }
  return m;
}

// The Cornell box from quads, in the coordinates of Mitsuba's cbox scene (y up).
Mesh cornell_box_quads() {
  Mesh m;
  m.add_quad({552.8f, 0, 0}, {0, 0, 0}, {0, 0, 559.2f}, {549.6f, 0, 559.2f});                     // floor
  m.add_quad({556, 548.8f, 0}, {556, 548.8f, 559.2f}, {0, 548.8f, 559.2f}, {0, 548.8f, 0});       // ceiling
  m.add_quad({549.6f, 0, 559.2f}, {0, 0, 559.2f}, {0, 548.8f, 559.2f}, {556, 548.8f, 559.2f});    // back
  m.add_quad({0, 0, 559.2f}, {0, 0, 0}, {0, 548.8f, 0}, {0, 548.8f, 559.2f});                     // green
  m.add_quad({552.8f, 0, 0}, {549.6f, 0, 559.2f}, {556, 548.8f, 559.2f}, {556, 548.8f, 0});       // red
  m.add_quad({343, 548.7f, 227}, {343, 548.7f, 332}, {213, 548.7f, 332}, {213, 548.7f, 227});     // light
  auto block = [&](std::array<vec3, 4> base, float h) {
    vec3 up(0, h, 0);
    m.add_quad(base[0] + up, base[1] + up, base[2] + up, base[3] + up);
    for (int k = 0; k < 4; ++k) {
      vec3 a = base[k], b = base[(k + 1) % 4];
      m.add_quad(a, b, b + up, a + up);
    }
  };
  block({vec3(130, 0, 65), vec3(82, 0, 225), vec3(240, 0, 272), vec3(290, 0, 114)}, 165);
  block({vec3(423, 0, 247), vec3(265, 0, 296), vec3(314, 0, 456), vec3(472, 0, 406)}, 330);
  return m;
}

std::optional<Mesh> load_obj_dir(const std::string& dir) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(dir)) return std::nullopt;
  std::vector<fs::path> files;
  for (auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".obj") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  Mesh m;
  for (auto& f : files) {
    tinyobj::ObjReader reader;
    if (!reader.ParseFromFile(f.string())) return std::nullopt;
    const auto& attrib = reader.GetAttrib();
    uint32_t base = static_cast<uint32_t>(m.positions.size());
    for (size_t i = 0; i + 2 < attrib.vertices.size(); i += 3)
      m.positions.push_back({attrib.vertices[i], attrib.vertices[i + 1], attrib.vertices[i + 2]});
    for (auto& shape : reader.GetShapes()) {
      const auto& idx = shape.mesh.indices;
      for (size_t i = 0; i + 2 < idx.size(); i += 3)
        m.triangles.push_back(
            {base + idx[i].vertex_index, base + idx[i + 1].vertex_index, base + idx[i + 2].vertex_index});
    }
  }
  return m;
}

// Rays from random points inside the box [lo, hi] in uniform directions.
std::vector<Ray> rays_in_box(uint32_t seed, size_t count, vec3 lo, vec3 hi, float tmax) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  std::vector<Ray> rays;
  for (size_t i = 0; i < count; ++i) {
    vec3 o = lo + (hi - lo) * vec3(u01(rng), u01(rng), u01(rng));
    rays.push_back(make_ray(o, uniform_sphere(rng), 0.0f, tmax));
  }
  return rays;
}

}  // namespace

TEST_CASE("Raycast: random triangle soups match the brute-force reference", "[raycast]") {
  struct Case {
    uint32_t seed;
    size_t triangles;
    size_t rays;
    float size;
  };
  for (Case c : {Case{1, 1000, 3001, 0.08f}, Case{2, 2500, 2047, 0.05f}, Case{3, 77, 1025, 0.3f},
                 Case{4, 4000, 1999, 0.03f}}) {
    INFO("seed " << c.seed << ", " << c.triangles << " triangles, " << c.rays << " rays");
    Mesh m = random_soup(c.seed, c.triangles, c.size);
    std::mt19937 rng(c.seed * 7 + 1);
    std::uniform_real_distribution<float> u01(0.0f, 1.0f);
    std::vector<Ray> rays;
    for (size_t i = 0; i < c.rays; ++i) {
      vec3 o = vec3(-0.2f) + 1.4f * vec3(u01(rng), u01(rng), u01(rng));
      vec3 d = uniform_sphere(rng) * (0.5f + 2.0f * u01(rng));  // not normalised
      float tmin = i % 3 == 0 ? 0.0f : 0.01f * u01(rng);
      float tmax = i % 4 == 0 ? std::numeric_limits<float>::max() : 0.1f + u01(rng);
      rays.push_back(make_ray(o, d, tmin, tmax));
    }
    size_t hits = check_scene(m, rays);
    CHECK(hits > c.rays / 10);  // the scene is actually being hit
  }
}

TEST_CASE("Raycast: Cornell box from quads matches the reference", "[raycast]") {
  Mesh m = cornell_box_quads();
  // A scene of trace_lanes' flat casts that skip leaves by the root's boxes.
  REQUIRE(flat_boxes_apply(psf::build_bvh(m.positions, m.triangles)));
  std::vector<Ray> rays = rays_in_box(11, 4097, vec3(1, 1, 1), vec3(550, 547, 558), 1e30f);
  size_t hits = check_scene(m, rays);
  CHECK(hits > rays.size() * 7 / 10);  // a closed box except the open front (z = 0)
}

TEST_CASE("Raycast: Cornell box meshes from ../shared match the reference", "[raycast]") {
  auto shared = psf::test::shared_dir();
  std::optional<Mesh> m;
  if (shared) m = load_obj_dir(*shared + "/scenes/cbox/meshes/cbox");
  if (!m) {
    WARN("scenes/cbox/meshes/cbox/*.obj not found under the shared folder: skipped");
    return;
  }
  REQUIRE(m->triangles.size() >= 30);
  std::vector<Ray> rays = rays_in_box(12, 3001, vec3(1, 1, 1), vec3(550, 547, 558), 1e30f);
  check_scene(*m, rays);
}

TEST_CASE("Raycast: an empty scene is all misses", "[raycast]") {
  psf::Bvh bvh = psf::build_bvh({}, {});
  REQUIRE(bvh.nodes.size() == 1);
  for (int s = 0; s < PSF_BVH_WIDTH; ++s) CHECK(bvh.nodes[0].child[s] == PSF_EMPTY_CHILD);
  std::vector<Ray> rays = rays_in_box(3, 130, vec3(-1), vec3(1), 100.0f);
  for (CastMode mode : cast_modes(bvh))
    for (auto hits : {cast(bvh, rays, false, mode), cast(bvh, rays, true, mode)}) {
      for (size_t i = 0; i < rays.size(); ++i) {
        CHECK(hits[i].prim == PSF_NO_HIT);
        CHECK(hits[i].t == 100.0f);
      }
    }
}

TEST_CASE("Raycast: one triangle", "[raycast]") {
  Mesh m;
  m.add_triangle({0, 0, 0}, {1, 0, 0}, {0, 1, 0});
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles);
  CHECK(bvh.triangle_count == 1);
  std::vector<Ray> rays = {
      make_ray({0.25f, 0.25f, 1}, {0, 0, -1}, 0, 10),      // straight down onto it
      make_ray({0.25f, 0.25f, -1}, {0, 0, 2}, 0, 10),      // from below, dir not unit: t = 0.5
      make_ray({0.75f, 0.75f, 1}, {0, 0, -1}, 0, 10),      // beside the hypotenuse
      make_ray({0.25f, 0.25f, 1}, {0, 0, 1}, 0, 10),       // away from it
      make_ray({0.25f, 0.25f, 1}, {0, 0, -1}, 0, 0.5f),    // tmax short of it
      make_ray({0.25f, 0.25f, 1}, {0, 0, -1}, 0, -1.0f),   // a dead ray
  };
  for (CastMode mode : cast_modes(bvh)) {
    INFO(cast_mode_name(mode));
    std::vector<Hit> hits = cast(bvh, rays, false, mode);
    CHECK(hits[0].prim == 0u);
    CHECK(hits[0].t == Approx(1.0f));
    CHECK(hits[0].u == Approx(0.25f));
    CHECK(hits[0].v == Approx(0.25f));
    CHECK(hits[1].prim == 0u);
    CHECK(hits[1].t == Approx(0.5f));
    for (int i : {2, 3, 4, 5}) {
      INFO("ray " << i);
      CHECK(hits[i].prim == PSF_NO_HIT);
      CHECK(hits[i].t == rays[i].dir.s[3]);
    }
    std::vector<Hit> any = cast(bvh, rays, true, mode);
    for (size_t i = 0; i < rays.size(); ++i) CHECK((any[i].prim == PSF_NO_HIT) == (hits[i].prim == PSF_NO_HIT));
  }
  check_scene(m, rays_in_box(5, 515, vec3(-0.5f), vec3(1.5f), 5.0f));
}

TEST_CASE("Raycast: degenerate triangles are never hit and do not disturb others", "[raycast]") {
  Mesh m;
  m.add_triangle({0, 0, 0}, {0, 0, 0}, {0, 0, 0});                 // a point
  m.add_triangle({0, 0, 0}, {1, 0, 0}, {1, 0, 0});                 // repeated vertex
  m.add_triangle({0, 0, 0}, {1, 1, 0.5f}, {2, 2, 1});              // collinear
  m.add_triangle({-1, 0.5f, 0}, {1, 0.5f, 0}, {0.25f, 0.5f, 0});   // collinear along x
  m.add_triangle({0.5f, -1, -1}, {0.5f, 1, 1}, {0.5f, 1, 1});      // a segment
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  m.add_triangle({nan, 0, 0}, {1, 0, 0}, {0, 1, 0});               // non-finite vertex
  m.add_triangle({inf, 0, 0}, {1, 0, 0}, {0, 1, 0});
  for (int k = 0; k < 40; ++k) {                                   // and some proper ones
    float x = -1.0f + 0.05f * k;
    m.add_triangle({x, -1, 0.3f}, {x + 0.04f, -1, 0.3f}, {x, 1, 0.3f});
  }
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles);
  CHECK(bvh.skipped == 7);
  CHECK(bvh.triangle_count == 40);
  // Rays through the degenerate ones in many directions, and along their lines.
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  std::vector<Ray> rays;
  for (int i = 0; i < 1000; ++i) {
    vec3 target = i % 2 ? vec3(u01(rng), u01(rng), 0.5f * u01(rng)) : vec3(2 * u01(rng) - 1, 0.5f, 0);
    vec3 d = uniform_sphere(rng);
    rays.push_back(make_ray(target - 2.0f * d, d, 0.0f, 4.0f));
  }
  rays.push_back(make_ray({-2, -2, -1}, {1, 1, 0.5f}, 0, 10));   // along the collinear one
  rays.push_back(make_ray({-3, 0.5f, 0}, {1, 0, 0}, 0, 10));      // along the x-aligned one
  rays.push_back(make_ray({0, 0, -1}, {0, 0, 1}, 0, 10));         // through the point
  Mesh proper;                                                    // the reference sees only these
  proper.positions = m.positions;
  for (size_t t = 7; t < m.triangles.size(); ++t) proper.triangles.push_back(m.triangles[t]);
  for (CastMode mode : cast_modes(bvh)) {
    INFO(cast_mode_name(mode));
    std::vector<Hit> hits = cast(bvh, rays, false, mode);
    std::vector<Hit> any = cast(bvh, rays, true, mode);
    for (size_t i = 0; i < rays.size(); ++i) {
      INFO("ray " << i);
      CHECK((hits[i].prim == PSF_NO_HIT || hits[i].prim >= 7));
      CHECK((any[i].prim == PSF_NO_HIT || any[i].prim >= 7));
      CHECK(!std::isnan(hits[i].t));
      // Scene indices shift by 7 against `proper`.
      Hit h = hits[i];
      if (h.prim != PSF_NO_HIT) h.prim -= 7;
      Verdict v = judge(proper, rays[i], h, false);
      INFO(v.why);
      CHECK(v.ok);
    }
  }
}

TEST_CASE("Raycast: rays through edges shared by two triangles hit one of them", "[raycast]") {
  // A height field of 32 x 32 quads (two triangles each) with random heights
  // (slopes below 0.2, facets within 12 degrees of the xy plane): every ray is
  // aimed at a point exactly on a shared edge (a quad's diagonal or the edge between
  // two quads) or at a shared vertex, from directions at least 37 degrees from the
  // xy plane, so it crosses the surface there rather than touching a ridge.
  // Watertightness within the kernel's barycentric tolerance (1e-6 + 5e-7 times
  // distance / triangle size) means each must hit one of the triangles at that
  // point; none may slip through. Rays start 0.5 (16 triangle sizes) and 40 (1300
  // triangle sizes) before the aimed-at point.
  const int n = 32;
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  Mesh m;
  std::vector<float> height((n + 1) * (n + 1));
  for (float& h : height) h = 0.003f * u01(rng);
  auto p = [&](int x, int y) { return vec3(x / float(n), y / float(n), height[y * (n + 1) + x]); };
  for (int y = 0; y <= n; ++y)
    for (int x = 0; x <= n; ++x) m.positions.push_back(p(x, y));
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      uint32_t a = y * (n + 1) + x, b = a + 1, c = a + n + 2, d = a + n + 1;
      m.triangles.push_back({a, b, c});
      m.triangles.push_back({a, c, d});
    }
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles);
  for (float dist : {0.5f, 40.0f}) {
    INFO("rays start " << dist << " before the edge");
    std::vector<Ray> rays;
    for (int i = 0; i < 3000; ++i) {
      int x = 1 + int(u01(rng) * (n - 2)), y = 1 + int(u01(rng) * (n - 2));
      float s = u01(rng);
      vec3 target;
      switch (i % 4) {
        case 0: target = glm::mix(p(x, y), p(x + 1, y + 1), s); break;  // diagonal
        case 1: target = glm::mix(p(x, y), p(x + 1, y), s); break;      // between quads in y
        case 2: target = glm::mix(p(x, y), p(x, y + 1), s); break;      // between quads in x
        default: target = p(x, y); break;                               // a vertex
      }
      vec3 d = uniform_sphere(rng);
      d.z = std::copysign(std::max(std::abs(d.z), 0.6f), d.z);  // >= 37 degrees from the xy plane
      d = glm::normalize(d);
      rays.push_back(make_ray(target - dist * d, d, 0.0f, 1e3f));
    }
    for (CastMode mode : cast_modes(bvh)) {
      INFO(cast_mode_name(mode));
      std::vector<Hit> hits = cast(bvh, rays, false, mode);
      std::vector<Hit> any = cast(bvh, rays, true, mode);
      size_t missed = 0, missed_any = 0;
      for (size_t i = 0; i < rays.size(); ++i) {
        missed += hits[i].prim == PSF_NO_HIT;
        missed_any += any[i].prim == PSF_NO_HIT;
        if (hits[i].prim != PSF_NO_HIT) {
          INFO("ray " << i);
          Verdict v = judge(m, rays[i], hits[i], false);
          INFO(v.why);
          CHECK(v.ok);
          CHECK(hits[i].t <= dist * (1 + 1e-4f));  // the aimed-at point, or an occluder before it
        }
      }
      CHECK(missed == 0);
      CHECK(missed_any == 0);
    }
  }
}

TEST_CASE("Raycast: rays leaving a surface with tmin > 0 skip it", "[raycast]") {
  Mesh m = cornell_box_quads();
  std::mt19937 rng(31);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  std::vector<Ray> rays;
  std::vector<uint32_t> start;
  // Points on the floor (triangles 0, 1), the back wall (4, 5) and the tall block's top.
  const uint32_t tris[] = {0, 1, 4, 5, 22, 23};
  for (int i = 0; i < 2000; ++i) {
    uint32_t t = tris[i % 6];
    float a = u01(rng), b = u01(rng);
    if (a + b > 1) a = 1 - a, b = 1 - b;
    const uvec3& tri = m.triangles[t];
    vec3 v0 = m.positions[tri.x], v1 = m.positions[tri.y], v2 = m.positions[tri.z];
    vec3 o = v0 + a * (v1 - v0) + b * (v2 - v0);
    vec3 n = glm::normalize(glm::cross(v1 - v0, v2 - v0));
    vec3 d = uniform_sphere(rng);
    if (i % 5 != 0 && glm::dot(d, n) * glm::dot(vec3(278, 274, 280) - o, n) < 0) d = -d;  // mostly into the room
    rays.push_back(make_ray(o, d, 1e-2f, 1e30f));
    start.push_back(t);
  }
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles);
  for (CastMode mode : cast_modes(bvh)) {
    std::vector<Hit> hits = cast(bvh, rays, false, mode);
    for (size_t i = 0; i < rays.size(); ++i) {
      INFO("ray " << i << " from triangle " << start[i] << ", " << cast_mode_name(mode));
      CHECK(hits[i].prim != start[i]);
      CHECK((hits[i].prim == PSF_NO_HIT || hits[i].t > 1e-2f));
    }
  }
  check_scene(m, rays);
}

TEST_CASE("Raycast: axis-aligned and special rays give no NaN", "[raycast]") {
  Mesh m = cornell_box_quads();
  std::vector<Ray> rays;
  const float inf = std::numeric_limits<float>::infinity();
  for (vec3 o : {vec3(278, 274, 280), vec3(0, 0, 0), vec3(552.8f, 0, 0), vec3(130, 165, 65), vec3(-10, 100, 100)})
    for (vec3 d : {vec3(1, 0, 0), vec3(-1, 0, 0), vec3(0, 1, 0), vec3(0, -1, 0), vec3(0, 0, 1), vec3(0, 0, -1),
                   vec3(-0.0f, 0.0f, 1), vec3(1, 1, 0), vec3(0, -1, -1), vec3(1e-30f, 1, 0)})
      for (float tmax : {1e30f, inf, 50.0f}) rays.push_back(make_ray(o, d, 0.0f, tmax));
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles);
  REQUIRE(flat_boxes_apply(bvh));
  for (int k = 0; k < 6; ++k) {  // closest and any, each way of casting
    const bool any = k & 1;
    const CastMode mode = kCastModes[k / 2];
    std::vector<Hit> hits = cast(bvh, rays, any, mode);
    for (size_t i = 0; i < rays.size(); ++i) {
      INFO("ray " << i << (any ? " any, " : " closest, ") << cast_mode_name(mode));
      CHECK(!std::isnan(hits[i].t));
      CHECK(!std::isnan(hits[i].u));
      CHECK(!std::isnan(hits[i].v));
      Verdict v = judge(m, rays[i], hits[i], any);
      INFO(v.why);
      CHECK(v.ok);
    }
  }
}

TEST_CASE("Raycast: without spatial splits the BVH references every triangle once inside its boxes", "[raycast]") {
  Mesh m = random_soup(77, 5000, 0.05f);
  m.add_triangle({0.5f, 0.5f, 0.5f}, {0.5f, 0.5f, 0.5f}, {0.6f, 0.5f, 0.5f});  // degenerate: left out
  for (int k = 0; k < 100; ++k)  // equal centroids
    m.add_triangle({0.2f, 0.2f, 0.2f}, {0.3f, 0.2f, 0.2f}, {0.2f, 0.3f, 0.2f});
  for (int k = 0; k < 50; ++k)  // centroids a denormal apart: bins / extent overflows
    m.add_triangle({k * 1e-43f, 0, 0}, {1e-3f, 0, 0}, {0, 1e-3f, 0});
  psf::BvhParams whole;
  whole.spatial_splits = false;
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles, {}, whole);
  REQUIRE(bvh.skipped == 1);
  REQUIRE(bvh.triangle_count == m.triangles.size() - 1);
  CHECK(bvh.references == bvh.triangle_count);
  CHECK(bvh.depth >= 1);
  CHECK(bvh.depth <= PSF_BVH_MAX_DEPTH);
  std::vector<int> refs(m.triangles.size(), 0);     // leaf references of each scene triangle
  std::vector<int> pack_refs(bvh.packs.size(), 0);  // leaf references of each pack
  std::vector<int> node_refs(bvh.nodes.size(), 0);
  size_t leaves = 0;
  int depth = 0;
  struct Item {
    uint32_t node;
    int level;
  };
  std::vector<Item> todo = {{0, 1}};
  while (!todo.empty()) {
    Item it = todo.back();
    todo.pop_back();
    depth = std::max(depth, it.level);
    REQUIRE(it.node < bvh.nodes.size());
    const BvhNode& n = bvh.nodes[it.node];
    for (int s = 0; s < PSF_BVH_WIDTH; ++s) {
      uint32_t c = n.child[s];
      vec3 lo(n.min_x[s], n.min_y[s], n.min_z[s]), hi(n.max_x[s], n.max_y[s], n.max_z[s]);
      if (c == PSF_EMPTY_CHILD) {
        CHECK((lo.x > hi.x && lo.y > hi.y && lo.z > hi.z));
        continue;
      }
      auto inside = [&](vec3 p) { return glm::all(glm::lessThanEqual(lo, p)) && glm::all(glm::lessThanEqual(p, hi)); };
      if (psf::is_leaf(c)) {
        ++leaves;
        uint32_t first = psf::leaf_first(c), count = psf::leaf_count(c);
        CHECK(count * PSF_BVH_WIDTH <= std::max<unsigned>(PSF_LEAF_MAX_TRIS, PSF_BVH_WIDTH));
        REQUIRE(first + count <= bvh.packs.size());
        uint32_t used = 0;
        for (uint32_t k = first; k < first + count; ++k) {
          const BvhTriPack& p = bvh.packs[k];
          pack_refs[k] += 1;
          for (int lane = 0; lane < PSF_BVH_WIDTH; ++lane) {
            uint32_t prim = p.prim[lane];
            vec3 e1(p.e1_x[lane], p.e1_y[lane], p.e1_z[lane]), e2(p.e2_x[lane], p.e2_y[lane], p.e2_z[lane]);
            if (prim == PSF_NO_HIT) {  // unused lanes come last in a leaf, with zero edges
              CHECK(k == first + count - 1);
              CHECK(e1 == vec3(0));
              CHECK(e2 == vec3(0));
              continue;
            }
            ++used;
            REQUIRE(prim < m.triangles.size());
            refs[prim] += 1;
            const uvec3& tri = m.triangles[prim];
            CHECK(vec3(p.v0_x[lane], p.v0_y[lane], p.v0_z[lane]) == m.positions[tri.x]);
            CHECK(e1 == m.positions[tri.y] - m.positions[tri.x]);
            CHECK(e2 == m.positions[tri.z] - m.positions[tri.x]);
            CHECK(p.inv_size[lane] > 0.0f);
            for (int v = 0; v < 3; ++v) CHECK(inside(m.positions[tri[v]]));
          }
        }
        CHECK_FALSE(psf::leaf_spheres(c));
        CHECK(used <= PSF_LEAF_MAX_TRIS);
        CHECK(used > (count - 1) * PSF_BVH_WIDTH);  // no pack without a triangle
      } else {
        REQUIRE(c < bvh.nodes.size());
        REQUIRE(c != it.node);
        node_refs[c] += 1;
        // The child node's own boxes lie inside this slot's box.
        const BvhNode& k = bvh.nodes[c];
        for (int s2 = 0; s2 < PSF_BVH_WIDTH; ++s2)
          if (k.child[s2] != PSF_EMPTY_CHILD) {
            CHECK(inside(vec3(k.min_x[s2], k.min_y[s2], k.min_z[s2])));
            CHECK(inside(vec3(k.max_x[s2], k.max_y[s2], k.max_z[s2])));
          }
        todo.push_back({c, it.level + 1});
      }
    }
  }
  CHECK(depth == bvh.depth);
  CHECK(node_refs[0] == 0);
  for (size_t i = 1; i < node_refs.size(); ++i) CHECK(node_refs[i] == 1);
  for (size_t k = 0; k < pack_refs.size(); ++k) CHECK(pack_refs[k] == 1);
  for (size_t t = 0; t < 5000; ++t) CHECK(refs[t] == 1);
  CHECK(refs[5000] == 0);  // the degenerate one
  for (size_t t = 5001; t < refs.size(); ++t) CHECK(refs[t] == 1);
  CHECK(leaves >= bvh.triangle_count / PSF_LEAF_MAX_TRIS);
}

// Long thin triangles across a soup of small ones: their boxes overlap most of
// the soup's, which is where spatial splits cut them.
Mesh soup_with_slivers(uint32_t seed, size_t small, size_t slivers) {
  Mesh m = random_soup(seed, small, 0.02f);
  std::mt19937 rng(seed + 1000);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  for (size_t k = 0; k < slivers; ++k) {
    const vec3 a(u01(rng), u01(rng), u01(rng)), b(u01(rng), u01(rng), u01(rng));
    m.add_triangle(a, b, b + 0.01f * uniform_sphere(rng));
  }
  return m;
}

TEST_CASE("Raycast: spatial splits cut long triangles, every point of a triangle in a leaf box that holds it",
          "[raycast]") {
  Mesh m = soup_with_slivers(5, 3000, 300);
  const psf::BvhParams params;
  REQUIRE(params.spatial_splits);
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles, {}, params);
  REQUIRE(bvh.triangle_count == m.triangles.size());
  // The slivers were cut (some triangles are in several leaves), within the budget.
  CHECK(bvh.references > bvh.triangle_count + 100);
  CHECK(bvh.references <= bvh.triangle_count + uint32_t(params.split_budget * bvh.triangle_count));
  // Every leaf's triangles with its box.
  struct Leaf {
    glm::dvec3 lo, hi;
  };
  std::vector<std::vector<Leaf>> leaves_of(m.triangles.size());
  uint32_t lanes = 0;
  std::vector<uint32_t> todo = {0};
  while (!todo.empty()) {
    const BvhNode& n = bvh.nodes[todo.back()];
    todo.pop_back();
    for (int s = 0; s < PSF_BVH_WIDTH; ++s) {
      const uint32_t c = n.child[s];
      if (c == PSF_EMPTY_CHILD) continue;
      if (!psf::is_leaf(c)) {
        REQUIRE(c < bvh.nodes.size());
        todo.push_back(c);
        continue;
      }
      const Leaf box{{n.min_x[s], n.min_y[s], n.min_z[s]}, {n.max_x[s], n.max_y[s], n.max_z[s]}};
      std::vector<uint32_t> seen;
      for (uint32_t k = psf::leaf_first(c); k < psf::leaf_first(c) + psf::leaf_count(c); ++k)
        for (int lane = 0; lane < PSF_BVH_WIDTH; ++lane) {
          const uint32_t prim = bvh.packs[k].prim[lane];
          if (prim == PSF_NO_HIT) continue;
          REQUIRE(prim < m.triangles.size());
          CHECK(std::find(seen.begin(), seen.end(), prim) == seen.end());  // once in a leaf
          seen.push_back(prim);
          leaves_of[prim].push_back(box);
          ++lanes;
        }
    }
  }
  CHECK(lanes == bvh.references);
  // Points on each triangle (its corners, edges and inside, in double) lie in
  // some leaf box that holds it: the clipped boxes are conservative.
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  size_t cut = 0, missed = 0;
  for (size_t t = 0; t < m.triangles.size(); ++t) {
    const std::vector<Leaf>& boxes = leaves_of[t];
    REQUIRE(!boxes.empty());
    cut += boxes.size() > 1;
    const glm::dvec3 a(m.positions[m.triangles[t].x]), b(m.positions[m.triangles[t].y]),
        c(m.positions[m.triangles[t].z]);
    // The corners, the edges' midpoints, then random points inside.
    const double fixed_u[6] = {0, 1, 0, 0.5, 0, 0.5}, fixed_v[6] = {0, 0, 1, 0, 0.5, 0.5};
    for (int k = 0; k < 64; ++k) {
      double u = u01(rng), v = u01(rng);
      if (k < 6) {
        u = fixed_u[k];
        v = fixed_v[k];
      } else if (u + v > 1.0) {
        u = 1.0 - u;
        v = 1.0 - v;
      }
      const glm::dvec3 p = a + u * (b - a) + v * (c - a);
      bool inside = false;
      for (const Leaf& l : boxes)
        inside |= glm::all(glm::lessThanEqual(l.lo, p)) && glm::all(glm::lessThanEqual(p, l.hi));
      missed += !inside;
    }
  }
  CHECK(cut > 50);
  CHECK(missed == 0);
  // Casts through it (and the flat casts over its packs, duplicates included)
  // against the brute-force reference.
  std::vector<Ray> rays = rays_in_box(23, 4001, vec3(-0.1f), vec3(1.1f), 3.0f);
  CHECK(check_scene(m, rays) > rays.size() / 10);
  // The budgets hold: no cuts allowed, no references added; a budget of 1 %
  // of references, at most that many.
  psf::BvhParams no_cuts = params, few = params;
  no_cuts.split_cuts = 0.0f;
  few.split_budget = 0.01f;
  CHECK(psf::build_bvh(m.positions, m.triangles, {}, no_cuts).references == bvh.triangle_count);
  psf::BvhParams negative = params, nan = params;
  negative.split_budget = -1.0f;
  nan.split_cuts = std::numeric_limits<float>::quiet_NaN();
  CHECK(psf::build_bvh(m.positions, m.triangles, {}, negative).references == bvh.triangle_count);
  CHECK(psf::build_bvh(m.positions, m.triangles, {}, nan).references == bvh.triangle_count);
  // mark_masked counts primitives, not their references: the slivers (the
  // last 300 triangles, which the splits cut) masked are 300.
  std::vector<bool> masked(m.triangles.size(), false);
  for (size_t t = 3000; t < m.triangles.size(); ++t) masked[t] = true;
  psf::Bvh marked = bvh;
  CHECK(psf::mark_masked(marked, masked) == 300);
  const psf::Bvh small = psf::build_bvh(m.positions, m.triangles, {}, few);
  CHECK(small.references > bvh.triangle_count);
  CHECK(small.references <= bvh.triangle_count + bvh.triangle_count / 100);
}

TEST_CASE("Raycast: the BVH is the same whatever the number of build threads", "[raycast]") {
  // Subtrees of at least 4096 triangles on both sides of a top split are built
  // on threads of their own and their nodes spliced in: the wide nodes and packs
  // must come out byte for byte as from one thread (images never depend on cores).
  // Spatial splits too: long triangles cut in the subtrees built on threads.
  Mesh m = soup_with_slivers(91, 40000, 2000);
  for (int k = 0; k < 6000; ++k)  // a cluster of equal centroids: median splits below a parallel level
    m.add_triangle({0.7f, 0.7f, 0.7f}, {0.71f, 0.7f, 0.7f}, {0.7f, 0.71f, 0.7f});
  psf::BvhParams one, many;
  one.threads = 1;
  many.threads = 8;
  const psf::Bvh a = psf::build_bvh(m.positions, m.triangles, {}, one);
  const psf::Bvh b = psf::build_bvh(m.positions, m.triangles, {}, many);
  REQUIRE(a.nodes.size() > 500);
  CHECK(a.references > a.triangle_count + 1000);
  REQUIRE(a.nodes.size() == b.nodes.size());
  REQUIRE(a.packs.size() == b.packs.size());
  CHECK(a.depth == b.depth);
  CHECK(std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(BvhNode)) == 0);
  CHECK(std::memcmp(a.packs.data(), b.packs.data(), a.packs.size() * sizeof(BvhTriPack)) == 0);
}

TEST_CASE("Raycast: one leaf's worth of triangles gives a root with one leaf", "[raycast]") {
  Mesh m;
  for (int k = 0; k < 3; ++k) m.add_triangle({0, 0, float(k)}, {1, 0, float(k)}, {0, 1, float(k)});
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles);
  REQUIRE(!bvh.nodes.empty());
  int used = 0;
  for (int s = 0; s < PSF_BVH_WIDTH; ++s) used += bvh.nodes[0].child[s] != PSF_EMPTY_CHILD;
  CHECK(used >= 1);
  check_scene(m, rays_in_box(8, 300, vec3(-0.5f), vec3(1.5f, 1.5f, 3.0f), 10.0f));
}

TEST_CASE("Raycast: a leaf size the child reference cannot count is refused", "[raycast]") {
  // A leaf reference counts up to 8 packs; a leaf of max_leaf primitives, its
  // triangles and spheres in packs of their own, takes up to max_leaf / W + 2.
  Mesh m = random_soup(3, 200, 0.05f);
  psf::BvhParams params;
  params.max_leaf = 6 * PSF_BVH_WIDTH;
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles, params);
  CHECK(bvh.triangle_count == m.triangles.size());
  params.max_leaf = 7 * PSF_BVH_WIDTH;
  CHECK_THROWS_AS(psf::build_bvh(m.positions, m.triangles, params), std::invalid_argument);
}

namespace {

// The reference for analytic spheres: both roots of |org + t dir - c|^2 = r^2 in
// double (the textbook quadratic; double keeps it accurate at these scales).
struct RefSphere {
  bool valid = false;  // the line meets the sphere
  double t0 = 0, t1 = 0;  // roots, t0 <= t1
  double margin = 0;      // how far inside the sphere's outline the line passes, relative to r
};

RefSphere ref_sphere(const psf::BvhSphere& s, const Ray& ray) {
  dvec3 o(ray.org.s[0], ray.org.s[1], ray.org.s[2]), d(ray.dir.s[0], ray.dir.s[1], ray.dir.s[2]);
  dvec3 f = o - dvec3(s.center);
  double a = glm::dot(d, d), b = glm::dot(f, d), c = glm::dot(f, f) - double(s.radius) * s.radius;
  double disc = b * b - a * c;
  RefSphere r;
  if (disc < 0) return r;
  double sq = std::sqrt(disc);
  r.valid = true;
  r.t0 = (-b - sq) / a;
  r.t1 = (-b + sq) / a;
  // Distance of the line from the centre against r: 1 - dist / r.
  double dist = glm::length(f - d * (b / a));
  r.margin = 1.0 - dist / s.radius;
  return r;
}

// Judges closest and any-hit results in a scene of triangles (prims [0, T)) and
// spheres (prims T + k). Sphere hits must be at a root within t tolerance
// kSlack (|t| + (|org - c| + r) / |dir|); a sphere whose line passes within 1e-4 r
// of its outline, or whose root lies within tolerance of tmin or tmax, may be hit
// or missed.
Verdict judge_mixed(const Mesh& m, const std::vector<psf::BvhSphere>& spheres, const Ray& ray, const Hit& hit,
                    bool any) {
  const uint32_t first = uint32_t(m.triangles.size());
  const double inf = std::numeric_limits<double>::infinity();
  const double tmin = ray.org.s[3], tmax = ray.dir.s[3];
  dvec3 o(ray.org.s[0], ray.org.s[1], ray.org.s[2]), d(ray.dir.s[0], ray.dir.s[1], ray.dir.s[2]);
  uint32_t strict_prim = PSF_NO_HIT;
  double strict_t = inf, clear_t = inf;
  for (uint32_t i = 0; i < first; ++i) {
    RefIsect r = ref_isect(m, i, ray);
    if (ref_inside(r, 0.0, 0.0, ray) && r.t < strict_t) strict_t = r.t, strict_prim = i;
    if (r.valid) {
      double tt = t_tolerance(r, ray);
      if (ref_inside(r, -r.bary_tol, -tt, ray)) clear_t = std::min(clear_t, r.t + tt);
    }
  }
  auto sphere_tol = [&](const psf::BvhSphere& s, double t) {
    return kSlack * (std::abs(t) + (glm::length(o - dvec3(s.center)) + s.radius) / glm::length(d));
  };
  for (uint32_t k = 0; k < spheres.size(); ++k) {
    RefSphere r = ref_sphere(spheres[k], ray);
    if (!r.valid) continue;
    for (double t : {r.t0, r.t1}) {
      if (t > tmin && t < tmax && t < strict_t) strict_t = t, strict_prim = first + k;
      double tt = sphere_tol(spheres[k], t);
      if (r.margin > 1e-4 && t > tmin + tt && t < tmax - tt) clear_t = std::min(clear_t, t + tt);
    }
  }
  Verdict v;
  if (std::isnan(hit.t)) {
    v.ok = false;
    v.why = "NaN in the hit";
    return v;
  }
  if (hit.prim == PSF_NO_HIT) {
    v.exact = strict_prim == PSF_NO_HIT;
    if (clear_t < inf) {
      v.ok = false;
      v.why = "device misses, reference hits prim " + std::to_string(strict_prim) + " at t " + std::to_string(strict_t);
    }
    return v;
  }
  v.exact = any ? strict_prim != PSF_NO_HIT : hit.prim == strict_prim;
  if (hit.prim < first) {
    RefIsect r = ref_isect(m, hit.prim, ray);
    double tt = r.valid ? t_tolerance(r, ray) : 0.0;
    if (!ref_inside(r, r.bary_tol, tt, ray) || std::abs(hit.t - r.t) > tt) {
      v.ok = false;
      v.why = "device reports triangle " + std::to_string(hit.prim) + " which the reference does not hit there";
    }
  } else if (hit.prim - first < spheres.size()) {
    const psf::BvhSphere& s = spheres[hit.prim - first];
    RefSphere r = ref_sphere(s, ray);
    double tt = sphere_tol(s, hit.t);
    bool at_root = r.valid && (std::abs(hit.t - r.t0) <= tt || std::abs(hit.t - r.t1) <= tt);
    if (!at_root || !(hit.t > tmin - tt && hit.t < tmax + tt)) {
      v.ok = false;
      v.why = "device reports sphere " + std::to_string(hit.prim - first) + " at t " + std::to_string(hit.t) +
              ", not at a root in range (reference " + std::to_string(r.t0) + ", " + std::to_string(r.t1) + ")";
    } else if (hit.u != 0.0f || hit.v != 0.0f) {
      v.ok = false;
      v.why = "a sphere hit carries u = v = 0";
    }
  } else {
    v.ok = false;
    v.why = "device reports prim " + std::to_string(hit.prim) + " out of range";
    return v;
  }
  if (v.ok && !any && hit.t > clear_t) {
    v.ok = false;
    v.why = "prim " + std::to_string(strict_prim) + " is clearly closer (t " + std::to_string(strict_t) + ")";
  }
  return v;
}

size_t check_mixed(const Mesh& m, const std::vector<psf::BvhSphere>& spheres, const std::vector<Ray>& rays,
                   double min_exact = 0.99) {
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles, spheres);
  CHECK(bvh.sphere_count == spheres.size());
  // Each leaf says whether it holds spheres (PSF_LEAF_SPHERES), where the
  // traversal looks at a pack's kind; its sphere packs follow its triangles'.
  size_t sphere_leaves = 0;
  for (const BvhNode& n : bvh.nodes)
    for (uint32_t c : n.child) {
      if (!psf::is_leaf(c)) continue;
      const uint32_t first = psf::leaf_first(c), count = psf::leaf_count(c);
      REQUIRE(first + count <= bvh.packs.size());
      bool kinds_ordered = true, any_sphere = false;
      for (uint32_t k = first; k < first + count; ++k) {
        const bool sphere = (bvh.packs[k].prim[0] & PSF_PRIM_SPHERE) != 0u;
        kinds_ordered &= sphere || !any_sphere;
        any_sphere |= sphere;
      }
      CHECK(kinds_ordered);
      CHECK(psf::leaf_spheres(c) == any_sphere);
      sphere_leaves += any_sphere;
    }
  CHECK((sphere_leaves > 0) == !spheres.empty());
  return check_casts(
      bvh, rays, min_exact, [&](const Ray& r, const Hit& h, bool any) { return judge_mixed(m, spheres, r, h, any); },
      [&](const Hit& h) { return h.prim != PSF_NO_HIT && h.prim >= m.triangles.size(); });
}

}  // namespace

TEST_CASE("Raycast: analytic spheres among triangles match the brute-force reference", "[raycast]") {
  // Spheres of radii from 1e-3 to 0.2 (and one enclosing everything, so rays
  // start inside it) mixed with a triangle soup; leaves then hold both kinds.
  // Seed 8: few of each, a BVH of one node, whose flat casts skip leaves of
  // both kinds by their boxes.
  for (uint32_t seed : {5u, 6u, 7u, 8u}) {
    INFO("seed " << seed);
    Mesh m = random_soup(seed, seed == 6 ? 0 : seed == 8 ? 30 : psf::test::pick(600, 60), 0.06f);
    std::mt19937 rng(seed * 13 + 3);
    std::uniform_real_distribution<float> u01(0.0f, 1.0f);
    std::vector<psf::BvhSphere> spheres;
    const int count = seed == 8 ? 16 : psf::test::pick(500, 60);
    for (int k = 0; k < count; ++k) {
      float r = 0.2f * std::pow(10.0f, -2.3f * u01(rng));
      spheres.push_back({vec3(u01(rng), u01(rng), u01(rng)), r});
    }
    spheres.push_back({vec3(0.5f), 3.0f});
    if (seed == 8) REQUIRE(flat_boxes_apply(psf::build_bvh(m.positions, m.triangles, spheres)));
    std::vector<Ray> rays;
    for (size_t i = 0, n = psf::test::pick(3001, 301); i < n; ++i) {
      vec3 o = vec3(-0.2f) + 1.4f * vec3(u01(rng), u01(rng), u01(rng));
      vec3 d = uniform_sphere(rng) * (0.5f + 2.0f * u01(rng));  // not normalised
      float tmin = i % 3 == 0 ? 0.0f : 0.01f * u01(rng);
      float tmax = i % 4 == 0 ? std::numeric_limits<float>::max() : 0.1f + u01(rng);
      rays.push_back(make_ray(o, d, tmin, tmax));
    }
    size_t sphere_hits = check_mixed(m, spheres, rays);
    CHECK(sphere_hits > rays.size() / 4);  // the spheres, and the enclosing one, are hit
  }
}

TEST_CASE("Raycast: rays leaving a sphere's surface miss it outwards and cross it inwards", "[raycast]") {
  // As the renderer offsets them (shade.cl): from a point moved 1e-4 of its
  // distance off the surface. Outwards (into the normal's hemisphere) the sphere
  // is behind; inwards the ray crosses to the far side, at the chord's length.
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  // The last: a ground sphere of radius 1e5 below the origin, left from points
  // near its top (|p| of a few units, so the offset is 1e-4: a float f = org -
  // centre holds it only to 1/128; raycast.cl tests spheres in double).
  for (float radius : {0.01f, 1.0f, 300.0f, 1e5f}) {
    INFO("radius " << radius);
    const bool ground = radius == 1e5f;
    psf::BvhSphere s{ground ? vec3(0.0f, -radius, 0.0f) : vec3(3.0f, -2.0f, 7.0f) * radius, radius};
    psf::Bvh bvh = psf::build_bvh({}, {}, {s});
    std::vector<Ray> rays;
    std::vector<double> chords;  // expected t of the inward rays' hits
    for (int i = 0, n_rays = psf::test::pick(2000, 200); i < n_rays; ++i) {
      vec3 n = uniform_sphere(rng);
      if (ground) n = glm::normalize(vec3(5.0f * n.x, radius, 5.0f * n.z));  // within 5 of the top
      vec3 w = uniform_sphere(rng);
      bool inward = i % 2 == 1;
      if ((glm::dot(w, n) > 0.0f) == inward) w = -w;
      vec3 p = s.center + radius * n;
      float off = 1e-4f * std::max(1.0f, std::max(std::fabs(p.x), std::max(std::fabs(p.y), std::fabs(p.z))));
      vec3 o = p + (inward ? -n : n) * off;
      rays.push_back(make_ray(o, w * 2.0f, 0.0f, std::numeric_limits<float>::infinity()));
      chords.push_back(ref_sphere(s, rays.back()).t1);  // the far root, from the offset origin
    }
    for (CastMode mode : cast_modes(bvh)) {
      INFO(cast_mode_name(mode));
      std::vector<Hit> hits = cast(bvh, rays, false, mode);
      std::vector<Hit> any = cast(bvh, rays, true, mode);
      int bad = 0;
      for (size_t i = 0; i < rays.size(); ++i) {
        bool inward = i % 2 == 1;
        const double tol =
            kSlack * (chords[i] +
                      (glm::length(glm::dvec3(rays[i].org.s[0], rays[i].org.s[1], rays[i].org.s[2]) - dvec3(s.center)) +
                       radius) /
                          2.0);
        bool ok = inward ? hits[i].prim == 0 && any[i].prim == 0 && std::abs(hits[i].t - chords[i]) <= tol
                         : hits[i].prim == PSF_NO_HIT && any[i].prim == PSF_NO_HIT;
        if (!ok && ++bad <= 3) {
          INFO("ray " << i << (inward ? " inwards" : " outwards") << ": prim " << hits[i].prim << " t " << hits[i].t
                      << ", chord " << chords[i]);
          CHECK(ok);
        }
      }
      CHECK(bad == 0);
    }
  }
}

// Adds the cube [-1, 1]^3 turned by r and moved to c to m: 12 triangles, normals outwards.
void add_cube(Mesh& m, vec3 c = vec3(0.0f), glm::mat3 r = glm::mat3(1.0f)) {
  for (int axis = 0; axis < 3; ++axis)
    for (float side : {-1.0f, 1.0f}) {
      vec3 q[4];
      for (int k = 0; k < 4; ++k) {  // the face's corners in order around it
        vec3 p;
        p[axis] = side;
        p[(axis + 1) % 3] = (k == 0 || k == 3) ? -1.0f : 1.0f;
        p[(axis + 2) % 3] = k < 2 ? -1.0f : 1.0f;
        q[k] = p;
      }
      if (glm::dot(glm::cross(q[1] - q[0], q[2] - q[0]), q[0]) < 0.0f) std::swap(q[1], q[3]);
      m.add_quad(c + r * q[0], c + r * q[1], c + r * q[2], c + r * q[3]);
    }
}

// A random point on a diagonal of a random face of [-1, 1]^3, (a, a) or (a, -a)
// in the face's other two axes (one diagonal is the edge its two triangles
// share); *axis the face's normal axis.
vec3 face_diagonal_point(std::mt19937& rng, int* axis) {
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  *axis = int(u01(rng) * 3.0f) % 3;
  const float a = -1.0f + 2.0f * u01(rng);
  vec3 p;
  p[*axis] = u01(rng) < 0.5f ? -1.0f : 1.0f;
  p[(*axis + 1) % 3] = a;
  p[(*axis + 2) % 3] = u01(rng) < 0.5f ? a : -a;
  return p;
}

// kernels/shade.cl cast_shadows_media over `rays` (untextured masks), ray i
// starting in medium media[i] (1 + the material whose interior it is, 0: none;
// PathState.pending.w): each hit, or t, u, v the transmittance of a miss.
std::vector<Hit> cast_shadows_media(const psf::Bvh& bvh, const std::vector<Ray>& rays,
                                    const std::vector<uint32_t>& media, const std::vector<uint32_t>& tri_material,
                                    const std::vector<Material>& materials) {
  const size_t n = rays.size();
  std::vector<PathState> states(n);
  std::vector<uint32_t> queue(n);
  for (size_t i = 0; i < n; ++i) {
    std::memcpy(&states[i].pending.s[3], &media[i], sizeof(uint32_t));
    queue[i] = uint32_t(i);
  }
  auto& rt = psf::test::runtime();
  psf::RayCaster caster(rt, bvh);
  cl::Buffer hits = rt.buffer(CL_MEM_WRITE_ONLY, n * sizeof(Hit));
  cl::Buffer attribs = rt.buffer(CL_MEM_READ_ONLY, tri_material.size() * sizeof(TriAttrib));
  cl::Buffer textures = rt.buffer(CL_MEM_READ_ONLY, sizeof(TextureInfo)), texels = rt.buffer(CL_MEM_READ_ONLY, 16);
  rt.launch("cast_shadows_media", n, 64, caster.nodes(), caster.packs(), cl_uint(n), rt.upload(queue),
            rt.upload(rays), hits, rt.upload(states), rt.upload(tri_material), rt.upload(materials), attribs, textures,
            texels);
  rt.finish();
  return rt.download<Hit>(hits, n);
}

TEST_CASE("Raycast: shadow rays pass media's null boundaries with their transmittance", "[raycast]") {
  // kernels/shade.cl cast_shadows_media against a reference in double: a cube
  // [-1, 1]^3 (12 triangles, normals outwards) and an analytic sphere of radius 1
  // at (3, 0, 0), both null boundaries of media, an analytic sphere of radius 0.5
  // inside the cube whose exterior medium is the cube's (Mitsuba's exterior),
  // and an opaque square at y = -2. Rays start anywhere around them, in the
  // medium their origin lies in, with finite or infinite reach. A ray the square
  // blocks is a hit; any other misses, with t, u, v = exp(-sum of sigma_t times
  // the length of its stretch in each medium) (slab and sphere chords), within
  // 2e-5 + 2e-5 of the optical depth.
  const vec3 sigma_cube(0.5f, 1.0f, 2.0f), sigma_sphere(0.7f, 0.3f, 1.1f), sigma_inner(0.1f, 2.5f, 0.4f);
  const dvec3 centre(3.0, 0.0, 0.0), inner_centre(0.2, 0.1, -0.1);
  const double inner_radius = 0.5;
  Mesh m;
  add_cube(m);
  const uint32_t cube_tris = uint32_t(m.triangles.size());
  m.add_quad(vec3(-3, -2, -3), vec3(6, -2, -3), vec3(6, -2, 3), vec3(-3, -2, 3));
  psf::Bvh bvh =
      psf::build_bvh(m.positions, m.triangles, {{vec3(centre), 1.0f}, {vec3(inner_centre), float(inner_radius)}});
  // Materials: 0 opaque, 1 the cube's null boundary, 2 the sphere's, 3 the inner
  // sphere's (outside it the cube's medium, 1 + material 1); prims are the
  // triangles, then the spheres.
  std::vector<Material> materials(4);
  for (int k : {1, 2, 3}) {
    const vec3 s = k == 1 ? sigma_cube : k == 2 ? sigma_sphere : sigma_inner;
    materials[k].flags = PSF_MATFLAG_NULL_BOUNDARY;
    materials[k].interior = {{s.x, s.y, s.z, 1.0f}};
  }
  materials[3].exterior = 2u;
  std::vector<uint32_t> tri_material(m.triangles.size() + 2, 0u);
  std::vector<bool> masked(tri_material.size(), false);
  for (uint32_t t = 0; t < cube_tris; ++t) tri_material[t] = 1u, masked[t] = true;
  tri_material[m.triangles.size()] = 2u;
  tri_material[m.triangles.size() + 1] = 3u;
  masked[m.triangles.size()] = masked[m.triangles.size() + 1] = true;
  CHECK(psf::mark_masked(bvh, masked) == cube_tris + 2);

  std::mt19937 rng(29);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  const int n = psf::test::pick(4000, 400);
  std::vector<Ray> rays;
  std::vector<uint32_t> media(n);  // the medium each ray starts in: 1 + material index, 0 none
  for (int i = 0; i < n; ++i) {
    vec3 o(-2.0f + 7.0f * u01(rng), -1.5f + 3.0f * u01(rng), -1.5f + 3.0f * u01(rng));
    vec3 d = uniform_sphere(rng) * (0.5f + 4.0f * u01(rng));
    if (i % 2 == 1) {
      // Every other ray from inside the cube through a diagonal of one of its
      // faces, (a, a) or (a, -a) in the face's other two axes: one of them is the
      // edge its two triangles share, where pack_test's widened triangles both
      // take the ray, and the crossing must count once (553 of these 2000 rays
      // counted it twice before pack_null_crossings learnt to tell).
      o = vec3(-0.9f) + 1.8f * vec3(u01(rng), u01(rng), u01(rng));
      int axis;
      d = (face_diagonal_point(rng, &axis) - o) * (0.5f + u01(rng));
    }
    rays.push_back(make_ray(o, d, 0.0f, i % 4 == 0 ? std::numeric_limits<float>::infinity() : 0.2f + 2.0f * u01(rng)));
    const bool in_cube = std::max(std::fabs(o.x), std::max(std::fabs(o.y), std::fabs(o.z))) < 1.0f;
    const bool in_sphere = glm::length(dvec3(o) - centre) < 1.0;
    const bool in_inner = glm::length(dvec3(o) - inner_centre) < inner_radius;
    const uint32_t medium = in_inner ? 4u : in_cube ? 2u : in_sphere ? 3u : 0u;  // 1 + material index
    media[i] = medium;
  }
  const std::vector<Hit> out = cast_shadows_media(bvh, rays, media, tri_material, materials);

  int bad = 0, blocked = 0, through_media = 0;
  for (int i = 0; i < n; ++i) {
    const dvec3 o(rays[i].org.s[0], rays[i].org.s[1], rays[i].org.s[2]);
    const dvec3 d(rays[i].dir.s[0], rays[i].dir.s[1], rays[i].dir.s[2]);
    const double tmax = rays[i].dir.s[3];
    // The square: t where the ray meets y = -2 within the square.
    bool block = false;
    if (d.y != 0.0) {
      const double t = (-2.0 - o.y) / d.y;
      const dvec3 p = o + t * d;
      block = t > 0.0 && t < tmax && p.x > -3.0 && p.x < 6.0 && p.z > -3.0 && p.z < 3.0;
    }
    // The chords within [0, tmax]: the slab test of the cube, the sphere's roots.
    double t0 = 0.0, t1 = tmax;
    for (int a = 0; a < 3; ++a) {
      const double ta = (-1.0 - o[a]) / d[a], tb = (1.0 - o[a]) / d[a];
      t0 = std::max(t0, std::min(ta, tb));
      t1 = std::min(t1, std::max(ta, tb));
    }
    const double cube = std::max(0.0, t1 - t0) * glm::length(d);
    auto chord = [&](dvec3 c0, double r) {
      const dvec3 f = o - c0;
      const double a2 = glm::dot(d, d), b = glm::dot(f, d), c = glm::dot(f, f) - r * r, disc = b * b - a2 * c;
      if (!(disc > 0.0)) return 0.0;
      const double s0 = std::max(0.0, (-b - std::sqrt(disc)) / a2), s1 = std::min(tmax, (-b + std::sqrt(disc)) / a2);
      return std::max(0.0, s1 - s0) * glm::length(d);
    };
    const double sphere = chord(centre, 1.0), inner = chord(inner_centre, inner_radius);
    const bool missed = out[i].prim == PSF_NO_HIT;
    bool ok = missed == !block;
    blocked += block;
    through_media += !block && cube + sphere > 0.0;
    double worst = 0.0;
    if (ok && missed) {
      const float got[3] = {out[i].t, out[i].u, out[i].v};
      for (int k = 0; k < 3; ++k) {
        const double tau = sigma_cube[k] * (cube - inner) + sigma_sphere[k] * sphere + sigma_inner[k] * inner;
        worst = std::max(worst, std::abs(got[k] - std::exp(-tau)));
        ok = ok && std::abs(got[k] - std::exp(-tau)) <= 2e-5 * (1.0 + tau);
      }
    }
    if (!ok && ++bad <= 5) {
      INFO("ray " << i << ": prim " << out[i].prim << " (blocked " << block << "), cube " << cube << ", sphere "
                  << sphere << ", inner sphere " << inner << ", worst transmittance error " << worst);
      CHECK(ok);
    }
  }
  INFO(bad << " of " << n << " rays fail");
  CHECK(bad == 0);
  CHECK(blocked > n / 10);
  CHECK(through_media > n / 5);
}

TEST_CASE("Raycast: shadow rays change medium at each null boundary in order, as paths do", "[raycast]") {
  // cast_shadows_media against a walk in double over each ray's crossings in
  // order, each replacing the medium (Mitsuba's transitions: entering a shape,
  // its interior; leaving it, its exterior, here none). 27 rotated cubes (3 x 3
  // x 3, 4 apart: none overlap) of one fog, the middle one holding a null
  // sphere of another whose exterior is not declared, so that a ray leaving the
  // sphere is in no medium until it enters a cube again, as a path would be.
  // Rays start in any medium or none (the cube's fog around the sphere counts
  // only where the ray is in it), some to infinity; half end at a point on a
  // face diagonal (an edge two triangles share, crossed after other crossings
  // the traversal may meet in between: each counts once), at least 17 degrees
  // from grazing. Within 2e-5 + 2e-5 of the optical depth.
  const vec3 sigma_fog(0.5f, 1.0f, 2.0f), sigma_ball(0.7f, 0.3f, 1.1f);
  std::mt19937 rng(31);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  struct Cube {
    dvec3 c;
    dmat3 r;
  };
  std::vector<Cube> cubes;
  Mesh m;
  for (int x = 0; x < 3; ++x)
    for (int y = 0; y < 3; ++y)
      for (int z = 0; z < 3; ++z) {
        // A rotation about a random axis k by a random angle (Rodrigues: I + sin K + (1 - cos) K^2).
        const vec3 k = glm::normalize(vec3(u01(rng), u01(rng), u01(rng)) - vec3(0.5f));
        const float angle = 6.28f * u01(rng);
        const glm::mat3 kx(0.0f, k.z, -k.y, -k.z, 0.0f, k.x, k.y, -k.x, 0.0f);  // columns: K v = k x v
        const glm::mat3 r = glm::mat3(1.0f) + std::sin(angle) * kx + (1.0f - std::cos(angle)) * (kx * kx);
        const vec3 c(4.0f * float(x), 4.0f * float(y), 4.0f * float(z));
        cubes.push_back({dvec3(c), dmat3(r)});
        add_cube(m, c, r);
      }
  const dvec3 ball(4.1, 3.9, 4.0);  // inside the middle cube (13)
  const double ball_r = 0.6;
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles, {{vec3(ball), float(ball_r)}});
  std::vector<Material> materials(2);  // 0 the cubes' boundary, 1 the sphere's
  materials[0].flags = materials[1].flags = PSF_MATFLAG_NULL_BOUNDARY;
  materials[0].interior = {{sigma_fog.x, sigma_fog.y, sigma_fog.z, 1.0f}};
  materials[1].interior = {{sigma_ball.x, sigma_ball.y, sigma_ball.z, 1.0f}};
  std::vector<uint32_t> tri_material(m.triangles.size() + 1, 0u);
  tri_material.back() = 1u;
  CHECK(psf::mark_masked(bvh, std::vector<bool>(tri_material.size(), true)) == tri_material.size());

  auto in_cube = [&](const Cube& c, dvec3 p) {
    const dvec3 l = glm::transpose(c.r) * (p - c.c);
    return std::max(std::fabs(l.x), std::max(std::fabs(l.y), std::fabs(l.z))) < 1.0;
  };
  const int n = psf::test::pick(4000, 400);
  std::vector<Ray> rays;
  std::vector<uint32_t> media(n);  // the medium each ray starts in: 1 + material index, 0 none
  for (int i = 0; i < n; ++i) {
    const Cube& a = cubes[i % 3 == 0 ? 13 : rng() % cubes.size()];
    dvec3 o = i % 3 == 2 ? dvec3(-2.0 + 13.0 * u01(rng), -2.0 + 13.0 * u01(rng), -2.0 + 13.0 * u01(rng))
                         : a.c + a.r * dvec3(-0.9 + 1.8 * u01(rng), -0.9 + 1.8 * u01(rng), -0.9 + 1.8 * u01(rng));
    if (i % 6 == 0) o = ball + 0.5 * dvec3(uniform_sphere(rng)) * double(u01(rng));  // inside the sphere
    const Cube& b = cubes[rng() % cubes.size()];
    int axis;
    const dvec3 face(face_diagonal_point(rng, &axis));
    dvec3 normal(0.0);
    normal[axis] = 1.0;
    const dvec3 d = i % 2 == 0 ? (b.c + b.r * face - o) * (1.2 + double(u01(rng)))
                               : dvec3(uniform_sphere(rng)) * (1.0 + 6.0 * u01(rng));
    if (i % 2 == 0 && std::fabs(glm::dot(glm::normalize(d), b.r * normal)) < 0.3) {
      --i;
      continue;
    }
    const float tmax = i % 4 == 1 ? std::numeric_limits<float>::infinity() : 1.0f;
    rays.push_back(make_ray(vec3(o), vec3(d), 0.0f, tmax));
    uint32_t medium = 0u;  // 1 + the material whose interior holds the origin
    for (const Cube& c : cubes) medium = in_cube(c, o) ? 1u : medium;
    if (glm::length(o - ball) < ball_r) medium = 2u;
    media[i] = medium;
  }
  const std::vector<Hit> out = cast_shadows_media(bvh, rays, media, tri_material, materials);

  int bad = 0, nested = 0;
  for (int i = 0; i < n; ++i) {
    const dvec3 o(rays[i].org.s[0], rays[i].org.s[1], rays[i].org.s[2]);
    const dvec3 d(rays[i].dir.s[0], rays[i].dir.s[1], rays[i].dir.s[2]);
    const double tmax = rays[i].dir.s[3], len = glm::length(d);
    // The crossings in (0, tmax): (t, medium after), the cubes' slabs and the sphere's roots.
    std::vector<std::pair<double, uint32_t>> events;
    for (const Cube& c : cubes) {
      const dvec3 lo = glm::transpose(c.r) * (o - c.c), ld = glm::transpose(c.r) * d;
      double t0 = -INFINITY, t1 = INFINITY;
      for (int a = 0; a < 3; ++a) {
        const double ta = (-1.0 - lo[a]) / ld[a], tb = (1.0 - lo[a]) / ld[a];
        t0 = std::max(t0, std::min(ta, tb));
        t1 = std::min(t1, std::max(ta, tb));
      }
      if (t0 < t1) {
        if (t0 > 0.0 && t0 < tmax) events.push_back({t0, 1u});
        if (t1 > 0.0 && t1 < tmax) events.push_back({t1, 0u});
      }
    }
    const dvec3 f = o - ball;
    const double b = glm::dot(f, d), c = glm::dot(f, f) - ball_r * ball_r, disc = b * b - glm::dot(d, d) * c;
    if (disc > 0.0) {
      const double s0 = (-b - std::sqrt(disc)) / glm::dot(d, d), s1 = (-b + std::sqrt(disc)) / glm::dot(d, d);
      if (s0 > 0.0 && s0 < tmax) events.push_back({s0, 2u});
      if (s1 > 0.0 && s1 < tmax) events.push_back({s1, 0u});  // no exterior declared: no medium
      nested += s1 > 0.0 && s1 < tmax;
    }
    std::sort(events.begin(), events.end());
    uint32_t medium = media[i];
    auto sigma = [&](uint32_t med) { return med == 1u ? dvec3(sigma_fog) : med == 2u ? dvec3(sigma_ball) : dvec3(0.0); };
    dvec3 tau(0.0);
    double prev = 0.0;
    for (auto [t, after] : events) {
      tau += sigma(medium) * ((t - prev) * len);
      prev = t;
      medium = after;
    }
    if (std::isinf(tmax)) {
      for (int k = 0; k < 3; ++k) tau[k] = sigma(medium)[k] > 0.0 ? INFINITY : tau[k];
    } else {
      tau += sigma(medium) * ((tmax - prev) * len);
    }
    bool ok = out[i].prim == PSF_NO_HIT;
    const float got[3] = {out[i].t, out[i].u, out[i].v};
    for (int k = 0; k < 3 && ok; ++k) ok = std::abs(got[k] - std::exp(-tau[k])) <= 2e-5 * (1.0 + std::min(tau[k], 1e30));
    if (!ok && ++bad <= 5) {
      INFO("ray " << i << ": prim " << out[i].prim << ", " << events.size() << " crossings, expected tau " << tau.x
                  << " " << tau.y << " " << tau.z << ", got transmittance " << got[0] << " " << got[1] << " "
                  << got[2]);
      CHECK(ok);
    }
  }
  INFO(bad << " of " << n << " rays fail");
  CHECK(bad == 0);
  CHECK(nested > n / 20);
}

TEST_CASE("Raycast: the filter's hemisphere rays pass null boundaries and stop at surfaces", "[raycast]") {
  // kernels/visibility.cl visibility_cast_media: rays from inside a null cube of
  // fog, [-1, 1]^3, some of them towards an opaque square at y = -2 below it:
  // a ray that reaches the square is a hit; every other passes the cube's
  // boundary and misses, with any reach.
  Mesh m;
  add_cube(m);
  const uint32_t cube_tris = uint32_t(m.triangles.size());
  m.add_quad(vec3(-3, -2, -3), vec3(3, -2, -3), vec3(3, -2, 3), vec3(-3, -2, 3));
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles);
  std::vector<Material> materials(2);  // 0 the square, 1 the cube's boundary
  materials[1].flags = PSF_MATFLAG_NULL_BOUNDARY;
  materials[1].interior = {{0.5f, 1.0f, 2.0f, 1.0f}};
  std::vector<uint32_t> tri_material(m.triangles.size(), 0u);
  std::vector<bool> masked(m.triangles.size(), false);
  for (uint32_t t = 0; t < cube_tris; ++t) tri_material[t] = 1u, masked[t] = true;
  CHECK(psf::mark_masked(bvh, masked) == cube_tris);
  std::mt19937 rng(37);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  const int n = 512;
  std::vector<Ray> rays;
  for (int i = 0; i < n; ++i) {
    const vec3 o = vec3(-0.9f) + 1.8f * vec3(u01(rng), u01(rng), u01(rng));
    const float reach = i % 2 == 0 ? std::numeric_limits<float>::infinity() : 0.5f + 4.0f * u01(rng);
    rays.push_back(make_ray(o, uniform_sphere(rng), 1e-4f, reach));
  }
  auto& rt = psf::test::runtime();
  psf::RayCaster caster(rt, bvh);
  cl::Buffer hits = rt.buffer(CL_MEM_WRITE_ONLY, n * sizeof(Hit));
  cl::Buffer attribs = rt.buffer(CL_MEM_READ_ONLY, tri_material.size() * sizeof(TriAttrib));
  cl::Buffer textures = rt.buffer(CL_MEM_READ_ONLY, sizeof(TextureInfo)), texels = rt.buffer(CL_MEM_READ_ONLY, 16);
  rt.launch("visibility_cast_media", size_t(n), 64, caster.nodes(), caster.packs(), cl_uint(n), rt.upload(rays), hits,
            rt.upload(tri_material), rt.upload(materials), attribs, textures, texels);
  rt.finish();
  const std::vector<Hit> out = rt.download<Hit>(hits, n);
  int bad = 0, square = 0;
  for (int i = 0; i < n; ++i) {
    const vec3 o(rays[i].org.s[0], rays[i].org.s[1], rays[i].org.s[2]);
    const vec3 d(rays[i].dir.s[0], rays[i].dir.s[1], rays[i].dir.s[2]);
    const float t = d.y < 0.0f ? (-2.0f - o.y) / d.y : -1.0f;
    const vec3 p = o + t * d;
    const bool reaches = t > 0.0f && t < rays[i].dir.s[3] && std::fabs(p.x) < 3.0f && std::fabs(p.z) < 3.0f;
    square += reaches;
    bad += (out[i].prim != PSF_NO_HIT) != reaches;
    if (reaches && out[i].prim != PSF_NO_HIT) bad += out[i].prim < cube_tris;  // the square's, not the cube's
  }
  CHECK(bad == 0);
  CHECK(square > n / 8);
}

TEST_CASE("Raycast: a shadow ray through more null boundaries than one record holds", "[raycast]") {
  // 14 slabs of fog (28 crossings, more than PSF_NULL_CROSSINGS), each 0.2 thick
  // and 0.4 apart, crossed from below by rays of finite and infinite reach:
  // exp(-sigma x the length inside them), against the slab chords in double.
  Mesh m;
  const int slabs = 14;
  for (int k = 0; k < slabs; ++k) add_cube(m, vec3(0.0f, 0.4f * float(k), 0.0f), glm::mat3(4.0f, 0, 0, 0, 0.1f, 0, 0, 0, 4.0f));
  psf::Bvh bvh = psf::build_bvh(m.positions, m.triangles);
  std::vector<Material> materials(1);
  materials[0].flags = PSF_MATFLAG_NULL_BOUNDARY;
  materials[0].interior = {{0.5f, 1.0f, 0.25f, 1.0f}};
  const std::vector<uint32_t> tri_material(m.triangles.size(), 0u);
  CHECK(psf::mark_masked(bvh, std::vector<bool>(m.triangles.size(), true)) == m.triangles.size());
  std::mt19937 rng(41);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  std::vector<Ray> rays;
  for (int i = 0; i < 256; ++i) {
    const vec3 o(-1.0f + 2.0f * u01(rng), -1.0f, -1.0f + 2.0f * u01(rng));
    const vec3 d = glm::normalize(vec3(0.3f * (u01(rng) - 0.5f), 1.0f, 0.3f * (u01(rng) - 0.5f))) * 8.0f;
    rays.push_back(make_ray(o, d, 0.0f, i % 2 == 0 ? std::numeric_limits<float>::infinity() : 1.0f));
  }
  const std::vector<Hit> out = cast_shadows_media(bvh, rays, std::vector<uint32_t>(rays.size(), 0u), tri_material,
                                                  materials);
  int bad = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    const dvec3 o(rays[i].org.s[0], rays[i].org.s[1], rays[i].org.s[2]);
    const dvec3 d(rays[i].dir.s[0], rays[i].dir.s[1], rays[i].dir.s[2]);
    const double tmax = std::min(double(rays[i].dir.s[3]), 1e30);
    double inside = 0.0;  // the slabs' chords within [0, tmax], in length
    for (int k = 0; k < slabs; ++k) {
      const double y0 = 0.4 * k - 0.1, y1 = 0.4 * k + 0.1;
      const double t0 = std::max(0.0, (y0 - o.y) / d.y), t1 = std::min(tmax, (y1 - o.y) / d.y);
      inside += std::max(0.0, t1 - t0) * glm::length(d);
    }
    const float got[3] = {out[i].t, out[i].u, out[i].v};
    bool ok = out[i].prim == PSF_NO_HIT;
    for (int c = 0; c < 3 && ok; ++c) {
      const double tau = materials[0].interior.s[c] * inside;
      ok = std::abs(got[c] - std::exp(-tau)) <= 2e-5 * (1.0 + tau);
    }
    if (!ok && ++bad <= 3) {
      INFO("ray " << i << ": length in fog " << inside << ", transmittance " << got[0] << " " << got[1] << " " << got[2]);
      CHECK(ok);
    }
  }
  CHECK(bad == 0);
}
