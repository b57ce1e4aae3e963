/* surface.cl: the shading point of a hit, between ray casting and the BSDF.
 *
 * Reads: the hit triangle's TriAttrib (shading normals, uv), the texture table
 * and texels (texture.cl). Writes into the Material: its colour term from its
 * texture (albedo for diffuse, plastics and principled, specular for the other
 * types, a dielectric's transmittance with PSF_MATFLAG_TEX_TRANSMITTANCE, or
 * with PSF_MATFLAG_REFLECTANCE a conductor's complex IOR), its
 * roughness from tex_alpha (principled: roughness, which gives alpha_u and
 * alpha_v with its anisotropy), and a principled's metallic from tex_table.
 *   surface_frame(&m, attrib, b1, b2, p0, p1, p2, ng, wo, textures, texels, &n0) -> the shading Frame,
 *     and in n0 the shading normal before a bump or normal map (surface_side_agrees)
 * The shading normal is the barycentric interpolation of the vertex normals
 * (Phong 1975), else the face normal ng; the geometric normal stays with the
 * caller for side tests and ray offsets. Bump mapping perturbs it as Mitsuba's
 * bumpmap (Blinn 1978): dp/du' = dp/du + n (dh/du - <n, dp/du>), likewise for
 * v, n' = normalize(dp/du' x dp/dv') turned to the side of n, where h is the
 * scaled height texture and dp/du, dp/dv come from the triangle's uv; a normal
 * map (PSF_MATFLAG_NORMALMAP) gives n' in the frame (t, n x t, n), t along
 * dp/du. The tangent follows dp/du where it matters (bump maps, anisotropic
 * roughness).
 * Two-sided reflective materials turn the frame towards wo (Mitsuba's twosided).
 *   surface_blend(m, materials, attrib, b1, b2, textures, texels, u, front) -> the material that scatters
 * A blended material (Material.blend) hands the shading point to its partner with
 * probability blend_weight (times tex_blend's x channel there), u uniform in
 * [0, 1). Light sampling, BSDF sampling and their MIS weights at the point then
 * all use the one chosen, so each choice's estimate is unbiased for its BSDF and
 * the expectation is the weighted sum of the two (stochastic material selection).
 * The partner may blend in turn (a chain of up to three materials). With
 * PSF_MATFLAG_BACK_PARTNER the partner is instead the back side's BSDF, chosen
 * where the hit is on the back (front false). */

/* The shading point of a hit on an analytic sphere (psf_shared.h PSF_PRIM_SPHERE)
 * from its three tri_pos entries `s` (host/render.cpp: centre and radius, the
 * local x axis with the normal's sign, -1 for flip_normals, the local y axis;
 * z = x cross y): the unit geometric normal *ng at the hit point pos (left
 * where the ray put it: c + r n in float is off the surface by up to ulp(|c|),
 * 1/128 for a ground sphere of radius 1e5, where the hit point is accurate to
 * ulp(|pos|)), Mitsuba 3's uv (phi / 2pi, theta / pi of the local
 * direction, theta from z) into *u, *v, and p0 = the point, p1 = p0 + dp/du,
 * p2 = p0 + dp/dv with Mitsuba's dp/du = 2 pi r (-y, x, 0) and dp/dv = pi r (z
 * cos phi, z sin phi, -sin theta) (local coordinates), so that
 * surface_frame_general's formulas for a triangle with the uvs (0,0), (1,0),
 * (0,1), which the sphere's TriAttrib holds, give these derivatives, and its
 * texture lookups at (b1, b2) = (u, v) the uv. The sphere's TriAttrib has no
 * vertex normals: the shading normal is *ng. */
/* Mitsuba 3's uv of the unit direction n from a sphere's centre in its frame
 * (x, y, z = x cross y): (phi / 2pi, theta / pi), theta from z (surface_sphere,
 * and emitter.cl's sphere light samples). */
inline float2 sphere_uv(float3 n, float3 x, float3 y, float3 z) {
  /* sampling.cl's atan2 (about 1 ulp): PoCL's built-in took 2-3.5 % of the
   * samples of the sphere scenes' renders. */
  float phi = psf_atan2(dot(n, y), dot(n, x));
  if (phi < 0.0f) phi += 2.0f * PSF_PI;
  return (float2)(phi * (0.5f / PSF_PI), acos(clamp(dot(n, z), -1.0f, 1.0f)) * (1.0f / PSF_PI));
}

