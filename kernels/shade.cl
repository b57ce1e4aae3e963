/* shade.cl: the surface interaction stage of the wavefront path tracer:
 * unidirectional path tracing with next-event estimation and multiple importance
 * sampling (Veach 1997, Sec. 9.2, power heuristic), Russian roulette, and the
 * record of each path's filtering vertex (Keller et al. 2016, Sec. 2).
 *
 * shade: reads each path's closest hit; adds emission reached by the BSDF-sampled
 * ray (MIS-weighted against light sampling), or for a ray that escaped the scene
 * the environment's radiance (likewise weighted, emitter.cl); at the first
 * sufficiently diffuse vertex writes the PathVertex (x, n, albedo, alpha, d) and from there on gathers
 * the path's radiance into c = vertex_radiance relative to alpha, so that the
 * pixel gets radiance + alpha * c; samples a light (shadow ray + pending
 * contribution) and the BSDF (next ray). Depth follows Mitsuba's max_depth: the
 * number of path segments, so max_depth 1 shows emitters only and 2 adds direct light.
 * shade_shadows: adds the pending contribution of unoccluded shadow rays and
 * records the filtering vertex's light-sample visibility. */

#define PSF_RAY_EPS 1e-4f

inline float max3(float3 v) { return fmax(v.x, fmax(v.y, v.z)); }

