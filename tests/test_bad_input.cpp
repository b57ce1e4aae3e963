// Bad input: truncated and malformed files of every format (tests/data/bad/),
// NaN/Inf vertices, degenerate triangles, out-of-range indices, missing
// textures, absurd film sizes, bad options and output paths. Each run of the
// psf binary must end with exit 2 and a message naming the file (or exit 0 and
// a warning for a documented fallback), never with a signal or a timeout, and
// must leave an existing output file untouched. Also: NaN/Inf path
// contributions never reach the image and are counted.
#include <catch2/catch.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include <sys/stat.h>

#include "render.h"
#include "support.h"

namespace fs = std::filesystem;

namespace {

using Run = psf::test::PsfRun;

// Runs psf with a time limit (a hang is a failure too: timeout exits 124, or
// 128 + signal when it or psf was killed).
Run run(const std::string& args) { return psf::test::run_psf(args, "timeout -k 10 300"); }

fs::path temp_dir() { return psf::test::temp_dir("psf-bad-input"); }

std::string read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string bad(const std::string& name) { return psf::test::source_path("tests/data/bad/" + name); }

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

// A small, fast render of `scene` over an existing output file that must survive a failure.
struct Outcome {
  Run run;
  bool output_kept;  // the existing output file is byte for byte what it was
};
Outcome render(const std::string& scene, const std::string& extra = "") {
  fs::path dir = temp_dir();
  fs::path out = dir / "keep.exr";
  std::ofstream(out) << "precious";
  Outcome o;
  o.run = run("render " + scene + " --no-png --spp 1 --width 8 --height 8 -o " + out.string() + " " + extra);
  o.output_kept = read_file(out) == "precious";
  return o;
}

void require_clear_error(const Outcome& o, const std::string& names) {
  INFO(o.run.output);
  CHECK(o.run.status == 2);
  CHECK(contains(o.run.output, names));
  CHECK(o.output_kept);
}

}  // namespace

