/* emitter.cl: light sampling for next-event estimation and the environment seen
 * by escaped rays.
 *
 * Reads: the emitter table (psf_shared.h Emitter; host/lights.cpp builds it and
 * its selection cdf, in proportion to each light's power), the Environment and
 * its data buffer (texels, marginal and two-level conditional cdfs).
 *   emitter_sample(...)  -> LightSample {wi, dist, radiance, pdf, delta}: one light
 *                           chosen by the cdf, then a point or direction on it
 *   emitter_pdf_hit(...) -> solid-angle pdf of hitting an emitter triangle by chance (for MIS)
 *   emitter_pdf_sphere(...) -> the same for a sphere light, from the point p
 *   env_radiance(...)    -> radiance of the environment along a world direction
 *   env_pdf(...)         -> solid-angle pdf of env_sample for that direction
 * Light types and their samples:
 *   triangle:    uniform by area (Turk 1990: b1 = sqrt(u) (1 - v), b2 = sqrt(u) v);
 *                pdf = P(light) / area * r^2 / cos_l; with an emission texture
 *                the caller multiplies the radiance by it at (prim, b1, b2)
 *   sphere:      seen from outside (one-sided, emitting outwards): uniform in the
 *                cone of directions it subtends (pbrt's and Mitsuba 3's sphere
 *                sampling), pdf = P(light) / (2 pi (1 - cos theta_max)); else
 *                uniform by area (z = 1 - 2u, phi = 2 pi v in its frame) with
 *                the triangle's pdf, points facing away from p having cos_l <= 0;
 *                (b1, b2) is the point's uv (its TriAttrib's uvs are the identity)
 *   point:       delta; radiance I / r^2, pdf = P(light)
 *   spot:        delta; I / r^2 times Mitsuba's falloff: 1 inside the beam width,
 *                (cutoff - angle) / (cutoff - beam width) up to the cutoff, 0 beyond
 *   directional: delta; wi = -direction, radiance the irradiance E, pdf = P(light)
 *   environment: a lat-long map, its radiance bilinear between texels
 *                (env_lookup), sampled with a 2D piecewise-constant distribution
 *                over a grid of W x H cells of the (u, v) square (Pharr, Jakob &
 *                Humphreys, PBRT 3rd ed., Sec. 13.6.7 and 14.2.4), each cell
 *                weighted by the mean of the bilinear radiance over it times
 *                sin(theta) at its centre (host/lights.cpp): a row from the
 *                marginal cdf, a cell from that row's conditional cdf (in two
 *                levels: a block of PSF_ENV_BLOCK cells, then a cell of it), a
 *                uniform point in the cell; pdf(omega) = p(u, v) / (2 pi^2
 *                sin theta). A constant environment is sampled uniformly over
 *                the sphere (1 / 4pi).
 * Delta lights carry delta = 1: they cannot be hit by BSDF sampling, so their
 * samples take MIS weight 1. Directions at infinity have dist = INFINITY. */

#define PSF_ENV_PI 3.14159265358979323846f

typedef struct {
  float3 wi;       /* unit direction from the shading point to the light */
  float dist;      /* distance to the light point (INFINITY: directional, environment) */
  float3 radiance; /* radiance arriving at the shading point (point, spot: I / r^2; directional: E) */
  float pdf;       /* solid-angle pdf of this sample, or the selection probability of a delta light (0: none) */
  uint delta;      /* 1: a delta light (no MIS) */
  uint tex;        /* a triangle's emission texture (radiance is to be multiplied by it at (prim, b1, b2)), or none */
  uint prim;       /* the triangle or sphere (prim index) */
  float b1, b2;    /* barycentrics of the point on it */
} LightSample;

/* Index of the first of the n upper cdf values `cdf` that exceeds u (n - 1 if
 * none), from the cdf's guide table (host/lights.h cdf_guide_table): a bucket's
 * entry is at or below the answer for every u of the bucket, so a short forward
 * search finds it, in about one step and one cache line. A bisection waited on a
 * line per step, and its selects were compiled into branches that a processor
 * mispredicts half of the time (the environment's searches were a sixth of the
 * living room's time on PoCL). */
