// Shared test support: one OpenCL runtime per test process (PoCL compiles are
// slow, so the program is built once), and the location of ../shared.
#pragma once
#include <optional>
#include <string>

#include "cl/runtime.h"

namespace psf::test {

// The runtime on the default device (PSF_TEST_DEVICE overrides), built on first use.
Runtime& runtime();

// The shared data folder ($PSF_SHARED, else ../shared beside the source tree), if present.
std::optional<std::string> shared_dir();

// Path of a file under the source tree.
std::string source_path(const std::string& relative);

}  // namespace psf::test
