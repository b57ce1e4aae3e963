// Binned SAH BVH build (Wald, "On fast construction of SAH-based bounding volume
// hierarchies", RT 2007) of a binary BVH with spatial splits (Stich, Friedrich,
// Dietrich, "Spatial splits in bounding volume hierarchies", HPG 2009: where an
// object split's sides overlap, a plane may cut primitives, which both sides
// then reference, clipped), collapsed into a PSF_BVH_WIDTH-wide BVH by
// repeatedly opening the child of largest surface area (Wald et al., "Getting
// rid of packets", RT 2008), and the RayCaster that uploads it.
#include "bvh.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <future>
#include <limits>
#include <stdexcept>
#include <string>
#include <thread>
#include <type_traits>

namespace psf {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

struct Box {
  glm::vec3 lo{kInf};   // minimum corner; lo > hi on an empty box
  glm::vec3 hi{-kInf};  // maximum corner

  void grow(const glm::vec3& p) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  void grow(const Box& b) {
    lo = glm::min(lo, b.lo);
    hi = glm::max(hi, b.hi);
  }
  bool empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
  // Half the surface area (the SAH only needs ratios); 0 for an empty box.
  float half_area() const {
    if (empty()) return 0.0f;
    glm::vec3 d = hi - lo;
    return d.x * d.y + d.y * d.z + d.z * d.x;
  }
};

// A node of the binary BVH: an inner node (left, right) or a leaf (first, count)
// over a range of the builder's primitive index array.
struct BinaryNode {
  Box box;             // bounds of the node's references
  uint32_t left = 0;   // inner node: children (binary node indices)
  uint32_t right = 0;
  uint32_t first = 0;  // leaf: first position in the index array
  uint32_t count = 0;  // leaf: number of primitives; 0 for an inner node
};

// A reference to a primitive during the build: the whole primitive, or with
// spatial splits the part of it inside `box` (a triangle clipped to the split
// planes; a sphere's box cut by them).
struct Ref {
  Box box;
  uint32_t prim = 0;
  glm::vec3 centroid() const { return 0.5f * (box.lo + box.hi); }
};

// Float bounds of double points, rounded outwards; `exact_axis` (-1: none) of
// a point computed with rounding (an edge's crossing of a plane, exact on the
// plane's axis): one float ulp further on the other axes, more than the double
// computation's own error.
void grow_outwards(Box* box, const glm::dvec3& p, int exact_axis = 0, bool inexact = false) {
  for (int d = 0; d < 3; ++d) {
    const float f = static_cast<float>(p[d]);
    float lo = double(f) > p[d] ? std::nextafter(f, -kInf) : f;
    float hi = double(f) < p[d] ? std::nextafter(f, kInf) : f;
    if (inexact && d != exact_axis) {
      lo = std::nextafter(lo, -kInf);
      hi = std::nextafter(hi, kInf);
    }
    box->lo[d] = std::min(box->lo[d], lo);
    box->hi[d] = std::max(box->hi[d], hi);
  }
}

Box intersect(const Box& a, const Box& b) {
  Box r;
  r.lo = glm::max(a.lo, b.lo);
  r.hi = glm::min(a.hi, b.hi);
  return r;
}

// The primitives a spatial split cuts: triangles [0, first_sphere), then spheres.
struct SplitGeometry {
  const std::vector<glm::vec3>& positions;
  const std::vector<glm::uvec3>& triangles;
  size_t first_sphere;

  // A primitive as a split sees it: a triangle's vertices, or a sphere.
  struct Shape {
    bool sphere = false;
    glm::vec3 v[3];
  };
  Shape shape(uint32_t prim) const {
    Shape s;
    s.sphere = prim >= first_sphere;
    if (!s.sphere)
      for (int k = 0; k < 3; ++k) s.v[k] = positions[triangles[prim][k]];
    return s;
  }

