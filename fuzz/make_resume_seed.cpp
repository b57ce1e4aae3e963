// Writes a valid resume-state EXR (8x4 film, AOV state, the attributes
// fuzz_readers.cpp's resume target expects) as the seed of that target's corpus.
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "image.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_resume_seed OUT.exr\n");
    return 2;
  }
  const int w = 8, h = 4, n = w * h;
  psf::Image img{w, h, std::vector<float>(size_t(n) * 3, 0.5f)};
  std::vector<psf::ExrLayer> layers = {
      {"psf.state.filtered", 3, std::vector<float>(size_t(n) * 3, 2.0f)},
      {"psf.state.counts", 1, std::vector<float>(n, 4.0f)},
      {"psf.state.unfiltered", 3, std::vector<float>(size_t(n) * 3, 2.0f)},
      {"psf.state.bad", 1, std::vector<float>(n, 0.0f)},
      {"psf.state.bad_unfiltered", 1, std::vector<float>(n, 0.0f)},
      {"psf.state.aov0", 3, std::vector<float>(size_t(n) * 3, 0.5f)},
      {"psf.state.aov1", 1, std::vector<float>(n, 1.0f)},
      {"psf.state.aov2", 3, std::vector<float>(size_t(n) * 3, 0.0f)},
      {"psf.state.aov3", 1, std::vector<float>(n, 1.0f)},
  };
  std::map<std::string, std::string> attrs = {
      {"psf:scene_hash", "fuzz-hash"},   {"psf:options", "fuzz-options"}, {"psf:batch_log2", "6"},
      {"psf:state_batches", "2"},        {"psf:state_paths", "128"},      {"psf:filter_off_after", "0"},
  };
  psf::write_exr(argv[1], img, attrs, layers);
  return 0;
}
