#include "sim/geometry/band_filter.h"

#include <openvdb/math/FiniteDifference.h>
#include <openvdb/math/Operators.h>
#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/Prune.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>

namespace stokes::sim {
inline namespace geometry {
namespace {

constexpr int kLeafDim = 8;
constexpr int kLeafVoxels = kLeafDim * kLeafDim * kLeafDim;
constexpr int kHalo = 3;  ///< HJ-WENO5 reads three voxels along each axis
constexpr int kSide = kLeafDim + 2 * kHalo;
constexpr int kPadded = kSide * kSide * kSide;

/// Index of voxel (x, y, z) of a leaf (OpenVDB's order: z fastest) and of padded position (x, y, z).
constexpr int leafIndex(int x, int y, int z) { return (x << 6) | (y << 3) | z; }
constexpr int paddedIndex(int x, int y, int z) { return ((x + kHalo) * kSide + (y + kHalo)) * kSide + (z + kHalo); }

/// A stencil over a padded leaf copy with the interface OpenVDB's finite differences read
/// (getValue<i, j, k>() relative to the centre).
struct PaddedStencil {
  using ValueType = float;
  const float* centre;
  template <int i, int j, int k>
  const float& getValue() const {
    return centre[(i * kSide + j) * kSide + k];
  }
};

/// openvdb::math::CurvatureStencil::meanCurvatureNormGrad() (openvdb/math/Stencils.h), the same
/// operations in the same order: float differences of float values, the rest in double.
float meanCurvatureNormGrad(const PaddedStencil& s, float invDx2) {
  using Real = double;
  const float v0 = s.getValue<0, 0, 0>();
  const Real Dx = 0.5 * (s.getValue<1, 0, 0>() - s.getValue<-1, 0, 0>());
  const Real Dy = 0.5 * (s.getValue<0, 1, 0>() - s.getValue<0, -1, 0>());
  const Real Dz = 0.5 * (s.getValue<0, 0, 1>() - s.getValue<0, 0, -1>());
  const Real Dx2 = Dx * Dx, Dy2 = Dy * Dy, Dz2 = Dz * Dz, normGrad2 = Dx2 + Dy2 + Dz2;
  if (normGrad2 <= openvdb::math::Tolerance<Real>::value()) return 0.0f;
  const Real Dxx = s.getValue<1, 0, 0>() - 2 * v0 + s.getValue<-1, 0, 0>();
  const Real Dyy = s.getValue<0, 1, 0>() - 2 * v0 + s.getValue<0, -1, 0>();
  const Real Dzz = s.getValue<0, 0, 1>() - 2 * v0 + s.getValue<0, 0, -1>();
  const Real Dxy = 0.25 * (s.getValue<1, 1, 0>() - s.getValue<1, -1, 0>() + s.getValue<-1, -1, 0>() -
                           s.getValue<-1, 1, 0>());
  const Real Dxz = 0.25 * (s.getValue<1, 0, 1>() - s.getValue<1, 0, -1>() + s.getValue<-1, 0, -1>() -
                           s.getValue<-1, 0, 1>());
  const Real Dyz = 0.25 * (s.getValue<0, 1, 1>() - s.getValue<0, 1, -1>() + s.getValue<0, -1, -1>() -
                           s.getValue<0, -1, 1>());
  const Real alpha =
      Dx2 * (Dyy + Dzz) + Dy2 * (Dxx + Dzz) + Dz2 * (Dxx + Dyy) - 2 * (Dx * (Dy * Dxy + Dz * Dxz) + Dy * Dz * Dyz);
  const Real normGrad = std::sqrt(normGrad2);
  return float(alpha * invDx2 / (2 * (normGrad * normGrad)));
}

/// openvdb::math::GodunovsNormSqrd (openvdb/math/FiniteDifference.h): the upwind |grad phi|^2 from
/// the backward (m) and forward (p) differences, the same operations, with both sides evaluated
/// and one selected so that a row of voxels vectorises.
float godunovNormSqrd(bool outside, const openvdb::Vec3s& m, const openvdb::Vec3s& p) {
  const float zero = 0.0f;
  auto sq = [](float v) { return v * v; };
  float out = std::max(sq(std::max(m[0], zero)), sq(std::min(p[0], zero)));
  out += std::max(sq(std::max(m[1], zero)), sq(std::min(p[1], zero)));
  out += std::max(sq(std::max(m[2], zero)), sq(std::min(p[2], zero)));
  float in = std::max(sq(std::min(m[0], zero)), sq(std::max(p[0], zero)));
  in += std::max(sq(std::min(m[1], zero)), sq(std::max(p[1], zero)));
  in += std::max(sq(std::min(m[2], zero)), sq(std::max(p[2], zero)));
  return outside ? out : in;
}

/// One Euler step of the reinitialisation (LevelSetTracker's Normalizer::eval, TVD_RK1), with
/// |grad phi|^2 as openvdb::math::ISGradientNormSqrd<HJWENO5_BIAS> computes it.
float renormalised(const PaddedStencil& s, float dt, float invDx) {
  using namespace openvdb::math;
  const float normSqGradPhi = godunovNormSqrd(s.getValue<0, 0, 0>() > 0, ISGradient<BD_HJWENO5>::result(s),
                                              ISGradient<FD_HJWENO5>::result(s));
  const float phi0 = s.getValue<0, 0, 0>();
  float v = phi0 / (std::sqrt(phi0 * phi0 + normSqGradPhi) + openvdb::math::Tolerance<float>::value());
  v = phi0 - dt * v * (std::sqrt(normSqGradPhi) * invDx - 1.0f);
  return v;
}

/// Copies into `padded` the part of neighbour o (each component in {-1, 0, 1}) that lies within
/// `layers` voxels of the leaf: the full 8 along axes where o is 0, `layers` along the others.
void gatherNeighbour(const int o[3], const float* data, float value, int layers, float* padded) {
  int lo[3], hi[3], shift[3];  // padded range [lo, hi) per axis; source = padded position - shift
  for (int a = 0; a < 3; ++a) {
    lo[a] = o[a] == 0 ? 0 : o[a] > 0 ? kLeafDim : -layers;
    hi[a] = o[a] == 0 ? kLeafDim : o[a] > 0 ? kLeafDim + layers : 0;
    shift[a] = o[a] * kLeafDim;
  }
  for (int x = lo[0]; x < hi[0]; ++x)
    for (int y = lo[1]; y < hi[1]; ++y) {
      float* row = padded + paddedIndex(x, y, 0);
      if (!data) {
        for (int z = lo[2]; z < hi[2]; ++z) row[z] = value;
        continue;
      }
      const float* src = data + leafIndex(x - shift[0], y - shift[1], 0);
      for (int z = lo[2]; z < hi[2]; ++z) row[z] = src[z - shift[2]];
    }
}

}  // namespace

BandFilter::BandFilter(openvdb::FloatGrid& grid) : grid_(grid), dx_(float(grid.voxelSize()[0])) {
  if (!grid.hasUniformVoxels()) throw std::invalid_argument("BandFilter: the grid's voxels must be cubes");
  if (grid.getGridClass() != openvdb::GRID_LEVEL_SET)
    throw std::invalid_argument("BandFilter: the grid must be a level set (GRID_LEVEL_SET)");
}

void BandFilter::collectLeaves() {
  leaves_.clear();
  grid_.tree().getNodes(leaves_);
}

void BandFilter::linkNeighbours() {
  const std::ptrdiff_t n = std::ptrdiff_t(leaves_.size());
  around_.resize(leaves_.size());
  next_.resize(leaves_.size() * kLeafVoxels);
  const openvdb::FloatTree& tree = grid_.tree();
#pragma omp parallel
  {
    openvdb::tree::ValueAccessor<const openvdb::FloatTree, false> acc(tree);
#pragma omp for schedule(static)
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      const openvdb::Coord origin = leaves_[i]->origin();
      Neighbourhood& around = around_[i];
      for (int k = 0; k < 27; ++k) {
        const openvdb::Coord at = origin.offsetBy(kLeafDim * (k / 9 - 1), kLeafDim * (k / 3 % 3 - 1), kLeafDim * (k % 3 - 1));
        const Leaf* leaf = acc.probeConstLeaf(at);
        around.data[k] = leaf ? leaf->buffer().data() : nullptr;
        around.value[k] = leaf ? 0.0f : acc.getValue(at);
      }
    }
  }
}

/// One Jacobi sweep over the active voxels: update(stencil) -> new value, reading a padded copy
/// with `layers` voxels from each face neighbour (and one from each edge neighbour if `edges`);
/// the new values are written back once every leaf has read the old ones.
template <class VoxelUpdate>
void BandFilter::sweep(int layers, bool edges, const VoxelUpdate& update) {
  const std::ptrdiff_t n = std::ptrdiff_t(leaves_.size());
#pragma omp parallel
  {
    std::vector<float> padded(kPadded);
#pragma omp for schedule(dynamic, 16)
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      const Neighbourhood& around = around_[i];
      for (int k = 0; k < 27; ++k) {
        const int o[3] = {k / 9 - 1, k / 3 % 3 - 1, k % 3 - 1};
        const int nonzero = (o[0] != 0) + (o[1] != 0) + (o[2] != 0);
        if (nonzero == 3 || (nonzero == 2 && !edges)) continue;
        gatherNeighbour(o, around.data[k], around.value[k], nonzero == 2 ? 1 : layers, padded.data());
      }
      // Whole rows along z (contiguous in the padded copy, so the update vectorises), kept
      // where the row has an active voxel.
      const auto& mask = leaves_[i]->getValueMask();
      float* out = next_.data() + std::size_t(i) * kLeafVoxels;
      for (int x = 0; x < kLeafDim; ++x)
        for (int y = 0; y < kLeafDim; ++y)
          if (mask.getWord<std::uint8_t>(x * kLeafDim + y) != 0)
            update(padded.data() + paddedIndex(x, y, 0), out + leafIndex(x, y, 0));
    }
#pragma omp for schedule(static)
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      float* values = leaves_[i]->buffer().data();
      const float* out = next_.data() + std::size_t(i) * kLeafVoxels;
      for (auto on = leaves_[i]->getValueMask().beginOn(); on; ++on) values[on.pos()] = out[on.pos()];
    }
  }
}

