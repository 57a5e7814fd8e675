// Scene files (sim/scene/scene.h) and the OBJ reader (sim/geometry/obj_mesh.h): the shipped scenes parse, every
// malformed input gives a SceneError / MeshError that names the file, the place and the
// expectation, and seeded random mutations never produce anything else.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <typeinfo>
#include <vector>

#include "sim/geometry/geometry.h"
#include "sim/geometry/obj_mesh.h"
#include "sim/scene/scene.h"

namespace {

using namespace stokes::sim;
namespace fs = std::filesystem;
using nlohmann::json;

const fs::path kSource = STOKES_SOURCE_DIR;
const fs::path kScenes = kSource / "scenes";
const fs::path kLowres = kSource / "data" / "meshes" / "armadillo_lowres.obj";
const fs::path kArmadillo = kSource / "data" / "meshes" / "armadillo.obj";

std::string readText(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::vector<fs::path> sceneFiles() {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(kScenes))
    if (entry.path().extension() == ".json" && entry.path().filename() != "scene.schema.json")
      files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  return files;
}

/// A temporary file that removes itself.
struct TempFile {
  fs::path path;
  explicit TempFile(const std::string& name, const std::string& contents) {
    static int counter = 0;
    path = fs::temp_directory_path() /
           ("stokes_test_scene_" + std::to_string(::getpid()) + "_" + std::to_string(counter++) + "_" + name);
    std::ofstream(path, std::ios::binary) << contents;
  }
  ~TempFile() {
    std::error_code ec;
    fs::remove(path, ec);
  }
};

// ---- shipped scenes -----------------------------------------------------------------------------

TEST(Scene, EveryShippedSceneParses) {
  const auto files = sceneFiles();
  ASSERT_GE(files.size(), 4u);
  for (const auto& f : files) {
    SCOPED_TRACE(f.string());
    Scene s;
    ASSERT_NO_THROW(s = loadScene(f.string())) << f;
    EXPECT_FALSE(s.name.empty());
    EXPECT_EQ(s.sourcePath, f.string());
    EXPECT_GT(s.dx(), 0.0);
    EXPECT_TRUE(!s.liquid.empty() || !s.emitters.empty());
    EXPECT_LE(s.resolution, 256) << "keep the default resolution moderate";
    for (const auto& shape : s.liquid) {
      if (shape.kind == ShapeDesc::Kind::Mesh) {
        EXPECT_TRUE(fs::is_regular_file(shape.meshPath)) << shape.meshPath;
      }
    }
  }
}

TEST(Scene, ShippedScenesMatchTheThesisSetUps) {
  const Scene beam = loadScene((kScenes / "beam.json").string());
  EXPECT_DOUBLE_EQ(beam.material.density, 1.0);
  EXPECT_DOUBLE_EQ(beam.material.viscosity, 100.0);
  EXPECT_NEAR(beam.duration(), 1.6, 1e-12);
  EXPECT_EQ(beam.system, stokes::solver::SystemKind::UnifiedStokes);
  EXPECT_EQ(beam.model.type, ModelType::Uniform);  // at res 64 tiles save nothing (scenes/README.md)
  EXPECT_TRUE(beam.gravity.has_value());
  EXPECT_TRUE(beam.hasSolids());
  // the thesis' settings: decoupled viscosity, quadratic tiles 8 / 2 (thesis Fig. 4.2 / 4.3)
  const Scene beamThesis = loadScene((kScenes / "beam_thesis.json").string());
  EXPECT_EQ(beamThesis.system, stokes::solver::SystemKind::DecoupledStokes);
  EXPECT_EQ(beamThesis.model.type, ModelType::Quadratic);
  EXPECT_EQ(beamThesis.model.tile, 8);
  EXPECT_EQ(beamThesis.model.padding, 2);
  // the other thesis variants are their scenes with the thesis' quadratic tiles
  for (const char* name : {"honey_coil", "armadillos", "armadillo_pile"}) {
    SCOPED_TRACE(name);
    const Scene ours = loadScene((kScenes / (std::string(name) + ".json")).string());
    const Scene thesis = loadScene((kScenes / (std::string(name) + "_thesis.json")).string());
    EXPECT_EQ(ours.model.type, ModelType::Uniform);
    EXPECT_EQ(thesis.model.type, ModelType::Quadratic);
    EXPECT_EQ(thesis.model.tile, ours.model.tile);  // --model quadratic on ours is the thesis run
    EXPECT_EQ(thesis.model.padding, ours.model.padding);
    EXPECT_EQ(thesis.liquid.size(), ours.liquid.size());
    EXPECT_EQ(thesis.resolution, ours.resolution);
  }

  const Scene coil = loadScene((kScenes / "honey_coil.json").string());
  ASSERT_EQ(coil.emitters.size(), 1u);
  EXPECT_EQ(coil.emitters[0].kind, EmitterDesc::Kind::Disc);
  EXPECT_DOUBLE_EQ(coil.emitters[0].thickness, coil.dx());  // default thickness: one cell
  EXPECT_NEAR(coil.emitters[0].normal.length(), 1.0, 1e-12);
  EXPECT_TRUE(std::isinf(coil.emitters[0].stop));
  EXPECT_EQ(coil.model.tile, 12);
  EXPECT_EQ(coil.model.padding, 4);
  EXPECT_TRUE(coil.hasViscosity());

  const Scene arm = loadScene((kScenes / "armadillos.json").string());
  ASSERT_EQ(arm.liquid.size(), 9u);
  EXPECT_DOUBLE_EQ(arm.material.density, 1000.0);
  EXPECT_DOUBLE_EQ(arm.material.viscosity, 500.0);
  for (const auto& a : arm.liquid) {
    EXPECT_EQ(a.kind, ShapeDesc::Kind::Mesh);
    EXPECT_EQ(fs::path(a.meshPath).lexically_normal(), kArmadillo.lexically_normal());
    EXPECT_NEAR(a.placement.scale * 151.3, 0.25, 1e-3);  // 0.25 m tall
  }
  EXPECT_NE(arm.liquid[0].placement.rotationDegrees, arm.liquid[1].placement.rotationDegrees);

  const Scene def = loadScene((kScenes / "default.json").string());
  EXPECT_EQ(def.resolution, 32);
  EXPECT_EQ(def.model.type, ModelType::Uniform);
  EXPECT_FALSE(def.hasSolids());
}

// The pile's column (scenes/README.md): every armadillo stays 2.5 cm clear of the container's
// walls, and each after the first lies above an earlier one whose bounding box it overlaps in x
// and z, 2 cm above it -- so each lands on those below.
TEST(Scene, ArmadilloPileIsAColumnInItsContainer) {
  const Scene pile = loadScene((kScenes / "armadillo_pile.json").string());
  ASSERT_EQ(pile.liquid.size(), 9u);
  EXPECT_DOUBLE_EQ(pile.material.density, 1000.0);
  EXPECT_DOUBLE_EQ(pile.material.viscosity, 500.0);
  const TriangleMesh mesh = loadObj(kArmadillo.string());
  std::vector<std::pair<Vec3d, Vec3d>> boxes;
  for (const auto& a : pile.liquid) {
    ASSERT_EQ(a.kind, ShapeDesc::Kind::Mesh);
    Vec3d lo(1e30), hi(-1e30);
    for (const auto& p : mesh.points) {
      const Vec3d q = applyPlacement(a.placement, Vec3d(p));
      for (int i = 0; i < 3; ++i) lo[i] = std::min(lo[i], q[i]), hi[i] = std::max(hi[i], q[i]);
    }
    EXPECT_NEAR(a.placement.scale * 151.3, 0.25, 1e-3);  // 0.25 m tall
    for (int i : {0, 2}) {
      EXPECT_GE(lo[i] - pile.domainMin[i], 0.025 - 1e-4);
      EXPECT_GE(pile.domainMax[i] - hi[i], 0.025 - 1e-4);
    }
    EXPECT_LT(hi.y(), pile.domainMax.y());
    if (!boxes.empty()) {
      double below = -1.0;  // the highest top of an earlier box overlapping this one in x and z
      for (const auto& [blo, bhi] : boxes)
        if (lo.x() < bhi.x() && hi.x() > blo.x() && lo.z() < bhi.z() && hi.z() > blo.z()) below = std::max(below, bhi.y());
      EXPECT_NEAR(lo.y() - below, 0.02, 2e-3) << "armadillo " << boxes.size();
    } else {
      EXPECT_NEAR(lo.y(), 0.1, 2e-3);  // the floor gap
    }
    boxes.emplace_back(lo, hi);
  }
}

TEST(Scene, DxAndCellsFollowTheLongestAxis) {
  const Scene beam = loadScene((kScenes / "beam.json").string());  // 1.6 x 1.0 x 0.65 m, 64 cells
  EXPECT_DOUBLE_EQ(beam.dx(), 1.6 / 64);
  EXPECT_EQ(beam.resolutionCells(), openvdb::Coord(64, 40, 26));
}

// A float that is an integer only as a double: 9223372036854775807.0 is 2^63, past int64's range
// (the conversion would be undefined); 2^62 as a float is taken.
TEST(Scene, IntegerKeysRejectFloatsPastTheirRange) {
  auto seedScene = [](const std::string& seed) {
    return R"({"name": "s", "domain": {"min": [0, 0, 0], "max": [1, 1, 1]}, "resolution": 8, "frames": 1,
      "material": {"density": 1000, "viscosity": 1},
      "liquid": [{"shape": "sphere", "center": [0.5, 0.5, 0.5], "radius": 0.2}], "seed": )" + seed + "}";
  };
  EXPECT_THROW(parseSceneText(seedScene("9223372036854775807.0"), "s.json", "."), SceneError);
  EXPECT_EQ(parseSceneText(seedScene("4611686018427387904.0"), "s.json", ".").seed, 4611686018427387904ull);
}

