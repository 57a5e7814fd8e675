// Geometry and output of the 3D simulator (sim/geometry/geometry.h, sim/output/vdb_frame.h, png_preview.h, stats_csv.h). Every expected number is
// fixed by geometry: exact distances, analytic volumes, file contents.
#include "sparse_grid/vdb_trees.h"
#include <openvdb/points/PointCount.h>
#include <openvdb/points/PointDataGrid.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/LevelSetFilter.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/ParticlesToLevelSet.h>

#include <gtest/gtest.h>
#include <stb/stb_image.h>

#include <unistd.h>

#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "sim/geometry/band_filter.h"
#include "sim/geometry/band_phi.h"
#include "sim/geometry/geometry.h"
#include "sim/output/png_preview.h"
#include "sim/output/stats_csv.h"
#include "sim/output/vdb_frame.h"
#include "sim/geometry/sphere_raster.h"

namespace stokes::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

/// The closed 12-triangle mesh of the box [lo, hi] (outward winding).
TriangleMesh boxMesh(const Vec3d& lo, const Vec3d& hi) {
  TriangleMesh m;
  for (int c = 0; c < 8; ++c)
    m.points.emplace_back((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(), (c & 4) ? hi.z() : lo.z());
  const unsigned quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.triangles.emplace_back(q[0], q[1], q[2]);
    m.triangles.emplace_back(q[0], q[2], q[3]);
  }
  return m;
}

ShapeDesc sphere(const Vec3d& c, double r) {
  ShapeDesc s;
  s.kind = ShapeDesc::Kind::Sphere;
  s.center = c;
  s.radius = r;
  return s;
}
ShapeDesc box(const Vec3d& lo, const Vec3d& hi) {
  ShapeDesc s;
  s.kind = ShapeDesc::Kind::Box;
  s.min = lo;
  s.max = hi;
  return s;
}
ShapeDesc plane(const Vec3d& p, const Vec3d& n) {
  ShapeDesc s;
  s.kind = ShapeDesc::Kind::Plane;
  s.point = p;
  s.normal = n;
  return s;
}
ShapeDesc meshShape(const Placement& placement = {}) {
  ShapeDesc s;
  s.kind = ShapeDesc::Kind::Mesh;
  s.meshPath = "test-mesh";
  s.placement = placement;
  return s;
}

/// Volume of A \ B plus B \ A for two balls of radius R whose centres are d apart (d < 2R):
/// 2 (4/3 pi R^3 - lens), lens = pi (4R + d)(2R - d)^2 / 12.
double twoBallSymmetricDifference(double R, double d) {
  const double lens = kPi * (4.0 * R + d) * (2.0 * R - d) * (2.0 * R - d) / 12.0;
  return 2.0 * (4.0 / 3.0 * kPi * R * R * R - lens);
}

