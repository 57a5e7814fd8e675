#pragma once
// The pressure-velocity form of (reduced) unified variational Stokes, thesis Eq. 4.19: the stresses
// are eliminated where their compliance can be inverted; the rigid stress samples keep a
// multiplier. Unknowns x = [u_C | v_R | p | l_r]:
//
//   [ (rho/dt) W_F W_m + W_F V W_F   W_F V J^T     W_F G Wp   W_F D^T Wt ] [u_C]   [ (rho/dt) W_F W_m u* ]
//   [ J V W_F                        B + J V J^T   J G Wp     J D^T Wt   ] [v_R] = [ M_R v* / dt         ]
//   [ Wp G^T W_F                     Wp G^T J^T    0          0          ] [ p ]   [ -Wp s               ]
//   [ Wt D W_F                       Wt D J^T      0          0          ] [l_r]   [ 0                   ]
//
// (s: the divergence target, StaggeredProblem::divergenceTarget, 0 for incompressible liquid;
// G^T = -div, so the pressure rows read div u_bar = s), with solid velocities moved to the
// right-hand side, B = M_R/dt + K_R and V = D^T Q D; the last block row and column are restricted
// to the rigid samples.
//
// Exactness. The pressure-stress form (pressure_stress_system.h) has the stress rows
// Wt D u_bar = C tau with the compliance C = c/mu W_F^tau Wt (c = 1/2 diagonal, 1 shear;
// W_F^tau below minMassWeight counts as 0, StaggeredProblem::constitutiveFluidWeight). Where
// C > 0, tau = C^-1 Wt D u_bar is eliminated: its force D^T Wt tau is V u_bar with
// Q = Wt^2 / C = mu/c Wt / W_F^tau. A rigid sample (rigidStressSample: liquid with C = 0, e.g. the
// liquid's extension into a solid, thesis Fig. 3.4c) holds its strain rate at the solid's,
// Wt D u_bar = 0, which cannot be eliminated; its stress is split into a penalty and a multiplier,
// tau = C'^-1 Wt D u_bar + l with C' = c/mu f_r Wt (V carries the penalty, Q = mu/c Wt / f_r), and
// its row is the constraint Wt D u_bar = 0. The penalty vanishes at the solution, so u is the
// pressure-stress form's for every weight: both forms give one answer with solids, walls, tiles,
// inflow and a divergence target (tests/sim/test_forms.cpp). (A penalty with f_r = 1/27
// alone, without the multiplier, was 1.4-7.8% off in kinetic energy on a ball next to solids.)
//
// Conditioning: an augmented Lagrangian (Benzi & Olshanskii 2006, "An augmented Lagrangian-based
// approach to the Oseen problem"). The velocity block keeps a penalty, so the multigrid's velocity
// cycle sees a stiff layer instead of an unconstrained one, and the multipliers' Schur complement
// B_r (U0 + B_r^T C'^-1 B_r)^-1 B_r^T lies below C' and near it wherever the penalty dominates:
// its diagonal estimate preconditions it. Multipliers without the penalty took 5-12x the MINRES +
// multigrid iterations of the penalty alone on the ball on solids; with f_r = 1/100, 1.2-1.7x
// on the ball and the beam (rigidPenaltyWeight).
//
// The matrix is symmetric but indefinite (a saddle point), solved with MINRES (or BiCGSTAB, the
// thesis' choice). diagonal() is the positive block-diagonal used for preconditioning: the velocity
// diagonal, and for the constraint rows (pressure and rigid stress) the Schur-complement diagonal
// estimate sum_f B_jf^2 / diag_f, with the tiles' blocks A_tt exact.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "kernels/staggered_stencils.h"
#include "solver/reduced/reduced_tiles.h"
#include "solver/problem/divergence_target.h"
#include "solver/problem/staggered_problem.h"
#include "solver/krylov/vector_ops.h"

