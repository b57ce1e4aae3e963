// Mesh file formats: PLY (ASCII and binary of both byte orders, written here),
// glTF 2.0 (.gltf with an embedded base64 buffer, and .glb) against hand-computed
// expectations, their errors, and the default sky of bare mesh files.
#include <sys/wait.h>
#include <unistd.h>

#include <Imath/half.h>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>

#include <meshoptimizer.h>
#include <stb_image_write.h>
#include <zlib.h>

#include "image.h"
#include "scene/formats.h"
#include "scene/scene.h"
#include "support.h"

namespace fs = std::filesystem;

namespace {

class TempDir {
 public:
  TempDir() {
    static int counter = 0;
    path_ = fs::temp_directory_path() /
            ("psf-formats-test-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  std::string write(const std::string& name, const std::string& bytes) const {
    fs::path p = path_ / name;
    std::ofstream(p, std::ios::binary) << bytes;
    return p.string();
  }

 private:
  fs::path path_;
};

// The SceneError of loading `path`: its line and message.
std::pair<int, std::string> error_of(const std::function<void()>& load) {
  try {
    load();
  } catch (const psf::SceneError& e) {
    return {e.line(), e.what()};
  }
  FAIL("no SceneError");
  return {0, ""};
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

// --- PLY ------------------------------------------------------------------------

// Five vertices with colour, quality, normal and uv; a quad and a pentagon; an extra element.
const float kVerts[5][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5f, 2, 0}};
const std::vector<std::vector<int>> kFaces = {{0, 1, 2, 3}, {0, 1, 2, 4, 3}};

std::string ply_header(const std::string& format, const std::string& index_type = "int") {
  return "ply\nformat " + format +
         " 1.0\ncomment written by test_formats\nelement vertex 5\n"
         "property float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty double quality\n"
         "property float nx\nproperty float ny\nproperty float nz\nproperty float s\nproperty float t\n"
         "element face 2\nproperty uchar flags\nproperty list uchar " +
         index_type +
         " vertex_indices\n"
         "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n";
}

std::string ascii_ply() {
  std::string s = ply_header("ascii");
  for (int i = 0; i < 5; ++i)
    s += std::to_string(kVerts[i][0]) + " " + std::to_string(kVerts[i][1]) + " " + std::to_string(kVerts[i][2]) +
         " 200 0.5 0 0 1 " + std::to_string(0.25 * i) + " " + std::to_string(1 - 0.25 * i) + "\n";
  for (const auto& f : kFaces) {
    s += "7 " + std::to_string(f.size());
    for (int i : f) s += " " + std::to_string(i);
    s += "\n";
  }
  s += "0 1\n";
  return s;
}

template <class T>
void put(std::string& out, T v, bool big) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big) std::reverse(b, b + sizeof(T));  // the test machine is little-endian (x86-64)
  out.append(b, sizeof(T));
}

// `bad_index`: written in place of vertex index 4.
std::string binary_ply(bool big, std::optional<int32_t> bad_index = std::nullopt) {
  std::string s = ply_header(big ? "binary_big_endian" : "binary_little_endian");
  for (int i = 0; i < 5; ++i) {
    for (int k = 0; k < 3; ++k) put<float>(s, kVerts[i][k], big);
    put<uint8_t>(s, 200, big);
    put<double>(s, 0.5, big);
    put<float>(s, 0, big);
    put<float>(s, 0, big);
    put<float>(s, 1, big);
    put<float>(s, 0.25f * i, big);
    put<float>(s, 1 - 0.25f * i, big);
  }
  for (const auto& f : kFaces) {
    put<uint8_t>(s, 7, big);
    put<uint8_t>(s, uint8_t(f.size()), big);
    for (int i : f) put<int32_t>(s, bad_index && i == 4 ? *bad_index : i, big);
  }
  put<int32_t>(s, 0, big);
  put<int32_t>(s, 1, big);
  return s;
}

void check_test_mesh(const psf::detail::PlyMesh& m) {
  REQUIRE(m.mesh.positions.size() == 5);
  for (int i = 0; i < 5; ++i) CHECK(m.mesh.positions[i] == glm::vec3(kVerts[i][0], kVerts[i][1], kVerts[i][2]));
  // Fans (0, k-1, k): the quad gives 2 triangles, the pentagon 3.
  std::vector<glm::uvec3> expected = {{0, 1, 2}, {0, 2, 3}, {0, 1, 2}, {0, 2, 4}, {0, 4, 3}};
  CHECK(m.mesh.triangles == expected);
  REQUIRE(m.mesh.normals.size() == 5);
  CHECK(m.mesh.normals[3] == glm::vec3(0, 0, 1));
  REQUIRE(m.mesh.uvs.size() == 5);  // from s, t
  CHECK(m.mesh.uvs[2].x == Approx(0.5f));
  CHECK(m.mesh.uvs[2].y == Approx(0.5f));
  auto ignored = [&](const std::string& n) { return std::count(m.ignored.begin(), m.ignored.end(), n) == 1; };
  CHECK(ignored("vertex.red"));
  CHECK(ignored("vertex.quality"));
  CHECK(ignored("face.flags"));
  CHECK(ignored("edge"));
}

// --- glTF -----------------------------------------------------------------------

std::string base64(const std::string& bytes) {
  static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < bytes.size(); i += 3) {
    uint32_t n = uint32_t(uint8_t(bytes[i])) << 16;
    if (i + 1 < bytes.size()) n |= uint32_t(uint8_t(bytes[i + 1])) << 8;
    if (i + 2 < bytes.size()) n |= uint32_t(uint8_t(bytes[i + 2]));
    out += table[(n >> 18) & 63];
    out += table[(n >> 12) & 63];
    out += i + 1 < bytes.size() ? table[(n >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? table[n & 63] : '=';
  }
  return out;
}

// An 8-bit PNG in memory: width x height texels of `channels` bytes, rows from the top.
std::string png_bytes(int width, int height, int channels, const unsigned char* px) {
  std::string png;
  stbi_write_png_to_func([](void* ctx, void* data, int size) { static_cast<std::string*>(ctx)->append((char*)data, size); },
                         &png, width, height, channels, px, width * channels);
  return png;
}

// `json` with `png` as image 0 (embedded, base64) and texture 0 sampling it;
// `more` adds further top-level members (samplers).
std::string with_image(std::string json, const std::string& png, const std::string& texture = R"({"source": 0})",
                       const std::string& more = "") {
  json.replace(json.find("\"asset\""), 0,
               "\"images\": [{\"uri\": \"data:image/png;base64," + base64(png) + "\"}], \"textures\": [" + texture +
                   "]," + more + "\n  ");
  return json;
}

// `json` with its first `what` replaced by `with` (which must be there).
std::string replaced(std::string json, const std::string& what, const std::string& with) {
  size_t at = json.find(what);
  REQUIRE(at != std::string::npos);
  return json.replace(at, what.size(), with);
}

// The x channel of texel i of texture `index` of a loaded scene (halfs).
float texel_x(const psf::Scene& s, uint32_t index, size_t i) {
  Imath::half h;
  h.setBits(s.texels.at((size_t(s.textures.at(index).offset) + i) * 4));
  return float(h);
}

// 176 bytes: a unit quad's 4 positions, its 6 uint16 indices, a triangle's 3
// positions, the quad's 4 normals and 4 uvs.
std::string gltf_buffer() {
  std::string b;
  for (float v : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 1.f, 0.f, 0.f, 1.f, 0.f}) put<float>(b, v, false);
  for (uint16_t i : {0, 1, 2, 0, 2, 3}) put<uint16_t>(b, i, false);
  for (float v : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f}) put<float>(b, v, false);
  for (int i = 0; i < 4; ++i)
    for (float v : {0.f, 0.f, 1.f}) put<float>(b, v, false);
  for (float v : {0.f, 1.f, 1.f, 1.f, 1.f, 0.f, 0.f, 0.f}) put<float>(b, v, false);
  return b;
}

// The test scene's JSON; `buffer` is the "buffers" entry, `extra_index` replaces index accessor count.
std::string gltf_json(const std::string& buffer, int index_count = 6, bool lights = true) {
  std::string light_nodes = lights ? ",3,4,5" : "";
  return R"({
  "asset": {"version": "2.0"},
  "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_emissive_strength"],
  "extensions": {"KHR_lights_punctual": {"lights": [
    {"type": "point", "color": [1, 0.5, 0.5], "intensity": 10},
    {"type": "spot", "intensity": 5, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}},
    {"type": "directional", "intensity": 2}]}},
  "scene": 0,
  "scenes": [{"nodes": [0, 1)" + light_nodes + R"(]}],
  "nodes": [
    {"mesh": 0, "translation": [0, 0, -5], "scale": [2, 2, 2]},
    {"mesh": 1, "rotation": [0, 0, 0.70710678, 0.70710678], "children": [2]},
    {"camera": 0, "translation": [0, 0, 10]},
    {"translation": [1, 2, 3], "extensions": {"KHR_lights_punctual": {"light": 0}}},
    {"rotation": [-0.70710678, 0, 0, 0.70710678], "extensions": {"KHR_lights_punctual": {"light": 1}}},
    {"extensions": {"KHR_lights_punctual": {"light": 2}}}],
  "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": 1.5, "znear": 0.1}}],
  "meshes": [
    {"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 3, "TEXCOORD_0": 4}, "indices": 1, "material": 0}]},
    {"primitives": [{"attributes": {"POSITION": 2}, "material": 1}]}],
  "materials": [
    {"pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 0.6, 1], "metallicFactor": 0}, "doubleSided": true},
    {"pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0},
     "emissiveFactor": [1, 0.5, 0.25], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4}}}],
  "accessors": [
    {"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": 4, "min": [0, 0, 0], "max": [1, 1, 0]},
    {"bufferView": 1, "componentType": 5123, "type": "SCALAR", "count": )" +
         std::to_string(index_count) + R"(},
    {"bufferView": 2, "componentType": 5126, "type": "VEC3", "count": 3, "min": [0, 0, 0], "max": [1, 1, 0]},
    {"bufferView": 3, "componentType": 5126, "type": "VEC3", "count": 4},
    {"bufferView": 4, "componentType": 5126, "type": "VEC2", "count": 4}],
  "bufferViews": [
    {"buffer": 0, "byteOffset": 0, "byteLength": 48},
    {"buffer": 0, "byteOffset": 48, "byteLength": 12},
    {"buffer": 0, "byteOffset": 60, "byteLength": 36},
    {"buffer": 0, "byteOffset": 96, "byteLength": 48},
    {"buffer": 0, "byteOffset": 144, "byteLength": 32}],
  "buffers": [)" + buffer + R"(]
})";
}

std::string glb(const std::string& json, const std::string& bin) {
  std::string j = json, b = bin;
  while (j.size() % 4) j += ' ';
  while (b.size() % 4) b += '\0';
  std::string out;
  put<uint32_t>(out, 0x46546C67u, false);  // "glTF"
  put<uint32_t>(out, 2u, false);
  put<uint32_t>(out, uint32_t(12 + 8 + j.size() + 8 + b.size()), false);
  put<uint32_t>(out, uint32_t(j.size()), false);
  put<uint32_t>(out, 0x4E4F534Au, false);  // "JSON"
  out += j;
  put<uint32_t>(out, uint32_t(b.size()), false);
  put<uint32_t>(out, 0x004E4942u, false);  // "BIN"
  out += b;
  return out;
}

