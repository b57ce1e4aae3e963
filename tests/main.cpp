// Catch2's runner with one addition: the shared OpenCL runtime is released after
// the last test, before main returns, instead of during static destruction.
#define CATCH_CONFIG_RUNNER
#include <catch2/catch.hpp>

#include <exception>
#include <iostream>

#include "support.h"

int main(int argc, char* argv[]) {
  int result = Catch::Session().run(argc, argv);
  try {
    psf::test::release_runtime();
  } catch (const std::exception& e) {
    std::cerr << "releasing the OpenCL runtime failed: " << e.what() << "\n";
    if (result == 0) result = 1;
  }
  return result;
}
