#pragma once
// Sums that give the same bits for any rank count and any order of their terms: each term is
// rounded once to a multiple of 2^-32 (of its unit), and the multiples are added as 64-bit
// integers, which is exact and associative (docs/petsc.md, "Particles by block"). A volume
// fraction in [0, 1] per voxel keeps 2^-32 = 2.3e-10 of a voxel, and up to 2^31 whole voxels fit;
// a floating-point sum over the same voxels depends on where the ranks' parts begin.
#include <cmath>
#include <cstdint>
#include <stdexcept>

#include "sim/ranks/rank_comm.h"

namespace stokes::sim {
inline namespace ranks {

class ExactSum {
 public:
  static constexpr double kUnit = 0x1.0p-32;

  void add(double v) { units_ += std::int64_t(std::llround(v / kUnit)); }
  void add(const ExactSum& other) { units_ += other.units_; }
  std::int64_t units() const { return units_; }
  double value() const { return double(units_) * kUnit; }
  /// The sum over every rank's terms. Collective.
  ExactSum overRanks() const {
    ExactSum s;
    s.units_ = sumOverRanks(units_);
    return s;
  }

 private:
  std::int64_t units_ = 0;
};

}  // namespace ranks
}  // namespace stokes::sim
