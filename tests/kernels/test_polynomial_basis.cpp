// The polynomial bases of reduced tiles (kernels/polynomial_basis.h):
//  - sizes and names of the 8 (Dim, order, family) combinations;
//  - each column is the field the header documents (checked against formulas written out here);
//  - divergence-free fields have zero divergence; divergence() matches finite differences;
//  - the divergence-free family spans exactly the divergence-free polynomials of its degree
//    (independent columns + dimension count from the divergence constraint map), the full family
//    spans all polynomial fields of its degree (least-squares reproduction);
//  - the quadratic divergence-free family reproduces curls of random cubic potentials, the affine
//    one does not;
//  - evaluateComponent == the rows of evaluate() and writes nothing past size().
// Linear algebra is hand written (Gaussian elimination with full pivoting, Householder least
// squares) so the test only needs the header.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "kernels/polynomial_basis.h"

namespace stokes {
namespace {

using kernels::BasisFamily;
using kernels::PolynomialBasis;
using kernels::PolynomialOrder;

constexpr std::array<PolynomialOrder, 2> kOrders{PolynomialOrder::Affine, PolynomialOrder::Quadratic};
constexpr std::array<BasisFamily, 2> kFamilies{BasisFamily::DivergenceFree, BasisFamily::Full};

template <int Dim>
std::vector<PolynomialBasis<Dim>> allBases() {
  std::vector<PolynomialBasis<Dim>> out;
  for (auto f : kFamilies)
    for (auto o : kOrders) out.emplace_back(o, f);
  return out;
}

int degreeOf(PolynomialOrder o) { return o == PolynomialOrder::Affine ? 1 : 2; }

// ---------------------------------------------------------------------------------------------
// Small dense linear algebra (row-major matrices as vector<double> with explicit sizes).

/// Rank by Gaussian elimination with full pivoting; tolerance relative to the largest entry.
int rankOf(std::vector<double> A, int rows, int cols, double relTol = 1e-10) {
  double maxAbs = 0.0;
  for (double v : A) maxAbs = std::max(maxAbs, std::abs(v));
  if (maxAbs == 0.0) return 0;
  std::vector<int> colPerm(cols);
  for (int j = 0; j < cols; ++j) colPerm[j] = j;
  int rank = 0;
  for (int step = 0; step < std::min(rows, cols); ++step) {
    int pr = -1, pc = -1;
    double best = 0.0;
    for (int i = step; i < rows; ++i)
      for (int j = step; j < cols; ++j)
        if (std::abs(A[i * cols + j]) > best) {
          best = std::abs(A[i * cols + j]);
          pr = i;
          pc = j;
        }
    if (best <= relTol * maxAbs) break;
    for (int j = 0; j < cols; ++j) std::swap(A[step * cols + j], A[pr * cols + j]);
    for (int i = 0; i < rows; ++i) std::swap(A[i * cols + step], A[i * cols + pc]);
    for (int i = step + 1; i < rows; ++i) {
      const double f = A[i * cols + step] / A[step * cols + step];
      for (int j = step; j < cols; ++j) A[i * cols + j] -= f * A[step * cols + j];
    }
    ++rank;
  }
  return rank;
}

/// min ||A c - b|| by Householder QR (A full column rank); returns ||A c - b|| / ||b||.
double leastSquaresRelativeResidual(std::vector<double> A, int rows, int cols, std::vector<double> b) {
  double bNorm = 0.0;
  for (double v : b) bNorm += v * v;
  bNorm = std::sqrt(bNorm);
  for (int k = 0; k < cols; ++k) {
    double norm = 0.0;
    for (int i = k; i < rows; ++i) norm += A[i * cols + k] * A[i * cols + k];
    norm = std::sqrt(norm);
    if (norm == 0.0) continue;
    const double alpha = A[k * cols + k] > 0 ? -norm : norm;
    std::vector<double> v(rows, 0.0);
    for (int i = k; i < rows; ++i) v[i] = A[i * cols + k];
    v[k] -= alpha;
    double vv = 0.0;
    for (int i = k; i < rows; ++i) vv += v[i] * v[i];
    if (vv == 0.0) continue;
    for (int j = k; j < cols; ++j) {
      double s = 0.0;
      for (int i = k; i < rows; ++i) s += v[i] * A[i * cols + j];
      s = 2.0 * s / vv;
      for (int i = k; i < rows; ++i) A[i * cols + j] -= s * v[i];
    }
    double s = 0.0;
    for (int i = k; i < rows; ++i) s += v[i] * b[i];
    s = 2.0 * s / vv;
    for (int i = k; i < rows; ++i) b[i] -= s * v[i];
  }
  // Q^T b = (R c, r): the residual norm is the norm of the trailing rows.
  double r = 0.0;
  for (int i = cols; i < rows; ++i) r += b[i] * b[i];
  return std::sqrt(r) / bNorm;
}

// ---------------------------------------------------------------------------------------------
// Independent polynomials: sum of coeff * x^e, with derivatives, evaluated by std::pow.

template <int Dim>
struct Poly {
  std::vector<std::pair<std::array<int, Dim>, double>> terms;

