// Named IORs, plastic constants (Fresnel averages, roughplastic's transmittance
// table) and the per-triangle shading attributes; textures are in textures.cpp.
#include "scene/materials.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <thread>
#include <utility>

namespace psf {

namespace {

// A unit tangent and its handedness packed as TriAttrib's n_k.w (psf_shared.h).
float pack_tangent(const glm::vec4& t) {
  glm::vec3 d = glm::vec3(t) / (std::fabs(t.x) + std::fabs(t.y) + std::fabs(t.z));
  glm::vec2 o(d.x, d.y);
  if (d.z < 0.0f)
    o = glm::vec2((1.0f - std::fabs(d.y)) * (d.x < 0.0f ? -1.0f : 1.0f), (1.0f - std::fabs(d.x)) * (d.y < 0.0f ? -1.0f : 1.0f));
  auto q = [](float v) { return uint32_t(std::lround(std::clamp(v, -1.0f, 1.0f) * 16383.0f) + 16383); };
  const uint32_t bits = q(o.x) | (q(o.y) << 15) | (t.w < 0.0f ? 1u << 30 : 0u);
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}

}  // namespace

std::vector<TriAttrib> triangle_attributes(const Scene& scene) {
  std::vector<TriAttrib> out(scene.triangles.size() + scene.spheres.size());
  for (size_t k = scene.triangles.size(); k < out.size(); ++k) {
    out[k].uv01 = {{0, 0, 1, 0}};
    out[k].u2 = 0;
    out[k].v2 = 1;
  }
  const bool has_normals = scene.normals.size() == scene.positions.size();
  const bool has_tangents = has_normals && scene.tangents.size() == scene.positions.size();
  const bool has_uvs = scene.uvs.size() == scene.positions.size();
  const bool has_colors = scene.colors.size() == scene.positions.size();
  // A colour in [0, 1] as TriAttrib packs it: 11, 11 and 10 bits.
  auto pack_color = [](const glm::vec3& c) {
    auto q = [](float v, float levels) { return uint32_t(std::lround(std::clamp(v, 0.0f, 1.0f) * levels)); };
    return q(c.x, 2047.0f) | q(c.y, 2047.0f) << 11 | q(c.z, 1023.0f) << 22;
  };
  for (size_t i = 0; i < scene.triangles.size(); ++i) {
    const glm::uvec3& t = scene.triangles[i];
    TriAttrib& a = out[i];
    if (has_normals) {
      glm::vec3 n[3] = {scene.normals[t.x], scene.normals[t.y], scene.normals[t.z]};
      bool ok = true;
      for (const glm::vec3& v : n) ok = ok && glm::dot(v, v) > 0.0f && std::isfinite(v.x + v.y + v.z);
      if (ok) {
        a.n0 = {{n[0].x, n[0].y, n[0].z, 0}};
        a.n1 = {{n[1].x, n[1].y, n[1].z, 0}};
        a.n2 = {{n[2].x, n[2].y, n[2].z, 0}};
        a.flags |= PSF_TRI_NORMALS;
        if (has_tangents) {
          glm::vec4 tv[3] = {scene.tangents[t.x], scene.tangents[t.y], scene.tangents[t.z]};
          bool all = true;
          for (const glm::vec4& v : tv) all = all && v.w != 0.0f;
          if (all) {
            a.n0.s[3] = pack_tangent(tv[0]);
            a.n1.s[3] = pack_tangent(tv[1]);
            a.n2.s[3] = pack_tangent(tv[2]);
            a.flags |= PSF_TRI_TANGENTS;
          }
        }
      }
    }
    glm::vec2 uv[3] = {{0, 0}, {1, 0}, {0, 1}};  // barycentric (b1, b2), Mitsuba's uv without texcoords
    if (has_uvs) {
      glm::vec2 given[3] = {scene.uvs[t.x], scene.uvs[t.y], scene.uvs[t.z]};
      bool ok = true;
      for (const glm::vec2& v : given) ok = ok && std::isfinite(v.x) && std::isfinite(v.y);
      if (ok) std::copy(given, given + 3, uv);
    }
    a.uv01 = {{uv[0].x, uv[0].y, uv[1].x, uv[1].y}};
    a.u2 = uv[2].x;
    a.v2 = uv[2].y;
    if (has_colors) {
      const glm::vec3 c[3] = {scene.colors[t.x], scene.colors[t.y], scene.colors[t.z]};
      if (c[0].x >= 0.0f && c[1].x >= 0.0f && c[2].x >= 0.0f) {
        a.color0 = pack_color(c[0]);
        a.color1 = pack_color(c[1]);
        a.color2 = pack_color(c[2]);
        a.flags |= PSF_TRI_COLORS;
      }
    }
  }
  return out;
}

void scene_bounds(const Scene& scene, glm::vec3& lo, glm::vec3& hi) {
  lo = glm::vec3(std::numeric_limits<float>::max());
  hi = glm::vec3(-std::numeric_limits<float>::max());
  auto finite = [](const glm::vec3& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); };
  for (const glm::vec3& p : scene.positions)
    if (finite(p)) {
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
  for (const SphereShape& s : scene.spheres)
    if (finite(s.center) && std::isfinite(s.radius)) {
      lo = glm::min(lo, s.center - glm::vec3(s.radius));
      hi = glm::max(hi, s.center + glm::vec3(s.radius));
    }
}

std::vector<Material> device_materials(const Scene& scene, const std::vector<TriAttrib>& attributes) {
  std::vector<Material> out = scene.materials;
  for (Material& m : out) {
    m.flags &= ~PSF_MATFLAG_NORMALS;
    if (m.blend > out.size()) m.blend = 0;  // a partner outside the table: no blend
  }
  for (size_t i = 0; i < attributes.size() && i < scene.tri_material.size(); ++i)
    if ((attributes[i].flags & PSF_TRI_NORMALS) && scene.tri_material[i] < out.size())
      out[scene.tri_material[i]].flags |= PSF_MATFLAG_NORMALS;
  // A blend's partners shade the same triangles: they take the normal flag of
  // the material that names them. (PSF_MATFLAG_VERTEX_COLOR is the loaders':
  // a part multiplies vertex colours only where its colour term reads them.)
  for (int pass = 0; pass < 2; ++pass)
    for (Material& m : out)
      if (m.blend > 0) out[m.blend - 1].flags |= m.flags & PSF_MATFLAG_NORMALS;
  return out;
}

std::vector<bool> masked_prims(const Scene& scene) {
  auto tested = [&](uint32_t m) {
    return m < scene.materials.size() &&
           (scene.materials[m].flags & (PSF_MATFLAG_MASKED | PSF_MATFLAG_NULL_BOUNDARY)) != 0u;
  };
  std::vector<bool> out(scene.triangles.size() + scene.spheres.size(), false);
  for (size_t i = 0; i < scene.tri_material.size() && i < scene.triangles.size(); ++i)
    out[i] = tested(scene.tri_material[i]);
  for (size_t i = 0; i < scene.spheres.size(); ++i) out[scene.triangles.size() + i] = tested(scene.spheres[i].material);
  return out;
}

}  // namespace psf

