// The frame intake's SIMD loops (frame_intake_simd.hpp): eight lanes (AVX2, FMA, F16C) and sixteen
// (AVX-512F), each function compiled for its instructions by its target attribute whatever the
// build's -march, and run only where the CPU has them. The two widths take the same operations
// lane by lane, so they give the same values bit for bit.

#include "frame_intake_simd.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>

#include "seqloc/intake/frame.hpp"

#if defined(__x86_64__)
#include <cpuid.h>
#include <immintrin.h>
#endif

// The sixteen-lane loops need a compiler that knows AVX-512's intrinsics (GCC >= 5, clang >= 3.9).
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define SEQLOC_INTAKE_AVX512 1
#else
#define SEQLOC_INTAKE_AVX512 0
#endif

namespace seqloc::intake::detail {

#if defined(__x86_64__)

namespace {
std::atomic<int> lanes_cap{16};

/// The vector width (in floats) the CPU runs: 16 with AVX-512F, 8 with AVX2, FMA and F16C, else 1.
int hardware_lanes() {
  static const int lanes = [] {
    // F16C from CPUID leaf 1 (clang's __builtin_cpu_supports does not know "f16c").
    unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
    const bool f16c = __get_cpuid(1, &eax, &ebx, &ecx, &edx) != 0 && (ecx & bit_F16C) != 0;
    if (!(__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") && f16c)) return 1;
    return SEQLOC_INTAKE_AVX512 && __builtin_cpu_supports("avx512f") ? 16 : 8;
  }();
  return lanes;
}
}  // namespace

int intake_lanes() { return std::min(hardware_lanes(), lanes_cap.load(std::memory_order_relaxed)); }

int cap_intake_lanes(int lanes) { return lanes_cap.exchange(lanes, std::memory_order_relaxed); }

namespace {

#define SEQLOC_SIMD __attribute__((target("avx2,fma,f16c"))) inline

constexpr float kZero = kLogZero;

/// Eight values of a cell's bins as float: `lanes` of them from `at`, the rest -inf (a zero).
SEQLOC_SIMD __m256 load8(const std::uint16_t* at, int lanes) {
  if (lanes == 8) return _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(at)));
  alignas(16) std::uint16_t padded[8] = {0xFC00, 0xFC00, 0xFC00, 0xFC00, 0xFC00, 0xFC00, 0xFC00, 0xFC00};
  std::copy(at, at + lanes, padded);
  return _mm256_cvtph_ps(_mm_load_si128(reinterpret_cast<const __m128i*>(padded)));
}
SEQLOC_SIMD __m256 load8(const float* at, int lanes) {
  if (lanes == 8) return _mm256_loadu_ps(at);
  alignas(32) float padded[8];
  std::fill(padded, padded + 8, -std::numeric_limits<float>::infinity());
  std::copy(at, at + lanes, padded);
  return _mm256_load_ps(padded);
}

/// A value as the filter takes it: raw * power where raw > kLogZero, kLogZero where raw <= kLogZero,
/// and NaN where raw is NaN, so that a NaN reaches the sums, which are checked instead of every
/// value (maxps returns its second operand where either is NaN).
template <bool Raised>
SEQLOC_SIMD __m256 powered(__m256 raw, __m256 power) {
  const __m256 zero = _mm256_set1_ps(kZero);
  if constexpr (!Raised) return _mm256_max_ps(zero, raw);
  return _mm256_blendv_ps(zero, _mm256_mul_ps(raw, power), _mm256_cmp_ps(raw, zero, _CMP_NLE_UQ));
}

/// log of the smallest normal float: an exp below it counts zero.
constexpr float kLogSmallestNormal = -87.3365448f;

/// exp's polynomial on [-log 2 / 2, log 2 / 2], 1 + c1 r + ... + c5 r^5: a minimax fit of the
/// relative error (Lawson's iteration over 20,001 points) with the constant held at 1, so that
/// exp(0) is 1 exactly (a frame with all its mass in one cell has log-probability 0 there).
constexpr float kExp0 = 1.0f, kExp1 = 0.99999970198f, kExp2 = 0.49999150634f, kExp3 = 0.16667635739f,
                kExp4 = 0.041897922754f, kExp5 = 0.0082903029397f;

/// exp(a) for log of the smallest normal float <= a <= 88 (below, the result is not an exp and the
/// caller masks the lane out; above, the caller takes that row again against a larger reference; a
/// NaN or +inf gives NaN): 2^n p(r), r = a - n log 2 in [-log 2 / 2, log 2 / 2], p the degree-5
/// polynomial below (relative error 1.5e-7 evaluated in float, the degree-6 Taylor polynomial's
/// 2.2e-7).
SEQLOC_SIMD __m256 exp_normal(__m256 a) {
  const __m256 n = _mm256_round_ps(_mm256_mul_ps(a, _mm256_set1_ps(1.44269504f)), _MM_FROUND_TO_NEAREST_INT);
  __m256 r = _mm256_fnmadd_ps(n, _mm256_set1_ps(0.693359375f), a);
  r = _mm256_fnmadd_ps(n, _mm256_set1_ps(-2.12194440e-4f), r);
  __m256 p = _mm256_set1_ps(kExp5);
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(kExp4));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(kExp3));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(kExp2));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(kExp1));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(kExp0));
  const __m256i bits = _mm256_slli_epi32(_mm256_add_epi32(_mm256_cvtps_epi32(n), _mm256_set1_epi32(127)), 23);
  return _mm256_mul_ps(p, _mm256_castsi256_ps(bits));
}

