/* trace_lanes.cl: the per-path stage (shade.cl trace_paths) with eight paths at
 * a time in the lanes of float8 vectors.
 *
 * PoCL runs a kernel's work-items one after another and vectorises them only
 * where the kernel has no loops, no vector types and no stores under branches
 * (docs/performance-notes.md), so trace_paths, which loops over bounces and BVH
 * nodes, runs one path at a time in scalar code. Here each work-item holds
 * eight paths in lanes: the shading of a bounce on a diffuse surface (the hit's
 * triangle and frame, the emission it adds, a light sample on a triangle and
 * its MIS weight, the cosine-weighted direction, Russian roulette) and the
 * drawing of its samples are written with float8 vectors, so every step is one
 * instruction for the eight. Lane by lane: the two casts of a bounce (the BVH8
 * traversal of raycast.cl, alpha-tested where the scene has masks; in a scene
 * of a few primitives without masks both casts are vector code too, each
 * primitive against the eight rays: flat_closest8, flat_any8), the loads
 * of the hit's triangle, material and light, and what is rarer or branchier: a
 * colour texture's albedo and frame, any other material's surface (a blend's
 * choice, its frame and bump map: surface.cl's own functions; its BSDF's value,
 * pdf and sample are the vectors', LanesBsdfs, for every kind of BSDF, with a
 * bump map's side rule; a kind they lacked would go through bsdf.cl's), the
 * environment map an escaped ray sees, a light sample on a point, spot or
 * directional light, on a sphere light other than below, or on any light but
 * a triangle among many lights (emitter.cl emitter_sample), a hit on an
 * analytic sphere of a material the vectors do not shade or of a texture (its
 * uv and frame). Among a few lights (PSF_LANES_FEW_LIGHTS) the cone of a
 * one-sided, outward-emitting, untextured sphere light seen from outside and
 * the directions of a constant environment are sampled in vectors, and a
 * constant environment is seen in vectors. A light sample on an environment map takes its
 * steps over all lanes before the next, between the closest-hit casts
 * (EnvLanes), so that the lanes' cache misses overlap and wait behind casts.
 * A lane whose path ends stores the path's state and takes the next path of
 * the work-item's run of `per_item` paths, so the lanes stay full until the
 * run's end. The kernel draws its camera rays itself
 * (camera_rays8: camera.cl's rays from the same samples, eight paths in
 * vectors), so that no camera_rays pass writes rays and states for it to read.
 * Where nothing after the trace reads the paths' states and filtering vertices
 * (`store` PSF_LANES_STORE_DIRECT: a batch neither filtered nor kept, without
 * AOVs or emission rays), a path's end writes its contribution instead, as
 * accumulate.cl computes it (the radiance before its filtering vertex plus
 * alpha * c), and no state or vertex: 16 bytes a path where there were 160,
 * and no accumulate pass. Where
 * the filter (or a test) reads the vertices and the values c, but nothing
 * else of the states (`store` PSF_LANES_STORE_TUPLES: no emission rays), a
 * path's end writes its vertex, its c into the tuple store's values and the
 * radiance before its vertex into contrib_unfiltered, which
 * accumulate_tuples then completes: 32 bytes a path where the states took 96,
 * and no store_tuples pass.
 *
 * The scene class (host/render.cpp lanes_materials_supported): no medium, null
 * boundary or camera medium (an analytic sphere's lanes that shade lane by lane
 * take their frame from surface.cl surface_sphere, the others their normal
 * from its centre; an emission texture multiplies the emission where
 * it is hit or sampled lane by lane). The arithmetic is shade_path_inline's for
 * that class, written the same way, and the samples are drawn by the same
 * functions, so a path's result is the same as trace_paths' up to the rounding
 * of a different instruction order (tests/test_emitter.cpp compares the two). */

#define PSF_LANES 8
/* Up to this many lights the lanes choose one by counting cdf entries (below). */
#define PSF_LANES_FEW_LIGHTS 16u
/* Lane l of a private vector (a scalar view of its memory). */
#define LANE_F(v, l) (((float*)&(v))[l])
#define LANE_U(v, l) (((uint*)&(v))[l])
#define LANE_I(v, l) (((int*)&(v))[l])

/* Eight 3-vectors, one per lane. */
typedef struct {
  float8 x, y, z;
} Vec8;

inline Vec8 vec8(float8 x, float8 y, float8 z) {
  Vec8 r;
  r.x = x;
  r.y = y;
  r.z = z;
  return r;
}
inline Vec8 vec8_add(Vec8 a, Vec8 b) { return vec8(a.x + b.x, a.y + b.y, a.z + b.z); }
inline Vec8 vec8_sub(Vec8 a, Vec8 b) { return vec8(a.x - b.x, a.y - b.y, a.z - b.z); }
inline Vec8 vec8_mul(Vec8 a, Vec8 b) { return vec8(a.x * b.x, a.y * b.y, a.z * b.z); }
inline Vec8 vec8_scale(Vec8 a, float8 s) { return vec8(a.x * s, a.y * s, a.z * s); }
inline Vec8 vec8_div(Vec8 a, float8 s) { return vec8(a.x / s, a.y / s, a.z / s); }
inline Vec8 vec8_neg(Vec8 a) { return vec8(-a.x, -a.y, -a.z); }
inline float8 vec8_dot(Vec8 a, Vec8 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline float8 vec8_max3(Vec8 a) { return fmax(a.x, fmax(a.y, a.z)); }
inline Vec8 vec8_cross(Vec8 a, Vec8 b) {
  return vec8(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
/* Per lane: c ? a : b (c a mask of all ones or zeros per lane). */
inline Vec8 vec8_select(Vec8 b, Vec8 a, int8 c) {
  return vec8(select(b.x, a.x, c), select(b.y, a.y, c), select(b.z, a.z, c));
}
inline float8 vec8_length(Vec8 a) { return sqrt(vec8_dot(a, a)); }
inline Vec8 vec8_normalize(Vec8 a) { return vec8_scale(a, rsqrt(vec8_dot(a, a))); }
inline void vec8_set(Vec8* v, uint l, float3 a) {
  LANE_F(v->x, l) = a.x;
  LANE_F(v->y, l) = a.y;
  LANE_F(v->z, l) = a.z;
}
/* Lane l of v (an lvalue), read lane by lane where v lies. A function taking
 * the Vec8 by value copied its three vectors whole first, and such a load
 * stalls on lane stores made to them just before (the store
 * buffer cannot forward a scalar store to a wider load). */
#define VEC8_GET(v, l) ((float3)(LANE_F((v).x, l), LANE_F((v).y, l), LANE_F((v).z, l)))
/* Lane l's frame (bsdf.cl Frame) of tangents s, t and normal n. */
inline Frame vec8_frame(const Vec8* s, const Vec8* t, const Vec8* n, uint l) {
  Frame f;
  f.s = VEC8_GET(*s, l);
  f.t = VEC8_GET(*t, l);
  f.n = VEC8_GET(*n, l);
  return f;
}

inline float8 power_heuristic8(float8 a, float8 b) {
  float8 a2 = a * a, b2 = b * b;
  return select((float8)(0.0f), a2 / (a2 + b2), (a2 + b2) > 0.0f);
}

/* psf_sincos (sampling.cl), lane by lane the same operations. */
inline float8 psf_sincos8(float8 x, float8* c) {
  float8 ax = fabs(x);
  int8 j = convert_int8(ax * 1.27323954473516f);
  j += j & 1;
  float8 y = convert_float8(j);
  float8 z = ((ax - y * 0.78515625f) - y * 2.4187564849853515625e-4f) - y * 3.77489497744594108e-8f;
  float8 zz = z * z;
  float8 s = ((-1.9515295891e-4f * zz + 8.3321608736e-3f) * zz - 1.6666654611e-1f) * zz * z + z;
  float8 co =
      ((2.443315711809948e-5f * zz - 1.388731625493765e-3f) * zz + 4.166664568298827e-2f) * zz * zz - 0.5f * zz + 1.0f;
  int8 q = (j >> 1) & 3;
  float8 sv = select(s, co, (q & 1) != 0), cv = select(co, s, (q & 1) != 0);
  sv = select(sv, -sv, (q & 2) != 0);
  cv = select(cv, -cv, ((q + 1) & 2) != 0);
  *c = cv;
  return select(sv, -sv, x < 0.0f);
}

/* square_to_cosine_hemisphere (bsdf.cl) per lane. */
inline Vec8 cosine_hemisphere8(float8 u1, float8 u2) {
  float8 a = 2.0f * u1 - 1.0f, b = 2.0f * u2 - 1.0f;
  int8 wide = fabs(a) > fabs(b), centre = a == 0.0f && b == 0.0f;
  float8 r = select(b, a, wide);
  float8 q = select(a, b, wide) / select(r, (float8)(1.0f), centre);
  float8 phi = select((PSF_PI / 2.0f) - (PSF_PI / 4.0f) * q, (PSF_PI / 4.0f) * q, wide);
  float8 c;
  float8 s = psf_sincos8(phi, &c);
  float8 dx = r * c, dy = r * s;
  return vec8(dx, dy, sqrt(fmax(0.0f, 1.0f - dx * dx - dy * dy)));
}

/* frame_from_normal (bsdf.cl) per lane: s and t around unit n. */
inline void frame_from_normal8(Vec8 n, Vec8* s, Vec8* t) {
  float8 sign = select((float8)(-1.0f), (float8)(1.0f), n.z >= 0.0f);
  float8 a = -1.0f / (sign + n.z);
  float8 c = n.x * n.y * a;
  *s = vec8(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
  *t = vec8(c, sign + n.y * n.y * a, -n.y);
}

/* offset_origin (shade.cl) per lane. */
inline Vec8 offset_origin8(Vec8 p, Vec8 n) {
  float8 scale = PSF_RAY_EPS * fmax(1.0f, vec8_max3(vec8(fabs(p.x), fabs(p.y), fabs(p.z))));
  return vec8_add(p, vec8_scale(n, scale));
}

/* The paths of one work-item's lanes between bounces: PathState's fields, the
 * next ray, and which lanes hold a live path. */
typedef struct {
  Vec8 org, dir; /* the ray to cast */
  float8 tmin, tmax;
  Vec8 beta; /* PathState.throughput */
  float8 bsdf_pdf;
  Vec8 radiance; /* PathState.radiance */
  float8 radiance_w;
  Vec8 vertex_radiance; /* PathState.vertex_radiance */
  float8 vertex_radiance_w;
  Vec8 alpha; /* PathVertex.alpha: the throughput to the filtering vertex (0 before one) */
  Vec8 prev; /* PathState.prev_pos */
  float8 path_length;
  uint8 pixel, sample, depth, flags, path;
  int8 live; /* all ones: the lane holds a path */
} Lanes;

/* pixel_filter_offset (camera.cl) per lane. */
inline float8 pixel_filter_offset8(const Camera* c, float8 u) {
  if (c->filter == PSF_PIXEL_FILTER_TENT)
    return select(c->filter_a * (1.0f - sqrt(2.0f - 2.0f * u)), c->filter_a * (sqrt(2.0f * u) - 1.0f), u < 0.5f);
  if (c->filter == PSF_PIXEL_FILTER_GAUSSIAN) return c->filter_a * psf_erfinv8((2.0f * u - 1.0f) * c->filter_b);
  return (2.0f * u - 1.0f) * (c->filter_a > 0.0f ? c->filter_a : 0.5f);
}

/* The camera rays of eight consecutive paths, drawn a vector at a time for
 * lanes to take one by one (lanes_refill). */
typedef struct {
  Vec8 org, dir;
  float8 tmin, tmax;
  uint8 pixel, sample; /* film pixel and sample number */
  uint first;          /* the batch's paths first..first + 7 */
} CameraRays8;

/* Path j's camera ray (camera.cl camera_ray from the samples camera_rays
 * draws), its film pixel and its sample number, as lane l of `c`. */
inline void lane_camera_ray(const FrameParams* params, const Camera* camera, __global const uint* sobol, uint j, uint l,
                            CameraRays8* c) {
  uint fx, fy, sample;
  const uint pixel = camera_film_pixel(*params, *camera, j, &sample, &fx, &fy);
  const Ray r =
      camera_ray(*camera, fx, fy, sample_8d_keyed(sobol, pixel_seed(params->seed, pixel), sample, PSF_DIM_PIXEL));
  vec8_set(&c->org, l, r.org.xyz);
  vec8_set(&c->dir, l, r.dir.xyz);
  LANE_F(c->tmin, l) = r.org.w;
  LANE_F(c->tmax, l) = r.dir.w;
  LANE_U(c->pixel, l) = pixel;
  LANE_U(c->sample, l) = sample;
}

/* The camera rays of paths j..j + 7 into `c`: camera_film_pixel, the samples
 * (sample_8d_keyed's numbers: consecutive paths are consecutive pixels of one
 * sample number, or of two where they pass the image's end, so the unscrambled
 * Sobol points are those of two indices) and camera_ray, in vectors. An image
 * narrower than the lanes takes them lane by lane. Out of line, as the casts. */
__attribute__((noinline)) void camera_rays8(const FrameParams* params, const Camera* camera, __global const uint* sobol,
                                            uint j, CameraRays8* c) {
  c->first = j;
  const uint width = params->width;
  if (width < PSF_LANES) {
    for (uint l = 0u; l < PSF_LANES; ++l) lane_camera_ray(params, camera, sobol, j + l, l, c);
    return;
  }
  const ulong pixels = (ulong)width * (ulong)params->height;
  const ulong g = frame_first_path(*params) + (ulong)j;
  const uint pixel0 = (uint)(g % pixels), sample0 = (uint)(g / pixels);
  const uint8 k = (uint8)(0u, 1u, 2u, 3u, 4u, 5u, 6u, 7u);
  /* At most one row end and one image end among eight pixels of a row of at least eight. */
  const int8 next_image = convert_int8((ulong8)(pixel0) + convert_ulong8(k) >= (ulong8)(pixels));
  uint8 x = (uint8)(pixel0 % width) + k;
  const int8 next_row = x >= (uint8)(width);
  x = select(x, x - width, next_row);
  uint8 y = (uint8)(pixel0 / width) + select((uint8)(0u), (uint8)(1u), next_row);
  y = select(y, y - params->height, next_image);
  const uint8 sample = select((uint8)(sample0), (uint8)(sample0 + 1u), next_image);
  const uint8 fx = x + (uint)camera->right.w, fy = y + (uint)camera->down.w;
  const uint8 pixel = fy * camera->width + fx;
  const uint8 key = psf_hash_combine8((uint8)(psf_hash(params->seed)), pixel);
  /* Dimensions PSF_DIM_PIXEL.. (two, four with a lens). */
  float8 u[4];
  const uint dims = camera->aperture > 0.0f ? 4u : 2u;
  uint8 row = sobol_unscrambled8(sobol, sample0, PSF_DIM_PIXEL);
  uint8 row_next = any(next_image) ? sobol_unscrambled8(sobol, sample0 + 1u, PSF_DIM_PIXEL) : row;
  for (uint d = 0u; d < dims; ++d) {
    const uint dim = PSF_DIM_PIXEL + d;
    const uint8 bits = select((uint8)(LANE_U(row, d)), (uint8)(LANE_U(row_next, d)), next_image);
    u[d] = convert_float8(nested_uniform_scramble8(bits, psf_hash_combine8(key, (uint8)(dim))) >> 8) *
           (1.0f / 16777216.0f);
  }
  const float8 s =
      (convert_float8(fx) + 0.5f + pixel_filter_offset8(camera, u[0])) / (float)camera->width + camera->shift_s;
  const float8 t =
      (convert_float8(fy) + 0.5f + pixel_filter_offset8(camera, u[1])) / (float)camera->height + camera->shift_t;
  const float3 fw = camera->forward.xyz, rt = camera->right.xyz, dn = camera->down.xyz, o = camera->origin.xyz;
  const float8 a = 2.0f * s - 1.0f, b = 2.0f * t - 1.0f;
  Vec8 dir = vec8(fw.x + a * rt.x + b * dn.x, fw.y + a * rt.y + b * dn.y, fw.z + a * rt.z + b * dn.z);
  Vec8 org = vec8((float8)(o.x), (float8)(o.y), (float8)(o.z));
  if (camera->orthographic) {
    org = vec8(org.x + dir.x - fw.x, org.y + dir.y - fw.y, org.z + dir.z - fw.z);
    dir = vec8((float8)(fw.x), (float8)(fw.y), (float8)(fw.z));
  } else if (camera->aperture > 0.0f) {
    const float8 r = camera->aperture * sqrt(u[2]);
    float8 cs;
    const float8 sn = psf_sincos8(2.0f * 3.14159265358979f * u[3], &cs);
    const float3 er = normalize(rt), ed = normalize(dn);
    const Vec8 lens = vec8(r * (cs * er.x + sn * ed.x), r * (cs * er.y + sn * ed.y), r * (cs * er.z + sn * ed.z));
    dir = vec8_sub(vec8_scale(dir, (float8)(camera->focus)), lens);
    org = vec8_add(org, lens);
  }
  const Vec8 d = vec8_normalize(dir);
  const float8 inv_cos = 1.0f / (d.x * fw.x + d.y * fw.y + d.z * fw.z);
  c->org = org;
  c->dir = d;
  c->tmin = camera->origin.w * inv_cos;
  c->tmax = camera->forward.w * inv_cos;
  c->pixel = pixel;
  c->sample = sample;
}

/* The lanes of `take` take the batch's next paths, from *next on while below
 * `end`, in lane order: their camera rays (from `c`, drawn anew when it does
 * not hold the path) and the state camera_rays gives a path (the lanes' class
 * has no camera medium). Each lane's values go in by selects of whole vectors:
 * lane stores, which the next vector loads of these fields would have waited
 * for (a store buffer cannot forward scalar stores to a wider load), cost
 * more. */
inline void lanes_refill(Lanes* ln, int8 take, uint* next, uint end, const FrameParams* params, const Camera* camera,
                         __global const uint* sobol, CameraRays8* c) {
  const int8 ids = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
  int8 load = (int8)(0);
  for (uint todo = psf_lanes8(take); todo != 0u && *next < end; todo &= todo - 1u) {
    const uint l = bvh_first_lane(todo), j = (*next)++;
    if (j - c->first >= (uint)PSF_LANES) camera_rays8(params, camera, sobol, j, c);
    const uint k = j - c->first;
    const int8 m = ids == (int8)((int)l);
    load |= m;
    const Vec8 org = vec8((float8)(LANE_F(c->org.x, k)), (float8)(LANE_F(c->org.y, k)), (float8)(LANE_F(c->org.z, k)));
    ln->org = vec8_select(ln->org, org, m);
    ln->dir = vec8_select(
        ln->dir, vec8((float8)(LANE_F(c->dir.x, k)), (float8)(LANE_F(c->dir.y, k)), (float8)(LANE_F(c->dir.z, k))), m);
    ln->tmin = select(ln->tmin, (float8)(LANE_F(c->tmin, k)), m);
    ln->tmax = select(ln->tmax, (float8)(LANE_F(c->tmax, k)), m);
    ln->pixel = select(ln->pixel, (uint8)(LANE_U(c->pixel, k)), as_uint8(m));
    ln->sample = select(ln->sample, (uint8)(LANE_U(c->sample, k)), as_uint8(m));
    ln->path = select(ln->path, (uint8)(j), as_uint8(m));
  }
  const Vec8 zero = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
  ln->beta = vec8_select(ln->beta, vec8((float8)(1.0f), (float8)(1.0f), (float8)(1.0f)), load);
  ln->bsdf_pdf = select(ln->bsdf_pdf, (float8)(0.0f), load);
  ln->radiance = vec8_select(ln->radiance, zero, load);
  ln->radiance_w = select(ln->radiance_w, (float8)(0.0f), load);
  ln->vertex_radiance = vec8_select(ln->vertex_radiance, zero, load);
  ln->vertex_radiance_w = select(ln->vertex_radiance_w, (float8)(0.0f), load);
  ln->alpha = vec8_select(ln->alpha, zero, load);
  ln->prev = vec8_select(ln->prev, ln->org, load);
  ln->path_length = select(ln->path_length, (float8)(0.0f), load);
  ln->depth = select(ln->depth, (uint8)(0u), as_uint8(load));
  ln->flags = select(ln->flags, (uint8)(PSF_PATH_ALIVE), as_uint8(load));
  ln->live |= load;
}

/* What a lane writes at its path's end (trace_lanes' `store`). */
#define PSF_LANES_STORE_STATES 0u /* the state and the filtering vertex */
#define PSF_LANES_STORE_DIRECT 1u /* the contribution (contrib) */
#define PSF_LANES_STORE_TUPLES 2u /* the vertex, c (values) and the radiance before the vertex (contrib) */

/* Lane l's path has ended: its state as trace_paths leaves it (`pending` the
 * light sample's contribution where its shadow ray was blocked), and the
 * empty filtering vertex of a path that met none (camera_rays' default); or,
 * as `store` says, its contribution as accumulate.cl's, or its vertex, its c
 * as store_tuples' (zero without a vertex) and the radiance before. */
inline void lanes_store(const Lanes* ln, uint l, float3 pending, __global PathState* states,
                        __global PathVertex* vertices, uint store, __global float4* contrib,
                        __global float4* values) {
  if (store == PSF_LANES_STORE_DIRECT) {
    float3 c = VEC8_GET(ln->radiance, l);
    if (LANE_U(ln->flags, l) & PSF_PATH_VERTEX) c += VEC8_GET(ln->alpha, l) * VEC8_GET(ln->vertex_radiance, l);
    contrib[LANE_U(ln->path, l)] = (float4)(c, 1.0f);
    return;
  }
  const uint j = LANE_U(ln->path, l);
  if (store == PSF_LANES_STORE_TUPLES) {
    contrib[j] = (float4)(VEC8_GET(ln->radiance, l), 0.0f);
    values[j] = (float4)(VEC8_GET(ln->vertex_radiance, l), 0.0f);
    if (LANE_U(ln->flags, l) & PSF_PATH_VERTEX) return; /* its vertex is written */
    PathVertex none;
    none.position = none.normal = none.albedo = none.alpha = (float4)(0.0f);
    vertices[j] = none;
    return;
  }
  PathState st;
  st.throughput = (float4)(VEC8_GET(ln->beta, l), LANE_F(ln->bsdf_pdf, l));
  st.radiance = (float4)(VEC8_GET(ln->radiance, l), LANE_F(ln->radiance_w, l));
  st.vertex_radiance = (float4)(VEC8_GET(ln->vertex_radiance, l), LANE_F(ln->vertex_radiance_w, l));
  st.pending = (float4)(pending, 0.0f);
  st.prev_pos = (float4)(VEC8_GET(ln->prev, l), LANE_F(ln->path_length, l));
  st.pixel = LANE_U(ln->pixel, l);
  st.sample = LANE_U(ln->sample, l);
  st.depth = LANE_U(ln->depth, l);
  st.flags = LANE_U(ln->flags, l);
  states[LANE_U(ln->path, l)] = st;
  if (!(st.flags & PSF_PATH_VERTEX)) {
    PathVertex none;
    none.position = none.normal = none.albedo = none.alpha = (float4)(0.0f);
    vertices[LANE_U(ln->path, l)] = none;
  }
}

/* Adds c where `mask`, as shade.cl's add_radiance (seen: add_radiance_seen). */
inline void lanes_add_radiance(Lanes* ln, Vec8 c, int8 mask, bool seen) {
  const int8 vertex = (ln->flags & PSF_PATH_VERTEX) != 0u;
  int8 to_vertex = mask & vertex, to_prefix = mask & ~vertex;
  int8 raise_w = to_prefix;
  if (seen) raise_w &= ~(ln->depth == 0u && (ln->flags & (PSF_PATH_VERTEX | PSF_PATH_NULL_CROSSED)) == 0u);
  ln->vertex_radiance = vec8_select(ln->vertex_radiance, vec8_add(ln->vertex_radiance, c), to_vertex);
  ln->radiance = vec8_select(ln->radiance, vec8_add(ln->radiance, c), to_prefix);
  ln->radiance_w = select(ln->radiance_w, (float8)(1.0f), raise_w);
}

/* The dimensions of each lane's bounce (shade.cl bounce_samples: light
 * choice, point on the light, BSDF direction, Russian roulette, lobe), the
 * same numbers as sample_8d_keyed's, with the work across the lanes, in two
 * steps so that a bounce scrambles only the dimensions some lane uses
 * (lanes_sample_dim). lanes_sample_rows: each lane's unscrambled point is the
 * xor of the rows of the generator matrices that its sample index selects (a
 * row holds 8 consecutive dimensions), read four index bits at a time from the
 * nibbles' xors (PSF_SOBOL_NIBBLES), for the nibbles of the largest index
 * without a branch on any lane's; then the points are transposed to a vector
 * per dimension. Lanes whose dimensions run past the table (from depth 36 on,
 * 35 with a lens) take sample_bits_keyed's own path in lanes_sample_dim. */
typedef struct {
  uint8 cols[PSF_DIMS_PER_BOUNCE]; /* the unscrambled points, a vector per dimension */
  uint8 key, dim, sample;          /* each lane's scrambling key, first dimension and sample index */
  int8 own;                        /* active lanes past the table */
} LaneSamples;

inline void lanes_sample_rows(__global const uint* sobol, uint seed_hash, uint dim0, const Lanes* ln, int8 active,
                              LaneSamples* s) {
  s->key = psf_hash_combine8((uint8)(seed_hash), ln->pixel);
  s->dim = (uint8)(dim0) + (uint8)(PSF_DIMS_PER_BOUNCE)*ln->depth;
  s->sample = ln->sample;
  const int8 table = s->dim <= (uint8)(PSF_SOBOL_DIMS - 8u);
  s->own = active & ~table;
  const uint8 samples = select((uint8)(0u), ln->sample, as_uint8(active & table));
  uint any_bits = 0u;
  for (uint l = 0u; l < PSF_LANES; ++l) any_bits |= LANE_U(samples, l);
  const uint nibbles = (35u - clz(any_bits)) / 4u;
  __global const uint* base[PSF_LANES];
  uint8 rows[PSF_LANES];
  for (uint l = 0u; l < PSF_LANES; ++l) {
    base[l] = sobol + PSF_SOBOL_NIBBLES + (LANE_I(table, l) ? LANE_U(s->dim, l) : 0u);
    rows[l] = (uint8)(0u);
  }
  /* Nibble by nibble, the lanes' loads of one nibble independent of each other. */
  for (uint n = 0u; n < nibbles; ++n)
    for (uint l = 0u; l < PSF_LANES; ++l)
      rows[l] ^= vload8(0, base[l] + (16u * n + ((LANE_U(samples, l) >> (4u * n)) & 15u)) * PSF_SOBOL_DIMS);
  /* The transpose, a vector per dimension, in three rounds of shuffles. */
#if PSF_DIMS_PER_BOUNCE != 7
#error "lanes_sample_rows transposes seven dimensions"
#endif
  const uint8 lo = (uint8)(0, 8, 1, 9, 2, 10, 3, 11), hi = (uint8)(4, 12, 5, 13, 6, 14, 7, 15);
  const uint8 p01e = shuffle2(rows[0], rows[1], lo), p01h = shuffle2(rows[0], rows[1], hi);
  const uint8 p23e = shuffle2(rows[2], rows[3], lo), p23h = shuffle2(rows[2], rows[3], hi);
  const uint8 p45e = shuffle2(rows[4], rows[5], lo), p45h = shuffle2(rows[4], rows[5], hi);
  const uint8 p67e = shuffle2(rows[6], rows[7], lo), p67h = shuffle2(rows[6], rows[7], hi);
  const uint8 q_a = (uint8)(0, 1, 8, 9, 2, 3, 10, 11), q_b = (uint8)(4, 5, 12, 13, 6, 7, 14, 15);
  const uint8 q0 = shuffle2(p01e, p23e, q_a), q1 = shuffle2(p01e, p23e, q_b);
  const uint8 q2 = shuffle2(p01h, p23h, q_a), q3 = shuffle2(p01h, p23h, q_b);
  const uint8 q4 = shuffle2(p45e, p67e, q_a), q5 = shuffle2(p45e, p67e, q_b);
  const uint8 q6 = shuffle2(p45h, p67h, q_a), q7 = shuffle2(p45h, p67h, q_b);
  const uint8 c_a = (uint8)(0, 1, 2, 3, 8, 9, 10, 11), c_b = (uint8)(4, 5, 6, 7, 12, 13, 14, 15);
  s->cols[0] = shuffle2(q0, q4, c_a);
  s->cols[1] = shuffle2(q0, q4, c_b);
  s->cols[2] = shuffle2(q1, q5, c_a);
  s->cols[3] = shuffle2(q1, q5, c_b);
  s->cols[4] = shuffle2(q2, q6, c_a);
  s->cols[5] = shuffle2(q2, q6, c_b);
  s->cols[6] = shuffle2(q3, q7, c_a);
}

/* Dimension o of the bounce (PSF_DIM_*) for every lane, scrambled 8 lanes at a
 * time: sample_bits_keyed's numbers as floats in [0, 1) (sample_8d_keyed's). */
inline float8 lanes_sample_dim(__global const uint* sobol, const LaneSamples* s, uint o) {
  uint8 v = nested_uniform_scramble8(s->cols[o], psf_hash_combine8(s->key, s->dim + o));
  for (uint todo = psf_lanes8(s->own); todo != 0u; todo &= todo - 1u) {
    const uint l = bvh_first_lane(todo);
    LANE_U(v, l) = sample_bits_keyed(sobol, LANE_U(s->key, l), LANE_U(s->sample, l), LANE_U(s->dim, l) + o);
  }
  return convert_float8(v >> 8) * (1.0f / 16777216.0f);
}

/* The texels env_lookup reads at uv: a prefetch of the two of each row (12
 * bytes each, so each pair's end too). */
inline void env_prefetch_texels(Environment env, __global const float* data, float2 uv) {
  float2 t;
  const uint4 c = env_bilinear(env, uv, &t);
  __global const float* row0 = data + 3u * ((size_t)c.z * env.width + c.x);
  __global const float* row1 = data + 3u * ((size_t)c.w * env.width + c.x);
  psf_prefetch(row0);
  psf_prefetch(row0 + 5);
  psf_prefetch(row1);
  psf_prefetch(row1 + 5);
}

/* What env_radiance_pdf reads for direction d (unit) from a map: a prefetch
 * of its texels and of the cdf entries of its pdf (env_map_pdf). */
inline void env_prefetch_lookup(Environment env, __global const float* data, float3 d) {
  const float2 uv = env_uv(env_to_map(env, d));
  const uint2 t = env_cell_of_uv(env, uv);
  psf_prefetch(data + env_marginal_offset(env) + t.y);
  psf_prefetch(data + env_block_cdf_offset(env, t.y) + t.x / PSF_ENV_BLOCK);
  psf_prefetch(data + env_texel_cdf_offset(env, t.y, t.x / PSF_ENV_BLOCK));
  env_prefetch_texels(env, data, uv);
}

/* Light samples on an environment map (env.width > 0) for the lanes of
 * `mask`, as emitter_sample draws them (emitter.cl env_sample: the row, the
 * block, the texel and its direction, then the radiance), in five steps, each
 * over the lanes before the next and each prefetching what the next reads.
 * A sample depends on the lane's two numbers only, not on the hit, so the
 * kernel starts the lanes' samples before their closest-hit casts and takes
 * the steps between them (trace_lanes): each chain of cache misses (the row's
 * block guide, its block cdf, the block's texel cdf, the texels) then waits
 * behind a cast instead of stalling the kernel, where a step right after the
 * one before waited on its prefetch. A lane whose texel has no probability
 * gets pdf 0, as emitter_sample. */
typedef struct {
  float4 r[PSF_LANES];  /* env_sample_row's, then env_sample_block's record */
  uint y[PSF_LANES];    /* the row */
  uint b[PSF_LANES];    /* the block */
  float2 uv[PSF_LANES]; /* the texels' map coordinates */
  int8 mask;            /* the lanes with a sample */
  Vec8 wi;              /* the direction (world), where pdf > 0 */
  float8 pdf;           /* its solid-angle pdf times the environment's selection probability */
} EnvLanes;

/* Step 1: the rows, from the marginal cdf (small, in cache); prefetches the
 * rows' block guide entries. */
inline void env_lanes_row(Environment env, __global const float* data, int8 mask, float8 u1, float8 u2, EnvLanes* e) {
  e->mask = mask;
  for (uint todo = psf_lanes8(mask); todo != 0u; todo &= todo - 1u) {
    const uint l = bvh_first_lane(todo);
    e->r[l] = env_sample_row(env, data, LANE_F(u1, l), LANE_F(u2, l), &e->y[l]);
    psf_prefetch(data + env_block_guide_at(env, e->y[l], e->r[l].x));
  }
}
/* Step 2: the guide entries; prefetches the block cdf entries they point at. */
inline void env_lanes_guide(Environment env, __global const float* data, const EnvLanes* e) {
  for (uint l = 0u; l < PSF_LANES; ++l)
    if (LANE_I(e->mask, l))
      psf_prefetch(data + env_block_cdf_at(env, e->y[l]) + as_uint(data[env_block_guide_at(env, e->y[l], e->r[l].x)]));
}
/* Step 3: the blocks; prefetches their texel cdfs. */
inline void env_lanes_block(Environment env, __global const float* data, EnvLanes* e) {
  for (uint todo = psf_lanes8(e->mask); todo != 0u; todo &= todo - 1u) {
    const uint l = bvh_first_lane(todo);
    e->r[l] = env_sample_block(env, data, e->r[l], e->y[l], &e->b[l]);
    psf_prefetch(data + env_texel_cdf_offset(env, e->y[l], e->b[l]));
  }
}
/* Step 4: the texels, the directions and their pdfs (times `choose`); prefetches the texels. */
inline void env_lanes_cell(Environment env, __global const float* data, float choose, EnvLanes* e) {
  for (uint todo = psf_lanes8(e->mask); todo != 0u; todo &= todo - 1u) {
    const uint l = bvh_first_lane(todo);
    float p;
    const float3 w = env_sample_cell(env, data, e->r[l], (uint2)(e->y[l], e->b[l]), &p, &e->uv[l]);
    vec8_set(&e->wi, l, p > 0.0f ? w : (float3)(0.0f, 0.0f, 1.0f));
    LANE_F(e->pdf, l) = p > 0.0f ? choose * p : 0.0f;
    if (p > 0.0f) env_prefetch_texels(env, data, e->uv[l]);
  }
}
/* Step 5: the radiance of the lanes of `mask` (among e's) into radiance, where pdf > 0. */
inline void env_lanes_radiance(Environment env, __global const float* data, const EnvLanes* e, int8 mask,
                               Vec8* radiance) {
  for (uint l = 0u; l < PSF_LANES; ++l)
    if (LANE_I(mask, l) && LANE_F(e->pdf, l) > 0.0f)
      vec8_set(radiance, l, env_lookup(env, data, e->uv[l]) * env.scale.xyz);
}

/* One lane's casts (raycast.cl), out of line: the kernel calls each in a loop
 * over the lanes, and its vectors stay where they are across the call. The
 * ray and hit go by pointer: by value, the ray's two halves were stored apart
 * and loaded as one, a stall on every call (PoCL, Mitsuba's cbox: the
 * call's argument copy was 8 % of the kernel's samples). Alpha-tested apart
 * (lane_*_masked: a scene with opacity masks), so that the casts of a scene
 * without masks compile without the tests; and without the sphere test apart
 * (lane_*_tris: a scene without analytic spheres), where the call to
 * sphere_pack_test made every cast spill twelve vectors on entry (Mitsuba's
 * cbox: 2-3 % of a render). With spheres the test is inlined for the same
 * reason (PSF_SPHERES_INLINE: sphere-light 6 % faster), in double, or in
 * float where no sphere of the BVH needs double (lane_*_float_spheres,
 * PSF_SPHERES_INLINE_FLOAT). */
#define PSF_LANE_CASTS(SUFFIX, SPHERES)                                                                                \
  __attribute__((noinline)) void lane_closest##SUFFIX(__global const BvhNode* nodes, __global const BvhTriPack* packs, \
                                                      const Ray* r, Hit* h) {                                          \
    *h = intersect_closest_leaves(nodes, packs, *r, 0, SPHERES);                                                       \
  }                                                                                                                    \
  __attribute__((noinline)) void lane_any##SUFFIX(__global const BvhNode* nodes, __global const BvhTriPack* packs,     \
                                                  const Ray* r, Hit* h) {                                              \
    *h = intersect_any_hit_leaves(nodes, packs, *r, 0, SPHERES);                                                       \
  }                                                                                                                    \
  __attribute__((noinline)) void lane_closest_masked##SUFFIX(__global const BvhNode* nodes,                            \
                                                             __global const BvhTriPack* packs,                         \
                                                             const AlphaScene* alpha, const Ray* r, Hit* h) {          \
    *h = intersect_closest_leaves(nodes, packs, *r, alpha, SPHERES);                                                   \
  }                                                                                                                    \
  __attribute__((noinline)) void lane_any_masked##SUFFIX(__global const BvhNode* nodes,                                \
                                                         __global const BvhTriPack* packs, const AlphaScene* alpha,    \
                                                         const Ray* r, Hit* h) {                                       \
    *h = intersect_any_hit_leaves(nodes, packs, *r, alpha, SPHERES);                                                   \
  }
