#pragma once
// What every analytic case shares (analytic_cases.cpp defines the functions): the step options
// its AnalyticOptions ask for, its problem, its report, and the kinetic energy of a face field.
#include <array>
#include <cmath>
#include <map>
#include <vector>

#include "analytic/analytic_cases.h"
#include "solver/step/rank_sums.h"
#include "sparse_grid/block_order.h"

namespace stokes::analytic::detail {

/// The solver options of one case: system, model (reduced tiles), the plan of the solve.
solver::StepOptions stepOptions(const AnalyticOptions& o, solver::SystemKind kind);

/// A result named `test` carrying the case's parameters.
AnalyticResult makeResult(const char* test, const AnalyticOptions& o);

/// The solve's numbers (iterations, timings, tiles) into r; u into r.velocities if asked. Returns
/// (and sets r.measured) whether u can be measured: not when the solve left none or broke down,
/// diverged or went non-finite (its status says so; an iteration cap leaves an approximate u,
/// which is measured).
bool fillReport(AnalyticResult& r, const solver::StepReport& rep, const AnalyticOptions& o, const solver::Vector& u);

/// A problem on `layout` with the case's rho, mu and dt; weights and u* allocated (zeros).
template <int Dim>
solver::StaggeredProblem<Dim> makeProblem(const sparse_grid::BlockLayout<Dim>& layout, const AnalyticOptions& o,
                                          bool withSolids) {
  solver::StaggeredProblem<Dim> prob;
  prob.layout = &layout;
  prob.rho = o.rho;
  prob.mu = o.mu;
  prob.dt = o.dt;
  prob.allocate(withSolids);
  return prob;
}

template <int Dim>
openvdb::Coord cellCoord(int i, int j, int k) {
  return Dim == 2 ? openvdb::Coord(i, j, 0) : openvdb::Coord(i, j, k);
}

/// sum over faces of rho W_m u^2 dV / 2 (W_m = W_F max(W_L, min)) on faces with W_F W_L > 0 (of
/// every rank's blocks in a distributed problem).
template <int Dim>
double kineticEnergy(const solver::StaggeredProblem<Dim>& prob, const solver::Vector& u) {
  const double dV = std::pow(prob.layout->dx(), Dim);
  const std::size_t n = prob.slots();
  double e = 0.0;
  for (std::size_t i = 0; i < u.size(); ++i) {
    const double w = prob.fluidFaceWeight(i) * prob.liquidFace[i];
    if (w > 0.0 && prob.ownsSlot(i % n)) e += 0.5 * prob.rho * w * u[i] * u[i] * dV;
  }
  return solver::sumOverParts(prob, e);
}

/// The cells of a case's layout on this rank, [lo, hi)^Dim filtered by `inLayout(i, j, k)`: all of
/// them, or, where `distributed`, the blocks this rank owns and their halo to `haloDepth` cells
/// (sparse_grid/block_order.h: blocks cut by active cells, every rank computing the same cut),
/// whose owners go to the problem (assignOwners). No rank visits more than counting the others' cells.
template <int Dim>
struct RankCells {
  openvdb::MaskTree mask;
  std::map<std::array<int, 3>, int> ownerOfBlock;  ///< by block origin; empty: a whole problem
  int rank = 0;
};
template <int Dim, class InLayout>
RankCells<Dim> rankCells(int lo, int hi, InLayout inLayout, bool distributed, int rank, int ranks, int haloDepth = 1) {
  constexpr int W = sparse_grid::BlockLayout<Dim>::kWidth;
  const int kLo = Dim == 3 ? lo : 0, kHi = Dim == 3 ? hi : 1, kStep = Dim == 3 ? W : 1;
  const int first = lo - ((lo % W) + W) % W;  // the block origin at or below lo
  const int kFirst = Dim == 3 ? first : 0;
  RankCells<Dim> out;
  out.rank = rank;
  // fn(i, j, k) over the case's cells of the block at (bi, bj, bk)
  auto forBlockCells = [&](int bi, int bj, int bk, auto&& fn) {
    for (int k = std::max(bk, kLo); k < std::min(bk + kStep, kHi); ++k)
      for (int j = std::max(bj, lo); j < std::min(bj + W, hi); ++j)
        for (int i = std::max(bi, lo); i < std::min(bi + W, hi); ++i)
          if (inLayout(i, j, k)) fn(i, j, k);
  };
  auto addBlockCells = [&](int bi, int bj, int bk) {
    forBlockCells(bi, bj, bk, [&](int i, int j, int k) { out.mask.setValueOn(cellCoord<Dim>(i, j, k)); });
  };
  if (!distributed) {
    for (int bk = kFirst; bk < kHi; bk += kStep)
      for (int bj = first; bj < hi; bj += W)
        for (int bi = first; bi < hi; bi += W) addBlockCells(bi, bj, bk);
    return out;
  }
  std::vector<openvdb::Coord> origins;
  std::vector<std::size_t> cells;
  for (int bk = kFirst; bk < kHi; bk += kStep)
    for (int bj = first; bj < hi; bj += W)
      for (int bi = first; bi < hi; bi += W) {
        std::size_t count = 0;
        forBlockCells(bi, bj, bk, [&](int, int, int) { ++count; });
        if (count == 0) continue;
        origins.push_back(cellCoord<Dim>(bi, bj, bk));
        cells.push_back(count);
      }
  const std::vector<int> owner = sparse_grid::blockOwners<Dim>(origins, cells, ranks);
  const std::vector<std::uint8_t> halo = sparse_grid::haloBlocks<Dim>(origins, owner, rank, W, haloDepth);
  for (std::size_t b = 0; b < origins.size(); ++b) {
    if (owner[b] != rank && !halo[b]) continue;
    out.ownerOfBlock[{origins[b][0], origins[b][1], origins[b][2]}] = owner[b];
    addBlockCells(origins[b][0], origins[b][1], origins[b][2]);
  }
  return out;
}

/// The owners of the problem's blocks from the cells it was built on (nothing for a whole problem).
template <int Dim>
void assignOwners(solver::StaggeredProblem<Dim>& prob, const RankCells<Dim>& cells) {
  if (cells.ownerOfBlock.empty()) return;
  const sparse_grid::BlockLayout<Dim>& L = *prob.layout;
  prob.rank = cells.rank;
  prob.blockOwner.resize(L.numBlocks());
  for (std::size_t b = 0; b < L.numBlocks(); ++b)
    prob.blockOwner[b] = cells.ownerOfBlock.at({L.blockOrigin(b)[0], L.blockOrigin(b)[1], L.blockOrigin(b)[2]});
}

}  // namespace stokes::analytic::detail
