#include "compare.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "scene/loaders.h"  // detail::srgb_to_linear

namespace psf {

namespace {

double pixel_luminance(const Image& img, size_t i) {
  return luminance(img.rgb[3 * i], img.rgb[3 * i + 1], img.rgb[3 * i + 2]);
}

// Block means of luminance; non-finite pixels count as 0.
std::vector<double> block_means(const Image& img, int bx, int by, double& overall) {
  if (img.width < bx || img.height < by)
    throw std::invalid_argument("image " + std::to_string(img.width) + "x" + std::to_string(img.height) +
                                " is smaller than the " + std::to_string(bx) + "x" + std::to_string(by) + " grid");
  std::vector<double> sum(size_t(bx) * by, 0.0), count(size_t(bx) * by, 0.0);
  double total = 0.0;
  for (int y = 0; y < img.height; ++y) {
    int j = int(int64_t(y) * by / img.height);
    for (int x = 0; x < img.width; ++x) {
      int i = int(int64_t(x) * bx / img.width);
      double l = pixel_luminance(img, size_t(y) * img.width + x);
      if (!std::isfinite(l)) l = 0.0;
      sum[size_t(j) * bx + i] += l;
      count[size_t(j) * bx + i] += 1;
      total += l;
    }
  }
  overall = total / (double(img.width) * img.height);
  for (size_t b = 0; b < sum.size(); ++b) sum[b] /= count[b];
  return sum;
}

}  // namespace

BlockStats block_stats(const Image& test, const Image& ref, int blocks_x, int blocks_y) {
  BlockStats s;
  s.blocks_x = blocks_x;
  s.blocks_y = blocks_y;
  s.test_mean = block_means(test, blocks_x, blocks_y, s.test_overall);
  s.ref_mean = block_means(ref, blocks_x, blocks_y, s.ref_overall);
  const double floor = std::max(1e-3 * s.ref_overall, 1e-30);
  s.rel_error.resize(s.test_mean.size());
  for (size_t b = 0; b < s.rel_error.size(); ++b) {
    s.rel_error[b] = std::abs(s.test_mean[b] - s.ref_mean[b]) / std::max(s.ref_mean[b], floor);
    s.mean_rel_error += s.rel_error[b] / double(s.rel_error.size());
    if (s.rel_error[b] > s.worst_rel_error) {
      s.worst_rel_error = s.rel_error[b];
      s.worst_block = int(b);
    }
  }
  s.overall_rel_error = (s.test_overall - s.ref_overall) / std::max(s.ref_overall, 1e-30);
  return s;
}

void default_grid(const Image& image, int& blocks_x, int& blocks_y) {
  bool portrait = image.height > image.width;
  blocks_x = portrait ? 9 : 16;
  blocks_y = portrait ? 16 : 9;
}

double rel_mse(const Image& test, const Image& ref) {
  if (test.width != ref.width || test.height != ref.height)
    throw std::invalid_argument("relMSE needs images of the same size, not " + std::to_string(test.width) + "x" +
                                std::to_string(test.height) + " and " + std::to_string(ref.width) + "x" +
                                std::to_string(ref.height));
  double sum = 0.0;
  for (size_t i = 0; i < test.rgb.size(); ++i) {
    double x = test.rgb[i], y = ref.rgb[i];
    if (!std::isfinite(x)) x = 0.0;
    sum += (x - y) * (x - y) / (y * y + 0.01);
  }
  return test.rgb.empty() ? 0.0 : sum / double(test.rgb.size());
}

ErrorMetrics error_metrics(const Image& test, const Image& ref) {
  ErrorMetrics e;
  e.rel_mse = rel_mse(test, ref);  // checks the sizes
  for (size_t i = 0; i < test.rgb.size(); ++i) {
    double x = test.rgb[i], y = ref.rgb[i];
    if (!std::isfinite(x)) x = 0.0;
    e.mse += (x - y) * (x - y);
    e.mae += std::fabs(x - y);
    e.mape += std::fabs(x - y) / (std::fabs(y) + 0.01);
  }
  const double n = std::max<double>(double(test.rgb.size()), 1.0);
  e.mse /= n;
  e.mae /= n;
  e.mape /= n;
  return e;
}

Image box_downsample(const Image& image, int width, int height) {
  if (width <= 0 || height <= 0 || image.width % width != 0 || image.height % height != 0)
    throw std::invalid_argument("cannot box-filter " + std::to_string(image.width) + "x" +
                                std::to_string(image.height) + " down to " + std::to_string(width) + "x" +
                                std::to_string(height) + " (the sizes must divide evenly)");
  const int fx = image.width / width, fy = image.height / height;
  Image out;
  out.width = width;
  out.height = height;
  out.rgb.assign(size_t(width) * height * 3, 0.0f);
  const double norm = 1.0 / double(fx * fy);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < 3; ++c) {
        double sum = 0.0;
        for (int v = 0; v < fy; ++v)
          for (int u = 0; u < fx; ++u)
            sum += image.rgb[(size_t(y * fy + v) * image.width + size_t(x * fx + u)) * 3 + c];
        out.rgb[(size_t(y) * width + x) * 3 + c] = float(sum * norm);
      }
  return out;
}

