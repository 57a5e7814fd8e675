#include "analytic/analytic_cases.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <numbers>
#include <optional>
#include <stdexcept>

#include "analytic/case_setup.h"
#include "analytic/disk_stokes_solution.h"
#include "kernels/staggered_stencils.h"
#include "sparse_grid/volume_weights.h"
#include "solver/krylov/stopwatch.h"

namespace stokes::analytic {

using sparse_grid::BlockLayout;
using sparse_grid::Coord;
using sparse_grid::StressChannels;
using sparse_grid::Vec3d;
using solver::StaggeredProblem;
using solver::Vector;

namespace {

std::optional<solver::ReducedOptions> reducedOptions(const AnalyticOptions& o, solver::SystemKind kind) {
  if (o.model == "uniform") return std::nullopt;
  solver::ReducedOptions r;
  if (o.model == "affine") r.order = solver::PolynomialOrder::Affine;
  else if (o.model == "quadratic") r.order = solver::PolynomialOrder::Quadratic;
  else throw std::invalid_argument("unknown model '" + o.model + "' (uniform, affine or quadratic)");
  const bool viscosityOnly = kind == solver::SystemKind::Viscosity;
  if (o.family == "auto") r.family = viscosityOnly ? solver::BasisFamily::Full : solver::BasisFamily::DivergenceFree;
  else if (o.family == "full") r.family = solver::BasisFamily::Full;
  else if (o.family == "divfree") r.family = solver::BasisFamily::DivergenceFree;
  else throw std::invalid_argument("unknown basis family '" + o.family + "' (auto, divfree or full)");
  // auto: quadratic fits use every tile face (the full quadratic fit on boundary faces alone is
  // singular; the divergence-free one is 2-4x less accurate on the disk), affine the boundary.
  if (o.fit == "auto") r.fitAllFaces = r.order == solver::PolynomialOrder::Quadratic;
  else if (o.fit == "all" || o.fit == "boundary") r.fitAllFaces = o.fit == "all";
  else throw std::invalid_argument("unknown fit '" + o.fit + "' (auto, boundary or all)");
  r.tiling.tileSize = o.tileSize;
  r.tiling.padding = o.padding;
  r.tiling.bandAir = o.bandAir;
  r.tiling.bandSolid = o.bandSolid;
  r.tiling.minRegion = o.minRegion;
  r.tiling.minTileSize = o.minTileSize;
  r.tileAccuracy = o.tileAccuracy;
  if (o.tileCache == "none") r.cache = solver::TileCacheStrategy::None;
  else if (o.tileCache == "library") r.cache = solver::TileCacheStrategy::Library;
  else if (o.tileCache == "shapes") r.cache = solver::TileCacheStrategy::Shapes;
  else throw std::invalid_argument("unknown tile cache '" + o.tileCache + "' (none, library or shapes)");
  return r;
}

}  // namespace

namespace detail {

solver::StepOptions stepOptions(const AnalyticOptions& o, solver::SystemKind kind) {
  solver::StepOptions s;
  s.reduced = reducedOptions(o, kind);
  s.system = kind;
  solver::SolveRequest request;
  request.system = kind;
  request.reducedTiles = s.reduced.has_value();
  request.preconditioner = o.preconditioner;
  request.form = o.form;
  request.method = o.method;
  request.tileRule = o.tileRule;
  request.backend = o.backend;
  solver::applyPlan(solver::planSolve(request), s);
  s.rows = o.rows;
  s.rowStencils = o.rowStencils;
  s.multigrid.smootherDegree = o.multigridDegree;
  s.multigrid.smootherRange = o.multigridRange;
  s.multigrid.pressureSchur = o.multigridSchur;
  s.multigrid.interpolation = o.multigridInterpolation;
  s.krylov.relativeTolerance = o.tolerance;
  s.krylov.maxIterations = o.maxIterations;
  return s;
}

bool fillReport(AnalyticResult& r, const solver::StepReport& rep, const AnalyticOptions& o, const Vector& u) {
  if (o.keepVelocities) r.velocities.assign(u.begin(), u.end());
  r.tiles = rep.tiles;
  r.fallbackTiles = rep.fallbackTiles;
  r.partialTiles = rep.partialTiles;
  r.unpaidTiles = rep.unpaidTiles;
  r.tileRule = rep.tileRule;
  r.tileWorkSaved = rep.tileWorkSaved;
  r.tileWorkOverhead = rep.tileWorkOverhead;
  r.tilesByEdge = rep.tilesByEdge;
  r.cacheHits = rep.cacheHits;
  r.cacheMisses = rep.cacheMisses;
  r.reducedDofs = rep.reducedDofs;
  r.cartesianDofs = rep.cartesianDofs;
  r.reconstructionLinf = rep.reconstructionLinf;
  r.tileSeconds = rep.tileSeconds;
  r.iterations = rep.solve.iterations;
  r.unknowns = rep.unknowns;
  r.paddedRows = rep.paddedRows;
  r.krylovRows = rep.krylovRows;
  r.status = solver::toString(rep.solve.status);
  r.relativeResidual = rep.solve.relativeResidual;
  r.setupSeconds = rep.setupSeconds;
  r.solveSeconds = rep.solveSeconds;
  r.preconditionerSeconds = rep.preconditionerSeconds;
  r.multigridLevels = rep.multigridLevels;
  r.schurBlock = rep.schurBlock;
  r.solver = rep.solver;
  const solver::Status st = rep.solve.status;
  r.measured = !u.empty() && (st == solver::Status::Converged || st == solver::Status::MaxIterations);
  return r.measured;
}

AnalyticResult makeResult(const char* test, const AnalyticOptions& o) {
  AnalyticResult r;
  r.test = test;
  r.model = o.model;
  r.dim = o.dim;
  r.n = o.n;
  r.mu = o.mu;
  r.rho = o.rho;
  r.dt = o.dt;
  return r;
}

}  // namespace detail

namespace {

using detail::cellCoord;
using detail::fillReport;
using detail::kineticEnergy;
using detail::makeResult;
using detail::stepOptions;

// ---- box viscosity (thesis 5.3), any dimension -------------------------------------------------

/// prod_c sin x_c, and its mixed derivative d^2/(dx_a dx_b) for a != b.
template <int Dim>
double sineProduct(const Vec3d& x) {
  double s = 1.0;
  for (int c = 0; c < Dim; ++c) s *= std::sin(x[c]);
  return s;
}
template <int Dim>
double sineProductMixed(const Vec3d& x, int a, int b) {
  double s = std::cos(x[a]) * std::cos(x[b]);
  for (int c = 0; c < Dim; ++c)
    if (c != a && c != b) s *= std::sin(x[c]);
  return s;
}

template <int Dim>
AnalyticResult boxViscosity(const AnalyticOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  const int N = o.n;
  const double pi = std::numbers::pi, dx = pi / N, eps = 1e-9 * dx;
  openvdb::MaskTree mask;
  sparse_grid::activateBox(mask, cellCoord<Dim>(-1, -1, -1), cellCoord<Dim>(N, N, N));
  const BlockLayout<Dim> layout(mask, dx);

  StaggeredProblem<Dim> prob = detail::makeProblem(layout, o, /*withSolids=*/true);
  auto inside = [&](const Vec3d& x, bool closed) {
    for (int a = 0; a < Dim; ++a) {
      if (closed ? (x[a] < -eps || x[a] > pi + eps) : (x[a] < eps || x[a] > pi - eps)) return false;
    }
    return true;
  };
  const std::size_t n = layout.numSlots();
  // u* = u - dt mu/rho (lap u + grad div u), u_a = s:  u*_a = s + dt mu/rho ((Dim+1) s - sum_{b!=a} s_ab)
  const double k = o.dt * o.mu / o.rho;
  for (std::size_t s = 0; s < n; ++s) {
    for (int a = 0; a < Dim; ++a) {
      const Vec3d x = layout.samplePosition(s, sparse_grid::faceMask(a));
      const std::size_t i = a * n + s;
      double mixed = 0.0;
      for (int b = 0; b < Dim; ++b)
        if (b != a) mixed += sineProductMixed<Dim>(x, a, b);
      prob.liquidFace[i] = 1.0;
      prob.fluidFace[i] = inside(x, /*closed=*/false) ? 1.0 : 0.0;
      prob.uSolid[i] = sineProduct<Dim>(x);
      prob.uStar[i] = (1.0 + (Dim + 1) * k) * sineProduct<Dim>(x) - k * mixed;
    }
    prob.liquidCell[s] = inside(layout.samplePosition(s, sparse_grid::kCellCentre), true) ? 1.0 : 0.0;
    for (int c = 0; c < StressChannels<Dim>::kCount; ++c)
      prob.liquidStress[c * n + s] = inside(layout.samplePosition(s, StressChannels<Dim>::mask(c)), true) ? 1.0 : 0.0;
  }

  Vector u;
  const solver::StepReport rep = solver::solveStep(prob, stepOptions(o, solver::SystemKind::Viscosity), u);
  AnalyticResult r = makeResult("box-viscosity", o);
  if (!fillReport(r, rep, o, u)) return r;  // the solve failed (status, diagnostics)
  const double dV = std::pow(dx, Dim);
  for (std::size_t i = 0; i < u.size(); ++i) {
    if (prob.fluidFace[i] <= 0.0) continue;
    const double e = std::abs(u[i] - prob.uSolid[i]);  // uSolid holds the exact field everywhere
    r.L1 += e * dV;
    r.Linf = std::max(r.Linf, e);
  }
  r.kineticEnergyBefore = kineticEnergy(prob, prob.uStar);
  r.kineticEnergyAfter = kineticEnergy(prob, u);
  r.totalSeconds = solver::secondsSince(t0);
  return r;
}

// ---- free-surface Stokes disk (thesis 5.4) ------------------------------------------------------

// Whether the case's problem is built per rank (PETSc backend, rankSetup "own"), on which rank of
// how many, and how deep its halo: a cell for the stencils, or the reach of the reduced tiles that
// each rank builds near its blocks (solver::distributedTileDepth). Cases with adaptive
// tiles (whose split test reads the whole liquid) or with tiles in the pressure-velocity form keep
// the whole problem.
struct RankShare {
  bool distributed = false;
  int rank = 0, ranks = 1;
  int haloDepth = 1;
};
RankShare rankShare(const AnalyticOptions& o) {
  if (o.rankSetup != "own" && o.rankSetup != "whole")
    throw std::invalid_argument("rank set-up must be own or whole, not '" + o.rankSetup + "'");
#ifdef STOKES_HAVE_PETSC
  const std::optional<solver::ReducedOptions> reduced = reducedOptions(o, o.system);
  const bool splitTiles = !reduced || (reduced->tiling.minTileSize == 0 && o.form != solver::StokesForm::PressureVelocity);
  if (o.backend == solver::Backend::Petsc && o.rankSetup == "own" && splitTiles) {
    solver::petsc::Session::initialise({});
    return {true, solver::petsc::rank(), solver::petsc::ranks(), reduced ? solver::distributedTileDepth(reduced->tiling) : 1};
  }
#endif
  return {};
}

AnalyticResult diskStokes(const AnalyticOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  constexpr int Dim = 2;
  const int N = o.n;
  const double dx = 1.0 / N;
  const DiskStokesSolution exact(o.mu);
  auto phi = [&](const Vec3d& x) { return exact.levelSet(x); };

  // Cells whose centre lies within 4 cells of the liquid: all of them, or this rank's blocks and
  // their halo.
  const int extent = int(std::ceil((DiskStokesSolution::kRadius + 5 * dx) / dx));
  const RankShare share = rankShare(o);
  const detail::RankCells<Dim> cells = detail::rankCells<Dim>(
      -extent, extent, [&](int i, int j, int) { return phi(Vec3d((i + 0.5) * dx, (j + 0.5) * dx, 0.0)) < 4.0 * dx; },
      share.distributed, share.rank, share.ranks, share.haloDepth);
  const BlockLayout<Dim> layout(cells.mask, dx);

  StaggeredProblem<Dim> prob = detail::makeProblem(layout, o, /*withSolids=*/false);
  detail::assignOwners(prob, cells);
  solver::fillLiquidWeights(prob, phi, o.liquidWeights.value_or(sparse_grid::kLiquidFractionRule));
  const std::size_t n = layout.numSlots();
  for (int a = 0; a < Dim; ++a)
    sparse_grid::sampleField<Dim>(layout, sparse_grid::faceMask(a),
                           [&](const Vec3d& x) { return exact.startVelocity(x, a, o.rho, o.dt); },
                           prob.uStar.data() + a * n);

  Vector u;
  const solver::StepReport rep = solver::solveStep(prob, stepOptions(o, o.system), u);
  AnalyticResult r = makeResult("disk-stokes", o);
  if (!fillReport(r, rep, o, u)) return r;  // the solve failed (status, diagnostics)
  const double dV = dx * dx;
  for (std::size_t s = 0; s < n; ++s)
    for (int a = 0; a < Dim; ++a) {
      const std::size_t i = a * n + s;
      const Vec3d x = layout.samplePosition(s, sparse_grid::faceMask(a));
      if (!prob.ownsSlot(s) || !DiskStokesSolution::controlVolumeHoldsLiquid(x, dx)) continue;
      const double e = std::abs(u[i] - exact.velocity(x, a));
      r.L1 += e * dV;
      r.Linf = std::max(r.Linf, e);
    }
  r.L1 = solver::sumOverParts(prob, r.L1);
  r.Linf = solver::maxOverParts(prob, r.Linf);
  r.kineticEnergyBefore = kineticEnergy(prob, prob.uStar);
  r.kineticEnergyAfter = kineticEnergy(prob, u);
  r.maxDivergence = maxDivergence(prob, u);
  r.totalSeconds = solver::secondsSince(t0);
  return r;
}

// ---- 3D liquid ball ------------------------------------------------------------------------------

BallStep makeBallStep(const AnalyticOptions& o) {
  if (o.n < 8) throw std::invalid_argument("ball: n must be >= 8");
  constexpr int Dim = 3;
  const int N = o.n;
  const double dx = 1.0 / N;
  const Vec3d centre(0.5, 0.5, o.solids ? 0.42 : 0.5);
  const double radius = 0.3;
  const Vec3d solidCentre(0.5, 0.5, 0.3);
  const double solidRadius = 0.12, floorHeight = 0.15;
  auto phiLiquid = [&](const Vec3d& x) { return (x - centre).length() - radius; };
  // Solid: the floor z < floorHeight and a sphere inside the ball. phi_F < 0 in the fluid region.
  auto phiFluid = [&](const Vec3d& x) {
    return std::min(x[2] - floorHeight, (x - solidCentre).length() - solidRadius);
  };

  // the liquid and a band of 3 cells around it: all of it, or this rank's blocks and their halo
  const RankShare share = rankShare(o);
  const detail::RankCells<Dim> cells = detail::rankCells<Dim>(
      0, N, [&](int i, int j, int k) { return phiLiquid(Vec3d((i + 0.5) * dx, (j + 0.5) * dx, (k + 0.5) * dx)) < 3.0 * dx; },
      share.distributed, share.rank, share.ranks, share.haloDepth);
  BallStep step;
  step.layout = std::make_unique<BlockLayout<Dim>>(cells.mask, dx);
  const BlockLayout<Dim>& layout = *step.layout;
  step.prob = detail::makeProblem(layout, o, o.solids);
  StaggeredProblem<Dim>& prob = step.prob;
  detail::assignOwners(prob, cells);
  solver::fillLiquidWeights(prob, phiLiquid, o.liquidWeights.value_or(sparse_grid::kLiquidFractionRule));
  const std::size_t n = layout.numSlots();
  if (o.solids) {
    // W_F = fraction of the control volume with phi_F > 0, i.e. with -phi_F < 0.
    for (int a = 0; a < Dim; ++a)
      sparse_grid::computeVolumeFractions<Dim>(layout, sparse_grid::faceMask(a), [&](const Vec3d& x) { return -phiFluid(x); },
                                        prob.fluidFace.data() + a * n);
    for (int c = 0; c < StressChannels<Dim>::kCount; ++c)
      sparse_grid::computeVolumeFractions<Dim>(layout, StressChannels<Dim>::mask(c),
                                        [&](const Vec3d& x) { return -phiFluid(x); },
                                        prob.fluidStress.data() + c * n);
  }
  // A swirling, shearing start velocity plus one step of gravity.
  const double twoPi = 2.0 * std::numbers::pi;
  for (int a = 0; a < Dim; ++a)
    sparse_grid::sampleField<Dim>(layout, sparse_grid::faceMask(a),
                           [&](const Vec3d& x) {
                             const double swirl = 0.5 * std::sin(twoPi * x[(a + 1) % 3]);
                             return swirl - (a == 2 ? 9.81 * o.dt : 0.0);
                           },
                           prob.uStar.data() + a * n);

  step.options = stepOptions(o, o.system);
  return step;
}

// One face of the liquid in a faces file: its cell, axis and velocity.
struct FaceRecord {
  std::int32_t cell[3];
  std::int32_t axis;
  double u;
};

// The liquid's faces (W_L > 0) of the blocks this rank owns, in layout order.
template <int Dim>
void writeFaces(const StaggeredProblem<Dim>& prob, const Vector& u, const std::string& path) {
#ifdef STOKES_HAVE_PETSC
  if (solver::petsc::ranks() > 1) throw std::invalid_argument("--faces-out: write the faces from one rank");
#endif
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) throw std::runtime_error("cannot write '" + path + "'");
  const std::size_t n = prob.slots();
  for (std::size_t i = 0; i < u.size(); ++i) {
    if (!(prob.liquidFace[i] > 0.0) || !prob.ownsSlot(i % n)) continue;
    const Coord c = prob.layout->cellOf(i % n);
    const FaceRecord r{{c[0], c[1], c[2]}, std::int32_t(i / n), u[i]};
    if (std::fwrite(&r, sizeof r, 1, f) != 1) {
      std::fclose(f);
      throw std::runtime_error("cannot write '" + path + "'");
    }
  }
  if (std::fclose(f) != 0) throw std::runtime_error("cannot write '" + path + "'");
}

// Streams a faces file and compares the faces this rank owns; sums and maxima over the ranks.
template <int Dim>
void compareFaces(const StaggeredProblem<Dim>& prob, const Vector& u, const std::string& path, AnalyticResult& r) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) throw std::runtime_error("cannot read '" + path + "'");
  const std::size_t n = prob.slots();
  double worst = 0.0, largest = 0.0, compared = 0.0;
  FaceRecord rec;
  while (std::fread(&rec, sizeof rec, 1, f) == 1) {
    largest = std::max(largest, std::abs(rec.u));
    const std::int64_t s = prob.layout->slotOf(Coord(rec.cell[0], rec.cell[1], rec.cell[2]));
    if (s < 0 || !prob.ownsSlot(std::size_t(s)) || rec.axis < 0 || rec.axis >= Dim) continue;
    worst = std::max(worst, std::abs(u[std::size_t(rec.axis) * n + std::size_t(s)] - rec.u));
    compared += 1.0;
  }
  std::fclose(f);
  worst = solver::maxOverParts(prob, worst);
  compared = solver::sumOverParts(prob, compared);
  r.facesDifference = largest > 0.0 ? worst / largest : worst;
  r.facesCompared = std::size_t(compared);
}

