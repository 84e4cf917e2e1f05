#pragma once
// Wall-clock timing of stages (preprocessing, frame intake, the modes' filter time).

#include <chrono>

namespace seqloc::core {

using Clock = std::chrono::steady_clock;

/// Seconds from `start` to now.
[[nodiscard]] inline double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

/// Seconds since construction or the last restart().
class Stopwatch {
 public:
  [[nodiscard]] double seconds() const { return seconds_since(start_); }
  void restart() { start_ = Clock::now(); }

 private:
  Clock::time_point start_ = Clock::now();
};

}  // namespace seqloc::core
