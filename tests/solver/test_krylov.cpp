// Tests for the matrix-free Krylov layer (solver/krylov/krylov.h, solver/krylov/operator.h, solver/krylov/vector_ops.h).
// Every expectation is fixed by the mathematics: exact solutions are manufactured
// (b = A x*), orthogonality and determinism are checked to the bit where they must hold.

#include <Eigen/Dense>
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "solver/krylov/aligned_vector.h"
#include "solver/krylov/csr_matrix.h"
#include "solver/krylov/gmres.h"
#include "solver/krylov/krylov.h"
#include "solver/krylov/lanczos_spectrum.h"
#include "solver/krylov/minres.h"
#include "solver/krylov/operator.h"
#include "solver/krylov/saddle_point_preconditioner.h"
#include "solver/krylov/vector_ops.h"
#include "tests/parallel_path.h"

namespace {

using stokes::solver::bicgstab;
using stokes::solver::conjugateGradient;
using stokes::solver::CsrMatrix;
using stokes::solver::fgmres;
using stokes::solver::gmres;
using stokes::solver::IdentityPreconditioner;
using stokes::solver::JacobiPreconditioner;
using stokes::solver::lanczosSpectrum;
using stokes::solver::minres;
using stokes::solver::SolveOptions;
using stokes::solver::SolveResult;
using stokes::solver::Status;
using stokes::solver::Vector;
using stokes::test::TeamCount;
using stokes::test::withThreads;
namespace ops = stokes::solver;
using Region = stokes::parallel::Region;

// ---- test operators ---------------------------------------------------------------------------

// The engine's compressed-row matrix (solver/krylov/csr_matrix.h), built from entries added row by
// row in any order (repeats summed).
class CsrBuilder {
 public:
  explicit CsrBuilder(std::size_t n) : rows_(n) {}
  void add(std::size_t i, std::size_t j, double value) { rows_[i].emplace_back(j, value); }
  CsrMatrix build() const {
    return ops::buildCsrRows(rows_.size(), rows_.size(), [&](std::size_t r, const auto& emit) {
      for (const auto& [j, a] : rows_[r]) emit(j, a);
    });
  }

 private:
  std::vector<std::vector<std::pair<std::size_t, double>>> rows_;
};

/// y = A x.
Vector times(const CsrMatrix& A, const Vector& x) {
  Vector y(A.size());
  A.apply(x.data(), y.data());
  return y;
}

static_assert(ops::LinearOperator<CsrMatrix>);

// 5-point stencil on an m x m interior grid with Dirichlet boundaries (scaled by h^2):
//   center 4, east/west -1 -/+ px, north/south -1 -/+ py
// where px = cx h / 2, py = cy h / 2 (central convection); px = py = 0 gives the SPD Poisson matrix.
CsrMatrix stencil2d(std::size_t m, double px, double py) {
  CsrBuilder A(m * m);
  for (std::size_t j = 0; j < m; ++j) {
    for (std::size_t i = 0; i < m; ++i) {
      const std::size_t row = j * m + i;
      A.add(row, row, 4.0);
      if (i > 0) A.add(row, row - 1, -1.0 - px);
      if (i + 1 < m) A.add(row, row + 1, -1.0 + px);
      if (j > 0) A.add(row, row - m, -1.0 - py);
      if (j + 1 < m) A.add(row, row + m, -1.0 + py);
    }
  }
  return A.build();
}

CsrMatrix poisson2d(std::size_t m) { return stencil2d(m, 0.0, 0.0); }

// -u'' with homogeneous Neumann ends: rows [1 -1], [-1 2 -1], ..., [-1 1]; null space = constants.
CsrMatrix neumann1d(std::size_t n) {
  CsrBuilder A(n);
  for (std::size_t i = 0; i < n; ++i) {
    double diag = 0.0;
    if (i > 0) A.add(i, i - 1, -1.0), diag += 1.0;
    if (i + 1 < n) A.add(i, i + 1, -1.0), diag += 1.0;
    A.add(i, i, diag);
  }
  return A.build();
}

// Tridiagonal [-1, shift + 2, -1]: SPD with condition number <= (shift + 4) / shift.
CsrMatrix shiftedLaplacian1d(std::size_t n, double shift) {
  CsrBuilder A(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (i > 0) A.add(i, i - 1, -1.0);
    A.add(i, i, 2.0 + shift);
    if (i + 1 < n) A.add(i, i + 1, -1.0);
  }
  return A.build();
}

// Symmetric, strictly diagonally dominant (hence SPD) with diagonal d_i = 10^U(0,4):
// off-diagonals -min(d_i, d_{i+1}) / 4 bound each row's off-diagonal sum by d_i / 2.
CsrMatrix badlyScaled(std::size_t n, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> exponent(0.0, 4.0);
  std::vector<double> d(n);
  for (auto& di : d) di = std::pow(10.0, exponent(rng));
  CsrBuilder A(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (i > 0) A.add(i, i - 1, -0.25 * std::min(d[i - 1], d[i]));
    A.add(i, i, d[i]);
    if (i + 1 < n) A.add(i, i + 1, -0.25 * std::min(d[i], d[i + 1]));
  }
  return A.build();
}

// Wraps an operator and returns NaN from the k-th application on (simulates a failing kernel).
struct PoisonedOperator {
  const CsrMatrix& A;
  int healthyApplications;
  mutable int applications = 0;

