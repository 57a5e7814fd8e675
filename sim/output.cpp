// Output of the 3D simulator: see output.h.
#include "sim/output.h"

#include <openvdb/io/File.h>
#include <openvdb/points/PointConversion.h>
#include <openvdb/points/PointDataGrid.h>
#include <openvdb/tools/PointIndexGrid.h>
#include <openvdb/tools/RayIntersector.h>
#include <openvdb/tools/RayTracer.h>

#include <stb/stb_image_write.h>

#include <algorithm>
#include <array>
#include <limits>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <stdexcept>

namespace stokes::sim {

// ---- VDB files --------------------------------------------------------------------------------

namespace {

/// OpenVDB's registries (grid types, codecs) must be initialised before any file I/O or point
/// grid; openvdb::initialize() is idempotent and internally locked.
void ensureOpenVdbInitialised() { openvdb::initialize(); }

openvdb::points::PointDataGrid::Ptr makePointsGrid(const std::vector<Vec3d>& positions,
                                                   const std::vector<Vec3d>* velocities,
                                                   const openvdb::math::Transform& xform) {
  namespace pts = openvdb::points;
  const pts::PointAttributeVector<openvdb::Vec3d> positionList(positions);
  auto index = openvdb::tools::createPointIndexGrid<openvdb::tools::PointIndexGrid>(positionList, xform);
  auto points = pts::createPointDataGrid<pts::NullCodec, pts::PointDataGrid>(*index, positionList, xform);
  if (velocities) {
    std::vector<openvdb::Vec3f> v(velocities->begin(), velocities->end());
    pts::appendAttribute<openvdb::Vec3f>(points->tree(), "v");
    const pts::PointAttributeVector<openvdb::Vec3f> velocityList(v);
    pts::populateAttribute<pts::PointDataTree, openvdb::tools::PointIndexTree,
                           pts::PointAttributeVector<openvdb::Vec3f>>(points->tree(), index->tree(),
                                                                      "v", velocityList);
  }
  points->setName("particles");
  return points;
}

}  // namespace

void writeFrameVdb(const std::string& path, openvdb::FloatGrid::Ptr liquid,
                   const std::vector<Vec3d>* particles, const std::vector<Vec3d>* velocities) {
  if (!liquid) throw std::invalid_argument("writeFrameVdb: null liquid grid for '" + path + "'");
  if (velocities && !particles)
    throw std::invalid_argument("writeFrameVdb: velocities without particles for '" + path + "'");
  if (velocities && velocities->size() != particles->size())
    throw std::invalid_argument("writeFrameVdb: " + std::to_string(velocities->size()) +
                                " velocities for " + std::to_string(particles->size()) +
                                " particles in '" + path + "'");
  ensureOpenVdbInitialised();
  const std::string tmp = path + ".tmp";
  try {
    openvdb::GridPtrVec grids;
    auto named = liquid->copyGrid();  // shares the tree; own metadata
    named->setName("liquid");
    grids.push_back(named);
    if (particles) grids.push_back(makePointsGrid(*particles, velocities, liquid->constTransform()));
    openvdb::io::File file(tmp);
    file.write(grids);
    file.close();
    std::filesystem::rename(tmp, path);
  } catch (const std::exception& e) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw std::runtime_error("writeFrameVdb: cannot write '" + path + "': " + e.what());
  }
}

std::vector<std::string> readVdbGridNames(const std::string& path) {
  ensureOpenVdbInitialised();
  std::vector<std::string> names;
  try {
    openvdb::io::File file(path);
    file.open(/*delayLoad=*/false);
    for (auto it = file.beginName(); it != file.endName(); ++it) names.push_back(it.gridName());
    file.close();
  } catch (const std::exception& e) {
    throw std::runtime_error("readVdbGridNames: cannot read '" + path + "': " + e.what());
  }
  return names;
}

openvdb::FloatGrid::Ptr readLiquidGrid(const std::string& path) {
  ensureOpenVdbInitialised();
  openvdb::GridBase::Ptr base;
  try {
    openvdb::io::File file(path);
    file.open(/*delayLoad=*/false);
    if (file.hasGrid("liquid")) base = file.readGrid("liquid");
    file.close();
  } catch (const std::exception& e) {
    throw std::runtime_error("readLiquidGrid: cannot read '" + path + "': " + e.what());
  }
  auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
  if (!grid) throw std::runtime_error("readLiquidGrid: no float grid 'liquid' in '" + path + "'");
  return grid;
}

// ---- preview render ---------------------------------------------------------------------------