std::filesystem::path scratchDir(const std::string& name) {
  auto dir = std::filesystem::temp_directory_path() /
             ("stokes_test_geometry_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  return dir;
}

// ---- analytic shapes ------------------------------------------------------------------------

TEST(ShapeField, AnalyticShapesAreExactSignedDistances) {
  const std::vector<ShapeDesc> shapes{sphere(Vec3d(1, 2, 3), 0.5)};
  ShapeField s(shapes, {}, 0.1);
  EXPECT_DOUBLE_EQ(s.phi(Vec3d(1, 2, 3)), -0.5);
  EXPECT_DOUBLE_EQ(s.phi(Vec3d(1, 2, 4)), 0.5);
  EXPECT_NEAR(s.phi(Vec3d(1, 2 + 0.3, 3)), -0.2, 1e-15);

  ShapeField b({box(Vec3d(0), Vec3d(1))}, {}, 0.1);
  EXPECT_DOUBLE_EQ(b.phi(Vec3d(0.5, 0.5, 0.5)), -0.5);
  EXPECT_NEAR(b.phi(Vec3d(0.5, 0.5, 0.9)), -0.1, 1e-15);
  EXPECT_DOUBLE_EQ(b.phi(Vec3d(2, 0.5, 0.5)), 1.0);
  EXPECT_DOUBLE_EQ(b.phi(Vec3d(2, 2, 0.5)), std::sqrt(2.0));  // nearest point is an edge
  EXPECT_DOUBLE_EQ(b.phi(Vec3d(2, 3, 3)), 3.0);               // nearest point is the corner (1,1,1)

  // Half-space below y = 0.25; the normal's length does not matter.
  ShapeField p({plane(Vec3d(7, 0.25, -3), Vec3d(0, 2, 0))}, {}, 0.1);
  EXPECT_DOUBLE_EQ(p.phi(Vec3d(3, 1, 4)), 0.75);
  EXPECT_DOUBLE_EQ(p.phi(Vec3d(3, -1, 4)), -1.25);

  // Union: the minimum.
  ShapeField u({box(Vec3d(0), Vec3d(1)), sphere(Vec3d(3, 0.5, 0.5), 0.5)}, {}, 0.1);
  EXPECT_DOUBLE_EQ(u.phi(Vec3d(2, 0.5, 0.5)), 0.5);
  EXPECT_DOUBLE_EQ(u.phi(Vec3d(1.4, 0.5, 0.5)), 0.4);
  EXPECT_FALSE(u.empty());
  EXPECT_TRUE(ShapeField({}, {}, 0.1).empty());
  EXPECT_GT(ShapeField({}, {}, 0.1).phi(Vec3d(0)), 1e300);
}

TEST(ShapeField, DomainWallPhiIsNegativeOutsideTheBox) {
  const Vec3d lo(0), hi(1, 2, 1);
  EXPECT_DOUBLE_EQ(domainWallPhi(Vec3d(0.5, 0.1, 0.5), lo, hi), 0.1);   // 0.1 above the floor
  EXPECT_DOUBLE_EQ(domainWallPhi(Vec3d(0.5, 1.0, 0.5), lo, hi), 0.5);   // nearest walls x = 0, 1
  EXPECT_DOUBLE_EQ(domainWallPhi(Vec3d(0.5, -0.2, 0.5), lo, hi), -0.2);
  EXPECT_DOUBLE_EQ(domainWallPhi(Vec3d(2, 3, 0.5), lo, hi), -std::sqrt(2.0));
}

TEST(ShapeField, GradientIsTheUnitNormal) {
  ShapeField s({sphere(Vec3d(1, 2, 3), 0.5)}, {}, 0.05);
  const Vec3d g = s.gradient(Vec3d(1, 2, 3.6));
  EXPECT_NEAR(g.x(), 0.0, 1e-12);
  EXPECT_NEAR(g.y(), 0.0, 1e-12);
  EXPECT_NEAR(g.z(), 1.0, 1e-12);
  const Vec3d d = Vec3d(1, 1, 1) / std::sqrt(3.0);
  const Vec3d g2 = s.gradient(Vec3d(1, 2, 3) + 0.7 * d);
  EXPECT_NEAR((g2 - d).length(), 0.0, 1e-3);  // O(h^2 / r^2) from the central difference
}

TEST(ShapeField, BoundingBoxesClipPlanesToTheDomain) {
  const openvdb::BBoxd domain(Vec3d(0), Vec3d(1));
  // Half-space x + y <= 0.5 inside the unit cube: x, y in [0, 0.5], z in [0, 1].
  ShapeField tilted({plane(Vec3d(0.25, 0.25, 0), Vec3d(1, 1, 0))}, {}, 0.1);
  const openvdb::BBoxd b = tilted.worldBBox(domain);
  EXPECT_NEAR((b.min() - Vec3d(0, 0, 0)).length(), 0.0, 1e-12);
  EXPECT_NEAR((b.max() - Vec3d(0.5, 0.5, 1)).length(), 0.0, 1e-12);

  // A floor y <= 0.25 and a sphere poking out of the domain at the top.
  ShapeField both({plane(Vec3d(0, 0.25, 0), Vec3d(0, 1, 0)), sphere(Vec3d(0.5, 1.0, 0.5), 0.2)}, {}, 0.1);
  const openvdb::BBoxd u = both.worldBBox(domain);
  EXPECT_NEAR((u.min() - Vec3d(0, 0, 0)).length(), 0.0, 1e-12);
  EXPECT_NEAR((u.max() - Vec3d(1, 1, 1)).length(), 0.0, 1e-12);
  // Cells [i dx, (i+1) dx] overlapping [0, 1]^3 with dx = 0.1: 0..10 (the max touches cell 10).
  const openvdb::CoordBBox c = both.indexBBox(domain);
  EXPECT_EQ(c.min(), openvdb::Coord(0, 0, 0));
  EXPECT_EQ(c.max(), openvdb::Coord(10, 10, 10));

  ShapeField outside({sphere(Vec3d(5), 0.5)}, {}, 0.1);
  EXPECT_TRUE(outside.indexBBox(domain).empty());
}

TEST(ShapeField, RejectsBadShapesNamingTheIndex) {
  try {
    ShapeField({sphere(Vec3d(0), 1), plane(Vec3d(0), Vec3d(0))}, {}, 0.1);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("shape 1 (plane)"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ShapeField({meshShape()}, {nullptr}, 0.1), std::invalid_argument);
  EXPECT_THROW(ShapeField({sphere(Vec3d(0), 1)}, {}, 0.0), std::invalid_argument);
}

// ---- meshes ---------------------------------------------------------------------------------

TEST(Placement, RotatesAboutXThenYThenZ) {
  Placement p;
  p.rotationDegrees = Vec3d(0, 0, 90);
  EXPECT_NEAR((applyPlacement(p, Vec3d(1, 0, 0)) - Vec3d(0, 1, 0)).length(), 0.0, 1e-12);
  // x first: (0,0,1) -Rx90-> (0,-1,0) -Rz90-> (1,0,0). (z first would give (0,0,1) -> (0,-1,0).)
  p.rotationDegrees = Vec3d(90, 0, 90);
  EXPECT_NEAR((applyPlacement(p, Vec3d(0, 0, 1)) - Vec3d(1, 0, 0)).length(), 0.0, 1e-12);
  // Scale, then rotate, then translate.
  p.rotationDegrees = Vec3d(0, 90, 0);  // Ry90: (1,0,0) -> (0,0,-1)
  p.scale = 2.0;
  p.translation = Vec3d(1, 2, 3);
  EXPECT_NEAR((applyPlacement(p, Vec3d(1, 0, 0)) - Vec3d(1, 2, 1)).length(), 0.0, 1e-12);
}

TEST(MeshLevelSet, UnitCubeHasDepthHalfAndVolumeOne) {
  const double dx = 1.0 / 32.0;
  const TriangleMesh cube = boxMesh(Vec3d(0), Vec3d(1));
  ShapeField f({meshShape()}, {&cube}, dx);
  // The whole interior holds distances (default MeshLevelSetOptions).
  // The centre is a voxel corner and the kink of the distance (a maximum of |phi|): trilinear
  // interpolation reads -(0.5 - dx/2) there.
  EXPECT_NEAR(f.phi(Vec3d(0.5, 0.5, 0.5)), -0.5, 0.75 * dx);
  EXPECT_NEAR(f.phi(Vec3d(0.5, 0.5, 0.2)), -0.2, 0.5 * dx);
  EXPECT_NEAR(f.phi(Vec3d(1.0 + 2 * dx, 0.5, 0.5)), 2 * dx, 0.25 * dx);
  EXPECT_GT(f.phi(Vec3d(3, 3, 3)), 0.0);  // far outside: +background
  const double volume = levelSetVolume(*f.meshGrid(0));
  EXPECT_NEAR(volume, 1.0, 0.02);
  std::printf("[ measured ] cube mesh, dx = 1/32: phi(centre) = %.5f, volume = %.5f\n",
              f.phi(Vec3d(0.5)), volume);

  // Narrow interior band: still negative deep inside (sign-flooded).
  MeshLevelSetOptions narrow;
  narrow.interiorBandCells = 3.0;
  ShapeField g({meshShape()}, {&cube}, dx, narrow);
  EXPECT_NEAR(g.phi(Vec3d(0.5)), -3.0 * dx, 1e-6);
}

TEST(MeshLevelSet, PlacementMovesTheMesh) {
  // Box [0,2]x[0,0.5]x[0,0.5], scaled by 1/2, rotated 90 degrees about z, moved by (1,1,1):
  // it becomes [0.75,1]x[1,2]x[1,1.25]; the vertex (2,0,0) lands on (1,2,1).
  const double dx = 1.0 / 32.0;
  const TriangleMesh bar = boxMesh(Vec3d(0), Vec3d(2, 0.5, 0.5));
  Placement p;
  p.scale = 0.5;
  p.rotationDegrees = Vec3d(0, 0, 90);
  p.translation = Vec3d(1, 1, 1);
  EXPECT_NEAR((applyPlacement(p, Vec3d(2, 0, 0)) - Vec3d(1, 2, 1)).length(), 0.0, 1e-12);
  // Meshes given per shape (parallel to the shape list) -- the sphere's entry is ignored.
  ShapeField f({sphere(Vec3d(-5), 0.1), meshShape(p)}, {nullptr, &bar}, dx);
  EXPECT_NEAR(f.phi(Vec3d(1, 2, 1)), 0.0, 0.5 * dx);                // the moved vertex
  EXPECT_NEAR(f.phi(Vec3d(0.875, 1.5, 1.125)), -0.125, 0.5 * dx);   // centre of the moved bar
  EXPECT_GT(f.phi(Vec3d(1.5, 1.1, 1.1)), 0.0);  // inside the unrotated bar, outside the rotated one
  const openvdb::BBoxd b = f.worldBBox(openvdb::BBoxd(Vec3d(0), Vec3d(3)));
  EXPECT_NEAR(b.min().x(), 0.75, 1e-6);  // the placed vertices' box
  EXPECT_NEAR(b.max().y(), 2.0, 1e-6);
}

// ---- liquid from particles ------------------------------------------------------------------

/// Particles at 2x2x2 per cell (cell-centred stratified positions dx (i + 1/4 + a/2)) inside a ball.
std::vector<Vec3d> ballParticles(const Vec3d& c, double R, double dx) {
  std::vector<Vec3d> out;
  const int n = static_cast<int>(std::ceil(R / dx)) + 1;
  const openvdb::Coord base = openvdb::Coord::floor(c / dx);
  for (int i = -n; i <= n; ++i)
    for (int j = -n; j <= n; ++j)
      for (int k = -n; k <= n; ++k)
        for (int s = 0; s < 8; ++s) {
          const Vec3d x = dx * (Vec3d(base.x() + i, base.y() + j, base.z() + k) +
                                Vec3d(0.25 + 0.5 * (s & 1), 0.25 + 0.5 * ((s >> 1) & 1), 0.25 + 0.5 * (s >> 2)));
          if ((x - c).length() < R) out.push_back(x);
        }
  return out;
}

/// A dense ball of particles (8 per cell, radius 0.4, a deep interior) and 2,000 lone particles
/// scattered above it (thin features), the cloud drawn from `seed`.
std::vector<Vec3d> ballAndCloud(double dx, std::uint64_t seed) {
  std::vector<Vec3d> particles = ballParticles(Vec3d(0.03, -0.1, 0.02), 0.4, dx);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-0.9, 0.9);
  for (int i = 0; i < 2000; ++i) particles.emplace_back(u(rng), 0.6 + 0.3 * u(rng), u(rng));
  return particles;
}

/// An empty cell-centred level set of voxel dx and half width 3 voxels (the liquid's).
openvdb::FloatGrid::Ptr emptyLevelSet(double dx) {
  auto g = openvdb::FloatGrid::create(float(3.0 * dx));
  g->setTransform(cellCentredTransform(dx));
  g->setGridClass(openvdb::GRID_LEVEL_SET);
  return g;
}

// The surface of a seeded ball (8 particles per cell, R = 9.6 cells) encloses its volume to 1%:
// the erosion puts it half a particle spacing beyond the outermost centres, where the particles'
// volume ends, and 1% of the volume is a mean surface shift of R / 300 = 0.03 dx. Measured 0.9985
// (the raw union of spheres: 1.268); eroding by a whole spacing instead of half shifts the surface
// by 0.25 dx, about 8%.
TEST(LiquidFromParticles, BallKeepsItsVolume) {
  const double dx = 1.0 / 32.0, R = 0.3;  // 9.6 cells
  const Vec3d c(0.5, 0.5, 0.5);
  const auto particles = ballParticles(c, R, dx);
  auto grid = liquidLevelSetFromParticles(particles, dx);
  EXPECT_EQ(grid->getName(), "liquid");
  EXPECT_EQ(grid->getGridClass(), openvdb::GRID_LEVEL_SET);
  EXPECT_NEAR(grid->voxelSize().x(), dx, 1e-15);
  // Voxel (i,j,k) is centred at dx (i + 1/2).
  const Vec3d w = grid->indexToWorld(openvdb::Coord(3, 0, 0));
  EXPECT_NEAR(w.x(), 3.5 * dx, 1e-12);
  const double exact = 4.0 / 3.0 * kPi * R * R * R;
  const double volume = levelSetVolume(*grid);
  EXPECT_NEAR(volume / exact, 1.0, 0.01);
  GridPhi phi(grid);
  EXPECT_LT(phi(c), 0.0);
  EXPECT_GT(phi(c + Vec3d(R + 4 * dx, 0, 0)), 0.0);
  EXPECT_NEAR(phi(c + Vec3d(R, 0, 0)), 0.0, 0.75 * dx);

  ParticleSurfaceOptions raw;
  raw.particleSpacingInCells = 0.0;  // union of radius-1-cell spheres, no erosion
  raw.smoothingPasses = 0;
  const double rawVolume = levelSetVolume(*liquidLevelSetFromParticles(particles, dx, 1.0, 3.0, raw));
  std::printf("[ measured ] %zu particles, ball R = %.1f cells: volume / exact = %.4f "
              "(raw union of spheres: %.4f)\n",
              particles.size(), R / dx, volume / exact, rawVolume / exact);
  EXPECT_GT(rawVolume, volume);

  auto empty = liquidLevelSetFromParticles({}, dx);
  EXPECT_EQ(levelSetVolume(*empty), 0.0);
  EXPECT_GT(GridPhi(empty)(c), 0.0);
}

// The deep interior left out of the raster (the default margin, 3 voxels) changes the surface by
// a sliver: the filters' values near the zero level hardly depend on voxels 3.5 or more voxels
// inside (measured: 3e-8 of the volume, 3e-5 dx at most where |phi| < dx).
TEST(LiquidFromParticles, DeepInteriorKeepsTheSurface) {
  const double dx = 1.0 / 32.0, R = 0.4;  // 12.8 cells
  const auto particles = ballParticles(Vec3d(0.5, 0.5, 0.5), R, dx);
  ParticleSurfaceOptions whole, deep;
  whole.deepInteriorMargin = -1;
  ASSERT_EQ(deep.deepInteriorMargin, 3);
  auto a = liquidLevelSetFromParticles(particles, dx, 1.0, 3.0, whole);
  auto b = liquidLevelSetFromParticles(particles, dx, 1.0, 3.0, deep);
  const double va = levelSetVolume(*a), vb = levelSetVolume(*b);
  double worst = 0.0;  // largest change of phi where the whole union's |phi| < dx
  std::size_t near = 0;
  const auto acc = b->getConstAccessor();
  for (auto v = a->tree().cbeginValueOn(); v; ++v)
    if (std::abs(*v) < dx) {
      ++near;
      worst = std::max(worst, std::abs(double(acc.getValue(v.getCoord())) - double(*v)));
    }
  std::printf("[ measured ] volume whole %.8g deep %.8g (%.2e relative); near-surface voxels %zu, largest "
              "|change| %.3g dx; active voxels %zu -> %zu\n",
              va, vb, vb / va - 1.0, near, worst / dx, std::size_t(a->activeVoxelCount()),
              std::size_t(b->activeVoxelCount()));
  EXPECT_GT(near, 3000u);
  EXPECT_NEAR(vb / va, 1.0, 1e-6);
  EXPECT_LT(worst, 1e-3 * dx);
  EXPECT_LT(b->activeVoxelCount(), a->activeVoxelCount());  // the speed is bench_stages' (BM_ParticleSurface)
  EXPECT_LT(GridPhi(b)(Vec3d(0.5, 0.5, 0.5)), -2.5 * dx);  // the centre is the inside tile
}

/// A level set phi = z - h over a 16 x 16 x 24 block of voxels, every voxel set (no band, no
/// tiles), background 20 dx: its volume by the smoothed Heaviside is exactly 16 x 16 cells times h.
openvdb::FloatGrid::Ptr planeLevelSet(double dx, double h) {
  auto grid = openvdb::FloatGrid::create(static_cast<float>(20 * dx));
  grid->setTransform(cellCentredTransform(dx));
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  auto acc = grid->getAccessor();
  for (int i = 0; i < 16; ++i)
    for (int j = 0; j < 16; ++j)
      for (int k = 0; k < 24; ++k) acc.setValue(openvdb::Coord(i, j, k), static_cast<float>((k + 0.5) * dx - h));
  return grid;
}

// Moving a plane by c changes its volume by exactly c times its area: the match finds c from the
// volume, moves every value by it, honours a clip, and stops at its bound.
TEST(MatchClippedVolume, MovesAPlaneByTheOffsetItsVolumeNeeds) {
  const double dx = 0.125, h = 7.3 * dx, area = 16 * 16 * dx * dx;
  const auto noClip = [](const Vec3d&) { return -1e9; };
  auto grid = planeLevelSet(dx, h);
  EXPECT_NEAR(levelSetVolume(*grid), h * area, 1e-6 * area * dx);  // float values
  const VolumeMatch m = matchClippedVolume(*grid, (h + 0.3 * dx) * area, noClip, 0.5 * dx);
  EXPECT_NEAR(m.offset, 0.3 * dx, 1e-8 * dx);
  EXPECT_NEAR(m.volume, (h + 0.3 * dx) * area, 1e-6 * area * dx);
  EXPECT_FALSE(m.bounded);
  const auto acc = grid->getConstAccessor();
  EXPECT_NEAR(acc.getValue(openvdb::Coord(3, 4, 9)), (9.5 * dx - h - 0.3 * dx), 1e-6);
  EXPECT_NEAR(levelSetVolume(*grid), (h + 0.3 * dx) * area, 1e-6 * area * dx);

  // Only x < 6 dx counts: 6 of the 16 columns; shrinking the plane by 0.2 dx there.
  auto clipped = planeLevelSet(dx, h);
  const auto halfSpace = [dx](const Vec3d& x) { return x.x() - 6 * dx; };
  const VolumeMatch mc = matchClippedVolume(*clipped, (h - 0.2 * dx) * area * 6 / 16, halfSpace, 0.5 * dx);
  EXPECT_NEAR(mc.offset, -0.2 * dx, 1e-8 * dx);

  // A target beyond the bound: the surface moves by the bound and says so.
  auto far = planeLevelSet(dx, h);
  const VolumeMatch mb = matchClippedVolume(*far, (h + 2.0 * dx) * area, noClip, 0.5 * dx);
  EXPECT_TRUE(mb.bounded);
  EXPECT_DOUBLE_EQ(mb.offset, 0.5 * dx);
  EXPECT_NEAR(mb.volume, (h + 0.5 * dx) * area, 1e-6 * area * dx);
  EXPECT_THROW(matchClippedVolume(*far, area, noClip, 20 * dx), std::invalid_argument);
}

// The union of spheres is a maximum over the particles: disorder that keeps their density (here
// Gaussian noise of 0.15 dx on a stratified ball, a particle volume of dx^3 / 8 each) pushes the
// eroded surface out by several percent of the ball's volume. Matched to the volume the particles
// carry (the lattice's count inside the ball times dx^3 / 8: the analytic volume to 1%), the surface
// moves inwards and lies on the ball's sphere again.
TEST(MatchClippedVolume, HoldsTheVolumeParticlesCarryUnderDisorder) {
  const double dx = 1.0 / 32.0, R = 0.3;  // 9.6 cells
  const Vec3d c(0.5, 0.5, 0.5);
  std::vector<Vec3d> particles = ballParticles(c, R, dx);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0.0, 0.15 * dx);
  for (Vec3d& x : particles)
    for (int a = 0; a < 3; ++a) x[a] += noise(rng);
  ParticleSurfaceOptions surface;
  surface.particleSpacingInCells = 0.5;
  auto grid = liquidLevelSetFromParticles(particles, dx, 1.0, 3.0, surface);
  const double exact = 4.0 / 3.0 * kPi * R * R * R, carried = double(particles.size()) * dx * dx * dx / 8.0;
  const double raw = levelSetVolume(*grid);
  const VolumeMatch m = matchClippedVolume(*grid, carried, [](const Vec3d&) { return -1e9; }, 0.5 * dx);
  std::printf("[ measured ] ball of %zu particles, noise 0.15 dx: eroded union %+.2f%% of the volume they carry, "
              "matched %+.2e, offset %.4f dx\n",
              particles.size(), 100.0 * (raw / carried - 1.0), m.volume / carried - 1.0, m.offset / dx);
  EXPECT_NEAR(carried / exact, 1.0, 0.01);
  EXPECT_GT(raw / carried, 1.02);
  EXPECT_NEAR(m.volume / carried, 1.0, 1e-9);
  EXPECT_NEAR(levelSetVolume(*grid) / carried, 1.0, 1e-6);
  EXPECT_LT(m.offset, 0.0);
  EXPECT_FALSE(m.bounded);
  const GridPhi phi(grid);
  double meanRadiusError = 0.0;  // signed distance at the sphere along the six axis directions
  for (int a = 0; a < 3; ++a)
    for (double sign : {-1.0, 1.0}) {
      Vec3d x = c;
      x[a] += sign * R;
      meanRadiusError += phi(x) / 6.0;
    }
  EXPECT_LT(std::abs(meanRadiusError), 0.25 * dx);
}

