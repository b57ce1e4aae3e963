// The render session (host/session.cpp) through the command line: resume equals
// an uninterrupted run, several devices equal one, an interrupted render leaves a
// readable image, batch sizing from a memory budget, AOV layers.
#include <catch2/catch.hpp>

#include <sys/wait.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "image.h"
#include "support.h"

namespace fs = std::filesystem;

namespace {

using Run = psf::test::PsfRun;

Run psf_run(const std::string& args) { return psf::test::run_psf(args); }

fs::path temp_dir() { return psf::test::temp_dir("psf-session"); }

// The Cornell box at 24x24 (576 pixels) in batches of 2^10 paths: 3 spp end in a
// partial batch, so a resumed render has to redo it.
std::string box(const std::string& extra) {
  return "render " + psf::test::source_path("scenes/cornell-box.xml") + " -D res=24 --batch-log2 10 -q " + extra;
}

}  // namespace

TEST_CASE("Session: a resumed render equals one uninterrupted run", "[session]") {
  fs::path d = temp_dir();
  std::string a = (d / "a.exr").string(), b = (d / "b.exr").string(), c = (d / "c.exr").string();
  REQUIRE(psf_run(box("--spp 3 -o " + a)).status == 0);
  REQUIRE(psf_run(box("--spp 7 --resume " + a + " -o " + b)).status == 0);
  REQUIRE(psf_run(box("--spp 7 -o " + c)).status == 0);
  psf::Image ib = psf::read_exr(b), ic = psf::read_exr(c);
  CHECK(ib.rgb == ic.rgb);
  auto fb = psf::read_exr_file(b);
  CHECK(fb.attributes["psf:paths"] == std::to_string(576 * 7));
  // Resuming the finished render to the same count changes nothing.
  std::string e = (d / "e.exr").string();
  REQUIRE(psf_run(box("--spp 7 --resume " + c + " -o " + e)).status == 0);
  CHECK(psf::read_exr(e).rgb == ic.rgb);
}

TEST_CASE("Session: an incompatible --resume is refused with a clear message", "[session]") {
  fs::path d = temp_dir();
  std::string a = (d / "a.exr").string(), out = (d / "x.exr").string();
  REQUIRE(psf_run(box("--spp 2 -o " + a)).status == 0);
  Run seed = psf_run(box("--spp 4 --seed 9 --resume " + a + " -o " + out));
  CHECK(seed.status == 2);
  CHECK(seed.output.find("other options") != std::string::npos);
  // The vertices' visibility (here auto: the light sample) is an option of the render too.
  Run visibility = psf_run(box("--spp 4 --visibility-ray 50 --resume " + a + " -o " + out));
  CHECK(visibility.status == 2);
  CHECK(visibility.output.find("other options") != std::string::npos);
  REQUIRE(psf_run(box("--spp 3 --visibility-ray auto --resume " + a + " -o " + out)).status == 0);
  fs::remove(out);
  Run scene = psf_run(box("--spp 4 -D res=32 --resume " + a + " -o " + out));
  CHECK(scene.status == 2);
  CHECK(scene.output.find("another scene") != std::string::npos);
  Run fewer = psf_run(box("--spp 1 --resume " + a + " -o " + out));
  CHECK(fewer.status == 2);
  psf::Image plain;
  plain.width = plain.height = 4;
  plain.rgb.assign(48, 0.5f);
  psf::write_exr((d / "plain.exr").string(), plain);
  Run foreign = psf_run(box("--spp 4 --resume " + (d / "plain.exr").string() + " -o " + out));
  CHECK(foreign.status == 2);
  CHECK(foreign.output.find("not a psf render") != std::string::npos);
  // A render of another psf version (here one before the principled BSDF and the
  // foreshortened footprint) is refused before anything else is compared.
  psf::write_exr((d / "old.exr").string(), plain, {{"psf:version", "0.1.0"}});
  Run old = psf_run(box("--spp 4 --resume " + (d / "old.exr").string() + " -o " + out));
  CHECK(old.status == 2);
  CHECK(old.output.find("rendered by psf 0.1.0, not by this psf " PSF_VERSION) != std::string::npos);
  CHECK_FALSE(fs::exists(out));
}