inline void surface_sphere(__global const float4* s, float3 pos, float3* ng, float* u, float* v, float3* p0,
                           float3* p1, float3* p2) {
  float4 s0 = s[0], s1 = s[1], s2 = s[2];
  float3 x = s1.xyz, y = s2.xyz, z = cross(x, y);
  float3 d = pos - s0.xyz;
  float len = length(d);
  float3 n = len > 0.0f ? d / len : z;
  *ng = n * s1.w;
  float lx = dot(n, x), ly = dot(n, y), lz = clamp(dot(n, z), -1.0f, 1.0f);
  float2 uv = sphere_uv(n, x, y, z);
  *u = uv.x;
  *v = uv.y;
  float rho = sqrt(lx * lx + ly * ly); /* sin theta */
  float cos_phi = rho > 0.0f ? lx / rho : 1.0f, sin_phi = rho > 0.0f ? ly / rho : 0.0f;
  float3 dpdu = (2.0f * PSF_PI * s0.w) * (ly * -x + lx * y);
  float3 dpdv = (PSF_PI * s0.w) * (lz * cos_phi * x + lz * sin_phi * y - rho * z);
  *p0 = pos;
  *p1 = pos + dpdu;
  *p2 = pos + dpdv;
}

/* The surface uv at barycentrics (b1, b2) of a triangle's attributes. */
inline float2 surface_uv(__global const TriAttrib* a, float b1, float b2) {
  float4 uv01 = a->uv01;
  return (1.0f - b1 - b2) * uv01.xy + b1 * uv01.zw + b2 * (float2)(a->u2, a->v2);
}

/* The material that scatters at a hit on material m (see the header): m, or with
 * probability blend_weight (times tex_blend) its partner, which keeps m's
 * vertex-normal flag (m's emission is added by the caller). A partner may blend
 * in turn (up to PSF_BLEND_CHAIN materials in all): u, rescaled to [0, 1) by
 * each choice taken, decides the next. */
#define PSF_BLEND_CHAIN 3
/* The number in [0, 1) that decides a blend at bounce `depth` of sample
 * `sample` of the pixel whose pixel_seed is `key`: a hash, not a Sobol
 * dimension, so that the other dimensions keep their place. */
inline float surface_blend_u(uint key, uint sample, uint depth) {
  return bits_to_float(psf_hash_combine(psf_hash_combine(key, sample), depth));
}
inline Material surface_blend(Material m, __global const Material* materials, __global const TriAttrib* a, float b1,
                              float b2, __global const TextureInfo* textures, __global const half* texels, float u,
                              bool front) {
  const uint normals = m.flags & PSF_MATFLAG_NORMALS;
  if (m.flags & PSF_MATFLAG_BACK_PARTNER) { /* twosided with a back BSDF: chosen by the side, not by u */
    if (front || m.blend == 0u) return m;
    m = materials[m.blend - 1u];
    m.flags = (m.flags & ~PSF_MATFLAG_NORMALS) | normals;
    return m;
  }
  for (int k = 1; k < PSF_BLEND_CHAIN && m.blend != 0u; ++k) {
    float w = m.blend_weight;
    if (m.tex_blend != PSF_NO_TEXTURE) w *= texture_eval(textures, texels, m.tex_blend, surface_uv(a, b1, b2)).x;
    if (!(u < w)) break;
    u /= w;
    m = materials[m.blend - 1u];
    m.flags = (m.flags & ~PSF_MATFLAG_NORMALS) | normals;
  }
  return m;
}

/* roughplastic with a roughness texture (PSF_MATFLAG_ROUGH_TABLE2D): the rows of
 * its table around sqrt(alpha_u), the lower in k.y and the upper's weight in k.x,
 * and the coat's internal and external reflectances (eta.z, eta.w) between them. */
inline void rough_table_rows(Material* m, __global const TextureInfo* textures, __global const half* texels) {
  float f = clamp(sqrt(m->alpha_u), 0.0f, 1.0f) * (float)(PSF_ROUGH_TABLE_ROWS - 1);
  uint r = min((uint)f, (uint)(PSF_ROUGH_TABLE_ROWS - 2));
  float w = f - (float)r;
  __global const half* lo = texels + 4ul * ((ulong)textures[m->tex_table].offset + r * PSF_ROUGH_TABLE_WIDTH);
  __global const half* hi = lo + 4u * PSF_ROUGH_TABLE_WIDTH;
  m->eta.z = mix(vload_half(4u * PSF_ROUGH_TABLE_RES, lo), vload_half(4u * PSF_ROUGH_TABLE_RES, hi), w);
  m->eta.w = mix(vload_half(4u * (PSF_ROUGH_TABLE_RES + 1), lo), vload_half(4u * (PSF_ROUGH_TABLE_RES + 1), hi), w);
  m->k.x = w;
  m->k.y = (float)r;
}

