// Environment images (lat-long maps) for the envmap emitter, and the default sky
// of bare mesh files. OpenEXR through OpenEXR's RGBA interface (which converts
// half/float/uint, RGB/RGBA/luminance-chroma channels to RGBA half), everything
// else through stb_image (Radiance .hdr as float; 8-bit images as sRGB).
#include <ImfArray.h>
#include <ImfRgbaFile.h>
#include <stb_image.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>

#include "scene/formats.h"

namespace psf {
namespace {

std::string extension_of(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

EnvImage read_exr_rgba(const std::string& path) {
  EnvImage img;
  try {
    Imf::RgbaInputFile file(path.c_str());
    Imath::Box2i dw = file.dataWindow();
    img.width = dw.max.x - dw.min.x + 1;
    img.height = dw.max.y - dw.min.y + 1;
    if (img.width <= 0 || img.height <= 0) throw SceneError(path, 0, "empty OpenEXR data window");
    Imf::Array2D<Imf::Rgba> px(img.height, img.width);
    file.setFrameBuffer(&px[0][0] - dw.min.x - dw.min.y * img.width, 1, size_t(img.width));
    file.readPixels(dw.min.y, dw.max.y);
    img.rgb.resize(size_t(img.width) * img.height * 3);
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        const Imf::Rgba& p = px[y][x];
        float* o = &img.rgb[(size_t(y) * img.width + x) * 3];
        o[0] = float(p.r);
        o[1] = float(p.g);
        o[2] = float(p.b);
      }
  } catch (const SceneError&) {
    throw;
  } catch (const std::exception& e) {
    throw SceneError(path, 0, std::string("cannot read OpenEXR environment map: ") + e.what());
  }
  return img;
}

EnvImage read_stb(const std::string& path) {
  EnvImage img;
  int channels = 0;
  if (stbi_is_hdr(path.c_str())) {
    float* data = stbi_loadf(path.c_str(), &img.width, &img.height, &channels, 3);
    if (!data) throw SceneError(path, 0, std::string("cannot read environment map: ") + stbi_failure_reason());
    img.rgb.assign(data, data + size_t(img.width) * img.height * 3);
    stbi_image_free(data);
  } else {
    unsigned char* data = stbi_load(path.c_str(), &img.width, &img.height, &channels, 3);
    if (!data) throw SceneError(path, 0, std::string("cannot read environment map: ") + stbi_failure_reason());
    img.rgb.resize(size_t(img.width) * img.height * 3);
    for (size_t i = 0; i < img.rgb.size(); ++i) img.rgb[i] = detail::srgb_to_linear(float(data[i]) / 255.0f);
    stbi_image_free(data);
  }
  return img;
}

}  // namespace

EnvImage read_env_image(const std::string& path) {
  if (!std::filesystem::is_regular_file(path)) throw SceneError(path, 0, "environment map file not found");
  EnvImage img = extension_of(path) == ".exr" ? read_exr_rgba(path) : read_stb(path);
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
    // cos(zenith angle) at the row's centre; rows 0..15 lie above the horizon.
    float cos_theta = std::cos((float(y) + 0.5f) / float(sky.height) * 3.14159265f);
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
