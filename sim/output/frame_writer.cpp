#include "sim/output/frame_writer.h"

#include <cstdio>
#include <filesystem>

#include "sim/output/vdb_frame.h"

namespace stokes::sim {
inline namespace output {

std::string framePath(const std::string& dir, int frame, const char* ext) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%04d.%s", frame, ext);
  return (std::filesystem::path(dir) / name).string();
}

FrameWriter::FrameWriter(const Simulator& sim, std::string dir) : sim_(sim), dir_(std::move(dir)) {
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

FrameGrids FrameWriter::grids(const openvdb::FloatGrid::Ptr& liquid, const ParticleSet<kSimDim>& particles, int frame,
                              bool points) const {
  FrameGrids g;
  g.surface = liquid;
  g.positions = &particles.x;
  g.velocities = &particles.v;
  g.points = points;
  g.info = {sim_.time(), frame, sim_.scene().name};
  g.up = upAxis();
  return g;
}

void FrameWriter::writeFailedState(const std::string& path) const {
  const openvdb::FloatGrid::Ptr liquid = sim_.liquidLevelSet();
  const ParticleSet<kSimDim> particles = sim_.gatheredParticles();
  if (liquid) writeFrameVdb(path, grids(liquid, particles, -1, true));
}

double FrameWriter::write(int frame) const {
  // Split over ranks, rank 0 receives the whole liquid and the particles (for "vel") and writes.
  VolumeMatch match;
  const openvdb::FloatGrid::Ptr liquid = sim_.liquidLevelSet(&match);
  const OutputDesc& out = sim_.scene().output;
  const ParticleSet<kSimDim> particles = sim_.gatheredParticles();
  if (!liquid) return match.volume;
  FrameGrids g = grids(liquid, particles, frame, out.particles);
  const openvdb::Vec3SGrid::Ptr vel = particleVelocityGrid(particles.x, particles.v, *liquid);  // once: vdb and mesh
  g.velocity = vel;
  writeFrameVdb(framePath(dir_, frame, "vdb"), g);
  if (out.mesh) {
    SurfaceMesh mesh = meshLevelSet(*liquid, out.meshSubdivisions);
    sampleVertexVelocities(mesh, *vel);
    applyUpAxis(mesh, upAxis());
    writePly(framePath(dir_, frame, "ply"), mesh);
  }
  if (out.preview && sim_.solids() && sim_.solids()->moving())
    solidGrid_ = sim_.solids()->toLevelSet(domainBBox());  // where the solids are now
  if (out.preview) {
    const openvdb::BBoxd box = domainBBox();
    renderPreviewPng(framePath(dir_, frame, "png"), *liquid, solidGrid_.get(), camera_, out.previewWidth,
                     out.previewHeight, PreviewStyle{}, &box);
  }
  return match.volume;
}

}  // namespace output
}  // namespace stokes::sim
