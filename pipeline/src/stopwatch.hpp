#pragma once
// Wall-clock timing of the pipeline's stages (preprocessing, frame intake, the modes' filter time).

#include <chrono>

namespace seqloc::pipeline::detail {

using Clock = std::chrono::steady_clock;

/// Seconds from `start` to now.
[[nodiscard]] inline double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

}  // namespace seqloc::pipeline::detail