/// The state of intake_sums, per bin (padded to whole vectors): the reference of the bin's sums
/// so far (its largest value before the row), what the row's exps are taken against (the
/// reference, or the row's maximum where that lies far above it), the row's largest values and
/// its sums.
struct RowSums {
  AlignedVector<float> ref, against, row_max, sum, ex;
  explicit RowSums(std::size_t padded)
      : ref(padded, kZero), against(padded, kZero), row_max(padded), sum(padded), ex(padded) {}
};

/// Nats a row's values may lie above their reference before its exps are taken again against its
/// own maximum (e^40 times a row's cells and values stays far from the largest float).
constexpr float kHeadroom = 40;

/// A row starts with its exps taken against the bins' references; a bin without a value yet (its
/// reference kLogZero) against +inf, so that its zero cells add nothing (a = -inf) and its first
/// values are taken again against their own maximum (rose_too_far).
void start_row(RowSums& r) {
  for (std::size_t j = 0; j < r.ref.size(); ++j) {
    r.against[j] = r.ref[j] > kZero ? r.ref[j] : std::numeric_limits<float>::infinity();
  }
}

/// Where bins j0 .. j1 of a row rose more than kHeadroom above their reference: their exps are to
/// be taken against the row's maximum instead (r.against). Returns whether any did.
bool rose_too_far(RowSums& r, int j0, int j1) {
  bool any = false;
  for (int j = j0; j < j1; ++j) {
    const float top = r.row_max[static_cast<std::size_t>(j)];
    if (top > kZero && top - r.ref[static_cast<std::size_t>(j)] > kHeadroom) {
      r.against[static_cast<std::size_t>(j)] = top;
      any = true;
    }
  }
  return any;
}

/// Adds a row's sums to the bins' (`nb` of them): each rescaled from its reference to the larger of
/// the reference and the row's maximum, which becomes the reference. Returns false where a row's sum
/// is not finite: the row holds a NaN or +inf (block_pass; a value that rose too far for its exp
/// was taken again against its row's maximum by then), or a value its power took out of float's
/// range.
bool fold_row(RowSums& r, int nb, double* sum, double* ex) {
  for (std::size_t j = 0; j < static_cast<std::size_t>(nb); ++j) {
    if (!std::isfinite(r.sum[j])) return false;
    const float ref = r.ref[j], against = r.against[j], top = std::max(ref, r.row_max[j]);
    if (top > ref) {
      const double rescale = ref > kZero ? std::exp(double{ref} - top) : 0.0;
      sum[j] *= rescale;
      ex[j] *= rescale;
    }
    if (r.sum[j] > 0) {  // (nothing where every e was 0, against +inf among them)
      const double row_scale = against == top ? 1.0 : std::exp(double{against} - top);
      sum[j] += r.sum[j] * row_scale;
      ex[j] += r.ex[j] * row_scale;
    }
    r.ref[j] = top;
  }
  return true;
}

/// Asks for the lines holding `bytes` bytes from `at` in the second-level cache.
SEQLOC_SIMD void prefetch(const void* at, std::size_t bytes) {
  for (std::size_t offset = 0; offset < bytes; offset += 64) {
    _mm_prefetch(static_cast<const char*>(at) + offset, _MM_HINT_T1);
  }
}

