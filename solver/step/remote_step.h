#pragma once
// Leader and workers: a program whose particles and grids live on rank 0 still solves on every
// rank. Rank 0 calls leadStep() where it would call solveStep(); the other ranks sit in
// serveSteps() until rank 0 ends the run (finishSteps(), or the LeaderGuard). A scene runs this
// way when it has reduced tiles (sim::splitsOverRanks; every other scene is split over the ranks
// by blocks, sim/ranks/): a tile region may span ranks, so every step sends every rank the whole
// problem (one broadcast) and every rank solves it with the others. Per-slot vectors travel
// sparsely (putBlocks): on the armadillos at res 96 a step's whole problem is 42-56 bytes per
// active cell, where the padded vectors were 341-520. The solve's own traffic is the ghost
// exchange of each apply.
#include <mpi.h>

#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "solver/petsc/petsc_krylov.h"
#include "solver/step/packet.h"
#include "solver/step/stokes_step.h"

namespace stokes::solver {
inline namespace step {

namespace remote {

enum Command : std::int32_t { kQuit = 0, kSolve = 1 };

using step::Packet;

inline void broadcast(Packet& p) {
  std::uint64_t size = p.bytes().size();
  MPI_Bcast(&size, 1, MPI_UINT64_T, 0, MPI_COMM_WORLD);
  p.bytes().resize(std::size_t(size));
  MPI_Bcast(p.bytes().data(), int(size), MPI_CHAR, 0, MPI_COMM_WORLD);
}

inline void broadcastCommand(Command c) {
  std::int32_t v = c;
  MPI_Bcast(&v, 1, MPI_INT32_T, 0, MPI_COMM_WORLD);
}

/// Per-slot values (any number of channels of numSlots each) of the listed blocks, channel by
/// channel, block by block in the list's order, sparsely: a bitmap of the values that differ from
/// a background (0 or 1, whichever most values are: a block's padding carries zero liquid weights
/// and unit fluid weights), then those values.
template <int Dim, class Values>
void putBlocks(Packet& p, const Values& v, std::size_t slots, const std::vector<std::size_t>& blocks) {
  using T = typename Values::value_type;
  constexpr std::size_t kSlots = BlockLayout<Dim>::kSlots;
  const std::size_t channels = slots ? v.size() / slots : 0, count = channels * blocks.size() * kSlots;
  auto forEachValue = [&](auto&& fn) {
    std::size_t k = 0;
    for (std::size_t c = 0; c < channels; ++c)
      for (std::size_t b : blocks)
        for (std::size_t i = c * slots + b * kSlots; i < c * slots + (b + 1) * kSlots; ++i) fn(k++, v[i]);
  };
  std::size_t ones = 0;
  forEachValue([&](std::size_t, T x) { ones += x == T(1) ? 1 : 0; });
  const T background = 2 * ones > count ? T(1) : T(0);
  std::vector<std::uint64_t> differs((count + 63) / 64, 0);
  std::vector<T> values;
  forEachValue([&](std::size_t k, T x) {
    if (x == background) return;
    differs[k / 64] |= std::uint64_t(1) << (k % 64);
    values.push_back(x);
  });
  p.put(std::uint64_t(channels)), p.put(background);
  p.putVector(differs), p.putVector(values);
}
/// Reads putBlocks' values into v (channels x numSlots, sized here unless `keepSize`): the k-th
/// block sent goes to block blocks[k].
template <int Dim, class Values>
void getBlocks(Packet& p, Values& v, std::size_t slots, const std::vector<std::size_t>& blocks, bool keepSize = false) {
  using T = typename Values::value_type;
  constexpr std::size_t kSlots = BlockLayout<Dim>::kSlots;
  const std::size_t channels = std::size_t(p.get<std::uint64_t>());
  const T background = p.get<T>();
  std::vector<std::uint64_t> differs;
  std::vector<T> values;
  p.getVector(differs), p.getVector(values);
  if (differs.size() != (channels * blocks.size() * kSlots + 63) / 64)
    throw std::runtime_error("leader/worker step: a block vector has the wrong size");
  if (!keepSize) v.assign(channels * slots, T(0));
  if (v.size() != channels * slots) throw std::runtime_error("leader/worker step: a block vector has the wrong channels");
  std::size_t k = 0, next = 0;
  for (std::size_t c = 0; c < channels; ++c)
    for (std::size_t b : blocks)
      for (std::size_t i = c * slots + b * kSlots; i < c * slots + (b + 1) * kSlots; ++i, ++k)
        v[i] = differs[k / 64] >> (k % 64) & 1 ? values.at(next++) : background;
}

/// The step's whole problem: origins, active cells (a bitmap per block), the constants, the
/// weights, u* and the solids per slot, the options, the warm-start guess.
template <int Dim>
void packStep(Packet& p, const StaggeredProblem<Dim>& prob, const StepOptions& opt, const Vector* guess) {
  constexpr std::size_t kSlots = BlockLayout<Dim>::kSlots;
  const BlockLayout<Dim>& L = *prob.layout;
  const std::size_t n = L.numSlots();
  std::vector<std::size_t> blocks(L.numBlocks());
  for (std::size_t b = 0; b < blocks.size(); ++b) blocks[b] = b;
  p.put(std::int32_t(Dim));
  p.put(L.dx());
  for (int a = 0; a < 3; ++a) p.put(double(L.origin()[a]));
  std::vector<std::int32_t> origins;
  std::vector<std::uint64_t> active((kSlots + 63) / 64 * blocks.size(), 0);
  for (std::size_t k = 0; k < blocks.size(); ++k) {
    for (int a = 0; a < 3; ++a) origins.push_back(L.blockOrigin(blocks[k])[a]);
    for (std::size_t s = 0; s < kSlots; ++s)
      if (L.isActiveCell(blocks[k] * kSlots + s)) active[k * ((kSlots + 63) / 64) + s / 64] |= std::uint64_t(1) << (s % 64);
  }
  p.putVector(origins), p.putVector(active);
  p.put(prob.rho), p.put(prob.mu), p.put(prob.dt), p.put(prob.minMassWeight), p.put(prob.divergenceTarget);
  for (const Vector* v : {&prob.liquidFace, &prob.liquidCell, &prob.liquidStress, &prob.fluidFace, &prob.fluidStress,
                          &prob.uStar, &prob.uSolid})
    putBlocks<Dim>(p, *v, n, blocks);
  putBlocks<Dim>(p, prob.closedFace, n, blocks);
  p.put(opt.system), p.put(opt.form), p.put(opt.backend);
  p.put(opt.krylov.relativeTolerance), p.put(opt.krylov.absoluteTolerance), p.put(opt.krylov.maxIterations);
  p.put(opt.krylov.divergenceFactor);
  p.put(std::uint8_t(opt.reduced.has_value()));
  if (opt.reduced) {
    const ReducedOptions& r = *opt.reduced;
    p.put(r.order), p.put(r.family), p.put(r.tiling), p.put(r.tileAccuracy), p.put(r.fitAllFaces), p.put(r.cache), p.put(r.rule);
    p.put(std::uint64_t(r.uniformRows)), p.put(r.uniformRowCost);
    // the leader's previous tiling, so that every rank takes the same adaptive decisions
    p.put(std::uint8_t(r.history != nullptr));
    if (r.history) p.putVector(r.history->state().decisionWords()), p.putVector(r.history->state().tiles);
  }
  p.put(std::uint8_t(guess != nullptr));
  if (guess) putBlocks<Dim>(p, *guess, n, blocks);
}

/// A step received by a worker: the layout, problem, options and guess it describes.
template <int Dim>
struct ReceivedStep {
  BlockLayout<Dim> layout;
  StaggeredProblem<Dim> prob;
  StepOptions opt;
  Vector guess;
  bool hasGuess = false;

  /// The leader's block of each of the layout's blocks is sent[k] for layout block local[k].
  std::vector<std::size_t> local;

  ReceivedStep(Packet& p, const std::shared_ptr<TileLibrary>& library) {
    constexpr std::size_t kSlots = BlockLayout<Dim>::kSlots, kWords = (kSlots + 63) / 64;
    if (p.get<std::int32_t>() != Dim) throw std::runtime_error("leader/worker step: dimension mismatch");
    const double dx = p.get<double>();
    sparse_grid::Vec3d origin;
    for (int a = 0; a < 3; ++a) origin[a] = p.get<double>();
    std::vector<std::int32_t> origins;
    std::vector<std::uint64_t> active;
    p.getVector(origins), p.getVector(active);
    const std::size_t blocks = origins.size() / 3;
    openvdb::MaskTree mask;
    for (std::size_t k = 0; k < blocks; ++k)
      for (std::size_t s = 0; s < kSlots; ++s)
        if (active[k * kWords + s / 64] >> (s % 64) & 1)
          mask.setValueOn(sparse_grid::Coord(origins[3 * k], origins[3 * k + 1], origins[3 * k + 2]) +
                          BlockLayout<Dim>::localCoord(int(s)));
    layout = BlockLayout<Dim>(mask, dx, origin);
    if (layout.numBlocks() != blocks)
      throw std::runtime_error("leader/worker step: the rebuilt layout has a different number of blocks");
    for (std::size_t k = 0; k < blocks; ++k) {
      const std::int32_t b = layout.blockAt(sparse_grid::Coord(origins[3 * k], origins[3 * k + 1], origins[3 * k + 2]));
      if (b < 0) throw std::runtime_error("leader/worker step: a block sent is not in the rebuilt layout");
      local.push_back(std::size_t(b));
    }
    prob.layout = &layout;
    prob.rho = p.get<double>(), prob.mu = p.get<double>(), prob.dt = p.get<double>();
    prob.minMassWeight = p.get<double>(), prob.divergenceTarget = p.get<double>();
    const std::size_t n = layout.numSlots();
    for (Vector* v : {&prob.liquidFace, &prob.liquidCell, &prob.liquidStress, &prob.fluidFace, &prob.fluidStress,
                      &prob.uStar, &prob.uSolid})
      getBlocks<Dim>(p, *v, n, local);
    getBlocks<Dim>(p, prob.closedFace, n, local);
    opt.system = p.get<SystemKind>(), opt.form = p.get<StokesForm>(), opt.backend = p.get<Backend>();
    opt.krylov.relativeTolerance = p.get<double>(), opt.krylov.absoluteTolerance = p.get<double>();
    opt.krylov.maxIterations = p.get<int>();
    opt.krylov.divergenceFactor = p.get<double>();
    if (p.get<std::uint8_t>()) {
      ReducedOptions r;
      r.order = p.get<PolynomialOrder>(), r.family = p.get<BasisFamily>(), r.tiling = p.get<sparse_grid::TilingOptions>();
      r.tileAccuracy = p.get<double>();
      r.fitAllFaces = p.get<bool>(), r.cache = p.get<TileCacheStrategy>(), r.rule = p.get<TileRule>();
      r.uniformRows = std::size_t(p.get<std::uint64_t>()), r.uniformRowCost = p.get<double>();
      if (p.get<std::uint8_t>()) {
        std::vector<std::int64_t> words;
        std::vector<std::uint64_t> tiles;
        p.getVector(words), p.getVector(tiles);
        r.history = std::make_shared<TileHistory>();
        r.history->restore(TileHistory::State::fromWords(words, std::move(tiles)));
      }
      r.library = library;
      opt.reduced = r;
    }
    hasGuess = p.get<std::uint8_t>() != 0;
    if (hasGuess) getBlocks<Dim>(p, guess, n, local);
  }
};

}  // namespace remote


/// Rank 0 of a leader/worker program: solveStep() on every rank. On one rank it is solveStep().
template <int Dim>
StepReport leadStep(const StaggeredProblem<Dim>& prob, const StepOptions& opt, Vector& u, Vector* solution = nullptr,
                    const Vector* guess = nullptr) {
  if (petsc::ranks() == 1 || opt.backend != Backend::Petsc) return solveStep(prob, opt, u, solution, guess);
  prob.validate();  // a bad problem fails here, before the workers are involved
  StepReport rep;
  remote::Packet p;
  remote::packStep(p, prob, opt, guess);
  remote::broadcastCommand(remote::kSolve);
  remote::broadcast(p);
  rep = solveStep(prob, opt, u, solution, guess);
  rep.sentBytes = p.bytes().size() * std::size_t(petsc::ranks() - 1);
  return rep;
}

/// The other ranks: take part in every step rank 0 leads, until it calls finishSteps().
template <int Dim>
void serveSteps() {
  auto library = std::make_shared<TileLibrary>();  // the workers' own cache of tile factorisations
  for (;;) {
    std::int32_t command = remote::kQuit;
    MPI_Bcast(&command, 1, MPI_INT32_T, 0, MPI_COMM_WORLD);
    if (command == remote::kQuit) return;
    remote::Packet p;
    remote::broadcast(p);
    remote::ReceivedStep<Dim> step(p, library);
    Vector u, x;
    try {
      solveStep(step.prob, step.opt, u, &x, step.hasGuess ? &step.guess : nullptr);
    } catch (const std::invalid_argument&) {
      // rank 0 runs the same checks on the same problem, fails the same way and reports it
    }
  }
}

/// Rank 0: releases the workers from serveSteps().
inline void finishSteps() {
  if (petsc::ranks() > 1) remote::broadcastCommand(remote::kQuit);
}

/// Calls finishSteps() when rank 0 leaves the run, however it leaves.
class LeaderGuard {
 public:
  ~LeaderGuard() { finishSteps(); }
};

}  // namespace step
}  // namespace stokes::solver
