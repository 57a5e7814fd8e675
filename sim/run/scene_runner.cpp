// A whole run of a scene: see scene_runner.h.
#include "sim/run/scene_runner.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <ostream>

#include <fstream>
#include <sstream>

#include "sim/run/checkpoint.h"
#include "sim/output/frame_writer.h"
#include "sim/ranks/rank_comm.h"
#include "sim/output/stats_csv.h"
#include "sim/run/run_progress.h"
#include "solver/krylov/stopwatch.h"

namespace stokes::sim {
inline namespace run {

namespace {

/// The stats.csv column of a stage's seconds.
std::string stageColumn(Stage stage) { return std::string(stageName(stage)) + "_s"; }

}  // namespace


std::vector<std::pair<std::string, double>> statsRow(const StepStats& s) {
  std::vector<std::pair<std::string, double>> row = {
      {"frame", s.frame}, {"step", s.step}, {"t", s.t}, {"dt", s.dt}, {"cfl", s.cflNumber},
      {"particles", double(s.particles)}, {"added", double(s.added)}, {"removed", double(s.removed)},
      {"cells", double(s.grid.cells)}, {"unknowns", double(s.grid.unknowns)},
      {"stress_unknowns", double(s.grid.stressUnknowns)}, {"krylov_rows", double(s.grid.krylovRows)},
      {"stencil_slots", double(s.grid.stencilSlots)}, {"iterations", s.grid.iterations},
      {"krylov_s", s.grid.krylovSeconds}, {"setup_s", s.grid.setupSeconds},
      {"relative_residual", s.grid.relativeResidual}, {"tiles", double(s.grid.tiles)},
      {"fallback_tiles", double(s.grid.fallbackTiles)}, {"partial_tiles", double(s.grid.partialTiles)},
      {"unpaid_tiles", double(s.grid.unpaidTiles)}, {"kept_tiles", double(s.grid.keptTiles)},
      {"sent_bytes", double(s.grid.sentBytes)},
      {"tile_unknowns", double(s.grid.tileDofs)}, {"fluid_weights", s.grid.builtFluidWeights ? 1.0 : 0.0},
      {"kinetic_energy", s.kineticEnergy}, {"liquid_volume", s.liquidVolume}, {"volume_target", s.volumeTarget},
      {"surface_offset", s.surfaceOffset}, {"raw_volume", s.rawVolume}, {"divergence_target", s.divergenceTarget},
      {"retry_level", double(s.retryLevel)},
      {"levelset_volume", s.levelSetVolume}, {"deep_density", s.deepDensity}, {"step_s", s.times.total}};
  for (const Stage stage : kStages)
    if (s.times[stage]) row.emplace_back(stageColumn(stage), *s.times[stage]);
  if (s.coilDegrees) row.emplace_back("coil_angle_deg", *s.coilDegrees);
  if (s.coilRadius) row.emplace_back("coil_radius", *s.coilRadius);
  return row;
}

std::vector<std::string> statsColumns() {
  std::vector<std::string> columns = {"frame",           "step",        "t",           "dt",
                                      "cfl",             "particles",   "added",       "removed",
                                      "cells",           "unknowns",    "stress_unknowns", "krylov_rows",
                                      "stencil_slots",   "iterations",  "relative_residual", "krylov_s", "setup_s",
                                      "solver",          "tiles",       "fallback_tiles", "partial_tiles",
                                      "unpaid_tiles",    "kept_tiles",  "tile_unknowns",  "fluid_weights",
                                      "sent_bytes"};
  for (const Stage stage : kStages) columns.push_back(stageColumn(stage));
  for (const char* c : {"step_s", "kinetic_energy", "liquid_volume", "volume_target", "surface_offset", "raw_volume",
                        "divergence_target", "retry_level", "levelset_volume", "deep_density", "coil_angle_deg",
                        "coil_radius"})
    columns.push_back(c);
  return columns;
}

std::string runSignature(const Scene& scene, const std::string& options) {
  std::string text = "scene " + scene.name + "\n";
  if (!scene.sourcePath.empty()) {
    std::ifstream in(scene.sourcePath, std::ios::binary);
    std::ostringstream body;
    body << in.rdbuf();
    text = body.str();
  }
  return text + "\n--- options: " + options;
}

namespace {

/// The checkpoint to resume from: the newest readable one whose signature is the run's.
RunCheckpoint checkpointToResume(const RunOptions& options, const std::string& signature, RunProgressLine& line) {
  std::vector<std::string> notes;
  auto found = findNewestCheckpoint(options.outDir, &notes);
  for (const std::string& n : notes) line.note("resume: " + n);
  if (!found)
    throw ResumeError("resume: no complete checkpoint in '" + checkpointFolder(options.outDir) +
                      "' (run without --resume to start from frame 0)");
  if (found->second.signature != signature)
    throw ResumeError("resume: checkpoint '" + found->first +
                      "' belongs to another run: the scene file's text or the command line's options "
                      "(other than --frames and --threads) differ from the run's");
  line.note("resume: from " + found->first + " (step " + std::to_string(found->second.state.steps) + ", t = " +
            std::to_string(found->second.state.time) + " s, frames 0-" +
            std::to_string(found->second.progress.framesWritten) + " written)");
  return std::move(found->second);
}

}  // namespace

namespace {

/// Where rank `rank` of a run split over ranks keeps its checkpoints: DIR (rank 0), else
/// DIR/ranks/rank_RRRR.
std::string rankFolder(const std::string& outDir, int rank) {
  if (rank == 0) return outDir;
  char name[32];
  std::snprintf(name, sizeof name, "rank_%04d", rank);
  return (std::filesystem::path(outDir) / "ranks" / name).string();
}

}  // namespace

RunSummary runScene(const Scene& scene, const RunOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  std::filesystem::create_directories(options.outDir);
  Simulator sim(scene);
  // Split over ranks, every rank runs the scene: rank 0 writes the frames, the statistics and
  // the progress; each rank keeps its own checkpoints (its particles), and the signature names
  // the rank count, so that a resume needs the same one.
  const bool split = sim.splitOverRanks();
  const bool writes = !split || thisRank() == 0;
  const std::string signature =
      runSignature(scene, options.signature + (split ? " ranks=" + std::to_string(rankCount()) : std::string()));
  RunOptions own = options;
  if (split) {
    own.outDir = rankFolder(options.outDir, thisRank());
    std::filesystem::create_directories(own.outDir);
    if (!writes) own.progress = nullptr;
    if (options.stopRequested)  // every rank stops at the same step
      own.stopRequested = [stop = options.stopRequested] { return maxOverRanks(stop() ? 1.0 : 0.0) > 0.0; };
  }
  const std::string csvPath = (std::filesystem::path(options.outDir) / "stats.csv").string();
  const FrameWriter writer(sim, options.outDir);
  RunSummary summary;
  RunProgress progress;
  std::optional<StatsCsv> csv;  // (optional: its two constructors need the resume decision)
  std::optional<RunProgressLine> line;
  if (options.resume) {
    RunProgressLine notes(own.progress, options.progressIsTerminal, scene.name, scene.frames, 0.0, 0.0);
    const RunCheckpoint checkpoint = checkpointToResume(own, signature, notes);
    if (split && maxOverRanks(double(checkpoint.state.steps)) != -maxOverRanks(-double(checkpoint.state.steps)))
      throw ResumeError("resume: the ranks' newest checkpoints are of different steps (one rank's last write did not "
                        "finish); remove the newest on the ranks ahead (" + checkpointFolder(own.outDir) + ")");
    sim.restore(checkpoint.state);
    progress = checkpoint.progress;
    summary.resumedFromStep = int(checkpoint.state.steps);
    if (writes) csv.emplace(StatsCsv::resume(csvPath, statsColumns(), "step", double(checkpoint.state.steps)));
    summary.initialVolume = progress.initialVolume;
    summary.finalVolume = progress.initialVolume;
    summary.maxIterations = progress.maxIterations;
    summary.frames = progress.framesWritten;
  } else {
    if (writes) csv.emplace(csvPath, statsColumns());
    progress.initialVolume = summary.initialVolume = summary.finalVolume = writer.write(0);
  }
  line.emplace(own.progress, options.progressIsTerminal, scene.name, scene.frames, scene.duration(), sim.time());
  auto checkpoint = [&] {
    progress.maxIterations = summary.maxIterations;
    summary.lastCheckpoint = writeCheckpoint(own.outDir, {signature, progress, sim.state()});
  };
  auto finish = [&] {
    line->finish();
    summary.stepsTotal = sim.stepsTaken();
    summary.stageSeconds = line->stageSeconds();
    summary.peakResidentBytes = peakResidentBytes();
    summary.wallSeconds = solver::secondsSince(start);
  };
  const int every = scene.output.checkpointEvery;
  for (int frame = progress.framesWritten + 1; frame <= scene.frames; ++frame) {
    bool complete = false;
    try {
      complete = sim.advanceFrame(
          frame,
          [&](const StepStats& s) {
            if (csv) csv->row(statsRow(s), {{"solver", s.grid.solver}});
            summary.maxIterations = std::max(summary.maxIterations, s.grid.iterations);
            ++summary.steps;
            if (s.retryLevel > 0) ++summary.retriedSteps;
            line->step(s);
            if (options.onStep) options.onStep(s);
          },
          own.stopRequested);
    } catch (const StepInterrupted&) {
      complete = false;  // stopped inside a solve: the simulator is back where that step began
    } catch (const SimulationError& e) {
      // the simulator is back at its last good state (Simulator::advanceFrame): keep it
      line->finish();
      std::string kept;
      try {
        checkpoint();
        char name[48];
        std::snprintf(name, sizeof name, "failed_step_%09d.vdb", sim.stepsTaken());
        const std::string path = (std::filesystem::path(options.outDir) / name).string();
        writer.writeFailedState(path);
        kept = "; the last good state is in " + summary.lastCheckpoint + " and " + path;
      } catch (const std::exception& io) {
        kept = std::string("; could not keep the last good state: ") + io.what();
      }
      throw SimulationError(e.what() + kept);
    }
    if (!complete) {  // stopped on request, mid-frame
      checkpoint();
      summary.stopped = true;
      break;
    }
    summary.finalVolume = writer.write(frame);
    summary.frames = frame;
    progress.framesWritten = frame;
    line->frameWritten(frame, sim.time());
    if (own.stopRequested && own.stopRequested()) {
      checkpoint();
      summary.stopped = true;
      break;
    }
    if (every > 0 && (frame % every == 0 || frame == scene.frames)) checkpoint();
  }
  finish();
  return summary;
}

}  // namespace run
}  // namespace stokes::sim
