#include "image.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <ImfStringAttribute.h>
#include <stb_image_write.h>
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <stdexcept>

namespace psf {
namespace fs = std::filesystem;

namespace {

// An existing output that is neither a file nor a folder: a device or a pipe
// (/dev/null), which the bytes go into rather than a rename replacing it.
bool is_special(const fs::path& path) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);  // through symbolic links
  return !ec && fs::exists(st) && !fs::is_regular_file(st) && !fs::is_directory(st);
}

// Where an output's bytes go: the file a symbolic link names (the link stays),
// else the path itself.
std::string output_target(const std::string& path) {
  std::error_code ec;
  if (!fs::is_symlink(fs::symlink_status(path, ec))) return path;
  fs::path target = fs::weakly_canonical(path, ec);
  return ec ? path : target.string();
}

// A temporary name in the target's folder, so the final rename is atomic (a
// device's bytes are staged in the temporary folder instead).
std::string temp_name(const std::string& path) {
  std::random_device rd;
  fs::path p(path);
  fs::path dir = is_special(p) ? fs::temp_directory_path() : p.parent_path();
  return (dir / ("." + p.filename().string() + ".tmp" + std::to_string(rd() % 1000000))).string();
}

// Writes all of `data` to the open descriptor `fd` and closes it; false on any error.
bool write_all(int fd, const unsigned char* data, size_t size) {
  bool ok = fd >= 0;
  for (size_t done = 0; ok && done < size;) {
    ssize_t n = ::write(fd, data + done, size - done);
    if (n < 0 && errno == EINTR) continue;
    ok = n > 0;
    if (ok) done += size_t(n);
  }
  if (fd >= 0 && ::close(fd) != 0) ok = false;
  return ok;
}

// Replaces `path` by the finished temporary file `tmp` (a rename: readers see the
// old file or the new one, never a part), or for a device copies the bytes into it.
void commit(const std::string& tmp, const std::string& path) {
  std::error_code ec;
  if (is_special(path)) {
    std::ifstream in(tmp, std::ios::binary);
    std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const int saved = [&] {
      errno = 0;
      return write_all(::open(path.c_str(), O_WRONLY), bytes.data(), bytes.size()) ? 0 : (errno ? errno : EIO);
    }();
    fs::remove(tmp, ec);
    if (saved) throw std::runtime_error(path + ": cannot write: " + std::strerror(saved));
    return;
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw std::runtime_error(path + ": cannot replace the file: " + ec.message());
  }
}

float srgb_encode(float x) {
  x = std::clamp(std::isfinite(x) ? x : 0.0f, 0.0f, 1.0f);
  return x <= 0.0031308f ? 12.92f * x : 1.055f * std::pow(x, 1.0f / 2.4f) - 0.055f;
}

// A data window psf could have written (each side 1 to 65536, at most 2^28 pixels);
// a corrupt header would otherwise ask for any amount of memory.
void check_size(int64_t width, int64_t height) {
  if (width <= 0 || height <= 0 || width > 65536 || height > 65536 || width * height > (int64_t(1) << 28))
    throw std::runtime_error("data window " + std::to_string(width) + "x" + std::to_string(height) + " out of range");
}

// The data window of an open file, its size checked (check_size), and its size.
Imath::Box2i data_window(const Imf::InputFile& file, int& width, int& height) {
  Imath::Box2i dw = file.header().dataWindow();
  check_size(int64_t(dw.max.x) - dw.min.x + 1, int64_t(dw.max.y) - dw.min.y + 1);
  width = dw.max.x - dw.min.x + 1;
  height = dw.max.y - dw.min.y + 1;
  return dw;
}

}  // namespace

void check_writable(const std::string& path_in) {
  const std::string path = output_target(path_in);
  fs::path p(path);
  if (is_special(p)) {  // a device or pipe: written into, not replaced
    if (access(path.c_str(), W_OK) != 0) throw std::invalid_argument(path_in + ": not writable");
    return;
  }
  if (p.filename().empty()) throw std::invalid_argument(path + ": output path names a folder, not a file");
  std::error_code ec;  // a name the system refuses (too long, a loop of links): its reason
  if (fs::is_directory(p, ec)) throw std::invalid_argument(path + ": output path is a folder");
  fs::path dir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
  if (!fs::is_directory(dir, ec))
    throw std::invalid_argument(path + ": folder " + dir.string() +
                                (ec && ec != std::errc::no_such_file_or_directory ? ": " + ec.message()
                                                                                  : std::string(" does not exist")));
  if (access(dir.c_str(), W_OK) != 0) throw std::invalid_argument(path + ": folder " + dir.string() + " is not writable");
  // access() says yes to root and on read-only file systems: create (and remove) the
  // temporary file a write would use, so the check is the write's own.
  std::string probe = temp_name(path);
  int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0600);
  if (fd < 0) throw std::invalid_argument(path + ": cannot create a file in folder " + dir.string() + ": " + std::strerror(errno));
  ::close(fd);
  ::unlink(probe.c_str());
}