/// Every leaf (origin, value buffer, active mask) and every tile (value, active) of two trees
/// agree bit for bit.
void expectSameTree(const openvdb::FloatTree& a, const openvdb::FloatTree& b) {
  EXPECT_EQ(a.leafCount(), b.leafCount());
  EXPECT_EQ(a.activeVoxelCount(), b.activeVoxelCount());
  std::size_t compared = 0, differing = 0;
  for (auto leaf = a.cbeginLeaf(); leaf; ++leaf) {
    const auto* other = b.probeConstLeaf(leaf->origin());
    ASSERT_NE(other, nullptr) << "leaf " << leaf->origin() << " missing";
    for (openvdb::Index i = 0; i < openvdb::FloatTree::LeafNodeType::SIZE; ++i) {
      ++compared;
      const float va = leaf->getValue(i), vb = other->getValue(i);
      if (std::memcmp(&va, &vb, sizeof va) != 0 || leaf->isValueOn(i) != other->isValueOn(i)) ++differing;
    }
  }
  EXPECT_EQ(differing, 0u) << "of " << compared << " voxels";
  std::size_t tilesA = 0, tilesB = 0;
  for (auto it = a.cbeginValueAll(); it; ++it)
    if (it.isTileValue()) {
      ++tilesA;
      EXPECT_EQ(*it, b.getValue(it.getCoord())) << "tile at " << it.getCoord();
    }
  for (auto it = b.cbeginValueAll(); it; ++it) tilesB += it.isTileValue() ? 1 : 0;
  EXPECT_EQ(tilesA, tilesB);
}

