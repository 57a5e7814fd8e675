#pragma once
// Coarsening of a BlockLayout by a factor of 2 and the transfers between the two levels, generic in
// the dimension and in the sample kind (stagger mask). Used by the geometric multigrid
// preconditioner (solver/multigrid/multigrid_hierarchy.h).
//
// Coarse cell C covers fine cells 2C .. 2C+1 along every axis (same origin, dx_c = 2 dx).
// A sample of kind `mask` sits, along an axis a in the mask, on the lower face of its cell
// (node-like: fine index 2C coincides with coarse C), and along an axis not in the mask at the
// cell centre (cell-like: fine cells 2C and 2C+1 lie at -dx_c/4 and +dx_c/4 from coarse C).
//
// Prolongation P (coarse -> fine), a tensor product of 1D linear interpolations:
//   node-like axis:  f = 2C      <- C                      (weight 1)
//                    f = 2C + 1  <- C, C + 1               (1/2, 1/2)
//   cell-like axis:  f = 2C      <- C, C - 1               (3/4, 1/4)
//                    f = 2C + 1  <- C, C + 1               (3/4, 1/4)
// Restriction R = P^T / 2^Dim, so that for operators scaled like 1/dx^2, R A_f P ~ A_c and the
// coarse correction P A_c^-1 R is symmetric. Coarse samples outside the coarse layout are dropped
// (they are zero rows, i.e. homogeneous Dirichlet: air at a free surface).
// Coarse samples flagged `excluded` (inside a solid: a Neumann wall for pressure) are dropped too,
// but the fine row's remaining weights are rescaled to the row's full weight, so that a constant
// coarse correction stays constant up to the wall instead of being pulled to zero there.
//
// Both transfers are stored as compressed rows (P by fine rows, P^T by coarse rows), so each is a
// parallel gather with no write conflicts, and bit-identical for any thread count.
//
// Inactive samples (cheap cycles): a multigrid level only ever reads the prolonged
// correction on its active fine rows and restricts residuals that are zero off them, and the
// coarse level ignores its inactive rows. Given the active flags of both levels, P keeps only the
// rows of active fine samples and the entries of active coarse samples (after the exclusion's
// rescaling, which still sees every coarse sample): on active rows both transfers give the same
// values bit for bit (only exact zero terms are dropped), and every other row is 0. On the 48^3
// ball's velocity block 2/3 of the padded fine rows are inactive.
#include "sparse_grid/vdb_trees.h"

#include <algorithm>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <vector>

#include "sparse_grid/block_layout.h"
#include "sparse_grid/stagger.h"

namespace stokes::sparse_grid {

/// The layout of the parent cells of every active cell of `fine` (dx doubled, same origin).
template <int Dim>
BlockLayout<Dim> coarsenLayout(const BlockLayout<Dim>& fine) {
  openvdb::MaskTree parents(false);
  openvdb::tree::ValueAccessor<openvdb::MaskTree> acc(parents);
  for (std::size_t s = 0; s < fine.numSlots(); ++s) {
    if (!fine.isActiveCell(s)) continue;
    const Coord c = fine.cellOf(s);
    acc.setValueOn(Coord(c.x() >> 1, c.y() >> 1, Dim == 3 ? c.z() >> 1 : 0));  // >> floors negatives
  }
  return BlockLayout<Dim>(parents, 2.0 * fine.dx(), fine.origin());
}

/// Sparse rows (CSR): row r holds (col[k], weight[k]) for k in [start[r], start[r+1]).
struct SparseRows {
  std::vector<std::int64_t> start{0};
  std::vector<std::int32_t> col;
  std::vector<double> weight;

