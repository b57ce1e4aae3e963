// PLY (Stanford polygon file format) reader: ASCII and binary of either byte
// order, written for robustness rather than speed: every read is bounds-checked,
// every index range-checked and every position checked for NaN/Inf, and errors
// name the header line, the ASCII body line or the binary byte offset.
//
// Format (Turk, "The PLY polygon file format", 1994): a text header
//   ply / format <ascii|binary_little_endian|binary_big_endian> 1.0 /
//   { comment ... | obj_info ... | element <name> <count> /
//     { property <type> <name> | property list <count type> <item type> <name> } } /
//   end_header
// then the elements' items in header order, each item its properties in order.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>

#include "scene/formats.h"
#include "scene/loaders.h"

namespace psf::detail {
namespace {

enum class PlyType { I8, U8, I16, U16, I32, U32, F32, F64 };

// Type names of the PLY specification and their sized aliases (as written by VTK, Blender, ...).
bool parse_type(const std::string& name, PlyType& t) {
  static const std::map<std::string, PlyType> types = {
      {"char", PlyType::I8},     {"int8", PlyType::I8},     {"uchar", PlyType::U8},    {"uint8", PlyType::U8},
      {"short", PlyType::I16},   {"int16", PlyType::I16},   {"ushort", PlyType::U16},  {"uint16", PlyType::U16},
      {"int", PlyType::I32},     {"int32", PlyType::I32},   {"uint", PlyType::U32},    {"uint32", PlyType::U32},
      {"float", PlyType::F32},   {"float32", PlyType::F32}, {"double", PlyType::F64},  {"float64", PlyType::F64}};
  auto it = types.find(name);
  if (it == types.end()) return false;
  t = it->second;
  return true;
}

size_t type_size(PlyType t) {
  switch (t) {
    case PlyType::I8:
    case PlyType::U8:
      return 1;
    case PlyType::I16:
    case PlyType::U16:
      return 2;
    case PlyType::I32:
    case PlyType::U32:
    case PlyType::F32:
      return 4;
    case PlyType::F64:
      return 8;
  }
  return 1;
}

bool is_integer(PlyType t) { return t != PlyType::F32 && t != PlyType::F64; }

struct PlyProperty {
  std::string name;
  bool list = false;
  PlyType count_type = PlyType::U8;  // list: type of the item count
  PlyType type = PlyType::F32;       // the value, or a list's items
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  int line = 0;  // header line of the element
  std::vector<PlyProperty> props;
};

enum class Format { Ascii, BinaryLittle, BinaryBig };

bool host_is_little_endian() {
  const uint16_t one = 1;
  unsigned char b;
  std::memcpy(&b, &one, 1);
  return b == 1;
}

// Reads values of the body, ASCII or binary, with their location for messages.
class BodyReader {
 public:
  BodyReader(const std::string& path, const std::string& data, size_t offset, int line, Format format)
      : path_(path), data_(data), pos_(offset), line_(line), format_(format) {
    swap_ = format != Format::Ascii && (format == Format::BinaryLittle) != host_is_little_endian();
  }

  // The location of the next value: "line N" (ASCII) or "byte N" (binary).
  std::string where() const {
    return format_ == Format::Ascii ? "line " + std::to_string(line_) : "byte " + std::to_string(pos_);
  }

  [[noreturn]] void fail(const std::string& message) const {
    if (format_ == Format::Ascii) throw SceneError(path_, line_, message);
    throw SceneError(path_, 0, "byte " + std::to_string(pos_) + ": " + message);
  }

  // Bytes left (binary); used to reject impossible element counts early.
  size_t remaining() const { return data_.size() - std::min(pos_, data_.size()); }
  bool binary() const { return format_ != Format::Ascii; }
  // Bytes after the last element that are not blank (ASCII) or at all (binary).
  size_t trailing() const {
    if (format_ != Format::Ascii) return remaining();
    size_t n = 0;
    for (size_t i = pos_; i < data_.size(); ++i) n += std::isspace(static_cast<unsigned char>(data_[i])) ? 0 : 1;
    return n;
  }

  double read(PlyType t) { return format_ == Format::Ascii ? read_ascii(t) : read_binary(t); }

  // Skips past the rest of the body's current ASCII line (items end at a newline).
  void end_ascii_item() {
    if (format_ != Format::Ascii) return;
    while (pos_ < data_.size() && (data_[pos_] == ' ' || data_[pos_] == '\t' || data_[pos_] == '\r')) ++pos_;
    if (pos_ < data_.size() && data_[pos_] != '\n') fail("more values than the header's properties declare");
  }