PSF_LANE_CASTS(, PSF_SPHERES_INLINE)
PSF_LANE_CASTS(_float_spheres, PSF_SPHERES_INLINE_FLOAT)
PSF_LANE_CASTS(_tris, PSF_SPHERES_NONE)

/* Lane casts by the scene's kind: alpha-tested (`masked`), with spheres
 * (FrameParams.spheres: PSF_FRAME_SPHERES_*). */
inline void lane_cast_closest(bool masked, uint spheres, __global const BvhNode* nodes,
                              __global const BvhTriPack* packs, const AlphaScene* alpha, const Ray* r, Hit* h) {
  if (masked && spheres == PSF_FRAME_SPHERES_DOUBLE)
    lane_closest_masked(nodes, packs, alpha, r, h);
  else if (masked && spheres == PSF_FRAME_SPHERES_FLOAT)
    lane_closest_masked_float_spheres(nodes, packs, alpha, r, h);
  else if (masked)
    lane_closest_masked_tris(nodes, packs, alpha, r, h);
  else if (spheres == PSF_FRAME_SPHERES_DOUBLE)
    lane_closest(nodes, packs, r, h);
  else if (spheres == PSF_FRAME_SPHERES_FLOAT)
    lane_closest_float_spheres(nodes, packs, r, h);
  else
    lane_closest_tris(nodes, packs, r, h);
}
inline void lane_cast_any(bool masked, uint spheres, __global const BvhNode* nodes, __global const BvhTriPack* packs,
                          const AlphaScene* alpha, const Ray* r, Hit* h) {
  if (masked && spheres == PSF_FRAME_SPHERES_DOUBLE)
    lane_any_masked(nodes, packs, alpha, r, h);
  else if (masked && spheres == PSF_FRAME_SPHERES_FLOAT)
    lane_any_masked_float_spheres(nodes, packs, alpha, r, h);
  else if (masked)
    lane_any_masked_tris(nodes, packs, alpha, r, h);
  else if (spheres == PSF_FRAME_SPHERES_DOUBLE)
    lane_any(nodes, packs, r, h);
  else if (spheres == PSF_FRAME_SPHERES_FLOAT)
    lane_any_float_spheres(nodes, packs, r, h);
  else
    lane_any_tris(nodes, packs, r, h);
}

/* Casts in scenes of a few primitives (FrameParams.flat_packs > 0:
 * Renderer::flat_packs sets it where the BVH holds at most kLanesFlatPrims
 * primitives or is one node, and none is alpha-tested): every primitive of the
 * packs against the eight lanes' rays at once, without the BVH (but for the
 * root's boxes, flat_root_leaves). A cast through the BVH costs
 * a call, a slab test and the branches of its traversal whatever the scene's
 * size, and a lane's ray goes into a Ray and its hit out of a Hit; here the
 * rays stay in the lanes' vectors. Each primitive's test is raycast.cl's
 * (pack_test, the sphere tests) with the roles of the vectors swapped: the
 * same arithmetic per ray and primitive, the same hits up to the choice
 * between primitives at exactly the same distance (the BVH's order of packs
 * against the packs' order here), the barycentric tolerance outside a leaf's
 * box, and a sphere's precision, which is its pack's (float or double, as
 * sphere_pack_test has it; the lanes' BVH casts test every sphere in double
 * where any needs it). */
#if defined(cl_khr_fp64)
typedef double8 flat_real8;
#define FLAT_REAL8(x) convert_double8(x)
#define FLAT_REAL_SCALAR double
#else
typedef float8 flat_real8;
#define FLAT_REAL8(x) (x)
#define FLAT_REAL_SCALAR float
#endif

/* The lanes' rays as the flat tests read them: origin, direction and its
 * length, and the unit direction and 1 / length of the sphere tests. */
typedef struct {
  Vec8 org, dir;
  float8 len;
  Vec8 unit;      /* dir / len, as sphere_pack_test_float's */
  float8 inv_len; /* 1 / len */
  Vec8 inv;       /* with the leaves' box tests: 1 / dir as slab_ray clamps it */
} FlatRays;

inline FlatRays flat_rays(Vec8 org, Vec8 dir, bool spheres, bool boxes) {
  FlatRays r;
  r.org = org;
  r.dir = dir;
  r.len = vec8_length(dir);
  r.inv_len = (float8)(0.0f);
  r.unit = dir;
  if (spheres) {
    r.inv_len = 1.0f / r.len;
    r.unit = vec8_scale(dir, r.inv_len);
  }
  r.inv = dir;
  if (!boxes) return r;
  const float8 tiny = (float8)(1e-12f);
  r.inv = vec8(1.0f / select(dir.x, copysign(tiny, dir.x), isless(fabs(dir.x), tiny)),
               1.0f / select(dir.y, copysign(tiny, dir.y), isless(fabs(dir.y), tiny)),
               1.0f / select(dir.z, copysign(tiny, dir.z), isless(fabs(dir.z), tiny)));
  return r;
}

/* The lanes whose rays meet child k's box of node f (slab_test's arithmetic)
 * within (tmin, tmax). */
inline int8 flat_box8(__global const float* f, uint k, const FlatRays* r, float8 tmin, float8 tmax) {
  const uint w = PSF_BVH_WIDTH;
  const float8 x0 = (f[BVH_MIN_X + k] - r->org.x) * r->inv.x, x1 = (f[BVH_MIN_X + w + k] - r->org.x) * r->inv.x;
  const float8 y0 = (f[BVH_MIN_Y + k] - r->org.y) * r->inv.y, y1 = (f[BVH_MIN_Y + w + k] - r->org.y) * r->inv.y;
  const float8 z0 = (f[BVH_MIN_Z + k] - r->org.z) * r->inv.z, z1 = (f[BVH_MIN_Z + w + k] - r->org.z) * r->inv.z;
  const float8 tn = BVH_MAX(BVH_MAX(BVH_MIN(x0, x1), BVH_MIN(y0, y1)), BVH_MAX(BVH_MIN(z0, z1), tmin));
  const float8 tf =
      BVH_MIN(BVH_MIN(BVH_MAX(x0, x1), BVH_MAX(y0, y1)), BVH_MIN(BVH_MAX(z0, z1), tmax)) * PSF_SLAB_FAR_SCALE;
  return tn <= tf;
}

