// The members of ReducedTiles (reduced_tiles.h), compiled once for Dim = 2 and 3 into the stokes_systems
// library.
#include "solver/reduced/reduced_tiles.h"

#include <optional>

#include "parallel/fork_policy.h"

namespace stokes::solver {
inline namespace reduced {

template <int Dim>
ReducedTiles<Dim>::ReducedTiles(const StaggeredProblem<Dim>& prob, const ReducedOptions& opt, const CouplingKinds& kinds)
    : prob_(&prob), layout_(prob.layout), basis_(opt.order, opt.family), kinds_(kinds), n_(prob.slots()) {
  if (kinds.viscous && opt.tiling.padding < 2)
    throw std::invalid_argument("reduced tiles: padding " + std::to_string(opt.tiling.padding) +
                                " is refused with viscosity: viscous stencils reach two cells, so --pad must be >= 2 "
                                "(thesis 4.4)");
  cache_ = opt.cache;
  library_ = opt.library ? opt.library : std::make_shared<TileLibrary>();
  fitAllFaces_ = opt.fitAllFaces;
  const std::size_t hits0 = library_->hits(), misses0 = library_->misses();
  if (prob.isDistributed() && opt.tileAccuracy > 0.0)
    throw std::invalid_argument("reduced tiles: adaptive tiles (--tile-min) need the whole problem: the split test "
                                "reads the whole liquid's velocity variation and the previous step's decisions");
  buildTiling(opt.tiling, opt.tileAccuracy, opt.history.get());
  if (prob.isDistributed()) keepTilesNearOwnedBlocks();
  applyTileRule(opt);
  // A tile whose fit faces do not resolve every basis field keeps the modes they resolve
  // (resolvedModes); one that does not even resolve the translations, or whose B cannot be
  // factored, goes back to Cartesian cells, and the others are then rebuilt without it.
  for (int attempt = 0; attempt < 2; ++attempt) {
    labelFacesAndSamples();
    const std::vector<std::string> failures = buildAllTiles();
    std::vector<std::size_t> failed;
    for (std::size_t t = 0; t < failures.size(); ++t)
      if (!failures[t].empty()) failed.push_back(t);
    if (failed.empty()) break;
    if (attempt == 1) throw std::runtime_error("reduced tiles: " + failures[failed.front()]);
    for (std::size_t t : failed)
      if (reportsRegion(tiling_.tiles[t])) fallbackMessages_.push_back(failures[t]);
    demoteTiles(failed);
  }
  reports_.resize(tiles_.size());
  for (std::size_t t = 0; t < tiles_.size(); ++t) {
    reports_[t] = reportsRegion(tiling_.tiles[t]) ? 1 : 0;
    if (reports_[t]) reconstructionLinf_ = std::max(reconstructionLinf_, tiles_[t].reconstructionLinf);
  }
  if (opt.history) recordTiles(*opt.history);
  // the hot loops over tiles fork only when their multiply-adds (J_t and B_t^-1 per tile) pay
  // for a fork-join (parallel/fork_policy.h: the vector threshold)
  std::size_t work = 0;
  for (const auto& t : tiles_) work += std::size_t(basis_.size()) * (t.faces.size() + std::size_t(basis_.size()));
  parallelTiles_ = parallel::forkVectorWork(work);
  cacheHits_ = library_->hits() - hits0;
  cacheMisses_ = library_->misses() - misses0;
}

template <int Dim>
std::size_t ReducedTiles<Dim>::reportedTiles() const {
  return std::size_t(std::count(reports_.begin(), reports_.end(), std::uint8_t(1)));
}

template <int Dim>
std::size_t ReducedTiles<Dim>::resolvedDofs() const {
  std::size_t k = 0;
  for (std::size_t t = 0; t < tiles_.size(); ++t) k += reports_[t] ? std::size_t(tiles_[t].modeCount) : 0;
  return k;
}

template <int Dim>
std::size_t ReducedTiles<Dim>::partialTiles() const {
  std::size_t k = 0;
  for (std::size_t t = 0; t < tiles_.size(); ++t) k += reports_[t] && tiles_[t].modeCount < basis_.size() ? 1 : 0;
  return k;
}

template <int Dim>
void ReducedTiles<Dim>::coupleFaces(double* faces) const {
#pragma omp parallel if (parallelTiles_)
  {
    parallel::countTeam(parallel::Region::Tiles);
#pragma omp for schedule(static) nowait
    for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(tiles_.size()); ++t) coupleTile(std::size_t(t), faces);
  }
}

template <int Dim>
void ReducedTiles<Dim>::coupleFaces(double* faces, const std::vector<std::int32_t>& tiles) const {
#pragma omp parallel for schedule(static) if (parallelTiles_)
  for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(tiles.size()); ++k) coupleTile(std::size_t(tiles[k]), faces);
}

template <int Dim>
void ReducedTiles<Dim>::gather(const double* faces, double* F) const {
#pragma omp parallel for schedule(static) if (parallelTiles_)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(tiles_.size()); ++t) gatherTile(std::size_t(t), faces, F + t * basis_.size());
}

