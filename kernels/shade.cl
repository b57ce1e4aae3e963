/* shade.cl: the surface interaction stage of the wavefront path tracer:
 * unidirectional path tracing with next-event estimation and multiple importance
 * sampling (Veach 1997, Sec. 9.2, power heuristic), Russian roulette, and the
 * record of each path's filtering vertex (Keller et al. 2016, Sec. 2).
 *
 * The wavefront is compacted: a launch covers the `count` live paths of queue_in
 * (path indices; work-item k owns slot k of rays_in, hits and shadow_rays), and
 * shade appends each path that goes on to queue_out and rays_out. Path states and
 * filtering vertices are indexed by path.
 *
 * shade: reads each path's closest hit; adds emission reached by the BSDF-sampled
 * ray (MIS-weighted against light sampling), or for a ray that escaped the scene
 * the environment's radiance (likewise weighted, emitter.cl); at the first
 * sufficiently diffuse vertex writes the PathVertex (x, n, albedo, alpha, d) and from there on gathers
 * the path's radiance into c = vertex_radiance relative to alpha, so that the
 * pixel gets radiance + alpha * c; samples a light (shadow ray + pending
 * contribution) and the BSDF (next ray). Depth follows Mitsuba's max_depth: the
 * number of path segments, so max_depth 1 shows emitters only and 2 adds direct light.
 * shade_env_samples, shade_env_blocks, shade_env_cells and shade_env_texels
 * (before shade, for scenes lit by an environment map): draw each live path's
 * light choice and, where it is the environment, the row of the map, then the
 * block of the row, then the texel, direction and pdf, then read the map's
 * radiance there (four texels, bilinear). This is the part of next-event
 * estimation that does not depend on the shading point, and the one that waits
 * on memory: the row's block guide and block cdf, a block's texel cdf, then
 * texels, all at random. In short kernels of their own each is prefetched for
 * the path 16 slots on (on CPUs; program.cl psf_prefetch), so that the waits of
 * many paths overlap (PoCL, living room at 2 spp: the kernels but the first
 * 0.80-0.85 s of device time where the two without prefetches took 1.16-1.26 s).
 * shade itself prefetches only what it can address cheaply ahead of time: the
 * hit triangle, the path's state and the colour texture's texels (16 and 8
 * slots on).
 * cast_shadows_media (scenes with a medium behind a null boundary, in place of
 * raycast.cl's any-hit cast): shadow rays that pass null boundaries and carry
 * the transmittance of the media they cross.
 * shade_shadows: adds the pending contribution of unoccluded shadow rays and
 * records the filtering vertex's light-sample visibility: 0 where something
 * blocked a sample that would have lit it, else 1, so that samples behind the
 * surface do not split a lit surface's vertices (visibility.cl may replace it by
 * a hemisphere ray's).
 * trace_paths (CPU devices, and the wavefront's tail on GPUs): all of the above
 * for one path per work-item, bounce after bounce, from the same inline functions
 * (env_row_slot, env_block_slot, env_cell_slot, env_texel_slot, shade_path, shadow_slot). */

#define PSF_RAY_EPS 1e-4f

inline float max3(float3 v) { return fmax(v.x, fmax(v.y, v.z)); }

