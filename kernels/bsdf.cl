/* bsdf.cl: scattering at a surface, in a local frame around the shading normal.
 *
 * Interface used by shade.cl (directions point away from the surface; wo towards
 * the previous vertex, wi the sampled or light direction; `table` is the
 * material's tex_table row in the texel buffer, read by roughplastic only:
 * principled's tex_table is its metallic texture, which surface.cl reads):
 *   bsdf_sample(m, table, frame, wo, u1, u2, uc) -> BsdfSample {wi, weight = f |cos| / pdf, pdf, flags}
 *   bsdf_eval(m, table, frame, wo, wi, &pdf)    -> f (without the cosine), pdf of bsdf_sample choosing wi
 *   bsdf_albedo(m)                              -> the colour term path space filtering compares
 *   bsdf_is_diffuse(m)                          -> whether a vertex is diffuse enough to filter at
 *   bsdf_scatters(m), bsdf_transmits(m)         -> whether m reflects anything at all, can transmit
 * (u1, u2) choose the direction, uc the lobe. The Material has its textures already
 * applied (shade.cl). Only the side of the shading normal scatters for reflective
 * types (Mitsuba's one-sided BSDFs; twosided flips the frame in shade.cl);
 * dielectrics scatter on both sides, eta being interior / exterior.
 *
 * The models are Mitsuba 3's plugins of the same names:
 * - diffuse: f = albedo / pi, cosine-weighted sampling (Malley's method over
 *   Shirley-Chiu's concentric disk), so weight = albedo.
 * - conductor: a mirror with the unpolarised Fresnel reflectance of a conductor
 *   with complex IOR eta + i k (Born & Wolf; pbrt-v3 FrConductor) times specular.
 * - roughconductor: the Torrance-Sparrow microfacet BRDF
 *   f = F(wo.h) D(h) G1(wo) G1(wi) / (4 cos_o cos_i) (Walter et al. 2007, Eq. 20)
 *   with GGX or Beckmann D (anisotropic alpha_u, alpha_v), Smith's separable
 *   G1 (Beckmann: Walter's rational approximation, < 0.35 % error). GGX samples
 *   the distribution of visible normals (Heitz 2018, "Sampling the GGX
 *   Distribution of Visible Normals"); Beckmann samples D(h) cos(theta_h).
 *   Single scattering only: energy is lost at high roughness, as in Mitsuba.
 * - plastic: a smooth dielectric coating (eta) on a Lambertian base: specular
 *   Fresnel reflection F(cos_o) (delta) plus the base seen through the coating,
 *   f = albedo' (1 - F(cos_o)) (1 - F(cos_i)) / (pi eta^2) where albedo' =
 *   albedo / (1 - F_dr,int) (or / (1 - albedo F_dr,int) with `nonlinear`)
 *   accounts for internal reflections (Mitsuba's plastic). Lobe choice by
 *   F(cos_o) s / ((F s) + (1 - F)(1 - s)), s = specular sampling weight.
 * - roughplastic: the same with a microfacet coating: the specular lobe is
 *   roughconductor's with dielectric Fresnel; the base term uses the coating's
 *   tabulated external transmittance T(cos) (the microfacet refraction's
 *   directional albedo, Mitsuba 3's eval_transmittance: less than 1 - R, the
 *   rest lost to single scattering) and its internal reflectance (Mitsuba 3's
 *   roughplastic; the host computes them, host/scene/materials.cpp).
 * - pplastic: Mitsuba 3's polarized plastic in its RGB variants, roughconductor's
 *   lobe with dielectric Fresnel F(wo.h) added to albedo (1 - F(cos_o))
 *   (1 - F(cos_i)) / pi, with no internal reflections and no 1 / eta^2 (not
 *   energy conserving, as Mitsuba says). The lobe is chosen by the constant
 *   specular sampling weight mean(s) / (mean(albedo) + mean(s)).
 * - dielectric: Fresnel reflection or refraction (Snell), chosen with
 *   probability F; refraction scales radiance by (eta_i / eta_t)^2 (Veach 1997,
 *   Sec. 5.2; Mitsuba's TransportMode::Radiance).
 * - roughdielectric: Walter et al. 2007, Eq. 20 (reflection) and Eq. 21
 *   (refraction, with the same radiance scaling), the normal sampled as above
 *   for the side of wo, reflection chosen with probability F(wo.h).
 * - thindielectric: a thin sheet: reflection R = F + T^2 F / (1 - F^2) from the
 *   inter-reflections inside it (T = 1 - F), transmission straight through with
 *   1 - R (Mitsuba's thindielectric).
 * - principled: Mitsuba 3's Disney-style BSDF (Burley, "Physically Based
 *   Shading at Disney", 2012; "Extending the Disney BRDF to a BSDF with
 *   Integrated Subsurface Scattering", 2015), lobe for lobe as Mitsuba 3.6
 *   evaluates it (psf_shared.h has the parameters; M metallic, T spec_trans):
 *   diffuse (1 - M)(1 - T) base / pi ((1 - F_o/2)(1 - F_i/2) + retro-reflection
 *   R_r (F_o + F_i + F_o F_i (R_r - 1)), R_r = 2 roughness cos^2 theta_d, blended
 *   towards the Hanrahan-Krueger-like flatness term), sheen (F_d weighted,
 *   tinted), a GGX microfacet reflection whose Fresnel mixes the dielectric's
 *   with Schlick's of base (metallic) and of the tinted dielectric (spec_tint),
 *   GGX transmission sqrt(base)(1 - M) T (Walter et al. Eq. 21), and a GTR1
 *   clearcoat 0.25 clearcoat F_cc D_cc G_cc (Schlick 0.04, alpha from 0.1 to
 *   0.001 with clearcoat_gloss, G of GGX alpha 0.25), F = (1 - cos)^5 Schlick
 *   weights. Not energy conserving (the lobes add), as Mitsuba's. Sampling
 *   picks diffuse, clearcoat or the main specular lobe by the sampling rates
 *   (diffuse weighted by (1 - M)(1 - T), clearcoat by clearcoat / 4), then for
 *   the specular a GGX visible normal and reflection with probability
 *   1 - T (1 - M)(1 - F) (from inside: F); the pdf is the mixture's.
 * - principledthin: Mitsuba 3's thin principled BSDF (Burley 2015, Sec. 4):
 *   a sheet with one medium on both sides, the same seen from either (o and i
 *   turned together so that o lies in front). With T spec_trans and D
 *   diff_trans / 2: GGX reflection T F_thin D G / (4 cos_o cos_i), F_thin the
 *   dielectric Fresnel F(o.h) blended towards the tinted Schlick term by
 *   spec_tint; specular transmission, the reflection's mirror image through the
 *   sheet (no bending), T base (1 - F) D' G' / (4 |cos_o cos_i|) with GGX
 *   alphas from the roughness scaled by 0.65 eta - 0.35 (Burley 2015, Fig. 15);
 *   principled's diffuse (retro-reflection, flatness) and sheen times
 *   (1 - T)(1 - D); Lambertian transmission (1 - T) D base / pi. Sampling picks
 *   specular reflection, specular transmission, cosine reflection or cosine
 *   transmission in proportion to rate T / 2, rate T / 2, rate (1 - T)(1 - D)
 *   and rate (1 - T) D; the pdf is the mixture's. */

