#pragma once
// Decoupled variational viscosity (Batty & Bridson 2008; thesis 3.5, Eq. 3.20), SPD in the face
// velocities. Minimising
//   1/2 sum_f rho W_m (u - u*)^2 + dt sum_j mu W_L^tau (sum_a eps_aa^2 + 1/2 sum_{a<b} gamma_ab^2)
// over the unknown faces gives, after dividing by dt,
//   A u = (rho/dt) W_m u + D^T Q D u,   Q = c^-1 mu W_L^tau / max(W_F^tau, minMassWeight)
//   (c^-1 = 2 diagonal, 1 shear; the floor keeps a sliver of stress sample from a huge coupling),
//   b   = (rho/dt) W_m u* - D^T Q D u_dir,
// where W_m = max(W_L^u, minMassWeight) and u_dir holds the solid velocity on Dirichlet faces
// (W_F = 0) and zero elsewhere. Rows of faces that are not unknowns are zero.
//
// With reduced tiles (thesis Eq. 4.7) the unknowns are x = [u_C | v_R]: Cartesian faces, then the
// tiles' generalised velocities. Stress samples inside a tile leave Q (they are K_R), and
//   y_C = (rho/dt) W_m u_C + U ⊙ D^T Q D (u_C + J^T v_R)
//   y_R = (M_R/dt + K_R) v_R + J D^T Q D (u_C + J^T v_R),     b_R = M_R v* / dt - J D^T Q D u_dir.
#include <algorithm>
#include <stdexcept>
#include <vector>

#include "kernels/staggered_stencils.h"
#include "solver/reduced/reduced_tiles.h"
#include "solver/problem/staggered_problem.h"
#include "solver/krylov/vector_ops.h"

namespace stokes::solver {
inline namespace systems {

template <int Dim>
class ViscositySystem {
 public:
  using SC = StressChannels<Dim>;

  /// `tiles` (optional) couples reduced tiles in; it must outlive the system.
  explicit ViscositySystem(const StaggeredProblem<Dim>& prob, const ReducedTiles<Dim>* tiles = nullptr);

  std::size_t size() const { return Dim * n_ + (tiles_ ? tiles_->totalDofs() : 0); }

  /// y = (rho/dt) W_m u + U ⊙ D^T (Q ⊙ D u)   (U: unknown-face mask), plus the tile rows.
  void apply(const double* u, double* y) const;

  const Vector& rhs() const { return rhs_; }
  const Vector& diagonal() const { return diag_; }
  const double* nullSpace() const { return nullptr; }
  std::size_t activeUnknowns() const;
  const std::vector<FaceState>& faceStates() const { return state_; }

  /// Face velocities from the solution: x on unknown faces, solid velocity on Dirichlet faces,
  /// u* on inactive faces.
  void velocities(const double* x, double* u) const;

 private:
  void applyReduced(const double* x, double* y) const;

  // Q = c^-1 mu W_L^tau / max(W_F^tau, minMassWeight): the fluid weight of a sample a wall or
  // solid cuts scales the coupling across it (the ghost-fluid factor, StaggeredProblem::fluidStress),
  // and a sample inside a solid the liquid reaches is a 1/minMassWeight penalty, as in the
  // pressure-velocity form.
  void buildStressWeights();

  void classify();

  // diag_f = (rho/dt) W_m + U_f sum_{j in stencil(f)} Q_j / dx^2.
  void buildDiagonal();

  // b = (rho/dt) W_m u* - U ⊙ D^T Q D u_dir.
  void buildRightHandSide();

  const StaggeredProblem<Dim>* prob_;
  const BlockLayout<Dim>* layout_;
  const ReducedTiles<Dim>* tiles_;
  std::size_t n_;
  std::vector<FaceState> state_;
  Vector q_, unknownMask_, mass_, diag_, rhs_;
  mutable Vector stress_, faceField_, faceForce_;
};

// Compiled once, in viscosity_system.cpp.
extern template class ViscositySystem<2>;
extern template class ViscositySystem<3>;

}  // namespace systems
}  // namespace stokes::solver
