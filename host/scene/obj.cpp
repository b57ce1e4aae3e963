// Wavefront OBJ loading with tinyobjloader: used by <shape type="obj"> in Mitsuba
// scenes (geometry, vertex normals and uvs) and by load_scene("x.obj") (the same,
// MTL materials mapped onto the BSDFs with their textures, a camera framing the model).
//
// tinyobjloader is asked not to triangulate: its triangulation reads vertex
// positions before indices are range-checked, and Mitsuba triangulates polygons
// as fans, which read_obj does after checking every index.
#include <tiny_obj_loader.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <unordered_map>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include "scene/loaders.h"
#include "scene/materials.h"

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
      if (!std::isfinite(x) || !std::isfinite(float(x)))  // 1e39 is finite, but not as a float
        throw SceneError(path, line, "vertex position is not finite: v" + rest);
      c = next;
    }
    return true;
  });
}

// Throws if a face's index (of a position, texture coordinate or normal) lies
// outside the range of an int: tinyobjloader's parser wraps it around, so that
// 4294967299 would be vertex 3.
void check_face_index_range(const std::string& text, const std::string& path) {
  for_each_keyword_line(text, "f", [&](int line, const char* b, const char* e) {
    for (const char* c = b; c < e && *c != '#';) {
      if (*c == '-' || (*c >= '0' && *c <= '9')) {
        const char* start = c;
        if (*c == '-') ++c;
        while (c < e && *c == '0') ++c;  // leading zeros
        const char* digits = c;
        while (c < e && *c >= '0' && *c <= '9') ++c;
        if (c - digits > 10 || (c - digits == 10 && std::string(digits, c) > "2147483647"))
          throw SceneError(path, line, "face index " + std::string(start, c) + " is out of range");
      } else {
        ++c;
      }
    }
    return true;
  });
}

// Throws at the line of an MTL colour or number whose value is not a finite
// number ("Kd nan", "Ns high"): tinyobjloader reads such a value as 0 and says
// nothing. The spectral and CIE XYZ forms of a colour (Kd spectral FILE, Kd xyz
// X Y Z), which tinyobjloader does not read either, are left alone, and so is
// the -halo of a dissolve (d -halo FACTOR).
void check_mtl_numbers(const std::string& text, const std::string& path) {
  static const char* const keys[] = {"Ka", "Kd", "Ks", "Ke", "Kt", "Tf", "Ns", "Ni", "d", "Tr", "Pr", "Pm", "Pc", "Pcr"};
  for (const char* key : keys)
    for_each_keyword_line(text, key, [&](int line, const char* b, const char* e) {
      std::istringstream tokens(std::string(b, std::find_if(b, e, [](char c) { return c == '#' || c == '\r'; })));
      bool first = true;
      for (std::string token; tokens >> token; first = false) {
        if (first && (token == "spectral" || token == "xyz")) return true;
        if (first && token == "-halo") continue;  // "d -halo FACTOR": its factor is checked
        const char* begin = token.c_str();
        char* end = nullptr;
        const double v = std::strtod(begin, &end);
        if (end == begin || *end != '\0' || !std::isfinite(v) || std::abs(v) > double(std::numeric_limits<float>::max()))
          throw SceneError(path, line, std::string(key) + ": '" + token + "' is not a finite number");
      }
      return true;
    });
}

