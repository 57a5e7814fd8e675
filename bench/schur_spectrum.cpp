// Where the pressure-velocity form's MINRES iterations come from, measured in isolation: for the
// first step of a scene at a given resolution (uniform model, its own dt), the condition numbers of
//
//   A_cyc   C^-1 A, A the PV system's velocity block and C its V-cycle (the default
//           preconditioner's velocity block);
//   S_diag  s^-1 S,  S = B A^-1 B^T on the constraint rows [p | l_r] (B: the PV system's pressure
//           and rigid-multiplier rows, A its velocity block, inverted exactly: CG with the
//           velocity V-cycle to a relative residual of 1e-12), s the Schur diagonal estimate;
//   S_pre   P_c^-1 S, P_c the pressure block of the default preconditioner (s, or Cahouet-Chabard
//           s^-1 + L^-1 where it runs);
//   K_pre   P^-1 K, K the whole system and P the default block preconditioner (velocity V-cycle,
//           P_c): max |lambda| / min |lambda|, which sets MINRES' iterations;
//
// with the constant pressure deflated where it is a null mode (closed boxes). Estimates come from
// Lanczos (solver/krylov/lanczos_spectrum.h): lower bounds that rise with the steps taken.
//
//   schur_spectrum SCENE.json RES [--steps N] [--k-steps N] [--frame-steps K] [--cycle galerkin|rediscretised]
//                  [--degree D] [--range R] [--slow-mode SWEEPS] [--schur on|off] [--time-applies N]
//                  [--floors on|off] [--rhs random|gravity]
//   schur_spectrum ball N [--model uniform|affine|quadratic] [--tile T] [--pad P] [same options]
//
// `ball N` measures the analytic ball's step (stokesvdb analytic ball --n N: mu = rho = dt = 1) with
// the reduced tiles its --model / --tile / --pad make, which a scene step (uniform model) does not
// have; there the slow modes of s^-1 S (--slow-mode) are also placed against the tiles: the share
// of |e|^2 on pressure cells next to two or more tiles (the slabs between them), next to one, or
// farther away.
//
// --steps: Lanczos steps on the definite operators (default 150); --k-steps: on the square of the
// whole system (default 1600: its condition number is squared, so it converges more slowly);
// --frame-steps K: simulator steps taken before the measured one (default 0: the first step). The velocity cycle
// is the scenes' (Galerkin coarse levels on the live rows) or the re-discretised padded one; --degree
// sets its Chebyshev smoothing degree (default: the pressure-velocity default), --range the ratio
// lambda_max / lambda_min of the interval it smooths (default 20). --slow-mode N: after A_cyc,
// where the cycle's slowest modes live (N sweeps of e <- (I - C^-1 A) e, then |e|^2 by axis, by cell
// and its largest rows with their diagonal against the median). --schur off skips S_diag and S_pre
// (the inner exact solves are most of the run's time). s is the estimate the preconditioner uses,
// the strong face groups' blocks included (multigrid_preconditioners.h, schurDiagonalWithFaceGroups).
// --floors on: only the outer methods' iterations on the step to 1e-6 (the floors): MINRES with the
// block diagonal and FGMRES (no restart) with the block upper-triangular preconditioner, each with
// the velocity V-cycle and with an exact velocity solve (CG with the cycle to 1e-10). Their
// right-hand side is K x* for a pseudo-random x*, or with --rhs gravity the step's own b for a
// liquid at rest (u* = g dt on the open faces), whose answer is the hydrostatic pressure.
// --time-applies N: only the cost of one MINRES iteration's two applies on the live rows, K x
// (matrix-free on the compact neighbour index, as the scenes apply it) and P^-1 r (the block preconditioner), each timed N times: median ms and ns per
// live row; no spectra.
#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "analytic/analytic_cases.h"
#include "sim/scene/scene.h"
#include "sim/step/simulator.h"
#include "sim/step/stokes_stage.h"
#include "solver/krylov/compact_rows.h"
#include "solver/krylov/gmres.h"
#include "solver/krylov/krylov.h"
#include "solver/krylov/lanczos_spectrum.h"
#include "solver/krylov/minres.h"
#include "solver/krylov/saddle_point_preconditioner.h"
#include "solver/krylov/stopwatch.h"
#include "solver/multigrid/multigrid_preconditioners.h"
#include "solver/systems/pressure_velocity_rows.h"
#include "solver/systems/pressure_velocity_system.h"
#include "sparse_grid/vdb_trees.h"

