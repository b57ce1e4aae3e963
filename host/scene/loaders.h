// Private interface between the scene loaders: scene.cpp dispatches by file
// extension to mitsuba.cpp and obj.cpp; shapes.cpp tessellates Mitsuba's
// analytic shapes and appends meshes to the scene.
#pragma once
#include <glm/glm.hpp>
#include <istream>
#include <string>
#include <utility>
#include <vector>

#include "scene/scene.h"

namespace psf::detail {

// What is wrong with reading `path` whole as scene input: "" for a regular file
// (or one that does not exist: the reader's own message names that), else "is a
// folder", "is not a regular file" (a device such as /dev/zero or a FIFO,
// which would never end or never answer) or "cannot be read: <reason>" (a name
// the system refuses: too long, a loop of symbolic links).
std::string unreadable_input(const std::string& path);
// Throws SceneError(path, 0, "<what> <unreadable_input>") where that is not "".
void require_readable_input(const std::string& path, const std::string& what);
// The rest of `in` as a string, copied a buffer at a time (std::string from
// istreambuf_iterators copies a character at a time).
std::string read_all(std::istream& in);

// A triangle mesh in object space.
struct TriMesh {
  std::vector<glm::vec3> positions;   // vertex positions
  std::vector<glm::uvec3> triangles;  // vertex indices, counter-clockwise seen from the front
  std::vector<glm::vec3> normals;     // per vertex shading normal, or empty (face normals)
  std::vector<glm::vec2> uvs;         // per vertex uv (v = 0 at the image top, Mitsuba's), or empty
  std::vector<glm::vec4> tangents;    // per vertex tangent xyz and handedness w = +-1 (glTF's TANGENT), or empty
  std::vector<glm::vec3> colors;      // per vertex linear RGB colour in [0, 1], or empty
};

// Smooth vertex normals of `mesh`: the face normals around each vertex weighted
// by the face's angle at it (Thuermer & Wuethrich 1998), as Mitsuba computes
// them for meshes without normals.
void compute_vertex_normals(TriMesh& mesh);

// Vertex tangents for a normal map where a glTF primitive has none, as the
// specification asks (MikkTSpace, Mikkelsen 2008, without its vertex splitting):
// each triangle's dp/du and dp/dv made orthogonal to the vertex normal, summed
// around the vertex weighted by the triangles' angles at it; the handedness
// w = sign(<n x t, dp/dv>) with v upwards in the image (so that an unmirrored
// mapping is right-handed, as Blender writes it). Needs normals and uvs; a vertex
// whose triangles give no tangent keeps (0, 0, 0, 0) (the kernel then follows dp/du).
void compute_vertex_tangents(TriMesh& mesh);

// Mitsuba 0.5's maxSmoothAngle: the mesh's normals rebuilt so that faces meeting
// at a vertex (by position) share a normal only where their normals differ by
// less than `max_angle_degrees`; each face corner's normal is the angle-weighted
// sum of those faces' normals, and vertices are split where corners differ.
void compute_crease_normals(TriMesh& mesh, float max_angle_degrees);

// Mitsuba's rectangle: [-1,1]^2 in the plane z = 0, facing +z (2 triangles).
TriMesh make_rectangle();
// Mitsuba's cube: [-1,1]^3 with outward faces, 4 vertices per face (12 triangles).
TriMesh make_cube();
// Mitsuba's disk: the unit disk in the plane z = 0, facing +z, as a fan of `segments` triangles; uv (r, phi / 2pi).
TriMesh make_disk(int segments = 64);
// Mitsuba's sphere: a latitude-longitude tessellation with outward faces whose
// vertices lie on the sphere; `rings` >= 2 bands from pole to pole, `segments` >= 3 around.
TriMesh make_sphere(const glm::vec3& center, float radius, int rings = 32, int segments = 64);
// Mitsuba's cylinder: the open tube (no caps) of `radius` from p0 to p1 with
// outward faces and normals, `segments` >= 3 quads around; uv (phi / 2pi, 0 at p0 to 1 at p1).
TriMesh make_cylinder(const glm::vec3& p0, const glm::vec3& p1, float radius, int segments = 64);

// Appends `mesh` transformed by `to_world` with material `material` to the scene,
// reversing the winding and the normals when `flip` is set; normals are
// transformed by the inverse transpose. Throws SceneError(file, line) if a
// transformed position is not finite.
void append_mesh(Scene& scene, const TriMesh& mesh, const glm::mat4& to_world, uint32_t material, bool flip,
                 const std::string& file, int line);

// A texture map of an MTL material (map_Kd, map_d, map_bump).
struct ObjTexture {
  std::string file;          // file name as written, relative to the MTL file; empty: none
  glm::vec2 scale{1.0f};     // -s u v
  glm::vec2 offset{0.0f};    // -o u v
  bool clamp = false;        // -clamp on
  float bump_multiplier = 1; // -bm (bump maps)
};

// A material of an OBJ file's MTL library.
struct ObjMaterial {
  std::string name;        // newmtl name
  std::string mtl_file;    // the MTL file defining it, "" if unknown
  int line = 0;            // line of its newmtl there, 0 if unknown
  glm::vec3 kd{0.0f};      // Kd, diffuse reflectance
  glm::vec3 ks{0.0f};      // Ks, specular reflectance
  glm::vec3 ke{0.0f};      // Ke, emitted radiance
  glm::vec3 tf{1.0f};      // Tf, transmission filter
  float ns = 0.0f;         // Ns, Phong exponent
  float ni = 1.0f;         // Ni, index of refraction
  float d = 1.0f;          // d (or 1 - Tr), dissolve = opacity
  int illum = 2;           // illumination model
  float pr = 0.0f;         // Pr, roughness (the PBR extension; with Pm, 0 when absent)
  float pm = 0.0f;         // Pm, metallic
  ObjTexture map_kd;       // map_Kd
  ObjTexture map_d;        // map_d
  ObjTexture map_bump;     // map_bump / bump
  std::vector<std::string> unsupported;  // other statements given (map_Ks, norm, disp, ...), for a warning
};

// The contents of an OBJ file, triangulated as fans (as Mitsuba does).
struct ObjData {
  TriMesh mesh;                        // referenced vertices only, in file coordinates
  std::vector<int> tri_material;       // index into `materials` per triangle, -1 without usemtl
  std::vector<ObjMaterial> materials;  // from the MTL library (empty unless requested)
  std::vector<std::string> warnings;   // tinyobjloader's warnings, each "file: message"
  // With `with_materials`, a file without vn whose faces have smoothing groups
  // (`s 1`): vertices are shared only within a group (faces of `s off` share
  // none), so that vertex normals computed from the faces shade each group smooth
  // and the rest flat.
  bool smoothing_groups = false;
};

// Reads an OBJ file with its vt (v flipped to Mitsuba's convention) and vn, a
// vertex per distinct (v, vt, vn); with `with_materials` also its MTL library. Throws
// SceneError(path, line) for a missing file, a parse error reported by
// tinyobjloader, an out-of-range index or a non-finite vertex position.
ObjData read_obj(const std::string& path, bool with_materials);

// A camera looking along -z at the bounding box of `positions`, with a 45 degree
// field of view along the larger film axis that fits the box.
CameraDesc camera_framing(const std::vector<glm::vec3>& positions);

// Loads a Wavefront OBJ file: MTL materials mapped onto the BSDFs (obj.cpp),
// textures, vertex normals and uvs as given, camera_framing, 512x512 film.
Scene load_obj_scene(const std::string& path);

// Loads a Mitsuba 0.5 / 2 / 3 XML scene; `params` override the file's <default> values.
Scene load_mitsuba(const std::string& path, const std::vector<std::pair<std::string, std::string>>& params);

// A reflectance (`emitter` false) or emitted radiance (`emitter` true) spectrum
// given as wavelength (nm) and value samples, converted to linear sRGB the way
// Mitsuba 3's RGB variants do: linear interpolation between samples, zero outside
// them, integrated against the CIE 1931 colour-matching functions (under the D65
// illuminant for reflectances), normalised so that a constant reflectance 1 gives
// (1,1,1) and a constant radiance 1 has luminance 1. Reflectances are clamped to
// [0,1], radiances to >= 0.
glm::vec3 spectrum_to_rgb(const std::vector<double>& wavelengths, const std::vector<double>& values, bool emitter);

// The sRGB transfer function inverted: an 8-bit style sRGB-encoded value in [0,1] to linear.
float srgb_to_linear(float encoded);

}  // namespace psf::detail
