#pragma once
// The symmetric positive (semi-)definite pressure-stress form of unified variational Stokes
// (thesis Eq. 3.58 with u eliminated; Eq. 4.20-4.25 without reduced terms; docs/design.md §3), and --
// with the stress block switched off -- the variational pressure projection (thesis 3.5, Eq. 3.22).
//
// Unknowns x = [p | tau] (tau: StressChannels<Dim>::kCount channels). With K = [G Wp, D^T Wt]
// (Wp = W_L^p, Wt = W_L^tau) and the face scaling S = dt W_F (rho W_L^u)^-1 on unknown faces:
//
//   A = K^T S K + C,   C = diag(c mu^-1 W_F^tau Wt)   (c = 1/2 diagonal, 1 shear; 0 without stress;
//                                                     W_F^tau below minMassWeight counts as 0:
//                                                     StaggeredProblem::constitutiveFluidWeight)
//     i.e. A11 = dt Wp G^T W_F (W_L^u)^-1 M^-1 G Wp
//          A12 = dt Wp G^T W_F (W_L^u)^-1 M^-1 D^T Wt
//          A22 = dt Wt D W_F (W_L^u)^-1 M^-1 D^T Wt + c mu^-1 W_F^tau Wt
//   b = K^T g,  g = W_F u* + (1 - W_F) u_solid,   b_p += Wp s  with a divergence target s
//
// (at the solution K^T u_bar = b - (A - C) x, so the pressure rows read Wp G^T u_bar = -Wp s,
// i.e. div u_bar = s on the liquid cells; G^T = -div, kernels/staggered_stencils.h)
// and afterwards, on unknown faces, u = u* - dt (rho W_L^u)^-1 K x.
//
// With reduced tiles (thesis Eq. 4.20-4.25) pressure lives only on Cartesian cells and stress only
// on samples not folded into a tile (their weights are zeroed), S is replaced on the tiles' faces
// by J^T B^-1 J, and g there by J^T B^-1 M_R v* / dt:
//   A = K^T S_C K + K^T J^T B^-1 J K + C,   b = K^T g_C + K^T J^T B^-1 M_R v* / dt.
// Rows whose diagonal is zero (no liquid, or every face solid) are inactive: their right-hand side
// is zeroed and they stay zero. Without a free surface (a closed container) constant pressure is a
// null space; it is detected by applying A to it and handed to the Krylov solver.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "kernels/staggered_stencils.h"
#include "solver/reduced/reduced_tiles.h"
#include "solver/problem/divergence_target.h"
#include "solver/problem/staggered_problem.h"
#include "solver/krylov/vector_ops.h"