template <int Dim>
void ReducedTiles<Dim>::scatter(const double* V, double* faces, bool couplingOnly) const {
#pragma omp parallel for schedule(static) if (parallelTiles_)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(tiles_.size()); ++t)
    scatterTile(std::size_t(t), V + t * basis_.size(), faces, couplingOnly);
}

template <int Dim>
void ReducedTiles<Dim>::applyInverses(const double* F, double* V) const {
#pragma omp parallel for schedule(static) if (parallelTiles_)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(tiles_.size()); ++t)
    applyInverse(std::size_t(t), F + t * basis_.size(), V + t * basis_.size());
}

template <int Dim>
void ReducedTiles<Dim>::solveVelocities(const double* faces, double* v) const {
#pragma omp parallel for schedule(static) if (parallelTiles_)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(tiles_.size()); ++t) {
    double F[kRowStorage], V[kRowStorage];
    gatherTile(std::size_t(t), faces, F);
    applyInverse(std::size_t(t), F, V);
    for (int k = 0; k < basis_.size(); ++k) v[t * basis_.size() + k] = tiles_[t].vFree[k] - V[k];
  }
}

template <int Dim>
double ReducedTiles<Dim>::kineticEnergy(const double* v) const {
  double e = 0.0;
  const double dV = std::pow(layout_->dx(), Dim);
  for (std::size_t t = 0; t < tiles_.size(); ++t) {
    if (!reports_[t]) continue;
    const Eigen::Map<const VectorX> vt(v + t * basis_.size(), basis_.size());
    e += 0.5 * vt.dot(tiles_[t].massR * vt) * dV;
  }
  return e;
}

template <int Dim>
void ReducedTiles<Dim>::addCouplingDiagonal(const double* pWeight, const double* tauWeight, double* diag,
                                            const std::vector<Matrix>* inverses) const {
  for (std::size_t t = 0; t < tiles_.size(); ++t) {
    std::unordered_map<std::int64_t, Eigen::Matrix<double, Eigen::Dynamic, 1>> k;
    const TileData& td = tiles_[t];
    double row[kRowStorage];
    for (std::size_t q = 0; q < td.coupling.size(); ++q) {
      const std::int64_t f = td.coupling[q];
      const int a = int(f / std::int64_t(n_));
      const std::size_t slot = std::size_t(f % std::int64_t(n_));
      basisRow(td, a, &td.couplingCoords[q * Dim], row);
      const Eigen::Map<const VectorX> c(row, basis_.size());
      auto add = [&](std::int64_t sample, double coef) {
        auto it = k.find(sample);
        if (it == k.end()) it = k.emplace(sample, VectorX::Zero(basis_.size())).first;
        it->second += coef * c;
      };
      kernels::forEachSampleOfFace<Dim>(
          *layout_, a, slot,
          [&](std::size_t ps, double coef) {
            if (kinds_.pressure && pWeight[ps] > 0.0) add(std::int64_t(ps), coef * pWeight[ps]);
          },
          [&](int ch, std::size_t ts, double coef) {
            const std::size_t i = ch * n_ + ts;
            if (kinds_.stress && tauWeight && tauWeight[i] > 0.0) add(std::int64_t(n_ + i), coef * tauWeight[i]);
          });
    }
    const Matrix& inverse = inverses ? (*inverses)[t] : td.inverseB;
    for (const auto& [sample, kj] : k) diag[sample] += kj.dot(inverse * kj);
  }
}

template <int Dim>
auto ReducedTiles<Dim>::viscosityTileBlocks(const double* q) const -> std::vector<Matrix> {
  std::vector<Matrix> blocks(tiles_.size());
#pragma omp parallel for schedule(dynamic)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(tiles_.size()); ++t) {
    const TileData& td = tiles_[t];
    std::unordered_map<std::int64_t, VectorX> d;
    double row[kRowStorage];
    for (std::size_t p = 0; p < td.coupling.size(); ++p) {
      const std::int64_t f = td.coupling[p];
      const int a = int(f / std::int64_t(n_));
      basisRow(td, a, &td.couplingCoords[p * Dim], row);
      const Eigen::Map<const VectorX> c(row, basis_.size());
      kernels::forEachSampleOfFace<Dim>(
          *layout_, a, std::size_t(f % std::int64_t(n_)), [](std::size_t, double) {},
          [&](int ch, std::size_t ts, double coef) {
            const std::int64_t i = std::int64_t(ch * n_ + ts);
            if (q[i] <= 0.0) return;
            auto it = d.find(i);
            if (it == d.end()) it = d.emplace(i, VectorX::Zero(basis_.size())).first;
            it->second += coef * c;
          });
    }
    Matrix a = td.massR / prob_->dt + td.viscR;
    // the samples in a fixed order, so that the sum does not depend on the hash map's
    std::vector<std::int64_t> order;
    for (const auto& entry : d) order.push_back(entry.first);
    std::sort(order.begin(), order.end());
    for (std::int64_t i : order) a.noalias() += q[i] * d.at(i) * d.at(i).transpose();
    blocks[t] = std::move(a);
  }
  return blocks;
}

