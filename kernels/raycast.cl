/* raycast.cl: closest-hit and any-hit ray casting through a PSF_BVH_WIDTH-wide BVH.
 *
 * Reads: the BVH built by host/bvh.cpp (BvhNode array, node 0 the root; BvhTriPack
 * array, PSF_BVH_WIDTH triangles per pack, leaves as runs of packs) and Rays
 * (org.w = tmin, dir.w = tmax; a ray with tmax < 0 is dead).
 * Writes: one Hit per ray. Closest: the smallest t in (tmin, tmax), prim the scene
 * triangle index, u, v the barycentrics of vertices 1 and 2; a miss (or a dead
 * ray) has t = tmax, prim = PSF_NO_HIT. Any: prim = PSF_NO_HIT when nothing lies
 * within (tmin, tmax), otherwise some hit triangle with its t, u, v.
 *
 * Algorithms:
 * - Ray/box: the slab test (Kay & Kajiya 1986) of all PSF_BVH_WIDTH children of a
 *   node at once, in float4/float8 arithmetic on the node's structure-of-arrays
 *   boxes: t = (plane - org) * (1 / dir) with the inverse direction precomputed,
 *   near and far planes chosen by the sign of the direction (so empty slots,
 *   min > max, never hit). Direction components of magnitude below 1e-12 are
 *   replaced by +-1e-12 so no 0 * inf = NaN arises. The far distance is enlarged
 *   by a few ulps (Ize, "Robust BVH ray traversal", JCGT 2013) so boxes touched at
 *   an edge or of zero thickness are not missed.
 * - Traversal: depth first with a private stack of child references and their
 *   entry distances. For the closest hit: one child hit, descend into it; two,
 *   push the farther; more, push all sorted far to near (three or four by a
 *   sorting network of selects, more by one over the node's vectors) and
 *   descend into the nearest. Popped entries farther than the closest hit so far are dropped.
 *   The any-hit traversal stops at the first hit.
 * - Ray/triangle: Moller & Trumbore, "Fast, minimum storage ray/triangle
 *   intersection", JGT 1997, without back-face culling, on the PSF_BVH_WIDTH
 *   triangles of a pack at once. Its barycentrics carry an error of a few ulps
 *   times |org - v0| / size of the triangle, so they are accepted up to
 *   eps = PSF_BARY_EPS + PSF_BARY_EPS_DIST * distance / size outside [0,1]
 *   (size = sqrt(|e1 x e2|), stored inverted in the pack): a ray through an edge
 *   shared by two triangles hits at least one of them. The tests are written so
 *   that NaN (det = 0: unused lanes, degenerate triangles) rejects.
 * - Alpha testing (raycast_closest_masked, raycast_any_masked): packs mark the
 *   triangles of mask materials with PSF_PRIM_MASKED in their prim; a hit on
 *   one counts only if the material's opacity (constant times texture, at the
 *   hit's uv) exceeds a hash of the ray and the triangle in [0,1) (stochastic
 *   transparency: binary cut-outs exactly, partial opacity on average). The
 *   unmasked kernels never test and cost nothing extra.
 * - Null boundaries of media (PSF_MATFLAG_NULL_BOUNDARY, triangles and spheres,
 *   marked as masked): a hit for closest-hit casts, but an any-hit cast given a
 *   record of crossings (AlphaScene.crossings, shade.cl's shadow rays) passes
 *   them and records each, in order of distance whatever order the traversal
 *   meets them in (record_null_crossing).
 * - Ray/sphere (analytic spheres, sphere packs): sphere_pack_test below. Spheres
 *   are never alpha-tested (host/scene keeps masked spheres as triangles), and
 *   their hits carry u = v = 0.
 * No barriers; kernels guard the rounded-up tail of the global range. */

#if PSF_BVH_WIDTH == 8
typedef float8 bvh_floatw;
typedef int8 bvh_intw;
#define BVH_VLOAD vload8
#define BVH_VSTORE vstore8
#define BVH_HMIN(x) bvh_hmin4(BVH_MIN((x).lo, (x).hi))
#elif PSF_BVH_WIDTH == 4
typedef float4 bvh_floatw;
typedef int4 bvh_intw;
#define BVH_VLOAD vload4
#define BVH_VSTORE vstore4
#define BVH_HMIN(x) bvh_hmin4(x)
#else
#error "PSF_BVH_WIDTH must be 4 or 8"
#endif

/* Entries of the traversal stack: at most PSF_BVH_WIDTH - 1 per level below the root. */
#define PSF_BVH_STACK ((PSF_BVH_WIDTH - 1) * PSF_BVH_MAX_DEPTH + 1)
/* Barycentric tolerance eps = PSF_BARY_EPS + PSF_BARY_EPS_DIST * distance / size: the
 * triangle grows by 1e-6 of its size plus 5e-7 of its distance (about 4x the float
 * rounding of Moller-Trumbore measured at shared edges), so rays not nearly
 * parallel to a triangle cannot slip between two that share an edge. */
#define PSF_BARY_EPS 1e-6f
#define PSF_BARY_EPS_DIST 5e-7f
/* 1 + 2 gamma(3) (Ize 2013), rounded up: the conservative far distance of the slab test. */
#define PSF_SLAB_FAR_SCALE 1.0000004f

/* Float offsets of the arrays of a BvhNode seen as a float array. */
#define BVH_MIN_X 0
#define BVH_MIN_Y (2 * PSF_BVH_WIDTH)
#define BVH_MIN_Z (4 * PSF_BVH_WIDTH)
#define BVH_CHILD (6 * PSF_BVH_WIDTH)

/* Float offsets of the arrays of a BvhTriPack seen as a float array. */
#define PACK_V0 0
#define PACK_E1 (3 * PSF_BVH_WIDTH)
#define PACK_E2 (6 * PSF_BVH_WIDTH)
#define PACK_INV_SIZE (9 * PSF_BVH_WIDTH)
#define PACK_PRIM (10 * PSF_BVH_WIDTH)

/* Forced inlining of the traversal's helpers (program.cl PSF_FORCE_INLINE). */
#define BVH_INLINE PSF_FORCE_INLINE

