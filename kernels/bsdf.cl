/* bsdf.cl: scattering at a surface, in a local frame around the shading normal.
 *
 * Interface used by shade.cl:
 *   bsdf_sample(m, frame, wo, u1, u2, uc) -> BsdfSample {wi, weight = f |cos| / pdf, pdf, flags}
 *   bsdf_eval(m, frame, wo, wi, &pdf)    -> f (without the cosine)
 *   bsdf_albedo(m)                       -> the colour term path space filtering compares
 *   bsdf_is_diffuse(m)                   -> whether a vertex is diffuse enough to filter at
 * Directions point away from the surface. Lambertian: f = albedo / pi, sampled
 * with a cosine-weighted hemisphere (Malley's method over Shirley-Chiu's
 * concentric disk), so weight = albedo. */

#define PSF_PI 3.14159265358979323846f
#define PSF_INV_PI 0.31830988618379067154f

#define BSDF_DELTA 1u        /* the sampled lobe is a Dirac delta: pdf is not comparable */
#define BSDF_TRANSMISSION 2u /* wi is on the other side of the surface */

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

inline float3 frame_to_local(Frame f, float3 v) { return (float3)(dot(v, f.s), dot(v, f.t), dot(v, f.n)); }
inline float3 frame_to_world(Frame f, float3 v) { return v.x * f.s + v.y * f.t + v.z * f.n; }

/* Shirley-Chiu concentric map of [0,1)^2 onto the unit disk. */
inline float2 square_to_disk(float u1, float u2) {
  float a = 2.0f * u1 - 1.0f, b = 2.0f * u2 - 1.0f;
  if (a == 0.0f && b == 0.0f) return (float2)(0.0f, 0.0f);
  float r, phi;
  if (fabs(a) > fabs(b)) {
    r = a;
    phi = (PSF_PI / 4.0f) * (b / a);
  } else {
    r = b;
    phi = (PSF_PI / 2.0f) - (PSF_PI / 4.0f) * (a / b);
  }
  return (float2)(r * cos(phi), r * sin(phi));
}

/* Cosine-weighted direction in the local frame (z up). */
inline float3 square_to_cosine_hemisphere(float u1, float u2) {
  float2 d = square_to_disk(u1, u2);
  return (float3)(d.x, d.y, sqrt(fmax(0.0f, 1.0f - d.x * d.x - d.y * d.y)));
}

inline float3 bsdf_albedo(Material m) { return m.albedo.xyz; }

inline bool bsdf_is_diffuse(Material m) { return m.type == PSF_MATERIAL_DIFFUSE; }

inline float3 bsdf_eval(Material m, Frame f, float3 wo, float3 wi, float* pdf) {
  float cos_o = dot(wo, f.n), cos_i = dot(wi, f.n);
  if (cos_o <= 0.0f || cos_i <= 0.0f) {
    *pdf = 0.0f;
    return (float3)(0.0f);
  }
  *pdf = cos_i * PSF_INV_PI;
  return m.albedo.xyz * PSF_INV_PI;
}

inline BsdfSample bsdf_sample(Material m, Frame f, float3 wo, float u1, float u2, float uc) {
  BsdfSample bs;
  bs.flags = 0u;
  float3 wl = square_to_cosine_hemisphere(u1, u2);
  bs.wi = normalize(frame_to_world(f, wl));
  bs.pdf = dot(wo, f.n) > 0.0f ? wl.z * PSF_INV_PI : 0.0f;
  bs.weight = bs.pdf > 0.0f ? m.albedo.xyz : (float3)(0.0f);
  return bs;
}
