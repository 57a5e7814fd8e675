#pragma once
// StaggeredProblem: everything one Stokes / viscosity / pressure step needs on a BlockLayout --
// material constants, the intermediate velocity u*, prescribed solid velocities, and the volume
// weights of the liquid (W_L) and the non-solid region (W_F) for each sample kind.
//
// Arrays are channel-major over layout.numSlots(): faces have Dim channels (u_a on the lower face
// normal to a), cells one, stresses StressChannels<Dim>::kCount (diagonal first, then pairs).
// An empty fluid-weight array means "no solids": W_F = 1 everywhere and no W_F is stored.
#include <cmath>
#include <stdexcept>
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "solver/krylov/aligned_vector.h"
#include "sparse_grid/block_layout.h"
#include "sparse_grid/stagger.h"
#include "sparse_grid/volume_weights.h"

namespace stokes::solver {
inline namespace problem {

using sparse_grid::BlockLayout;
using sparse_grid::StressChannels;

template <int Dim>
struct StaggeredProblem {
  const BlockLayout<Dim>* layout = nullptr;
  double rho = 1.0;  ///< density
  double mu = 1.0;   ///< dynamic viscosity
  double dt = 1.0;   ///< time step

  /// Faces whose liquid weight is below this get this mass weight instead: a face that a
  /// positive-weight pressure or stress stencil touches must stay an unknown (docs/design.md §3), and
  /// a zero mass cannot be inverted in the SPD form. 1/27 = the smallest non-zero 3^3 fraction.
  double minMassWeight = 1.0 / 27.0;


  Vector liquidFace;    ///< W_L^u   (Dim channels)
  Vector liquidCell;    ///< W_L^p   (1 channel)
  Vector liquidStress;  ///< W_L^tau (kCount channels)
  Vector fluidFace;     ///< W_F^u   (Dim channels, or empty: no solids)
  /// W_F^tau (kCount channels, or empty: 1 everywhere). Stored without fluidFace for the walls of
  /// a domain box: a stress sample on a wall has half its control volume outside, and its weight
  /// scales the viscous coupling across the wall by 1 / W_F^tau (the compliance c mu^-1 W_F^tau of
  /// the SPD form, Q = mu/c W_L^tau / W_F^tau of the others): the ghost-fluid factor that puts
  /// the no-slip plane at the wall (a wall through the sample: 1/2, twice the coupling).
  Vector fluidStress;

  Vector uStar;   ///< intermediate velocity u* (Dim channels)
  Vector uSolid;  ///< prescribed velocity on faces with W_F = 0 (Dim channels, or empty: zero)

  /// Faces held at zero velocity without a fluid weight (Dim channels, 0/1, or empty: none): the
  /// walls of a domain box where the layout ends, so that a scene without solids needs no W_F.
  /// A closed face is Dirichlet (classifyFaces). u* and the solid velocity must be 0 there
  /// (validate() checks): the systems' right-hand sides read u* (W_F = 1) or (1 - W_F) u_solid.
  std::vector<std::uint8_t> closedFace;

  /// Divergence target s (1/s, uniform): the liquid cells' constraint becomes div u = s instead of
  /// div u = 0 (weighted as the constraint rows are: Wp G^T u_bar = -Wp s). s < 0 contracts the
  /// liquid at the relative rate |s|. Volume control (Kim et al. 2007): the simulator sets it from
  /// the drift of the liquid's volume. It applies to the liquid cells that can change their
  /// volume, those connected to a free surface past the solids' rigid samples (ventedCells,
  /// solver/problem/divergence_target.h); a pocket sealed by solids, walls or the liquid's rigid
  /// extension into a solid keeps div u = 0 (a closed container among them). Reduced tiles stay
  /// divergence-free (no pressure rows).
  double divergenceTarget = 0.0;

  std::size_t slots() const { return layout->numSlots(); }
  /// mu dt / (rho dx^2): the cell-scale ratio of viscous to inertial resistance in the velocity
  /// block (rho/dt) W_m + W_F V W_F (Eq. 4.19); >> 1 for the viscous liquids of the thesis.
  double viscousNumber() const { return mu * dt / (rho * layout->dx() * layout->dx()); }
  bool hasSolids() const { return !fluidFace.empty(); }
  double fluidFaceWeight(std::size_t i) const { return fluidFace.empty() ? 1.0 : fluidFace[i]; }
  double fluidStressWeight(std::size_t i) const { return fluidStress.empty() ? 1.0 : fluidStress[i]; }
  /// The fluid weight the constitutive law of stress sample i uses: W_F^tau, or 0 below
  /// minMassWeight. A sample a solid cuts to a sliver is rigid -- zero compliance, its strain rate
  /// held at the solid's -- as a face cut below minMassWeight is the solid's (Dirichlet) and as
  /// ventedCells counts it. Its tiny compliance left a near-null mode in both forms (the
  /// pressure-stress form's Jacobi CG took 2.6x the iterations with compliance 1e-3 c/mu Wt on the
  /// samples inside solids, ball on solids 32^3) and cannot be inverted in the pressure-velocity
  /// form; an exact zero is a constraint both forms carry exactly.
  double constitutiveFluidWeight(std::size_t i) const {
    const double w = fluidStressWeight(i);
    return w < minMassWeight ? 0.0 : w;
  }
  double solidVelocity(std::size_t i) const { return uSolid.empty() ? 0.0 : uSolid[i]; }
  bool isClosedFace(std::size_t i) const { return !closedFace.empty() && closedFace[i] != 0; }

  /// One rank's part of a problem distributed by blocks (docs/petsc.md, "Per-rank set-up"), or
  /// empty: the whole problem. Else the MPI rank that owns each of the layout's blocks: this
  /// rank's own blocks and a halo of its neighbours' (sparse_grid/block_order.h, haloBlocks), whose
  /// weights and u* are filled as the owned ones are. A solve on such a problem gives the velocities
  /// of the owned blocks' faces; those of the halo's are not meaningful.
  std::vector<std::int32_t> blockOwner;
  std::int32_t rank = 0;  ///< this process's rank, where blockOwner is set
  bool isDistributed() const { return !blockOwner.empty(); }
  /// Whether this rank owns the samples of `slot` (always, in a whole problem).
  bool ownsSlot(std::size_t slot) const {
    return blockOwner.empty() || blockOwner[slot / sparse_grid::BlockLayout<Dim>::kSlots] == rank;
  }

  /// Allocates the liquid weights and u* (zeros); call before filling them.
  void allocate(bool withSolids) {
    const std::size_t n = slots();
    liquidFace.assign(Dim * n, 0.0);
    liquidCell.assign(n, 0.0);
    liquidStress.assign(StressChannels<Dim>::kCount * n, 0.0);
    uStar.assign(Dim * n, 0.0);
    if (withSolids) {
      fluidFace.assign(Dim * n, 1.0);
      fluidStress.assign(StressChannels<Dim>::kCount * n, 1.0);
      uSolid.assign(Dim * n, 0.0);
    } else {
      fluidFace.clear();
      fluidStress.clear();
      uSolid.clear();
    }
  }

  /// Throws std::invalid_argument naming the first problem: wrong sizes, non-positive constants,
  /// weights outside [0,1], or a non-finite u* (with the face index and its cell).
  void validate() const {
    if (!layout) throw std::invalid_argument("StaggeredProblem: no layout");
    if (!(rho > 0.0) || !std::isfinite(rho)) throw std::invalid_argument("StaggeredProblem: rho must be > 0");
    if (!(mu >= 0.0) || !std::isfinite(mu)) throw std::invalid_argument("StaggeredProblem: mu must be >= 0");
    if (!(dt > 0.0) || !std::isfinite(dt)) throw std::invalid_argument("StaggeredProblem: dt must be > 0");
    if (!std::isfinite(divergenceTarget))
      throw std::invalid_argument("StaggeredProblem: divergenceTarget must be finite");
    const std::size_t n = slots();
    auto checkSize = [&](const Vector& v, std::size_t want, const char* name, bool optional) {
      if (optional && v.empty()) return;
      if (v.size() != want)
        throw std::invalid_argument(std::string("StaggeredProblem: ") + name + " has " + std::to_string(v.size()) +
                                    " values, expected " + std::to_string(want));
    };
    checkSize(liquidFace, Dim * n, "liquidFace", false);
    checkSize(liquidCell, n, "liquidCell", false);
    checkSize(liquidStress, StressChannels<Dim>::kCount * n, "liquidStress", false);
    checkSize(fluidFace, Dim * n, "fluidFace", true);
    checkSize(fluidStress, StressChannels<Dim>::kCount * n, "fluidStress", true);
    checkSize(uStar, Dim * n, "uStar", false);
    checkSize(uSolid, Dim * n, "uSolid", true);
    if (isDistributed() && blockOwner.size() != layout->numBlocks())
      throw std::invalid_argument("StaggeredProblem: blockOwner has " + std::to_string(blockOwner.size()) +
                                  " entries, expected one per block (" + std::to_string(layout->numBlocks()) + ")");
    if (!closedFace.empty() && closedFace.size() != Dim * n)
      throw std::invalid_argument("StaggeredProblem: closedFace has " + std::to_string(closedFace.size()) +
                                  " values, expected " + std::to_string(Dim * n));
    for (std::size_t i = 0; i < closedFace.size(); ++i)
      if (closedFace[i] && (uStar[i] != 0.0 || solidVelocity(i) != 0.0))
        throw std::invalid_argument("StaggeredProblem: non-zero u* or solid velocity on closed face " +
                                    std::to_string(i));
    for (std::size_t i = 0; i < uStar.size(); ++i) {
      if (!std::isfinite(uStar[i]) || (!uSolid.empty() && !std::isfinite(uSolid[i]))) {
        const auto c = layout->cellOf(i % n);
        throw std::invalid_argument("StaggeredProblem: non-finite velocity on face axis " + std::to_string(i / n) +
                                    " of cell (" + std::to_string(c.x()) + "," + std::to_string(c.y()) + "," +
                                    std::to_string(c.z()) + ")");
      }
    }
  }
};

/// Compliance factor per stress channel: tau_aa = 2 mu eps_aa and tau_ab = mu gamma_ab, so the
/// stationarity rows read  D u - c mu^-1 tau = 0  with c = 1/2 (diagonal) or 1 (pairs).
template <int Dim>
constexpr double complianceFactor(int channel) {
  return StressChannels<Dim>::isDiagonal(channel) ? 0.5 : 1.0;
}

}  // namespace problem
}  // namespace stokes::solver

