// Particles by block: see particle_exchange.h.
#include "sim/ranks/particle_exchange.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>

#include "sim/ranks/rank_comm.h"

namespace stokes::sim {
inline namespace ranks {

namespace {

constexpr int kBlockCells = 8;

/// The bits of a double as an unsigned integer (a total order on the values a particle holds).
std::uint64_t bitsOf(double v) {
  std::uint64_t b;
  std::memcpy(&b, &v, sizeof b);
  return b;
}

void putParticle(Bytes& out, const ParticleSet<3>& p, std::size_t i) {
  out.put(p.x[i]);
  out.put(p.v[i]);
  out.put(p.c[i]);
}

void takeParticles(Bytes& in, ParticleSet<3>& p) {
  while (!in.done()) {
    const Vec3d x = in.get<Vec3d>(), v = in.get<Vec3d>();
    p.push_back(x, v, in.get<ParticleSet<3>::Affine>());
  }
}

/// Particle i's permutation applied to the set: p'[k] = p[order[k]].
void permute(ParticleSet<3>& p, const std::vector<std::size_t>& order) {
  ParticleSet<3> sorted;
  sorted.resize(order.size());
  for (std::size_t k = 0; k < order.size(); ++k) {
    sorted.x[k] = p.x[order[k]];
    sorted.v[k] = p.v[order[k]];
    sorted.c[k] = p.c[order[k]];
  }
  p = std::move(sorted);
}

/// Chebyshev distance from cell c to the 8^3 block at origin o (0 inside).
int distanceToBlock(const Coord& c, const Coord& o) {
  int d = 0;
  for (int a = 0; a < 3; ++a) d = std::max(d, std::max(o[a] - c[a], c[a] - (o[a] + kBlockCells - 1)));
  return d;
}

}  // namespace

Coord CellIndex::operator()(const Vec3d& x) const {
  const double invDx = 1.0 / dx;
  Coord k;
  for (int a = 0; a < 3; ++a) k[a] = int(std::floor((x[a] - origin[a]) * invDx));
  return k;
}

void canonicalOrder(ParticleSet<3>& particles, const CellIndex& cellOf) {
  const std::size_t n = particles.size();
  std::vector<Coord> cell(n);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(n); ++i) cell[i] = cellOf(particles.x[i]);
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t(0));
  auto key = [&](std::size_t i, int k) -> std::uint64_t {  // the k-th word of particle i's key
    if (k < 3) return std::uint64_t(std::uint32_t(cell[i][k]) ^ 0x80000000u);  // signed order
    if (k < 6) return bitsOf(particles.x[i][k - 3]);
    if (k < 9) return bitsOf(particles.v[i][k - 6]);
    return bitsOf(particles.c[i][std::size_t(k - 9) / 3][(k - 9) % 3]);
  };
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    for (int k = 0; k < 18; ++k) {
      const std::uint64_t ka = key(a, k), kb = key(b, k);
      if (ka != kb) return ka < kb;
    }
    return a < b;  // the same particle twice: any order gives the same bits
  });
  permute(particles, order);
}

std::size_t migrateParticles(ParticleSet<3>& particles, const RankBlocks& blocks, const CellIndex& cellOf,
                             std::size_t* sentBytes) {
  const int n = rankCount(), me = blocks.rank;
  std::vector<Bytes> out(static_cast<std::size_t>(n));
  std::vector<std::uint8_t> leaves(particles.size(), 0);
  std::size_t homeless = 0;
  for (std::size_t i = 0; i < particles.size(); ++i) {
    const int owner = blocks.ownerOfCell(cellOf(particles.x[i]));
    if (owner < 0) ++homeless;
    if (owner < 0 || owner == me) continue;
    putParticle(out[std::size_t(owner)], particles, i);
    leaves[i] = 1;
  }
  if (sentBytes) {
    *sentBytes = 0;
    for (const Bytes& b : out) *sentBytes += b.bytes().size();
  }
  particles.eraseMasked(leaves);
  for (Bytes& in : exchange(out)) takeParticles(in, particles);
  canonicalOrder(particles, cellOf);
  return homeless;
}