#define PSF_PI 3.14159265358979323846f
#define PSF_INV_PI 0.31830988618379067154f

#define BSDF_DELTA 1u        /* the sampled lobe is a Dirac delta: pdf is not comparable */
#define BSDF_TRANSMISSION 2u /* wi is on the other side of the surface */

/* The filtering vertex rule (bsdf_is_diffuse): microfacet lobes count as diffuse
 * above this roughness sqrt(alpha_u alpha_v) ... */
#define PSF_DIFFUSE_ALPHA 0.3f
/* ... and plastics when the base reflects at least this many times as much as
 * the coating under uniform illumination: 1, at least half of the reflected
 * light. (4, which psf used before, left textured floors' glossy rough plastics,
 * the living room's and the staircase's, to the next vertex: their filtering
 * vertices lay scattered over the room and found few neighbours.) */
#define PSF_PLASTIC_DIFFUSE_RATIO 1.0f

/* An orthonormal frame: s, t tangents and n the shading normal. */
typedef struct {
  float3 s;
  float3 t;
  float3 n;
} Frame;

typedef struct {
  float3 wi;     /* sampled direction, world space */
  float3 weight; /* f |cos theta_i| / pdf */
  float pdf;     /* solid-angle pdf (0 for a delta lobe, or when sampling failed) */
  uint flags;    /* BSDF_* */
} BsdfSample;

