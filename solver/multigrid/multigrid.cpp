// The members of Multigrid (multigrid.h), compiled once into the stokes_systems library.
#include "solver/multigrid/multigrid.h"

namespace stokes::solver {
inline namespace multigrid {

Multigrid::Multigrid(std::vector<MultigridLevel> levels, const MultigridOptions& opt)
    : opt_(opt) {
  if (levels.empty()) throw std::invalid_argument("Multigrid: no levels");
  if (opt_.smootherDegree == 0) opt_.smootherDegree = kDefaultSmootherDegree;
  if (opt_.smootherDegree < 0) throw std::invalid_argument("Multigrid: negative smoother degree");
  for (auto& l : levels) levels_.push_back(prepare(std::move(l)));
  factorCoarsest();
}

std::vector<std::uint8_t> Multigrid::activeRows(const Vector& diagonal) {
  std::vector<std::uint8_t> active(diagonal.size());
  for (std::size_t i = 0; i < diagonal.size(); ++i) active[i] = isActive(diagonal[i]) ? 1 : 0;
  return active;
}

auto Multigrid::prepare(MultigridLevel op) -> Level {
  Level l;
  const std::size_t n = op.size;
  if (op.diagonal.size() != n) throw std::invalid_argument("Multigrid: diagonal size mismatch");
  for (const MultigridLevel::RowMap* m : {&op.applyRows, &op.prolongRows})
    if (m->rows && (m->chunks.size() < 2 || m->chunks.front() != 0 || m->chunks.back() != n))
      throw std::invalid_argument("Multigrid: row chunks must run from 0 to the level's size");
  const MultigridLevel::DiagonalBlocks& b = op.blocks;
  if (b.offsets.empty() || b.offsets.back() != b.rows.size() || b.inverseOffsets.size() != b.offsets.size() ||
      b.inverseOffsets.back() != b.inverses.size())
    throw std::invalid_argument("Multigrid: inconsistent diagonal blocks");
  std::vector<std::uint8_t> inBlock(n, 0);
  for (std::uint32_t i : b.rows) {
    if (i >= n || inBlock[i]) throw std::invalid_argument("Multigrid: diagonal blocks must hold distinct rows of the level");
    inBlock[i] = 1;
  }
  l.invDiag.assign(n, 0.0);
  l.mask.assign(n, 0.0);
  for (std::size_t i = 0; i < n; ++i)
    if (isActive(op.diagonal[i])) {
      // rows in a block: scaled by the block's inverse (DiagonalBlocks::scale), not by 1/d
      l.invDiag[i] = inBlock[i] ? 0.0 : 1.0 / op.diagonal[i];
      l.mask[i] = 1.0;
    }
  l.blockWork.assign(b.rows.size(), 0.0);
  l.op = std::move(op);
  l.r.assign(n, 0.0);
  l.t.assign(n, 0.0);
  l.d.assign(n, 0.0);
  l.dNext.assign(n, 0.0);
  l.e.assign(n, 0.0);
  l.lambdaMax = opt_.lambdaSafety * estimateLambdaMax(l);
  return l;
}

double Multigrid::estimateLambdaMax(Level& l) const {
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
    l.op.blocks.scale(t, l.blockWork.data());
    detail::parallelFor(n, [=](std::ptrdiff_t i) { t[i] *= inv[i]; });
    const std::uint32_t* rows = l.op.blocks.rows.data();
    const double* w = l.blockWork.data();
    detail::parallelFor(l.blockWork.size(), [=](std::ptrdiff_t q) { t[rows[q]] = w[q]; });
    lambda = dot(x.data(), l.t.data(), n);  // Rayleigh quotient in the Euclidean product
    lambda = std::max(lambda, norm2(l.t.data(), n));
    copy(l.t.data(), x.data(), n);
  }
  return lambda;
}

void MultigridLevel::DiagonalBlocks::scale(const double* in, double* out) const {
  detail::parallelFor(
      count(),
      [&](std::ptrdiff_t k) {
        const std::size_t first = offsets[std::size_t(k)], m = blockSize(std::size_t(k));
        const double* h = inverses.data() + inverseOffsets[std::size_t(k)];
        const std::uint32_t* blockRows = rows.data() + first;
        double* o = out + first;
        for (std::size_t i = 0; i < m; ++i) {
          double s = 0.0;
          for (std::size_t j = 0; j < m; ++j) s += h[i * m + j] * in[blockRows[j]];
          o[i] = s;
        }
      },
      inverses.size());
}

void Multigrid::smooth(const Level& l, const double* f, double* x, bool zeroGuess) const {
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
  const std::size_t nb = l.blockWork.size();
  const std::uint32_t* rows = l.op.blocks.rows.data();
  double* w = l.blockWork.data();
  if (zeroGuess) {
    detail::parallelFor(n, [=](std::ptrdiff_t i) {
      r[i] = inv[i] * f[i];
      d[i] = r[i] / theta;
    });
    if (nb > 0) l.op.blocks.scale(f, w);
  } else {
    applyThen(l, x, t, [=](std::ptrdiff_t i) {
      r[i] = inv[i] * (f[i] - t[i]);
      d[i] = r[i] / theta;
    });
    if (nb > 0) {
      detail::parallelFor(nb, [=](std::ptrdiff_t q) { t[rows[q]] = f[rows[q]] - t[rows[q]]; });
      l.op.blocks.scale(t, w);
    }
  }
  // (a row lies in one block at most, so the block rows' updates are independent)
  detail::parallelFor(nb, [=](std::ptrdiff_t q) {
    const std::size_t i = rows[q];
    r[i] = w[q];
    d[i] = r[i] / theta;
  });
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
    if (nb > 0) {
      l.op.blocks.scale(t, w);
      detail::parallelFor(nb, [=](std::ptrdiff_t q) {
        const std::size_t i = rows[q];
        r[i] -= w[q];
        dn[i] -= c2 * w[q];
        if (last) x[i] -= c2 * w[q];
      });
    }
    std::swap(d, dn);
    rho = rhoNext;
  }
}

