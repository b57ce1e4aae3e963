// Scene loading: Mitsuba XML (0.5 and 3), OBJ, the default Cornell box and the
// shared scenes. Small scenes are written to a temporary directory per test.
//
// Tolerances: positions and matrices 1e-4 (float products of exact inputs);
// spectra 1e-3 where the answer is exact by construction (a constant spectrum)
// and 1% against values integrated independently with the tabulated CIE 1931
// curves (the loader uses an analytic fit of them).
#include <unistd.h>

#include <Imath/half.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include "scene/loaders.h"
#include "scene/materials.h"
#include "scene/scene.h"
#include "support.h"

namespace fs = std::filesystem;

namespace {

// A fresh directory under the system's temporary directory, removed at the end of the test.
class TempDir {
 public:
  TempDir() {
    static int counter = 0;
    path_ =
        fs::temp_directory_path() / ("psf-scene-test-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  // Writes `text` to `name` (subdirectories created) and returns its path.
  std::string write(const std::string& name, const std::string& text) const {
    fs::path p = path_ / name;
    fs::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
  }

 private:
  fs::path path_;
};

// A Mitsuba scene file: line 1 is <scene>, so `body` starts on line 2.
std::string scene_xml(const std::string& body, const std::string& version = "3.0.0") {
  return "<scene version=\"" + version + "\">\n" + body + "</scene>\n";
}

psf::Scene load_text(const std::string& body, const std::vector<std::pair<std::string, std::string>>& params = {},
                     const std::string& version = "3.0.0") {
  TempDir dir;
  return psf::load_scene(dir.write("scene.xml", scene_xml(body, version)), params);
}

// The world-space corners of Mitsuba's rectangle (-1,-1), (1,-1), (1,1), (-1,1) under `transform`.
std::vector<glm::vec3> rectangle_corners(const std::string& transform) {
  psf::Scene s =
      load_text("<shape type=\"rectangle\"><transform name=\"to_world\">" + transform + "</transform></shape>\n");
  REQUIRE(s.positions.size() == 4);
  return s.positions;
}

bool near(const glm::vec3& a, const glm::vec3& b, float tol = 1e-4f) {
  return glm::all(glm::lessThanEqual(glm::abs(a - b), glm::vec3(tol * std::max(1.0f, glm::length(b)))));
}

glm::vec3 albedo(const Material& m) { return {m.albedo.s[0], m.albedo.s[1], m.albedo.s[2]}; }
glm::vec3 emission(const Material& m) { return {m.emission.s[0], m.emission.s[1], m.emission.s[2]}; }

// The albedo of a one-shape scene whose diffuse reflectance is `color` (an <rgb>, <srgb> or <spectrum>).
glm::vec3 reflectance_of(const std::string& color) {
  psf::Scene s = load_text("<shape type=\"rectangle\"><bsdf type=\"diffuse\">" + color + "</bsdf></shape>\n");
  REQUIRE(s.materials.size() == 1);
  return albedo(s.materials[0]);
}

// The emission of a one-shape scene whose area emitter has radiance `color`.
glm::vec3 radiance_of(const std::string& color, const std::string& version = "3.0.0") {
  psf::Scene s =
      load_text("<shape type=\"rectangle\"><emitter type=\"area\">" + color + "</emitter></shape>\n", {}, version);
  REQUIRE(s.materials.size() == 1);
  return emission(s.materials[0]);
}

// Loads `path` and expects a SceneError naming `file` and `line` whose message contains `text`.
void require_error(const std::string& path, const std::string& file, int line, const std::string& text) {
  try {
    psf::load_scene(path);
    FAIL("no SceneError for " << path);
  } catch (const psf::SceneError& e) {
    INFO(e.what());
    CHECK(e.file() == file);
    CHECK(e.line() == line);
    CHECK(std::string(e.what()).find(text) != std::string::npos);
    if (line > 0) CHECK(std::string(e.what()).find(file + ":" + std::to_string(line) + ":") == 0);
  }
}

// Expects a SceneError at line `line` of a scene made of `body` (body line 1 is file line 2).
void require_xml_error(const std::string& body, int line, const std::string& text) {
  TempDir dir;
  std::string path = dir.write("bad.xml", scene_xml(body));
  require_error(path, path, line, text);
}

size_t count_warnings(const psf::Scene& s, const std::string& text) {
  return size_t(std::count_if(s.warnings.begin(), s.warnings.end(),
                              [&](const std::string& w) { return w.find(text) != std::string::npos; }));
}

size_t emissive_materials(const psf::Scene& s) {
  return size_t(std::count_if(s.materials.begin(), s.materials.end(), [](const Material& m) {
    return glm::any(glm::greaterThan(emission(m), glm::vec3(0.0f)));
  }));
}

}  // namespace

TEST_CASE("Default Cornell box loads", "[scene]") {
  psf::Scene s = psf::load_scene(psf::test::source_path("scenes/cornell-box.xml"));
  CHECK(s.warnings.empty());
  CHECK(s.triangles.size() == 36);  // 5 walls and the light: 2 each; 2 cubes: 12 each
  CHECK(s.tri_material.size() == s.triangles.size());
  REQUIRE(emissive_materials(s) == 1);
  for (const Material& m : s.materials)
    if (glm::any(glm::greaterThan(emission(m), glm::vec3(0.0f)))) CHECK(near(emission(m), {17, 12, 4}));
  CHECK(s.camera.origin == glm::vec3(278, 273, -800));
  CHECK(near(s.camera.target, {278, 273, -799}));
  CHECK(near(s.camera.up, {0, 1, 0}));
  CHECK(s.camera.fov_degrees == Approx(39.3077f));
  CHECK(s.camera.fov_axis == "x");
  CHECK_FALSE(s.camera.mirrored);
  CHECK(s.width == 256);
  CHECK(s.height == 256);
  CHECK(s.max_depth == 8);
  CHECK(s.default_spp == 64);
  for (const glm::vec3& p : s.positions) {
    CHECK(p.x >= -1e-3f);
    CHECK(p.x <= 556.001f);
    CHECK(p.y >= -1e-3f);
    CHECK(p.y <= 548.801f);
    CHECK(p.z >= -1e-3f);
    CHECK(p.z <= 559.201f);
  }
  // The camera sees red on its left: make_camera's right vector points to -x.
  Camera cam = psf::make_camera(s.camera, s.width, s.height);
  CHECK(cam.right.s[0] < 0.0f);
}

TEST_CASE("Transform elements give Mitsuba's matrices", "[scene]") {
  SECTION("translate") {
    CHECK(near(rectangle_corners("<translate x=\"1\" y=\"2\" z=\"3\"/>")[0], {0, 1, 3}));
    CHECK(near(rectangle_corners("<translate value=\"1, 2, 3\"/>")[0], {0, 1, 3}));
  }
  SECTION("scale") {
    CHECK(near(rectangle_corners("<scale value=\"2\"/>")[2], {2, 2, 0}));
    CHECK(near(rectangle_corners("<scale x=\"2\" y=\"3\"/>")[2], {2, 3, 0}));
    CHECK(near(rectangle_corners("<scale value=\"2 3 4\"/>")[2], {2, 3, 0}));
  }
  SECTION("rotate: right-handed, angle in degrees") {
    CHECK(near(rectangle_corners("<rotate z=\"1\" angle=\"90\"/>")[1], {1, 1, 0}));
    CHECK(near(rectangle_corners("<rotate x=\"1\" angle=\"90\"/>")[2], {1, 0, 1}));
    CHECK(near(rectangle_corners("<rotate value=\"0, 1, 0\" angle=\"90\"/>")[2], {0, 1, -1}));
    CHECK(near(rectangle_corners("<rotate y=\"2\" angle=\"90\"/>")[2], {0, 1, -1}));  // axis normalised
  }
  SECTION("matrix: row-major 4x4 and 3x3") {
    CHECK(near(rectangle_corners("<matrix value=\"1 0 0 10  0 2 0 20  0 0 3 30  0 0 0 1\"/>")[2], {11, 22, 30}));
    CHECK(near(rectangle_corners("<matrix value=\"0 -1 0, 1 0 0, 0 0 1\"/>")[1], {1, 1, 0}));
  }
  SECTION("lookat: columns left, up, direction, origin") {
    // dir = -z, left = up x dir = -x, up' = dir x left = +y.
    CHECK(near(rectangle_corners("<lookat origin=\"0,0,0\" target=\"0,0,-1\" up=\"0,1,0\"/>")[2], {-1, 1, 0}));
    CHECK(near(rectangle_corners("<lookat origin=\"5,6,7\" target=\"5,6,8\" up=\"0,1,0\"/>")[0], {4, 5, 7}));
  }
  SECTION("each element left-multiplies the ones before it") {
    CHECK(near(rectangle_corners("<translate x=\"1\"/><scale value=\"2\"/>")[0], {0, -2, 0}));
    CHECK(near(rectangle_corners("<scale value=\"2\"/><translate x=\"1\"/>")[0], {-1, -2, 0}));
    CHECK(near(rectangle_corners("<rotate z=\"1\" angle=\"90\"/><translate x=\"10\"/>")[1], {11, 1, 0}));
  }
}

TEST_CASE("Sensor to_world: lookat and the equivalent matrix give the same camera", "[scene]") {
  auto sensor = [](const std::string& transform) {
    return load_text(
        "<sensor type=\"perspective\"><float name=\"fov\" value=\"40\"/>"
        "<transform name=\"to_world\">" +
        transform + "</transform></sensor>\n");
  };
  // Looking along +x with +y up: left = up x dir = -z, so the matrix columns are (-z, y, x).
  psf::Scene a = sensor("<lookat origin=\"1,2,3\" target=\"11,2,3\" up=\"0,1,0\"/>");
  psf::Scene b = sensor("<matrix value=\"0 0 1 1  0 1 0 2  -1 0 0 3  0 0 0 1\"/>");
  CHECK(near(a.camera.origin, {1, 2, 3}));
  CHECK(near(glm::normalize(a.camera.target - a.camera.origin), {1, 0, 0}));
  CHECK(near(a.camera.up, {0, 1, 0}));
  Camera ca = psf::make_camera(a.camera, 64, 64), cb = psf::make_camera(b.camera, 64, 64);
  for (int i = 0; i < 3; ++i) {
    CHECK(ca.origin.s[i] == Approx(cb.origin.s[i]).margin(1e-5));
    CHECK(ca.forward.s[i] == Approx(cb.forward.s[i]).margin(1e-5));
    CHECK(ca.right.s[i] == Approx(cb.right.s[i]).margin(1e-5));
    CHECK(ca.down.s[i] == Approx(cb.down.s[i]).margin(1e-5));
  }
  // Mitsuba's image right is -left = +z here.
  CHECK(ca.right.s[2] > 0.0f);
  CHECK_FALSE(a.camera.mirrored);
  CHECK_FALSE(b.camera.mirrored);

  // A reflection before the lookat keeps the view but mirrors the image
  // left-right: the film's right axis flips, its down axis does not.
  psf::Scene m = sensor("<scale x=\"-1\"/><lookat origin=\"1,2,3\" target=\"11,2,3\" up=\"0,1,0\"/>");
  CHECK(m.camera.mirrored);
  CHECK(near(m.camera.origin, a.camera.origin));
  CHECK(near(m.camera.target, a.camera.target));
  CHECK(near(m.camera.up, a.camera.up));
  Camera cm = psf::make_camera(m.camera, 64, 64);
  for (int i = 0; i < 3; ++i) {
    CHECK(cm.right.s[i] == Approx(-ca.right.s[i]).margin(1e-5));
    CHECK(cm.down.s[i] == Approx(ca.down.s[i]).margin(1e-5));
  }
}

TEST_CASE("Sensor to_world: a lookat without up takes Mitsuba's arbitrary axis", "[scene]") {
  // Both Mitsubas complete the view direction to a basis and use its first axis
  // as up; the camera's up is then that axis made orthogonal to the view.
  auto up_of = [](const std::string& lookat, const std::string& version) {
    psf::Scene s = load_text("<sensor type=\"perspective\"><transform name=\"to_world\">" + lookat +
                                 "</transform></sensor>\n",
                             {}, version);
    return glm::normalize(s.camera.up);
  };
  const glm::vec3 dir = glm::normalize(glm::vec3(0, 0.4f, 0) - glm::vec3(1, 1.5f, 4));
  auto orthogonal = [&](glm::vec3 up) { return glm::normalize(up - glm::dot(up, dir) * dir); };
  // Mitsuba 3.6's coordinate_system(dir).first, and Mitsuba 0.5's coordinateSystem's
  // second output, for this dir (worked out by hand from their definitions).
  const glm::vec3 up3 = orthogonal({0.971655f, -0.031180f, -0.234339f});
  const glm::vec3 up05 = orthogonal({0.972150f, -0.062140f, -0.225950f});
  const std::string no_up = "<lookat origin=\"1,1.5,4\" target=\"0,0.4,0\"/>";
  CHECK(glm::dot(up_of(no_up, "3.0.0"), up3) > 0.99999f);
  CHECK(glm::dot(up_of("<lookat origin=\"1,1.5,4\" target=\"0,0.4,0\" up=\"0,0,0\"/>", "3.0.0"), up3) > 0.99999f);
  CHECK(glm::dot(up_of(no_up, "0.5.0"), up05) > 0.99999f);
  // Distinct enough that the check means something.
  CHECK(glm::dot(up3, up05) < 0.9995f);
  CHECK(glm::dot(up3, orthogonal({0, 1, 0})) < 0.5f);
}

TEST_CASE("Sensor: a sheared to_world warns", "[scene]") {
  // A non-uniform scale after the lookat scales world axes, which skews a camera
  // that looks along neither; before it (camera space) it is the film's extent.
  const std::string look = "<lookat origin=\"0, 2, 5\" target=\"0, 0.3, 0\" up=\"0, 1, 0\"/>";
  auto sensor = [](const std::string& t) {
    return "<sensor type=\"orthographic\">\n<transform name=\"to_world\">" + t + "</transform></sensor>\n";
  };
  psf::Scene sheared = load_text(sensor(look + "<scale x=\"2\" y=\"1.5\"/>"));
  CHECK(count_warnings(sheared, ":3: the sensor's to_world shears its axes") == 1);
  psf::Scene fine = load_text(sensor("<scale x=\"2\" y=\"1.5\"/>" + look));
  CHECK(count_warnings(fine, "shears") == 0);
}

TEST_CASE("Sensor defaults and field of view", "[scene]") {
  psf::Scene s = load_text("<sensor type=\"perspective\"/>\n");
  CHECK(s.width == 768);  // Mitsuba's default film
  CHECK(s.height == 576);
  CHECK(s.camera.fov_axis == "diagonal");  // from the default 50mm focal length
  CHECK(s.camera.fov_degrees == Approx(46.793f).epsilon(1e-3));
  CHECK(near(s.camera.target - s.camera.origin, {0, 0, 1}));

  psf::Scene d = load_text("<integrator type=\"direct\"/>\n");
  CHECK(d.max_depth == 2);
}

TEST_CASE("Sensor thinlens and orthographic: aperture radius, focus distance, film extent", "[scene]") {
  psf::Scene s = load_text(
      "<sensor type=\"thinlens\"><float name=\"aperture_radius\" value=\"0.1\"/>"
      "<float name=\"focus_distance\" value=\"3.5\"/></sensor>\n<shape type=\"cube\"/>\n");
  CHECK(s.camera.aperture_radius == Approx(0.1f));
  CHECK(s.camera.focus_distance == Approx(3.5f));
  for (const auto& w : s.warnings) CHECK(w.find("thinlens") == std::string::npos);
  psf::Scene mitsuba05 = load_text(
      "<sensor type=\"thinlens\"><float name=\"apertureRadius\" value=\"0.2\"/></sensor>\n<shape type=\"cube\"/>\n",
      {}, "0.5.0");
  CHECK(mitsuba05.camera.aperture_radius == Approx(0.2f));
  CHECK(mitsuba05.camera.focus_distance == Approx(1e4f));  // far_clip, Mitsuba's default
  CHECK(load_text("<shape type=\"cube\"/>\n").camera.aperture_radius == 0.0f);  // perspective: a pinhole
  // Both are camera-space lengths: a to_world that scales by 2 doubles them (as Mitsuba).
  psf::Scene scaled = load_text(
      "<sensor type=\"thinlens\"><float name=\"aperture_radius\" value=\"0.1\"/>"
      "<float name=\"focus_distance\" value=\"3.5\"/><transform name=\"to_world\"><scale value=\"2\"/>"
      "<lookat origin=\"0, 0, 5\" target=\"0, 0, 0\" up=\"0, 1, 0\"/></transform></sensor>\n<shape type=\"cube\"/>\n");
  CHECK(scaled.camera.aperture_radius == Approx(0.2f));
  CHECK(scaled.camera.focus_distance == Approx(7.0f));
  // orthographic: to_world's x and y scales are the film's half extents.
  psf::Scene ortho = load_text(
      "<sensor type=\"orthographic\"><transform name=\"to_world\"><scale x=\"2\" y=\"3\"/>"
      "<lookat origin=\"0, 0, 5\" target=\"0, 0, 0\" up=\"0, 1, 0\"/></transform></sensor>\n<shape type=\"cube\"/>\n");
  CHECK(ortho.camera.orthographic);
  CHECK(ortho.camera.ortho_scale.x == Approx(2.0f));
  CHECK(ortho.camera.ortho_scale.y == Approx(3.0f));
  for (const auto& w : ortho.warnings) CHECK(w.find("orthographic") == std::string::npos);
  require_xml_error("<shape type=\"rectangle\"><bsdf type=\"twosided\"><bsdf type=\"diffuse\"/><bsdf type=\"diffuse\"/>\n"
                    "<bsdf type=\"diffuse\"/></bsdf></shape>\n",
                    3, "one or two nested BSDFs");
  require_xml_error("<sensor type=\"thinlens\"/>\n", 2, "needs an 'aperture_radius'");
  require_xml_error("<sensor type=\"thinlens\"><float name=\"aperture_radius\" value=\"0.1\"/>\n"
                    "<float name=\"focus_distance\" value=\"-1\"/></sensor>\n",
                    3, "focus distance must be positive");
}

TEST_CASE("Film rfilter: box, tent and gaussian as Mitsuba's, its default a Gaussian", "[scene]") {
  auto film = [](const std::string& rfilter) {
    return load_text("<sensor type=\"perspective\"><film type=\"hdrfilm\">" + rfilter + "</film></sensor>\n");
  };
  psf::Scene none = film("");
  CHECK(none.camera.pixel_filter == "gaussian");
  CHECK(none.camera.filter_stddev == 0.5f);
  CHECK(load_text("<sensor type=\"perspective\"/>\n").camera.pixel_filter == "gaussian");  // no film
  CHECK(load_text("<shape type=\"cube\"/>\n").camera.pixel_filter == "gaussian");           // no sensor
  CHECK(film("<rfilter type=\"box\"/>").camera.pixel_filter == "box");
  psf::Scene tent = film("<rfilter type=\"tent\"/>");
  CHECK(tent.camera.pixel_filter == "tent");
  CHECK(tent.camera.filter_radius == 1.0f);
  CHECK(film("<rfilter type=\"tent\"><float name=\"radius\" value=\"1.5\"/></rfilter>").camera.filter_radius ==
        1.5f);
  psf::Scene narrow =
      film("<rfilter name=\"rfilter\" type=\"gaussian\"><float name=\"stddev\" value=\"0.3\"/></rfilter>");
  CHECK(narrow.camera.pixel_filter == "gaussian");
  CHECK(narrow.camera.filter_stddev == 0.3f);
  // Negative lobes cannot be sampled with weight 1: a Gaussian instead, with one warning at the line.
  psf::Scene mitchell = load_text(
      "<sensor type=\"perspective\">\n<film type=\"hdrfilm\">\n<rfilter type=\"mitchell\"/>\n</film></sensor>\n");
  CHECK(mitchell.camera.pixel_filter == "gaussian");
  REQUIRE(count_warnings(mitchell, "rfilter 'mitchell' is not supported") == 1);
  CHECK(count_warnings(mitchell, "scene.xml:4:") == 1);
  // OBJ, PLY and glTF scenes keep a box.
  CHECK(psf::CameraDesc{}.pixel_filter == "box");
  require_xml_error("<sensor type=\"perspective\"><film type=\"hdrfilm\">\n<rfilter type=\"tent\">\n"
                    "<float name=\"radius\" value=\"-1\"/></rfilter></film></sensor>\n",
                    4, "radius must be positive");
}

TEST_CASE("$parameters and <default>", "[scene]") {
  const std::string body =
      "<default name=\"w\" value=\"64\"/>\n"
      "<default name=\"depth\" value=\"5\"/>\n"
      "<integrator type=\"path\"><integer name=\"max_depth\" value=\"$depth\"/></integrator>\n"
      "<sensor type=\"perspective\"><film type=\"hdrfilm\">"
      "<integer name=\"width\" value=\"$w\"/><integer name=\"height\" value=\"$w$w\"/></film></sensor>\n";
  psf::Scene defaults = load_text(body);
  CHECK(defaults.width == 64);
  CHECK(defaults.height == 6464);  // substitution inside a value
  CHECK(defaults.max_depth == 5);
  psf::Scene given = load_text(body, {{"w", "32"}});
  CHECK(given.width == 32);
  CHECK(given.max_depth == 5);

  require_xml_error("<integrator type=\"path\">\n<integer name=\"max_depth\" value=\"$nope\"/>\n</integrator>\n", 3,
                    "undefined parameter '$nope'");
}

TEST_CASE("<include> is relative to the including file", "[scene]") {
  TempDir dir;
  // Mitsuba ignores OBJ materials: no warning about the missing MTL library.
  dir.write("parts/quad.obj", "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl x\nf 1 2 3 4\n");
  dir.write("parts/materials.xml", scene_xml("<bsdf type=\"diffuse\" id=\"grey\">"
                                             "<rgb name=\"reflectance\" value=\"0.25\"/></bsdf>\n"
                                             "<shape type=\"obj\"><string name=\"filename\" value=\"quad.obj\"/>"
                                             "<ref id=\"grey\"/></shape>\n"));
  std::string main = dir.write("main.xml", scene_xml("<include filename=\"parts/materials.xml\"/>\n"
                                                     "<shape type=\"rectangle\"><ref id=\"grey\"/></shape>\n"));
  psf::Scene s = psf::load_scene(main);
  CHECK(s.triangles.size() == 4);
  CHECK(s.warnings.size() == 1);     // only: no <sensor>
  REQUIRE(s.materials.size() == 1);  // both shapes share the referenced BSDF
  CHECK(near(albedo(s.materials[0]), glm::vec3(0.25f)));

  std::string broken = dir.write("broken.xml", scene_xml("<include filename=\"missing.xml\"/>\n"));
  require_error(broken, broken, 2, "cannot open included file");
}

TEST_CASE("Colours: rgb, srgb, spectrum", "[scene]") {
  SECTION("rgb") {
    CHECK(near(reflectance_of("<rgb name=\"reflectance\" value=\"0.1 0.2 0.3\"/>"), {0.1f, 0.2f, 0.3f}));
    CHECK(near(reflectance_of("<rgb name=\"reflectance\" value=\"0.1, 0.2, 0.3\"/>"), {0.1f, 0.2f, 0.3f}));
    CHECK(near(reflectance_of("<rgb name=\"reflectance\" value=\"0.4\"/>"), glm::vec3(0.4f)));
    CHECK(near(reflectance_of("<rgb name=\"reflectance\" value=\"1.5, 0.5, -1\"/>"), {1, 0.5f, 0}));  // clamped
    CHECK(near(reflectance_of(""), glm::vec3(0.5f)));                                                 // diffuse default
  }
  SECTION("srgb: decoded to linear") {
    // 0x80 / 255 = 0.50196 -> ((0.50196 + 0.055) / 1.055)^2.4 = 0.21586.
    CHECK(near(reflectance_of("<srgb name=\"reflectance\" value=\"#ff8000\"/>"), {1, 0.21586f, 0}));
    CHECK(near(reflectance_of("<srgb name=\"reflectance\" value=\"0.5\"/>"), glm::vec3(0.21404f)));
  }
  SECTION("spectrum: a constant reflectance 1 is white") {
    CHECK(near(reflectance_of("<spectrum name=\"reflectance\" value=\"1\"/>"), glm::vec3(1.0f), 1e-3f));
    CHECK(near(reflectance_of("<spectrum name=\"reflectance\" value=\"360:1, 830:1\"/>"), glm::vec3(1.0f), 1e-3f));
    CHECK(near(reflectance_of("<spectrum name=\"reflectance\" value=\"360:0.5, 600:0.5, 830:0.5\"/>"), glm::vec3(0.5f),
               1e-3f));
  }
  SECTION("spectrum: emitted radiance as in Mitsuba 3's RGB mode") {
    // A uniform emitted spectrum is equal-energy white: xyz_to_srgb(1, 1, 1) (version 3), or 1 (version 0.5).
    CHECK(near(radiance_of("<spectrum name=\"radiance\" value=\"2\"/>"),
               2.0f * glm::vec3(1.204794f, 0.948291f, 0.908916f), 1e-3f));
    CHECK(near(radiance_of("<spectrum name=\"radiance\" value=\"2\"/>", "0.5.0"), glm::vec3(2.0f)));
    CHECK(near(radiance_of("<spectrum name=\"radiance\" value=\"360:1, 830:1\"/>"),
               glm::vec3(1.204794f, 0.948291f, 0.908916f), 2e-3f));
    // The cbox light, integrated with the tabulated CIE 1931 curves at 1 nm (5 nm table, linear interpolation).
    CHECK(near(radiance_of("<spectrum name=\"radiance\" value=\"400:0, 500:8, 600:15.6, 700:18.4\"/>"),
               {20.714f, 10.854f, 2.771f}, 1e-2f));
    CHECK(near(radiance_of("<rgb name=\"radiance\" value=\"17, 12, 4\"/>"), {17, 12, 4}));  // unbounded
  }
  SECTION("Mitsuba 3's spectrum plugins, as its RGB modes read them") {
    // uniform: its value; srgb: its colour; d65: its scale times its colour or white.
    CHECK(near(reflectance_of("<spectrum type=\"uniform\" name=\"reflectance\"><float name=\"value\" value=\"0.3\"/>"
                              "</spectrum>"),
               glm::vec3(0.3f)));
    CHECK(near(reflectance_of("<spectrum type=\"srgb\" name=\"reflectance\"><rgb name=\"color\" value=\"0.2, 0.5, 0.9\"/>"
                              "</spectrum>"),
               {0.2f, 0.5f, 0.9f}));
    CHECK(near(radiance_of("<spectrum type=\"d65\" name=\"radiance\"><float name=\"scale\" value=\"3\"/></spectrum>"),
               glm::vec3(3.0f)));
    CHECK(near(radiance_of("<spectrum type=\"d65\" name=\"radiance\"><rgb name=\"color\" value=\"1, 2, 4\"/>"
                           "<float name=\"scale\" value=\"0.5\"/></spectrum>"),
               {0.5f, 1.0f, 2.0f}));
    CHECK(near(radiance_of("<spectrum type=\"d65\" name=\"radiance\"/>"), glm::vec3(1.0f)));
  }
  SECTION("spectrum from a file") {
    TempDir dir;
    dir.write("flat.spd", "# wavelength value\n360 0.25\n830 0.25\n");
    std::string path = dir.write("s.xml", scene_xml("<shape type=\"rectangle\"><bsdf type=\"diffuse\">"
                                                    "<spectrum name=\"reflectance\" filename=\"flat.spd\"/>"
                                                    "</bsdf></shape>\n"));
    CHECK(near(albedo(psf::load_scene(path).materials[0]), glm::vec3(0.25f), 1e-3f));
  }
}

TEST_CASE("Integrator: max_depth, rr_depth and hide_emitters, in both versions' names", "[scene]") {
  const std::string shape = "<shape type=\"rectangle\"/>\n";
  psf::Scene v3 = load_text("<integrator type=\"path\"><integer name=\"max_depth\" value=\"9\"/>"
                            "<integer name=\"rr_depth\" value=\"3\"/><boolean name=\"hide_emitters\" value=\"true\"/>"
                            "<boolean name=\"strict_normals\" value=\"true\"/></integrator>\n" + shape);
  CHECK(v3.max_depth == 9);
  CHECK(v3.rr_depth == 3);
  CHECK(v3.hide == PSF_HIDE_ENVIRONMENT);  // Mitsuba 3.6's path tracer: the environment only
  CHECK(count_warnings(v3, ":2: property 'strict_normals' of integrator 'path' is not supported; ignored") == 1);
  psf::Scene v05 = load_text("<integrator type=\"path\"><integer name=\"rrDepth\" value=\"2\"/>"
                             "<boolean name=\"hideEmitters\" value=\"true\"/></integrator>\n" + shape, {}, "0.5.0");
  CHECK(v05.max_depth == -1);
  CHECK(v05.rr_depth == 2);
  CHECK(v05.hide == (PSF_HIDE_ENVIRONMENT | PSF_HIDE_AREA));  // Mitsuba 0.5: every emitter
  // Mitsuba's volumetric and path replay path tracers are path tracing without media.
  for (const char* type : {"volpath", "volpathmis", "prb"}) {
    psf::Scene v = load_text(std::string("<integrator type=\"") + type +
                             "\"><integer name=\"max_depth\" value=\"7\"/><integer name=\"rr_depth\" value=\"3\"/>"
                             "</integrator>\n");
    INFO(type);
    CHECK(v.max_depth == 7);
    CHECK(v.rr_depth == 3);
    CHECK(count_warnings(v, "integrator") == 0);
  }
  // hide_emitters as Mitsuba 3.6 renders it: volpath and volpathmis hide area
  // emitters as well, prb (as path) the environment only.
  const uint32_t all = PSF_HIDE_ENVIRONMENT | PSF_HIDE_AREA;
  for (const auto& [type, hide] : std::vector<std::pair<std::string, uint32_t>>{
           {"volpath", all}, {"volpathmis", all}, {"prbvolpath", all}, {"prb", PSF_HIDE_ENVIRONMENT},
           {"prb_basic", PSF_HIDE_ENVIRONMENT}}) {
    psf::Scene v = load_text("<integrator type=\"" + type +
                             "\"><boolean name=\"hide_emitters\" value=\"true\"/></integrator>\n" + shape);
    INFO(type);
    CHECK(v.hide == hide);
  }
  psf::Scene o = load_text(
      "<integrator type=\"volpath_simple\"><integer name=\"maxDepth\" value=\"4\"/></integrator>\n", {}, "0.5.0");
  CHECK(o.max_depth == 4);
  CHECK(count_warnings(o, "integrator") == 0);
  psf::Scene b = load_text("<integrator type=\"bdpt\"/>\n");
  CHECK(count_warnings(b, "integrator 'bdpt' is not supported yet; using path tracing") == 1);
  // A wrapper renders the integrator nested in it, with its depths (Mitsuba 3's aov, 0.5's adaptive), one warning.
  psf::Scene aov = load_text(
      "<integrator type=\"aov\">\n<string name=\"aovs\" value=\"nn:sh_normal\"/>\n"
      "<integrator type=\"path\" name=\"image\"><integer name=\"max_depth\" value=\"6\"/>"
      "<integer name=\"rr_depth\" value=\"3\"/></integrator></integrator>\n");
  CHECK(aov.max_depth == 6);
  CHECK(aov.rr_depth == 3);
  CHECK(count_warnings(aov, ":2: integrator 'aov' is not supported; rendering the 'path' nested in it") == 1);
  CHECK(count_warnings(aov, "integrator") == 1);
  psf::Scene adaptive = load_text(
      "<integrator type=\"adaptive\"><integrator type=\"direct\"/></integrator>\n", {}, "0.5.0");
  CHECK(adaptive.max_depth == 2);
  CHECK(count_warnings(adaptive, "integrator 'adaptive' is not supported; rendering the 'direct'") == 1);
  psf::Scene plain = load_text("<integrator type=\"direct\"/>\n" + shape);
  CHECK(plain.max_depth == 2);
  CHECK(plain.rr_depth == 5);
  CHECK(plain.hide == 0u);
  psf::Scene direct = load_text(
      "<integrator type=\"direct\"><boolean name=\"hide_emitters\" value=\"true\"/></integrator>\n" + shape);
  CHECK(direct.hide == (PSF_HIDE_ENVIRONMENT | PSF_HIDE_AREA));  // Mitsuba 3's direct: every emitter
  // Equal indices of refraction are an error for dielectrics, as in Mitsuba
  // (psf rendered a rough one black).
  require_xml_error("<bsdf type=\"roughdielectric\"><float name=\"int_ior\" value=\"1.000277\"/></bsdf>\n", 2,
                    "indices of refraction must differ");
  require_xml_error("<bsdf type=\"dielectric\"><string name=\"int_ior\" value=\"air\"/></bsdf>\n", 2,
                    "indices of refraction must differ");
  // A merge that contains itself is an error, not an endless recursion.
  require_xml_error("<shape type=\"merge\" id=\"m\"><ref id=\"m\"/></shape>\n", 2, "merge shape contains itself");
  require_xml_error("<integrator type=\"path\"><integer name=\"rr_depth\" value=\"0\"/></integrator>\n", 2,
                    "'rr_depth' must be at least 1");
}

TEST_CASE("Sensor: the principal point offset shifts the image plane as Mitsuba 3's perspective does", "[scene]") {
  // Directions of Mitsuba 3.6.4's PerspectiveCamera::sample_ray (fov 90 along x,
  // a 200 x 100 film, looking down +z with y up) at the film's centre and its
  // top-left corner, per unit of view distance (right, down): with no offset
  // (0, 0) and (-1, -0.5); x = 0.1: (0.2, 0) and (-0.8, -0.5); y = 0.2: (0, 0.2)
  // and (-1, -0.3).
  auto camera = [](float x, float y, const char* type) {
    const std::string lens = std::string(type) == "thinlens" ? "<float name=\"aperture_radius\" value=\"0.1\"/>" : "";
    psf::Scene s = load_text(std::string("<sensor type=\"") + type + "\"><float name=\"fov\" value=\"90\"/>" + lens +
                             "<float name=\"principal_point_offset_x\" value=\"" + std::to_string(x) + "\"/>" +
                             "<float name=\"principal_point_offset_y\" value=\"" + std::to_string(y) + "\"/>" +
                             "<film type=\"hdrfilm\"><integer name=\"width\" value=\"200\"/>"
                             "<integer name=\"height\" value=\"100\"/></film></sensor>\n");
    return std::make_pair(s, psf::make_camera(s.camera, s.width, s.height));
  };
  // The kernel's direction for film point (s, t): forward + (2(s + shift_s) - 1) right + (2(t + shift_t) - 1) down.
  auto dir = [](const Camera& c, float s, float t) {
    auto v = [](const psf_float4& f) { return glm::vec3(f.s[0], f.s[1], f.s[2]); };
    glm::vec3 d = v(c.forward) + (2 * (s + c.shift_s) - 1) * v(c.right) + (2 * (t + c.shift_t) - 1) * v(c.down);
    glm::vec3 r = glm::normalize(v(c.right)), dn = glm::normalize(v(c.down));
    return glm::vec2(glm::dot(d, r), glm::dot(d, dn)) / glm::dot(d, v(c.forward));
  };
  struct Case {
    float x, y;
    glm::vec2 centre, corner;
  };
  for (Case k : {Case{0, 0, {0, 0}, {-1, -0.5f}}, Case{0.1f, 0, {0.2f, 0}, {-0.8f, -0.5f}},
                 Case{0, 0.2f, {0, 0.2f}, {-1, -0.3f}}}) {
    auto [scene, c] = camera(k.x, k.y, "perspective");
    INFO("offset " << k.x << ", " << k.y);
    CHECK(scene.warnings.empty());
    CHECK(glm::length(dir(c, 0.5f, 0.5f) - k.centre) < 1e-5f);
    CHECK(glm::length(dir(c, 0.0f, 0.0f) - k.corner) < 1e-5f);
  }
  // thinlens has no such property in Mitsuba 3 (it rejects it): a warning, no shift.
  auto [thin, tc] = camera(0.1f, 0.0f, "thinlens");
  CHECK(count_warnings(thin, "property 'principal_point_offset_x' of sensor 'thinlens' is not supported") == 1);
  CHECK(tc.shift_s == 0.0f);
}

TEST_CASE("Sensor: clip planes, crop window; unsupported sensor, film and sampler properties warn", "[scene]") {
  const std::string film = "<film type=\"hdrfilm\"><integer name=\"width\" value=\"8\"/>"
                           "<string name=\"pixel_format\" value=\"rgba\"/><boolean name=\"high_quality_edges\" "
                           "value=\"true\"/><integer name=\"crop_offset_x\" value=\"3\"/>"
                           "<integer name=\"crop_width\" value=\"4\"/></film>";
  psf::Scene s = load_text("<sensor type=\"perspective\"><float name=\"near_clip\" value=\"0.5\"/>"
                           "<float name=\"far_clip\" value=\"20\"/><float name=\"principal_point_offset_x\" "
                           "value=\"0.1\"/><transform name=\"to_world\"><scale value=\"2\"/></transform>" +
                           film + "<sampler type=\"stratified\"><integer name=\"seed\" value=\"3\"/></sampler>"
                           "</sensor>\n<shape type=\"rectangle\"/>\n");
  CHECK(s.camera.near_clip == Approx(0.5f));  // world-space distances, as Mitsuba 3 casts its rays
  CHECK(s.camera.far_clip == Approx(20.0f));
  // The window: 4 columns from 3 of the 8, every row of the 576 (Mitsuba's default height).
  CHECK(s.width == 4);
  CHECK(s.height == 576);
  CHECK(s.camera.film_width == 8);
  CHECK(s.camera.film_height == 576);
  CHECK(s.camera.crop_x == 3);
  CHECK(s.camera.crop_y == 0);
  CHECK(s.warnings.size() == 1);
  CHECK(count_warnings(s, ":2: property 'seed' of sampler 'stratified' is not supported") == 1);
  CHECK(s.camera.principal_point == glm::vec2(0.1f, 0.0f));
  require_xml_error("<sensor type=\"perspective\"><film type=\"hdrfilm\"><integer name=\"width\" value=\"8\"/>"
                    "<integer name=\"crop_offset_x\" value=\"6\"/><integer name=\"crop_width\" value=\"4\"/>"
                    "</film></sensor>\n",
                    2, "does not lie within the 8x576 film");
  psf::Scene d = load_text("<sensor type=\"perspective\"/>\n<shape type=\"rectangle\"/>\n");
  CHECK(d.camera.near_clip == Approx(0.01f));  // Mitsuba's defaults
  CHECK(d.camera.far_clip == Approx(1e4f));
  require_xml_error("<sensor type=\"perspective\"><float name=\"near_clip\" value=\"5\"/>"
                    "<float name=\"far_clip\" value=\"2\"/></sensor>\n",
                    2, "0 <= near_clip < far_clip");
}

TEST_CASE("camelCase (0.5) and snake_case (3) names are the same properties", "[scene]") {
  auto body = [](const char* to_world, const char* fov_axis, const char* max_depth, const char* sample_count) {
    return std::string("<integrator type=\"path\"><integer name=\"") + max_depth + "\" value=\"7\"/></integrator>\n" +
           "<sensor type=\"perspective\"><float name=\"fov\" value=\"30\"/><string name=\"" + fov_axis +
           "\" value=\"y\"/><transform name=\"" + to_world +
           "\"><lookat origin=\"1,1,1\" target=\"0,0,0\" up=\"0,1,0\"/></transform>"
           "<sampler type=\"independent\"><integer name=\"" +
           sample_count +
           "\" value=\"16\"/></sampler><film type=\"ldrfilm\"><integer name=\"width\" value=\"40\"/>"
           "<integer name=\"height\" value=\"30\"/></film></sensor>\n"
           "<shape type=\"rectangle\"><transform name=\"" +
           to_world + "\"><translate x=\"3\"/></transform></shape>\n";
  };
  psf::Scene old_names = load_text(body("toWorld", "fovAxis", "maxDepth", "sampleCount"), {}, "0.5.0");
  psf::Scene new_names = load_text(body("to_world", "fov_axis", "max_depth", "sample_count"));
  CHECK(old_names.max_depth == 7);
  CHECK(new_names.max_depth == 7);
  CHECK(old_names.default_spp == 16);
  CHECK(new_names.default_spp == 16);
  CHECK(old_names.camera.fov_axis == "y");
  CHECK(new_names.camera.fov_axis == "y");
  CHECK(old_names.width == new_names.width);
  CHECK(near(old_names.camera.origin, new_names.camera.origin));
  CHECK(near(old_names.camera.target, new_names.camera.target));
  CHECK(near(old_names.camera.up, new_names.camera.up));
  CHECK(old_names.positions == new_names.positions);
  CHECK(near(new_names.positions[0], {2, -1, 0}));
}

TEST_CASE("Shapes: tessellation, materials and area emitters", "[scene]") {
  psf::Scene s = load_text(
      "<bsdf type=\"twosided\" id=\"two\"><bsdf type=\"diffuse\"><rgb name=\"reflectance\" "
      "value=\"0.2\"/></bsdf></bsdf>\n"
      "<shape type=\"cube\"><ref id=\"two\"/></shape>\n"
      "<shape type=\"disk\"><ref id=\"two\"/></shape>\n"
      "<shape type=\"sphere\"><point name=\"center\" x=\"10\" y=\"0\" z=\"0\"/><float name=\"radius\" value=\"2\"/>"
      "</shape>\n"
      "<shape type=\"rectangle\"><boolean name=\"flip_normals\" value=\"true\"/>"
      "<emitter type=\"area\"><rgb name=\"radiance\" value=\"1, 2, 3\"/></emitter></shape>\n");
  CHECK(s.warnings.size() == 1);
  CHECK(count_warnings(s, "no <sensor>") == 1);
  REQUIRE(s.materials.size() == 3);  // twosided (cube and disk), default (sphere), default + emitter
  CHECK(near(albedo(s.materials[0]), glm::vec3(0.2f)));
  CHECK(s.materials[0].two_sided == 1);
  CHECK(near(albedo(s.materials[1]), glm::vec3(0.5f)));
  CHECK(s.materials[1].two_sided == 0);
  CHECK(near(emission(s.materials[2]), {1, 2, 3}));
  CHECK(s.materials[2].two_sided == 0);  // area emitters emit from the front only
  // An emitter's shape without a BSDF reflects nothing (Mitsuba 3's and 0.5's
  // default for emitters: a black diffuse; other shapes get 0.5 grey).
  CHECK(near(albedo(s.materials[2]), glm::vec3(0.0f)));
  CHECK(s.materials[2].type == PSF_MATERIAL_DIFFUSE);
  psf::Scene lit = load_text(
      "<shape type=\"rectangle\"><bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0.3\"/></bsdf>"
      "<emitter type=\"area\"/></shape>\n");
  CHECK(near(albedo(lit.materials.at(0)), glm::vec3(0.3f)));  // a BSDF given: kept

  // The sphere is analytic (an identity to_world).
  REQUIRE(s.spheres.size() == 1);
  CHECK(near(s.spheres[0].center, {10, 0, 0}));
  CHECK(s.spheres[0].radius == 2.0f);
  CHECK(s.spheres[0].material == 1);
  CHECK(!s.spheres[0].flip);
  // Every triangle faces away from its shape's centre (outward), except the flipped rectangle.
  const glm::vec3 centres[4] = {{0, 0, 0}, {0, 0, -1}, {10, 0, 0}, {0, 0, 1}};
  size_t tri = 0;
  const size_t counts[4] = {12, 64, 0, 2};
  for (int shape = 0; shape < 4; ++shape) {
    for (size_t k = 0; k < counts[shape]; ++k, ++tri) {
      REQUIRE(tri < s.triangles.size());
      glm::uvec3 t = s.triangles[tri];
      glm::vec3 a = s.positions[t.x], b = s.positions[t.y], c = s.positions[t.z];
      glm::vec3 n = glm::cross(b - a, c - a);
      CHECK(glm::dot(n, (a + b + c) / 3.0f - centres[shape]) > 0.0f);
    }
  }
  CHECK(tri == s.triangles.size());
}

TEST_CASE("Shapes: spheres are analytic unless mirrored or masked", "[scene]") {
  // Rotation, uniform scale and translation: the centre and radius go through
  // to_world, the frame's axes are the rotation's columns; flip_normals is kept.
  psf::Scene s = load_text(
      "<shape type=\"sphere\"><point name=\"center\" x=\"1\" y=\"0\" z=\"0\"/><float name=\"radius\" value=\"0.5\"/>"
      "<boolean name=\"flip_normals\" value=\"true\"/>"
      "<transform name=\"to_world\"><rotate z=\"1\" angle=\"90\"/><scale value=\"3\"/><translate y=\"2\"/></transform>"
      "</shape>\n");
  REQUIRE(s.spheres.size() == 1);
  CHECK(s.triangles.empty());
  const psf::SphereShape& sp = s.spheres[0];
  CHECK(near(sp.center, {0, 5, 0}));  // (1, 0, 0) turned to (0, 1, 0), scaled by 3, moved up by 2
  CHECK(sp.radius == Approx(1.5f));
  CHECK(near(sp.axis_x, {0, 1, 0}));
  CHECK(near(sp.axis_y, {-1, 0, 0}));
  CHECK(sp.flip);
  glm::vec3 lo, hi;
  psf::scene_bounds(s, lo, hi);
  CHECK(near(lo, {-1.5f, 3.5f, -1.5f}));
  CHECK(near(hi, {1.5f, 6.5f, 1.5f}));

  // A non-uniform scale: drawn as Mitsuba 3 draws it, with a warning: M = to_world
  // * scale(radius) splits into a rotation Q and a stretch S (M = Q S), and the
  // sphere has radius S[0][0], turned by Q. For M = R_y(90) diag(0.3, 0.6, 0.4)
  // S is that diagonal (radius 0.3) and Q = R_y(90); for M = diag(0.3, 0.6, 0.4)
  // R_y(90) = R_y(90) (R_y(90)^T diag R_y(90)), S[0][0] is the scale along
  // R_y(90)'s first column (0, 0, -1): 0.4.
  psf::Scene u = load_text(
      "<shape type=\"sphere\"><transform name=\"to_world\"><scale x=\"0.3\" y=\"0.6\" z=\"0.4\"/>"
      "<rotate y=\"1\" angle=\"90\"/><translate x=\"5\"/></transform></shape>\n"
      "<shape type=\"sphere\"><transform name=\"to_world\"><rotate y=\"1\" angle=\"90\"/>"
      "<scale x=\"0.3\" y=\"0.6\" z=\"0.4\"/></transform></shape>\n");
  REQUIRE(u.spheres.size() == 2);
  CHECK(u.triangles.empty());
  CHECK(u.spheres[0].radius == Approx(0.3f));
  CHECK(near(u.spheres[0].center, {5, 0, 0}));
  CHECK(near(u.spheres[0].axis_x, {0, 0, -1}));
  CHECK(u.spheres[1].radius == Approx(0.4f));
  CHECK(near(u.spheres[1].center, {0, 0, 0}));
  CHECK(near(u.spheres[1].axis_x, {0, 0, -1}));
  CHECK(count_warnings(u, "scales non-uniformly") == 2);

  // A mirroring scale and a mask BSDF (cut-outs are alpha tests on triangles):
  // tessellated, each with its vertices on the transformed sphere.
  psf::Scene t = load_text(
      "<shape type=\"sphere\"><transform name=\"to_world\"><scale x=\"-1\" y=\"1\" z=\"1\"/></transform></shape>\n"
      "<shape type=\"sphere\"><bsdf type=\"mask\"><float name=\"opacity\" value=\"0.5\"/>"
      "<bsdf type=\"diffuse\"/></bsdf></shape>\n");
  CHECK(t.spheres.empty());
  REQUIRE(t.triangles.size() == 2 * size_t(2 * 64 + 2 * 64 * 30));
  for (const glm::vec3& p : t.positions) CHECK(glm::length(p) == Approx(1.0f).epsilon(1e-5));
}

TEST_CASE("Shapes: a cylinder is Mitsuba's open tube from p0 to p1", "[scene]") {
  // Axis along (1, 2, 2) / 3 from p0 = (1, 0, 0), length 3, radius 0.5, under a
  // translation by y = 4.
  psf::Scene s = load_text(
      "<shape type=\"cylinder\"><point name=\"p0\" x=\"1\" y=\"0\" z=\"0\"/>"
      "<point name=\"p1\" x=\"2\" y=\"2\" z=\"2\"/><float name=\"radius\" value=\"0.5\"/>"
      "<transform name=\"to_world\"><translate y=\"4\"/></transform></shape>\n");
  const glm::vec3 p0(1, 4, 0), d = glm::vec3(1, 2, 2) / 3.0f;
  REQUIRE(s.triangles.size() == 2 * 64);  // 64 quads around, no caps
  REQUIRE(s.normals.size() == s.positions.size());
  REQUIRE(s.uvs.size() == s.positions.size());
  for (size_t i = 0; i < s.positions.size(); ++i) {
    const glm::vec3 q = s.positions[i] - p0;
    const float along = glm::dot(q, d);
    const glm::vec3 radial = q - along * d;
    CHECK(glm::length(radial) == Approx(0.5f).epsilon(1e-5));
    CHECK((std::fabs(along) < 1e-5f || std::fabs(along - 3.0f) < 1e-5f));
    CHECK(s.uvs[i].y == Approx(along / 3.0f).margin(1e-5));  // v runs from p0 to p1
    CHECK(near(s.normals[i], radial / 0.5f));                 // the shading normal points outwards
  }
  // Every triangle faces away from the axis, and the quads close around it.
  float around = 0.0f;
  for (const glm::uvec3& t : s.triangles) {
    glm::vec3 a = s.positions[t.x], b = s.positions[t.y], c = s.positions[t.z];
    glm::vec3 centre = (a + b + c) / 3.0f - p0;
    CHECK(glm::dot(glm::cross(b - a, c - a), centre - glm::dot(centre, d) * d) > 0.0f);
    around += glm::length(glm::cross(b - a, c - a)) / 2.0f;
  }
  CHECK(around == Approx(2.0 * 3.14159265 * 0.5 * 3.0).epsilon(0.002));  // the lateral area, tessellated
  require_xml_error("<shape type=\"cylinder\"><float name=\"radius\" value=\"0\"/></shape>\n", 2,
                    "radius must be positive");
  require_xml_error("<shape type=\"cylinder\"><point name=\"p1\" x=\"0\" y=\"0\" z=\"0\"/></shape>\n", 2,
                    "p0 and p1 must differ");
}

TEST_CASE("Shapes: a cube has Mitsuba 3's uv on each face", "[scene]") {
  // Points on the six faces and the uv Mitsuba 3.6's ray_intersect gives there.
  psf::Scene s = load_text("<shape type=\"cube\"/>\n");
  REQUIRE(s.uvs.size() == s.positions.size());
  REQUIRE(s.triangles.size() == 12);
  const std::vector<std::pair<glm::vec3, glm::vec2>> probes = {
      {{0.5f, 0.25f, 1}, {0.625f, 0.75f}}, {{0.3f, 1, -0.6f}, {0.35f, 0.8f}},  {{1, -0.2f, 0.7f}, {0.4f, 0.15f}},
      {{-1, 0.4f, 0.1f}, {0.7f, 0.55f}},   {{0.1f, -1, 0.5f}, {0.75f, 0.55f}}, {{-0.7f, 0.2f, -1}, {0.4f, 0.15f}}};
  for (const auto& [q, want] : probes) {
    int found = 0;
    for (const glm::uvec3& t : s.triangles) {
      glm::vec3 a = s.positions[t.x], b = s.positions[t.y], c = s.positions[t.z];
      glm::vec3 n = glm::cross(b - a, c - a);
      if (std::abs(glm::dot(glm::normalize(n), q - a)) > 1e-6f) continue;  // not this face's plane
      float d = glm::dot(n, n);
      float w1 = glm::dot(glm::cross(q - a, c - a), n) / d, w2 = glm::dot(glm::cross(b - a, q - a), n) / d;
      if (w1 < 0 || w2 < 0 || w1 + w2 > 1) continue;
      ++found;
      CHECK(glm::dot(n, q) > 0.0f);  // facing outwards
      glm::vec2 uv = s.uvs[t.x] * (1 - w1 - w2) + s.uvs[t.y] * w1 + s.uvs[t.z] * w2;
      INFO("at " << q.x << ", " << q.y << ", " << q.z << ": uv " << uv.x << ", " << uv.y);
      CHECK(glm::length(uv - want) < 1e-5f);
    }
    CHECK(found == 1);
  }
}

TEST_CASE("Shapes: a disk is Mitsuba's unit disk with its uv (r, phi / 2pi)", "[scene]") {
  // Rotated by 90 degrees about z and scaled by 2: the object-space point (x, y)
  // lies at (-2y, 2x). Mitsuba 3.6's ray_intersect gives uv (0.5, 0.25) at
  // object (0, 0.5), (0.424264, 0.875) at (0.3, -0.3), (0.707107, 0.0225836)
  // at (0.7, 0.1); here, every point against (|p|, atan2(y, x) / 2pi): u within
  // the fan's 0.12 % (cos of half a sector), v within half a sector near the centre.
  psf::Scene s = load_text(
      "<shape type=\"disk\"><transform name=\"to_world\"><scale value=\"2\"/><rotate z=\"1\" angle=\"90\"/>"
      "</transform></shape>\n");
  REQUIRE(s.uvs.size() == s.positions.size());
  REQUIRE(s.triangles.size() == 64);
  double area = 0;
  for (const glm::uvec3& t : s.triangles) {
    glm::vec3 a = s.positions[t.x], b = s.positions[t.y], c = s.positions[t.z];
    CHECK(glm::cross(b - a, c - a).z > 0.0f);  // facing +z
    area += glm::length(glm::cross(b - a, c - a)) / 2.0;
  }
  CHECK(area == Approx(4 * 3.14159265).epsilon(0.002));
  auto object = [](const glm::vec3& p) { return glm::vec2(p.y, -p.x) / 2.0f; };
  auto want = [](glm::vec2 q) {
    double v = std::atan2(q.y, q.x) / (2 * 3.14159265358979);
    return glm::dvec2(glm::length(q), v < 0 ? v + 1 : v);
  };
  const std::vector<glm::vec2> probes = {{0, 0.5f}, {0.3f, -0.3f}, {0.7f, 0.1f}, {-0.9f, 0.01f}, {0.2f, -0.01f}};
  const std::vector<glm::dvec2> mitsuba = {{0.5, 0.25}, {0.424264, 0.875}, {0.707107, 0.0225836}};
  for (size_t k = 0; k < probes.size(); ++k) {
    const glm::vec2 q = probes[k];
    if (k < mitsuba.size()) CHECK(glm::length(want(q) - mitsuba[k]) < 1e-5);  // the convention is Mitsuba's
    int found = 0;
    for (const glm::uvec3& t : s.triangles) {
      glm::vec2 a = object(s.positions[t.x]), b = object(s.positions[t.y]), c = object(s.positions[t.z]);
      auto cross2 = [](glm::vec2 u, glm::vec2 v) { return u.x * v.y - u.y * v.x; };
      float d = cross2(b - a, c - a), w1 = cross2(q - a, c - a) / d, w2 = cross2(b - a, q - a) / d;
      if (w1 < 0 || w2 < 0 || w1 + w2 > 1) continue;
      ++found;
      glm::dvec2 uv = glm::dvec2(s.uvs[t.x]) * double(1 - w1 - w2) + glm::dvec2(s.uvs[t.y]) * double(w1) +
                      glm::dvec2(s.uvs[t.z]) * double(w2);
      INFO("probe " << q.x << ", " << q.y << ": uv " << uv.x << ", " << uv.y);
      CHECK(uv.x == Approx(want(q).x).epsilon(1.3e-3));
      CHECK(uv.y == Approx(want(q).y).margin(0.5 / 64));
    }
    CHECK(found == 1);
  }
}

TEST_CASE("Shapes: merge draws its shapes; Mitsuba's curves and SDF grids are ignored with a warning", "[scene]") {
  psf::Scene s = load_text(
      "<shape type=\"merge\">\n"
      "  <shape type=\"rectangle\"/>\n"
      "  <shape type=\"cube\"><transform name=\"to_world\"><translate x=\"5\"/></transform></shape>\n"
      "</shape>\n"
      "<shape type=\"bsplinecurve\"><string name=\"filename\" value=\"hair.txt\"/></shape>\n"
      "<shape type=\"sdfgrid\"/>\n");
  REQUIRE(s.triangles.size() == 2 + 12);
  CHECK(s.positions[4] == glm::vec3(6, -1, -1));  // the cube's first corner, moved by its own to_world
  CHECK(count_warnings(s, ":6: shape 'bsplinecurve' is not supported yet; ignored") == 1);
  CHECK(count_warnings(s, ":7: shape 'sdfgrid' is not supported yet; ignored") == 1);
  require_xml_error("<shape type=\"cylindre\"/>\n", 2, "unknown shape type 'cylindre'");
  // A shape's properties it does not read warn (Mitsuba 0.5's maxSmoothAngle smooths normals).
  psf::Scene smooth = load_text("<shape type=\"sphere\"><float name=\"radius\" value=\"2\"/>"
                                "<float name=\"maxSmoothAngle\" value=\"30\"/></shape>\n", {}, "0.5.0");
  CHECK(smooth.warnings.size() == 2);  // and no <sensor>
  CHECK(count_warnings(smooth, ":2: property 'max_smooth_angle' of shape 'sphere' is not supported; ignored") == 1);
}

TEST_CASE("Shapes: maxSmoothAngle rebuilds a mesh's normals with creases (Mitsuba 0.5)", "[scene]") {
  // A cube of 8 shared vertices: at 30 degrees its 90-degree edges are creases
  // (each corner takes its face's normal); at 100 the three faces at a corner
  // share (1, 1, 1) / sqrt(3), each weighted by its 90 degrees there.
  TempDir dir;
  dir.write("cube.obj",
            "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
            "vn 0 0 1\n"  // file normals, discarded
            "f 1//1 4//1 3//1 2//1\nf 5//1 6//1 7//1 8//1\nf 1//1 2//1 6//1 5//1\n"
            "f 2//1 3//1 7//1 6//1\nf 3//1 4//1 8//1 7//1\nf 4//1 1//1 5//1 8//1\n");
  auto load = [&](float degrees) {
    return psf::load_scene(dir.write("s.xml", "<scene version=\"0.5.0\"><shape type=\"obj\">"
                                              "<string name=\"filename\" value=\"cube.obj\"/>"
                                              "<float name=\"maxSmoothAngle\" value=\"" +
                                                  std::to_string(degrees) + "\"/></shape></scene>\n"));
  };
  psf::Scene creased = load(30.0f), smooth = load(100.0f);
  REQUIRE(creased.triangles.size() == 12);
  REQUIRE(smooth.triangles.size() == 12);
  CHECK(creased.positions.size() == 24);  // 4 corners per face
  CHECK(smooth.positions.size() == 8);    // one normal per corner of the cube
  for (const glm::uvec3& t : creased.triangles) {
    glm::vec3 a = creased.positions[t.x], b = creased.positions[t.y], c = creased.positions[t.z];
    glm::vec3 face = glm::normalize(glm::cross(b - a, c - a));
    for (int k = 0; k < 3; ++k) CHECK(near(creased.normals[t[k]], face));
  }
  for (size_t v = 0; v < smooth.positions.size(); ++v)
    CHECK(near(smooth.normals[v], glm::normalize(smooth.positions[v])));
  // Vertex colours follow their vertices into the split ones.
  psf::detail::TriMesh coloured;
  coloured.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  coloured.triangles = {{0, 1, 2}, {0, 3, 1}};  // two faces at 90 degrees
  coloured.colors = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 0}};
  psf::detail::compute_crease_normals(coloured, 30.0f);
  REQUIRE(coloured.colors.size() == coloured.positions.size());
  for (size_t v = 0; v < coloured.positions.size(); ++v) {
    const glm::vec3 p = coloured.positions[v];
    const glm::vec3 want = p == glm::vec3(0, 0, 0)   ? glm::vec3(1, 0, 0)
                           : p == glm::vec3(1, 0, 0) ? glm::vec3(0, 1, 0)
                           : p == glm::vec3(0, 1, 0) ? glm::vec3(0, 0, 1)
                                                     : glm::vec3(1, 1, 0);
    CHECK(coloured.colors[v] == want);
  }
  CHECK_THROWS_WITH(load(-5.0f), Catch::Contains("maxSmoothAngle must be between 0 and 180 degrees"));
  // face_normals wins over maxSmoothAngle: flat shading.
  psf::Scene flat = psf::load_scene(dir.write("f.xml", "<scene version=\"0.5.0\"><shape type=\"obj\">"
                                                       "<string name=\"filename\" value=\"cube.obj\"/>"
                                                       "<boolean name=\"faceNormals\" value=\"true\"/>"
                                                       "<float name=\"maxSmoothAngle\" value=\"30\"/></shape></scene>\n"));
  CHECK(flat.normals.empty());
}

