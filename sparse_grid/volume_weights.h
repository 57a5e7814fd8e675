#pragma once
// Volume weights (thesis 3.3.2, 3.6.2): the fraction of a sample's control volume -- the unit cell
// centred on the sample -- that lies inside a region { phi < 0 }. It is estimated by counting
// n^Dim sub-samples (n = 3 by default, so the smallest non-zero fraction is 1/27 in 3D).
#include <cmath>
#include <cstddef>

#include "sparse_grid/block_layout.h"

namespace stokes::grid {

namespace detail {
/// Fraction of the subsamples^Dim sub-sample centres of the unit control volume around `centre`
/// (spacing h = dx / subsamples) where phi < 0.
template <int Dim, class Phi>
double subsampledFraction(const Vec3d& centre, const Phi& phi, double dx, int subsamples) {
  const double h = dx / subsamples;
  const double first = -0.5 * dx + 0.5 * h;  // sub-sample centres at first + k h
  const int total = Dim == 2 ? subsamples * subsamples : subsamples * subsamples * subsamples;
  int inside = 0;
  for (int k = 0; k < total; ++k) {
    Vec3d p = centre;
    int rest = k;
    for (int a = 0; a < Dim; ++a) {
      p[a] += first + h * (rest % subsamples);
      rest /= subsamples;
    }
    inside += phi(p) < 0.0 ? 1 : 0;
  }
  return double(inside) / double(total);
}
}  // namespace detail

/// out[slot] = fraction of the control volume of sample kind `mask` of each slot with phi < 0.
/// `phi(const Vec3d& worldPos) -> double` must be safe to call from several threads.
template <int Dim, class Phi>
void computeVolumeFractions(const BlockLayout<Dim>& layout, StaggerMask mask, const Phi& phi,
                            double* out, int subsamples = 3) {
  const std::ptrdiff_t n = std::ptrdiff_t(layout.numSlots());
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < n; ++s)
    out[s] = detail::subsampledFraction<Dim>(layout.samplePosition(std::size_t(s), mask), phi, layout.dx(), subsamples);
}

/// computeVolumeFractions for a signed distance (|grad phi| <= 1, e.g. a level set): a control
/// volume whose centre lies farther than half a cell diagonal from the surface is entirely on one
/// side, so its fraction is 0 or 1 from one evaluation; only samples near the surface are
/// sub-sampled. Same result as computeVolumeFractions for such a phi, at ~1/27 of the cost away
/// from the surface.
template <int Dim, class Phi>
void computeVolumeFractionsOfDistance(const BlockLayout<Dim>& layout, StaggerMask mask, const Phi& phi, double* out,
                                      int subsamples = 3) {
  const double reach = 0.5 * std::sqrt(double(Dim)) * layout.dx();
  const std::ptrdiff_t n = std::ptrdiff_t(layout.numSlots());
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < n; ++s) {
    const Vec3d centre = layout.samplePosition(std::size_t(s), mask);
    const double c = phi(centre);
    out[s] = std::abs(c) > reach ? (c < 0.0 ? 1.0 : 0.0)
                                 : detail::subsampledFraction<Dim>(centre, phi, layout.dx(), subsamples);
  }
}

/// out[slot] = value(samplePosition) for every slot: fills a channel from an analytic function.
template <int Dim, class Fn>
void sampleField(const BlockLayout<Dim>& layout, StaggerMask mask, const Fn& value, double* out) {
  const std::ptrdiff_t n = std::ptrdiff_t(layout.numSlots());
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < n; ++s) out[s] = value(layout.samplePosition(std::size_t(s), mask));
}

}  // namespace stokes::grid
