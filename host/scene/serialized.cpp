// Mitsuba's .serialized meshes (Mitsuba 0.5's and Mitsuba 3's `serialized`
// shape): read with zlib, every count checked against the data before use.
//
// Layout (little endian): uint16 0x041C, uint16 version (3 or 4), then a zlib
// stream holding uint32 flags (0x0001 normals, 0x0002 uvs, 0x0008 colours,
// 0x0010 face normals, 0x2000 double precision), the name as a NUL-terminated
// string (version 4 only), uint64 vertex count, uint64 triangle count, the
// positions (x, y, z per vertex), the normals, uvs (u, v) and colours (r, g, b)
// where the flags say so, then the triangles as uint32 vertex indices. Files
// with several meshes concatenate these (each with its own header); the file
// ends with each mesh's offset (uint64 in version 4, uint32 in version 3) and
// the number of meshes (uint32).
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>

#include "scene/formats.h"
#include "scene/loaders.h"

namespace psf::detail {
namespace {

constexpr uint16_t kMagic = 0x041C;
constexpr uint32_t kNormals = 0x0001, kUvs = 0x0002, kColours = 0x0008, kFaceNormals = 0x0010, kDouble = 0x2000;

template <class T>
T read_le(const unsigned char* p) {
  T v = 0;
  for (size_t i = 0; i < sizeof(T); ++i) v |= T(p[i]) << (8 * i);
  return v;
}

// The zlib stream starting at data[begin], decompressed on demand.
class Inflater {
 public:
  Inflater(const std::string& path, const std::string& data, size_t begin) : path_(path) {
    if (inflateInit(&z_) != Z_OK) throw SceneError(path, 0, "zlib: cannot start decompression");
    z_.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data() + begin));
    z_.avail_in = uInt(std::min<size_t>(data.size() - begin, std::numeric_limits<uInt>::max()));
  }
  ~Inflater() { inflateEnd(&z_); }
  Inflater(const Inflater&) = delete;
  Inflater& operator=(const Inflater&) = delete;

  // The compressed bytes not read yet.
  size_t compressed_left() const { return z_.avail_in; }

  // Appends the next n bytes of the stream to `out`; throws if the stream ends
  // first or is corrupt.
  void read(std::vector<unsigned char>& out, size_t n, const std::string& what) {
    const size_t start = out.size();
    out.resize(start + n);
    size_t done = 0;
    while (done < n) {
      const size_t chunk = std::min<size_t>(n - done, std::numeric_limits<uInt>::max());
      z_.next_out = out.data() + start + done;
      z_.avail_out = uInt(chunk);
      const int status = inflate(&z_, Z_NO_FLUSH);
      done += chunk - z_.avail_out;
      if (done == n) break;
      if (status != Z_OK) {
        std::string why = status == Z_STREAM_END ? "the mesh's data ends in its " + what
                          : z_.msg             ? std::string("zlib: ") + z_.msg
                                               : "zlib: the data ends early";
        throw SceneError(path_, 0, "the mesh's compressed data cannot be read (" + why + ")");
      }
    }
  }

 private:
  std::string path_;
  z_stream z_{};
};

}  // namespace