namespace stokes::solver {
inline namespace systems {

template <int Dim>
class PressureVelocitySystem {
 public:
  using SC = StressChannels<Dim>;
  using Matrix = typename ReducedTiles<Dim>::Matrix;

  PressureVelocitySystem(const StaggeredProblem<Dim>& prob, const ReducedTiles<Dim>* tiles = nullptr)
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

  std::size_t size() const { return Dim * n_ + nTile_ + n_ + rigid_.size(); }
  /// First pressure row (n_ pressure rows follow, then the rigid stress rows).
  std::size_t pressureOffset() const { return Dim * n_ + nTile_; }
  /// First rigid stress row; rigidSample(k) names the stress sample of row rigidOffset() + k.
  std::size_t rigidOffset() const { return pressureOffset() + n_; }
  std::size_t rigidRows() const { return rigid_.size(); }
  /// Channel-major stress sample index (channel * numSlots + slot) of rigid row k.
  std::size_t rigidSample(std::size_t k) const { return std::size_t(rigid_[k]); }

  void apply(const double* x, double* y) const {
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

  /// Rows of the velocity block [u_C | v_R]: the Cartesian faces and the tile DOFs.
  std::size_t velocityRows() const { return Dim * n_ + nTile_; }
  /// y = A_vv x on x = [u_C | v_R], A_vv the leading 2x2 block of the matrix above:
  ///   [ (rho/dt) W_F W_m + W_F V W_F    W_F V J^T   ]
  ///   [ J V W_F                         B + J V J^T ],
  /// the leading block of apply() with p = 0 and l_r = 0, bit for bit, without forming the
  /// constraint rows (the multigrid's velocity cycle applies this on every level).
  void applyVelocityBlock(const double* x, double* y) const {
    loadFaceField(x);
    if (tiles_) tiles_->scatter(x + Dim * n_, faceField_.data(), /*couplingOnly=*/true);
    stressFromFaces(nullptr);
    forceOnFaces(nullptr, x, y);
    if (tiles_) tiles_->applyTileRows(faceForce_.data(), x + Dim * n_, y + Dim * n_);
  }
  /// The tiles coupled into this system (null: the uniform model).
  const ReducedTiles<Dim>* tiles() const { return tiles_; }
  /// Rows of the Cartesian face block (the first velocityRows() - tile DOFs).
  std::size_t faceRows() const { return Dim * n_; }

  /// Blocks holding a pressure or stress sample / an unknown or tile face (benchmarks, tests).
  std::size_t cellBlocks() const { return cellBlocks_.size(); }
  std::size_t faceBlocks() const { return faceBlocks_.size(); }

  const Vector& rhs() const { return rhs_; }
  const Vector& diagonal() const { return diag_; }
  /// A_tt^-1 per tile, A_tt = B + (J V J^T)_tt the tile's diagonal block of the velocity block.
  const std::vector<Matrix>& tileBlockInverses() const { return tileInverses_; }
  const double* nullSpace() const { return nullSpace_.empty() ? nullptr : nullSpace_.data(); }
  std::size_t activeUnknowns() const {
    std::size_t k = 0;
    for (double d : diag_) k += d > 0.0 ? 1 : 0;
    return k;
  }
  const std::vector<FaceState>& faceStates() const { return state_; }
  /// What the velocity block is made of, for assembling it (solver/multigrid/velocity_block_matrix.h):
  /// Q per stress sample (channel-major, 0 where no Cartesian stress), W_F on the Cartesian unknown
  /// faces (0 elsewhere) and their mass (rho/dt) W_F W_m.
  const Vector& stressCoefficients() const { return q_; }
  const Vector& unknownFaceWeights() const { return wfUnknown_; }
  const Vector& faceMass() const { return mass_; }
  const sparse_grid::BlockLayout<Dim>& layout() const { return *layout_; }
  /// Wp per cell and Wt per stress sample (channel-major; 0 on reduced cells and inside tiles), and
  /// per rigid row C' / Wt (the rigid row reads Q D w times this): for the operator on live rows
  /// (pressure_velocity_rows.h).
  const Vector& pressureWeights() const { return pWeight_; }
  const Vector& stressWeights() const { return tauWeight_; }
  const Vector& rigidStrainScales() const { return rigidStrainScale_; }

  /// Face velocities: x on Cartesian unknown faces, C(x) v on tile faces, solid velocity on
  /// Dirichlet faces, u* on inactive faces.
  void velocities(const double* x, double* u) const {
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

 private:
  // faceField = W_F u on the faces of faceBlocks_ (zero elsewhere, which no apply changes).
  void loadFaceField(const double* u) const {
    constexpr std::size_t S = BlockLayout<Dim>::kSlots;
    const kernels::BlockList& blocks = faceBlocks_;
    const std::ptrdiff_t nb = std::ptrdiff_t(blocks.size());
#pragma omp parallel for schedule(static) if (sparse_grid::worthParallel(Dim * blocks.size() * S))
    for (std::ptrdiff_t k = 0; k < nb; ++k)
      for (int a = 0; a < Dim; ++a) {
        const std::size_t s0 = a * n_ + std::size_t(blocks[k]) * S;
        for (std::size_t s = s0; s < s0 + S; ++s) faceField_[s] = wfUnknown_[s] * u[s];
      }
  }

  // yp = Wp G^T faceField (if yp) and stress = Q D faceField over cellBlocks_; yp is zero on every
  // other block (no pressure sample there), stress_ stays zero there.
  void stressFromFaces(double* yp) const {
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

  // On a rigid sample stress_ holds the penalty's Q D w = (Wt / C') Wt D w: the row
  // y_r = Wt D w = stress_ C' / Wt, then stress_ += Wt l_r, the multiplier's force for forceOnFaces.
  void addRigidRows(const double* l, double* yR) const {
    const std::ptrdiff_t m = std::ptrdiff_t(rigid_.size());
#pragma omp parallel for schedule(static) if (sparse_grid::worthParallel(rigid_.size()))
    for (std::ptrdiff_t k = 0; k < m; ++k) {
      const std::size_t i = std::size_t(rigid_[k]);
      yR[k] = stress_[i] * rigidStrainScale_[k];
      stress_[i] += tauWeight_[i] * l[k];
    }
  }

  // faceForce = D^T stress + G (Wp p) over faceBlocks_ (p may be null: no pressure), then
  // yu = m u + W_F faceForce on every Cartesian face (m = W_F = 0 off faceBlocks_).
  void forceOnFaces(const double* p, const double* u, double* yu) const {
    kernels::CellStressInput in;
    in.p = p;
    in.pWeight = pWeight_.data();
    in.tau = stress_.data();
    kernels::facesFromCells<Dim>(*layout_, in, nullptr, faceForce_.data(), &faceBlocks_);
    const std::ptrdiff_t m = std::ptrdiff_t(Dim * n_);
#pragma omp parallel for schedule(static) if (sparse_grid::worthParallel(Dim * n_))
    for (std::ptrdiff_t i = 0; i < m; ++i) yu[i] = mass_[i] * u[i] + wfUnknown_[i] * faceForce_[i];
  }

  // The blocks the kernels of apply() visit: cellBlocks_ hold a pressure (Wp > 0) or stress
  // (Q > 0) sample, faceBlocks_ an unknown or tile face. Off them every output of apply() is zero.
  void buildBlockLists() {
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

  // Wp, Wt (zero on reduced cells / inside tiles) and Q = mu/c Wt / W_F^tau (rigid samples: the
  // penalty's Q = mu/c Wt / f_r).
  void buildWeights() {
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

  void classify() {
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

  // Velocity rows: their diagonal. Constraint rows (pressure, rigid stress): the Schur diagonal
  // estimate diag(B A_d^-1 B^T), A_d the block diagonal of the velocity block: Cartesian
  // faces by their diagonal, sum_f w_j^2 W_F^2 / (dx^2 diag_f), plus for the samples next to a
  // tile k_j^T A_tt^-1 k_j, k_j = J_t K e_j. (Counting a tile face with its mass alone,
  // (dt/rho) / dx^2, overestimated it by 1 + 4 mu dt / (rho dx^2) in the viscous limit.) A rigid
  // sample whose estimate is zero touches no unknown face: its row would be zero, and it gets none,
  // as the pressure-stress form leaves such rows inactive.
  void buildDiagonal() {
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

  // A_tt = B + (J V J^T)_tt per tile (exact): its diagonal into `diagonal`; returns its inverses.
  std::vector<Matrix> tileBlocks(Vector& diagonal) const {
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

  // u rows: (rho/dt) W_F W_m u* - W_F V d;  v rows: M_R v*/dt - J V d;  p rows: -Wp G^T d;
  // rigid rows: -Wt D d, with d = (1 - W_F) u_solid on the non-tile faces.
  void buildRightHandSide() {
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

  // Closed container: constant pressure on the active cells is a null vector.
  void detectNullSpace() {
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

  // The penalty's fluid weight f_r on rigid samples: Q = mu/c Wt / f_r there. It does not change
  // the answer (the multiplier completes the constraint), only the conditioning. MINRES + multigrid
  // iterations with f_r = 1/27, 1/100, 1/300, 1/1000: ball on solids 32^3 360 / 290 / 272 / 288,
  // 48^3 555 / 419 / 397 / -; the beam (res 64, its first three steps) 763-511-440 /
  // 844-538-465 / 924-621-525 / 1004-691-598 (1e-4: 1469-1061-959). 1/100 is the best compromise
  // (geometric mean 1.32x the iterations of the penalty without multipliers; 1/27: 1.40x, 1/300: 1.38x).
  static constexpr double rigidPenaltyWeight() { return 1.0 / 100.0; }
  const StaggeredProblem<Dim>* prob_;
  const BlockLayout<Dim>* layout_;
  const ReducedTiles<Dim>* tiles_;
  std::size_t n_, nTile_;
  std::vector<FaceState> state_;
  Vector pWeight_, tauWeight_, q_, wfUnknown_, mass_, diag_, rhs_, nullSpace_;
  std::vector<Matrix> tileInverses_;  // A_tt^-1 per tile (buildDiagonal)
  std::vector<std::int64_t> rigid_;  // channel-major stress samples with a multiplier row
  Vector rigidStrainScale_;           // per rigid row: C' / Wt (Q D w -> Wt D w)
  kernels::BlockList cellBlocks_, otherCellBlocks_, faceBlocks_;
  mutable Vector faceField_, faceForce_, stress_;
};

}  // namespace systems
}  // namespace stokes::solver
