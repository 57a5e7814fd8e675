#pragma once
// What a step's report says about it: the one-line summary, the first non-finite row or face named
// by its cell or tile, and the name of the system that ran (StepReport::diagnostics, ::solver).
#include <cmath>
#include <cstdio>
#include <string>
#include <type_traits>

#include "solver/step/step_options.h"
#include "solver/systems/pressure_stress_system.h"
#include "solver/systems/pressure_velocity_system.h"
#include "solver/systems/viscosity_system.h"

namespace stokes::solver {
inline namespace step {

namespace detail {

inline std::string cellName(const sparse_grid::Coord& c) {
  return "cell (" + std::to_string(c.x()) + "," + std::to_string(c.y()) + "," + std::to_string(c.z()) + ")";
}

/// Names row `row` of `sys`: its unknown kind and its cell, or its tile. Layouts: pressure-stress
/// [p | tau], viscosity [u_C | v_R], pressure-velocity [u_C | v_R | p | l_r] (every block
/// numSlots long except v_R, one block of dofs per tile, and l_r, one row per rigid stress sample).
template <int Dim, class System>
std::string describeRow(const StaggeredProblem<Dim>& prob, const System& sys, const ReducedTiles<Dim>* tiles,
                        std::size_t row) {
  const std::size_t n = prob.slots();
  auto at = [&](std::size_t slot) { return cellName(prob.layout->cellOf(slot)); };
  if constexpr (std::is_same_v<System, PressureStressSystem<Dim>>) {
    if (row < n) return "pressure row of " + at(row);
    return "stress channel " + std::to_string((row - n) / n) + " row of " + at(row % n);
  } else {
    if (row < Dim * n) return "velocity row on face axis " + std::to_string(row / n) + " of " + at(row % n);
    const std::size_t tileDofs = tiles ? tiles->totalDofs() : 0;
    if (row < Dim * n + tileDofs) {
      const std::size_t t = (row - Dim * n) / std::size_t(tiles->dofsPerTile());
      return "tile " + std::to_string(t) + " (" + std::to_string(tiles->tiling().tiles[t].cells.size()) + " cells)";
    }
    if (row < Dim * n + tileDofs + n) return "pressure row of " + at(row - Dim * n - tileDofs);
    if constexpr (std::is_same_v<System, PressureVelocitySystem<Dim>>) {
      const std::size_t i = sys.rigidSample(row - sys.rigidOffset());
      return "rigid stress channel " + std::to_string(i / n) + " row of " + at(i % n);
    }
    return "row " + std::to_string(row);
  }
}

/// After a NonFinite solve: the first non-finite entry of the right-hand side, else of A x (the
/// Krylov layer keeps x finite), named by describeRow; "" if both are finite.
template <int Dim, class System>
std::string locateNonFinite(const StaggeredProblem<Dim>& prob, const System& sys, const ReducedTiles<Dim>* tiles,
                            const Vector& x) {
  auto firstNonFinite = [](const Vector& v) {
    for (std::size_t i = 0; i < v.size(); ++i)
      if (!std::isfinite(v[i])) return std::ptrdiff_t(i);
    return std::ptrdiff_t(-1);
  };
  std::ptrdiff_t i = firstNonFinite(sys.rhs());
  if (i >= 0) return "non-finite right-hand side at the " + describeRow<Dim, System>(prob, sys, tiles, std::size_t(i));
  Vector y(sys.size());
  sys.apply(x.data(), y.data());
  i = firstNonFinite(y);
  if (i >= 0) return "non-finite operator output at the " + describeRow<Dim, System>(prob, sys, tiles, std::size_t(i));
  return "";
}


/// The system and form a solve ran on, for StepReport::solver.
template <int Dim, class System>
const char* systemName(const System& sys) {
  if constexpr (std::is_same_v<System, PressureVelocitySystem<Dim>>) return "unified Stokes pressure-velocity";
  else if constexpr (std::is_same_v<System, ViscositySystem<Dim>>) return "viscosity";
  else return sys.withStress() ? "unified Stokes pressure-stress" : "pressure projection";
}

inline std::string modelName(const StepOptions& opt) {
  if (!opt.reduced) return "uniform";
  return opt.reduced->order == PolynomialOrder::Affine ? "affine" : "quadratic";
}

/// "<system> <model>: <status> after <k> iterations, relative residual <r>"
inline std::string stepSummary(const StepOptions& opt, const StepReport& rep) {
  char line[160];
  std::snprintf(line, sizeof line, "%s %s: %s after %d iterations, relative residual %.3g", toString(opt.system),
                modelName(opt).c_str(), toString(rep.solve.status), rep.solve.iterations, rep.solve.relativeResidual);
  return line;
}

/// Marks the report NonFinite, naming the first face with a non-finite velocity, if there is one.
template <int Dim>
void checkFiniteVelocities(const StaggeredProblem<Dim>& prob, const Vector& u, StepReport& rep) {
  const std::size_t n = prob.slots();
  for (std::size_t i = 0; i < u.size(); ++i) {
    if (std::isfinite(u[i])) continue;
    rep.solve.status = Status::NonFinite;
    const std::string where = "non-finite velocity on face axis " + std::to_string(i / n) + " of " +
                              cellName(prob.layout->cellOf(i % n));
    rep.diagnostics = rep.diagnostics.empty() ? where : rep.diagnostics + "; " + where;
    return;
  }
}

}  // namespace detail

}  // namespace step
}  // namespace stokes::solver
