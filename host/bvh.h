// BVH and ray casting stage, host side: a binned SAH build of a binary BVH
// with spatial splits, collapsed into a PSF_BVH_WIDTH-wide BVH (kernels/psf_shared.h: BvhNode,
// BvhTriangle), and RayCaster, which uploads it and launches kernels/raycast.cl.
#pragma once
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "cl/runtime.h"
#include "psf_shared.h"

namespace psf {

// Build settings; the defaults are what the renderer and the benchmark use.
struct BvhParams {
  int bins = 16;                          // SAH bins per axis over the centroid bounds
  float traversal_cost = 1.0f;            // SAH cost of a binary split, in pack tests
  float intersection_cost = 1.0f;         // SAH cost of testing one BvhTriPack
  unsigned max_leaf = PSF_LEAF_MAX_TRIS;  // a node with more triangles is always split
  int threads = 0;                        // build threads (0: the machine's); the BVH is the same for any
  // Spatial splits (Stich et al. 2009): where an object split's sides overlap
  // by more than split_alpha of the root's surface area, a plane may cut
  // primitives, which are then referenced by both sides, each clipped; at most
  // split_budget times the primitives' count of references are added (and never
  // more than the leaf encoding counts: PSF_LEAF_FIRST_MASK in all), and the
  // searches cut references at bin planes at most split_cuts times per
  // primitive (the living room took 10, Sponza 21; a soup of large triangles
  // overlapping everywhere 274, for 10 references more).
  // Budgets below 0 (or NaN) allow none. (Stich et al.'s alpha of 1e-5 built
  // the living room in 194 ms instead of 98 and cast no faster.)
  bool spatial_splits = true;
  float split_alpha = 1e-3f;
  float split_budget = 0.25f;
  float split_cuts = 32.0f;
};

// An analytic sphere for the BVH: its prim index is the number of triangles
// plus its position in the list (psf_shared.h PSF_PRIM_SPHERE).
struct BvhSphere {
  glm::vec3 center{0.0f};
  float radius = 1.0f;
};

struct Bvh {
  std::vector<BvhNode> nodes;      // node 0 is the root
  std::vector<BvhTriPack> packs;   // leaf triangles, PSF_BVH_WIDTH per pack, in leaf order
  uint32_t triangle_count = 0;     // triangles in the packs (scene triangles less `skipped`)
  uint32_t sphere_count = 0;       // spheres in the packs (less those `skipped`)
  uint32_t double_spheres = 0;     // of which raycast.cl tests in double (their packs' e1_y[0])
  double build_ms = 0.0;           // wall time of build_bvh
  int depth = 0;                   // levels of wide nodes (1: the root only)
  uint32_t skipped = 0;            // degenerate or non-finite triangles and spheres left out
  uint32_t references = 0;         // primitives in the packs, counted in each leaf that holds them
};

// Builds the wide BVH over `triangles` (indices into `positions`). Triangles of
// zero area (below a relative tolerance: they can never be hit) or with
// non-finite vertices are left out; an empty scene gives a root whose slots are
// all empty. Throws std::invalid_argument on an out-of-range vertex index.
Bvh build_bvh(const std::vector<glm::vec3>& positions, const std::vector<glm::uvec3>& triangles,
              const BvhParams& params = {});
// The same over triangles and analytic spheres (prims triangles.size() + k),
// each leaf's triangles and spheres in packs of their own; spheres of radius
// <= 0 or with non-finite values are left out.
Bvh build_bvh(const std::vector<glm::vec3>& positions, const std::vector<glm::uvec3>& triangles,
              const std::vector<BvhSphere>& spheres, const BvhParams& params = {});

// Decodes a leaf child reference (PSF_LEAF_BIT set): first pack, number of packs,
// and whether some of them hold spheres.
inline uint32_t leaf_first(uint32_t child) { return child & PSF_LEAF_FIRST_MASK; }
inline uint32_t leaf_count(uint32_t child) { return ((child >> PSF_LEAF_COUNT_SHIFT) & PSF_LEAF_COUNT_MASK) + 1u; }
inline bool leaf_spheres(uint32_t child) { return (child & PSF_LEAF_SPHERES) != 0u; }
inline bool is_leaf(uint32_t child) { return child != PSF_EMPTY_CHILD && (child & PSF_LEAF_BIT); }

// Sets PSF_PRIM_MASKED on the pack lanes of the primitives with masked[prim] set
// (prim: triangles, then spheres; alpha-tested mask materials, null boundaries);
// returns how many primitives it marked (each in every leaf that holds it).
size_t mark_masked(Bvh& bvh, const std::vector<bool>& masked);

// The scene data that alpha testing reads (kernels/raycast.cl, AlphaScene).
struct AlphaBuffers {
  cl::Buffer tri_material;  // material index per triangle (uint)
  cl::Buffer materials;     // Material
  cl::Buffer attribs;       // TriAttrib per triangle (uv)
  cl::Buffer textures;      // TextureInfo
  cl::Buffer texels;        // RGBA halfs
};

// The BVH on a device and the ray casting kernels over it.
class RayCaster {
 public:
  RayCaster(Runtime& rt, const Bvh& bvh);

  // From now on casts with alpha testing of masked triangles (raycast_closest_masked,
  // raycast_any_masked); the BVH should have been marked with mark_masked.
  void enable_alpha(const AlphaBuffers& buffers) {
    alpha_ = buffers;
    masked_ = true;
  }

  // Closest hit of each of `count` rays (Ray) into `hits` (Hit): raycast_closest.
  void closest(const cl::Buffer& rays, const cl::Buffer& hits, uint32_t count);
  // Occlusion of each ray within [tmin, tmax] (shadow rays): raycast_any.
  void any(const cl::Buffer& rays, const cl::Buffer& hits, uint32_t count);

  // The BVH buffers (BvhNode, BvhTriPack), for kernels that call intersect_closest
  // or intersect_any themselves.
  const cl::Buffer& nodes() const { return nodes_; }
  const cl::Buffer& packs() const { return packs_; }
  int depth() const { return depth_; }
  uint32_t pack_count() const { return pack_count_; }  // BvhTriPacks in packs()
  uint32_t prim_count() const { return prim_count_; }  // triangles and spheres in them
  bool masked() const { return masked_; }  // enable_alpha was called
  // The BVH is one node whose children are leaves (or empty): trace_lanes' flat
  // casts can skip a leaf by its box (kernels/trace_lanes.cl flat_root_leaves).
  bool root_of_leaves() const { return root_of_leaves_; }
  bool spheres() const { return spheres_; }  // the BVH holds sphere packs
  // FrameParams.spheres for trace_lanes' casts: PSF_FRAME_SPHERES_NONE, _DOUBLE
  // (some sphere needs the test in double) or _FLOAT.
  uint32_t sphere_mode() const { return sphere_mode_; }

  // Work-group size of the launches.
  size_t local_size = 64;

 private:
  Runtime& rt_;
  cl::Buffer nodes_;
  cl::Buffer packs_;
  int depth_ = 0;
  uint32_t pack_count_ = 0;
  uint32_t prim_count_ = 0;
  bool root_of_leaves_ = false;
  bool spheres_ = false;  // the BVH holds sphere packs (the kernels' `spheres`)
  uint32_t sphere_mode_ = PSF_FRAME_SPHERES_NONE;
  bool masked_ = false;   // enable_alpha was called
  AlphaBuffers alpha_;    // its buffers
};

}  // namespace psf
