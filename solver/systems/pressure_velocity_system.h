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

  PressureVelocitySystem(const StaggeredProblem<Dim>& prob, const ReducedTiles<Dim>* tiles = nullptr);

  std::size_t size() const { return Dim * n_ + nTile_ + n_ + rigid_.size(); }
  /// First pressure row (n_ pressure rows follow, then the rigid stress rows).
  std::size_t pressureOffset() const { return Dim * n_ + nTile_; }
  /// First rigid stress row; rigidSample(k) names the stress sample of row rigidOffset() + k.
  std::size_t rigidOffset() const { return pressureOffset() + n_; }
  std::size_t rigidRows() const { return rigid_.size(); }
  /// Channel-major stress sample index (channel * numSlots + slot) of rigid row k.
  std::size_t rigidSample(std::size_t k) const { return std::size_t(rigid_[k]); }

  void apply(const double* x, double* y) const;

  /// Rows of the velocity block [u_C | v_R]: the Cartesian faces and the tile DOFs.
  std::size_t velocityRows() const { return Dim * n_ + nTile_; }
  /// y = A_vv x on x = [u_C | v_R], A_vv the leading 2x2 block of the matrix above:
  ///   [ (rho/dt) W_F W_m + W_F V W_F    W_F V J^T   ]
  ///   [ J V W_F                         B + J V J^T ],
  /// the leading block of apply() with p = 0 and l_r = 0, bit for bit, without forming the
  /// constraint rows (the multigrid's velocity cycle applies this on every level).
  void applyVelocityBlock(const double* x, double* y) const;
  /// The tiles coupled into this system (null: the uniform model).
  const ReducedTiles<Dim>* tiles() const { return tiles_; }
  /// Rows of the Cartesian face block (the first velocityRows() - tile DOFs).
  std::size_t faceRows() const { return Dim * n_; }

  /// Blocks holding a pressure or stress sample / an unknown or tile face (benchmarks, tests).
  std::size_t cellBlocks() const { return cellBlocks_.size(); }
  std::size_t faceBlocks() const { return faceBlocks_.size(); }

  const Vector& rhs() const { return rhs_; }
  const Vector& diagonal() const { return diag_; }
  /// Adds to the pressure rows' Schur diagonal estimate `pressureDiagonal` (n_ entries, the
  /// pressure part of diagonal()) the difference that one group of Cartesian face rows makes
  /// when its block H of the velocity block is inverted exactly instead of by its diagonal:
  ///   s_p += sum_{f, g in G} B_pf (H^-1)_fg B_pg - sum_{f in G} B_pf^2 / A_ff,
  /// B_pf = +-wp_p W_F,f / dx the pressure coupling (+ on the cell's low face). `faces`: the m
  /// padded face rows, `inverse`: H^-1, m x m row-major.
  void addFaceBlockToSchurDiagonal(const std::uint32_t* faces, std::size_t m, const double* inverse,
                                   double* pressureDiagonal) const;
  /// A_tt^-1 per tile, A_tt = B + (J V J^T)_tt the tile's diagonal block of the velocity block.
  const std::vector<Matrix>& tileBlockInverses() const { return tileInverses_; }
  const double* nullSpace() const { return nullSpace_.empty() ? nullptr : nullSpace_.data(); }
  std::size_t activeUnknowns() const;
  const std::vector<FaceState>& faceStates() const { return state_; }
  /// What the velocity block is made of, for assembling it (solver/multigrid/velocity_block_matrix.h):
  /// Q per stress sample (channel-major, 0 where no Cartesian stress), W_F on the Cartesian unknown
  /// faces (0 elsewhere) and their mass (rho/dt) W_F W_m.
  const Vector& stressCoefficients() const { return q_; }
  const Vector& unknownFaceWeights() const { return wfUnknown_; }
  const Vector& faceMass() const { return mass_; }
  const sparse_grid::BlockLayout<Dim>& layout() const { return *layout_; }
  /// The problem's mu dt / (rho dx^2).
  double viscousNumber() const { return prob_->viscousNumber(); }
  /// Wp per cell and Wt per stress sample (channel-major; 0 on reduced cells and inside tiles), and
  /// per rigid row C' / Wt (the rigid row reads Q D w times this): for the operator on live rows
  /// (pressure_velocity_rows.h).
  const Vector& pressureWeights() const { return pWeight_; }
  const Vector& stressWeights() const { return tauWeight_; }
  const Vector& rigidStrainScales() const { return rigidStrainScale_; }

  /// Face velocities: x on Cartesian unknown faces, C(x) v on tile faces, solid velocity on
  /// Dirichlet faces, u* on inactive faces.
  void velocities(const double* x, double* u) const;

 private:
  // faceField = W_F u on the faces of faceBlocks_ (zero elsewhere, which no apply changes).
  void loadFaceField(const double* u) const;

  // yp = Wp G^T faceField (if yp) and stress = Q D faceField over cellBlocks_; yp is zero on every
  // other block (no pressure sample there), stress_ stays zero there.
  void stressFromFaces(double* yp) const;

  // On a rigid sample stress_ holds the penalty's Q D w = (Wt / C') Wt D w: the row
  // y_r = Wt D w = stress_ C' / Wt, then stress_ += Wt l_r, the multiplier's force for forceOnFaces.
  void addRigidRows(const double* l, double* yR) const;

  // faceForce = D^T stress + G (Wp p) over faceBlocks_ (p may be null: no pressure), then
  // yu = m u + W_F faceForce on every Cartesian face (m = W_F = 0 off faceBlocks_).
  void forceOnFaces(const double* p, const double* u, double* yu) const;

  // The blocks the kernels of apply() visit: cellBlocks_ hold a pressure (Wp > 0) or stress
  // (Q > 0) sample, faceBlocks_ an unknown or tile face. Off them every output of apply() is zero.
  void buildBlockLists();

  // Wp, Wt (zero on reduced cells / inside tiles) and Q = mu/c Wt / W_F^tau (rigid samples: the
  // penalty's Q = mu/c Wt / f_r).
  void buildWeights();

  void classify();

  // Velocity rows: their diagonal. Constraint rows (pressure, rigid stress): the Schur diagonal
  // estimate diag(B A_d^-1 B^T), A_d the block diagonal of the velocity block: Cartesian
  // faces by their diagonal, sum_f w_j^2 W_F^2 / (dx^2 diag_f), plus for the samples next to a
  // tile k_j^T A_tt^-1 k_j, k_j = J_t K e_j. (Counting a tile face with its mass alone,
  // (dt/rho) / dx^2, overestimated it by 1 + 4 mu dt / (rho dx^2) in the viscous limit.) A rigid
  // sample whose estimate is zero touches no unknown face: its row would be zero, and it gets none,
  // as the pressure-stress form leaves such rows inactive.
  void buildDiagonal();

  // A_tt = B + (J V J^T)_tt per tile (exact): its diagonal into `diagonal`; returns its inverses.
  std::vector<Matrix> tileBlocks(Vector& diagonal) const;

  // u rows: (rho/dt) W_F W_m u* - W_F V d;  v rows: M_R v*/dt - J V d;  p rows: -Wp G^T d;
  // rigid rows: -Wt D d, with d = (1 - W_F) u_solid on the non-tile faces.
  void buildRightHandSide();

  // Closed container: constant pressure on the active cells is a null vector.
  void detectNullSpace();

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

// Compiled once, in pressure_velocity_system.cpp.
extern template class PressureVelocitySystem<2>;
extern template class PressureVelocitySystem<3>;

}  // namespace systems
}  // namespace stokes::solver
