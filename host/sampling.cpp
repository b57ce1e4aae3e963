#include "sampling.h"

#include "psf_shared.h"

namespace psf {

const std::vector<JoeKuoRow>& joe_kuo_rows() {
  static const std::vector<JoeKuoRow> rows = {
#include "sobol_joe_kuo.inc"
  };
  return rows;
}

std::vector<uint32_t> sobol_matrices() {
  constexpr int B = PSF_SOBOL_BITS;
  std::vector<uint32_t> c(size_t(PSF_SOBOL_DIMS) * B);  // by dimension first, transposed at the end
  for (int b = 0; b < B; ++b) c[b] = 1u << (B - 1 - b);  // dimension 1: van der Corput
  const auto& rows = joe_kuo_rows();
  for (int dim = 1; dim < PSF_SOBOL_DIMS; ++dim) {
    const JoeKuoRow& r = rows[dim - 1];
    uint32_t* v = &c[size_t(dim) * B];
    // Joe & Kuo (2008), Eq. (3): v_i = m_i / 2^i for i <= s, then the recurrence.
    for (int i = 0; i < B; ++i) {
      if (i < r.s) {
        v[i] = r.m[i] << (B - 1 - i);
      } else {
        uint32_t x = v[i - r.s] ^ (v[i - r.s] >> r.s);
        for (int k = 1; k < r.s; ++k)
          if ((r.a >> (r.s - 1 - k)) & 1u) x ^= v[i - k];
        v[i] = x;
      }
    }
  }
  std::vector<uint32_t> t(c.size() + size_t(B / 4) * 16 * PSF_SOBOL_DIMS);
  for (int dim = 0; dim < PSF_SOBOL_DIMS; ++dim)
    for (int b = 0; b < B; ++b) t[size_t(b) * PSF_SOBOL_DIMS + dim] = c[size_t(dim) * B + b];
  // The nibbles' xors (psf_shared.h PSF_SOBOL_NIBBLES).
  for (int n = 0; n < B / 4; ++n)
    for (uint32_t v = 0; v < 16; ++v)
      for (int dim = 0; dim < PSF_SOBOL_DIMS; ++dim) {
        uint32_t x = 0;
        for (int k = 0; k < 4; ++k)
          if ((v >> k) & 1u) x ^= c[size_t(dim) * B + 4 * n + k];
        t[PSF_SOBOL_NIBBLES + (size_t(n) * 16 + v) * PSF_SOBOL_DIMS + dim] = x;
      }
  return t;
}

}  // namespace psf