  std::size_t size() const { return A.size(); }
  void apply(const double* x, double* y) const {
    A.apply(x, y);
    if (++applications > healthyApplications) y[0] = std::numeric_limits<double>::quiet_NaN();
  }
};

// 2 x 2 rotation by 90 degrees: (r, A r) = 0 for every r, so BiCGSTAB's (r0^, v) always vanishes.
struct Rotation90 {
  std::size_t size() const { return 2; }
  void apply(const double* x, double* y) const {
    y[0] = x[1];
    y[1] = -x[0];
  }
};

// ---- helpers ----------------------------------------------------------------------------------

Vector randomVector(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Vector v(n);
  for (auto& vi : v) vi = uniform(rng);
  return v;
}

double norm(const Vector& v) { return ops::norm2(v.data(), v.size()); }

double relativeError(const Vector& x, const Vector& exact) {
  Vector diff(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) diff[i] = x[i] - exact[i];
  return norm(diff) / norm(exact);
}

bool allFinite(const Vector& v) { return ops::allFinite(v.data(), v.size()); }

bool bitwiseEqual(const Vector& a, const Vector& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

bool bitwiseEqual(double a, double b) { return std::memcmp(&a, &b, sizeof(double)) == 0; }


enum class SolverKind { CG, BiCGSTAB };
enum class PreconditionerKind { Identity, Jacobi };

template <class Op, class Pre>
SolveResult solveWith(SolverKind kind, const Op& A, const Vector& b, Vector& x, const Pre& M,
                      const SolveOptions& opt) {
  return kind == SolverKind::CG ? conjugateGradient(A, b.data(), x.data(), M, opt)
                                : bicgstab(A, b.data(), x.data(), M, opt);
}

SolveResult solveWith(SolverKind solver, PreconditionerKind pre, const CsrMatrix& A, const Vector& b, Vector& x,
                      const SolveOptions& opt) {
  if (pre == PreconditionerKind::Jacobi) return solveWith(solver, A, b, x, JacobiPreconditioner(A.diagonal()), opt);
  return solveWith(solver, A, b, x, IdentityPreconditioner{A.size()}, opt);
}

std::string name(SolverKind kind) { return kind == SolverKind::CG ? "CG" : "BiCGSTAB"; }
std::string name(PreconditionerKind kind) { return kind == PreconditionerKind::Jacobi ? "Jacobi" : "Identity"; }

std::string solverName(const ::testing::TestParamInfo<SolverKind>& param) { return name(param.param); }

std::string pairName(const ::testing::TestParamInfo<std::tuple<SolverKind, PreconditionerKind>>& param) {
  return name(std::get<0>(param.param)) + "_" + name(std::get<1>(param.param));
}

SolveOptions tolerance(double relTol) {
  SolveOptions opt;
  opt.relativeTolerance = relTol;
  return opt;
}

// ---- vector kernels ---------------------------------------------------------------------------

TEST(VectorOps, AlignedVectorIs64ByteAligned) {
  for (std::size_t n : {1u, 7u, 1000u}) {
    Vector v(n);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(v.data()) % 64, 0u);
  }
}

TEST(VectorOps, ReductionsMatchExactValues) {
  const std::size_t n = 10000;  // three chunks, the last one partial
  Vector a(n), b(n);
  for (std::size_t i = 0; i < n; ++i) {
    a[i] = static_cast<double>(i % 7) - 3.0;  // small integers: every sum is exact in double
    b[i] = static_cast<double>(i % 5);
  }
  double exactDot = 0.0, exactSum = 0.0, exactAA = 0.0;
  for (std::size_t i = 0; i < n; ++i) exactDot += a[i] * b[i], exactSum += a[i], exactAA += a[i] * a[i];
  EXPECT_EQ(ops::dot(a.data(), b.data(), n), exactDot);
  EXPECT_EQ(ops::sum(a.data(), n), exactSum);
  EXPECT_EQ(ops::norm2(a.data(), n), std::sqrt(exactAA));
  EXPECT_EQ(ops::maxAbs(a.data(), n), 3.0);
  const auto [ab, aa] = ops::dot2(a.data(), b.data(), a.data(), a.data(), n);
  EXPECT_EQ(ab, exactDot);
  EXPECT_EQ(aa, exactAA);
  EXPECT_EQ(ops::dot(a.data(), b.data(), 0), 0.0);
}

TEST(VectorOps, FusedUpdatesFollowTheirFormulas) {
  const std::size_t n = 9000;
  const Vector p = randomVector(n, 1), Ap = randomVector(n, 2), x0 = randomVector(n, 3), r0 = randomVector(n, 4);
  const double alpha = 0.375;  // exact in binary
  Vector x = x0, r = r0;
  const double rr = ops::cgUpdate(alpha, p.data(), Ap.data(), x.data(), r.data(), n);
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(x[i], x0[i] + alpha * p[i]);
    EXPECT_EQ(r[i], r0[i] - alpha * Ap[i]);
  }
  EXPECT_EQ(rr, ops::dot(r.data(), r.data(), n));

  Vector y = x0;
  ops::xpby(p.data(), -2.0, y.data(), n);  // y = p - 2 y
  for (std::size_t i = 0; i < n; ++i) EXPECT_EQ(y[i], p[i] - 2.0 * x0[i]);

  Vector u(n, 1.0 / std::sqrt(static_cast<double>(n)));
  Vector v = x0;
  ops::projectOut(u.data(), v.data(), n);  // v -= (u.v) u  =>  u.v = 0
  EXPECT_NEAR(ops::dot(u.data(), v.data(), n), 0.0, 1e-13 * norm(x0));
}

TEST(VectorOps, AllFiniteDetectsNanAndInf) {
  Vector v = randomVector(20000, 5);
  EXPECT_TRUE(allFinite(v));
  v[12345] = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(allFinite(v));
  v[12345] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(allFinite(v));
}

// n = 300,007 (74 chunks, a short last one): above the vector fork threshold of 2^17 entries, so
// every thread count takes its production path, and 2 and 3 threads split the chunks (counted).
constexpr std::size_t kSplitSize = 300007;

TEST(VectorOps, DotIsBitIdenticalAcrossThreadCounts) {
  const std::size_t n = kSplitSize;
  const Vector a = randomVector(n, 11), b = randomVector(n, 12);
  const auto reduce = [&] {
    const auto [ab, bb] = ops::dot2(a.data(), b.data(), b.data(), b.data(), n);
    return std::vector<double>{ops::dot(a.data(), b.data(), n), ops::sum(a.data(), n), ab, bb};
  };
  const std::vector<double> one = withThreads(1, reduce);
  for (int threads : {2, 3}) {
    const TeamCount split;
    const std::vector<double> many = withThreads(threads, reduce);
    EXPECT_EQ(split(Region::Reduction), 3u) << "threads " << threads << ": dot, sum and dot2 split over threads";
    for (std::size_t k = 0; k < one.size(); ++k) EXPECT_TRUE(bitwiseEqual(one[k], many[k])) << "threads " << threads;
  }
  long double reference = 0.0L;
  for (std::size_t i = 0; i < n; ++i) reference += static_cast<long double>(a[i]) * b[i];
  EXPECT_NEAR(one[0], static_cast<double>(reference), 1e-12 * static_cast<double>(n));
}

// ---- preconditioners --------------------------------------------------------------------------

TEST(Preconditioners, IdentityCopies) {
  const Vector r = randomVector(100, 6);
  Vector z(100);
  IdentityPreconditioner{100}.apply(r.data(), z.data());
  EXPECT_TRUE(bitwiseEqual(r, z));
}