/* pack_test of lane j of triangle pack p against the eight rays: the lanes hit
 * within (tmin, tmax), their distances into *t (infinity elsewhere) and
 * barycentrics into *u, *v. */
inline int8 flat_triangle8(__global const float* p, uint j, const FlatRays* r, float8 tmin, float8 tmax, float8* t_out,
                           float8* u_out, float8* v_out) {
  const float8 dx = r->dir.x, dy = r->dir.y, dz = r->dir.z;
  const float e1x = p[PACK_E1 + j], e1y = p[PACK_E1 + PSF_BVH_WIDTH + j], e1z = p[PACK_E1 + 2 * PSF_BVH_WIDTH + j];
  const float e2x = p[PACK_E2 + j], e2y = p[PACK_E2 + PSF_BVH_WIDTH + j], e2z = p[PACK_E2 + 2 * PSF_BVH_WIDTH + j];
  const float8 pvx = dy * e2z - dz * e2y, pvy = dz * e2x - dx * e2z, pvz = dx * e2y - dy * e2x;
  const float8 inv_det = 1.0f / (e1x * pvx + e1y * pvy + e1z * pvz);
  const float8 sx = r->org.x - p[PACK_V0 + j];
  const float8 sy = r->org.y - p[PACK_V0 + PSF_BVH_WIDTH + j];
  const float8 sz = r->org.z - p[PACK_V0 + 2 * PSF_BVH_WIDTH + j];
  const float8 u = (sx * pvx + sy * pvy + sz * pvz) * inv_det;
  const float8 qx = sy * e1z - sz * e1y, qy = sz * e1x - sx * e1z, qz = sx * e1y - sy * e1x;
  const float8 v = (dx * qx + dy * qy + dz * qz) * inv_det;
  const float8 t = (e2x * qx + e2y * qy + e2z * qz) * inv_det;
  const float8 eps = (PSF_BARY_EPS_DIST * r->len) * fabs(t) * p[PACK_INV_SIZE + j] + PSF_BARY_EPS;
  const int8 ok = (u >= -eps) & (v >= -eps) & (u + v <= 1.0f + eps) & (t > tmin) & (t < tmax);
  *t_out = select((float8)(INFINITY), t, ok);
  *u_out = u;
  *v_out = v;
  return ok;
}

/* sphere_roots for the eight rays. */
inline int8 flat_roots8(float8 t0, float8 t1, int8 hit, float8 tmin, float8 tmax, float8* t_out) {
  const float8 tn = BVH_MIN(t0, t1), tf = BVH_MAX(t0, t1);
  const int8 ok_n = hit & (tn > tmin) & (tn < tmax);
  const int8 ok_f = hit & (tf > tmin) & (tf < tmax);
  *t_out = select(select((float8)(INFINITY), tf, ok_f), tn, ok_n);
  return ok_n | ok_f;
}

/* sphere_pack_test_float of lane j of sphere pack p against the eight rays. */
inline int8 flat_sphere8(__global const float* p, uint j, const FlatRays* r, float8 tmin, float8 tmax, float8* t_out) {
  const float8 dx = r->unit.x, dy = r->unit.y, dz = r->unit.z;
  const float8 fx = r->org.x - p[PACK_V0 + j];
  const float8 fy = r->org.y - p[PACK_V0 + PSF_BVH_WIDTH + j];
  const float8 fz = r->org.z - p[PACK_V0 + 2 * PSF_BVH_WIDTH + j];
  const float rad = p[PACK_E1 + j];
  const float8 b = -(fx * dx + fy * dy + fz * dz);
  const float8 lx = fx + b * dx, ly = fy + b * dy, lz = fz + b * dz;
  const float8 r2 = (float8)(rad * rad);
  const float8 disc = r2 - (lx * lx + ly * ly + lz * lz);
  const float8 c = (fx * fx + fy * fy + fz * fz) - r2;
  const float8 q = b + copysign(sqrt(fmax(disc, 0.0f)), b);
  return flat_roots8(c * r->inv_len / q, q * r->inv_len, (disc >= 0.0f) & (int8)(rad > 0.0f ? -1 : 0), tmin, tmax,
                     t_out);
}

/* sphere_pack_test_double of lane j of sphere pack p against the eight rays. */
inline int8 flat_sphere8_double(__global const float* p, uint j, const FlatRays* r, float8 tmin, float8 tmax,
                                float8* t_out) {
  const flat_real8 dirx = FLAT_REAL8(r->dir.x), diry = FLAT_REAL8(r->dir.y), dirz = FLAT_REAL8(r->dir.z);
  const flat_real8 len = sqrt(dirx * dirx + diry * diry + dirz * dirz);
  const flat_real8 inv_len = (FLAT_REAL_SCALAR)1 / len;
  const flat_real8 dx = dirx * inv_len, dy = diry * inv_len, dz = dirz * inv_len;
  const flat_real8 fx = FLAT_REAL8(r->org.x) - (FLAT_REAL_SCALAR)p[PACK_V0 + j];
  const flat_real8 fy = FLAT_REAL8(r->org.y) - (FLAT_REAL_SCALAR)p[PACK_V0 + PSF_BVH_WIDTH + j];
  const flat_real8 fz = FLAT_REAL8(r->org.z) - (FLAT_REAL_SCALAR)p[PACK_V0 + 2 * PSF_BVH_WIDTH + j];
  const float radf = p[PACK_E1 + j];
  const FLAT_REAL_SCALAR rad = radf;
  const flat_real8 b = -(fx * dx + fy * dy + fz * dz);
  const flat_real8 lx = fx + b * dx, ly = fy + b * dy, lz = fz + b * dz;
  const FLAT_REAL_SCALAR r2 = rad * rad;
  const flat_real8 disc = r2 - (lx * lx + ly * ly + lz * lz);
  const flat_real8 c = (fx * fx + fy * fy + fz * fz) - r2;
  const float8 bf = convert_float8(b), discf = convert_float8(disc);
  const float8 q = bf + copysign(sqrt(fmax(discf, 0.0f)), bf);
  const float8 inv_lenf = convert_float8(inv_len);
  const int8 hit = convert_int8(disc >= (flat_real8)(0)) & (int8)(radf > 0.0f ? -1 : 0);
  return flat_roots8(convert_float8(c) * inv_lenf / q, q * inv_lenf, hit, tmin, tmax, t_out);
}

/* Whether pack p's spheres are tested in double (sphere_pack_test_body). */
inline bool flat_pack_double(__global const float* p) { return p[PACK_E1 + PSF_BVH_WIDTH] != 0.0f; }

/* Whether the flat casts of `count` packs skip the leaves whose boxes no lane's
 * ray meets: with at least PSF_FLAT_BOX_PACKS packs and a root (not null) whose
 * children are all leaves or empty. Decided once per work-item: the flat casts
 * take the root where it holds, else null. With fewer packs the box tests cost more
 * than they save (PoCL, AMD EPYC, tracing time with the boxes / without:
 * the thin principled sheets, 3 packs, 1.05; Mitsuba's cbox and our Cornell
 * box, 5 packs, 0.96 and 0.97). */
#define PSF_FLAT_BOX_PACKS 4u
inline bool flat_root_leaves(__global const BvhNode* root, uint count) {
  if (!root || count < PSF_FLAT_BOX_PACKS) return false;
  for (uint c = 0u; c < PSF_BVH_WIDTH; ++c)
    if (root->child[c] != PSF_EMPTY_CHILD && !(root->child[c] & PSF_LEAF_BIT)) return false;
  return true;
}

/* The closest hits of the lanes of `live` among the first `count` packs: t
 * (tmax where none), prim (PSF_NO_HIT where none) and the barycentrics, as the
 * lane casts give them; lanes not live get t 0 and no hit. root: the BVH's root
 * where flat_root_leaves holds (its leaves are skipped by their boxes), else
 * null. */
inline void flat_closest8(__global const BvhTriPack* packs, uint count, __global const BvhNode* root, bool spheres,
                          Vec8 org, Vec8 dir, float8 tmin, float8 tmax, int8 live, float8* t_out, uint8* prim_out,
                          float8* u_out, float8* v_out) {
  const bool boxes = root != 0;
  const FlatRays r = flat_rays(org, dir, spheres, boxes);
  float8 best = select((float8)(-1.0f), tmax, live); /* no hit within a dead lane's (tmin, -1) */
  uint8 prim = (uint8)(PSF_NO_HIT);
  float8 bu = (float8)(0.0f), bv = (float8)(0.0f);
  for (uint c = 0u; c < (boxes ? (uint)PSF_BVH_WIDTH : 1u); ++c) {
    uint k0 = 0u, k1 = count;
    if (boxes) {
      const uint child = root->child[c];
      if (child == PSF_EMPTY_CHILD || !any(flat_box8((__global const float*)root, c, &r, tmin, best))) continue;
      k0 = child & PSF_LEAF_FIRST_MASK;
      k1 = k0 + ((child >> PSF_LEAF_COUNT_SHIFT) & PSF_LEAF_COUNT_MASK) + 1u;
    }
    for (uint k = k0; k < k1; ++k) {
      __global const float* p = (__global const float*)(packs + k);
      __global const uint* prims = (__global const uint*)(p + PACK_PRIM);
      const bool sphere_pack = spheres && pack_is_spheres(p);
      const bool dbl = sphere_pack && flat_pack_double(p);
      for (uint j = 0u; j < PSF_BVH_WIDTH; ++j) {
        const uint id = prims[j];
        if (id == PSF_NO_HIT) break; /* a pack's used lanes come first */
        float8 t, u = (float8)(0.0f), v = (float8)(0.0f);
        const int8 ok = sphere_pack ? (dbl ? flat_sphere8_double(p, j, &r, tmin, best, &t)
                                           : flat_sphere8(p, j, &r, tmin, best, &t))
                                    : flat_triangle8(p, j, &r, tmin, best, &t, &u, &v);
        best = select(best, t, ok);
        prim = select(prim, (uint8)(id & ~(PSF_PRIM_MASKED | PSF_PRIM_SPHERE)), as_uint8(ok));
        bu = select(bu, u, ok);
        bv = select(bv, v, ok);
      }
    }
  }
  *t_out = select((float8)(0.0f), best, live);
  *prim_out = select((uint8)(PSF_NO_HIT), prim, as_uint8(live));
  *u_out = bu;
  *v_out = bv;
}

/* The lanes of `cast` whose segment (tmin, tmax) meets a primitive of the
 * first `count` packs (intersect_any_hit_leaves' verdict); root as flat_closest8's. */
inline int8 flat_any8(__global const BvhTriPack* packs, uint count, __global const BvhNode* root, bool spheres,
                      Vec8 org, Vec8 dir, float8 tmin, float8 tmax, int8 cast) {
  const bool boxes = root != 0;
  const FlatRays r = flat_rays(org, dir, spheres, boxes);
  int8 blocked = ~cast;
  for (uint c = 0u; c < (boxes ? (uint)PSF_BVH_WIDTH : 1u) && !all(blocked); ++c) {
    uint k0 = 0u, k1 = count;
    if (boxes) {
      const uint child = root->child[c];
      if (child == PSF_EMPTY_CHILD || !any(~blocked & flat_box8((__global const float*)root, c, &r, tmin, tmax)))
        continue;
      k0 = child & PSF_LEAF_FIRST_MASK;
      k1 = k0 + ((child >> PSF_LEAF_COUNT_SHIFT) & PSF_LEAF_COUNT_MASK) + 1u;
    }
    for (uint k = k0; k < k1 && !all(blocked); ++k) {
      __global const float* p = (__global const float*)(packs + k);
      __global const uint* prims = (__global const uint*)(p + PACK_PRIM);
      const bool sphere_pack = spheres && pack_is_spheres(p);
      const bool dbl = sphere_pack && flat_pack_double(p);
      for (uint j = 0u; j < PSF_BVH_WIDTH; ++j) {
        if (prims[j] == PSF_NO_HIT) break;
        float8 t, u, v;
        blocked |= sphere_pack ? (dbl ? flat_sphere8_double(p, j, &r, tmin, tmax, &t)
                                      : flat_sphere8(p, j, &r, tmin, tmax, &t))
                               : flat_triangle8(p, j, &r, tmin, tmax, &t, &u, &v);
      }
    }
  }
  return cast & blocked;
}
/* One lane's surface where the vectors do not shade it (a colour texture or a
 * material of another kind), as shade_path_inline: a blend's choice by the
 * hash of the path and bounce, the frame and the textures. */
__attribute__((noinline)) void lane_surface(Material* m, __global const Material* materials,
                                            __global const TriAttrib* a, float b1, float b2, float3 p0, float3 p1,
                                            float3 p2, float3 ng, float3 wo, __global const TextureInfo* textures,
                                            __global const half* texels, float u_blend, Frame* f, float3* unperturbed) {
  if (m->blend != 0u) *m = surface_blend(*m, materials, a, b1, b2, textures, texels, u_blend, dot(ng, wo) > 0.0f);
  *f = surface_frame(m, a, b1, b2, p0, p1, p2, ng, wo, textures, texels, unperturbed);
}

/* One lane's BSDF value and pdf for a light sample (zero where a bump map's
 * sides disagree), and its sampled direction, as shade_path_inline. */
__attribute__((noinline)) float3 lane_bsdf_eval(const Material* m, __global const TextureInfo* textures,
                                                __global const half* texels, const Frame* f, const float3* unperturbed,
                                                float3 wo, float3 wi, float* pdf) {
  *pdf = 0.0f;
  if (!surface_side_agrees(m, *f, *unperturbed, wi)) return (float3)(0.0f);
  return bsdf_eval(*m, surface_table(*m, textures, texels), *f, wo, wi, pdf);
}
__attribute__((noinline)) void lane_bsdf_sample(const Material* m, __global const TextureInfo* textures,
                                                __global const half* texels, const Frame* f, const float3* unperturbed,
                                                float3 wo, float u1, float u2, float uc, BsdfSample* bs) {
  *bs = bsdf_sample(*m, surface_table(*m, textures, texels), *f, wo, u1, u2, bsdf_chooses_lobe(*m) ? uc : 0.5f);
  if (!surface_side_agrees(m, *f, *unperturbed, bs->wi)) bs->weight = (float3)(0.0f);
}

/* --- rough plastic in vectors ------------------------------------------------
 * bsdf.cl's roughplastic (bsdf_eval_local, bsdf_sample_general), GGX or
 * Beckmann, isotropic or not (the floors and walls of Bitterli's scenes,
 * Mitsuba's default roughplastic), written with the same operations in float8
 * arithmetic; its transmittance table read lane by lane. */

/* Whether the lanes shade material m as a Plastic8. */
inline bool lanes_plastic(const Material* m) { return m->type == PSF_MATERIAL_ROUGH_PLASTIC; }

/* The lanes' rough plastics: their parameters (Material's, as bsdf.cl reads
 * them) and the coat's transmittance towards wo. */
typedef struct {
  float8 au, av, eta, scale, weight, t_o; /* alpha_u, alpha_v, eta.x, eta.y, albedo.w, T(cos_o) */
  Vec8 spec, base;                        /* specular, plastic_base */
  int8 beckmann;                          /* Beckmann's distribution, else GGX */
} Plastic8;

/* fresnel_dielectric for 0 <= cos_i (a microfacet's cosine towards o). */
inline float8 fresnel_dielectric8(float8 ci, float8 n) {
  const float8 ct2 = 1.0f - (1.0f - ci * ci) / (n * n);
  const float8 ct = sqrt(fmax(ct2, 0.0f));
  const float8 rs = (ci - n * ct) / (ci + n * ct);
  const float8 rp = (n * ci - ct) / (n * ci + ct);
  return select(0.5f * (rs * rs + rp * rp), (float8)(1.0f), ct2 <= 0.0f);
}

/* mf_D and mf_G1 for GGX of roughness au, av (the same operations for au = av). */
inline float8 ggx_D8(Vec8 m, float8 au, float8 av) {
  const float8 ct = m.z, x = m.x / au, y = m.y / av, ct2 = ct * ct;
  const float8 d = x * x + y * y + ct2;
  const float8 r = 1.0f / (PSF_PI * au * av * d * d);
  return select((float8)(0.0f), r, (ct > 0.0f) & (r * ct > 1e-20f));
}
inline float8 ggx_G1_8(Vec8 v, Vec8 m, float8 au, float8 av) {
  const float8 xy = au * au * v.x * v.x + av * av * v.y * v.y;
  const float8 t2 = xy / (v.z * v.z);
  const float8 g = select(2.0f / (1.0f + sqrt(1.0f + t2)), (float8)(1.0f), xy == 0.0f);
  return select(g, (float8)(0.0f), vec8_dot(v, m) * v.z <= 0.0f);
}

/* mf_sample for GGX: a visible normal for v (v.z > 0). */
inline Vec8 ggx_sample8(Vec8 v, float8 au, float8 av, float8 u1, float8 u2) {
  const Vec8 vh = vec8_normalize(vec8(au * v.x, av * v.y, v.z));
  const float8 lensq = vh.x * vh.x + vh.y * vh.y;
  const float8 inv = rsqrt(lensq);
  const int8 tilted = lensq > 0.0f;
  const Vec8 t1 =
      vec8(select((float8)(1.0f), -vh.y * inv, tilted), select((float8)(0.0f), vh.x * inv, tilted), (float8)(0.0f));
  const Vec8 t2 = vec8_cross(vh, t1);
  const float8 r = sqrt(u1), phi = 2.0f * PSF_PI * u2;
  float8 cos_phi;
  const float8 sin_phi = psf_sincos8(phi, &cos_phi);
  const float8 p1 = r * cos_phi, s = 0.5f * (1.0f + vh.z);
  const float8 p2 = (1.0f - s) * sqrt(fmax(0.0f, 1.0f - p1 * p1)) + s * (r * sin_phi);
  const float8 pz = sqrt(fmax(0.0f, 1.0f - p1 * p1 - p2 * p2));
  const Vec8 nh = vec8_add(vec8_add(vec8_scale(t1, p1), vec8_scale(t2, p2)), vec8_scale(vh, pz));
  return vec8_normalize(vec8(au * nh.x, av * nh.y, fmax(1e-6f, nh.z)));
}

/* mf_D, mf_G1 and mf_sample for Beckmann of roughness au, av. */
inline float8 beckmann_D8(Vec8 m, float8 au, float8 av) {
  const float8 ct = m.z, x = m.x / au, y = m.y / av, ct2 = ct * ct;
  const float8 r = exp(-(x * x + y * y) / ct2) / (PSF_PI * au * av * ct2 * ct2);
  return select((float8)(0.0f), r, (ct > 0.0f) & (r * ct > 1e-20f));
}
inline float8 beckmann_G1_8(Vec8 v, Vec8 m, float8 au, float8 av) {
  const float8 xy = au * au * v.x * v.x + av * av * v.y * v.y;
  const float8 t2 = xy / (v.z * v.z);
  const float8 r = rsqrt(t2);
  const float8 g = (3.535f * r + 2.181f * r * r) / (1.0f + 2.276f * r + 2.577f * r * r);
  return select(select(g, (float8)(1.0f), (xy == 0.0f) | (r >= 1.6f)), (float8)(0.0f), vec8_dot(v, m) * v.z <= 0.0f);
}
inline Vec8 beckmann_sample8(float8 au, float8 av, float8 u1, float8 u2) {
  float8 cp;
  float8 sp = psf_sincos8(2.0f * PSF_PI * u2, &cp);
  const int8 aniso = au != av;
  if (any(aniso)) {
    float8 cq;
    const float8 sq = psf_sincos8(atan2(av * sp, au * cp), &cq);
    sp = select(sp, sq, aniso);
    cp = select(cp, cq, aniso);
  }
  const float8 inv_a2 = cp * cp / (au * au) + sp * sp / (av * av);
  const float8 tan2 = -log(1.0f - u1) / inv_a2;
  const float8 ct = rsqrt(1.0f + tan2), st = sqrt(fmax(0.0f, 1.0f - ct * ct));
  return vec8(st * cp, st * sp, ct);
}

/* The microfacet terms at the half-vector h of o and i (mf_D, mf_G1 of each,
 * mf_pdf of o), GGX's or, in the lanes of `beckmann`, Beckmann's. */
inline void mf8_terms(Vec8 h, Vec8 o, Vec8 i, float8 au, float8 av, int8 beckmann, float8* d, float8* g_o,
                      float8* g_i, float8* pm) {
  *d = *g_o = *g_i = *pm = (float8)(0.0f);
  if (!all(beckmann)) {
    *d = ggx_D8(h, au, av);
    *g_o = ggx_G1_8(o, h, au, av);
    *g_i = ggx_G1_8(i, h, au, av);
    *pm = *d * *g_o * fabs(vec8_dot(o, h)) / o.z;
  }
  if (any(beckmann)) {
    const float8 db = beckmann_D8(h, au, av);
    *d = select(*d, db, beckmann);
    *g_o = select(*g_o, beckmann_G1_8(o, h, au, av), beckmann);
    *g_i = select(*g_i, beckmann_G1_8(i, h, au, av), beckmann);
    *pm = select(*pm, db * h.z, beckmann);
  }
}

/* mf_sample for o (o.z > 0): GGX's visible normal or, in the lanes of
 * `beckmann`, Beckmann's. */