TEST(Scene, OverridesReplaceAndAreValidated) {
  const std::string path = (kScenes / "default.json").string();
  SceneOverrides o;
  o.resolution = 48;
  o.frames = 3;
  const Scene s = loadScene(path, o);
  EXPECT_EQ(s.resolution, 48);
  EXPECT_EQ(s.frames, 3);
  EXPECT_DOUBLE_EQ(s.dx(), 0.2 / 48);
  EXPECT_EQ(s.resolutionCells(), openvdb::Coord(48, 48, 48));

  o.resolution = 0;
  try {
    loadScene(path, o);
    FAIL() << "resolution override 0 accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("resolution (override): expected an integer in [1, 4096], got 0"),
              std::string::npos)
        << e.what();
  }
  o.resolution.reset();
  o.frames = -2;
  EXPECT_THROW(loadScene(path, o), SceneError);

  // the file's own value is still checked when an override replaces it
  std::string text;
  {
    std::ifstream in(path);
    text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const std::size_t at = text.find("\"frames\": 48");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, 12, "\"frames\": \"48\"");
  EXPECT_THROW(parseSceneText(text, "default.json", kScenes.string(), SceneOverrides{std::nullopt, 3}), SceneError);
}

// ---- malformed scenes ---------------------------------------------------------------------------