TEST(Preconditioners, JacobiDividesByDiagonalAndZeroesInactiveRows) {
  const std::vector<double> diagonal{4.0, 0.0, -2.0, 0.5, 0.0};
  const Vector r{8.0, 5.0, 3.0, 1.0, std::numeric_limits<double>::quiet_NaN()};
  Vector z(5, -1.0);
  JacobiPreconditioner(diagonal).apply(r.data(), z.data());  // z = D^-1 r, 0 where d_i = 0
  EXPECT_EQ(z[0], 2.0);
  EXPECT_EQ(z[1], 0.0);
  EXPECT_EQ(z[2], -1.5);
  EXPECT_EQ(z[3], 2.0);
  EXPECT_EQ(z[4], 0.0);

  const Vector alignedDiagonal(diagonal.begin(), diagonal.end());
  const JacobiPreconditioner fromVector(alignedDiagonal);
  EXPECT_EQ(fromVector.size(), 5u);
  EXPECT_EQ(fromVector.inverseDiagonal()[1], 0.0);
  EXPECT_EQ(fromVector.inverseDiagonal()[3], 2.0);
}

// ---- every solver x preconditioner on 2D Poisson ---------------------------------------------

class PoissonSolve : public ::testing::TestWithParam<std::tuple<SolverKind, PreconditionerKind>> {};

TEST_P(PoissonSolve, RecoversManufacturedSolution) {
  const auto [solver, pre] = GetParam();
  const CsrMatrix A = poisson2d(40);
  const Vector exact = randomVector(A.size(), 21);
  const Vector b = times(A, exact);
  Vector x(A.size(), 0.0);

  const SolveResult result = solveWith(solver, pre, A, b, x, tolerance(1e-10));

  EXPECT_EQ(result.status, Status::Converged) << ops::toString(result.status);
  EXPECT_TRUE(result.converged());
  EXPECT_GT(result.iterations, 0);
  EXPECT_LE(result.relativeResidual, 1e-10 * (1.0 + 1e-6));
  EXPECT_DOUBLE_EQ(result.initialResidual, norm(b));  // x0 = 0  =>  r0 = b
  EXPECT_LT(relativeError(x, exact), 1e-7);
}

INSTANTIATE_TEST_SUITE_P(
    AllPairs, PoissonSolve,
    ::testing::Combine(::testing::Values(SolverKind::CG, SolverKind::BiCGSTAB),
                       ::testing::Values(PreconditionerKind::Identity, PreconditionerKind::Jacobi)),
    pairName);

// ---- BiCGSTAB ---------------------------------------------------------------------------------

TEST(BiCgStab, SolvesNonSymmetricConvectionDiffusion) {
  const std::size_t m = 40;
  const double h = 1.0 / static_cast<double>(m + 1);
  const CsrMatrix A = stencil2d(m, 30.0 * h / 2.0, -20.0 * h / 2.0);  // convection c = (30, -20)
  const Vector exact = randomVector(A.size(), 31);
  const Vector b = times(A, exact);
  for (PreconditionerKind pre : {PreconditionerKind::Identity, PreconditionerKind::Jacobi}) {
    Vector x(A.size(), 0.0);
    const SolveResult result = solveWith(SolverKind::BiCGSTAB, pre, A, b, x, tolerance(1e-10));
    EXPECT_EQ(result.status, Status::Converged) << ops::toString(result.status);
    EXPECT_GT(result.iterations, 0);
    EXPECT_LT(relativeError(x, exact), 1e-7);
  }
}

TEST(BiCgStab, PersistentBreakdownGivesUpAfterStalledRestarts) {
  const Rotation90 A;  // (r0^, A p) = 0 on every restart: no progress is possible
  const Vector b{1.0, 2.0};
  Vector x{0.0, 0.0};
  const SolveResult result = bicgstab(A, b.data(), x.data(), IdentityPreconditioner{2});
  EXPECT_EQ(result.status, Status::Breakdown);
  EXPECT_EQ(result.restarts, 5);
  EXPECT_TRUE(allFinite(x));
}

// A = [0 0 2; -2 -1 -2; 2 0 1], b = (0, -1, -1): the first pass gives alpha = -1, omega = 4/11 and
// r1 = (-6, -2, 2)/11, which is exactly orthogonal to r0^ = b, so rho_1 = (r0^, r1) = 0. The solver
// restarts from the true residual (r0^ = r1) and then converges to x = (-1/2, 2, 0).
TEST(BiCgStab, RestartsOnBreakdownAndConverges) {
  CsrBuilder entries3(3);
  const double entries[3][3] = {{0, 0, 2}, {-2, -1, -2}, {2, 0, 1}};
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t j = 0; j < 3; ++j)
      if (entries[i][j] != 0.0) entries3.add(i, j, entries[i][j]);
  const CsrMatrix A = entries3.build();
  const Vector b{0.0, -1.0, -1.0};
  Vector x(3, 0.0);
  const SolveResult result = bicgstab(A, b.data(), x.data(), IdentityPreconditioner{3}, tolerance(1e-12));
  EXPECT_EQ(result.status, Status::Converged) << ops::toString(result.status);
  EXPECT_EQ(result.restarts, 1);
  EXPECT_LT(relativeError(x, Vector{-0.5, 2.0, 0.0}), 1e-12);
}

// ---- CG ---------------------------------------------------------------------------------------

TEST(ConjugateGradient, JacobiBeatsPlainCgOnBadlyScaledMatrix) {
  std::mt19937_64 rng(41);
  const CsrMatrix A = badlyScaled(500, rng);
  const Vector exact = randomVector(A.size(), 42);
  const Vector b = times(A, exact);
  Vector xPlain(A.size(), 0.0), xJacobi(A.size(), 0.0);
  const SolveResult plain = solveWith(SolverKind::CG, PreconditionerKind::Identity, A, b, xPlain, tolerance(1e-10));
  const SolveResult jacobi = solveWith(SolverKind::CG, PreconditionerKind::Jacobi, A, b, xJacobi, tolerance(1e-10));
  ASSERT_EQ(plain.status, Status::Converged);
  ASSERT_EQ(jacobi.status, Status::Converged);
  EXPECT_LT(jacobi.iterations, plain.iterations);
  EXPECT_LT(relativeError(xJacobi, exact), 1e-8);
}