inline Vec8 mf8_sample(Vec8 o, float8 au, float8 av, int8 beckmann, int8 lanes, float8 u1, float8 u2) {
  Vec8 h = vec8(u1, u1, u1);
  if (any(lanes & ~beckmann)) h = ggx_sample8(o, au, av, u1, u2);
  if (any(lanes & beckmann)) h = vec8_select(h, beckmann_sample8(au, av, u1, u2), beckmann);
  return h;
}

/* plastic_prob_specular for the coat's reflectance 1 - T(cos_o). */
inline float8 plastic8_prob_specular(const Plastic8* p) {
  const float8 r = 1.0f - p->t_o;
  const float8 ps = r * p->weight, pd = (1.0f - r) * (1.0f - p->weight);
  return select((float8)(0.0f), ps / (ps + pd), ps + pd > 0.0f);
}

/* bsdf_eval_local's roughplastic: f and *pdf for local o and i, t_i the coat's
 * transmittance towards i. */
inline Vec8 plastic8_eval(const Plastic8* p, Vec8 o, Vec8 i, float8 t_i, float8* pdf) {
  const int8 on = (o.z > 0.0f) & (i.z > 0.0f);
  const float8 ps = plastic8_prob_specular(p);
  const Vec8 h = vec8_normalize(vec8_add(o, i));
  const float8 oh = vec8_dot(o, h);
  const float8 fr = fresnel_dielectric8(oh, p->eta);
  float8 d, g_o, g_i, pm;
  mf8_terms(h, o, i, p->au, p->av, p->beckmann, &d, &g_o, &g_i, &pm);
  const float8 g = g_o * g_i;
  *pdf = select((float8)(0.0f), ps * pm / (4.0f * oh) + (1.0f - ps) * i.z * PSF_INV_PI, on);
  const Vec8 f = vec8_add(vec8_scale(p->spec, fr * d * g / (4.0f * o.z * i.z)),
                          vec8_scale(p->base, p->scale * p->t_o * t_i * PSF_INV_PI));
  return vec8_select(vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f)), f, on);
}

/* --- rough conductors in vectors ---------------------------------------------
 * bsdf.cl's roughconductor (bsdf_eval_local, bsdf_sample_general) for the
 * lanes whose material has an isotropic GGX or Beckmann distribution (the
 * metals of Bitterli's scenes, Mitsuba's default roughconductor),
 * with the same operations in float8. */

/* Whether the lanes shade material m as a Conductor8. */
inline bool lanes_conductor(const Material* m) { return m->type == PSF_MATERIAL_ROUGH_CONDUCTOR; }

/* The lanes' rough conductors: Material's alpha_u, alpha_v, specular, eta and
 * k, and whether the distribution is Beckmann's. */
typedef struct {
  float8 au, av;
  Vec8 spec, eta, k;
  int8 beckmann;
} Conductor8;

inline void conductor8_set(Conductor8* c, uint l, const Material* m) {
  LANE_F(c->au, l) = m->alpha_u;
  LANE_F(c->av, l) = m->alpha_v;
  vec8_set(&c->spec, l, m->specular.xyz);
  vec8_set(&c->eta, l, m->eta.xyz);
  vec8_set(&c->k, l, m->k.xyz);
  LANE_I(c->beckmann, l) = (m->flags & PSF_MATFLAG_BECKMANN) ? -1 : 0;
}

/* fresnel_conductor of one channel. */
inline float8 fresnel_conductor8(float8 cos_i, float8 eta, float8 k) {
  const float8 c2 = cos_i * cos_i, s2 = 1.0f - c2, s4 = s2 * s2;
  const float8 t1 = eta * eta - k * k - s2;
  const float8 a2b2 = sqrt(t1 * t1 + 4.0f * k * k * eta * eta);
  const float8 a = sqrt(fmax(0.5f * (a2b2 + t1), 0.0f));
  const float8 term1 = a2b2 + c2, term2 = 2.0f * cos_i * a;
  const float8 rs = (term1 - term2) / (term1 + term2);
  const float8 term3 = a2b2 * c2 + s4, term4 = term2 * s2;
  const float8 rp = rs * (term3 - term4) / (term3 + term4);
  return 0.5f * (rs + rp);
}

/* bsdf_eval_local's roughconductor: f and *pdf for local o and i. */
inline Vec8 conductor8_eval(const Conductor8* c, Vec8 o, Vec8 i, float8* pdf) {
  const int8 on = (o.z > 0.0f) & (i.z > 0.0f);
  const Vec8 h = vec8_normalize(vec8_add(o, i));
  const float8 oh = vec8_dot(o, h);
  float8 d, g_o, g_i, pm;
  mf8_terms(h, o, i, c->au, c->av, c->beckmann, &d, &g_o, &g_i, &pm);
  const float8 g = g_o * g_i;
  *pdf = select((float8)(0.0f), pm / (4.0f * oh), on);
  const Vec8 fr = vec8(fresnel_conductor8(oh, c->eta.x, c->k.x), fresnel_conductor8(oh, c->eta.y, c->k.y),
                       fresnel_conductor8(oh, c->eta.z, c->k.z));
  const Vec8 f = vec8_scale(vec8_mul(c->spec, fr), d * g / (4.0f * o.z * i.z));
  return vec8_select(vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f)), f, on);
}

/* --- smooth dielectrics and conductors in vectors ---------------------------------
 * bsdf.cl's dielectric and conductor (bsdf_sample_general: a mirror or
 * refracted direction, its weight; delta lobes, which bsdf_eval_local gives
 * nothing). */

inline bool lanes_delta(const Material* m) {
  return m->type == PSF_MATERIAL_DIELECTRIC || m->type == PSF_MATERIAL_CONDUCTOR ||
         m->type == PSF_MATERIAL_THIN_DIELECTRIC;
}

/* The lanes' smooth dielectrics, conductors and thin dielectrics: Material's
 * specular, transmittance, eta and k, and which are conductors and which thin. */
typedef struct {
  Vec8 spec, trans, eta, k;
  int8 conductor, thin;
} Delta8;

inline void delta8_set(Delta8* d, uint l, const Material* m) {
  vec8_set(&d->spec, l, m->specular.xyz);
  vec8_set(&d->trans, l, m->transmittance.xyz);
  vec8_set(&d->eta, l, m->eta.xyz);
  vec8_set(&d->k, l, m->k.xyz);
  LANE_I(d->conductor, l) = m->type == PSF_MATERIAL_CONDUCTOR ? -1 : 0;
  LANE_I(d->thin, l) = m->type == PSF_MATERIAL_THIN_DIELECTRIC ? -1 : 0;
}

/* fresnel_dielectric for either side: F, the refracted cosine and eta_ti. */
inline float8 fresnel_dielectric_t8(float8 cos_i, float8 eta, float8* cos_t, float8* eta_ti) {
  const int8 outside = cos_i >= 0.0f;
  const float8 n = select(1.0f / eta, eta, outside), ci = fabs(cos_i);
  const float8 ct2 = 1.0f - (1.0f - ci * ci) / (n * n);
  *eta_ti = 1.0f / n;
  const float8 ct = sqrt(fmax(ct2, 0.0f));
  *cos_t = select(select(ct, -ct, outside), (float8)(0.0f), ct2 <= 0.0f);
  const float8 rs = (ci - n * ct) / (ci + n * ct), rp = (n * ci - ct) / (n * ci + ct);
  return select(0.5f * (rs * rs + rp * rp), (float8)(1.0f), ct2 <= 0.0f);
}

/* bsdf_sample_general's dielectric and conductor for local o and the lobe
 * choice uc: the local direction, *weight, and *fails where a conductor is
 * seen from behind (bsdf_fail). */
inline Vec8 delta8_sample(const Delta8* d, Vec8 o, float8 uc, Vec8* weight, int8* fails) {
  float8 cos_t, eta_ti;
  const float8 fr = fresnel_dielectric_t8(o.z, d->eta.x, &cos_t, &eta_ti);
  /* A thin sheet: the reflectance of its two interfaces and their
   * interreflections, and transmission straight through. */
  float8 r = fresnel_dielectric8(fabs(o.z), d->eta.x);
  r = select(r, r + (1.0f - r) * (1.0f - r) * r / (1.0f - r * r), r < 1.0f);
  const int8 reflect = d->conductor | select(uc < fr, uc < r, d->thin);
  const Vec8 mirror = vec8(-o.x, -o.y, o.z);
  const Vec8 refracted = vec8_select(vec8(-eta_ti * o.x, -eta_ti * o.y, cos_t), vec8_neg(o), d->thin);
  const Vec8 fc = vec8(fresnel_conductor8(o.z, d->eta.x, d->k.x), fresnel_conductor8(o.z, d->eta.y, d->k.y),
                       fresnel_conductor8(o.z, d->eta.z, d->k.z));
  const Vec8 trans = vec8_select(vec8_scale(d->trans, eta_ti * eta_ti), d->trans, d->thin);
  *weight = vec8_select(vec8_select(trans, d->spec, reflect), vec8_mul(d->spec, fc), d->conductor);
  *fails = d->conductor & (o.z <= 0.0f);
  return vec8_select(refracted, mirror, reflect);
}

/* --- rough dielectrics in vectors ---------------------------------------------
 * bsdf.cl's roughdielectric (bsdf_eval_local, bsdf_sample_general): a GGX or
 * Beckmann microfacet normal, reflected or refracted by its Fresnel term,
 * from either side. */

inline bool lanes_rough_dielectric(const Material* m) { return m->type == PSF_MATERIAL_ROUGH_DIELECTRIC; }

/* The lanes' rough dielectrics: alpha_u, alpha_v, eta.x, specular,
 * transmittance, Beckmann's or GGX. */
typedef struct {
  float8 au, av, eta;
  Vec8 spec, trans;
  int8 beckmann;
} RoughDielectric8;

inline void rough_dielectric8_set(RoughDielectric8* p, uint l, const Material* m) {
  LANE_F(p->au, l) = m->alpha_u;
  LANE_F(p->av, l) = m->alpha_v;
  LANE_F(p->eta, l) = m->eta.x;
  vec8_set(&p->spec, l, m->specular.xyz);
  vec8_set(&p->trans, l, m->transmittance.xyz);
  LANE_I(p->beckmann, l) = (m->flags & PSF_MATFLAG_BECKMANN) ? -1 : 0;
}

/* bsdf_eval_local's roughdielectric: f and *pdf for local o and i. */
inline Vec8 rough_dielectric8_eval(const RoughDielectric8* p, Vec8 o, Vec8 i, float8* pdf) {
  const Vec8 zero = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
  const float8 co = o.z, ci = i.z;
  const int8 reflect = co * ci > 0.0f;
  const float8 eta = select(1.0f / p->eta, p->eta, co > 0.0f); /* IOR of i's side over o's side */
  Vec8 h = vec8_normalize(vec8_add(o, vec8_scale(i, select(eta, (float8)(1.0f), reflect))));
  h = vec8_select(h, vec8_neg(h), h.z < 0.0f);
  const float8 oh = vec8_dot(o, h), ih = vec8_dot(i, h);
  const int8 none = (co == 0.0f) | (ci == 0.0f) | (oh * co <= 0.0f) | (ih * ci <= 0.0f);
  float8 cos_t, eta_ti;
  const float8 fr = fresnel_dielectric_t8(oh, p->eta, &cos_t, &eta_ti);
  const Vec8 of = vec8_select(vec8_neg(o), o, co > 0.0f); /* o on the side of the sampled normals */
  float8 d, g_o, g_i, pm;
  mf8_terms(h, of, i, p->au, p->av, p->beckmann, &d, &g_o, &g_i, &pm);
  const float8 g = g_o * g_i;
  const float8 denom = oh + eta * ih;
  const float8 jac = eta * eta * fabs(ih) / (denom * denom); /* |d h / d i| (Walter et al. Eq. 17) */
  const float8 pdf_r = pm * fr / (4.0f * fabs(ih)), pdf_t = pm * (1.0f - fr) * jac;
  *pdf = select(select(pdf_t, pdf_r, reflect), (float8)(0.0f), none);
  const Vec8 f_r = vec8_scale(p->spec, fr * d * g / (4.0f * fabs(co * ci)));
  const Vec8 f_t = vec8_scale(p->trans, fabs((1.0f - fr) * d * g * oh * ih / (co * ci * denom * denom)));
  return vec8_select(vec8_select(f_t, f_r, reflect), zero, none);
}

/* --- smooth plastic in vectors ------------------------------------------------
 * bsdf.cl's plastic (bsdf_eval_local, bsdf_sample_general): the coat's mirror
 * direction (a delta lobe) with plastic_prob_specular's probability, else the
 * cosine direction for the base seen through the coat. */

inline bool lanes_smooth_plastic(const Material* m) {
  return m->type == PSF_MATERIAL_PLASTIC;
}

/* The lanes' smooth plastics: eta.x, eta.y, albedo.w, specular, plastic_base. */
typedef struct {
  float8 eta, scale, weight;
  Vec8 spec, base;
} SmoothPlastic8;

inline void smooth_plastic8_set(SmoothPlastic8* p, uint l, const Material* m) {
  LANE_F(p->eta, l) = m->eta.x;
  LANE_F(p->scale, l) = m->eta.y;
  LANE_F(p->weight, l) = m->albedo.w;
  vec8_set(&p->spec, l, m->specular.xyz);
  vec8_set(&p->base, l, plastic_base(*m));
}

/* plastic_prob_specular for the coat's reflectance r. */
inline float8 smooth_plastic8_prob_specular(const SmoothPlastic8* p, float8 r) {
  const float8 ps = r * p->weight, pd = (1.0f - r) * (1.0f - p->weight);
  return select((float8)(0.0f), ps / (ps + pd), ps + pd > 0.0f);
}

/* bsdf_eval_local's plastic: the base's f and *pdf for local o and i. */
inline Vec8 smooth_plastic8_eval(const SmoothPlastic8* p, Vec8 o, Vec8 i, float8* pdf) {
  const int8 on = (o.z > 0.0f) & (i.z > 0.0f);
  const float8 fo = fresnel_dielectric8(o.z, p->eta), fi = fresnel_dielectric8(i.z, p->eta);
  *pdf = select((float8)(0.0f), (1.0f - smooth_plastic8_prob_specular(p, fo)) * i.z * PSF_INV_PI, on);
  return vec8_select(vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f)),
                     vec8_scale(p->base, p->scale * (1.0f - fo) * (1.0f - fi) * PSF_INV_PI), on);
}

/* --- pplastic in vectors -----------------------------------------------------
 * bsdf.cl's pplastic (Mitsuba 3's, rendered unpolarized): GGX or Beckmann,
 * isotropic or not. */

inline bool lanes_pplastic(const Material* m) {
  return m->type == PSF_MATERIAL_PPLASTIC;
}

/* The lanes' pplastics: alpha_u, alpha_v, eta.x, albedo.w (the specular
 * sampling weight), specular, albedo, Beckmann's or GGX. */
typedef struct {
  float8 au, av, eta, ps;
  Vec8 spec, base;
  int8 beckmann;
} PPlastic8;

inline void pplastic8_set(PPlastic8* p, uint l, const Material* m) {
  LANE_F(p->au, l) = m->alpha_u;
  LANE_F(p->av, l) = m->alpha_v;
  LANE_F(p->eta, l) = m->eta.x;
  LANE_F(p->ps, l) = m->albedo.w;
  vec8_set(&p->spec, l, m->specular.xyz);
  vec8_set(&p->base, l, m->albedo.xyz);
  LANE_I(p->beckmann, l) = (m->flags & PSF_MATFLAG_BECKMANN) ? -1 : 0;
}

/* bsdf_eval_local's pplastic: f and *pdf for local o and i. */
inline Vec8 pplastic8_eval(const PPlastic8* p, Vec8 o, Vec8 i, float8* pdf) {
  const int8 on = (o.z > 0.0f) & (i.z > 0.0f);
  const Vec8 h = vec8_normalize(vec8_add(o, i));
  const float8 oh = vec8_dot(o, h);
  const float8 fr = fresnel_dielectric8(oh, p->eta);
  const float8 fo = fresnel_dielectric8(o.z, p->eta), fi = fresnel_dielectric8(i.z, p->eta);
  float8 d, g_o, g_i, pm;
  mf8_terms(h, o, i, p->au, p->av, p->beckmann, &d, &g_o, &g_i, &pm);
  const float8 g = g_o * g_i;
  pm = select((float8)(0.0f), pm / (4.0f * oh), (oh > 0.0f) & (vec8_dot(i, h) > 0.0f));
  *pdf = select((float8)(0.0f), p->ps * pm + (1.0f - p->ps) * i.z * PSF_INV_PI, on);
  const Vec8 f = vec8_add(vec8_scale(p->spec, fr * d * g / (4.0f * o.z * i.z)),
                          vec8_scale(p->base, (1.0f - fo) * (1.0f - fi) * PSF_INV_PI));
  return vec8_select(vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f)), f, on);
}

/* --- principled in vectors ---------------------------------------------------
 * bsdf.cl's principled (principled_eval, principled_sample): Burley's diffuse
 * with retro-reflection, flatness and sheen, the anisotropic GGX reflection
 * with its tints and metallic part, the clearcoat, and where spec_trans > 0
 * the GGX transmission, from either side; the same operations in float8. */

/* Whether the lanes shade material m as a Principled8. */
inline bool lanes_principled(const Material* m) { return m->type == PSF_MATERIAL_PRINCIPLED; }

/* The lanes' principled materials (Material's fields as host/scene/mitsuba.cpp
 * fills them). */
typedef struct {
  float8 au, av, eta, roughness;          /* alpha_u, alpha_v, eta.x, eta.z */
  float8 metallic, spec_trans;           /* specular.x, .y */
  float8 spec_tint, sheen;                /* specular.z, .w */
  float8 sheen_tint, flatness, clearcoat; /* transmittance.x, .y, .z */
  float8 cc_alpha;                        /* principled_clearcoat_alpha */
  float8 p_diffuse, p_clearcoat, p_spec;  /* principled_lobes from the front */
  Vec8 base;                              /* albedo */
} Principled8;

inline void principled8_set(Principled8* p, uint l, const Material* m) {
  LANE_F(p->au, l) = m->alpha_u;
  LANE_F(p->av, l) = m->alpha_v;
  LANE_F(p->eta, l) = m->eta.x;
  LANE_F(p->roughness, l) = m->eta.z;
  LANE_F(p->metallic, l) = m->specular.x;
  LANE_F(p->spec_trans, l) = m->specular.y;
  LANE_F(p->spec_tint, l) = m->specular.z;
  LANE_F(p->sheen, l) = m->specular.w;
  LANE_F(p->sheen_tint, l) = m->transmittance.x;
  LANE_F(p->flatness, l) = m->transmittance.y;
  LANE_F(p->clearcoat, l) = m->transmittance.z;
  LANE_F(p->cc_alpha, l) = principled_clearcoat_alpha(*m);
  const float3 lobes = principled_lobes(*m, true);
  LANE_F(p->p_diffuse, l) = lobes.x;
  LANE_F(p->p_clearcoat, l) = lobes.y;
  LANE_F(p->p_spec, l) = lobes.z;
  vec8_set(&p->base, l, m->albedo.xyz);
}

inline float8 principled_schlick_weight8(float8 c) {
  const float8 m = clamp(1.0f - c, 0.0f, 1.0f), m2 = m * m;
  return m2 * m2 * m;
}
/* principled_schlick for cos_i >= 0. */
inline float8 principled_schlick8(float8 cos_i, float8 eta) {
  const float8 ct2 = 1.0f - (1.0f - cos_i * cos_i) / (eta * eta);
  return principled_schlick_weight8(select(sqrt(fmax(ct2, 0.0f)), fabs(cos_i), eta > 1.0f));
}
/* principled_fresnel for either side: F (0 where the indices match), the
 * refracted cosine and eta_ti. */
inline float8 principled_fresnel8(float8 cos_i, float8 eta, float8* cos_t, float8* eta_ti) {
  const int8 matched = eta == 1.0f;
  const float8 f = fresnel_dielectric_t8(cos_i, eta, cos_t, eta_ti);
  *eta_ti = select(*eta_ti, (float8)(1.0f), matched);
  *cos_t = select(*cos_t, -cos_i, matched);
  return select(f, (float8)(0.0f), matched);
}
inline Vec8 principled_tint8(Vec8 base) {
  const float8 lum = 0.212671f * base.x + 0.715160f * base.y + 0.072169f * base.z;
  return vec8_select(vec8((float8)(1.0f), (float8)(1.0f), (float8)(1.0f)), vec8_div(base, lum), lum > 0.0f);
}
inline float8 principled_gtr1_8(float8 cos_m, float8 a) {
  const float8 a2 = a * a;
  const float8 r = (a2 - 1.0f) / (PSF_PI * log(a2) * (1.0f + (a2 - 1.0f) * cos_m * cos_m));
  return select((float8)(0.0f), r, r * cos_m > 1e-20f);
}
inline float8 principled_ggx_g1_8(Vec8 v, Vec8 m, float8 a) {
  const float8 c2 = v.z * v.z, t2 = (1.0f - c2) / c2;
  const float8 g = select(2.0f / (1.0f + sqrt(1.0f + a * a * t2)), (float8)(1.0f), v.z == 1.0f);
  return select(g, (float8)(0.0f), vec8_dot(v, m) * v.z <= 0.0f);
}

/* principled_diffuse for the lanes of `lanes`, with their roughness and
 * flatness. */
