#pragma once
// Polynomial velocity bases of reduced tiles.
//
// Inside a reduced tile the velocity is a polynomial field
//
//     u_R(x) = C(x~) v_R,      x~ = (x - x_COM) / h,
//
// with x_COM the tile centre of mass and h the tile half-width (the caller does the scaling and
// passes x~, written xs below; x, y, z denote its components). Column k of the Dim x size() matrix
// C is basis field k, a Dim-vector polynomial field. On a face normal to axis a only component a
// of u matters, so the hot operation is the row C_a(x~) (evaluateComponent).
//
// Monomials, in this order (the "monomial index" m used in comments and tables):
//   2D: m = 0:1  1:x  2:y  3:x^2  4:xy  5:y^2
//   3D: m = 0:1  1:x  2:y  3:z    4:x^2  5:xy  6:xz  7:y^2  8:yz  9:z^2
// Affine families use m < 1 + Dim, quadratic ones all of them.
//
// Families (each item one column, written (u_x, u_y[, u_z])):
//
//   DivergenceFree, 2D affine (5):     (1,0) (0,1) (x,-y) (y,0) (0,x)
//   DivergenceFree, 2D quadratic (9):  the 5 above, then (x^2,-2xy) (y^2,0) (0,x^2) (-2xy,y^2)
//   DivergenceFree, 3D affine (11):    (1,0,0) (0,1,0) (0,0,1)
//                                      (x,0,-z) (y,0,0) (z,0,0) (0,x,0) (0,y,-z) (0,z,0) (0,0,x) (0,0,y)
//   DivergenceFree, 3D quadratic (26): the 11 above, then
//        (x^2,0,-2xz) (xy,0,-yz) (xz,0,-z^2/2) (y^2,0,0) (yz,0,0) (z^2,0,0)
//        (0,x^2,0) (0,xy,-xz) (0,xz,0) (0,y^2,-2yz) (0,yz,-z^2/2) (0,z^2,0)
//        (0,0,x^2) (0,0,xy) (0,0,y^2)
//   These span exactly the divergence-free polynomial fields of their degree k: Dim * #monomials
//   of degree <= k minus the independent constraints div u = 0, a polynomial of degree <= k-1
//   (1 constraint for affine, 1 + Dim for quadratic): 2D 6-1=5, 12-3=9; 3D 12-1=11, 30-4=26.
//
//   Full (every component independently spans the monomials of degree <= k; used by the
//   decoupled viscosity step where u need not be divergence free):
//        field k = e_{k mod Dim} * m_{k div Dim},
//   i.e. monomial-major, so the first Dim columns are the constant fields (as in the divergence-
//   free families), then the linear ones, then the quadratic ones. Sizes: 2D 6 / 12, 3D 12 / 30.
//
// Everything is in scaled coordinates: the physical derivative of C is (1/h) times the one here.
// No allocation, no virtual calls; evaluateComponent switches once on (order, family) and then
// fills the row from the monomials computed once.
#include <array>
#include <cstddef>

