// glTF 2.0 scenes (.gltf, .glb) through tinygltf (Debian's libtinygltf, a shared
// library, so neither its JSON parser nor stb_image is compiled here).
//
// tinygltf parses the JSON, loads the buffers and decodes the images (stb_image);
// everything read from the
// buffers goes through read_accessor, which checks the accessor, buffer view and
// buffer indices and that every element lies inside its buffer. Locations in
// messages are JSON paths ("meshes[2].primitives[0]", "accessors[5][17]"), as
// tinygltf keeps no line numbers.
//
// Conventions (glTF 2.0 specification): right-handed, +y up, metres; a node's
// transform is its matrix, else T * R * S; cameras look along their local -z with
// +y up; KHR_lights_punctual lights shine along local -z. Light intensities are
// taken as they are (candela for point and spot, lux for directional) as
// radiometric W/sr and W/m^2.
#include <draco/compression/decode.h>
#include <meshoptimizer.h>
#include <nlohmann/json.hpp>
#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <filesystem>
#include <functional>
#include <limits>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <set>
#include <sstream>

#include "scene/formats.h"
#include "scene/loaders.h"
#include "scene/materials.h"

namespace psf::detail {
namespace {

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// tinygltf's image decoder for PNG and JPEG only, glTF 2.0's image formats:
// anything else is refused before stb_image sees it (the stb_image Debian ships
// loops forever on some malformed HDR data, which a data: URI can hold).
bool load_png_or_jpeg(tinygltf::Image* image, const int index, std::string* err, std::string* warn, int width,
                      int height, const unsigned char* bytes, int size, void* user) {
  const bool png = size >= 8 && std::memcmp(bytes, "\x89PNG\r\n\x1a\n", 8) == 0;
  const bool jpeg = size >= 3 && bytes[0] == 0xFF && bytes[1] == 0xD8 && bytes[2] == 0xFF;
  if (!png && !jpeg) {
    if (err) *err += "images[" + std::to_string(index) + "] is neither PNG nor JPEG\n";
    return false;
  }
  return tinygltf::LoadImageData(image, index, err, warn, width, height, bytes, size, user);
}

// tinygltf's FileExists without opening anything but a regular file (its own
// fopen blocks on a FIFO): a folder or device exists, and read_regular_file
// then says what it is.
bool file_exists(const std::string& path, void* user) {
  return !unreadable_input(path).empty() || tinygltf::FileExists(path, user);
}

// tinygltf's ReadWholeFile for regular files only.
bool read_regular_file(std::vector<unsigned char>* out, std::string* err, const std::string& path, void* user) {
  if (const std::string why = unreadable_input(path); !why.empty()) {
    if (err) *err += "File " + path + " " + why + "\n";
    return false;
  }
  return tinygltf::ReadWholeFile(out, err, path, user);
}

class GltfLoader {
 public:
  explicit GltfLoader(const std::string& path) : path_(path) {}

  Scene load() {
    tinygltf::TinyGLTF loader;
    std::string err, warn;
    bool binary = lower(std::filesystem::path(path_).extension().string()) == ".glb";
    // Read once: checked for nesting, then parsed from memory (buffers and
    // images relative to the file's folder).
    std::ifstream in(path_, std::ios::binary);
    if (!in) throw SceneError(path_, 0, "glTF parse error: cannot read the file");
    const std::string text = read_all(in);
    if (text.empty()) throw SceneError(path_, 0, "glTF parse error: Empty file.");
    if (text.size() > size_t(std::numeric_limits<unsigned int>::max()))
      throw SceneError(path_, 0, "glTF parse error: the file is too large");
    check_json_depth(text, binary);
    check_json_fields(text, binary);
    const std::string prepared = prepare_compressed(text, binary);
    loader.SetImageLoader(load_png_or_jpeg, nullptr);
    // External buffers and images: regular files only (a uri "." or /dev/zero
    // would be read as a folder or for ever).
    loader.SetFsCallbacks({&file_exists, &tinygltf::ExpandFilePath, &read_regular_file, &tinygltf::WriteWholeFile,
                           nullptr});
    const std::string base = std::filesystem::path(path_).parent_path().string();
    bool ok = false;
    try {  // tinygltf throws on some malformed files (a .glb's buffer of byteLength 0: std::out_of_range)
      ok = binary ? loader.LoadBinaryFromMemory(&model_, &err, &warn,
                                                reinterpret_cast<const unsigned char*>(prepared.data()),
                                                static_cast<unsigned int>(prepared.size()), base)
                  : loader.LoadASCIIFromString(&model_, &err, &warn, prepared.data(),
                                               static_cast<unsigned int>(prepared.size()), base);
    } catch (const std::exception& e) {
      throw SceneError(path_, 0, std::string("glTF parse error: ") + e.what());
    }
    if (!ok || !err.empty()) throw SceneError(path_, 0, "glTF parse error: " + trim(err.empty() ? warn : err));
    for (const std::string& w : split_lines(warn)) warn_once("tinygltf: " + w);

    static const std::set<std::string> supported = {
        "KHR_lights_punctual",   "KHR_materials_emissive_strength", "KHR_materials_transmission",
        "KHR_materials_ior",     "KHR_materials_volume",            "KHR_texture_transform",
        "KHR_mesh_quantization", "KHR_draco_mesh_compression",      "EXT_meshopt_compression"};
    // A file that requires an extension cannot be read without it (glTF 2.0,
    // 3.12): its geometry or images are compressed, or its meaning changes.
    for (const std::string& e : model_.extensionsRequired)
      if (!supported.count(e))
        fail("extensionsRequired", e.empty() ? std::string("an entry is not an extension's name")
                                             : "the file requires extension " + e + ", which is not supported");
    for (const std::string& e : model_.extensionsUsed)
      if (!supported.count(e)) warn_once("extension " + e + " is not supported; ignored");
    decode_meshopt();
    quantized_ = std::count(model_.extensionsUsed.begin(), model_.extensionsUsed.end(), "KHR_mesh_quantization") > 0;
    if (!model_.animations.empty()) warn_once("animations are not supported; using the rest pose");
    if (!model_.skins.empty()) warn_once("skins are not supported; meshes are placed by their nodes only");

    scene_.width = 512;
    scene_.height = 512;
    materials_.assign(model_.materials.size(), uint32_t(-1));

    std::vector<int> roots;
    if (!model_.scenes.empty()) {
      if (model_.defaultScene < -1) fail("scene", "scene " + std::to_string(model_.defaultScene) + " out of range");
      int s = model_.defaultScene >= 0 ? model_.defaultScene : 0;
      if (size_t(s) >= model_.scenes.size()) fail("scene", "defaultScene " + std::to_string(s) + " does not exist");
      roots = model_.scenes[size_t(s)].nodes;
    } else {
      // No scenes: every node that is nobody's child is a root.
      std::vector<bool> child(model_.nodes.size(), false);
      for (const auto& n : model_.nodes)
        for (int c : n.children)
          if (c >= 0 && size_t(c) < child.size()) child[size_t(c)] = true;
      for (size_t i = 0; i < child.size(); ++i)
        if (!child[i]) roots.push_back(int(i));
    }
    // glTF's nodes form trees (2.0, 3.5.1: a node has one parent at most, a
    // scene's roots are unique): a node shared by two parents, drawn once per
    // path to it, could make a small file draw 2^40 copies.
    std::vector<int> parents(model_.nodes.size(), 0);
    for (const auto& n : model_.nodes)
      for (int c : n.children)
        if (c >= 0 && size_t(c) < parents.size() && ++parents[size_t(c)] == 2)
          fail("nodes[" + std::to_string(c) + "]", "is the child of more than one node (glTF's nodes form trees)");
    for (size_t i = 0; i < roots.size(); ++i)
      if (std::find(roots.begin(), roots.begin() + ptrdiff_t(i), roots[i]) != roots.begin() + ptrdiff_t(i))
        fail("scene.nodes", "lists node " + std::to_string(roots[i]) + " twice");
    for (int r : roots) visit(r, glm::mat4(1.0f), "scene.nodes");

    if (!has_camera_) scene_.camera = camera_framing(scene_.positions);
    return std::move(scene_);
  }

 private:
  static std::string trim(std::string s) {
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
    return s;
  }

  static std::vector<std::string> split_lines(const std::string& s) {
    std::vector<std::string> out;
    size_t pos = 0;
    while (pos < s.size()) {
      size_t eol = s.find('\n', pos);
      if (eol == std::string::npos) eol = s.size();
      std::string line = trim(s.substr(pos, eol - pos));
      if (!line.empty()) out.push_back(line);
      pos = eol + 1;
    }
    return out;
  }

  [[noreturn]] void fail(const std::string& where, const std::string& message) const {
    throw SceneError(path_, 0, where + ": " + message);
  }

  void warn_once(const std::string& message) {
    std::string w = path_ + ": " + message;
    if (std::find(scene_.warnings.begin(), scene_.warnings.end(), w) == scene_.warnings.end())
      scene_.warnings.push_back(w);
  }

  // --- nodes ------------------------------------------------------------------