TEST_CASE("Bad input: malformed and truncated scene files give exit 2 naming the file", "[bad_input]") {
  // file, and the part of the message that says where
  const std::pair<const char*, const char*> cases[] = {
      {"truncated.xml", "truncated.xml:3:"},
      {"malformed.xml", "malformed.xml:"},
      {"film-zero.xml", "film-zero.xml:5:"},
      {"film-negative.xml", "film-negative.xml:5:"},
      {"nan-transform.xml", "nan-transform.xml:3:"},
      {"medium-negative.xml", "medium-negative.xml:5: the medium's sigma_a and sigma_s must be >= 0"},
      {"missing-mesh.xml", "no-such-mesh.obj"},
      {"integer-overflow.xml", "integer-overflow.xml:4:"},
      {"bad-serialized.xml", "index-out-of-range.serialized"},
      {"truncated.obj", "truncated.obj:6:"},
      {"nan-vertex.obj", "nan-vertex.obj:3:"},
      {"inf-vertex.obj", "inf-vertex.obj:3:"},
      {"index-out-of-range.obj", "index-out-of-range.obj:4:"},
      {"negative-index.obj", "negative-index.obj:4:"},
      {"truncated.ply", "truncated.ply: byte"},
      {"not-a-ply.ply", "not-a-ply.ply:1:"},
      {"inf-vertex.ply", "inf-vertex.ply:11:"},
      {"index-out-of-range.ply", "index-out-of-range.ply:13:"},
      {"huge-count.ply", "huge-count.ply: byte"},
      {"truncated.gltf", "truncated.gltf:"},
      {"truncated.glb", "truncated.glb:"},
      {"nan-vertex.gltf", "nan-vertex.gltf:"},
      {"index-out-of-range.gltf", "index-out-of-range.gltf:"},
      {"accessor-past-buffer.gltf", "accessor-past-buffer.gltf:"},
      {"accessor-negative-offset.gltf", "accessor-negative-offset.gltf: accessors[0].byteOffset: -12"},
      {"texture-sampler-missing.gltf", "texture-sampler-missing.gltf: textures[0].sampler: 5 names no sampler"},
      {"missing-buffer.gltf", "missing.bin"},
      // counts and offsets near 2^64, which wrapped around in the bounds check
      {"accessor-count-wrap.gltf", "accessor-count-wrap.gltf: accessors[0]: 6148914691236517206 elements"},
      {"accessor-offset-wrap.gltf", "accessor-offset-wrap.gltf: accessors[0]: 3 elements at byte offset"},
      {"accessor-count-no-view.gltf", "accessor-count-no-view.gltf: accessors[0]: count 1000000000000 is too large"},
      // a run-length encoded HDR cut short, on which stb_image loops forever
      {"truncated-hdr-envmap.xml", "truncated-rle.hdr: cannot read environment map: truncated HDR image"},
      {"hdr-image.gltf", "hdr-image.gltf: glTF parse error: images[0] is neither PNG nor JPEG"},
      // an index past 2^32 that tinyobjloader wrapped around to vertex 3, and
      // numbers finite in double precision but not in single
      {"index-wraps-around.obj", "index-wraps-around.obj:4: face index 4294967299 is out of range"},
      {"float-overflow.obj", "float-overflow.obj:3: vertex position is not finite"},
      {"float-overflow.xml", "float-overflow.xml:2: attribute 'value': '1e39' is not a number"},
      // a folder where a file belongs
      {"include-folder.xml", "bad/.' is a folder"},
      {"mtllib-folder.obj", "mtllib-folder.obj:1: mtllib '.' is a folder"},
      {"not-an-obj.obj", "not-an-obj.obj: no faces"},
      // negative values glTF forbids, which were ignored without a word
      {"negative-mesh-index.gltf", "negative-mesh-index.gltf: nodes[0]: mesh index -5 out of range"},
      {"sparse-index-out-of-range.gltf", "sparse-index-out-of-range.gltf: accessors[0].sparse.indices[0]: index 7"},
      {"negative-light.gltf", "negative-light.gltf: KHR_lights_punctual.lights[0]: intensity and color must be"},
      // compressed meshes that do not decode, and an extension the file requires that psf lacks
      {"draco-bad-attribute.gltf", "KHR_draco_mesh_compression.attributes.NORMAL: no attribute with this id"},
      {"draco-truncated.gltf", "draco-truncated.gltf: meshes[0].primitives[0].extensions.KHR_draco_mesh_compression: Draco:"},
      {"meshopt-corrupt.gltf", "meshopt-corrupt.gltf: bufferViews[0].extensions.EXT_meshopt_compression: the compressed"},
      // 4 GiB of output claimed from 16 compressed bytes: refused before it is allocated
      {"meshopt-huge-count.gltf", "meshopt-huge-count.gltf: bufferViews[0].extensions.EXT_meshopt_compression: byteLength"},
      {"required-extension.gltf", "required-extension.gltf: extensionsRequired: the file requires extension"},
  };
  for (const auto& [file, where] : cases) {
    SECTION(file) { require_clear_error(render(bad(file)), where); }
  }
}

TEST_CASE("Bad input: nesting deep enough to exhaust the stack is refused", "[bad_input]") {
  // 30,000 levels of XML elements, 20,000 of JSON arrays: the loaders (and the
  // JSON parser) recurse once a level.
  fs::path dir = temp_dir();
  std::string open, close;
  for (int i = 0; i < 30000; ++i) open += "<a>", close += "</a>";
  const fs::path xml = dir / "deep.xml";
  std::ofstream(xml) << "<scene version=\"3.0.0\">\n" << open << close << "</scene>\n";
  require_clear_error(render(xml.string()), "deep.xml:2: elements nested deeper than 256 levels");
  const fs::path gltf = dir / "deep.gltf";
  std::ofstream(gltf) << "{\"asset\": {\"version\": \"2.0\"}, \"extras\": " << std::string(20000, '[')
                      << std::string(20000, ']') << "}\n";
  require_clear_error(render(gltf.string()), "deep.gltf:1: JSON nested deeper than 512 levels");
}