void check_gltf_scene(const psf::Scene& s) {
  INFO([&] {
    std::string all;
    for (const auto& w : s.warnings) all += w + "\n";
    return all;
  }());
  CHECK(s.warnings.empty());
  REQUIRE(s.triangles.size() == 3);
  // Node 0: the quad scaled by 2 and moved to z = -5.
  auto tri = [&](size_t t, int k) { return s.positions[s.triangles[t][k]]; };
  CHECK(tri(0, 0) == glm::vec3(0, 0, -5));
  CHECK(tri(0, 1) == glm::vec3(2, 0, -5));
  CHECK(tri(0, 2) == glm::vec3(2, 2, -5));
  CHECK(tri(1, 2) == glm::vec3(0, 2, -5));
  // The quad's normals and uvs (the triangle has none: flat, and NaN uvs).
  REQUIRE(s.normals.size() == s.positions.size());
  REQUIRE(s.uvs.size() == s.positions.size());
  CHECK(s.normals[s.triangles[0][0]] == glm::vec3(0, 0, 1));
  CHECK(s.normals[s.triangles[2][0]] == glm::vec3(0, 0, 0));
  CHECK(s.uvs[s.triangles[0][2]] == glm::vec2(1, 0));
  CHECK(std::isnan(s.uvs[s.triangles[2][0]].x));
  // Node 1: the triangle rotated by 90 degrees about +z: (1,0,0) -> (0,1,0), (0,1,0) -> (-1,0,0).
  CHECK(glm::length(tri(2, 1) - glm::vec3(0, 1, 0)) < 1e-6f);
  CHECK(glm::length(tri(2, 2) - glm::vec3(-1, 0, 0)) < 1e-6f);
  REQUIRE(s.materials.size() == 2);
  const Material& a = s.materials[s.tri_material[0]];
  CHECK(a.albedo.s[0] == Approx(0.2f));
  CHECK(a.albedo.s[2] == Approx(0.6f));
  CHECK(a.two_sided == 1);
  const Material& e = s.materials[s.tri_material[2]];
  CHECK(e.emission.s[0] == Approx(4.0f));
  CHECK(e.emission.s[1] == Approx(2.0f));
  CHECK(e.two_sided == 0);
  // The camera (node 2, a child of node 1): at (0, 0, 10) looking along -z, up = R (0, 1, 0) = (-1, 0, 0).
  CHECK(glm::length(s.camera.origin - glm::vec3(0, 0, 10)) < 1e-5f);
  CHECK(glm::length(s.camera.target - glm::vec3(0, 0, 9)) < 1e-5f);
  CHECK(glm::length(s.camera.up - glm::vec3(-1, 0, 0)) < 1e-5f);
  CHECK(s.camera.fov_degrees == Approx(glm::degrees(0.8f)));
  CHECK(s.camera.fov_axis == "y");
  CHECK(s.width == 768);
  CHECK(s.height == 512);
  REQUIRE(s.lights.size() == 3);
  CHECK(s.lights[0].type == psf::LightType::Point);
  CHECK(glm::length(s.lights[0].position - glm::vec3(1, 2, 3)) < 1e-6f);
  CHECK(s.lights[0].color == glm::vec3(10, 5, 5));
  CHECK(s.lights[1].type == psf::LightType::Spot);
  CHECK(glm::length(s.lights[1].direction - glm::vec3(0, -1, 0)) < 1e-5f);
  CHECK(s.lights[1].cutoff_angle == Approx(0.5f));
  CHECK(s.lights[1].beam_width == Approx(0.2f));
  CHECK(s.lights[1].color == glm::vec3(5.0f));
  CHECK(s.lights[2].type == psf::LightType::Directional);
  CHECK(glm::length(s.lights[2].direction - glm::vec3(0, 0, -1)) < 1e-6f);
  CHECK(s.lights[2].color == glm::vec3(2.0f));
}

}  // namespace

TEST_CASE("PLY: ASCII and binary of both byte orders read the same mesh", "[formats]") {
  TempDir dir;
  SECTION("ascii") { check_test_mesh(psf::detail::read_ply(dir.write("a.ply", ascii_ply()))); }
  SECTION("binary little endian") { check_test_mesh(psf::detail::read_ply(dir.write("l.ply", binary_ply(false)))); }
  SECTION("binary big endian") { check_test_mesh(psf::detail::read_ply(dir.write("b.ply", binary_ply(true)))); }
  SECTION("CRLF header, sized type names, vertex_index, texture_u/v") {
    std::string s =
        "ply\r\nformat ascii 1.0\r\nelement vertex 3\r\nproperty float32 x\r\nproperty float32 y\r\n"
        "property float32 z\r\nproperty float32 texture_u\r\nproperty float32 texture_v\r\nelement face 1\r\n"
        "property list uint8 uint32 vertex_index\r\nend_header\r\n0 0 0 0 0\r\n1 0 0 1 0\r\n0 1 0 0 1\r\n3 0 1 2\r\n";
    psf::detail::PlyMesh m = psf::detail::read_ply(dir.write("c.ply", s));
    CHECK(m.mesh.triangles.size() == 1);
    CHECK(m.mesh.uvs.size() == 3);
    CHECK(m.mesh.normals.empty());
    CHECK(m.ignored.empty());
  }
}

TEST_CASE("PLY: malformed files are errors naming the line or byte", "[formats]") {
  TempDir dir;
  using psf::detail::read_ply;
  SECTION("truncated binary") {
    std::string full = binary_ply(false);
    std::string path = dir.write("t.ply", full.substr(0, full.size() - 13));
    auto [line, msg] = error_of([&] { read_ply(path); });
    CHECK(line == 0);
    CHECK(contains(msg, "byte "));
    CHECK(contains(msg, "truncated"));
    // A header promising more vertices than the file can hold fails before reading them.
    std::string huge = ply_header("binary_little_endian");
    huge.replace(huge.find("vertex 5"), 8, "vertex 4000000000");
    std::string hp = dir.write("h.ply", huge + "xyz");
    CHECK(contains(error_of([&] { read_ply(hp); }).second, "more than the rest of the file"));
  }
  SECTION("bad headers") {
    auto header_error = [&](const std::string& text) { return error_of([&] { read_ply(dir.write("x.ply", text)); }); };
    CHECK(header_error("plx\n").first == 1);
    auto [l1, m1] = header_error("ply\nformat ascii 2.0\nend_header\n");
    CHECK(l1 == 2);
    CHECK(contains(m1, "version"));
    auto [l2, m2] = header_error("ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n");
    CHECK(l2 == 4);
    CHECK(contains(m2, "quad"));
    CHECK(header_error("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n").second.find("end_header") !=
          std::string::npos);
    CHECK(header_error("ply\nformat ascii 1.0\nelement vertex -3\nend_header\n").first == 3);
    CHECK(contains(header_error("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n").second,
                   "lacks x, y or z"));
  }
  SECTION("out-of-range indices") {
    std::string text = ascii_ply();
    text.replace(text.find("7 5 0 1 2 4 3"), 13, "7 5 0 1 2 9 3");
    std::string path = dir.write("r.ply", text);
    auto [line, msg] = error_of([&] { read_ply(path); });
    CHECK(line == 28);  // 21 header lines, 5 vertices, the second face
    CHECK(contains(msg, "index 9 out of range"));
    std::string bin = dir.write("rb.ply", binary_ply(true, 5));
    CHECK(contains(error_of([&] { read_ply(bin); }).second, "index 5 out of range"));
    std::string neg = dir.write("rn.ply", binary_ply(false, -1 - 0x7fffffff));
    CHECK(contains(error_of([&] { read_ply(neg); }).second, "out of range"));
  }
  SECTION("non-finite vertices") {
    std::string text = ascii_ply();
    size_t at = text.find("end_header\n") + 11;
    at = text.find('\n', at) + 1;  // the second vertex line (line 23)
    text.replace(at, text.find(' ', at) - at, "nan");
    auto [line, msg] = error_of([&] { read_ply(dir.write("n.ply", text)); });
    CHECK(line == 23);
    CHECK(contains(msg, "non-finite"));
    std::string bin = binary_ply(false);
    float inf = INFINITY;
    size_t body = bin.find("end_header\n") + 11;
    std::memcpy(&bin[body + 4], &inf, 4);  // y of vertex 0
    CHECK(contains(error_of([&] { read_ply(dir.write("i.ply", bin)); }).second, "non-finite"));
  }
  SECTION("ASCII values that are not numbers, or too many") {
    std::string text = ascii_ply();
    text.replace(text.find("7 4 0 1 2 3"), 11, "7 4 0 1 x 3");
    CHECK(contains(error_of([&] { read_ply(dir.write("w.ply", text)); }).second, "'x' is not an integer"));
    std::string extra = ascii_ply();
    extra.replace(extra.find("7 4 0 1 2 3"), 11, "7 4 0 1 2 3 8");
    CHECK(error_of([&] { read_ply(dir.write("e.ply", extra)); }).first == 27);
  }
}

TEST_CASE("PLY: load_scene and Mitsuba's ply shape", "[formats]") {
  TempDir dir;
  std::string path = dir.write("mesh.ply", binary_ply(false));
  psf::Scene s = psf::load_scene(path);
  CHECK(s.triangles.size() == 5);
  CHECK(s.width == 512);
  REQUIRE(s.materials.size() == 1);
  REQUIRE(s.lights.size() == 1);  // no emitter: the default sky
  CHECK(s.lights[0].type == psf::LightType::Envmap);
  CHECK(s.lights[0].source == "default sky");
  REQUIRE(s.warnings.size() == 1);  // the properties read past, named
  CHECK(contains(s.warnings[0], "vertex.red"));
  CHECK(contains(s.warnings[0], "edge"));

  std::string xml = dir.write("scene.xml",
                              "<scene version=\"0.5.0\">\n<shape type=\"ply\"><string name=\"filename\" value=\"mesh.ply\"/>"
                              "<transform name=\"toWorld\"><translate x=\"10\"/></transform></shape>\n</scene>\n");
  psf::Scene m = psf::load_scene(xml);
  REQUIRE(m.positions.size() == 5);
  CHECK(m.positions[4] == glm::vec3(10.5f, 2, 0));
  CHECK(m.lights.empty());  // Mitsuba scenes get no default light
  bool named = false;
  for (const auto& w : m.warnings) named = named || (contains(w, "scene.xml:2") && contains(w, "vertex.red"));
  CHECK(named);
  // An error in the PLY file names the PLY file.
  dir.write("bad.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                       "end_header\n0 0 inf\n");
  std::string bad = dir.write("bad.xml", "<scene version=\"3.0.0\">\n<shape type=\"ply\"><string name=\"filename\" "
                                         "value=\"bad.ply\"/></shape>\n</scene>\n");
  auto [line, msg] = error_of([&] { psf::load_scene(bad); });
  CHECK(line == 8);
  CHECK(contains(msg, "bad.ply"));
}

using psf::detail::read_serialized;
using psf::detail::SerializedMesh;

namespace {
// A Mitsuba .serialized mesh, written here with zlib from the format's
// description: header, then the zlib stream of flags, name (version 4), counts,
// positions, normals, uvs (where given, in double precision if `dbl`) and
// uint32 indices.
struct SerialMesh {
  std::vector<glm::vec3> p, n;
  std::vector<glm::vec2> uv;
  std::vector<uint32_t> idx;
  std::string name;
  bool dbl = false;
  uint32_t extra_flags = 0;
};
template <class T>
void put_le(std::string& out, T v) {
  for (size_t i = 0; i < sizeof(T); ++i) out.push_back(char((uint64_t(v) >> (8 * i)) & 0xFF));
}
std::string serialized_stream(const SerialMesh& m, uint16_t version) {
  std::string raw;
  uint32_t flags = (m.n.empty() ? 0u : 0x0001u) | (m.uv.empty() ? 0u : 0x0002u) | (m.dbl ? 0x2000u : 0x1000u) | m.extra_flags;
  put_le(raw, flags);
  if (version == 4) raw += m.name + std::string(1, '\0');
  put_le(raw, uint64_t(m.p.size()));
  put_le(raw, uint64_t(m.idx.size() / 3));
  auto real = [&](float v) {
    if (m.dbl) {
      double d = v;
      uint64_t b;
      std::memcpy(&b, &d, 8);
      put_le(raw, b);
    } else {
      uint32_t b;
      std::memcpy(&b, &v, 4);
      put_le(raw, b);
    }
  };
  for (const auto& v : m.p) real(v.x), real(v.y), real(v.z);
  for (const auto& v : m.n) real(v.x), real(v.y), real(v.z);
  for (const auto& v : m.uv) real(v.x), real(v.y);
  for (uint32_t i : m.idx) put_le(raw, i);
  uLongf size = compressBound(uLong(raw.size()));
  std::string z(size, '\0');
  REQUIRE(compress2(reinterpret_cast<Bytef*>(&z[0]), &size, reinterpret_cast<const Bytef*>(raw.data()), uLong(raw.size()),
                    6) == Z_OK);
  z.resize(size);
  std::string out;
  put_le(out, uint16_t(0x041C));
  put_le(out, version);
  return out + z;
}
std::string serialized_file(const std::vector<SerialMesh>& meshes, uint16_t version) {
  std::string out;
  std::vector<uint64_t> offsets;
  for (const auto& m : meshes) {
    offsets.push_back(out.size());
    out += serialized_stream(m, version);
  }
  for (uint64_t o : offsets) version == 4 ? put_le(out, o) : put_le(out, uint32_t(o));
  put_le(out, uint32_t(meshes.size()));
  return out;
}
}  // namespace

TEST_CASE("Serialized: Mitsuba's binary meshes, by shape_index, both versions", "[formats]") {
  TempDir dir;
  SerialMesh quad;  // single precision, normals and uvs
  quad.name = "quad";
  quad.p = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  quad.n = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, 1}};
  quad.uv = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
  quad.idx = {0, 1, 2, 0, 2, 3};
  SerialMesh tri;  // double precision, no normals: smooth ones are computed
  tri.name = "triangle";
  tri.dbl = true;
  tri.p = {{0, 0, 2}, {0.5f, 0, 2}, {0, 0.25f, 2}};
  tri.idx = {0, 1, 2};
  for (uint16_t version : {uint16_t(4), uint16_t(3)}) {
    INFO("version " << version);
    const std::string file = dir.write("m.serialized", serialized_file({quad, tri}, version));
    SerializedMesh a = read_serialized(file, 0);
    CHECK(a.name == (version == 4 ? "quad" : ""));
    CHECK(a.mesh.positions == quad.p);
    CHECK(a.mesh.normals == quad.n);
    CHECK(a.mesh.uvs == quad.uv);
    REQUIRE(a.mesh.triangles.size() == 2);
    CHECK(a.mesh.triangles[1] == glm::uvec3(0, 2, 3));
    SerializedMesh b = read_serialized(file, 1);
    CHECK(b.mesh.positions == tri.p);
    CHECK(b.mesh.normals.empty());
    CHECK(b.mesh.uvs.empty());
    CHECK(b.mesh.triangles.size() == 1);
    // Through Mitsuba's serialized shape, with to_world.
    std::string xml = dir.write(
        "scene.xml", "<scene version=\"3.0.0\">\n"
                     "<shape type=\"serialized\"><string name=\"filename\" value=\"m.serialized\"/>"
                     "<transform name=\"to_world\"><translate x=\"10\"/></transform></shape>\n"
                     "<shape type=\"serialized\"><string name=\"filename\" value=\"m.serialized\"/>"
                     "<integer name=\"shape_index\" value=\"1\"/></shape>\n</scene>\n");
    psf::Scene s = psf::load_scene(xml);
    REQUIRE(s.triangles.size() == 3);
    REQUIRE(s.positions.size() == 7);
    CHECK(s.positions[2] == glm::vec3(11, 1, 0));
    CHECK(s.positions[5] == glm::vec3(0.5f, 0, 2));
    REQUIRE(s.normals.size() == 7);
    CHECK(glm::length(s.normals[5] - glm::vec3(0, 0, 1)) < 1e-6f);  // computed for the triangle
  }
  // The file's face-normal flag drops its normals.
  SerialMesh faceted = quad;
  faceted.extra_flags = 0x0010;
  CHECK(read_serialized(dir.write("f.serialized", serialized_file({faceted}, 4)), 0).face_normals);
}

