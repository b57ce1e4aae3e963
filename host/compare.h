// Image comparison against a reference render: the field's relMSE and block
// statistics of luminance, used by `psf compare` and the reference tests.
#pragma once
#include <string>
#include <vector>

#include "image.h"

namespace psf {

// Luminance means over a grid of blocks of each image (each at its own
// resolution: block (i, j) covers columns [i W / bx, (i+1) W / bx) and rows
// [j H / by, (j+1) H / by)), and their relative differences
// e_b = |test_b - ref_b| / max(ref_b, 1e-3 * mean of ref) (the floor keeps black
// blocks from dividing by zero).
struct BlockStats {
  int blocks_x = 0, blocks_y = 0;   // grid size
  std::vector<double> test_mean;    // per block, row-major from the top-left
  std::vector<double> ref_mean;     // per block
  std::vector<double> rel_error;    // per block: e_b
  double mean_rel_error = 0.0;      // mean of e_b over the blocks
  double worst_rel_error = 0.0;     // max of e_b
  int worst_block = 0;              // index of the max
  double test_overall = 0.0;        // mean luminance of the whole test image
  double ref_overall = 0.0;         // mean luminance of the whole reference
  double overall_rel_error = 0.0;   // (test_overall - ref_overall) / ref_overall, signed
};

// Block statistics; the images may differ in size. Throws std::invalid_argument
// when an image is smaller than the grid.
BlockStats block_stats(const Image& test, const Image& ref, int blocks_x, int blocks_y);

// The grid "16x9" along the longer side: 16 x 9 for landscape, 9 x 16 for portrait.
void default_grid(const Image& image, int& blocks_x, int& blocks_y);

// relMSE: mean over pixels and channels of (x - y)^2 / (y^2 + 0.01), y the
// reference. The images must have the same size (see box_downsample).
double rel_mse(const Image& test, const Image& ref);

// The usual per-pixel errors against a reference y, means over pixels and
// channels (a non-finite test value counts as 0, as in rel_mse): relMSE, MSE
// (x - y)^2, MAE |x - y| and MAPE |x - y| / (|y| + 0.01). Same sizes, as rel_mse.
struct ErrorMetrics {
  double rel_mse = 0.0, mse = 0.0, mae = 0.0, mape = 0.0;
};
ErrorMetrics error_metrics(const Image& test, const Image& ref);

// Box-filters `image` down to width x height; the sizes must divide evenly.
// Throws std::invalid_argument otherwise.
Image box_downsample(const Image& image, int width, int height);

// A report of the statistics: overall means, block mean and worst error, and
// the grid of per-block errors in percent (rows from the top).
std::string describe(const BlockStats& stats);

// A picture of a comparison, three panels side by side at the test's size with
// white gaps between them: the test, the reference (box-filtered to the test's
// size where the sizes divide evenly, else sampled at the test's pixel centres),
// both scaled by `exposure`, and the blocks of `stats` coloured by their signed
// relative difference (test - ref) / ref: white at 0, red where the test is
// brighter, blue where darker, full at +-range, a darker shade beyond it, grey
// lines between the blocks. Linear RGB, for write_png at exposure 1.
Image comparison_picture(const Image& test, const Image& ref, const BlockStats& stats, double range, float exposure);

// The exposure that takes the image's log-average luminance (Reinhard et al.
// 2002's key) to 0.18, middle grey; 1 where the image is black or not finite.
float auto_exposure(const Image& image);

// Luminance of linear sRGB (ITU-R BT.709).
inline double luminance(double r, double g, double b) { return 0.2126 * r + 0.7152 * g + 0.0722 * b; }

}  // namespace psf
