#pragma once
// The pressure-stress system A = K^T S K + C (pressure_stress_system.h; thesis Eq. 4.20-4.25) as
// an operator on compact vectors: its rows are the live rows R of the padded system (the
// RowSelection the Krylov solve runs on), and its stencils run over the unknowns through a
// compact neighbour index (kernels/compact_stencils.h) instead of sweeping the 8^Dim blocks:
//
//   wx = w ⊙ x_R,   f = S ⊙ K wx   (faces F: unknown and tile faces),
//   f|tiles <- J^T B^-1 J f        (the reduced tiles' coupling, on the padded face array),
//   y_R = w ⊙ K^T f + C x_R.
//
// It computes exactly P^T A P x_R of compact_rows.h's CompactOperator (bit for bit: the stencil
// terms are added in the block kernels' order), without the scatter and gather around the apply
// and without the padding slots (7 swept slots per unknown on the armadillos).
#include <cstdint>
#include <optional>
#include <vector>

#include "kernels/compact_stencils.h"
#include "solver/krylov/compact_rows.h"
#include "solver/systems/pressure_stress_system.h"

namespace stokes::solver {
inline namespace systems {

template <int Dim>
class PressureStressRows {
 public:
  using Index = RowSelection::Index;

  /// `rows` must be the system's live rows (RowSelection::positiveDiagonal(sys.diagonal())).
  /// sys and its tiles must outlive the operator.
  PressureStressRows(const PressureStressSystem<Dim>& sys, const RowSelection& rows)
      : PressureStressRows(sys, rows, liveFaces(sys.faceScale()), std::nullopt) {}

  /// A rank's share of the operator (solver/petsc/pressure_stress_ranks.h): `rows` are the samples
  /// the rank reads (its own rows and its ghosts), `faces` (increasing) the faces whose K x its
  /// own rows need, and `tiles` every tile with a coupling face among them. y is right on the rows
  /// whose faces are all listed (the rank's own); on the ghost rows it is partial and not used.
  PressureStressRows(const PressureStressSystem<Dim>& sys, const RowSelection& rows, const std::vector<Index>& faces,
                     std::optional<std::vector<std::int32_t>> tiles)
      : tiles_(sys.tiles()),
        tileList_(std::move(tiles)),
        stencil_(sys.layout(), rows.rows(), faces, sys.withStress()),
        parallel_(parallel::forkGridLoop(stencil_.numRows() + stencil_.numFaces())),
        weight_(rows.size()),
        compliance_(rows.size(), 0.0),
        faceScale_(stencil_.numFaces()),
        wx_(rows.size() + 1, 0.0),
        f_(stencil_.numFaces() + 1, 0.0) {
    if (rows.fullSize() != sys.size())
      throw std::invalid_argument("PressureStressRows: selection of " + std::to_string(rows.fullSize()) +
                                  " rows for a system of size " + std::to_string(sys.size()));
    const std::size_t n = sys.layout().numSlots();
    for (std::size_t k = 0; k < rows.size(); ++k) {
      const std::size_t r = rows.rows()[k];
      weight_[k] = r < n ? sys.pressureWeights()[r] : sys.stressWeights()[r - n];
      if (r >= n) compliance_[k] = sys.compliance()[r - n];
    }
    for (std::size_t m = 0; m < stencil_.numFaces(); ++m) {
      faceScale_[m] = sys.faceScale()[stencil_.paddedFace(m)];
      if (tiles_ && tiles_->tileOfFace(stencil_.paddedFace(m)) >= 0) tileFaces_.push_back(Index(m));
    }
    if (tiles_) padded_.assign(sys.faceScale().size(), 0.0);
  }

  std::size_t size() const noexcept { return stencil_.numRows(); }
  /// Faces whose K x the apply forms (unknown and tile faces).
  std::size_t faces() const noexcept { return stencil_.numFaces(); }
  /// Bytes of the neighbour index (reports).
  std::size_t indexBytes() const { return stencil_.bytes(); }

  /// y = P^T A P x on compact vectors.
  void apply(const double* x, double* y) const {
    const std::ptrdiff_t m = std::ptrdiff_t(size());
    const double* w = weight_.data();
    double* wx = wx_.data();
#pragma omp parallel if (parallel_)
    {
      parallel::countTeam(parallel::Region::GridLoop);
#pragma omp for schedule(static)
      for (std::ptrdiff_t k = 0; k < m; ++k) wx[k] = x[k] * w[k];
      stencil_.facesFromRows(wx, faceScale_.data(), f_.data());
      if (!tiles_) {
#pragma omp barrier
        stencil_.rowsFromFaces(f_.data(), w, compliance_.data(), x, y);
      }
    }
    if (!tiles_) return;
    coupleTiles();
#pragma omp parallel if (parallel_)
    stencil_.rowsFromFaces(f_.data(), w, compliance_.data(), x, y);
  }

 private:
  static std::vector<Index> liveFaces(const Vector& faceScale) {
    std::vector<Index> faces;
    for (std::size_t i = 0; i < faceScale.size(); ++i)
      if (faceScale[i] != 0.0) faces.push_back(Index(i));
    return faces;
  }

  // f on the tiles' faces <- J^T B^-1 J f: the tiles work on the padded face array.
  void coupleTiles() const {
    for (Index m : tileFaces_) padded_[stencil_.paddedFace(m)] = f_[m];
    if (tileList_) tiles_->coupleFaces(padded_.data(), *tileList_);
    else tiles_->coupleFaces(padded_.data());
    for (Index m : tileFaces_) f_[m] = padded_[stencil_.paddedFace(m)];
  }

  const ReducedTiles<Dim>* tiles_;
  std::optional<std::vector<std::int32_t>> tileList_;  ///< couple these tiles only (a rank's share)
  kernels::CompactStencil<Dim> stencil_;
  bool parallel_;
  Vector weight_, compliance_, faceScale_;
  std::vector<Index> tileFaces_;
  mutable Vector wx_, f_, padded_;
};

}  // namespace systems
}  // namespace stokes::solver
