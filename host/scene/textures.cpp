// Bitmap textures: file lookup ignoring case, decoding (stb_image for JPG, PNG,
// BMP, TGA, HDR; OpenEXR for EXR), conversion to linear RGBA halfs in the
// scene's texel buffer (psf_shared.h TextureInfo, kernels/texture.cl).
#include <stb_image.h>

#include <Imath/half.h>
#include <ImfArray.h>
#include <ImfRgbaFile.h>
#if defined(__x86_64__)
#include <cpuid.h>
#include <immintrin.h>
#endif

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "scene/loaders.h"
#include "scene/materials.h"

namespace fs = std::filesystem;

namespace psf::detail {

namespace {

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

using Pixels = ImagePixels;

Pixels load_exr(const std::string& path) {
  if (const std::string why = unreadable_input(path); !why.empty()) throw std::runtime_error("the image file " + why);
  Pixels p;
  try {
    Imf::RgbaInputFile file(path.c_str());
    Imath::Box2i dw = file.dataWindow();
    p.width = dw.max.x - dw.min.x + 1;
    p.height = dw.max.y - dw.min.y + 1;
    p.has_alpha = (file.channels() & Imf::WRITE_A) != 0;
    Imf::Array2D<Imf::Rgba> px(p.height, p.width);
    // The data window may lie anywhere: the offset in 64 bits (an int product
    // overflowed for a window 300M rows down, and OpenEXR wrote out of bounds).
    file.setFrameBuffer(&px[0][0] - (ptrdiff_t(dw.min.x) + ptrdiff_t(dw.min.y) * ptrdiff_t(p.width)), 1,
                        size_t(p.width));
    file.readPixels(dw.min.y, dw.max.y);
    p.rgba.resize(size_t(p.width) * p.height * 4);
    for (int y = 0; y < p.height; ++y)
      for (int x = 0; x < p.width; ++x) {
        const Imf::Rgba& c = px[y][x];
        float* o = &p.rgba[(size_t(y) * p.width + x) * 4];
        o[0] = c.r;
        o[1] = c.g;
        o[2] = c.b;
        o[3] = p.has_alpha ? float(c.a) : 1.0f;
      }
  } catch (const std::exception& e) {
    throw std::runtime_error(std::string("cannot read EXR image: ") + e.what());
  }
  return p;
}

// Checks a Radiance HDR file's run-length encoded scanlines before stb_image
// decodes them: the stb_image Debian ships loops forever on a run whose length
// byte is 0, which is what it reads past the end of a truncated file. Throws on
// a scanline that would not decode, or data cut short (flat, unencoded
// scanlines too, where stb_image would read zeros past the end); other formats
// pass unchecked.
void check_hdr_runs(const std::string& d) {
  size_t at = d.find("\n\n");  // the header ends with an empty line
  if (at == std::string::npos) return;
  at += 2;
  const size_t eol = d.find('\n', at);
  if (eol == std::string::npos) return;
  int height = 0, width = 0;
  if (std::sscanf(d.substr(at, eol - at).c_str(), "-Y %d +X %d", &height, &width) != 2) return;  // stb refuses it
  at = eol + 1;
  if (height <= 0 || width <= 0) return;  // stb refuses it
  auto byte = [&](size_t i) { return static_cast<unsigned char>(d[i]); };
  // Flat scanlines from `at` on, `rows` of them: 4 bytes a pixel (stb_image reads zeros past the end).
  auto check_flat = [&](int rows, const std::string& where) {
    if ((d.size() - at) / 4 / size_t(width) < size_t(rows)) throw std::runtime_error("truncated HDR image" + where);
  };
  if (width < 8 || width >= 32768) return check_flat(height, "");  // never run-length encoded
  for (int y = 0; y < height; ++y) {
    if (at + 4 > d.size()) throw std::runtime_error("truncated HDR image (scanline " + std::to_string(y) + ")");
    if (byte(at) != 2 || byte(at + 1) != 2 || (byte(at + 2) & 0x80))  // flat from here on
      return check_flat(height - y, " (scanline " + std::to_string(y) + ")");
    if ((byte(at + 2) << 8 | byte(at + 3)) != width)
      throw std::runtime_error("malformed HDR image: scanline " + std::to_string(y) + " has the wrong width");
    at += 4;
    for (int k = 0; k < 4; ++k)
      for (int i = 0; i < width;) {
        if (at >= d.size()) throw std::runtime_error("truncated HDR image (scanline " + std::to_string(y) + ")");
        int count = byte(at++);
        const bool run = count > 128;
        if (run) count -= 128;
        if (count == 0 || count > width - i)
          throw std::runtime_error("malformed HDR image: a bad run in scanline " + std::to_string(y));
        at += run ? 1 : size_t(count);
        if (at > d.size()) throw std::runtime_error("truncated HDR image (scanline " + std::to_string(y) + ")");
        i += count;
      }
  }
}

Pixels load_stb(const std::string& path, bool raw) {
  Pixels p;
  int comp = 0;
  // The file read once, then decoded from memory (format probes, the HDR check and the decoder).
  if (const std::string why = unreadable_input(path); !why.empty()) throw std::runtime_error("the image file " + why);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot decode image: can't fopen");
  const std::string bytes = read_all(in);
  if (bytes.size() > size_t(std::numeric_limits<int>::max())) throw std::runtime_error("the image file is too large");
  const auto* b = reinterpret_cast<const stbi_uc*>(bytes.data());
  const int len = int(bytes.size());
  bool hdr = stbi_is_hdr_from_memory(b, len);
  if (hdr) check_hdr_runs(bytes);
  bool wide = !hdr && stbi_is_16_bit_from_memory(b, len);
  void* data = hdr ? static_cast<void*>(stbi_loadf_from_memory(b, len, &p.width, &p.height, &comp, 0))
               : wide ? static_cast<void*>(stbi_load_16_from_memory(b, len, &p.width, &p.height, &comp, 0))
                      : static_cast<void*>(stbi_load_from_memory(b, len, &p.width, &p.height, &comp, 0));
  if (!data) {
    const char* reason = stbi_failure_reason();  // null where stb_image gives none (a corrupt PNG's deflate data)
    throw std::runtime_error(std::string("cannot decode image: ") + (reason ? reason : "corrupt data"));
  }
  p.has_alpha = comp == 2 || comp == 4;
  const size_t n = size_t(p.width) * p.height;
  p.rgba.resize(n * 4);
  // sRGB decoding of 8-bit values through a table.
  float lut[256];
  for (int i = 0; i < 256; ++i) lut[i] = raw ? float(i) / 255.0f : srgb_to_linear(float(i) / 255.0f);
  for (size_t i = 0; i < n; ++i) {
    float v[4] = {0, 0, 0, 1};
    for (int c = 0; c < comp; ++c) {
      size_t at = i * comp + c;
      bool alpha = p.has_alpha && c == comp - 1;
      float x;
      if (hdr) {
        x = static_cast<const float*>(data)[at];
      } else if (wide) {
        float e = static_cast<const uint16_t*>(data)[at] / 65535.0f;
        x = raw || alpha ? e : srgb_to_linear(e);
      } else {
        uint8_t b = static_cast<const uint8_t*>(data)[at];
        x = alpha ? b / 255.0f : lut[b];
      }
      v[c] = x;
    }
    float* o = &p.rgba[i * 4];
    if (comp <= 2) {  // grey (and alpha)
      o[0] = o[1] = o[2] = v[0];
      o[3] = comp == 2 ? v[1] : 1.0f;
    } else {
      o[0] = v[0];
      o[1] = v[1];
      o[2] = v[2];
      o[3] = comp == 4 ? v[3] : 1.0f;
    }
  }
  stbi_image_free(data);
  return p;
}

float luminance(const float* c) { return 0.212671f * c[0] + 0.715160f * c[1] + 0.072169f * c[2]; }

}  // namespace

ImagePixels load_image(const std::string& path, bool raw) {
  return lower(fs::path(path).extension().string()) == ".exr" ? load_exr(path) : load_stb(path, raw);
}

std::optional<std::string> find_file_nocase(const std::string& path) {
  std::error_code ec;
  if (fs::is_regular_file(path, ec)) return path;
  fs::path p(path);
  fs::path resolved = p.root_path();
  for (const fs::path& part : p.relative_path()) {
    fs::path next = resolved / part;
    if (resolved.empty()) next = part;
    if (!fs::exists(next, ec)) {
      std::string want = lower(part.string());
      bool found = false;
      fs::path dir = resolved.empty() ? fs::path(".") : resolved;
      for (const fs::directory_entry& e : fs::directory_iterator(dir, ec)) {
        if (lower(e.path().filename().string()) == want) {
          next = resolved.empty() ? e.path().filename() : resolved / e.path().filename();
          found = true;
          break;
        }
      }
      if (!found) return std::nullopt;
    }
    resolved = next;
  }
  if (!fs::is_regular_file(resolved, ec)) return std::nullopt;
  return resolved.string();
}

namespace {

// The filtering, wrapping and uv transform of a stored texture, for one made from it.
TextureDesc sampling_of(const TextureInfo& t) {
  TextureDesc d;
  d.bilinear = (t.flags & PSF_TEX_BILINEAR) != 0;
  d.wrap = t.flags & (PSF_TEX_CLAMP | PSF_TEX_MIRROR);
  d.uv_u = glm::vec3(t.uv_u.s[0], t.uv_u.s[1], t.uv_u.s[2]);
  d.uv_v = glm::vec3(t.uv_v.s[0], t.uv_v.s[1], t.uv_v.s[2]);
  return d;
}

// The x channel of texel i of a stored texture.
float stored_x(const Scene& scene, const TextureInfo& t, size_t i) {
  Imath::half h;
  h.setBits(scene.texels[(size_t(t.offset) + i) * 4]);
  return float(h);
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define PSF_F16C 1
// Eight at a time with the F16C instructions (rounding to nearest even, as
// Imath::half does: the same bits for every float that to_halfs takes).
__attribute__((target("avx,f16c"))) void to_halfs_f16c(const float* in, uint16_t* out, size_t n) {
  size_t i = 0;
  for (; i + 8 <= n; i += 8)
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i),
                     _mm256_cvtps_ph(_mm256_loadu_ps(in + i), _MM_FROUND_TO_NEAREST_INT));
  for (; i < n; ++i) out[i] = Imath::half(in[i]).bits();
}
#endif

// Finite floats of at most 65504 in magnitude as the bits of halfs: Imath's
// conversion, one at a time (about a tenth of loading a scene of large
// textures), or F16C's where the CPU has it.
void to_halfs(const float* in, uint16_t* out, size_t n) {
#ifdef PSF_F16C
  // F16C from CPUID (clang before 18 does not know __builtin_cpu_supports("f16c")),
  // AVX (whose registers it uses) from the builtin, which also asks the OS.
  static const bool f16c = [] {
    unsigned a = 0, b = 0, c = 0, d = 0;
    return __get_cpuid(1, &a, &b, &c, &d) && (c & bit_F16C) != 0 && __builtin_cpu_supports("avx");
  }();
  if (f16c) return to_halfs_f16c(in, out, n);
#endif
  for (size_t i = 0; i < n; ++i) out[i] = Imath::half(in[i]).bits();
}

}  // namespace

