#include "support.h"

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <unistd.h>
#include <filesystem>
#include <memory>

namespace psf::test {

namespace {
std::unique_ptr<Runtime>& shared_runtime() {
  static std::unique_ptr<Runtime> rt;
  return rt;
}
}  // namespace

Runtime& runtime() {
  auto& rt = shared_runtime();
  if (!rt) {
    const char* spec = std::getenv("PSF_TEST_DEVICE");
    rt = std::make_unique<Runtime>(choose_device(spec ? spec : ""));
  }
  return *rt;
}

void release_runtime() {
  std::unique_ptr<Runtime> rt = std::move(shared_runtime());
  if (rt) rt->finish();  // destroyed on return, or while a failure unwinds
}

bool small_sizes() {
  static const bool small = [] {
    const char* env = std::getenv("PSF_TEST_SMALL");
    return env && *env && std::string(env) != "0";
  }();
  return small;
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

PsfRun run_psf(const std::string& args, const std::string& prefix) {
  const char* b = std::getenv("PSF_BINARY");
  std::string cmd = prefix + (prefix.empty() ? "" : " ") + (b ? b : PSF_BINARY_DEFAULT) + " " + args + " 2>&1";
  PsfRun r;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) throw std::runtime_error("cannot run " + cmd);
  std::array<char, 4096> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), p)) > 0) r.output.append(buf.data(), n);
  int st = pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + (WIFSIGNALED(st) ? WTERMSIG(st) : 0);
  return r;
}

std::string temp_dir(const std::string& name) {
  namespace fs = std::filesystem;
  fs::path d = fs::temp_directory_path() / (name + "-" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d.string();
}

void look_at(psf::Scene& s, glm::vec3 origin, glm::vec3 target, glm::vec3 up, float fov_degrees, int size) {
  s.camera.origin = origin;
  s.camera.target = target;
  s.camera.up = up;
  s.camera.fov_degrees = fov_degrees;
  s.width = s.height = size;
}

}  // namespace psf::test
