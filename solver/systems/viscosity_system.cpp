// The members of ViscositySystem (viscosity_system.h), compiled once for Dim = 2 and 3 into the stokes_systems
// library.
#include "solver/systems/viscosity_system.h"

namespace stokes::solver {
inline namespace systems {

template <int Dim>
ViscositySystem<Dim>::ViscositySystem(const StaggeredProblem<Dim>& prob, const ReducedTiles<Dim>* tiles)
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

template <int Dim>
void ViscositySystem<Dim>::apply(const double* u, double* y) const {
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
#pragma omp parallel for schedule(static) if (parallel::forkGridLoop(size()))
  for (std::ptrdiff_t i = 0; i < m; ++i) y[i] += mass_[i] * u[i];
}

template <int Dim>
std::size_t ViscositySystem<Dim>::activeUnknowns() const {
  return std::count(state_.begin(), state_.end(), FaceState::Unknown) + (tiles_ ? tiles_->totalDofs() : 0);
}

template <int Dim>
void ViscositySystem<Dim>::velocities(const double* x, double* u) const {
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

template <int Dim>
void ViscositySystem<Dim>::applyReduced(const double* x, double* y) const {
  const std::ptrdiff_t m = std::ptrdiff_t(Dim * n_);
  // u_full = u_C on Cartesian faces, J^T v_R on coupling faces
#pragma omp parallel for schedule(static) if (parallel::forkGridLoop(Dim * n_))
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
#pragma omp parallel for schedule(static) if (parallel::forkGridLoop(Dim * n_))
  for (std::ptrdiff_t i = 0; i < m; ++i) y[i] = unknownMask_[i] * faceForce_[i] + mass_[i] * x[i];
  tiles_->applyTileRows(faceForce_.data(), x + m, y + m);  // (M_R/dt + K_R) v + J f
}

template <int Dim>
void ViscositySystem<Dim>::buildStressWeights() {
  q_.assign(SC::kCount * n_, 0.0);
  for (int c = 0; c < SC::kCount; ++c)
    for (std::size_t i = 0; i < n_; ++i)
      q_[c * n_ + i] = tiles_ && tiles_->isInsideStress(c, i)
                           ? 0.0  // folded into K_R
                           : prob_->mu / complianceFactor<Dim>(c) * prob_->liquidStress[c * n_ + i] /
                                 std::max(prob_->fluidStressWeight(c * n_ + i), prob_->minMassWeight);
}

template <int Dim>
void ViscositySystem<Dim>::classify() {
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

template <int Dim>
void ViscositySystem<Dim>::buildDiagonal() {
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

template <int Dim>
void ViscositySystem<Dim>::buildRightHandSide() {
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

template class ViscositySystem<2>;
template class ViscositySystem<3>;

}  // namespace systems
}  // namespace stokes::solver
