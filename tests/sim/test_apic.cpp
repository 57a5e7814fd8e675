// The particle layer: quadratic B-spline weights, APIC P2G / G2P on the staggered faces, face
// velocity sampling and extrapolation, RK2 advection, solid push-out, seeding and reseeding.
// Every expected number below follows from the maths stated in the sim/ headers.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <random>

#include "sim/particles/advection.h"
#include "sim/particles/apic_transfer.h"
#include "sim/particles/grid_velocity.h"
#include "sim/particles/particles.h"
#include "sim/particles/reseed.h"
#include "tests/parallel_path.h"
#include "tests/test_helpers.h"

namespace stokes {
namespace {

using openvdb::Coord;
using openvdb::Vec3d;
using sim::ParticleSet;

template <class T>
class ApicTest : public ::testing::Test {};
using Dims = ::testing::Types<std::integral_constant<int, 2>, std::integral_constant<int, 3>>;
TYPED_TEST_SUITE(ApicTest, Dims);

/// A non-trivial origin, so that a transfer that forgets it fails.
template <int Dim>
Vec3d testOrigin() {
  return Vec3d(0.13, -0.21, Dim == 3 ? 0.07 : 0.0);
}

/// Layout of the cells [0, cells)^Dim (z = 0 in 2D).
template <int Dim>
sparse_grid::BlockLayout<Dim> boxLayout(int cells, double dx) {
  openvdb::MaskTree mask;
  sparse_grid::activateBox(mask, Coord(0), Coord(cells - 1, cells - 1, Dim == 3 ? cells - 1 : 0));
  return sparse_grid::BlockLayout<Dim>(mask, dx, testOrigin<Dim>());
}

/// `count` particles uniform in the cells [lo, hi)^Dim, zero velocity.
template <int Dim>
ParticleSet<Dim> randomParticles(const sparse_grid::BlockLayout<Dim>& layout, double lo, double hi, std::size_t count,
                                 std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(lo, hi);
  ParticleSet<Dim> ps;
  for (std::size_t p = 0; p < count; ++p) {
    Vec3d x(0.0);
    for (int a = 0; a < Dim; ++a) x[a] = layout.origin()[a] + layout.dx() * u(rng);
    ps.push_back(x, Vec3d(0.0));
  }
  return ps;
}

/// Face array with u_a(x_f) = field(a, x_f) on every slot.
template <int Dim, class Field>
solver::Vector sampleOnFaces(const sparse_grid::BlockLayout<Dim>& layout, const Field& field) {
  const std::size_t n = layout.numSlots();
  solver::Vector u(Dim * n);
  for (int a = 0; a < Dim; ++a)
    for (std::size_t s = 0; s < n; ++s) u[a * n + s] = field(a, layout.samplePosition(s, sparse_grid::faceMask(a)));
  return u;
}

/// A random affine field u_a(x) = A_a + B_a . x.
template <int Dim>
struct AffineField {
  std::array<double, Dim> A;
  std::array<Vec3d, Dim> B;
  explicit AffineField(std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int a = 0; a < Dim; ++a) {
      A[a] = u(rng);
      B[a] = Vec3d(0.0);
      for (int b = 0; b < Dim; ++b) B[a][b] = u(rng);
    }
  }
  double operator()(int a, const Vec3d& x) const { return A[a] + B[a].dot(x); }
};

// --- weights --------------------------------------------------------------------------------

TEST(QuadraticBSpline, PartitionOfUnityLinearReproductionAndSecondMoment) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(-20.0, 20.0);
  for (int t = 0; t < 1000; ++t) {
    const double g = u(rng);
    const auto st = sim::quadraticStencil(g);
    double sum = 0.0, first = 0.0, second = 0.0;
    for (int j = 0; j < 3; ++j) {
      const double r = double(st.base + j) - g;
      sum += st.w[j];
      first += st.w[j] * r;
      second += st.w[j] * r * r;
      EXPECT_GE(st.w[j], 0.0);
    }
    EXPECT_NEAR(sum, 1.0, 1e-14);     // partition of unity
    EXPECT_NEAR(first, 0.0, 1e-14);   // sum w x_i = x_p
    EXPECT_NEAR(second, 0.25, 1e-14); // D = dx^2/4 I, so D^-1 = 4/dx^2
    // No weight outside the three nodes.
    EXPECT_EQ(sim::quadraticBSpline(double(st.base - 1) - g), 0.0);
    EXPECT_EQ(sim::quadraticBSpline(double(st.base + 3) - g), 0.0);
  }
}