/// A small valid scene used as the base of the malformed cases.
json baseScene() {
  return json::parse(R"({
    "name": "bad",
    "domain": {"min": [0, 0, 0], "max": [1, 2, 1]},
    "resolution": 32,
    "frames": 10,
    "material": {"density": 1000, "viscosity": 5},
    "gravity": [0, -9.81, 0],
    "liquid": [{"shape": "box", "min": [0.2, 0.2, 0.2], "max": [0.8, 0.8, 0.8]}],
    "emitters": [{"shape": "disc", "center": [0.5, 1.5, 0.5], "radius": 0.1, "normal": [0, -1, 0],
                  "velocity": [0, -1, 0], "start": 0.5, "stop": 1.0}]
  })");
}

/// Parses `text` as "bad_scene.json" and returns the SceneError message ("" if it parsed).
std::string sceneErrorOf(const std::string& text) {
  try {
    parseSceneText(text, "bad_scene.json", kScenes.string());
  } catch (const SceneError& e) {
    return e.what();
  }
  return "";
}

std::string sceneErrorOf(const json& j) { return sceneErrorOf(j.dump(2)); }

/// Checks that `message` names the file and contains each of `parts`.
void expectMessage(const std::string& message, std::initializer_list<const char*> parts) {
  ASSERT_FALSE(message.empty()) << "the scene was accepted";
  EXPECT_NE(message.find("bad_scene.json"), std::string::npos) << message;
  for (const char* part : parts) EXPECT_NE(message.find(part), std::string::npos) << "missing '" << part << "' in: " << message;
}

TEST(SceneErrors, BaseSceneIsValid) {
  const Scene s = parseScene(baseScene(), "bad_scene.json", kScenes.string());
  EXPECT_DOUBLE_EQ(s.dx(), 2.0 / 32);
  EXPECT_EQ(s.resolutionCells(), openvdb::Coord(16, 32, 16));
  EXPECT_DOUBLE_EQ(s.emitters[0].stop, 1.0);
  EXPECT_EQ(s.system, stokes::solver::SystemKind::UnifiedStokes);
  EXPECT_EQ(s.liquidWeights, stokes::sparse_grid::kLiquidFractionRule);
  EXPECT_FALSE(s.solver.preconditioner.has_value());  // "auto": chosen per step by size
  EXPECT_EQ(s.output.previewWidth, 480);
  EXPECT_EQ(s.seed, 1u);
}

TEST(SceneErrors, TruncatedJsonReportsLineAndByte) {
  const std::string text = baseScene().dump(2);
  const std::string message = sceneErrorOf(text.substr(0, text.size() / 2));
  expectMessage(message, {"line ", "column ", "byte ", "JSON syntax error"});
}

TEST(SceneErrors, NegativeResolution) {
  json j = baseScene();
  j["resolution"] = -1;
  expectMessage(sceneErrorOf(j), {"resolution: expected an integer in [1, 4096], got -1"});
}

TEST(SceneErrors, HugeResolution) {
  json j = baseScene();
  j["resolution"] = 1000000000;
  expectMessage(sceneErrorOf(j), {"resolution: expected an integer in [1, 4096], got 1000000000"});
  j["resolution"] = 0;
  expectMessage(sceneErrorOf(j), {"resolution: expected an integer in [1, 4096], got 0"});
  j = baseScene();
  j["model"] = {{"tile", 0u}};
  expectMessage(sceneErrorOf(j), {"model.tile: expected an integer in [2, 256], got 0"});
  j["resolution"] = 1e300;
  expectMessage(sceneErrorOf(j), {"resolution: expected an integer"});
  j["resolution"] = 32.5;
  expectMessage(sceneErrorOf(j), {"resolution: expected an integer", "got 32.5"});
  j = baseScene();
  j["frames"] = 10000001;
  expectMessage(sceneErrorOf(j), {"frames: expected an integer in [1, 1000000]"});
}

TEST(SceneErrors, OverflowingNumberIsRejected) {
  std::string text = baseScene().dump();
  text.replace(text.find("\"density\":1000"), 14, "\"density\":1e999");
  expectMessage(sceneErrorOf(text), {"material.density: expected a number, got number overflow parsing '1e999'"});
  text = baseScene().dump();
  text.replace(text.find("[0,-9.81,0]"), 11, "[0,-1e400,0]");
  expectMessage(sceneErrorOf(text), {"gravity[1]: expected a number, got number overflow"});
}

TEST(SceneErrors, UnknownKeySuggestsTheClosest) {
  json j = baseScene();
  j["resolutoin"] = 32;
  expectMessage(sceneErrorOf(j), {"resolutoin: unknown key", "did you mean \"resolution\"?"});
  j = baseScene();
  j["domain"]["openTop"] = true;
  expectMessage(sceneErrorOf(j), {"domain.openTop: unknown key", "did you mean \"open_top\"?"});
  j = baseScene();
  j["model"] = {{"type", "quadratic"}, {"zzz", 1}};
  const std::string m = sceneErrorOf(j);
  expectMessage(m, {"model.zzz: unknown key", "expected one of: type, tile"});
  EXPECT_EQ(m.find("did you mean"), std::string::npos) << m;
  j = baseScene();
  j["liquid"][0]["radius"] = 1;  // a box has no radius
  expectMessage(sceneErrorOf(j), {"liquid[0].radius: unknown key for a box"});
}