/* Per-component max / min as compare and select (maps to maxps / minps; no NaN
 * can reach them, see slab_ray). */
#define BVH_MAX(a, b) select((b), (a), (a) > (b))
#define BVH_MIN(a, b) select((b), (a), (a) < (b))

/* Compare and swap of two (distance, reference) pairs so that the first holds
 * the farther: selects, not branches. */
#define BVH_SORT2(da, ca, db, cb) \
  do {                            \
    const bool sw_ = (da) < (db); \
    const float dt_ = (da);       \
    const uint ct_ = (ca);        \
    (da) = sw_ ? (db) : (da);     \
    (ca) = sw_ ? (cb) : (ca);     \
    (db) = sw_ ? dt_ : (db);      \
    (cb) = sw_ ? ct_ : (cb);      \
  } while (0)

inline float bvh_hmin4(float4 x) {
  float2 m = BVH_MIN(x.lo, x.hi);
  return m.x < m.y ? m.x : m.y;
}
/* Bit k set where lane k of a comparison result is true. */
inline uint bvh_lane_mask(bvh_intw c) {
#if PSF_BVH_WIDTH == 8
  return psf_lanes8(c); /* program.cl */
#else
  /* One byte per lane (0 or 1), gathered into the top byte by a multiplication. */
  uint bytes = as_uint(convert_uchar4(c) & (uchar4)(1));
  return (bytes * 0x01020408u) >> 24;
#endif
}
/* Index of the lowest set bit of a nonzero mask. */
inline uint bvh_first_lane(uint mask) { return 31u - clz(mask & (0u - mask)); }

#if PSF_BVH_WIDTH == 8
/* One round of a sorting network over the eight lanes: lane k and lane
 * partner[k] (a pair, or k itself) end with the larger distance in the pair's
 * lane marked in `first`; the child references move with their distances. */
BVH_INLINE void bvh_sort_round(float8* d, uint8* c, uint8 partner, int8 first) {
  const float8 dp = shuffle(*d, partner);
  const uint8 cp = shuffle(*c, partner);
  const int8 swap = select(dp < *d, *d < dp, first);
  *d = select(*d, dp, swap);
  *c = select(*c, cp, as_uint8(swap));
}
/* The eight lanes sorted by distance, farthest first, in the six rounds of an
 * optimal network of 19 comparators (Knuth, TAOCP vol. 3, Sec. 5.3.4):
 * shuffles and selects, no branches. */
BVH_INLINE void bvh_sort_far_first(float8* d, uint8* c) {
  bvh_sort_round(d, c, (uint8)(2, 3, 0, 1, 6, 7, 4, 5), (int8)(-1, -1, 0, 0, -1, -1, 0, 0));
  bvh_sort_round(d, c, (uint8)(4, 5, 6, 7, 0, 1, 2, 3), (int8)(-1, -1, -1, -1, 0, 0, 0, 0));
  bvh_sort_round(d, c, (uint8)(1, 0, 3, 2, 5, 4, 7, 6), (int8)(-1, 0, -1, 0, -1, 0, -1, 0));
  bvh_sort_round(d, c, (uint8)(0, 1, 4, 5, 2, 3, 6, 7), (int8)(0, 0, -1, -1, 0, 0, 0, 0));
  bvh_sort_round(d, c, (uint8)(0, 4, 2, 6, 1, 5, 3, 7), (int8)(0, -1, 0, -1, 0, 0, 0, 0));
  bvh_sort_round(d, c, (uint8)(0, 2, 1, 4, 3, 6, 5, 7), (int8)(0, -1, 0, -1, 0, -1, 0, 0));
}
#endif

/* The per-ray constants of the slab test. */
typedef struct {
  float3 inv;     /* 1 / direction, components below 1e-12 in magnitude clamped to +-1e-12 */
  float3 org;     /* origin */
  uint near_x;    /* float offset in a node of the near-plane array of each axis */
  uint near_y;
  uint near_z;
  uint far_x;     /* and of the far-plane array */
  uint far_y;
  uint far_z;
} SlabRay;

inline SlabRay slab_ray(float3 org, float3 dir) {
  SlabRay s;
  float3 d = select(dir, copysign((float3)(1e-12f), dir), isless(fabs(dir), (float3)(1e-12f)));
  s.inv = 1.0f / d;
  s.org = org;
  uint fx = s.inv.x >= 0.0f ? 0u : PSF_BVH_WIDTH;
  uint fy = s.inv.y >= 0.0f ? 0u : PSF_BVH_WIDTH;
  uint fz = s.inv.z >= 0.0f ? 0u : PSF_BVH_WIDTH;
  s.near_x = BVH_MIN_X + fx;
  s.near_y = BVH_MIN_Y + fy;
  s.near_z = BVH_MIN_Z + fz;
  s.far_x = BVH_MIN_X + (PSF_BVH_WIDTH - fx);
  s.far_y = BVH_MIN_Y + (PSF_BVH_WIDTH - fy);
  s.far_z = BVH_MIN_Z + (PSF_BVH_WIDTH - fz);
  return s;
}

/* Slab test of all children of node `f` (a BvhNode as floats): returns a mask with
 * bit k set when child k's box overlaps [tmin, tmax]; *tnear gets the entry distances. */
BVH_INLINE uint slab_test(__global const float* f, const SlabRay* s, float tmin, float tmax, bvh_floatw* tnear) {
  bvh_floatw ix = (bvh_floatw)(s->inv.x), iy = (bvh_floatw)(s->inv.y), iz = (bvh_floatw)(s->inv.z);
  bvh_floatw ox = (bvh_floatw)(s->org.x), oy = (bvh_floatw)(s->org.y), oz = (bvh_floatw)(s->org.z);
  bvh_floatw nx = (BVH_VLOAD(0, f + s->near_x) - ox) * ix;
  bvh_floatw ny = (BVH_VLOAD(0, f + s->near_y) - oy) * iy;
  bvh_floatw nz = (BVH_VLOAD(0, f + s->near_z) - oz) * iz;
  bvh_floatw fx = (BVH_VLOAD(0, f + s->far_x) - ox) * ix;
  bvh_floatw fy = (BVH_VLOAD(0, f + s->far_y) - oy) * iy;
  bvh_floatw fz = (BVH_VLOAD(0, f + s->far_z) - oz) * iz;
  bvh_floatw tn = BVH_MAX(BVH_MAX(nx, ny), BVH_MAX(nz, (bvh_floatw)(tmin)));
  bvh_floatw tf = BVH_MIN(BVH_MIN(fx, fy), BVH_MIN(fz, (bvh_floatw)(tmax))) * PSF_SLAB_FAR_SCALE;
  *tnear = tn;
  return bvh_lane_mask(tn <= tf);
}

