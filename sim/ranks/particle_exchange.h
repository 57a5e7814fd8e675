#pragma once
// The particles of a simulation split over the ranks by the blocks that hold them (docs/petsc.md,
// "Particles by block"): each rank keeps the particles whose cell lies in a block it owns
// (RankBlocks), sends the others to their owners after advection (migrateParticles), and lends
// copies of those near another rank's blocks to it for the stages that read neighbours: the
// level set, the layout's band and P2G (ghostParticles).
//
// One order for any rank count: after every migration a rank's particles are sorted by cell, then
// by the bits of their position and velocity (canonicalOrder). The particles of a cell are then
// listed in the same order whichever rank holds them and whatever the rank count, and every
// per-cell sum (P2G, the reseeder's thinning) adds them in that order.
#include <vector>

#include "sim/particles/particles.h"
#include "sim/ranks/rank_blocks.h"

namespace stokes::sim {
inline namespace ranks {

/// Cells past a rank's blocks whose particles its part of a step reads (the ghosts):
///  - positions within kGhostReachCells, for the level set: a voxel's raster value reads the
///    particles within the sphere radius and half band (1 + 3 cells), but the sign flood fill
///    (OpenVDB's, in the order of the 16^3 leaves of an internal node) carries a sign from the
///    previous leaf in that order, a block away. Measured against one rank's run (the same bits on
///    the owned blocks): 12 cells fail on the armadillos at res 96, 14 at res 192, 16 hold on
///    both and on the ball (where 10 held). The halo's weights come from their owners anyway
///    (GridStep), so a shorter reach costs the bits across rank counts, not the operator's symmetry;
///  - the whole state within kGhostStateReachCells: u* is read on the owned faces and those
///    one cell past them (the divergence and strain rows of the owned samples), and P2G reaches
///    2 cells, one more for margin.
inline constexpr int kGhostReachCells = 16;
inline constexpr int kGhostStateReachCells = 4;

/// The cell index of a world position, floor((x - origin) / dx), as the transfers compute it
/// (sim/particles/grid_velocity.h cellOfPosition).
struct CellIndex {
  double dx = 1.0;
  Vec3d origin{0.0};
  Coord operator()(const Vec3d& x) const;
};

/// Sorts the particles by cell (x, then y, then z), then by the bits of x_p, v_p and c_p.
void canonicalOrder(ParticleSet<3>& particles, const CellIndex& cellOf);

/// Sends every particle whose cell's block another rank owns to that rank, and takes those sent
/// here; the result is in canonical order. A particle whose cell is in no block stays (the band
/// holds every particle's cell, so that means a caller's mistake) -- returns how many did.
/// Collective. `sentBytes`, if given, receives what this rank sent.
std::size_t migrateParticles(ParticleSet<3>& particles, const RankBlocks& blocks, const CellIndex& cellOf,
                             std::size_t* sentBytes = nullptr);

/// The other ranks' particles near this rank's blocks (ghostParticles).
struct Ghosts {
  ParticleSet<3> state;            ///< the whole state, within stateReach cells (canonical order)
  std::vector<Vec3d> positions;    ///< the positions of those farther, within reach cells
};

/// Copies of this rank's particles for the other ranks: to rank r every particle whose cell lies
/// within `reach` cells (along each axis) of a block r owns, with its velocity and affine vectors
/// within `stateReach` cells, as a position beyond. Returns the copies the other ranks sent this
/// one. Collective. `sentBytes`, if given, receives what this rank sent.
Ghosts ghostParticles(const ParticleSet<3>& own, const RankBlocks& blocks, const CellIndex& cellOf, int reach,
                      int stateReach, std::size_t* sentBytes = nullptr);

}  // namespace ranks
}  // namespace stokes::sim
