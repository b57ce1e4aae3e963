// psf: the command line. `psf devices` lists OpenCL devices; `psf render SCENE`
// renders a scene to OpenEXR (and a PNG preview).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "cl/runtime.h"
#include "compare.h"
#include "image.h"
#include "render.h"
#include "scene/scene.h"
#include "scheduler.h"
#include "session.h"

namespace {

constexpr double kFloatMax = std::numeric_limits<float>::max();

// A path's extension in lower case (".png"), for checks of output names.
std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

// A validator for a floating-point option: a finite number in [lo, hi] (lo
// excluded when `open_lo`). CLI11's Range, PositiveNumber and NonNegativeNumber
// let "nan" through (every comparison with NaN is false) and name an unbounded
// range by 300 digits of DBL_MAX. hi = kFloatMax: unbounded, but finite as a float.
CLI::Validator finite_number(double lo, double hi, bool open_lo = false, bool is_float = true) {
  std::ostringstream what;
  what << "a number ";
  if (hi >= kFloatMax) what << (open_lo ? "> " : ">= ") << lo << " (and below 3.4e38)";
  else what << "in " << (open_lo ? "(" : "[") << lo << ", " << hi << "]";
  const std::string description = what.str();
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        const char* begin = text.c_str();
        char* end = nullptr;
        const double v = std::strtod(begin, &end);
        const bool parsed = end != begin && *end == '\0';
        if (!parsed || !std::isfinite(v) || v < lo || v > hi || (open_lo && v == lo))
          return "'" + text + "' is not " + description;
        if (is_float && v != 0.0 && std::fabs(v) < std::numeric_limits<float>::min())
          return "'" + text + "' is too small for a float (it would become 0)";
        return std::string();
      },
      description);
}

constexpr int kExitBadInput = 2;
constexpr int kExitFailure = 1;

std::string bytes_text(uint64_t b) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.2f GiB", double(b) / (1024.0 * 1024.0 * 1024.0));
  return buf;
}

int run_devices() {
  auto devices = psf::list_devices();
  int platform = -1;
  for (const auto& d : devices) {
    if (d.platform_index != platform) {
      platform = d.platform_index;
      std::cout << "Platform " << platform << ": " << d.platform << "\n";
    }
    std::cout << "  [" << d.index << "] " << d.name << " (" << d.type << ", " << d.version << ", driver "
              << d.driver << ")\n"
              << "      global memory " << bytes_text(d.global_mem) << ", max allocation "
              << bytes_text(d.max_alloc) << ", local memory " << d.local_mem / 1024 << " KiB, "
              << d.compute_units << " compute units\n";
  }
  return 0;
}

struct RenderArgs {
  std::string scene;                   // scene file
  std::string output;                  // EXR path; PNG beside it
  std::string device;                  // --device SPEC
  std::string filter = "psf";          // --filter
  std::string aov;                     // --aov list
  psf::FilterOptions fopt;             // path space filtering parameters
  bool albedo_threshold_given = false; // --albedo-threshold: with --demodulate, fopt.albedo_log2_tol
  std::string visibility_ray = "auto";  // --visibility-ray: auto, light or a length
  std::string foreshortening = "on";   // --foreshortening on|off
  std::vector<std::string> defines;    // -D name=value
  int spp = 0;                         // 0: the scene's sample count, else 16
  int width = 0, height = 0;           // 0: the scene's film
  int max_depth = -2;                  // -2: the scene's integrator
  uint32_t seed = 0;
  int emission_rays = 0;               // --emission-rays K
  bool stats = false, quiet = false, no_png = false;
  double time = 0;                     // --time seconds
  double checkpoint_seconds = 30;      // --checkpoint-seconds
  std::string memory_budget;           // --memory-budget
  std::string resume;                  // --resume EXR
  int batch_log2 = 0;                  // --batch-log2 (0: the default for the image)
  std::string path_kernels = "auto";   // --path-kernels
  std::string look_at;                 // --look-at ox,oy,oz,tx,ty,tz[,ux,uy,uz]
  float fov = 0;                       // --fov degrees; 0: the scene's
};

