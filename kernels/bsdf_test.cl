/* bsdf_test.cl: kernels exposing bsdf.cl and texture.cl to tests/test_bsdf.cpp.
 *
 * One work-item per query; directions are in the local frame of the shading
 * normal (s = x, t = y, n = z). A material's roughplastic table is found as in
 * shade.cl. Not used by the renderer. */

inline __global const half* bsdf_test_table(Material m, __global const TextureInfo* textures,
                                            __global const half* texels) {
  return surface_table(m, textures, texels);
}

inline Frame bsdf_test_frame(void) {
  Frame f;
  f.s = (float3)(1.0f, 0.0f, 0.0f);
  f.t = (float3)(0.0f, 1.0f, 0.0f);
  f.n = (float3)(0.0f, 0.0f, 1.0f);
  return f;
}

/* bsdf_sample for query k: material mat[k], wo = wo[k].xyz, (u1, u2, uc) = u[k].xyz.
 * Writes wi (xyz) and pdf (w), weight (xyz) and flags (w, as a float). */
__kernel void bsdf_test_sample(__global const Material* materials, __global const TextureInfo* textures,
                               __global const half* texels, __global const uint* mat, __global const float4* wo,
                               __global const float4* u, __global float4* wi_pdf, __global float4* weight_flags,
                               uint count) {
  uint k = get_global_id(0);
  if (k >= count) return;
  Material m = materials[mat[k]];
  float4 r = u[k];
  BsdfSample bs = bsdf_sample(m, bsdf_test_table(m, textures, texels), bsdf_test_frame(), wo[k].xyz, r.x, r.y, r.z);
  wi_pdf[k] = (float4)(bs.wi, bs.pdf);
  weight_flags[k] = (float4)(bs.weight, (float)bs.flags);
}

/* bsdf_eval for query k: writes f (xyz) and pdf (w). */
__kernel void bsdf_test_eval(__global const Material* materials, __global const TextureInfo* textures,
                             __global const half* texels, __global const uint* mat, __global const float4* wo,
                             __global const float4* wi, __global float4* f_pdf, uint count) {
  uint k = get_global_id(0);
  if (k >= count) return;
  Material m = materials[mat[k]];
  float pdf;
  float3 f = bsdf_eval(m, bsdf_test_table(m, textures, texels), bsdf_test_frame(), wo[k].xyz, wi[k].xyz, &pdf);
  f_pdf[k] = (float4)(f, pdf);
}

/* bsdf_albedo (xyz) and bsdf_is_diffuse (w: 1 or 0) of every material. */
__kernel void bsdf_test_props(__global const Material* materials, __global float4* out, uint count) {
  uint k = get_global_id(0);
  if (k >= count) return;
  Material m = materials[k];
  out[k] = (float4)(bsdf_albedo(m), bsdf_is_diffuse(m) ? 1.0f : 0.0f);
}

/* texture_eval (value) and texture_eval_grad (grad.xy) of texture `index` at uv[k]. */
__kernel void texture_test_eval(__global const TextureInfo* textures, __global const half* texels, uint index,
                                __global const float2* uv, __global float4* value, __global float2* grad, uint count) {
  uint k = get_global_id(0);
  if (k >= count) return;
  value[k] = texture_eval(textures, texels, index, uv[k]);
  grad[k] = texture_eval_grad(textures, texels, index, uv[k]);
}

/* surface_frame on triangle (p0, p1, p2) with attributes attribs[0], for query k:
 * barycentrics bary[k].xy, wo[k]. Writes the frame's n and s and the material's
 * resolved albedo (xyz), specular (xyz), bsdf_albedo (xyz) and alpha_u (w), and alpha_v
 * (n's w). */
__kernel void surface_test_frame(__global const Material* materials, __global const TriAttrib* attribs,
                                 __global const TextureInfo* textures, __global const half* texels,
                                 __global const uint* mat, float4 p0, float4 p1, float4 p2,
                                 __global const float2* bary, __global const float4* wo, __global float4* n_out,
                                 __global float4* s_out, __global float4* albedo_out, __global float4* specular_out,
                                 __global float4* colour_out, uint count) {
  uint k = get_global_id(0);
  if (k >= count) return;
  Material m = materials[mat[k]];
  float3 ng = normalize(cross(p1.xyz - p0.xyz, p2.xyz - p0.xyz));
  float3 n0;
  Frame f = surface_frame(&m, attribs, bary[k].x, bary[k].y, p0.xyz, p1.xyz, p2.xyz, ng, wo[k].xyz, textures, texels,
                          &n0);
  n_out[k] = (float4)(f.n, m.alpha_v);
  s_out[k] = (float4)(f.s, m.transmittance.z); /* w: principledthin's transmission alpha_u */
  albedo_out[k] = m.albedo;
  specular_out[k] = m.specular;
  colour_out[k] = (float4)(bsdf_albedo(m), m.alpha_u);
}

/* surface_frame on triangle (p0, p1, p2) with attributes attribs[0] at
 * barycentrics bary[k], material mat[k], then the roughplastic's coat as the
 * BSDF reads it: out[k] = (external transmittance at cos_t[k], the internal and
 * external reflectances eta.z and eta.w, alpha_u). */
__kernel void surface_test_coat(__global const Material* materials, __global const TriAttrib* attribs,
                                __global const TextureInfo* textures, __global const half* texels,
                                __global const uint* mat, float4 p0, float4 p1, float4 p2,
                                __global const float2* bary, __global const float* cos_t, __global float4* out,
                                uint count) {
  uint k = get_global_id(0);
  if (k >= count) return;
  Material m = materials[mat[k]];
  float3 ng = normalize(cross(p1.xyz - p0.xyz, p2.xyz - p0.xyz));
  float3 n0;
  surface_frame(&m, attribs, bary[k].x, bary[k].y, p0.xyz, p1.xyz, p2.xyz, ng, ng, textures, texels, &n0);
  out[k] = (float4)(rough_transmittance(m, surface_table(m, textures, texels), cos_t[k]), m.eta.z, m.eta.w, m.alpha_u);
}

/* sample_henyey_greenstein for query k: direction of travel d[k].xyz, asymmetry g,
 * (u1, u2) = u[k]. Writes the direction (xyz) and henyey_greenstein's value for
 * it, its pdf (w). */
__kernel void phase_test_sample(__global const float4* d, float g, __global const float2* u,
                                __global float4* wi_pdf, uint count) {
  uint k = get_global_id(0);
  if (k >= count) return;
  float3 wi = sample_henyey_greenstein(d[k].xyz, g, u[k].x, u[k].y);
  wi_pdf[k] = (float4)(wi, henyey_greenstein(g, dot(d[k].xyz, wi)));
}
