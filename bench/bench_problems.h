#pragma once
// Deterministic problem set-ups for the operator benchmarks, rebuilt from the public building
// blocks exactly as analytic/analytic_cases.cpp builds its cases (same masks, weights, u*):
//
//   disk  2D free-surface Stokes disk (radius 0.75, thesis 5.4): cells within 4 dx of the liquid,
//         volume-fraction weights from the level set, u* = the exact start velocity.
//   ball  3D liquid ball, radius 0.3 centred in the unit box, free surface only (no solids):
//         cells within 3 dx of the liquid, u* = swirl + one gravity step.
//
// A BenchProblem owns its layout; StaggeredProblem points at it, so it is neither copied nor moved
// (hand it around by unique_ptr).
#include <cmath>
#include <memory>
#include <numbers>

#include "analytic/disk_stokes_solution.h"
#include "solver/problem/staggered_problem.h"
#include "sparse_grid/block_layout.h"
#include "sparse_grid/volume_weights.h"

namespace stokes::bench {

using sparse_grid::BlockLayout;
using sparse_grid::Coord;
using sparse_grid::StressChannels;
using sparse_grid::Vec3d;

template <int Dim>
struct BenchProblem {
  BlockLayout<Dim> layout;
  solver::StaggeredProblem<Dim> prob;

  BenchProblem(const openvdb::MaskTree& mask, double dx) : layout(mask, dx) { prob.layout = &layout; }
  BenchProblem(const BenchProblem&) = delete;
  BenchProblem& operator=(const BenchProblem&) = delete;
};

/// The disk-stokes case at N cells per unit length (rho = dt = 1).
inline std::unique_ptr<BenchProblem<2>> buildDiskProblem(int N, double mu) {
  const double dx = 1.0 / N;
  const analytic::DiskStokesSolution exact(mu);
  auto phi = [&](const Vec3d& x) { return exact.levelSet(x); };

  openvdb::MaskTree mask;  // cells whose centre lies within 4 cells of the liquid
  const int extent = int(std::ceil((analytic::DiskStokesSolution::kRadius + 5 * dx) / dx));
  for (int j = -extent; j < extent; ++j)
    for (int i = -extent; i < extent; ++i)
      if (phi(Vec3d((i + 0.5) * dx, (j + 0.5) * dx, 0.0)) < 4.0 * dx) mask.setValueOn(Coord(i, j, 0));

  auto p = std::make_unique<BenchProblem<2>>(mask, dx);
  solver::StaggeredProblem<2>& prob = p->prob;
  prob.rho = 1.0;
  prob.mu = mu;
  prob.dt = 1.0;
  prob.allocate(/*withSolids=*/false);
  solver::fillLiquidWeights(prob, phi);
  const std::size_t n = p->layout.numSlots();
  for (int a = 0; a < 2; ++a)
    sparse_grid::sampleField<2>(p->layout, sparse_grid::faceMask(a),
                         [&](const Vec3d& x) { return exact.startVelocity(x, a, prob.rho, prob.dt); },
                         prob.uStar.data() + a * n);
  return p;
}

/// The liquid ball (radius 0.3, centre (0.5, 0.5, 0.5), free surface only) at n cells per unit
/// length (rho = dt = 1).
inline std::unique_ptr<BenchProblem<3>> buildBallProblem(int N, double mu) {
  const double dx = 1.0 / N;
  const Vec3d centre(0.5, 0.5, 0.5);
  const double radius = 0.3;
  auto phi = [&](const Vec3d& x) { return (x - centre).length() - radius; };

  openvdb::MaskTree mask;  // cells whose centre lies within 3 cells of the liquid
  for (int k = 0; k < N; ++k)
    for (int j = 0; j < N; ++j)
      for (int i = 0; i < N; ++i)
        if (phi(Vec3d((i + 0.5) * dx, (j + 0.5) * dx, (k + 0.5) * dx)) < 3.0 * dx) mask.setValueOn(Coord(i, j, k));

  auto p = std::make_unique<BenchProblem<3>>(mask, dx);
  solver::StaggeredProblem<3>& prob = p->prob;
  prob.rho = 1.0;
  prob.mu = mu;
  prob.dt = 1.0;
  prob.allocate(/*withSolids=*/false);
  solver::fillLiquidWeights(prob, phi);
  const std::size_t n = p->layout.numSlots();
  const double twoPi = 2.0 * std::numbers::pi;
  for (int a = 0; a < 3; ++a)
    sparse_grid::sampleField<3>(p->layout, sparse_grid::faceMask(a),
                         [&](const Vec3d& x) {
                           const double swirl = 0.5 * std::sin(twoPi * x[(a + 1) % 3]);
                           return swirl - (a == 2 ? 9.81 * prob.dt : 0.0);
                         },
                         prob.uStar.data() + a * n);
  return p;
}

}  // namespace stokes::bench
