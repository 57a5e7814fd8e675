#pragma once
// Reduced tiles inside the velocity multigrid. The finest level of the velocity
// block is [Cartesian faces | tile DOFs] (PressureVelocitySystem::applyVelocityBlock); level 1 and
// below are the re-discretised uniform problems, on which the tiles' cells are ordinary liquid.
// Between level 0 and level 1:
//
//   P = [ Mask_C P_g ]      e_C = P_g e_c on the Cartesian faces,
//       [ E P_g      ]      v_t = E_t (P_g e_c) = M^_t^-1 sum_{faces j of t} C_j^T (P_g e_c)_j,
//   R = P^T / 2^Dim  =  P_g^T (Mask_C r_C + E^T r_v) / 2^Dim,
//
// with P_g the staggered face prolongation (sparse_grid/grid_transfer.h) onto the Cartesian and the
// tile faces alike, and E the least-squares fit of a face field over all of a tile's faces in the
// face mass norm (ReducedTiles::fitFaceField). The coarse correction is thus the uniform correction
// projected onto the tiles' polynomial fields, the same Galerkin relation that ties the reduced
// operator to the uniform one. R stays a multiple of P^T, so the V-cycle stays symmetric positive
// definite, as MINRES needs.
#include <cstdint>
#include <memory>
#include <vector>

#include "solver/krylov/vector_ops.h"
#include "solver/multigrid/multigrid.h"
#include "solver/multigrid/multigrid_hierarchy.h"
#include "solver/reduced/reduced_tiles.h"

namespace stokes::solver {
inline namespace multigrid {

template <int Dim>
class TileFaceTransfer {
 public:
  /// `fine`, `coarse`: the diagonals of level 0 ([faces | tile DOFs]) and level 1 (faces).
  TileFaceTransfer(const ProblemHierarchy<Dim>& h, const ReducedTiles<Dim>& tiles, const Vector& fine, const Vector& coarse)
      : tiles_(&tiles), nFaces_(Dim * h.problem(0).slots()),
        grid_(h.layout(0), h.layout(1), faceChannels<Dim>(), airVelocitySamples(h.problem(1), Multigrid::activeRows(coarse)),
              prolongedFaces(tiles, fine, Dim * h.problem(0).slots()), Multigrid::activeRows(coarse)),
        faces_(nFaces_, 0.0) {}

  /// f = P c: P_g on the faces (the tile faces' values are left there; the cycle masks them),
  /// then the fit E into the tile rows.
  void prolong(const double* c, double* f) const {
    grid_.prolong(c, f, false);
    tiles_->fitFaceField(f, f + nFaces_);
  }

  /// c = R f = P_g^T (f_C + E^T f_v) / 2^Dim; f is zero on the inactive face rows (the tile faces).
  void restrictTo(const double* f, double* c) const {
    copy(f, faces_.data(), nFaces_);
    tiles_->addFitTranspose(f + nFaces_, faces_.data());
    grid_.restrictTo(faces_.data(), c);
  }

 private:
  // The face rows P_g must fill: the active Cartesian faces and every tile face.
  static std::vector<std::uint8_t> prolongedFaces(const ReducedTiles<Dim>& tiles, const Vector& fine, std::size_t nFaces) {
    std::vector<std::uint8_t> rows(nFaces);
    for (std::size_t i = 0; i < nFaces; ++i) rows[i] = Multigrid::isActive(fine[i]) || tiles.tileOfFace(i) >= 0 ? 1 : 0;
    return rows;
  }

  const ReducedTiles<Dim>* tiles_;
  std::size_t nFaces_;
  sparse_grid::GridTransfer<Dim> grid_;
  mutable Vector faces_;  // work array (the cycle is not re-entrant)
};

/// Points level 0 of `levels` ([faces | tile DOFs]) at level 1 through a TileFaceTransfer.
template <int Dim>
void attachTileFaceTransfer(std::vector<MultigridLevel>& levels, const ProblemHierarchy<Dim>& h, const ReducedTiles<Dim>& tiles) {
  auto transfer = std::make_shared<TileFaceTransfer<Dim>>(h, tiles, levels[0].diagonal, levels[1].diagonal);
  levels[0].restrictToCoarse = [transfer](const double* f, double* c) { transfer->restrictTo(f, c); };
  levels[0].prolongToFine = [transfer](const double* c, double* f) { transfer->prolong(c, f); };
}

}  // namespace multigrid
}  // namespace stokes::solver