  std::size_t rows() const { return start.size() - 1; }
  /// y[r] (+)= sum_k weight[k] x[col[k]] * scale
  void gather(const double* x, double* y, double scale, bool accumulate) const {
    const std::ptrdiff_t n = std::ptrdiff_t(rows());
#pragma omp parallel for schedule(static) if (parallel::forkGridLoop(rows()))
    for (std::ptrdiff_t r = 0; r < n; ++r) {
      double sum = 0.0;
      for (std::int64_t k = start[r]; k < start[r + 1]; ++k) sum += weight[k] * x[col[k]];
      y[r] = accumulate ? y[r] + scale * sum : scale * sum;
    }
  }
};

/// P and P^T for the samples of several channels (one stagger mask each, channel-major with
/// stride numSlots on both levels), e.g. the Dim face channels of a velocity field.
/// The 1D interpolation along a cell-like axis of a sample (for a face: the axes across its normal).
///   Linear    (3/4, 1/4) from the parent and its nearer neighbour: second order, the default.
///   Constant  1 from the parent (piecewise constant across the face normal, linear along it): the
///             Galerkin velocity cycle's choice (solver/multigrid/galerkin_cycle.h), whose coarse
///             operators P^T A P then keep ~12-15 entries per row instead of 75-130 (armadillo
///             pile res 128: 1.4 against 5.4 stored entries per fine-level entry over all levels).
enum class CellAxes { Linear, Constant };

/// The 1D interpolation stencil of fine index f along one axis: up to two (coarse index, weight)
/// pairs (see the file comment; `constantAcross`: CellAxes::Constant on a cell-like axis).
struct Stencil1D {
  int count = 0;
  int index[2];
  double weight[2];
};
inline Stencil1D stencil1D(int f, bool nodeLike, bool constantAcross) {
  const int c = f >> 1;  // floors negatives
  const bool odd = (f & 1) != 0;
  if (nodeLike) return odd ? Stencil1D{2, {c, c + 1}, {0.5, 0.5}} : Stencil1D{1, {c, 0}, {1.0, 0.0}};
  if (constantAcross) return Stencil1D{1, {c, 0}, {1.0, 0.0}};
  return Stencil1D{2, {c, odd ? c + 1 : c - 1}, {0.75, 0.25}};
}

/// fn(coarse cell, weight) over row `fineCell` of P for samples of kind `mask`: the tensor product
/// of the 1D stencils, in a fixed order (the first axis fastest). On global cell coordinates, so a
/// level needs no layout to know where its rows reach.
template <int Dim, class Fn>
void forEachProlongationTerm(const Coord& fineCell, StaggerMask mask, CellAxes across, Fn&& fn) {
  Stencil1D st[3];
  int total = 1;
  for (int a = 0; a < Dim; ++a) {
    st[a] = stencil1D(fineCell[a], (mask >> a) & 1u, across == CellAxes::Constant);
    total *= st[a].count;
  }
  for (int k = 0; k < total; ++k) {
    Coord cc(0, 0, 0);
    double w = 1.0;
    int rest = k;
    for (int a = 0; a < Dim; ++a) {
      const int j = rest % st[a].count;
      rest /= st[a].count;
      cc[a] = st[a].index[j];
      w *= st[a].weight[j];
    }
    fn(cc, w);
  }
}

template <int Dim>
class GridTransfer {
 public:
  /// `excluded` (empty, or one flag per coarse sample, channel-major): coarse samples whose
  /// weight is redistributed over the row's other samples (see the file comment).
  /// `activeFine`, `activeCoarse` (empty: all active; else one flag per sample, channel-major):
  /// the rows the levels use (see the file comment). `across`: the interpolation along the axes on
  /// which a sample is cell-like (see CellAxes).
  GridTransfer(const BlockLayout<Dim>& fine, const BlockLayout<Dim>& coarse, const std::vector<StaggerMask>& channels,
               const std::vector<std::uint8_t>& excluded = {}, const std::vector<std::uint8_t>& activeFine = {},
               const std::vector<std::uint8_t>& activeCoarse = {}, CellAxes across = CellAxes::Linear)
      : fineSize_(channels.size() * fine.numSlots()), coarseSize_(channels.size() * coarse.numSlots()), across_(across) {
    if (coarseSize_ > std::size_t(std::numeric_limits<std::int32_t>::max()) ||
        fineSize_ > std::size_t(std::numeric_limits<std::int32_t>::max()))
      throw std::length_error("GridTransfer: more than 2^31 samples on a level");
    if ((!activeFine.empty() && activeFine.size() != fineSize_) ||
        (!activeCoarse.empty() && activeCoarse.size() != coarseSize_))
      throw std::invalid_argument("GridTransfer: active flags do not match the levels' sample counts");
    buildProlongation(fine, coarse, channels, excluded, activeFine, activeCoarse);
    buildRestriction();
  }

