#pragma once
// The time loop (thesis Algorithm 1 around the Stokes step of Algorithm 2). One step:
//
//   emit          active emitters seed what entered them since the last step (scenes with
//                 emitters only); the solve prescribes their velocity (GridStep::setInflow)
//   levelset      liquid level set from the particles (sim/geometry/geometry.h), its surface moved to the
//                 volume the particles carry (keep_volume)
//   layout        BlockLayout over the particles' cells plus a band, clipped to the domain
//   weights       W_L from the level set; W_F from the solids (scenes with solids only)
//   p2g           APIC particle-to-grid transfer into u*
//   gravity       u* += g dt (scenes with gravity only)
//   stokes | viscosity + pressure | pressure
//                 the solve the scene names: coupled = unified Stokes, decoupled = viscosity then
//                 projection, none (or mu = 0) = projection only (no stress unknowns, no
//                 stress weights); the liquid's divergence target is the volume control's
//                 (volume_control: the raw particle surface's volume error, k of it per step)
//   extrapolate   face velocities beyond the liquid (3 layers)
//   g2p           APIC grid-to-particle transfer
//   reseed        keep particles per cell between target/2 and 3 target/2
//   advect        RK2 through the grid velocity; particles kept inside the domain and out of solids
//
// Time steps: dt = cfl dx / (v_max + sqrt(|g| dx)) (v_max over particles and emitters; the sqrt
// term bounds the first steps from rest), and a frame of 1/fps is split into n = ceil(remaining /
// dt_cfl) equal substeps, at most max_substeps per frame (then the CFL number exceeds cfl; the
// statistics record it).
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sim/step/coil_measure.h"
#include "sim/geometry/geometry.h"
#include "sim/particles/particles.h"
#include "sim/ranks/particle_exchange.h"
#include "sim/ranks/rank_blocks.h"
#include "sim/scene/scene.h"
#include "sim/step/simulator_state.h"
#include "sim/step/stages.h"
#include "sim/step/stokes_stage.h"

