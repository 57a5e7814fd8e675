#pragma once
// The pressure-velocity system (pressure_velocity_system.h; thesis Eq. 4.19) as an operator on its
// live rows, matrix-free through the compact neighbour index (kernels/compact_stencils.h) instead of
// the 8^Dim block sweeps (on the armadillos the block kernels swept 20 padded rows per
// live row). x = [u_C | v_R | p | l_r] on the live rows R of the system; the stencil's samples S are
// the cells with Wp > 0 and the stress samples with Q > 0, its faces F the Cartesian unknown faces
// and the tiles' coupling faces:
//
//   w_F   = W_F u on unknown faces, C v on coupling faces (J^T, on the padded face array)
//   s     = [Wp G^T w ; Q D w]                    (rowsFromFaces, one value per sample)
//   y_p   = s on the pressure rows;  y_r = (C'/Wt) s, then s += Wt l_r on the rigid samples
//   f     = G (Wp p) + D^T s                      (facesFromRows)
//   y_u   = (rho/dt) W_F W_m u + W_F f;   y_v = (M_R/dt + K_R) v + J f
//
// The same operator as the padded apply() restricted to R (to rounding: the terms are summed in
// the compact stencil's order); tested in tests/solver/test_multigrid.cpp.
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "kernels/compact_stencils.h"
#include "solver/krylov/compact_rows.h"
#include "solver/systems/pressure_velocity_system.h"

