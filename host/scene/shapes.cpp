// Tessellation of Mitsuba's analytic shapes (rectangle, cube, disk, sphere, cylinder) in
// their object-space conventions, and the transform-and-append step shared by
// every shape loader.
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <tuple>
#include <glm/gtc/constants.hpp>

#include "scene/loaders.h"

namespace psf::detail {

TriMesh make_rectangle() {
  TriMesh m;
  m.positions = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  m.uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};  // Mitsuba's: (x, y) * 0.5 + 0.5
  return m;
}

TriMesh make_cube() {
  // Mitsuba 3's cube, vertex for vertex (src/shapes/cube.cpp as 3.6 builds it):
  // four vertices per face, in the order -y, +y, +x, +z, -x, -z, each face's
  // uv (0, 1), (1, 1), (1, 0), (0, 0) at its corners in that order, and the
  // triangles (a, b, c), (d, a, c), counter-clockwise seen from outside.
  TriMesh m;
  m.positions = {{1, -1, -1}, {1, -1, 1},   {-1, -1, 1}, {-1, -1, -1},  // -y
                 {1, 1, -1},  {-1, 1, -1},  {-1, 1, 1},  {1, 1, 1},     // +y
                 {1, -1, -1}, {1, 1, -1},   {1, 1, 1},   {1, -1, 1},    // +x
                 {1, -1, 1},  {1, 1, 1},    {-1, 1, 1},  {-1, -1, 1},   // +z
                 {-1, -1, 1}, {-1, 1, 1},   {-1, 1, -1}, {-1, -1, -1},  // -x
                 {1, 1, -1},  {1, -1, -1},  {-1, -1, -1}, {-1, 1, -1}};  // -z
  for (uint32_t f = 0; f < 6; ++f) {
    const uint32_t a = 4 * f;
    m.uvs.insert(m.uvs.end(), {{0, 1}, {1, 1}, {1, 0}, {0, 0}});
    m.triangles.push_back({a, a + 1, a + 2});
    m.triangles.push_back({a + 3, a, a + 2});
  }
  return m;
}

TriMesh make_disk(int segments) {
  TriMesh m;
  // Mitsuba's uv: (r, phi / 2pi). Rim vertex i at phi_i = 2pi i / segments, the
  // seam's twice (v = 0 and 1); each triangle its own centre vertex, at the v of
  // the middle of its sector, so that v does not sweep across the fan there.
  for (int i = 0; i <= segments; ++i) {
    float phi = 2 * glm::pi<float>() * float(i % segments) / float(segments);
    m.positions.push_back({std::cos(phi), std::sin(phi), 0});
    m.uvs.push_back({1.0f, float(i) / float(segments)});
  }
  for (int i = 0; i < segments; ++i) {
    uint32_t centre = uint32_t(m.positions.size());
    m.positions.push_back({0, 0, 0});
    m.uvs.push_back({0.0f, (float(i) + 0.5f) / float(segments)});
    m.triangles.push_back({centre, uint32_t(i), uint32_t(i + 1)});
  }
  return m;
}

