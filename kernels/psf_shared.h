/* psf_shared.h: every struct that crosses the host/kernel boundary.
 *
 * Included by the C++ host and by the OpenCL C kernels, so the two layouts cannot
 * drift; tests/test_layout.cpp checks sizeof/offsetof on the device against the host.
 * Rules: only float, uint, float4 and fixed arrays of them; no float3, bool, size_t
 * or pointers; padding is named; every struct is a multiple of 16 bytes.
 */
#ifndef PSF_SHARED_H
#define PSF_SHARED_H

#ifdef __OPENCL_C_VERSION__
typedef float4 psf_float4;
typedef uint psf_uint;
#else
#include <CL/cl_platform.h>
typedef cl_float4 psf_float4;
typedef cl_uint psf_uint;
#endif

#ifndef PSF_BVH_WIDTH
#define PSF_BVH_WIDTH 4
#endif

/* Number of Sobol dimensions with Joe-Kuo direction numbers; higher dimensions
 * fall back to hashed random numbers (sampling.cl). */
#define PSF_SOBOL_DIMS 256
/* Bits per Sobol coordinate (32: indices up to 2^32 per pixel). */
#define PSF_SOBOL_BITS 32

/* Sample dimensions: 0,1 pixel position; then PSF_DIMS_PER_BOUNCE per bounce. */
#define PSF_DIM_PIXEL 0
#define PSF_DIM_BOUNCE0 2
#define PSF_DIMS_PER_BOUNCE 6
#define PSF_DIM_LIGHT_SELECT 0 /* offset within a bounce: which emitter */
#define PSF_DIM_LIGHT_UV 1     /* two dimensions: point on the emitter */
#define PSF_DIM_BSDF_UV 3      /* two dimensions: BSDF direction */
#define PSF_DIM_RR 5           /* Russian roulette */

#define PSF_NO_HIT 0xFFFFFFFFu
#define PSF_EMPTY_CHILD 0xFFFFFFFFu
/* A BVH child reference with this bit set is a leaf: bits 0..26 its first
 * triangle pack (BvhTriPack), bits 27..30 the number of packs minus one. */
#define PSF_LEAF_BIT 0x80000000u
#define PSF_LEAF_MAX_TRIS 16u /* triangles in a leaf at most */
#define PSF_LEAF_COUNT_SHIFT 27u
#define PSF_LEAF_FIRST_MASK 0x07FFFFFFu
/* Deepest BVH (levels of wide nodes, root included) that host/bvh.cpp builds;
 * sizes the traversal stack of kernels/raycast.cl. */
#define PSF_BVH_MAX_DEPTH 48

/* A ray. Directions need not be normalised; t is measured in units of |dir|. */
typedef struct {
  psf_float4 org; /* xyz origin, w: tmin */
  psf_float4 dir; /* xyz direction, w: tmax */
} Ray;

/* The closest hit of a ray (or whether any hit exists, for shadow rays). */
typedef struct {
  float t;       /* ray parameter of the hit; the ray's tmax on a miss */
  psf_uint prim; /* index of the triangle in scene order, PSF_NO_HIT on a miss */
  float u;       /* barycentric coordinate of vertex 1 */
  float v;       /* barycentric coordinate of vertex 2 */
} Hit;

/* PSF_BVH_WIDTH triangles as structure of arrays, so that Moller-Trumbore tests
 * them all at once with PSF_BVH_WIDTH-wide vector arithmetic; a BVH leaf is a run
 * of packs. An unused lane has zero edges (never hit) and prim PSF_NO_HIT. */
typedef struct {
  float v0_x[PSF_BVH_WIDTH];     /* first vertex */
  float v0_y[PSF_BVH_WIDTH];
  float v0_z[PSF_BVH_WIDTH];
  float e1_x[PSF_BVH_WIDTH];     /* second vertex minus first */
  float e1_y[PSF_BVH_WIDTH];
  float e1_z[PSF_BVH_WIDTH];
  float e2_x[PSF_BVH_WIDTH];     /* third vertex minus first */
  float e2_y[PSF_BVH_WIDTH];
  float e2_z[PSF_BVH_WIDTH];
  float inv_size[PSF_BVH_WIDTH]; /* 1 / sqrt(|e1 x e2|): scales the intersection tolerance */
  psf_uint prim[PSF_BVH_WIDTH];  /* triangle index in scene order, PSF_NO_HIT if unused */
} BvhTriPack;

/* A node of a PSF_BVH_WIDTH-wide BVH: the children's boxes as structure of arrays
 * so that one node is tested with PSF_BVH_WIDTH-wide vector arithmetic. */