// The leaf-by-leaf raster (sim/geometry/sphere_raster.h) writes what OpenVDB's ParticlesToLevelSet writes,
// bit for bit: a dense jittered ball (8 particles per cell, a deep interior), a sparse cloud (no
// interior) and a few lone particles, on both sides of the origin, for radii of 1 and 1.5 cells.
TEST(SphereRaster, IsOpenVdbsParticleRasterBitForBit) {
  const double dx = 1.0 / 32.0;  // a power of 2: the voxel-centre particle below is exact
  std::vector<Vec3d> particles = ballParticles(Vec3d(-0.05, 0.1, 0.02), 0.35, dx);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-0.9, 0.9);
  for (int i = 0; i < 3000; ++i) particles.emplace_back(u(rng), 0.6 + 0.3 * u(rng), u(rng));
  particles.emplace_back(0.0, -0.8, 0.0);
  particles.emplace_back(12.5 * dx, -11.5 * dx, -6.5 * dx);  // exactly on the centre of voxel (12, -12, -7)
  ASSERT_GT(particles.size(), 20000u);
  for (double radiusInCells : {1.0, 1.5, 3.5}) {  // 3.5: R + w = 6.5 voxels, and R > w marks voxels inside
    auto reference = emptyLevelSet(dx), ours = emptyLevelSet(dx);
    {
      openvdb::tools::ParticlesToLevelSet<openvdb::FloatGrid> raster(*reference);
      raster.setRmin(0.0);
      raster.rasterizeSpheres(ParticlePositionList(particles), radiusInCells * dx);
      raster.finalize(/*prune=*/true);
    }
    rasterizeSphereUnion(*ours, particles, radiusInCells * dx);
    ASSERT_GT(reference->activeVoxelCount(), 100000u);
    expectSameTree(reference->tree(), ours->tree());
  }
  auto tooWide = openvdb::FloatGrid::create(float(7.0 * dx));
  tooWide->setTransform(cellCentredTransform(dx));
  EXPECT_THROW(rasterizeSphereUnion(*tooWide, particles, dx), std::invalid_argument);
}

