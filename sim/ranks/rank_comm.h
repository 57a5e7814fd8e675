#pragma once
// The messages of a simulation split over MPI ranks by blocks (docs/petsc.md, "Particles by
// block"): all-to-all exchanges of byte buffers, gathers to every rank, and exact integer sums.
// Without MPI (a build without the PETSc backend, or MPI not initialised) there is one rank and
// every call is local.
#include <cstdint>
#include <cstring>
#include <functional>
#include <stdexcept>
#include <vector>

namespace stokes::sim {
inline namespace ranks {

/// This process's rank and the number of ranks (0 and 1 without MPI).
int thisRank();
int rankCount();

/// A message: plain values (trivially copyable) written and read back in order.
class Bytes {
 public:
  template <class T>
  void put(const T& v) {
    const char* p = reinterpret_cast<const char*>(&v);
    bytes_.insert(bytes_.end(), p, p + sizeof(T));
  }
  template <class T>
  T get() {
    T v;
    if (read_ + sizeof(T) > bytes_.size()) throw std::runtime_error("message between ranks: truncated");
    std::memcpy(&v, bytes_.data() + read_, sizeof(T));
    read_ += sizeof(T);
    return v;
  }
  /// Whether every byte has been read.
  bool done() const { return read_ == bytes_.size(); }
  std::vector<char>& bytes() { return bytes_; }
  const std::vector<char>& bytes() const { return bytes_; }

 private:
  std::vector<char> bytes_;
  std::size_t read_ = 0;
};

/// Sends out[r] to rank r (out.size() == rankCount()) and returns what each rank sent this one, by
/// sender. Collective.
std::vector<Bytes> exchange(const std::vector<Bytes>& out);
/// Every rank's buffer, by rank. Collective.
std::vector<Bytes> allGather(const Bytes& mine);
/// Every rank's buffer on rank 0, streamed: `take` (called on rank 0 only) gets them one at a
/// time in rank order (rank 0's own first), each received after the previous was taken, so rank 0
/// holds one other rank's buffer at a time besides what `take` keeps. Collective.
void streamToRoot(Bytes mine, const std::function<void(Bytes&)>& take);
/// Sum and maximum over the ranks. Integer sums are exact, so they do not depend on the rank count
/// or the order of the ranks. Collective.
std::int64_t sumOverRanks(std::int64_t v);
double maxOverRanks(double v);
/// Logical and over the ranks: whether every rank says true. Collective.
bool allRanks(bool v);

}  // namespace ranks
}  // namespace stokes::sim