AnalyticResult ball(const AnalyticOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  const BallStep step = makeBallStep(o);
  const StaggeredProblem<3>& prob = step.prob;
  Vector u;
  const solver::StepReport rep = solver::solveStep(prob, step.options, u);
  AnalyticResult r = makeResult(o.solids ? "ball-on-floor" : "ball", o);
  if (!fillReport(r, rep, o, u)) return r;  // the solve failed (status, diagnostics)
  r.kineticEnergyBefore = kineticEnergy(prob, prob.uStar);
  r.kineticEnergyAfter = kineticEnergy(prob, u);
  r.maxDivergence = maxDivergence(prob, u);
  if (!o.facesOut.empty()) writeFaces(prob, u, o.facesOut);
  if (!o.facesCompare.empty()) compareFaces(prob, u, o.facesCompare, r);
  r.totalSeconds = solver::secondsSince(t0);
  return r;
}

}  // namespace

AnalyticResult runBoxViscosity(const AnalyticOptions& o) {
  if (o.n < 2) throw std::invalid_argument("box-viscosity: n must be >= 2");
  if (o.dim == 2) return boxViscosity<2>(o);
  if (o.dim == 3) return boxViscosity<3>(o);
  throw std::invalid_argument("box-viscosity: dim must be 2 or 3");
}