TEST_CASE("Shapes: vertex tangents for normal maps follow dp/du smoothly, with the uv's handedness", "[scene]") {
  // A quarter of a unit cylinder about y in 8 strips: (sin phi, y, cos phi) for y
  // in {0, 1}, outward normals, u = phi / (pi / 2) (or 1 - that: mirrored), v = 1 - y
  // (glTF's v runs down the image). Each tangent must be the circle's direction
  // (cos phi, 0, -sin phi) times the sign of du/dphi, orthogonal to the normal; the
  // handedness w = +1 for the unmirrored mapping (n x t = +y, up the image) and -1 mirrored.
  for (bool mirrored : {false, true}) {
    psf::detail::TriMesh m;
    const int n = 8;
    for (int i = 0; i <= n; ++i)
      for (int j = 0; j < 2; ++j) {
        float phi = 0.5f * 3.14159265f * float(i) / float(n);
        m.positions.push_back({std::sin(phi), float(j), std::cos(phi)});
        m.normals.push_back({std::sin(phi), 0.0f, std::cos(phi)});
        float u = float(i) / float(n);
        m.uvs.push_back({mirrored ? 1.0f - u : u, 1.0f - float(j)});
      }
    for (uint32_t i = 0; i < uint32_t(n); ++i) {  // counter-clockwise seen from outside
      uint32_t a = 2 * i, b = 2 * i + 1, c = 2 * i + 2, d = 2 * i + 3;
      m.triangles.push_back({a, c, d});
      m.triangles.push_back({a, d, b});
    }
    psf::detail::compute_vertex_tangents(m);
    REQUIRE(m.tangents.size() == m.positions.size());
    for (size_t v = 0; v < m.positions.size(); ++v) {
      float phi = std::atan2(m.positions[v].x, m.positions[v].z);
      glm::vec3 want = glm::vec3(std::cos(phi), 0.0f, -std::sin(phi)) * (mirrored ? -1.0f : 1.0f);
      INFO("mirrored " << mirrored << ", vertex " << v);
      CHECK(glm::length(glm::vec3(m.tangents[v]) - want) < 1e-5f);
      CHECK(m.tangents[v].w == (mirrored ? -1.0f : 1.0f));
    }
  }
  // Without uvs nothing is made; a vertex only on uv-degenerate triangles has none.
  psf::detail::TriMesh flat;
  flat.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  flat.normals.assign(3, glm::vec3(0, 0, 1));
  flat.triangles = {{0, 1, 2}};
  psf::detail::compute_vertex_tangents(flat);
  CHECK(flat.tangents.empty());
  flat.uvs.assign(3, glm::vec2(0.5f));
  psf::detail::compute_vertex_tangents(flat);
  REQUIRE(flat.tangents.size() == 3);
  CHECK(flat.tangents[0] == glm::vec4(0.0f));
}

