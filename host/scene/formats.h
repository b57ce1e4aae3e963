// Mesh file formats besides OBJ: PLY (host/scene/ply.cpp), Mitsuba's .serialized
// (host/scene/serialized.cpp) and glTF 2.0 (host/scene/gltf.cpp), and the default
// lighting of bare mesh files.
#pragma once
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "scene/loaders.h"
#include "scene/scene.h"

namespace psf::detail {

// The contents of a PLY file: polygons fanned into triangles (0, k-1, k), as Mitsuba does.
struct PlyMesh {
  TriMesh mesh;                     // positions, triangles, and per vertex normals (nx, ny, nz) and uvs
                                    // (u, v / s, t / texture_u, texture_v / texture_s, texture_t, taken
                                    // as they are, as Mitsuba does) when the file has them; file coordinates
  std::vector<std::string> ignored; // names of the properties and elements read past, e.g. "vertex.red"
};

// Reads a PLY file: "format ascii 1.0", "binary_little_endian 1.0" or
// "binary_big_endian 1.0"; elements "vertex" (x, y, z; optional normals and
// uv) and "face" (a list "vertex_indices" or "vertex_index") with any other
// properties and elements skipped; polygons of any size are fanned. Throws
// SceneError naming the file and the header line, or for binary data the byte
// offset, or for ASCII data the line, of: a bad header, an unknown type, a
// truncated body, an out-of-range index, a non-finite vertex.
PlyMesh read_ply(const std::string& path);

// One mesh of a Mitsuba .serialized file (Mitsuba 0.5 to 3: a little-endian
// header 0x041C and version 3 or 4, then per mesh a zlib stream of flags, the
// name (version 4), vertex and triangle counts, positions, and optional normals,
// uvs and colours in single or double precision, then uint32 indices; at the end
// of the file each mesh's offset and the mesh count).
struct SerializedMesh {
  TriMesh mesh;               // positions, triangles, and the normals and uvs the file has (file coordinates)
  std::string name;           // the mesh's name (version 4), else empty
  bool face_normals = false;  // the file asks for face normals (flag 0x0010)
};

// Reads mesh `shape_index` of a .serialized file. Throws SceneError naming the
// file (line 0) for: a file that is not one, an unknown version, a shape index
// outside the file's dictionary, a corrupt or truncated zlib stream, counts that
// do not fit the data, an index outside the vertices.
SerializedMesh read_serialized(const std::string& path, int shape_index);

// Loads a PLY file as a scene: one diffuse material (albedo 0.5, two-sided),
// smooth vertex normals unless the file has its own, camera_framing, a 512x512
// film (load_scene adds default_sky()).
Scene load_ply_scene(const std::string& path);

// Loads a glTF 2.0 file (.gltf with external or embedded buffers, or .glb) with
// tinygltf: the default scene's node hierarchy with its transforms, triangle
// meshes (indexed or not), metallic-roughness materials as diffuse base colour
// (a warning names the features left out), the first perspective camera (else
// camera_framing), KHR_lights_punctual point, spot and directional lights
// (load_scene adds default_sky() when nothing emits).
Scene load_gltf_scene(const std::string& path);

// True if the scene emits light: an emissive material used by a triangle, or a LightDesc.
bool has_emitters(const Scene& scene);

}  // namespace psf::detail
