// Host scheduler: sizes and batch plans from device memory limits.
#include <catch2/catch.hpp>

#include "scheduler.h"

TEST_CASE("Scheduler: sizes parse with binary units", "[scheduler]") {
  CHECK(psf::parse_bytes("1048576") == 1048576u);
  CHECK(psf::parse_bytes("256M") == 256ull << 20);
  CHECK(psf::parse_bytes("256MB") == 256ull << 20);
  CHECK(psf::parse_bytes("256MiB") == 256ull << 20);
  CHECK(psf::parse_bytes("2G") == 2ull << 30);
  CHECK(psf::parse_bytes("1.5g") == 3ull << 29);
  CHECK(psf::parse_bytes("512k") == 512ull << 10);
  CHECK(psf::parse_bytes("100B") == 100u);
  for (const char* bad : {"", "M", "-5M", "12Q", "1.2.3G", "0"}) {
    INFO(bad);
    CHECK_THROWS_AS(psf::parse_bytes(bad), std::invalid_argument);
  }
  CHECK(psf::format_bytes(3ull << 29) == "1.50 GiB");
  CHECK(psf::format_bytes(100) == "100 B");
}

TEST_CASE("Scheduler: the batch is the largest 2^m that fits every limit", "[scheduler]") {
  const std::vector<psf::BufferNeed> needs = {{"state", 96}, {"rays", 32}, {"table", 8.5}};
  const double per_path = 96 + 32 + 8.5;
  SECTION("bounded by global memory") {
    auto p = psf::plan_batch(needs, 0, uint64_t(per_path * 1000), 1ull << 40, 0, 24);
    CHECK(p.log2 == 9);  // 512 paths fit in 1000 paths' worth, 1024 do not
    CHECK(p.bytes == uint64_t(per_path * 512));
    CHECK(p.largest == 96u * 512u);
  }
  SECTION("bounded by the largest single allocation") {
    auto p = psf::plan_batch(needs, 0, 1ull << 40, 96ull << 12, 0, 24);
    CHECK(p.log2 == 12);
  }
  SECTION("bounded by the budget and the fixed bytes") {
    auto p = psf::plan_batch(needs, 1 << 20, 1ull << 40, 1ull << 40, (1 << 20) + uint64_t(per_path * 4096), 24);
    CHECK(p.log2 == 12);
  }
  SECTION("bounded by max_log2") {
    CHECK(psf::plan_batch(needs, 0, 1ull << 40, 1ull << 40, 0, 20).log2 == 20);
  }
  SECTION("nothing fits: a clear error") {
    CHECK_THROWS_WITH(psf::plan_batch(needs, 0, 1000, 1ull << 40, 0, 20),
                      Catch::Contains("device memory"));
    CHECK_THROWS_WITH(psf::plan_batch(needs, 0, 1ull << 40, 1ull << 40, 5000, 20),
                      Catch::Contains("--memory-budget"));
  }
}

TEST_CASE("Scheduler: the default batch holds 4 spp of the image, 2^20 to 2^22 paths", "[scheduler]") {
  CHECK(psf::default_batch_log2(1) == 20);
  CHECK(psf::default_batch_log2(256 * 256) == 20);        // 16 spp per batch
  CHECK(psf::default_batch_log2(512 * 512) == 20);        // exactly 4 spp
  CHECK(psf::default_batch_log2(512 * 512 + 1) == 21);
  CHECK(psf::default_batch_log2(1280 * 720) == 22);       // 3.7 M paths: 4.55 spp per batch
  CHECK(psf::default_batch_log2(3840 * 2160) == 22);      // capped
  CHECK(psf::default_batch_log2(uint64_t(1) << 40) == 22);
}
