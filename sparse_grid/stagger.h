#pragma once
// Staggered sample kinds, generic in the dimension.
//
// A sample kind is a "stagger mask": bit a set means the sample sits on the lower face of the cell
// along axis a (shifted by -dx/2 from the cell centre). So, for a cell with integer index i:
//   mask 0                 cell centre (i + 1/2) dx         pressure, diagonal stresses tau_aa
//   mask 1<<a              face normal to a                 velocity component u_a
//   mask (1<<a)|(1<<b)     edge along the third axis (3D),  off-diagonal stress tau_ab
//                          node (2D)
// One implementation serves 2D (the z = 0 layer) and 3D and every axis.
#include <array>
#include <cstdint>
#include <utility>

namespace stokes::sparse_grid {

using StaggerMask = std::uint8_t;

constexpr StaggerMask kCellCentre = 0;
constexpr StaggerMask faceMask(int axis) { return StaggerMask(1u << axis); }
constexpr StaggerMask pairMask(int a, int b) { return StaggerMask((1u << a) | (1u << b)); }

/// Stress channels of a symmetric Dim x Dim tensor: Dim diagonal entries at cell centres, then one
/// channel per axis pair (a < b) on edges (3D) or nodes (2D).
template <int Dim>
struct StressChannels {
  static_assert(Dim == 2 || Dim == 3, "StokesVDB supports 2D and 3D");
  static constexpr int kDiagonal = Dim;
  static constexpr int kPairs = Dim * (Dim - 1) / 2;
  static constexpr int kCount = kDiagonal + kPairs;

  /// Axis pairs (a, b), a < b, in channel order: (0,1) in 2D; (0,1) (0,2) (1,2) in 3D.
  static constexpr std::array<std::pair<int, int>, kPairs> pairs() {
    std::array<std::pair<int, int>, kPairs> p{};
    int k = 0;
    for (int a = 0; a < Dim; ++a)
      for (int b = a + 1; b < Dim; ++b) p[k++] = {a, b};
    return p;
  }
  /// Channel index of the off-diagonal pair (a, b), order-insensitive.
  static constexpr int pairChannel(int a, int b) {
    if (a > b) std::swap(a, b);
    const auto p = pairs();
    for (int k = 0; k < kPairs; ++k)
      if (p[k].first == a && p[k].second == b) return kDiagonal + k;
    return -1;
  }
  static constexpr StaggerMask mask(int channel) {
    if (channel < kDiagonal) return kCellCentre;
    const auto p = pairs()[channel - kDiagonal];
    return pairMask(p.first, p.second);
  }
  static constexpr bool isDiagonal(int channel) { return channel < kDiagonal; }
};

}  // namespace stokes::sparse_grid
