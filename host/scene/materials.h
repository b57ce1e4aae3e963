// Materials and textures shared by the scene loaders (Mitsuba XML, OBJ/MTL):
// bitmap textures in the scene's texel buffer, Mitsuba's tables of named IORs,
// and the derived constants of plastics (psf_shared.h Material; the kernel side
// is kernels/bsdf.cl and kernels/texture.cl).
#pragma once
#include <glm/glm.hpp>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "scene/scene.h"

namespace psf::detail {

// How a texture's texels are stored (RGBA halfs, kernels/texture.cl).
enum class TextureUse {
  Color,   // linear RGB; alpha the image's, else 1
  Height,  // x (and y, z): luminance of the linear RGB (Mitsuba 3's eval_1): bump maps, blendbsdf's weight
  Opacity  // x (and y, z): the alpha channel if the image has one, else the luminance
};

// A bitmap texture as a scene names it.
struct TextureDesc {
  std::string path;                   // the file (already resolved, see find_file_nocase)
  TextureUse use = TextureUse::Color;  // which channels are kept
  bool bilinear = true;               // bilinear filtering, else nearest
  uint32_t wrap = 0;                  // 0 (repeat), PSF_TEX_CLAMP or PSF_TEX_MIRROR
  bool raw = false;                   // 8/16-bit values used as stored instead of decoded from sRGB
  glm::vec3 uv_u{1, 0, 0};            // texture u = dot(uv_u, (u, v, 1)) of the surface uv
  glm::vec3 uv_v{0, 1, 0};            // texture v likewise
};

// `path` if it exists, else the file whose path matches it ignoring case (each
// component looked up in its parent folder): archives made on case-insensitive
// file systems name "Foo.JPG" as "foo.jpg". nullopt if there is none.
std::optional<std::string> find_file_nocase(const std::string& path);

// Appends textures to a Scene's texture table and texel buffer: images loaded
// once per file and use, tables and small constant images. Entry 0 is the
// placeholder (one white texel), added on first use.
class TextureStore {
 public:
  explicit TextureStore(Scene& scene) : scene_(scene) {}

  // Loads a JPG, PNG, BMP, TGA, HDR (stb_image) or EXR (OpenEXR) image. 8- and
  // 16-bit images are decoded from sRGB unless `raw`. Throws std::runtime_error
  // with the reason if the file cannot be decoded.
  uint32_t image(const TextureDesc& desc);

  // A texture of `width` x `height` RGBA texels given as floats (4 per texel,
  // rows from the top), with desc's filtering, wrapping and uv transform (desc.path is ignored).
  uint32_t pixels(const TextureDesc& desc, int width, int height, const std::vector<float>& rgba);

  // A table (x channel) of `width` columns (0: one row of all the values),
  // reused for equal `key`s.
  uint32_t table(const std::string& key, const std::vector<float>& values, int width = 0);
  // Whether table() holds one for `key`, and the values of table `index`.
  bool has_table(const std::string& key) const { return cache_.count("table|" + key) != 0; }
  const std::vector<float>& table_values(uint32_t index) const { return table_values_.at(index); }
  // Numbers that belong with table `key` (roughplastic: the internal and
  // external reflectances of its row), so that a cached table needs no recompute.
  void set_table_numbers(const std::string& key, std::vector<double> numbers) {
    table_numbers_[key] = std::move(numbers);
  }
  const std::vector<double>* table_numbers(const std::string& key) const {
    auto it = table_numbers_.find(key);
    return it == table_numbers_.end() ? nullptr : &it->second;
  }

  // A texture whose x channel is texture x's (the constant cx where x is
  // PSF_NO_TEXTURE) and whose y channel is texture y's (or cy): anisotropic
  // roughness. It takes the grid, filtering, wrapping and uv transform of the
  // textures, which must agree where both are given (nullopt where they do not).
  std::optional<uint32_t> combine_xy(uint32_t x, float cx, uint32_t y, float cy);

  // A texture whose x, y and z channels are 1 - texture t's x (blendbsdf's weight
  // for the other BSDF), with t's grid, filtering, wrapping and uv transform.
  uint32_t complement_x(uint32_t t);