AnalyticResult runDiskStokes(const AnalyticOptions& o) {
  if (o.dim != 2) throw std::invalid_argument("disk-stokes is a 2D test (dim 2)");
  if (o.n < 4) throw std::invalid_argument("disk-stokes: n must be >= 4");
  return diskStokes(o);
}

namespace {
/// rms(u - reference) / rms(reference less its mean per axis), over the faces where either is
/// non-zero (the liquid's); u and reference are padded face vectors of one 3D layout.
double relativeDifference(const std::vector<double>& u, const std::vector<double>& reference) {
  if (u.size() != reference.size() || u.size() % 3 != 0)
    throw std::logic_error("relativeDifference: velocities of different layouts");
  const std::size_t n = u.size() / 3;
  double difference = 0.0, variation = 0.0;  // sums over the same faces: their ratio is that of the rms
  for (int a = 0; a < 3; ++a) {
    double sum = 0.0, squares = 0.0;
    std::size_t k = 0;
    for (std::size_t i = a * n; i < (a + 1) * n; ++i) {
      if (u[i] == 0.0 && reference[i] == 0.0) continue;
      difference += (u[i] - reference[i]) * (u[i] - reference[i]);
      sum += reference[i];
      squares += reference[i] * reference[i];
      ++k;
    }
    if (k) variation += squares - sum * sum / double(k);
  }
  return variation > 0.0 ? std::sqrt(difference / variation) : 0.0;
}
}  // namespace

BallStep ballStep(const AnalyticOptions& o) {
  AnalyticOptions o3 = o;
  o3.dim = 3;
  return makeBallStep(o3);
}

AnalyticResult runBall(const AnalyticOptions& o) {
  AnalyticOptions o3 = o;
  o3.dim = 3;
  if (!o.versusUniform || o.model == "uniform") return ball(o3);
  AnalyticOptions uniform = o3;
  uniform.model = "uniform";
  uniform.keepVelocities = true;
  const std::vector<double> reference = ball(uniform).velocities;
  o3.keepVelocities = true;
  AnalyticResult r = ball(o3);
  r.versusUniform = relativeDifference(r.velocities, reference);
  if (!o.keepVelocities) r.velocities.clear();
  return r;
}

}  // namespace stokes::analytic
