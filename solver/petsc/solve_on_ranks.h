#pragma once
// One solve of a system split over the MPI ranks by blocks (pressure_stress_ranks.h,
// pressure_velocity_ranks.h) with the PETSc backend (petsc_krylov.h): the owners of the blocks
// (the problem's, or cut here for a whole problem), the split, the solve, and the solution back on
// the padded rows.
#include <chrono>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "solver/krylov/compact_rows.h"
#include "solver/krylov/stopwatch.h"
#include "solver/petsc/petsc_krylov.h"
#include "solver/petsc/pressure_stress_ranks.h"
#include "solver/petsc/pressure_velocity_ranks.h"
#include "solver/problem/staggered_problem.h"
#include "sparse_grid/block_order.h"

namespace stokes::solver::petsc {

/// Solves `sys` of `prob` on PETSC_COMM_WORLD with the split `Ranks` (PressureStressRanks or
/// PressureVelocityRanks). x: padded rows; the initial guess on entry (live rows); on return the
/// solution on every row of a whole problem, or, for a problem distributed by blocks, on the rows
/// of the rank's blocks and the halo rows their stencils read. `liveRows` receives the unknowns
/// over all ranks. `interpolation`: the velocity multigrid's, for a split that has one.
template <template <int> class Ranks, int Dim, class System>
PetscReport solveOnRanks(const StaggeredProblem<Dim>& prob, const System& sys, const SolveOptions& opt, Vector& x,
                         std::size_t* liveRows = nullptr, FaceInterpolation interpolation = FaceInterpolation::Auto) {
  const auto t0 = std::chrono::steady_clock::now();
  const RowSelection rows = RowSelection::positiveDiagonal(sys.diagonal());
  std::vector<std::int32_t> owner = prob.blockOwner;
  if (!prob.isDistributed()) {
    const std::vector<int> cut = sparse_grid::blockOwners<Dim>(sys.layout(), ranks());
    owner.assign(cut.begin(), cut.end());
  }
  Ranks<Dim> split = [&] {
    if constexpr (std::is_constructible_v<Ranks<Dim>, const System&, const RowSelection&, std::vector<std::int32_t>,
                                          int, FaceInterpolation>)
      return Ranks<Dim>(sys, rows, std::move(owner), rank(), interpolation);
    else return Ranks<Dim>(sys, rows, std::move(owner), rank());
  }();
  const DistributedSystem& d = split.system();
  std::vector<double> owned(d.ownedRows);
  const BlockRows<Dim>& numbering = split.numbering();
  for (std::size_t k = 0; k < d.ownedRows; ++k) owned[k] = x[rows.rows()[numbering.owned()[k]]];
  const double partitionSeconds = secondsSince(t0);
  std::vector<double> ghosts;
  PetscReport rep = solveDistributed(d, opt, owned.data(), prob.isDistributed() ? &ghosts : nullptr);
  rep.setupSeconds += partitionSeconds;
  if (prob.isDistributed()) numbering.scatterRead(ghosts, rows.rows(), x.data());
  else numbering.scatterWhole(allGather(owned.data(), owned.size()), rows.rows(), x.data());
  if (liveRows) *liveRows = std::size_t(d.globalRows);
  return rep;
}

}  // namespace stokes::solver::petsc