uint32_t TextureStore::append(const TextureDesc& d, int width, int height, const std::vector<float>& rgba) {
  if (scene_.textures.empty()) {  // the placeholder, PSF_NO_TEXTURE
    TextureInfo t{};
    t.uv_u = {{1, 0, 0, 0}};
    t.uv_v = {{0, 1, 0, 0}};
    t.offset = uint32_t(scene_.texels.size() / 4);
    t.width = t.height = 1;
    scene_.textures.push_back(t);
    scene_.texels.insert(scene_.texels.end(), 4, Imath::half(1.0f).bits());
  }
  const size_t n = size_t(width) * height;
  if (scene_.texels.size() / 4 + n > size_t(UINT32_MAX)) throw std::runtime_error("texture memory exceeds 2^32 texels");
  TextureInfo t{};
  t.uv_u = {{d.uv_u.x, d.uv_u.y, d.uv_u.z, 0}};
  t.uv_v = {{d.uv_v.x, d.uv_v.y, d.uv_v.z, 0}};
  t.offset = uint32_t(scene_.texels.size() / 4);
  t.width = uint32_t(width);
  t.height = uint32_t(height);
  t.flags = (d.bilinear ? PSF_TEX_BILINEAR : 0u) | d.wrap;
  // Room for the texels: at least double the capacity, so that a scene of many
  // textures copies its texels a bounded number of times (growing to the exact
  // size copied every earlier texture's texels at each one: seconds for
  // Bitterli's staircase); load_scene trims the spare capacity once.
  const size_t base = scene_.texels.size();
  if (scene_.texels.capacity() < base + n * 4)
    scene_.texels.reserve(std::max(base + n * 4, scene_.texels.capacity() * 2));
  scene_.texels.resize(base + n * 4);
  uint16_t* out = scene_.texels.data() + base;
  glm::dvec3 sum(0.0);
  // Texels are halfs: a NaN or infinite value reads as 0 and one beyond the
  // largest half (65504) as that, with a warning each, where the half would
  // have been NaN or infinite and every path reading it lost.
  size_t nonfinite = 0, clamped = 0;
  constexpr size_t kChunk = 1024;  // texels made representable, then converted together
  float v[kChunk * 4];
  for (size_t first = 0; first < n; first += kChunk) {
    const size_t count = std::min(kChunk, n - first);
    for (size_t k = 0; k < count * 4; ++k) {
      float x = rgba[first * 4 + k];
      if (!std::isfinite(x)) {
        x = 0.0f;
        ++nonfinite;
      } else if (std::fabs(x) > 65504.0f) {
        x = std::copysign(65504.0f, x);
        ++clamped;
      }
      v[k] = x;
    }
    double r = 0.0, g = 0.0, b = 0.0;  // in registers (a dvec3 sum went through memory every texel)
    for (size_t k = 0; k < count; ++k) {
      r += v[k * 4];
      g += v[k * 4 + 1];
      b += v[k * 4 + 2];
    }
    sum += glm::dvec3(r, g, b);
    to_halfs(v, out + first * 4, count * 4);
  }
  const std::string name = d.path.empty() ? "a texture" : d.path;
  if (nonfinite)
    scene_.warnings.push_back(name + ": " + std::to_string(nonfinite) + " texel values are NaN or infinite; read as 0");
  if (clamped)
    scene_.warnings.push_back(name + ": " + std::to_string(clamped) +
                              " texel values exceed 65504, the largest a half holds; read as 65504");
  uint32_t index = uint32_t(scene_.textures.size());
  scene_.textures.push_back(t);
  means_[index] = n ? glm::vec3(sum / double(n)) : glm::vec3(0.0f);
  return index;
}

