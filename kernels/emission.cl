/* emission.cl: the emission the camera sees directly, from more camera rays
 * (--emission-rays K; host/render.cpp, after the paths are traced).
 *
 * A path's first segment adds the emission of what its camera ray hits (a light,
 * or the sky where it escapes), a function of where in the pixel the ray starts.
 * Where a pixel sees the edge of a light or a window, a few samples either see
 * the light or not, and that noise is the same filtered or not: path space
 * filtering averages only what leaves the filtering vertex. (The Cornell box at
 * 3 spp, 16 passes: the ~100 pixels along its light's edge held half the
 * filtered image's relMSE.)
 *
 * So each path also casts K more camera rays that only look up the emission
 * they hit, and its contribution gains
 *
 *   delta = (Le(ray_0) + ... + Le(ray_K)) / (K + 1) - Le(ray_0),
 *
 * ray_0 its own camera ray and ray_1..K drawn from the pixel filter by another
 * scrambling of the same Sobol dimensions, at indices sample K + m - 1 (a
 * pixel's spp K extra rays are one stratified sequence). Le is the emission of
 * what a ray hits as shade.cl finds it at depth 0: front faces (or two-sided
 * emitters), the emission texture, Mitsuba's hide_emitters (PSF_HIDE_*), the
 * environment where it escapes. Every ray_m has the distribution of ray_0, so
 * E[delta] = 0: the render stays unbiased, and where Le(ray_0) is the emission
 * the path added (not where a mask, a medium or a null boundary it passed made
 * it differ: there only the correlation is lost), the pixel's directly seen
 * emission is the mean of (K + 1) times as many rays. Le(ray_0) comes from the
 * path's state where that holds it exactly (emission_own), else from casting
 * ray_0 again. delta joins the path's radiance gathered before its filtering
 * vertex (accumulate.cl): the filtered and the unfiltered image alike. */

/* The scrambling key of the extra rays is the pixel's, hashed with this. */
#define PSF_EMISSION_KEY 0x656d6974u

/* Le of what `ray` hits first (shade.cl at depth 0). */
inline float3 emission_seen(FrameParams params, Ray ray, Hit hit, __global const float4* tri_pos,
                            __global const uint* tri_material, __global const Material* materials, Environment env,
                            __global const float* env_data, __global const TriAttrib* tri_attribs,
                            __global const TextureInfo* textures, __global const half* texels) {
  if (hit.prim == PSF_NO_HIT)
    return env.present && !(params.hide & PSF_HIDE_ENVIRONMENT) ? env_radiance(env, env_data, normalize(ray.dir.xyz))
                                                                : (float3)(0.0f);
  Material m = materials[tri_material[hit.prim]];
  if (!(max3(m.emission.xyz) > 0.0f) || (params.hide & PSF_HIDE_AREA)) return (float3)(0.0f);
  /* The front side as shade.cl finds it, bit for bit. */
  const float3 wo = -ray.dir.xyz / length(ray.dir.xyz);
  float3 ng;
  if (hit.prim >= params.first_sphere) {
    float3 p0, p1, p2;
    surface_sphere(tri_pos + 3u * hit.prim, ray.org.xyz + hit.t * ray.dir.xyz, &ng, &hit.u, &hit.v, &p0, &p1, &p2);
  } else {
    const float3 p0 = tri_pos[3u * hit.prim].xyz;
    ng = cross(tri_pos[3u * hit.prim + 1u].xyz - p0, tri_pos[3u * hit.prim + 2u].xyz - p0);
    const float area2 = length(ng);
    ng = area2 > 0.0f ? ng / area2 : (float3)(0.0f, 0.0f, 1.0f);
  }
  return dot(ng, wo) > 0.0f || m.two_sided
             ? surface_emission(m, tri_attribs + hit.prim, hit.u, hit.v, textures, texels)
             : (float3)(0.0f);
}

/* Ray 0, the path's own: -k / (k + 1) of its emission. Where radiance.w is 0
 * (shade.cl add_radiance_seen) radiance.xyz is that emission, bit for bit what
 * casting the ray again would find (emission_seen follows shade.cl; not where a
 * medium's null boundary may lie in front: use_trace 0); elsewhere the ray is
 * cast again here, for the few paths that need it. */
__kernel void emission_own(FrameParams params, Camera camera, __global const uint* sobol, uint k, uint use_trace,
                           __global const float4* tri_pos, __global const uint* tri_material,
                           __global const Material* materials, Environment env, __global const float* env_data,
                           __global const BvhNode* nodes, __global const BvhTriPack* packs, uint masked,
                           __global const TriAttrib* tri_attribs, __global const TextureInfo* textures,
                           __global const half* texels, __global PathState* states) {
  uint j = get_global_id(0);
  if (j >= params.batch_size) return;
  float4 radiance = states[j].radiance;
  float3 own = radiance.xyz;
  if (!use_trace || radiance.w != 0.0f) {
    uint sample, fx, fy;
    const uint key = pixel_seed(params.seed, camera_film_pixel(params, camera, j, &sample, &fx, &fy));
    const Ray ray = camera_ray(camera, fx, fy, sample_8d_keyed(sobol, key, sample, PSF_DIM_PIXEL));
    AlphaScene as = {tri_material, materials, tri_attribs, textures, texels, 0};
    const Hit hit = intersect_closest_alpha(nodes, packs, ray, masked ? &as : 0); /* as trace_paths casts */
    own = emission_seen(params, ray, hit, tri_pos, tri_material, materials, env, env_data, tri_attribs, textures,
                        texels);
  }
  if (max3(own) > 0.0f) {
    radiance.xyz += (-(float)k / (float)(k + 1u)) * own;
    states[j].radiance = radiance;
  }
}

/* Ray m >= 1 of path j into rays[j]. */
__kernel void emission_rays(FrameParams params, Camera camera, __global const uint* sobol, uint m, uint k,
                            __global Ray* rays) {
  uint j = get_global_id(0);
  if (j >= params.batch_size) return;
  uint sample, fx, fy;
  const uint key = pixel_seed(params.seed, camera_film_pixel(params, camera, j, &sample, &fx, &fy));
  rays[j] = camera_ray(camera, fx, fy,
                       sample_8d_keyed(sobol, psf_hash_combine(key, PSF_EMISSION_KEY), sample * k + (m - 1u),
                                       PSF_DIM_PIXEL));
}

/* Adds weight = 1 / (k + 1) times Le of each path's ray m (emission_rays, then
 * the caster's closest hits) to its radiance. (One kernel per path that
 * generated, cast and looked up all k + 1 rays took 1.4x as long on PoCL: its
 * loop ran one path at a time.) */
__kernel void emission_add(FrameParams params, float weight, __global const float4* tri_pos,
                           __global const uint* tri_material, __global const Material* materials, Environment env,
                           __global const float* env_data, __global const TriAttrib* tri_attribs,
                           __global const TextureInfo* textures, __global const half* texels,
                           __global const Ray* rays, __global const Hit* hits, __global PathState* states) {
  uint j = get_global_id(0);
  if (j >= params.batch_size) return;
  const float3 le = emission_seen(params, rays[j], hits[j], tri_pos, tri_material, materials, env, env_data,
                                  tri_attribs, textures, texels);
  if (max3(le) > 0.0f) {
    float4 radiance = states[j].radiance;
    radiance.xyz += weight * le;
    states[j].radiance = radiance;
  }
}