TEST_CASE("Shapes: a PLY's vertex colours reach a BSDF through mesh_attribute 'vertex_color' only", "[scene]") {
  TempDir dir;
  dir.write("c.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                     "property uchar red\nproperty uchar green\nproperty uchar blue\nelement face 1\n"
                     "property list uchar int vertex_indices\nend_header\n0 0 0 255 0 0\n1 0 0 0 255 0\n"
                     "0 1 0 0 0 255\n3 0 1 2\n");
  auto load = [&](const std::string& bsdf) {
    return psf::load_scene(dir.write("s.xml", "<scene version=\"3.0.0\">\n<shape type=\"ply\"><string name=\"filename\" "
                                              "value=\"c.ply\"/>" + bsdf + "</shape>\n</scene>\n"));
  };
  const std::string attribute = "<texture name=\"reflectance\" type=\"mesh_attribute\"><string name=\"name\" "
                                "value=\"vertex_color\"/></texture>";
  psf::Scene used = load("<bsdf type=\"twosided\"><bsdf type=\"diffuse\">" + attribute + "</bsdf></bsdf>");
  REQUIRE(used.colors.size() == 3);
  CHECK(used.colors[1] == glm::vec3(0, 1, 0));
  CHECK(used.materials[used.tri_material[0]].albedo.s[0] == 1.0f);  // white times the colours
  CHECK(count_warnings(used, "vertex colours") == 0);
  psf::Scene left = load("<bsdf type=\"diffuse\"/>");
  CHECK(left.colors.empty());
  CHECK(count_warnings(left, ":2: the mesh's vertex colours are not used") == 1);
  psf::Scene other = load("<bsdf type=\"diffuse\"><texture name=\"reflectance\" type=\"mesh_attribute\">"
                          "<string name=\"name\" value=\"face_color\"/></texture></bsdf>");
  CHECK(count_warnings(other, "mesh_attribute 'face_color' is not supported") == 1);
  CHECK(other.colors.empty());
  // In a blend only the part whose colour term reads them multiplies them in;
  // a plastic's specular reflectance cannot (a warning), its diffuse can.
  psf::Scene blend = load("<bsdf type=\"blendbsdf\"><bsdf type=\"diffuse\"><rgb name=\"reflectance\" "
                          "value=\"0.3\"/></bsdf><bsdf type=\"diffuse\">" + attribute + "</bsdf></bsdf>");
  const Material& top = blend.materials[blend.tri_material[0]];
  REQUIRE(top.blend >= 1u);
  CHECK((top.flags & PSF_MATFLAG_VERTEX_COLOR) == 0u);
  CHECK((blend.materials[top.blend - 1].flags & PSF_MATFLAG_VERTEX_COLOR) != 0u);
  CHECK(blend.colors.size() == 3);
  std::string specular = attribute;
  specular.replace(specular.find("reflectance"), 11, "specular_reflectance");
  psf::Scene coat = load("<bsdf type=\"plastic\">" + specular + "</bsdf>");
  CHECK(count_warnings(coat, "a mesh_attribute for 'specular_reflectance' is not supported") == 1);
  CHECK((coat.materials[coat.tri_material[0]].flags & PSF_MATFLAG_VERTEX_COLOR) == 0u);
  CHECK(coat.colors.empty());
  // A principled base_color from the colours: the one material is marked (its
  // base colour, and through it the metallic Fresnel, reads them).
  std::string base = attribute;
  base.replace(base.find("reflectance"), 11, "base_color");
  psf::Scene pr = load("<bsdf type=\"principled\"><float name=\"metallic\" value=\"0.5\"/>" + base + "</bsdf>");
  const Material& principled = pr.materials[pr.tri_material[0]];
  CHECK(principled.type == PSF_MATERIAL_PRINCIPLED);
  CHECK(principled.blend == 0u);
  CHECK((principled.flags & PSF_MATFLAG_VERTEX_COLOR) != 0u);
  CHECK(pr.colors.size() == 3);
}