TEST(SceneErrors, WrongType) {
  json j = baseScene();
  j["frames"] = "ten";
  expectMessage(sceneErrorOf(j), {"frames: expected an integer in [1, 1000000], got \"ten\" (a string)"});
  j = baseScene();
  j["gravity"] = {0, -9.81};
  expectMessage(sceneErrorOf(j), {"gravity: expected an array of 3 numbers"});
  j = baseScene();
  j["domain"]["min"][1] = nullptr;
  expectMessage(sceneErrorOf(j), {"domain.min[1]: expected a number", "got null"});
  j = baseScene();
  j["viscosity"] = "sticky";
  expectMessage(sceneErrorOf(j), {"viscosity: expected one of \"coupled\", \"decoupled\", \"none\""});
  j = baseScene();
  j["liquid_weights"] = "exact";
  expectMessage(sceneErrorOf(j), {"liquid_weights: expected one of \"subsample\", \"plane-cut\""});
  j = baseScene();
  j["liquid_weights"] = "plane-cut";
  EXPECT_EQ(parseScene(j, "bad_scene.json", kScenes.string()).liquidWeights, stokes::sparse_grid::FractionRule::PlaneCut);
  j = baseScene();
  j["solver"] = {{"rows", "dense"}};
  expectMessage(sceneErrorOf(j), {"solver.rows: expected one of \"auto\", \"compact\", \"padded\""});
  j = baseScene();
  j["solver"] = {{"stencils", "halo"}};
  expectMessage(sceneErrorOf(j), {"solver.stencils: expected one of \"rows\", \"blocks\""});
  j = baseScene();
  j["solver"] = {{"warm_start", "yes"}};
  expectMessage(sceneErrorOf(j), {"solver.warm_start: expected true or false"});
  j = baseScene();
  j["solver"] = {{"multigrid_degree", 17}};
  expectMessage(sceneErrorOf(j), {"solver.multigrid_degree: expected an integer in [0, 16], got 17"});
  j = baseScene();
  j["solver"] = {{"multigrid_method", "cg"}};
  expectMessage(sceneErrorOf(j), {"solver.multigrid_method: expected one of \"auto\", \"gmres\", \"minres\", "
                                  "\"fgmres\", \"bicgstab\""});
  j["solver"] = {{"multigrid_method", "minres"}};
  EXPECT_EQ(parseScene(j, "bad_scene.json", kScenes.string()).solver.multigridMethod, stokes::solver::KrylovMethod::MINRES);
  j = baseScene();
  j["liquid"] = json::object();
  expectMessage(sceneErrorOf(j), {"liquid: expected an array"});
  expectMessage(sceneErrorOf(std::string("[1, 2, 3]")), {"top level: expected a JSON object"});
}

TEST(SceneErrors, MissingRequiredKey) {
  json j = baseScene();
  j.erase("material");
  expectMessage(sceneErrorOf(j), {"material: missing required key", "density"});
  j = baseScene();
  j["domain"].erase("max");
  expectMessage(sceneErrorOf(j), {"domain.max: missing required key"});
  j = baseScene();
  j["emitters"][0].erase("velocity");
  expectMessage(sceneErrorOf(j), {"emitters[0].velocity: missing required key"});
}

TEST(SceneErrors, EmitterStopBeforeStart) {
  json j = baseScene();
  j["emitters"][0]["stop"] = 0.2;
  expectMessage(sceneErrorOf(j), {"emitters[0].stop: expected a time after start (0.5 s), got 0.2"});
  j = baseScene();
  j["emitters"][0]["radius"] = -1;
  expectMessage(sceneErrorOf(j), {"bad_scene.json: emitters[0].radius: expected a positive number, got -1"});
}

TEST(SceneErrors, GeometryChecks) {
  json j = baseScene();
  j["domain"]["max"][1] = -1;
  expectMessage(sceneErrorOf(j), {"domain.max[1]: expected a value greater than domain.min[1]"});
  j = baseScene();
  j["liquid"][0] = {{"shape", "plane"}, {"point", {0, 0, 0}}, {"normal", {0, 1, 0}}};
  expectMessage(sceneErrorOf(j), {"liquid[0].shape: expected one of \"box\", \"sphere\", \"mesh\""});
  j = baseScene();
  j["liquid"][0] = {{"shape", "sphere"}, {"center", {5, 5, 5}}, {"radius", 0.5}};
  expectMessage(sceneErrorOf(j), {"liquid[0]: expected a sphere overlapping the domain"});
  j = baseScene();
  j["solids"] = {{{"shape", "plane"}, {"point", {0, 0.1, 0}}, {"normal", {0, 0, 0}}}};
  expectMessage(sceneErrorOf(j), {"solids[0].normal: expected a non-zero direction vector"});
  j = baseScene();
  j["solids"] = {{{"shape", "mesh"}, {"file", "no_such_mesh.obj"}}};
  expectMessage(sceneErrorOf(j), {"solids[0].file: expected an existing OBJ file", "no_such_mesh.obj"});
  j["solids"] = {{{"shape", "box"}, {"min", {0, 0, 0}}, {"max", {1, 0.1, 1}}, {"velocity", {0.5, 0, 1e9}}}};
  expectMessage(sceneErrorOf(j), {"solids[0].velocity[2]: expected"});
  j = baseScene();
  j["model"] = {{"type", "affine"}, {"tile", 4}, {"padding", 4}};
  expectMessage(sceneErrorOf(j), {"model.padding: expected a padding smaller than the tile (4), got 4"});
  j = baseScene();
  j["model"] = {{"type", "quadratic"}, {"tile", 32}, {"padding", 2}, {"tile_min", 8}};
  expectMessage(sceneErrorOf(j), {"model.tile_accuracy: expected tile_min and tile_accuracy together"});
  j = baseScene();
  j.erase("liquid");
  j.erase("emitters");
  expectMessage(sceneErrorOf(j), {"liquid: expected at least one liquid shape or emitter"});
}

