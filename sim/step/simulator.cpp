// The time loop: see simulator.h.
#include "sim/step/simulator.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <utility>

#include "sim/particles/advection.h"
#include "sim/particles/apic_transfer.h"
#include "sim/step/emitters.h"
#include "sim/geometry/obj_mesh.h"
#include "sim/particles/reseed.h"
#include "sim/ranks/block_values.h"
#include "sim/ranks/exact_sum.h"
#include "sim/ranks/rank_comm.h"
#include "sim/ranks/rank_volume.h"
#include "solver/krylov/stopwatch.h"

namespace stokes::sim {
inline namespace step {

namespace {

using Clock = std::chrono::steady_clock;

/// Runs `body`, records its wall time in `slot` and its name in the stage list.
template <class Body>
void timed(StepStats& stats, Stage stage, Body&& body) {
  const auto t0 = Clock::now();
  body();
  stats.times.add(stage, solver::secondsSince(t0));
  stats.stages.push_back(stage);
}

std::unique_ptr<ShapeField> buildSolids(const Scene& scene) {
  if (!scene.hasSolids()) return nullptr;
  std::vector<TriangleMesh> meshes;
  meshes.reserve(scene.solids.size());
  std::vector<const TriangleMesh*> pointers(scene.solids.size(), nullptr);
  for (std::size_t i = 0; i < scene.solids.size(); ++i)
    if (scene.solids[i].kind == ShapeDesc::Kind::Mesh) {
      meshes.push_back(loadObj(scene.solids[i].meshPath));
      pointers[i] = &meshes.back();
    }
  return std::make_unique<ShapeField>(scene.solids, pointers, scene.dx());
}

}  // namespace

bool splitsOverRanks(const Scene& scene) {
  return scene.solver.backend == solver::Backend::Petsc && scene.stepSystem() != solver::SystemKind::DecoupledStokes;
}

Simulator::Simulator(Scene scene) : scene_(std::move(scene)), domain_(DomainBox::fromScene(scene_)) {
  plan_ = planStokes(scene_, std::make_shared<solver::TileLibrary>(), tileHistory_);
  solids_ = buildSolids(scene_);
  byRanks_ = splitsOverRanks(scene_);
  // Split over ranks, each rank seeds the cells of every rankCount()-th block (by a hash of its
  // coordinates); the first step sends the particles to their blocks' owners.
  std::function<bool(const openvdb::Coord&)> share;
  if (byRanks_ && rankCount() > 1)
    share = [r = std::uint64_t(thisRank()), n = std::uint64_t(rankCount())](const openvdb::Coord& c) {
      std::uint64_t h = 0;
      for (int a = 0; a < 3; ++a) h = mixBits(h ^ std::uint64_t(std::uint32_t(c[a] >> 3)));
      return h % n == r;
    };
  particles_ = seedInitialLiquid(scene_, domain_, solids_.get(), share);
  if (solids_) pushOutOfSolid<kSimDim>(particles_, *solids_, domain_.dx);
  volumeTarget_ = double(overRanks(particles_.size())) * particleVolume();
  faceBulge_ = seededFaceBulge(scene_.particlesPerCellAxis);
  for (const EmitterDesc& e : scene_.emitters)
    if (e.kind == EmitterDesc::Kind::Disc) {
      coil_.emplace(e.center, e.velocity.length() > 0.0 ? e.velocity : e.normal, std::max(e.velocity.length(), 1e-12),
                    2.0 * domain_.dx, 0.5 * domain_.dx);
      break;
    }
}

openvdb::FloatGrid::Ptr Simulator::levelSetOf(const std::vector<Vec3d>& positions, VolumeMatch* match,
                                               const std::function<bool(const openvdb::Coord&)>& owned) const {
  ParticleSurfaceOptions surface;
  surface.particleSpacingInCells = 1.0 / scene_.particlesPerCellAxis;
  surface.faceBulgeInCells = faceBulge_;
  openvdb::FloatGrid::Ptr liquid = liquidLevelSetFromParticles(positions, domain_.dx, 1.0, 3.0, surface);
  VolumeMatch m;
  if (owned) {
    if (scene_.keepVolume) m = matchClippedVolumeOnRanks(*liquid, volumeTarget_, liquidClip(), 0.5 * domain_.dx, owned);
    else m.volume = m.raw = clippedVolumeOnRanks(*liquid, liquidClip(), owned);
  } else {
    if (scene_.keepVolume) m = matchClippedVolume(*liquid, volumeTarget_, liquidClip(), 0.5 * domain_.dx);
    else m.volume = m.raw = liquidVolume(*liquid);
  }
  if (match) *match = m;
  return liquid;
}

openvdb::FloatGrid::Ptr Simulator::liquidLevelSet(VolumeMatch* match) const {
  if (!byRanks_) return levelSetOf(particles_.x, match, {});
  const RankView view = rankView(stepBlocks());
  const auto owned = ownedVoxels(*cellCentredTransform(domain_.dx), view.blocks, cellIndex());
  return gatherLevelSet(*levelSetOf(view.surface, match, owned), owned);
}

RankBlocks Simulator::stepBlocks() const {
  return gatherRankBlocks(particleBandMask(particles_.x, domain_, layoutBand(scene_)));
}

std::size_t Simulator::moveWarmStart(const RankBlocks& now, bool ownedOnly) {
  const Layout3* layout = warm_.layout();
  std::vector<std::uint8_t> mine;
  if (layout) {
    mine.assign(layout->numBlocks(), 1);
    if (ownedOnly)
      for (std::size_t b = 0; b < layout->numBlocks(); ++b) mine[b] = now.ownerOfCell(layout->blockOrigin(b)) == now.rank;
  }
  std::size_t sent = 0;
  BlockValues to = moveToOwners(layout, warm_.solution(), mine, now, domain_.dx, domain_.min, &sent);
  if (to.layout) warm_.keep(std::move(to.layout), std::move(to.values));
  else warm_.clear();
  return sent;
}

Simulator::RankView Simulator::rankView(RankBlocks blocks) const {
  RankView view;
  view.blocks = std::move(blocks);
  Ghosts ghosts =
      ghostParticles(particles_, view.blocks, cellIndex(), kGhostReachCells, kGhostStateReachCells, &view.sentBytes);
  view.withGhosts = std::move(ghosts.state);
  view.withGhosts.append(particles_);
  canonicalOrder(view.withGhosts, cellIndex());
  view.surface = view.withGhosts.x;
  view.surface.insert(view.surface.end(), ghosts.positions.begin(), ghosts.positions.end());
  return view;
}

ParticleSet<kSimDim> Simulator::gatheredParticles() const {
  if (!byRanks_) return particles_;
  Bytes mine;
  for (std::size_t p = 0; p < particles_.size(); ++p) {
    mine.put(particles_.x[p]);
    mine.put(particles_.v[p]);
  }
  ParticleSet<kSimDim> all;
  streamToRoot(std::move(mine), [&](Bytes& b) {
    while (!b.done()) {
      const Vec3d x = b.get<Vec3d>();
      all.push_back(x, b.get<Vec3d>());
    }
  });
  canonicalOrder(all, cellIndex());
  return all;
}

std::function<double(const Vec3d&)> Simulator::liquidClip() const {
  return [this](const Vec3d& x) {
    const double box = domain_.phi(x);
    return solids_ ? std::max(box, -solids_->phi(x)) : box;
  };
}

double Simulator::liquidVolume(const openvdb::FloatGrid& liquid) const {
  return levelSetVolumeClipped(liquid, liquidClip());
}

double Simulator::particleVolume() const {
  const int perAxis = scene_.particlesPerCellAxis;
  return std::pow(domain_.dx, 3) / double(perAxis * perAxis * perAxis);
}

double Simulator::particleMass() const { return scene_.material.density * particleVolume(); }

double Simulator::cflTimeStep() const {
  double vmax = 0.0;
  for (const Vec3d& v : particles_.v) vmax = std::max(vmax, v.length());
  if (byRanks_) vmax = maxOverRanks(vmax);
  for (const EmitterDesc& e : scene_.emitters) vmax = std::max(vmax, e.velocity.length());
  const double g = scene_.gravity ? scene_.gravity->length() : 0.0;
  const double speed = vmax + std::sqrt(g * domain_.dx);
  return speed > 0.0 ? scene_.cfl * domain_.dx / speed : std::numeric_limits<double>::infinity();
}

bool Simulator::advanceFrame(int frame, const std::function<void(const StepStats&)>& onStep,
                             const std::function<bool()>& stop) {
  if (frame != frame_) {
    frame_ = frame;
    frameSubsteps_ = 0;
  }
  // the solves poll the same request once per Krylov iteration (a step they stop is rolled back);
  // over MPI ranks the request is a collective, so there only between steps
  plan_.options.krylov.stopRequested = rankCount() == 1 ? stop : std::function<bool()>{};
  const double frameEnd = frame / scene_.fps;
  while (time_ < frameEnd) {
    const double remaining = frameEnd - time_;
    const int stepsLeft = std::max(scene_.maxSubsteps - frameSubsteps_, 1);
    const double n = std::min(std::ceil(remaining / std::min(cflTimeStep(), retryDtLimit_)), double(stepsLeft));
    const double dt = remaining / std::max(n, 1.0);
    std::vector<std::string> failures;
    stepRetrying(dt, frame, 0, onStep, failures);
    ++frameSubsteps_;
    if (n <= 1.0) time_ = frameEnd;  // the last substep lands on the frame time exactly
    if (time_ < frameEnd && stop && stop()) return false;
  }
  return true;
}

void Simulator::stepRetrying(double dt, int frame, int level, const std::function<void(const StepStats&)>& onStep,
                             std::vector<std::string>& failures) {
  // The roll-back point: after a failure the simulator is back where the step began, so that a
  // retry starts there and, after the last one, the caller holds the last good state.
  const SimulatorState start = rollBackPoint();
  StepStats stats;
  try {
    stats = step(dt, frame);
  } catch (const StepInterrupted&) {
    rollBack(start);
    throw;
  } catch (const SimulationError& e) {
    rollBack(start);
    if (level >= scene_.solver.retries) {
      if (level == 0) throw;
      throw SimulationError(std::string(e.what()) + " (after " + std::to_string(level) +
                            " halvings of the step, the scene's solver.retries)");
    }
    failures.push_back(e.what());
    stepRetrying(0.5 * dt, frame, level + 1, onStep, failures);
    stepRetrying(0.5 * dt, frame, level + 1, onStep, failures);
    return;
  }
  // The next steps start from the dt that passed, doubling it back after each step that needed no
  // retry (a solve that failed at dt would fail again at the next step's similar dt).
  retryDtLimit_ = level > 0 ? dt : 2.0 * retryDtLimit_;
  stats.retryLevel = level;
  stats.failedAttempts = std::move(failures);
  failures.clear();
  if (onStep) onStep(stats);
}

SimulatorState Simulator::rollBackPoint() const {
  SimulatorState s;
  s.time = time_;
  s.lastDt = lastDt_;
  s.volumeTarget = volumeTarget_;
  s.steps = steps_;
  s.frame = frame_;
  s.frameSubsteps = frameSubsteps_;
  s.retryDtLimit = retryDtLimit_;
  s.particles = particles_;
  return s;
}

void Simulator::rollBack(const SimulatorState& s) {
  time_ = s.time;
  lastDt_ = s.lastDt;
  volumeTarget_ = s.volumeTarget;
  steps_ = int(s.steps);
  frame_ = s.frame;
  frameSubsteps_ = s.frameSubsteps;
  retryDtLimit_ = s.retryDtLimit;
  particles_ = s.particles;
  tileHistory_->forgetRecorded();  // a failed step's tiling is not the previous step's
}

SimulatorState Simulator::state() const {
  SimulatorState s = rollBackPoint();
  if (const Layout3* layout = warm_.layout()) {
    WarmStartState w;
    w.dx = layout->dx();
    w.origin = layout->origin();
    w.blockOrigins.reserve(layout->numBlocks());
    for (std::size_t b = 0; b < layout->numBlocks(); ++b) w.blockOrigins.push_back(layout->blockOrigin(b));
    w.activeSlots.resize(layout->numSlots());
    for (std::size_t slot = 0; slot < layout->numSlots(); ++slot) w.activeSlots[slot] = layout->isActiveCell(slot);
    w.solution = warm_.solution();
    s.warm = std::move(w);
  }
  if (coil_) s.coil = coil_->state();
  s.tileHistory = tileHistory_->state();
  return s;
}

void Simulator::restore(const SimulatorState& s) {
  const std::size_t n = s.particles.size();
  if (s.particles.v.size() != n || s.particles.c.size() != n)
    throw std::invalid_argument("Simulator::restore: particle arrays of different lengths");
  if (s.coil.has_value() != coil_.has_value())
    throw std::invalid_argument(std::string("Simulator::restore: the state ") + (s.coil ? "has" : "lacks") +
                                " a coil measure and the scene " + (coil_ ? "has" : "lacks") + " a disc emitter");
  rollBack(s);
  warm_.clear();
  if (s.warm) {
    const WarmStartState& w = *s.warm;
    if (w.activeSlots.size() != w.blockOrigins.size() * Layout3::kSlots)
      throw std::invalid_argument("Simulator::restore: warm start cells do not fill its blocks");
    openvdb::MaskTree cells;
    for (std::size_t slot = 0; slot < w.activeSlots.size(); ++slot)
      if (w.activeSlots[slot])
        cells.setValueOn(w.blockOrigins[slot / Layout3::kSlots] + Layout3::localCoord(int(slot % Layout3::kSlots)));
    auto layout = std::make_unique<Layout3>(cells, w.dx, w.origin);
    bool sameBlocks = layout->numBlocks() == w.blockOrigins.size();
    for (std::size_t b = 0; sameBlocks && b < w.blockOrigins.size(); ++b)
      sameBlocks = layout->blockOrigin(b) == w.blockOrigins[b];
    if (!sameBlocks)
      throw std::invalid_argument("Simulator::restore: the warm start's blocks do not rebuild in their order");
    warm_.keep(std::move(layout), w.solution);
  }
  if (coil_ && s.coil) coil_->restore(*s.coil);
  tileHistory_->restore(s.tileHistory);
}

StepStats Simulator::step(double dt, int frame) {
  try {
    return stepStages(dt, frame);
  } catch (const SimulationError& e) {
    throw SimulationError("frame " + std::to_string(frame) + ", step " + std::to_string(steps_) +
                          " (t = " + std::to_string(time_) + " s, dt = " + std::to_string(dt) + " s): " + e.what());
  }
}

void Simulator::emit(StepStats& stats) {
  const double previousStart = time_ - lastDt_;  // the previous step's start (lastDt_ = 0: none)
  for (std::size_t i = 0; i < scene_.emitters.size(); ++i) {
    const EmitterDesc& e = scene_.emitters[i];
    if (time_ < e.start || time_ >= e.stop) continue;
    const bool wasActive = lastDt_ > 0.0 && previousStart >= e.start && previousStart < e.stop;
    // split over ranks, every rank sets the velocity of its particles in the emitter, rank 0 seeds,
    // and the step's migration sends the new particles to their owners
    const std::size_t emitted = overRanks(
        applyEmitter(e, domain_, scene_.particlesPerCellAxis, scene_.seed ^ (std::uint64_t(steps_) << 20) ^ (i + 1),
                     particles_, wasActive ? lastDt_ : 0.0, !byRanks_ || thisRank() == 0));
    stats.added += emitted;
    volumeTarget_ += double(emitted) * particleVolume();
  }
}

double Simulator::volumeControlDivergence(double volume, double dt) const {
  // Kim et al. 2007 (proportional part): div u = -k e / ((1 + e) dt), e = V / V_target - 1. A
  // uniform s changes the Cartesian liquid's volume at the relative rate s, so one step removes
  // about k of the error: (1 + e) (1 + s dt) = 1 + (1 - k) e. The error is the particles' own:
  // reseeding refills the sparse cells of a liquid whose particles spread apart (the coil's pile
  // at res 96: +27% over 5 s), and the raw surface reads that growth.
  const double k = scene_.volumeControl;
  if (!(k > 0.0) || !(volumeTarget_ > 0.0) || !(volume > 0.0)) return 0.0;
  const double e = volume / volumeTarget_ - 1.0;
  return -k * e / ((1.0 + e) * dt);
}

void Simulator::keepInsideDomain(StepStats& stats) {
  // Closed walls: clamp into the box by a hundredth of a cell. Open top: drop what left through it.
  const double margin = 0.01 * domain_.dx;
  std::vector<std::uint8_t> drop(particles_.size(), 0);
  for (std::size_t p = 0; p < particles_.size(); ++p) {
    Vec3d& x = particles_.x[p];
    for (int a = 0; a < 3; ++a) {
      if (a == 1 && domain_.openTop && x[a] > domain_.max[a]) {
        drop[p] = 1;
        continue;
      }
      x[a] = std::clamp(x[a], domain_.min[a] + margin, domain_.max[a] - margin);
    }
  }
  const std::size_t dropped = overRanks(particles_.eraseMasked(drop));
  stats.removed += dropped;
  volumeTarget_ -= double(dropped) * particleVolume();
}

StepStats Simulator::stepStages(double dt, int frame) {
  const auto start = Clock::now();
  StepStats stats;
  stats.frame = frame;
  stats.step = steps_;
  stats.dt = dt;
  double vmax = 0.0;
  for (const Vec3d& v : particles_.v) vmax = std::max(vmax, v.length());
  if (byRanks_) vmax = maxOverRanks(vmax);
  stats.cflNumber = vmax * dt / domain_.dx;

  if (solids_) solids_->setTime(time_);  // moving solids: where they are at the step's start
  bool emitting = false;
  for (const EmitterDesc& e : scene_.emitters) emitting = emitting || (time_ >= e.start && time_ < e.stop);
  if (emitting) timed(stats, Stage::Emit, [&] { emit(stats); });
  if (overRanks(particles_.size()) == 0) throw SimulationError("stage emit: no liquid particles left to simulate");

  // Split over ranks: the blocks' owners, this rank's particles sent to them, the ghosts read.
  std::optional<RankView> view;
  if (byRanks_)
    timed(stats, Stage::Migrate, [&] {
      std::size_t sent = 0;
      RankBlocks blocks = stepBlocks();
      migrateParticles(particles_, blocks, cellIndex(), &sent);
      view = rankView(std::move(blocks));
      if (scene_.solver.warmStart) sent += moveWarmStart(view->blocks, false);
      stats.grid.sentBytes += sent;
    });
  const ParticleSet<kSimDim>& gridParticles = view ? view->withGhosts : particles_;

  openvdb::FloatGrid::Ptr liquid;
  timed(stats, Stage::LevelSet, [&] {
    VolumeMatch match;
    stats.volumeTarget = volumeTarget_;
    const auto owned = view ? ownedVoxels(*cellCentredTransform(domain_.dx), view->blocks, cellIndex())
                            : std::function<bool(const openvdb::Coord&)>();
    liquid = levelSetOf(view ? view->surface : particles_.x, &match, owned);
    stats.liquidVolume = match.volume;
    stats.surfaceOffset = match.offset / domain_.dx;
    stats.levelSetVolume = view ? clippedVolumeOnRanks(*liquid, {}, owned) : levelSetVolume(*liquid);
    stats.rawVolume = match.raw;
  });
  stats.divergenceTarget = volumeControlDivergence(stats.rawVolume, dt);

  GridStep grid(gridParticles.x, *liquid, solids_.get(), domain_, scene_, dt, plan_.viscous(), layoutBand(scene_),
                view ? &view->blocks : nullptr);
  for (const EmitterDesc& e : scene_.emitters)  // the liquid leaves an active emitter at its velocity
    if (time_ >= e.start && time_ < e.stop)
      grid.setInflow([&e](const Vec3d& x) { return emitterPhi(e, x); }, e.velocity);
  grid.setDivergenceTarget(stats.divergenceTarget);
  grid.solve(gridParticles, scene_.gravity ? &*scene_.gravity : nullptr, plan_,
             scene_.solver.warmStart ? &warm_ : nullptr);
  const std::size_t migrated = stats.grid.sentBytes;
  stats.grid = grid.report();
  // split over ranks: what all ranks sent each other (particles, ghosts, halo velocities)
  stats.grid.sentBytes = overRanks(stats.grid.sentBytes + migrated + (view ? view->sentBytes : 0));
  stats.grid.cells = overRanks(stats.grid.cells);
  stats.grid.stressUnknowns = overRanks(stats.grid.stressUnknowns);
  const GridStepReport& g = stats.grid;
  for (const Stage s : g.stages) stats.stages.push_back(s);
  for (const Stage s : kStages)
    if (g.times[s]) stats.times.add(s, *g.times[s]);

  const Layout3& layout = grid.layout();
  const solver::Vector& u = grid.velocity();
  const BoxWalls walls = domain_.walls();
  timed(stats, Stage::G2P, [&] { gridToParticles<kSimDim>(layout, u, particles_, &walls); });
  timed(stats, Stage::Reseed, [&] {
    const GridPhi liquidPhi(liquid);
    const int perAxis = scene_.particlesPerCellAxis;
    std::vector<std::uint8_t> ownedBlocks;  // split over ranks: this rank reseeds its own blocks
    for (std::int32_t owner : grid.problem().blockOwner) ownedBlocks.push_back(owner == thisRank() ? 1 : 0);
    const std::vector<std::uint8_t>* blocks = view ? &ownedBlocks : nullptr;
    const ReseedCounts counts =
        scene_.reseed ? reseedParticles<kSimDim>(layout, particles_, liquidPhi, u, perAxis * perAxis * perAxis,
                                                 scene_.seed ^ (std::uint64_t(steps_) << 24), &walls, blocks)
                      : countDeepParticles<kSimDim>(layout, particles_.x, liquidPhi, blocks);
    stats.added += overRanks(counts.added);
    stats.removed += overRanks(counts.removed);
    const std::size_t deepCells = overRanks(counts.deepCells), deepParticles = overRanks(counts.deepParticles);
    if (deepCells > 0) stats.deepDensity = double(deepParticles) / (double(deepCells) * perAxis * perAxis * perAxis);
  });
  timed(stats, Stage::Advect, [&] {
    advectRK2<kSimDim>(layout, u, particles_, dt, &walls);
    keepInsideDomain(stats);
    if (solids_) {
      solids_->setTime(time_ + dt);  // the particles' new positions against the solids' new ones
      pushOutOfSolid<kSimDim>(particles_, *solids_, [this](const Vec3d& x) { return solids_->velocityAt(x); },
                              domain_.dx);
    }
  });
  std::size_t nonFinite = particles_.size();
  for (std::size_t p = 0; p < particles_.size() && nonFinite == particles_.size(); ++p)
    if (!std::isfinite(particles_.x[p].x() + particles_.x[p].y() + particles_.x[p].z() + particles_.v[p].x() +
                       particles_.v[p].y() + particles_.v[p].z()))
      nonFinite = p;
  if (overRanks(nonFinite == particles_.size() ? 0 : 1) > 0)
    throw SimulationError("stage advect: non-finite position or velocity of " +
                          (nonFinite < particles_.size() ? "particle " + std::to_string(nonFinite) : std::string("a particle on another rank")));
  // From here on the step cannot fail: what a retry's roll-back (rollBackPoint) does not restore
  // -- the warm start, the tile history and the coil measure -- changes only now.
  if (scene_.solver.warmStart) {
    grid.passTo(warm_);
    if (view) moveWarmStart(view->blocks, true);  // the blocks this rank owns, exact there
  }
  tileHistory_->advance();

  double energy = 0.0;
  Vec3d mean(0.0);
  if (byRanks_) {  // exact sums: the same bits for any rank count
    // units: 2^-20 m^2/s^2 of |v|^2 and 2^-24 m/s of v, so that 10^7 particles at 100 m/s fit
    ExactSum e(0x1.0p-20), m[3] = {ExactSum(0x1.0p-24), ExactSum(0x1.0p-24), ExactSum(0x1.0p-24)};
    for (const Vec3d& v : particles_.v) {
      e.add(v.lengthSqr());
      for (int a = 0; a < 3; ++a) m[a].add(v[a]);
    }
    energy = e.overRanks().value();
    for (int a = 0; a < 3; ++a) mean[a] = m[a].overRanks().value();
  } else {
    for (const Vec3d& v : particles_.v) {
      energy += v.lengthSqr();
      mean += v;
    }
  }
  stats.kineticEnergy = 0.5 * particleMass() * energy;
  stats.particles = overRanks(particles_.size());
  if (stats.particles > 0)
    for (int a = 0; a < 3; ++a) stats.meanVelocity[a] = mean[a] / double(stats.particles);
  if (coil_) {
    coil_->update(particles_, byRanks_);
    stats.coilDegrees = coil_->sweptDegrees();
    if (std::isfinite(coil_->radius())) stats.coilRadius = coil_->radius();
  }
  time_ += dt;
  lastDt_ = dt;
  ++steps_;
  stats.t = time_;
  stats.times.total = solver::secondsSince(start);
  return stats;
}

}  // namespace step
}  // namespace stokes::sim