namespace {

using stokes::solver::Vector;
using System = stokes::solver::PressureVelocitySystem<3>;
using Preconditioner = stokes::solver::BlockMultigridPreconditioner;

// A_vv x on the velocity rows.
struct VelocityBlock {
  const System& sys;
  std::size_t size() const { return sys.velocityRows(); }
  void apply(const double* x, double* y) const { sys.applyVelocityBlock(x, y); }
};

// A preconditioner of the live rows `rows` (the scenes' Galerkin cycle) applied to padded vectors:
// gather, apply, scatter (zero off the live rows). Without rows: the padded preconditioner itself.
struct PaddedPreconditioner {
  const stokes::solver::RowSelection* rows;
  const Preconditioner& pre;
  std::size_t fullSize;
  mutable Vector rc, zc;
  std::size_t size() const { return fullSize; }
  void apply(const double* r, double* z) const {
    if (!rows) return pre.apply(r, z);
    rc.resize(rows->size());
    zc.resize(rows->size());
    rows->gather(r, rc.data());
    pre.apply(rc.data(), zc.data());
    std::fill(z, z + fullSize, 0.0);
    rows->scatter(zc.data(), z);
  }
};

// One diagonal block of the block preconditioner P: rows [offset, offset + count) of P applied to
// a vector that is r on those rows and 0 elsewhere (the velocity V-cycle, or the constraint block:
// s^-1, or Cahouet-Chabard's s^-1 + L^-1).
struct PreconditionerBlock {
  const System& sys;
  const PaddedPreconditioner& pre;
  std::size_t offset, count;
  mutable Vector full, out;
  std::size_t size() const { return count; }
  void apply(const double* r, double* z) const {
    full.assign(sys.size(), 0.0);
    out.resize(sys.size());
    std::copy(r, r + count, full.begin() + offset);
    pre.apply(full.data(), out.data());
    std::copy(out.begin() + offset, out.begin() + offset + count, z);
  }
};

// S x = B A^-1 B^T x on the constraint rows, A^-1 by CG to 1e-12.
struct SchurComplement {
  const System& sys;
  const PreconditionerBlock& cycle;
  mutable Vector full, out, rhs, u;
  mutable long innerIterations = 0;
  std::size_t size() const { return sys.size() - sys.pressureOffset(); }
  void apply(const double* x, double* y) const {
    const std::size_t n = sys.size(), c0 = sys.pressureOffset(), nv = sys.velocityRows();
    full.assign(n, 0.0);
    out.resize(n);
    std::copy(x, x + size(), full.begin() + c0);
    sys.apply(full.data(), out.data());  // velocity rows: B^T x
    rhs.assign(out.begin(), out.begin() + nv);
    u.assign(nv, 0.0);
    stokes::solver::SolveOptions opt;
    opt.relativeTolerance = 1e-12;
    opt.maxIterations = 2000;
    const auto r = stokes::solver::conjugateGradient(VelocityBlock{sys}, rhs.data(), u.data(), cycle, opt);
    innerIterations += r.iterations;
    if (r.status != stokes::solver::Status::Converged && r.relativeResidual > 1e-10)
      throw std::runtime_error("schur_spectrum: the inner velocity solve did not converge");
    std::fill(full.begin(), full.end(), 0.0);
    std::copy(u.begin(), u.end(), full.begin());
    sys.apply(full.data(), out.data());  // constraint rows: B u
    std::copy(out.begin() + c0, out.end(), y);
  }
};

// Ritz values below this fraction of the largest are a null space: constraint rows that depend on
// each other (a rigid cell's three diagonal strain rates sum to its divergence), not a small mode.
constexpr double kNullCut = 1e-9;
// The whole system's magnitudes come from its square, whose rounding level is ~1e-13 of the
// largest: below 1e-6 |lambda|max a Ritz value cannot be told from a null mode.
constexpr double kNullCutSquared = 1e-6;

// A reproducible start vector: uniform in [-1/2, 1/2) on the rows whose `weight` is positive (every
// row without one), 0 elsewhere.
Vector pseudoRandomStart(std::size_t n, const double* weight = nullptr) {
  Vector x(n);
  std::uint64_t state = 0x9E3779B97F4A7C15ull;
  for (std::size_t i = 0; i < n; ++i) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    x[i] = !weight || weight[i] > 0.0 ? double(state >> 11) * 0x1.0p-53 - 0.5 : 0.0;
  }
  return x;
}

