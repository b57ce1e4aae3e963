// Mitsuba XML scenes (versions 0.5, 2 and 3) loaded into psf::Scene.
//
// Two passes over the top-level elements of <scene>, with <include>d files
// spliced in place:
//   1. <default> values fill in the `$name` parameters not given by the caller,
//      and every element with an id is indexed (a <ref> may point forward, as in
//      Mitsuba 3's own cbox scene);
//   2. integrator, sensor, shapes and top-level BSDFs are instantiated in
//      document order; BSDFs and emitters are built on first use and memoised.
// Plugins are looked up by type name in small tables (shape_plugins(),
// bsdf_plugins(), emitter_plugins()); a BSDF or emitter type without an exact
// counterpart is approximated (a diffuse reflectance, or ignored) and reported
// once per element in Scene::warnings as "file:line: ...".
//
// Property names are compared in snake_case, so Mitsuba 0.5's camelCase names
// (toWorld, fovAxis, maxDepth, sampleCount, ...) are the same properties as
// Mitsuba 3's (to_world, fov_axis, max_depth, sample_count, ...).
#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <glm/gtc/matrix_transform.hpp>
#include <limits>
#include <map>
#include <tuple>
#include <memory>
#include <optional>
#include <pugixml.hpp>
#include <set>
#include <sstream>
#include <string_view>
#include <unordered_map>

#include "scene/formats.h"
#include "scene/loaders.h"
#include "scene/materials.h"

namespace fs = std::filesystem;

namespace psf::detail {

// ---------------------------------------------------------------------------
// Colour: spectra to linear sRGB
// ---------------------------------------------------------------------------
namespace {

// One lobe of the piecewise Gaussian fit: exp(-((x - mu) / sigma)^2 / 2) with
// sigma = s1 left of mu and s2 right of it.
double lobe(double x, double mu, double s1, double s2) {
  double t = (x - mu) / (x < mu ? s1 : s2);
  return std::exp(-0.5 * t * t);
}

// CIE 1931 2-degree colour-matching functions, the multi-lobe fit of Wyman,
// Sloan and Shirley, "Simple Analytic Approximations to the CIE XYZ Color
// Matching Functions", JCGT 2(2), 2013, equations 2-4.
glm::dvec3 cie_xyz(double nm) {
  return {
      1.056 * lobe(nm, 599.8, 37.9, 31.0) + 0.362 * lobe(nm, 442.0, 16.0, 26.7) - 0.065 * lobe(nm, 501.1, 20.4, 26.2),
      0.821 * lobe(nm, 568.8, 46.9, 40.5) + 0.286 * lobe(nm, 530.9, 16.3, 31.1),
      1.217 * lobe(nm, 437.0, 11.8, 36.0) + 0.681 * lobe(nm, 459.0, 26.0, 13.8)};
}

constexpr double kCieMin = 360.0;  // integration range in nm, as Mitsuba's MI_CIE_MIN ...
constexpr double kCieMax = 830.0;  // ... and MI_CIE_MAX
constexpr int kCieSteps = 471;     // 1 nm steps from kCieMin to kCieMax inclusive

// CIE standard illuminant D65, relative spectral power at 5 nm steps from 360 to
// 830 nm (CIE 15:2004, table T.1).
constexpr std::array<double, 95> kD65 = {
    46.6383, 49.3637, 52.0891, 51.0323, 49.9755, 52.3118, 54.6482, 68.7015, 82.7549, 87.1204, 91.486,  92.4589,
    93.4318, 90.057,  86.6823, 95.7736, 104.865, 110.936, 117.008, 117.41,  117.812, 116.336, 114.861, 115.392,
    115.923, 112.367, 108.811, 109.082, 109.354, 108.578, 107.802, 106.296, 104.79,  106.239, 107.689, 106.047,
    104.405, 104.225, 104.046, 102.023, 100.0,   98.1671, 96.3342, 96.0611, 95.788,  92.2368, 88.6856, 89.3459,
    90.0062, 89.8026, 89.5991, 88.6489, 87.6987, 85.4936, 83.2886, 83.4939, 83.6992, 81.863,  80.0268, 80.1207,
    80.2146, 81.2462, 82.2778, 80.281,  78.2842, 74.0027, 69.7213, 70.6652, 71.6091, 72.979,  74.349,  67.9765,
    61.604,  65.7448, 69.8856, 72.4863, 75.087,  69.3398, 63.5927, 55.0054, 46.4182, 56.6118, 66.8054, 65.0941,
    63.3828, 63.8434, 64.304,  61.8779, 59.4519, 55.7054, 51.959,  54.6998, 57.4406, 58.8765, 60.3125};

double d65(double nm) {
  double t = std::clamp((nm - kCieMin) / 5.0, 0.0, double(kD65.size() - 1));
  size_t i = std::min(size_t(t), kD65.size() - 2);
  double f = t - double(i);
  return (1 - f) * kD65[i] + f * kD65[i + 1];
}

// XYZ to linear sRGB (ITU-R BT.709 primaries, D65 white), the matrix Mitsuba uses.
glm::dvec3 xyz_to_srgb(const glm::dvec3& c) {
  return {3.240479 * c.x - 1.537150 * c.y - 0.498535 * c.z, -0.969256 * c.x + 1.875991 * c.y + 0.041556 * c.z,
          0.055648 * c.x - 0.204043 * c.y + 1.057311 * c.z};
}

// Integration constants of the fitted curves over the 1 nm grid.
struct CieIntegrals {
  glm::dvec3 flat;       // sum of xyz(l): the equal-energy white, unnormalised
  glm::dvec3 d65_white;  // linear sRGB of sum(xyz(l) d65(l)) / sum(y(l) d65(l)), ideally (1,1,1)
  double d65_y = 0;      // sum of y(l) d65(l)
};

const CieIntegrals& cie_integrals() {
  static const CieIntegrals integrals = [] {
    CieIntegrals c;
    glm::dvec3 d65_xyz(0.0);
    c.flat = glm::dvec3(0.0);
    for (int i = 0; i < kCieSteps; ++i) {
      double nm = kCieMin + i;
      c.flat += cie_xyz(nm);
      d65_xyz += cie_xyz(nm) * d65(nm);
    }
    c.d65_y = d65_xyz.y;
    c.d65_white = xyz_to_srgb(d65_xyz / d65_xyz.y);
    return c;
  }();
  return integrals;
}

}  // namespace

glm::vec3 spectrum_to_rgb(const std::vector<double>& wavelengths, const std::vector<double>& values, bool emitter) {
  const CieIntegrals& cie = cie_integrals();
  glm::dvec3 xyz(0.0);
  size_t k = 0;
  for (int i = 0; i < kCieSteps; ++i) {
    double nm = kCieMin + i;
    if (wavelengths.empty() || nm < wavelengths.front() || nm > wavelengths.back()) continue;
    while (k + 2 < wavelengths.size() && wavelengths[k + 1] < nm) ++k;
    double w0 = wavelengths[k], w1 = wavelengths[std::min(k + 1, wavelengths.size() - 1)];
    double f = w1 > w0 ? (nm - w0) / (w1 - w0) : 0.0;
    double v = (1 - f) * values[k] + f * values[std::min(k + 1, values.size() - 1)];
    xyz += cie_xyz(nm) * v * (emitter ? 1.0 : d65(nm));
  }
  glm::dvec3 rgb;
  if (emitter) {
    // Luminance 1 for a unit spectrum; each fitted curve rescaled to the same
    // integral, as the tabulated CIE curves have (equal-energy white x = y = 1/3).
    xyz *= glm::dvec3(1.0) / cie.flat;
    rgb = xyz_to_srgb(xyz);
  } else {
    // Under D65 with luminance 1 for the perfect reflector; dividing by its sRGB
    // removes the residual white-point error of the fitted curves.
    rgb = xyz_to_srgb(xyz / cie.d65_y) / cie.d65_white;
  }
  return glm::vec3(glm::max(rgb, glm::dvec3(0.0)));
}

float srgb_to_linear(float c) { return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f); }

// ---------------------------------------------------------------------------
// The loader
// ---------------------------------------------------------------------------
namespace {

// Paths named in a scene, asked without throwing: a name the system refuses
// (too long, a loop of symbolic links) is an error of the scene's, with its
// file:line, not a std::filesystem exception.
bool is_file(const std::string& path) {
  std::error_code ec;
  return fs::is_regular_file(path, ec);
}

// ": <unreadable_input's reason>" (a folder, a device, a name the system
// refuses), else "" (a missing file: the message says enough).
std::string why_unopenable(const std::string& path) {
  const std::string why = unreadable_input(path);
  return why.empty() ? why : ": " + why;
}

// The path made absolute and free of . and .., for include cycles; the path
// itself where the system cannot resolve it.
std::string canonical_name(const std::string& path) {
  std::error_code ec;
  fs::path p = fs::weakly_canonical(path, ec);
  return ec ? path : p.string();
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

// A decimal number spanning all of `s` (blanks around it allowed), finite as a
// float too (scenes are rendered in single precision: 1e39 would be infinite).
std::optional<double> parse_number(std::string_view s) {
  std::string t(trim(s));
  if (t.empty()) return std::nullopt;
  char* end = nullptr;
  double v = std::strtod(t.c_str(), &end);
  if (end != t.c_str() + t.size() || !std::isfinite(v) || !std::isfinite(float(v))) return std::nullopt;
  return v;
}

// Splits at blanks and commas: "1 2 3", "1, 2, 3" and "1,2,3" give three tokens.
std::vector<std::string> split_list(std::string_view s) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : s) {
    if (c == ',' || std::isspace(static_cast<unsigned char>(c))) {
      if (!cur.empty()) out.push_back(std::move(cur));
      cur.clear();
    } else {
      cur += c;
    }
  }
  if (!cur.empty()) out.push_back(std::move(cur));
  return out;
}

// camelCase to snake_case: toWorld -> to_world, intIOR -> int_ior; snake_case is unchanged.
std::string to_snake(std::string_view name) {
  std::string out;
  for (size_t i = 0; i < name.size(); ++i) {
    char c = name[i];
    bool upper = std::isupper(static_cast<unsigned char>(c));
    if (upper && i > 0 &&
        (std::islower(static_cast<unsigned char>(name[i - 1])) ||
         std::isdigit(static_cast<unsigned char>(name[i - 1]))))
      out += '_';
    out += char(std::tolower(static_cast<unsigned char>(c)));
  }
  return out;
}

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string fmt(const glm::vec3& v) {
  std::ostringstream s;
  s.precision(3);
  s << "(" << v.x << ", " << v.y << ", " << v.z << ")";
  return s.str();
}

std::string fmt(float v) {
  std::ostringstream s;
  s.precision(4);
  s << v;
  return s.str();
}

// One XML file of the scene (the main file or an <include>d one).
struct XmlFile {
  std::string path;                 // path as opened
  std::vector<size_t> line_starts;  // byte offset of the first character of each line
  pugi::xml_document doc;           // the parsed document

  // 1-based line of a byte offset (pugixml's offset_debug), 0 if unknown.
  int line_of(ptrdiff_t offset) const {
    if (offset < 0) return 0;
    return int(std::upper_bound(line_starts.begin(), line_starts.end(), size_t(offset)) - line_starts.begin());
  }
};

// A property element (<float>, <rgb>, <spectrum>, <transform>, <ref name=...>, ...), parsed.
struct Property {
  enum class Kind { Number, Integer, Boolean, String, Color, Spectrum, Vector, Transform, Object };
  Kind kind = Kind::Number;         // which field below holds the value
  pugi::xml_node node;              // the element, for error locations
  double number = 0;                // Number and Integer
  bool boolean = false;             // Boolean
  std::string text;                 // String
  glm::vec3 vec{0.0f};              // Color (linear RGB) and Vector (<point>, <vector>)
  std::vector<double> wavelengths;  // Spectrum: sample wavelengths in nm, empty if uniform
  std::vector<double> values;       // Spectrum: sample values, one if uniform
  glm::mat4 matrix{1.0f};           // Transform
  pugi::xml_node object;            // Object: the nested or referenced plugin element
};

// A plugin element (<shape>, <bsdf>, <sensor>, ...) with its properties parsed.
struct Element {
  pugi::xml_node node;                    // the element
  std::string type;                       // its type attribute
  std::map<std::string, Property> props;  // properties by snake_case name
  std::vector<pugi::xml_node> objects;    // nested and referenced plugin elements, in document order
};

// How a colour-valued property is converted (Mitsuba's texture intents).
enum class ColorUse {
  Reflectance,  // spectra under D65, clamped to [0, 1]
  Radiance,     // emitted spectra, >= 0, a uniform spectrum is equal-energy white
  Unbounded     // spectra under D65, >= 0 (indices of refraction)
};

// A diffuse material of reflectance `albedo` (Mitsuba's default BSDF: 0.5).
Material diffuse_material(const glm::vec3& albedo) {
  Material m{};
  m.type = PSF_MATERIAL_DIFFUSE;
  m.albedo = {{albedo.x, albedo.y, albedo.z, 0}};
  return m;
}

// A BSDF as the renderer represents it.
struct Bsdf {
  Material m = diffuse_material(glm::vec3(0.5f));  // type, parameters, textures (emission zero)
  bool two_sided = false;                          // scatters on both sides (Mitsuba's twosided)
  std::string name;                                // the element's id, else its type
  // blendbsdf: the BSDF that scatters instead with probability m.blend_weight
  // (times m.tex_blend); the material gets it as Material.blend.
  std::shared_ptr<const Bsdf> blend;
  // A colour of it (or of a BSDF inside) is the mesh's vertex colour (Mitsuba 3's
  // mesh_attribute "vertex_color"): the colour term is 1, times the vertex colours.
  bool vertex_color = false;
  bool null = false;  // Mitsuba's null BSDF: rays pass through (a mask of opacity 0)
};

// Element tags that hold a plugin (a nested object) rather than a property value.
const std::set<std::string>& plugin_tags() {
  static const std::set<std::string> tags = {"bsdf",  "emitter", "shape",      "texture", "sensor",
                                             "film",  "sampler", "integrator", "rfilter", "medium",
                                             "phase", "volume",  "subsurface"};
  return tags;
}

// Element tags that hold a property value.
const std::set<std::string>& property_tags() {
  static const std::set<std::string> tags = {"float",    "integer",   "boolean", "string", "rgb",      "srgb",
                                             "spectrum", "blackbody", "point",   "vector", "transform"};
  return tags;
}

class MitsubaLoader {
 public:
  explicit MitsubaLoader(const std::vector<std::pair<std::string, std::string>>& params) {
    for (const auto& [name, value] : params) params_[name] = value;
  }

  Scene load(const std::string& path) {
    scene_.camera.pixel_filter = "gaussian";  // Mitsuba's film's default rfilter, stddev 0.5
    XmlFile& main = open(path, pugi::xml_node());
    pugi::xml_node root = main.doc.document_element();
    std::string version = attr(root, "version").value_or("3.0.0");
    version_major_ = std::atoi(version.c_str());

    std::vector<pugi::xml_node> top;
    std::vector<std::string> include_stack = {canonical_name(path)};
    collect(root, top, include_stack);
    for (pugi::xml_node node : top) index_ids(node);
    resolve_aliases();
    // Media are rendered only by a volumetric integrator, as in Mitsuba, whose
    // path tracer (also its default integrator) leaves them out: the first
    // <integrator>'s type, or the type nested in a wrapper such as aov.
    for (pugi::xml_node node : top)
      if (std::string(node.name()) == "integrator") {
        pugi::xml_node n = node;
        static const std::set<std::string> volumetric = {"volpath", "volpathmis", "volpath_simple", "prbvolpath"};
        for (int depth = 0; n && depth < 8; ++depth) {
          integrator_type_ = attr(n, "type").value_or("");
          if (volumetric.count(integrator_type_)) break;
          n = n.child("integrator");
        }
        media_rendered_ = volumetric.count(integrator_type_) > 0;
        break;
      }

    using Handler = void (MitsubaLoader::*)(pugi::xml_node);
    static const std::map<std::string, Handler> handlers = {
        {"integrator", &MitsubaLoader::load_integrator}, {"sensor", &MitsubaLoader::load_sensor},
        {"shape", &MitsubaLoader::load_shape},           {"bsdf", &MitsubaLoader::load_top_bsdf},
        {"emitter", &MitsubaLoader::load_top_emitter},   {"texture", &MitsubaLoader::skip},
        {"alias", &MitsubaLoader::skip},         {"medium", &MitsubaLoader::skip},  // used where a shape refers to it
    };
    // The shapes the scene will draw, counted first (merge_shapes): merges or
    // instances that each hold the next twice would draw 2^depth copies (a
    // 1 KB file, 2^40 spheres), and a million shapes take a minute to load.
    size_t shapes = 0;
    for (pugi::xml_node node : top)
      if (std::string(node.name()) == "shape" && (shapes += shapes_drawn_by(node)) > kMaxShapes)
        fail(node, "the scene draws more than " + std::to_string(kMaxShapes) +
                       " shapes (merges or instances that hold each other more than once?)");
    for (pugi::xml_node node : top) {
      auto it = handlers.find(node.name());
      if (it != handlers.end()) {
        (this->*it->second)(node);
      } else if (plugin_tags().count(node.name())) {
        warn(node, node.name(), std::string("<") + node.name() + "> is not supported yet; ignored");
      } else {
        fail(node, std::string("unexpected element <") + node.name() + "> in <scene>");
      }
    }

    if (camera_medium_) scene_.camera_medium = medium_material(camera_medium_->object);
    if (!has_sensor_) {
      scene_.camera = camera_framing(scene_.positions);
      scene_.camera.pixel_filter = "gaussian";
      scene_.warnings.push_back(main.path + ": no <sensor>; using a camera framing the scene");
    }
    return std::move(scene_);
  }

 private:
  // --- files, locations, messages -----------------------------------------

