// Surface meshes of the liquid: see surface_mesh.h.
#include "sim/output/surface_mesh.h"

#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <unordered_map>

#include "sim/output/atomic_file.h"
#include "sim/output/vdb_frame.h"

namespace stokes::sim {
inline namespace output {

openvdb::Vec3d toUpAxis(const openvdb::Vec3d& x, UpAxis up) {
  return up == UpAxis::Z ? openvdb::Vec3d(x.x(), -x.z(), x.y()) : x;
}

namespace {

/// Moves every point of `mesh` from index `first` on onto the zero isosurface of the level set's
/// quadratic interpolant: two Newton steps x -= phi grad / |grad|^2 (central differences over half
/// a voxel).
void projectOntoSurface(const openvdb::FloatGrid& levelSet, SurfaceMesh& mesh, std::size_t first) {
  const openvdb::tools::GridSampler<openvdb::FloatTree, openvdb::tools::QuadraticSampler> sample(
      levelSet.tree(), levelSet.transform());
  const double h = 0.5 * levelSet.voxelSize()[0];
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = std::ptrdiff_t(first); i < std::ptrdiff_t(mesh.points.size()); ++i) {
    openvdb::Vec3d x(mesh.points[std::size_t(i)]);
    for (int iteration = 0; iteration < 2; ++iteration) {
      openvdb::Vec3d g;
      for (int a = 0; a < 3; ++a) {
        openvdb::Vec3d e(0.0);
        e[a] = h;
        g[a] = (sample.wsSample(x + e) - sample.wsSample(x - e)) / (2.0 * h);
      }
      const double gg = g.lengthSqr();
      if (!(gg > 1e-12)) break;
      x -= double(sample.wsSample(x)) / gg * g;
    }
    mesh.points[std::size_t(i)] = openvdb::Vec3f(x);
  }
}

/// Splits every triangle into four at its edges' midpoints (one shared point per edge, so the
/// surface stays closed); the new points are projected onto the surface.
void subdivide(const openvdb::FloatGrid& levelSet, SurfaceMesh& mesh) {
  const std::size_t first = mesh.points.size();
  std::unordered_map<std::uint64_t, std::uint32_t> midpoint;
  midpoint.reserve(3 * mesh.triangles.size() / 2);
  auto mid = [&](std::uint32_t a, std::uint32_t b) {
    const std::uint64_t key = (std::uint64_t(std::min(a, b)) << 32) | std::max(a, b);
    const auto [it, added] = midpoint.try_emplace(key, std::uint32_t(mesh.points.size()));
    if (added) mesh.points.push_back(0.5f * (mesh.points[a] + mesh.points[b]));
    return it->second;
  };
  std::vector<std::array<std::uint32_t, 3>> finer;
  finer.reserve(4 * mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    const std::uint32_t ab = mid(t[0], t[1]), bc = mid(t[1], t[2]), ca = mid(t[2], t[0]);
    finer.push_back({t[0], ab, ca});
    finer.push_back({ab, t[1], bc});
    finer.push_back({ca, bc, t[2]});
    finer.push_back({ab, bc, ca});
  }
  mesh.triangles.swap(finer);
  projectOntoSurface(levelSet, mesh, first);
}

}  // namespace

SurfaceMesh meshLevelSet(const openvdb::FloatGrid& levelSet, int subdivisions) {
  SurfaceMesh mesh;
  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(levelSet, points, triangles, quads, 0.0, 0.0);
  mesh.points.assign(points.begin(), points.end());
  mesh.triangles.reserve(triangles.size() + 2 * quads.size());
  // OpenVDB winds its polygons clockwise seen from outside a level set (negative inside); reversed
  // here so that the normals point out of the liquid
  for (const openvdb::Vec3I& t : triangles) mesh.triangles.push_back({t[2], t[1], t[0]});
  for (const openvdb::Vec4I& q : quads) {
    mesh.triangles.push_back({q[3], q[2], q[1]});
    mesh.triangles.push_back({q[3], q[1], q[0]});
  }
  // volumeToMesh puts a vertex per cell on the zero of the trilinear interpolant, which lies inside
  // a convex surface by ~0.03 cells (a ball of 8 cells' radius: r = 0.9964 R on average); projected
  // onto the quadratic interpolant's zero they sit at R to 5e-4, and the facets' chords alone lose
  // 0.6% of that ball's volume (2.2% before), a quarter of it per subdivision
  projectOntoSurface(levelSet, mesh, 0);
  for (int s = 0; s < subdivisions; ++s) subdivide(levelSet, mesh);
  return mesh;
}

void sampleVertexVelocities(SurfaceMesh& mesh, const openvdb::Vec3SGrid& velocity) {
  const openvdb::math::Transform& xform = velocity.constTransform();
  mesh.velocities.assign(mesh.points.size(), openvdb::Vec3f(0.0f));
  const std::ptrdiff_t count = std::ptrdiff_t(mesh.points.size());
#pragma omp parallel
  {
    openvdb::Vec3SGrid::ConstAccessor acc = velocity.getConstAccessor();
#pragma omp for schedule(static)
    for (std::ptrdiff_t i = 0; i < count; ++i) {
      openvdb::Vec3d sum(0.0);
      double weight = 0.0;
      forEachTrilinearCorner(xform.worldToIndex(openvdb::Vec3d(mesh.points[std::size_t(i)])),
                             [&](const openvdb::Coord& c, double w) {
                               openvdb::Vec3f value;
                               if (!acc.probeValue(c, value)) return;
                               sum += w * openvdb::Vec3d(value);
                               weight += w;
                             });
      if (weight > 0.0) mesh.velocities[std::size_t(i)] = openvdb::Vec3f(sum / weight);
    }
  }
}

void applyUpAxis(SurfaceMesh& mesh, UpAxis up) {
  if (up == UpAxis::Y) return;
  for (openvdb::Vec3f& p : mesh.points) p = openvdb::Vec3f(p.x(), -p.z(), p.y());
  for (openvdb::Vec3f& v : mesh.velocities) v = openvdb::Vec3f(v.x(), -v.z(), v.y());
}

void writePly(const std::string& path, const SurfaceMesh& mesh) {
  writeFileAtomically(path, "writePly", [&](const std::string& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    const bool moving = !mesh.velocities.empty();
    if (moving && mesh.velocities.size() != mesh.points.size())
      throw std::invalid_argument(std::to_string(mesh.velocities.size()) + " velocities for " +
                                  std::to_string(mesh.points.size()) + " points");
    out << "ply\nformat binary_little_endian 1.0\ncomment StokesVDB liquid surface\nelement vertex "
        << mesh.points.size() << "\nproperty float x\nproperty float y\nproperty float z\n"
        << (moving ? "property float vx\nproperty float vy\nproperty float vz\n" : "") << "element face "
        << mesh.triangles.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
    static_assert(sizeof(openvdb::Vec3f) == 12);
    if (moving) {
      std::vector<openvdb::Vec3f> vertices(2 * mesh.points.size());
      for (std::size_t i = 0; i < mesh.points.size(); ++i) {
        vertices[2 * i] = mesh.points[i];
        vertices[2 * i + 1] = mesh.velocities[i];
      }
      out.write(reinterpret_cast<const char*>(vertices.data()), std::streamsize(12 * vertices.size()));
    } else {
      out.write(reinterpret_cast<const char*>(mesh.points.data()), std::streamsize(12 * mesh.points.size()));
    }
    std::vector<char> faces(13 * mesh.triangles.size());
    for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
      faces[13 * f] = 3;
      for (int k = 0; k < 3; ++k) {
        const std::int32_t v = std::int32_t(mesh.triangles[f][k]);
        std::memcpy(&faces[13 * f + 1 + 4 * k], &v, 4);
      }
    }
    out.write(faces.data(), std::streamsize(faces.size()));
    out.close();
    if (!out) throw std::runtime_error("disk full or not writable?");
  });
}

