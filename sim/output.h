#pragma once
// Output of the 3D simulator: per-frame OpenVDB files (liquid level set, optional particles),
// preview PNG renders, and per-step statistics as CSV.
#include <openvdb/openvdb.h>

#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "sim/shapes.h"
#include "sim/surface_mesh.h"

namespace stokes::sim {

/// Writes `liquid` as a grid named "liquid" (a shallow copy is renamed; the caller's grid is not
/// touched) and, when `particles` is given, an OpenVDB points grid named "particles" (positions,
/// plus a Vec3f attribute "v" when `velocities` is given; voxel size = the liquid's). The file is
/// written to path + ".tmp" and renamed onto path, so a crash never leaves a half-written file.
/// Throws std::invalid_argument for a null grid or mismatched sizes, std::runtime_error naming the
/// path when writing fails.
/// `up`: UpAxis::Z turns every grid's transform (and the velocities) from y-up to z-up
/// (sim/surface_mesh.h).
void writeFrameVdb(const std::string& path, openvdb::FloatGrid::Ptr liquid,
                   const std::vector<Vec3d>* particles = nullptr,
                   const std::vector<Vec3d>* velocities = nullptr, UpAxis up = UpAxis::Y);

/// Names of the grids in a .vdb file. Throws std::runtime_error naming the path.
std::vector<std::string> readVdbGridNames(const std::string& path);

/// The float grid named "liquid" of a .vdb file. Throws std::runtime_error naming the path when
/// the file cannot be read or has no float grid of that name.
openvdb::FloatGrid::Ptr readLiquidGrid(const std::string& path);

/// A pinhole camera for previews. `fovDegrees` is the HORIZONTAL field of view (as in
/// openvdb::tools::PerspectiveCamera); the image's aspect ratio sets the vertical one.
struct PreviewCamera {
  Vec3d eye{0.0, 0.0, 5.0};
  Vec3d target{0.0};
  Vec3d up{0.0, 1.0, 0.0};
  double fovDegrees = 40.0;
};

/// A camera looking at the centre of `box` from direction `viewDirection` (from the target
/// towards the eye), far enough that the box's bounding sphere fits in the smaller of the
/// horizontal and vertical fields of view (aspect = width / height), with a 5% margin.
PreviewCamera frameWorldBBox(const openvdb::BBoxd& box, double aspect = 1.0,
                             const Vec3d& viewDirection = Vec3d(0.8, 0.6, 1.2),
                             double fovDegrees = 40.0, const Vec3d& up = Vec3d(0.0, 1.0, 0.0));

/// Colours (linear 0..1 RGB) used by renderPreviewPng.
struct PreviewStyle {
  Vec3d liquid{0.85, 0.55, 0.12};  ///< honey
  Vec3d solid{0.6, 0.6, 0.6};      ///< grey
  Vec3d background{0.12, 0.13, 0.16};
  Vec3d floorLight{0.42, 0.43, 0.46}, floorDark{0.30, 0.31, 0.34};  ///< the domain's floor, checkered
  Vec3d edges{0.75, 0.77, 0.82};                                    ///< the domain box's outline
};

/// Ray-casts the liquid level set and (optional) solid level set with
/// openvdb::tools::LevelSetRayIntersector through an openvdb::tools::PerspectiveCamera, one ray
/// per pixel; each pixel takes the nearer hit of the two grids (depth compositing) and is shaded
/// Lambertian (ambient + key light + headlight) from the level-set normal. Pixels that hit
/// nothing get the background colour; an empty (or non-level-set-class) grid is simply not drawn,
/// so an empty liquid gives a background image -- no slice fallback. Rows are rendered in
/// parallel (OpenMP, one intersector copy per thread). Written as 8-bit RGB PNG with
/// stbi_write_png. Throws std::invalid_argument for width/height <= 0 and std::runtime_error
/// naming the path when writing fails.
///
/// `domain` (optional): the box the liquid lives in, drawn for scale as a checkered floor
/// (its y = min face, 8 checks along its longer side; depth-composited with the grids) and the
/// outline of its 12 edges (lines about 1.5 pixels wide, hidden behind nearer liquid or solid).
void renderPreviewPng(const std::string& path, const openvdb::FloatGrid& liquid,
                      const openvdb::FloatGrid* solid, const PreviewCamera& cam, int width,
                      int height, const PreviewStyle& style = {}, const openvdb::BBoxd* domain = nullptr);

/// A CSV file of per-step statistics. The header is written on construction; every row is flushed
/// (a crash keeps the rows so far); numbers are written with %.9g. Not thread-safe.
class StatsCsv {
 public:
  /// Opens (truncates) `path`; throws std::runtime_error naming the path when it cannot, and
  /// std::invalid_argument for an empty or duplicated column list.
  StatsCsv(const std::string& path, std::vector<std::string> columns);
  /// Continues the file of a resumed run: keeps its header and the rows whose `keyColumn` value is
  /// below `keyLimit` (the steps before the checkpoint; rows of steps after it are dropped, they
  /// will be written again), rewritten through a temporary file, then appends. Throws
  /// std::runtime_error naming the path when it is missing, unreadable, or its header is not
  /// `columns`.
  static StatsCsv resume(const std::string& path, std::vector<std::string> columns, const std::string& keyColumn,
                         double keyLimit);
  StatsCsv(StatsCsv&& other) noexcept;
  ~StatsCsv();
  StatsCsv(const StatsCsv&) = delete;
  StatsCsv& operator=(const StatsCsv&) = delete;
  StatsCsv& operator=(StatsCsv&&) = delete;

  /// One row by column name; columns not given are left empty. Throws std::invalid_argument
  /// naming an unknown column.
  void row(const std::vector<std::pair<std::string, double>>& values);
  /// The same with text columns too (quoted where CSV needs it).
  void row(const std::vector<std::pair<std::string, double>>& values,
           const std::vector<std::pair<std::string, std::string>>& text);
  /// One row in column order; throws std::invalid_argument when the count differs.
  void row(const std::vector<double>& values);

  const std::string& path() const { return path_; }
  const std::vector<std::string>& columns() const { return columns_; }
  std::size_t rowsWritten() const { return rows_; }

 private:
  StatsCsv() = default;
  void checkColumns() const;
  void writeLine(const std::string& line);
  std::string path_;
  std::vector<std::string> columns_;
  std::FILE* file_ = nullptr;
  std::size_t rows_ = 0;
};

}  // namespace stokes::sim