/* Moller-Trumbore test of the PSF_BVH_WIDTH triangles of pack `p` (a BvhTriPack as
 * floats) at once. Returns the mask of lanes hit within (tmin, tmax); *t_out gets
 * their distances (infinity in the other lanes), *u_out and *v_out the barycentrics. */
BVH_INLINE uint pack_test(__global const float* p, float3 org, float3 dir, float dir_len, float tmin, float tmax,
                          bvh_floatw* t_out, bvh_floatw* u_out, bvh_floatw* v_out) {
  bvh_floatw dx = (bvh_floatw)(dir.x), dy = (bvh_floatw)(dir.y), dz = (bvh_floatw)(dir.z);
  bvh_floatw e1x = BVH_VLOAD(0, p + PACK_E1), e1y = BVH_VLOAD(0, p + PACK_E1 + PSF_BVH_WIDTH),
             e1z = BVH_VLOAD(0, p + PACK_E1 + 2 * PSF_BVH_WIDTH);
  bvh_floatw e2x = BVH_VLOAD(0, p + PACK_E2), e2y = BVH_VLOAD(0, p + PACK_E2 + PSF_BVH_WIDTH),
             e2z = BVH_VLOAD(0, p + PACK_E2 + 2 * PSF_BVH_WIDTH);
  /* pv = dir x e2, det = e1 . pv */
  bvh_floatw pvx = dy * e2z - dz * e2y, pvy = dz * e2x - dx * e2z, pvz = dx * e2y - dy * e2x;
  bvh_floatw inv_det = 1.0f / (e1x * pvx + e1y * pvy + e1z * pvz);
  /* s = org - v0, u = s . pv / det */
  bvh_floatw sx = (bvh_floatw)(org.x) - BVH_VLOAD(0, p + PACK_V0);
  bvh_floatw sy = (bvh_floatw)(org.y) - BVH_VLOAD(0, p + PACK_V0 + PSF_BVH_WIDTH);
  bvh_floatw sz = (bvh_floatw)(org.z) - BVH_VLOAD(0, p + PACK_V0 + 2 * PSF_BVH_WIDTH);
  bvh_floatw u = (sx * pvx + sy * pvy + sz * pvz) * inv_det;
  /* q = s x e1, v = dir . q / det, t = e2 . q / det */
  bvh_floatw qx = sy * e1z - sz * e1y, qy = sz * e1x - sx * e1z, qz = sx * e1y - sy * e1x;
  bvh_floatw v = (dx * qx + dy * qy + dz * qz) * inv_det;
  bvh_floatw t = (e2x * qx + e2y * qy + e2z * qz) * inv_det;
  bvh_floatw eps = (PSF_BARY_EPS_DIST * dir_len) * fabs(t) * BVH_VLOAD(0, p + PACK_INV_SIZE) + PSF_BARY_EPS;
  /* Conjunctions of true comparisons: a NaN lane (det = 0, unused lanes) fails. */
  bvh_intw ok = (u >= -eps) & (v >= -eps) & (u + v <= 1.0f + eps) & (t > tmin) & (t < tmax);
  *t_out = select((bvh_floatw)(INFINITY), t, ok);
  *u_out = u;
  *v_out = v;
  return bvh_lane_mask(ok);
}

/* Ray/sphere test of the PSF_BVH_WIDTH spheres of sphere pack `p` (centres in
 * v0, radii in e1_x) at once, in the form of Haines et al., "Precision
 * improvements for ray/sphere intersection" (Ray Tracing Gems, 2019, ch. 7):
 * with f = org - centre and unit direction d, the squared distance of the line
 * from the centre is |f - (f.d) d|^2, which keeps the discriminant accurate far
 * from the sphere, and the two roots are c / q and q with q = b + sign(b)
 * sqrt(disc), b = -f.d, c = |f|^2 - r^2. The nearer root in (tmin, tmax) is
 * taken, else the farther (a ray starting inside). Returns the mask of lanes
 * hit; *t_out their ray parameters (infinity elsewhere).
 * In double precision where the device has it (cl_khr_fp64; Mitsuba 3 too
 * intersects its spheres in double on the CPU) for a pack holding a large
 * sphere: a ray leaving a ground of radius 1e5 starts 1e-4 off its surface
 * (shade.cl's offset, 1e-4 of the point's largest coordinate), c = |f|^2 - r^2
 * is then about 2e5 x 1e-4 = 20, and float's rounding of |f|^2 = 1e10 is
 * larger: such rays hit their own sphere. In float elsewhere: f = org - centre
 * is one rounding of exact values, so c's error is about 3 eps r^2 against
 * |c| = 2 r x offset, below 1 % where r <= 4 or r <= |centre| / 2 (then the
 * offset is at least 1e-4 r / sqrt(3)); the double test cost sphere-light 8 %.
 * Out of line on CPUs: inlined, the compiler hoists the direction's
 * normalisation in double out of the traversal loop, and every ray of a scene
 * without spheres paid for it (PoCL, Mitsuba's cbox: 4-7 % of its tracing
 * time). Inlined on GPUs: the call cost NVIDIA's OpenCL 10 % of Sponza's casts
 * (H200, 724 -> 649 Mrays/s, although Sponza has no sphere). */