// --- G2P / P2G on affine fields -------------------------------------------------------------

TYPED_TEST(ApicTest, GridToParticlesIsExactForAffineFields) {
  constexpr int Dim = TypeParam::value;
  const auto layout = boxLayout<Dim>(16, 0.1);
  std::mt19937_64 rng(2);
  const AffineField<Dim> field(rng);
  const solver::Vector u = sampleOnFaces<Dim>(layout, field);
  auto ps = randomParticles<Dim>(layout, 2.0, 14.0, 500, rng);
  sim::gridToParticles<Dim>(layout, u, ps);
  for (std::size_t p = 0; p < ps.size(); ++p)
    for (int a = 0; a < Dim; ++a) {
      EXPECT_NEAR(ps.v[p][a], field(a, ps.x[p]), 1e-12);
      for (int b = 0; b < 3; ++b) EXPECT_NEAR(ps.c[p][a][b], b < Dim ? field.B[a][b] : 0.0, 1e-12);
    }
}

TYPED_TEST(ApicTest, ParticlesToGridIsExactForAffineParticles) {
  // Every particle's affine prediction v_a + c_a.(x_f - x_p) equals the field at x_f, so every
  // face with mass (full support or not) gets the field value.
  constexpr int Dim = TypeParam::value;
  const auto layout = boxLayout<Dim>(16, 0.1);
  std::mt19937_64 rng(3);
  const AffineField<Dim> field(rng);
  auto ps = randomParticles<Dim>(layout, 3.0, 13.0, Dim == 2 ? 800 : 8000, rng);
  for (std::size_t p = 0; p < ps.size(); ++p)
    for (int a = 0; a < Dim; ++a) {
      ps.v[p][a] = field(a, ps.x[p]);
      ps.c[p][a] = field.B[a];
    }
  solver::Vector u, m;
  sim::particlesToGrid<Dim>(layout, ps, u, m);
  const std::size_t n = layout.numSlots();
  std::size_t faces = 0;
  for (int a = 0; a < Dim; ++a)
    for (std::size_t s = 0; s < n; ++s) {
      if (!(m[a * n + s] > 0.0)) {
        EXPECT_EQ(u[a * n + s], 0.0);
        continue;
      }
      ++faces;
      EXPECT_NEAR(u[a * n + s], field(a, layout.samplePosition(s, sparse_grid::faceMask(a))), 1e-10);
    }
  EXPECT_GT(faces, std::size_t(Dim * std::pow(10, Dim)));
}

// --- conservation ---------------------------------------------------------------------------

TYPED_TEST(ApicTest, ParticlesToGridConservesLinearMomentum) {
  // sum_f m_f u_f = sum_p v_p per component (unit particle mass), all faces inside the layout.
  constexpr int Dim = TypeParam::value;
  const auto layout = boxLayout<Dim>(16, 0.1);
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  auto ps = randomParticles<Dim>(layout, 3.0, 13.0, Dim == 2 ? 600 : 6000, rng);
  for (std::size_t p = 0; p < ps.size(); ++p)
    for (int a = 0; a < Dim; ++a) {
      ps.v[p][a] = u(rng);
      for (int b = 0; b < Dim; ++b) ps.c[p][a][b] = 10.0 * u(rng);
    }
  solver::Vector vel, mass;
  sim::particlesToGrid<Dim>(layout, ps, vel, mass);
  const std::size_t n = layout.numSlots();
  for (int a = 0; a < Dim; ++a) {
    double grid = 0.0, particles = 0.0, totalMass = 0.0;
    for (std::size_t s = 0; s < n; ++s) {
      grid += mass[a * n + s] * vel[a * n + s];
      totalMass += mass[a * n + s];
    }
    for (std::size_t p = 0; p < ps.size(); ++p) particles += ps.v[p][a];
    EXPECT_NEAR(grid, particles, 1e-10);
    EXPECT_NEAR(totalMass, double(ps.size()), 1e-9);
  }
}