  XmlFile& open(const std::string& path, pugi::xml_node from) {
    std::error_code ec;
    if (fs::is_directory(path, ec)) {
      if (from) fail(from, "included file '" + path + "' is a folder");
      throw SceneError(path, 0, "is a folder, not a scene file");
    }
    if (const std::string why = unreadable_input(path); !why.empty()) {
      if (from) fail(from, "included file '" + path + "' " + why);
      throw SceneError(path, 0, why);
    }
    // Includes that each include the next twice would open 2^depth files.
    if (++files_opened_ > kMaxFiles)
      fail(from, "more than " + std::to_string(kMaxFiles) + " included files (includes that repeat each other?)");
    std::ifstream in(path, std::ios::binary);
    if (!in) {
      if (from) fail(from, "cannot open included file '" + path + "'");
      throw SceneError(path, 0, "cannot open file");
    }
    std::string text = read_all(in);
    auto file = std::make_unique<XmlFile>();
    file->path = path;
    file->line_starts.push_back(0);
    for (size_t i = 0; i < text.size(); ++i)
      if (text[i] == '\n') file->line_starts.push_back(i + 1);
    pugi::xml_parse_result result =
        file->doc.load_buffer(text.data(), text.size(), pugi::parse_default, pugi::encoding_utf8);
    if (!result)
      throw SceneError(path, file->line_of(result.offset), std::string("malformed XML: ") + result.description());
    pugi::xml_node root = file->doc.document_element();
    if (std::string(root.name()) != "scene")
      throw SceneError(path, file->line_of(root.offset_debug()),
                       std::string("the root element is <") + root.name() + ">, expected <scene>");
    // The loader walks elements recursively: refuse a depth no scene needs (a
    // scene nests a handful of levels) before that could exhaust the stack.
    constexpr int kMaxDepth = 256;
    std::vector<std::pair<pugi::xml_node, int>> stack = {{root, 1}};
    while (!stack.empty()) {
      auto [node, depth] = stack.back();
      stack.pop_back();
      if (depth > kMaxDepth)
        throw SceneError(path, file->line_of(node.offset_debug()),
                         "elements nested deeper than " + std::to_string(kMaxDepth) + " levels");
      for (pugi::xml_node child : node.children())
        if (child.type() == pugi::node_element) stack.emplace_back(child, depth + 1);
    }
    roots_[file->doc.internal_object()] = file.get();
    files_.push_back(std::move(file));
    return *files_.back();
  }

  const XmlFile& file_of(pugi::xml_node node) const { return *roots_.at(node.root().internal_object()); }

  int line_of(pugi::xml_node node) const { return file_of(node).line_of(node.offset_debug()); }

  std::string where(pugi::xml_node node) const { return file_of(node).path + ":" + std::to_string(line_of(node)); }

  [[noreturn]] void fail(pugi::xml_node node, const std::string& message) const {
    throw SceneError(file_of(node).path, line_of(node), message);
  }

  // Records "file:line: message" once per element and plugin type.
  void warn(pugi::xml_node node, const std::string& plugin, const std::string& message) {
    std::string at = where(node);
    if (warned_.insert(at + " " + plugin).second) scene_.warnings.push_back(at + ": " + message);
  }

  // The directory of the file holding `node`, for relative paths.
  fs::path directory_of(pugi::xml_node node) const { return fs::path(file_of(node).path).parent_path(); }

  // A path named in the file holding `node`: relative to that file, else to the main file.
  std::string resolve(pugi::xml_node node, const std::string& name) const {
    fs::path p(name);
    if (p.is_absolute()) return p.string();
    fs::path local = directory_of(node) / p;
    // Paths the system refuses (a name too long, a loop of links) count as
    // absent here; opening them then fails with file:line.
    std::error_code ec;
    if (fs::exists(local, ec)) return local.string();
    fs::path main = fs::path(files_.front()->path).parent_path() / p;
    return fs::exists(main, ec) ? main.string() : local.string();
  }

  // --- attributes and $parameters -----------------------------------------

  // The attribute's value with `$name` parameters substituted, if present.
  std::optional<std::string> attr(pugi::xml_node node, const char* name) const {
    pugi::xml_attribute a = node.attribute(name);
    if (!a) return std::nullopt;
    return substitute(node, a.value());
  }

  std::string required_attr(pugi::xml_node node, const char* name) const {
    std::optional<std::string> v = attr(node, name);
    if (!v) fail(node, std::string("<") + node.name() + "> needs the attribute '" + name + "'");
    return *v;
  }

  std::string substitute(pugi::xml_node node, std::string_view raw) const {
    std::string out;
    for (size_t i = 0; i < raw.size(); ++i) {
      size_t j = i + 1;
      while (j < raw.size() && (std::isalnum(static_cast<unsigned char>(raw[j])) || raw[j] == '_')) ++j;
      if (raw[i] != '$' || j == i + 1) {
        out += raw[i];
        continue;
      }
      std::string name(raw.substr(i + 1, j - i - 1));
      auto it = params_.find(name);
      if (it == params_.end())
        fail(node, "undefined parameter '$" + name + "' (pass " + name + "=value or add a <default>)");
      out += it->second;
      i = j - 1;
    }
    return out;
  }

  double number_attr(pugi::xml_node node, const char* name, double fallback) const {
    std::optional<std::string> v = attr(node, name);
    if (!v) return fallback;
    std::optional<double> x = parse_number(*v);
    if (!x)
      fail(node, std::string("attribute '") + name + "': '" + *v + "' is not a number (finite in single precision)");
    return *x;
  }

  double required_number(pugi::xml_node node, const char* name) const {
    required_attr(node, name);
    return number_attr(node, name, 0.0);
  }

  // Exactly `counts` numbers (any of them) in the attribute, separated by blanks or commas.
  std::vector<double> number_list(pugi::xml_node node, const char* name, std::initializer_list<size_t> counts) const {
    std::string v = required_attr(node, name);
    std::vector<double> out;
    for (const std::string& token : split_list(v)) {
      std::optional<double> x = parse_number(token);
      if (!x)
        fail(node,
             std::string("attribute '") + name + "': '" + token + "' is not a number (finite in single precision)");
      out.push_back(*x);
    }
    if (std::find(counts.begin(), counts.end(), out.size()) == counts.end()) {
      std::string expected;
      for (size_t c : counts) expected += (expected.empty() ? "" : " or ") + std::to_string(c);
      fail(node, std::string("attribute '") + name + "' has " + std::to_string(out.size()) + " numbers, expected " +
                     expected);
    }
    return out;
  }

  // <point>/<vector>/<translate>-style xyz: a `value` list or x, y, z attributes.
  glm::vec3 xyz_attrs(pugi::xml_node node, float fallback) const {
    if (node.attribute("value")) {
      std::vector<double> v = number_list(node, "value", {1, 3});
      return v.size() == 1 ? glm::vec3(float(v[0])) : glm::vec3(float(v[0]), float(v[1]), float(v[2]));
    }
    return {float(number_attr(node, "x", fallback)), float(number_attr(node, "y", fallback)),
            float(number_attr(node, "z", fallback))};
  }

  glm::vec3 vec_attr(pugi::xml_node node, const char* name) const {
    std::vector<double> v = number_list(node, name, {3});
    return {float(v[0]), float(v[1]), float(v[2])};
  }

  // --- pass 1: defaults, includes, ids ------------------------------------

  void collect(pugi::xml_node scene, std::vector<pugi::xml_node>& top, std::vector<std::string>& include_stack) {
    for (pugi::xml_node child : scene.children()) {
      if (child.type() != pugi::node_element) continue;
      std::string tag = child.name();
      if (tag == "default") {
        std::string name = required_attr(child, "name");
        params_.emplace(name, required_attr(child, "value"));
      } else if (tag == "include") {
        std::string path = resolve(child, required_attr(child, "filename"));
        std::string canonical = canonical_name(path);
        if (std::find(include_stack.begin(), include_stack.end(), canonical) != include_stack.end())
          fail(child, "'" + path + "' includes itself");
        XmlFile& file = open(path, child);
        include_stack.push_back(canonical);
        collect(file.doc.document_element(), top, include_stack);
        include_stack.pop_back();
      } else {
        top.push_back(child);
      }
    }
  }

  void index_ids(pugi::xml_node node) {
    if (std::string(node.name()) == "alias") {  // resolved once every id is known (resolve_aliases)
      aliases_.push_back(node);
      return;
    }
    if (node.attribute("id") && std::string(node.name()) != "ref") {
      std::string id = required_attr(node, "id");
      auto [it, inserted] = ids_.emplace(id, node);
      if (!inserted) fail(node, "duplicate id '" + id + "' (first defined at " + where(it->second) + ")");
    }
    for (pugi::xml_node child : node.children())
      if (child.type() == pugi::node_element) index_ids(child);
  }

  // <alias id="a" as="b"/>: b names the element a names.
  void resolve_aliases() {
    for (pugi::xml_node node : aliases_) {
      std::string id = required_attr(node, "id"), as = required_attr(node, "as");
      auto target = ids_.find(id);
      if (target == ids_.end()) fail(node, "alias of unknown id '" + id + "'");
      auto [it, inserted] = ids_.emplace(as, target->second);
      if (!inserted) fail(node, "duplicate id '" + as + "' (first defined at " + where(it->second) + ")");
    }
  }

  pugi::xml_node resolve_ref(pugi::xml_node ref) const {
    std::string id = required_attr(ref, "id");
    auto it = ids_.find(id);
    if (it == ids_.end()) fail(ref, "reference to unknown id '" + id + "'");
    return it->second;
  }

  // --- elements and properties --------------------------------------------

  Element parse_element(pugi::xml_node node) const {
    Element e;
    e.node = node;
    e.type = attr(node, "type").value_or("");
    for (pugi::xml_node child : node.children()) {
      if (child.type() != pugi::node_element) continue;
      std::string tag = child.name();
      std::optional<std::string> name = attr(child, "name");
      Property p;
      p.node = child;
      if (tag == "ref" || plugin_tags().count(tag) || (tag == "spectrum" && child.attribute("type"))) {
        p.kind = Property::Kind::Object;
        p.object = tag == "ref" ? resolve_ref(child) : child;
        e.objects.push_back(p.object);
        if (!name) continue;
      } else if (property_tags().count(tag)) {
        if (!name) fail(child, "<" + tag + "> needs the attribute 'name'");
        p = parse_property(child);
      } else {
        fail(child, "unexpected element <" + tag + "> in <" + node.name() + ">");
      }
      auto [it, inserted] = e.props.emplace(to_snake(*name), p);
      if (!inserted) fail(child, "property '" + *name + "' is given twice (also at " + where(it->second.node) + ")");
    }
    return e;
  }

  Property parse_property(pugi::xml_node node) const {
    Property p;
    p.node = node;
    std::string tag = node.name();
    if (tag == "float") {
      p.kind = Property::Kind::Number;
      p.number = required_number(node, "value");
    } else if (tag == "integer") {
      p.kind = Property::Kind::Integer;
      std::string v(trim(required_attr(node, "value")));
      char* end = nullptr;
      errno = 0;
      long long x = std::strtoll(v.c_str(), &end, 10);
      if (v.empty() || end != v.c_str() + v.size()) fail(node, "'" + v + "' is not an integer");
      if (errno == ERANGE || x < std::numeric_limits<int>::min() || x > std::numeric_limits<int>::max())
        fail(node, "'" + v + "' is out of the range of an integer");
      p.number = double(x);
    } else if (tag == "boolean") {
      p.kind = Property::Kind::Boolean;
      std::string v = lower(std::string(trim(required_attr(node, "value"))));
      if (v != "true" && v != "false") fail(node, "'" + v + "' is not a boolean (true or false)");
      p.boolean = v == "true";
    } else if (tag == "string") {
      p.kind = Property::Kind::String;
      p.text = required_attr(node, "value");
    } else if (tag == "rgb") {
      p.kind = Property::Kind::Color;
      std::vector<double> v = number_list(node, "value", {1, 3});
      p.vec = v.size() == 1 ? glm::vec3(float(v[0])) : glm::vec3(float(v[0]), float(v[1]), float(v[2]));
    } else if (tag == "srgb") {
      p.kind = Property::Kind::Color;
      p.vec = parse_srgb(node);
    } else if (tag == "spectrum") {
      p.kind = Property::Kind::Spectrum;
      parse_spectrum(node, p);
    } else if (tag == "blackbody") {
      p.kind = Property::Kind::Spectrum;
      parse_blackbody(node, p);
    } else if (tag == "point" || tag == "vector") {
      p.kind = Property::Kind::Vector;
      p.vec = xyz_attrs(node, 0.0f);
    } else if (tag == "transform") {
      p.kind = Property::Kind::Transform;
      p.matrix = parse_transform(node);
    }
    return p;
  }

  glm::vec3 parse_srgb(pugi::xml_node node) const {
    std::string v(trim(required_attr(node, "value")));
    glm::vec3 encoded;
    if (!v.empty() && v[0] == '#') {
      bool hex = v.size() == 7 && std::all_of(v.begin() + 1, v.end(), [](char c) { return std::isxdigit(c); });
      if (!hex) fail(node, "'" + v + "' is not an sRGB colour (#rrggbb)");
      for (int i = 0; i < 3; ++i) encoded[i] = float(std::stoi(v.substr(1 + 2 * i, 2), nullptr, 16)) / 255.0f;
    } else {
      std::vector<double> x = number_list(node, "value", {1, 3});
      encoded = x.size() == 1 ? glm::vec3(float(x[0])) : glm::vec3(float(x[0]), float(x[1]), float(x[2]));
    }
    return {srgb_to_linear(encoded.r), srgb_to_linear(encoded.g), srgb_to_linear(encoded.b)};
  }

  // <spectrum value="0.5"/>, <spectrum value="400:0.1, 500:0.2"/> or <spectrum filename="x.spd"/>
  // (lines of "wavelength value", '#' comments).
  void parse_spectrum(pugi::xml_node node, Property& p) const {
    std::vector<std::string> tokens;
    if (std::optional<std::string> file = attr(node, "filename")) {
      std::string path = resolve(node, *file);
      if (const std::string why = unreadable_input(path); !why.empty())
        fail(node, "spectrum file '" + path + "' " + why);
      std::ifstream in(path);
      if (!in) fail(node, "cannot open spectrum file '" + path + "'");
      for (std::string line; std::getline(in, line);) {
        line = line.substr(0, line.find('#'));
        std::vector<std::string> pair = split_list(line);
        if (pair.empty()) continue;
        if (pair.size() != 2) fail(node, "spectrum file '" + path + "': expected 'wavelength value' in: " + line);
        tokens.push_back(pair[0] + ":" + pair[1]);
      }
    } else {
      tokens = split_list(required_attr(node, "value"));
    }
    if (tokens.size() == 1 && tokens[0].find(':') == std::string::npos) {
      std::optional<double> x = parse_number(tokens[0]);
      if (!x) fail(node, "'" + tokens[0] + "' is not a number");
      p.values = {*x};
      return;
    }
    for (const std::string& token : tokens) {
      size_t colon = token.find(':');
      std::optional<double> w, v;
      if (colon != std::string::npos) {
        w = parse_number(std::string_view(token).substr(0, colon));
        v = parse_number(std::string_view(token).substr(colon + 1));
      }
      if (!w || !v) fail(node, "'" + token + "' is not a wavelength:value pair");
      if (!p.wavelengths.empty() && *w <= p.wavelengths.back())
        fail(node, "spectrum wavelengths must increase ('" + token + "')");
      p.wavelengths.push_back(*w);
      p.values.push_back(*v);
    }
    if (p.wavelengths.size() < 2) fail(node, "a sampled spectrum needs at least two wavelength:value pairs");
  }

  // Mitsuba 0.5's <blackbody temperature="5000K" scale="1"/>: Planck's law in W/(m^2 sr nm).
  void parse_blackbody(pugi::xml_node node, Property& p) const {
    std::string t(trim(required_attr(node, "temperature")));
    if (!t.empty() && (t.back() == 'k' || t.back() == 'K')) t.pop_back();
    std::optional<double> kelvin = parse_number(t);
    if (!kelvin || *kelvin <= 0) fail(node, "'" + t + "' is not a temperature in kelvin");
    double scale = number_attr(node, "scale", 1.0);
    const double h = 6.62607015e-34, c = 2.99792458e8, kb = 1.380649e-23;
    for (double nm = kCieMin; nm <= kCieMax; nm += 5.0) {
      double l = nm * 1e-9;
      double radiance = 2 * h * c * c / std::pow(l, 5) / (std::exp(h * c / (l * kb * *kelvin)) - 1);
      p.wavelengths.push_back(nm);
      p.values.push_back(radiance * 1e-9 * scale);
    }
  }

  // <transform>: each child left-multiplies the matrix so far, as in Mitsuba.
  glm::mat4 parse_transform(pugi::xml_node node) const {
    glm::mat4 m(1.0f);
    for (pugi::xml_node c : node.children()) {
      if (c.type() != pugi::node_element) continue;
      std::string tag = lower(c.name());
      glm::mat4 step(1.0f);
      if (tag == "translate") {
        step = glm::translate(glm::mat4(1.0f), xyz_attrs(c, 0.0f));
      } else if (tag == "scale") {
        step = glm::scale(glm::mat4(1.0f), xyz_attrs(c, 1.0f));
      } else if (tag == "rotate") {
        glm::vec3 axis = xyz_attrs(c, 0.0f);
        if (glm::length(axis) == 0.0f) fail(c, "<rotate> needs a non-zero axis (x, y, z or value)");
        float angle = float(required_number(c, "angle"));
        step = glm::rotate(glm::mat4(1.0f), glm::radians(angle), glm::normalize(axis));
      } else if (tag == "matrix") {
        std::vector<double> v = number_list(c, "value", {9, 16});
        size_t n = v.size() == 9 ? 3 : 4;
        for (size_t row = 0; row < n; ++row)
          for (size_t col = 0; col < n; ++col) step[int(col)][int(row)] = float(v[row * n + col]);
      } else if (tag == "lookat") {
        step = look_at(c);
      } else {
        fail(c, "unexpected element <" + std::string(c.name()) + "> in <transform>");
      }
      m = step * m;
    }
    return m;
  }

  // The first vector of Mitsuba 3's coordinate_system(n) (Duff et al., "Building an
  // Orthonormal Basis, Revisited", JCGT 2017), n a unit vector.
  static glm::vec3 default_up_mitsuba3(glm::vec3 n) {
    const float sign = std::signbit(n.z) ? -1.0f : 1.0f;
    const float a = -1.0f / (sign + n.z), b = n.x * n.y * a;
    return glm::vec3(sign * (n.x * n.x * a) + 1.0f, sign * b, -sign * n.x);
  }
  // The second vector b of Mitsuba 0.5's coordinateSystem(a, b, c), a a unit vector.
  static glm::vec3 default_up_mitsuba05(glm::vec3 a) {
    glm::vec3 c;
    if (std::abs(a.x) > std::abs(a.y))
      c = glm::vec3(a.z, 0.0f, -a.x) / std::sqrt(a.x * a.x + a.z * a.z);
    else
      c = glm::vec3(0.0f, a.z, -a.y) / std::sqrt(a.y * a.y + a.z * a.z);
    return glm::cross(c, a);
  }

