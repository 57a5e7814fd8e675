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
  PressureStressSystem(const StaggeredProblem<Dim>& prob, bool withStress, const ReducedTiles<Dim>* tiles = nullptr)
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

  std::size_t size() const { return n_ * (withStress_ ? 1 + SC::kCount : 1); }
  bool withStress() const { return withStress_; }

  /// y = A x = K^T S K x + C x.
  void apply(const double* x, double* y) const {
    kernels::facesFromCells<Dim>(*layout_, input(x), faceScale_.data(), faces_.data());
    if (tiles_) tiles_->coupleFaces(faces_.data());  // S on tile faces: J^T B^-1 J
    kernels::cellsFromFaces<Dim>(*layout_, faces_.data(), output(y, x));
  }

  /// y = A x on the active rows (positive diagonal) only, the rest of y unspecified: K x is
  /// formed on the blocks holding an unknown or tile face, K^T on the blocks holding an active
  /// row. For the compact-row solve (solver/krylov/compact_rows.h); x must be zero off the
  /// active rows.
  void applyOnRows(const double* x, double* y) const {
    kernels::facesFromCells<Dim>(*layout_, input(x), faceScale_.data(), faces_.data(), &faceBlocks_);
    if (tiles_) tiles_->coupleFaces(faces_.data());
    kernels::cellsFromFaces<Dim>(*layout_, faces_.data(), output(y, x), &rowBlocks_);
  }
  /// y = A x on the rows of `rowBlocks` only (the rest of y untouched), for a rank of a
  /// distributed solve (solver/petsc/pressure_stress_ranks.h): K x is formed on `faceBlocks`, which
  /// must hold every face those rows read, and J^T B^-1 J on the listed `tiles` only, which must be
  /// every tile with a coupling face among them. x need only be right on the samples those faces
  /// read (the rank's rows and its ghosts); it must be finite everywhere.
  void applyOnBlocks(const double* x, double* y, const kernels::BlockList& faceBlocks,
                     const kernels::BlockList& rowBlocks, const std::vector<std::int32_t>& tiles) const {
    kernels::facesFromCells<Dim>(*layout_, input(x), faceScale_.data(), faces_.data(), &faceBlocks);
    if (tiles_) tiles_->coupleFaces(faces_.data(), tiles);
    kernels::cellsFromFaces<Dim>(*layout_, faces_.data(), output(y, x), &rowBlocks);
  }
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
  void velocities(const double* x, double* u) const {
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

  /// Generalised velocities of the tiles from the last velocities() call (tile-major).
  const Vector& reducedVelocities() const { return reducedVelocity_; }
  const ReducedTiles<Dim>* tiles() const { return tiles_; }

 private:
  kernels::CellStressInput input(const double* x) const {
    kernels::CellStressInput in;
    in.p = x;
    in.pWeight = pWeight_.data();
    if (withStress_) {
      in.tau = x + n_;
      in.tauWeight = tauWeight_.data();
    }
    return in;
  }
  kernels::CellStressOutput output(double* y, const double* x) const {
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

  // Wp = W_L^p and Wt = W_L^tau, zeroed where a tile replaces the unknown (reduced cells, stress
  // samples inside a tile).
  void buildEffectiveWeights() {
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

  // Unknown faces: W_F > 0 and (liquid, or touched by a positive-weight p / tau stencil); tile
  // faces are Reduced.
  void classify() {
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

  // S = dt W_F / (rho W_m) and dt / (rho W_m) on unknown faces (W_m: faceMassWeights), 0 elsewhere.
  void buildScalings() {
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

  // diag(A)_j = w_j^2 / dx^2 sum_{faces f in stencil(j)} S_f  (+ C_j).
  void buildDiagonal() {
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

  // b = K^T g, g = W_F u* + (1 - W_F) u_solid; zero on inactive rows.
  void buildRightHandSide() {
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



  // The blocks applyOnRows visits. faces_ must be zero on every other block, which holds from
  // here on: apply() and velocities() scale K x by factors that are zero off those blocks.
  void buildBlockLists() {
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

  // Constant pressure on the active cells is a null vector iff A 1_p = 0 (no free surface).
  void detectNullSpace() {
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

}  // namespace systems
}  // namespace stokes::solver