 private:
  double read_binary(PlyType t) {
    size_t n = type_size(t);
    if (pos_ + n > data_.size()) fail("the file ends inside the binary data (truncated)");
    unsigned char b[8];
    std::memcpy(b, data_.data() + pos_, n);
    if (swap_) std::reverse(b, b + n);
    pos_ += n;
    switch (t) {
      case PlyType::I8: return double(int8_t(b[0]));
      case PlyType::U8: return double(b[0]);
      case PlyType::I16: { int16_t v; std::memcpy(&v, b, 2); return double(v); }
      case PlyType::U16: { uint16_t v; std::memcpy(&v, b, 2); return double(v); }
      case PlyType::I32: { int32_t v; std::memcpy(&v, b, 4); return double(v); }
      case PlyType::U32: { uint32_t v; std::memcpy(&v, b, 4); return double(v); }
      case PlyType::F32: { float v; std::memcpy(&v, b, 4); return double(v); }
      case PlyType::F64: { double v; std::memcpy(&v, b, 8); return v; }
    }
    return 0.0;
  }

  double read_ascii(PlyType t) {
    // Values of one item may not continue on the next line, but items may be
    // separated by blank lines.
    while (pos_ < data_.size() && std::isspace(static_cast<unsigned char>(data_[pos_]))) {
      if (data_[pos_] == '\n') ++line_;
      ++pos_;
    }
    if (pos_ >= data_.size()) fail("the file ends before all elements declared in the header were read");
    size_t end = pos_;
    while (end < data_.size() && !std::isspace(static_cast<unsigned char>(data_[end]))) ++end;
    std::string token = data_.substr(pos_, end - pos_);
    char* stop = nullptr;
    double v;
    if (is_integer(t)) {
      long long i = std::strtoll(token.c_str(), &stop, 10);
      if (stop != token.c_str() + token.size()) fail("'" + token + "' is not an integer");
      v = double(i);
    } else {
      v = std::strtod(token.c_str(), &stop);
      if (stop != token.c_str() + token.size()) fail("'" + token + "' is not a number");
    }
    pos_ = end;
    return v;
  }