  // Mitsuba's look_at: columns left = up x dir, up' = dir x left, dir, origin.
  // Without an up (or a zero one) both Mitsubas complete dir to a basis and take
  // its first vector: Mitsuba 3 by Duff et al.'s construction (coordinate_system),
  // Mitsuba 0.5 by its older coordinateSystem.
  glm::mat4 look_at(pugi::xml_node c) const {
    glm::vec3 origin = vec_attr(c, "origin"), target = vec_attr(c, "target");
    glm::vec3 dir = target - origin;
    if (glm::length(dir) == 0.0f) fail(c, "<lookat> origin and target coincide");
    dir = glm::normalize(dir);
    glm::vec3 up = c.attribute("up") ? vec_attr(c, "up") : glm::vec3(0.0f);
    if (glm::dot(up, up) == 0.0f) up = version_major_ >= 2 ? default_up_mitsuba3(dir) : default_up_mitsuba05(dir);
    glm::vec3 left = glm::cross(up, dir);
    if (glm::length(left) < 1e-6f * std::max(glm::length(up), 1e-30f))
      fail(c, "<lookat> up is parallel to the view direction");
    left = glm::normalize(left);
    glm::vec3 new_up = glm::cross(dir, left);
    glm::mat4 m(1.0f);
    m[0] = glm::vec4(left, 0);
    m[1] = glm::vec4(new_up, 0);
    m[2] = glm::vec4(dir, 0);
    m[3] = glm::vec4(origin, 1);
    return m;
  }

  // --- typed property access ----------------------------------------------

  static const Property* find(const Element& e, const std::string& name) {
    auto it = e.props.find(name);
    return it == e.props.end() ? nullptr : &it->second;
  }

  [[noreturn]] void wrong_type(const Property& p, const std::string& name, const char* expected) const {
    fail(p.node, "property '" + name + "' has the wrong type <" + p.node.name() + ">, expected " + expected);
  }

  double get_float(const Element& e, const std::string& name, double fallback) const {
    const Property* p = find(e, name);
    if (!p) return fallback;
    if (p->kind != Property::Kind::Number && p->kind != Property::Kind::Integer) wrong_type(*p, name, "<float>");
    return p->number;
  }

  int get_int(const Element& e, const std::string& name, int fallback) const {
    const Property* p = find(e, name);
    if (!p) return fallback;
    if (p->kind != Property::Kind::Integer) wrong_type(*p, name, "<integer>");
    return int(p->number);
  }

  bool get_bool(const Element& e, const std::string& name, bool fallback) const {
    const Property* p = find(e, name);
    if (!p) return fallback;
    if (p->kind != Property::Kind::Boolean) wrong_type(*p, name, "<boolean>");
    return p->boolean;
  }

  std::optional<std::string> get_string(const Element& e, const std::string& name) const {
    const Property* p = find(e, name);
    if (!p) return std::nullopt;
    if (p->kind != Property::Kind::String) wrong_type(*p, name, "<string>");
    return p->text;
  }

  glm::vec3 get_point(const Element& e, const std::string& name, const glm::vec3& fallback) const {
    const Property* p = find(e, name);
    if (!p) return fallback;
    if (p->kind != Property::Kind::Vector) wrong_type(*p, name, "<point>");
    return p->vec;
  }

  glm::mat4 get_transform(const Element& e, const std::string& name) const {
    const Property* p = find(e, name);
    if (!p) return glm::mat4(1.0f);
    if (p->kind != Property::Kind::Transform) wrong_type(*p, name, "<transform>");
    return p->matrix;
  }

  std::optional<glm::vec3> get_color(const Element& e, const std::string& name, ColorUse use) {
    const Property* p = find(e, name);
    if (!p) return std::nullopt;
    switch (p->kind) {
      case Property::Kind::Number:
      case Property::Kind::Integer:
        return glm::vec3(float(p->number));
      case Property::Kind::Color:
        return use == ColorUse::Reflectance ? glm::clamp(p->vec, 0.0f, 1.0f) : p->vec;
      case Property::Kind::Spectrum:
        if (p->wavelengths.empty()) {
          // Mitsuba 3 in RGB mode: a uniform emitted spectrum is equal-energy white, xyz_to_srgb(1, 1, 1).
          bool equal_energy = use == ColorUse::Radiance && version_major_ >= 3;
          return float(p->values[0]) * (equal_energy ? glm::vec3(xyz_to_srgb(glm::dvec3(1.0))) : glm::vec3(1.0f));
        } else {
          glm::vec3 rgb = spectrum_to_rgb(p->wavelengths, p->values, use == ColorUse::Radiance);
          return use == ColorUse::Reflectance ? glm::min(rgb, glm::vec3(1.0f)) : rgb;
        }
      case Property::Kind::Object: {
        std::string type = attr(p->object, "type").value_or("?");
        // Mitsuba 3's spectrum plugins in its RGB modes: uniform is its value, srgb
        // its colour, d65 (the illuminant, which RGB modes leave out) its scale
        // times its colour or white.
        if (std::string(p->object.name()) == "spectrum" && (type == "uniform" || type == "srgb" || type == "d65")) {
          const Element s = parse_element(p->object);
          if (type == "uniform") return glm::vec3(float(get_float(s, "value", 1.0)));
          if (type == "srgb") {
            std::optional<glm::vec3> c = get_color(s, "color", use);
            if (!c) fail(p->object, "<spectrum type=\"srgb\"> needs a 'color'");
            return *c;
          }
          if (!s.objects.empty()) fail(s.objects[0], "a texture inside <spectrum type=\"d65\"> is not supported");
          return float(get_float(s, "scale", 1.0)) * get_color(s, "color", use).value_or(glm::vec3(1.0f));
        }
        warn(p->object, std::string(p->object.name()) + ":" + type,
             std::string(p->object.name()) + " '" + type + "' for '" + name +
                 "' is not supported yet; using the default value");
        return std::nullopt;
      }
      default:
        break;
    }
    wrong_type(*p, name, "<rgb>, <srgb>, <spectrum> or <float>");
  }

  // The nested and referenced plugin elements of `e` with the tag `tag`.
  static std::vector<pugi::xml_node> objects(const Element& e, const char* tag) {
    std::vector<pugi::xml_node> out;
    for (pugi::xml_node o : e.objects)
      if (std::string(o.name()) == tag) out.push_back(o);
    return out;
  }

  // --- top-level plugins --------------------------------------------------

  void skip(pugi::xml_node) {}

  void load_integrator(pugi::xml_node node) {
    Element e = parse_element(node);
    const bool direct = e.type == "direct";
    // The volumetric path tracers (Mitsuba 3's volpath, volpathmis, prbvolpath,
    // Mitsuba 0.5's volpath, volpath_simple) and the path replay ones (prb,
    // prb_basic) render what path does where there are no media (psf renders a
    // shape's interior medium for the volumetric ones, as Mitsuba, and warns
    // about other media): their estimates have the same expectation, and they
    // take the same max_depth and rr_depth.
    static const std::set<std::string> like_path = {"path", "volpath", "volpathmis", "volpath_simple",
                                                    "prbvolpath", "prb", "prb_basic"};
    // An integrator that wraps another (Mitsuba 3's aov, moment and stokes,
    // Mitsuba 0.5's adaptive, irrcache, multichannel...) renders the image of
    // the one nested in it (the first), with its max depth; what the wrapper
    // adds (AOV channels, moments, adaptive sample counts) is not rendered.
    std::vector<pugi::xml_node> nested = objects(e, "integrator");
    if (!like_path.count(e.type) && !direct && !nested.empty()) {
      warn(node, "integrator:" + e.type,
           "integrator '" + e.type + "' is not supported; rendering the '" + attr(nested[0], "type").value_or("") +
               "' nested in it, without what '" + e.type + "' adds");
      load_integrator(nested[0]);
      return;
    }
    if (!like_path.count(e.type) && !direct)
      warn(node, "integrator:" + e.type, "integrator '" + e.type + "' is not supported yet; using path tracing");
    // direct: emitters seen directly plus one bounce of direct light.
    scene_.max_depth = direct ? 2 : get_int(e, "max_depth", -1);
    if (scene_.max_depth < -1)  // as Mitsuba 3 refuses it
      fail(find(e, "max_depth")->node, "'max_depth' must be -1 (unbounded) or at least 0");
    scene_.rr_depth = direct ? 5 : get_int(e, "rr_depth", 5);
    if (scene_.rr_depth < 1) fail(find(e, "rr_depth")->node, "'rr_depth' must be at least 1");
    // hide_emitters: Mitsuba 3's path tracer (3.6; prb and prb_basic alike)
    // hides the environment from camera rays (an area emitter hit stays
    // visible); its direct integrator, its volumetric path tracers and Mitsuba
    // 0.5's integrators hide every emitter they see.
    const bool hides_area = direct || version_major_ < 2 || e.type == "volpath" || e.type == "volpathmis" ||
                            e.type == "prbvolpath";
    if (get_bool(e, "hide_emitters", false))
      scene_.hide = hides_area ? PSF_HIDE_ENVIRONMENT | PSF_HIDE_AREA : PSF_HIDE_ENVIRONMENT;
    for (const auto& [name, p] : e.props)
      if (direct ? name != "hide_emitters" : name != "max_depth" && name != "rr_depth" && name != "hide_emitters")
        warn(p.node, "integrator:" + name,
             "property '" + name + "' of integrator '" + e.type + "' is not supported; ignored");
  }

  // One warning per property of `e` (a `kind` element) not in `known`, nor a nested plugin.
  void ignored_properties(const Element& e, const std::string& kind, const std::vector<std::string>& known) {
    for (const auto& [name, p] : e.props) {
      if (p.kind == Property::Kind::Object) continue;
      bool ok = false;
      for (const std::string& k : known) ok = ok || name == k;
      if (!ok)
        warn(p.node, kind + ":" + e.type + ":" + name,
             "property '" + name + "' of " + kind + " '" + e.type + "' is not supported; ignored");
    }
  }

  void load_sensor(pugi::xml_node node) {
    if (has_sensor_) {
      warn(node, "sensor", "only the first <sensor> is used");
      return;
    }
    has_sensor_ = true;
    Element e = parse_element(node);
    if (e.type != "perspective" && e.type != "thinlens" && e.type != "orthographic")
      warn(node, "sensor:" + e.type, "sensor '" + e.type + "' is not supported yet; using a perspective camera");

    CameraDesc& cam = scene_.camera;
    if (e.type == "thinlens") {  // Mitsuba's: aperture_radius required, focus_distance by default far_clip
      const Property* a = find(e, "aperture_radius");
      if (!a) fail(node, "<sensor type=\"thinlens\"> needs an 'aperture_radius'");
      cam.aperture_radius = float(get_float(e, "aperture_radius", 0.0));
      cam.focus_distance = float(get_float(e, "focus_distance", get_float(e, "far_clip", 1e4)));
      if (!(cam.aperture_radius >= 0.0f) || !std::isfinite(cam.aperture_radius))
        fail(a->node, "the aperture radius must be a finite number >= 0");
      if (!(cam.focus_distance > 0.0f) || !std::isfinite(cam.focus_distance))
        fail(find(e, "focus_distance") ? find(e, "focus_distance")->node : node, "the focus distance must be positive");
    }
    const Property* fov = find(e, "fov");
    const Property* focal = find(e, "focal_length");
    if (fov && focal) fail(focal->node, "give either 'fov' or 'focal_length', not both");
    if (fov) {
      cam.fov_degrees = float(get_float(e, "fov", 0.0));
      cam.fov_axis = lower(get_string(e, "fov_axis").value_or("x"));
      static const std::set<std::string> axes = {"x", "y", "diagonal", "smaller", "larger"};
      if (!axes.count(cam.fov_axis))
        fail(find(e, "fov_axis")->node, "fov_axis '" + cam.fov_axis + "' is not x, y, diagonal, smaller or larger");
    } else {
      // A 35 mm film equivalent focal length (default 50mm) fixes the diagonal field of view.
      std::string f = lower(get_string(e, "focal_length").value_or("50mm"));
      if (f.size() > 2 && f.compare(f.size() - 2, 2, "mm") == 0) f.resize(f.size() - 2);
      std::optional<double> mm = parse_number(f);
      if (!mm || *mm <= 0) fail(focal ? focal->node : node, "focal_length '" + f + "' is not of the form <x>mm");
      cam.fov_degrees = float(glm::degrees(2.0 * std::atan(std::sqrt(36.0 * 36.0 + 24.0 * 24.0) / (2.0 * *mm))));
      cam.fov_axis = "diagonal";
    }
    if (!(cam.fov_degrees > 0.0f && cam.fov_degrees < 180.0f))
      fail(fov ? fov->node : node, "the field of view must be between 0 and 180 degrees");

    // Mitsuba's camera frame: +z forward, +y up (and +x towards the image's left).
    glm::mat4 m = get_transform(e, "to_world");
    // A thin lens's aperture and focus distance are camera-space lengths, which
    // a scaling to_world scales (the aperture by its x-y scale, the focus by z).
    const glm::mat3 axes(m);
    cam.aperture_radius *= std::sqrt(glm::length(axes[0]) * glm::length(axes[1]));
    cam.focus_distance *= glm::length(axes[2]);
    // orthographic: the film spans camera-space x in [-1, 1] and y in [-1, 1] / aspect,
    // so to_world's x and y scales are its world-space half extents.
    cam.orthographic = e.type == "orthographic";
    cam.ortho_scale = glm::vec2(glm::length(axes[0]), glm::length(axes[1]));
    cam.origin = glm::vec3(m * glm::vec4(0, 0, 0, 1));
    cam.target = glm::vec3(m * glm::vec4(0, 0, 1, 1));
    glm::vec3 up = glm::mat3(m) * glm::vec3(0, 1, 0);
    glm::vec3 forward = cam.target - cam.origin;
    if (glm::length(glm::cross(forward, up)) <= 1e-12f * glm::length(forward) * glm::length(up))
      fail(find(e, "to_world") ? find(e, "to_world")->node : node, "the sensor's to_world is degenerate");
    cam.up = glm::normalize(up);
    // A reflection (negative determinant) turns the image's left into its right,
    // which origin, target and up cannot express.
    cam.mirrored = glm::determinant(glm::mat3(m)) < 0.0f;
    // Nor can they express a shear: axes that are no longer perpendicular (a
    // non-uniform scale applied after a lookat or rotation, in world space).
    for (int i = 0; i < 3; ++i) {
      const glm::vec3 a = axes[i], b = axes[(i + 1) % 3];
      if (std::abs(glm::dot(a, b)) > 1e-4f * glm::length(a) * glm::length(b)) {
        warn(find(e, "to_world") ? find(e, "to_world")->node : node, "sensor:shear",
             "the sensor's to_world shears its axes (a non-uniform scale after lookat or rotate?), which is not "
             "supported; the camera keeps its origin, direction, up and axis lengths");
        break;
      }
    }

    // Clip planes: Mitsuba's defaults (0.01 and 10^4), world-space distances
    // along the view direction as Mitsuba 3 casts them; only an orthographic
    // camera's near plane is a camera-space point, scaled by to_world's z.
    const float near_clip = float(get_float(e, "near_clip", 0.01)), far_clip = float(get_float(e, "far_clip", 1e4));
    cam.near_clip = e.type == "orthographic" ? near_clip * glm::length(axes[2]) : near_clip;
    cam.far_clip = cam.near_clip + (far_clip - near_clip);
    if (!(cam.near_clip >= 0.0f && cam.far_clip > cam.near_clip && std::isfinite(cam.far_clip)))
      fail(find(e, "far_clip") ? find(e, "far_clip")->node : find(e, "near_clip") ? find(e, "near_clip")->node : node,
           "the clip distances must satisfy 0 <= near_clip < far_clip");
    // Mitsuba 3's perspective sensor shifts the image plane: film point (s, t)
    // looks along (s + x, t + y) in fractions of the film (measured in Mitsuba
    // 3.6.4's sample_ray; thinlens and orthographic have no such property).
    std::vector<std::string> known = {"fov", "fov_axis", "focal_length", "to_world", "near_clip", "far_clip",
                                      "aperture_radius", "focus_distance"};
    if (e.type == "perspective") {
      cam.principal_point = {float(get_float(e, "principal_point_offset_x", 0.0)),
                             float(get_float(e, "principal_point_offset_y", 0.0))};
      if (!std::isfinite(cam.principal_point.x) || !std::isfinite(cam.principal_point.y))
        fail(node, "the principal point offset must be finite");
      known.push_back("principal_point_offset_x");
      known.push_back("principal_point_offset_y");
    }
    ignored_properties(e, "sensor", known);

    scene_.width = 768;
    scene_.height = 576;
    for (pugi::xml_node film : objects(e, "film")) load_film(film);
    for (pugi::xml_node sampler : objects(e, "sampler")) load_sampler(sampler);
    // The medium around the camera (Mitsuba 3's `medium`, 0.5's `exterior`),
    // resolved at the end of load (medium_material).
    for (const auto& [name, p] : e.props)
      if (p.kind == Property::Kind::Object && std::string(p.object.name()) == "medium") {
        if (!camera_medium_ && media_rendered_) camera_medium_ = p;
        else if (!media_rendered_) warn(p.node, "medium:integrator", "the integrator leaves media out; ignored");
        else warn(p.node, "medium:sensor", "only one medium around the camera; ignored");
      }
  }

