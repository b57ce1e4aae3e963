#include "support.h"

#include <cstdlib>
#include <filesystem>
#include <memory>

namespace psf::test {

Runtime& runtime() {
  static std::unique_ptr<Runtime> rt;
  if (!rt) {
    const char* spec = std::getenv("PSF_TEST_DEVICE");
    rt = std::make_unique<Runtime>(choose_device(spec ? spec : ""));
  }
  return *rt;
}

std::optional<std::string> shared_dir() {
  namespace fs = std::filesystem;
  if (const char* env = std::getenv("PSF_SHARED"); env && *env) {
    if (fs::is_directory(env)) return std::string(env);
    return std::nullopt;
  }
  fs::path p = fs::path(PSF_SOURCE_DIR) / ".." / "shared";
  if (fs::is_directory(p)) return fs::canonical(p).string();
  return std::nullopt;
}

std::string source_path(const std::string& relative) {
  return (std::filesystem::path(PSF_SOURCE_DIR) / relative).string();
}

}  // namespace psf::test
