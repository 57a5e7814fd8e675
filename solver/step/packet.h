#pragma once
// The messages between MPI ranks, as flat byte buffers: values and vectors appended in order and
// read back in the same order (the leader's step packets, solver/step/remote_step.h; a split
// scene's particles and halo values, sim/ranks/). Plain values only (trivially copyable).
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <vector>

namespace stokes::solver {
inline namespace step {

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
  /// Whether every byte has been read.
  bool done() const { return read_ == bytes_.size(); }
  std::vector<char>& bytes() { return bytes_; }
  const std::vector<char>& bytes() const { return bytes_; }

 private:
  void take(void* out, std::size_t n) {
    if (read_ + n > bytes_.size()) throw std::runtime_error("message between ranks: truncated");
    std::memcpy(out, bytes_.data() + read_, n);
    read_ += n;
  }
  std::vector<char> bytes_;
  std::size_t read_ = 0;
};

}  // namespace step
}  // namespace stokes::solver