// Where the cycle's slowest modes live: e <- (I - C^-1 A) e from a pseudo-random start, `sweeps`
// times, leaves the modes with the smallest eigenvalues of C^-1 A; prints the share of |e|^2 by
// axis, by cell coordinate (bins of 4 cells) and by the row's diagonal against the median.
template <class Cycle>
void printSlowMode(const System& sys, const Cycle& cycle, int sweeps) {
  const std::size_t nv = sys.velocityRows(), nf = sys.faceRows(), slots = sys.layout().numSlots();
  Vector e = pseudoRandomStart(nv, sys.diagonal().data()), ae(nv), z(nv);
  for (int k = 0; k < sweeps; ++k) {
    sys.applyVelocityBlock(e.data(), ae.data());
    cycle.apply(ae.data(), z.data());
    for (std::size_t i = 0; i < nv; ++i) e[i] -= z[i];
  }
  double total = 0.0, eAe = 0.0;
  sys.applyVelocityBlock(e.data(), ae.data());
  for (std::size_t i = 0; i < nv; ++i) total += e[i] * e[i], eAe += e[i] * ae[i];
  cycle.apply(ae.data(), z.data());
  double eCe = 0.0;
  for (std::size_t i = 0; i < nv; ++i) eCe += ae[i] * z[i];
  std::printf("  slow mode after %d sweeps: Rayleigh quotient (Ae, C^-1 Ae)/(e, Ae) %.4g\n", sweeps, eCe / eAe);
  std::vector<double> diag;
  for (std::size_t i = 0; i < nf; ++i)
    if (sys.diagonal()[i] > 0.0) diag.push_back(sys.diagonal()[i]);
  std::nth_element(diag.begin(), diag.begin() + diag.size() / 2, diag.end());
  const double median = diag[diag.size() / 2];
  std::vector<double> byAxis(3, 0.0), stiff(2, 0.0);
  std::vector<std::vector<double>> byCoord(3, std::vector<double>(64, 0.0));
  double tiles = 0.0;
  for (std::size_t i = 0; i < nv; ++i) {
    const double w = e[i] * e[i] / total;
    if (i >= nf) { tiles += w; continue; }
    const int axis = int(i / slots);
    byAxis[std::size_t(axis)] += w;
    stiff[sys.diagonal()[i] > 10.0 * median ? 1 : 0] += w;
    const auto c = sys.layout().cellOf(i % slots);
    for (int a = 0; a < 3; ++a) byCoord[std::size_t(a)][std::size_t(std::clamp(c[a] / 4, 0, 63))] += w;
  }
  double e4 = 0.0;
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < nv; ++i) e4 += e[i] * e[i] * e[i] * e[i] / (total * total), order.push_back(i);
  std::partial_sort(order.begin(), order.begin() + 12, order.end(), [&](std::size_t a, std::size_t b) { return std::abs(e[a]) > std::abs(e[b]); });
  std::printf("    participation: %.0f rows; largest:", 1.0 / e4);
  for (int k = 0; k < 12; ++k) {
    const std::size_t i = order[std::size_t(k)];
    if (i >= nf) { std::printf(" tile %zu %.2f;", i - nf, e[i] * e[i] / total); continue; }
    const auto c = sys.layout().cellOf(i % slots);
    std::printf(" %c(%d,%d,%d) %.3f d/med %.2g;", "uvw"[i / slots], c[0], c[1], c[2], e[i] * e[i] / total, sys.diagonal()[i] / median);
  }
  std::printf("\n");
  std::printf("    |e|^2 share: u %.3f v %.3f w %.3f tiles %.3f; rows with diagonal > 10x median %.3f\n", byAxis[0],
              byAxis[1], byAxis[2], tiles, stiff[1]);
  for (int a = 0; a < 3; ++a) {
    std::printf("    by cell %c / 4:", "xyz"[a]);
    for (std::size_t b = 0; b < 64; ++b)
      if (byCoord[std::size_t(a)][b] > 0.005) std::printf(" %zu:%.2f", b, byCoord[std::size_t(a)][b]);
    std::printf("\n");
  }
}

// The tiles within `reach` cells (Chebyshev) of each slot, up to two distinct ones (enough to tell
// one from several), and the distance to the nearest tile cell (reach + 1 beyond).
struct TilesNear {
  std::vector<std::array<std::int32_t, 2>> tiles;
  std::vector<int> distance;
};
TilesNear tilesNear(const stokes::sparse_grid::BlockLayout<3>& layout, const stokes::sparse_grid::Tiling<3>& tiling, int reach) {
  const std::size_t slots = layout.numSlots();
  TilesNear near{std::vector<std::array<std::int32_t, 2>>(slots, {-1, -1}), std::vector<int>(slots, reach + 1)};
  for (std::size_t q = 0; q < slots; ++q) {
    near.tiles[q][0] = tiling.tileOfCell[q];
    if (near.tiles[q][0] >= 0) near.distance[q] = 0;
  }
  for (int pass = 1; pass <= reach; ++pass) {
    for (int a = 0; a < 3; ++a) {  // a Chebyshev step is one face step along each axis in turn
      std::vector<std::array<std::int32_t, 2>> next = near.tiles;
      for (std::size_t q = 0; q < slots; ++q)
        for (int dir : {-1, 1}) {
          const std::int64_t nb = layout.neighbourSlot(q, a, dir);
          if (nb < 0) continue;
          for (std::int32_t t : near.tiles[std::size_t(nb)]) {
            if (t < 0 || next[q][0] == t || next[q][1] == t) continue;
            (next[q][0] < 0 ? next[q][0] : next[q][1]) = t;
          }
        }
      near.tiles.swap(next);
    }
    for (std::size_t q = 0; q < slots; ++q)
      if (near.distance[q] > reach && near.tiles[q][0] >= 0) near.distance[q] = pass;
  }
  return near;
}