Ghosts ghostParticles(const ParticleSet<3>& own, const RankBlocks& blocks, const CellIndex& cellOf, int reach,
                      int stateReach, std::size_t* sentBytes) {
  const int n = rankCount(), me = blocks.rank;
  const int reachBlocks = (reach + kBlockCells - 1) / kBlockCells;
  // per block that holds particles here: the other ranks' blocks within reach of it
  struct Near {
    int rank;
    Coord origin;
  };
  std::vector<std::vector<Near>> nearOf(blocks.size());
  std::vector<std::uint8_t> listed(blocks.size(), 0);
  // per rank: the whole state of the near particles, then the positions of the far ones
  std::vector<Bytes> state(static_cast<std::size_t>(n)), far(static_cast<std::size_t>(n));
  std::vector<int> nearest(std::size_t(n), 0);
  for (std::size_t i = 0; i < own.size(); ++i) {
    const Coord c = cellOf(own.x[i]);
    const std::int64_t b = blocks.blockOf(c);
    if (b < 0) continue;
    if (!listed[std::size_t(b)]) {
      listed[std::size_t(b)] = 1;
      const Coord o = blocks.origins[std::size_t(b)];
      for (int dx = -reachBlocks; dx <= reachBlocks; ++dx)
        for (int dy = -reachBlocks; dy <= reachBlocks; ++dy)
          for (int dz = -reachBlocks; dz <= reachBlocks; ++dz) {
            const Coord q = o + Coord(dx * kBlockCells, dy * kBlockCells, dz * kBlockCells);
            const std::int64_t k = blocks.blockOf(q);
            if (k >= 0 && blocks.owner[std::size_t(k)] != me)
              nearOf[std::size_t(b)].push_back({blocks.owner[std::size_t(k)], q});
          }
    }
    std::fill(nearest.begin(), nearest.end(), reach + 1);
    for (const Near& q : nearOf[std::size_t(b)])
      nearest[std::size_t(q.rank)] = std::min(nearest[std::size_t(q.rank)], distanceToBlock(c, q.origin));
    for (int r = 0; r < n; ++r) {
      if (nearest[std::size_t(r)] <= stateReach) putParticle(state[std::size_t(r)], own, i);
      else if (nearest[std::size_t(r)] <= reach) far[std::size_t(r)].put(own.x[i]);
    }
  }
  // one message per rank: the state records, then the positions, with their count first
  std::vector<Bytes> out(static_cast<std::size_t>(n));
  for (int r = 0; r < n; ++r) {
    out[std::size_t(r)].put(std::uint64_t(state[std::size_t(r)].bytes().size()));
    auto& d = out[std::size_t(r)].bytes();
    d.insert(d.end(), state[std::size_t(r)].bytes().begin(), state[std::size_t(r)].bytes().end());
    d.insert(d.end(), far[std::size_t(r)].bytes().begin(), far[std::size_t(r)].bytes().end());
  }
  if (sentBytes) {
    *sentBytes = 0;
    for (int r = 0; r < n; ++r)
      if (r != me) *sentBytes += out[std::size_t(r)].bytes().size();
  }
  Ghosts ghosts;
  for (Bytes& in : exchange(out)) {
    const std::size_t stateBytes = std::size_t(in.get<std::uint64_t>());
    Bytes records;
    records.bytes().assign(in.bytes().begin() + std::ptrdiff_t(sizeof(std::uint64_t)),
                          in.bytes().begin() + std::ptrdiff_t(sizeof(std::uint64_t) + stateBytes));
    takeParticles(records, ghosts.state);
    Bytes positions;
    positions.bytes().assign(in.bytes().begin() + std::ptrdiff_t(sizeof(std::uint64_t) + stateBytes), in.bytes().end());
    while (!positions.done()) ghosts.positions.push_back(positions.get<Vec3d>());
  }
  canonicalOrder(ghosts.state, cellOf);
  return ghosts;
}

}  // namespace ranks
}  // namespace stokes::sim