  // The bounds of the parts of primitive `shape` on either side of the plane
  // x[axis] = plane, each cut to `box` (the reference's) and to its side: a
  // triangle's vertices and its edges' crossings of the plane, a sphere's box
  // cut by the plane. `exact`: the crossings in double and their bounds
  // rounded outwards (the splits made), else in float (the bins' estimates).
  template <bool exact>
  static void split(const Shape& shape, const Box& box, int axis, float plane, Box* left, Box* right) {
    *left = box;
    *right = box;
    left->hi[axis] = std::min(left->hi[axis], plane);
    right->lo[axis] = std::max(right->lo[axis], plane);
    if (shape.sphere) return;
    using vec = std::conditional_t<exact, glm::dvec3, glm::vec3>;
    using real = typename vec::value_type;
    const vec v[3] = {vec(shape.v[0]), vec(shape.v[1]), vec(shape.v[2])};
    const real p = plane;
    Box l, r;
    auto grow = [axis](Box* b, const vec& x, bool crossing) {
      if constexpr (exact)
        grow_outwards(b, x, axis, crossing);
      else
        b->grow(x);
    };
    for (int k = 0; k < 3; ++k) {
      const vec &a = v[k], &b = v[(k + 1) % 3];
      if (a[axis] <= p) grow(&l, a, false);
      if (a[axis] >= p) grow(&r, a, false);
      if ((a[axis] < p && b[axis] > p) || (a[axis] > p && b[axis] < p)) {
        vec x = a + (b - a) * ((p - a[axis]) / (b[axis] - a[axis]));
        x[axis] = p;
        grow(&l, x, true);
        grow(&r, x, true);
      }
    }
    *left = intersect(*left, l);
    *right = intersect(*right, r);
  }
};

class BinaryBuilder {
 public:
  BinaryBuilder(const std::vector<Box>& boxes, const BvhParams& params, const SplitGeometry& geometry)
      : boxes_(boxes), params_(params), geometry_(geometry) {}

  // Builds over the given primitive ids; returns the root (binary node 0).
  // `threads` > 1: the subtrees of the top splits are built on threads of their
  // own (the same tree whatever the count; only the nodes' numbering differs).
  void build(const std::vector<uint32_t>& ids, unsigned threads) {
    std::vector<Ref> refs(ids.size());
    Box box;
    for (size_t i = 0; i < ids.size(); ++i) {
      refs[i] = {boxes_[ids[i]], ids[i]};
      box.grow(refs[i].box);
    }
    root_area_ = box.half_area();
    // The budgets: not negative (or NaN), and references within the leaf
    // encoding's count of packs (each holds at least one).
    Budget budget;
    if (params_.spatial_splits) {
      const double n = double(ids.size()), room = double(PSF_LEAF_FIRST_MASK) - n;
      auto limit = [](double x, double most) { return static_cast<uint64_t>(x > 0.0 ? std::min(x, most) : 0.0); };
      budget.refs = limit(double(params_.split_budget) * n, room);
      budget.cuts = limit(double(params_.split_cuts) * n, 1e18);
    }
    nodes_.reserve(2 * ids.size());
    index_.reserve(ids.size());
    nodes_.emplace_back();
    int parallel_levels = 0;
    while ((2u << parallel_levels) <= threads && parallel_levels < 4) ++parallel_levels;
    build_node(nodes_, index_, 0, std::move(refs), 1, parallel_levels, budget);
  }

  const std::vector<BinaryNode>& nodes() const { return nodes_; }
  const std::vector<uint32_t>& index() const { return index_; }

 private:
  struct Split {
    int axis = -1;                                  // -1: none found
    int bin = 0;                                    // left side is bins [0, bin]
    float cost = std::numeric_limits<float>::max();  // sum of area * count of both sides
    Box left, right;                                 // bounds of both sides
  };

  // Triangle tests come in packs of PSF_BVH_WIDTH: the SAH counts packs.
  static float packs(uint32_t n) { return float((n + PSF_BVH_WIDTH - 1) / PSF_BVH_WIDTH); }

  // The bin of coordinate c; clamped before the conversion to int so that an
  // overflowing scale (a tiny extent) cannot produce an out-of-range value.
  static int bin_of(float c, float lo, float scale, int bins) {
    float f = (c - lo) * scale;
    if (!(f > 0.0f)) return 0;
    if (f >= float(bins - 1)) return bins - 1;
    return static_cast<int>(f);
  }

  // The cheapest boundary between an axis's bins by the SAH: the left side
  // bins [0, bin], which hold the references that enter[] counts in their
  // first bin, the right side those that leave[] counts in their last; both
  // sides must hold some, and neither all `total`.
  struct Sweep {
    int bin = -1;
    float cost = std::numeric_limits<float>::max();
    Box left, right;
  };
  static Sweep sweep(const Box* bin_box, const uint32_t* enter, const uint32_t* leave, int bins, uint32_t total) {
    std::vector<Box> right_box(bins);
    std::vector<uint32_t> right_count(bins);
    Box acc;
    uint32_t n = 0;
    for (int b = bins - 1; b > 0; --b) {
      acc.grow(bin_box[b]);
      n += leave[b];
      right_box[b] = acc;
      right_count[b] = n;
    }
    Sweep best;
    acc = Box{};
    n = 0;
    for (int b = 0; b < bins - 1; ++b) {
      acc.grow(bin_box[b]);
      n += enter[b];
      const uint32_t nr = right_count[b + 1];
      if (n == 0 || nr == 0 || n >= total || nr >= total) continue;
      const float cost = acc.half_area() * packs(n) + right_box[b + 1].half_area() * packs(nr);
      if (cost < best.cost) best = {b, cost, acc, right_box[b + 1]};
    }
    return best;
  }