namespace stokes::kernels {

enum class PolynomialOrder { Affine, Quadratic };
enum class BasisFamily { DivergenceFree, Full };

namespace polynomial_detail {

/// One term of a basis field: field `field` has coeff * monomial `mono` in component `comp`.
struct Term {
  int field;
  int comp;
  int mono;
  double coeff;
};

/// Number of monomials of degree <= (1 or 2) in Dim variables.
constexpr int numMonomials(int dim, PolynomialOrder order) {
  return order == PolynomialOrder::Affine ? 1 + dim : (dim + 1) * (dim + 2) / 2;
}

// Sparse term tables of the divergence-free families (the affine family is a prefix of the
// quadratic one, field- and term-wise). They are the second, independent encoding of the bases
// (the first being the explicit code of evaluateComponentFixed); divergence() uses them.
inline constexpr std::array<Term, 12> kDivFreeTerms2D{{
    // affine: (1,0) (0,1) (x,-y) (y,0) (0,x)
    {0, 0, 0, 1.0},
    {1, 1, 0, 1.0},
    {2, 0, 1, 1.0}, {2, 1, 2, -1.0},
    {3, 0, 2, 1.0},
    {4, 1, 1, 1.0},
    // quadratic: (x^2,-2xy) (y^2,0) (0,x^2) (-2xy,y^2)
    {5, 0, 3, 1.0}, {5, 1, 4, -2.0},
    {6, 0, 5, 1.0},
    {7, 1, 3, 1.0},
    {8, 0, 4, -2.0}, {8, 1, 5, 1.0},
}};
inline constexpr int kDivFreeAffineTerms2D = 6;

inline constexpr std::array<Term, 34> kDivFreeTerms3D{{
    // affine
    {0, 0, 0, 1.0},
    {1, 1, 0, 1.0},
    {2, 2, 0, 1.0},
    {3, 0, 1, 1.0}, {3, 2, 3, -1.0},   // (x,0,-z)
    {4, 0, 2, 1.0},                    // (y,0,0)
    {5, 0, 3, 1.0},                    // (z,0,0)
    {6, 1, 1, 1.0},                    // (0,x,0)
    {7, 1, 2, 1.0}, {7, 2, 3, -1.0},   // (0,y,-z)
    {8, 1, 3, 1.0},                    // (0,z,0)
    {9, 2, 1, 1.0},                    // (0,0,x)
    {10, 2, 2, 1.0},                   // (0,0,y)
    // quadratic
    {11, 0, 4, 1.0}, {11, 2, 6, -2.0},  // (x^2,0,-2xz)
    {12, 0, 5, 1.0}, {12, 2, 8, -1.0},  // (xy,0,-yz)
    {13, 0, 6, 1.0}, {13, 2, 9, -0.5},  // (xz,0,-z^2/2)
    {14, 0, 7, 1.0},                    // (y^2,0,0)
    {15, 0, 8, 1.0},                    // (yz,0,0)
    {16, 0, 9, 1.0},                    // (z^2,0,0)
    {17, 1, 4, 1.0},                    // (0,x^2,0)
    {18, 1, 5, 1.0}, {18, 2, 6, -1.0},  // (0,xy,-xz)
    {19, 1, 6, 1.0},                    // (0,xz,0)
    {20, 1, 7, 1.0}, {20, 2, 8, -2.0},  // (0,y^2,-2yz)
    {21, 1, 8, 1.0}, {21, 2, 9, -0.5},  // (0,yz,-z^2/2)
    {22, 1, 9, 1.0},                    // (0,z^2,0)
    {23, 2, 4, 1.0},                    // (0,0,x^2)
    {24, 2, 5, 1.0},                    // (0,0,xy)
    {25, 2, 7, 1.0},                    // (0,0,y^2)
}};
inline constexpr int kDivFreeAffineTerms3D = 13;

/// The affine family is the prefix of `count` terms: fields below `size`, and the next term (if
/// any) of a field beyond it.
template <std::size_t N>
constexpr bool isAffinePrefix(const std::array<Term, N>& terms, int count, int size) {
  for (int t = 0; t < count; ++t)
    if (terms[t].field >= size) return false;
  return count == int(N) || terms[count].field >= size;
}
static_assert(isAffinePrefix(kDivFreeTerms2D, kDivFreeAffineTerms2D, 5), "2D affine divergence-free terms");
static_assert(isAffinePrefix(kDivFreeTerms3D, kDivFreeAffineTerms3D, 11), "3D affine divergence-free terms");

/// Exponents of monomial m (see the header comment for the order).
template <int Dim>
constexpr std::array<int, Dim> exponents(int m) {
  if constexpr (Dim == 2) {
    constexpr int e[6][2] = {{0, 0}, {1, 0}, {0, 1}, {2, 0}, {1, 1}, {0, 2}};
    return {e[m][0], e[m][1]};
  } else {
    constexpr int e[10][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {2, 0, 0},
                              {1, 1, 0}, {1, 0, 1}, {0, 2, 0}, {0, 1, 1}, {0, 0, 2}};
    return {e[m][0], e[m][1], e[m][2]};
  }
}

/// d(monomial m)/d x_c at xs: e_c * x^(e - unit_c) (exponents are at most 2).
template <int Dim>
inline double monomialDerivative(int m, int c, const double* xs) {
  const auto e = exponents<Dim>(m);
  if (e[c] == 0) return 0.0;
  double v = static_cast<double>(e[c]);
  for (int d = 0; d < Dim; ++d) {
    const int p = d == c ? e[d] - 1 : e[d];
    for (int q = 0; q < p; ++q) v *= xs[d];
  }
  return v;
}

}  // namespace polynomial_detail

template <int Dim>
class PolynomialBasis {
  static_assert(Dim == 2 || Dim == 3, "PolynomialBasis: Dim must be 2 or 3");

