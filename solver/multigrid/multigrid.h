#pragma once
// A symmetric multigrid V-cycle as a preconditioner, z = B r ~ A^-1 r, over a hierarchy of levels
// that it sees only as linear maps (no grid includes): each level has y = A_l x, its diagonal,
// and maps to the next coarser level (r_c = R r, e += P e_c). solver/multigrid/multigrid_hierarchy.h builds
// the levels from staggered problems by re-discretisation on coarsened layouts.
//
// One V-cycle, level l (Briggs, Henson & McCormick, "A Multigrid Tutorial", ch. 3):
//   x  = S_l f                         pre-smoothing from x = 0
//   x += P V_{l+1}(R (f - A_l x))      coarse-grid correction
//   x += S_l (f - A_l x)               post-smoothing, the same polynomial
// and on the coarsest level x = A_c^-1 f by a dense Cholesky factor of the active rows, or
// x = A_c^+ f (dense pseudo-inverse) where A_c is singular (a pressure Laplacian without Dirichlet rows).
//
// The smoother is a Chebyshev polynomial in D^-1 A (Adams, Brezina, Hu & Tuminaro 2003), aimed at
// the eigenvalues [lambdaMax / ratio, lambdaMax] of D^-1 A, lambdaMax from a power iteration. D is
// the diagonal, or block diagonal on rows a level groups into dense blocks (a tile's DOFs:
// MultigridLevel::DiagonalBlocks). The
// polynomial is self-adjoint in the A inner product, so with R = c P^T the cycle is a symmetric
// positive definite operator and can precondition CG and MINRES.
//
// Rows with a zero diagonal are inactive: the smoother never touches them and corrections are
// masked on them. Every step is a fixed sequence of deterministic kernels: the result does not
// depend on the thread count.
#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "solver/krylov/aligned_vector.h"
#include "solver/krylov/vector_ops.h"