TEST_CASE("Shapegroups and instances: the group's shapes drawn once per instance", "[scene]") {
  // A group of a rectangle (its own to_world: scaled by 2) and a cube with a
  // diffuse BSDF, drawn by two instances (translated by x = 10 and by y = 5);
  // the group itself draws nothing.
  psf::Scene s = load_text(
      "<shape type=\"shapegroup\" id=\"g\">\n"
      "  <shape type=\"rectangle\"><transform name=\"to_world\"><scale value=\"2\"/></transform></shape>\n"
      "  <shape type=\"cube\"><bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0.3\"/></bsdf></shape>\n"
      "</shape>\n"
      "<shape type=\"instance\"><ref id=\"g\"/><transform name=\"to_world\"><translate x=\"10\"/></transform></shape>\n"
      "<shape type=\"instance\"><ref id=\"g\"/><transform name=\"to_world\"><translate y=\"5\"/></transform></shape>\n");
  REQUIRE(s.triangles.size() == 2 * (2 + 12));
  REQUIRE(s.positions.size() == 2 * (4 + 24));
  CHECK(s.positions[0] == glm::vec3(8, -2, 0));   // the first instance's rectangle: scaled, then moved by x
  CHECK(s.positions[28] == glm::vec3(-2, 3, 0));  // the second's: scaled, then moved by y
  // One material per (BSDF, emitter) pair, shared by the instances.
  CHECK(s.tri_material[2] == s.tri_material[16]);
  CHECK(near(albedo(s.materials[s.tri_material[2]]), glm::vec3(0.3f)));
  // An instance needs a shapegroup; instances do not nest.
  require_xml_error("<shape type=\"rectangle\" id=\"r\"/>\n<shape type=\"instance\"><ref id=\"r\"/></shape>\n", 3,
                    "needs one reference to a shapegroup");
  require_xml_error("<shape type=\"shapegroup\" id=\"a\"><shape type=\"cube\"/></shape>\n"
                    "<shape type=\"shapegroup\" id=\"b\">\n<shape type=\"instance\"><ref id=\"a\"/></shape></shape>\n"
                    "<shape type=\"instance\"><ref id=\"b\"/></shape>\n",
                    4, "nested instancing");
}