  void load_film(pugi::xml_node node) {
    Element e = parse_element(node);
    if (e.type != "hdrfilm" && e.type != "ldrfilm")
      warn(node, "film:" + e.type, "film '" + e.type + "' is not supported yet; reading width and height");
    scene_.width = get_int(e, "width", 768);
    scene_.height = get_int(e, "height", 576);
    if (scene_.width <= 0 || scene_.height <= 0) fail(node, "the film's width and height must be positive");
    // A crop window: the image is crop_width x crop_height pixels of the film from
    // (crop_offset_x, crop_offset_y) on.
    CameraDesc& cam = scene_.camera;
    cam.film_width = cam.film_height = cam.crop_x = cam.crop_y = 0;
    if (find(e, "crop_offset_x") || find(e, "crop_offset_y") || find(e, "crop_width") || find(e, "crop_height")) {
      const int x = get_int(e, "crop_offset_x", 0), y = get_int(e, "crop_offset_y", 0);
      const int w = get_int(e, "crop_width", scene_.width - x), h = get_int(e, "crop_height", scene_.height - y);
      if (x < 0 || y < 0 || w < 1 || h < 1 || int64_t(x) + w > scene_.width || int64_t(y) + h > scene_.height)
        fail(node, "the crop window (" + std::to_string(x) + ", " + std::to_string(y) + ") + " + std::to_string(w) +
                       "x" + std::to_string(h) + " does not lie within the " + std::to_string(scene_.width) + "x" +
                       std::to_string(scene_.height) + " film");
      cam.film_width = scene_.width;
      cam.film_height = scene_.height;
      cam.crop_x = x;
      cam.crop_y = y;
      scene_.width = w;
      scene_.height = h;
    }
    // The reconstruction filter: Mitsuba's default is a Gaussian of stddev 0.5.
    scene_.camera.pixel_filter = "gaussian";
    scene_.camera.filter_stddev = 0.5f;
    for (pugi::xml_node rfilter : objects(e, "rfilter")) load_rfilter(rfilter);
    // The output's format is psf's own (OpenEXR, float RGB, and a PNG): those
    // properties do not change the image and are ignored quietly. Pixel filters
    // are sampled, so pixels at the border draw samples from beyond it as
    // high_quality_edges asks (without it Mitsuba leaves those out).
    ignored_properties(e, "film", {"width", "height", "pixel_format", "component_format", "file_format", "banner",
                                   "gamma", "exposure", "tonemap_method", "high_quality_edges", "crop_offset_x",
                                   "crop_offset_y", "crop_width", "crop_height"});
  }

  // box, tent (radius, default 1) and gaussian (stddev, default 0.5) are sampled
  // as Mitsuba weights them; the filters with negative lobes are not (a sample's
  // weight would be negative), and a Gaussian takes their place.
  void load_rfilter(pugi::xml_node node) {
    Element e = parse_element(node);
    CameraDesc& cam = scene_.camera;
    if (e.type == "box") {
      cam.pixel_filter = "box";
    } else if (e.type == "tent") {
      cam.pixel_filter = "tent";
      cam.filter_radius = float(get_float(e, "radius", 1.0));
      if (!(cam.filter_radius > 0.0f) || !std::isfinite(cam.filter_radius))
        fail(find(e, "radius") ? find(e, "radius")->node : node, "the tent filter's radius must be positive");
    } else if (e.type == "gaussian") {
      cam.pixel_filter = "gaussian";
      cam.filter_stddev = float(get_float(e, "stddev", 0.5));
      if (!(cam.filter_stddev > 0.0f) || !std::isfinite(cam.filter_stddev))
        fail(find(e, "stddev") ? find(e, "stddev")->node : node, "the Gaussian filter's stddev must be positive");
    } else {
      warn(node, "rfilter:" + e.type,
           "rfilter '" + e.type + "' is not supported (box, tent, gaussian); using a Gaussian of stddev 0.5");
      cam.pixel_filter = "gaussian";
      cam.filter_stddev = 0.5f;
    }
  }

  void load_sampler(pugi::xml_node node) {
    Element e = parse_element(node);
    scene_.default_spp = get_int(e, "sample_count", 4);
    if (scene_.default_spp <= 0) fail(find(e, "sample_count")->node, "sample_count must be positive");
    // Every sampler type draws psf's scrambled Sobol points (--seed picks the scrambling).
    ignored_properties(e, "sampler", {"sample_count"});
  }

  void load_top_bsdf(pugi::xml_node node) { bsdf(node); }

  void load_top_emitter(pugi::xml_node node) {
    std::string type = attr(node, "type").value_or("");
    if (light_plugins().count(type)) {
      load_light(node);
    } else if (type != "area") {
      emitter(node);
    } else if (!node.attribute("id")) {
      warn(node, "emitter:area", "an area emitter outside a <shape> has no surface; ignored");
    }
  }

  // --- shapes -------------------------------------------------------------

  using ShapeBuilder = TriMesh (MitsubaLoader::*)(const Element&);

  static const std::map<std::string, ShapeBuilder>& shape_plugins() {
    static const std::map<std::string, ShapeBuilder> plugins = {{"obj", &MitsubaLoader::shape_obj},
                                                                {"rectangle", &MitsubaLoader::shape_rectangle},
                                                                {"cube", &MitsubaLoader::shape_cube},
                                                                {"disk", &MitsubaLoader::shape_disk},
                                                                {"sphere", &MitsubaLoader::shape_sphere},
                                                                {"cylinder", &MitsubaLoader::shape_cylinder},
                                                                {"ply", &MitsubaLoader::shape_ply},
                                                                {"serialized", &MitsubaLoader::shape_serialized}};
    return plugins;
  }

  void load_shape(pugi::xml_node node) { load_shape_at(node, glm::mat4(1.0f), 0); }

  // The shapes a merge (or the shapegroup an instance draws) draws, counting
  // those of the merges and instances inside it (each container's count once,
  // however often it is held), up to kMaxShapes + 1; a merge inside itself
  // counts 0 here (load_shape_at reports it).
  size_t merge_shapes(pugi::xml_node node, size_t depth = 1) {
    if (auto m = merge_counts_.find(node.internal_object()); m != merge_counts_.end()) return m->second;
    if (depth > kMaxNesting) fail(node, "merges nested more than " + std::to_string(kMaxNesting) + " deep");
    merge_counts_[node.internal_object()] = 0;  // while counting: a cycle adds nothing
    size_t n = 0;
    for (pugi::xml_node child : objects(parse_element(node), "shape"))
      n = std::min(n + shapes_drawn_by(child, depth + 1), kMaxShapes + 1);
    return merge_counts_[node.internal_object()] = n;
  }

  // The shapes load_shape_at draws for `node`: a merge's or an instance's
  // group's (merge_shapes), none for a shapegroup itself, else 1.
  size_t shapes_drawn_by(pugi::xml_node node, size_t depth = 1) {
    const std::string type = attr(node, "type").value_or("");
    if (type == "merge") return merge_shapes(node, depth);
    if (type == "shapegroup") return 0;
    if (type == "instance") {  // only containers are parsed here (load_shape_at parses every shape)
      std::vector<pugi::xml_node> groups = objects(parse_element(node), "shape");
      return groups.size() == 1 ? merge_shapes(groups[0], depth) : 0;  // else load_shape_at reports it
    }
    return 1;
  }

  // A shape, its to_world after `parent` (the instance it is reached through,
  // `depth` 1, else 0). A shapegroup is not drawn itself; an instance draws the
  // shapes of the shapegroup it refers to, each copied into the scene with the
  // instance's to_world applied after its own (as Mitsuba, no nested instancing).
  void load_shape_at(pugi::xml_node node, const glm::mat4& parent, int depth) {
    Element e = parse_element(node);
    if (e.type == "shapegroup") {
      if (depth > 0) warn(node, "shapegroup-nested", "a shapegroup inside a shapegroup is not supported; ignored");
      for (pugi::xml_node o : e.objects)
        if (std::string(o.name()) != "shape")
          warn(o, "shapegroup:" + std::string(o.name()), "<" + std::string(o.name()) + "> in a shapegroup is ignored");
      return;
    }
    if (e.type == "merge") {  // Mitsuba 3's merge: its shapes, drawn as they are (merging only saves memory there)
      if (!in_progress_.insert(node.internal_object()).second) fail(node, "merge shape contains itself");
      if (in_progress_.size() > kMaxNesting) fail(node, "merges nested more than " + std::to_string(kMaxNesting) + " deep");
      for (pugi::xml_node child : objects(e, "shape")) load_shape_at(child, parent, depth);
      in_progress_.erase(node.internal_object());
      return;
    }
    if (e.type == "instance") {
      std::vector<pugi::xml_node> groups = objects(e, "shape");
      if (groups.size() != 1 || attr(groups[0], "type").value_or("") != "shapegroup")
        fail(node, "<shape type=\"instance\"> needs one reference to a shapegroup");
      if (depth > 0) fail(node, "an instance inside a shapegroup (nested instancing) is not supported");
      const glm::mat4 to_world = parent * get_transform(e, "to_world");
      Element group = parse_element(groups[0]);
      for (pugi::xml_node child : objects(group, "shape")) load_shape_at(child, to_world, depth + 1);
      return;
    }
    auto plugin = shape_plugins().find(e.type);
    // Mitsuba 3's other shapes: curves, SDF grids and ellipsoid clouds are not
    // triangle surfaces psf can tessellate yet; a name Mitsuba does not know is an error.
    static const std::set<std::string> unsupported = {"bsplinecurve", "linearcurve", "sdfgrid", "ellipsoids",
                                                      "ellipsoidsmesh"};
    if (plugin == shape_plugins().end() && unsupported.count(e.type)) {
      warn(node, "shape:" + e.type, "shape '" + e.type + "' is not supported yet; ignored");
      return;
    }
    if (plugin == shape_plugins().end()) {
      std::string known;
      for (const auto& entry : shape_plugins()) known += (known.empty() ? "" : ", ") + entry.first;
      fail(node, "unknown shape type '" + e.type + "' (supported: " + known + ", shapegroup, instance, merge)");
    }
    TriMesh mesh = (this->*plugin->second)(e);
    // Mitsuba uses a mesh's vertex colours only through a mesh_attribute texture
    // of its BSDF: without one they are left out (with a warning).
    {
      std::vector<pugi::xml_node> shape_bsdfs = objects(e, "bsdf");
      const bool wanted = !shape_bsdfs.empty() && reads_vertex_colors(bsdf(shape_bsdfs[0]));
      if (!mesh.colors.empty() && !wanted) {
        warn(node, "shape:vertex-colors",
             "the mesh's vertex colours are not used (its BSDF has no mesh_attribute 'vertex_color')");
        mesh.colors.clear();
      } else if (mesh.colors.empty() && wanted) {
        warn(node, "shape:no-vertex-colors",
             "the BSDF reads vertex colours, which psf found none of in this mesh (it reads them from PLY and OBJ "
             "files); white");
      }
    }
    // Mitsuba 0.5's maxSmoothAngle (obj, ply, serialized): normals rebuilt with
    // creases, unless face_normals cleared them (face normals win).
    if (const Property* a = find(e, "max_smooth_angle");
        a && (e.type == "obj" || e.type == "ply" || e.type == "serialized") && !mesh.normals.empty()) {
      const float degrees = float(get_float(e, "max_smooth_angle", 0.0));
      if (!(degrees >= 0.0f && degrees <= 180.0f)) fail(a->node, "maxSmoothAngle must be between 0 and 180 degrees");
      compute_crease_normals(mesh, degrees);
    }
    // Each type's properties (as read by its builder); the others get a warning.
    static const std::map<std::string, std::set<std::string>> shape_properties = {
        {"obj", {"filename", "face_normals", "flip_tex_coords", "max_smooth_angle"}},
        {"ply", {"filename", "face_normals", "flip_tex_coords", "max_smooth_angle"}},
        {"serialized", {"filename", "shape_index", "face_normals", "max_smooth_angle"}},
        {"sphere", {"center", "radius"}},
        {"cylinder", {"p0", "p1", "radius"}},
        {"rectangle", {}},
        {"cube", {}},
        {"disk", {}}};
    for (const auto& [name, prop] : e.props)
      if (prop.kind != Property::Kind::Object && name != "to_world" && name != "flip_normals" &&
          !shape_properties.at(e.type).count(name))
        warn(prop.node, "shape:" + e.type + ":" + name,
             "property '" + name + "' of shape '" + e.type + "' is not supported; ignored");

    std::vector<pugi::xml_node> bsdfs = objects(e, "bsdf"), emitters = objects(e, "emitter");
    if (bsdfs.size() > 1) fail(bsdfs[1], "a shape can have only one BSDF");
    if (emitters.size() > 1) fail(emitters[1], "a shape can have only one emitter");
    for (pugi::xml_node o : e.objects) {
      std::string tag = o.name();
      if (tag != "bsdf" && tag != "emitter" && tag != "medium")
        warn(o, tag, "<" + tag + "> in a <shape> is not supported yet; ignored");
    }
    // Media: the shape's interior and exterior.
    pugi::xml_node interior, exterior;
    size_t named_media = 0;
    for (const auto& [name, p] : e.props) {
      if (p.kind != Property::Kind::Object || std::string(p.object.name()) != "medium") continue;
      ++named_media;
      if ((name == "interior" || name == "exterior") && !media_rendered_)
        warn(p.node, "medium:integrator",
             "the integrator '" + (integrator_type_.empty() ? std::string("path") : integrator_type_) +
                 "' leaves media out, as Mitsuba's does (volpath renders them); ignored");
      else if (name == "interior") interior = p.object;
      else if (name == "exterior") exterior = p.object;
      else
        warn(p.node, "medium:" + name,
             "a shape's medium must be named interior or exterior, not '" + name + "'; ignored");
    }
    if (objects(e, "medium").size() > named_media)
      warn(e.node, "medium:unnamed", "a <medium> in a <shape> needs name=\"interior\" or \"exterior\"; ignored");
    uint32_t mat = material(bsdfs.empty() ? pugi::xml_node() : bsdfs[0],
                            emitters.empty() ? pugi::xml_node() : emitters[0], interior, exterior);
    const glm::mat4 to_world = parent * get_transform(e, "to_world");
    const bool flip = get_bool(e, "flip_normals", false);
    if (e.type == "sphere") {
      if (std::optional<glm::mat4> unit = sphere_as_mitsuba3(e, to_world)) {
        warn(e.node, "sphere:non-uniform",
             "the sphere's to_world scales non-uniformly; drawn as Mitsuba 3 draws it, a sphere of the radius "
             "along its first axis (not an ellipsoid)");
        if (add_analytic_sphere(*unit, glm::vec3(0.0f), 1.0f, mat, flip)) return;
        append_mesh(scene_, make_sphere(glm::vec3(0.0f), 1.0f), *unit, mat, flip, file_of(node).path, line_of(node));
        return;
      }
      if (add_analytic_sphere(to_world, get_point(e, "center", glm::vec3(0.0f)), float(get_float(e, "radius", 1.0)),
                              mat, flip))
        return;
    }
    append_mesh(scene_, mesh, to_world, mat, flip, file_of(node).path, line_of(node));
  }

  // Mitsuba 3 keeps a sphere's to_world a similarity: it splits M = to_world *
  // translate(center) * scale(radius) by the polar decomposition into a rotation
  // Q and a symmetric stretch S (and M's translation T), warns where S is not a
  // multiple of the identity, and draws the sphere of radius S[0][0] turned by Q
  // about T. For a to_world that scales non-uniformly and does not mirror, that
  // transform of the unit sphere at the origin; otherwise none (a similarity is
  // drawn as it is; Mitsuba 3 draws a mirrored sphere black).
  std::optional<glm::mat4> sphere_as_mitsuba3(const Element& e, const glm::mat4& to_world) const {
    const glm::vec3 center = get_point(e, "center", glm::vec3(0.0f));
    const float radius = float(get_float(e, "radius", 1.0));
    const glm::mat4 m = to_world * glm::translate(glm::mat4(1.0f), center) * glm::scale(glm::mat4(1.0f), glm::vec3(radius));
    const glm::dmat3 a = glm::dmat3(glm::mat3(m));
    const double det = glm::determinant(a);
    if (!(det > 0.0) || !std::isfinite(det) || is_similarity(a)) return std::nullopt;
    // Higham's scaled Newton iteration for the orthogonal factor (as Dr.Jit's polar_decomp).
    glm::dmat3 q = a;
    for (int it = 0; it < 25; ++it) {
      const glm::dmat3 qi = glm::transpose(glm::inverse(q));
      double fq = 0, fi = 0;
      for (int c = 0; c < 3; ++c) {
        fq += glm::dot(q[c], q[c]);
        fi += glm::dot(qi[c], qi[c]);
      }
      const double gamma = std::sqrt(std::sqrt(fi / fq));
      q = 0.5 * (gamma * q + qi / gamma);
    }
    const glm::dmat3 stretch = glm::transpose(q) * a;
    const double r = stretch[0][0];
    if (!(r > 0.0) || !std::isfinite(r)) return std::nullopt;
    glm::mat4 out(glm::mat3(q * r));
    out[3] = m[3];
    return out;
  }

  // A sphere (center, radius) whose to_world is a rotation, uniform scale and
  // translation (as Mitsuba 3 expects of its spheres) goes in as an analytic
  // sphere, unless its material is alpha-tested (masks cut triangles only);
  // otherwise the caller draws its tessellation.
  // Whether `a` is a rotation times a positive uniform scale: (a / cbrt(det a))
  // times its transpose within 1e-4 of the identity.
  template <typename T>
  static bool is_similarity(const glm::mat<3, 3, T>& a) {
    const T s = std::cbrt(glm::determinant(a));
    if (!(s > T(0)) || !std::isfinite(s)) return false;
    const glm::mat<3, 3, T> qtq = glm::transpose(a / s) * (a / s);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (std::fabs(qtq[i][j] - (i == j ? T(1) : T(0))) > T(1e-4)) return false;
    return true;
  }

  bool add_analytic_sphere(const glm::mat4& to_world, glm::vec3 center, float radius, uint32_t mat, bool flip) {
    // Masked spheres are alpha-tested as triangles; a null boundary's shadow-ray
    // crossings (kernels/raycast.cl) take a sphere's normals to point outwards.
    if (mat < scene_.materials.size() && (scene_.materials[mat].flags & PSF_MATFLAG_MASKED)) return false;
    if (mat < scene_.materials.size() && flip && (scene_.materials[mat].flags & PSF_MATFLAG_NULL_BOUNDARY))
      return false;
    const glm::mat3 a(to_world);
    if (!is_similarity(a)) return false;
    const float s = std::cbrt(glm::determinant(a));
    const glm::mat3 q = a / s;  // the rotation
    SphereShape sp;
    sp.center = glm::vec3(to_world * glm::vec4(center, 1.0f));
    sp.radius = s * radius;
    sp.axis_x = glm::normalize(q[0]);
    sp.axis_y = glm::normalize(q[1] - sp.axis_x * glm::dot(sp.axis_x, q[1]));
    sp.flip = flip;
    sp.material = mat;
    if (!std::isfinite(sp.radius) || !std::isfinite(sp.center.x + sp.center.y + sp.center.z)) return false;
    scene_.spheres.push_back(sp);
    return true;
  }

