#pragma once
// The particle set of the simulator (thesis Algorithm 1) and its binning by grid cell.
//
// Each particle p carries a position x_p, a velocity v_p and, for APIC (Jiang et al. 2015, thesis
// 3.4.1), one affine vector per velocity component: c[a] such that near x_p
//     u_a(x) ~ v_a + c[a] . (x - x_p).
// Equivalently C_ab = c[a][b] is the particle's velocity gradient estimate. All particles have the
// same mass (1); the transfers are written in momentum form so that a different uniform mass
// cancels. In 2D positions, velocities and c[a] have z = 0.
//
// binParticles() is a stable counting sort of the particles by the slot of the cell that holds
// them: the particles of one cell are listed in increasing index, so every gather over a cell's
// particles sums in an order that does not depend on the thread count.
#include "sparse_grid/vdb_trees.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <vector>

#include "sim/particles/grid_velocity.h"
#include "sparse_grid/block_layout.h"
#include "sparse_grid/bucket_sort.h"

namespace stokes::sim {
inline namespace particles {

using openvdb::Coord;
using openvdb::Vec3d;

template <int Dim>
struct ParticleSet {
  static_assert(Dim == 2 || Dim == 3, "StokesVDB supports 2D and 3D");
  using Affine = std::array<Vec3d, Dim>;  ///< c[a]: affine vector of velocity component a

  std::vector<Vec3d> x;   ///< positions (world)
  std::vector<Vec3d> v;   ///< velocities
  std::vector<Affine> c;  ///< APIC affine vectors

  static Affine zeroAffine() {
    Affine z;
    z.fill(Vec3d(0.0));
    return z;
  }

  std::size_t size() const { return x.size(); }
  bool empty() const { return x.empty(); }
  void resize(std::size_t n) {
    x.resize(n, Vec3d(0.0));
    v.resize(n, Vec3d(0.0));
    c.resize(n, zeroAffine());
  }
  void reserve(std::size_t n) {
    x.reserve(n);
    v.reserve(n);
    c.reserve(n);
  }
  void clear() { resize(0); }

  void push_back(const Vec3d& position, const Vec3d& velocity, const Affine& affine = zeroAffine()) {
    x.push_back(position);
    v.push_back(velocity);
    c.push_back(affine);
  }
  void append(const ParticleSet& other) {
    x.insert(x.end(), other.x.begin(), other.x.end());
    v.insert(v.end(), other.v.begin(), other.v.end());
    c.insert(c.end(), other.c.begin(), other.c.end());
  }

  /// Removes every particle p with remove[p] != 0 (remove.size() == size()), keeping the order of
  /// the others. Returns the number removed.
  std::size_t eraseMasked(const std::vector<std::uint8_t>& remove) {
    if (remove.size() != size()) throw std::invalid_argument("ParticleSet::eraseMasked: mask size mismatch");
    std::size_t kept = 0;
    for (std::size_t p = 0; p < size(); ++p) {
      if (remove[p]) continue;
      x[kept] = x[p];
      v[kept] = v[p];
      c[kept] = c[p];
      ++kept;
    }
    const std::size_t removed = size() - kept;
    resize(kept);
    return removed;
  }
};

/// Particles sorted by cell slot: the particles of slot s are order[start[s] .. start[s+1]), in
/// increasing index. slot[p] is the slot of particle p, or -1 if its cell is outside the layout
/// (such particles are in no bin).
struct ParticleBins {
  std::vector<std::int64_t> slot;
  std::vector<std::size_t> start;
  std::vector<std::size_t> order;

  std::size_t count(std::size_t s) const { return start[s + 1] - start[s]; }
  std::size_t binned() const { return order.size(); }
};

/// Stable counting sort of the particles by cell slot, in parallel and in two levels: by block
/// (sparse_grid::sortByBucket over fixed chunks of the particles), then by slot inside each block
/// (a counting sort over its kSlots cells, one block per task). Both levels are stable, so every
/// slot lists its particles in increasing index: the one order a serial counting sort gives, for
/// any thread count.
template <int Dim>
ParticleBins binParticles(const sparse_grid::BlockLayout<Dim>& layout, const std::vector<Vec3d>& x) {
  constexpr std::size_t kSlots = sparse_grid::BlockLayout<Dim>::kSlots;
  ParticleBins bins;
  const std::size_t n = x.size(), nb = layout.numBlocks();
  bins.slot.resize(n);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t p = 0; p < std::ptrdiff_t(n); ++p) bins.slot[p] = layout.slotOf(cellOfPosition<Dim>(layout, x[p]));

  const auto byBlock = sparse_grid::sortByBucket<std::size_t>(n, nb, std::min<std::size_t>(64, n / 8192 + 1), [&](std::size_t p) {
    return bins.slot[p] < 0 ? std::int64_t(-1) : bins.slot[p] / std::int64_t(kSlots);
  });
  const std::vector<std::size_t>& blockStart = byBlock.start;
  const std::size_t next = blockStart[nb];

  // By slot inside each block.
  bins.start.resize(layout.numSlots() + 1);
  bins.order.resize(next);
  bins.start[layout.numSlots()] = next;
#pragma omp parallel for schedule(dynamic, 16)
  for (std::ptrdiff_t blk = 0; blk < std::ptrdiff_t(nb); ++blk) {
    std::array<std::size_t, kSlots> at{};
    for (std::size_t j = blockStart[blk]; j < blockStart[blk + 1]; ++j) ++at[std::size_t(bins.slot[byBlock.items[j]]) % kSlots];
    std::size_t first = blockStart[blk];
    for (std::size_t k = 0; k < kSlots; ++k) {
      bins.start[std::size_t(blk) * kSlots + k] = first;
      const std::size_t count = at[k];
      at[k] = first;
      first += count;
    }
    for (std::size_t j = blockStart[blk]; j < blockStart[blk + 1]; ++j) {
      const std::size_t p = byBlock.items[j];
      bins.order[at[std::size_t(bins.slot[p]) % kSlots]++] = p;
    }
  }
  return bins;
}

}  // namespace particles
}  // namespace stokes::sim
