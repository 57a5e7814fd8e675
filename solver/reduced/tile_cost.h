#pragma once
// Which tiles pay (docs/design.md §3.8, "Which tiles are kept"): a tile replaces the Cartesian
// rows of its region by m polynomial DOFs, and costs the velocity cycle its couplings. Per Krylov
// iteration of the pressure-velocity MINRES with the Galerkin velocity cycle, in units of one
// Cartesian row's work:
//
//   saved(t)    = faces(t) + cells(t)      (its face rows and its cells' pressure rows)
//   overhead(t) = kShellCost * shell(t)
//
// shell(t): the faces between a tile cell and a Cartesian one. The couplings reach one or two
// cells past them, so the Cartesian rows next to the tile grow denser, and on the coarse levels the
// tile's rows couple densely to every coarse face near it. kShellCost was fitted by least squares
// to the time per iteration of the analytic ball (n = 96, cube tiles 12 to 48) and disk (N = 512,
// tiles 8 to 64) against the uniform Galerkin cycle: 8.0 and 9.3 row-equivalents per shell face; a
// term per tile DOF fitted to 1 or less. A full cube tile w cells wide pays from w = 13 in 3D
// (4 w^3 + 3 w^2 against 54 w^2) and w = 12 in 2D (3 w^2 + 2 w against 36 w). The estimate
// leaves out how tiles change the iteration count (the slabs between tiles raise it) and the
// cheaper padded cycle a step without tiles may run: it is what a tile must at least fold, not a
// prediction of the speed-up.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "sparse_grid/tiling.h"

namespace stokes::solver {
inline namespace reduced {

/// Row-equivalents of work per iteration per shell face (see the file comment).
inline constexpr double kShellCost = 9.0;

struct TileWork {
  std::size_t cells = 0;   ///< the tile's cells (pressure rows it folds)
  std::size_t faces = 0;   ///< its faces (velocity rows it folds), each counted once
  std::size_t shell = 0;   ///< faces between one of its cells and a cell of no tile
  double saved() const { return double(faces + cells); }
  double overhead() const { return kShellCost * double(shell); }
  bool pays() const { return saved() > overhead(); }
};

/// TileWork summed over tiles.
struct TileWorkTotals {
  double saved = 0.0, overhead = 0.0;
  void add(const TileWork& w) {
    saved += w.saved();
    overhead += w.overhead();
  }
};

/// All: every tile the tiling makes. Paying: the tiles whose saved() exceeds their overhead().
enum class TileRule { All, Paying };

/// The counts of TileWork for tile `t` of `tiling` (cells outside the layout count as Cartesian).
template <int Dim>
TileWork tileWork(const sparse_grid::BlockLayout<Dim>& layout, const sparse_grid::Tiling<Dim>& tiling, std::size_t t) {
  TileWork w;
  const auto inTile = [&](std::int64_t slot) { return slot >= 0 && tiling.tileOfCell[std::size_t(slot)] == std::int32_t(t); };
  for (std::size_t s : tiling.tiles[t].cells) {
    ++w.cells;
    for (int a = 0; a < Dim; ++a) {
      const bool below = inTile(layout.neighbourSlot(s, a, -1)), above = inTile(layout.neighbourSlot(s, a, +1));
      w.faces += above ? 1 : 2;  // its lower face, and its upper one unless the next cell owns it
      w.shell += std::size_t(!below) + std::size_t(!above);
    }
  }
  return w;
}

}  // namespace reduced
}  // namespace stokes::solver