#if defined(cl_khr_fp64) && PSF_BVH_WIDTH == 8
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double8 sphere_realw;
#define SPHERE_REAL(x) convert_double8(x)
#define SPHERE_FLOATW(x) convert_float8(x)
#define SPHERE_INTW(x) convert_int8(x)
#define SPHERE_SCALAR double
#elif defined(cl_khr_fp64) && PSF_BVH_WIDTH == 4
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double4 sphere_realw;
#define SPHERE_REAL(x) convert_double4(x)
#define SPHERE_FLOATW(x) convert_float4(x)
#define SPHERE_INTW(x) convert_int4(x)
#define SPHERE_SCALAR double
#else
typedef bvh_floatw sphere_realw;
#define SPHERE_REAL(x) (x)
#define SPHERE_FLOATW(x) (x)
#define SPHERE_INTW(x) (x)
#define SPHERE_SCALAR float
#endif
#if PSF_CPU_DEVICE
#define SPHERE_TEST_PLACEMENT __attribute__((noinline))
#else
#define SPHERE_TEST_PLACEMENT BVH_INLINE
#endif
/* The roots t0, t1 of a sphere test (sphere_pack_test) in lanes `hit`: the
 * nearer in (tmin, tmax), else the farther; returns the mask of lanes hit. */
BVH_INLINE uint sphere_roots(bvh_floatw t0, bvh_floatw t1, bvh_intw hit, float tmin, float tmax, bvh_floatw* t_out) {
  bvh_floatw tn = BVH_MIN(t0, t1), tf = BVH_MAX(t0, t1);
  bvh_intw ok_n = hit & (tn > tmin) & (tn < tmax);
  bvh_intw ok_f = hit & (tf > tmin) & (tf < tmax);
  *t_out = select(select((bvh_floatw)(INFINITY), tf, ok_f), tn, ok_n);
  return bvh_lane_mask(ok_n | ok_f);
}

/* The test in float: the spheres of packs that the builder found small
 * enough (host/bvh.cpp sphere_needs_double). */
BVH_INLINE uint sphere_pack_test_float(__global const float* p, float3 org, float3 dir, float dir_len, float tmin,
                                       float tmax, bvh_floatw* t_out) {
  const float inv_len = 1.0f / dir_len;
  const float dx = dir.x * inv_len, dy = dir.y * inv_len, dz = dir.z * inv_len;
  const bvh_floatw fx = (bvh_floatw)(org.x) - BVH_VLOAD(0, p + PACK_V0);
  const bvh_floatw fy = (bvh_floatw)(org.y) - BVH_VLOAD(0, p + PACK_V0 + PSF_BVH_WIDTH);
  const bvh_floatw fz = (bvh_floatw)(org.z) - BVH_VLOAD(0, p + PACK_V0 + 2 * PSF_BVH_WIDTH);
  const bvh_floatw r = BVH_VLOAD(0, p + PACK_E1);
  const bvh_floatw b = -(fx * dx + fy * dy + fz * dz);
  const bvh_floatw lx = fx + b * dx, ly = fy + b * dy, lz = fz + b * dz;
  const bvh_floatw r2 = r * r;
  const bvh_floatw disc = r2 - (lx * lx + ly * ly + lz * lz);
  const bvh_floatw c = (fx * fx + fy * fy + fz * fz) - r2;
  const bvh_floatw q = b + copysign(sqrt(fmax(disc, 0.0f)), b);
  return sphere_roots(c * inv_len / q, q * inv_len, (disc >= 0.0f) & (r > 0.0f), tmin, tmax, t_out);
}

/* The test with f, b, disc and c in double where the device has it. */
BVH_INLINE uint sphere_pack_test_double(__global const float* p, float3 org, float3 dir, float dir_len, float tmin,
                                        float tmax, bvh_floatw* t_out) {
  SPHERE_SCALAR len = sqrt((SPHERE_SCALAR)dir.x * dir.x + (SPHERE_SCALAR)dir.y * dir.y + (SPHERE_SCALAR)dir.z * dir.z);
  SPHERE_SCALAR inv_len = (SPHERE_SCALAR)1 / len;
  SPHERE_SCALAR dx = dir.x * inv_len, dy = dir.y * inv_len, dz = dir.z * inv_len;
  sphere_realw fx = (SPHERE_SCALAR)org.x - SPHERE_REAL(BVH_VLOAD(0, p + PACK_V0));
  sphere_realw fy = (SPHERE_SCALAR)org.y - SPHERE_REAL(BVH_VLOAD(0, p + PACK_V0 + PSF_BVH_WIDTH));
  sphere_realw fz = (SPHERE_SCALAR)org.z - SPHERE_REAL(BVH_VLOAD(0, p + PACK_V0 + 2 * PSF_BVH_WIDTH));
  bvh_floatw rf = BVH_VLOAD(0, p + PACK_E1);
  sphere_realw r = SPHERE_REAL(rf);
  sphere_realw b = -(fx * dx + fy * dy + fz * dz);
  sphere_realw lx = fx + b * dx, ly = fy + b * dy, lz = fz + b * dz;
  sphere_realw r2 = r * r;
  sphere_realw disc = r2 - (lx * lx + ly * ly + lz * lz);
  sphere_realw c = (fx * fx + fy * fy + fz * fz) - r2;
  /* The root and the division in float: b, disc and c carry what double
   * buys (their cancellations), q = b + sign(b) sqrt(disc) adds two numbers of
   * one sign, and a double square root and division of eight lanes were a
   * fifth of sphere-light's closest-hit casts. q = 0: t0 NaN, which fails below. */
  const bvh_floatw bf = SPHERE_FLOATW(b), discf = SPHERE_FLOATW(disc);
  const bvh_floatw q = bf + copysign(sqrt(fmax(discf, 0.0f)), bf);
  const float inv_lenf = (float)inv_len;
  bvh_intw hit = SPHERE_INTW(disc >= (sphere_realw)(0)) & (rf > 0.0f);
  return sphere_roots(SPHERE_FLOATW(c) * inv_lenf / q, q * inv_lenf, hit, tmin, tmax, t_out);
}