TEST_CASE("<alias> gives an element a second id", "[scene]") {
  psf::Scene s = load_text(
      "<bsdf type=\"diffuse\" id=\"red\"><rgb name=\"reflectance\" value=\"0.8 0.1 0.1\"/></bsdf>\n"
      "<alias id=\"red\" as=\"wall\"/>\n"
      "<shape type=\"rectangle\"><ref id=\"wall\"/></shape>\n");
  REQUIRE(s.materials.size() == 1);
  CHECK(near(albedo(s.materials[0]), glm::vec3(0.8f, 0.1f, 0.1f)));
  require_xml_error("<alias id=\"nothing\" as=\"x\"/>\n", 2, "alias of unknown id 'nothing'");
  require_xml_error("<bsdf type=\"diffuse\" id=\"a\"/>\n<bsdf type=\"diffuse\" id=\"b\"/>\n<alias id=\"a\" as=\"b\"/>\n",
                    4, "duplicate id 'b'");
}

TEST_CASE("Unsupported plugins are approximated with one warning each", "[scene]") {
  psf::Scene s = load_text(
      "<bsdf type=\"ward\" id=\"p\"><rgb name=\"diffuse_reflectance\" value=\"0.3\"/></bsdf>\n"
      "<bsdf type=\"mixturebsdf\" id=\"c\"><bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0.2\"/></bsdf>"
      "<bsdf type=\"conductor\"/></bsdf>\n"
      "<shape type=\"rectangle\"><ref id=\"p\"/></shape>\n"
      "<shape type=\"rectangle\"><ref id=\"p\"/></shape>\n"
      "<shape type=\"rectangle\"><ref id=\"c\"/></shape>\n"
      "<shape type=\"rectangle\"><bsdf type=\"diffuse\"><texture name=\"reflectance\" type=\"bitmap\">"
      "<string name=\"filename\" value=\"x.png\"/></texture></bsdf></shape>\n"
      "<emitter type=\"sunsky\"/>\n");
  CHECK(s.warnings.size() == 5);
  CHECK(count_warnings(s, "no <sensor>") == 1);
  CHECK(count_warnings(s, ":2: bsdf 'ward'") == 1);
  CHECK(count_warnings(s, ":3: bsdf 'mixturebsdf'") == 1);
  CHECK(count_warnings(s, ":7: texture file 'x.png' not found") == 1);  // the default reflectance instead
  CHECK(count_warnings(s, ":8: emitter 'sunsky'") == 1);
  REQUIRE(s.materials.size() == 3);
  CHECK(near(albedo(s.materials[0]), glm::vec3(0.3f)));
  CHECK(near(albedo(s.materials[1]), glm::vec3(0.6f)));  // the mean of diffuse 0.2 and a mirror's 1
  CHECK(near(albedo(s.materials[2]), glm::vec3(0.5f)));
}

