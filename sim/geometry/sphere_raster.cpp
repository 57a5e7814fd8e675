// The sphere-union raster: see sphere_raster.h.
#include "sim/geometry/sphere_raster.h"

#include <openvdb/tools/Prune.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>

#include "sparse_grid/bucket_sort.h"

namespace stokes::sim {
inline namespace geometry {

namespace {

using openvdb::Coord;
using openvdb::Vec3d;
using Leaf = openvdb::FloatTree::LeafNodeType;

constexpr int kLeafDim = 8;

constexpr std::uint8_t kUntouched = 0, kActive = 1, kInside = 2;

/// Leaf origins packed into one sortable key (18 bits per axis: +-2^17 leaves, +-1M voxels),
/// leaving the low 9 bits of a 64-bit sort key for the voxel inside the leaf.
std::uint64_t leafKey(const Coord& origin) {
  auto part = [](int v) { return std::uint64_t(std::uint32_t((v >> 3) + (1 << 17)) & 0x3FFFFu); };
  return (part(origin.x()) << 36) | (part(origin.y()) << 18) | part(origin.z());
}

/// Offset of voxel c inside its leaf, as LeafNode::coordToOffset.
int voxelOffset(const Coord& c) { return ((c.x() & 7) << 6) | ((c.y() & 7) << 3) | (c.z() & 7); }

Coord leafOriginOf(const Coord& c) { return Coord(c.x() & ~7, c.y() & ~7, c.z() & ~7); }

/// The constants of ParticlesToLevelSet's makeSphere, computed as it computes them.
struct SphereConstants {
  double dx, R, max, max2, min2;
  float background, inside;
};

/// One target leaf's dense state: value and kUntouched / kActive / kInside per voxel, indexed as
/// LeafNode::coordToOffset (x * 64 + y * 8 + z).
struct LeafBuffer {
  std::array<float, 512> value;
  std::array<std::uint8_t, 512> state;
};

/// Particles sorted by the voxel floor(P) (leaf by leaf, voxels in offset order), with the range
/// of each voxel of each leaf that holds particles.
struct ParticlesByLeaf {
  std::vector<Vec3d> P;                 ///< index-space positions, sorted
  std::vector<std::uint64_t> keys;      ///< the leaves that hold particles, ascending
  std::vector<std::uint32_t> voxelStart;  ///< per leaf 513 offsets into P, one per voxel + end

  /// Index of the leaf with `key` among keys, or -1.
  std::ptrdiff_t find(std::uint64_t key) const {
    const auto it = std::lower_bound(keys.begin(), keys.end(), key);
    return it == keys.end() || *it != key ? -1 : std::ptrdiff_t(it - keys.begin());
  }
};

Coord floorCoord(const Vec3d& P) {
  return Coord(int(std::floor(P[0])), int(std::floor(P[1])), int(std::floor(P[2])));
}

using sparse_grid::chunkRange;

/// The particles' fixed chunks for the counting sort: the order never depends on them.
std::size_t sortChunks(std::size_t n) { return std::min<std::size_t>(64, n / 4096 + 1); }

/// The distinct keys of `leafOf`, ascending: each chunk's runs of one key, sorted and unique, then
/// merged.
std::vector<std::uint64_t> uniqueLeafKeys(const std::vector<std::uint64_t>& leafOf, std::size_t chunks) {
  const std::size_t n = leafOf.size();
  std::vector<std::vector<std::uint64_t>> runKeys(chunks);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t ch = 0; ch < std::ptrdiff_t(chunks); ++ch) {
    const auto [b, e] = chunkRange(n, chunks, std::size_t(ch));
    for (std::size_t i = b; i < e; ++i)
      if (i == b || leafOf[i] != leafOf[i - 1]) runKeys[ch].push_back(leafOf[i]);
    std::sort(runKeys[ch].begin(), runKeys[ch].end());
    runKeys[ch].erase(std::unique(runKeys[ch].begin(), runKeys[ch].end()), runKeys[ch].end());
  }
  std::vector<std::uint64_t> keys;
  for (const auto& r : runKeys) keys.insert(keys.end(), r.begin(), r.end());
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  return keys;
}

/// Replaces each key of `leafOf` by its leaf's index in `sorted` (one search per run of equal keys).
void keysToLeafIndices(const ParticlesByLeaf& sorted, std::vector<std::uint64_t>& leafOf, std::size_t chunks) {
  const std::size_t n = leafOf.size();
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t ch = 0; ch < std::ptrdiff_t(chunks); ++ch) {
    const auto [b, e] = chunkRange(n, chunks, std::size_t(ch));
    std::uint64_t lastKey = ~std::uint64_t(0), lastLeaf = 0;
    for (std::size_t i = b; i < e; ++i) {
      if (leafOf[i] != lastKey) {
        lastKey = leafOf[i];
        lastLeaf = std::uint64_t(sorted.find(lastKey));
      }
      leafOf[i] = lastLeaf;
    }
  }
}

/// The particles sorted by (leaf key, voxel offset, index): a stable counting sort, first by leaf
/// over fixed chunks of the particles, then by voxel inside each leaf, both in parallel. The order
/// is std::sort's of the (key, index) pairs, whatever the thread count; the work is O(n).
ParticlesByLeaf sortByLeaf(const openvdb::math::Transform& xform, const std::vector<Vec3d>& positions) {
  const std::size_t n = positions.size();
  // ParticlesToLevelSet: mMap.applyInverseMap(pos). Computed again where needed rather than
  // stored: at 15 M particles the temporaries' first touch, not the arithmetic, is the cost.
  auto indexPosition = [&](std::size_t i) { return xform.worldToIndex(positions[i]); };
  std::vector<std::uint64_t> leafOf(n);  // the leaf key, then the leaf's index among the keys
  std::vector<std::uint16_t> voxelOf(n);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(n); ++i) {
    const Coord c = floorCoord(indexPosition(std::size_t(i)));
    leafOf[i] = leafKey(leafOriginOf(c));
    voxelOf[i] = std::uint16_t(voxelOffset(c));
  }
  const std::size_t chunks = sortChunks(n);
  ParticlesByLeaf out;
  out.keys = uniqueLeafKeys(leafOf, chunks);
  keysToLeafIndices(out, leafOf, chunks);
  const auto byLeafOrder = sparse_grid::sortByBucket<std::uint32_t>(
      n, out.keys.size(), chunks, [&](std::size_t i) { return std::int64_t(leafOf[i]); });
  const std::vector<std::uint32_t>& leafStart = byLeafOrder.start;
  const std::vector<std::uint32_t>& byLeaf = byLeafOrder.items;

