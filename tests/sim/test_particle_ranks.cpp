// Particles by block (sim/ranks/): the step's blocks gathered from every rank's particles, the
// migration to the blocks' owners and the ghost copies, in one order for any rank count. Each
// rank builds the whole set too and checks its part against it, bit for bit: the owned particles,
// the ghosts, P2G on the owned faces, G2P and the reseeding of the owned blocks. Runs on 1, 2 and
// 3 ranks (mpiexec; one rank without the PETSc backend).
#include <gtest/gtest.h>
#include <openvdb/tools/Morphology.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include "sim/geometry/geometry.h"
#include "sim/particles/apic_transfer.h"
#include "sim/particles/reseed.h"
#include "sim/ranks/exact_sum.h"
#include "sim/ranks/particle_exchange.h"
#include "sim/ranks/rank_blocks.h"
#include "sparse_grid/block_order.h"
#ifdef STOKES_HAVE_PETSC
#include "solver/petsc/petsc_krylov.h"
#endif

namespace {

using namespace stokes;
using openvdb::Coord;
using openvdb::Vec3d;
using Particles = sim::ParticleSet<3>;
using Layout = sparse_grid::BlockLayout<3>;

constexpr double kDx = 1.0 / 32.0;
constexpr int kBand = 3;
const sim::CellIndex kCellOf{kDx, Vec3d(0.0)};

double ballPhi(const Vec3d& x) { return (x - Vec3d(0.5, 0.45, 0.5)).length() - 0.3; }

/// A smooth velocity field with a swirl, so that every component and gradient differs.
Vec3d field(const Vec3d& x) {
  return Vec3d(std::sin(3.0 * x.y()) + 0.2 * x.z(), std::cos(2.0 * x.z()) - 0.5 * x.x(), 0.3 * x.x() * x.y());
}

/// The whole liquid: a seeded ball with the field's velocities, thinned in one slab (cells to refill)
/// and doubled in another (cells to thin), in a scrambled order.
Particles wholeSet() {
  sim::CellBox box;
  box.cells = openvdb::CoordBBox(Coord(0), Coord(31));
  box.dx = kDx;
  Particles seeded = sim::seedParticles<3>(box, ballPhi, 2, 7);
  Particles p;
  for (std::size_t i = 0; i < seeded.size(); ++i) {
    const Vec3d x = seeded.x[i];
    if (std::abs(x.x() - 0.45) < 0.03 && i % 4 != 0) continue;  // a thin slab: deep cells below target / 2
    p.push_back(x, field(x));
    if (std::abs(x.z() - 0.6) < 0.02) p.push_back(x + Vec3d(1e-3, 2e-3, 0.0), field(x));  // a clump
  }
  std::vector<std::size_t> order(p.size());
  std::iota(order.begin(), order.end(), std::size_t(0));
  for (std::size_t i = 0; i < order.size(); ++i) std::swap(order[i], order[(i * 7919) % order.size()]);
  Particles scrambled;
  for (std::size_t i : order) scrambled.push_back(p.x[i], p.v[i], p.c[i]);
  return scrambled;
}

openvdb::MaskTree bandMask(const std::vector<Vec3d>& x) {
  openvdb::MaskTree mask;
  for (const Vec3d& p : x) mask.setValueOn(kCellOf(p));
  openvdb::tools::dilateActiveValues(mask, kBand, openvdb::tools::NN_FACE_EDGE_VERTEX, openvdb::tools::EXPAND_TILES);
  mask.voxelizeActiveTiles();
  return mask;
}

bool sameParticle(const Particles& a, std::size_t i, const Particles& b, std::size_t j) {
  return std::memcmp(&a.x[i], &b.x[j], sizeof(Vec3d)) == 0 && std::memcmp(&a.v[i], &b.v[j], sizeof(Vec3d)) == 0 &&
         std::memcmp(&a.c[i], &b.c[j], sizeof(Particles::Affine)) == 0;
}

/// The particles of `all` (in order) for which keep(cell) holds.
template <class Keep>
Particles subset(const Particles& all, Keep keep) {
  Particles s;
  for (std::size_t i = 0; i < all.size(); ++i)
    if (keep(kCellOf(all.x[i]))) s.push_back(all.x[i], all.v[i], all.c[i]);
  return s;
}

void expectSameParticles(const Particles& got, const Particles& want, const char* what) {
  ASSERT_EQ(got.size(), want.size()) << what << " on rank " << sim::thisRank();
  std::size_t differ = 0;
  for (std::size_t i = 0; i < got.size(); ++i) differ += sameParticle(got, i, want, i) ? 0 : 1;
  EXPECT_EQ(differ, 0u) << what << " on rank " << sim::thisRank();
}

int distanceToBlock(const Coord& c, const Coord& o) {
  int d = 0;
  for (int a = 0; a < 3; ++a) d = std::max(d, std::max(o[a] - c[a], c[a] - (o[a] + 7)));
  return d;
}

/// The state every test starts from: the whole set (canonical order), this rank's share of it
/// after migration, and the blocks.
struct Split {
  Particles whole, own;
  sim::RankBlocks blocks;
  std::size_t homeless = 0;
};

Split split() {
  Split s;
  s.whole = wholeSet();
  Particles mine;  // an arbitrary first holding: every rankCount()-th particle of the scrambled set
  for (std::size_t i = std::size_t(sim::thisRank()); i < s.whole.size(); i += std::size_t(sim::rankCount()))
    mine.push_back(s.whole.x[i], s.whole.v[i], s.whole.c[i]);
  s.blocks = sim::gatherRankBlocks(bandMask(mine.x));
  s.homeless = sim::migrateParticles(mine, s.blocks, kCellOf);
  s.own = std::move(mine);
  sim::canonicalOrder(s.whole, kCellOf);
  return s;
}

TEST(ParticleRanks, GatheredBlocksAreTheWholeLayoutsAndItsPartition) {
  const Split s = split();
  const Layout whole(bandMask(s.whole.x), kDx);
  ASSERT_EQ(s.blocks.size(), whole.numBlocks());
  const std::vector<int> owners = sparse_grid::blockOwners<3>(whole, sim::rankCount());
  std::size_t wrongCells = 0, wrongOwners = 0;
  for (std::size_t b = 0; b < whole.numBlocks(); ++b) {
    const std::int64_t k = s.blocks.blockOf(whole.blockOrigin(b));
    ASSERT_GE(k, 0);
    for (int i = 0; i < int(Layout::kSlots); ++i) {
      const bool on = (s.blocks.cells[std::size_t(k)][std::size_t(i) / 64] >> (i % 64)) & 1u;
      wrongCells += on != whole.isActiveCell(b * Layout::kSlots + std::size_t(i)) ? 1 : 0;
    }
    wrongOwners += s.blocks.owner[std::size_t(k)] != owners[b] ? 1 : 0;
  }
  EXPECT_EQ(wrongCells, 0u);
  EXPECT_EQ(wrongOwners, 0u);
}

TEST(ParticleRanks, MigrationLeavesEachRankTheWholeSetsParticlesOfItsBlocks) {
  const Split s = split();
  EXPECT_EQ(s.homeless, 0u);
  const Particles want = subset(s.whole, [&](const Coord& c) { return s.blocks.ownerOfCell(c) == sim::thisRank(); });
  expectSameParticles(s.own, want, "owned particles");
  EXPECT_EQ(sim::sumOverRanks(std::int64_t(s.own.size())), std::int64_t(s.whole.size()));
}

TEST(ParticleRanks, GhostsAreTheOtherRanksParticlesWithinReach) {
  const Split s = split();
  constexpr int kReach = 10, kStateReach = 5;  // past the next block: the search spans two blocks each way
  const sim::Ghosts ghosts = sim::ghostParticles(s.own, s.blocks, kCellOf, kReach, kStateReach);
  std::vector<Coord> mine;
  for (std::size_t b = 0; b < s.blocks.size(); ++b)
    if (s.blocks.owner[b] == sim::thisRank()) mine.push_back(s.blocks.origins[b]);
  auto distance = [&](const Coord& c) {
    int d = std::numeric_limits<int>::max();
    for (const Coord& o : mine) d = std::min(d, distanceToBlock(c, o));
    return d;
  };
  auto other = [&](const Coord& c) { return s.blocks.ownerOfCell(c) != sim::thisRank(); };
  expectSameParticles(ghosts.state, subset(s.whole, [&](const Coord& c) { return other(c) && distance(c) <= kStateReach; }),
                      "ghosts with their state");
  const Particles far = subset(s.whole, [&](const Coord& c) {
    return other(c) && distance(c) > kStateReach && distance(c) <= kReach;
  });
  auto sorted = [](std::vector<Vec3d> x) {
    std::sort(x.begin(), x.end(), [](const Vec3d& a, const Vec3d& b) {
      return std::lexicographical_compare(a.asPointer(), a.asPointer() + 3, b.asPointer(), b.asPointer() + 3);
    });
    return x;
  };
  EXPECT_TRUE(sorted(ghosts.positions) == sorted(far.x)) << "ghost positions on rank " << sim::thisRank();
  if (sim::rankCount() == 1) {
    EXPECT_EQ(ghosts.state.size() + ghosts.positions.size(), 0u);
  } else {
    EXPECT_GT(sim::sumOverRanks(std::int64_t(ghosts.positions.size())), 0);
  }
}

/// A rank's layout (its blocks and their halo), its particles with the ghosts P2G reads, and the
/// map from its slots to the whole layout's.
struct Part {
  std::unique_ptr<Layout> layout;
  Particles withGhosts;
  std::vector<std::uint8_t> ownedBlock;  ///< per local block
  std::vector<std::int64_t> wholeSlot;   ///< per local slot
};

Part partOf(const Split& s, const Layout& whole) {
  Part p;
  p.layout = std::make_unique<Layout>(s.blocks.mask(s.blocks.ownedAndHalo()), kDx);
  p.withGhosts = s.own;
  p.withGhosts.append(sim::ghostParticles(s.own, s.blocks, kCellOf, 3, 3).state);  // P2G reaches 2 cells
  sim::canonicalOrder(p.withGhosts, kCellOf);
  p.ownedBlock.resize(p.layout->numBlocks());
  for (std::size_t b = 0; b < p.layout->numBlocks(); ++b)
    p.ownedBlock[b] = s.blocks.owner[std::size_t(s.blocks.blockOf(p.layout->blockOrigin(b)))] == sim::thisRank();
  p.wholeSlot.resize(p.layout->numSlots());
  for (std::size_t k = 0; k < p.layout->numSlots(); ++k) p.wholeSlot[k] = whole.slotOf(p.layout->cellOf(k));
  return p;
}

TEST(ParticleRanks, P2GOnTheOwnedFacesIsTheWholeSetsBitForBit) {
  const Split s = split();
  const Layout whole(bandMask(s.whole.x), kDx);
  const Part part = partOf(s, whole);
  solver::Vector uWhole, mWhole, uPart, mPart;
  sim::particlesToGrid<3>(whole, s.whole, uWhole, mWhole, sparse_grid::SlotsToFill::ActiveCells);
  sim::particlesToGrid<3>(*part.layout, part.withGhosts, uPart, mPart, sparse_grid::SlotsToFill::ActiveCells);
  const std::size_t n = part.layout->numSlots(), N = whole.numSlots();
  std::size_t compared = 0, differ = 0;
  for (std::size_t k = 0; k < n; ++k) {
    if (!part.ownedBlock[k / Layout::kSlots] || !part.layout->isActiveCell(k)) continue;
    for (int a = 0; a < 3; ++a) {
      const std::size_t w = std::size_t(a) * N + std::size_t(part.wholeSlot[k]), l = std::size_t(a) * n + k;
      ++compared;
      differ += std::memcmp(&uWhole[w], &uPart[l], sizeof(double)) != 0 || std::memcmp(&mWhole[w], &mPart[l], sizeof(double)) != 0;
    }
  }
  EXPECT_GT(compared, 0u);
  EXPECT_EQ(differ, 0u) << "of " << compared << " owned faces on rank " << sim::thisRank();
}

/// The field on every face of a layout.
solver::Vector faceField(const Layout& L) {
  solver::Vector u(3 * L.numSlots());
  for (std::size_t k = 0; k < L.numSlots(); ++k)
    for (int a = 0; a < 3; ++a) u[std::size_t(a) * L.numSlots() + k] = field(L.samplePosition(k, sparse_grid::faceMask(a)))[a];
  return u;
}

TEST(ParticleRanks, G2PAndReseedingOfTheOwnedBlocksAreTheWholeSetsBitForBit) {
  const Split s = split();
  const Layout whole(bandMask(s.whole.x), kDx);
  const Part part = partOf(s, whole);
  Particles all = s.whole, own = s.own;
  const solver::Vector uWhole = faceField(whole), uPart = faceField(*part.layout);
  sim::gridToParticles<3>(whole, uWhole, all);
  sim::gridToParticles<3>(*part.layout, uPart, own);
  const sim::ReseedCounts cw = sim::reseedParticles<3>(whole, all, ballPhi, uWhole, 8, 11);
  const sim::ReseedCounts cp = sim::reseedParticles<3>(*part.layout, own, ballPhi, uPart, 8, 11, nullptr, &part.ownedBlock);
  EXPECT_GT(cw.added, 0u);
  EXPECT_GT(cw.removed, 0u);
  EXPECT_EQ(sim::sumOverRanks(std::int64_t(cp.added)), std::int64_t(cw.added));
  EXPECT_EQ(sim::sumOverRanks(std::int64_t(cp.removed)), std::int64_t(cw.removed));
  EXPECT_EQ(sim::sumOverRanks(std::int64_t(cp.deepParticles)), std::int64_t(cw.deepParticles));
  sim::canonicalOrder(all, kCellOf);
  sim::canonicalOrder(own, kCellOf);
  expectSameParticles(own, subset(all, [&](const Coord& c) { return s.blocks.ownerOfCell(c) == sim::thisRank(); }),
                      "particles after G2P and reseeding");
}

TEST(ParticleRanks, LevelSetFromTheGhostsIsTheWholeSetsOnTheBlocksAndHalo) {
  // the level set of a rank's particles and the ghosts within kGhostReachCells (in the order they
  // arrive) equals the whole set's on every voxel of its blocks and their halo, bit for bit: the
  // weights there are exact
  const Split s = split();
  const int reach = sim::kGhostReachCells;
  Particles local = s.own;
  const sim::Ghosts ghosts = sim::ghostParticles(s.own, s.blocks, kCellOf, reach, sim::kGhostStateReachCells);
  local.append(ghosts.state);
  for (const Vec3d& x : ghosts.positions) local.push_back(x, Vec3d(0.0));
  sim::ParticleSurfaceOptions surface;
  surface.particleSpacingInCells = 0.5;
  surface.faceBulgeInCells = 0.05;
  const auto whole = sim::liquidLevelSetFromParticles(s.whole.x, kDx, 1.0, 3.0, surface);
  const auto part = sim::liquidLevelSetFromParticles(local.x, kDx, 1.0, 3.0, surface);
  const std::vector<std::uint8_t> keep = s.blocks.ownedAndHalo();
  auto a = whole->getConstAccessor();
  auto b = part->getConstAccessor();
  std::size_t compared = 0, differ = 0;
  for (std::size_t k = 0; k < s.blocks.size(); ++k) {
    if (!keep[k]) continue;
    const openvdb::CoordBBox box(s.blocks.origins[k], s.blocks.origins[k] + Coord(7));
    for (auto ijk = box.begin(); ijk; ++ijk) {  // voxel ijk's centre lies in cell ijk (origin 0)
      ++compared;
      const float va = a.getValue(*ijk), vb = b.getValue(*ijk);
      differ += std::memcmp(&va, &vb, sizeof va) != 0 ? 1 : 0;
    }
  }
  EXPECT_GT(compared, 0u);
  EXPECT_EQ(differ, 0u) << "of " << compared << " voxels on rank " << sim::thisRank() << ", reach " << reach;
}

TEST(ParticleRanks, ExactSumsAreTheSameForAnyRankCount) {
  const Split s = split();
  sim::ExactSum whole, part;
  for (const Vec3d& v : s.whole.v) whole.add(v.lengthSqr());
  for (const Vec3d& v : s.own.v) part.add(v.lengthSqr());
  EXPECT_EQ(part.overRanks().units(), whole.units());
  EXPECT_NEAR(whole.value(), [&] {
    double sum = 0.0;
    for (const Vec3d& v : s.whole.v) sum += v.lengthSqr();
    return sum;
  }(), 1e-9 * whole.value());
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
#ifdef STOKES_HAVE_PETSC
  stokes::solver::petsc::Session session;
  stokes::solver::petsc::Session::initialise({});
#endif
  // every rank runs every test; only rank 0 prints
  if (stokes::sim::thisRank() != 0) delete ::testing::UnitTest::GetInstance()->listeners().Release(
                                    ::testing::UnitTest::GetInstance()->listeners().default_result_printer());
  return RUN_ALL_TESTS();
}
