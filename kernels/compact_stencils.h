#pragma once
// The fused stencils of staggered_stencils.h on compact vectors, through a compact neighbour
// index. Where the block kernels sweep every slot of every 8^Dim block that holds an
// unknown -- 7 slots per unknown on the armadillos -- these run over the unknowns only:
//
//   rows  R = the live rows of x = [p | tau] (channel-major padded order, compact index k)
//   faces F = the faces whose K x is needed (unknown and tile faces, compact index m)
//
//   faces pass:  f_m = S_m ⊙ invDx ⊙ sum_j (wx[plus_mj] - wx[minus_mj])        (K x, then scaled)
//   rows pass:   y_k = w_k ⊙ invDx ⊙ sum_j (f[plus_kj] - f[minus_kj]) (+ d_k x_k)   (K^T f + C x)
//
// with wx = w ⊙ x. Each term is one of the "diff" pairs of staggered_stencils.h, stored as two
// 32-bit indices; a sample outside R (or a face outside F, or a missing neighbour block) points
// to a trailing zero entry of wx (or f). The pairs are listed in the order in which the block
// kernels add them, so both give bit-identical results (tested).
//
// Face terms of face a at cell i (kernels/staggered_stencils.h, facesFromCells):
//   (p[i], p[i - e_a]);  with stresses also (t_aa[i - e_a], t_aa[i]) and, for every pair q = (a, o)
//   or (o, a) in channel order, (t_q[i], t_q[i + e_o]).
// Row terms of the sample of cell i (cellsFromFaces):
//   p:     (f_a[i], f_a[i + e_a]) for a = 0 .. Dim-1
//   t_aa:  (f_a[i + e_a], f_a[i])
//   t_ab:  (f_a[i], f_a[i - e_b]), (f_b[i], f_b[i - e_a])
#include <array>
#include <cstdint>
#include <limits>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "sparse_grid/block_layout.h"
#include "sparse_grid/stagger.h"
#include "kernels/staggered_stencils.h"

namespace stokes::kernels {

template <int Dim>
class CompactStencil {
 public:
  using Index = std::uint32_t;
  using SC = sparse_grid::StressChannels<Dim>;
  /// Row channels: 0 = pressure, 1 + c = stress channel c.
  static constexpr int kMaxChannels = 1 + SC::kCount;

  CompactStencil() = default;

  /// `rows`: the live rows, increasing indices into the padded [p | tau] vector (channels * n);
  /// `faces`: the faces whose K x is needed, increasing indices into the padded face vector
  /// (Dim * n). withStress = false: pressure only (the projection).
  CompactStencil(const sparse_grid::BlockLayout<Dim>& layout, std::span<const Index> rows, std::span<const Index> faces,
                 bool withStress)
      : n_(layout.numSlots()),
        channels_(withStress ? kMaxChannels : 1),
        facePairs_(withStress ? 2 + (Dim - 1) : 1),
        numRows_(rows.size()),
        numFaces_(faces.size()),
        invDx_(1.0 / layout.dx()) {
    if (std::size_t(channels_) * n_ >= std::numeric_limits<Index>::max() ||
        std::size_t(Dim) * n_ >= std::numeric_limits<Index>::max())
      throw std::invalid_argument("CompactStencil: " + std::to_string(n_) + " slots per channel exceed 32-bit indices");
    rowBegin_ = channelStarts(rows, channels_);
    channelStarts(faces, Dim);  // validates the face list
    faceSlot_.resize(numFaces_);
    for (std::size_t m = 0; m < numFaces_; ++m) faceSlot_[m] = faces[m];
    const std::vector<Index> rowOf = inverse(rows, std::size_t(channels_) * n_);
    const std::vector<Index> faceOf = inverse(faces, std::size_t(Dim) * n_);
    buildFaceTerms(layout, rowOf);
    buildRowTerms(layout, rows, faceOf);
  }