 public:
  /// Largest size() over all families (3D quadratic full = 3 * 10; 2D quadratic full = 2 * 6).
  static constexpr int kMaxSize = Dim == 2 ? 12 : 30;
  /// Number of monomials of degree <= 2 (the most evaluateComponent ever needs).
  static constexpr int kMaxMonomials = (Dim + 1) * (Dim + 2) / 2;

  /// Number of basis fields of a family, at compile time.
  static constexpr int sizeOf(PolynomialOrder order, BasisFamily family) {
    const int full = Dim * polynomial_detail::numMonomials(Dim, order);
    if (family == BasisFamily::Full) return full;
    // minus the independent divergence constraints: 1 (affine) or 1 + Dim (quadratic)
    return full - (order == PolynomialOrder::Affine ? 1 : 1 + Dim);
  }

  constexpr PolynomialBasis(PolynomialOrder order, BasisFamily family)
      : order_(order), family_(family), size_(sizeOf(order, family)) {}

  constexpr int size() const { return size_; }
  constexpr PolynomialOrder order() const { return order_; }
  constexpr BasisFamily family() const { return family_; }

  /// "affine-divfree-5", "quadratic-divfree-26", "affine-full-12", ...
  const char* name() const {
    static constexpr const char* k2[2][2] = {{"affine-divfree-5", "affine-full-6"},
                                             {"quadratic-divfree-9", "quadratic-full-12"}};
    static constexpr const char* k3[2][2] = {{"affine-divfree-11", "affine-full-12"},
                                             {"quadratic-divfree-26", "quadratic-full-30"}};
    const int o = order_ == PolynomialOrder::Affine ? 0 : 1;
    const int f = family_ == BasisFamily::DivergenceFree ? 0 : 1;
    return Dim == 2 ? k2[o][f] : k3[o][f];
  }

  /// row[k] = component `axis` of basis field k at scaled coordinates xs[0..Dim-1],
  /// for k < size(). `row` needs size() entries (kMaxSize is always enough).
  inline void evaluateComponent(int axis, const double* xs, double* row) const {
    using O = PolynomialOrder;
    using F = BasisFamily;
    if (order_ == O::Affine) {
      if (family_ == F::DivergenceFree)
        evaluateComponentFixed<O::Affine, F::DivergenceFree>(axis, xs, row);
      else
        evaluateComponentFixed<O::Affine, F::Full>(axis, xs, row);
    } else {
      if (family_ == F::DivergenceFree)
        evaluateComponentFixed<O::Quadratic, F::DivergenceFree>(axis, xs, row);
      else
        evaluateComponentFixed<O::Quadratic, F::Full>(axis, xs, row);
    }
  }

  /// Full evaluation, ROW-MAJOR Dim x size(): C[a * size() + k] = component a of field k.
  /// (Row a is exactly what evaluateComponent(a, ...) writes.) C needs Dim * size() entries.
  void evaluate(const double* xs, double* C) const {
    for (int a = 0; a < Dim; ++a) evaluateComponent(a, xs, C + a * size_);
  }

  /// Monomials the family's fields use: 1 + Dim (affine) or (Dim + 1)(Dim + 2) / 2 (quadratic).
  constexpr int monomialCount() const { return polynomial_detail::numMonomials(Dim, order_); }

  /// out[m] = monomial m at xs (the header's order), m < count (1 + Dim or kMaxMonomials).
  static inline void monomials(const double* xs, int count, double* out) {
    const double x = xs[0], y = xs[1];
    out[0] = 1.0;
    out[1] = x;
    out[2] = y;
    if constexpr (Dim == 2) {
      if (count > 3) {
        out[3] = x * x;
        out[4] = x * y;
        out[5] = y * y;
      }
    } else {
      const double z = xs[2];
      out[3] = z;
      if (count > 4) {
        out[4] = x * x;
        out[5] = x * y;
        out[6] = x * z;
        out[7] = y * y;
        out[8] = y * z;
        out[9] = z * z;
      }
    }
  }

