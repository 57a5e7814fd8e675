#pragma once
// What every analytic case shares (analytic_cases.cpp defines the functions): the step options
// its AnalyticOptions ask for, its problem, its report, and the kinetic energy of a face field.
#include <cmath>

#include "analytic/analytic_cases.h"

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

/// sum over faces of rho W_m u^2 dV / 2 (W_m = W_F max(W_L, min)) on faces with W_F W_L > 0.
template <int Dim>
double kineticEnergy(const solver::StaggeredProblem<Dim>& prob, const solver::Vector& u) {
  const double dV = std::pow(prob.layout->dx(), Dim);
  double e = 0.0;
  for (std::size_t i = 0; i < u.size(); ++i) {
    const double w = prob.fluidFaceWeight(i) * prob.liquidFace[i];
    if (w > 0.0) e += 0.5 * prob.rho * w * u[i] * u[i] * dV;
  }
  return e;
}

}  // namespace stokes::analytic::detail
