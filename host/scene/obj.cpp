// Wavefront OBJ loading with tinyobjloader: used by <shape type="obj"> in Mitsuba
// scenes (geometry only) and by load_scene("x.obj") (geometry, MTL Kd/Ke, a
// camera framing the model).
//
// tinyobjloader is asked not to triangulate: its triangulation reads vertex
// positions before indices are range-checked, and Mitsuba triangulates polygons
// as fans, which read_obj does after checking every index.
#include <tiny_obj_loader.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include "scene/loaders.h"

namespace psf::detail {
namespace {

bool is_blank(char c) { return c == ' ' || c == '\t'; }

// Calls `fn(line_number, line_begin, line_end)` for each line of `text` that
// starts (after blanks) with the OBJ keyword `key` followed by a blank; stops
// early when `fn` returns false.
template <typename Fn>
void for_each_keyword_line(const std::string& text, const char* key, Fn fn) {
  size_t key_len = std::char_traits<char>::length(key);
  int line = 0;
  for (size_t pos = 0; pos < text.size();) {
    size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    ++line;
    size_t p = pos;
    while (p < end && is_blank(text[p])) ++p;
    if (end - p > key_len && text.compare(p, key_len, key) == 0 && is_blank(text[p + key_len])) {
      if (!fn(line, text.data() + p + key_len, text.data() + end)) return;
    }
    pos = end + 1;
  }
}

// Number of blank-separated tokens in [begin, end), ignoring a trailing comment or CR.
int count_tokens(const char* begin, const char* end) {
  int n = 0;
  bool in_token = false;
  for (const char* c = begin; c < end && *c != '#' && *c != '\r'; ++c) {
    bool blank = is_blank(*c);
    if (!blank && !in_token) ++n;
    in_token = !blank;
  }
  return n;
}

// The line of the `index`-th (0-based) face with at least 3 vertices, the faces tinyobjloader keeps.
int face_line(const std::string& text, size_t index) {
  int found = 0;
  size_t seen = 0;
  for_each_keyword_line(text, "f", [&](int line, const char* b, const char* e) {
    if (count_tokens(b, e) < 3) return true;
    if (seen++ == index) {
      found = line;
      return false;
    }
    return true;
  });
  return found;
}

// Throws if a vertex line holds a coordinate that is not a finite number:
// tinyobjloader reads "nan" and "inf" as 0.
void check_finite_vertices(const std::string& text, const std::string& path) {
  for_each_keyword_line(text, "v", [&](int line, const char* b, const char* e) {
    std::string rest(b, e);
    const char* c = rest.c_str();
    for (int i = 0; i < 3; ++i) {
      char* next = nullptr;
      double x = std::strtod(c, &next);
      if (next == c) break;
      if (!std::isfinite(x)) throw SceneError(path, line, "vertex position is not finite: v" + rest);
      c = next;
    }
    return true;
  });
}

// The line number tinyobjloader names in an error message ("... line 12 ..."), 0 if none.
int line_in_message(const std::string& message) {
  size_t at = message.find("line ");
  if (at == std::string::npos) return 0;
  return std::atoi(message.c_str() + at + 5);
}

std::string trim_newlines(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r' || s.back() == '.')) s.pop_back();
  return s;
}

}  // namespace

ObjData read_obj(const std::string& path, bool with_materials) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path, 0, "cannot open OBJ file");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  check_finite_vertices(text, path);

  tinyobj::attrib_t attrib;
  std::vector<tinyobj::shape_t> shapes;
  std::vector<tinyobj::material_t> materials;
  std::string warn, err;
  std::istringstream stream(text);
  std::string base_dir = std::filesystem::path(path).parent_path().string();
  tinyobj::MaterialFileReader mtl_reader(base_dir.empty() ? "." : base_dir);
  bool ok = tinyobj::LoadObj(&attrib, &shapes, &materials, &warn, &err, &stream, with_materials ? &mtl_reader : nullptr,
                             /*triangulate=*/false,
                             /*default_vcols_fallback=*/false);
  if (!ok || !err.empty()) {
    std::string message = trim_newlines(err.empty() ? "tinyobjloader failed" : err);
    throw SceneError(path, line_in_message(message), "OBJ parse error: " + message);
  }

  ObjData data;
  std::istringstream warnings(warn);
  for (std::string line; std::getline(warnings, line);) {
    // The end-of-file index bounds messages are replaced by the exact check below;
    // without an MTL library, usemtl lines are expected not to resolve.
    bool about_materials = line.find("aterial") != std::string::npos || line.find("mtl") != std::string::npos;
    if (line.empty() || line == "." || line.find("indices out of bounds") != std::string::npos ||
        (!with_materials && about_materials))
      continue;
    std::string message = path + ": " + line;
    if (std::find(data.warnings.begin(), data.warnings.end(), message) == data.warnings.end())
      data.warnings.push_back(message);
  }

  const size_t num_vertices = attrib.vertices.size() / 3;
  std::vector<int64_t> remap(num_vertices, -1);
  size_t face_index = 0;
  for (const tinyobj::shape_t& shape : shapes) {
    const tinyobj::mesh_t& mesh = shape.mesh;
    size_t offset = 0;
    for (size_t f = 0; f < mesh.num_face_vertices.size(); ++f, ++face_index) {
      size_t n = mesh.num_face_vertices[f];
      uint32_t corner[3] = {0, 0, 0};
      for (size_t k = 0; k < n; ++k) {
        int idx = mesh.indices[offset + k].vertex_index;
        if (idx < 0 || size_t(idx) >= num_vertices) {
          std::string given = idx < 0 ? std::to_string(idx - int(num_vertices)) : std::to_string(idx + 1);
          throw SceneError(path, face_line(text, face_index),
                           "face vertex index " + given + " out of range (the file has " +
                               std::to_string(num_vertices) + " vertices)");
        }
        if (remap[size_t(idx)] < 0) {
          remap[size_t(idx)] = int64_t(data.mesh.positions.size());
          const float* p = &attrib.vertices[3 * size_t(idx)];
          data.mesh.positions.emplace_back(p[0], p[1], p[2]);
        }
        uint32_t v = uint32_t(remap[size_t(idx)]);
        // Fan triangulation: (0, k-1, k) for k >= 2.
        if (k == 0) corner[0] = v;
        corner[1] = corner[2];
        corner[2] = v;
        if (k >= 2) {
          data.mesh.triangles.push_back({corner[0], corner[1], corner[2]});
          data.tri_material.push_back(f < mesh.material_ids.size() ? mesh.material_ids[f] : -1);
        }
      }
      offset += n;
    }
  }

  for (const tinyobj::material_t& m : materials) {
    ObjMaterial om;
    om.name = m.name;
    om.kd = {m.diffuse[0], m.diffuse[1], m.diffuse[2]};
    om.ke = {m.emission[0], m.emission[1], m.emission[2]};
    om.textured = !m.diffuse_texname.empty() || !m.emissive_texname.empty() || !m.alpha_texname.empty() ||
                  !m.bump_texname.empty() || !m.normal_texname.empty();
    data.materials.push_back(om);
  }
  return data;
}

