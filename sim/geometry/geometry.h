#pragma once
// Geometry for the 3D simulator: signed distances of scene shapes (solids, initial liquid), the
// liquid level set rebuilt from particles, and volume measures on level sets.
//
// Conventions (shared with sparse_grid/block_layout.h):
//  - phi < 0 inside a region, phi > 0 outside, |phi| ~ distance to its boundary (world units);
//  - the solver's cell (i,j,k) has its centre at world dx * ((i,j,k) + 0.5): every grid built here
//    uses cellCentredTransform(dx), so voxel (i,j,k) of a grid is cell (i,j,k) of the solver;
//  - every phi-like callable here is const and safe to call from many OpenMP threads at once
//    (the volume-fraction code, sparse_grid/volume_weights.h, does so).
#include "sparse_grid/vdb_trees.h"

#include <cstddef>
#include <cstdint>
#include <algorithm>
#include <functional>
#include <vector>

#include "sim/scene/shapes.h"
#include "sim/geometry/triangle_mesh.h"

namespace stokes::sim {
inline namespace geometry {

/// Linear transform with voxel size dx and voxel (i,j,k) centred at dx * ((i,j,k) + 0.5).
openvdb::math::Transform::Ptr cellCentredTransform(double dx);

/// p_world = translation + Rz * Ry * Rx * (scale * p): rotation about x first, then y, then z
/// (extrinsic, degrees), as documented on Placement in sim/scene/shapes.h.
Vec3d applyPlacement(const Placement& placement, const Vec3d& p);

/// Exact signed distance to the axis-aligned box [lo, hi] (negative inside).
double boxSignedDistance(const Vec3d& x, const Vec3d& lo, const Vec3d& hi);

/// Signed distance to the SOLID region outside the domain box [lo, hi]: positive inside the box
/// (distance to the nearest wall), negative outside it (minus the distance to the box). It is
/// -boxSignedDistance(x, lo, hi), exact everywhere.
double domainWallPhi(const Vec3d& x, const Vec3d& lo, const Vec3d& hi);

/// Bandwidths of the level sets built for mesh shapes.
struct MeshLevelSetOptions {
  /// Exterior narrow band in cells; beyond it phi reads +exteriorBandCells * dx.
  double exteriorBandCells = 3.0;
  /// Interior band in cells. The default (a huge value) fills the whole interior with true
  /// distances (cost ~ the interior voxel count); with a finite value the deep interior reads
  /// -exteriorBandCells * dx (the sign is right everywhere: the grid is sign-flood filled).
  double interiorBandCells = 1e30;
};

/// The union of a list of shapes, as one signed distance phi(x) = min over shapes of phi_s(x).
///
/// - Box, sphere: exact signed distance.
/// - Plane: the half-space on the -normal side, phi = (x - point) . n / |n| (exact).
/// - Mesh: the placed mesh (applyPlacement on every vertex) is converted with
///   openvdb::tools::meshToSignedDistanceField into a grid with voxel size dx
///   (cellCentredTransform) and sampled trilinearly. Exact to O(dx) inside the bands of
///   MeshLevelSetOptions; clamped to +band outside. The mesh must be closed for its sign
///   to be right (the sign comes from a flood fill, not from the triangle winding).
///
/// Thread safety: phi() and gradient() are const and only read immutable data; mesh grids are
/// sampled through an un-registered accessor created per call, so any number of threads may
/// call them concurrently.
class ShapeField {
 public:
  ShapeField() = default;

  /// `meshesForMeshShapes` gives the mesh of each Kind::Mesh shape: either one entry per mesh
  /// shape, in the order they appear in `shapes`, or one entry per shape (parallel to `shapes`,
  /// entries of non-mesh shapes ignored, may be null). Throws std::invalid_argument naming the
  /// shape index for a missing/empty mesh, a degenerate plane normal, a negative radius, an
  /// inverted box, or a non-positive dx.
  ShapeField(const std::vector<ShapeDesc>& shapes,
             const std::vector<const TriangleMesh*>& meshesForMeshShapes, double dx,
             const MeshLevelSetOptions& meshOptions = {});

  /// Signed distance to the union (negative inside). With no shapes: +max double.
  double phi(const Vec3d& x) const;
  double operator()(const Vec3d& x) const { return phi(x); }

  /// Signed distance to shape `index` alone.
  double shapePhi(std::size_t index, const Vec3d& x) const;

  /// grad phi by central differences with step h = dx / 2 (not normalised; |grad| ~ 1 near the
  /// surface, 0 where phi is clamped).
  Vec3d gradient(const Vec3d& x) const;

  /// Solids move rigidly at their constant `velocity` (sim/scene/shapes.h): at time t shape i is its
  /// scene placement translated by velocity_i t. phi, shapePhi, gradient, velocityAt, worldBBox
  /// and toLevelSet read the shapes at the time set here (0 until set). Not thread-safe against
  /// concurrent queries: set it between parallel sections.
  void setTime(double t) { time_ = t; }
  double time() const { return time_; }
  /// Translation of shape i at the current time: velocity_i t.
  Vec3d displacement(std::size_t i) const { return shapes_[i].velocity * time_; }
  /// True when some shape has a non-zero velocity.
  bool moving() const;
  /// Velocity of the solid at x: that of the shape with the smallest phi there (the one containing
  /// x, or the nearest), as every shape moves rigidly without rotation.
  Vec3d velocityAt(const Vec3d& x) const;

  bool empty() const { return shapes_.empty(); }
  std::size_t size() const { return shapes_.size(); }
  double dx() const { return dx_; }
  const std::vector<ShapeDesc>& shapes() const { return shapes_; }

  /// The level set of mesh shape `index` (null for analytic shapes).
  openvdb::FloatGrid::ConstPtr meshGrid(std::size_t index) const;

  /// World bounding box of the union, intersected with `domain`. Planes are infinite: their part
  /// is the bounding box of (half-space intersected with domain), computed exactly. Empty
  /// (BBoxd with min > max) when nothing lies inside the domain.
  openvdb::BBoxd worldBBox(const openvdb::BBoxd& domain) const;

  /// Cells (index space of cellCentredTransform(dx)) whose extent [i dx, (i+1) dx] overlaps
  /// worldBBox(domain); an empty CoordBBox when that box is empty.
  openvdb::CoordBBox indexBBox(const openvdb::BBoxd& domain) const;

  /// A narrow-band level set of the union sampled at cell centres inside indexBBox(domain)
  /// (grown by the band): |phi| < band active, deeper cells inactive -background (explicitly,
  /// not by flood fill, so half-spaces clipped by the box come out right), pruned to tiles,
  /// class LEVEL_SET. Serial; for previews and solid output, not for per-step use.
  openvdb::FloatGrid::Ptr toLevelSet(const openvdb::BBoxd& domain,
                                     double halfWidthInCells = 3.0) const;

 private:
  std::vector<ShapeDesc> shapes_;
  std::vector<Vec3d> unitNormals_;                          // planes: normalised normal
  std::vector<openvdb::FloatGrid::ConstPtr> meshGrids_;     // meshes: level set, else null
  std::vector<openvdb::BBoxd> meshBBoxes_;                  // meshes: placed vertices' bbox
  double dx_ = 1.0;
  double time_ = 0.0;
};

/// Samples a level-set grid trilinearly at world positions (openvdb::tools::BoxSampler). Far from
/// the band it returns the tree's value there: +background outside, -background in sign-flooded
/// interior regions. An empty (or null) grid reads +background (or +max double for null)
/// everywhere. Thread-safe and lock-free: each thread keeps one un-registered accessor for the
/// GridPhi (and its copies) it read last, so successive samples in the same leaf skip the walk
/// from the root (the volume weights' 10-27 samples per control volume: 2-3x faster than an
/// accessor per call), and reads the eight corners straight from the leaf's buffer while they lie
/// in the leaf it read last. Same bits as BoxSampler. The grid must not change while a GridPhi
/// reads it.
class GridPhi {
 public:
  GridPhi() = default;
  explicit GridPhi(openvdb::FloatGrid::ConstPtr grid);
  double operator()(const Vec3d& worldPos) const;
  double phi(const Vec3d& worldPos) const { return (*this)(worldPos); }
  const openvdb::FloatGrid::ConstPtr& grid() const { return grid_; }

 private:
  openvdb::FloatGrid::ConstPtr grid_;
  std::uint64_t id_ = 0;  ///< unique per constructed grid reader; copies share it (same tree)
};

/// Mesh -> narrow-band level set in the cellCentredTransform(dx) frame, after applying the
/// placement to the points. Throws std::invalid_argument for an empty mesh or dx <= 0.
openvdb::FloatGrid::Ptr meshLevelSet(const TriangleMesh& mesh, const Placement& placement,
                                     double dx, const MeshLevelSetOptions& options = {});

/// How the liquid surface is built from particles.
struct ParticleSurfaceOptions {
  /// Spacing of the particles as seeded, in cells (0.5 = 2x2x2 per cell). After the union of
  /// spheres is built, the surface is eroded to lie half a spacing beyond the outermost particle
  /// centres -- where the volume the particles carry ends -- so a resting block of liquid keeps
  /// its seeded volume. <= 0 disables the erosion (the raw union of spheres is returned).
  double particleSpacingInCells = 0.5;
  /// A further erosion, in cells, for the seeding's jitter: the union of spheres is a maximum
  /// over the particles, so particles jittered in their sub-cells push a flat face out beyond
  /// where their volume ends (by 0.04-0.05 dx for 2-4 particles per axis).
  /// Measured once per seeding density (sim::seededFaceBulge). Applied with the
  /// erosion above (only when particleSpacingInCells > 0).
  double faceBulgeInCells = 0.0;
  /// Passes of mean-curvature flow (BandFilter::meanCurvature, OpenVDB's LevelSetFilter bits)
  /// applied before the erosion (smooths the bumps between spheres; 0 disables).
  int smoothingPasses = 1;
  /// The deep interior left out of the raster (rasterizeSphereUnion's deepMargin, voxels): voxels
  /// whose cells within this many voxels along each axis all hold particles start as the inside
  /// tile (-background), so the raster and the filters above work on the band around the surface
  /// only. 3, the band's half width: such voxels lie 3.5 voxels or more inside the union of
  /// spheres, below the band, where the whole union's filtered values are -2 to -3 voxels
  /// (three renormalisation sweeps per filter pass do not make them a distance). < 0 rasterises
  /// the whole union (OpenVDB's raster bit for bit).
  int deepInteriorMargin = 3;
};

/// The liquid level set from particle positions (world units), voxel size dx, cell-centred
/// (cellCentredTransform), class LEVEL_SET, name "liquid".
///
/// Steps: (1) rasterizeSphereUnion (sim/geometry/sphere_raster.h: openvdb::tools::ParticlesToLevelSet's
/// raster, bit for bit, built leaf by leaf) rasterises the union of spheres of radius
/// r = radiusInCells * dx (default 1 cell: it must exceed sqrt(3)/2 of the particle spacing,
/// 0.43 dx for 2x2x2 seeding, or the union has holes at voxel centres; one cell leaves margin for
/// jittered particles), the deep interior (options.deepInteriorMargin) left as the inside tile;
/// (2) sign flood fill (interior -background); (3) `smoothingPasses` passes
/// of mean-curvature flow; (4) erosion by r - spacing/2 + faceBulgeInCells dx in steps of dx/2,
/// each renormalised; (3) and (4) are openvdb::tools::LevelSetFilter's meanCurvature() and offset(),
/// bit for bit, run by BandFilter (sim/geometry/band_filter.h) on padded leaf copies. (4) undoes
/// the bias of the union of spheres: an isolated particle shrinks to a sphere of radius spacing/2
/// and may vanish at the grid's resolution -- its mass stays with the particle.
/// The narrow band is halfWidthInCells cells on each side; radiusInCells + halfWidthInCells must
/// stay below 7. No particles: an empty level set.
openvdb::FloatGrid::Ptr liquidLevelSetFromParticles(const std::vector<Vec3d>& positions, double dx,
                                                    double radiusInCells = 1.0,
                                                    double halfWidthInCells = 3.0,
                                                    const ParticleSurfaceOptions& options = {});

/// Volume of {phi < 0}: sum over all voxels (and tiles) of the smoothed Heaviside
/// clamp(1/2 - phi/dx, 0, 1) times dx^3. Exact for a plane through cells, O(dx^2) for smooth
/// surfaces, robust for empty grids and open (clipped) surfaces, deterministic.
double levelSetVolume(const openvdb::FloatGrid& grid);

/// Volume of {phi < 0} inside the region {clip < 0} (`clip(Vec3d) -> double`, a signed distance):
/// levelSetVolume with each voxel's value replaced by max(phi, clip(voxel centre)). The simulator
/// clips the liquid with the domain box and the solids, as the volume weights do: the particle
/// surface of liquid resting on a wall or solid reaches a fraction of a cell into it (particles are
/// kept 0.01 dx inside the walls and 0.1 dx out of solids, the surface lies half a particle
/// spacing beyond them), which is not liquid. Interior tiles are visited voxel by voxel. Serial.
double levelSetVolumeClipped(const openvdb::FloatGrid& grid, const std::function<double(const Vec3d&)>& clip);

/// What matchClippedVolume did: the offset c subtracted from phi (c > 0 dilates), and the clipped
/// volume after it (the target, unless |c| reached its bound).
struct VolumeMatch {
  double offset = 0.0;
  double volume = 0.0;
  double raw = 0.0;  ///< the clipped volume before the move (c = 0)
  bool bounded = false;  ///< |c| hit maxOffset: the volume is as close as the bound allows
};

/// Moves the surface of a level set along its normal by the one distance c (phi -> phi - c on the
/// active voxels, clamped to +-background) that makes levelSetVolumeClipped equal `target`, with
/// |c| <= maxOffset (world units, < background - dx/2). The clipped volume is a monotone,
/// piecewise-linear function of c (each voxel's fraction clamp(1/2 - max(phi - c, clip)/dx, 0, 1));
/// c is found by bisection to 1e-9 dx over the voxels whose fraction can change. Serial.
/// The simulator's use: a union of spheres is a maximum over the particles, so any disorder of the
/// particles raises its volume (Gaussian noise of 0.1 dx: +1%), which the fixed erosion by
/// r - spacing/2 cannot undo; c restores the volume the particles carry.
VolumeMatch matchClippedVolume(openvdb::FloatGrid& grid, double target,
                               const std::function<double(const Vec3d&)>& clip, double maxOffset);

/// The clipped volume of a level set as a function of the offset c, |c| <= maxOffset
/// (matchClippedVolume's split): voxels whose fraction cannot change are summed once ('full'
/// whole voxels and the clipped 'partial' fractions), the others keep (phi, clip).
struct ClippedVolumeTerms {
  double dx = 1.0, voxelVolume = 1.0, maxOffset = 0.0;
  std::size_t full = 0;                               ///< voxels inside for every c
  std::vector<double> partial;                        ///< fractions the clip fixes
  std::vector<std::pair<double, double>> variable;    ///< (phi, clip) of the voxels c moves

  double fraction(double phi, double clip, double c) const {
    return std::clamp(0.5 - std::max(phi - c, clip) / dx, 0.0, 1.0);
  }
  /// add(f) for the fraction f at offset c of every voxel but the `full` ones.
  template <class Add>
  void forEachFraction(double c, Add&& add) const {
    for (double f : partial) add(f);
    for (const auto& [phi, b] : variable) add(fraction(phi, b, c));
  }
};

/// The terms over the voxels `counts` accepts (every voxel when empty). Serial.
ClippedVolumeTerms clippedVolumeTerms(const openvdb::FloatGrid& grid, const std::function<double(const Vec3d&)>& clip,
                                      double maxOffset,
                                      const std::function<bool(const openvdb::Coord&)>& counts = {});

/// matchClippedVolume's search and move with the volume given as a function of c (monotone
/// non-decreasing): a caller that sums the volume its own way (over MPI ranks: sim/ranks/) finds
/// the same offset from the same sums.
VolumeMatch matchVolume(openvdb::FloatGrid& grid, double target, double maxOffset,
                        const std::function<double(double)>& volumeAt);

/// Volume of (A \ B) U (B \ A): the two grids are sampled (trilinear) at the centres of a lattice
/// with spacing h = min(voxel sizes) covering the union of their interior bounding boxes, and the
/// samples where exactly one phi is negative are counted (times h^3). OpenMP-parallel, integer
/// counts (deterministic).
double symmetricVolumeDifference(const openvdb::FloatGrid& a, const openvdb::FloatGrid& b);

/// World bounding box of the region {phi < 0} a grid can hold: its leaf nodes plus its negative
/// tiles. Empty (min > max) for an empty grid.
openvdb::BBoxd interiorWorldBBox(const openvdb::FloatGrid& grid);

}  // namespace geometry
}  // namespace stokes::sim