  TriMesh shape_obj(const Element& e) {
    std::optional<std::string> name = get_string(e, "filename");
    if (!name) fail(e.node, "<shape type=\"obj\"> needs a 'filename'");
    std::string path = resolve(e.node, *name);
    if (!is_file(path)) fail(e.node, "cannot open OBJ file '" + path + "'" + why_unopenable(path));
    ObjData obj = read_obj(path, false);
    for (const std::string& w : obj.warnings) scene_.warnings.push_back(where(e.node) + ": " + w);
    TriMesh mesh = std::move(obj.mesh);
    // Mitsuba flips v on loading (flip_tex_coords, default true; read_obj already did).
    if (!get_bool(e, "flip_tex_coords", true))
      for (glm::vec2& uv : mesh.uvs) uv.y = 1.0f - uv.y;
    // face_normals discards the file's normals; without any, Mitsuba computes smooth ones.
    if (get_bool(e, "face_normals", false)) mesh.normals.clear();
    else if (mesh.normals.empty()) compute_vertex_normals(mesh);
    return mesh;
  }

  // serialized: mesh `shape_index` (default 0) of a Mitsuba .serialized file.
  TriMesh shape_serialized(const Element& e) {
    std::optional<std::string> name = get_string(e, "filename");
    if (!name) fail(e.node, "<shape type=\"serialized\"> needs a 'filename'");
    std::string path = resolve(e.node, *name);
    if (!is_file(path)) fail(e.node, "cannot open serialized mesh file '" + path + "'" + why_unopenable(path));
    SerializedMesh s = read_serialized(path, get_int(e, "shape_index", 0));
    // As for OBJ: face normals (asked for by the file or by face_normals) discard
    // the file's normals; without any, Mitsuba computes smooth ones.
    if (s.face_normals || get_bool(e, "face_normals", false)) s.mesh.normals.clear();
    else if (s.mesh.normals.empty()) compute_vertex_normals(s.mesh);
    return std::move(s.mesh);
  }

  TriMesh shape_ply(const Element& e) {
    std::optional<std::string> name = get_string(e, "filename");
    if (!name) fail(e.node, "<shape type=\"ply\"> needs a 'filename'");
    std::string path = resolve(e.node, *name);
    if (!is_file(path)) fail(e.node, "cannot open PLY file '" + path + "'" + why_unopenable(path));
    PlyMesh ply = read_ply(path);
    if (!ply.ignored.empty()) {
      std::string list;
      for (const std::string& n : ply.ignored) list += (list.empty() ? "" : ", ") + n;
      warn(e.node, "ply-data", "PLY data of '" + path + "' not used: " + list);
    }
    // As for OBJ: face_normals discards the file's normals; without any, smooth ones.
    if (get_bool(e, "face_normals", false)) ply.mesh.normals.clear();
    else if (ply.mesh.normals.empty()) compute_vertex_normals(ply.mesh);
    return std::move(ply.mesh);
  }

  TriMesh shape_rectangle(const Element&) { return make_rectangle(); }
  TriMesh shape_cube(const Element&) { return make_cube(); }
  TriMesh shape_disk(const Element&) { return make_disk(); }

  TriMesh shape_sphere(const Element& e) {
    float radius = float(get_float(e, "radius", 1.0));
    if (!(radius > 0.0f)) fail(find(e, "radius")->node, "the sphere radius must be positive");
    return make_sphere(get_point(e, "center", glm::vec3(0.0f)), radius);
  }

  TriMesh shape_cylinder(const Element& e) {
    float radius = float(get_float(e, "radius", 1.0));
    if (!(radius > 0.0f)) fail(find(e, "radius")->node, "the cylinder radius must be positive");
    glm::vec3 p0 = get_point(e, "p0", glm::vec3(0.0f)), p1 = get_point(e, "p1", glm::vec3(0.0f, 0.0f, 1.0f));
    if (!(glm::length(p1 - p0) > 0.0f)) fail(e.node, "the cylinder's p0 and p1 must differ");
    return make_cylinder(p0, p1, radius);
  }

  // --- materials, BSDFs, textures -------------------------------------------

  // A homogeneous medium: its extinction sigma_t, single-scattering albedo and
  // Henyey-Greenstein g (Material.interior, interior_albedo). Mitsuba 3's sigma_t,
  // albedo, scale and phase (isotropic or hg), or 0.5's sigmaA and sigmaS (or
  // sigmaT and albedo) and scale. None for other medium types.
  struct Medium {
    glm::vec3 sigma_t{1.0f}, albedo{0.75f};
    float g = 0.0f;
  };
  // Medium `node`, read (and warned about) once however many shapes refer to it.
  const std::optional<Medium>& medium(pugi::xml_node node) {
    auto it = media_.find(node.internal_object());
    if (it == media_.end()) it = media_.emplace(node.internal_object(), read_medium(node)).first;
    return it->second;
  }
  std::optional<Medium> read_medium(pugi::xml_node node) {
    const Element e = parse_element(node);
    if (e.type != "homogeneous") {
      warn(node, "medium:" + e.type, "medium '" + e.type + "' is not supported; the shape's interior is left empty");
      return std::nullopt;
    }
    ignored_properties(e, "medium", {"sigma_t", "albedo", "scale", "sigma_a", "sigma_s", "density_multiplier",
                                     "sample_emitters", "has_spectral_extinction"});
    if (find(e, "material"))
      warn(node, "medium:material", "named media (material) are not supported; using sigma_t and albedo");
    Medium m;
    if (find(e, "sigma_a") || find(e, "sigma_s")) {
      const glm::vec3 a = get_color(e, "sigma_a", ColorUse::Unbounded).value_or(glm::vec3(0.0f));
      const glm::vec3 sc = get_color(e, "sigma_s", ColorUse::Unbounded).value_or(glm::vec3(0.0f));
      if (!glm::all(glm::greaterThanEqual(glm::min(a, sc), glm::vec3(0.0f))))
        fail(node, "the medium's sigma_a and sigma_s must be >= 0");
      m.sigma_t = a + sc;
      for (int i = 0; i < 3; ++i) m.albedo[i] = sc[i] > 0 ? sc[i] / m.sigma_t[i] : 0.0f;
    } else {
      m.sigma_t = get_color(e, "sigma_t", ColorUse::Unbounded).value_or(glm::vec3(1.0f));
      m.albedo = get_color(e, "albedo", ColorUse::Reflectance).value_or(glm::vec3(0.75f));
    }
    m.sigma_t *= float(get_float(e, "scale", 1.0) * get_float(e, "density_multiplier", 1.0));
    if (!(glm::all(glm::greaterThanEqual(m.sigma_t, glm::vec3(0.0f))) && std::isfinite(m.sigma_t.x) &&
          std::isfinite(m.sigma_t.y) && std::isfinite(m.sigma_t.z)))
      fail(node, "the medium's sigma_t must be finite and >= 0");
    for (pugi::xml_node phase : objects(e, "phase")) {
      const Element ph = parse_element(phase);
      if (ph.type == "hg") {
        m.g = float(get_float(ph, "g", 0.8));  // Mitsuba's default
        if (!(m.g > -1.0f && m.g < 1.0f)) fail(phase, "the Henyey-Greenstein g must lie in (-1, 1)");
      } else if (ph.type != "isotropic") {
        warn(phase, "phase:" + ph.type, "phase function '" + ph.type + "' is not supported; isotropic instead");
      }
    }
    return m;
  }

  // 1 + the index of a material whose interior is medium `node`: the first shape's
  // that has it inside, else a material of its own that no shape uses (a medium
  // only outside shapes, or around the camera); 0 where it is not rendered.
  uint32_t medium_material(pugi::xml_node node) {
    auto it = medium_materials_.find(node.internal_object());
    if (it != medium_materials_.end()) return it->second + 1;
    const std::optional<Medium>& md = medium(node);
    if (!md) return 0;
    Material m = diffuse_material(glm::vec3(0.0f));
    m.interior = {{md->sigma_t.x, md->sigma_t.y, md->sigma_t.z, 1.0f}};
    m.interior_albedo = {{md->albedo.x, md->albedo.y, md->albedo.z, md->g}};
    scene_.materials.push_back(m);
    const std::string id = node.attribute("id").as_string();
    scene_.material_names.push_back("medium" + (id.empty() ? std::string() : " '" + id + "'"));
    const uint32_t index = uint32_t(scene_.materials.size() - 1);
    medium_materials_.emplace(node.internal_object(), index);
    return index + 1;
  }

  // The material of a shape with this BSDF, emitter, interior and exterior medium
  // (any may be null), shared between shapes.
  uint32_t material(pugi::xml_node bsdf_node, pugi::xml_node emitter_node, pugi::xml_node medium_node = {},
                    pugi::xml_node exterior_node = {}) {
    auto key = std::make_tuple(bsdf_node.internal_object(), emitter_node.internal_object(),
                               medium_node.internal_object(), exterior_node.internal_object());
    auto it = materials_.find(key);
    if (it != materials_.end()) return it->second;
    glm::vec4 interior(0.0f), interior_albedo(0.0f);
    if (medium_node)
      if (const std::optional<Medium>& md = medium(medium_node)) {
        interior = glm::vec4(md->sigma_t, 1.0f);
        interior_albedo = glm::vec4(md->albedo, md->g);
      }
    const uint32_t exterior = exterior_node ? medium_material(exterior_node) : 0u;

    Bsdf b;
    b.name = "default";
    if (bsdf_node) b = bsdf(bsdf_node);
    // Without a BSDF Mitsuba (3 and 0.5) gives a shape a diffuse one of
    // reflectance 0.5, but an emitter's shape a black one: a light reflects nothing.
    else if (emitter_node) b.m = diffuse_material(glm::vec3(0.0f));
    const bool null_boundary = b.null && (interior.w > 0.0f || exterior > 0u);
    if (null_boundary) {
      // psf's null surfaces are skipped by every ray, so no path would enter the
      // medium: its boundary becomes a smooth dielectric of relative index 1,
      // which reflects nothing and lets every path through unbent, but is a hit
      // that moves the path into the medium or out; light samples pass it with
      // the transmittance of the media they cross (kernels/raycast.cl).
      b.m = Material{};
      b.m.type = PSF_MATERIAL_DIELECTRIC;
      b.m.eta = {{1.0f, 1.0f, 0.0f, 0.0f}};
      b.m.specular = {{1.0f, 1.0f, 1.0f, 0.0f}};
      b.m.transmittance = {{1.0f, 1.0f, 1.0f, 0.0f}};
      b.m.flags = PSF_MATFLAG_NULL_BOUNDARY;
      b.null = false;
    }
    SurfaceEmission emission = emitter_node ? emitter(emitter_node) : SurfaceEmission{};
    const glm::vec3 radiance = emission.radiance;
    bool emits = glm::any(glm::greaterThan(radiance, glm::vec3(0.0f)));
    if (b.null && emits) {
      // Rays that skip the surface would never reach the emitter, and light
      // sampling, whose MIS weights count on them, would be short of them.
      warn(emitter_node, "bsdf:null+emitter",
           "an area emitter on a shape with a null BSDF: the shape is drawn as an opaque black emitter (Mitsuba "
           "lets rays pass through it)");
      b.m.flags &= ~PSF_MATFLAG_MASKED;
    }

    auto with_emission = [&](const Bsdf& from) {
      Material m = from.m;
      m.emission = {{radiance.x, radiance.y, radiance.z, 0}};
      m.tex_emission = emission.texture;
      // Mitsuba's area emitters emit from the front side only, whatever the BSDF.
      m.two_sided = from.two_sided && !emits ? 1u : 0u;
      m.interior = {{interior.x, interior.y, interior.z, interior.w}};
      m.interior_albedo = {{interior_albedo.x, interior_albedo.y, interior_albedo.z, interior_albedo.w}};
      m.exterior = exterior;
      return m;
    };
    std::string name = b.name;
    if (emitter_node) name += "+" + attr(emitter_node, "id").value_or("emitter");
    // A blend's partners first (Material.blend is 1 + the partner's index), then the material.
    std::function<uint32_t(const Bsdf&, const std::string&)> push = [&](const Bsdf& x, const std::string& as) {
      Material m = with_emission(x);
      if (x.blend) m.blend = 1 + push(*x.blend, name + " (blended " + x.blend->name + ")");
      scene_.materials.push_back(m);
      scene_.material_names.push_back(as);
      return uint32_t(scene_.materials.size() - 1);
    };
    uint32_t index = push(b, name);
    if (interior.w > 0.0f) medium_materials_.emplace(medium_node.internal_object(), index);
    materials_.emplace(key, index);
    return index;
  }

  using BsdfBuilder = Bsdf (MitsubaLoader::*)(const Element&);

  // BSDFs the renderer reproduces (Mitsuba 3's semantics, kernels/bsdf.cl); every
  // other type goes to approximate_bsdf.
  static const std::map<std::string, BsdfBuilder>& bsdf_plugins() {
    static const std::map<std::string, BsdfBuilder> plugins = {
        {"diffuse", &MitsubaLoader::bsdf_diffuse},          {"conductor", &MitsubaLoader::bsdf_conductor},
        {"roughconductor", &MitsubaLoader::bsdf_conductor}, {"plastic", &MitsubaLoader::bsdf_plastic},
        {"roughplastic", &MitsubaLoader::bsdf_plastic},     {"dielectric", &MitsubaLoader::bsdf_dielectric},
        {"roughdielectric", &MitsubaLoader::bsdf_dielectric}, {"thindielectric", &MitsubaLoader::bsdf_dielectric},
        {"twosided", &MitsubaLoader::bsdf_twosided},        {"bumpmap", &MitsubaLoader::bsdf_bumpmap},
        {"mask", &MitsubaLoader::bsdf_mask},                {"normalmap", &MitsubaLoader::bsdf_normalmap},
        {"blendbsdf", &MitsubaLoader::bsdf_blend},          {"principled", &MitsubaLoader::bsdf_principled},
        {"null", &MitsubaLoader::bsdf_null},                {"pplastic", &MitsubaLoader::bsdf_pplastic},
        {"principledthin", &MitsubaLoader::bsdf_principledthin}};
    return plugins;
  }

  const Bsdf& bsdf(pugi::xml_node node) {
    auto cached = bsdfs_.find(node.internal_object());
    if (cached != bsdfs_.end()) return cached->second;
    if (!in_progress_.insert(node.internal_object()).second) fail(node, "BSDF refers to itself");
    if (in_progress_.size() > kMaxNesting)  // each level is a frame of this recursion
      fail(node, "BSDFs nested more than " + std::to_string(kMaxNesting) + " deep");
    Element e = parse_element(node);
    auto plugin = bsdf_plugins().find(e.type);
    // vertex_color_: whether this BSDF's own colour term (not a nested BSDF's)
    // is a mesh_attribute 'vertex_color'; then its material multiplies it in.
    const bool outer_vertex_color = vertex_color_;
    vertex_color_ = false;
    Bsdf b = plugin != bsdf_plugins().end() ? (this->*plugin->second)(e) : approximate_bsdf(e);
    if (vertex_color_) {
      b.vertex_color = true;
      b.m.flags |= PSF_MATFLAG_VERTEX_COLOR;
    }
    vertex_color_ = outer_vertex_color;
    b.name = attr(node, "id").value_or(b.name.empty() ? e.type : b.name);
    in_progress_.erase(node.internal_object());
    return bsdfs_.emplace(node.internal_object(), b).first->second;
  }

  // Whether `b` or a BSDF of its blend chain multiplies in the vertex colours.
  static bool reads_vertex_colors(const Bsdf& b) {
    return b.vertex_color || (b.m.flags & PSF_MATFLAG_VERTEX_COLOR) || (b.blend && reads_vertex_colors(*b.blend));
  }

  // One warning per property of `e` not in `known` (snake_case names).
  void check_properties(const Element& e, std::initializer_list<const char*> known) {
    for (const auto& [name, p] : e.props) {
      bool ok = false;
      for (const char* k : known) ok = ok || name == k;
      if (!ok)
        warn(p.node, "bsdf:" + e.type + ":" + name,
             "property '" + name + "' of bsdf '" + e.type + "' is not supported; ignored");
    }
  }

  // f applied to `b` and to each BSDF of its blend chain (a wrapper around a
  // blendbsdf wraps all of its BSDFs).
  template <class F>
  static void for_each_part(Bsdf& b, F&& f) {
    f(b);
    if (b.blend) {
      auto partner = std::make_shared<Bsdf>(*b.blend);
      for_each_part(*partner, f);
      b.blend = partner;
    }
  }

  // The only nested BSDF of a wrapper (twosided, bumpmap, mask).
  pugi::xml_node nested_bsdf(const Element& e) {
    std::vector<pugi::xml_node> nested = objects(e, "bsdf");
    if (nested.empty()) fail(e.node, "<bsdf type=\"" + e.type + "\"> needs a nested BSDF");
    if (nested.size() > 1 && e.type != "twosided") fail(nested[1], "bsdf '" + e.type + "' takes one nested BSDF");
    return nested[0];
  }

  // A colour parameter: a constant or a texture (texture index, `value` then the
  // fallback used when the texture's file is missing).
  struct ColorParam {
    glm::vec3 value{0.0f};
    uint32_t texture = PSF_NO_TEXTURE;
  };