void write_exr(const std::string& path_in, const Image& image, const std::map<std::string, std::string>& attributes,
               const std::vector<ExrLayer>& layers) {
  const std::string path = output_target(path_in);
  std::string tmp = temp_name(path);
  try {
    Imf::Header header(image.width, image.height);
    for (const char* c : {"R", "G", "B"}) header.channels().insert(c, Imf::Channel(Imf::FLOAT));
    for (const auto& [k, v] : attributes) header.insert(k, Imf::StringAttribute(v));
    for (const auto& l : layers) {
      if (l.data.size() != size_t(image.width) * image.height * l.channels)
        throw std::invalid_argument("layer " + l.name + " has the wrong size");
      for (const char* c : {"R", "G", "B", "Y"})
        if ((l.channels == 1) == (c[0] == 'Y')) header.channels().insert(l.name + "." + c, Imf::Channel(Imf::FLOAT));
    }
    Imf::OutputFile file(tmp.c_str(), header);
    Imf::FrameBuffer fb;
    char* base = reinterpret_cast<char*>(const_cast<float*>(image.rgb.data()));
    size_t xs = 3 * sizeof(float), ys = xs * image.width;
    fb.insert("R", Imf::Slice(Imf::FLOAT, base, xs, ys));
    fb.insert("G", Imf::Slice(Imf::FLOAT, base + sizeof(float), xs, ys));
    fb.insert("B", Imf::Slice(Imf::FLOAT, base + 2 * sizeof(float), xs, ys));
    for (const auto& l : layers) {
      char* lb = reinterpret_cast<char*>(const_cast<float*>(l.data.data()));
      size_t lxs = l.channels * sizeof(float), lys = lxs * image.width;
      if (l.channels == 1) {
        fb.insert(l.name + ".Y", Imf::Slice(Imf::FLOAT, lb, lxs, lys));
      } else {
        fb.insert(l.name + ".R", Imf::Slice(Imf::FLOAT, lb, lxs, lys));
        fb.insert(l.name + ".G", Imf::Slice(Imf::FLOAT, lb + sizeof(float), lxs, lys));
        fb.insert(l.name + ".B", Imf::Slice(Imf::FLOAT, lb + 2 * sizeof(float), lxs, lys));
      }
    }
    file.setFrameBuffer(fb);
    file.writePixels(image.height);
  } catch (const std::exception& e) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw std::runtime_error(path + ": cannot write OpenEXR file: " + e.what());
  }
  commit(tmp, path);
}

Image read_exr(const std::string& path) {
  try {
    Imf::InputFile file(path.c_str());
    Image img;
    Imath::Box2i dw = data_window(file, img.width, img.height);
    img.rgb.assign(size_t(img.width) * img.height * 3, 0.0f);
    // Slice::Make offsets the pointer by the data window's origin itself (a
    // pointer computed here before the array's start is undefined behaviour,
    // which the resume fuzzer's sanitizer reported for a window far from 0).
    size_t xs = 3 * sizeof(float), ys = xs * img.width;
    Imf::FrameBuffer fb;
    fb.insert("R", Imf::Slice::Make(Imf::FLOAT, img.rgb.data(), dw, xs, ys));
    fb.insert("G", Imf::Slice::Make(Imf::FLOAT, img.rgb.data() + 1, dw, xs, ys));
    fb.insert("B", Imf::Slice::Make(Imf::FLOAT, img.rgb.data() + 2, dw, xs, ys));
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    return img;
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": cannot read OpenEXR file: " + e.what());
  }
}

ExrFile read_exr_file(const std::string& path) {
  try {
    Imf::InputFile file(path.c_str());
    ExrFile out;
    Imath::Box2i dw = data_window(file, out.width, out.height);
    for (auto it = file.header().begin(); it != file.header().end(); ++it)
      if (const auto* a = dynamic_cast<const Imf::StringAttribute*>(&it.attribute())) out.attributes[it.name()] = a->value();
    Imf::FrameBuffer fb;
    const size_t n = size_t(out.width) * out.height;
    for (auto c = file.header().channels().begin(); c != file.header().channels().end(); ++c) {
      if (c.channel().xSampling != 1 || c.channel().ySampling != 1)
        throw std::runtime_error(std::string("channel ") + c.name() + " is subsampled (not written by psf)");
      std::vector<float>& data = out.channels[c.name()];
      data.assign(n, 0.0f);
      fb.insert(c.name(), Imf::Slice::Make(Imf::FLOAT, data.data(), dw, sizeof(float), sizeof(float) * out.width));
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    return out;
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": cannot read OpenEXR file: " + e.what());
  }
}

void write_png(const std::string& path_in, const Image& image, float exposure) {
  const std::string path = output_target(path_in);
  std::vector<uint8_t> px(size_t(image.width) * image.height * 3);
  for (size_t i = 0; i < px.size(); ++i)
    px[i] = uint8_t(std::lround(255.0f * srgb_encode(image.rgb[i] * exposure)));
  // Encoded in memory and written here, where every write and the close are
  // checked (stbi_write_png ignores a full disk, and would leave a cut-off file).
  std::vector<unsigned char> png;
  auto append = [](void* context, void* data, int size) {
    auto* out = static_cast<std::vector<unsigned char>*>(context);
    out->insert(out->end(), static_cast<unsigned char*>(data), static_cast<unsigned char*>(data) + size);
  };
  if (!stbi_write_png_to_func(append, &png, image.width, image.height, 3, px.data(), image.width * 3))
    throw std::runtime_error(path + ": cannot encode PNG image");
  std::string tmp = temp_name(path);
  errno = 0;
  const bool ok = write_all(::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644), png.data(), png.size());
  const int err = errno;
  if (!ok) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw std::runtime_error(path + ": cannot write PNG file: " + std::strerror(err ? err : EIO));
  }
  commit(tmp, path);
}

}  // namespace psf