SerializedMesh read_serialized(const std::string& path, int shape_index) {
  require_readable_input(path, "serialized mesh file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path, 0, "cannot open serialized mesh file");
  const std::string data = read_all(in);
  auto bytes = [&](size_t at) { return reinterpret_cast<const unsigned char*>(data.data() + at); };
  if (data.size() < 4 || read_le<uint16_t>(bytes(0)) != kMagic)
    throw SceneError(path, 0, "not a Mitsuba serialized mesh file (no 0x041C header)");
  const uint16_t version = read_le<uint16_t>(bytes(2));
  if (version != 3 && version != 4)
    throw SceneError(path, 0, "serialized mesh version " + std::to_string(version) + " is not supported (3 or 4)");
  if (shape_index < 0) throw SceneError(path, 0, "shape_index must not be negative");

  // The mesh's offset: 0 for the first, else from the dictionary at the end.
  size_t offset = 0;
  if (shape_index > 0) {
    if (data.size() < 8) throw SceneError(path, 0, "the file has no mesh dictionary");
    const uint32_t count = read_le<uint32_t>(bytes(data.size() - 4));
    if (uint32_t(shape_index) >= count)
      throw SceneError(path, 0, "shape_index " + std::to_string(shape_index) + " is out of range (the file holds " +
                                    std::to_string(count) + " meshes)");
    const size_t entry = version == 4 ? 8 : 4, back = size_t(count - uint32_t(shape_index)) * entry + 4;
    if (back > data.size()) throw SceneError(path, 0, "the mesh dictionary is larger than the file");
    offset = version == 4 ? size_t(read_le<uint64_t>(bytes(data.size() - back)))
                          : size_t(read_le<uint32_t>(bytes(data.size() - back)));
    if (offset > data.size() - 4 || read_le<uint16_t>(bytes(offset)) != kMagic || read_le<uint16_t>(bytes(offset + 2)) != version)
      throw SceneError(path, 0, "mesh " + std::to_string(shape_index) + " has no header at offset " +
                                    std::to_string(offset));
  }
  // The header (flags, name, counts) first, then exactly the bytes its counts
  // need, which deflate's largest ratio (1032:1) bounds by the compressed bytes
  // left: a file cannot make the reader allocate more than that.
  Inflater stream(path, data, offset + 4);
  std::vector<unsigned char> z;
  SerializedMesh out;
  stream.read(z, 4, "flags");
  const uint32_t flags = read_le<uint32_t>(z.data());
  if (version == 4) {
    for (;;) {
      stream.read(z, 1, "name");
      if (z.back() == 0) break;
      if (z.size() > 4 + 65536) throw SceneError(path, 0, "mesh " + std::to_string(shape_index) + ": its name is not terminated");
    }
    out.name.assign(reinterpret_cast<const char*>(z.data() + 4), z.size() - 5);
  }
  const size_t counts_at = z.size();
  stream.read(z, 16, "counts");
  const uint64_t vertices = read_le<uint64_t>(z.data() + counts_at), triangles = read_le<uint64_t>(z.data() + counts_at + 8);
  const size_t real = (flags & kDouble) ? 8 : 4;
  const uint64_t per_vertex = 3 + ((flags & kNormals) ? 3 : 0) + ((flags & kUvs) ? 2 : 0) + ((flags & kColours) ? 3 : 0);
  const uint64_t limit = 1032 * uint64_t(stream.compressed_left()) + 1024;
  if (vertices > limit / (per_vertex * real) || triangles > limit / 12 ||
      vertices * per_vertex * real + triangles * 12 > limit)
    throw SceneError(path, 0, "mesh " + std::to_string(shape_index) + ": " + std::to_string(vertices) +
                                  " vertices and " + std::to_string(triangles) +
                                  " triangles do not fit its data");
  size_t at = z.size();
  stream.read(z, size_t(vertices * per_vertex * real + triangles * 12), "vertex and triangle data");
  auto reals = [&](size_t dims) {
    std::vector<float> v(size_t(vertices) * dims);
    for (size_t i = 0; i < v.size(); ++i, at += real) {
      if (real == 8) {
        const uint64_t b = read_le<uint64_t>(z.data() + at);
        double d;
        std::memcpy(&d, &b, 8);
        v[i] = float(d);
      } else {
        const uint32_t b = read_le<uint32_t>(z.data() + at);
        std::memcpy(&v[i], &b, 4);
      }
    }
    return v;
  };
  TriMesh& mesh = out.mesh;
  const std::vector<float> p = reals(3);
  mesh.positions.resize(size_t(vertices));
  for (size_t i = 0; i < mesh.positions.size(); ++i) mesh.positions[i] = {p[3 * i], p[3 * i + 1], p[3 * i + 2]};
  if (flags & kNormals) {
    const std::vector<float> n = reals(3);
    mesh.normals.resize(size_t(vertices));
    for (size_t i = 0; i < mesh.normals.size(); ++i) {  // a non-finite normal: none (the face normal)
      const glm::vec3 v(n[3 * i], n[3 * i + 1], n[3 * i + 2]);
      mesh.normals[i] = std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z) ? v : glm::vec3(0.0f);
    }
  }
  if (flags & kUvs) {  // Mitsuba's own convention already: taken as they are
    const std::vector<float> t = reals(2);
    mesh.uvs.resize(size_t(vertices));
    for (size_t i = 0; i < mesh.uvs.size(); ++i) mesh.uvs[i] = {t[2 * i], t[2 * i + 1]};
  }
  if (flags & kColours) at += size_t(vertices) * 3 * real;  // not used
  mesh.triangles.resize(size_t(triangles));
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k, at += 4) {
      const uint32_t v = read_le<uint32_t>(z.data() + at);
      if (v >= vertices)
        throw SceneError(path, 0, "mesh " + std::to_string(shape_index) + ": triangle " + std::to_string(t) +
                                      " refers to vertex " + std::to_string(v) + " of " + std::to_string(vertices));
      mesh.triangles[t][k] = v;
    }
  out.face_normals = (flags & kFaceNormals) != 0;
  return out;
}

}  // namespace psf::detail