  // `colour_term`: the parameter is the material's colour term (diffuse
  // reflectance, a plastic's diffuse, a conductor's specular, base_color), the
  // one slot that vertex colours multiply (kernels/surface.cl).
  ColorParam color_param(const Element& e, const std::string& name, const glm::vec3& fallback,
                         bool colour_term = true) {
    const Property* p = find(e, name);
    if (p && p->kind == Property::Kind::Object && std::string(p->object.name()) == "texture" &&
        attr(p->object, "type").value_or("") == "mesh_attribute") {
      if (!colour_term) {
        warn(p->object, "texture:mesh_attribute:" + name,
             "a mesh_attribute for '" + name + "' is not supported (only for a colour term); using " +
                 fmt(fallback));
        return {fallback};
      }
      // Mitsuba 3's mesh_attribute: "vertex_color" (a PLY's colours) is the
      // colour 1 times the vertex colours; other attributes are not supported.
      Element t = parse_element(p->object);
      const std::string attribute = get_string(t, "name").value_or("");
      check_texture_properties(t, {"name", "scale"});
      if (attribute == "vertex_color") {
        vertex_color_ = true;
        return {glm::vec3(float(get_float(t, "scale", 1.0)))};
      }
      warn(p->object, "texture:mesh_attribute:" + attribute,
           "mesh_attribute '" + attribute + "' is not supported (only vertex_color); using " + fmt(fallback) +
               " for '" + name + "'");
      return {fallback};
    }
    if (p && p->kind == Property::Kind::Object && std::string(p->object.name()) == "texture") {
      ColorParam c{fallback};
      c.texture = texture(p->object, TextureUse::Color, "using " + fmt(fallback) + " for '" + name + "'");
      return c;
    }
    return {get_color(e, name, ColorUse::Reflectance).value_or(fallback)};
  }

  // A colour parameter that cannot be textured: a texture gives a warning and its mean.
  glm::vec3 constant_color(const Element& e, const std::string& name, const glm::vec3& fallback) {
    ColorParam c = color_param(e, name, fallback, false);
    if (c.texture == PSF_NO_TEXTURE) return c.value;
    warn(find(e, name)->node, "bsdf:" + e.type + ":" + name + ":texture",
         "a texture for '" + name + "' of bsdf '" + e.type + "' is not supported; using its mean colour");
    return store_.mean(c.texture);
  }

  // An index of refraction: a number or one of Mitsuba's names ("bk7", "air", ...).
  float get_ior(const Element& e, const std::string& name, float fallback) {
    const Property* p = find(e, name);
    if (!p) return fallback;
    if (p->kind == Property::Kind::Number || p->kind == Property::Kind::Integer) {
      if (!(p->number > 0.0)) fail(p->node, "'" + name + "' must be positive");
      return float(p->number);
    }
    if (p->kind != Property::Kind::String) wrong_type(*p, name, "<float> or <string>");
    std::optional<float> ior = ior_by_name(p->text);
    if (!ior) fail(p->node, "unknown index of refraction '" + p->text + "'");
    return *ior;
  }

  // Microfacet roughness (alpha, or alpha_u and alpha_v) and distribution into m.
  void microfacet(const Element& e, Material& m, bool isotropic) {
    const Property* a = find(e, "alpha");
    const Property* au = find(e, "alpha_u");
    const Property* av = find(e, "alpha_v");
    if (a && (au || av)) fail(a->node, "give either 'alpha' or 'alpha_u' and 'alpha_v'");
    if ((au != nullptr) != (av != nullptr)) fail((au ? au : av)->node, "give both 'alpha_u' and 'alpha_v'");
    auto value = [&](const Property* p, const char* name) -> float {
      if (!p) return 0.1f;
      if (p->kind == Property::Kind::Object) {
        warn(p->node, "bsdf:" + e.type + ":" + name + ":texture",
             std::string("a texture for '") + name + "' is not supported; using 0.1");
        return 0.1f;
      }
      return float(get_float(e, name, 0.1));
    };
    // A texture for 'alpha' (Mitsuba 3) where the roughness is read per hit
    // (kernels/surface.cl): roughconductor, roughdielectric, and roughplastic
    // through its table of rows by roughness (finish_plastic).
    const bool texturable = m.type == PSF_MATERIAL_ROUGH_CONDUCTOR || m.type == PSF_MATERIAL_ROUGH_DIELECTRIC ||
                            m.type == PSF_MATERIAL_ROUGH_PLASTIC;
    if (a && a->kind == Property::Kind::Object && texturable)
      m.tex_alpha = texture(a->object, TextureUse::Height, "using 0.1");
    // Textures for alpha_u or alpha_v (anisotropic BSDFs): one texture whose x
    // and y channels hold them (PSF_MATFLAG_ALPHA_UV), a constant in the channel
    // of one that is a value.
    const bool tex_u = au && au->kind == Property::Kind::Object, tex_v = av && av->kind == Property::Kind::Object;
    if ((tex_u || tex_v) && texturable && !isotropic) {
      auto axis = [&](const Property* p, bool tex, const char* name, float& constant) {
        constant = 0.1f;
        if (tex) return texture(p->object, TextureUse::Height, "using 0.1");
        constant = value(p, name);
        if (constant < 0.0f) fail(p->node, "the roughness must not be negative");
        return PSF_NO_TEXTURE;
      };
      float cu, cv;
      const uint32_t tu = axis(au, tex_u, "alpha_u", cu), tv = axis(av, tex_v, "alpha_v", cv);
      if (tu != PSF_NO_TEXTURE || tv != PSF_NO_TEXTURE) {
        std::optional<uint32_t> both = store_.combine_xy(tu, cu, tv, cv);
        if (both) {
          m.tex_alpha = *both;
          m.flags |= PSF_MATFLAG_ALPHA_UV;
        } else {
          warn(au->node, "bsdf:" + e.type + ":alpha_uv",
               "textures for 'alpha_u' and 'alpha_v' of different sizes, filtering or uv transforms are not "
               "supported; using alpha_u's for both");
          m.tex_alpha = tu;
        }
      }
    }
    float alpha_u, alpha_v;
    if (m.tex_alpha != PSF_NO_TEXTURE) {  // the texture's mean, for what reads alpha before a hit
      const glm::vec3 mean = store_.mean(m.tex_alpha);
      alpha_u = mean.x;
      alpha_v = m.flags & PSF_MATFLAG_ALPHA_UV ? mean.y : mean.x;
    } else if ((tex_u || tex_v) && texturable && !isotropic) {  // the textures' files were missing (warned)
      alpha_u = tex_u ? 0.1f : value(au, "alpha_u");
      alpha_v = tex_v ? 0.1f : value(av, "alpha_v");
    } else {
      alpha_u = a ? value(a, "alpha") : value(au, "alpha_u");
      alpha_v = a ? alpha_u : value(av, "alpha_v");
      if (alpha_u < 0.0f || alpha_v < 0.0f) fail((a ? a : au)->node, "the roughness must not be negative");
    }
    if (isotropic && alpha_u != alpha_v) {
      warn(au->node, "bsdf:" + e.type + ":anisotropic",
           "bsdf '" + e.type + "' is isotropic; using alpha = sqrt(alpha_u alpha_v)");
      alpha_u = alpha_v = std::sqrt(alpha_u * alpha_v);
    }
    m.alpha_u = std::max(alpha_u, 1e-4f);  // Mitsuba's lower bound
    m.alpha_v = std::max(alpha_v, 1e-4f);
    std::string distribution = lower(get_string(e, "distribution").value_or("beckmann"));
    if (distribution == "beckmann") {
      m.flags |= PSF_MATFLAG_BECKMANN;
    } else if (distribution == "phong" || distribution == "as") {
      warn(find(e, "distribution")->node, "bsdf:" + e.type + ":" + distribution,
           "distribution '" + distribution + "' is not supported; using beckmann");
      m.flags |= PSF_MATFLAG_BECKMANN;
    } else if (distribution != "ggx") {
      fail(find(e, "distribution")->node, "unknown distribution '" + distribution + "' (beckmann or ggx)");
    }
  }

  Bsdf bsdf_diffuse(const Element& e) {
    check_properties(e, {"reflectance"});
    ColorParam c = color_param(e, "reflectance", glm::vec3(0.5f));
    Bsdf b;
    b.m = diffuse_material(c.value);
    b.m.tex_color = c.texture;
    return b;
  }

  // conductor and roughconductor: eta, k from `material` (Mitsuba 3 default
  // "none", a perfect mirror; 0.5 default "Cu") or given (eta 0, k 1 when one
  // is missing, as Mitsuba 3), divided by ext_eta; specular_reflectance.
  Bsdf bsdf_conductor(const Element& e) {
    bool rough = e.type == "roughconductor";
    if (rough)
      check_properties(e, {"material", "eta", "k", "ext_eta", "specular_reflectance", "alpha", "alpha_u", "alpha_v",
                           "distribution", "sample_visible"});
    else
      check_properties(e, {"material", "eta", "k", "ext_eta", "specular_reflectance"});
    Bsdf b;
    Material& m = b.m;
    m = Material{};
    m.type = rough ? PSF_MATERIAL_ROUGH_CONDUCTOR : PSF_MATERIAL_CONDUCTOR;
    ColorParam spec = color_param(e, "specular_reflectance", glm::vec3(1.0f));
    m.specular = {{spec.value.x, spec.value.y, spec.value.z, 0}};
    m.tex_color = spec.texture;
    std::optional<glm::vec3> eta = get_color(e, "eta", ColorUse::Unbounded);
    std::optional<glm::vec3> k = get_color(e, "k", ColorUse::Unbounded);
    glm::vec3 eta_v(0.0f), k_v(1.0f);  // material "none"
    std::optional<std::string> metal = get_string(e, "material");
    std::string name = metal.value_or(version_major_ >= 2 || eta || k ? "none" : "Cu");
    if (name != "none" && !conductor_by_name(name, eta_v, k_v))
      fail(find(e, "material") ? find(e, "material")->node : e.node, "unknown conductor material '" + name + "'");
    if (eta) eta_v = *eta;
    if (k) k_v = *k;
    float ext = get_ior(e, "ext_eta", 1.000277f);
    eta_v /= ext;
    k_v /= ext;
    m.eta = {{eta_v.x, eta_v.y, eta_v.z, 0}};
    m.k = {{k_v.x, k_v.y, k_v.z, 0}};
    if (rough) microfacet(e, m, false);
    return b;
  }

  // plastic and roughplastic: int_ior (polypropylene) / ext_ior (air),
  // diffuse_reflectance (0.5, texture), specular_reflectance (1), nonlinear.
  Bsdf bsdf_plastic(const Element& e) {
    bool rough = e.type == "roughplastic";
    if (rough)
      check_properties(e, {"int_ior", "ext_ior", "diffuse_reflectance", "specular_reflectance", "nonlinear", "alpha",
                           "alpha_u", "alpha_v", "distribution", "sample_visible"});
    else
      check_properties(e, {"int_ior", "ext_ior", "diffuse_reflectance", "specular_reflectance", "nonlinear"});
    Bsdf b;
    Material& m = b.m;
    m = Material{};
    m.type = rough ? PSF_MATERIAL_ROUGH_PLASTIC : PSF_MATERIAL_PLASTIC;
    float eta = get_ior(e, "int_ior", 1.49f) / get_ior(e, "ext_ior", 1.000277f);
    if (rough && eta == 1.0f) fail(e.node, "the interior and exterior indices of refraction must differ");
    ColorParam d = color_param(e, "diffuse_reflectance", glm::vec3(0.5f));
    glm::vec3 s = constant_color(e, "specular_reflectance", glm::vec3(1.0f));
    m.albedo = {{d.value.x, d.value.y, d.value.z, 0}};
    m.tex_color = d.texture;
    m.specular = {{s.x, s.y, s.z, 0}};
    m.eta = {{eta, 0, 0, 0}};
    if (get_bool(e, "nonlinear", false)) m.flags |= PSF_MATFLAG_NONLINEAR;
    if (rough) microfacet(e, m, true);
    glm::vec3 dm = d.texture != PSF_NO_TEXTURE ? store_.mean(d.texture) : d.value;
    finish_plastic(m, (dm.x + dm.y + dm.z) / 3.0f, (s.x + s.y + s.z) / 3.0f, store_);
    return b;
  }

  // pplastic (Mitsuba 3's polarized plastic, as its RGB variants render it):
  // int_ior (polypropylene) / ext_ior (air), which must differ;
  // diffuse_reflectance (0.5, texture), specular_reflectance (1), a microfacet
  // distribution (Beckmann by default, alpha 0.1). The lobe choice is Mitsuba's
  // constant mean(specular) / (mean(diffuse) + mean(specular)).
  Bsdf bsdf_pplastic(const Element& e) {
    check_properties(e, {"int_ior", "ext_ior", "diffuse_reflectance", "specular_reflectance", "alpha", "alpha_u",
                         "alpha_v", "distribution", "sample_visible"});
    Bsdf b;
    Material& m = b.m;
    m = Material{};
    m.type = PSF_MATERIAL_PPLASTIC;
    float int_ior = get_ior(e, "int_ior", 1.49f), ext_ior = get_ior(e, "ext_ior", 1.000277f);
    if (!(int_ior > 0.0f) || !(ext_ior > 0.0f) || int_ior == ext_ior)
      fail(e.node, "the interior and exterior indices of refraction must be positive and differ");
    ColorParam d = color_param(e, "diffuse_reflectance", glm::vec3(0.5f));
    glm::vec3 s = constant_color(e, "specular_reflectance", glm::vec3(1.0f));
    m.albedo = {{d.value.x, d.value.y, d.value.z, 0}};
    m.tex_color = d.texture;
    m.specular = {{s.x, s.y, s.z, 0}};
    m.eta = {{int_ior / ext_ior, 0, 0, 0}};
    microfacet(e, m, false);
    glm::vec3 dm = d.texture != PSF_NO_TEXTURE ? store_.mean(d.texture) : d.value;
    finish_plastic(m, (dm.x + dm.y + dm.z) / 3.0f, (s.x + s.y + s.z) / 3.0f, store_);
    return b;
  }

  // dielectric, roughdielectric, thindielectric: int_ior (bk7) / ext_ior (air),
  // specular_reflectance and specular_transmittance (1), either of them a
  // texture read per hit (Material.tex_color; both: the reflectance's mean, with
  // a warning).
  Bsdf bsdf_dielectric(const Element& e) {
    bool rough = e.type == "roughdielectric";
    if (rough)
      check_properties(e, {"int_ior", "ext_ior", "specular_reflectance", "specular_transmittance", "alpha", "alpha_u",
                           "alpha_v", "distribution", "sample_visible"});
    else
      check_properties(e, {"int_ior", "ext_ior", "specular_reflectance", "specular_transmittance"});
    Bsdf b;
    Material& m = b.m;
    m = Material{};
    m.type = rough ? PSF_MATERIAL_ROUGH_DIELECTRIC
                   : e.type == "thindielectric" ? PSF_MATERIAL_THIN_DIELECTRIC : PSF_MATERIAL_DIELECTRIC;
    float eta = get_ior(e, "int_ior", 1.5046f) / get_ior(e, "ext_ior", 1.000277f);
    // As Mitsuba: equal indices are an error (a rough one's half-vector would be 0, and the surface nothing).
    if (eta == 1.0f) fail(e.node, "the interior and exterior indices of refraction must differ");
    ColorParam rp = color_param(e, "specular_reflectance", glm::vec3(1.0f), false);
    ColorParam tp = color_param(e, "specular_transmittance", glm::vec3(1.0f), false);
    glm::vec3 r = rp.value, t = tp.value;
    if (tp.texture != PSF_NO_TEXTURE) {
      m.tex_color = tp.texture;
      m.flags |= PSF_MATFLAG_TEX_TRANSMITTANCE;
      t = store_.mean(tp.texture);  // the filtering-vertex rule's colour; hits read the texture
      if (rp.texture != PSF_NO_TEXTURE) r = constant_color(e, "specular_reflectance", glm::vec3(1.0f));
    } else if (rp.texture != PSF_NO_TEXTURE) {
      m.tex_color = rp.texture;
      r = store_.mean(rp.texture);
    }
    m.eta = {{eta, 1.0f / (eta * eta), 0, 0}};
    m.specular = {{r.x, r.y, r.z, 0}};
    m.transmittance = {{t.x, t.y, t.z, 0}};
    if (rough) microfacet(e, m, false);
    return b;
  }

  // twosided: the nested BSDF on both sides, or with two nested BSDFs the first
  // on the front and the second on the back (Material.blend with
  // PSF_MATFLAG_BACK_PARTNER, chosen by the side of the hit).
  Bsdf bsdf_twosided(const Element& e) {
    check_properties(e, {});
    std::vector<pugi::xml_node> nested = objects(e, "bsdf");
    Bsdf b = bsdf(nested_bsdf(e));
    auto transmissive = [](const Material& m) {
      return m.type == PSF_MATERIAL_DIELECTRIC || m.type == PSF_MATERIAL_ROUGH_DIELECTRIC ||
             m.type == PSF_MATERIAL_THIN_DIELECTRIC || (m.type == PSF_MATERIAL_PRINCIPLED && m.specular.s[1] > 0.0f) ||
             (m.type == PSF_MATERIAL_PRINCIPLED_THIN && (m.specular.s[1] > 0.0f || m.specular.s[0] > 0.0f));
    };
    if (transmissive(b.m))
      warn(e.node, "bsdf:twosided-transmission", "twosided around a transmissive BSDF has no effect");
    if (nested.size() > 2) fail(nested[2], "bsdf 'twosided' takes one or two nested BSDFs");
    if (nested.size() > 1) {
      Bsdf back = bsdf(nested[1]);
      if (transmissive(back.m))
        warn(e.node, "bsdf:twosided-transmission", "twosided around a transmissive BSDF has no effect");
      if (b.blend || back.blend) {
        warn(e.node, "bsdf:twosided2-blend", "twosided with separate front and back BSDFs, one of them a blendbsdf, "
                                             "is not supported; the front one is used on both sides");
      } else {
        back.two_sided = true;
        b.blend = std::make_shared<const Bsdf>(back);
        b.m.flags |= PSF_MATFLAG_BACK_PARTNER;
      }
    }
    for_each_part(b, [](Bsdf& x) { x.two_sided = true; });
    b.name.clear();
    return b;
  }