void BandFilter::renormalise() {
  const float dt = dx_ * 0.3f, invDx = 1.0f / dx_;
  for (int pass = 0; pass < int(openvdb::LEVEL_SET_HALF_WIDTH); ++pass)
    sweep(kHalo, /*edges=*/false, [&](const float* row, float* out) {
      for (int z = 0; z < kLeafDim; ++z) out[z] = renormalised(PaddedStencil{row + z}, dt, invDx);
    });
}

void BandFilter::trimAndPrune() {
  const float gamma = grid_.background();
  const std::ptrdiff_t n = std::ptrdiff_t(leaves_.size());
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    Leaf& leaf = *leaves_[i];
    for (auto v = leaf.beginValueOn(); v; ++v) {
      const float value = *v;
      if (value <= -gamma)
        leaf.setValueOff(v.pos(), -gamma);
      else if (value >= gamma)
        leaf.setValueOff(v.pos(), gamma);
    }
  }
  openvdb::tools::pruneLevelSet(grid_.tree());
}

void BandFilter::track() {
  openvdb::tools::dilateActiveValues(grid_.tree(), 1, openvdb::tools::NN_FACE, openvdb::tools::IGNORE_TILES);
  collectLeaves();
  linkNeighbours();
  renormalise();
  trimAndPrune();
}

void BandFilter::meanCurvature() {
  collectLeaves();
  linkNeighbours();
  const float dt = dx_ * dx_ / 3.0f;
  const double inv2Dx = float(0.5 / double(dx_));
  const float invDx2 = float(4.0 * inv2Dx * inv2Dx);
  sweep(1, /*edges=*/true, [&](const float* row, float* out) {
    for (int z = 0; z < kLeafDim; ++z) out[z] = row[z] + dt * meanCurvatureNormGrad(PaddedStencil{row + z}, invDx2);
  });
  track();
}

void BandFilter::offset(float distance) {
  const float cfl = 0.5f * dx_, total = std::abs(distance);
  float done = 0.0f;
  while (total - done > 0.001f * cfl) {
    const float step = std::copysign(std::min(total - done, cfl), distance);
    done += std::abs(step);
    collectLeaves();
    const std::ptrdiff_t n = std::ptrdiff_t(leaves_.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < n; ++i)
      for (auto v = leaves_[i]->beginValueOn(); v; ++v) v.setValue(*v + step);
    track();
  }
}

}  // namespace geometry
}  // namespace stokes::sim