PreviewCamera frameWorldBBox(const openvdb::BBoxd& box, double aspect, const Vec3d& viewDirection,
                             double fovDegrees, const Vec3d& up) {
  if (!(aspect > 0.0)) throw std::invalid_argument("frameWorldBBox: aspect must be > 0");
  if (!(fovDegrees > 0.0 && fovDegrees < 180.0))
    throw std::invalid_argument("frameWorldBBox: fovDegrees must be in (0, 180)");
  PreviewCamera cam;
  cam.fovDegrees = fovDegrees;
  cam.up = up;
  cam.target = box.getCenter();
  // Half-angle of the narrower field: tan(v/2) = tan(h/2) / aspect.
  const double tanHalfH = std::tan(0.5 * fovDegrees * openvdb::math::pi<double>() / 180.0);
  const double halfAngle = std::atan(std::min(tanHalfH, tanHalfH / aspect));
  const double radius = std::max(0.5 * box.extents().length(), 1e-6);
  // A sphere of radius r subtends half-angle asin(r / d) at distance d.
  const double distance = 1.05 * radius / std::sin(halfAngle);
  Vec3d dir = viewDirection;
  if (!(dir.length() > 0.0)) dir = Vec3d(0.0, 0.0, 1.0);
  dir.normalize();
  cam.eye = cam.target + distance * dir;
  return cam;
}

namespace {

using Intersector = openvdb::tools::LevelSetRayIntersector<openvdb::FloatGrid>;

struct Hit {
  double depth = std::numeric_limits<double>::infinity();
  Vec3d normal{0.0};
  Vec3d colour{0.0};
};

/// A level-set view of `grid` the intersector accepts (class LEVEL_SET), or nothing when the grid
/// has no active voxels. Shallow copy: shares the tree.
openvdb::FloatGrid::ConstPtr renderable(const openvdb::FloatGrid* grid) {
  if (grid == nullptr || grid->activeVoxelCount() == 0) return nullptr;
  // copyGrid() of a const grid is a const shallow copy; its metadata (the class) is its own.
  auto levelSet = std::const_pointer_cast<openvdb::FloatGrid>(
      openvdb::gridConstPtrCast<openvdb::FloatGrid>(grid->copyGrid()));
  levelSet->setGridClass(openvdb::GRID_LEVEL_SET);
  return levelSet;
}

/// Lambert shading: ambient + key light from above + headlight along the view ray, then an
/// approximate sRGB encoding (gamma 1/2.2).
std::array<std::uint8_t, 3> shade(const Hit& hit, const Vec3d& rayDir, const Vec3d& keyLight,
                                  const Vec3d& background) {
  Vec3d c = background;
  if (std::isfinite(hit.depth)) {
    Vec3d n = hit.normal;
    if (n.length() > 0.0) n.normalize();
    if (n.dot(rayDir) > 0.0) n = -n;  // face the camera
    const double light = 0.2 + 0.55 * std::max(0.0, n.dot(keyLight)) + 0.35 * std::max(0.0, -n.dot(rayDir));
    c = hit.colour * light;
  }
  std::array<std::uint8_t, 3> rgb;
  for (int a = 0; a < 3; ++a)
    rgb[a] = static_cast<std::uint8_t>(std::lround(255.0 * std::pow(std::clamp(c[a], 0.0, 1.0), 1.0 / 2.2)));
  return rgb;
}

}  // namespace

