#pragma once
// G = sum_k c_k c_k^T over m-vectors c_k given one at a time: a tile's mass, fit and viscous
// blocks (thesis Eq. 4.10-4.12, 4.25) and the tiling's fit test (reduced_tiles.h).
//
// One rank-1 update per face costs m^2 multiply-adds at matrix-vector speed; here the vectors are
// kept as the columns of an m x kColumns block and added by one symmetric rank-k update per block
// (matrix-matrix speed). The columns are summed in the order given, so a fixed order (a tile's
// shape order) gives the same bits on every run and thread count.
#include <Eigen/Dense>

namespace stokes::solver {
inline namespace reduced {

class GramAccumulator {
 public:
  explicit GramAccumulator(int m) : sum_(Eigen::MatrixXd::Zero(m, m)), columns_(m, kColumns) {}

  /// G += (scale c)(scale c)^T.
  template <class V>
  void add(const V& c, double scale = 1.0) {
    columns_.col(count_++) = scale * c;
    if (count_ == kColumns) flush();
  }

  /// The symmetric sum of everything added.
  Eigen::MatrixXd result() {
    flush();
    return sum_.selfadjointView<Eigen::Lower>();
  }

 private:
  static constexpr Eigen::Index kColumns = 64;

  void flush() {
    if (count_ > 0) sum_.selfadjointView<Eigen::Lower>().rankUpdate(columns_.leftCols(count_));
    count_ = 0;
  }

  Eigen::MatrixXd sum_, columns_;
  Eigen::Index count_ = 0;
};

}  // namespace reduced
}  // namespace stokes::solver
