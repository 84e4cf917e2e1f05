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
#include <utility>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace seqloc::intake {

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

/// AlignedAllocator whose resize leaves new values uninitialized (default-initialized), for a
/// buffer that is written whole after it is sized: a frame's 16 MB were otherwise written twice,
/// once with zeros.
template <class T>
struct UninitializedAlignedAllocator : AlignedAllocator<T> {
  using value_type = T;
  template <class U>
  struct rebind {
    using other = UninitializedAlignedAllocator<U>;
  };
  UninitializedAlignedAllocator() noexcept = default;
  template <class U>
  explicit UninitializedAlignedAllocator(const UninitializedAlignedAllocator<U>& /*other*/) noexcept {}
  /// As AlignedAllocator's; a buffer of 4 MB or more asks for transparent huge pages (Linux, where
  /// they are given on request): a frame's fresh 16 MB then fault in eight pages, not 4,096.
  [[nodiscard]] T* allocate(std::size_t n) {
    T* p = AlignedAllocator<T>::allocate(n);
#if defined(__linux__)
    constexpr std::uintptr_t kHuge = std::uintptr_t{1} << 21;
    const std::size_t bytes = n * sizeof(T);
    if (bytes >= (std::size_t{4} << 20)) {
      const auto begin = (reinterpret_cast<std::uintptr_t>(p) + kHuge - 1) & ~(kHuge - 1);
      const auto end = (reinterpret_cast<std::uintptr_t>(p) + bytes) & ~(kHuge - 1);
      // NOLINTNEXTLINE(performance-no-int-to-ptr): the 2 MB-aligned part of our own buffer
      if (end > begin) (void)::madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
    }
#endif
    return p;
  }
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;  // NOLINT(cppcoreguidelines-pro-type-member-init): left for the writer
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

/// An AlignedVector whose resize does not initialize what it adds (UninitializedAlignedAllocator).
template <class T>
using UninitializedAlignedVector = std::vector<T, UninitializedAlignedAllocator<T>>;

}  // namespace seqloc::intake