  glm::mat4 local_transform(const tinygltf::Node& n, const std::string& where) const {
    if (n.matrix.size() == 16) {
      glm::mat4 m;
      for (int i = 0; i < 16; ++i) glm::value_ptr(m)[i] = float(n.matrix[size_t(i)]);  // column-major, as glTF
      return m;
    }
    if (!n.matrix.empty()) fail(where, "matrix must have 16 numbers");
    glm::mat4 t(1.0f), r(1.0f), s(1.0f);
    if (n.translation.size() == 3)
      t = glm::translate(glm::mat4(1.0f), glm::vec3(n.translation[0], n.translation[1], n.translation[2]));
    if (n.rotation.size() == 4)  // glTF quaternions are (x, y, z, w)
      r = glm::mat4_cast(glm::normalize(glm::quat(float(n.rotation[3]), float(n.rotation[0]), float(n.rotation[1]),
                                                  float(n.rotation[2]))));
    if (n.scale.size() == 3) s = glm::scale(glm::mat4(1.0f), glm::vec3(n.scale[0], n.scale[1], n.scale[2]));
    return t * r * s;
  }

  // The scene's node trees, depth first, each node's children in order: an
  // explicit stack instead of recursion, so that no file's nesting can exhaust
  // the thread's stack (a sanitizer's larger frames overflowed 8 MiB at 1024
  // levels of recursion). The depth limit stays: no scene nests nodes this deep.
  static constexpr size_t kMaxNodeDepth = 1024;
  void visit(int root, const glm::mat4& root_parent, const std::string& root_from) {
    struct Open {
      int index;
      glm::mat4 m;  // the node's world transform
      size_t next;  // the next child to visit
      std::string where;
    };
    std::vector<Open> open;  // the path from the root to the current node
    auto enter = [&](int index, const glm::mat4& parent, const std::string& from) {
      std::string where = "nodes[" + std::to_string(index) + "]";
      if (index < 0 || size_t(index) >= model_.nodes.size())
        fail(from, "node index " + std::to_string(index) + " out of range");
      for (const Open& o : open)
        if (o.index == index) fail(where, "the node hierarchy has a cycle");
      if (open.size() >= kMaxNodeDepth) fail(where, "nodes nested more than " + std::to_string(kMaxNodeDepth) + " deep");
      const tinygltf::Node& node = model_.nodes[size_t(index)];
      glm::mat4 m = parent * local_transform(node, where);
      for (int k = 0; k < 16; ++k)
        if (!std::isfinite(glm::value_ptr(m)[k])) fail(where, "the transform is not finite");
      // tinygltf marks an absent index -1; any other negative one is malformed.
      if (node.mesh < -1) fail(where, "mesh index " + std::to_string(node.mesh) + " out of range");
      if (node.camera < -1) fail(where, "camera index " + std::to_string(node.camera) + " out of range");
      if (node.mesh >= 0) add_mesh(node.mesh, m, where);
      if (node.camera >= 0) add_camera(node.camera, m, where);
      auto ext = node.extensions.find("KHR_lights_punctual");
      if (ext != node.extensions.end() && ext->second.Has("light"))
        add_light(ext->second.Get("light").GetNumberAsInt(), m, where);
      open.push_back({index, m, 0, std::move(where)});
    };
    enter(root, root_parent, root_from);
    while (!open.empty()) {
      Open& top = open.back();
      const std::vector<int>& children = model_.nodes[size_t(top.index)].children;
      if (top.next == children.size()) {
        open.pop_back();
        continue;
      }
      const int child = children[top.next++];
      const glm::mat4 m = top.m;  // copies: enter() grows `open`, which may move `top`
      const std::string from = top.where + ".children";
      enter(child, m, from);
    }
  }

  // Debian's tinygltf is built without Draco and knows nothing of
  // EXT_meshopt_compression, and refuses what the two extensions write: an
  // indices accessor without a bufferView (a Draco primitive's: its data are in
  // the compressed view) and a buffer without data (meshopt's fallback, whose
  // views are decoded from another buffer). Before it parses the file, such an
  // accessor gets its primitive's compressed bufferView (decode_draco gives it
  // the decoded one) and such a buffer a one-byte data URI (decode_meshopt gives
  // its views decoded data). Files that use neither are passed on as they are;
  // malformed JSON is left for tinygltf to report.
  std::string prepare_compressed(const std::string& text, bool binary) const {
    if (text.find("KHR_draco_mesh_compression") == std::string::npos &&
        text.find("EXT_meshopt_compression") == std::string::npos)
      return text;
    size_t end = text.size(), begin = 0;
    if (binary) {  // header (12 bytes), the JSON chunk's length and type, its text, the other chunks
      uint32_t length = 0;
      if (text.size() < 20) return text;
      std::memcpy(&length, text.data() + 12, 4);
      if (length > text.size() - 20) return text;
      begin = 20;
      end = 20 + size_t(length);
    }
    nlohmann::json j = nlohmann::json::parse(text.begin() + std::ptrdiff_t(begin),
                                             text.begin() + std::ptrdiff_t(end), nullptr, false);
    if (j.is_discarded() || !j.is_object()) return text;
    auto array = [](nlohmann::json& o, const char* key) -> nlohmann::json* {
      auto it = o.find(key);
      return it != o.end() && it->is_array() ? &*it : nullptr;
    };
    auto object = [](nlohmann::json& o, const char* key) -> nlohmann::json* {
      auto it = o.find(key);
      return it != o.end() && it->is_object() ? &*it : nullptr;
    };
    bool changed = false;
    nlohmann::json* accessors = array(j, "accessors");
    if (nlohmann::json* meshes = array(j, "meshes"); meshes && accessors)
      for (nlohmann::json& mesh : *meshes) {
        nlohmann::json* prims = mesh.is_object() ? array(mesh, "primitives") : nullptr;
        for (size_t k = 0; prims && k < prims->size(); ++k) {
          nlohmann::json& prim = (*prims)[k];
          nlohmann::json* ext = prim.is_object() ? object(prim, "extensions") : nullptr;
          nlohmann::json* draco = ext ? object(*ext, "KHR_draco_mesh_compression") : nullptr;
          auto view = draco ? draco->find("bufferView") : nlohmann::json::iterator();
          auto indices = draco ? prim.find("indices") : nlohmann::json::iterator();
          if (!draco || view == draco->end() || !view->is_number_unsigned() || indices == prim.end() ||
              !indices->is_number_unsigned() || indices->get<uint64_t>() >= accessors->size())
            continue;
          nlohmann::json& a = (*accessors)[indices->get<size_t>()];
          if (a.is_object() && !a.contains("bufferView")) {
            a["bufferView"] = *view;
            changed = true;
          }
        }
      }
    if (nlohmann::json* buffers = array(j, "buffers"))
      for (nlohmann::json& b : *buffers) {
        nlohmann::json* ext = b.is_object() && !b.contains("uri") ? object(b, "extensions") : nullptr;
        nlohmann::json* meshopt = ext ? object(*ext, "EXT_meshopt_compression") : nullptr;
        if (meshopt && meshopt->value("fallback", false)) {
          b["uri"] = "data:application/octet-stream;base64,AA==";  // one byte: tinygltf refuses none
          b["byteLength"] = 1;
          changed = true;
        }
      }
    if (!changed) return text;
    std::string json = j.dump();
    if (!binary) return json;
    while (json.size() % 4) json += ' ';
    const std::string rest = text.substr(end);
    std::string out = text.substr(0, 20);
    const uint32_t total = uint32_t(20 + json.size() + rest.size()), length = uint32_t(json.size());
    std::memcpy(&out[8], &total, 4);
    std::memcpy(&out[12], &length, 4);
    return out + json + rest;
  }

  // The JSON text's [begin, end) in the file: a .glb's JSON chunk (after the
  // header's 12 bytes and the chunk's length and type; cut at the file's end),
  // else the whole file.
  static std::pair<size_t, size_t> json_range(const std::string& text, bool binary) {
    if (!binary || text.size() < 20) return {0, text.size()};
    uint32_t length = 0;
    std::memcpy(&length, text.data() + 12, 4);
    return {20, std::min(text.size(), size_t(20) + length)};
  }

  // What tinygltf takes without a word though the specification forbids it: a
  // negative byte offset, length or stride (read as 0: another part of the
  // buffer) and a texture's sampler index past the samplers (the default
  // sampler). Each is an error naming the element. Malformed JSON is left for
  // tinygltf to report.
  void check_json_fields(const std::string& text, bool binary) const {
    const auto [begin, end] = json_range(text, binary);
    const nlohmann::json j = nlohmann::json::parse(text.begin() + std::ptrdiff_t(begin),
                                                   text.begin() + std::ptrdiff_t(end), nullptr, false);
    if (!j.is_object()) return;
    auto elements = [&](const char* key) {
      auto it = j.find(key);
      return it != j.end() && it->is_array() ? &*it : nullptr;
    };
    auto require_count = [&](const char* array, size_t k, const nlohmann::json& e, const char* field) {
      auto it = e.find(field);
      if (it == e.end() || it->is_number_unsigned()) return;
      throw SceneError(path_, 0, std::string(array) + "[" + std::to_string(k) + "]." + field + ": " + it->dump() +
                                     " is not a count of bytes (an integer >= 0)");
    };
    for (const char* array : {"accessors", "bufferViews"})
      if (const nlohmann::json* a = elements(array))
        for (size_t k = 0; k < a->size(); ++k)
          if ((*a)[k].is_object())
            for (const char* field : {"byteOffset", "byteLength", "byteStride"}) require_count(array, k, (*a)[k], field);
    const nlohmann::json* samplers = elements("samplers");
    if (const nlohmann::json* textures = elements("textures"))
      for (size_t k = 0; k < textures->size(); ++k) {
        if (!(*textures)[k].is_object()) continue;
        auto it = (*textures)[k].find("sampler");
        if (it == (*textures)[k].end()) continue;
        if (!it->is_number_unsigned() || it->get<uint64_t>() >= (samplers ? samplers->size() : 0))
          throw SceneError(path_, 0, "textures[" + std::to_string(k) + "].sampler: " + it->dump() + " names no sampler (" +
                                         std::to_string(samplers ? samplers->size() : 0) + " in the file)");
      }
  }

