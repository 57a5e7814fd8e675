// surface-mode: a small disturbance of a viscous pool's free surface. One unified Stokes
// step from rest under gravity; the vertical velocity on a face row just below the disturbance is
// fitted against the linear theory of analytic/surface_mode_solution.h. The pool fills a box 1 unit
// deep, open above, y up, with a no-slip floor and free-slip side walls (solid weights W_F by plane
// cuts, the liquid continuing into them as in the scenes). Free-slip walls are the pool's mirror
// planes: the box holds the periodic pool of period twice its width, whose modes are the cosines
// cos(pi m x / width), and the theory sums exactly those (freeSlipSideWalls, Disturbance).
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <memory>
#include <numbers>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "analytic/analytic_cases.h"
#include "analytic/case_setup.h"
#include "analytic/surface_mode_solution.h"
#include "solver/krylov/stopwatch.h"
#include "sparse_grid/volume_weights.h"

namespace stokes::analytic {

namespace {

using solver::StaggeredProblem;
using solver::Vector;
using sparse_grid::StressChannels;
using sparse_grid::Vec3d;

constexpr int kUp = 1;          // the vertical axis
constexpr double kDepth = 1.0;  // the pool's depth below the mean surface (levelOffset aside)

/// eta(x) = a shape(x) on the horizontal axes, and the linear theory's vertical velocity
/// w(x, z) = -a sum_K W_K(z) (shape's K-component)(x) for z below the mean surface.
template <int Dim>
class Disturbance {
 public:
  Disturbance(const AnalyticOptions& o, double dx, const Vec3d& centre, double depth, double width)
      : gaussian_(o.shape == "gaussian"), a_(o.amplitude * dx), s_(0.5 * o.radius * dx), centre_(centre), o_(o),
        depth_(depth), width_(width) {
    if (gaussian_) boxModes_ = gaussianBoxModes();
  }

  double height(const Vec3d& x) const {
    if (gaussian_) return a_ * std::exp(-radius2(x) / (2.0 * s_ * s_));
    return a_ * modeShape(x);
  }

  /// |grad eta|^2
  double slope2(const Vec3d& x) const {
    double g2 = 0.0;
    for (int h : horizontal()) {
      double d;
      if (gaussian_) {
        d = -height(x) * (x[h] - centre_[h]) / (s_ * s_);
      } else {
        d = -a_ * kMode * std::sin(kMode * (x[h] - centre_[h]));
        for (int other : horizontal())
          if (other != h) d *= std::cos(kMode * (x[other] - centre_[other]));
      }
      g2 += d * d;
    }
    return g2;
  }

  /// The theory's w on the row at height z (<= 0) above the mean surface, as a function of the
  /// horizontal position (the Gaussian's mode profiles at z are tabulated once for the row).
  std::function<double(const Vec3d&)> verticalOnRow(double z) const {
    if (!gaussian_) {
      const double profile = modeSolution().verticalProfile(z);
      return [this, profile](const Vec3d& x) { return -a_ * profile * modeShape(x); };
    }
    auto table = std::make_shared<const std::vector<double>>(
        overModes([&](double K) { return solutionFor(K).verticalProfile(z); }));
    return [this, table](const Vec3d& x) { return -a_ * gaussianSeries(x, *table); };
  }

  /// -w / eta at the crest on the surface (the mode's rate; the Gaussian's rate at its apex)
  double rate() const {
    if (!gaussian_) return modeSolution().rate();
    return gaussianSeries(centre_, overModes([&](double K) { return solutionFor(K).rate(); }));
  }

  double quasiStaticRate() const {
    auto quasiStatic = [&](double K) {
      return SurfaceModeSolution::quasiStaticRate(K, depth_, o_.mu, o_.rho, o_.gravity);
    };
    if (!gaussian_) return quasiStatic(modeWavenumber());
    return gaussianSeries(centre_, overModes(quasiStatic));
  }

