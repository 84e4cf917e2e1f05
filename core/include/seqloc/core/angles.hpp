#pragma once
// Angles in degrees, as every stage states headings (conventions.md section 1): wrapped to
// [0, 360) for a heading, to [-180, 180) for a turn, and the difference of two headings.

#include <algorithm>
#include <cmath>

namespace seqloc::core {

inline constexpr double kPi = 3.14159265358979323846;
inline constexpr double kDegToRad = kPi / 180.0;
inline constexpr double kRadToDeg = 180.0 / kPi;

/// `deg` wrapped to [0, 360).
[[nodiscard]] inline double wrap360(double deg) {
  const double r = std::fmod(deg, 360.0);
  return r < 0 ? r + 360.0 : r;
}

/// `deg` wrapped to [-180, 180).
[[nodiscard]] inline double wrap180(double deg) { return wrap360(deg + 180.0) - 180.0; }

/// The smaller angle between two headings, in [0, 180]: min(|a - b| mod 360, 360 - |a - b| mod 360).
[[nodiscard]] inline double heading_difference_deg(double a, double b) {
  const double d = std::fmod(std::abs(a - b), 360.0);
  return std::min(d, 360.0 - d);
}

}  // namespace seqloc::core
