#pragma once
// Wavefront OBJ reader for solid and liquid meshes (scene shapes of kind "mesh").
//
// Reads `v` and `f` records only: `v x y z [w | r g b ...]` (the first three numbers are used),
// `f i j k ...` with 3 or more corners fanned into triangles (i, j, k), (i, k, l), ...; corners may
// be `v`, `v/vt`, `v//vn` or `v/vt/vn`, and indices may be negative (relative to the vertices read
// so far, -1 = the last one). Every other record (vt, vn, g, o, s, usemtl, mtllib, l, p, comments)
// is ignored.
//
// Untrusted input: every problem is a MeshError whose message reads
//   "<file>: line <n>: <problem>"
// (missing or unreadable file, malformed or out-of-range numbers, NaN/inf coordinates, zero or
// out-of-range indices, faces with fewer than 3 corners, binary data, counts beyond ObjLimits, and
// files without vertices or faces). Nothing is allocated from a count read in the file: vectors
// grow with the records actually read, and a header comment such as "# Vertices: 49990" is only a
// reserve hint, clamped by the file size (a declared count above the limits is an error, reported
// before anything is read).
#include <cstdint>
#include <iosfwd>
#include <stdexcept>
#include <string>

#include "sim/geometry/triangle_mesh.h"

namespace stokes::sim {
inline namespace geometry {

/// Thrown for every problem with an OBJ file; the message names the file and the line.
class MeshError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ObjLimits {
  std::uint64_t maxVertices = 50'000'000;
  std::uint64_t maxTriangles = 50'000'000;   ///< after fanning polygons
  std::uint64_t maxFileBytes = 4ull << 30;   ///< 4 GiB
  std::uint64_t maxLineBytes = 1u << 20;     ///< one record; longer lines are an error
};

/// Reads an OBJ file. Throws MeshError (see above).
TriangleMesh loadObj(const std::string& path, const ObjLimits& limits = {});

/// Reads OBJ text from a stream; `sourceName` names it in error messages. The stream is read up to
/// `limits.maxFileBytes` bytes. Throws MeshError.
TriangleMesh readObj(std::istream& in, const std::string& sourceName, const ObjLimits& limits = {});

}  // namespace geometry
}  // namespace stokes::sim