  // The best split of the references by their centroids' bins (object split).
  Split find_split(const std::vector<Ref>& refs, const Box& cbox) const {
    const int bins = std::max(2, params_.bins);
    Split best;
    std::vector<Box> bin_box(bins);
    std::vector<uint32_t> bin_count(bins);
    for (int axis = 0; axis < 3; ++axis) {
      float lo = cbox.lo[axis], extent = cbox.hi[axis] - cbox.lo[axis];
      if (!(extent > 0.0f)) continue;
      float scale = bins / extent;
      std::fill(bin_box.begin(), bin_box.end(), Box{});
      std::fill(bin_count.begin(), bin_count.end(), 0u);
      for (const Ref& r : refs) {
        int b = bin_of(r.centroid()[axis], lo, scale, bins);
        bin_box[b].grow(r.box);
        bin_count[b] += 1;
      }
      const Sweep w =
          sweep(bin_box.data(), bin_count.data(), bin_count.data(), bins, static_cast<uint32_t>(refs.size()));
      if (w.cost < best.cost) best = {axis, w.bin, w.cost, w.left, w.right};
    }
    return best;
  }

  // A spatial split (Stich, Friedrich, Dietrich, "Spatial splits in bounding
  // volume hierarchies", HPG 2009): a plane through the node's box; references
  // crossing it go to both sides, each clipped to its side.
  struct SpatialSplit {
    int axis = -1;
    float plane = 0.0f;
    float cost = std::numeric_limits<float>::max();
    uint64_t cuts = 0;  // cuts of references at bin planes that the search made
  };

  // What spatial splits may still spend in a subtree: references added, and
  // cuts of references at bin planes in the searches (the build's time), each
  // shared by the two sides of a split in proportion to their sizes, so that
  // the tree does not depend on the build's threads.
  struct Budget {
    uint64_t refs = 0;
    uint64_t cuts = 0;
    // What is left after `added` references and `cuts` cuts, for a side of
    // `part` of `total` references.
    Budget share(uint64_t added, uint64_t spent, size_t part, size_t total) const {
      const uint64_t r = refs - std::min(refs, added), c = cuts - std::min(cuts, spent);
      using wide = unsigned __int128;  // c * part can pass 2^64
      return {static_cast<uint64_t>(wide(r) * part / total), static_cast<uint64_t>(wide(c) * part / total)};
    }
  };

  // The plane between spatial bins b and b + 1 of an axis over [lo, lo + extent].
  static float spatial_plane(float lo, float extent, int b, int bins) { return lo + extent * float(b + 1) / bins; }

  // Bins every reference on the three axes in one pass over them (a
  // triangle's vertices read once), then sweeps each axis.
  SpatialSplit find_spatial_split(const std::vector<Ref>& refs, const Box& box) const {
    const int bins = std::max(2, params_.bins);
    SpatialSplit best;
    std::vector<Box> bin_box(3 * bins);
    std::vector<uint32_t> enter(3 * bins), leave(3 * bins);
    float scale[3];
    bool axes[3];
    for (int axis = 0; axis < 3; ++axis) {
      const float extent = box.hi[axis] - box.lo[axis];
      axes[axis] = extent > 0.0f;
      scale[axis] = axes[axis] ? bins / extent : 0.0f;
    }
    for (const Ref& r : refs) {
      int b0[3], b1[3];
      bool crossing = false;
      for (int axis = 0; axis < 3; ++axis) {
        if (!axes[axis]) continue;
        b0[axis] = bin_of(r.box.lo[axis], box.lo[axis], scale[axis], bins);
        b1[axis] = std::max(b0[axis], bin_of(r.box.hi[axis], box.lo[axis], scale[axis], bins));
        enter[axis * bins + b0[axis]] += 1;
        leave[axis * bins + b1[axis]] += 1;
        if (b0[axis] == b1[axis])
          bin_box[axis * bins + b0[axis]].grow(r.box);
        else
          crossing = true;
      }
      if (!crossing) continue;
      const SplitGeometry::Shape shape = geometry_.shape(r.prim);
      for (int axis = 0; axis < 3; ++axis) {
        if (!axes[axis] || b0[axis] == b1[axis]) continue;
        // Cut at each plane in turn: the part left of it into its bin.
        const float extent = box.hi[axis] - box.lo[axis];
        Box rest = r.box;
        for (int b = b0[axis]; b < b1[axis]; ++b) {
          Box part;
          SplitGeometry::split<false>(shape, rest, axis, spatial_plane(box.lo[axis], extent, b, bins), &part, &rest);
          bin_box[axis * bins + b].grow(part);
        }
        bin_box[axis * bins + b1[axis]].grow(rest);
        best.cuts += static_cast<uint64_t>(b1[axis] - b0[axis]);
      }
    }
    for (int axis = 0; axis < 3; ++axis) {
      if (!axes[axis]) continue;
      const Sweep w = sweep(&bin_box[axis * bins], &enter[axis * bins], &leave[axis * bins], bins,
                            static_cast<uint32_t>(refs.size()));
      if (w.cost < best.cost)
        best = {axis, spatial_plane(box.lo[axis], box.hi[axis] - box.lo[axis], w.bin, bins), w.cost, best.cuts};
    }
    return best;
  }