// CG fuses a diagonal preconditioner into its vector update (cgUpdateDiagonal). The fused loop
// performs the same floating-point operations in the same order as the separate update, Jacobi
// application and dot product: the iterates are bit-identical to a Jacobi preconditioner that
// hides its diagonal (and so takes the unfused path).
TEST(ConjugateGradient, FusedJacobiStepIsBitIdenticalToSeparateSteps) {
  struct OpaqueJacobi {  // the same z = D^-1 r, not a DiagonalPreconditioner
    const JacobiPreconditioner* jacobi;
    std::size_t size() const { return jacobi->size(); }
    void apply(const double* r, double* z) const { jacobi->apply(r, z); }
  };
  static_assert(!stokes::solver::DiagonalPreconditioner<OpaqueJacobi>);
  std::mt19937_64 rng(43);
  const CsrMatrix A = badlyScaled(20000, rng);
  const Vector b = times(A, randomVector(A.size(), 44));
  const JacobiPreconditioner jacobi(A.diagonal());
  Vector xFused(A.size(), 0.0), xSeparate(A.size(), 0.0);
  const SolveResult fused = conjugateGradient(A, b.data(), xFused.data(), jacobi, tolerance(1e-10));
  const SolveResult separate = conjugateGradient(A, b.data(), xSeparate.data(), OpaqueJacobi{&jacobi}, tolerance(1e-10));
  ASSERT_EQ(fused.status, Status::Converged);
  EXPECT_GT(fused.iterations, 10);
  EXPECT_EQ(fused.iterations, separate.iterations);
  EXPECT_TRUE(bitwiseEqual(fused.finalResidual, separate.finalResidual));
  EXPECT_TRUE(bitwiseEqual(xFused, xSeparate));
}

TEST(ConjugateGradient, SingularNeumannSystemWithNullSpace) {
  const std::size_t n = 100;
  const CsrMatrix A = neumann1d(n);
  const Vector unitConstant(n, 1.0 / std::sqrt(static_cast<double>(n)));
  Vector exact = randomVector(n, 51);
  ops::projectOut(unitConstant.data(), exact.data(), n);  // the unique solution orthogonal to constants
  const Vector b = times(A, exact);                     // consistent: b is orthogonal to constants
  EXPECT_NEAR(ops::sum(b.data(), n), 0.0, 1e-12);

  SolveOptions opt = tolerance(1e-12);
  opt.nullSpace = unitConstant.data();
  for (SolverKind solver : {SolverKind::CG, SolverKind::BiCGSTAB}) {
    Vector x = randomVector(n, 52);  // initial guess with a constant component, removed by the solver
    const SolveResult result = solveWith(solver, PreconditionerKind::Jacobi, A, b, x, opt);
    EXPECT_EQ(result.status, Status::Converged) << ops::toString(result.status);
    EXPECT_NEAR(ops::dot(unitConstant.data(), x.data(), n), 0.0, 1e-13 * norm(x));
    EXPECT_LT(relativeError(x, exact), 1e-7);
  }
}

TEST(ConjugateGradient, IndefiniteMatrixBreaksDown) {
  CsrBuilder diagonal(2);
  diagonal.add(0, 0, 1.0);
  diagonal.add(1, 1, -1.0);
  const CsrMatrix A = diagonal.build();
  const Vector b{1.0, 1.0};  // p0 = b gives (p, Ap) = 1 - 1 = 0
  Vector x{0.0, 0.0};
  const SolveResult result = conjugateGradient(A, b.data(), x.data(), IdentityPreconditioner{2});
  EXPECT_EQ(result.status, Status::Breakdown);
  EXPECT_EQ(result.iterations, 0);
  EXPECT_TRUE(allFinite(x));
}

// Divergence guard: CG's residual is not monotone. A = diag(1, 100), b = (1, 0.1): the first step
// (alpha = (r,r)/(r,Ar) = 1.01/2) leaves r1 = (0.495, -4.95), |r1| = 4.97 > 2 max(|r0|, |b|) = 2.01,
// so with divergenceFactor 2 the solve stops with Diverged after one iteration, x finite; with
// the default factor the same solve converges in two (two distinct eigenvalues).
TEST(ConjugateGradient, ResidualGrowingPastTheBoundIsDiverged) {
  CsrBuilder diagonal(2);
  diagonal.add(0, 0, 1.0);
  diagonal.add(1, 1, 100.0);
  const CsrMatrix A = diagonal.build();
  const Vector b{1.0, 0.1};
  Vector x{0.0, 0.0};
  SolveOptions opt = tolerance(1e-12);
  opt.divergenceFactor = 2.0;
  const SolveResult diverged = conjugateGradient(A, b.data(), x.data(), IdentityPreconditioner{2}, opt);
  EXPECT_EQ(diverged.status, Status::Diverged) << ops::toString(diverged.status);
  EXPECT_EQ(diverged.iterations, 1);
  EXPECT_NEAR(diverged.finalResidual, std::hypot(0.495, 4.95), 1e-12);
  EXPECT_TRUE(allFinite(x));
  x.assign(2, 0.0);
  const SolveResult converged = conjugateGradient(A, b.data(), x.data(), IdentityPreconditioner{2}, tolerance(1e-12));
  EXPECT_EQ(converged.status, Status::Converged);
  EXPECT_EQ(converged.iterations, 2);
}

TEST(ConjugateGradient, HistoryRecordsInitialAndEveryIteration) {
  const CsrMatrix A = poisson2d(10);
  const Vector b = randomVector(A.size(), 61);
  Vector x(A.size(), 0.0);
  SolveOptions opt = tolerance(1e-8);
  opt.recordHistory = true;
  const SolveResult result = conjugateGradient(A, b.data(), x.data(), IdentityPreconditioner{A.size()}, opt);
  ASSERT_EQ(result.status, Status::Converged);
  ASSERT_EQ(result.history.size(), static_cast<std::size_t>(result.iterations) + 1);
  EXPECT_EQ(result.history.front(), result.initialResidual);
  EXPECT_LE(result.history.back(), 1e-8 * norm(b));
}

