#pragma once
// Checkpoints of a run (`stokesvdb run --resume`): the simulator's state (sim/step/simulator_state.h)
// and where the run stood, in one binary file per checkpoint,
//
//   DIR/checkpoints/step_SSSSSSSSS.ckpt
//
// written to a temporary name, flushed to disk (fsync) and renamed, so a file under its final name
// is always complete. The file ends in a 64-bit FNV-1a checksum of everything before it; a file
// that fails it (a disk that lied about the fsync) is skipped by findNewestCheckpoint with a note.
//
// Layout (little-endian, as the machine writes it): the magic "STOKESVDB-CKPT\n", a format version
// (uint32), the run's signature string (the scene file's text and the options that change its
// result, compared on resume), the run progress, the simulator state, the checksum.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "sim/step/simulator_state.h"

namespace stokes::sim {
inline namespace run {

/// Where the run stood when the checkpoint was written.
struct RunProgress {
  int framesWritten = 0;      ///< the last frame file written (frames 0..framesWritten exist)
  double initialVolume = 0.0;  ///< the summary's frame-0 volume
  int maxIterations = 0;       ///< the summary's most iterations in a step
};

struct RunCheckpoint {
  std::string signature;
  RunProgress progress;
  SimulatorState state;
};

/// DIR/checkpoints.
std::string checkpointFolder(const std::string& outDir);

/// Writes `checkpoint` as DIR/checkpoints/step_<steps>.ckpt (atomically, see above) and removes all
/// but the newest `keep` checkpoints. Returns the path. Throws std::runtime_error naming the path
/// (and the system's reason, e.g. a full disk) when it cannot; no partial file is left.
std::string writeCheckpoint(const std::string& outDir, const RunCheckpoint& checkpoint, int keep = 2);

/// Reads one checkpoint file. Throws std::runtime_error naming the path and what is wrong (not a
/// checkpoint, another format version, truncated, checksum mismatch).
RunCheckpoint readCheckpoint(const std::string& path);

/// The newest readable checkpoint in DIR/checkpoints, or none. `notes` receives one line per newer
/// file that was skipped, with the reason.
std::optional<std::pair<std::string, RunCheckpoint>> findNewestCheckpoint(const std::string& outDir,
                                                                          std::vector<std::string>* notes = nullptr);

}  // namespace run
}  // namespace stokes::sim
