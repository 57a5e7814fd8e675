#pragma once
// Geometric multigrid for the staggered systems by re-discretisation (docs/design.md §5):
// the fine StaggeredProblem is coarsened level by level (layout: parent cells, dx doubled;
// volume weights: means of the fine weights, grid_transfer.h), and on every coarse level the SAME
// system class is built from the coarse problem -- the stencils are generic in dx, so each level
// is, e.g., a ViscositySystem of its own. Transfers are the staggered linear interpolations of
// grid_transfer.h, one stagger mask per channel of the unknowns.
#include <algorithm>
#include <memory>
#include <vector>

#include "solver/multigrid/multigrid.h"
#include "solver/problem/staggered_problem.h"
#include "sparse_grid/grid_transfer.h"

namespace stokes::solver {
inline namespace multigrid {

/// The smallest wet W_L^p and W_L^tau of a coarse level (ProblemHierarchy::floorWetWeights).
/// Measured with the unified SPD cycle on 2D plane-cut Gaussians (n = 16 to 64): floors 0.01 /
/// 0.05 / 0.2 took 1.9-3.6x / 1.05-1.21x / 0.93-1.01x the CG iterations of 0.1, none
/// broke down (without a floor all broke down or stalled); flooring W_L^p alone or W_L^tau alone
/// still broke down.
inline constexpr double kCoarseLiquidWeightFloor = 0.1;

/// A fine problem and its coarsened copies (level 0 = the fine problem itself, not owned).
template <int Dim>
class ProblemHierarchy {
 public:
  /// Coarsens until a level has at most `maxCoarseCells` active cells, stops shrinking, or
  /// `maxLevels` levels exist.
  ProblemHierarchy(const StaggeredProblem<Dim>& fine, std::size_t maxCoarseCells = 64, int maxLevels = 12);

  std::size_t levels() const { return 1 + coarse_.size(); }
  const StaggeredProblem<Dim>& problem(std::size_t l) const { return l == 0 ? *fine_ : *coarse_[l - 1]; }
  const BlockLayout<Dim>& layout(std::size_t l) const { return *problem(l).layout; }

  static std::size_t countActiveCells(const BlockLayout<Dim>& L);

 private:
  /// Same constants, weights averaged (sparse_grid::coarsenSampleWeights; wet W_L^p and W_L^tau
  /// floored, floorWetWeights), closed wall faces kept
  /// (coarsenClosedFaces), u* and solid velocity zero: a coarse level only ever sees residuals.
  static StaggeredProblem<Dim> coarsenProblem(const StaggeredProblem<Dim>& f, const BlockLayout<Dim>& layout);

  /// Raises the wet weights below kCoarseLiquidWeightFloor to it (zero stays zero). A coarse row
  /// carries W^2 (and W) of its weight W (W_L^p or W_L^tau) on its diagonal, but its prolonged hat also
  /// covers wet fine samples: under plane-cut weights a sample may be wet by 1e-13, so a near-empty
  /// coarse sample is a near-null row of A_c while P^T A P holds its wet neighbours' energy. A_c^-1
  /// then inflates that direction (the unified SPD cycle's eigenvalues reached 1e74 on a 2D
  /// Gaussian, and rounding made it indefinite: CG broke down). Sub-samples
  /// never go below 1/27 on the fine level. A coarse level only preconditions, so its weights may
  /// differ; the floor bounds that ratio by ~1 / floor^2.
  static void floorWetWeights(Vector& w);

  /// A coarse face is closed (a wall, Dirichlet 0) when any fine face it covers is: the coarse
  /// face of axis a at coarse cell C covers the fine faces of axis a at cells 2C + (0 or 1 along
  /// the other axes). A wall at an odd fine index lands half a coarse cell outward; a coarse level
  /// only preconditions, and without the walls its velocity block would miss them entirely.
  static std::vector<std::uint8_t> coarsenClosedFaces(const StaggeredProblem<Dim>& f, const BlockLayout<Dim>& layout);

  const StaggeredProblem<Dim>* fine_;
  std::vector<std::unique_ptr<BlockLayout<Dim>>> layouts_;
  std::vector<std::unique_ptr<StaggeredProblem<Dim>>> coarse_;
};

/// The stagger masks of common unknown blocks.
template <int Dim>
std::vector<sparse_grid::StaggerMask> faceChannels() {
  std::vector<sparse_grid::StaggerMask> m;
  for (int a = 0; a < Dim; ++a) m.push_back(sparse_grid::faceMask(a));
  return m;
}
template <int Dim>
std::vector<sparse_grid::StaggerMask> pressureStressChannels(bool withStress) {
  std::vector<sparse_grid::StaggerMask> m{sparse_grid::kCellCentre};
  if (withStress)
    for (int c = 0; c < StressChannels<Dim>::kCount; ++c) m.push_back(StressChannels<Dim>::mask(c));
  return m;
}

/// One flag per sample of `channels` (channel-major) for GridTransfer's `excluded`: the pressure
/// samples (a cell-centred first channel, as in pressureStressChannels) of cells wholly inside a
/// solid (W_F = 0 at the cell centre, read from the cell-centred diagonal stress channel). There
/// the pressure sees a Neumann wall, so the prolongation extrapolates instead of pulling the
/// correction to zero. Velocities and stresses in a solid are Dirichlet: never flagged. Empty when
/// the problem has no solids.
template <int Dim>
std::vector<std::uint8_t> solidPressureSamples(const StaggeredProblem<Dim>& p, const std::vector<sparse_grid::StaggerMask>& channels) {
  if (!p.hasSolids() || channels.empty() || channels.front() != sparse_grid::kCellCentre) return {};
  const std::size_t n = p.slots();
  std::vector<std::uint8_t> solid(channels.size() * n, 0);
  for (std::size_t s = 0; s < n; ++s) solid[s] = p.fluidStress[s] <= 0.0 ? 1 : 0;
  return solid;
}

/// One flag per sample of the face channels (channel-major) for GridTransfer's `excluded`: coarse
/// faces in the air, i.e. inactive on the coarse level (no liquid stencil reaches them) with
/// W_F = 1 and not on a closed wall. Across a free surface the velocity is free (no traction),
/// so the prolongation extrapolates the correction up to the surface instead of pulling it to
/// zero there; faces in solids and on walls stay Dirichlet (no slip). Measured on the 3D mixed
/// problem without solids: velocity-cycle PCG 23 -> 16 (N = 32), 30 -> 19 (N = 64) iterations.
template <int Dim>
std::vector<std::uint8_t> airVelocitySamples(const StaggeredProblem<Dim>& p, const std::vector<std::uint8_t>& activeCoarse) {
  std::vector<std::uint8_t> air(activeCoarse.size(), 0);
  for (std::size_t i = 0; i < air.size(); ++i)
    air[i] = !activeCoarse[i] && p.fluidFaceWeight(i) >= 1.0 && !p.isClosedFace(i) ? 1 : 0;
  return air;
}

/// GridTransfer's `excluded` flags for `channels` on coarse problem `p`: solid pressure samples
/// (solidPressureSamples) for the pressure channels, air faces (airVelocitySamples) for the
/// velocity channels, none otherwise.
template <int Dim>
std::vector<std::uint8_t> excludedCoarseSamples(const StaggeredProblem<Dim>& p, const std::vector<sparse_grid::StaggerMask>& channels,
                                                const std::vector<std::uint8_t>& activeCoarse) {
  if (channels == faceChannels<Dim>()) return airVelocitySamples(p, activeCoarse);
  return solidPressureSamples(p, channels);
}

/// A level made of the leading block [0, count) of a system: y = (A [x; 0])[0, count).
template <class System>
MultigridLevel leadingBlockLevel(std::shared_ptr<const System> sys, std::size_t count) {
  MultigridLevel level;
  level.size = count;
  level.diagonal.assign(sys->diagonal().begin(), sys->diagonal().begin() + count);
  if (sys->size() == count) {
    level.apply = [sys](const double* x, double* y) { sys->apply(x, y); };
    return level;
  }
  // The pressure-velocity systems apply their velocity block without the zero-padded copies.
  if constexpr (requires(const System& s, const double* x, double* y) {
                  s.applyVelocityBlock(x, y);
                  s.velocityRows();
                }) {
    if (sys->velocityRows() == count) {
      level.apply = [sys](const double* x, double* y) { sys->applyVelocityBlock(x, y); };
      return level;
    }
  }
  auto xFull = std::make_shared<Vector>(sys->size(), 0.0);
  auto yFull = std::make_shared<Vector>(sys->size(), 0.0);
  level.apply = [sys, xFull, yFull, count](const double* x, double* y) {
    copy(x, xFull->data(), count);  // the trailing entries stay zero
    sys->apply(xFull->data(), yFull->data());
    copy(yFull->data(), y, count);
  };
  return level;
}

/// The levels of a V-cycle without their transfers: `fine` (a block of the fine system), then
/// `makeSystem(problem_l)` (returning shared_ptr<const System>) restricted to its leading
/// channels.size() x slots block on every coarse level.
template <int Dim, class MakeSystem>
std::vector<MultigridLevel> hierarchyLevels(const ProblemHierarchy<Dim>& h, const std::vector<sparse_grid::StaggerMask>& channels,
                                            MultigridLevel fine, const MakeSystem& makeSystem) {
  std::vector<MultigridLevel> levels;
  levels.push_back(std::move(fine));
  for (std::size_t l = 1; l < h.levels(); ++l) {
    auto sys = makeSystem(h.problem(l));
    levels.push_back(leadingBlockLevel(sys, channels.size() * h.problem(l).slots()));
  }
  return levels;
}

/// Sets the staggered grid transfers (grid_transfer.h) between levels l and l + 1, pruned to the
/// active rows of both levels.
template <int Dim>
void attachGridTransfer(std::vector<MultigridLevel>& levels, const ProblemHierarchy<Dim>& h,
                        const std::vector<sparse_grid::StaggerMask>& channels, std::size_t l) {
  const std::vector<std::uint8_t> activeCoarse = Multigrid::activeRows(levels[l + 1].diagonal);
  auto transfer = std::make_shared<sparse_grid::GridTransfer<Dim>>(
      h.layout(l), h.layout(l + 1), channels, excludedCoarseSamples(h.problem(l + 1), channels, activeCoarse),
      Multigrid::activeRows(levels[l].diagonal), activeCoarse);
  levels[l].restrictToCoarse = [transfer](const double* f, double* c) { transfer->restrictTo(f, c); };
  levels[l].prolongToFine = [transfer](const double* c, double* f) { transfer->prolong(c, f, false); };
}

/// A V-cycle whose fine level is `fine` (a block of the fine system, sized channels x slots) and
/// whose coarse levels are `makeSystem(problem_l)`, with grid transfers between all levels. The
/// hierarchy must outlive the result.
template <int Dim, class MakeSystem>
std::shared_ptr<Multigrid> buildMultigrid(const ProblemHierarchy<Dim>& h, const std::vector<sparse_grid::StaggerMask>& channels,
                                          MultigridLevel fine, const MakeSystem& makeSystem,
                                          const MultigridOptions& opt = {}) {
  std::vector<MultigridLevel> levels = hierarchyLevels(h, channels, std::move(fine), makeSystem);
  for (std::size_t l = 0; l + 1 < levels.size(); ++l) attachGridTransfer(levels, h, channels, l);
  return std::make_shared<Multigrid>(std::move(levels), opt);
}

// Compiled once, in multigrid_hierarchy.cpp.
extern template class ProblemHierarchy<2>;
extern template class ProblemHierarchy<3>;

}  // namespace multigrid
}  // namespace stokes::solver
