#pragma once
// Volume weights (thesis 3.3.2, 3.6.2): the fraction of a sample's control volume -- the unit cell
// centred on the sample -- that lies inside a region { phi < 0 }: cut by the plane a signed
// distance defines at the sample (computePlaneCutFractions, the solid weights), or by counting
// n^Dim sub-samples (computeVolumeFractions; the liquid weights, see FractionRule; n = 3 by
// default, so the smallest non-zero fraction is 1/27 in 3D). The faces' liquid fractions are their
// masses; with plane cuts they are tent-weighted (computeTentMassFractions).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <optional>
#include <string_view>
#include <utility>

#include "sparse_grid/block_layout.h"

namespace stokes::sparse_grid {

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

/// phi(c) / (dx |grad phi(c)|_1): the signed distance from c to the plane phi defines there, in
/// units of the width dx |n|_1 that a unit cell spans along the plane's normal n (grad phi by
/// central differences of step dx/2). +-infinity where the gradient vanishes.
template <int Dim, class Phi>
double planeOffsetInWidths(const Vec3d& c, double centre, const Phi& phi, double dx) {
  double gradL1 = 0.0;
  for (int a = 0; a < Dim; ++a) {
    Vec3d lo = c, hi = c;
    lo[a] -= 0.25 * dx;
    hi[a] += 0.25 * dx;
    gradL1 += std::abs(phi(hi) - phi(lo)) / (0.5 * dx);
  }
  if (gradL1 > 0.0) return centre / (dx * gradL1);
  return centre < 0.0 ? -std::numeric_limits<double>::infinity() : std::numeric_limits<double>::infinity();
}

/// Cut fractions within this of 0 or 1 are 0 or 1 (CutRoundOff::Snap). A plane that only touches
/// a control volume (a wall on a grid line at a corner or a side) gives 1/2 - d = 0 or 1 exactly,
/// and round-off in phi and its differences leaves about 1e-15 there (more on large grids:
/// coordinates of 10^4 cells carry ~1e-12 of a cell). Such a weight holds no fluid, yet it makes a
/// live row whose diagonal is round-off, which a multigrid smoother scales by its inverse: on the
/// surface mode at n = 12 a corner cell outside the box had a diagonal of 8e-15, the V-cycle an
/// eigenvalue of 2.6e15, and CG and MINRES stalled; dx = 1/8 or 1/16, exact in binary, left none.
inline constexpr double kRoundOffFraction = 1e-10;
inline double snapRoundOff(double f) { return f < kRoundOffFraction ? 0.0 : (f > 1.0 - kRoundOffFraction ? 1.0 : f); }

/// Fills out[slot] = fraction(c, phi(c)) near the surface, 0 or 1 where |phi(c)| > reach (the
/// kernel's support lies on one side), 0 in inactive cells' slots with ActiveCells.
template <int Dim, class Phi, class Fraction>
void fillNearSurface(const BlockLayout<Dim>& layout, StaggerMask mask, const Phi& phi, double* out, double reach,
                     SlotsToFill slots, const Fraction& fraction) {
  const std::ptrdiff_t n = std::ptrdiff_t(layout.numSlots());
  const bool activeOnly = slots == SlotsToFill::ActiveCells;
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < n; ++s) {
    if (activeOnly && !layout.isActiveCell(std::size_t(s))) {
      out[s] = 0.0;
      continue;
    }
    const Vec3d c = layout.samplePosition(std::size_t(s), mask);
    const double centre = phi(c);
    out[s] = std::abs(centre) > reach ? (centre < 0.0 ? 1.0 : 0.0) : fraction(c, centre);
  }
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
                                      int subsamples = 3, SlotsToFill slots = SlotsToFill::All) {
  // ActiveCells: for a region { phi < 0 } clear of the control volumes of the inactive cells'
  // samples (the liquid, which the layout's band of cells around the particles surrounds).
  detail::fillNearSurface<Dim>(layout, mask, phi, out, 0.5 * std::sqrt(double(Dim)) * layout.dx(), slots,
                               [&](const Vec3d& centre, double) {
                                 return detail::subsampledFraction<Dim>(centre, phi, layout.dx(), subsamples);
                               });
}

