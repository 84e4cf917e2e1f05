#include <cmath>
#include <cstring>
#include <sstream>

#include "seqloc/filter/config.hpp"
#include "seqloc/filter/types.hpp"

#if defined(__x86_64__)
#include <cpuid.h>
#include <immintrin.h>
#endif

namespace seqloc::filter {
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
    throw FilterError(std::string(what) + ": " + std::to_string(in) + " values in, room for " + std::to_string(out),
                      ErrorCategory::internal);
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

std::span<const FilterConfigField> filter_config_fields() {
  using C = FilterConfig;
  static const FilterConfigField kFields[] = {
      {"width", &C::width, "Belief window width, cells of 0.5 m"},
      {"height", &C::height, "Belief window height, cells of 0.5 m"},
      {"headings", &C::headings, "Heading bins R"},
      {"etu", &C::etu, "Entropy-Tempered Uncertainty"},
      {"mgr", &C::mgr, "Map-Guided Relocalization"},
      {"pas", &C::pas, "Peak-Anchored Smoothing"},
      {"etu_reference_entropy", &C::etu_reference_entropy,
       "ETU relative to this normalized entropy: w = min(1, (1 - H) / (1 - H_ref)); 0: the paper's 1 - H"},
      {"etu_route_reference", &C::etu_route_reference,
       "ETU relative to the median entropy of the route's frames so far (as given) instead of --etu-reference"},
      {"mgr_epsilon", &C::mgr_epsilon, "MGR's eps: the share of road-prior mass mixed into the belief"},
      {"mgr_sigma_m", &C::mgr_sigma_m, "MGR's road-prior sigma in metres"},
      {"pas_radius", &C::pas_radius, "PAS radius in cells"},
      {"outside_crop_nats", &C::outside_crop_nats,
       "Window cells outside a frame's crop get log(1/M) minus this (0: the paper's rule)"},
      {"self_calibrate", &C::self_calibrate,
       "self-calibration: raise each volume to the power its predecessors' predictive likelihood favours"},
      {"self_calibration_bank", &C::self_calibration_bank,
       "Self-calibration: judge each power by the route's likelihood under a coarse filter run at it "
       "(off: by the one-step predictive likelihood, with the hold)"},
      {"self_calibration_prior_octaves", &C::self_calibration_prior_octaves,
       "Self-calibration: sigma of the prior on log2 of the power (octaves)"},
      {"self_calibration_outlier_share", &C::self_calibration_outlier_share,
       "Self-calibration: share of a uniform belief each frame is also judged against"},
      {"self_calibration_hold_below_octaves", &C::self_calibration_hold_below_octaves,
       "Self-calibration: powers down to this many octaves under 1 count as calibrated"},
      {"self_calibration_hold_above_octaves", &C::self_calibration_hold_above_octaves,
       "Self-calibration: powers up to this many octaves over 1 count as calibrated"},
      {"self_calibration_hold_follow_octaves", &C::self_calibration_hold_follow_octaves,
       "Self-calibration: held, an estimate this many octaves under 1 is followed all the same"},
      {"self_calibration_hold_share", &C::self_calibration_hold_share,
       "Self-calibration: the power stays 1 while the posterior keeps this share on calibrated powers"},
      {"relocalization_jump_m", &C::relocalization_jump_m, "An argmax jump beyond this (m) is flagged relocalized"},
      {"subbin_heading", &C::subbin_heading, "Refine the heading between bins (beyond the paper)"},
      {"subbin_half_width", &C::subbin_half_width, "Bins each side of the heading in that refinement"},
      {"motion_noise", &C::motion_noise, "Diffuse the belief with the step length (beyond the paper)"},
      {"motion_noise_xy_per_m", &C::motion_noise_xy_per_m, "Motion noise: position sigma (m) per metre driven"},
      {"motion_noise_deg_per_m", &C::motion_noise_deg_per_m, "Motion noise: heading sigma (degrees) per metre driven"},
      {"gps_prior", &C::gps_prior, "Use every frame's GPS fix as a prior term (beyond the paper)"},
      {"threads", &C::threads, "Worker threads of one filter step"},
  };
  return kFields;
}

FilterConfig paper_config() {
  FilterConfig c;
  c.etu_reference_entropy = 0;
  c.outside_crop_nats = 0;
  c.self_calibrate = false;
  c.etu_route_reference = false;
  return c;
}

void FilterConfig::validate() const {
  auto fail = [](const std::string& field, double value, const std::string& constraint) {
    std::ostringstream s;
    s << "filter config: " << field << " = " << value << ": " << constraint;
    throw FilterError(s.str(), ErrorCategory::usage);
  };
  if (width < 8 || width > 4096) fail("width", width, "must be in [8, 4096] cells");
  if (height < 8 || height > 4096) fail("height", height, "must be in [8, 4096] cells");
  if (headings < 4 || headings > 4096) fail("headings", headings, "must be in [4, 4096] bins");
  if (!(mgr_epsilon > 0 && mgr_epsilon < 1)) fail("mgr_epsilon", mgr_epsilon, "must be in (0, 1)");
  if (!(mgr_sigma_m > 0)) fail("mgr_sigma_m", mgr_sigma_m, "must be > 0");
  if (pas_radius < 0 || pas_radius > 64) fail("pas_radius", pas_radius, "must be in [0, 64] cells");
  if (!(relocalization_jump_m > 0)) fail("relocalization_jump_m", relocalization_jump_m, "must be > 0");
  if (!(etu_reference_entropy >= 0 && etu_reference_entropy < 1)) {
    fail("etu_reference_entropy", etu_reference_entropy, "must be in [0, 1) (0: the paper's ETU)");
  }
  if (!(outside_crop_nats >= 0 && outside_crop_nats <= 50)) {
    fail("outside_crop_nats", outside_crop_nats, "must be in [0, 50]");
  }
  if (subbin_half_width < 1 || subbin_half_width >= headings / 2) {
    fail("subbin_half_width", subbin_half_width, "must be in [1, headings / 2)");
  }
  if (!(motion_noise_xy_per_m >= 0)) fail("motion_noise_xy_per_m", motion_noise_xy_per_m, "must be >= 0");
  if (!(motion_noise_deg_per_m >= 0)) fail("motion_noise_deg_per_m", motion_noise_deg_per_m, "must be >= 0");
  if (!(self_calibration_prior_octaves > 0 && self_calibration_prior_octaves <= 16)) {
    fail("self_calibration_prior_octaves", self_calibration_prior_octaves, "must be in (0, 16]");
  }
  if (!(self_calibration_outlier_share >= 0 && self_calibration_outlier_share < 1)) {
    fail("self_calibration_outlier_share", self_calibration_outlier_share, "must be in [0, 1)");
  }
  if (!(self_calibration_hold_below_octaves >= 0 && self_calibration_hold_below_octaves <= 4)) {
    fail("self_calibration_hold_below_octaves", self_calibration_hold_below_octaves, "must be in [0, 4]");
  }
  if (!(self_calibration_hold_above_octaves >= 0 && self_calibration_hold_above_octaves <= 4)) {
    fail("self_calibration_hold_above_octaves", self_calibration_hold_above_octaves, "must be in [0, 4]");
  }
  if (!(self_calibration_hold_follow_octaves >= 0 && self_calibration_hold_follow_octaves <= 10)) {
    fail("self_calibration_hold_follow_octaves", self_calibration_hold_follow_octaves, "must be in [0, 10]");
  }
  if (!(self_calibration_hold_share >= 0 && self_calibration_hold_share <= 1)) {
    fail("self_calibration_hold_share", self_calibration_hold_share, "must be in [0, 1]");
  }
  if (threads < 1 || threads > 256) fail("threads", threads, "must be in [1, 256]");
}

}  // namespace seqloc::filter