inline uint sample_cdf_guided(__global const float* cdf, uint n, __global const float* guide, float u) {
  uint i = as_uint(guide[min((uint)(u * (float)n), n - 1u)]);
#if PSF_CPU_DEVICE
  /* On CPUs eight entries at a time: those at or below u are a prefix of the
   * window (the cdf does not decrease), counted without a branch per entry,
   * whose data-dependent loop exit a processor mispredicts. */
  while (i + 8u <= n - 1u) {
    const int8 below = vload8(0, cdf + i) <= (float8)(u);
    const uint k = popcount(psf_lanes8(below));
    i += k;
    if (k < 8u) return i;
  }
#endif
  while (i < n - 1u && cdf[i] <= u) ++i;
  return i;
}

/* --- the environment -------------------------------------------------------- */

/* World direction to the map's frame. */
inline float3 env_to_map(Environment env, float3 d) {
  return (float3)(dot(env.to_map0.xyz, d), dot(env.to_map1.xyz, d), dot(env.to_map2.xyz, d));
}

/* Map frame to world: the transpose of the rotation. */
inline float3 env_to_world(Environment env, float3 m) {
  return m.x * env.to_map0.xyz + m.y * env.to_map1.xyz + m.z * env.to_map2.xyz;
}

/* The map coordinates (u, v) in [0, 1]^2 of the unit map-frame direction m. */
inline float2 env_uv(float3 m) {
  float u = psf_atan2(m.x, -m.z) * (0.5f / PSF_ENV_PI);
  if (u < 0.0f) u += 1.0f;
  return (float2)(u, acos(clamp(m.y, -1.0f, 1.0f)) * (1.0f / PSF_ENV_PI));
}

/* The cell (x, y) of the sampling grid (W x H cells of the (u, v) square) holding
 * the map coordinates uv. */
inline uint2 env_cell_of_uv(Environment env, float2 uv) {
  uint x = min((uint)(uv.x * (float)env.width), env.width - 1u);
  uint y = min((uint)(uv.y * (float)env.height), env.height - 1u);
  return (uint2)(x, y);
}

inline float3 env_texel_value(Environment env, __global const float* data, uint2 t) {
  size_t i = 3u * ((size_t)t.y * env.width + t.x);
  return (float3)(data[i], data[i + 1u], data[i + 2u]);
}

/* The texels the map's radiance at (u, v) blends, bilinear as Mitsuba 3 reads
 * its envmap: column x's centre at u = (x + 1/2) / W, periodic in u; row y at
 * v = y / (H - 1), so the first and last rows lie on the poles. Returns (x0, x1,
 * y0, y1); *t the weights of x1 and y1. */
inline uint4 env_bilinear(Environment env, float2 uv, float2* t) {
  float fx = uv.x * (float)env.width - 0.5f, fy = uv.y * (float)(env.height - 1u);
  float x0f = floor(fx);
  float tx = clamp(fx - x0f, 0.0f, 1.0f);
  int xi = (int)x0f;
  uint x0 = xi < 0 ? env.width - 1u : min((uint)xi, env.width - 1u);
  uint x1 = x0 + 1u < env.width ? x0 + 1u : 0u;
  uint y0 = min((uint)fmax(fy, 0.0f), env.height > 1u ? env.height - 2u : 0u);
  uint y1 = min(y0 + 1u, env.height - 1u);
  *t = (float2)(tx, clamp(fy - (float)y0, 0.0f, 1.0f));
  return (uint4)(x0, x1, y0, y1);
}

/* The map's radiance at (u, v) (env_bilinear). */
inline float3 env_lookup(Environment env, __global const float* data, float2 uv) {
  float2 t;
  uint4 c = env_bilinear(env, uv, &t);
  float3 top = mix(env_texel_value(env, data, c.s02), env_texel_value(env, data, c.s12), t.x);
  float3 bottom = mix(env_texel_value(env, data, c.s03), env_texel_value(env, data, c.s13), t.x);
  return mix(top, bottom, t.y);
}

/* Offsets in the data buffer (psf_shared.h Environment): the marginal cdf, row
 * y's cdf over its blocks, and block b of row y's cdf over its texels. */
