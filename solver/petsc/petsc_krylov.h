#pragma once
// The PETSc backend's Krylov layer: a linear system distributed over MPI ranks by rows, solved with
// a PETSc KSP whose operator is a MatShell around the engine's own matrix-free apply.
//
// Like solver/krylov/, this layer knows nothing of grids. A rank hands over its contiguous run of
// rows [firstRow, firstRow + owned) of the global numbering, the global rows its apply reads (its
// "ghosts", owned rows included), and a callback y_owned = (A x)_owned that receives exactly those
// x values. The MatShell's mult scatters the ghosts (one PETSc VecScatter, built once), then calls
// the callback: the halo exchange of the stencils. Preconditioners that need entries get an
// assembled copy of (an approximation of) A in parallel AIJ form; the shell still defines the
// system (KSPSetOperators(ksp, shell, assembled)). Fields (pressure, stresses, ...) become
// PCFieldSplit index sets named "0", "1", ... so that `-fieldsplit_0_pc_type gamg` addresses them.
//
// The solver and preconditioner come from PETSc's options database. The defaults are CG with
// Jacobi, stopping on the unpreconditioned residual ||b - A x|| <= rtol ||b||, as the in-house
// solve does, so the two are compared on the same measure.
//
// None of this header needs petsc.h: only petsc_krylov.cpp includes it.
#include <algorithm>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "solver/krylov/krylov.h"

