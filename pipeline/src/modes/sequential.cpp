// online and seqloc: the sequential filter (conventions.md section 6) in a window that follows the
// vehicle, driven along a route. online is the same filter with ETU, MGR and PAS off (naive
// fusion). The filter and its window are SequentialLocalizer (sequential_localizer.cpp), which
// also smooths with a lag (LocalizeOptions::lag): frame i's pose is then final once frame i + lag
// has been stepped, or the route has ended. A route that crosses into another region has its
// belief handed over at the seam (SequentialLocalizer::hand_over).
#include <map>
#include <optional>

#include "factories.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/pipeline/sequential_localizer.hpp"
#include "seqloc/pipeline/volume_shape.hpp"

namespace seqloc::pipeline::modes {
namespace {

class SequentialMode final : public LocalizationMode {
 public:
  SequentialMode(const RouteContext& context, bool online)
      : LocalizationMode(context),
        localizer_(context.cache, context.options.filter, online, context.options.recentre_margin, context.options.lag,
                   context.options.device) {}

  FrameEstimate estimate(std::size_t i, const GridCrop&, FramePrefetcher& frames) override {
    const std::size_t n = context_.route.frames.size();
    while (final_.find(i) == final_.end()) {
      if (next_ == n)
        throw Error(ErrorCategory::internal, "sequential mode: frame " + std::to_string(i) + " asked for twice");
      step(next_++, frames);
      if (next_ == n) localizer_.finish();
      for (auto& [index, e] : localizer_.take_final()) final_.emplace(index, e);
    }
    const FrameEstimate e = final_.at(i);
    final_.erase(i);
    return e;
  }

  void finish(io::RouteResult& result) override {
    LocalizationMode::finish(result);
    result.recentres += localizer_.recentres();
    if (context_.options.keep_beliefs) {
      result.belief_width = localizer_.config().width;
      result.belief_height = localizer_.config().height;
      result.beliefs = std::move(beliefs_);
      result.likelihoods = std::move(likelihoods_);
      result.belief_origins = std::move(belief_origins_);
    }
  }

 private:
  // The filter's step on frame j (and, with a lag, the backward pass it completes).
  void step(std::size_t j, FramePrefetcher& frames) {
    const io::RouteFrame& f = context_.route.frames[j];
    if (j > 0 && region_of(j) != region_of(j - 1)) localizer_.hand_over(cache_of(j));
    const auto& projection = projection_of(j);
    const GridCrop crop = frame_crop(f, cache_of(j).grid(), projection);
    const auto frame = frames.get_shared(j);
    const std::optional<GridFix> gps = frame_gps_fix(f, projection);
    const auto t0 = Clock::now();
    (void)localizer_.step(frame, crop, f.odometry, gps);
    filter_seconds_ += seconds_since(t0);
    const RegionWindow& window = localizer_.window();
    if (context_.inspect) {
      context_.inspect({j, frame.get(), crop, &localizer_.filter()->belief(), window.origin_u(), window.origin_v()});
    }
    if (context_.options.keep_beliefs) {
      const auto& belief = localizer_.filter()->belief();
      const auto marginal = belief.position_marginal();
      beliefs_.insert(beliefs_.end(), marginal.begin(), marginal.end());
      const auto own = window_marginal(*frame, window.crop_pose(crop), belief.width(), belief.height());
      likelihoods_.insert(likelihoods_.end(), own.begin(), own.end());
      belief_origins_.push_back({window.origin_u(), window.origin_v()});
    }
    frames.release(j);  // the localizer keeps what its lag needs
  }

  SequentialLocalizer localizer_;
  std::size_t next_ = 0;
  std::map<std::size_t, FrameEstimate> final_;
  std::vector<float> beliefs_, likelihoods_;
  std::vector<std::array<std::int64_t, 2>> belief_origins_;
};

}  // namespace

std::unique_ptr<LocalizationMode> make_sequential(const RouteContext& context, bool online) {
  return std::make_unique<SequentialMode>(context, online);
}

}  // namespace seqloc::pipeline::modes