  /// coeff[m * size() + k] = the coefficient of monomial m in component `axis` of field k, so that
  /// evaluateComponent(axis, xs, row) is row[k] = sum_m coeff[m * size() + k] monomial_m(xs)
  /// (m < monomialCount(); coeff needs monomialCount() * size() entries). With it a field
  /// C_a(x) v is evaluated as sum_m monomial_m(x) (coeff v)_m: monomialCount() multiply-adds per
  /// point instead of size().
  void componentCoefficients(int axis, double* coeff) const {
    namespace pd = polynomial_detail;
    const int count = monomialCount();
    for (int i = 0; i < count * size_; ++i) coeff[i] = 0.0;
    if (family_ == BasisFamily::Full) {
      for (int k = 0; k < size_; ++k)
        if (k % Dim == axis) coeff[(k / Dim) * size_ + k] = 1.0;
      return;
    }
    const pd::Term* terms;
    int termCount;
    if constexpr (Dim == 2) {
      terms = pd::kDivFreeTerms2D.data();
      termCount = order_ == PolynomialOrder::Affine ? pd::kDivFreeAffineTerms2D : static_cast<int>(pd::kDivFreeTerms2D.size());
    } else {
      terms = pd::kDivFreeTerms3D.data();
      termCount = order_ == PolynomialOrder::Affine ? pd::kDivFreeAffineTerms3D : static_cast<int>(pd::kDivFreeTerms3D.size());
    }
    for (int t = 0; t < termCount; ++t)
      if (terms[t].comp == axis) coeff[terms[t].mono * size_ + terms[t].field] += terms[t].coeff;
  }

  /// div[k] = sum_c d(C_ck)/d xs_c at xs (w.r.t. scaled coordinates; divide by h for physical).
  /// Identically zero for the divergence-free families (computed from their term tables all the
  /// same); for the full family field k = e_c m_j has divergence d m_j / d x_c, c = k mod Dim.
  void divergence(const double* xs, double* div) const {
    namespace pd = polynomial_detail;
    if (family_ == BasisFamily::Full) {
      for (int k = 0; k < size_; ++k) div[k] = pd::monomialDerivative<Dim>(k / Dim, k % Dim, xs);
      return;
    }
    for (int k = 0; k < size_; ++k) div[k] = 0.0;
    const pd::Term* terms;
    int count;
    if constexpr (Dim == 2) {
      terms = pd::kDivFreeTerms2D.data();
      count = order_ == PolynomialOrder::Affine ? pd::kDivFreeAffineTerms2D
                                                : static_cast<int>(pd::kDivFreeTerms2D.size());
    } else {
      terms = pd::kDivFreeTerms3D.data();
      count = order_ == PolynomialOrder::Affine ? pd::kDivFreeAffineTerms3D
                                                : static_cast<int>(pd::kDivFreeTerms3D.size());
    }
    for (int t = 0; t < count; ++t)
      div[terms[t].field] += terms[t].coeff * pd::monomialDerivative<Dim>(terms[t].mono, terms[t].comp, xs);
  }

