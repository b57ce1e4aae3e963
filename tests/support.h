// Shared test support: one OpenCL runtime per test process (PoCL compiles are
// slow, so the program is built once), and the location of ../shared.
#pragma once
#include <optional>
#include <string>

#include <glm/glm.hpp>

#include "cl/runtime.h"
#include "scene/scene.h"

namespace psf::test {

// The runtime on the default device (PSF_TEST_DEVICE overrides), built on first use.
Runtime& runtime();

// Finishes and destroys the shared runtime (its kernels, program, queue and
// context), if one was built; runtime() after this builds a new one.
// tests/main.cpp calls it after the last test so that the OpenCL objects are
// released before exit. Left to static destruction, the runtime's holder
// (registered for destruction before the OpenCL implementation's lazily
// created statics) is destroyed after them: under Oclgrind, clReleaseProgram
// then freed corrupted memory ("corrupted double-linked list") at exit.
void release_runtime();

// True when PSF_TEST_SMALL is set to anything but "" or "0": the tests pick
// smaller problem sizes (fewer elements, pixels, samples) so that a device
// simulator such as Oclgrind (scripts/oclgrind sets it) finishes in minutes. The
// tests check the same properties either way, with the same tolerances; only
// the sizes shrink. Without it every size is the normal one.
bool small_sizes();

// `normal`, or `small` under small_sizes().
template <class T>
T pick(T normal, T small) {
  return small_sizes() ? small : normal;
}

// The shared data folder ($PSF_SHARED, else ../shared beside the source tree), if present.
std::optional<std::string> shared_dir();

// Path of a file under the source tree.
std::string source_path(const std::string& relative);

// One run of the psf binary ($PSF_BINARY, else the one built beside the tests).
struct PsfRun {
  int status = -1;     // exit status; 128 + signal when killed (124: timeout)
  std::string output;  // stdout and stderr together
};

// Runs `prefix psf args` through the shell (prefix: environment assignments or a
// command such as `timeout 300`).
PsfRun run_psf(const std::string& args, const std::string& prefix = "");

// A folder of this test process under the system's temporary folder.
std::string temp_dir(const std::string& name);

// Points the scene's camera from `origin` at `target` (up, field of view in
// degrees along the camera's fov_axis) and sets a square film of `size` pixels.
void look_at(psf::Scene& s, glm::vec3 origin, glm::vec3 target, glm::vec3 up, float fov_degrees, int size);

}  // namespace psf::test