TEST(SceneErrors, DuplicateKey) {
  std::string text = baseScene().dump();
  text.insert(1, "\"frames\": 3, ");
  expectMessage(sceneErrorOf(text), {"frames: duplicate key"});
  text = baseScene().dump();
  const std::size_t radius = text.find("\"radius\"");
  text.insert(radius, "\"radius\": 2, ");
  expectMessage(sceneErrorOf(text), {"emitters[0].radius: duplicate key"});
}

TEST(SceneErrors, MissingFile) {
  try {
    loadScene((kScenes / "does_not_exist.json").string());
    FAIL();
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("does_not_exist.json: cannot open"), std::string::npos) << e.what();
  }
}

// ---- OBJ reader ---------------------------------------------------------------------------------

/// Reads OBJ text as "bad.obj" and returns the MeshError message ("" if it loaded).
std::string meshErrorOf(const std::string& text, const ObjLimits& limits = {}) {
  std::istringstream in(text);
  try {
    readObj(in, "bad.obj", limits);
  } catch (const MeshError& e) {
    return e.what();
  }
  return "";
}

void expectMeshMessage(const std::string& message, std::initializer_list<const char*> parts) {
  ASSERT_FALSE(message.empty()) << "the mesh was accepted";
  for (const char* part : parts) EXPECT_NE(message.find(part), std::string::npos) << "missing '" << part << "' in: " << message;
}

const char* kTriangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

TEST(ObjReader, LowResArmadilloCounts) {
  const TriangleMesh m = loadObj(kLowres.string());
  EXPECT_EQ(m.points.size(), 2502u);
  EXPECT_EQ(m.triangles.size(), 5000u);
  float ymin = 1e9f, ymax = -1e9f;
  for (const auto& p : m.points) ymin = std::min(ymin, p.y()), ymax = std::max(ymax, p.y());
  EXPECT_NEAR(ymin, -0.36, 0.01);
  EXPECT_NEAR(ymax, 0.64, 0.01);
}

TEST(ObjReader, FullArmadilloCounts) {
  const TriangleMesh m = loadObj(kArmadillo.string());
  EXPECT_EQ(m.points.size(), 49990u);
  EXPECT_EQ(m.triangles.size(), 99976u);
}

TEST(ObjReader, PolygonsSlashesAndRelativeIndices) {
  std::istringstream in(
      "# comment\no thing\nv 0 0 0\nv 1 0 0 1.0\nv 1 1 0\nv 0 1 0 0.5 0.5 0.5\n"
      "vt 0 0\nvn 0 0 1\ns off\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf -4//1 -3//1 -2//1\r\nf +1 2 3\n");
  const TriangleMesh m = readObj(in, "quad.obj");
  ASSERT_EQ(m.points.size(), 4u);
  ASSERT_EQ(m.triangles.size(), 4u);
  EXPECT_EQ(m.triangles[0], openvdb::Vec3I(0, 1, 2));
  EXPECT_EQ(m.triangles[1], openvdb::Vec3I(0, 2, 3));
  EXPECT_EQ(m.triangles[2], openvdb::Vec3I(0, 1, 2));
  EXPECT_EQ(m.points[3], openvdb::Vec3s(0, 1, 0));
}

TEST(ObjReader, TruncatedFile) {
  const std::string text = readText(kLowres);
  const std::size_t cut = text.find('\n', text.size() / 4) + 10;  // inside a "v x y z" line
  const std::size_t line = static_cast<std::size_t>(std::count(text.begin(), text.begin() + cut, '\n')) + 1;
  expectMeshMessage(meshErrorOf(text.substr(0, cut)), {"bad.obj: line ", "vertex record needs 3 coordinates"});
  EXPECT_NE(meshErrorOf(text.substr(0, cut)).find("line " + std::to_string(line) + ":"), std::string::npos);
}

TEST(ObjReader, IndexOutOfRangeOrZero) {
  expectMeshMessage(meshErrorOf(std::string(kTriangle) + "f 1 2 4\n"),
                    {"bad.obj: line 4: vertex index 4 out of range (3 vertices defined so far)"});
  expectMeshMessage(meshErrorOf(std::string(kTriangle) + "f 1 2 -4\n"), {"line 4: vertex index -4 out of range"});
  expectMeshMessage(meshErrorOf(std::string(kTriangle) + "f 0 1 2\n"), {"line 4: vertex index 0"});
  expectMeshMessage(meshErrorOf(std::string(kTriangle) + "f 1 2 99999999999999999999999\n"),
                    {"line 4: vertex index", "out of range"});
  expectMeshMessage(meshErrorOf(std::string(kTriangle) + "f 1 2 x3\n"), {"line 4: malformed vertex index 'x3'"});
  expectMeshMessage(meshErrorOf(std::string(kTriangle) + "f 1 2\n"), {"line 4: face with 2 vertices"});
}