  /// Stored entries of P (and of P^T).
  std::size_t entries() const { return p_.col.size(); }

  std::size_t fineSize() const { return fineSize_; }
  std::size_t coarseSize() const { return coarseSize_; }

  /// P by fine rows (padded sample indices; rows and columns outside the active flags are empty).
  const SparseRows& prolongation() const { return p_; }

  /// fine (+)= P coarse
  void prolong(const double* coarse, double* fine, bool accumulate) const { p_.gather(coarse, fine, 1.0, accumulate); }
  /// coarse = P^T fine / 2^Dim
  void restrictTo(const double* fine, double* coarse) const { pt_.gather(fine, coarse, 1.0 / (1 << Dim), false); }

 private:
  // Entries of one chunk of consecutive rows of P (see buildProlongation).
  struct RowChunk {
    std::vector<std::int64_t> ends;  // per row: end of its entries in col / weight (chunk-local)
    std::vector<std::int32_t> col;
    std::vector<double> weight;
  };

  // Rows are independent, so chunks of consecutive rows are built in parallel into their own
  // arrays and then concatenated in row order: the same P, entry for entry, for any thread count.
  void buildProlongation(const BlockLayout<Dim>& fine, const BlockLayout<Dim>& coarse,
                         const std::vector<StaggerMask>& channels, const std::vector<std::uint8_t>& excluded,
                         const std::vector<std::uint8_t>& activeFine, const std::vector<std::uint8_t>& activeCoarse) {
    const std::size_t nf = fine.numSlots();
    constexpr std::size_t kChunkRows = 16384;
    const std::size_t nChunks = (fineSize_ + kChunkRows - 1) / kChunkRows;
    std::vector<RowChunk> chunks(nChunks);
#pragma omp parallel for schedule(dynamic, 1) if (parallel::forkGridLoop(fineSize_))
    for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(nChunks); ++k) {
      RowChunk& chunk = chunks[std::size_t(k)];
      const std::size_t first = std::size_t(k) * kChunkRows, last = std::min(fineSize_, first + kChunkRows);
      chunk.ends.reserve(last - first);
      for (std::size_t row = first; row < last; ++row) {
        const std::size_t ch = row / nf, s = row % nf;
        if (activeFine.empty() || activeFine[row])
          appendRow(fine, coarse, channels[ch], ch, s, excluded, activeCoarse, across_, chunk.col, chunk.weight);
        chunk.ends.push_back(std::int64_t(chunk.col.size()));
      }
    }
    std::vector<std::int64_t> offset(nChunks + 1, 0);
    for (std::size_t k = 0; k < nChunks; ++k) offset[k + 1] = offset[k] + std::int64_t(chunks[k].col.size());
    p_.start.assign(fineSize_ + 1, 0);
    p_.col.resize(std::size_t(offset[nChunks]));
    p_.weight.resize(std::size_t(offset[nChunks]));
#pragma omp parallel for schedule(static) if (parallel::forkGridLoop(fineSize_))
    for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(nChunks); ++k) {
      const RowChunk& chunk = chunks[std::size_t(k)];
      const std::size_t first = std::size_t(k) * kChunkRows;
      for (std::size_t r = 0; r < chunk.ends.size(); ++r) p_.start[first + r + 1] = offset[k] + chunk.ends[r];
      std::copy(chunk.col.begin(), chunk.col.end(), p_.col.begin() + offset[k]);
      std::copy(chunk.weight.begin(), chunk.weight.end(), p_.weight.begin() + offset[k]);
    }
  }

  // Appends row (channel ch, fine slot s) of P to col / weight: the tensor product of the 1D
  // stencils, excluded coarse samples' weight handed to the others, inactive coarse samples dropped.
  static void appendRow(const BlockLayout<Dim>& fine, const BlockLayout<Dim>& coarse, StaggerMask mask, std::size_t ch,
                        std::size_t s, const std::vector<std::uint8_t>& excluded,
                        const std::vector<std::uint8_t>& activeCoarse, CellAxes across, std::vector<std::int32_t>& col,
                        std::vector<double>& weight) {
    const std::size_t nc = coarse.numSlots();
    const std::size_t rowStart = col.size();
    double kept = 0.0, dropped = 0.0;
    forEachProlongationTerm<Dim>(fine.cellOf(s), mask, across, [&](const Coord& cc, double w) {
      const std::int64_t cs = coarse.slotOf(cc);
      if (cs < 0) return;
      const std::int64_t column = std::int64_t(ch * nc) + cs;
      if (!excluded.empty() && excluded[column]) {
        dropped += w;
        return;
      }
      col.push_back(std::int32_t(column));
      weight.push_back(w);
      kept += w;
    });
    // P_fc *= (kept + dropped) / kept on the kept entries: the excluded weight goes to them
    if (dropped > 0.0 && kept > 0.0)
      for (std::size_t k = rowStart; k < col.size(); ++k) weight[k] *= (kept + dropped) / kept;
    if (activeCoarse.empty()) return;
    // drop the entries of inactive coarse samples, keeping the order of the others
    std::size_t out = rowStart;
    for (std::size_t k = rowStart; k < col.size(); ++k) {
      if (!activeCoarse[std::size_t(col[k])]) continue;
      col[out] = col[k];
      weight[out++] = weight[k];
    }
    col.resize(out);
    weight.resize(out);
  }

  // P^T by counting sort of P's entries on their column; rows keep ascending fine order, so the
  // sums are formed in a fixed order.
  void buildRestriction() {
    pt_.start.assign(coarseSize_ + 1, 0);
    for (std::int32_t c : p_.col) ++pt_.start[c + 1];
    for (std::size_t r = 0; r < coarseSize_; ++r) pt_.start[r + 1] += pt_.start[r];
    pt_.col.resize(p_.col.size());
    pt_.weight.resize(p_.col.size());
    std::vector<std::int64_t> next(pt_.start.begin(), pt_.start.end() - 1);
    for (std::size_t row = 0; row < fineSize_; ++row)
      for (std::int64_t k = p_.start[row]; k < p_.start[row + 1]; ++k) {
        const std::int64_t pos = next[p_.col[k]]++;
        pt_.col[pos] = std::int32_t(row);
        pt_.weight[pos] = p_.weight[k];
      }
  }

  std::size_t fineSize_, coarseSize_;
  CellAxes across_ = CellAxes::Linear;
  SparseRows p_, pt_;
};

