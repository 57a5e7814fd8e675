#pragma once
// The files of one frame of a run (sim/run/scene_runner.h): DIR/frame_NNNN.vdb (the liquid level
// set "surface", the velocity "vel", plus the particles when the scene asks), frame_NNNN.ply (the surface mesh with vertex velocities from "vel", output.mesh) and
// frame_NNNN.png (the preview, output.preview), each written atomically.
#include "sparse_grid/vdb_trees.h"

#include <string>

#include "sim/output/png_preview.h"
#include "sim/output/vdb_frame.h"
#include "sim/output/surface_mesh.h"
#include "sim/step/simulator.h"

namespace stokes::sim {
inline namespace output {

/// DIR/frame_NNNN.EXT
std::string framePath(const std::string& dir, int frame, const char* ext);

/// Writes the frames of one simulator into one folder.
class FrameWriter {
 public:
  FrameWriter(const Simulator& sim, std::string dir);

  /// The level set and the particles of the simulator's state now, for a step that failed.
  void writeFailedState(const std::string& path) const;

  /// Writes frame `frame` of the simulator's state now; returns the liquid volume of the frame.
  double write(int frame) const;

 private:
  UpAxis upAxis() const { return sim_.scene().output.zUp ? UpAxis::Z : UpAxis::Y; }
  // A frame's grids: the surface, "vel" from the particles, the points grid when `points`.
  FrameGrids grids(const openvdb::FloatGrid::Ptr& liquid, const ParticleSet<kSimDim>& particles, int frame,
                   bool points) const;
  openvdb::BBoxd domainBBox() const { return {sim_.domain().min, sim_.domain().max}; }
  const Simulator& sim_;
  std::string dir_;
  mutable openvdb::FloatGrid::Ptr solidGrid_;  // re-rendered per frame when solids move
  PreviewCamera camera_;
};

}  // namespace output
}  // namespace stokes::sim