inline uint env_blocks(Environment env) { return (env.width + PSF_ENV_BLOCK - 1u) / PSF_ENV_BLOCK; }
inline size_t env_marginal_offset(Environment env) { return 3u * (size_t)env.width * env.height; }
inline size_t env_block_cdf_offset(Environment env, uint y) {
  return env_marginal_offset(env) + env.height + 1u + (size_t)y * (env_blocks(env) + 1u);
}
inline size_t env_texel_cdf_offset(Environment env, uint y, uint b) {
  size_t start = env_block_cdf_offset(env, env.height);
  start = (start + PSF_ENV_BLOCK - 1u) / PSF_ENV_BLOCK * PSF_ENV_BLOCK;
  return start + ((size_t)y * env_blocks(env) + b) * PSF_ENV_BLOCK;
}
/* The marginal's guide table (height entries), then row y's (env_blocks entries). */
inline size_t env_guide_offset(Environment env) { return env_texel_cdf_offset(env, env.height, 0u); }
inline size_t env_block_guide_offset(Environment env, uint y) {
  return env_guide_offset(env) + env.height + (size_t)y * env_blocks(env);
}

/* Probability of texel column x within row y (block, then texel in block). */
inline float env_column_prob(Environment env, __global const float* data, uint x, uint y) {
  uint b = x / PSF_ENV_BLOCK, k = x % PSF_ENV_BLOCK;
  __global const float* blocks = data + env_block_cdf_offset(env, y);
  __global const float* fine = data + env_texel_cdf_offset(env, y, b);
  return (blocks[b + 1u] - blocks[b]) * (fine[k] - (k > 0u ? fine[k - 1u] : 0.0f));
}

/* The solid-angle pdf with which env_sample returns the map-frame direction m
 * (unit) of map coordinates uv = env_uv(m), for a map (env.width > 0). */
inline float env_map_pdf(Environment env, __global const float* data, float3 m, float2 uv) {
  float sin_theta = sqrt(fmax(m.x * m.x + m.z * m.z, 0.0f));
  if (!(sin_theta > 0.0f)) return 0.0f;
  uint2 t = env_cell_of_uv(env, uv);
  __global const float* marginal = data + env_marginal_offset(env);
  float p_uv = (marginal[t.y + 1u] - marginal[t.y]) * (float)env.height * env_column_prob(env, data, t.x, t.y) *
               (float)env.width;
  return p_uv / (2.0f * PSF_ENV_PI * PSF_ENV_PI * sin_theta);
}

/* Radiance arriving from world direction d (unit) from infinitely far away and,
 * where pdf is not null, the solid-angle pdf with which env_sample returns d,
 * from one computation of the map coordinates. */
inline float3 env_radiance_pdf(Environment env, __global const float* data, float3 d, float* pdf) {
  if (!env.present || env.width == 0u) {
    if (pdf) *pdf = env.present ? 1.0f / (4.0f * PSF_ENV_PI) : 0.0f;
    return env.present ? env.scale.xyz : (float3)(0.0f);
  }
  float3 m = env_to_map(env, d);
  float2 uv = env_uv(m);
  if (pdf) *pdf = env_map_pdf(env, data, m, uv);
  return env_lookup(env, data, uv) * env.scale.xyz;
}

/* Radiance arriving from world direction d (unit) from infinitely far away. */
inline float3 env_radiance(Environment env, __global const float* data, float3 d) {
  return env_radiance_pdf(env, data, d, 0);
}

/* Solid-angle pdf with which env_sample returns world direction d (unit). */
inline float env_pdf(Environment env, __global const float* data, float3 d) {
  if (!env.present) return 0.0f;
  if (env.width == 0u) return 1.0f / (4.0f * PSF_ENV_PI);
  float3 m = env_to_map(env, d);
  return env_map_pdf(env, data, m, env_uv(m));
}

/* Sampling a map's distribution (env.width > 0) by the inversion method in
 * three steps, so that a wavefront can run each over all paths before the next
 * (shade.cl): the processor then overlaps the cache misses of many paths, where
 * one path's chain of them (the row's block guide and block cdf, then the
 * block's texel cdf) waits on each in turn.
 * env_sample_row: the row, from the marginal cdf by u2 (a small table, in
 * cache). Returns (u1, fv, row_p, 0): u2's remainder inside the row and the
 * row's probability; *y the row. */
