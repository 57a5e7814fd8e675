// BandPhi (band_phi.h).
#include "sim/geometry/band_phi.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <openvdb/tools/Interpolation.h>

namespace stokes::sim {
inline namespace geometry {

namespace {
/// The layout's origin as a whole number of cells per axis, or false.
bool originInCells(const BandPhi::Layout& layout, openvdb::Coord& shift) {
  for (int a = 0; a < 3; ++a) {
    const double cells = layout.origin()[a] / layout.dx();
    const double whole = std::round(cells);
    if (std::abs(cells - whole) > 1e-9 * std::max(1.0, std::abs(cells))) return false;
    shift[a] = int(whole);
  }
  return true;
}
}  // namespace

BandPhi::BandPhi(openvdb::FloatGrid::ConstPtr grid, const Layout& layout) : gridPhi_(grid), layout_(&layout) {
  if (!grid) return;
  if (std::abs(grid->voxelSize()[0] - layout.dx()) > 1e-12 * layout.dx())
    throw std::invalid_argument("BandPhi: the grid's voxel size differs from the layout's cell size");
  // the level set's voxel v must be the cell v - shift: cellCentredTransform, no other offset
  const Vec3d firstCentre = grid->transform().indexToWorld(Vec3d(0.0));
  if (std::abs(firstCentre[0] - 0.5 * layout.dx()) > 1e-12 * layout.dx() || !originInCells(layout, shift_)) return;
  const std::size_t blocks = layout.numBlocks();
  values_.resize(blocks * std::size_t(kBlockVoxels));
#pragma omp parallel
  {
    openvdb::FloatGrid::ConstAccessor acc = grid->getConstAccessor();
#pragma omp for schedule(dynamic, 16)
    for (std::ptrdiff_t b = 0; b < std::ptrdiff_t(blocks); ++b) {
      const openvdb::Coord lo = layout.blockOrigin(std::size_t(b)) + shift_ - openvdb::Coord(1);
      float* out = values_.data() + std::size_t(b) * std::size_t(kBlockVoxels);
      for (int i = 0; i < kSide; ++i)
        for (int j = 0; j < kSide; ++j)
          for (int k = 0; k < kSide; ++k) *out++ = acc.getValue(lo.offsetBy(i, j, k));
    }
  }
}

double BandPhi::operator()(const Vec3d& worldPos) const {
  if (values_.empty()) return gridPhi_(worldPos);
  // GridPhi's (BoxSampler's) corners and weights, bit for bit
  const Vec3d ijk = gridPhi_.grid()->transform().worldToIndex(worldPos);
  const openvdb::Coord base(int(std::floor(ijk[0])), int(std::floor(ijk[1])), int(std::floor(ijk[2])));
  const std::int64_t slot = layout_->slotOf(base - shift_ + openvdb::Coord(1));
  if (slot < 0) return gridPhi_(worldPos);
  const std::size_t b = std::size_t(slot) / Layout::kSlots;
  const openvdb::Coord l = base - (layout_->blockOrigin(b) + shift_ - openvdb::Coord(1));  // in [0, kSide - 2]
  const float* v = values_.data() + b * std::size_t(kBlockVoxels);
  float data[2][2][2];
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j)
      for (int k = 0; k < 2; ++k) data[i][j][k] = v[((l.x() + i) * kSide + (l.y() + j)) * kSide + (l.z() + k)];
  return static_cast<double>(openvdb::tools::BoxSampler::trilinearInterpolation(data, ijk - base.asVec3d()));
}

}  // namespace geometry
}  // namespace stokes::sim