  // Inside each leaf, counting sort by voxel, stable: the ranges of voxelStart and the positions.
  const std::size_t L = out.keys.size();
  out.P.resize(n);
  out.voxelStart.resize(L * 513);
#pragma omp parallel for schedule(dynamic, 16)
  for (std::ptrdiff_t l = 0; l < std::ptrdiff_t(L); ++l) {
    std::uint32_t* v = out.voxelStart.data() + std::size_t(l) * 513;
    std::array<std::uint32_t, 512> count{};
    for (std::uint32_t p = leafStart[l]; p < leafStart[l + 1]; ++p) ++count[voxelOf[byLeaf[p]]];
    std::uint32_t at = leafStart[l];
    for (int k = 0; k < 512; ++k) {
      v[k] = at;
      at += count[k];
      count[k] = v[k];
    }
    v[512] = at;
    for (std::uint32_t p = leafStart[l]; p < leafStart[l + 1]; ++p) {
      const std::uint32_t i = byLeaf[p];
      out.P[count[voxelOf[i]]++] = indexPosition(i);
    }
  }
  return out;
}

/// Origins of every leaf a particle's box can reach: the leaves holding particles and their 26
/// neighbours (R + w < 8 voxels), sorted and unique.
std::vector<Coord> targetLeaves(const ParticlesByLeaf& sorted) {
  std::vector<std::pair<std::uint64_t, Coord>> all;
  all.reserve(27 * sorted.keys.size());
  for (std::size_t i = 0; i < sorted.keys.size(); ++i) {
    const Coord origin = leafOriginOf(floorCoord(sorted.P[sorted.voxelStart[i * 513]]));
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const Coord o = origin + Coord(dx * kLeafDim, dy * kLeafDim, dz * kLeafDim);
          all.emplace_back(leafKey(o), o);
        }
  }
  std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<Coord> out;
  for (std::size_t i = 0; i < all.size(); ++i)
    if (i == 0 || all[i].first != all[i - 1].first) out.push_back(all[i].second);
  return out;
}