TEST_CASE("Serialized: malformed files are errors naming the file", "[formats]") {
  TempDir dir;
  SerialMesh tri;
  tri.p = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  tri.idx = {0, 1, 2};
  const std::string good = serialized_file({tri}, 4);
  auto error = [&](const std::string& bytes, int index = 0) {
    return error_of([&] { read_serialized(dir.write("x.serialized", bytes), index); });
  };
  CHECK(contains(error("PK\x03\x04 not a mesh").second, "not a Mitsuba serialized mesh"));
  std::string v9 = good;
  v9[2] = 9;
  CHECK(contains(error(v9).second, "version 9"));
  CHECK(contains(error(good, 1).second, "shape_index 1 is out of range (the file holds 1 meshes)"));
  CHECK(contains(error(good.substr(0, 20)).second, "compressed data"));
  std::string corrupt = good;
  corrupt[6] = char(corrupt[6] ^ 0x55);
  CHECK(contains(error(corrupt).second, "compressed data"));
  SerialMesh out_of_range = tri;
  out_of_range.idx = {0, 1, 3};
  CHECK(contains(error(serialized_file({out_of_range}, 4)).second, "triangle 0 refers to vertex 3 of 3"));
  // A count larger than the data: checked before anything is allocated.
  SerialMesh big = tri;
  std::string lie = serialized_stream(big, 3);
  std::string raw_counts;  // version 3: flags, then the counts at offset 4 of the stream
  put_le(raw_counts, uint32_t(0x1000));
  put_le(raw_counts, uint64_t(1) << 40);
  put_le(raw_counts, uint64_t(1));
  uLongf size = compressBound(uLong(raw_counts.size()));
  std::string z(size, '\0');
  REQUIRE(compress2(reinterpret_cast<Bytef*>(&z[0]), &size, reinterpret_cast<const Bytef*>(raw_counts.data()),
                    uLong(raw_counts.size()), 6) == Z_OK);
  z.resize(size);
  std::string huge = lie.substr(0, 4) + z;
  CHECK(contains(error(huge).second, "do not fit its data"));
  // Through the XML loader: the error names the serialized file.
  dir.write("bad.serialized", corrupt);
  std::string xml = dir.write("bad.xml", "<scene version=\"3.0.0\">\n<shape type=\"serialized\"><string name=\"filename\" "
                                         "value=\"bad.serialized\"/></shape>\n</scene>\n");
  CHECK(contains(error_of([&] { psf::load_scene(xml); }).second, "bad.serialized"));
}

TEST_CASE("PLY: the shared Stanford bunny (binary)", "[formats]") {
  std::optional<std::string> shared = psf::test::shared_dir();
  if (!shared || !fs::exists(*shared + "/scenes/bunny/bunny.ply")) {
    WARN("shared/scenes/bunny/bunny.ply not found: skipped");
    return;
  }
  std::string path = *shared + "/scenes/bunny/bunny.ply";
  // The counts from the file's own header.
  std::ifstream in(path, std::ios::binary);
  uint64_t vertices = 0, faces = 0;
  for (std::string line; std::getline(in, line) && line.rfind("end_header", 0) != 0;) {
    if (line.rfind("element vertex ", 0) == 0) vertices = std::stoull(line.substr(15));
    if (line.rfind("element face ", 0) == 0) faces = std::stoull(line.substr(13));
  }
  psf::detail::PlyMesh m = psf::detail::read_ply(path);
  CHECK(m.mesh.positions.size() == vertices);
  CHECK(m.mesh.triangles.size() >= faces);
  glm::vec3 lo(1e30f), hi(-1e30f);
  for (const glm::vec3& p : m.mesh.positions) lo = glm::min(lo, p), hi = glm::max(hi, p);
  CHECK(glm::length(hi - lo) > 0.0f);
  CHECK(glm::length(hi - lo) < 1e3f);
}

TEST_CASE("glTF: meshes, node transforms, materials, camera and punctual lights", "[formats]") {
  TempDir dir;
  std::string bin = gltf_buffer();
  REQUIRE(bin.size() == 176);
  SECTION(".gltf with an embedded base64 buffer") {
    std::string json = gltf_json(R"({"byteLength": 176, "uri": "data:application/octet-stream;base64,)" + base64(bin) + "\"}");
    check_gltf_scene(psf::load_scene(dir.write("scene.gltf", json)));
  }
  SECTION(".gltf with a .bin beside it") {
    dir.write("scene.bin", bin);
    check_gltf_scene(psf::load_scene(dir.write("scene.gltf", gltf_json(R"({"byteLength": 176, "uri": "scene.bin"})"))));
  }
  SECTION(".glb") {
    check_gltf_scene(psf::load_scene(dir.write("scene.glb", glb(gltf_json(R"({"byteLength": 176})"), bin))));
  }
  SECTION("no lights: the default sky (the emissive triangle is the only emitter otherwise)") {
    std::string json = gltf_json(R"({"byteLength": 176, "uri": "data:application/octet-stream;base64,)" + base64(bin) + "\"}",
                                 6, false);
    json.replace(json.find("\"emissiveFactor\": [1, 0.5, 0.25]"), 32, "\"emissiveFactor\": [0, 0, 0]");
    psf::Scene s = psf::load_scene(dir.write("dark.gltf", json));
    REQUIRE(s.lights.size() == 1);
    CHECK(s.lights[0].source == "default sky");
  }
}

TEST_CASE("glTF: vertex tangents are read, transformed and mirrored with their node", "[formats]") {
  TempDir dir;
  // The quad gets tangents x (vertices 0, 1) and y (2, 3), right-handed, as accessor 5.
  std::string bin = gltf_buffer();
  for (int i = 0; i < 4; ++i)
    for (float v : {i < 2 ? 1.f : 0.f, i < 2 ? 0.f : 1.f, 0.f, 1.f}) put<float>(bin, v, false);
  auto json_with = [&](int tangent_count, const std::string& scale) {
    std::string json = gltf_json(R"({"byteLength": 240, "uri": "data:application/octet-stream;base64,)" + base64(bin) + "\"}");
    json = replaced(json, R"("NORMAL": 3, "TEXCOORD_0": 4})", R"("NORMAL": 3, "TEXCOORD_0": 4, "TANGENT": 5})");
    json = replaced(json, R"({"bufferView": 4, "componentType": 5126, "type": "VEC2", "count": 4}])",
                    R"({"bufferView": 4, "componentType": 5126, "type": "VEC2", "count": 4},
    {"bufferView": 5, "componentType": 5126, "type": "VEC4", "count": )" + std::to_string(tangent_count) + "}]");
    json = replaced(json, R"({"buffer": 0, "byteOffset": 144, "byteLength": 32}])",
                    R"({"buffer": 0, "byteOffset": 144, "byteLength": 32},
    {"buffer": 0, "byteOffset": 176, "byteLength": 64}])");
    return replaced(json, R"("scale": [2, 2, 2])", "\"scale\": " + scale);
  };
  auto tangent_of = [](const psf::Scene& s, size_t tri, int corner) { return s.tangents.at(s.triangles.at(tri)[corner]); };
  psf::Scene plain = psf::load_scene(dir.write("plain.gltf", json_with(4, "[2, 2, 2]")));
  CHECK(plain.warnings.empty());
  REQUIRE(plain.tangents.size() == plain.positions.size());
  CHECK(tangent_of(plain, 0, 0) == glm::vec4(1, 0, 0, 1));  // quad vertex 0
  CHECK(tangent_of(plain, 0, 2) == glm::vec4(0, 1, 0, 1));  // vertex 2
  CHECK(tangent_of(plain, 2, 0) == glm::vec4(0));           // the triangle has none
  // Mirrored along x: the tangent turns with the geometry and the handedness flips.
  psf::Scene mirrored = psf::load_scene(dir.write("mirrored.gltf", json_with(4, "[-2, 2, 2]")));
  REQUIRE(mirrored.tangents.size() == mirrored.positions.size());
  CHECK(mirrored.tangents[0] == glm::vec4(-1, 0, 0, -1));
  CHECK(mirrored.tangents[2] == glm::vec4(0, 1, 0, -1));
  // The shading attributes carry them for the quad's triangles only.
  std::vector<TriAttrib> a = psf::triangle_attributes(plain);
  CHECK((a[0].flags & PSF_TRI_TANGENTS) != 0);
  CHECK((a[2].flags & PSF_TRI_TANGENTS) == 0);
  try {
    psf::load_scene(dir.write("short.gltf", json_with(3, "[2, 2, 2]")));
    FAIL("a TANGENT accessor shorter than POSITION was accepted");
  } catch (const psf::SceneError& e) {
    CHECK_THAT(e.what(), Catch::Contains("TANGENT and POSITION have different counts"));
  }
}