// Throws if an mtllib names a folder: reading one throws deep inside the reader.
void check_mtllib_files(const std::string& text, const std::string& path, const std::string& base_dir) {
  for_each_keyword_line(text, "mtllib", [&](int line, const char* b, const char* e) {
    std::istringstream names(std::string(b, e));
    for (std::string name; names >> name;)
      if (const std::string why =
              unreadable_input((std::filesystem::path(base_dir.empty() ? "." : base_dir) / name).string());
          !why.empty())
        throw SceneError(path, line, "mtllib '" + name + "' " + (why == "is a folder" ? why + ", not an MTL file" : why));
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
  require_readable_input(path, "OBJ file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path, 0, "cannot open OBJ file");
  std::string text = read_all(in);
  check_finite_vertices(text, path);

  tinyobj::attrib_t attrib;
  std::vector<tinyobj::shape_t> shapes;
  std::vector<tinyobj::material_t> materials;
  std::string warn, err;
  std::istringstream stream(text);
  std::string base_dir = std::filesystem::path(path).parent_path().string();
  check_face_index_range(text, path);
  if (with_materials) check_mtllib_files(text, path, base_dir);
  tinyobj::MaterialFileReader mtl_reader(base_dir.empty() ? "." : base_dir);
  bool ok = tinyobj::LoadObj(&attrib, &shapes, &materials, &warn, &err, &stream, with_materials ? &mtl_reader : nullptr,
                             /*triangulate=*/false,
                             /*default_vcols_fallback=*/false);
  if (!ok || !err.empty()) {
    std::string message = trim_newlines(err.empty() ? "tinyobjloader failed" : err);
    throw SceneError(path, line_in_message(message), "OBJ parse error: " + message);
  }

  ObjData data;
  // The line of each material name's first usemtl, found in one pass when a
  // warning needs one (tinyobjloader warns at every usemtl of a missing material).
  std::map<std::string, int> first_usemtl;
  bool usemtl_scanned = false;
  auto usemtl_line = [&](const std::string& name) {
    if (!usemtl_scanned) {
      usemtl_scanned = true;
      std::istringstream lines(text);
      int number = 0;
      for (std::string l; std::getline(lines, l);) {
        ++number;
        std::istringstream words(l);
        std::string keyword, used;
        if (words >> keyword >> used && keyword == "usemtl") first_usemtl.emplace(used, number);
      }
    }
    auto it = first_usemtl.find(name);
    return it == first_usemtl.end() ? 0 : it->second;
  };
  std::istringstream warnings(warn);
  for (std::string line; std::getline(warnings, line);) {
    // The end-of-file index bounds messages are replaced by the exact check below;
    // without an MTL library, usemtl lines are expected not to resolve.
    bool about_materials = line.find("aterial") != std::string::npos || line.find("mtl") != std::string::npos;
    // "Both d and Tr defined ... use d": d is what the material mapping reads, nothing is lost.
    bool d_and_tr = line.find("Both `d` and `Tr`") != std::string::npos;
    if (line.empty() || line == "." || line.find("indices out of bounds") != std::string::npos ||
        (!with_materials && about_materials) || d_and_tr)
      continue;
    std::string message = path + ": " + line;
    // tinyobjloader's "material [ 'NAME' ] not found in .mtl": with the line of
    // the first usemtl of NAME and what becomes of its faces.
    const size_t open = line.find("material [ '"), close = line.find("' ] not found");
    if (open != std::string::npos && close != std::string::npos && close > open + 12) {
      const std::string name = line.substr(open + 12, close - open - 12);
      const int first = usemtl_line(name);
      message = path + (first > 0 ? ":" + std::to_string(first) : std::string()) + ": usemtl '" + name +
                "': no such material in the MTL library; its faces are diffuse grey";
    }
    if (std::find(data.warnings.begin(), data.warnings.end(), message) == data.warnings.end())
      data.warnings.push_back(message);
  }

  // Vertex colours ("v x y z r g b"; tinyobjloader gives 1 where a vertex has
  // none): used where some vertex has one other than white.
  const bool with_colors = attrib.colors.size() == attrib.vertices.size() &&
                           std::any_of(attrib.colors.begin(), attrib.colors.end(), [](float c) { return c != 1.0f; });
  const size_t num_vertices = attrib.vertices.size() / 3;
  const size_t num_uvs = attrib.texcoords.size() / 2;
  const size_t num_normals = attrib.normals.size() / 3;
  // One vertex per distinct (position, uv, normal) index triple, as Mitsuba's OBJ loader.
  struct TripleHash {
    size_t operator()(const std::array<int, 3>& a) const {
      return size_t(uint32_t(a[0])) * 0x9E3779B97F4A7C15ull ^ size_t(uint32_t(a[1] + 1)) * 0xC2B2AE3D27D4EB4Full ^
             size_t(uint32_t(a[2] + 1)) * 0x165667B19E3779F9ull;
    }
  };
  std::unordered_map<std::array<int, 3>, uint32_t, TripleHash> remap;
  std::vector<std::array<int, 3>> corners;  // the triple of each new vertex
  auto out_of_range = [&](size_t face_index, const char* what, int idx, size_t count) {
    std::string given = idx < 0 ? std::to_string(idx - int(count)) : std::to_string(idx + 1);
    throw SceneError(path, face_line(text, face_index),
                     std::string("face ") + what + " index " + given + " out of range (the file has " +
                         std::to_string(count) + " " + what + (count == 1 ? "" : "s") + ")");
  };
  if (num_normals == 0 && with_materials)
    for (const tinyobj::shape_t& shape : shapes)
      for (unsigned group : shape.mesh.smoothing_group_ids) data.smoothing_groups = data.smoothing_groups || group != 0;
  size_t face_index = 0;
  for (const tinyobj::shape_t& shape : shapes) {
    const tinyobj::mesh_t& mesh = shape.mesh;
    size_t offset = 0;
    for (size_t f = 0; f < mesh.num_face_vertices.size(); ++f, ++face_index) {
      size_t n = mesh.num_face_vertices[f];
      uint32_t corner[3] = {0, 0, 0};
      for (size_t k = 0; k < n; ++k) {
        const tinyobj::index_t& ix = mesh.indices[offset + k];
        int idx = ix.vertex_index, ti = ix.texcoord_index, ni = ix.normal_index;
        if (idx < 0 || size_t(idx) >= num_vertices) {
          std::string given = idx < 0 ? std::to_string(idx - int(num_vertices)) : std::to_string(idx + 1);
          throw SceneError(path, face_line(text, face_index),
                           "face vertex index " + given + " out of range (the file has " +
                               std::to_string(num_vertices) + " vertices)");
        }
        if (ti >= 0 && size_t(ti) >= num_uvs) out_of_range(face_index, "texture coordinate", ti, num_uvs);
        if (ni >= 0 && size_t(ni) >= num_normals) out_of_range(face_index, "normal", ni, num_normals);
        if (ti < -1) ti = -1;
        if (ni < -1) ni = -1;
        int key_n = ni;  // the key's third part: the normal, or without any, the smoothing group
        if (data.smoothing_groups) {
          const unsigned group = f < mesh.smoothing_group_ids.size() ? mesh.smoothing_group_ids[f] : 0u;
          key_n = group != 0 ? -2 - int(group & 0x1fffffffu)                           // shared within the group
                             : std::numeric_limits<int>::min() + int(face_index & 0x3fffffffu);  // this face's own
        }
        auto [it, inserted] = remap.emplace(std::array<int, 3>{idx, ti, key_n}, uint32_t(corners.size()));
        if (inserted) corners.push_back(it->first);
        uint32_t v = it->second;
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
  bool any_uv = false, any_normal = false;
  for (const auto& c : corners) {
    any_uv = any_uv || c[1] >= 0;
    any_normal = any_normal || c[2] >= 0;
  }
  data.mesh.positions.reserve(corners.size());
  for (const auto& c : corners) {
    const float* p = &attrib.vertices[3 * size_t(c[0])];
    data.mesh.positions.emplace_back(p[0], p[1], p[2]);
    if (with_colors) {
      const float* q = &attrib.colors[3 * size_t(c[0])];
      data.mesh.colors.emplace_back(q[0], q[1], q[2]);
    }
    if (any_uv) {
      // OBJ's v points up the image; Mitsuba's (and the texture table's) down.
      const float nan = std::numeric_limits<float>::quiet_NaN();
      data.mesh.uvs.push_back(c[1] >= 0 ? glm::vec2(attrib.texcoords[2 * size_t(c[1])],
                                                    1.0f - attrib.texcoords[2 * size_t(c[1]) + 1])
                                        : glm::vec2(nan));
    }
    if (any_normal) {
      glm::vec3 nv(0.0f);
      if (c[2] >= 0) {
        const float* q = &attrib.normals[3 * size_t(c[2])];
        nv = glm::vec3(q[0], q[1], q[2]);
        float len = glm::length(nv);
        nv = len > 0.0f && std::isfinite(len) ? nv / len : glm::vec3(0.0f);
      }
      data.mesh.normals.push_back(nv);
    }
  }

  // Where each material is defined, for messages: the newmtl lines of the mtllib files.
  std::map<std::string, std::pair<std::string, int>> defined_at;
  if (with_materials) {
    for_each_keyword_line(text, "mtllib", [&](int, const char* b, const char* e) {
      std::istringstream names(std::string(b, e));
      for (std::string name; names >> name;) {
        std::string mtl = (std::filesystem::path(base_dir) / name).string();
        std::ifstream m(mtl, std::ios::binary);
        if (!m) continue;
        std::string mtext = read_all(m);
        check_mtl_numbers(mtext, mtl);
        for_each_keyword_line(mtext, "newmtl", [&](int line, const char* nb, const char* ne) {
          std::string mname(nb, ne);
          while (!mname.empty() && std::isspace(static_cast<unsigned char>(mname.back()))) mname.pop_back();
          size_t first = mname.find_first_not_of(" \t");
          if (first != std::string::npos) defined_at.emplace(mname.substr(first), std::make_pair(mtl, line));
          return true;
        });
      }
      return true;
    });
  }

  for (const tinyobj::material_t& m : materials) {
    ObjMaterial om;
    om.name = m.name;
    if (auto it = defined_at.find(m.name); it != defined_at.end()) {
      om.mtl_file = it->second.first;
      om.line = it->second.second;
    }
    om.kd = {m.diffuse[0], m.diffuse[1], m.diffuse[2]};
    om.ks = {m.specular[0], m.specular[1], m.specular[2]};
    om.ke = {m.emission[0], m.emission[1], m.emission[2]};
    om.tf = {m.transmittance[0], m.transmittance[1], m.transmittance[2]};
    om.ns = m.shininess;
    om.ni = m.ior;
    om.d = m.dissolve;
    om.illum = m.illum;
    om.pr = m.roughness;
    om.pm = m.metallic;
    // A value that overflows a float (Ks 1e39) or is nan would poison every
    // path that meets the material: refuse the file at the material.
    const std::pair<const char*, glm::vec3> colours[] = {{"Kd", om.kd}, {"Ks", om.ks}, {"Ke", om.ke}, {"Tf", om.tf}};
    for (const auto& [what, v] : colours)
      if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))
        throw SceneError(om.mtl_file.empty() ? path : om.mtl_file, om.line,
                         "material '" + om.name + "': " + what + " is not a finite number");
    const std::pair<const char*, float> numbers[] = {
        {"Ns", om.ns}, {"Ni", om.ni}, {"d", om.d}, {"Pr", om.pr}, {"Pm", om.pm}};
    for (const auto& [what, x] : numbers)
      if (!std::isfinite(x))
        throw SceneError(om.mtl_file.empty() ? path : om.mtl_file, om.line,
                         "material '" + om.name + "': " + what + " is not a finite number");
    auto texture = [](const std::string& name, const tinyobj::texture_option_t& o) {
      ObjTexture t;
      t.file = name;
      std::replace(t.file.begin(), t.file.end(), '\\', '/');
      t.scale = {o.scale[0], o.scale[1]};
      t.offset = {o.origin_offset[0], o.origin_offset[1]};
      t.clamp = o.clamp;
      t.bump_multiplier = o.bump_multiplier;
      return t;
    };
    om.map_kd = texture(m.diffuse_texname, m.diffuse_texopt);
    om.map_d = texture(m.alpha_texname, m.alpha_texopt);
    om.map_bump = texture(m.bump_texname, m.bump_texopt);
    // Ambient (Ka, map_Ka) has no meaning in a path tracer and is left out without a warning.
    const std::pair<const std::string*, const char*> others[] = {
        {&m.specular_texname, "map_Ks"},        {&m.specular_highlight_texname, "map_Ns"},
        {&m.displacement_texname, "disp"},      {&m.reflection_texname, "refl"},
        {&m.normal_texname, "norm"},            {&m.roughness_texname, "map_Pr"},
        {&m.metallic_texname, "map_Pm"},        {&m.sheen_texname, "map_Ps"},
        {&m.emissive_texname, "map_Ke"}};
    for (const auto& [name, what] : others)
      if (!name->empty()) om.unsupported.push_back(what);
    const std::pair<float, const char*> pbr_others[] = {
        {m.sheen, "Ps"}, {m.clearcoat_thickness, "Pc"}, {m.clearcoat_roughness, "Pcr"}, {m.anisotropy, "aniso"}};
    for (const auto& [value, what] : pbr_others)
      if (value != 0.0f) om.unsupported.push_back(what);
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

namespace {

// Heights of an MTL bump map (map_bump -bm m) are m * kObjBumpScale texture
// widths: the MTL format gives no unit; 1/200 gives stone and brick textures
// (Sponza) a plausible relief of a few millimetres per metre of texture.
constexpr float kObjBumpScale = 1.0f / 200.0f;

// A texture map's file next to the MTL file (case-insensitive lookup), loaded
// for `use`; PSF_NO_TEXTURE with a warning when it is missing or unreadable.
uint32_t obj_texture(const ObjMaterial& om, const ObjTexture& t, TextureUse use, const char* statement,
                     const std::string& fallback, TextureStore& store, Scene& scene) {
  std::string where = (om.mtl_file.empty() ? std::string("MTL") : om.mtl_file) +
                      (om.line > 0 ? ":" + std::to_string(om.line) : std::string());
  std::filesystem::path dir = std::filesystem::path(om.mtl_file).parent_path();
  std::optional<std::string> file = find_file_nocase((dir / t.file).string());
  if (!file) {
    scene.warnings.push_back(where + ": " + statement + " '" + t.file + "' of material '" + om.name +
                             "' not found; " + fallback);
    return PSF_NO_TEXTURE;
  }
  TextureDesc d;
  d.path = *file;
  d.use = use;
  d.wrap = t.clamp ? PSF_TEX_CLAMP : 0u;
  // -s and -o act on OBJ's uv (v up); the table's v points down: v' = 1 - (s v_obj + o).
  d.uv_u = {t.scale.x, 0.0f, t.offset.x};
  d.uv_v = {0.0f, t.scale.y, 1.0f - t.scale.y - t.offset.y};
  try {
    return store.image(d);
  } catch (const std::exception& e) {
    throw SceneError(om.mtl_file.empty() ? *file : om.mtl_file, om.line,
                     std::string(statement) + " '" + *file + "' of material '" + om.name + "': " + e.what());
  }
}

float max3(const glm::vec3& v) { return std::max(v.x, std::max(v.y, v.z)); }

// Whether some texel of texture `index` (RGBA halfs) has an alpha below 1.
bool texture_has_transparency(const Scene& scene, uint32_t index) {
  const TextureInfo& t = scene.textures.at(index);
  const size_t first = size_t(t.offset) * 4, end = first + size_t(t.width) * t.height * 4;
  for (size_t i = first + 3; i < end && i < scene.texels.size(); i += 4)
    if (scene.texels[i] < 0x3C00u) return true;  // below 1.0 as a half (alpha is never negative)
  return false;
}

// An MTL material as one of the renderer's BSDFs. There is no standard for
// this; the usual reading of the illumination models:
// - illum 4, 6, 7 or 9 (the refraction models): dielectric with IOR Ni (1.5 if
//   Ni <= 1) and specular transmittance Tf; d, Kd and Ks are not used.
// - otherwise Ks > 0: a glossy coating of roughness alpha = sqrt(2 / (Ns + 2))
//   (Beckmann equivalent of the Phong exponent, Walter et al. 2007, Sec. 5.2):
//   without diffuse colour (Kd = 0, no map_Kd) a conductor reflecting Ks
//   (Mitsuba's material "none"), else roughplastic with diffuse Kd, specular Ks
//   and IOR Ni (1.5 if Ni <= 1); alpha below 0.001 gives the smooth variants.
//   Except for illum 3, 5 and 8 (the models with a mirror reflection weighted
//   by Ks): diffuse Kd (or map_Kd) blended with a (rough) conductor reflecting
//   Ks / max(Ks) at every angle, chosen with probability max(Ks) per shading
//   point (Material.blend), so that the surface reflects Ks + (1 - max(Ks)) Kd:
//   McGuire's Cornell boxes' "mirror" (Kd 0.01, Ks 0.95, illum 5) is a mirror,
//   not a dark plastic whose coat reflects 4 %.
// - otherwise diffuse Kd.
// map_Kd replaces Kd (Kd stays the colour if the file is missing); d < 1 or
// map_d make a mask of opacity d times map_d (its alpha channel, else
// luminance), and without map_d so does map_Kd's alpha channel where it has
// texels that are not opaque; map_bump / bump a bump map (heights: luminance). Ke is emission,
// from the front side only (the side the face's counter-clockwise winding faces),
// as Mitsuba's and pbrt's area lights emit: a light panel just below a ceiling
// (McGuire's Cornell boxes) would otherwise light the ceiling through the gap.
// All other surfaces but dielectrics scatter on both sides (OBJ has no one-sided
// surfaces); an emitter, like a Mitsuba area emitter's surface, on its front only.
Material obj_material(const ObjMaterial& om, TextureStore& store, Scene& scene) {
  Material m{};
  m.emission = {{om.ke.x, om.ke.y, om.ke.z, 0}};
  std::string where = (om.mtl_file.empty() ? std::string("MTL") : om.mtl_file) +
                      (om.line > 0 ? ":" + std::to_string(om.line) : std::string());
  if (!om.unsupported.empty()) {
    std::string list;
    for (const std::string& u : om.unsupported) list += (list.empty() ? "" : ", ") + u;
    scene.warnings.push_back(where + ": material '" + om.name + "': " + list + " not supported; ignored");
  }
  const float eta = om.ni > 1.0f ? om.ni : 1.5f;
  const bool glass = om.illum == 4 || om.illum == 6 || om.illum == 7 || om.illum == 9;
  if (glass) {
    m.type = PSF_MATERIAL_DIELECTRIC;
    m.eta = {{eta, 0, 0, 0}};
    m.specular = {{1, 1, 1, 0}};
    m.transmittance = {{om.tf.x, om.tf.y, om.tf.z, 0}};
    return m;
  }
  m.two_sided = max3(om.ke) > 0.0f ? 0u : 1u;
  uint32_t kd_tex = PSF_NO_TEXTURE;
  if (!om.map_kd.file.empty())
    kd_tex = obj_texture(om, om.map_kd, TextureUse::Color, "map_Kd", "using Kd", store, scene);
  glm::vec3 kd = om.kd;
  const bool diffuse_colour = max3(kd) > 0.0f || kd_tex != PSF_NO_TEXTURE;
  const float alpha = std::sqrt(2.0f / (std::max(om.ns, 0.0f) + 2.0f));
  const bool mirror = max3(om.ks) > 0.0f && diffuse_colour && (om.illum == 3 || om.illum == 5 || om.illum == 8);
  // The PBR extension (Pr, Pm; Blender writes it): as glTF's metallic-roughness,
  // a plastic over Kd with IOR Ni (1.5 if Ni <= 1) and a conductor reflecting
  // Kd at normal incidence, chosen with probability Pm; GGX, alpha = Pr^2 (the
  // smooth types below 0.001). Ks and Ns are then not used.
  const bool pbr = om.pr > 0.0f || om.pm > 0.0f;
  const float pbr_alpha = std::max(om.pr * om.pr, 1e-4f);
  const glm::vec3 base = glm::clamp(kd_tex != PSF_NO_TEXTURE ? store.mean(kd_tex) : kd, 0.0f, 1.0f);
  auto pbr_metal = [&](Material r) {
    r.type = pbr_alpha < 1e-3f ? PSF_MATERIAL_CONDUCTOR : PSF_MATERIAL_ROUGH_CONDUCTOR;
    glm::vec3 eta_v, k_v;
    conductor_from_reflectance(base, eta_v, k_v);
    r.eta = {{eta_v.x, eta_v.y, eta_v.z, 0}};
    r.k = {{k_v.x, k_v.y, k_v.z, 0}};
    r.specular = {{1, 1, 1, 0}};
    r.albedo = {{0, 0, 0, 0}};
    r.tex_color = kd_tex;
    if (kd_tex != PSF_NO_TEXTURE) r.flags |= PSF_MATFLAG_REFLECTANCE;  // eta, k per hit from map_Kd
    r.alpha_u = r.alpha_v = pbr_alpha;
    return r;
  };
  if (pbr && om.pm >= 1.0f) {
    m = pbr_metal(m);
  } else if (pbr) {
    m.type = pbr_alpha < 1e-3f ? PSF_MATERIAL_PLASTIC : PSF_MATERIAL_ROUGH_PLASTIC;
    m.albedo = {{kd.x, kd.y, kd.z, 0}};
    m.specular = {{1, 1, 1, 0}};
    m.eta = {{eta, 0, 0, 0}};
    m.alpha_u = m.alpha_v = pbr_alpha;
    m.tex_color = kd_tex;
    finish_plastic(m, (base.x + base.y + base.z) / 3.0f, 1.0f, store);
  } else if (mirror) {
    m.type = PSF_MATERIAL_DIFFUSE;  // the mirror is added as its blend partner below
    m.albedo = {{kd.x, kd.y, kd.z, 0}};
    m.tex_color = kd_tex;
  } else if (max3(om.ks) > 0.0f && !diffuse_colour) {
    m.type = alpha < 1e-3f ? PSF_MATERIAL_CONDUCTOR : PSF_MATERIAL_ROUGH_CONDUCTOR;
    m.specular = {{om.ks.x, om.ks.y, om.ks.z, 0}};
    m.eta = {{0, 0, 0, 0}};  // eta 0 + i: reflectance 1 at every angle
    m.k = {{1, 1, 1, 0}};
    m.alpha_u = m.alpha_v = alpha;
    m.flags |= PSF_MATFLAG_BECKMANN;
  } else if (max3(om.ks) > 0.0f) {
    m.type = alpha < 1e-3f ? PSF_MATERIAL_PLASTIC : PSF_MATERIAL_ROUGH_PLASTIC;
    m.albedo = {{kd.x, kd.y, kd.z, 0}};
    m.specular = {{om.ks.x, om.ks.y, om.ks.z, 0}};
    m.eta = {{eta, 0, 0, 0}};
    m.alpha_u = m.alpha_v = alpha;
    m.flags |= PSF_MATFLAG_BECKMANN;
    m.tex_color = kd_tex;
    glm::vec3 dm = kd_tex != PSF_NO_TEXTURE ? store.mean(kd_tex) : kd;
    finish_plastic(m, (dm.x + dm.y + dm.z) / 3.0f, (om.ks.x + om.ks.y + om.ks.z) / 3.0f, store);
  } else {
    m.type = PSF_MATERIAL_DIFFUSE;
    m.albedo = {{kd.x, kd.y, kd.z, 0}};
    m.tex_color = kd_tex;
  }
  if (om.d < 1.0f || !om.map_d.file.empty()) {
    m.opacity = std::clamp(om.d, 0.0f, 1.0f);
    if (!om.map_d.file.empty())
      m.tex_opacity = obj_texture(om, om.map_d, TextureUse::Opacity, "map_d", "using d alone", store, scene);
    if (m.opacity < 1.0f || m.tex_opacity != PSF_NO_TEXTURE) m.flags |= PSF_MATFLAG_MASKED;
  }
  // Without map_d, map_Kd's own alpha channel, where some texel of it is not
  // opaque, cuts the surface out: archives draw foliage so (McGuire's, whose
  // pine was made for alpha-testing research), and G3D and Falcor read it so.
  if (om.map_d.file.empty() && kd_tex != PSF_NO_TEXTURE && texture_has_transparency(scene, kd_tex)) {
    m.opacity = std::clamp(om.d, 0.0f, 1.0f);
    m.tex_opacity = obj_texture(om, om.map_kd, TextureUse::Opacity, "map_Kd", "opaque", store, scene);
    if (m.tex_opacity != PSF_NO_TEXTURE) m.flags |= PSF_MATFLAG_MASKED;
  }
  if (!om.map_bump.file.empty()) {
    m.tex_bump = obj_texture(om, om.map_bump, TextureUse::Height, "map_bump", "no bump mapping", store, scene);
    if (m.tex_bump != PSF_NO_TEXTURE) m.bump_scale = om.map_bump.bump_multiplier * kObjBumpScale;
  }
  if (pbr && om.pm > 0.0f && om.pm < 1.0f) {  // the metal partner: the same sides, bump map and cut-out
    Material r = pbr_metal(m);
    r.emission = {{0, 0, 0, 0}};
    r.tex_table = PSF_NO_TEXTURE;
    m.blend = 1 + uint32_t(scene.materials.size());
    m.blend_weight = om.pm;
    scene.materials.push_back(r);
    scene.material_names.push_back(om.name + " (metal)");
  } else if (mirror && !pbr) {  // the same sides and bump map, no emission (the blend's top emits)
    const float weight = std::min(max3(om.ks), 1.0f);
    Material r = m;
    r.type = alpha < 1e-3f ? PSF_MATERIAL_CONDUCTOR : PSF_MATERIAL_ROUGH_CONDUCTOR;
    r.emission = {{0, 0, 0, 0}};
    r.albedo = {{0, 0, 0, 0}};
    r.tex_color = PSF_NO_TEXTURE;
    r.specular = {{om.ks.x / max3(om.ks), om.ks.y / max3(om.ks), om.ks.z / max3(om.ks), 0}};
    r.eta = {{0, 0, 0, 0}};  // eta 0 + i: reflectance 1 at every angle
    r.k = {{1, 1, 1, 0}};
    r.alpha_u = r.alpha_v = alpha;
    r.flags |= PSF_MATFLAG_BECKMANN;
    m.blend = 1 + uint32_t(scene.materials.size());
    m.blend_weight = weight;
    scene.materials.push_back(r);
    scene.material_names.push_back(om.name + " (mirror)");
  }
  return m;
}

}  // namespace

Scene load_obj_scene(const std::string& path) {
  ObjData obj = read_obj(path, true);
  // A file given to render must draw something: a binary file, or a PLY named
  // .obj, parses as an OBJ without faces.
  if (obj.mesh.triangles.empty()) throw SceneError(path, 0, "no faces: nothing to render (is it an OBJ file?)");
  Scene scene;
  scene.warnings = obj.warnings;
  TextureStore store(scene);

  std::vector<uint32_t> material_index(obj.materials.size());
  for (size_t i = 0; i < obj.materials.size(); ++i) {
    const ObjMaterial& om = obj.materials[i];
    Material m = obj_material(om, store, scene);  // may append its blend partner first
    material_index[i] = uint32_t(scene.materials.size());
    scene.materials.push_back(m);
    scene.material_names.push_back(om.name);
  }

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
      const float grey = obj.mesh.colors.empty() ? 0.5f : 1.0f;  // vertex colours are then the colour
      d.albedo = {{grey, grey, grey, 0}};
      d.type = PSF_MATERIAL_DIFFUSE;
      d.two_sided = 1;
      if (!obj.mesh.colors.empty()) d.flags |= PSF_MATFLAG_VERTEX_COLOR;
      default_material = uint32_t(scene.materials.size());
      scene.materials.push_back(d);
      scene.material_names.push_back("default");
    }
    tri_material[t] = default_material;
  }

  // Vertex normals and uvs as the file gives them; without vn, smooth within the
  // smoothing groups the file names (`s 1`) and flat elsewhere (`s off`, or no `s`).
  if (obj.smoothing_groups) compute_vertex_normals(obj.mesh);
  scene.positions = std::move(obj.mesh.positions);
  scene.triangles = std::move(obj.mesh.triangles);
  scene.normals = std::move(obj.mesh.normals);
  scene.uvs = std::move(obj.mesh.uvs);
  // Vertex colours as append_mesh takes them: clamped to [0, 1], a non-finite one none (x = -1).
  scene.colors = std::move(obj.mesh.colors);
  for (glm::vec3& c : scene.colors)
    c = std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.z) ? glm::clamp(c, 0.0f, 1.0f) : glm::vec3(-1.0f);
  // With vertex colours every material (and blend partner) multiplies them in.
  if (!scene.colors.empty())
    for (Material& m : scene.materials) m.flags |= PSF_MATFLAG_VERTEX_COLOR;
  scene.tri_material = std::move(tri_material);
  scene.camera = camera_framing(scene.positions);
  scene.width = 512;
  scene.height = 512;
  return scene;
}

}  // namespace psf::detail