TEST(ConjugateGradient, AbsoluteToleranceStopsEarlier) {
  const CsrMatrix A = poisson2d(20);
  const Vector b = randomVector(A.size(), 71);
  Vector xRel(A.size(), 0.0), xAbs(A.size(), 0.0);
  SolveOptions absolute = tolerance(0.0);
  absolute.absoluteTolerance = 1e-3 * norm(b);
  const SolveResult rel = conjugateGradient(A, b.data(), xRel.data(), IdentityPreconditioner{A.size()}, tolerance(1e-10));
  const SolveResult abs = conjugateGradient(A, b.data(), xAbs.data(), IdentityPreconditioner{A.size()}, absolute);
  ASSERT_TRUE(rel.converged());
  ASSERT_TRUE(abs.converged());
  EXPECT_LT(abs.iterations, rel.iterations);
}

// ---- behaviour shared by both solvers ---------------------------------------------------------

class BothSolvers : public ::testing::TestWithParam<SolverKind> {};

TEST_P(BothSolvers, ZeroRightHandSideGivesZeroSolution) {
  const CsrMatrix A = poisson2d(8);
  const Vector b(A.size(), 0.0);
  Vector x = randomVector(A.size(), 81);  // nonzero guess
  const SolveResult result = solveWith(GetParam(), PreconditionerKind::Jacobi, A, b, x, SolveOptions{});
  EXPECT_EQ(result.status, Status::Converged);
  EXPECT_EQ(result.iterations, 0);
  EXPECT_EQ(result.relativeResidual, 0.0);
  for (double xi : x) EXPECT_EQ(xi, 0.0);
}

TEST_P(BothSolvers, NanInRightHandSideIsReportedAndXStaysFinite) {
  const CsrMatrix A = poisson2d(8);
  Vector b = randomVector(A.size(), 82);
  b[17] = std::numeric_limits<double>::quiet_NaN();
  Vector x(A.size(), 0.0);
  const SolveResult result = solveWith(GetParam(), PreconditionerKind::Identity, A, b, x, SolveOptions{});
  EXPECT_EQ(result.status, Status::NonFinite);
  EXPECT_FALSE(result.converged());
  EXPECT_TRUE(allFinite(x));
}

TEST_P(BothSolvers, NanFromOperatorStopsAtLastFiniteIterate) {
  const CsrMatrix A = poisson2d(10);
  const Vector b = randomVector(A.size(), 83);
  const PoisonedOperator poisoned{A, 4};
  Vector x(A.size(), 0.0);
  const SolveResult result = solveWith(GetParam(), poisoned, b, x, IdentityPreconditioner{A.size()}, SolveOptions{});
  EXPECT_EQ(result.status, Status::NonFinite);
  EXPECT_GT(result.iterations, 0);
  EXPECT_TRUE(allFinite(x));
}

TEST_P(BothSolvers, MaxIterationsIsHonoured) {
  const CsrMatrix A = poisson2d(40);
  const Vector b = randomVector(A.size(), 84);
  Vector x(A.size(), 0.0);
  SolveOptions opt = tolerance(1e-14);
  opt.maxIterations = 3;
  const SolveResult result = solveWith(GetParam(), PreconditionerKind::Identity, A, b, x, opt);
  EXPECT_EQ(result.status, Status::MaxIterations);
  EXPECT_EQ(result.iterations, 3);
  EXPECT_LT(result.finalResidual, result.initialResidual);
}

// Solves A x = b (x from 0) on 1, then 2 threads: the same iterations, residual and bits, the
// 2-thread run splitting at least one reduction an iteration over the threads.
template <class Solve>
void expectSolveBitIdenticalForOneAndTwoThreads(std::size_t n, const Solve& solve) {
  const auto run = [&] {
    Vector x(n, 0.0);
    const SolveResult result = solve(x);
    return std::make_pair(x, result);
  };
  const auto [xOne, resultOne] = withThreads(1, run);
  const TeamCount split;
  const auto [xTwo, resultTwo] = withThreads(2, run);
  EXPECT_GE(split(Region::Reduction), std::uint64_t(resultTwo.iterations)) << "at least one split reduction an iteration";
  ASSERT_EQ(resultOne.status, Status::Converged);
  EXPECT_EQ(resultOne.iterations, resultTwo.iterations);
  EXPECT_TRUE(bitwiseEqual(resultOne.finalResidual, resultTwo.finalResidual));
  EXPECT_TRUE(bitwiseEqual(xOne, xTwo));
}

TEST_P(BothSolvers, SolveIsBitIdenticalAcrossThreadCounts) {
  const std::size_t n = kSplitSize;
  const CsrMatrix A = shiftedLaplacian1d(n, 0.5);
  const Vector b = randomVector(n, 91);
  expectSolveBitIdenticalForOneAndTwoThreads(n, [&](Vector& x) {
    return solveWith(GetParam(), PreconditionerKind::Jacobi, A, b, x, tolerance(1e-10));
  });
}

// ---- MINRES: the same guards ----------------------------------------------------------------------

// MINRES (the pressure-velocity form's method) reduces in its own places (Lanczos coefficients,
// the preconditioned norm, the true residual): the same bits on 1 and 2 threads, its reductions
// split over the threads.
TEST(Minres, SolveIsBitIdenticalAcrossThreadCounts) {
  const std::size_t n = kSplitSize;
  const CsrMatrix A = shiftedLaplacian1d(n, 0.5);
  const Vector b = randomVector(n, 92), d = A.diagonal();
  expectSolveBitIdenticalForOneAndTwoThreads(n, [&](Vector& x) {
    return minres(A, b.data(), x.data(), JacobiPreconditioner(d), tolerance(1e-10));
  });
}

TEST(Minres, ZeroRightHandSideGivesZeroSolution) {
  const CsrMatrix A = poisson2d(8);
  const Vector b(A.size(), 0.0);
  Vector x = randomVector(A.size(), 85);
  const SolveResult result = minres(A, b.data(), x.data(), IdentityPreconditioner{A.size()});
  EXPECT_EQ(result.status, Status::Converged);
  EXPECT_EQ(result.iterations, 0);
  for (double xi : x) EXPECT_EQ(xi, 0.0);
}

TEST(Minres, NonFiniteRightHandSideAndOperatorAreReportedAndXStaysFinite) {
  const CsrMatrix A = poisson2d(10);
  Vector b = randomVector(A.size(), 86);
  Vector x(A.size(), 0.0);
  const PoisonedOperator poisoned{A, 4};
  const SolveResult fromOperator = minres(poisoned, b.data(), x.data(), IdentityPreconditioner{A.size()});
  EXPECT_EQ(fromOperator.status, Status::NonFinite);
  EXPECT_GT(fromOperator.iterations, 0);
  EXPECT_TRUE(allFinite(x));
  b[3] = std::numeric_limits<double>::infinity();
  x.assign(A.size(), 0.0);
  const SolveResult fromRhs = minres(A, b.data(), x.data(), IdentityPreconditioner{A.size()});
  EXPECT_EQ(fromRhs.status, Status::NonFinite);
  EXPECT_EQ(fromRhs.iterations, 0);
  EXPECT_TRUE(allFinite(x));
}

