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

namespace stokes::sim::inline geometry {

namespace {

using openvdb::Coord;
using openvdb::Vec3d;
using Leaf = openvdb::FloatTree::LeafNodeType;

constexpr int kLeafDim = 8, kBrickDim = 4, kBricksPerAxis = kLeafDim / kBrickDim,
              kBricks = kBricksPerAxis * kBricksPerAxis * kBricksPerAxis;

/// Corner of brick `brick` inside its leaf (bricks in x-y-z order).
Coord brickCorner(int brick) {
  return Coord((brick / (kBricksPerAxis * kBricksPerAxis)) * kBrickDim, ((brick / kBricksPerAxis) % kBricksPerAxis) * kBrickDim,
               (brick % kBricksPerAxis) * kBrickDim);
}
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

/// makeSphere's update of voxel c (global index coordinates) by the particle at P (index space).
inline void updateVoxel(const SphereConstants& k, const Vec3d& P, const Coord& c, int offset, LeafBuffer& b) {
  const double x2 = openvdb::math::Pow2(c.x() - P[0]);
  const double x2y2 = x2 + openvdb::math::Pow2(c.y() - P[1]);
  const double a = x2y2 + openvdb::math::Pow2(c.z() - P[2]);
  if (a >= k.max2 || b.state[offset] == kInside) return;
  if (a <= k.min2) {
    b.state[offset] = kInside;
    b.value[offset] = k.inside;
    return;
  }
  const float d = static_cast<float>(k.dx * (std::sqrt(a) - k.R));
  if (d < b.value[offset]) {
    b.value[offset] = d;
    b.state[offset] = kActive;
  }
}

/// Visits the voxels of [lo, hi] (inclusive, clipped to the leaf at `origin`) for particle P.
inline void updateBox(const SphereConstants& k, const Vec3d& P, const Coord& origin, Coord lo, Coord hi,
                      LeafBuffer& b) {
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::max(lo[a], origin[a]);
    hi[a] = std::min(hi[a], origin[a] + kLeafDim - 1);
    if (lo[a] > hi[a]) return;
  }
  Coord c;
  for (c.x() = lo.x(); c.x() <= hi.x(); ++c.x())
    for (c.y() = lo.y(); c.y() <= hi.y(); ++c.y())
      for (c.z() = lo.z(); c.z() <= hi.z(); ++c.z()) {
        const Coord l = c - origin;
        updateVoxel(k, P, c, (l.x() << 6) | (l.y() << 3) | l.z(), b);
      }
}

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
  /// Particles of voxels [from, to] (offsets in leaf `leaf`, contiguous in the sort).
  std::pair<std::size_t, std::size_t> range(std::ptrdiff_t leaf, int from, int to) const {
    const std::uint32_t* v = voxelStart.data() + std::size_t(leaf) * 513;
    return {v[from], v[to + 1]};
  }
};

Coord floorCoord(const Vec3d& P) {
  return Coord(int(std::floor(P[0])), int(std::floor(P[1])), int(std::floor(P[2])));
}