template <int Dim>
void ReducedTiles<Dim>::addViscosityTileDiagonal(const double* q, double* diagTiles) const {
  const std::vector<Matrix> blocks = viscosityTileBlocks(q);
  for (std::size_t t = 0; t < tiles_.size(); ++t)
    for (int k = 0; k < basis_.size(); ++k) diagTiles[t * basis_.size() + k] = blocks[t](k, k);
}

template <int Dim>
void ReducedTiles<Dim>::fitFaceField(const double* faces, double* v) const {
#pragma omp parallel for schedule(static) if (parallelTiles_)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(tiles_.size()); ++t) {
    const int m = basis_.size();
    VectorX F = VectorX::Zero(m);
    forEachTileFaceRow(std::size_t(t), [&](std::int64_t f, const Eigen::Map<const VectorX>& c) { F += faces[f] * c; });
    Eigen::Map<VectorX>(v + t * m, m).noalias() = tiles_[t].massHatInverse * F;
  }
}

template <int Dim>
void ReducedTiles<Dim>::addFitTranspose(const double* v, double* faces) const {
#pragma omp parallel for schedule(static) if (parallelTiles_)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(tiles_.size()); ++t) {
    const int m = basis_.size();
    const VectorX w = tiles_[t].massHatInverse * Eigen::Map<const VectorX>(v + t * m, m);
    forEachTileFaceRow(std::size_t(t), [&](std::int64_t f, const Eigen::Map<const VectorX>& c) { faces[f] += c.dot(w); });
  }
}

template <int Dim>
void ReducedTiles<Dim>::applyTileRows(const double* faces, const double* v, double* y) const {
#pragma omp parallel for schedule(static) if (parallelTiles_)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(tiles_.size()); ++t) {
    const int m = basis_.size();
    double F[kRowStorage];
    gatherTile(std::size_t(t), faces, F);
    const Eigen::Map<const VectorX> vt(v + t * m, m);
    Eigen::Map<VectorX> yt(y + t * m, m);
    yt.noalias() = tiles_[t].massR * vt / prob_->dt + tiles_[t].viscR * vt + Eigen::Map<const VectorX>(F, m);
  }
}

template <int Dim>
void ReducedTiles<Dim>::tileRightHandSide(const double* faces, double* r) const {
#pragma omp parallel for schedule(static) if (parallelTiles_)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(tiles_.size()); ++t) {
    const int m = basis_.size();
    double F[kRowStorage];
    gatherTile(std::size_t(t), faces, F);
    Eigen::Map<VectorX>(r + t * m, m) =
        tiles_[t].massR * tiles_[t].vStar / prob_->dt - Eigen::Map<const VectorX>(F, m);
  }
}

template <int Dim>
std::vector<std::string> ReducedTiles<Dim>::buildAllTiles() {
  const std::size_t nt = tiling_.tiles.size();
  tiles_.assign(nt, TileData{});
  std::vector<std::string> failures(nt), keys(nt);
  std::vector<std::vector<std::uint8_t>> boundary(nt);
#pragma omp parallel for schedule(dynamic)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(nt); ++t) {
    collectFaces(std::size_t(t), tiles_[t], boundary[t]);
    keys[t] = shapeKey(tiling_.tiles[t]);
  }
  std::vector<std::shared_ptr<const TileShapeBlocks>> blocks(nt);
  std::vector<std::size_t> computeHere, firstOfShape(nt);
  std::unordered_map<std::string, std::size_t> first;
  for (std::size_t t = 0; t < nt; ++t) {
    firstOfShape[t] = t;
    if (keys[t].empty()) {
      computeHere.push_back(t);
    } else if (const auto it = first.find(keys[t]); it != first.end()) {
      firstOfShape[t] = it->second;
    } else if (!(blocks[t] = library_->find(keys[t]))) {
      first.emplace(keys[t], t);
      computeHere.push_back(t);
    }
  }
#pragma omp parallel for schedule(dynamic)
  for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(computeHere.size()); ++k) {
    const std::size_t t = computeHere[k];
    try {
      blocks[t] = computeShapeBlocks(t, tiles_[t], boundary[t]);
    } catch (const std::exception& e) {
      failures[t] = e.what();
    }
  }
  for (std::size_t t : computeHere)
    if (!keys[t].empty() && blocks[t]) library_->insert(keys[t], blocks[t]);
  for (std::size_t t = 0; t < nt; ++t) {
    const std::size_t f = firstOfShape[t];
    if (f == t) continue;
    blocks[t] = blocks[f];
    if (!failures[f].empty()) failures[t] = "tile " + std::to_string(t) + " has the shape of tile " + std::to_string(f) + ": " + failures[f];
  }
#pragma omp parallel for schedule(dynamic)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(nt); ++t) {
    if (!failures[t].empty()) continue;
    try {
      buildTile(std::size_t(t), *blocks[t], boundary[t]);
    } catch (const std::exception& e) {
      failures[t] = e.what();
    }
  }
  return failures;
}