// With a deep margin K the raster leaves out exactly the voxels whose cells within K voxels along
// each axis all hold particles (inactive at -background), and writes every other voxel as OpenVDB
// does, bit for bit: the dense ball has a deep interior, the cloud around it none.
TEST(SphereRaster, LeavesOutExactlyTheDeepInterior) {
  const double dx = 1.0 / 32.0;
  const std::vector<Vec3d> particles = ballAndCloud(dx, 11);
  auto full = emptyLevelSet(dx);
  rasterizeSphereUnion(*full, particles, dx);
  std::set<std::tuple<int, int, int>> occupied;  // cells floor(P), P in index space
  for (const Vec3d& x : particles) {
    const Vec3d P = full->transform().worldToIndex(x);
    occupied.emplace(int(std::floor(P[0])), int(std::floor(P[1])), int(std::floor(P[2])));
  }
  for (int K : {0, 3, kMaxDeepMargin}) {
    auto isDeep = [&](const openvdb::Coord& c) {
      for (int i = -1 - K; i <= K; ++i)
        for (int j = -1 - K; j <= K; ++j)
          for (int k = -1 - K; k <= K; ++k)
            if (!occupied.count({c.x() + i, c.y() + j, c.z() + k})) return false;
      return true;
    };
    auto deep = emptyLevelSet(dx);
    rasterizeSphereUnion(*deep, particles, dx, K);
    const auto fullAcc = full->getConstAccessor();
    const auto deepAcc = deep->getConstAccessor();
    std::size_t deepVoxels = 0, same = 0, differing = 0;
    for (auto leaf = full->tree().cbeginLeaf(); leaf; ++leaf)
      for (openvdb::Index i = 0; i < openvdb::FloatTree::LeafNodeType::SIZE; ++i) {
        const openvdb::Coord c = leaf->offsetToGlobalCoord(i);
        const float vd = deepAcc.getValue(c), vf = fullAcc.getValue(c);
        if (isDeep(c)) {
          ++deepVoxels;
          differing += deepAcc.isValueOn(c) || vd != -deep->background() ? 1 : 0;
        } else if (std::memcmp(&vd, &vf, sizeof vd) == 0 && deepAcc.isValueOn(c) == fullAcc.isValueOn(c)) {
          ++same;
        } else {
          ++differing;
        }
      }
    EXPECT_EQ(differing, 0u) << "K = " << K;
    EXPECT_GT(deepVoxels, K < kMaxDeepMargin ? 1000u : 10u) << "K = " << K;  // a 14^3 cube fits in the ball
    EXPECT_GT(same, 10000u) << "K = " << K;
    EXPECT_LT(deep->activeVoxelCount(), full->activeVoxelCount()) << "K = " << K;
  }
  EXPECT_THROW(rasterizeSphereUnion(*emptyLevelSet(dx), particles, dx, kMaxDeepMargin + 1), std::invalid_argument);
}

// BandFilter (sim/geometry/band_filter.h) writes what OpenVDB's LevelSetFilter writes, bit for bit:
// the liquid's own sequence (one mean-curvature pass, an erosion of 0.79 dx in two steps) and a
// dilation, on the raster of a dense ball with a deep interior and a cloud of lone particles (thin
// features, tiles of both signs, leaves appearing and vanishing).
TEST(BandFilter, IsOpenVdbsLevelSetFilterBitForBit) {
  const double dx = 1.0 / 32.0;
  const std::vector<Vec3d> particles = ballAndCloud(dx, 5);
  for (int deep : {-1, 3}) {
    auto raster = emptyLevelSet(dx);
    rasterizeSphereUnion(*raster, particles, dx, deep);
    openvdb::tools::signedFloodFill(raster->tree(), true, 1, /*minLevel=*/1);
    auto reference = raster->deepCopy(), ours = raster->deepCopy();
    {
      openvdb::tools::LevelSetFilter<openvdb::FloatGrid> filter(*reference);
      filter.meanCurvature();
      filter.offset(float(0.79 * dx));
    }
    {
      BandFilter filter(*ours);
      filter.meanCurvature();
      filter.offset(float(0.79 * dx));
    }
    ASSERT_GT(reference->activeVoxelCount(), 50000u);
    expectSameTree(reference->tree(), ours->tree());
    {
      openvdb::tools::LevelSetFilter<openvdb::FloatGrid> filter(*reference);
      filter.offset(float(-1.3 * dx));  // dilation: three steps, the last 0.3 dx
    }
    BandFilter(*ours).offset(float(-1.3 * dx));
    expectSameTree(reference->tree(), ours->tree());
  }
  auto fog = openvdb::FloatGrid::create(1.0f);
  EXPECT_THROW(BandFilter{*fog}, std::invalid_argument);
}

