// The members of ProblemHierarchy (multigrid_hierarchy.h), compiled once for Dim = 2 and 3 into the stokes_systems
// library.
#include "solver/multigrid/multigrid_hierarchy.h"

namespace stokes::solver {
inline namespace multigrid {

template <int Dim>
ProblemHierarchy<Dim>::ProblemHierarchy(const StaggeredProblem<Dim>& fine, std::size_t maxCoarseCells, int maxLevels)
    : fine_(&fine) {
  std::size_t cells = countActiveCells(*fine.layout);
  while (int(levels()) < maxLevels && cells > maxCoarseCells) {
    const StaggeredProblem<Dim>& f = problem(levels() - 1);
    auto layout = std::make_unique<BlockLayout<Dim>>(sparse_grid::coarsenLayout(*f.layout));
    const std::size_t coarseCells = countActiveCells(*layout);
    if (coarseCells >= cells) break;
    auto coarse = std::make_unique<StaggeredProblem<Dim>>(coarsenProblem(f, *layout));
    layouts_.push_back(std::move(layout));
    coarse_.push_back(std::move(coarse));
    cells = coarseCells;
  }
}

template <int Dim>
std::size_t ProblemHierarchy<Dim>::countActiveCells(const BlockLayout<Dim>& L) {
  std::size_t k = 0;
  for (std::size_t s = 0; s < L.numSlots(); ++s) k += L.isActiveCell(s) ? 1 : 0;
  return k;
}

template <int Dim>
StaggeredProblem<Dim> ProblemHierarchy<Dim>::coarsenProblem(const StaggeredProblem<Dim>& f, const BlockLayout<Dim>& layout) {
  using SC = StressChannels<Dim>;
  StaggeredProblem<Dim> c;
  c.layout = &layout;
  c.rho = f.rho;
  c.mu = f.mu;
  c.dt = f.dt;
  c.minMassWeight = f.minMassWeight;
  c.allocate(f.hasSolids());
  const std::size_t nf = f.slots(), nc = c.slots();
  auto coarsen = [&](sparse_grid::StaggerMask mask, const Vector& fine, Vector& coarse, int channel, double missing) {
    sparse_grid::coarsenSampleWeights<Dim>(*f.layout, layout, mask, fine.data() + channel * nf,
                                    coarse.data() + channel * nc, missing);
  };
  for (int a = 0; a < Dim; ++a) {
    coarsen(sparse_grid::faceMask(a), f.liquidFace, c.liquidFace, a, 0.0);
    if (f.hasSolids()) coarsen(sparse_grid::faceMask(a), f.fluidFace, c.fluidFace, a, 1.0);
  }
  if (!f.closedFace.empty()) c.closedFace = coarsenClosedFaces(f, layout);
  if (!f.fluidStress.empty()) c.fluidStress.assign(SC::kCount * nc, 1.0);  // walls without solids
  coarsen(sparse_grid::kCellCentre, f.liquidCell, c.liquidCell, 0, 0.0);
  for (int ch = 0; ch < SC::kCount; ++ch) {
    coarsen(SC::mask(ch), f.liquidStress, c.liquidStress, ch, 0.0);
    if (!f.fluidStress.empty()) coarsen(SC::mask(ch), f.fluidStress, c.fluidStress, ch, 1.0);
  }
  floorWetWeights(c.liquidCell);
  floorWetWeights(c.liquidStress);
  return c;
}

template <int Dim>
void ProblemHierarchy<Dim>::floorWetWeights(Vector& w) {
  for (double& v : w)
    if (v > 0.0) v = std::max(v, kCoarseLiquidWeightFloor);
}

template <int Dim>
std::vector<std::uint8_t> ProblemHierarchy<Dim>::coarsenClosedFaces(const StaggeredProblem<Dim>& f, const BlockLayout<Dim>& layout) {
  const std::size_t nf = f.slots(), nc = layout.numSlots();
  Vector fineFlags(Dim * nf), coarseFlags(Dim * nc);
  for (std::size_t i = 0; i < Dim * nf; ++i) fineFlags[i] = f.closedFace[i] ? 1.0 : 0.0;
  for (int a = 0; a < Dim; ++a)
    sparse_grid::coarsenSampleWeights<Dim>(*f.layout, layout, sparse_grid::faceMask(a), fineFlags.data() + a * nf,
                                    coarseFlags.data() + a * nc, 0.0);
  std::vector<std::uint8_t> closed(Dim * nc);
  for (std::size_t i = 0; i < Dim * nc; ++i) closed[i] = coarseFlags[i] > 0.0 ? 1 : 0;
  return closed;
}

template class ProblemHierarchy<2>;
template class ProblemHierarchy<3>;

}  // namespace multigrid
}  // namespace stokes::solver
