#pragma once
// A univariate Taylor jet truncated at third order: t = c0 + c1 h + c2 h^2 + c3 h^3 about a point.
// Enough arithmetic to differentiate the closed-form analytic solutions three times exactly
// (to rounding), so that u* = u + dt/rho (grad p - mu lap u) needs no finite differences.
#include <array>
#include <cmath>

namespace stokes::analytic {

struct Jet3 {
  std::array<double, 4> c{};  // Taylor coefficients; the k-th derivative is k! c[k]

  static Jet3 variable(double x0) { return Jet3{{x0, 1.0, 0.0, 0.0}}; }
  static Jet3 constant(double v) { return Jet3{{v, 0.0, 0.0, 0.0}}; }
  double value() const { return c[0]; }
  double derivative(int k) const {
    static constexpr double kFactorial[4] = {1.0, 1.0, 2.0, 6.0};
    return kFactorial[k] * c[k];
  }

  friend Jet3 operator+(const Jet3& a, const Jet3& b) {
    Jet3 r;
    for (int k = 0; k < 4; ++k) r.c[k] = a.c[k] + b.c[k];
    return r;
  }
  friend Jet3 operator-(const Jet3& a, const Jet3& b) {
    Jet3 r;
    for (int k = 0; k < 4; ++k) r.c[k] = a.c[k] - b.c[k];
    return r;
  }
  friend Jet3 operator*(double s, const Jet3& a) {
    Jet3 r;
    for (int k = 0; k < 4; ++k) r.c[k] = s * a.c[k];
    return r;
  }
  friend Jet3 operator*(const Jet3& a, const Jet3& b) {  // Cauchy product, truncated
    Jet3 r;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; i + j < 4; ++j) r.c[i + j] += a.c[i] * b.c[j];
    return r;
  }
};

/// f(t) for a smooth f with derivatives f0..f3 at t.c0:  f0 + f1 e + f2/2 e^2 + f3/6 e^3, e = t - c0.
inline Jet3 compose(const Jet3& t, double f0, double f1, double f2, double f3) {
  Jet3 e = t;
  e.c[0] = 0.0;
  const Jet3 e2 = e * e, e3 = e2 * e;
  return Jet3::constant(f0) + f1 * e + (0.5 * f2) * e2 + (f3 / 6.0) * e3;
}
inline Jet3 log(const Jet3& t) {
  const double x = t.c[0];
  return compose(t, std::log(x), 1.0 / x, -1.0 / (x * x), 2.0 / (x * x * x));
}
inline Jet3 cos(const Jet3& t) {
  const double s = std::sin(t.c[0]), c = std::cos(t.c[0]);
  return compose(t, c, -s, -c, s);
}
inline Jet3 sin(const Jet3& t) {
  const double s = std::sin(t.c[0]), c = std::cos(t.c[0]);
  return compose(t, s, c, -s, -c);
}

}  // namespace stokes::analytic
