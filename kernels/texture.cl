/* texture.cl: texture lookups for materials (bitmap textures, tables).
 *
 * Reads: the TextureInfo table and the texel buffer (RGBA, four halfs per texel,
 * rows from the top of the image; psf_shared.h). Entry PSF_NO_TEXTURE (0) of the
 * table is a placeholder.
 *   texture_eval(textures, texels, index, uv)      -> RGBA at surface uv
 *   texture_eval_grad(textures, texels, index, uv) -> d x / du, d x / dv of the x channel (bump maps)
 *   table_lookup(table, x)                         -> linear interpolation of a 1 x PSF_ROUGH_TABLE_RES row
 * Conventions follow Mitsuba's bitmap texture: the surface uv is first mapped by
 * the texture's affine uv transform; uv (0,0) is the top-left corner of the image;
 * texel (i, j) has its centre at ((i + 0.5) / width, (j + 0.5) / height); bilinear
 * filtering interpolates the four nearest centres, nearest filtering takes the
 * texel containing uv; outside [0,1] the image repeats (or is clamped, or mirrored). */

/* Texel coordinate i wrapped into [0, n). */
inline int texture_wrap(int i, int n, uint flags) {
  if (flags & PSF_TEX_CLAMP) return clamp(i, 0, n - 1);
  if (flags & PSF_TEX_MIRROR) {
    int p = i % (2 * n);
    if (p < 0) p += 2 * n;
    return p < n ? p : 2 * n - 1 - p;
  }
  int r = i % n;
  return r < 0 ? r + n : r;
}

/* The index in the texel buffer of texel (x, y), wrapped. */
inline uint texture_texel_index(TextureInfo t, int x, int y) {
  x = texture_wrap(x, (int)t.width, t.flags);
  y = texture_wrap(y, (int)t.height, t.flags);
  return t.offset + (uint)y * t.width + (uint)x;
}

inline float4 texture_texel(__global const half* texels, TextureInfo t, int x, int y) {
  return vload_half4(texture_texel_index(t, x, y), texels);
}

/* The texture's uv transform applied to the surface uv. */
inline float2 texture_uv(TextureInfo t, float2 uv) {
  return (float2)(t.uv_u.x * uv.x + t.uv_u.y * uv.y + t.uv_u.z, t.uv_v.x * uv.x + t.uv_v.y * uv.y + t.uv_v.z);
}

/* A prefetch of the texels texture_eval reads at uv (psf_prefetch): x and x + 1
 * of both rows, 8 bytes a texel, so that the pair crosses a cache line one
 * time in eight. */
inline void texture_prefetch(__global const TextureInfo* textures, __global const half* texels, uint index, float2 uv) {
  const TextureInfo t = textures[index];
  const float2 st = texture_uv(t, uv);
  const int x = (int)floor(st.x * (float)t.width - 0.5f), y = (int)floor(st.y * (float)t.height - 0.5f);
  __global const half* row0 = texels + 4u * texture_texel_index(t, x, y);
  __global const half* row1 = texels + 4u * texture_texel_index(t, x, y + 1);
  psf_prefetch(row0);
  psf_prefetch(row0 + 7u);
  psf_prefetch(row1);
  psf_prefetch(row1 + 7u);
}

inline float4 texture_eval(__global const TextureInfo* textures, __global const half* texels, uint index, float2 uv) {
  TextureInfo t = textures[index];
  float2 st = texture_uv(t, uv);
  float x = st.x * (float)t.width, y = st.y * (float)t.height;
  if (!(t.flags & PSF_TEX_BILINEAR)) return texture_texel(texels, t, (int)floor(x), (int)floor(y));
  x -= 0.5f;
  y -= 0.5f;
  float x0 = floor(x), y0 = floor(y);
  float fx = x - x0, fy = y - y0;
  int ix = (int)x0, iy = (int)y0;
  float4 a = texture_texel(texels, t, ix, iy), b = texture_texel(texels, t, ix + 1, iy);
  float4 c = texture_texel(texels, t, ix, iy + 1), d = texture_texel(texels, t, ix + 1, iy + 1);
  return (1.0f - fy) * ((1.0f - fx) * a + fx * b) + fy * ((1.0f - fx) * c + fx * d);
}

/* Gradient of the x channel with respect to the surface (u, v): the derivative of
 * the bilinear interpolant (of the texel step for nearest filtering, which is
 * piecewise constant: there the bilinear interpolant's derivative is used as
 * well, as Mitsuba does), chained through the uv transform. */
inline float2 texture_eval_grad(__global const TextureInfo* textures, __global const half* texels, uint index,
                                float2 uv) {
  TextureInfo t = textures[index];
  float2 st = texture_uv(t, uv);
  float x = st.x * (float)t.width - 0.5f, y = st.y * (float)t.height - 0.5f;
  float x0 = floor(x), y0 = floor(y);
  float fx = x - x0, fy = y - y0;
  int ix = (int)x0, iy = (int)y0;
  float a = texture_texel(texels, t, ix, iy).x, b = texture_texel(texels, t, ix + 1, iy).x;
  float c = texture_texel(texels, t, ix, iy + 1).x, d = texture_texel(texels, t, ix + 1, iy + 1).x;
  float ds = ((1.0f - fy) * (b - a) + fy * (d - c)) * (float)t.width;  /* d / d(texture u) */
  float dt = ((1.0f - fx) * (c - a) + fx * (d - b)) * (float)t.height; /* d / d(texture v) */
  return (float2)(ds * t.uv_u.x + dt * t.uv_v.x, ds * t.uv_u.y + dt * t.uv_v.y);
}

/* Linear interpolation of a table of PSF_ROUGH_TABLE_RES samples (x channel) at
 * x = 0, 1/(N-1), ..., 1, as Mitsuba 3's lerp_gather. */
inline float table_lookup(__global const half* table, float x) {
  x = clamp(x, 0.0f, 1.0f) * (float)(PSF_ROUGH_TABLE_RES - 1);
  uint i = min((uint)x, (uint)(PSF_ROUGH_TABLE_RES - 2));
  float w = x - (float)i;
  return (1.0f - w) * vload_half(4u * i, table) + w * vload_half(4u * (i + 1u), table);
}