TriMesh make_sphere(const glm::vec3& center, float radius, int rings, int segments) {
  TriMesh m;
  // Vertex (ring r, segment s) for 0 < r < rings and 0 <= s <= segments (the
  // seam s = segments repeats s = 0 with u = 1); the poles are separate
  // vertices. Normals are the sphere's, uv Mitsuba's (phi / 2pi, theta / pi).
  auto add = [&](const glm::vec3& d, const glm::vec2& uv) {
    m.positions.push_back(center + radius * d);
    m.normals.push_back(d);
    m.uvs.push_back(uv);
  };
  add({0, 0, 1}, {0.5f, 0.0f});
  for (int r = 1; r < rings; ++r) {
    float theta = glm::pi<float>() * float(r) / float(rings);
    for (int s = 0; s <= segments; ++s) {
      float phi = 2 * glm::pi<float>() * float(s % segments) / float(segments);
      glm::vec3 d(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
      add(d, {float(s) / float(segments), float(r) / float(rings)});
    }
  }
  uint32_t south = uint32_t(m.positions.size());
  add({0, 0, -1}, {0.5f, 1.0f});
  auto at = [&](int r, int s) { return uint32_t(1 + (r - 1) * (segments + 1) + s); };
  for (int s = 0; s < segments; ++s) {
    // theta grows towards -z and phi counter-clockwise around +z: (r, s), (r+1, s), (r+1, s+1) faces outwards.
    m.triangles.push_back({0, at(1, s), at(1, s + 1)});
    for (int r = 1; r + 1 < rings; ++r) {
      m.triangles.push_back({at(r, s), at(r + 1, s), at(r + 1, s + 1)});
      m.triangles.push_back({at(r, s), at(r + 1, s + 1), at(r, s + 1)});
    }
    m.triangles.push_back({at(rings - 1, s), south, at(rings - 1, s + 1)});
  }
  return m;
}

TriMesh make_cylinder(const glm::vec3& p0, const glm::vec3& p1, float radius, int segments) {
  TriMesh m;
  // Mitsuba 3's frame about the axis d (Duff et al. 2017, its coordinate_system):
  // the local point (cos phi, sin phi, z) lies at p0 + radius (cos phi s + sin phi t) + z (p1 - p0).
  const glm::vec3 axis = p1 - p0, d = glm::normalize(axis);
  const float sign = d.z >= 0.0f ? 1.0f : -1.0f, a = -1.0f / (sign + d.z), b = d.x * d.y * a;
  const glm::vec3 s(1.0f + sign * d.x * d.x * a, sign * b, -sign * d.x), t(b, sign + d.y * d.y * a, -d.y);
  for (int i = 0; i <= segments; ++i) {  // the seam i = segments repeats i = 0 with u = 1
    float phi = 2 * glm::pi<float>() * float(i % segments) / float(segments);
    glm::vec3 radial = std::cos(phi) * s + std::sin(phi) * t;
    for (int z = 0; z < 2; ++z) {
      m.positions.push_back(p0 + radius * radial + float(z) * axis);
      m.normals.push_back(radial);
      m.uvs.push_back({float(i) / float(segments), float(z)});  // Mitsuba's: (phi / 2pi, z)
    }
  }
  for (int i = 0; i < segments; ++i) {
    // Bottom (2i), top (2i + 1); phi grows counter-clockwise about d, so
    // (bottom i, bottom i+1, top i+1) faces outwards.
    uint32_t b0 = uint32_t(2 * i), t0 = b0 + 1, b1 = b0 + 2, t1 = b0 + 3;
    m.triangles.push_back({b0, b1, t1});
    m.triangles.push_back({b0, t1, t0});
  }
  return m;
}

void compute_vertex_normals(TriMesh& mesh) {
  std::vector<glm::dvec3> sum(mesh.positions.size(), glm::dvec3(0.0));
  for (const glm::uvec3& t : mesh.triangles) {
    glm::dvec3 p[3] = {mesh.positions[t.x], mesh.positions[t.y], mesh.positions[t.z]};
    glm::dvec3 n = glm::cross(p[1] - p[0], p[2] - p[0]);
    double len = glm::length(n);
    if (!(len > 0.0)) continue;
    n /= len;
    for (int k = 0; k < 3; ++k) {
      glm::dvec3 a = p[(k + 1) % 3] - p[k], b = p[(k + 2) % 3] - p[k];
      double la = glm::length(a), lb = glm::length(b);
      if (!(la > 0.0 && lb > 0.0)) continue;
      double angle = std::acos(std::clamp(glm::dot(a, b) / (la * lb), -1.0, 1.0));
      sum[t[k]] += n * angle;
    }
  }
  mesh.normals.resize(mesh.positions.size());
  for (size_t i = 0; i < sum.size(); ++i) {
    double len = glm::length(sum[i]);
    mesh.normals[i] = len > 0.0 ? glm::vec3(sum[i] / len) : glm::vec3(0.0f);
  }
}

void compute_vertex_tangents(TriMesh& mesh) {
  const size_t nv = mesh.positions.size();
  if (mesh.normals.size() != nv || mesh.uvs.size() != nv) return;
  std::vector<glm::dvec3> tsum(nv, glm::dvec3(0.0)), bsum(nv, glm::dvec3(0.0));
  for (const glm::uvec3& t : mesh.triangles) {
    glm::dvec3 p[3] = {mesh.positions[t.x], mesh.positions[t.y], mesh.positions[t.z]};
    glm::dvec2 uv[3] = {mesh.uvs[t.x], mesh.uvs[t.y], mesh.uvs[t.z]};
    glm::dvec3 e1 = p[1] - p[0], e2 = p[2] - p[0];
    glm::dvec2 d1 = uv[1] - uv[0], d2 = uv[2] - uv[0];
    double det = d1.x * d2.y - d2.x * d1.y;
    if (!(std::abs(det) > 0.0) || !std::isfinite(det)) continue;
    // dp/du, and dp/dv with v upwards in the image (glTF's v runs downwards;
    // MikkTSpace as Blender runs it sees 1 - v).
    glm::dvec3 dpdu = (e1 * d2.y - e2 * d1.y) / det, dpdv_up = -(e2 * d1.x - e1 * d2.x) / det;
    for (int k = 0; k < 3; ++k) {
      glm::dvec3 a = p[(k + 1) % 3] - p[k], b = p[(k + 2) % 3] - p[k];
      double la = glm::length(a), lb = glm::length(b);
      if (!(la > 0.0 && lb > 0.0)) continue;
      double angle = std::acos(std::clamp(glm::dot(a, b) / (la * lb), -1.0, 1.0));
      glm::dvec3 n = glm::dvec3(mesh.normals[t[k]]);
      glm::dvec3 tk = dpdu - n * glm::dot(n, dpdu), bk = dpdv_up - n * glm::dot(n, dpdv_up);
      double lt = glm::length(tk), lbk = glm::length(bk);
      if (lt > 0.0) tsum[t[k]] += tk * (angle / lt);
      if (lbk > 0.0) bsum[t[k]] += bk * (angle / lbk);
    }
  }
  mesh.tangents.assign(nv, glm::vec4(0.0f));
  for (size_t i = 0; i < nv; ++i) {
    glm::dvec3 n = glm::dvec3(mesh.normals[i]), tv = tsum[i] - n * glm::dot(n, tsum[i]);
    double len = glm::length(tv);
    if (!(len > 1e-12) || !std::isfinite(len)) continue;  // none: the kernel falls back to dp/du
    tv /= len;
    mesh.tangents[i] = glm::vec4(glm::vec3(tv), glm::dot(glm::cross(n, tv), bsum[i]) < 0.0 ? -1.0f : 1.0f);
  }
}

void compute_crease_normals(TriMesh& mesh, float max_angle_degrees) {
  const size_t nt = mesh.triangles.size();
  // Unit face normals and each corner's angle.
  std::vector<glm::dvec3> face(nt, glm::dvec3(0.0));
  std::vector<glm::dvec3> angle(nt, glm::dvec3(0.0));
  for (size_t t = 0; t < nt; ++t) {
    const glm::uvec3 tri = mesh.triangles[t];
    glm::dvec3 p[3] = {mesh.positions[tri.x], mesh.positions[tri.y], mesh.positions[tri.z]};
    glm::dvec3 n = glm::cross(p[1] - p[0], p[2] - p[0]);
    double len = glm::length(n);
    if (!(len > 0.0)) continue;
    face[t] = n / len;
    for (int k = 0; k < 3; ++k) {
      glm::dvec3 a = p[(k + 1) % 3] - p[k], b = p[(k + 2) % 3] - p[k];
      double la = glm::length(a), lb = glm::length(b);
      if (la > 0.0 && lb > 0.0) angle[t][k] = std::acos(std::clamp(glm::dot(a, b) / (la * lb), -1.0, 1.0));
    }
  }
  // The corners at each position (vertices with equal coordinates are one).
  std::map<std::tuple<float, float, float>, std::vector<std::pair<uint32_t, int>>> at;
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const glm::vec3& p = mesh.positions[mesh.triangles[t][k]];
      at[{p.x, p.y, p.z}].push_back({uint32_t(t), k});
    }
  const double min_cos = std::cos(glm::radians(double(max_angle_degrees)));
  TriMesh out;
  out.triangles.resize(nt);
  std::map<std::tuple<uint32_t, float, float, float>, uint32_t> made;  // (vertex, normal) -> new vertex
  for (const auto& entry : at) {
    const auto& corners = entry.second;
    for (const auto& [t, k] : corners) {
      glm::dvec3 sum(0.0);
      for (const auto& [u, j] : corners)
        if (glm::dot(face[t], face[u]) >= min_cos) sum += face[u] * angle[u][j];
      const double len = glm::length(sum);
      const glm::vec3 n = len > 0.0 ? glm::vec3(sum / len) : glm::vec3(face[t]);
      const uint32_t v = mesh.triangles[t][k];
      auto [it, fresh] = made.insert({{v, n.x, n.y, n.z}, uint32_t(out.positions.size())});
      if (fresh) {
        out.positions.push_back(mesh.positions[v]);
        out.normals.push_back(n);
        if (!mesh.uvs.empty()) out.uvs.push_back(mesh.uvs[v]);
        if (!mesh.tangents.empty()) out.tangents.push_back(mesh.tangents[v]);
        if (!mesh.colors.empty()) out.colors.push_back(mesh.colors[v]);
      }
      out.triangles[t][k] = it->second;
    }
  }
  mesh = std::move(out);
}