/// One pass over groups g0 .. g0 + G of eight bins (G <= 2, the last one `lanes` wide) of a row,
/// the sums in registers: e = exp(x - against) where x - against >= log of the smallest normal
/// float, sum e, sum e x and the largest x (a NaN or +inf value makes its bin's sum NaN). `next`
/// (the next row, or null): its lines of these groups fetched on the way.
template <int G, bool Raised, class T>
SEQLOC_SIMD void block_pass(const T* row, const T* next, const IntakeSource& s, int g0, int lanes, float raised_to,
                            RowSums& r) {
  const __m256 power = _mm256_set1_ps(raised_to);
  const __m256 lowest = _mm256_set1_ps(kLogSmallestNormal);
  const std::size_t first = 8 * static_cast<std::size_t>(g0);
  __m256 ref[G], top[G], sum[G], ex[G];
  for (int i = 0; i < G; ++i) {
    ref[i] = _mm256_load_ps(r.against.data() + first + 8 * i);
    top[i] = _mm256_set1_ps(kZero);
    sum[i] = ex[i] = _mm256_setzero_ps();
  }
  for (int u = 0; u < s.width; ++u) {
    const std::size_t at = static_cast<std::size_t>(u) * s.cell_stride + first;
    if (next != nullptr) prefetch(next + at, G * 8 * sizeof(T));
    for (int i = 0; i < G; ++i) {
      const __m256 raw = load8(row + at + 8 * i, i + 1 < G ? 8 : lanes);
      const __m256 x = powered<Raised>(raw, power);
      top[i] = _mm256_max_ps(top[i], x);
      const __m256 a = _mm256_sub_ps(x, ref[i]);
      const __m256 e = _mm256_and_ps(exp_normal(a), _mm256_cmp_ps(a, lowest, _CMP_NLT_UQ));  // NaN kept
      sum[i] = _mm256_add_ps(sum[i], e);
      ex[i] = _mm256_fmadd_ps(e, x, ex[i]);  // x is finite: a zero cell's is kLogZero, its e 0
    }
  }
  for (int i = 0; i < G; ++i) {
    _mm256_store_ps(r.row_max.data() + first + 8 * i, top[i]);
    _mm256_store_ps(r.sum.data() + first + 8 * i, sum[i]);
    _mm256_store_ps(r.ex.data() + first + 8 * i, ex[i]);
  }
}

/// block_pass over a row's groups, two at a time (32 float16 values a cell, half a 64-byte line);
/// a block whose values rose more than kHeadroom above their reference passes again against its
/// maxima (the first row, a bin's first values).
template <bool Raised, class T>
SEQLOC_SIMD void row_pass(const T* row, const T* next, const IntakeSource& s, int nb, float power, RowSums& r) {
  const int groups = (nb + 7) / 8;
  start_row(r);
  for (int g0 = 0; g0 < groups; g0 += 2) {
    const int count = std::min(2, groups - g0), lanes = std::min(8, nb - 8 * (g0 + count - 1));
    auto pass = [&](const T* fetch) {
      if (count == 2) {
        block_pass<2, Raised>(row, fetch, s, g0, lanes, power, r);
      } else {
        block_pass<1, Raised>(row, fetch, s, g0, lanes, power, r);
      }
    };
    // The next row's lines: each by the block that starts it (two blocks share a line of float16).
    pass((8 * g0 * sizeof(T)) % 64 == 0 ? next : nullptr);
    if (rose_too_far(r, 8 * g0, std::min(nb, 8 * (g0 + count)))) pass(nullptr);
  }
}

#if SEQLOC_INTAKE_AVX512
#define SEQLOC_AVX512 __attribute__((target("avx512f,avx2,fma,f16c"))) inline
// GCC 12 warns of the undefined vector its AVX-512 intrinsics start from.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif

/// Sixteen values of a cell's bins as float: `lanes` of them from `at`, the rest -inf (a zero).
SEQLOC_AVX512 __m512 load16(const std::uint16_t* at, int lanes) {
  if (lanes == 16) return _mm512_cvtph_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(at)));
  alignas(32) std::uint16_t padded[16];
  std::fill(padded, padded + 16, std::uint16_t{0xFC00});
  std::copy(at, at + lanes, padded);
  return _mm512_cvtph_ps(_mm256_load_si256(reinterpret_cast<const __m256i*>(padded)));
}
SEQLOC_AVX512 __m512 load16(const float* at, int lanes) {
  if (lanes == 16) return _mm512_loadu_ps(at);
  alignas(64) float padded[16];
  std::fill(padded, padded + 16, -std::numeric_limits<float>::infinity());
  std::copy(at, at + lanes, padded);
  return _mm512_load_ps(padded);
}