TEST_CASE("OBJ files load directly with MTL materials and a framing camera", "[scene]") {
  TempDir dir;
  dir.write("lit.mtl", "newmtl red\nKd 0.8 0.1 0.1\nnewmtl lamp\nKd 0 0 0\nKe 5 4 3\n");
  std::string path = dir.write("model.obj",
                               "mtllib lit.mtl\n"
                               "v -2 0 0\nv 2 0 0\nv 2 1 -3\nv -2 1 -3\nv 0 3 -1\n"
                               "usemtl red\nf 1 2 3 4\n"
                               "usemtl lamp\nf 3 4 5\n"
                               "f -1 -2 -3\n");
  psf::Scene s = psf::load_scene(path);
  CHECK(s.warnings.empty());
  CHECK(s.triangles.size() == 4);
  CHECK(s.width == 512);
  CHECK(s.height == 512);
  REQUIRE(s.materials.size() == 2);
  CHECK(near(albedo(s.materials[s.tri_material[0]]), {0.8f, 0.1f, 0.1f}));
  CHECK(s.tri_material[0] == s.tri_material[1]);
  CHECK(near(emission(s.materials[s.tri_material[2]]), {5, 4, 3}));
  CHECK(emissive_materials(s) == 1);
  // The quad is a fan (0, 1, 2), (0, 2, 3) as in Mitsuba.
  CHECK(s.positions[s.triangles[1].z] == glm::vec3(-2, 1, -3));

  // Every vertex projects inside the image of the default camera, which looks along -z.
  Camera cam = psf::make_camera(s.camera, s.width, s.height);
  CHECK(s.camera.target.z < s.camera.origin.z);
  glm::vec3 o(cam.origin.s[0], cam.origin.s[1], cam.origin.s[2]);
  glm::vec3 f(cam.forward.s[0], cam.forward.s[1], cam.forward.s[2]);
  glm::vec3 r(cam.right.s[0], cam.right.s[1], cam.right.s[2]);
  glm::vec3 d(cam.down.s[0], cam.down.s[1], cam.down.s[2]);
  for (const glm::vec3& p : s.positions) {
    glm::vec3 v = p - o;
    float depth = glm::dot(v, f);
    REQUIRE(depth > 0.0f);
    float sx = glm::dot(v, r) / (depth * glm::dot(r, r)), sy = glm::dot(v, d) / (depth * glm::dot(d, d));
    CHECK(std::abs(sx) <= 1.0f);
    CHECK(std::abs(sy) <= 1.0f);
  }

  // A missing MTL library is a warning; the faces get the default material.
  std::string lonely = dir.write("lonely.obj", "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n");
  psf::Scene l = psf::load_scene(lonely);
  CHECK(l.triangles.size() == 1);
  CHECK(count_warnings(l, "gone.mtl") >= 1);
  REQUIRE(l.materials.size() == 1);
  CHECK(near(albedo(l.materials[0]), glm::vec3(0.5f)));

  // Missing texture maps: one warning each, the material keeps Kd (tests/test_bsdf.cpp has the rest).
  dir.write("tex.mtl", "newmtl a\nKd 1 1 1\nmap_Kd a.png\nnewmtl b\nmap_Kd b.png\n");
  std::string textured =
      dir.write("textured.obj", "mtllib tex.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\nusemtl b\nf 1 3 2\n");
  psf::Scene t = psf::load_scene(textured);
  CHECK(count_warnings(t, "tex.mtl:1: map_Kd 'a.png' of material 'a' not found") == 1);
  CHECK(count_warnings(t, "tex.mtl:4: map_Kd 'b.png' of material 'b' not found") == 1);
  CHECK(near(albedo(t.materials[0]), glm::vec3(1.0f)));
}