  // The JSON parser tinygltf uses recurses once per nested array or object: a
  // file nested thousands deep would exhaust the stack. No glTF needs more than
  // a few dozen levels; refuse more than kMaxJsonDepth before parsing. Counts
  // brackets outside strings in the JSON (a .glb's JSON chunk).
  void check_json_depth(const std::string& text, bool binary) const {
    constexpr int kMaxJsonDepth = 512;
    const auto [begin, end] = json_range(text, binary);
    int depth = 0, line = 1;
    bool in_string = false, escaped = false;
    for (size_t i = begin; i < end; ++i) {
      const char c = text[i];
      if (c == '\n') ++line;
      if (in_string) {
        if (escaped) escaped = false;
        else if (c == '\\') escaped = true;
        else if (c == '"') in_string = false;
      } else if (c == '"') {
        in_string = true;
      } else if (c == '[' || c == '{') {
        if (++depth > kMaxJsonDepth)
          throw SceneError(path_, binary ? 0 : line,
                           "JSON nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
      } else if (c == ']' || c == '}') {
        --depth;
      }
    }
  }

  // --- buffers ------------------------------------------------------------------

  // The elements of accessor `index` as doubles, `components` per element
  // (normalised integers mapped to [0,1] / [-1,1] when the accessor says so).
  std::vector<double> read_accessor(int index, int type, const std::string& from, bool allow_int, bool allow_float) {
    std::string where = "accessors[" + std::to_string(index) + "]";
    if (index < 0 || size_t(index) >= model_.accessors.size())
      fail(from, "accessor index " + std::to_string(index) + " out of range");
    const tinygltf::Accessor& a = model_.accessors[size_t(index)];
    if (a.type != type) fail(where, "unexpected accessor type for " + from);
    const int ct = a.componentType;
    bool is_float = ct == TINYGLTF_COMPONENT_TYPE_FLOAT;
    bool is_int = ct == TINYGLTF_COMPONENT_TYPE_BYTE || ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                  ct == TINYGLTF_COMPONENT_TYPE_SHORT || ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ||
                  ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    if (!(is_float && allow_float) && !(is_int && (allow_int || a.normalized)))
      fail(where, "component type " + std::to_string(ct) + " is not supported for " + from);
    const size_t components = size_t(tinygltf::GetNumComponentsInType(uint32_t(type)));
    const size_t csize = size_t(tinygltf::GetComponentSizeInBytes(uint32_t(ct)));
    // One component at q, as a double (normalised integers to [0, 1] or [-1, 1]).
    auto decode = [&](const unsigned char* q) {
      switch (ct) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: { float f; std::memcpy(&f, q, 4); return double(f); }
        case TINYGLTF_COMPONENT_TYPE_BYTE: { int8_t x; std::memcpy(&x, q, 1); return a.normalized ? std::max(x / 127.0, -1.0) : x; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: { uint8_t x; std::memcpy(&x, q, 1); return a.normalized ? x / 255.0 : x; }
        case TINYGLTF_COMPONENT_TYPE_SHORT: { int16_t x; std::memcpy(&x, q, 2); return a.normalized ? std::max(x / 32767.0, -1.0) : x; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { uint16_t x; std::memcpy(&x, q, 2); return a.normalized ? x / 65535.0 : x; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: { uint32_t x; std::memcpy(&x, q, 4); return double(x); }
        default: return 0.0;
      }
    };
    if (a.bufferView < -1) fail(where, "bufferView " + std::to_string(a.bufferView) + " out of range");
    if (a.bufferView < 0) {  // no buffer view: all zeros (glTF 2.0, 3.6.2.3), then the sparse values
      if (a.count > (size_t(1) << 22))  // a 200-byte file must not ask for gigabytes of zeros
        fail(where, "count " + std::to_string(a.count) + " is too large for an accessor without a bufferView");
      std::vector<double> zeros(a.count * components, 0.0);
      apply_sparse(a, where, components, csize, decode, zeros);
      return zeros;
    }
    const int stride = a.ByteStride(buffer_view(a.bufferView, where));
    if (stride <= 0) fail(where, "invalid byte stride");
    if (size_t(stride) < components * csize)
      fail(where, "byteStride " + std::to_string(stride) + " is smaller than an element (" +
                      std::to_string(components * csize) + " bytes)");
    const unsigned char* base =
        view_bytes(a.bufferView, a.byteOffset, a.count, components * csize, size_t(stride), where);
    std::vector<double> out(a.count * components, 0.0);
    for (size_t i = 0; i < a.count; ++i) {
      const unsigned char* p = base + size_t(stride) * i;
      for (size_t c = 0; c < components; ++c) out[i * components + c] = decode(p + c * csize);
    }
    apply_sparse(a, where, components, csize, decode, out);
    return out;
  }

  // bufferView `index`, checked to exist and to name a buffer that does.
  const tinygltf::BufferView& buffer_view(int index, const std::string& where) const {
    if (index < 0 || size_t(index) >= model_.bufferViews.size())
      fail(where, "bufferView " + std::to_string(index) + " out of range");
    const tinygltf::BufferView& view = model_.bufferViews[size_t(index)];
    if (view.buffer < 0 || size_t(view.buffer) >= model_.buffers.size())
      fail("bufferViews[" + std::to_string(index) + "]", "buffer " + std::to_string(view.buffer) + " out of range");
    return view;
  }

  // The first of `count` elements of `size` bytes, `stride` apart, from byte
  // `offset` of bufferView `index` (null for none), checked to lie inside the view
  // and its buffer, compared without sums or products that could wrap around (a
  // count or an offset near 2^64).
  const unsigned char* view_bytes(int index, size_t offset, size_t count, size_t size, size_t stride,
                                  const std::string& where) const {
    const tinygltf::BufferView& view = buffer_view(index, where);
    const std::vector<unsigned char>& buf = model_.buffers[size_t(view.buffer)].data;
    if (count == 0) return nullptr;
    const bool fits = view.byteOffset <= buf.size() && view.byteLength <= buf.size() - view.byteOffset &&
                      offset <= view.byteLength && size <= view.byteLength - offset && stride != 0 &&
                      count - 1 <= (view.byteLength - offset - size) / stride;
    if (!fits)
      fail(where, std::to_string(count) + " elements at byte offset " + std::to_string(offset) +
                      " do not fit in bufferView " + std::to_string(index) + " (" + std::to_string(view.byteLength) +
                      " bytes) or its buffer (" + std::to_string(buf.size()) + " bytes)");
    return buf.data() + view.byteOffset + offset;
  }

  // EXT_meshopt_compression: every buffer view compressed with meshoptimizer's
  // codecs gets a buffer of its own holding the decoded bytes (libmeshoptimizer:
  // vertex attributes, then the extension's filter; triangle or sequence indices).
  void decode_meshopt() {
    const size_t views = model_.bufferViews.size();
    for (size_t vi = 0; vi < views; ++vi) {
      auto ext = model_.bufferViews[vi].extensions.find("EXT_meshopt_compression");
      if (ext == model_.bufferViews[vi].extensions.end()) continue;
      const std::string at = "bufferViews[" + std::to_string(vi) + "].extensions.EXT_meshopt_compression";
      const tinygltf::Value& e = ext->second;
      auto integer = [&](const char* key, bool required) -> size_t {
        const tinygltf::Value& v = e.Get(key);
        if (!v.IsInt() && !(v.IsNumber() && v.GetNumberAsDouble() == std::floor(v.GetNumberAsDouble()))) {
          if (!required && v.Type() == tinygltf::NULL_TYPE) return 0;
          fail(at, std::string("'") + key + "' must be a non-negative integer");
        }
        const double d = v.GetNumberAsDouble();
        if (!(d >= 0 && d < 9.0e15)) fail(at, std::string("'") + key + "' must be a non-negative integer");
        return size_t(d);
      };
      if (!e.IsObject()) fail(at, "must be an object");
      const size_t buffer = integer("buffer", true), offset = integer("byteOffset", false),
                   length = integer("byteLength", true), stride = integer("byteStride", true),
                   count = integer("count", true);
      const std::string mode = e.Get("mode").IsString() ? e.Get("mode").Get<std::string>() : "";
      const std::string filter = e.Get("filter").IsString() ? e.Get("filter").Get<std::string>() : "NONE";
      if (buffer >= model_.buffers.size()) fail(at, "buffer " + std::to_string(buffer) + " out of range");
      const std::vector<unsigned char>& src = model_.buffers[buffer].data;
      if (offset > src.size() || length > src.size() - offset)
        fail(at, std::to_string(length) + " bytes at byte offset " + std::to_string(offset) +
                     " do not fit in buffer " + std::to_string(buffer) + " (" + std::to_string(src.size()) +
                     " bytes)");
      if (stride == 0 || stride > 256 || count > (size_t(1) << 32) / stride)
        fail(at, "byteStride " + std::to_string(stride) + " or count " + std::to_string(count) + " out of range");
      // Every 64 bytes of decoded vertices take at least one compressed byte (2
      // header bits per group of 16), every index or triangle at least one: a
      // count beyond that is refused before its output is allocated.
      if (count * stride > 64 * length + 4096)
        fail(at, "byteLength " + std::to_string(length) + " is too short for " + std::to_string(count) +
                     " elements of " + std::to_string(stride) + " bytes");
      tinygltf::Buffer out;
      out.data.resize(count * stride);
      const unsigned char* in = src.data() + offset;
      int status = -1;
      if (mode == "ATTRIBUTES") {
        if (stride % 4 != 0) fail(at, "ATTRIBUTES need a byteStride that is a multiple of 4");
        status = meshopt_decodeVertexBuffer(out.data.data(), count, stride, in, length);
        if (status == 0 && filter == "OCTAHEDRAL" && (stride == 4 || stride == 8))
          meshopt_decodeFilterOct(out.data.data(), count, stride);
        else if (status == 0 && filter == "QUATERNION" && stride == 8)
          meshopt_decodeFilterQuat(out.data.data(), count, stride);
        else if (status == 0 && filter == "EXPONENTIAL")
          meshopt_decodeFilterExp(out.data.data(), count, stride);
        else if (status == 0 && filter != "NONE")
          fail(at, "filter " + filter + " with byteStride " + std::to_string(stride) + " is not supported");
      } else if (mode == "TRIANGLES" || mode == "INDICES") {
        if (stride != 2 && stride != 4) fail(at, "indices need a byteStride of 2 or 4");
        if (mode == "TRIANGLES" && count % 3 != 0) fail(at, "TRIANGLES need a count that is a multiple of 3");
        status = mode == "TRIANGLES" ? meshopt_decodeIndexBuffer(out.data.data(), count, stride, in, length)
                                     : meshopt_decodeIndexSequence(out.data.data(), count, stride, in, length);
      } else {
        fail(at, "mode '" + mode + "' is not ATTRIBUTES, TRIANGLES or INDICES");
      }
      if (status != 0) fail(at, "the compressed data do not decode (meshoptimizer status " + std::to_string(status) + ")");
      tinygltf::BufferView& view = model_.bufferViews[vi];
      view.buffer = int(model_.buffers.size());
      view.byteOffset = 0;
      view.byteLength = out.data.size();
      model_.buffers.push_back(std::move(out));
    }
  }

  // KHR_draco_mesh_compression: decodes the primitive's compressed buffer view
  // (libdraco) and gives the accessors it replaces (its attributes and indices)
  // buffer views of the decoded values, in the accessors' own component types,
  // so that read_accessor reads them as any others. Once per primitive.
  void decode_draco(const tinygltf::Primitive& prim, const std::string& where) {
    auto ext = prim.extensions.find("KHR_draco_mesh_compression");
    if (ext == prim.extensions.end() || !draco_decoded_.insert(&prim).second) return;
    const std::string at = where + ".extensions.KHR_draco_mesh_compression";
    const tinygltf::Value& e = ext->second;
    if (!e.IsObject() || !e.Get("bufferView").IsInt() || !e.Get("attributes").IsObject())
      fail(at, "needs a bufferView and an attributes object");
    if (prim.indices < 0) fail(at, "a compressed primitive needs an indices accessor");
    const int view_index = e.Get("bufferView").GetNumberAsInt();
    const size_t length = buffer_view(view_index, at).byteLength;
    if (length == 0) fail(at, "bufferView " + std::to_string(view_index) + " is empty");
    const unsigned char* bytes = view_bytes(view_index, 0, 1, length, length, at);
    draco::DecoderBuffer in;
    in.Init(reinterpret_cast<const char*>(bytes), length);
    draco::Decoder decoder;
    auto decoded = decoder.DecodeMeshFromBuffer(&in);
    if (!decoded.ok()) fail(at, "Draco: " + decoded.status().error_msg_string());
    const std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();

    // The decoded arrays go to a buffer of their own, a buffer view each.
    tinygltf::Buffer out;
    const int buffer_index = int(model_.buffers.size());
    auto add_view = [&](size_t size) {
      tinygltf::BufferView v;
      v.buffer = buffer_index;
      v.byteOffset = out.data.size();
      v.byteLength = size;
      out.data.resize((out.data.size() + size + 3) / 4 * 4);
      model_.bufferViews.push_back(v);
      return int(model_.bufferViews.size() - 1);
    };
    auto accessor = [&](int index, const std::string& name) -> tinygltf::Accessor& {
      if (index < 0 || size_t(index) >= model_.accessors.size())
        fail(where + "." + name, "accessor index " + std::to_string(index) + " out of range");
      return model_.accessors[size_t(index)];
    };
    const size_t points = mesh->num_points();
    const tinygltf::Value& attributes = e.Get("attributes");
    for (const std::string& name : attributes.Keys()) {
      auto semantic = prim.attributes.find(name);
      if (semantic == prim.attributes.end()) continue;  // not an attribute of the primitive: not used
      const tinygltf::Value& id = attributes.Get(name);
      const draco::PointAttribute* att = id.IsInt() && id.GetNumberAsInt() >= 0
                                             ? mesh->GetAttributeByUniqueId(uint32_t(id.GetNumberAsInt()))
                                             : nullptr;
      if (!att) fail(at + ".attributes." + name, "no attribute with this id in the compressed mesh");
      tinygltf::Accessor& a = accessor(semantic->second, name);
      const int components = tinygltf::GetNumComponentsInType(uint32_t(a.type));
      const int csize = tinygltf::GetComponentSizeInBytes(uint32_t(a.componentType));
      if (components <= 0 || components > 16 || csize <= 0)
        fail(at + ".attributes." + name, "unsupported accessor type");
      const size_t stride = size_t(components) * size_t(csize);
      const int view = add_view(points * stride);
      unsigned char* dst = out.data.data() + model_.bufferViews[size_t(view)].byteOffset;
      bool ok = true;
      for (size_t i = 0; i < points && ok; ++i) {
        const draco::AttributeValueIndex v = att->mapped_index(draco::PointIndex(uint32_t(i)));
        unsigned char* d = dst + i * stride;
        auto convert = [&](auto sample) {
          using T = decltype(sample);
          T value[16] = {};  // up to a MAT4 (libdraco writes every component asked for)
          ok = att->ConvertValue<T>(v, int8_t(components), value);
          std::memcpy(d, value, stride);
        };
        switch (a.componentType) {
          case TINYGLTF_COMPONENT_TYPE_FLOAT: convert(float()); break;
          case TINYGLTF_COMPONENT_TYPE_BYTE: convert(int8_t()); break;
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: convert(uint8_t()); break;
          case TINYGLTF_COMPONENT_TYPE_SHORT: convert(int16_t()); break;
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: convert(uint16_t()); break;
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: convert(uint32_t()); break;
          default: ok = false;
        }
      }
      if (!ok) fail(at + ".attributes." + name, "the compressed values do not convert to the accessor's type");
      a.bufferView = view;
      a.byteOffset = 0;
      a.count = points;
      a.sparse.isSparse = false;
    }
    tinygltf::Accessor& indices = accessor(prim.indices, "indices");
    const size_t faces = mesh->num_faces();
    const int view = add_view(faces * 3 * sizeof(uint32_t));
    unsigned char* dst = out.data.data() + model_.bufferViews[size_t(view)].byteOffset;
    for (size_t f = 0; f < faces; ++f) {
      const draco::Mesh::Face& face = mesh->face(draco::FaceIndex(uint32_t(f)));
      for (int k = 0; k < 3; ++k) {
        const uint32_t index = face[k].value();
        std::memcpy(dst + (3 * f + size_t(k)) * sizeof(uint32_t), &index, sizeof(index));
      }
    }
    indices.bufferView = view;
    indices.byteOffset = 0;
    indices.count = 3 * faces;
    indices.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    indices.sparse.isSparse = false;
    model_.buffers.push_back(std::move(out));
  }

  // A sparse accessor's substitutions (glTF 2.0, 3.6.2.3): element indices[k]
  // takes values[k], both arrays tightly packed in their buffer views.
  template <typename Decode>
  void apply_sparse(const tinygltf::Accessor& a, const std::string& where, size_t components, size_t csize,
                    const Decode& decode, std::vector<double>& out) const {
    if (!a.sparse.isSparse) return;
    const std::string at = where + ".sparse";
    if (a.sparse.count < 1 || size_t(a.sparse.count) > a.count)
      fail(at, "count " + std::to_string(a.sparse.count) + " out of range");
    const size_t n = size_t(a.sparse.count);
    const int it = a.sparse.indices.componentType;
    const size_t isize = it == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE    ? 1
                         : it == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ? 2
                         : it == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT   ? 4
                                                                        : 0;
    if (isize == 0) fail(at + ".indices", "component type " + std::to_string(it) + " is not an unsigned integer");
    if (a.sparse.indices.byteOffset < 0 || a.sparse.values.byteOffset < 0) fail(at, "negative byteOffset");
    const unsigned char* indices = view_bytes(a.sparse.indices.bufferView, size_t(a.sparse.indices.byteOffset), n,
                                              isize, isize, at + ".indices");
    const unsigned char* values = view_bytes(a.sparse.values.bufferView, size_t(a.sparse.values.byteOffset), n,
                                             components * csize, components * csize, at + ".values");
    for (size_t k = 0; k < n; ++k) {
      uint32_t i = 0;
      if (isize == 1) i = indices[k];
      if (isize == 2) { uint16_t x; std::memcpy(&x, indices + 2 * k, 2); i = x; }
      if (isize == 4) std::memcpy(&i, indices + 4 * k, 4);
      if (i >= a.count)
        fail(at + ".indices[" + std::to_string(k) + "]", "index " + std::to_string(i) + " out of range");
      for (size_t c = 0; c < components; ++c)
        out[size_t(i) * components + c] = decode(values + (k * components + c) * csize);
    }
  }

  // --- meshes and materials -------------------------------------------------------

  void add_mesh(int index, const glm::mat4& to_world, const std::string& from) {
    if (size_t(index) >= model_.meshes.size()) fail(from, "mesh index " + std::to_string(index) + " out of range");
    const tinygltf::Mesh& mesh = model_.meshes[size_t(index)];
    for (size_t pi = 0; pi < mesh.primitives.size(); ++pi) {
      const tinygltf::Primitive& prim = mesh.primitives[pi];
      std::string where = "meshes[" + std::to_string(index) + "].primitives[" + std::to_string(pi) + "]";
      int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
      if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP && mode != TINYGLTF_MODE_TRIANGLE_FAN) {
        warn_once(where + ": primitive mode " + std::to_string(mode) + " (points or lines) is not supported; skipped");
        continue;
      }
      if (!prim.targets.empty()) warn_once(where + ": morph targets are not supported; using the base shape");
      decode_draco(prim, where);
      auto pos_attr = prim.attributes.find("POSITION");
      if (pos_attr == prim.attributes.end()) fail(where, "the primitive has no POSITION attribute");
      std::vector<double> p = read_accessor(pos_attr->second, TINYGLTF_TYPE_VEC3, where + ".POSITION", quantized_, true);
      TriMesh tm;
      const size_t nv = p.size() / 3;
      tm.positions.resize(nv);
      for (size_t i = 0; i < nv; ++i) {
        tm.positions[i] = glm::vec3(float(p[3 * i]), float(p[3 * i + 1]), float(p[3 * i + 2]));
        if (!std::isfinite(tm.positions[i].x) || !std::isfinite(tm.positions[i].y) || !std::isfinite(tm.positions[i].z))
          fail("accessors[" + std::to_string(pos_attr->second) + "][" + std::to_string(i) + "]",
               "vertex position is not finite");
      }
      std::vector<uint32_t> idx;
      if (prim.indices < -1) fail(where, "indices " + std::to_string(prim.indices) + " out of range");
      if (prim.material < -1) fail(where, "material " + std::to_string(prim.material) + " out of range");
      if (prim.indices >= 0) {
        std::vector<double> raw = read_accessor(prim.indices, TINYGLTF_TYPE_SCALAR, where + ".indices", true, false);
        idx.resize(raw.size());
        for (size_t i = 0; i < raw.size(); ++i) {
          if (!(raw[i] >= 0.0 && raw[i] < double(nv)))
            fail("accessors[" + std::to_string(prim.indices) + "][" + std::to_string(i) + "]",
                 "index " + std::to_string(int64_t(raw[i])) + " out of range (" + std::to_string(nv) + " vertices)");
          idx[i] = uint32_t(raw[i]);
        }
      } else {
        idx.resize(nv);
        for (size_t i = 0; i < nv; ++i) idx[i] = uint32_t(i);
      }
      if (mode == TINYGLTF_MODE_TRIANGLES) {
        if (idx.size() % 3 != 0)  // glTF 2.0, 3.7.2.1: a multiple of 3; the rest is no triangle
          warn_once(where + ": " + std::to_string(idx.size()) + " vertices or indices, not a multiple of 3; the last " +
                    std::to_string(idx.size() % 3) + " ignored");
        for (size_t i = 0; i + 2 < idx.size(); i += 3) tm.triangles.push_back({idx[i], idx[i + 1], idx[i + 2]});
      } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
        for (size_t i = 0; i + 2 < idx.size(); ++i)
          tm.triangles.push_back(i % 2 == 0 ? glm::uvec3(idx[i], idx[i + 1], idx[i + 2])
                                            : glm::uvec3(idx[i + 1], idx[i], idx[i + 2]));
      } else {
        for (size_t i = 1; i + 1 < idx.size(); ++i) tm.triangles.push_back({idx[0], idx[i], idx[i + 1]});
      }
      // Shading normals and texture coordinates (glTF's uv origin is the image's
      // top-left, as Mitsuba's). Without normals, glTF asks for flat shading.
      auto normal_attr = prim.attributes.find("NORMAL");
      if (normal_attr != prim.attributes.end()) {
        std::vector<double> n = read_accessor(normal_attr->second, TINYGLTF_TYPE_VEC3, where + ".NORMAL", false, true);
        if (n.size() != p.size()) fail(where, "NORMAL and POSITION have different counts");
        tm.normals.resize(nv);
        for (size_t i = 0; i < nv; ++i) {
          glm::vec3 v{float(n[3 * i]), float(n[3 * i + 1]), float(n[3 * i + 2])};
          tm.normals[i] = std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z) ? v : glm::vec3(0.0f);
        }
      }
      auto uv_attr = prim.attributes.find("TEXCOORD_0");
      if (uv_attr != prim.attributes.end()) {
        std::vector<double> t = read_accessor(uv_attr->second, TINYGLTF_TYPE_VEC2, where + ".TEXCOORD_0", quantized_, true);
        if (t.size() != 2 * nv) fail(where, "TEXCOORD_0 and POSITION have different counts");
        tm.uvs.resize(nv);
        for (size_t i = 0; i < nv; ++i) tm.uvs[i] = glm::vec2(float(t[2 * i]), float(t[2 * i + 1]));
      }
      // Tangents (xyz, handedness w) give the normal map's frame; glTF ignores
      // them without normals, and so do we.
      auto tangent_attr = prim.attributes.find("TANGENT");
      if (tangent_attr != prim.attributes.end() && !tm.normals.empty()) {
        std::vector<double> t = read_accessor(tangent_attr->second, TINYGLTF_TYPE_VEC4, where + ".TANGENT", false, true);
        if (t.size() != 4 * nv) fail(where, "TANGENT and POSITION have different counts");
        tm.tangents.resize(nv);
        for (size_t i = 0; i < nv; ++i) {
          glm::vec3 v{float(t[4 * i]), float(t[4 * i + 1]), float(t[4 * i + 2])};
          const bool ok = std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z) && std::isfinite(t[4 * i + 3]);
          tm.tangents[i] = ok ? glm::vec4(v, t[4 * i + 3] < 0.0 ? -1.0f : 1.0f) : glm::vec4(0.0f);
        }
      }
      // Without TANGENT, a normal-mapped primitive gets MikkTSpace-like tangents
      // (the specification's choice), continuous across its triangles.
      const bool normal_mapped = prim.material >= 0 && size_t(prim.material) < model_.materials.size() &&
                                 model_.materials[size_t(prim.material)].normalTexture.index >= 0;
      if (tangent_attr == prim.attributes.end() && !tm.normals.empty() && !tm.uvs.empty() && normal_mapped)
        compute_vertex_tangents(tm);
      // Vertex colours (VEC3 or VEC4, float or normalized integers; alpha not used)
      // multiply the base colour.
      auto color_attr = prim.attributes.find("COLOR_0");
      if (color_attr != prim.attributes.end()) {
        const int ai = color_attr->second;
        const bool vec4 = ai >= 0 && size_t(ai) < model_.accessors.size() &&
                          model_.accessors[size_t(ai)].type == TINYGLTF_TYPE_VEC4;
        const size_t k = vec4 ? 4 : 3;
        std::vector<double> c =
            read_accessor(ai, vec4 ? TINYGLTF_TYPE_VEC4 : TINYGLTF_TYPE_VEC3, where + ".COLOR_0", false, true);
        if (c.size() != k * nv) fail(where, "COLOR_0 and POSITION have different counts");
        tm.colors.resize(nv);
        for (size_t i = 0; i < nv; ++i) tm.colors[i] = glm::vec3(float(c[k * i]), float(c[k * i + 1]), float(c[k * i + 2]));
      }
      for (const auto& a : prim.attributes)
        if (a.first != "POSITION" && a.first != "NORMAL" && a.first != "TEXCOORD_0" && a.first != "TANGENT" &&
            a.first != "COLOR_0")
          ignored_attributes_.insert(a.first);
      if (!ignored_attributes_.empty()) {
        std::string list;
        for (const std::string& a : ignored_attributes_) list += (list.empty() ? "" : ", ") + a;
        attribute_warning_ = "vertex attributes " + list + " are not used";
      }
      // A transform with negative determinant mirrors the mesh: reverse the
      // winding so the front stays counter-clockwise (the normals transform by
      // the inverse transpose and need no flip).
      if (glm::determinant(glm::mat3(to_world)) < 0.0f)
        for (glm::uvec3& t : tm.triangles) std::swap(t.y, t.z);
      uint32_t mat = material(prim.material, where);
      if (!tm.colors.empty()) {
        // COLOR_0 multiplies the base colour of every part of the material (its
        // blend partners too); without a material, glTF's default white.
        if (prim.material < 0) {
          if (default_coloured_material_ == uint32_t(-1)) {
            Material m = scene_.materials[mat];
            m.albedo = {{1, 1, 1, 0}};
            m.flags |= PSF_MATFLAG_VERTEX_COLOR;
            default_coloured_material_ = push_material(m, "default (vertex colours)");
          }
          mat = default_coloured_material_;
        }
        for (uint32_t k = mat, n = 0; k < scene_.materials.size() && n < 4; ++n) {
          scene_.materials[k].flags |= PSF_MATFLAG_VERTEX_COLOR;
          if (scene_.materials[k].blend == 0) break;
          k = scene_.materials[k].blend - 1;
        }
      }
      append_mesh(scene_, tm, to_world, mat, false, path_, 0);
    }
    if (!attribute_warning_.empty()) warn_once(attribute_warning_);
  }