// The camera of --look-at and --fov in place of the scene's; a message for bad
// values, else empty.
std::string override_camera(const RenderArgs& a, psf::CameraDesc& cam) {
  if (!a.look_at.empty()) {
    std::vector<float> v;
    const char* p = a.look_at.c_str();
    while (*p) {
      char* end = nullptr;
      float x = std::strtof(p, &end);
      if (end == p || !std::isfinite(x)) return "--look-at " + a.look_at + ": expected numbers separated by commas";
      v.push_back(x);
      p = end;
      while (*p == ' ') ++p;
      if (*p == ',' && p[1]) ++p;
      else if (*p) return "--look-at " + a.look_at + ": expected numbers separated by commas";
    }
    if (v.size() != 6 && v.size() != 9)
      return "--look-at " + a.look_at + ": expected ox,oy,oz,tx,ty,tz (origin, target) or with ux,uy,uz (up)";
    glm::vec3 origin(v[0], v[1], v[2]), target(v[3], v[4], v[5]);
    glm::vec3 dir = target - origin;
    if (!(glm::length(dir) > 0.0f)) return "--look-at " + a.look_at + ": the origin and the target coincide";
    auto along = [&](glm::vec3 up) {
      return glm::length(glm::cross(glm::normalize(dir), up)) <= 1e-6f * glm::length(up);
    };
    glm::vec3 up = cam.up;
    if (v.size() == 9) {
      up = glm::vec3(v[6], v[7], v[8]);
      if (along(up)) return "--look-at " + a.look_at + ": the up direction is zero or along the view direction";
    } else {  // the scene's up where it is not along the view, else y, else z
      for (glm::vec3 u : {cam.up, glm::vec3(0, 1, 0), glm::vec3(0, 0, 1)})
        if (!along(u)) {
          up = u;
          break;
        }
    }
    cam.origin = origin;
    cam.target = target;
    cam.up = up;
    cam.mirrored = false;
  }
  if (a.fov > 0) {
    if (cam.orthographic) return "--fov: the scene's camera is orthographic";
    cam.fov_degrees = a.fov;
  }
  return "";
}

