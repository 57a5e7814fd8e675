// Messages between ranks: see rank_comm.h.
#include "sim/ranks/rank_comm.h"

#include <algorithm>
#include <limits>

#ifdef STOKES_HAVE_PETSC
#include <mpi.h>
#endif

namespace stokes::sim {
inline namespace ranks {

namespace {

#ifdef STOKES_HAVE_PETSC
bool haveMpi() {
  int initialised = 0, finalised = 0;
  MPI_Initialized(&initialised);
  MPI_Finalized(&finalised);
  return initialised && !finalised;
}

/// MPI counts are int: a message of 2 GiB or more is refused rather than truncated.
int countOf(std::size_t n) {
  if (n > std::size_t(std::numeric_limits<int>::max()))
    throw std::runtime_error("rank message of " + std::to_string(n) + " bytes: over MPI's 2 GiB limit");
  return int(n);
}
#endif

}  // namespace

int thisRank() {
#ifdef STOKES_HAVE_PETSC
  if (!haveMpi()) return 0;
  int r = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &r);
  return r;
#else
  return 0;
#endif
}

int rankCount() {
#ifdef STOKES_HAVE_PETSC
  if (!haveMpi()) return 1;
  int n = 1;
  MPI_Comm_size(MPI_COMM_WORLD, &n);
  return n;
#else
  return 1;
#endif
}

std::vector<Bytes> exchange(const std::vector<Bytes>& out) {
  const int n = rankCount();
  if (int(out.size()) != n) throw std::invalid_argument("exchange: one buffer per rank");
  std::vector<Bytes> in(static_cast<std::size_t>(n));
  if (n == 1) {
    in[0].bytes() = out[0].bytes();
    return in;
  }
#ifdef STOKES_HAVE_PETSC
  std::vector<int> sendCount(n), recvCount(n), sendOffset(n, 0), recvOffset(n, 0);
  for (int r = 0; r < n; ++r) sendCount[r] = countOf(out[r].bytes().size());
  MPI_Alltoall(sendCount.data(), 1, MPI_INT, recvCount.data(), 1, MPI_INT, MPI_COMM_WORLD);
  std::size_t sendTotal = 0, recvTotal = 0;
  for (int r = 0; r < n; ++r) {
    sendOffset[r] = countOf(sendTotal);
    recvOffset[r] = countOf(recvTotal);
    sendTotal += std::size_t(sendCount[r]);
    recvTotal += std::size_t(recvCount[r]);
  }
  std::vector<char> sent(sendTotal), received(recvTotal);
  for (int r = 0; r < n; ++r) std::copy(out[r].bytes().begin(), out[r].bytes().end(), sent.begin() + sendOffset[r]);
  MPI_Alltoallv(sent.data(), sendCount.data(), sendOffset.data(), MPI_CHAR, received.data(), recvCount.data(),
                recvOffset.data(), MPI_CHAR, MPI_COMM_WORLD);
  for (int r = 0; r < n; ++r)
    in[r].bytes().assign(received.begin() + recvOffset[r], received.begin() + recvOffset[r] + recvCount[r]);
#endif
  return in;
}

std::vector<Bytes> allGather(const Bytes& mine) {
  const int n = rankCount();
  std::vector<Bytes> all(static_cast<std::size_t>(n));
  if (n == 1) {
    all[0].bytes() = mine.bytes();
    return all;
  }
#ifdef STOKES_HAVE_PETSC
  int count = countOf(mine.bytes().size());
  std::vector<int> counts(n), offsets(n, 0);
  MPI_Allgather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, MPI_COMM_WORLD);
  std::size_t total = 0;
  for (int r = 0; r < n; ++r) {
    offsets[r] = countOf(total);
    total += std::size_t(counts[r]);
  }
  std::vector<char> received(total);
  MPI_Allgatherv(mine.bytes().data(), count, MPI_CHAR, received.data(), counts.data(), offsets.data(), MPI_CHAR,
                 MPI_COMM_WORLD);
  for (int r = 0; r < n; ++r) all[r].bytes().assign(received.begin() + offsets[r], received.begin() + offsets[r] + counts[r]);
#endif
  return all;
}

void streamToRoot(Bytes mine, const std::function<void(Bytes&)>& take) {
  const int n = rankCount();
  if (thisRank() == 0) {
    take(mine);
    mine = Bytes();  // taken: not held while the others stream in
  }
  if (n == 1) return;
#ifdef STOKES_HAVE_PETSC
  constexpr int kTag = 7301;
  if (thisRank() != 0) {
    MPI_Send(mine.bytes().data(), countOf(mine.bytes().size()), MPI_CHAR, 0, kTag, MPI_COMM_WORLD);
    return;
  }
  for (int r = 1; r < n; ++r) {
    MPI_Status status;
    MPI_Probe(r, kTag, MPI_COMM_WORLD, &status);
    int count = 0;
    MPI_Get_count(&status, MPI_CHAR, &count);
    Bytes theirs;
    theirs.bytes().resize(std::size_t(count));
    MPI_Recv(theirs.bytes().data(), count, MPI_CHAR, r, kTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    take(theirs);
  }
#endif
}

std::int64_t sumOverRanks(std::int64_t v) {
#ifdef STOKES_HAVE_PETSC
  if (rankCount() > 1) {
    std::int64_t sum = 0;
    MPI_Allreduce(&v, &sum, 1, MPI_INT64_T, MPI_SUM, MPI_COMM_WORLD);
    return sum;
  }
#endif
  return v;
}

double maxOverRanks(double v) {
#ifdef STOKES_HAVE_PETSC
  if (rankCount() > 1) {
    double m = v;
    MPI_Allreduce(&v, &m, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    return m;
  }
#endif
  return v;
}

bool allRanks(bool v) {
#ifdef STOKES_HAVE_PETSC
  if (rankCount() > 1) {
    int mine = v ? 1 : 0, all = 0;
    MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_LAND, MPI_COMM_WORLD);
    return all != 0;
  }
#endif
  return v;
}

}  // namespace ranks
}  // namespace stokes::sim
