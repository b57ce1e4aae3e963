/* sampling.cl: the Sobol sequence with Joe-Kuo direction numbers and hash-based
 * Owen scrambling, addressed by (pixel, sample index, dimension).
 *
 * Reads: the generator matrices `sobol` (PSF_SOBOL_DIMS x 32 columns, host/sampling.cpp).
 * Point n of dimension d is x_d(n) = XOR over the set bits b of n of sobol[d*32 + b]
 * (Bratley & Fox 1988; Joe & Kuo 2008), i.e. the natural, not Gray-code, order.
 * Scrambling: Burley, "Practical Hash-based Owen Scrambling", JCGT 9(4) 2020:
 * reverse the bits, apply a hash in which every bit depends only on lower bits
 * (a nested uniform scramble), reverse back. Each (pixel, dimension) gets its own
 * seed, so any path index maps to the same sample on every device and batch size.
 * Dimensions >= PSF_SOBOL_DIMS use hashed random numbers instead. */

/* The hash and scrambling functions are defined for uint and for uint8 (eight
 * dimensions of one sample at once, sample_bits8_keyed) from one body each. */
#define PSF_DEFINE_SCRAMBLE(T, SUFFIX)                                                  \
  /* lowbias32 (Wellons): a well-mixing 32-bit integer hash. */                         \
  inline T psf_hash##SUFFIX(T x) {                                                      \
    x ^= x >> 16;                                                                       \
    x *= 0x7feb352du;                                                                   \
    x ^= x >> 15;                                                                       \
    x *= 0x846ca68bu;                                                                   \
    x ^= x >> 16;                                                                       \
    return x;                                                                           \
  }                                                                                     \
  inline T psf_hash_combine##SUFFIX(T seed, T v) {                                      \
    return psf_hash##SUFFIX(seed ^ (v + 0x9e3779b9u + (seed << 6) + (seed >> 2)));      \
  }                                                                                     \
  inline T reverse_bits32##SUFFIX(T x) {                                                \
    x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);                            \
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);                            \
    x = ((x >> 4) & 0x0F0F0F0Fu) | ((x & 0x0F0F0F0Fu) << 4);                            \
    x = ((x >> 8) & 0x00FF00FFu) | ((x & 0x00FF00FFu) << 8);                            \
    return (x >> 16) | (x << 16);                                                       \
  }                                                                                     \
  /* Burley's improved Laine-Karras permutation (on bit-reversed values). */            \
  inline T laine_karras_permutation##SUFFIX(T x, T seed) {                              \
    x ^= x * 0x3d20adeau;                                                               \
    x += seed;                                                                          \
    x *= (seed >> 16) | 1u;                                                             \
    x ^= x * 0x05526c56u;                                                               \
    x ^= x * 0x53a22864u;                                                               \
    return x;                                                                           \
  }                                                                                     \
  inline T nested_uniform_scramble##SUFFIX(T x, T seed) {                               \
    return reverse_bits32##SUFFIX(laine_karras_permutation##SUFFIX(reverse_bits32##SUFFIX(x), seed)); \
  }

PSF_DEFINE_SCRAMBLE(uint, )
PSF_DEFINE_SCRAMBLE(uint8, 8)

/* Column b of dimension d of the generator matrices is sobol[b * PSF_SOBOL_DIMS + d]
 * (host/sampling.cpp), so that eight consecutive dimensions' columns are one vector. */
inline uint sobol_unscrambled(__global const uint* sobol, uint index, uint dim) {
  uint x = 0u;
  __global const uint* m = sobol + dim;
  for (uint b = 0u; index != 0u; index >>= 1, ++b)
    if (index & 1u) x ^= m[b * PSF_SOBOL_DIMS];
  return x;
}

/* The part of the scrambling seed that every dimension of one pixel's sequence
 * shares: a kernel that draws many dimensions for one pixel computes it once. */
inline uint pixel_seed(uint seed, uint pixel) { return psf_hash_combine(psf_hash(seed), pixel); }

/* sample_bits for the pixel whose pixel_seed is `key`; the dimension's scrambling
 * seed is hash_combine(key, dim). */