inline float8 principled_diffuse8(float8 roughness, float8 flatness, int8 lanes, float8 co, float8 ci, float8 cos_d) {
  const float8 fo = principled_schlick_weight8(ci), fi = principled_schlick_weight8(co);
  const float8 rr = 2.0f * roughness * cos_d * cos_d;
  float8 dif = (1.0f - 0.5f * fi) * (1.0f - 0.5f * fo) + rr * (fo + fi + fo * fi * (rr - 1.0f));
  const int8 flat = flatness > 0.0f;
  if (any(flat & lanes)) {
    const float8 fss = mix((float8)(1.0f), 0.5f * rr, fo) * mix((float8)(1.0f), 0.5f * rr, fi);
    const float8 ss = 1.25f * (fss * (1.0f / (co + ci) - 0.5f) + 0.5f);
    dif = select(dif, mix(dif, ss, flatness), flat);
  }
  return dif;
}
/* The sheen's colour: white mixed towards principled_tint by sheen_tint. */
inline Vec8 principled_sheen_tint8(Vec8 base, float8 sheen_tint) {
  const Vec8 t = principled_tint8(base);
  return vec8(mix((float8)(1.0f), t.x, sheen_tint), mix((float8)(1.0f), t.y, sheen_tint),
              mix((float8)(1.0f), t.z, sheen_tint));
}

/* The lobe probabilities of principled_lobes for the side o lies on (front:
 * the lanes' diffuse, clearcoat and specular; from inside only the specular,
 * where anything transmits). */
inline void principled8_lobes(const Principled8* p, int8 front, float8* diffuse, float8* coat, float8* spec) {
  const float8 inside = select((float8)(0.0f), (float8)(1.0f), (1.0f - p->metallic) * p->spec_trans > 0.0f);
  *diffuse = select((float8)(0.0f), p->p_diffuse, front);
  *coat = select((float8)(0.0f), p->p_clearcoat, front);
  *spec = select(inside, p->p_spec, front);
}

/* principled_eval for local o and i: f and *pdf. */
inline Vec8 principled8_eval(const Principled8* p, Vec8 o, Vec8 i, float8* pdf) {
  const Vec8 zero = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
  const float8 co = o.z, ci = i.z;
  const int8 reflect = co * ci > 0.0f, front = co > 0.0f;
  const float8 one_m = 1.0f - p->metallic;
  const float8 brdf = one_m * (1.0f - p->spec_trans), btdf = one_m * p->spec_trans;
  const float8 eta_p = select(1.0f / p->eta, p->eta, front); /* i's side over o's, for refraction */
  Vec8 h = vec8_normalize(vec8_add(o, vec8_scale(i, select(eta_p, (float8)(1.0f), reflect))));
  h = vec8_select(h, vec8_neg(h), h.z < 0.0f);
  const float8 oh = vec8_dot(o, h), ih = vec8_dot(i, h);
  const float8 side = select((float8)(-1.0f), (float8)(1.0f), front);
  const int8 micro_r = reflect & (oh * side > 0.0f) & (ih * side > 0.0f);
  const int8 micro_t = ~reflect & (oh * side > 0.0f) & (ih * side < 0.0f);
  float8 cos_t, eta_ti;
  const float8 fd = principled_fresnel8(oh, p->eta, &cos_t, &eta_ti);
  const float8 d = ggx_D8(h, p->au, p->av);
  const float8 g_o = ggx_G1_8(o, h, p->au, p->av), g = g_o * ggx_G1_8(i, h, p->au, p->av);
  const float8 pm = d * g_o * fabs(oh) / fabs(co); /* mf_pdf of o turned to the front */
  float8 l_diffuse, l_coat, l_spec;
  principled8_lobes(p, front, &l_diffuse, &l_coat, &l_spec);
  const float8 w = select((float8)(0.0f), principled_schlick8(oh, p->eta), front & micro_r);
  const float8 prefl = select(fd, 1.0f - btdf * (1.0f - fd), front);
  float8 pdf_r = select((float8)(0.0f), l_spec * prefl * pm / (4.0f * fabs(ih)), micro_r);
  Vec8 f = zero;
  {
    const float8 r = (p->eta - 1.0f) / (p->eta + 1.0f);
    const Vec8 r0 = vec8_scale(principled_tint8(p->base), r * r);
    const Vec8 one = vec8((float8)(1.0f), (float8)(1.0f), (float8)(1.0f));
    const Vec8 metal = vec8_scale(vec8_add(p->base, vec8_scale(vec8_sub(one, p->base), w)), p->metallic);
    const Vec8 tinted = vec8_scale(vec8_add(r0, vec8_scale(vec8_sub(one, r0), w)), one_m * p->spec_tint);
    const float8 plain = one_m * (1.0f - p->spec_tint) * fd;
    const Vec8 F_front = vec8_add(vec8_add(vec8((float8)(plain), plain, plain), metal), tinted);
    const float8 bf = btdf * fd;
    const Vec8 F = vec8_select(vec8(bf, bf, bf), F_front, front);
    f = vec8_select(f, vec8_scale(F, d * g / (4.0f * fabs(co * ci))), micro_r & (fd > 0.0f));
  }
  const int8 trans = micro_t & (btdf > 0.0f);
  if (any(trans)) { /* main specular transmission, radiance scaled by 1 / eta_p^2 */
    const float8 denom = oh + eta_p * ih;
    const float8 ft = btdf * fabs((1.0f - fd) * d * g * oh * ih / (co * ci * denom * denom));
    const Vec8 tint = vec8(sqrt(p->base.x), sqrt(p->base.y), sqrt(p->base.z));
    f = vec8_select(f, vec8_add(f, vec8_scale(tint, ft)), trans & (fd < 1.0f));
    const float8 ptrans = select(1.0f - fd, btdf * (1.0f - fd), front);
    pdf_r = select(pdf_r, pdf_r + l_spec * ptrans * pm * eta_p * eta_p * fabs(ih) / (denom * denom), trans);
  }
  const int8 coat = front & micro_r & (p->clearcoat > 0.0f);
  if (any(coat)) {
    const float8 dcc = principled_gtr1_8(h.z, p->cc_alpha);
    const float8 fcc = 0.04f + 0.96f * w;
    const float8 gcc = principled_ggx_g1_8(o, h, (float8)(0.25f)) * principled_ggx_g1_8(i, h, (float8)(0.25f));
    const float8 c = 0.25f * p->clearcoat * fcc * dcc * gcc;
    f = vec8_select(f, vec8_add(f, vec8(c, c, c)), coat);
    pdf_r = select(pdf_r, pdf_r + l_coat * dcc * h.z / (4.0f * fabs(ih)), coat);
  }
  const int8 diffuse = front & reflect & (brdf > 0.0f);
  if (any(diffuse)) {
    const float8 cos_d = vec8_dot(h, i);
    const float8 dif = principled_diffuse8(p->roughness, p->flatness, diffuse, co, ci, cos_d);
    Vec8 fd_ = vec8_add(f, vec8_scale(p->base, brdf * PSF_INV_PI * dif));
    const int8 sheen = diffuse & (p->sheen > 0.0f);
    if (any(sheen)) {
      fd_ = vec8_select(fd_,
                        vec8_add(fd_, vec8_scale(principled_sheen_tint8(p->base, p->sheen_tint),
                                                 p->sheen * (1.0f - p->metallic) * principled_schlick_weight8(cos_d))),
                        sheen);
    }
    f = vec8_select(f, fd_, diffuse);
    pdf_r = select(pdf_r, pdf_r + l_diffuse * ci * PSF_INV_PI, diffuse);
  }
  const int8 none = (co == 0.0f) | (ci == 0.0f);
  *pdf = select(pdf_r, (float8)(0.0f), none);
  return vec8_select(f, zero, none);
}

/* principled_sample's local direction for o in the lanes of `lanes` (the
 * lobe by uc: the cosine direction wl, a clearcoat normal's mirror direction,
 * or the GGX visible normal's reflection or refraction, for o turned to the
 * front); *fails where it returns bsdf_fail. */
inline Vec8 principled8_sample(const Principled8* p, int8 lanes, Vec8 o, Vec8 wl, float8 u1, float8 u2, float8 uc,
                               int8* fails) {
  const int8 front = o.z > 0.0f;
  float8 l_diffuse, l_coat, l_spec;
  principled8_lobes(p, front, &l_diffuse, &l_coat, &l_spec);
  const float8 lxy = l_diffuse + l_coat;
  const int8 diffuse = uc < l_diffuse, coat = lanes & ~diffuse & (uc < lxy), spec = lanes & ~diffuse & ~coat;
  Vec8 i = wl;
  int8 bad = o.z == 0.0f;
  if (any(coat)) { /* a GTR1 normal: cos^2 = (1 - a^2^(1 - u2)) / (1 - a^2) */
    const float8 a2 = p->cc_alpha * p->cc_alpha;
    const float8 c2 = (1.0f - pow(a2, 1.0f - u2)) / (1.0f - a2);
    const float8 st = sqrt(fmax(0.0f, 1.0f - c2));
    float8 cp;
    const float8 sp = psf_sincos8(2.0f * PSF_PI * u1, &cp);
    const Vec8 h = vec8(st * cp, st * sp, sqrt(fmax(0.0f, c2)));
    const Vec8 ic = vec8_sub(vec8_scale(h, 2.0f * vec8_dot(o, h)), o);
    i = vec8_select(i, ic, coat);
    bad |= coat & (ic.z <= 0.0f);
  }
  if (any(spec)) {
    const Vec8 h = ggx_sample8(vec8_select(vec8_neg(o), o, front), p->au, p->av, u1, u2);
    const float8 oh = vec8_dot(o, h);
    float8 cos_t, eta_ti;
    const float8 fd = principled_fresnel8(oh, p->eta, &cos_t, &eta_ti);
    const float8 btdf = (1.0f - p->metallic) * p->spec_trans;
    const float8 prefl = select(fd, 1.0f - btdf * (1.0f - fd), front); /* reflection, else refraction */
    const int8 reflect = uc < lxy + l_spec * prefl;
    const Vec8 ir = vec8_sub(vec8_scale(h, 2.0f * oh), o);
    const Vec8 it = vec8_sub(vec8_scale(h, oh * eta_ti + cos_t), vec8_scale(o, eta_ti));
    const Vec8 is = vec8_select(it, ir, reflect);
    i = vec8_select(i, is, spec);
    bad |= spec & (~(l_spec > 0.0f) | select(is.z * o.z >= 0.0f, is.z * o.z <= 0.0f, reflect));
  }
  *fails = bad;
  return i;
}

/* --- principledthin in vectors -----------------------------------------------
 * bsdf.cl's principledthin (thin_eval, thin_sample): the sheet seen from the
 * front (o and i turned together), GGX reflection with its tint, GGX
 * transmission as reflection carried through the sheet, Burley's diffuse with
 * flatness and sheen, and the diffuse transmission. */

inline bool lanes_thin(const Material* m) { return m->type == PSF_MATERIAL_PRINCIPLED_THIN; }

/* The lanes' principledthin materials (psf_shared.h's layout). */
typedef struct {
  float8 au, av, atu, atv, eta, roughness;  /* alpha_u, alpha_v, transmittance.z, .w, eta.x, eta.z */
  float8 diff_trans, spec_trans, spec_tint; /* specular.x, .y, .z */
  float8 sheen, sheen_tint, flatness;       /* specular.w, transmittance.x, .y */
  float8 l_sr, l_st, l_dr, l_dt;            /* thin_lobes */
  Vec8 base;                                /* albedo */
} Thin8;

inline void thin8_set(Thin8* p, uint l, const Material* m) {
  LANE_F(p->au, l) = m->alpha_u;
  LANE_F(p->av, l) = m->alpha_v;
  LANE_F(p->atu, l) = m->transmittance.z;
  LANE_F(p->atv, l) = m->transmittance.w;
  LANE_F(p->eta, l) = m->eta.x;
  LANE_F(p->roughness, l) = m->eta.z;
  LANE_F(p->diff_trans, l) = m->specular.x;
  LANE_F(p->spec_trans, l) = m->specular.y;
  LANE_F(p->spec_tint, l) = m->specular.z;
  LANE_F(p->sheen, l) = m->specular.w;
  LANE_F(p->sheen_tint, l) = m->transmittance.x;
  LANE_F(p->flatness, l) = m->transmittance.y;
  const float4 lobes = thin_lobes(*m);
  LANE_F(p->l_sr, l) = lobes.x;
  LANE_F(p->l_st, l) = lobes.y;
  LANE_F(p->l_dr, l) = lobes.z;
  LANE_F(p->l_dt, l) = lobes.w;
  vec8_set(&p->base, l, m->albedo.xyz);
}

/* thin_eval for local o and i: f and *pdf. */
inline Vec8 thin8_eval(const Thin8* p, Vec8 o, Vec8 i, float8* pdf) {
  const Vec8 zero = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
  const int8 none = (o.z == 0.0f) | (i.z == 0.0f), back = o.z < 0.0f;
  o = vec8_select(o, vec8_neg(o), back);
  i = vec8_select(i, vec8_neg(i), back);
  const float8 co = o.z, ci = fabs(i.z);
  const int8 reflect = i.z > 0.0f;
  const Vec8 ir = vec8(i.x, i.y, ci);
  const Vec8 h = vec8_normalize(vec8_add(o, ir));
  const float8 oh = vec8_dot(o, h), ih = vec8_dot(i, h);
  const int8 micro = (oh > 0.0f) & select(ih < 0.0f, ih > 0.0f, reflect);
  Vec8 f = zero;
  float8 pdf_ = (float8)(0.0f);
  const int8 spec = (p->spec_trans > 0.0f) & micro;
  if (any(spec)) {
    float8 cos_t, eta_ti;
    const float8 fd = principled_fresnel8(oh, p->eta, &cos_t, &eta_ti);
    const float8 jacobian = 1.0f / (4.0f * fabs(vec8_dot(ir, h))); /* dh / di */
    const float8 au = select(p->atu, p->au, reflect), av = select(p->atv, p->av, reflect);
    const float8 d = ggx_D8(h, au, av);
    const float8 g_o = ggx_G1_8(o, h, au, av), g = g_o * ggx_G1_8(i, h, au, av);
    const float8 pm = d * g_o * fabs(oh) / o.z;
    Vec8 F = vec8(fd, fd, fd);
    const int8 tint = reflect & (p->spec_tint > 0.0f);
    if (any(tint)) {
      const float8 r = (p->eta - 1.0f) / (p->eta + 1.0f), w = principled_schlick8(oh, p->eta);
      const Vec8 r0 = vec8_scale(principled_tint8(p->base), r * r);
      const Vec8 one = vec8((float8)(1.0f), (float8)(1.0f), (float8)(1.0f));
      const Vec8 ft = vec8_add(r0, vec8_scale(vec8_sub(one, r0), w));
      F = vec8_select(F, vec8(mix(F.x, ft.x, p->spec_tint), mix(F.y, ft.y, p->spec_tint), mix(F.z, ft.z, p->spec_tint)),
                      tint);
    }
    const float8 s = p->spec_trans * d * g / (4.0f * co * ci);
    f = vec8_select(f, vec8_select(vec8_scale(p->base, s * (1.0f - fd)), vec8_scale(F, s), reflect), spec);
    pdf_ = select(pdf_, select(p->l_st, p->l_sr, reflect) * pm * jacobian, spec);
  }
  const int8 diffuse = reflect & (p->spec_trans < 1.0f) & (p->diff_trans < 1.0f);
  if (any(diffuse)) {
    const float8 cos_d = vec8_dot(h, i);
    const float8 dif = principled_diffuse8(p->roughness, p->flatness, diffuse, co, ci, cos_d);
    const float8 w = (1.0f - p->spec_trans) * (1.0f - p->diff_trans);
    Vec8 fd_ = vec8_add(f, vec8_scale(p->base, w * PSF_INV_PI * dif));
    const int8 sheen = diffuse & (p->sheen > 0.0f);
    if (any(sheen))
      fd_ = vec8_select(fd_,
                        vec8_add(fd_, vec8_scale(principled_sheen_tint8(p->base, p->sheen_tint),
                                                 p->sheen * w * principled_schlick_weight8(fabs(cos_d)))),
                        sheen);
    f = vec8_select(f, fd_, diffuse);
  }
  const int8 diffuse_t = ~reflect & (p->spec_trans < 1.0f) & (p->diff_trans > 0.0f);
  f = vec8_select(f, vec8_add(f, vec8_scale(p->base, (1.0f - p->spec_trans) * p->diff_trans * PSF_INV_PI)), diffuse_t);
  pdf_ += select(p->l_dt, p->l_dr, reflect) * ci * PSF_INV_PI;
  *pdf = select(pdf_, (float8)(0.0f), none);
  return vec8_select(f, zero, none);
}

/* thin_sample's local direction for o (the lobe by uc: a GGX visible normal's
 * mirror direction, carried through the sheet for transmission, or the
 * cosine direction wl, through the sheet for the diffuse transmission), for
 * o turned to the front and turned back with it; *fails where it returns
 * bsdf_fail. */
inline Vec8 thin8_sample(const Thin8* p, Vec8 o, Vec8 wl, float8 u1, float8 u2, float8 uc, int8* fails) {
  const float8 side = select((float8)(-1.0f), (float8)(1.0f), o.z > 0.0f);
  const Vec8 of = vec8_scale(o, side);
  const float8 lxy = p->l_sr + p->l_st;
  const int8 spec = uc < lxy, reflect = uc < p->l_sr;
  const Vec8 h = ggx_sample8(of, select(p->atu, p->au, reflect), select(p->atv, p->av, reflect), u1, u2);
  const float8 oh = vec8_dot(of, h);
  Vec8 is = vec8_sub(vec8_scale(h, 2.0f * oh), of);
  is.z = select(-is.z, is.z, reflect);
  const float8 ih = vec8_dot(is, h);
  *fails = (o.z == 0.0f) |
           (spec & ((oh <= 0.0f) | select((is.z >= 0.0f) | (ih >= 0.0f), (is.z <= 0.0f) | (ih <= 0.0f), reflect)));
  Vec8 id = wl;
  id.z = select(wl.z, -wl.z, uc >= lxy + p->l_dr);
  return vec8_scale(vec8_select(id, is, spec), side);
}

/* --- the lanes' vector BSDFs together -------------------------------------------- */

/* Which kind of vector BSDF each lane's material is (none: bsdf.cl's scalar
 * functions, lane by lane), and each kind's parameters. Zero where no lane
 * fills them: their functions branch on any() of lanes they leave unused. */
typedef struct {
  int8 diffuse, plastic, conductor, principled, pplastic, delta, smooth_plastic, rough_dielectric, thin;
  Plastic8 pl;
  Conductor8 co;
  Principled8 pr8;
  PPlastic8 pp;
  Delta8 dl;
  SmoothPlastic8 spl;
  RoughDielectric8 rd;
  Thin8 th;
  __global const half* plastic_table[PSF_LANES]; /* a rough plastic's coat transmittance */
} LanesBsdfs;

inline int8 lanes_bsdfs_mask(const LanesBsdfs* b) {
  return b->diffuse | b->plastic | b->conductor | b->principled | b->pplastic | b->delta | b->smooth_plastic |
         b->rough_dielectric | b->thin;
}

/* Lane l joins a kind (its MASK): the kind's parameters zeroed as its first
 * lane joins, so that the lanes it leaves unused hold zeros, not what the
 * stack held (its functions branch on any() of such lanes). */
#define LANES_KIND_TAKE(MASK, PARAMS, TYPE, L) \
  do {                                         \
    if (!any(MASK)) {                          \
      const TYPE zero_ = {0};                  \
      PARAMS = zero_;                          \
    }                                          \
    LANE_I(MASK, L) = -1;                      \
  } while (0)

/* Lane l's kind and parameters for its material m (as lane_surface left it);
 * cos_o: wo's cosine to the shading normal (a rough plastic's coat
 * transmittance towards wo). */
inline void lanes_bsdfs_set(LanesBsdfs* b, uint l, const Material* m, __global const TextureInfo* textures,
                            __global const half* texels, float cos_o) {
  if (m->type == PSF_MATERIAL_DIFFUSE) { /* a blend's, a bump map's, vertex colours': the vectors' diffuse BSDF */
    LANE_I(b->diffuse, l) = -1;
  } else if (lanes_rough_dielectric(m)) {
    LANES_KIND_TAKE(b->rough_dielectric, b->rd, RoughDielectric8, l);
    rough_dielectric8_set(&b->rd, l, m);
  } else if (lanes_smooth_plastic(m)) {
    LANES_KIND_TAKE(b->smooth_plastic, b->spl, SmoothPlastic8, l);
    smooth_plastic8_set(&b->spl, l, m);
  } else if (lanes_delta(m)) {
    LANES_KIND_TAKE(b->delta, b->dl, Delta8, l);
    delta8_set(&b->dl, l, m);
  } else if (lanes_pplastic(m)) {
    LANES_KIND_TAKE(b->pplastic, b->pp, PPlastic8, l);
    pplastic8_set(&b->pp, l, m);
  } else if (lanes_principled(m)) {
    LANES_KIND_TAKE(b->principled, b->pr8, Principled8, l);
    principled8_set(&b->pr8, l, m);
  } else if (lanes_thin(m)) {
    LANES_KIND_TAKE(b->thin, b->th, Thin8, l);
    thin8_set(&b->th, l, m);
  } else if (lanes_conductor(m)) {
    LANES_KIND_TAKE(b->conductor, b->co, Conductor8, l);
    conductor8_set(&b->co, l, m);
  } else if (lanes_plastic(m)) {
    Plastic8* pl = &b->pl;
    LANES_KIND_TAKE(b->plastic, b->pl, Plastic8, l);
    b->plastic_table[l] = surface_table(*m, textures, texels);
    LANE_F(pl->au, l) = m->alpha_u;
    LANE_F(pl->av, l) = m->alpha_v;
    LANE_I(pl->beckmann, l) = (m->flags & PSF_MATFLAG_BECKMANN) ? -1 : 0;
    LANE_F(pl->eta, l) = m->eta.x;
    LANE_F(pl->scale, l) = m->eta.y;
    LANE_F(pl->weight, l) = m->albedo.w;
    LANE_F(pl->t_o, l) = rough_transmittance(*m, b->plastic_table[l], cos_o);
    vec8_set(&pl->spec, l, m->specular.xyz);
    vec8_set(&pl->base, l, plastic_base(*m));
  }
}