namespace stokes::solver {
inline namespace systems {

template <int Dim>
class PressureVelocityRows {
 public:
  using Index = RowSelection::Index;
  using SC = sparse_grid::StressChannels<Dim>;

  /// `rows`: the system's live rows (RowSelection::positiveDiagonal(sys.diagonal())). sys and its
  /// tiles must outlive the operator.
  PressureVelocityRows(const PressureVelocitySystem<Dim>& sys, const RowSelection& rows)
      : tiles_(sys.tiles()), n_(sys.layout().numSlots()),
        stencil_(sys.layout(), liveSamples(sys), liveFaces(sys), /*withStress=*/true),
        parallel_(parallel::forkGridLoop(rows.size() + stencil_.numFaces())) {
    if (rows.fullSize() != sys.size())
      throw std::invalid_argument("PressureVelocityRows: selection of " + std::to_string(rows.fullSize()) +
                                  " rows for a system of size " + std::to_string(sys.size()));
    const std::size_t nFaces = Dim * n_, p0 = sys.pressureOffset(), r0 = sys.rigidOffset();
    const std::vector<std::int64_t> faceOf = inverse(stencil_.numFaces(), nFaces, [&](std::size_t m) { return stencil_.paddedFace(m); });
    const std::vector<Index> samples = liveSamples(sys);
    const std::vector<std::int64_t> sampleOf = inverse(samples.size(), (1 + SC::kCount) * n_, [&](std::size_t j) { return samples[j]; });
    auto found = [](std::int64_t k, const char* what, Index r) {
      if (k < 0)
        throw std::logic_error(std::string("PressureVelocityRows: live row ") + std::to_string(r) + " has no " + what +
                               " in the stencil");
      return Index(k);
    };
    for (Index r : rows.rows()) {
      if (r < nFaces) {
        faceRow_.push_back(found(faceOf[r], "face", r));
        mass_.push_back(sys.faceMass()[r]);
        faceWeight_.push_back(sys.unknownFaceWeights()[r]);
      } else if (r < p0) {
        ++tileRows_;
      } else if (r < r0) {
        pressureRow_.push_back(found(sampleOf[r - p0], "pressure sample", r));
      } else {
        const std::size_t k = r - r0, i = sys.rigidSample(k);
        rigidRow_.push_back(found(sampleOf[n_ + i], "stress sample", r));
        rigidScale_.push_back(sys.rigidStrainScales()[k]);
        rigidWeight_.push_back(sys.stressWeights()[i]);
      }
    }
    if (tileRows_ != sys.velocityRows() - nFaces)
      throw std::invalid_argument("PressureVelocityRows: every tile DOF must be a live row");
    // per sample: the weight of rowsFromFaces ([Wp | Q]) and, for pressure, its row in x (or none)
    sampleWeight_.resize(samples.size() + 1, 0.0);
    pressureOfSample_.assign(samples.size(), -1);
    for (std::size_t j = 0; j < samples.size(); ++j)
      sampleWeight_[j] = samples[j] < n_ ? sys.pressureWeights()[samples[j]] : sys.stressCoefficients()[samples[j] - n_];
    for (std::size_t k = 0; k < pressureRow_.size(); ++k) pressureOfSample_[pressureRow_[k]] = std::int64_t(k);
    for (std::size_t m = 0; m < stencil_.numFaces(); ++m)
      if (tiles_ && tiles_->tileOfFace(stencil_.paddedFace(m)) >= 0) tileFaces_.push_back(Index(m));
    if (tiles_) padded_.assign(nFaces, 0.0);
    ones_.assign(stencil_.numFaces() + 1, 1.0);
    field_.assign(stencil_.numFaces() + 1, 0.0);
    force_.assign(stencil_.numFaces() + 1, 0.0);
    sample_.assign(samples.size() + 1, 0.0);
  }

  std::size_t size() const noexcept { return faceRow_.size() + tileRows_ + pressureRow_.size() + rigidRow_.size(); }

  void apply(const double* x, double* y) const {
    const std::size_t nu = faceRow_.size(), nv = tileRows_, np = pressureRow_.size(), nr = rigidRow_.size();
    const double* u = x;
    const double* v = x + nu;
    const double* p = x + nu + nv;
    const double* l = p + np;
    double* yu = y;
    double* yp = y + nu + nv;
    double* yr = yp + np;
    if (tiles_) tiles_->scatter(v, padded_.data(), /*couplingOnly=*/true);  // J^T v on the coupling faces
    double* field = field_.data();
    double* force = force_.data();
    double* s = sample_.data();
    const Index* face = faceRow_.data();
    const std::ptrdiff_t nTileFaces = std::ptrdiff_t(tileFaces_.size());
#pragma omp parallel if (parallel_)
    {
      parallel::countTeam(parallel::Region::GridLoop);
#pragma omp for schedule(static)
      for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(nu); ++k) field[face[k]] = faceWeight_[k] * u[k];
#pragma omp for schedule(static)
      for (std::ptrdiff_t q = 0; q < nTileFaces; ++q) field[tileFaces_[q]] = padded_[stencil_.paddedFace(tileFaces_[q])];
      stencil_.rowsFromFaces(field, sampleWeight_.data(), nullptr, nullptr, s);  // [Wp G^T w ; Q D w]
#pragma omp barrier
#pragma omp for schedule(static)
      for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(np); ++k) yp[k] = s[pressureRow_[k]];
#pragma omp for schedule(static)
      for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(nr); ++k) {
        const Index j = rigidRow_[k];
        yr[k] = s[j] * rigidScale_[k];
        s[j] += rigidWeight_[k] * l[k];
      }
      // the pressure samples now carry Wp p (0 where p is not a live row)
#pragma omp for schedule(static)
      for (std::ptrdiff_t j = 0; j < std::ptrdiff_t(stencil_.rowBegin(1)); ++j) {
        const std::int64_t k = pressureOfSample_[j];
        s[j] = k >= 0 ? sampleWeight_[j] * p[k] : 0.0;
      }
      stencil_.facesFromRows(s, ones_.data(), force);  // G (Wp p) + D^T s
#pragma omp barrier
#pragma omp for schedule(static)
      for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(nu); ++k) yu[k] = mass_[k] * u[k] + faceWeight_[k] * force[face[k]];
    }
    if (!tiles_) return;
    for (Index m : tileFaces_) padded_[stencil_.paddedFace(m)] = force[m];
    tiles_->applyTileRows(padded_.data(), v, y + nu);  // (M_R/dt + K_R) v + J f
  }

 private:
  // Samples of the stencil, padded [p | tau] indices, increasing: cells with Wp > 0, stress samples
  // with Q > 0.
  static std::vector<Index> liveSamples(const PressureVelocitySystem<Dim>& sys) {
    const std::size_t n = sys.layout().numSlots();
    std::vector<Index> out;
    for (std::size_t s = 0; s < n; ++s)
      if (sys.pressureWeights()[s] > 0.0) out.push_back(Index(s));
    for (std::size_t i = 0; i < SC::kCount * n; ++i)
      if (sys.stressCoefficients()[i] > 0.0) out.push_back(Index(n + i));
    return out;
  }
  // Faces of the stencil: Cartesian unknown faces (W_F > 0) and the tiles' coupling faces.
  static std::vector<Index> liveFaces(const PressureVelocitySystem<Dim>& sys) {
    const std::size_t nFaces = Dim * sys.layout().numSlots();
    std::vector<std::uint8_t> live(nFaces, 0);
    for (std::size_t f = 0; f < nFaces; ++f) live[f] = sys.unknownFaceWeights()[f] > 0.0 ? 1 : 0;
    if (const ReducedTiles<Dim>* tiles = sys.tiles())
      for (std::size_t t = 0; t < tiles->numTiles(); ++t)
        for (std::int64_t f : tiles->tile(t).coupling) live[std::size_t(f)] = 1;
    std::vector<Index> out;
    for (std::size_t f = 0; f < nFaces; ++f)
      if (live[f]) out.push_back(Index(f));
    return out;
  }
  // position of padded index at(k) for k < count, -1 elsewhere
  template <class At>
  static std::vector<std::int64_t> inverse(std::size_t count, std::size_t full, const At& at) {
    std::vector<std::int64_t> of(full, -1);
    for (std::size_t k = 0; k < count; ++k) of[at(k)] = std::int64_t(k);
    return of;
  }

  const ReducedTiles<Dim>* tiles_;
  std::size_t n_;
  kernels::CompactStencil<Dim> stencil_;
  bool parallel_;
  std::vector<Index> faceRow_, pressureRow_, rigidRow_, tileFaces_;
  std::size_t tileRows_ = 0;
  Vector mass_, faceWeight_, rigidScale_, rigidWeight_, sampleWeight_, ones_;
  std::vector<std::int64_t> pressureOfSample_;
  mutable Vector field_, force_, sample_, padded_;
};

}  // namespace systems
}  // namespace stokes::solver