TEST_CASE("glTF: a normal-mapped primitive without TANGENT gets tangents of its own", "[formats]") {
  // The quad (u along +x, v down the image: y = 1 at v = 0) with a normal map:
  // tangents along +x (scaled by the node, normalised), right-handed, at every
  // vertex; without the normal map none are made.
  TempDir dir;
  const unsigned char px[3] = {128, 128, 255};
  const std::string image = png_bytes(1, 1, 3, px);
  const std::string buffer = R"({"byteLength": 176, "uri": "data:application/octet-stream;base64,)" +
                             base64(gltf_buffer()) + "\"}";
  std::string json = with_image(gltf_json(buffer), image);
  json = replaced(json, R"("metallicFactor": 0}, "doubleSided": true})",
                  R"("metallicFactor": 0}, "doubleSided": true, "normalTexture": {"index": 0}})");
  psf::Scene s = psf::load_scene(dir.write("normal.gltf", json));
  REQUIRE(s.tangents.size() == s.positions.size());
  for (int corner = 0; corner < 3; ++corner) {
    CHECK(glm::length(glm::vec3(s.tangents.at(s.triangles.at(0)[corner])) - glm::vec3(1, 0, 0)) < 1e-6f);
    CHECK(s.tangents.at(s.triangles.at(0)[corner]).w == 1.0f);
  }
  CHECK(s.tangents.at(s.triangles.at(2)[0]) == glm::vec4(0.0f));  // the other mesh has no normal map
  psf::Scene plain = psf::load_scene(dir.write("plain.gltf", gltf_json(buffer)));
  CHECK(plain.tangents.empty());
}