// Where s^-1 S's slowest modes live: e <- (I - s^-1 S / lambda_max) e, `sweeps` times from a
// pseudo-random start, damps every mode but those with the smallest eigenvalues; the share of
// |e|^2 on pressure cells within `reach` cells (Chebyshev) of two or more tiles, of one, of none.
template <class Schur>
void printSchurSlowMode(const System& sys, const Schur& schur, const Vector& s, double lambdaMax,
                        const stokes::sparse_grid::Tiling<3>& tiling, int reach, int sweeps) {
  const std::size_t m = schur.size(), slots = sys.layout().numSlots(), c0 = sys.pressureOffset();
  const TilesNear nearTiles = tilesNear(sys.layout(), tiling, reach);
  const auto& near = nearTiles.tiles;
  const auto& distance = nearTiles.distance;
  Vector e = pseudoRandomStart(m, s.data()), se(m);
  for (int k = 0; k < sweeps; ++k) {
    schur.apply(e.data(), se.data());
    for (std::size_t i = 0; i < m; ++i) e[i] -= s[i] > 0.0 ? se[i] / (s[i] * lambdaMax) : 0.0;
  }
  schur.apply(e.data(), se.data());
  double total = 0.0, eSe = 0.0, eDe = 0.0, share[3] = {0.0, 0.0, 0.0};
  std::size_t cells[3] = {0, 0, 0};
  for (std::size_t i = 0; i < m; ++i) {
    if (s[i] <= 0.0) continue;
    total += e[i] * e[i];
    eSe += e[i] * se[i];
    eDe += e[i] * e[i] * s[i];
    const std::size_t slot = i;  // pressure row c0 + slot; the rigid multipliers after them
    const int tiles = slot < slots && c0 + slot < sys.rigidOffset() ? (near[slot][0] >= 0) + (near[slot][1] >= 0) : 0;
    share[tiles] += e[i] * e[i];
    ++cells[tiles];
  }
  std::printf("  S slow mode after %d sweeps: Rayleigh quotient (e, S e)/(e, s e) %.4g; |e|^2 share on pressure cells within %d "
              "cells of >= 2 tiles %.3f (%zu cells), of 1 tile %.3f (%zu), of none %.3f (%zu)\n",
              sweeps, eSe / eDe, reach, share[2] / total, cells[2], share[1] / total, cells[1], share[0] / total, cells[0]);
  // its shape on the slab cells: share by distance to the nearest tile, and the correlation of
  // neighbours along each axis (1: smooth, -1: alternating)
  std::vector<double> byDistance(std::size_t(reach) + 2, 0.0);
  double correlation[3] = {0.0, 0.0, 0.0}, slabSquares[3] = {0.0, 0.0, 0.0};
  for (std::size_t q = 0; q < std::min(m, slots); ++q) {
    if (s[q] <= 0.0 || near[q][1] < 0) continue;
    byDistance[std::size_t(std::min(distance[q], reach + 1))] += e[q] * e[q] / total;
    for (int a = 0; a < 3; ++a) {
      const std::int64_t nb = sys.layout().neighbourSlot(q, a, 1);
      if (nb < 0 || std::size_t(nb) >= m || s[std::size_t(nb)] <= 0.0 || near[std::size_t(nb)][1] < 0) continue;
      correlation[a] += e[q] * e[std::size_t(nb)];
      slabSquares[a] += 0.5 * (e[q] * e[q] + e[std::size_t(nb)] * e[std::size_t(nb)]);
    }
  }
  std::printf("    on the slabs: |e|^2 share at distance 1 / 2 / 3 from a tile %.3f / %.3f / %.3f; neighbour correlation x %.3f "
              "y %.3f z %.3f\n",
              byDistance[1], byDistance[2], byDistance[3], correlation[0] / slabSquares[0], correlation[1] / slabSquares[1],
              correlation[2] / slabSquares[2]);
  // candidate slow modes: a constant pressure on the cells near two or more tiles (the slabs), and
  // on the cells near each tile (its shell): their Rayleigh quotient, and how much of e they hold
  auto candidate = [&](const char* what, auto&& inside) {
    Vector z(m, 0.0), sz(m);
    for (std::size_t i = 0; i < m; ++i)
      if (s[i] > 0.0 && i < slots && c0 + i < sys.rigidOffset() && inside(near[i])) z[i] = 1.0;
    double zz = 0.0, ze = 0.0, zsz = 0.0, zSz = 0.0;
    schur.apply(z.data(), sz.data());
    for (std::size_t i = 0; i < m; ++i) zz += z[i], ze += z[i] * e[i], zsz += z[i] * s[i], zSz += z[i] * sz[i];
    std::printf("    constant on %s (%.0f cells): Rayleigh quotient %.4g, share of e %.3f\n", what, zz, zSz / zsz,
                ze * ze / (zz * total));
  };
  candidate("the slabs", [](const std::array<std::int32_t, 2>& t) { return t[1] >= 0; });
  const std::size_t shells = std::min<std::size_t>(tiling.tiles.size(), 4);
  for (std::size_t t = 0; t < shells; ++t) {
    const std::string what = "tile " + std::to_string(t) + "'s shell";
    candidate(what.c_str(), [t](const std::array<std::int32_t, 2>& n) { return n[0] == std::int32_t(t) || n[1] == std::int32_t(t); });
  }
}

