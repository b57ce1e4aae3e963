// Image output: OpenEXR (float RGB) and a tone-mapped PNG preview. Both are
// written to a temporary file beside the target and renamed over it, so an
// existing file is never left half-written.
#pragma once
#include <map>
#include <string>
#include <vector>

namespace psf {

struct Image {
  int width = 0;           // pixels
  int height = 0;          // pixels
  std::vector<float> rgb;  // linear RGB, row-major from the top-left, 3 floats a pixel
};

// An extra EXR layer (AOV): channels "<name>.R/G/B" (3 channels) or "<name>.Y" (1).
struct ExrLayer {
  std::string name;         // layer name, e.g. "unfiltered"
  int channels = 3;         // 1 or 3
  std::vector<float> data;  // width * height * channels floats, row-major
};

// Throws std::runtime_error naming the path when the file cannot be written.
void write_exr(const std::string& path, const Image& image,
               const std::map<std::string, std::string>& attributes = {},
               const std::vector<ExrLayer>& layers = {});
Image read_exr(const std::string& path);

// Every channel of an OpenEXR file as floats, with its string attributes.
struct ExrFile {
  int width = 0, height = 0;                              // data window
  std::map<std::string, std::string> attributes;          // string attributes only
  std::map<std::string, std::vector<float>> channels;     // by channel name, row-major
};
ExrFile read_exr_file(const std::string& path);

// sRGB-encoded 8-bit PNG of exposure-scaled, clamped linear RGB.
void write_png(const std::string& path, const Image& image, float exposure = 1.0f);

// Checks before a render that `path` can be written: its folder exists and is
// writable and the path is not a folder. Throws std::invalid_argument otherwise.
void check_writable(const std::string& path);

}  // namespace psf
