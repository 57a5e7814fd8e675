#pragma once
// Everything the time loop carries from one step to the next that the scene file does not fix:
// the checkpoint's content (sim/run/checkpoint.h) and the roll-back point of a retried step
// (Simulator::advanceFrame). The random draws of emitters and reseeding are seeded from the scene's
// seed and the step index, so `steps` is the random state.
#include <cstdint>
#include <limits>
#include <optional>
#include <vector>

#include "sim/step/coil_measure.h"
#include "sim/particles/particles.h"
#include "solver/krylov/aligned_vector.h"
#include "solver/reduced/tile_history.h"

namespace stokes::sim {
inline namespace step {

/// The warm start's kept solve (sim/step/warm_start.h): its layout as block origins and per-slot
/// active flags (a BlockLayout rebuilt from those cells has the same blocks in the same order).
struct WarmStartState {
  double dx = 0.0;
  Vec3d origin{0.0};
  std::vector<Coord> blockOrigins;
  std::vector<std::uint8_t> activeSlots;  ///< numBlocks * kSlots flags
  solver::Vector solution;
};

struct SimulatorState {
  double time = 0.0;
  double lastDt = 0.0;        ///< the previous step's dt (what emitters refill)
  double volumeTarget = 0.0;  ///< the volume the particles carry
  std::int64_t steps = 0;     ///< steps taken: also the random state
  int frame = 0;              ///< the frame advanceFrame last worked on (0: none yet)
  int frameSubsteps = 0;      ///< substeps taken in it
  /// Simulator::advanceFrame's dt limit after a retried step (infinity: none).
  double retryDtLimit = std::numeric_limits<double>::infinity();
  ParticleSet<3> particles;
  std::optional<WarmStartState> warm;
  std::optional<CoilMeasure::State> coil;
  /// The previous step's tiling (solver/reduced/tile_history.h); empty for a uniform model.
  solver::TileHistory::State tileHistory;
};

}  // namespace step
}  // namespace stokes::sim