uint32_t TextureStore::image(const TextureDesc& d) {
  std::ostringstream key;
  key.precision(9);
  key << d.path << '|' << int(d.use) << '|' << d.bilinear << '|' << d.wrap << '|' << d.raw << '|' << d.uv_u.x << ','
      << d.uv_u.y << ',' << d.uv_u.z << ',' << d.uv_v.x << ',' << d.uv_v.y << ',' << d.uv_v.z;
  auto it = cache_.find(key.str());
  if (it != cache_.end()) return it->second;
  std::string ext = lower(fs::path(d.path).extension().string());
  Pixels p = load_image(d.path, d.raw);
  if (p.width <= 0 || p.height <= 0) throw std::runtime_error("the image is empty");
  if (d.use != TextureUse::Color) {
    for (size_t i = 0; i < p.rgba.size(); i += 4) {
      float* c = &p.rgba[i];
      float v = d.use == TextureUse::Opacity && p.has_alpha ? c[3] : luminance(c);
      c[0] = c[1] = c[2] = v;
      c[3] = 1.0f;
    }
  }
  uint32_t index = append(d, p.width, p.height, p.rgba);
  cache_.emplace(key.str(), index);
  return index;
}

uint32_t TextureStore::pixels(const TextureDesc& d, int width, int height, const std::vector<float>& rgba) {
  if (width <= 0 || height <= 0 || rgba.size() != size_t(width) * height * 4)
    throw std::invalid_argument("TextureStore::pixels: wrong size");
  return append(d, width, height, rgba);
}

