// Kernel sources embedded into the binary at build time (cmake/embed_kernels.cmake).
#pragma once
#include <string>
#include <vector>

namespace psf {

struct EmbeddedFile {
  const char* name;      // file name inside kernels/, e.g. "raycast.cl"
  std::string contents;  // the file's text
};

// Every file of kernels/ (*.cl and *.h), in no particular order.
const std::vector<EmbeddedFile>& embedded_kernel_files();

// The text of one embedded file with its `#include "..."` lines expanded from the
// other embedded files (each file at most once). Throws std::runtime_error if a
// file is missing.
std::string expand_kernel_source(const std::string& name);

}  // namespace psf