ParticlesByLeaf sortByLeaf(const openvdb::math::Transform& xform, const std::vector<Vec3d>& positions) {
  const std::ptrdiff_t n = std::ptrdiff_t(positions.size());
  std::vector<Vec3d> P(positions.size());
  std::vector<std::pair<std::uint64_t, std::uint32_t>> order(positions.size());
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    P[i] = xform.worldToIndex(positions[i]);  // ParticlesToLevelSet: mMap.applyInverseMap(pos)
    const Coord c = floorCoord(P[i]);
    order[i] = {(leafKey(leafOriginOf(c)) << 9) | std::uint64_t(voxelOffset(c)), std::uint32_t(i)};
  }
  std::sort(order.begin(), order.end());
  ParticlesByLeaf out;
  out.P.resize(positions.size());
  std::vector<std::uint32_t> count;  // per leaf, particles per voxel
  for (std::size_t i = 0; i < order.size(); ++i) {
    out.P[i] = P[order[i].second];
    const std::uint64_t leaf = order[i].first >> 9;
    if (out.keys.empty() || out.keys.back() != leaf) {
      out.keys.push_back(leaf);
      count.resize(count.size() + 512, 0);
    }
    ++count[(out.keys.size() - 1) * 512 + (order[i].first & 511u)];
  }
  out.voxelStart.resize(out.keys.size() * 513);
  std::uint32_t next = 0;
  for (std::size_t l = 0; l < out.keys.size(); ++l) {
    std::uint32_t* v = out.voxelStart.data() + l * 513;
    for (int k = 0; k < 512; ++k) {
      v[k] = next;
      next += count[l * 512 + k];
    }
    v[512] = next;
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

/// Calls f(P) for every particle whose voxel floor(P) lies within `reach` voxels of the leaf at
/// `origin` along every axis (a particle in voxel q lies in [q, q + 1)): the only ones whose
/// spheres can reach it within that distance. Visits the 27 leaves around, row by row of voxels.
template <class F>
void forEachNearbyParticle(const ParticlesByLeaf& sorted, const Coord& origin, double reach, F&& f) {
  const int r = int(std::ceil(reach));
  const Coord lo = origin.offsetBy(-r - 1), hi = origin.offsetBy(kLeafDim - 1 + r);
  for (int lx = -1; lx <= 1; ++lx)
    for (int ly = -1; ly <= 1; ++ly)
      for (int lz = -1; lz <= 1; ++lz) {
        const Coord leafOrigin = origin + Coord(lx * kLeafDim, ly * kLeafDim, lz * kLeafDim);
        Coord a, b;  // the voxels of that leaf within the box, local coordinates
        bool empty = false;
        for (int k = 0; k < 3; ++k) {
          a[k] = std::max(lo[k], leafOrigin[k]) - leafOrigin[k];
          b[k] = std::min(hi[k], leafOrigin[k] + kLeafDim - 1) - leafOrigin[k];
          empty = empty || a[k] > b[k];
        }
        if (empty) continue;
        const std::ptrdiff_t leaf = sorted.find(leafKey(leafOrigin));
        if (leaf < 0) continue;
        for (int x = a.x(); x <= b.x(); ++x)
          for (int y = a.y(); y <= b.y(); ++y) {
            const auto [from, to] = sorted.range(leaf, (x << 6) | (y << 3) | a.z(), (x << 6) | (y << 3) | b.z());
            for (std::size_t i = from; i < to; ++i) f(sorted.P[i]);
          }
      }
}

/// Fills one leaf; returns it, or null if no voxel was touched.
std::unique_ptr<Leaf> rasterLeaf(const SphereConstants& k, const ParticlesByLeaf& sorted, const Coord& origin) {
  LeafBuffer b;
  b.value.fill(k.background);
  b.state.fill(kUntouched);
  // Phase 1, a bound: the particles within a voxel of the leaf update the 2^3 voxels around them.
  forEachNearbyParticle(sorted, origin, 1.0, [&](const Vec3d& P) {
    const Coord lo = floorCoord(P);
    updateBox(k, P, origin, lo, lo.offsetBy(1), b);
  });
  // M_b: the largest value in each brick (the background while a voxel is untouched): the final
  // values are at most these. A particle lowers a voxel of brick b only if
  // dx (|c - P| - R) < M_b, i.e. |c - P| < M_b / dx + R; the margin of 1e-3 voxels keeps the float
  // rounding of d on the safe side.
  std::array<double, kBricks> reach;
  for (int brick = 0; brick < kBricks; ++brick) {
    const Coord o = brickCorner(brick);
    float m = -std::numeric_limits<float>::max();
    for (int x = 0; x < kBrickDim; ++x)
      for (int y = 0; y < kBrickDim; ++y)
        for (int z = 0; z < kBrickDim; ++z) m = std::max(m, b.value[((o.x() + x) << 6) | ((o.y() + y) << 3) | (o.z() + z)]);
    reach[brick] = std::min(k.max, double(m) / k.dx + k.R + 1e-3);
  }
  // Phase 2: every particle of the 27 leaves around, over the voxels of each brick within reach.
  // A particle farther than the reach from a box of voxel centres along some axis is skipped.
  const double reachMax = *std::max_element(reach.begin(), reach.end());
  auto outOfReach = [](const Vec3d& P, const Coord& lo, int width, double r) {
    for (int a = 0; a < 3; ++a)
      if (lo[a] - P[a] >= r || P[a] - (lo[a] + width - 1) >= r) return true;
    return false;
  };
  forEachNearbyParticle(sorted, origin, reachMax, [&](const Vec3d& P) {
    if (outOfReach(P, origin, kLeafDim, reachMax)) return;
    for (int brick = 0; brick < kBricks; ++brick) {
      const double r = reach[brick];
      const Coord bo = origin + brickCorner(brick);
      if (r <= 0.0 || outOfReach(P, bo, kBrickDim, r)) continue;
      Coord lo(int(std::floor(P[0] - r)), int(std::floor(P[1] - r)), int(std::floor(P[2] - r)));
      Coord hi(int(std::ceil(P[0] + r)), int(std::ceil(P[1] + r)), int(std::ceil(P[2] + r)));
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::max(lo[a], bo[a]);
        hi[a] = std::min(hi[a], bo[a] + kBrickDim - 1);
      }
      updateBox(k, P, origin, lo, hi, b);
    }
  });
  bool touched = false;
  for (std::uint8_t s : b.state) touched = touched || s != kUntouched;
  if (!touched) return nullptr;
  auto leaf = std::make_unique<Leaf>(origin, k.background, /*active=*/false);
  for (int i = 0; i < 512; ++i) {
    if (b.state[i] == kActive) leaf->setValueOn(openvdb::Index(i), b.value[i]);
    else if (b.state[i] == kInside) leaf->setValueOff(openvdb::Index(i), k.inside);
  }
  return leaf;
}

}  // namespace

void rasterizeSphereUnion(openvdb::FloatGrid& grid, const std::vector<Vec3d>& positions, double radius) {
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
  if (positions.empty()) return;
  const ParticlesByLeaf sorted = sortByLeaf(grid.transform(), positions);
  const std::vector<Coord> targets = targetLeaves(sorted);
  std::vector<std::unique_ptr<Leaf>> leaves(targets.size());
#pragma omp parallel for schedule(dynamic, 16)
  for (std::ptrdiff_t t = 0; t < std::ptrdiff_t(targets.size()); ++t) leaves[t] = rasterLeaf(k, sorted, targets[t]);
  for (auto& leaf : leaves)
    if (leaf) grid.tree().addLeaf(leaf.release());
  openvdb::tools::pruneLevelSet(grid.tree());  // ParticlesToLevelSet::finalize(/*prune=*/true)
}

}  // namespace stokes::sim::inline geometry
