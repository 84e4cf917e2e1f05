#pragma once
// The mode classes' factories (each defined beside its class) and the timing they share.

#include <memory>

#include "seqloc/core/stopwatch.hpp"
#include "seqloc/pipeline/modes.hpp"

namespace seqloc::pipeline::modes {

[[nodiscard]] std::unique_ptr<LocalizationMode> make_single(const RouteContext& context);
[[nodiscard]] std::unique_ptr<LocalizationMode> make_offline(const RouteContext& context);
/// online: the filter with ETU, MGR and PAS off; seqloc: as the options configure it.
[[nodiscard]] std::unique_ptr<LocalizationMode> make_sequential(const RouteContext& context, bool online);
/// smooth: the seqloc filter forward and the backward filter, every frame given every frame.
[[nodiscard]] std::unique_ptr<LocalizationMode> make_smooth(const RouteContext& context);

using core::Clock;
using core::seconds_since;

}  // namespace seqloc::pipeline::modes
