#pragma once
// Per-block halo gather: copies one channel of a block (8^Dim values) and the face-adjacent layer
// of its neighbours into a dense (8+2)^Dim buffer, so that a stencil can then run on constant
// strides (1, 10, 100) with no branches and no tree look-ups. Edge and corner halo values are
// never read by the staggered stencils (they reach one step along one axis) and stay zero.
//
// Measured alternative designs are listed in docs/design.md §5; this is the "halo gather" variant.
#include <array>
#include <cstdint>
#include <vector>

#include "sparse_grid/block_layout.h"

namespace stokes::sparse_grid {

template <int Dim>
struct HaloGeometry {
  static constexpr int kWidth = BlockLayout<Dim>::kWidth + 2;  // 10
  static constexpr int kSize = Dim == 2 ? kWidth * kWidth : kWidth * kWidth * kWidth;
  static constexpr int kRows = BlockLayout<Dim>::kSlots / BlockLayout<Dim>::kWidth;  // 8 or 64
  static constexpr int kFaceEntries = 2 * Dim * kRows;  // one 8^(Dim-1) layer per side per axis
  /// Halo strides per world axis; the last axis is contiguous, like the block numbering.
  static constexpr std::array<int, 3> kStride =
      Dim == 3 ? std::array<int, 3>{kWidth * kWidth, kWidth, 1} : std::array<int, 3>{kWidth, 1, 0};

  struct FaceEntry {
    std::int16_t halo;   // index into the halo buffer
    std::int8_t code;    // neighbour-block code
    std::int16_t local;  // slot inside that neighbour block
  };

  /// Halo index of block-local cell (x, y, z); each coordinate may be -1 .. 8.
  static constexpr int haloIndex(int x, int y, int z = 0) {
    return Dim == 3 ? (z + 1) + (y + 1) * kWidth + (x + 1) * kWidth * kWidth : (y + 1) + (x + 1) * kWidth;
  }
  /// Halo index of the first cell of interior row r (rows run along the last axis; r enumerates
  /// the others exactly as the block numbering does: slot = 8 r + position in the row).
  static constexpr int rowHalo(int r) {
    return Dim == 2 ? haloIndex(r, 0) : haloIndex(r / 8, r % 8, 0);
  }
  static constexpr int rowSlot(int r) { return r * BlockLayout<Dim>::kWidth; }

  static constexpr std::array<FaceEntry, kFaceEntries> faceEntries() {
    std::array<FaceEntry, kFaceEntries> e{};
    int k = 0;
    constexpr int W = BlockLayout<Dim>::kWidth;
    for (int axis = 0; axis < Dim; ++axis)
      for (int side = 0; side < 2; ++side)
        for (int r = 0; r < kRows; ++r) {
          // r enumerates the 8^(Dim-1) cells of the layer; spread it over the other axes.
          int l[3] = {0, 0, 0};
          int rest = r;
          for (int a = 0; a < Dim; ++a) {
            if (a == axis) continue;
            l[a] = rest % W;
            rest /= W;
          }
          l[axis] = side == 0 ? -1 : W;
          int inNeighbour[3] = {l[0], l[1], l[2]};
          inNeighbour[axis] = side == 0 ? W - 1 : 0;
          int code = 0, pow3 = 1;
          for (int a = 0; a < Dim; ++a, pow3 *= 3) code += ((a == axis ? (side == 0 ? -1 : 1) : 0) + 1) * pow3;
          e[k].halo = std::int16_t(haloIndex(l[0], l[1], l[2]));
          e[k].code = std::int8_t(code);
          e[k].local = std::int16_t(BlockLayout<Dim>::localSlot(inNeighbour[0], inNeighbour[1], inNeighbour[2]));
          ++k;
        }
    return e;
  }
};

/// Bit of the halo side (axis, side): side 0 = the low layer (-1), 1 = the high layer (8).
constexpr unsigned haloSide(int axis, int side) { return 1u << (2 * axis + side); }
constexpr unsigned kAllHaloSides = 0x3Fu;

/// halo <- (w ⊙ x) over block b and the neighbour layers selected by `sides` (haloSide bits);
/// w == nullptr means weight 1. Missing neighbour blocks read as zero. Layers not selected keep
/// stale values: a stencil must only read the sides it asked for. Reading only the needed sides
/// matters: the layer across the x faces touches one cache line per value.
/// `halo` must hold HaloGeometry<Dim>::kSize doubles (allocate with makeHaloBuffer).
template <int Dim>
inline void gatherHalo(const BlockLayout<Dim>& layout, std::size_t b, const double* x,
                       const double* w, double* halo, unsigned sides = kAllHaloSides) {
  using H = HaloGeometry<Dim>;
  constexpr int W = BlockLayout<Dim>::kWidth;
  constexpr int S = BlockLayout<Dim>::kSlots;
  static constexpr auto kFaces = H::faceEntries();
  const double* xb = x + b * S;
  const double* wb = w ? w + b * S : nullptr;
  for (int r = 0; r < H::kRows; ++r) {
    double* dst = halo + H::rowHalo(r);
    const double* src = xb + H::rowSlot(r);
    if (wb) {
      const double* ws = wb + H::rowSlot(r);
#pragma omp simd
      for (int i = 0; i < W; ++i) dst[i] = src[i] * ws[i];
    } else {
#pragma omp simd
      for (int i = 0; i < W; ++i) dst[i] = src[i];
    }
  }
  const std::int32_t* nbrs = layout.neighbourTable() + b * BlockLayout<Dim>::kNeighbourCodes;
  for (int layer = 0; layer < 2 * Dim; ++layer) {  // faceEntries() is ordered (axis, side, row)
    if (!(sides & (1u << layer))) continue;
    const auto* first = kFaces.data() + layer * H::kRows;
    const std::int32_t nb = nbrs[first->code];
    if (nb < 0) {
      for (int r = 0; r < H::kRows; ++r) halo[first[r].halo] = 0.0;
      continue;
    }
    const double* xn = x + std::size_t(nb) * S;
    const double* wn = w ? w + std::size_t(nb) * S : nullptr;
    for (int r = 0; r < H::kRows; ++r) halo[first[r].halo] = wn ? xn[first[r].local] * wn[first[r].local] : xn[first[r].local];
  }
}

template <int Dim>
inline std::vector<double> makeHaloBuffer(int channels = 1) {
  return std::vector<double>(std::size_t(channels) * HaloGeometry<Dim>::kSize, 0.0);
}

}  // namespace stokes::sparse_grid