void append_mesh(Scene& scene, const TriMesh& mesh, const glm::mat4& to_world, uint32_t material, bool flip,
                 const std::string& file, int line) {
  uint32_t base = uint32_t(scene.positions.size());
  // Shading normals and uvs: per vertex of the scene once any mesh has them;
  // (0,0,0) and NaN mark the vertices of meshes without.
  const bool has_normals = mesh.normals.size() == mesh.positions.size() && !mesh.positions.empty();
  const bool has_uvs = mesh.uvs.size() == mesh.positions.size() && !mesh.positions.empty();
  const glm::vec2 no_uv(std::numeric_limits<float>::quiet_NaN());
  if (has_normals || !scene.normals.empty()) {
    scene.normals.resize(base, glm::vec3(0.0f));
    glm::mat3 normal_matrix = glm::transpose(glm::inverse(glm::mat3(to_world)));
    for (size_t i = 0; i < mesh.positions.size(); ++i) {
      glm::vec3 n(0.0f);
      if (has_normals && glm::dot(mesh.normals[i], mesh.normals[i]) > 0.0f) {
        n = normal_matrix * mesh.normals[i];
        float len = glm::length(n);
        n = len > 0.0f && std::isfinite(len) ? n / len * (flip ? -1.0f : 1.0f) : glm::vec3(0.0f);
      }
      scene.normals.push_back(n);
    }
  }
  // Tangents are directions in the surface: they transform as positions do. The
  // bitangent w n x t turns with a mirroring transform and with flipped normals.
  const bool has_tangents = mesh.tangents.size() == mesh.positions.size() && has_normals;
  if (has_tangents || !scene.tangents.empty()) {
    scene.tangents.resize(base, glm::vec4(0.0f));
    const glm::mat3 m(to_world);
    const float hand = (glm::determinant(m) < 0.0f ? -1.0f : 1.0f) * (flip ? -1.0f : 1.0f);
    for (size_t i = 0; i < mesh.positions.size(); ++i) {
      glm::vec4 t(0.0f);
      if (has_tangents && (mesh.tangents[i].w == 1.0f || mesh.tangents[i].w == -1.0f)) {
        glm::vec3 d = m * glm::vec3(mesh.tangents[i]);
        float len = glm::length(d);
        if (len > 0.0f && std::isfinite(len)) t = glm::vec4(d / len, mesh.tangents[i].w * hand);
      }
      scene.tangents.push_back(t);
    }
  }
  if (has_uvs || !scene.uvs.empty()) {
    scene.uvs.resize(base, no_uv);
    for (size_t i = 0; i < mesh.positions.size(); ++i) scene.uvs.push_back(has_uvs ? mesh.uvs[i] : no_uv);
  }
  // Vertex colours, clamped to [0, 1] (a NaN one is none: x = -1).
  const bool has_colors = mesh.colors.size() == mesh.positions.size() && !mesh.positions.empty();
  if (has_colors || !scene.colors.empty()) {
    const glm::vec3 none(-1.0f);
    scene.colors.resize(base, none);
    for (size_t i = 0; i < mesh.positions.size(); ++i) {
      const glm::vec3 c = has_colors ? mesh.colors[i] : none;
      const bool ok = has_colors && std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.z);
      scene.colors.push_back(ok ? glm::clamp(c, 0.0f, 1.0f) : none);
    }
  }
  // The arrays grow geometrically (reserving each mesh's exact size copied every
  // earlier mesh's vertices again); load_scene trims them once.
  for (const glm::vec3& p : mesh.positions) {
    glm::vec4 w = to_world * glm::vec4(p, 1.0f);
    glm::vec3 q = glm::vec3(w) / w.w;
    if (!std::isfinite(q.x) || !std::isfinite(q.y) || !std::isfinite(q.z))
      throw SceneError(file, line, "transformed vertex position is not finite (check to_world)");
    scene.positions.push_back(q);
  }
  for (const glm::uvec3& t : mesh.triangles) {
    glm::uvec3 tri = t + glm::uvec3(base);
    scene.triangles.push_back(flip ? glm::uvec3(tri.x, tri.z, tri.y) : tri);
  }
  scene.tri_material.insert(scene.tri_material.end(), mesh.triangles.size(), material);
}

}  // namespace psf::detail
