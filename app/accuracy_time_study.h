#pragma once
// `stokesvdb study accuracy-time`: what accuracy costs in time (thesis Fig. 5.8 / 5.9).
#include <string>

namespace stokes::app {

struct AccuracyTimeOptions {
  std::string outDir = "bench/results";
  int maxN = 128;     ///< largest 2D resolution (powers of two from 16)
  int maxN3d = 64;    ///< largest 3D resolution
  std::string solver = "strong";  ///< strong (solver::planSolve, solver/step/solve_plan.h) | jacobi (Jacobi CG on the SPD form)
  bool plots = true;  ///< render PNGs with gnuplot when it is installed
};

/// Runs uniform, affine and quadratic over N and several tile/pad settings on the box-viscosity
/// (2D and 3D) and disk-stokes cases; writes accuracy_time.csv and, with gnuplot, error-vs-time
/// and error-vs-N PNGs per case into outDir. Returns 0 on success.
int runAccuracyTimeStudy(const AccuracyTimeOptions& opt);

}  // namespace stokes::app
