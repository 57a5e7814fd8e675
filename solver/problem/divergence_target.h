#pragma once
// Which liquid cells may take a divergence target (StaggeredProblem::divergenceTarget, the
// simulator's volume control): div u = s on a cell is consistent with the step's other
// constraints only where the cell's liquid can change its volume.
//
// Where the liquid continues into a solid or wall (thesis Fig. 3.4c), its stress samples have
// W_F^tau = 0 -- zero compliance in the pressure-stress form -- and hold the strain rate at zero
// there: a face in the stencil of such a sample is pinned to the solid, like a Dirichlet face. A
// null vector z of A = K^T S K + C (z^T A z = 0: K z = 0 on unknown faces, z_tau = 0 on every
// sample with positive compliance) therefore has, across an unknown face whose stencil holds no
// zero-compliance sample, (K z)_f = (G Wp z_p)_f = 0: equal Wp z_p on both sides, and Wp z_p = 0
// where the other side holds no liquid (a free surface: a vent). So z_p = 0 on every set of cells
// connected through such faces that reaches a vent, and a source there lies in the range of A.
// Elsewhere -- a pocket that only Dirichlet faces, closed walls and pinned faces bound, a closed
// container among them -- the volume cannot change and a source makes the system inconsistent
// (Jacobi CG diverged at the first step of the beam, and when the coil's rope met its plate, while
// the source reached every cell). Nearly rigid samples count as rigid: a sample cut to a sliver
// (W_F^tau = 1e-3, compliance 1e-3 of a full one) leaves a near-null vector that blew the source up
// a million-fold (the beam and a column between plates at their first step) -- so W_F^tau below
// minMassWeight. Both forms (their constitutive law shares StaggeredProblem::constitutiveFluidWeight)
// take the same cells, for the same physics.
#include <cstdint>
#include <numeric>
#include <vector>

#include "solver/problem/staggered_problem.h"

namespace stokes::solver {
inline namespace problem {

/// Whether stress sample i (channel-major index) holds the strain rate at (nearly) zero: it has
/// liquid (`liquidWeight` > 0, the effective W_L^tau) and W_F^tau < minMassWeight.
template <int Dim>
bool rigidStressSample(const StaggeredProblem<Dim>& prob, double liquidWeight, std::size_t i) {
  return liquidWeight > 0.0 && prob.fluidStressWeight(i) < prob.minMassWeight;
}

/// Marks (1) the cells with liquid (pWeight > 0) that reach a vent through unknown faces free of
/// rigid stress samples; see above. `state`: the face states (Dim channels); `pWeight`: the
/// effective W_L^p (zero on reduced cells); `stressWeight`: the effective liquid weight of the
/// stress samples (kCount channels, zero inside tiles), null for a projection without stresses.
/// Serial; O(faces).
template <int Dim>
std::vector<std::uint8_t> ventedCells(const StaggeredProblem<Dim>& prob, const std::vector<FaceState>& state,
                                      const double* pWeight, const double* stressWeight) {
  using SC = StressChannels<Dim>;
  const sparse_grid::BlockLayout<Dim>& layout = *prob.layout;
  const std::size_t n = layout.numSlots();
  const auto rigid = [&](int c, std::size_t s) {
    return stressWeight && rigidStressSample(prob, stressWeight[c * n + s], c * n + s);
  };
  std::vector<std::size_t> parent(n);
  std::iota(parent.begin(), parent.end(), std::size_t(0));
  auto find = [&](std::size_t s) {
    while (parent[s] != s) s = parent[s] = parent[parent[s]];
    return s;
  };
  auto rigidAt = [&](int channel, std::int64_t slot) { return slot >= 0 && rigid(channel, std::size_t(slot)); };
  // The face normal to a on the lower side of cell s: D^T reads t_aa at s - e_a and s, and t_ab
  // at s and s + e_b for b != a (kernels/staggered_stencils.h).
  auto pinned = [&](int a, std::size_t s, std::int64_t below) {
    if (rigidAt(a, std::int64_t(s)) || rigidAt(a, below)) return true;
    for (int b = 0; b < Dim; ++b) {
      if (b == a) continue;
      const int c = SC::pairChannel(a, b);
      if (rigidAt(c, std::int64_t(s)) || rigidAt(c, layout.neighbourSlot(s, b, +1))) return true;
    }
    return false;
  };
  std::vector<std::uint8_t> vent(n, 0);
  for (int a = 0; a < Dim; ++a)
    for (std::size_t s = 0; s < n; ++s) {
      if (state[a * n + s] != FaceState::Unknown) continue;
      const std::int64_t below = layout.neighbourSlot(s, a, -1);
      const bool here = pWeight[s] > 0.0, there = below >= 0 && pWeight[below] > 0.0;
      if (!(here || there) || pinned(a, s, below)) continue;
      if (here && there) {
        const std::size_t r0 = find(s), r1 = find(std::size_t(below));
        if (r0 != r1) parent[std::max(r0, r1)] = std::min(r0, r1);
      } else {
        vent[here ? s : std::size_t(below)] = 1;
      }
    }
  std::vector<std::uint8_t> ventedRoot(n, 0), out(n, 0);
  for (std::size_t s = 0; s < n; ++s)
    if (vent[s]) ventedRoot[find(s)] = 1;
  for (std::size_t s = 0; s < n; ++s) out[s] = pWeight[s] > 0.0 && ventedRoot[find(s)];
  return out;
}

/// Adds sign * Wp s to the pressure rows (rhs[p0 + i], i a cell slot) of the active (diag > 0)
/// cells that ventedCells marks, for s = prob.divergenceTarget; nothing when s = 0 or constant
/// pressure is a null space (`closed`). The pressure-stress form adds (+1), the
/// pressure-velocity form subtracts (-1), each with its own row layout.
template <int Dim>
void addDivergenceTarget(const StaggeredProblem<Dim>& prob, const std::vector<FaceState>& state, const double* pWeight,
                         const double* stressWeight, bool closed, double sign, const double* diag, double* rhs) {
  const double s = prob.divergenceTarget;
  if (s == 0.0 || closed) return;
  const std::vector<std::uint8_t> vented = ventedCells(prob, state, pWeight, stressWeight);
  for (std::size_t i = 0; i < vented.size(); ++i)
    if (diag[i] > 0.0 && vented[i]) rhs[i] += sign * pWeight[i] * s;
}

}  // namespace problem
}  // namespace stokes::solver