/// The particles near one target leaf: for every voxel cell q of the region [origin - 1 - G,
/// origin + 7 + G]^3 (side 9 + 2G), the range [first, last) of the particles with
/// floor(P) = q in the sort. Cells of one z-row inside one source leaf are contiguous in the sort,
/// so a run of them is the single range [first of the lowest, last of the highest). A bit mask per
/// column marks the cells that hold particles (side <= 9 + 2 * 6 = 21 bits).
class NearbyCells {
 public:
  /// The occupancy masks only; loadRanges adds the particle ranges.
  NearbyCells(const ParticlesByLeaf& sorted, const Coord& origin, int G)
      : sorted_(&sorted), lo_(origin.offsetBy(-1 - G)), side_(kLeafDim + 1 + 2 * G),
        occupied_(std::size_t(side_) * side_, 0) {
    forEachCell([&](std::size_t, int x, int y, int z, std::uint32_t first, std::uint32_t last) {
      if (first < last) occupied_[column(x, y)] |= 1u << (z - lo_.z());
    });
  }
  /// Fills the table of particle ranges (before forEachRange).
  void loadRanges() {
    first_.assign(std::size_t(side_) * side_ * side_, 0);
    last_.assign(first_.size(), 0);
    forEachCell([&](std::size_t i, int, int, int, std::uint32_t first, std::uint32_t last) {
      first_[i] = first;
      last_[i] = last;
    });
  }
  /// Calls f(first, last) for the particle ranges of cells (x, y, z0..z1), global coordinates
  /// inside the region: one range per source leaf the run crosses.
  template <class F>
  void forEachRange(int x, int y, int z0, int z1, F&& f) const {
    if ((occupied_[column(x, y)] & runBits(z0, z1)) == 0) return;  // no particle in these cells
    while (z0 <= z1) {
      const int z = std::min(z1, (z0 | 7));  // the run's end inside z0's source leaf
      const std::size_t a = index(Coord(x, y, z0)), b = index(Coord(x, y, z));
      if (first_[a] < last_[b]) f(first_[a], last_[b]);
      z0 = z + 1;
    }
  }

  /// Bit z - lo.z set where some cell (x + ox, y + oy, z), ox and oy in [-1 - G, G], holds
  /// particles: the cells a voxel of column (x, y) can reach.
  std::uint32_t reachable(int x, int y, int G) const {
    std::uint32_t m = 0;
    for (int ox = -1 - G; ox <= G; ++ox)
      for (int oy = -1 - G; oy <= G; ++oy) m |= occupied_[column(x + ox, y + oy)];
    return m;
  }
  /// Bit z - lo.z set where every cell (x + ox, y + oy, z), ox and oy in [-1 - K, K], holds
  /// particles: the AND of those columns' occupancy.
  std::uint32_t fullColumns(int x, int y, int K) const {
    std::uint32_t m = ~0u;
    for (int ox = -1 - K; ox <= K; ++ox)
      for (int oy = -1 - K; oy <= K; ++oy) m &= occupied_[column(x + ox, y + oy)];
    return m;
  }
  /// The bits of cells lo.z + [z0, z1] in a column mask.
  std::uint32_t runBits(int z0, int z1) const {
    return ((2u << (z1 - lo_.z())) - 1u) & ~((1u << (z0 - lo_.z())) - 1u);
  }

