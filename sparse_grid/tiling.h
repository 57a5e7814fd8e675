#pragma once
// Cell labels and interior tiles (thesis 4.5.1-4.5.2, docs/design.md §3).
//
//  1. Every fully liquid, fully non-solid cell is a reduced candidate.
//  2. A band of `bandAir` cells next to air and (separately) `bandSolid` cells next to solids is
//     peeled back to Cartesian (Chebyshev distance, i.e. 8-neighbour in 2D, 26-neighbour in 3D).
//  3. Slabs: a cell is Cartesian if for ANY axis a, floormod(i_a, tileSize) < padding (the thesis'
//     Eq. 4.26 prints AND; slabs need OR).
//  4. The remaining reduced cells are flood-filled (face neighbours) into regions; a region whose
//     bounding box is narrower than `minRegion` cells along some axis goes back to Cartesian.
// Regions need not be convex or simply connected.
#include <algorithm>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "sparse_grid/block_layout.h"

namespace stokes::sparse_grid {

struct TilingOptions {
  int tileSize = 16;
  int padding = 3;
  int bandAir = 2;
  int bandSolid = 2;
  int minRegion = 2;

  void validate() const {
    if (tileSize < 2) throw std::invalid_argument("tiling: --tile must be >= 2");
    if (padding < 1) throw std::invalid_argument("tiling: --pad must be >= 1");
    if (padding >= tileSize) throw std::invalid_argument("tiling: --pad must be smaller than --tile");
    if (bandAir < 0 || bandSolid < 0) throw std::invalid_argument("tiling: bands must be >= 0");
    if (minRegion < 1) throw std::invalid_argument("tiling: --min-region must be >= 1");
  }
};

struct Tile {
  std::vector<std::size_t> cells;  ///< slots of the tile's cells, ascending
  Coord bboxMin, bboxMax;          ///< inclusive cell-index bounds
  /// Centre of mass of the cell centres, in cells from the corner of bboxMin (its lower face
  /// corner): computed from the integer offsets only, so that two tiles of one shape get the same
  /// bits wherever they sit (the tile library shares their blocks).
  Vec3d centreInCells{0.0};
  double halfWidthInCells = 0.0;   ///< half the largest bounding-box extent, the basis scale h / dx
  bool isFullBox = false;          ///< every cell of the bounding box belongs to the tile
};

template <int Dim>
struct Tiling {
  std::vector<std::int32_t> tileOfCell;  ///< per slot: tile index, or -1 for Cartesian
  std::vector<Tile> tiles;
  std::size_t culledRegions = 0;         ///< regions returned to Cartesian for being too small
};

namespace detail {
// floor(i / m) * m remainder in [0, m)
inline int floorMod(int i, int m) { return ((i % m) + m) % m; }

/// Marks every slot within Chebyshev distance `band` of a seed slot. A 3^Dim box dilation is the
/// composition of one-cell dilations along each axis. Missing neighbours (outside the layout)
/// count as seeds: the unknown region beyond the layout is never reduced.
template <int Dim>
std::vector<std::uint8_t> dilate(const BlockLayout<Dim>& layout, std::vector<std::uint8_t> seed, int band) {
  const std::ptrdiff_t n = std::ptrdiff_t(layout.numSlots());
  std::vector<std::uint8_t> next(seed.size());
  for (int pass = 0; pass < band; ++pass)
    for (int a = 0; a < Dim; ++a) {
#pragma omp parallel for schedule(static)
      for (std::ptrdiff_t s = 0; s < n; ++s) {
        bool hit = seed[s] != 0;
        for (int dir : {-1, 1}) {
          const std::int64_t nb = layout.neighbourSlot(std::size_t(s), a, dir);
          hit = hit || nb < 0 || seed[nb];
        }
        next[s] = hit ? 1 : 0;
      }
      seed.swap(next);
    }
  return seed;
}
}  // namespace detail

/// Builds the tiling. `liquidFull[s]` / `fluidFull[s]` say whether the cell of slot s is entirely
/// liquid / entirely outside solids (e.g. W_L^p == 1, W_F at the cell centre == 1).
template <int Dim>
Tiling<Dim> buildTiling(const BlockLayout<Dim>& layout, const std::vector<std::uint8_t>& liquidFull,
                        const std::vector<std::uint8_t>& fluidFull, const TilingOptions& opt) {
  opt.validate();
  const std::size_t n = layout.numSlots();
  std::vector<std::uint8_t> air(n), solid(n);
  for (std::size_t s = 0; s < n; ++s) {
    air[s] = !layout.isActiveCell(s) || !liquidFull[s];
    solid[s] = layout.isActiveCell(s) && !fluidFull[s];
  }
  const std::vector<std::uint8_t> nearAir = detail::dilate(layout, air, opt.bandAir);
  const std::vector<std::uint8_t> nearSolid = detail::dilate(layout, solid, opt.bandSolid);

  std::vector<std::uint8_t> candidate(n, 0);
  for (std::size_t s = 0; s < n; ++s) {
    if (nearAir[s] || nearSolid[s] || solid[s]) continue;
    const Coord c = layout.cellOf(s);
    bool slab = false;
    for (int a = 0; a < Dim; ++a) slab = slab || detail::floorMod(c[a], opt.tileSize) < opt.padding;
    candidate[s] = slab ? 0 : 1;
  }

  Tiling<Dim> tiling;
  tiling.tileOfCell.assign(n, -1);
  std::vector<std::size_t> stack;
  for (std::size_t seed = 0; seed < n; ++seed) {
    if (!candidate[seed] || tiling.tileOfCell[seed] != -1) continue;
    // flood fill one region through face neighbours
    Tile tile;
    const std::int32_t id = std::int32_t(tiling.tiles.size());
    stack.assign(1, seed);
    tiling.tileOfCell[seed] = id;
    while (!stack.empty()) {
      const std::size_t s = stack.back();
      stack.pop_back();
      tile.cells.push_back(s);
      for (int a = 0; a < Dim; ++a)
        for (int dir : {-1, 1}) {
          const std::int64_t nb = layout.neighbourSlot(s, a, dir);
          if (nb < 0 || !candidate[nb] || tiling.tileOfCell[nb] != -1) continue;
          tiling.tileOfCell[nb] = id;
          stack.push_back(std::size_t(nb));
        }
    }
    std::sort(tile.cells.begin(), tile.cells.end());
    Coord lo(std::numeric_limits<int>::max()), hi(std::numeric_limits<int>::min());
    for (std::size_t s : tile.cells) {
      const Coord c = layout.cellOf(s);
      lo = Coord::minComponent(lo, c);
      hi = Coord::maxComponent(hi, c);
    }
    std::int64_t sum[3] = {0, 0, 0};  // exact: offsets from lo
    for (std::size_t s : tile.cells) {
      const Coord c = layout.cellOf(s);
      for (int a = 0; a < 3; ++a) sum[a] += c[a] - lo[a];
    }
    tile.bboxMin = lo;
    tile.bboxMax = hi;
    const double count = double(tile.cells.size());
    for (int a = 0; a < Dim; ++a) tile.centreInCells[a] = (double(sum[a]) + 0.5 * count) / count;
    bool tooSmall = false;
    std::size_t boxCells = 1;
    int maxExtent = 0;
    for (int a = 0; a < Dim; ++a) {
      const int extent = hi[a] - lo[a] + 1;
      tooSmall = tooSmall || extent < opt.minRegion;
      boxCells *= std::size_t(extent);
      maxExtent = std::max(maxExtent, extent);
    }
    tile.halfWidthInCells = 0.5 * maxExtent;
    tile.isFullBox = boxCells == tile.cells.size();
    if (tooSmall) {
      for (std::size_t s : tile.cells) tiling.tileOfCell[s] = -2;  // culled: never a seed again
      ++tiling.culledRegions;
      continue;
    }
    tiling.tiles.push_back(std::move(tile));
  }
  for (auto& t : tiling.tileOfCell)
    if (t == -2) t = -1;
  return tiling;
}

}  // namespace stokes::sparse_grid