TEST_CASE("glTF: malformed files and unsupported features", "[formats]") {
  TempDir dir;
  std::string bin = gltf_buffer();
  std::string embedded = R"({"byteLength": 176, "uri": "data:application/octet-stream;base64,)" + base64(bin) + "\"}";
  SECTION("an index accessor running past its buffer view") {
    auto [line, msg] = error_of([&] { psf::load_scene(dir.write("a.gltf", gltf_json(embedded, 9))); });
    CHECK(contains(msg, "accessors[1]"));
    CHECK(contains(msg, "do not fit"));
  }
  SECTION("an out-of-range index") {
    std::string b = bin;
    uint16_t nine = 9;
    std::memcpy(&b[48 + 2 * 4], &nine, 2);
    std::string json = gltf_json(R"({"byteLength": 176, "uri": "data:application/octet-stream;base64,)" + base64(b) + "\"}");
    auto [line, msg] = error_of([&] { psf::load_scene(dir.write("i.gltf", json)); });
    CHECK(contains(msg, "accessors[1][4]"));
    CHECK(contains(msg, "index 9 out of range"));
  }
  SECTION("vertex colours (COLOR_0) are read per vertex") {
    // The quad's COLOR_0 is its POSITION accessor: (0,0,0), (1,0,0), (1,1,0), (0,1,0).
    psf::Scene s = psf::load_scene(dir.write(
        "c.gltf", replaced(gltf_json(embedded), "\"attributes\": {\"POSITION\": 0,",
                           "\"attributes\": {\"POSITION\": 0, \"COLOR_0\": 0,")));
    for (const std::string& w : s.warnings) CHECK_FALSE(contains(w, "COLOR_0"));
    REQUIRE(s.colors.size() == s.positions.size());
    CHECK(s.colors[0] == glm::vec3(0, 0, 0));
    CHECK(s.colors[1] == glm::vec3(1, 0, 0));
    CHECK(s.colors[2] == glm::vec3(1, 1, 0));
    CHECK(s.colors[3] == glm::vec3(0, 1, 0));
    CHECK(s.colors[4].x < 0.0f);  // the other mesh has none
  }
  SECTION("a non-finite position") {
    std::string b = bin;
    float nan = NAN;
    std::memcpy(&b[4 * 4], &nan, 4);  // vertex 1, y
    std::string json = gltf_json(R"({"byteLength": 176, "uri": "data:application/octet-stream;base64,)" + base64(b) + "\"}");
    CHECK(contains(error_of([&] { psf::load_scene(dir.write("n.gltf", json)); }).second, "accessors[0][1]"));
  }
  SECTION("an embedded base colour texture (sRGB) times the factor") {
    // 2x2 sRGB texels: red, green, blue, white; factor (0.5, 1, 1).
    const unsigned char px[] = {255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255};
    std::string json = gltf_json(embedded);
    const std::string factor = "\"baseColorFactor\": [0.2, 0.4, 0.6, 1]";
    json.replace(json.find(factor), factor.size(),
                 "\"baseColorFactor\": [0.5, 1, 1, 1], \"baseColorTexture\": {\"index\": 0}");
    json = with_image(json, png_bytes(2, 2, 3, px), R"({"source": 0, "sampler": 0})",
                      R"( "samplers": [{"magFilter": 9728, "wrapS": 33071, "wrapT": 33071}],)");
    psf::Scene s = psf::load_scene(dir.write("tex.gltf", json));
    CHECK(s.warnings.empty());
    const Material& m = s.materials[s.tri_material[0]];
    REQUIRE(m.tex_color != PSF_NO_TEXTURE);
    REQUIRE(m.tex_color < s.textures.size());
    CHECK(m.albedo.s[0] == Approx(0.25f));  // mean of (1, 0, 0, 1) x 0.5
    CHECK(m.albedo.s[1] == Approx(0.5f));
    CHECK(m.albedo.s[2] == Approx(0.5f));
  }
  SECTION("alphaMode MASK and BLEND: an opacity from the base colour's alpha") {
    // 2x2 RGBA texels, alpha 0.2, 0.4, 0.6, 1 (8-bit: 51, 102, 153, 255).
    const unsigned char px[] = {255, 255, 255, 51, 255, 255, 255, 102, 255, 255, 255, 153, 255, 255, 255, 255};
    const std::string png = png_bytes(2, 2, 4, px);
    auto load = [&](const std::string& alpha) {
      std::string json = gltf_json(embedded);
      const std::string factor = "\"baseColorFactor\": [0.2, 0.4, 0.6, 1]";
      json.replace(json.find(factor), factor.size(),
                   "\"baseColorFactor\": [0.5, 1, 1, 1], \"baseColorTexture\": {\"index\": 0}");
      const std::string sided = "\"doubleSided\": true";
      json.replace(json.find(sided), sided.size(), sided + ", " + alpha);
      return psf::load_scene(dir.write("alpha.gltf", with_image(json, png)));
    };
    // The x channel of the opacity texture's 4 texels.
    auto opacity = [](const psf::Scene& s, const Material& m) {
      std::vector<float> x;
      for (size_t i = 0; i < 4; ++i) x.push_back(texel_x(s, m.tex_opacity, i));
      return x;
    };
    psf::Scene mask = load("\"alphaMode\": \"MASK\", \"alphaCutoff\": 0.5");
    INFO(mask.warnings.size() << " warnings");
    CHECK(mask.warnings.empty());
    const Material& a = mask.materials[mask.tri_material[0]];
    CHECK((a.flags & PSF_MATFLAG_MASKED) != 0);
    REQUIRE(a.tex_opacity != PSF_NO_TEXTURE);
    CHECK(a.opacity == 1.0f);
    CHECK(opacity(mask, a) == std::vector<float>{0, 0, 1, 1});
    psf::Scene blend = load("\"alphaMode\": \"BLEND\"");
    const Material& b = blend.materials[blend.tri_material[0]];
    CHECK((b.flags & PSF_MATFLAG_MASKED) != 0);
    REQUIRE(b.tex_opacity != PSF_NO_TEXTURE);
    std::vector<float> bo = opacity(blend, b);
    const float expect[4] = {0.2f, 0.4f, 0.6f, 1.0f};
    for (int i = 0; i < 4; ++i) CHECK(bo[size_t(i)] == Approx(expect[i]).margin(1e-3));
    psf::Scene opaque = load("\"alphaMode\": \"OPAQUE\"");
    CHECK((opaque.materials[opaque.tri_material[0]].flags & PSF_MATFLAG_MASKED) == 0);
    // Without a texture: the factor's alpha against the cutoff, for the whole surface.
    std::string json = gltf_json(embedded);
    json.replace(json.find("[0.2, 0.4, 0.6, 1]"), 18, "[0.2, 0.4, 0.6, 0.3]");
    json.replace(json.find("\"doubleSided\": true"), 19, "\"doubleSided\": true, \"alphaMode\": \"MASK\"");
    psf::Scene cut = psf::load_scene(dir.write("cut.gltf", json));
    const Material& c = cut.materials[cut.tri_material[0]];
    CHECK((c.flags & PSF_MATFLAG_MASKED) != 0);
    CHECK(c.opacity == 0.0f);  // 0.3 < the default cutoff 0.5
    CHECK(c.tex_opacity == PSF_NO_TEXTURE);
  }
  SECTION("metallicRoughnessTexture: metallic (a blend) and a metal's roughness per texel") {
    const unsigned char px[] = {0, 128, 64};  // roughness (green) 128/255, metallic (blue) 64/255
    std::string json = replaced(gltf_json(embedded), "\"metallicFactor\": 0}, \"doubleSided\"",
                                "\"metallicFactor\": 1, \"roughnessFactor\": 0.5, \"metallicRoughnessTexture\": "
                                "{\"index\": 0}}, \"doubleSided\"");
    psf::Scene s = psf::load_scene(dir.write("rough.gltf", with_image(json, png_bytes(1, 1, 3, px))));
    // The dielectric scatters, or with probability metallic (the factor times
    // the blue channel, linear) the metal.
    const Material& d = s.materials[s.tri_material[0]];
    CHECK(d.type == PSF_MATERIAL_ROUGH_PLASTIC);
    CHECK(s.warnings.empty());
    REQUIRE(d.blend > 0);
    REQUIRE(d.blend <= s.materials.size());
    CHECK(d.blend_weight == 1.0f);
    REQUIRE(d.tex_blend != PSF_NO_TEXTURE);
    CHECK(texel_x(s, d.tex_blend, 0) == Approx(64.0f / 255.0f).margin(1e-3));  // not sRGB-decoded (0.05)
    const Material& m = s.materials[d.blend - 1];
    CHECK(m.type == PSF_MATERIAL_ROUGH_CONDUCTOR);
    CHECK(m.blend == 0);
    REQUIRE(m.tex_alpha != PSF_NO_TEXTURE);
    const float r = 0.5f * 128.0f / 255.0f;
    CHECK(texel_x(s, m.tex_alpha, 0) == Approx(r * r).margin(1e-3));  // (factor x green)^2, green linear
    CHECK(m.alpha_u == Approx(r * r).margin(1e-3));
    CHECK(m.two_sided == d.two_sided);
    // The plastic reads the same roughness per texel, through its table's rows.
    CHECK(d.tex_alpha == m.tex_alpha);
    CHECK((d.flags & PSF_MATFLAG_ROUGH_TABLE2D) != 0u);
    CHECK(s.textures[d.tex_table].height == PSF_ROUGH_TABLE_ROWS);
  }
  SECTION("KHR_texture_transform: u' = offset + R(rotation) S(scale) u, as its worked example") {
    const unsigned char px[] = {200, 100, 50};
    std::string json = replaced(gltf_json(embedded), "\"baseColorFactor\": [0.2, 0.4, 0.6, 1]",
                                "\"baseColorFactor\": [1, 1, 1, 1], \"baseColorTexture\": {\"index\": 0, "
                                "\"extensions\": {\"KHR_texture_transform\": {\"offset\": [0.25, -0.5], "
                                "\"rotation\": 0.5, \"scale\": [2, 3]}}}");
    psf::Scene s = psf::load_scene(dir.write("xform.gltf", with_image(json, png_bytes(1, 1, 3, px))));
    CHECK(s.warnings.empty());
    const Material& m = s.materials[s.tri_material[0]];
    REQUIRE(m.tex_color != PSF_NO_TEXTURE);
    const TextureInfo& t = s.textures.at(m.tex_color);
    // u' = cos(a) sx u + sin(a) sy v + ox, v' = -sin(a) sx u + cos(a) sy v + oy.
    const float c = std::cos(0.5f), sn = std::sin(0.5f);
    CHECK(t.uv_u.s[0] == Approx(2 * c));
    CHECK(t.uv_u.s[1] == Approx(3 * sn));
    CHECK(t.uv_u.s[2] == Approx(0.25f));
    CHECK(t.uv_v.s[0] == Approx(-2 * sn));
    CHECK(t.uv_v.s[1] == Approx(3 * c));
    CHECK(t.uv_v.s[2] == Approx(-0.5f));
    // The extension's worked example: offset [0, 1], rotation pi/2, scale 0.5
    // "utilizes only the lower left quadrant of the source image" (u in [0, 0.5],
    // v in [0.5, 1], v running down the image).
    std::string example = replaced(gltf_json(embedded), "\"baseColorFactor\": [0.2, 0.4, 0.6, 1]",
                                   "\"baseColorFactor\": [1, 1, 1, 1], \"baseColorTexture\": {\"index\": 0, "
                                   "\"extensions\": {\"KHR_texture_transform\": {\"offset\": [0, 1], "
                                   "\"rotation\": 1.57079632679, \"scale\": [0.5, 0.5]}}}");
    psf::Scene e = psf::load_scene(dir.write("example.gltf", with_image(example, png_bytes(1, 1, 3, px))));
    const TextureInfo& te = e.textures.at(e.materials[e.tri_material[0]].tex_color);
    for (float u : {0.0f, 1.0f})
      for (float v : {0.0f, 1.0f}) {
        const float tu = te.uv_u.s[0] * u + te.uv_u.s[1] * v + te.uv_u.s[2];
        const float tv = te.uv_v.s[0] * u + te.uv_v.s[1] * v + te.uv_v.s[2];
        CHECK(tu == Approx(0.5f * v).margin(1e-6));
        CHECK(tv == Approx(1.0f - 0.5f * u).margin(1e-6));
      }
  }
  SECTION("KHR_materials_transmission and KHR_materials_ior: glass") {
    const std::string m0 = "\"metallicFactor\": 0}, \"doubleSided\": true";
    psf::Scene s = psf::load_scene(dir.write(
        "glass.gltf", replaced(gltf_json(embedded), m0,
                               "\"metallicFactor\": 0, \"roughnessFactor\": 0}, \"doubleSided\": true, "
                               "\"extensions\": {\"KHR_materials_transmission\": {\"transmissionFactor\": 1}, "
                               "\"KHR_materials_ior\": {\"ior\": 1.33}}")));
    CHECK(s.warnings.empty());
    const Material& m = s.materials[s.tri_material[0]];
    CHECK(m.type == PSF_MATERIAL_DIELECTRIC);  // roughness 0
    CHECK(m.eta.s[0] == Approx(1.33f));
    CHECK(m.eta.s[1] == Approx(1.0f / (1.33f * 1.33f)));
    CHECK(m.transmittance.s[0] == Approx(0.2f));  // tinted by the base colour
    CHECK(m.transmittance.s[2] == Approx(0.6f));
    CHECK(m.specular.s[1] == Approx(1.0f));
    // ior alone sets a dielectric's coating.
    psf::Scene t = psf::load_scene(dir.write(
        "coat.gltf", replaced(gltf_json(embedded), m0,
                              "\"metallicFactor\": 0}, \"doubleSided\": true, \"extensions\": "
                              "{\"KHR_materials_ior\": {\"ior\": 1.7}}")));
    CHECK(t.materials[t.tri_material[0]].type == PSF_MATERIAL_ROUGH_PLASTIC);
    CHECK(t.materials[t.tri_material[0]].eta.s[0] == Approx(1.7f));
    // ior 1 (no refraction): a glass with an index just above 1, where a rough
    // dielectric's half-vector exists (it was an opaque plastic of IOR 1.5).
    psf::Scene one = psf::load_scene(dir.write(
        "ior1.gltf", replaced(gltf_json(embedded), m0,
                              "\"metallicFactor\": 0, \"roughnessFactor\": 0.3}, \"doubleSided\": true, "
                              "\"extensions\": {\"KHR_materials_transmission\": {\"transmissionFactor\": 1}, "
                              "\"KHR_materials_ior\": {\"ior\": 1}}")));
    CHECK(one.materials[one.tri_material[0]].type == PSF_MATERIAL_ROUGH_DIELECTRIC);
    CHECK(one.materials[one.tri_material[0]].eta.s[0] == Approx(1.001f));
    // The glass takes the texture's roughness per texel, as a metal does.
    const unsigned char px[] = {0, 128, 0};  // roughness (green) 128/255
    psf::Scene r = psf::load_scene(dir.write(
        "rough-glass.gltf",
        with_image(replaced(gltf_json(embedded), m0,
                            "\"metallicFactor\": 0, \"roughnessFactor\": 0.5, \"metallicRoughnessTexture\": "
                            "{\"index\": 0}}, \"doubleSided\": true, \"extensions\": "
                            "{\"KHR_materials_transmission\": {\"transmissionFactor\": 1}}"),
                   png_bytes(1, 1, 3, px))));
    CHECK(r.warnings.empty());
    const Material& rg = r.materials[r.tri_material[0]];
    CHECK(rg.type == PSF_MATERIAL_ROUGH_DIELECTRIC);
    REQUIRE(rg.tex_alpha != PSF_NO_TEXTURE);
    const float rough = 0.5f * 128.0f / 255.0f;
    CHECK(texel_x(r, rg.tex_alpha, 0) == Approx(rough * rough).margin(1e-3));
    // A transmission factor between 0 and 1 blends the plastic with the glass; with
    // metallic M too, a chain: plastic -> glass with M + (1 - M) t -> metal with
    // M / (M + (1 - M) t), so that P(metal) = M and P(glass) = (1 - M) t.
    for (float metallic : {0.0f, 0.25f}) {
      INFO("metallic " << metallic);
      psf::Scene u = psf::load_scene(dir.write(
          "part.gltf", replaced(gltf_json(embedded), m0,
                                "\"metallicFactor\": " + std::to_string(metallic) +
                                    "}, \"doubleSided\": true, \"extensions\": "
                                    "{\"KHR_materials_transmission\": {\"transmissionFactor\": 0.4}}")));
      CHECK(u.warnings.empty());
      const Material& top = u.materials[u.tri_material[0]];
      CHECK(top.type == PSF_MATERIAL_ROUGH_PLASTIC);
      const float w1 = metallic + (1 - metallic) * 0.4f;
      CHECK(top.blend_weight == Approx(w1));
      REQUIRE(top.blend >= 1);
      const Material& glass = u.materials[top.blend - 1];
      CHECK(glass.type == PSF_MATERIAL_ROUGH_DIELECTRIC);
      if (metallic == 0.0f) {
        CHECK(glass.blend == 0);
        continue;
      }
      CHECK(glass.blend_weight == Approx(metallic / w1));
      REQUIRE(glass.blend >= 1);
      CHECK(u.materials[glass.blend - 1].type == PSF_MATERIAL_ROUGH_CONDUCTOR);
      CHECK(top.blend_weight * glass.blend_weight == Approx(metallic));
      CHECK(top.blend_weight * (1 - glass.blend_weight) == Approx((1 - metallic) * 0.4f));
    }
  }
  SECTION("emissiveTexture: multiplies the emissive factor, sRGB-decoded") {
    const unsigned char px[] = {128, 64, 0};
    // Material 1 emits (factor (1, 0.5, 0.25) times strength 4).
    std::string json = replaced(gltf_json(embedded), "\"emissiveFactor\": [1, 0.5, 0.25]",
                                "\"emissiveFactor\": [1, 0.5, 0.25], \"emissiveTexture\": {\"index\": 0}");
    psf::Scene s = psf::load_scene(dir.write("glow.gltf", with_image(json, png_bytes(1, 1, 3, px))));
    CHECK(s.warnings.empty());
    const Material& e = s.materials[s.tri_material[2]];
    CHECK(e.emission.s[0] == Approx(4.0f));
    REQUIRE(e.tex_emission != PSF_NO_TEXTURE);
    CHECK(texel_x(s, e.tex_emission, 0) == Approx(0.2158f).margin(1e-3));  // sRGB 128/255 decoded
    CHECK(s.materials[s.tri_material[0]].tex_emission == PSF_NO_TEXTURE);
  }
  SECTION("normalTexture: a normal map, linear, with its scale") {
    const unsigned char px[] = {128, 128, 255};
    std::string json = gltf_json(embedded);
    const std::string sided = "\"doubleSided\": true";
    json.replace(json.find(sided), sided.size(), sided + ", \"normalTexture\": {\"index\": 0, \"scale\": 0.7}");
    psf::Scene s = psf::load_scene(dir.write("normal.gltf", with_image(json, png_bytes(1, 1, 3, px))));
    CHECK(s.warnings.empty());
    const Material& m = s.materials[s.tri_material[0]];
    CHECK((m.flags & PSF_MATFLAG_NORMALMAP) != 0);
    REQUIRE(m.tex_bump != PSF_NO_TEXTURE);
    CHECK(m.bump_scale == Approx(0.7f));
    CHECK(texel_x(s, m.tex_bump, 0) == Approx(128.0f / 255.0f).margin(1e-3));  // not sRGB-decoded (0.216)
  }
  SECTION("not JSON") { CHECK(contains(error_of([&] { psf::load_scene(dir.write("x.gltf", "{ nope")); }).second, "glTF")); }
  SECTION("missing textures are reported once per material; a metallic factor between 0 and 1 blends") {
    std::string json = gltf_json(embedded);
    json.replace(json.find("\"metallicFactor\": 0}, \"doubleSided\""), 20,
                 "\"metallicFactor\": 0.7, \"baseColorTexture\": {\"index\": 0}}");
    json.replace(json.find("\"asset\""), 0,
                 "\"images\": [{\"uri\": \"missing.png\"}], \"textures\": [{\"source\": 0}],\n  ");
    psf::Scene s = psf::load_scene(dir.write("t.gltf", json));
    size_t n = 0;
    for (const auto& w : s.warnings)
      if (contains(w, "materials[0]") && contains(w, "baseColorTexture")) ++n;
    CHECK(n == 1);
    const Material& d = s.materials[s.tri_material[0]];
    CHECK(d.type == PSF_MATERIAL_ROUGH_PLASTIC);
    CHECK(d.blend_weight == Approx(0.7f));
    CHECK(d.tex_blend == PSF_NO_TEXTURE);
    REQUIRE(d.blend > 0);
    CHECK(s.materials[d.blend - 1].type == PSF_MATERIAL_ROUGH_CONDUCTOR);
  }
  SECTION("metallic-roughness: metals are conductors of the base colour at normal incidence, dielectrics plastics") {
    std::string json = gltf_json(embedded);
    const std::string m0 =
        "{\"pbrMetallicRoughness\": {\"baseColorFactor\": [0.2, 0.4, 0.6, 1], \"metallicFactor\": 0}";
    REQUIRE(json.find(m0) != std::string::npos);
    // Material 0: a metal of roughness 0.5; material 1 (the emitter) stays a dielectric, roughness 1 by default.
    json.replace(json.find(m0), m0.size(),
                 "{\"pbrMetallicRoughness\": {\"baseColorFactor\": [0.9, 0.6, 0.3, 1], \"roughnessFactor\": 0.5}");
    psf::Scene s = psf::load_scene(dir.write("metal.gltf", json));
    CHECK(s.warnings.empty());
    const Material& a = s.materials[s.tri_material[0]];
    CHECK(a.type == PSF_MATERIAL_ROUGH_CONDUCTOR);  // metallicFactor defaults to 1
    CHECK(a.alpha_u == Approx(0.25f));              // roughness^2
    CHECK(a.alpha_v == Approx(0.25f));
    CHECK((a.flags & PSF_MATFLAG_BECKMANN) == 0);  // GGX
    // Normal incidence: F = ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2) times the specular colour.
    const float base[3] = {0.9f, 0.6f, 0.3f};
    for (int c = 0; c < 3; ++c) {
      const double eta = a.eta.s[c], k = a.k.s[c];
      const double f0 = ((eta - 1) * (eta - 1) + k * k) / ((eta + 1) * (eta + 1) + k * k);
      CHECK(f0 * a.specular.s[c] == Approx(base[c]).epsilon(1e-5));
    }
    const Material& e = s.materials[s.tri_material[2]];
    CHECK(e.type == PSF_MATERIAL_ROUGH_PLASTIC);
    CHECK(e.alpha_u == Approx(1.0f));
    CHECK(e.eta.s[0] == Approx(1.5f));
    CHECK(e.tex_table != PSF_NO_TEXTURE);  // roughplastic's transmittance table
    // Roughness 0: the smooth types.
    std::string smooth = json;
    smooth.replace(smooth.find("\"roughnessFactor\": 0.5"), 22, "\"roughnessFactor\": 0.0");
    psf::Scene t = psf::load_scene(dir.write("mirror.gltf", smooth));
    CHECK(t.materials[t.tri_material[0]].type == PSF_MATERIAL_CONDUCTOR);
  }
}