TEST(GridPhi, IsThreadSafeAndMatchesSerialSampling) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.4f, openvdb::Vec3f(0.5f), 1.0f / 32.0f);
  const GridPhi phi(grid);
  const int n = 20000;
  std::vector<double> parallel(n), serial(n);
  auto pos = [](int i) { return Vec3d(0.01 + 0.98 * ((i * 37) % 101) / 100.0, 0.5 + 0.3 * std::sin(i), 0.5); };
#pragma omp parallel for
  for (int i = 0; i < n; ++i) parallel[i] = phi(pos(i));
  for (int i = 0; i < n; ++i) serial[i] = phi(pos(i));
  EXPECT_EQ(parallel, serial);
  EXPECT_NEAR(phi(Vec3d(0.5, 0.5, 0.5 + 0.4)), 0.0, 1e-3);
  EXPECT_FLOAT_EQ(static_cast<float>(phi(Vec3d(5))), grid->background());
}

// GridPhi reads the corners from the leaf buffer or the tile it cached: it must give
// openvdb::tools::BoxSampler's value bit for bit everywhere -- in the band, across leaf faces,
// in interior tiles (the sphere of radius 0.4 at dx = 1/64 has some) and outside the tree.
TEST(GridPhi, IsBoxSamplersTrilinearSampleBitForBit) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.4f, openvdb::Vec3f(0.5f), 1.0f / 64.0f);
  std::size_t tiles = 0;
  for (auto it = grid->tree().cbeginValueAll(); it; ++it) tiles += it.isTileValue() ? 1 : 0;
  ASSERT_GT(tiles, 0u);
  const GridPhi phi(grid);
  auto acc = grid->getConstAccessor();
  std::size_t differing = 0, inTiles = 0;
  for (int i = 0; i < 200000; ++i) {  // a low-discrepancy walk over [-0.05, 1.05]^3
    const Vec3d x(-0.05 + 1.1 * std::fmod(0.5 + i * 0.7548776662, 1.0), -0.05 + 1.1 * std::fmod(0.5 + i * 0.5698402910, 1.0),
                  -0.05 + 1.1 * std::fmod(0.5 + i * 0.3176721961, 1.0));
    const Vec3d ijk = grid->transform().worldToIndex(x);
    const double expected = double(openvdb::tools::BoxSampler::sample(acc, ijk));
    const double got = phi(x);
    differing += std::memcmp(&expected, &got, sizeof got) != 0 ? 1 : 0;
    inTiles += expected == -double(grid->background()) ? 1 : 0;
  }
  EXPECT_EQ(differing, 0u);
  EXPECT_GT(inTiles, 1000u);
}

// BandPhi reads the eight corners from its per-block copies: GridPhi's value bit for bit, inside
// the layout's blocks, across their faces, in interior tiles and outside the layout (where it asks
// GridPhi), for layouts whose origin is a whole number of cells (copies used) or not (none).
TEST(BandPhi, IsGridPhisSampleBitForBit) {
  const double dx = 1.0 / 64.0;
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.4f, openvdb::Vec3f(0.5f), float(dx));
  grid->setTransform(cellCentredTransform(dx));  // voxel (i,j,k) centred at dx ((i,j,k) + 1/2)
  const GridPhi gridPhi(grid);
  openvdb::MaskTree cells;
  sparse_grid::activateBox(cells, openvdb::Coord(10, 12, 9), openvdb::Coord(50, 47, 53));
  for (const Vec3d origin : {Vec3d(0.0), Vec3d(-4 * dx, 2 * dx, 0.0), Vec3d(0.3 * dx, 0.0, 0.0)}) {
    const sparse_grid::BlockLayout<3> layout(cells, dx, origin);
    const BandPhi bandPhi(grid, layout);
    EXPECT_EQ(bandPhi.cached(), origin[0] != 0.3 * dx);
    std::size_t differing = 0, inTiles = 0;
    for (int i = 0; i < 100000; ++i) {
      const Vec3d x(-0.05 + 1.1 * std::fmod(0.5 + i * 0.7548776662, 1.0), -0.05 + 1.1 * std::fmod(0.5 + i * 0.5698402910, 1.0),
                    -0.05 + 1.1 * std::fmod(0.5 + i * 0.3176721961, 1.0));
      const double expected = gridPhi(x), got = bandPhi(x);
      differing += std::memcmp(&expected, &got, sizeof got) != 0 ? 1 : 0;
      inTiles += expected == -double(grid->background()) ? 1 : 0;
    }
    EXPECT_EQ(differing, 0u) << "origin " << origin;
    EXPECT_GT(inTiles, 1000u);
  }
}

// ---- volumes --------------------------------------------------------------------------------

TEST(Volumes, SymmetricDifferenceOfTwoBallsIsTheLensFormula) {
  const double R = 0.5, d = 0.4;
  auto a = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(float(R), openvdb::Vec3f(0), 1.0f / 32.0f);
  auto b = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(float(R), openvdb::Vec3f(float(d), 0, 0),
                                                                   1.0f / 24.0f);  // coarser: sampled at 1/32
  EXPECT_EQ(symmetricVolumeDifference(*a, *a), 0.0);
  const double exact = twoBallSymmetricDifference(R, d);  // 0.5948
  const double measured = symmetricVolumeDifference(*a, *b);
  EXPECT_NEAR(measured / exact, 1.0, 0.03);
  EXPECT_DOUBLE_EQ(measured, symmetricVolumeDifference(*b, *a));
  std::printf("[ measured ] two balls R = 0.5, d = 0.4: sym. difference %.5f, exact %.5f\n", measured, exact);

  auto empty = openvdb::createLevelSet<openvdb::FloatGrid>(1.0 / 32.0);
  EXPECT_NEAR(symmetricVolumeDifference(*a, *empty), 4.0 / 3.0 * kPi * R * R * R, 0.02);
  EXPECT_NEAR(levelSetVolume(*a), 4.0 / 3.0 * kPi * R * R * R, 0.005);
}

TEST(Volumes, ShapeFieldToLevelSetMatchesTheShape) {
  const double dx = 1.0 / 32.0;
  ShapeField f({sphere(Vec3d(0.5), 0.3), plane(Vec3d(0, 0.1, 0), Vec3d(0, 1, 0))}, {}, dx);
  const openvdb::BBoxd domain(Vec3d(0), Vec3d(1));
  auto grid = f.toLevelSet(domain);
  EXPECT_EQ(grid->getGridClass(), openvdb::GRID_LEVEL_SET);
  // Ball + slab of height 0.1 over the unit square (they do not overlap: 0.5 - 0.3 > 0.1), but the
  // sampled grid also holds the slab's band cells outside the domain; measure inside it only.
  GridPhi phi(grid);
  EXPECT_NEAR(phi(Vec3d(0.5, 0.5, 0.5)), -3.0 * dx, 1e-6);  // deep inside: -background
  EXPECT_NEAR(phi(Vec3d(0.5, 0.5, 0.5 + 0.28)), -0.02, 2e-3);  // trilinear on a curved field
  EXPECT_NEAR(phi(Vec3d(0.5, 0.05, 0.5)), -0.05, 1e-6);
  EXPECT_LT(phi(Vec3d(0.3, 0.01, 0.9)), 0.0);
  EXPECT_GT(phi(Vec3d(0.1, 0.9, 0.1)), 0.0);
}