  std::size_t numRows() const { return numRows_; }
  std::size_t numFaces() const { return numFaces_; }
  int channels() const { return channels_; }
  /// Compact rows [rowBegin(c), rowBegin(c + 1)) belong to row channel c.
  std::size_t rowBegin(int c) const { return rowBegin_[c]; }
  /// Padded face index of compact face m.
  Index paddedFace(std::size_t m) const { return faceSlot_[m]; }

  /// f_m = S_m (K x)_m for every compact face; wx = w ⊙ x with numRows() + 1 entries, the last
  /// one zero; f has numFaces() + 1 entries (the last is left zero). Call inside a parallel region.
  void facesFromRows(const double* wx, const double* faceScale, double* f) const {
    const int terms = 2 * facePairs_;
#pragma omp for schedule(static) nowait
    for (std::ptrdiff_t m = 0; m < std::ptrdiff_t(numFaces_); ++m) {
      const Index* t = faceTerms_.data() + std::size_t(m) * terms;
      double v = 0.0;
      for (int j = 0; j < terms; j += 2) v += wx[t[j]] - wx[t[j + 1]];
      v *= invDx_;
      f[m] = faceScale[m] * v;
    }
  }

  /// y_k = w_k (K^T f)_k (+ d_k x_k on channels >= 1 when d is given). Call inside a parallel region.
  void rowsFromFaces(const double* f, const double* w, const double* d, const double* x, double* y) const {
    for (int c = 0; c < channels_; ++c) {
      const int terms = 2 * rowPairs(c);
      const Index* base = rowTerms_.data() + rowTermBegin_[c];
      const std::ptrdiff_t k0 = std::ptrdiff_t(rowBegin_[c]), k1 = std::ptrdiff_t(rowBegin_[c + 1]);
      const bool withDiag = c > 0 && d;
#pragma omp for schedule(static) nowait
      for (std::ptrdiff_t k = k0; k < k1; ++k) {
        const Index* t = base + std::size_t(k - k0) * terms;
        double v = 0.0;
        for (int j = 0; j < terms; j += 2) v += f[t[j]] - f[t[j + 1]];
        v *= invDx_;
        v *= w[k];
        if (withDiag) v = detail::mulAdd(d[k], x[k], v);
        y[k] = v;
      }
    }
  }

  /// Index memory in bytes (for reports).
  std::size_t bytes() const { return (faceTerms_.size() + rowTerms_.size() + faceSlot_.size()) * sizeof(Index); }

 private:
  static constexpr Index kNone = std::numeric_limits<Index>::max();

  int rowPairs(int c) const {
    if (c == 0) return Dim;
    return SC::isDiagonal(c - 1) ? 1 : 2;
  }

  /// First compact index of each channel (channel = padded index / n), plus the end.
  std::vector<std::size_t> channelStarts(std::span<const Index> sorted, int channels) const {
    std::vector<std::size_t> begin(channels + 1, sorted.size());
    for (std::size_t k = sorted.size(); k-- > 0;) {
      const std::size_t c = sorted[k] / n_;
      if (c >= std::size_t(channels) || (k + 1 < sorted.size() && sorted[k] >= sorted[k + 1]))
        throw std::invalid_argument("CompactStencil: indices must increase and stay below channels x slots");
      for (std::size_t cc = 0; cc <= c; ++cc) begin[cc] = k;
    }
    return begin;
  }
  static std::vector<Index> inverse(std::span<const Index> sorted, std::size_t full) {
    std::vector<Index> of(full, kNone);
    for (std::size_t k = 0; k < sorted.size(); ++k) of[sorted[k]] = Index(k);
    return of;
  }
  /// Compact index of (channel, slot moved by dir along axis), or `zero` when absent.
  Index at(const sparse_grid::BlockLayout<Dim>& layout, const std::vector<Index>& of, int channel, std::size_t slot, int axis,
           int dir, Index zero) const {
    std::int64_t s = std::int64_t(slot);
    if (dir != 0) s = layout.neighbourSlot(slot, axis, dir);
    if (s < 0) return zero;
    const Index k = of[std::size_t(channel) * n_ + std::size_t(s)];
    return k == kNone ? zero : k;
  }