 private:
  std::size_t index(const Coord& c) const {
    return (std::size_t(c.x() - lo_.x()) * side_ + std::size_t(c.y() - lo_.y())) * side_ + std::size_t(c.z() - lo_.z());
  }
  std::size_t column(int x, int y) const { return std::size_t(x - lo_.x()) * side_ + std::size_t(y - lo_.y()); }
  /// Calls f(index, x, y, z, first, last) for every cell of the region inside a source leaf that
  /// holds particles.
  template <class F>
  void forEachCell(F&& f) const {
    const Coord hi = lo_.offsetBy(side_ - 1);
    for (int lx = lo_.x() & ~7; lx <= hi.x(); lx += kLeafDim)
      for (int ly = lo_.y() & ~7; ly <= hi.y(); ly += kLeafDim)
        for (int lz = lo_.z() & ~7; lz <= hi.z(); lz += kLeafDim) {
          const std::ptrdiff_t leaf = sorted_->find(leafKey(Coord(lx, ly, lz)));
          if (leaf < 0) continue;
          const std::uint32_t* v = sorted_->voxelStart.data() + std::size_t(leaf) * 513;
          for (int x = std::max(lx, lo_.x()); x <= std::min(lx + 7, hi.x()); ++x)
            for (int y = std::max(ly, lo_.y()); y <= std::min(ly + 7, hi.y()); ++y)
              for (int z = std::max(lz, lo_.z()); z <= std::min(lz + 7, hi.z()); ++z) {
                const int o = ((x - lx) << 6) | ((y - ly) << 3) | (z - lz);
                f(index(Coord(x, y, z)), x, y, z, v[o], v[o + 1]);
              }
        }
  }
  const ParticlesByLeaf* sorted_;
  Coord lo_;
  int side_;
  std::vector<std::uint32_t> first_, last_;
  std::vector<std::uint32_t> occupied_;  ///< per (x, y) column, bit z - lo.z set where a cell holds particles
};

/// Distance gap, in whole voxels along one axis, from a voxel centre c to the cell q = c + o
/// (particles in [q, q + 1)): o for o > 0, 0 for o = 0 or -1, -1 - o for o < -1.
int axisGap(int o) { return o > 0 ? o : (o < -1 ? -1 - o : 0); }

/// The (x, y) column offsets o of the cells within reach (gap < R + w per axis), nearest first by
/// their squared gap gx^2 + gy^2.
struct Column {
  int ox, oy, gap2;
};
std::vector<Column> columnsByGap(int G) {
  std::vector<Column> out;
  for (int ox = -1 - G; ox <= G; ++ox)
    for (int oy = -1 - G; oy <= G; ++oy)
      out.push_back({ox, oy, axisGap(ox) * axisGap(ox) + axisGap(oy) * axisGap(oy)});
  std::stable_sort(out.begin(), out.end(), [](const Column& a, const Column& b) { return a.gap2 < b.gap2; });
  return out;
}

/// floor(sqrt(n)) for 0 <= n (n < 64 here: squared reaches below 7^2).
int isqrt(int n) {
  int r = 0;
  while ((r + 1) * (r + 1) <= n) ++r;
  return r;
}

/// The squared index-space distance from voxel centre c to P, summed as makeSphere sums it.
inline double squaredDistance(const Coord& c, const Vec3d& P) {
  const double x2 = openvdb::math::Pow2(c.x() - P[0]);
  const double x2y2 = x2 + openvdb::math::Pow2(c.y() - P[1]);
  return x2y2 + openvdb::math::Pow2(c.z() - P[2]);
}

/// Whether every voxel of the leaf at `origin` is deep: all cells within K voxels hold particles.
bool isAllDeep(const NearbyCells& cells, const Coord& origin, int K) {
  const std::uint32_t run = cells.runBits(origin.z() - 1 - K, origin.z() + kLeafDim - 1 + K);
  for (int x = origin.x(); x < origin.x() + kLeafDim; ++x)
    for (int y = origin.y(); y < origin.y() + kLeafDim; ++y)
      if ((cells.fullColumns(x, y, K) & run) != run) return false;
  return true;
}