// ---- output ---------------------------------------------------------------------------------

// A frame written and read back: the liquid level set bit for bit, and every particle's position
// and velocity to float precision (the points grid stores Vec3f: positions as voxel offsets of at
// most half a cell, error <= 2^-25 dx; velocities below 2 m/s, error <= 2^-23 m/s). Each velocity's
// x component carries its particle's index (exact in float below 2^24), so every point read back is
// matched to the particle written.
// "vel" is the trilinear average of the particles' velocities: the particles of ballParticles sit
// at +-1/4 and +-3/4 of a voxel from each voxel centre in every axis, symmetric, so inside the
// liquid the average of a linear field is the field at the voxel centre (to float round-off); and
// no voxel farther than one voxel outside the liquid has a value.
TEST(Output, VelocityGridIsTheParticlesAverage) {
  const double dx = 1.0 / 16.0;
  const auto particles = ballParticles(Vec3d(0.5), 0.4, dx);
  auto field = [](const Vec3d& x) { return Vec3d(0.2 - 0.8 * (x.y() - 0.5), 0.8 * (x.x() - 0.5) - 1.0, 0.3 * x.z()); };
  std::vector<Vec3d> velocities;
  for (const Vec3d& x : particles) velocities.push_back(field(x));
  const auto liquid = liquidLevelSetFromParticles(particles, dx);
  const auto vel = particleVelocityGrid(particles, velocities, *liquid);
  EXPECT_EQ(vel->getName(), "vel");
  EXPECT_EQ(vel->getVectorType(), openvdb::VEC_CONTRAVARIANT_RELATIVE);
  const auto phi = liquid->getConstAccessor();
  std::size_t inside = 0;
  double worst = 0.0;
  for (auto it = vel->cbeginValueOn(); it; ++it) {
    const double d = phi.getValue(it.getCoord());
    EXPECT_LT(d, dx) << it.getCoord();
    if (d > -2.0 * dx) continue;
    ++inside;
    const Vec3d expected = field(vel->indexToWorld(it.getCoord()));
    worst = std::max(worst, (Vec3d(*it) - expected).length());
  }
  std::printf("[ measured ] vel on %zu voxels inside: largest error %.2e m/s\n", inside, worst);
  EXPECT_GT(inside, 100u);
  EXPECT_LT(worst, 1e-6);
}

TEST(Output, FrameVdbRoundTrips) {
  const auto dir = scratchDir("vdb");
  const double dx = 1.0 / 16.0;
  const auto particles = ballParticles(Vec3d(0.5), 0.25, dx);
  std::vector<Vec3d> velocities(particles.size());
  for (std::size_t p = 0; p < particles.size(); ++p)
    velocities[p] = Vec3d(double(p), -1.0 - particles[p].y(), 0.5 + 0.3 * particles[p].z());
  auto liquid = liquidLevelSetFromParticles(particles, dx);

  const std::string onlyLiquid = (dir / "a.vdb").string();
  writeFrameVdb(onlyLiquid, FrameGrids{liquid});
  EXPECT_EQ(readVdbGridNames(onlyLiquid), std::vector<std::string>{"surface"});

  const std::string withPoints = (dir / "b.vdb").string();
  writeFrameVdb(withPoints, FrameGrids{liquid, &particles, &velocities, true, {1.5, 3, "ball"}});
  EXPECT_FALSE(std::filesystem::exists(withPoints + ".tmp"));
  EXPECT_EQ(readVdbGridNames(withPoints), (std::vector<std::string>{"particles", "surface", "vel"}));  // by name
  auto back = readLiquidGrid(withPoints);
  EXPECT_NEAR(back->voxelSize().x(), dx, 1e-15);
  const GridPhi written(liquid), read(back);
  for (int i = 0; i < 50; ++i) {
    const Vec3d x(0.2 + 0.012 * i, 0.5 + 0.2 * std::sin(i), 0.5 + 0.2 * std::cos(3 * i));
    EXPECT_EQ(written(x), read(x)) << "at sample " << i;
  }
  openvdb::io::File file(withPoints);
  file.open();
  auto points = openvdb::gridPtrCast<openvdb::points::PointDataGrid>(file.readGrid("particles"));
  for (const char* name : {"surface", "vel", "particles"}) {  // every grid carries the frame's metadata
    const openvdb::GridBase::Ptr g = file.readGridMetadata(name);
    EXPECT_EQ(g->metaValue<double>("time"), 1.5) << name;
    EXPECT_EQ(g->metaValue<std::int32_t>("frame"), 3) << name;
    EXPECT_EQ(g->metaValue<double>("dx"), dx) << name;
    EXPECT_EQ(g->metaValue<std::string>("scene"), "ball") << name;
    EXPECT_EQ(g->metaValue<std::string>("up_axis"), "y") << name;
    EXPECT_FALSE(g->metaValue<std::string>("stokesvdb_version").empty()) << name;
  }
  file.close();
  ASSERT_TRUE(points);
  EXPECT_EQ(openvdb::points::pointCount(points->tree()), particles.size());
  const auto leaf = points->tree().cbeginLeaf();
  ASSERT_TRUE(leaf);
  EXPECT_TRUE(leaf->hasAttribute("v"));
  std::vector<int> seen(particles.size(), 0);
  double worstX = 0.0, worstV = 0.0;
  for (auto l = points->tree().cbeginLeaf(); l; ++l) {
    ASSERT_TRUE(l->hasAttribute("P") && l->hasAttribute("v"));
    const openvdb::points::AttributeHandle<openvdb::Vec3f> P(l->constAttributeArray("P"));
    const openvdb::points::AttributeHandle<openvdb::Vec3f> V(l->constAttributeArray("v"));
    for (auto idx = l->beginIndexOn(); idx; ++idx) {
      const openvdb::Vec3f v = V.get(*idx);
      const long p = std::lround(v.x());
      ASSERT_TRUE(p >= 0 && std::size_t(p) < particles.size() && double(v.x()) == double(p)) << "index " << v.x();
      ++seen[std::size_t(p)];
      const Vec3d x = points->transform().indexToWorld(idx.getCoord().asVec3d() + Vec3d(P.get(*idx)));
      worstX = std::max(worstX, (x - particles[std::size_t(p)]).length());
      for (int a = 1; a < 3; ++a) worstV = std::max(worstV, std::abs(double(v[a]) - velocities[std::size_t(p)][a]));
    }
  }
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), std::ptrdiff_t(particles.size()));
  std::printf("[ measured ] %zu points read back: position error %.2e dx, velocity error %.2e m/s\n",
              particles.size(), worstX / dx, worstV);
  EXPECT_LT(worstX, 1e-6 * dx);
  EXPECT_LT(worstV, 1e-6);

  // No particles at all still gives a (empty) points grid.
  const std::vector<Vec3d> none;
  const std::string emptyPoints = (dir / "d.vdb").string();
  writeFrameVdb(emptyPoints, FrameGrids{liquid, &none, &none, true});
  EXPECT_EQ(readVdbGridNames(emptyPoints), (std::vector<std::string>{"particles", "surface", "vel"}));

  try {
    writeFrameVdb((dir / "no_such_dir" / "c.vdb").string(), FrameGrids{liquid});
    FAIL() << "expected std::runtime_error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_dir"), std::string::npos) << e.what();
  }
  EXPECT_THROW(readLiquidGrid((dir / "missing.vdb").string()), std::runtime_error);
  std::filesystem::remove_all(dir);
}