  /// Whether horizontal position x lies where the fit looks: one wavelength around the crest on
  /// every axis (mode), or within two radii (Gaussian).
  bool inFitRegion(const Vec3d& x) const {
    if (gaussian_) return radius2(x) <= 16.0 * s_ * s_;
    for (int h : horizontal())
      if (std::abs(x[h] - centre_[h]) > 1.0) return false;
    return true;
  }

  double amplitude() const { return a_; }

 private:
  static constexpr double kMode = 2.0 * std::numbers::pi;  // one wavelength per unit length

  /// The horizontal axes (y is vertical): x in 2D, x and z in 3D. A fixed array, no allocation in
  /// the per-face loops that iterate it.
  static std::span<const int> horizontal() {
    static constexpr std::array<int, 2> kAxes{0, 2};
    return std::span<const int>(kAxes.data(), Dim == 2 ? 1 : 2);
  }

  double radius2(const Vec3d& x) const {
    double r2 = 0.0;
    for (int h : horizontal()) r2 += (x[h] - centre_[h]) * (x[h] - centre_[h]);
    return r2;
  }

  double modeWavenumber() const { return kMode * std::sqrt(double(Dim - 1)); }
  SurfaceModeSolution solutionFor(double K) const {
    return SurfaceModeSolution(K, depth_, o_.mu, o_.rho, o_.gravity, o_.dt);
  }
  SurfaceModeSolution modeSolution() const { return solutionFor(modeWavenumber()); }

  /// prod cos(2 pi (x_h - c_h)) over the horizontal axes
  double modeShape(const Vec3d& x) const {
    double m = 1.0;
    for (int h : horizontal()) m *= std::cos(kMode * (x[h] - centre_[h]));
    return m;
  }

  /// One cosine mode of the box, prod_h cos(k_h x_h) (k_h = pi m_h / width, not all m_h zero),
  /// with the Gaussian's coefficient in it divided by a.
  struct BoxMode {
    std::array<double, 2> k;  // per horizontal axis (the second unused in 2D)
    double K;                 // |k|
    double coefficient;
  };

  /// The Gaussian eta / a = exp(-r^2 / (2 s^2)) as the box's cosine series: coefficient
  ///   prod_h c_h  (2 pi s^2)^((Dim-1)/2) exp(-K^2 s^2 / 2) prod_h cos(k_h centre_h),
  /// c_h = 1 / width for m_h = 0 and 2 / width otherwise (the integral over the box of the Gaussian
  /// times the mode, the Gaussian negligible at the walls). Modes up to K = 9 / s, where
  /// exp(-K^2 s^2 / 2) < e^-40. The mean (all m_h = 0) is a level that does not move.
  std::vector<BoxMode> gaussianBoxModes() const {
    const double pi = std::numbers::pi, kMax = 9.0 / s_;
    const int mMax = int(kMax * width_ / pi);
    const int mOther = Dim == 3 ? mMax : 0;
    std::vector<BoxMode> modes;
    for (int m1 = 0; m1 <= mOther; ++m1)
      for (int m0 = 0; m0 <= mMax; ++m0) {
        const std::array<double, 2> k{pi * m0 / width_, pi * m1 / width_};
        const double K = std::hypot(k[0], k[1]);
        if (K == 0.0 || K > kMax) continue;
        double coefficient = std::pow(2.0 * pi * s_ * s_, 0.5 * (Dim - 1)) * std::exp(-0.5 * K * K * s_ * s_);
        const auto axes = horizontal();
        for (std::size_t j = 0; j < axes.size(); ++j)
          coefficient *= (k[j] == 0.0 ? 1.0 : 2.0) / width_ * std::cos(k[j] * centre_[axes[j]]);
        modes.push_back({k, K, coefficient});
      }
    return modes;
  }

  /// f(K) for every box mode.
  template <class F>
  std::vector<double> overModes(const F& f) const {
    std::vector<double> values(boxModes_.size());
    for (std::size_t j = 0; j < boxModes_.size(); ++j) values[j] = f(boxModes_[j].K);
    return values;
  }

