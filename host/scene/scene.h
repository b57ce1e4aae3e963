// The renderer's scene: triangles with materials, a camera and the film size.
// Every input format (Mitsuba XML, OBJ, ...) is loaded into this one structure.
#pragma once
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "psf_shared.h"
#include "scene/light.h"

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
  float aperture_radius = 0;   // thin lens radius (Mitsuba's thinlens); 0: a pinhole
  float focus_distance = 1e4f; // distance of the plane in focus along the view direction (thin lens)
  bool orthographic = false;   // parallel rays (Mitsuba's orthographic); fov and the lens are unused
  glm::vec2 ortho_scale{1.0f}; // orthographic: the film spans [-x, x] by [-y, y] / aspect in world units
  // Crop window (Mitsuba's film crop_*): the image is the part of a film of
  // film_width x film_height pixels from pixel (crop_x, crop_y) on, of the
  // scene's width x height; film_width 0: no crop, the film is the image.
  int film_width = 0, film_height = 0, crop_x = 0, crop_y = 0;
  glm::vec2 principal_point{0.0f};  // Mitsuba's principal_point_offset_x/y (perspective): film fractions
  float near_clip = 0.0f;      // camera rays see what lies between these distances along the view direction
  float far_clip = INFINITY;   // (Mitsuba's near_clip and far_clip)
  // Pixel filter (Mitsuba's rfilter): "box" (half-width 0.5), "tent" (radius
  // filter_radius) or "gaussian" (stddev filter_stddev, cut off at 4 stddev).
  std::string pixel_filter = "box";
  float filter_radius = 1.0f;
  float filter_stddev = 0.5f;
};

// An analytic sphere (Mitsuba's sphere under a to_world of rotation, uniform
// scale and translation): intersected exactly, shaded with its own normal and
// Mitsuba's uv (phi / 2pi, theta / pi in its local frame, z up), sampled as a
// light by area. Its prim index follows the triangles' (psf_shared.h).
struct SphereShape {
  glm::vec3 center{0.0f};
  float radius = 1.0f;
  glm::vec3 axis_x{1, 0, 0};  // the local frame's x and y axes in world space (unit,
  glm::vec3 axis_y{0, 1, 0};  // orthogonal); z = x cross y
  bool flip = false;          // flip_normals: the normal points inwards
  uint32_t material = 0;
};

struct Scene {
  std::vector<glm::vec3> positions;      // vertex positions in world space
  std::vector<glm::uvec3> triangles;     // vertex indices of each triangle
  std::vector<glm::vec3> normals;        // per vertex shading normal (world space) or empty; (0,0,0): none, face normal
  std::vector<glm::vec2> uvs;            // per vertex uv (Mitsuba's: v = 0 at the image top) or empty; NaN: none
  // Per vertex unit tangent (world space) and handedness w = +-1, the normal
  // map's frame (t, w n x t, n) (glTF's TANGENT), or empty; w = 0: none.
  std::vector<glm::vec4> tangents;
  // Per vertex linear RGB colour in [0, 1] (glTF COLOR_0, PLY, OBJ), or empty;
  // x < 0: none. It multiplies the colour term of the triangle's material.
  std::vector<glm::vec3> colors;
  std::vector<uint32_t> tri_material;    // material index of each triangle
  std::vector<SphereShape> spheres;      // analytic spheres (prims triangles.size() + k)
  std::vector<Material> materials;       // albedo and emission (psf_shared.h)
  std::vector<std::string> material_names;  // per material: bsdf id or MTL name, for messages and tests
  std::vector<TextureInfo> textures;     // texture table; entry 0 (PSF_NO_TEXTURE) a placeholder; may be empty
  std::vector<uint16_t> texels;          // every texture's RGBA texels as halfs (TextureInfo.offset counts texels)
  CameraDesc camera;                     // the sensor
  int width = 512;                       // film width in pixels
  int height = 512;                      // film height in pixels
  int max_depth = -1;                    // Mitsuba's max_depth: -1 unbounded, 1 emitters only, 2 direct light
  int rr_depth = 5;                      // Mitsuba's rr_depth: Russian roulette from this depth on
  uint32_t hide = 0;                     // PSF_HIDE_* (Mitsuba's hide_emitters): what camera rays do not see
  uint32_t camera_medium = 0;            // 1 + the material whose interior medium holds the camera, 0: none
  int default_spp = 0;                   // the scene's sampler sampleCount, 0 if none
  std::vector<LightDesc> lights;         // point, spot, directional lights and the environment (emissive surfaces are materials)
  std::vector<std::string> warnings;     // unsupported features, each with file:line
};

// Loads a scene by file extension (.xml: Mitsuba; .obj: Wavefront OBJ; .ply: PLY;
// .gltf, .glb: glTF 2.0). Mesh files without any emitter get default_sky().
// `params` are Mitsuba `$name` substitutions given on the command line (name=value).
// Throws SceneError with file and line.
Scene load_scene(const std::string& path, const std::vector<std::pair<std::string, std::string>>& params = {});

// The shading attributes of every triangle (psf_shared.h TriAttrib): the vertex
// normals and uvs of `scene`, barycentric uvs where a vertex has none; then
// one per analytic sphere, with the uvs (0,0), (1,0), (0,1), so that shade.cl's
// barycentrics (b1, b2) are the sphere's uv, and no vertex normals.
std::vector<TriAttrib> triangle_attributes(const Scene& scene);

// The axis-aligned bounds of the scene's triangles' vertices and spheres (finite
// values only); lo > hi where there are none.
void scene_bounds(const Scene& scene, glm::vec3& lo, glm::vec3& hi);

// The materials as the device gets them: PSF_MATFLAG_NORMALS set on those with
// a triangle with vertex normals in `attributes` (so that the others skip reading
// them); a blend whose partner lies outside the table is dropped.
std::vector<Material> device_materials(const Scene& scene, const std::vector<TriAttrib>& attributes);

// Per primitive (the triangles, then the analytic spheres): whether ray casts
// test its material, for its opacity (PSF_MATFLAG_MASKED) or as a medium's null
// boundary, which shadow rays pass (PSF_MATFLAG_NULL_BOUNDARY; kernels/raycast.cl).
std::vector<bool> masked_prims(const Scene& scene);

// Camera for the film: pinhole rays as in kernels/camera.cl.
Camera make_camera(const CameraDesc& desc, int width, int height);

// Sets the image to width x height pixels (the film's, or with a crop window
// the whole film scaled to that size, the window with it); 0 keeps a side.
void set_film_size(Scene& scene, int width, int height);

}  // namespace psf
