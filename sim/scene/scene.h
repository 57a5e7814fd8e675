#pragma once
// Scene files (JSON, schema in scenes/README.md) read into a validated Scene.
//
// Every problem with a scene file is a SceneError whose message names the file, the JSON key path
// and what was expected, e.g.
//   honey_coil.json: emitters[0].radius: expected a positive number, got -1
// JSON syntax errors report the line, column and byte. Unknown keys are errors (with a "did you
// mean" suggestion when a known key is close), so a misspelt optional key never silently falls back
// to its default. Values are range-checked against sane limits (resolution <= 4096, frames <= 1e6,
// ...), so a Scene that parses can be handed to the simulator without further checks.
#include <nlohmann/json_fwd.hpp>
#include "sparse_grid/vdb_trees.h"

#include <cstdint>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "sim/scene/shapes.h"
#include "solver/step/solve_plan.h"
#include "sparse_grid/volume_weights.h"

namespace stokes::sim {
inline namespace scene {

/// Thrown for every problem with a scene file; the message names the file and the key path.
class SceneError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Velocity model of the solved region (docs/design.md §3).
enum class ModelType { Uniform, Affine, Quadratic };

/// Tile factorisation cache (solver/reduced/tile_library.h TileCacheStrategy).
enum class TileCache { None, Library, Shapes };

// The names a scene file uses (and the start line prints); the solver's options (preconditioner,
// rows, backend) are named by solver/step/solve_plan.h.
inline constexpr solver::NamedValue<ModelType> kModelTypeNames[] = {{ModelType::Uniform, "uniform", "uniform"},
                                                                   {ModelType::Affine, "affine", "affine"},
                                                                   {ModelType::Quadratic, "quadratic", "quadratic"}};
inline constexpr solver::NamedValue<TileCache> kTileCacheNames[] = {
    {TileCache::None, "none", "none"}, {TileCache::Library, "library", "library"}, {TileCache::Shapes, "shapes", "shapes"}};
static_assert(solver::listsEveryValueInOrder(kModelTypeNames, ModelType::Quadratic));
static_assert(solver::listsEveryValueInOrder(kTileCacheNames, TileCache::Shapes));
constexpr std::span<const solver::NamedValue<ModelType>> namesOf(ModelType) { return kModelTypeNames; }
constexpr std::span<const solver::NamedValue<TileCache>> namesOf(TileCache) { return kTileCacheNames; }
using solver::toString;  // the label of any named value: toString(ModelType::Affine) is "affine"

/// How pressure and viscosity are solved is the solver's choice of system (solver::SystemKind);
/// a scene names it by its key "viscosity" in these words:
///   "coupled"    unified Stokes, pressure and stresses in one solve;
///   "decoupled"  a viscosity solve, then a pressure projection;
///   "none"       inviscid: a pressure projection only, the material's viscosity unused.
inline constexpr solver::NamedValue<solver::SystemKind> kViscosityModeNames[] = {
    {solver::SystemKind::UnifiedStokes, "coupled", "coupled"},
    {solver::SystemKind::DecoupledStokes, "decoupled", "decoupled"},
    {solver::SystemKind::PressureProjection, "none", "none"}};
/// The scene word for `system` (one of kViscosityModeNames; a viscosity solve alone is no scene's).
const char* viscosityModeKey(solver::SystemKind system);
/// The system a scene word names; std::invalid_argument naming the words for any other.
solver::SystemKind parseViscosityMode(std::string_view key);
/// The scene words, for a command line's choices.
std::vector<std::string> viscosityModeKeys();

struct MaterialDesc {
  double density = 0.0;    ///< rho > 0 (kg/m^3)
  double viscosity = 0.0;  ///< dynamic viscosity mu >= 0 (Pa s)
};

/// Reduced-model tiling (sparse_grid/tiling.h TilingOptions); unused for ModelType::Uniform.
struct ModelDesc {
  ModelType type = ModelType::Uniform;
  int tile = 16;        ///< tile edge in cells, >= 2
  int padding = 3;      ///< Cartesian slab width between tiles, 1 <= padding < tile
  int bandAir = 2;      ///< Cartesian band next to air
  int bandSolid = 2;    ///< Cartesian band next to solids
  int minRegion = 2;    ///< smallest reduced-region extent kept
  int tileMin = 0;      ///< adaptive tiles: cubes of `tile` split down to this edge (0: one edge)
  double tileAccuracy = 0.0;  ///< with tileMin: ReducedOptions::tileAccuracy
  /// "tile_rule": which tiles are kept (ReducedOptions::rule); nullopt ("auto", the default):
  /// solver::planSolve's, per step (paying tiles under the pressure-velocity multigrid, else all)
  std::optional<solver::TileRule> tileRule;
  TileCache tileCache = TileCache::Library;
};

struct SolverDesc {
  double tolerance = 1e-6;  ///< relative residual
  int maxIterations = 2000;
  /// nullopt ("auto", the default): chosen per step by the step's size (solver::planSolve)
  std::optional<solver::PreconditionerKind> preconditioner;
  solver::RowStorage rows = solver::RowStorage::Auto;
  bool rowStencils = true;  ///< "stencils": "rows" (neighbour index) or "blocks" (sweep the blocks)
  bool warmStart = true;    ///< each solve starts from the previous step's unknowns of its form
  int multigridDegree = 0;  ///< Chebyshev smoother degree of the V-cycles; 0: the preconditioner's default
  /// "multigrid_method": the Krylov method of the steps on the pressure-velocity form (the
  /// multigrid's); nullopt ("auto", the default): solver::planSolve's
  std::optional<solver::KrylovMethod> multigridMethod;
  int retries = 3;          ///< a failed step is retried at dt/2, dt/4, ... this many times
  /// Who solves: the engine's Krylov solvers, or PETSc over the MPI ranks of `mpirun -np R` (the
  /// particles and grids stay on rank 0; PETSc's options database picks method and preconditioner).
  solver::Backend backend = solver::Backend::InHouse;
};

/// Emits liquid particles with a fixed velocity while start <= t < stop.
struct EmitterDesc {
  enum class Kind { Disc, Box };
  Kind kind = Kind::Disc;
  Vec3d center{0.0};             ///< Disc: centre of the nozzle
  double radius = 0.0;           ///< Disc
  Vec3d normal{0.0, -1.0, 0.0};  ///< Disc: unit axis of the disc (normalised by the parser)
  double thickness = 0.0;        ///< Disc: extent along the normal; the file's value or Scene::dx()
  Vec3d min{0.0}, max{0.0};      ///< Box: corners
  Vec3d velocity{0.0};           ///< velocity of the emitted liquid (m/s)
  double start = 0.0;            ///< seconds
  double stop = std::numeric_limits<double>::infinity();  ///< seconds; infinity = until the end
};

struct CameraDesc {
  Vec3d eye{0.0};
  Vec3d target{0.0};
};

struct OutputDesc {
  bool particles = false;  ///< write particle points with each frame
  bool preview = true;     ///< render a preview image per frame
  int previewWidth = 480;
  int previewHeight = 360;
  std::optional<CameraDesc> camera;  ///< absent: the renderer chooses a view of the domain
  int checkpointEvery = 1;           ///< frames between checkpoints (sim/run/checkpoint.h); 0: none
  bool mesh = false;                 ///< write frame_NNNN.ply, the liquid surface (sim/output/surface_mesh.h)
  int meshSubdivisions = 1;          ///< triangles split in four this many times (meshLevelSet)
  bool zUp = false;                  ///< up_axis "z": .vdb and meshes turned y-up -> z-up (Blender)
};

struct Scene {
  std::string name;
  std::string description;
  std::string sourcePath;  ///< the file it was read from ("" when parsed from memory)

  Vec3d domainMin{0.0}, domainMax{0.0};  ///< metres; the box walls are solid
  bool openTop = false;                  ///< the +y face of the domain is open (air) instead of a wall

  int resolution = 0;          ///< cells along the longest domain axis
  int frames = 0;
  double fps = 24.0;
  double cfl = 1.0;
  int maxSubsteps = 50;

  MaterialDesc material;
  std::optional<Vec3d> gravity;  ///< absent: no gravity stage
  /// The solve a step runs (scene key "viscosity", kViscosityModeNames): UnifiedStokes,
  /// DecoupledStokes or PressureProjection. Not to be confused with material.viscosity, mu.
  solver::SystemKind system = solver::SystemKind::UnifiedStokes;
  ModelDesc model;
  SolverDesc solver;
  int particlesPerCellAxis = 2;
  /// Keep the particles per cell between target/2 and 3 target/2 (sim/particles/reseed.h); off, the particles
  /// only move (the emitters still add, the domain's open top still removes).
  bool reseed = true;
  /// Move the particle surface along its normal each step so that its volume is the volume the
  /// particles carry (Simulator::liquidLevelSet); off, the raw union of spheres eroded by
  /// r - spacing/2.
  bool keepVolume = true;
  /// How the liquid weights W_L are measured (GridStep::fillWeights): the engine's plane cuts
  /// with tent masses, taken apart from the walls' and solids' planes, or sub-samples.
  sparse_grid::FractionRule liquidWeights = sparse_grid::kLiquidFractionRule;
  /// Volume control (Kim et al. 2007, proportional): each step's solve asks the liquid for the
  /// uniform divergence s = -k e / ((1 + e) dt), e = (V - V_target) / V_target, V the clipped
  /// volume of the raw particle surface, so that the particles themselves return to the volume
  /// they carry: k of the error per step. 0: incompressible (div u = 0).
  double volumeControl = 0.1;

  std::vector<ShapeDesc> liquid;   ///< initial liquid (Box, Sphere, Mesh)
  std::vector<ShapeDesc> solids;   ///< static or moving solids (Box, Sphere, Plane, Mesh)
  std::vector<EmitterDesc> emitters;
  OutputDesc output;
  std::uint64_t seed = 1;

  /// Cell size: longest domain extent / resolution.
  double dx() const;
  /// Cells per axis: the longest axis has `resolution` cells, the others round(extent / dx), >= 1.
  openvdb::Coord resolutionCells() const;
  /// Solid shapes besides the domain walls (which are always there).
  bool hasSolids() const { return !solids.empty(); }
  /// A viscosity stage runs: the system is not the projection alone and mu > 0.
  bool hasViscosity() const { return system != solver::SystemKind::PressureProjection && material.viscosity > 0.0; }
  /// The system a step solves: `system`, or the projection alone where mu = 0.
  solver::SystemKind stepSystem() const { return hasViscosity() ? system : solver::SystemKind::PressureProjection; }
  /// Simulated time, frames / fps (seconds).
  double duration() const { return frames / fps; }
};

/// Values that replace the file's (command line --res / --frames, tests); checked like the file's.
struct SceneOverrides {
  std::optional<int> resolution;
  std::optional<int> frames;
};

/// Reads and validates a scene file; mesh paths are resolved against the file's directory.
Scene loadScene(const std::string& path, const SceneOverrides& overrides = {});

/// Parses scene JSON text. `sourceName` names it in messages; `baseDir` resolves mesh paths.
Scene parseSceneText(const std::string& text, const std::string& sourceName, const std::string& baseDir,
                     const SceneOverrides& overrides = {});

/// Validates an already-parsed JSON document.
Scene parseScene(const nlohmann::json& j, const std::string& sourceName, const std::string& baseDir,
                 const SceneOverrides& overrides = {});

}  // namespace scene
}  // namespace stokes::sim
