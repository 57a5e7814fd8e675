#pragma once
// Assembled sparse matrices (the multigrid's levels on live rows, the Krylov tests' operators):
// compressed rows (CSR, 32-bit columns), built row by row in parallel chunks and concatenated in
// row order, so that every entry -- and its summation order -- is the same for any thread count.
//
//   y = A x        a parallel gather over rows, no write conflicts;
//   A^T            by a counting pass (deterministic: entries land in increasing row order);
//   C = A B        Gustavson's row-by-row product with a dense accumulator per thread;
//   A_c = P^T A P  the Galerkin coarse operator (Trottenberg, Oosterlee & Schueller, "Multigrid",
//                  2001, sec. 2.3.2), row by row without A P where P's rows are short.
#include <algorithm>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include <omp.h>

#include "solver/krylov/vector_ops.h"

namespace stokes::solver {
inline namespace krylov {

struct CsrMatrix {
  using Index = std::int32_t;
  std::size_t rows = 0, cols = 0;
  std::vector<std::int64_t> start{0};
  std::vector<Index> col;
  std::vector<double> value;

  std::size_t entries() const { return col.size(); }
  /// Rows, for a square matrix used as a LinearOperator.
  std::size_t size() const { return rows; }

  /// Rows [begin, end) of y = A x.
  void applyRows(const double* x, double* y, std::size_t begin, std::size_t end) const {
    const std::int64_t* s = start.data();
    const Index* c = col.data();
    const double* v = value.data();
    for (std::size_t r = begin; r < end; ++r) {
      double sum = 0.0;
      for (std::int64_t k = s[r]; k < s[r + 1]; ++k) sum += v[k] * x[c[k]];
      y[r] = sum;
    }
  }

  /// y = A x (threads share the rows when the stored entries are worth a fork-join).
  void apply(const double* x, double* y) const {
    detail::parallelFor(rows, [=, this](std::ptrdiff_t r) { applyRows(x, y, std::size_t(r), std::size_t(r) + 1); },
                        entries() + rows);
  }

  /// The diagonal entries (0 where a row stores none).
  Vector diagonal() const {
    Vector d(rows, 0.0);
    for (std::size_t r = 0; r < rows; ++r)
      for (std::int64_t k = start[r]; k < start[r + 1]; ++k)
        if (std::size_t(col[k]) == r) d[r] += value[k];
    return d;
  }

  /// Bytes held by the arrays.
  std::size_t bytes() const { return start.size() * sizeof(std::int64_t) + col.size() * (sizeof(Index) + sizeof(double)); }
};

/// Row boundaries [0 = b_0 < b_1 < ... < b_k = rows] of consecutive chunks of whole rows holding
/// about `entriesPerChunk` stored entries each. Threads that share chunks (static schedule) then
/// share the work, not just the rows: a tile's dense rows would otherwise all fall to one thread.
inline std::vector<std::size_t> balancedRowChunks(const CsrMatrix& m, std::size_t entriesPerChunk = 4096) {
  if (m.rows == 0) return {0, 0};
  std::vector<std::size_t> bounds{0};
  std::int64_t next = std::int64_t(entriesPerChunk);
  for (std::size_t r = 1; r <= m.rows; ++r)
    if (m.start[r] + std::int64_t(r) >= next || r == m.rows) {
      bounds.push_back(r);
      next = m.start[r] + std::int64_t(r) + std::int64_t(entriesPerChunk);
    }
  return bounds;
}

/// A matrix of `rows` x `cols` whose row r is written by rowFn(r, emit), emit(col, value) in any
/// order and with repeats: the repeats are summed in the order emitted and the row is stored with
/// increasing columns. Rows are built in parallel chunks, concatenated in row order.
template <class RowFn>
CsrMatrix buildCsrRows(std::size_t rows, std::size_t cols, const RowFn& rowFn) {
  if (cols > std::size_t(std::numeric_limits<CsrMatrix::Index>::max()))
    throw std::length_error("CsrMatrix: " + std::to_string(cols) + " columns exceed 32-bit indices");
  struct Chunk {
    std::vector<std::int64_t> ends;
    std::vector<CsrMatrix::Index> col;
    std::vector<double> value;
  };
  const std::size_t chunkRows = 2048;
  const std::size_t nChunks = (rows + chunkRows - 1) / chunkRows;
  std::vector<Chunk> chunks(nChunks);
#pragma omp parallel
  {
    // dense accumulator: slot[c] = position of column c in the current row, or -1
    std::vector<std::int64_t> slot(cols, -1);
    std::vector<CsrMatrix::Index> touched, order;
    std::vector<double> sums;
#pragma omp for schedule(dynamic, 1)
    for (std::ptrdiff_t ci = 0; ci < std::ptrdiff_t(nChunks); ++ci) {
      Chunk& ch = chunks[ci];
      const std::size_t r0 = std::size_t(ci) * chunkRows, r1 = std::min(rows, r0 + chunkRows);
      for (std::size_t r = r0; r < r1; ++r) {
        touched.clear();
        sums.clear();
        rowFn(r, [&](std::size_t c, double v) {
          std::int64_t& p = slot[c];
          if (p < 0) {
            p = std::int64_t(touched.size());
            touched.push_back(CsrMatrix::Index(c));
            sums.push_back(v);
          } else {
            sums[p] += v;
          }
        });
        order.assign(touched.begin(), touched.end());
        std::sort(order.begin(), order.end());
        for (CsrMatrix::Index c : order) {
          ch.col.push_back(c);
          ch.value.push_back(sums[slot[c]]);
        }
        for (CsrMatrix::Index c : touched) slot[c] = -1;
        ch.ends.push_back(std::int64_t(ch.col.size()));
      }
      // the chunks and the matrix coexist while they are copied: keep the chunks at their size
      ch.col.shrink_to_fit();
      ch.value.shrink_to_fit();
    }
  }
  CsrMatrix m;
  m.rows = rows;
  m.cols = cols;
  m.start.reserve(rows + 1);
  std::size_t total = 0;
  for (const Chunk& ch : chunks) total += ch.col.size();
  m.col.reserve(total);
  m.value.reserve(total);
  for (Chunk& ch : chunks) {
    const std::int64_t base = std::int64_t(m.col.size());
    for (std::int64_t e : ch.ends) m.start.push_back(base + e);
    m.col.insert(m.col.end(), ch.col.begin(), ch.col.end());
    m.value.insert(m.value.end(), ch.value.begin(), ch.value.end());
    ch = Chunk{};  // freed as soon as it is copied
  }
  return m;
}

/// A^T (entries of each row in increasing column order).
inline CsrMatrix transpose(const CsrMatrix& a) {
  CsrMatrix t;
  t.rows = a.cols;
  t.cols = a.rows;
  t.start.assign(a.cols + 1, 0);
  for (CsrMatrix::Index c : a.col) ++t.start[std::size_t(c) + 1];
  for (std::size_t r = 0; r < a.cols; ++r) t.start[r + 1] += t.start[r];
  t.col.resize(a.entries());
  t.value.resize(a.entries());
  std::vector<std::int64_t> next(t.start.begin(), t.start.end() - 1);
  for (std::size_t r = 0; r < a.rows; ++r)
    for (std::int64_t k = a.start[r]; k < a.start[r + 1]; ++k) {
      const std::int64_t p = next[std::size_t(a.col[k])]++;
      t.col[p] = CsrMatrix::Index(r);
      t.value[p] = a.value[k];
    }
  return t;
}

/// C = A B.
inline CsrMatrix multiply(const CsrMatrix& a, const CsrMatrix& b) {
  if (a.cols != b.rows)
    throw std::invalid_argument("CsrMatrix multiply: " + std::to_string(a.cols) + " columns against " +
                                std::to_string(b.rows) + " rows");
  return buildCsrRows(a.rows, b.cols, [&](std::size_t r, auto&& emit) {
    for (std::int64_t k = a.start[r]; k < a.start[r + 1]; ++k) {
      const double av = a.value[k];
      const std::size_t j = std::size_t(a.col[k]);
      for (std::int64_t q = b.start[j]; q < b.start[j + 1]; ++q) emit(std::size_t(b.col[q]), av * b.value[q]);
    }
  });
}

/// The longest row of a matrix (stored entries).
inline std::int64_t longestRow(const CsrMatrix& m) {
  std::int64_t longest = 0;
  for (std::size_t r = 0; r < m.rows; ++r) longest = std::max(longest, m.start[r + 1] - m.start[r]);
  return longest;
}

/// P's longest row, and its mean row, for which galerkinProduct sums P^T A P directly (see there).
constexpr std::int64_t kDirectGalerkinMaxRow = 8;
constexpr double kDirectGalerkinMaxMeanRow = 2.0;

/// The Galerkin coarse operator P^T A P, with Pt = P^T given.
/// Where P's rows are short (the staggered prolongation: 1-2 coarse samples per fine one), coarse row
/// i is summed directly, (P^T A P)_i = sum_{k in Pt_i} Pt_ik sum_{j in A_k} A_kj P_j, without
/// storing A P -- the largest transient of the set-up (a fine level's rows with ~9 entries each).
/// Each fine row k is then expanded once per coarse row that restricts it (|P_k|, ~1.5 on average
/// in 3D), which costs fewer multiply-adds than forming A P and reading it back. Where P's rows are
/// longer -- a folded tile's fit (hundreds of entries), or linear interpolation across the cell
/// axes (3-4 on average: every fine row expanded 3-4 times, while A P's rows repeat columns that
/// the sum merges once) -- the product is taken in two steps (beam res 96, linear P: set-up 0.72-0.78
/// against 0.49-0.50 s; constant P keeps the direct sum, a mean row of at most 1.5).
inline CsrMatrix galerkinProduct(const CsrMatrix& pt, const CsrMatrix& a, const CsrMatrix& p) {
  if (pt.cols != a.rows || a.cols != p.rows || pt.rows != p.cols)
    throw std::invalid_argument("galerkinProduct: P^T " + std::to_string(pt.rows) + " x " + std::to_string(pt.cols) +
                                ", A " + std::to_string(a.rows) + " x " + std::to_string(a.cols) + ", P " +
                                std::to_string(p.rows) + " x " + std::to_string(p.cols));
  if (longestRow(p) > kDirectGalerkinMaxRow || double(p.entries()) > kDirectGalerkinMaxMeanRow * double(p.rows))
    return multiply(pt, multiply(a, p));
  return buildCsrRows(pt.rows, p.cols, [&](std::size_t i, auto&& emit) {
    for (std::int64_t e = pt.start[i]; e < pt.start[i + 1]; ++e) {
      const std::size_t k = std::size_t(pt.col[e]);
      for (std::int64_t f = a.start[k]; f < a.start[k + 1]; ++f) {
        const double w = pt.value[e] * a.value[f];
        const std::size_t j = std::size_t(a.col[f]);
        for (std::int64_t q = p.start[j]; q < p.start[j + 1]; ++q) emit(std::size_t(p.col[q]), w * p.value[q]);
      }
    }
  });
}

}  // namespace krylov
}  // namespace stokes::solver