inline float4 env_sample_row(Environment env, __global const float* data, float u1, float u2, uint* y) {
  __global const float* marginal = data + env_marginal_offset(env);
  *y = sample_cdf_guided(marginal + 1, env.height, data + env_guide_offset(env), u2);
  float row_lo = marginal[*y], row_p = marginal[*y + 1u] - row_lo;
  return (float4)(u1, clamp((u2 - row_lo) / row_p, 0.0f, 1.0f), row_p, 0.0f);
}

/* Where env_sample_block reads row y's tables for u1: the guide entry, and the
 * first entry of the block cdf the search starts from (add the guide's value). */
inline uint env_block_guide_at(Environment env, uint y, float u1) {
  uint nb = env_blocks(env);
  return (uint)env_block_guide_offset(env, y) + min((uint)(u1 * (float)nb), nb - 1u);
}
inline uint env_block_cdf_at(Environment env, uint y) { return (uint)env_block_cdf_offset(env, y) + 1u; }

/* env_sample_block: the block of row y, from its block cdf by u1 = r.x
 * (env_sample_row's record r). Returns (ub, fv, row_p, block_p): u1's remainder
 * inside the block, u2's inside the row, and the two probabilities; *b the
 * block. The column is a block of the row, then a texel of the block, each by
 * the remainder of u1 (the inversion method, so that u1's strata stay intact). */
inline float4 env_sample_block(Environment env, __global const float* data, float4 r, uint y, uint* b) {
  __global const float* blocks = data + env_block_cdf_offset(env, y);
  *b = sample_cdf_guided(blocks + 1, env_blocks(env), data + env_block_guide_offset(env, y), r.x);
  float block_lo = blocks[*b], block_p = blocks[*b + 1u] - block_lo;
  return (float4)(clamp((r.x - block_lo) / block_p, 0.0f, 1.0f), r.y, r.z, block_p);
}

/* env_sample_cell: the texel of block yb by the remainder ub (env_sample_block's
 * record r), a uniform point inside it, and its direction; *pdf its solid-angle
 * pdf, *uv its map coordinates (the radiance, not read here). */
inline float3 env_sample_cell(Environment env, __global const float* data, float4 r, uint2 yb, float* pdf,
                              float2* uv) {
  *uv = (float2)(0.0f);
  uint y = yb.x, b = yb.y;
  float ub = r.x, fv = r.y, row_p = r.z, block_p = r.w;
  __global const float* fine = data + env_texel_cdf_offset(env, y, b);
  uint last = min(env.width - b * PSF_ENV_BLOCK, (uint)PSF_ENV_BLOCK) - 1u;
  /* The first of the block's texels whose cdf exceeds ub: the number of those
   * before `last` at or below it, counted in one 16-wide comparison (the block's
   * cdf is one cache line) where a loop over them took 15 steps. */
#if PSF_ENV_BLOCK != 16
#error "env_sample_cell counts a block of 16 cells"
#endif
  const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  int16 below = (vload16(0, fine) <= (float16)(ub)) & (lane < (int16)((int)last));
  uint k = popcount(psf_lanes8(below.lo)) + popcount(psf_lanes8(below.hi));
  float texel_lo = k > 0u ? fine[k - 1u] : 0.0f, texel_p = fine[k] - texel_lo;
  uint x = b * PSF_ENV_BLOCK + k;
  float col_p = block_p * texel_p;
  if (!(row_p > 0.0f) || !(block_p > 0.0f) || !(texel_p > 0.0f)) {
    *pdf = 0.0f;
    return (float3)(0.0f, 1.0f, 0.0f);
  }
  /* A uniform point inside the texel, by the remainder of the uniform numbers. */
  float fu = clamp((ub - texel_lo) / texel_p, 0.0f, 1.0f);
  float v = ((float)y + fv) / (float)env.height;
  float u = ((float)x + fu) / (float)env.width;
  float cos_theta, cos_phi;
  float sin_theta = psf_sincos(v * PSF_ENV_PI, &cos_theta);
  float sin_phi = psf_sincos(u * 2.0f * PSF_ENV_PI, &cos_phi);
  float3 m = (float3)(sin_phi * sin_theta, cos_theta, -cos_phi * sin_theta);
  *uv = (float2)(u, v);
  *pdf = sin_theta > 0.0f
             ? row_p * (float)env.height * col_p * (float)env.width / (2.0f * PSF_ENV_PI * PSF_ENV_PI * sin_theta)
             : 0.0f;
  return env_to_world(env, m);
}