/// Angular momentum of a face field with masses m: sum_f m_f u_f (x_f x e_a).
template <int Dim>
Vec3d gridAngularMomentum(const sparse_grid::BlockLayout<Dim>& layout, const solver::Vector& u, const solver::Vector& m) {
  const std::size_t n = layout.numSlots();
  Vec3d L(0.0);
  for (int a = 0; a < Dim; ++a) {
    Vec3d e(0.0);
    e[a] = 1.0;
    for (std::size_t s = 0; s < n; ++s)
      L += (m[a * n + s] * u[a * n + s]) * layout.samplePosition(s, sparse_grid::faceMask(a)).cross(e);
  }
  return L;
}

/// Particle angular momentum sum_p x_p x v_p + dx^2/4 sum_a c_pa x e_a (header of apic_transfer.h).
template <int Dim>
Vec3d particleAngularMomentum(const ParticleSet<Dim>& ps, double dx) {
  Vec3d L(0.0);
  for (std::size_t p = 0; p < ps.size(); ++p) {
    L += ps.x[p].cross(ps.v[p]);
    for (int a = 0; a < Dim; ++a) {
      Vec3d e(0.0);
      e[a] = 1.0;
      L += (0.25 * dx * dx) * ps.c[p][a].cross(e);
    }
  }
  return L;
}

// P2G on the active cells only (what a simulation step runs) equals P2G on every slot, bit for
// bit, when every cell within two cells of a particle is active: cells [0, 13)^Dim in blocks of
// 8 leave the slots of cells 13-15 inactive, particles in cells [3, 11) reach cells 1-12.
TYPED_TEST(ApicTest, ParticlesToGridOnActiveCellsIsExactWhenTheyCoverTheReach) {
  constexpr int Dim = TypeParam::value;
  const auto layout = boxLayout<Dim>(13, 0.1);
  std::size_t inactive = 0;
  for (std::size_t s = 0; s < layout.numSlots(); ++s) inactive += layout.isActiveCell(s) ? 0 : 1;
  ASSERT_GT(inactive, 0u);
  std::mt19937_64 rng(11);
  auto ps = randomParticles<Dim>(layout, 3.0, 11.0, Dim == 2 ? 500 : 4000, rng);
  for (auto& v : ps.v) v = Vec3d(std::uniform_real_distribution<double>(-1.0, 1.0)(rng), 0.3, -0.2);
  solver::Vector u, m, ua, ma;
  sim::particlesToGrid<Dim>(layout, ps, u, m);
  sim::particlesToGrid<Dim>(layout, ps, ua, ma, sparse_grid::SlotsToFill::ActiveCells);
  ASSERT_EQ(u.size(), ua.size());
  EXPECT_EQ(0, std::memcmp(u.data(), ua.data(), u.size() * sizeof(double)));
  EXPECT_EQ(0, std::memcmp(m.data(), ma.data(), m.size() * sizeof(double)));
}

TYPED_TEST(ApicTest, GridToParticlesToGridConservesAngularMomentum) {
  // G2P then P2G (same particles, so the same masses m_f) maps L_grid to itself, through the
  // particle angular momentum. Random grid velocities: no structure to hide behind.
  constexpr int Dim = TypeParam::value;
  const double dx = 0.1;
  const auto layout = boxLayout<Dim>(16, dx);
  std::mt19937_64 rng(5);
  auto ps = randomParticles<Dim>(layout, 3.0, 13.0, Dim == 2 ? 600 : 6000, rng);
  solver::Vector ignored, mass;
  sim::particlesToGrid<Dim>(layout, ps, ignored, mass);
  const solver::Vector u = test::randomChannels<Dim>(layout, Dim, rng);
  const Vec3d before = gridAngularMomentum<Dim>(layout, u, mass);

  sim::gridToParticles<Dim>(layout, u, ps);
  const Vec3d onParticles = particleAngularMomentum<Dim>(ps, dx);
  solver::Vector u2, mass2;
  sim::particlesToGrid<Dim>(layout, ps, u2, mass2);
  const Vec3d after = gridAngularMomentum<Dim>(layout, u2, mass2);
  const double scale = std::max(1.0, before.length());
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(onParticles[k], before[k], 1e-10 * scale);
    EXPECT_NEAR(after[k], before[k], 1e-10 * scale);
  }
  EXPECT_GT(before.length(), 1.0);
}

