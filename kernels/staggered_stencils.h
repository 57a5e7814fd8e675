#pragma once
// The staggered finite-difference operators of the variational Stokes discretisation (thesis 3.6),
// applied on the fly block by block, generic over the dimension and the axis.
//
//   G      cell -> face     (G p)_a[i]    = (p[i] - p[i - e_a]) / dx                gradient
//   G^T    face -> cell     (G^T u)[i]    = sum_a (u_a[i] - u_a[i + e_a]) / dx      = -div u
//   D      face -> stress   (D u)_aa[i]   = (u_a[i + e_a] - u_a[i]) / dx            strain rate eps_aa
//                           (D u)_ab[i]   = (u_a[i] - u_a[i - e_b]
//                                           + u_b[i] - u_b[i - e_a]) / dx         gamma_ab = 2 eps_ab
//   D^T    stress -> face   (D^T t)_a[i]  = (t_aa[i - e_a] - t_aa[i]) / dx
//                                           + sum_{b != a} (t_ab[i] - t_ab[i + e_b]) / dx
// (-D^T is the discrete tensor divergence.) Off-diagonal stresses are stored once per pair and
// paired with the engineering strain gamma_ab, so tau : eps = sum_a t_aa eps_aa + sum_{a<b} t_ab gamma_ab.
//
// Two fused kernels cover every system of the engine (K = [G Wp, D^T Wt] in the notation of
// docs/design.md §3):
//   facesFromCells:  f = S ⊙ ( G (wp ⊙ p) + D^T (wt ⊙ tau) )               ("K x", then scaled)
//   cellsFromFaces:  y_p = wp ⊙ G^T f,  y_tau = wt ⊙ D f  (+ d ⊙ x)         ("K^T f" + diagonal)
// With kAbs = true every coefficient is replaced by its absolute value; that gives the diagonal of
// K^T S K cheaply (diag_j = w_j^2 / dx^2 sum_{faces f next to j} S_f).
//
// Both kernels run over every block of the layout, or over a BlockList (for compact rows, issue
// 13: the blocks that hold a live row or an unknown face). Blocks not listed are not written; the
// caller keeps those outputs zero (they are still read as neighbours' halos) or never reads them.
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "sparse_grid/block_layout.h"
#include "sparse_grid/halo.h"
#include "sparse_grid/stagger.h"

