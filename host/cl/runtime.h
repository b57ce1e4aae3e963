// OpenCL runtime layer: device discovery and choice, program build from the
// embedded kernel sources, named and timed kernel launches, errors by name.
#pragma once
#include <CL/opencl.hpp>

#include <chrono>
#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace psf {

// The symbolic name of an OpenCL status code ("CL_OUT_OF_RESOURCES").
const char* cl_error_name(cl_int code);

// An OpenCL failure: the call (and kernel, where one was launched) and the code by name.
class ClError : public std::runtime_error {
 public:
  ClError(cl_int code, const std::string& where);
  cl_int code() const { return code_; }

 private:
  cl_int code_;
};

// Raised when no OpenCL platform or device is present at all.
class NoDeviceError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct DeviceInfo {
  int index = 0;                 // position in the flat list of all devices
  int platform_index = 0;        // platform this device belongs to
  std::string platform;          // platform name
  std::string name;              // device name
  std::string version;           // CL_DEVICE_VERSION
  std::string driver;            // CL_DRIVER_VERSION
  std::string type;              // "GPU", "CPU", "accelerator", "other"
  uint64_t global_mem = 0;       // CL_DEVICE_GLOBAL_MEM_SIZE in bytes
  uint64_t max_alloc = 0;        // CL_DEVICE_MAX_MEM_ALLOC_SIZE in bytes
  uint64_t local_mem = 0;        // CL_DEVICE_LOCAL_MEM_SIZE in bytes
  unsigned compute_units = 0;    // CL_DEVICE_MAX_COMPUTE_UNITS
  size_t max_work_group = 0;     // CL_DEVICE_MAX_WORK_GROUP_SIZE
  cl::Device device;             // the handle
};

// Every device of every platform. Throws NoDeviceError when there is no platform.
std::vector<DeviceInfo> list_devices();

// Chooses a device: "" picks the first GPU, else the first CPU device; a number
// picks by index in list_devices(); anything else is a case-insensitive substring
// of "platform device". Throws std::invalid_argument when nothing matches.
DeviceInfo choose_device(const std::string& spec);

// Accumulated time of one named kernel.
struct KernelTime {
  uint64_t launches = 0;  // number of enqueues
  double ms = 0.0;        // device time from CL_PROFILING_COMMAND_START to END
};

// Owns a context, an in-order profiling queue and the program built from the
// embedded kernels. Kernel launches are named and timed with events.
class Runtime {
 public:
  // Builds the program from kernels/program.cl with `-cl-std=CL1.2` and `extra_options`.
  explicit Runtime(const DeviceInfo& device, const std::string& extra_options = "");

  const DeviceInfo& device() const { return device_; }
  cl::Context& context() { return context_; }
  cl::CommandQueue& queue() { return queue_; }
  cl::Program& program() { return program_; }
  double build_seconds() const { return build_seconds_; }

  // A kernel object of the program (created once, then cached).
  cl::Kernel& kernel(const std::string& name);

  // A device buffer; `bytes` of 0 allocates a minimal placeholder so kernels can
  // always be given a valid buffer.
  cl::Buffer buffer(cl_mem_flags flags, size_t bytes, const void* host = nullptr);

  template <class T>
  cl::Buffer upload(const std::vector<T>& data, cl_mem_flags flags = CL_MEM_READ_ONLY) {
    return buffer(flags | (data.empty() ? 0 : CL_MEM_COPY_HOST_PTR), data.size() * sizeof(T),
                  data.empty() ? nullptr : data.data());
  }
  template <class T>
  std::vector<T> download(const cl::Buffer& buf, size_t count) {
    std::vector<T> out(count);
    if (count) read(buf, out.data(), count * sizeof(T));
    return out;
  }
  void read(const cl::Buffer& buf, void* dst, size_t bytes, size_t offset = 0);
  void write(const cl::Buffer& buf, const void* src, size_t bytes, size_t offset = 0);
  // Sets `bytes` (a multiple of 4) of `buf` to zero without waiting: queued behind
  // the kernels before it and ahead of those after it.
  void zero(const cl::Buffer& buf, size_t bytes);

  // Sets the arguments in order and enqueues `name` over `global` work-items,
  // rounded up to a multiple of `local` (kernels guard their tail).
  template <class... Args>
  void launch(const std::string& name, size_t global, size_t local, const Args&... args) {
    cl::Kernel& k = kernel(name);
    cl_uint i = 0;
    (set_arg(k, name, i++, args), ...);
    enqueue(name, k, global, local);
  }

  // Waits for the queue and adds the time of every finished launch to stats().
  void finish();
  const std::map<std::string, KernelTime>& stats() const { return stats_; }
  // Forgets the times so far, including launches not yet collected by finish()
  // (a launch before the reset counted after it otherwise).
  void reset_stats() {
    stats_.clear();
    pending_.clear();
  }

  static constexpr size_t kDefaultLocal = 64;

 private:
  template <class T>
  void set_arg(cl::Kernel& k, const std::string& name, cl_uint index, const T& value) {
    try {
      k.setArg(index, value);
    } catch (const cl::Error& e) {
      throw ClError(e.err(), "clSetKernelArg(" + name + ", argument " + std::to_string(index) + ")");
    }
  }
  void enqueue(const std::string& name, cl::Kernel& k, size_t global, size_t local);

  DeviceInfo device_;
  cl::Context context_;
  cl::CommandQueue queue_;
  cl::Program program_;
  double build_seconds_ = 0.0;
  std::map<std::string, cl::Kernel> kernels_;
  std::vector<std::pair<std::string, cl::Event>> pending_;
  std::map<std::string, KernelTime> stats_;
};

}  // namespace psf