/* The row of the texel buffer the BSDF reads as m's table (roughplastic's; the
 * lower of the two rows with PSF_MATFLAG_ROUGH_TABLE2D); the buffer's start for
 * a material without one. */
inline __global const half* surface_table(Material m, __global const TextureInfo* textures,
                                          __global const half* texels) {
  if (m.tex_table == PSF_NO_TEXTURE) return texels;
  uint row = (m.flags & PSF_MATFLAG_ROUGH_TABLE2D) ? (uint)m.k.y * PSF_ROUGH_TABLE_WIDTH : 0u;
  return texels + 4ul * ((ulong)textures[m.tex_table].offset + row);
}

/* A material's emission at barycentrics (b1, b2) of the triangle (its emission
 * texture, if any, multiplies it). */
inline float3 surface_emission(Material m, __global const TriAttrib* a, float b1, float b2,
                               __global const TextureInfo* textures, __global const half* texels) {
  float3 le = m.emission.xyz;
  if (m.tex_emission != PSF_NO_TEXTURE) le *= texture_eval(textures, texels, m.tex_emission, surface_uv(a, b1, b2)).xyz;
  return le;
}

/* The unit tangent packed into a TriAttrib normal's w (psf_shared.h): octahedral
 * coordinates, 15 bits each. */
inline float3 tangent_unpack(float w) {
  uint bits = as_uint(w);
  float2 o = (float2)((float)(bits & 0x7fffu), (float)((bits >> 15) & 0x7fffu)) / 16383.0f - 1.0f;
  float3 d = (float3)(o, 1.0f - fabs(o.x) - fabs(o.y));
  if (d.z < 0.0f) d.xy = (float2)((1.0f - fabs(o.y)) * (o.x < 0.0f ? -1.0f : 1.0f), (1.0f - fabs(o.x)) * (o.y < 0.0f ? -1.0f : 1.0f));
  return normalize(d);
}

/* A vertex colour packed as in TriAttrib (11, 11, 10 bits unorm). */
inline float3 vertex_color_unpack(uint c) {
  return (float3)((float)(c & 2047u) / 2047.0f, (float)((c >> 11) & 2047u) / 2047.0f, (float)(c >> 22) / 1023.0f);
}

/* Mitsuba 3's principled GGX roughness from roughness r and anisotropic k:
 * alpha = r^2 stretched by sqrt(1 - 0.9 k) along the tangent's two axes, at
 * least 0.001 (Burley 2012; host/scene/mitsuba.cpp computes the untextured);
 * principledthin's specular transmission likewise from r (0.65 eta - 0.35). */
inline void principled_alphas(Material* m, float roughness) {
  float a = roughness * roughness, aspect = sqrt(1.0f - 0.9f * m->eta.w);
  m->eta.z = roughness;
  m->alpha_u = fmax(0.001f, a / aspect);
  m->alpha_v = fmax(0.001f, a * aspect);
  if (m->type == PSF_MATERIAL_PRINCIPLED_THIN) {
    float rt = (0.65f * m->eta.x - 0.35f) * roughness, at = rt * rt;
    m->transmittance.z = fmax(0.001f, at / aspect);
    m->transmittance.w = fmax(0.001f, at * aspect);
  }
}

/* The types whose colour term (texture, vertex colours) is albedo. */
inline bool surface_colours_albedo(const Material* m) {
  return m->type == PSF_MATERIAL_DIFFUSE || bsdf_is_plastic(*m) || m->type == PSF_MATERIAL_PPLASTIC ||
         m->type == PSF_MATERIAL_PRINCIPLED || m->type == PSF_MATERIAL_PRINCIPLED_THIN;
}

/* A principled material with a metallic texture (tex_table), which other types use for their tables. */
inline bool surface_metallic_map(const Material* m) {
  return m->type == PSF_MATERIAL_PRINCIPLED && m->tex_table != PSF_NO_TEXTURE;
}

