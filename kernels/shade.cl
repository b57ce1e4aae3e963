/* shade.cl: surface interaction of the wavefront path tracer (unidirectional
 * path tracing with next-event estimation and multiple importance sampling,
 * Veach 1997, Sec. 9.2, power heuristic).
 *
 * shade: reads each path's closest hit, adds emission seen by the BSDF-sampled
 * ray (MIS-weighted against light sampling), samples a point on an emitter
 * (chosen by power) and writes its shadow ray with the contribution it carries
 * if unoccluded (pending), then samples the BSDF for the next ray, with Russian
 * roulette. Depth follows Mitsuba's max_depth: the number of path segments, so
 * max_depth 1 shows emitters only and 2 adds direct light.
 * shade_shadows: adds the pending contribution of paths whose shadow ray is unoccluded.
 * Materials so far: Lambertian diffuse with one-sided (front) area emission. */

#define PSF_PI 3.14159265358979323846f
#define PSF_RAY_EPS 1e-4f

inline float max3(float3 v) { return fmax(v.x, fmax(v.y, v.z)); }

inline float power_heuristic(float a, float b) {
  float a2 = a * a, b2 = b * b;
  return (a2 + b2) > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

/* Orthonormal basis around n (Duff et al. 2017, "Building an Orthonormal Basis, Revisited"). */
inline void onb(float3 n, float3* t, float3* b) {
  float sign = n.z >= 0.0f ? 1.0f : -1.0f;
  float a = -1.0f / (sign + n.z);
  float c = n.x * n.y * a;
  *t = (float3)(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
  *b = (float3)(c, sign + n.y * n.y * a, -n.y);
}

/* Cosine-weighted hemisphere direction about n (Malley's method, concentric disk). */
inline float3 sample_cosine(float3 n, float u1, float u2) {
  float a = 2.0f * u1 - 1.0f, b = 2.0f * u2 - 1.0f;
  float r, phi;
  if (a == 0.0f && b == 0.0f) {
    r = 0.0f;
    phi = 0.0f;
  } else if (fabs(a) > fabs(b)) {
    r = a;
    phi = (PSF_PI / 4.0f) * (b / a);
  } else {
    r = b;
    phi = (PSF_PI / 2.0f) - (PSF_PI / 4.0f) * (a / b);
  }
  float x = r * cos(phi), y = r * sin(phi);
  float z = sqrt(fmax(0.0f, 1.0f - x * x - y * y));
  float3 t, bt;
  onb(n, &t, &bt);
  return normalize(x * t + y * bt + z * n);
}

/* Index of the first cdf entry > u (emitter selection by power). */
inline uint sample_cdf(__global const float* cdf, uint n, float u) {
  uint lo = 0u, hi = n - 1u;
  while (lo < hi) {
    uint mid = (lo + hi) >> 1;
    if (cdf[mid] > u) hi = mid; else lo = mid + 1u;
  }
  return lo;
}

inline float bounce_sample(__global const uint* sobol, FrameParams p, PathState st, uint offset) {
  return sample_1d(sobol, p.seed, st.pixel, st.sample, PSF_DIM_BOUNCE0 + PSF_DIMS_PER_BOUNCE * st.depth + offset);
}

/* True if a path with `segments` segments is allowed by max_depth. */
inline bool depth_allows(FrameParams p, uint segments) { return (int)p.max_depth < 0 || segments <= p.max_depth; }

__kernel void shade(FrameParams params, __global const uint* sobol, __global const float4* tri_pos,
                    __global const uint* tri_material, __global const Material* materials,
                    __global const Emitter* emitters, __global const float* emitter_cdf,
                    __global const float* tri_light_pdf, __global const Hit* hits,
                    __global Ray* rays, __global PathState* states, __global Ray* shadow_rays,
                    __global uint* alive_count) {
  uint j = get_global_id(0);
  if (j >= params.batch_size) return;
  PathState st = states[j];
  Ray shadow;
  shadow.org = (float4)(0.0f);
  shadow.dir = (float4)(0.0f, 0.0f, 1.0f, -1.0f);
  st.pending = (float4)(0.0f);
  if (!(st.flags & PSF_PATH_ALIVE)) {
    shadow_rays[j] = shadow;
    states[j] = st;
    return;
  }
  Ray ray = rays[j];
  Hit hit = hits[j];
  if (hit.prim == PSF_NO_HIT) {
    st.flags &= ~PSF_PATH_ALIVE;
    ray.dir.w = -1.0f;
    rays[j] = ray;
    shadow_rays[j] = shadow;
    states[j] = st;
    return;
  }
  float3 p0 = tri_pos[3u * hit.prim].xyz, p1 = tri_pos[3u * hit.prim + 1u].xyz, p2 = tri_pos[3u * hit.prim + 2u].xyz;
  float3 ng = cross(p1 - p0, p2 - p0);
  float area2 = length(ng);
  ng = area2 > 0.0f ? ng / area2 : (float3)(0.0f, 0.0f, 1.0f);
  float3 wo = -normalize(ray.dir.xyz);
  float3 pos = ray.org.xyz + hit.t * ray.dir.xyz;
  Material m = materials[tri_material[hit.prim]];
  bool front = dot(ng, wo) > 0.0f;
  float3 beta = st.throughput.xyz;

  /* Emission reached by the previous BSDF sample (or seen directly from the camera). */
  if (max3(m.emission.xyz) > 0.0f && (front || m.two_sided)) {
    float w = 1.0f;
    if (st.depth > 0u && !(st.flags & PSF_PATH_SPECULAR) && params.num_emitters > 0u) {
      float d2 = hit.t * hit.t * dot(ray.dir.xyz, ray.dir.xyz);
      float cos_l = fabs(dot(ng, wo));
      float light_pdf = cos_l > 0.0f ? tri_light_pdf[hit.prim] * d2 / cos_l : 0.0f;
      w = power_heuristic(st.throughput.w, light_pdf);
    }
    st.radiance.xyz += beta * m.emission.xyz * w;
  }

  /* The shading frame faces the incoming ray (two-sided scattering). */
  float3 n = front ? ng : -ng;
  float3 albedo = m.albedo.xyz;
  uint segments = st.depth + 1u; /* segments of the path up to this vertex */
  bool scatter = depth_allows(params, segments + 1u) && max3(albedo) > 0.0f;

  /* Next-event estimation: one point on one emitter, chosen by power. */
  if (scatter && params.num_emitters > 0u) {
    float ul = bounce_sample(sobol, params, st, PSF_DIM_LIGHT_SELECT);
    uint e = sample_cdf(emitter_cdf, params.num_emitters, ul);
    Emitter em = emitters[e];
    float a = bounce_sample(sobol, params, st, PSF_DIM_LIGHT_UV);
    float b = bounce_sample(sobol, params, st, PSF_DIM_LIGHT_UV + 1u);
    float su = sqrt(a);
    float3 lp = em.v0.xyz + su * (1.0f - b) * em.e1.xyz + su * b * em.e2.xyz;
    float3 ln = normalize(cross(em.e1.xyz, em.e2.xyz));
    float3 to_light = lp - pos;
    float d2 = dot(to_light, to_light);
    float dist = sqrt(d2);
    float3 wi = to_light / dist;
    float cos_s = dot(n, wi);
    float cos_l = -dot(ln, wi);
    if (em.two_sided) cos_l = fabs(cos_l);
    if (cos_s > 0.0f && cos_l > 0.0f && d2 > 0.0f) {
      float light_pdf = em.radiance.w / em.v0.w * d2 / cos_l; /* solid angle */
      float bsdf_pdf = cos_s / PSF_PI;
      float w = power_heuristic(light_pdf, bsdf_pdf);
      float3 f = albedo / PSF_PI;
      st.pending.xyz = beta * f * cos_s * em.radiance.xyz * (w / light_pdf);
      shadow.org = (float4)(pos + n * PSF_RAY_EPS * fmax(1.0f, max3(fabs(pos))), 0.0f);
      shadow.dir = (float4)(lp - shadow.org.xyz, 1.0f - PSF_RAY_EPS);
    }
  }
  shadow_rays[j] = shadow;

  /* BSDF sampling: cosine-weighted, so f cos / pdf = albedo. */
  if (scatter) {
    float u1 = bounce_sample(sobol, params, st, PSF_DIM_BSDF_UV);
    float u2 = bounce_sample(sobol, params, st, PSF_DIM_BSDF_UV + 1u);
    float3 wi = sample_cosine(n, u1, u2);
    float pdf = dot(n, wi) / PSF_PI;
    beta *= albedo;
    float rr = bounce_sample(sobol, params, st, PSF_DIM_RR);
    if (st.depth + 1u >= params.rr_depth) {
      float q = fmin(max3(beta), 0.95f);
      if (rr >= q) scatter = false;
      else beta /= q;
    }
    if (scatter && pdf > 0.0f) {
      st.throughput = (float4)(beta, pdf);
      st.prev_pos = (float4)(pos, 0.0f);
      st.flags &= ~PSF_PATH_SPECULAR;
      ray.org = (float4)(pos + n * PSF_RAY_EPS * fmax(1.0f, max3(fabs(pos))), 0.0f);
      ray.dir = (float4)(wi, INFINITY);
      st.depth += 1u;
      atomic_inc(alive_count);
    } else {
      scatter = false;
    }
  }
  if (!scatter) {
    st.flags &= ~PSF_PATH_ALIVE;
    ray.dir.w = -1.0f;
  }
  rays[j] = ray;
  states[j] = st;
}

__kernel void shade_shadows(uint count, __global const Hit* shadow_hits, __global PathState* states) {
  uint j = get_global_id(0);
  if (j >= count) return;
  PathState st = states[j];
  if (shadow_hits[j].prim == PSF_NO_HIT && (st.pending.x > 0.0f || st.pending.y > 0.0f || st.pending.z > 0.0f)) {
    st.radiance.xyz += st.pending.xyz;
    st.pending = (float4)(0.0f);
    states[j] = st;
  }
}