  // Splits `refs` at the plane of `s` into *left and *right: a reference wholly
  // on one side goes there; one that crosses it goes to both, clipped, unless
  // moving it whole to one side costs less by the SAH (Stich et al.'s reference
  // unsplitting), or its part on one side is empty.
  void spatial_partition(const std::vector<Ref>& refs, const SpatialSplit& s, std::vector<Ref>* left,
                         std::vector<Ref>* right) const {
    std::vector<const Ref*> crossing;
    Box lbox, rbox;
    for (const Ref& r : refs) {
      if (r.box.hi[s.axis] <= s.plane) {
        left->push_back(r);
        lbox.grow(r.box);
      } else if (r.box.lo[s.axis] >= s.plane) {
        right->push_back(r);
        rbox.grow(r.box);
      } else {
        crossing.push_back(&r);
      }
    }
    for (const Ref* r : crossing) {
      Box lpart, rpart;
      SplitGeometry::split<true>(geometry_.shape(r->prim), r->box, s.axis, s.plane, &lpart, &rpart);
      const float nl = packs(uint32_t(left->size()) + 1u), nr = packs(uint32_t(right->size()) + 1u);
      const float nl0 = packs(uint32_t(left->size())), nr0 = packs(uint32_t(right->size()));
      Box l = lbox, r2 = rbox, lwhole = lbox, rwhole = rbox;
      l.grow(lpart);
      r2.grow(rpart);
      lwhole.grow(r->box);
      rwhole.grow(r->box);
      const float split = l.half_area() * nl + r2.half_area() * nr;
      const float to_left = lwhole.half_area() * nl + rbox.half_area() * nr0;
      const float to_right = lbox.half_area() * nl0 + rwhole.half_area() * nr;
      if (rpart.empty() || (!lpart.empty() && to_left <= split && to_left <= to_right)) {
        left->push_back(*r);
        lbox.grow(r->box);
      } else if (lpart.empty() || to_right <= split) {
        right->push_back(*r);
        rbox.grow(r->box);
      } else {
        left->push_back({lpart, r->prim});
        right->push_back({rpart, r->prim});
        lbox.grow(lpart);
        rbox.grow(rpart);
      }
    }
  }

  static void make_leaf(std::vector<BinaryNode>& nodes, std::vector<uint32_t>& index, uint32_t node,
                        const std::vector<Ref>& refs) {
    nodes[node].first = static_cast<uint32_t>(index.size());
    nodes[node].count = static_cast<uint32_t>(refs.size());
    for (const Ref& r : refs) index.push_back(r.prim);
  }