template <int Dim>
void ReducedTiles<Dim>::demoteTiles(const std::vector<std::size_t>& failed) {
  std::vector<std::uint8_t> drop(tiling_.tiles.size(), 0);
  for (std::size_t t : failed) drop[t] = 1;
  std::vector<sparse_grid::Tile> kept;
  std::vector<std::int32_t> newId(tiling_.tiles.size(), -1);
  for (std::size_t t = 0; t < tiling_.tiles.size(); ++t) {
    if (drop[t]) continue;
    newId[t] = std::int32_t(kept.size());
    kept.push_back(std::move(tiling_.tiles[t]));
  }
  for (auto& id : tiling_.tileOfCell)
    if (id >= 0) id = newId[id];
  tiling_.tiles = std::move(kept);
}

template <int Dim>
void ReducedTiles<Dim>::keepTilesNearOwnedBlocks() {
  // A cell c is near the rank's blocks when one of them meets the box [c - R, c + R]; with R below
  // the block width that box meets at most two blocks per axis, those of its corners.
  static_assert(kTileTouchCells < BlockLayout<Dim>::kWidth);
  auto ownsBlockOf = [&](const sparse_grid::Coord& c) {
    const std::int32_t b = layout_->blockAt(BlockLayout<Dim>::blockOriginOf(c));
    return b >= 0 && prob_->blockOwner[std::size_t(b)] == prob_->rank;
  };
  auto nearOwnedBlocks = [&](const sparse_grid::Tile& tile) {
    for (std::size_t s : tile.cells) {
      const sparse_grid::Coord c = layout_->cellOf(s);
      for (int corner = 0; corner < (1 << Dim); ++corner) {
        sparse_grid::Coord q = c;
        for (int a = 0; a < Dim; ++a) q[a] += (corner >> a) & 1 ? kTileTouchCells : -kTileTouchCells;
        if (ownsBlockOf(q)) return true;
      }
    }
    return false;
  };
  std::vector<std::uint8_t> near(tiling_.tiles.size());
#pragma omp parallel for schedule(dynamic)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(near.size()); ++t) near[t] = nearOwnedBlocks(tiling_.tiles[t]) ? 1 : 0;
  std::vector<std::size_t> far;
  for (std::size_t t = 0; t < near.size(); ++t)
    if (!near[t]) far.push_back(t);
  if (!far.empty()) demoteTiles(far);
}

template <int Dim>
bool ReducedTiles<Dim>::reportsRegion(const sparse_grid::Tile& region) const {
  if (!prob_->isDistributed()) return true;
  sparse_grid::Coord first = layout_->cellOf(region.cells.front());
  for (std::size_t s : region.cells) first = std::min(first, layout_->cellOf(s));
  return prob_->ownsSlot(std::size_t(layout_->slotOf(first)));
}

template <int Dim>
void ReducedTiles<Dim>::recordTiles(TileHistory& history) {
  std::vector<std::uint64_t> fingerprints(tiling_.tiles.size());
#pragma omp parallel for schedule(dynamic)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(fingerprints.size()); ++t)
    fingerprints[t] = cellSetFingerprint(*layout_, tiling_.tiles[t].cells);
  for (std::size_t t = 0; t < fingerprints.size(); ++t) {
    keptTiles_ += reports_[t] && history.hadTile(fingerprints[t]) ? 1 : 0;
    history.recordTile(fingerprints[t]);
  }
}

template <int Dim>
void ReducedTiles<Dim>::buildTiling(const sparse_grid::TilingOptions& topt, double accuracy, TileHistory* history) {
  if ((topt.minTileSize > 0) != (accuracy > 0.0))
    throw std::invalid_argument("reduced tiles: --tile-min and --tile-accuracy go together (tile-min " +
                                std::to_string(topt.minTileSize) + ", accuracy " + std::to_string(accuracy) + ")");
  std::vector<std::uint8_t> liquidFull(n_), fluidFull(n_);
  for (std::size_t s = 0; s < n_; ++s) {
    liquidFull[s] = prob_->liquidCell[s] >= 1.0 ? 1 : 0;
    fluidFull[s] = prob_->fluidStressWeight(s) >= 1.0 ? 1 : 0;  // channel 0 sits at the cell centre
  }
  sparse_grid::RefineRegion refine;
  std::atomic<std::size_t> reused{0};
  if (accuracy > 0.0) {
    const double bound = accuracy * velocityVariation(liquidFull);
    refine = [this, bound, history, &reused](const sparse_grid::Tile& region, int edge) {
      return splitsCube(region, edge, bound, history, reused);
    };
  }
  tiling_ = sparse_grid::buildTiling<Dim>(*layout_, liquidFull, fluidFull, topt, refine);
  reusedDecisions_ = reused.load();
}

template <int Dim>
bool ReducedTiles<Dim>::splitsCube(const sparse_grid::Tile& region, int edge, double bound, TileHistory* history,
                                   std::atomic<std::size_t>& reused) const {
  if (!history) return fitMisfit(region) > bound;
  const sparse_grid::Coord k = sparse_grid::detail::cubeCorner(layout_->cellOf(region.cells.front()), edge);
  TileHistory::Decision d{{k[0], k[1], k[2]}, edge, cellSetFingerprint(*layout_, region.cells), false};
  const std::optional<bool> kept = history->previousDecision(d.corner, d.edge, d.region);
  if (kept) ++reused;
  d.split = kept ? *kept : fitMisfit(region) > bound;
  history->record(d);
  return d.split;
}