  uint32_t material(int index, const std::string& from) {
    if (index < 0) {
      if (default_material_ == uint32_t(-1)) {
        Material m{};
        m.albedo = {{0.5f, 0.5f, 0.5f, 0}};
        m.type = PSF_MATERIAL_DIFFUSE;
        m.two_sided = 1;
        default_material_ = push_material(m, "default");
      }
      return default_material_;
    }
    if (size_t(index) >= model_.materials.size()) fail(from, "material index " + std::to_string(index) + " out of range");
    if (materials_[size_t(index)] != uint32_t(-1)) return materials_[size_t(index)];
    const tinygltf::Material& g = model_.materials[size_t(index)];
    std::string where = "materials[" + std::to_string(index) + "]" + (g.name.empty() ? "" : " '" + g.name + "'");
    const auto& pbr = g.pbrMetallicRoughness;
    glm::vec3 base(1.0f);
    if (pbr.baseColorFactor.size() >= 3)
      base = glm::vec3(float(pbr.baseColorFactor[0]), float(pbr.baseColorFactor[1]), float(pbr.baseColorFactor[2]));
    glm::vec3 emission(0.0f);
    if (g.emissiveFactor.size() == 3)
      emission = glm::vec3(float(g.emissiveFactor[0]), float(g.emissiveFactor[1]), float(g.emissiveFactor[2]));
    auto strength = g.extensions.find("KHR_materials_emissive_strength");
    if (strength != g.extensions.end() && strength->second.Has("emissiveStrength"))
      emission *= float(strength->second.Get("emissiveStrength").GetNumberAsDouble());
    std::vector<std::string> left_out;
    uint32_t texture = PSF_NO_TEXTURE, opacity_texture = PSF_NO_TEXTURE;
    // Alpha (glTF 2.0 Sec. 3.9.4): MASK is opaque where alpha >= alphaCutoff and
    // absent elsewhere, BLEND an opacity of alpha (a stochastic cut-out, as
    // Mitsuba's mask: a surface of opacity a is seen with probability a);
    // alpha = baseColorFactor[3] times the base colour texture's alpha.
    const bool masked = g.alphaMode == "MASK", blended = g.alphaMode == "BLEND";
    const float alpha_factor =
        pbr.baseColorFactor.size() >= 4 ? std::clamp(float(pbr.baseColorFactor[3]), 0.0f, 1.0f) : 1.0f;
    const float cutoff = float(g.alphaCutoff);
    if (pbr.baseColorTexture.index >= 0) {
      texture = base_color_texture(pbr.baseColorTexture, base, where);
      if (texture != PSF_NO_TEXTURE && (masked || blended))
        opacity_texture = alpha_texture(pbr.baseColorTexture, alpha_factor, masked ? cutoff : -1.0f, where);
      if (texture == PSF_NO_TEXTURE) left_out.push_back("baseColorTexture (not decoded; using baseColorFactor)");
      if (pbr.baseColorTexture.texCoord != 0) left_out.push_back("baseColorTexture.texCoord != 0 (using TEXCOORD_0)");
    }
    // Metallic-roughness (glTF 2.0 Appendix B): metals as roughconductor whose
    // Fresnel reflectance at normal incidence is the base colour, dielectrics as
    // roughplastic with IOR 1.5 over the base colour; GGX with alpha = roughness^2
    // (the smooth types at roughness 0). Metallic between 0 and 1, from the
    // factor or from metallicRoughnessTexture's blue channel, blends the two
    // (Material.blend: the metal scatters with probability metallic).
    const float metallic = std::clamp(float(pbr.metallicFactor), 0.0f, 1.0f);
    const float roughness = std::clamp(float(pbr.roughnessFactor), 0.0f, 1.0f);
    const bool has_mr_texture = pbr.metallicRoughnessTexture.index >= 0;
    const bool metal_only = metallic >= 1.0f && !has_mr_texture, has_metal = metallic > 0.0f;
    uint32_t alpha_map = PSF_NO_TEXTURE, metallic_map = PSF_NO_TEXTURE;
    if (has_mr_texture && has_metal) {
      metallic_map = metallic_texture(pbr.metallicRoughnessTexture, where);
      if (metallic_map == PSF_NO_TEXTURE) left_out.push_back("metallicRoughnessTexture (not decoded; using the factors)");
    }
    uint32_t normal_map = PSF_NO_TEXTURE;
    if (g.normalTexture.index >= 0) {
      // Linear (not sRGB-decoded): rgb = (n + 1) / 2 of the tangent-space normal n.
      normal_map = make_texture(g.normalTexture.index, g.normalTexture.extensions, where, false, true);
      if (normal_map == PSF_NO_TEXTURE) left_out.push_back("normalTexture (not decoded)");
      if (g.normalTexture.texCoord != 0) left_out.push_back("normalTexture.texCoord != 0 (using TEXCOORD_0)");
    }
    // KHR_materials_ior (default 1.5) and KHR_materials_transmission: the
    // dielectric transmits as a (rough)dielectric whose transmission the base
    // colour tints; a factor between 0 and 1 blends it with the plastic.
    auto ext_number = [&](const char* ext, const char* name, float fallback) {
      auto it = g.extensions.find(ext);
      if (it == g.extensions.end() || !it->second.Has(name)) return fallback;
      const tinygltf::Value& v = it->second.Get(name);
      return v.IsNumber() || v.IsInt() ? float(v.GetNumberAsDouble()) : fallback;
    };
    float ior = ext_number("KHR_materials_ior", "ior", 1.5f);
    if (!(ior >= 1.0f)) ior = 1.5f;  // 0 (or nonsense): the default
    // ior 1 refracts nothing; the glass part's half-vector needs it apart from 1
    // (exactly 1, a rough transmission rendered black).
    const float glass_ior = std::max(ior, 1.001f);
    const float transmission =
        std::clamp(ext_number("KHR_materials_transmission", "transmissionFactor", 0.0f), 0.0f, 1.0f);
    const bool transmits = !metal_only && transmission > 0.0f;
    // KHR_materials_volume: the volume a transmitting surface encloses absorbs,
    // sigma = -ln(attenuationColor) / attenuationDistance per world unit (Beer's
    // law, as the extension defines it; Material.interior). A thicknessFactor of
    // 0 (the default) makes the surface a thin wall without a volume; the
    // thickness itself is for rasterisers: a path tracer has the geometry.
    glm::vec4 interior(0.0f);
    if (auto vol = g.extensions.find("KHR_materials_volume"); transmits && vol != g.extensions.end()) {
      const float thickness = ext_number("KHR_materials_volume", "thicknessFactor", 0.0f);
      const float distance = ext_number("KHR_materials_volume", "attenuationDistance", INFINITY);
      glm::vec3 color(1.0f);
      const tinygltf::Value& c = vol->second.Get("attenuationColor");
      if (c.IsArray() && c.ArrayLen() == 3)
        for (int i = 0; i < 3; ++i)
          if (c.Get(i).IsNumber() || c.Get(i).IsInt()) color[i] = float(c.Get(i).GetNumberAsDouble());
      if (thickness > 0.0f) {
        glm::vec3 sigma(0.0f);
        if (distance > 0.0f && std::isfinite(distance))
          for (int i = 0; i < 3; ++i) sigma[i] = -std::log(std::clamp(color[i], 1e-6f, 1.0f)) / distance;
        interior = glm::vec4(sigma, 1.0f);
      }
    }
    if (transmits && texture != PSF_NO_TEXTURE)  // a dielectric's texture would tint its reflection
      left_out.push_back("baseColorTexture on a transmitting material (using its mean as the transmittance)");
    // The texture's roughness (green) per hit, for every part (roughconductor,
    // roughdielectric, and roughplastic through its table of rows by roughness).
    if (has_mr_texture && roughness > 0.0f)
      alpha_map = roughness_texture(pbr.metallicRoughnessTexture, roughness, where);
    // The emission: emissiveFactor (times KHR_materials_emissive_strength) times
    // the emissive texture (sRGB-decoded), evaluated where it is hit or sampled.
    uint32_t emission_map = PSF_NO_TEXTURE;
    if (g.emissiveTexture.index >= 0 && glm::length(emission) > 0.0f) {
      emission_map = make_texture(g.emissiveTexture.index, g.emissiveTexture.extensions, where, true, true);
      if (emission_map == PSF_NO_TEXTURE) left_out.push_back("emissiveTexture (not decoded; using emissiveFactor)");
      if (g.emissiveTexture.texCoord != 0) left_out.push_back("emissiveTexture.texCoord != 0 (using TEXCOORD_0)");
    }
    if (g.alphaMode != "OPAQUE" && !masked && !blended) left_out.push_back("alphaMode " + g.alphaMode);
    for (const auto& e : g.extensions)
      if (e.first != "KHR_materials_emissive_strength" && e.first != "KHR_materials_transmission" &&
          e.first != "KHR_materials_ior" && e.first != "KHR_materials_volume")
        left_out.push_back(e.first);
    if (!left_out.empty()) {
      std::string list;
      for (const std::string& s : left_out) list += (list.empty() ? "" : ", ") + s;
      warn_once(where + ": not supported: " + list);
    }
    if (texture != PSF_NO_TEXTURE) base = textures_.mean(texture);  // the texture already holds the factor
    const glm::vec3 albedo = glm::clamp(base, 0.0f, 1.0f);
    const bool rough = roughness > 0.0f;
    // The parts' common settings: roughness, normal map, cut-out, emission, sides.
    auto part = [&]() {
      Material m{};
      m.tex_color = texture;
      m.alpha_u = m.alpha_v = std::max(roughness * roughness, 1e-4f);  // Mitsuba's lower bound
      if (alpha_map != PSF_NO_TEXTURE) {  // the roughness per texel; its mean until a hit reads it
        m.tex_alpha = alpha_map;
        m.alpha_u = m.alpha_v = std::max(textures_.mean(alpha_map).x, 1e-4f);
      }
      if (normal_map != PSF_NO_TEXTURE) {
        m.tex_bump = normal_map;
        m.bump_scale = float(g.normalTexture.scale);
        m.flags |= PSF_MATFLAG_NORMALMAP;
      }
      if (masked || blended) {
        // Without a texture the whole surface has one alpha.
        m.opacity = opacity_texture != PSF_NO_TEXTURE ? 1.0f
                    : masked                          ? (alpha_factor >= cutoff ? 1.0f : 0.0f)
                                                      : alpha_factor;
        m.tex_opacity = opacity_texture;
        if (m.opacity < 1.0f || m.tex_opacity != PSF_NO_TEXTURE) m.flags |= PSF_MATFLAG_MASKED;
      }
      m.emission = {{std::max(emission.x, 0.0f), std::max(emission.y, 0.0f), std::max(emission.z, 0.0f), 0}};
      m.tex_emission = emission_map;
      m.two_sided = g.doubleSided ? 1u : 0u;
      m.interior = {{interior.x, interior.y, interior.z, interior.w}};
      return m;
    };
    // The metal: the base colour is the reflectance at normal incidence, eta and k
    // from it (per hit from the texture: PSF_MATFLAG_REFLECTANCE, kernels/surface.cl).
    auto metal_part = [&]() {
      Material m = part();
      m.type = rough ? PSF_MATERIAL_ROUGH_CONDUCTOR : PSF_MATERIAL_CONDUCTOR;
      glm::vec3 eta, k;
      detail::conductor_from_reflectance(albedo, eta, k);
      m.eta = {{eta.x, eta.y, eta.z, 0}};
      m.k = {{k.x, k.y, k.z, 0}};
      m.specular = {{1, 1, 1, 0}};
      if (texture != PSF_NO_TEXTURE) m.flags |= PSF_MATFLAG_REFLECTANCE;
      return m;
    };
    auto glass_part = [&]() {
      Material m = part();
      m.type = rough ? PSF_MATERIAL_ROUGH_DIELECTRIC : PSF_MATERIAL_DIELECTRIC;
      m.eta = {{glass_ior, 1.0f / (glass_ior * glass_ior), 0, 0}};
      m.specular = {{1, 1, 1, 0}};
      m.transmittance = {{albedo.x, albedo.y, albedo.z, 0}};
      m.tex_color = PSF_NO_TEXTURE;
      return m;
    };
    auto plastic_part = [&]() {
      Material m = part();
      m.type = rough ? PSF_MATERIAL_ROUGH_PLASTIC : PSF_MATERIAL_PLASTIC;
      m.albedo = {{albedo.x, albedo.y, albedo.z, 0}};
      m.specular = {{1, 1, 1, 0}};
      m.eta = {{ior > 1.0f ? ior : 1.5f, 0, 0, 0}};
      detail::finish_plastic(m, (albedo.x + albedo.y + albedo.z) / 3.0f, 1.0f, textures_);
      return m;
    };
    // `m` hands the shading point to `partner` (pushed here) with probability
    // `weight` times texture `tex` (Material.blend).
    auto blend = [&](Material& m, const Material& partner, const std::string& part_name, float weight, uint32_t tex) {
      m.blend = 1 + push_material(partner, part_name);
      m.blend_weight = weight;
      m.tex_blend = tex;
    };
    const std::string name = g.name.empty() ? "material" + std::to_string(index) : g.name;
    const bool metal_texture = metallic_map != PSF_NO_TEXTURE;
    if (metal_only || (has_metal && !metal_texture && metallic >= 1.0f))
      return materials_[size_t(index)] = push_material(metal_part(), name);
    Material top = transmits && transmission >= 1.0f ? glass_part() : plastic_part();
    if (!transmits || transmission >= 1.0f) {
      if (has_metal) blend(top, metal_part(), name + " (metal)", metallic, metallic_map);
    } else if (!has_metal) {
      blend(top, glass_part(), name + " (transmission)", transmission, PSF_NO_TEXTURE);
    } else {
      // Metal with probability M (metallic), glass with (1 - M) t, plastic with
      // (1 - M)(1 - t): the plastic hands over to the glass with w1 = M + (1 - M) t,
      // the glass to the metal with M / w1; per texel where M comes from the texture.
      const float t = transmission;
      auto w1 = [t](float m) { return m + (1.0f - m) * t; };
      Material glass = glass_part();
      if (metal_texture) {
        const auto& info = pbr.metallicRoughnessTexture;
        blend(glass, metal_part(), name + " (metal)", 1.0f,
              metallic_texture(info, where, [&](float b) { return metallic * b / w1(metallic * b); }));
        blend(top, glass, name + " (transmission)", 1.0f,
              metallic_texture(info, where, [&](float b) { return w1(metallic * b); }));
      } else {
        blend(glass, metal_part(), name + " (metal)", metallic / w1(metallic), PSF_NO_TEXTURE);
        blend(top, glass, name + " (transmission)", w1(metallic), PSF_NO_TEXTURE);
      }
    }
    return materials_[size_t(index)] = push_material(top, name);
  }

