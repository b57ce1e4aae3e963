#include "scene/scene.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "scene/formats.h"
#include "scene/loaders.h"

namespace psf {

namespace detail {

std::string unreadable_input(const std::string& path) {
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);  // through symbolic links
  // A name the system refuses (too long, a loop of symbolic links): its reason.
  if (ec && ec != std::errc::no_such_file_or_directory && ec != std::errc::not_a_directory)
    return "cannot be read: " + ec.message();
  if (ec || !std::filesystem::exists(st) || std::filesystem::is_regular_file(st)) return "";
  return std::filesystem::is_directory(st) ? "is a folder" : "is not a regular file";
}

void require_readable_input(const std::string& path, const std::string& what) {
  if (const std::string why = unreadable_input(path); !why.empty())
    throw SceneError(path, 0, what.empty() ? why : what + " " + why);
}

std::string read_all(std::istream& in) {
  std::ostringstream out;
  if (in.peek() != std::char_traits<char>::eof()) out << in.rdbuf();
  return out.str();
}

}  // namespace detail

SceneError::SceneError(const std::string& file, int line, const std::string& message)
    : std::runtime_error(file + (line > 0 ? ":" + std::to_string(line) : std::string()) + ": " + message),
      file_(file),
      line_(line) {}

void set_film_size(Scene& scene, int width, int height) {
  CameraDesc& c = scene.camera;
  if (c.film_width <= 0) {
    if (width > 0) scene.width = width;
    if (height > 0) scene.height = height;
    return;
  }
  // One axis: the film scaled to `target` pixels, the window [offset, offset + extent) with it.
  auto scale = [](int& film, int& offset, int& extent, int target) {
    if (target <= 0 || target == film) return;
    const double f = double(target) / double(film);
    const int end = std::clamp(int(std::lround((offset + extent) * f)), 1, target);
    offset = std::min(int(std::lround(offset * f)), end - 1);
    extent = end - offset;
    film = target;
  };
  scale(c.film_width, c.crop_x, scene.width, width);
  scale(c.film_height, c.crop_y, scene.height, height);
}

Camera make_camera(const CameraDesc& desc, int image_width, int image_height) {
  // A crop window: the camera spans the whole film, the image a part of it.
  const int width = desc.film_width > 0 ? desc.film_width : image_width;
  const int height = desc.film_height > 0 ? desc.film_height : image_height;
  glm::vec3 forward = glm::normalize(desc.target - desc.origin);
  glm::vec3 right = glm::normalize(glm::cross(forward, desc.up));
  const glm::vec3 down = glm::cross(forward, right);
  if (desc.mirrored) right = -right;  // a reflecting to_world flips the image left-right, not up-down
  float aspect = float(width) / float(height);
  float tan_half = std::tan(glm::radians(desc.fov_degrees) * 0.5f);
  float half_w, half_h;
  const std::string& axis = desc.fov_axis;
  bool along_x = axis == "x" || (axis == "smaller" && width <= height) || (axis == "larger" && width >= height);
  if (desc.orthographic) {  // Mitsuba's orthographic: x in [-1, 1], y in [-1, 1] / aspect, then to_world's scale
    half_w = desc.ortho_scale.x;
    half_h = desc.ortho_scale.y / aspect;
  } else if (axis == "diagonal") {
    float diag = tan_half;
    half_w = diag * aspect / std::sqrt(1 + aspect * aspect);
    half_h = half_w / aspect;
  } else if (along_x) {
    half_w = tan_half;
    half_h = half_w / aspect;
  } else {
    half_h = tan_half;
    half_w = half_h * aspect;
  }
  Camera c{};
  c.origin = {{desc.origin.x, desc.origin.y, desc.origin.z, desc.near_clip}};
  c.forward = {{forward.x, forward.y, forward.z, desc.far_clip}};
  c.right = {{right.x * half_w, right.y * half_w, right.z * half_w, desc.film_width > 0 ? float(desc.crop_x) : 0.0f}};
  c.down = {{down.x * half_h, down.y * half_h, down.z * half_h, desc.film_height > 0 ? float(desc.crop_y) : 0.0f}};
  c.width = uint32_t(width);
  c.height = uint32_t(height);
  c.aperture = desc.orthographic ? 0.0f : std::max(desc.aperture_radius, 0.0f);
  c.focus = desc.focus_distance;
  c.shift_s = desc.orthographic ? 0.0f : desc.principal_point.x;
  c.shift_t = desc.orthographic ? 0.0f : desc.principal_point.y;
  c.orthographic = desc.orthographic ? 1u : 0u;
  if (desc.pixel_filter == "tent") {
    c.filter = PSF_PIXEL_FILTER_TENT;
    c.filter_a = desc.filter_radius;
  } else if (desc.pixel_filter == "gaussian") {
    c.filter = PSF_PIXEL_FILTER_GAUSSIAN;
    c.filter_a = std::sqrt(2.0f) * desc.filter_stddev;
    c.filter_b = float(std::erf(4.0 / std::sqrt(2.0)));  // cut off at 4 stddev, as Mitsuba
  } else {
    c.filter = PSF_PIXEL_FILTER_BOX;
    c.filter_a = 0.5f;
  }
  return c;
}

namespace {

// The loaders grow the geometry and texel arrays geometrically (append_mesh,
// TextureStore::append): the spare capacity goes once the scene is complete.
void trim(Scene& s) {
  s.positions.shrink_to_fit();
  s.triangles.shrink_to_fit();
  s.normals.shrink_to_fit();
  s.uvs.shrink_to_fit();
  s.tangents.shrink_to_fit();
  s.colors.shrink_to_fit();
  s.tri_material.shrink_to_fit();
  s.texels.shrink_to_fit();
}

}  // namespace

Scene load_scene(const std::string& path, const std::vector<std::pair<std::string, std::string>>& params) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (!std::filesystem::exists(path)) throw SceneError(path, 0, "no such file");
  if (std::filesystem::is_directory(path)) throw SceneError(path, 0, "is a folder, not a scene file");
  detail::require_readable_input(path, "");
  Scene scene;
  if (ext == ".xml") {
    scene = detail::load_mitsuba(path, params);
  } else {
    if (ext == ".obj") scene = detail::load_obj_scene(path);
    else if (ext == ".ply") scene = detail::load_ply_scene(path);
    else if (ext == ".gltf" || ext == ".glb") scene = detail::load_gltf_scene(path);
    else throw SceneError(path, 0, "unknown scene format '" + ext + "' (expected .xml, .obj, .ply, .gltf or .glb)");
    if (!params.empty()) scene.warnings.push_back(path + ": scene parameters are ignored for " + ext + " files");
    // A bare mesh file without any emitter is lit by the default sky.
    if (!detail::has_emitters(scene)) scene.lights.push_back(default_sky());
  }
  trim(scene);
  return scene;
}

}  // namespace psf