/// out[slot] = fraction of the control volume of sample kind `mask` on the side phi < 0 of the
/// plane that the signed distance phi defines at the sample centre c:
///     f = clamp(1/2 - phi(c) / (dx |grad phi(c)|_1), 0, 1)  (round-off at 0 and 1 snapped for
///     walls and solids: CutRoundOff),
/// with grad phi by central differences of step dx/2. It is the exact cut fraction of the control
/// volume for a plane normal to an axis, and exact at f = 0, 1/2 and 1 for a plane of any normal
/// (the ramp between the plane touching a corner and passing through the centre). Unlike n^Dim
/// sub-samples (multiples of 1/n: a plane through the centre reads 1/3 or 2/3 with n = 3) it
/// moves continuously with the surface, which the solid weights need for the no-slip plane
/// (solver/problem/staggered_problem.h, fluidStress). For the liquid weights see FractionRule
/// below; the exact volume under the tangent plane was tried there and measured worse than this
/// ramp on a pool's surface mode. `slots` = ActiveCells leaves the inactive
/// cells' slots at 0, as in computeVolumeFractionsOfDistance.
/// Snap: fractions within detail::kRoundOffFraction of 0 or 1 are 0 or 1, for walls and solids.
/// Keep: every fraction as computed, for the liquid, whose tiny weights can be geometry (a
/// Gaussian bump's tail on a grid line) that the discretisation feels through the mass floor:
/// snapped, the bump test's mean rate moved by 0.6%.
enum class CutRoundOff { Snap, Keep };

template <int Dim, class Phi>
void computePlaneCutFractions(const BlockLayout<Dim>& layout, StaggerMask mask, const Phi& phi, double* out,
                              SlotsToFill slots = SlotsToFill::All, CutRoundOff roundOff = CutRoundOff::Snap) {
  const double dx = layout.dx();
  detail::fillNearSurface<Dim>(layout, mask, phi, out, 0.5 * std::sqrt(double(Dim)) * dx, slots,
                               [&](const Vec3d& c, double centre) {
                                 const double d = detail::planeOffsetInWidths<Dim>(c, centre, phi, dx);
                                 const double f = std::clamp(0.5 - d, 0.0, 1.0);
                                 return roundOff == CutRoundOff::Snap ? detail::snapRoundOff(f) : f;
                               });
}

/// out[slot] = the tent-weighted liquid fraction of a sample under the plane the signed distance
/// phi defines at its centre c: the integral of the tent (linear B-spline, half-width dx) centred
/// on the sample over { phi < 0 }, along the plane's normal:
///     f = T(-phi(c) / dx),  T(t) = (1 + t)^2 / 2 on [-1, 0], 1 - (1 - t)^2 / 2 on [0, 1],
/// 0 below and 1 above. Tents sum to one and reproduce linear functions (sum_k x_k tent_k(x) = x),
/// so as mass weights these fractions keep the liquid's mass and its first moment: the weight of
/// a partly filled cell acts at the liquid's centroid. The unit-box fractions put it on the face
/// whose box holds the surface, up to half a cell off, which made a pool's surface mode first order
/// in where the surface sat in its cell. Exact for a plane normal to an axis.
/// The support is one cell along the normal, not the box ramp's dx |n|_1: with that, faces a cell
/// above a gently sloped surface, whose cells hold no liquid, got mass that nothing held up (the
/// mode 2.8% slow where its crest touched a grid line).
template <int Dim, class Phi>
void computeTentMassFractions(const BlockLayout<Dim>& layout, StaggerMask mask, const Phi& phi, double* out,
                              SlotsToFill slots = SlotsToFill::All) {
  const double dx = layout.dx();
  detail::fillNearSurface<Dim>(layout, mask, phi, out, dx, slots, [&](const Vec3d&, double centre) {
    const double t = std::clamp(-centre / dx, -1.0, 1.0);
    return t <= 0.0 ? 0.5 * (1.0 + t) * (1.0 + t) : 1.0 - 0.5 * (1.0 - t) * (1.0 - t);
  });
}