/* bsdf_eval_local of the lanes of `evaluate` for local o and i into *f and
 * *pdf: each kind's own, 0 for the delta lobes; the diffuse kind's lanes keep
 * what *f and *pdf hold (the caller's diffuse BSDF). mats: the lanes'
 * materials (a rough plastic's table lookup towards i). */
inline void lanes_bsdfs_eval(const LanesBsdfs* b, const Material* mats, Vec8 o, Vec8 i, int8 evaluate, Vec8* f,
                             float8* pdf) {
  float8 pdf_v;
  const int8 e_pplastic = evaluate & b->pplastic, e_rough_dielectric = evaluate & b->rough_dielectric;
  const int8 e_smooth_plastic = evaluate & b->smooth_plastic, e_principled = evaluate & b->principled;
  const int8 e_conductor = evaluate & b->conductor, e_plastic = evaluate & b->plastic, e_delta = evaluate & b->delta;
  const int8 e_thin = evaluate & b->thin;
  if (any(e_thin)) {
    *f = vec8_select(*f, thin8_eval(&b->th, o, i, &pdf_v), e_thin);
    *pdf = select(*pdf, pdf_v, e_thin);
  }
  if (any(e_pplastic)) {
    *f = vec8_select(*f, pplastic8_eval(&b->pp, o, i, &pdf_v), e_pplastic);
    *pdf = select(*pdf, pdf_v, e_pplastic);
  }
  if (any(e_rough_dielectric)) {
    *f = vec8_select(*f, rough_dielectric8_eval(&b->rd, o, i, &pdf_v), e_rough_dielectric);
    *pdf = select(*pdf, pdf_v, e_rough_dielectric);
  }
  if (any(e_smooth_plastic)) {
    *f = vec8_select(*f, smooth_plastic8_eval(&b->spl, o, i, &pdf_v), e_smooth_plastic);
    *pdf = select(*pdf, pdf_v, e_smooth_plastic);
  }
  if (any(e_principled)) {
    *f = vec8_select(*f, principled8_eval(&b->pr8, o, i, &pdf_v), e_principled);
    *pdf = select(*pdf, pdf_v, e_principled);
  }
  if (any(e_conductor)) {
    *f = vec8_select(*f, conductor8_eval(&b->co, o, i, &pdf_v), e_conductor);
    *pdf = select(*pdf, pdf_v, e_conductor);
  }
  if (any(e_plastic)) {
    float8 t_i = (float8)(0.0f);
    for (uint l = 0u; l < PSF_LANES; ++l)
      if (LANE_I(e_plastic, l)) LANE_F(t_i, l) = rough_transmittance(mats[l], b->plastic_table[l], LANE_F(i.z, l));
    *f = vec8_select(*f, plastic8_eval(&b->pl, o, i, t_i, &pdf_v), e_plastic);
    *pdf = select(*pdf, pdf_v, e_plastic);
  }
  *f = vec8_select(*f, vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f)), e_delta);
  *pdf = select(*pdf, (float8)(0.0f), e_delta);
}

/* bsdf_finish for the lanes of `take`: the sampled local direction i (wo where
 * the sample fails) in the frame (s, t, n), with f and pdf from the BSDF's
 * evaluation, into *wi, *pdf and *weight. */
inline void lanes_take_sample(int8 take, int8 fails, const Vec8* s, const Vec8* t, const Vec8* n, const Vec8* wo,
                              Vec8 i, Vec8 f, float8 pdf_i, Vec8* wi, float8* pdf, Vec8* weight) {
  const int8 ok = take & ~fails & (pdf_i > 0.0f);
  const Vec8 world = vec8_add(vec8_add(vec8_scale(*s, i.x), vec8_scale(*t, i.y)), vec8_scale(*n, i.z));
  *wi = vec8_select(*wi, vec8_select(*wo, world, ~fails), take);
  *pdf = select(*pdf, select((float8)(0.0f), pdf_i, ok), take);
  const Vec8 zero = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
  *weight = vec8_select(*weight, vec8_select(zero, vec8_scale(f, fabs(i.z) / pdf_i), ok), take);
}

/* bsdf_sample of the lanes of `sample_own` whose material is one of
 * LanesBsdfs' kinds (lanes_bsdfs_mask), for wo (world) in the frame (fs, ft,
 * fn), fn_wo = <wo, fn>, wl the cosine-weighted direction (local) of u_b1,
 * u_b2, and the lobe choice u_lobe: each kind's own sample, then its value and
 * pdf (bsdf_finish) into *wi, *pdf and *weight, and *delta_lobe where a delta
 * lobe was chosen; the other lanes keep what they hold. mats: the lanes'
 * materials (a rough plastic's table lookup). */
inline void lanes_bsdfs_sample(const LanesBsdfs* b, const Material* mats, int8 sample_own, const Vec8* fs,
                               const Vec8* ft, const Vec8* fn, const Vec8* wo, float8 fn_wo, Vec8 wl, float8 u_b1,
                               float8 u_b2, float8 u_lobe, Vec8* wi, float8* pdf, Vec8* weight, int8* delta_lobe) {
  const Vec8 o = vec8(vec8_dot(*wo, *fs), vec8_dot(*wo, *ft), fn_wo); /* wo in the frame */
  /* A rough plastic's sample (bsdf_sample_general): the coat's visible
   * normal with its probability, else the cosine-weighted direction (wl),
   * then bsdf_finish's value and pdf. */
  const int8 sample_plastic = sample_own & b->plastic;
  if (any(sample_plastic)) {
    const int8 coat = u_lobe < plastic8_prob_specular(&b->pl);
    const Vec8 h = mf8_sample(o, b->pl.au, b->pl.av, b->pl.beckmann, sample_plastic & coat, u_b1, u_b2);
    const Vec8 i = vec8_select(wl, vec8_sub(vec8_scale(h, 2.0f * vec8_dot(o, h)), o), coat);
    const int8 fails = (o.z <= 0.0f) | (coat & (i.z <= 0.0f));
    float8 t_i = (float8)(0.0f), pdf_p;
    for (uint l = 0u; l < PSF_LANES; ++l)
      if (LANE_I(sample_plastic, l)) LANE_F(t_i, l) = rough_transmittance(mats[l], b->plastic_table[l], LANE_F(i.z, l));
    const Vec8 f = plastic8_eval(&b->pl, o, i, t_i, &pdf_p);
    lanes_take_sample(sample_plastic, fails, fs, ft, fn, wo, i, f, pdf_p, wi, pdf, weight);
  }
  /* A rough conductor's sample (bsdf_sample_general): the visible normal's
   * mirror direction, then bsdf_finish's value and pdf. */
  const int8 sample_conductor = sample_own & b->conductor;
  if (any(sample_conductor)) {
    const Vec8 h = mf8_sample(o, b->co.au, b->co.av, b->co.beckmann, sample_conductor, u_b1, u_b2);
    const Vec8 i = vec8_sub(vec8_scale(h, 2.0f * vec8_dot(o, h)), o);
    const int8 fails = (o.z <= 0.0f) | (i.z <= 0.0f);
    float8 pdf_c;
    const Vec8 f = conductor8_eval(&b->co, o, i, &pdf_c);
    lanes_take_sample(sample_conductor, fails, fs, ft, fn, wo, i, f, pdf_c, wi, pdf, weight);
  }
  /* A smooth dielectric's or conductor's sample (bsdf_delta, bsdf_fail). */
  const int8 sample_delta = sample_own & b->delta;
  if (any(sample_delta)) {
    Vec8 w;
    int8 fails;
    const Vec8 i = delta8_sample(&b->dl, o, u_lobe, &w, &fails);
    const Vec8 world = vec8_add(vec8_add(vec8_scale(*fs, i.x), vec8_scale(*ft, i.y)), vec8_scale(*fn, i.z));
    *wi = vec8_select(*wi, vec8_select(world, *wo, fails), sample_delta);
    *pdf = select(*pdf, (float8)(0.0f), sample_delta);
    *weight =
        vec8_select(*weight, vec8_select(w, vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f)), fails), sample_delta);
    *delta_lobe = select(*delta_lobe, ~fails, sample_delta);
  }
  /* A rough dielectric's sample (bsdf_sample_general): the microfacet
   * normal for o turned to the normals' side, reflected or refracted by
   * its Fresnel term (microfacet_scatter), then bsdf_finish's. */
  const int8 sample_rough_dielectric = sample_own & b->rough_dielectric;
  if (any(sample_rough_dielectric)) {
    const Vec8 of = vec8_select(vec8_neg(o), o, o.z > 0.0f);
    const Vec8 h = mf8_sample(of, b->rd.au, b->rd.av, b->rd.beckmann, sample_rough_dielectric, u_b1, u_b2);
    const float8 oh = vec8_dot(o, h);
    float8 cos_t, eta_ti;
    const float8 fr = fresnel_dielectric_t8(oh, b->rd.eta, &cos_t, &eta_ti);
    const int8 reflect = u_lobe < fr;
    const Vec8 ir = vec8_sub(vec8_scale(h, 2.0f * oh), o);
    const Vec8 it = vec8_sub(vec8_scale(h, oh * eta_ti + cos_t), vec8_scale(o, eta_ti));
    const Vec8 i = vec8_select(it, ir, reflect);
    const int8 fails = (o.z == 0.0f) | select(i.z * o.z >= 0.0f, i.z * o.z <= 0.0f, reflect);
    float8 pdf_e;
    const Vec8 f = rough_dielectric8_eval(&b->rd, o, i, &pdf_e);
    lanes_take_sample(sample_rough_dielectric, fails, fs, ft, fn, wo, i, f, pdf_e, wi, pdf, weight);
  }
  /* A smooth plastic's sample (bsdf_sample_general): the coat's mirror
   * direction, a delta lobe, else the cosine direction and bsdf_finish's. */
  const int8 sample_smooth_plastic = sample_own & b->smooth_plastic;
  if (any(sample_smooth_plastic)) {
    const int8 fails = o.z <= 0.0f;
    const float8 fo = fresnel_dielectric8(o.z, b->spl.eta), ps = smooth_plastic8_prob_specular(&b->spl, fo);
    const int8 coat = sample_smooth_plastic & (u_lobe < ps);
    float8 pdf_e;
    const Vec8 f = smooth_plastic8_eval(&b->spl, o, wl, &pdf_e);
    lanes_take_sample(sample_smooth_plastic & ~coat, fails, fs, ft, fn, wo, wl, f, pdf_e, wi, pdf, weight);
    const Vec8 mirror = vec8_add(vec8_add(vec8_scale(*fs, -o.x), vec8_scale(*ft, -o.y)), vec8_scale(*fn, o.z));
    const Vec8 zero = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
    *wi = vec8_select(*wi, vec8_select(mirror, *wo, fails), coat);
    *pdf = select(*pdf, (float8)(0.0f), coat);
    *weight = vec8_select(*weight, vec8_select(vec8_scale(b->spl.spec, fo / ps), zero, fails), coat);
    *delta_lobe = select(*delta_lobe, ~fails, coat);
  }
  /* A pplastic's sample (bsdf_sample_general): the microfacet normal's
   * mirror direction with probability albedo.w, else the cosine direction. */
  const int8 sample_pplastic = sample_own & b->pplastic;
  if (any(sample_pplastic)) {
    const int8 spec = u_lobe < b->pp.ps;
    const Vec8 h = mf8_sample(o, b->pp.au, b->pp.av, b->pp.beckmann, sample_pplastic & spec, u_b1, u_b2);
    const Vec8 i = vec8_select(wl, vec8_sub(vec8_scale(h, 2.0f * vec8_dot(o, h)), o), spec);
    const int8 fails = (o.z <= 0.0f) | (spec & (i.z <= 0.0f));
    float8 pdf_e;
    const Vec8 f = pplastic8_eval(&b->pp, o, i, &pdf_e);
    lanes_take_sample(sample_pplastic, fails, fs, ft, fn, wo, i, f, pdf_e, wi, pdf, weight);
  }
  /* A principledthin's sample (thin_sample), then bsdf_finish's. */
  const int8 sample_thin = sample_own & b->thin;
  if (any(sample_thin)) {
    int8 fails;
    const Vec8 i = thin8_sample(&b->th, o, wl, u_b1, u_b2, u_lobe, &fails);
    float8 pdf_e;
    const Vec8 f = thin8_eval(&b->th, o, i, &pdf_e);
    lanes_take_sample(sample_thin, fails, fs, ft, fn, wo, i, f, pdf_e, wi, pdf, weight);
  }
  /* A principled material's sample (principled_sample), then bsdf_finish's. */
  const int8 sample_principled = sample_own & b->principled;
  if (any(sample_principled)) {
    int8 fails;
    const Vec8 i = principled8_sample(&b->pr8, sample_principled, o, wl, u_b1, u_b2, u_lobe, &fails);
    fails |= o.z == 0.0f;
    float8 pdf_e;
    const Vec8 f = principled8_eval(&b->pr8, o, i, &pdf_e);
    lanes_take_sample(sample_principled, fails, fs, ft, fn, wo, i, f, pdf_e, wi, pdf, weight);
  }
}