TEST(ObjReader, BadNumbers) {
  expectMeshMessage(meshErrorOf("v 0 0 0\nv nan 0 0\n"), {"bad.obj: line 2: vertex coordinate 'nan' is NaN or infinite"});
  expectMeshMessage(meshErrorOf("v 0 inf 0\n"), {"line 1: vertex coordinate 'inf' is NaN or infinite"});
  expectMeshMessage(meshErrorOf("v 0 1e999 0\n"), {"line 1: number '1e999' is out of the range"});
  expectMeshMessage(meshErrorOf("v 0 1e39 0\n"), {"line 1: vertex coordinate '1e39' does not fit in single precision"});
  expectMeshMessage(meshErrorOf("v 0 1.0.0 0\n"), {"line 1: malformed number '1.0.0'"});
  EXPECT_EQ(meshErrorOf(std::string("v 0 1e-400 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")), "");  // underflow reads as 0
}

TEST(ObjReader, NoFacesNoVertices) {
  expectMeshMessage(meshErrorOf(kTriangle), {"bad.obj: line 3: end of file reached without any face"});
  expectMeshMessage(meshErrorOf("# nothing here\ng group\n"), {"line 2: end of file reached without any vertex"});
  expectMeshMessage(meshErrorOf(""), {"bad.obj: line 1: the file is empty"});
}

TEST(ObjReader, HugeDeclaredCountsAndLimits) {
  expectMeshMessage(meshErrorOf("# Vertices: 999999999999\nv 0 0 0\n"),
                    {"bad.obj: line 1: the header declares 999999999999 vertices, more than the limit"});
  expectMeshMessage(meshErrorOf("# 184467440737095516160 faces\n"), {"line 1: the header declares an overflowing number of faces"});
  ObjLimits small;
  small.maxVertices = 10;
  expectMeshMessage(meshErrorOf(readText(kLowres), small), {"line 11: more than 10 vertices (ObjLimits::maxVertices)"});
  small = {};
  small.maxTriangles = 1;
  expectMeshMessage(meshErrorOf(std::string(kTriangle) + "v 1 1 0\nf 1 2 3 4\n", small),
                    {"line 5: more than 1 triangles"});
  small = {};
  small.maxLineBytes = 64;
  expectMeshMessage(meshErrorOf("v 0 0 0 " + std::string(100, ' ') + "\n", small), {"line 1: line longer than 64 bytes"});
  small = {};
  small.maxFileBytes = 100;
  expectMeshMessage(meshErrorOf(readText(kLowres), small), {"longer than 100 bytes"});
}

TEST(ObjReader, FilesOnDisk) {
  const TempFile empty("empty.obj", "");
  expectMeshMessage([&] {
    try { loadObj(empty.path.string()); } catch (const MeshError& e) { return std::string(e.what()); }
    return std::string();
  }(), {"empty.obj: line 1: the file is empty"});

  std::string garbage(4096, '\0');
  std::mt19937_64 rng(99);
  for (char& c : garbage) c = static_cast<char>(rng() & 0xff);
  const TempFile binary("garbage.obj", garbage);
  const auto binaryMessage = [&] {
    try { loadObj(binary.path.string()); } catch (const MeshError& e) { return std::string(e.what()); }
    return std::string();
  }();
  expectMeshMessage(binaryMessage, {"garbage.obj: line ", "this is not a text OBJ file"});

  expectMeshMessage([&] {
    try { loadObj((kSource / "no_such_file.obj").string()); } catch (const MeshError& e) { return std::string(e.what()); }
    return std::string();
  }(), {"no_such_file.obj: cannot open the mesh file: no such file"});
  expectMeshMessage([&] {
    try { loadObj(kSource.string()); } catch (const MeshError& e) { return std::string(e.what()); }
    return std::string();
  }(), {"not a regular file"});
}

// ---- seeded mutation fuzzing --------------------------------------------------------------------

/// Random edits of a text: byte flips, deletions, token insertions, number replacements, key
/// renames, duplications and truncations.
class Mutator {
 public:
  Mutator(std::uint64_t seed, std::vector<std::string> tokens, std::vector<std::string> numbers)
      : rng_(seed), tokens_(std::move(tokens)), numbers_(std::move(numbers)) {}

  std::string mutate(std::string text) {
    const int edits = 1 + static_cast<int>(rng_() % 3);
    for (int e = 0; e < edits && !text.empty(); ++e) text = edit(std::move(text));
    return text;
  }

 private:
  std::size_t pos(const std::string& t) { return t.empty() ? 0 : rng_() % t.size(); }
  const std::string& pick(const std::vector<std::string>& v) { return v[rng_() % v.size()]; }

  std::string edit(std::string t) {
    switch (rng_() % 8) {
      case 0: t[pos(t)] = static_cast<char>(rng_() & 0xff); break;  // byte replaced
      case 1: t[pos(t)] ^= static_cast<char>(1u << (rng_() % 8)); break;  // bit flip
      case 2: { const std::size_t p = pos(t); t.erase(p, 1 + rng_() % 12); break; }  // deletion
      case 3: t.insert(pos(t), pick(tokens_)); break;  // token insertion
      case 4: replaceNumber(t); break;
      case 5: renameKey(t); break;
      case 6: { const std::size_t p = pos(t); const std::size_t n = 1 + rng_() % 40; t.insert(p, t.substr(p, n)); break; }
      default: t.resize(pos(t)); break;  // truncation
    }
    return t;
  }