TEST(ApicRigidRotation, GridToParticlesGivesSpinAngularMomentum) {
  // u = omega x (x - x0) sampled on faces: G2P gives c_a . e_b = C_ab = eps_ajb omega_j, so the
  // particle's spin term dx^2/4 sum_a c_a x e_a = dx^2/2 omega.
  const double dx = 0.1;
  const auto layout = boxLayout<3>(16, dx);
  const Vec3d omega(0.3, -0.7, 1.1), x0(0.9, 0.7, 0.8);
  const auto u = sampleOnFaces<3>(layout, [&](int a, const Vec3d& x) { return omega.cross(x - x0)[a]; });
  std::mt19937_64 rng(6);
  auto ps = randomParticles<3>(layout, 3.0, 13.0, 200, rng);
  sim::gridToParticles<3>(layout, u, ps);
  for (std::size_t p = 0; p < ps.size(); ++p) {
    ParticleSet<3> one;
    one.push_back(ps.x[p], ps.v[p], ps.c[p]);
    const Vec3d L = particleAngularMomentum<3>(one, dx);
    const Vec3d expected = ps.x[p].cross(omega.cross(ps.x[p] - x0)) + 0.5 * dx * dx * omega;
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(L[k], expected[k], 1e-12);
  }
}

// --- determinism ----------------------------------------------------------------------------

// P2G, G2P and the binning under them give the same bits on 1 and 2 threads. 12,000 (2D) and
// 20,000 (3D) particles: above the grid loops' fork threshold of 8,192, so both runs take their
// production paths, and the 2-thread run scatters each colour, gathers and sorts on two threads
// (counted).
TYPED_TEST(ApicTest, TransfersAreBitIdenticalForOneAndTwoThreads) {
  constexpr int Dim = TypeParam::value;
  const auto layout = test::irregularLayout<Dim>(Dim == 2 ? 40 : 20, 0.1);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  auto ps = randomParticles<Dim>(layout, 0.0, Dim == 2 ? 40.0 : 20.0, Dim == 2 ? 12000 : 20000, rng);
  for (std::size_t p = 0; p < ps.size(); ++p)
    for (int a = 0; a < Dim; ++a) {
      ps.v[p][a] = uni(rng);
      for (int b = 0; b < Dim; ++b) ps.c[p][a][b] = uni(rng);
    }
  const solver::Vector grid = test::randomChannels<Dim>(layout, Dim, rng);
  const int threads = omp_get_max_threads();

  auto run = [&](int t, solver::Vector& u, solver::Vector& m, ParticleSet<Dim>& out) {
    omp_set_num_threads(t);
    sim::particlesToGrid<Dim>(layout, ps, u, m);
    out = ps;
    sim::gridToParticles<Dim>(layout, grid, out);
  };
  solver::Vector u1, m1, u2, m2;
  ParticleSet<Dim> g1, g2;
  run(1, u1, m1, g1);
  const test::TeamCount split;
  run(2, u2, m2, g2);
  omp_set_num_threads(threads);
  EXPECT_EQ(split(parallel::Region::ParticleScatter), std::uint64_t(1) << Dim) << "each colour of P2G on two threads";
  EXPECT_EQ(split(parallel::Region::ParticleGather), 1u);
  EXPECT_GE(split(parallel::Region::ParticleSort), 2u) << "the binning of P2G and of G2P in chunks on two threads";

  ASSERT_EQ(u1.size(), u2.size());
  EXPECT_EQ(std::memcmp(u1.data(), u2.data(), u1.size() * sizeof(double)), 0);
  EXPECT_EQ(std::memcmp(m1.data(), m2.data(), m1.size() * sizeof(double)), 0);
  EXPECT_EQ(std::memcmp(g1.v.data(), g2.v.data(), g1.size() * sizeof(Vec3d)), 0);
  EXPECT_EQ(std::memcmp(g1.c.data(), g2.c.data(), g1.size() * sizeof(g1.c[0])), 0);
}

// --- sampling, advection --------------------------------------------------------------------

TYPED_TEST(ApicTest, SampleFaceVelocityIsExactForLinearFields) {
  constexpr int Dim = TypeParam::value;
  const auto layout = boxLayout<Dim>(16, 0.1);
  std::mt19937_64 rng(8);
  const AffineField<Dim> field(rng);
  const solver::Vector u = sampleOnFaces<Dim>(layout, field);
  const auto ps = randomParticles<Dim>(layout, 1.0, 15.0, 500, rng);
  for (std::size_t p = 0; p < ps.size(); ++p) {
    const Vec3d v = sim::sampleFaceVelocity<Dim>(layout, u, ps.x[p]);
    for (int a = 0; a < Dim; ++a) EXPECT_NEAR(v[a], field(a, ps.x[p]), 1e-13);
    if (Dim == 2) {
      EXPECT_EQ(v[2], 0.0);
    }
  }
}