  // Node `node` of `nodes` over the references `refs`, its leaves' primitives
  // appended to `index`; `budget`: what spatial splits may still spend in
  // this subtree. parallel_levels > 0: the left subtree goes to
  // another thread, into vectors of its own that are then appended to `nodes`
  // and `index`.
  void build_node(std::vector<BinaryNode>& nodes, std::vector<uint32_t>& index, uint32_t node, std::vector<Ref> refs,
                  int depth, int parallel_levels, const Budget& budget) {
    Box box, cbox;
    for (const Ref& r : refs) {
      box.grow(r.box);
      cbox.grow(r.centroid());
    }
    nodes[node].box = box;
    const uint32_t count = static_cast<uint32_t>(refs.size());
    if (count <= 1) return make_leaf(nodes, index, node, refs);

    // Balanced splits from here on must still end within PSF_BVH_MAX_DEPTH levels.
    int levels_needed = static_cast<int>(std::ceil(std::log2(double(count)))) + 1;
    bool force_median = depth + levels_needed >= PSF_BVH_MAX_DEPTH;

    std::vector<Ref> left, right;
    uint64_t cuts = 0;  // spent by the spatial split's search
    if (force_median && count <= params_.max_leaf) return make_leaf(nodes, index, node, refs);
    if (!force_median) {
      Split s = find_split(refs, cbox);
      float area = box.half_area();
      SpatialSplit ss;
      // Spatial splits where the object split's sides overlap by more than
      // split_alpha of the root's area.
      if (budget.refs > 0 && budget.cuts > 0 && s.axis >= 0 &&
          intersect(s.left, s.right).half_area() > params_.split_alpha * root_area_)
        ss = find_spatial_split(refs, box);
      cuts = ss.cuts;
      const bool spatial = ss.axis >= 0 && ss.cost < s.cost;
      const float best_cost = spatial ? ss.cost : s.cost;
      float leaf_cost = params_.intersection_cost * packs(count);
      float split_cost = params_.traversal_cost + (area > 0.0f ? params_.intersection_cost * best_cost / area : 0.0f);
      if (count <= params_.max_leaf && ((s.axis < 0 && !spatial) || leaf_cost <= split_cost))
        return make_leaf(nodes, index, node, refs);
      if (spatial) {
        spatial_partition(refs, ss, &left, &right);
        if (left.size() + right.size() - count > budget.refs || left.empty() || right.empty()) {
          left.clear();
          right.clear();
          // The object split instead: the leaf may now be cheaper.
          const float object_cost =
              params_.traversal_cost + (area > 0.0f ? params_.intersection_cost * s.cost / area : 0.0f);
          if (count <= params_.max_leaf && (s.axis < 0 || leaf_cost <= object_cost))
            return make_leaf(nodes, index, node, refs);
        }
      }
      if (left.empty() && s.axis >= 0) {
        const int bins = std::max(2, params_.bins);
        float lo = cbox.lo[s.axis], scale = bins / (cbox.hi[s.axis] - cbox.lo[s.axis]);
        auto it = std::partition(refs.begin(), refs.end(),
                                 [&](const Ref& r) { return bin_of(r.centroid()[s.axis], lo, scale, bins) <= s.bin; });
        left.assign(refs.begin(), it);
        right.assign(it, refs.end());
      }
    }
    if (left.empty() || right.empty()) {
      // No usable SAH split (all centroids equal) or the depth budget is short:
      // median split along the widest centroid axis.
      glm::vec3 ext = cbox.hi - cbox.lo;
      int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
      const uint32_t mid = count / 2;
      std::nth_element(refs.begin(), refs.begin() + mid, refs.end(),
                       [&](const Ref& a, const Ref& b) { return a.centroid()[axis] < b.centroid()[axis]; });
      left.assign(refs.begin(), refs.begin() + mid);
      right.assign(refs.begin() + mid, refs.end());
    }
    // What is left of the budget, shared by the sides' sizes.
    const uint64_t added = left.size() + right.size() - count;
    const Budget left_budget = budget.share(added, cuts, left.size(), left.size() + right.size());
    const Budget right_budget = budget.share(added, cuts, right.size(), left.size() + right.size());
    refs.clear();
    refs.shrink_to_fit();

    uint32_t first_child = static_cast<uint32_t>(nodes.size());
    nodes.emplace_back();
    nodes.emplace_back();
    nodes[node].left = first_child;
    nodes[node].right = first_child + 1;
    const size_t left_count = left.size(), right_count = right.size();
    if (parallel_levels <= 0 || std::min(left_count, right_count) < kParallelMin) {
      build_node(nodes, index, first_child, std::move(left), depth + 1, 0, left_budget);
      build_node(nodes, index, first_child + 1, std::move(right), depth + 1, 0, right_budget);
      return;
    }
    // The left subtree on another thread, into `sub` and `sub_index`; its
    // leaves' primitives then follow the right subtree's in `index`.
    std::vector<BinaryNode> sub;
    std::vector<uint32_t> sub_index;
    sub.reserve(2 * left_count);
    sub_index.reserve(left_count);
    sub.emplace_back();
    std::future<void> done = std::async(std::launch::async, [&] {
      build_node(sub, sub_index, 0, std::move(left), depth + 1, parallel_levels - 1, left_budget);
    });
    build_node(nodes, index, first_child + 1, std::move(right), depth + 1, parallel_levels - 1, right_budget);
    done.get();  // rethrows what the thread threw
    // sub[0] becomes nodes[first_child], sub[k] (k >= 1) nodes[base + k - 1]; an
    // inner node's children are never node 0, so left == 0 marks a leaf.
    const uint32_t base = static_cast<uint32_t>(nodes.size());
    const uint32_t index_base = static_cast<uint32_t>(index.size());
    auto place = [&](uint32_t k) { return k == 0 ? first_child : base + k - 1; };
    for (BinaryNode& n : sub)
      if (n.left != 0) {
        n.left = place(n.left);
        n.right = place(n.right);
      } else {
        n.first += index_base;
      }
    nodes[first_child] = sub[0];
    nodes.insert(nodes.end(), sub.begin() + 1, sub.end());
    index.insert(index.end(), sub_index.begin(), sub_index.end());
  }

  // Subtrees smaller than this are built on the thread that split them.
  static constexpr uint32_t kParallelMin = 4096;