namespace stokes::sim {
inline namespace step {

struct StepStats {
  int frame = 0;  ///< frame being computed (1-based: frame k ends at t = k / fps)
  int step = 0;   ///< step index over the whole run (0-based)
  double t = 0.0;   ///< simulated time at the end of the step
  double dt = 0.0;
  double cflNumber = 0.0;  ///< v_max dt / dx
  std::vector<Stage> stages;  ///< stages that ran, in order
  StageTimes times;
  GridStepReport grid;
  std::size_t particles = 0, added = 0, removed = 0;
  /// Particles per deep liquid cell (centre deeper than dx) over the per-cell target, before
  /// reseeding: 1 where advection kept the particles' density (ReseedCounts).
  double deepDensity = 0.0;
  double kineticEnergy = 0.0;  ///< sum over particles of 1/2 m_p |v_p|^2, m_p = rho dx^3 / per-cell target
  double liquidVolume = 0.0;  ///< Simulator::liquidVolume of the step's level set (before advection)
  double volumeTarget = 0.0;  ///< Simulator::volumeTarget at the step's start
  double surfaceOffset = 0.0;  ///< keep_volume: the surface's move along its normal, in cells (> 0 out)
  double levelSetVolume = 0.0;  ///< the same level set's volume unclipped (levelSetVolume)
  double rawVolume = 0.0;  ///< the clipped volume of the particle surface before keep_volume's move
  double divergenceTarget = 0.0;  ///< volume control: the solve's div u = s on liquid cells (1/s)
  int retryLevel = 0;  ///< times this step's dt was halved after a failed attempt (0: first try)
  std::vector<std::string> failedAttempts;  ///< what each failed attempt before this step said
  std::optional<double> coilDegrees, coilRadius;  ///< scenes with a disc emitter
  double meanVelocity[3] = {0.0, 0.0, 0.0};       ///< mean particle velocity after the step
};

/// Whether a scene's steps are split over the MPI ranks by blocks (Simulator::splitOverRanks):
/// the PETSc backend on a scene without reduced tiles or a decoupled solve.
bool splitsOverRanks(const Scene& scene);

class Simulator {
 public:
  /// Seeds the initial liquid, reads the solid meshes and builds the solid field. Throws
  /// std::runtime_error (e.g. an unreadable mesh) before any step runs.
  explicit Simulator(Scene scene);

  const Scene& scene() const { return scene_; }
  const DomainBox& domain() const { return domain_; }
  double time() const { return time_; }
  int stepsTaken() const { return steps_; }
  /// The particles; in a run split over ranks (splitOverRanks), those of this rank's blocks.
  const ParticleSet<kSimDim>& particles() const { return particles_; }
  ParticleSet<kSimDim>& particles() { return particles_; }
  /// Whether the steps are split over the MPI ranks by blocks (docs/petsc.md, "Particles by
  /// block"): the PETSc backend on a scene without reduced tiles or a decoupled solve.
  /// Each rank then holds the particles of the blocks it owns, builds its part of the level set,
  /// the layout, the weights and u*, solves it with the others, and moves its particles; the calls
  /// below that read or change the state are collective.
  bool splitOverRanks() const { return byRanks_; }
  /// All particles, on rank 0 (a run split over ranks gathers them there; collective), else
  /// particles(): what a frame writes.
  ParticleSet<kSimDim> gatheredParticles() const;
  /// The solid union, or null when the scene has no solids.
  const ShapeField* solids() const { return solids_.get(); }
  /// The liquid level set of the current particles, eroded by the seeding's face bulge
  /// (seededFaceBulge, measured once per seeding density). With the scene's keep_volume (default) its
  /// surface is moved along the normal by the one distance that makes its clipped volume the
  /// volume the particles carry (volumeTarget; geometry.h matchClippedVolume), at most half a cell;
  /// `match` receives that offset and the volume. Split over ranks: the whole level set on rank 0
  /// and null on the others (collective; `match` on every rank).
  openvdb::FloatGrid::Ptr liquidLevelSet(VolumeMatch* match = nullptr) const;

  /// The liquid volume the particles carry: dx^3 / (per-cell target) for each particle seeded into
  /// the initial liquid or emitted, less those that left through the open top. Reseeding adds and
  /// removes particles without changing it (it fills holes the flow left, and thins clumps).
  double volumeTarget() const { return volumeTarget_; }

  /// Volume of a liquid level set inside the domain box and outside the solids
  /// (levelSetVolumeClipped): the volume stats.csv and the run summary report.
  double liquidVolume(const openvdb::FloatGrid& liquid) const;
  /// The region the liquid may fill, as a signed distance: max(box, -solids) (< 0 inside).
  std::function<double(const Vec3d&)> liquidClip() const;

  /// Largest step the CFL condition allows now.
  double cflTimeStep() const;
  /// One step of exactly dt, counted in frame `frame`. Throws SimulationError naming the step,
  /// the stage and (where known) the face.
  StepStats step(double dt, int frame);
  /// Steps to the end of frame `frame` (t = frame / fps, frame >= 1); onStep after every step.
  /// When `stop` returns true after a substep, returns false there, mid-frame; a later call for
  /// the same frame (or on a restored state) continues with the frame's remaining substeps.
  /// The solves poll `stop` once per Krylov iteration too: a step it stops is rolled back to where
  /// it began and StepInterrupted is thrown, which leaves the same state as a stop after the
  /// substep before. Returns true when the frame is complete. A failed step is retried (see the
  /// top of this file).
  bool advanceFrame(int frame, const std::function<void(const StepStats&)>& onStep = {},
                    const std::function<bool()>& stop = {});

  /// The state a checkpoint holds (sim/step/simulator_state.h), and its restoration: a simulator of
  /// the same scene restored from it takes the same steps, bit for bit, as the one it came from.
  SimulatorState state() const;
  /// Throws std::invalid_argument naming what does not fit the scene.
  void restore(const SimulatorState& state);

 private:
  StepStats stepStages(double dt, int frame);
  /// The time, counters and particles: what a failed step may have changed (a step changes the
  /// warm start and the coil measure only once it cannot fail any more).
  SimulatorState rollBackPoint() const;
  void rollBack(const SimulatorState& s);
  /// step(dt), rolled back and taken as two steps of dt/2 when it fails, down to
  /// scene.solver.retries halvings; onStep after each step that succeeded.
  void stepRetrying(double dt, int frame, int level, const std::function<void(const StepStats&)>& onStep,
                    std::vector<std::string>& failures);
  void emit(StepStats& stats);
  void keepInsideDomain(StepStats& stats);
  /// The volume control's divergence target for a step of dt whose raw particle surface holds
  /// `volume` (Scene::volumeControl; 0 when off or before any liquid).
  double volumeControlDivergence(double volume, double dt) const;
  double particleMass() const;
  double particleVolume() const;  ///< dx^3 / (per-cell target)
  /// The level set of `positions` with the volume match, over the voxels `owned` accepts summed
  /// over the ranks when given (sim/ranks/rank_volume.h).
  openvdb::FloatGrid::Ptr levelSetOf(const std::vector<Vec3d>& positions, VolumeMatch* match,
                                     const std::function<bool(const openvdb::Coord&)>& owned) const;
  /// A step split over ranks: the step's blocks and owners (`blocks`), and this rank's particles
  /// with the other ranks' near its blocks (ghostParticles; canonical order). Collective.
  struct RankView {
    RankBlocks blocks;
    ParticleSet<kSimDim> withGhosts;   ///< with the ghosts' state (kGhostStateReachCells): P2G's
    std::vector<Vec3d> surface;        ///< every position the level set reads (kGhostReachCells)
    std::size_t sentBytes = 0;
  };
  RankView rankView(RankBlocks blocks) const;
  /// Split over ranks: the warm start's blocks to their owners in `now` -- those this rank owns in
  /// `now` only (`ownedOnly`: the end of a step), or all it keeps (the next step's start) -- so that
  /// each rank's part of the solve starts where one rank's would. Collective.
  /// Returns the bytes this rank sent.
  std::size_t moveWarmStart(const RankBlocks& now, bool ownedOnly);
  /// The blocks of a step from every rank's particles (gatherRankBlocks). Collective.
  RankBlocks stepBlocks() const;
  CellIndex cellIndex() const { return {domain_.dx, domain_.min}; }
  /// sumOverRanks in a run split over ranks, else v.
  std::size_t overRanks(std::size_t v) const { return byRanks_ ? std::size_t(sumOverRanks(std::int64_t(v))) : v; }

  Scene scene_;
  DomainBox domain_;
  StokesPlan plan_;
  /// The previous step's tiling, shared with plan_'s reduced options (solver/reduced/tile_history.h).
  std::shared_ptr<solver::TileHistory> tileHistory_ = std::make_shared<solver::TileHistory>();
  WarmStart<kSimDim> warm_;  ///< the previous step's pressure and stresses (scene solver.warm_start)
  ParticleSet<kSimDim> particles_;
  std::unique_ptr<ShapeField> solids_;
  std::optional<CoilMeasure> coil_;
  double volumeTarget_ = 0.0;
  double faceBulge_ = 0.0;  ///< seededFaceBulge of the scene's seeding, cells: the surface's extra erosion
  double time_ = 0.0;
  double lastDt_ = 0.0;  ///< the previous step's dt (0 before the first step): what emitters refill
  int steps_ = 0;
  int frame_ = 0;          ///< the frame advanceFrame last worked on
  int frameSubsteps_ = 0;  ///< substeps taken in it
  bool byRanks_ = false;   ///< splitOverRanks
  /// After a retried step, the dt that passed: later steps start there (doubling back per step).
  double retryDtLimit_ = std::numeric_limits<double>::infinity();
};

}  // namespace step
}  // namespace stokes::sim