/* The pack's test: in double where its e1_y[0] says a sphere needs it. */
BVH_INLINE uint sphere_pack_test_body(__global const float* p, float3 org, float3 dir, float dir_len, float tmin,
                                      float tmax, bvh_floatw* t_out) {
  if (p[PACK_E1 + PSF_BVH_WIDTH] != 0.0f) return sphere_pack_test_double(p, org, dir, dir_len, tmin, tmax, t_out);
  return sphere_pack_test_float(p, org, dir, dir_len, tmin, tmax, t_out);
}
SPHERE_TEST_PLACEMENT uint sphere_pack_test(__global const float* p, float3 org, float3 dir, float dir_len,
                                            float tmin, float tmax, bvh_floatw* t_out) {
  return sphere_pack_test_body(p, org, dir, dir_len, tmin, tmax, t_out);
}

/* How a traversal tests sphere packs (intersect_closest_leaves' `spheres`):
 * not at all (the BVH holds none, and the code is left out), by
 * sphere_pack_test (out of line on CPUs, so that a traversal that meets no
 * sphere leaf does not pay for its hoisted normalisation; double or float by
 * the pack), or inlined (the lanes' casts of a scene with spheres: no call,
 * around which a CPU's caller spills its vectors; sphere-light 6 % faster),
 * in double, or in float where no sphere of the BVH needs double: one test
 * inlined (both, with the pack's branch between them, made sphere-light's
 * renders 4 % slower than the float test alone). */
#define PSF_SPHERES_NONE 0u
#define PSF_SPHERES_CALL 1u
#define PSF_SPHERES_INLINE 2u
#define PSF_SPHERES_INLINE_FLOAT 3u /* inlined, in float: the BVH's spheres need no double */

/* Whether pack `p` holds spheres (its first lane, always used, says). */
inline bool pack_is_spheres(__global const float* p) {
  return (((__global const uint*)(p + PACK_PRIM))[0] & PSF_PRIM_SPHERE) != 0u;
}

/* Records lane k of a pack test in *hit. */
BVH_INLINE void pack_take(__global const float* p, uint k, bvh_floatw t, bvh_floatw u, bvh_floatw v, Hit* hit) {
  float tl[PSF_BVH_WIDTH], ul[PSF_BVH_WIDTH], vl[PSF_BVH_WIDTH];
  BVH_VSTORE(t, 0, tl);
  BVH_VSTORE(u, 0, ul);
  BVH_VSTORE(v, 0, vl);
  hit->t = tl[k];
  hit->u = ul[k];
  hit->v = vl[k];
  hit->prim = ((__global const uint*)(p + PACK_PRIM))[k] & ~(PSF_PRIM_MASKED | PSF_PRIM_SPHERE);
}

/* The null-boundary crossings of one shadow ray (record_null_crossing): ray
 * parameters in ascending order and tags 2 material + 1 if entering. A ray
 * that crosses more than PSF_NULL_CROSSINGS boundaries keeps the nearest and
 * counts the others in `dropped` (shade.cl shadow_cast casts again for them). */
#define PSF_NULL_CROSSINGS 16u
typedef struct {
  float t[PSF_NULL_CROSSINGS];
  uint tag[PSF_NULL_CROSSINGS];
  uint count;   /* entries used */
  uint dropped; /* crossings left out beyond the nearest PSF_NULL_CROSSINGS */
} NullCrossings;

/* The scene data the alpha test reads (masked kernels); a null pointer to it
 * means no alpha testing, which the compiler removes after inlining. */
typedef struct {
  __global const uint* tri_material;
  __global const Material* materials;
  __global const TriAttrib* attribs;
  __global const TextureInfo* textures;
  __global const half* texels;
  /* Null: null boundaries are hits. Else any-hit casts pass them and record
   * each crossing here (record_null_crossing), for shade.cl's shadow_cast. */
  NullCrossings* crossings;
} AlphaScene;

/* A crossing at ray parameter t of null-boundary material `material`, entering
 * its shape or leaving it, into the record: the crossings are kept in order of
 * t, the nearest PSF_NULL_CROSSINGS of them (the traversal meets them in any
 * order); one beyond those is counted in `dropped`. */
inline void record_null_crossing(NullCrossings* c, float t, uint material, bool entering) {
  uint n = c->count;
  if (n == PSF_NULL_CROSSINGS) {
    ++c->dropped;
    if (t >= c->t[n - 1u]) return;
    --n; /* the farthest makes room */
  }
  uint i = n;
  for (; i > 0u && c->t[i - 1u] > t; --i) {
    c->t[i] = c->t[i - 1u];
    c->tag[i] = c->tag[i - 1u];
  }
  c->t[i] = t;
  c->tag[i] = 2u * material + (entering ? 1u : 0u);
  c->count = n + 1u;
}

/* The null-boundary crossings of lane k of a pack within (tmin, tmax): a
 * triangle's at t, entering where the ray meets its front (geometric normal e1 x
 * e2, outward; Material.interior lies behind it); a sphere's at both roots in
 * range, the nearer entering (host/scene tessellates spheres whose normals point
 * inwards). A ray through an edge crosses both triangles that share it
 * (pack_test widens them so that none slips between): shadow_cast counts such
 * a pair once. */
inline void pack_null_crossings(__global const float* p, uint k, float t, uint material, float3 org, float3 dir,
                                float dir_len, float tmin, float tmax, NullCrossings* crossings) {
  if (((__global const uint*)(p + PACK_PRIM))[k] & PSF_PRIM_SPHERE) {
    const float3 c = (float3)(p[PACK_V0 + k], p[PACK_V0 + PSF_BVH_WIDTH + k], p[PACK_V0 + 2 * PSF_BVH_WIDTH + k]);
    const float r = p[PACK_E1 + k];
    /* Haines et al.'s form (sphere_pack_test) in float: null spheres hold media,
     * not the ground planes of radius 1e5 that needed double there. */
    const float3 d = dir / dir_len, f = org - c;
    const float b = -dot(f, d);
    const float3 l = f + b * d;
    const float disc = r * r - dot(l, l);
    if (!(disc >= 0.0f)) return;
    const float q = b + copysign(sqrt(disc), b);
    const float t0 = (dot(f, f) - r * r) / q / dir_len, t1 = q / dir_len;
    const float tn = fmin(t0, t1), tf = fmax(t0, t1);
    if (tn > tmin && tn < tmax) record_null_crossing(crossings, tn, material, true);
    if (tf > tmin && tf < tmax) record_null_crossing(crossings, tf, material, false);
    return;
  }
  const float3 e1 = (float3)(p[PACK_E1 + k], p[PACK_E1 + PSF_BVH_WIDTH + k], p[PACK_E1 + 2 * PSF_BVH_WIDTH + k]);
  const float3 e2 = (float3)(p[PACK_E2 + k], p[PACK_E2 + PSF_BVH_WIDTH + k], p[PACK_E2 + 2 * PSF_BVH_WIDTH + k]);
  record_null_crossing(crossings, t, material, dot(cross(e1, e2), dir) < 0.0f);
}

