// libFuzzer entry points for the scene readers and the resume-state reader.
// The readers take file paths (an OBJ names its MTL library, a glTF its
// buffers), so each input is written to a file in a per-process temporary
// folder and read from there. One source, one target per PSF_FUZZ_TARGET:
//   xml: load_mitsuba   obj: load_obj_scene   mtl: an OBJ whose mtllib is the input
//   ply: load_ply_scene  gltf / glb: load_gltf_scene  resume: read_exr_file + load_state
//   serialized: read_serialized, its first and second mesh
// A reader may reject an input only by throwing; anything else (a crash, a
// sanitizer report, an exception of another type escaping) is a finding.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include "render.h"
#include "scene/formats.h"
#include "scene/loaders.h"
#include "scene/scene.h"
#include "session.h"

namespace {

namespace fs = std::filesystem;

const fs::path& work_dir() {
  static const fs::path dir = [] {
    fs::path d = fs::temp_directory_path() / ("psf-fuzz-" + std::to_string(::getpid()));
    fs::create_directories(d);
    return d;
  }();
  return dir;
}

fs::path write_input(const std::string& name, const uint8_t* data, size_t size) {
  fs::path p = work_dir() / name;
  std::ofstream(p, std::ios::binary).write(reinterpret_cast<const char*>(data), std::streamsize(size));
  return p;
}

#if defined(PSF_FUZZ_RESUME)
// The film and the state attributes make_resume_seed writes (fuzz/make_resume_seed.cpp).
constexpr int kResumeWidth = 8, kResumeHeight = 4;
#endif

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  // Inputs that throw are rejected cleanly; every reader documents SceneError
  // or std::runtime_error / std::invalid_argument, all std::exception.
  try {
#if defined(PSF_FUZZ_XML)
    psf::detail::load_mitsuba(write_input("scene.xml", data, size).string(), {});
#elif defined(PSF_FUZZ_OBJ)
    psf::detail::load_obj_scene(write_input("mesh.obj", data, size).string());
#elif defined(PSF_FUZZ_MTL)
    static const fs::path obj = [] {
      fs::path p = work_dir() / "uses_mtl.obj";
      std::ofstream(p) << "mtllib fuzz.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                          "usemtl a\nf 1/1 2/2 3/3\nusemtl b\nf 1/1 3/3 2/2\n";
      return p;
    }();
    write_input("fuzz.mtl", data, size);
    psf::detail::load_obj_scene(obj.string());
#elif defined(PSF_FUZZ_PLY)
    psf::detail::load_ply_scene(write_input("mesh.ply", data, size).string());
#elif defined(PSF_FUZZ_SERIALIZED)
    const std::string path = write_input("mesh.serialized", data, size).string();
    try {
      psf::detail::read_serialized(path, 0);
    } catch (const std::exception&) {
    }
    psf::detail::read_serialized(path, 1);
#elif defined(PSF_FUZZ_GLTF)
    psf::detail::load_gltf_scene(write_input("scene.gltf", data, size).string());
#elif defined(PSF_FUZZ_GLB)
    psf::detail::load_gltf_scene(write_input("scene.glb", data, size).string());
#elif defined(PSF_FUZZ_RESUME)
    psf::Accumulator acc;
    acc.reset(kResumeWidth, kResumeHeight, true);
    psf::load_state(write_input("state.exr", data, size).string(), "fuzz-hash", "fuzz-options", acc);
#else
#error "define one PSF_FUZZ_<TARGET>"
#endif
  } catch (const std::exception&) {
  }
  return 0;
}
