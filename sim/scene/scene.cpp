#include "sim/scene/scene.h"

#include "sim/scene/checked_json.h"
#include "sparse_grid/tiling.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <set>
#include <sstream>
#include <string_view>
#include <utility>

namespace stokes::sim {
inline namespace scene {

namespace fs = std::filesystem;

namespace {

// ---- limits -------------------------------------------------------------------------------------
// Sane bounds: anything outside them is a typo or an attack, not a scene.

constexpr std::uintmax_t kMaxSceneFileBytes = 16u << 20;  // 16 MiB
constexpr double kBig = 1e6;  // metres, seconds, m/s: anything larger is not a scene

constexpr Range kCoordinate{-kBig, kBig, false};
constexpr Range kLength{0.0, kBig, true};
constexpr Range kVelocity{-1e4, 1e4, false};
constexpr Range kAcceleration{-1e4, 1e4, false};
constexpr Range kTime{0.0, 1e7, false};
constexpr Range kAngle{-36000.0, 36000.0, false};
constexpr Range kScale{0.0, kBig, true};
constexpr Range kDensity{0.0, 1e7, true};
constexpr Range kViscosity{0.0, 1e12, false};
constexpr Range kFps{0.0, 1e5, true};
constexpr Range kCfl{0.0, 100.0, true};
constexpr Range kTolerance{0.0, 0.5, true};
constexpr Range kFraction{0.0, 1.0, false};

constexpr IntRange kResolution{1, 4096};
constexpr IntRange kFrames{1, 1'000'000};
constexpr IntRange kSubsteps{1, 100'000};
constexpr IntRange kTile{2, 256};
constexpr IntRange kPadding{1, 255};
constexpr IntRange kBand{0, 64};
constexpr IntRange kMinRegion{1, 4096};
constexpr IntRange kTileMin{0, 256};
constexpr IntRange kSmootherDegree{0, 16};
constexpr IntRange kIterations{1, 100'000'000};
constexpr IntRange kParticlesPerAxis{1, 8};
constexpr IntRange kPixels{16, 16384};
constexpr IntRange kRetries{0, 10};
constexpr IntRange kMeshSubdivisions{0, 3};
constexpr IntRange kCheckpointEvery{0, 1'000'000};
constexpr IntRange kSeed{0, std::numeric_limits<std::int64_t>::max()};

/// `max` must exceed `min` on every axis (boxes, the domain).
void requireOrderedCorners(const ObjectReader& r, const Vec3d& lo, const Vec3d& hi) {
  for (int a = 0; a < 3; ++a)
    if (!(hi[a] > lo[a]))
      fail(r.context(), itemPath(r.pathOf("max"), a),
           "expected a value greater than " + itemPath(r.pathOf("min"), a) + " (= " + formatNumber(lo[a]) +
               "), got " + formatNumber(hi[a]));
}

bool boxesOverlap(const Vec3d& aMin, const Vec3d& aMax, const Vec3d& bMin, const Vec3d& bMax) {
  for (int a = 0; a < 3; ++a)
    if (aMax[a] <= bMin[a] || bMax[a] <= aMin[a]) return false;
  return true;
}

double distanceToBox(const Vec3d& p, const Vec3d& lo, const Vec3d& hi) {
  Vec3d d;
  for (int a = 0; a < 3; ++a) d[a] = std::max({lo[a] - p[a], 0.0, p[a] - hi[a]});
  return d.length();
}

std::string boxText(const Vec3d& lo, const Vec3d& hi) {
  auto v = [](const Vec3d& p) {
    return "[" + formatNumber(p[0]) + ", " + formatNumber(p[1]) + ", " + formatNumber(p[2]) + "]";
  };
  return v(lo) + " - " + v(hi);
}

// ---- sections -----------------------------------------------------------------------------------

void parseDomain(const ObjectReader& r, Scene& s) {
  r.allowOnly({"min", "max", "open_top"});
  s.domainMin = r.vec3("min", kCoordinate);
  s.domainMax = r.vec3("max", kCoordinate);
  requireOrderedCorners(r, s.domainMin, s.domainMax);
  s.openTop = r.boolean("open_top", false);
}

void parseMaterial(const ObjectReader& r, Scene& s) {
  r.allowOnly({"density", "viscosity"});
  s.material.density = r.number("density", kDensity);
  s.material.viscosity = r.number("viscosity", kViscosity);
}

void parseModel(const ObjectReader& r, ModelDesc& m) {
  r.allowOnly({"type", "tile", "padding", "band_air", "band_solid", "min_region", "tile_cache", "tile_min", "tile_accuracy",
              "tile_rule"});
  m.type = r.named("type", ModelType::Uniform);
  m.tile = static_cast<int>(r.integer("tile", kTile, m.tile));
  m.padding = static_cast<int>(r.integer("padding", kPadding, m.padding));
  if (m.padding >= m.tile)
    fail(r.context(), r.pathOf("padding"),
         "expected a padding smaller than the tile (" + std::to_string(m.tile) + "), got " + std::to_string(m.padding));
  m.bandAir = static_cast<int>(r.integer("band_air", kBand, m.bandAir));
  m.bandSolid = static_cast<int>(r.integer("band_solid", kBand, m.bandSolid));
  m.minRegion = static_cast<int>(r.integer("min_region", kMinRegion, m.minRegion));
  m.tileCache = r.named("tile_cache", m.tileCache);
  m.tileMin = static_cast<int>(r.integer("tile_min", kTileMin, m.tileMin));
  m.tileAccuracy = r.number("tile_accuracy", kFraction, m.tileAccuracy);
  m.tileRule = r.namedOrAuto<solver::TileRule>("tile_rule");
  if ((m.tileMin > 0) != (m.tileAccuracy > 0.0))
    fail(r.context(), r.pathOf(m.tileMin > 0 ? "tile_accuracy" : "tile_min"),
         "expected tile_min and tile_accuracy together (adaptive tiles), got tile_min " + std::to_string(m.tileMin) +
             " and tile_accuracy " + std::to_string(m.tileAccuracy));
  sparse_grid::TilingOptions tiling;  // the octree's edges: tile = tile_min 2^k, tile_min > padding
  tiling.tileSize = m.tile;
  tiling.padding = m.padding;
  tiling.minTileSize = m.tileMin;
  try {
    tiling.validate();
  } catch (const std::invalid_argument& e) {
    fail(r.context(), r.pathOf("tile_min"), e.what());
  }
}

void parseSolver(const ObjectReader& r, SolverDesc& s) {
  r.allowOnly({"tolerance", "max_iterations", "preconditioner", "rows", "stencils", "multigrid_degree",
               "multigrid_method", "warm_start", "retries", "backend"});
  s.tolerance = r.number("tolerance", kTolerance, s.tolerance);
  s.maxIterations = static_cast<int>(r.integer("max_iterations", kIterations, s.maxIterations));
  s.preconditioner = r.namedOrAuto<solver::PreconditionerKind>("preconditioner");
  s.rows = r.named("rows", s.rows);
  using solver::StencilSweep;
  s.rowStencils = r.named("stencils", s.rowStencils ? StencilSweep::Rows : StencilSweep::Blocks) == StencilSweep::Rows;
  s.warmStart = r.boolean("warm_start", s.warmStart);
  s.multigridDegree = static_cast<int>(r.integer("multigrid_degree", kSmootherDegree, s.multigridDegree));
  // the methods of the symmetric indefinite pressure-velocity form (CG does not apply there)
  using solver::KrylovMethod, solver::keyOf;
  using Method = std::optional<KrylovMethod>;
  s.multigridMethod = r.choice<Method>("multigrid_method",
                                       {{"auto", std::nullopt},
                                        {keyOf(KrylovMethod::GMRES), KrylovMethod::GMRES},
                                        {keyOf(KrylovMethod::MINRES), KrylovMethod::MINRES},
                                        {keyOf(KrylovMethod::FGMRES), KrylovMethod::FGMRES},
                                        {keyOf(KrylovMethod::BiCGSTAB), KrylovMethod::BiCGSTAB}},
                                       s.multigridMethod);
  s.retries = static_cast<int>(r.integer("retries", kRetries, s.retries));
  s.backend = r.named("backend", s.backend);
}

enum class ShapeRole { Liquid, Solid };

/// Resolves a mesh path against the scene's directory and checks that the file is there.
std::string resolveMeshFile(const ObjectReader& r) {
  const std::string file = r.string("file");
  if (file.empty()) fail(r.context(), r.pathOf("file"), "expected the path of an OBJ file, got \"\"");
  fs::path p(file);
  if (p.is_relative() && !r.context().baseDir.empty()) p = fs::path(r.context().baseDir) / p;
  p = p.lexically_normal();
  std::error_code ec;
  if (!fs::is_regular_file(p, ec))
    fail(r.context(), r.pathOf("file"),
         "expected an existing OBJ file (relative paths start at the scene file's directory), got \"" + file +
             "\" (looked for " + p.string() + ")");
  return p.string();
}

ShapeDesc parseShape(const json& v, const Context& ctx, const std::string& path, ShapeRole role) {
  const ObjectReader r(v, ctx, path, "a shape object {\"shape\": ...}");
  using K = ShapeDesc::Kind;
  ShapeDesc s;
  s.kind = role == ShapeRole::Liquid
               ? r.choice<K>("shape", {{"box", K::Box}, {"sphere", K::Sphere}, {"mesh", K::Mesh}})
               : r.choice<K>("shape", {{"box", K::Box}, {"sphere", K::Sphere}, {"plane", K::Plane}, {"mesh", K::Mesh}});
  const std::string forKind = std::string(" for a ") + toString(s.kind);
  switch (s.kind) {
    case K::Box:
      r.allowOnly({"shape", "min", "max", "velocity"}, forKind);
      s.min = r.vec3("min", kCoordinate);
      s.max = r.vec3("max", kCoordinate);
      requireOrderedCorners(r, s.min, s.max);
      break;
    case K::Sphere:
      r.allowOnly({"shape", "center", "radius", "velocity"}, forKind);
      s.center = r.vec3("center", kCoordinate);
      s.radius = r.number("radius", kLength);
      break;
    case K::Plane:
      r.allowOnly({"shape", "point", "normal", "velocity"}, forKind);
      s.point = r.vec3("point", kCoordinate);
      s.normal = r.direction("normal");
      break;
    case K::Mesh:
      r.allowOnly({"shape", "file", "scale", "rotation_degrees", "translation", "velocity"}, forKind);
      s.meshPath = resolveMeshFile(r);
      s.placement.scale = r.number("scale", kScale, 1.0);
      s.placement.rotationDegrees = r.vec3("rotation_degrees", kAngle, Vec3d(0.0));
      s.placement.translation = r.vec3("translation", kCoordinate, Vec3d(0.0));
      break;
  }
  s.velocity = r.vec3("velocity", kVelocity, Vec3d(0.0));
  return s;
}

/// Initial liquid must touch the domain, or the scene starts empty by mistake. (Meshes are not
/// checked here: their extent is only known once the OBJ file is read.)
void requireLiquidInDomain(const ShapeDesc& s, const Scene& scene, const Context& ctx, const std::string& path) {
  const bool outside =
      (s.kind == ShapeDesc::Kind::Box && !boxesOverlap(s.min, s.max, scene.domainMin, scene.domainMax)) ||
      (s.kind == ShapeDesc::Kind::Sphere && distanceToBox(s.center, scene.domainMin, scene.domainMax) >= s.radius);
  if (outside)
    fail(ctx, path, std::string("expected a ") + toString(s.kind) + " overlapping the domain " +
                        boxText(scene.domainMin, scene.domainMax) + ", but it lies entirely outside");
}

void parseShapes(const ObjectReader& root, const char* key, ShapeRole role, Scene& scene) {
  auto& out = role == ShapeRole::Liquid ? scene.liquid : scene.solids;
  root.forEachItem(key, [&](const json& item, const std::string& path) {
    out.push_back(parseShape(item, root.context(), path, role));
    if (role == ShapeRole::Liquid) requireLiquidInDomain(out.back(), scene, root.context(), path);
  });
}

EmitterDesc parseEmitter(const json& v, const Context& ctx, const std::string& path, const Scene& scene) {
  const ObjectReader r(v, ctx, path, "an emitter object {\"shape\": ...}");
  using K = EmitterDesc::Kind;
  EmitterDesc e;
  e.kind = r.choice<K>("shape", {{"disc", K::Disc}, {"box", K::Box}});
  if (e.kind == K::Disc) {
    r.allowOnly({"shape", "center", "radius", "normal", "thickness", "velocity", "start", "stop"}, " for a disc");
    e.center = r.vec3("center", kCoordinate);
    e.radius = r.number("radius", kLength);
    e.normal = r.direction("normal");
    e.thickness = r.number("thickness", kLength, scene.dx());
    if (distanceToBox(e.center, scene.domainMin, scene.domainMax) > 0.0)
      fail(ctx, r.pathOf("center"), "expected a point inside the domain " + boxText(scene.domainMin, scene.domainMax));
  } else {
    r.allowOnly({"shape", "min", "max", "velocity", "start", "stop"}, " for a box");
    e.min = r.vec3("min", kCoordinate);
    e.max = r.vec3("max", kCoordinate);
    requireOrderedCorners(r, e.min, e.max);
    if (!boxesOverlap(e.min, e.max, scene.domainMin, scene.domainMax))
      fail(ctx, path, "expected a box overlapping the domain " + boxText(scene.domainMin, scene.domainMax) +
                          ", but it lies entirely outside");
  }
  e.velocity = r.vec3("velocity", kVelocity);
  e.start = r.number("start", kTime, 0.0);
  if (r.has("stop")) {
    e.stop = r.number("stop", kTime);
    if (!(e.stop > e.start))
      fail(ctx, r.pathOf("stop"), "expected a time after start (" + formatNumber(e.start) + " s), got " +
                                      formatNumber(e.stop));
  }
  return e;
}

void parseEmitters(const ObjectReader& root, Scene& scene) {
  root.forEachItem("emitters", [&](const json& item, const std::string& path) {
    scene.emitters.push_back(parseEmitter(item, root.context(), path, scene));
  });
}

void parseOutput(const ObjectReader& r, OutputDesc& o) {
  r.allowOnly(
      {"particles", "preview", "preview_width", "preview_height", "camera", "checkpoint_every", "mesh",
       "mesh_subdivisions", "up_axis"});
  o.mesh = r.boolean("mesh", o.mesh);
  o.meshSubdivisions = static_cast<int>(r.integer("mesh_subdivisions", kMeshSubdivisions, o.meshSubdivisions));
  o.zUp = r.choice<bool>("up_axis", {{"y", false}, {"z", true}}, o.zUp);
  o.checkpointEvery = static_cast<int>(r.integer("checkpoint_every", kCheckpointEvery, o.checkpointEvery));
  o.particles = r.boolean("particles", o.particles);
  o.preview = r.boolean("preview", o.preview);
  o.previewWidth = static_cast<int>(r.integer("preview_width", kPixels, o.previewWidth));
  o.previewHeight = static_cast<int>(r.integer("preview_height", kPixels, o.previewHeight));
  if (const auto camera = r.optionalObject("camera", "an object {\"eye\": [x, y, z], \"target\": [x, y, z]}")) {
    camera->allowOnly({"eye", "target"});
    CameraDesc c;
    c.eye = camera->vec3("eye", kCoordinate);
    c.target = camera->vec3("target", kCoordinate);
    if ((c.eye - c.target).length() <= 0.0)
      fail(r.context(), camera->pathOf("target"), "expected a target different from the eye position");
    o.camera = c;
  }
}

/// The file's value, or the override checked against the same range.
int resolutionOrOverride(const ObjectReader& root, const char* key, const IntRange& range,
                         const std::optional<int>& override) {
  if (!override) return static_cast<int>(root.integer(key, range));
  if (root.has(key)) root.integer(key, range);  // the file's own value is still checked
  return static_cast<int>(readInteger(json(*override), root.context(), std::string(key) + " (override)", range));
}

void requireSomeLiquid(const ObjectReader& root, const Scene& s) {
  if (s.liquid.empty() && s.emitters.empty())
    fail(root.context(), "liquid",
         "expected at least one liquid shape or emitter (the scene has neither \"liquid\" nor \"emitters\")");
}

// ---- JSON text ----------------------------------------------------------------------------------

/// SAX handler that builds the DOM (nlohmann's own builder) and rejects duplicate keys, which the
/// DOM parser would otherwise resolve silently by keeping the last value.
class StrictSax {
 public:
  using Dom = nlohmann::detail::json_sax_dom_parser<json>;
  explicit StrictSax(json& root) : dom_(root) {}

  bool null() { return value() && dom_.null(); }
  bool boolean(bool v) { return value() && dom_.boolean(v); }
  bool number_integer(json::number_integer_t v) { return value() && dom_.number_integer(v); }
  bool number_unsigned(json::number_unsigned_t v) { return value() && dom_.number_unsigned(v); }
  bool number_float(json::number_float_t v, const std::string& s) { return value() && dom_.number_float(v, s); }
  bool string(std::string& v) { return value() && dom_.string(v); }
  bool binary(json::binary_t& v) { return value() && dom_.binary(v); }
  bool start_object(std::size_t n) {
    value();
    frames_.push_back({false, {}, {}, 0});
    return dom_.start_object(n);
  }
  bool end_object() {
    frames_.pop_back();
    return dom_.end_object();
  }
  bool start_array(std::size_t n) {
    value();
    frames_.push_back({true, {}, {}, 0});
    return dom_.start_array(n);
  }
  bool end_array() {
    frames_.pop_back();
    return dom_.end_array();
  }
  bool key(std::string& k) {
    Frame& f = frames_.back();
    f.lastKey = k;
    if (!f.keys.insert(k).second) {
      duplicatePath_ = currentPath();
      return false;  // stops the parse
    }
    return dom_.key(k);
  }
  template <class Exception>
  bool parse_error(std::size_t position, const std::string& token, const Exception& ex) {
    return dom_.parse_error(position, token, ex);
  }

  const std::string& duplicatePath() const { return duplicatePath_; }

  /// Path of the value being read when the parser stopped (the next element or the last key).
  std::string pendingValuePath() const {
    std::string path;
    for (std::size_t i = 0; i < frames_.size(); ++i) {
      const Frame& f = frames_[i];
      const bool last = i + 1 == frames_.size();
      path = f.isArray ? itemPath(path, last ? f.index : f.index - 1) : childPath(path, f.lastKey);
    }
    return path;
  }

 private:
  struct Frame {
    bool isArray;
    std::set<std::string> keys;
    std::string lastKey;
    std::size_t index;
  };

  /// Counts array elements so that paths can name them.
  bool value() {
    if (!frames_.empty() && frames_.back().isArray) ++frames_.back().index;
    return true;
  }

  std::string currentPath() const {
    std::string path;
    for (const Frame& f : frames_)
      path = f.isArray ? itemPath(path, f.index - 1) : childPath(path, f.lastKey);
    return path;
  }

  Dom dom_;
  std::vector<Frame> frames_;
  std::string duplicatePath_;
};

/// Line and column (1-based) of a byte offset.
std::pair<std::size_t, std::size_t> lineColumn(const std::string& text, std::size_t byte) {
  std::size_t line = 1, column = 1;
  for (std::size_t i = 0; i < std::min(byte, text.size()); ++i) {
    if (text[i] == '\n') ++line, column = 1;
    else ++column;
  }
  return {line, column};
}

/// nlohmann quotes everything it read of a bad token ("last read: '<whole string>'"); keep the end.
std::string shortenedLastRead(std::string what) {
  constexpr std::size_t kKept = 40;
  const std::string marker = "last read: '";
  const std::size_t start = what.find(marker);
  if (start == std::string::npos) return what;
  const std::size_t from = start + marker.size();
  std::size_t to = what.rfind("'; expected");
  if (to == std::string::npos || to < from) to = what.size() - (what.back() == '\'' ? 1 : 0);
  if (to - from > kKept) what.replace(from, to - from - kKept, "...");
  return what;
}

json parseJsonText(const std::string& text, const Context& ctx) {
  json root;
  StrictSax sax(root);
  try {
    json::sax_parse(text, &sax);
  } catch (const json::parse_error& e) {
    const std::string what = shortenedLastRead(e.what());
    const std::size_t detail = what.find("syntax error");
    const std::size_t byte = e.byte > 0 ? e.byte - 1 : 0;  // nlohmann counts from 1
    const auto [line, column] = lineColumn(text, byte);
    throw SceneError(ctx.source + ": line " + std::to_string(line) + ", column " + std::to_string(column) +
                     " (byte " + std::to_string(byte) + "): JSON " +
                     (detail == std::string::npos ? std::string("error: ") + what : what.substr(detail)));
  } catch (const json::out_of_range& e) {  // a number literal beyond the range of a double
    const std::string what = e.what();
    const std::size_t detail = what.find("] ");
    fail(ctx, sax.pendingValuePath(),
         "expected a number, got " + (detail == std::string::npos ? what : what.substr(detail + 2)));
  } catch (const json::exception& e) {
    throw SceneError(ctx.source + ": invalid JSON: " + e.what());
  }
  if (!sax.duplicatePath().empty())
    fail(ctx, sax.duplicatePath(), "duplicate key (each key may appear once per object)");
  return root;
}

Scene parseWithContext(const json& j, const Context& ctx, const SceneOverrides& overrides) {
  const ObjectReader root(j, ctx, "", "a JSON object {\"name\": ..., \"domain\": ..., ...}");
  // "$schema": the JSON Schema editors check the file against (scenes/scene.schema.json); ignored
  root.allowOnly({"$schema", "name", "description", "domain", "resolution", "frames", "fps", "cfl", "max_substeps",
                  "material", "gravity", "viscosity", "model", "solver", "particles_per_cell_axis", "reseed",
                  "keep_volume", "volume_control", "liquid_weights", "liquid", "solids", "emitters", "output", "seed"});
  Scene s;
  s.name = root.string("name");
  s.description = root.string("description", TextKind::Paragraph, "");
  parseDomain(root.object("domain", "an object {\"min\": [x, y, z], \"max\": [x, y, z]}"), s);
  s.resolution = resolutionOrOverride(root, "resolution", kResolution, overrides.resolution);
  s.frames = resolutionOrOverride(root, "frames", kFrames, overrides.frames);
  s.fps = root.number("fps", kFps, s.fps);
  s.cfl = root.number("cfl", kCfl, s.cfl);
  s.maxSubsteps = static_cast<int>(root.integer("max_substeps", kSubsteps, s.maxSubsteps));
  parseMaterial(root.object("material", "an object {\"density\": rho, \"viscosity\": mu}"), s);
  s.gravity = root.optionalVec3("gravity", kAcceleration);
  {
    const auto& k = kViscosityModeNames;
    static_assert(std::size(kViscosityModeNames) == 3);
    s.system = root.choice<solver::SystemKind>(
        "viscosity", {{k[0].key, k[0].value}, {k[1].key, k[1].value}, {k[2].key, k[2].value}}, s.system);
  }
  if (const auto model = root.optionalObject("model", "an object {\"type\": ...}")) parseModel(*model, s.model);
  if (const auto solver = root.optionalObject("solver", "an object {\"tolerance\": ...}")) parseSolver(*solver, s.solver);
  s.particlesPerCellAxis = static_cast<int>(root.integer("particles_per_cell_axis", kParticlesPerAxis, 2));
  s.reseed = root.boolean("reseed", s.reseed);
  s.keepVolume = root.boolean("keep_volume", s.keepVolume);
  s.volumeControl = root.number("volume_control", kFraction, s.volumeControl);
  s.liquidWeights = root.choice<sparse_grid::FractionRule>(
      "liquid_weights",
      {{sparse_grid::fractionRuleName(sparse_grid::FractionRule::SubSamples), sparse_grid::FractionRule::SubSamples},
       {sparse_grid::fractionRuleName(sparse_grid::FractionRule::PlaneCut), sparse_grid::FractionRule::PlaneCut}},
      s.liquidWeights);
  parseShapes(root, "liquid", ShapeRole::Liquid, s);
  parseShapes(root, "solids", ShapeRole::Solid, s);
  parseEmitters(root, s);
  requireSomeLiquid(root, s);
  if (const auto output = root.optionalObject("output", "an object {\"preview\": ...}")) parseOutput(*output, s.output);
  s.seed = static_cast<std::uint64_t>(root.integer("seed", kSeed, 1));
  return s;
}

}  // namespace

// ---- public API ---------------------------------------------------------------------------------

double Scene::dx() const {
  const Vec3d extent = domainMax - domainMin;
  return std::max({extent[0], extent[1], extent[2]}) / resolution;
}

openvdb::Coord Scene::resolutionCells() const {
  const Vec3d extent = domainMax - domainMin;
  const double longest = std::max({extent[0], extent[1], extent[2]});
  const double h = dx();
  openvdb::Coord cells;
  for (int a = 0; a < 3; ++a)
    cells[a] = extent[a] == longest ? resolution : std::max(1, static_cast<int>(std::lround(extent[a] / h)));
  return cells;
}

Scene parseScene(const json& j, const std::string& sourceName, const std::string& baseDir,
                 const SceneOverrides& overrides) {
  return parseWithContext(j, Context{sourceName, baseDir}, overrides);
}

Scene parseSceneText(const std::string& text, const std::string& sourceName, const std::string& baseDir,
                     const SceneOverrides& overrides) {
  const Context ctx{sourceName, baseDir};
  return parseWithContext(parseJsonText(text, ctx), ctx, overrides);
}

const char* viscosityModeKey(solver::SystemKind system) {
  for (const auto& v : kViscosityModeNames)
    if (v.value == system) return v.key;
  throw std::invalid_argument(std::string("no scene's viscosity mode runs the ") + solver::toString(system) +
                              " system alone");
}

solver::SystemKind parseViscosityMode(std::string_view key) {
  for (const auto& v : kViscosityModeNames)
    if (key == v.key) return v.value;
  throw std::invalid_argument("unknown viscosity mode '" + std::string(key) + "' (coupled, decoupled or none)");
}

std::vector<std::string> viscosityModeKeys() {
  std::vector<std::string> keys;
  for (const auto& v : kViscosityModeNames) keys.emplace_back(v.key);
  return keys;
}

Scene loadScene(const std::string& path, const SceneOverrides& overrides) {
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (ec || !fs::exists(status)) throw SceneError(path + ": cannot open the scene file: no such file");
  if (!fs::is_regular_file(status)) throw SceneError(path + ": cannot open the scene file: not a regular file");
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec || size > kMaxSceneFileBytes)
    throw SceneError(path + ": the scene file is larger than " + std::to_string(kMaxSceneFileBytes) +
                     " bytes; scene files describe shapes, not data");
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  if (!(in && text << in.rdbuf())) throw SceneError(path + ": cannot read the scene file");
  Scene s = parseSceneText(text.str(), path, fs::path(path).parent_path().string(), overrides);
  s.sourcePath = path;
  return s;
}

}  // namespace scene
}  // namespace stokes::sim