__kernel void trace_lanes(FrameParams params, __global const uint* restrict sobol,
                          __global const float4* restrict tri_pos, __global const uint* restrict tri_material,
                          __global const Material* restrict materials, __global const Emitter* restrict emitters,
                          __global const float* restrict emitter_cdf, __global const float* restrict tri_light_pdf,
                          __global const BvhNode* restrict nodes, __global const BvhTriPack* restrict packs,
                          Camera camera, __global PathState* restrict states, __global PathVertex* restrict vertices,
                          __global const TriAttrib* restrict tri_attribs, __global const TextureInfo* restrict textures,
                          __global const half* restrict texels, Environment env,
                          __global const float* restrict env_data, uint masked, uint count, uint per_item, uint store,
                          __global float4* restrict contrib_unfiltered, __global float4* restrict values) {
  const uint first = get_global_id(0) * per_item;
  if (first >= count) return;
  const uint end = min(first + per_item, count);
  uint next = first;
  Lanes ln;
  {
    const Vec8 zero = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
    ln.org = ln.dir = ln.beta = ln.radiance = ln.vertex_radiance = ln.prev = ln.alpha = zero;
    ln.tmin = ln.tmax = ln.bsdf_pdf = ln.radiance_w = ln.vertex_radiance_w = ln.path_length = (float8)(0.0f);
    ln.pixel = ln.sample = ln.depth = ln.flags = ln.path = (uint8)(0u);
    ln.live = (int8)(0);
  }
  CameraRays8 cam;
  cam.first = next + PSF_LANES; /* empty */
  lanes_refill(&ln, (int8)(-1), &next, end, &params, &camera, sobol, &cam);
  const uint seed_hash = psf_hash(params.seed);
  const AlphaScene alpha = {tri_material, materials, tri_attribs, textures, texels, 0};
  const int8 hide_area = (int8)((params.hide & PSF_HIDE_AREA) ? -1 : 0);
  const int8 mis_on = (int8)(params.num_emitters > 0u ? -1 : 0);
  __global const BvhNode* flat_root = flat_root_leaves(nodes, params.flat_packs) ? nodes : 0;
  /* With a few lights, the environment map's entry among them (none: num_emitters). */
  uint env_emitter = params.num_emitters;
  if (env.width > 0u && params.num_emitters <= PSF_LANES_FEW_LIGHTS)
    for (uint k = 0u; k < params.num_emitters; ++k)
      if (emitters[k].type == PSF_EMITTER_ENVIRONMENT) env_emitter = k;

  while (any(ln.live)) {
    /* The bounce's samples (shade.cl bounce_samples), across the lanes, and
     * its light choice: before the casts, for every live lane (those that
     * scatter are among them, and a lane's numbers do not depend on the
     * others'), so that the environment map's light samples can start. */
    LaneSamples us;
    lanes_sample_rows(sobol, seed_hash, params.dim_bounce0, &ln, ln.live, &us);
    /* With one light, its choice needs no number (sample_cdf_guided of one entry). */
    const float8 u_light =
        params.num_emitters > 1u ? lanes_sample_dim(sobol, &us, PSF_DIM_LIGHT_SELECT) : (float8)(0.0f);
    /* The point on the light: here where an environment map's samples start
     * before the casts, else with the light samples. */
    float8 u_la = (float8)(0.0f), u_lb = (float8)(0.0f);
    const bool light_uv_early = env.width > 0u && params.num_emitters > 0u;
    if (light_uv_early) {
      u_la = lanes_sample_dim(sobol, &us, PSF_DIM_LIGHT_UV);
      u_lb = lanes_sample_dim(sobol, &us, PSF_DIM_LIGHT_UV + 1);
    }
    /* The light, by sample_cdf_guided for all lanes at once: each lane's guide
     * entry, then the forward steps of the lanes together, so that no lane's
     * number of steps is a branch to mispredict. With a few lights, the number
     * of cdf entries at most u instead (the same index: the guide entry is at
     * most it), from loads all lanes share rather than gathers. */
    uint8 light = (uint8)(0u);
    if (params.num_emitters > 0u && params.num_emitters <= PSF_LANES_FEW_LIGHTS) {
      for (uint k = 0u; k + 1u < params.num_emitters; ++k)
        light -= as_uint8(ln.live & ((float8)(emitter_cdf[k]) <= u_light));
    } else if (params.num_emitters > 0u) {
      const uint n = params.num_emitters;
      for (uint l = 0u; l < PSF_LANES; ++l)
        if (LANE_I(ln.live, l))
          LANE_U(light, l) = as_uint(emitter_cdf[n + min((uint)(LANE_F(u_light, l) * (float)n), n - 1u)]);
      for (;;) {
        float8 c;
        for (uint l = 0u; l < PSF_LANES; ++l) LANE_F(c, l) = emitter_cdf[LANE_U(light, l)];
        const int8 step = ln.live & (light < (uint8)(n - 1u)) & (c <= u_light);
        if (!any(step)) break;
        light = select(light, light + 1u, as_uint8(step));
      }
    }

    /* The lanes that chose an environment map start their samples (EnvLanes):
     * the steps run between the closest-hit casts. */
    EnvLanes env_lanes;
    int8 env_choice = (int8)(0);
    if (env.width > 0u && params.num_emitters > 0u) {
      if (params.num_emitters <= PSF_LANES_FEW_LIGHTS) {
        env_choice = ln.live & as_int8(light == (uint8)(env_emitter));
      } else {
        for (uint l = 0u; l < PSF_LANES; ++l)
          if (LANE_I(ln.live, l) && emitters[LANE_U(light, l)].type == PSF_EMITTER_ENVIRONMENT)
            LANE_I(env_choice, l) = -1;
      }
    }
    const bool env_samples = any(env_choice);
    if (env_samples) env_lanes_row(env, env_data, env_choice, u_la, u_lb, &env_lanes);

    /* The closest hits: all lanes at once in a scene of a few packs, else
     * lane by lane through the BVH. */
    float8 t = (float8)(0.0f), bu = (float8)(0.0f), bv = (float8)(0.0f);
    uint8 prim = (uint8)(PSF_NO_HIT);
    if (params.flat_packs > 0u) { /* a scene of a few packs: all lanes at once, without the BVH */
      if (env_samples) {
        env_lanes_guide(env, env_data, &env_lanes);
        env_lanes_block(env, env_data, &env_lanes);
        env_lanes_cell(env, env_data, env.scale.w, &env_lanes);
      }
      flat_closest8(packs, params.flat_packs, flat_root, params.spheres != PSF_FRAME_SPHERES_NONE, ln.org, ln.dir,
                    ln.tmin, ln.tmax, ln.live, &t, &prim, &bu, &bv);
    }
    for (uint l = 0u; l < PSF_LANES && params.flat_packs == 0u; ++l) {
      if (env_samples && l == 2u) env_lanes_guide(env, env_data, &env_lanes);
      if (env_samples && l == 4u) env_lanes_block(env, env_data, &env_lanes);
      if (env_samples && l == 6u) env_lanes_cell(env, env_data, env.scale.w, &env_lanes);
      if (!LANE_I(ln.live, l)) continue;
      Ray r;
      r.org = (float4)(VEC8_GET(ln.org, l), LANE_F(ln.tmin, l));
      r.dir = (float4)(VEC8_GET(ln.dir, l), LANE_F(ln.tmax, l));
      Hit h;
      lane_cast_closest(masked, params.spheres, nodes, packs, &alpha, &r, &h);
      if (PSF_PREFETCH && h.prim != PSF_NO_HIT) { /* what shading reads of the hit, while the other lanes cast */
        psf_prefetch(tri_pos + 3u * h.prim);
        psf_prefetch(tri_pos + 3u * h.prim + 2u);
        psf_prefetch(tri_material + h.prim);
        psf_prefetch(tri_light_pdf + h.prim);
        psf_prefetch(tri_attribs + h.prim); /* its 96 bytes span two lines: flags and uvs in the second */
        psf_prefetch((__global const char*)(tri_attribs + h.prim) + 64);
      } else if (PSF_PREFETCH && env.width > 0u) { /* what the environment's lookup below reads */
        env_prefetch_lookup(env, env_data, normalize(VEC8_GET(ln.dir, l)));
      }
      LANE_F(t, l) = h.t;
      LANE_U(prim, l) = h.prim;
      LANE_F(bu, l) = h.u;
      LANE_F(bv, l) = h.v;
    }
    ln.flags &= ~PSF_PATH_VERTEX_NEW;
    const int8 hit = ln.live & (prim != PSF_NO_HIT);

    /* Escaped rays see the environment, MIS-weighted against its light samples
     * unless they left the camera (shade.cl), lane by lane. */
    if (env.present && env.width == 0u) { /* a constant environment, in vectors */
      int8 sees = ln.live & ~hit;
      if (params.hide & PSF_HIDE_ENVIRONMENT) sees &= ln.depth > 0u;
      const int8 mis = (ln.depth > 0u) & ((ln.flags & PSF_PATH_SPECULAR) == 0u);
      const float8 w = select((float8)(1.0f),
                              power_heuristic8(ln.bsdf_pdf, (float8)(env.scale.w * (1.0f / (4.0f * PSF_ENV_PI)))), mis);
      const Vec8 le = vec8((float8)(env.scale.x), (float8)(env.scale.y), (float8)(env.scale.z));
      lanes_add_radiance(&ln, vec8_scale(vec8_mul(ln.beta, le), w), sees, true);
    } else if (env.present) {
      const int8 escaped = ln.live & ~hit;
      Vec8 seen = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
      int8 sees = (int8)(0);
      for (uint todo = psf_lanes8(escaped); todo != 0u; todo &= todo - 1u) {
        const uint l = bvh_first_lane(todo);
        const uint depth = LANE_U(ln.depth, l);
        if (depth == 0u && (params.hide & PSF_HIDE_ENVIRONMENT)) continue;
        const float3 d = normalize(VEC8_GET(ln.dir, l));
        float w = 1.0f, pdf;
        const bool mis = depth > 0u && !(LANE_U(ln.flags, l) & PSF_PATH_SPECULAR);
        const float3 radiance = env_radiance_pdf(env, env_data, d, mis ? &pdf : 0);
        if (mis) w = power_heuristic(LANE_F(ln.bsdf_pdf, l), env.scale.w * pdf);
        vec8_set(&seen, l, VEC8_GET(ln.beta, l) * radiance * w);
        LANE_I(sees, l) = -1;
      }
      lanes_add_radiance(&ln, seen, sees, true);
    }

    /* The hit triangles' corners, materials and shading normals, lane by lane. */
    Vec8 p0, p1, p2, albedo, emission, n0, n1, n2;
    uint8 emission_tex = (uint8)(PSF_NO_TEXTURE);
    float8 light_pdf = (float8)(0.0f);
    int8 two_sided = (int8)(0), mat_normals = (int8)(0), normals = (int8)(0), textured = (int8)(0);
    /* A material the vectors do not shade as diffuse (PSF_MATFLAG_LANES_VECTOR), or a sphere's textured one. */
    int8 general = (int8)(0);
    p0 = p1 = p2 = albedo = emission = n0 = n1 = n2 = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
    for (uint l = 0u; l < PSF_LANES; ++l) {
      if (!LANE_I(hit, l)) continue;
      const uint pr = LANE_U(prim, l);
      vec8_set(&p0, l, tri_pos[3u * pr].xyz);
      vec8_set(&p1, l, tri_pos[3u * pr + 1u].xyz);
      vec8_set(&p2, l, tri_pos[3u * pr + 2u].xyz);
      __global const Material* m = materials + tri_material[pr];
      vec8_set(&albedo, l, m->albedo.xyz);
      vec8_set(&emission, l, m->emission.xyz);
      LANE_U(emission_tex, l) = m->tex_emission;
      LANE_I(two_sided, l) = m->two_sided ? -1 : 0;
      LANE_I(textured, l) = m->tex_color != PSF_NO_TEXTURE ? -1 : 0;
      /* A sphere shades in vectors where nothing needs its uv or dp/du. */
      const bool plain_sphere = m->tex_color == PSF_NO_TEXTURE && m->tex_emission == PSF_NO_TEXTURE;
      LANE_I(general, l) = (m->flags & PSF_MATFLAG_LANES_VECTOR) && (pr < params.first_sphere || plain_sphere) ? 0 : -1;
      LANE_F(light_pdf, l) = tri_light_pdf[pr];
      __global const TriAttrib* a = tri_attribs + pr;
      LANE_I(mat_normals, l) = (m->flags & PSF_MATFLAG_NORMALS) ? -1 : 0;
      if ((m->flags & PSF_MATFLAG_NORMALS) && (a->flags & PSF_TRI_NORMALS)) {
        LANE_I(normals, l) = -1;
        vec8_set(&n0, l, a->n0.xyz);
        vec8_set(&n1, l, a->n1.xyz);
        vec8_set(&n2, l, a->n2.xyz);
      }
    }

    /* The hit point, its geometric normal and the emission found there. */
    const float8 ray_len = vec8_length(ln.dir);
    const float8 dist = t * ray_len;
    const Vec8 wo = vec8_div(vec8_neg(ln.dir), ray_len);
    const Vec8 pos = vec8_add(ln.org, vec8_scale(ln.dir, t));
    Vec8 ng = vec8_cross(vec8_sub(p1, p0), vec8_sub(p2, p0));
    const float8 area2 = vec8_length(ng);
    ng = vec8_select(vec8((float8)(0.0f), (float8)(0.0f), (float8)(1.0f)), vec8_div(ng, area2), area2 > 0.0f);
    /* An analytic sphere: its radius and normal sign; its normal in vectors
     * where its material is shaded in vectors, else its normal, uv and dp/du,
     * dp/dv as three points (surface.cl surface_sphere), lane by lane for the
     * lanes' own frame. p0, p1 and p2 hold its tri_pos entries (centre, x and y
     * axes) until then. */
    const int8 sphere = hit & (prim >= (uint8)(params.first_sphere));
    float8 sphere_r = (float8)(0.0f), sphere_sign = (float8)(0.0f);
    if (any(sphere)) {
      for (uint todo = psf_lanes8(sphere); todo != 0u; todo &= todo - 1u) {
        const uint l = bvh_first_lane(todo);
        __global const float4* sp = tri_pos + 3u * LANE_U(prim, l);
        LANE_F(sphere_r, l) = sp[0].w;
        LANE_F(sphere_sign, l) = sp[1].w;
        if (!LANE_I(general, l)) continue;
        float3 n, a, b, c;
        surface_sphere(sp, VEC8_GET(pos, l), &n, &LANE_F(bu, l), &LANE_F(bv, l), &a, &b, &c);
        vec8_set(&ng, l, n);
        vec8_set(&p0, l, a);
        vec8_set(&p1, l, b);
        vec8_set(&p2, l, c);
      }
      const int8 vector_sphere = sphere & ~general;
      if (any(vector_sphere)) {
        const Vec8 d = vec8_sub(pos, p0);
        const float8 len = vec8_length(d);
        const Vec8 n = vec8_select(vec8_cross(p1, p2), vec8_div(d, len), len > 0.0f);
        ng = vec8_select(ng, vec8_scale(n, sphere_sign), vector_sphere);
      }
    }
    ln.path_length = select(ln.path_length, ln.path_length + dist, hit);
    const float8 ng_wo = vec8_dot(ng, wo);
    const int8 front = ng_wo > 0.0f;
    const int8 emits = hit & (vec8_max3(emission) > 0.0f) & (front | two_sided) & ~(hide_area & (ln.depth == 0u));
    {
      const int8 mis = mis_on & (ln.depth > 0u) & ((ln.flags & PSF_PATH_SPECULAR) == 0u);
      const float8 cos_l = fabs(ng_wo);
      float8 pdf_hit = select((float8)(0.0f), light_pdf * dist * dist / cos_l, cos_l > 0.0f);
      /* A sphere light: emitter_pdf_sphere, in vectors where its centre is in p0. */
      const int8 sphere_light = emits & mis & sphere;
      if (any(sphere_light & ~general)) {
        const Vec8 dc = vec8_sub(p0, ln.prev);
        const float8 r2 = sphere_r * sphere_r;
        const int8 cone = sphere_light & ~general & ~two_sided & (sphere_sign > 0.0f) & (vec8_dot(dc, dc) > r2);
        const float8 s = fmin(r2 / vec8_dot(dc, dc), 1.0f);
        const float8 width = s / (1.0f + sqrt(1.0f - s));
        pdf_hit = select(pdf_hit, light_pdf * (4.0f * PSF_ENV_PI * r2) / (2.0f * PSF_ENV_PI * width), cone);
      }
      for (uint todo = psf_lanes8(sphere_light & general); todo != 0u; todo &= todo - 1u) {
        const uint l = bvh_first_lane(todo);
        LANE_F(pdf_hit, l) =
            emitter_pdf_sphere(tri_light_pdf, LANE_U(prim, l), tri_pos + 3u * LANE_U(prim, l),
                               LANE_I(two_sided, l) ? 1u : 0u, VEC8_GET(ln.prev, l), LANE_F(dist, l), LANE_F(cos_l, l));
      }
      const float8 w = select((float8)(1.0f), power_heuristic8(ln.bsdf_pdf, pdf_hit), mis);
      /* An emission texture multiplies the emission there (surface.cl surface_emission). */
      const int8 emits_textured = emits & (emission_tex != (uint8)(PSF_NO_TEXTURE));
      if (any(emits_textured))
        for (uint l = 0u; l < PSF_LANES; ++l)
          if (LANE_I(emits_textured, l))
            vec8_set(&emission, l,
                     VEC8_GET(emission, l) *
                         texture_eval(textures, texels, LANE_U(emission_tex, l),
                                      surface_uv(tri_attribs + LANE_U(prim, l), LANE_F(bu, l), LANE_F(bv, l)))
                             .xyz);
      lanes_add_radiance(&ln, vec8_scale(vec8_mul(ln.beta, emission), w), emits, true);
    }

    /* The shading frame: the interpolated normal (else the geometric one),
     * turned towards wo where the surface is two-sided, as surface.cl's
     * surface_frame: with a material's vertex normals its s and t are those
     * of the normal before the turn, else of the turned one. */
    Vec8 fn = ng, fs, ft;
    {
      const Vec8 ni = vec8_add(vec8_add(vec8_scale(n0, 1.0f - bu - bv), vec8_scale(n1, bu)), vec8_scale(n2, bv));
      const float8 len = vec8_length(ni);
      const Vec8 ns = vec8_select(ng, vec8_div(ni, len), normals & (len > 0.0f));
      fn = vec8_select(ns, vec8_neg(ns), two_sided & (vec8_dot(ns, wo) < 0.0f));
      frame_from_normal8(vec8_select(fn, ns, mat_normals), &fs, &ft);
    }
    /* A colour texture (its albedo, and a frame along dp/du) or a material the
     * vectors do not shade (a blend's choice, its frame and textures, what
     * scatters, whether it is diffuse enough for the filtering vertex): from
     * surface.cl's and bsdf.cl's own functions, lane by lane. */
    Material mats[PSF_LANES];      /* the material that scatters, where `general` */
    float3 unperturbed[PSF_LANES]; /* surface_frame's normal before a bump map */
    int8 scatters = (int8)(0), diffuse = (int8)(0);
    const int8 own_frame = hit & (textured | general);
    const int8 texels_read = hit & textured;
    if (PSF_PREFETCH) /* first the lanes' colour texels, so that their misses overlap */
      for (uint l = 0u; l < PSF_LANES; ++l)
        if (LANE_I(texels_read, l)) {
          const uint pr = LANE_U(prim, l);
          texture_prefetch(textures, texels, materials[tri_material[pr]].tex_color,
                           surface_uv(tri_attribs + pr, LANE_F(bu, l), LANE_F(bv, l)));
        }
    for (uint todo = psf_lanes8(own_frame); todo != 0u; todo &= todo - 1u) {
      const uint l = bvh_first_lane(todo);
      const uint pr = LANE_U(prim, l);
      /* lane_surface changes the lane's material in place: a copy of it made
       * after those field stores would wait on them (store forwarding). */
      Material* m = &mats[l];
      *m = materials[tri_material[pr]];
      const float u_blend = m->blend != 0u ? surface_blend_u(psf_hash_combine(seed_hash, LANE_U(ln.pixel, l)),
                                                             LANE_U(ln.sample, l), LANE_U(ln.depth, l))
                                           : 0.0f;
      Frame f;
      lane_surface(m, materials, tri_attribs + pr, LANE_F(bu, l), LANE_F(bv, l), VEC8_GET(p0, l), VEC8_GET(p1, l),
                   VEC8_GET(p2, l), VEC8_GET(ng, l), VEC8_GET(wo, l), textures, texels, u_blend, &f, &unperturbed[l]);
      vec8_set(&fs, l, f.s);
      vec8_set(&ft, l, f.t);
      vec8_set(&fn, l, f.n);
      vec8_set(&albedo, l, bsdf_albedo(*m));
      LANE_I(scatters, l) = bsdf_scatters(*m) ? -1 : 0;
      LANE_I(diffuse, l) = bsdf_is_diffuse(*m) ? -1 : 0;
    }
    const float8 fn_wo = vec8_dot(fn, wo);
    /* The lanes whose BSDF the vectors evaluate and sample (SmoothPlastic8,
     * Delta8, PPlastic8, Principled8, Conductor8, Plastic8): their parameters, and a rough
     * plastic's coat transmittance towards wo, its table read lane by lane. */
    /* The lanes whose BSDF the vectors evaluate and sample (LanesBsdfs), and a
     * bump or normal map's lanes: the normal before it (surface_side_agrees,
     * applied to every BSDF the vectors shade, below). */
    LanesBsdfs bs; /* the kinds' parameters zeroed as each kind's first lane is set (LANES_KIND_TAKE) */
    bs.diffuse = bs.plastic = bs.conductor = bs.principled = bs.pplastic = bs.delta = bs.smooth_plastic =
        bs.rough_dielectric = bs.thin = (int8)(0);
    int8 bump = (int8)(0);
    Vec8 unp = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
    for (uint todo = psf_lanes8(own_frame & general); todo != 0u; todo &= todo - 1u) {
      const uint l = bvh_first_lane(todo);
      if (mats[l].tex_bump != PSF_NO_TEXTURE) {
        LANE_I(bump, l) = -1;
        vec8_set(&unp, l, unperturbed[l]);
      }
      lanes_bsdfs_set(&bs, l, &mats[l], textures, texels, LANE_F(fn_wo, l));
    }
    const Vec8 n_camera = vec8_select(vec8_neg(fn), fn, fn_wo >= 0.0f);
    const uint8 segments = ln.depth + 1u;
    int8 scatter = hit & select(vec8_max3(albedo) > 0.0f, scatters, general);
    if ((int)params.max_depth >= 0) scatter &= segments + 1u <= params.max_depth;

    /* The filtering vertex: the first diffuse one. */
    const int8 new_vertex = scatter & ((ln.flags & PSF_PATH_VERTEX) == 0u) & (~general | diffuse);
    ln.flags = select(ln.flags, ln.flags | (PSF_PATH_VERTEX | PSF_PATH_VERTEX_NEW), as_uint8(new_vertex));
    Vec8 beta = vec8_select(ln.beta, vec8((float8)(1.0f), (float8)(1.0f), (float8)(1.0f)), new_vertex);

    /* Next-event estimation: a point on the chosen triangle (emitter.cl
     * emitter_sample) in vectors, and among a few lights a direction in the
     * cone of a one-sided, untextured sphere light or from a constant
     * environment; any other light (point, spot, directional lights, other
     * sphere lights, a constant environment among many lights) by
     * emitter_sample itself, lane by lane, and an environment map's
     * from EnvLanes; the sample's
     * MIS weight against the BSDF's pdf (none for a delta light). */
    Vec8 pending = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
    Vec8 shadow_org = pending, shadow_dir = pending;
    float8 shadow_tmax = (float8)(1.0f - PSF_RAY_EPS);
    int8 contributes = (int8)(0);
    if (params.num_emitters > 0u && any(scatter)) {
      if (!light_uv_early) {
        u_la = lanes_sample_dim(sobol, &us, PSF_DIM_LIGHT_UV);
        u_lb = lanes_sample_dim(sobol, &us, PSF_DIM_LIGHT_UV + 1);
      }
      Vec8 v0, e1, e2, le;
      float8 area = (float8)(1.0f), choose = (float8)(0.0f);
      int8 light_two_sided = (int8)(0), other_light = (int8)(0), env_light = (int8)(0), sphere_light = (int8)(0);
      int8 constant_light = (int8)(0); /* a constant environment */
      uint8 light_tex = (uint8)(PSF_NO_TEXTURE), light_prim = (uint8)(0u);
      float8 light_r = (float8)(0.0f); /* a sphere light's radius (its centre in v0) */
      v0 = e1 = e2 = le = pending;
      if (params.num_emitters <= PSF_LANES_FEW_LIGHTS) {
        /* A few lights: each light's data into the lanes that chose it, by
         * selects, where lane stores would leave the vectors in memory for
         * loads that wait on them (store forwarding). */
        for (uint k = 0u; k < params.num_emitters; ++k) {
          const int8 pick = scatter & as_int8(light == (uint8)(k));
          if (!any(pick)) continue;
          __global const Emitter* em = emitters + k;
          if (em->type == PSF_EMITTER_ENVIRONMENT && env.width > 0u) {
            env_light |= pick;
            choose = select(choose, (float8)(em->radiance.w), pick);
          } else if (em->type == PSF_EMITTER_ENVIRONMENT) {
            constant_light |= pick;
            choose = select(choose, (float8)(em->radiance.w), pick);
          } else if (em->type == PSF_EMITTER_SPHERE && em->e2.w > 0.0f && !em->two_sided &&
                     em->tex_emission == PSF_NO_TEXTURE) {
            /* A one-sided untextured sphere light: its cone sampled in vectors
             * (below) from outside, by emitter_sample from inside. */
            const float4 c = em->v0, r = em->radiance;
            const float rad = em->e1.w;
            const Vec8 centre = vec8((float8)(c.x), (float8)(c.y), (float8)(c.z));
            const Vec8 dc = vec8_sub(centre, pos);
            const int8 cone = pick & (vec8_dot(dc, dc) > rad * rad);
            other_light |= pick & ~cone;
            sphere_light |= cone;
            v0 = vec8_select(v0, centre, cone);
            le = vec8_select(le, vec8((float8)(r.x), (float8)(r.y), (float8)(r.z)), cone);
            light_r = select(light_r, (float8)(rad), cone);
            choose = select(choose, (float8)(r.w), cone);
          } else if (em->type != PSF_EMITTER_TRIANGLE) {
            other_light |= pick;
          } else {
            const float4 a = em->v0, b = em->e1, c = em->e2, r = em->radiance;
            v0 = vec8_select(v0, vec8((float8)(a.x), (float8)(a.y), (float8)(a.z)), pick);
            e1 = vec8_select(e1, vec8((float8)(b.x), (float8)(b.y), (float8)(b.z)), pick);
            e2 = vec8_select(e2, vec8((float8)(c.x), (float8)(c.y), (float8)(c.z)), pick);
            le = vec8_select(le, vec8((float8)(r.x), (float8)(r.y), (float8)(r.z)), pick);
            area = select(area, (float8)(a.w), pick);
            choose = select(choose, (float8)(r.w), pick);
            light_two_sided = select(light_two_sided, (int8)(em->two_sided ? -1 : 0), pick);
            light_tex = select(light_tex, (uint8)(em->tex_emission), as_uint8(pick));
            light_prim = select(light_prim, (uint8)(em->prim), as_uint8(pick));
          }
        }
      } else {
        for (uint l = 0u; l < PSF_LANES; ++l) {
          if (!LANE_I(scatter, l)) continue;
          __global const Emitter* em = emitters + LANE_U(light, l);
          if (em->type == PSF_EMITTER_ENVIRONMENT && env.width > 0u) {
            LANE_I(env_light, l) = -1;
            LANE_F(choose, l) = em->radiance.w;
            continue;
          }
          if (em->type != PSF_EMITTER_TRIANGLE) {
            LANE_I(other_light, l) = -1;
            continue;
          }
          const float4 a = em->v0;
          vec8_set(&v0, l, a.xyz);
          LANE_F(area, l) = a.w;
          vec8_set(&e1, l, em->e1.xyz);
          vec8_set(&e2, l, em->e2.xyz);
          const float4 r = em->radiance;
          vec8_set(&le, l, r.xyz);
          LANE_F(choose, l) = r.w;
          LANE_I(light_two_sided, l) = em->two_sided ? -1 : 0;
          LANE_U(light_tex, l) = em->tex_emission;
          LANE_U(light_prim, l) = em->prim;
        }
      }
      const float8 su = sqrt(u_la);
      const Vec8 lp = vec8_add(v0, vec8_add(vec8_scale(e1, su * (1.0f - u_lb)), vec8_scale(e2, su * u_lb)));
      const Vec8 lnrm = vec8_normalize(vec8_cross(e1, e2));
      const Vec8 d = vec8_sub(lp, pos);
      const float8 d2 = vec8_dot(d, d);
      float8 ldist = sqrt(d2);
      Vec8 wi = vec8_div(d, ldist);
      float8 cos_l = -vec8_dot(lnrm, wi);
      cos_l = select(cos_l, fabs(cos_l), light_two_sided);
      const int8 sampled = scatter & (d2 > 0.0f) & (cos_l > 0.0f);
      float8 lpdf = select((float8)(0.0f), choose / area * d2 / cos_l, sampled);
      /* An emission texture at the sampled point (shade.cl next_event_sample). */
      const int8 light_textured = sampled & (lpdf > 0.0f) & (light_tex != (uint8)(PSF_NO_TEXTURE));
      if (any(light_textured))
        for (uint l = 0u; l < PSF_LANES; ++l)
          if (LANE_I(light_textured, l))
            vec8_set(&le, l,
                     VEC8_GET(le, l) * texture_eval(textures, texels, LANE_U(light_tex, l),
                                                    surface_uv(tri_attribs + LANE_U(light_prim, l),
                                                               LANE_F(su, l) * (1.0f - LANE_F(u_lb, l)),
                                                               LANE_F(su, l) * LANE_F(u_lb, l)))
                                           .xyz);
      if (any(sphere_light)) {
        /* emitter_sample's cone around the direction to the centre, in vectors:
         * 1 - cos(theta) uniform in [0, 1 - cos(theta_max)], phi = 2 pi u_lb,
         * then the nearer intersection with the sphere. */
        const Vec8 dc = vec8_sub(v0, pos);
        const float8 dc2 = vec8_dot(dc, dc), r2 = light_r * light_r;
        const float8 s = fmin(r2 / dc2, 1.0f);
        const float8 width = s / (1.0f + sqrt(1.0f - s));
        const float8 omc = u_la * width, cos_t = 1.0f - omc, sin_t = sqrt(fmax(0.0f, omc * (2.0f - omc)));
        float8 cos_phi;
        const float8 sin_phi = psf_sincos8(2.0f * PSF_ENV_PI * u_lb, &cos_phi);
        Vec8 cs, ct;
        const Vec8 cn = vec8_scale(dc, rsqrt(dc2));
        frame_from_normal8(cn, &cs, &ct);
        const Vec8 swi = vec8_normalize(vec8_add(
            vec8_add(vec8_scale(cs, sin_t * cos_phi), vec8_scale(ct, sin_t * sin_phi)), vec8_scale(cn, cos_t)));
        const float8 b = vec8_dot(swi, dc);
        const Vec8 off = vec8_sub(dc, vec8_scale(swi, b));
        const float8 sdist = b - sqrt(fmax(0.0f, r2 - vec8_dot(off, off)));
        const float8 spdf = choose / (2.0f * PSF_ENV_PI * width);
        const int8 ok = (sdist > 0.0f) & (spdf > 0.0f) & isfinite(spdf);
        wi = vec8_select(wi, swi, sphere_light);
        ldist = select(ldist, sdist, sphere_light);
        lpdf = select(lpdf, select((float8)(0.0f), spdf, ok), sphere_light);
      }
      if (any(constant_light)) {
        /* emitter.cl env_sample's uniform direction over the sphere. */
        const float8 z = 1.0f - 2.0f * u_la, r = sqrt(fmax(0.0f, 1.0f - z * z));
        float8 c;
        const float8 sn = psf_sincos8(2.0f * PSF_ENV_PI * u_lb, &c);
        wi = vec8_select(wi, vec8(r * c, r * sn, z), constant_light);
        lpdf = select(lpdf, choose * (1.0f / (4.0f * PSF_ENV_PI)), constant_light);
        le = vec8_select(le, vec8((float8)(env.scale.x), (float8)(env.scale.y), (float8)(env.scale.z)), constant_light);
        ldist = select(ldist, (float8)(INFINITY), constant_light);
      }
      int8 delta = (int8)(0);
      for (uint todo = psf_lanes8(other_light); todo != 0u; todo &= todo - 1u) {
        const uint l = bvh_first_lane(todo);
        LightSample ls = emitter_sample(emitters, emitter_cdf, params.num_emitters, env, env_data, VEC8_GET(pos, l),
                                        LANE_F(u_light, l), LANE_F(u_la, l), LANE_F(u_lb, l));
        light_sample_textured(&ls, tri_attribs, textures, texels);
        vec8_set(&wi, l, ls.wi);
        LANE_F(ldist, l) = ls.dist;
        LANE_F(lpdf, l) = ls.pdf;
        vec8_set(&le, l, ls.radiance);
        LANE_I(delta, l) = ls.delta ? -1 : 0;
      }
      if (any(env_light)) {
        wi = vec8_select(wi, env_lanes.wi, env_light);
        lpdf = select(lpdf, env_lanes.pdf, env_light);
        env_lanes_radiance(env, env_data, &env_lanes, env_light, &le);
        ldist = select(ldist, (float8)(INFINITY), env_light);
      }
      const float8 cos_i = vec8_dot(wi, fn);
      const int8 f_on = (fn_wo > 0.0f) & (cos_i > 0.0f);
      Vec8 f = vec8_select(pending, vec8_scale(albedo, PSF_INV_PI), f_on);
      float8 bpdf = select((float8)(0.0f), cos_i * PSF_INV_PI, f_on);
      const int8 evaluate = general & scatter & (lpdf > 0.0f);
      const int8 vector_bsdf = lanes_bsdfs_mask(&bs);
      for (uint todo = psf_lanes8(evaluate & ~vector_bsdf); todo != 0u; todo &= todo - 1u) {
        const uint l = bvh_first_lane(todo);
        const Frame fr = vec8_frame(&fs, &ft, &fn, l);
        float pdf_l;
        vec8_set(
            &f, l,
            lane_bsdf_eval(&mats[l], textures, texels, &fr, &unperturbed[l], VEC8_GET(wo, l), VEC8_GET(wi, l), &pdf_l));
        LANE_F(bpdf, l) = pdf_l;
      }
      /* The BSDFs in vectors, in the local frame; then nothing towards a
       * direction whose sides a bump map turned (surface_side_agrees). */
      if (any(evaluate & vector_bsdf)) {
        const Vec8 o = vec8(vec8_dot(wo, fs), vec8_dot(wo, ft), fn_wo);
        const Vec8 i = vec8(vec8_dot(wi, fs), vec8_dot(wi, ft), cos_i);
        lanes_bsdfs_eval(&bs, mats, o, i, evaluate, &f, &bpdf);
        const int8 off = evaluate & vector_bsdf & bump & ~(vec8_dot(wi, unp) * cos_i > 0.0f);
        f = vec8_select(f, vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f)), off);
        bpdf = select(bpdf, (float8)(0.0f), off);
      }
      const float8 cos_s = fabs(cos_i);
      contributes = (lpdf > 0.0f) & (cos_s > 0.0f) & (vec8_max3(f) > 0.0f);
      const float8 w = select(power_heuristic8(lpdf, bpdf), (float8)(1.0f), delta);
      pending =
          vec8_select(pending, vec8_scale(vec8_mul(vec8_scale(vec8_mul(beta, f), cos_s), le), w / lpdf), contributes);
      const Vec8 side = vec8_select(vec8_neg(ng), ng, vec8_dot(wi, ng) >= 0.0f);
      shadow_org = offset_origin8(pos, side);
      const int8 infinite = isinf(ldist);
      shadow_dir = vec8_select(vec8_sub(vec8_add(pos, vec8_scale(wi, ldist)), shadow_org), wi, infinite);
      shadow_tmax = select(shadow_tmax, (float8)(INFINITY), infinite);
    }

    /* The next direction (bsdf.cl bsdf_sample: diffuse in vectors, any other
     * material lane by lane), then Russian roulette. The lobe's number only
     * where a lane's BSDF chooses one (not a diffuse or rough conductor's). */
    const bool scatters_any = any(scatter);
    const float8 u_b1 = scatters_any ? lanes_sample_dim(sobol, &us, PSF_DIM_BSDF_UV) : (float8)(0.0f);
    const float8 u_b2 = scatters_any ? lanes_sample_dim(sobol, &us, PSF_DIM_BSDF_UV + 1) : (float8)(0.0f);
    const Vec8 wl = cosine_hemisphere8(u_b1, u_b2);
    Vec8 wi = vec8_normalize(vec8_add(vec8_add(vec8_scale(fs, wl.x), vec8_scale(ft, wl.y)), vec8_scale(fn, wl.z)));
    float8 pdf = select((float8)(0.0f), wl.z * PSF_INV_PI, fn_wo > 0.0f);
    Vec8 weight = vec8_select(vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f)), albedo, pdf > 0.0f);
    int8 delta_lobe = (int8)(0);
    const int8 sample_own = general & scatter;
    const int8 sample_vector = lanes_bsdfs_mask(&bs);
    const float8 u_lobe = any(sample_own & ~(bs.diffuse | bs.conductor))
                              ? lanes_sample_dim(sobol, &us, PSF_DIM_BSDF_LOBE)
                              : (float8)(0.0f);
    for (uint todo = psf_lanes8(sample_own & ~sample_vector); todo != 0u; todo &= todo - 1u) {
      const uint l = bvh_first_lane(todo);
      const Frame fr = vec8_frame(&fs, &ft, &fn, l);
      BsdfSample sm;
      lane_bsdf_sample(&mats[l], textures, texels, &fr, &unperturbed[l], VEC8_GET(wo, l), LANE_F(u_b1, l),
                       LANE_F(u_b2, l), LANE_F(u_lobe, l), &sm);
      vec8_set(&wi, l, sm.wi);
      LANE_F(pdf, l) = sm.pdf;
      vec8_set(&weight, l, sm.weight);
      LANE_I(delta_lobe, l) = (sm.flags & BSDF_DELTA) ? -1 : 0;
    }
    lanes_bsdfs_sample(&bs, mats, sample_own, &fs, &ft, &fn, &wo, fn_wo, wl, u_b1, u_b2, u_lobe, &wi, &pdf, &weight,
                       &delta_lobe);
    /* A sampled direction whose sides a bump map turned carries nothing
     * (lane_bsdf_sample's surface_side_agrees). */
    const int8 side_off = sample_own & sample_vector & bump & ~(vec8_dot(wi, unp) * vec8_dot(wi, fn) > 0.0f);
    weight = vec8_select(weight, vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f)), side_off);
    beta = vec8_mul(beta, weight);
    const int8 rr = scatter & (segments >= params.rr_depth);
    const float8 q = fmin(vec8_max3(beta), 0.95f);
    if (any(rr)) scatter &= ~(rr & (lanes_sample_dim(sobol, &us, PSF_DIM_RR) >= q));
    beta = vec8_select(beta, vec8_div(beta, q), rr);
    const int8 go = scatter & (vec8_max3(weight) > 0.0f);

    /* The shadow rays (trace_paths' intersect_any_hit_alpha without alpha;
     * all lanes at once in a scene of a few packs, else lane by lane), and
     * what they decide (shade.cl shadow_slot). */
    int8 visible = (int8)(0);
    if (params.flat_packs > 0u)
      visible = contributes & ~flat_any8(packs, params.flat_packs, flat_root, params.spheres != PSF_FRAME_SPHERES_NONE,
                                         shadow_org, shadow_dir, (float8)(0.0f), shadow_tmax, contributes);
    for (uint todo = params.flat_packs > 0u ? 0u : psf_lanes8(contributes); todo != 0u;
         todo &= todo - 1u) { /* else its set lanes through the BVH: no branch per lane */
      const uint l = bvh_first_lane(todo);
      Ray r;
      r.org = (float4)(VEC8_GET(shadow_org, l), 0.0f);
      r.dir = (float4)(VEC8_GET(shadow_dir, l), LANE_F(shadow_tmax, l));
      Hit h;
      lane_cast_any(masked, params.spheres, nodes, packs, &alpha, &r, &h);
      LANE_I(visible, l) = h.prim != PSF_NO_HIT ? 0 : -1;
    }
    lanes_add_radiance(&ln, pending, visible, false);
    ln.alpha = vec8_select(ln.alpha, ln.beta, new_vertex);
    for (uint l = 0u; l < PSF_LANES && store != PSF_LANES_STORE_DIRECT; ++l) {
      if (!LANE_I(new_vertex, l)) continue;
      PathVertex v;
      v.position = (float4)(VEC8_GET(pos, l), LANE_F(ln.path_length, l));
      v.normal = (float4)(VEC8_GET(n_camera, l), LANE_I(visible, l) || !LANE_I(contributes, l) ? 1.0f : 0.0f);
      v.albedo = (float4)(VEC8_GET(albedo, l), rsqrt(fmax(fabs(LANE_F(ng_wo, l)), PSF_FOOTPRINT_MIN_COS)));
      v.alpha = (float4)(VEC8_GET(ln.beta, l), 0.0f);
      vertices[LANE_U(ln.path, l)] = v;
    }

    /* Paths that go on: the next ray from the point, off the surface on the
     * side wi leaves on; the others end, and their lanes take the next paths. */
    ln.beta = vec8_select(ln.beta, beta, go);
    ln.bsdf_pdf = select(ln.bsdf_pdf, pdf, go);
    ln.prev = vec8_select(ln.prev, pos, go);
    ln.flags = select(ln.flags, ln.flags & ~(PSF_PATH_SPECULAR | PSF_PATH_NULL_CROSSED), as_uint8(go));
    ln.flags = select(ln.flags, ln.flags | PSF_PATH_SPECULAR, as_uint8(go & delta_lobe));
    ln.org = vec8_select(ln.org, offset_origin8(pos, vec8_select(vec8_neg(ng), ng, vec8_dot(wi, ng) >= 0.0f)), go);
    ln.dir = vec8_select(ln.dir, wi, go);
    ln.tmin = select(ln.tmin, (float8)(0.0f), go);
    ln.tmax = select(ln.tmax, (float8)(INFINITY), go);
    ln.depth = select(ln.depth, ln.depth + 1u, as_uint8(go));
    const int8 ends = ln.live & ~go;
    ln.flags = select(ln.flags, ln.flags & ~PSF_PATH_ALIVE, as_uint8(ends));
    for (uint todo = psf_lanes8(ends); todo != 0u; todo &= todo - 1u) {
      const uint l = bvh_first_lane(todo);
      lanes_store(&ln, l, LANE_I(visible, l) ? (float3)(0.0f) : VEC8_GET(pending, l), states, vertices, store,
                  contrib_unfiltered, values);
    }
    ln.live &= ~ends;
    lanes_refill(&ln, ends, &next, end, &params, &camera, sobol, &cam);
  }
}