/// Largest |x' - R(theta) x| over particles at radius r around x0 after one RK2 step of dt in the
/// rigid rotation u = omega e_z x (x - x0), also checking the radius factor sqrt(1 + theta^4/4).
template <int Dim>
double rotationStepError(double dt) {
  const auto layout = boxLayout<Dim>(32, 1.0 / 32);
  const double omega = 1.0, r = 0.25;
  const Vec3d x0 = layout.origin() + Vec3d(0.5, 0.5, Dim == 3 ? 0.5 : 0.0);
  const auto u = sampleOnFaces<Dim>(layout, [&](int a, const Vec3d& x) {
    const Vec3d d = x - x0;
    return a == 0 ? -omega * d[1] : a == 1 ? omega * d[0] : 0.0;
  });
  ParticleSet<Dim> ps;
  for (int k = 0; k < 16; ++k) {
    const double phase = 2.0 * M_PI * k / 16 + 0.1;
    ps.push_back(x0 + Vec3d(r * std::cos(phase), r * std::sin(phase), Dim == 3 ? 0.1 * (k - 8) / 8.0 : 0.0),
                 Vec3d(0.0));
  }
  const ParticleSet<Dim> start = ps;
  sim::advectRK2<Dim>(layout, u, ps, dt);
  const double theta = omega * dt, growth = std::sqrt(1.0 + std::pow(theta, 4) / 4.0);
  double worst = 0.0;
  for (std::size_t p = 0; p < ps.size(); ++p) {
    const Vec3d d0 = start.x[p] - x0, d1 = ps.x[p] - x0;
    EXPECT_NEAR(std::hypot(d1[0], d1[1]), r * growth, 1e-14);  // in-plane radius, exact for RK2
    EXPECT_NEAR(d1[2], d0[2], 1e-15);
    const Vec3d exact(d0[0] * std::cos(theta) - d0[1] * std::sin(theta),
                      d0[0] * std::sin(theta) + d0[1] * std::cos(theta), d0[2]);
    worst = std::max(worst, (d1 - exact).length());
  }
  return worst;
}

TYPED_TEST(ApicTest, RK2RotationErrorIsThirdOrderPerStep) {
  constexpr int Dim = TypeParam::value;
  const double e1 = rotationStepError<Dim>(0.1), e2 = rotationStepError<Dim>(0.05);
  // Leading error r theta^3 / 6 (sqrt(1 + theta^2/16) corrections below 1e-3 relative).
  EXPECT_NEAR(e1, 0.25 * std::pow(0.1, 3) / 6.0, 1e-3 * e1);
  EXPECT_NEAR(e1 / e2, 8.0, 0.05);
}

// --- extrapolation, solids ------------------------------------------------------------------

TYPED_TEST(ApicTest, ExtrapolationFillsAConstantFieldExactlyLayerByLayer) {
  // Known: the faces of the cells [6, 9]^Dim. After L layers a face is known iff its graph
  // distance to that box, sum_b max(0, 6 - i_b, i_b - 9), is at most L, and holds the constant.
  constexpr int Dim = TypeParam::value;
  const auto layout = boxLayout<Dim>(16, 0.1);
  const std::size_t n = layout.numSlots();
  std::mt19937_64 rng(9);
  solver::Vector u = test::randomChannels<Dim>(layout, Dim, rng);
  std::vector<std::uint8_t> known(Dim * n, 0);
  auto distance = [&](std::size_t s) {
    const Coord c = layout.cellOf(s);
    int d = 0;
    for (int b = 0; b < Dim; ++b) d += std::max({0, 6 - c[b], c[b] - 9});
    return d;
  };
  const double value = 2.5;
  for (std::size_t i = 0; i < Dim * n; ++i)
    if (distance(i % n) == 0) {
      known[i] = 1;
      u[i] = value;
    }
  const int layers = 3;
  sim::extrapolateFaceVelocities<Dim>(layout, u, known, layers);
  for (std::size_t i = 0; i < Dim * n; ++i) {
    EXPECT_EQ(bool(known[i]), distance(i % n) <= layers) << i;
    if (known[i]) {
      EXPECT_EQ(u[i], value);
    }
  }
}