SurfaceMesh readPly(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("readPly: cannot open '" + path + "'");
  auto fail = [&](const std::string& what) { throw std::runtime_error("readPly: '" + path + "': " + what); };
  std::string line;
  std::size_t vertices = 0, faces = 0;
  std::vector<std::string> vertexProperties;
  bool inVertex = false;
  if (!std::getline(in, line) || line != "ply") fail("not a PLY file");
  while (std::getline(in, line) && line != "end_header") {
    if (line.rfind("format ", 0) == 0 && line != "format binary_little_endian 1.0") fail("not binary little-endian");
    if (line.rfind("element ", 0) == 0) inVertex = std::sscanf(line.c_str(), "element vertex %zu", &vertices) == 1;
    std::sscanf(line.c_str(), "element face %zu", &faces);
    if (inVertex && line.rfind("property float ", 0) == 0) vertexProperties.push_back(line.substr(15));
  }
  if (line != "end_header") fail("no end_header");
  const std::vector<std::string> still = {"x", "y", "z"}, moving = {"x", "y", "z", "vx", "vy", "vz"};
  if (vertexProperties != still && vertexProperties != moving)
    fail("vertices are neither (x, y, z) nor (x, y, z, vx, vy, vz) floats");
  SurfaceMesh mesh;
  mesh.points.resize(vertices);
  if (vertexProperties == moving) {
    std::vector<openvdb::Vec3f> interleaved(2 * vertices);
    in.read(reinterpret_cast<char*>(interleaved.data()), std::streamsize(12 * interleaved.size()));
    mesh.velocities.resize(vertices);
    for (std::size_t i = 0; i < vertices; ++i) {
      mesh.points[i] = interleaved[2 * i];
      mesh.velocities[i] = interleaved[2 * i + 1];
    }
  } else {
    in.read(reinterpret_cast<char*>(mesh.points.data()), std::streamsize(12 * vertices));
  }
  mesh.triangles.resize(faces);
  for (std::size_t f = 0; f < faces; ++f) {
    unsigned char n = 0;
    in.read(reinterpret_cast<char*>(&n), 1);
    if (n != 3) fail("face " + std::to_string(f) + " has " + std::to_string(int(n)) + " vertices, expected 3");
    std::int32_t v[3];
    in.read(reinterpret_cast<char*>(v), 12);
    for (int k = 0; k < 3; ++k) {
      if (v[k] < 0 || std::size_t(v[k]) >= vertices) fail("face " + std::to_string(f) + " has a bad vertex index");
      mesh.triangles[f][k] = std::uint32_t(v[k]);
    }
  }
  if (!in) fail("truncated");
  return mesh;
}

double enclosedVolume(const SurfaceMesh& mesh) {
  double six = 0.0;
  for (const auto& t : mesh.triangles) {
    const openvdb::Vec3d a(mesh.points[t[0]]), b(mesh.points[t[1]]), c(mesh.points[t[2]]);
    six += a.dot(b.cross(c));
  }
  return six / 6.0;
}

std::size_t openOrMisorientedEdges(const SurfaceMesh& mesh) {
  // a closed, consistently wound surface uses each directed edge (i, j) exactly once and its
  // reverse (j, i) exactly once
  std::unordered_map<std::uint64_t, int> directed;
  directed.reserve(3 * mesh.triangles.size());
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) ++directed[(std::uint64_t(t[k]) << 32) | t[(k + 1) % 3]];
  std::size_t bad = 0;
  for (const auto& [key, count] : directed) {
    const std::uint64_t reverse = (key << 32) | (key >> 32);
    const auto it = directed.find(reverse);
    if (count != 1 || it == directed.end() || it->second != 1) ++bad;
  }
  return bad;
}

}  // namespace output
}  // namespace stokes::sim