typedef struct {
  float min_x[PSF_BVH_WIDTH]; /* child box minima and maxima per axis; */
  float max_x[PSF_BVH_WIDTH]; /* an empty slot has min > max */
  float min_y[PSF_BVH_WIDTH];
  float max_y[PSF_BVH_WIDTH];
  float min_z[PSF_BVH_WIDTH];
  float max_z[PSF_BVH_WIDTH];
  psf_uint child[PSF_BVH_WIDTH]; /* node index, leaf (PSF_LEAF_BIT) or PSF_EMPTY_CHILD */
} BvhNode;

/* A pinhole camera: a ray through film point (s, t) in [0,1]^2 (s to the right,
 * t downwards) has direction forward + (2s-1) right + (2t-1) down. */
typedef struct {
  psf_float4 origin;  /* xyz eye position */
  psf_float4 forward; /* xyz view direction, unit length */
  psf_float4 right;   /* xyz half-width of the film at distance 1 */
  psf_float4 down;    /* xyz half-height of the film at distance 1 */
  psf_uint width;     /* film width in pixels */
  psf_uint height;    /* film height in pixels */
  psf_uint pad0;      /* padding */
  psf_uint pad1;      /* padding */
} Camera;

#define PSF_MATERIAL_DIFFUSE 0u

/* A surface's scattering and emission. */
typedef struct {
  psf_float4 albedo;   /* xyz diffuse reflectance */
  psf_float4 emission; /* xyz emitted radiance (both sides if two-sided) */
  psf_uint type;       /* PSF_MATERIAL_* */
  psf_uint two_sided;  /* 1: emission and scattering on both sides */
  psf_uint pad0;       /* padding */
  psf_uint pad1;       /* padding */
} Material;

/* An emissive triangle for next-event estimation. */
typedef struct {
  psf_float4 v0;       /* xyz first vertex, w: area */
  psf_float4 e1;       /* xyz v1 - v0 */
  psf_float4 e2;       /* xyz v2 - v0 */
  psf_float4 radiance; /* xyz emitted radiance, w: selection probability */
  psf_uint prim;       /* triangle index in scene order */
  psf_uint two_sided;  /* 1: emits on both sides */
  psf_uint pad0;       /* padding */
  psf_uint pad1;       /* padding */
} Emitter;

#define PSF_PATH_ALIVE 1u
#define PSF_PATH_SPECULAR 2u  /* the last bounce was a delta lobe (no MIS) */
#define PSF_PATH_VERTEX 4u    /* the path has its filtering vertex; contributions go to c */
#define PSF_PATH_VERTEX_NEW 8u /* the filtering vertex was made at this bounce */

/* The state of one path of the wavefront between kernel stages. */
typedef struct {
  psf_float4 throughput; /* xyz throughput from the filtering vertex (from the camera before it); w: solid-angle pdf of the last BSDF sample */
  psf_float4 radiance;   /* xyz radiance gathered before the filtering vertex, its own emission included */
  psf_float4 vertex_radiance; /* xyz c: radiance scattered at the filtering vertex towards the camera */
  psf_float4 pending;    /* xyz next-event contribution awaiting its shadow ray */
  psf_float4 prev_pos;   /* xyz position of the previous vertex (MIS of emitter hits); w: camera path length so far */
  psf_uint pixel;        /* pixel index y * width + x */
  psf_uint sample;       /* sample index within the pixel (Sobol index) */
  psf_uint depth;        /* number of surface interactions so far */
  psf_uint flags;        /* PSF_PATH_* */
} PathState;

/* The vertex of a path that path space filtering uses (Keller et al. 2016, Sec. 2):
 * the first sufficiently diffuse vertex x_i along the camera path. The pixel gets
 * prefix + alpha * c, where c is replaced by its filtered mean c-bar. */
typedef struct {
  psf_float4 position; /* xyz x_i; w: camera path length d_i to it */
  psf_float4 normal;   /* xyz shading normal n_i facing the camera side; w: light-sample visibility (1 visible, 0 not) */
  psf_float4 albedo;   /* xyz the BSDF's colour term at x_i; w: 1 if the path has the vertex, else 0 */
  psf_float4 alpha;    /* xyz throughput alpha_i from the camera to x_i */
} PathVertex;

/* Render-wide constants of one batch. */
typedef struct {
  psf_uint width;          /* film width */
  psf_uint height;         /* film height */
  psf_uint seed;           /* scrambling seed (--seed) */
  psf_uint max_depth;      /* longest path in segments, Mitsuba's convention (-1 = unbounded) */
  psf_uint first_path_lo;  /* global index of the batch's first path, low 32 bits */
  psf_uint first_path_hi;  /* high 32 bits */
  psf_uint batch_size;     /* number of paths in the batch */
  psf_uint num_emitters;   /* entries of the emitter table */
  psf_uint rr_depth;       /* Russian roulette starts at this depth */
  psf_uint pad0;           /* padding */
  psf_uint pad1;           /* padding */
  psf_uint pad2;           /* padding */
} FrameParams;

#endif /* PSF_SHARED_H */