TEST_CASE("Scene errors name the file and line", "[scene]") {
  SECTION("missing file") {
    require_error("/nonexistent/psf/scene.xml", "/nonexistent/psf/scene.xml", 0, "no such file");
  }
  SECTION("malformed XML") {
    TempDir dir;
    std::string path = dir.write("bad.xml", "<scene version=\"3.0.0\">\n  <shape type=\"cube\">\n\n</scene>\n");
    require_error(path, path, 4, "malformed XML");
  }
  SECTION("unknown shape type") { require_xml_error("\n<shape type=\"teapot\"/>\n", 3, "unknown shape type 'teapot'"); }
  SECTION("bad number") {
    require_xml_error("<sensor type=\"perspective\">\n<float name=\"fov\" value=\"1.0x\"/>\n</sensor>\n", 3,
                      "'1.0x' is not a number");
    require_xml_error(
        "<shape type=\"rectangle\"><bsdf type=\"diffuse\">\n<rgb name=\"reflectance\" value=\"0.5 x 1\"/>"
        "</bsdf></shape>\n",
        3, "'x' is not a number");
    require_xml_error(
        "<shape type=\"rectangle\"><transform name=\"to_world\">\n<translate x=\"1e\"/>"
        "</transform></shape>\n",
        3, "is not a number");
    require_xml_error("<integrator type=\"path\">\n<integer name=\"max_depth\" value=\"2.5\"/></integrator>\n", 3,
                      "'2.5' is not an integer");
  }
  SECTION("unparsable values") {
    require_xml_error(
        "<sensor type=\"perspective\"><float name=\"fov\" value=\"30\"/>\n"
        "<string name=\"fov_axis\" value=\"z\"/></sensor>\n",
        3, "fov_axis 'z'");
    require_xml_error("<shape type=\"rectangle\">\n<boolean name=\"flip_normals\" value=\"yes\"/></shape>\n", 3,
                      "not a boolean");
    require_xml_error(
        "<shape type=\"rectangle\"><bsdf type=\"diffuse\">\n<spectrum name=\"reflectance\" "
        "value=\"500:0.5, 400:0.5\"/></bsdf></shape>\n",
        3, "wavelengths must increase");
    require_xml_error("<shape type=\"rectangle\">\n<transform name=\"to_world\"><shear/></transform></shape>\n", 3,
                      "unexpected element <shear>");
  }
  SECTION("reference to an unknown id") {
    require_xml_error("<shape type=\"rectangle\">\n\n<ref id=\"nowhere\"/>\n</shape>\n", 4, "unknown id 'nowhere'");
  }
  SECTION("missing OBJ file") {
    require_xml_error("\n<shape type=\"obj\"><string name=\"filename\" value=\"gone.obj\"/></shape>\n", 3,
                      "cannot open OBJ file");
  }
  SECTION("OBJ index out of range") {
    TempDir dir;
    std::string obj = dir.write("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n# comment\nf 1 2 9\n");
    require_error(obj, obj, 6, "index 9 out of range");
    std::string xml =
        dir.write("uses.xml", scene_xml("<shape type=\"obj\"><string name=\"filename\" value=\"bad.obj\"/></shape>\n"));
    require_error(xml, obj, 6, "out of range");
    std::string negative = dir.write("neg.obj", "v 0 0 0\nv 1 0 0\nf -1 -2 -3\n");
    require_error(negative, negative, 3, "out of range");
  }
  SECTION("OBJ index zero: tinyobjloader's message") {
    TempDir dir;
    std::string obj = dir.write("zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
    require_error(obj, obj, 4, "OBJ parse error");
  }
  SECTION("non-finite OBJ vertex") {
    TempDir dir;
    std::string nan = dir.write("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
    require_error(nan, nan, 2, "not finite");
    std::string inf = dir.write("inf.obj", "v 0 0 0\nv 1 0 0\n\nv 0 1e999 0\nf 1 2 3\n");
    require_error(inf, inf, 4, "not finite");
  }
  SECTION("unknown format") {
    TempDir dir;
    std::string path = dir.write("scene.fbx", "Kaydara FBX Binary\n");
    require_error(path, path, 0, "unknown scene format");
  }
}

TEST_CASE("Shared scenes load", "[scene]") {
  std::optional<std::string> shared = psf::test::shared_dir();
  if (!shared) {
    WARN("../shared not found (set PSF_SHARED): skipping the shared scenes");
    return;
  }
  auto load_if_present = [&](const std::string& relative) -> std::optional<psf::Scene> {
    std::string path = *shared + "/" + relative;
    if (!fs::exists(path)) {
      WARN(path << " not found: skipped");
      return std::nullopt;
    }
    return psf::load_scene(path);
  };

  SECTION("cbox (Mitsuba 3, spectral reflectances, OBJ meshes)") {
    std::optional<psf::Scene> s = load_if_present("scenes/cbox/scene.xml");
    if (!s) return;
    CHECK(s->warnings.empty());
    CHECK(s->triangles.size() == 38);  // faces in the OBJ files, quads split in two
    CHECK(emissive_materials(*s) == 1);
    CHECK(s->max_depth == 6);
    CHECK(s->default_spp == 256);
    CHECK(s->width == 500);
    CHECK(s->camera.fov_axis == "smaller");
    CHECK(near(s->camera.origin, {278, 273, -800}));
    for (size_t m = 0; m < s->materials.size(); ++m) {
      glm::vec3 a = albedo(s->materials[m]);
      INFO(s->material_names[m] << " " << a.x << " " << a.y << " " << a.z);
      if (s->material_names[m] == "red") CHECK((a.x > 0.4f && a.y < 0.1f && a.z < 0.1f));
      if (s->material_names[m] == "green") CHECK((a.y > 0.3f && a.x < 0.15f && a.z < 0.15f));
      if (s->material_names[m] == "white") CHECK(near(a, glm::vec3(0.74f), 0.03f));
      if (glm::any(glm::greaterThan(emission(s->materials[m]), glm::vec3(0.0f))))
        CHECK(near(emission(s->materials[m]), {20.714f, 10.854f, 2.771f}, 1e-2f));
    }
    // The luminaire is moved 0.5 down from the ceiling (y = 548.8).
    for (size_t t = 0; t < s->triangles.size(); ++t) {
      if (!glm::any(glm::greaterThan(emission(s->materials[s->tri_material[t]]), glm::vec3(0.0f)))) continue;
      for (int k = 0; k < 3; ++k) CHECK(s->positions[s->triangles[t][k]].y == Approx(548.3f));
    }
  }
  SECTION("living-room (Mitsuba 0.5)") {
    std::optional<psf::Scene> s = load_if_present("scenes/living-room/scene.xml");
    if (!s) return;
    CHECK(s->triangles.size() == 143163);
    CHECK(s->width == 1280);
    CHECK(s->height == 720);
    CHECK(s->max_depth == 65);
    CHECK(s->camera.fov_degrees == Approx(90.0f));
    CHECK_FALSE(s->camera.mirrored);
    REQUIRE(s->lights.size() == 1);  // the envmap, 2048x1024, rotated about +y
    CHECK(s->lights[0].type == psf::LightType::Envmap);
    CHECK(s->lights[0].width == 2048);
    CHECK(s->lights[0].height == 1024);
    CHECK(count_warnings(*s, "bsdf") == 0);  // every BSDF and texture is supported
    CHECK(count_warnings(*s, "texture") == 0);
    for (size_t m = 0; m < s->materials.size(); ++m) {
      const Material& mat = s->materials[m];
      if (s->material_names[m] == "Leaves") {  // mask of a diffuse leaf texture, opacity from its alpha
        CHECK((mat.flags & PSF_MATFLAG_MASKED) != 0u);
        CHECK(mat.tex_opacity != PSF_NO_TEXTURE);
        CHECK(mat.tex_color != PSF_NO_TEXTURE);
      }
      if (s->material_names[m] == "Floor") CHECK(mat.type == PSF_MATERIAL_ROUGH_PLASTIC);
      if (s->material_names[m] == "Mirror") CHECK(mat.type == PSF_MATERIAL_CONDUCTOR);
      if (s->material_names[m] == "Glass") CHECK(mat.type == PSF_MATERIAL_DIELECTRIC);
    }
    CHECK(emissive_materials(*s) == 0);  // lit by the environment map only
  }
  SECTION("staircase (Mitsuba 0.5)") {
    std::optional<psf::Scene> s = load_if_present("scenes/staircase/scene.xml");
    if (!s) return;
    CHECK(s->triangles.size() == 262663);
    CHECK(s->width == 720);
    CHECK(s->height == 1280);
    CHECK(emissive_materials(*s) == 1);
    CHECK(count_warnings(*s, "bsdf") == 0);  // every BSDF and texture is supported
    CHECK(count_warnings(*s, "texture") == 0);
    REQUIRE(s->normals.size() == s->positions.size());  // the meshes' vn (faceNormals on most shapes)
    REQUIRE(s->uvs.size() == s->positions.size());
    for (size_t m = 0; m < s->materials.size(); ++m) {
      const Material& mat = s->materials[m];
      if (s->material_names[m] == "Gold") {
        CHECK(mat.type == PSF_MATERIAL_CONDUCTOR);
        CHECK(mat.eta.s[0] == Approx(0.143119f / 1.000277f));
      }
      if (s->material_names[m] == "WoodFloor") {
        CHECK(mat.type == PSF_MATERIAL_ROUGH_PLASTIC);
        CHECK(mat.two_sided == 1u);
        CHECK(mat.tex_color != PSF_NO_TEXTURE);
        CHECK((mat.flags & PSF_MATFLAG_BECKMANN) == 0u);  // ggx
      }
      if (s->material_names[m] == "Brass") CHECK(mat.type == PSF_MATERIAL_ROUGH_CONDUCTOR);
    }
    for (const std::string& w : s->warnings) CHECK(w.find("scene.xml:") != std::string::npos);
  }
}

TEST_CASE("Textures: NaN and infinite texels read as 0, values beyond a half's range as 65504, with warnings", "[scene]") {
  psf::Scene scene;
  psf::detail::TextureStore store(scene);
  psf::detail::TextureDesc d;
  d.path = "hdr-emission.exr";
  const float inf = std::numeric_limits<float>::infinity();
  const std::vector<float> rgba = {std::nanf(""), 1.0f, -inf, 1.0f, 1e5f, 0.5f, -2e5f, 1.0f};
  const uint32_t t = store.pixels(d, 2, 1, rgba);
  const TextureInfo& info = scene.textures.at(t);
  auto texel = [&](size_t i, int c) {
    Imath::half h;
    h.setBits(scene.texels.at((size_t(info.offset) + i) * 4 + size_t(c)));
    return float(h);
  };
  CHECK(texel(0, 0) == 0.0f);
  CHECK(texel(0, 1) == 1.0f);
  CHECK(texel(0, 2) == 0.0f);
  CHECK(texel(1, 0) == 65504.0f);
  CHECK(texel(1, 1) == 0.5f);
  CHECK(texel(1, 2) == -65504.0f);
  CHECK(count_warnings(scene, "hdr-emission.exr: 2 texel values are NaN or infinite; read as 0") == 1);
  CHECK(count_warnings(scene, "hdr-emission.exr: 2 texel values exceed 65504") == 1);
}

TEST_CASE("Textures: texels are the halfs Imath rounds to, whatever the conversion and the textures before", "[scene]") {
  // Independent reference: Imath::half of each value, one at a time (beyond
  // the largest half, of 65504, as the store reads those). The store
  // converts in chunks (with F16C where the CPU has it) into an array that grows
  // as textures arrive; every texture's texels must stay where its offset says.
  psf::Scene scene;
  psf::detail::TextureStore store(scene);
  psf::detail::TextureDesc d;
  auto values = [](uint32_t seed, size_t n) {
    std::vector<float> v(n);
    uint32_t x = seed;
    for (size_t i = 0; i < n; ++i) {
      x = x * 1664525u + 1013904223u;
      // Exponents from half's subnormals to its largest, some exact ties
      // between two halves (11 significant bits and a half), some negative.
      float mant = 1.0f + float(x >> 9) / float(1u << 23);
      if (i % 7 == 0) mant = 1.0f + (float((x >> 20) | 1u) + 0.5f) / 2048.0f;  // a tie at 11 bits
      int e = int((x >> 3) % 42) - 26;
      v[i] = std::ldexp((x & 1u) ? -mant : mant, e);
    }
    return v;
  };
  const std::vector<float> a = values(1, 1031 * 4), b = values(2, 3 * 4), c = values(3, 2049 * 4);
  const uint32_t ta = store.pixels(d, 1031, 1, a), tb = store.pixels(d, 3, 1, b), tc = store.pixels(d, 2049, 1, c);
  size_t checked = 0, mismatched = 0;
  for (auto [t, v] : {std::pair{ta, &a}, std::pair{tb, &b}, std::pair{tc, &c}}) {
    const TextureInfo& info = scene.textures.at(t);
    for (size_t i = 0; i < v->size(); ++i) {
      const float x = (*v)[i];
      const uint16_t want = Imath::half(std::fabs(x) > 65504.0f ? std::copysign(65504.0f, x) : x).bits();
      mismatched += scene.texels.at(size_t(info.offset) * 4 + i) == want ? 0 : 1;
      ++checked;
    }
  }
  CHECK(checked == (1031 + 3 + 2049) * 4);
  CHECK(mismatched == 0);
}

TEST_CASE("Media: a shape's homogeneous interior and exterior media are its material's; others warn", "[scene]") {
  psf::Scene s = load_text(
      "<integrator type=\"volpath\"/>\n"
      "<sensor type=\"perspective\"><ref name=\"exterior\" id=\"fog\"/></sensor>\n"
      "<medium type=\"homogeneous\" id=\"ink\"><rgb name=\"sigma_t\" value=\"0.1, 0.5, 1\"/>"
      "<float name=\"scale\" value=\"2\"/><float name=\"albedo\" value=\"0\"/></medium>\n"
      "<medium type=\"homogeneous\" id=\"fog\"><float name=\"sigma_t\" value=\"0.3\"/>"
      "<phase type=\"hg\"><float name=\"g\" value=\"0.4\"/></phase></medium>\n"
      "<shape type=\"cube\"><bsdf type=\"dielectric\"/><ref name=\"interior\" id=\"ink\"/></shape>\n"
      "<shape type=\"cube\"><bsdf type=\"dielectric\"/><ref name=\"interior\" id=\"fog\"/></shape>\n"
      "<shape type=\"cube\"><bsdf type=\"dielectric\"/><ref name=\"exterior\" id=\"ink\"/></shape>\n"
      "<shape type=\"cube\"><bsdf type=\"dielectric\"/><medium type=\"heterogeneous\" name=\"interior\"/></shape>\n");
  INFO([&] {
    std::string all;
    for (const auto& w : s.warnings) all += w + "\n";
    return all;
  }());
  CHECK(count_warnings(s, ":9: medium 'heterogeneous' is not supported") == 1);
  CHECK(count_warnings(s, "around the camera") == 0);  // fog, the second cube's interior, holds it
  std::vector<glm::vec4> interiors;  // each cube's (12 triangles each)
  REQUIRE(s.tri_material.size() == 48);
  for (size_t t = 0; t < 48; t += 12) {
    const auto& in = s.materials[s.tri_material[t]].interior;
    interiors.emplace_back(in.s[0], in.s[1], in.s[2], in.s[3]);
  }
  CHECK(glm::length(interiors[0] - glm::vec4(0.2f, 1.0f, 2.0f, 1.0f)) < 1e-6f);  // scale x sigma_t
  CHECK(interiors[1] == glm::vec4(0.3f, 0.3f, 0.3f, 1.0f));                       // its extinction all the same
  CHECK(interiors[2] == glm::vec4(0.0f));                                          // only an exterior
  CHECK(interiors[3] == glm::vec4(0.0f));                                          // an unsupported type: none
  CHECK(s.warnings.size() == 1);
  // An exterior medium names a material whose interior it is (ink: the first cube's).
  CHECK(s.materials[s.tri_material[24]].exterior == s.tri_material[0] + 1);
  CHECK(s.materials[s.tri_material[0]].exterior == 0u);

  // A medium only outside shapes, and around the camera, gets a material of its
  // own that no triangle uses.
  psf::Scene outside = load_text(
      "<integrator type=\"volpath\"/>\n"
      "<medium type=\"homogeneous\" id=\"haze\"><float name=\"sigma_t\" value=\"0.25\"/></medium>\n"
      "<sensor type=\"perspective\"><ref name=\"medium\" id=\"haze\"/></sensor>\n"
      "<shape type=\"cube\"><bsdf type=\"dielectric\"/><ref name=\"exterior\" id=\"haze\"/></shape>\n");
  CHECK(outside.warnings.empty());
  REQUIRE(outside.camera_medium > 0u);
  const Material& haze = outside.materials.at(outside.camera_medium - 1);
  CHECK((haze.interior.s[0] == 0.25f && haze.interior.s[3] == 1.0f));
  CHECK(std::count(outside.tri_material.begin(), outside.tri_material.end(), outside.camera_medium - 1) == 0);
  CHECK(outside.materials[outside.tri_material[0]].exterior == outside.camera_medium);
  CHECK(s.camera_medium == s.tri_material[12] + 1);
  // The single-scattering albedo (Mitsuba 3's default 0.75) and the phase function's g.
  const auto& ink = s.materials[s.tri_material[0]].interior_albedo;
  const auto& fog = s.materials[s.tri_material[12]].interior_albedo;
  CHECK((ink.s[0] == 0.0f && ink.s[1] == 0.0f && ink.s[2] == 0.0f && ink.s[3] == 0.0f));
  CHECK((fog.s[0] == 0.75f && fog.s[1] == 0.75f && fog.s[2] == 0.75f && fog.s[3] == 0.4f));

  // Light samples pass a null boundary (kernels/raycast.cl): a point light
  // outside one is no cause for a warning. A null sphere keeps its analytic
  // form unless its normals point inwards (shadow rays' crossings take them
  // outwards): that one is tessellated.
  psf::Scene lit = load_text(
      "<integrator type=\"volpath\"/>\n"
      "<emitter type=\"point\"><point name=\"position\" x=\"0\" y=\"3\" z=\"0\"/></emitter>\n"
      "<shape type=\"sphere\"><bsdf type=\"null\"/><medium type=\"homogeneous\" name=\"interior\"/></shape>\n"
      "<shape type=\"sphere\"><boolean name=\"flip_normals\" value=\"true\"/><bsdf type=\"null\"/>\n"
      "  <medium type=\"homogeneous\" name=\"interior\"/></shape>\n");
  CHECK(lit.warnings.size() == 1);  // no sensor
  CHECK(lit.spheres.size() == 1);
  CHECK(!lit.triangles.empty());
  REQUIRE(!lit.tri_material.empty());
  CHECK((lit.materials[lit.tri_material[0]].flags & PSF_MATFLAG_NULL_BOUNDARY) != 0u);
  CHECK((lit.materials[lit.spheres[0].material].flags & PSF_MATFLAG_NULL_BOUNDARY) != 0u);

  // A null boundary (which rays skip) becomes a dielectric of relative index 1:
  // no reflection, no bending, but a hit that takes the path into the medium.
  psf::Scene null = load_text(
      "<integrator type=\"volpath\"/>\n"
      "<shape type=\"cube\"><bsdf type=\"null\"/><medium type=\"homogeneous\" name=\"interior\"/></shape>\n");
  CHECK(null.warnings.size() == 1);  // no sensor
  REQUIRE(!null.tri_material.empty());
  const Material& boundary = null.materials[null.tri_material[0]];
  CHECK(boundary.interior.s[3] == 1.0f);
  CHECK(boundary.type == PSF_MATERIAL_DIELECTRIC);
  CHECK(boundary.eta.s[0] == 1.0f);
  CHECK((boundary.flags & PSF_MATFLAG_MASKED) == 0u);

  // Mitsuba 0.5: sigmaA and sigmaS, their sum the extinction.
  psf::Scene old = load_text(
      "<integrator type=\"volpath\"/>\n"
      "<shape type=\"cube\"><bsdf type=\"dielectric\"/><medium type=\"homogeneous\" name=\"interior\">"
      "<rgb name=\"sigmaA\" value=\"0.5, 1, 2\"/><rgb name=\"sigmaS\" value=\"0, 0, 0\"/></medium></shape>\n",
      {}, "0.5.0");
  REQUIRE(!old.tri_material.empty());
  const auto& in = old.materials[old.tri_material[0]].interior;
  CHECK((in.s[0] == 0.5f && in.s[1] == 1.0f && in.s[2] == 2.0f && in.s[3] == 1.0f));
  CHECK(old.materials[old.tri_material[0]].interior_albedo.s[0] == 0.0f);  // sigmaS / sigmaT
  CHECK(count_warnings(old, "medium") == 0);

  // Mitsuba's path tracer (its default integrator too) leaves media out, and so does psf then.
  for (const std::string integrator : {"", "<integrator type=\"path\"/>\n"}) {
    psf::Scene plain = load_text(integrator + "<shape type=\"cube\"><bsdf type=\"dielectric\"/>"
                                              "<medium type=\"homogeneous\" name=\"interior\"/></shape>\n");
    CHECK(count_warnings(plain, "leaves media out, as Mitsuba's does") == 1);
    CHECK(plain.materials[plain.tri_material[0]].interior.s[3] == 0.0f);
  }
}