  // Mean of the RGB channels of texture `index` over its texels.
  glm::vec3 mean(uint32_t index) const;

 private:
  uint32_t append(const TextureDesc& desc, int width, int height, const std::vector<float>& rgba);

  Scene& scene_;
  std::map<std::string, uint32_t> cache_;  // file + use + sampling -> index; table keys
  std::map<uint32_t, glm::vec3> means_;    // texture -> mean RGB
  std::map<uint32_t, std::vector<float>> table_values_;  // table() textures -> their values
  std::map<std::string, std::vector<double>> table_numbers_;  // set_table_numbers
};

// Mitsuba's named dielectric IORs ("bk7", "water", "air", ...); nullopt if unknown.
std::optional<float> ior_by_name(const std::string& name);

// Mitsuba's named conductors ("Cu", "Au", "Ag", "Al", "Cr", ...; case-sensitive as
// in Mitsuba, "none" excluded): the complex IOR in linear sRGB, the spectral
// data integrated against the CIE curves as Mitsuba's RGB variants do (values as
// tabulated by Tungsten's ComplexIorData). False if unknown.
bool conductor_by_name(const std::string& name, glm::vec3& eta, glm::vec3& k);

// The complex IOR of a conductor whose Fresnel reflectance at normal incidence is
// r (clamped to [0, PSF_MAX_REFLECTANCE]): eta = 1, k = 2 sqrt(r / (1 - r)), as
// kernels/bsdf.cl's conductor_from_reflectance (glTF's metals).
void conductor_from_reflectance(const glm::vec3& r, glm::vec3& eta, glm::vec3& k);

// Unpolarised Fresnel reflectance of a dielectric interface (eta = transmitted /
// incident IOR) at incidence cosine cos_i in [0, 1].
double fresnel_dielectric(double cos_i, double eta);

// Hemispherical average 2 int_0^1 F(mu, eta) mu dmu of the dielectric Fresnel
// reflectance (numerical quadrature; Mitsuba uses a polynomial fit of it).
double fresnel_diffuse_reflectance(double eta);

// Directional albedo of the microfacet reflection f = F D G / (4 cos_o cos_i)
// (without specular reflectance) for incidence cosine mu: Mitsuba 3's
// MicrofacetDistribution eval_reflectance, by quadrature over normals sampled
// from D(m) cos(theta_m). GGX (beckmann false) or Beckmann, isotropic alpha.
double rough_reflectance(double mu, double alpha, double eta, bool beckmann);

// The fraction of light from incidence cosine mu that the microfacets refract
// through the interface (relative IOR eta), single scattering: Mitsuba 3's
// eval_transmittance, E[(1 - F(wo.m)) G1(wi_t, m)] over visible normals, by the
// same quadrature. Less than 1 - rough_reflectance: the rest is the energy
// single-scattering microfacet models lose.
double rough_transmittance(double mu, double alpha, double eta, bool beckmann);

// Fills the derived constants of a plastic, roughplastic or pplastic material
// from its type, albedo, specular, eta.x, alpha and flags: eta.y = 1 / eta^2,
// eta.z the internal (pplastic: 0) and eta.w the external diffuse reflectance of
// the coating, albedo.w the specular sampling weight s / (d + s) of the means
// `diffuse_mean` and `specular_mean` (Mitsuba's), and for roughplastic
// tex_table, the external transmittance table (Mitsuba 3's roughplastic).
void finish_plastic(Material& m, float diffuse_mean, float specular_mean, TextureStore& store);

// An image file's texels as linear RGBA floats, rows from the top: OpenEXR through
// OpenEXR, everything else through stb_image (HDR as float; 8/16-bit values
// decoded from sRGB unless `raw`). Throws std::runtime_error.
struct ImagePixels {
  int width = 0, height = 0;  // texels
  bool has_alpha = false;     // the file has an alpha channel
  std::vector<float> rgba;    // 4 floats a texel
};
ImagePixels load_image(const std::string& path, bool raw);

}  // namespace psf::detail
