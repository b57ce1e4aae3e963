// Environment images (lat-long maps) for the envmap emitter, and the default sky
// of bare mesh files, read by the textures' image loader (OpenEXR, or stb_image:
// Radiance .hdr as float, 8/16-bit images as sRGB).

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>

#include "scene/formats.h"
#include "scene/materials.h"

namespace psf {
namespace {

// The map's texels as linear RGB (the textures' image loader, host/scene/textures.cpp).
EnvImage read_rgb(const std::string& path) {
  detail::ImagePixels px;
  try {
    px = detail::load_image(path, false);
  } catch (const std::exception& e) {
    throw SceneError(path, 0, std::string("cannot read environment map: ") + e.what());
  }
  EnvImage img;
  img.width = px.width;
  img.height = px.height;
  img.rgb.resize(size_t(img.width) * img.height * 3);
  for (size_t i = 0; i < size_t(img.width) * img.height; ++i)
    for (int c = 0; c < 3; ++c) img.rgb[i * 3 + c] = px.rgba[i * 4 + c];
  return img;
}

}  // namespace

EnvImage read_env_image(const std::string& path) {
  if (!std::filesystem::is_regular_file(path)) throw SceneError(path, 0, "environment map file not found");
  EnvImage img = read_rgb(path);
  if (img.width < 2 || img.height < 2)
    throw SceneError(path, 0, "the environment map must be at least 2x2 texels, not " + std::to_string(img.width) +
                                  "x" + std::to_string(img.height));
  for (size_t i = 0; i < img.rgb.size(); ++i) {
    float v = img.rgb[i];
    if (!std::isfinite(v)) {
      size_t t = i / 3;
      throw SceneError(path, 0, "texel (" + std::to_string(t % size_t(img.width)) + ", " +
                                    std::to_string(t / size_t(img.width)) + ") is not finite");
    }
    if (v < 0.0f) {
      img.rgb[i] = 0.0f;
      ++img.negative;
    }
  }
  return img;
}

LightDesc default_sky() {
  LightDesc sky;
  sky.type = LightType::Envmap;
  sky.width = 64;
  sky.height = 32;
  sky.color = glm::vec3(1.0f);
  sky.source = "default sky";
  const glm::vec3 horizon(1.0f), zenith(0.5f, 0.7f, 1.0f), ground(0.3f);
  sky.texels.resize(size_t(sky.width) * sky.height * 3);
  for (int y = 0; y < sky.height; ++y) {
    // cos(zenith angle) of the row, at v = y / (height - 1) as the map is read
    // (kernels/emitter.cl env_lookup); rows 0..15 lie above the horizon.
    float cos_theta = std::cos(float(y) / float(sky.height - 1) * 3.14159265f);
    glm::vec3 c = cos_theta > 0.0f ? glm::mix(horizon, zenith, cos_theta) : ground;
    for (int x = 0; x < sky.width; ++x)
      for (int k = 0; k < 3; ++k) sky.texels[(size_t(y) * sky.width + x) * 3 + k] = c[k];
  }
  return sky;
}

namespace detail {

bool has_emitters(const Scene& scene) {
  if (!scene.lights.empty()) return true;
  std::vector<bool> emissive(scene.materials.size(), false);
  for (size_t i = 0; i < scene.materials.size(); ++i) {
    const Material& m = scene.materials[i];
    emissive[i] = m.emission.s[0] > 0.0f || m.emission.s[1] > 0.0f || m.emission.s[2] > 0.0f;
  }
  for (uint32_t m : scene.tri_material)
    if (m < emissive.size() && emissive[m]) return true;
  return false;
}

}  // namespace detail
}  // namespace psf