template <int Dim>
void ReducedTiles<Dim>::applyTileRule(const ReducedOptions& opt) {
  const TileRule rule = opt.rule;
  std::vector<TileWork> work(tiling_.tiles.size());
#pragma omp parallel for schedule(dynamic)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(work.size()); ++t) work[t] = tileWork(*layout_, tiling_, std::size_t(t));
  std::vector<std::size_t> unpaid;
  for (std::size_t t = 0; t < work.size(); ++t) {
    if (rule == TileRule::Paying && !work[t].pays()) {
      unpaid.push_back(t);
      continue;
    }
    work_.add(work[t]);
  }
  const double rows = double(opt.uniformRows);
  if (rule == TileRule::Paying && rows > 0.0 && rows - work_.saved + work_.overhead >= opt.uniformRowCost * rows) {
    unpaid.clear();  // the uniform step is the cheaper one: no tile
    for (std::size_t t = 0; t < work.size(); ++t) unpaid.push_back(t);
    work_ = {};
  }
  unpaidTiles_ = std::size_t(std::count_if(unpaid.begin(), unpaid.end(),
                                           [&](std::size_t t) { return reportsRegion(tiling_.tiles[t]); }));
  if (!unpaid.empty()) demoteTiles(unpaid);
}

template <int Dim>
double ReducedTiles<Dim>::velocityVariation(const std::vector<std::uint8_t>& liquidFull) const {
  double total = 0.0;
  std::size_t count = 0;
  for (int a = 0; a < Dim; ++a) {
    double sum = 0.0, squares = 0.0;
    std::size_t k = 0;
    for (std::size_t s = 0; s < n_; ++s) {
      if (!liquidFull[s]) continue;
      const double u = prob_->uStar[a * n_ + s];
      sum += u;
      squares += u * u;
      ++k;
    }
    if (k == 0) continue;
    total += std::max(0.0, squares - sum * sum / double(k));
    count += k;
  }
  return count ? std::sqrt(total / double(count)) : 0.0;
}

template <int Dim>
double ReducedTiles<Dim>::fitMisfit(const sparse_grid::Tile& region) const {
  const int m = basis_.size();
  GramAccumulator F(m);
  VectorX b = VectorX::Zero(m);
  double uu = 0.0, row[kRowStorage], xs[3];
  for (std::size_t s : region.cells)
    for (int a = 0; a < Dim; ++a) {
      const std::int64_t f = std::int64_t(a * n_ + s);
      scaledCoords(region, f, xs);
      basis_.evaluateComponent(a, xs, row);
      const Eigen::Map<const VectorX> c(row, m);
      F.add(c);
      b += prob_->uStar[f] * c;
      uu += prob_->uStar[f] * prob_->uStar[f];
    }
  const VectorX v = F.result().ldlt().solve(b);
  const double count = double(Dim * region.cells.size());
  return std::sqrt(std::max(0.0, uu - b.dot(v)) / count);
}

template <int Dim>
void ReducedTiles<Dim>::labelFacesAndSamples() {
  tileOfFace_.assign(Dim * n_, -1);
  for (std::size_t t = 0; t < tiling_.tiles.size(); ++t)
    for (std::size_t s : tiling_.tiles[t].cells)
      for (int a = 0; a < Dim; ++a) {
        tileOfFace_[a * n_ + s] = std::int32_t(t);
        const std::int64_t up = layout_->neighbourSlot(s, a, +1);
        if (up >= 0) tileOfFace_[a * n_ + std::size_t(up)] = std::int32_t(t);
      }
  insideStress_.assign(SC::kCount * n_, 0);
  if (!kinds_.stress) return;
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t s = 0; s < std::ptrdiff_t(n_); ++s)
    for (int c = 0; c < SC::kCount; ++c) {
      std::int32_t owner = -2;
      int count = 0;
      bool inside = true;
      kernels::forEachStressFace<Dim>(*layout_, c, std::size_t(s), [&](std::int64_t f, double) {
        const std::int32_t t = tileOfFace_[f];
        if (owner == -2) owner = t;
        inside = inside && t >= 0 && t == owner;
        ++count;
      });
      insideStress_[c * n_ + s] = inside && count == (SC::isDiagonal(c) ? 2 : 4) ? 1 : 0;
    }
}

template <int Dim>
bool ReducedTiles<Dim>::isCartesianPressure(std::size_t slot) const {
  return kinds_.pressure && !isReducedCell(slot) && prob_->liquidCell[slot] > 0.0;
}

template <int Dim>
bool ReducedTiles<Dim>::isCartesianStress(int c, std::size_t slot) const {
  return kinds_.stress && !isInsideStress(c, slot) && prob_->liquidStress[c * n_ + slot] > 0.0;
}

