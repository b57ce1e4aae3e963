/* visibility.cl: the filtering vertices' hemisphere-ray visibility
 * (--visibility-ray LENGTH), for scenes lit by an environment or ambient light
 * (Keller et al. 2016, Sec. 2.2: the weights compare "the lengths of one
 * hemisphere ray" against a threshold).
 *
 * Without it, similar vertices must agree on their light sample's visibility
 * (shade.cl). An environment's light sample is an infinite ray in a random
 * direction: two vertices side by side in a room lit through a window disagree
 * on it as often as not, which halves the neighbours without telling apart
 * surfaces that are lit differently. With it, the flag is instead whether one
 * cosine-distributed ray around the shading normal n_i travels LENGTH without
 * hitting anything: open surfaces (1) are kept apart from creases, corners and
 * the undersides of furniture (0), whatever the light.
 *
 * visibility_rays: path i's ray (its filtering vertex's, a dead ray without one)
 * into rays[i]; the direction from a hash of the seed and the path's index, so
 * that the image stays a function of the seed. The origin is offset along n_i
 * as shade.cl offsets its rays, and hits closer than LENGTH / 1000 are not
 * counted: where the shading normal leans away from the geometric one, some
 * directions graze the vertex's own triangle.
 * visibility_store: normal.w of each vertex becomes 1 where its ray hit nothing,
 * 0 where it hit something (raycast.cl's any-hit kernel runs in between, or
 * visibility_cast_media, below, where null boundaries are to be passed). */

inline float3 visibility_direction(uint seed, uint first_lo, uint first_hi, uint i, float3 n) {
  uint h = psf_hash_combine(psf_hash_combine(psf_hash(seed ^ 0x5bd1e995u), first_hi), first_lo + i);
  float u1 = bits_to_float(h), u2 = bits_to_float(psf_hash(h));
  return frame_to_world(frame_from_normal(n), square_to_cosine_hemisphere(u1, u2));
}

__kernel void visibility_rays(FrameParams params, float range, __global const PathVertex* vertices,
                              __global Ray* rays) {
  uint i = get_global_id(0);
  if (i >= params.batch_size) return;
  Ray ray;
  ray.org = (float4)(0.0f);
  ray.dir = (float4)(0.0f, 0.0f, 1.0f, -1.0f); /* dead */
  PathVertex v = vertices[i];
  if (v.albedo.w != 0.0f) {
    float3 n = v.normal.xyz;
    float3 d = visibility_direction(params.seed, params.first_path_lo, params.first_path_hi, i, n);
    ray.org = (float4)(offset_origin(v.position.xyz, n), 1e-3f * range);
    ray.dir = (float4)(d, range);
  }
  rays[i] = ray;
}

__kernel void visibility_store(uint count, __global const Hit* hits, __global PathVertex* vertices) {
  uint i = get_global_id(0);
  if (i >= count) return;
  if (vertices[i].albedo.w != 0.0f) vertices[i].normal.w = hits[i].prim == PSF_NO_HIT ? 1.0f : 0.0f;
}

/* The hemisphere rays' any-hit cast in a scene with null boundaries
 * (FrameParams.null_media, in place of raycast.cl's any-hit kernel): they pass
 * the boundaries as light samples do (shade.cl shadow_cast; the transmittance it
 * returns is not used), so that a medium's boundary near a vertex does not count
 * as something that hides it. */
__kernel void visibility_cast_media(__global const BvhNode* nodes, __global const BvhTriPack* packs, uint count,
                                    __global const Ray* rays, __global Hit* hits, __global const uint* tri_material,
                                    __global const Material* materials, __global const TriAttrib* attribs,
                                    __global const TextureInfo* textures, __global const half* texels) {
  uint i = get_global_id(0);
  if (i >= count) return;
  AlphaScene as = {tri_material, materials, attribs, textures, texels, 0};
  hits[i] = shadow_cast(nodes, packs, rays[i], as, 0u);
}
