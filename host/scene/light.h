// Lights other than emissive surfaces, as the scene loaders describe them: delta
// lights (point, spot, directional) and the environment (a lat-long map or a
// constant radiance). World space, linear RGB. host/lights.cpp turns them into
// the device's emitter table (psf_shared.h Emitter, Environment).
#pragma once
#include <string>
#include <vector>

#include <glm/glm.hpp>

namespace psf {

enum class LightType {
  Point,        // isotropic point light: intensity I (W/sr)
  Spot,         // point light in a cone about `direction` (Mitsuba's spot falloff)
  Directional,  // parallel light travelling along `direction`: irradiance E (W/m^2)
  Constant,     // environment of constant radiance L
  Envmap        // environment from a lat-long image times a scale
};

struct LightDesc {
  LightType type = LightType::Point;
  glm::vec3 position{0.0f};         // point, spot: world position
  glm::vec3 direction{0, 0, 1};     // spot: unit axis of the cone; directional: unit direction of travel
  glm::vec3 color{1.0f};            // intensity (point, spot), irradiance (directional), radiance (constant), scale (envmap)
  float cutoff_angle = 0.3490659f;  // spot: half-angle where the light ends, radians (Mitsuba default 20 degrees)
  float beam_width = 0.2617994f;    // spot: half-angle of full intensity, radians (default 3/4 of the cutoff)
  glm::mat3 to_world{1.0f};         // envmap: rotation from the map's frame (+y up) to world space
  int width = 0;                    // envmap: texels across (u = 0..1 left to right)
  int height = 0;                   // envmap: texels down (v = 0 at the top, +y)
  std::vector<float> texels;        // envmap: RGB radiance, row-major from the top-left
  std::string source;               // "file:line" (or the file) that defined the light, for messages
};

// A lat-long image for an environment: width x height RGB texels, row-major from the top.
struct EnvImage {
  int width = 0;
  int height = 0;
  std::vector<float> rgb;
  size_t negative = 0;  // negative values found in the file, set to 0 (callers warn)
};

// Reads an environment image: OpenEXR (.exr: RGB, RGBA or luminance channels, any
// pixel type) or Radiance RGBE (.hdr, .pic) with stb_image; 8-bit PNG/JPEG/TGA/BMP
// are read as sRGB and linearised. Throws SceneError(path, 0, ...) when the file
// cannot be read, is smaller than 2x2 texels, or holds non-finite values.
EnvImage read_env_image(const std::string& path);

// The default sky given to scenes without any emitter that are loaded from a bare
// mesh file (OBJ, PLY, glTF): a lat-long gradient environment, +y up, 64x32
// texels: radiance 1 at the horizon blending linearly in cos(zenith angle) to a
// blue (0.5, 0.7, 1.0) at the zenith, and a grey ground of 0.3 below the horizon.
LightDesc default_sky();

}  // namespace psf