/* Whether the hit at barycentrics (b1, b2) on masked triangle `prim` of material m is opaque. */
inline bool alpha_opaque(const AlphaScene* as, __global const Material* m, uint prim, float b1, float b2, float3 org,
                         float3 dir) {
  float opacity = m->opacity;
  uint tex = m->tex_opacity;
  if (tex != PSF_NO_TEXTURE) {
    __global const TriAttrib* a = as->attribs + prim;
    float4 uv01 = a->uv01;
    float2 uv = (1.0f - b1 - b2) * uv01.xy + b1 * uv01.zw + b2 * (float2)(a->u2, a->v2);
    opacity *= texture_eval(as->textures, as->texels, tex, uv).x;
  }
  if (opacity >= 1.0f) return true;
  if (opacity <= 0.0f) return false;
  uint h = psf_hash_combine(psf_hash_combine(psf_hash_combine(psf_hash(prim), as_uint(org.x)), as_uint(org.y) ^ as_uint(dir.x)),
                            as_uint(org.z) ^ as_uint(dir.y) ^ as_uint(dir.z));
  return opacity > bits_to_float(h);
}

/* Removes from a pack test's lane mask the masked triangles whose hit is cut out
 * (their t becomes infinity), and null boundaries where `as` has a record of
 * crossings, adding theirs to it. */
BVH_INLINE uint alpha_filter(__global const float* p, uint mask, bvh_floatw* t, bvh_floatw u, bvh_floatw v,
                             const AlphaScene* as, float3 org, float3 dir, float dir_len, float tmin, float tmax) {
  __global const int* prims = (__global const int*)(p + PACK_PRIM);
#if PSF_BVH_WIDTH == 8
  uint masked = mask & bvh_lane_mask(vload8(0, prims) < (int8)(0));
#else
  uint masked = mask & bvh_lane_mask(vload4(0, prims) < (int4)(0));
#endif
  if (masked == 0u) return mask;
  float tl[PSF_BVH_WIDTH], ul[PSF_BVH_WIDTH], vl[PSF_BVH_WIDTH];
  BVH_VSTORE(*t, 0, tl);
  BVH_VSTORE(u, 0, ul);
  BVH_VSTORE(v, 0, vl);
  while (masked != 0u) {
    uint k = bvh_first_lane(masked);
    masked &= masked - 1u;
    const uint prim = (uint)prims[k] & ~(PSF_PRIM_MASKED | PSF_PRIM_SPHERE), material = as->tri_material[prim];
    __global const Material* m = as->materials + material;
    if (m->flags & PSF_MATFLAG_NULL_BOUNDARY) {
      if (as->crossings) {
        pack_null_crossings(p, k, tl[k], material, org, dir, dir_len, tmin, tmax, as->crossings);
        mask &= ~(1u << k);
        tl[k] = INFINITY;
      }
      continue;
    }
    if (!alpha_opaque(as, m, prim, ul[k], vl[k], org, dir)) {
      mask &= ~(1u << k);
      tl[k] = INFINITY;
    }
  }
  *t = BVH_VLOAD(0, tl);
  return mask;
}

/* The closest hit among a leaf's packs [first, end), updating *hit; `spheres`:
 * how to test those that hold spheres (the traversal's constant, so that only
 * its test is compiled), `leaf_spheres`: whether any does (PSF_LEAF_SPHERES). */
BVH_INLINE void leaf_closest(__global const BvhTriPack* packs, uint first, uint end, uint spheres, bool leaf_spheres,
                             float3 org, float3 dir, float dir_len, float tmin, Hit* hit, const AlphaScene* as) {
  for (uint k = first; k < end; ++k) {
    __global const float* p = (__global const float*)(packs + k);
    bvh_floatw t, u, v;
    uint mask;
    if (spheres != PSF_SPHERES_NONE && leaf_spheres && pack_is_spheres(p)) {
      mask = spheres == PSF_SPHERES_INLINE         ? sphere_pack_test_double(p, org, dir, dir_len, tmin, hit->t, &t)
             : spheres == PSF_SPHERES_INLINE_FLOAT ? sphere_pack_test_float(p, org, dir, dir_len, tmin, hit->t, &t)
                                                   : sphere_pack_test(p, org, dir, dir_len, tmin, hit->t, &t);
      u = v = (bvh_floatw)(0.0f);
    } else {
      mask = pack_test(p, org, dir, dir_len, tmin, hit->t, &t, &u, &v);
    }
    if (mask == 0u) continue;
    if (as) {
      mask = alpha_filter(p, mask, &t, u, v, as, org, dir, dir_len, tmin, hit->t);
      if (mask == 0u) continue;
    }
    /* Several lanes hit: the nearest (the other lanes hold infinity). */
    if (mask & (mask - 1u)) mask = bvh_lane_mask(t == (bvh_floatw)(BVH_HMIN(t)));
    uint lane = bvh_first_lane(mask);
    pack_take(p, lane, t, u, v, hit);
  }
}

/* A miss of `ray`: t at its tmax. */
inline Hit hit_none(Ray ray) {
  Hit hit;
  hit.t = ray.dir.w;
  hit.prim = PSF_NO_HIT;
  hit.u = 0.0f;
  hit.v = 0.0f;
  return hit;
}

/* The closest hit of `ray` (see the file comment); alpha-tested if `as` is not
 * null; sphere packs tested as `spheres` (PSF_SPHERES_*) says: with
 * PSF_SPHERES_NONE (the BVH holds none) their code, and the call to
 * sphere_pack_test around which a CPU's caller spills its vectors, is left out. */