  // Texture `index` decoded (sRGB unless `srgb` is false), each texel's 4 floats
  // passed through `map` (if any), with the sampler and the uv transform of the
  // textureInfo's `extensions`; PSF_NO_TEXTURE if the image has no usable pixels.
  // `warn`: report the sampler's unsupported settings (once per texture use).
  uint32_t make_texture(int index, const tinygltf::ExtensionMap& extensions, const std::string& where, bool srgb,
                        bool warn, const std::function<void(float*)>& map = {}) {
    int width = 0, height = 0;
    std::vector<float> rgba = decode_texture(index, where, width, height, srgb);
    if (rgba.empty()) return PSF_NO_TEXTURE;
    if (map)
      for (size_t i = 0; i < rgba.size(); i += 4) map(&rgba[i]);
    return textures_.pixels(texture_desc(index, extensions, warn), width, height, rgba);
  }

  // The base colour texture times the factor, as linear RGB (the image is
  // sRGB-encoded, glTF 2.0 Sec. 3.9.2), or PSF_NO_TEXTURE.
  uint32_t base_color_texture(const tinygltf::TextureInfo& info, const glm::vec3& factor, const std::string& where) {
    return make_texture(info.index, info.extensions, where, true, true, [&](float* t) {
      for (int k = 0; k < 3; ++k) t[k] *= factor[k];
    });
  }