TEST_CASE("Session: two devices give the same image as one", "[session]") {
  // Two runtimes on device 0 (two contexts), batches interleaved between them.
  fs::path d = temp_dir();
  std::string one = (d / "one.exr").string(), two = (d / "two.exr").string();
  REQUIRE(psf_run(box("--spp 6 --device 0 -o " + one)).status == 0);
  REQUIRE(psf_run(box("--spp 6 --device 0,0 -o " + two)).status == 0);
  CHECK(psf::read_exr(one).rgb == psf::read_exr(two).rgb);
}

TEST_CASE("Session: an interrupted render leaves a readable image of its finished batches", "[session]") {
  fs::path d = temp_dir();
  std::string out = (d / "int.exr").string();
  const char* b = std::getenv("PSF_BINARY");
  // Interrupt once the first checkpoint exists (whatever the program build costs),
  // then let the render go on a little: it must finish its batch and write again.
  std::string cmd = std::string(b ? b : PSF_BINARY_DEFAULT) + " " +
                    box("--spp 1000000 --checkpoint-seconds 0.2 -o " + out) +
                    " & pid=$!; for i in $(seq 600); do [ -f " + out +
                    " ] && break; sleep 0.1; done; sleep 1; kill -INT $pid; wait $pid; echo status=$?";
  FILE* p = popen(("sh -c '" + cmd + "' 2>&1").c_str(), "r");
  REQUIRE(p);
  std::string text;
  std::array<char, 256> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), p)) > 0) text.append(buf.data(), n);
  pclose(p);
  CHECK(text.find("status=130") != std::string::npos);
  REQUIRE(fs::exists(out));
  auto f = psf::read_exr_file(out);
  uint64_t paths = std::stoull(f.attributes["psf:paths"]);
  CHECK(paths > 0);
  CHECK(paths % 1024 == 0);  // whole batches only
  for (float v : f.channels["R"]) REQUIRE(std::isfinite(v));
}

TEST_CASE("Session: the batch is sized from --memory-budget", "[session]") {
  fs::path d = temp_dir();
  Run r = psf_run("render " + psf::test::source_path("scenes/cornell-box.xml") +
                  " -D res=16 --spp 2 --memory-budget 80M -o " + (d / "m.exr").string());
  REQUIRE(r.status == 0);
  CHECK(r.output.find("batches of 2^") != std::string::npos);
  CHECK(r.output.find("2^20") == std::string::npos);  // 80M cannot hold 2^20 paths
  Run tiny = psf_run("render " + psf::test::source_path("scenes/cornell-box.xml") +
                     " -D res=16 --spp 2 --memory-budget 1K -o " + (d / "m.exr").string());
  CHECK(tiny.status == 2);
  CHECK(tiny.output.find("--memory-budget") != std::string::npos);
  Run bad = psf_run("render " + psf::test::source_path("scenes/cornell-box.xml") + " --memory-budget lots");
  CHECK(bad.status == 2);
}

TEST_CASE("Session: albedo, normal and depth AOVs of the filtering vertices", "[session]") {
  fs::path d = temp_dir();
  std::string out = (d / "aov.exr").string();
  REQUIRE(psf_run(box("--spp 2 --aov albedo,normal,depth -o " + out)).status == 0);
  auto f = psf::read_exr_file(out);
  for (const char* c : {"albedo.R", "albedo.G", "albedo.B", "normal.R", "normal.G", "normal.B", "depth.Y"})
    REQUIRE(f.channels.count(c));
  size_t pixels = 24 * 24;
  for (size_t i = 0; i < pixels; ++i) {
    float a = f.channels["albedo.R"][i], depth = f.channels["depth.Y"][i];
    REQUIRE(a >= 0.0f);
    REQUIRE(a <= 1.0f);
    REQUIRE(depth >= 0.0f);
    float nx = f.channels["normal.R"][i], ny = f.channels["normal.G"][i], nz = f.channels["normal.B"][i];
    REQUIRE(std::sqrt(nx * nx + ny * ny + nz * nz) <= 1.0001f);
  }
  // The box is about 800 mm from the camera: the mean depth lies near that.
  double mean = 0;
  for (float v : f.channels["depth.Y"]) mean += v;
  mean /= pixels;
  CHECK(mean > 500);
  CHECK(mean < 1500);
}

TEST_CASE("Session: --time stops a render after the batch that reaches it", "[session]") {
  fs::path d = temp_dir();
  std::string out = (d / "t.exr").string();
  Run r = psf_run(box("--time 1 -o " + out));
  REQUIRE(r.status == 0);
  auto f = psf::read_exr_file(out);
  CHECK(std::stoull(f.attributes["psf:paths"]) >= 1024);
}