BVH_INLINE Hit intersect_closest_leaves(__global const BvhNode* nodes, __global const BvhTriPack* packs, Ray ray,
                                        const AlphaScene* as, uint spheres) {
  Hit hit = hit_none(ray);
  float tmin = ray.org.w;
  if (!(ray.dir.w >= 0.0f)) return hit;
  float3 org = ray.org.xyz, dir = ray.dir.xyz;
  float dir_len = length(dir);
  SlabRay s = slab_ray(org, dir);

  uint stack_ref[PSF_BVH_STACK];   /* child references: node index or leaf */
  float stack_t[PSF_BVH_STACK];    /* their entry distances */
  int sp = 0;
  uint ref = 0u;                   /* the root */
  for (;;) {
    if (ref & PSF_LEAF_BIT) {
      uint first = ref & PSF_LEAF_FIRST_MASK;
      uint end = first + ((ref >> PSF_LEAF_COUNT_SHIFT) & PSF_LEAF_COUNT_MASK) + 1u;
      leaf_closest(packs, first, end, spheres, (ref & PSF_LEAF_SPHERES) != 0u, org, dir, dir_len, tmin, &hit, as);
    } else {
      __global const float* f = (__global const float*)(nodes + ref);
      bvh_floatw tn;
      uint mask = slab_test(f, &s, tmin, hit.t, &tn);
      if (mask != 0u) {
        float tnear[PSF_BVH_WIDTH];
        BVH_VSTORE(tn, 0, tnear);
        __global const uint* child = (__global const uint*)(f + BVH_CHILD);
        uint k0 = bvh_first_lane(mask);
        mask &= mask - 1u;
        if (mask == 0u) {  /* one child hit: descend without the stack */
          ref = child[k0];
          continue;
        }
        uint k1 = bvh_first_lane(mask);
        mask &= mask - 1u;
        float d0 = tnear[k0], d1 = tnear[k1];
        uint c0 = child[k0], c1 = child[k1];
        if (mask == 0u) {  /* two: push the farther, descend into the nearer */
          bool swap = d1 < d0;
          stack_ref[sp] = swap ? c0 : c1;
          stack_t[sp] = swap ? d0 : d1;
          ++sp;
          ref = swap ? c1 : c0;
          continue;
        }
        const uint k2 = bvh_first_lane(mask);
        mask &= mask - 1u;
        if ((mask & (mask - 1u)) == 0u) {
          /* Three or four: a sorting network far to near (Knuth, TAOCP vol. 3,
           * Sec. 5.3.4: five comparators for four, the fourth at -infinity when
           * there are three) of selects, where an insertion sort's loop exits
           * were mispredicted; push all but the nearest and descend into it. */
          float d2 = tnear[k2], d3 = -INFINITY;
          uint c2 = child[k2], c3 = 0u;
          const bool four = mask != 0u;
          if (four) {
            const uint k3 = bvh_first_lane(mask);
            d3 = tnear[k3];
            c3 = child[k3];
          }
          BVH_SORT2(d0, c0, d1, c1);
          BVH_SORT2(d2, c2, d3, c3);
          BVH_SORT2(d0, c0, d2, c2);
          BVH_SORT2(d1, c1, d3, c3);
          BVH_SORT2(d1, c1, d2, c2);
          stack_ref[sp] = c0;
          stack_t[sp] = d0;
          stack_ref[sp + 1] = c1;
          stack_t[sp + 1] = d1;
          stack_ref[sp + 2] = c2; /* the nearest of three: above the stack's top, not pushed */
          stack_t[sp + 2] = d2;
          sp += four ? 3 : 2;
          ref = four ? c3 : c2;
          continue;
        }
        mask |= (1u << k0) | (1u << k1) | (1u << k2);
#if PSF_BVH_WIDTH == 8
        /* Five or more: the node's eight slots sorted far to near at once, the
         * slots not hit at -infinity, so the hit ones lead; push all but the
         * nearest and descend into it. */
        float8 d = select((float8)(-INFINITY), tn,
                          (((int8)((int)mask)) & (int8)(1, 2, 4, 8, 16, 32, 64, 128)) != (int8)(0));
        uint8 c = vload8(0, child);
        bvh_sort_far_first(&d, &c);
        vstore8(d, 0, stack_t + sp); /* up to index 7 L at level L: within the stack */
        vstore8(c, 0, stack_ref + sp);
        sp += (int)popcount(mask) - 1;
        ref = stack_ref[sp];
#else
        /* Four children at most in a BVH4: not reached. */
        ref = c0;
#endif
        continue;
      }
    }
    /* Pop the nearest entry not beyond the closest hit found so far. */
    do {
      if (sp == 0) return hit;
      --sp;
    } while (stack_t[sp] > hit.t);
    ref = stack_ref[sp];
  }
}

/* The closest hit of `ray`, alpha-tested if `as` is not null. */
BVH_INLINE Hit intersect_closest_alpha(__global const BvhNode* nodes, __global const BvhTriPack* packs, Ray ray,
                                       const AlphaScene* as) {
  return intersect_closest_leaves(nodes, packs, ray, as, PSF_SPHERES_CALL);
}

/* The closest hit of `ray` (see the file comment). */
inline Hit intersect_closest(__global const BvhNode* nodes, __global const BvhTriPack* packs, Ray ray) {
  return intersect_closest_alpha(nodes, packs, ray, 0);
}

/* Some hit of `ray` within (tmin, tmax), prim PSF_NO_HIT when there is none;
 * alpha-tested if `as` is not null; `spheres` as intersect_closest_leaves'. */
