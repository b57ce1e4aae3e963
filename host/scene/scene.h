// The renderer's scene: triangles with materials, a camera and the film size.
// Every input format (Mitsuba XML, OBJ, ...) is loaded into this one structure.
#pragma once
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "psf_shared.h"

namespace psf {

// A malformed or unreadable scene: the message names the file and, where known, the line.
class SceneError : public std::runtime_error {
 public:
  SceneError(const std::string& file, int line, const std::string& message);
  const std::string& file() const { return file_; }
  int line() const { return line_; }  // 0 when unknown

 private:
  std::string file_;
  int line_;
};

struct CameraDesc {
  glm::vec3 origin{0, 0, 1};   // eye position
  glm::vec3 target{0, 0, 0};   // a point the camera looks at
  glm::vec3 up{0, 1, 0};       // up direction
  float fov_degrees = 39.3f;   // field of view along fov_axis
  std::string fov_axis = "x";  // Mitsuba's fovAxis: x, y, diagonal, smaller, larger
  bool mirrored = false;       // image mirrored left-right (a to_world with negative determinant): negate right
};

struct Scene {
  std::vector<glm::vec3> positions;      // vertex positions in world space
  std::vector<glm::uvec3> triangles;     // vertex indices of each triangle
  std::vector<uint32_t> tri_material;    // material index of each triangle
  std::vector<Material> materials;       // albedo and emission (psf_shared.h)
  std::vector<std::string> material_names;  // per material: bsdf id or MTL name, for messages and tests
  CameraDesc camera;                     // the sensor
  int width = 512;                       // film width in pixels
  int height = 512;                      // film height in pixels
  int max_depth = -1;                    // Mitsuba's max_depth: -1 unbounded, 1 emitters only, 2 direct light
  int default_spp = 0;                   // the scene's sampler sampleCount, 0 if none
  std::vector<std::string> warnings;     // unsupported features, each with file:line
};

// Loads a scene by file extension (.xml: Mitsuba; .obj: Wavefront OBJ).
// `params` are Mitsuba `$name` substitutions given on the command line (name=value).
// Throws SceneError with file and line.
Scene load_scene(const std::string& path, const std::vector<std::pair<std::string, std::string>>& params = {});

// Camera for the film: pinhole rays as in kernels/camera.cl.
Camera make_camera(const CameraDesc& desc, int width, int height);

}  // namespace psf