std::string describe(const BlockStats& s) {
  char buf[256];
  std::string out;
  std::snprintf(buf, sizeof buf, "mean luminance: test %.6g, reference %.6g (%+.2f %%)\n", s.test_overall,
                s.ref_overall, 100.0 * s.overall_rel_error);
  out += buf;
  std::snprintf(buf, sizeof buf, "blocks %dx%d: mean relative error %.2f %%, worst %.2f %% at block (%d, %d)\n",
                s.blocks_x, s.blocks_y, 100.0 * s.mean_rel_error, 100.0 * s.worst_rel_error,
                s.worst_block % s.blocks_x, s.worst_block / s.blocks_x);
  out += buf;
  out += "per-block (test - reference) / reference in %, rows from the top:\n";
  for (int j = 0; j < s.blocks_y; ++j) {
    for (int i = 0; i < s.blocks_x; ++i) {
      size_t b = size_t(j) * s.blocks_x + i;
      double signed_error = s.test_mean[b] >= s.ref_mean[b] ? s.rel_error[b] : -s.rel_error[b];
      std::snprintf(buf, sizeof buf, "%7.1f", 100.0 * signed_error);
      out += buf;
    }
    out += "\n";
  }
  return out;
}

float auto_exposure(const Image& image) {
  // Reinhard et al.'s key: the log-average luminance exp(mean log(1e-4 + L)),
  // which bright windows and lights move far less than the mean.
  double sum = 0.0;
  size_t n = 0;
  for (size_t i = 0; i < size_t(image.width) * image.height; ++i) {
    double l = pixel_luminance(image, i);
    if (!std::isfinite(l)) continue;
    sum += std::log(1e-4 + std::max(l, 0.0));
    ++n;
  }
  const double key = n > 0 ? std::exp(sum / double(n)) : 0.0;
  return key > 2e-4 && std::isfinite(0.18 / key) ? float(0.18 / key) : 1.0f;
}

namespace {

// The error panel's colour (display values) for signed error e at full scale range.
void error_colour(double e, double range, float out[3]) {
  static const float white[3] = {0.96f, 0.96f, 0.96f};
  static const float red[3] = {0.84f, 0.13f, 0.11f}, dark_red[3] = {0.45f, 0.03f, 0.03f};
  static const float blue[3] = {0.13f, 0.35f, 0.76f}, dark_blue[3] = {0.04f, 0.10f, 0.40f};
  const bool beyond = std::abs(e) > range;
  const float* full = e >= 0.0 ? (beyond ? dark_red : red) : (beyond ? dark_blue : blue);
  const float t = beyond ? 1.0f : float(std::abs(e) / range);
  for (int c = 0; c < 3; ++c) out[c] = white[c] + t * (full[c] - white[c]);
}

}  // namespace

Image comparison_picture(const Image& test, const Image& ref, const BlockStats& stats, double range, float exposure) {
  const int w = test.width, h = test.height, bx = stats.blocks_x, by = stats.blocks_y;
  if (w <= 0 || h <= 0 || ref.width <= 0 || ref.height <= 0)
    throw std::invalid_argument("comparison picture of an empty image");
  if (!(range > 0.0)) throw std::invalid_argument("comparison picture: the colour scale's range must be positive");
  if (bx <= 0 || by <= 0 || stats.test_mean.size() != size_t(bx) * by || stats.ref_mean.size() != stats.test_mean.size())
    throw std::invalid_argument("comparison picture: block statistics do not match their grid");
  const bool divides = ref.width % w == 0 && ref.height % h == 0 && ref.width / w == ref.height / h;
  const Image r = divides ? box_downsample(ref, w, h) : Image{};
  const int gap = std::max(2, w / 64);
  Image out;
  out.width = 3 * w + 2 * gap;
  out.height = h;
  out.rgb.assign(size_t(out.width) * h * 3, 1.0f);  // white gaps (write_png clamps to 1)
  auto put = [&](int x, int y, float a, float b, float c) {
    float* px = &out.rgb[(size_t(y) * out.width + x) * 3];
    px[0] = a;
    px[1] = b;
    px[2] = c;
  };
  const double floor = std::max(1e-3 * stats.ref_overall, 1e-30);  // block_stats' floor
  for (int y = 0; y < h; ++y) {
    const int j = int(int64_t(y) * by / h);
    const bool row_edge = y > 0 && int(int64_t(y - 1) * by / h) != j;
    for (int x = 0; x < w; ++x) {
      const float* t = &test.rgb[(size_t(y) * w + x) * 3];
      put(x, y, t[0] * exposure, t[1] * exposure, t[2] * exposure);
      const float* q = divides ? &r.rgb[(size_t(y) * w + x) * 3]
                               : &ref.rgb[(size_t((2 * int64_t(y) + 1) * ref.height / (2 * h)) * ref.width +
                                           size_t((2 * int64_t(x) + 1) * ref.width / (2 * w))) * 3];
      put(w + gap + x, y, q[0] * exposure, q[1] * exposure, q[2] * exposure);
      const int i = int(int64_t(x) * bx / w);
      const bool col_edge = x > 0 && int(int64_t(x - 1) * bx / w) != i;
      float c[3] = {0.6f, 0.6f, 0.6f};  // grid lines
      if (!row_edge && !col_edge) {
        const size_t b = size_t(j) * bx + i;
        error_colour((stats.test_mean[b] - stats.ref_mean[b]) / std::max(stats.ref_mean[b], floor), range, c);
      }
      // The linear values that write_png's sRGB encoding turns into these display values.
      put(2 * (w + gap) + x, y, detail::srgb_to_linear(c[0]), detail::srgb_to_linear(c[1]),
          detail::srgb_to_linear(c[2]));
    }
  }
  return out;
}

}  // namespace psf