  // The microfacet alpha = (factor g)^2 of the metallic-roughness texture
  // (linear; roughness in green) in the x channel, or PSF_NO_TEXTURE.
  uint32_t roughness_texture(const tinygltf::TextureInfo& info, float factor, const std::string& where) {
    return make_texture(info.index, info.extensions, where, false, false, [&](float* t) {
      float r = factor * t[1];
      t[0] = t[1] = t[2] = r * r;
      t[3] = 1.0f;
    });
  }

  // The metallic channel (blue) of a metallicRoughnessTexture, through `f`, in
  // the x channel.
  uint32_t metallic_texture(const tinygltf::TextureInfo& info, const std::string& where,
                            const std::function<float(float)>& f = [](float b) { return b; }) {
    return make_texture(info.index, info.extensions, where, false, false, [&](float* t) {
      t[0] = t[1] = t[2] = f(t[2]);
      t[3] = 1.0f;
    });
  }

  // The opacity of the base colour texture in the x channel: its alpha times
  // `factor`, thresholded at `cutoff` (0 below, 1 at or above) unless cutoff < 0.
  uint32_t alpha_texture(const tinygltf::TextureInfo& info, float factor, float cutoff, const std::string& where) {
    return make_texture(info.index, info.extensions, where, true, false, [&](float* t) {
      float a = t[3] * factor;
      if (cutoff >= 0.0f) a = a >= cutoff ? 1.0f : 0.0f;
      t[0] = t[1] = t[2] = a;
      t[3] = 1.0f;
    });
  }