// Median seconds of `repeats` calls of f.
template <class F>
double medianSeconds(int repeats, F&& f) {
  std::vector<double> s;
  for (int k = 0; k < repeats; ++k) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    s.push_back(stokes::solver::secondsSince(t0));
  }
  std::nth_element(s.begin(), s.begin() + s.size() / 2, s.end());
  return s[s.size() / 2];
}

// One MINRES iteration's two applies on the live rows, as the scenes' solve makes them.
void timeLiveRowApplies(const System& sys, const stokes::solver::RowSelection& rows, const Preconditioner& pre, int repeats) {
  const stokes::solver::PressureVelocityRows<3> k(sys, rows);
  const std::size_t m = rows.size();
  const Vector x = pseudoRandomStart(m);
  Vector y(m);
  const double tk = medianSeconds(repeats, [&] { k.apply(x.data(), y.data()); });
  const double tp = medianSeconds(repeats, [&] { pre.apply(x.data(), y.data()); });
  std::printf("  applies on %zu live rows, median of %d: K x %.3f ms (%.1f ns per row), P^-1 r %.3f ms (%.1f ns per row), "
              "ratio %.1f\n",
              m, repeats, 1e3 * tk, 1e9 * tk / double(m), 1e3 * tp, 1e9 * tp / double(m), tp / tk);
  // the velocity cycle's levels: one y = A_l x each (a V-cycle of Chebyshev degree d makes 2d of
  // them per level: d - 1 + 1 before the coarse correction, d after)
  std::vector<stokes::solver::RowSelection::Index> v;
  for (auto i : rows.rows())
    if (i < sys.pressureOffset()) v.push_back(i);
  const stokes::solver::RowSelection velocityRows(std::move(v), sys.velocityRows());
  const stokes::solver::GalerkinVelocityHierarchy<3> h(sys, velocityRows, stokes::solver::MultigridOptions{});
  // a level in factored form (level 0 with tiles, tile_coupled_rows.h) counts its multiply-adds
  const std::vector<stokes::solver::MultigridLevel> ops = stokes::solver::assembledLevels(h.levels());
  auto levelEntries = [&](std::size_t l) {
    const stokes::solver::AssembledLevel& L = (*h.levels())[l];
    return L.factored.rows ? L.factored.entries : L.a.entries();
  };
  double entries = 0.0;
  for (std::size_t l = 0; l < h.levels()->size(); ++l) {
    const std::size_t rows = ops[l].size, stored = levelEntries(l);
    entries += double(stored);
    Vector xl(rows, 1.0), yl(rows);
    const double ta = medianSeconds(repeats, [&] { ops[l].apply(xl.data(), yl.data()); });
    std::printf("    level %zu: %zu rows, %.1f entries per row, A_l x %.3f ms (%.2f ns per entry)\n", l, rows,
                double(stored) / double(std::max<std::size_t>(rows, 1)), 1e3 * ta, 1e9 * ta / double(std::max<std::size_t>(stored, 1)));
  }
  std::printf("    operator complexity (entries of all levels / level 0's): %.2f\n",
              entries / double(std::max<std::size_t>(levelEntries(0), 1)));
}

// The block preconditioner P split at the first constraint row, each part applied alone (P is
// block diagonal): the split preconditioner of solver/krylov/saddle_point_preconditioner.h. With
// `exactVelocity` the velocity part is A^-1 itself, by CG with the cycle to a relative residual of
// 1e-10 (the floors: what the outer method needs with a perfect velocity block).
struct SplitBlocks {
  const System& sys;
  const PaddedPreconditioner& pre;
  bool exactVelocity = false;
  mutable Vector full, out, rhs, u;
  mutable long innerIterations = 0;
  std::size_t size() const { return sys.size(); }
  void apply(const double* r, double* z) const { applyRows(r, z, 0, size()); }
  void applyRows(const double* r, double* z, std::size_t begin, std::size_t end) const {
    const std::size_t n = sys.size(), nv = sys.pressureOffset();
    full.assign(n, 0.0);
    out.resize(n);
    std::copy(r + begin, r + end, full.begin() + std::ptrdiff_t(begin));
    pre.apply(full.data(), out.data());
    std::copy(out.begin() + std::ptrdiff_t(begin), out.begin() + std::ptrdiff_t(end), z + begin);
    if (!exactVelocity || begin >= nv) return;
    rhs.assign(r, r + nv);
    u.assign(out.begin(), out.begin() + std::ptrdiff_t(nv));  // the cycle's answer starts CG
    const PreconditionerBlock cycle{sys, pre, 0, nv, {}, {}};
    stokes::solver::SolveOptions opt;
    opt.relativeTolerance = 1e-10;
    opt.maxIterations = 2000;
    const auto res = stokes::solver::conjugateGradient(VelocityBlock{sys}, rhs.data(), u.data(), cycle, opt);
    innerIterations += res.iterations;
    std::copy(u.begin(), u.end(), z);
  }
};