TEST_CASE("glTF: scenes/material-spheres.gltf has its metals, dielectrics, glass and blends", "[formats]") {
  psf::Scene s = psf::load_scene(psf::test::source_path("scenes/material-spheres.gltf"));
  CHECK(s.warnings.empty());
  // The ground, rows of 4 metals, 4 dielectrics, 4 glasses, then copper of
  // metallic 0, 1/3, 2/3, 1: a plastic, two plastics blended with a metal (each
  // metal pushed before its plastic), a metal.
  REQUIRE(s.materials.size() == 19);
  const uint32_t types[19] = {
      PSF_MATERIAL_ROUGH_PLASTIC,    PSF_MATERIAL_CONDUCTOR,        PSF_MATERIAL_ROUGH_CONDUCTOR,
      PSF_MATERIAL_ROUGH_CONDUCTOR,  PSF_MATERIAL_ROUGH_CONDUCTOR,  PSF_MATERIAL_PLASTIC,
      PSF_MATERIAL_ROUGH_PLASTIC,    PSF_MATERIAL_ROUGH_PLASTIC,    PSF_MATERIAL_ROUGH_PLASTIC,
      PSF_MATERIAL_DIELECTRIC,       PSF_MATERIAL_ROUGH_DIELECTRIC, PSF_MATERIAL_ROUGH_DIELECTRIC,
      PSF_MATERIAL_ROUGH_DIELECTRIC, PSF_MATERIAL_ROUGH_PLASTIC,    PSF_MATERIAL_ROUGH_CONDUCTOR,
      PSF_MATERIAL_ROUGH_PLASTIC,    PSF_MATERIAL_ROUGH_CONDUCTOR,  PSF_MATERIAL_ROUGH_PLASTIC,
      PSF_MATERIAL_ROUGH_CONDUCTOR};
  for (int i = 0; i < 19; ++i) {
    INFO("material " << i);
    CHECK(s.materials[i].type == types[i]);
  }
  CHECK(s.materials[3].alpha_u == Approx(0.25f));  // roughness 0.5
  CHECK(s.materials[13].blend == 0);
  CHECK(s.materials[15].blend == 15);  // 1 + the metal at 14
  CHECK(s.materials[15].blend_weight == Approx(1.0f / 3.0f));
  CHECK(s.materials[17].blend == 17);
  CHECK(s.materials[17].blend_weight == Approx(2.0f / 3.0f));
  CHECK(s.materials[18].blend == 0);
}

TEST_CASE("CLI: psf render of PLY and glTF files, psf compare", "[formats]") {
  TempDir dir;
  auto run = [](const std::string& args, std::string& output) {
    psf::test::PsfRun r = psf::test::run_psf(args);
    output = r.output;
    return r.status;
  };
  std::string out;
  std::string ply = dir.write("mesh.ply", binary_ply(true));
  std::string exr = fs::path(ply).replace_extension(".exr").string();
  CHECK(run("render " + ply + " -o " + exr + " --spp 2 --width 12 --height 8 --filter off -q", out) == 0);
  INFO(out);
  psf::Image img = psf::read_exr(exr);
  CHECK(img.width == 12);
  // The default sky lights the mesh and fills the background: nothing is black.
  for (float v : img.rgb) CHECK(v > 0.0f);

  std::string bin = gltf_buffer();
  std::string gltf = dir.write("scene.gltf", gltf_json(R"({"byteLength": 176, "uri": "data:application/octet-stream;base64,)" +
                                                       base64(bin) + "\"}"));
  CHECK(run("render " + gltf + " -o " + dir.write("g.exr", "") + " --spp 1 --width 12 --height 8 --filter off -q", out) == 0);

  psf::Image a, b;
  a.width = b.width = 32;
  a.height = b.height = 18;
  a.rgb.assign(32 * 18 * 3, 2.0f);
  b.rgb.assign(32 * 18 * 3, 1.0f);
  std::string pa = dir.write("a.exr", ""), pb = dir.write("b.exr", "");
  psf::write_exr(pa, a);
  psf::write_exr(pb, b);
  CHECK(run("compare " + pa + " " + pb, out) == 0);
  CHECK(contains(out, "relMSE: 0.990099"));
  CHECK(contains(out, "MSE: 1, MAE: 1, MAPE: 99.0099 %"));
  // Half the pixels 3, half 1, against 1: (x - y)^2 is 4 or 0, |x - y| 2 or 0.
  psf::Image c = b;
  for (size_t i = 0; i < c.rgb.size() / 2; ++i) c.rgb[i] = 3.0f;
  std::string pc = dir.write("c.exr", "");
  psf::write_exr(pc, c);
  CHECK(run("compare " + pc + " " + pb, out) == 0);
  CHECK(contains(out, "MSE: 2, MAE: 1, MAPE: 99.0099 %"));
  CHECK(contains(out, "relMSE: 1.9802"));
  CHECK(contains(out, "blocks 16x9: mean relative error 100.00 %"));
  CHECK(contains(out, "(+100.00 %)"));
  CHECK(run("compare " + pa + " " + pb + " --blocks 4x2", out) == 0);
  CHECK(contains(out, "blocks 4x2"));
  CHECK(run("compare " + pa + " " + pb + " --blocks four", out) == 2);
  // --diff: a PNG of the two images and the block errors, three 32x18 panels
  // with gaps of 2; not where it would replace an input, not another format.
  const std::string diff = (fs::path(pa).parent_path() / "diff.png").string();
  CHECK(run("compare " + pa + " " + pb + " --diff " + diff, out) == 0);
  CHECK(contains(out, "wrote " + diff));
  {
    std::ifstream png(diff, std::ios::binary);
    unsigned char head[24] = {};
    png.read(reinterpret_cast<char*>(head), sizeof head);
    REQUIRE(png.gcount() == 24);
    CHECK(std::string(reinterpret_cast<char*>(head + 1), 3) == "PNG");
    CHECK((head[16] << 24 | head[17] << 16 | head[18] << 8 | head[19]) == 3 * 32 + 2 * 2);  // IHDR width
    CHECK((head[20] << 24 | head[21] << 16 | head[22] << 8 | head[23]) == 18);              // height
  }
  const std::string renamed = (fs::path(pa).parent_path() / "a-copy.png").string();
  fs::copy_file(pa, renamed);
  CHECK(run("compare " + renamed + " " + pb + " --diff " + renamed, out) == 2);
  CHECK(contains(out, "would overwrite"));
  CHECK(psf::read_exr(renamed).width == 32);  // left as it was
  CHECK(run("compare " + pa + " " + pb + " --diff " + (fs::path(pa).parent_path() / "d.exr").string(), out) == 2);
  CHECK(contains(out, "PNG"));
  CHECK(run("compare " + pa + " " + pb + " --diff " + (fs::path(pa).parent_path() / "no" / "d.png").string(), out) == 2);
  CHECK(run("compare " + pa + " " + pb + " --diff " + diff + " --diff-range 0", out) == 2);
  CHECK(run("compare " + pa + " " + pb + " --diff " + diff + " --diff-range inf", out) == 2);
  CHECK(run("compare " + pa + " " + pb + " --diff ''", out) == 2);
  // An input that is not OpenEXR: bad input, exit 2, naming it.
  const std::string junk = dir.write("junk.exr", "not an image");
  CHECK(run("compare " + junk + " " + pb, out) == 2);
  CHECK(contains(out, "junk.exr"));
}

TEST_CASE("OBJ and PLY: vertex colours are read, and then are the default material's colour", "[formats]") {
  TempDir dir;
  psf::Scene obj = psf::load_scene(dir.write("c.obj", "v 0 0 0 1 0 -0.2\nv 1 0 0 0 1 0\nv 0 1 0 0 0 0.5\nf 1 2 3\n"));
  psf::Scene plain = psf::load_scene(dir.write("p.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"));
  psf::Scene ply = psf::load_scene(dir.write(
      "c.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
               "property uchar red\nproperty uchar green\nproperty uchar blue\nelement face 1\n"
               "property list uchar int vertex_indices\nend_header\n0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 51\n"
               "3 0 1 2\n"));
  for (const psf::Scene* s : {&obj, &ply}) {
    REQUIRE(s->colors.size() == 3);
    CHECK(s->colors[0] == glm::vec3(1, 0, 0));
    CHECK(s->colors[1] == glm::vec3(0, 1, 0));
    CHECK(s->materials[s->tri_material[0]].albedo.s[0] == 1.0f);  // white: the colours are the colour
  }
  CHECK(obj.colors[2] == glm::vec3(0, 0, 0.5f));
  CHECK(ply.colors[2].z == Approx(0.2f));  // uchar 51 / 255
  CHECK(ply.warnings.empty());             // red, green, blue are used
  CHECK(plain.colors.empty());
  CHECK(plain.materials[plain.tri_material[0]].albedo.s[0] == 0.5f);
}

