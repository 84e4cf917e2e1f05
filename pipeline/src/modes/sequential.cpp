// online and seqloc: the sequential filter (conventions.md section 6) in a window that follows the
// vehicle, driven along a route. online is the same filter with ETU, MGR and PAS off (naive
// fusion). The filter and its window are SequentialLocalizer (sequential_localizer.cpp).
#include <optional>

#include "factories.hpp"
#include "seqloc/pipeline/sequential_localizer.hpp"

namespace seqloc::pipeline::modes {
namespace {

class SequentialMode final : public LocalizationMode {
 public:
  SequentialMode(const RouteContext& context, bool online)
      : LocalizationMode(context),
        localizer_(context.cache, context.options.filter, online, context.options.recentre_margin) {}

  FrameEstimate estimate(std::size_t i, const GridCrop& crop, FramePrefetcher& frames) override {
    const RouteFrame& f = context_.route.frames[i];
    const filter::PreparedFrame& frame = frames.get(i);
    std::optional<GridFix> gps;
    if (f.gps) {
      const auto g = context_.cache.metadata().projection().forward(f.gps->where);
      gps = GridFix{g.x_m, g.y_m, f.gps->sigma_m};
    }
    const auto t0 = Clock::now();
    const FrameEstimate e = localizer_.step(frame, crop, f.odometry, gps);
    filter_seconds_ += seconds_since(t0);
    const RegionWindow& window = localizer_.window();
    if (context_.inspect) {
      context_.inspect({i, &frame, crop, &localizer_.filter()->belief(), window.origin_u(), window.origin_v()});
    }
    if (context_.options.keep_beliefs) {
      const auto marginal = localizer_.filter()->belief().position_marginal();
      beliefs_.insert(beliefs_.end(), marginal.begin(), marginal.end());
      belief_origins_.push_back({window.origin_u(), window.origin_v()});
    }
    frames.release(i);
    return e;
  }

  void finish(RouteResult& result) override {
    LocalizationMode::finish(result);
    result.recentres += localizer_.recentres();
    if (context_.options.keep_beliefs) {
      result.belief_width = localizer_.config().width;
      result.belief_height = localizer_.config().height;
      result.beliefs = std::move(beliefs_);
      result.belief_origins = std::move(belief_origins_);
    }
  }

 private:
  SequentialLocalizer localizer_;
  std::vector<float> beliefs_;
  std::vector<std::array<std::int64_t, 2>> belief_origins_;
};

}  // namespace

std::unique_ptr<LocalizationMode> make_sequential(const RouteContext& context, bool online) {
  return std::make_unique<SequentialMode>(context, online);
}

}  // namespace seqloc::pipeline::modes