/* A world direction from a map's distribution (env.width > 0): all three steps. */
inline float3 env_sample_texel(Environment env, __global const float* data, float u1, float u2, float* pdf,
                               float2* uv) {
  uint y, b;
  float4 r = env_sample_block(env, data, env_sample_row(env, data, u1, u2, &y), y, &b);
  return env_sample_cell(env, data, r, (uint2)(y, b), pdf, uv);
}

/* A world direction from the environment's distribution; *pdf its solid-angle
 * pdf, *radiance the radiance from it (scaled). */
inline float3 env_sample(Environment env, __global const float* data, float u1, float u2, float* pdf,
                         float3* radiance) {
  if (env.width == 0u) {
    /* Uniform over the sphere. */
    float z = 1.0f - 2.0f * u1;
    float r = sqrt(fmax(0.0f, 1.0f - z * z));
    float phi = 2.0f * PSF_ENV_PI * u2;
    *pdf = 1.0f / (4.0f * PSF_ENV_PI);
    *radiance = env.scale.xyz;
    float c;
    float s = psf_sincos(phi, &c);
    return (float3)(r * c, r * s, z);
  }
  float2 uv;
  float3 wi = env_sample_texel(env, data, u1, u2, pdf, &uv);
  *radiance = *pdf > 0.0f ? env_lookup(env, data, uv) * env.scale.xyz : (float3)(0.0f);
  return wi;
}

/* --- next-event estimation ------------------------------------------------------ */

/* Mitsuba's spot falloff for cos_a = cos of the angle between the axis and the direction. */
inline float spot_falloff(Emitter em, float cos_a) {
  if (cos_a <= em.e1.w) return 0.0f;
  if (cos_a >= em.e2.w) return 1.0f;
  return clamp((em.e2.x - acos(clamp(cos_a, -1.0f, 1.0f))) * em.e2.y, 0.0f, 1.0f);
}

/* Whether a sphere light (centre c, radius r, normal sign, two-sided flag) is
 * sampled from p by the cone of directions it subtends: an outward-emitting,
 * one-sided sphere seen from outside (Mitsuba 3's sphere does the same); else
 * uniformly by area. Light sampling and emitter_pdf_sphere decide alike. */
inline bool sphere_cone_sampled(float3 c, float r, float sign, uint two_sided, float3 p) {
  float3 d = c - p;
  return sign > 0.0f && !two_sided && dot(d, d) > r * r;
}

/* 1 - cos(theta_max) of the cone of a sphere of radius r whose centre lies at
 * squared distance d2 > r^2, without cancellation: s / (1 + sqrt(1 - s)), s = r^2 / d2. */
inline float sphere_cone_width(float r, float d2) {
  float s = fmin(r * r / d2, 1.0f);
  return s / (1.0f + sqrt(1.0f - s));
}

/* One light chosen by `ul` from the table and a point (ua, ub) on it, seen from p.
 * Always inlined: as a call, it took its Environment by value and its
 * LightSample back through memory (PoCL, Mitsuba's cbox: 4 % fewer
 * instructions per path inlined). */