/// exp_normal in sixteen lanes, the same operations (2^n by scalef, exact as the AVX2 version's
/// exponent bits are): the same value in every lane.
SEQLOC_AVX512 __m512 exp_normal16(__m512 a) {
  const __m512 n = _mm512_roundscale_ps(_mm512_mul_ps(a, _mm512_set1_ps(1.44269504f)), _MM_FROUND_TO_NEAREST_INT);
  __m512 r = _mm512_fnmadd_ps(n, _mm512_set1_ps(0.693359375f), a);
  r = _mm512_fnmadd_ps(n, _mm512_set1_ps(-2.12194440e-4f), r);
  __m512 p = _mm512_set1_ps(kExp5);
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(kExp4));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(kExp3));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(kExp2));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(kExp1));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(kExp0));
  return _mm512_scalef_ps(p, n);
}

/// block_pass in sixteen lanes: groups g0 .. g0 + G of sixteen bins.
template <int G, bool Raised, class T>
SEQLOC_AVX512 void block_pass16(const T* row, const T* next, const IntakeSource& s, int g0, int lanes, float raised_to,
                                RowSums& r) {
  const __m512 power = _mm512_set1_ps(raised_to);
  const __m512 zero = _mm512_set1_ps(kZero), lowest = _mm512_set1_ps(kLogSmallestNormal);
  const std::size_t first = 16 * static_cast<std::size_t>(g0);
  __m512 ref[G], top[G], sum[G], ex[G];
  for (int i = 0; i < G; ++i) {
    ref[i] = _mm512_load_ps(r.against.data() + first + 16 * i);
    top[i] = zero;
    sum[i] = ex[i] = _mm512_setzero_ps();
  }
  for (int u = 0; u < s.width; ++u) {
    const std::size_t at = static_cast<std::size_t>(u) * s.cell_stride + first;
    if (next != nullptr) prefetch(next + at, G * 16 * sizeof(T));
    for (int i = 0; i < G; ++i) {
      const __m512 raw = load16(row + at + 16 * i, i + 1 < G ? 16 : lanes);
      const __m512 x = Raised ? _mm512_mask_mul_ps(zero, _mm512_cmp_ps_mask(raw, zero, _CMP_NLE_UQ), raw, power)
                              : _mm512_max_ps(zero, raw);
      top[i] = _mm512_max_ps(top[i], x);
      const __m512 a = _mm512_sub_ps(x, ref[i]);
      const __mmask16 keep = _mm512_cmp_ps_mask(a, lowest, _CMP_NLT_UQ);  // NaN kept
      const __m512 e = exp_normal16(a);
      sum[i] = _mm512_mask_add_ps(sum[i], keep, sum[i], e);
      ex[i] = _mm512_mask3_fmadd_ps(e, x, ex[i], keep);
    }
  }
  for (int i = 0; i < G; ++i) {
    _mm512_store_ps(r.row_max.data() + first + 16 * i, top[i]);
    _mm512_store_ps(r.sum.data() + first + 16 * i, sum[i]);
    _mm512_store_ps(r.ex.data() + first + 16 * i, ex[i]);
  }
}

