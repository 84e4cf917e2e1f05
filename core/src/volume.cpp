#include "seqloc/core/volume.hpp"

#include <cmath>
#include <cstring>
#include <string>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/error.hpp"

#if defined(__x86_64__)
#include <cpuid.h>
#include <immintrin.h>
#endif

namespace seqloc::core {
namespace {

#if defined(__x86_64__)
// F16C, compiled for it whatever the build's -march (a function's target attribute): the
// one-value conversions where the build targets F16C, and the array ones where the CPU has it
// (has_f16c). Ties to even, overflow to infinity. (Not _cvtss_sh: clang's macro is a C99
// compound literal.)
__attribute__((target("f16c"))) float f16c_half_to_float(std::uint16_t h) { return _cvtsh_ss(h); }

__attribute__((target("f16c"))) std::uint16_t f16c_float_to_half(float f) {
  return static_cast<std::uint16_t>(_mm_extract_epi16(_mm_cvtps_ph(_mm_set_ss(f), _MM_FROUND_TO_NEAREST_INT), 0));
}

__attribute__((target("avx,f16c"))) void halves_to_floats_f16c(const std::uint16_t* in, std::size_t n, float* out) {
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    _mm256_storeu_ps(out + i, _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(in + i))));
  }
  for (; i < n; ++i) out[i] = f16c_half_to_float(in[i]);
}

__attribute__((target("avx,f16c"))) void floats_to_halves_f16c(const float* in, std::size_t n, std::uint16_t* out) {
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i),
                     _mm256_cvtps_ph(_mm256_loadu_ps(in + i), _MM_FROUND_TO_NEAREST_INT));
  }
  for (; i < n; ++i) out[i] = f16c_float_to_half(in[i]);
}

// AVX as the compiler's runtime asks it (the OS saves the YMM registers too), F16C from CPUID
// leaf 1 (clang 14's __builtin_cpu_supports does not know "f16c").
bool has_f16c() {
  static const bool yes = [] {
    unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
    return __builtin_cpu_supports("avx") && __get_cpuid(1, &eax, &ebx, &ecx, &edx) != 0 && (ecx & bit_F16C) != 0;
  }();
  return yes;
}
#endif

void require_same_length(std::size_t in, std::size_t out, const char* what) {
  if (in != out) {
    throw Error(ErrorCategory::internal,
                std::string(what) + ": " + std::to_string(in) + " values in, room for " + std::to_string(out));
  }
}

}  // namespace

void halves_to_floats(std::span<const std::uint16_t> halves, std::span<float> out) {
  require_same_length(halves.size(), out.size(), "halves_to_floats");
#if defined(__x86_64__)
  if (has_f16c()) return halves_to_floats_f16c(halves.data(), halves.size(), out.data());
#endif
  for (std::size_t i = 0; i < halves.size(); ++i) out[i] = half_to_float(halves[i]);
}

void floats_to_halves(std::span<const float> values, std::span<std::uint16_t> out) {
  require_same_length(values.size(), out.size(), "floats_to_halves");
#if defined(__x86_64__)
  if (has_f16c()) return floats_to_halves_f16c(values.data(), values.size(), out.data());
#endif
  for (std::size_t i = 0; i < values.size(); ++i) out[i] = float_to_half(values[i]);
}

float half_to_float(std::uint16_t h) {
#if defined(__F16C__)
  return f16c_half_to_float(h);  // one instruction, exact (F16C: x86-64-v3)
#else
  return detail::half_to_float_portable(h);
#endif
}

std::uint16_t float_to_half(float f) {
#if defined(__F16C__)
  return f16c_float_to_half(f);
#else
  return detail::float_to_half_portable(f);
#endif
}

float detail::half_to_float_portable(std::uint16_t h) {
  const std::uint32_t sign = static_cast<std::uint32_t>(h & 0x8000u) << 16;
  const std::uint32_t exponent = (h >> 10) & 0x1Fu;
  const std::uint32_t mantissa = h & 0x3FFu;
  std::uint32_t bits = 0;
  if (exponent == 0) {
    if (mantissa == 0) {
      bits = sign;
    } else {  // subnormal: value = mantissa * 2^-24
      const float value = std::ldexp(static_cast<float>(mantissa), -24);
      std::memcpy(&bits, &value, 4);
      bits |= sign;
    }
  } else if (exponent == 31) {
    bits = sign | 0x7F800000u | (mantissa << 13);  // inf or NaN
  } else {
    bits = sign | ((exponent + 112) << 23) | (mantissa << 13);
  }
  float out = 0;
  std::memcpy(&out, &bits, 4);
  return out;
}

std::uint16_t detail::float_to_half_portable(float f) {
  std::uint32_t bits = 0;
  std::memcpy(&bits, &f, 4);
  const auto sign = static_cast<std::uint16_t>((bits >> 16) & 0x8000u);
  const std::uint32_t magnitude = bits & 0x7FFFFFFFu;
  // Rounds `value` to nearest, ties to even, after dropping its `dropped` low bits.
  auto round_off = [](std::uint32_t value, int dropped) {
    const std::uint32_t kept = value >> dropped, rest = value & ((1u << dropped) - 1), half = 1u << (dropped - 1);
    return kept + ((rest > half || (rest == half && (kept & 1u))) ? 1u : 0u);
  };
  if (magnitude > 0x7F800000u) return static_cast<std::uint16_t>(sign | 0x7E00u);   // NaN, quiet
  if (magnitude >= 0x477FF000u) return static_cast<std::uint16_t>(sign | 0x7C00u);  // >= 65520: infinity
  if (magnitude >= 0x38800000u) {  // a normal half (>= 2^-14): rebias the exponent, keep 10 mantissa bits;
    // a carry out of the mantissa correctly moves to the next exponent.
    return static_cast<std::uint16_t>(sign | round_off(magnitude - (112u << 23), 13));
  }
  if (magnitude <= 0x33000000u) return sign;  // <= 2^-25 (a tie at 2^-25 goes to the even 0)
  // A subnormal half counts units of 2^-24: the float's 24-bit significand shifted right.
  const auto exponent = static_cast<int>(magnitude >> 23);  // 102 ... 112
  const std::uint32_t significand = (magnitude & 0x7FFFFFu) | 0x800000u;
  return static_cast<std::uint16_t>(sign | round_off(significand, 126 - exponent));  // 2^-14 rounds up to 0x0400
}

Odometry compose(const std::vector<Odometry>& increments) {
  double x = 0, y = 0, yaw = 0;
  for (const auto& o : increments) {
    const double c = std::cos(yaw * kDegToRad), s = std::sin(yaw * kDegToRad);
    x += c * o.forward_m - s * o.left_m;
    y += s * o.forward_m + c * o.left_m;
    yaw += o.yaw_deg;
  }
  return {x, y, yaw};
}

Odometry invert(const Odometry& m) {
  // Minus the displacement, rotated into the end's frame.
  const double c = std::cos(m.yaw_deg * kDegToRad), s = std::sin(m.yaw_deg * kDegToRad);
  return {-(c * m.forward_m + s * m.left_m), -(-s * m.forward_m + c * m.left_m), -m.yaw_deg};
}

}  // namespace seqloc::core
