#pragma once
// Cache-line aligned storage for the Krylov work vectors.
//
// Aligning every vector to 64 bytes keeps the streaming loops in vector_ops.h
// free of peeling prologues and makes the OpenMP static partition land on whole
// cache lines, so two threads never write into the same line (no false sharing
// apart from the single boundary line of each thread's range).

#include <cstddef>
#include <limits>
#include <new>
#include <type_traits>
#include <vector>

namespace stokes::solver {
inline namespace krylov {

// Minimal std-conforming allocator returning storage aligned to `Align` bytes.
template <class T, std::size_t Align = 64>
struct AlignedAllocator {
  static_assert(Align >= alignof(T), "alignment must not be weaker than alignof(T)");
  static_assert((Align & (Align - 1)) == 0, "alignment must be a power of two");

  using value_type = T;
  using size_type = std::size_t;
  using difference_type = std::ptrdiff_t;
  using propagate_on_container_move_assignment = std::true_type;
  using is_always_equal = std::true_type;

  template <class U>
  struct rebind {
    using other = AlignedAllocator<U, Align>;
  };

  AlignedAllocator() noexcept = default;
  template <class U>
  constexpr AlignedAllocator(const AlignedAllocator<U, Align>&) noexcept {}

  [[nodiscard]] T* allocate(std::size_t n) {
    if (n > std::numeric_limits<std::size_t>::max() / sizeof(T)) throw std::bad_array_new_length();
    return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t(Align)));
  }

  void deallocate(T* p, std::size_t) noexcept { ::operator delete(p, std::align_val_t(Align)); }

  template <class U>
  constexpr bool operator==(const AlignedAllocator<U, Align>&) const noexcept {
    return true;
  }
};

// The solver's vector type: contiguous doubles on 64-byte boundaries.
using Vector = std::vector<double, AlignedAllocator<double>>;

}  // namespace krylov
}  // namespace stokes::solver
