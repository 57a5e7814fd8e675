#pragma once
// Problems for the hard-case suite (tests/solver/test_hard_cases.cpp): a unit box of n^Dim
// cells, liquid and solid given by level sets (phi < 0 inside), volume weights from sub-sample
// counts, and a smooth swirling u*. Each builder states which hard feature it produces.
#include "sparse_grid/vdb_trees.h"

#include <cmath>
#include <functional>
#include <numbers>

#include "solver/problem/staggered_problem.h"
#include "sparse_grid/volume_weights.h"

namespace stokes::test {

using sparse_grid::StressChannels;
using sparse_grid::Vec3d;
using solver::StaggeredProblem;

using LevelSet = std::function<double(const Vec3d&)>;

/// Euclidean distance in the first Dim coordinates.
template <int Dim>
double distance(const Vec3d& x, const Vec3d& c) {
  double s = 0.0;
  for (int a = 0; a < Dim; ++a) s += (x[a] - c[a]) * (x[a] - c[a]);
  return std::sqrt(s);
}

/// Signed distance (Chebyshev) to the axis-aligned box [lo, hi] in the first Dim coordinates.
template <int Dim>
double boxLevelSet(const Vec3d& x, const Vec3d& lo, const Vec3d& hi) {
  double d = -1e300;
  for (int a = 0; a < Dim; ++a) d = std::max(d, std::max(lo[a] - x[a], x[a] - hi[a]));
  return d;
}

struct HardProblemSpec {
  int n = 32;            ///< cells per unit length; active cells [0, n)^Dim
  LevelSet liquid;       ///< phi_L < 0 in the liquid
  LevelSet solid;        ///< phi_S < 0 in the solid; empty: no solids
  int solidSubsamples = 3;  ///< 1: point-sampled (binary) W_F, for walls that close exactly
  double rho = 1.0, mu = 1.0, dt = 0.1;
  sparse_grid::FractionRule liquidRule = sparse_grid::kLiquidFractionRule;  ///< how W_L is measured
};

/// The hard case's problem: layout, weights (W_L from phi_L, W_F = 1 - solid fraction) and
/// u*_a(x) = sin(2 pi x_{a+1} + a) cos(pi x_a) + 0.3 (smooth, divergent, non-zero mean).
template <int Dim>
struct HardProblem {
  sparse_grid::BlockLayout<Dim> layout;
  StaggeredProblem<Dim> prob;

  explicit HardProblem(const HardProblemSpec& spec) {
    const int n = spec.n;
    openvdb::MaskTree mask;
    sparse_grid::activateBox(mask, openvdb::Coord(0), Dim == 3 ? openvdb::Coord(n - 1) : openvdb::Coord(n - 1, n - 1, 0));
    layout = sparse_grid::BlockLayout<Dim>(mask, 1.0 / n);
    prob.layout = &layout;
    prob.rho = spec.rho;
    prob.mu = spec.mu;
    prob.dt = spec.dt;
    prob.allocate(/*withSolids=*/bool(spec.solid));
    solver::fillLiquidWeights(prob, spec.liquid, spec.liquidRule);
    const std::size_t ns = layout.numSlots();
    if (spec.solid) {
      for (int a = 0; a < Dim; ++a)
        sparse_grid::computeVolumeFractions<Dim>(layout, sparse_grid::faceMask(a), spec.solid, prob.fluidFace.data() + a * ns,
                                          spec.solidSubsamples);
      for (int c = 0; c < StressChannels<Dim>::kCount; ++c)
        sparse_grid::computeVolumeFractions<Dim>(layout, StressChannels<Dim>::mask(c), spec.solid,
                                          prob.fluidStress.data() + c * ns, spec.solidSubsamples);
      for (auto& w : prob.fluidFace) w = 1.0 - w;  // fractions above are of the solid
      for (auto& w : prob.fluidStress) w = 1.0 - w;
    }
    const double twoPi = 2.0 * std::numbers::pi;
    for (int a = 0; a < Dim; ++a)
      sparse_grid::sampleField<Dim>(layout, sparse_grid::faceMask(a),
                             [&](const Vec3d& x) {
                               return std::sin(twoPi * x[(a + 1) % Dim] + a) * std::cos(std::numbers::pi * x[a]) + 0.3;
                             },
                             prob.uStar.data() + a * ns);
  }
  HardProblem(const HardProblem&) = delete;
  HardProblem& operator=(const HardProblem&) = delete;
};

}  // namespace stokes::test
