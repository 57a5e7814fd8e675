#pragma once
// Small fixtures shared by the tests: random sparse layouts and random weights.
#include "sparse_grid/vdb_trees.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "solver/krylov/aligned_vector.h"
#include "solver/problem/staggered_problem.h"
#include "sparse_grid/block_layout.h"
#include "sparse_grid/volume_weights.h"

namespace stokes::test {

/// A sparse, irregular layout: cells inside a blob of radius ~ extent/2 plus a detached box, so
/// that blocks have missing neighbours on every side.
template <int Dim>
sparse_grid::BlockLayout<Dim> irregularLayout(int extent, double dx, unsigned seed = 7) {
  openvdb::MaskTree mask;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-1.5, 1.5);
  const int kLo = Dim == 3 ? 0 : 0, kHi = Dim == 3 ? extent - 1 : 0;
  const double c = 0.5 * extent;
  for (int k = kLo; k <= kHi; ++k)
    for (int j = 0; j < extent; ++j)
      for (int i = 0; i < extent; ++i) {
        double r2 = (i - c) * (i - c) + (j - c) * (j - c) + (Dim == 3 ? (k - c) * (k - c) : 0.0);
        if (std::sqrt(r2) < 0.45 * extent + jitter(rng)) mask.setValueOn(openvdb::Coord(i, j, k));
      }
  const int o = extent + 9;  // a detached box, one block away
  for (int k = kLo; k <= (Dim == 3 ? 4 : 0); ++k)
    for (int j = 0; j < 5; ++j)
      for (int i = o; i < o + 5; ++i) mask.setValueOn(openvdb::Coord(i, j, k));
  return sparse_grid::BlockLayout<Dim>(mask, dx);
}

/// Uniform random values in [lo, hi), zero on slots outside the layout's active cells.
template <int Dim>
solver::Vector randomChannels(const sparse_grid::BlockLayout<Dim>& layout, int channels, std::mt19937_64& rng,
                              double lo = -1.0, double hi = 1.0) {
  std::uniform_real_distribution<double> u(lo, hi);
  const std::size_t n = layout.numSlots();
  solver::Vector v(channels * n, 0.0);
  for (int c = 0; c < channels; ++c)
    for (std::size_t s = 0; s < n; ++s)
      if (layout.isActiveCell(s)) v[c * n + s] = u(rng);
  return v;
}

inline double dotProduct(const solver::Vector& a, const solver::Vector& b) {
  long double s = 0.0L;
  for (std::size_t i = 0; i < a.size(); ++i) s += (long double)a[i] * b[i];
  return double(s);
}

/// <x, A y> = <A x, y> on random vectors (zero on inactive rows), <x, A x> > 0 when `positive`,
/// and diagonal() equal to e_i^T A e_i on sampled rows when `exactDiagonal`.
template <class System>
void expectSymmetricPositive(const System& sys, unsigned seed, bool positive = true, bool exactDiagonal = true) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto& d = sys.diagonal();
  solver::Vector x(sys.size()), y(sys.size()), Ax(sys.size()), Ay(sys.size());
  for (std::size_t i = 0; i < x.size(); ++i) {
    x[i] = d[i] > 0.0 ? u(rng) : 0.0;
    y[i] = d[i] > 0.0 ? u(rng) : 0.0;
  }
  sys.apply(x.data(), Ax.data());
  sys.apply(y.data(), Ay.data());
  const double xAy = dotProduct(x, Ay), yAx = dotProduct(y, Ax);
  EXPECT_NEAR(xAy, yAx, 1e-12 * (std::abs(xAy) + std::abs(dotProduct(x, Ax))));
  if (positive) {
    EXPECT_GT(dotProduct(x, Ax), 0.0);
    EXPECT_GT(dotProduct(y, Ay), 0.0);
  }
  if (!exactDiagonal) return;
  // The Jacobi diagonal is the operator's diagonal: e_i^T A e_i for a few rows.
  int checked = 0;
  for (std::size_t i = 0; i < x.size() && checked < 20; i += x.size() / 97 + 1) {
    if (!(d[i] > 0.0)) continue;
    solver::Vector e(sys.size(), 0.0), Ae(sys.size());
    e[i] = 1.0;
    sys.apply(e.data(), Ae.data());
    EXPECT_NEAR(Ae[i], d[i], 1e-12 * d[i]);
    ++checked;
  }
  EXPECT_GT(checked, 5);
}

/// A liquid layer (free surface at y = level; above 1: a full, closed container) resting in a closed box whose walls are closed faces
/// (StaggeredProblem::closedFace, the simulator's domain walls: no W_F), with a random u*.
template <int Dim>
struct WalledLayerProblem {
  sparse_grid::BlockLayout<Dim> layout;
  solver::StaggeredProblem<Dim> prob;
  explicit WalledLayerProblem(int n, double level = 0.45) {
    openvdb::MaskTree mask;
    sparse_grid::activateBox(mask, openvdb::Coord(0), Dim == 3 ? openvdb::Coord(n - 1) : openvdb::Coord(n - 1, n - 1, 0));
    layout = sparse_grid::BlockLayout<Dim>(mask, 1.0 / n);
    prob.layout = &layout;
    prob.rho = 1.0;
    prob.mu = 0.5;
    prob.dt = 0.05;
    prob.allocate(/*withSolids=*/false);
    auto liquid = [level](const sparse_grid::Vec3d& x) { return x[1] - level; };
    const std::size_t ns = layout.numSlots();
    for (int a = 0; a < Dim; ++a)
      sparse_grid::computeVolumeFractions<Dim>(layout, sparse_grid::faceMask(a), liquid, prob.liquidFace.data() + a * ns);
    sparse_grid::computeVolumeFractions<Dim>(layout, sparse_grid::kCellCentre, liquid, prob.liquidCell.data());
    for (int ch = 0; ch < sparse_grid::StressChannels<Dim>::kCount; ++ch)
      sparse_grid::computeVolumeFractions<Dim>(layout, sparse_grid::StressChannels<Dim>::mask(ch), liquid, prob.liquidStress.data() + ch * ns);
    prob.closedFace.assign(Dim * ns, 0);
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (std::size_t s = 0; s < ns; ++s)
      for (int a = 0; a < Dim; ++a) {
        const std::size_t i = a * ns + s;
        prob.closedFace[i] = layout.cellOf(s)[a] == 0 ? 1 : 0;  // the lower walls (upper ones: absent faces)
        prob.uStar[i] = prob.closedFace[i] ? 0.0 : u(rng);
      }
  }
};

/// max_i |a_i - b_i| / max_i |b_i| (or the plain difference where b is zero): how far two solvers'
/// velocities are apart, relative to the motion.
template <class A, class B>
double relativeMaxDifference(const A& a, const B& b) {
  EXPECT_EQ(a.size(), b.size());
  double d = 0.0, scale = 0.0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) {
    d = std::max(d, std::abs(a[i] - b[i]));
    scale = std::max(scale, std::abs(b[i]));
  }
  return scale > 0.0 ? d / scale : d;
}

}  // namespace stokes::test
