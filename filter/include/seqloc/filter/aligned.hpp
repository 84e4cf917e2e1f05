#pragma once
// Buffers the filter's vectorized loops run over. Eigen splits a loop over a buffer into a scalar
// head up to the first aligned address, a packet body and a scalar tail; packet exp, log, fused
// multiply-add and sums round differently from their scalar forms, so on a buffer of arbitrary
// address the last bits of a result depended on where the allocator happened to put it (a run
// of several routes side by side gave other beliefs than the same route alone). Buffers aligned
// to a cache line give every run the same split.

#include <cstddef>
#include <new>
#include <vector>

namespace seqloc::filter {

inline constexpr std::size_t kBufferAlignment = 64;

template <class T>
struct AlignedAllocator {
  using value_type = T;
  AlignedAllocator() noexcept = default;
  template <class U>
  explicit AlignedAllocator(const AlignedAllocator<U>& /*other*/) noexcept {}
  [[nodiscard]] T* allocate(std::size_t n) {
    return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t{kBufferAlignment}));
  }
  void deallocate(T* p, std::size_t /*n*/) noexcept { ::operator delete(p, std::align_val_t{kBufferAlignment}); }
  template <class U>
  bool operator==(const AlignedAllocator<U>& /*other*/) const noexcept {
    return true;
  }
};

/// A std::vector whose data starts on a 64-byte boundary.
template <class T>
using AlignedVector = std::vector<T, AlignedAllocator<T>>;

}  // namespace seqloc::filter