/* LanesBsdfs' evaluation for tests/test_bsdf.cpp: queries k = 8 g .. 8 g + 7
 * of work-item g (material mat[k], local wo[k] and wi[k] in the frame x, y,
 * z): f (xyz) and pdf (w) as trace_lanes evaluates a light sample, with the
 * diffuse BSDF the vectors' own; w = -1 where the lane's material is none of
 * the kinds the vectors shade. */
__kernel void lanes_test_eval(__global const Material* materials, __global const TextureInfo* textures,
                              __global const half* texels, __global const uint* mat, __global const float4* wo,
                              __global const float4* wi, __global float4* f_pdf, uint count) {
  const uint k0 = get_global_id(0) * PSF_LANES;
  if (k0 >= count) return;
  Material mats[PSF_LANES];
  LanesBsdfs b = {0};
  const Vec8 zero = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
  Vec8 o = zero, i = zero, albedo = zero;
  int8 valid = (int8)(0);
  for (uint l = 0u; l < PSF_LANES; ++l) {
    if (k0 + l >= count) continue;
    mats[l] = materials[mat[k0 + l]];
    LANE_I(valid, l) = -1;
    vec8_set(&o, l, wo[k0 + l].xyz);
    vec8_set(&i, l, wi[k0 + l].xyz);
    vec8_set(&albedo, l, bsdf_albedo(mats[l]));
    lanes_bsdfs_set(&b, l, &mats[l], textures, texels, LANE_F(o.z, l));
  }
  const int8 on = (o.z > 0.0f) & (i.z > 0.0f);
  Vec8 f = vec8_select(zero, vec8_scale(albedo, PSF_INV_PI), on);
  float8 pdf = select((float8)(0.0f), i.z * PSF_INV_PI, on);
  lanes_bsdfs_eval(&b, mats, o, i, valid, &f, &pdf);
  const int8 shaded = lanes_bsdfs_mask(&b);
  for (uint l = 0u; l < PSF_LANES && k0 + l < count; ++l)
    f_pdf[k0 + l] = LANE_I(shaded, l) ? (float4)(VEC8_GET(f, l), LANE_F(pdf, l)) : (float4)(0.0f, 0.0f, 0.0f, -1.0f);
}

/* Tests (tests/test_raycast.cpp): the flat casts of eight rays a work-item
 * over all `pack_count` packs (spheres: whether sphere packs are among them;
 * boxes: skipping the leaves of the root `nodes` whose boxes no ray meets,
 * where flat_root_leaves allows, as trace_lanes does), into closest as
 * flat_closest8 gives them and into any the closest hit where flat_any8 finds
 * the ray blocked (prim PSF_NO_HIT - 1 where the closest cast found nothing),
 * a miss (t = tmax) where it does not. */
__kernel void lanes_test_casts(__global const BvhTriPack* packs, uint pack_count, uint spheres,
                               __global const BvhNode* nodes, uint boxes, __global const Ray* rays,
                               __global Hit* closest, __global Hit* any, uint count) {
  const uint k0 = get_global_id(0) * PSF_LANES;
  if (k0 >= count) return;
  const Vec8 zero = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
  Vec8 org = zero, dir = zero;
  float8 tmin = (float8)(0.0f), tmax = (float8)(0.0f);
  int8 valid = (int8)(0);
  for (uint l = 0u; l < PSF_LANES && k0 + l < count; ++l) {
    const Ray r = rays[k0 + l];
    vec8_set(&org, l, r.org.xyz);
    vec8_set(&dir, l, r.dir.xyz);
    LANE_F(tmin, l) = r.org.w;
    LANE_F(tmax, l) = r.dir.w;
    LANE_I(valid, l) = -1;
  }
  float8 t, u, v;
  uint8 prim;
  __global const BvhNode* root = boxes && flat_root_leaves(nodes, pack_count) ? nodes : 0;
  flat_closest8(packs, pack_count, root, spheres != 0u, org, dir, tmin, tmax, valid, &t, &prim, &u, &v);
  const int8 blocked = flat_any8(packs, pack_count, root, spheres != 0u, org, dir, tmin, tmax, valid);
  for (uint l = 0u; l < PSF_LANES && k0 + l < count; ++l) {
    Hit h;
    h.t = LANE_F(t, l);
    h.prim = LANE_U(prim, l);
    h.u = LANE_F(u, l);
    h.v = LANE_F(v, l);
    closest[k0 + l] = h;
    if (!LANE_I(blocked, l)) {
      h.t = LANE_F(tmax, l);
      h.prim = PSF_NO_HIT;
      h.u = h.v = 0.0f;
    } else if (h.prim == PSF_NO_HIT) {
      h.prim = PSF_NO_HIT - 1u;
    }
    any[k0 + l] = h;
  }
}

/* Tests (tests/test_bsdf.cpp): lanes_bsdfs_sample for queries k of
 * bsdf_test_sample's arguments (material mat[k], local wo[k], (u1, u2, uc) =
 * u[k].xyz), eight a work-item, in the local frame: wi (xyz) and pdf (w),
 * weight (xyz) and 1 where a delta lobe was chosen, else 0 (w); w = -1 where
 * the lane's material is none of the kinds the vectors sample (the diffuse
 * kind's lanes take the kernel's own cosine sample). */
__kernel void lanes_test_sample(__global const Material* materials, __global const TextureInfo* textures,
                                __global const half* texels, __global const uint* mat, __global const float4* wo,
                                __global const float4* u, __global float4* wi_pdf, __global float4* weight_flags,
                                uint count) {
  const uint k0 = get_global_id(0) * PSF_LANES;
  if (k0 >= count) return;
  Material mats[PSF_LANES];
  LanesBsdfs b = {0};
  const Vec8 zero = vec8((float8)(0.0f), (float8)(0.0f), (float8)(0.0f));
  Vec8 o = zero;
  float8 u1 = (float8)(0.0f), u2 = (float8)(0.0f), uc = (float8)(0.0f);
  int8 valid = (int8)(0);
  for (uint l = 0u; l < PSF_LANES; ++l) {
    if (k0 + l >= count) continue;
    mats[l] = materials[mat[k0 + l]];
    LANE_I(valid, l) = -1;
    vec8_set(&o, l, wo[k0 + l].xyz);
    const float4 r = u[k0 + l];
    LANE_F(u1, l) = r.x;
    LANE_F(u2, l) = r.y;
    LANE_F(uc, l) = r.z;
    lanes_bsdfs_set(&b, l, &mats[l], textures, texels, LANE_F(o.z, l));
  }
  const Vec8 fs = vec8((float8)(1.0f), (float8)(0.0f), (float8)(0.0f));
  const Vec8 ft = vec8((float8)(0.0f), (float8)(1.0f), (float8)(0.0f));
  const Vec8 fn = vec8((float8)(0.0f), (float8)(0.0f), (float8)(1.0f));
  const int8 sampled = valid & lanes_bsdfs_mask(&b) & ~b.diffuse;
  Vec8 wi = o, weight = zero;
  float8 pdf = (float8)(0.0f);
  int8 delta = (int8)(0);
  lanes_bsdfs_sample(&b, mats, sampled, &fs, &ft, &fn, &o, o.z, cosine_hemisphere8(u1, u2), u1, u2, uc, &wi, &pdf,
                     &weight, &delta);
  for (uint l = 0u; l < PSF_LANES && k0 + l < count; ++l) {
    const bool s = LANE_I(sampled, l) != 0;
    wi_pdf[k0 + l] = s ? (float4)(VEC8_GET(wi, l), LANE_F(pdf, l)) : (float4)(0.0f);
    weight_flags[k0 + l] = s ? (float4)(VEC8_GET(weight, l), LANE_I(delta, l) ? 1.0f : 0.0f)
                             : (float4)(0.0f, 0.0f, 0.0f, -1.0f);
  }
}