TEST_CASE("Bad input: a film of 100000x100000 pixels is refused before anything is allocated", "[bad_input]") {
  fs::path dir = temp_dir();
  fs::path out = dir / "keep.exr";
  std::ofstream(out) << "precious";
  Run r = run("render " + bad("film-huge.xml") + " --no-png --spp 1 -o " + out.string());
  INFO(r.output);
  CHECK(r.status == 2);
  CHECK(contains(r.output, "film-huge.xml: film 100000x100000 is out of range"));
  CHECK(read_file(out) == "precious");
  // --width and --height override the film: the documented way out.
  Outcome small = render(bad("film-huge.xml"));
  CHECK(small.run.status == 0);
  // A 16x16 window of that film: the film's pixel indices key the samples (and
  // would wrap around 32 bits), so the film is held to the same limits.
  std::ofstream(out) << "precious";
  Run crop = run("render " + bad("film-huge-crop.xml") + " --no-png --spp 1 -o " + out.string());
  INFO(crop.output);
  CHECK(crop.status == 2);
  CHECK(contains(crop.output, "film-huge-crop.xml: film 100000x100000 is out of range"));
  CHECK(read_file(out) == "precious");
}

TEST_CASE("Bad input: documented fallbacks render with a warning", "[bad_input]") {
  SECTION("a missing bitmap texture in Mitsuba XML: a constant 0.5 reflectance") {
    Outcome o = render(bad("missing-texture.xml"));
    INFO(o.run.output);
    CHECK(o.run.status == 0);
    CHECK(contains(o.run.output, "warning: " + bad("missing-texture.xml") + ":8: texture file 'no-such-texture.png' not found"));
  }
  SECTION("a missing map_Kd in an MTL file: Kd") {
    Outcome o = render(bad("missing-texture.obj"));
    INFO(o.run.output);
    CHECK(o.run.status == 0);
    CHECK(contains(o.run.output, "missing-texture.mtl:1: map_Kd 'no-such-texture.png'"));
  }
  SECTION("a missing MTL library: the default material") {
    Outcome o = render(bad("missing-mtl.obj"));
    INFO(o.run.output);
    CHECK(o.run.status == 0);
    CHECK(contains(o.run.output, "warning: " + bad("missing-mtl.obj")));
    CHECK(contains(o.run.output, "no-such-library.mtl"));
  }
  SECTION("a malformed MTL file: what can be read, with a warning") {
    Outcome o = render(bad("malformed-mtl.obj"));
    INFO(o.run.output);
    CHECK(o.run.status < 3);
    CHECK(contains(o.run.output, "malformed.mtl"));
    if (o.run.status == 2) CHECK(o.output_kept);
  }
  SECTION("zero-area and degenerate triangles are never hit") {
    Outcome o = render(bad("degenerate.obj"));
    INFO(o.run.output);
    CHECK(o.run.status == 0);
  }
}

