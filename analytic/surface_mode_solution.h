#pragma once
// Linear theory of a small surface mode on a viscous layer: the velocity one unified
// Stokes step of length dt gives, from rest, a layer of depth H on a no-slip floor whose free
// surface is displaced by eta = a m(x), with m a horizontal Fourier mode of wavenumber K
// (m = cos K x in 2D; cos k x cos k z with K = sqrt(2) k in 3D, the same problem along K).
//
// The step solves (rho/dt) u - mu lap u + grad p' = 0, div u = 0 for the perturbation (gravity is
// balanced by the hydrostatic pressure of the flat layer). With u = psi_z, w = -psi_x and
// psi = f(z) sin K x (z = 0 the mean surface, z = -H the floor), f solves
//     (D^2 - K^2)(D^2 - K^2 - alpha^2) f = 0,   alpha^2 = rho / (mu dt),
// so f = A cosh Kz + B sinh Kz + C cosh Mz + D sinh Mz with M = sqrt(K^2 + alpha^2), and
//     f(-H) = f'(-H) = 0                                  no slip on the floor
//     f''(0) + K^2 f(0) = 0                               no shear stress on the surface
//     (mu / K) (f'''(0) - (3 K^2 + alpha^2) f'(0)) = -rho g a
// the last one the normal stress: -p' + 2 mu w_z balances the hydrostatic load rho g eta of the
// displaced surface. Then w(x, z) = -K f(z) m(x), and the surface's decay rate is
// gamma = K f(0) / a, which tends as alpha -> 0 to the quasi-static rate of a layer on a no-slip
// floor,
//     gamma = rho g / (2 mu K) (sinh 2KH - 2KH) / (cosh 2KH + 2 K^2 H^2 + 1)
// (the deep-layer rate rho g / (2 mu K) times the finite-depth factor).
// A floor deeper than kDeepLayer / K is taken at that depth: its effect is below e^-60 there, and
// cosh K H stays finite.
#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace stokes::analytic {

class SurfaceModeSolution {
 public:
  /// K: horizontal wavenumber; H: depth; alpha^2 = rho / (mu dt) > 0 (one step of length dt).
  static constexpr double kDeepLayer = 30.0;

  SurfaceModeSolution(double K, double H, double mu, double rho, double g, double dt)
      : K_(K), H_(std::min(H, kDeepLayer / K)), M_(std::sqrt(K * K + rho / (mu * dt))) {
    if (!(K > 0.0 && H > 0.0 && mu > 0.0 && rho > 0.0 && dt > 0.0))
      throw std::invalid_argument("SurfaceModeSolution: K, H, mu, rho and dt must be positive");
    if (M_ / K_ - 1.0 < 1e-6)
      throw std::invalid_argument("SurfaceModeSolution: rho / (mu dt) is too small against K^2 for the two "
                                  "exponentials to be told apart; shorten dt");
    const double alpha2 = M_ * M_ - K_ * K_;
    Eigen::Matrix4d A;
    A.row(0) = derivatives(-H_, 0);
    A.row(1) = derivatives(-H_, 1);
    A.row(2) = derivatives(0.0, 2) + K_ * K_ * derivatives(0.0, 0);
    A.row(3) = mu / K_ * (derivatives(0.0, 3) - (3.0 * K_ * K_ + alpha2) * derivatives(0.0, 1));
    const Eigen::Vector4d rhs(0.0, 0.0, 0.0, -rho * g);  // unit amplitude a = 1
    coefficients_ = A.fullPivLu().solve(rhs);
  }

  double wavenumber() const { return K_; }

  /// gamma: the surface's decay rate, -w(surface) / eta.
  double rate() const { return verticalProfile(0.0); }

  /// W(z) = K f(z) for a = 1, z the height above the mean surface (-H <= z <= 0):
  /// w(x, z) = -a W(z) m(x).
  double verticalProfile(double z) const { return K_ * derivatives(std::max(z, -H_), 0).dot(coefficients_); }

  /// The quasi-static (alpha -> 0) rate of the file comment.
  static double quasiStaticRate(double K, double H, double mu, double rho, double g) {
    const double x = K * H;
    return rho * g / (2.0 * mu * K) * (std::sinh(2.0 * x) - 2.0 * x) / (std::cosh(2.0 * x) + 2.0 * x * x + 1.0);
  }

 private:
  /// The `order`-th z-derivative of the four basis functions at z.
  Eigen::RowVector4d derivatives(double z, int order) const {
    auto pair = [&](double k, int o) {  // d^o/dz^o of (cosh kz, sinh kz)
      const double c = std::cosh(k * z), s = std::sinh(k * z), f = std::pow(k, o);
      return o % 2 == 0 ? Eigen::RowVector2d(f * c, f * s) : Eigen::RowVector2d(f * s, f * c);
    };
    Eigen::RowVector4d d;
    d << pair(K_, order), pair(M_, order);
    return d;
  }

  double K_, H_, M_;
  Eigen::Vector4d coefficients_;
};

}  // namespace stokes::analytic