  const std::vector<Box>& boxes_;
  const BvhParams& params_;
  const SplitGeometry& geometry_;
  float root_area_ = 0.0f;
  std::vector<uint32_t> index_;
  std::vector<BinaryNode> nodes_;
};

BvhNode empty_node() {
  BvhNode n;
  for (int s = 0; s < PSF_BVH_WIDTH; ++s) {
    n.min_x[s] = n.min_y[s] = n.min_z[s] = kInf;
    n.max_x[s] = n.max_y[s] = n.max_z[s] = -kInf;
    n.child[s] = PSF_EMPTY_CHILD;
  }
  return n;
}

// A pack whose lanes are all unused: zero edges are never hit.
BvhTriPack empty_pack() {
  BvhTriPack p;
  std::memset(&p, 0, sizeof p);
  for (int k = 0; k < PSF_BVH_WIDTH; ++k) p.prim[k] = PSF_NO_HIT;
  return p;
}

// Whether raycast.cl tests sphere s in double precision: a ray leaving its
// surface starts 1e-4 of the point's largest coordinate off it (shade.cl), and
// float's c = |f|^2 - r^2 keeps that offset's sign at least where r <= 4 or
// r <= |centre| / 2 (raycast.cl, sphere_pack_test): not so for a ground sphere
// of radius 1e5 below the origin.
bool sphere_needs_double(const BvhSphere& s) {
  return !(s.radius <= 4.0f || s.radius <= 0.5f * glm::length(s.center));
}

// Collapses the binary BVH into wide nodes, depth first (a node before its children).
class Collapser {
 public:
  // Writes a leaf's packs; returns its child reference (PSF_LEAF_BIT set).
  using LeafFn = std::function<uint32_t(const BinaryNode&)>;
  Collapser(const std::vector<BinaryNode>& bin, std::vector<BvhNode>& out, LeafFn leaf)
      : bin_(bin), out_(out), leaf_(std::move(leaf)) {}

  // Emits the wide node whose slots are the (grand)children of binary node `b`;
  // a binary leaf as root becomes a wide root with one leaf slot.
  uint32_t emit(uint32_t b, int depth) {
    depth_ = std::max(depth_, depth);
    uint32_t id = static_cast<uint32_t>(out_.size());
    out_.push_back(empty_node());
    std::vector<uint32_t> kids;
    if (bin_[b].count > 0) {
      kids.push_back(b);
    } else {
      kids.push_back(bin_[b].left);
      kids.push_back(bin_[b].right);
    }
    while (kids.size() < PSF_BVH_WIDTH) {
      int open = -1;
      float best = -1.0f;
      for (size_t k = 0; k < kids.size(); ++k) {
        const BinaryNode& n = bin_[kids[k]];
        if (n.count == 0 && n.box.half_area() > best) {
          best = n.box.half_area();
          open = static_cast<int>(k);
        }
      }
      if (open < 0) break;
      uint32_t opened = kids[open];
      kids[open] = bin_[opened].left;
      kids.push_back(bin_[opened].right);
    }
    for (size_t s = 0; s < kids.size(); ++s) {
      const BinaryNode& n = bin_[kids[s]];
      uint32_t child;
      if (n.count > 0) {
        child = leaf_(n);
      } else {
        child = emit(kids[s], depth + 1);
      }
      BvhNode& w = out_[id];  // after the recursion: out_ may have grown
      w.min_x[s] = n.box.lo.x;
      w.min_y[s] = n.box.lo.y;
      w.min_z[s] = n.box.lo.z;
      w.max_x[s] = n.box.hi.x;
      w.max_y[s] = n.box.hi.y;
      w.max_z[s] = n.box.hi.z;
      w.child[s] = child;
    }
    return id;
  }
  int depth() const { return depth_; }