TEST_CASE("Bad input: absurd options and output paths give exit 2 and damage nothing", "[bad_input]") {
  std::string scene = bad("film-zero.xml");  // never read: the options are checked first
  fs::path dir = temp_dir();
  // Floating-point options: CLI11's own range checks let NaN through (--fov nan
  // and --r0 nan were taken for their defaults without a word), and a float
  // option given 1e40 became infinity.
  for (const char* opt : {"--spp 0", "--spp -3", "--width 0", "--width -8", "--height 100000", "--width abc",
                          "--fov nan", "--alpha nan", "--r0 nan", "--r0 1e40", "--footprint-pixels inf",
                          "--normal-threshold nan", "--albedo-threshold -0.1", "--visibility-ray nan",
                          "--visibility-ray -1", "--visibility-ray 1e-50", "--r0 1e-45", "--min-removed nan",
                          "--time nan", "--checkpoint-seconds nan", "--emission-rays -1", "--emission-rays 65",
                          "--visibility-ray of"}) {
    SECTION(opt) {
      Outcome o = render(bad("degenerate.obj"), opt);
      INFO(o.run.output);
      CHECK(o.run.status == 2);
      CHECK(contains(o.run.output, std::string(opt).substr(0, std::string(opt).find(' '))));
      CHECK(o.output_kept);
    }
  }
  SECTION("the output path is a folder") {
    Run r = run("render " + bad("degenerate.obj") + " --spp 1 -o " + dir.string());
    INFO(r.output);
    CHECK(r.status == 2);
    CHECK(contains(r.output, dir.string() + ": output path is a folder"));
    CHECK(fs::is_directory(dir));
  }
  SECTION("the output folder cannot be written (even as root)") {
    Run r = run("render " + bad("degenerate.obj") + " --spp 1 -o /proc/psf-bad-input.exr");
    INFO(r.output);
    CHECK(r.status == 2);
    CHECK(contains(r.output, "/proc/psf-bad-input.exr"));
  }
  SECTION("the scene is a folder") {
    fs::create_directories(dir / "folder.obj");
    Outcome f = render((dir / "folder.obj").string());
    require_clear_error(f, "folder.obj: is a folder, not a scene file");
  }
  SECTION("the output folder does not exist") {
    Run r = run("render " + bad("degenerate.obj") + " --spp 1 -o " + (dir / "nope" / "x.exr").string());
    CHECK(r.status == 2);
    CHECK(contains(r.output, "does not exist"));
  }
  SECTION("an output named .png: its preview would overwrite the image") {
    Run r = run("render " + bad("degenerate.obj") + " --spp 1 --width 8 --height 8 -o " + (dir / "x.png").string());
    INFO(r.output);
    CHECK(r.status == 2);
    CHECK(contains(r.output, (dir / "x.png").string() + ": the output is the OpenEXR image"));
    CHECK_FALSE(fs::exists(dir / "x.png"));
  }
  SECTION("an output named as another format: never an OpenEXR file under that name") {
    for (const char* name : {"x.jpg", "x.HDR", "x.png"}) {
      Run r = run("render " + bad("degenerate.obj") + " --spp 1 --width 8 --height 8 --no-png -o " +
                  (dir / name).string());
      INFO(r.output);
      CHECK(r.status == 2);
      CHECK(contains(r.output, (dir / name).string() + ": the output is the OpenEXR image"));
      CHECK_FALSE(fs::exists(dir / name));
    }
    for (const char* name : {"x.EXR", "tmp.9YQF0XQrLz"}) {  // any case; mktemp's names
      Run r = run("render " + bad("degenerate.obj") + " --spp 1 --width 8 --height 8 --no-png -o " +
                  (dir / name).string());
      INFO(r.output);
      CHECK(r.status == 0);
      CHECK(psf::read_exr((dir / name).string()).width == 8);
    }
  }
  SECTION("a symbolic link or a device as the output: written through, not replaced") {
    std::ofstream(dir / "target.exr") << "old";
    fs::create_symlink("target.exr", dir / "link.exr");
    Run r = run("render " + bad("degenerate.obj") + " --spp 1 --width 8 --height 8 -o " + (dir / "link.exr").string());
    INFO(r.output);
    CHECK(r.status == 0);
    CHECK(fs::is_symlink(dir / "link.exr"));
    CHECK(psf::read_exr((dir / "target.exr").string()).width == 8);
    CHECK(fs::exists(dir / "link.png"));  // the preview beside the name given
    Run null = run("render " + bad("degenerate.obj") + " --spp 1 --width 8 --height 8 --no-png -o /dev/null");
    INFO(null.output);
    CHECK(null.status == 0);
    CHECK(fs::is_character_file("/dev/null"));
  }
  SECTION("--resume of a one-batch render to fewer spp than its image holds") {
    // Its state holds no finished batch (the only one was cut short by --spp),
    // but its image holds 4 spp: a render to 2 would replace it by a worse one.
    fs::path out = dir / "r.exr";
    Run first = run("render " + bad("degenerate.obj") + " --spp 4 --width 8 --height 8 --no-png -o " + out.string());
    REQUIRE(first.status == 0);
    const std::string before = read_file(out);
    Run again = run("render " + bad("degenerate.obj") + " --spp 2 --width 8 --height 8 --no-png --resume " +
                    out.string() + " -o " + out.string());
    INFO(again.output);
    CHECK(again.status == 2);
    CHECK(contains(again.output, "it already holds 4 spp, more than --spp 2"));
    CHECK(read_file(out) == before);
  }
  SECTION("the output names the scene file: refused, the scene untouched") {
    fs::copy_file(bad("degenerate.obj"), dir / "scene.obj", fs::copy_options::overwrite_existing);
    const std::string before = read_file(dir / "scene.obj");
    for (const std::string& extra : {"--no-png -o " + (dir / "scene.obj").string(),
                                     "-o " + (dir / "." / "scene.obj").string()}) {
      Run r = run("render " + (dir / "scene.obj").string() + " --spp 1 --width 8 --height 8 " + extra);
      INFO(r.output);
      CHECK(r.status == 2);
      CHECK(contains(r.output, "would replace the scene file"));
      CHECK(read_file(dir / "scene.obj") == before);
    }
  }
  SECTION("names the system refuses (too long, a loop of links) give exit 2, not a std::filesystem error") {
    // From fuzzing: std::filesystem's throwing calls turned these into exit 1
    // with "filesystem error: status: File name too long".
    const std::string long_name(300, 'x');
    Run scene = run("render " + (dir / (long_name + ".xml")).string() + " --spp 1");
    INFO(scene.output);
    CHECK(scene.status == 2);
    CHECK(contains(scene.output, "File name too long"));
    fs::remove(dir / "loop");  // a folder of an earlier process with this pid
    fs::create_directory_symlink("loop", dir / "loop");
    Run out = run("render " + bad("degenerate.obj") + " --spp 1 --width 8 --height 8 -o " +
                  (dir / "loop" / "x.exr").string());
    INFO(out.output);
    CHECK(out.status == 2);
    CHECK(contains(out.output, "symbolic links"));
    std::ofstream(dir / "include.xml") << "<scene version=\"3.0.0\">\n<include filename=\"" << long_name
                                       << ".xml\"/>\n</scene>\n";
    Outcome inc = render((dir / "include.xml").string());
    require_clear_error(inc, "include.xml:2: included file");
    CHECK(contains(inc.run.output, "File name too long"));
    std::ofstream(dir / "mesh.xml") << "<scene version=\"3.0.0\">\n<shape type=\"ply\"><string name=\"filename\" "
                                    << "value=\"loop/m.ply\"/></shape>\n</scene>\n";
    Outcome mesh = render((dir / "mesh.xml").string());
    require_clear_error(mesh, "mesh.xml:2: cannot open PLY file");
  }
  SECTION("the default output folder out/ is a file") {
    fs::path work = dir / "cwd";
    fs::remove_all(work);
    fs::create_directories(work);
    std::ofstream(work / "out") << "a file";
    Run r = psf::test::run_psf("render " + bad("degenerate.obj") + " --spp 1 --width 8 --height 8",
                               "cd " + work.string() + " && timeout -k 10 300");
    INFO(r.output);
    CHECK(r.status == 2);
    CHECK(contains(r.output, "cannot create the output folder out"));
    CHECK(read_file(work / "out") == "a file");
  }
  SECTION("--resume of a file that is not OpenEXR") {
    Outcome o = render(bad("degenerate.obj"), "--resume " + bad("not-an-exr.exr"));
    INFO(o.run.output);
    require_clear_error(o, "not-an-exr.exr");
  }
  SECTION("--resume of an OpenEXR file whose data window starts at x = -2304") {
    // From the resume fuzzer: reading it computed a pointer 2304 pixels before
    // the array (undefined behaviour, reported by UBSan in scripts/test --sanitize).
    Outcome o = render(bad("degenerate.obj"), "--resume " + bad("resume-far-window.exr"));
    INFO(o.run.output);
    require_clear_error(o, "resume-far-window.exr");
  }
}