// The outer methods' floors on this step (K x = b to the scenes' 1e-6, b = K x* for a
// pseudo-random x* on the active rows: the measured step's own right-hand side is that of a
// liquid at rest, zero before gravity acts): MINRES with the
// block diagonal and FGMRES with the block upper-triangular form, each with the velocity V-cycle
// and with an exact velocity solve (flexible: the inner CG varies between applies).
void printFloors(const System& sys, const PaddedPreconditioner& pre, bool stepRhs) {
  namespace solver = stokes::solver;
  solver::SolveOptions opt;
  opt.relativeTolerance = 1e-6;
  opt.maxIterations = 3000;
  opt.restart = 200;  // no restarts: the floor of the method itself
  opt.nullSpace = sys.nullSpace();
  Vector b(sys.size());
  if (stepRhs) b = sys.rhs();
  else sys.apply(pseudoRandomStart(sys.size(), sys.diagonal().data()).data(), b.data());
  for (bool exact : {false, true}) {
    const SplitBlocks blocks{sys, pre, exact, {}, {}, {}, {}};
    using SP = solver::SaddlePointPreconditioner<System, SplitBlocks>;
    const SP diagonal(sys, blocks, sys.pressureOffset(), solver::SaddlePointBlocks::Diagonal);
    const SP triangular(sys, blocks, sys.pressureOffset(), solver::SaddlePointBlocks::UpperTriangular);
    Vector x(sys.size(), 0.0);
    auto t0 = std::chrono::steady_clock::now();
    const auto m = solver::minres(sys, b.data(), x.data(), diagonal, opt);
    const double tm = solver::secondsSince(t0);
    const long innerM = blocks.innerIterations;
    std::fill(x.begin(), x.end(), 0.0);
    t0 = std::chrono::steady_clock::now();
    const auto g = solver::fgmres(sys, b.data(), x.data(), triangular, opt);
    const double tg = solver::secondsSince(t0);
    std::printf("  floors, %s velocity block: MINRES + diagonal %d iterations (%s, %.1f s%s), FGMRES + triangular %d "
                "(%s, %.1f s%s)\n",
                exact ? "exact" : "V-cycle", m.iterations, solver::toString(m.status), tm,
                exact ? (", " + std::to_string(innerM / std::max(m.iterations, 1)) + " inner CG its each").c_str() : "",
                g.iterations, solver::toString(g.status), tg,
                exact ? (", " + std::to_string((blocks.innerIterations - innerM) / std::max(g.iterations, 1)) +
                         " inner CG its each").c_str()
                      : "");
  }
}

int usage(const char* argv0) {
  std::fprintf(stderr, "usage: %s SCENE.json RES [--steps N] [--k-steps N] [--frame-steps K] [--cycle galerkin|rediscretised] "
               "[--degree D] [--range R] [--slow-mode SWEEPS] [--schur on|off] [--time-applies N] [--floors on|off] [--rhs random|gravity]\n"
               "       %s ball N [--model uniform|affine|quadratic] [--tile T] [--pad P] [the options above]\n",
               argv0, argv0);
  return 2;
}

}  // namespace

/// What is measured and how (the command line's options).
struct Settings {
  int steps = 150, kSteps = 1600, slowModeSweeps = 0, timeApplies = 0;
  bool floors = false;  ///< --floors: only the outer methods' iterations (printFloors)
  bool gravity = false;  ///< --rhs gravity: u* = g dt (from rest), and the floors solve the step's own b
  bool schurSpectrum = true, galerkin = true;
  stokes::solver::MultigridOptions cycleOptions;  // smootherDegree 0: the default degree
};