  void buildFaceTerms(const sparse_grid::BlockLayout<Dim>& layout, const std::vector<Index>& rowOf) {
    constexpr auto pairs = SC::pairs();
    const int terms = 2 * facePairs_;
    const Index zero = Index(numRows_);
    faceTerms_.resize(numFaces_ * terms);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t m = 0; m < std::ptrdiff_t(numFaces_); ++m) {
      const int a = int(faceSlot_[m] / n_);
      const std::size_t s = faceSlot_[m] % n_;
      Index* t = faceTerms_.data() + std::size_t(m) * terms;
      *t++ = at(layout, rowOf, 0, s, a, 0, zero);   // p[i]
      *t++ = at(layout, rowOf, 0, s, a, -1, zero);  // p[i - e_a]
      if (channels_ == 1) continue;
      *t++ = at(layout, rowOf, 1 + a, s, a, -1, zero);  // t_aa[i - e_a]
      *t++ = at(layout, rowOf, 1 + a, s, a, 0, zero);   // t_aa[i]
      for (int q = 0; q < SC::kPairs; ++q) {
        const int other = pairs[q].first == a ? pairs[q].second : pairs[q].second == a ? pairs[q].first : -1;
        if (other < 0) continue;
        *t++ = at(layout, rowOf, 1 + SC::kDiagonal + q, s, other, 0, zero);  // t_q[i]
        *t++ = at(layout, rowOf, 1 + SC::kDiagonal + q, s, other, 1, zero);  // t_q[i + e_other]
      }
    }
  }

  void buildRowTerms(const sparse_grid::BlockLayout<Dim>& layout, std::span<const Index> rows, const std::vector<Index>& faceOf) {
    constexpr auto pairs = SC::pairs();
    const Index zero = Index(numFaces_);
    rowTermBegin_.assign(channels_, 0);
    std::size_t total = 0;
    for (int c = 0; c < channels_; ++c) {
      rowTermBegin_[c] = total;
      total += (rowBegin_[c + 1] - rowBegin_[c]) * 2 * rowPairs(c);
    }
    rowTerms_.resize(total);
    for (int c = 0; c < channels_; ++c) {
      const int terms = 2 * rowPairs(c);
      const std::ptrdiff_t k0 = std::ptrdiff_t(rowBegin_[c]), k1 = std::ptrdiff_t(rowBegin_[c + 1]);
      Index* base = rowTerms_.data() + rowTermBegin_[c];
#pragma omp parallel for schedule(static)
      for (std::ptrdiff_t k = k0; k < k1; ++k) {
        const std::size_t s = rows[std::size_t(k)] % n_;
        Index* t = base + std::size_t(k - k0) * terms;
        if (c == 0) {
          for (int a = 0; a < Dim; ++a) {
            *t++ = at(layout, faceOf, a, s, a, 0, zero);  // f_a[i]
            *t++ = at(layout, faceOf, a, s, a, 1, zero);  // f_a[i + e_a]
          }
        } else if (SC::isDiagonal(c - 1)) {
          const int a = c - 1;
          *t++ = at(layout, faceOf, a, s, a, 1, zero);  // f_a[i + e_a]
          *t++ = at(layout, faceOf, a, s, a, 0, zero);  // f_a[i]
        } else {
          const int a = pairs[c - 1 - SC::kDiagonal].first, b = pairs[c - 1 - SC::kDiagonal].second;
          *t++ = at(layout, faceOf, a, s, b, 0, zero);   // f_a[i]
          *t++ = at(layout, faceOf, a, s, b, -1, zero);  // f_a[i - e_b]
          *t++ = at(layout, faceOf, b, s, a, 0, zero);   // f_b[i]
          *t++ = at(layout, faceOf, b, s, a, -1, zero);  // f_b[i - e_a]
        }
      }
    }
  }

  std::size_t n_ = 0;
  int channels_ = 1, facePairs_ = 1;
  std::size_t numRows_ = 0, numFaces_ = 0;
  double invDx_ = 1.0;
  std::vector<std::size_t> rowBegin_, rowTermBegin_;
  std::vector<Index> faceSlot_, faceTerms_, rowTerms_;
};

}  // namespace stokes::kernels