template <int Dim>
void ReducedTiles<Dim>::scaledCoords(const sparse_grid::Tile& tile, std::int64_t f, double* xs) const {
  const int a = int(f / std::int64_t(n_));
  const sparse_grid::Coord c = layout_->cellOf(std::size_t(f % std::int64_t(n_))) - tile.bboxMin;
  for (int d = 0; d < Dim; ++d)
    xs[d] = (double(c[d]) + (d == a ? 0.0 : 0.5) - tile.centreInCells[d]) / tile.halfWidthInCells;
}

template <int Dim>
void ReducedTiles<Dim>::basisRow(const TileData& td, int axis, const double* xs, double* row) const {
  basis_.evaluateComponent(axis, xs, row);
  if (td.modes.size() == 0) return;
  const int m = basis_.size();
  double full[kRowStorage];
  std::copy(row, row + m, full);
  Eigen::Map<VectorX>(row, m).noalias() = td.modes.transpose() * Eigen::Map<const VectorX>(full, m);
}

template <int Dim>
auto ReducedTiles<Dim>::resolvedModes(const Matrix& F) const -> Matrix {
  const int m = basis_.size();
  const int affine = PolynomialBasis<Dim>(PolynomialOrder::Affine, basis_.family()).size();
  std::vector<int> ends = {Dim, affine};
  if (m > affine) ends.push_back(m);
  const double tol = 1e-10 * Eigen::SelfAdjointEigenSolver<Matrix>(F, Eigen::EigenvaluesOnly).eigenvalues().maxCoeff();
  Matrix T = Matrix::Zero(m, m);
  int r = 0, begin = 0;
  for (const int end : ends) {
    Matrix W = Matrix::Zero(m, end - begin);
    W.middleRows(begin, end - begin).setIdentity();
    if (r > 0) {
      const Matrix Tr = T.leftCols(r);
      W -= Tr * (Tr.transpose() * F * Tr).ldlt().solve(Tr.transpose() * F * W);
    }
    const Eigen::SelfAdjointEigenSolver<Matrix> eig(W.transpose() * F * W);
    for (int k = end - begin - 1; k >= 0; --k)  // largest first
      if (eig.eigenvalues()[k] > tol) T.col(r++) = W * eig.eigenvectors().col(k);
    if (begin == 0 && r < Dim) return Matrix();
    begin = end;
  }
  return T;
}

template <int Dim>
std::vector<std::size_t> ReducedTiles<Dim>::shapeOrder(const std::vector<std::int64_t>& faces) const {
  std::vector<std::size_t> order(faces.size());
  std::iota(order.begin(), order.end(), std::size_t(0));
  auto key = [&](std::int64_t f) {
    const sparse_grid::Coord c = layout_->cellOf(std::size_t(f % std::int64_t(n_)));
    return std::array<std::int64_t, 4>{c.z(), c.y(), c.x(), f / std::int64_t(n_)};
  };
  std::sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) { return key(faces[i]) < key(faces[j]); });
  return order;
}

template <int Dim>
std::string ReducedTiles<Dim>::shapeKey(const sparse_grid::Tile& tile) const {
  if (cache_ == TileCacheStrategy::None) return "";
  if (cache_ == TileCacheStrategy::Library && !tile.isFullBox) return "";
  std::string key = std::string(basis_.name()) + (fitAllFaces_ ? "/all/" : "/boundary/") +
                    (kinds_.viscous ? "visc/" : "novisc/");
  char dx[32];  // K^ scales with 1/dx^2
  std::snprintf(dx, sizeof dx, "%a/", layout_->dx());
  key += dx;
  for (int a = 0; a < Dim; ++a) key += std::to_string(tile.bboxMax[a] - tile.bboxMin[a] + 1) + "x";
  if (tile.isFullBox) return key + "box";
  // occupancy mask of the bounding box, one character per 6 cells
  const sparse_grid::Coord lo = tile.bboxMin;
  std::vector<std::uint8_t> bits;
  for (std::size_t s : tile.cells) {
    const sparse_grid::Coord c = layout_->cellOf(s) - lo;
    std::size_t idx = 0, stride = 1;
    for (int a = 0; a < Dim; ++a) {
      idx += std::size_t(c[a]) * stride;
      stride *= std::size_t(tile.bboxMax[a] - tile.bboxMin[a] + 1);
    }
    if (bits.size() <= idx / 6) bits.resize(idx / 6 + 1, 0);
    bits[idx / 6] |= std::uint8_t(1u << (idx % 6));
  }
  for (std::uint8_t b : bits) key += char('0' + b);
  return key;
}

template <int Dim>
void ReducedTiles<Dim>::collectFaces(std::size_t t, TileData& td, std::vector<std::uint8_t>& boundary) const {
  const sparse_grid::Tile& tile = tiling_.tiles[t];
  for (std::size_t s : tile.cells)
    for (int a = 0; a < Dim; ++a)
      for (int dir : {0, 1}) {
        const std::int64_t owner = dir == 0 ? std::int64_t(s) : layout_->neighbourSlot(s, a, +1);
        const std::int64_t other = dir == 0 ? layout_->neighbourSlot(s, a, -1) : std::int64_t(s);
        if (owner < 0) continue;
        const bool otherInTile = dir == 0 ? (other >= 0 && tiling_.tileOfCell[other] == std::int32_t(t))
                                          : (tiling_.tileOfCell[owner] == std::int32_t(t));
        if (dir == 1 && otherInTile) continue;  // the lower face of a tile cell: counted there
        td.faces.push_back(std::int64_t(a * n_) + owner);
        boundary.push_back(otherInTile ? 0 : 1);
      }
}

