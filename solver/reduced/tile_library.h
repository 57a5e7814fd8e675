#pragma once
// The tile-inverse library (thesis 4.5; docs/design.md §3): the per-tile matrices that depend only on
// the tile's shape -- not on u*, dt, mu or rho -- computed once and shared.
//
//   M^ = sum_{faces j} C_j^T C_j                   (M_R = rho M^)
//   K^ = sum_{inside stress s} c_s^-1 d_s d_s^T    (K_R = mu K^)
//   F  = sum_{fit faces j} C_j^T C_j, kept as a rank-revealing QR (the least-squares fit)
//   K^ Phi = M^ Phi Lambda,  Phi^T M^ Phi = I      (generalised eigen-decomposition)
//   T                                              (the modes the shape resolves, see below)
//
// so that for any dt, mu and rho
//   B^-1 = (rho/dt M^ + mu K^)^-1 = Phi diag(1 / (rho/dt + mu lambda_k)) Phi^T
// with no refactorisation. Strategies (TileCacheStrategy):
//   None     every tile is factored every step;
//   Library  tiles that fill their bounding box ("cube tiles", not clipped by the band) are looked
//            up by their extents; irregular tiles are factored every step;
//   Shapes   every tile is looked up by its occupancy mask, irregular ones too.
#include <Eigen/Dense>

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>

namespace stokes::solver {
inline namespace reduced {

enum class TileCacheStrategy { None, Library, Shapes };

inline const char* toString(TileCacheStrategy s) {
  switch (s) {
    case TileCacheStrategy::None: return "none";
    case TileCacheStrategy::Library: return "library";
    case TileCacheStrategy::Shapes: return "shapes";
  }
  return "?";
}

/// Shape-only blocks of one tile (see the file comment).
///
/// A tile whose fit faces do not resolve every basis field (a region one or two cells thick has
/// no quadratic modes across its thin direction) keeps the modes it resolves: its fields are the
/// columns of C T, T = [T_kept | 0] (reduced_tiles.h, resolvedModes), and every block above is
/// taken in that basis, with the identity added on the dropped columns of M^ and F so that they
/// stay invertible. A dropped mode has a zero basis row on every face: it couples to nothing, its
/// fit is 0, and its DOF is an inert row rho/dt v = 0 of the solve.
struct TileShapeBlocks {
  Eigen::MatrixXd massHat, viscHat;
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> fit;
  Eigen::MatrixXd eigenvectors;  ///< Phi, M^-orthonormal
  Eigen::VectorXd eigenvalues;   ///< lambda >= 0
  Eigen::MatrixXd modes;         ///< T (m x m), empty when the shape resolves every basis field
  int modeCount = 0;             ///< columns of T that are not zero (m when `modes` is empty)

  /// B^-1 = Phi diag(1 / (rho/dt + mu lambda)) Phi^T.
  Eigen::MatrixXd inverseB(double rho, double dt, double mu) const {
    const Eigen::VectorXd d = (rho / dt + mu * eigenvalues.array()).inverse().matrix();
    return eigenvectors * d.asDiagonal() * eigenvectors.transpose();
  }
};

/// A thread-safe cache of TileShapeBlocks keyed by a shape string. Keep one alive across steps
/// (and share it between solves) to reuse the factorisations.
class TileLibrary {
 public:
  using Entry = std::shared_ptr<const TileShapeBlocks>;

  Entry find(const std::string& key) const {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = entries_.find(key);
    if (it == entries_.end()) return nullptr;
    ++hits_;
    return it->second;
  }
  void insert(const std::string& key, Entry entry) {
    std::lock_guard<std::mutex> lock(mutex_);
    ++misses_;
    entries_.emplace(key, std::move(entry));
  }
  std::size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return entries_.size();
  }
  std::size_t hits() const { return hits_; }
  std::size_t misses() const { return misses_; }

 private:
  mutable std::mutex mutex_;
  std::unordered_map<std::string, Entry> entries_;
  mutable std::atomic<std::size_t> hits_{0};
  std::atomic<std::size_t> misses_{0};
};

}  // namespace reduced
}  // namespace stokes::solver