/// row_pass in sixteen lanes.
template <bool Raised, class T>
SEQLOC_AVX512 void row_pass16(const T* row, const T* next, const IntakeSource& s, int nb, float power, RowSums& r) {
  const int groups = (nb + 15) / 16;
  start_row(r);
  for (int g0 = 0; g0 < groups; g0 += 4) {
    const int count = std::min(4, groups - g0), lanes = std::min(16, nb - 16 * (g0 + count - 1));
    auto pass = [&](const T* fetch) {
      switch (count) {
        case 4:
          return block_pass16<4, Raised>(row, fetch, s, g0, lanes, power, r);
        case 3:
          return block_pass16<3, Raised>(row, fetch, s, g0, lanes, power, r);
        case 2:
          return block_pass16<2, Raised>(row, fetch, s, g0, lanes, power, r);
        default:
          return block_pass16<1, Raised>(row, fetch, s, g0, lanes, power, r);
      }
    };
    pass(next);
    if (rose_too_far(r, 16 * g0, std::min(nb, 16 * (g0 + count)))) pass(nullptr);
  }
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#undef SEQLOC_AVX512
#endif

/// The online softmax of bins j0 .. j1 a row at a time, each row summed by `pass` (row_pass or
/// row_pass16), in `lanes`-wide vectors.
template <class T, class Pass>
bool sums(const IntakeSource& s, const T* data, int j0, int j1, int lanes, float* max, double* sum, double* ex,
          Pass&& pass) {
  const int nb = j1 - j0;
  RowSums r(static_cast<std::size_t>((nb + lanes - 1) / lanes * lanes));
  std::fill(sum, sum + nb, 0.0);
  std::fill(ex, ex + nb, 0.0);
  const std::size_t row_values = static_cast<std::size_t>(s.width) * s.cell_stride;
  for (int v = 0; v < s.height; ++v) {
    const T* row = data + static_cast<std::size_t>(v) * row_values + j0;
    pass(row, v + 1 < s.height ? row + row_values : nullptr, r);
    if (!fold_row(r, nb, sum, ex)) return false;
  }
  std::copy(r.ref.begin(), r.ref.begin() + nb, max);
  return true;
}

/// sums with the widest loops this CPU runs.
template <bool Raised, class T>
bool sums(const IntakeSource& s, const T* data, int j0, int j1, float power, float* max, double* sum, double* ex) {
  const int nb = j1 - j0;
#if SEQLOC_INTAKE_AVX512
  if (intake_lanes() == 16) {
    return sums(s, data, j0, j1, 16, max, sum, ex, [&](const T* row, const T* next, RowSums& r) {
      return row_pass16<Raised>(row, next, s, nb, power, r);
    });
  }
#endif
  return sums(s, data, j0, j1, 8, max, sum, ex,
              [&](const T* row, const T* next, RowSums& r) { return row_pass<Raised>(row, next, s, nb, power, r); });
}

/// r[0 .. 7] transposed in registers: r[i] afterwards holds lane i of each of the eight.
SEQLOC_SIMD void transpose8(__m256* r) {
  const __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]), t1 = _mm256_unpackhi_ps(r[0], r[1]);
  const __m256 t2 = _mm256_unpacklo_ps(r[2], r[3]), t3 = _mm256_unpackhi_ps(r[2], r[3]);
  const __m256 t4 = _mm256_unpacklo_ps(r[4], r[5]), t5 = _mm256_unpackhi_ps(r[4], r[5]);
  const __m256 t6 = _mm256_unpacklo_ps(r[6], r[7]), t7 = _mm256_unpackhi_ps(r[6], r[7]);
  const __m256 s0 = _mm256_shuffle_ps(t0, t2, 0x44), s1 = _mm256_shuffle_ps(t0, t2, 0xEE);
  const __m256 s2 = _mm256_shuffle_ps(t1, t3, 0x44), s3 = _mm256_shuffle_ps(t1, t3, 0xEE);
  const __m256 s4 = _mm256_shuffle_ps(t4, t6, 0x44), s5 = _mm256_shuffle_ps(t4, t6, 0xEE);
  const __m256 s6 = _mm256_shuffle_ps(t5, t7, 0x44), s7 = _mm256_shuffle_ps(t5, t7, 0xEE);
  r[0] = _mm256_permute2f128_ps(s0, s4, 0x20);
  r[1] = _mm256_permute2f128_ps(s1, s5, 0x20);
  r[2] = _mm256_permute2f128_ps(s2, s6, 0x20);
  r[3] = _mm256_permute2f128_ps(s3, s7, 0x20);
  r[4] = _mm256_permute2f128_ps(s0, s4, 0x31);
  r[5] = _mm256_permute2f128_ps(s1, s5, 0x31);
  r[6] = _mm256_permute2f128_ps(s2, s6, 0x31);
  r[7] = _mm256_permute2f128_ps(s3, s7, 0x31);
}

