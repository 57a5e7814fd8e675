#pragma once
// The free-surface Stokes disk of Batty & Bridson 2010, used in thesis 5.4 (docs/design.md §4):
// a disk of radius 0.75 centred at the origin, with the final velocity given by the stream function
//   Psi = 128/81 r^4 cos(2 theta) cos(sqrt3 ln r) (15 - 30 r + 16 r^2),   u = (dPsi/dy, -dPsi/dx),
// the pressure
//   p = 512 sqrt3/81 mu r^2 sin(2 theta) sin(sqrt3 ln r) (15 - 30 r + 16 r^2),
// and the start velocity u* = u + dt/rho (grad p - mu lap u), so that one Stokes step of length dt
// from u* returns u. The traction (-p I + tau) n vanishes on r = 0.75.
//
// Writing Psi = f(r) c2 with c2 = cos 2theta = (x^2 - y^2)/r^2 and lap Psi = g(r) c2,
// g = f'' + f'/r - 4 f/r^2, every quantity needs at most f''' -- taken from a Taylor jet.
#include "sparse_grid/vdb_trees.h"

#include <algorithm>
#include <cmath>

#include "analytic/taylor_jet.h"

namespace stokes::analytic {

class DiskStokesSolution {
 public:
  static constexpr double kRadius = 0.75;

  explicit DiskStokesSolution(double mu) : mu_(mu) {}

  double levelSet(const openvdb::Vec3d& x) const { return std::hypot(x[0], x[1]) - kRadius; }

  /// Whether the control volume of a sample at x (the square of side dx centred on it) holds
  /// liquid: its point nearest the disk's centre lies inside the disk. The error norms run over
  /// these faces, whichever liquid-weight rule the solve used, so that the rules are compared on
  /// the same faces (thesis 5.4 measures the faces of non-zero box fraction).
  static bool controlVolumeHoldsLiquid(const openvdb::Vec3d& x, double dx) {
    const double nearestX = std::clamp(0.0, x[0] - 0.5 * dx, x[0] + 0.5 * dx);
    const double nearestY = std::clamp(0.0, x[1] - 0.5 * dx, x[1] + 0.5 * dx);
    return std::hypot(nearestX, nearestY) < kRadius;
  }

  /// Exact velocity component `axis` (0: x, 1: y) at x.
  double velocity(const openvdb::Vec3d& x, int axis) const { return curl(x, axis, /*laplacian=*/false); }

  /// Exact pressure.
  double pressure(const openvdb::Vec3d& x) const {
    const double r = std::hypot(x[0], x[1]);
    if (r < 1e-12) return 0.0;
    return pressureRadial(Jet3::variable(r)).value() * 2.0 * x[0] * x[1] / (r * r);
  }

  /// u* = u + dt/rho (grad p - mu lap u), component `axis`.
  double startVelocity(const openvdb::Vec3d& x, int axis, double rho, double dt) const {
    return velocity(x, axis) + dt / rho * (pressureGradient(x, axis) - mu_ * curl(x, axis, /*laplacian=*/true));
  }

 private:
  // f(r) = 128/81 r^4 cos(sqrt3 ln r) (15 - 30 r + 16 r^2)
  static Jet3 streamRadial(const Jet3& r) {
    const Jet3 r2 = r * r;
    const Jet3 q = Jet3::constant(15.0) - 30.0 * r + 16.0 * r2;
    return (128.0 / 81.0) * (r2 * r2) * cos(std::sqrt(3.0) * log(r)) * q;
  }
  // P(r) = 512 sqrt3/81 mu r^2 sin(sqrt3 ln r) (15 - 30 r + 16 r^2)
  Jet3 pressureRadial(const Jet3& r) const {
    const Jet3 q = Jet3::constant(15.0) - 30.0 * r + 16.0 * (r * r);
    return (512.0 * std::sqrt(3.0) / 81.0 * mu_) * (r * r) * sin(std::sqrt(3.0) * log(r)) * q;
  }

  // Component `axis` of (d/dy, -d/dx) applied to F(r) c2, where F = f (velocity) or
  // F = g = f'' + f'/r - 4 f/r^2 (laplacian = true: then this is lap u).
  double curl(const openvdb::Vec3d& p, int axis, bool laplacian) const {
    const double x = p[0], y = p[1];
    const double r = std::hypot(x, y);
    if (r < 1e-12) return 0.0;
    const Jet3 f = streamRadial(Jet3::variable(r));
    const double f0 = f.derivative(0), f1 = f.derivative(1), f2 = f.derivative(2), f3 = f.derivative(3);
    double F = f0, dF = f1;
    if (laplacian) {
      const double r2 = r * r, r3 = r2 * r;
      F = f2 + f1 / r - 4.0 * f0 / r2;
      dF = f3 + f2 / r - f1 / r2 - 4.0 * f1 / r2 + 8.0 * f0 / r3;
    }
    const double r2 = r * r, r4 = r2 * r2;
    const double c2 = (x * x - y * y) / r2;
    if (axis == 0) return dF * (y / r) * c2 + F * (-4.0 * x * x * y / r4);  // d/dy (F c2)
    return -(dF * (x / r) * c2 + F * (4.0 * x * y * y / r4));                // -d/dx (F c2)
  }

  // d/dx_axis of P(r) s2, s2 = sin 2theta = 2 x y / r^2.
  double pressureGradient(const openvdb::Vec3d& p, int axis) const {
    const double x = p[0], y = p[1];
    const double r = std::hypot(x, y);
    if (r < 1e-12) return 0.0;
    const Jet3 P = pressureRadial(Jet3::variable(r));
    const double r2 = r * r, r4 = r2 * r2;
    const double s2 = 2.0 * x * y / r2;
    if (axis == 0) return P.derivative(1) * (x / r) * s2 + P.value() * 2.0 * y * (y * y - x * x) / r4;
    return P.derivative(1) * (y / r) * s2 + P.value() * 2.0 * x * (x * x - y * y) / r4;
  }

  double mu_;
};

}  // namespace stokes::analytic
