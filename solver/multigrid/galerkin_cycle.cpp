// The members of GalerkinVelocityHierarchy (galerkin_cycle.h), compiled once for Dim = 2 and 3 into the stokes_systems
// library.
#include "solver/multigrid/galerkin_cycle.h"

namespace stokes::solver {
inline namespace multigrid {

template <int Dim>
GalerkinVelocityHierarchy<Dim>::GalerkinVelocityHierarchy(const PressureVelocitySystem<Dim>& sys, const RowSelection& rows, const MultigridOptions& opt,
                                                          TileCouplings couplings)
    : tiles_(sys.tiles()), nt_(tiles_ ? tiles_->numTiles() : 0), m_(tiles_ ? tiles_->dofsPerTile() : 0),
      cellAxes_(cellAxes(sys.viscousNumber(), opt.interpolation)) {
  auto levels = std::make_shared<std::vector<AssembledLevel>>();
  levels->push_back({VelocityBlockAssembly<Dim>(sys, rows).release(), {}, {}, rows.rows()});
  markRowsAndBlocks(levels->back(), sys.faceRows());
  std::vector<std::uint8_t> kept(nt_, 1);  // tile t's DOFs are rows of the current level
  std::vector<TileFit> fit(nt_);           // kept tiles: their fit as samples of the current level
  const sparse_grid::BlockLayout<Dim>* fine = &sys.layout();
  const std::size_t target = std::min(kCoarsestRows, opt.maxCoarseRows);
  for (int l = 0; levels->back().a.rows > target && levels->size() < 12; ++l) {
    auto coarse = std::make_unique<sparse_grid::BlockLayout<Dim>>(sparse_grid::coarsenLayout(*fine));
    AssembledLevel& f = levels->back();
    AssembledLevel next;
    std::vector<TileFit> coarseFit;
    std::vector<std::uint8_t> fold;
    f.p = transfer(l, *fine, *coarse, f.padded, kept, fit, next.padded, coarseFit, fold);
    f.pt = transpose(f.p);
    next.a = galerkinProduct(f.pt, f.a, f.p);
    if (next.a.rows == 0 || next.a.rows >= f.a.rows) {  // no coarsening left: this level is the coarsest
      f.p = {};
      f.pt = {};
      break;
    }
    markRowsAndBlocks(next, Dim * coarse->numSlots());
    levels->push_back(std::move(next));
    layouts_.push_back(std::move(coarse));
    fine = layouts_.back().get();
    for (std::size_t t = 0; t < nt_; ++t) kept[t] = kept[t] && !fold[t];
    fit = std::move(coarseFit);
  }
  if (couplings == TileCouplings::Factored) factorTileCouplings(sys, rows, *levels);
  levels_ = std::move(levels);
}

template <int Dim>
void GalerkinVelocityHierarchy<Dim>::factorTileCouplings(const PressureVelocitySystem<Dim>& sys, const RowSelection& rows,
                                                         std::vector<AssembledLevel>& levels) const {
  AssembledLevel& zero = levels.front();
  // a level 0 that is also the coarsest is factored densely and applied only to set that up
  if (zero.tileRows >= zero.rows() || levels.size() == 1) return;
  // the coarse levels are formed: A_0 is applied in factored form only, its arrays become the
  // face block's
  zero.diagonal = zero.a.diagonal();
  auto f = std::make_shared<const TileCoupledRows<Dim>>(sys, rows, std::move(zero.a));
  zero.a = {};
  zero.factored = {[f](const double* x, double* y, std::size_t b, std::size_t e) { f->applyRows(x, y, b, e); }, f->rowChunks(),
                   f->work(), [f](const double* x) { f->prepare(x); }};
  zero.factoredBytes = f->bytes();
}

template <int Dim>
std::size_t GalerkinVelocityHierarchy<Dim>::bytes() const {
  std::size_t b = 0;
  for (const AssembledLevel& l : *levels_)
    b += l.a.bytes() + l.p.bytes() + l.pt.bytes() + 4 * l.padded.size() + 8 * l.diagonal.size() + l.factoredBytes;
  return b;
}

template <int Dim>
void GalerkinVelocityHierarchy<Dim>::markRowsAndBlocks(AssembledLevel& level, std::size_t faceSamples) const {
  const auto& padded = level.padded;
  level.tileRows = std::size_t(std::lower_bound(padded.begin(), padded.end(), std::uint32_t(faceSamples)) - padded.begin());
  level.dofsPerTile = level.tileRows < padded.size() ? m_ : 0;
  level.blocks = {};
  appendStrongPairBlocks(level.a, level.tileRows, level.blocks);
  appendDiagonalBlockInverses(level.a, level.tileRows, level.dofsPerTile, level.blocks);
}

template <int Dim>
CsrMatrix GalerkinVelocityHierarchy<Dim>::transfer(int l, const sparse_grid::BlockLayout<Dim>& fine, const sparse_grid::BlockLayout<Dim>& coarse,
    const std::vector<std::uint32_t>& finePadded, const std::vector<std::uint8_t>& kept,
    const std::vector<TileFit>& fit, std::vector<std::uint32_t>& coarsePadded,
    std::vector<TileFit>& coarseFit, std::vector<std::uint8_t>& fold) const {
  const std::size_t nFine = Dim * fine.numSlots(), nCoarse = Dim * coarse.numSlots();
  // the fine samples P_g must reach: the face rows, and the samples the kept tiles' fits read
  std::vector<std::uint8_t> activeFine(nFine, 0);
  for (std::uint32_t i : finePadded)
    if (i < nFine) activeFine[i] = 1;
  for (std::size_t t = 0; t < nt_; ++t) {
    if (!kept[t]) continue;
    if (l == 0) {
      for (std::int64_t face : tiles_->tile(t).faces) activeFine[std::size_t(face)] = 1;
    } else {
      for (std::size_t c : fit[t].columns) activeFine[c] = 1;
    }
  }
  const sparse_grid::GridTransfer<Dim> gt(fine, coarse, faceChannels<Dim>(), {}, activeFine, {}, cellAxes_);
  const sparse_grid::SparseRows& pg = gt.prolongation();
  coarseFit.assign(nt_, {});
  fold.assign(nt_, 0);
  const double scale = double(1 << (l + 1));
#pragma omp parallel for schedule(dynamic, 1)
  for (std::ptrdiff_t ti = 0; ti < std::ptrdiff_t(nt_); ++ti) {
    const std::size_t t = std::size_t(ti);
    if (!kept[t]) continue;
    coarseFit[t] = l == 0 ? fitOfFaces(t, pg) : throughProlongation(fit[t], pg);
    fold[t] = 2.0 * tiles_->tiling().tiles[t].halfWidthInCells / scale <= kFoldTileWidth ? 1 : 0;
  }
  // coarse rows: the face samples that the face rows prolong from or that a tile folding now is
  // fitted to (increasing), then the DOFs of the tiles still kept. The samples that only a kept
  // tile's fit reads are not rows: they would be empty, and where tiles cover most of the liquid
  // they outnumbered the fine rows, which ended the coarsening (disk N = 128, tiles 16 / 2).
  std::vector<std::int32_t> faceIndex(nCoarse, -1);
  for (std::uint32_t i : finePadded)
    if (i < nFine && i < pg.rows())
      for (std::int64_t k = pg.start[i]; k < pg.start[i + 1]; ++k) faceIndex[std::size_t(pg.col[k])] = 0;
  for (std::size_t t = 0; t < nt_; ++t)
    if (kept[t] && fold[t])
      for (std::size_t c : coarseFit[t].columns) faceIndex[c] = 0;
  coarsePadded.clear();
  for (std::size_t c = 0; c < nCoarse; ++c)
    if (faceIndex[c] == 0) {
      faceIndex[c] = std::int32_t(coarsePadded.size());
      coarsePadded.push_back(std::uint32_t(c));
    }
  std::vector<std::size_t> tileIndex(nt_, 0);
  for (std::size_t t = 0; t < nt_; ++t) {
    if (!kept[t] || fold[t]) continue;
    tileIndex[t] = coarsePadded.size();
    for (int k = 0; k < m_; ++k) coarsePadded.push_back(std::uint32_t(nCoarse + t * m_ + k));
  }
  return buildCsrRows(finePadded.size(), coarsePadded.size(), [&](std::size_t r, auto&& emit) {
    const std::size_t i = finePadded[r];
    if (i < nFine) {
      for (std::int64_t k = pg.start[i]; k < pg.start[i + 1]; ++k)
        emit(std::size_t(faceIndex[std::size_t(pg.col[k])]), pg.weight[k]);
      return;
    }
    const std::size_t t = (i - nFine) / m_;
    const int k = int((i - nFine) % m_);
    if (!fold[t]) {
      emit(tileIndex[t] + k, 1.0);
      return;
    }
    const TileFit& tf = coarseFit[t];
    for (std::size_t j = 0; j < tf.columns.size(); ++j)
      emit(std::size_t(faceIndex[tf.columns[j]]), tf.values(k, Eigen::Index(j)));
  });
}

template <int Dim>
auto GalerkinVelocityHierarchy<Dim>::fitOfFaces(std::size_t t, const sparse_grid::SparseRows& pg) const -> TileFit {
  DenseColumns acc;
  tiles_->forEachTileFaceRow(t, [&](std::int64_t f, const Eigen::Map<const Eigen::VectorXd>& c) {
    for (std::int64_t k = pg.start[f]; k < pg.start[f + 1]; ++k) acc.add(std::size_t(pg.col[k]), pg.weight[k] * c);
  });
  ColumnBlock fit = acc.block(m_);
  fit.values = tiles_->tile(t).massHatInverse * fit.values;
  return fit;
}

template <int Dim>
auto GalerkinVelocityHierarchy<Dim>::throughProlongation(const TileFit& f, const sparse_grid::SparseRows& pg) const -> TileFit {
  DenseColumns acc;
  for (std::size_t j = 0; j < f.columns.size(); ++j) {
    const std::size_t s = f.columns[j];
    for (std::int64_t k = pg.start[s]; k < pg.start[s + 1]; ++k)
      acc.add(std::size_t(pg.col[k]), pg.weight[k] * f.values.col(Eigen::Index(j)));
  }
  return acc.block(m_);
}

template class GalerkinVelocityHierarchy<2>;
template class GalerkinVelocityHierarchy<3>;

}  // namespace multigrid
}  // namespace stokes::solver