  double operator()(const double* xs) const {
    double s = 0.0;
    for (const auto& [e, c] : terms) {
      double v = c;
      for (int d = 0; d < Dim; ++d) v *= std::pow(xs[d], e[d]);
      s += v;
    }
    return s;
  }
  Poly derivative(int c) const {
    Poly out;
    for (const auto& [e, coef] : terms) {
      if (e[c] == 0) continue;
      auto e2 = e;
      e2[c] -= 1;
      out.terms.push_back({e2, coef * e[c]});
    }
    return out;
  }
  Poly operator-(const Poly& o) const {
    Poly out = *this;
    for (const auto& [e, c] : o.terms) out.terms.push_back({e, -c});
    return out;
  }
};

/// All exponent vectors of total degree <= deg.
template <int Dim>
std::vector<std::array<int, Dim>> exponentsUpTo(int deg) {
  std::vector<std::array<int, Dim>> out;
  if constexpr (Dim == 2) {
    for (int t = 0; t <= deg; ++t)
      for (int i = t; i >= 0; --i) out.push_back({i, t - i});
  } else {
    for (int t = 0; t <= deg; ++t)
      for (int i = t; i >= 0; --i)
        for (int j = t - i; j >= 0; --j) out.push_back({i, j, t - i - j});
  }
  return out;
}

template <int Dim>
Poly<Dim> randomPoly(int deg, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Poly<Dim> p;
  for (const auto& e : exponentsUpTo<Dim>(deg)) p.terms.push_back({e, u(rng)});
  return p;
}

template <int Dim>
std::array<double, Dim> randomPoint(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::array<double, Dim> x;
  for (auto& v : x) v = u(rng);
  return x;
}

/// Rows (point, component) x columns (basis fields) of C at random points, and the matching
/// values of a target field.
template <int Dim>
void sample(const PolynomialBasis<Dim>& basis, int numPoints, std::mt19937_64& rng,
            std::vector<double>& A, const std::array<Poly<Dim>, Dim>* target, std::vector<double>* b) {
  const int n = basis.size();
  A.assign(static_cast<std::size_t>(numPoints) * Dim * n, 0.0);
  if (b) b->assign(static_cast<std::size_t>(numPoints) * Dim, 0.0);
  for (int p = 0; p < numPoints; ++p) {
    const auto x = randomPoint<Dim>(rng);
    basis.evaluate(x.data(), A.data() + static_cast<std::size_t>(p) * Dim * n);  // row-major Dim x n
    if (b)
      for (int a = 0; a < Dim; ++a) (*b)[p * Dim + a] = (*target)[a](x.data());
  }
}

template <class T>
class PolynomialBasisTest : public ::testing::Test {};
using Dims = ::testing::Types<std::integral_constant<int, 2>, std::integral_constant<int, 3>>;
TYPED_TEST_SUITE(PolynomialBasisTest, Dims);

TEST(PolynomialBasis, SizesAndNames) {
  using O = PolynomialOrder;
  using F = BasisFamily;
  EXPECT_EQ(PolynomialBasis<2>(O::Affine, F::DivergenceFree).size(), 5);
  EXPECT_EQ(PolynomialBasis<2>(O::Quadratic, F::DivergenceFree).size(), 9);
  EXPECT_EQ(PolynomialBasis<3>(O::Affine, F::DivergenceFree).size(), 11);
  EXPECT_EQ(PolynomialBasis<3>(O::Quadratic, F::DivergenceFree).size(), 26);
  EXPECT_EQ(PolynomialBasis<2>(O::Affine, F::Full).size(), 6);
  EXPECT_EQ(PolynomialBasis<2>(O::Quadratic, F::Full).size(), 12);
  EXPECT_EQ(PolynomialBasis<3>(O::Affine, F::Full).size(), 12);
  EXPECT_EQ(PolynomialBasis<3>(O::Quadratic, F::Full).size(), 30);
  static_assert(PolynomialBasis<3>::sizeOf(O::Quadratic, F::DivergenceFree) == 26);
  static_assert(PolynomialBasis<2>::kMaxSize == 12 && PolynomialBasis<3>::kMaxSize == 30);
  EXPECT_STREQ(PolynomialBasis<3>(O::Affine, F::DivergenceFree).name(), "affine-divfree-11");
  EXPECT_STREQ(PolynomialBasis<2>(O::Quadratic, F::Full).name(), "quadratic-full-12");
  for (const auto& b : allBases<2>()) EXPECT_LE(b.size(), PolynomialBasis<2>::kMaxSize);
  for (const auto& b : allBases<3>()) EXPECT_LE(b.size(), PolynomialBasis<3>::kMaxSize);
  const PolynomialBasis<2> b(O::Quadratic, F::Full);
  EXPECT_EQ(b.order(), O::Quadratic);
  EXPECT_EQ(b.family(), F::Full);
}

// Every column is the field listed in the header (formulas restated independently here).
TYPED_TEST(PolynomialBasisTest, ColumnsAreTheDocumentedFields) {
  constexpr int Dim = TypeParam::value;
  using Field = std::function<std::array<double, Dim>(double, double, double)>;
  std::vector<Field> divfree;
  if constexpr (Dim == 2) {
    using V = std::array<double, 2>;
    divfree = {
        [](double, double, double) { return V{1, 0}; },
        [](double, double, double) { return V{0, 1}; },
        [](double x, double y, double) { return V{x, -y}; },
        [](double, double y, double) { return V{y, 0}; },
        [](double x, double, double) { return V{0, x}; },
        [](double x, double y, double) { return V{x * x, -2 * x * y}; },
        [](double, double y, double) { return V{y * y, 0}; },
        [](double x, double, double) { return V{0, x * x}; },
        [](double x, double y, double) { return V{-2 * x * y, y * y}; },
    };
  } else {
    using V = std::array<double, 3>;
    divfree = {
        [](double, double, double) { return V{1, 0, 0}; },
        [](double, double, double) { return V{0, 1, 0}; },
        [](double, double, double) { return V{0, 0, 1}; },
        [](double x, double, double z) { return V{x, 0, -z}; },
        [](double, double y, double) { return V{y, 0, 0}; },
        [](double, double, double z) { return V{z, 0, 0}; },
        [](double x, double, double) { return V{0, x, 0}; },
        [](double, double y, double z) { return V{0, y, -z}; },
        [](double, double, double z) { return V{0, z, 0}; },
        [](double x, double, double) { return V{0, 0, x}; },
        [](double, double y, double) { return V{0, 0, y}; },
        [](double x, double, double z) { return V{x * x, 0, -2 * x * z}; },
        [](double x, double y, double z) { return V{x * y, 0, -y * z}; },
        [](double x, double, double z) { return V{x * z, 0, -z * z / 2}; },
        [](double, double y, double) { return V{y * y, 0, 0}; },
        [](double, double y, double z) { return V{y * z, 0, 0}; },
        [](double, double, double z) { return V{z * z, 0, 0}; },
        [](double x, double, double) { return V{0, x * x, 0}; },
        [](double x, double y, double z) { return V{0, x * y, -x * z}; },
        [](double x, double, double z) { return V{0, x * z, 0}; },
        [](double, double y, double z) { return V{0, y * y, -2 * y * z}; },
        [](double, double y, double z) { return V{0, y * z, -z * z / 2}; },
        [](double, double, double z) { return V{0, z * z, 0}; },
        [](double x, double, double) { return V{0, 0, x * x}; },
        [](double x, double y, double) { return V{0, 0, x * y}; },
        [](double, double y, double) { return V{0, 0, y * y}; },
    };
  }
  // Full family: constants, then linear, then quadratic monomials, each times e_0..e_{Dim-1}.
  std::vector<std::array<int, Dim>> mono = exponentsUpTo<Dim>(2);
  // exponentsUpTo lists degree 1 as x, y(, z) and degree 2 as x^2, xy, (xz,) y^2, (yz, z^2):
  // the header's monomial order.
  std::mt19937_64 rng(3);
  for (const auto& basis : allBases<Dim>()) {
    SCOPED_TRACE(basis.name());
    const int n = basis.size();
    for (int p = 0; p < 20; ++p) {
      const auto x = randomPoint<Dim>(rng);
      std::array<double, Dim * PolynomialBasis<Dim>::kMaxSize> C{};
      basis.evaluate(x.data(), C.data());
      const double z = Dim == 3 ? x[Dim - 1] : 0.0;
      for (int k = 0; k < n; ++k) {
        std::array<double, Dim> expect{};
        if (basis.family() == BasisFamily::DivergenceFree) {
          expect = divfree[k](x[0], x[1], z);
        } else {
          Poly<Dim> m;
          m.terms.push_back({mono[k / Dim], 1.0});
          expect[k % Dim] = m(x.data());
        }
        for (int a = 0; a < Dim; ++a) EXPECT_NEAR(C[a * n + k], expect[a], 1e-15) << "field " << k << " comp " << a;
      }
    }
  }
}

TYPED_TEST(PolynomialBasisTest, DivergenceFreeFieldsHaveZeroDivergence) {
  constexpr int Dim = TypeParam::value;
  std::mt19937_64 rng(5);
  for (auto o : kOrders) {
    const PolynomialBasis<Dim> basis(o, BasisFamily::DivergenceFree);
    SCOPED_TRACE(basis.name());
    const int n = basis.size();
    for (int p = 0; p < 200; ++p) {
      const auto x = randomPoint<Dim>(rng);
      std::array<double, PolynomialBasis<Dim>::kMaxSize> div;
      basis.divergence(x.data(), div.data());
      // A central difference with step H is exact for polynomials of degree <= 2, so a large
      // step gives the divergence of evaluate() itself up to rounding.
      const double H = 0.5;
      std::array<double, PolynomialBasis<Dim>::kMaxSize> fdDiv{};
      for (int c = 0; c < Dim; ++c) {
        auto xp = x, xm = x;
        xp[c] += H;
        xm[c] -= H;
        std::array<double, PolynomialBasis<Dim>::kMaxSize> rp, rm;
        basis.evaluateComponent(c, xp.data(), rp.data());
        basis.evaluateComponent(c, xm.data(), rm.data());
        for (int k = 0; k < n; ++k) fdDiv[k] += (rp[k] - rm[k]) / (2 * H);
      }
      for (int k = 0; k < n; ++k) {
        EXPECT_LE(std::abs(div[k]), 1e-14) << "field " << k;
        EXPECT_LE(std::abs(fdDiv[k]), 1e-14) << "field " << k;
      }
    }
  }
}

TYPED_TEST(PolynomialBasisTest, DivergenceMatchesFiniteDifferences) {
  constexpr int Dim = TypeParam::value;
  constexpr int M = PolynomialBasis<Dim>::kMaxSize;
  std::mt19937_64 rng(7);
  const double h = 1e-6;
  for (const auto& basis : allBases<Dim>()) {
    SCOPED_TRACE(basis.name());
    const int n = basis.size();
    double maxDiv = 0.0;
    for (int p = 0; p < 50; ++p) {
      const auto x = randomPoint<Dim>(rng);
      std::array<double, M> div;
      basis.divergence(x.data(), div.data());
      std::array<double, M> fd{};
      for (int c = 0; c < Dim; ++c) {
        auto xp = x, xm = x;
        xp[c] += h;
        xm[c] -= h;
        std::array<double, Dim * M> Cp, Cm;
        basis.evaluate(xp.data(), Cp.data());
        basis.evaluate(xm.data(), Cm.data());
        for (int k = 0; k < n; ++k) fd[k] += (Cp[c * n + k] - Cm[c * n + k]) / (2 * h);
      }
      for (int k = 0; k < n; ++k) {
        EXPECT_NEAR(div[k], fd[k], 1e-7) << "field " << k;
        maxDiv = std::max(maxDiv, std::abs(div[k]));
      }
    }
    // The full family is not divergence free: make sure the comparison is not vacuous.
    if (basis.family() == BasisFamily::Full) {
      EXPECT_GT(maxDiv, 0.5);
    }
  }
}

// Dimension of the divergence-free polynomial fields of degree <= k, computed from the linear
// map (coefficients of u) -> (coefficients of div u): nullity = Dim * #monomials - rank.
template <int Dim>
int divergenceConstraintRank(int deg) {
  const auto mono = exponentsUpTo<Dim>(deg);
  const auto lower = exponentsUpTo<Dim>(deg - 1);
  const int cols = Dim * static_cast<int>(mono.size());
  const int rows = static_cast<int>(lower.size());
  std::vector<double> D(static_cast<std::size_t>(rows) * cols, 0.0);
  for (int j = 0; j < static_cast<int>(mono.size()); ++j)
    for (int c = 0; c < Dim; ++c) {
      if (mono[j][c] == 0) continue;
      auto e = mono[j];
      e[c] -= 1;  // d/dx_c x^e = e_c x^(e - unit_c)
      for (int r = 0; r < rows; ++r)
        if (lower[r] == e) D[r * cols + j * Dim + c] += mono[j][c];
    }
  return rankOf(D, rows, cols);
}

TYPED_TEST(PolynomialBasisTest, DivergenceFreeFamilySpansDivergenceFreePolynomials) {
  constexpr int Dim = TypeParam::value;
  std::mt19937_64 rng(13);
  for (auto o : kOrders) {
    const PolynomialBasis<Dim> basis(o, BasisFamily::DivergenceFree);
    SCOPED_TRACE(basis.name());
    const int deg = degreeOf(o);
    const int numMono = static_cast<int>(exponentsUpTo<Dim>(deg).size());
    const int constraints = deg == 1 ? 1 : 1 + Dim;  // div u has degree <= deg - 1
    EXPECT_EQ(divergenceConstraintRank<Dim>(deg), constraints);
    const int dimDivFree = Dim * numMono - constraints;
    EXPECT_EQ(basis.size(), dimDivFree);
    const int expected = Dim == 2 ? (deg == 1 ? 5 : 9) : (deg == 1 ? 11 : 26);
    EXPECT_EQ(dimDivFree, expected);
    // Columns linearly independent (and zero divergence, tested above) => they span the space.
    std::vector<double> A;
    const int pts = 3 * basis.size();
    sample<Dim>(basis, pts, rng, A, nullptr, nullptr);
    EXPECT_EQ(rankOf(A, pts * Dim, basis.size()), basis.size());
  }
}

TYPED_TEST(PolynomialBasisTest, FullFamilySpansAllPolynomialFields) {
  constexpr int Dim = TypeParam::value;
  std::mt19937_64 rng(17);
  for (auto o : kOrders) {
    const PolynomialBasis<Dim> basis(o, BasisFamily::Full);
    SCOPED_TRACE(basis.name());
    const int deg = degreeOf(o);
    EXPECT_EQ(basis.size(), Dim * static_cast<int>(exponentsUpTo<Dim>(deg).size()));
    std::array<Poly<Dim>, Dim> target;
    for (auto& t : target) t = randomPoly<Dim>(deg, rng);
    std::vector<double> A, b;
    const int pts = 3 * basis.size();
    sample<Dim>(basis, pts, rng, A, &target, &b);
    EXPECT_EQ(rankOf(A, pts * Dim, basis.size()), basis.size());
    EXPECT_LT(leastSquaresRelativeResidual(A, pts * Dim, basis.size(), b), 1e-10);
    // A field of higher degree is not in the span.
    std::array<Poly<Dim>, Dim> higher;
    for (auto& t : higher) t = randomPoly<Dim>(deg + 1, rng);
    sample<Dim>(basis, pts, rng, A, &higher, &b);
    EXPECT_GT(leastSquaresRelativeResidual(A, pts * Dim, basis.size(), b), 1e-3);
  }
}

/// A random divergence-free quadratic field: 2D u = (dpsi/dy, -dpsi/dx) for a cubic stream
/// function psi; 3D u = curl A for a cubic vector potential A.
template <int Dim>
std::array<Poly<Dim>, Dim> randomDivergenceFreeQuadratic(std::mt19937_64& rng) {
  if constexpr (Dim == 2) {
    const Poly<2> psi = randomPoly<2>(3, rng);
    const Poly<2> zero;
    return {psi.derivative(1), zero - psi.derivative(0)};
  } else {
    const std::array<Poly<3>, 3> A{randomPoly<3>(3, rng), randomPoly<3>(3, rng), randomPoly<3>(3, rng)};
    return {A[2].derivative(1) - A[1].derivative(2), A[0].derivative(2) - A[2].derivative(0),
            A[1].derivative(0) - A[0].derivative(1)};
  }
}

TYPED_TEST(PolynomialBasisTest, QuadraticDivergenceFreeReproducesCurlOfCubicPotential) {
  constexpr int Dim = TypeParam::value;
  std::mt19937_64 rng(19);
  const PolynomialBasis<Dim> quad(PolynomialOrder::Quadratic, BasisFamily::DivergenceFree);
  const PolynomialBasis<Dim> affine(PolynomialOrder::Affine, BasisFamily::DivergenceFree);
  for (int trial = 0; trial < 3; ++trial) {
    const auto target = randomDivergenceFreeQuadratic<Dim>(rng);
    // sanity: the target is divergence free
    const auto x0 = randomPoint<Dim>(rng);
    double div = 0.0;
    for (int c = 0; c < Dim; ++c) div += target[c].derivative(c)(x0.data());
    ASSERT_NEAR(div, 0.0, 1e-12);
    std::vector<double> A, b;
    const int pts = 3 * quad.size();
    sample<Dim>(quad, pts, rng, A, &target, &b);
    EXPECT_LT(leastSquaresRelativeResidual(A, pts * Dim, quad.size(), b), 1e-10);
    sample<Dim>(affine, pts, rng, A, &target, &b);
    EXPECT_GT(leastSquaresRelativeResidual(A, pts * Dim, affine.size(), b), 1e-3);
  }
}

TYPED_TEST(PolynomialBasisTest, EvaluateComponentIsARowOfEvaluate) {
  constexpr int Dim = TypeParam::value;
  constexpr int M = PolynomialBasis<Dim>::kMaxSize;
  std::mt19937_64 rng(23);
  for (const auto& basis : allBases<Dim>()) {
    SCOPED_TRACE(basis.name());
    const int n = basis.size();
    for (int p = 0; p < 50; ++p) {
      const auto x = randomPoint<Dim>(rng);
      std::array<double, Dim * M> C;
      basis.evaluate(x.data(), C.data());
      for (int a = 0; a < Dim; ++a) {
        std::array<double, M> row;
        row.fill(std::numeric_limits<double>::quiet_NaN());
        basis.evaluateComponent(a, x.data(), row.data());
        for (int k = 0; k < n; ++k) EXPECT_EQ(row[k], C[a * n + k]) << "axis " << a << " field " << k;
        for (int k = n; k < M; ++k) EXPECT_TRUE(std::isnan(row[k])) << "wrote past size() at " << k;
      }
    }
  }
}

// The monomial form of a component (componentCoefficients, monomials) is the component itself:
// row[k] = sum_m coeff[m][k] monomial_m(x) for every family, axis and field, and every field
// uses only the family's monomialCount() monomials.
TYPED_TEST(PolynomialBasisTest, ComponentCoefficientsTimesMonomialsAreTheRow) {
  constexpr int Dim = TypeParam::value;
  constexpr int M = PolynomialBasis<Dim>::kMaxSize, K = PolynomialBasis<Dim>::kMaxMonomials;
  std::mt19937_64 rng(31);
  for (const auto& basis : allBases<Dim>()) {
    SCOPED_TRACE(basis.name());
    const int n = basis.size(), count = basis.monomialCount();
    EXPECT_EQ(count, basis.order() == PolynomialOrder::Affine ? 1 + Dim : K);
    for (int a = 0; a < Dim; ++a) {
      std::array<double, K * M> coeff;
      coeff.fill(std::numeric_limits<double>::quiet_NaN());
      basis.componentCoefficients(a, coeff.data());
      for (int i = count * n; i < K * M; ++i) ASSERT_TRUE(std::isnan(coeff[i])) << "wrote past count * size() at " << i;
      for (int p = 0; p < 20; ++p) {
        const auto x = randomPoint<Dim>(rng);
        std::array<double, M> row;
        std::array<double, K> mono;
        basis.evaluateComponent(a, x.data(), row.data());
        PolynomialBasis<Dim>::monomials(x.data(), count, mono.data());
        for (int k = 0; k < n; ++k) {
          double sum = 0.0;
          for (int m = 0; m < count; ++m) sum += coeff[m * n + k] * mono[m];
          EXPECT_DOUBLE_EQ(sum, row[k]) << "axis " << a << " field " << k;
        }
      }
    }
  }
}

TYPED_TEST(PolynomialBasisTest, FirstDimColumnsAreConstantFields) {
  constexpr int Dim = TypeParam::value;
  constexpr int M = PolynomialBasis<Dim>::kMaxSize;
  std::mt19937_64 rng(29);
  for (const auto& basis : allBases<Dim>()) {
    SCOPED_TRACE(basis.name());
    const int n = basis.size();
    const auto x = randomPoint<Dim>(rng);
    std::array<double, Dim * M> C;
    basis.evaluate(x.data(), C.data());
    for (int k = 0; k < Dim; ++k)
      for (int a = 0; a < Dim; ++a) EXPECT_EQ(C[a * n + k], a == k ? 1.0 : 0.0);
  }
}

}  // namespace
}  // namespace stokes