BVH_INLINE Hit intersect_any_hit_leaves(__global const BvhNode* nodes, __global const BvhTriPack* packs, Ray ray,
                                        const AlphaScene* as, uint spheres) {
  Hit hit = hit_none(ray);
  float tmin = ray.org.w;
  if (!(ray.dir.w >= 0.0f)) return hit;
  float3 org = ray.org.xyz, dir = ray.dir.xyz;
  float dir_len = length(dir);
  SlabRay s = slab_ray(org, dir);

  uint stack_ref[PSF_BVH_STACK];
  int sp = 0;
  uint ref = 0u; /* the root */
  for (;;) {
    if (ref & PSF_LEAF_BIT) {
      uint first = ref & PSF_LEAF_FIRST_MASK;
      uint end = first + ((ref >> PSF_LEAF_COUNT_SHIFT) & PSF_LEAF_COUNT_MASK) + 1u;
      const bool leaf_spheres = (ref & PSF_LEAF_SPHERES) != 0u;
      for (uint k = first; k < end; ++k) {
        __global const float* p = (__global const float*)(packs + k);
        bvh_floatw t, u, v;
        uint mask;
        if (spheres != PSF_SPHERES_NONE && leaf_spheres && pack_is_spheres(p)) {
          mask = spheres == PSF_SPHERES_INLINE ? sphere_pack_test_double(p, org, dir, dir_len, tmin, hit.t, &t)
                 : spheres == PSF_SPHERES_INLINE_FLOAT
                     ? sphere_pack_test_float(p, org, dir, dir_len, tmin, hit.t, &t)
                     : sphere_pack_test(p, org, dir, dir_len, tmin, hit.t, &t);
          u = v = (bvh_floatw)(0.0f);
        } else {
          mask = pack_test(p, org, dir, dir_len, tmin, hit.t, &t, &u, &v);
        }
        if (mask != 0u && as) mask = alpha_filter(p, mask, &t, u, v, as, org, dir, dir_len, tmin, hit.t);
        if (mask != 0u) {
          pack_take(p, bvh_first_lane(mask), t, u, v, &hit);
          return hit;
        }
      }
    } else {
      __global const float* f = (__global const float*)(nodes + ref);
      bvh_floatw tn;
      uint mask = slab_test(f, &s, tmin, hit.t, &tn);
      if (mask != 0u) {
        /* Descend into the last hit child at once and push the others (the
         * order of pushing them all and popping the last, without its store
         * and load, and no stack at all for a single child). */
        __global const uint* child = (__global const uint*)(f + BVH_CHILD);
        const uint last = 31u - clz(mask);
        mask &= ~(1u << last);
        while (mask != 0u) {
          uint k = bvh_first_lane(mask);
          mask &= mask - 1u;
          stack_ref[sp++] = child[k];
        }
        ref = child[last];
        continue;
      }
    }
    if (sp == 0) return hit;
    ref = stack_ref[--sp];
  }
}

/* Some hit of `ray` within (tmin, tmax), alpha-tested if `as` is not null. */
BVH_INLINE Hit intersect_any_hit_alpha(__global const BvhNode* nodes, __global const BvhTriPack* packs, Ray ray,
                                       const AlphaScene* as) {
  return intersect_any_hit_leaves(nodes, packs, ray, as, PSF_SPHERES_CALL);
}

/* Some hit of `ray` within (tmin, tmax), prim PSF_NO_HIT when there is none. */
inline Hit intersect_any_hit(__global const BvhNode* nodes, __global const BvhTriPack* packs, Ray ray) {
  return intersect_any_hit_alpha(nodes, packs, ray, 0);
}

/* Whether anything blocks `ray` within (tmin, tmax). */
inline bool intersect_any(__global const BvhNode* nodes, __global const BvhTriPack* packs, Ray ray) {
  return intersect_any_hit(nodes, packs, ray).prim != PSF_NO_HIT;
}

/* The casts of a RayCaster. `spheres` 0: the BVH holds no sphere packs, and
 * the traversal without their code runs (intersect_closest_leaves). */
__kernel void raycast_closest(__global const BvhNode* nodes, __global const BvhTriPack* packs,
                              __global const Ray* rays, __global Hit* hits, uint count, uint spheres) {
  uint i = get_global_id(0);
  if (i >= count) return;
  hits[i] = spheres ? intersect_closest_leaves(nodes, packs, rays[i], 0, PSF_SPHERES_CALL)
                    : intersect_closest_leaves(nodes, packs, rays[i], 0, PSF_SPHERES_NONE);
}

__kernel void raycast_any(__global const BvhNode* nodes, __global const BvhTriPack* packs,
                          __global const Ray* rays, __global Hit* hits, uint count, uint spheres) {
  uint i = get_global_id(0);
  if (i >= count) return;
  hits[i] = spheres ? intersect_any_hit_leaves(nodes, packs, rays[i], 0, PSF_SPHERES_CALL)
                    : intersect_any_hit_leaves(nodes, packs, rays[i], 0, PSF_SPHERES_NONE);
}

/* raycast_closest and raycast_any with alpha testing of masked triangles. */
__kernel void raycast_closest_masked(__global const BvhNode* nodes, __global const BvhTriPack* packs,
                                     __global const Ray* rays, __global Hit* hits, uint count, uint spheres,
                                     __global const uint* tri_material, __global const Material* materials,
                                     __global const TriAttrib* attribs, __global const TextureInfo* textures,
                                     __global const half* texels) {
  uint i = get_global_id(0);
  if (i >= count) return;
  AlphaScene as = {tri_material, materials, attribs, textures, texels, 0};
  hits[i] = spheres ? intersect_closest_leaves(nodes, packs, rays[i], &as, PSF_SPHERES_CALL)
                    : intersect_closest_leaves(nodes, packs, rays[i], &as, PSF_SPHERES_NONE);
}

__kernel void raycast_any_masked(__global const BvhNode* nodes, __global const BvhTriPack* packs,
                                 __global const Ray* rays, __global Hit* hits, uint count, uint spheres,
                                 __global const uint* tri_material, __global const Material* materials,
                                 __global const TriAttrib* attribs, __global const TextureInfo* textures,
                                 __global const half* texels) {
  uint i = get_global_id(0);
  if (i >= count) return;
  AlphaScene as = {tri_material, materials, attribs, textures, texels, 0};
  hits[i] = spheres ? intersect_any_hit_leaves(nodes, packs, rays[i], &as, PSF_SPHERES_CALL)
                    : intersect_any_hit_leaves(nodes, packs, rays[i], &as, PSF_SPHERES_NONE);
}