uint32_t TextureStore::table(const std::string& key, const std::vector<float>& values, int width) {
  auto it = cache_.find("table|" + key);
  if (it != cache_.end()) return it->second;
  if (width <= 0) width = int(values.size());
  if (values.empty() || values.size() % size_t(width) != 0)
    throw std::invalid_argument("TextureStore::table: not a whole number of rows");
  std::vector<float> rgba(values.size() * 4, 1.0f);
  for (size_t i = 0; i < values.size(); ++i) rgba[i * 4] = values[i];
  TextureDesc d;
  d.wrap = PSF_TEX_CLAMP;
  uint32_t index = append(d, width, int(values.size() / size_t(width)), rgba);
  table_values_.emplace(index, values);
  cache_.emplace("table|" + key, index);
  return index;
}

std::optional<uint32_t> TextureStore::combine_xy(uint32_t x, float cx, uint32_t y, float cy) {
  if (x == PSF_NO_TEXTURE && y == PSF_NO_TEXTURE) throw std::invalid_argument("TextureStore::combine_xy: no texture");
  const TextureInfo grid = scene_.textures.at(x != PSF_NO_TEXTURE ? x : y);  // a copy: append grows the table
  auto same = [](const psf_float4& a, const psf_float4& b) {
    return a.s[0] == b.s[0] && a.s[1] == b.s[1] && a.s[2] == b.s[2];
  };
  if (x != PSF_NO_TEXTURE && y != PSF_NO_TEXTURE) {
    const TextureInfo& other = scene_.textures.at(y);
    if (other.width != grid.width || other.height != grid.height || other.flags != grid.flags ||
        !same(other.uv_u, grid.uv_u) || !same(other.uv_v, grid.uv_v))
      return std::nullopt;
  }
  const size_t n = size_t(grid.width) * grid.height;
  auto texel_x = [&](uint32_t t, size_t i) { return stored_x(scene_, scene_.textures[t], i); };
  std::vector<float> rgba(n * 4);
  for (size_t i = 0; i < n; ++i) {
    rgba[i * 4] = x != PSF_NO_TEXTURE ? texel_x(x, i) : cx;
    rgba[i * 4 + 1] = y != PSF_NO_TEXTURE ? texel_x(y, i) : cy;
    rgba[i * 4 + 2] = 0.0f;
    rgba[i * 4 + 3] = 1.0f;
  }
  return append(sampling_of(grid), int(grid.width), int(grid.height), rgba);
}

uint32_t TextureStore::complement_x(uint32_t t) {
  const std::string key = "complement|" + std::to_string(t);
  auto it = cache_.find(key);
  if (it != cache_.end()) return it->second;
  const TextureInfo grid = scene_.textures.at(t);  // a copy: append grows the table
  const size_t n = size_t(grid.width) * grid.height;
  std::vector<float> rgba(n * 4, 1.0f);
  for (size_t i = 0; i < n; ++i) {
    rgba[i * 4] = rgba[i * 4 + 1] = rgba[i * 4 + 2] = 1.0f - stored_x(scene_, grid, i);
  }
  const TextureDesc d = sampling_of(grid);
  const uint32_t index = append(d, int(grid.width), int(grid.height), rgba);
  cache_.emplace(key, index);
  return index;
}

glm::vec3 TextureStore::mean(uint32_t index) const {
  auto it = means_.find(index);
  return it == means_.end() ? glm::vec3(1.0f) : it->second;
}

}  // namespace psf::detail
