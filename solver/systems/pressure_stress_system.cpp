// The members of PressureStressSystem (pressure_stress_system.h), compiled once for Dim = 2 and 3 into the stokes_systems
// library.
#include "solver/systems/pressure_stress_system.h"

namespace stokes::solver {
inline namespace systems {

template <int Dim>
PressureStressSystem<Dim>::PressureStressSystem(const StaggeredProblem<Dim>& prob, bool withStress, const ReducedTiles<Dim>* tiles)
    : prob_(&prob), layout_(prob.layout), tiles_(tiles), withStress_(withStress), n_(prob.slots()) {
  prob.validate();
  if (withStress && !(prob.mu > 0.0))
    throw std::invalid_argument("PressureStressSystem: unified Stokes needs mu > 0 (use the pressure projection)");
  faces_.assign(Dim * n_, 0.0);
  buildEffectiveWeights();
  classify();
  buildScalings();
  buildDiagonal();
  buildRightHandSide();
  detectNullSpace();
  // b_p += Wp s where the liquid can change its volume (elsewhere the system is inconsistent)
  solver::addDivergenceTarget(*prob_, state_, pWeight_.data(), withStress_ ? tauWeight_.data() : nullptr,
                              !nullSpace_.empty(), +1.0, diag_.data(), rhs_.data());
  buildBlockLists();
}

template <int Dim>
void PressureStressSystem<Dim>::apply(const double* x, double* y) const {
  kernels::facesFromCells<Dim>(*layout_, input(x), faceScale_.data(), faces_.data());
  if (tiles_) tiles_->coupleFaces(faces_.data());  // S on tile faces: J^T B^-1 J
  kernels::cellsFromFaces<Dim>(*layout_, faces_.data(), output(y, x));
}

template <int Dim>
void PressureStressSystem<Dim>::applyOnRows(const double* x, double* y) const {
  kernels::facesFromCells<Dim>(*layout_, input(x), faceScale_.data(), faces_.data(), &faceBlocks_);
  if (tiles_) tiles_->coupleFaces(faces_.data());
  kernels::cellsFromFaces<Dim>(*layout_, faces_.data(), output(y, x), &rowBlocks_);
}

template <int Dim>
void PressureStressSystem<Dim>::applyOnBlocks(const double* x, double* y, const kernels::BlockList& faceBlocks,
    const kernels::BlockList& rowBlocks, const std::vector<std::int32_t>& tiles) const {
  kernels::facesFromCells<Dim>(*layout_, input(x), faceScale_.data(), faces_.data(), &faceBlocks);
  if (tiles_) tiles_->coupleFaces(faces_.data(), tiles);
  kernels::cellsFromFaces<Dim>(*layout_, faces_.data(), output(y, x), &rowBlocks);
}

template <int Dim>
void PressureStressSystem<Dim>::velocities(const double* x, double* u) const {
  if (tiles_) {
    // v = B^-1 (M_R v* / dt - J K x), then u = C(x) v on every tile face
    kernels::facesFromCells<Dim>(*layout_, input(x), reducedMask_.data(), faces_.data());
    reducedVelocity_.assign(tiles_->totalDofs(), 0.0);
    tiles_->solveVelocities(faces_.data(), reducedVelocity_.data());
    tiles_->scatter(reducedVelocity_.data(), u, /*couplingOnly=*/false);
  }
  kernels::facesFromCells<Dim>(*layout_, input(x), velocityScale_.data(), faces_.data());
  const StaggeredProblem<Dim>& p = *prob_;
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(Dim * n_); ++i) {
    switch (state_[i]) {
      case FaceState::Unknown: u[i] = p.uStar[i] - faces_[i]; break;
      case FaceState::Dirichlet: u[i] = p.solidVelocity(i); break;
      case FaceState::Reduced: break;  // written from the tiles above
      case FaceState::Inactive: u[i] = p.uStar[i]; break;
    }
  }
}

template <int Dim>
kernels::CellStressInput PressureStressSystem<Dim>::input(const double* x) const {
  kernels::CellStressInput in;
  in.p = x;
  in.pWeight = pWeight_.data();
  if (withStress_) {
    in.tau = x + n_;
    in.tauWeight = tauWeight_.data();
  }
  return in;
}

template <int Dim>
kernels::CellStressOutput PressureStressSystem<Dim>::output(double* y, const double* x) const {
  kernels::CellStressOutput out;
  out.p = y;
  out.pWeight = pWeight_.data();
  if (withStress_) {
    out.tau = y + n_;
    out.tauWeight = tauWeight_.data();
    out.tauDiag = compliance_.data();
    out.tauX = x + n_;
  }
  return out;
}

template <int Dim>
void PressureStressSystem<Dim>::buildEffectiveWeights() {
  pWeight_.assign(prob_->liquidCell.begin(), prob_->liquidCell.end());
  if (withStress_) tauWeight_.assign(prob_->liquidStress.begin(), prob_->liquidStress.end());
  if (!tiles_) return;
  for (std::size_t s = 0; s < n_; ++s) {
    if (tiles_->isReducedCell(s)) pWeight_[s] = 0.0;
    if (withStress_)
      for (int c = 0; c < SC::kCount; ++c)
        if (tiles_->isInsideStress(c, s)) tauWeight_[c * n_ + s] = 0.0;
  }
}

template <int Dim>
void PressureStressSystem<Dim>::classify() {
  Vector indicator(size(), 0.0);
  for (std::size_t i = 0; i < n_; ++i) indicator[i] = pWeight_[i] > 0.0 ? 1.0 : 0.0;
  if (withStress_)
    for (std::size_t i = 0; i < SC::kCount * n_; ++i) indicator[n_ + i] = tauWeight_[i] > 0.0 ? 1.0 : 0.0;
  kernels::CellStressInput in;
  in.p = indicator.data();
  if (withStress_) in.tau = indicator.data() + n_;
  kernels::facesFromCells<Dim, true>(*layout_, in, nullptr, faces_.data());
  state_ = classifyFaces(*prob_, faces_.data());
  if (tiles_)
    for (std::size_t i = 0; i < Dim * n_; ++i)
      if (tiles_->tileOfFace(i) >= 0) state_[i] = FaceState::Reduced;
}

template <int Dim>
void PressureStressSystem<Dim>::buildScalings() {
  const StaggeredProblem<Dim>& p = *prob_;
  faceScale_.assign(Dim * n_, 0.0);
  velocityScale_.assign(Dim * n_, 0.0);
  reducedMask_.assign(Dim * n_, 0.0);
  const std::vector<double> massWeight = faceMassWeights(p, state_);
  for (std::size_t i = 0; i < Dim * n_; ++i) {
    if (state_[i] == FaceState::Reduced) {
      faceScale_[i] = 1.0;  // raw K x: the tiles apply J^T B^-1 J to it
      reducedMask_[i] = 1.0;
    }
    if (state_[i] != FaceState::Unknown) continue;
    velocityScale_[i] = p.dt / (p.rho * massWeight[i]);
    faceScale_[i] = p.fluidFaceWeight(i) * velocityScale_[i];
  }
  if (withStress_) {
    compliance_.assign(SC::kCount * n_, 0.0);
    for (int c = 0; c < SC::kCount; ++c)
      for (std::size_t i = 0; i < n_; ++i) {
        const std::size_t k = c * n_ + i;
        compliance_[k] = complianceFactor<Dim>(c) / p.mu * p.constitutiveFluidWeight(k) * tauWeight_[k];
      }
  }
}

template <int Dim>
void PressureStressSystem<Dim>::buildDiagonal() {
  const double invDx = 1.0 / layout_->dx();
  Vector scaled(Dim * n_), wp2(n_), wt2;
  for (std::size_t i = 0; i < Dim * n_; ++i) scaled[i] = state_[i] == FaceState::Unknown ? faceScale_[i] * invDx : 0.0;
  for (std::size_t i = 0; i < n_; ++i) wp2[i] = pWeight_[i] * pWeight_[i];
  diag_.assign(size(), 0.0);
  kernels::CellStressOutput out;
  out.p = diag_.data();
  out.pWeight = wp2.data();
  if (withStress_) {
    wt2.resize(SC::kCount * n_);
    for (std::size_t i = 0; i < wt2.size(); ++i) wt2[i] = tauWeight_[i] * tauWeight_[i];
    out.tau = diag_.data() + n_;
    out.tauWeight = wt2.data();
    out.tauDiag = compliance_.data();
    Vector ones(SC::kCount * n_, 1.0);
    out.tauX = ones.data();
    kernels::cellsFromFaces<Dim, true>(*layout_, scaled.data(), out);
  } else {
    kernels::cellsFromFaces<Dim, true>(*layout_, scaled.data(), out);
  }
  if (tiles_) tiles_->addCouplingDiagonal(pWeight_.data(), withStress_ ? tauWeight_.data() : nullptr, diag_.data());
  activeRows_ = 0;
  for (double d : diag_) activeRows_ += d > 0.0 ? 1 : 0;
}

template <int Dim>
void PressureStressSystem<Dim>::buildRightHandSide() {
  const StaggeredProblem<Dim>& p = *prob_;
  for (std::size_t i = 0; i < Dim * n_; ++i) {
    const double wf = p.fluidFaceWeight(i);
    faces_[i] = state_[i] == FaceState::Reduced ? 0.0 : wf * p.uStar[i] + (1.0 - wf) * p.solidVelocity(i);
  }
  if (tiles_) {  // tile faces: J^T B^-1 M_R v* / dt
    Vector vFree(tiles_->totalDofs());
    for (std::size_t t = 0; t < tiles_->numTiles(); ++t)
      for (int k = 0; k < tiles_->dofsPerTile(); ++k) vFree[t * tiles_->dofsPerTile() + k] = tiles_->tile(t).vFree[k];
    tiles_->scatter(vFree.data(), faces_.data(), /*couplingOnly=*/true);
  }
  rhs_.assign(size(), 0.0);
  kernels::CellStressOutput out;
  out.p = rhs_.data();
  out.pWeight = pWeight_.data();
  if (withStress_) {
    out.tau = rhs_.data() + n_;
    out.tauWeight = tauWeight_.data();
  }
  kernels::cellsFromFaces<Dim>(*layout_, faces_.data(), out);
  for (std::size_t i = 0; i < size(); ++i)
    if (!(diag_[i] > 0.0)) rhs_[i] = 0.0;
}

template <int Dim>
void PressureStressSystem<Dim>::buildBlockLists() {
  constexpr std::size_t S = BlockLayout<Dim>::kSlots;
  const std::size_t nb = layout_->numBlocks();
  const std::size_t channels = withStress_ ? 1 + SC::kCount : 1;
  for (std::size_t b = 0; b < nb; ++b) {
    bool row = false, face = false;
    for (std::size_t c = 0; c < channels && !row; ++c)
      for (std::size_t s = c * n_ + b * S; s < c * n_ + (b + 1) * S && !row; ++s) row = diag_[s] > 0.0;
    for (int a = 0; a < Dim && !face; ++a)
      for (std::size_t s = a * n_ + b * S; s < a * n_ + (b + 1) * S && !face; ++s) face = faceScale_[s] != 0.0;
    if (row) rowBlocks_.push_back(std::int32_t(b));
    if (face) faceBlocks_.push_back(std::int32_t(b));
  }
  std::fill(faces_.begin(), faces_.end(), 0.0);
}

template <int Dim>
void PressureStressSystem<Dim>::detectNullSpace() {
  Vector ones(size(), 0.0), y(size(), 0.0);
  double count = 0.0;
  for (std::size_t i = 0; i < n_; ++i)
    if (diag_[i] > 0.0) { ones[i] = 1.0; count += 1.0; }
  if (count == 0.0) return;
  apply(ones.data(), y.data());
  const double maxDiag = *std::max_element(diag_.begin(), diag_.begin() + n_);
  if (norm2(y.data(), y.size()) <= 1e-10 * maxDiag * std::sqrt(count)) {
    nullSpace_ = ones;
    scale(1.0 / std::sqrt(count), nullSpace_.data(), nullSpace_.size());
  }
}

template class PressureStressSystem<2>;
template class PressureStressSystem<3>;

}  // namespace systems
}  // namespace stokes::solver