  /// Replaces the number starting at or after a random position by a hostile one.
  void replaceNumber(std::string& t) {
    std::size_t p = pos(t);
    while (p < t.size() && !std::isdigit(static_cast<unsigned char>(t[p]))) ++p;
    if (p >= t.size()) return;
    std::size_t start = p;
    while (start > 0 && (t[start - 1] == '-' || t[start - 1] == '.' || std::isdigit(static_cast<unsigned char>(t[start - 1])))) --start;
    std::size_t end = p;
    while (end < t.size() && (std::isdigit(static_cast<unsigned char>(t[end])) || t[end] == '.' || t[end] == 'e' ||
                              t[end] == 'E' || t[end] == '-' || t[end] == '+'))
      ++end;
    t.replace(start, end - start, pick(numbers_));
  }

  /// Changes one character of a quoted string (keys and enum values alike) or swaps its case.
  void renameKey(std::string& t) {
    const std::size_t q = t.find('"', pos(t));
    if (q == std::string::npos || q + 2 >= t.size()) return;
    const std::size_t close = t.find('"', q + 1);
    if (close == std::string::npos || close == q + 1) return;
    const std::size_t c = q + 1 + rng_() % (close - q - 1);
    switch (rng_() % 3) {
      case 0: t[c] = static_cast<char>('a' + rng_() % 26); break;
      case 1: t[c] = static_cast<char>(std::toupper(static_cast<unsigned char>(t[c]))); break;
      default: t.erase(c, 1); break;
    }
  }

  std::mt19937_64 rng_;
  std::vector<std::string> tokens_, numbers_;
};

/// Mutations per fuzz test (override with -DSTOKES_FUZZ_MUTATIONS=... for long runs) and the seed
/// offset (environment STOKES_FUZZ_SEED, default 0: the fixed, reproducible sequence).
#ifndef STOKES_FUZZ_MUTATIONS
#define STOKES_FUZZ_MUTATIONS 6000
#endif
constexpr std::size_t kFuzzMutations = STOKES_FUZZ_MUTATIONS;

std::uint64_t fuzzSeed(std::uint64_t base) {
  const char* env = std::getenv("STOKES_FUZZ_SEED");
  return base + (env ? std::strtoull(env, nullptr, 10) : 0);
}

struct FuzzCounts {
  std::size_t accepted = 0, rejected = 0;
};

/// Runs `parse` on `count` mutations of each text; anything but success or `Expected` fails.
template <class Expected>
FuzzCounts fuzz(const std::vector<std::string>& texts, std::size_t count, Mutator& mutator,
                const std::function<void(const std::string&)>& parse) {
  FuzzCounts counts;
  for (const std::string& original : texts)
    for (std::size_t i = 0; i < count; ++i) {
      const std::string text = mutator.mutate(original);
      try {
        parse(text);
        ++counts.accepted;
      } catch (const Expected&) {
        ++counts.rejected;
      } catch (const std::exception& e) {
        ADD_FAILURE() << "unexpected exception " << typeid(e).name() << ": " << e.what() << "\non input:\n" << text;
        return counts;
      }
    }
  return counts;
}

/// What the parser accepts is within the documented limits (scenes/README.md).
void expectWithinLimits(const Scene& s) {
  EXPECT_TRUE(s.resolution >= 1 && s.resolution <= 4096) << s.resolution;
  EXPECT_TRUE(std::isfinite(s.dx()) && s.dx() > 0.0);
  EXPECT_TRUE(s.frames >= 1 && s.frames <= 1'000'000);
  EXPECT_TRUE(s.fps > 0.0 && s.cfl > 0.0 && s.maxSubsteps >= 1);
  EXPECT_TRUE(s.material.density > 0.0 && s.material.viscosity >= 0.0);
  EXPECT_TRUE(s.model.tile >= 2 && s.model.padding >= 1 && s.model.padding < s.model.tile);
  EXPECT_TRUE(s.model.bandAir >= 0 && s.model.bandSolid >= 0 && s.model.minRegion >= 1);
  EXPECT_TRUE(s.solver.tolerance > 0.0 && s.solver.maxIterations >= 1);
  EXPECT_TRUE(s.particlesPerCellAxis >= 1 && s.particlesPerCellAxis <= 8);
  EXPECT_TRUE(s.output.previewWidth >= 16 && s.output.previewHeight >= 16);
  EXPECT_TRUE(!s.liquid.empty() || !s.emitters.empty());
  for (int a = 0; a < 3; ++a) EXPECT_LT(s.domainMin[a], s.domainMax[a]);
  for (const auto* shapes : {&s.liquid, &s.solids})
    for (const ShapeDesc& shape : *shapes) {
      if (shape.kind == ShapeDesc::Kind::Box) {
        for (int a = 0; a < 3; ++a) EXPECT_LT(shape.min[a], shape.max[a]);
      }
      if (shape.kind == ShapeDesc::Kind::Sphere) {
        EXPECT_GT(shape.radius, 0.0);
      }
      if (shape.kind == ShapeDesc::Kind::Plane) {
        EXPECT_NEAR(shape.normal.length(), 1.0, 1e-9);
      }
      if (shape.kind == ShapeDesc::Kind::Mesh) {
        EXPECT_GT(shape.placement.scale, 0.0);
        EXPECT_TRUE(fs::is_regular_file(shape.meshPath)) << shape.meshPath;
      }
    }
  for (const EmitterDesc& e : s.emitters) {
    EXPECT_GT(e.stop, e.start);
    if (e.kind == EmitterDesc::Kind::Disc) {
      EXPECT_TRUE(e.radius > 0.0 && e.thickness > 0.0);
      EXPECT_NEAR(e.normal.length(), 1.0, 1e-9);
    }
  }
}

