// The members of PressureVelocitySystem (pressure_velocity_system.h), compiled once for Dim = 2 and 3 into the stokes_systems
// library.
#include "solver/systems/pressure_velocity_system.h"

namespace stokes::solver {
inline namespace systems {

template <int Dim>
PressureVelocitySystem<Dim>::PressureVelocitySystem(const StaggeredProblem<Dim>& prob, const ReducedTiles<Dim>* tiles)
    : prob_(&prob), layout_(prob.layout), tiles_(tiles), n_(prob.slots()),
        nTile_(tiles ? tiles->totalDofs() : 0) {
  prob.validate();
  if (!(prob.mu > 0.0)) throw std::invalid_argument("PressureVelocitySystem: needs mu > 0");
  faceField_.assign(Dim * n_, 0.0);
  faceForce_.assign(Dim * n_, 0.0);
  stress_.assign(SC::kCount * n_, 0.0);
  buildWeights();
  classify();
  buildDiagonal();
  buildRightHandSide();
  buildBlockLists();
  detectNullSpace();
  // pressure rows: rhs -= Wp s on the cells ventedCells marks (rigid samples as the
  // pressure-stress form counts them), the pressure-stress form's cells
  addDivergenceTarget(*prob_, state_, pWeight_.data(), tauWeight_.data(), !nullSpace_.empty(), -1.0,
                      diag_.data() + pressureOffset(), rhs_.data() + pressureOffset());
}

template <int Dim>
void PressureVelocitySystem<Dim>::apply(const double* x, double* y) const {
  const double* u = x;
  const double* v = x + Dim * n_;
  const double* p = x + pressureOffset();
  // w = W_F u_C on Cartesian faces, J^T v on coupling faces
  loadFaceField(u);
  if (tiles_) tiles_->scatter(v, faceField_.data(), /*couplingOnly=*/true);
  // y_p = Wp G^T w, stress = Q D w
  stressFromFaces(y + pressureOffset());
  // rigid rows y_r = Wt D w; the multipliers' force D^T (Wt l_r) joins the stress
  addRigidRows(x + rigidOffset(), y + rigidOffset());
  // f = D^T stress + G (Wp p) (on the blocks holding an unknown or tile face)
  forceOnFaces(p, u, y);
  if (tiles_) tiles_->applyTileRows(faceForce_.data(), v, y + Dim * n_);  // (M_R/dt + K_R) v + J f
}

template <int Dim>
void PressureVelocitySystem<Dim>::applyVelocityBlock(const double* x, double* y) const {
  loadFaceField(x);
  if (tiles_) tiles_->scatter(x + Dim * n_, faceField_.data(), /*couplingOnly=*/true);
  stressFromFaces(nullptr);
  forceOnFaces(nullptr, x, y);
  if (tiles_) tiles_->applyTileRows(faceForce_.data(), x + Dim * n_, y + Dim * n_);
}

template <int Dim>
std::size_t PressureVelocitySystem<Dim>::activeUnknowns() const {
  std::size_t k = 0;
  for (double d : diag_) k += d > 0.0 ? 1 : 0;
  return k;
}

template <int Dim>
void PressureVelocitySystem<Dim>::velocities(const double* x, double* u) const {
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(Dim * n_); ++i) {
    switch (state_[i]) {
      case FaceState::Unknown: u[i] = x[i]; break;
      case FaceState::Dirichlet: u[i] = prob_->solidVelocity(i); break;
      case FaceState::Reduced: break;
      case FaceState::Inactive: u[i] = prob_->uStar[i]; break;
    }
  }
  if (tiles_) tiles_->scatter(x + Dim * n_, u, /*couplingOnly=*/false);
}

template <int Dim>
void PressureVelocitySystem<Dim>::loadFaceField(const double* u) const {
  constexpr std::size_t S = BlockLayout<Dim>::kSlots;
  const kernels::BlockList& blocks = faceBlocks_;
  const std::ptrdiff_t nb = std::ptrdiff_t(blocks.size());
#pragma omp parallel for schedule(static) if (parallel::forkGridLoop(Dim * blocks.size() * S))
  for (std::ptrdiff_t k = 0; k < nb; ++k)
    for (int a = 0; a < Dim; ++a) {
      const std::size_t s0 = a * n_ + std::size_t(blocks[k]) * S;
      for (std::size_t s = s0; s < s0 + S; ++s) faceField_[s] = wfUnknown_[s] * u[s];
    }
}

template <int Dim>
void PressureVelocitySystem<Dim>::stressFromFaces(double* yp) const {
  kernels::CellStressOutput out;
  out.p = yp;
  out.pWeight = pWeight_.data();
  out.tau = stress_.data();
  out.tauWeight = q_.data();
  kernels::cellsFromFaces<Dim>(*layout_, faceField_.data(), out, &cellBlocks_);
  if (!yp) return;
  constexpr std::size_t S = BlockLayout<Dim>::kSlots;
  for (std::int32_t b : otherCellBlocks_) std::fill(yp + std::size_t(b) * S, yp + std::size_t(b + 1) * S, 0.0);
}

template <int Dim>
void PressureVelocitySystem<Dim>::addRigidRows(const double* l, double* yR) const {
  const std::ptrdiff_t m = std::ptrdiff_t(rigid_.size());
#pragma omp parallel for schedule(static) if (parallel::forkGridLoop(rigid_.size()))
  for (std::ptrdiff_t k = 0; k < m; ++k) {
    const std::size_t i = std::size_t(rigid_[k]);
    yR[k] = stress_[i] * rigidStrainScale_[k];
    stress_[i] += tauWeight_[i] * l[k];
  }
}

template <int Dim>
void PressureVelocitySystem<Dim>::forceOnFaces(const double* p, const double* u, double* yu) const {
  kernels::CellStressInput in;
  in.p = p;
  in.pWeight = pWeight_.data();
  in.tau = stress_.data();
  kernels::facesFromCells<Dim>(*layout_, in, nullptr, faceForce_.data(), &faceBlocks_);
  const std::ptrdiff_t m = std::ptrdiff_t(Dim * n_);
#pragma omp parallel for schedule(static) if (parallel::forkGridLoop(Dim * n_))
  for (std::ptrdiff_t i = 0; i < m; ++i) yu[i] = mass_[i] * u[i] + wfUnknown_[i] * faceForce_[i];
}

template <int Dim>
void PressureVelocitySystem<Dim>::buildBlockLists() {
  constexpr std::size_t S = BlockLayout<Dim>::kSlots;
  for (std::size_t b = 0; b < layout_->numBlocks(); ++b) {
    bool cell = false, face = false;
    for (std::size_t s = b * S; s < (b + 1) * S && !cell; ++s) {
      cell = pWeight_[s] > 0.0;
      for (int c = 0; c < SC::kCount && !cell; ++c) cell = q_[c * n_ + s] > 0.0;
    }
    for (int a = 0; a < Dim && !face; ++a)
      for (std::size_t s = a * n_ + b * S; s < a * n_ + (b + 1) * S && !face; ++s)
        face = state_[s] == FaceState::Unknown || state_[s] == FaceState::Reduced;
    (cell ? cellBlocks_ : otherCellBlocks_).push_back(std::int32_t(b));
    if (face) faceBlocks_.push_back(std::int32_t(b));
  }
  std::fill(faceField_.begin(), faceField_.end(), 0.0);
  std::fill(stress_.begin(), stress_.end(), 0.0);
}

template <int Dim>
void PressureVelocitySystem<Dim>::buildWeights() {
  const StaggeredProblem<Dim>& p = *prob_;
  pWeight_.assign(p.liquidCell.begin(), p.liquidCell.end());
  tauWeight_.assign(p.liquidStress.begin(), p.liquidStress.end());
  q_.assign(SC::kCount * n_, 0.0);
  for (std::size_t s = 0; s < n_; ++s) {
    if (tiles_ && tiles_->isReducedCell(s)) pWeight_[s] = 0.0;
    for (int c = 0; c < SC::kCount; ++c) {
      const std::size_t i = c * n_ + s;
      if (tiles_ && tiles_->isInsideStress(c, s)) tauWeight_[i] = 0.0;  // in K_R
      const double wf = rigidStressSample(p, tauWeight_[i], i) ? rigidPenaltyWeight() : p.constitutiveFluidWeight(i);
      q_[i] = tauWeight_[i] > 0.0 ? p.mu / complianceFactor<Dim>(c) * tauWeight_[i] / wf : 0.0;
    }
  }
}

template <int Dim>
void PressureVelocitySystem<Dim>::classify() {
  Vector indicator(n_ + SC::kCount * n_);
  for (std::size_t i = 0; i < n_; ++i) indicator[i] = pWeight_[i] > 0.0 ? 1.0 : 0.0;
  for (std::size_t i = 0; i < SC::kCount * n_; ++i) indicator[n_ + i] = q_[i] > 0.0 ? 1.0 : 0.0;
  kernels::CellStressInput in;
  in.p = indicator.data();
  in.tau = indicator.data() + n_;
  kernels::facesFromCells<Dim, true>(*layout_, in, nullptr, faceField_.data());
  state_ = classifyFaces(*prob_, faceField_.data());
  wfUnknown_.assign(Dim * n_, 0.0);
  mass_.assign(Dim * n_, 0.0);
  if (tiles_)
    for (std::size_t i = 0; i < Dim * n_; ++i)
      if (tiles_->tileOfFace(i) >= 0) state_[i] = FaceState::Reduced;
  const std::vector<double> massWeight = faceMassWeights(*prob_, state_);
  for (std::size_t i = 0; i < Dim * n_; ++i) {
    if (state_[i] != FaceState::Unknown) continue;
    wfUnknown_[i] = prob_->fluidFaceWeight(i);
    mass_[i] = prob_->rho / prob_->dt * wfUnknown_[i] * massWeight[i];
  }
}

template <int Dim>
void PressureVelocitySystem<Dim>::buildDiagonal() {
  const double invDx = 1.0 / layout_->dx();
  Vector velocity(Dim * n_, 0.0);
  Vector wf2(Dim * n_);
  for (std::size_t i = 0; i < Dim * n_; ++i) wf2[i] = wfUnknown_[i] * wfUnknown_[i] * invDx;
  kernels::CellStressInput in;
  in.tau = q_.data();
  kernels::facesFromCells<Dim, true>(*layout_, in, wf2.data(), velocity.data());
  for (std::size_t i = 0; i < Dim * n_; ++i) velocity[i] += mass_[i];
  Vector tileDiagonal;
  tileInverses_ = tiles_ ? tileBlocks(tileDiagonal) : std::vector<Matrix>{};
  const std::vector<Matrix>& tileInverses = tileInverses_;
  // the constraint rows' estimate on [p | tau], laid out as the pressure-stress form's rows
  Vector h(Dim * n_, 0.0), wp2(n_), rigidWeight(SC::kCount * n_, 0.0), wt2(SC::kCount * n_, 0.0);
  Vector schur(n_ + SC::kCount * n_, 0.0);
  for (std::size_t i = 0; i < Dim * n_; ++i)
    if (state_[i] == FaceState::Unknown && velocity[i] > 0.0) h[i] = wf2[i] / velocity[i];
  for (std::size_t s = 0; s < n_; ++s) wp2[s] = pWeight_[s] * pWeight_[s];
  for (std::size_t i = 0; i < SC::kCount * n_; ++i)
    if (rigidStressSample(*prob_, tauWeight_[i], i)) {
      rigidWeight[i] = tauWeight_[i];
      wt2[i] = tauWeight_[i] * tauWeight_[i];
    }
  kernels::CellStressOutput out;
  out.p = schur.data();
  out.pWeight = wp2.data();
  out.tau = schur.data() + n_;
  out.tauWeight = wt2.data();
  kernels::cellsFromFaces<Dim, true>(*layout_, h.data(), out);
  if (tiles_) tiles_->addCouplingDiagonal(pWeight_.data(), rigidWeight.data(), schur.data(), &tileInverses);
  // the rigid rows, in sample order; C' / Wt = c/mu f_r turns the penalty's Q D w into Wt D w
  rigid_.clear();
  for (std::size_t i = 0; i < SC::kCount * n_; ++i) {
    if (!(rigidWeight[i] > 0.0 && schur[n_ + i] > 0.0)) continue;
    rigid_.push_back(std::int64_t(i));
    rigidStrainScale_.push_back(complianceFactor<Dim>(int(i / n_)) / prob_->mu * rigidPenaltyWeight());
  }
  diag_.assign(size(), 0.0);
  std::copy(velocity.begin(), velocity.end(), diag_.begin());
  std::copy(tileDiagonal.begin(), tileDiagonal.end(), diag_.begin() + Dim * n_);
  std::copy(schur.begin(), schur.begin() + n_, diag_.begin() + pressureOffset());
  for (std::size_t k = 0; k < rigid_.size(); ++k)
    diag_[rigidOffset() + k] = schur[n_ + std::size_t(rigid_[k])];
}

template <int Dim>
void PressureVelocitySystem<Dim>::addFaceBlockToSchurDiagonal(const std::uint32_t* faces, std::size_t m, const double* inverse,
                                                              double* pressureDiagonal) const {
  // the cells next to the group's faces: face (a, s) is the low face of cell s (+) and the high
  // face of cell s - e_a (-)
  std::vector<std::size_t> cells;
  for (std::size_t q = 0; q < m; ++q) {
    const std::size_t slot = faces[q] % n_;
    cells.push_back(slot);
    const std::int64_t below = layout_->neighbourSlot(slot, int(faces[q] / n_), -1);
    if (below >= 0) cells.push_back(std::size_t(below));
  }
  std::sort(cells.begin(), cells.end());
  cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
  const double invDx = 1.0 / layout_->dx();
  std::vector<double> b(m);
  for (std::size_t p : cells) {
    if (!(pWeight_[p] > 0.0)) continue;
    for (std::size_t q = 0; q < m; ++q) {
      const std::size_t slot = faces[q] % n_;
      const double sign = slot == p ? 1.0 : layout_->neighbourSlot(slot, int(faces[q] / n_), -1) == std::int64_t(p) ? -1.0 : 0.0;
      b[q] = sign * pWeight_[p] * wfUnknown_[faces[q]] * invDx;
    }
    double exact = 0.0, estimate = 0.0;
    for (std::size_t q = 0; q < m; ++q) {
      if (b[q] == 0.0) continue;
      if (diag_[faces[q]] > 0.0) estimate += b[q] * b[q] / diag_[faces[q]];
      for (std::size_t r = 0; r < m; ++r) exact += b[q] * inverse[q * m + r] * b[r];
    }
    pressureDiagonal[p] += exact - estimate;
  }
}

template <int Dim>
auto PressureVelocitySystem<Dim>::tileBlocks(Vector& diagonal) const -> std::vector<Matrix> {
  const std::vector<Matrix> blocks = tiles_->viscosityTileBlocks(q_.data());
  const int m = tiles_->dofsPerTile();
  diagonal.assign(nTile_, 0.0);
  std::vector<Matrix> inverses(blocks.size());
  for (std::size_t t = 0; t < blocks.size(); ++t) {
    for (int k = 0; k < m; ++k) diagonal[t * m + k] = blocks[t](k, k);
    Eigen::LLT<Matrix> llt(blocks[t]);
    if (llt.info() != Eigen::Success)
      throw std::runtime_error("PressureVelocitySystem: the velocity block of tile " + std::to_string(t) +
                               " is not positive definite");
    inverses[t] = llt.solve(Matrix::Identity(m, m));
  }
  return inverses;
}

template <int Dim>
void PressureVelocitySystem<Dim>::buildRightHandSide() {
  const StaggeredProblem<Dim>& p = *prob_;
  Vector d(Dim * n_, 0.0), divD(n_);
  for (std::size_t i = 0; i < Dim * n_; ++i)
    if (state_[i] != FaceState::Reduced) d[i] = (1.0 - p.fluidFaceWeight(i)) * p.solidVelocity(i);
  kernels::CellStressOutput out;
  out.p = divD.data();
  out.pWeight = pWeight_.data();
  out.tau = stress_.data();
  out.tauWeight = q_.data();
  kernels::cellsFromFaces<Dim>(*layout_, d.data(), out);
  rhs_.assign(size(), 0.0);
  for (std::size_t k = 0; k < rigid_.size(); ++k) rhs_[rigidOffset() + k] = -stress_[rigid_[k]] * rigidStrainScale_[k];
  kernels::CellStressInput in;
  in.tau = stress_.data();
  kernels::facesFromCells<Dim>(*layout_, in, nullptr, faceForce_.data());
  for (std::size_t i = 0; i < Dim * n_; ++i) rhs_[i] = mass_[i] * p.uStar[i] - wfUnknown_[i] * faceForce_[i];
  if (tiles_) tiles_->tileRightHandSide(faceForce_.data(), rhs_.data() + Dim * n_);
  double* rp = rhs_.data() + pressureOffset();
  for (std::size_t s = 0; s < n_; ++s) rp[s] = diag_[pressureOffset() + s] > 0.0 ? -divD[s] : 0.0;
}

template <int Dim>
void PressureVelocitySystem<Dim>::detectNullSpace() {
  Vector ones(size(), 0.0), y(size());
  double count = 0.0;
  const std::size_t p0 = pressureOffset();
  for (std::size_t s = 0; s < n_; ++s)
    if (diag_[p0 + s] > 0.0) { ones[p0 + s] = 1.0; count += 1.0; }
  if (count == 0.0) return;
  apply(ones.data(), y.data());
  const double scale = *std::max_element(diag_.begin(), diag_.begin() + p0);
  if (norm2(y.data(), y.size()) <= 1e-10 * scale * std::sqrt(count) * layout_->dx()) {
    nullSpace_ = ones;
    solver::scale(1.0 / std::sqrt(count), nullSpace_.data(), nullSpace_.size());
  }
}

template class PressureVelocitySystem<2>;
template class PressureVelocitySystem<3>;

}  // namespace systems
}  // namespace stokes::solver
