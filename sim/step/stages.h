#pragma once
// The stages of one simulation step, in the order they run (docs/design.md §1). This list drives
// the step's timing (StageTimes), the stats.csv columns "<name>_s" (sim/output/stats_csv.h via
// sim/run/scene_runner.cpp), the stage list of a step and the run's summary line. A new stage is
// one enumerator and one name here.
#include <array>
#include <cstddef>
#include <optional>

namespace stokes::sim {
inline namespace step {

enum class Stage {
  Emit,         ///< active emitters seed what entered them
  Migrate,      ///< a step split over ranks: the blocks' owners, particles to them, ghosts near them
  LevelSet,     ///< the liquid level set from the particles
  Layout,       ///< the grid's block layout around the particles
  Weights,      ///< volume weights (liquid, solids, walls)
  P2G,          ///< APIC particle-to-grid transfer into u*
  Gravity,      ///< u* += g dt
  Stokes,       ///< the unified Stokes solve
  Viscosity,    ///< the decoupled viscosity solve
  Pressure,     ///< the pressure projection
  Extrapolate,  ///< face velocities extended past the liquid for G2P and advection
  G2P,          ///< APIC grid-to-particle transfer
  Reseed,       ///< particles per cell kept near the target
  Advect,       ///< RK2 advection, domain and solid boundaries
};

inline constexpr std::size_t kStageCount = std::size_t(Stage::Advect) + 1;

/// Every stage in running order.
inline constexpr std::array<Stage, kStageCount> kStages = {
    Stage::Emit,    Stage::Migrate,   Stage::LevelSet, Stage::Layout,      Stage::Weights, Stage::P2G,    Stage::Gravity,
    Stage::Stokes,  Stage::Viscosity, Stage::Pressure, Stage::Extrapolate, Stage::G2P,     Stage::Reseed, Stage::Advect};

/// The stage's name in the stage list, stats.csv ("<name>_s") and the summary line.
constexpr const char* stageName(Stage s) {
  switch (s) {
    case Stage::Emit: return "emit";
    case Stage::Migrate: return "migrate";
    case Stage::LevelSet: return "levelset";
    case Stage::Layout: return "layout";
    case Stage::Weights: return "weights";
    case Stage::P2G: return "p2g";
    case Stage::Gravity: return "gravity";
    case Stage::Stokes: return "stokes";
    case Stage::Viscosity: return "viscosity";
    case Stage::Pressure: return "pressure";
    case Stage::Extrapolate: return "extrapolate";
    case Stage::G2P: return "g2p";
    case Stage::Reseed: return "reseed";
    case Stage::Advect: return "advect";
  }
  return "?";  // not reached: -Wswitch names a missing stage
}

/// Wall time of the stages that ran in a step (seconds; a stage that did not run stays unset).
struct StageTimes {
  std::array<std::optional<double>, kStageCount> seconds{};
  double total = 0.0;  ///< the whole step

  std::optional<double>& operator[](Stage s) { return seconds[std::size_t(s)]; }
  const std::optional<double>& operator[](Stage s) const { return seconds[std::size_t(s)]; }
  /// Adds `t` seconds to stage `s` (a stage that runs twice in a step, e.g. a retried solve).
  void add(Stage s, double t) { (*this)[s] = (*this)[s].value_or(0.0) + t; }
};

}  // namespace step
}  // namespace stokes::sim