template <bool Raised, class T>
SEQLOC_SIMD float write_row(const IntakeSource& s, const T* data, int v, int j0, int j1, float power, float shift,
                            float* out, std::size_t slice) {
  const T* row = data + static_cast<std::size_t>(v) * s.width * s.cell_stride + j0;
  const __m256 k = _mm256_set1_ps(power), by = _mm256_set1_ps(shift), zero = _mm256_set1_ps(kZero);
  __m256 top = zero;
  // Where every line's destination is 64-byte aligned, the stores bypass the cache: the frame
  // (16 MB at 128 x 128 x 256) does not stay there anyway, and its lines need not be read first.
  const bool stream = reinterpret_cast<std::uintptr_t>(out) % 64 == 0 && slice % 16 == 0;
  // A 64-byte line of each cell's values at a time (32 float16 bins), sixteen cells after
  // sixteen: every line read once from memory and used whole, and the bins' rows written in order
  // (a row of 128 cells is 8 lines of one page).
  constexpr int kTile = static_cast<int>(64 / sizeof(T));
  // The next row's lines, each fetched into the second-level cache by the block that reads the
  // same line of this row: the tiles walk a row's cells with a stride of a cell's bins, which the
  // hardware's prefetchers do not follow (the write took 2.4 ms a frame without, 1.3 with).
  const std::size_t row_values = static_cast<std::size_t>(s.width) * s.cell_stride;
  const T* next = v + 1 < s.height ? row + row_values : nullptr;
  for (int tile = 0; tile < j1 - j0; tile += kTile) {
    for (int u = 0; u < s.width; u += 16) {
      if (next != nullptr) {
        for (int i = 0; i < 16; ++i) {
          _mm_prefetch(reinterpret_cast<const char*>(next + static_cast<std::size_t>(u + i) * s.cell_stride + tile),
                       _MM_HINT_T1);
        }
      }
      for (int b = tile; b < std::min(j1 - j0, tile + kTile); b += 8) {
        __m256 r[16];
        for (int i = 0; i < 16; ++i) {
          const __m256 x = powered<Raised>(load8(row + static_cast<std::size_t>(u + i) * s.cell_stride + b, 8), k);
          top = _mm256_max_ps(top, x);
          r[i] = _mm256_max_ps(_mm256_sub_ps(x, by), zero);  // a zero cell's kLogZero stays kLogZero
        }
        transpose8(r);
        transpose8(r + 8);
        for (int i = 0; i < 8; ++i) {
          float* dst = out + static_cast<std::size_t>(b + i) * slice + u;
          if (stream) {
            _mm256_stream_ps(dst, r[i]);
            _mm256_stream_ps(dst + 8, r[8 + i]);
          } else {
            _mm256_storeu_ps(dst, r[i]);
            _mm256_storeu_ps(dst + 8, r[8 + i]);
          }
        }
      }
    }
  }
  if (stream) _mm_sfence();  // the streamed stores visible before the worker reports its part done
  alignas(32) float lanes[8];
  _mm256_store_ps(lanes, top);
  return *std::max_element(lanes, lanes + 8);
}

#undef SEQLOC_SIMD

}  // namespace

bool intake_sums_simd(const IntakeSource& source, int j0, int j1, float power, float* max, double* sum, double* ex) {
  const bool halves = source.type == core::VolumeType::float16;
  const auto* h = static_cast<const std::uint16_t*>(source.data);
  const auto* f = static_cast<const float*>(source.data);
  if (power == 1.0f) {
    return halves ? sums<false>(source, h, j0, j1, power, max, sum, ex)
                  : sums<false>(source, f, j0, j1, power, max, sum, ex);
  }
  return halves ? sums<true>(source, h, j0, j1, power, max, sum, ex)
                : sums<true>(source, f, j0, j1, power, max, sum, ex);
}

float intake_write_row_simd(const IntakeSource& source, int v, int j0, int j1, float power, float shift, float* out,
                            std::size_t slice) {
  const bool halves = source.type == core::VolumeType::float16;
  const auto* h = static_cast<const std::uint16_t*>(source.data);
  const auto* f = static_cast<const float*>(source.data);
  if (power == 1.0f) {
    return halves ? write_row<false>(source, h, v, j0, j1, power, shift, out, slice)
                  : write_row<false>(source, f, v, j0, j1, power, shift, out, slice);
  }
  return halves ? write_row<true>(source, h, v, j0, j1, power, shift, out, slice)
                : write_row<true>(source, f, v, j0, j1, power, shift, out, slice);
}

#else  // not x86-64: the portable loops in frame_intake.cpp

int intake_lanes() { return 1; }
int cap_intake_lanes(int lanes) { return lanes; }
bool intake_sums_simd(const IntakeSource&, int, int, float, float*, double*, double*) { return false; }
float intake_write_row_simd(const IntakeSource&, int, int, int, float, float, float*, std::size_t) { return 0; }

#endif

}  // namespace seqloc::intake::detail