namespace stokes::solver {
inline namespace problem {

/// What a face is in a solve.
enum class FaceState : std::uint8_t {
  Inactive = 0,   ///< air face no positive-weight stencil touches: keeps u*
  Unknown = 1,    ///< solved for
  Dirichlet = 2,  ///< inside a solid (W_F = 0): takes the solid's velocity
  Reduced = 3,    ///< face of a reduced tile: u = C(x) v_R
};

/// Classifies every face: Dirichlet where W_F = 0 or the face is closed, Unknown where W_F > 0
/// and the face holds liquid or a positive-weight pressure/stress stencil touches it (`touched` > 0,
/// Dim channels), else Inactive. docs/design.md §3: dropping touched zero-liquid faces ruins the free-surface stresses.
template <int Dim>
std::vector<FaceState> classifyFaces(const StaggeredProblem<Dim>& prob, const double* touched) {
  const std::size_t m = Dim * prob.slots();
  std::vector<FaceState> state(m, FaceState::Inactive);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(m); ++i) {
    if (prob.fluidFaceWeight(i) <= 0.0 || prob.isClosedFace(i)) state[i] = FaceState::Dirichlet;
    else if (prob.liquidFace[i] > 0.0 || touched[i] > 0.0) state[i] = FaceState::Unknown;
  }
  return state;
}

/// The clamped mass weight of an unknown face, max(W_L^u, minMassWeight), before any lending
/// (the systems read faceMassWeights).
template <int Dim>
double faceMassWeight(const StaggeredProblem<Dim>& prob, std::size_t i) {
  return std::max(prob.liquidFace[i], prob.minMassWeight);
}

/// The same-channel neighbour (2 Dim of them) of face `i` that is an unknown with the most
/// liquid W_L^u, first in axis order on ties; -1 if none is an unknown.
template <int Dim>
std::int64_t mostLiquidNeighbourFace(const StaggeredProblem<Dim>& prob, const std::vector<FaceState>& state,
                                     std::size_t i) {
  const std::size_t n = prob.slots(), channel = i / n * n, slot = i % n;
  std::int64_t best = -1;
  for (int b = 0; b < Dim; ++b)
    for (int dir : {-1, 1}) {
      const std::int64_t s = prob.layout->neighbourSlot(slot, b, dir);
      if (s < 0) continue;
      const std::size_t j = channel + std::size_t(s);
      if (state[j] == FaceState::Unknown && (best < 0 || prob.liquidFace[j] > prob.liquidFace[std::size_t(best)]))
        best = std::int64_t(j);
    }
  return best;
}

/// Mass weights W_m of the unknown faces, 0 on the others (the inertia is rho/dt W_F W_m,
/// design §3.3). W_m = max(W_L^u, minMassWeight): the SPD form inverts it, so a touched air face
/// (W_L^u = 0) or a sliver keeps the clamp. Its excess mass minMassWeight - W_L^u is **lent** by
/// the unknown face of its channel with the most liquid among its neighbours, whose W_m drops by
/// it (when that leaves it at least minMassWeight; else nothing is lent). The faces' masses then
/// sum to the liquid's, and u* = g dt (every face) still translates a falling blob exactly. With
/// the clamp alone, each touched air face added rho g dx^3 / 27 to the weight its column
/// carries: a film draining down a wall was first order. Lending is a fixed-order
/// pass, so the masses do not depend on the thread count.
template <int Dim>
std::vector<double> faceMassWeights(const StaggeredProblem<Dim>& prob, const std::vector<FaceState>& state) {
  const std::size_t m = Dim * prob.slots();
  std::vector<double> mass(m, 0.0), lent(m, 0.0);
  std::vector<std::int64_t> lender(m, -1);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(m); ++k) {
    const std::size_t i = std::size_t(k);
    if (state[i] != FaceState::Unknown) continue;
    mass[i] = faceMassWeight(prob, i);
    if (prob.liquidFace[i] < prob.minMassWeight) lender[i] = mostLiquidNeighbourFace(prob, state, i);
  }
  for (std::size_t i = 0; i < m; ++i)
    if (lender[i] >= 0) lent[std::size_t(lender[i])] += mass[i] - prob.liquidFace[i];
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(m); ++k)
    if (lent[k] > 0.0 && mass[k] - lent[k] >= prob.minMassWeight) mass[k] -= lent[k];
  return mass;
}

}  // namespace problem
}  // namespace stokes::solver

