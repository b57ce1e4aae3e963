// OpenCL runtime layer: device choice, errors by name, build logs, timed launches.
#include <catch2/catch.hpp>

#include "cl/embedded.h"
#include "cl/runtime.h"
#include "support.h"

TEST_CASE("Runtime: OpenCL status codes are reported by name", "[runtime]") {
  CHECK(std::string(psf::cl_error_name(CL_OUT_OF_RESOURCES)) == "CL_OUT_OF_RESOURCES");
  CHECK(std::string(psf::cl_error_name(CL_MEM_OBJECT_ALLOCATION_FAILURE)) == "CL_MEM_OBJECT_ALLOCATION_FAILURE");
  CHECK(std::string(psf::cl_error_name(CL_INVALID_WORK_GROUP_SIZE)) == "CL_INVALID_WORK_GROUP_SIZE");
  CHECK(std::string(psf::cl_error_name(-9999)) == "CL_UNKNOWN_ERROR");
  psf::ClError e(CL_OUT_OF_RESOURCES, "clEnqueueNDRangeKernel(shade)");
  CHECK(std::string(e.what()) == "OpenCL error CL_OUT_OF_RESOURCES (-5) in clEnqueueNDRangeKernel(shade)");
}

TEST_CASE("Runtime: devices are chosen by default, index and name", "[runtime]") {
  auto devices = psf::list_devices();
  REQUIRE(!devices.empty());
  for (const auto& d : devices) {
    CHECK(d.global_mem > 0);
    CHECK(d.max_alloc > 0);
    CHECK(d.max_alloc <= d.global_mem);
    CHECK(d.compute_units > 0);
  }
  auto def = psf::choose_device("");
  bool has_gpu = std::any_of(devices.begin(), devices.end(), [](auto& d) { return d.type == "GPU"; });
  CHECK(def.type == (has_gpu ? "GPU" : devices.front().type));
  CHECK(psf::choose_device("0").index == 0);
  // A case-insensitive substring of "platform device".
  std::string name = devices.back().name;
  for (auto& c : name) c = char(std::toupper(static_cast<unsigned char>(c)));
  CHECK(psf::choose_device(name).index == devices.back().index);
  CHECK_THROWS_AS(psf::choose_device(std::to_string(devices.size())), std::invalid_argument);
  CHECK_THROWS_AS(psf::choose_device("no such device anywhere"), std::invalid_argument);
}

TEST_CASE("Runtime: a failed program build reports the whole build log", "[runtime]") {
  // An undeclared identifier as an array size breaks the build the way a typo would.
  try {
    psf::Runtime broken(psf::choose_device(""), "-DPSF_BVH_WIDTH=psf_no_such_type");
    FAIL("the build should have failed");
  } catch (const psf::ClError& e) {
    std::string what = e.what();
    CHECK(e.code() == CL_BUILD_PROGRAM_FAILURE);
    CHECK(what.find("CL_BUILD_PROGRAM_FAILURE") != std::string::npos);
    CHECK(what.find("-cl-std=CL1.2") != std::string::npos);
    CHECK(what.find("psf_no_such_type") != std::string::npos);  // from the compiler's log
  }
}

TEST_CASE("Runtime: launches are named, timed, and fail by name", "[runtime]") {
  auto& rt = psf::test::runtime();
  rt.reset_stats();
  // layout_report writes one entry per struct field it reports (72; test_layout
  // gives it 128): a buffer of 64 was overrun since the report grew past 64.
  cl::Buffer out = rt.buffer(CL_MEM_WRITE_ONLY, 128 * sizeof(cl_uint));
  for (int i = 0; i < 3; ++i) rt.launch("layout_report", 1, 1, out);
  rt.finish();
  REQUIRE(rt.stats().count("layout_report") == 1);
  CHECK(rt.stats().at("layout_report").launches == 3);
  CHECK(rt.stats().at("layout_report").ms >= 0.0);
  try {
    rt.launch("no_such_kernel", 1, 1, out);
    FAIL("launching an unknown kernel should throw");
  } catch (const psf::ClError& e) {
    CHECK(std::string(e.what()).find("no_such_kernel") != std::string::npos);
    CHECK(std::string(e.what()).find("CL_INVALID_KERNEL_NAME") != std::string::npos);
  }
}

TEST_CASE("Runtime: includes are expanded once from the embedded sources", "[runtime]") {
  std::string src = psf::expand_kernel_source("program.cl");
  CHECK(src.find("\n#include \"") == std::string::npos);
  size_t first = src.find("#define PSF_SHARED_H");
  REQUIRE(first != std::string::npos);
  CHECK(src.find("#define PSF_SHARED_H", first + 1) == std::string::npos);
  CHECK_THROWS(psf::expand_kernel_source("no_such_file.cl"));
}

TEST_CASE("Runtime: zero clears the bytes asked for, in queue order", "[runtime]") {
  auto& rt = psf::test::runtime();
  std::vector<uint32_t> v(37, 0xABCDu);
  cl::Buffer b = rt.upload(v, CL_MEM_READ_WRITE);
  rt.zero(b, 5 * sizeof(uint32_t));  // queued after the upload, before the download
  auto got = rt.download<uint32_t>(b, v.size());
  for (size_t i = 0; i < v.size(); ++i) CHECK(got[i] == (i < 5 ? 0u : 0xABCDu));
}