void Multigrid::cycle(std::size_t li, const double* f, double* x) const {
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

void Multigrid::factorCoarsest() {
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

bool Multigrid::factorCholesky(const Eigen::MatrixXd& a) {
  if (a.rows() == 0) return true;  // no active row: solveCoarsest has nothing to solve
  coarseFactor_.compute(a);
  if (coarseFactor_.info() != Eigen::Success) return false;
  const Eigen::VectorXd pivots = coarseFactor_.matrixLLT().diagonal().cwiseAbs2();
  useFactor_ = pivots.minCoeff() > kCoarsePivotCut * pivots.maxCoeff();
  return useFactor_;
}

void Multigrid::pseudoInverse(const Eigen::MatrixXd& a) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(a);
  const Eigen::VectorXd& lambda = eig.eigenvalues();
  const double cut = 1e-10 * std::max(std::abs(lambda.maxCoeff()), std::abs(lambda.minCoeff()));
  Eigen::VectorXd inv(a.rows());
  for (Eigen::Index i = 0; i < a.rows(); ++i) inv[i] = std::abs(lambda[i]) > cut ? 1.0 / lambda[i] : 0.0;
  coarseInverse_ = eig.eigenvectors() * inv.asDiagonal() * eig.eigenvectors().transpose();
}

void Multigrid::solveCoarsest(const double* f, double* x) const {
  const std::size_t m = coarseIndex_.size();
  fill(x, 0.0, levels_.back().op.size);
  Eigen::VectorXd b(m);
  for (std::size_t i = 0; i < m; ++i) b[i] = f[coarseIndex_[i]];
  const Eigen::VectorXd y = useFactor_ ? Eigen::VectorXd(coarseFactor_.solve(b)) : Eigen::VectorXd(coarseInverse_ * b);
  for (std::size_t i = 0; i < m; ++i) x[coarseIndex_[i]] = y[i];
}

}  // namespace multigrid
}  // namespace stokes::solver
