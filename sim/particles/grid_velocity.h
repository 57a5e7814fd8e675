#pragma once
// Reading a staggered face velocity at arbitrary points, and extending it past the faces that hold
// data (thesis Algorithm 1: G2P and advection read velocities near the liquid surface).
//
// Face channel a lives on the lower face normal to a of every cell (channel-major arrays of
// Dim * layout.numSlots() doubles, sparse_grid/stagger.h). In cell units the face of cell i sits at
//     g = (x - origin) / dx - s_a,     s_a[b] = 0 (b == a), 1/2 (b != a),
// i.e. at the integer point g = i of the "channel-a lattice". Every interpolation below is written
// on that lattice, so one code path serves every axis and both dimensions.
//
// Neighbouring cells are reached in O(1) through the layout's neighbour-block table (offsetSlot),
// never through a ValueAccessor; a point costs at most one slotOf (for the cell that holds it).
#include "sparse_grid/vdb_trees.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "solver/krylov/aligned_vector.h"
#include "sparse_grid/block_layout.h"
#include "sparse_grid/stagger.h"

namespace stokes::sim {
inline namespace particles {

using openvdb::Coord;
using openvdb::Vec3d;

/// Slot of the cell at `offset` from the cell of `slot` (|offset[a]| <= 8, so the cell lies in the
/// block or one of its 3^Dim - 1 neighbours), or -1 if that block is absent. O(1): neighbourSlot
/// generalised to any offset in one step (chaining unit steps could pass through an absent block).
template <int Dim>
std::int64_t offsetSlot(const sparse_grid::BlockLayout<Dim>& layout, std::size_t slot, const Coord& offset) {
  using Layout = sparse_grid::BlockLayout<Dim>;
  const std::size_t b = slot / Layout::kSlots;
  Coord l = Layout::localCoord(int(slot % Layout::kSlots));
  int code = 0, pow3 = 1;
  for (int a = 0; a < Dim; ++a, pow3 *= 3) {
    l[a] += offset[a];
    int off = 0;
    if (l[a] < 0) { off = -1; l[a] += Layout::kWidth; }
    else if (l[a] >= Layout::kWidth) { off = 1; l[a] -= Layout::kWidth; }
    code += (off + 1) * pow3;
  }
  const std::int32_t nb = layout.neighbourBlock(b, code);
  if (nb < 0) return -1;
  return std::int64_t(nb) * Layout::kSlots + Layout::localSlot(l.x(), l.y(), l.z());
}

/// Index of the cell that holds world position x: floor((x - origin) / dx) per axis (z = 0 in 2D).
/// Every transfer uses this same expression, so a particle's cell and its weights agree bit for bit.
template <int Dim>
Coord cellOfPosition(const sparse_grid::BlockLayout<Dim>& layout, const Vec3d& x) {
  const double invDx = 1.0 / layout.dx();
  Coord k(0, 0, 0);
  for (int a = 0; a < Dim; ++a) k[a] = int(std::floor((x[a] - layout.origin()[a]) * invDx));
  return k;
}

/// The cell holding a point and its slot: slots of nearby cells in O(1). If the cell itself is
/// outside the layout (slot -1), nearby cells fall back to slotOf (slower, still thread-safe).
template <int Dim>
struct CellAnchor {
  const sparse_grid::BlockLayout<Dim>* layout;
  Coord cell;
  std::int64_t slot;

  Coord local;  ///< the cell's coordinates in its block

  CellAnchor(const sparse_grid::BlockLayout<Dim>& l, const Coord& c)
      : layout(&l), cell(c), slot(l.slotOf(c)), local(c - sparse_grid::BlockLayout<Dim>::blockOriginOf(c)) {}
  std::int64_t slotAt(const Coord& offset) const {
    using Layout = sparse_grid::BlockLayout<Dim>;
    if (slot < 0) return layout->slotOf(cell + offset);
    bool inBlock = true;
    for (int a = 0; a < Dim; ++a) inBlock = inBlock && unsigned(local[a] + offset[a]) < unsigned(Layout::kWidth);
    if (inBlock) {  // localSlot is linear in the coordinates: the last axis 1, the others by kWidth
      std::int64_t delta = 0;
      for (int a = 0; a < Dim; ++a) delta = delta * Layout::kWidth + offset[a];
      return slot + delta;
    }
    return offsetSlot<Dim>(*layout, std::size_t(slot), offset);
  }
};

/// Position of x on the channel-a lattice, in cell units: g_b = (x_b - o_b)/dx - (b == a ? 0 : 1/2).
template <int Dim>
Vec3d faceLatticePosition(const sparse_grid::BlockLayout<Dim>& layout, const Vec3d& x, int a) {
  const double invDx = 1.0 / layout.dx();
  Vec3d g(0.0);
  for (int b = 0; b < Dim; ++b) g[b] = (x[b] - layout.origin()[b]) * invDx - (b == a ? 0.0 : 0.5);
  return g;
}

/// The static no-slip walls of a domain box of N_a cells (cell i spans [i, i + 1) dx from the
/// layout's origin along a), as the velocity samplers see them. A lattice node beyond a wall reads
/// the odd reflection of the node mirrored across it, u_ghost = -u_mirror, so the interpolant
/// vanishes on the wall (no slip, no penetration), where the solve puts the no-slip plane
/// (StaggeredProblem::fluidStress). On the channel-a lattice the walls lie at node -1/2 and
/// N_b - 1/2 across (b != a) and on the nodes 0 and N_a along a, whose value is 0. Without it a
/// particle in the first half cell read a renormalised or absent ghost: it slipped along the wall.
/// `openTop`: no wall at +y.
struct BoxWalls {
  Coord cells{0, 0, 0};
  bool openTop = false;

  /// Moves `node` (channel-a lattice) to the node whose value it reads and returns the factor:
  /// 1 (itself), -1 (reflected across one wall, or across three), 0 (a wall node, value 0).
  template <int Dim>
  int reflect(int a, Coord& node) const {
    int sign = 1;
    for (int b = 0; b < Dim; ++b) {
      const int N = cells[b];
      const bool upper = !(b == 1 && openTop);
      if (b != a) {  // nodes at (i + 1/2) dx, walls at -1/2 and N - 1/2
        if (node[b] < 0) { node[b] = -1 - node[b]; sign = -sign; }
        else if (upper && node[b] > N - 1) { node[b] = 2 * N - 1 - node[b]; sign = -sign; }
      } else {  // nodes at i dx, walls at 0 and N
        if (node[b] < 0) { node[b] = -node[b]; sign = -sign; }
        else if (upper && node[b] > N) { node[b] = 2 * N - node[b]; sign = -sign; }
        if (node[b] == 0 || (upper && node[b] == N)) return 0;
      }
    }
    return sign;
  }

  /// Whether the interpolation stencils of a point in `cell` (reaching `margin` nodes) can reach a wall.
  template <int Dim>
  bool near(const Coord& cell, int margin) const {
    for (int b = 0; b < Dim; ++b)
      if (cell[b] < margin || (cell[b] >= cells[b] - margin && !(b == 1 && openTop))) return true;
    return false;
  }
};

/// Reads face values of one channel through the walls: value of node `cell + off` (reflected where
/// it lies beyond a wall), `slotAt(off)` giving slots near the anchor cell. Returns false where the
/// node is absent from the layout.
template <int Dim, class SlotAt>
bool readFaceNode(const solver::Vector& u, std::size_t n, int a, const Coord& cell, Coord off, const SlotAt& slotAt,
                  const BoxWalls* walls, double& value) {
  int sign = 1;
  if (walls) {
    Coord node = cell + off;
    sign = walls->reflect<Dim>(a, node);
    if (sign == 0) {
      value = 0.0;
      return true;
    }
    off = node - cell;
  }
  const std::int64_t s = slotAt(off);
  if (s < 0) return false;
  value = sign * u[a * n + std::size_t(s)];
  return true;
}

/// Throws unless `u` holds Dim channels over the layout's slots.
template <int Dim>
void checkFaceArray(const sparse_grid::BlockLayout<Dim>& layout, const solver::Vector& u, const char* who) {
  if (u.size() != Dim * layout.numSlots())
    throw std::invalid_argument(std::string(who) + ": face array has " + std::to_string(u.size()) +
                                " values, expected Dim * numSlots = " + std::to_string(Dim * layout.numSlots()));
}

/// Velocity at x: per component a, the (bi/tri)linear interpolation of channel a on its 2^Dim
/// lattice nodes  u_a(x) = sum_n prod_b (f_b or 1 - f_b) u_n,  f = g - floor(g).
/// Nodes outside the layout are skipped and the rest renormalised by the weight found (0 if none),
/// so a linear field is reproduced exactly wherever all nodes exist. With `walls`, nodes beyond a
/// wall of the box read their reflection (BoxWalls). Thread-safe; z = 0 in 2D.
template <int Dim>
Vec3d sampleFaceVelocity(const sparse_grid::BlockLayout<Dim>& layout, const solver::Vector& u, const Vec3d& x,
                         const BoxWalls* walls = nullptr) {
  const std::size_t n = layout.numSlots();
  const CellAnchor<Dim> anchor(layout, cellOfPosition<Dim>(layout, x));
  if (walls && !walls->near<Dim>(anchor.cell, 1)) walls = nullptr;
  const auto slotAt = [&](const Coord& off) { return anchor.slotAt(off); };
  Vec3d result(0.0);
  for (int a = 0; a < Dim; ++a) {
    const Vec3d g = faceLatticePosition<Dim>(layout, x, a);
    Coord base(0, 0, 0);
    Vec3d f(0.0);
    for (int b = 0; b < Dim; ++b) {
      const double fl = std::floor(g[b]);
      base[b] = int(fl) - anchor.cell[b];  // in {-1, 0} relative to the holding cell
      f[b] = g[b] - fl;
    }
    double sum = 0.0, weight = 0.0;
    for (int corner = 0; corner < (1 << Dim); ++corner) {
      Coord off = base;
      double w = 1.0;
      for (int b = 0; b < Dim; ++b) {
        const int bit = (corner >> b) & 1;
        off[b] += bit;
        w *= bit ? f[b] : 1.0 - f[b];
      }
      double value = 0.0;
      if (!readFaceNode<Dim>(u, n, a, anchor.cell, off, slotAt, walls, value)) continue;
      sum += w * value;
      weight += w;
    }
    result[a] = weight > 0.0 ? sum / weight : 0.0;
  }
  return result;
}

/// Extends a face velocity from the faces marked `known` (Dim channels, 0/1) by `layers` layers:
/// in each layer every unknown face with at least one known face neighbour of the same channel
/// (the 2 Dim faces one cell away along each axis) takes their mean and becomes known. A layer
/// reads only faces known before it and writes only faces unknown before it, so it runs in place,
/// in parallel, with a result independent of the thread count. A constant field is extended
/// exactly. Returns the number of faces filled.
template <int Dim>
std::size_t extrapolateFaceVelocities(const sparse_grid::BlockLayout<Dim>& layout, solver::Vector& u,
                                      std::vector<std::uint8_t>& known, int layers) {
  checkFaceArray<Dim>(layout, u, "extrapolateFaceVelocities");
  const std::size_t n = layout.numSlots();
  if (known.size() != Dim * n) throw std::invalid_argument("extrapolateFaceVelocities: known has the wrong size");
  using Layout = sparse_grid::BlockLayout<Dim>;
  constexpr int kShift[3] = {(Dim - 1) * Layout::kLog2Width, (Dim - 2) * Layout::kLog2Width, 0};  // axis b's bit offset in a local slot
  std::vector<std::uint8_t> next(known);
  std::size_t filled = 0;
  for (int layer = 0; layer < layers; ++layer) {
    std::size_t filledThisLayer = 0;
    const std::ptrdiff_t m = std::ptrdiff_t(Dim * n);
#pragma omp parallel for schedule(static) reduction(+ : filledThisLayer)
    for (std::ptrdiff_t i = 0; i < m; ++i) {
      if (known[i]) continue;
      const std::size_t channel = std::size_t(i) / n, s = std::size_t(i) % n;
      const int local = int(s % Layout::kSlots);
      double sum = 0.0;
      int count = 0;
      for (int b = 0; b < Dim; ++b)
        for (int dir = -1; dir <= 1; dir += 2) {
          // inside the block the neighbour is the slot kStride[b] away (localSlot: the last axis
          // contiguous); across a block face the neighbour table decides
          const int l = (local >> kShift[b]) & (Layout::kWidth - 1);
          const std::int64_t t = unsigned(l + dir) < unsigned(Layout::kWidth)
                                     ? std::int64_t(s) + dir * (std::int64_t(1) << kShift[b])
                                     : layout.neighbourSlot(s, b, dir);
          if (t < 0 || !known[channel * n + std::size_t(t)]) continue;
          sum += u[channel * n + std::size_t(t)];
          ++count;
        }
      if (count == 0) continue;
      u[i] = sum / count;  // mean of the known neighbours
      next[i] = 1;
      ++filledThisLayer;
    }
    known = next;
    filled += filledThisLayer;
    if (filledThisLayer == 0) break;
  }
  return filled;
}

}  // namespace particles
}  // namespace stokes::sim