void renderPreviewPng(const std::string& path, const openvdb::FloatGrid& liquid,
                      const openvdb::FloatGrid* solid, const PreviewCamera& cam, int width,
                      int height, const PreviewStyle& style) {
  if (width <= 0 || height <= 0)
    throw std::invalid_argument("renderPreviewPng: image size must be positive for '" + path + "'");
  if (!(cam.fovDegrees > 0.0 && cam.fovDegrees < 180.0))
    throw std::invalid_argument("renderPreviewPng: fovDegrees must be in (0, 180) for '" + path + "'");

  openvdb::tools::Film film(static_cast<size_t>(width), static_cast<size_t>(height));
  const double aperture = 41.2136;  // mm; only the ratio to the focal length matters
  openvdb::tools::PerspectiveCamera camera(
      film, Vec3d(0.0), cam.eye,
      openvdb::tools::PerspectiveCamera::fieldOfViewToFocalLength(cam.fovDegrees, aperture), aperture);
  camera.lookAt(cam.target, cam.up);

  // Grids to draw, each with its colour; intersectors are built once and copied per thread.
  const std::array<openvdb::FloatGrid::ConstPtr, 2> grids{renderable(&liquid), renderable(solid)};
  const std::array<Vec3d, 2> colours{style.liquid, style.solid};
  std::array<std::optional<Intersector>, 2> shared;
  try {
    for (int g = 0; g < 2; ++g)
      if (grids[g]) shared[g].emplace(*grids[g]);
  } catch (const openvdb::Exception& e) {
    throw std::runtime_error("renderPreviewPng: cannot ray-trace a grid for '" + path + "': " + e.what());
  }

  Vec3d keyLight = Vec3d(0.4, 1.0, 0.6);
  keyLight.normalize();
  std::vector<std::uint8_t> pixels(static_cast<std::size_t>(width) * height * 3);
#pragma omp parallel
  {
    std::array<std::optional<Intersector>, 2> local;
    for (int g = 0; g < 2; ++g)
      if (shared[g]) local[g].emplace(*shared[g]);
#pragma omp for schedule(dynamic, 4)
    for (int j = 0; j < height; ++j) {
      for (int i = 0; i < width; ++i) {
        const openvdb::math::Ray<double> ray = camera.getRay(i, j);
        Hit nearest;
        for (int g = 0; g < 2; ++g) {
          if (!local[g]) continue;
          Vec3d world, normal;
          if (!local[g]->intersectsWS(ray, world, normal)) continue;
          const double depth = (world - ray.eye()).length();
          if (depth < nearest.depth) nearest = Hit{depth, normal, colours[g]};
        }
        const auto rgb = shade(nearest, ray.dir(), keyLight, style.background);
        std::uint8_t* px = &pixels[(static_cast<std::size_t>(j) * width + i) * 3];
        px[0] = rgb[0], px[1] = rgb[1], px[2] = rgb[2];
      }
    }
  }
  const std::string tmp = path + ".tmp";
  if (stbi_write_png(tmp.c_str(), width, height, 3, pixels.data(), width * 3) == 0)
    throw std::runtime_error("renderPreviewPng: cannot write '" + path + "'");
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) throw std::runtime_error("renderPreviewPng: cannot rename onto '" + path + "': " + ec.message());
}

// ---- statistics CSV ---------------------------------------------------------------------------

namespace {

/// RFC 4180 quoting for header names that contain a comma, quote or newline.
std::string csvField(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

std::string formatNumber(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

}  // namespace

StatsCsv::StatsCsv(const std::string& path, std::vector<std::string> columns)
    : path_(path), columns_(std::move(columns)) {
  if (columns_.empty()) throw std::invalid_argument("StatsCsv: no columns for '" + path_ + "'");
  for (std::size_t c = 0; c < columns_.size(); ++c)
    if (std::find(columns_.begin(), columns_.begin() + c, columns_[c]) != columns_.begin() + c)
      throw std::invalid_argument("StatsCsv: duplicate column '" + columns_[c] + "' for '" + path_ + "'");
  file_ = std::fopen(path_.c_str(), "w");
  if (!file_) throw std::runtime_error("StatsCsv: cannot open '" + path_ + "' for writing");
  std::string header;
  for (std::size_t c = 0; c < columns_.size(); ++c) {
    if (c) header += ',';
    header += csvField(columns_[c]);
  }
  writeLine(header);
}

StatsCsv::~StatsCsv() {
  if (file_) std::fclose(file_);
}

void StatsCsv::writeLine(const std::string& line) {
  if (std::fputs(line.c_str(), file_) < 0 || std::fputc('\n', file_) == EOF || std::fflush(file_) != 0)
    throw std::runtime_error("StatsCsv: write failed on '" + path_ + "'");
}

void StatsCsv::row(const std::vector<std::pair<std::string, double>>& values) { row(values, {}); }

void StatsCsv::row(const std::vector<std::pair<std::string, double>>& values,
                   const std::vector<std::pair<std::string, std::string>>& text) {
  std::vector<std::string> fields(columns_.size());
  auto field = [&](const std::string& name) -> std::string& {
    const auto it = std::find(columns_.begin(), columns_.end(), name);
    if (it == columns_.end())
      throw std::invalid_argument("StatsCsv: unknown column '" + name + "' for '" + path_ + "'");
    return fields[static_cast<std::size_t>(it - columns_.begin())];
  };
  for (const auto& [name, value] : values) field(name) = formatNumber(value);
  for (const auto& [name, value] : text) field(name) = csvField(value);
  std::string line;
  for (std::size_t c = 0; c < fields.size(); ++c) {
    if (c) line += ',';
    line += fields[c];
  }
  writeLine(line);
  ++rows_;
}

void StatsCsv::row(const std::vector<double>& values) {
  if (values.size() != columns_.size())
    throw std::invalid_argument("StatsCsv: " + std::to_string(values.size()) + " values for " +
                                std::to_string(columns_.size()) + " columns in '" + path_ + "'");
  std::string line;
  for (std::size_t c = 0; c < values.size(); ++c) {
    if (c) line += ',';
    line += formatNumber(values[c]);
  }
  writeLine(line);
  ++rows_;
}

}  // namespace stokes::sim
