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
 * ray_0 its own camera ray (camera_ray with the same sample, cast again) and
 * ray_1..K drawn from the pixel filter by another scrambling of the same Sobol
 * dimensions, at indices sample K + m - 1: a pixel's (spp K) extra rays are one
 * stratified sequence. Every ray_m has the distribution of ray_0, so E[delta] =
 * 0 whatever Le is (a mask, a medium or a null boundary the path itself passed
 * only weakens the correlation): the render stays unbiased, and where Le(ray_0)
 * is the emission the path added, the pixel's directly seen emission is the mean
 * of (K + 1) times as many rays. delta joins the path's radiance gathered before
 * its filtering vertex (accumulate.cl): the filtered and the unfiltered image
 * alike. Le
 * follows shade.cl at depth 0: front faces (or two-sided emitters), the emission
 * texture, Mitsuba's hide_emitters (PSF_HIDE_*), the environment where a ray
 * escapes. */

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
  float3 ng;
  if (hit.prim >= params.first_sphere) {
    float3 p0, p1, p2;
    surface_sphere(tri_pos + 3u * hit.prim, ray.org.xyz + hit.t * ray.dir.xyz, &ng, &hit.u, &hit.v, &p0, &p1, &p2);
  } else {
    const float3 p0 = tri_pos[3u * hit.prim].xyz;
    ng = cross(tri_pos[3u * hit.prim + 1u].xyz - p0, tri_pos[3u * hit.prim + 2u].xyz - p0);
  }
  return dot(ng, ray.dir.xyz) < 0.0f || m.two_sided
             ? surface_emission(m, tri_attribs + hit.prim, hit.u, hit.v, textures, texels)
             : (float3)(0.0f);
}

/* Ray m of path j (0: its own camera ray, again) into rays[j]. */
__kernel void emission_rays(FrameParams params, Camera camera, __global const uint* sobol, uint m, uint k,
                            __global Ray* rays) {
  uint j = get_global_id(0);
  if (j >= params.batch_size) return;
  uint sample, fx, fy;
  uint key = pixel_seed(params.seed, camera_film_pixel(params, camera, j, &sample, &fx, &fy));
  uint index = sample;
  if (m > 0u) {
    key = psf_hash_combine(key, PSF_EMISSION_KEY);
    index = sample * k + (m - 1u);
  }
  rays[j] = camera_ray(camera, fx, fy, sample_8d_keyed(sobol, key, index, PSF_DIM_PIXEL));
}

/* Adds weight * Le of each path's ray m (emission_rays, then cast) to its
 * radiance: weight -k / (k + 1) for ray 0, 1 / (k + 1) for the others, so that
 * the radiance gains delta. (One kernel per path that generated, cast and looked
 * up all k + 1 rays took 1.4x as long on PoCL: its loop ran one path at a time.) */
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