inline uint sample_bits_keyed(__global const uint* sobol, uint key, uint index, uint dim) {
  uint s = psf_hash_combine(key, dim);
  if (dim < PSF_SOBOL_DIMS) return nested_uniform_scramble(sobol_unscrambled(sobol, index, dim), s);
  return psf_hash_combine(psf_hash_combine(s, index), 0x51ed270bu);
}

/* sobol_unscrambled for dimensions dim..dim+7 (dim + 8 <= PSF_SOBOL_DIMS) at
 * once: the xor of one row of the nibbles' xors (PSF_SOBOL_NIBBLES) per four
 * bits of the index. */
inline uint8 sobol_unscrambled8(__global const uint* sobol, uint index, uint dim) {
  uint8 x = (uint8)(0u);
  __global const uint* m = sobol + PSF_SOBOL_NIBBLES + dim;
  for (uint n = 0u; index != 0u; index >>= 4, ++n) x ^= vload8(0, m + (16u * n + (index & 15u)) * PSF_SOBOL_DIMS);
  return x;
}

/* Dimensions dim..dim+7 of sample `index`, lane k = sample_bits_keyed(sobol, key,
 * index, dim + k) bit for bit: one pass over the index's nibbles for all eight
 * (a bounce's dimensions, shade.cl; the nibbles' xors, PSF_SOBOL_NIBBLES), the
 * scrambling in 8-wide arithmetic. */
inline uint8 sample_bits8_keyed(__global const uint* sobol, uint key, uint index, uint dim) {
  const uint8 d = (uint8)(dim) + (uint8)(0u, 1u, 2u, 3u, 4u, 5u, 6u, 7u);
  const uint8 s = psf_hash_combine8((uint8)(key), d);
  if (dim + 8u > PSF_SOBOL_DIMS) { /* past the table: each lane on its own */
    uint x[8];
    for (uint k = 0u; k < 8u; ++k) x[k] = sample_bits_keyed(sobol, key, index, dim + k);
    return vload8(0, x);
  }
  return nested_uniform_scramble8(sobol_unscrambled8(sobol, index, dim), s);
}

/* 32-bit value of dimension `dim` of sample `index` of `pixel`, scrambled. */
inline uint sample_bits(__global const uint* sobol, uint seed, uint pixel, uint index, uint dim) {
  return sample_bits_keyed(sobol, pixel_seed(seed, pixel), index, dim);
}

/* sin(x), and cos(x) in *c, for |x| <= 8192 (the warps use |x| <= 2 pi): Cody and
 * Waite's reduction by pi/2 in three parts, then Cephes' minimax polynomials on
 * [-pi/4, pi/4] (about 1 ulp), with selects instead of branches. The built-in
 * sincos reduces every argument as if it could be huge, which PoCL spends more
 * time on than on the polynomials. */
inline float psf_sincos(float x, float* c) {
  float ax = fabs(x);
  int j = (int)(ax * 1.27323954473516f); /* 4 / pi */
  j += j & 1;
  float y = (float)j;
  float z = ((ax - y * 0.78515625f) - y * 2.4187564849853515625e-4f) - y * 3.77489497744594108e-8f;
  float zz = z * z;
  float s = ((-1.9515295891e-4f * zz + 8.3321608736e-3f) * zz - 1.6666654611e-1f) * zz * z + z;
  float co = ((2.443315711809948e-5f * zz - 1.388731625493765e-3f) * zz + 4.166664568298827e-2f) * zz * zz -
             0.5f * zz + 1.0f;
  int q = (j >> 1) & 3; /* x = q pi/2 + z */
  float sv = (q & 1) ? co : s, cv = (q & 1) ? s : co;
  sv = (q & 2) ? -sv : sv;
  cv = ((q + 1) & 2) ? -cv : cv;
  *c = cv;
  return x < 0.0f ? -sv : sv;
}

