#include "factories.hpp"

namespace seqloc::pipeline {

void LocalizationMode::finish(RouteResult& result) { result.filter_seconds += filter_seconds_; }

double LocalizationMode::reported_etu_weight(double entropy) const {
  return filter::etu_weight(entropy, context_.options.filter.etu_reference_entropy);
}

std::unique_ptr<LocalizationMode> make_mode(Mode mode, const RouteContext& context) {
  switch (mode) {
    case Mode::single:
      return modes::make_single(context);
    case Mode::offline:
      return modes::make_offline(context);
    case Mode::online:
      return modes::make_sequential(context, /*online=*/true);
    case Mode::smooth:
      return modes::make_smooth(context);
    case Mode::seqloc:
      break;
  }
  return modes::make_sequential(context, /*online=*/false);
}

}  // namespace seqloc::pipeline
