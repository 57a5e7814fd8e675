#pragma once
// Leader and workers: a program whose particles and grids live on rank 0 (a scene run) still
// solves on every rank. Rank 0 calls leadStep() where it would call solveStep(): it sends the
// step's problem (the layout's active cells, the weights, u*, the solids, the constants), the
// options that shape the system and the warm-start guess to the other ranks, and all ranks then
// run solveStep() together, the linear solve distributed by PETSc (pressure_stress_ranks.h). The
// other ranks sit in serveSteps() until rank 0 ends the run (finishSteps(), or the LeaderGuard).
//
// One broadcast per step moves the whole problem (about 30 doubles per cell); the solve's own
// traffic is the ghost exchange of each apply. docs/petsc.md describes how the other stages would
// be distributed.
#include <mpi.h>

#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "solver/petsc/petsc_krylov.h"
#include "solver/step/stokes_step.h"

namespace stokes::solver {
inline namespace step {

namespace remote {

enum Command : std::int32_t { kQuit = 0, kSolve = 1 };

/// A flat byte buffer: values and vectors appended in order, read back in the same order.
class Packet {
 public:
  template <class T>
  void put(const T& v) {
    const char* p = reinterpret_cast<const char*>(&v);
    bytes_.insert(bytes_.end(), p, p + sizeof(T));
  }
  template <class T>
  void putVector(const T& v) {
    put(std::uint64_t(v.size()));
    const char* p = reinterpret_cast<const char*>(v.data());
    bytes_.insert(bytes_.end(), p, p + v.size() * sizeof(v[0]));
  }
  template <class T>
  T get() {
    T v;
    take(&v, sizeof(T));
    return v;
  }
  template <class T>
  void getVector(T& v) {
    v.resize(std::size_t(get<std::uint64_t>()));
    take(v.data(), v.size() * sizeof(v[0]));
  }
  std::vector<char>& bytes() { return bytes_; }

 private:
  void take(void* out, std::size_t n) {
    if (read_ + n > bytes_.size()) throw std::runtime_error("leader/worker step: truncated message");
    std::memcpy(out, bytes_.data() + read_, n);
    read_ += n;
  }
  std::vector<char> bytes_;
  std::size_t read_ = 0;
};

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

template <int Dim>
void packStep(Packet& p, const StaggeredProblem<Dim>& prob, const StepOptions& opt, const Vector* guess) {
  const BlockLayout<Dim>& L = *prob.layout;
  p.put(std::int32_t(Dim));
  p.put(L.dx());
  for (int a = 0; a < 3; ++a) p.put(double(L.origin()[a]));
  std::vector<std::int32_t> cells;  // the active cells, 3 coordinates each
  for (std::size_t s = 0; s < L.numSlots(); ++s)
    if (L.isActiveCell(s))
      for (int a = 0; a < 3; ++a) cells.push_back(L.cellOf(s)[a]);
  p.putVector(cells);
  p.put(std::uint64_t(L.numBlocks()));
  p.put(prob.rho), p.put(prob.mu), p.put(prob.dt), p.put(prob.minMassWeight), p.put(prob.divergenceTarget);
  for (const Vector* v : {&prob.liquidFace, &prob.liquidCell, &prob.liquidStress, &prob.fluidFace, &prob.fluidStress,
                          &prob.uStar, &prob.uSolid})
    p.putVector(*v);
  p.putVector(prob.closedFace);
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
  if (guess) p.putVector(*guess);
}

/// A step received by a worker: the layout, problem, options and guess it describes.
template <int Dim>
struct ReceivedStep {
  BlockLayout<Dim> layout;
  StaggeredProblem<Dim> prob;
  StepOptions opt;
  Vector guess;
  bool hasGuess = false;

  ReceivedStep(Packet& p, const std::shared_ptr<TileLibrary>& library) {
    if (p.get<std::int32_t>() != Dim) throw std::runtime_error("leader/worker step: dimension mismatch");
    const double dx = p.get<double>();
    sparse_grid::Vec3d origin;
    for (int a = 0; a < 3; ++a) origin[a] = p.get<double>();
    std::vector<std::int32_t> cells;
    p.getVector(cells);
    openvdb::MaskTree mask;
    for (std::size_t k = 0; k + 2 < cells.size(); k += 3) mask.setValueOn(sparse_grid::Coord(cells[k], cells[k + 1], cells[k + 2]));
    layout = BlockLayout<Dim>(mask, dx, origin);
    if (layout.numBlocks() != p.get<std::uint64_t>())
      throw std::runtime_error("leader/worker step: the rebuilt layout has a different number of blocks");
    prob.layout = &layout;
    prob.rho = p.get<double>(), prob.mu = p.get<double>(), prob.dt = p.get<double>();
    prob.minMassWeight = p.get<double>(), prob.divergenceTarget = p.get<double>();
    for (Vector* v : {&prob.liquidFace, &prob.liquidCell, &prob.liquidStress, &prob.fluidFace, &prob.fluidStress,
                      &prob.uStar, &prob.uSolid})
      p.getVector(*v);
    p.getVector(prob.closedFace);
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
    if (hasGuess) p.getVector(guess);
  }
};

}  // namespace remote

/// Rank 0 of a leader/worker program: solveStep() on every rank. On one rank it is solveStep().
template <int Dim>
StepReport leadStep(const StaggeredProblem<Dim>& prob, const StepOptions& opt, Vector& u, Vector* solution = nullptr,
                    const Vector* guess = nullptr) {
  std::size_t sent = 0;
  if (petsc::ranks() > 1 && opt.backend == Backend::Petsc) {
    prob.validate();  // a bad problem fails here, before the workers are involved
    remote::Packet p;
    remote::packStep(p, prob, opt, guess);
    remote::broadcastCommand(remote::kSolve);
    remote::broadcast(p);
    sent = p.bytes().size();
  }
  StepReport rep = solveStep(prob, opt, u, solution, guess);
  rep.broadcastBytes = sent;
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
    Vector u;
    try {
      solveStep(step.prob, step.opt, u, nullptr, step.hasGuess ? &step.guess : nullptr);
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