template <int Dim>
std::shared_ptr<TileShapeBlocks> ReducedTiles<Dim>::computeShapeBlocks(std::size_t t, const TileData& td,
    const std::vector<std::uint8_t>& boundary) const {
  const sparse_grid::Tile& tile = tiling_.tiles[t];
  const int m = basis_.size();
  auto blocks = std::make_shared<TileShapeBlocks>();
  GramAccumulator massSum(m), fitSum(m);
  double row[kRowStorage], xs[3];
  for (std::size_t q : shapeOrder(td.faces)) {
    scaledCoords(tile, td.faces[q], xs);
    basis_.evaluateComponent(int(td.faces[q] / std::int64_t(n_)), xs, row);
    const Eigen::Map<const VectorX> c(row, m);
    massSum.add(c);
    if (fitAllFaces_ || boundary[q]) fitSum.add(c);
  }
  Matrix M = massSum.result(), fit = fitSum.result();
  Matrix K = kinds_.viscous ? viscousBlock(tile, t) : Matrix::Zero(m, m);
  blocks->fit.setThreshold(1e-10);  // "nearly singular" counts as singular
  blocks->fit.compute(fit);
  blocks->modeCount = m;
  if (const int rank = int(blocks->fit.rank()); rank < m) {
    // the fields the faces do not resolve are dropped: every block in the basis C T, with the
    // identity on the dropped columns of M^ and F (tile_library.h)
    const Matrix T = resolvedModes(fit);
    const int r = int((T.colwise().norm().array() > 0.0).count());
    if (T.size() == 0)
      throw std::runtime_error("the least-squares fit of tile " + std::to_string(t) + " (" +
                               std::to_string(tile.cells.size()) + " cells) is singular (rank " + std::to_string(rank) +
                               " of " + std::to_string(m) + ") for basis " + basis_.name() +
                               " and does not resolve the translations; it falls back to Cartesian cells");
    Matrix dropped = Matrix::Zero(m, m);
    for (int k = r; k < m; ++k) dropped(k, k) = 1.0;
    M = T.transpose() * M * T + dropped;
    fit = T.transpose() * fit * T + dropped;
    K = T.transpose() * K * T;
    blocks->fit.compute(fit);
    blocks->modes = T;
    blocks->modeCount = r;
  }
  blocks->massHat = M;
  blocks->viscHat = K;
  Eigen::GeneralizedSelfAdjointEigenSolver<Matrix> eig(blocks->viscHat, blocks->massHat);
  if (eig.info() != Eigen::Success || !(eig.eigenvalues().minCoeff() > -1e-8 * (1.0 + eig.eigenvalues().maxCoeff())))
    throw std::runtime_error("B = M_R/dt + K_R of tile " + std::to_string(t) +
                             " cannot be factored (M_R not positive definite); it falls back to Cartesian cells");
  blocks->eigenvectors = eig.eigenvectors();
  blocks->eigenvalues = eig.eigenvalues().cwiseMax(0.0);
  return blocks;
}

template <int Dim>
void ReducedTiles<Dim>::buildTile(std::size_t t, const TileShapeBlocks& shape, const std::vector<std::uint8_t>& boundary) {
  const sparse_grid::Tile& tile = tiling_.tiles[t];
  TileData& td = tiles_[t];
  const int m = basis_.size();
  const double rho = prob_->rho, mu = prob_->mu, dt = prob_->dt;
  td.modes = shape.modes;
  td.modeCount = shape.modeCount;
  td.massR = rho * shape.massHat;
  td.viscR = mu * shape.viscHat;
  td.inverseB = shape.inverseB(rho, dt, kinds_.viscous ? mu : 0.0);
  td.massHatInverse = shape.eigenvectors * shape.eigenvectors.transpose();
  // per-step data: fit of u*, coupling rows, reconstruction error
  double row[kRowStorage], xs[3];
  VectorX fitRhs = VectorX::Zero(m);
  for (std::size_t q = 0; q < td.faces.size(); ++q) {
    const std::int64_t f = td.faces[q];
    scaledCoords(tile, f, xs);
    basisRow(td, int(f / std::int64_t(n_)), xs, row);
    if (fitAllFaces_ || boundary[q]) fitRhs += prob_->uStar[f] * Eigen::Map<const VectorX>(row, m);
    if (isCoupling(f)) {
      td.coupling.push_back(f);
      for (int d = 0; d < Dim; ++d) td.couplingCoords.push_back(xs[d]);
    }
  }
  td.vStar = shape.fit.solve(fitRhs);  // (sum C^T C) v* = sum C^T u*
  td.couplingRows.resize(Eigen::Index(td.coupling.size()), m);
  for (std::size_t q = 0; q < td.coupling.size(); ++q)
    basisRow(td, int(td.coupling[q] / std::int64_t(n_)), &td.couplingCoords[q * Dim],
             td.couplingRows.row(Eigen::Index(q)).data());
  for (std::int64_t f : td.faces) {
    scaledCoords(tile, f, xs);
    basisRow(td, int(f / std::int64_t(n_)), xs, row);
    const double u = Eigen::Map<const VectorX>(row, m).dot(td.vStar);
    td.reconstructionLinf = std::max(td.reconstructionLinf, std::abs(u - prob_->uStar[f]));
  }
  td.vFree = td.inverseB * (td.massR * td.vStar / dt);
}