TEST_CASE("Bad input: NaN/Inf path contributions never reach the image and are counted", "[bad_input]") {
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  psf::Accumulator acc;
  acc.reset(2, 1, false);
  psf::BatchImages b;
  b.index = 0;
  b.first = 0;
  // Pixel 0: a good path, a NaN and an Inf; pixel 1: a good path and a -Inf.
  b.filtered = {{{1, 2, 3, 1}}, {{4, 5, 6, 1}}, {{nan, 0, 0, 1}}, {{0, 0, 1, 1}}, {{0, inf, 0, 1}}, {{0, 0, -inf, 1}}};
  b.unfiltered = {{{1, 2, 3, 1}}, {{4, 5, 6, 1}}, {{0, nan, 0, 1}}, {{0, 0, 1, 1}}, {{0, inf, 0, 1}}, {{0, 0, -inf, 1}}};
  acc.add(b);
  CHECK(acc.nonfinite() == 3);
  CHECK(acc.bad_filtered == std::vector<uint32_t>{2, 1});
  CHECK(acc.bad_unfiltered == std::vector<uint32_t>{2, 1});
  // The averages are over the finite paths only: (1,2,3) and ((4,5,6) + (0,0,1)) / 2.
  CHECK(acc.image().rgb == std::vector<float>{1, 2, 3, 2, 2.5f, 3.5f});
  for (float v : acc.image().rgb) CHECK(std::isfinite(v));
  for (float v : acc.unfiltered_image().rgb) CHECK(std::isfinite(v));
  for (float v : acc.filtered) CHECK(std::isfinite(v));
}