TYPED_TEST(ApicTest, PushOutOfSolidLeavesParticlesOutsideTheSphere) {
  constexpr int Dim = TypeParam::value;
  const double dx = 0.05, radius = 0.3;
  const Vec3d centre(0.5, 0.5, Dim == 3 ? 0.5 : 0.0);
  auto phi = [&](const Vec3d& x) {
    Vec3d d = x - centre;
    if (Dim == 2) d[2] = 0.0;
    return d.length() - radius;
  };
  std::mt19937_64 rng(10);
  std::uniform_real_distribution<double> u(0.0, 1.0), w(-1.0, 1.0);
  ParticleSet<Dim> ps;
  for (int p = 0; p < 2000; ++p) {
    Vec3d x(0.0), v(0.0);
    for (int a = 0; a < Dim; ++a) {
      x[a] = u(rng);
      v[a] = w(rng);
    }
    ps.push_back(x, v);
  }
  std::size_t inside = 0;
  for (std::size_t p = 0; p < ps.size(); ++p) inside += phi(ps.x[p]) < 0.1 * dx;
  const auto before = ps;
  const std::size_t moved = sim::pushOutOfSolid<Dim>(ps, phi, dx);
  EXPECT_EQ(moved, inside);
  EXPECT_GT(moved, 100u);
  for (std::size_t p = 0; p < ps.size(); ++p) {
    EXPECT_GE(phi(ps.x[p]), 0.1 * dx - 1e-12);
    if (phi(before.x[p]) >= 0.1 * dx) {
      EXPECT_EQ(ps.x[p], before.x[p]);
      continue;
    }
    Vec3d normal = ps.x[p] - centre;
    normal.normalize();
    // Nothing left moving into the solid, up to the central-difference normal's error
    // ~ (h / r)^2 |v| with h = dx/100, r ~ 0.3.
    EXPECT_GE(ps.v[p].dot(normal), -1e-5);
    EXPECT_LE(phi(ps.x[p]), 0.1 * dx + 1.01e-4 * dx);  // landed in the documented window
  }
}

// --- seeding, reseeding ---------------------------------------------------------------------

/// Signed distance to the box [lo, hi] (negative inside), on the first Dim axes.
template <int Dim>
double boxDistance(const Vec3d& x, const Vec3d& lo, const Vec3d& hi) {
  double outside = 0.0, inside = -1e300;
  for (int a = 0; a < Dim; ++a) {
    const double d = std::max(lo[a] - x[a], x[a] - hi[a]);
    outside += std::max(d, 0.0) * std::max(d, 0.0);
    inside = std::max(inside, d);
  }
  return outside > 0.0 ? std::sqrt(outside) : inside;
}

// binParticles is a stable counting sort by slot: each slot lists its particles in increasing
// index (the order std::stable_sort of the indices by slot gives), particles outside the layout in
// no slot, whatever the thread count. 60,000 particles: several chunks of the parallel sort.
TYPED_TEST(ApicTest, BinningIsTheStableSortBySlotForAnyThreadCount) {
  constexpr int Dim = TypeParam::value;
  const auto layout = boxLayout<Dim>(20, 0.1);  // 3^Dim blocks of 8^Dim cells
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(-0.3, 2.3);  // some particles fall outside the layout
  std::vector<Vec3d> x(60000, Vec3d(0.0));
  for (auto& p : x)
    for (int a = 0; a < Dim; ++a) p[a] = layout.origin()[a] + u(rng);
  std::vector<std::size_t> expected;
  for (std::size_t p = 0; p < x.size(); ++p)
    if (layout.slotOf(sim::cellOfPosition<Dim>(layout, x[p])) >= 0) expected.push_back(p);
  std::stable_sort(expected.begin(), expected.end(), [&](std::size_t a, std::size_t b) {
    return layout.slotOf(sim::cellOfPosition<Dim>(layout, x[a])) < layout.slotOf(sim::cellOfPosition<Dim>(layout, x[b]));
  });
  ASSERT_LT(expected.size(), x.size());
  const int threads = omp_get_max_threads();
  for (int t : {1, 2, 3}) {
    omp_set_num_threads(t);
    const test::TeamCount split;
    const auto bins = sim::binParticles<Dim>(layout, x);
    EXPECT_EQ(split(parallel::Region::ParticleSort), t > 1 ? 1u : 0u) << t << " threads: the chunks' counts on the threads";
    EXPECT_EQ(bins.order, expected) << t << " threads";
    ASSERT_EQ(bins.start.size(), layout.numSlots() + 1);
    for (std::size_t s = 0; s < layout.numSlots(); ++s)
      for (std::size_t j = bins.start[s]; j < bins.start[s + 1]; ++j)
        ASSERT_EQ(bins.slot[bins.order[j]], std::int64_t(s));
    EXPECT_EQ(bins.start.back(), expected.size());
  }
  omp_set_num_threads(threads);
}