/// The spectra (or the applies' cost) of one step's system: `prob` with the reduced `tiles` (or none).
int measure(const std::string& name, const stokes::solver::StaggeredProblem<3>& prob,
            const stokes::solver::ReducedTiles<3>* tiles, const Settings& set) {
  namespace solver = stokes::solver;
  const int steps = set.steps, kSteps = set.kSteps, slowModeSweeps = set.slowModeSweeps, timeApplies = set.timeApplies;
  const bool schurSpectrum = set.schurSpectrum, galerkin = set.galerkin;
  const solver::MultigridOptions& cycleOptions = set.cycleOptions;
  const System sys(prob, tiles);
  // the scenes' preconditioner (solver/step/stokes_step_impl.h): the Galerkin velocity cycle on
  // the live rows, or the padded cycle over re-discretised coarse problems
  const solver::RowSelection rows = solver::RowSelection::positiveDiagonal(sys.diagonal());
  const Preconditioner pre = galerkin ? solver::makeMultigridPreconditioner(prob, sys, rows, cycleOptions)
                                      : solver::makeMultigridPreconditioner(prob, sys, cycleOptions);
  const PaddedPreconditioner padded{galerkin ? &rows : nullptr, pre, sys.size(), {}, {}};
  const bool cahouetChabard = solver::usesPressureCycle(prob, solver::SchurApproximation::Auto);
  const std::size_t c0 = sys.pressureOffset();
  std::vector<double> nullConstraint;
  const double* null = nullptr;
  if (sys.nullSpace()) {
    nullConstraint.assign(sys.nullSpace() + c0, sys.nullSpace() + sys.size());
    null = nullConstraint.data();
  }
  std::printf("%s: dt %.4g s, viscous number mu dt/(rho dx^2) %.3g, %zu padded velocity rows (%zu tiles, %zu DOFs), %zu pressure + "
              "%zu multiplier rows, %s, pressure block %s, %s velocity cycle\n",
              name.c_str(), prob.dt, prob.viscousNumber(), sys.velocityRows(), tiles ? tiles->numTiles() : 0,
              tiles ? tiles->resolvedDofs() : 0,
              c0 < sys.rigidOffset() ? sys.rigidOffset() - c0 : 0, sys.rigidRows(), null ? "closed (deflated)" : "free surface",
              cahouetChabard ? "Cahouet-Chabard" : "Schur diagonal", galerkin ? "Galerkin" : "re-discretised");

  if (timeApplies > 0) {
    if (!galerkin) throw std::invalid_argument("--time-applies times the Galerkin cycle on the live rows");
    timeLiveRowApplies(sys, rows, pre, timeApplies);
    return 0;
  }
  if (set.floors) {
    printFloors(sys, padded, set.gravity);
    return 0;
  }
  auto t0 = std::chrono::steady_clock::now();
  const PreconditionerBlock velocityCycle{sys, padded, 0, sys.velocityRows(), {}, {}};
  const auto aCycle = solver::lanczosSpectrum(VelocityBlock{sys}, velocityCycle, steps, nullptr, kNullCut);
  std::printf("  A_cyc : kappa %.4g (lambda %.4g .. %.4g, %d null), %d steps, %.1f s\n", aCycle.condition(),
              aCycle.smallestAbs, aCycle.lambdaMax, aCycle.nullRitz, aCycle.steps, solver::secondsSince(t0));
  if (slowModeSweeps > 0) printSlowMode(sys, velocityCycle, slowModeSweeps);
  // the Schur diagonal estimate the preconditioner uses (with the strong face groups' blocks)
  Vector fullDiagonal = sys.diagonal();
  if (galerkin) {
    std::vector<solver::RowSelection::Index> v;
    for (auto i : rows.rows())
      if (i < c0) v.push_back(i);
    const solver::RowSelection velocityRows(std::move(v), sys.velocityRows());
    const solver::GalerkinVelocityHierarchy<3> h(sys, velocityRows, cycleOptions);
    fullDiagonal = solver::schurDiagonalWithFaceGroups(sys, velocityRows, h.levels()->front());
  }
  const Vector schurDiagonal(fullDiagonal.begin() + std::ptrdiff_t(c0), fullDiagonal.end());
  const SchurComplement schur{sys, velocityCycle, {}, {}, {}, {}};
  t0 = std::chrono::steady_clock::now();
  const auto sDiag = schurSpectrum ? solver::lanczosSpectrum(schur, solver::JacobiPreconditioner(schurDiagonal), steps, null, kNullCut)
                                   : solver::SpectrumEstimate{};
  std::printf("  S_diag: kappa %.4g (lambda %.4g .. %.4g, %d null), %d Lanczos steps, %.1f inner CG iterations per "
              "apply, %.1f s\n",
              sDiag.condition(), sDiag.smallestAbs, sDiag.lambdaMax, sDiag.nullRitz, sDiag.steps,
              double(schur.innerIterations) / std::max(sDiag.steps, 1), solver::secondsSince(t0));
  if (tiles && schurSpectrum && slowModeSweeps > 0)
    printSchurSlowMode(sys, schur, schurDiagonal, sDiag.lambdaMax, tiles->tiling(), 3, slowModeSweeps);
  if (cahouetChabard && schurSpectrum) {
    t0 = std::chrono::steady_clock::now();
    const auto sPre = solver::lanczosSpectrum(schur, PreconditionerBlock{sys, padded, c0, sys.size() - c0, {}, {}}, steps, null, kNullCut);
    std::printf("  S_pre : kappa %.4g (lambda %.4g .. %.4g, %d null), %d steps, %.1f s\n", sPre.condition(),
                sPre.smallestAbs, sPre.lambdaMax, sPre.nullRitz, sPre.steps, solver::secondsSince(t0));
  }
  t0 = std::chrono::steady_clock::now();
  const auto kPre = solver::lanczosMagnitudes(sys, padded, kSteps, sys.nullSpace(), kNullCutSquared);
  std::printf("  K_pre : kappa %.4g (|lambda| %.4g .. %.4g, %d null), %d steps, %.1f s\n", kPre.condition(),
              kPre.smallestAbs, kPre.largestAbs, kPre.nullRitz, kPre.steps, solver::secondsSince(t0));
  return 0;
}