  /// Compile-time-family version of evaluateComponent (for loops that fix the family).
  template <PolynomialOrder Order, BasisFamily Family>
  static inline void evaluateComponentFixed(int axis, const double* xs, double* row) {
    constexpr bool kQuad = Order == PolynomialOrder::Quadratic;
    const double x = xs[0], y = xs[1];
    if constexpr (Dim == 2) {
      if constexpr (Family == BasisFamily::Full) {
        // field k = e_{k mod 2} m_{k div 2}: row[2j + axis] = m_j, row[2j + other] = 0
        double m[6] = {1.0, x, y, 0.0, 0.0, 0.0};
        if constexpr (kQuad) {
          m[3] = x * x;
          m[4] = x * y;
          m[5] = y * y;
        }
        constexpr int nm = kQuad ? 6 : 3;
        const int other = 1 - axis;
        for (int j = 0; j < nm; ++j) {
          row[2 * j + axis] = m[j];
          row[2 * j + other] = 0.0;
        }
      } else {
        // fields: (1,0) (0,1) (x,-y) (y,0) (0,x) | (x^2,-2xy) (y^2,0) (0,x^2) (-2xy,y^2)
        if (axis == 0) {
          row[0] = 1.0; row[1] = 0.0; row[2] = x; row[3] = y; row[4] = 0.0;
          if constexpr (kQuad) {
            const double xy = x * y;
            row[5] = x * x; row[6] = y * y; row[7] = 0.0; row[8] = -2.0 * xy;
          }
        } else {
          row[0] = 0.0; row[1] = 1.0; row[2] = -y; row[3] = 0.0; row[4] = x;
          if constexpr (kQuad) {
            const double xy = x * y;
            row[5] = -2.0 * xy; row[6] = 0.0; row[7] = x * x; row[8] = y * y;
          }
        }
      }
    } else {
      const double z = xs[2];
      if constexpr (Family == BasisFamily::Full) {
        // field k = e_{k mod 3} m_{k div 3}: row[3j + axis] = m_j, zero in the other two slots
        double m[10] = {1.0, x, y, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
        if constexpr (kQuad) {
          m[4] = x * x; m[5] = x * y; m[6] = x * z;
          m[7] = y * y; m[8] = y * z; m[9] = z * z;
        }
        constexpr int nm = kQuad ? 10 : 4;
        for (int j = 0; j < nm; ++j) {
          row[3 * j + 0] = 0.0;
          row[3 * j + 1] = 0.0;
          row[3 * j + 2] = 0.0;
          row[3 * j + axis] = m[j];
        }
      } else {
        // affine:    0 (1,0,0)   1 (0,1,0)   2 (0,0,1)
        //            3 (x,0,-z)  4 (y,0,0)   5 (z,0,0)   6 (0,x,0)   7 (0,y,-z)  8 (0,z,0)
        //            9 (0,0,x)  10 (0,0,y)
        // quadratic: 11 (x^2,0,-2xz) 12 (xy,0,-yz) 13 (xz,0,-z^2/2) 14 (y^2,0,0) 15 (yz,0,0)
        //            16 (z^2,0,0)    17 (0,x^2,0)  18 (0,xy,-xz)    19 (0,xz,0)  20 (0,y^2,-2yz)
        //            21 (0,yz,-z^2/2) 22 (0,z^2,0) 23 (0,0,x^2)     24 (0,0,xy)  25 (0,0,y^2)
        switch (axis) {
          case 0:
            row[0] = 1.0; row[1] = 0.0; row[2] = 0.0;
            row[3] = x; row[4] = y; row[5] = z;
            row[6] = 0.0; row[7] = 0.0; row[8] = 0.0; row[9] = 0.0; row[10] = 0.0;
            if constexpr (kQuad) {
              row[11] = x * x; row[12] = x * y; row[13] = x * z;
              row[14] = y * y; row[15] = y * z; row[16] = z * z;
              for (int k = 17; k < 26; ++k) row[k] = 0.0;
            }
            break;
          case 1:
            row[0] = 0.0; row[1] = 1.0; row[2] = 0.0;
            row[3] = 0.0; row[4] = 0.0; row[5] = 0.0;
            row[6] = x; row[7] = y; row[8] = z;
            row[9] = 0.0; row[10] = 0.0;
            if constexpr (kQuad) {
              for (int k = 11; k < 17; ++k) row[k] = 0.0;
              row[17] = x * x; row[18] = x * y; row[19] = x * z;
              row[20] = y * y; row[21] = y * z; row[22] = z * z;
              row[23] = 0.0; row[24] = 0.0; row[25] = 0.0;
            }
            break;
          default: {
            row[0] = 0.0; row[1] = 0.0; row[2] = 1.0;
            row[3] = -z; row[4] = 0.0; row[5] = 0.0;
            row[6] = 0.0; row[7] = -z; row[8] = 0.0;
            row[9] = x; row[10] = y;
            if constexpr (kQuad) {
              const double xz = x * z, yz = y * z, hzz = 0.5 * z * z;
              row[11] = -2.0 * xz; row[12] = -yz; row[13] = -hzz;
              row[14] = 0.0; row[15] = 0.0; row[16] = 0.0;
              row[17] = 0.0; row[18] = -xz; row[19] = 0.0;
              row[20] = -2.0 * yz; row[21] = -hzz; row[22] = 0.0;
              row[23] = x * x; row[24] = x * y; row[25] = y * y;
            }
            break;
          }
        }
      }
    }
  }

 private:
  PolynomialOrder order_;
  BasisFamily family_;
  int size_;
};

}  // namespace stokes::kernels