  // Texture `index`'s image as RGB (sRGB-decoded unless `srgb` is false) and
  // alpha, 4 floats a texel, rows from the top; empty if it has no usable pixels.
  std::vector<float> decode_texture(int index, const std::string& where, int& width, int& height,
                                    bool srgb = true) {
    if (size_t(index) >= model_.textures.size()) fail(where, "texture index " + std::to_string(index) + " out of range");
    const tinygltf::Texture& tex = model_.textures[size_t(index)];
    if (tex.source < 0 || size_t(tex.source) >= model_.images.size())
      fail("textures[" + std::to_string(index) + "]", "image index " + std::to_string(tex.source) + " out of range");
    const tinygltf::Image& img = model_.images[size_t(tex.source)];
    const size_t n = size_t(std::max(img.width, 0)) * size_t(std::max(img.height, 0));
    const int c = img.component, bytes = img.bits == 16 ? 2 : 1;
    if (n == 0 || c < 1 || c > 4 || (img.bits != 8 && img.bits != 16) || img.image.size() < n * size_t(c * bytes))
      return {};
    width = img.width;
    height = img.height;
    std::vector<float> rgba(n * 4, 1.0f);
    for (size_t i = 0; i < n; ++i)
      for (int k = 0; k < c; ++k) {
        size_t at = (i * size_t(c) + size_t(k)) * size_t(bytes);
        float v = bytes == 2 ? float(img.image[at] | (img.image[at + 1] << 8)) / 65535.0f : float(img.image[at]) / 255.0f;
        bool alpha = k == 3 || (c == 2 && k == 1);
        if (!alpha && srgb) v = srgb_to_linear(v);
        if (c <= 2 && k == 0) rgba[i * 4 + 1] = rgba[i * 4 + 2] = v;  // grey (+ alpha)
        rgba[i * 4 + (c <= 2 && k == 1 ? 3 : size_t(k))] = v;
      }
    return rgba;
  }