namespace stokes::solver {
inline namespace problem {

/// Fills every liquid-weight channel (faces, cell centres, stresses) of `prob` from the signed
/// distance `phi` (liquid where phi < 0), by `rule` (sparse_grid::FractionRule: the engine's
/// plane cuts, kLiquidFractionRule, unless asked otherwise; the faces' by
/// computeLiquidFaceFractions).
template <int Dim, class Phi>
void fillLiquidWeights(StaggeredProblem<Dim>& prob, const Phi& phi,
                       sparse_grid::FractionRule rule = sparse_grid::kLiquidFractionRule) {
  const BlockLayout<Dim>& L = *prob.layout;
  const std::size_t n = L.numSlots();
  for (int a = 0; a < Dim; ++a)
    sparse_grid::computeLiquidFaceFractions<Dim>(L, a, phi, prob.liquidFace.data() + a * n, rule);
  sparse_grid::computeLiquidFractions<Dim>(L, sparse_grid::kCellCentre, phi, prob.liquidCell.data(), rule);
  for (int c = 0; c < StressChannels<Dim>::kCount; ++c)
    sparse_grid::computeLiquidFractions<Dim>(L, StressChannels<Dim>::mask(c), phi, prob.liquidStress.data() + c * n, rule);
}

}  // namespace problem
}  // namespace stokes::solver
