// The command line: usage, bad input (clear message, exit 2, nothing damaged),
// devices, and a render to OpenEXR and PNG.
#include <catch2/catch.hpp>

#include <ImfChannelList.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfStringAttribute.h>
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "image.h"
#include "support.h"

namespace fs = std::filesystem;

namespace {

using Run = psf::test::PsfRun;

Run run(const std::string& args, const std::string& env = "") { return psf::test::run_psf(args, env); }

fs::path temp_dir() { return psf::test::temp_dir("psf-cli"); }

void write_file(const fs::path& p, const std::string& text) { std::ofstream(p) << text; }

std::string read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

const char* kTinyScene = R"(<scene version="3.0.0">
  <sensor type="perspective">
    <float name="fov" value="60"/>
    <transform name="to_world"><lookat origin="0, 0, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="16"/></film>
  </sensor>
  <shape type="rectangle"><bsdf type="diffuse"/></shape>
  <shape type="rectangle">
    <transform name="to_world"><translate z="2.5"/></transform>
    <emitter type="area"><rgb name="radiance" value="1"/></emitter>
  </shape>
</scene>
)";

}  // namespace

TEST_CASE("CLI: help describes the commands and options", "[cli]") {
  Run h = run("--help");
  CHECK(h.status == 0);
  CHECK(h.output.find("render") != std::string::npos);
  CHECK(h.output.find("devices") != std::string::npos);
  Run rh = run("render --help");
  CHECK(rh.status == 0);
  for (const char* opt : {"--spp", "--width", "--height", "--seed", "--device", "--stats", "--quiet", "-o"})
    CHECK(rh.output.find(opt) != std::string::npos);
}

TEST_CASE("CLI: devices lists the OpenCL devices with their memory", "[cli]") {
  Run d = run("devices");
  CHECK(d.status == 0);
  CHECK(d.output.find("global memory") != std::string::npos);
  CHECK(d.output.find("compute units") != std::string::npos);
}

TEST_CASE("CLI: no OpenCL platform gives one clear message and exit 1", "[cli]") {
  fs::path empty = temp_dir() / "no-icd";
  fs::create_directories(empty);
  Run d = run("devices", "OCL_ICD_VENDORS=" + empty.string() + " OCL_ICD_FILENAMES=");
  CHECK(d.status == 1);
  CHECK(d.output.find("pocl-opencl-icd") != std::string::npos);
}

TEST_CASE("CLI: bad input gives a clear error, exit 2, and leaves outputs alone", "[cli]") {
  fs::path dir = temp_dir();
  fs::path good = dir / "keep.exr";
  write_file(good, "precious");
  write_file(dir / "broken.xml", "<scene version=\"3.0.0\">\n  <shape type=\"rectangle\">\n</scene>\n");

  Run unknown = run("render --no-such-option x.xml");
  CHECK(unknown.status == 2);
  CHECK(unknown.output.find("--no-such-option") != std::string::npos);

  Run missing = run("render " + (dir / "missing.xml").string() + " -o " + good.string());
  CHECK(missing.status == 2);
  CHECK(missing.output.find("missing.xml") != std::string::npos);

  Run broken = run("render " + (dir / "broken.xml").string() + " -o " + good.string());
  CHECK(broken.status == 2);
  CHECK(broken.output.find("broken.xml:") != std::string::npos);  // file:line
  CHECK(read_file(good) == "precious");

  Run bad_spp = run("render " + (dir / "broken.xml").string() + " --spp 0");
  CHECK(bad_spp.status == 2);

  Run to_dir = run("render " + psf::test::source_path("scenes/cornell-box.xml") + " -o " + dir.string());
  CHECK(to_dir.status == 2);
  CHECK(to_dir.output.find("folder") != std::string::npos);

  Run no_dir = run("render " + psf::test::source_path("scenes/cornell-box.xml") + " -o " +
                   (dir / "nope" / "x.exr").string());
  CHECK(no_dir.status == 2);
}