inline float power_heuristic(float a, float b) {
  float a2 = a * a, b2 = b * b;
  return (a2 + b2) > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

inline float bounce_sample(__global const uint* sobol, FrameParams p, PathState st, uint offset) {
  return sample_1d(sobol, p.seed, st.pixel, st.sample, PSF_DIM_BOUNCE0 + PSF_DIMS_PER_BOUNCE * st.depth + offset);
}

/* True if a path with `segments` segments is allowed by max_depth. */
inline bool depth_allows(FrameParams p, uint segments) { return (int)p.max_depth < 0 || segments <= p.max_depth; }

/* Adds a contribution to the prefix or, past the filtering vertex, to c. */
inline void add_radiance(PathState* st, float3 c) {
  if (st->flags & PSF_PATH_VERTEX) st->vertex_radiance.xyz += c;
  else st->radiance.xyz += c;
}

/* A ray origin off the surface, on the side of `n`. */
inline float3 offset_origin(float3 p, float3 n) { return p + n * PSF_RAY_EPS * fmax(1.0f, max3(fabs(p))); }

__kernel void shade(FrameParams params, __global const uint* sobol, __global const float4* tri_pos,
                    __global const uint* tri_material, __global const Material* materials,
                    __global const Emitter* emitters, __global const float* emitter_cdf,
                    __global const float* tri_light_pdf, Environment env, __global const float* env_data,
                    __global const Hit* hits, __global Ray* rays,
                    __global PathState* states, __global PathVertex* vertices, __global Ray* shadow_rays,
                    __global uint* alive_count, __global const TriAttrib* tri_attribs,
                    __global const TextureInfo* textures, __global const half* texels) {
  uint j = get_global_id(0);
  if (j >= params.batch_size) return;
  PathState st = states[j];
  Ray shadow;
  shadow.org = (float4)(0.0f);
  shadow.dir = (float4)(0.0f, 0.0f, 1.0f, -1.0f);
  st.pending = (float4)(0.0f);
  st.flags &= ~PSF_PATH_VERTEX_NEW;
  Ray ray = rays[j];
  Hit hit = hits[j];
  if (!(st.flags & PSF_PATH_ALIVE) || hit.prim == PSF_NO_HIT) {
    /* An escaped ray sees the environment, MIS-weighted against its light samples
     * unless it left the camera or a delta lobe (emitter.cl). */
    if ((st.flags & PSF_PATH_ALIVE) && env.present) {
      float3 d = normalize(ray.dir.xyz);
      float w = 1.0f;
      if (st.depth > 0u && !(st.flags & PSF_PATH_SPECULAR))
        w = power_heuristic(st.throughput.w, env.scale.w * env_pdf(env, env_data, d));
      add_radiance(&st, st.throughput.xyz * env_radiance(env, env_data, d) * w);
    }
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
  float ray_len = length(ray.dir.xyz);
  float3 wo = -ray.dir.xyz / ray_len;
  float3 pos = ray.org.xyz + hit.t * ray.dir.xyz;
  float dist = hit.t * ray_len;
  st.prev_pos.w += dist;
  Material m = materials[tri_material[hit.prim]];
  bool front = dot(ng, wo) > 0.0f;
  float3 beta = st.throughput.xyz;

  /* Emission reached by the previous BSDF sample (or seen directly from the camera). */
  if (max3(m.emission.xyz) > 0.0f && (front || m.two_sided)) {
    float w = 1.0f;
    if (st.depth > 0u && !(st.flags & PSF_PATH_SPECULAR) && params.num_emitters > 0u)
      w = power_heuristic(st.throughput.w, emitter_pdf_hit(tri_light_pdf, hit.prim, dist, fabs(dot(ng, wo))));
    add_radiance(&st, beta * m.emission.xyz * w);
  }

  /* The shading frame (interpolated normal, bump map; turned towards wo if
   * two-sided) and the material's textures (surface.cl). */
  Frame frame = surface_frame(&m, tri_attribs + hit.prim, hit.u, hit.v, p0, p1, p2, ng, wo, textures, texels);
  float3 n = dot(frame.n, wo) >= 0.0f ? frame.n : -frame.n; /* shading normal on the camera side */
  __global const half* table = m.tex_table != PSF_NO_TEXTURE ? texels + 4u * textures[m.tex_table].offset : texels;
  uint segments = st.depth + 1u; /* segments of the path up to this vertex */
  bool scatter = depth_allows(params, segments + 1u) && bsdf_scatters(m);

  /* The filtering vertex: the first diffuse one. From here on the throughput
   * and the gathered radiance are relative to it. */
  if (scatter && !(st.flags & PSF_PATH_VERTEX) && bsdf_is_diffuse(m)) {
    PathVertex v;
    v.position = (float4)(pos, st.prev_pos.w);
    v.normal = (float4)(n, 0.0f);
    v.albedo = (float4)(bsdf_albedo(m), 1.0f);
    v.alpha = (float4)(beta, 0.0f);
    vertices[j] = v;
    st.flags |= PSF_PATH_VERTEX | PSF_PATH_VERTEX_NEW;
    beta = (float3)(1.0f);
  }

  /* Next-event estimation: one point on one emitter, chosen by power. */
  if (scatter && params.num_emitters > 0u) {
    LightSample ls = emitter_sample(emitters, emitter_cdf, params.num_emitters, env, env_data, pos,
                                    bounce_sample(sobol, params, st, PSF_DIM_LIGHT_SELECT),
                                    bounce_sample(sobol, params, st, PSF_DIM_LIGHT_UV),
                                    bounce_sample(sobol, params, st, PSF_DIM_LIGHT_UV + 1u));
    float bsdf_pdf;
    float3 f = ls.pdf > 0.0f ? bsdf_eval(m, table, frame, wo, ls.wi, &bsdf_pdf) : (float3)(0.0f);
    float cos_s = fabs(dot(frame.n, ls.wi)); /* the BSDF decides which side scatters */
    if (ls.pdf > 0.0f && cos_s > 0.0f && max3(f) > 0.0f) {
      float w = ls.delta ? 1.0f : power_heuristic(ls.pdf, bsdf_pdf); /* delta lights: no MIS */
      st.pending.xyz = beta * f * cos_s * ls.radiance * (w / ls.pdf);
      shadow.org = (float4)(offset_origin(pos, dot(ls.wi, ng) >= 0.0f ? ng : -ng), 0.0f);
      if (isinf(ls.dist)) {
        shadow.dir = (float4)(ls.wi, INFINITY); /* directional light or environment */
      } else {
        float3 lp = pos + ls.wi * ls.dist;
        shadow.dir = (float4)(lp - shadow.org.xyz, 1.0f - PSF_RAY_EPS);
      }
    }
  }
  shadow_rays[j] = shadow;

  /* BSDF sampling for the next segment, then Russian roulette. */
  if (scatter) {
    BsdfSample bs = bsdf_sample(m, table, frame, wo, bounce_sample(sobol, params, st, PSF_DIM_BSDF_UV),
                                bounce_sample(sobol, params, st, PSF_DIM_BSDF_UV + 1u),
                                bsdf_chooses_lobe(m) ? bounce_sample(sobol, params, st, PSF_DIM_BSDF_LOBE) : 0.5f);
    beta *= bs.weight;
    if (segments >= params.rr_depth) {
      /* Survival by the throughput since the filtering vertex: any probability
       * keeps the estimate unbiased, and this one does not depend on alpha. */
      float q = fmin(max3(beta), 0.95f);
      if (bounce_sample(sobol, params, st, PSF_DIM_RR) >= q) scatter = false;
      else beta /= q;
    }
    if (scatter && max3(bs.weight) > 0.0f) {
      st.throughput = (float4)(beta, bs.pdf);
      st.prev_pos.xyz = pos;
      if (bs.flags & BSDF_DELTA) st.flags |= PSF_PATH_SPECULAR;
      else st.flags &= ~PSF_PATH_SPECULAR;
      float3 side = dot(bs.wi, ng) >= 0.0f ? ng : -ng; /* the geometric side wi leaves on */
      ray.org = (float4)(offset_origin(pos, side), 0.0f);
      ray.dir = (float4)(bs.wi, INFINITY);
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

__kernel void shade_shadows(uint count, __global const Hit* shadow_hits, __global PathState* states,
                            __global PathVertex* vertices) {
  uint j = get_global_id(0);
  if (j >= count) return;
  PathState st = states[j];
  bool visible = shadow_hits[j].prim == PSF_NO_HIT && max3(st.pending.xyz) > 0.0f;
  if (st.flags & PSF_PATH_VERTEX_NEW) vertices[j].normal.w = visible ? 1.0f : 0.0f;
  if (visible) {
    add_radiance(&st, st.pending.xyz);
    st.pending = (float4)(0.0f);
    states[j] = st;
  }
}