namespace stokes::solver::petsc {

/// One level transfer of a geometric multigrid over ranks: P maps the next coarser level's
/// unknowns (`coarseOwned` of them on this rank, numbered rank-major from `coarseFirst`) onto this
/// level's owned rows, CSR with global column numbers (rowStart: one entry per owned row, plus 1).
struct Interpolation {
  std::int64_t coarseFirst = 0;
  std::size_t coarseOwned = 0;
  std::vector<std::int64_t> rowStart{0}, columns;
  std::vector<double> values;
};

/// One rank's share of a distributed linear system.
struct DistributedSystem {
  std::int64_t globalRows = 0;
  std::int64_t firstRow = 0;  ///< this rank owns rows [firstRow, firstRow + ownedRows)
  std::size_t ownedRows = 0;
  /// Global rows whose x values the apply reads, increasing; the owned rows are among them.
  std::vector<std::int64_t> ghostRows;
  /// yOwned = (A x) on the owned rows, from x on ghostRows (in that order).
  std::function<void(const double* ghostValues, double* yOwned)> apply;
  std::vector<double> rhs, diagonal;  ///< owned entries
  /// Field of each owned row (0, 1, ...) and the fields' names for reports; one field: no split.
  std::vector<int> field;
  std::vector<std::string> fieldNames;
  /// Owned entries of a vector spanning null(A) (a closed container's constant pressure); empty: none.
  std::vector<double> nullSpace;
  /// Fills the owned rows of the matrix the preconditioner is built from, CSR with global column
  /// indices (rowStart gets ownedRows + 1 entries). Called only when the chosen preconditioner
  /// needs entries (anything but Jacobi and none, which read the shell's diagonal); unset: such
  /// preconditioners are refused.
  std::function<void(std::vector<std::int64_t>& rowStart, std::vector<std::int64_t>& columns,
                     std::vector<double>& values)>
      assemble;
  /// What the assembled matrix leaves out, for reports ("" when it is A).
  std::string assembledNote;
  /// Near-null vectors of field 0's block (each with one entry per owned row of field 0, in
  /// order), for algebraic multigrid on it (GAMG builds its coarse spaces from them): the rigid
  /// motions of a viscous velocity block. Called only where field 0's preconditioner is GAMG;
  /// unset: none.
  std::function<std::vector<std::vector<double>>()> nearNullSpace;
  /// A geometric multigrid for field 0's block, finest transfer first (level 0's rows: field 0's
  /// owned rows in order): PETSc's PCMG with Galerkin coarse operators, where field 0's
  /// preconditioner is `mg`; unset: PCMG (if chosen) gets no levels from here.
  /// Called (collectively) only when that preconditioner is chosen.
  std::function<std::vector<Interpolation>()> fieldZeroLevels;
  /// The finest level's smoother preconditioner on field 0's owned rows (r -> z, in their order),
  /// in place of Jacobi (unset: Jacobi). Called only where that multigrid gets its levels and the
  /// options database names no preconditioner for that level.
  std::function<std::function<void(const double* r, double* z)>()> fieldZeroSmoother;
  /// Whether the null space (if any) is also the assembled matrix's.
  bool assembledHasNullSpace = true;
  /// Options this system is solved with unless the options database names them ("-name value"
  /// pairs, e.g. MINRES for an indefinite system); CG with Jacobi where empty.
  std::vector<std::string> defaultOptions;
};

/// A row's (column, value) terms in any order, in place: sorted by column, the terms of one column
/// summed into one.
template <class Column>
void mergeRowTerms(std::vector<std::pair<Column, double>>& terms) {
  std::sort(terms.begin(), terms.end());
  std::size_t kept = 0;
  for (std::size_t t = 0; t < terms.size(); ++t) {
    if (kept > 0 && terms[kept - 1].first == terms[t].first) terms[kept - 1].second += terms[t].second;
    else terms[kept++] = terms[t];
  }
  terms.resize(kept);
}

/// Appends one row to a CSR matrix (DistributedSystem::assemble's arrays, or a CsrMatrix's) from
/// its (column, value) terms in any order (mergeRowTerms).
template <class Column>
void appendCsrRow(std::vector<std::pair<Column, double>>& terms, std::vector<std::int64_t>& rowStart,
                  std::vector<Column>& columns, std::vector<double>& values) {
  mergeRowTerms(terms);
  for (const auto& [c, v] : terms) columns.push_back(c), values.push_back(v);
  rowStart.push_back(std::int64_t(columns.size()));
}

/// What a PETSc solve did.
struct PetscReport {
  SolveResult solve;  ///< iterations, status, ||b - A x|| recomputed with the shell
  std::string kspType, pcType, normType, reason;
  int ranks = 1;
  double setupSeconds = 0.0;  ///< matrices, scatter and KSPSetUp (the preconditioner's build)
  double solveSeconds = 0.0;  ///< KSPSolve
  long long assembledNonzeros = 0;  ///< over all ranks; 0 without an assembled matrix
  std::string assembledNote;  ///< what the assembled matrix leaves out, when one was built
  /// The split over the ranks: owned rows (fewest, most) and the halo, the rows of other ranks
  /// one apply receives (most on a rank, and summed over the ranks: 8 bytes each per apply).
  std::size_t rowsMin = 0, rowsMax = 0, haloMax = 0, haloSum = 0;
  /// Solves continued from the last because the method's own norm stopped above the tolerance.
  int restarts = 0;
};

/// Keeps PETSc (and MPI) initialised for the life of the program: construct one in main. Options
/// (`-ksp_type cg -pc_type gamg ...`) go into PETSc's database; initialisation is deferred to the
/// first solve unless `now` is set (programs that run under mpirun initialise at once, so that
/// every rank takes part).
class Session {
 public:
  Session() = default;
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;
  /// Initialises PETSc now with these options (idempotent; later calls add options).
  static void initialise(const std::vector<std::string>& options);
  /// Empties the options database (tests that try several solvers in one program).
  static void clearOptions();
};

/// Splits argv into PETSc's options (single-dash words such as -ksp_type, each with its value if
/// the next word is not an option) and the rest, in order.
void splitPetscOptions(const std::vector<std::string>& args, std::vector<std::string>& rest,
                       std::vector<std::string>& petscOptions);

/// This process's rank and the number of ranks in PETSC_COMM_WORLD (0 and 1 before initialisation).
int rank();
int ranks();

/// Solves A x = b. xOwned holds the initial guess on entry (ownedRows values) and the solution on
/// return; `ghostValues`, if given, receives the solution on sys.ghostRows (one more halo
/// exchange). Collective on every rank.
PetscReport solveDistributed(const DistributedSystem& sys, const SolveOptions& opt, double* xOwned,
                             std::vector<double>* ghostValues = nullptr);

/// Every rank's owned values, concatenated in rank order (the global numbering). Collective.
std::vector<double> allGather(const double* owned, std::size_t count);

/// Sum and maximum over ranks (collective).
double sumOverRanks(double v);
double maxOverRanks(double v);

/// The sum of `v` over the ranks before this one (0 on rank 0; collective): where a rank's run of
/// a rank-major numbering starts.
std::uint64_t sumOverEarlierRanks(std::uint64_t v);

/// Asks other ranks for records by key (collective). asks[r] holds keyWords integers per key for
/// rank r; every rank answers each key it is asked with answer(key, record), which fills
/// recordWords words. Returns, per rank, the records in the order of its keys.
std::vector<std::vector<std::uint64_t>> askRanks(
    const std::vector<std::vector<std::int32_t>>& asks, int keyWords, int recordWords,
    const std::function<void(const std::int32_t* key, std::uint64_t* record)>& answer);

}  // namespace stokes::solver::petsc