namespace stokes::solver {
inline namespace multigrid {

/// Rows [begin, end) of a linear map y = M x.
using RowKernel = std::function<void(const double* x, double* y, std::size_t begin, std::size_t end)>;

/// One level as the V-cycle sees it. `restrictToCoarse` and `prolongToFine` are empty on the
/// coarsest level; prolongToFine writes (not adds) e = P e_c.
struct MultigridLevel {
  std::size_t size = 0;
  std::function<void(const double*, double*)> apply;
  Vector diagonal;
  std::function<void(const double*, double*)> restrictToCoarse;
  std::function<void(const double*, double*)> prolongToFine;
  /// Optional (assembled levels): the rows of A x and of P e_c, each with its row chunks (boundaries
  /// 0 = b_0 < ... < b_k = size, chunks of about equal work) and stored entries (its work, which
  /// decides whether a pass forks). With them every step of the cycle that maps a vector and then
  /// updates rows runs as one pass over the chunks: one fork-join, and the rows are updated while
  /// they are in cache.
  struct RowMap {
    RowKernel rows;
    std::vector<std::size_t> chunks;
    std::size_t entries = 0;
  };
  RowMap applyRows, prolongRows;
  /// Optional: the rows [begin, size) come in blocks of `size` consecutive rows whose dense
  /// diagonal blocks scale the smoother instead of their diagonal entries (block Jacobi), given as
  /// their inverses, row-major, block after block. For the DOFs of a reduced tile: its modes are
  /// coupled densely, and Jacobi on such a block spreads D^-1 A over a range the Chebyshev
  /// polynomial does not reach (bench/results/reduced_tiles.md).
  struct DiagonalBlocks {
    std::size_t begin = 0;
    int size = 0;
    Vector inverses;
    std::size_t count() const { return size > 0 ? inverses.size() / (std::size_t(size) * std::size_t(size)) : 0; }
  };
  DiagonalBlocks blocks;
};

/// y = M x over the chunks of `m`, with post(i) on every row of a chunk right after the chunk's rows
/// of M x (one pass; the threads share the chunks when m's work is worth a fork-join).
template <class Post>
void applyRowMap(const MultigridLevel::RowMap& m, const double* x, double* y, Post post) {
  const std::vector<std::size_t>& chunks = m.chunks;
  const std::size_t n = chunks.back();
  detail::parallelFor(
      chunks.size() - 1,
      [&](std::ptrdiff_t c) {
        const std::size_t begin = chunks[std::size_t(c)], end = chunks[std::size_t(c) + 1];
        m.rows(x, y, begin, end);
        for (std::size_t i = begin; i < end; ++i) post(std::ptrdiff_t(i));
      },
      m.entries + 4 * n);
}

/// Measured (bench/results/multigrid_cycles.md): degree 3 for the V-cycles of the SPD systems
/// (projection, viscosity, [p | tau]); degree 2 for the pressure-velocity form's block cycles, where
/// it took 1.0-2.1x less time than degree 3 (ball 48^3 / 64^3, disk N = 128 / 256).
inline constexpr int kDefaultSmootherDegree = 3;
inline constexpr int kPressureVelocitySmootherDegree = 2;

/// The pressure block of the pressure-velocity form's block preconditioner:
///   Diagonal        z_p = s^-1 r_p, the Schur diagonal estimate alone;
///   CahouetChabard  z_p = L^-1 r_p + s^-1 r_p, plus a V-cycle of the projection operator L;
///   Auto            Cahouet-Chabard iff the viscous number mu dt / (rho dx^2) is below
///                   kCahouetChabardMaxViscousNumber, else Diagonal.
enum class SchurApproximation { Auto, Diagonal, CahouetChabard };

/// Measured (bench/results/schur_block.md): the L^-1 term pays only where inertia dominates the
/// cells (2D disk N = 128: 44 against 311 MINRES iterations at mu dt / (rho dx^2) = 0.16, break-even
/// near 16, and 52 against 53 at 1,638 for 1.5x less time per iteration).
inline constexpr double kCahouetChabardMaxViscousNumber = 10.0;

struct MultigridOptions {
  /// Chebyshev degree per pre/post smoothing; 0: the preconditioner's default (kDefaultSmootherDegree,
  /// or kPressureVelocitySmootherDegree for the velocity and Schur blocks of the PV form)
  int smootherDegree = 0;
  double smootherRange = 20.0;       ///< smooth eigenvalues in [lambdaMax / range, lambdaMax]
  double lambdaSafety = 1.2;         ///< lambdaMax = safety * power-iteration estimate
  int powerIterations = 15;
  std::size_t maxCoarseRows = 800;   ///< dense coarse solve limit (active rows)
  /// Pressure-velocity form only: the pressure block (see SchurApproximation).
  SchurApproximation pressureSchur = SchurApproximation::Auto;
};

class Multigrid {
 public:
  Multigrid(std::vector<MultigridLevel> levels, const MultigridOptions& opt = {}) : opt_(opt) {
    if (levels.empty()) throw std::invalid_argument("Multigrid: no levels");
    if (opt_.smootherDegree == 0) opt_.smootherDegree = kDefaultSmootherDegree;
    if (opt_.smootherDegree < 0) throw std::invalid_argument("Multigrid: negative smoother degree");
    for (auto& l : levels) levels_.push_back(prepare(std::move(l)));
    factorCoarsest();
  }

  /// The rows a level works on: positive, finite diagonal (the others are inactive, see above).
  static bool isActive(double diagonal) { return diagonal > 0.0 && std::isfinite(diagonal); }
  static std::vector<std::uint8_t> activeRows(const Vector& diagonal) {
    std::vector<std::uint8_t> active(diagonal.size());
    for (std::size_t i = 0; i < diagonal.size(); ++i) active[i] = isActive(diagonal[i]) ? 1 : 0;
    return active;
  }

  std::size_t size() const { return levels_.front().op.size; }
  std::size_t numLevels() const { return levels_.size(); }
  std::size_t coarseRows() const { return coarseIndex_.size(); }
  /// Estimated largest eigenvalue of D^-1 A on level l (the smoother's upper bound / safety).
  double lambdaMax(std::size_t l) const { return levels_[l].lambdaMax / opt_.lambdaSafety; }

  /// z = B r, one V-cycle from z = 0.
  void apply(const double* r, double* z) const { cycle(0, r, z); }

 private:
  struct Level {
    MultigridLevel op;
    Vector invDiag, mask;
    mutable Vector blockWork;  // the block rows' share of a vector (blockScale)
    double lambdaMax = 1.0;
    mutable Vector r, t, d, dNext, fc, xc, e;  // work arrays (the cycle is not re-entrant)
  };

  // y = M x, then post(i) for every row i. With `rows`, chunk by chunk in one pass (the chunk's
  // rows of M x, then its post); else the whole map, then post over all rows. Either way each row
  // gets the same operations, so the two give the same bits.
  template <class Post>
  static void mapThen(const std::function<void(const double*, double*)>& map, const MultigridLevel::RowMap& rows,
                      const double* x, double* y, std::size_t n, Post post) {
    if (!rows.rows) {
      map(x, y);
      detail::parallelFor(n, post);
      return;
    }
    applyRowMap(rows, x, y, post);
  }

  // t = A_l x, then post(i) per row.
  template <class Post>
  static void applyThen(const Level& l, const double* x, double* t, Post post) {
    mapThen(l.op.apply, l.op.applyRows, x, t, l.op.size, post);
  }

  Level prepare(MultigridLevel op) {
    Level l;
    const std::size_t n = op.size;
    if (op.diagonal.size() != n) throw std::invalid_argument("Multigrid: diagonal size mismatch");
    for (const MultigridLevel::RowMap* m : {&op.applyRows, &op.prolongRows})
      if (m->rows && (m->chunks.size() < 2 || m->chunks.front() != 0 || m->chunks.back() != n))
        throw std::invalid_argument("Multigrid: row chunks must run from 0 to the level's size");
    const MultigridLevel::DiagonalBlocks& b = op.blocks;
    if (b.size > 0 && b.begin + b.count() * std::size_t(b.size) != n)
      throw std::invalid_argument("Multigrid: diagonal blocks must cover the rows from their first to the last");
    l.invDiag.assign(n, 0.0);
    l.mask.assign(n, 0.0);
    for (std::size_t i = 0; i < n; ++i)
      if (isActive(op.diagonal[i])) {
        // rows in a block: scaled by the block's inverse (blockScale), not by 1/d
        l.invDiag[i] = i < b.begin || b.size == 0 ? 1.0 / op.diagonal[i] : 0.0;
        l.mask[i] = 1.0;
      }
    l.blockWork.assign(n - std::min(n, b.size > 0 ? b.begin : n), 0.0);
    l.op = std::move(op);
    l.r.assign(n, 0.0);
    l.t.assign(n, 0.0);
    l.d.assign(n, 0.0);
    l.dNext.assign(n, 0.0);
    l.e.assign(n, 0.0);
    l.lambdaMax = opt_.lambdaSafety * estimateLambdaMax(l);
    return l;
  }

  // Power iteration on D^-1 A from a fixed pseudo-random start (deterministic).
  double estimateLambdaMax(Level& l) const {
    const std::size_t n = l.op.size;
    Vector& x = l.d;
    std::uint64_t state = 0x9E3779B97F4A7C15ull;
    for (std::size_t i = 0; i < n; ++i) {
      state = state * 6364136223846793005ull + 1442695040888963407ull;
      x[i] = l.mask[i] * (double(state >> 11) * 0x1.0p-53 - 0.5);
    }
    double lambda = 1.0;
    for (int it = 0; it < opt_.powerIterations; ++it) {
      const double norm = norm2(x.data(), n);
      if (!(norm > 0.0)) return 1.0;
      scale(1.0 / norm, x.data(), n);
      l.op.apply(x.data(), l.t.data());
      double* t = l.t.data();
      const double* inv = l.invDiag.data();
      blockScale(l, t, l.blockWork.data());
      detail::parallelFor(n, [=](std::ptrdiff_t i) { t[i] *= inv[i]; });
      std::copy(l.blockWork.begin(), l.blockWork.end(), t + (n - l.blockWork.size()));
      lambda = dot(x.data(), l.t.data(), n);  // Rayleigh quotient in the Euclidean product
      lambda = std::max(lambda, norm2(l.t.data(), n));
      copy(l.t.data(), x.data(), n);
    }
    return lambda;
  }

  // out = H_b^-1 in on the rows of the diagonal blocks, block by block (out: the blocks' rows only,
  // from the first block row).
  static void blockScale(const Level& l, const double* in, double* out) {
    const MultigridLevel::DiagonalBlocks& b = l.op.blocks;
    const std::size_t m = std::size_t(b.size);
    detail::parallelFor(
        b.count(),
        [&](std::ptrdiff_t k) {
          const double* h = b.inverses.data() + std::size_t(k) * m * m;
          const double* v = in + b.begin + std::size_t(k) * m;
          double* o = out + std::size_t(k) * m;
          for (std::size_t i = 0; i < m; ++i) {
            double s = 0.0;
            for (std::size_t j = 0; j < m; ++j) s += h[i * m + j] * v[j];
            o[i] = s;
          }
        },
        b.inverses.size());
  }

  // Chebyshev smoothing of A x = f, degree k in D^-1 A on [lo, hi] (Saad, Iterative Methods,
  // Alg. 12.1):  r = D^-1 (f - A x);  d = r / theta;  then k - 1 times  x += d,  r -= D^-1 A d,
  // rho' = 1 / (2 theta/delta - rho),  d' = rho' rho d + (2 rho'/delta) r;  finally x += d.
  // A d does not depend on x, so each step is one pass (applyThen): the rows of A d, then x, r and
  // d' on them, d' into a second array because later rows of A d still read d. The last step adds
  // its d' to x in the same pass.
  void smooth(const Level& l, const double* f, double* x, bool zeroGuess) const {
    const std::size_t n = l.op.size;
    const double hi = l.lambdaMax, lo = hi / opt_.smootherRange;
    const double theta = 0.5 * (hi + lo), delta = 0.5 * (hi - lo);
    double* r = l.r.data();
    double* d = l.d.data();
    double* dn = l.dNext.data();
    double* t = l.t.data();
    const double* inv = l.invDiag.data();
    // the block rows (invDiag 0 there): r_b = H_b^-1 (f - A x)_b, d_b = r_b / theta, and in each
    // step r_b -= H_b^-1 (A d)_b with d' and (last step) x corrected by the change of r_b
    const std::size_t b0 = n - l.blockWork.size();
    double* w = l.blockWork.data();
    if (zeroGuess) {
      detail::parallelFor(n, [=](std::ptrdiff_t i) {
        r[i] = inv[i] * f[i];
        d[i] = r[i] / theta;
      });
      if (b0 < n) blockScale(l, f, w);
    } else {
      applyThen(l, x, t, [=](std::ptrdiff_t i) {
        r[i] = inv[i] * (f[i] - t[i]);
        d[i] = r[i] / theta;
      });
      if (b0 < n) {
        for (std::size_t i = b0; i < n; ++i) t[i] = f[i] - t[i];
        blockScale(l, t, w);
      }
    }
    for (std::size_t i = b0; i < n; ++i) {
      r[i] = w[i - b0];
      d[i] = r[i] / theta;
    }
    if (opt_.smootherDegree == 1) {
      axpy(1.0, d, x, n);
      return;
    }
    double rho = delta / theta;
    for (int k = 1; k < opt_.smootherDegree; ++k) {
      const double rhoNext = 1.0 / (2.0 * theta / delta - rho);
      const double c1 = rhoNext * rho, c2 = 2.0 * rhoNext / delta;
      const bool last = k + 1 == opt_.smootherDegree;
      applyThen(l, d, t, [=](std::ptrdiff_t i) {
        x[i] += d[i];
        r[i] -= inv[i] * t[i];
        dn[i] = c1 * d[i] + c2 * r[i];
        if (last) x[i] += dn[i];
      });
      if (b0 < n) {
        blockScale(l, t, w);
        for (std::size_t i = b0; i < n; ++i) {
          r[i] -= w[i - b0];
          dn[i] -= c2 * w[i - b0];
          if (last) x[i] -= c2 * w[i - b0];
        }
      }
      std::swap(d, dn);
      rho = rhoNext;
    }
  }

  void cycle(std::size_t li, const double* f, double* x) const {
    const Level& l = levels_[li];
    const std::size_t n = l.op.size;
    if (li + 1 == levels_.size()) {
      solveCoarsest(f, x);
      return;
    }
    fill(x, 0.0, n);
    smooth(l, f, x, /*zeroGuess=*/true);
    // coarse-grid correction of the residual f - A x, on the active rows only: the transfers are
    // Mask P and R Mask, so that the cycle stays symmetric
    double* t = l.t.data();
    const double* mask = l.mask.data();
    applyThen(l, x, t, [=](std::ptrdiff_t i) { t[i] = mask[i] * (f[i] - t[i]); });
    const Level& c = levels_[li + 1];
    l.fc.resize(c.op.size);
    l.xc.resize(c.op.size);
    l.op.restrictToCoarse(l.t.data(), l.fc.data());
    cycle(li + 1, l.fc.data(), l.xc.data());
    const double* e = l.e.data();
    mapThen(l.op.prolongToFine, l.op.prolongRows, l.xc.data(), l.e.data(), n,
            [=](std::ptrdiff_t i) { x[i] += mask[i] * e[i]; });
    smooth(l, f, x, /*zeroGuess=*/false);
  }

  // The coarsest operator on its active rows, by applying it to unit vectors, then factored.
  void factorCoarsest() {
    const Level& l = levels_.back();
    const std::size_t n = l.op.size;
    for (std::size_t i = 0; i < n; ++i)
      if (l.mask[i] > 0.0) coarseIndex_.push_back(i);
    const std::size_t m = coarseIndex_.size();
    if (m > opt_.maxCoarseRows)
      throw std::runtime_error("Multigrid: coarsest level has " + std::to_string(m) + " active rows (limit " +
                               std::to_string(opt_.maxCoarseRows) + "); add levels");
    Eigen::MatrixXd a(m, m);
    Vector e(n, 0.0), col(n);
    for (std::size_t j = 0; j < m; ++j) {
      e[coarseIndex_[j]] = 1.0;
      l.op.apply(e.data(), col.data());
      e[coarseIndex_[j]] = 0.0;
      for (std::size_t i = 0; i < m; ++i) a(i, j) = col[coarseIndex_[i]];
    }
    a = 0.5 * (a + a.transpose()).eval();
    // Eigen's own OpenMP products choose their blocking by thread count, which would make the
    // factor (and every solve after it) depend on the thread count: factor on one thread.
    const int eigenThreads = Eigen::nbThreads();
    Eigen::setNbThreads(1);
    if (!factorCholesky(a)) pseudoInverse(a);
    Eigen::setNbThreads(eigenThreads);
  }

  // A = L L^T, kept where every pivot L_ii^2 exceeds kCoarsePivotCut times the largest: a
  // singular A (constants in a closed box's pressure) leaves a last pivot at rounding level.
  // m^3/3 multiply-adds against ~9 m^3 for the eigen-decomposition of pseudoInverse.
  bool factorCholesky(const Eigen::MatrixXd& a) {
    if (a.rows() == 0) return true;  // no active row: solveCoarsest has nothing to solve
    coarseFactor_.compute(a);
    if (coarseFactor_.info() != Eigen::Success) return false;
    const Eigen::VectorXd pivots = coarseFactor_.matrixLLT().diagonal().cwiseAbs2();
    useFactor_ = pivots.minCoeff() > kCoarsePivotCut * pivots.maxCoeff();
    return useFactor_;
  }

  // A^+ = V diag(1 / lambda) V^T over the eigenvalues above 1e-10 of the largest.
  void pseudoInverse(const Eigen::MatrixXd& a) {
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(a);
    const Eigen::VectorXd& lambda = eig.eigenvalues();
    const double cut = 1e-10 * std::max(std::abs(lambda.maxCoeff()), std::abs(lambda.minCoeff()));
    Eigen::VectorXd inv(a.rows());
    for (Eigen::Index i = 0; i < a.rows(); ++i) inv[i] = std::abs(lambda[i]) > cut ? 1.0 / lambda[i] : 0.0;
    coarseInverse_ = eig.eigenvectors() * inv.asDiagonal() * eig.eigenvectors().transpose();
  }

  void solveCoarsest(const double* f, double* x) const {
    const std::size_t m = coarseIndex_.size();
    fill(x, 0.0, levels_.back().op.size);
    Eigen::VectorXd b(m);
    for (std::size_t i = 0; i < m; ++i) b[i] = f[coarseIndex_[i]];
    const Eigen::VectorXd y = useFactor_ ? Eigen::VectorXd(coarseFactor_.solve(b)) : Eigen::VectorXd(coarseInverse_ * b);
    for (std::size_t i = 0; i < m; ++i) x[coarseIndex_[i]] = y[i];
  }

  /// Smallest pivot of the coarsest Cholesky factor, relative to the largest, that is kept.
  static constexpr double kCoarsePivotCut = 1e-10;

  MultigridOptions opt_;
  std::vector<Level> levels_;
  std::vector<std::size_t> coarseIndex_;
  Eigen::LLT<Eigen::MatrixXd> coarseFactor_;
  bool useFactor_ = false;
  Eigen::MatrixXd coarseInverse_;
};

}  // namespace multigrid
}  // namespace stokes::solver