PSF_FORCE_INLINE LightSample emitter_sample(__global const Emitter* emitters,
                                                                 __global const float* cdf, uint count,
                                                                 Environment env, __global const float* env_data,
                                                                 float3 p, float ul, float ua, float ub) {
  LightSample ls;
  ls.pdf = 0.0f;
  ls.radiance = (float3)(0.0f);
  ls.wi = (float3)(0.0f, 0.0f, 1.0f);
  ls.dist = 0.0f;
  ls.delta = 0u;
  ls.tex = PSF_NO_TEXTURE;
  ls.prim = 0u;
  ls.b1 = ls.b2 = 0.0f;
  if (count == 0u) return ls;
  Emitter em = emitters[sample_cdf_guided(cdf, count, cdf + count, ul)];
  float select = em.radiance.w;
  if (em.type == PSF_EMITTER_ENVIRONMENT) {
    float pdf;
    float3 radiance;
    float3 wi = env_sample(env, env_data, ua, ub, &pdf, &radiance);
    if (!(pdf > 0.0f)) return ls;
    ls.wi = wi;
    ls.dist = INFINITY;
    ls.radiance = radiance;
    ls.pdf = select * pdf;
    return ls;
  }
  if (em.type == PSF_EMITTER_DIRECTIONAL) {
    ls.wi = -em.e1.xyz;
    ls.dist = INFINITY;
    ls.radiance = em.radiance.xyz;
    ls.pdf = select;
    ls.delta = 1u;
    return ls;
  }
  if (em.type == PSF_EMITTER_POINT || em.type == PSF_EMITTER_SPOT) {
    float3 d = em.v0.xyz - p;
    float d2 = dot(d, d);
    if (!(d2 > 0.0f)) return ls;
    ls.dist = sqrt(d2);
    ls.wi = d / ls.dist;
    float falloff = em.type == PSF_EMITTER_SPOT ? spot_falloff(em, -dot(ls.wi, em.e1.xyz)) : 1.0f;
    if (!(falloff > 0.0f)) return ls;
    ls.radiance = em.radiance.xyz * (falloff / d2);
    ls.pdf = select;
    ls.delta = 1u;
    return ls;
  }
  float3 lp, ln;
  if (em.type == PSF_EMITTER_SPHERE && sphere_cone_sampled(em.v0.xyz, em.e1.w, em.e2.w, em.two_sided, p)) {
    /* The cone around the direction w to the centre: 1 - cos(theta) uniform in
     * [0, 1 - cos(theta_max)], phi = 2 pi ub, then the nearer intersection
     * with the sphere (the precise form of raycast.cl); pdf = P(light) / (2 pi
     * (1 - cos(theta_max))). */
    float3 dc = em.v0.xyz - p;
    float d2 = dot(dc, dc), r = em.e1.w;
    float width = sphere_cone_width(r, d2);
    float omc = ua * width, cos_t = 1.0f - omc, sin_t = sqrt(fmax(0.0f, omc * (2.0f - omc))), cos_phi;
    float sin_phi = psf_sincos(2.0f * PSF_ENV_PI * ub, &cos_phi);
    Frame f = frame_from_normal(dc * rsqrt(d2));
    float3 wi = normalize(sin_t * cos_phi * f.s + sin_t * sin_phi * f.t + cos_t * f.n);
    float b = dot(wi, dc);
    float3 l = dc - b * wi;
    float dist = b - sqrt(fmax(0.0f, r * r - dot(l, l)));
    if (!(dist > 0.0f)) return ls;
    float3 n = normalize(p + dist * wi - em.v0.xyz);
    ls.wi = wi;
    ls.dist = dist;
    ls.pdf = select / (2.0f * PSF_ENV_PI * width);
    ls.radiance = em.radiance.xyz;
    ls.tex = em.tex_emission;
    ls.prim = em.prim;
    if (ls.tex != PSF_NO_TEXTURE) { /* the point's uv in the sphere's frame (surface.cl) */
      float2 uv = sphere_uv(n, em.e1.xyz, em.e2.xyz, cross(em.e1.xyz, em.e2.xyz));
      ls.b1 = uv.x;
      ls.b2 = uv.y;
    }
    if (!(ls.pdf > 0.0f) || !isfinite(ls.pdf)) ls.pdf = 0.0f;
    return ls;
  } else if (em.type == PSF_EMITTER_SPHERE) {
    /* Uniform by area: z = 1 - 2 ua, phi = 2 pi ub in the sphere's frame, so
     * that (ub, acos(z) / pi) is the point's uv. */
    float z = 1.0f - 2.0f * ua, rho = sqrt(fmax(0.0f, 1.0f - z * z)), cos_phi;
    float sin_phi = psf_sincos(2.0f * PSF_ENV_PI * ub, &cos_phi);
    float3 n = rho * cos_phi * em.e1.xyz + rho * sin_phi * em.e2.xyz + z * cross(em.e1.xyz, em.e2.xyz);
    lp = em.v0.xyz + em.e1.w * n;
    ln = n * em.e2.w;
    ls.b1 = ub;
    ls.b2 = em.tex_emission != PSF_NO_TEXTURE ? acos(clamp(z, -1.0f, 1.0f)) * (1.0f / PSF_ENV_PI) : 0.0f;
  } else {
    float su = sqrt(ua);
    lp = em.v0.xyz + su * (1.0f - ub) * em.e1.xyz + su * ub * em.e2.xyz;
    ln = normalize(cross(em.e1.xyz, em.e2.xyz));
    ls.b1 = su * (1.0f - ub);
    ls.b2 = su * ub;
  }
  float3 d = lp - p;
  float d2 = dot(d, d);
  if (!(d2 > 0.0f)) return ls;
  ls.dist = sqrt(d2);
  ls.wi = d / ls.dist;
  float cos_l = -dot(ln, ls.wi);
  if (em.two_sided) cos_l = fabs(cos_l);
  if (cos_l <= 0.0f) return ls;
  ls.pdf = select / em.v0.w * d2 / cos_l;
  ls.radiance = em.radiance.xyz;
  ls.tex = em.tex_emission;
  ls.prim = em.prim;
  return ls;
}