TYPED_TEST(ApicTest, SeedingFillsLiquidCellsWithPerAxisToTheDimSamples) {
  // The liquid box covers cells [2, 10) exactly: every such cell gets 3^Dim samples, no other.
  constexpr int Dim = TypeParam::value;
  const double dx = 0.1;
  const auto layout = boxLayout<Dim>(12, dx);
  const Vec3d lo = layout.origin() + Vec3d(2 * dx), hi = layout.origin() + Vec3d(10 * dx);
  auto phi = [&](const Vec3d& x) { return boxDistance<Dim>(x, lo, hi); };
  const Vec3d velocity(0.5, -0.25, 0.125);
  const auto ps = sim::seedParticles<Dim>(layout, phi, 3, 42, velocity);
  EXPECT_EQ(ps.size(), std::size_t(std::pow(3 * 8, Dim)));
  const auto bins = sim::binParticles<Dim>(layout, ps.x);
  for (std::size_t s = 0; s < layout.numSlots(); ++s) {
    const Coord c = layout.cellOf(s);
    bool liquid = true;
    for (int a = 0; a < Dim; ++a) liquid = liquid && c[a] >= 2 && c[a] < 10;
    EXPECT_EQ(bins.count(s), liquid ? std::size_t(std::pow(3, Dim)) : 0u);
  }
  for (std::size_t p = 0; p < ps.size(); ++p) {
    EXPECT_LT(phi(ps.x[p]), 0.0);
    EXPECT_EQ(ps.v[p], Dim == 3 ? velocity : Vec3d(0.5, -0.25, 0.0));
  }
  // The same cells as a CellBox give the same particles.
  sim::CellBox box{openvdb::CoordBBox(Coord(0), Coord(11, 11, Dim == 3 ? 11 : 0)), dx, layout.origin()};
  const auto fromBox = sim::seedParticles<Dim>(box, phi, 3, 42, velocity);
  ASSERT_EQ(fromBox.size(), ps.size());
}

/// A liquid box over cells [1, 15) of a 16-cell layout (dx = 0.1), seeded with one particle per
/// sub-cell (2 per axis); its deep cells (centre phi < -dx) are [2, 14) per axis.
template <int Dim>
struct SeededLiquidBox {
  static constexpr double dx = 0.1;
  sparse_grid::BlockLayout<Dim> layout = boxLayout<Dim>(16, dx);
  Vec3d lo = layout.origin() + Vec3d(1 * dx), hi = layout.origin() + Vec3d(15 * dx);
  std::function<double(const Vec3d&)> phi = [lo = lo, hi = hi](const Vec3d& x) { return boxDistance<Dim>(x, lo, hi); };
  sim::ParticleSet<Dim> particles = sim::seedParticles<Dim>(layout, phi, 2, 1);
};

TYPED_TEST(ApicTest, ReseedingCountsTheDeepCellsAndTheirParticles) {
  // A freshly seeded liquid box holds exactly one particle per sub-cell, so its deep cells hold
  // exactly the target each: density 1.
  constexpr int Dim = TypeParam::value;
  SeededLiquidBox<Dim> box;
  const std::size_t target = std::size_t(1) << Dim, deepCells = Dim == 3 ? 12 * 12 * 12 : 12 * 12;
  const auto measured = sim::countDeepParticles<Dim>(box.layout, box.particles.x, box.phi);
  const solver::Vector u(Dim * box.layout.numSlots(), 0.0);
  const auto counts = sim::reseedParticles<Dim>(box.layout, box.particles, box.phi, u, int(target), 5);
  EXPECT_EQ(counts.deepCells, deepCells);
  EXPECT_EQ(counts.deepParticles, deepCells * target);
  EXPECT_EQ(measured.deepCells, counts.deepCells);
  EXPECT_EQ(measured.deepParticles, counts.deepParticles);
  EXPECT_EQ(counts.added, 0u);
  EXPECT_EQ(counts.removed, 0u);
}