inline Frame surface_frame_general(Material* m, __global const TriAttrib* a, float b1, float b2, float3 p0,
                                   float3 p1, float3 p2, float3 ng, float3 wo, __global const TextureInfo* textures,
                                   __global const half* texels, float3* unperturbed) {
  float b0 = 1.0f - b1 - b2;
  float3 ns = ng;
  if ((m->flags & PSF_MATFLAG_NORMALS) && (a->flags & PSF_TRI_NORMALS)) {
    float3 n = b0 * a->n0.xyz + b1 * a->n1.xyz + b2 * a->n2.xyz;
    float len = length(n);
    if (len > 0.0f) ns = n / len;
  }
  float3 ns0 = ns; /* before the bump or normal map */
  bool bump = m->tex_bump != PSF_NO_TEXTURE;
  Frame f;
  if (m->tex_color != PSF_NO_TEXTURE || bump || m->alpha_u != m->alpha_v || m->tex_alpha != PSF_NO_TEXTURE ||
      surface_metallic_map(m)) {
    float4 uv01 = a->uv01;
    float2 uv0 = uv01.xy, uv1 = uv01.zw, uv2 = (float2)(a->u2, a->v2);
    float2 uv = b0 * uv0 + b1 * uv1 + b2 * uv2;
    if (m->tex_color != PSF_NO_TEXTURE) {
      float3 c = texture_eval(textures, texels, m->tex_color, uv).xyz;
      if (surface_colours_albedo(m)) m->albedo.xyz = c;
      else if (m->flags & PSF_MATFLAG_REFLECTANCE) conductor_from_reflectance(m, c);
      else if (m->flags & PSF_MATFLAG_TEX_TRANSMITTANCE) m->transmittance.xyz = c;
      else m->specular.xyz = c;
    }
    const bool principled = m->type == PSF_MATERIAL_PRINCIPLED || m->type == PSF_MATERIAL_PRINCIPLED_THIN;
    if (m->tex_alpha != PSF_NO_TEXTURE && principled) {
      principled_alphas(m, clamp(texture_eval(textures, texels, m->tex_alpha, uv).x, 0.0f, 1.0f));
    } else if (m->tex_alpha != PSF_NO_TEXTURE) { /* textured roughness, at Mitsuba's lower bound */
      float2 t = texture_eval(textures, texels, m->tex_alpha, uv).xy;
      m->alpha_u = fmax(t.x, 1e-4f);
      m->alpha_v = (m->flags & PSF_MATFLAG_ALPHA_UV) ? fmax(t.y, 1e-4f) : m->alpha_u;
      if (m->flags & PSF_MATFLAG_ROUGH_TABLE2D) rough_table_rows(m, textures, texels);
    }
    if (surface_metallic_map(m)) m->specular.x = clamp(texture_eval(textures, texels, m->tex_table, uv).x, 0.0f, 1.0f);
    /* dp/du and dp/dv of the triangle's uv parametrisation. */
    float2 d1 = uv1 - uv0, d2 = uv2 - uv0;
    float det = d1.x * d2.y - d1.y * d2.x;
    float3 e1 = p1 - p0, e2 = p2 - p0;
    float3 dpdu, dpdv;
    if (det != 0.0f) {
      float inv = 1.0f / det;
      dpdu = (d2.y * e1 - d1.y * e2) * inv;
      dpdv = (d1.x * e2 - d2.x * e1) * inv;
    } else {
      Frame c = frame_from_normal(ns);
      dpdu = c.s;
      dpdv = c.t;
    }
    if (bump && (m->flags & PSF_MATFLAG_NORMALMAP)) {
      /* Tangent space: t along dp/du made orthogonal to n, b = n x t (Mitsuba 3's
       * normalmap, the glTF sample viewer's frame without stored tangents), or
       * the vertices' tangents interpolated, made orthogonal to n, and
       * b = s n x t (glTF's TANGENT; s the handedness of vertex 0's). */
      float3 c = texture_eval(textures, texels, m->tex_bump, uv).xyz * 2.0f - 1.0f;
      c.xy *= m->bump_scale;
      float3 tu = dpdu;
      float b_sign = 1.0f;
      if ((m->flags & PSF_MATFLAG_NORMALS) && (a->flags & PSF_TRI_TANGENTS)) {
        float4 n0 = a->n0, n1 = a->n1, n2 = a->n2;
        float3 tv = b0 * tangent_unpack(n0.w) + b1 * tangent_unpack(n1.w) + b2 * tangent_unpack(n2.w);
        if (dot(tv, tv) > 0.0f) tu = tv;
        b_sign = (as_uint(n0.w) & (1u << 30)) ? -1.0f : 1.0f;
      }
      float3 t = normalize(tu - ns * dot(ns, tu));
      float3 nb = normalize(c.x * t + c.y * b_sign * cross(ns, t) + c.z * ns);
      if (isfinite(nb.x) && isfinite(nb.y) && isfinite(nb.z) && isfinite(t.x) && dot(nb, ns) > 0.0f) {
        ns = nb;
        dpdu = t;
      }
    } else if (bump) {
      float2 g = texture_eval_grad(textures, texels, m->tex_bump, uv) * m->bump_scale;
      float3 du = dpdu + ns * (g.x - dot(ns, dpdu));
      float3 dv = dpdv + ns * (g.y - dot(ns, dpdv));
      float3 nb = normalize(cross(du, dv));
      if (dot(nb, ns) < 0.0f) nb = -nb;
      if (isfinite(nb.x) && isfinite(nb.y) && isfinite(nb.z)) {
        ns = nb;
        dpdu = du;
      }
    }
    f = frame_from_normal_tangent(ns, dpdu);
  } else {
    f = frame_from_normal(ns);
  }
  /* Vertex colours multiply the colour term (after its texture, as glTF's COLOR_0). */
  if ((m->flags & PSF_MATFLAG_VERTEX_COLOR) && (a->flags & PSF_TRI_COLORS)) {
    float3 c = b0 * vertex_color_unpack(a->color0) + b1 * vertex_color_unpack(a->color1) +
               b2 * vertex_color_unpack(a->color2);
    if (surface_colours_albedo(m)) m->albedo.xyz *= c;
    else if (m->type == PSF_MATERIAL_CONDUCTOR || m->type == PSF_MATERIAL_ROUGH_CONDUCTOR) m->specular.xyz *= c;
  }
  if (m->two_sided && !bsdf_transmits(*m) && dot(f.n, wo) < 0.0f) {
    f.n = -f.n;
    ns0 = -ns0;
  }
  *unperturbed = ns0;
  return f;
}