namespace psf::detail {

std::optional<float> ior_by_name(const std::string& name) {
  // Mitsuba's table of named indices of refraction (ior.h), at 589 nm.
  static const std::map<std::string, float> table = {
      {"vacuum", 1.0f},          {"helium", 1.000036f},      {"hydrogen", 1.000132f},
      {"air", 1.000277f},        {"carbon dioxide", 1.00045f}, {"water", 1.3330f},
      {"acetone", 1.36f},        {"ethanol", 1.361f},        {"carbon tetrachloride", 1.461f},
      {"glycerol", 1.4729f},     {"benzene", 1.501f},        {"silicone oil", 1.52045f},
      {"bromine", 1.661f},       {"water ice", 1.31f},       {"fused quartz", 1.458f},
      {"pyrex", 1.470f},         {"acrylic glass", 1.49f},   {"polypropylene", 1.49f},
      {"bk7", 1.5046f},          {"sodium chloride", 1.544f}, {"amber", 1.55f},
      {"pet", 1.5750f},          {"diamond", 2.419f}};
  std::string key;
  for (char c : name) key += char(std::tolower(static_cast<unsigned char>(c)));
  auto it = table.find(key);
  if (it == table.end()) return std::nullopt;
  return it->second;
}

bool conductor_by_name(const std::string& name, glm::vec3& eta, glm::vec3& k) {
  struct Ior {
    glm::vec3 eta, k;
  };
  // Mitsuba's conductor presets (data/ior/*.spd) in linear sRGB.
  static const std::map<std::string, Ior> table = {
      {"a-C", {{2.9440999183f, 2.2271502925f, 1.9681668794f}, {0.8874329109f, 0.7993216383f, 0.8152862927f}}},
      {"Ag", {{0.1552646489f, 0.1167232965f, 0.1383806959f}, {4.8283433224f, 3.1222459278f, 2.1469504455f}}},
      {"Al", {{1.6574599595f, 0.8803689579f, 0.5212287346f}, {9.2238691996f, 6.2695232477f, 4.8370012281f}}},
      {"AlAs", {{3.6051023902f, 3.2329365777f, 2.2175611545f}, {0.0006670247f, -0.0004999400f, 0.0074261204f}}},
      {"AlSb", {{-0.0485225705f, 4.1427547893f, 4.6697691348f}, {-0.0363741915f, 0.0937665154f, 1.3007390124f}}},
      {"Au", {{0.1431189557f, 0.3749570432f, 1.4424785571f}, {3.9831604247f, 2.3857207478f, 1.6032152899f}}},
      {"Be", {{4.1850592788f, 3.1850604423f, 2.7840913457f}, {3.8354398268f, 3.0101260162f, 2.8690088743f}}},
      {"Cr", {{4.3696828663f, 2.9167024892f, 1.6547005413f}, {5.2064337956f, 4.2313645277f, 3.7549467933f}}},
      {"CsI", {{2.1449030413f, 1.7023164587f, 1.6624194173f}, {0.0f, 0.0f, 0.0f}}},
      {"Cu", {{0.2004376970f, 0.9240334304f, 1.1022119527f}, {3.9129485033f, 2.4528477015f, 2.1421879552f}}},
      {"Cu2O", {{3.5492833755f, 2.9520622449f, 2.7369202137f}, {0.1132179294f, 0.1946659670f, 0.6001681264f}}},
      {"CuO", {{3.2453822204f, 2.4496293965f, 2.1974114493f}, {0.5202739621f, 0.5707372756f, 0.7172250613f}}},
      {"d-C", {{2.7112524747f, 2.3185812849f, 2.2288565009f}, {0.0f, 0.0f, 0.0f}}},
      {"Hg", {{2.3989314904f, 1.4400254917f, 0.9095512090f}, {6.3276269444f, 4.3719414152f, 3.4217899270f}}},
      {"HgTe", {{4.7795267752f, 3.2309984581f, 2.6600252401f}, {1.6319827058f, 1.5808189339f, 1.7295753852f}}},
      {"Ir", {{3.0864098394f, 2.0821938440f, 1.6178866805f}, {5.5921510077f, 4.0671757150f, 3.2672611269f}}},
      {"K", {{0.0640493070f, 0.0464100621f, 0.0381842017f}, {2.1042155920f, 1.3489364357f, 0.9132113889f}}},
      {"Li", {{0.2657871942f, 0.1956102432f, 0.2209198538f}, {3.5401743407f, 2.3111306542f, 1.6685930000f}}},
      {"MgO", {{2.0895885542f, 1.6507224525f, 1.5948759692f}, {0.0f, 0.0f, 0.0f}}},
      {"Mo", {{4.4837010280f, 3.5254578255f, 2.7760769438f}, {4.1111307988f, 3.4208716252f, 3.1506031404f}}},
      {"Na_palik", {{0.0602665320f, 0.0561412435f, 0.0619909494f}, {3.1792906496f, 2.1124800781f, 1.5790940266f}}},
      {"Nb", {{3.4201353595f, 2.7901921379f, 2.3955856658f}, {3.4413817900f, 2.7376437930f, 2.5799132708f}}},
      {"Ni_palik", {{2.3672753521f, 1.6633583302f, 1.4670554172f}, {4.4988329911f, 3.0501643957f, 2.3454274399f}}},
      {"Rh", {{2.5857954933f, 1.8601866068f, 1.5544279524f}, {6.7822927110f, 4.7029501026f, 3.9760892461f}}},
      {"Se-e", {{5.7242724833f, 4.1653992967f, 4.0816099264f}, {0.8713747439f, 1.1052845009f, 1.5647788766f}}},
      {"Se", {{4.0592611085f, 2.8426947380f, 2.8207582835f}, {0.7543791750f, 0.6385150558f, 0.5215872029f}}},
      {"SiC", {{3.1723450205f, 2.5259677964f, 2.4793623897f}, {0.0000007284f, -0.0000006859f, 0.0000100150f}}},
      {"SnTe", {{4.5251865890f, 1.9811525984f, 1.2816819226f}, {0.0f, 0.0f, 0.0f}}},
      {"Ta", {{2.0625846607f, 2.3930915569f, 2.6280684948f}, {2.4080467973f, 1.7413705864f, 1.9470377016f}}},
      {"Te-e", {{7.5090397678f, 4.2964603080f, 2.3698732430f}, {5.5842076830f, 4.9476231084f, 3.9975145063f}}},
      {"Te", {{7.3908396088f, 4.4821028985f, 2.6370708478f}, {3.2561412892f, 3.5273908133f, 3.2921683116f}}},
      {"ThF4", {{1.8307187117f, 1.4422274283f, 1.3876488528f}, {0.0f, 0.0f, 0.0f}}},
      {"TiC", {{3.7004673762f, 2.8374356509f, 2.5823030278f}, {3.2656905818f, 2.3515586388f, 2.1727857800f}}},
      {"TiN", {{1.6484691607f, 1.1504482522f, 1.3797795097f}, {3.3684596226f, 1.9434888540f, 1.1020123347f}}},
      {"TiO2-e", {{3.1065574823f, 2.5131551146f, 2.5823844157f}, {0.0000289537f, -0.0000251484f, 0.0001775555f}}},
      {"TiO2", {{3.4566203131f, 2.8017076558f, 2.9051485020f}, {0.0001026662f, -0.0000897534f, 0.0006356902f}}},
      {"VC", {{3.6575665991f, 2.7527298065f, 2.5326814570f}, {3.0683516659f, 2.1986687713f, 1.9631816252f}}},
      {"VN", {{2.8656011588f, 2.1191817791f, 1.9400767149f}, {3.0323264950f, 2.0561075580f, 1.6162930914f}}},
      {"V", {{4.2775126218f, 3.5131538236f, 2.7611257461f}, {3.4911844504f, 2.8893580874f, 3.1116965117f}}},
      {"W", {{4.3707029924f, 3.3002972445f, 2.9982666528f}, {3.5006778591f, 2.6048652781f, 2.2731930614f}}},
  };
  auto it = table.find(name);
  if (it == table.end() && (name == "Na" || name == "Ni")) it = table.find(name + "_palik");
  if (it == table.end()) return false;
  eta = it->second.eta;
  k = it->second.k;
  return true;
}

void conductor_from_reflectance(const glm::vec3& r, glm::vec3& eta, glm::vec3& k) {
  const glm::vec3 c = glm::clamp(r, 0.0f, PSF_MAX_REFLECTANCE);
  eta = glm::vec3(1.0f);
  k = 2.0f * glm::sqrt(c / (1.0f - c));
}

double fresnel_dielectric(double cos_i, double eta) {
  double s2 = 1.0 - cos_i * cos_i;
  double ct2 = 1.0 - s2 / (eta * eta);
  if (ct2 <= 0.0) return 1.0;
  double ct = std::sqrt(ct2);
  double rs = (cos_i - eta * ct) / (cos_i + eta * ct);
  double rp = (eta * cos_i - ct) / (eta * cos_i + ct);
  return 0.5 * (rs * rs + rp * rp);
}

double fresnel_diffuse_reflectance(double eta) {
  // Midpoint rule in mu^2 (d(mu^2) = 2 mu dmu): smooth except at the critical
  // angle, where 4096 cells leave an error below 1e-5.
  const int n = 4096;
  double sum = 0.0;
  for (int i = 0; i < n; ++i) {
    double mu2 = (i + 0.5) / n;
    sum += fresnel_dielectric(std::sqrt(mu2), eta);
  }
  return sum / n;
}

namespace {

// Smith's G1 for an isotropic distribution, as kernels/bsdf.cl (mf_G1).
double smith_g1(const glm::dvec3& v, const glm::dvec3& m, double alpha, bool beckmann) {
  if (glm::dot(v, m) * v.z <= 0.0) return 0.0;
  double xy = alpha * alpha * (v.x * v.x + v.y * v.y);
  if (xy == 0.0) return 1.0;
  double t2 = xy / (v.z * v.z);
  if (beckmann) {
    double a = 1.0 / std::sqrt(t2);
    return a >= 1.6 ? 1.0 : (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a);
  }
  return 2.0 / (1.0 + std::sqrt(1.0 + t2));
}

// R (transmit false) or T (true) of rough_reflectance and rough_transmittance:
// int f(wo, wi) |cos_i| dwi = E[w(wo.m) G1(wo) G1(wi) (wo.m) / (cos_o cos_m)] for
// m drawn from D(m) cos(theta_m) (dwi = 4 (wo.m) dwm for reflection; the
// refraction's Jacobian cancels likewise against the BTDF), w = F or 1 - F, wi
// the reflected or refracted direction, on a midpoint grid of the inversion
// method's unit square (u, phi) with u = 1 - s^2 (du = 2 s ds): the integrand
// grows like 1 / cos_m ~ (1 - u)^(-1/2) towards grazing normals, which the
// midpoint rule in u resolved badly (transmittance 1 % low at mu = 0.25).
// wo lies in the xz-plane, so the integrand is even in phi: the cells at phi
// and 2 pi - phi are summed once, twice over (half the evaluations, and the
// angles' cosines and sines once per call instead of once per cell).
double rough_scattering(double mu, double alpha, double eta, bool beckmann, bool transmit) {
  const glm::dvec3 wo(std::sqrt(std::max(0.0, 1.0 - mu * mu)), 0.0, mu);
  constexpr int n_theta = 192, n_phi = 96, half_phi = n_phi / 2;
  const double pi = 3.14159265358979323846;
  double cos_phi[half_phi], sin_phi[half_phi];
  for (int j = 0; j < half_phi; ++j) {
    double phi = 2.0 * pi * (j + 0.5) / n_phi;
    cos_phi[j] = std::cos(phi);
    sin_phi[j] = std::sin(phi);
  }
  double sum = 0.0;
  for (int i = 0; i < n_theta; ++i) {
    double s = (i + 0.5) / n_theta, u = 1.0 - s * s, du = 2.0 * s;
    double tan2 = beckmann ? -alpha * alpha * std::log(s * s) : alpha * alpha * u / (s * s);
    double ct = 1.0 / std::sqrt(1.0 + tan2), st = std::sqrt(std::max(0.0, 1.0 - ct * ct));
    for (int j = 0; j < half_phi; ++j) {
      glm::dvec3 m(st * cos_phi[j], st * sin_phi[j], ct);
      double om = glm::dot(wo, m);
      if (om <= 0.0) continue;
      double f = fresnel_dielectric(om, eta), w;
      glm::dvec3 wi;
      if (transmit) {  // Snell's law about m; none past the critical angle
        double sin2_t = (1.0 - om * om) / (eta * eta);
        if (sin2_t >= 1.0) continue;
        wi = -wo / eta + (om / eta - std::sqrt(1.0 - sin2_t)) * m;
        if (wi.z >= 0.0) continue;
        w = 1.0 - f;
      } else {
        wi = 2.0 * om * m - wo;
        if (wi.z <= 0.0) continue;
        w = f;
      }
      double g = smith_g1(wo, m, alpha, beckmann) * smith_g1(wi, m, alpha, beckmann);
      sum += du * w * g * om / (mu * ct);
    }
  }
  return 2.0 * sum / (double(n_theta) * n_phi);
}

}  // namespace

double rough_reflectance(double mu, double alpha, double eta, bool beckmann) {
  return rough_scattering(mu, alpha, eta, beckmann, false);
}

double rough_transmittance(double mu, double alpha, double eta, bool beckmann) {
  return rough_scattering(mu, alpha, eta, beckmann, true);
}

void finish_plastic(Material& m, float diffuse_mean, float specular_mean, TextureStore& store) {
  const double eta = m.eta.s[0];
  m.eta.s[1] = float(1.0 / (eta * eta));
  m.albedo.s[3] = diffuse_mean + specular_mean > 0.0f ? specular_mean / (diffuse_mean + specular_mean) : 0.0f;
  if (m.type == PSF_MATERIAL_PLASTIC || m.type == PSF_MATERIAL_PPLASTIC) {
    m.eta.s[2] = m.type == PSF_MATERIAL_PLASTIC ? float(fresnel_diffuse_reflectance(1.0 / eta)) : 0.0f;
    m.eta.s[3] = float(fresnel_diffuse_reflectance(eta));
    return;
  }
  // roughplastic (Mitsuba 3): the external transmittance T(mu_i) (rough_transmittance,
  // Mitsuba 3's eval_transmittance) at mu_i = i / (N - 1) (at least 1e-6),
  // internal reflectance 2 mean_i(R(mu_i, 1 / eta) mu_i). One
  // row for the material's alpha; with a roughness texture (tex_alpha) a row per
  // roughness r / (ROWS - 1), each followed by its internal and external
  // reflectance, that the kernel interpolates per hit (PSF_MATFLAG_ROUGH_TABLE2D).
  const bool beckmann = (m.flags & PSF_MATFLAG_BECKMANN) != 0;
  // A row's integrals over `threads` threads (each column is three integrals of
  // 192 x 96 microfacet integrand evaluations; 64 columns of the two before the
  // transmittance's took about 60 ms a material on one core), summed in column
  // order whatever the thread count.
  auto row = [&](double alpha, double& internal, double& external, unsigned threads) {
    std::vector<double> outside(PSF_ROUGH_TABLE_RES), inside(PSF_ROUGH_TABLE_RES), through(PSF_ROUGH_TABLE_RES);
    auto column = [&](int i) {
      double mu = std::max(1e-6, double(i) / (PSF_ROUGH_TABLE_RES - 1));
      outside[size_t(i)] = rough_reflectance(mu, alpha, eta, beckmann);
      inside[size_t(i)] = rough_reflectance(mu, alpha, 1.0 / eta, beckmann);
      through[size_t(i)] = rough_transmittance(mu, alpha, eta, beckmann);
    };
    if (threads <= 1) {
      for (int i = 0; i < PSF_ROUGH_TABLE_RES; ++i) column(i);
    } else {
      std::vector<std::thread> workers;
      for (unsigned w = 0; w < threads; ++w)
        workers.emplace_back([&, w] {
          for (int i = int(w); i < PSF_ROUGH_TABLE_RES; i += int(threads)) column(i);
        });
      for (auto& t : workers) t.join();
    }
    std::vector<float> t(PSF_ROUGH_TABLE_RES);
    internal = external = 0.0;
    for (int i = 0; i < PSF_ROUGH_TABLE_RES; ++i) {
      double mu = std::max(1e-6, double(i) / (PSF_ROUGH_TABLE_RES - 1));
      t[size_t(i)] = float(through[size_t(i)]);
      internal += inside[size_t(i)] * mu;
      external += outside[size_t(i)] * mu;
    }
    internal *= 2.0 / PSF_ROUGH_TABLE_RES;
    external *= 2.0 / PSF_ROUGH_TABLE_RES;
    return t;
  };
  const unsigned cores = std::max(1u, std::min(std::thread::hardware_concurrency(), 16u));
  std::ostringstream key;
  key.precision(9);
  key << "roughplastic " << (beckmann ? "beckmann " : "ggx ") << eta;
  double internal = 0.0, external = 0.0;
  if (m.tex_alpha == PSF_NO_TEXTURE) {
    key << " " << m.alpha_u;
    m.flags &= ~PSF_MATFLAG_ROUGH_TABLE2D;
    // OBJ exports often give every material the same Ns and Ni: one row for all.
    const std::vector<double>* known = store.has_table(key.str()) ? store.table_numbers(key.str()) : nullptr;
    if (known && known->size() == 2) {
      internal = (*known)[0];
      external = (*known)[1];
      m.tex_table = store.table(key.str(), {});  // the cached table
    } else {
      m.tex_table = store.table(key.str(), row(m.alpha_u, internal, external, cores));
      store.set_table_numbers(key.str(), {internal, external});
    }
    m.eta.s[2] = float(internal);
    m.eta.s[3] = float(external);
    return;
  }
  // The rows (in parallel: each is a few hundred thousand microfacet integrand
  // evaluations), then eta.z, eta.w and k for the texture's mean alpha, for what
  // reads them before a hit sets its own (kernels/surface.cl rough_table_rows).
  key << " rows " << PSF_ROUGH_TABLE_ROWS;
  std::vector<float> table(size_t(PSF_ROUGH_TABLE_ROWS) * PSF_ROUGH_TABLE_WIDTH);
  std::vector<double> in(PSF_ROUGH_TABLE_ROWS), ex(PSF_ROUGH_TABLE_ROWS);
  auto fill = [&](int r) {
    double rough = double(r) / (PSF_ROUGH_TABLE_ROWS - 1);
    std::vector<float> t = row(std::max(rough * rough, 1e-4), in[size_t(r)], ex[size_t(r)], 1);  // rows in parallel
    float* dst = &table[size_t(r) * PSF_ROUGH_TABLE_WIDTH];
    std::copy(t.begin(), t.end(), dst);
    dst[PSF_ROUGH_TABLE_RES] = float(in[size_t(r)]);
    dst[PSF_ROUGH_TABLE_RES + 1] = float(ex[size_t(r)]);
  };
  if (!store.has_table(key.str())) {
    std::vector<std::thread> workers;
    const int n = int(std::max(1u, std::min(std::thread::hardware_concurrency(), unsigned(PSF_ROUGH_TABLE_ROWS))));
    for (int w = 0; w < n; ++w)
      workers.emplace_back([&, w] {
        for (int r = w; r < PSF_ROUGH_TABLE_ROWS; r += n) fill(r);
      });
    for (auto& t : workers) t.join();
  }
  m.flags |= PSF_MATFLAG_ROUGH_TABLE2D;
  m.tex_table = store.table(key.str(), table, PSF_ROUGH_TABLE_WIDTH);
  const std::vector<float>& stored = store.table_values(m.tex_table);
  double f = std::clamp(std::sqrt(double(m.alpha_u)), 0.0, 1.0) * (PSF_ROUGH_TABLE_ROWS - 1);
  int r = std::min(int(f), PSF_ROUGH_TABLE_ROWS - 2);
  double w = f - r;
  auto at = [&](int row_index, int column) { return double(stored[size_t(row_index) * PSF_ROUGH_TABLE_WIDTH + column]); };
  m.eta.s[2] = float((1 - w) * at(r, PSF_ROUGH_TABLE_RES) + w * at(r + 1, PSF_ROUGH_TABLE_RES));
  m.eta.s[3] = float((1 - w) * at(r, PSF_ROUGH_TABLE_RES + 1) + w * at(r + 1, PSF_ROUGH_TABLE_RES + 1));
  m.k = {{float(w), float(r), 0, 0}};
}

}  // namespace psf::detail