TYPED_TEST(ApicTest, ReseedingBoundsTheCountInDeepLiquidCells) {
  // Liquid box over cells [1, 15); deep cells (centre phi < -dx) are [2, 14). Start from 2^Dim per
  // cell, empty some cells and clump 60 particles into others; after reseeding every deep cell
  // holds between target/2 and 3 target/2, no cell more than 3 target/2, and the thread count does
  // not matter.
  constexpr int Dim = TypeParam::value;
  const int target = 1 << Dim;
  SeededLiquidBox<Dim> box;
  const double dx = box.dx;
  const auto& layout = box.layout;
  const auto& phi = box.phi;
  auto& ps = box.particles;

  std::mt19937_64 rng(11);
  auto cellIsEmptied = [&](const Coord& c) { return (c[0] + 2 * c[1]) % 5 == 0; };
  std::vector<std::uint8_t> drop(ps.size(), 0);
  for (std::size_t p = 0; p < ps.size(); ++p) drop[p] = cellIsEmptied(sim::cellOfPosition<Dim>(layout, ps.x[p]));
  ps.eraseMasked(drop);
  std::uniform_real_distribution<double> jitter(0.0, 0.01 * dx);
  for (int clump = 0; clump < 6; ++clump) {
    Vec3d centre = layout.origin() + Vec3d((3 + 2 * clump + 0.5) * dx, (4 + clump + 0.5) * dx, 0.0);
    if (Dim == 3) centre[2] = layout.origin()[2] + 7.5 * dx;
    for (int k = 0; k < 60; ++k) {
      Vec3d x = centre;
      for (int a = 0; a < Dim; ++a) x[a] += jitter(rng);
      ps.push_back(x, Vec3d(0.0));
    }
  }
  const AffineField<Dim> field(rng);
  const solver::Vector u = sampleOnFaces<Dim>(layout, field);

  std::size_t excess = 0;  // particles beyond the target in cells holding more than 3 target / 2
  {
    const auto before = sim::binParticles<Dim>(layout, ps.x);
    for (std::size_t s = 0; s < layout.numSlots(); ++s)
      excess += 2 * before.count(s) > std::size_t(3 * target) ? before.count(s) - target : 0;
  }
  EXPECT_GE(excess, std::size_t(6 * (60 - target)));

  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  auto one = ps;
  const auto countsOne = sim::reseedParticles<Dim>(layout, one, phi, u, target, 99);
  omp_set_num_threads(2);
  const auto counts = sim::reseedParticles<Dim>(layout, ps, phi, u, target, 99);
  omp_set_num_threads(threads);
  EXPECT_EQ(counts.added, countsOne.added);
  EXPECT_EQ(counts.removed, countsOne.removed);
  EXPECT_EQ(counts.removed, excess);  // crowded cells keep the target
  EXPECT_GT(counts.added, 0u);
  ASSERT_EQ(one.size(), ps.size());
  EXPECT_EQ(std::memcmp(one.x.data(), ps.x.data(), ps.size() * sizeof(Vec3d)), 0);

  const auto bins = sim::binParticles<Dim>(layout, ps.x);
  for (std::size_t s = 0; s < layout.numSlots(); ++s) {
    EXPECT_LE(2 * bins.count(s), std::size_t(3 * target));
    if (phi(layout.samplePosition(s, sparse_grid::kCellCentre)) < -dx) {
      EXPECT_GE(2 * bins.count(s), std::size_t(target));
    }
  }
  // New particles carry the grid's affine field (G2P at their position, full support).
  for (std::size_t p = ps.size() - counts.added; p < ps.size(); ++p)
    for (int a = 0; a < Dim; ++a) {
      EXPECT_NEAR(ps.v[p][a], field(a, ps.x[p]), 1e-12);
      for (int b = 0; b < Dim; ++b) EXPECT_NEAR(ps.c[p][a][b], field.B[a][b], 1e-12);
    }
}

}  // namespace
}  // namespace stokes