  // blendbsdf: the first nested BSDF, or with probability `weight` (a float or a
  // texture's luminance, default 0.5) the second, chosen per shading point
  // (Material.blend, kernels/surface.cl); in expectation Mitsuba's
  // (1 - weight) f_0 + weight f_1. The second may be a blend of two itself (a
  // chain of three); a blend as the first BSDF, or deeper, keeps its first BSDF.
  Bsdf bsdf_blend(const Element& e) {
    check_properties(e, {"weight"});
    std::vector<pugi::xml_node> nested = objects(e, "bsdf");
    if (nested.size() != 2) fail(e.node, "<bsdf type=\"blendbsdf\"> takes two nested BSDFs, not " +
                                             std::to_string(nested.size()));
    Bsdf b = bsdf(nested[0]);
    Bsdf partner = bsdf(nested[1]);
    // A blend as the first BSDF and none as the second: the same mixture with
    // the two swapped and the weight w replaced by 1 - w, which makes a chain
    // (second, first's first, first's second). Two blends would need a tree.
    const bool blended = [](const Bsdf& x) { return x.blend || (x.m.flags & PSF_MATFLAG_BACK_PARTNER); }(partner);
    const bool swapped = b.blend && !(b.m.flags & PSF_MATFLAG_BACK_PARTNER) && !b.blend->blend && !blended;
    if (swapped) std::swap(b, partner);
    auto unblend = [&](Bsdf& inner) {
      warn(e.node, "bsdf:blendbsdf-nested",
           "blendbsdfs as both BSDFs of a blendbsdf, nested deeper than a chain of three, or a twosided with a back "
           "BSDF inside a blendbsdf are not supported; the inner one's first BSDF is used");
      inner.blend.reset();
      inner.m.blend = 0;
      inner.m.tex_blend = PSF_NO_TEXTURE;
      inner.m.flags &= ~PSF_MATFLAG_BACK_PARTNER;
    };
    if (b.blend) unblend(b);
    if (partner.m.flags & PSF_MATFLAG_BACK_PARTNER) unblend(partner);  // a twosided's back BSDF: its front is used
    if (partner.blend && partner.blend->blend) {
      auto second = std::make_shared<Bsdf>(*partner.blend);
      unblend(*second);
      partner.blend = second;
    }
    const Property* p = find(e, "weight");
    b.m.blend_weight = 0.5f;
    if (p && p->kind == Property::Kind::Object && std::string(p->object.name()) == "texture") {
      b.m.blend_weight = 1.0f;
      b.m.tex_blend = texture(p->object, TextureUse::Height, "using 0.5 for 'weight'");
      if (b.m.tex_blend == PSF_NO_TEXTURE) b.m.blend_weight = 0.5f;
      else if (swapped) b.m.tex_blend = store_.complement_x(b.m.tex_blend);
    } else if (p) {
      b.m.blend_weight = std::clamp(float(get_float(e, "weight", 0.5)), 0.0f, 1.0f);
      if (swapped) b.m.blend_weight = 1.0f - b.m.blend_weight;
    }
    b.blend = std::make_shared<const Bsdf>(partner);
    b.name.clear();
    return b;
  }

  // principled: Mitsuba 3's Disney-style BSDF (kernels/bsdf.cl), with its
  // parameters as Mitsuba 3.6 reads them: `eta`, or `specular` (default 0.5)
  // standing for eta = 2 / (1 - sqrt(0.08 specular)) - 1 (1.5 for 0.5); where
  // spec_trans is given and not 0, an eta of 1 becomes 1.001 and a specular of
  // 0 becomes 0.001 (Mitsuba: "not plausible for transmission"). base_color,
  // roughness and metallic may be textures; the others' textures are replaced
  // by their mean, one warning each.
  // The base colour of the principled BSDFs (a colour or a texture).
  void principled_base(const Element& e, Material& m) {
    ColorParam base = color_param(e, "base_color", glm::vec3(0.5f));
    const glm::vec3 color = glm::max(base.value, glm::vec3(0.0f));
    m.albedo = {{color.x, color.y, color.z, 0}};
    m.tex_color = base.texture;
  }

  // A parameter of the principled BSDFs: a float in [0, hi] (Mitsuba's stated
  // range: others are clamped into it, with a warning), or a texture: into *tex
  // where the kernels read one, else its mean with a warning.
  float principled_scalar(const Element& e, const char* name, float fallback, uint32_t* tex, float hi = 1.0f) {
    const Property* p = find(e, name);
    const std::string key = "bsdf:" + e.type + ":" + name, of = std::string("'") + name + "' of bsdf '" + e.type + "'";
    if (!p || p->kind != Property::Kind::Object) {
      const float v = float(get_float(e, name, fallback));
      if (v < 0.0f || v > hi)
        warn(p->node, key + ":range", of + " is " + fmt(v) + ", outside [0, " + fmt(hi) + "]; clamped");
      return std::clamp(v, 0.0f, hi);
    }
    uint32_t t = texture(p->object, TextureUse::Height, "using " + fmt(glm::vec3(fallback)) + " for '" + name + "'");
    if (t == PSF_NO_TEXTURE) return fallback;
    if (tex) {
      *tex = t;
      return std::clamp(store_.mean(t).x, 0.0f, hi);  // the filtering-vertex rule's value; hits read the texture
    }
    warn(p->node, key + ":texture", "a texture for " + of + " is not supported; using its mean");
    return std::clamp(store_.mean(t).x, 0.0f, hi);
  }

  // A sampling rate of the principled BSDFs (default 1, at least 0).
  float principled_rate(const Element& e, const char* name) {
    float r = float(get_float(e, name, 1.0));
    if (!(r >= 0.0f)) fail(find(e, name)->node, std::string("'") + name + "' must be at least 0");
    return r;
  }

  Bsdf bsdf_principled(const Element& e) {
    check_properties(e, {"base_color", "roughness", "anisotropic", "metallic", "spec_trans", "eta", "specular",
                         "spec_tint", "sheen", "sheen_tint", "flatness", "clearcoat", "clearcoat_gloss",
                         "diffuse_reflectance_sampling_rate", "main_specular_sampling_rate",
                         "clearcoat_sampling_rate"});
    if (find(e, "eta") && find(e, "specular"))
      fail(find(e, "specular")->node, "bsdf 'principled' takes 'eta' or 'specular', not both");
    Bsdf b;
    b.m = Material{};
    b.m.type = PSF_MATERIAL_PRINCIPLED;
    principled_base(e, b.m);
    auto scalar = [&](const char* name, float fallback, uint32_t* tex) {
      return principled_scalar(e, name, fallback, tex);
    };
    const float roughness = scalar("roughness", 0.5f, &b.m.tex_alpha);
    const float anisotropic = scalar("anisotropic", 0.0f, nullptr);
    const float metallic = scalar("metallic", 0.0f, &b.m.tex_table);
    const float spec_trans = scalar("spec_trans", 0.0f, nullptr);
    const float spec_tint = scalar("spec_tint", 0.0f, nullptr);
    const float sheen = scalar("sheen", 0.0f, nullptr);
    const float sheen_tint = scalar("sheen_tint", 0.0f, nullptr);
    const float flatness = scalar("flatness", 0.0f, nullptr);
    const float clearcoat = scalar("clearcoat", 0.0f, nullptr);
    const float clearcoat_gloss = scalar("clearcoat_gloss", 0.0f, nullptr);
    const Property* st = find(e, "spec_trans");
    const bool has_spec_trans = st && (st->kind == Property::Kind::Object || spec_trans != 0.0f);
    float eta;
    if (find(e, "eta")) {
      eta = get_ior(e, "eta", 1.5f);
      if (has_spec_trans && eta == 1.0f) eta = 1.001f;
    } else {
      // Any specular in [0, 12.5) stands for an eta (1 at 0, 1.5 at 0.5, 2.33 at 2).
      float specular = float(get_float(e, "specular", 0.5));
      if (!(specular >= 0.0f && specular < 12.5f))
        fail(find(e, "specular")->node, "'specular' of bsdf 'principled' must lie in [0, 12.5) (" + fmt(specular) + ")");
      if (has_spec_trans && specular == 0.0f) specular = 1e-3f;
      eta = 2.0f / (1.0f - std::sqrt(0.08f * specular)) - 1.0f;
    }
    const float main_rate = principled_rate(e, "main_specular_sampling_rate"),
                clearcoat_rate = principled_rate(e, "clearcoat_sampling_rate"),
                diffuse_rate = principled_rate(e, "diffuse_reflectance_sampling_rate");
    // GGX alpha = roughness^2 stretched by sqrt(1 - 0.9 anisotropic), at least 0.001
    // (surface.cl principled_alphas does the same with a roughness texture).
    const float alpha = roughness * roughness, aspect = std::sqrt(1.0f - 0.9f * anisotropic);
    b.m.alpha_u = std::max(0.001f, alpha / aspect);
    b.m.alpha_v = std::max(0.001f, alpha * aspect);
    b.m.eta = {{eta, 1.0f / (eta * eta), roughness, anisotropic}};
    b.m.specular = {{metallic, spec_trans, spec_tint, sheen}};
    b.m.transmittance = {{sheen_tint, flatness, clearcoat, clearcoat_gloss}};
    b.m.k = {{main_rate, clearcoat_rate, diffuse_rate, 0}};
    return b;
  }

  // principledthin: Mitsuba 3's thin principled BSDF (kernels/bsdf.cl), with its
  // parameters as Mitsuba 3.6 reads them: `eta` (default 1.5) the sheet's relative
  // IOR, which shapes its Fresnel term and widens the specular transmission
  // (roughness times 0.65 eta - 0.35); `diff_trans` in [0, 2] (2: all diffuse
  // light transmitted). base_color and roughness may be textures; the others'
  // textures are replaced by their mean, one warning each.
  Bsdf bsdf_principledthin(const Element& e) {
    check_properties(e, {"base_color", "roughness", "anisotropic", "spec_trans", "eta", "spec_tint", "sheen",
                         "sheen_tint", "flatness", "diff_trans", "diffuse_reflectance_sampling_rate",
                         "specular_reflectance_sampling_rate", "specular_transmittance_sampling_rate",
                         "diffuse_transmittance_sampling_rate"});
    Bsdf b;
    b.m = Material{};
    b.m.type = PSF_MATERIAL_PRINCIPLED_THIN;
    principled_base(e, b.m);
    const float roughness = principled_scalar(e, "roughness", 0.5f, &b.m.tex_alpha);
    const float anisotropic = principled_scalar(e, "anisotropic", 0.0f, nullptr);
    const float spec_trans = principled_scalar(e, "spec_trans", 0.0f, nullptr);
    const float spec_tint = principled_scalar(e, "spec_tint", 0.0f, nullptr);
    const float sheen = principled_scalar(e, "sheen", 0.0f, nullptr);
    const float sheen_tint = principled_scalar(e, "sheen_tint", 0.0f, nullptr);
    const float flatness = principled_scalar(e, "flatness", 0.0f, nullptr);
    const float diff_trans = principled_scalar(e, "diff_trans", 0.0f, nullptr, 2.0f);
    const Property* ep = find(e, "eta");
    float eta = 1.5f;
    if (ep && ep->kind == Property::Kind::Object) {
      uint32_t t = texture(ep->object, TextureUse::Height, "using 1.5 for 'eta'");
      if (t != PSF_NO_TEXTURE) {
        warn(ep->node, "bsdf:principledthin:eta:texture",
             "a texture for 'eta' of bsdf 'principledthin' is not supported; using its mean");
        eta = store_.mean(t).x;
      }
    } else {
      eta = float(get_float(e, "eta", 1.5));
    }
    if (!(eta > 0.0f)) fail(ep->node, "'eta' of bsdf 'principledthin' must be positive (" + fmt(eta) + ")");
    // GGX alphas as principled's (surface.cl principled_alphas, also with a roughness texture).
    const float aspect = std::sqrt(1.0f - 0.9f * anisotropic), a = roughness * roughness;
    const float rt = (0.65f * eta - 0.35f) * roughness, at = rt * rt;
    b.m.alpha_u = std::max(0.001f, a / aspect);
    b.m.alpha_v = std::max(0.001f, a * aspect);
    b.m.eta = {{eta, 1.0f / (eta * eta), roughness, anisotropic}};
    b.m.specular = {{0.5f * diff_trans, spec_trans, spec_tint, sheen}};
    b.m.transmittance = {{sheen_tint, flatness, std::max(0.001f, at / aspect), std::max(0.001f, at * aspect)}};
    b.m.k = {{principled_rate(e, "specular_reflectance_sampling_rate"),
              principled_rate(e, "specular_transmittance_sampling_rate"),
              principled_rate(e, "diffuse_reflectance_sampling_rate"),
              principled_rate(e, "diffuse_transmittance_sampling_rate")}};
    return b;
  }

  // bumpmap: the nested BSDF with its shading normal perturbed by the gradient of
  // a height texture (luminance) times `scale` (Mitsuba 3; Mitsuba 0.5 scales
  // with a `scale` texture around the bitmap).
  Bsdf bsdf_bumpmap(const Element& e) {
    // The height texture may have any name (Mitsuba's own example calls it "arbitrary").
    for (const auto& [name, p] : e.props)
      if (name != "scale" && !(p.kind == Property::Kind::Object && std::string(p.object.name()) == "texture"))
        warn(p.node, "bsdf:bumpmap:" + name, "property '" + name + "' of bsdf 'bumpmap' is not supported; ignored");
    Bsdf b = bsdf(nested_bsdf(e));
    std::vector<pugi::xml_node> textures = objects(e, "texture");
    if (textures.empty()) fail(e.node, "<bsdf type=\"bumpmap\"> needs a height texture");
    pugi::xml_node tex = textures[0];
    float scale = float(get_float(e, "scale", 1.0));
    if (attr(tex, "type").value_or("") == "scale") {
      Element s = parse_element(tex);
      scale *= float(get_float(s, "scale", 1.0));
      std::vector<pugi::xml_node> inner = objects(s, "texture");
      if (inner.empty()) fail(tex, "<texture type=\"scale\"> needs a nested texture");
      tex = inner[0];
    }
    if (b.m.tex_bump != PSF_NO_TEXTURE)
      warn(e.node, "bsdf:bumpmap-nested", "nested bump maps are not supported; the outer one is used");
    uint32_t index = texture(tex, TextureUse::Height, "no bump mapping");
    if (index != PSF_NO_TEXTURE)
      for_each_part(b, [&](Bsdf& x) {
        x.m.tex_bump = index;
        x.m.bump_scale = scale;
        x.m.flags &= ~PSF_MATFLAG_NORMALMAP;
      });
    b.name.clear();
    return b;
  }

  // normalmap (Mitsuba 3): the nested BSDF with its shading normal read from a
  // tangent-space normal map, rgb = (n + 1) / 2 in the frame (t, n x t, n), t
  // along dp/du (kernels/surface.cl). Mitsuba asks for a bitmap with raw="true";
  // the texture is decoded as the file says, as Mitsuba does.
  Bsdf bsdf_normalmap(const Element& e) {
    check_properties(e, {"normalmap"});
    Bsdf b = bsdf(nested_bsdf(e));
    const Property* p = find(e, "normalmap");
    if (!p || p->kind != Property::Kind::Object || std::string(p->object.name()) != "texture")
      fail(e.node, "<bsdf type=\"normalmap\"> needs a texture named 'normalmap'");
    if (b.m.tex_bump != PSF_NO_TEXTURE)
      warn(e.node, "bsdf:bumpmap-nested", "nested bump or normal maps are not supported; the outer one is used");
    uint32_t index = texture(p->object, TextureUse::Color, "no normal mapping");
    if (index != PSF_NO_TEXTURE)
      for_each_part(b, [&](Bsdf& x) {
        x.m.tex_bump = index;
        x.m.bump_scale = 1.0f;
        x.m.flags |= PSF_MATFLAG_NORMALMAP;
      });
    b.name.clear();
    return b;
  }

  // mask: the nested BSDF cut out where the opacity (a constant or a texture:
  // its alpha channel, else luminance; default 0.5) is low: hits are kept with
  // probability opacity during ray traversal (kernels/raycast.cl).
  Bsdf bsdf_mask(const Element& e) {
    check_properties(e, {"opacity"});
    Bsdf b = bsdf(nested_bsdf(e));
    const Property* p = find(e, "opacity");
    float opacity = 0.5f;
    uint32_t index = PSF_NO_TEXTURE;
    if (p && p->kind == Property::Kind::Object && std::string(p->object.name()) == "texture") {
      opacity = 1.0f;
      // Mitsuba 3 reads a bitmap's RGB only: the opacity is their luminance, and
      // an alpha channel is ignored. For Mitsuba 0.5 files (Bitterli's scenes, whose
      // leaves are RGBA images cut out by their alpha, as Tungsten renders them)
      // the alpha channel where the image has one.
      index = texture(p->object, version_major_ >= 2 ? TextureUse::Height : TextureUse::Opacity, "opaque");
    } else if (p) {
      glm::vec3 c = get_color(e, "opacity", ColorUse::Reflectance).value_or(glm::vec3(0.5f));
      if (c.x != c.y || c.y != c.z)
        warn(p->node, "bsdf:mask:rgb", "a coloured opacity is not supported; using its mean");
      opacity = (c.x + c.y + c.z) / 3.0f;
    }
    if (b.m.flags & PSF_MATFLAG_MASKED)
      warn(e.node, "bsdf:mask-nested", "nested masks are not supported; the outer one is used");
    b.m.opacity = std::clamp(opacity, 0.0f, 1.0f);
    b.m.tex_opacity = index;
    if (b.m.opacity < 1.0f || index != PSF_NO_TEXTURE) b.m.flags |= PSF_MATFLAG_MASKED;
    else b.m.flags &= ~PSF_MATFLAG_MASKED;
    b.name.clear();
    return b;
  }

  // null: a surface rays pass through (Mitsuba's boundaries of media, which psf
  // does not render, and helper geometry): a black material of opacity 0, never
  // hit by ray casting (raycast.cl's alpha test).
  Bsdf bsdf_null(const Element& e) {
    check_properties(e, {});
    Bsdf b;
    b.m = diffuse_material(glm::vec3(0.0f));
    b.m.flags |= PSF_MATFLAG_MASKED;
    b.m.opacity = 0.0f;
    b.null = true;
    return b;
  }

