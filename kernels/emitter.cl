/* emitter.cl: light sampling for next-event estimation.
 *
 * Emitters are the triangles of emissive materials (area lights), chosen in
 * proportion to their power (host/render.cpp builds the table and its cdf) and
 * sampled uniformly by area (Turk 1990: b1 = sqrt(u) (1 - v), b2 = sqrt(u) v).
 *   emitter_sample(...)   -> LightSample {wi, dist, radiance, pdf (solid angle)}
 *   emitter_pdf_hit(...)  -> solid-angle pdf of hitting an emitter triangle by chance (for MIS) */

typedef struct {
  float3 wi;       /* unit direction from the shading point to the light point */
  float dist;      /* distance to the light point */
  float3 radiance; /* emitted radiance towards the shading point */
  float pdf;       /* solid-angle pdf of this sample (0: no contribution) */
} LightSample;

/* Index of the first cdf entry > u. */
inline uint sample_cdf(__global const float* cdf, uint n, float u) {
  uint lo = 0u, hi = n - 1u;
  while (lo < hi) {
    uint mid = (lo + hi) >> 1;
    if (cdf[mid] > u) hi = mid;
    else lo = mid + 1u;
  }
  return lo;
}

inline LightSample emitter_sample(__global const Emitter* emitters, __global const float* cdf, uint count, float3 p,
                                  float ul, float ua, float ub) {
  LightSample ls;
  ls.pdf = 0.0f;
  ls.radiance = (float3)(0.0f);
  ls.wi = (float3)(0.0f, 0.0f, 1.0f);
  ls.dist = 0.0f;
  if (count == 0u) return ls;
  Emitter em = emitters[sample_cdf(cdf, count, ul)];
  float su = sqrt(ua);
  float3 lp = em.v0.xyz + su * (1.0f - ub) * em.e1.xyz + su * ub * em.e2.xyz;
  float3 ln = normalize(cross(em.e1.xyz, em.e2.xyz));
  float3 d = lp - p;
  float d2 = dot(d, d);
  if (!(d2 > 0.0f)) return ls;
  ls.dist = sqrt(d2);
  ls.wi = d / ls.dist;
  float cos_l = -dot(ln, ls.wi);
  if (em.two_sided) cos_l = fabs(cos_l);
  if (cos_l <= 0.0f) return ls;
  ls.pdf = em.radiance.w / em.v0.w * d2 / cos_l;
  ls.radiance = em.radiance.xyz;
  return ls;
}

/* Solid-angle pdf with which emitter_sample would have chosen the point hit at
 * distance `dist` on triangle `prim` with cosine `cos_l` to its normal. */
inline float emitter_pdf_hit(__global const float* tri_light_pdf, uint prim, float dist, float cos_l) {
  return cos_l > 0.0f ? tri_light_pdf[prim] * dist * dist / cos_l : 0.0f;
}
