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

void writeFrameVdb(const std::string& path, openvdb::FloatGrid::Ptr liquid,
                   const std::vector<Vec3d>* particles, const std::vector<Vec3d>* velocities, UpAxis up) {
  if (!liquid) throw std::invalid_argument("writeFrameVdb: null liquid grid for '" + path + "'");
  if (velocities && !particles)
    throw std::invalid_argument("writeFrameVdb: velocities without particles for '" + path + "'");
  if (velocities && velocities->size() != particles->size())
    throw std::invalid_argument("writeFrameVdb: " + std::to_string(velocities->size()) +
                                " velocities for " + std::to_string(particles->size()) +
                                " particles in '" + path + "'");
  ensureOpenVdbInitialised();
  writeFileAtomically(path, "writeFrameVdb", [&](const std::string& tmp) {
    openvdb::GridPtrVec grids;
    auto named = liquid->copyGrid();  // shares the tree; own metadata
    named->setName("liquid");
    grids.push_back(named);
    std::vector<Vec3d> turned;  // velocities in the output frame
    if (velocities && up != UpAxis::Y) {
      turned.reserve(velocities->size());
      for (const Vec3d& v : *velocities) turned.push_back(toUpAxis(v, up));
      velocities = &turned;
    }
    if (particles) grids.push_back(makePointsGrid(*particles, velocities, liquid->constTransform()));
    if (up == UpAxis::Z) {
      // index -> y-up world -> z-up world: a +90 degree turn about x after the grid's own map
      openvdb::math::Transform::Ptr xform = liquid->constTransform().copy();
      xform->postRotate(0.5 * M_PI, openvdb::math::X_AXIS);
      for (openvdb::GridBase::Ptr& g : grids) g->setTransform(xform);
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
    if (file.hasGrid("liquid")) base = file.readGrid("liquid");
    file.close();
  } catch (const std::exception& e) {
    throw std::runtime_error("readLiquidGrid: cannot read '" + path + "': " + e.what());
  }
  auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
  if (!grid) throw std::runtime_error("readLiquidGrid: no float grid 'liquid' in '" + path + "'");
  return grid;
}

}  // namespace output
}  // namespace stokes::sim