TEST(Fuzz, SceneParserOnlyAcceptsOrThrowsSceneError) {
  const std::vector<std::string> tokens = {
      "{", "}", "[", "]", ",", ":", "\"", "null", "true", "false", "-", "0", "1e999", "-1", "\"x\"", "{\"a\":1}",
      "[1,2]", "NaN", "Infinity", "1e308", "-0", "4097", "99999999999999999999", "\"\\u0000\"", "\"\\ud800\"",
      "\"resolution\": 1,", "[[[[[[[[", "\xff\xfe", "\"shape\": \"plane\",", "\"file\": \"/\","};
  const std::vector<std::string> numbers = {"1e309", "-1e309", "-5", "0", "1e9", "NaN", "nan", "-0.0", "0.5",
                                            "18446744073709551616", "-9223372036854775809", "1.5", "inf", "4096",
                                            "1e-320", "2147483648", "1000001", "-"};
  std::vector<std::string> texts;
  for (const auto& f : sceneFiles()) texts.push_back(readText(f));
  ASSERT_FALSE(texts.empty());
  Mutator mutator(fuzzSeed(0x5eed5ce7e), tokens, numbers);
  const std::size_t perFile = kFuzzMutations / texts.size() + 1;

  const auto t0 = std::chrono::steady_clock::now();
  const FuzzCounts counts = fuzz<SceneError>(texts, perFile, mutator, [&](const std::string& text) {
    expectWithinLimits(parseSceneText(text, "fuzz.json", kScenes.string()));
  });
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("scene fuzz: %zu mutations of %zu files: %zu accepted, %zu rejected (SceneError), %.2f s\n",
              counts.accepted + counts.rejected, texts.size(), counts.accepted, counts.rejected, seconds);
  EXPECT_GE(counts.accepted + counts.rejected, 5000u);
  EXPECT_GT(counts.accepted, 0u);
  EXPECT_GT(counts.rejected, 0u);
}

/// The first 300 vertices of the low-res armadillo and the faces that use only them.
std::string objSnippet() {
  std::istringstream in(readText(kLowres));
  std::string line, vertices, faces;
  int v = 0;
  while (std::getline(in, line)) {
    if (line.rfind("v ", 0) == 0 && v < 300) vertices += line + "\n", ++v;
    if (line.rfind("f ", 0) == 0) {
      std::istringstream f(line.substr(2));
      int a = 0, b = 0, c = 0;
      if (f >> a >> b >> c && a <= 300 && b <= 300 && c <= 300) faces += line + "\n";
    }
  }
  return vertices + faces;
}

TEST(Fuzz, ObjReaderOnlyAcceptsOrThrowsMeshError) {
  const std::vector<std::string> tokens = {"v", "f", "nan", "inf", "-1", "0", "1e39", "99999999999", "/", "//",
                                           "\n", std::string(1, '\0'), "#", "1e-400", "-0", "+", "4294967296",
                                           "\r\n", "f 1 2\n", "v 1 2\n", "\nf -1 -2 -3\n", "# Vertices: 1e30\n",
                                           "\n# 99999999999999 faces\n", "\nf 1/2/3/4 1 2\n", "\xff"};
  const std::vector<std::string> numbers = {"1e309", "-1e309", "-5", "0", "nan", "-nan", "inf", "1e39", "-0.0",
                                            "18446744073709551616", "-9223372036854775809", "301", "-301", "1.5"};
  const std::string snippet = objSnippet();
  ASSERT_GT(snippet.size(), 10000u);
  {
    std::istringstream in(snippet);
    const TriangleMesh m = readObj(in, "snippet.obj");
    ASSERT_EQ(m.points.size(), 300u);
    ASSERT_EQ(m.triangles.size(), 233u);
  }
  Mutator mutator(fuzzSeed(0x0b1f22), tokens, numbers);
  const auto t0 = std::chrono::steady_clock::now();
  const FuzzCounts counts = fuzz<MeshError>({snippet}, kFuzzMutations, mutator, [&](const std::string& text) {
    std::istringstream in(text);
    const TriangleMesh m = readObj(in, "fuzz.obj");
    ASSERT_FALSE(m.points.empty());
    ASSERT_FALSE(m.triangles.empty());
    for (const auto& p : m.points) ASSERT_TRUE(std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()));
    for (const auto& t : m.triangles)
      for (int k = 0; k < 3; ++k) ASSERT_LT(t[k], m.points.size());
  });
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("obj fuzz: %zu mutations: %zu accepted, %zu rejected (MeshError), %.2f s\n",
              counts.accepted + counts.rejected, counts.accepted, counts.rejected, seconds);
  EXPECT_GE(counts.accepted + counts.rejected, 5000u);
  EXPECT_GT(counts.accepted, 0u);
  EXPECT_GT(counts.rejected, 0u);
}

}  // namespace