 private:
  const std::vector<BinaryNode>& bin_;
  std::vector<BvhNode>& out_;
  LeafFn leaf_;
  int depth_ = 1;
};

bool finite(const glm::vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

}  // namespace

Bvh build_bvh(const std::vector<glm::vec3>& positions, const std::vector<glm::uvec3>& triangles,
              const BvhParams& params) {
  return build_bvh(positions, triangles, {}, params);
}

Bvh build_bvh(const std::vector<glm::vec3>& positions, const std::vector<glm::uvec3>& triangles,
              const std::vector<BvhSphere>& spheres, const BvhParams& params) {
  static_assert(PSF_BVH_WIDTH == 4 || PSF_BVH_WIDTH == 8, "PSF_BVH_WIDTH must be 4 or 8");
  auto t0 = std::chrono::steady_clock::now();
  // A leaf's triangles and spheres fill packs of their own: at most
  // max_leaf / PSF_BVH_WIDTH + 2 of them, which the reference's count must hold.
  if (params.max_leaf / PSF_BVH_WIDTH + 2u > PSF_LEAF_COUNT_MASK + 1u)
    throw std::invalid_argument("build_bvh: max_leaf " + std::to_string(params.max_leaf) + " may need " +
                                std::to_string(params.max_leaf / PSF_BVH_WIDTH + 2u) +
                                " packs in a leaf; its reference counts " +
                                std::to_string(PSF_LEAF_COUNT_MASK + 1u));
  if (triangles.size() + spheres.size() > PSF_LEAF_FIRST_MASK)
    throw std::invalid_argument("build_bvh: " + std::to_string(triangles.size() + spheres.size()) +
                                " primitives exceed the leaf encoding (2^27)");
  const size_t first_sphere = triangles.size();
  Bvh bvh;
  std::vector<Box> boxes(triangles.size() + spheres.size());
  std::vector<uint32_t> ids;
  ids.reserve(boxes.size());
  for (size_t t = 0; t < triangles.size(); ++t) {
    const glm::uvec3& tri = triangles[t];
    for (int k = 0; k < 3; ++k)
      if (tri[k] >= positions.size())
        throw std::invalid_argument("build_bvh: triangle " + std::to_string(t) + " refers to vertex " +
                                    std::to_string(tri[k]) + " of " + std::to_string(positions.size()));
    const glm::vec3 &a = positions[tri.x], &b = positions[tri.y], &c = positions[tri.z];
    // Zero area (repeated vertices, collinear) to a relative tolerance of 1e-12 in
    // sin(angle), computed in double: such a triangle can never be hit.
    glm::dvec3 e1 = glm::dvec3(b) - glm::dvec3(a), e2 = glm::dvec3(c) - glm::dvec3(a);
    double cross2 = glm::dot(glm::cross(e1, e2), glm::cross(e1, e2));
    double scale2 = glm::dot(e1, e1) * glm::dot(e2, e2);
    if (!finite(a) || !finite(b) || !finite(c) || !(cross2 > 1e-24 * scale2)) {
      bvh.skipped += 1;
      continue;
    }
    boxes[t].grow(a);
    boxes[t].grow(b);
    boxes[t].grow(c);
    ids.push_back(static_cast<uint32_t>(t));
    bvh.triangle_count += 1;
  }
  for (size_t k = 0; k < spheres.size(); ++k) {
    const BvhSphere& s = spheres[k];
    if (!finite(s.center) || !(s.radius > 0.0f) || !std::isfinite(s.radius)) {
      bvh.skipped += 1;
      continue;
    }
    grow_outwards(&boxes[first_sphere + k], glm::dvec3(s.center) - double(s.radius));
    grow_outwards(&boxes[first_sphere + k], glm::dvec3(s.center) + double(s.radius));
    ids.push_back(static_cast<uint32_t>(first_sphere + k));
    bvh.sphere_count += 1;
    bvh.double_spheres += sphere_needs_double(s);
  }

  if (ids.empty()) {
    bvh.nodes.push_back(empty_node());
    bvh.depth = 1;
  } else {
    const SplitGeometry geometry{positions, triangles, first_sphere};
    BinaryBuilder builder(boxes, params, geometry);
    builder.build(ids,
                  params.threads > 0 ? unsigned(params.threads) : std::max(1u, std::thread::hardware_concurrency()));
    const std::vector<uint32_t>& order = builder.index();
    // A binary leaf's triangles, PSF_BVH_WIDTH to a pack, then its spheres in
    // packs of their own, appended in leaf order.
    auto write_leaf = [&](const BinaryNode& leaf) {
      bvh.references += leaf.count;
      uint32_t first = static_cast<uint32_t>(bvh.packs.size());
      uint32_t lanes = 0;
      for (uint32_t k = 0; k < leaf.count; ++k) {
        uint32_t t = order[leaf.first + k];
        if (t >= first_sphere) continue;
        if (lanes++ % PSF_BVH_WIDTH == 0) bvh.packs.push_back(empty_pack());
        BvhTriPack& p = bvh.packs.back();
        int lane = (lanes - 1) % PSF_BVH_WIDTH;
        const glm::uvec3& tri = triangles[t];
        const glm::vec3 &a = positions[tri.x], &b = positions[tri.y], &c = positions[tri.z];
        glm::vec3 e1 = b - a, e2 = c - a;
        glm::dvec3 n = glm::cross(glm::dvec3(b) - glm::dvec3(a), glm::dvec3(c) - glm::dvec3(a));
        p.v0_x[lane] = a.x;
        p.v0_y[lane] = a.y;
        p.v0_z[lane] = a.z;
        p.e1_x[lane] = e1.x;
        p.e1_y[lane] = e1.y;
        p.e1_z[lane] = e1.z;
        p.e2_x[lane] = e2.x;
        p.e2_y[lane] = e2.y;
        p.e2_z[lane] = e2.z;
        p.inv_size[lane] = static_cast<float>(1.0 / std::sqrt(glm::length(n)));
        p.prim[lane] = t;
      }
      const uint32_t triangle_packs = static_cast<uint32_t>(bvh.packs.size()) - first;
      lanes = 0;
      for (uint32_t k = 0; k < leaf.count; ++k) {
        uint32_t t = order[leaf.first + k];
        if (t < first_sphere) continue;
        if (lanes++ % PSF_BVH_WIDTH == 0) bvh.packs.push_back(empty_pack());
        BvhTriPack& p = bvh.packs.back();
        int lane = (lanes - 1) % PSF_BVH_WIDTH;
        const BvhSphere& s = spheres[t - first_sphere];
        p.v0_x[lane] = s.center.x;
        p.v0_y[lane] = s.center.y;
        p.v0_z[lane] = s.center.z;
        p.e1_x[lane] = s.radius;
        if (sphere_needs_double(s)) p.e1_y[0] = 1.0f;
        p.prim[lane] = t | PSF_PRIM_SPHERE;
      }
      const uint32_t count = static_cast<uint32_t>(bvh.packs.size()) - first;
      if (count - 1u > PSF_LEAF_COUNT_MASK)  // max_leaf is checked above: never
        throw std::logic_error("build_bvh: a leaf of " + std::to_string(count) + " packs");
      if (first > PSF_LEAF_FIRST_MASK)  // the reference budget is capped: never
        throw std::logic_error("build_bvh: pack " + std::to_string(first) + " beyond the leaf encoding");
      return PSF_LEAF_BIT | (count > triangle_packs ? PSF_LEAF_SPHERES : 0u) |
             ((count - 1u) << PSF_LEAF_COUNT_SHIFT) | first;
    };
    Collapser collapser(builder.nodes(), bvh.nodes, write_leaf);
    collapser.emit(0, 1);
    bvh.depth = collapser.depth();
  }
  if (bvh.depth > PSF_BVH_MAX_DEPTH)
    throw std::logic_error("build_bvh: depth " + std::to_string(bvh.depth) + " exceeds PSF_BVH_MAX_DEPTH");
  bvh.build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return bvh;
}

RayCaster::RayCaster(Runtime& rt, const Bvh& bvh)
    : rt_(rt),
      nodes_(rt.upload(bvh.nodes)),
      packs_(rt.upload(bvh.packs)),
      depth_(bvh.depth),
      pack_count_(static_cast<uint32_t>(bvh.packs.size())),
      prim_count_(bvh.triangle_count + bvh.sphere_count),
      root_of_leaves_(bvh.nodes.size() == 1 &&
                      std::all_of(std::begin(bvh.nodes[0].child), std::end(bvh.nodes[0].child),
                                  [](uint32_t c) { return c == PSF_EMPTY_CHILD || is_leaf(c); })),
      spheres_(bvh.sphere_count > 0),
      sphere_mode_(bvh.sphere_count == 0    ? PSF_FRAME_SPHERES_NONE
                   : bvh.double_spheres > 0 ? PSF_FRAME_SPHERES_DOUBLE
                                            : PSF_FRAME_SPHERES_FLOAT) {}

void RayCaster::closest(const cl::Buffer& rays, const cl::Buffer& hits, uint32_t count) {
  if (masked_)
    rt_.launch("raycast_closest_masked", count, local_size, nodes_, packs_, rays, hits, count, cl_uint(spheres_),
               alpha_.tri_material, alpha_.materials, alpha_.attribs, alpha_.textures, alpha_.texels);
  else
    rt_.launch("raycast_closest", count, local_size, nodes_, packs_, rays, hits, count, cl_uint(spheres_));
}

void RayCaster::any(const cl::Buffer& rays, const cl::Buffer& hits, uint32_t count) {
  if (masked_)
    rt_.launch("raycast_any_masked", count, local_size, nodes_, packs_, rays, hits, count, cl_uint(spheres_),
               alpha_.tri_material, alpha_.materials, alpha_.attribs, alpha_.textures, alpha_.texels);
  else
    rt_.launch("raycast_any", count, local_size, nodes_, packs_, rays, hits, count, cl_uint(spheres_));
}

size_t mark_masked(Bvh& bvh, const std::vector<bool>& masked) {
  std::vector<bool> seen(masked.size(), false);  // a primitive may lie in several leaves
  size_t marked = 0;
  for (BvhTriPack& p : bvh.packs)
    for (int lane = 0; lane < PSF_BVH_WIDTH; ++lane) {
      const uint32_t prim = p.prim[lane];
      if (prim == PSF_NO_HIT) continue;
      const uint32_t index = prim & ~PSF_PRIM_SPHERE;
      if (index >= masked.size() || !masked[index]) continue;
      p.prim[lane] = prim | PSF_PRIM_MASKED;
      marked += !seen[index];
      seen[index] = true;
    }
  return marked;
}

}  // namespace psf