template <int Dim>
auto ReducedTiles<Dim>::viscousBlock(const sparse_grid::Tile& tile, std::size_t t) const -> Matrix {
  const int m = basis_.size();
  GramAccumulator K(m);
  double row[kRowStorage], xs[3];
  VectorX d(m);
  // inside samples sit on tile cells or their upper neighbours (edges): scan cells and +1 layer
  std::vector<std::size_t> candidates = tile.cells;
  for (std::size_t s : tile.cells)
    for (int a = 0; a < Dim; ++a) {
      const std::int64_t up = layout_->neighbourSlot(s, a, +1);
      if (up >= 0) candidates.push_back(std::size_t(up));
    }
  std::sort(candidates.begin(), candidates.end());
  candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
  // summed in an order fixed by the shape (cell z, y, x), not by slot
  std::sort(candidates.begin(), candidates.end(), [&](std::size_t i, std::size_t j) {
    const sparse_grid::Coord a = layout_->cellOf(i), b = layout_->cellOf(j);
    return std::array<int, 3>{a.z(), a.y(), a.x()} < std::array<int, 3>{b.z(), b.y(), b.x()};
  });
  for (std::size_t s : candidates)
    for (int c = 0; c < SC::kCount; ++c) {
      if (!isInsideStress(c, s)) continue;
      bool mine = true;
      d.setZero();
      kernels::forEachStressFace<Dim>(*layout_, c, s, [&](std::int64_t f, double coef) {
        mine = mine && tileOfFace_[f] == std::int32_t(t);
        scaledCoords(tile, f, xs);
        basis_.evaluateComponent(int(f / std::int64_t(n_)), xs, row);
        d += coef * Eigen::Map<const VectorX>(row, m);
      });
      if (mine) K.add(d, std::sqrt(1.0 / complianceFactor<Dim>(c)));
    }
  return K.result();
}

template <int Dim>
bool ReducedTiles<Dim>::isCoupling(std::int64_t f) const {
  const int a = int(f / std::int64_t(n_));
  bool touched = false;
  kernels::forEachSampleOfFace<Dim>(
      *layout_, a, std::size_t(f % std::int64_t(n_)),
      [&](std::size_t ps, double) { touched = touched || isCartesianPressure(ps); },
      [&](int c, std::size_t ts, double) { touched = touched || isCartesianStress(c, ts); });
  return touched;
}

template <int Dim>
void ReducedTiles<Dim>::coupleTile(std::size_t t, double* faces) const {
  double F[kRowStorage], V[kRowStorage];
  gatherTile(t, faces, F);
  applyInverse(t, F, V);
  scatterTile(t, V, faces, /*couplingOnly=*/true);
}

template <int Dim>
void ReducedTiles<Dim>::gatherTile(std::size_t t, const double* faces, double* F) const {
  const TileData& td = tiles_[t];
  const int m = basis_.size();
  const Eigen::Index nc = Eigen::Index(td.coupling.size());
  thread_local VectorX values;
  values.resize(nc);
  for (Eigen::Index q = 0; q < nc; ++q) values[q] = faces[td.coupling[q]];
  Eigen::Map<VectorX>(F, m).noalias() = td.couplingRows.transpose() * values;
}

template <int Dim>
void ReducedTiles<Dim>::applyInverse(std::size_t t, const double* F, double* V) const {
  const int m = basis_.size();
  const Eigen::Map<const VectorX> Fm(F, m);
  Eigen::Map<VectorX>(V, m).noalias() = tiles_[t].inverseB * Fm;
}

template <int Dim>
void ReducedTiles<Dim>::scatterTile(std::size_t t, const double* V, double* faces, bool couplingOnly) const {
  const TileData& td = tiles_[t];
  const int m = basis_.size();
  double row[kRowStorage], xs[3];
  if (couplingOnly) {  // f|coupling = C V  (a dense mat-vec, then a scatter)
    const Eigen::Index nc = Eigen::Index(td.coupling.size());
    thread_local VectorX values;
    values.noalias() = td.couplingRows * Eigen::Map<const VectorX>(V, m);
    for (Eigen::Index q = 0; q < nc; ++q) faces[td.coupling[q]] = values[q];
    return;
  }
  for (std::int64_t f : td.faces) {
    scaledCoords(tiling_.tiles[t], f, xs);
    basisRow(td, int(f / std::int64_t(n_)), xs, row);
    double v = 0.0;
    for (int k = 0; k < m; ++k) v += row[k] * V[k];
    faces[f] = v;
  }
}

template class ReducedTiles<2>;
template class ReducedTiles<3>;

}  // namespace reduced
}  // namespace stokes::solver