/* atan2(y, x) in [-pi, pi]: Cephes' atanf of t = |y| / |x| (reduced by tan(3pi/8)
 * and tan(pi/8) to |z| <= tan(pi/8), where a minimax polynomial gives about 1
 * ulp), then the quadrant; 0 where x = y = 0. With selects instead of branches:
 * PoCL's built-in atan2 took 6 % of the samples of a sky-lit render (Sponza),
 * once per ray that escapes to the environment map (emitter.cl env_uv). */
inline float psf_atan2(float y, float x) {
  float ax = fabs(x), ay = fabs(y);
  float t = ay / ax; /* inf where x = 0, NaN where both are 0 (selected away) */
  bool big = t > 2.414213562373095f, mid = t > 0.4142135623730950f;
  float base = big ? 1.5707963267948966f : mid ? 0.7853981633974483f : 0.0f;
  float z = big ? -1.0f / t : mid ? (t - 1.0f) / (t + 1.0f) : t;
  float zz = z * z;
  float r = base + ((((8.05374449538e-2f * zz - 1.38776856032e-1f) * zz + 1.99777106478e-1f) * zz -
                     3.33329491539e-1f) * zz * z + z);
  r = x < 0.0f ? 3.14159265358979f - r : r;
  r = ax == 0.0f && ay == 0.0f ? 0.0f : r;
  return y < 0.0f ? -r : r;
}

/* Uniform float in [0, 1): the top 24 bits. */
inline float bits_to_float(uint x) { return (float)(x >> 8) * (1.0f / 16777216.0f); }

inline float sample_1d_keyed(__global const uint* sobol, uint key, uint index, uint dim) {
  return bits_to_float(sample_bits_keyed(sobol, key, index, dim));
}

inline float sample_1d(__global const uint* sobol, uint seed, uint pixel, uint index, uint dim) {
  return sample_1d_keyed(sobol, pixel_seed(seed, pixel), index, dim);
}

/* sample_1d_keyed of dimensions dim..dim+7 (bits_to_float of each lane, exactly). */
inline float8 sample_8d_keyed(__global const uint* sobol, uint key, uint index, uint dim) {
  return convert_float8(sample_bits8_keyed(sobol, key, index, dim) >> 8) * (1.0f / 16777216.0f);
}

/* Writes `dims` dimensions of the points first..first+count-1 (row per point):
 * unscrambled when scramble == 0, else scrambled with (seed, pixel); with
 * scramble == 2 by sample_bits8_keyed, in groups as shade.cl's bounces draw them. */
__kernel void sobol_points(__global const uint* sobol, uint first, uint count, uint dims,
                           uint scramble, uint seed, uint pixel, __global uint* out) {
  uint i = get_global_id(0);
  if (i >= count) return;
  if (scramble == 2u) { /* dimensions 0, 1 one at a time, then groups as a bounce's (shade.cl) */
    const uint key = pixel_seed(seed, pixel);
    for (uint d = 0u; d < min(dims, 2u); ++d) out[i * dims + d] = sample_bits_keyed(sobol, key, first + i, d);
    for (uint g = 2u; g < dims; g += PSF_DIMS_PER_BOUNCE) {
      uint x[8];
      vstore8(sample_bits8_keyed(sobol, key, first + i, g), 0, x);
      for (uint k = 0u; k < PSF_DIMS_PER_BOUNCE && g + k < dims; ++k) out[i * dims + g + k] = x[k];
    }
    return;
  }
  for (uint d = 0u; d < dims; ++d) {
    uint x = scramble ? sample_bits(sobol, seed, pixel, first + i, d)
                      : sobol_unscrambled(sobol, first + i, d);
    out[i * dims + d] = x;
  }
}

/* psf_atan2 of each (y, x) = yx[i] (tests). */
__kernel void atan2_values(__global const float2* yx, uint count, __global float* out) {
  uint i = get_global_id(0);
  if (i >= count) return;
  out[i] = psf_atan2(yx[i].x, yx[i].y);
}

/* psf_sincos of each x (tests): out[i] = (sin, cos). */
__kernel void sincos_values(__global const float* x, uint count, __global float2* out) {
  uint i = get_global_id(0);
  if (i >= count) return;
  float c;
  float s = psf_sincos(x[i], &c);
  out[i] = (float2)(s, c);
}