namespace stokes::kernels {

using sparse_grid::BlockLayout;
using sparse_grid::HaloGeometry;
using sparse_grid::StressChannels;

/// Cell-centred inputs of K: pressure and stresses (channel-major, stride = numSlots) with their
/// volume weights. Any pointer may be null: a null value pointer drops that block of K, a null
/// weight means weight 1.
struct CellStressInput {
  const double* p = nullptr;
  const double* pWeight = nullptr;
  const double* tau = nullptr;
  const double* tauWeight = nullptr;
};

/// Outputs of K^T: y_p = wp ⊙ G^T f (+ pDiag ⊙ pX), y_tau = wt ⊙ D f (+ tauDiag ⊙ tauX).
struct CellStressOutput {
  double* p = nullptr;
  const double* pWeight = nullptr;
  const double* pDiag = nullptr;
  const double* pX = nullptr;
  double* tau = nullptr;
  const double* tauWeight = nullptr;
  const double* tauDiag = nullptr;
  const double* tauX = nullptr;
};

/// The blocks a kernel runs over, in increasing order; nullptr means every block of the layout.
using BlockList = std::vector<std::int32_t>;

namespace detail {
template <bool kAbs>
inline double diff(double a, double b) {
  if constexpr (kAbs) return a + b;
  else return a - b;
}
/// a b + c, rounded the same way by every kernel: one fused rounding where the CPU has FMA,
/// two roundings where it has not. Left to the compiler, contraction differs between a
/// vectorised loop and a scalar one, and the block and compact-row kernels (compact_stencils.h)
/// would no longer agree bit for bit.
inline double mulAdd(double a, double b, double c) {
#ifdef __FMA__
  return std::fma(a, b, c);
#else
  return a * b + c;
#endif
}
inline const double* channel(const double* base, int c, std::size_t n) { return base ? base + c * n : nullptr; }
inline double* channel(double* base, int c, std::size_t n) { return base ? base + c * n : nullptr; }
inline std::ptrdiff_t blockCount(const BlockList* blocks, std::size_t all) {
  return std::ptrdiff_t(blocks ? blocks->size() : all);
}
inline std::ptrdiff_t blockAt(const BlockList* blocks, std::ptrdiff_t k) { return blocks ? (*blocks)[k] : k; }
}  // namespace detail

/// Halo layers each stencil reads (see the formulas at the top of this file).
template <int Dim>
constexpr unsigned lowSides() {
  unsigned m = 0;
  for (int a = 0; a < Dim; ++a) m |= sparse_grid::haloSide(a, 0);
  return m;
}
template <int Dim>
constexpr unsigned stressSidesForFaces(int c) {
  if (StressChannels<Dim>::isDiagonal(c)) return sparse_grid::haloSide(c, 0);
  const auto p = StressChannels<Dim>::pairs()[c - StressChannels<Dim>::kDiagonal];
  return sparse_grid::haloSide(p.first, 1) | sparse_grid::haloSide(p.second, 1);
}
template <int Dim>
constexpr unsigned faceSidesForCells(int a) {
  unsigned m = sparse_grid::haloSide(a, 1);
  for (int b = 0; b < Dim; ++b)
    if (b != a) m |= sparse_grid::haloSide(b, 0);
  return m;
}

/// f_a = S_a ⊙ ( G (wp ⊙ p) + D^T (wt ⊙ tau) )_a for every face axis a (f has Dim channels).
/// faceScale (Dim channels) may be null (scale 1). `blocks`: see the top of this file.
template <int Dim, bool kAbs = false>
void facesFromCells(const BlockLayout<Dim>& layout, const CellStressInput& in, const double* faceScale,
                    double* faces, const BlockList* blocks = nullptr) {
  using H = HaloGeometry<Dim>;
  using SC = StressChannels<Dim>;
  constexpr int W = BlockLayout<Dim>::kWidth;
  constexpr int S = BlockLayout<Dim>::kSlots;
  constexpr auto st = H::kStride;
  constexpr auto pairs = SC::pairs();
  const std::size_t n = layout.numSlots();
  const double invDx = 1.0 / layout.dx();
  const bool hasP = in.p != nullptr, hasTau = in.tau != nullptr;
  const std::ptrdiff_t nBlocks = detail::blockCount(blocks, layout.numBlocks());

#pragma omp parallel if (parallel::forkGridLoop(std::size_t(nBlocks) * S))
  {
    parallel::countTeam(parallel::Region::GridLoop);
    std::vector<double> halo = sparse_grid::makeHaloBuffer<Dim>(1 + SC::kCount);
    double* P = halo.data();
    double* T = halo.data() + H::kSize;  // channel c at T + c * kSize
#pragma omp for schedule(static)
    for (std::ptrdiff_t k = 0; k < nBlocks; ++k) {
      const std::ptrdiff_t b = detail::blockAt(blocks, k);
      // sides read below: p[i - e_a] (low, every axis); t_aa[i - e_a] (low along a);
      // t_ab[i + e_b] and t_ab[i + e_a] (high along a and b)
      if (hasP) sparse_grid::gatherHalo<Dim>(layout, b, in.p, in.pWeight, P, lowSides<Dim>());
      if (hasTau)
        for (int c = 0; c < SC::kCount; ++c)
          sparse_grid::gatherHalo<Dim>(layout, b, in.tau + c * n, detail::channel(in.tauWeight, c, n), T + c * H::kSize,
                                stressSidesForFaces<Dim>(c));

      for (int a = 0; a < Dim; ++a) {
        double* fa = faces + a * n + b * S;
        const double* sa = faceScale ? faceScale + a * n + b * S : nullptr;
        const double* Taa = T + a * H::kSize;
        for (int r = 0; r < H::kRows; ++r) {
          const int h0 = H::rowHalo(r), s0 = H::rowSlot(r);
#pragma omp simd
          for (int x = 0; x < W; ++x) {
            const int h = h0 + x;
            double v = 0.0;
            if (hasP) v += detail::diff<kAbs>(P[h], P[h - st[a]]);  // (G p)_a
            if (hasTau) {
              v += detail::diff<kAbs>(Taa[h - st[a]], Taa[h]);      // (D^T t)_a, diagonal part
              for (int q = 0; q < SC::kPairs; ++q) {
                const int other = pairs[q].first == a ? pairs[q].second : pairs[q].second == a ? pairs[q].first : -1;
                if (other < 0) continue;
                const double* Tq = T + (SC::kDiagonal + q) * H::kSize;
                v += detail::diff<kAbs>(Tq[h], Tq[h + st[other]]);  // (D^T t)_a, shear part
              }
            }
            v *= invDx;
            fa[s0 + x] = sa ? sa[s0 + x] * v : v;
          }
        }
      }
    }
  }
}

/// y_p = wp ⊙ (G^T f) (+ pDiag ⊙ pX),  y_tau = wt ⊙ (D f) (+ tauDiag ⊙ tauX).
/// `blocks`: see the top of this file.
template <int Dim, bool kAbs = false>
void cellsFromFaces(const BlockLayout<Dim>& layout, const double* faces, const CellStressOutput& out,
                    const BlockList* blocks = nullptr) {
  using H = HaloGeometry<Dim>;
  using SC = StressChannels<Dim>;
  constexpr int W = BlockLayout<Dim>::kWidth;
  constexpr int S = BlockLayout<Dim>::kSlots;
  constexpr auto st = H::kStride;
  constexpr auto pairs = SC::pairs();
  const std::size_t n = layout.numSlots();
  const double invDx = 1.0 / layout.dx();
  const std::ptrdiff_t nBlocks = detail::blockCount(blocks, layout.numBlocks());

#pragma omp parallel if (parallel::forkGridLoop(std::size_t(nBlocks) * S))
  {
    parallel::countTeam(parallel::Region::GridLoop);
    std::vector<double> halo = sparse_grid::makeHaloBuffer<Dim>(Dim);
    std::array<const double*, Dim> F;
    for (int a = 0; a < Dim; ++a) F[a] = halo.data() + a * H::kSize;
#pragma omp for schedule(static)
    for (std::ptrdiff_t k = 0; k < nBlocks; ++k) {
      const std::ptrdiff_t b = detail::blockAt(blocks, k);
      // sides read below: f_a[i + e_a] (high along a) and f_a[i - e_b] (low along every b != a)
      for (int a = 0; a < Dim; ++a)
        sparse_grid::gatherHalo<Dim>(layout, b, faces + a * n, nullptr, halo.data() + a * H::kSize, faceSidesForCells<Dim>(a));
      const std::size_t base = std::size_t(b) * S;
      for (int r = 0; r < H::kRows; ++r) {
        const int h0 = H::rowHalo(r);
        const std::size_t s0 = base + H::rowSlot(r);
        if (out.p) {
#pragma omp simd
          for (int x = 0; x < W; ++x) {
            const int h = h0 + x;
            double v = 0.0;
            for (int a = 0; a < Dim; ++a) v += detail::diff<kAbs>(F[a][h], F[a][h + st[a]]);  // G^T f
            v *= invDx;
            if (out.pWeight) v *= out.pWeight[s0 + x];
            if (out.pDiag) v = detail::mulAdd(out.pDiag[s0 + x], out.pX[s0 + x], v);
            out.p[s0 + x] = v;
          }
        }
        if (out.tau) {
          for (int c = 0; c < SC::kCount; ++c) {
            double* y = out.tau + c * n + s0;
            const double* w = out.tauWeight ? out.tauWeight + c * n + s0 : nullptr;
            const double* d = out.tauDiag ? out.tauDiag + c * n + s0 : nullptr;
            const double* xx = out.tauX ? out.tauX + c * n + s0 : nullptr;
            if (c < SC::kDiagonal) {
              const double* Fa = F[c];
#pragma omp simd
              for (int x = 0; x < W; ++x) {
                const int h = h0 + x;
                double v = detail::diff<kAbs>(Fa[h + st[c]], Fa[h]) * invDx;  // eps_aa
                if (w) v *= w[x];
                if (d) v = detail::mulAdd(d[x], xx[x], v);
                y[x] = v;
              }
            } else {
              const int a = pairs[c - SC::kDiagonal].first, bb = pairs[c - SC::kDiagonal].second;
              const double* Fa = F[a];
              const double* Fb = F[bb];
#pragma omp simd
              for (int x = 0; x < W; ++x) {
                const int h = h0 + x;
                double v = (detail::diff<kAbs>(Fa[h], Fa[h - st[bb]]) + detail::diff<kAbs>(Fb[h], Fb[h - st[a]])) *
                           invDx;  // gamma_ab
                if (w) v *= w[x];
                if (d) v = detail::mulAdd(d[x], xx[x], v);
                y[x] = v;
              }
            }
          }
        }
      }
    }
  }
}

}  // namespace stokes::kernels