/// How the liquid weights W_L are measured: PlaneCut, the plane-cut ramp of
/// computePlaneCutFractions (the faces' masses by computeTentMassFractions), or SubSamples, 3^Dim
/// sub-sample counts (computeVolumeFractionsOfDistance). Plane cuts read where the surface sits
/// inside its cell: on a pool's surface mode they keep the decay rate within 0.997-1.023 of linear
/// theory at 16 cells per wavelength and 1.002-1.003 at 64 wherever the surface sits, where
/// sub-samples swing from 0.79 to 1.15 (`stokesvdb analytic surface-mode --liquid-weights`); a film
/// draining down a wall converges with them wherever its surface sits, where sub-samples are right
/// on a grid line only. kLiquidFractionRule is that one decision, read by
/// fillLiquidWeights and by the scenes' default (`liquid_weights`).
enum class FractionRule { PlaneCut, SubSamples };
inline constexpr FractionRule kLiquidFractionRule = FractionRule::PlaneCut;

/// The rules' names, as scenes (`liquid_weights`) and command lines (`--liquid-weights`) spell them.
inline constexpr std::pair<const char*, FractionRule> kFractionRuleNames[] = {
    {"plane-cut", FractionRule::PlaneCut}, {"subsample", FractionRule::SubSamples}};

inline const char* fractionRuleName(FractionRule rule) {
  for (const auto& [name, r] : kFractionRuleNames)
    if (r == rule) return name;
  return "unknown";
}

/// The rule a name spells; std::nullopt for any other name.
inline std::optional<FractionRule> fractionRuleNamed(std::string_view name) {
  for (const auto& [n, r] : kFractionRuleNames)
    if (name == n) return r;
  return std::nullopt;
}

/// W_L of sample kind `mask` by `rule`, for a signed distance phi.
template <int Dim, class Phi>
void computeLiquidFractions(const BlockLayout<Dim>& layout, StaggerMask mask, const Phi& phi, double* out,
                            FractionRule rule = kLiquidFractionRule, SlotsToFill slots = SlotsToFill::All) {
  if (rule == FractionRule::PlaneCut) computePlaneCutFractions<Dim>(layout, mask, phi, out, slots, CutRoundOff::Keep);
  else computeVolumeFractionsOfDistance<Dim>(layout, mask, phi, out, 3, slots);
}

/// W_L^u, the faces' liquid fractions (the solve reads them as mass weights, faceMassWeights), by
/// `rule`: with sub-samples the box fractions, as every other channel; with plane cuts the
/// tent-weighted fractions, which keep the liquid's first moments (computeTentMassFractions).
template <int Dim, class Phi>
void computeLiquidFaceFractions(const BlockLayout<Dim>& layout, int axis, const Phi& phi, double* out,
                                FractionRule rule = kLiquidFractionRule, SlotsToFill slots = SlotsToFill::All) {
  if (rule == FractionRule::PlaneCut) computeTentMassFractions<Dim>(layout, faceMask(axis), phi, out, slots);
  else computeLiquidFractions<Dim>(layout, faceMask(axis), phi, out, rule, slots);
}

/// out[slot] = value(samplePosition) for every slot: fills a channel from an analytic function.
template <int Dim, class Fn>
void sampleField(const BlockLayout<Dim>& layout, StaggerMask mask, const Fn& value, double* out) {
  const std::ptrdiff_t n = std::ptrdiff_t(layout.numSlots());
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < n; ++s) out[s] = value(layout.samplePosition(std::size_t(s), mask));
}

}  // namespace stokes::sparse_grid