/// Coarse sample weights (volume fractions) as the mean of the fine samples of the same kind that
/// the coarse control volume holds: along node-like axes the coincident fine sample 2C, along
/// cell-like axes both children 2C and 2C+1. Fine samples outside the fine layout are skipped;
/// a coarse sample with none gets `missing`.
template <int Dim>
void coarsenSampleWeights(const BlockLayout<Dim>& fine, const BlockLayout<Dim>& coarse, StaggerMask mask,
                          const double* fineValues, double* coarseValues, double missing) {
  const std::ptrdiff_t nc = std::ptrdiff_t(coarse.numSlots());
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < nc; ++s) {
    const Coord c = coarse.cellOf(std::size_t(s));
    double sum = 0.0;
    int found = 0;
    for (int k = 0; k < (1 << Dim); ++k) {
      Coord f(0, 0, 0);
      bool skip = false;
      for (int a = 0; a < Dim; ++a) {
        const int bit = (k >> a) & 1;
        if (((mask >> a) & 1u) && bit) skip = true;  // node-like axis: only the coincident child
        f[a] = 2 * c[a] + bit;
      }
      if (skip) continue;
      const std::int64_t fs = fine.slotOf(f);
      if (fs < 0) continue;
      sum += fineValues[fs];
      ++found;
    }
    coarseValues[s] = found ? sum / found : missing;
  }
}

}  // namespace stokes::sparse_grid
