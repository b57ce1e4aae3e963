// Sobol sampling stage (host side): the generator matrices uploaded to kernels/sampling.cl.
#pragma once
#include <cstdint>
#include <vector>

namespace psf {

// One row of Joe & Kuo's direction-number table.
struct JoeKuoRow {
  int d;                    // dimension, 1-based (2.. in the table)
  int s;                    // degree of the primitive polynomial
  uint32_t a;               // its interior coefficients as bits
  std::vector<uint32_t> m;  // initial direction numbers m_1..m_s
};

// The embedded rows for dimensions 2..PSF_SOBOL_DIMS (host/sobol_joe_kuo.inc).
const std::vector<JoeKuoRow>& joe_kuo_rows();

// Generator matrices: PSF_SOBOL_DIMS x 32 columns, column b of dimension d at
// [b * PSF_SOBOL_DIMS + d] (the direction number v_{b+1} scaled to 32 bits), so
// that the kernels read the columns of consecutive dimensions as one vector;
// then, from PSF_SOBOL_NIBBLES on, the xors of each nibble's four columns for
// its 16 values, so that four bits of an index take one read.
std::vector<uint32_t> sobol_matrices();

}  // namespace psf
