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
/* After the generator matrices (PSF_SOBOL_BITS x PSF_SOBOL_DIMS uints), the
 * sobol buffer holds the xors of each nibble's columns: for nibble n (index
 * bits 4n..4n+3) and its value c, dimension d's entry at
 * PSF_SOBOL_NIBBLES + (16 n + c) PSF_SOBOL_DIMS + d (host/sampling.cpp). */
#define PSF_SOBOL_NIBBLES (PSF_SOBOL_BITS * PSF_SOBOL_DIMS)

/* Sample dimensions: 0,1 pixel position; with a thin lens 2,3 the point on the
 * lens; then PSF_DIMS_PER_BOUNCE per bounce from FrameParams.dim_bounce0 (2, or 4
 * with a lens). Moving the bounces of pinhole renders to 4 made the Cornell box's
 * relMSE at 16 spp 1.5x higher: the first bounces keep Sobol dimensions 2 on. */
#define PSF_DIM_PIXEL 0
#define PSF_DIM_LENS 2
#define PSF_DIM_BOUNCE0 2
#define PSF_DIM_BOUNCE0_LENS 4
#define PSF_DIMS_PER_BOUNCE 7
#define PSF_DIM_LIGHT_SELECT 0 /* offset within a bounce: which emitter */
#define PSF_DIM_LIGHT_UV 1     /* two dimensions: point on the emitter */
#define PSF_DIM_BSDF_UV 3      /* two dimensions: BSDF direction */
#define PSF_DIM_RR 5           /* Russian roulette */
#define PSF_DIM_BSDF_LOBE 6    /* BSDF lobe choice (reflection or transmission, specular or diffuse) */

/* Radix sort (sort.cl): the scan of the digit counts runs in blocks of
 * PSF_SCAN_BLOCK entries, each by one work-group of PSF_SCAN_LOCAL work-items. */
#define PSF_SCAN_LOCAL 256u
#define PSF_SCAN_BLOCK 1024u
/* GPUs' radix sort (sort.cl, radix_tile_*): tiles of PSF_TILE_LOCAL *
 * PSF_TILE_PER_ITEM pairs, one a work-group, ranked by 4-bit digit in local memory. */
#define PSF_TILE_LOCAL 256u
#define PSF_TILE_PER_ITEM 8u
#define PSF_TILE (PSF_TILE_LOCAL * PSF_TILE_PER_ITEM)
/* The tile kernel's table of (digit, work-item) ranks: 16 digits, one word of
 * padding every 16 entries. */
#define PSF_TILE_RANKS_PADDED (16u * PSF_TILE_LOCAL + PSF_TILE_LOCAL)
/* filter.cl's filter_max_count: counts per work-item. */
#define PSF_MAX_COUNT_CHUNK 256u

#define PSF_NO_HIT 0xFFFFFFFFu
/* Bit of BvhTriPack.prim marking an alpha-tested triangle (a mask material):
 * raycast.cl's masked kernels test its opacity; hits report the prim without it. */
#define PSF_PRIM_MASKED 0x80000000u
/* Bit of BvhTriPack.prim marking a sphere pack's lanes (every lane of a pack is
 * one kind): v0 holds the centre, e1_x the radius (0 in unused lanes, never hit),
 * e1_y[0] 1 where a sphere of the pack needs the test in double precision
 * (host/bvh.cpp sphere_needs_double, raycast.cl sphere_pack_test), else 0, the
 * other arrays are unused; hits report the prim without it, and u = v = 0
 * (shade.cl computes the sphere's uv). Scene primitives are the triangles, then
 * the analytic spheres: prim >= FrameParams.first_sphere is sphere
 * prim - first_sphere. */
#define PSF_PRIM_SPHERE 0x40000000u
#define PSF_EMPTY_CHILD 0xFFFFFFFFu
/* A BVH child reference with this bit set is a leaf: bits 0..26 its first
 * triangle pack (BvhTriPack), bits 27..29 the number of packs minus one, bit 30
 * (PSF_LEAF_SPHERES) set when some of its packs hold spheres, so that the
 * leaves of triangles alone never look at a pack's kind. */