inline float power_heuristic(float a, float b) {
  float a2 = a * a, b2 = b * b;
  return (a2 + b2) > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

/* The dimensions of this bounce of path `st` (PSF_DIMS_PER_BOUNCE of them, and
 * the next bounce's first), drawn together; key = pixel_seed(seed, st.pixel). */
inline float8 bounce_samples(FrameParams params, __global const uint* sobol, uint key, PathState st) {
  return sample_8d_keyed(sobol, key, st.sample, params.dim_bounce0 + PSF_DIMS_PER_BOUNCE * st.depth);
}

/* Dimension `offset` (PSF_DIM_*) of a bounce's samples. */
inline float bounce_sample(float8 u, uint offset) {
  float a[8];
  vstore8(u, 0, a);
  return a[offset];
}

/* The record for slot k, PSF_ENV_RECORD float4s from env_samples[3k]: [3k] =
 * (wi, pdf), [3k + 1] = (radiance, 1 if the environment was chosen, else 0),
 * drawn in four steps (emitter.cl): env_row_slot chooses the light and, where
 * it is the environment, the row of the map, and leaves env_sample_row's
 * record, [3k] = (u1, fv, row_p, 0) and [3k + 1] = (y, 0, selection
 * probability, 1); env_block_slot finds the block, [3k] = (ub, fv, row_p,
 * block_p) and [3k + 1] = (y, b, selection probability, 1); env_cell_slot turns
 * that into the direction and pdf, with the sample's map coordinates (u, v) in
 * place of the radiance; env_texel_slot reads the radiance there. [3k + 2]
 * holds what the steps after read, for the kernels' prefetches: z and w the
 * row's block guide entry and block cdf (offsets in the map's data, written by
 * env_row_slot), x the block's texel cdf (by env_block_slot), y the first texel
 * env_lookup reads (by env_cell_slot); each kernel reads the words of slots
 * further on that a kernel before wrote, and writes another. */
inline void env_row_slot(uint k, uint j, FrameParams params, __global const uint* sobol,
                         __global const Emitter* emitters, __global const float* emitter_cdf, Environment env,
                         __global const float* env_data, __global const PathState* states,
                         __global float4* env_samples) {
  float4 a = (float4)(0.0f), b = (float4)(0.0f);
  uint guide = 0u, blocks = 0u;
  if (params.num_emitters > 0u) {
    /* The bounce's dimensions drawn together, as shade_path draws them (one
     * pass over the index's bits for all, where three draws of one each took
     * three). */
    PathState st = states[j];
    float8 u = bounce_samples(params, sobol, pixel_seed(params.seed, st.pixel), st);
    float ul = bounce_sample(u, PSF_DIM_LIGHT_SELECT);
    Emitter em = emitters[sample_cdf_guided(emitter_cdf, params.num_emitters, emitter_cdf + params.num_emitters, ul)];
    if (em.type == PSF_EMITTER_ENVIRONMENT) {
      uint y;
      a = env_sample_row(env, env_data, bounce_sample(u, PSF_DIM_LIGHT_UV), bounce_sample(u, PSF_DIM_LIGHT_UV + 1u),
                         &y);
      b = (float4)(as_float(y), 0.0f, em.radiance.w, 1.0f);
      guide = env_block_guide_at(env, y, a.x);
      blocks = env_block_cdf_at(env, y);
    }
  }
  env_samples[PSF_ENV_RECORD * k] = a;
  env_samples[PSF_ENV_RECORD * k + 1u] = b;
  env_samples[PSF_ENV_RECORD * k + 2u] = (float4)(0.0f, 0.0f, as_float(guide), as_float(blocks));
}

/* The words of slot k's record [3k + 2] (env_row_slot). */
inline __global uint* env_ahead(__global float4* env_samples, uint k) {
  return (__global uint*)(env_samples + PSF_ENV_RECORD * k + 2u);
}

inline void env_block_slot(uint k, Environment env, __global const float* env_data, __global float4* env_samples) {
  float4 b = env_samples[PSF_ENV_RECORD * k + 1u];
  if (b.w == 0.0f) return;
  uint y = as_uint(b.x), blk;
  env_samples[PSF_ENV_RECORD * k] = env_sample_block(env, env_data, env_samples[PSF_ENV_RECORD * k], y, &blk);
  env_samples[PSF_ENV_RECORD * k + 1u] = (float4)(b.x, as_float(blk), b.z, 1.0f);
  env_ahead(env_samples, k)[0] = (uint)env_texel_cdf_offset(env, y, blk);
}

inline void env_cell_slot(uint k, Environment env, __global const float* env_data, __global float4* env_samples) {
  float4 b = env_samples[PSF_ENV_RECORD * k + 1u];
  if (b.w == 0.0f) return;
  float pdf;
  float2 uv;
  float3 wi = env_sample_cell(env, env_data, env_samples[PSF_ENV_RECORD * k], (uint2)(as_uint(b.x), as_uint(b.y)),
                              &pdf, &uv);
  env_samples[PSF_ENV_RECORD * k] = (float4)(wi, pdf > 0.0f ? b.z * pdf : 0.0f);
  env_samples[PSF_ENV_RECORD * k + 1u] = (float4)(uv, 0.0f, 1.0f);
  float2 t;
  uint4 c = env_bilinear(env, uv, &t);
  env_ahead(env_samples, k)[1] = 3u * (c.z * env.width + c.x);
}

inline void env_texel_slot(uint k, Environment env, __global const float* env_data, __global float4* env_samples) {
  float4 b = env_samples[PSF_ENV_RECORD * k + 1u];
  if (b.w == 0.0f) return;
  float3 radiance = env_lookup(env, env_data, b.xy) * env.scale.xyz;
  env_samples[PSF_ENV_RECORD * k + 1u] = (float4)(radiance, 1.0f);
}

/* The state of the path in slot k + PSF_PREFETCH_AHEAD (its two cache lines; the
 * paths' states are read in queue order, at random after the first bounce). */
inline void prefetch_state_ahead(__global const PathState* states, __global const uint* queue_in, uint k,
                                 uint count) {
  if (PSF_PREFETCH && k + PSF_PREFETCH_AHEAD < count) {
    __global const PathState* ahead = states + queue_in[k + PSF_PREFETCH_AHEAD];
    psf_prefetch(ahead);
    psf_prefetch((__global const float4*)ahead + 5);
  }
}

/* For shade: the hit triangle's positions, attributes and material index of
 * the slot PSF_PREFETCH_AHEAD on (random reads into arrays of the whole scene,
 * which shade_path otherwise waits on in turn; PoCL, living room: the
 * positions' load alone was a seventh of its samples), and half as far on,
 * where those have arrived, texels x and x + 1 of both rows its colour
 * texture's bilinear lookup reads (texture.cl texture_eval). */
inline void prefetch_hit_ahead(FrameParams params, __global const float4* tri_pos, __global const uint* tri_material,
                               __global const Material* materials, __global const Hit* hits,
                               __global const TriAttrib* tri_attribs, __global const TextureInfo* textures,
                               __global const half* texels, uint k, uint count) {
  if (!PSF_PREFETCH) return;
  if (k + PSF_PREFETCH_AHEAD < count) {
    const uint prim = hits[k + PSF_PREFETCH_AHEAD].prim;
    if (prim != PSF_NO_HIT) {
      psf_prefetch(tri_pos + 3u * prim);
      psf_prefetch(tri_pos + 3u * prim + 2u);
      psf_prefetch(tri_attribs + prim);
      psf_prefetch((__global const float4*)(tri_attribs + prim) + 5);
      psf_prefetch(tri_material + prim);
    }
  }
  if (k + PSF_PREFETCH_AHEAD / 2u < count) {
    const Hit h = hits[k + PSF_PREFETCH_AHEAD / 2u];
    if (h.prim >= params.first_sphere) return; /* a sphere, or PSF_NO_HIT (above every prim) */
    const uint tex = materials[tri_material[h.prim]].tex_color;
    if (tex != PSF_NO_TEXTURE) texture_prefetch(textures, texels, tex, surface_uv(tri_attribs + h.prim, h.u, h.v));
  }
}

__kernel void shade_env_samples(FrameParams params, __global const uint* sobol, __global const Emitter* emitters,
                                __global const float* emitter_cdf, Environment env, __global const float* env_data,
                                uint count, __global const uint* queue_in, __global const PathState* states,
                                __global float4* env_samples) {
  uint k = get_global_id(0);
  if (k >= count) return;
  prefetch_state_ahead(states, queue_in, k, count);
  env_row_slot(k, queue_in[k], params, sobol, emitters, emitter_cdf, env, env_data, states, env_samples);
}

__kernel void shade_env_blocks(Environment env, __global const float* env_data, uint count,
                               __global float4* env_samples) {
  uint k = get_global_id(0);
  if (k >= count) return;
  if (PSF_PREFETCH) { /* two steps ahead: the guide entry, then (once it is in) the block cdf it points to */
    if (k + 2u * PSF_PREFETCH_AHEAD < count)
      psf_prefetch(env_data + env_ahead(env_samples, k + 2u * PSF_PREFETCH_AHEAD)[2]);
    if (k + PSF_PREFETCH_AHEAD < count) {
      __global const uint* w = env_ahead(env_samples, k + PSF_PREFETCH_AHEAD);
      uint blocks = w[3];
      if (blocks != 0u) psf_prefetch(env_data + blocks + as_uint(env_data[w[2]]));
    }
  }
  env_block_slot(k, env, env_data, env_samples);
}

__kernel void shade_env_cells(Environment env, __global const float* env_data, uint count,
                              __global float4* env_samples) {
  uint k = get_global_id(0);
  if (k >= count) return;
  if (PSF_PREFETCH && k + PSF_PREFETCH_AHEAD < count)
    psf_prefetch(env_data + env_ahead(env_samples, k + PSF_PREFETCH_AHEAD)[0]);
  env_cell_slot(k, env, env_data, env_samples);
}

__kernel void shade_env_texels(Environment env, __global const float* env_data, uint count,
                               __global float4* env_samples) {
  uint k = get_global_id(0);
  if (k >= count) return;
  if (PSF_PREFETCH && k + PSF_PREFETCH_AHEAD < count) {
    /* Two texels of 12 bytes in each of two rows: their 24 bytes cross a cache
     * line's end five times in sixteen. */
    __global const float* texel = env_data + env_ahead(env_samples, k + PSF_PREFETCH_AHEAD)[1];
    psf_prefetch(texel);
    psf_prefetch(texel + 5);
    psf_prefetch(texel + 3u * env.width); /* the next row */
    psf_prefetch(texel + 3u * env.width + 5u);
  }
  env_texel_slot(k, env, env_data, env_samples);
}

/* True if a path with `segments` segments is allowed by max_depth. */
inline bool depth_allows(FrameParams p, uint segments) { return (int)p.max_depth < 0 || segments <= p.max_depth; }

/* Adds a contribution to the prefix or, past the filtering vertex, to c. */
inline void add_radiance(PathState* st, float3 c) {
  if (st->flags & PSF_PATH_VERTEX) {
    st->vertex_radiance.xyz += c;
  } else {
    st->radiance.xyz += c;
    st->radiance.w = 1.0f; /* more than the camera ray's emission (add_radiance_seen) */
  }
}

/* The emission the camera ray adds where it hits a light or escapes: while
 * radiance.w stays 0, radiance.xyz is exactly that (throughput and MIS weight 1),
 * which emission.cl takes instead of casting the ray again. */
inline void add_radiance_seen(PathState* st, float3 c) {
  if (st->depth == 0u && !(st->flags & (PSF_PATH_VERTEX | PSF_PATH_NULL_CROSSED))) st->radiance.xyz += c;
  else add_radiance(st, c);
}

/* The medium (PathState.flags' upper bits) of a path that leaves a surface on
 * its front (geometric normal's) side or its back: a surface with an interior
 * medium (Material.interior) or an exterior one (Material.exterior) leads into
 * the exterior on the front and into the interior on the back (either may be
 * none), as Mitsuba's medium transitions; any other keeps the path's medium. */
inline uint medium_after(uint current, float4 interior, uint exterior, uint material, bool leaves_front) {
  if (!(interior.w > 0.0f) && exterior == 0u) return current;
  return leaves_front ? exterior : interior.w > 0.0f ? material + 1u : 0u;
}

/* The extinction sigma_t of medium `medium` (0 outside every medium). */
inline float3 medium_sigma(__global const Material* materials, uint medium) {
  return medium > 0u ? materials[medium - 1u].interior.xyz : (float3)(0.0f);
}

/* Transmittance exp(-sigma_t d) of `dist` through medium `medium` (1 outside
 * every medium; 0 over an infinite distance through one that absorbs). */
inline float3 medium_transmittance(__global const Material* materials, uint medium, float dist) {
  if (medium == 0u) return (float3)(1.0f);
  const float3 sigma = medium_sigma(materials, medium);
  return select(exp(-sigma * dist), (float3)(1.0f), sigma <= (float3)(0.0f));
}

/* The part of a light sample's transmittance that shading applies, over `dist`
 * from the medium it starts in: all of it, where the first boundary on the way
 * stops the sample; none where the scene has null boundaries (FrameParams.
 * null_media), which shadow rays pass: shadow_cast then finds it all. */
inline float3 shadow_transmittance(FrameParams params, __global const Material* materials, uint medium, float dist) {
  return params.null_media ? (float3)(1.0f) : medium_transmittance(materials, medium, dist);
}

/* Free-flight sampling in the medium the path is in over a segment of length
 * `dist` (INFINITY where the ray escapes). Returns the distance t < dist of a
 * scattering event, with the throughput weighted by sigma_s T(t) / p(t), or
 * `dist`, with it weighted by T(dist) / P(dist): spectral MIS over the three
 * channels, as Mitsuba 3's volpath in RGB (a channel chosen uniformly, t drawn
 * by its sigma_t, the pdfs the channels' mean). A medium that only absorbs has
 * no events: T(dist) exactly. The two numbers are hashes of the path and
 * bounce, as a blend's choice (surface.cl): Sobol dimensions of the bounce
 * would be correlated with the surface's, which it uses where there is no event. */
inline float medium_sample(__global const Material* materials, uint medium, float dist, uint key, PathState* st) {
  if (medium == 0u) return dist;
  const float3 sigma_t = materials[medium - 1u].interior.xyz;
  const float3 albedo = materials[medium - 1u].interior_albedo.xyz;
  if (!(max3(albedo) > 0.0f)) {
    st->throughput.xyz *= medium_transmittance(materials, medium, dist);
    return dist;
  }
  /* The path length so far tells this segment from others of the same depth
   * (a null boundary's crossing keeps the depth). */
  const uint h = psf_hash_combine(psf_hash_combine(psf_hash_combine(key, st->sample), st->depth),
                                  as_uint(st->prev_pos.w) ^ 0x6d656469u);
  const float u = bits_to_float(h), u2 = bits_to_float(psf_hash(h ^ 0x9e3779b9u));
  const int c = min((int)(u * 3.0f), 2);
  const float s = c == 0 ? sigma_t.x : c == 1 ? sigma_t.y : sigma_t.z;
  const float t = s > 0.0f ? -log1p(-u2) / s : INFINITY;
  if (t < dist) {
    const float3 tr = exp(-sigma_t * t);
    const float pdf = (sigma_t.x * tr.x + sigma_t.y * tr.y + sigma_t.z * tr.z) / 3.0f;
    st->throughput.xyz *= albedo * sigma_t * tr / pdf;
    return t;
  }
  const float3 tr = select(exp(-sigma_t * dist), (float3)(1.0f), sigma_t <= (float3)(0.0f));
  const float p = (tr.x + tr.y + tr.z) / 3.0f;
  st->throughput.xyz *= p > 0.0f ? tr / p : (float3)(0.0f);
  return dist;
}

/* A light sample's radiance times its emitter's emission texture at the
 * sampled point, where it has one. */
inline void light_sample_textured(LightSample* ls, __global const TriAttrib* tri_attribs,
                                  __global const TextureInfo* textures, __global const half* texels) {
  if (ls->tex != PSF_NO_TEXTURE && ls->pdf > 0.0f)
    ls->radiance *= texture_eval(textures, texels, ls->tex, surface_uv(tri_attribs + ls->prim, ls->b1, ls->b2)).xyz;
}

/* The light sample of slot k's bounce from `pos`: one point on one emitter,
 * chosen by power, with the bounce's light dimensions; the environment's drawn
 * ahead by shade_env_samples with the same numbers where it was presampled. */
inline LightSample next_event_sample(uint k, FrameParams params, __global const Emitter* emitters,
                                     __global const float* emitter_cdf, Environment env,
                                     __global const float* env_data, float3 pos, float8 samples,
                                     __global const TriAttrib* tri_attribs, __global const TextureInfo* textures,
                                     __global const half* texels, uint env_presampled,
                                     __global const float4* env_samples) {
  LightSample ls;
  if (env_presampled && env_samples[PSF_ENV_RECORD * k + 1u].w != 0.0f) {
    float4 a = env_samples[PSF_ENV_RECORD * k], b = env_samples[PSF_ENV_RECORD * k + 1u];
    ls.wi = a.xyz;
    ls.pdf = a.w;
    ls.radiance = b.xyz;
    ls.dist = INFINITY;
    ls.delta = 0u;
    return ls;
  }
  ls = emitter_sample(emitters, emitter_cdf, params.num_emitters, env, env_data, pos,
                      bounce_sample(samples, PSF_DIM_LIGHT_SELECT), bounce_sample(samples, PSF_DIM_LIGHT_UV),
                      bounce_sample(samples, PSF_DIM_LIGHT_UV + 1u));
  light_sample_textured(&ls, tri_attribs, textures, texels);
  return ls;
}

/* A ray origin off the surface, on the side of `n`. */
inline float3 offset_origin(float3 p, float3 n) { return p + n * PSF_RAY_EPS * fmax(1.0f, max3(fabs(p))); }

/* Shades slot k (path j = queue_in[k]): updates its state, writes its shadow ray,
 * and returns whether it goes on, with its next ray in *next. Inlined into
 * trace_paths, where the compiler then keeps what the bounce's stages hand each
 * other in registers (PoCL, Mitsuba's cbox: 3 % fewer instructions per path,
 * 5 % less time); called by shade (shade_path), where inlining it cost 4 %. */
PSF_FORCE_INLINE bool shade_path_inline(
    uint k, uint j, FrameParams params, __global const uint* sobol, __global const float4* tri_pos,
    __global const uint* tri_material, __global const Material* materials, __global const Emitter* emitters,
    __global const float* emitter_cdf, __global const float* tri_light_pdf, Environment env,
    __global const float* env_data, __global const Hit* hits, __global const Ray* rays_in, __global PathState* states,
    __global PathVertex* vertices, __global Ray* shadow_rays, __global const TriAttrib* tri_attribs,
    __global const TextureInfo* textures, __global const half* texels, uint env_presampled,
    __global const float4* env_samples, Ray* next) {
  PathState st = states[j];
  const uint key = pixel_seed(params.seed, st.pixel);  /* bounce_sample's */
  Ray shadow;
  shadow.org = (float4)(0.0f);
  shadow.dir = (float4)(0.0f, 0.0f, 1.0f, -1.0f);
  st.pending = (float4)(0.0f);
  st.flags &= ~PSF_PATH_VERTEX_NEW;
  Ray ray = rays_in[k];
  Hit hit = hits[k];
  const uint medium = st.flags >> PSF_PATH_MEDIUM_SHIFT;
  const float ray_len = length(ray.dir.xyz);
  const float segment = hit.prim == PSF_NO_HIT ? INFINITY : hit.t * ray_len;
  const float t_medium = medium_sample(materials, medium, segment, key, &st);
  if (t_medium < segment) {
    /* A scattering event in the medium: a light sample weighted by the phase
     * function and the transmittance up to the light (a dielectric boundary on
     * the way stops it, a null one it passes), then a direction from the phase
     * function, MIS-weighted against light samples where it hits an emitter. */
    const float3 d = ray.dir.xyz / ray_len, p = ray.org.xyz + d * t_medium;
    const uint segments = st.depth + 1u;
    bool go = depth_allows(params, segments + 1u);
    st.prev_pos.w += t_medium;
    if (go) {
      const float8 samples = bounce_samples(params, sobol, key, st);
      const float g = materials[medium - 1u].interior_albedo.w;
      float3 beta = st.throughput.xyz;
      if (params.num_emitters > 0u) {
        const LightSample ls = next_event_sample(k, params, emitters, emitter_cdf, env, env_data, p, samples,
                                                 tri_attribs, textures, texels, env_presampled, env_samples);
        if (ls.pdf > 0.0f) {
          const float f = henyey_greenstein(g, dot(d, ls.wi));
          const float w = ls.delta ? 1.0f : power_heuristic(ls.pdf, f);
          st.pending = (float4)(beta * f * ls.radiance * (w / ls.pdf) *
                                    shadow_transmittance(params, materials, medium, ls.dist),
                                as_float(medium));
          shadow.org = (float4)(p, 0.0f);
          shadow.dir = isinf(ls.dist) ? (float4)(ls.wi, INFINITY) : (float4)(ls.wi * ls.dist, 1.0f - PSF_RAY_EPS);
        }
      }
      if (segments >= params.rr_depth) { /* Russian roulette, as at a surface */
        const float q = fmin(max3(beta), 0.95f);
        if (bounce_sample(samples, PSF_DIM_RR) >= q) go = false;
        else beta /= q;
      }
      if (go) {
        const float3 wi = sample_henyey_greenstein(d, g, bounce_sample(samples, PSF_DIM_BSDF_UV),
                                                   bounce_sample(samples, PSF_DIM_BSDF_UV + 1u));
        ray.org = (float4)(p, 0.0f);
        ray.dir = (float4)(wi, INFINITY);
        st.throughput = (float4)(beta, henyey_greenstein(g, dot(d, wi)));
        st.prev_pos.xyz = p;
        st.flags &= ~(PSF_PATH_SPECULAR | PSF_PATH_NULL_CROSSED);
        st.depth += 1u;
        *next = ray;
      }
    }
    if (!go) st.flags &= ~PSF_PATH_ALIVE;
    shadow_rays[k] = shadow;
    states[j] = st;
    return go;
  }
  if (hit.prim == PSF_NO_HIT) {
    /* An escaped ray sees the environment, MIS-weighted against its light samples
     * unless it left the camera or a delta lobe (emitter.cl); through a medium
     * that absorbs, nothing (medium_sample). */
    if (env.present && !(st.depth == 0u && (params.hide & PSF_HIDE_ENVIRONMENT))) {
      float3 d = normalize(ray.dir.xyz);
      float w = 1.0f, pdf;
      bool mis = st.depth > 0u && !(st.flags & PSF_PATH_SPECULAR);
      float3 radiance = env_radiance_pdf(env, env_data, d, mis ? &pdf : 0);
      if (mis) w = power_heuristic(st.throughput.w, env.scale.w * pdf);
      add_radiance_seen(&st, st.throughput.xyz * radiance * w);
    }
    st.flags &= ~PSF_PATH_ALIVE;
    shadow_rays[k] = shadow;
    states[j] = st;
    return false;
  }
  float3 wo = -ray.dir.xyz / ray_len;
  float3 pos = ray.org.xyz + hit.t * ray.dir.xyz;
  float3 p0, p1, p2, ng;
  if (hit.prim >= params.first_sphere) { /* an analytic sphere: its point, normal, uv and dp/du, dp/dv (surface.cl) */
    surface_sphere(tri_pos + 3u * hit.prim, pos, &ng, &hit.u, &hit.v, &p0, &p1, &p2);
  } else {
    p0 = tri_pos[3u * hit.prim].xyz;
    p1 = tri_pos[3u * hit.prim + 1u].xyz;
    p2 = tri_pos[3u * hit.prim + 2u].xyz;
    ng = cross(p1 - p0, p2 - p0);
    float area2 = length(ng);
    ng = area2 > 0.0f ? ng / area2 : (float3)(0.0f, 0.0f, 1.0f);
  }
  float dist = segment;
  st.prev_pos.w += dist;
  const uint hit_material = tri_material[hit.prim];
  Material m = materials[hit_material];
  const float4 interior = m.interior; /* the shape's media, whatever BSDF a blend picks */
  const uint exterior = m.exterior;
  bool front = dot(ng, wo) > 0.0f;
  float3 beta = st.throughput.xyz;

  /* Emission reached by the previous BSDF sample (or seen directly from the camera);
   * its light-sample pdf from the last scattering vertex, before any null boundary. */
  if (max3(m.emission.xyz) > 0.0f && (front || m.two_sided) && !(st.depth == 0u && (params.hide & PSF_HIDE_AREA))) {
    float w = 1.0f;
    if (st.depth > 0u && !(st.flags & PSF_PATH_SPECULAR) && params.num_emitters > 0u) {
      const float light_dist = (st.flags & PSF_PATH_NULL_CROSSED) ? distance(st.prev_pos.xyz, pos) : dist;
      w = power_heuristic(st.throughput.w,
                          hit.prim >= params.first_sphere
                              ? emitter_pdf_sphere(tri_light_pdf, hit.prim, tri_pos + 3u * hit.prim, m.two_sided,
                                                   st.prev_pos.xyz, light_dist, fabs(dot(ng, wo)))
                              : emitter_pdf_hit(tri_light_pdf, hit.prim, light_dist, fabs(dot(ng, wo))));
    }
    add_radiance_seen(&st, beta * surface_emission(m, tri_attribs + hit.prim, hit.u, hit.v, textures, texels) * w);
  }

  /* A blend's choice of BSDF (surface.cl), by a hash of the path and bounce (not a
   * Sobol dimension, so that the other dimensions keep their place); then the
   * shading frame (interpolated normal, bump map; turned towards wo if
   * two-sided) and the material's textures. */
  if (m.blend != 0u)
    m = surface_blend(m, materials, tri_attribs + hit.prim, hit.u, hit.v, textures, texels,
                      surface_blend_u(key, st.sample, st.depth), front);
  float3 n_unperturbed;
  Frame frame =
      surface_frame(&m, tri_attribs + hit.prim, hit.u, hit.v, p0, p1, p2, ng, wo, textures, texels, &n_unperturbed);
  float3 n = dot(frame.n, wo) >= 0.0f ? frame.n : -frame.n; /* shading normal on the camera side */
  __global const half* table = surface_table(m, textures, texels);
  uint segments = st.depth + 1u; /* segments of the path up to this vertex */
  /* A medium's null boundary (PSF_MATFLAG_NULL_BOUNDARY) lets the path through
   * without counting towards its depth or Russian roulette, as Mitsuba's null
   * interactions; its crossing draws no number (its Fresnel reflectance is 0),
   * so the next vertex may use the same dimensions, and it is no scattering
   * vertex: the MIS of an emitter hit further on refers to the vertex before. */
  const bool null_boundary = (m.flags & PSF_MATFLAG_NULL_BOUNDARY) != 0u;
  bool scatter = (null_boundary || depth_allows(params, segments + 1u)) && bsdf_scatters(m);

  /* The filtering vertex: the first diffuse one. From here on the throughput
   * and the gathered radiance are relative to it. */
  if (scatter && !(st.flags & PSF_PATH_VERTEX) && bsdf_is_diffuse(m)) {
    PathVertex v;
    v.position = (float4)(pos, st.prev_pos.w);
    v.normal = (float4)(n, 0.0f);
    v.albedo = (float4)(bsdf_albedo(m), rsqrt(fmax(fabs(dot(ng, wo)), PSF_FOOTPRINT_MIN_COS)));
    v.alpha = (float4)(beta, 0.0f);
    vertices[j] = v;
    st.flags |= PSF_PATH_VERTEX | PSF_PATH_VERTEX_NEW;
    beta = (float3)(1.0f);
  }

  const float8 samples = scatter ? bounce_samples(params, sobol, key, st) : (float8)(0.0f);

  /* Next-event estimation: one point on one emitter, chosen by power. */
  if (scatter && params.num_emitters > 0u) {
    const LightSample ls = next_event_sample(k, params, emitters, emitter_cdf, env, env_data, pos, samples,
                                             tri_attribs, textures, texels, env_presampled, env_samples);
    float bsdf_pdf;
    float3 f = ls.pdf > 0.0f && surface_side_agrees(&m, frame, n_unperturbed, ls.wi)
                   ? bsdf_eval(m, table, frame, wo, ls.wi, &bsdf_pdf)
                   : (float3)(0.0f);
    float cos_s = fabs(dot(frame.n, ls.wi)); /* the BSDF decides which side scatters */
    if (ls.pdf > 0.0f && cos_s > 0.0f && max3(f) > 0.0f) {
      float w = ls.delta ? 1.0f : power_heuristic(ls.pdf, bsdf_pdf); /* delta lights: no MIS */
      const uint shadow_medium = medium_after(medium, interior, exterior, hit_material, dot(ls.wi, ng) >= 0.0f);
      st.pending = (float4)(beta * f * cos_s * ls.radiance * (w / ls.pdf) *
                                shadow_transmittance(params, materials, shadow_medium, ls.dist),
                            as_float(shadow_medium));
      shadow.org = (float4)(offset_origin(pos, dot(ls.wi, ng) >= 0.0f ? ng : -ng), 0.0f);
      if (isinf(ls.dist)) {
        shadow.dir = (float4)(ls.wi, INFINITY); /* directional light or environment */
      } else {
        float3 lp = pos + ls.wi * ls.dist;
        shadow.dir = (float4)(lp - shadow.org.xyz, 1.0f - PSF_RAY_EPS);
      }
    }
  }
  shadow_rays[k] = shadow;

  /* BSDF sampling for the next segment, then Russian roulette. */
  if (scatter) {
    BsdfSample bs = bsdf_sample(m, table, frame, wo, bounce_sample(samples, PSF_DIM_BSDF_UV),
                                bounce_sample(samples, PSF_DIM_BSDF_UV + 1u),
                                bsdf_chooses_lobe(m) ? bounce_sample(samples, PSF_DIM_BSDF_LOBE) : 0.5f);
    if (!surface_side_agrees(&m, frame, n_unperturbed, bs.wi)) bs.weight = (float3)(0.0f);
    beta *= bs.weight;
    if (segments >= params.rr_depth && !null_boundary) {
      /* Survival by the throughput since the filtering vertex: any probability
       * keeps the estimate unbiased, and this one does not depend on alpha. */
      float q = fmin(max3(beta), 0.95f);
      if (bounce_sample(samples, PSF_DIM_RR) >= q) scatter = false;
      else beta /= q;
    }
    if (scatter && max3(bs.weight) > 0.0f) {
      if (null_boundary) { /* the last scattering vertex's pdf, position and kind stay */
        st.throughput.xyz = beta;
        st.flags |= PSF_PATH_NULL_CROSSED;
      } else {
        st.throughput = (float4)(beta, bs.pdf);
        st.prev_pos.xyz = pos;
        st.flags &= ~(PSF_PATH_SPECULAR | PSF_PATH_NULL_CROSSED);
        if (bs.flags & BSDF_DELTA) st.flags |= PSF_PATH_SPECULAR;
      }
      float3 side = dot(bs.wi, ng) >= 0.0f ? ng : -ng; /* the geometric side wi leaves on */
      st.flags = (st.flags & ((1u << PSF_PATH_MEDIUM_SHIFT) - 1u)) |
                 (medium_after(medium, interior, exterior, hit_material, dot(bs.wi, ng) >= 0.0f)
                  << PSF_PATH_MEDIUM_SHIFT);
      ray.org = (float4)(offset_origin(pos, side), 0.0f);
      ray.dir = (float4)(bs.wi, INFINITY);
      st.depth += null_boundary ? 0u : 1u;
      *next = ray;
    } else {
      scatter = false;
    }
  }
  if (!scatter) st.flags &= ~PSF_PATH_ALIVE;
  states[j] = st;
  return scatter;
}

__attribute__((noinline)) bool shade_path(uint k, uint j, FrameParams params, __global const uint* sobol,
                                          __global const float4* tri_pos, __global const uint* tri_material,
                                          __global const Material* materials, __global const Emitter* emitters,
                                          __global const float* emitter_cdf, __global const float* tri_light_pdf,
                                          Environment env, __global const float* env_data, __global const Hit* hits,
                                          __global const Ray* rays_in, __global PathState* states,
                                          __global PathVertex* vertices, __global Ray* shadow_rays,
                                          __global const TriAttrib* tri_attribs, __global const TextureInfo* textures,
                                          __global const half* texels, uint env_presampled,
                                          __global const float4* env_samples, Ray* next) {
  return shade_path_inline(k, j, params, sobol, tri_pos, tri_material, materials, emitters, emitter_cdf, tri_light_pdf,
                           env, env_data, hits, rays_in, states, vertices, shadow_rays, tri_attribs, textures, texels,
                           env_presampled, env_samples, next);
}

/* Survivors are appended to queue_out and rays_out with one global atomic per
 * work-group: slots within the group from a local counter, the group's base from
 * alive_count (a global atomic per path contends for one cache line across every
 * core). Every work-item reaches the barriers, so the tail is masked, not
 * returned from. */
__kernel void shade(FrameParams params, __global const uint* sobol, __global const float4* tri_pos,
                    __global const uint* tri_material, __global const Material* materials,
                    __global const Emitter* emitters, __global const float* emitter_cdf,
                    __global const float* tri_light_pdf, Environment env, __global const float* env_data,
                    uint count, __global const uint* queue_in, __global const Hit* hits,
                    __global const Ray* rays_in, __global PathState* states, __global PathVertex* vertices,
                    __global Ray* shadow_rays, __global uint* alive_count, __global uint* queue_out,
                    __global Ray* rays_out, __global const TriAttrib* tri_attribs,
                    __global const TextureInfo* textures, __global const half* texels, uint env_presampled,
                    __global const float4* env_samples) {
  __local uint group_count, group_base;
  uint k = get_global_id(0), l = get_local_id(0);
  uint j = k < count ? queue_in[k] : 0u;
  prefetch_hit_ahead(params, tri_pos, tri_material, materials, hits, tri_attribs, textures, texels, k, count);
  prefetch_state_ahead(states, queue_in, k, count);
  Ray next;
  bool go = k < count && shade_path(k, j, params, sobol, tri_pos, tri_material, materials, emitters, emitter_cdf,
                                    tri_light_pdf, env, env_data, hits, rays_in, states, vertices, shadow_rays,
                                    tri_attribs, textures, texels, env_presampled, env_samples, &next);
  if (l == 0u) group_count = 0u;
  barrier(CLK_LOCAL_MEM_FENCE);
  uint slot = go ? atomic_inc(&group_count) : 0u;
  barrier(CLK_LOCAL_MEM_FENCE);
  if (l == 0u) group_base = group_count > 0u ? atomic_add(alive_count, group_count) : 0u;
  barrier(CLK_LOCAL_MEM_FENCE);
  if (go) {
    queue_out[group_base + slot] = j;
    rays_out[group_base + slot] = next;
  }
}

/* The shadow ray's verdict on slot k's light sample; with `media` (FrameParams.
 * null_media) its hit carries the transmittance of the media on the way
 * (shadow_cast). */
inline void shadow_slot(uint k, uint j, __global const Hit* shadow_hits, __global PathState* states,
                        __global PathVertex* vertices, uint media) {
  PathState st = states[j];
  const Hit h = shadow_hits[k];
  const bool contributes = max3(st.pending.xyz) > 0.0f, visible = h.prim == PSF_NO_HIT && contributes;
  if (st.flags & PSF_PATH_VERTEX_NEW) vertices[j].normal.w = visible || !contributes ? 1.0f : 0.0f;
  if (visible) {
    add_radiance(&st, media ? st.pending.xyz * (float3)(h.t, h.u, h.v) : st.pending.xyz);
    st.pending = (float4)(0.0f);
    states[j] = st;
  }
}

__kernel void shade_shadows(uint count, __global const uint* queue_in, __global const Hit* shadow_hits,
                            __global PathState* states, __global PathVertex* vertices, uint media) {
  uint k = get_global_id(0);
  if (k >= count) return;
  prefetch_state_ahead(states, queue_in, k, count);
  shadow_slot(k, queue_in[k], shadow_hits, states, vertices, media);
}

/* The any-hit cast of a light sample's shadow ray that starts in `medium`, in a
 * scene with null boundaries (FrameParams.null_media): it passes them, and a ray
 * nothing blocks returns in its hit's t, u and v the transmittance exp(-tau) of
 * the media along it. tau is summed over the stretches between its crossings in
 * order of distance, each through the medium the ray is in there, which each
 * crossing replaces as a path's does (medium_after, Mitsuba's medium
 * transitions), so that light samples see the media the paths see whatever the
 * scene declares. A crossing of the same material and side at the distance of
 * one counted before it (a ray through an edge two triangles share) counts
 * once. A ray to infinity that ends inside a medium (one not closed) is
 * absorbed. A ray with more crossings than the record holds is cast again from
 * the last one kept, as often as it takes. Out of line: trace_paths of scenes
 * without such media pays nothing for its code. */
__attribute__((noinline)) Hit shadow_cast(__global const BvhNode* nodes, __global const BvhTriPack* packs, Ray ray,
                                          AlphaScene as, uint medium) {
  NullCrossings c;
  c.count = 0u;
  c.dropped = 0u;
  as.crossings = &c;
  Hit hit = intersect_any_hit_alpha(nodes, packs, ray, &as);
  if (hit.prim != PSF_NO_HIT) return hit;
  const float len = length(ray.dir.xyz);
  float3 tau = (float3)(0.0f);
  float prev = 0.0f;
  for (uint first = 0u;;) {
    for (uint k = first; k < c.count; ++k) {
      const float t = c.t[k];
      bool again = false;
      for (uint q = k; q > 0u && c.t[q - 1u] >= t - 1e-5f * fabs(t); --q) again |= c.tag[q - 1u] == c.tag[k];
      if (again) continue;
      tau += medium_sigma(as.materials, medium) * ((t - prev) * len);
      prev = t;
      const uint material = c.tag[k] >> 1;
      __global const Material* m = as.materials + material;
      medium = medium_after(medium, m->interior, m->exterior, material, (c.tag[k] & 1u) == 0u);
    }
    if (c.dropped == 0u) break;
    /* More crossings than the record holds: the rest from another cast that
     * starts at the last one kept, whose record starts with that crossing (not
     * walked again), so that its twin across an edge still counts once. The
     * first cast found nothing opaque on the whole ray. */
    const float t_last = c.t[c.count - 1u];
    c.t[0] = t_last;
    c.tag[0] = c.tag[c.count - 1u];
    c.count = 1u;
    c.dropped = 0u;
    Ray rest = ray;
    rest.org.w = t_last;
    intersect_any_hit_alpha(nodes, packs, rest, &as);
    first = 1u;
  }
  const float3 sigma = medium_sigma(as.materials, medium);
  if (!isinf(ray.dir.w)) tau += sigma * ((ray.dir.w - prev) * len);
  else tau = select(tau, (float3)(INFINITY), sigma > (float3)(0.0f));
  const float3 tr = exp(-tau);
  hit.t = tr.x;
  hit.u = tr.y;
  hit.v = tr.z;
  return hit;
}

/* The wavefront's shadow rays in a scene with null boundaries (instead of
 * raycast_any_masked): shadow_cast from the medium each light sample starts in
 * (PathState.pending.w). */
__kernel void cast_shadows_media(__global const BvhNode* nodes, __global const BvhTriPack* packs, uint count,
                                 __global const uint* queue_in, __global const Ray* shadow_rays,
                                 __global Hit* shadow_hits, __global const PathState* states,
                                 __global const uint* tri_material, __global const Material* materials,
                                 __global const TriAttrib* attribs, __global const TextureInfo* textures,
                                 __global const half* texels) {
  uint k = get_global_id(0);
  if (k >= count) return;
  AlphaScene as = {tri_material, materials, attribs, textures, texels, 0};
  shadow_hits[k] = shadow_cast(nodes, packs, shadow_rays[k], as, as_uint(states[queue_in[k]].pending.w));
}

/* trace_paths: each path of queue[0, count) whole in one work-item, from the
 * bounce it is at, on slot k (its ray in rays[k]): the same stages as the wavefront
 * (closest hit, environment samples, shade, shadow ray, shadow test) in the same
 * order, so the result is the same, bit for bit. Two uses:
 * - CPU devices, the whole batch (queue: camera_rays' path order, from the camera): a
 *   path's state, rays and hits stay in the core's cache from one bounce to the
 *   next instead of streaming through memory at every bounce (on a GPU the paths'
 *   different lengths would idle most lanes);
 * - GPUs, the wavefront's last few live paths (its queue, the next bounce):
 *   one launch instead of a round of launches and a read of the live count per
 *   bounce while they die out (tens of bounces of a few thousand paths each).
 * Every buffer is its own (restrict): the compiler may then keep what one stage
 * stores for the next in registers (PoCL, cbox: 1 % fewer instructions). */
__kernel void trace_paths(FrameParams params, __global const uint* restrict sobol,
                          __global const float4* restrict tri_pos, __global const uint* restrict tri_material,
                          __global const Material* restrict materials, __global const Emitter* restrict emitters,
                          __global const float* restrict emitter_cdf, __global const float* restrict tri_light_pdf,
                          Environment env, __global const float* restrict env_data,
                          __global const BvhNode* restrict nodes, __global const BvhTriPack* restrict packs,
                          uint masked, __global Ray* restrict rays, __global Hit* restrict hits,
                          __global PathState* restrict states, __global PathVertex* restrict vertices,
                          __global Ray* restrict shadow_rays, __global Hit* restrict shadow_hits,
                          __global const TriAttrib* restrict tri_attribs, __global const TextureInfo* restrict textures,
                          __global const half* restrict texels, uint env_presampled,
                          __global float4* restrict env_samples, uint count,
                          __global const uint* restrict queue) {
  uint k = get_global_id(0);
  if (k >= count) return;
  uint j = queue[k];
  AlphaScene as = {tri_material, materials, tri_attribs, textures, texels, 0};
  const AlphaScene* alpha = masked ? &as : 0;
  /* Until the path ends: shade_path_inline ends it at the maximum depth, before
   * max_rounds (unbounded where a medium's null boundary, crossed without
   * counting, can make the rounds outnumber the depth). */
  for (uint round = 0u; (int)params.max_rounds < 0 || round < params.max_rounds; ++round) {
    hits[k] = intersect_closest_alpha(nodes, packs, rays[k], alpha);
    if (env_presampled) {
      env_row_slot(k, j, params, sobol, emitters, emitter_cdf, env, env_data, states, env_samples);
      env_block_slot(k, env, env_data, env_samples);
      env_cell_slot(k, env, env_data, env_samples);
      env_texel_slot(k, env, env_data, env_samples);
    }
    Ray next;
    bool go = shade_path_inline(k, j, params, sobol, tri_pos, tri_material, materials, emitters, emitter_cdf,
                                tri_light_pdf, env, env_data, hits, rays, states, vertices, shadow_rays, tri_attribs,
                                textures, texels, env_presampled, env_samples, &next);
    shadow_hits[k] = params.null_media ? shadow_cast(nodes, packs, shadow_rays[k], as, as_uint(states[j].pending.w))
                                       : intersect_any_hit_alpha(nodes, packs, shadow_rays[k], alpha);
    shadow_slot(k, j, shadow_hits, states, vertices, params.null_media);
    if (!go) break;
    rays[k] = next;
  }
}