int main(int argc, char** argv) {
  namespace sim = stokes::sim;
  namespace solver = stokes::solver;
  if (argc < 3) return usage(argv[0]);
  Settings set;
  int frameSteps = 0;
  stokes::analytic::AnalyticOptions ball;  // `ball N`: the analytic ball's step and tiles
  ball.n = std::atoi(argv[2]);
  for (int i = 3; i + 1 < argc; i += 2) {
    const std::string key = argv[i], value = argv[i + 1];
    if (key == "--steps") set.steps = std::atoi(value.c_str());
    else if (key == "--k-steps") set.kSteps = std::atoi(value.c_str());
    else if (key == "--degree") set.cycleOptions.smootherDegree = std::atoi(value.c_str());
    else if (key == "--range") set.cycleOptions.smootherRange = std::atof(value.c_str());
    else if (key == "--schur" && (value == "on" || value == "off")) set.schurSpectrum = value == "on";
    else if (key == "--slow-mode") set.slowModeSweeps = std::atoi(value.c_str());
    else if (key == "--time-applies") set.timeApplies = std::atoi(value.c_str());
    else if (key == "--floors" && (value == "on" || value == "off")) set.floors = value == "on";
    else if (key == "--rhs" && (value == "gravity" || value == "random")) set.gravity = value == "gravity";
    else if (key == "--frame-steps") frameSteps = std::atoi(value.c_str());
    else if (key == "--cycle" && (value == "galerkin" || value == "rediscretised")) set.galerkin = value == "galerkin";
    else if (key == "--model") ball.model = value;
    else if (key == "--tile") ball.tileSize = std::atoi(value.c_str());
    else if (key == "--pad") ball.padding = std::atoi(value.c_str());
    else return usage(argv[0]);
  }
  try {
    openvdb::initialize();
    if (std::string(argv[1]) == "ball") {
      const stokes::analytic::BallStep step = stokes::analytic::ballStep(ball);
      std::unique_ptr<solver::ReducedTiles<3>> tiles;
      if (step.options.reduced)
        tiles = std::make_unique<solver::ReducedTiles<3>>(step.prob, *step.options.reduced,
                                                          solver::couplingKinds(solver::SystemKind::UnifiedStokes));
      const std::string name = "ball n " + std::to_string(ball.n) + ", " + ball.model +
                               (tiles ? ", tile " + std::to_string(ball.tileSize) + " pad " + std::to_string(ball.padding) : "");
      return measure(name, step.prob, tiles.get(), set);
    }
    sim::Scene scene = sim::loadScene(argv[1], sim::SceneOverrides{std::atoi(argv[2]), 1});
    scene.model.type = sim::ModelType::Uniform;
    sim::Simulator simulator(scene);
    for (int k = 0; k < frameSteps; ++k) simulator.step(simulator.cflTimeStep(), 0);
    const double dt = simulator.cflTimeStep();
    const auto liquid = simulator.liquidLevelSet();
    sim::GridStep grid(simulator.particles().x, *liquid, simulator.solids(), simulator.domain(), simulator.scene(), dt,
                       true, sim::layoutBand(simulator.scene()));
    stokes::solver::StaggeredProblem<3> prob = grid.problem();
    if (set.gravity) {  // the step of a liquid at rest: u* = g dt on the open faces
      const std::size_t n = prob.slots();
      for (std::size_t i = 0; i < prob.uStar.size(); ++i)
        prob.uStar[i] = prob.closedFace[i] || !scene.gravity ? 0.0 : (*scene.gravity)[int(i / n)] * dt;
    }
    return measure(scene.name + " res " + std::to_string(scene.resolution) + ", step " + std::to_string(frameSteps) +
                       (set.gravity ? ", u* = g dt" : ""),
                   prob, nullptr, set);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "schur_spectrum: %s\n", e.what());
    return 1;
  }
  return 0;
}