/* Frame around unit n (Duff et al. 2017, "Building an Orthonormal Basis, Revisited"). */
inline Frame frame_from_normal(float3 n) {
  float sign = n.z >= 0.0f ? 1.0f : -1.0f;
  float a = -1.0f / (sign + n.z);
  float c = n.x * n.y * a;
  Frame f;
  f.s = (float3)(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
  f.t = (float3)(c, sign + n.y * n.y * a, -n.y);
  f.n = n;
  return f;
}

/* Frame around unit n whose s is the tangent `dpdu` projected into the tangent
 * plane (Mitsuba's shading frame: anisotropic roughness follows dp/du). */
inline Frame frame_from_normal_tangent(float3 n, float3 dpdu) {
  float3 s = dpdu - n * dot(n, dpdu);
  float len = length(s);
  if (!(len > 1e-20f)) return frame_from_normal(n);
  Frame f;
  f.n = n;
  f.s = s / len;
  f.t = cross(n, f.s);
  return f;
}

inline float3 frame_to_local(Frame f, float3 v) { return (float3)(dot(v, f.s), dot(v, f.t), dot(v, f.n)); }
inline float3 frame_to_world(Frame f, float3 v) { return v.x * f.s + v.y * f.t + v.z * f.n; }

/* Shirley-Chiu concentric map of [0,1)^2 onto the unit disk. With selects
 * instead of branches: which of |a|, |b| is larger is a coin toss per sample,
 * and a mispredicted branch on it cost more than the one division both share. */
inline float2 square_to_disk(float u1, float u2) {
  float a = 2.0f * u1 - 1.0f, b = 2.0f * u2 - 1.0f;
  bool wide = fabs(a) > fabs(b), centre = a == 0.0f && b == 0.0f;
  float r = wide ? a : b; /* 0 only at the centre, which maps to r = 0 whatever phi is */
  float q = (wide ? b : a) / (centre ? 1.0f : r);
  float phi = wide ? (PSF_PI / 4.0f) * q : (PSF_PI / 2.0f) - (PSF_PI / 4.0f) * q;
  float c;
  float s = psf_sincos(phi, &c);
  return (float2)(r * c, r * s);
}

/* Cosine-weighted direction in the local frame (z up). */
inline float3 square_to_cosine_hemisphere(float u1, float u2) {
  float2 d = square_to_disk(u1, u2);
  return (float3)(d.x, d.y, sqrt(fmax(0.0f, 1.0f - d.x * d.x - d.y * d.y)));
}

inline float bsdf_mean3(float3 v) { return (v.x + v.y + v.z) * (1.0f / 3.0f); }

/* --- Fresnel ------------------------------------------------------------- */

/* Unpolarised Fresnel reflectance of a dielectric interface, eta = interior /
 * exterior IOR, for a direction with cosine cos_i to the normal (negative: it lies
 * inside). *cos_t gets the cosine of the refracted direction (sign opposite to
 * cos_i; 0 on total internal reflection), *eta_ti the IOR ratio of the
 * direction's side over the other side (refraction scales tangential components
 * by it). */
inline float fresnel_dielectric(float cos_i, float eta, float* cos_t, float* eta_ti) {
  float n = cos_i >= 0.0f ? eta : 1.0f / eta; /* transmitted over incident IOR */
  float ci = fabs(cos_i);
  float ct2 = 1.0f - (1.0f - ci * ci) / (n * n);
  *eta_ti = 1.0f / n;
  if (ct2 <= 0.0f) {
    *cos_t = 0.0f;
    return 1.0f;
  }
  float ct = sqrt(ct2);
  *cos_t = cos_i >= 0.0f ? -ct : ct;
  float rs = (ci - n * ct) / (ci + n * ct);
  float rp = (n * ci - ct) / (n * ci + ct);
  return 0.5f * (rs * rs + rp * rp);
}

/* Unpolarised Fresnel reflectance of a conductor with relative complex IOR
 * eta + i k, for 0 <= cos_i <= 1. */
inline float3 fresnel_conductor(float cos_i, float3 eta, float3 k) {
  float c2 = cos_i * cos_i, s2 = 1.0f - c2, s4 = s2 * s2;
  float3 t1 = eta * eta - k * k - s2;
  float3 a2b2 = sqrt(t1 * t1 + 4.0f * k * k * eta * eta);
  float3 a = sqrt(fmax(0.5f * (a2b2 + t1), 0.0f));
  float3 term1 = a2b2 + c2, term2 = 2.0f * cos_i * a;
  float3 rs = (term1 - term2) / (term1 + term2);
  float3 term3 = a2b2 * c2 + s4, term4 = term2 * s2;
  float3 rp = rs * (term3 - term4) / (term3 + term4);
  return 0.5f * (rs + rp);
}

/* A conductor whose Fresnel reflectance at normal incidence is r (clamped to
 * [0, PSF_MAX_REFLECTANCE]) and rises to 1 at grazing angles: eta = 1 and
 * k = 2 sqrt(r / (1 - r)), since F(1) = ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2)
 * = k^2 / (4 + k^2) (pbrt-v4's conductor `reflectance`; glTF's metals). */
inline void conductor_from_reflectance(Material* m, float3 r) {
  r = clamp(r, 0.0f, PSF_MAX_REFLECTANCE);
  m->eta.xyz = (float3)(1.0f);
  m->k.xyz = 2.0f * sqrt(r / (1.0f - r));
  m->specular.xyz = (float3)(1.0f);
}

/* --- Microfacet distributions ------------------------------------------- */

/* D(m): GGX (Trowbridge-Reitz) or Beckmann, anisotropic (Walter et al. 2007). */
inline float mf_D(float3 m, float au, float av, bool beckmann) {
  float ct = m.z;
  if (ct <= 0.0f) return 0.0f;
  float x = m.x / au, y = m.y / av, ct2 = ct * ct, r;
  if (beckmann) {
    r = exp(-(x * x + y * y) / ct2) / (PSF_PI * au * av * ct2 * ct2);
  } else {
    float d = x * x + y * y + ct2;
    r = 1.0f / (PSF_PI * au * av * d * d);
  }
  return r * ct > 1e-20f ? r : 0.0f;
}

/* Smith's G1(v, m), 0 where v sees the back of m. */
inline float mf_G1(float3 v, float3 m, float au, float av, bool beckmann) {
  if (dot(v, m) * v.z <= 0.0f) return 0.0f;
  float xy = au * au * v.x * v.x + av * av * v.y * v.y;
  if (xy == 0.0f) return 1.0f;
  float t2 = xy / (v.z * v.z);
  if (beckmann) {
    float a = rsqrt(t2);
    return a >= 1.6f ? 1.0f : (3.535f * a + 2.181f * a * a) / (1.0f + 2.276f * a + 2.577f * a * a);
  }
  return 2.0f / (1.0f + sqrt(1.0f + t2));
}

/* A microfacet normal for direction v (v.z > 0): GGX's visible normals, Beckmann's D(m) cos(theta_m). */
inline float3 mf_sample(float3 v, float au, float av, bool beckmann, float u1, float u2) {
  if (beckmann) {
    float phi = 2.0f * PSF_PI * u2;
    float cp;
    float sp = psf_sincos(phi, &cp);
    if (au != av) sp = psf_sincos(atan2(av * sp, au * cp), &cp);
    float inv_a2 = cp * cp / (au * au) + sp * sp / (av * av);
    float tan2 = -log(1.0f - u1) / inv_a2;
    float ct = rsqrt(1.0f + tan2), st = sqrt(fmax(0.0f, 1.0f - ct * ct));
    return (float3)(st * cp, st * sp, ct);
  }
  float3 vh = normalize((float3)(au * v.x, av * v.y, v.z));
  float lensq = vh.x * vh.x + vh.y * vh.y;
  float3 t1 = lensq > 0.0f ? (float3)(-vh.y, vh.x, 0.0f) * rsqrt(lensq) : (float3)(1.0f, 0.0f, 0.0f);
  float3 t2 = cross(vh, t1);
  float r = sqrt(u1), phi = 2.0f * PSF_PI * u2;
  float cos_phi;
  float sin_phi = psf_sincos(phi, &cos_phi);
  float p1 = r * cos_phi, p2 = r * sin_phi;
  float s = 0.5f * (1.0f + vh.z);
  p2 = (1.0f - s) * sqrt(fmax(0.0f, 1.0f - p1 * p1)) + s * p2;
  float3 nh = p1 * t1 + p2 * t2 + sqrt(fmax(0.0f, 1.0f - p1 * p1 - p2 * p2)) * vh;
  return normalize((float3)(au * nh.x, av * nh.y, fmax(1e-6f, nh.z)));
}

/* The density of mf_sample's normal m for direction v (v.z > 0). */
inline float mf_pdf(float3 v, float3 m, float au, float av, bool beckmann) {
  float d = mf_D(m, au, av, beckmann);
  if (beckmann) return d * m.z;
  return d * mf_G1(v, m, au, av, beckmann) * fabs(dot(v, m)) / v.z;
}

/* --- Material queries ----------------------------------------------------- */

inline bool bsdf_transmits(Material m) {
  return m.type == PSF_MATERIAL_DIELECTRIC || m.type == PSF_MATERIAL_ROUGH_DIELECTRIC ||
         m.type == PSF_MATERIAL_THIN_DIELECTRIC ||
         (m.type == PSF_MATERIAL_PRINCIPLED && m.specular.y > 0.0f) || /* by spec_trans, whatever metallic's texel */
         (m.type == PSF_MATERIAL_PRINCIPLED_THIN && (m.specular.y > 0.0f || m.specular.x > 0.0f));
}

/* Whether bsdf_sample reads uc (a choice between lobes). */
inline bool bsdf_chooses_lobe(Material m) {
  return m.type == PSF_MATERIAL_PLASTIC || m.type == PSF_MATERIAL_ROUGH_PLASTIC ||
         m.type == PSF_MATERIAL_PPLASTIC || m.type == PSF_MATERIAL_PRINCIPLED ||
         m.type == PSF_MATERIAL_PRINCIPLED_THIN || bsdf_transmits(m);
}

inline bool bsdf_is_plastic(Material m) {
  return m.type == PSF_MATERIAL_PLASTIC || m.type == PSF_MATERIAL_ROUGH_PLASTIC;
}

/* Whether anything is reflected or transmitted at all. */
inline bool bsdf_scatters(Material m) {
  float s = fmax(max(m.specular.x, max(m.specular.y, m.specular.z)),
                 max(m.transmittance.x, max(m.transmittance.y, m.transmittance.z)));
  float d = max(m.albedo.x, max(m.albedo.y, m.albedo.z));
  if (m.type == PSF_MATERIAL_DIFFUSE) return d > 0.0f;
  if (bsdf_is_plastic(m) || m.type == PSF_MATERIAL_PPLASTIC) return fmax(d, s) > 0.0f;
  if (m.type == PSF_MATERIAL_PRINCIPLED) return true; /* its dielectric Fresnel reflects at any base colour */
  if (m.type == PSF_MATERIAL_PRINCIPLED_THIN) return m.specular.y > 0.0f || d > 0.0f;
  return s > 0.0f;
}

/* The colour term compared by path space filtering: the (textured) diffuse
 * reflectance of diffuse and plastic materials, a conductor's reflectance at
 * normal incidence, a dielectric's specular transmittance. */
inline float3 bsdf_albedo(Material m) {
  if (m.type == PSF_MATERIAL_DIFFUSE || bsdf_is_plastic(m) || m.type == PSF_MATERIAL_PPLASTIC ||
      m.type == PSF_MATERIAL_PRINCIPLED || m.type == PSF_MATERIAL_PRINCIPLED_THIN)
    return m.albedo.xyz;
  if (m.type == PSF_MATERIAL_CONDUCTOR || m.type == PSF_MATERIAL_ROUGH_CONDUCTOR)
    return m.specular.xyz * fresnel_conductor(1.0f, m.eta.xyz, m.k.xyz);
  return m.transmittance.xyz;
}

/* Whether a vertex with this material is diffuse enough to be the filtering
 * vertex: diffuse always; rough conductors and dielectrics when their roughness
 * sqrt(alpha_u alpha_v) exceeds PSF_DIFFUSE_ALPHA; plastics when that holds or
 * when the base reflects at least as much as the coating, mean(albedo) (1 - F_ext) >=
 * PSF_PLASTIC_DIFFUSE_RATIO mean(specular) F_ext (F_ext, in eta.w: the coating's
 * reflectance under uniform illumination; pplastic's likewise); principled likewise, its base
 * weighted by (1 - M)(1 - T) against the specular lobes' reflectance under
 * uniform illumination in Schlick's approximation (the hemispherical mean of
 * R0 + (1 - R0)(1 - cos)^5 is R0 + (1 - R0) / 21: M base, (1 - M) times the
 * dielectric's R0, clearcoat / 4 times 0.04's); principledthin likewise, its
 * diffuse lobes weighted by (1 - T) against T times the specular reflection's
 * Schlick mean plus the specular transmission's base (1 - R0); smooth conductors
 * and dielectrics, thin dielectrics: never. */
inline bool bsdf_is_diffuse(Material m) {
  if (m.type == PSF_MATERIAL_DIFFUSE) return true;
  bool rough = m.type == PSF_MATERIAL_ROUGH_CONDUCTOR || m.type == PSF_MATERIAL_ROUGH_DIELECTRIC ||
               m.type == PSF_MATERIAL_ROUGH_PLASTIC || m.type == PSF_MATERIAL_PPLASTIC ||
               m.type == PSF_MATERIAL_PRINCIPLED || m.type == PSF_MATERIAL_PRINCIPLED_THIN;
  if (rough && m.alpha_u * m.alpha_v > PSF_DIFFUSE_ALPHA * PSF_DIFFUSE_ALPHA) return true;
  if (bsdf_is_plastic(m) || m.type == PSF_MATERIAL_PPLASTIC)
    return bsdf_mean3(m.albedo.xyz) * (1.0f - m.eta.w) >=
           PSF_PLASTIC_DIFFUSE_RATIO * bsdf_mean3(m.specular.xyz) * m.eta.w;
  if (m.type == PSF_MATERIAL_PRINCIPLED) {
    float metallic = m.specular.x, base = bsdf_mean3(m.albedo.xyz), r = (m.eta.x - 1.0f) / (m.eta.x + 1.0f);
    float r0 = r * r, mean = 1.0f / 21.0f;
    float spec = metallic * (base + (1.0f - base) * mean) + (1.0f - metallic) * (r0 + (1.0f - r0) * mean) +
                 0.25f * m.transmittance.z * (0.04f + 0.96f * mean);
    return (1.0f - metallic) * (1.0f - m.specular.y) * base >= PSF_PLASTIC_DIFFUSE_RATIO * spec;
  }
  if (m.type == PSF_MATERIAL_PRINCIPLED_THIN) {
    float base = bsdf_mean3(m.albedo.xyz), r = (m.eta.x - 1.0f) / (m.eta.x + 1.0f), r0 = r * r;
    float spec = m.specular.y * (r0 + (1.0f - r0) / 21.0f + (1.0f - r0) * base);
    return (1.0f - m.specular.y) * base >= PSF_PLASTIC_DIFFUSE_RATIO * spec;
  }
  return false;
}

/* --- Evaluation ------------------------------------------------------------ */

/* A plastic's base reflectance divided by the internal reflections' loss. */
inline float3 plastic_base(Material m) {
  float3 d = m.albedo.xyz;
  return (m.flags & PSF_MATFLAG_NONLINEAR) ? d / (1.0f - d * m.eta.z) : d / (1.0f - m.eta.z);
}

/* roughplastic's external transmittance T(cos) from its table; 1 - F(cos) (the
 * smooth coat's) for a material made without one. */
inline float rough_transmittance(Material m, __global const half* table, float cos_t) {
  if (m.flags & PSF_MATFLAG_ROUGH_TABLE2D) /* the two rows around the hit's roughness (surface.cl) */
    return mix(table_lookup(table, cos_t), table_lookup(table + 4u * PSF_ROUGH_TABLE_WIDTH, cos_t), m.k.x);
  if (m.tex_table != PSF_NO_TEXTURE) return table_lookup(table, cos_t);
  float c, e;
  return 1.0f - fresnel_dielectric(cos_t, m.eta.x, &c, &e);
}

/* Probability of choosing a plastic's coating lobe, given the coating's
 * reflectance r (F(cos_o) smooth, 1 - T(cos_o) rough) at wo. */
inline float plastic_prob_specular(Material m, float r) {
  float ps = r * m.albedo.w, pd = (1.0f - r) * (1.0f - m.albedo.w);
  return ps + pd > 0.0f ? ps / (ps + pd) : 0.0f;
}

/* --- principled (Mitsuba 3) ---------------------------------------------- */

/* (1 - c)^5 for c clamped to [0, 1]: Schlick's weight. */
inline float principled_schlick_weight(float c) {
  float m = clamp(1.0f - c, 0.0f, 1.0f), m2 = m * m;
  return m2 * m2 * m;
}

/* The weight w of Schlick's F = R0 + (1 - R0) w at a microfacet cosine cos_i
 * (negative: from inside) of an interface of relative IOR eta: the cosine on the
 * side of the lower index (the refracted one where the ray comes from the higher). */
inline float principled_schlick(float cos_i, float eta) {
  float eta_it = cos_i >= 0.0f ? eta : 1.0f / eta;
  if (eta_it > 1.0f) return principled_schlick_weight(fabs(cos_i));
  float ct2 = 1.0f - (1.0f - cos_i * cos_i) / (eta_it * eta_it);
  return principled_schlick_weight(sqrt(fmax(ct2, 0.0f)));
}

/* The dielectric Fresnel reflectance of principled's interface: exactly 0 where
 * the indices match (eta 1, Mitsuba's `specular` 0), as Mitsuba's fresnel()
 * has it, which then leaves out the whole main reflection lobe, tints
 * included (fresnel_dielectric rounds to tiny values there, or to 0). */
inline float principled_fresnel(float cos_i, float eta, float* cos_t, float* eta_ti) {
  if (eta == 1.0f) {
    *cos_t = -cos_i;
    *eta_ti = 1.0f;
    return 0.0f;
  }
  return fresnel_dielectric(cos_i, eta, cos_t, eta_ti);
}

/* The base colour over its luminance (Rec. 709, Mitsuba's luminance()), 1 for
 * black: the hue that spec_tint and sheen_tint tint towards. */
inline float3 principled_tint(float3 base) {
  float lum = 0.212671f * base.x + 0.715160f * base.y + 0.072169f * base.z;
  return lum > 0.0f ? base / lum : (float3)(1.0f);
}

/* The clearcoat's GTR1 distribution D(m) (Burley 2012, Eq. 4 with gamma = 1). */
inline float principled_gtr1(float cos_m, float a) {
  float a2 = a * a;
  float r = (a2 - 1.0f) / (PSF_PI * log(a2) * (1.0f + (a2 - 1.0f) * cos_m * cos_m));
  return r * cos_m > 1e-20f ? r : 0.0f;
}

/* Smith's G1 of an isotropic GGX of roughness a (the clearcoat's masking). */
inline float principled_ggx_g1(float3 v, float3 m, float a) {
  if (dot(v, m) * v.z <= 0.0f) return 0.0f;
  if (v.z == 1.0f) return 1.0f;
  float c2 = v.z * v.z, t2 = (1.0f - c2) / c2;
  return 2.0f / (1.0f + sqrt(1.0f + a * a * t2));
}

/* The clearcoat's roughness: from 0.1 to 0.001 as clearcoat_gloss goes from 0 to 1. */
inline float principled_clearcoat_alpha(Material m) { return mix(0.1f, 0.001f, m.transmittance.w); }

/* The lobe probabilities of sampling from o's side: diffuse, clearcoat and the
 * main specular lobe (which then reflects or refracts), summing to 1; from
 * inside only the specular, where anything transmits. */
inline float3 principled_lobes(Material m, bool front) {
  if (!front) return (float3)(0.0f, 0.0f, (1.0f - m.specular.x) * m.specular.y > 0.0f ? 1.0f : 0.0f);
  float3 p = (float3)((1.0f - m.specular.x) * (1.0f - m.specular.y) * m.k.z, 0.25f * m.transmittance.z * m.k.y, m.k.x);
  float t = p.x + p.y + p.z;
  return t > 0.0f ? p / t : (float3)(0.0f, 0.0f, 1.0f);
}

/* The diffuse term of principled and principledthin without base / pi, for
 * cosines co, ci > 0 and cos_d = <h, i>: Burley's (1 - F_o / 2)(1 - F_i / 2)
 * plus retro-reflection R_r (F_o + F_i + F_o F_i (R_r - 1)), R_r = 2 roughness
 * cos_d^2, blended towards the Hanrahan-Krueger-like flatness term. */
inline float principled_diffuse(Material m, float co, float ci, float cos_d) {
  float fo = principled_schlick_weight(ci), fi = principled_schlick_weight(co), rr = 2.0f * m.eta.z * cos_d * cos_d;
  float diffuse = (1.0f - 0.5f * fi) * (1.0f - 0.5f * fo) + rr * (fo + fi + fo * fi * (rr - 1.0f));
  float flatness = m.transmittance.y;
  if (flatness > 0.0f) {
    float fss = mix(1.0f, 0.5f * rr, fo) * mix(1.0f, 0.5f * rr, fi);
    float ss = 1.25f * (fss * (1.0f / (co + ci) - 0.5f) + 0.5f);
    diffuse = mix(diffuse, ss, flatness);
  }
  return diffuse;
}

/* f and pdf of principled in the local frame (o = wo, i = wi). */
inline float3 principled_eval(Material m, float3 o, float3 i, float* pdf) {
  *pdf = 0.0f;
  float co = o.z, ci = i.z;
  if (co == 0.0f || ci == 0.0f) return (float3)(0.0f);
  float metallic = m.specular.x, spec_trans = m.specular.y, eta = m.eta.x, au = m.alpha_u, av = m.alpha_v;
  float brdf = (1.0f - metallic) * (1.0f - spec_trans), btdf = (1.0f - metallic) * spec_trans;
  float3 base = m.albedo.xyz;
  bool reflect = co * ci > 0.0f, front = co > 0.0f;
  float eta_p = front ? eta : 1.0f / eta; /* IOR of i's side over o's side, for refraction */
  float3 h = normalize(o + i * (reflect ? 1.0f : eta_p));
  if (h.z < 0.0f) h = -h;
  float oh = dot(o, h), ih = dot(i, h);
  float side = front ? 1.0f : -1.0f; /* neither direction may see the back of the microfacet */
  bool micro_r = reflect && oh * side > 0.0f && ih * side > 0.0f;
  bool micro_t = !reflect && oh * side > 0.0f && ih * side < 0.0f;
  float cos_t, eta_ti;
  float fd = principled_fresnel(oh, eta, &cos_t, &eta_ti);
  float d = mf_D(h, au, av, false);
  float g = mf_G1(o, h, au, av, false) * mf_G1(i, h, au, av, false);
  float3 of = front ? o : -o;
  float pm = mf_pdf(of, h, au, av, false);
  float3 lobes = principled_lobes(m, front);
  float3 f = (float3)(0.0f);
  /* Schlick's weight at the microfacet, for the front's tinted specular and its clearcoat. */
  float w = front && micro_r ? principled_schlick(oh, eta) : 0.0f;
  if (micro_r) { /* main specular reflection: sampled even where fd = 0, so its pdf counts there too */
    float prefl = front ? 1.0f - btdf * (1.0f - fd) : fd;
    *pdf += lobes.z * prefl * pm / (4.0f * fabs(ih));
  }
  if (micro_r && fd > 0.0f) {
    float3 F;
    if (front) {
      float eta_it = oh >= 0.0f ? eta : 1.0f / eta, r = (eta_it - 1.0f) / (eta_it + 1.0f);
      float3 r0 = principled_tint(base) * (r * r);
      float spec_tint = m.specular.z;
      F = (1.0f - metallic) * (1.0f - spec_tint) * fd + metallic * (base + (1.0f - base) * w) +
          (1.0f - metallic) * spec_tint * (r0 + (1.0f - r0) * w);
    } else {
      F = (float3)(btdf * fd);
    }
    f += F * (d * g / (4.0f * fabs(co * ci)));
  }
  if (micro_t && btdf > 0.0f) { /* main specular transmission, radiance scaled by 1 / eta_p^2 */
    float denom = oh + eta_p * ih;
    if (fd < 1.0f) f += sqrt(base) * (btdf * fabs((1.0f - fd) * d * g * oh * ih / (co * ci * denom * denom)));
    float ptrans = front ? btdf * (1.0f - fd) : 1.0f - fd;
    *pdf += lobes.z * ptrans * pm * eta_p * eta_p * fabs(ih) / (denom * denom);
  }
  if (front && micro_r && m.transmittance.z > 0.0f) { /* clearcoat */
    float a = principled_clearcoat_alpha(m);
    float dcc = principled_gtr1(h.z, a);
    float fcc = 0.04f + 0.96f * w;
    float gcc = principled_ggx_g1(o, h, 0.25f) * principled_ggx_g1(i, h, 0.25f);
    f += (float3)(0.25f * m.transmittance.z * fcc * dcc * gcc);
    *pdf += lobes.y * dcc * h.z / (4.0f * fabs(ih));
  }
  if (front && reflect && brdf > 0.0f) { /* diffuse, retro-reflection, flatness, sheen */
    float cos_d = dot(h, i), diffuse = principled_diffuse(m, co, ci, cos_d);
    f += base * (brdf * PSF_INV_PI * diffuse);
    float sheen = m.specular.w;
    if (sheen > 0.0f)
      f += mix((float3)(1.0f), principled_tint(base), m.transmittance.x) *
           (sheen * (1.0f - metallic) * principled_schlick_weight(cos_d));
    *pdf += lobes.x * ci * PSF_INV_PI;
  }
  return f;
}

/* --- principledthin (Mitsuba 3) ------------------------------------------- */

/* The lobe probabilities of principledthin: specular reflection, specular
 * transmission, cosine reflection, cosine transmission (sampling rates k). */
inline float4 thin_lobes(Material m) {
  float t = m.specular.y, d = m.specular.x;
  float4 p = (float4)(0.5f * t * m.k.x, 0.5f * t * m.k.y, (1.0f - t) * (1.0f - d) * m.k.z, (1.0f - t) * d * m.k.w);
  float sum = p.x + p.y + p.z + p.w;
  return sum > 0.0f ? p / sum : (float4)(0.0f, 0.0f, 1.0f, 0.0f);
}

/* f and pdf of principledthin in the local frame (o = wo, i = wi): both turned
 * so that o lies in front (the sheet is the same from either side); h is the
 * half-vector of o and i mirrored into o's hemisphere, for reflection and
 * transmission alike (transmission is reflection carried through the sheet). */
inline float3 thin_eval(Material m, float3 o, float3 i, float* pdf) {
  *pdf = 0.0f;
  if (o.z == 0.0f || i.z == 0.0f) return (float3)(0.0f);
  if (o.z < 0.0f) {
    o = -o;
    i = -i;
  }
  float co = o.z, ci = fabs(i.z), spec_trans = m.specular.y, diff_trans = m.specular.x;
  bool reflect = i.z > 0.0f;
  float3 ir = (float3)(i.x, i.y, ci);
  float3 h = normalize(o + ir);
  float oh = dot(o, h), ih = dot(i, h);
  /* Mitsuba's macro-micro compatibility: o in front of the microfacet, and i
   * in front of it (reflection) or behind it (transmission). */
  bool micro = oh > 0.0f && (reflect ? ih > 0.0f : ih < 0.0f);
  float3 base = m.albedo.xyz;
  float4 lobes = thin_lobes(m);
  float3 f = (float3)(0.0f);
  if (spec_trans > 0.0f && micro) {
    float cos_t, eta_ti;
    float fd = principled_fresnel(oh, m.eta.x, &cos_t, &eta_ti);
    float jacobian = 1.0f / (4.0f * fabs(dot(ir, h))); /* dh / di */
    if (reflect) {
      float d = mf_D(h, m.alpha_u, m.alpha_v, false);
      float g = mf_G1(o, h, m.alpha_u, m.alpha_v, false) * mf_G1(i, h, m.alpha_u, m.alpha_v, false);
      float3 F = (float3)(fd);
      float spec_tint = m.specular.z;
      if (spec_tint > 0.0f) {
        float r = (m.eta.x - 1.0f) / (m.eta.x + 1.0f);
        float3 r0 = principled_tint(base) * (r * r);
        F = mix(F, r0 + (1.0f - r0) * principled_schlick(oh, m.eta.x), spec_tint);
      }
      f += F * (spec_trans * d * g / (4.0f * co * ci));
      *pdf += lobes.x * mf_pdf(o, h, m.alpha_u, m.alpha_v, false) * jacobian;
    } else {
      float atu = m.transmittance.z, atv = m.transmittance.w;
      float d = mf_D(h, atu, atv, false);
      float g = mf_G1(o, h, atu, atv, false) * mf_G1(i, h, atu, atv, false);
      f += base * (spec_trans * (1.0f - fd) * d * g / (4.0f * co * ci));
      *pdf += lobes.y * mf_pdf(o, h, atu, atv, false) * jacobian;
    }
  }
  if (reflect && spec_trans < 1.0f && diff_trans < 1.0f) { /* diffuse, retro-reflection, flatness, sheen */
    float cos_d = dot(h, i), diffuse = principled_diffuse(m, co, ci, cos_d);
    float w = (1.0f - spec_trans) * (1.0f - diff_trans);
    f += base * (w * PSF_INV_PI * diffuse);
    float sheen = m.specular.w;
    if (sheen > 0.0f)
      f += mix((float3)(1.0f), principled_tint(base), m.transmittance.x) *
           (sheen * w * principled_schlick_weight(fabs(cos_d)));
  }
  if (!reflect && spec_trans < 1.0f && diff_trans > 0.0f) f += base * ((1.0f - spec_trans) * diff_trans * PSF_INV_PI);
  *pdf += (reflect ? lobes.z : lobes.w) * ci * PSF_INV_PI;
  return f;
}

/* f and pdf in the local frame (o = wo, i = wi). Delta lobes contribute nothing. */
inline float3 bsdf_eval_local(Material m, __global const half* table, float3 o, float3 i, float* pdf) {
  *pdf = 0.0f;
  uint type = m.type;
  bool beckmann = (m.flags & PSF_MATFLAG_BECKMANN) != 0u;
  float au = m.alpha_u, av = m.alpha_v;
  if (type == PSF_MATERIAL_DIFFUSE) {
    if (o.z <= 0.0f || i.z <= 0.0f) return (float3)(0.0f);
    *pdf = i.z * PSF_INV_PI;
    return m.albedo.xyz * PSF_INV_PI;
  }
  if (type == PSF_MATERIAL_ROUGH_CONDUCTOR) {
    if (o.z <= 0.0f || i.z <= 0.0f) return (float3)(0.0f);
    float3 h = normalize(o + i);
    float oh = dot(o, h);
    float d = mf_D(h, au, av, beckmann);
    float g = mf_G1(o, h, au, av, beckmann) * mf_G1(i, h, au, av, beckmann);
    *pdf = mf_pdf(o, h, au, av, beckmann) / (4.0f * oh);
    return m.specular.xyz * fresnel_conductor(oh, m.eta.xyz, m.k.xyz) * (d * g / (4.0f * o.z * i.z));
  }
  if (type == PSF_MATERIAL_PLASTIC) {
    if (o.z <= 0.0f || i.z <= 0.0f) return (float3)(0.0f);
    float c, e;
    float fo = fresnel_dielectric(o.z, m.eta.x, &c, &e), fi = fresnel_dielectric(i.z, m.eta.x, &c, &e);
    *pdf = (1.0f - plastic_prob_specular(m, fo)) * i.z * PSF_INV_PI;
    return plastic_base(m) * (m.eta.y * (1.0f - fo) * (1.0f - fi) * PSF_INV_PI);
  }
  if (type == PSF_MATERIAL_ROUGH_PLASTIC) {
    if (o.z <= 0.0f || i.z <= 0.0f) return (float3)(0.0f);
    float to = rough_transmittance(m, table, o.z), ti = rough_transmittance(m, table, i.z);
    float ps = plastic_prob_specular(m, 1.0f - to);
    float3 h = normalize(o + i);
    float oh = dot(o, h);
    float c, e;
    float fr = fresnel_dielectric(oh, m.eta.x, &c, &e);
    float d = mf_D(h, au, av, beckmann);
    float g = mf_G1(o, h, au, av, beckmann) * mf_G1(i, h, au, av, beckmann);
    *pdf = ps * mf_pdf(o, h, au, av, beckmann) / (4.0f * oh) + (1.0f - ps) * i.z * PSF_INV_PI;
    return m.specular.xyz * (fr * d * g / (4.0f * o.z * i.z)) +
           plastic_base(m) * (m.eta.y * to * ti * PSF_INV_PI);
  }
  if (type == PSF_MATERIAL_PPLASTIC) { /* Mitsuba 3's pplastic outside its polarized variants */
    if (o.z <= 0.0f || i.z <= 0.0f) return (float3)(0.0f);
    float3 h = normalize(o + i);
    float oh = dot(o, h), ps = m.albedo.w;
    float c, e;
    float fr = fresnel_dielectric(oh, m.eta.x, &c, &e);
    float fo = fresnel_dielectric(o.z, m.eta.x, &c, &e), fi = fresnel_dielectric(i.z, m.eta.x, &c, &e);
    float d = mf_D(h, au, av, beckmann);
    float g = mf_G1(o, h, au, av, beckmann) * mf_G1(i, h, au, av, beckmann);
    float pm = oh > 0.0f && dot(i, h) > 0.0f ? mf_pdf(o, h, au, av, beckmann) / (4.0f * oh) : 0.0f;
    *pdf = ps * pm + (1.0f - ps) * i.z * PSF_INV_PI;
    return m.specular.xyz * (fr * d * g / (4.0f * o.z * i.z)) +
           m.albedo.xyz * ((1.0f - fo) * (1.0f - fi) * PSF_INV_PI);
  }
  if (type == PSF_MATERIAL_ROUGH_DIELECTRIC) {
    float co = o.z, ci = i.z;
    if (co == 0.0f || ci == 0.0f) return (float3)(0.0f);
    bool reflect = co * ci > 0.0f;
    float eta = co > 0.0f ? m.eta.x : 1.0f / m.eta.x; /* IOR of i's side over o's side */
    float3 h = normalize(o + i * (reflect ? 1.0f : eta));
    if (h.z < 0.0f) h = -h;
    float oh = dot(o, h), ih = dot(i, h);
    /* Neither direction may see the back of the microfacet (else no path through it). */
    if (oh * co <= 0.0f || ih * ci <= 0.0f) return (float3)(0.0f);
    float c, e;
    float fr = fresnel_dielectric(oh, m.eta.x, &c, &e);
    float d = mf_D(h, au, av, beckmann);
    float g = mf_G1(o, h, au, av, beckmann) * mf_G1(i, h, au, av, beckmann);
    float3 of = co > 0.0f ? o : -o; /* o on the side of the sampled normals */
    float pm = mf_pdf(of, h, au, av, beckmann);
    if (reflect) {
      *pdf = pm * fr / (4.0f * fabs(ih));
      return m.specular.xyz * (fr * d * g / (4.0f * fabs(co * ci)));
    }
    float denom = oh + eta * ih;
    float jac = eta * eta * fabs(ih) / (denom * denom); /* |d h / d i| (Walter et al. Eq. 17) */
    *pdf = pm * (1.0f - fr) * jac;
    /* Eq. 21 with radiance scaling 1 / eta^2: the eta^2 factors cancel. */
    return m.transmittance.xyz * fabs((1.0f - fr) * d * g * oh * ih / (co * ci * denom * denom));
  }
  if (type == PSF_MATERIAL_PRINCIPLED) return principled_eval(m, o, i, pdf);
  if (type == PSF_MATERIAL_PRINCIPLED_THIN) return thin_eval(m, o, i, pdf);
  return (float3)(0.0f); /* delta types */
}

inline float3 bsdf_eval(Material m, __global const half* table, Frame f, float3 wo, float3 wi, float* pdf) {
  if (m.type == PSF_MATERIAL_DIFFUSE) { /* the common case, without the local frame */
    float cos_o = dot(wo, f.n), cos_i = dot(wi, f.n);
    if (cos_o <= 0.0f || cos_i <= 0.0f) {
      *pdf = 0.0f;
      return (float3)(0.0f);
    }
    *pdf = cos_i * PSF_INV_PI;
    return m.albedo.xyz * PSF_INV_PI;
  }
  return bsdf_eval_local(m, table, frame_to_local(f, wo), frame_to_local(f, wi), pdf);
}

/* --- Sampling -------------------------------------------------------------- */

/* A sample of a non-delta lobe: weight and pdf from bsdf_eval_local, so that
 * sampling and evaluation agree by construction. */
inline BsdfSample bsdf_finish(Material m, __global const half* table, Frame f, float3 o, float3 i) {
  BsdfSample bs;
  bs.wi = frame_to_world(f, i);
  bs.flags = o.z * i.z < 0.0f ? BSDF_TRANSMISSION : 0u;
  float pdf;
  float3 v = bsdf_eval_local(m, table, o, i, &pdf);
  bs.pdf = pdf > 0.0f ? pdf : 0.0f;
  bs.weight = pdf > 0.0f ? v * (fabs(i.z) / pdf) : (float3)(0.0f);
  return bs;
}

inline BsdfSample bsdf_delta(Frame f, float3 i, float3 weight, uint flags) {
  BsdfSample bs;
  bs.wi = frame_to_world(f, i);
  bs.weight = weight;
  bs.pdf = 0.0f;
  bs.flags = BSDF_DELTA | flags;
  return bs;
}

inline BsdfSample bsdf_fail(float3 wo) {
  BsdfSample bs;
  bs.wi = wo;
  bs.weight = (float3)(0.0f);
  bs.pdf = 0.0f;
  bs.flags = 0u;
  return bs;
}

/* The direction *i from o through the microfacet h (oh = o.h): the mirror
 * direction, or the refracted one (cos_t, eta_ti from fresnel_dielectric of oh);
 * false where it leaves on the wrong side of the surface. */
inline bool microfacet_scatter(float3 o, float3 h, float oh, bool reflect, float cos_t, float eta_ti, float3* i) {
  if (reflect) {
    *i = 2.0f * oh * h - o;
    return i->z * o.z > 0.0f;
  }
  *i = h * (oh * eta_ti + cos_t) - o * eta_ti;
  return i->z * o.z < 0.0f;
}

/* A direction from principled's mixture (principled_lobes), uc choosing the lobe. */
inline BsdfSample principled_sample(Material m, __global const half* table, Frame f, float3 wo, float3 o, float u1,
                                    float u2, float uc) {
  if (o.z == 0.0f) return bsdf_fail(wo);
  bool front = o.z > 0.0f;
  float3 lobes = principled_lobes(m, front);
  float3 i;
  if (uc < lobes.x) {
    i = square_to_cosine_hemisphere(u1, u2);
  } else if (uc < lobes.x + lobes.y) { /* a GTR1 normal: cos^2 = (1 - a^2^(1 - u2)) / (1 - a^2) */
    float a2 = principled_clearcoat_alpha(m);
    a2 *= a2;
    float c2 = (1.0f - pow(a2, 1.0f - u2)) / (1.0f - a2);
    float st = sqrt(fmax(0.0f, 1.0f - c2)), cp;
    float sp = psf_sincos(2.0f * PSF_PI * u1, &cp);
    float3 h = (float3)(st * cp, st * sp, sqrt(fmax(0.0f, c2)));
    i = 2.0f * dot(o, h) * h - o;
    if (i.z <= 0.0f) return bsdf_fail(wo);
  } else {
    if (!(lobes.z > 0.0f)) return bsdf_fail(wo);
    float3 h = mf_sample(front ? o : -o, m.alpha_u, m.alpha_v, false, u1, u2);
    float oh = dot(o, h);
    float cos_t, eta_ti;
    float fd = principled_fresnel(oh, m.eta.x, &cos_t, &eta_ti);
    float btdf = (1.0f - m.specular.x) * m.specular.y;
    float prefl = front ? 1.0f - btdf * (1.0f - fd) : fd; /* reflection, else refraction, within the lobe */
    if (!microfacet_scatter(o, h, oh, uc < lobes.x + lobes.y + lobes.z * prefl, cos_t, eta_ti, &i))
      return bsdf_fail(wo);
  }
  return bsdf_finish(m, table, f, o, i);
}

/* A direction from principledthin's mixture (thin_lobes), uc choosing the lobe,
 * sampled for o turned to the front and turned back with it. */
inline BsdfSample thin_sample(Material m, __global const half* table, Frame f, float3 wo, float3 o, float u1,
                              float u2, float uc) {
  if (o.z == 0.0f) return bsdf_fail(wo);
  float side = o.z > 0.0f ? 1.0f : -1.0f;
  float3 of = o * side, i;
  float4 lobes = thin_lobes(m);
  if (uc < lobes.x + lobes.y) { /* specular: a GGX visible normal, reflected, for transmission through the sheet */
    bool reflect = uc < lobes.x;
    float3 h = reflect ? mf_sample(of, m.alpha_u, m.alpha_v, false, u1, u2)
                       : mf_sample(of, m.transmittance.z, m.transmittance.w, false, u1, u2);
    float oh = dot(of, h);
    i = 2.0f * oh * h - of;
    if (!reflect) i.z = -i.z;
    /* Through the sheet the mirror image must lie behind the microfacet (thin_eval). */
    if (oh <= 0.0f || (reflect ? i.z <= 0.0f || dot(i, h) <= 0.0f : i.z >= 0.0f || dot(i, h) >= 0.0f))
      return bsdf_fail(wo);
  } else {
    i = square_to_cosine_hemisphere(u1, u2);
    if (uc >= lobes.x + lobes.y + lobes.z) i.z = -i.z;
  }
  return bsdf_finish(m, table, f, o, i * side);
}

/* bsdf_sample of the types other than diffuse. */
inline BsdfSample bsdf_sample_general(Material m, __global const half* table, Frame f, float3 wo, float u1, float u2,
                                      float uc) {
  uint type = m.type;
  float3 o = frame_to_local(f, wo);
  bool beckmann = (m.flags & PSF_MATFLAG_BECKMANN) != 0u;
  float au = m.alpha_u, av = m.alpha_v;
  float3 mirror = (float3)(-o.x, -o.y, o.z);
  if (type == PSF_MATERIAL_CONDUCTOR) {
    if (o.z <= 0.0f) return bsdf_fail(wo);
    return bsdf_delta(f, mirror, m.specular.xyz * fresnel_conductor(o.z, m.eta.xyz, m.k.xyz), 0u);
  }
  if (type == PSF_MATERIAL_ROUGH_CONDUCTOR) {
    if (o.z <= 0.0f) return bsdf_fail(wo);
    float3 h = mf_sample(o, au, av, beckmann, u1, u2);
    float3 i = 2.0f * dot(o, h) * h - o;
    if (i.z <= 0.0f) return bsdf_fail(wo);
    return bsdf_finish(m, table, f, o, i);
  }
  if (type == PSF_MATERIAL_PLASTIC) {
    if (o.z <= 0.0f) return bsdf_fail(wo);
    float c, e;
    float fo = fresnel_dielectric(o.z, m.eta.x, &c, &e);
    float ps = plastic_prob_specular(m, fo);
    if (uc < ps) return bsdf_delta(f, mirror, m.specular.xyz * (fo / ps), 0u);
    return bsdf_finish(m, table, f, o, square_to_cosine_hemisphere(u1, u2));
  }
  if (type == PSF_MATERIAL_ROUGH_PLASTIC || type == PSF_MATERIAL_PPLASTIC) {
    if (o.z <= 0.0f) return bsdf_fail(wo);
    float ps = type == PSF_MATERIAL_PPLASTIC ? m.albedo.w
                                             : plastic_prob_specular(m, 1.0f - rough_transmittance(m, table, o.z));
    float3 i;
    if (uc < ps) {
      float3 h = mf_sample(o, au, av, beckmann, u1, u2);
      i = 2.0f * dot(o, h) * h - o;
      if (i.z <= 0.0f) return bsdf_fail(wo);
    } else {
      i = square_to_cosine_hemisphere(u1, u2);
    }
    return bsdf_finish(m, table, f, o, i);
  }
  if (type == PSF_MATERIAL_DIELECTRIC) {
    float cos_t, eta_ti;
    float fr = fresnel_dielectric(o.z, m.eta.x, &cos_t, &eta_ti);
    if (uc < fr) return bsdf_delta(f, mirror, m.specular.xyz, 0u);
    float3 i = (float3)(-eta_ti * o.x, -eta_ti * o.y, cos_t);
    return bsdf_delta(f, i, m.transmittance.xyz * (eta_ti * eta_ti), BSDF_TRANSMISSION);
  }
  if (type == PSF_MATERIAL_THIN_DIELECTRIC) {
    float cos_t, eta_ti;
    float r = fresnel_dielectric(fabs(o.z), m.eta.x, &cos_t, &eta_ti);
    if (r < 1.0f) r += (1.0f - r) * (1.0f - r) * r / (1.0f - r * r);
    if (uc < r) return bsdf_delta(f, mirror, m.specular.xyz, 0u);
    return bsdf_delta(f, -o, m.transmittance.xyz, BSDF_TRANSMISSION);
  }
  if (type == PSF_MATERIAL_PRINCIPLED) return principled_sample(m, table, f, wo, o, u1, u2, uc);
  if (type == PSF_MATERIAL_PRINCIPLED_THIN) return thin_sample(m, table, f, wo, o, u1, u2, uc);
  if (type == PSF_MATERIAL_ROUGH_DIELECTRIC) {
    if (o.z == 0.0f) return bsdf_fail(wo);
    float3 of = o.z > 0.0f ? o : -o;
    float3 h = mf_sample(of, au, av, beckmann, u1, u2);
    float oh = dot(o, h);
    float cos_t, eta_ti;
    float fr = fresnel_dielectric(oh, m.eta.x, &cos_t, &eta_ti);
    float3 i;
    if (!microfacet_scatter(o, h, oh, uc < fr, cos_t, eta_ti, &i)) return bsdf_fail(wo);
    return bsdf_finish(m, table, f, o, i);
  }
  return bsdf_fail(wo);
}

/* Diffuse inline (the common case, no call), the other types in bsdf_sample_general. */
inline BsdfSample bsdf_sample(Material m, __global const half* table, Frame f, float3 wo, float u1, float u2,
                              float uc) {
  if (m.type != PSF_MATERIAL_DIFFUSE) return bsdf_sample_general(m, table, f, wo, u1, u2, uc);
  BsdfSample bs;
  bs.flags = 0u;
  float3 wl = square_to_cosine_hemisphere(u1, u2);
  bs.wi = normalize(frame_to_world(f, wl));
  bs.pdf = dot(wo, f.n) > 0.0f ? wl.z * PSF_INV_PI : 0.0f;
  bs.weight = bs.pdf > 0.0f ? m.albedo.xyz : (float3)(0.0f);
  return bs;
}

/* --- the phase function of media (shade.cl) ------------------------------ */

/* The Henyey-Greenstein phase function of asymmetry g for directions whose
 * cosine, from the direction of travel, is cos_theta: also the solid-angle pdf
 * of sample_henyey_greenstein. */
inline float henyey_greenstein(float g, float cos_theta) {
  if (fabs(g) < 1e-3f) return 1.0f / (4.0f * M_PI_F); /* sampled as isotropic there */
  const float d = 1.0f + g * g - 2.0f * g * cos_theta;
  return (1.0f - g * g) / (4.0f * M_PI_F * d * sqrt(d));
}

/* A direction scattered from `d` (unit, the direction of travel) by the
 * Henyey-Greenstein phase function of asymmetry g (> 0 forwards), sampled
 * exactly, so that the sample's weight is 1. */
inline float3 sample_henyey_greenstein(float3 d, float g, float u1, float u2) {
  float c = 1.0f - 2.0f * u1;
  if (fabs(g) >= 1e-3f) {
    const float sq = (1.0f - g * g) / (1.0f - g + 2.0f * g * u1);
    c = (1.0f + g * g - sq * sq) / (2.0f * g);
  }
  c = clamp(c, -1.0f, 1.0f);
  float cos_phi;
  const float sin_phi = psf_sincos(2.0f * M_PI_F * u2, &cos_phi), sin_theta = sqrt(fmax(0.0f, 1.0f - c * c));
  return frame_to_world(frame_from_normal(d), (float3)(sin_theta * cos_phi, sin_theta * sin_phi, c));
}
