#pragma once
// Sums that give the same bits for any rank count and any order of their terms: each term is
// rounded once to a multiple of 2^-32 (of its unit), and the multiples are added as 64-bit
// integers, which is exact and associative (docs/petsc.md, "Particles by block"). A volume
// fraction in [0, 1] per voxel keeps 2^-32 = 2.3e-10 of a voxel, and up to 2^31 whole voxels fit;
// a floating-point sum over the same voxels depends on where the ranks' parts begin.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>

#include "sim/ranks/rank_comm.h"

namespace stokes::sim {
inline namespace ranks {

class ExactSum {
 public:
  static constexpr double kUnit = 0x1.0p-32;

  /// Terms rounded to multiples of `unit` (a power of 2); the sum may reach 2^63 units.
  explicit ExactSum(double unit = kUnit) : unit_(unit) {}
  void add(double v) { units_ += std::int64_t(std::llround(v / unit_)); }
  void add(const ExactSum& other) { units_ += other.units_; }
  /// Adds `count` whole units of 1.
  void addWhole(std::size_t count) { units_ += std::int64_t(std::llround(double(count) / unit_)); }
  std::int64_t units() const { return units_; }
  double value() const { return double(units_) * unit_; }
  /// The sum over every rank's terms. Collective.
  ExactSum overRanks() const {
    ExactSum s(unit_);
    s.units_ = sumOverRanks(units_);
    return s;
  }

 private:
  double unit_;
  std::int64_t units_ = 0;
};

}  // namespace ranks
}  // namespace stokes::sim
