#include "sim/output/vdb_frame.h"

#include <openvdb/io/File.h>
#include <openvdb/points/PointConversion.h>
#include <openvdb/points/PointDataGrid.h>
#include <openvdb/tools/PointIndexGrid.h>

#include <cmath>
#include <stdexcept>

#include "sim/output/atomic_file.h"

namespace stokes::sim {
inline namespace output {

namespace {

/// OpenVDB's registries (grid types, codecs) must be initialised before any file I/O or point
/// grid; openvdb::initialize() is idempotent and internally locked.
void ensureOpenVdbInitialised() { openvdb::initialize(); }

openvdb::points::PointDataGrid::Ptr makePointsGrid(const std::vector<Vec3d>& positions,
                                                   const std::vector<Vec3d>* velocities,
                                                   const openvdb::math::Transform& xform) {
  namespace pts = openvdb::points;
  const pts::PointAttributeVector<openvdb::Vec3d> positionList(positions);
  auto index = openvdb::tools::createPointIndexGrid<openvdb::tools::PointIndexGrid>(positionList, xform);
  auto points = pts::createPointDataGrid<pts::NullCodec, pts::PointDataGrid>(*index, positionList, xform);
  if (velocities) {
    std::vector<openvdb::Vec3f> v(velocities->begin(), velocities->end());
    pts::appendAttribute<openvdb::Vec3f>(points->tree(), "v");
    const pts::PointAttributeVector<openvdb::Vec3f> velocityList(v);
    pts::populateAttribute<pts::PointDataTree, openvdb::tools::PointIndexTree,
                           pts::PointAttributeVector<openvdb::Vec3f>>(points->tree(), index->tree(),
                                                                      "v", velocityList);
  }
  points->setName("particles");
  return points;
}

}  // namespace

openvdb::Vec3SGrid::Ptr particleVelocityGrid(const std::vector<Vec3d>& positions, const std::vector<Vec3d>& velocities,
                                             const openvdb::FloatGrid& surface) {
  if (positions.size() != velocities.size())
    throw std::invalid_argument("particleVelocityGrid: " + std::to_string(velocities.size()) + " velocities for " +
                                std::to_string(positions.size()) + " particles");
  const openvdb::math::Transform& xform = surface.constTransform();
  openvdb::Vec3DGrid sum(openvdb::Vec3d(0.0));
  openvdb::DoubleGrid weight(0.0);
  auto s = sum.getAccessor();
  auto w = weight.getAccessor();
  for (std::size_t p = 0; p < positions.size(); ++p) {  // in particle order: the same sums every run
    forEachTrilinearCorner(xform.worldToIndex(positions[p]), [&](const openvdb::Coord& c, double wc) {
      if (wc <= 0.0) return;
      s.setValue(c, s.getValue(c) + wc * velocities[p]);
      w.setValue(c, w.getValue(c) + wc);
    });
  }
  auto vel = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
  vel->setTransform(xform.copy());
  vel->setName("vel");
  vel->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
  const float near = float(xform.voxelSize()[0]);
  auto out = vel->getAccessor();
  const auto phi = surface.getConstAccessor();
  for (auto it = weight.cbeginValueOn(); it; ++it) {
    if (!(*it > 0.0) || !(phi.getValue(it.getCoord()) < near)) continue;
    out.setValue(it.getCoord(), openvdb::Vec3s(s.getValue(it.getCoord()) / *it));
  }
  return vel;
}

void writeFrameVdb(const std::string& path, const FrameGrids& frame) {
  const openvdb::FloatGrid::Ptr& liquid = frame.surface;
  const std::vector<Vec3d>* particles = frame.positions;
  const std::vector<Vec3d>* velocities = frame.velocities;
  if (!liquid) throw std::invalid_argument("writeFrameVdb: null surface grid for '" + path + "'");
  if ((velocities || frame.points) && !particles)
    throw std::invalid_argument("writeFrameVdb: velocities or points without particles for '" + path + "'");
  if (velocities && velocities->size() != particles->size())
    throw std::invalid_argument("writeFrameVdb: " + std::to_string(velocities->size()) +
                                " velocities for " + std::to_string(particles->size()) +
                                " particles in '" + path + "'");
  ensureOpenVdbInitialised();
  writeFileAtomically(path, "writeFrameVdb", [&](const std::string& tmp) {
    openvdb::GridPtrVec grids;
    auto named = liquid->copyGrid();  // shares the tree; own metadata
    named->setName("surface");
    grids.push_back(named);
    // "vel", splatted in the simulator's y-up frame, its values then turned to the output frame
    // (a signed permutation: the same bits as splatting turned velocities)
    openvdb::Vec3SGrid::Ptr vel;
    if (frame.velocity) vel = frame.velocity->deepCopy();
    else if (particles && velocities) vel = particleVelocityGrid(*particles, *velocities, *liquid);
    if (vel && frame.up != UpAxis::Y)
      for (auto it = vel->beginValueOn(); it; ++it)
        it.setValue(openvdb::Vec3s(toUpAxis(openvdb::Vec3d(*it), frame.up)));
    if (vel) grids.push_back(vel);
    std::vector<Vec3d> turned;  // the particles' velocities in the output frame
    if (velocities && frame.up != UpAxis::Y) {
      turned.reserve(velocities->size());
      for (const Vec3d& v : *velocities) turned.push_back(toUpAxis(v, frame.up));
      velocities = &turned;
    }
    if (frame.points) grids.push_back(makePointsGrid(*particles, velocities, liquid->constTransform()));
    if (frame.up == UpAxis::Z) {
      // index -> y-up world -> z-up world: a +90 degree turn about x after the grid's own map
      openvdb::math::Transform::Ptr xform = liquid->constTransform().copy();
      xform->postRotate(0.5 * M_PI, openvdb::math::X_AXIS);
      for (openvdb::GridBase::Ptr& g : grids) g->setTransform(xform);
    }
    for (openvdb::GridBase::Ptr& g : grids) {
      g->insertMeta("time", openvdb::DoubleMetadata(frame.info.time));
      g->insertMeta("frame", openvdb::Int32Metadata(frame.info.frame));
      g->insertMeta("dx", openvdb::DoubleMetadata(liquid->voxelSize()[0]));
      g->insertMeta("scene", openvdb::StringMetadata(frame.info.scene));
      g->insertMeta("up_axis", openvdb::StringMetadata(frame.up == UpAxis::Z ? "z" : "y"));
      g->insertMeta("stokesvdb_version", openvdb::StringMetadata(STOKES_VERSION));
    }
    openvdb::io::File file(tmp);
    file.write(grids);
    file.close();
  });
}

std::vector<std::string> readVdbGridNames(const std::string& path) {
  ensureOpenVdbInitialised();
  std::vector<std::string> names;
  try {
    openvdb::io::File file(path);
    file.open(/*delayLoad=*/false);
    for (auto it = file.beginName(); it != file.endName(); ++it) names.push_back(it.gridName());
    file.close();
  } catch (const std::exception& e) {
    throw std::runtime_error("readVdbGridNames: cannot read '" + path + "': " + e.what());
  }
  return names;
}

openvdb::FloatGrid::Ptr readLiquidGrid(const std::string& path) {
  ensureOpenVdbInitialised();
  openvdb::GridBase::Ptr base;
  try {
    openvdb::io::File file(path);
    file.open(/*delayLoad=*/false);
    for (const char* name : {"surface", "liquid"})  // "liquid": frames written before "surface"
      if (!base && file.hasGrid(name)) base = file.readGrid(name);
    file.close();
  } catch (const std::exception& e) {
    throw std::runtime_error("readLiquidGrid: cannot read '" + path + "': " + e.what());
  }
  auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
  if (!grid) throw std::runtime_error("readLiquidGrid: no float grid 'surface' (or 'liquid') in '" + path + "'");
  return grid;
}

}  // namespace output
}  // namespace stokes::sim