  // A diffuse stand-in for a BSDF type the renderer does not support yet:
  // wrappers (coating, ...) average their nested BSDFs' colour terms;
  // otherwise the first of reflectance, diffuse_reflectance,
  // specular_reflectance, else 0.5 grey.
  Bsdf approximate_bsdf(const Element& e) {
    Bsdf b;
    glm::vec3 albedo(0.5f);
    std::vector<pugi::xml_node> nested = objects(e, "bsdf");
    if (!nested.empty()) {
      albedo = glm::vec3(0.0f);
      for (pugi::xml_node n : nested) {
        const Bsdf& inner = bsdf(n);
        const Material& im = inner.m;
        bool coloured = im.type == PSF_MATERIAL_DIFFUSE || im.type == PSF_MATERIAL_PLASTIC ||
                        im.type == PSF_MATERIAL_ROUGH_PLASTIC || im.type == PSF_MATERIAL_PPLASTIC ||
                        im.type == PSF_MATERIAL_PRINCIPLED || im.type == PSF_MATERIAL_PRINCIPLED_THIN;
        const psf_float4& c = coloured ? im.albedo : im.specular;
        albedo += glm::vec3(c.s[0], c.s[1], c.s[2]) / float(nested.size());
        b.two_sided = b.two_sided || inner.two_sided;
      }
    } else {
      std::optional<glm::vec3> c;
      for (const char* name : {"reflectance", "diffuse_reflectance", "specular_reflectance"}) {
        const Property* p = find(e, name);
        if (!c && p && p->kind != Property::Kind::Object) c = get_color(e, name, ColorUse::Reflectance);
      }
      albedo = c.value_or(glm::vec3(0.5f));
    }
    b.m = diffuse_material(albedo);
    warn(e.node, "bsdf:" + e.type,
         "bsdf '" + e.type + "' is not supported yet; approximated by diffuse reflectance " + fmt(albedo));
    return b;
  }

  // A <texture> element loaded for `use` (memoised): bitmap or checkerboard.
  // A bitmap whose file is missing (also ignoring case) gives a warning naming
  // `fallback` and PSF_NO_TEXTURE; one that cannot be decoded is an error.
  uint32_t texture(pugi::xml_node node, TextureUse use, const std::string& fallback) {
    auto key = std::make_pair(node.internal_object(), int(use));
    auto cached = textures_.find(key);
    if (cached != textures_.end()) return cached->second;
    Element e = parse_element(node);
    TextureDesc d;
    d.use = use;
    // The uv transform: Mitsuba 3's to_uv, Mitsuba 0.5's uscale, vscale, uoffset, voffset.
    glm::mat4 to_uv = get_transform(e, "to_uv");
    glm::vec2 uv_scale(float(get_float(e, "uscale", 1.0)), float(get_float(e, "vscale", 1.0)));
    glm::vec2 uv_offset(float(get_float(e, "uoffset", 0.0)), float(get_float(e, "voffset", 0.0)));
    d.uv_u = glm::vec3(to_uv[0][0], to_uv[1][0], to_uv[3][0]) * uv_scale.x + glm::vec3(0, 0, uv_offset.x);
    d.uv_v = glm::vec3(to_uv[0][1], to_uv[1][1], to_uv[3][1]) * uv_scale.y + glm::vec3(0, 0, uv_offset.y);
    uint32_t index = PSF_NO_TEXTURE;
    if (e.type == "bitmap") {
      for (const auto& [name, p] : e.props) {
        static const std::set<std::string> known = {"filename", "filter_type", "wrap_mode", "wrap_mode_u",
                                                    "wrap_mode_v", "raw", "gamma", "to_uv", "uscale", "vscale",
                                                    "uoffset", "voffset", "format", "max_anisotropy", "cache"};
        if (!known.count(name))
          warn(p.node, "texture:bitmap:" + name, "property '" + name + "' of texture 'bitmap' is not supported; ignored");
      }
      std::optional<std::string> name = get_string(e, "filename");
      if (!name) fail(node, "<texture type=\"bitmap\"> needs a 'filename'");
      std::string filter = lower(get_string(e, "filter_type").value_or("bilinear"));
      if (filter == "nearest") {
        d.bilinear = false;
      } else if (filter != "bilinear") {  // Mitsuba 0.5's ewa and trilinear filter mip maps
        warn(find(e, "filter_type")->node, "texture:filter:" + filter,
             "filter_type '" + filter + "' is not supported; using bilinear");
      }
      std::string wrap = lower(get_string(e, "wrap_mode").value_or(get_string(e, "wrap_mode_u").value_or("repeat")));
      std::string wrap_v = lower(get_string(e, "wrap_mode_v").value_or(wrap));
      if (wrap_v != wrap)
        warn(node, "texture:wrap", "different wrap modes along u and v are not supported; using '" + wrap + "'");
      if (wrap == "clamp") {
        d.wrap = PSF_TEX_CLAMP;
      } else if (wrap == "mirror") {
        d.wrap = PSF_TEX_MIRROR;
      } else if (wrap != "repeat") {
        warn(node, "texture:wrap:" + wrap, "wrap mode '" + wrap + "' is not supported; using clamp");
        d.wrap = PSF_TEX_CLAMP;
      }
      d.raw = get_bool(e, "raw", false);
      if (find(e, "gamma")) {
        double gamma = get_float(e, "gamma", 0.0);
        if (gamma == 1.0) d.raw = true;
        else if (gamma != -1.0 && gamma != 0.0)  // -1: sRGB, Mitsuba 0.5's default
          warn(find(e, "gamma")->node, "texture:gamma", "gamma other than 1 (linear) or sRGB is not supported");
      }
      std::optional<std::string> file = find_file_nocase(resolve(node, *name));
      if (!file && fs::path(*name).is_relative())  // as resolve(): else relative to the main file
        file = find_file_nocase((fs::path(files_.front()->path).parent_path() / *name).string());
      if (!file) {
        warn(node, "texture:missing", "texture file '" + *name + "' not found; " + fallback);
      } else {
        d.path = *file;
        try {
          index = store_.image(d);
        } catch (const std::exception& ex) {
          fail(node, "texture '" + *file + "': " + ex.what());
        }
      }
    } else if (e.type == "checkerboard") {
      // Mitsuba's checkerboard: color0 where frac(u) and frac(v) are both below or
      // both above 1/2, else color1; a 2 x 2 texture with nearest filtering.
      check_texture_properties(e, {"color0", "color1", "to_uv", "uscale", "vscale", "uoffset", "voffset"});
      glm::vec3 c0 = get_color(e, "color0", ColorUse::Reflectance).value_or(glm::vec3(0.4f));
      glm::vec3 c1 = get_color(e, "color1", ColorUse::Reflectance).value_or(glm::vec3(0.2f));
      d.bilinear = false;
      std::vector<float> px;
      for (const glm::vec3& c : {c0, c1, c1, c0}) {
        float v = use == TextureUse::Color ? 0.0f : 0.212671f * c.x + 0.715160f * c.y + 0.072169f * c.z;
        if (use == TextureUse::Color) px.insert(px.end(), {c.x, c.y, c.z, 1.0f});
        else px.insert(px.end(), {v, v, v, 1.0f});
      }
      index = store_.pixels(d, 2, 2, px);
    } else {
      warn(node, "texture:" + e.type, "texture '" + e.type + "' is not supported yet; " + fallback);
    }
    textures_.emplace(key, index);
    return index;
  }

  void check_texture_properties(const Element& e, std::initializer_list<const char*> known) {
    for (const auto& [name, p] : e.props) {
      bool ok = false;
      for (const char* k : known) ok = ok || name == k;
      if (!ok)
        warn(p.node, "texture:" + e.type + ":" + name,
             "property '" + name + "' of texture '" + e.type + "' is not supported; ignored");
    }
  }

  // --- emitters -------------------------------------------------------------

  // What an emitter on a surface gives its material: a radiance, times a texture
  // if there is one.
  struct SurfaceEmission {
    glm::vec3 radiance{0.0f};
    uint32_t texture = PSF_NO_TEXTURE;
  };
  using EmitterBuilder = SurfaceEmission (MitsubaLoader::*)(const Element&);

  static const std::map<std::string, EmitterBuilder>& emitter_plugins() {
    static const std::map<std::string, EmitterBuilder> plugins = {{"area", &MitsubaLoader::emitter_area}};
    return plugins;
  }

  // The radiance of an emitter on a surface; zero (with a warning) for unsupported types.
  SurfaceEmission emitter(pugi::xml_node node) {
    auto cached = emitters_.find(node.internal_object());
    if (cached != emitters_.end()) return cached->second;
    Element e = parse_element(node);
    auto plugin = emitter_plugins().find(e.type);
    SurfaceEmission radiance;
    if (plugin != emitter_plugins().end()) {
      radiance = (this->*plugin->second)(e);
    } else {
      warn(node, "emitter:" + e.type, "emitter '" + e.type + "' is not supported yet; ignored");
    }
    emitters_.emplace(node.internal_object(), radiance);
    return radiance;
  }

  SurfaceEmission emitter_area(const Element& e) {
    // A radiance texture (Mitsuba 3): evaluated where the light is hit or
    // sampled (Material.tex_emission).
    const Property* p = find(e, "radiance");
    if (p && p->kind == Property::Kind::Object && std::string(p->object.name()) == "texture")
      return {glm::vec3(1.0f), texture(p->object, TextureUse::Color, "emitting 1")};
    return {emitted(e, "radiance"), PSF_NO_TEXTURE};  // negative: an error, as for the other lights
  }

  // --- lights: point, spot, directional, constant, envmap ------------------

  using LightBuilder = LightDesc (MitsubaLoader::*)(const Element&);

  // Emitters that are not surfaces. Property names in snake_case: Mitsuba 0.5's
  // cutoffAngle, beamWidth, toWorld are cutoff_angle, beam_width, to_world.
  static const std::map<std::string, LightBuilder>& light_plugins() {
    static const std::map<std::string, LightBuilder> plugins = {{"point", &MitsubaLoader::light_point},
                                                                {"spot", &MitsubaLoader::light_spot},
                                                                {"directional", &MitsubaLoader::light_directional},
                                                                {"constant", &MitsubaLoader::light_constant},
                                                                {"envmap", &MitsubaLoader::light_envmap}};
    return plugins;
  }

  void load_light(pugi::xml_node node) {
    Element e = parse_element(node);
    LightDesc l = (this->*light_plugins().at(e.type))(e);
    l.source = where(node);
    // Properties that only steer sampling do not change the image and are ignored quietly.
    static const std::map<std::string, std::set<std::string>> known = {
        {"point", {"intensity", "position", "to_world"}},
        {"spot", {"intensity", "cutoff_angle", "beam_width", "to_world"}},
        {"directional", {"irradiance", "direction", "to_world"}},
        {"constant", {"radiance"}},
        {"envmap", {"filename", "scale", "to_world", "cache", "mis_compensation"}}};
    for (const auto& [name, prop] : e.props)
      if (!known.at(e.type).count(name) && name != "sampling_weight")
        warn(prop.node, "emitter:" + e.type + ":" + name,
             "property '" + name + "' of emitter '" + e.type + "' is not supported yet; ignored");
    for (pugi::xml_node o : e.objects)
      if (!e.props.count(attr(o, "name").value_or("")))
        warn(o, std::string(o.name()), "<" + std::string(o.name()) + "> in emitter '" + e.type + "' is not supported yet; ignored");
    if (l.type == LightType::Constant || l.type == LightType::Envmap) {
      if (has_environment_) {
        warn(node, "emitter:" + e.type, "only one environment emitter is supported; this one is ignored");
        return;
      }
      has_environment_ = true;
    }
    scene_.lights.push_back(std::move(l));
  }

  glm::vec3 emitted(const Element& e, const char* name) {
    glm::vec3 c = get_color(e, name, ColorUse::Radiance).value_or(glm::vec3(1.0f));
    if (glm::any(glm::lessThan(c, glm::vec3(0.0f)))) fail(find(e, name)->node, std::string("'") + name + "' is negative");
    return c;
  }

  // A unit direction; `what` names it in the message when it is zero.
  glm::vec3 unit(const glm::vec3& v, pugi::xml_node node, const std::string& what) const {
    float len = glm::length(v);
    if (!(len > 0.0f) || !std::isfinite(len)) fail(node, what + " is zero or not finite");
    return v / len;
  }

  LightDesc light_point(const Element& e) {
    LightDesc l;
    l.type = LightType::Point;
    l.color = emitted(e, "intensity");
    if (find(e, "position") && find(e, "to_world"))
      fail(find(e, "position")->node, "give either 'position' or 'to_world', not both");
    l.position = find(e, "position") ? get_point(e, "position", glm::vec3(0.0f))
                                     : glm::vec3(get_transform(e, "to_world") * glm::vec4(0, 0, 0, 1));
    return l;
  }

  LightDesc light_spot(const Element& e) {
    LightDesc l;
    l.type = LightType::Spot;
    l.color = emitted(e, "intensity");
    glm::mat4 m = get_transform(e, "to_world");
    l.position = glm::vec3(m * glm::vec4(0, 0, 0, 1));
    l.direction = unit(glm::mat3(m) * glm::vec3(0, 0, 1), e.node, "the spot's axis (to_world applied to +z)");
    double cutoff = get_float(e, "cutoff_angle", 20.0);
    double beam = get_float(e, "beam_width", cutoff * 0.75);
    if (!(cutoff > 0.0 && cutoff <= 180.0)) fail(find(e, "cutoff_angle")->node, "cutoff_angle must lie in (0, 180] degrees");
    if (!(beam >= 0.0)) fail(find(e, "beam_width")->node, "beam_width must not be negative");
    l.cutoff_angle = float(glm::radians(cutoff));
    l.beam_width = float(glm::radians(std::min(beam, cutoff)));
    return l;
  }

  LightDesc light_directional(const Element& e) {
    LightDesc l;
    l.type = LightType::Directional;
    l.color = emitted(e, "irradiance");
    if (find(e, "direction") && find(e, "to_world"))
      fail(find(e, "direction")->node, "give either 'direction' or 'to_world', not both");
    if (const Property* d = find(e, "direction")) {
      l.direction = unit(get_point(e, "direction", glm::vec3(0, 0, 1)), d->node, "'direction'");
    } else {
      l.direction = unit(glm::mat3(get_transform(e, "to_world")) * glm::vec3(0, 0, 1), e.node,
                         "the light's direction (to_world applied to +z)");
    }
    return l;
  }

  LightDesc light_constant(const Element& e) {
    LightDesc l;
    l.type = LightType::Constant;
    l.color = emitted(e, "radiance");
    return l;
  }

  LightDesc light_envmap(const Element& e) {
    LightDesc l;
    l.type = LightType::Envmap;
    std::optional<std::string> name = get_string(e, "filename");
    if (!name) fail(e.node, "<emitter type=\"envmap\"> needs a 'filename'");
    std::string path = resolve(e.node, *name);
    EnvImage img;
    try {
      img = read_env_image(path);
    } catch (const SceneError& err) {
      fail(find(e, "filename")->node, err.what());
    }
    if (img.negative)
      warn(e.node, "emitter:envmap:negative",
           std::to_string(img.negative) + " negative values in '" + path + "' were set to 0");
    l.width = img.width;
    l.height = img.height;
    l.texels = std::move(img.rgb);
    double scale = get_float(e, "scale", 1.0);
    if (!(scale >= 0.0)) fail(find(e, "scale")->node, "scale must not be negative");
    l.color = glm::vec3(float(scale));
    // The map's frame: the rotation part of to_world. A uniform scale is divided
    // out; anything else is made orthonormal (Gram-Schmidt) with a warning.
    glm::mat3 m(get_transform(e, "to_world"));
    glm::vec3 x = m[0], y = m[1];
    bool orthogonal = std::abs(glm::dot(glm::normalize(x), glm::normalize(y))) < 1e-4f &&
                      std::abs(glm::dot(glm::normalize(x), glm::normalize(m[2]))) < 1e-4f &&
                      std::abs(glm::dot(glm::normalize(y), glm::normalize(m[2]))) < 1e-4f;
    x = unit(x, e.node, "to_world's x axis");
    y = unit(y - glm::dot(y, x) * x, e.node, "to_world's y axis");
    glm::vec3 z = glm::cross(x, y);
    if (glm::dot(z, m[2]) < 0.0f) z = -z;  // keep a mirroring to_world mirrored
    if (!orthogonal) warn(e.node, "emitter:envmap:to_world", "the envmap's to_world is not a rotation; using its orthonormalised axes");
    l.to_world = glm::mat3(x, y, z);
    return l;
  }

  // --- state ----------------------------------------------------------------

  Scene scene_;                                                        // the result
  std::map<std::string, std::string> params_;                          // $name values: caller's, then <default>s
  std::vector<std::unique_ptr<XmlFile>> files_;                        // main file first, then includes
  static constexpr int kMaxFiles = 4096;  // scene files opened at most (open)
  int files_opened_ = 0;
  static constexpr size_t kMaxNesting = 64;    // BSDFs within BSDFs, merges within merges (their recursion)
  static constexpr size_t kMaxShapes = 1u << 20;  // shapes the scene draws, instances' copies counted
  std::map<const void*, size_t> merge_counts_;    // merge_shapes' counts by merge or shapegroup
  std::unordered_map<const void*, const XmlFile*> roots_;              // document node -> its file
  std::map<std::string, pugi::xml_node> ids_;                          // id -> element
  std::vector<pugi::xml_node> aliases_;                                // <alias> elements, resolved after the ids
  std::set<std::string> warned_;                                       // "file:line plugin" already warned about
  std::map<const void*, Bsdf> bsdfs_;                                  // BSDF element -> built BSDF
  TextureStore store_{scene_};                                         // scene_'s textures and texels
  std::map<std::pair<const void*, int>, uint32_t> textures_;           // (texture element, use) -> texture
  std::set<const void*> in_progress_;                                  // BSDFs and merges being built (cycle check)
  bool vertex_color_ = false;  // the BSDF being built reads the vertex colours (Bsdf::vertex_color)
  std::map<const void*, SurfaceEmission> emitters_;                    // emitter element -> radiance
  std::string integrator_type_;   // the scene's (first, unwrapped) integrator's type; "" without one
  std::optional<Property> camera_medium_;                 // the sensor's medium, if any
  std::map<const void*, uint32_t> medium_materials_;      // medium node -> the first material it is the interior of
  std::map<const void*, std::optional<Medium>> media_;    // medium node -> the medium read from it (medium())
  bool media_rendered_ = false;   // a volumetric integrator: shapes' interior media are rendered
  // (bsdf, emitter, interior medium, exterior medium) -> material
  std::map<std::tuple<const void*, const void*, const void*, const void*>, uint32_t> materials_;
  int version_major_ = 3;                                              // the scene's version="major.minor.patch"
  bool has_sensor_ = false;                                            // a <sensor> was loaded
  bool has_environment_ = false;                                       // an envmap or constant emitter was loaded
};

}  // namespace

Scene load_mitsuba(const std::string& path, const std::vector<std::pair<std::string, std::string>>& params) {
  return MitsubaLoader(params).load(path);
}

}  // namespace psf::detail
