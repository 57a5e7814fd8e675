#pragma once
// Cell labels and interior tiles (thesis 4.5.1-4.5.2, docs/design.md §3).
//
//  1. Every fully liquid, fully non-solid cell is a reduced candidate.
//  2. A band of `bandAir` cells next to air and (separately) `bandSolid` cells next to solids is
//     peeled back to Cartesian (Chebyshev distance, i.e. 8-neighbour in 2D, 26-neighbour in 3D).
//  3. Slabs: a cell is Cartesian if for ANY axis a, floormod(i_a, e) < padding (the thesis'
//     Eq. 4.26 prints AND; slabs need OR), e the edge of the cube holding the cell: tileSize, or,
//     with minTileSize, an octree edge tileSize / 2^k >= minTileSize. A cube splits where the
//     caller's RefineRegion asks (the reduced tiles ask where a polynomial misses the velocity:
//     the thesis' Chapter 6 adaptivity).
//  4. The remaining reduced cells are flood-filled (face neighbours) into regions; a region whose
//     bounding box is narrower than `minRegion` cells along some axis goes back to Cartesian.
// Regions need not be convex or simply connected.
#include <algorithm>
#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "sparse_grid/block_layout.h"

namespace stokes::sparse_grid {

struct TilingOptions {
  int tileSize = 16;     ///< edge of the tile cubes; with minTileSize, of the largest
  int minTileSize = 0;   ///< 0: one edge; else cubes split (octree) down to this edge where asked
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
    if (minTileSize == 0) return;
    if (minTileSize <= padding || minTileSize > tileSize)
      throw std::invalid_argument("tiling: --tile-min " + std::to_string(minTileSize) + " must lie in (--pad, --tile] = (" +
                                  std::to_string(padding) + ", " + std::to_string(tileSize) + "]");
    int e = tileSize;
    while (e > minTileSize && e % 2 == 0) e /= 2;
    if (e != minTileSize)
      throw std::invalid_argument("tiling: --tile " + std::to_string(tileSize) + " must be --tile-min " +
                                  std::to_string(minTileSize) + " times a power of two (cubes split in halves)");
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
  int cubeEdge = 0;                ///< edge of the cube it lies in (TilingOptions: tileSize or an octree edge)
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

/// A region's tile: its cells (sorted) with their bounding box, centre and scale.
template <int Dim>
Tile describeRegion(const BlockLayout<Dim>& layout, std::vector<std::size_t> cells) {
  Tile tile;
  tile.cells = std::move(cells);
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
  std::size_t boxCells = 1;
  int maxExtent = 0;
  for (int a = 0; a < Dim; ++a) {
    const int extent = hi[a] - lo[a] + 1;
    boxCells *= std::size_t(extent);
    maxExtent = std::max(maxExtent, extent);
  }
  tile.halfWidthInCells = 0.5 * maxExtent;
  tile.isFullBox = boxCells == tile.cells.size();
  return tile;
}

/// Asks whether the cube of edge `edge` that holds `region` (one flood-filled region of the cube's
/// cells outside its slabs, as a Tile) should split into 2^Dim cubes of edge / 2.
using RefineRegion = std::function<bool(const Tile& region, int edge)>;

namespace detail {
// The reduced candidates: cells outside `excluded` and outside the slabs of their cube, whose edge
// is edge[s] (rule 3 per cube; a cube's slabs sit on its lower sides, so every boundary between
// two cubes of any edges is covered by the slab of the upper one).
template <int Dim>
std::vector<std::uint8_t> candidates(const BlockLayout<Dim>& layout, const std::vector<std::uint8_t>& excluded,
                                     const std::vector<int>& edge, int padding) {
  const std::size_t n = layout.numSlots();
  std::vector<std::uint8_t> candidate(n, 0);
  for (std::size_t s = 0; s < n; ++s) {
    if (excluded[s]) continue;
    const Coord c = layout.cellOf(s);
    bool slab = false;
    for (int a = 0; a < Dim; ++a) slab = slab || floorMod(c[a], edge[s]) < padding;
    candidate[s] = slab ? 0 : 1;
  }
  return candidate;
}

// The candidates flood-filled through face neighbours into regions, seeded in slot order.
template <int Dim>
std::vector<std::vector<std::size_t>> floodRegions(const BlockLayout<Dim>& layout, const std::vector<std::uint8_t>& candidate) {
  std::vector<std::vector<std::size_t>> regions;
  std::vector<std::uint8_t> seen(candidate.size(), 0);
  std::vector<std::size_t> stack;
  for (std::size_t seed = 0; seed < candidate.size(); ++seed) {
    if (!candidate[seed] || seen[seed]) continue;
    std::vector<std::size_t> cells;
    stack.assign(1, seed);
    seen[seed] = 1;
    while (!stack.empty()) {
      const std::size_t s = stack.back();
      stack.pop_back();
      cells.push_back(s);
      for (int a = 0; a < Dim; ++a)
        for (int dir : {-1, 1}) {
          const std::int64_t nb = layout.neighbourSlot(s, a, dir);
          if (nb < 0 || !candidate[nb] || seen[nb]) continue;
          seen[nb] = 1;
          stack.push_back(std::size_t(nb));
        }
    }
    regions.push_back(std::move(cells));
  }
  return regions;
}

// The corner of the cube of edge e holding cell c.
inline Coord cubeCorner(const Coord& c, int e) {
  return Coord(c[0] - floorMod(c[0], e), c[1] - floorMod(c[1], e), c[2] - floorMod(c[2], e));
}

// Octree refinement: every cube of edge L > minTileSize whose region asks to
// split, as `refine` says, passes edge L / 2 to all its cells; level by level from tileSize down.
template <int Dim>
std::vector<int> cubeEdges(const BlockLayout<Dim>& layout, const std::vector<std::uint8_t>& excluded,
                           const TilingOptions& opt, const RefineRegion& refine) {
  std::vector<int> edge(layout.numSlots(), opt.tileSize);
  if (!refine || opt.minTileSize == 0) return edge;
  for (int L = opt.tileSize; L > opt.minTileSize; L /= 2) {
    std::vector<std::vector<std::size_t>> regions = floodRegions(layout, candidates(layout, excluded, edge, opt.padding));
    std::erase_if(regions, [&](const std::vector<std::size_t>& r) { return edge[r.front()] != L; });
    std::vector<std::uint8_t> split(regions.size(), 0);
#pragma omp parallel for schedule(dynamic, 1)
    for (std::ptrdiff_t r = 0; r < std::ptrdiff_t(regions.size()); ++r)
      split[r] = refine(describeRegion(layout, regions[r]), L) ? 1 : 0;
    std::vector<std::array<int, 3>> corners;
    for (std::size_t r = 0; r < regions.size(); ++r)
      if (split[r]) {
        const Coord k = cubeCorner(layout.cellOf(regions[r].front()), L);
        corners.push_back({k[0], k[1], k[2]});
      }
    if (corners.empty()) break;
    std::sort(corners.begin(), corners.end());
    for (std::size_t s = 0; s < edge.size(); ++s) {
      if (edge[s] != L) continue;
      const Coord k = cubeCorner(layout.cellOf(s), L);
      if (std::binary_search(corners.begin(), corners.end(), std::array<int, 3>{k[0], k[1], k[2]})) edge[s] = L / 2;
    }
  }
  return edge;
}
}  // namespace detail

/// Builds the tiling. `liquidFull[s]` / `fluidFull[s]` say whether the cell of slot s is entirely
/// liquid / entirely outside solids (e.g. W_L^p == 1, W_F at the cell centre == 1). With
/// opt.minTileSize > 0, `refine` chooses the cube edges (octree, detail::cubeEdges); without, every
/// cube has edge opt.tileSize.
template <int Dim>
Tiling<Dim> buildTiling(const BlockLayout<Dim>& layout, const std::vector<std::uint8_t>& liquidFull,
                        const std::vector<std::uint8_t>& fluidFull, const TilingOptions& opt,
                        const RefineRegion& refine = {}) {
  opt.validate();
  const std::size_t n = layout.numSlots();
  std::vector<std::uint8_t> air(n), solid(n);
  for (std::size_t s = 0; s < n; ++s) {
    air[s] = !layout.isActiveCell(s) || !liquidFull[s];
    solid[s] = layout.isActiveCell(s) && !fluidFull[s];
  }
  const std::vector<std::uint8_t> nearAir = detail::dilate(layout, air, opt.bandAir);
  const std::vector<std::uint8_t> nearSolid = detail::dilate(layout, solid, opt.bandSolid);
  std::vector<std::uint8_t> excluded(n);
  for (std::size_t s = 0; s < n; ++s) excluded[s] = nearAir[s] || nearSolid[s] || solid[s];
  const std::vector<int> edge = detail::cubeEdges(layout, excluded, opt, refine);

  Tiling<Dim> tiling;
  tiling.tileOfCell.assign(n, -1);
  for (std::vector<std::size_t>& cells : detail::floodRegions(layout, detail::candidates(layout, excluded, edge, opt.padding))) {
    Tile tile = describeRegion(layout, std::move(cells));
    tile.cubeEdge = edge[tile.cells.front()];
    bool tooSmall = false;
    for (int a = 0; a < Dim; ++a) tooSmall = tooSmall || tile.bboxMax[a] - tile.bboxMin[a] + 1 < opt.minRegion;
    if (tooSmall) {
      ++tiling.culledRegions;
      continue;
    }
    for (std::size_t s : tile.cells) tiling.tileOfCell[s] = std::int32_t(tiling.tiles.size());
    tiling.tiles.push_back(std::move(tile));
  }
  return tiling;
}

}  // namespace stokes::sparse_grid