/// Fills one leaf; returns it, or null if no voxel was touched. Each voxel's value depends only on
/// the smallest squared distance a* to a particle (makeSphere's update is monotone in a), so each
/// voxel needs its nearest particle. A z-row of 8 voxels searches together: the particles of a
/// cell column share their (x, y) distance to the row, so each particle met updates all 8 voxels
/// at once (a = ((x - Px)^2 + (y - Py)^2) + (z - Pz)^2, summed as makeSphere sums it; the row's
/// lanes vectorise). The row starts from the previous row's nearest particles (upper bounds,
/// usually exact), then reads only the columns of cells, nearest first, whose gap could still beat
/// the largest of its bounds, and in each column only the cells that gap leaves within reach.
/// Particles farther than R + w never change a voxel; slack of 1e-9 voxels^2 keeps float ties on
/// the safe side. Deep voxels (deepMargin) take no part in the bound.
std::unique_ptr<Leaf> rasterLeaf(const SphereConstants& k, const ParticlesByLeaf& sorted, const Coord& origin, int G,
                                 int deepMargin, const std::vector<Column>& columns) {
  NearbyCells cells(sorted, origin, std::max(G, deepMargin));
  if (deepMargin >= 0 && isAllDeep(cells, origin, deepMargin))  // pruned to the inside tile
    return std::make_unique<Leaf>(origin, k.inside, /*active=*/false);
  cells.loadRanges();
  constexpr double kSlack = 1e-9;
  constexpr std::uint32_t kNone = ~std::uint32_t(0);
  LeafBuffer b;
  b.value.fill(k.background);
  b.state.fill(kUntouched);
  bool touched = false;
  std::array<std::uint32_t, kLeafDim> hint;  // the previous row's nearest particle per lane
  hint.fill(kNone);
  for (int row = 0; row < kLeafDim * kLeafDim; ++row) {
    const Coord c0 = origin + Coord(row >> 3, row & 7, 0);
    std::uint32_t live = 0xFFu;  // lanes that are not deep
    if (deepMargin >= 0) {
      const std::uint32_t full = cells.fullColumns(c0.x(), c0.y(), deepMargin);
      for (int z = 0; z < kLeafDim; ++z) {
        const std::uint32_t run = cells.runBits(c0.z() + z - 1 - deepMargin, c0.z() + z + deepMargin);
        if ((full & run) != run) continue;
        live &= ~(1u << z);  // deep: left inactive at -background (rasterizeSphereUnion)
        b.state[(row << 3) | z] = kInside;
        b.value[(row << 3) | z] = k.inside;
        touched = true;
      }
    }
    if (live == 0) continue;
    if ((cells.reachable(c0.x(), c0.y(), G) & cells.runBits(c0.z() - 1 - G, c0.z() + kLeafDim - 1 + G)) == 0)
      continue;  // no particle within reach of the row
    alignas(64) std::array<double, kLeafDim> best;
    std::array<std::uint32_t, kLeafDim> nearest;
    best.fill(k.max2);  // a >= (R + w)^2 changes nothing
    nearest.fill(kNone);
    auto visit = [&](std::uint32_t p) {
      const Vec3d& P = sorted.P[p];
      const double x2y2 = openvdb::math::Pow2(c0.x() - P[0]) + openvdb::math::Pow2(c0.y() - P[1]);
      const int cz = c0.z();
#pragma omp simd
      for (int z = 0; z < kLeafDim; ++z) {
        const double dz = double(cz + z) - P[2];
        const double a = x2y2 + dz * dz;
        const bool closer = a < best[z];
        best[z] = closer ? a : best[z];
        nearest[z] = closer ? p : nearest[z];
      }
    };
    for (int z = 0; z < kLeafDim; ++z)
      if (hint[z] != kNone) visit(hint[z]);
    auto bound = [&] {
      double m = 0.0;
      for (int z = 0; z < kLeafDim; ++z)
        if (live & (1u << z)) m = std::max(m, best[z]);
      return m;
    };
    double rowBound = bound();
    int rangeGap2 = -1, zLo = 0, zHi = -1;  // the z-range below, for columns of gap rangeGap2
    for (const Column& col : columns) {
      if (double(col.gap2) > rowBound + kSlack) break;
      if (col.gap2 != rangeGap2) {
        // The cells along z some lane can still reach from a column of this gap: lane z those
        // within K_z of it, K_z^2 <= its bound less the gap. Kept while the bounds hold.
        rangeGap2 = col.gap2;
        zLo = std::numeric_limits<int>::max(), zHi = std::numeric_limits<int>::min();
        for (int z = 0; z < kLeafDim; ++z) {
          if (!(live & (1u << z)) || double(col.gap2) > best[z] + kSlack) continue;
          const int K = std::min(G, isqrt(int(best[z] + kSlack) - col.gap2));
          zLo = std::min(zLo, c0.z() + z - 1 - K);
          zHi = std::max(zHi, c0.z() + z + K);
        }
      }
      if (zLo > zHi) continue;
      bool any = false;
      cells.forEachRange(c0.x() + col.ox, c0.y() + col.oy, zLo, zHi, [&](std::uint32_t from, std::uint32_t to) {
        for (std::uint32_t p = from; p < to; ++p) visit(p);
        any = true;
      });
      if (any) {
        rowBound = bound();
        rangeGap2 = -1;  // the bounds fell: narrow the range again
      }
    }
    for (int z = 0; z < kLeafDim; ++z) {
      if (nearest[z] != kNone) hint[z] = nearest[z];
      const int i = (row << 3) | z;
      if (!(live & (1u << z)) || nearest[z] == kNone) continue;  // deep, or no particle within R + w
      if (best[z] <= k.min2) {
        b.state[i] = kInside;
        b.value[i] = k.inside;
        touched = true;
        continue;
      }
      const float d = static_cast<float>(k.dx * (std::sqrt(best[z]) - k.R));
      if (d < b.value[i]) {
        b.value[i] = d;
        b.state[i] = kActive;
        touched = true;
      }
    }
  }
  if (!touched) return nullptr;
  auto leaf = std::make_unique<Leaf>(origin, k.background, /*active=*/false);
  for (int i = 0; i < 512; ++i) {
    if (b.state[i] == kActive) leaf->setValueOn(openvdb::Index(i), b.value[i]);
    else if (b.state[i] == kInside) leaf->setValueOff(openvdb::Index(i), k.inside);
  }
  return leaf;
}

}  // namespace