TEST(Minres, MaxIterationsIsHonoured) {
  const CsrMatrix A = poisson2d(40);
  const Vector b = randomVector(A.size(), 87);
  Vector x(A.size(), 0.0);
  SolveOptions opt = tolerance(1e-14);
  opt.maxIterations = 3;
  const SolveResult result = minres(A, b.data(), x.data(), IdentityPreconditioner{A.size()}, opt);
  EXPECT_EQ(result.status, Status::MaxIterations);
  EXPECT_EQ(result.iterations, 3);
  EXPECT_LT(result.finalResidual, result.initialResidual);
}

INSTANTIATE_TEST_SUITE_P(Solvers, BothSolvers, ::testing::Values(SolverKind::CG, SolverKind::BiCGSTAB),
                         solverName);

// ---- spectrum estimates (lanczos_spectrum.h) --------------------------------------------------

// y = diag(d) x: its eigenvalues are d, so the estimates are fixed exactly.
struct DiagonalOperator {
  std::vector<double> d;
  std::size_t size() const { return d.size(); }
  void apply(const double* x, double* y) const {
    for (std::size_t i = 0; i < d.size(); ++i) y[i] = d[i] * x[i];
  }
};

TEST(LanczosSpectrum, FindsTheExtremeEigenvaluesOfADiagonalOperator) {
  DiagonalOperator a;
  for (int i = 1; i <= 200; ++i) a.d.push_back(0.5 + 0.01 * i * i);  // 0.51 ... 400.5
  const auto s = lanczosSpectrum(a, IdentityPreconditioner{a.size()}, 600);
  EXPECT_NEAR(s.lambdaMin, 0.51, 1e-9);
  EXPECT_NEAR(s.lambdaMax, 400.5, 1e-9 * 400.5);
  EXPECT_NEAR(s.condition(), 400.5 / 0.51, 1e-6);
}

TEST(LanczosSpectrum, TheExactPreconditionerGivesConditionOne) {
  DiagonalOperator a;
  for (int i = 1; i <= 50; ++i) a.d.push_back(double(i * i));
  const Vector diagonal(a.d.begin(), a.d.end());
  const auto s = lanczosSpectrum(a, JacobiPreconditioner(diagonal), 50);
  EXPECT_EQ(s.steps, 1);  // M^-1 A = I: the Krylov space is one vector
  EXPECT_NEAR(s.lambdaMin, 1.0, 1e-12);
  EXPECT_NEAR(s.lambdaMax, 1.0, 1e-12);
}

TEST(LanczosSpectrum, SquareOfAnIndefiniteOperatorGivesTheSmallestMagnitude) {
  DiagonalOperator a;
  for (int i = 1; i <= 60; ++i) a.d.push_back(i % 2 ? -0.25 * i : 2.0 + i);  // -0.25 ... -14.75, 4 ... 62
  const auto s = lanczosSpectrum(a, IdentityPreconditioner{a.size()}, 180);
  EXPECT_NEAR(s.lambdaMin, -14.75, 1e-9);
  EXPECT_NEAR(s.lambdaMax, 62.0, 1e-9);
  // Ritz values may fall into the gap (-0.25, 4); the square's may not
  const auto m = stokes::solver::lanczosMagnitudes(a, IdentityPreconditioner{a.size()}, 400);
  EXPECT_NEAR(m.smallestAbs, 0.25, 1e-9);
  EXPECT_NEAR(m.largestAbs, 62.0, 1e-9);
  EXPECT_NEAR(m.condition(), 62.0 / 0.25, 1e-5);
}

TEST(LanczosSpectrum, ProjectsOutTheNullVector) {
  // diag(0, 1, ..., 39): singular, null vector e_0; on its complement the spectrum is 1 ... 39.
  DiagonalOperator a;
  for (int i = 0; i < 40; ++i) a.d.push_back(double(i));
  std::vector<double> null(40, 0.0);
  null[0] = 1.0;
  const auto s = lanczosSpectrum(a, IdentityPreconditioner{a.size()}, 40, null.data());
  EXPECT_NEAR(s.lambdaMin, 1.0, 1e-9);
  EXPECT_NEAR(s.lambdaMax, 39.0, 1e-9);
  EXPECT_NEAR(s.condition(), 39.0, 1e-7);
}

// ---- GMRES and flexible GMRES -------------------------------------------------------------------------------

// The nonsymmetric convection-diffusion stencil (cell Peclet numbers 0.6 and 0.3, where CG does not
// apply): FGMRES with Jacobi and restarts of 20 recovers the manufactured solution, and its
// residual estimate is the true residual (b - A x is recomputed at the end of every cycle).
TEST(Fgmres, SolvesNonsymmetricSystemWithRestarts) {
  const CsrMatrix A = stencil2d(30, 0.6, 0.3);
  const Vector exact = randomVector(A.size(), 101);
  const Vector b = times(A, exact);
  Vector x(A.size(), 0.0);
  SolveOptions opt = tolerance(1e-10);
  opt.restart = 20;
  const SolveResult result = fgmres(A, b.data(), x.data(), JacobiPreconditioner(A.diagonal()), opt);
  ASSERT_EQ(result.status, Status::Converged);
  EXPECT_GT(result.restarts, 0);
  EXPECT_LE(result.relativeResidual, 1e-10);
  EXPECT_LT(relativeError(x, exact), 1e-7);
}

// Without restarts and with M = I, GMRES and MINRES minimise the same ||b - A x||_2 over the same
// Krylov spaces for symmetric A: their residual histories agree (to round-off) step by step.
TEST(Fgmres, MatchesMinresOnSymmetricSystems) {
  const CsrMatrix A = poisson2d(12);
  const Vector b = randomVector(A.size(), 102);
  SolveOptions opt = tolerance(1e-9);
  opt.recordHistory = true;
  opt.restart = int(A.size());
  Vector xg(A.size(), 0.0), xm(A.size(), 0.0);
  const SolveResult g = fgmres(A, b.data(), xg.data(), IdentityPreconditioner{A.size()}, opt);
  const SolveResult m = minres(A, b.data(), xm.data(), IdentityPreconditioner{A.size()}, opt);
  ASSERT_EQ(g.status, Status::Converged);
  ASSERT_EQ(m.status, Status::Converged);
  EXPECT_NEAR(g.iterations, m.iterations, 1);
  const std::size_t k = std::min(g.history.size(), m.history.size()) - 1;
  for (std::size_t i = 0; i < k; ++i) EXPECT_NEAR(g.history[i], m.history[i], 1e-7 * g.history[0]) << "step " << i;
  EXPECT_LT(relativeError(xg, xm), 1e-7);
}