int run_render(const RenderArgs& a) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(a.scene, ec)) {
    std::cerr << "psf: " << a.scene << ": " << (ec ? ec.message() : std::string("no such file")) << "\n";
    return kExitBadInput;
  }
  std::vector<std::pair<std::string, std::string>> params;
  for (const auto& d : a.defines) {
    auto eq = d.find('=');
    if (eq == std::string::npos || eq == 0) {
      std::cerr << "psf: -D " << d << ": expected name=value\n";
      return kExitBadInput;
    }
    params.emplace_back(d.substr(0, eq), d.substr(eq + 1));
  }
  std::string out = a.output.empty() ? "out/" + fs::path(a.scene).stem().string() + ".exr" : a.output;
  std::string png = fs::path(out).replace_extension(".png").string();
  // The output is OpenEXR whatever its name: one named .png (whose preview
  // would overwrite it) or .jpg would be an OpenEXR file under another image
  // format's name. Other names (/dev/null, mktemp's tmp.XXXXXXXXXX) are taken as they are.
  const std::string ext = lower_extension(out);
  const std::vector<std::string> other_formats = {".png", ".jpg", ".jpeg", ".hdr", ".pfm", ".ppm", ".pgm", ".tga",
                                                  ".bmp", ".tif", ".tiff", ".webp", ".gif", ".rgbe", ".dds"};
  if (std::find(other_formats.begin(), other_formats.end(), ext) != other_formats.end()) {
    std::cerr << "psf: --output " << out << ": the output is the OpenEXR image"
              << (a.no_png ? "" : ", and its PNG preview goes beside it with the extension .png") << "; name it .exr\n";
    return kExitBadInput;
  }
  if (a.output.empty() && (fs::create_directories("out", ec), ec)) {
    std::cerr << "psf: cannot create the output folder out: " << ec.message() << "\n";
    return kExitBadInput;
  }
  // The output replaces its file at the end: never the scene file itself.
  for (const std::string& written : {out, png})
    if (fs::equivalent(written, a.scene, ec) && (written == out || !a.no_png)) {
      std::cerr << "psf: --output " << out << ": " << (written == out ? "the image" : "its PNG preview " + png)
                << " would replace the scene file " << a.scene << "\n";
      return kExitBadInput;
    }
  try {
    psf::check_writable(out);
    if (!a.no_png) psf::check_writable(png);
  } catch (const std::invalid_argument& e) {
    std::cerr << "psf: " << e.what() << "\n";
    return kExitBadInput;
  }

  psf::Scene scene;
  try {
    scene = psf::load_scene(a.scene, params);
  } catch (const psf::SceneError& e) {
    std::cerr << "psf: " << e.what() << "\n";
    return kExitBadInput;
  }
  if (!a.quiet)
    for (const auto& w : scene.warnings) std::cerr << "psf: warning: " << w << "\n";
  psf::set_film_size(scene, a.width, a.height);
  if (std::string bad = override_camera(a, scene.camera); !bad.empty()) {
    std::cerr << "psf: " << bad << "\n";
    return kExitBadInput;
  }
  // The film's per-pixel sums alone take 40 bytes a pixel on the host: refuse
  // sizes that cannot be held rather than fail in an allocation mid-render.
  constexpr int kMaxFilmSide = 65536;
  constexpr uint64_t kMaxFilmPixels = uint64_t(1) << 27;
  // With a crop window the film it cuts from is held to the same limits (its
  // pixel indices key the samples, kernels/camera.cl).
  const int film_w = std::max(scene.width, scene.camera.film_width);
  const int film_h = std::max(scene.height, scene.camera.film_height);
  if (scene.width <= 0 || scene.height <= 0 || film_w > kMaxFilmSide || film_h > kMaxFilmSide ||
      uint64_t(film_w) * uint64_t(film_h) > kMaxFilmPixels) {
    std::cerr << "psf: " << a.scene << ": film " << film_w << "x" << film_h
              << " is out of range (each side 1 to " << kMaxFilmSide << ", at most " << kMaxFilmPixels
              << " pixels); set --width and --height\n";
    return kExitBadInput;
  }

  uint64_t memory_budget = 0;
  if (!a.memory_budget.empty()) {
    try {
      memory_budget = psf::parse_bytes(a.memory_budget);
    } catch (const std::invalid_argument& e) {
      std::cerr << "psf: --memory-budget: " << e.what() << "\n";
      return kExitBadInput;
    }
  }
  if (!a.resume.empty()) {
    try {
      psf::read_exr_file(a.resume);
    } catch (const std::exception& e) {
      std::cerr << "psf: " << e.what() << "\n";
      return kExitBadInput;
    }
  }
  psf::RenderOptions opt;
  opt.spp = a.spp > 0 ? a.spp : (scene.default_spp > 0 ? scene.default_spp : 16);
  opt.seed = a.seed;
  opt.emission_rays = a.emission_rays;
  const std::string& kernels = a.path_kernels;  // auto, wavefront, per-path or lanes
  opt.per_path = kernels == "auto" ? -1 : kernels == "wavefront" ? 0 : 1;
  opt.lanes = kernels == "auto" ? -1 : kernels == "lanes" ? 1 : 0;
  opt.max_depth = a.max_depth >= -1 ? a.max_depth : scene.max_depth;
  opt.rr_depth = scene.rr_depth;
  opt.filter = a.fopt;
  if (a.fopt.demodulate && a.albedo_threshold_given) opt.filter.albedo_log2_tol = a.fopt.albedo_tol;
  opt.filter.visibility_ray = a.visibility_ray == "auto"    ? psf::kVisibilityRayAuto
                              : a.visibility_ray == "light" ? 0.0f
                              : a.visibility_ray == "off"   ? psf::kVisibilityRayOff
                                                            : float(std::strtod(a.visibility_ray.c_str(), nullptr));
  opt.filter.enabled = a.filter == "psf";
  opt.filter.foreshortening = a.foreshortening == "on";
  bool aov_unfiltered = false, aov_neighbours = false, aov_albedo = false, aov_normal = false, aov_depth = false;
  for (size_t b = 0; b <= a.aov.size();) {
    size_t e = a.aov.find(',', b);
    if (e == std::string::npos) e = a.aov.size();
    std::string name = a.aov.substr(b, e - b);
    if (name == "unfiltered") aov_unfiltered = true;
    else if (name == "neighbours") aov_neighbours = true;
    else if (name == "albedo") aov_albedo = true;
    else if (name == "normal") aov_normal = true;
    else if (name == "depth") aov_depth = true;
    else if (!name.empty()) {
      std::cerr << "psf: --aov " << name << ": unknown layer (unfiltered, neighbours, albedo, normal, depth)\n";
      return kExitBadInput;
    }
    b = e + 1;
  }

  psf::SessionOptions so;
  so.render = opt;
  so.render.spp = a.spp > 0 ? a.spp : (a.time > 0 ? 0 : opt.spp);
  so.scene_path = a.scene;
  so.params = params;
  // A resumed render must have the same camera: the overrides join the scene's
  // hash, as the camera they give (so "1,2" and "1, 2.0" are the same).
  if (!a.look_at.empty()) {
    const psf::CameraDesc& c = scene.camera;
    char text[256];
    std::snprintf(text, sizeof text, "%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g", c.origin.x, c.origin.y,
                  c.origin.z, c.target.x, c.target.y, c.target.z, c.up.x, c.up.y, c.up.z);
    so.params.emplace_back("--look-at", text);
  }
  if (a.fov > 0) so.params.emplace_back("--fov", std::to_string(a.fov));
  so.device = a.device;
  so.time_limit = a.time;
  so.checkpoint_seconds = a.checkpoint_seconds;
  so.memory_budget = memory_budget;
  so.max_batch_log2 = a.batch_log2;
  so.output = out;
  so.png = a.no_png ? "" : png;
  so.resume = a.resume;
  so.aov_unfiltered = aov_unfiltered;
  so.aov_neighbours = aov_neighbours;
  so.aov_albedo = aov_albedo;
  so.aov_normal = aov_normal;
  so.aov_depth = aov_depth;
  so.quiet = a.quiet;
  so.stats = a.stats;
  psf::SessionResult r = psf::run_session(scene, so);
  if (!a.quiet) {
    std::cerr << "psf: " << r.paths << " paths (" << double(r.paths) / double(uint64_t(scene.width) * scene.height)
              << " spp) in " << r.seconds << " s, " << r.paths / std::max(r.seconds, 1e-9) / 1e6
              << " M paths/s; device time: tracing " << r.trace_ms / 1000 << " s, filtering " << r.filter_ms / 1000
              << " s; wrote " << out << (a.no_png ? "" : " and " + png) << "\n";
    if (r.nonfinite) std::cerr << "psf: warning: " << r.nonfinite << " paths had NaN/Inf radiance and were left out\n";
    if (r.interrupted) std::cerr << "psf: interrupted: the image holds every finished batch\n";
  }
  if (r.interrupted) return 128 + r.signal;
  return 0;
}