  // Filtering and wrapping of texture `index` from its sampler, and the uv
  // transform of KHR_texture_transform in the textureInfo's `extensions` (u' =
  // T R S u: offset, rotation, scale), with u' = cos u + sin v and v' = -sin u +
  // cos v for the rotation, as the extension's worked example (offset [0, 1],
  // rotation pi/2, scale 0.5: the image's lower left quadrant) and the sample
  // viewers read it (its GLSL listing has the opposite sign: glTF issue 1563);
  // `warn`: report what is not supported.
  TextureDesc texture_desc(int index, const tinygltf::ExtensionMap& extensions, bool warn) {
    const tinygltf::Texture& tex = model_.textures[size_t(index)];
    TextureDesc desc;
    auto transform = extensions.find("KHR_texture_transform");
    if (transform != extensions.end()) {
      const tinygltf::Value& t = transform->second;
      auto number = [&](const tinygltf::Value& v, double fallback) {
        return v.IsNumber() || v.IsInt() ? v.GetNumberAsDouble() : fallback;
      };
      auto pair = [&](const char* name, double fallback) {
        glm::dvec2 out(fallback);
        if (t.Has(name) && t.Get(name).IsArray() && t.Get(name).ArrayLen() == 2)
          out = glm::dvec2(number(t.Get(name).Get(0), fallback), number(t.Get(name).Get(1), fallback));
        return out;
      };
      const glm::dvec2 offset = pair("offset", 0.0), scale = pair("scale", 1.0);
      const double angle = t.Has("rotation") ? number(t.Get("rotation"), 0.0) : 0.0;
      const double c = std::cos(angle), sn = std::sin(angle);
      desc.uv_u = glm::vec3(float(c * scale.x), float(sn * scale.y), float(offset.x));
      desc.uv_v = glm::vec3(float(-sn * scale.x), float(c * scale.y), float(offset.y));
      if (warn && t.Has("texCoord") && number(t.Get("texCoord"), 0.0) != 0.0)
        warn_once("KHR_texture_transform texCoord != 0: using TEXCOORD_0");
    }
    desc.path = "gltf:" + path_ + ":images[" + std::to_string(tex.source) + "]";
    if (tex.sampler >= 0 && size_t(tex.sampler) < model_.samplers.size()) {
      const tinygltf::Sampler& smp = model_.samplers[size_t(tex.sampler)];
      desc.bilinear = smp.magFilter != TINYGLTF_TEXTURE_FILTER_NEAREST;
      if (smp.wrapS == TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE) desc.wrap = PSF_TEX_CLAMP;
      if (smp.wrapS == TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT) desc.wrap = PSF_TEX_MIRROR;
      if (smp.wrapS != smp.wrapT && warn)
        warn_once("samplers[" + std::to_string(tex.sampler) + "]: wrapT differs from wrapS; using wrapS");
    }
    return desc;
  }

  uint32_t push_material(const Material& m, const std::string& name) {
    scene_.materials.push_back(m);
    scene_.material_names.push_back(name);
    return uint32_t(scene_.materials.size() - 1);
  }

  // --- cameras and lights -----------------------------------------------------------

  void add_camera(int index, const glm::mat4& m, const std::string& from) {
    if (size_t(index) >= model_.cameras.size()) fail(from, "camera index " + std::to_string(index) + " out of range");
    const tinygltf::Camera& c = model_.cameras[size_t(index)];
    std::string where = "cameras[" + std::to_string(index) + "]";
    if (c.type != "perspective") {
      warn_once(where + ": camera type '" + c.type + "' is not supported; ignored");
      return;
    }
    if (has_camera_) {
      warn_once(where + ": only the first camera is used");
      return;
    }
    if (!(c.perspective.yfov > 0.0 && c.perspective.yfov < 3.14159)) fail(where, "yfov must lie in (0, pi)");
    has_camera_ = true;
    CameraDesc& cam = scene_.camera;
    cam.origin = glm::vec3(m * glm::vec4(0, 0, 0, 1));
    cam.target = glm::vec3(m * glm::vec4(0, 0, -1, 1));
    glm::vec3 up = glm::mat3(m) * glm::vec3(0, 1, 0);
    if (glm::length(glm::cross(cam.target - cam.origin, up)) <= 0.0f) fail(where, "the camera's node transform is degenerate");
    cam.up = glm::normalize(up);
    cam.fov_degrees = float(glm::degrees(c.perspective.yfov));
    cam.fov_axis = "y";
    // A mirroring transform flips the image left-right.
    cam.mirrored = glm::determinant(glm::mat3(m)) < 0.0f;
    if (c.perspective.aspectRatio > 0.0) {
      scene_.height = 512;
      scene_.width = std::max(1, int(std::lround(512.0 * c.perspective.aspectRatio)));
    }
  }

  void add_light(int index, const glm::mat4& m, const std::string& from) {
    std::string where = "KHR_lights_punctual.lights[" + std::to_string(index) + "]";
    if (index < 0 || size_t(index) >= model_.lights.size()) fail(from, "light index " + std::to_string(index) + " out of range");
    const tinygltf::Light& g = model_.lights[size_t(index)];
    LightDesc l;
    glm::vec3 color(1.0f);
    if (g.color.size() == 3) color = glm::vec3(float(g.color[0]), float(g.color[1]), float(g.color[2]));
    if (!(g.intensity >= 0.0) || !std::isfinite(g.intensity) || glm::any(glm::lessThan(color, glm::vec3(0.0f))))
      fail(where, "intensity and color must be finite and not negative (KHR_lights_punctual)");
    l.color = glm::max(color * float(g.intensity), glm::vec3(0.0f));
    l.position = glm::vec3(m * glm::vec4(0, 0, 0, 1));
    glm::vec3 dir = glm::mat3(m) * glm::vec3(0, 0, -1);
    if (!(glm::length(dir) > 0.0f)) fail(from, "the light's node transform is degenerate");
    l.direction = glm::normalize(dir);
    l.source = path_ + ": " + where;
    if (g.type == "point") {
      l.type = LightType::Point;
    } else if (g.type == "spot") {
      l.type = LightType::Spot;
      l.cutoff_angle = float(g.spot.outerConeAngle);
      l.beam_width = float(std::min(g.spot.innerConeAngle, g.spot.outerConeAngle));
    } else if (g.type == "directional") {
      l.type = LightType::Directional;
    } else {
      warn_once(where + ": light type '" + g.type + "' is not supported; ignored");
      return;
    }
    scene_.lights.push_back(l);
  }

  std::string path_;
  tinygltf::Model model_;
  Scene scene_;
  TextureStore textures_{scene_};              // base colour textures, into scene_
  std::vector<uint32_t> materials_;            // glTF material -> scene material, -1 until used
  uint32_t default_material_ = uint32_t(-1);  // for primitives without a material
  uint32_t default_coloured_material_ = uint32_t(-1);  // the same, white, for primitives with COLOR_0
  bool has_camera_ = false;
  std::set<const tinygltf::Primitive*> draco_decoded_;  // primitives whose compressed data are decoded
  bool quantized_ = false;  // KHR_mesh_quantization: integer positions and uvs (the nodes' transforms scale them)
  std::set<std::string> ignored_attributes_;   // vertex attributes other than POSITION
  std::string attribute_warning_;
};

}  // namespace

Scene load_gltf_scene(const std::string& path) { return GltfLoader(path).load(); }

}  // namespace psf::detail
