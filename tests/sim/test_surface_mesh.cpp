// Meshes of the liquid for renderers (sim/output/surface_mesh.h) and the z-up output frame: a meshed
// level set is closed, consistently wound outwards and encloses the level set's volume; PLY files
// round-trip with their vertex velocities; up_axis "z" turns meshes, .vdb transforms and velocities alike; a run writes a mesh
// per frame.
#include <gtest/gtest.h>
#include "sparse_grid/vdb_trees.h"
#include <openvdb/tools/LevelSetSphere.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>

#include "sim/geometry/geometry.h"
#include "sim/output/vdb_frame.h"
#include "sim/scene/scene.h"
#include "sim/run/scene_runner.h"
#include "sim/output/surface_mesh.h"

namespace fs = std::filesystem;
using namespace stokes::sim;

namespace {

class SurfaceMeshTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("stokes_mesh_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

openvdb::FloatGrid::Ptr sphere(double radius, const openvdb::Vec3f& centre, double dx) {
  return openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(float(radius), centre, float(dx), 3.0f);
}

}  // namespace

// A sphere of 8 cells' radius: a closed surface (every directed edge once, its reverse once) whose
// vertices lie on the sphere; the volume it encloses converges to the ball's at second order in
// the facet size: 0.63% short without subdivision, 0.16% with one (a quarter), and within 1% of
// the level set's own (smoothed-Heaviside, itself +0.38%) volume: 0.54%. The winding makes the volume positive.
TEST_F(SurfaceMeshTest, MeshOfALevelSetIsClosedAndEnclosesItsVolume) {
  const double r = 0.2, dx = 0.025;
  const openvdb::Vec3d centre(0.1, 0.5, -0.2);
  const auto grid = sphere(r, openvdb::Vec3f(centre), dx);
  const double ball = 4.0 / 3.0 * std::numbers::pi * r * r * r;
  const SurfaceMesh coarse = meshLevelSet(*grid, 0), mesh = meshLevelSet(*grid, 1);
  ASSERT_GT(coarse.triangles.size(), 1000u);
  EXPECT_EQ(mesh.triangles.size(), 4 * coarse.triangles.size());
  for (const SurfaceMesh* m : {&coarse, &mesh}) {
    EXPECT_EQ(openOrMisorientedEdges(*m), 0u);
    for (const auto& p : m->points) ASSERT_NEAR((openvdb::Vec3d(p) - centre).length(), r, 0.02 * dx);
  }
  const double e0 = 1.0 - enclosedVolume(coarse) / ball, e1 = 1.0 - enclosedVolume(mesh) / ball;
  EXPECT_GT(e0, 0.003);
  EXPECT_LT(e0, 0.01);
  EXPECT_NEAR(e1 / e0, 0.25, 0.05);  // second order in the facet size
  // the issue's bound against the level set's own volume, which reads +0.38% on this ball
  EXPECT_NEAR(enclosedVolume(mesh) / levelSetVolume(*grid), 1.0, 0.01);
  // a torn surface is seen
  SurfaceMesh torn = mesh;
  torn.triangles.pop_back();
  EXPECT_GT(openOrMisorientedEdges(torn), 0u);
  SurfaceMesh flipped = mesh;
  std::swap(flipped.triangles[0][0], flipped.triangles[0][1]);
  EXPECT_GT(openOrMisorientedEdges(flipped), 0u);
}

// Binary PLY round-trips every float; z-up turns (x, y, z) into (x, -z, y) and keeps the volume.
TEST_F(SurfaceMeshTest, PlyRoundTripsAndZUpTurnsTheMesh) {
  const auto grid = sphere(0.1, openvdb::Vec3f(0.0f, 0.5f, 0.0f), 0.02);
  SurfaceMesh mesh = meshLevelSet(*grid);
  const fs::path path = dir_ / "ball.ply";
  writePly(path.string(), mesh);
  EXPECT_FALSE(fs::exists(path.string() + ".tmp"));
  const SurfaceMesh back = readPly(path.string());
  ASSERT_EQ(back.points.size(), mesh.points.size());
  ASSERT_EQ(back.triangles, mesh.triangles);
  for (std::size_t i = 0; i < mesh.points.size(); ++i) ASSERT_EQ(back.points[i], mesh.points[i]);

  const double volume = enclosedVolume(mesh);
  applyUpAxis(mesh, UpAxis::Z);
  EXPECT_NEAR(enclosedVolume(mesh), volume, 1e-12);
  openvdb::Vec3d centre(0.0);
  for (const auto& p : mesh.points) centre += openvdb::Vec3d(p);
  centre /= double(mesh.points.size());
  EXPECT_NEAR(centre.z(), 0.5, 1e-3);  // the y-up height is now z
  EXPECT_NEAR(centre.y(), 0.0, 1e-3);

  std::ofstream(dir_ / "bad.ply") << "ply\nformat ascii 1.0\nend_header\n";
  EXPECT_THROW(readPly((dir_ / "bad.ply").string()), std::runtime_error);
}

// Vertex velocities: a "vel" grid holding an affine field on every voxel within two voxels of a
// ball's surface gives each vertex the field at its own position (trilinear weights reproduce an
// affine field), to float round-off; the PLY keeps them; the z-up frame turns them with the points.
TEST_F(SurfaceMeshTest, VertexVelocitiesSampleTheVelocityGrid) {
  const double dx = 0.02;
  const auto grid = sphere(0.1, openvdb::Vec3f(0.0f, 0.5f, 0.0f), dx);
  const auto field = [](const openvdb::Vec3d& x) {
    return openvdb::Vec3d(0.3 - 2.0 * x.y(), 1.5 * x.x() + 0.5 * x.z(), -0.7 + 4.0 * x.y());
  };
  openvdb::Vec3SGrid vel(openvdb::Vec3f(0.0f));
  vel.setTransform(grid->transform().copy());
  auto acc = vel.getAccessor();
  const auto phi = grid->getConstAccessor();
  const openvdb::CoordBBox box = grid->evalActiveVoxelBoundingBox();
  for (auto it = box.begin(); it; ++it)
    if (std::abs(phi.getValue(*it)) < 2.0 * dx) acc.setValue(*it, openvdb::Vec3f(field(grid->indexToWorld(*it))));

  SurfaceMesh mesh = meshLevelSet(*grid);
  sampleVertexVelocities(mesh, vel);
  ASSERT_EQ(mesh.velocities.size(), mesh.points.size());
  for (std::size_t i = 0; i < mesh.points.size(); ++i)
    ASSERT_LT((openvdb::Vec3d(mesh.velocities[i]) - field(openvdb::Vec3d(mesh.points[i]))).length(), 1e-5) << i;

  const fs::path path = dir_ / "moving.ply";
  writePly(path.string(), mesh);
  const SurfaceMesh back = readPly(path.string());
  ASSERT_EQ(back.velocities.size(), mesh.velocities.size());
  for (std::size_t i = 0; i < mesh.points.size(); ++i) {
    ASSERT_EQ(back.points[i], mesh.points[i]);
    ASSERT_EQ(back.velocities[i], mesh.velocities[i]);
  }
  const openvdb::Vec3f v0 = mesh.velocities[0];
  applyUpAxis(mesh, UpAxis::Z);
  EXPECT_EQ(mesh.velocities[0], openvdb::Vec3f(v0.x(), -v0.z(), v0.y()));
}

// A .vdb written z-up: the grid's own transform puts a voxel at height y at height z, and the
// particles' velocities turn with it.
TEST_F(SurfaceMeshTest, ZUpVdbTurnsTheTransformAndVelocities) {
  const auto grid = sphere(0.1, openvdb::Vec3f(0.0f, 0.5f, 0.0f), 0.02);
  const std::vector<Vec3d> x = {Vec3d(0.0, 0.5, 0.0)}, v = {Vec3d(0.0, -2.0, 1.0)};
  const fs::path path = dir_ / "frame.vdb";
  FrameGrids frame{grid, &x, &v, true};
  frame.up = UpAxis::Z;
  writeFrameVdb(path.string(), frame);
  const auto liquid = readLiquidGrid(path.string());
  const openvdb::Vec3d top = liquid->indexToWorld(grid->worldToIndex(openvdb::Vec3d(0.0, 0.6, 0.1)));
  EXPECT_NEAR(top.x(), 0.0, 1e-9);
  EXPECT_NEAR(top.y(), -0.1, 1e-9);
  EXPECT_NEAR(top.z(), 0.6, 1e-9);
  EXPECT_EQ(toUpAxis(v[0], UpAxis::Z), Vec3d(0.0, -1.0, -2.0));
  EXPECT_EQ(toUpAxis(v[0], UpAxis::Y), v[0]);
}

// A run with output.mesh writes frame_NNNN.ply next to each .vdb: closed, and enclosing the
// frame's level-set volume to 1% (the issue's bound) for a ball 8 cells across at res 32.
TEST_F(SurfaceMeshTest, RunWritesAClosedMeshPerFrame) {
  const std::string text = R"({"name": "mesh", "domain": {"min": [0, 0, 0], "max": [0.2, 0.2, 0.2]},
    "resolution": 32, "frames": 2, "fps": 24, "material": {"density": 1000, "viscosity": 10},
    "gravity": [0, -9.81, 0], "liquid": [{"shape": "sphere", "center": [0.1, 0.06, 0.1], "radius": 0.05}],
    "output": {"preview": false, "mesh": true, "up_axis": "z"}})";
  RunOptions options;
  options.outDir = (dir_ / "run").string();
  runScene(parseSceneText(text, "mesh.json", "."), options);
  for (const char* f : {"frame_0000", "frame_0002"}) {
    SCOPED_TRACE(f);
    const SurfaceMesh mesh = readPly((fs::path(options.outDir) / (std::string(f) + ".ply")).string());
    EXPECT_EQ(openOrMisorientedEdges(mesh), 0u);
    ASSERT_EQ(mesh.velocities.size(), mesh.points.size());
    const double level = levelSetVolume(*readLiquidGrid((fs::path(options.outDir) / (std::string(f) + ".vdb")).string()));
    EXPECT_NEAR(enclosedVolume(mesh) / level, 1.0, 0.01);
    double lowest = 1e9;
    for (const auto& p : mesh.points) lowest = std::min(lowest, double(p.z()));
    EXPECT_LT(lowest, 0.02);  // z-up: the ball rests near z = 0
  }
}
