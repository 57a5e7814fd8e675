#pragma once
// A small problem with every kind of boundary: a liquid blob with a free surface, partly inside a
// solid floor and around a solid sphere, fractional weights along both, and a random u*.
#include "sparse_grid/vdb_trees.h"

#include <random>

#include "solver/problem/staggered_problem.h"
#include "sparse_grid/volume_weights.h"

namespace stokes::test {

using sparse_grid::StressChannels;
using sparse_grid::Vec3d;
using solver::StaggeredProblem;

/// A liquid blob (free surface) partly inside a solid floor and around a solid sphere, with
/// fractional weights everywhere along both boundaries, and a random u*.
template <int Dim>
struct MixedBoundaryProblem {
  sparse_grid::BlockLayout<Dim> layout;
  StaggeredProblem<Dim> prob;

  explicit MixedBoundaryProblem(int n, unsigned seed = 3) {
    const double dx = 1.0 / n;
    openvdb::MaskTree mask;
    sparse_grid::activateBox(mask, openvdb::Coord(0), Dim == 3 ? openvdb::Coord(n - 1) : openvdb::Coord(n - 1, n - 1, 0));
    layout = sparse_grid::BlockLayout<Dim>(mask, dx);
    prob.layout = &layout;
    prob.rho = 2.0;
    prob.mu = 0.7;
    prob.dt = 0.05;
    prob.allocate(/*withSolids=*/true);
    const Vec3d c(0.5, 0.43, 0.5), sc(0.62, 0.55, 0.5);
    auto liquid = [&](const Vec3d& x) {
      Vec3d d = x - c;
      if (Dim == 2) d[2] = 0.0;
      return d.length() - 0.31;
    };
    auto solid = [&](const Vec3d& x) {  // phi < 0 inside the solid
      Vec3d d = x - sc;
      if (Dim == 2) d[2] = 0.0;
      return std::min(x[1] - 0.2, d.length() - 0.09);
    };
    const std::size_t ns = layout.numSlots();
    for (int a = 0; a < Dim; ++a) {
      sparse_grid::computeVolumeFractions<Dim>(layout, sparse_grid::faceMask(a), liquid, prob.liquidFace.data() + a * ns);
      sparse_grid::computeVolumeFractions<Dim>(layout, sparse_grid::faceMask(a), solid, prob.fluidFace.data() + a * ns);
    }
    sparse_grid::computeVolumeFractions<Dim>(layout, sparse_grid::kCellCentre, liquid, prob.liquidCell.data());
    for (int ch = 0; ch < StressChannels<Dim>::kCount; ++ch) {
      sparse_grid::computeVolumeFractions<Dim>(layout, StressChannels<Dim>::mask(ch), liquid, prob.liquidStress.data() + ch * ns);
      sparse_grid::computeVolumeFractions<Dim>(layout, StressChannels<Dim>::mask(ch), solid, prob.fluidStress.data() + ch * ns);
    }
    // The fractions above are of the solid; W_F is the non-solid fraction.
    for (auto& w : prob.fluidFace) w = 1.0 - w;
    for (auto& w : prob.fluidStress) w = 1.0 - w;
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (auto& v : prob.uStar) v = u(rng);
  }
};

}  // namespace stokes::test