// A preconditioner that changes at every apply (Jacobi scaled by 1, 3, 1/2, 2, ... in turn): the
// flexible method updates x from the vectors it preconditioned, so it still converges to A^-1 b.
struct VaryingJacobi {
  Vector dinv;
  mutable int applies = 0;
  std::size_t size() const { return dinv.size(); }
  void apply(const double* r, double* z) const {
    static constexpr double kScales[] = {1.0, 3.0, 0.5, 2.0, 0.25};
    const double s = kScales[applies++ % 5];
    for (std::size_t i = 0; i < dinv.size(); ++i) z[i] = s * dinv[i] * r[i];
  }
};

TEST(Fgmres, ConvergesWithAPreconditionerThatVaries) {
  const CsrMatrix A = stencil2d(20, 0.4, -0.2);
  const Vector exact = randomVector(A.size(), 103);
  const Vector b = times(A, exact);
  VaryingJacobi M{A.diagonal()};
  for (double& d : M.dinv) d = 1.0 / d;
  Vector x(A.size(), 0.0);
  const SolveResult result = fgmres(A, b.data(), x.data(), M, tolerance(1e-10));
  ASSERT_EQ(result.status, Status::Converged);
  EXPECT_EQ(M.applies, result.iterations);  // one apply an iteration
  EXPECT_LT(relativeError(x, exact), 1e-7);
}

TEST(Fgmres, SolveIsBitIdenticalAcrossThreadCounts) {
  const std::size_t n = kSplitSize;
  const CsrMatrix A = shiftedLaplacian1d(n, 0.5);
  const Vector b = randomVector(n, 93), d = A.diagonal();
  expectSolveBitIdenticalForOneAndTwoThreads(n, [&](Vector& x) {
    return fgmres(A, b.data(), x.data(), JacobiPreconditioner(d), tolerance(1e-10));
  });
}

TEST(Fgmres, NonFiniteOperatorStopsAtLastFiniteIterate) {
  const CsrMatrix A = poisson2d(10);
  const Vector b = randomVector(A.size(), 104);
  const PoisonedOperator poisoned{A, 4};
  Vector x(A.size(), 0.0);
  const SolveResult result = fgmres(poisoned, b.data(), x.data(), IdentityPreconditioner{A.size()});
  EXPECT_EQ(result.status, Status::NonFinite);
  EXPECT_TRUE(allFinite(x));
}

// With a fixed preconditioner GMRES and FGMRES build the same Krylov space and minimise the same
// residual: the same iterations and restarts, the same solution to round-off (GMRES forms
// M^-1 (V y) where FGMRES sums Z y).
TEST(Gmres, MatchesFgmresWithAFixedPreconditioner) {
  const CsrMatrix A = stencil2d(30, 0.6, 0.3);
  const Vector exact = randomVector(A.size(), 105);
  const Vector b = times(A, exact);
  SolveOptions opt = tolerance(1e-10);
  opt.restart = 20;
  Vector xg(A.size(), 0.0), xf(A.size(), 0.0);
  const JacobiPreconditioner M(A.diagonal());
  const SolveResult g = gmres(A, b.data(), xg.data(), M, opt);
  const SolveResult f = fgmres(A, b.data(), xf.data(), M, opt);
  ASSERT_EQ(g.status, Status::Converged);
  EXPECT_GT(g.restarts, 0);
  EXPECT_EQ(g.iterations, f.iterations);
  EXPECT_EQ(g.restarts, f.restarts);
  EXPECT_LE(g.relativeResidual, 1e-10);
  EXPECT_LT(relativeError(xg, xf), 1e-9);
  EXPECT_LT(relativeError(xg, exact), 1e-7);
}

TEST(Gmres, SolveIsBitIdenticalAcrossThreadCounts) {
  const std::size_t n = kSplitSize;
  const CsrMatrix A = shiftedLaplacian1d(n, 0.5);
  const Vector b = randomVector(n, 94), d = A.diagonal();
  expectSolveBitIdenticalForOneAndTwoThreads(n, [&](Vector& x) {
    SolveOptions opt = tolerance(1e-10);
    opt.restart = 5;  // restarts, so the cycle's end (x += M^-1 V y) runs too
    return gmres(A, b.data(), x.data(), JacobiPreconditioner(d), opt);
  });
}

// ---- saddle-point block preconditioners ----------------------------------------------------------

// K = [A B^T; B 0] with A SPD (a shifted 1D Laplacian, n_u rows) and B a full-rank random n_c x n_u
// block, and the exact blocks A^-1 and S^-1 = (B A^-1 B^T)^-1 as a split preconditioner.
struct SaddlePoint {
  std::size_t nu, nc;
  Eigen::MatrixXd K, Ainv, Sinv;
  CsrMatrix Kcsr;

  SaddlePoint(std::size_t u, std::size_t c, std::uint64_t seed) : nu(u), nc(c) {
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(Eigen::Index(nu), Eigen::Index(nu));
    for (Eigen::Index i = 0; i < Eigen::Index(nu); ++i) {
      A(i, i) = 2.5;
      if (i > 0) A(i, i - 1) = A(i - 1, i) = -1.0;
    }
    const Vector random = randomVector(nc * nu, seed);
    Eigen::MatrixXd B(static_cast<Eigen::Index>(nc), static_cast<Eigen::Index>(nu));
    for (Eigen::Index i = 0; i < B.rows(); ++i)
      for (Eigen::Index j = 0; j < B.cols(); ++j) B(i, j) = random[std::size_t(i * B.cols() + j)];
    K = Eigen::MatrixXd::Zero(Eigen::Index(nu + nc), Eigen::Index(nu + nc));
    K.topLeftCorner(A.rows(), A.cols()) = A;
    K.bottomLeftCorner(B.rows(), B.cols()) = B;
    K.topRightCorner(B.cols(), B.rows()) = B.transpose();
    Ainv = A.inverse();
    Sinv = (B * Ainv * B.transpose()).inverse();
    CsrBuilder builder(nu + nc);
    for (Eigen::Index i = 0; i < K.rows(); ++i)
      for (Eigen::Index j = 0; j < K.cols(); ++j)
        if (K(i, j) != 0.0) builder.add(std::size_t(i), std::size_t(j), K(i, j));
    Kcsr = builder.build();
  }
};

