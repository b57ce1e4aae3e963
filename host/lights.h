// Lights, host side: the next-event estimation table that kernels/emitter.cl
// samples, built from a scene's emissive triangles and its LightDescs (point,
// spot, directional, the environment).
#pragma once
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "psf_shared.h"
#include "scene/scene.h"

namespace psf {

struct LightTable {
  std::vector<Emitter> emitters;    // one entry per emissive triangle, delta light and the environment
  std::vector<float> cdf;           // selection cdf over `emitters` by power (last entry 1), then its guide table
  std::vector<float> tri_light_pdf; // per prim (triangles, then spheres): selection probability / area if emissive, else 0
  Environment env{};                // the environment (env.present 0: none)
  std::vector<float> env_data;      // its texels and cdfs (layout in psf_shared.h); one 0 when none
};

// Builds the table. Each light is chosen in proportion to its power Phi
// (luminance of the RGB values):
//   triangle:    pi A L (twice that if two-sided)
//   point:       4 pi I;  spot: 2 pi I (1 - (cos(cutoff) + cos(beam width)) / 2)
//   directional: pi R^2 E;  environment: pi R^2 times the integral of L over the sphere,
// with R the radius of the scene's bounding sphere (1 for an empty scene). The
// first environment (Constant or Envmap) of scene.lights is the environment; the
// loaders warn about further ones. Throws std::invalid_argument for an envmap
// whose texel count does not match its size.
LightTable build_light_table(const Scene& scene);

// The environment's 2D piecewise-constant distribution over a grid of W x H
// cells of the (u, v) square: f(x, y) = the mean over cell (x, y) of the
// map's bilinear luminance (kernels/emitter.cl env_lookup) times sin(theta_y),
// theta_y at the row's centre.
// marginal: height + 1 entries from 0 to 1. Each row's conditional in two levels
// (psf_shared.h Environment): blocks, B + 1 entries per row with B =
// ceil(width / PSF_ENV_BLOCK), and within_block, PSF_ENV_BLOCK upper values per
// block (1 past the row's end). A row or block whose sum is zero gets a uniform
// cdf (it is never chosen). guide: the guide tables of the marginal (height
// entries) and of each row's block cdf (B entries per row) (cdf_guide_table).
struct EnvDistribution {
  std::vector<float> marginal;
  std::vector<float> blocks;
  std::vector<float> within_block;
  std::vector<float> guide;
  double integral = 0.0;  // sum of f times the cell's (du, dv) area: the mean of f over [0,1]^2
};
EnvDistribution build_env_distribution(const std::vector<float>& rgb, int width, int height);

// The guide table of the n upper cdf values `upper` (non-decreasing, the last 1),
// appended to `out` (kernels/emitter.cl sample_cdf_guided): entry k is the first
// i with upper[i] > k/n - 1e-6 (n - 1 if none), a lower bound of the first
// upper value above any u whose float bucket (uint)(u n) is k, so that a search
// from there forward finds what a bisection of the whole cdf would, in about
// one step. Each index is stored as its uint32 bits in a float.
void cdf_guide_table(const float* upper, size_t n, std::vector<float>& out);

}  // namespace psf
