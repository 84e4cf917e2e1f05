#pragma once
// The mode classes' factories (each defined beside its class) and the timing they share.

#include <chrono>
#include <memory>

#include "seqloc/pipeline/modes.hpp"

namespace seqloc::pipeline::modes {

[[nodiscard]] std::unique_ptr<LocalizationMode> make_single(const RouteContext& context);
[[nodiscard]] std::unique_ptr<LocalizationMode> make_offline(const RouteContext& context);
/// online: the filter with ETU, MGR and PAS off; seqloc: as the options configure it.
[[nodiscard]] std::unique_ptr<LocalizationMode> make_sequential(const RouteContext& context, bool online);

using Clock = std::chrono::steady_clock;
[[nodiscard]] inline double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

}  // namespace seqloc::pipeline::modes
