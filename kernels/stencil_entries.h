#pragma once
// The rows and columns of K = [G Wp, D^T Wt] one sample at a time (unweighted, coefficients
// +-1/dx), for set-up work that needs individual entries: face classification, the tile coupling
// lists, exact Jacobi diagonals with tiles. The hot loops use staggered_stencils.h instead; both
// encode the same operators (see the stencil tests).
//
// Face index f = a * numSlots + slot (u_a on the lower face of the slot's cell).
// Cell-sample index: pressure p at `slot`; stress channel c at `slot`.
#include <cstdint>

#include "sparse_grid/block_layout.h"
#include "sparse_grid/stagger.h"

namespace stokes::kernels {

using sparse_grid::BlockLayout;
using sparse_grid::StressChannels;

/// Faces in the G^T row of the pressure at `slot`: (G^T f)[i] = sum_a (f_a[i] - f_a[i + e_a]) / dx.
/// fn(faceIndex, coefficient).
template <int Dim, class Fn>
void forEachPressureFace(const BlockLayout<Dim>& L, std::size_t slot, Fn&& fn) {
  const std::size_t n = L.numSlots();
  const double h = 1.0 / L.dx();
  for (int a = 0; a < Dim; ++a) {
    fn(std::int64_t(a * n + slot), h);
    const std::int64_t up = L.neighbourSlot(slot, a, +1);
    if (up >= 0) fn(std::int64_t(a * n + up), -h);
  }
}

/// Faces in the D row of stress channel c at `slot`:
///   eps_aa[i]   = (u_a[i + e_a] - u_a[i]) / dx
///   gamma_ab[i] = (u_a[i] - u_a[i - e_b] + u_b[i] - u_b[i - e_a]) / dx.
template <int Dim, class Fn>
void forEachStressFace(const BlockLayout<Dim>& L, int c, std::size_t slot, Fn&& fn) {
  using SC = StressChannels<Dim>;
  const std::size_t n = L.numSlots();
  const double h = 1.0 / L.dx();
  if (SC::isDiagonal(c)) {
    const int a = c;
    fn(std::int64_t(a * n + slot), -h);
    const std::int64_t up = L.neighbourSlot(slot, a, +1);
    if (up >= 0) fn(std::int64_t(a * n + up), h);
    return;
  }
  const auto [a, b] = SC::pairs()[c - SC::kDiagonal];
  fn(std::int64_t(a * n + slot), h);
  const std::int64_t downB = L.neighbourSlot(slot, b, -1);
  if (downB >= 0) fn(std::int64_t(a * n + downB), -h);
  fn(std::int64_t(b * n + slot), h);
  const std::int64_t downA = L.neighbourSlot(slot, a, -1);
  if (downA >= 0) fn(std::int64_t(b * n + downA), -h);
}

/// The samples whose rows contain face (axis a, slot): the column of K at that face.
/// fnP(pressureSlot, coefficient) and fnTau(channel, slot, coefficient), coefficients as above.
template <int Dim, class FnP, class FnTau>
void forEachSampleOfFace(const BlockLayout<Dim>& L, int a, std::size_t slot, FnP&& fnP, FnTau&& fnTau) {
  using SC = StressChannels<Dim>;
  const double h = 1.0 / L.dx();
  const std::int64_t down = L.neighbourSlot(slot, a, -1);
  // pressure: +h from cell i, -h from cell i - e_a
  fnP(slot, h);
  if (down >= 0) fnP(std::size_t(down), -h);
  // diagonal stress a: -h from cell i, +h from cell i - e_a
  fnTau(a, slot, -h);
  if (down >= 0) fnTau(a, std::size_t(down), h);
  // shear (a, b): +h from sample i, -h from sample i + e_b
  for (int b = 0; b < Dim; ++b) {
    if (b == a) continue;
    const int c = SC::pairChannel(a, b);
    fnTau(c, slot, h);
    const std::int64_t up = L.neighbourSlot(slot, b, +1);
    if (up >= 0) fnTau(c, std::size_t(up), -h);
  }
}

}  // namespace stokes::kernels
