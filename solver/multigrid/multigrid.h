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
    /// Optional: run on x before the rows (a level whose rows read quantities derived from x as a
    /// whole, such as the tiles' coupling faces of tile_coupled_rows.h).
    std::function<void(const double* x)> prepare{};
  };
  RowMap applyRows, prolongRows;
  /// Optional: disjoint groups of rows whose dense diagonal blocks H_k scale the smoother instead of
  /// their diagonal entries (block Jacobi), given as their inverses. For the DOFs of a reduced tile:
  /// its modes are coupled densely, and Jacobi on such a block spreads D^-1 A over a range the
  /// Chebyshev polynomial does not reach (bench/results/reduced_tiles.md). For a strongly coupled
  /// pair of faces (galerkin_cycle.h, strongPairBlocks): a near-singular 2 x 2 block whose small
  /// eigenvalue of D^-1 A neither the smoother nor the coarse levels reach.
  struct DiagonalBlocks {
    std::vector<std::uint32_t> rows{};        ///< the rows of all blocks, block after block
    std::vector<std::size_t> offsets{0};      ///< block k: rows[offsets[k], offsets[k + 1])
    Vector inverses{};                        ///< H_k^-1, row-major, block after block
    std::vector<std::size_t> inverseOffsets{0};
    std::size_t count() const { return offsets.size() - 1; }
    std::size_t blockSize(std::size_t k) const { return offsets[k + 1] - offsets[k]; }
    /// Appends a block on `blockRows` (m rows) with its inverse `inverse` (m * m, row-major).
    void append(const std::uint32_t* blockRows, std::size_t m, const double* inverse) {
      rows.insert(rows.end(), blockRows, blockRows + m);
      offsets.push_back(rows.size());
      inverses.insert(inverses.end(), inverse, inverse + m * m);
      inverseOffsets.push_back(inverses.size());
    }
    /// out[q] = (H_k^-1 in_k) on each block's rows, in the order of `rows` (threads share the blocks).
    void scale(const double* in, double* out) const;
  };
  DiagonalBlocks blocks;
};

/// y = M x over the chunks of `m`, with post(i) on every row of a chunk right after the chunk's rows
/// of M x (one pass; the threads share the chunks when m's work is worth a fork-join).
template <class Post>
void applyRowMap(const MultigridLevel::RowMap& m, const double* x, double* y, Post post) {
  if (m.prepare) m.prepare(x);
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

/// How the Galerkin velocity cycle's prolongation interpolates across the face normals in 3D
/// (galerkin_cycle.h, GalerkinVelocityHierarchy::cellAxes): Constant, Linear, or Auto (linear from a
/// viscous number of kLinearMinViscousNumber). 2D is always linear.
enum class FaceInterpolation { Auto, Constant, Linear };

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
  /// Pressure-velocity form on live rows only: the velocity cycle's interpolation (FaceInterpolation).
  FaceInterpolation interpolation = FaceInterpolation::Auto;
};

class Multigrid {
 public:
  Multigrid(std::vector<MultigridLevel> levels, const MultigridOptions& opt = {});

  /// The rows a level works on: positive, finite diagonal (the others are inactive, see above).
  static bool isActive(double diagonal) { return diagonal > 0.0 && std::isfinite(diagonal); }
  static std::vector<std::uint8_t> activeRows(const Vector& diagonal);

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
    mutable Vector blockWork;  // the block rows' share of a vector (DiagonalBlocks::scale)
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

  Level prepare(MultigridLevel op);

  // Power iteration on D^-1 A from a fixed pseudo-random start (deterministic).
  double estimateLambdaMax(Level& l) const;


  // Chebyshev smoothing of A x = f, degree k in D^-1 A on [lo, hi] (Saad, Iterative Methods,
  // Alg. 12.1):  r = D^-1 (f - A x);  d = r / theta;  then k - 1 times  x += d,  r -= D^-1 A d,
  // rho' = 1 / (2 theta/delta - rho),  d' = rho' rho d + (2 rho'/delta) r;  finally x += d.
  // A d does not depend on x, so each step is one pass (applyThen): the rows of A d, then x, r and
  // d' on them, d' into a second array because later rows of A d still read d. The last step adds
  // its d' to x in the same pass.
  void smooth(const Level& l, const double* f, double* x, bool zeroGuess) const;

  void cycle(std::size_t li, const double* f, double* x) const;

  // The coarsest operator on its active rows, by applying it to unit vectors, then factored.
  void factorCoarsest();

  // A = L L^T, kept where every pivot L_ii^2 exceeds kCoarsePivotCut times the largest: a
  // singular A (constants in a closed box's pressure) leaves a last pivot at rounding level.
  // m^3/3 multiply-adds against ~9 m^3 for the eigen-decomposition of pseudoInverse.
  bool factorCholesky(const Eigen::MatrixXd& a);

  // A^+ = V diag(1 / lambda) V^T over the eigenvalues above 1e-10 of the largest.
  void pseudoInverse(const Eigen::MatrixXd& a);

  void solveCoarsest(const double* f, double* x) const;

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
