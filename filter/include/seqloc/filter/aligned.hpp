#pragma once
// Buffers the filter's vectorized loops run over. Eigen splits a loop over a buffer into a scalar
// head up to the first aligned address, a packet body and a scalar tail; packet exp, log, fused
// multiply-add and sums round differently from their scalar forms, so on a buffer of arbitrary
// address the last bits of a result depended on where the allocator happened to put it (a run
// of several routes side by side gave other beliefs than the same route alone). Buffers aligned
// to a cache line give every run the same split.

#include <cstddef>
#include <cstdint>
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
  /// From the ordinary heap (plain operator new, n * sizeof(T) + 64 bytes), the pointer moved
  /// up to the next 64-byte boundary and the distance kept in the byte before it. With aligned
  /// operator new (glibc's memalign) the frames' buffers were not reused as well: bench/localize's
  /// peak memory rose from 260 to 357 MB (npy route) and from 368 to 1,215 MB (online mode).
  [[nodiscard]] T* allocate(std::size_t n) {
    auto* raw = static_cast<unsigned char*>(::operator new(n * sizeof(T) + kBufferAlignment));
    const std::size_t shift = kBufferAlignment - reinterpret_cast<std::uintptr_t>(raw) % kBufferAlignment;  // 1..64
    unsigned char* aligned = raw + shift;
    aligned[-1] = static_cast<unsigned char>(shift);
    return reinterpret_cast<T*>(aligned);
  }
  void deallocate(T* p, std::size_t /*n*/) noexcept {
    auto* aligned = reinterpret_cast<unsigned char*>(p);
    ::operator delete(aligned - aligned[-1]);
  }
  template <class U>
  bool operator==(const AlignedAllocator<U>& /*other*/) const noexcept {
    return true;
  }
};

/// A std::vector whose data starts on a 64-byte boundary.
template <class T>
using AlignedVector = std::vector<T, AlignedAllocator<T>>;

}  // namespace seqloc::filter