/* The untextured, isotropic cases inline (no call), flat or with interpolated
 * normals (surface_frame_general's steps for them, so the same frame bit for
 * bit), the rest in surface_frame_general. */
inline Frame surface_frame(Material* m, __global const TriAttrib* a, float b1, float b2, float3 p0, float3 p1,
                           float3 p2, float3 ng, float3 wo, __global const TextureInfo* textures,
                           __global const half* texels, float3* unperturbed) {
  if ((m->flags & PSF_MATFLAG_VERTEX_COLOR) || m->tex_color != PSF_NO_TEXTURE || m->tex_bump != PSF_NO_TEXTURE ||
      m->alpha_u != m->alpha_v || m->tex_alpha != PSF_NO_TEXTURE || surface_metallic_map(m))
    return surface_frame_general(m, a, b1, b2, p0, p1, p2, ng, wo, textures, texels, unperturbed);
  bool flip = m->two_sided && !bsdf_transmits(*m);
  if (m->flags & PSF_MATFLAG_NORMALS) {
    float3 ns = ng;
    if (a->flags & PSF_TRI_NORMALS) {
      float3 n = (1.0f - b1 - b2) * a->n0.xyz + b1 * a->n1.xyz + b2 * a->n2.xyz;
      float len = length(n);
      if (len > 0.0f) ns = n / len;
    }
    Frame f = frame_from_normal(ns);
    if (flip && dot(f.n, wo) < 0.0f) {
      f.n = -f.n;
      ns = -ns;
    }
    *unperturbed = ns;
    return f;
  }
  float3 n = flip && dot(ng, wo) < 0.0f ? -ng : ng;
  *unperturbed = n;
  return frame_from_normal(n);
}

/* Whether direction w may scatter at a bump- or normal-mapped point: only on
 * the same side of the shading normal before the perturbation (`unperturbed`)
 * as after it, as Mitsuba 3's bumpmap and normalmap decide, so that no light
 * leaks through the surface. True where nothing perturbs the normal. */
inline bool surface_side_agrees(const Material* m, Frame f, float3 unperturbed, float3 w) {
  return m->tex_bump == PSF_NO_TEXTURE || dot(w, unperturbed) * dot(w, f.n) > 0.0f;
}