TEST_CASE("CLI: render writes an OpenEXR and a PNG, deterministically per seed", "[cli]") {
  fs::path dir = temp_dir();
  write_file(dir / "tiny.xml", kTinyScene);
  fs::path a = dir / "a.exr", b = dir / "b.exr", c = dir / "c.exr";
  Run ra = run("render " + (dir / "tiny.xml").string() + " --spp 4 --seed 1 --quiet -o " + a.string());
  REQUIRE(ra.status == 0);
  CHECK(ra.output.empty());
  CHECK(fs::exists(dir / "a.png"));
  // b: the wavefront's kernels by name; a (auto: trace_lanes on a CPU device for
  // this scene of diffuse surfaces and a triangle light) must be the same image
  // up to float rounding, and per-path (d, e) bit for bit.
  Run rb = run("render " + (dir / "tiny.xml").string() +
               " --spp 4 --seed 1 --quiet --stats --path-kernels wavefront -o " + b.string());
  REQUIRE(rb.status == 0);
  for (const char* k : {"camera_rays", "raycast_closest", "raycast_any", "shade", "accumulate"})
    CHECK(rb.output.find(k) != std::string::npos);
  Run rd = run("render " + (dir / "tiny.xml").string() + " --spp 4 --seed 1 --quiet --stats --path-kernels per-path -o " +
               (dir / "d.exr").string());
  REQUIRE(rd.status == 0);
  CHECK(rd.output.find("trace_paths") != std::string::npos);
  Run re = run("render " + (dir / "tiny.xml").string() + " --spp 4 --seed 1 --quiet --stats --path-kernels lanes -o " +
               (dir / "e.exr").string());
  REQUIRE(re.status == 0);
  CHECK(re.output.find("trace_lanes") != std::string::npos);
  Run rc = run("render " + (dir / "tiny.xml").string() + " --spp 4 --seed 2 -q -o " + c.string() + " --width 12");
  REQUIRE(rc.status == 0);

  psf::Image ia = psf::read_exr(a.string()), ib = psf::read_exr(b.string()), ic = psf::read_exr(c.string());
  CHECK(ia.width == 24);
  CHECK(ia.height == 16);
  CHECK(ic.width == 12);
  CHECK(psf::read_exr((dir / "d.exr").string()).rgb == ib.rgb);
  const psf::Image ie = psf::read_exr((dir / "e.exr").string());
  CHECK(ia.rgb == ie.rgb);
  REQUIRE(ia.rgb.size() == ib.rgb.size());
  for (size_t i = 0; i < ia.rgb.size(); ++i) CHECK(ia.rgb[i] == Approx(ib.rgb[i]).epsilon(1e-3).margin(1e-6));
  double sum = 0;
  for (float v : ia.rgb) {
    REQUIRE(std::isfinite(v));
    sum += v;
  }
  CHECK(sum > 0);
}

TEST_CASE("CLI: --aov adds the unfiltered image and the neighbour count as EXR layers", "[cli]") {
  fs::path dir = temp_dir();
  write_file(dir / "tiny.xml", kTinyScene);
  fs::path out = dir / "aov.exr";
  Run r = run("render " + (dir / "tiny.xml").string() + " --spp 4 -q --aov unfiltered,neighbours -o " + out.string());
  REQUIRE(r.status == 0);
  Imf::InputFile file(out.string().c_str());
  const Imf::ChannelList& ch = file.header().channels();
  for (const char* c : {"R", "G", "B", "unfiltered.R", "unfiltered.G", "unfiltered.B", "neighbours.Y"})
    CHECK(ch.findChannel(c) != nullptr);
  Run bad = run("render " + (dir / "tiny.xml").string() + " --spp 1 -q --aov unfiltered,nonsense -o " + out.string());
  CHECK(bad.status == 2);
  CHECK(bad.output.find("nonsense") != std::string::npos);
  Run off = run("render " + (dir / "tiny.xml").string() + " --spp 1 -q --filter bogus");
  CHECK(off.status == 2);
}

TEST_CASE("CLI: the log of filtering switching itself off leaves the summary's numbers whole", "[cli]") {
  // The Cornell box at 32x32 pixels and 16 spp in batches of 2^8 paths: 64
  // batches. With --min-removed 1 the first batch the noise monitor can judge
  // (one whose pixels had two paths before it) switches filtering off, as the
  // filter removes less than all the noise. The summary after that message must
  // print 16 spp, not a number rounded to the message's one digit (2e+01).
  fs::path dir = temp_dir();
  Run r = run("render " + psf::test::source_path("scenes/cornell-box.xml") +
              " --width 32 --height 32 --spp 16 --batch-log2 8 --min-removed 1 --no-png -o " +
              (dir / "off.exr").string());
  REQUIRE(r.status == 0);
  INFO(r.output);
  CHECK(r.output.find("switched itself off after") != std::string::npos);
  CHECK(r.output.find("psf: 16384 paths (16 spp)") != std::string::npos);
}