  const std::string& path_;
  const std::string& data_;
  size_t pos_;
  int line_;
  Format format_;
  bool swap_ = false;
};

// Roles of the vertex properties the reader uses.
enum Role { kX, kY, kZ, kNx, kNy, kNz, kU, kV, kR, kG, kB, kRoles };

}  // namespace

PlyMesh read_ply(const std::string& path) {
  require_readable_input(path, "PLY file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path, 0, "cannot open PLY file");
  std::string data = read_all(in);

  // --- header ---
  std::vector<PlyElement> elements;
  Format format = Format::Ascii;
  bool have_format = false;
  size_t pos = 0;
  int line = 0;
  bool ended = false;
  while (!ended) {
    if (pos >= data.size()) throw SceneError(path, line, "the PLY header has no end_header line");
    size_t eol = data.find('\n', pos);
    if (eol == std::string::npos) eol = data.size();
    std::string text = data.substr(pos, eol - pos);
    if (!text.empty() && text.back() == '\r') text.pop_back();
    pos = std::min(eol + 1, data.size());
    ++line;
    std::istringstream words(text);
    std::string key;
    words >> key;
    if (line == 1) {
      if (key != "ply") throw SceneError(path, 1, "not a PLY file (the first line is not 'ply')");
      continue;
    }
    if (key.empty() || key == "comment" || key == "obj_info") continue;
    if (key == "format") {
      std::string name, version;
      words >> name >> version;
      if (name == "ascii") format = Format::Ascii;
      else if (name == "binary_little_endian") format = Format::BinaryLittle;
      else if (name == "binary_big_endian") format = Format::BinaryBig;
      else throw SceneError(path, line, "unknown PLY format '" + name + "'");
      if (version != "1.0") throw SceneError(path, line, "unsupported PLY version '" + version + "' (expected 1.0)");
      have_format = true;
    } else if (key == "element") {
      PlyElement e;
      std::string count;
      words >> e.name >> count;
      char* stop = nullptr;
      unsigned long long n = std::strtoull(count.c_str(), &stop, 10);
      if (e.name.empty() || count.empty() || count[0] == '-' || stop != count.c_str() + count.size())
        throw SceneError(path, line, "bad element line '" + text + "' (expected: element <name> <count>)");
      e.count = n;
      e.line = line;
      elements.push_back(e);
    } else if (key == "property") {
      if (elements.empty()) throw SceneError(path, line, "property before any element");
      PlyProperty p;
      std::string type;
      words >> type;
      if (type == "list") {
        std::string count_type, item_type;
        words >> count_type >> item_type >> p.name;
        p.list = true;
        if (!parse_type(count_type, p.count_type) || !parse_type(item_type, p.type))
          throw SceneError(path, line, "unknown type in '" + text + "'");
        if (!is_integer(p.count_type)) throw SceneError(path, line, "a list count must have an integer type: '" + text + "'");
      } else {
        words >> p.name;
        if (!parse_type(type, p.type)) throw SceneError(path, line, "unknown property type '" + type + "'");
      }
      if (p.name.empty()) throw SceneError(path, line, "property without a name: '" + text + "'");
      elements.back().props.push_back(p);
    } else if (key == "end_header") {
      ended = true;
    } else {
      throw SceneError(path, line, "unexpected header line '" + text + "'");
    }
  }
  if (!have_format) throw SceneError(path, line, "the PLY header has no format line");

  // --- the roles of the vertex and face properties ---
  const PlyElement* vertex_element = nullptr;
  for (const PlyElement& e : elements)
    if (e.name == "vertex") vertex_element = &e;
  if (!vertex_element) throw SceneError(path, line, "the PLY file has no vertex element");
  const uint64_t num_vertices = vertex_element->count;

  PlyMesh out;
  int role_of[kRoles];
  std::fill(role_of, role_of + kRoles, -1);
  {
    const auto& props = vertex_element->props;
    auto index_of = [&](const char* name) {
      for (size_t i = 0; i < props.size(); ++i)
        if (props[i].name == name) return int(i);
      return -1;
    };
    role_of[kX] = index_of("x");
    role_of[kY] = index_of("y");
    role_of[kZ] = index_of("z");
    if (role_of[kX] < 0 || role_of[kY] < 0 || role_of[kZ] < 0)
      throw SceneError(path, vertex_element->line, "the vertex element lacks x, y or z");
    int nx = index_of("nx"), ny = index_of("ny"), nz = index_of("nz");
    if (nx >= 0 && ny >= 0 && nz >= 0) {
      role_of[kNx] = nx;
      role_of[kNy] = ny;
      role_of[kNz] = nz;
    }
    const char* uv_names[][2] = {{"u", "v"}, {"s", "t"}, {"texture_u", "texture_v"}, {"texture_s", "texture_t"}};
    for (auto& names : uv_names) {
      int u = index_of(names[0]), v = index_of(names[1]);
      if (u >= 0 && v >= 0) {
        role_of[kU] = u;
        role_of[kV] = v;
        break;
      }
    }
    const char* color_names[][3] = {{"red", "green", "blue"}, {"r", "g", "b"},
                                    {"diffuse_red", "diffuse_green", "diffuse_blue"}};
    for (auto& names : color_names) {
      int r = index_of(names[0]), g = index_of(names[1]), b = index_of(names[2]);
      if (r >= 0 && g >= 0 && b >= 0) {
        role_of[kR] = r;
        role_of[kG] = g;
        role_of[kB] = b;
        break;
      }
    }
    for (int r = 0; r < kRoles; ++r)
      if (role_of[r] >= 0 && props[size_t(role_of[r])].list)
        throw SceneError(path, vertex_element->line, "vertex property '" + props[size_t(role_of[r])].name + "' is a list");
    for (size_t i = 0; i < props.size(); ++i)
      if (std::find(role_of, role_of + kRoles, int(i)) == role_of + kRoles) out.ignored.push_back("vertex." + props[i].name);
  }

  // --- body ---
  BodyReader body(path, data, pos, line + 1, format);
  out.mesh.positions.reserve(size_t(std::min<uint64_t>(num_vertices, data.size())));
  if (role_of[kNx] >= 0) out.mesh.normals.reserve(out.mesh.positions.capacity());
  if (role_of[kU] >= 0) out.mesh.uvs.reserve(out.mesh.positions.capacity());
  std::vector<double> values;
  uint64_t short_faces = 0;
  for (const PlyElement& e : elements) {
    // Each item has at least one byte per property in binary, one character in ASCII.
    size_t min_item = 0;
    for (const PlyProperty& p : e.props) min_item += body.binary() ? type_size(p.list ? p.count_type : p.type) : 1;
    if (min_item > 0 && e.count > body.remaining() / min_item)
      body.fail("element '" + e.name + "' declares " + std::to_string(e.count) +
                " items, more than the rest of the file can hold (truncated?)");
    bool is_vertex = &e == vertex_element, is_face = e.name == "face";
    int face_list = -1;
    if (is_face) {
      for (size_t i = 0; i < e.props.size(); ++i)
        if (e.props[i].name == "vertex_indices" || e.props[i].name == "vertex_index") face_list = int(i);
      if (face_list < 0 || !e.props[size_t(face_list)].list)
        throw SceneError(path, e.line, "the face element has no list property vertex_indices");
      if (!is_integer(e.props[size_t(face_list)].type))
        throw SceneError(path, e.line, "face vertex indices must have an integer type");
      for (size_t i = 0; i < e.props.size(); ++i)
        if (int(i) != face_list) out.ignored.push_back("face." + e.props[i].name);
    } else if (!is_vertex) {
      out.ignored.push_back(e.name);
    }
    values.resize(e.props.size());
    if (e.props.empty()) continue;  // items of nothing (a count of 2^64 - 1 would be a loop of as many steps)
    for (uint64_t item = 0; item < e.count; ++item) {
      for (size_t pi = 0; pi < e.props.size(); ++pi) {
        const PlyProperty& p = e.props[pi];
        if (!p.list) {
          values[pi] = body.read(p.type);
          continue;
        }
        double n = body.read(p.count_type);
        if (n < 0) body.fail("negative list length " + std::to_string(int64_t(n)));
        if (body.binary() && double(type_size(p.type)) * n > double(body.remaining()))
          body.fail("a list of " + std::to_string(uint64_t(n)) + " items runs past the end of the file (truncated)");
        uint32_t corner[3] = {0, 0, 0};
        for (uint64_t k = 0; k < uint64_t(n); ++k) {
          double v = body.read(p.type);
          if (!is_face || int(pi) != face_list) continue;
          if (!(v >= 0.0 && v < double(num_vertices)))
            body.fail("face vertex index " + std::to_string(int64_t(v)) + " out of range (the file has " +
                      std::to_string(num_vertices) + " vertices)");
          uint32_t idx = uint32_t(v);
          // Fan triangulation: (0, k-1, k) for k >= 2.
          if (k == 0) corner[0] = idx;
          corner[1] = corner[2];
          corner[2] = idx;
          if (k >= 2) out.mesh.triangles.push_back({corner[0], corner[1], corner[2]});
        }
        if (is_face && int(pi) == face_list && n < 3) ++short_faces;
      }
      body.end_ascii_item();
      if (is_vertex) {
        glm::vec3 p{float(values[size_t(role_of[kX])]), float(values[size_t(role_of[kY])]),
                    float(values[size_t(role_of[kZ])])};
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
          body.fail("vertex " + std::to_string(item) + " has a non-finite position");
        out.mesh.positions.push_back(p);
        if (role_of[kNx] >= 0)
          out.mesh.normals.emplace_back(float(values[size_t(role_of[kNx])]), float(values[size_t(role_of[kNy])]),
                                   float(values[size_t(role_of[kNz])]));
        if (role_of[kU] >= 0)
          out.mesh.uvs.emplace_back(float(values[size_t(role_of[kU])]), float(values[size_t(role_of[kV])]));
        if (role_of[kR] >= 0) {  // integers are unorm (uchar / 255, ushort / 65535, ...), floats as they are
          glm::vec3 c;
          for (int k = 0; k < 3; ++k) {
            const PlyProperty& prop = vertex_element->props[size_t(role_of[kR + k])];
            double scale = prop.type == PlyType::U8    ? 255.0
                           : prop.type == PlyType::I8  ? 127.0
                           : prop.type == PlyType::U16 ? 65535.0
                           : prop.type == PlyType::I16 ? 32767.0
                           : prop.type == PlyType::U32 ? 4294967295.0
                           : prop.type == PlyType::I32 ? 2147483647.0
                                                       : 1.0;
            c[k] = float(values[size_t(role_of[kR + k])] / scale);
          }
          out.mesh.colors.push_back(c);
        }
      }
    }
  }
  if (short_faces) out.ignored.push_back(std::to_string(short_faces) + " faces with fewer than 3 vertices");
  if (const size_t extra = body.trailing())
    out.ignored.push_back(std::to_string(extra) + (body.binary() ? " bytes" : " characters") +
                          " after the last element the header declares");
  return out;
}

Scene load_ply_scene(const std::string& path) {
  PlyMesh ply = read_ply(path);
  Scene scene;
  if (ply.mesh.normals.empty()) compute_vertex_normals(ply.mesh);
  if (!ply.ignored.empty()) {
    std::string list;
    for (const std::string& name : ply.ignored) list += (list.empty() ? "" : ", ") + name;
    scene.warnings.push_back(path + ": PLY data not used: " + list);
  }
  Material m{};
  // Vertex colours are the diffuse colour; without them a grey of 0.5.
  const float grey = ply.mesh.colors.empty() ? 0.5f : 1.0f;
  m.albedo = {{grey, grey, grey, 0}};
  m.type = PSF_MATERIAL_DIFFUSE;
  if (!ply.mesh.colors.empty()) m.flags |= PSF_MATFLAG_VERTEX_COLOR;
  m.two_sided = 1;
  scene.materials.push_back(m);
  scene.material_names.push_back("default");
  append_mesh(scene, ply.mesh, glm::mat4(1.0f), 0, false, path, 0);
  scene.camera = camera_framing(scene.positions);
  scene.width = 512;
  scene.height = 512;
  return scene;
}

}  // namespace psf::detail