void rasterizeSphereUnion(openvdb::FloatGrid& grid, const std::vector<Vec3d>& positions, double radius,
                          int deepMargin) {
  if (!grid.hasUniformVoxels()) throw std::invalid_argument("rasterizeSphereUnion: the grid's voxels are not uniform");
  if (!grid.tree().empty()) throw std::invalid_argument("rasterizeSphereUnion: the grid is not empty");
  SphereConstants k;
  k.dx = grid.voxelSize()[0];
  k.background = grid.background();
  k.inside = -k.background;
  const double w = k.background / k.dx;  // ParticlesToLevelSet: mHalfWidth = background / mDx
  k.R = radius / k.dx;
  k.max = k.R + w;
  k.max2 = openvdb::math::Pow2(k.max);
  k.min2 = openvdb::math::Pow2(std::max(0.0, k.R - w));
  if (!(k.R > 0.0) || !(w > 0.0) || !(k.max < 7.0))
    throw std::invalid_argument("rasterizeSphereUnion: radius " + std::to_string(k.R) + " and half width " +
                                std::to_string(w) + " voxels must be positive and add up to less than 7");
  if (deepMargin > kMaxDeepMargin)
    throw std::invalid_argument("rasterizeSphereUnion: deep margin " + std::to_string(deepMargin) +
                                " voxels is above the largest supported, " + std::to_string(kMaxDeepMargin));
  if (positions.empty()) return;
  const ParticlesByLeaf sorted = sortByLeaf(grid.transform(), positions);
  const std::vector<Coord> targets = targetLeaves(sorted);
  const int G = int(std::ceil(k.max)) - 1;  // the largest whole-voxel gap g with g^2 < (R + w)^2
  const std::vector<Column> columns = columnsByGap(G);
  std::vector<std::unique_ptr<Leaf>> leaves(targets.size());
#pragma omp parallel for schedule(dynamic, 16)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(targets.size()); ++t)
    leaves[t] = rasterLeaf(k, sorted, targets[t], G, deepMargin, columns);
  for (auto& leaf : leaves)
    if (leaf) grid.tree().addLeaf(leaf.release());
  openvdb::tools::pruneLevelSet(grid.tree());  // ParticlesToLevelSet::finalize(/*prune=*/true)
}

}  // namespace geometry
}  // namespace stokes::sim
