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
#include "sim/output/stats_csv.h"
#include "sim/run/run_progress.h"
#include "solver/krylov/stopwatch.h"

namespace stokes::sim {
inline namespace run {

namespace {

/// The stats.csv column of a stage's seconds.
std::string stageColumn(Stage stage) { return std::string(stageName(stage)) + "_s"; }

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

}  // namespace

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

RunSummary runScene(const Scene& scene, const RunOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  std::filesystem::create_directories(options.outDir);
  const std::string signature = runSignature(scene, options.signature);
  Simulator sim(scene);
  const std::string csvPath = (std::filesystem::path(options.outDir) / "stats.csv").string();
  const FrameWriter writer(sim, options.outDir);
  RunSummary summary;
  RunProgress progress;
  std::optional<StatsCsv> csv;  // (optional: its two constructors need the resume decision)
  std::optional<RunProgressLine> line;
  if (options.resume) {
    RunProgressLine notes(options.progress, options.progressIsTerminal, scene.name, scene.frames, 0.0, 0.0);
    const RunCheckpoint checkpoint = checkpointToResume(options, signature, notes);
    sim.restore(checkpoint.state);
    progress = checkpoint.progress;
    summary.resumedFromStep = int(checkpoint.state.steps);
    csv.emplace(StatsCsv::resume(csvPath, statsColumns(), "step", double(checkpoint.state.steps)));
    summary.initialVolume = progress.initialVolume;
    summary.finalVolume = progress.initialVolume;
    summary.maxIterations = progress.maxIterations;
    summary.frames = progress.framesWritten;
  } else {
    csv.emplace(csvPath, statsColumns());
    progress.initialVolume = summary.initialVolume = summary.finalVolume = writer.write(0);
  }
  line.emplace(options.progress, options.progressIsTerminal, scene.name, scene.frames, scene.duration(), sim.time());
  auto checkpoint = [&] {
    progress.maxIterations = summary.maxIterations;
    summary.lastCheckpoint = writeCheckpoint(options.outDir, {signature, progress, sim.state()});
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
            csv->row(statsRow(s), {{"solver", s.grid.solver}});
            summary.maxIterations = std::max(summary.maxIterations, s.grid.iterations);
            ++summary.steps;
            if (s.retryLevel > 0) ++summary.retriedSteps;
            line->step(s);
            if (options.onStep) options.onStep(s);
          },
          options.stopRequested);
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
    if (options.stopRequested && options.stopRequested()) {
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
