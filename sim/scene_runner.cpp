// A whole run of a scene: see scene_runner.h.
#include "sim/scene_runner.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <ostream>

#include "sim/output.h"

namespace stokes::sim {

namespace {

std::string framePath(const std::string& dir, int frame, const char* ext) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%04d.%s", frame, ext);
  return (std::filesystem::path(dir) / name).string();
}

std::string formatDuration(double s) {
  char buf[32];
  if (!std::isfinite(s)) return "?";
  if (s < 60.0) std::snprintf(buf, sizeof buf, "%.0fs", s);
  else if (s < 3600.0) std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  else std::snprintf(buf, sizeof buf, "%dh%02dm", int(s) / 3600, (int(s) % 3600) / 60);
  return buf;
}

/// Writes one frame: level set (+ particles) and the preview.
class FrameWriter {
 public:
  FrameWriter(const Simulator& sim, std::string dir) : sim_(sim), dir_(std::move(dir)) {
    const Scene& scene = sim.scene();
    if (sim.solids()) solidGrid_ = sim.solids()->toLevelSet(domainBBox());
    const OutputDesc& out = scene.output;
    if (out.camera) {
      camera_.eye = out.camera->eye;
      camera_.target = out.camera->target;
    } else {
      camera_ = frameWorldBBox(domainBBox(), double(out.previewWidth) / out.previewHeight);
    }
  }

  /// Returns the liquid volume of the frame.
  double write(int frame) const {
    VolumeMatch match;
    const openvdb::FloatGrid::Ptr liquid = sim_.liquidLevelSet(&match);
    const OutputDesc& out = sim_.scene().output;
    if (out.particles) writeFrameVdb(framePath(dir_, frame, "vdb"), liquid, &sim_.particles().x, &sim_.particles().v);
    else writeFrameVdb(framePath(dir_, frame, "vdb"), liquid);
    if (out.preview && sim_.solids() && sim_.solids()->moving())
      solidGrid_ = sim_.solids()->toLevelSet(domainBBox());  // where the solids are now
    if (out.preview)
      renderPreviewPng(framePath(dir_, frame, "png"), *liquid, solidGrid_.get(), camera_, out.previewWidth,
                       out.previewHeight);
    return match.volume;
  }

 private:
  openvdb::BBoxd domainBBox() const { return {sim_.domain().min, sim_.domain().max}; }
  const Simulator& sim_;
  std::string dir_;
  mutable openvdb::FloatGrid::Ptr solidGrid_;  // re-rendered per frame when solids move
  PreviewCamera camera_;
};

std::vector<std::pair<std::string, double>> statsRow(const StepStats& s) {
  std::vector<std::pair<std::string, double>> row = {
      {"frame", s.frame}, {"step", s.step}, {"t", s.t}, {"dt", s.dt}, {"cfl", s.cflNumber},
      {"particles", double(s.particles)}, {"added", double(s.added)}, {"removed", double(s.removed)},
      {"cells", double(s.grid.cells)}, {"unknowns", double(s.grid.unknowns)},
      {"stress_unknowns", double(s.grid.stressUnknowns)}, {"krylov_rows", double(s.grid.krylovRows)},
      {"stencil_slots", double(s.grid.stencilSlots)}, {"iterations", s.grid.iterations},
      {"krylov_s", s.grid.krylovSeconds},
      {"relative_residual", s.grid.relativeResidual}, {"tiles", double(s.grid.tiles)},
      {"fallback_tiles", double(s.grid.fallbackTiles)}, {"fluid_weights", s.grid.builtFluidWeights ? 1.0 : 0.0},
      {"kinetic_energy", s.kineticEnergy}, {"liquid_volume", s.liquidVolume}, {"volume_target", s.volumeTarget},
      {"surface_offset", s.surfaceOffset}, {"raw_volume", s.rawVolume}, {"divergence_target", s.divergenceTarget},
      {"levelset_volume", s.levelSetVolume}, {"deep_density", s.deepDensity}, {"step_s", s.times.total}};
  const std::pair<const char*, const std::optional<double>*> stages[] = {
      {"emit_s", &s.times.emit},         {"levelset_s", &s.times.levelset},   {"layout_s", &s.times.layout},
      {"weights_s", &s.times.weights},   {"p2g_s", &s.times.p2g},             {"gravity_s", &s.times.gravity},
      {"stokes_s", &s.times.stokes},     {"viscosity_s", &s.times.viscosity}, {"pressure_s", &s.times.pressure},
      {"g2p_s", &s.times.g2p},           {"reseed_s", &s.times.reseed},       {"advect_s", &s.times.advect}};
  for (const auto& [name, value] : stages)
    if (*value) row.emplace_back(name, **value);
  if (s.coilDegrees) row.emplace_back("coil_angle_deg", *s.coilDegrees);
  if (s.coilRadius) row.emplace_back("coil_radius", *s.coilRadius);
  return row;
}

}  // namespace

std::vector<std::string> statsColumns() {
  return {"frame",          "step",         "t",          "dt",          "cfl",           "particles",
          "added",          "removed",
          "cells",          "unknowns",     "stress_unknowns", "krylov_rows", "stencil_slots", "iterations", "relative_residual", "krylov_s", "solver", "tiles",
          "fallback_tiles", "fluid_weights", "emit_s",    "levelset_s",  "layout_s",      "weights_s",
          "p2g_s",          "gravity_s",    "stokes_s",   "viscosity_s", "pressure_s",    "g2p_s",
          "reseed_s",       "advect_s",     "step_s",     "kinetic_energy", "liquid_volume", "volume_target", "surface_offset", "raw_volume", "divergence_target", "levelset_volume", "deep_density", "coil_angle_deg",
          "coil_radius"};
}

RunSummary runScene(const Scene& scene, const RunOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  std::filesystem::create_directories(options.outDir);
  Simulator sim(scene);
  StatsCsv csv((std::filesystem::path(options.outDir) / "stats.csv").string(), statsColumns());
  const FrameWriter writer(sim, options.outDir);
  RunSummary summary;
  summary.initialVolume = writer.write(0);
  summary.finalVolume = summary.initialVolume;
  const double duration = scene.duration();
  for (int frame = 1; frame <= scene.frames; ++frame) {
    sim.advanceFrame(frame, [&](const StepStats& s) {
      csv.row(statsRow(s), {{"solver", s.grid.solver}});
      summary.maxIterations = std::max(summary.maxIterations, s.grid.iterations);
      ++summary.steps;
      if (options.onStep) options.onStep(s);
      if (!options.progress) return;
      const double elapsed =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      const double eta = s.t > 0.0 ? elapsed / s.t * (duration - s.t) : NAN;
      char line[256];
      std::snprintf(line, sizeof line,
                    "[%s] frame %d/%d step %d t=%.4f s dt=%.2e iters=%d particles=%zu | %.1f s elapsed, ETA %s\n",
                    scene.name.c_str(), s.frame, scene.frames, s.step, s.t, s.dt, s.grid.iterations, s.particles,
                    elapsed, formatDuration(eta).c_str());
      *options.progress << line << std::flush;
    });
    summary.finalVolume = writer.write(frame);
    summary.frames = frame;
  }
  summary.wallSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace stokes::sim