/// Reads a PNG back with stb_image; returns width, height and RGB pixels.
struct Image {
  int width = 0, height = 0;
  std::vector<unsigned char> rgb;
  std::array<int, 3> at(int i, int j) const {
    const unsigned char* p = &rgb[(static_cast<std::size_t>(j) * width + i) * 3];
    return {p[0], p[1], p[2]};
  }
};
Image readPng(const std::string& path) {
  Image im;
  int channels = 0;
  unsigned char* data = stbi_load(path.c_str(), &im.width, &im.height, &channels, 3);
  if (data) {
    im.rgb.assign(data, data + static_cast<std::size_t>(im.width) * im.height * 3);
    stbi_image_free(data);
  }
  return im;
}

TEST(Output, PreviewPngShowsTheBallAndCompositesSolidsByDepth) {
  const auto dir = scratchDir("png");
  const double dx = 1.0 / 32.0;
  auto ball = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.3f, openvdb::Vec3f(0.5f), float(dx));
  PreviewCamera cam = frameWorldBBox(openvdb::BBoxd(Vec3d(0.2), Vec3d(0.8)), 64.0 / 48.0, Vec3d(0, 0, 1));
  const std::string path = (dir / "ball.png").string();
  renderPreviewPng(path, *ball, nullptr, cam, 64, 48);
  const Image im = readPng(path);
  ASSERT_EQ(im.width, 64);
  ASSERT_EQ(im.height, 48);
  const auto corner = im.at(0, 0), centre = im.at(32, 24);
  EXPECT_NE(corner, centre);
  EXPECT_GT(centre[0], centre[2] + 40);  // honey: red well above blue

  // A grey solid slab between the camera and the ball covers the centre.
  ShapeField slab({box(Vec3d(0.3, 0.3, 0.9), Vec3d(0.7, 0.7, 1.0))}, {}, dx);
  auto solid = slab.toLevelSet(openvdb::BBoxd(Vec3d(0), Vec3d(1.2)));
  const std::string both = (dir / "both.png").string();
  renderPreviewPng(both, *ball, solid.get(), cam, 64, 48);
  const auto grey = readPng(both).at(32, 24);
  EXPECT_NEAR(grey[0], grey[2], 2);
  EXPECT_GT(grey[0], corner[0] + 40);

  // An empty liquid gives a uniform background image.
  auto empty = openvdb::createLevelSet<openvdb::FloatGrid>(dx);
  const std::string blank = (dir / "blank.png").string();
  renderPreviewPng(blank, *empty, nullptr, cam, 16, 8);
  const Image b = readPng(blank);
  ASSERT_EQ(b.width, 16);
  ASSERT_EQ(b.height, 8);
  for (int j = 0; j < 8; ++j)
    for (int i = 0; i < 16; ++i) EXPECT_EQ(b.at(i, j), corner);
  std::filesystem::remove_all(dir);
}

// With the domain box given, an empty scene shows its floor (checkered, below the box's centre
// in the image) and its outline; the sky above the box stays background.
TEST(Output, PreviewShowsTheDomainFloorAndOutline) {
  const auto dir = scratchDir("floor");
  const openvdb::BBoxd box(Vec3d(0.0), Vec3d(1.0, 0.6, 1.0));
  const PreviewCamera cam = frameWorldBBox(box, 96.0 / 64.0);
  auto empty = openvdb::createLevelSet<openvdb::FloatGrid>(0.05);
  const std::string path = (dir / "floor.png").string();
  renderPreviewPng(path, *empty, nullptr, cam, 96, 64, PreviewStyle{}, &box);
  const Image im = readPng(path);
  const auto background = im.at(0, 0);
  int floor = 0, other = 0;
  std::set<std::array<int, 3>> floorShades;
  for (int j = 0; j < 64; ++j)
    for (int i = 0; i < 96; ++i) {
      if (im.at(i, j) == background) continue;
      ++other;
      if (j > 32) {
        ++floor;
        floorShades.insert(im.at(i, j));
      }
    }
  EXPECT_GT(floor, 96 * 64 / 8);         // the floor fills much of the lower half
  EXPECT_GE(floorShades.size(), 3u);     // two checks and the outline
  EXPECT_GT(other - floor, 20);          // the outline's upper edges
  EXPECT_EQ(im.at(48, 0), background);   // above the box
  std::filesystem::remove_all(dir);
}

TEST(Output, StatsCsvWritesRowsImmediately) {
  const auto dir = scratchDir("csv");
  const std::string path = (dir / "stats.csv").string();
  auto slurp = [&path] {
    std::ifstream in(path);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  };
  StatsCsv csv(path, {"step", "time", "volume"});
  EXPECT_EQ(slurp(), "step,time,volume\n");
  csv.row({{"step", 0}, {"time", 0.5}, {"volume", 1.0 / 3.0}});
  csv.row({{"volume", 2.0}, {"step", 1}});        // any order; time left empty
  csv.row(std::vector<double>{2, 1e-12, 123456789.25});
  EXPECT_EQ(slurp(), "step,time,volume\n0,0.5,0.333333333\n1,,2\n2,1e-12,123456789\n");
  EXPECT_EQ(csv.rowsWritten(), 3u);
  EXPECT_THROW(csv.row({{"pressure", 1.0}}), std::invalid_argument);
  EXPECT_THROW(csv.row(std::vector<double>{1.0}), std::invalid_argument);
  EXPECT_THROW(StatsCsv((dir / "nope" / "x.csv").string(), {"a"}), std::runtime_error);
  EXPECT_THROW(StatsCsv((dir / "dup.csv").string(), {"a", "a"}), std::invalid_argument);
  {
    StatsCsv quoted((dir / "q.csv").string(), {"a,b", "c\"d"});  // RFC 4180 quoting
  }
  std::ifstream q(dir / "q.csv");
  std::string header;
  std::getline(q, header);
  EXPECT_EQ(header, "\"a,b\",\"c\"\"d\"");
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace stokes::sim
