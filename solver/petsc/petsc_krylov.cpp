// PETSc backend: MatShell + ghost scatter + optional assembled AIJ copy + KSP (petsc_krylov.h).
#include "solver/petsc/petsc_krylov.h"
#include "solver/krylov/stopwatch.h"
#include "solver/petsc/exact_dot.h"

#include <petscksp.h>
#include <petsc/private/vecimpl.h>  // the solve vectors' reduction operations (exactReductions)

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace stokes::solver::petsc {
namespace {

bool gInitialisedHere = false;

// Turns a PETSc error code into an exception naming the call.
void check(PetscErrorCode ierr, const char* call) {
  if (ierr == 0) return;
  const char* text = nullptr;
  PetscErrorMessage(ierr, &text, nullptr);
  throw std::runtime_error(std::string("PETSc: ") + call + " failed: " + (text ? text : "unknown error"));
}
#define STOKES_PETSC(call) check((call), #call)

// The solve vectors' dot products and 2-norms, exact (exact_dot.h): the same bits for any rank
// count, so that a Krylov method whose other operations are per row (CG or MINRES with Jacobi,
// the shell's apply) gives the same iterates on any rank count.
PetscErrorCode exactVecDot(Vec x, Vec y, PetscScalar* value) {
  const PetscScalar *a = nullptr, *b = nullptr;
  PetscInt n = 0, N = 0;
  PetscCall(VecGetLocalSize(x, &n));
  PetscCall(VecGetSize(x, &N));
  PetscCall(VecGetArrayRead(x, &a));
  PetscCall(VecGetArrayRead(y, &b));
  *value = exactDot(a, b, std::size_t(n), std::int64_t(N), PetscObjectComm((PetscObject)x));
  PetscCall(VecRestoreArrayRead(y, &b));
  PetscCall(VecRestoreArrayRead(x, &a));
  return 0;
}

PetscErrorCode exactVecMDot(Vec x, PetscInt count, const Vec y[], PetscScalar* values) {
  for (PetscInt k = 0; k < count; ++k) PetscCall(exactVecDot(x, y[k], &values[k]));
  return 0;
}

PetscErrorCode (*gVectorNorm)(Vec, NormType, PetscReal*) = nullptr;  // the vector type's own

PetscErrorCode exactVecNorm(Vec x, NormType type, PetscReal* z) {
  if (type != NORM_2 && type != NORM_1_AND_2) return gVectorNorm(x, type, z);
  PetscReal* two = z;
  if (type == NORM_1_AND_2) {
    PetscCall(gVectorNorm(x, NORM_1, z));
    two = z + 1;
  }
  PetscScalar squares = 0.0;
  PetscCall(exactVecDot(x, x, &squares));
  *two = std::sqrt(squares);
  return 0;
}

/// Gives `v` and every vector duplicated from it (VecDuplicate copies the operations: KSP's work
/// vectors) the exact reductions.
void exactReductions(Vec v) {
  if (!gVectorNorm) gVectorNorm = v->ops->norm;
  v->ops->dot = exactVecDot;
  v->ops->tdot = exactVecDot;
  v->ops->mdot = exactVecMDot;
  v->ops->mtdot = exactVecMDot;
  v->ops->norm = exactVecNorm;
}

// Objects created for one solve, destroyed in reverse order whatever happens.
struct SolveObjects {
  Vec x = nullptr, b = nullptr, ghosts = nullptr, work = nullptr, nullVec = nullptr;
  IS ghostIs = nullptr;
  VecScatter scatter = nullptr;
  Mat shell = nullptr, assembled = nullptr;
  MatNullSpace nullSpace = nullptr;
  KSP ksp = nullptr;
  std::vector<IS> fieldIs;
  std::vector<Vec> nearNull;
  MatNullSpace nearNullSpace = nullptr;
  std::vector<Mat> interpolations;
  std::function<void(const double*, double*)> fineSmoother;
  ~SolveObjects() {
    KSPDestroy(&ksp);
    for (Mat& m : interpolations) MatDestroy(&m);
    MatNullSpaceDestroy(&nearNullSpace);
    for (Vec& v : nearNull) VecDestroy(&v);
    for (IS& is : fieldIs) ISDestroy(&is);
    MatNullSpaceDestroy(&nullSpace);
    MatDestroy(&assembled);
    MatDestroy(&shell);
    VecScatterDestroy(&scatter);
    ISDestroy(&ghostIs);
    VecDestroy(&nullVec);
    VecDestroy(&work);
    VecDestroy(&ghosts);
    VecDestroy(&b);
    VecDestroy(&x);
  }
};

// A system's default options (DistributedSystem::defaultOptions) in PETSc's options database for
// the life of one solve, where the user set none of that name.
class DefaultOptions {
 public:
  explicit DefaultOptions(const std::vector<std::string>& pairs) {
    for (std::size_t k = 0; k + 1 < pairs.size(); k += 2) {
      PetscBool set = PETSC_FALSE;
      STOKES_PETSC(PetscOptionsHasName(nullptr, nullptr, pairs[k].c_str(), &set));
      if (set) continue;
      STOKES_PETSC(PetscOptionsSetValue(nullptr, pairs[k].c_str(), pairs[k + 1].c_str()));
      inserted_.push_back(pairs[k]);
    }
  }
  ~DefaultOptions() {
    for (const std::string& name : inserted_) PetscOptionsClearValue(nullptr, name.c_str());
  }
  DefaultOptions(const DefaultOptions&) = delete;
  DefaultOptions& operator=(const DefaultOptions&) = delete;

 private:
  std::vector<std::string> inserted_;
};

struct ShellContext {
  const DistributedSystem* sys;
  VecScatter scatter;
  Vec ghosts;
  Vec model;  ///< a vector of the solve (exact reductions): what the shell's vectors duplicate
};

// The shell's vectors (KSP's work vectors come from here): duplicates of the solve's, so that
// they take its exact reductions.
PetscErrorCode shellCreateVecs(Mat A, Vec* right, Vec* left) {
  ShellContext* ctx = nullptr;
  PetscCall(MatShellGetContext(A, &ctx));
  if (right) PetscCall(VecDuplicate(ctx->model, right));
  if (left) PetscCall(VecDuplicate(ctx->model, left));
  return 0;
}

// y = A x: gather x on the ghost rows, then the rank's matrix-free apply.
PetscErrorCode shellMult(Mat A, Vec x, Vec y) {
  ShellContext* ctx = nullptr;
  PetscCall(MatShellGetContext(A, &ctx));
  PetscCall(VecScatterBegin(ctx->scatter, x, ctx->ghosts, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(ctx->scatter, x, ctx->ghosts, INSERT_VALUES, SCATTER_FORWARD));
  const PetscScalar* g = nullptr;
  PetscScalar* out = nullptr;
  PetscCall(VecGetArrayRead(ctx->ghosts, &g));
  PetscCall(VecGetArray(y, &out));
  try {
    ctx->sys->apply(g, out);
  } catch (const std::exception& e) {
    SETERRQ(PETSC_COMM_SELF, PETSC_ERR_LIB, "matrix-free apply failed: %s", e.what());
  }
  PetscCall(VecRestoreArray(y, &out));
  PetscCall(VecRestoreArrayRead(ctx->ghosts, &g));
  return 0;
}

PetscErrorCode shellDiagonal(Mat A, Vec d) {
  ShellContext* ctx = nullptr;
  PetscCall(MatShellGetContext(A, &ctx));
  PetscScalar* out = nullptr;
  PetscCall(VecGetArray(d, &out));
  std::copy(ctx->sys->diagonal.begin(), ctx->sys->diagonal.end(), out);
  PetscCall(VecRestoreArray(d, &out));
  return 0;
}

Status statusOf(KSPConvergedReason reason) {
  if (reason > 0) return Status::Converged;
  switch (reason) {
    case KSP_DIVERGED_ITS: return Status::MaxIterations;
    case KSP_DIVERGED_NANORINF: return Status::NonFinite;
    case KSP_DIVERGED_DTOL: return Status::Diverged;
    case KSP_CONVERGED_ITERATING: return Status::MaxIterations;
    default: return Status::Breakdown;
  }
}

void fillVec(Vec v, const std::vector<double>& values) {
  PetscScalar* a = nullptr;
  STOKES_PETSC(VecGetArray(v, &a));
  std::copy(values.begin(), values.end(), a);
  STOKES_PETSC(VecRestoreArray(v, &a));
}

// The parallel AIJ copy of the owned rows (DistributedSystem::assemble).
Mat assemble(const DistributedSystem& s) {
  if (!s.assemble) throw std::invalid_argument("PETSc solve: the preconditioner needs matrix entries, which this system does not assemble");
  std::vector<std::int64_t> rowStart, columns;
  std::vector<double> values;
  s.assemble(rowStart, columns, values);
  std::vector<PetscInt> i(rowStart.begin(), rowStart.end()), j(columns.begin(), columns.end());
  // AIJ: sequential on one rank (so that factorisations such as ICC apply), MPI on more
  Mat m = nullptr;
  STOKES_PETSC(MatCreate(PETSC_COMM_WORLD, &m));
  STOKES_PETSC(MatSetSizes(m, PetscInt(s.ownedRows), PetscInt(s.ownedRows), PetscInt(s.globalRows),
                           PetscInt(s.globalRows)));
  STOKES_PETSC(MatSetType(m, MATAIJ));
  STOKES_PETSC(MatSeqAIJSetPreallocationCSR(m, i.data(), j.data(), values.data()));
  STOKES_PETSC(MatMPIAIJSetPreallocationCSR(m, i.data(), j.data(), values.data()));
  return m;
}

// Jacobi and no preconditioner read the shell's diagonal; everything else needs entries.
bool needsEntries(PC pc) {
  PCType type = nullptr;
  STOKES_PETSC(PCGetType(pc, &type));
  const std::string t = type ? type : "";
  return !(t == PCJACOBI || t == PCNONE);
}

// Stopping on ||b - A x|| as the in-house solvers do, unless -ksp_norm_type says otherwise: the CG
// family supports it with left preconditioning, GMRES-like methods with right preconditioning;
// other methods (MINRES, SYMMLQ, ...) keep their own norm, which the report names.
void chooseNorm(KSP ksp) {
  PetscBool userSet = PETSC_FALSE;
  STOKES_PETSC(PetscOptionsHasName(nullptr, nullptr, "-ksp_norm_type", &userSet));
  if (userSet) return;
  KSPType type = nullptr;
  STOKES_PETSC(KSPGetType(ksp, &type));
  const std::string t = type;
  const bool cgFamily = t == "cg" || t == "pipecg" || t == "groppcg" || t == "pipecgrr" || t == "fcg";
  const bool rightSide = t == "gmres" || t == "fgmres" || t == "lgmres" || t == "dgmres" || t == "pgmres" ||
                         t == "bcgs" || t == "bcgsl" || t == "gcr" || t == "tfqmr";
  if (rightSide) STOKES_PETSC(KSPSetPCSide(ksp, PC_RIGHT));
  if (cgFamily || rightSide) STOKES_PETSC(KSPSetNormType(ksp, KSP_NORM_UNPRECONDITIONED));
}

// Field 0's near-null vectors, orthonormalised (modified Gram-Schmidt), on its block's matrix
// `block`, where GAMG reads them in its set-up.
void attachNearNullSpace(const DistributedSystem& s, std::size_t ownedOfField, Mat block, SolveObjects& o) {
  for (const std::vector<double>& v : s.nearNullSpace()) {
    if (v.size() != ownedOfField) throw std::invalid_argument("PETSc solve: a near-null vector needs one value per owned row of field 0");
    Vec w = nullptr;
    STOKES_PETSC(VecCreateMPI(PETSC_COMM_WORLD, PetscInt(ownedOfField), PETSC_DETERMINE, &w));
    fillVec(w, v);
    for (Vec q : o.nearNull) {
      PetscScalar d = 0.0;
      STOKES_PETSC(VecDot(w, q, &d));
      STOKES_PETSC(VecAXPY(w, -d, q));
    }
    PetscReal norm = 0.0;
    STOKES_PETSC(VecNormalize(w, &norm));
    if (norm > 0.0) o.nearNull.push_back(w);
    else VecDestroy(&w);
  }
  STOKES_PETSC(MatNullSpaceCreate(PETSC_COMM_WORLD, PETSC_FALSE, PetscInt(o.nearNull.size()), o.nearNull.data(),
                                  &o.nearNullSpace));
  STOKES_PETSC(MatSetNearNullSpace(block, o.nearNullSpace));
}

}  // namespace

Session::~Session() {
  if (gInitialisedHere) {
    PetscFinalize();
    gInitialisedHere = false;
  }
}

void Session::initialise(const std::vector<std::string>& options) {
  PetscBool up = PETSC_FALSE;
  PetscInitialized(&up);
  if (!up) {
    // No argv: CLI11 owns the command line; the options go in below.
    STOKES_PETSC(PetscInitializeNoArguments());
    gInitialisedHere = true;
  }
  std::string joined;
  for (const std::string& o : options) joined += (joined.empty() ? "" : " ") + o;
  if (!joined.empty()) STOKES_PETSC(PetscOptionsInsertString(nullptr, joined.c_str()));
  // PETSc starts its event log at initialisation only if -log_view was among argv, which it never
  // sees here; start it now, so that -log_view prints at the end instead of failing there
  PetscBool logView = PETSC_FALSE;
  STOKES_PETSC(PetscOptionsHasName(nullptr, nullptr, "-log_view", &logView));
  if (logView) STOKES_PETSC(PetscLogDefaultBegin());
}

void Session::clearOptions() { STOKES_PETSC(PetscOptionsClear(nullptr)); }

void splitPetscOptions(const std::vector<std::string>& args, std::vector<std::string>& rest,
                       std::vector<std::string>& petscOptions) {
  auto isPetscOption = [](const std::string& a) {
    return a.size() > 2 && a[0] == '-' && a[1] != '-' && (std::isalpha(static_cast<unsigned char>(a[1])) != 0);
  };
  for (std::size_t k = 0; k < args.size(); ++k) {
    if (!isPetscOption(args[k])) {
      rest.push_back(args[k]);
      continue;
    }
    petscOptions.push_back(args[k]);
    if (k + 1 < args.size() && !isPetscOption(args[k + 1]) && args[k + 1].rfind("--", 0) != 0)
      petscOptions.push_back(args[++k]);
  }
}

namespace {
bool initialised() {
  PetscBool up = PETSC_FALSE;
  PetscInitialized(&up);
  return up == PETSC_TRUE;
}
}  // namespace

int rank() {
  int r = 0;
  if (initialised()) MPI_Comm_rank(PETSC_COMM_WORLD, &r);
  return r;
}

int ranks() {
  int n = 1;
  if (initialised()) MPI_Comm_size(PETSC_COMM_WORLD, &n);
  return n;
}

std::vector<double> allGather(const double* owned, std::size_t count) {
  const int n = ranks();
  std::vector<int> counts(n), offsets(n);
  const int mine = int(count);
  MPI_Allgather(&mine, 1, MPI_INT, counts.data(), 1, MPI_INT, PETSC_COMM_WORLD);
  long long total = 0;
  for (int r = 0; r < n; ++r) {
    offsets[r] = int(total);
    total += counts[r];
  }
  std::vector<double> all(static_cast<std::size_t>(total));
  MPI_Allgatherv(owned, mine, MPI_DOUBLE, all.data(), counts.data(), offsets.data(), MPI_DOUBLE, PETSC_COMM_WORLD);
  return all;
}

double sumOverRanks(double v) {
  if (ranks() == 1) return v;
  double s = 0.0;
  MPI_Allreduce(&v, &s, 1, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
  return s;
}

double maxOverRanks(double v) {
  if (ranks() == 1) return v;
  double m = 0.0;
  MPI_Allreduce(&v, &m, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  return m;
}

std::uint64_t sumOverEarlierRanks(std::uint64_t v) {
  if (ranks() == 1) return 0;
  std::uint64_t before = 0;
  MPI_Exscan(&v, &before, 1, MPI_UINT64_T, MPI_SUM, PETSC_COMM_WORLD);
  return rank() == 0 ? 0 : before;
}

std::vector<std::vector<std::uint64_t>> askRanks(
    const std::vector<std::vector<std::int32_t>>& asks, int keyWords, int recordWords,
    const std::function<void(const std::int32_t* key, std::uint64_t* record)>& answer) {
  const int n = ranks();
  if (int(asks.size()) != n) throw std::invalid_argument("askRanks: one list of keys per rank");
  // the keys: counts, then the keys themselves (all-to-all)
  std::vector<int> sendCount(n), recvCount(n), sendOffset(n, 0), recvOffset(n, 0);
  for (int r = 0; r < n; ++r) sendCount[r] = int(asks[r].size());
  MPI_Alltoall(sendCount.data(), 1, MPI_INT, recvCount.data(), 1, MPI_INT, PETSC_COMM_WORLD);
  for (int r = 1; r < n; ++r) {
    sendOffset[r] = sendOffset[r - 1] + sendCount[r - 1];
    recvOffset[r] = recvOffset[r - 1] + recvCount[r - 1];
  }
  std::vector<std::int32_t> sent, received(std::size_t(recvOffset[n - 1] + recvCount[n - 1]));
  for (const auto& a : asks) sent.insert(sent.end(), a.begin(), a.end());
  MPI_Alltoallv(sent.data(), sendCount.data(), sendOffset.data(), MPI_INT32_T, received.data(), recvCount.data(),
                recvOffset.data(), MPI_INT32_T, PETSC_COMM_WORLD);
  // the answers, recordWords per key, back the same way
  const std::size_t keys = received.size() / std::size_t(keyWords);
  std::vector<std::uint64_t> replies(keys * std::size_t(recordWords));
  for (std::size_t k = 0; k < keys; ++k) answer(received.data() + k * keyWords, replies.data() + k * recordWords);
  auto scale = [&](std::vector<int>& v) {
    for (int& x : v) x = x / keyWords * recordWords;
  };
  scale(sendCount), scale(recvCount), scale(sendOffset), scale(recvOffset);
  std::vector<std::uint64_t> back(std::size_t(sendOffset[n - 1] + sendCount[n - 1]));
  MPI_Alltoallv(replies.data(), recvCount.data(), recvOffset.data(), MPI_UINT64_T, back.data(), sendCount.data(),
                sendOffset.data(), MPI_UINT64_T, PETSC_COMM_WORLD);
  std::vector<std::vector<std::uint64_t>> out(n);
  for (int r = 0; r < n; ++r) out[r].assign(back.begin() + sendOffset[r], back.begin() + sendOffset[r] + sendCount[r]);
  return out;
}

namespace {

// The stopping test of a method that measures its own (preconditioned) norm, MINRES: every
// kCheckEvery iterations it computes ||b - A x|| and stops once that is at most the target, as the
// in-house MINRES stops. A stop on the method's
// norm alone landed 20-200x below the target on the true residual, or above it, where a new solve
// then started without the Krylov space built so far. Past its own norm's stop the method goes on
// while the true residual still falls; once that stalls (kStallChecks checks without a 10% drop:
// the recurrence's rounding, ball 24 at 1e-12 stalled at 4e-12), it stops there and the caller's
// next solve starts from the true residual.
struct TrueResidualTest {
  static constexpr PetscInt kCheckEvery = 5;  // one more apply of A every 5 iterations
  static constexpr int kStallChecks = 4;
  double target = 0.0;
  void* defaultContext = nullptr;
  Vec scratch = nullptr, residual = nullptr;
  double best = 0.0;  // the smallest true residual of this solve so far
  int stalled = 0;    // checks since it last fell by 10%
  ~TrueResidualTest() {
    VecDestroy(&residual);
    VecDestroy(&scratch);
    if (defaultContext) KSPConvergedDefaultDestroy(defaultContext);
  }
};

PetscErrorCode trueResidualConverged(KSP ksp, PetscInt it, PetscReal ownNorm, KSPConvergedReason* reason, void* ctx) {
  auto* t = static_cast<TrueResidualTest*>(ctx);
  if (it == 0) t->best = std::numeric_limits<double>::infinity(), t->stalled = 0;
  PetscCall(KSPConvergedDefault(ksp, it, ownNorm, reason, t->defaultContext));
  if (*reason < 0) return 0;  // diverged or broke down: as PETSc says
  const KSPConvergedReason own = *reason;
  *reason = KSP_CONVERGED_ITERATING;
  if (it == 0 || it % TrueResidualTest::kCheckEvery != 0) return 0;
  Vec r = nullptr;
  PetscCall(KSPBuildResidual(ksp, t->scratch, t->residual, &r));
  PetscReal trueNorm = 0.0;
  PetscCall(VecNorm(r, NORM_2, &trueNorm));
  if (trueNorm <= t->target) {
    *reason = KSP_CONVERGED_RTOL;
    return 0;
  }
  if (trueNorm < 0.9 * t->best) t->best = trueNorm, t->stalled = 0;
  else ++t->stalled;
  *reason = own != KSP_CONVERGED_ITERATING && t->stalled >= TrueResidualTest::kStallChecks ? own : KSP_CONVERGED_ITERATING;
  return 0;
}

// One transfer as a parallel AIJ matrix: `rows` rows of this rank from `first` on.
Mat interpolationMatrix(const Interpolation& p, PetscInt rows, PetscInt first, MPI_Comm comm) {
  if (p.rowStart.size() != std::size_t(rows) + 1)
    throw std::invalid_argument("PETSc multigrid: a transfer needs one row per owned row of its finer level");
  std::vector<PetscInt> diagonalCount(std::size_t(rows), 0), offCount(std::size_t(rows), 0);
  const std::int64_t lo = p.coarseFirst, hi = p.coarseFirst + std::int64_t(p.coarseOwned);
  for (PetscInt i = 0; i < rows; ++i)
    for (std::int64_t k = p.rowStart[std::size_t(i)]; k < p.rowStart[std::size_t(i) + 1]; ++k)
      ++(p.columns[std::size_t(k)] >= lo && p.columns[std::size_t(k)] < hi ? diagonalCount : offCount)[std::size_t(i)];
  Mat m = nullptr;
  STOKES_PETSC(MatCreateAIJ(comm, rows, PetscInt(p.coarseOwned), PETSC_DETERMINE, PETSC_DETERMINE, 0,
                            diagonalCount.data(), 0, offCount.data(), &m));
  std::vector<PetscInt> columns;
  for (PetscInt i = 0; i < rows; ++i) {
    const std::int64_t b = p.rowStart[std::size_t(i)], e = p.rowStart[std::size_t(i) + 1];
    columns.assign(p.columns.begin() + b, p.columns.begin() + e);
    const PetscInt row = first + i;
    STOKES_PETSC(MatSetValues(m, 1, &row, PetscInt(e - b), columns.data(), p.values.data() + b, ADD_VALUES));
  }
  STOKES_PETSC(MatAssemblyBegin(m, MAT_FINAL_ASSEMBLY));
  STOKES_PETSC(MatAssemblyEnd(m, MAT_FINAL_ASSEMBLY));
  return m;
}

PetscErrorCode fineSmootherApply(PC pc, Vec r, Vec z) {
  void* ctx = nullptr;
  PetscCall(PCShellGetContext(pc, &ctx));
  const auto& apply = *static_cast<const std::function<void(const double*, double*)>*>(ctx);
  const PetscScalar* a = nullptr;
  PetscScalar* b = nullptr;
  PetscCall(VecGetArrayRead(r, &a));
  PetscCall(VecGetArray(z, &b));
  apply(a, b);
  PetscCall(VecRestoreArray(z, &b));
  PetscCall(VecRestoreArrayRead(r, &a));
  return 0;
}

// The levels' smoother preconditioners, unless the options database names them: Jacobi, and on
// the finest level the system's own (DistributedSystem::fieldZeroSmoother) as a PCSHELL. PETSc's
// own default, SOR, is local to each rank: the cycle would change with the split.
void chooseSmoothers(const DistributedSystem& s, PC mg, PetscInt levels, SolveObjects& o) {
  for (PetscInt l = 1; l < levels; ++l) {
    KSP smoother = nullptr;
    PC pc = nullptr;
    STOKES_PETSC(PCMGGetSmoother(mg, l, &smoother));
    STOKES_PETSC(KSPGetPC(smoother, &pc));
    const char* prefix = nullptr;
    STOKES_PETSC(KSPGetOptionsPrefix(smoother, &prefix));
    // PETSc finds "-..._mg_levels_pc_type" for this level's "-..._mg_levels_3_pc_type" too
    const std::string name = std::string("-") + (prefix ? prefix : "") + "pc_type";
    PetscBool named = PETSC_FALSE;
    STOKES_PETSC(PetscOptionsHasName(nullptr, nullptr, name.c_str(), &named));
    if (named) continue;
    if (l + 1 == levels && s.fieldZeroSmoother) {
      o.fineSmoother = s.fieldZeroSmoother();
      STOKES_PETSC(PCSetType(pc, PCSHELL));
      STOKES_PETSC(PCShellSetContext(pc, &o.fineSmoother));
      STOKES_PETSC(PCShellSetApply(pc, fineSmootherApply));
      STOKES_PETSC(PCShellSetName(pc, "Jacobi with the strongly coupled face groups inverted"));
    } else {
      STOKES_PETSC(PCSetType(pc, PCJACOBI));
    }
  }
}

// PCMG on field 0 (`mg`, the preconditioner of its sub-solver `first`): the system's levels
// (DistributedSystem::fieldZeroLevels) with Galerkin coarse operators; the smoothers read their
// options (-fieldsplit_0_mg_levels_...), then chooseSmoothers sets the rest.
void multigridLevels(const DistributedSystem& s, PC mg, KSP first, SolveObjects& o) {
  const std::vector<Interpolation> levels = s.fieldZeroLevels();
  if (levels.empty()) return;
  const MPI_Comm comm = PetscObjectComm((PetscObject)mg);
  const PetscInt fineRows = PetscInt(std::count(s.field.begin(), s.field.end(), 0));
  const PetscInt levelCount = PetscInt(levels.size()) + 1;
  STOKES_PETSC(PCMGSetLevels(mg, levelCount, nullptr));
  PetscInt rows = fineRows, firstRow = PetscInt(sumOverEarlierRanks(std::uint64_t(fineRows)));
  for (std::size_t l = 0; l < levels.size(); ++l) {  // PCMG's level levelCount - 1 is the finest
    o.interpolations.push_back(interpolationMatrix(levels[l], rows, firstRow, comm));
    STOKES_PETSC(PCMGSetInterpolation(mg, levelCount - 1 - PetscInt(l), o.interpolations.back()));
    rows = PetscInt(levels[l].coarseOwned), firstRow = PetscInt(levels[l].coarseFirst);
  }
  STOKES_PETSC(PCMGSetGalerkin(mg, PC_MG_GALERKIN_BOTH));
  STOKES_PETSC(PCSetFromOptions(mg));
  chooseSmoothers(s, mg, levelCount, o);
  STOKES_PETSC(KSPSetUp(first));  // the coarse operators now, not in the first apply: set-up time
}

// Field 0's preconditioner, once the field split is set up (so that its sub-solvers exist and
// have read their options): GAMG gets the system's near-null space on the block's matrix, PCMG the
// system's levels (multigridLevels).
void configureFieldZero(const DistributedSystem& s, PC pc, SolveObjects& o) {
  STOKES_PETSC(PCSetUp(pc));
  PetscInt splits = 0;
  KSP* sub = nullptr;
  STOKES_PETSC(PCFieldSplitGetSubKSP(pc, &splits, &sub));
  KSP first = sub[0];
  STOKES_PETSC(PetscFree(sub));
  PC inner = nullptr;
  STOKES_PETSC(KSPGetPC(first, &inner));
  PetscBool isGamg = PETSC_FALSE, isMg = PETSC_FALSE;
  STOKES_PETSC(PetscObjectTypeCompare((PetscObject)inner, PCGAMG, &isGamg));
  STOKES_PETSC(PetscObjectTypeCompare((PetscObject)inner, PCMG, &isMg));
  if (isGamg && s.nearNullSpace) {
    Mat block = nullptr;
    STOKES_PETSC(KSPGetOperators(first, nullptr, &block));
    attachNearNullSpace(s, std::size_t(std::count(s.field.begin(), s.field.end(), 0)), block, o);
  } else if (isMg && s.fieldZeroLevels) {
    multigridLevels(s, inner, first, o);
  }
}

}  // namespace

PetscReport solveDistributed(const DistributedSystem& s, const SolveOptions& opt, double* xOwned,
                             std::vector<double>* ghostValues) {
  Session::initialise({});
  const auto t0 = std::chrono::steady_clock::now();
  const MPI_Comm comm = PETSC_COMM_WORLD;
  const PetscInt m = PetscInt(s.ownedRows), N = PetscInt(s.globalRows);
  if (s.rhs.size() != s.ownedRows || s.diagonal.size() != s.ownedRows || s.field.size() != s.ownedRows)
    throw std::invalid_argument("PETSc solve: rhs, diagonal and field need one value per owned row");
  PetscReport rep;
  rep.ranks = ranks();
  {
    // the split: owned rows and halo per rank (ghostRows holds the owned rows too)
    unsigned long long mine[2] = {s.ownedRows, s.ghostRows.size() - s.ownedRows}, lo = 0, hi[2] = {0, 0}, sum = 0;
    MPI_Allreduce(&mine[0], &lo, 1, MPI_UNSIGNED_LONG_LONG, MPI_MIN, comm);
    MPI_Allreduce(mine, hi, 2, MPI_UNSIGNED_LONG_LONG, MPI_MAX, comm);
    MPI_Allreduce(&mine[1], &sum, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, comm);
    rep.rowsMin = lo, rep.rowsMax = hi[0], rep.haloMax = hi[1], rep.haloSum = sum;
  }
  SolveObjects o;

  // vectors and the ghost scatter (the halo exchange of every apply)
  STOKES_PETSC(VecCreateMPI(comm, m, N, &o.x));
  exactReductions(o.x);
  STOKES_PETSC(VecDuplicate(o.x, &o.b));
  STOKES_PETSC(VecDuplicate(o.x, &o.work));
  fillVec(o.b, s.rhs);
  {
    PetscScalar* a = nullptr;
    STOKES_PETSC(VecGetArray(o.x, &a));
    std::copy(xOwned, xOwned + s.ownedRows, a);
    STOKES_PETSC(VecRestoreArray(o.x, &a));
  }
  std::vector<PetscInt> ghost(s.ghostRows.begin(), s.ghostRows.end());
  STOKES_PETSC(VecCreateSeq(PETSC_COMM_SELF, PetscInt(ghost.size()), &o.ghosts));
  STOKES_PETSC(ISCreateGeneral(PETSC_COMM_SELF, PetscInt(ghost.size()), ghost.data(), PETSC_COPY_VALUES, &o.ghostIs));
  STOKES_PETSC(VecScatterCreate(o.x, o.ghostIs, o.ghosts, nullptr, &o.scatter));

  ShellContext ctx{&s, o.scatter, o.ghosts, o.x};
  STOKES_PETSC(MatCreateShell(comm, m, m, N, N, &ctx, &o.shell));
  STOKES_PETSC(MatShellSetOperation(o.shell, MATOP_MULT, (void (*)(void))shellMult));
  STOKES_PETSC(MatShellSetOperation(o.shell, MATOP_CREATE_VECS, (void (*)(void))shellCreateVecs));
  STOKES_PETSC(MatShellSetOperation(o.shell, MATOP_GET_DIAGONAL, (void (*)(void))shellDiagonal));
  STOKES_PETSC(MatSetOption(o.shell, MAT_SYMMETRIC, PETSC_TRUE));

  if (!s.nullSpace.empty()) {
    // a closed container: the constant pressure; b is made consistent with it
    STOKES_PETSC(VecDuplicate(o.x, &o.nullVec));
    fillVec(o.nullVec, s.nullSpace);
    STOKES_PETSC(VecNormalize(o.nullVec, nullptr));
    STOKES_PETSC(MatNullSpaceCreate(comm, PETSC_FALSE, 1, &o.nullVec, &o.nullSpace));
    STOKES_PETSC(MatSetNullSpace(o.shell, o.nullSpace));
    STOKES_PETSC(MatNullSpaceRemove(o.nullSpace, o.b));
  }

  // the system's own defaults, for the options the user did not give; taken out again after
  DefaultOptions defaults(s.defaultOptions);
  STOKES_PETSC(KSPCreate(comm, &o.ksp));
  STOKES_PETSC(KSPSetOperators(o.ksp, o.shell, o.shell));
  STOKES_PETSC(KSPSetType(o.ksp, KSPCG));
  PC pc = nullptr;
  STOKES_PETSC(KSPGetPC(o.ksp, &pc));
  STOKES_PETSC(PCSetType(pc, PCJACOBI));
  STOKES_PETSC(KSPSetTolerances(o.ksp, opt.relativeTolerance, opt.absoluteTolerance, opt.divergenceFactor,
                                opt.maxIterations));
  STOKES_PETSC(KSPSetInitialGuessNonzero(o.ksp, PETSC_TRUE));
  STOKES_PETSC(KSPSetFromOptions(o.ksp));
  chooseNorm(o.ksp);
  if (needsEntries(pc)) {
    // the shell still defines the system; the preconditioner is built from the AIJ copy
    o.assembled = assemble(s);
    MatInfo info;
    STOKES_PETSC(MatGetInfo(o.assembled, MAT_GLOBAL_SUM, &info));
    rep.assembledNonzeros = (long long)info.nz_used;
    rep.assembledNote = s.assembledNote;
    STOKES_PETSC(MatSetOption(o.assembled, MAT_SYMMETRIC, PETSC_TRUE));
    if (o.nullSpace && s.assembledHasNullSpace) STOKES_PETSC(MatSetNullSpace(o.assembled, o.nullSpace));
    STOKES_PETSC(KSPSetOperators(o.ksp, o.shell, o.assembled));
  }
  PetscBool split = PETSC_FALSE;
  STOKES_PETSC(PetscObjectTypeCompare((PetscObject)pc, PCFIELDSPLIT, &split));
  if (split) {
    const int fields = int(std::max<std::size_t>(1, s.fieldNames.size()));
    for (int f = 0; f < fields; ++f) {
      std::vector<PetscInt> rows;
      for (std::size_t k = 0; k < s.ownedRows; ++k)
        if (s.field[k] == f) rows.push_back(PetscInt(s.firstRow + std::int64_t(k)));
      IS is = nullptr;
      STOKES_PETSC(ISCreateGeneral(comm, PetscInt(rows.size()), rows.data(), PETSC_COPY_VALUES, &is));
      o.fieldIs.push_back(is);
      STOKES_PETSC(PCFieldSplitSetIS(pc, std::to_string(f).c_str(), is));
    }
  }
  if (split && (s.fieldZeroLevels || s.nearNullSpace)) configureFieldZero(s, pc, o);
  STOKES_PETSC(KSPSetUp(o.ksp));
  rep.setupSeconds = secondsSince(t0);

  const auto t1 = std::chrono::steady_clock::now();
  // ||b - A x|| with the shell, as the in-house solvers report it
  PetscReal bNorm = 0.0, rNorm = 0.0;
  STOKES_PETSC(VecNorm(o.b, NORM_2, &bNorm));
  auto trueResidual = [&] {
    STOKES_PETSC(MatMult(o.shell, o.x, o.work));
    STOKES_PETSC(VecAYPX(o.work, -1.0, o.b));
    STOKES_PETSC(VecNorm(o.work, NORM_2, &rNorm));
  };
  const double target = std::max(opt.relativeTolerance * bNorm, opt.absoluteTolerance);
  // A method that stops on its own (preconditioned) norm may call a solve converged whose true
  // residual is above the tolerance: it continues from there with its tolerance scaled by the
  // shortfall (kMoreSolves times at most), as the in-house MINRES checks its true residual.
  // (A method stopping on ||b - A x|| itself, CG here, drifts only by rounding: it stops once.)
  constexpr int kMoreSolves = 4;
  KSPNormType norm = KSP_NORM_DEFAULT;
  STOKES_PETSC(KSPGetNormType(o.ksp, &norm));
  const int moreSolves = norm == KSP_NORM_UNPRECONDITIONED ? 0 : kMoreSolves;
  TrueResidualTest test{target};
  if (norm != KSP_NORM_UNPRECONDITIONED && norm != KSP_NORM_NONE) {
    STOKES_PETSC(KSPConvergedDefaultCreate(&test.defaultContext));
    STOKES_PETSC(VecDuplicate(o.x, &test.scratch));
    STOKES_PETSC(VecDuplicate(o.x, &test.residual));
    STOKES_PETSC(KSPSetConvergenceTest(o.ksp, trueResidualConverged, &test, nullptr));
  }
  KSPConvergedReason reason = KSP_CONVERGED_ITERATING;
  PetscInt its = 0, total = 0;
  double rtol = opt.relativeTolerance;
  for (int attempt = 0; attempt <= moreSolves; ++attempt) {
    STOKES_PETSC(KSPSolve(o.ksp, o.b, o.x));
    STOKES_PETSC(KSPGetConvergedReason(o.ksp, &reason));
    STOKES_PETSC(KSPGetIterationNumber(o.ksp, &its));
    total += its;
    trueResidual();
    if (reason <= 0 || !std::isfinite(rNorm) || rNorm <= target || total >= opt.maxIterations) break;
    rtol *= 0.5 * target / rNorm;
    STOKES_PETSC(KSPSetTolerances(o.ksp, rtol, opt.absoluteTolerance, opt.divergenceFactor,
                                  PetscInt(opt.maxIterations) - total));
    ++rep.restarts;
  }
  rep.solveSeconds = secondsSince(t1);
  rep.reason = KSPConvergedReasons[reason];
  rep.solve.status = statusOf(reason);
  rep.solve.iterations = int(total);
  KSPType type = nullptr;
  PCType pcType = nullptr;
  STOKES_PETSC(KSPGetType(o.ksp, &type));
  STOKES_PETSC(PCGetType(pc, &pcType));
  rep.kspType = type;
  rep.pcType = pcType;
  rep.normType = KSPNormTypes[norm];
  rep.solve.finalResidual = rNorm;
  rep.solve.relativeResidual = bNorm > 0.0 ? rNorm / bNorm : 0.0;
  if (!std::isfinite(rNorm)) rep.solve.status = Status::NonFinite;
  // still far from the tolerance after its continuations (an indefinite preconditioner under
  // MINRES, say): a failed solve, not an answer
  if (rep.solve.status == Status::Converged && rNorm > 100.0 * target) {
    rep.solve.status = Status::Breakdown;
    rep.reason += " (its own norm converged, but ||b - A x|| / ||b|| = " + std::to_string(rep.solve.relativeResidual) + ")";
  }

  const PetscScalar* a = nullptr;
  STOKES_PETSC(VecGetArrayRead(o.x, &a));
  std::copy(a, a + s.ownedRows, xOwned);
  STOKES_PETSC(VecRestoreArrayRead(o.x, &a));
  if (ghostValues) {
    STOKES_PETSC(VecScatterBegin(o.scatter, o.x, o.ghosts, INSERT_VALUES, SCATTER_FORWARD));
    STOKES_PETSC(VecScatterEnd(o.scatter, o.x, o.ghosts, INSERT_VALUES, SCATTER_FORWARD));
    STOKES_PETSC(VecGetArrayRead(o.ghosts, &a));
    ghostValues->assign(a, a + s.ghostRows.size());
    STOKES_PETSC(VecRestoreArrayRead(o.ghosts, &a));
  }
  return rep;
}

}  // namespace stokes::solver::petsc