/* Solid-angle pdf with which emitter_sample would have chosen the point hit at
 * distance `dist` on triangle `prim` with cosine `cos_l` to its normal (sampled
 * uniformly by area: the pdf per area is tri_light_pdf[prim]). */
inline float emitter_pdf_hit(__global const float* tri_light_pdf, uint prim, float dist, float cos_l) {
  return cos_l > 0.0f ? tri_light_pdf[prim] * dist * dist / cos_l : 0.0f;
}

/* The same for the sphere light `prim` (its tri_pos entries `sp`, surface.cl
 * surface_sphere) seen from p: the cone's uniform pdf, or emitter_pdf_hit's
 * where it is sampled by area (sphere_cone_sampled). */
inline float emitter_pdf_sphere(__global const float* tri_light_pdf, uint prim, __global const float4* sp,
                                uint two_sided, float3 p, float dist, float cos_l) {
  float4 s0 = sp[0];
  if (!sphere_cone_sampled(s0.xyz, s0.w, sp[1].w, two_sided, p)) return emitter_pdf_hit(tri_light_pdf, prim, dist, cos_l);
  float3 d = s0.xyz - p;
  float select = tri_light_pdf[prim] * (4.0f * PSF_ENV_PI * s0.w * s0.w); /* per area times the area */
  return select / (2.0f * PSF_ENV_PI * sphere_cone_width(s0.w, dot(d, d)));
}

/* --- test hooks ------------------------------------------------------------------- */

/* Light samples seen from point p for count triples of uniform numbers u[i].xyz
 * (light choice, two for the point): out[3i] = (wi, pdf), out[3i+1] = (radiance,
 * dist), out[3i+2] = (delta, 0, 0, 0). Used by tests/test_emitter.cpp. */
__kernel void light_sample_points(uint count, __global const Emitter* emitters, __global const float* cdf, uint num_emitters,
                                  Environment env, __global const float* env_data, float4 p, __global const float4* u,
                                  __global float4* out) {
  uint i = get_global_id(0);
  if (i >= count) return;
  LightSample ls = emitter_sample(emitters, cdf, num_emitters, env, env_data, p.xyz, u[i].x, u[i].y, u[i].z);
  out[3u * i] = (float4)(ls.wi, ls.pdf);
  out[3u * i + 1u] = (float4)(ls.radiance, ls.dist);
  out[3u * i + 2u] = (float4)((float)ls.delta, 0.0f, 0.0f, 0.0f);
}

/* The environment along count world directions: out[i] = (radiance, env_pdf). */
__kernel void env_eval_points(uint count, Environment env, __global const float* env_data, __global const float4* dirs,
                              __global float4* out) {
  uint i = get_global_id(0);
  if (i >= count) return;
  float3 d = normalize(dirs[i].xyz);
  out[i] = (float4)(env_radiance(env, env_data, d), env_pdf(env, env_data, d));
}
