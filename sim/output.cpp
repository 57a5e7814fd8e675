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
#include <cstdlib>
#include <filesystem>
#include <fstream>
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
                   const std::vector<Vec3d>* particles, const std::vector<Vec3d>* velocities, UpAxis up) {
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
    std::vector<Vec3d> turned;  // velocities in the output frame
    if (velocities && up != UpAxis::Y) {
      turned.reserve(velocities->size());
      for (const Vec3d& v : *velocities) turned.push_back(toUpAxis(v, up));
      velocities = &turned;
    }
    if (particles) grids.push_back(makePointsGrid(*particles, velocities, liquid->constTransform()));
    if (up == UpAxis::Z) {
      // index -> y-up world -> z-up world: a +90 degree turn about x after the grid's own map
      openvdb::math::Transform::Ptr xform = liquid->constTransform().copy();
      xform->postRotate(0.5 * M_PI, openvdb::math::X_AXIS);
      for (openvdb::GridBase::Ptr& g : grids) g->setTransform(xform);
    }
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

namespace {

/// The floor of `box` (its y = min face) where `ray` meets it before `nearest`: a checkered hit.
void hitFloor(const openvdb::math::Ray<double>& ray, const openvdb::BBoxd& box, const PreviewStyle& style,
              Hit& nearest) {
  const double dy = ray.dir().y();
  if (!(std::abs(dy) > 1e-12)) return;
  const double t = (box.min().y() - ray.eye().y()) / dy;
  if (!(t > 0.0)) return;
  const Vec3d x = ray.eye() + t * ray.dir();
  if (x.x() < box.min().x() || x.x() > box.max().x() || x.z() < box.min().z() || x.z() > box.max().z()) return;
  const double depth = (x - ray.eye()).length();
  if (depth >= nearest.depth) return;
  const double check = std::max(box.extents().x(), box.extents().z()) / 8.0;
  const long ix = std::lround(std::floor((x.x() - box.min().x()) / check));
  const long iz = std::lround(std::floor((x.z() - box.min().z()) / check));
  nearest = Hit{depth, Vec3d(0.0, 1.0, 0.0), (ix + iz) % 2 == 0 ? style.floorLight : style.floorDark};
}

/// Whether `ray` passes within `halfWidth(depth)` of an edge of `box` nearer than `depth`.
template <class HalfWidth>
bool onBoxEdge(const openvdb::math::Ray<double>& ray, const openvdb::BBoxd& box, double depth, HalfWidth halfWidth) {
  const Vec3d lo = box.min(), hi = box.max();
  for (int a = 0; a < 3; ++a)
    for (int k = 0; k < 4; ++k) {
      // the edge along axis a at the corner (b, c) = (k & 1, k >> 1) of the other two axes
      Vec3d p0 = lo;
      const int b = (a + 1) % 3, c = (a + 2) % 3;
      p0[b] = (k & 1) ? hi[b] : lo[b];
      p0[c] = (k >> 1) ? hi[c] : lo[c];
      Vec3d e(0.0);
      e[a] = hi[a] - lo[a];
      // closest points of the ray eye + t d (t >= 0) and the segment p0 + s e (0 <= s <= 1)
      const Vec3d d = ray.dir(), w = ray.eye() - p0;
      const double ee = e.dot(e), de = d.dot(e), dd = d.dot(d), dw = d.dot(w), ew = e.dot(w);
      const double denom = dd * ee - de * de;
      if (!(denom > 1e-18)) continue;
      const double s = std::clamp((dd * ew - de * dw) / denom, 0.0, 1.0);
      const double t = std::max((de * s - dw) / dd, 0.0);
      const Vec3d onRay = ray.eye() + t * d, onEdge = p0 + s * e;
      const double along = (onRay - ray.eye()).length();
      if (along < depth && (onRay - onEdge).length() < halfWidth(along)) return true;
    }
  return false;
}

}  // namespace

void renderPreviewPng(const std::string& path, const openvdb::FloatGrid& liquid,
                      const openvdb::FloatGrid* solid, const PreviewCamera& cam, int width,
                      int height, const PreviewStyle& style, const openvdb::BBoxd* domain) {
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
  // the angle one pixel spans (horizontal field over the width; rays are unit length)
  const double pixelAngle = 2.0 * std::tan(0.5 * cam.fovDegrees * openvdb::math::pi<double>() / 180.0) / width;
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
        if (domain) hitFloor(ray, *domain, style, nearest);
        auto rgb = shade(nearest, ray.dir(), keyLight, style.background);
        if (domain && onBoxEdge(ray, *domain, nearest.depth, [&](double depth) { return 0.75 * pixelAngle * depth; }))
          rgb = shade(Hit{0.0, -ray.dir(), style.edges}, ray.dir(), keyLight, style.background);
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

namespace {

std::string csvHeader(const std::vector<std::string>& columns) {
  std::string header;
  for (std::size_t c = 0; c < columns.size(); ++c) {
    if (c) header += ',';
    header += csvField(columns[c]);
  }
  return header;
}

/// The fields of a CSV line (RFC 4180 quoting undone).
std::vector<std::string> csvFields(const std::string& line) {
  std::vector<std::string> fields(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') fields.back() += line[++i];
      else if (c == '"') quoted = false;
      else fields.back() += c;
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      fields.emplace_back();
    } else {
      fields.back() += c;
    }
  }
  return fields;
}

}  // namespace

void StatsCsv::checkColumns() const {
  if (columns_.empty()) throw std::invalid_argument("StatsCsv: no columns for '" + path_ + "'");
  for (std::size_t c = 0; c < columns_.size(); ++c)
    if (std::find(columns_.begin(), columns_.begin() + c, columns_[c]) != columns_.begin() + c)
      throw std::invalid_argument("StatsCsv: duplicate column '" + columns_[c] + "' for '" + path_ + "'");
}

StatsCsv::StatsCsv(const std::string& path, std::vector<std::string> columns)
    : path_(path), columns_(std::move(columns)) {
  checkColumns();
  file_ = std::fopen(path_.c_str(), "w");
  if (!file_) throw std::runtime_error("StatsCsv: cannot open '" + path_ + "' for writing");
  writeLine(csvHeader(columns_));
}

StatsCsv::StatsCsv(StatsCsv&& other) noexcept
    : path_(std::move(other.path_)), columns_(std::move(other.columns_)), file_(other.file_), rows_(other.rows_) {
  other.file_ = nullptr;
}

StatsCsv StatsCsv::resume(const std::string& path, std::vector<std::string> columns, const std::string& keyColumn,
                          double keyLimit) {
  StatsCsv csv;
  csv.path_ = path;
  csv.columns_ = std::move(columns);
  csv.checkColumns();
  const auto key = std::find(csv.columns_.begin(), csv.columns_.end(), keyColumn);
  if (key == csv.columns_.end())
    throw std::invalid_argument("StatsCsv::resume: unknown column '" + keyColumn + "' for '" + path + "'");
  std::ifstream in(path);
  if (!in) throw std::runtime_error("StatsCsv: cannot read '" + path + "' to resume it");
  std::string line, kept;
  if (!std::getline(in, line) || line != csvHeader(csv.columns_))
    throw std::runtime_error("StatsCsv: '" + path + "' has other columns than this build writes; move it away to resume");
  kept = line + '\n';
  while (std::getline(in, line)) {
    // a row cut short by a killed process (its last) lacks fields, or its key may be cut: dropped
    const std::vector<std::string> fields = csvFields(line);
    if (fields.size() != csv.columns_.size()) continue;
    const std::string& field = fields[std::size_t(key - csv.columns_.begin())];
    char* end = nullptr;
    const double value = std::strtod(field.c_str(), &end);
    if (field.empty() || end != field.c_str() + field.size() || !(value < keyLimit)) continue;
    kept += line + '\n';
    ++csv.rows_;
  }
  in.close();
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << kept;
    out.close();
    if (!out) {
      std::error_code ignored;
      std::filesystem::remove(tmp, ignored);
      throw std::runtime_error("StatsCsv: cannot write '" + tmp + "'");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) throw std::runtime_error("StatsCsv: cannot rename onto '" + path + "': " + ec.message());
  csv.file_ = std::fopen(path.c_str(), "a");
  if (!csv.file_) throw std::runtime_error("StatsCsv: cannot open '" + path + "' for appending");
  return csv;
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