TEST_CASE("CLI: --look-at and --fov replace the scene's camera", "[cli]") {
  fs::path dir = temp_dir();
  const std::string scene = psf::test::source_path("scenes/cornell-box.xml");
  auto render = [&](const std::string& name, const std::string& args) {
    Run r = run("render " + scene + " --width 32 --height 32 --spp 2 -q --no-png -o " + (dir / name).string() + " " +
                args);
    INFO(r.output);
    REQUIRE(r.status == 0);
    return psf::read_exr((dir / name).string()).rgb;
  };
  // The file's own camera (lookat 278,273,-800 -> 278,273,-799, up y; fov 39.3077
  // along x) given on the command line renders the same image, bit for bit.
  std::vector<float> plain = render("plain.exr", "");
  CHECK(render("same.exr", "--look-at 278,273,-800,278,273,-799,0,1,0 --fov 39.3077") == plain);
  CHECK(render("same-up.exr", "--look-at 278,273,-800,278,273,-799") == plain);  // the scene's up
  // Another view, and another field of view, are other images.
  CHECK(render("side.exr", "--look-at 100,273,-800,278,273,0") != plain);
  CHECK(render("wide.exr", "--fov 60") != plain);
  // Bad values: a message naming the option, exit 2, the output left alone.
  const std::string before = read_file(dir / "plain.exr");
  for (const char* bad : {"1,2", "0,0,0,0,0,0", "0,0,0,1,0,0,2,0,0", "a,b,c,d,e,f", "1,2,3,4,5,6,"}) {
    INFO(bad);
    Run r = run("render " + scene + " --spp 1 -q -o " + (dir / "plain.exr").string() + " --look-at " + bad);
    CHECK(r.status == 2);
    CHECK(r.output.find("--look-at") != std::string::npos);
  }
  CHECK(read_file(dir / "plain.exr") == before);
  // A render resumes only with the camera it started with.
  const std::string small = " --width 32 --height 32 -q --no-png ";
  const std::string cam = (dir / "cam.exr").string();
  Run start = run("render " + scene + small + "--spp 2 --look-at 100,273,-800,278,273,0 -o " + cam);
  REQUIRE(start.status == 0);
  Run other = run("render " + scene + small + "--spp 4 --resume " + cam + " -o " + (dir / "cam2.exr").string());
  CHECK(other.status == 2);
  CHECK(other.output.find("another scene") != std::string::npos);
  Run same = run("render " + scene + small + "--spp 4 --look-at \"100, 273.0,-800,278,273,0\" --resume " + cam +
                 " -o " + (dir / "cam3.exr").string());
  INFO(same.output);
  CHECK(same.status == 0);  // the same camera, written otherwise
}

TEST_CASE("CLI: --demodulate compares albedos as log2 ratios, 1 unless --albedo-threshold says", "[cli]") {
  fs::path dir = temp_dir();
  write_file(dir / "tiny.xml", kTinyScene);
  auto options = [&](const std::string& args) {
    fs::path out = dir / "demodulate.exr";
    Run r = run("render " + (dir / "tiny.xml").string() + " --spp 2 -q " + args + " -o " + out.string());
    REQUIRE(r.status == 0);
    Imf::InputFile file(out.string().c_str());
    auto* a = file.header().findTypedAttribute<Imf::StringAttribute>("psf:options");
    REQUIRE(a != nullptr);
    return a->value();
  };
  CHECK(options("").find(" albedo=0.05 cells27") != std::string::npos);
  CHECK(options("--demodulate").find(" albedo=1 demodulate=1 ") != std::string::npos);
  CHECK(options("--demodulate --albedo-threshold 0.5").find(" albedo=0.5 demodulate=1 ") != std::string::npos);
  CHECK(options("--albedo-threshold 0.2").find(" albedo=0.2 cells27") != std::string::npos);
}
