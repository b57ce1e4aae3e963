#include "cl/runtime.h"

#include <algorithm>
#include <cctype>
#include <functional>
#include <set>
#include <sstream>

#include "cl/embedded.h"

namespace psf {

const char* cl_error_name(cl_int code) {
  switch (code) {
#define PSF_CL_CASE(x) \
  case x:              \
    return #x;
    PSF_CL_CASE(CL_SUCCESS)
    PSF_CL_CASE(CL_DEVICE_NOT_FOUND)
    PSF_CL_CASE(CL_DEVICE_NOT_AVAILABLE)
    PSF_CL_CASE(CL_COMPILER_NOT_AVAILABLE)
    PSF_CL_CASE(CL_MEM_OBJECT_ALLOCATION_FAILURE)
    PSF_CL_CASE(CL_OUT_OF_RESOURCES)
    PSF_CL_CASE(CL_OUT_OF_HOST_MEMORY)
    PSF_CL_CASE(CL_PROFILING_INFO_NOT_AVAILABLE)
    PSF_CL_CASE(CL_MEM_COPY_OVERLAP)
    PSF_CL_CASE(CL_IMAGE_FORMAT_MISMATCH)
    PSF_CL_CASE(CL_IMAGE_FORMAT_NOT_SUPPORTED)
    PSF_CL_CASE(CL_BUILD_PROGRAM_FAILURE)
    PSF_CL_CASE(CL_MAP_FAILURE)
    PSF_CL_CASE(CL_MISALIGNED_SUB_BUFFER_OFFSET)
    PSF_CL_CASE(CL_EXEC_STATUS_ERROR_FOR_EVENTS_IN_WAIT_LIST)
    PSF_CL_CASE(CL_COMPILE_PROGRAM_FAILURE)
    PSF_CL_CASE(CL_LINKER_NOT_AVAILABLE)
    PSF_CL_CASE(CL_LINK_PROGRAM_FAILURE)
    PSF_CL_CASE(CL_DEVICE_PARTITION_FAILED)
    PSF_CL_CASE(CL_KERNEL_ARG_INFO_NOT_AVAILABLE)
    PSF_CL_CASE(CL_INVALID_VALUE)
    PSF_CL_CASE(CL_INVALID_DEVICE_TYPE)
    PSF_CL_CASE(CL_INVALID_PLATFORM)
    PSF_CL_CASE(CL_INVALID_DEVICE)
    PSF_CL_CASE(CL_INVALID_CONTEXT)
    PSF_CL_CASE(CL_INVALID_QUEUE_PROPERTIES)
    PSF_CL_CASE(CL_INVALID_COMMAND_QUEUE)
    PSF_CL_CASE(CL_INVALID_HOST_PTR)
    PSF_CL_CASE(CL_INVALID_MEM_OBJECT)
    PSF_CL_CASE(CL_INVALID_IMAGE_FORMAT_DESCRIPTOR)
    PSF_CL_CASE(CL_INVALID_IMAGE_SIZE)
    PSF_CL_CASE(CL_INVALID_SAMPLER)
    PSF_CL_CASE(CL_INVALID_BINARY)
    PSF_CL_CASE(CL_INVALID_BUILD_OPTIONS)
    PSF_CL_CASE(CL_INVALID_PROGRAM)
    PSF_CL_CASE(CL_INVALID_PROGRAM_EXECUTABLE)
    PSF_CL_CASE(CL_INVALID_KERNEL_NAME)
    PSF_CL_CASE(CL_INVALID_KERNEL_DEFINITION)
    PSF_CL_CASE(CL_INVALID_KERNEL)
    PSF_CL_CASE(CL_INVALID_ARG_INDEX)
    PSF_CL_CASE(CL_INVALID_ARG_VALUE)
    PSF_CL_CASE(CL_INVALID_ARG_SIZE)
    PSF_CL_CASE(CL_INVALID_KERNEL_ARGS)
    PSF_CL_CASE(CL_INVALID_WORK_DIMENSION)
    PSF_CL_CASE(CL_INVALID_WORK_GROUP_SIZE)
    PSF_CL_CASE(CL_INVALID_WORK_ITEM_SIZE)
    PSF_CL_CASE(CL_INVALID_GLOBAL_OFFSET)
    PSF_CL_CASE(CL_INVALID_EVENT_WAIT_LIST)
    PSF_CL_CASE(CL_INVALID_EVENT)
    PSF_CL_CASE(CL_INVALID_OPERATION)
    PSF_CL_CASE(CL_INVALID_GL_OBJECT)
    PSF_CL_CASE(CL_INVALID_BUFFER_SIZE)
    PSF_CL_CASE(CL_INVALID_MIP_LEVEL)
    PSF_CL_CASE(CL_INVALID_GLOBAL_WORK_SIZE)
    PSF_CL_CASE(CL_INVALID_PROPERTY)
    PSF_CL_CASE(CL_INVALID_IMAGE_DESCRIPTOR)
    PSF_CL_CASE(CL_INVALID_COMPILER_OPTIONS)
    PSF_CL_CASE(CL_INVALID_LINKER_OPTIONS)
    PSF_CL_CASE(CL_INVALID_DEVICE_PARTITION_COUNT)
#undef PSF_CL_CASE
    case -1001:
      return "CL_PLATFORM_NOT_FOUND_KHR";
    default:
      return "CL_UNKNOWN_ERROR";
  }
}

ClError::ClError(cl_int code, const std::string& where)
    : std::runtime_error("OpenCL error " + std::string(cl_error_name(code)) + " (" +
                         std::to_string(code) + ") in " + where),
      code_(code) {}

namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

std::string trim(std::string s) {
  while (!s.empty() && (s.back() == '\0' || std::isspace(static_cast<unsigned char>(s.back()))))
    s.pop_back();
  size_t b = 0;
  while (b < s.size() && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  return s.substr(b);
}

std::string type_name(cl_device_type t) {
  if (t & CL_DEVICE_TYPE_GPU) return "GPU";
  if (t & CL_DEVICE_TYPE_CPU) return "CPU";
  if (t & CL_DEVICE_TYPE_ACCELERATOR) return "accelerator";
  return "other";
}

const char* kNoPlatformHelp =
    "no OpenCL platform found. Install an OpenCL driver, e.g. on Debian: "
    "apt-get install pocl-opencl-icd (OpenCL on the CPU)";

}  // namespace

std::vector<DeviceInfo> list_devices() {
  std::vector<cl::Platform> platforms;
  try {
    cl::Platform::get(&platforms);
  } catch (const cl::Error& e) {
    if (e.err() == -1001 || e.err() == CL_PLATFORM_NOT_FOUND_KHR) throw NoDeviceError(kNoPlatformHelp);
    throw ClError(e.err(), "clGetPlatformIDs");
  }
  if (platforms.empty()) throw NoDeviceError(kNoPlatformHelp);
  std::vector<DeviceInfo> out;
  for (size_t p = 0; p < platforms.size(); ++p) {
    std::vector<cl::Device> devices;
    try {
      platforms[p].getDevices(CL_DEVICE_TYPE_ALL, &devices);
    } catch (const cl::Error& e) {
      if (e.err() == CL_DEVICE_NOT_FOUND) continue;
      throw ClError(e.err(), "clGetDeviceIDs");
    }
    for (auto& d : devices) {
      DeviceInfo info;
      info.index = static_cast<int>(out.size());
      info.platform_index = static_cast<int>(p);
      info.platform = trim(platforms[p].getInfo<CL_PLATFORM_NAME>());
      info.name = trim(d.getInfo<CL_DEVICE_NAME>());
      info.version = trim(d.getInfo<CL_DEVICE_VERSION>());
      info.driver = trim(d.getInfo<CL_DRIVER_VERSION>());
      info.type = type_name(d.getInfo<CL_DEVICE_TYPE>());
      info.global_mem = d.getInfo<CL_DEVICE_GLOBAL_MEM_SIZE>();
      info.max_alloc = d.getInfo<CL_DEVICE_MAX_MEM_ALLOC_SIZE>();
      info.local_mem = d.getInfo<CL_DEVICE_LOCAL_MEM_SIZE>();
      info.compute_units = d.getInfo<CL_DEVICE_MAX_COMPUTE_UNITS>();
      info.max_work_group = d.getInfo<CL_DEVICE_MAX_WORK_GROUP_SIZE>();
      info.device = d;
      out.push_back(info);
    }
  }
  if (out.empty()) throw NoDeviceError("no OpenCL device found on any platform");
  return out;
}

DeviceInfo choose_device(const std::string& spec) {
  auto devices = list_devices();
  if (spec.empty()) {
    for (auto& d : devices)
      if (d.type == "GPU") return d;
    for (auto& d : devices)
      if (d.type == "CPU") return d;
    return devices.front();
  }
  bool numeric = std::all_of(spec.begin(), spec.end(), [](unsigned char c) { return std::isdigit(c); });
  if (numeric) {
    size_t i = std::stoul(spec);
    if (i < devices.size()) return devices[i];
    throw std::invalid_argument("--device " + spec + ": there are only " +
                                std::to_string(devices.size()) + " devices (see `psf devices`)");
  }
  for (auto& d : devices)
    if (lower(d.platform + " " + d.name).find(lower(spec)) != std::string::npos) return d;
  throw std::invalid_argument("--device " + spec + ": no device name matches (see `psf devices`)");
}

std::string expand_kernel_source(const std::string& name) {
  const auto& files = embedded_kernel_files();
  std::set<std::string> seen;
  std::ostringstream out;
  std::function<void(const std::string&)> emit = [&](const std::string& file) {
    if (!seen.insert(file).second) return;
    auto it = std::find_if(files.begin(), files.end(), [&](const EmbeddedFile& f) { return file == f.name; });
    if (it == files.end()) throw std::runtime_error("kernel source '" + file + "' is not embedded");
    std::istringstream in(it->contents);
    std::string line;
    int line_no = 0;
    out << "#line 1 \"" << file << "\"\n";
    while (std::getline(in, line)) {
      ++line_no;
      std::string t = trim(line);
      if (t.rfind("#include \"", 0) == 0) {
        size_t end = t.find('"', 10);
        emit(t.substr(10, end - 10));
        out << "#line " << line_no + 1 << " \"" << file << "\"\n";
      } else {
        out << line << '\n';
      }
    }
  };
  emit(name);
  return out.str();
}

Runtime::Runtime(const DeviceInfo& device, const std::string& extra_options) : device_(device) {
  try {
    context_ = cl::Context(device_.device);
    queue_ = cl::CommandQueue(context_, device_.device, CL_QUEUE_PROFILING_ENABLE);
  } catch (const cl::Error& e) {
    throw ClError(e.err(), std::string(e.what()) + " for device '" + device_.name + "'");
  }
  std::string source = expand_kernel_source("program.cl");
  std::string options = "-cl-std=CL1.2 -DPSF_BVH_WIDTH=" + std::to_string(PSF_BVH_WIDTH);
  // The filter's variant by device kind (kernels/filter.cl; measured, README):
  // CPUs test 8 candidates at a time without branches, GPUs 2 at a time,
  // skipping the similarity tests where none lies in the ball.
  if (extra_options.find("PSF_FILTER_LANES") == std::string::npos)
    options += device_.type == "GPU" ? " -DPSF_FILTER_LANES=2 -DPSF_FILTER_SKIP=1"
                                     : " -DPSF_FILTER_LANES=8 -DPSF_FILTER_SKIP=0";
  // Prefetches in the kernels that read at random (kernels/program.cl psf_prefetch):
  // Clang's builtin on CPU devices (PoCL), where OpenCL's prefetch() does nothing.
  if (device_.type == "CPU" && extra_options.find("PSF_PREFETCH") == std::string::npos)
    options += " -DPSF_PREFETCH=1";
  // Code placement that differs by device kind (kernels/program.cl PSF_CPU_DEVICE).
  if (device_.type == "CPU" && extra_options.find("PSF_CPU_DEVICE") == std::string::npos)
    options += " -DPSF_CPU_DEVICE=1";
  if (!extra_options.empty()) options += " " + extra_options;
  auto t0 = std::chrono::steady_clock::now();
  program_ = cl::Program(context_, source);
  try {
    program_.build({device_.device}, options.c_str());
  } catch (const cl::Error& e) {
    std::string log;
    try {
      log = program_.getBuildInfo<CL_PROGRAM_BUILD_LOG>(device_.device);
    } catch (...) {
    }
    throw ClError(e.err(), "clBuildProgram (options: " + options + "); build log:\n" + log);
  }
  build_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

cl::Kernel& Runtime::kernel(const std::string& name) {
  auto it = kernels_.find(name);
  if (it != kernels_.end()) return it->second;
  try {
    return kernels_.emplace(name, cl::Kernel(program_, name.c_str())).first->second;
  } catch (const cl::Error& e) {
    throw ClError(e.err(), "clCreateKernel(" + name + ")");
  }
}

cl::Buffer Runtime::buffer(cl_mem_flags flags, size_t bytes, const void* host) {
  try {
    return cl::Buffer(context_, flags, bytes ? bytes : 16, const_cast<void*>(host));
  } catch (const cl::Error& e) {
    throw ClError(e.err(), "clCreateBuffer(" + std::to_string(bytes) + " bytes)");
  }
}

void Runtime::read(const cl::Buffer& buf, void* dst, size_t bytes, size_t offset) {
  try {
    queue_.enqueueReadBuffer(buf, CL_TRUE, offset, bytes, dst);
  } catch (const cl::Error& e) {
    throw ClError(e.err(), "clEnqueueReadBuffer(" + std::to_string(bytes) + " bytes)");
  }
}

void Runtime::write(const cl::Buffer& buf, const void* src, size_t bytes, size_t offset) {
  try {
    queue_.enqueueWriteBuffer(buf, CL_TRUE, offset, bytes, src);
  } catch (const cl::Error& e) {
    throw ClError(e.err(), "clEnqueueWriteBuffer(" + std::to_string(bytes) + " bytes)");
  }
}

void Runtime::zero(const cl::Buffer& buf, size_t bytes) {
  try {
    queue_.enqueueFillBuffer(buf, cl_uint(0), 0, bytes);
  } catch (const cl::Error& e) {
    throw ClError(e.err(), "clEnqueueFillBuffer(" + std::to_string(bytes) + " bytes)");
  }
}

void Runtime::enqueue(const std::string& name, cl::Kernel& k, size_t global, size_t local) {
  if (global == 0) return;
  local = std::max<size_t>(1, std::min(local, device_.max_work_group));
  size_t rounded = (global + local - 1) / local * local;
  cl::Event ev;
  try {
    queue_.enqueueNDRangeKernel(k, cl::NullRange, cl::NDRange(rounded), cl::NDRange(local), nullptr, &ev);
  } catch (const cl::Error& e) {
    throw ClError(e.err(), "clEnqueueNDRangeKernel(" + name + ", global " + std::to_string(rounded) +
                               ", local " + std::to_string(local) + ")");
  }
  pending_.emplace_back(name, ev);
  if (pending_.size() > 4096) finish();
}

void Runtime::finish() {
  try {
    queue_.finish();
  } catch (const cl::Error& e) {
    throw ClError(e.err(), "clFinish");
  }
  for (auto& [name, ev] : pending_) {
    auto start = ev.getProfilingInfo<CL_PROFILING_COMMAND_START>();
    auto end = ev.getProfilingInfo<CL_PROFILING_COMMAND_END>();
    KernelTime& t = stats_[name];
    t.launches += 1;
    t.ms += (end - start) * 1e-6;
  }
  pending_.clear();
}

}  // namespace psf