// diag(A^-1, S^-1), each part applied alone (the SplitPreconditioner interface).
struct ExactBlocks {
  const SaddlePoint& k;
  std::size_t size() const { return k.nu + k.nc; }
  void apply(const double* r, double* z) const { applyRows(r, z, 0, size()); }
  void applyRows(const double* r, double* z, std::size_t begin, std::size_t end) const {
    if (begin < k.nu) block(k.Ainv, r, z);
    if (end > k.nu) block(k.Sinv, r + k.nu, z + k.nu);
  }
  static void block(const Eigen::MatrixXd& inverse, const double* r, double* z) {
    Eigen::Map<Eigen::VectorXd>(z, inverse.rows()) = inverse * Eigen::Map<const Eigen::VectorXd>(r, inverse.rows());
  }
};
static_assert(ops::SplitPreconditioner<ExactBlocks>);

// With exact blocks, K P^-1 = [I 0; B A^-1 I] for the upper-triangular P: (K P^-1 - I)^2 = 0, so
// GMRES finishes in two iterations. The block-diagonal P gives P^-1 K three eigenvalues, 1 and
// (1 +- sqrt 5) / 2 (Murphy, Golub & Wathen 2000), so MINRES finishes in three.
TEST(SaddlePointPreconditioner, ExactBlocksFixTheIterations) {
  const SaddlePoint k(40, 12, 106);
  const ExactBlocks blocks{k};
  const Vector exact = randomVector(k.nu + k.nc, 107);
  const Vector b = times(k.Kcsr, exact);
  using P = ops::SaddlePointPreconditioner<CsrMatrix, ExactBlocks>;
  const P triangular(k.Kcsr, blocks, k.nu, ops::SaddlePointBlocks::UpperTriangular);
  const P diagonal(k.Kcsr, blocks, k.nu, ops::SaddlePointBlocks::Diagonal);
  Vector xg(b.size(), 0.0), xm(b.size(), 0.0);
  const SolveResult g = gmres(k.Kcsr, b.data(), xg.data(), triangular, tolerance(1e-11));
  const SolveResult m = minres(k.Kcsr, b.data(), xm.data(), diagonal, tolerance(1e-11));
  ASSERT_EQ(g.status, Status::Converged);
  ASSERT_EQ(m.status, Status::Converged);
  EXPECT_EQ(g.iterations, 2);
  EXPECT_EQ(m.iterations, 3);
  EXPECT_LT(relativeError(xg, exact), 1e-9);
  EXPECT_LT(relativeError(xm, exact), 1e-9);
}

// The triangular apply itself: P z = r with P = [A_hat B^T; 0 -S_hat] for the blocks given.
TEST(SaddlePointPreconditioner, UpperTriangularApplySolvesTheTriangularSystem) {
  const SaddlePoint k(25, 7, 108);
  const ExactBlocks blocks{k};
  const ops::SaddlePointPreconditioner triangular(k.Kcsr, blocks, k.nu, ops::SaddlePointBlocks::UpperTriangular);
  const Vector r = randomVector(k.nu + k.nc, 109);
  Vector z(r.size());
  triangular.apply(r.data(), z.data());
  Eigen::MatrixXd P = Eigen::MatrixXd::Zero(k.K.rows(), k.K.cols());
  P.topLeftCorner(Eigen::Index(k.nu), Eigen::Index(k.nu)) = k.Ainv.inverse();
  P.topRightCorner(Eigen::Index(k.nu), Eigen::Index(k.nc)) = k.K.topRightCorner(Eigen::Index(k.nu), Eigen::Index(k.nc));
  P.bottomRightCorner(Eigen::Index(k.nc), Eigen::Index(k.nc)) = -k.Sinv.inverse();
  const Eigen::VectorXd Pz = P * Eigen::Map<const Eigen::VectorXd>(z.data(), Eigen::Index(z.size()));
  for (std::size_t i = 0; i < r.size(); ++i) EXPECT_NEAR(Pz[Eigen::Index(i)], r[i], 1e-10 * (1.0 + std::abs(r[i]))) << i;
}

}  // namespace

// ---- stopping on request ---------------------------------------------------------------------------

// SolveOptions::stopRequested is asked once per iteration: every method stops at the iteration it
// first says yes, with Status::Interrupted and a finite iterate; without it the same solve converges.
TEST(StopRequested, EveryMethodStopsAtTheIterationItIsAskedTo) {
  const CsrMatrix A = poisson2d(40);
  const Vector b = times(A, randomVector(A.size(), 7));
  const JacobiPreconditioner M(A.diagonal());
  using Solve = std::function<SolveResult(double*, const SolveOptions&)>;
  const std::vector<std::pair<const char*, Solve>> methods = {
      {"cg", [&](double* x, const SolveOptions& o) { return conjugateGradient(A, b.data(), x, M, o); }},
      {"bicgstab", [&](double* x, const SolveOptions& o) { return bicgstab(A, b.data(), x, M, o); }},
      {"minres", [&](double* x, const SolveOptions& o) { return minres(A, b.data(), x, M, o); }},
      {"gmres", [&](double* x, const SolveOptions& o) { return gmres(A, b.data(), x, M, o); }},
      {"fgmres", [&](double* x, const SolveOptions& o) { return fgmres(A, b.data(), x, M, o); }}};
  for (const auto& [name, solve] : methods) {
    SCOPED_TRACE(name);
    SolveOptions opt = tolerance(1e-10);
    Vector x(A.size(), 0.0);
    ASSERT_EQ(solve(x.data(), opt).status, Status::Converged);
    int asked = 0;
    opt.stopRequested = [&] { return ++asked == 5; };
    std::fill(x.begin(), x.end(), 0.0);
    const SolveResult stopped = solve(x.data(), opt);
    EXPECT_EQ(stopped.status, Status::Interrupted);
    EXPECT_EQ(asked, 5);
    EXPECT_EQ(stopped.iterations, 5);
    for (double v : x) ASSERT_TRUE(std::isfinite(v));
  }
}