  /// sum over the box modes of profile(K) (tabulated by overModes) times the Gaussian's component
  /// at x (a constant profile c gives c (eta / a - its mean)).
  double gaussianSeries(const Vec3d& x, const std::vector<double>& profile) const {
    const auto axes = horizontal();
    double sum = 0.0;
    for (std::size_t j = 0; j < boxModes_.size(); ++j) {
      double shape = boxModes_[j].coefficient;
      for (std::size_t h = 0; h < axes.size(); ++h) shape *= std::cos(boxModes_[j].k[h] * x[axes[h]]);
      sum += profile[j] * shape;
    }
    return sum;
  }

  bool gaussian_;
  double a_, s_;
  Vec3d centre_;
  const AnalyticOptions& o_;
  double depth_, width_;
  std::vector<BoxMode> boxModes_;
};

/// The box's width: the option, else 4 wavelengths for a mode and 8 units for a Gaussian. (With the
/// theory of the box's own modes the width no longer biases the rate; it sets the cost.)
int boxWidth(const AnalyticOptions& o) { return o.width.value_or(o.shape == "gaussian" ? 8 : 4); }

void checkOptions(const AnalyticOptions& o) {
  if (o.dim != 2 && o.dim != 3) throw std::invalid_argument("surface-mode: dim must be 2 or 3");
  if (o.shape != "mode" && o.shape != "gaussian")
    throw std::invalid_argument("surface-mode: unknown shape '" + o.shape + "' (mode or gaussian)");
  if (o.n < 8) throw std::invalid_argument("surface-mode: n must be >= 8");
  if (o.amplitude == 0.0 || std::abs(o.amplitude) > 0.25 * o.n)
    throw std::invalid_argument("surface-mode: the amplitude must be non-zero and at most a quarter of the depth (" +
                                std::to_string(0.25 * o.n) + " cells)");
  if (o.shape == "gaussian" && (o.radius < 1.0 || o.radius > 0.25 * o.n * boxWidth(o)))
    throw std::invalid_argument("surface-mode: the radius must lie between 1 cell and a quarter of the box");
  if (boxWidth(o) < 2) throw std::invalid_argument("surface-mode: the box must be at least 2 wide");
  if (o.system != solver::SystemKind::UnifiedStokes)
    throw std::invalid_argument("surface-mode: the case solves unified Stokes (system unified)");
}

/// Free-slip side walls: no shear stress on them. W_L^tau = 0 for the off-diagonal samples tau_ab
/// (a or b horizontal) on or beyond a side wall normal to a or b, so the tangential velocity there
/// is not held; the normal velocity is, by W_F. The floor stays no-slip. With no-slip side walls 2
/// wavelengths from the crest, a mode's rate read 0.831 / 1.0018 / 0.9991 of the infinite pool's
/// in boxes 2 / 4 / 8 wide at n = 128, a bias at every resolution; free-slip reads 0.9987 in all three.
template <int Dim>
void freeSlipSideWalls(const sparse_grid::BlockLayout<Dim>& layout, StaggeredProblem<Dim>& prob, double width) {
  const std::size_t n = layout.numSlots();
  const double eps = 1e-9 * layout.dx();
  for (int k = 0; k < StressChannels<Dim>::kPairs; ++k) {
    const auto [a, b] = StressChannels<Dim>::pairs()[k];
    const int channel = StressChannels<Dim>::kDiagonal + k;
    for (std::size_t s = 0; s < n; ++s) {
      const Vec3d x = layout.samplePosition(s, StressChannels<Dim>::mask(channel));
      for (int h : {a, b})
        if (h != kUp && (x[h] <= eps || x[h] >= width - eps)) prob.liquidStress[channel * n + s] = 0.0;
    }
  }
}

template <int Dim>
AnalyticResult surfaceMode(const AnalyticOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  const double dx = 1.0 / o.n, width = boxWidth(o);
  const int cells = boxWidth(o) * o.n;  // across the box, per horizontal axis
  const double level = kDepth + o.levelOffset * dx;
  Vec3d centre(0.5 * width + o.crestOffset * dx, level, Dim == 3 ? 0.5 * width + o.crestOffset * dx : 0.0);
  const Disturbance<Dim> eta(o, dx, centre, level, width);
  const double a = std::abs(eta.amplitude());

  // The box's cells and one layer past its walls and floor; air above the crest.
  const int top = int(std::ceil((level + a) / dx)) + 3;
  openvdb::MaskTree mask;
  sparse_grid::activateBox(mask, detail::cellCoord<Dim>(-1, -1, -1), detail::cellCoord<Dim>(cells, top, cells));
  const sparse_grid::BlockLayout<Dim> layout(mask, dx);

  StaggeredProblem<Dim> prob = detail::makeProblem(layout, o, /*withSolids=*/true);
  // phi_L: the distance to the surface's tangent plane (signed, < 0 in the liquid)
  auto phiLiquid = [&](const Vec3d& x) { return (x[kUp] - level - eta.height(x)) / std::sqrt(1.0 + eta.slope2(x)); };
  // inside the box: > 0; W_F counts the side phi < 0 of -inside
  auto outsideBox = [&](const Vec3d& x) {
    double inside = x[kUp];
    for (int h = 0; h < Dim; ++h)
      if (h != kUp) inside = std::min({inside, x[h], width - x[h]});
    return -inside;
  };
  const std::size_t n = layout.numSlots();
  for (int axis = 0; axis < Dim; ++axis)
    sparse_grid::computePlaneCutFractions<Dim>(layout, sparse_grid::faceMask(axis), outsideBox,
                                               prob.fluidFace.data() + axis * n);
  for (int c = 0; c < StressChannels<Dim>::kCount; ++c)
    sparse_grid::computePlaneCutFractions<Dim>(layout, StressChannels<Dim>::mask(c), outsideBox,
                                               prob.fluidStress.data() + c * n);
  solver::fillLiquidWeights(prob, phiLiquid, o.liquidWeights.value_or(sparse_grid::kLiquidFractionRule));
  freeSlipSideWalls(layout, prob, width);
  // from rest: one step of gravity
  for (std::size_t s = 0; s < n; ++s) prob.uStar[kUp * n + s] = -o.gravity * o.dt;

  Vector u;
  const solver::StepReport rep = solver::solveStep(prob, detail::stepOptions(o, solver::SystemKind::UnifiedStokes), u);
  AnalyticResult r = detail::makeResult(o.shape == "gaussian" ? "surface-gaussian" : "surface-mode", o);
  if (!detail::fillReport(r, rep, o, u)) return r;  // the solve failed (status, diagnostics)

  // The fit: vertical faces on the row two cells below the lowest point of the disturbance.
  const double rowHeight = std::floor((level - a) / dx - 2.0) * dx;
  double along = 0.0, theory2 = 0.0;
  const double dA = std::pow(dx, Dim - 1);
  const std::function<double(const Vec3d&)> theory = eta.verticalOnRow(rowHeight - level);
  for (std::size_t s = 0; s < n; ++s) {
    const Vec3d x = layout.samplePosition(s, sparse_grid::faceMask(kUp));
    if (std::abs(x[kUp] - rowHeight) > 1e-9 * dx || !eta.inFitRegion(x)) continue;
    const double t = theory(x), w = u[kUp * n + s];
    along += w * t;
    theory2 += t * t;
    r.L1 += std::abs(w - t) * dA;
    r.Linf = std::max(r.Linf, std::abs(w - t));
  }
  if (theory2 <= 0.0) throw std::logic_error("surface-mode: no face in the fit region");
  r.theoryRate = eta.rate();
  r.rate = r.theoryRate * along / theory2;
  r.quasiStaticRate = eta.quasiStaticRate();
  r.kineticEnergyBefore = detail::kineticEnergy(prob, prob.uStar);
  r.kineticEnergyAfter = detail::kineticEnergy(prob, u);
  r.maxDivergence = maxDivergence(prob, u);
  r.totalSeconds = solver::secondsSince(t0);
  return r;
}

}  // namespace

AnalyticResult runSurfaceMode(const AnalyticOptions& o) {
  checkOptions(o);
  return o.dim == 2 ? surfaceMode<2>(o) : surfaceMode<3>(o);
}

}  // namespace stokes::analytic