TEST_CASE("OBJ: a file without Ke gets the default sky; one with Ke does not", "[formats]") {
  TempDir dir;
  std::string dark = dir.write("dark.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  psf::Scene s = psf::load_scene(dark);
  REQUIRE(s.lights.size() == 1);
  const psf::LightDesc& sky = s.lights[0];
  CHECK(sky.type == psf::LightType::Envmap);
  CHECK(sky.width == 64);
  CHECK(sky.height == 32);
  // Brighter above the horizon (row 0: near the zenith, bluish) than below it.
  CHECK(sky.texels[2] > sky.texels[0]);
  CHECK(sky.texels[(size_t(31) * 64) * 3 + 1] == Approx(0.3f));
  dir.write("lamp.mtl", "newmtl lamp\nKe 1 1 1\n");
  std::string lit = dir.write("lit.obj", "mtllib lamp.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl lamp\nf 1 2 3\n");
  CHECK(psf::load_scene(lit).lights.empty());
}

TEST_CASE("OBJ: a usemtl of a material the MTL library lacks warns at its line", "[formats]") {
  // McGuire's CornellBox-Glossy.obj uses 'light', which its MTL file lacks: one
  // warning at the first usemtl of it, saying what its faces become.
  TempDir dir;
  dir.write("box.mtl", "newmtl wall\nKd 0.8 0.8 0.8\n");
  std::string obj = dir.write("box.obj",
                              "mtllib box.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl wall\nf 1 2 3\n"
                              "usemtl light\nf 1 3 2\nusemtl light\nf 1 2 3\n");
  psf::Scene s = psf::load_scene(obj);
  size_t found = 0;
  for (const std::string& w : s.warnings) {
    INFO(w);
    if (w.find("light") == std::string::npos) continue;
    ++found;
    CHECK(w.find("box.obj:7: usemtl 'light': no such material") != std::string::npos);
    CHECK(w.find("diffuse grey") != std::string::npos);
  }
  CHECK(found == 1);
  REQUIRE(s.tri_material.size() == 3);
  const Material& grey = s.materials[s.tri_material[1]];
  CHECK(s.tri_material[1] != s.tri_material[0]);
  CHECK(grey.type == PSF_MATERIAL_DIFFUSE);
  CHECK(grey.albedo.s[0] == 0.5f);
  CHECK(s.tri_material[2] == s.tri_material[1]);
}

TEST_CASE("OBJ: the MTL PBR extension (Pr, Pm) maps as glTF's metallic-roughness", "[formats]") {
  TempDir dir;
  dir.write("m.mtl",
            "newmtl red\nKd 0.8 0.1 0.1\nKs 0.5 0.5 0.5\nNs 10\nPr 0.3\n"
            "newmtl gold\nKd 0.5 0.5 0.5\nPm 1\n"
            "newmtl half\nKd 0.2 0.5 0.9\nPm 0.25\nPr 0.5\nNi 1.7\nPs 0.2\n");
  std::string obj = dir.write("m.obj",
                              "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                              "usemtl red\nf 1 2 3\nusemtl gold\nf 1 2 3\nusemtl half\nf 1 2 3\n");
  psf::Scene s = psf::load_scene(obj);
  auto at = [&](size_t t) -> const Material& { return s.materials.at(s.tri_material.at(t)); };
  // Pr: a rough plastic over Kd with GGX alpha = Pr^2; Ks and Ns are not used.
  CHECK(at(0).type == PSF_MATERIAL_ROUGH_PLASTIC);
  CHECK(at(0).alpha_u == Approx(0.09f));
  CHECK((at(0).flags & PSF_MATFLAG_BECKMANN) == 0u);
  CHECK(at(0).specular.s[0] == 1.0f);
  CHECK(at(0).eta.s[0] == Approx(1.5f));
  CHECK(at(0).blend == 0u);
  // Pm 1, Pr 0: a smooth conductor whose normal-incidence reflectance is Kd.
  CHECK(at(1).type == PSF_MATERIAL_CONDUCTOR);
  const double eta = at(1).eta.s[0], k = at(1).k.s[0];
  CHECK(((eta - 1) * (eta - 1) + k * k) / ((eta + 1) * (eta + 1) + k * k) == Approx(0.5).epsilon(1e-3));
  // Pm 0.25: the plastic (IOR Ni) hands over to the metal with probability 0.25.
  CHECK(at(2).type == PSF_MATERIAL_ROUGH_PLASTIC);
  CHECK(at(2).eta.s[0] == Approx(1.7f));
  CHECK(at(2).blend_weight == Approx(0.25f));
  REQUIRE(at(2).blend >= 1u);
  CHECK(s.materials[at(2).blend - 1].type == PSF_MATERIAL_ROUGH_CONDUCTOR);
  CHECK(s.materials[at(2).blend - 1].alpha_u == Approx(0.25f));
  // Sheen (Ps) is not supported: one warning at its material.
  size_t sheen = 0;
  for (const std::string& w : s.warnings) sheen += contains(w, "m.mtl:9: material 'half': Ps not supported");
  CHECK(sheen == 1);
}

TEST_CASE("OBJ: an MTL value that is not a finite float is an error at its line", "[formats]") {
  // Ks 1e39 overflows a float; the mirror model would divide by it (NaN).
  // tinyobjloader reads "nan" or a word as 0 without a word of warning.
  TempDir dir;
  dir.write("m.mtl", "newmtl ok\nKd 0.5 0.5 0.5\n\nnewmtl big\nKd 0.5 0.5 0.5\nKs 1e39 0 0\nillum 5\n");
  std::string obj = dir.write("m.obj", "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl big\nf 1 2 3\n");
  auto [line, message] = error_of([&] { psf::load_scene(obj); });
  CHECK(line == 6);
  CHECK(contains(message, "m.mtl"));
  CHECK(contains(message, "Ks: '1e39' is not a finite number"));
  const std::pair<std::string, std::string> cases[] = {
      {"Kd nan 0.5 0.5", "Kd: 'nan' is not a finite number"},
      {"Ns high", "Ns: 'high' is not a finite number"},
      {"d 0.5x", "d: '0.5x' is not a finite number"},
      {"Ke 1 inf 1", "Ke: 'inf' is not a finite number"},
  };
  for (const auto& [value, expected] : cases) {
    INFO(value);
    dir.write("m.mtl", "newmtl big\nKd 0.5 0.5 0.5 # grey\n" + value + "\n");
    auto [l, m] = error_of([&] { psf::load_scene(obj); });
    CHECK(l == 3);
    CHECK(contains(m, expected));
  }
  // Comments, the spectral and xyz forms and exponents stay accepted.
  dir.write("m.mtl", "newmtl big\nKd 0.5 0.5 0.5 # a comment\nKa spectral ident.rfl 1.0\nKs xyz 0.1 0.1 0.1\n"
                     "Ns 1.5e+01\nd -halo 0.5\n");
  CHECK_NOTHROW(psf::load_scene(obj));
  dir.write("m.mtl", "newmtl big\nd -halo x\n");
  CHECK_THROWS_WITH(psf::load_scene(obj), Catch::Contains("m.mtl:2") && Catch::Contains("d: 'x' is not a finite number"));
}

TEST_CASE("OBJ: map_Kd's alpha channel cuts the surface out where the material has no map_d", "[formats]") {
  // McGuire's archive draws foliage so (the pine of ../shared: RGBA leaves, no
  // map_d). An RGB image, an RGBA image whose every texel is opaque, and a
  // material with its own map_d keep the behaviour they had.
  TempDir dir;
  const unsigned char leaf[] = {40, 160, 40, 255, 40, 160, 40, 0, 40, 160, 40, 128, 40, 160, 40, 255};
  const unsigned char opaque[] = {40, 160, 40, 255, 40, 160, 40, 255, 40, 160, 40, 255, 40, 160, 40, 255};
  const unsigned char rgb[] = {40, 160, 40, 0, 0, 0, 90, 90, 90, 255, 255, 255};
  const unsigned char mask[] = {255, 0, 0, 255};
  dir.write("leaf.png", png_bytes(2, 2, 4, leaf));
  dir.write("opaque.png", png_bytes(2, 2, 4, opaque));
  dir.write("rgb.png", png_bytes(2, 2, 3, rgb));
  dir.write("mask.png", png_bytes(2, 2, 1, mask));
  dir.write("m.mtl",
            "newmtl leaf\nmap_Kd leaf.png\nnewmtl opaque\nmap_Kd opaque.png\nnewmtl rgb\nmap_Kd rgb.png\n"
            "newmtl own\nmap_Kd leaf.png\nmap_d mask.png\n");
  std::string obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\n";
  for (const char* m : {"leaf", "opaque", "rgb", "own"}) obj += std::string("usemtl ") + m + "\nf 1/1 2/2 3/3\n";
  psf::Scene s = psf::load_scene(dir.write("m.obj", obj));
  CHECK(s.warnings.empty());
  REQUIRE(s.tri_material.size() == 4);
  auto material = [&](size_t k) -> const Material& { return s.materials.at(s.tri_material[k]); };
  const Material& cut = material(0);
  CHECK((cut.flags & PSF_MATFLAG_MASKED) != 0);
  REQUIRE(cut.tex_opacity != PSF_NO_TEXTURE);
  CHECK(cut.opacity == 1.0f);
  CHECK(texel_x(s, cut.tex_opacity, 0) == 1.0f);
  CHECK(texel_x(s, cut.tex_opacity, 1) == 0.0f);
  CHECK(texel_x(s, cut.tex_opacity, 2) == Approx(128 / 255.0).epsilon(2e-3));
  for (size_t k : {size_t(1), size_t(2)}) {
    INFO("material " << k);
    CHECK((material(k).flags & PSF_MATFLAG_MASKED) == 0);
    CHECK(material(k).tex_opacity == PSF_NO_TEXTURE);
  }
  const Material& own = material(3);  // map_d decides: its luminance, not leaf.png's alpha
  REQUIRE(own.tex_opacity != PSF_NO_TEXTURE);
  CHECK(texel_x(s, own.tex_opacity, 0) == 1.0f);
  CHECK(texel_x(s, own.tex_opacity, 1) == 0.0f);
  CHECK(texel_x(s, own.tex_opacity, 2) == 0.0f);
}

TEST_CASE("Mitsuba mask: a bitmap's opacity is its luminance (Mitsuba 3) or its alpha (0.5 files)", "[formats]") {
  // Mitsuba 3 reads a bitmap's RGB only; Bitterli's 0.5 files cut their leaves
  // out by the images' alpha, as Tungsten renders them.
  TempDir dir;
  const unsigned char px[] = {200, 100, 50, 64};
  dir.write("leaf.png", png_bytes(1, 1, 4, px));
  auto mask = [&](const std::string& version) {
    psf::Scene s = psf::load_scene(dir.write(
        "mask" + version + ".xml",
        "<scene version=\"" + version +
            "\"><shape type=\"rectangle\"><bsdf type=\"mask\"><texture type=\"bitmap\" name=\"opacity\">"
            "<string name=\"filename\" value=\"leaf.png\"/></texture><bsdf type=\"diffuse\"/></bsdf></shape></scene>\n"));
    const Material& m = s.materials.at(s.tri_material.at(0));
    REQUIRE(m.tex_opacity != PSF_NO_TEXTURE);
    return texel_x(s, m.tex_opacity, 0);
  };
  auto linear = [](double e) { return e <= 0.04045 ? e / 12.92 : std::pow((e + 0.055) / 1.055, 2.4); };
  const double lum = 0.212671 * linear(200 / 255.0) + 0.715160 * linear(100 / 255.0) + 0.072169 * linear(50 / 255.0);
  CHECK(mask("3.0.0") == Approx(lum).epsilon(2e-3));      // a half's precision
  CHECK(mask("0.5.0") == Approx(64 / 255.0).epsilon(2e-3));
}

TEST_CASE("glTF: a sparse accessor's values replace the elements it names", "[formats]") {
  // A quad at z = 0 whose POSITION accessor replaces vertex 2, (1, 1, 0), by
  // (1, 1, -1) through one sparse substitution (unsigned short index 2).
  psf::Scene s = psf::load_scene(psf::test::source_path("tests/data/gltf/sparse.gltf"));
  CHECK(s.warnings.empty());
  REQUIRE(s.positions.size() == 4);
  CHECK(s.positions[0] == glm::vec3(-1, -1, 0));
  CHECK(s.positions[1] == glm::vec3(1, -1, 0));
  CHECK(s.positions[2] == glm::vec3(1, 1, -1));
  CHECK(s.positions[3] == glm::vec3(-1, 1, 0));
}

TEST_CASE("OBJ without vn: smoothing groups shade smooth within a group, flat elsewhere", "[formats]") {
  // A roof: two triangles meeting at the ridge (0, 1, 0)-(0, 1, 1) at a right angle.
  TempDir dir;
  const std::string roof = "v -1 0 0\nv 0 1 0\nv 0 1 1\nv 1 0 0\nv -1 0 1\nv 1 0 1\n";
  const std::string faces = "f 1 3 2\nf 2 3 4\n";
  // s off (or no s): flat, no vertex normals, the ridge's vertices shared as before.
  psf::Scene flat = psf::load_scene(dir.write("flat.obj", roof + "s off\n" + faces));
  CHECK(flat.normals.empty());
  CHECK(flat.positions.size() == 4);
  // s 1: the ridge's two vertices are shared and their normal is the mean of the
  // two faces' (straight up), the others keep their face's.
  psf::Scene smooth = psf::load_scene(dir.write("smooth.obj", roof + "s 1\n" + faces));
  REQUIRE(smooth.normals.size() == smooth.positions.size());
  CHECK(smooth.positions.size() == 4);
  int up = 0;
  for (size_t i = 0; i < smooth.positions.size(); ++i) {
    const glm::vec3 n = glm::normalize(smooth.normals[i]);
    if (smooth.positions[i].y == 1.0f) {
      CHECK(n.y == Approx(1.0f).margin(1e-5));
      ++up;
    } else {
      CHECK(std::fabs(n.x) == Approx(std::sqrt(0.5f)).margin(1e-5));  // the face's own, at 45 degrees
    }
  }
  CHECK(up == 2);
  // Groups 1 and 2: nothing shared across the ridge, each face flat again.
  psf::Scene split = psf::load_scene(dir.write("split.obj", roof + "s 1\nf 1 3 2\ns 2\nf 2 3 4\n"));
  REQUIRE(split.normals.size() == split.positions.size());
  CHECK(split.positions.size() == 6);
  for (const glm::vec3& n : split.normals) CHECK(std::fabs(glm::normalize(n).x) == Approx(std::sqrt(0.5f)).margin(1e-5));
}

TEST_CASE("PLY: data after the last element the header declares is reported", "[formats]") {
  TempDir dir;
  const std::string header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                             "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  const std::string body = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  psf::Scene clean = psf::load_scene(dir.write("clean.ply", header + body + "\n\n"));
  CHECK(clean.warnings.empty());
  psf::Scene extra = psf::load_scene(dir.write("extra.ply", header + body + "7 7 7\n"));
  REQUIRE(extra.warnings.size() == 1);
  CHECK(contains(extra.warnings[0], "extra.ply: PLY data not used: 3 characters after the last element"));
  CHECK(extra.triangles.size() == 1);
}

TEST_CASE("glTF: Draco-compressed primitives (KHR_draco_mesh_compression) are decoded", "[formats]") {
  // tests/data/gltf/draco.gltf: draco_encoder (Debian's draco 1.5.5, default
  // quantization: 11 bits for positions, 10 for uvs, 8 for normals) of a square
  // [-1, 1]^2 at z = 0 fanned about its centre into 4 triangles, uv = ((x + 1) / 2,
  // (y + 1) / 2), normals +z. Draco reorders the vertices: compare by position.
  psf::Scene s = psf::load_scene(psf::test::source_path("tests/data/gltf/draco.gltf"));
  INFO((s.warnings.empty() ? std::string() : s.warnings.front()));
  CHECK(s.warnings.empty());
  REQUIRE(s.positions.size() == 5);
  REQUIRE(s.triangles.size() == 4);
  REQUIRE(s.uvs.size() == 5);
  REQUIRE(s.normals.size() == 5);
  const float tol = 2.0f / 2047.0f;  // a quantization step of the 11-bit positions
  int corners = 0, centres = 0;
  for (size_t i = 0; i < 5; ++i) {
    const glm::vec3 p = s.positions[i];
    INFO("vertex " << i << " at " << p.x << ", " << p.y << ", " << p.z);
    CHECK(std::abs(p.z) <= tol);
    if (std::abs(std::abs(p.x) - 1) <= tol && std::abs(std::abs(p.y) - 1) <= tol) ++corners;
    if (std::abs(p.x) <= tol && std::abs(p.y) <= tol) ++centres;
    CHECK(std::abs(s.uvs[i].x - (p.x + 1) / 2) <= 2e-3f);
    CHECK(std::abs(s.uvs[i].y - (p.y + 1) / 2) <= 2e-3f);
    CHECK(glm::length(s.normals[i] - glm::vec3(0, 0, 1)) <= 1e-2f);
  }
  CHECK(corners == 4);
  CHECK(centres == 1);
  // Every triangle keeps its counter-clockwise winding (facing +z) and together
  // they cover the square once.
  float area = 0;
  for (const glm::uvec3& t : s.triangles) {
    const glm::vec3 n = glm::cross(s.positions[t[1]] - s.positions[t[0]], s.positions[t[2]] - s.positions[t[0]]);
    CHECK(n.z > 0);
    area += 0.5f * n.z;
  }
  CHECK(std::abs(area - 4) <= 1e-2f);
}

TEST_CASE("glTF: meshoptimizer-compressed buffer views (EXT_meshopt_compression) and quantized attributes",
          "[formats]") {
  // A 3 x 3 grid of vertices as gltfpack writes one: positions as 16-bit integers
  // scaled by their node (KHR_mesh_quantization), normals as octahedral 8-bit
  // (the OCTAHEDRAL filter), uvs as normalized 16-bit, indices as 16-bit
  // triangles, each view compressed by meshoptimizer's encoders into buffer 0 of
  // a .glb, with an uncompressed fallback buffer that holds no data.
  const size_t n = 9;
  std::vector<int16_t> pos(4 * n);  // x, y, z, padding
  std::vector<float> normal(4 * n);
  std::vector<uint16_t> uv(2 * n);
  const glm::vec3 tilted = glm::normalize(glm::vec3(0.3f, -0.2f, 1.0f));
  for (size_t i = 0; i < n; ++i) {
    const int x = int(i % 3), y = int(i / 3);
    pos[4 * i] = int16_t(1000 * (x - 1));
    pos[4 * i + 1] = int16_t(1000 * (y - 1));
    pos[4 * i + 2] = int16_t(250 * x * y);
    const glm::vec3 nv = i == 4 ? tilted : glm::vec3(0, 0, 1);
    normal[4 * i] = nv.x, normal[4 * i + 1] = nv.y, normal[4 * i + 2] = nv.z, normal[4 * i + 3] = 0;
    uv[2 * i] = uint16_t(x * 65535 / 2);
    uv[2 * i + 1] = uint16_t(y * 65535 / 2);
  }
  std::vector<uint32_t> indices;
  for (uint32_t y = 0; y < 2; ++y)
    for (uint32_t x = 0; x < 2; ++x) {
      const uint32_t a = 3 * y + x;
      for (uint32_t v : {a, a + 1, a + 4, a, a + 4, a + 3}) indices.push_back(v);
    }
  std::vector<int8_t> oct(4 * n);
  meshopt_encodeFilterOct(oct.data(), n, 4, 8, normal.data());

  std::string compressed, views, fallback_views;
  size_t fallback = 0;
  int view = 0;
  auto add = [&](const std::vector<unsigned char>& encoded, size_t count, size_t stride, const char* mode,
                 const char* filter, bool attribute) {
    const size_t offset = compressed.size();
    compressed.append(reinterpret_cast<const char*>(encoded.data()), encoded.size());
    while (compressed.size() % 4) compressed += '\0';
    views += std::string(view ? "," : "") + R"({"buffer": 1, "byteOffset": )" + std::to_string(fallback) +
             R"(, "byteLength": )" + std::to_string(count * stride) +
             (attribute ? R"(, "byteStride": )" + std::to_string(stride) : std::string()) +
             R"(, "extensions": {"EXT_meshopt_compression": {"buffer": 0, "byteOffset": )" + std::to_string(offset) +
             R"(, "byteLength": )" + std::to_string(encoded.size()) + R"(, "byteStride": )" + std::to_string(stride) +
             R"(, "count": )" + std::to_string(count) + R"(, "mode": ")" + mode + R"(", "filter": ")" + filter +
             "\"}}}";
    fallback += (count * stride + 3) / 4 * 4;
    ++view;
  };
  auto encode_vertices = [&](const void* data, size_t stride) {
    std::vector<unsigned char> out(meshopt_encodeVertexBufferBound(n, stride));
    out.resize(meshopt_encodeVertexBuffer(out.data(), out.size(), data, n, stride));
    return out;
  };
  add(encode_vertices(pos.data(), 8), n, 8, "ATTRIBUTES", "NONE", true);
  add(encode_vertices(oct.data(), 4), n, 4, "ATTRIBUTES", "OCTAHEDRAL", true);
  add(encode_vertices(uv.data(), 4), n, 4, "ATTRIBUTES", "NONE", true);
  std::vector<unsigned char> encoded_indices(meshopt_encodeIndexBufferBound(indices.size(), n));
  encoded_indices.resize(
      meshopt_encodeIndexBuffer(encoded_indices.data(), encoded_indices.size(), indices.data(), indices.size()));
  add(encoded_indices, indices.size(), 2, "TRIANGLES", "NONE", false);
  const std::string json = R"({"asset": {"version": "2.0"},
  "extensionsUsed": ["EXT_meshopt_compression", "KHR_mesh_quantization"],
  "extensionsRequired": ["EXT_meshopt_compression", "KHR_mesh_quantization"],
  "buffers": [{"byteLength": )" + std::to_string(compressed.size()) + R"(},
              {"byteLength": )" + std::to_string(fallback) +
                           R"(, "extensions": {"EXT_meshopt_compression": {"fallback": true}}}],
  "bufferViews": [)" + views + R"(],
  "accessors": [
    {"bufferView": 0, "componentType": 5122, "type": "VEC3", "count": 9, "min": [-1000, -1000, 0], "max": [1000, 1000, 1000]},
    {"bufferView": 1, "componentType": 5120, "normalized": true, "type": "VEC3", "count": 9},
    {"bufferView": 2, "componentType": 5123, "normalized": true, "type": "VEC2", "count": 9},
    {"bufferView": 3, "componentType": 5123, "type": "SCALAR", "count": 24}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3}]}],
  "nodes": [{"mesh": 0, "scale": [0.001, 0.001, 0.001]}],
  "scenes": [{"nodes": [0]}], "scene": 0})";
  TempDir dir;
  psf::Scene s = psf::load_scene(dir.write("grid.glb", glb(json, compressed)));
  INFO((s.warnings.empty() ? std::string() : s.warnings.front()));
  REQUIRE(s.positions.size() == n);
  REQUIRE(s.triangles.size() == 8);
  REQUIRE(s.normals.size() == n);
  REQUIRE(s.uvs.size() == n);
  for (size_t i = 0; i < n; ++i) {
    const float x = float(i % 3), y = float(i / 3);
    INFO("vertex " << i);
    CHECK(glm::length(s.positions[i] - glm::vec3(x - 1, y - 1, 0.25f * x * y)) <= 1e-6f);
    CHECK(glm::length(s.normals[i] - (i == 4 ? tilted : glm::vec3(0, 0, 1))) <= 0.02f);  // 8-bit octahedral
    CHECK(std::abs(s.uvs[i].x - x / 2) <= 1e-4f);
    CHECK(std::abs(s.uvs[i].y - y / 2) <= 1e-4f);
  }
  // The index codec keeps each triangle and its winding, but may rotate its vertices.
  for (size_t t = 0; t < 8; ++t) {
    const glm::uvec3 want(indices[3 * t], indices[3 * t + 1], indices[3 * t + 2]), got = s.triangles[t];
    INFO("triangle " << t);
    CHECK((got == want || got == glm::uvec3(want.y, want.z, want.x) || got == glm::uvec3(want.z, want.x, want.y)));
  }
}