namespace stokes::solver {
inline namespace systems {

template <int Dim>
class PressureStressSystem {
 public:
  using SC = StressChannels<Dim>;
  static constexpr int kDim = Dim;

  /// withStress = true: unified Stokes (needs mu > 0). false: plain pressure projection.
  /// `tiles` (optional) couples reduced tiles in; it must outlive the system.
  PressureStressSystem(const StaggeredProblem<Dim>& prob, bool withStress, const ReducedTiles<Dim>* tiles = nullptr);

  std::size_t size() const { return n_ * (withStress_ ? 1 + SC::kCount : 1); }
  bool withStress() const { return withStress_; }

  /// y = A x = K^T S K x + C x.
  void apply(const double* x, double* y) const;

  /// y = A x on the active rows (positive diagonal) only, the rest of y unspecified: K x is
  /// formed on the blocks holding an unknown or tile face, K^T on the blocks holding an active
  /// row. For the compact-row solve (solver/krylov/compact_rows.h); x must be zero off the
  /// active rows.
  void applyOnRows(const double* x, double* y) const;
  /// y = A x on the rows of `rowBlocks` only (the rest of y untouched), for a rank of a
  /// distributed solve (solver/petsc/pressure_stress_ranks.h): K x is formed on `faceBlocks`, which
  /// must hold every face those rows read, and J^T B^-1 J on the listed `tiles` only, which must be
  /// every tile with a coupling face among them. x need only be right on the samples those faces
  /// read (the rank's rows and its ghosts); it must be finite everywhere.
  void applyOnBlocks(const double* x, double* y, const kernels::BlockList& faceBlocks,
                     const kernels::BlockList& rowBlocks, const std::vector<std::int32_t>& tiles) const;
  /// Blocks holding an active row / an unknown or tile face (for benchmarks and tests).
  std::size_t rowBlocks() const { return rowBlocks_.size(); }
  std::size_t faceBlocks() const { return faceBlocks_.size(); }

  const Vector& rhs() const { return rhs_; }
  const Vector& diagonal() const { return diag_; }
  /// Unit null-space vector (constant pressure) for closed containers, else nullptr.
  const double* nullSpace() const { return nullSpace_.empty() ? nullptr : nullSpace_.data(); }
  /// Number of rows with a non-zero diagonal (the real unknowns).
  std::size_t activeUnknowns() const { return activeRows_; }
  const std::vector<FaceState>& faceStates() const { return state_; }
  std::size_t unknownFaces() const { return std::count(state_.begin(), state_.end(), FaceState::Unknown); }

  /// What the compact-row operator (pressure_stress_rows.h) needs: the layout, the effective
  /// sample weights (Wp, Wt), the face scaling S (1 on tile faces, 0 where K x is not needed) and
  /// the compliance diagonal C (stress channels).
  const BlockLayout<Dim>& layout() const { return *layout_; }
  const Vector& pressureWeights() const { return pWeight_; }
  const Vector& stressWeights() const { return tauWeight_; }
  const Vector& faceScale() const { return faceScale_; }
  const Vector& compliance() const { return compliance_; }

  /// Face velocities from a solution x: u = u* - dt (rho W_L^u)^-1 K x on unknown faces, the
  /// solid velocity on Dirichlet faces, u* on inactive faces. `u` has Dim * numSlots entries.
  void velocities(const double* x, double* u) const;

  /// Generalised velocities of the tiles from the last velocities() call (tile-major).
  const Vector& reducedVelocities() const { return reducedVelocity_; }
  const ReducedTiles<Dim>* tiles() const { return tiles_; }

 private:
  kernels::CellStressInput input(const double* x) const;
  kernels::CellStressOutput output(double* y, const double* x) const;

  // Wp = W_L^p and Wt = W_L^tau, zeroed where a tile replaces the unknown (reduced cells, stress
  // samples inside a tile).
  void buildEffectiveWeights();

  // Unknown faces: W_F > 0 and (liquid, or touched by a positive-weight p / tau stencil); tile
  // faces are Reduced.
  void classify();

  // S = dt W_F / (rho W_m) and dt / (rho W_m) on unknown faces (W_m: faceMassWeights), 0 elsewhere.
  void buildScalings();

  // diag(A)_j = w_j^2 / dx^2 sum_{faces f in stencil(j)} S_f  (+ C_j).
  void buildDiagonal();

  // b = K^T g, g = W_F u* + (1 - W_F) u_solid; zero on inactive rows.
  void buildRightHandSide();



  // The blocks applyOnRows visits. faces_ must be zero on every other block, which holds from
  // here on: apply() and velocities() scale K x by factors that are zero off those blocks.
  void buildBlockLists();

  // Constant pressure on the active cells is a null vector iff A 1_p = 0 (no free surface).
  void detectNullSpace();

  const StaggeredProblem<Dim>* prob_;
  const BlockLayout<Dim>* layout_;
  const ReducedTiles<Dim>* tiles_;
  bool withStress_;
  std::size_t n_;
  std::vector<FaceState> state_;
  Vector pWeight_, tauWeight_;  // effective sample weights
  Vector faceScale_, velocityScale_, reducedMask_, compliance_, diag_, rhs_, nullSpace_;
  mutable Vector reducedVelocity_;
  std::size_t activeRows_ = 0;
  kernels::BlockList rowBlocks_, faceBlocks_;
  mutable Vector faces_;
};

// Compiled once, in pressure_stress_system.cpp.
extern template class PressureStressSystem<2>;
extern template class PressureStressSystem<3>;

}  // namespace systems
}  // namespace stokes::solver
