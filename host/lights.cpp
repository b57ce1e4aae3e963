#include "lights.h"

#include <Imath/half.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <stdexcept>

namespace psf {

namespace {

constexpr double kPi = 3.14159265358979323846;

float lum(const glm::vec3& c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

psf_float4 f4(const glm::vec3& v, float w = 0.0f) { return {{v.x, v.y, v.z, w}}; }

// Radius of the bounding sphere of the scene's vertices (1 when there are none).
float scene_radius(const Scene& scene) {
  glm::vec3 lo, hi;
  scene_bounds(scene, lo, hi);
  if (lo.x > hi.x) return 1.0f;
  float r = 0.5f * glm::length(hi - lo);
  return std::isfinite(r) && r > 0.0f ? r : 1.0f;
}

bool is_environment(const LightDesc& l) { return l.type == LightType::Constant || l.type == LightType::Envmap; }

// The integral over [0, s] of the hat function max(0, 1 - |t|), for any s
// (an antiderivative, 0 at s = 0).
double hat_integral(double s) {
  const double a = std::min(std::abs(s), 1.0);
  return std::copysign(a - 0.5 * a * a, s);
}

}  // namespace

EnvDistribution build_env_distribution(const std::vector<float>& rgb, int width, int height) {
  EnvDistribution d;
  const size_t w = size_t(width), h = size_t(height);
  const size_t K = PSF_ENV_BLOCK, nb = (w + K - 1) / K;
  d.marginal.assign(h + 1, 0.0f);
  d.blocks.assign(h * (nb + 1), 0.0f);
  d.within_block.assign(h * nb * K, 1.0f);
  // Cell (x, y) covers u in [x, x + 1] / W and v in [y, y + 1] / H; its weight is
  // the mean over it of the bilinear luminance (kernels/emitter.cl env_lookup:
  // column x's centre at u = (x + 1/2) / W, row r at v = r / (H - 1)) times
  // sin(theta) at its centre. Along u the cell spans column x's centre and half
  // of each neighbour's hat: weights 1/8, 3/4, 1/8. Along v it spans
  // [y, y + 1] (H - 1) / H in row units, over which row r's hat integrates to
  // the difference of hat_integral at the ends.
  std::vector<double> blurred(w * h);
  for (size_t y = 0; y < h; ++y)
    for (size_t x = 0; x < w; ++x) {
      auto lum_at = [&](size_t c) {
        const float* t = &rgb[(y * w + c) * 3];
        return std::max(0.0, double(lum(glm::vec3(t[0], t[1], t[2]))));
      };
      blurred[y * w + x] = 0.125 * lum_at((x + w - 1) % w) + 0.75 * lum_at(x) + 0.125 * lum_at((x + 1) % w);
    }
  std::vector<double> row_sum(h, 0.0), f(w), block_sum(nb);
  double total = 0.0;
  for (size_t y = 0; y < h; ++y) {
    double sin_theta = std::sin((double(y) + 0.5) / double(h) * kPi);
    const double rows = double(h > 1 ? h - 1 : 1), a = double(y) * rows / double(h), b = double(y + 1) * rows / double(h);
    std::fill(f.begin(), f.end(), 0.0);
    for (size_t r = size_t(std::floor(a)); r < h && double(r) <= std::ceil(b); ++r) {
      const double weight = (hat_integral(b - double(r)) - hat_integral(a - double(r))) / (b - a);
      if (weight > 0.0)
        for (size_t x = 0; x < w; ++x) f[x] += weight * blurred[r * w + x];
    }
    double run = 0.0;
    std::fill(block_sum.begin(), block_sum.end(), 0.0);
    for (size_t x = 0; x < w; ++x) {
      f[x] *= sin_theta;
      run += f[x];
      block_sum[x / K] += f[x];
    }
    // A zero row or block gets a uniform cdf; it is never chosen.
    float* bc = &d.blocks[y * (nb + 1)];
    double acc = 0.0;
    for (size_t b = 0; b < nb; ++b) {
      const size_t in_block = std::min(K, w - b * K);
      acc += run > 0.0 ? block_sum[b] : double(in_block);
      bc[b + 1] = float(acc / (run > 0.0 ? run : double(w)));
      float* fine = &d.within_block[(y * nb + b) * K];
      double part = 0.0;
      for (size_t k = 0; k < in_block; ++k) {
        part += block_sum[b] > 0.0 ? f[b * K + k] : 1.0;
        fine[k] = float(part / (block_sum[b] > 0.0 ? block_sum[b] : double(in_block)));
      }
      fine[in_block - 1] = 1.0f;
    }
    bc[nb] = 1.0f;
    row_sum[y] = run;
    total += run;
  }
  double acc = 0.0;
  for (size_t y = 0; y < h; ++y) {
    acc += row_sum[y];
    d.marginal[y + 1] = total > 0.0 ? float(acc / total) : float(double(y + 1) / double(h));
  }
  d.marginal[h] = 1.0f;
  d.integral = total / double(w * h);
  d.guide.reserve(h + h * nb);
  cdf_guide_table(&d.marginal[1], h, d.guide);
  for (size_t y = 0; y < h; ++y) cdf_guide_table(&d.blocks[y * (nb + 1) + 1], nb, d.guide);
  return d;
}

void cdf_guide_table(const float* upper, size_t n, std::vector<float>& out) {
  size_t i = 0;
  for (size_t k = 0; k < n; ++k) {
    const double threshold = double(k) / double(n) - 1e-6;
    while (i + 1 < n && double(upper[i]) <= threshold) ++i;
    const uint32_t index = uint32_t(i);
    float bits;
    std::memcpy(&bits, &index, sizeof bits);  // the index's bits (emitter.cl reads them with as_uint)
    out.push_back(bits);
  }
}

namespace {
// The mean RGB of texture `index` of the scene's texel buffer (halfs), or 1 for
// none or a texture outside the table.
glm::vec3 texture_mean(const Scene& scene, uint32_t index) {
  if (index == PSF_NO_TEXTURE || index >= scene.textures.size()) return glm::vec3(1.0f);
  const TextureInfo& t = scene.textures[index];
  const size_t n = size_t(t.width) * t.height, first = size_t(t.offset) * 4;
  if (n == 0 || first + n * 4 > scene.texels.size()) return glm::vec3(1.0f);
  glm::dvec3 sum(0.0);
  for (size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) {
      Imath::half h;
      h.setBits(scene.texels[first + i * 4 + size_t(c)]);
      sum[c] += double(float(h));
    }
  return glm::vec3(sum / double(n));
}
}  // namespace

LightTable build_light_table(const Scene& scene) {
  LightTable t;
  std::vector<double> power;
  std::map<uint32_t, glm::vec3> means;  // of the emission textures

  // An area light of material m and the given area: its table entry (the caller
  // fills in the geometry) and power. With an emission texture, the light is
  // chosen by its mean (any choice keeps next-event estimation unbiased; the
  // sample carries the texel's value).
  auto add_area_light = [&](const Material& m, float area, uint32_t prim, uint32_t type) -> Emitter& {
    glm::vec3 le(m.emission.s[0], m.emission.s[1], m.emission.s[2]);
    glm::vec3 scale(1.0f);
    if (m.tex_emission != PSF_NO_TEXTURE) {
      auto it = means.find(m.tex_emission);
      if (it == means.end()) it = means.emplace(m.tex_emission, texture_mean(scene, m.tex_emission)).first;
      scale = it->second;
    }
    Emitter e{};
    e.radiance = f4(le);
    e.prim = prim;
    e.two_sided = m.two_sided;
    e.type = type;
    e.tex_emission = m.tex_emission;
    t.emitters.push_back(e);
    power.push_back(kPi * double(area) * lum(le * scale) * (m.two_sided ? 2.0 : 1.0));
    return t.emitters.back();
  };
  auto emits = [](const Material& m) { return lum(glm::vec3(m.emission.s[0], m.emission.s[1], m.emission.s[2])) > 0.0f; };

  // Emissive triangles (area lights): every triangle of an emissive material.
  for (size_t i = 0; i < scene.triangles.size(); ++i) {
    const Material& m = scene.materials[scene.tri_material[i]];
    if (!emits(m)) continue;
    const auto& tri = scene.triangles[i];
    glm::vec3 a = scene.positions[tri[0]], b = scene.positions[tri[1]], c = scene.positions[tri[2]];
    float area = 0.5f * glm::length(glm::cross(b - a, c - a));
    if (!(area > 0.0f) || !std::isfinite(area)) continue;
    Emitter& e = add_area_light(m, area, uint32_t(i), PSF_EMITTER_TRIANGLE);
    e.v0 = f4(a, area);
    e.e1 = f4(b - a);
    e.e2 = f4(c - a);
  }

  // Emissive analytic spheres: sampled uniformly by area (emitter.cl).
  for (size_t k = 0; k < scene.spheres.size(); ++k) {
    const SphereShape& sp = scene.spheres[k];
    const Material& m = scene.materials[sp.material];
    if (!emits(m)) continue;
    float area = float(4.0 * kPi * double(sp.radius) * double(sp.radius));
    if (!(area > 0.0f) || !std::isfinite(area)) continue;
    Emitter& e = add_area_light(m, area, uint32_t(scene.triangles.size() + k), PSF_EMITTER_SPHERE);
    e.v0 = f4(sp.center, area);
    e.e1 = f4(sp.axis_x, sp.radius);
    e.e2 = f4(sp.axis_y, sp.flip ? -1.0f : 1.0f);
  }

  const double radius = scene_radius(scene);
  const double disk = kPi * radius * radius;
  const LightDesc* env = nullptr;
  for (const LightDesc& l : scene.lights) {
    if (is_environment(l)) {
      if (!env) env = &l;
      continue;
    }
    Emitter e{};
    double phi = 0.0;
    e.radiance = f4(l.color);
    if (l.type == LightType::Point) {
      e.type = PSF_EMITTER_POINT;
      e.v0 = f4(l.position);
      phi = 4.0 * kPi * lum(l.color);
    } else if (l.type == LightType::Spot) {
      e.type = PSF_EMITTER_SPOT;
      e.v0 = f4(l.position);
      float cutoff = std::clamp(l.cutoff_angle, 0.0f, float(kPi));
      float beam = std::clamp(l.beam_width, 0.0f, cutoff);
      e.e1 = f4(glm::normalize(l.direction), std::cos(cutoff));
      e.e2 = {{cutoff, cutoff > beam ? 1.0f / (cutoff - beam) : 0.0f, 0.0f, std::cos(beam)}};
      phi = 2.0 * kPi * lum(l.color) * (1.0 - 0.5 * (std::cos(cutoff) + std::cos(beam)));
    } else {
      e.type = PSF_EMITTER_DIRECTIONAL;
      e.e1 = f4(glm::normalize(l.direction));
      phi = disk * lum(l.color);
    }
    if (!(phi > 0.0) || !std::isfinite(phi)) continue;
    t.emitters.push_back(e);
    power.push_back(phi);
  }

  // The environment: its data buffer and, if it emits, a table entry.
  t.env_data.assign(1, 0.0f);
  if (env) {
    Environment& v = t.env;
    v.present = 1;
    glm::mat3 r = env->to_world;  // columns: the map's axes in world space; rows of its inverse
    v.to_map0 = f4(r[0]);
    v.to_map1 = f4(r[1]);
    v.to_map2 = f4(r[2]);
    v.scale = f4(env->color);
    double integral = 0.0;  // of the luminance over the sphere
    if (env->type == LightType::Constant) {
      integral = 4.0 * kPi * lum(env->color);
    } else {
      const size_t n = size_t(env->width) * size_t(env->height);
      if (env->width < 1 || env->height < 1 || env->texels.size() != 3 * n)
        throw std::invalid_argument(env->source + ": environment map texels do not match its size");
      v.width = uint32_t(env->width);
      v.height = uint32_t(env->height);
      std::vector<float> scaled(env->texels);
      for (size_t i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) scaled[3 * i + k] *= env->color[k];
      EnvDistribution d = build_env_distribution(scaled, env->width, env->height);
      // Solid angle of the (u, v) square: 2 pi^2 sin(theta); sum of f du dv times 2 pi^2.
      integral = 2.0 * kPi * kPi * d.integral;
      t.env_data = env->texels;
      t.env_data.insert(t.env_data.end(), d.marginal.begin(), d.marginal.end());
      t.env_data.insert(t.env_data.end(), d.blocks.begin(), d.blocks.end());
      t.env_data.resize((t.env_data.size() + PSF_ENV_BLOCK - 1) / PSF_ENV_BLOCK * PSF_ENV_BLOCK, 0.0f);
      t.env_data.insert(t.env_data.end(), d.within_block.begin(), d.within_block.end());
      t.env_data.insert(t.env_data.end(), d.guide.begin(), d.guide.end());
    }
    double phi = disk * integral;
    if (phi > 0.0 && std::isfinite(phi)) {
      Emitter e{};
      e.type = PSF_EMITTER_ENVIRONMENT;
      t.emitters.push_back(e);
      power.push_back(phi);
    }
  }

  // The lights at infinity (environment, directional) take their power from
  // the disk of the scene's bounding radius, which a large ground (a sphere of
  // radius 1e5, a huge floor) makes far larger than the part the camera sees:
  // there they took all but 1e-5 of the light samples, and the lamps' rare
  // samples came back as fireflies. Their share of the samples, where there are
  // lights of both kinds, is held within [kMinShare, 1 - kMinShare] (a bound on
  // the variance; any selection keeps the estimate unbiased).
  constexpr double kMinShare = 0.1;
  double infinite = 0.0, finite = 0.0;
  for (size_t i = 0; i < power.size(); ++i) {
    const uint32_t type = t.emitters[i].type;
    (type == PSF_EMITTER_ENVIRONMENT || type == PSF_EMITTER_DIRECTIONAL ? infinite : finite) += power[i];
  }
  if (infinite > 0.0 && finite > 0.0) {
    const double share = infinite / (infinite + finite);
    const double held = std::clamp(share, kMinShare, 1.0 - kMinShare);
    for (size_t i = 0; i < power.size(); ++i) {
      const uint32_t type = t.emitters[i].type;
      power[i] *= type == PSF_EMITTER_ENVIRONMENT || type == PSF_EMITTER_DIRECTIONAL ? held / share
                                                                                     : (1.0 - held) / (1.0 - share);
    }
  }

  // Selection by power: probabilities, cdf, and the per-triangle pdf for MIS.
  double total = 0.0;
  for (double p : power) total += p;
  t.cdf.resize(t.emitters.size());
  t.tri_light_pdf.assign(scene.triangles.size() + scene.spheres.size(), 0.0f);
  double run = 0.0;
  for (size_t i = 0; i < t.emitters.size(); ++i) {
    float pmf = float(power[i] / total);
    Emitter& e = t.emitters[i];
    e.radiance.s[3] = pmf;
    run += power[i];
    t.cdf[i] = float(run / total);
    if (e.type == PSF_EMITTER_TRIANGLE || e.type == PSF_EMITTER_SPHERE) t.tri_light_pdf[e.prim] = pmf / e.v0.s[3];
    if (e.type == PSF_EMITTER_ENVIRONMENT) t.env.scale.s[3] = pmf;
  }
  if (!t.cdf.empty()) t.cdf.back() = 1.0f;
  std::vector<float> guide;
  cdf_guide_table(t.cdf.data(), t.cdf.size(), guide);
  t.cdf.insert(t.cdf.end(), guide.begin(), guide.end());
  return t;
}

}  // namespace psf
