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
  explicit ViscositySystem(const StaggeredProblem<Dim>& prob, const ReducedTiles<Dim>* tiles = nullptr)
      : prob_(&prob), layout_(prob.layout), tiles_(tiles), n_(prob.slots()) {
    prob.validate();
    stress_.assign(SC::kCount * n_, 0.0);
    if (tiles_) {
      faceField_.assign(Dim * n_, 0.0);
      faceForce_.assign(Dim * n_, 0.0);
    }
    buildStressWeights();
    classify();
    buildDiagonal();
    buildRightHandSide();
  }

  std::size_t size() const { return Dim * n_ + (tiles_ ? tiles_->totalDofs() : 0); }

  /// y = (rho/dt) W_m u + U ⊙ D^T (Q ⊙ D u)   (U: unknown-face mask), plus the tile rows.
  void apply(const double* u, double* y) const {
    if (tiles_) {
      applyReduced(u, y);
      return;
    }
    kernels::CellStressOutput out;
    out.tau = stress_.data();
    out.tauWeight = q_.data();
    kernels::cellsFromFaces<Dim>(*layout_, u, out);
    kernels::CellStressInput in;
    in.tau = stress_.data();
    kernels::facesFromCells<Dim>(*layout_, in, unknownMask_.data(), y);
    const std::ptrdiff_t m = std::ptrdiff_t(size());
#pragma omp parallel for schedule(static) if (sparse_grid::worthParallel(size()))
    for (std::ptrdiff_t i = 0; i < m; ++i) y[i] += mass_[i] * u[i];
  }

  const Vector& rhs() const { return rhs_; }
  const Vector& diagonal() const { return diag_; }
  const double* nullSpace() const { return nullptr; }
  std::size_t activeUnknowns() const {
    return std::count(state_.begin(), state_.end(), FaceState::Unknown) + (tiles_ ? tiles_->totalDofs() : 0);
  }
  const std::vector<FaceState>& faceStates() const { return state_; }

  /// Face velocities from the solution: x on unknown faces, solid velocity on Dirichlet faces,
  /// u* on inactive faces.
  void velocities(const double* x, double* u) const {
    const StaggeredProblem<Dim>& p = *prob_;
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(Dim * n_); ++i) {
      switch (state_[i]) {
        case FaceState::Unknown: u[i] = x[i]; break;
        case FaceState::Dirichlet: u[i] = p.solidVelocity(i); break;
        case FaceState::Reduced: break;
        case FaceState::Inactive: u[i] = p.uStar[i]; break;
      }
    }
    if (tiles_) tiles_->scatter(x + Dim * n_, u, /*couplingOnly=*/false);
  }

 private:
  void applyReduced(const double* x, double* y) const {
    const std::ptrdiff_t m = std::ptrdiff_t(Dim * n_);
    // u_full = u_C on Cartesian faces, J^T v_R on coupling faces
#pragma omp parallel for schedule(static) if (sparse_grid::worthParallel(Dim * n_))
    for (std::ptrdiff_t i = 0; i < m; ++i) faceField_[i] = unknownMask_[i] * x[i];
    tiles_->scatter(x + m, faceField_.data(), /*couplingOnly=*/true);
    // f = D^T Q D u_full
    kernels::CellStressOutput out;
    out.tau = stress_.data();
    out.tauWeight = q_.data();
    kernels::cellsFromFaces<Dim>(*layout_, faceField_.data(), out);
    kernels::CellStressInput in;
    in.tau = stress_.data();
    kernels::facesFromCells<Dim>(*layout_, in, nullptr, faceForce_.data());
#pragma omp parallel for schedule(static) if (sparse_grid::worthParallel(Dim * n_))
    for (std::ptrdiff_t i = 0; i < m; ++i) y[i] = unknownMask_[i] * faceForce_[i] + mass_[i] * x[i];
    tiles_->applyTileRows(faceForce_.data(), x + m, y + m);  // (M_R/dt + K_R) v + J f
  }

  // Q = c^-1 mu W_L^tau / max(W_F^tau, minMassWeight): the fluid weight of a sample a wall or
  // solid cuts scales the coupling across it (the ghost-fluid factor, StaggeredProblem::fluidStress),
  // and a sample inside a solid the liquid reaches is a 1/minMassWeight penalty, as in the
  // pressure-velocity form.
  void buildStressWeights() {
    q_.assign(SC::kCount * n_, 0.0);
    for (int c = 0; c < SC::kCount; ++c)
      for (std::size_t i = 0; i < n_; ++i)
        q_[c * n_ + i] = tiles_ && tiles_->isInsideStress(c, i)
                             ? 0.0  // folded into K_R
                             : prob_->mu / complianceFactor<Dim>(c) * prob_->liquidStress[c * n_ + i] /
                                   std::max(prob_->fluidStressWeight(c * n_ + i), prob_->minMassWeight);
  }

  void classify() {
    Vector indicator(SC::kCount * n_), touched(size());
    for (std::size_t i = 0; i < indicator.size(); ++i) indicator[i] = q_[i] > 0.0 ? 1.0 : 0.0;
    kernels::CellStressInput in;
    in.tau = indicator.data();
    kernels::facesFromCells<Dim, true>(*layout_, in, nullptr, touched.data());
    state_ = classifyFaces(*prob_, touched.data());
    if (tiles_)
      for (std::size_t i = 0; i < Dim * n_; ++i)
        if (tiles_->tileOfFace(i) >= 0) state_[i] = FaceState::Reduced;
    unknownMask_.assign(Dim * n_, 0.0);
    mass_.assign(Dim * n_, 0.0);
    const std::vector<double> massWeight = faceMassWeights(*prob_, state_);
    for (std::size_t i = 0; i < Dim * n_; ++i) {
      if (state_[i] != FaceState::Unknown) continue;
      unknownMask_[i] = 1.0;
      mass_[i] = prob_->rho / prob_->dt * massWeight[i];
    }
  }

  // diag_f = (rho/dt) W_m + U_f sum_{j in stencil(f)} Q_j / dx^2.
  void buildDiagonal() {
    const double invDx = 1.0 / layout_->dx();
    Vector maskOverDx(Dim * n_);
    for (std::size_t i = 0; i < Dim * n_; ++i) maskOverDx[i] = unknownMask_[i] * invDx;
    diag_.assign(size(), 0.0);
    kernels::CellStressInput in;
    in.tau = q_.data();
    kernels::facesFromCells<Dim, true>(*layout_, in, maskOverDx.data(), diag_.data());
    for (std::size_t i = 0; i < Dim * n_; ++i) diag_[i] += mass_[i];
    if (tiles_) tiles_->addViscosityTileDiagonal(q_.data(), diag_.data() + Dim * n_);
  }

  // b = (rho/dt) W_m u* - U ⊙ D^T Q D u_dir.
  void buildRightHandSide() {
    Vector dir(Dim * n_, 0.0), force(Dim * n_, 0.0);
    for (std::size_t i = 0; i < Dim * n_; ++i)
      if (state_[i] == FaceState::Dirichlet) dir[i] = prob_->solidVelocity(i);
    rhs_.assign(size(), 0.0);
    kernels::CellStressOutput out;
    out.tau = stress_.data();
    out.tauWeight = q_.data();
    kernels::cellsFromFaces<Dim>(*layout_, dir.data(), out);
    kernels::CellStressInput in;
    in.tau = stress_.data();
    kernels::facesFromCells<Dim>(*layout_, in, nullptr, force.data());
    for (std::size_t i = 0; i < Dim * n_; ++i) rhs_[i] = mass_[i] * prob_->uStar[i] - unknownMask_[i] * force[i];
    if (tiles_) tiles_->tileRightHandSide(force.data(), rhs_.data() + Dim * n_);
  }

  const StaggeredProblem<Dim>* prob_;
  const BlockLayout<Dim>* layout_;
  const ReducedTiles<Dim>* tiles_;
  std::size_t n_;
  std::vector<FaceState> state_;
  Vector q_, unknownMask_, mass_, diag_, rhs_;
  mutable Vector stress_, faceField_, faceForce_;
};

}  // namespace systems
}  // namespace stokes::solver