// `psf compare TEST REFERENCE`: relMSE, MSE, MAE and MAPE (the reference
// box-filtered to the test's size when it is an integer multiple of it) and
// block luminance statistics.
// With `diff_path`, also a PNG of the two images and the blocks' errors
// (psf::comparison_picture) at full colour for +-diff_range.
int run_compare(const std::string& test_path, const std::string& ref_path, int blocks_x, int blocks_y,
                const std::string& diff_path, double diff_range) {
  namespace fs = std::filesystem;
  if (!diff_path.empty()) {  // checked before the work, as render checks -o
    if (lower_extension(diff_path) != ".png") throw std::invalid_argument("--diff " + diff_path + ": the picture is a PNG file (.png)");
    std::error_code ec;
    for (const std::string& input : {test_path, ref_path})
      if (fs::equivalent(diff_path, input, ec))
        throw std::invalid_argument("--diff " + diff_path + ": would overwrite the image " + input);
    psf::check_writable(diff_path);
  }
  // An input that is not a readable OpenEXR image is bad input (exit 2), as for render.
  auto read = [](const std::string& path) {
    try {
      return psf::read_exr(path);
    } catch (const std::runtime_error& e) {
      throw std::invalid_argument(e.what());
    }
  };
  psf::Image test = read(test_path), ref = read(ref_path);
  std::printf("test %s: %dx%d; reference %s: %dx%d\n", test_path.c_str(), test.width, test.height, ref_path.c_str(),
              ref.width, ref.height);
  psf::Image ref_at_test = ref;
  bool same = test.width == ref.width && test.height == ref.height;
  if (!same && ref.width % test.width == 0 && ref.height % test.height == 0 &&
      ref.width / test.width == ref.height / test.height) {
    ref_at_test = psf::box_downsample(ref, test.width, test.height);
    const psf::ErrorMetrics e = psf::error_metrics(test, ref_at_test);
    std::printf("relMSE: %.6g (reference box-filtered %dx down to the test's size)\n", e.rel_mse,
                ref.width / test.width);
    std::printf("MSE: %.6g, MAE: %.6g, MAPE: %.6g %%\n", e.mse, e.mae, 100.0 * e.mape);
  } else if (same) {
    const psf::ErrorMetrics e = psf::error_metrics(test, ref);
    std::printf("relMSE: %.6g\n", e.rel_mse);
    std::printf("MSE: %.6g, MAE: %.6g, MAPE: %.6g %%\n", e.mse, e.mae, 100.0 * e.mape);
  } else {
    std::printf("relMSE: not computed (the reference is not an integer multiple of the test's size)\n");
  }
  if (blocks_x <= 0 || blocks_y <= 0) psf::default_grid(ref, blocks_x, blocks_y);
  const psf::BlockStats stats = psf::block_stats(test, ref, blocks_x, blocks_y);
  std::printf("%s", psf::describe(stats).c_str());
  if (!diff_path.empty()) {
    const float exposure = psf::auto_exposure(ref);
    psf::write_png(diff_path, psf::comparison_picture(test, ref, stats, diff_range / 100.0, exposure));
    std::printf("wrote %s: test | reference (exposure %.3g) | block errors, full colour at +-%g %%\n",
                diff_path.c_str(), exposure, diff_range);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"psf: consistent path space filtering on OpenCL"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("psf ") + PSF_VERSION);

  CLI::App* devices = app.add_subcommand("devices", "List OpenCL platforms and devices");

  std::string compare_test, compare_ref, compare_grid;
  CLI::App* compare = app.add_subcommand("compare", "Compare a render with a reference (OpenEXR): relMSE and block luminance");
  compare->add_option("test", compare_test, "The render (.exr)")->required()->check(CLI::ExistingFile);
  compare->add_option("reference", compare_ref, "The reference (.exr)")->required()->check(CLI::ExistingFile);
  compare->add_option("--blocks", compare_grid, "Block grid WxH (default 16x9, or 9x16 for portrait images)");
  std::string compare_diff;
  double compare_range = 10.0;
  compare->add_option("--diff", compare_diff,
                      "Also write a PNG: the test, the reference and the blocks' signed relative errors (red: test "
                      "brighter, blue: darker)");
  compare->add_option("--diff-range", compare_range, "Percent error drawn at full colour in --diff's block map (10)")
      ->check(finite_number(0.0, kFloatMax, true));

  RenderArgs ra;
  CLI::App* render = app.add_subcommand("render", "Render a scene (Mitsuba XML, OBJ, PLY or glTF) to OpenEXR and PNG");
  render->add_option("scene", ra.scene, "Scene file (.xml, .obj, .ply, .gltf, .glb); mesh files without emitters get a default sky")->required();
  render->add_option("-o,--output", ra.output,
                     "Output OpenEXR file, not named as another image format (default out/<scene>.exr); a PNG is "
                     "written beside it");
  render->add_option("--spp", ra.spp, "Samples per pixel (default: the scene's, else 16)")->check(CLI::PositiveNumber);
  render->add_option("--width", ra.width, "Image width (default: the scene's film)")->check(CLI::Range(1, 65536));
  render->add_option("--height", ra.height, "Image height (default: the scene's film)")->check(CLI::Range(1, 65536));
  render->add_option("--look-at", ra.look_at,
                     "Camera origin and target, with an up direction or not: ox,oy,oz,tx,ty,tz[,ux,uy,uz] "
                     "(default: the scene's camera; OBJ, PLY: one framing the bounds)");
  render->add_option("--fov", ra.fov,
                     "Field of view in degrees along the scene camera's fov axis (default: the scene's)")
      ->check(finite_number(0.01, 179.0));
  render->add_option("--max-depth", ra.max_depth, "Longest path in segments, -1 unbounded (default: the scene's)")
      ->check(CLI::Range(-1, 1 << 16));
  render->add_option("--seed", ra.seed, "Sampling seed: the image is a deterministic function of it");
  render->add_option("--device", ra.device, "Device index or name substring (default: first GPU, else CPU)");
  render->add_option("--emission-rays", ra.emission_rays,
                     "K more camera rays per path that only add the emission they see (lights, the sky): the "
                     "edges of lights and windows get (K + 1) times the samples, filtered or not (0)")
      ->check(CLI::Range(0, 64));
  render->add_option("--filter", ra.filter, "psf: path space filtering (default); off: plain path tracing")
      ->check(CLI::IsMember({"psf", "off"}));
  render->add_option("--alpha", ra.fopt.alpha, "Radius exponent: r(n) = r0 / n^alpha, n paths per pixel so far (0.25)")
      ->check(finite_number(0.0, 1.0));
  render->add_option("--r0", ra.fopt.r0, "Global initial radius in scene units (default: per vertex from --footprint-pixels)")
      ->check(finite_number(0.0, kFloatMax));
  render->add_option("--footprint-pixels", ra.fopt.footprint_pixels,
                     "r0 covers the solid angle of N x N pixels at the vertex's distance (3)")
      ->check(finite_number(0.01, 1000.0));
  render->add_option("--foreshortening", ra.foreshortening,
                     "on (default): r0 grows by 1/sqrt(cos theta) where a vertex is seen at an angle theta (at most "
                     "2x), so that the ball holds the surface the N x N pixels see; off: the solid angle's radius")
      ->check(CLI::IsMember({"on", "off"}));
  render->add_option("--iterations", ra.fopt.iterations, "Averaging passes, each over the previous result (1)")
      ->check(CLI::Range(1, 64));
  render->add_option("--normal-threshold", ra.fopt.normal_cos, "Similar vertices: <n_i, n_j> >= this (0.95)")
      ->check(finite_number(-1.0, 1.0));
  render
      ->add_option("--albedo-threshold", ra.fopt.albedo_tol,
                   "Similar vertices: |albedo_i - albedo_j| <= this (0.05); with --demodulate "
                   "|log2 albedo_i - log2 albedo_j| <= this (1)")
      ->check(finite_number(0.0, kFloatMax));
  render->add_option("--visibility-ray", ra.visibility_ray,
                     "Similar vertices agree on: LENGTH, whether one hemisphere ray of this length (scene units) "
                     "hits something; light, their light sample's visibility; auto (default): a ray of 1 % of the "
                     "scene's size where the only light is an environment, else light; off: they need not agree "
                     "(no shadow edge stops the average; penumbrae lose their light samples' noise)")
      ->check(CLI::IsMember({"auto", "light", "off"}) | finite_number(0.0, kFloatMax, true));
  render->add_flag("--demodulate", ra.fopt.demodulate,
                   "Texture-preserving averaging: of c / albedo, times the vertex's own albedo, over neighbours "
                   "whose albedo differs by a ratio (--albedo-threshold in log2 units)");
  render->add_flag("--cells27", ra.fopt.cells27,
                   "Neighbour search in cells of size r (3x3 rows along x) instead of 2r (2x2 rows)");
  render->add_option("--min-removed", ra.fopt.min_removed,
                     "Filtering switches itself off after a batch where it removed less than this fraction of the "
                     "noise; 0: only when no vertex has a neighbour (0.2)")
      ->check(finite_number(0.0, 1.0));
  render->add_option("--aov", ra.aov,
                     "Extra EXR layers, comma-separated: unfiltered, neighbours, albedo, normal, depth");
  render->add_option("-D,--define", ra.defines, "Scene parameter name=value ($name in Mitsuba XML)");
  render->add_option("--time", ra.time, "Render until this many seconds have passed (with --spp: whichever comes first)")
      ->check(finite_number(0.0, kFloatMax, true, false));
  render->add_option("--checkpoint-seconds", ra.checkpoint_seconds,
                     "Rewrite the output (atomically) this often while rendering; 0: only at the end (30)")
      ->check(finite_number(0.0, kFloatMax, false, false));
  render->add_option("--memory-budget", ra.memory_budget, "Device memory for the batch buffers, e.g. 256M, 2G");
  render
      ->add_option("--batch-log2", ra.batch_log2,
                   "Largest batch: 2^N paths (default: the smallest holding 4 spp of the image, 2^20 to 2^22)")
      ->check(CLI::Range(6, 26));
  render->add_option("--path-kernels", ra.path_kernels,
                     "wavefront: a kernel per stage over the live paths; per-path: each path in one work-item; "
                     "lanes: eight paths per work-item in vector lanes, for scenes without media (others: "
                     "per-path); auto: on CPU devices lanes where the scene allows, else per-path for scenes "
                     "without an environment map, else wavefront "
                     "(lanes: the same image up to float rounding)")
      ->check(CLI::IsMember({"auto", "wavefront", "per-path", "lanes"}));
  render->add_option("--resume", ra.resume, "Continue the render saved in this EXR (same scene and options) to --spp")
      ->check(CLI::ExistingFile);
  render->add_flag("--stats", ra.stats, "Print device time per kernel");
  render->add_flag("-q,--quiet", ra.quiet, "Print nothing but errors");
  render->add_flag("--no-png", ra.no_png, "Do not write the PNG preview");

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "psf: " << e.what() << "\nRun `psf --help` or `psf render --help` for usage.\n";
    return kExitBadInput;
  }
  try {
    if (devices->parsed()) return run_devices();
    if (compare->parsed()) {
      int bx = 0, by = 0;
      if (!compare_grid.empty() && (std::sscanf(compare_grid.c_str(), "%dx%d", &bx, &by) != 2 || bx <= 0 || by <= 0)) {
        std::cerr << "psf: --blocks " << compare_grid << ": expected WxH, e.g. 16x9\n";
        return kExitBadInput;
      }
      if (compare->count("--diff") > 0 && compare_diff.empty()) {
        std::cerr << "psf: --diff needs a file name (.png)\n";
        return kExitBadInput;
      }
      return run_compare(compare_test, compare_ref, bx, by, compare_diff, compare_range);
    }
    ra.albedo_threshold_given = render->count("--albedo-threshold") > 0;
    return run_render(ra);
  } catch (const psf::NoDeviceError& e) {
    std::cerr << "psf: " << e.what() << "\n";
    return kExitFailure;
  } catch (const std::invalid_argument& e) {
    std::cerr << "psf: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const std::filesystem::filesystem_error& e) {  // a path given that the system refuses
    std::cerr << "psf: " << e.path1().string() << ": " << e.code().message() << "\n";
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << "psf: " << e.what() << "\n";
    return kExitFailure;
  }
}