TEST_CASE("glTF: a required extension psf does not support is an error", "[formats]") {
  // glTF 2.0, 3.12: a client must not load an asset that requires an extension it lacks.
  const std::string bin = gltf_buffer();
  std::string json = gltf_json(R"({"byteLength": 176, "uri": "data:application/octet-stream;base64,)" + base64(bin) + "\"}");
  json.insert(json.find("\"extensionsUsed\""), R"("extensionsRequired": ["KHR_texture_basisu"], )");
  json.replace(json.find("\"KHR_materials_emissive_strength\"]"), 34,
               "\"KHR_materials_emissive_strength\", \"KHR_texture_basisu\"]");
  TempDir dir;
  const std::string path = dir.write("basisu.gltf", json);
  const auto [line, message] = error_of([&] { psf::load_scene(path); });
  CHECK(contains(message, "basisu.gltf: extensionsRequired: the file requires extension KHR_texture_basisu, "
                          "which is not supported"));
}

TEST_CASE("glTF: KHR_materials_volume gives a transmitting material an absorbing interior", "[formats]") {
  // sigma = -ln(attenuationColor) / attenuationDistance; thicknessFactor 0 (the
  // default) is a thin wall without a volume, and so is a surface that does not transmit.
  const std::string bin = gltf_buffer();
  auto load = [&](const std::string& material_extensions) {
    std::string json = gltf_json(R"({"byteLength": 176, "uri": "data:application/octet-stream;base64,)" +
                                 base64(bin) + "\"}");
    const std::string from = R"("metallicFactor": 0}, "doubleSided": true})";
    json.replace(json.find(from), from.size(),
                 R"("metallicFactor": 0}, "doubleSided": true, "extensions": {)" + material_extensions + "}}");
    TempDir dir;
    psf::Scene s = psf::load_scene(dir.write("volume.gltf", json));
    INFO((s.warnings.empty() ? std::string() : s.warnings.front()));
    CHECK(s.warnings.empty());
    const auto& in = s.materials[s.tri_material[0]].interior;
    return glm::vec4(in.s[0], in.s[1], in.s[2], in.s[3]);
  };
  const std::string glass = R"("KHR_materials_transmission": {"transmissionFactor": 1}, )";
  const glm::vec4 v = load(glass + R"("KHR_materials_volume": {"thicknessFactor": 0.5, "attenuationDistance": 2,
                                       "attenuationColor": [0.5, 0.25, 1]})");
  CHECK(glm::length(v - glm::vec4(std::log(2.0f) / 2, std::log(4.0f) / 2, 0.0f, 1.0f)) < 1e-6f);
  CHECK(load(glass + R"("KHR_materials_volume": {"attenuationDistance": 2, "attenuationColor": [0.5, 0.5, 0.5]})") ==
        glm::vec4(0.0f));
  CHECK(load(R"("KHR_materials_volume": {"thicknessFactor": 1, "attenuationDistance": 2,
                 "attenuationColor": [0.5, 0.5, 0.5]})") == glm::vec4(0.0f));
  // Without an attenuationDistance the volume is clear: a medium that does not absorb.
  CHECK(load(glass + R"("KHR_materials_volume": {"thicknessFactor": 1})") == glm::vec4(0, 0, 0, 1));
}