CameraDesc camera_framing(const std::vector<glm::vec3>& positions) {
  CameraDesc cam;
  cam.fov_degrees = 45.0f;
  cam.fov_axis = "larger";
  if (positions.empty()) return cam;
  glm::vec3 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
  for (const glm::vec3& p : positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  glm::vec3 center = 0.5f * (lo + hi), extent = hi - lo;
  // The half-extent in x and y must fit the half field of view at the box's front face (z = hi.z).
  float half = 0.5f * std::max({extent.x, extent.y, 1e-6f * glm::length(extent), 1e-6f});
  float distance = half / std::tan(glm::radians(cam.fov_degrees) * 0.5f) * 1.05f;
  cam.target = center;
  cam.origin = center + glm::vec3(0, 0, 0.5f * extent.z + distance);
  cam.up = {0, 1, 0};
  return cam;
}

Scene load_obj_scene(const std::string& path) {
  ObjData obj = read_obj(path, true);
  Scene scene;
  scene.warnings = obj.warnings;

  // OBJ has no notion of one-sided surfaces: every material scatters and emits on both sides.
  std::vector<uint32_t> material_index(obj.materials.size());
  bool any_textured = false;
  for (size_t i = 0; i < obj.materials.size(); ++i) {
    const ObjMaterial& om = obj.materials[i];
    Material m{};
    m.albedo = {{om.kd.x, om.kd.y, om.kd.z, 0}};
    m.emission = {{om.ke.x, om.ke.y, om.ke.z, 0}};
    m.type = PSF_MATERIAL_DIFFUSE;
    m.two_sided = 1;
    material_index[i] = uint32_t(scene.materials.size());
    scene.materials.push_back(m);
    scene.material_names.push_back(om.name);
    any_textured = any_textured || om.textured;
  }
  if (any_textured) scene.warnings.push_back(path + ": MTL texture maps are not supported yet; using Kd and Ke");

  uint32_t default_material = uint32_t(-1);
  std::vector<uint32_t> tri_material(obj.tri_material.size());
  for (size_t t = 0; t < obj.tri_material.size(); ++t) {
    int m = obj.tri_material[t];
    if (m >= 0 && size_t(m) < material_index.size()) {
      tri_material[t] = material_index[size_t(m)];
      continue;
    }
    if (default_material == uint32_t(-1)) {
      Material d{};
      d.albedo = {{0.5f, 0.5f, 0.5f, 0}};
      d.type = PSF_MATERIAL_DIFFUSE;
      d.two_sided = 1;
      default_material = uint32_t(scene.materials.size());
      scene.materials.push_back(d);
      scene.material_names.push_back("default");
    }
    tri_material[t] = default_material;
  }

  scene.positions = std::move(obj.mesh.positions);
  scene.triangles = std::move(obj.mesh.triangles);
  scene.tri_material = std::move(tri_material);
  scene.camera = camera_framing(scene.positions);
  scene.width = 512;
  scene.height = 512;
  return scene;
}

}  // namespace psf::detail