TEST_CASE("Bad input: what fuzzing found crashing, hanging or eating memory gives exit 2 or renders", "[bad_input]") {
  fs::path dir = temp_dir();
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name, std::ios::binary) << text;
    return (dir / name).string();
  };
  const std::string head = "<scene version=\"3.0.0\">\n";
  SECTION("a PNG whose deflate data stb_image refuses without a reason (a null message)") {
    require_clear_error(render(bad("corrupt-png-texture.xml")), "corrupt-deflate.png': cannot decode image");
  }
  SECTION("an EXR texture whose data window lies 300M rows down (an int offset overflowed)") {
    Outcome o = render(bad("far-data-window-texture.xml"));
    INFO(o.run.output);
    CHECK(o.run.status == 0);
  }
  SECTION("a PLY element of no properties and 2^64 - 1 items (a loop of as many steps)") {
    Outcome o = render(bad("empty-element-huge-count.ply"));
    INFO(o.run.output);
    CHECK(o.run.status == 0);
  }
  SECTION("a .glb whose buffer has byteLength 0 (tinygltf threw std::out_of_range)") {
    require_clear_error(render(bad("glb-empty-buffer.glb")), "glb-empty-buffer.glb: glTF parse error");
  }
  SECTION("a flat HDR image cut short (stb_image read zeros past its end)") {
    write("short.hdr", "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 64 +X 4\n\x80\x80\x80\x80");
    const std::string xml = write("short.xml", head + "<emitter type=\"envmap\"><string name=\"filename\" "
                                                      "value=\"short.hdr\"/></emitter>\n</scene>\n");
    require_clear_error(render(xml), "short.hdr: cannot read environment map: truncated HDR image");
  }
  SECTION("BSDFs and merges that refer to each other 5000 deep (a stack overflow)") {
    std::string bsdfs = head, merges = head;
    for (int i = 0; i < 5000; ++i) {
      const std::string next = i + 1 < 5000 ? "<ref id=\"b" + std::to_string(i + 1) + "\"/>" : "<bsdf type=\"diffuse\"/>";
      bsdfs += "<bsdf type=\"twosided\" id=\"b" + std::to_string(i) + "\">" + next + "</bsdf>\n";
      const std::string shape = i + 1 < 5000 ? "<ref id=\"m" + std::to_string(i + 1) + "\"/>" : "<shape type=\"sphere\"/>";
      merges += "<shape type=\"merge\" id=\"m" + std::to_string(i) + "\">" + shape + "</shape>\n";
    }
    bsdfs += "<shape type=\"sphere\"><ref id=\"b0\"/></shape>\n</scene>\n";
    merges += "</scene>\n";
    require_clear_error(render(write("bsdfs.xml", bsdfs)), "bsdfs.xml:66: BSDFs nested more than 64 deep");
    require_clear_error(render(write("merges.xml", merges)), "merges nested more than 64 deep");
  }
  SECTION("merges that each hold the next twice (2^40 spheres)") {
    std::string xml = head;
    for (int i = 0; i < 40; ++i) {
      const std::string next = i + 1 < 40 ? "<ref id=\"m" + std::to_string(i + 1) + "\"/>" : "<shape type=\"sphere\"/>";
      xml += "<shape type=\"merge\" id=\"m" + std::to_string(i) + "\">" + next + next + "</shape>\n";
    }
    require_clear_error(render(write("dag.xml", xml + "<shape type=\"merge\"><ref id=\"m0\"/></shape>\n</scene>\n")),
                        "dag.xml:2: the scene draws more than 1048576 shapes");
    // 2^16 spheres in a merge held 100 times (by shapes, and by instances of a
    // shapegroup of it), the chain defined inside a shapegroup that is not drawn.
    std::string many = head + "<shape type=\"shapegroup\">\n", grouped = head + "<shape type=\"shapegroup\">\n";
    for (int i = 0; i < 16; ++i) {
      const std::string next = i + 1 < 16 ? "<ref id=\"m" + std::to_string(i + 1) + "\"/>" : "<shape type=\"sphere\"/>";
      const std::string merge = "<shape type=\"merge\" id=\"m" + std::to_string(i) + "\">" + next + next + "</shape>\n";
      many += merge;
      grouped += merge;
    }
    many += "</shape>\n";
    grouped += "</shape>\n<shape type=\"shapegroup\" id=\"g\"><ref id=\"m0\"/></shape>\n";
    for (int i = 0; i < 100; ++i) {
      many += "<shape type=\"merge\"><ref id=\"m0\"/></shape>\n";
      grouped += "<shape type=\"instance\"><ref id=\"g\"/></shape>\n";
    }
    require_clear_error(render(write("many.xml", many + "</scene>\n")), "the scene draws more than 1048576 shapes");
    require_clear_error(render(write("grouped.xml", grouped + "</scene>\n")), "the scene draws more than 1048576 shapes");
  }
  SECTION("includes that each include the next twice (2^23 files)") {
    for (int i = 0; i < 23; ++i) {
      const std::string next = i + 1 < 23 ? "<include filename=\"i" + std::to_string(i + 1) + ".xml\"/>" : "";
      write("i" + std::to_string(i) + ".xml", head + next + next + "</scene>\n");
    }
    require_clear_error(render(write("top.xml", head + "<include filename=\"i0.xml\"/>\n</scene>\n")),
                        "more than 4096 included files");
  }
  SECTION("a device or a FIFO named as a scene file, an include, an MTL or a spectrum") {
    require_clear_error(render(write("zero.xml", head + "<include filename=\"/dev/zero\"/>\n</scene>\n")),
                        "zero.xml:2: included file '/dev/zero' is not a regular file");
    require_clear_error(render(write("zero.obj", "mtllib /dev/zero\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")),
                        "zero.obj:1: mtllib '/dev/zero' is not a regular file");
    require_clear_error(render(write("spectrum.xml", head + "<shape type=\"sphere\"><bsdf type=\"diffuse\"><spectrum "
                                                            "name=\"reflectance\" filename=\"/dev/zero\"/></bsdf>"
                                                            "</shape>\n</scene>\n")),
                        "spectrum file '/dev/zero' is not a regular file");
    const fs::path fifo = dir / "pipe.xml";
    REQUIRE(mkfifo(fifo.c_str(), 0600) == 0);
    require_clear_error(render(write("fifo.xml", head + "<include filename=\"pipe.xml\"/>\n</scene>\n")),
                        "fifo.xml:2: included file");
    require_clear_error(render(fifo.string()), "pipe.xml: is not a regular file");
    const std::string gltf = "{\"asset\": {\"version\": \"2.0\"}, \"buffers\": [{\"byteLength\": 4, \"uri\": "
                             "\"pipe.xml\"}]}";
    require_clear_error(render(write("fifo.gltf", gltf)), "pipe.xml is not a regular file");
  }
  SECTION("glTF: nodes shared by two parents (2^40 copies), 12,500 deep, a buffer that is a folder") {
    const std::string mesh =
        "\"meshes\": [{\"primitives\": [{\"attributes\": {\"POSITION\": 0}}]}], \"accessors\": [{\"componentType\": "
        "5126, \"count\": 3, \"type\": \"VEC3\", \"bufferView\": 0}], \"bufferViews\": [{\"buffer\": 0, "
        "\"byteLength\": 36}], \"buffers\": [{\"byteLength\": 36, \"uri\": \"";
    std::string dag = "{\"asset\": {\"version\": \"2.0\"}, \"scenes\": [{\"nodes\": [0]}], \"nodes\": [";
    for (int i = 0; i < 40; ++i)
      dag += "{\"children\": [" + std::to_string(i + 1) + ", " + std::to_string(i + 1) + "]}, ";
    dag += "{\"mesh\": 0}], " + mesh + "data:application/octet-stream;base64," + std::string(48, 'A') + "\"}]}";
    require_clear_error(render(write("dag.gltf", dag)), "dag.gltf: nodes[1]: is the child of more than one node");
    std::string chain = "{\"asset\": {\"version\": \"2.0\"}, \"scenes\": [{\"nodes\": [0]}], \"nodes\": [";
    for (int i = 0; i < 12500; ++i) chain += "{\"children\": [" + std::to_string(i + 1) + "]}, ";
    chain += "{\"mesh\": 0}], " + mesh + "data:application/octet-stream;base64," + std::string(48, 'A') + "\"}]}";
    require_clear_error(render(write("chain.gltf", chain)), "chain.gltf: nodes[1024]: nodes nested more than 1024 deep");
    const std::string folder = "{\"asset\": {\"version\": \"2.0\"}, \"scenes\": [{\"nodes\": [0]}], \"nodes\": "
                               "[{\"mesh\": 0}], " + mesh + ".\"}]}";
    require_clear_error(render(write("folder.gltf", folder)), "is a folder");
    // An accessor's bufferView -5 (read as all zeros) and a byteStride shorter than its elements.
    const std::string valid = "{\"asset\": {\"version\": \"2.0\"}, \"scenes\": [{\"nodes\": [0]}], \"nodes\": "
                              "[{\"mesh\": 0}], " + mesh + "data:application/octet-stream;base64," +
                              std::string(48, 'A') + "\"}]}";
    auto edit = [&](const std::string& from, const std::string& to) {
      std::string s = valid;
      return s.replace(s.find(from), from.size(), to);
    };
    require_clear_error(render(write("view.gltf", edit("\"bufferView\": 0", "\"bufferView\": -5"))),
                        "view.gltf: accessors[0]: bufferView -5 out of range");
    const std::string stride = edit("\"byteLength\": 36}", "\"byteLength\": 36, \"byteStride\": 4}");
    require_clear_error(render(write("stride.gltf", stride)), "byteStride 4 is smaller than an element (12 bytes)");
    require_clear_error(render(write("scene.gltf", edit("\"scenes\"", "\"scene\": -7, \"scenes\""))),
                        "scene.gltf: scene: scene -7 out of range");
    // 4 vertices without indices: one triangle and a vertex left over, with a warning.
    std::string four = valid;
    for (const auto& [from, to] : {std::pair<std::string, std::string>{"\"count\": 3", "\"count\": 4"},
                                   {"\"byteLength\": 36}", "\"byteLength\": 48}"},
                                   {"\"byteLength\": 36,", "\"byteLength\": 48,"},
                                   {std::string(48, 'A'), std::string(64, 'A')}})
      four.replace(four.find(from), from.size(), to);
    Outcome o = render(write("four.gltf", four));
    INFO(o.run.output);
    CHECK(o.run.status == 0);
    CHECK(contains(o.run.output, "4 vertices or indices, not a multiple of 3; the last 1 ignored"));
  }
  SECTION("a negative area light, and a glTF extensionsRequired entry that is no name") {
    require_clear_error(render(write("negative.xml", head + "<shape type=\"sphere\"><emitter type=\"area\"><rgb "
                                                            "name=\"radiance\" value=\"1, -2, 1\"/></emitter></shape>\n"
                                                            "</scene>\n")),
                        "negative.xml:2: 'radiance' is negative");
    require_clear_error(render(write("required.gltf", "{\"asset\": {\"version\": \"2.0\"}, \"extensionsRequired\": "
                                                      "[7]}")),
                        "required.gltf: extensionsRequired: an entry is not an extension's name");
  }
  SECTION("a max_depth below -1, which Mitsuba 3 refuses") {
    require_clear_error(render(write("depth.xml", head + "<integrator type=\"path\"><integer name=\"max_depth\" "
                                                         "value=\"-7\"/></integrator>\n<shape type=\"sphere\"/>\n"
                                                         "</scene>\n")),
                        "depth.xml:2: 'max_depth' must be -1 (unbounded) or at least 0");
  }
}