#define PSF_LEAF_BIT 0x80000000u
#define PSF_LEAF_SPHERES 0x40000000u
#define PSF_LEAF_MAX_TRIS 16u /* triangles in a leaf at most */
#define PSF_LEAF_COUNT_SHIFT 27u
#define PSF_LEAF_COUNT_MASK 0x7u /* packs minus one, after the shift: 8 packs at most */
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
 * t downwards) has direction forward + (2s-1) right + (2t-1) down. A thin lens
 * (aperture > 0, Mitsuba's thinlens) starts the ray at a point of the lens disk
 * of that radius around origin, perpendicular to forward, towards the point the
 * pinhole ray reaches at distance `focus` along forward. An orthographic camera
 * (Mitsuba's orthographic) sends parallel rays instead. */
typedef struct {
  psf_float4 origin;  /* xyz eye position (the lens's centre); w: near clip distance along forward */
  psf_float4 forward; /* xyz view direction, unit length; w: far clip distance along forward */
  psf_float4 right;   /* xyz half-width of the film at distance 1; w: the image's first column in the film */
  psf_float4 down;    /* xyz half-height of the film at distance 1; w: the image's first row in the film */
  psf_uint width;     /* film width in pixels (the image is the film, or a crop window of it) */
  psf_uint height;    /* film height in pixels */
  float aperture;     /* lens radius; 0: a pinhole */
  float focus;        /* distance of the plane in focus along forward (thin lens) */
  psf_uint orthographic; /* 1: parallel rays along forward from origin + (2s-1) right + (2t-1) down
                            (right and down then the film's world-space half extents) */
  psf_uint filter;    /* pixel filter, PSF_PIXEL_FILTER_*: each axis of a sample's offset from its pixel's
                         centre is drawn from it (filter importance sampling; camera.cl) */
  float filter_a;     /* box: half-width (0: 0.5); tent: radius; gaussian: sqrt(2) stddev */
  float filter_b;     /* gaussian: erf(radius / (sqrt(2) stddev)), where it is cut off */
  float shift_s;      /* Mitsuba's principal point offset: the film point (s, t) looks along (s + shift_s, */
  float shift_t;      /* t + shift_t) (perspective only; fractions of the film's width and height) */
  psf_uint pad0;      /* padding */
  psf_uint pad1;
} Camera;

/* Camera.filter: Mitsuba's reconstruction filters with no negative lobes. */
#define PSF_PIXEL_FILTER_BOX 0u
#define PSF_PIXEL_FILTER_TENT 1u
#define PSF_PIXEL_FILTER_GAUSSIAN 2u

/* Material types (Material.type): Mitsuba's BSDF plugins of the same names
 * (kernels/bsdf.cl has the equations). */
#define PSF_MATERIAL_DIFFUSE 0u          /* diffuse: Lambertian */
#define PSF_MATERIAL_CONDUCTOR 1u        /* conductor: smooth mirror, complex Fresnel */
#define PSF_MATERIAL_ROUGH_CONDUCTOR 2u  /* roughconductor: microfacet reflection, complex Fresnel */
#define PSF_MATERIAL_PLASTIC 3u          /* plastic: smooth dielectric coating on a diffuse base */
#define PSF_MATERIAL_ROUGH_PLASTIC 4u    /* roughplastic: rough coating on a diffuse base */
#define PSF_MATERIAL_DIELECTRIC 5u       /* dielectric: smooth interface (glass, water) */
#define PSF_MATERIAL_ROUGH_DIELECTRIC 6u /* roughdielectric: microfacet reflection and refraction */
#define PSF_MATERIAL_THIN_DIELECTRIC 7u  /* thindielectric: thin sheet, straight transmission */
/* principled: Mitsuba 3's Disney-style BSDF (Burley 2012, 2015). Its parameters
 * in the Material: albedo.xyz base_color (tex_color); alpha_u, alpha_v the GGX
 * roughness of the main lobes (from roughness and anisotropic); eta = (eta,
 * 1 / eta^2, roughness, anisotropic); specular = (metallic, spec_trans,
 * spec_tint, sheen); transmittance = (sheen_tint, flatness, clearcoat,
 * clearcoat_gloss); k = the sampling rates (main specular, clearcoat, diffuse);
 * tex_alpha: a roughness texture (x), tex_table: a metallic texture (x). */
#define PSF_MATERIAL_PRINCIPLED 8u
/* pplastic: Mitsuba 3's polarized plastic as its RGB variants render it, a
 * microfacet reflection (GGX or Beckmann) added to a Lambertian base attenuated
 * by two smooth refractions, (1 - F(cos_o)) (1 - F(cos_i)). albedo.xyz
 * diffuse_reflectance (tex_color), albedo.w the specular sampling weight;
 * specular.xyz specular_reflectance; eta = (int/ext IOR, 1 / eta^2, 0, the
 * Fresnel reflectance under uniform illumination F_dr(eta), for the
 * filtering-vertex rule); alpha_u, alpha_v. */
#define PSF_MATERIAL_PPLASTIC 9u
/* principledthin: Mitsuba 3's thin principled BSDF (Burley 2015's thin-surface
 * model), a sheet with the same medium on both sides that scatters alike from
 * either: albedo.xyz base_color (tex_color); alpha_u, alpha_v the GGX roughness
 * of its specular reflection (from roughness and anisotropic, as principled's);
 * eta = (eta, 1 / eta^2, roughness, anisotropic); specular = (diff_trans / 2,
 * spec_trans, spec_tint, sheen); transmittance = (sheen_tint, flatness, and the
 * specular transmission's GGX alphas, from the roughness scaled by
 * 0.65 eta - 0.35); k = the sampling rates (specular reflection, specular
 * transmission, diffuse reflection, diffuse transmission); tex_alpha: a
 * roughness texture (x). */
#define PSF_MATERIAL_PRINCIPLED_THIN 10u

/* Material.flags */
#define PSF_MATFLAG_BECKMANN 1u  /* microfacet distribution Beckmann (else GGX) */
#define PSF_MATFLAG_NONLINEAR 2u /* plastics: Mitsuba's `nonlinear` (colour shift by internal scattering) */
#define PSF_MATFLAG_MASKED 4u    /* opacity below 1 somewhere (mask): alpha-tested during ray traversal */
#define PSF_MATFLAG_NORMALS 8u   /* some triangle of it has vertex normals (set by host/render.cpp) */
/* Conductors with tex_color: the texture is the reflectance at normal incidence
 * r, and each hit sets eta = 1, k = 2 sqrt(r / (1 - r)), specular = 1
 * (conductor_from_reflectance, bsdf.cl; pbrt-v4's conductor `reflectance`). */
#define PSF_MATFLAG_REFLECTANCE 16u
/* tex_bump is a tangent-space normal map (rgb = (n + 1) / 2, glTF's normalTexture,
 * Mitsuba 3's normalmap) instead of a height map; bump_scale scales its x and y. */
#define PSF_MATFLAG_NORMALMAP 32u
/* roughplastic with a roughness texture (tex_alpha): tex_table holds
 * PSF_ROUGH_TABLE_ROWS rows of PSF_ROUGH_TABLE_WIDTH texels, row r for the
 * roughness sqrt(alpha) = r / (PSF_ROUGH_TABLE_ROWS - 1): the external
 * transmittance by cos theta, then the internal and the external reflectance
 * (eta.z, eta.w). Each hit interpolates between the two rows around its alpha
 * (surface.cl rough_table_rows, which keeps the lower row in k.y and the upper
 * row's weight in k.x). */
#define PSF_MATFLAG_ROUGH_TABLE2D 64u
/* Material.blend names the BSDF of the back side (Mitsuba's twosided with two
 * BSDFs) instead of a random choice: the partner scatters where the hit is on
 * the back of the geometric normal, this material on the front. */
#define PSF_MATFLAG_BACK_PARTNER 128u
/* tex_alpha holds alpha_u in its x channel and alpha_v in y (anisotropic
 * roughness textures, one of them perhaps a constant; TextureStore::combine_xy). */
#define PSF_MATFLAG_ALPHA_UV 256u
/* The colour term (diffuse, plastic: albedo; conductors: specular) is multiplied
 * by the vertex colour interpolated at the hit, on triangles with PSF_TRI_COLORS
 * (set by the loaders: glTF's COLOR_0, PLY and OBJ colours, Mitsuba's
 * mesh_attribute 'vertex_color'). */
#define PSF_MATFLAG_VERTEX_COLOR 512u
/* Dielectrics: tex_color is the specular transmittance (Mitsuba's textured
 * specular_transmittance) instead of the specular reflectance. */
#define PSF_MATFLAG_TEX_TRANSMITTANCE 1024u
/* The boundary of a medium behind Mitsuba's null BSDF: a smooth dielectric of
 * relative index 1 (nothing reflected, nothing bent) whose crossing, as a null
 * interaction in Mitsuba, counts neither towards the depth nor for Russian roulette. */
#define PSF_MATFLAG_NULL_BOUNDARY 2048u
/* Set by host/render.cpp on device materials that trace_lanes shades in
 * vectors: diffuse, with nothing but a colour texture, an opacity mask, two
 * sides and vertex normals to change its frame or reflectance. */
#define PSF_MATFLAG_LANES_VECTOR 4096u
/* Largest normal-incidence reflectance conductor_from_reflectance keeps finite. */
#define PSF_MAX_REFLECTANCE 0.9999f

/* Texture index meaning "none": entry 0 of the texture table is a placeholder, so
 * that a zero-initialised Material is a plain diffuse one. */
#define PSF_NO_TEXTURE 0u

/* A surface's scattering and emission. Colours are linear RGB. */
typedef struct {
  psf_float4 albedo;        /* xyz diffuse reflectance (diffuse, plastics); w: plastics' specular sampling weight */
  psf_float4 emission;      /* xyz emitted radiance (both sides if two-sided) */
  psf_float4 specular;      /* xyz specular reflectance (conductors, plastics, dielectrics) */
  psf_float4 transmittance; /* xyz specular transmittance (dielectrics) */
  psf_float4 eta;           /* conductors: xyz real part of the relative IOR; plastics, dielectrics: x int/ext IOR,
                               y 1/x^2; plastics: z the coat's internal reflectance (F_dr(1/eta); roughplastic:
                               Mitsuba 3's), w its reflectance under uniform illumination (F_dr(eta)) */
  psf_float4 k;             /* conductors: xyz imaginary part (absorption) of the relative IOR; roughplastic with
                               PSF_MATFLAG_ROUGH_TABLE2D: x the upper table row's weight, y the lower row */
  float alpha_u;            /* microfacet roughness along the shading tangent (rough types) */
  float alpha_v;            /* microfacet roughness along the bitangent */
  psf_uint type;            /* PSF_MATERIAL_* */
  psf_uint two_sided;       /* 1: emission and scattering on both sides */
  psf_uint flags;           /* PSF_MATFLAG_* */
  psf_uint tex_color;       /* texture replacing albedo (diffuse, plastics) or specular (others), or PSF_NO_TEXTURE */
  psf_uint tex_opacity;     /* opacity texture (mask; x channel), or PSF_NO_TEXTURE */
  psf_uint tex_bump;        /* bump map height texture (x channel; with PSF_MATFLAG_NORMALMAP a normal map), or none */
  float opacity;            /* with PSF_MATFLAG_MASKED: constant opacity, times tex_opacity (mask; 1 opaque) */
  float bump_scale;         /* with tex_bump: multiplier of the heights (Mitsuba's bumpmap `scale`) */
  psf_uint tex_table;       /* roughplastic: 1 x PSF_ROUGH_TABLE_RES texture, x = external transmittance by cos theta;
                               principled: a metallic texture (x) */
  psf_uint tex_alpha;       /* roughconductor, roughdielectric: texture whose x channel is alpha (both axes; with
                               PSF_MATFLAG_ALPHA_UV alpha_u, and y alpha_v), or none; principled: roughness (x) */
  psf_uint tex_emission;    /* texture (rgb) multiplying the emission where it is hit or sampled, or PSF_NO_TEXTURE */
  /* A blend of BSDFs (glTF's metallic and transmission between 0 and 1,
   * Mitsuba's blendbsdf): 1 + the index of the material that scatters instead of
   * this one with probability blend_weight (times tex_blend's x channel at the
   * hit), 0 for none; that one may blend in turn (a chain of up to three). The
   * choice is made per shading point (surface.cl surface_blend). */
  psf_uint blend;
  float blend_weight;
  psf_uint tex_blend;       /* texture (x channel) multiplying blend_weight, or PSF_NO_TEXTURE */
  /* The homogeneous medium inside the shape (Mitsuba's interior medium, glTF's
   * KHR_materials_volume): xyz its extinction coefficient sigma_t per scene
   * unit, w 1 where there is one (the surface bounds it: a path that leaves on
   * its back side is inside), else 0. */
  psf_float4 interior;
  psf_float4 interior_albedo; /* xyz the medium's single-scattering albedo (0: it only absorbs), w its
                                 Henyey-Greenstein g (0: isotropic) */
  /* The medium outside the shape (Mitsuba's exterior): 1 + the index of a material whose interior it is (maybe one no
   * shape uses), 0 for none. A surface with an interior or an exterior medium is a transition between the two, as
   * in Mitsuba (either may be none, vacuum); any other keeps a path's medium. */
  psf_uint exterior;
  psf_uint pad_medium0, pad_medium1, pad_medium2; /* to a multiple of 16 bytes */
} Material;

/* TriAttrib.flags */
#define PSF_TRI_NORMALS 1u  /* the triangle has per-vertex shading normals */
#define PSF_TRI_TANGENTS 2u /* and tangents: n0.w, n1.w, n2.w hold each vertex's, packed (surface.cl tangent_unpack) */
#define PSF_TRI_COLORS 4u   /* and vertex colours: color0-2, linear RGB in [0, 1] as 11, 11 and 10 bits (surface.cl) */

/* Shading attributes of one triangle, in scene order. A mesh without texture
 * coordinates has uv (0,0), (1,0), (0,1) at its corners, so that uv are the
 * barycentrics (b1, b2), as in Mitsuba. */
/* With PSF_TRI_TANGENTS, n_k.w holds vertex k's unit tangent t and handedness s
 * (the normal map's frame is (t, s n x t, n), glTF's TANGENT) as uint bits: the
 * tangent's octahedral coordinates in [-1, 1], each as 15 bits (q + 16383, q =
 * round(16383 x)), in bits 0-14 and 15-29, and bit 30 set where s = -1. */
typedef struct {
  psf_float4 n0;   /* xyz unit shading normal at vertex 0 (world space), with PSF_TRI_NORMALS; w a tangent */
  psf_float4 n1;   /* at vertex 1 */
  psf_float4 n2;   /* at vertex 2 */
  psf_float4 uv01; /* xy uv at vertex 0, zw uv at vertex 1 */
  float u2;        /* uv at vertex 2 */
  float v2;
  psf_uint flags;  /* PSF_TRI_* */
  psf_uint color0; /* with PSF_TRI_COLORS: vertex 0's colour, R in bits 0-10, G 11-21, B 22-31 (unorm) */
  psf_uint color1; /* vertex 1's */
  psf_uint color2; /* vertex 2's */
  psf_uint pad0;   /* padding */
  psf_uint pad1;
} TriAttrib;

/* Entries of roughplastic's external transmittance table over cos theta in [0, 1] (as Mitsuba 3). */
#define PSF_ROUGH_TABLE_RES 64
/* The textured-roughness table (PSF_MATFLAG_ROUGH_TABLE2D): rows and their width. */
#define PSF_ROUGH_TABLE_ROWS 16
#define PSF_ROUGH_TABLE_WIDTH (PSF_ROUGH_TABLE_RES + 2)

/* TextureInfo.flags */
#define PSF_TEX_BILINEAR 1u /* bilinear filtering (else nearest texel) */
#define PSF_TEX_CLAMP 2u    /* uv outside [0,1] clamps to the border (else the image repeats) */
#define PSF_TEX_MIRROR 4u   /* the image repeats mirrored (Mitsuba's wrap_mode mirror) */

/* A texture: an image in the texel buffer, RGBA as four halfs per texel
 * (vload_half4), rows from the top of the image. uv (0,0) is the top-left corner
 * of the image and (1,1) the bottom-right, as in Mitsuba (whose OBJ loader flips v). */
typedef struct {
  psf_float4 uv_u;   /* texture u = dot(xyz, (u, v, 1)) of the surface's (u, v): Mitsuba's to_uv, uvscale/uoffset */
  psf_float4 uv_v;   /* texture v likewise */
  psf_uint offset;   /* index of the first texel in the texel buffer */
  psf_uint width;    /* texels across */
  psf_uint height;   /* texels down */
  psf_uint flags;    /* PSF_TEX_* */
} TextureInfo;

/* Emitter types (Emitter.type). */
#define PSF_EMITTER_TRIANGLE 0u    /* an emissive triangle (area light) */
#define PSF_EMITTER_POINT 1u       /* isotropic point light */
#define PSF_EMITTER_SPOT 2u        /* point light restricted to a cone */
#define PSF_EMITTER_DIRECTIONAL 3u /* parallel light from infinitely far away */
#define PSF_EMITTER_ENVIRONMENT 4u /* the Environment (envmap or constant) */
#define PSF_EMITTER_SPHERE 5u      /* an emissive analytic sphere (area light) */

/* One entry of the next-event estimation table: an emissive triangle, a delta
 * light or the environment (whose data is the Environment struct). */
typedef struct {
  psf_float4 v0;       /* triangle: xyz first vertex, w area; sphere: xyz centre, w area; point, spot: xyz position */
  psf_float4 e1;       /* triangle: xyz v1 - v0; sphere: xyz its local x axis, w radius; spot: xyz unit axis, */
                       /* w cos(cutoff); directional: xyz unit direction of travel */
  psf_float4 e2;       /* triangle: xyz v2 - v0; sphere: xyz its local y axis, w 1 or -1 (flip_normals: inwards); spot: x cutoff angle, y 1 / (cutoff - beam width) (radians), w cos(beam width) */
  psf_float4 radiance; /* xyz radiance (triangle), intensity (point, spot) or irradiance (directional); w: selection probability */
  psf_uint prim;       /* triangle, sphere: prim index in scene order */
  psf_uint two_sided;  /* triangle, sphere: 1 emits on both sides */
  psf_uint type;       /* PSF_EMITTER_* */
  psf_uint tex_emission; /* triangle, sphere: its material's tex_emission (radiance times the texture at the point) */
} Emitter;

/* The environment: radiance from infinitely far away along every direction that
 * escapes the scene. A latitude-longitude map in Mitsuba's convention (map
 * direction d = rotation * world direction; u = atan2(d.x, -d.z) / 2pi wrapped
 * to [0,1), v = acos(d.y) / pi, texel row 0 at v = 0, i.e. +y up), bilinear
 * between texels (emitter.cl env_lookup), or a constant radiance when width is
 * 0. Its data buffer (floats) holds the texels (width * height * 3, RGB,
 * row-major), then the sampling distribution over a grid of as many cells: the
 * marginal cdf over rows (height + 1), then each row's conditional distribution
 * in two levels: a cdf over its blocks of PSF_ENV_BLOCK cells (B + 1 entries per row,
 * B = ceil(width / PSF_ENV_BLOCK)), and, from the next multiple of
 * PSF_ENV_BLOCK floats on, each block's own cdf (PSF_ENV_BLOCK upper values per
 * block, row after row; 1 past the row's end), then the guide tables of the
 * marginal (height entries) and of each row's block cdf (B per row), each
 * index as its uint bits (host/lights.h cdf_guide_table). The block cdfs are small enough
 * to stay in cache, and a block's texel cdf is one cache line: a sample reads
 * one line of the conditional where a search over the whole row would wait on
 * several. */
#define PSF_ENV_BLOCK 16
/* float4s per path of the environment light samples drawn ahead of shade
 * (shade.cl env_block_slot). */
#define PSF_ENV_RECORD 3
typedef struct {
  psf_float4 to_map0;   /* rows of the world-to-map rotation (the inverse of to_world) */
  psf_float4 to_map1;
  psf_float4 to_map2;
  psf_float4 scale;     /* xyz radiance scale of the map, or the constant radiance; w: selection probability in NEE */
  psf_uint width;       /* texels across (0: constant radiance) */
  psf_uint height;      /* texels down */
  psf_uint present;     /* 1: the scene has an environment (0: escaped rays see black) */
  psf_uint pad0;        /* padding */
} Environment;

#define PSF_PATH_ALIVE 1u
#define PSF_PATH_SPECULAR 2u  /* the last bounce was a delta lobe (no MIS) */
#define PSF_PATH_VERTEX 4u    /* the path has its filtering vertex; contributions go to c */
#define PSF_PATH_VERTEX_NEW 8u /* the filtering vertex was made at this bounce */
#define PSF_PATH_NULL_CROSSED 16u /* a null boundary was crossed since the last scattering vertex */
/* Bits from PSF_PATH_MEDIUM_SHIFT up of PathState.flags: 1 + the material whose
 * interior medium the path is in (Material.interior), 0 outside every medium. */
#define PSF_PATH_MEDIUM_SHIFT 8u

/* The state of one path of the wavefront between kernel stages. */
typedef struct {
  psf_float4 throughput; /* xyz throughput from the filtering vertex (from the camera before it); w: solid-angle pdf of the last BSDF sample */
  psf_float4 radiance;   /* xyz radiance gathered before the filtering vertex, its own emission included; */
                         /* w: 0 while it is only what the camera ray hit emits (shade.cl add_radiance_seen) */
  psf_float4 vertex_radiance; /* xyz c: radiance scattered at the filtering vertex towards the camera */
  psf_float4 pending;    /* xyz next-event contribution awaiting its shadow ray; w: with FrameParams.null_media, */
                         /* the medium the shadow ray starts in (as PathState.flags' upper bits; a uint's bits) */
  psf_float4 prev_pos;   /* xyz position of the last scattering vertex (MIS of emitter hits; a null boundary */
                         /* is none); w: camera path length so far */
  psf_uint pixel;        /* film pixel index y * width + x (the film's, with a crop window): the samples' key */
  psf_uint sample;       /* sample index within the pixel (Sobol index) */
  psf_uint depth;        /* number of surface interactions so far */
  psf_uint flags;        /* PSF_PATH_* */
} PathState;

/* The vertex of a path that path space filtering uses (Keller et al. 2016, Sec. 2):
 * the first sufficiently diffuse vertex x_i along the camera path. The pixel gets
 * prefix + alpha * c, where c is replaced by its filtered mean c-bar. */
typedef struct {
  psf_float4 position; /* xyz x_i; w: camera path length d_i to it */
  psf_float4 normal;   /* xyz shading normal n_i facing the camera side; w: visibility, 1 or 0: 0 where */
                       /* something blocked the light sample, or visibility.cl's hemisphere ray */
  psf_float4 albedo;   /* xyz the BSDF's colour term at x_i; w: 0 for a path without a vertex, else its */
                       /* footprint stretch 1 / sqrt(max(|cos theta_i|, PSF_FOOTPRINT_MIN_COS)) >= 1, */
                       /* theta_i between the arriving ray and the geometric normal */
  psf_float4 alpha;    /* xyz throughput alpha_i from the camera to x_i */
} PathVertex;

/* The surface a pixel sees at distance d under an angle theta has d^2 dOmega /
 * cos theta of area: a ball of radius r0 sqrt(1 / cos theta) holds as much of
 * it as the ball of r0 holds of a surface facing the camera (FilterParams.
 * stretch). Cosines below this count as this, so that a grazing footprint,
 * a long ellipse on the surface, does not blur the image more than 2x the
 * footprint sideways. */
#define PSF_FOOTPRINT_MIN_COS 0.25f
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
  psf_uint dim_bounce0;    /* first sample dimension of the bounces: PSF_DIM_BOUNCE0, or _LENS with a thin lens */
  psf_uint hide;           /* PSF_HIDE_*: what camera rays do not see (Mitsuba's hide_emitters) */
  psf_uint first_sphere;   /* prim index of the first analytic sphere (the number of triangles) */
  psf_uint camera_medium;  /* the medium camera rays start in (PathState.flags' upper bits), 0: none */
  psf_uint max_rounds;     /* trace_paths' rounds at most: max_depth, or -1 (unbounded) where a medium's null
                              boundary is crossed without counting (a bound the compiler knows is 5 % faster) */
  psf_uint null_media;     /* 1: the scene has a medium behind a null boundary, which shadow rays pass with the
                              transmittance of the media they cross (shade.cl shadow_cast); 0: none */
  psf_uint spheres;        /* PSF_FRAME_SPHERES_*: how trace_lanes' casts test the BVH's analytic spheres */
  psf_uint flat_packs;     /* > 0: trace_lanes tests each ray against the BVH's packs, all flat_packs of them, */
                           /* without traversing it (a scene of a few primitives); 0: through the BVH */
  psf_uint pad[3];         /* to a multiple of 16 bytes */
} FrameParams;

#define PSF_FRAME_SPHERES_NONE 0u   /* the BVH holds none: casts without the test */
#define PSF_FRAME_SPHERES_DOUBLE 1u /* some sphere needs the test in double (host/bvh.cpp sphere_needs_double) */
#define PSF_FRAME_SPHERES_FLOAT 2u  /* every sphere is tested in float */

#define PSF_HIDE_ENVIRONMENT 1u /* a camera ray that escapes sees black (Mitsuba 3's hide_emitters) */
#define PSF_HIDE_AREA 2u        /* an emitter a camera ray hits adds nothing (Mitsuba 0.5's hideEmitters) */

/* Path space filtering of one batch (Keller et al. 2016, Eq. 1-2; filter.cl). */
#define PSF_NO_KEY 0xFFFFFFFFu /* key of a path without a filtering vertex */

typedef struct {
  float r0;          /* global radius r0 (--r0); <= 0: per vertex from the footprint */
  float footprint;   /* sqrt(dOmega / pi) of the footprint's solid angle: r0_i = d_i * footprint */
  float n_scale;     /* 1 / n^alpha: r(n) = r0 * n_scale */
  float normal_cos;  /* smallest <n_i, n_j> of similar vertices (0.95) */
  float albedo_tol;  /* largest |albedo_i - albedo_j| of similar vertices (0.05) */
  psf_uint count;    /* tuples in the batch */
  psf_uint key_bits; /* cell keys lie in [0, 2^key_bits) */
  psf_uint cells27;  /* 1: cells of size r searched 3x3x3; 0: cells of size 2r searched 2x2x2 */
  psf_uint stretch;  /* 1: r0_i is multiplied by the vertex's footprint stretch (albedo.w; --foreshortening) */
  psf_uint ignore_visibility; /* 1: similar vertices need not agree on visibility (--visibility-ray off) */
  psf_uint demodulate; /* 1: average c_j / albedo_j and compare albedos as log2 ratios (PSF_DEMODULATE_MIN) */
  psf_uint pad2;
} FilterParams;

/* With FilterParams.demodulate, albedo channels below this count as this. */
#define PSF_DEMODULATE_MIN 0.01f

/* The tuples of a batch in cell order: gather_tuples (tuples.cl) copies each
 * path's filtering vertex (PathVertex) with its query radius and grid level
 * into separate arrays, the PSF_SORTED_* fields of one float buffer, `stride`
 * floats apart, which filter.cl reads PSF_FILTER_LANES candidates at a time;
 * the values c_j being averaged are three more such arrays (r, g, b). Only the
 * tuples with a filtering vertex are gathered; they come first in cell order. */
#define PSF_SORTED_X 0
#define PSF_SORTED_Y 1
#define PSF_SORTED_Z 2
#define PSF_SORTED_NX 3
#define PSF_SORTED_NY 4
#define PSF_SORTED_NZ 5
#define PSF_SORTED_AR 6 /* albedo */
#define PSF_SORTED_AG 7
#define PSF_SORTED_AB 8
#define PSF_SORTED_TAG 9 /* int (read through an int pointer): 4 level + 2 visibility + 1 if c_j is finite */
#define PSF_SORTED_R 10  /* query radius r_j */
#define PSF_SORTED_FIELDS 11

/* Arrays end PSF_SORTED_PAD entries past the batch: filter.cl reads up to
 * PSF_FILTER_LANES - 1 candidates past a cell's end (and ignores them), and
 * gather_tuples writes up to PSF_GATHER_LANES - 1 past the last valid tuple. */
#define PSF_SORTED_PAD 16

/* Tuples per work-item of gather_tuples (tuples.cl). */
#define PSF_GATHER_LANES 8u

/* Queries per work-item of filter (filter.cl) on CPUs. */
#define PSF_FILTER_QUERIES 16u
#if PSF_SORTED_PAD < PSF_FILTER_QUERIES - 1 || PSF_SORTED_PAD < PSF_GATHER_LANES - 1
/* filter_cells8 loads up to PSF_FILTER_QUERIES - 1 and gather_tuples writes up to PSF_GATHER_LANES - 1 past the batch. */
#error "PSF_SORTED_PAD is less than the filter's queries or the gather's lanes reach past the batch"
#endif

/* Records a query's list holds (filter.cl filter_record): with --iterations > 1
 * the first pass records, for each query, the vectors of candidates it took
 * neighbours from, and the later passes sum those again instead of searching; a
 * query with more such vectors, or one further from the query in cell order than
 * a record can say, searches again. A list is PSF_FILTER_LIST_WORDS uints (four
 * cache lines; the few records most queries have share the first with the
 * count): the count, PSF_FILTER_LIST records of one uint each (the vector's
 * first index minus the query's, above the lanes taken), and the sink of the
 * branch-free appends. 62 records rather than 30: a batch of 64 spp of the
 * Cornell box (about 50 neighbours a vertex) overflowed most lists of 30, and
 * its 15 later passes took 11.1 s instead of 2.6 s; at 3 spp both take the
 * same (20.5 against 20.9 ms). */
#define PSF_FILTER_LIST_WORDS 64u
#define PSF_FILTER_LIST (PSF_FILTER_LIST_WORDS - 2u)

#endif /* PSF_SHARED_H */
